"""Plumbing shared by the leader, agent and world nodes: parameters, QoS, messages, time.

Every node reads the same scenario (parameter ``scenario``: a preset name or a path); any
other parameter whose name is a dotted scenario key overrides that single value, e.g.
``ros2 run flock_swarm agent --ros-args -p agent_id:=3 -p scenario:=demo -p protocol.c1:=0.8``.
"""

import functools
import math
import re
import sys
from typing import Any, Callable

import numpy as np
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from flock_swarm.cli import EXIT_USAGE, accept_sigint
from flock_swarm.core.errors import ScenarioError, one_line
from flock_swarm.core.run import check_law_output
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.presets import load

#: Lockstep state and commands: reliable, because a lost odometry or command stalls the step
#: until its timeout; the depth covers a burst of one message per agent and step.
LOCKSTEP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
#: /clock: reliable so that every tick reaches the leader in lockstep mode.
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: Markers and metrics: reliable with a short queue, so RViz and Foxglove (which subscribe
#: reliable by default) match, and a slow viewer only ever lags by a few frames.
TELEMETRY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)

#: Parameters every rclpy node has; they are not scenario overrides.
ROS_PARAMS = {'use_sim_time', 'start_type_description_service'}
#: The fixed frame of every position (REP-103).
FRAME = 'world'


def odom_topic(i: int) -> str:
    """Return the odometry topic of agent ``i`` (relative: namespaces apply)."""
    return f'agent_{i}/odom'


def cmd_topic(i: int) -> str:
    """Return the command topic of agent ``i``."""
    return f'agent_{i}/cmd_accel'


LEADER_ODOM = 'leader/odom'
LEADER_ACCEL = 'leader/accel'
CLOCK = '/clock'
MARKERS = 'swarm/markers'
METRICS = 'swarm/metrics'


class StepClock:
    """Simulation time of step ``k``: ``t_k = k dt``, stamped exactly in integer nanoseconds."""

    def __init__(self, dt: float) -> None:
        """Create the clock for step ``dt`` seconds."""
        self.dt = dt
        self.dt_ns = int(round(dt * 1e9))

    def stamp(self, k: int) -> Time:
        """Return the stamp of step ``k``."""
        ns = k * self.dt_ns
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def ns(self, k: int) -> int:
        """Return ``t_k`` in nanoseconds."""
        return k * self.dt_ns

    def step_of(self, stamp: Time) -> int:
        """Return the step ``k`` of a stamp (nearest step)."""
        return self.step_at(stamp.sec * 1_000_000_000 + stamp.nanosec)

    def step_at(self, ns: int) -> int:
        """Return the step ``k`` nearest to time ``ns`` [ns] (exact integer arithmetic)."""
        return (2 * ns + self.dt_ns) // (2 * self.dt_ns)


#: Parameters that take more than their default's type and whose node checks the value
#: itself: ``agent_ids`` is a string of ids and ranges or an integer array.
FREE_TYPED = {'agent_ids'}


def declare(node: Node, name: str, default: Any, description: str) -> Any:
    """Declare a node parameter (unless an override already declared it) and return its value.

    An override is automatically declared with its own type, so the value is checked against
    the default's: a boolean, an integer, a number (an integer is taken for a float, NaN is
    not) or a string, as the default is.

    :param node: the node.
    :param name: parameter name.
    :param default: default value (its type is the parameter's type).
    :param description: what it is, shown by ``ros2 param describe``.
    :return: the value.
    :raises ScenarioError: when the value is not of the default's type.
    """
    if not node.has_parameter(name):
        node.declare_parameter(name, default, ParameterDescriptor(description=description))
    value = node.get_parameter(name).value
    return value if name in FREE_TYPED else typed_value(name, value, default)


def typed_value(name: str, value: Any, default: Any) -> Any:
    """Return ``value`` if it has the type of ``default`` (a float for a float default).

    :raises ScenarioError: naming ``name`` otherwise.
    """
    if isinstance(default, bool):
        ok, what = isinstance(value, bool), 'true or false'
    elif isinstance(default, int):
        ok, what = isinstance(value, int) and not isinstance(value, bool), 'an integer'
    elif isinstance(default, float):
        ok, what = (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and not math.isnan(value)), 'a number'
        value = float(value) if ok else value
    elif isinstance(default, str):
        # No NUL: rcl passes strings as C strings, and paths cannot hold one.
        ok, what = isinstance(value, str) and '\0' not in value, 'a string (without NUL)'
    else:
        return value
    if not ok:
        raise ScenarioError(name, f'expected {what}, got {value!r}')
    return value


def scenario_overrides(node: Node, own: set[str]) -> dict[str, Any]:
    """Return the node's parameters that override scenario keys (all but its own ones).

    :param node: a node created with ``automatically_declare_parameters_from_overrides``.
    :param own: names of the node's own parameters.
    :return: ``{dotted.key: value}``.
    """
    out = {}
    for name, param in node._parameters.items():
        if name in own or name in ROS_PARAMS or name.startswith('qos_overrides.'):
            continue
        value = param.value
        out[name] = list(value) if isinstance(value, (list, tuple, np.ndarray)) else value
    return out


def load_scenario(node: Node, own: set[str]) -> Scenario:
    """Load the scenario named by the node's ``scenario`` parameter, with overrides.

    :param node: the node (``scenario`` and ``seed`` parameters already declared).
    :param own: names of the node's own parameters.
    :return: the validated scenario.
    :raises ScenarioError: on any invalid value.
    """
    name = node.get_parameter('scenario').value
    seed = node.get_parameter('seed').value
    if not isinstance(seed, int) or seed < -1:
        raise ScenarioError('seed', f'must be -1 (the scenario seed) or >= 0, got {seed!r}')
    sc = load(name, seed=None if seed == -1 else seed, extra=scenario_overrides(node, own))
    # A plugin law that raises or returns unusable commands fails here, in one line, not in
    # a callback of the running node.
    check_law_output(sc, realize(sc))
    return sc


def declare_common(node: Node) -> None:
    """Declare the parameters every node has: ``scenario``, ``seed`` and ``mode``."""
    declare(node, 'scenario', 'demo', 'scenario preset name or path to a YAML file')
    declare(node, 'seed', -1, 'random seed; -1 keeps the scenario seed')
    mode = declare(node, 'mode', 'lockstep',
                   'lockstep (deterministic, world waits for every agent) or realtime')
    if mode not in ('lockstep', 'realtime'):
        raise ScenarioError('mode', f'must be lockstep or realtime, got {mode!r}')
    factor = declare(node, 'realtime_factor', 1.0,
                     'realtime mode: simulated seconds per wall second (same for every node)')
    if not math.isfinite(factor) or factor <= 0:
        raise ScenarioError('realtime_factor', f'must be finite and > 0, got {factor!r}')


def timer_period(node: Node, dt: float) -> float:
    """Return the wall-clock period of a realtime-mode timer for simulation step ``dt``."""
    return dt / node.get_parameter('realtime_factor').value


COMMON_PARAMS = {'scenario', 'seed', 'mode', 'realtime_factor'}


def command_claims(node: Node, n_agents: int) -> dict[int, list[tuple[str, str]]]:
    """Return, for each agent whose ``agent_<i>/cmd_accel`` has a publishing node, the
    ``(namespace, name)`` of every such node (sorted).

    One graph query per node of the graph, not one per agent topic: each query walks the
    whole graph cache, so asking topic by topic cost O(N^2) per call (116 ms at N = 1000,
    made every second by the world and by every agent host, and every 10 ms by the world
    while it waits for the start; docs/performance.md). A node that left the graph between
    the two queries is skipped.

    :param node: the node asking (its namespace resolves the topics).
    :param n_agents: the swarm's size.
    """
    index = _command_topics(node.resolve_topic_name(cmd_topic(0)), n_agents)
    claims: dict[int, set[tuple[str, str]]] = {}
    for name, namespace in set(node.get_node_names_and_namespaces()):
        try:
            topics = node.get_publisher_names_and_types_by_node(name, namespace)
        except NodeNameNonExistentError:
            continue
        for topic, _ in topics:
            i = index.get(topic)
            if i is not None:
                claims.setdefault(i, set()).add((namespace, name))
    return {i: sorted(nodes) for i, nodes in claims.items()}


@functools.lru_cache(maxsize=8)
def _command_topics(first: str, n_agents: int) -> dict[str, int]:
    """Return ``{resolved agent_<i>/cmd_accel: i}`` given the resolved topic of agent 0."""
    head, _, tail = first.rpartition(cmd_topic(0))
    return {f'{head}{cmd_topic(i)}{tail}': i for i in range(n_agents)}


def agent_hosts(node: Node, n_agents: int) -> int | None:
    """Return how many nodes host the swarm's agents, or ``None`` while one is not there yet.

    A host is a node publishing on some ``agent_<i>/cmd_accel``: an agent node, or a
    container hosting many agents. Each host subscribes to every odometry topic and to the
    leader's, so the counts the world and the leader wait for follow from it.

    :param node: the node asking (its namespace resolves the topics).
    :param n_agents: the swarm's size.
    :return: the number of distinct hosting nodes, or ``None`` if some agent has none.
    """
    claims = command_claims(node, n_agents)
    if len(claims) < n_agents:
        return None
    return len(set().union(*claims.values()))


def make_executor(context=None):
    """Return the executor every node and runner spins: rclpy's ``EventsExecutor``.

    It delivers about twice the messages per second of ``SingleThreadedExecutor`` on the
    project's 2-core machines (docs/performance.md).
    """
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def run_node(name: str, factory: Callable[[], Node], args: list[str] | None = None,
             until: Callable[[Node], bool] | None = None) -> int:
    """Run one node as in ros2/demos: init, spin, clean shutdown; return the exit status.

    Invalid configuration is reported as one line on stderr with exit status 2. The node
    spins on :func:`make_executor`'s executor.

    :param name: executable name (prefix of error lines).
    :param factory: builds the node (after ``rclpy.init``).
    :param args: command-line arguments (``None``: ``sys.argv``).
    :param until: optional condition ending the spin (the world ends after its last step).
    :return: the exit status.
    """
    accept_sigint()
    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.logging import LoggingSeverity, get_logger_level, set_logger_level
    # rcl logs a line of its own for malformed arguments; the reason is in the error below.
    previous = get_logger_level('rcl')
    set_logger_level('rcl', LoggingSeverity.FATAL)
    try:
        rclpy.init(args=args)
    except rclpy_implementation.RCLError as exc:
        set_logger_level('rcl', previous)
        reason = str(exc).removeprefix('failed to initialize rcl: ')
        if "Couldn't parse" not in reason:
            raise
        # A malformed --ros-args rule ('-p key' without ':=', unparsable YAML, a missing
        # params file): rcl's message, without the C source locations it appends.
        reason = re.split(r'(?:\. Error: |, at /)', reason, maxsplit=1)[0]
        print(f'{name}: error: --ros-args: {one_line(reason)}', file=sys.stderr)
        return EXIT_USAGE
    if get_logger_level('rcl') == LoggingSeverity.FATAL:
        # Unless --ros-args --log-level set the rcl logger's level itself.
        set_logger_level('rcl', previous)
    node = None
    executor = None
    status = 0
    try:
        node = factory()
        executor = make_executor()
        executor.add_node(node)
        while rclpy.ok() and (until is None or not until(node)):
            executor.spin_once(timeout_sec=0.1)
    except ScenarioError as exc:
        print(f'{name}: error: {exc}', file=sys.stderr)
        status = EXIT_USAGE
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A signal shuts the context down asynchronously: a callback that was publishing at
        # that moment fails with "context is invalid". That is the shutdown, not a fault.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status
