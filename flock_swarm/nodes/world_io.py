"""The world's message paths: its state out and the agents' commands in, as strategy objects.

:class:`StatePublisher` publishes a step's ``/clock`` and every ``/agent_<i>/odom`` (one
serialised message each, through rclpy) and records the same bytes;
:class:`BatchStatePublisher` sends them in one call of the compiled extension
(:mod:`flock_swarm.nodes.batch`). :class:`CommandIntake` takes every agent's
``cmd_accel`` (in lockstep queued as bytes and handed to the stepper at once,
:class:`~flock_swarm.nodes.stepper.CommandInbox`); :class:`BatchCommandIntake` takes every
waiting command in one call of the extension. :func:`state_publisher` and
:func:`command_intake` choose one of each; another transport (a whole swarm's state in one
message, one command message per host) is one more class of each kind, chosen there.
"""

import time
from typing import Callable

import numpy as np
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock

from flock_swarm.contract import (agent_name, CLOCK, CLOCK_QOS, LOCKSTEP_QOS, cmd_topic,
                                  odom_topic, qos_profile)
from flock_swarm.nodes.batch import BatchPublish, BatchTake, release
from flock_swarm.nodes.ros_graph import command_claims
from flock_swarm.nodes.stepper import CommandInbox, WorldStepper
from flock_swarm.nodes.wire import (OdometryBatchEncoder, decode_accel, encode_clock,
                                    odometry_rows)


class StatePublisher:
    """The world's state out, through rclpy: ``/clock`` and every agent's odometry of a step.

    :ivar clock_pub: the ``/clock`` publisher.
    :ivar odom_pubs: every agent's odometry publisher, by agent.
    :ivar step_bytes: the open step's messages as published (offered again if it stalls).
    """

    def __init__(self, node, stepper: WorldStepper, pubs: list, encoder) -> None:
        """Publish through ``pubs``.

        :param node: the world (a :class:`~flock_swarm.nodes.recording.RecordedNode`).
        :param stepper: its stepper (the scenario, the plant and the state published).
        :param pubs: the ``/clock`` publisher, then those of the state (recorded).
        :param encoder: encodes a step's state as the messages of ``pubs[1:]``
            (:class:`~flock_swarm.nodes.wire.OdometryBatchEncoder`'s ``encode``).
        """
        self.node, self.stepper, self.encoder = node, stepper, encoder
        self.pubs = pubs
        self.clock_pub, self.odom_pubs = pubs[0], pubs[1:]
        self.topics = [pub.topic_name for pub in self.pubs]
        self.step_bytes: list[bytes] = []

    def publish(self, t_ns: int) -> None:
        """Publish ``/clock`` and every agent's odometry for time ``t_ns`` and record them
        (every sink flushed: the step's messages are in the bag before the agents answer)."""
        st = self.stepper
        rows = (st.q, st.p) if st.plant is None else odometry_rows(st.plant, st.x,
                                                                   st.scenario.dim)
        sent = [encode_clock(t_ns)]
        sent += self.encoder.encode(t_ns, *rows)
        self.send(sent)
        self.node.record_messages(self.topics, sent, t_ns)
        for sink in self.node.sinks:
            sink.flush()
        self.step_bytes = sent

    def resend(self) -> None:
        """Offer the open step's messages again (not recorded again)."""
        self.send(self.step_bytes)

    def send(self, sent: list[bytes]) -> None:
        """Publish ``/clock`` and every odometry (their bytes, in that order)."""
        for pub, data in zip(self.pubs, sent):
            pub.publish(data)

    def release(self) -> None:
        """Let go of what holds the publishers (nothing here)."""


class BatchStatePublisher(StatePublisher):
    """The world's state out in one call of the compiled extension (lockstep)."""

    def __init__(self, node, stepper: WorldStepper, pubs: list, encoder) -> None:
        """Publish through ``pubs`` (see :class:`StatePublisher`) in one call."""
        super().__init__(node, stepper, pubs, encoder)
        self.batch = BatchPublish(self.pubs)
        self.targets = np.arange(len(self.pubs), dtype=np.int64)

    def send(self, sent: list[bytes]) -> None:
        """Publish ``/clock`` and every odometry in one call."""
        self.batch.publish_to(self.targets, sent)

    def release(self) -> None:
        """Release the extension's hold on the publishers."""
        release(self.batch)


def state_publisher(node, stepper: WorldStepper, c_path: bool) -> StatePublisher:
    """Return the world's state out, ``/clock`` then one odometry topic per agent: the
    compiled path's (``c_path``) or rclpy's."""
    sc, qos = stepper.scenario, qos_profile(LOCKSTEP_QOS)
    pubs = [node.recorded_publisher(Clock, CLOCK, qos_profile(CLOCK_QOS))]
    pubs += [node.recorded_publisher(Odometry, odom_topic(i), qos) for i in range(sc.n_agents)]
    plant = stepper.plant
    encoder = OdometryBatchEncoder([agent_name(i) for i in range(sc.n_agents)],
                                   oriented=plant is not None and plant.oriented)
    return (BatchStatePublisher if c_path else StatePublisher)(node, stepper, pubs, encoder)


class CommandIntake:
    """The agents' accelerations in, through rclpy: one recorded subscription per agent.

    Realtime, each command is checked and handed to the stepper as it comes
    (:meth:`on_command`). Lockstep, the commands are queued as bytes and taken at once once
    they can complete the step (:meth:`take`).

    :ivar topics: every agent's command topic, by agent.
    :ivar inbox: the lockstep queue.
    """

    def __init__(self, node, stepper: WorldStepper, closed: Callable[[], None]) -> None:
        """Subscribe to every agent's commands.

        :param node: the world (its guard, clock and sinks judge and record the commands).
        :param stepper: its stepper.
        :param closed: called after a command that may complete the open step.
        """
        self.node, self.stepper, self.closed = node, stepper, closed
        n, lockstep = stepper.scenario.n_agents, stepper.lockstep
        self.handlers = [lambda msg, i=i: self.on_command(i, msg) for i in range(n)]
        self.topics = [node.recorded_subscription(AccelStamped, cmd_topic(i), decode_accel,
                                                  self.handlers[i],
                                                  (lambda data, i=i: self.queue(i, data))
                                                  if lockstep else None)
                       for i in range(n)]
        self.inbox = CommandInbox(stepper, node.guard, self.topics)

    def claims(self, n_agents: int) -> dict[int, list[tuple[str, str]]]:
        """Return the nodes publishing each agent's commands, as the ROS graph tells
        (:func:`~flock_swarm.nodes.ros_graph.command_claims`)."""
        return command_claims(self.node, n_agents)

    def queue(self, i: int, data: bytes) -> None:
        """Lockstep: queue agent ``i``'s command (serialised), and those waiting
        (:meth:`take_waiting`); take the queue once it can complete the step."""
        if self.inbox.put(i, data):
            self.take()
        self.take_waiting()

    def take_waiting(self) -> None:
        """Queue the commands waiting in the subscriptions (none here: each comes through
        its own callback)."""

    def take(self) -> None:
        """Lockstep: handle the queued commands, at once when they are the open step's
        command of every agent (:meth:`CommandInbox.take_step`: recorded here in their order
        of arrival), else message by message in the order they came
        (:meth:`~flock_swarm.nodes.recording.RecordedNode.take_recorded`,
        :meth:`on_command`: each judged, counted and recorded as it would have been on
        arrival).
        """
        node = self.node
        queue = self.inbox.take()
        if not queue:
            return
        k = self.inbox.take_step(queue)
        if k is not None:
            node.record_messages([self.topics[i] for i, _ in queue],
                                 [data for _, data in queue], node.clock.ns(k))
            self.closed()
            return
        for i, data in queue:
            node.take_recorded(self.topics[i], data, decode_accel, self.handlers[i])

    def on_command(self, i: int, msg: tuple) -> None:
        """Check agent ``i``'s command ``(stamp_ns, frame_id, linear)`` and hand it on."""
        ns, frame, lin = msg
        guard, st, topic = self.node.guard, self.stepper, self.topics[i]
        k = guard.check(topic, ns, frame, ((lin, guard.limits.accel),), window=st.window())
        if k is None:
            return
        if st.command(i, k, lin[:st.scenario.dim], time.monotonic()):
            guard.reject(topic, 'late', f'a command for step {k} at step {st.k}')
        self.closed()

    def release(self) -> None:
        """Let go of what holds the subscriptions (nothing here)."""

    def __len__(self) -> int:
        """Return how many commands are queued (lockstep)."""
        return len(self.inbox)

    def stalled(self) -> bool:
        """Return whether queued commands stopped coming for a tick (take them one by one)."""
        return self.inbox.stalled()


class BatchCommandIntake(CommandIntake):
    """Lockstep on the compiled path: every waiting command taken in one call when the first
    of a step comes (:class:`~flock_swarm.nodes.batch.BatchTake`).

    :ivar take_all: the extension's hold on the subscriptions.
    """

    def __init__(self, node, stepper: WorldStepper, closed: Callable[[], None]) -> None:
        """Subscribe, then hold the subscriptions in the extension."""
        super().__init__(node, stepper, closed)
        subs = {sub.topic_name: sub for sub in node.subscriptions}
        self.take_all = BatchTake([subs[name] for name in self.topics])

    def take_waiting(self) -> None:
        """Queue every command waiting in the subscriptions, taken in one call."""
        for j, more in self.take_all.take():
            if self.inbox.put(j, more):
                self.take()

    def release(self) -> None:
        """Release the extension's hold on the subscriptions."""
        release(self.take_all)


def command_intake(node, stepper: WorldStepper, closed: Callable[[], None],
                   c_path: bool) -> CommandIntake:
    """Return the world's command intake: the compiled path's (``c_path``, lockstep) or
    rclpy's."""
    return (BatchCommandIntake if c_path else CommandIntake)(node, stepper, closed)
