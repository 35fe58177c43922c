"""Yu, Chen, Cao 2010: pinning observer-based navigation feedback, control (3) with (7).

W. Yu, G. Chen, M. Cao, "Distributed leader-follower flocking control for multi-agent
dynamical systems with time-varying velocities", Systems & Control Letters 59, 2010
([Yu10]).
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.checks import require
from flock_swarm.core.laws.base import Law
from flock_swarm.core.stability import consensus_bounds


@dataclass(frozen=True)
class YuPinningObserver(Law):
    """[Yu10] eq. (3), (7), (36): pair force, velocity consensus, partial observations.

    The intrinsic term ``f(r_i, v_i)`` of eq. (3) is the scenario's ``intrinsic`` field,
    integrated by the world; the per-agent gains ``D_i H_i`` and ``D~_i H~_i`` come from the
    scenario's ``observers`` (:class:`AgentData` data ``'nav_gains'``, shape
    ``(n, 2, dim, dim)``).

    :ivar a: attraction gain of the pair force.
    :ivar b: repulsion gain (``b > a``).
    :ivar c_bar: repulsion width ``c_bar``.
    :ivar r_s: interaction range (neighbours ``||r_j - r_i|| <= r_s``).
    :ivar c: velocity coupling strength.
    """

    name: ClassVar[str] = 'yu_pinning_observer'
    #: The gradient and the velocity consensus are odd in (q_j - q_i, p_j - p_i).
    antisymmetric: ClassVar[bool] = True
    citation: ClassVar[str] = ('Yu, Chen, Cao 2010, eq. (3) + (7): pinning observer-based '
                               'navigation feedback')
    strict_radius: ClassVar[bool] = False
    uses_observers: ClassVar[bool] = True

    a: float = 1.0
    b: float = 20.0
    c_bar: float = 0.2
    r_s: float = 1.0
    c: float = 5.0

    @property
    def radius(self) -> float:
        """Return ``r_s``."""
        return self.r_s

    @property
    def d(self) -> float:
        """Return the equilibrium distance ``sqrt(c_bar ln(b / a))``."""
        return float(np.sqrt(self.c_bar * np.log(self.b / self.a)))

    def validate(self, ctx):
        """Check positive ``a, c_bar, r_s``, ``b > a`` and ``c >= 0``."""
        k = 'protocol.'
        for name in ('a', 'c_bar', 'r_s'):
            value = getattr(self, name)
            require(value > 0, k + name, f'must be > 0, got {value}')
        require(self.b > self.a, k + 'b', f'must be > a = {self.a}, got {self.b}')
        require(self.c >= 0, k + 'c', f'must be >= 0, got {self.c}')

    def pair(self, qi, pi, qj, pj, w):
        """Return ``[a - b exp(-||r_ij||^2 / c_bar)] (r_j - r_i) + c (v_j - v_i)``."""
        dq = qj - qi
        dist = np.sqrt(np.einsum('ek,ek->e', dq, dq))
        return pot.yu_pair_gain(dist, self.a, self.b, self.c_bar)[:, None] * dq \
            + self.c * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt, t=0.0):
        """Add ``-D_i H_i (r_i - r_o) - D~_i H~_i (v_i - v_o)`` ([Yu10] eq. (7))."""
        gains = agents.data.get('nav_gains')
        if gains is None or leader is None:
            return s
        pos = np.einsum('nab,nb->na', gains[:, 0], q - leader.q)
        vel = np.einsum('nab,nb->na', gains[:, 1], p - leader.p)
        return s - pos - vel

    def agent_data(self, setup):
        """Return ``'nav_gains'``: ``D_i H_i`` and ``D~_i H~_i`` of each observer group."""
        if not setup.observers:
            return {}
        gains = np.zeros((setup.n_agents, 2, setup.dim, setup.dim))
        for group in setup.observers:
            for i in group.ids:
                gains[i, 0] = group.pos_gain
                gains[i, 1] = group.vel_gain
        return {'nav_gains': gains}

    def step_bounds(self, setup):
        """Bound ``dt`` by the observers' gains plus ``c`` times the consensus Laplacian."""
        kp = kv = 0.0
        gains = self.agent_data(setup).get('nav_gains')
        if gains is not None and gains.size:
            kp = float(np.max(np.abs(np.linalg.eigvals(gains[:, 0]))))
            kv = float(np.max(np.abs(np.linalg.eigvals(gains[:, 1]))))
        return consensus_bounds(setup, self.radius, kp, kv, self.c, self.d)
