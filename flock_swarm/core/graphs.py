"""Interaction graphs as edge lists: the r-disk graph, fixed graphs, Barabasi-Albert graphs.

An undirected graph on ``n`` vertices is held as two integer arrays ``i < j`` of equal length
(one entry per edge) and an optional weight per edge. No ``n x n`` matrix is built for the
r-disk graph: pairs come from a k-d tree (:class:`scipy.spatial.cKDTree`), so the cost of a
neighbour search is ``O(n log n + |E|)``.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class EdgeList:
    """An undirected graph on ``n`` vertices: edges ``(i[k], j[k])`` with ``i < j``."""

    n: int
    i: np.ndarray
    j: np.ndarray
    weight: np.ndarray

    @property
    def size(self) -> int:
        """Return the number of edges."""
        return int(self.i.size)


def disk_graph(q: np.ndarray, r: float, strict: bool = True) -> EdgeList:
    """Return the r-disk graph ``{(i, j): ||q_i - q_j|| < r}`` ([Su09] eq. (3)).

    :param q: positions, shape ``(n, dim)``.
    :param r: interaction radius, ``> 0``.
    :param strict: ``True`` for ``< r`` ([Su09] eq. (3)); ``False`` for ``<= r``
        ([Yu10] ``N_i``; [Jadbabaie03] "in or on a circle").
    :return: the edge list, unit weights, edges sorted by ``(i, j)``.
    """
    n = q.shape[0]
    if n < 2:
        empty = np.zeros(0, dtype=np.intp)
        return EdgeList(n, empty, empty, np.zeros(0))
    # The tree (or, for a small swarm, every pair) proposes candidates with a margin; the
    # decision is within_radius(), the one predicate the agent node uses too, so both agree
    # even for pairs exactly r apart, and both ways give the same edges.
    i, j = every_pair(n) if n <= BRUTE_FORCE_MAX else sorted_pairs(q, r * (1.0 + 1e-9))
    keep = within_radius(pair_sq_distances(q, i, j), r, strict)
    i, j = i[keep], j[keep]
    return EdgeList(n, i, j, np.ones(i.size))


#: Swarms up to this size test every pair for the r-disk graph: below about 100 agents that
#: is cheaper than building a k-d tree (5 us against 50 us at 5 agents, 17 against 66 at 50).
BRUTE_FORCE_MAX = 64


@lru_cache(maxsize=8)
def every_pair(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Return all pairs ``i < j`` of ``n`` vertices sorted by ``(i, j)`` (read-only arrays)."""
    i, j = np.triu_indices(n, 1)
    i, j = i.astype(np.intp), j.astype(np.intp)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def sorted_pairs(q: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the candidate pairs ``i < j`` of a k-d tree within ``radius``, sorted by ``(i, j)``.

    :param q: positions, shape ``(n, dim)``, finite.
    :param radius: the search radius (the tree's ``<=``; callers add their own margin).
    :return: ``(i, j)``, contiguous ``intp`` arrays.
    """
    return sorted_pairs_of_tree(cKDTree(q, balanced_tree=False, compact_nodes=False), radius,
                                q.shape[0])


def sorted_pairs_of_tree(tree: cKDTree, radius: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the pairs ``i < j`` of a k-d tree of ``n`` points within ``radius``, sorted.

    :param tree: the tree.
    :param radius: the search radius (the tree's ``<=``).
    :param n: the number of points.
    :return: ``(i, j)``, contiguous ``intp`` arrays sorted by ``(i, j)``.
    """
    pairs = tree.query_pairs(radius, output_type='ndarray')
    # One integer key per pair: sorting it is an order of magnitude faster than lexsort.
    return pairs_of_keys(np.sort(pair_keys(pairs[:, 0], pairs[:, 1])))


def pair_keys(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Return one ``int64`` key per pair, ordered as the pairs ``(i, j)`` are (ids < 2^31)."""
    return (i.astype(np.int64) << 32) | j


def pairs_of_keys(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the pairs ``(i, j)`` of keys made by :func:`pair_keys`."""
    return (key >> 32).astype(np.intp), (key & 0xFFFFFFFF).astype(np.intp)


def pair_sq_distances(q: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Return ``||q_j - q_i||^2`` for each pair.

    ``take`` rather than fancy indexing: it gathers rows of an ``(n, dim)`` array several
    times faster, with the same values.

    :param q: positions, shape ``(n, dim)``.
    :param i: first ends, shape ``(e,)``.
    :param j: second ends, shape ``(e,)``.
    :return: squared distances, shape ``(e,)``.
    """
    diff = q.take(j, axis=0) - q.take(i, axis=0)
    return np.einsum('ek,ek->e', diff, diff)


class VerletDiskGraph:
    """The r-disk graph of a moving swarm, filtered from candidate pairs kept up to date.

    A Verlet neighbour list (L. Verlet, Phys. Rev. 159, 98, 1967) with per-agent refresh.
    Candidates are the pairs within ``R = r + skin``. Each agent keeps the position where
    its candidates were last searched, seen in a frame that drifts with its swarm (the median
    displacement, so a flock moving with its leader stays still in it). An agent that has
    moved more than ``skin / 3`` in that frame has its candidates searched again, against
    every agent where it is now. Every pair within ``r`` is then a candidate: a pair left
    out was more than ``R`` apart when the later of its two agents was last searched, and
    since then that agent has moved at most ``skin / 3`` and the other at most
    ``2 skin / 3`` (``skin / 3`` to its own search position and ``skin / 3`` back), so it is
    still more than ``r`` apart. Filtering the candidates with :func:`within_radius` gives
    exactly :func:`disk_graph`: the same edges in the same order. A flock costs a distance
    per candidate and step instead of a tree search; stragglers are searched in the tree of
    the last full search (where every other agent is within ``skin / 3``) and among the
    agents searched since.

    The swarm may be a stack of ``blocks`` independent groups of equal size (consecutive
    agents), none linked to another; each drifts with its own median.
    """

    #: Once this fraction of the agents has been searched again, search all of them.
    FULL_SEARCH_FRACTION = 0.25
    #: Below this many agents one search of all costs less than searching some again.
    FEWEST_TO_REFRESH = 1000
    #: When the candidates of a full search last no more than MIN_LIFETIME steps (the start
    #: of a run, agents rushing to the leader), the next PLAIN_STEPS steps search the r-disk
    #: graph alone, without skin or bookkeeping (measured on Fig. 3 runs: as fast as
    #: disk_graph there, against 1.4 times slower with the list).
    MIN_LIFETIME = 4
    PLAIN_STEPS = 10

    def __init__(self, r: float, strict: bool = True, skin: float = 0.2,
                 blocks: int = 1) -> None:
        """Create the graph; the first call to :meth:`edges` searches every agent.

        :param r: interaction radius, ``> 0``.
        :param strict: ``< r`` (``True``) or ``<= r``, as :func:`disk_graph`.
        :param skin: extra search radius, relative to ``r``, ``> 0``.
        :param blocks: number of independent groups the swarm is made of.
        """
        self.r, self.strict, self.blocks = r, strict, blocks
        self.skin = skin * r
        # The tree's <= with a margin: rounding cannot drop a pair at distance R.
        self.reach = (r + self.skin) * (1.0 + 1e-9)
        #: Searches of every agent (with and without skin), and of some agents only.
        self.searches = self.plain_searches = self.refreshes = 0
        self._ref: np.ndarray | None = None
        self._calls = self._last_search = self._plain = 0
        self._key = np.zeros(0, dtype=np.int64)
        self._i = self._j = np.zeros(0, dtype=np.intp)
        self.sq_dist = np.zeros(0)

    def edges(self, q: np.ndarray) -> EdgeList:
        """Return the r-disk graph at positions ``q`` (``disk_graph(q, r, strict)`` per group).

        :param q: positions, shape ``(n, dim)``, the same ``n`` at every call; finite.
        :return: the edge list, unit weights, edges sorted by ``(i, j)``.
        """
        n, dim = q.shape
        if n % self.blocks:
            raise ValueError(f'{n} agents do not split into {self.blocks} equal groups')
        self._calls += 1
        if self._plain:
            self._plain -= 1
            self._search_all(q, plain=True)
        elif self._ref is None:
            self._search_all(q)
        else:
            m = n // self.blocks
            offset = (q - self._ref).reshape(self.blocks, m, dim)
            # Any vector common to a group will do as its drift: a median (the middle order
            # statistic of each coordinate) is cheap and ignores stragglers.
            middle = np.partition(offset, m // 2, axis=1)[:, m // 2]
            drift = np.repeat(middle, m, axis=0)
            dev = offset.reshape(n, dim) - drift
            moved = np.flatnonzero(~(9.0 * np.einsum('nk,nk->n', dev, dev)
                                     <= self.skin * self.skin))
            if moved.size and (n < self.FEWEST_TO_REFRESH or moved.size + self._searched.sum()
                               > self.FULL_SEARCH_FRACTION * n):
                lasted = self._calls - self._last_search > self.MIN_LIFETIME
                self._plain = 0 if lasted else self.PLAIN_STEPS - 1
                self._search_all(q, plain=not lasted)
            elif moved.size:
                self._refresh(q, moved, q - drift)
        sq = pair_sq_distances(q, self._i, self._j)
        keep = within_radius(sq, self.r, self.strict)
        i, j = self._i[keep], self._j[keep]
        #: The squared lengths of the edges last returned (``pair_sq_distances`` of them).
        self.sq_dist = sq[keep]
        return EdgeList(n, i, j, np.ones(i.size))

    def _search_all(self, q: np.ndarray, plain: bool = False) -> None:
        """Search the candidates of every agent; make ``q`` their reference.

        ``plain``: candidates within ``r`` only, valid for this step alone.
        """
        n = q.shape[0]
        # Groups side by side along the first axis with gaps of 2 R: the tree pairs no two
        # groups (the shift's rounding, ~1e-16 of it, is far inside the margin of reach).
        self._shift = np.zeros(n)
        if self.blocks > 1:
            x = q[:, 0].reshape(self.blocks, -1)
            low, width = x.min(axis=1), x.max(axis=1) - x.min(axis=1)
            start = np.concatenate(([0.0], np.cumsum(width + 2.0 * self.reach)[:-1]))
            self._shift = np.repeat(start - low, n // self.blocks)
        self._tree = cKDTree(self._apart(q), balanced_tree=False, compact_nodes=False)
        i, j = sorted_pairs_of_tree(self._tree, self.r * (1.0 + 1e-9) if plain else self.reach,
                                    n)
        self._key = pair_keys(i, j)
        self._i, self._j = i, j
        self._last_search = self._calls
        if plain:
            self._ref = None
            self.plain_searches += 1
            return
        self._ref = q.copy()
        self._searched = np.zeros(n, dtype=bool)
        self.searches += 1

    def _apart(self, y: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Return positions (of agents ``rows``, default all) with the groups shifted apart.

        The shift is that of the last full search.
        """
        if rows is not None:
            y = y[rows]
        if self.blocks == 1:
            return y
        out = y.copy()
        out[:, 0] += self._shift if rows is None else self._shift[rows]
        return out

    def _refresh(self, q: np.ndarray, moved: np.ndarray, y: np.ndarray) -> None:
        """Search the candidates of the agents ``moved`` again, ``y`` the drifting positions.

        Agents not searched since the full search are in its tree within ``skin / 3`` of
        where they are now; the others are searched where they are now.
        """
        n, size = q.shape[0], q.shape[0] // self.blocks
        self._searched[moved] = True
        here = cKDTree(self._apart(y, moved), balanced_tree=False, compact_nodes=False)
        old = here.sparse_distance_matrix(self._tree, self.reach + self.skin / 3.0,
                                          output_type='ndarray')
        a, b = moved[old['i']], old['j']
        keep = ~self._searched[b]
        a, b = a[keep], b[keep]
        since = np.flatnonzero(self._searched)
        new = here.sparse_distance_matrix(
            cKDTree(self._apart(y, since), balanced_tree=False, compact_nodes=False),
            self.reach, output_type='ndarray')
        a = np.concatenate((a, moved[new['i']]))
        b = np.concatenate((b, since[new['j']]))
        # A straggler may leave its group's range in the shifted frame: drop other groups.
        keep = (a != b) & (a // size == b // size)
        lo, hi = np.minimum(a, b)[keep], np.maximum(a, b)[keep]
        # The old tree's wider reach finds more than the candidates: keep those within R.
        near = pair_sq_distances(q, lo, hi) <= self.reach * self.reach
        fresh = np.unique(pair_keys(lo[near], hi[near]))
        touched = np.zeros(n, dtype=bool)
        touched[moved] = True
        kept = self._key[~(touched[self._i] | touched[self._j])]
        # Both parts are sorted and disjoint: inserting one into the other merges them, in
        # half the time of a stable sort of both (measured on 52 000 keys: 270 vs 560 us).
        self._key = np.insert(kept, np.searchsorted(kept, fresh), fresh)
        self._i, self._j = pairs_of_keys(self._key)
        self._ref[moved] = y[moved]
        self.refreshes += 1


def within_radius(sq_dist: np.ndarray, r: float, strict: bool = True) -> np.ndarray:
    """Return whether squared distances are within ``r``: ``< r^2`` or ``<= r^2``.

    The single neighbourhood predicate of the package (simulator and agent node alike).

    :param sq_dist: squared Euclidean distances.
    :param r: the radius.
    :param strict: ``<`` (``True``) or ``<=``.
    :return: boolean array.
    """
    return sq_dist < r * r if strict else sq_dist <= r * r


def fixed_graph(adjacency: np.ndarray, coupling: float = 1.0) -> EdgeList:
    """Return the graph of a symmetric adjacency (or diffusive weight) matrix.

    Off-diagonal entries are the weights ``b_ij``; the diagonal is ignored (a diffusive matrix
    as in [Zhou12] Section 2.1 has ``b_ii = -sum_j b_ij``).

    :param adjacency: symmetric ``(n, n)`` matrix, non-negative off the diagonal.
    :param coupling: common factor ``w`` so that ``W = w B`` ([Zhou12] Section 4.2).
    :return: the edge list with weights ``w b_ij``.
    """
    a = np.asarray(adjacency, dtype=float)
    i, j = np.nonzero(np.triu(a, k=1))
    return EdgeList(a.shape[0], i.astype(np.intp), j.astype(np.intp), coupling * a[i, j])


def complete_graph(n: int) -> EdgeList:
    """Return the complete graph on ``n`` vertices with unit weights.

    :param n: number of vertices.
    :return: the edge list.
    """
    i, j = np.triu_indices(n, k=1)
    return EdgeList(n, i.astype(np.intp), j.astype(np.intp), np.ones(i.size))


def barabasi_albert(n: int, m0: int, m: int, rng: np.random.Generator) -> np.ndarray:
    """Return the 0/1 adjacency matrix of a Barabasi-Albert scale-free graph.

    Start from a complete graph on ``m0`` vertices; each new vertex attaches to ``m`` distinct
    existing vertices chosen with probability proportional to their degree (preferential
    attachment, [Zhou12] Section 5.2 with ``q0 = m0``, ``q = m``).

    :param n: number of vertices, ``n >= m0``.
    :param m0: size of the initial complete graph, ``m0 >= m``.
    :param m: edges added per new vertex, ``1 <= m <= m0``.
    :param rng: the random generator.
    :return: symmetric ``(n, n)`` 0/1 matrix with zero diagonal.
    """
    adj = np.zeros((n, n))
    adj[:m0, :m0] = 1.0
    np.fill_diagonal(adj, 0.0)
    # One entry per edge end: sampling uniformly from it is sampling proportionally to degree.
    ends = [v for v in range(m0) for _ in range(m0 - 1)]
    for new in range(m0, n):
        targets: set[int] = set()
        while len(targets) < m:
            # A single seed vertex has no edge ends yet: it is the only possible target.
            pick = ends[rng.integers(len(ends))] if ends else rng.integers(new)
            targets.add(int(pick))
        for t in sorted(targets):
            adj[new, t] = adj[t, new] = 1.0
            ends.extend((new, t))
    return adj


def diffusive_matrix(adjacency: np.ndarray) -> np.ndarray:
    """Return ``B`` with the off-diagonal of ``adjacency`` and ``b_ii = -sum_{j != i} b_ij``.

    [Zhou12] Section 2.1 (diffusive condition ``sum_j b_ij = 0``).

    :param adjacency: symmetric ``(n, n)`` matrix.
    :return: the diffusive matrix (``-`` the graph Laplacian).
    """
    b = np.array(adjacency, dtype=float)
    np.fill_diagonal(b, 0.0)
    np.fill_diagonal(b, -b.sum(axis=1))
    return b


def edges_to_adjacency(edges: EdgeList) -> np.ndarray:
    """Return the dense symmetric weight matrix of an edge list (small graphs only).

    :param edges: the graph.
    :return: ``(n, n)`` matrix.
    """
    a = np.zeros((edges.n, edges.n))
    a[edges.i, edges.j] = edges.weight
    a[edges.j, edges.i] = edges.weight
    return a


def components(edges: EdgeList) -> tuple[int, np.ndarray]:
    """Return the number of connected components and the label of every vertex.

    :param edges: the graph.
    :return: ``(count, labels)``.
    """
    if edges.n == 0:
        return 0, np.zeros(0, dtype=int)
    m = coo_matrix((np.ones(edges.size), (edges.i, edges.j)), shape=(edges.n, edges.n))
    count, labels = connected_components(m, directed=False)
    return int(count), labels


def degrees(edges: EdgeList) -> np.ndarray:
    """Return the (unweighted) degree of every vertex.

    :param edges: the graph.
    :return: integer array of length ``n``.
    """
    return (np.bincount(edges.i, minlength=edges.n)
            + np.bincount(edges.j, minlength=edges.n))
