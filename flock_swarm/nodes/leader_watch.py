"""Whether the leader's state is coming in (no ROS): heard, lost, back.

The world and the agents both follow the leader's messages and fall back when they stop
(the world steps on without waiting for it, the agents apply the uninformed law); this is
the one bookkeeping of both, each caller logging the change in its own words (to a
:class:`Log`, the logging of the ROS-free parts of the nodes).
"""

import math
from typing import Protocol


class Log(Protocol):
    """Where the world stepper and the agent controller say what happened (an rclpy logger,
    a :mod:`logging` logger)."""

    def info(self, message: str) -> object:
        """Log an event."""

    def warning(self, message: str) -> object:
        """Log a problem."""


class LeaderWatch:
    """The leader heard and lost, with the steps at which it was lost and came back.

    :ivar lost: whether the leader counts as lost now.
    :ivar ever_heard: whether any leader message came in.
    :ivar seen_at: the time [s, a monotonic clock] the last leader message came in.
    :ivar events: ``[step, 'lost' | 'back']`` in order (the world's summary).
    """

    def __init__(self, seen_at: float = -math.inf) -> None:
        """Create a watch that has heard nothing yet.

        :param seen_at: the time to count the leader's silence from.
        """
        self.lost = False
        self.ever_heard = False
        self.seen_at = seen_at
        self.events: list[list] = []

    def heard(self, step: int, now: float) -> bool:
        """Note a leader message at ``now``; return whether a lost leader is back.

        :param step: the step to record the return at.
        :param now: the time [s].
        """
        self.seen_at = now
        self.ever_heard = True
        if not self.lost:
            return False
        self.lost = False
        self.events.append([step, 'back'])
        return True

    def lose(self, step: int) -> bool:
        """Note that the leader is gone; return whether it was not lost already.

        :param step: the step to record the loss at.
        """
        if self.lost:
            return False
        self.lost = True
        self.events.append([step, 'lost'])
        return True

    def silent_for(self, now: float) -> float:
        """Return the seconds since the last leader message (or since the start)."""
        return now - self.seen_at
