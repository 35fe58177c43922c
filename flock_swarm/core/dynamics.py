"""Velocity fields, the virtual leader, and the integrators of agents and leader.

Every model here is a *velocity field* ``f(p)``: the acceleration as a function of velocity.
The virtual leader obeys ``q' = p, p' = f(p)`` ([Su09] eq. (6), [Zhou12] eq. (2), [Yu10]
eq. (1)); agents with intrinsic dynamics obey ``q' = p, p' = f(p) + u`` ([Zhou12] eq. (1),
[Yu10] eq. (36)).

Integration (one step of length ``dt``):

- agents without intrinsic dynamics advance *exactly* under a zero-order hold on ``u``:
  ``q += p dt + u dt^2 / 2``, ``p += u dt`` (:func:`step_double_integrator`);
- agents with intrinsic dynamics, and the leader, use classical RK4 with ``u`` held
  (:func:`rk4_step`); RK4 is exact for the constant-velocity and constant-acceleration leaders.
"""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

VelocityField = Callable[[np.ndarray], np.ndarray]

#: Lorenz parameters of [Su09] Section V.B (sigma, rho, beta).
LORENZ_DEFAULTS = {'sigma': 10.0, 'rho': 28.0, 'beta': 8.0 / 3.0}
#: Lu system parameters of [Zhou12] Section 5.1 (chaotic attractor).
LU_DEFAULTS = {'a': 36.0, 'b': 3.0, 'c': 20.0}


def lorenz(p: np.ndarray, sigma: float, rho: float, beta: float) -> np.ndarray:
    """Return the Lorenz vector field applied to velocities ([Su09] Section V.B).

    ``(sigma (y - x), rho x - x z - y, x y - beta z)`` with ``(x, y, z) = p``.

    :param p: velocities, shape ``(..., 3)``.
    :return: accelerations, shape ``(..., 3)``.
    """
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack((sigma * (y - x), rho * x - x * z - y, x * y - beta * z), axis=-1)


def lu(p: np.ndarray, a: float, b: float, c: float) -> np.ndarray:
    """Return the Lu system ``R x + T(x)`` applied to velocities ([Zhou12] Section 5.1).

    ``(a (y - x), c y - x z, x y - b z)`` with ``(x, y, z) = p``.

    :param p: velocities, shape ``(..., 3)``.
    :return: accelerations, shape ``(..., 3)``.
    """
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack((a * (y - x), c * y - x * z, x * y - b * z), axis=-1)


@dataclass(frozen=True)
class FieldSpec:
    """A named velocity field with its parameters (comparable, printable)."""

    kind: str
    params: dict = field(default_factory=dict)

    def build(self) -> VelocityField:
        """Return the field as a function ``f(p)`` over arrays of shape ``(..., dim)``."""
        if self.kind == 'zero':
            return lambda p: np.zeros_like(p)
        if self.kind == 'constant':
            acc = np.asarray(self.params['acceleration'], dtype=float)
            return lambda p: np.broadcast_to(acc, p.shape).copy()
        if self.kind == 'lorenz':
            prm = {**LORENZ_DEFAULTS, **self.params}
            return lambda p: lorenz(p, prm['sigma'], prm['rho'], prm['beta'])
        if self.kind == 'lu':
            prm = {**LU_DEFAULTS, **self.params}
            return lambda p: lu(p, prm['a'], prm['b'], prm['c'])
        if self.kind == 'linear':
            mat = np.asarray(self.params['A'], dtype=float)
            return lambda p: p @ mat.T
        raise ValueError(f'unknown velocity field {self.kind!r}')

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        """Return ``df/dp`` at one velocity ``p`` (used by the step-size check)."""
        dim = p.shape[-1]
        if self.kind in ('zero', 'constant'):
            return np.zeros((dim, dim))
        if self.kind == 'linear':
            return np.asarray(self.params['A'], dtype=float)
        if self.kind not in ('lorenz', 'lu'):
            raise ValueError(f'unknown velocity field {self.kind!r}')
        x, y, z = p
        if self.kind == 'lorenz':
            prm = {**LORENZ_DEFAULTS, **self.params}
            return np.array([[-prm['sigma'], prm['sigma'], 0.0],
                             [prm['rho'] - z, -1.0, -x],
                             [y, x, -prm['beta']]])
        prm = {**LU_DEFAULTS, **self.params}
        return np.array([[-prm['a'], prm['a'], 0.0],
                         [-z, prm['c'], -x],
                         [y, x, -prm['b']]])


def step_double_integrator(q: np.ndarray, p: np.ndarray, u: np.ndarray,
                           dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Advance ``q' = p, p' = u`` exactly over ``dt`` with ``u`` held constant.

    [Su09] eq. (1) under a zero-order hold: ``q += p dt + u dt^2 / 2``, ``p += u dt``.

    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param u: accelerations, shape ``(n, dim)``.
    :param dt: step, ``> 0``.
    :return: the new ``(q, p)`` (new arrays).
    """
    return q + p * dt + u * (0.5 * dt * dt), p + u * dt


def rk4_step(q: np.ndarray, p: np.ndarray, u: np.ndarray, dt: float,
             f: VelocityField) -> tuple[np.ndarray, np.ndarray]:
    """Advance ``q' = p, p' = f(p) + u`` over ``dt`` by classical RK4, ``u`` held constant.

    :param q: positions, shape ``(..., dim)``.
    :param p: velocities, shape ``(..., dim)``.
    :param u: held input, broadcastable to ``p``.
    :param dt: step, ``> 0``.
    :param f: the velocity field.
    :return: the new ``(q, p)``.
    """
    k1q, k1p = p, f(p) + u
    p2 = p + 0.5 * dt * k1p
    k2q, k2p = p2, f(p2) + u
    p3 = p + 0.5 * dt * k2p
    k3q, k3p = p3, f(p3) + u
    p4 = p + dt * k3p
    k4q, k4p = p4, f(p4) + u
    q_new = q + (dt / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
    p_new = p + (dt / 6.0) * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
    return q_new, p_new


def step_agents(q: np.ndarray, p: np.ndarray, u: np.ndarray, dt: float,
                intrinsic: VelocityField | None) -> tuple[np.ndarray, np.ndarray]:
    """Advance every agent one step: exact zero-order hold, or RK4 with intrinsic dynamics.

    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param u: control inputs, shape ``(n, dim)``, held over the step.
    :param dt: step, ``> 0``.
    :param intrinsic: the intrinsic field ``f`` of ``p' = f(p) + u``, or ``None``.
    :return: the new ``(q, p)``.
    """
    if intrinsic is None:
        return step_double_integrator(q, p, u, dt)
    return rk4_step(q, p, u, dt, intrinsic)


@dataclass(frozen=True)
class LeaderState:
    """The virtual leader's state: position, velocity and acceleration ``f_gamma``."""

    q: np.ndarray
    p: np.ndarray
    a: np.ndarray


class VirtualLeader:
    """The virtual leader ``q' = p, p' = f(p)`` of [Su09] eq. (6), advanced by RK4."""

    def __init__(self, spec: FieldSpec, q0: np.ndarray, p0: np.ndarray) -> None:
        """Create the leader.

        :param spec: its velocity field.
        :param q0: initial position ``q_gamma(0)``.
        :param p0: initial velocity ``p_gamma(0)``.
        """
        self.spec = spec
        self._f = spec.build()
        self._q = np.array(q0, dtype=float)
        self._p = np.array(p0, dtype=float)

    @property
    def state(self) -> LeaderState:
        """Return the current state, with ``a = f(p)`` evaluated now."""
        return LeaderState(self._q.copy(), self._p.copy(), self._f(self._p))

    def step(self, dt: float) -> None:
        """Advance the leader by ``dt`` (RK4, exact for polynomial motion)."""
        self._q, self._p = rk4_step(self._q, self._p, 0.0, dt, self._f)
