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


#: The conversions :func:`sampled_lag_matrix` models (``plant.conversion`` of a velocity lag).
LAG_CONVERSIONS = ('exact', 'naive')


def _lag_gains(tau: float, dt: float, conversion: str,
               conversion_tau: float | None) -> tuple[float, float]:
    """Return ``(c, beta)``: how one step moves the position and the velocity per ``u dt``."""
    if conversion not in LAG_CONVERSIONS:
        raise ValueError(f'conversion must be one of {LAG_CONVERSIONS}, got {conversion!r}')
    reach = -math.expm1(-dt / tau)
    gain = 1.0 if conversion == 'naive' else 1.0 / -math.expm1(-dt / (conversion_tau or tau))
    return gain * (dt - tau * reach), gain * reach


def sampled_lag_matrix(lam: float, tau: float, dt: float, k_p: float, k_v: float,
                       conversion: str = 'exact',
                       conversion_tau: float | None = None) -> np.ndarray:
    """Return the one-step map ``(q, v)_{k+1} = M (q, v)_k`` of a disagreement mode of the
    linear law flying velocity-lag robots (``plant: {model: velocity_lag}``, no limits).

    The mode of Laplacian eigenvalue ``lam`` commands ``u = -lam (k_p q + k_v v)``. The
    conversion turns it into the setpoint ``v_sp = v + gamma u T`` (``T = dt``): ``gamma = 1``
    naive, ``gamma = 1 / a_c`` exact, ``a_c = 1 - exp(-dt / tau_c)`` with ``tau_c`` the
    assumed lag (``conversion_tau``, default ``tau``). The lag ``v' = (v_sp - v) / tau`` held
    over ``dt`` (``a = 1 - exp(-dt / tau)``) gives exactly

        ``v_{k+1} = v + beta dt u``,   ``q_{k+1} = q + dt v + c dt u``,
        ``beta = a gamma``,   ``c = gamma (dt - tau a)``.

    The conversion reads the measured velocity, the lag's own state, so the lag adds no
    state: the loop is ``M = [[1, dt], [0, 1]] - lam dt (c, beta)^T (k_p, k_v)``, second
    order, with the characteristic equation ``z^2 - tr z + det = 0``,
    ``tr = 2 - lam dt (c k_p + beta k_v)``, ``det = 1 - lam dt (c k_p + beta k_v) + lam dt^2
    beta k_p``. The exact conversion with ``tau_c = tau`` has ``beta = 1`` (the velocity
    changes by ``u dt``, as the double integrator's) and ``c = dt / a - tau``, between
    ``dt / 2`` (``tau >> dt``: the double integrator's zero-order hold) and ``dt``
    (``tau -> 0``: the velocity jumps at the step's start); the naive one has ``beta = a``:
    every gain divided by about ``tau / dt`` for a long lag.

    :param lam: a Laplacian eigenvalue (the mode's loop gain factor).
    :param tau: the robots' lag [s].
    :param dt: the step, the command period [s].
    :param k_p: relative position gain.
    :param k_v: relative velocity gain.
    :param conversion: ``exact`` or ``naive``.
    :param conversion_tau: the lag the exact conversion assumes (``None``: ``tau``).
    :return: ``M``, 2 x 2.
    """
    c, beta = _lag_gains(tau, dt, conversion, conversion_tau)
    return (np.array([[1.0, dt], [0.0, 1.0]])
            - lam * dt * np.outer([c, beta], [k_p, k_v]))


def sampled_lag_radius(lam: float, tau: float, dt: float, k_p: float, k_v: float,
                       conversion: str = 'exact', conversion_tau: float | None = None) -> float:
    """Return the spectral radius of :func:`sampled_lag_matrix` (above 1: the mode diverges)."""
    return float(np.max(np.abs(np.linalg.eigvals(
        sampled_lag_matrix(lam, tau, dt, k_p, k_v, conversion, conversion_tau)))))


def lag_margin(lam: float, tau: float, dt: float, k_p: float, k_v: float,
               conversion: str = 'exact') -> float:
    """Return ``1 + tr + det`` of :func:`sampled_lag_matrix`: the Jury condition that can fail.

    Jury's test for ``z^2 - tr z + det``: both roots inside the unit circle iff
    ``1 - tr + det > 0``, ``1 + tr + det > 0`` and ``|det| < 1``. Here ``1 - tr + det = lam
    dt^2 beta k_p > 0`` always; ``det < 1`` iff ``c k_p + beta k_v > dt beta k_p``, which holds
    for every lag when ``k_v > k_p dt / 2`` (``c - dt beta`` lies in ``(-dt / 2, 0)`` for the
    exact conversion, ``c - dt beta = dt e - tau a`` in ``(-dt beta / 2, 0)`` for the naive);
    ``det > -1`` follows from ``1 + tr + det > 0``. What is left is

        ``1 + tr + det = 4 - 2 lam dt (c k_p + beta k_v) + lam dt^2 beta k_p``.
    """
    c, beta = _lag_gains(tau, dt, conversion, None)
    return 4.0 - 2.0 * lam * dt * (c * k_p + beta * k_v) + lam * dt * dt * beta * k_p


def critical_lag(lam: float, dt: float, k_p: float, k_v: float,
                 conversion: str = 'exact') -> float:
    """Return the critical lag ``tau_c`` of the mode of eigenvalue ``lam``: the mode of
    :func:`sampled_lag_matrix` (``conversion_tau = tau``) is stable for ``tau > tau_c`` and
    unstable for ``tau < tau_c``; ``0.0`` if stable for every lag, ``inf`` for none.

    The structure (:func:`lag_margin`, with ``k_v > k_p dt / 2``): the only condition that
    can fail is ``1 + tr + det > 0``. For ``tau -> 0`` both conversions are the instantaneous
    plant, margin ``4 - 2 lam dt k_v - lam dt^2 k_p``. A lag only lowers the loop's gain:
    the naive margin rises to 4 as ``tau -> inf`` (``beta = a -> 0``, ``c -> 0``), the exact
    margin to ``4 - 2 lam dt k_v`` (``c -> dt / 2``: the double integrator's), both
    monotonically (the naive one when ``2 k_v > dt k_p``). So no lag destabilises the loop:
    a critical lag exists only when the loop gain is near the sampled double integrator's
    limit (``2 lam dt k_v + lam dt^2 k_p >= 4``), and it is the SMALLEST lag that stabilises
    it, found here by bisection (in ``log tau``, to adjacent floats) on the margin's sign.
    Not a delay: the conversion acts on the measured velocity, the lag's state, each step.

    :param lam: a positive Laplacian eigenvalue.
    :param dt: the step, the command period [s].
    :param k_p: relative position gain.
    :param k_v: relative velocity gain (``> k_p dt / 2``).
    :param conversion: ``exact`` or ``naive``.
    :return: ``tau_c`` [s].
    """
    if not k_v > k_p * dt / 2:
        raise ValueError(f'critical_lag needs k_v > k_p dt / 2, got k_p = {k_p}, k_v = {k_v}')
    lo, hi = dt * 1e-9, dt * 1e9
    if lag_margin(lam, lo, dt, k_p, k_v, conversion) > 0.0:
        return 0.0
    if lag_margin(lam, hi, dt, k_p, k_v, conversion) <= 0.0:
        return math.inf
    while True:
        mid = math.sqrt(lo * hi)
        if not lo < mid < hi:
            return hi
        if lag_margin(lam, mid, dt, k_p, k_v, conversion) > 0.0:
            hi = mid
        else:
            lo = mid
