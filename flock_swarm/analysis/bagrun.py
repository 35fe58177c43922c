"""A run rebuilt from its bag: :func:`load_run` reads a rosbag2 MCAP bag into :class:`RunData`.

Every step of a run is rebuilt from the agents' odometry and commands, the leader's state and
a law's adaptive state (grouped by header stamp, ``t_k = k dt``). The scenario stored in the
bag (MCAP metadata record ``flock_swarm``) gives ``dt``, the radius and the tolerances; bags
without that record (any rosbag2 bag with ``/agent_<i>/odom`` topics) are read with a radius
and tolerances given by the caller (``analyze --radius``...). The topic names and types are
the contract's (:mod:`flock_swarm.contract`).
"""

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
import itertools
import json
from pathlib import Path
import struct
import time
from typing import Any

import numpy as np
import yaml

from flock_swarm import contract
from flock_swarm.bag import BagError, BagMessage, BagReader
from flock_swarm.bag.reader import UndecodableMessage
from flock_swarm.core.errors import ScenarioError, one_line
from flock_swarm.core.network_stats import STATISTICS
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.nodes.cloud import ID, TWIST_FIELDS, decode_cloud
from flock_swarm.nodes.recording import END_RECORD
from flock_swarm.nodes.wire import (decode_accel, decode_odometry_state, decode_state,
                                    MalformedMessage, POSE_BYTES)
from flock_swarm.presets import reread
from flock_swarm.scenario_yaml import parse_yaml

#: Name of the MCAP metadata record in which the world node stores the scenario as run.
METADATA_RECORD = 'flock_swarm'
#: Wall-clock seconds between progress lines.
PROGRESS_EVERY = 2.0
#: Tolerances for bags without a scenario: the scenario schema's defaults
#: (``metrics.eta_tolerance``, ``metrics.collision_distance`` in ``docs/scenarios.md``).
FALLBACK_ETA_TOLERANCE = 0.1
FALLBACK_COLLISION_DISTANCE = 0.1
#: The status of the world's live metrics on ``/swarm/metrics``.
METRICS_STATUS = contract.METRICS_STATUS

ODOMETRY = contract.ODOMETRY_TYPE
ACCEL = contract.ACCEL_TYPE
DIAGNOSTICS = contract.METRICS_TYPE
STATE = contract.STATE_TYPE
#: Columns of an agent's odometry as read: position, linear velocity (3 each), orientation
#: (x, y, z, w), angular velocity.
ODOM_COLUMNS = 13
#: The type of each kind of agent topic.
_AGENT_TYPES = {'odom': ODOMETRY, 'cmd_accel': ACCEL, 'state': STATE}
_AGENT_TOPIC = contract.AGENT_TOPIC
#: What ``analyze`` needs from a bag, in one sentence (said with every missing-topic error).
NEEDS = ('analyze needs /agent_<i>/odom (nav_msgs/msg/Odometry) of every agent; it also '
         'uses, when present, /agent_<i>/cmd_accel and /leader/accel '
         '(geometry_msgs/msg/AccelStamped), /leader/odom (nav_msgs/msg/Odometry), '
         '/agent_<i>/state (sensor_msgs/msg/JointState) and '
         '/swarm/metrics (diagnostic_msgs/msg/DiagnosticArray)')

Progress = Callable[[str], None]


class AnalyzeError(Exception):
    """The bag cannot be analysed as asked; the message is one line."""


@dataclass(frozen=True)
class SwarmTopics:
    """Where a swarm's messages are in a bag."""

    #: Namespace of the swarm's topics (``''`` for none).
    namespace: str
    #: ``/agent_<i>/odom`` of agent ``i``, for ``i`` in ``0 .. N-1``.
    odom: tuple[str, ...]
    #: ``/agent_<i>/cmd_accel`` of the agents that have one.
    cmd: dict[int, str]
    leader_odom: str | None
    leader_accel: str | None
    metrics: str | None
    #: ``/agent_<i>/state`` of the agents that have one (a law with adaptive state).
    state: dict[int, str] = field(default_factory=dict)
    #: The batched transport's state and command clouds (docs/ros.md, "Transports"):
    #: ``/swarm/states`` replaces the odometry topics (``odom`` then names the per-agent
    #: topics it stands for), ``/swarm/commands`` the command and state topics.
    states: str | None = None
    commands: str | None = None


@dataclass
class RunData:
    """A run rebuilt from a bag: the state at every complete step, and the scenario facts.

    A step is complete when every agent's odometry for it is in the bag. Arrays have one row
    per complete step, in step order.
    """

    #: The bag read.
    bag: Path
    #: Step indices ``k`` (``t_k = k dt``), shape ``(K,)``.
    steps: np.ndarray
    #: Times [s], shape ``(K,)``.
    t: np.ndarray
    #: Positions, velocities and the commands applied, shape ``(K, N, dim)``.
    q: np.ndarray
    p: np.ndarray
    u: np.ndarray
    #: The virtual leader's position, velocity and acceleration ``f_gamma``, ``(K, dim)``.
    leader_q: np.ndarray
    leader_p: np.ndarray
    leader_a: np.ndarray
    #: Informed agents, shape ``(N,)``.
    informed: np.ndarray
    #: Step [s].
    dt: float
    #: Interaction radius ``r`` and whether neighbourhoods are ``< r`` (``True``) or ``<= r``.
    radius: float
    strict_radius: bool
    eta_tolerance: float
    collision_distance: float
    #: Subsampling of the time series (the scenario's ``record_every``).
    record_every: int
    #: The scenario as run, from the bag's metadata (``None`` for other bags).
    scenario: Scenario | None = None
    #: ``lockstep`` or ``realtime`` (``None`` when the bag does not say).
    mode: str | None = None
    #: Commands the world did not receive in time, per agent, and steps without the leader.
    missed_commands_per_agent: list[int] = field(default_factory=list)
    leader_missed: int = 0
    #: The agents whose law gave a non-finite command, by step, as ``/swarm/metrics`` told
    #: (``None``: the bag's metrics do not count them, a bag of an older world).
    non_finite_at: dict[int, list[int]] | None = None
    #: Whether the bag has the leader's state (otherwise the centre of mass stands in).
    has_leader: bool = True
    #: The reader's warning for a truncated or unfinished bag.
    warning: str | None = None
    #: Whether a file of the bag was cut or not closed (its warning says how).
    recovered: bool = False
    #: How the world said the run ended (the bag's ``flock_swarm_end`` record: ``status``,
    #: ``failure``), or ``None``: a bag of an older world, or of a world that was killed.
    end: dict[str, str] | None = None
    #: Facts about how the bag was read (fallbacks, skipped steps), one line each.
    notes: list[str] = field(default_factory=list)
    #: Whether the bag says which agents are informed (no scenario anywhere: ``False``).
    informed_known: bool = True
    #: Odometry stamps for which some agent's message is missing.
    incomplete_steps: int = 0
    #: Whether the world closed the last complete step: ``False`` for a lockstep run stopped
    #: while that step waited for its commands (its odometry is in the bag, none of its
    #: commands and no metrics): the world's series and metrics end the step before.
    last_observed: bool = True
    #: The law's adaptive state per step, ``{key: (K, N, ...)}`` as ``sim`` records it (empty
    #: for a law without, or a bag without ``/agent_<i>/state``).
    state: dict[str, np.ndarray] = field(default_factory=dict)
    #: The network statistics ``/swarm/metrics`` told, by step (``{}``: none), each of the
    #: steps since the message before (a realtime run's: the world measured them).
    network_at: dict[int, dict[str, float]] = field(default_factory=dict)
    #: A robot plant's state per step, ``(K, N, S)``, rebuilt from the odometry
    #: (:meth:`~flock_swarm.core.plants.base.Plant.from_odometry`; ``q`` and ``p`` are then
    #: its :meth:`~flock_swarm.core.plants.base.Plant.law_state`); ``None`` for the double
    #: integrator and for bags without a scenario.
    plant_state: np.ndarray | None = None

    @property
    def n_agents(self) -> int:
        """Return the number of agents N."""
        return self.q.shape[1]

    @property
    def dim(self) -> int:
        """Return the dimension of the space (2 or 3)."""
        return self.q.shape[2]

    @property
    def name(self) -> str:
        """Return the scenario name, or the bag's name for bags without a scenario."""
        return self.scenario.name if self.scenario is not None else self.bag.name


class Ticker:
    """Calls ``progress`` with a line at most every :data:`PROGRESS_EVERY` seconds."""

    def __init__(self, progress: Progress | None) -> None:
        self.progress = progress
        self.last = time.monotonic()

    def __call__(self, line: Callable[[], str]) -> None:
        if self.progress is None:
            return
        now = time.monotonic()
        if now - self.last >= PROGRESS_EVERY:
            self.last = now
            self.progress(line())


def swarm_topics(topics: dict[str, str], n_agents: int | None = None) -> SwarmTopics:
    """Find the swarm's topics among a bag's topics.

    :param topics: topic name to type, as :meth:`BagReader.topics` returns them.
    :param n_agents: the number of agents the scenario says (``None``: from the topics).
    :return: the topics.
    :raises AnalyzeError: without agent odometry, with agents missing, or with topics of
        several namespaces; the message names the missing topics and what is needed
        (:data:`NEEDS`).
    """
    found: dict[str, dict[str, dict[int, str]]] = {}
    for name, type_name in topics.items():
        match = _AGENT_TOPIC.match(name)
        if match and type_name == _AGENT_TYPES[match['kind']]:
            kinds = found.setdefault(match['ns'], {kind: {} for kind in _AGENT_TYPES})
            kinds[match['kind']][int(match['id'])] = name
    found = {ns: kinds for ns, kinds in found.items() if kinds['odom']}
    if not found:
        batched = _batched_topics(topics, n_agents)
        if batched is not None:
            return batched
        raise AnalyzeError('the bag has no /agent_<i>/odom topics of type nav_msgs/msg/Odometry'
                           f' (it has {_topic_list(topics)}); {NEEDS}')
    if len(found) > 1:
        raise AnalyzeError('the bag holds swarms in several namespaces '
                           f'({", ".join(repr(ns) for ns in sorted(found))}); not supported')
    ns, kinds = next(iter(found.items()))
    odom = kinds['odom']
    n = n_agents if n_agents is not None else max(odom) + 1
    missing = [contract.absolute(contract.odom_topic(i), ns or '/') for i in range(n)
               if i not in odom]
    if missing:
        wrong = [f'{name} is {topics[name]}' for name in missing if name in topics]
        typed = f' ({"; ".join(wrong)})' if wrong else ''
        raise AnalyzeError(f'the bag lacks required topic(s) {_topic_list(missing)}{typed} '
                           f'(expected agents 0..{n - 1}); {NEEDS}')
    extra = sorted(i for i in odom if i >= n)
    if extra:
        raise AnalyzeError(f'the bag has odometry of agent(s) {_id_list(extra)}, but its '
                           f'scenario has {n} agents')

    def topic(suffix: str, type_name: str) -> str | None:
        name = f'{ns}/{suffix}'
        return name if topics.get(name) == type_name else None

    return SwarmTopics(ns, tuple(odom[i] for i in range(n)),
                       {i: name for i, name in kinds['cmd_accel'].items() if i < n},
                       topic(contract.LEADER_ODOM, ODOMETRY),
                       topic(contract.LEADER_ACCEL, ACCEL), topic(contract.METRICS, DIAGNOSTICS),
                       {i: name for i, name in kinds['state'].items() if i < n})


def _batched_topics(topics: dict[str, str], n_agents: int | None) -> SwarmTopics | None:
    """Return the swarm's topics of a bag of the batched transport (``/swarm/states``, and
    ``/swarm/commands`` when present), or ``None`` when it has no state cloud.

    :raises AnalyzeError: for state clouds in several namespaces, or without the scenario
        (which gives the number of agents).
    """
    suffix = '/' + contract.STATES
    states = sorted(name for name, type_name in topics.items()
                    if type_name == contract.CLOUD_TYPE and name.endswith(suffix))
    if not states:
        return None
    if len(states) > 1:
        raise AnalyzeError(f'the bag holds swarm states in several namespaces ({", ".join(states)}'
                           '); not supported')
    if n_agents is None:
        raise AnalyzeError(f'the bag holds the batched transport\'s {states[0]} but no '
                           'flock_swarm scenario (which gives the number of agents)')
    ns = states[0][:-len(suffix)]

    def topic(suffix: str, type_name: str) -> str | None:
        name = f'{ns}/{suffix}'
        return name if topics.get(name) == type_name else None

    return SwarmTopics(ns, tuple(contract.absolute(contract.odom_topic(i), ns or '/')
                                 for i in range(n_agents)), {},
                       topic(contract.LEADER_ODOM, ODOMETRY), topic(contract.LEADER_ACCEL, ACCEL),
                       topic(contract.METRICS, DIAGNOSTICS), {}, states[0],
                       topic(contract.COMMANDS, contract.CLOUD_TYPE))


def optional_topics_missing(topics: SwarmTopics) -> list[str]:
    """Return the topics ``analyze`` uses when present that a bag lacks.

    :param topics: the swarm's topics in the bag.
    :return: names such as ``/leader/accel`` or ``/agent_<i>/cmd_accel of agent(s) 1, 2``.
    """
    ns = topics.namespace
    missing = [f'{ns}/{suffix}' for suffix, name in (
        (contract.LEADER_ODOM, topics.leader_odom), (contract.LEADER_ACCEL, topics.leader_accel),
        (contract.METRICS, topics.metrics)) if name is None]
    if topics.states is not None:
        return missing + ([] if topics.commands else [f'{ns}/{contract.COMMANDS}'])
    no_cmd = [i for i in range(len(topics.odom)) if i not in topics.cmd]
    if no_cmd:
        missing.insert(0, f'{ns}/agent_<i>/cmd_accel of agent(s) {_id_list(no_cmd)}')
    return missing


def _topic_list(names: Iterable[str]) -> str:
    names = list(names)
    if not names:
        return 'no topics'
    shown = ', '.join(names[:8])
    return shown + (f' and {len(names) - 8} more' if len(names) > 8 else '')


def _id_list(ids: list[int]) -> str:
    shown = ', '.join(str(i) for i in ids[:8])
    return shown + (f' and {len(ids) - 8} more' if len(ids) > 8 else '')


#: The scenario keys that name a plugin (a law, a leader model or a plant) and what each
#: names: a bag whose scenario fails on one of them was recorded with a plugin this
#: installation does not have (or cannot load).
PLUGIN_KEYS = {'protocol.name': 'law', 'leader.model': 'leader model',
               'intrinsic.model': 'leader model', 'plant.model': 'plant model'}


def _stored_scenario(reader: BagReader, notes: list[str]
                     ) -> tuple[Scenario | None, dict[str, str] | None, str | None]:
    """Return the scenario of the bag's ``flock_swarm`` record, the record itself, and why a
    plugin the scenario names cannot be used here (``None``: no such problem)."""
    meta = reader.metadata(METADATA_RECORD)
    if meta is None:
        meta = _scenario_topic(reader, notes)
    if meta is None:
        return None, None, None
    plugin = None
    try:
        data = json.loads(meta['scenario'])
        return reread(data), meta, None
    except KeyError:
        reason = 'no scenario key'
    except json.JSONDecodeError as exc:
        reason = f'not JSON: {exc}'
    except ScenarioError as exc:
        reason = str(exc)
        if exc.key in PLUGIN_KEYS:
            plugin = _missing_plugin(data, exc)
    notes.append(f'the bag\'s {METADATA_RECORD} metadata has no usable scenario ({reason}); '
                 'analysed like a bag without one')
    return None, meta, plugin


def _missing_plugin(data, exc: ScenarioError) -> str:
    """Return the one line naming the plugin a bag's scenario needs and why it is unusable."""
    section, _, field = exc.key.partition('.')
    name = data.get(section, {}).get(field) if isinstance(data.get(section), dict) else None
    return (f'the bag was recorded with the {PLUGIN_KEYS[exc.key]} {name!r} ({exc.key}), '
            f'which cannot be loaded here ({exc.reason}): install the package that provides it')


def _scenario_topic(reader: BagReader, notes: list[str]) -> dict[str, str] | None:
    """Return the provenance record of the bag's ``/swarm/scenario`` message (the world
    records it at t = 0), as the metadata record holds it; ``None`` when there is none.

    Tools that rewrite a bag (``rosbags-convert``) drop MCAP metadata but keep messages.
    """
    names = [name for name, type_name in reader.topics().items()
             if name.endswith('/' + contract.SCENARIO) and type_name == contract.SCENARIO_TYPE]
    if len(names) != 1:
        return None
    try:
        for _, msg in reader.decoded(names[0]):
            data = parse_yaml(msg.data)
            break
        else:
            return None
        record = {key: str(value) for key, value in data.items()
                  if key not in ('scenario', 'informed')}
        record['scenario'] = json.dumps(data['scenario'])
        if 'informed' in data:
            record['informed'] = json.dumps([int(i) for i in data['informed']])
    except (BagError, yaml.YAMLError, AttributeError, KeyError, TypeError, ValueError) as exc:
        notes.append(f'{names[0]} holds no usable scenario ({one_line(str(exc))}); analysed '
                     'like a bag without one')
        return None
    notes.append(f'scenario, seed and informed set from {names[0]} (the bag has no '
                 f'{METADATA_RECORD} metadata record)')
    return record


def _stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def load_run(bag: Path | str, *, radius: float | None = None,
             eta_tolerance: float | None = None, collision_distance: float | None = None,
             progress: Progress | None = None) -> RunData:
    """Read a bag and rebuild the state of every complete step.

    Messages are grouped into steps by their header stamps (``t_k = k dt``): odometry gives
    ``q`` and ``p`` (for a robot plant the plant state, and ``q``, ``p`` what the law saw of
    it); the command stamped ``t_k`` is ``u`` at step ``k`` (zero where the world
    reported it missing on ``/swarm/metrics``). In realtime mode the world applies whichever
    command arrived last: ``u_k = (p_{k+1} - p_k) / dt`` for double integrators, otherwise the
    latest command of an earlier step. The leader's odometry and acceleration give
    ``q_gamma``, ``p_gamma``, ``f_gamma`` (held over steps where they are missing, as the world
    does).

    :param bag: a bag directory or ``.mcap`` file.
    :param radius: interaction radius, for bags without a scenario (required then).
    :param eta_tolerance: velocity tolerance of ``eta``, for bags without a scenario.
    :param collision_distance: collision distance, for bags without a scenario.
    :param progress: called with a line every few seconds while reading.
    :return: the run.
    :raises BagError: if the path is not a readable bag.
    :raises AnalyzeError: if the bag holds no complete step of a swarm, or a bag without a
        scenario comes without ``radius``.
    """
    reader = BagReader(Path(bag))
    notes: list[str] = []
    sc, meta, plugin = _stored_scenario(reader, notes)
    topics = swarm_topics(reader.topics(), sc.n_agents if sc is not None else None)
    absent = optional_topics_missing(topics)
    if absent:
        notes.append(f'optional topic(s) not in the bag: {"; ".join(absent)} (the odometry '
                     'of every agent is all analyze requires)')
    if sc is None:
        if radius is None and plugin is not None:
            raise AnalyzeError(f'{plugin}, or give --radius (and --eta-tolerance, '
                               '--collision-distance) to analyse it without its scenario')
        if radius is None:
            raise AnalyzeError('the bag has no flock_swarm scenario metadata: give --radius '
                               '(and --eta-tolerance, --collision-distance)')
        eta_tolerance = FALLBACK_ETA_TOLERANCE if eta_tolerance is None else eta_tolerance
        collision_distance = (FALLBACK_COLLISION_DISTANCE if collision_distance is None
                              else collision_distance)
        notes.append(f'no flock_swarm scenario in the bag: radius {radius:g} m, eta tolerance '
                     f'{eta_tolerance:g} m/s, collision distance {collision_distance:g} m '
                     'from the options')
    else:
        given = [f'--{name}' for name, value in (('radius', radius),
                                                 ('eta-tolerance', eta_tolerance),
                                                 ('collision-distance', collision_distance))
                 if value is not None]
        if given:
            notes.append(f'{", ".join(given)} ignored: the bag\'s scenario gives the values')
        radius, eta_tolerance = sc.law.radius, sc.eta_tolerance
        collision_distance = sc.collision_distance
    raw = _read_messages(reader, topics, progress)
    if raw.undecodable:
        notes.append(f'{len(raw.undecodable)} message(s) that do not decode as their type '
                     f'skipped (a faulty writer\'s, recorded as received; first: '
                     f'{raw.undecodable[0]})')
    return _assemble(reader, topics, sc, meta, raw, radius, eta_tolerance, collision_distance,
                     notes)


@dataclass
class _Messages:
    """The messages of a swarm, keyed by header stamp [ns]."""

    # agent -> batches of (stamps, their ODOM_COLUMNS values: position, linear velocity,
    # orientation (x, y, z, w), angular velocity), in bag order (_odometry_table joins them)
    odom: dict[int, list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    # (stamp, agent, acceleration), in bag order
    cmd: list[tuple[int, int, tuple[float, float, float]]] = field(default_factory=list)
    leader_odom: dict[int, tuple[float, ...]] = field(default_factory=dict)
    leader_accel: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    # (stamp, the world's metric values)
    metrics: list[tuple[int, dict[str, str]]] = field(default_factory=list)
    # (stamp, agent, labels, values), in bag order
    state: list[tuple[int, int, tuple[str, ...], tuple[float, ...]]] = \
        field(default_factory=list)
    #: Messages whose bytes do not decode (skipped): ``topic at t ns (reason)``.
    undecodable: list[str] = field(default_factory=list)


#: How the swarm's message types are read: straight from their CDR bytes
#: (:mod:`flock_swarm.nodes.wire`, a few microseconds a message), and, for bytes that reader
#: refuses, from rclpy's object (the same values; or the reason they do not decode).
_FAST = {
    contract.ODOMETRY_TYPE: decode_odometry_state,
    contract.ACCEL_TYPE: lambda data: (lambda ns, _, a: (ns, a))(*decode_accel(data)),
    contract.STATE_TYPE: lambda data: (lambda ns, _, names, values: (ns, (names, values)))(
        *decode_state(data)),
}


def _from_object(msg: Any) -> tuple[int, tuple]:
    """Return :func:`_fields`' values of an rclpy message object."""
    stamp = _stamp_ns(msg.header.stamp)
    if hasattr(msg, 'pose'):
        pos, vel = msg.pose.pose.position, msg.twist.twist.linear
        turn, spin = msg.pose.pose.orientation, msg.twist.twist.angular
        return stamp, (pos.x, pos.y, pos.z, vel.x, vel.y, vel.z, turn.x, turn.y, turn.z,
                       turn.w, spin.x, spin.y, spin.z)
    if hasattr(msg, 'accel'):
        lin = msg.accel.linear
        return stamp, (lin.x, lin.y, lin.z)
    return stamp, (tuple(msg.name), tuple(msg.position))


def _fields(reader: BagReader, message: BagMessage) -> tuple[int, tuple]:
    """Return the header stamp [ns] and the values analyze takes of an odometry (13: see
    :func:`~flock_swarm.nodes.wire.decode_odometry_state`), a command (3) or a state (labels,
    values) message.

    :raises UndecodableMessage: when its bytes do not decode as its type.
    """
    fast = _FAST.get(message.type_name)
    if fast is not None:
        try:
            return fast(message.data)
        except MalformedMessage:
            pass  # rclpy's word on it: the same values, or why it does not decode
    return _from_object(reader.decode(message))


#: Messages of a topic decoded at once (:func:`_decode_batch`).
DECODE_BATCH = 4096


def _align(offset: int, size: int) -> int:
    """Return ``offset`` aligned to ``size`` relative to the CDR payload (after 4 bytes)."""
    return 4 + ((offset - 4 + size - 1) & -size)


def _layout_of(type_name: str, data: bytes) -> tuple[int, list[tuple[int, int]], tuple]:
    """Return where the values of a little-endian message of ``type_name`` lie: the offset
    where its strings and counts end, the ``(offset, count)`` of its float64 runs, and
    its joint names (a state's; else empty).

    :raises ValueError: for bytes this walk cannot follow (the caller decodes them one by
        one instead).
    """
    u32 = struct.Struct('<I')

    def string_end(offset: int) -> int:
        return offset + 4 + u32.unpack_from(data, offset)[0]

    if data[:2] != b'\x00\x01':
        raise ValueError('not little-endian CDR')
    end = string_end(12)
    if type_name == contract.ODOMETRY_TYPE:
        pose = _align(string_end(_align(end, 4)), 8)
        twist = pose + POSE_BYTES
        return pose, [(pose, 3), (twist, 3), (pose + 24, 4), (twist + 24, 3)], ()
    if type_name == contract.ACCEL_TYPE:
        accel = _align(end, 8)
        return accel, [(accel, 3)], ()
    count_at = _align(end, 4)
    (count,) = u32.unpack_from(data, count_at)
    names, end = [], count_at + 4
    for _ in range(min(count, len(data))):
        start = _align(end, 4)
        end = string_end(start)
        names.append(data[start + 4:end - 1].decode())
    count_at = _align(end, 4)
    (count,) = u32.unpack_from(data, count_at)
    values = _align(count_at + 4, 8) if count else count_at + 4
    return values, [(values, count)], tuple(names)


@dataclass
class _Columns:
    """A batch of one topic's messages that all share the first one's layout."""

    #: Header stamps [ns], ``(M,)``.
    stamps: np.ndarray
    #: Their values, ``(M, K)``.
    values: np.ndarray
    #: A state's joint names (empty for the other types).
    names: tuple


def _decode_batch(reader: BagReader, records: list[tuple]
                  ) -> list[tuple | UndecodableMessage] | _Columns:
    """Return :func:`_fields`' stamp and values (or why it does not decode) of each message
    of one topic (:meth:`BagReader.records`), those of one layout read at once with NumPy.

    The messages of one topic share their layout: the same length and the same bytes where
    the frame ids, names and counts are (only the stamp and the values differ). Those are
    read as columns of one byte array, after the first one's values were checked against
    :mod:`flock_swarm.nodes.wire`'s; every other message is decoded on its own
    (:func:`_fields`). A batch whose messages all share the layout comes back as its
    columns (:class:`_Columns`).
    """
    datas = [record[2] for record in records]
    found: list[tuple | UndecodableMessage | None] = [None] * len(records)
    log_time, (topic, type_name, qos), data, publish_time = records[0]
    first = BagMessage(topic, type_name, log_time, data, qos, publish_time)
    try:
        head, runs, names = _layout_of(first.type_name, first.data)
        stamp, values = _fields(reader, first)
        size = len(first.data)
        if max(offset + 8 * count for offset, count in runs) > size:
            raise ValueError('values past the end')
        flat = np.concatenate([np.frombuffer(first.data, '<f8', count, offset)
                               for offset, count in runs])
        if names:
            ok = values == (names, tuple(flat))
        else:
            ok = np.array_equal(np.asarray(values, dtype=float), flat, equal_nan=True)
        if not ok or stamp != _stamp_ns_of(first.data):
            raise ValueError('the layout does not read as the message')
    except (ValueError, struct.error, IndexError, UnicodeDecodeError, UndecodableMessage,
            MalformedMessage):
        head = None
    if head is not None:
        rows = [j for j, data in enumerate(datas) if len(data) == size]
        table = np.frombuffer(b''.join(datas[j] for j in rows) if len(rows) < len(datas)
                              else b''.join(datas), np.uint8).reshape(len(rows), size)
        same = ((table[:, :4] == table[0, :4]).all(axis=1)
                & (table[:, 12:head] == table[0, 12:head]).all(axis=1))
        secs = table[:, 4:8].copy().view('<i4')[:, 0].astype(np.int64)
        nanos = table[:, 8:12].copy().view('<u4')[:, 0].astype(np.int64)
        stamps = secs * 1_000_000_000 + nanos
        columns = np.concatenate([table[:, offset:offset + 8 * count].copy().view('<f8')
                                  for offset, count in runs], axis=1)
        if len(rows) == len(datas) and same.all():
            return _Columns(stamps, columns, names)
        values = ([(names, tuple(row)) for row in columns.tolist()] if names
                  else list(columns))
        for r, (j, stamp, same_layout) in enumerate(zip(rows, stamps.tolist(),
                                                        same.tolist())):
            if same_layout:
                found[j] = (stamp, values[r])
    for j, item in enumerate(found):
        if item is None:
            log_time, (topic, type_name, qos), data, publish_time = records[j]
            try:
                found[j] = _fields(reader, BagMessage(topic, type_name, log_time, data, qos,
                                                      publish_time))
            except UndecodableMessage as exc:
                found[j] = exc
    return found


def _stamp_ns_of(data: bytes) -> int:
    """Return the header stamp [ns] of a little-endian CDR message with a header."""
    sec, nanosec = struct.unpack_from('<iI', data, 4)
    return sec * 1_000_000_000 + nanosec


def _read_messages(reader: BagReader, topics: SwarmTopics,
                   progress: Progress | None) -> _Messages:
    """Decode the swarm's topics of the bag."""
    kinds: dict[str, tuple[str, int]] = {} if topics.states is not None else \
        {name: ('odom', i) for i, name in enumerate(topics.odom)}
    kinds.update({name: ('cmd', i) for i, name in topics.cmd.items()})
    kinds.update({name: ('state', i) for i, name in topics.state.items()})
    for kind, name in (('leader_odom', topics.leader_odom),
                       ('leader_accel', topics.leader_accel), ('metrics', topics.metrics),
                       ('states', topics.states), ('commands', topics.commands)):
        if name is not None:
            kinds[name] = (kind, -1)
    clouds = _Clouds(len(topics.odom))
    counts = reader.message_counts()
    total = sum(counts.get(name, 0) for name in kinds)
    out = _Messages()
    tick = Ticker(progress)
    read = 0
    bad: list[tuple[int, str]] = []
    pending: dict[str, list[tuple]] = {}

    def flush(topic: str) -> None:
        kind, i = kinds[topic]
        decoded = _decode_batch(reader, pending.pop(topic))
        if isinstance(decoded, _Columns):
            stamps = decoded.stamps.tolist()
            if kind == 'odom':
                out.odom.setdefault(i, []).append((decoded.stamps, decoded.values))
            elif kind == 'cmd':
                out.cmd.extend(zip(stamps, itertools.repeat(i), decoded.values.tolist()))
            elif kind == 'state':
                names = decoded.names
                out.state.extend((stamp, i, names, tuple(values))
                                 for stamp, values in zip(stamps, decoded.values.tolist()))
            elif kind == 'leader_odom':
                out.leader_odom.update(
                    (stamp, tuple(values[:6]))
                    for stamp, values in zip(stamps, decoded.values.tolist()))
            else:
                out.leader_accel.update(
                    (stamp, tuple(values))
                    for stamp, values in zip(stamps, decoded.values.tolist()))
            return
        if kind == 'odom':
            good = [item for item in decoded if not isinstance(item, UndecodableMessage)]
            out.odom.setdefault(i, []).append((
                np.fromiter((item[0] for item in good), np.int64, len(good)),
                np.array([item[1] for item in good], dtype=float).reshape(-1, ODOM_COLUMNS)))
            decoded = [item for item in decoded if isinstance(item, UndecodableMessage)]
        for found in decoded:
            if isinstance(found, UndecodableMessage):
                bad.append((found.message.log_time_ns, f'{topic} at '
                            f'{found.message.log_time_ns} ns ({found.reason})'))
                continue
            stamp, values = found
            if kind == 'leader_odom':
                out.leader_odom[stamp] = tuple(values[:6])
            elif kind == 'cmd':
                out.cmd.append((stamp, i, values))
            elif kind == 'leader_accel':
                out.leader_accel[stamp] = tuple(values)
            else:
                out.state.append((stamp, i, *values))

    # Each topic's messages are decoded in batches, in the bag's order (what is kept of a
    # topic depends on that order only: the last message of a stamp wins).
    metrics_topic = topics.metrics
    for record in reader.records(list(kinds)):
        read += 1
        if not read & 1023:
            tick(lambda: f'[analyze] reading {reader.path}: {read}/{total} messages '
                         f'({100 * read / max(total, 1):.0f} %)')
        topic = record[1][0]
        if kinds[topic][0] in ('states', 'commands'):
            clouds.take(kinds[topic][0], topic, record, bad)
        elif topic != metrics_topic:
            batch = pending.get(topic)
            if batch is None:
                batch = pending[topic] = []
            batch.append(record)
            if len(batch) == DECODE_BATCH:
                flush(topic)
        else:
            log_time, (_, type_name, qos), data, publish_time = record
            message = BagMessage(topic, type_name, log_time, data, qos, publish_time)
            try:
                msg = reader.decode(message)
            except UndecodableMessage as exc:
                bad.append((message.log_time_ns,
                            f'{message.topic} at {message.log_time_ns} ns ({exc.reason})'))
                continue
            stamp = _stamp_ns(msg.header.stamp)
            for status in msg.status:
                if status.name == METRICS_STATUS:
                    out.metrics.append((stamp, {kv.key: kv.value for kv in status.values}))
    for topic in list(pending):
        flush(topic)
    clouds.into(out)
    bad.sort(key=lambda item: item[0])
    out.undecodable = [text for _, text in bad]
    return out


class _Clouds:
    """The batched transport's clouds of a bag (:mod:`flock_swarm.nodes.cloud`), turned into
    what the per-agent topics give: every agent's odometry columns, commands and states."""

    def __init__(self, n: int) -> None:
        """Collect the clouds of a swarm of ``n`` agents."""
        self.n = n
        self.stamps: list[int] = []
        self.odometry: list[np.ndarray] = []
        self.cmd: list[tuple[int, int, tuple[float, float, float]]] = []
        self.state: list[tuple[int, int, tuple[str, ...], tuple[float, ...]]] = []

    def take(self, kind: str, topic: str, record: tuple, bad: list) -> None:
        """Decode one recorded cloud (``kind``: ``states`` or ``commands``); a cloud that
        does not decode, or lacks a field, goes to ``bad``."""
        log_time, _, data, _ = record
        try:
            cloud = decode_cloud(data)
            ids = cloud.ids()
            if kind == 'states':
                self.states(cloud, ids)
            else:
                self.commands(cloud, ids)
        except MalformedMessage as exc:
            bad.append((log_time, f'{topic} at {log_time} ns ({exc})'))

    def states(self, cloud, ids: np.ndarray) -> None:
        """Keep a state cloud as the ODOM_COLUMNS of every agent."""
        names = cloud.names()
        if len(ids) != self.n or not np.array_equal(np.sort(ids), np.arange(self.n)):
            raise MalformedMessage(f'{len(ids)} points, not one of each of the {self.n} agents')
        table = np.zeros((self.n, ODOM_COLUMNS))
        table[:, 9] = 1.0
        for name in ('x', 'y', 'vx', 'vy'):
            if name not in names:
                raise MalformedMessage(f'no field {name!r} (fields {list(names)})')
        # A 2-D cloud has no z, vz; one without a heading the identity orientation.
        for column, name in ((0, 'x'), (1, 'y'), (2, 'z'), (3, 'vx'), (4, 'vy'), (5, 'vz'),
                             (8, 'qz'), (9, 'qw'), (12, 'wz')):
            if name in names:
                table[ids, column] = cloud.points[name]
        self.stamps.append(cloud.stamp_ns)
        self.odometry.append(table)

    def commands(self, cloud, ids: np.ndarray) -> None:
        """Keep a command cloud's accelerations and adaptive states, agent by agent."""
        names = cloud.names()
        accel = [name for name in ('ax', 'ay', 'az') if name in names]
        u = np.zeros((len(ids), 3))
        u[:, :len(accel)] = cloud.columns(accel)
        labels = tuple(name for name in names if name not in ('ax', 'ay', 'az', ID)
                       and name not in TWIST_FIELDS)
        ns = cloud.stamp_ns
        self.cmd.extend(zip(itertools.repeat(ns), ids.tolist(), map(tuple, u.tolist())))
        if labels:
            self.state.extend((ns, i, labels, tuple(values)) for i, values in
                              zip(ids.tolist(), cloud.columns(labels).tolist()))

    def into(self, out: '_Messages') -> None:
        """Add what the clouds hold to ``out``, as the per-agent topics would have."""
        if self.odometry:
            stamps = np.array(self.stamps, dtype=np.int64)
            table = np.stack(self.odometry)
            for i in range(self.n):
                out.odom.setdefault(i, []).append((stamps, table[:, i]))
        out.cmd.extend(self.cmd)
        out.state.extend(self.state)


def _assemble(reader: BagReader, topics: SwarmTopics, sc: Scenario | None,
              meta: dict[str, str] | None, raw: _Messages, radius: float,
              eta_tolerance: float, collision_distance: float, notes: list[str]) -> RunData:
    """Turn the decoded messages into per-step arrays."""
    n = len(topics.odom)
    # The whole odometry: a robot plant's state needs the heading and the yaw rate besides
    # (Plant.from_odometry).
    all_stamps, odometry, seen = _odometry_table(raw.odom, n)
    whole = seen.all(axis=1)
    complete = all_stamps[whole].tolist()
    incomplete = len(all_stamps) - len(complete)
    if not complete:
        lost = f' ({reader.warning})' if reader.warning else ''
        raise AnalyzeError('the bag holds no complete step (odometry of every agent for one '
                           f'stamp){lost}')
    if sc is not None:
        dt, origin = sc.dt, 0
        dt_ns = int(round(dt * 1e9))
    else:
        diffs = np.diff(all_stamps)
        diffs = diffs[diffs > 0]
        dt_ns = int(np.median(diffs)) if diffs.size else 0
        dt, origin = dt_ns * 1e-9, complete[0]
        notes.append(f'dt = {dt:g} s from the odometry stamps; t = 0 at the first complete step')

    def step_of(stamp: int) -> int:
        return int(round((stamp - origin) / dt_ns)) if dt_ns else 0

    steps_seen: dict[int, int] = {}
    for stamp in complete:
        steps_seen.setdefault(step_of(stamp), stamp)
    steps = np.array(sorted(steps_seen), dtype=np.int64)
    stamps = [steps_seen[k] for k in steps]
    states = odometry[np.searchsorted(all_stamps, np.array(stamps, dtype=np.int64))]
    if sc is not None:
        dim = sc.dim
        t = steps * dt
    else:
        dim = 3 if np.any(states[:, :, [2, 5]] != 0.0) else 2
        t = (np.array(stamps, dtype=np.int64) - origin) * 1e-9
    q = states[:, :, :dim].copy()
    p = states[:, :, 3:3 + dim].copy()
    plant_state = None
    if sc is not None and not sc.plant.default:
        plant_state, q, p = _plant_states(sc, states)
    if incomplete:
        notes.append(f'{incomplete} step(s) without every agent\'s odometry skipped')

    mode = meta.get('mode') if meta is not None else None
    index = {int(k): row for row, k in enumerate(steps)}
    missed = _agents_by_step(raw.metrics, 'missed_this_step', index, n, step_of)
    non_finite = None
    if any('non_finite_this_step' in values for _, values in raw.metrics):
        non_finite = _agents_by_step(raw.metrics, 'non_finite_this_step', index, n, step_of)
    u = _commands(raw.cmd, steps, index, missed, n, dim, step_of, mode == 'realtime')
    if mode == 'realtime' and sc is not None and sc.intrinsic is None and sc.plant.default:
        # Which held command the world applied is not in the bag, but the double integrator
        # gives it back from the next state: p_{k+1} = p_k + u_k dt (a robot plant does not:
        # its velocity is not p + u dt).
        follows = np.flatnonzero(np.diff(steps) == 1)
        u[follows] = (p[follows + 1] - p[follows]) / dt
    per_agent = np.zeros(n, dtype=int)
    if topics.metrics is not None and raw.metrics:
        for ids in missed.values():
            per_agent[ids] += 1
    else:
        answered = np.zeros((len(steps), n), dtype=bool)
        for stamp, i, _ in raw.cmd:
            if step_of(stamp) in index:
                answered[index[step_of(stamp)], i] = True
        per_agent = (~answered).sum(axis=0)
        if mode is None and raw.cmd:
            notes.append('no /swarm/metrics: a command absent for its step counts as missed')

    leader, leader_missed = _leader(raw, topics, sc, steps, dim, step_of, q, p, u, notes)
    last_metrics = [values for stamp, values in raw.metrics if step_of(stamp) in index]
    if last_metrics and 'leader_missed' in last_metrics[-1]:
        leader_missed = int(last_metrics[-1]['leader_missed'])

    informed_known = True
    if meta is not None and 'informed' in meta:
        ids = json.loads(meta['informed'])
    elif sc is not None:
        ids = realize(sc).informed_ids
    else:
        ids = []
        informed_known = False
        notes.append('informed agents unknown (no scenario in the bag): none marked')
    informed = np.zeros(n, dtype=bool)
    informed[[int(i) for i in ids]] = True
    state = _states(raw.state, sc, steps, index, n, step_of, mode == 'realtime', notes)
    network_at = {step_of(stamp): {key: _number(values[key]) for key in STATISTICS}
                  for stamp, values in raw.metrics
                  if step_of(stamp) in index and all(key in values for key in STATISTICS)}
    last_observed = True
    if (sc is not None and mode == 'lockstep' and not reader.recovered
            and steps[-1] < sc.steps and len(steps) > 1):
        final = stamps[-1]
        last_observed = (any(stamp == final for stamp, _, _ in raw.cmd)
                         or any(stamp == final for stamp, _ in raw.metrics))
    return RunData(
        bag=reader.path, steps=steps, t=t, q=q, p=p, u=u, leader_q=leader[0],
        leader_p=leader[1], leader_a=leader[2], informed=informed, dt=dt, radius=float(radius),
        strict_radius=sc.law.strict_radius if sc is not None else True,
        eta_tolerance=float(eta_tolerance), collision_distance=float(collision_distance),
        record_every=sc.record_every if sc is not None else 1, scenario=sc, mode=mode,
        missed_commands_per_agent=[int(x) for x in per_agent], leader_missed=leader_missed,
        non_finite_at=non_finite,
        has_leader=topics.leader_odom is not None, warning=reader.warning, notes=notes,
        incomplete_steps=incomplete, state=state, recovered=reader.recovered,
        informed_known=informed_known, network_at=network_at, plant_state=plant_state,
        last_observed=last_observed, end=reader.metadata(END_RECORD))


def _odometry_table(parts: dict[int, list[tuple[np.ndarray, np.ndarray]]], n: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return every odometry stamp (sorted), each agent's values at each, ``(S, N,``
    :data:`ODOM_COLUMNS` ``)`` (zero where it sent none), and which agents sent one ``(S, N)``:
    of an agent's messages of one stamp, the last in the bag.
    """
    joined = {i: (np.concatenate([s for s, _ in batches]),
                  np.concatenate([v for _, v in batches]))
              for i, batches in parts.items()}
    stamps = (np.unique(np.concatenate([s for s, _ in joined.values()])) if joined
              else np.zeros(0, dtype=np.int64))
    values = np.zeros((len(stamps), n, ODOM_COLUMNS))
    seen = np.zeros((len(stamps), n), dtype=bool)
    for i, (agent_stamps, agent_values) in joined.items():
        # The last of each stamp: the first in the reversed order.
        _, first = np.unique(agent_stamps[::-1], return_index=True)
        last = len(agent_stamps) - 1 - first
        rows = np.searchsorted(stamps, agent_stamps[last])
        values[rows, i] = agent_values[last]
        seen[rows, i] = True
    return stamps, values, seen


def _plant_states(sc: Scenario, states: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return a robot plant's states ``(K, N, S)`` of the odometry read (``(K, N,``
    :data:`ODOM_COLUMNS` ``)``) and what the law saw of them, ``q`` and ``p`` ``(K, N, dim)``.

    The world's odometry carries the plant state (:meth:`Plant.odometry`; for the unicycle
    the axle, its heading and its body twist), which :meth:`Plant.from_odometry` gives back
    exactly; the law's point and its velocity are :meth:`Plant.law_state` of it, as ``sim``
    and the world compute them (element-wise arithmetic: bit for bit over any rows).
    """
    plant, dim = sc.plant.model, sc.dim
    k, n = states.shape[:2]
    rows = states.reshape(k * n, ODOM_COLUMNS)
    x = plant.from_odometry(rows[:, 0:3], rows[:, 6:10], rows[:, 3:6], rows[:, 10:13], dim)
    q, p = plant.law_state(x)
    return x.reshape(k, n, -1), q.reshape(k, n, dim), p.reshape(k, n, dim)


def _number(text: str) -> float:
    """Return a ``/swarm/metrics`` value as a float (NaN when it is none)."""
    try:
        return float(text)
    except ValueError:
        return float('nan')


def _agents_by_step(metrics: list, key: str, index: dict[int, int], n: int,
                    step_of: Callable[[int], int]) -> dict[int, list[int]]:
    """Return ``{step: agents}`` of a ``/swarm/metrics`` value listing agents (a JSON list,
    ``missed_this_step``, ``non_finite_this_step``), for the complete steps."""
    found: dict[int, list[int]] = {}
    for stamp, values in metrics:
        try:
            ids = json.loads(values.get(key, '[]'))
        except json.JSONDecodeError:
            ids = []
        if ids and step_of(stamp) in index:
            found[step_of(stamp)] = [int(i) for i in ids if 0 <= int(i) < n]
    return found


def _commands(cmds: list, steps: np.ndarray, index: dict[int, int],
              missed: dict[int, list[int]], n: int, dim: int, step_of: Callable[[int], int],
              realtime: bool) -> np.ndarray:
    """Return the command applied at each step, ``(K, N, dim)``."""
    u = np.zeros((len(steps), n, dim))
    if realtime:
        # The world holds each agent's latest command (zero-order hold); a command answers
        # the odometry of its stamp, so it can act from the next step on.
        held = np.zeros((n, dim))
        ordered = sorted(((step_of(stamp), i, a) for stamp, i, a in cmds), key=lambda c: c[0])
        position = 0
        for row, k in enumerate(steps):
            while position < len(ordered) and ordered[position][0] < k:
                _, i, a = ordered[position]
                held[i] = a[:dim]
                position += 1
            u[row] = held
        return u
    if cmds:
        # Vectorised, with the same outcome as one by one in bag order: each command goes
        # to its step's row (when that step is complete), the last one for an agent and
        # step wins.
        stamps = np.fromiter((c[0] for c in cmds), np.int64, len(cmds))
        ids = np.fromiter((c[1] for c in cmds), np.int64, len(cmds))
        values = np.array([c[2][:dim] for c in cmds], dtype=float).reshape(len(cmds), dim)
        ks = np.array([step_of(int(stamp)) for stamp in np.unique(stamps)], dtype=np.int64)
        ks = ks[np.searchsorted(np.unique(stamps), stamps)]
        rows = np.searchsorted(steps, ks)
        rows[rows >= len(steps)] = 0
        known = steps[rows] == ks if len(steps) else np.zeros(len(ks), dtype=bool)
        slot = rows * n + ids
        keep = np.flatnonzero(known)
        # The last command of each (row, agent): the first in the reversed order.
        _, last = np.unique(slot[keep][::-1], return_index=True)
        chosen = keep[::-1][last]
        u.reshape(-1, dim)[slot[chosen]] = values[chosen]
    for k, ids in missed.items():
        # The world applied zero: the command came after the step's timeout.
        u[index[k], ids] = 0.0
    return u


def _state_shapes(labels: tuple[str, ...]) -> dict[str, tuple[int, ...]]:
    """Return the state shapes of an agent's state labels, for a bag without a scenario: a
    key alone is a scalar, ``key[0]``, ``key[1]``... a vector (:func:`contract.state_labels`)."""
    sizes: dict[str, int | None] = {}
    for label in labels:
        key, bracket, _ = label.partition('[')
        sizes[key] = (sizes.get(key) or 0) + 1 if bracket else None
    return {key: () if size is None else (size,) for key, size in sizes.items()}


def _states(messages: list, sc: Scenario | None, steps: np.ndarray, index: dict[int, int],
            n: int, step_of: Callable[[int], int], realtime: bool,
            notes: list[str]) -> dict[str, np.ndarray]:
    """Return the law's adaptive state at each step, ``{key: (K, N, ...)}``, as the world
    recorded it: an agent's state of step ``k`` (realtime: its latest of an earlier step),
    else its last one (its initial value before the first; NaN without a scenario)."""
    initial = realize(sc).agents.state if sc is not None else {}
    if not messages:
        if initial:
            notes.append('no /agent_<i>/state in the bag: the law\'s adaptive state is not in '
                         'the series or the summary')
        return {}
    if sc is not None:
        shapes = {key: value.shape[1:] for key, value in initial.items()}
    else:
        shapes = _state_shapes(messages[0][2])
    labels = contract.state_labels(shapes)
    start = np.full((n, len(labels)), np.nan)
    if initial:
        start = np.concatenate([value.reshape(n, -1) for value in initial.values()], axis=1)
    flat = np.full((len(steps), n, len(labels)), np.nan)
    given = np.zeros((len(steps), n), dtype=bool)
    foreign = 0
    if realtime:
        held = start.copy()
        ordered = sorted(((step_of(stamp), i, names, values)
                          for stamp, i, names, values in messages), key=lambda m: m[0])
        position = 0
        for row, k in enumerate(steps):
            while position < len(ordered) and ordered[position][0] < k:
                _, i, names, values = ordered[position]
                if names == labels:
                    held[i] = values
                else:
                    foreign += 1
                position += 1
            flat[row] = held
    else:
        for stamp, i, names, values in messages:
            row = index.get(step_of(stamp))
            if names != labels:
                foreign += 1
            elif row is not None:
                flat[row, i] = values
                given[row, i] = True
        for row in range(len(steps)):
            before = flat[row - 1] if row else start
            flat[row, ~given[row]] = before[~given[row]]
    if foreign:
        notes.append(f'{foreign} /agent_<i>/state message(s) with labels other than '
                     f'{list(labels)} skipped')
    return {key: flat[:, :, part].reshape(len(steps), n, *shape)
            for key, shape, part in contract.state_slices(shapes)}


def _leader(raw: _Messages, topics: SwarmTopics, sc: Scenario | None, steps: np.ndarray,
            dim: int, step_of: Callable[[int], int], q: np.ndarray, p: np.ndarray,
            u: np.ndarray, notes: list[str]) -> tuple[tuple[np.ndarray, ...], int]:
    """Return the leader's ``(q, p, a)`` per step and the number of steps it was missing."""
    count = len(steps)
    if topics.leader_odom is None or not raw.leader_odom:
        notes.append('no leader odometry in the bag: the centre of mass stands in for the '
                     'virtual leader (eta and mismatch then measure velocity consensus)')
        return (q.mean(axis=1), p.mean(axis=1), u.mean(axis=1)), 0
    odom = {step_of(stamp): state for stamp, state in raw.leader_odom.items()}
    accel = {step_of(stamp): a for stamp, a in raw.leader_accel.items()}
    need_accel = topics.leader_accel is not None
    if sc is not None:
        held = (sc.leader.position.copy(), sc.leader.velocity.copy(), np.zeros(dim))
    else:
        first = odom[min(odom)]
        first_a = accel[min(accel)] if accel else (0.0, 0.0, 0.0)
        held = (np.array(first[:dim]), np.array(first[3:3 + dim]), np.array(first_a[:dim]))
    out = tuple(np.zeros((count, dim)) for _ in range(3))
    missing = 0
    for row, k in enumerate(steps):
        k = int(k)
        if k in odom and (k in accel or not need_accel):
            state = odom[k]
            a = accel[k] if need_accel else (0.0, 0.0, 0.0)
            held = (np.array(state[:dim]), np.array(state[3:3 + dim]), np.array(a[:dim]))
        else:
            missing += 1
        for array, value in zip(out, held):
            array[row] = value
    if not need_accel:
        notes.append('no /leader/accel in the bag: f_gamma taken as zero')
    return out, missing
