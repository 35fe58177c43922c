"""Plumbing shared by the leader, agent and world nodes: parameters, QoS, messages, time.

Every node reads the same scenario (parameter ``scenario``: a preset name or a path); any
other parameter whose name is a dotted scenario key overrides that single value, e.g.
``ros2 run flock_swarm agent --ros-args -p agent_id:=3 -p scenario:=demo -p protocol.c1:=0.8``.
Every parameter is then declared read-only with the value the node uses, every scenario key
included (:func:`load_scenario`), so the parameter services tell the truth about a run.
"""

import array
import copy
import dataclasses
import functools
import math
import re
import signal
import sys
from typing import Any, Callable

import numpy as np
import yaml
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.parameter import Parameter

from flock_swarm import contract
from flock_swarm.console import EXIT_USAGE
from flock_swarm.contract import (CLOCK, FRAME, LEADER_ACCEL, LEADER_ODOM, MARKERS,  # noqa: F401
                                  METRICS, RUNNING, STATUS, cmd_topic, odom_topic,
                                  qos_profile)
from flock_swarm.core.errors import ScenarioError, one_line
from flock_swarm.core.run import check_law_output
from flock_swarm.core.scenario import Scenario, parse_yaml, realize
from flock_swarm.presets import load, load_mapping

#: The topic contract's QoS as rclpy profiles (the names, types and QoS live in
#: :mod:`flock_swarm.contract`).
LOCKSTEP_QOS = qos_profile(contract.LOCKSTEP_QOS)
CLOCK_QOS = qos_profile(contract.CLOCK_QOS)
TELEMETRY_QOS = qos_profile(contract.TELEMETRY_QOS)
STATUS_QOS = qos_profile(contract.STATUS_QOS)

#: Parameters every rclpy node has; they are not scenario overrides.
ROS_PARAMS = {'use_sim_time', 'start_type_description_service'}


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


def plain(value: Any) -> Any:
    """Return a parameter value with its arrays as lists (rclpy gives ``array.array``)."""
    return list(value) if isinstance(value, (list, tuple, array.array, np.ndarray)) else value


def given(node: Node, name: str, default: Any) -> Any:
    """Return the value given for a node parameter (``-p``, a params file,
    ``parameter_overrides``), or ``default``; checked against the default's type.

    The value is checked as :func:`typed_value` says (not for :data:`FREE_TYPED` names).

    :raises ScenarioError: when the value is not of the default's type.
    """
    param = node._parameter_overrides.get(name)
    if param is None or param.type_ == Parameter.Type.NOT_SET:
        return default
    value = plain(param.value)
    return value if name in FREE_TYPED else typed_value(name, value, default)


def declare_value(node: Node, name: str, value: Any, description: str) -> None:
    """Declare a read-only parameter holding ``value``, the value the node works with.

    Every parameter is read once, at the start, so it is read-only: ``ros2 param set`` is
    refused with a reason instead of succeeding and being ignored (docs/ros.md).
    """
    node.declare_parameter(name, value, ParameterDescriptor(
        description=description, read_only=True, dynamic_typing=name in FREE_TYPED),
        ignore_override=True)


def declare(node: Node, name: str, default: Any, description: str) -> Any:
    """Declare a read-only node parameter with its given value (or ``default``); return it.

    :param node: the node.
    :param name: parameter name.
    :param default: default value (its type is the parameter's type).
    :param description: what it is, shown by ``ros2 param describe``.
    :return: the value.
    :raises ScenarioError: when the value is not of the default's type (see :func:`given`).
    """
    value = given(node, name, default)
    declare_value(node, name, value, description)
    return value


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


def scenario_overrides(node: Node, own: set[str], base: dict) -> dict[str, Any]:
    """Return the node's given parameters that override scenario keys (all but its own ones).

    A value a ROS parameter cannot hold (a nested list, an empty list or mapping, null) is
    given as a string of its YAML text (as :func:`scenario_parameters` declares it): a string
    for a key whose value in ``base`` is not a string is read as YAML when that gives such a
    value.

    :param node: the node.
    :param own: names of the node's own parameters.
    :param base: the scenario file's mapping.
    :return: ``{dotted.key: value}``.
    """
    out = {}
    for name, param in node._parameter_overrides.items():
        if name in own or name in ROS_PARAMS or name.startswith('qos_overrides.'):
            continue
        value = plain(param.value)
        if isinstance(value, str) and not isinstance(lookup(base, name), str):
            try:
                parsed = parse_yaml(value)
            except yaml.YAMLError:
                parsed = value
            if parsed is None or isinstance(parsed, (list, dict)):
                value = parsed
        out[name] = value
    return out


def lookup(data: dict, dotted: str) -> Any:
    """Return the value of a dotted key in a nested mapping (``None`` when absent)."""
    for part in dotted.split('.'):
        if not isinstance(data, dict):
            return None
        data = data.get(part)
    return data


#: The largest integer a ROS parameter holds (int64).
INT64_MAX = 2 ** 63 - 1


def parameter_value(value: Any) -> Any:
    """Return a scenario value as a ROS parameter value: scalars and flat arrays as they are
    (numbers of mixed types as floats), anything else as a string of its YAML flow text."""
    def fits(v: Any) -> bool:
        return (isinstance(v, (bool, float)) or (isinstance(v, str) and '\0' not in v)
                or (isinstance(v, int) and -INT64_MAX - 1 <= v <= INT64_MAX))
    if fits(value):
        return value
    if isinstance(value, list) and value and all(fits(v) for v in value):
        kinds = {bool if isinstance(v, bool) else str if isinstance(v, str) else 'number'
                 for v in value}
        if kinds == {'number'} and not all(isinstance(v, int) for v in value):
            return [float(v) for v in value]
        if len(kinds) == 1:
            return value
    text = yaml.safe_dump(value, default_flow_style=True, width=float('inf'))
    return text.removesuffix('\n...\n').strip()


def scenario_parameters(sc: Scenario) -> dict[str, Any]:
    """Return every scenario key a run uses as ``{dotted.key: parameter value}``.

    The keys of the scenario (its file and overrides) and the defaults it was given for the
    ones it left out: protocol gains, ``record_every``, metrics...; nested mappings become
    dotted names (``protocol.c1``). Given back as overrides, they reproduce the scenario.
    """
    data = copy.deepcopy(sc.raw)
    for key, value in (('name', sc.name), ('description', sc.description),
                       ('reference', sc.reference), ('seed', sc.seed),
                       ('record_every', sc.record_every)):
        data.setdefault(key, value)
    for section, defaults in (
            ('graph', {'type': sc.graph_type}),
            ('metrics', {'eta_tolerance': sc.eta_tolerance,
                         'collision_distance': sc.collision_distance}),
            ('protocol', {f.name: getattr(sc.law, f.name) for f in dataclasses.fields(sc.law)
                          if f.init and isinstance(getattr(sc.law, f.name),
                                                   (bool, int, float, str))})):
        if isinstance(data.get(section) or {}, dict):
            data[section] = dict(defaults, **(data.get(section) or {}))
    out: dict[str, Any] = {}

    def flatten(section: dict, prefix: str) -> None:
        for key, value in section.items():
            if isinstance(value, dict) and value:
                flatten(value, f'{prefix}{key}.')
            else:
                out[f'{prefix}{key}'] = parameter_value(value)
    flatten(data, '')
    return out


def load_scenario(node: Node, own: set[str]) -> Scenario:
    """Load the scenario named by the node's ``scenario`` parameter, with overrides.

    Declares the ``seed`` parameter with the seed of the run and every scenario key the run
    uses (:func:`scenario_parameters`) as read-only parameters, so that ``ros2 param dump``
    writes a file that reproduces the run.

    :param node: the node (``scenario`` already declared).
    :param own: names of the node's own parameters.
    :return: the validated scenario.
    :raises ScenarioError: on any invalid value.
    """
    name = node.get_parameter('scenario').value
    seed = given(node, 'seed', -1)
    if seed < -1:
        raise ScenarioError('seed', f'must be -1 (the scenario seed) or >= 0, got {seed!r}')
    extra = scenario_overrides(node, own, load_mapping(name))
    sc = load(name, seed=None if seed == -1 else seed, extra=extra)
    # A plugin law that raises or returns unusable commands fails here, in one line, not in
    # a callback of the running node.
    check_law_output(sc, realize(sc))
    declare_value(node, 'seed', sc.seed, 'random seed of the run (given as -1: the '
                  'scenario seed, and it reads back as that seed)')
    for key, value in scenario_parameters(sc).items():
        if key not in own and key != 'seed':
            declare_value(node, key, value, f'scenario key {key} (read at start)')
    return sc


def declare_common(node: Node) -> None:
    """Declare ``scenario``, ``mode`` and ``realtime_factor`` (``seed``: :func:`load_scenario`)."""
    declare(node, 'scenario', 'demo', 'scenario preset name or path to a YAML file')
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


def follow_world(node: Node) -> Callable[[], bool]:
    """Subscribe ``node`` to the world's ``swarm/status``; return whether it should stop.

    Declares ``keep_running`` (default false): when the world announces the end of its run,
    the node logs it and, unless ``keep_running`` is true, its ``run_node`` loop ends with
    exit status 0.

    :param node: a leader or agent node.
    :return: a predicate, true once the world finished and the node is not to keep running.
    """
    from std_msgs.msg import String
    keep = declare(node, 'keep_running', False,
                   'keep running after the world announced the end of its run on swarm/status')
    ended: list[str] = []

    def on_status(msg: String) -> None:
        if msg.data != RUNNING and not ended:
            ended.append(msg.data)
            node.get_logger().info(f'the world finished its run ({msg.data})' +
                                   ('' if keep else '; exiting'))
    node.create_subscription(String, STATUS, on_status, STATUS_QOS)
    return lambda: bool(ended) and not keep


def run_node(name: str, factory: Callable[[], Node], args: list[str] | None = None,
             until: Callable[[Node], bool] | None = None) -> int:
    """Run one node as in ros2/demos: init, spin, clean shutdown; return the exit status.

    Invalid configuration is reported as one line on stderr with exit status 2. The node
    spins on :func:`make_executor`'s executor. SIGINT and SIGTERM only end the spin: the
    context stays valid until the node is closed and destroyed, so no callback meets an
    invalid context (rclpy's own handlers shut it down under a running callback).

    :param name: executable name (prefix of error lines).
    :param factory: builds the node (after ``rclpy.init``).
    :param args: command-line arguments (``None``: ``sys.argv``).
    :param until: optional condition ending the spin (the world ends after its last step).
    :return: the exit status.
    """
    signalled: list[int] = []
    previous_handlers = {sig: signal.signal(sig, lambda number, frame: signalled.append(number))
                         for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _spin(name, factory, args, until, signalled)
    finally:
        for sig, handler in previous_handlers.items():
            signal.signal(sig, handler)


def _spin(name: str, factory: Callable[[], Node], args: list[str] | None,
          until: Callable[[Node], bool] | None, signalled: list[int]) -> int:
    """:func:`run_node` with its signal handlers installed (``signalled`` lists the signals)."""
    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.logging import LoggingSeverity, get_logger_level, set_logger_level
    from rclpy.signals import SignalHandlerOptions
    # rcl logs a line of its own for malformed arguments; the reason is in the error below.
    previous = get_logger_level('rcl')
    set_logger_level('rcl', LoggingSeverity.FATAL)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
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
        while not signalled and rclpy.ok() and (until is None or not until(node)):
            executor.spin_once(timeout_sec=0.1)
    except ScenarioError as exc:
        print(f'{name}: error: {exc}', file=sys.stderr)
        status = EXIT_USAGE
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
