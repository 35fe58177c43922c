"""Zhou, Wu, Yu, Small, Lu 2012: flocking with adaptive pseudo-leaders, control (4).

J. Zhou, X. Wu, W. Yu, M. Small, J. Lu, "Flocking of multi-agent dynamical systems based on
pseudo-leader mechanism", Systems & Control Letters 61, 2012 ([Zhou12]).
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.checks import require
from flock_swarm.core.graphs import diffusive_matrix
from flock_swarm.core.laws.base import Law, StepViolation


@dataclass(frozen=True)
class ZhouPseudoLeader(Law):
    """[Zhou12] eq. (4): diffusive velocity coupling, APF gradient, adaptive pseudo-leaders.

    The APF acts between *all* pairs (eq. (4) sums ``j != i`` and the Lyapunov function of
    Theorem 1 sums every pair); the velocity coupling uses the weights ``w_ij`` of the graph.
    The adaptive gains ``h_i`` are the state ``'h'`` of :class:`AgentData`.

    :ivar sigma: sigma-norm parameter.
    :ivar c1: APF attraction weight of eq. (3).
    :ivar c2: APF repulsion weight of eq. (3).
    :ivar w: common coupling weight, ``W = w B`` (Section 4.2).
    :ivar k: adaptation rate ``k_i`` of ``h_i' = k_i ||v_i - v_l||^2``.
    :ivar h0: initial adaptive gain ``h_i(0)``.
    :ivar alpha: constant of Assumption A1 of the intrinsic dynamics (pseudo-leader choice).
    :ivar r: radius of the r-disk graph when the scenario uses one (Section 4.4).
    """

    name: ClassVar[str] = 'zhou_pseudo_leader'
    citation: ClassVar[str] = ('Zhou, Wu, Yu, Small, Lu 2012, eq. (4): adaptive pseudo-leaders, '
                               'Theorems 1-2')
    all_pairs: ClassVar[bool] = True
    #: The gradient and the velocity consensus are odd in (q_j - q_i, p_j - p_i).
    antisymmetric: ClassVar[bool] = True
    state_summary: ClassVar[dict[str, str]] = {'h': 'adaptive_gain_final'}

    sigma: float = 0.1
    c1: float = 0.5
    c2: float = 0.5
    w: float = 70.0
    k: float = 0.01
    h0: float = 1.0
    alpha: float = 60.3402
    r: float = 4.0

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    @property
    def coupling_weight(self) -> float:
        """Return ``w``: the weights of a fixed graph are ``W = w B``."""
        return self.w

    def validate(self, ctx):
        """Check positive ``sigma, c1, c2, w, k, r`` and non-negative ``h0, alpha``."""
        k = 'protocol.'
        for name in ('sigma', 'c1', 'c2', 'w', 'k', 'r'):
            value = getattr(self, name)
            require(value > 0, k + name, f'must be > 0, got {value}')
        require(self.h0 >= 0, k + 'h0', f'must be >= 0, got {self.h0}')
        require(self.alpha >= 0, k + 'alpha', f'must be >= 0, got {self.alpha}')

    def pair(self, qi, pi, qj, pj, w):
        """Return ``V'(s) n_ij + w_ij (p_j - p_i)`` with ``s = ||p_j - p_i||_sigma``.

        ``-grad_{p_i} V_ij = V'(s) (p_j - p_i) / sqrt(1 + sigma ||p_j - p_i||^2)`` for the APF
        of eq. (3); ``w_ij`` is the (already scaled) coupling weight of the edge.
        """
        dq = qj - qi
        s = pot.sigma_norm(dq, self.sigma)
        gradient = pot.zhou_potential_derivative(s, self.c1, self.c2)[:, None] \
            * pot.sigma_grad(dq, self.sigma)
        return gradient + w[:, None] * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt, t=0.0):
        """Add ``u3 = -h_i (v_i - v_l)`` for pseudo-leaders ([Zhou12] eq. (4))."""
        if leader is None:
            return s
        gain = np.where(agents.informed, agents.state['h'], 0.0)
        return s - gain[:, None] * (p - leader.p)

    def initial_state(self, n):
        """Return ``h_i(0) = h0`` for every agent."""
        return {'h': np.full(n, self.h0)}

    def state_rate(self, q, p, leader, agents, s=None, t=0.0):
        """Return ``h_i' = k ||v_i - v_l||^2`` for pseudo-leaders, ``0`` otherwise."""
        if leader is None:
            return {'h': np.zeros(q.shape[0])}
        err = p - leader.p
        return {'h': np.where(agents.informed, self.k * np.einsum('nk,nk->n', err, err), 0.0)}

    def pseudo_leader_gains(self):
        """Return ``(w, alpha)`` of Theorem 1."""
        return self.w, self.alpha

    def step_bounds(self, setup):
        """Bound ``dt`` by the spectrum of ``W - H`` on a fixed graph (explicit update)."""
        if setup.adjacency is None:
            return []
        weights = setup.adjacency * self.coupling_weight
        gain = np.where(setup.informed, self.h0, 0.0)
        lam = float(-np.linalg.eigvalsh(diffusive_matrix(weights) - np.diag(gain))[0])
        bound = 2.0 / lam if lam > 0 else float('inf')
        if setup.dt < bound:
            return []
        return [StepViolation(
            'velocity coupling', bound,
            f'|lambda_min(W - H)| = {lam:.4g} with W = {self.w:g} B; the explicit '
            'update v += dt (W - H) v needs dt < 2 / |lambda_min|')]
