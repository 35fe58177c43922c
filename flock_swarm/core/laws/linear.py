"""Second-order linear consensus with a virtual leader: the textbook baseline.

W. Ren, R. W. Beard, "Distributed Consensus in Multi-vehicle Cooperative Control",
Springer 2008, Ch. 4 ([RB08]); R. Olfati-Saber, R. M. Murray, "Consensus Problems in
Networks of Agents With Switching Topology and Time-Delays", IEEE TAC 49(9), 2004 ([OSM04],
the delay analysis the network oracle of ``test/test_network.py`` follows).
"""

from dataclasses import dataclass
from typing import ClassVar

from flock_swarm.core.checks import require
from flock_swarm.core.laws.base import Law


@dataclass(frozen=True)
class LinearConsensus(Law):
    """[RB08] Sec. 4.2: ``u_i = -sum_j a_ij [k_p (q_i - q_j) + k_v (p_i - p_j)]`` + leader.

    The informed agents add the navigational feedback ``-c1 (q_i - q_l) - c2 (p_i - p_l)
    + f_l`` towards the virtual leader ``(q_l, p_l, f_l)`` ([RB08] Sec. 4.3, consensus
    tracking with a reference). The weights ``a_ij`` are those of a fixed graph, or 1 within
    the radius ``r`` of an r-disk graph. Linear, so a fixed connected undirected graph's
    disagreement modes obey ``s^2 + lambda (k_v s + k_p) = 0`` for each Laplacian eigenvalue
    ``lambda``, and ``s^2 + lambda (k_v s + k_p) exp(-s tau)`` under an input delay ``tau``
    ([OSM04] Sec. VIII): the analytic oracle of the network model.

    :ivar k_p: relative position gain.
    :ivar k_v: relative velocity gain.
    :ivar c1: navigational position gain of the informed agents.
    :ivar c2: navigational velocity gain of the informed agents.
    :ivar r: radius of the r-disk graph.
    """

    name: ClassVar[str] = 'linear_consensus'
    citation: ClassVar[str] = ('Ren & Beard 2008, Sec. 4.2-4.3: second-order linear consensus '
                               'with a virtual leader')
    graph_types: ClassVar[tuple[str, ...]] = ('disk', 'fixed')
    #: ``a_ij = a_ji`` and the differences change sign: each pair is evaluated once.
    antisymmetric: ClassVar[bool] = True

    k_p: float = 1.0
    k_v: float = 1.0
    c1: float = 0.5
    c2: float = 1.0
    r: float = 5.0

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def validate(self, ctx):
        """Check non-negative gains and ``r > 0``."""
        for name in ('k_p', 'k_v', 'c1', 'c2'):
            value = getattr(self, name)
            require(value >= 0, f'protocol.{name}', f'must be >= 0, got {value}')
        require(self.r > 0, 'protocol.r', f'must be > 0, got {self.r}')

    def pair(self, qi, pi, qj, pj, w):
        """Return ``a_ij [k_p (q_j - q_i) + k_v (p_j - p_i)]``."""
        return w[:, None] * (self.k_p * (qj - qi) + self.k_v * (pj - pi))

    def combine(self, q, p, s, leader, agents, dt, t=0.0):
        """Add ``-c1 (q_i - q_l) - c2 (p_i - p_l) + f_l`` for the informed agents."""
        if leader is None:
            return s
        nav = leader.a - self.c1 * (q - leader.q) - self.c2 * (p - leader.p)
        return s + agents.informed[:, None] * nav
