"""Flocking metrics: one definition, used by the simulator, the world node and ``analyze``.

``eta`` is the fraction of agents moving with the desired velocity ([Su09] Section V.A):
``||p_i - p_gamma|| <= eta_tolerance``.
"""

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from flock_swarm.core import potentials as pot
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.graphs import EdgeList, components, disk_graph, pair_sq_distances

#: The names of the per-step metrics, in the order of :func:`step_metrics`.
STEP_METRICS = ('eta', 'velocity_mismatch_max', 'com_position_error', 'com_velocity_error',
                'min_pair_distance', 'components')


def step_metrics(q: np.ndarray, p: np.ndarray, leader: LeaderState, eta_tolerance: float,
                 radius: float, strict: bool = True) -> dict[str, float]:
    """Return the metrics of one instant.

    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param leader: the virtual leader.
    :param eta_tolerance: velocity tolerance of ``eta``.
    :param radius: radius of the r-disk graph whose components are counted.
    :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
    :return: a dict with the keys of :data:`STEP_METRICS`.
    """
    mismatch = np.linalg.norm(p - leader.p, axis=1)
    count, _ = components(disk_graph(q, radius, strict))
    return {
        'eta': float(np.mean(mismatch <= eta_tolerance)),
        'velocity_mismatch_max': float(mismatch.max()),
        'com_position_error': float(np.linalg.norm(q.mean(axis=0) - leader.q)),
        'com_velocity_error': float(np.linalg.norm(p.mean(axis=0) - leader.p)),
        'min_pair_distance': min_pair_distance(q),
        'components': float(count),
    }


def min_pair_distance(q: np.ndarray) -> float:
    """Return the smallest distance between two agents (``inf`` for fewer than two).

    :param q: positions, shape ``(n, dim)``.
    :return: the distance.
    """
    if q.shape[0] < 2:
        return float('inf')
    dist, _ = cKDTree(q).query(q, k=2)
    return float(dist[:, 1].min())


def close_pairs(q: np.ndarray, distance: float) -> set[tuple[int, int]]:
    """Return the pairs ``(i, j)``, ``i < j``, closer than ``distance``.

    :param q: positions, shape ``(n, dim)``.
    :param distance: the collision distance.
    :return: the set of pairs.
    """
    edges = disk_graph(q, distance, strict=True)
    return set(zip(edges.i.tolist(), edges.j.tolist()))


@dataclass
class RunMetrics:
    """Whole-run metrics, accumulated step by step.

    :ivar collision_distance: pairs closer than this count as colliding.
    """

    collision_distance: float
    min_pair_distance: float = float('inf')
    collision_pairs: set = field(default_factory=set)
    #: The agent-obstacle metrics (:class:`flock_swarm.core.obstacles.ObstacleMetrics`) of a
    #: run with obstacles, ``None`` without.
    obstacles: Any = None
    #: Keys ``i n + j`` of the pairs close at the previous call of :meth:`add_collisions`.
    _recent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                                repr=False, compare=False)

    def add_collisions(self, i: np.ndarray, j: np.ndarray, n: int) -> None:
        """Add the close pairs ``(i[k], j[k])`` of one instant (sorted, ``i < j < n``).

        Colliding pairs mostly stay close for many steps: only the pairs not already close
        at the previous call go through the set.
        """
        key = i.astype(np.int64) * n + j
        # Both key arrays are sorted: a binary search tells which keys are new.
        at = np.minimum(np.searchsorted(self._recent, key), max(self._recent.size - 1, 0))
        new = self._recent[at] != key if self._recent.size else np.ones(key.size, dtype=bool)
        self._recent = key
        if new.any():
            self.collision_pairs.update(zip(i[new].tolist(), j[new].tolist()))

    def update(self, q: np.ndarray, step_min_distance: float) -> None:
        """Fold in one instant."""
        self.min_pair_distance = min(self.min_pair_distance, step_min_distance)
        if step_min_distance < self.collision_distance:
            self.collision_pairs |= close_pairs(q, self.collision_distance)

    def update_from_edges(self, q: np.ndarray, edges: EdgeList, radius: float) -> None:
        """Fold in one instant from the interaction edges already computed for the step.

        Pairs closer than ``collision_distance`` are among the r-disk edges whenever
        ``collision_distance <= radius``, so no second neighbour search is needed; the minimum
        distance is exact whenever it is below ``radius`` (otherwise the pairs are farther
        apart than ``radius`` and the recorded instants give it).

        :param q: positions.
        :param edges: the step's r-disk (or denser) graph.
        :param radius: the radius the edges cover completely.
        """
        update_stacked_from_edges([self], q, edges, radius)


def update_stacked_from_edges(runs: list[RunMetrics], q: np.ndarray, edges: EdgeList,
                              radius: float, sq_dist: np.ndarray | None = None) -> None:
    """Fold one instant of a stack of independent swarms into the metrics of each.

    The stack holds ``len(runs)`` swarms of equal size, agents ``g m .. (g + 1) m - 1`` being
    swarm ``g`` (ids within a swarm in the metrics), and no edge links two swarms; each swarm
    gets exactly what :meth:`RunMetrics.update_from_edges` would give it alone.

    :param runs: the whole-run metrics of each swarm (the same ``collision_distance``).
    :param q: positions of the stack, shape ``(len(runs) m, dim)``.
    :param edges: the step's graph of the stack, sorted by ``(i, j)``.
    :param radius: the radius the edges cover completely.
    :param sq_dist: the squared lengths of the edges when the caller has them (as
        :func:`~flock_swarm.core.graphs.pair_sq_distances` gives them), else ``None``.
    """
    if edges.size == 0:
        return
    size = q.shape[0] // len(runs)
    sq = pair_sq_distances(q, edges.i, edges.j) if sq_dist is None else sq_dist
    # Edges are sorted by i, so each swarm's edges are one contiguous run.
    bounds = np.searchsorted(edges.i, np.arange(len(runs) + 1) * size)
    linked = np.flatnonzero(bounds[1:] > bounds[:-1])
    # sqrt is monotonic and correctly rounded: the root of the least square is the least root.
    lows = np.sqrt(np.minimum.reduceat(sq, bounds[linked])).tolist()
    for g, low in zip(linked.tolist(), lows):
        runs[g].min_pair_distance = min(runs[g].min_pair_distance, low)
    collision_distance = runs[0].collision_distance
    if collision_distance > radius:
        for g, low in zip(linked.tolist(), lows):
            lo = g * size
            runs[g].update(q[lo:lo + size], low)
        return
    # Roots only of the few squares near the collision distance.
    near = np.flatnonzero(sq < (collision_distance * (1.0 + 1e-6)) ** 2)
    close = near[np.sqrt(sq[near]) < collision_distance]
    if close.size:
        group = edges.i[close] // size
        for g in np.unique(group).tolist():
            pick = close[group == g]
            runs[g].add_collisions(edges.i[pick] - g * size, edges.j[pick] - g * size, size)


def su_energy(q: np.ndarray, p: np.ndarray, leader: LeaderState, law, informed: np.ndarray,
              c1: float) -> float:
    """Return the energy ``Q`` of [Su09] eq. (12)-(13) (eq. (34)-(35) when all are informed).

    ``Q = 1/2 sum_i [sum_{j != i} psi_alpha(||q_ij||_sigma) + h_i c1 ||q_i - q_gamma||^2
    + ||p_i - p_gamma||^2]``, over all pairs (``O(n^2)``: for tests and small swarms).

    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param leader: the virtual leader.
    :param law: a :class:`~flock_swarm.core.laws.su2009.SuParams` law.
    :param informed: ``h_i`` as booleans.
    :param c1: the position gain.
    :return: ``Q``.
    """
    n = q.shape[0]
    i, j = np.triu_indices(n, k=1)
    z = pot.sigma_norm(q[j] - q[i], law.eps)
    pair_energy = pot.psi_alpha(z, law.r_alpha, law.d_alpha, law.h, law.a, law.b).sum()
    dq = q - leader.q
    dp = p - leader.p
    nav = c1 * np.einsum('nk,nk->n', dq, dq) * informed
    # Each unordered pair appears twice in sum_i sum_{j != i}; the 1/2 of Q cancels that.
    return float(pair_energy + 0.5 * nav.sum() + 0.5 * np.einsum('nk,nk->', dp, dp))
