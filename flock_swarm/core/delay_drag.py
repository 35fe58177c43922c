"""The drag of a communication delay on a moving flock: the predicted braking rate.

Under ``network: {model: communication, delay: D}`` agent ``i`` sets its neighbours' states,
sent ``D`` ago, against its own current state (``docs/network.md``). In a flock translating
at a common velocity ``v`` every neighbour's held position is ``q_j - v D``: each pair term
sees the relative position ``x_ij - v D`` (``x_ij = q_j - q_i``) and the relative velocity
``0``. To first order in ``v D``

    ``u_i = u_i^0 - J_i v D``,  ``J_i = sum_{j in N_i} J(x_ij)``,  ``J(x) = d pair / d x``

where ``J`` is the Jacobian of the pair term's position part: for the gradient term of
Olfati-Saber 2006 / Su 2009, ``phi_alpha(||x||_sigma) grad ||x||_sigma``, the Hessian of the
pair potential ``psi_alpha(||x||_sigma)``. The velocity consensus ``a_ij (p_j - p_i)`` adds
nothing while the velocities are equal. Without navigational feedback (uninformed agents)
an antisymmetric law's ``u_i^0`` sum to zero, so the mean velocity ``v_bar`` obeys

    ``d v_bar / dt = -J_bar v D``,  ``J_bar = (1 / N) sum_i J_i``

and ``beta_0 = D v_hat^T J_bar v_hat`` [1/s] is the rate at which the flock starts to brake
(the first step the delayed messages are used, the velocities still equal). Summed per
undirected edge that first mean acceleration is ``(1 / N) sum_edges [F(x - v D) - F(x +
v D)]`` with ``F`` odd, so the first order is exact up to ``O((v D)^3)``.

Once the flock brakes, ``v_bar(t) = v e^{-beta t}``, the held velocities are older, so
larger: the consensus term adds ``K_bar (e^{beta D} - 1) v`` (``K_i = sum_j d pair / d
p_j``; ``a_ij`` for Su's law) and the held positions lag by ``v (e^{beta D} - 1) / beta``.
The settled rate solves, along ``v_hat`` (``j = v_hat^T J_bar v_hat``, ``kappa = v_hat^T
K_bar v_hat``),

    ``beta = j D (e^{beta D} - 1) / (beta D) - kappa (e^{beta D} - 1)``,

about ``beta_0 / (1 + kappa D - beta_0 D / 2)``. On an alpha-lattice (every neighbour at the
distance ``d``, where ``phi_alpha = 0``) ``J(x) = phi_alpha'(d_alpha) g g^T`` with ``g = x /
sqrt(1 + eps d^2)``: in the interior of a triangular lattice (six neighbours) ``J_i = 3
phi_alpha'(d_alpha) d^2 / (1 + eps d^2) I``, and ``phi_alpha'(d_alpha) = a`` when ``a = b``
and ``d_alpha < h r_alpha``.
"""

from dataclasses import dataclass

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.graphs import EdgeList, disk_graph
from flock_swarm.core.laws.base import Law
from flock_swarm.core.laws.su2009 import SuParams

#: The step of the central differences of :func:`numeric_jacobians` [m].
DIFFERENCE_STEP = 1e-6
#: The settled rate's fixed-point iteration: at most this many steps, to this tolerance.
MAX_ITERATIONS, RATE_TOLERANCE = 200, 1e-14


@dataclass(frozen=True)
class DragPrediction:
    """The predicted first-order drag of a delay on a uniformly moving flock.

    :ivar acceleration: the first mean acceleration ``-J_bar v D`` [m/s^2], ``(dim,)``.
    :ivar rate: the first braking rate ``beta_0 = D v_hat^T J_bar v_hat`` [1/s].
    :ivar settled_rate: the exponential braking rate ``beta`` with the consensus term [1/s]
        (NaN when its fixed-point iteration does not converge).
    :ivar stiffness: ``J_bar``, shape ``(dim, dim)`` [1/s^2].
    :ivar consensus: ``K_bar``, shape ``(dim, dim)`` [1/s].
    :ivar per_agent: ``J_i``, shape ``(N, dim, dim)`` [1/s^2].
    """

    acceleration: np.ndarray
    rate: float
    settled_rate: float
    stiffness: np.ndarray
    consensus: np.ndarray
    per_agent: np.ndarray


def phi_alpha_derivative(z: np.ndarray, law: SuParams) -> np.ndarray:
    """Return ``d phi_alpha / dz`` of the law's action function at sigma-norms ``z``.

    ``phi_alpha(z) = rho_h(z / r_alpha) phi(z - d_alpha)``, ``phi(y) = ((a + b) sigma_1(y +
    c) + a - b) / 2``, ``sigma_1'(u) = (1 + u^2)^(-3/2)``.

    :param z: sigma-norm distances.
    :param law: a law of the Su 2009 / Olfati-Saber 2006 family.
    """
    z = np.asarray(z, dtype=float)
    r_a, d_a = law.r_alpha, law.d_alpha
    c = abs(law.a - law.b) / np.sqrt(4.0 * law.a * law.b)
    y = z - d_a
    dphi = 0.5 * (law.a + law.b) * (1.0 + (y + c) ** 2) ** -1.5
    return (pot.bump_derivative(z / r_a, law.h) / r_a * pot.phi(y, law.a, law.b)
            + pot.bump(z / r_a, law.h) * dphi)


def su_jacobians(law: SuParams, x: np.ndarray) -> np.ndarray:
    """Return the Hessians of ``psi_alpha(||x||_sigma)``, the Jacobians of the gradient term.

    ``H(x) = phi_alpha'(z) g g^T + phi_alpha(z) (I - eps g g^T) / s`` with ``s = sqrt(1 + eps
    |x|^2)``, ``g = x / s`` (the gradient of the sigma-norm ``z``).

    :param law: a law of the Su 2009 / Olfati-Saber 2006 family.
    :param x: relative positions ``q_j - q_i``, shape ``(E, dim)``.
    :return: shape ``(E, dim, dim)``.
    """
    x = np.asarray(x, dtype=float)
    root = np.sqrt(1.0 + law.eps * np.einsum('ek,ek->e', x, x))
    z = pot.sigma_of_distance(np.linalg.norm(x, axis=1), law.eps)
    g = x / root[:, None]
    ggt = np.einsum('ek,el->ekl', g, g)
    eye = np.eye(x.shape[1])[None]
    action = pot.phi_alpha(z, law.r_alpha, law.d_alpha, law.h, law.a, law.b)
    return (phi_alpha_derivative(z, law)[:, None, None] * ggt
            + (action / root)[:, None, None] * (eye - law.eps * ggt))


def numeric_jacobians(law: Law, x: np.ndarray, weight: np.ndarray | None = None,
                      step: float = DIFFERENCE_STEP) -> np.ndarray:
    """Return ``d pair / d x`` of any law by central differences, at equal velocities.

    :param law: the law (its ``pair`` with both velocities zero).
    :param x: relative positions ``q_j - q_i``, shape ``(E, dim)``.
    :param weight: the edges' weights (default 1).
    :param step: the difference step [m].
    :return: shape ``(E, dim, dim)``: ``[e, k, l] = d pair_k / d x_l``.
    """
    x = np.asarray(x, dtype=float)
    e, dim = x.shape
    zero = np.zeros_like(x)
    weight = np.ones(e) if weight is None else np.asarray(weight, dtype=float)
    out = np.empty((e, dim, dim))
    for col in range(dim):
        shift = np.zeros(dim)
        shift[col] = step
        ahead = law.pair(zero, zero, x + shift, zero, weight)[:, :dim]
        behind = law.pair(zero, zero, x - shift, zero, weight)[:, :dim]
        out[:, :, col] = (ahead - behind) / (2.0 * step)
    return out


def jacobians(law: Law, x: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """Return the pair term's Jacobians: analytic for the Su 2009 family (whose pair term
    takes no weight), numeric for any other law."""
    if isinstance(law, SuParams):
        return su_jacobians(law, x)
    return numeric_jacobians(law, x, weight)


def velocity_gains(law: Law, x: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """Return ``d pair / d p_j`` at relative positions ``x`` (equal velocities).

    Su 2009's ``a_ij I`` (``a_ij = rho_h(||x||_sigma / r_alpha)``); any other law by
    central differences (exact for a pair term linear in the velocities).

    :return: shape ``(E, dim, dim)``.
    """
    x = np.asarray(x, dtype=float)
    e, dim = x.shape
    if isinstance(law, SuParams):
        z = pot.sigma_of_distance(np.linalg.norm(x, axis=1), law.eps)
        return pot.bump(z / law.r_alpha, law.h)[:, None, None] * np.eye(dim)[None]
    zero = np.zeros_like(x)
    weight = np.ones(e) if weight is None else np.asarray(weight, dtype=float)
    out = np.empty((e, dim, dim))
    for col in range(dim):
        shift = np.zeros((e, dim))
        shift[:, col] = DIFFERENCE_STEP
        ahead = law.pair(zero, zero, x, shift, weight)[:, :dim]
        behind = law.pair(zero, zero, x, -shift, weight)[:, :dim]
        out[:, :, col] = (ahead - behind) / (2.0 * DIFFERENCE_STEP)
    return out


def settled_rate(j: float, kappa: float, delay: float) -> float:
    """Return ``beta`` solving ``beta = j D (e^{beta D} - 1) / (beta D) - kappa (e^{beta D} -
    1)`` by fixed-point iteration from ``j D`` (NaN when it does not converge).

    :param j: ``v_hat^T J_bar v_hat`` [1/s^2].
    :param kappa: ``v_hat^T K_bar v_hat`` [1/s].
    :param delay: ``D`` [s].
    """
    beta = j * delay
    for _ in range(MAX_ITERATIONS):
        x = beta * delay
        grown = np.expm1(x)
        lag = delay * (grown / x if x != 0.0 else 1.0)
        new = j * lag - kappa * grown
        if abs(new - beta) <= RATE_TOLERANCE * max(1.0, abs(new)):
            return float(new)
        beta = new
    return float('nan')


def predict_drag(law: Law, q: np.ndarray, velocity, delay: float,
                 edges: EdgeList | None = None) -> DragPrediction:
    """Return the predicted drag of a communication delay on a flock moving at ``velocity``.

    :param law: the law (antisymmetric; its navigation is not included: uninformed agents).
    :param q: the flock's positions, shape ``(N, dim)``.
    :param velocity: the common velocity ``v`` [m/s], shape ``(dim,)``.
    :param delay: the communication delay ``D`` [s].
    :param edges: the interaction graph (default: the law's r-disk graph at ``q``).
    :return: the mean acceleration, the braking rate and the stiffnesses.
    """
    q = np.asarray(q, dtype=float)
    v = np.asarray(velocity, dtype=float)
    n, dim = q.shape
    if edges is None:
        edges = disk_graph(q, law.radius, law.strict_radius)
    x = q[edges.j] - q[edges.i]
    per_agent, gains = np.zeros((n, dim, dim)), np.zeros((n, dim, dim))
    # Each end of an undirected edge, at its own relative position.
    for ends, rel in ((edges.i, x), (edges.j, -x)):
        np.add.at(per_agent, ends, jacobians(law, rel, edges.weight))
        np.add.at(gains, ends, velocity_gains(law, rel, edges.weight))
    stiffness, consensus = per_agent.mean(axis=0), gains.mean(axis=0)
    acceleration = -stiffness @ v * delay
    speed = float(np.linalg.norm(v))
    if speed == 0.0:
        return DragPrediction(acceleration, 0.0, 0.0, stiffness, consensus, per_agent)
    v_hat = v / speed
    j, kappa = float(v_hat @ stiffness @ v_hat), float(v_hat @ consensus @ v_hat)
    return DragPrediction(acceleration, j * delay, settled_rate(j, kappa, delay), stiffness,
                          consensus, per_agent)


def measured_rate(t: np.ndarray, p: np.ndarray, direction) -> float:
    """Return the braking rate of a run: minus the slope of ``ln(v_bar . v_hat)`` over ``t``.

    :param t: the instants [s] (at least two).
    :param p: the velocities at those instants, shape ``(T, N, dim)``.
    :param direction: the flock's initial direction of motion (normalised here).
    :return: ``beta`` [1/s], by least squares.
    """
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    along = np.asarray(p, dtype=float).mean(axis=1) @ d
    return float(-np.polyfit(np.asarray(t, dtype=float), np.log(along), 1)[0])


def triangular_lattice(count: int, spacing: float) -> np.ndarray:
    """Return the ``count`` points of a triangular lattice nearest its origin (a hexagonal
    patch, ties broken by angle), shape ``(count, 2)``: an alpha-lattice at ``spacing``.
    """
    side = int(np.ceil(np.sqrt(count))) + 2
    i, j = np.meshgrid(np.arange(-side, side + 1), np.arange(-side, side + 1), indexing='ij')
    i, j = i.ravel().astype(float), j.ravel().astype(float)
    points = spacing * np.stack([i + 0.5 * j, np.sqrt(3.0) / 2.0 * j], axis=1)
    radius = np.round(np.hypot(points[:, 0], points[:, 1]) / spacing, 9)
    angle = np.round(np.arctan2(points[:, 1], points[:, 0]), 9)
    order = np.lexsort((angle, radius))
    return points[order[:count]]
