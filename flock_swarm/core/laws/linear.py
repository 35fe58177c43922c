"""Second-order linear consensus with a virtual leader: the textbook baseline.

W. Ren, R. W. Beard, "Distributed Consensus in Multi-vehicle Cooperative Control",
Springer 2008, Ch. 4 ([RB08]); R. Olfati-Saber, R. M. Murray, "Consensus Problems in
Networks of Agents With Switching Topology and Time-Delays", IEEE TAC 49(9), 2004 ([OSM04],
the delay analysis the network oracle of ``test/test_network.py`` follows).
"""

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

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


def critical_delay(lam: float, k_p: float, k_v: float) -> tuple[float, float]:
    """Return ``(tau*, omega)``: the critical input delay of the mode of eigenvalue ``lam``.

    [OSM04] Sec. VIII: the mode obeys ``s^2 + lam (k_v s + k_p) exp(-s tau) = 0`` (with both
    states delayed, the input delay model, the whole coupling is delayed). A root crosses the
    imaginary axis at ``s = i w`` when ``w^2 = lam (k_p + i k_v w) exp(-i w tau)``. Moduli:
    ``w^2 = lam sqrt(k_p^2 + k_v^2 w^2)``, i.e. ``w^4 - lam^2 k_v^2 w^2 - lam^2 k_p^2 = 0``, so
    ``w^2 = (lam^2 k_v^2 + sqrt(lam^4 k_v^4 + 4 lam^2 k_p^2)) / 2``. Phases: ``w tau =
    arg(k_p + i k_v w)`` (mod 2 pi), the smallest positive ``tau* = atan2(k_v w, k_p) / w``.
    At ``tau = 0`` every root is in the left half-plane (``lam > 0``), so the mode is stable
    for ``tau < tau*`` and has a root in the right half-plane just above it. ``tau*``
    decreases with ``lam``: the largest Laplacian eigenvalue decides.

    :param lam: a positive Laplacian eigenvalue.
    :param k_p: relative position gain.
    :param k_v: relative velocity gain.
    :return: the critical delay [s] and the crossing frequency [rad/s].
    """
    w = math.sqrt((lam ** 2 * k_v ** 2 + math.sqrt(lam ** 4 * k_v ** 4 + 4 * lam ** 2 * k_p ** 2))
                  / 2)
    return math.atan2(k_v * w, k_p) / w, w


def sampled_delay_radius(lam: float, d: int, dt: float, k_p: float, k_v: float) -> float:
    """Return the spectral radius per step of the sampled mode under an input delay of ``d``
    steps: the run's exact counterpart of :func:`critical_delay` (above 1: it diverges).

    ``x_{k+1} = A x_k + B u_k`` (the exact zero-order hold of the double integrator),
    ``u_k = -lam (k_p q_{k-d} + k_v p_{k-d})``, stacked with the ``d`` past states.

    :param lam: a Laplacian eigenvalue.
    :param d: the delay [steps].
    :param dt: the step [s].
    :param k_p: relative position gain.
    :param k_v: relative velocity gain.
    :return: the largest modulus of the stacked map's eigenvalues.
    """
    size = 2 * (d + 1)
    m = np.zeros((size, size))
    m[:2, :2] = [[1.0, dt], [0.0, 1.0]]
    m[:2, 2 * d:2 * d + 2] += np.outer([dt * dt / 2, dt], [-lam * k_p, -lam * k_v])
    for s in range(1, d + 1):
        m[2 * s:2 * s + 2, 2 * s - 2:2 * s] = np.eye(2)
    return float(np.max(np.abs(np.linalg.eigvals(m))))
