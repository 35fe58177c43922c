"""A real robot's measured state, as the plant models hold it (no ROS).

The robot agent (:mod:`flock_swarm.nodes.robot_agent`) hears each robot's pose and velocity
from the robot's own topics: ``nav_msgs/Odometry`` (REP 105: the pose in the header's frame,
the twist in the ``child_frame_id``'s, the robot's body frame) or a motion-capture
``geometry_msgs/PoseStamped`` (a pose only: the velocity is estimated by
:class:`PoseDifferentiator`). :func:`world_velocity` rotates a body twist into the world frame
and :func:`plant_state` builds the state row a plant model takes (the ``velocity_lag`` plant's
``[q, v]``, the ``unicycle``'s ``[x, y, qz, qw, v, omega]``) with the plant's own
``from_odometry``, so the law sees exactly the point ``sim`` would (for the unicycle, the point
``ell`` ahead of the axle).
"""

import math

import numpy as np

from flock_swarm.core.plants.base import Plant


def yaw_of(orientation: np.ndarray) -> float:
    """Return the yaw (rad) of a unit quaternion ``(x, y, z, w)`` (ROS order), ZYX convention."""
    x, y, z, w = (float(c) for c in orientation)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def rotate(orientation: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Return ``vector`` (3,) rotated by the unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = (float(c) for c in orientation)
    u = np.array([x, y, z])
    v = np.asarray(vector, dtype=float)
    # v' = v + 2 w (u x v) + 2 u x (u x v), the rotation of a vector by a unit quaternion.
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


def world_velocity(orientation: np.ndarray, body_linear: np.ndarray) -> np.ndarray:
    """Return the world-frame velocity of an ``Odometry`` twist (given in the body frame)."""
    return rotate(orientation, body_linear)


def plant_state(plant: Plant, dim: int, position: np.ndarray, orientation: np.ndarray,
                velocity: np.ndarray, yaw_rate: float) -> np.ndarray:
    """Return one robot's state row for ``plant``, through the plant's own
    :meth:`~flock_swarm.core.plants.base.Plant.from_odometry` (the world's odometry
    convention: a heading plant's twist in the body frame, another's velocity in the world).

    A real robot's orientation is reduced to its yaw first (a ground robot's odometry may
    carry small roll and pitch), so the unicycle's heading is a yaw-only quaternion.

    :param plant: the scenario's plant model (``velocity_lag`` or ``unicycle``).
    :param dim: the scenario's dimension.
    :param position: the position (3,) in the world frame.
    :param orientation: the orientation ``(x, y, z, w)``.
    :param velocity: the world-frame velocity (3,).
    :param yaw_rate: the yaw rate (rad/s).
    :return: the state row.
    """
    yaw = yaw_of(orientation)
    c, s = math.cos(yaw), math.sin(yaw)
    heading = np.array([[0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)]])
    v = np.asarray(velocity, dtype=float)
    linear = np.array([c * v[0] + s * v[1], c * v[1] - s * v[0], v[2]]) \
        if 'body' in plant.frames else v
    return plant.from_odometry(np.asarray(position, dtype=float)[None], heading, linear[None],
                               np.array([[0.0, 0.0, yaw_rate]]), dim)[0]


def from_command(plant: Plant, x: np.ndarray, cmd: np.ndarray) -> np.ndarray:
    """Return state rows ``x`` with their velocities replaced by the last command sent.

    A plant's ``command`` integrates the law's acceleration from the velocity in the state
    (``v_sp = p + u T``): a deadbeat velocity loop, exact in ``sim``, which oscillates when the
    measured velocity arrives late (a real robot's odometry: 50-150 ms). Integrating from the
    last command sent instead (``v_sp = v_sp_prev + u T``, the robot's own velocity controller
    closing the loop) is the robot agent's ``integrate_from:=command``; its default,
    ``predict``, predicts the whole state instead (:mod:`flock_swarm.core.latency`).

    :param plant: the plant model, which says which columns are velocities
        (:meth:`~flock_swarm.core.plants.base.Plant.commanded_state`).
    :param x: state rows ``(n, S)`` (:func:`plant_state`).
    :param cmd: the commands sent, as the plant's commands ``(n, C)`` (``v_sp``, or
        ``(v, omega)``).
    :return: the rows with the velocity columns replaced.
    """
    return plant.commanded_state(x, cmd)


class PoseDifferentiator:
    """The velocity of a pose-only source (motion capture), by smoothed backward differences.

    Each new pose at time ``t`` gives the raw estimate ``(position - last) / (t - t_last)``
    (the yaw rate from the wrapped yaw difference), blended into the estimate by an
    exponential filter of time constant ``tau``: ``est += alpha (raw - est)``,
    ``alpha = h / (tau + h)`` with ``h = t - t_last`` (a first-order low-pass filter discretised
    by backward Euler, so that a motion-capture system's millimetre jitter at 100-300 Hz is
    not amplified into metres per second). ``tau = 0`` takes the raw difference. The first
    pose gives zero velocity; a pose not later than the previous one is ignored.

    :param tau: the filter's time constant (s, >= 0).
    """

    def __init__(self, tau: float = 0.05) -> None:
        self.tau = tau
        self.t: float | None = None
        self.position = np.zeros(3)
        self.yaw = 0.0
        self.velocity = np.zeros(3)
        self.yaw_rate = 0.0

    def update(self, t: float, position: np.ndarray, orientation: np.ndarray) -> bool:
        """Take the pose measured at ``t``; return whether it was used.

        :param t: the measurement time (s).
        :param position: the position (3,).
        :param orientation: the orientation ``(x, y, z, w)``.
        """
        position = np.asarray(position, dtype=float)
        yaw = yaw_of(orientation)
        if self.t is None:
            self.t, self.position, self.yaw = t, position, yaw
            return True
        h = t - self.t
        if h <= 0.0:
            return False
        raw = (position - self.position) / h
        turn = math.remainder(yaw - self.yaw, 2.0 * math.pi)
        alpha = h / (self.tau + h)
        self.velocity = self.velocity + alpha * (raw - self.velocity)
        self.yaw_rate += alpha * (turn / h - self.yaw_rate)
        self.t, self.position, self.yaw = t, position, yaw
        return True
