"""``analyze BAG``: the metrics, time series and figures of a recorded run, from its bag.

``analyze BAG [--out DIR] [--verify] ...`` rebuilds every step of a run from the agents'
odometry and commands and the leader's state in a rosbag2 MCAP bag, recomputes the flocking
metrics with the code ``sim`` and the world node use
(:func:`flock_swarm.core.metrics.step_metrics`, :class:`flock_swarm.core.metrics.RunMetrics`)
and writes ``summary.json``, ``timeseries.npz``, ``timeseries.csv`` and figures
(``docs/analysis.md``). The scenario stored in the bag (MCAP metadata record ``flock_swarm``)
gives ``dt``, the radius and the tolerances; ``--verify`` re-runs ``sim`` from it and compares
the trajectories. Bags without that record (any rosbag2 bag with ``/agent_<i>/odom`` topics)
are analysed with ``--radius``, ``--eta-tolerance`` and ``--collision-distance``.
"""

import argparse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
import json
from pathlib import Path
import sys
import time

import numpy as np

from flock_swarm.cli import EXIT_USAGE, OneLineParser
from flock_swarm import __version__, contract
from flock_swarm.bag import BagError, BagReader
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.metrics import STEP_METRICS, RunMetrics
from flock_swarm.core.scenario import Scenario, parse_scenario, realize
from flock_swarm.core.run import RunLog, build_summary, simulate
from flock_swarm.outputs import ensure_writable, json_text

#: Exit status when ``--verify`` finds the recording off the simulation.
EXIT_VERIFY_FAILED = 1
#: Exit status after Ctrl-C.
EXIT_INTERRUPTED = 130
#: Name of the MCAP metadata record in which the world node stores the scenario as run.
METADATA_RECORD = 'flock_swarm'
#: Wall-clock seconds between progress lines.
PROGRESS_EVERY = 2.0
#: Default largest deviation from ``sim`` that ``--verify`` accepts (m, m/s). A lockstep run
#: reproduces ``sim`` bit for bit; the margin only absorbs a different floating-point library.
VERIFY_TOLERANCE = 1e-6
#: Tolerances for bags without a scenario: the scenario schema's defaults
#: (``metrics.eta_tolerance``, ``metrics.collision_distance`` in ``docs/scenarios.md``).
FALLBACK_ETA_TOLERANCE = 0.1
FALLBACK_COLLISION_DISTANCE = 0.1
#: The status of the world's live metrics on ``/swarm/metrics``.
METRICS_STATUS = contract.METRICS_STATUS

ODOMETRY = contract.ODOMETRY_TYPE
ACCEL = contract.ACCEL_TYPE
DIAGNOSTICS = contract.METRICS_TYPE
_AGENT_TOPIC = contract.AGENT_TOPIC
#: What ``analyze`` needs from a bag, in one sentence (said with every missing-topic error).
NEEDS = ('analyze needs /agent_<i>/odom (nav_msgs/msg/Odometry) of every agent; it also '
         'uses, when present, /agent_<i>/cmd_accel and /leader/accel '
         '(geometry_msgs/msg/AccelStamped), /leader/odom (nav_msgs/msg/Odometry) and '
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
    #: Whether the bag has the leader's state (otherwise the centre of mass stands in).
    has_leader: bool = True
    #: The reader's warning for a truncated or unfinished bag.
    warning: str | None = None
    #: Facts about how the bag was read (fallbacks, skipped steps), one line each.
    notes: list[str] = field(default_factory=list)
    #: Odometry stamps for which some agent's message is missing.
    incomplete_steps: int = 0

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


@dataclass(frozen=True)
class Verification:
    """How far the recorded trajectory is from ``sim`` run on the stored scenario and seed."""

    #: ``max_k max_i ||q_i - q_i^sim||`` [m] over the compared steps.
    max_position_error: float
    #: ``max_k max_i ||p_i - p_i^sim||`` [m/s].
    max_velocity_error: float
    #: Number of steps compared.
    steps_compared: int
    #: The largest accepted error.
    tolerance: float

    @property
    def passed(self) -> bool:
        """Return whether both errors are within the tolerance."""
        return max(self.max_position_error, self.max_velocity_error) <= self.tolerance


@dataclass
class Analysis:
    """What :func:`analyze` produced."""

    #: ``summary.json``.
    summary: dict
    #: ``timeseries.npz``.
    series: dict[str, np.ndarray]
    #: Every file written, ``summary.json`` last.
    files: list[Path] = field(default_factory=list)
    verification: Verification | None = None


class _Ticker:
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
        wanted = ODOMETRY if match and match['kind'] == 'odom' else ACCEL
        if match and type_name == wanted:
            kinds = found.setdefault(match['ns'], {'odom': {}, 'cmd_accel': {}})
            kinds[match['kind']][int(match['id'])] = name
    found = {ns: kinds for ns, kinds in found.items() if kinds['odom']}
    if not found:
        raise AnalyzeError('the bag has no /agent_<i>/odom topics of type nav_msgs/msg/Odometry'
                           f' (it has {_topic_list(topics)}); {NEEDS}')
    if len(found) > 1:
        raise AnalyzeError('the bag holds swarms in several namespaces '
                           f'({", ".join(repr(ns) for ns in sorted(found))}); not supported')
    ns, kinds = next(iter(found.items()))
    odom = kinds['odom']
    n = n_agents if n_agents is not None else max(odom) + 1
    missing = [f'{ns}/agent_{i}/odom' for i in range(n) if i not in odom]
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
                       topic('leader/odom', ODOMETRY), topic('leader/accel', ACCEL),
                       topic('swarm/metrics', DIAGNOSTICS))


def optional_topics_missing(topics: SwarmTopics) -> list[str]:
    """Return the topics ``analyze`` uses when present that a bag lacks.

    :param topics: the swarm's topics in the bag.
    :return: names such as ``/leader/accel`` or ``/agent_<i>/cmd_accel of agent(s) 1, 2``.
    """
    ns = topics.namespace
    missing = [f'{ns}/{suffix}' for suffix, name in (
        ('leader/odom', topics.leader_odom), ('leader/accel', topics.leader_accel),
        ('swarm/metrics', topics.metrics)) if name is None]
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


def _stored_scenario(reader: BagReader, notes: list[str]
                     ) -> tuple[Scenario | None, dict[str, str] | None]:
    """Return the scenario of the bag's ``flock_swarm`` record and the record itself."""
    meta = reader.metadata(METADATA_RECORD)
    if meta is None:
        return None, None
    try:
        return parse_scenario(json.loads(meta['scenario'])), meta
    except KeyError:
        reason = 'no scenario key'
    except json.JSONDecodeError as exc:
        reason = f'not JSON: {exc}'
    except ScenarioError as exc:
        reason = str(exc)
    notes.append(f'the bag\'s {METADATA_RECORD} metadata has no usable scenario ({reason}); '
                 'analysed like a bag without one')
    return None, meta


def _stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def load_run(bag: Path | str, *, radius: float | None = None,
             eta_tolerance: float | None = None, collision_distance: float | None = None,
             progress: Progress | None = None) -> RunData:
    """Read a bag and rebuild the state of every complete step.

    Messages are grouped into steps by their header stamps (``t_k = k dt``): odometry gives
    ``q`` and ``p``; the command stamped ``t_k`` is ``u`` at step ``k`` (zero where the world
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
    sc, meta = _stored_scenario(reader, notes)
    topics = swarm_topics(reader.topics(), sc.n_agents if sc is not None else None)
    absent = optional_topics_missing(topics)
    if absent:
        notes.append(f'optional topic(s) not in the bag: {"; ".join(absent)} (the odometry '
                     'of every agent is all analyze requires)')
    if sc is None:
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

    # stamp -> (N x 6 positions and velocities, N presence flags)
    odom: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    # (stamp, agent, acceleration), in bag order
    cmd: list[tuple[int, int, tuple[float, float, float]]] = field(default_factory=list)
    leader_odom: dict[int, tuple[float, ...]] = field(default_factory=dict)
    leader_accel: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    # (stamp, the world's metric values)
    metrics: list[tuple[int, dict[str, str]]] = field(default_factory=list)
    #: Messages whose bytes do not decode (skipped): ``topic at t ns (reason)``.
    undecodable: list[str] = field(default_factory=list)


def _read_messages(reader: BagReader, topics: SwarmTopics,
                   progress: Progress | None) -> _Messages:
    """Decode the swarm's topics of the bag."""
    kinds: dict[str, tuple[str, int]] = {name: ('odom', i) for i, name in enumerate(topics.odom)}
    kinds.update({name: ('cmd', i) for i, name in topics.cmd.items()})
    for kind, name in (('leader_odom', topics.leader_odom),
                       ('leader_accel', topics.leader_accel), ('metrics', topics.metrics)):
        if name is not None:
            kinds[name] = (kind, -1)
    counts = reader.message_counts()
    total = sum(counts.get(name, 0) for name in kinds)
    n = len(topics.odom)
    out = _Messages()
    tick = _Ticker(progress)
    read = 0
    bad: list[str] = []

    def undecodable(message, reason: str) -> None:
        bad.append(f'{message.topic} at {message.log_time_ns} ns ({reason})')

    for message, msg in reader.decoded(list(kinds), undecodable):
        kind, i = kinds[message.topic]
        stamp = _stamp_ns(msg.header.stamp)
        if kind == 'odom' or kind == 'leader_odom':
            pos, vel = msg.pose.pose.position, msg.twist.twist.linear
            state = (pos.x, pos.y, pos.z, vel.x, vel.y, vel.z)
            if kind == 'leader_odom':
                out.leader_odom[stamp] = state
            else:
                entry = out.odom.get(stamp)
                if entry is None:
                    entry = out.odom[stamp] = (np.zeros((n, 6)), np.zeros(n, dtype=bool))
                entry[0][i] = state
                entry[1][i] = True
        elif kind == 'cmd' or kind == 'leader_accel':
            lin = msg.accel.linear
            if kind == 'cmd':
                out.cmd.append((stamp, i, (lin.x, lin.y, lin.z)))
            else:
                out.leader_accel[stamp] = (lin.x, lin.y, lin.z)
        else:
            for status in msg.status:
                if status.name == METRICS_STATUS:
                    out.metrics.append((stamp, {kv.key: kv.value for kv in status.values}))
        read += 1
        tick(lambda: f'[analyze] reading {reader.path}: {read}/{total} messages '
                     f'({100 * read / max(total, 1):.0f} %)')
    out.undecodable = bad
    return out


def _assemble(reader: BagReader, topics: SwarmTopics, sc: Scenario | None,
              meta: dict[str, str] | None, raw: _Messages, radius: float,
              eta_tolerance: float, collision_distance: float, notes: list[str]) -> RunData:
    """Turn the decoded messages into per-step arrays."""
    n = len(topics.odom)
    complete = sorted(stamp for stamp, (_, seen) in raw.odom.items() if seen.all())
    incomplete = len(raw.odom) - len(complete)
    if not complete:
        lost = f' ({reader.warning})' if reader.warning else ''
        raise AnalyzeError('the bag holds no complete step (odometry of every agent for one '
                           f'stamp){lost}')
    if sc is not None:
        dt, origin = sc.dt, 0
        dt_ns = int(round(dt * 1e9))
    else:
        diffs = np.diff(np.array(sorted(raw.odom), dtype=np.int64))
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
    states = np.stack([raw.odom[stamp][0] for stamp in stamps])
    if sc is not None:
        dim = sc.dim
        t = steps * dt
    else:
        dim = 3 if np.any(states[:, :, [2, 5]] != 0.0) else 2
        t = (np.array(stamps, dtype=np.int64) - origin) * 1e-9
    q = states[:, :, :dim].copy()
    p = states[:, :, 3:3 + dim].copy()
    if incomplete:
        notes.append(f'{incomplete} step(s) without every agent\'s odometry skipped')

    mode = meta.get('mode') if meta is not None else None
    index = {int(k): row for row, k in enumerate(steps)}
    missed: dict[int, list[int]] = {}
    for stamp, values in raw.metrics:
        try:
            ids = json.loads(values.get('missed_this_step', '[]'))
        except json.JSONDecodeError:
            ids = []
        if ids and step_of(stamp) in index:
            missed[step_of(stamp)] = [int(i) for i in ids if 0 <= int(i) < n]
    u = _commands(raw.cmd, steps, index, missed, n, dim, step_of, mode == 'realtime')
    if mode == 'realtime' and sc is not None and sc.intrinsic is None:
        # Which held command the world applied is not in the bag, but the double integrator
        # gives it back from the next state: p_{k+1} = p_k + u_k dt.
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

    if meta is not None and 'informed' in meta:
        ids = json.loads(meta['informed'])
    elif sc is not None:
        ids = realize(sc).informed_ids
    else:
        ids = []
        notes.append('informed agents unknown (no scenario in the bag): none marked')
    informed = np.zeros(n, dtype=bool)
    informed[[int(i) for i in ids]] = True
    return RunData(
        bag=reader.path, steps=steps, t=t, q=q, p=p, u=u, leader_q=leader[0],
        leader_p=leader[1], leader_a=leader[2], informed=informed, dt=dt, radius=float(radius),
        strict_radius=sc.law.strict_radius if sc is not None else True,
        eta_tolerance=float(eta_tolerance), collision_distance=float(collision_distance),
        record_every=sc.record_every if sc is not None else 1, scenario=sc, mode=mode,
        missed_commands_per_agent=[int(x) for x in per_agent], leader_missed=leader_missed,
        has_leader=topics.leader_odom is not None, warning=reader.warning, notes=notes,
        incomplete_steps=incomplete)


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
    for stamp, i, a in cmds:
        row = index.get(step_of(stamp))
        if row is not None:
            u[row, i] = a[:dim]
    for k, ids in missed.items():
        # The world applied zero: the command came after the step's timeout.
        u[index[k], ids] = 0.0
    return u


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


def recompute(run: RunData, record_every: int | None = None,
              progress: Progress | None = None) -> tuple[dict[str, np.ndarray], RunMetrics]:
    """Recompute the metrics of every step as the world node does, and the time series.

    Every complete step updates the whole-run metrics from its r-disk edges
    (:meth:`RunMetrics.update_from_edges`: minimum distance, collision pairs); every
    ``record_every``-th step and the last are recorded with :func:`step_metrics`, exactly as
    in ``WorldStepper.observe`` (and ``sim`` for r-disk scenarios).

    :param run: the run.
    :param record_every: subsampling of the series (default: the scenario's).
    :param progress: called with a line every few seconds.
    :return: the series (the arrays of ``timeseries.npz``) and the whole-run metrics.
    """
    log = RunLog(run.eta_tolerance, run.collision_distance, run.radius, run.strict_radius,
                 record_every or run.record_every)
    last = len(run.steps) - 1
    tick = _Ticker(progress)
    for row, k in enumerate(run.steps):
        q, p = run.q[row], run.p[row]
        leader = LeaderState(run.leader_q[row], run.leader_p[row], run.leader_a[row])
        log.observe(int(k), float(run.t[row]), q, p, run.u[row], leader, run.informed,
                    disk_graph(q, run.radius, run.strict_radius), run.radius, row == last)
        tick(lambda: f'[analyze] metrics: step {row + 1}/{last + 1}')
    return log.rec.arrays(), log.metrics


def _status(run: RunData) -> str:
    if run.scenario is not None and run.steps[-1] >= run.scenario.steps:
        return 'completed'
    if run.warning is not None:
        return 'truncated'
    return 'interrupted' if run.scenario is not None else 'completed'


def summarize(run: RunData, series: dict[str, np.ndarray], metrics: RunMetrics) -> dict:
    """Return ``summary.json``: the world's summary for the same run, from the bag.

    :param run: the run.
    :param series: its recomputed series.
    :param metrics: its whole-run metrics.
    :return: the keys of ``docs/outputs.md``, provenance, the world's ``mode`` and
        missed-command counts, and where the data came from (``bag``, ``complete_steps``,
        ``bag_warning``).
    """
    status = _status(run)
    last_step = int(run.steps[-1])
    if run.scenario is not None:
        summary = build_summary(run.scenario, realize(run.scenario), series, metrics,
                                last_step, status)
    else:
        final = {name: float(series[f'metric_{name}'][-1]) for name in STEP_METRICS}
        summary = {
            'n_agents': run.n_agents, 't_final': float(series['t'][-1]), 'steps': last_step,
            'eta': final['eta'], 'eta_tolerance': run.eta_tolerance,
            'velocity_mismatch_max': final['velocity_mismatch_max'],
            'com_position_error': final['com_position_error'],
            'com_velocity_error': final['com_velocity_error'],
            'min_pair_distance': metrics.min_pair_distance,
            'collisions': len(metrics.collision_pairs),
            'collision_distance': run.collision_distance,
            'components_final': int(final['components']),
            'informed': [int(i) for i in np.flatnonzero(run.informed)],
            'scenario': None, 'seed': None, 'protocol': None, 'dt': run.dt, 'status': status,
            'flock_swarm_version': __version__,
        }
    summary.update({
        'mode': run.mode,
        'missed_commands': int(sum(run.missed_commands_per_agent)),
        'missed_commands_per_agent': run.missed_commands_per_agent,
        'leader_missed': run.leader_missed,
        'bag': str(run.bag),
        'complete_steps': int(len(run.steps)),
        'bag_warning': run.warning,
    })
    return summary


def verify_run(run: RunData, tolerance: float = VERIFY_TOLERANCE,
               progress: Progress | None = None) -> Verification:
    """Re-run ``sim`` on the bag's scenario and seed; compare positions and velocities.

    The simulation runs to the last complete step of the bag and records every step; each
    complete step of the bag is compared with the simulated state of the same step.

    :param run: a run whose bag stores its scenario.
    :param tolerance: the largest accepted error (m and m/s).
    :param progress: forwarded to :func:`flock_swarm.core.run.simulate`.
    :return: the largest errors.
    :raises AnalyzeError: if the bag has no scenario.
    """
    sc = run.scenario
    if sc is None:
        raise AnalyzeError('--verify needs the scenario stored in the bag (MCAP metadata '
                           f'record {METADATA_RECORD!r}); this bag has none')
    data = dict(sc.raw, record_every=1)
    last = int(run.steps[-1])
    if last < sc.steps:
        data['duration'] = max(last, 1) * sc.dt
    reference = simulate(parse_scenario(data), progress=progress).series
    simulated = reference['q'].shape[0]
    rows = np.flatnonzero(run.steps < simulated)
    if rows.size < len(run.steps):
        # The simulation diverged before the recording ended: no agreement there.
        return Verification(float('inf'), float('inf'), int(rows.size), tolerance)
    k = run.steps[rows]
    dq = np.linalg.norm(run.q[rows] - reference['q'][k], axis=2)
    dp = np.linalg.norm(run.p[rows] - reference['p'][k], axis=2)
    return Verification(float(dq.max()), float(dp.max()), int(rows.size), tolerance)


def write_csv(series: dict[str, np.ndarray], path: Path) -> Path:
    """Write the metric time series as CSV: ``t`` and the metrics of :data:`STEP_METRICS`.

    :param series: the time series.
    :param path: the file.
    :return: the path.
    """
    columns = ['t'] + [f'metric_{name}' for name in STEP_METRICS]
    table = np.column_stack([series[name] for name in columns])
    np.savetxt(path, table, fmt='%.17g', delimiter=',', comments='',
               header=','.join(['t', *STEP_METRICS]))
    return path


def analyze(run: RunData, out: Path, *, snapshots: Sequence[float] | None = None,
            animate: bool = True, verify: bool = False,
            verify_tolerance: float = VERIFY_TOLERANCE, record_every: int | None = None,
            progress: Progress | None = None) -> Analysis:
    """Recompute the metrics of a run and write its outputs and figures into ``out``.

    Files: ``timeseries.npz``, ``timeseries.csv``, ``scenario.json`` (when the bag stores the
    scenario), the figures of :func:`flock_swarm.plots.plot_analysis`, and ``summary.json``
    last (atomically: its presence means the other files are complete).

    :param run: the run, from :func:`load_run`.
    :param out: the output directory (created).
    :param snapshots: snapshot times [s] (default: first, middle and last instants).
    :param animate: write ``flock.gif``.
    :param verify: compare with ``sim`` (:func:`verify_run`) and add ``verify_*`` keys.
    :param verify_tolerance: the largest accepted deviation.
    :param record_every: subsampling of the series (default: the scenario's).
    :param progress: called with one-line progress messages.
    :return: the summary, the series, the files written and the verification.
    :raises OSError: if ``out`` cannot be written.
    """
    from flock_swarm.plots import plot_analysis
    series, metrics = recompute(run, record_every, progress)
    summary = summarize(run, series, metrics)
    verification = None
    if verify:
        verification = verify_run(run, verify_tolerance, progress)
        summary.update({
            'verify_max_position_error': verification.max_position_error,
            'verify_max_velocity_error': verification.max_velocity_error,
            'verify_steps_compared': verification.steps_compared,
            'verify_tolerance': verification.tolerance,
            'verify_passed': verification.passed,
        })
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / 'timeseries.npz', **series)
    files = [out / 'timeseries.npz', write_csv(series, out / 'timeseries.csv')]
    if run.scenario is not None:
        (out / 'scenario.json').write_text(
            json_text(run.scenario.raw))
        files.append(out / 'scenario.json')

    def wrote(path: Path) -> None:
        files.append(path)
        if progress is not None:
            progress(f'[analyze] wrote {path}')

    plot_analysis(series, out, radius=run.radius, strict=run.strict_radius, title=run.name,
                  informed=run.informed, eta_tolerance=run.eta_tolerance,
                  collision_distance=run.collision_distance, snapshots=snapshots,
                  animate=animate, progress=wrote)
    tmp = out / 'summary.json.tmp'
    tmp.write_text(json_text(summary))
    tmp.replace(out / 'summary.json')
    files.append(out / 'summary.json')
    return Analysis(summary, series, files, verification)


def default_out(bag: Path) -> Path:
    """Return the default output directory: ``<bag>_analysis`` next to the bag.

    :param bag: the bag directory or ``.mcap`` file.
    :return: for ``out/demo_ros/bag``, ``out/demo_ros/bag_analysis``.
    """
    bag = Path(bag)
    if not bag.name:
        bag = bag.resolve()
    stem = bag.stem if bag.suffix == '.mcap' else bag.name
    return bag.parent / f'{stem}_analysis'


def _times(text: str) -> list[float]:
    try:
        times = [float(part) for part in text.split(',') if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected times in seconds like 0,10,30, got {text!r}')
    if not times or not all(np.isfinite(times)):
        raise argparse.ArgumentTypeError(f'expected times in seconds like 0,10,30, got {text!r}')
    return times


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float('nan')
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f'must be a positive number, got {text!r}')
    return value


def _positive_int(text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f'must be a positive integer, got {text!r}')
    return int(text)


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``analyze``."""
    parser = OneLineParser(
        prog='analyze',
        description='Metrics, time series and figures of a recorded flock_swarm run.')
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('--out', type=Path,
                        help='output directory (default: BAG_analysis next to the bag)')
    parser.add_argument('--snapshots', type=_times, metavar='T,T,...',
                        help='snapshot times in seconds (default: first, middle, last)')
    parser.add_argument('--no-anim', action='store_true', help='do not write flock.gif')
    parser.add_argument('--record-every', type=_positive_int, metavar='N',
                        help='record every N-th step in the series (default: the scenario\'s '
                        'record_every, 1 without a scenario)')
    parser.add_argument('--verify', action='store_true',
                        help='re-run sim from the scenario and seed in the bag and compare '
                        'the trajectories (exit status 1 if they differ)')
    parser.add_argument('--verify-tolerance', type=_positive, default=VERIFY_TOLERANCE,
                        metavar='TOL', help='largest accepted deviation in m and m/s '
                        f'(default {VERIFY_TOLERANCE:g})')
    fallback = parser.add_argument_group(
        'bags without a flock_swarm scenario (ignored when the bag has one)')
    fallback.add_argument('--radius', type=_positive, metavar='R',
                          help='interaction radius r [m] (required for such bags)')
    fallback.add_argument('--eta-tolerance', type=_positive, metavar='TOL',
                          help=f'tolerance of eta [m/s] (default {FALLBACK_ETA_TOLERANCE:g})')
    fallback.add_argument('--collision-distance', type=_positive, metavar='D',
                          help='collision distance [m] '
                          f'(default {FALLBACK_COLLISION_DISTANCE:g})')
    parser.add_argument('--quiet', action='store_true',
                        help='no progress output (warnings and the --verify result remain)')
    return parser


def _check_writable(out: Path) -> None:
    try:
        ensure_writable(out)
    except OSError as exc:
        raise AnalyzeError(f'--out: cannot write to {out}: {exc.strerror or exc}') from None


def main(argv: list[str] | None = None) -> int:
    """Run ``analyze`` from the command line; return the exit status."""
    args = build_parser().parse_args(argv)

    def warn(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    say = None if args.quiet else warn
    try:
        return _run(args, say, warn)
    except KeyboardInterrupt:
        warn('analyze: interrupted')
        return EXIT_INTERRUPTED
    except (AnalyzeError, BagError) as exc:
        warn(f'analyze: error: {exc}')
        return EXIT_USAGE
    except OSError as exc:
        warn(f'analyze: error: {exc.filename or ""}: {exc.strerror or exc}')
        return EXIT_USAGE
    except Exception as exc:
        # One line, as promised for every failure; the type says where to look.
        warn(f'analyze: error: {type(exc).__name__}: {" ".join(str(exc).split())}')
        return EXIT_USAGE


def _run(args: argparse.Namespace, say: Progress | None, warn: Progress) -> int:
    started = time.monotonic()
    run = load_run(args.bag, radius=args.radius, eta_tolerance=args.eta_tolerance,
                   collision_distance=args.collision_distance, progress=say)
    if run.warning is not None:
        warn(f'[analyze] warning: {run.warning}; analysing the {len(run.steps)} complete '
             'step(s)')
    for note in run.notes:
        warn(f'[analyze] note: {note}')
    if args.verify and run.scenario is None:
        raise AnalyzeError('--verify needs the scenario stored in the bag (MCAP metadata '
                           f'record {METADATA_RECORD!r}); this bag has none')
    if args.verify and run.mode == 'realtime':
        warn('[analyze] note: a realtime run is asynchronous; --verify compares it with the '
             'deterministic sim anyway')
    out = args.out if args.out is not None else default_out(args.bag)
    _check_writable(out)
    if say:
        say(f'[analyze] {run.name}: {run.n_agents} agents in {run.dim}-D, '
            f'{len(run.steps)} complete steps of {run.dt:g} s')
    try:
        result = analyze(run, out, snapshots=args.snapshots, animate=not args.no_anim,
                         verify=args.verify, verify_tolerance=args.verify_tolerance,
                         record_every=args.record_every, progress=say)
    except OSError as exc:
        raise AnalyzeError(f'--out: writing {out} failed: {exc.strerror or exc}') from None
    s = result.summary
    if say:
        say(f'[analyze] {s["status"]} at t = {s["t_final"]:g} s: eta = {s["eta"]:.3f}, '
            f'velocity mismatch = {s["velocity_mismatch_max"]:.3g}, '
            f'collisions = {s["collisions"]}, components = {s["components_final"]} '
            f'({time.monotonic() - started:.1f} s)')
        say(f'[analyze] wrote {len(result.files)} files to {out}')
    check = result.verification
    if check is not None:
        print(f'[analyze] verify: largest deviation from sim over {check.steps_compared} '
              f'steps: position {check.max_position_error:.3g} m, velocity '
              f'{check.max_velocity_error:.3g} m/s (tolerance {check.tolerance:g})', flush=True)
        if not check.passed:
            warn(f'analyze: verify failed: the recording deviates from sim by '
                 f'{check.max_position_error:.3g} m, {check.max_velocity_error:.3g} m/s '
                 f'(tolerance {check.tolerance:g})')
            return EXIT_VERIFY_FAILED
    return 0


if __name__ == '__main__':
    sys.exit(main())
