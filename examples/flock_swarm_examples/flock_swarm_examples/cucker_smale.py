"""Cucker-Smale flocking behind a virtual leader: a law that is not in flock_swarm's papers.

F. Cucker, S. Smale, "Emergent behavior in flocks", IEEE TAC 52(5), 2007 ([CS07]), eq. (1):
every agent adjusts its velocity towards its neighbours' with the weight

    a_ij = psi(||q_j - q_i||),   psi(r) = K / (1 + r^2)^beta,

so ``u_i = sum_j a_ij (p_j - p_i)``. The exact double-integrator step of flock_swarm
(``p += u dt``) is then [CS07]'s discrete-time update with ``h = dt``. Two choices of this
example: the sum runs over the r-disk neighbours (``||q_j - q_i|| < r``) instead of all
agents, and informed agents add the leader-tracking feedback ``-c1 (q_i - q_gamma)
- c2 (p_i - p_gamma)`` of Su, Wang, Lin 2009 eq. (10).
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import Law, LawContext, LawSetup, StepViolation, pd_dt_max, require


@dataclass(frozen=True)
class CuckerSmale(Law):
    """Cucker-Smale velocity alignment with a virtual leader for the informed agents.

    :ivar r: interaction radius [m] of the r-disk graph.
    :ivar K: coupling strength of ``psi`` [1/s].
    :ivar beta: decay exponent of ``psi`` (unconditional flocking for ``beta < 1/2``,
        [CS07] Theorem 1, when every pair interacts).
    :ivar c1: position gain of the leader tracking [1/s^2].
    :ivar c2: velocity gain of the leader tracking [1/s].
    """

    name: ClassVar[str] = 'cucker_smale'
    citation: ClassVar[str] = ('Cucker, Smale 2007, IEEE TAC 52(5), eq. (1), '
                               'psi(r) = K/(1+r^2)^beta, plus leader tracking')
    antisymmetric: ClassVar[bool] = True
    strict_radius: ClassVar[bool] = True

    r: float = 4.0
    K: float = 1.0
    beta: float = 0.25
    c1: float = 0.5
    c2: float = 0.5

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def validate(self, ctx: LawContext) -> None:
        """Check ``r > 0``, ``K > 0``, ``beta >= 0`` and ``c1, c2 >= 0``."""
        require(self.r > 0, 'protocol.r', f'must be > 0, got {self.r}')
        require(self.K > 0, 'protocol.K', f'must be > 0, got {self.K}')
        require(self.beta >= 0, 'protocol.beta', f'must be >= 0, got {self.beta}')
        require(self.c1 >= 0, 'protocol.c1', f'must be >= 0, got {self.c1}')
        require(self.c2 >= 0, 'protocol.c2', f'must be >= 0, got {self.c2}')

    def step_bounds(self, setup: LawSetup) -> list[StepViolation]:
        """Bound ``dt`` by the leader tracking of an informed agent without neighbours.

        Such an agent is the PD loop ``-c1 x - c2 x'`` under the zero-order hold of each
        step, stable only for ``dt < min(2 c2 / c1, 2 / c2)`` (:func:`pd_dt_max`); the
        alignment term only adds damping, which the bound leaves out (a necessary bound).
        """
        if not setup.informed.any():
            return []
        bound = pd_dt_max(self.c1, self.c2)
        if setup.dt < bound:
            return []
        return [StepViolation('leader tracking', bound, f'c1 = {self.c1:g}, c2 = {self.c2:g}')]

    def psi(self, squared_distance: np.ndarray) -> np.ndarray:
        """Return ``psi = K / (1 + r^2)^beta`` from ``r^2`` ([CS07] eq. (1))."""
        return self.K * (1.0 + squared_distance) ** -self.beta

    def pair(self, qi: np.ndarray, pi: np.ndarray, qj: np.ndarray, pj: np.ndarray,
             w: np.ndarray) -> np.ndarray:
        """Return ``w_ij psi(||q_j - q_i||) (p_j - p_i)`` for each directed edge ``j -> i``.

        Antisymmetric: ``psi`` depends on the distance only and ``p_j - p_i`` changes sign.
        """
        dq = qj - qi
        weight = w * self.psi(np.einsum('ek,ek->e', dq, dq))
        return weight[:, None] * (pj - pi)

    def combine(self, q: np.ndarray, p: np.ndarray, s: np.ndarray, leader,
                agents, dt: float, t: float) -> np.ndarray:
        """Return the alignment sums plus the informed agents' leader tracking.

        Without the leader's state (``leader is None``: lost) every agent aligns only. The
        law does not depend on the time ``t`` of the step.
        """
        if leader is None:
            return s
        track = -self.c1 * (q - leader.q) - self.c2 * (p - leader.p)
        return s + agents.informed[:, None] * track
