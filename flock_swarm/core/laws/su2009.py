"""Su, Wang, Lin 2009 (and Olfati-Saber 2006 Algorithm 2): protocols (7), (10), (33), V.C.

H. Su, X. Wang, Z. Lin, "Flocking of Multi-Agents With a Virtual Leader", IEEE TAC 54(2),
2009 ([Su09]); ``psi_alpha`` is Olfati-Saber's (IEEE TAC 51(3), 2006, [OS06]).
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.checks import choice, require
from flock_swarm.core.laws.base import Law
from flock_swarm.core.stability import consensus_bounds

#: The navigational feedbacks on the position error (:attr:`SuParams.navigation`).
NAVIGATION = ('linear', 'bounded')


@dataclass(frozen=True)
class SuParams(Law):
    """Parameters of the protocols of [Su09] (Olfati-Saber's ``psi_alpha`` of [OS06]).

    :ivar r: interaction radius ``r`` (Euclidean).
    :ivar d: desired distance ``d < r``.
    :ivar eps: sigma-norm parameter ``epsilon``.
    :ivar h: bump plateau of ``rho_h``, in ``(0, 1)``.
    :ivar a: attraction limit of ``phi`` (``0 < a <= b``).
    :ivar b: repulsion limit of ``phi``.
    :ivar c1: position navigation gain.
    :ivar c2: velocity navigation gain.
    :ivar navigation: the navigational feedback on the position error ``z = q_i - q_gamma``:
        ``linear``, ``-c1 z`` as printed in [Su09] eq. (7) and (10) (the default), or
        ``bounded``, ``-c1 sigma_1(z)`` with ``sigma_1(z) = z / sqrt(1 + ||z||^2)``, the
        gamma-agent's feedback of Olfati-Saber 2006 (IEEE TAC 51(3), Section VI), whose pull
        saturates at ``c1`` far from the leader.
    """

    r: float = 4.0
    d: float = 3.3
    eps: float = 0.1
    h: float = 0.2
    a: float = 5.0
    b: float = 5.0
    c1: float = 0.5
    c2: float = 0.5
    navigation: str = 'linear'

    #: The gradient and the velocity consensus are odd in (q_j - q_i, p_j - p_i).
    antisymmetric: ClassVar[bool] = True
    #: Whether only informed agents (``h_i = 1``) get navigational feedback.
    partial: ClassVar[bool] = False
    #: Whether the leader's acceleration ``f_gamma`` is fed forward.
    feedforward: ClassVar[bool] = False
    #: [Su09]'s protocols are Olfati-Saber's alpha + gamma terms (Algorithm 2); Algorithm 3
    #: adds the beta term of obstacles to the same alpha-agents (docs/obstacles.md).
    accepts_obstacles: ClassVar[bool] = True

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    @property
    def r_alpha(self) -> float:
        """Return ``r_alpha = ||r||_sigma``."""
        return float(pot.sigma_of_distance(self.r, self.eps))

    @property
    def d_alpha(self) -> float:
        """Return ``d_alpha = ||d||_sigma``."""
        return float(pot.sigma_of_distance(self.d, self.eps))

    @property
    def com_closed_form(self) -> bool:
        """Return whether the centre of mass obeys (45) exactly ([Su09] Theorem 2 (iii)).

        So it does under protocol (33): every agent informed, ``f_gamma`` fed forward, the
        linear navigational feedback.
        """
        return self.feedforward and not self.partial and self.navigation == 'linear'

    def validate(self, ctx):
        """Check ``0 < d < r``, ``eps > 0``, ``0 < h < 1``, ``0 < a <= b``, ``c1, c2 > 0``."""
        k = 'protocol.'
        require(self.r > 0, k + 'r', f'must be > 0, got {self.r}')
        require(0 < self.d < self.r, k + 'd', f'must satisfy 0 < d < r = {self.r}, got {self.d}')
        require(self.eps > 0, k + 'eps', f'must be > 0, got {self.eps}')
        require(0 < self.h < 1, k + 'h', f'must be in (0, 1), got {self.h}')
        require(self.a > 0, k + 'a', f'must be > 0, got {self.a}')
        require(self.b >= self.a, k + 'b', f'must be >= a = {self.a}, got {self.b}')
        require(self.c1 > 0, k + 'c1', f'must be > 0, got {self.c1}')
        require(self.c2 > 0, k + 'c2', f'must be > 0, got {self.c2}')
        choice(self.navigation, k + 'navigation', NAVIGATION)

    def pair(self, qi, pi, qj, pj, w):
        """Return ``phi_alpha(||q_j - q_i||_sigma) n_ij + a_ij (p_j - p_i)``.

        The gradient term ``-grad_{q_i} psi_alpha`` and velocity consensus of [Su09] eq. (7),
        with ``a_ij = rho_h(||q_j - q_i||_sigma / r_alpha)`` (eq. (8)) and
        ``n_ij = (q_j - q_i) / sqrt(1 + eps ||q_j - q_i||^2)``.
        """
        dq = qj - qi
        sq = pot.squared_norm(dq)
        # sqrt(1 + eps ||dq||^2) is shared by the sigma-norm and n_ij; the sigma-norm in the
        # cancellation-free form of pot.sigma_of_distance, from ||dq||^2 directly.
        root = np.sqrt(1.0 + self.eps * sq)
        z = sq / (root + 1.0)
        r_a, d_a = self.r_alpha, self.d_alpha
        # The bump of the action phi_alpha is a_ij: evaluated once for both terms.
        a_ij = pot.bump(z / r_a, self.h)
        # phi_alpha n_ij = (phi_alpha / root) dq: one scalar per edge, then per component.
        coef = pot.phi_alpha(z, r_a, d_a, self.h, self.a, self.b, a_ij)
        coef /= root
        out = np.empty_like(dq)
        for k in range(dq.shape[1]):
            np.multiply(dq[:, k], coef, out=out[:, k])
            out[:, k] += (pj[:, k] - pi[:, k]) * a_ij
        return out

    #: Whether ``f_gamma`` reaches the uninformed agents too (Section V.C's variant).
    feedforward_all: ClassVar[bool] = False

    def combine(self, q, p, s, leader, agents, dt, t=0.0):
        """Add the navigational feedback of [Su09] eq. (7), (10), (33) or Section V.C."""
        if leader is None:
            return s
        z = q - leader.q
        if self.navigation == 'bounded':
            z = z / np.sqrt(1.0 + np.einsum('nk,nk->n', z, z))[:, None]
        nav = -self.c1 * z - self.c2 * (p - leader.p)
        if self.feedforward and not self.feedforward_all:
            nav = nav + leader.a
        if self.partial:
            nav = agents.informed[:, None] * nav
        if self.feedforward_all:
            nav = nav + leader.a
        return s + nav

    def step_bounds(self, setup):
        """Bound ``dt`` by the PD feedback ``(c1, c2)`` plus the consensus Laplacian."""
        return consensus_bounds(setup, self.radius, self.c1, self.c2, 1.0, self.d)


@dataclass(frozen=True)
class OlfatiSaber2006(SuParams):
    """[Su09] eq. (7): Olfati-Saber's Algorithm 2, every agent informed."""

    name: ClassVar[str] = 'olfati_saber_2006'
    citation: ClassVar[str] = ('Su, Wang, Lin 2009, eq. (7): Olfati-Saber 2006 Algorithm 2, '
                               'every agent informed')


@dataclass(frozen=True)
class SuInformed(SuParams):
    """[Su09] eq. (10): navigational feedback only for informed agents (``h_i = 1``)."""

    name: ClassVar[str] = 'su_informed'
    citation: ClassVar[str] = 'Su, Wang, Lin 2009, eq. (10): only informed agents (h_i = 1)'
    partial: ClassVar[bool] = True


@dataclass(frozen=True)
class SuAccel(SuParams):
    """[Su09] eq. (33): every agent informed, leader acceleration ``f_gamma`` fed forward."""

    name: ClassVar[str] = 'su_accel'
    citation: ClassVar[str] = 'Su, Wang, Lin 2009, eq. (33): leader acceleration fed forward'
    feedforward: ClassVar[bool] = True


@dataclass(frozen=True)
class SuInformedAccel(SuParams):
    """[Su09] Section V.C: ``h_i [f_gamma + c1 (q_gamma - q_i) + c2 (p_gamma - p_i)]``.

    :ivar feedforward_to: who receives ``f_gamma``: ``informed``, as printed (``h_i``
        multiplies it, the default), or ``all``, the reading under which an accelerating
        leader changes nothing relative to Fig. 2 seen from the leader's frame:
        ``f_gamma + h_i [c1 (q_gamma - q_i) + c2 (p_gamma - p_i)]``.
    """

    name: ClassVar[str] = 'su_informed_accel'
    citation: ClassVar[str] = ('Su, Wang, Lin 2009, Section V.C: informed agents, '
                               'f_gamma fed forward')
    partial: ClassVar[bool] = True
    feedforward: ClassVar[bool] = True

    feedforward_to: str = 'informed'

    @property
    def feedforward_all(self) -> bool:
        """Return whether every agent receives ``f_gamma`` (``feedforward_to: all``)."""
        return self.feedforward_to == 'all'

    def validate(self, ctx):
        """Check the parameters of :class:`SuParams` and ``feedforward_to``."""
        super().validate(ctx)
        choice(self.feedforward_to, 'protocol.feedforward_to', ('informed', 'all'))
