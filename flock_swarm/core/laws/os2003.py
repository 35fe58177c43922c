"""Olfati-Saber 2003: the (alpha, alpha) protocol (22) with the sink PD term (40).

R. Olfati-Saber, "A Unified Analytical Look at Reynolds Flocking Rules", Caltech CDS, 2003
([OS03]).
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.checks import require
from flock_swarm.core.laws.base import Law
from flock_swarm.core.stability import consensus_bounds


@dataclass(frozen=True)
class OlfatiSaber2003Sink(Law):
    """[OS03] eq. (22) (the (alpha, alpha) protocol) plus the sink PD term eq. (40).

    :ivar d: desired distance ``d_alpha``.
    :ivar r: interaction radius ``r``.
    :ivar a: attraction limit of the penalty eq. (20), ``0 < a < b``.
    :ivar b: repulsion limit.
    :ivar delta: plateau of the influence map eq. (4).
    :ivar k: smoothness order of the influence map.
    :ivar c_d: velocity-matching (dissipation) gain of eq. (22).
    :ivar c1: sink position gain of eq. (40).
    :ivar c2: sink velocity gain of eq. (40).
    """

    name: ClassVar[str] = 'os2003_sink'
    citation: ClassVar[str] = 'Olfati-Saber 2003, eq. (22) + (40): (alpha, alpha) protocol, sink'
    #: The gradient and the velocity consensus are odd in (q_j - q_i, p_j - p_i).
    antisymmetric: ClassVar[bool] = True

    d: float = 7.0
    r: float = 8.4
    a: float = 1.0
    b: float = 5.0
    delta: float = 0.2
    k: int = 1
    c_d: float = 1.0
    c1: float = 0.1
    c2: float = 0.5

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def validate(self, ctx):
        """Check ``0 < d < r``, ``0 < a < b``, ``0 < delta < 1``, ``k >= 1``, positive gains."""
        k = 'protocol.'
        require(self.d > 0, k + 'd', f'must be > 0, got {self.d}')
        require(self.r > self.d, k + 'r', f'must be > d = {self.d}, got {self.r}')
        require(self.a > 0, k + 'a', f'must be > 0, got {self.a}')
        require(self.b > self.a, k + 'b', f'must be > a = {self.a} (eq. (20)), got {self.b}')
        require(0 < self.delta < 1, k + 'delta', f'must be in (0, 1), got {self.delta}')
        require(self.k >= 1, k + 'k', f'must be a positive integer, got {self.k}')
        for name in ('c_d', 'c1', 'c2'):
            value = getattr(self, name)
            require(value > 0, k + name, f'must be > 0, got {value}')

    def pair(self, qi, pi, qj, pj, w):
        """Return ``phi_alpha(||q_j - q_i|| - d_alpha) n_ij + c_d (p_j - p_i)`` ([OS03] (22)).

        ``n_ij`` is the unit vector from ``q_i`` to ``q_j`` (zero for coincident agents).
        """
        dq = qj - qi
        dist = np.sqrt(np.einsum('ek,ek->e', dq, dq))
        safe = np.where(dist > 0.0, dist, 1.0)
        unit = np.where(dist[:, None] > 0.0, dq / safe[:, None], 0.0)
        action = pot.os2003_action(dist - self.d, self.d, self.r, self.a, self.b,
                                   self.delta, self.k)
        return action[:, None] * unit + self.c_d * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt, t=0.0):
        """Add the sink PD term ``-c1 (q_i - q_d) - c2 (p_i - p_d)`` ([OS03] eq. (40))."""
        if leader is None:
            return s
        return s - self.c1 * (q - leader.q) - self.c2 * (p - leader.p)

    def step_bounds(self, setup):
        """Bound ``dt`` by the PD feedback ``(c1, c2)`` plus ``c_d`` times the Laplacian."""
        return consensus_bounds(setup, self.radius, self.c1, self.c2, self.c_d, self.d)
