"""Step-size check: flag a ``dt`` too large for a scenario's gains before the run starts.

The control input is held over each step (zero-order hold), so its linear parts behave like
explicit integrators and diverge when ``dt`` is too large:

- navigational PD feedback ``-k_p x - k_v x'`` under a zero-order hold: the exact discrete map
  ``[[1 - k_p dt^2/2, dt - k_v dt^2/2], [-k_p dt, 1 - k_v dt]]`` must have spectral radius
  ``< 1``, which holds exactly for ``dt < min(2 k_v / k_p, 2 / k_v)`` (Jury's criterion);
  the velocity gain includes the consensus Laplacian, bounded by ``2 deg_max`` times the
  largest edge weight, with ``deg_max`` from a packing bound for r-disk graphs (agents
  at least ``d`` apart within a ball of radius ``r``) or the exact spectrum for fixed graphs;
- the leader's (and intrinsic) nonlinear fields under RK4: ``dt max|lambda(J)| < 2.78``
  (RK4's stability interval on the negative real axis), with ``J`` the Jacobian at the
  leader's initial velocity and at rest.

The gradient (spring) terms are not checked: their stiffness depends on the configuration.
"""

import numpy as np

from flock_swarm.core.graphs import diffusive_matrix
from flock_swarm.core.laws.base import LawSetup, StepViolation
from flock_swarm.core.leaders.base import LeaderModel

#: RK4 is stable for ``dt lambda`` in ``[-2.785, 0]`` on the real axis.
RK4_REAL_LIMIT = 2.78

__all__ = ['RK4_REAL_LIMIT', 'StepViolation', 'consensus_bounds', 'model_bounds',
           'packing_degree', 'pd_dt_max', 'pd_stable']


def pd_stable(kp: float, kv: float, dt: float) -> bool:
    """Return whether ``x'' = -kp x - kv x'`` under a zero-order hold is stable at ``dt``."""
    m = np.array([[1.0 - 0.5 * kp * dt * dt, dt - 0.5 * kv * dt * dt],
                  [-kp * dt, 1.0 - kv * dt]])
    return float(np.max(np.abs(np.linalg.eigvals(m)))) < 1.0 + 1e-12


def pd_dt_max(kp: float, kv: float) -> float:
    """Return the largest stable ``dt`` of :func:`pd_stable`: ``min(2 kv / kp, 2 / kv)``.

    Jury's criterion on the map of :func:`pd_stable`: ``det = 1 - kv dt + kp dt^2 / 2 < 1``
    gives ``dt < 2 kv / kp``; ``1 + det + trace = 4 - 2 kv dt > 0`` gives ``dt < 2 / kv``;
    ``1 + det > |trace|`` holds for every ``dt > 0``. Without damping (``kv = 0 < kp``) no
    step is stable.
    """
    if kv <= 0.0:
        return 0.0 if kp > 0.0 else float('inf')
    return min(2.0 * kv / kp if kp > 0.0 else float('inf'), 2.0 / kv)


def packing_degree(r: float, spacing: float, dim: int) -> int:
    """Return an upper bound on the neighbours within ``r`` of agents at least ``spacing`` apart.

    Balls of radius ``spacing / 2`` around the neighbours are disjoint and fit in the ball of
    radius ``r + spacing / 2``; the agent itself takes one of them.
    """
    return max(int(((r + 0.5 * spacing) / (0.5 * spacing)) ** dim) - 1, 1)


def consensus_bounds(setup: LawSetup, radius: float, kp: float, kv: float,
                     coupling: float, spacing: float) -> list[StepViolation]:
    """Return the violated bounds of a PD navigation term plus velocity consensus.

    The consensus Laplacian is bounded by its exact spectrum on a fixed graph, or on an
    r-disk graph by ``2 deg_max`` with ``deg_max`` from :func:`packing_degree` for agents at
    least ``spacing`` apart.

    :param setup: the run (its ``dt``, dimension and fixed graph, if any).
    :param radius: the law's interaction radius (of the r-disk graph).
    :param kp: the position gain of the navigation term.
    :param kv: its velocity gain.
    :param coupling: the gain of the velocity consensus term.
    :param spacing: the law's desired distance between neighbours.
    :return: the violations (empty when ``dt`` is fine).
    """
    if setup.adjacency is not None:
        lam = float(-np.linalg.eigvalsh(diffusive_matrix(setup.adjacency))[0])
        source = 'fixed graph Laplacian'
    else:
        lam = 2.0 * packing_degree(radius, spacing, setup.dim)
        source = f'r-disk Laplacian <= {lam:g} for agents >= {spacing:.3g} apart'
    found = []
    for part, kv_total, detail in (
            ('navigation feedback', kv, f'k_p = {kp:g}, k_v = {kv:g}'),
            ('velocity consensus', kv + coupling * lam,
             f'k_v = {kv:g} + {coupling:g} x {source}')):
        bound = pd_dt_max(kp, kv_total)
        if setup.dt >= bound:
            found.append(StepViolation(part, bound, detail))
    return found


def model_bounds(part: str, model: LeaderModel | None, p0: np.ndarray, dim: int,
                 dt: float) -> list[StepViolation]:
    """Return RK4's violated bound for a leader model (or the intrinsic dynamics) at ``dt``.

    ``dt max|lambda(J)| < 2.78`` with ``J`` the model's Jacobian at the velocity ``p0`` and at
    rest; nothing for a model without a Jacobian.

    :param part: what the model is, for the message (``leader model``...).
    :param model: the model, or ``None`` (nothing to check).
    :param p0: the leader's initial velocity.
    :param dim: the dimension.
    :param dt: the step.
    :return: the violation, if any.
    """
    if model is None:
        return []
    points = (np.asarray(p0, dtype=float), np.zeros(dim))
    jacobians = [model.jacobian(x) for x in points]
    if any(j is None for j in jacobians):
        return []
    rate = max(float(np.max(np.abs(np.linalg.eigvals(j)))) for j in jacobians)
    bound = RK4_REAL_LIMIT / rate if rate > 0 else float('inf')
    if dt >= bound:
        return [StepViolation(part, bound, f'RK4 with spectral radius {rate:.4g} of the Jacobian')]
    return []
