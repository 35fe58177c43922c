"""The safety layer between a flocking law and a real robot's velocity command.

ROS-free, so that every rule is tested on its own (test/test_safety.py) and the robot agent
node (:mod:`flock_swarm.nodes.robot_agent`) only feeds it times, states and commands. One call
of :meth:`SafetyLayer.filter` per command, in this order (the first rule that fires wins):

1. **emergency stop**: while the e-stop input is true, the command is zero;
2. **stale state**: when the robot's own state or the leader's is older than ``stale_after``
   seconds (or none has arrived yet), the command is zero;
3. **geofence**: when the robot's position is outside the box ``fence_min .. fence_max``, the
   command is zero (the robot holds where it left the fence, as PX4's geofence "hold" action
   does, until an operator moves it back or widens the fence);
4. **non-finite command** (a law's NaN or inf): zero;
5. otherwise the command is **saturated**: the acceleration first (the change of the linear
   command from the last one sent, at most ``max_accel`` times the time since it, the vector
   shortened along its direction; the first command starts from rest), then the speed (the
   linear vector shortened to ``max_speed``), and the yaw rate clipped to ``max_yaw_rate``.

A stop is sent at once, not ramped: the zero command hands braking to the robot's own
controller, and the acceleration limit restarts from zero afterwards.
"""

from dataclasses import dataclass

import numpy as np

from flock_swarm.core.errors import ScenarioError

#: Why a command was changed (``''``: passed, saturated or not).
ESTOP, STALE_OWN, STALE_LEADER, GEOFENCE, NON_FINITE = (
    'estop', 'stale_own', 'stale_leader', 'geofence', 'non_finite')
#: The stop reasons, in the order the rules are checked.
STOPS = (ESTOP, STALE_OWN, STALE_LEADER, GEOFENCE, NON_FINITE)
#: The bounds a robot gets unless it is given its own (a TurtleBot3 Burger's speed and yaw
#: rate), name -> (default, description): the one table of the robot agent's parameters and
#: the launch file's arguments (:mod:`flock_swarm.nodes.robot_profiles`).
ROBOT_DEFAULTS = {
    'max_speed': (0.22, 'safety: largest linear speed (m/s)'),
    'max_accel': (0.5, 'safety: largest change of the linear command per second (m/s^2)'),
    'max_yaw_rate': (2.84, 'safety: largest yaw rate (rad/s)'),
    'stale_after': (0.5, 'safety: the oldest own or leader state that still commands motion '
                    '(s)'),
}


@dataclass(frozen=True)
class SafetyLimits:
    """The safety layer's bounds (``None`` or an empty fence: that rule is off).

    :param max_speed: largest norm of the linear command (m/s).
    :param max_accel: largest change of the linear command per second (m/s^2).
    :param max_yaw_rate: largest ``|angular.z|`` (rad/s).
    :param stale_after: largest age of the own and the leader's state (s).
    :param fence_min: the geofence's lower corner (x, y[, z]) in the world frame (m).
    :param fence_max: its upper corner.
    """

    max_speed: float | None = None
    max_accel: float | None = None
    max_yaw_rate: float | None = None
    stale_after: float | None = None
    fence_min: tuple[float, ...] = ()
    fence_max: tuple[float, ...] = ()

    def validate(self, prefix: str = 'safety.') -> None:
        """Raise :class:`ScenarioError` naming the first invalid bound.

        :param prefix: prepended to the key in the message (a node parameter's prefix).
        """
        for key in ('max_speed', 'max_accel', 'max_yaw_rate', 'stale_after'):
            value = getattr(self, key)
            if value is not None and not (np.isfinite(value) and value > 0.0):
                raise ScenarioError(prefix + key, f'must be a positive number, got {value!r}')
        if len(self.fence_min) != len(self.fence_max):
            raise ScenarioError(prefix + 'fence_max', 'must have as many values as fence_min '
                                f'({len(self.fence_max)} != {len(self.fence_min)})')
        if self.fence_min and len(self.fence_min) not in (2, 3):
            raise ScenarioError(prefix + 'fence_min', 'must have 2 or 3 values (x, y[, z]), '
                                f'got {len(self.fence_min)}')
        for lo, hi in zip(self.fence_min, self.fence_max):
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ScenarioError(prefix + 'fence_max', 'each value must be finite and above '
                                    f'fence_min\'s (got {list(self.fence_min)} .. '
                                    f'{list(self.fence_max)})')


@dataclass(frozen=True)
class Verdict:
    """One filtered command.

    :param linear: the linear velocity to send (3,).
    :param yaw_rate: the ``angular.z`` to send.
    :param stop: the stop rule that fired (one of :data:`STOPS`) or ``''``.
    :param saturated: whether a limit changed the command.
    """

    linear: np.ndarray
    yaw_rate: float
    stop: str
    saturated: bool


def _shorten(vector: np.ndarray, bound: float) -> np.ndarray:
    """Return ``vector`` shortened along its direction to norm ``bound`` if it is longer."""
    norm = float(np.linalg.norm(vector))
    return vector * (bound / norm) if norm > bound else vector


class SafetyLayer:
    """The safety rules of the module docstring, with the memory the acceleration limit needs.

    :param limits: the bounds (validated here).
    """

    def __init__(self, limits: SafetyLimits) -> None:
        limits.validate()
        self.limits = limits
        self._last_linear = np.zeros(3)
        self._last_time: float | None = None
        #: How many commands each stop rule zeroed, and how many were saturated.
        self.counts = {reason: 0 for reason in STOPS + ('saturated',)}

    def filter(self, now: float, linear: np.ndarray, yaw_rate: float, *,
               own_stamp: float | None, leader_stamp: float | None,
               position: np.ndarray | None, estop: bool) -> Verdict:
        """Return the command to send at time ``now``.

        :param now: the current time (s; the clock the stamps are on).
        :param linear: the law's linear velocity command (3,), in the command's frame.
        :param yaw_rate: its ``angular.z`` (rad/s).
        :param own_stamp: when the robot's state was measured (``None``: never).
        :param leader_stamp: when the leader's state was (``None``: never).
        :param position: the robot's position in the world frame (2 or 3 values), or ``None``.
        :param estop: whether the emergency stop is engaged.
        :return: the verdict.
        """
        stop = self._stop_reason(now, linear, yaw_rate, own_stamp, leader_stamp, position,
                                 estop)
        if stop:
            self.counts[stop] += 1
            self._last_linear = np.zeros(3)
            self._last_time = now
            return Verdict(np.zeros(3), 0.0, stop, False)
        lim = self.limits
        out = np.asarray(linear, dtype=float).copy()
        if lim.max_accel is not None:
            # The first command ramps from rest, as after a stop.
            elapsed = 0.0 if self._last_time is None else max(now - self._last_time, 0.0)
            out = self._last_linear + _shorten(out - self._last_linear, lim.max_accel * elapsed)
        if lim.max_speed is not None:
            out = _shorten(out, lim.max_speed)
        yaw = float(yaw_rate)
        if lim.max_yaw_rate is not None:
            yaw = float(np.clip(yaw, -lim.max_yaw_rate, lim.max_yaw_rate))
        saturated = yaw != yaw_rate or not np.array_equal(out, linear)
        self.counts['saturated'] += saturated
        self._last_linear = out
        self._last_time = now
        return Verdict(out, yaw, '', saturated)

    def _stop_reason(self, now: float, linear: np.ndarray, yaw_rate: float,
                     own_stamp: float | None, leader_stamp: float | None,
                     position: np.ndarray | None, estop: bool) -> str:
        """Return the first stop rule that fires, or ``''``."""
        lim = self.limits
        if estop:
            return ESTOP
        if lim.stale_after is not None:
            if own_stamp is None or now - own_stamp > lim.stale_after:
                return STALE_OWN
            if leader_stamp is None or now - leader_stamp > lim.stale_after:
                return STALE_LEADER
        if lim.fence_min:
            if position is None:
                return GEOFENCE
            where = np.asarray(position, dtype=float)
            # A 3-D fence on a ground robot's 2-D position checks x and y.
            k = min(len(lim.fence_min), len(where))
            if (np.any(where[:k] < lim.fence_min[:k])
                    or np.any(where[:k] > lim.fence_max[:k])):
                return GEOFENCE
        if not (np.all(np.isfinite(linear)) and np.isfinite(yaw_rate)):
            return NON_FINITE
        return ''
