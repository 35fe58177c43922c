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

from dataclasses import dataclass

import numpy as np

from flock_swarm.core.graphs import diffusive_matrix
from flock_swarm.core.scenario import Realization, Scenario

#: RK4 is stable for ``dt lambda`` in ``[-2.785, 0]`` on the real axis.
RK4_REAL_LIMIT = 2.78


@dataclass(frozen=True)
class StepViolation:
    """One violated bound: what it protects, the largest stable ``dt``, and why."""

    part: str
    dt_max: float
    detail: str

    def message(self, dt: float) -> str:
        """Return the one-line message for a run with step ``dt``."""
        return (f'dt: {dt:g} exceeds the stability bound {self.dt_max:.4g} of the '
                f'{self.part} ({self.detail}); use dt < {self.dt_max:.4g}')


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


def check_step(sc: Scenario, real: Realization) -> list[StepViolation]:
    """Return the bounds the scenario's ``dt`` violates (empty when it is fine).

    :param sc: the scenario.
    :param real: its realisation (fixed graphs, gains).
    :return: the violations.
    """
    law, dt = sc.law, sc.dt
    found: list[StepViolation] = []

    def pd(part: str, kp: float, kv: float, detail: str) -> None:
        bound = pd_dt_max(kp, kv)
        if dt >= bound:
            found.append(StepViolation(part, bound, detail))

    name = law.name
    if name in ('olfati_saber_2006', 'su_informed', 'su_accel', 'su_informed_accel',
                'os2003_sink', 'yu_pinning_observer'):
        spacing = law.d
        coupling = {'os2003_sink': 'c_d', 'yu_pinning_observer': 'c'}.get(name)
        coupling = getattr(law, coupling) if coupling else 1.0
        if real.adjacency is not None:
            lam = float(-np.linalg.eigvalsh(diffusive_matrix(real.adjacency))[0])
            source = 'fixed graph Laplacian'
        else:
            lam = 2.0 * packing_degree(law.radius, spacing, sc.dim)
            source = f'r-disk Laplacian <= {lam:g} for agents >= {spacing:.3g} apart'
        kp = getattr(law, 'c1', 0.0)
        kv = getattr(law, 'c2', 0.0)
        if name == 'yu_pinning_observer' and real.agents.nav_gains is not None:
            gains = real.agents.nav_gains
            kp = float(np.max(np.abs(np.linalg.eigvals(gains[:, 0])))) if gains.size else 0.0
            kv = float(np.max(np.abs(np.linalg.eigvals(gains[:, 1])))) if gains.size else 0.0
        pd('navigation feedback', kp, kv, f'k_p = {kp:g}, k_v = {kv:g}')
        pd('velocity consensus', kp, kv + coupling * lam,
           f'k_v = {kv:g} + {coupling:g} x {source}')
    elif name == 'zhou_pseudo_leader':
        weights = real.adjacency
        if weights is not None:
            gain = np.where(real.agents.informed, law.h0, 0.0)
            lam = float(-np.linalg.eigvalsh(diffusive_matrix(weights) - np.diag(gain))[0])
            bound = 2.0 / lam if lam > 0 else float('inf')
            if dt >= bound:
                found.append(StepViolation(
                    'velocity coupling', bound,
                    f'|lambda_min(W - H)| = {lam:.4g} with W = {law.w:g} B; the explicit '
                    'update v += dt (W - H) v needs dt < 2 / |lambda_min|'))
    for part, spec, p0 in (('leader model', sc.leader.field, sc.leader.velocity),
                           ('intrinsic dynamics', sc.intrinsic, sc.leader.velocity)):
        if spec is None or spec.kind in ('zero', 'constant'):
            continue
        rate = max(float(np.max(np.abs(np.linalg.eigvals(spec.jacobian(x)))))
                   for x in (np.asarray(p0, dtype=float), np.zeros(sc.dim)))
        bound = RK4_REAL_LIMIT / rate if rate > 0 else float('inf')
        if dt >= bound:
            found.append(StepViolation(part, bound,
                                       f'RK4 with spectral radius {rate:.4g} of the Jacobian'))
    return found
