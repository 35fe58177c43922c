"""A lockstep step's messages, queued as serialised bytes until the step can be taken at once.

In lockstep mode every sender sends one message a step: each agent its command to the world,
the world each agent's odometry to every agent host. Handling them one by one costs a Python
callback, a decode and the input checks per message; queued as bytes instead, a step whose
every message is in is decoded and checked in one pass (a wire batch,
:class:`~flock_swarm.nodes.wire.OdometryBatch` or :class:`~flock_swarm.nodes.wire.AccelBatch`,
and :meth:`~flock_swarm.nodes.guard.InputGuard.pass_batch`). Whatever is not one stamp of
every sender in the senders' layout (a fault, a duplicate, another byte order), and a queue
that stopped growing for a timer tick (a sender missing), goes message by message through the
node's checks, so every rejection is judged and counted as on arrival.

:class:`StepInbox` is the queue; the world's :class:`~flock_swarm.nodes.stepper.CommandInbox`
and the agents' :class:`~flock_swarm.nodes.controller.OdometryInbox` decide what a step taken
at once is for their stepper and controller. No rclpy.
"""

from typing import Protocol, Sequence

import numpy as np


class Batch(Protocol):
    """A wire batch decoder (:class:`~flock_swarm.nodes.wire.OdometryBatch`, ``AccelBatch``)."""

    def decode(self, buffers: Sequence[bytes | None]) -> tuple[int, np.ndarray] | None:
        """Return ``(stamp_ns, values)`` of one message per sender, or ``None``."""


class StepInbox:
    """The messages of ``size`` senders (``(sender, bytes)``), in their order of arrival.

    :ivar size: the number of senders.
    """

    def __init__(self, size: int, batch: Batch) -> None:
        """Create an empty inbox.

        :param size: the number of senders (ids ``0 .. size - 1``).
        :param batch: decodes one message of every sender at once.
        """
        self.size = size
        self.batch = batch
        self.queue: list[tuple[int, bytes]] = []
        # The queue's length at the last timer tick (see stalled).
        self.seen = 0

    def __len__(self) -> int:
        """Return the number of queued messages."""
        return len(self.queue)

    def put(self, sender: int, data: bytes) -> None:
        """Queue a message of ``sender``."""
        self.queue.append((sender, data))

    def stalled(self) -> bool:
        """Return, at a timer tick, whether the queue holds messages and did not grow since
        the last tick: then it is to be taken (:meth:`take`) and handled one by one.

        A step still arriving (over tens of milliseconds from another process at N = 1000)
        keeps growing, so it stays one pass.
        """
        queued = len(self.queue)
        if queued and queued == self.seen:
            return True
        self.seen = queued
        return False

    def take(self) -> list[tuple[int, bytes]]:
        """Return the queued messages in their order of arrival and empty the queue."""
        queue, self.queue = self.queue, []
        self.seen = 0
        return queue

    def decode(self, queue: Sequence[tuple[int, bytes]]) -> tuple[int, np.ndarray] | None:
        """Return ``(stamp_ns, values)`` of a queue holding one message of every sender with
        one stamp, in the senders' layout (the batch's); ``None`` for any other queue.

        :param queue: messages taken (:meth:`take`).
        """
        if len(queue) != self.size:
            return None
        buffers: list[bytes | None] = [None] * self.size
        for sender, data in queue:
            buffers[sender] = data
        return self.batch.decode(buffers)
