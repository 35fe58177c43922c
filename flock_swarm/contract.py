"""The topic contract of flock_swarm: every topic's name, message type and QoS, in one place.

The nodes, the recorder, the live view (``--foxglove``), ``analyze``, ``replay`` and the
process launcher all read the topics from here (docs/ros.md, "Topics").
This module imports no rclpy: names and types are plain strings, and a QoS is a small
frozen :class:`QosSpec` that :func:`qos_profile` turns into an rclpy ``QoSProfile`` where a
node needs one. Topic names are relative (namespaces apply) except ``/clock``.
"""

from dataclasses import dataclass
import math
import re
from typing import Mapping

#: The fixed frame of every position (REP-103).
FRAME = 'world'

#: Message types of the contract (``pkg/msg/Type``), standard messages only.
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
ODOMETRY_TYPE = 'nav_msgs/msg/Odometry'
ACCEL_TYPE = 'geometry_msgs/msg/AccelStamped'
#: A robot's velocity command (``cmd_vel``): the robots' convention, unstamped; body frame
#: for a unicycle, world frame for a holonomic robot (REP 103/105, docs/plants.md).
TWIST_TYPE = 'geometry_msgs/msg/Twist'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
METRICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
STATUS_TYPE = 'std_msgs/msg/String'
#: A law's adaptive per-agent state: stamped like a command (the world matches it to its step
#: as it matches commands), the state's labels in ``name`` and its values in ``position``
#: (``velocity`` and ``effort`` empty). ``std_msgs/Float64MultiArray`` carries no header,
#: so its step would rest on the order in which DDS delivers two topics, which it does not
#: keep (docs/ros.md, "Topics").
STATE_TYPE = 'sensor_msgs/msg/JointState'

#: The simulation clock (REP-2008), global whatever the namespace.
CLOCK = '/clock'
LEADER_ODOM = 'leader/odom'
LEADER_ACCEL = 'leader/accel'
MARKERS = 'swarm/markers'
METRICS = 'swarm/metrics'
#: Where rqt_robot_monitor and diagnostic_aggregator look (REP 107's aggregator input,
#: absolute): the world publishes every ``/swarm/metrics`` message there too, the same
#: bytes, type :data:`METRICS_TYPE`, QoS :data:`TELEMETRY_QOS`; not recorded (the bag holds
#: them on ``/swarm/metrics``).
DIAGNOSTICS = '/diagnostics'
STATUS = 'swarm/status'
#: The run's scenario, seed and informed set (what the bag's ``flock_swarm`` MCAP metadata
#: record holds) as a YAML mapping, published once, latched, and recorded at t = 0: it
#: survives tools that drop MCAP metadata (``rosbags-convert``) and ``ros2 topic echo`` shows
#: it to a late joiner.
SCENARIO = 'swarm/scenario'
SCENARIO_TYPE = STATUS_TYPE
#: The obstacle map of a scenario with ``obstacles:`` (docs/obstacles.md): one marker per
#: obstacle (:data:`MARKERS_TYPE`: RViz and Foxglove draw it as it is, where a custom type
#: would need a plugin), published once by the world, latched, and recorded at t = 0 beside
#: ``/swarm/scenario`` (which holds the exact map ``analyze`` reads); not published without
#: obstacles.
OBSTACLES = 'swarm/obstacles'
OBSTACLES_TYPE = MARKERS_TYPE
#: Faults the leader and the agent nodes report to the world (not recorded in the bag:
#: ``summary.json`` tells them); type :data:`METRICS_TYPE`, QoS :data:`FAULTS_QOS`.
FAULTS = 'swarm/faults'
#: The robot agents' emergency stop (``robot_agent``, docs/robots.md): absolute, so one
#: message stops every robot agent whatever its namespace; QoS :data:`ESTOP_QOS`.
ESTOP = '/swarm/estop'
ESTOP_TYPE = 'std_msgs/msg/Bool'
#: A robot's own topics (``robot_agent``, ``engine_robots``, docs/robots.md), ``{robot}``
#: standing for its name (its namespace): its odometry (QoS :data:`SENSOR_QOS`) and its
#: velocity command (:data:`TWIST_TYPE`, QoS :data:`ROBOT_CMD_QOS`); the robot agent's
#: defaults, a robot profile may map them elsewhere.
ROBOT_ODOM = '{robot}/odom'
ROBOT_CMD_VEL = '{robot}/cmd_vel'
#: The batched transport (``transport: batched``, docs/ros.md "Transports"): the whole
#: swarm's state of a step as one message of the world, and each agents host's commands (and
#: adaptive states) of a step as one message, instead of the per-agent odometry and command
#: topics (:mod:`flock_swarm.nodes.cloud` has the fields).
STATES = 'swarm/states'
COMMANDS = 'swarm/commands'
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'
#: The world's status while it runs; any other is the end of the run (``summary.json``).
RUNNING = 'running'
#: The name of the one status of ``/swarm/metrics``'s DiagnosticArray.
METRICS_STATUS = 'flock_swarm/metrics'

#: An agent's name from its index ``{i}``: its node's name (one agent a node), its topics'
#: prefix, a robot's default name (``robot_pattern``).
AGENT_PATTERN = 'agent_{i}'

#: An agent topic of the contract, absolute, in any namespace: ``<ns>/agent_<i>/<kind>``.
AGENT_TOPIC = re.compile(
    r'^(?P<ns>(?:/[^/]+)*?)/agent_(?P<id>\d+)/(?P<kind>odom|cmd_accel|state)$')


def agent_name(i: int) -> str:
    """Return the name of agent ``i`` (:data:`AGENT_PATTERN`): ``agent_<i>``."""
    return AGENT_PATTERN.format(i=i)


def odom_topic(i: int) -> str:
    """Return the odometry topic of agent ``i`` (relative: namespaces apply)."""
    return f'{agent_name(i)}/odom'


def cmd_topic(i: int) -> str:
    """Return the command topic of agent ``i`` (relative: namespaces apply)."""
    return f'{agent_name(i)}/cmd_accel'


def cmd_vel_topic(i: int) -> str:
    """Return the velocity-command topic of agent ``i`` (relative: namespaces apply).

    Only the agents of a robot plant commanded by velocity (``plant.command: cmd_vel``)
    publish it, beside ``cmd_accel`` (the law's acceleration, recorded).
    """
    return f'{agent_name(i)}/cmd_vel'


def state_topic(i: int) -> str:
    """Return the adaptive-state topic of agent ``i`` (relative: namespaces apply).

    Optional: only the agents of a law with adaptive state publish it.
    """
    return f'{agent_name(i)}/state'


def network_topic(i: int) -> str:
    """Return the topic of agent ``i``'s network report (relative: namespaces apply).

    Optional: published in realtime mode with an active ``network:`` section only, type
    :data:`STATE_TYPE`, one message per command, stamped like it, its names
    :data:`flock_swarm.core.network.USAGE_LABELS` (``docs/network.md``).
    """
    return f'{agent_name(i)}/network'


def state_slices(shapes: Mapping[str, tuple[int, ...]]
                 ) -> tuple[tuple[str, tuple[int, ...], slice], ...]:
    """Return where each adaptive state is among one agent's values (:func:`state_labels`).

    :param shapes: ``{state key: shape of one agent's value}``, in the law's order.
    :return: ``(key, shape, slice of the values)`` per key, in order.
    """
    out, start = [], 0
    for key, shape in shapes.items():
        size = math.prod(shape)
        out.append((key, tuple(shape), slice(start, start + size)))
        start += size
    return tuple(out)


def state_labels(shapes: Mapping[str, tuple[int, ...]]) -> tuple[str, ...]:
    """Return the labels of one agent's adaptive state, in order (``JointState.name``).

    A scalar state (``sim``'s series ``K x N``) is labelled by its key (``h``); any other
    by its key and the flat index of each value, row-major (``e[0]``, ``e[1]``: a state of
    shape ``(2,)`` per agent, series ``K x N x 2``).

    :param shapes: ``{state key: shape of one agent's value}``, in the law's order.
    """
    labels: list[str] = []
    for key, shape, part in state_slices(shapes):
        labels += [key] if shape == () else [f'{key}[{j}]'
                                             for j in range(part.stop - part.start)]
    return tuple(labels)


@dataclass(frozen=True)
class QosSpec:
    """A QoS of the contract: KEEP_LAST history of ``depth``, reliability and durability.

    :ivar depth: the history depth.
    :ivar reliable: ``RELIABLE`` (``True``) or ``BEST_EFFORT``.
    :ivar latched: ``TRANSIENT_LOCAL`` (``True``) or ``VOLATILE``.
    """

    depth: int
    reliable: bool = True
    latched: bool = False


#: Lockstep state and commands: reliable, because a lost odometry or command stalls the step
#: until its timeout; the depth covers a burst of one message per agent and step.
LOCKSTEP_QOS = QosSpec(depth=100)
#: /clock: reliable, because a reliable offer matches both reliable subscribers (this
#: package's nodes) and best-effort ones (rclpy's and rclcpp's time sources); volatile, so a
#: late joiner does not receive stale times; a short queue, since only the latest time matters.
CLOCK_QOS = QosSpec(depth=10)
#: Markers and metrics: reliable with a short queue, so RViz and Foxglove (which subscribe
#: reliable by default) match, and a slow viewer only ever lags by a few frames.
TELEMETRY_QOS = QosSpec(depth=5)
#: /swarm/status: latched (transient local), so a leader or agent that subscribes after the
#: world announced the end of the run still learns it.
STATUS_QOS = QosSpec(depth=1, latched=True)
#: /swarm/scenario: latched (transient local), published once before the run.
SCENARIO_QOS = QosSpec(depth=1, latched=True)
#: /swarm/obstacles: latched (transient local), published once before the run, so a viewer
#: started later still gets the map.
OBSTACLES_QOS = QosSpec(depth=1, latched=True)
#: /swarm/faults: reliable, and latched (transient local) so that a world that matches a
#: failed node late still learns its fault; the depth covers a run of non-finite commands
#: reported step after step.
FAULTS_QOS = QosSpec(depth=10, latched=True)
#: The e-stop's subscriptions, one per durability: latched (transient local), so a robot
#: agent started after a latched publisher engaged the stop sees it, and volatile, because a
#: transient-local subscription ignores a volatile publisher (``ros2 topic pub``'s default)
#: while a volatile one matches both (a latched publisher's message comes through both).
ESTOP_QOS = (QosSpec(depth=1, latched=True), QosSpec(depth=1))
#: What a robot's driver publishes and a robot agent subscribes (its own and the others'
#: odometry, the leader's state): ROS's sensor-data profile (``qos_profile_sensor_data``:
#: best effort, depth 5, volatile).
SENSOR_QOS = QosSpec(depth=5, reliable=False)
#: A robot's velocity command: reliable, depth 1 (only the newest command matters to a
#: robot's driver).
ROBOT_CMD_QOS = QosSpec(depth=1)
#: A viewer's bridge: best effort, so a viewer never makes a writer wait for its
#: acknowledgements (it matches the reliable writers of the contract); the depth covers a
#: step's burst.
BRIDGE_QOS = QosSpec(depth=100, reliable=False)


def qos_profile(spec: QosSpec):
    """Return the rclpy ``QoSProfile`` of a contract QoS (imports rclpy on first use).

    :param spec: the contract's QoS.
    :return: an ``rclpy.qos.QoSProfile``.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=spec.depth,
        reliability=(ReliabilityPolicy.RELIABLE if spec.reliable
                     else ReliabilityPolicy.BEST_EFFORT),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.latched
                    else DurabilityPolicy.VOLATILE))


@dataclass(frozen=True)
class Topic:
    """One topic of the contract.

    :ivar name: the topic name (relative unless it starts with ``/``).
    :ivar type: the message type, ``pkg/msg/Type``.
    :ivar qos: its QoS.
    :ivar publisher: the node that publishes it.
    """

    name: str
    type: str
    qos: QosSpec
    publisher: str


def contract(n_agents: int, state: bool = False, velocity: bool = False,
             batched: bool = False) -> list[Topic]:
    """Return every topic of the contract for ``n_agents`` agents, ``/clock`` first.

    The recorded topics of a bag, in the order the live view advertises them.

    :param n_agents: the number of agents.
    :param state: whether the law has adaptive state (the agents publish it then).
    :param velocity: whether the agents publish velocity commands (``cmd_vel``).
    :param batched: the batched transport: :data:`STATES` and :data:`COMMANDS` instead of
        the per-agent topics (which carry the state and velocity commands then).
    """
    topics = [Topic(CLOCK, CLOCK_TYPE, CLOCK_QOS, 'world'),
              Topic(LEADER_ODOM, ODOMETRY_TYPE, LOCKSTEP_QOS, 'leader'),
              Topic(LEADER_ACCEL, ACCEL_TYPE, LOCKSTEP_QOS, 'leader')]
    if batched:
        topics += [Topic(STATES, CLOUD_TYPE, LOCKSTEP_QOS, 'world'),
                   Topic(COMMANDS, CLOUD_TYPE, LOCKSTEP_QOS, 'agents')]
    for i in range(0 if batched else n_agents):
        topics += [Topic(odom_topic(i), ODOMETRY_TYPE, LOCKSTEP_QOS, 'world'),
                   Topic(cmd_topic(i), ACCEL_TYPE, LOCKSTEP_QOS, agent_name(i))]
        if state:
            topics.append(Topic(state_topic(i), STATE_TYPE, LOCKSTEP_QOS, agent_name(i)))
        if velocity:
            topics.append(Topic(cmd_vel_topic(i), TWIST_TYPE, LOCKSTEP_QOS, agent_name(i)))
    topics += [Topic(MARKERS, MARKERS_TYPE, TELEMETRY_QOS, 'world'),
               Topic(METRICS, METRICS_TYPE, TELEMETRY_QOS, 'world')]
    return topics


def absolute(name: str, namespace: str = '/') -> str:
    """Return a contract topic's absolute name in ``namespace`` (``/clock`` stays global).

    :param name: a topic of the contract.
    :param namespace: the nodes' namespace (``/``: none).
    """
    if name.startswith('/'):
        return name
    return f"{namespace.rstrip('/')}/{name}"


def contract_topics(n_agents: int, namespace: str = '/', state: bool = False,
                    batched: bool = False) -> list[tuple[str, str]]:
    """Return ``(absolute topic, pkg/msg/Type)`` of the contract's topics, ``/clock`` first.

    :param n_agents: number of agents.
    :param namespace: the namespace the nodes run in (``/``: none).
    :param state: whether the law has adaptive state (:func:`contract`).
    :param batched: the batched transport's topics (:func:`contract`).
    """
    return [(absolute(t.name, namespace), t.type)
            for t in contract(n_agents, state, batched=batched)]
