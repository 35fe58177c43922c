"""The integrators of the agents: exact double integrator, RK4 with intrinsic dynamics.

Agents with intrinsic dynamics obey ``q' = p, p' = f(p) + u`` ([Zhou12] eq. (1), [Yu10]
eq. (36)), with ``f`` the velocity field of an autonomous leader model
(:mod:`flock_swarm.core.leaders`); the leader itself is advanced by
:class:`~flock_swarm.core.leaders.base.VirtualLeader`.

Integration (one step of length ``dt``):

- agents without intrinsic dynamics advance *exactly* under a zero-order hold on ``u``:
  ``q += p dt + u dt^2 / 2``, ``p += u dt`` (:func:`step_double_integrator`);
- agents with intrinsic dynamics use classical RK4 with ``u`` held (:func:`rk4_step`).
"""

import numpy as np

from flock_swarm.core.leaders.base import VelocityField


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
