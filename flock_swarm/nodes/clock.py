"""The simulation clock of the nodes: step ``k`` is at ``t_k = k dt``, in integer nanoseconds.

Every stamp the nodes publish or accept is a step of this clock, so a message's step is exact
integer arithmetic on its stamp. No rclpy: the world's stepper, the agents' controller and the
input guard use it without ROS.
"""


class StepClock:
    """Simulation time of step ``k``: ``t_k = k dt``, stamped exactly in integer nanoseconds."""

    def __init__(self, dt: float) -> None:
        """Create the clock for step ``dt`` seconds."""
        self.dt = dt
        self.dt_ns = int(round(dt * 1e9))

    def stamp(self, k: int):
        """Return the stamp of step ``k`` (a ``builtin_interfaces/Time``)."""
        # Imported here: the message type is the only ROS the clock touches, and only for it.
        from builtin_interfaces.msg import Time
        ns = k * self.dt_ns
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def ns(self, k: int) -> int:
        """Return ``t_k`` in nanoseconds."""
        return k * self.dt_ns

    def step_of(self, stamp) -> int:
        """Return the step ``k`` of a stamp (anything with ``sec`` and ``nanosec``; nearest)."""
        return self.step_at(stamp.sec * 1_000_000_000 + stamp.nanosec)

    def step_at(self, ns: int) -> int:
        """Return the step ``k`` nearest to time ``ns`` [ns] (exact integer arithmetic)."""
        return (2 * ns + self.dt_ns) // (2 * self.dt_ns)
