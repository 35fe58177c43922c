"""The batched transport's node side: the world's state cloud out and the hosts' command
clouds in, and an agents host's state cloud in and command cloud out (docs/ros.md,
"Transports"; the codec is :mod:`flock_swarm.nodes.cloud`).

``transport: per_agent`` (the default) moves a step as ``N`` odometry messages to every host
and ``N`` commands (and adaptive states) back, one topic per agent. ``transport: batched``
moves the same numbers as one :data:`~flock_swarm.nodes.cloud.STATES` message a step from
the world and one :data:`~flock_swarm.nodes.cloud.COMMANDS` message a step from each agents
host (its agents' accelerations and adaptive states); the leader's topics are unchanged.
Every agent's law still sees only the neighbours within its radius: the hosts evaluate the
same :class:`~flock_swarm.nodes.controller.AgentController` on the same numbers, so a
lockstep run equals ``sim`` and the per-agent run bit for bit.

:func:`batched_state_publisher` and :class:`BatchedCommandIntake` are the world's strategies
(beside :mod:`flock_swarm.nodes.world_io`'s per-agent ones: the state out and the commands in,
handed to the :class:`~flock_swarm.nodes.stepper.WorldStepper`); :class:`StateCloud` is what
an agents host makes of a state cloud, :func:`host_commands` what it sends. Each message is
checked as the per-agent messages are (frame, stamp on the step grid, the step window,
finiteness and magnitude), with NumPy over the whole message, and through
:class:`~flock_swarm.nodes.guard.InputGuard` so that a rejection is counted and logged the
same way.
"""

import sys
import time
from typing import Callable

import numpy as np
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2

from flock_swarm.contract import CLOCK, CLOCK_QOS, FRAME, LOCKSTEP_QOS, qos_profile
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.scenario import TRANSPORTS, Scenario
from flock_swarm.nodes.cloud import (BATCHED, COMMANDS, PER_AGENT, STATES, TWIST_FIELDS,
                                     CloudEncoder, command_fields, decode_cloud, state_fields)
from flock_swarm.nodes.guard import InputGuard
from flock_swarm.nodes.inbox import StepInbox
from flock_swarm.nodes.stepper import WorldStepper
from flock_swarm.nodes.world_io import CommandIntake, StatePublisher
from flock_swarm.nodes.parameters import Param
from flock_swarm.nodes.wire import AccelBatch, MalformedMessage

#: The world's and the agents' ``transport`` parameter.
TRANSPORT = Param('transport', '', "'' (the scenario's transport key), per_agent (one odometry "
                  'and one command topic per agent) or batched (the swarm\'s state as one '
                  'PointCloud2 on swarm/states, each host\'s commands as one on swarm/commands)',
                  lambda v: v in ('', *TRANSPORTS),
                  "must be '', 'per_agent' or 'batched', got {value!r}")


def transport_of(sc: Scenario, override: str, mode: str) -> str:
    """Return the transport a node uses: its ``transport`` parameter if set, else the
    scenario's ``transport``.

    :param sc: the scenario.
    :param override: the node's ``transport`` parameter (``''``: the scenario's).
    :param mode: ``lockstep`` or ``realtime``.
    :raises ScenarioError: naming ``transport`` for what the batched transport does not
        carry: the realtime reports of the network model.
    """
    transport = override or sc.transport
    if transport != BATCHED:
        return PER_AGENT
    if mode == 'realtime' and sc.network.active:
        raise ScenarioError('transport', "batched in realtime carries no network reports: a "
                            "network: section in realtime needs transport 'per_agent'")
    return transport


def stamped_cloud(data: bytes) -> tuple:
    """Return ``(stamp_ns, cloud)`` of a serialised PointCloud2 (a recorded subscription's
    decoder: the stamp first, :meth:`~flock_swarm.nodes.recording.RecordedNode.take_recorded`)."""
    cloud = decode_cloud(data)
    return cloud.stamp_ns, cloud


def _within(array: np.ndarray, limit: float) -> bool:
    """Return whether every value of ``array`` is finite and within ``[-limit, limit]``."""
    return bool((np.abs(array) <= limit).all())


def check_cloud(guard: InputGuard, topic: str, ns: int, frame: str,
                values: tuple[tuple[np.ndarray, float], ...],
                window: tuple[int, int] | None = None, ordered: bool = True) -> int | None:
    """Return the step of an acceptable cloud, or ``None`` (rejected and counted).

    The values are checked with NumPy at once; only a message that fails goes through the
    guard's value by value check, which names the fault as it would for one agent's message.

    :param values: ``(array, limit)`` pairs.
    """
    if frame == FRAME and all(_within(array, limit) for array, limit in values):
        return guard.check(topic, ns, frame, (), window=window, ordered=ordered)
    return guard.check(topic, ns, frame, tuple((array.ravel().tolist(), limit)
                                               for array, limit in values),
                       window=window, ordered=ordered)


class StateCloud:
    """An agents host's view of the world's state cloud: the vectors its controller takes.

    :meth:`decode` gives ``(step, vectors)``: ``(N, 2, dim)`` (positions, velocities) or, for
    an oriented plant, ``(N, 4, dim)`` with ``(qz, qw)`` and ``(yaw rate, 0)``: what the
    per-agent odometry gives (:func:`flock_swarm.nodes.wire.odometry_rows`).
    """

    def __init__(self, n_agents: int, dim: int, oriented: bool, guard: InputGuard) -> None:
        """Prepare for a swarm of ``n_agents`` in ``dim`` dimensions."""
        self.n, self.dim, self.oriented, self.guard = n_agents, dim, oriented, guard
        self.fields = state_fields(dim, oriented)
        self.order = np.arange(n_agents)

    def decode(self, topic: str, data: bytes, ordered: bool) -> tuple[int, np.ndarray] | None:
        """Return the step and the vectors of a state cloud, or ``None`` (rejected).

        :param topic: the topic it came on (the guard's counts name it).
        :param ordered: reject a stamp older than the latest (realtime).
        """
        guard = self.guard
        try:
            cloud = decode_cloud(data)
            values, ids = cloud.columns(self.fields), cloud.ids()
        except MalformedMessage as exc:
            guard.reject(topic, 'malformed', str(exc))
            return None
        if not np.array_equal(ids, self.order):
            if len(ids) != self.n or not np.array_equal(np.sort(ids), self.order):
                guard.reject(topic, 'malformed', f'{len(ids)} points, not one of each of the '
                             f'{self.n} agents')
                return None
            values = values[np.argsort(ids)]
        dim, lim = self.dim, guard.limits
        k = check_cloud(guard, topic, cloud.stamp_ns, cloud.frame_id,
                        ((values[:, :dim], lim.position), (values[:, dim:2 * dim], lim.velocity)),
                        ordered=ordered)
        if k is None:
            return None
        rows = np.zeros((self.n, 4 if self.oriented else 2, dim))
        rows[:, 0], rows[:, 1] = values[:, :dim], values[:, dim:2 * dim]
        if self.oriented:
            rows[:, 2], rows[:, 3, 0] = values[:, 2 * dim:2 * dim + 2], values[:, 2 * dim + 2]
        return k, rows


class StateEncoder:
    """The world's state cloud of a step from the odometry vectors
    (:func:`~flock_swarm.nodes.wire.odometry_rows`): ``encode(ns, *rows)`` gives a list of
    one message, as :class:`~flock_swarm.nodes.wire.OdometryBatchEncoder` gives ``N``."""

    def __init__(self, n_agents: int, dim: int, oriented: bool) -> None:
        """Prepare the encoder of ``n_agents`` agents."""
        self.encoder = CloudEncoder(state_fields(dim, oriented))
        self.ids = np.arange(n_agents)

    def encode(self, ns: int, q: np.ndarray, p: np.ndarray, *heading: np.ndarray) -> list[bytes]:
        """Return ``[cloud]`` stamped ``ns`` [ns] (an oriented plant's heading rows too)."""
        columns = [q, p]
        if heading:
            columns += [heading[0], heading[1][:, :1]]
        return [self.encoder.encode(ns, self.ids, np.concatenate(columns, axis=1))]


def batched_state_publisher(node, stepper: WorldStepper) -> StatePublisher:
    """Return the world's state out with the batched transport: ``/clock`` and the state
    cloud (:data:`~flock_swarm.contract.STATES`), both recorded, two messages a step."""
    sc, plant = stepper.scenario, stepper.plant
    pubs = [node.recorded_publisher(Clock, CLOCK, qos_profile(CLOCK_QOS)),
            node.recorded_publisher(PointCloud2, STATES, qos_profile(LOCKSTEP_QOS))]
    return StatePublisher(node, stepper, pubs, StateEncoder(
        sc.n_agents, sc.dim, plant is not None and plant.oriented))


class BatchedCommandIntake(CommandIntake):
    """The hosts' command clouds in (:data:`~flock_swarm.contract.COMMANDS`): one recorded
    subscription, each cloud checked at once and its rows handed to the stepper with the
    adaptive states and velocity commands it carries. No agent has a topic of its own
    (:attr:`topics` is empty: the world subscribes to no per-agent family).

    :ivar commands_topic: the resolved topic of the command clouds.
    """

    def __init__(self, node, stepper: WorldStepper, closed: Callable[[], None]) -> None:
        """Subscribe to the command clouds (``node``, ``stepper``, ``closed``: see
        :class:`~flock_swarm.nodes.world_io.CommandIntake`)."""
        self.node, self.stepper, self.closed = node, stepper, closed
        self.handlers, self.topics = [], []
        # Empty for good: each cloud is handled as it comes (the lockstep timer asks it).
        self.inbox = StepInbox(0, AccelBatch(0))
        self.inbox.steps_at_once = 0
        sc = stepper.scenario
        self.accel = command_fields(sc.dim)
        self.labels = stepper.state_labels
        self.twist = TWIST_FIELDS if stepper.velocity else ()
        self.commands_topic = node.recorded_subscription(PointCloud2, COMMANDS, stamped_cloud,
                                                         self.on_cloud)

    def hosts(self) -> list[tuple[str, str]]:
        """Return the ``(namespace, name)`` of every node publishing command clouds."""
        return sorted({(i.node_namespace, i.node_name) for i in
                       self.node.get_publishers_info_by_topic(self.commands_topic)
                       if not i.node_name.startswith('_NODE_NAME_UNKNOWN')})

    def claims(self, n_agents: int) -> dict[int, list[tuple[str, str]]]:
        """Return the nodes commanding each agent as the graph tells it: every node
        publishing command clouds for every agent (the clouds, not the graph, say which
        agents each commands), or none while there is no such node."""
        hosts = self.hosts()
        return {i: hosts for i in range(n_agents)} if hosts else {}

    def take(self) -> None:
        """Nothing is queued: each cloud is handled as it comes."""

    def on_cloud(self, msg: tuple) -> None:
        """Check a host's command cloud (``(stamp_ns, cloud)``: decoded, recorded) and hand
        its rows to the stepper."""
        cloud = msg[1]
        node, topic = self.node, self.commands_topic
        st, guard = self.stepper, node.guard
        n = st.scenario.n_agents
        try:
            ids = cloud.ids()
            u = cloud.columns(self.accel)
            state = cloud.columns(self.labels) if self.labels else None
            twist = cloud.columns(self.twist) if self.twist else None
        except MalformedMessage as exc:
            guard.reject(topic, 'malformed', str(exc))
            return
        if len(ids) == 0 or ids.min() < 0 or ids.max() >= n or len(np.unique(ids)) != len(ids):
            guard.reject(topic, 'malformed', f'ids not distinct agents of [0, {n - 1}]: '
                         f'{ids[:8].tolist()}')
            return
        values = ((u, guard.limits.accel),)
        if state is not None:
            # A law's adaptive state may take any finite value (the per-agent topics' rule).
            values += ((state, sys.float_info.max),)
        if twist is not None:
            # A velocity command too (as on cmd_vel: only a non-finite one is rejected).
            values += ((twist, sys.float_info.max),)
        k = check_cloud(guard, topic, cloud.stamp_ns, cloud.frame_id, values,
                        window=st.window())
        if k is None:
            return
        now, rows = time.monotonic(), ids.tolist()
        if state is not None:
            for i, values in zip(rows, state):
                st.agent_state(i, k, values)
        if twist is not None and (not st.lockstep or k == st.k):
            # A Twist answers the open step (a repeated cloud of the step before does not).
            for i, values in zip(rows, twist):
                st.twist(i, values[:3], values[3:], now)
        if st.lockstep and k == st.k and len(ids) == n and (ids == np.arange(n)).all():
            # One host commanding every agent: the step's commands at once.
            st.commands_all(k, u)
        else:
            late = [i for i, row in zip(rows, u) if st.command(i, k, row, now)]
            if late:
                guard.reject(topic, 'late', f'commands of agents {late[:8]} for step {k} at '
                             f'step {st.k}')
        self.closed()


def host_commands(encoder: CloudEncoder, ids: np.ndarray, ns: int, u: np.ndarray,
                  state: Callable[[], np.ndarray] | None,
                  twist: Callable[[], tuple[np.ndarray, np.ndarray]] | None) -> bytes:
    """Return an agents host's command cloud stamped ``ns`` [ns] for the agents ``ids``:
    ``u`` (``(m, dim)``), for a law with adaptive state ``state()`` (``(m, labels)``), for a
    robot plant commanded by velocity ``twist()`` (``(linear, angular)``, ``(m, 3)`` each)."""
    values = [u]
    if state is not None:
        values.append(state())
    if twist is not None:
        values.extend(twist())
    return encoder.encode(ns, ids, np.concatenate(values, axis=1))
