"""Interaction graphs as edge lists: the r-disk graph, fixed graphs, Barabasi-Albert graphs.

An undirected graph on ``n`` vertices is held as two integer arrays ``i < j`` of equal length
(one entry per edge) and an optional weight per edge. No ``n x n`` matrix is built for the
r-disk graph: pairs come from a k-d tree (:class:`scipy.spatial.cKDTree`), so the cost of a
neighbour search is ``O(n log n + |E|)``.
"""

from dataclasses import dataclass

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
    # The tree proposes candidates with a margin; the decision is within_radius(), the one
    # predicate the agent node uses too, so both agree even for pairs exactly r apart.
    pairs = cKDTree(q).query_pairs(r * (1.0 + 1e-9), output_type='ndarray')
    if pairs.size:
        diff = q[pairs[:, 1]] - q[pairs[:, 0]]
        pairs = pairs[within_radius(np.einsum('ek,ek->e', diff, diff), r, strict)]
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    i = pairs[:, 0].astype(np.intp)
    j = pairs[:, 1].astype(np.intp)
    return EdgeList(n, i, j, np.ones(i.size))


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
