"""The player: a node that republishes a recorded bag with its recorded timing.

What ``replay`` runs (:mod:`flock_swarm.cli.replay`), like ``ros2 bag play``. ``BAG`` is a bag
directory or one ``.mcap`` file, written by this package or by ``ros2 bag record -s mcap``.
Each message is published at wall time ``start + (log_time - t_start) / rate`` (monotonic
clock), as the CDR bytes it was recorded with: :meth:`rclpy.publisher.Publisher.publish`
takes ``bytes`` and hands them to ``rcl_publish_serialized_message``, so nothing is
deserialised. With a progress stream, a line updated twice a second gives the bag time (ns
since the epoch, or simulation time for a simulated run) and the time elapsed since the start
of the bag::

    [RUNNING]  Bag Time 1700000012.340000000  Duration 2.340000000/10.000000000

Given a :class:`~flock_swarm.foxglove_ws.LiveServer`, the same bytes, on the same schedule,
are also served over the Foxglove WebSocket protocol, logged at their recorded times, the
server's time following bag time. Invalid options raise :class:`ReplayError`, one line
naming the option. See ``docs/replay.md``.
"""

from dataclasses import dataclass, field
import difflib
import math
from numbers import Integral
from pathlib import Path
import re
import sys
import threading
import time
from typing import Callable, Iterable, Sequence, TextIO

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy)
from rosgraph_msgs.msg import Clock

from flock_swarm import contract
from flock_swarm.bag import BagError, BagReader, message_class, parse_qos_profiles
from flock_swarm.bag.msgdefs import DefinitionNotFoundError
from flock_swarm.contract import CLOUD_TYPE, COMMANDS, STATES, qos_profile
from flock_swarm.nodes.cloud import PerAgentMessages, decode_cloud
from flock_swarm.nodes.wire import MalformedMessage

#: The simulation clock topic (REP-2008 ``/clock``).
CLOCK_TOPIC = contract.CLOCK
#: Publisher depth of replayed volatile topics, at least: the recorded offer's depth sized the
#: original publisher's queue for its own rate, while a replay at ``--rate 10`` sends bursts ten
#: times denser; a reliable writer overwrites unacknowledged samples once its queue is full.
REPLAY_DEPTH = 100
#: /clock as the world publishes it (the contract's QoS).
CLOCK_QOS = qos_profile(contract.CLOCK_QOS)
#: Longest single wait (s): bounds the reaction time to Ctrl-C and :meth:`Player.stop`.
MAX_WAIT = 0.05
#: Before its first message the player waits for discovery to settle (a subscriber that was
#: there before the replay missed its first seconds: discovery matches it only a while after
#: the player's publishers were made): at least DISCOVERY_MIN s after the publishers were
#: made, and until neither the nodes of the graph nor the matched subscriptions of the
#: publishers have changed for DISCOVERY_QUIET s; all within ``--wait-timeout``.
DISCOVERY_MIN = 1.0
DISCOVERY_QUIET = 0.5
#: With ``clock``, the player looks on the ROS graph for another ``/clock`` publisher for at
#: least DISCOVERY_MIN s after its publishers were made, before its first tick, whatever
#: ``wait_timeout`` says, and refuses to play beside one (:class:`ClockTaken`).
#: How a publisher whose node discovery has not named yet is listed.
UNNAMED = 'a node not yet named'
#: Final stretch (s) of a wait that is slept rather than spent in the executor: rcl's wait
#: overshoots its timeout by up to ~3.5 ms now and then on these machines, time.sleep by ~0.1 ms.
SLEEP_MARGIN = 0.005
#: Wall seconds between two progress updates (ros2 bag play updates a few times a second).
PROGRESS_PERIOD = 0.5

_NS = 10**9


class ReplayError(ValueError):
    """An invalid replay option; the message is one line and starts with the option."""

    def __init__(self, option: str, reason: str) -> None:
        """Create the error.

        :param option: the offending option, such as ``--rate``.
        :param reason: what is wrong, one line.
        """
        super().__init__(f'{option}: {reason}')
        self.option = option
        self.reason = reason


class ClockTaken(ReplayError):
    """``--clock`` on a domain where another node publishes ``/clock`` (a world started by
    hand, another replay): two clocks would make simulation time jump. Invalid input, as a
    domain held by a run of this machine is (exit status 2)."""


@dataclass
class PlayResult:
    """What :meth:`Player.play` did."""

    #: Messages published per topic (over all passes).
    published: dict[str, int] = field(default_factory=dict)
    #: /clock messages published (``--clock``).
    clock_ticks: int = 0
    #: Passes through the bag that were started (more than one with ``loop``).
    passes: int = 0
    #: Whether every publisher had its subscribers before the start (always with ``N = 0``).
    matched: bool = True
    #: Whether Ctrl-C, a shutdown of the context or :meth:`Player.stop` ended the playback.
    interrupted: bool = False
    #: Largest delay (s) of a publication behind its scheduled wall time.
    max_lateness: float = 0.0

    @property
    def total(self) -> int:
        """All messages published (without /clock)."""
        return sum(self.published.values())


def replay_qos(profiles: Sequence[QoSProfile]) -> QoSProfile:
    """Return the QoS a replay publisher offers, given the offers recorded for the topic.

    As ``rosbag2_transport`` does: the recorded offer is kept (reliability, durability,
    deadline, lifespan, liveliness), since it is what the topic's subscribers were made to
    match. Offers that disagree on reliability or durability fall back to reliable and
    volatile: a reliable offer matches reliable and best-effort requests alike, and volatile
    does not hand stale history to late joiners. A transient-local topic keeps its recorded
    depth (that many latched messages); a volatile one gets at least :data:`REPLAY_DEPTH`.
    With no recorded offer: reliable, volatile, keep last :data:`REPLAY_DEPTH`, which
    matches any subscription whose durability is volatile (rclpy's and rclcpp's default).

    :param profiles: the recorded offers (:func:`flock_swarm.bag.parse_qos_profiles`).
    :return: the profile for the replay publisher.
    """
    if not profiles:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REPLAY_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
    first = profiles[0]
    reliability = first.reliability
    if (any(p.reliability != reliability for p in profiles)
            or reliability not in (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT)):
        reliability = ReliabilityPolicy.RELIABLE
    durability = first.durability
    if (any(p.durability != durability for p in profiles)
            or durability not in (DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL)):
        durability = DurabilityPolicy.VOLATILE
    liveliness = first.liveliness
    if liveliness not in (LivelinessPolicy.AUTOMATIC, LivelinessPolicy.MANUAL_BY_TOPIC):
        liveliness = LivelinessPolicy.AUTOMATIC
    history = (HistoryPolicy.KEEP_ALL if first.history == HistoryPolicy.KEEP_ALL
               else HistoryPolicy.KEEP_LAST)
    if durability == DurabilityPolicy.TRANSIENT_LOCAL:
        depth = max(int(first.depth), 1)
    else:
        depth = max(int(first.depth), REPLAY_DEPTH)
    return QoSProfile(
        history=history, depth=depth, reliability=reliability, durability=durability,
        deadline=first.deadline, lifespan=first.lifespan, liveliness=liveliness,
        liveliness_lease_duration=first.liveliness_lease_duration,
        avoid_ros_namespace_conventions=first.avoid_ros_namespace_conventions)


def select_topics(available: Iterable[str], topics: Sequence[str] | None = None,
                  regex: str | None = None, exclude: str | None = None,
                  clock: bool = False) -> list[str]:
    """Return the recorded topics to replay, in bag order.

    The filters combine as in rosbag2's storage filter: a topic is replayed if it is in
    ``topics`` (when given) and matches ``regex`` (when given) and does not match
    ``exclude``. Patterns are Python regular expressions searched anywhere in the name
    (:func:`re.search`); anchor them (``^/agent_\\d+/odom$``) to match whole names. With
    ``clock``, the recorded /clock is left out: the player publishes /clock itself.

    :param available: the topics of the bag.
    :param topics: topic names to replay; every one must be in the bag.
    :param regex: keep only topics matching this pattern.
    :param exclude: drop topics matching this pattern.
    :param clock: whether the player publishes /clock (``--clock``).
    :return: the selected topics.
    :raises ReplayError: for a topic the bag does not have, an invalid pattern, /clock named
        together with ``clock``, or a selection left empty.
    """
    available = list(available)
    compiled = {}
    for option, pattern in (('--regex', regex), ('--exclude', exclude)):
        if pattern is not None:
            try:
                compiled[option] = re.compile(pattern)
            except re.error as exc:
                raise ReplayError(option, f'invalid regular expression {pattern!r}: {exc}'
                                  ) from None
    selected = available
    if topics is not None:
        missing = [name for name in topics if name not in available]
        if missing:
            # The closest recorded names first: a typo (/leader/odm, leader/odom) is then
            # answered with the name meant, not only a list of every topic of the bag.
            close = difflib.get_close_matches(missing[0], available, n=3, cutoff=0.6)
            hint = f"did you mean {' or '.join(close)}? " if close else ''
            raise ReplayError('--topics', f"not in the bag: {', '.join(missing)} ({hint}the "
                              f"bag has {', '.join(available) or 'no topics'})")
        if clock and CLOCK_TOPIC in topics:
            raise ReplayError('--topics', f'{CLOCK_TOPIC} cannot be replayed with --clock, '
                              f'which publishes {CLOCK_TOPIC} from bag time')
        selected = [name for name in available if name in set(topics)]
    if '--regex' in compiled:
        selected = [name for name in selected if compiled['--regex'].search(name)]
        if not selected:
            raise ReplayError('--regex', f'{regex!r} matches no selected topic of the bag')
    if '--exclude' in compiled:
        selected = [name for name in selected if not compiled['--exclude'].search(name)]
        if not selected:
            raise ReplayError('--exclude', f'{exclude!r} leaves no topic to replay')
    if clock:
        selected = [name for name in selected if name != CLOCK_TOPIC]
        if not selected:
            raise ReplayError('--clock', f'the only selected topic is {CLOCK_TOPIC}, which '
                              '--clock replaces')
    if not selected:
        raise ReplayError('BAG', 'the bag has no topics')
    return selected


def bag_timeline(reader: BagReader) -> tuple[int, int] | None:
    """Return the log times (ns) of the first and last message of the whole bag.

    Taken from ``metadata.yaml`` when the bag has a sound one, else from a pass over the
    messages (a recovered bag, or a bare ``.mcap`` file).

    :param reader: the open bag.
    :return: ``(start_ns, end_ns)``, or None for a bag without messages.
    """
    info = reader.bag_metadata
    if info is not None and not reader.recovered:
        try:
            if int(info['message_count']) == 0:
                return None
            start = int(info['starting_time']['nanoseconds_since_epoch'])
            return start, start + int(info['duration']['nanoseconds'])
        except (KeyError, TypeError, ValueError):
            pass
    start = end = None
    for message in reader.messages():
        t = message.log_time_ns
        start = t if start is None else min(start, t)
        end = t if end is None else max(end, t)
    return None if start is None else (start, end)


def recorded_offers(reader: BagReader, topics: Iterable[str]) -> dict[str, str]:
    """Return the recorded ``offered_qos_profiles`` text of topics that have messages.

    Reads messages only until each topic has shown one (usually within the first chunk).

    :param reader: the open bag.
    :param topics: the topics wanted.
    :return: topic to the channel's ``offered_qos_profiles`` (topics without messages are
        left out).
    """
    counts = reader.message_counts()
    wanted = {name for name in topics if counts.get(name)}
    offers: dict[str, str] = {}
    if wanted:
        for message in reader.messages(wanted):
            offers.setdefault(message.topic, message.offered_qos_profiles)
            if len(offers) == len(wanted):
                break
    return offers


#: ``republish``'s values: the topics as recorded, or a batched bag's clouds as the
#: per-agent transport's topics.
REPUBLISH = ('as_recorded', 'per_agent')
#: A cloud topic of the batched transport, in any namespace.
_CLOUD_TOPIC = re.compile(rf'^(?P<ns>(?:/[^/]+)*?)/(?P<kind>{STATES}|{COMMANDS})$')


class PerAgentView:
    """A batched bag seen as the per-agent transport's bag (``--republish per_agent``).

    :ivar available: the topics to choose from and their types, in bag order, each cloud
        topic in place of the per-agent topics it becomes.
    :ivar source: each of those topics' recorded topic.
    """

    def __init__(self, reader: BagReader, recorded: dict[str, str]) -> None:
        """Find the bag's clouds and, from their first messages, the per-agent topics.

        :raises ReplayError: for a bag without a state cloud (a per-agent bag, say).
        """
        clouds = {name: _CLOUD_TOPIC.match(name) for name, kind in recorded.items()
                  if kind == CLOUD_TYPE and _CLOUD_TOPIC.match(name)}
        counts = reader.message_counts()
        states = [n for n, m in clouds.items() if m['kind'] == STATES and counts.get(n)]
        if not states:
            raise ReplayError('--republish', f'per_agent: the bag has no {STATES} cloud with '
                              'messages (a per-agent bag has the per-agent topics already: '
                              'replay it without --republish)')
        namespace = clouds[states[0]]['ns']
        commands = [n for n, m in clouds.items() if m['ns'] == namespace and counts.get(n)
                    and m['kind'] == COMMANDS]
        first = {}
        for message in reader.messages([states[0], *commands]):
            first.setdefault(message.topic, message.data)
            if len(first) == 1 + len(commands):
                break
        try:
            state = decode_cloud(bytes(first[states[0]]))
            command = decode_cloud(bytes(first[commands[0]])) if commands else None
        except MalformedMessage as exc:
            raise ReplayError('--republish', f'per_agent: {states[0]}: {exc}') from None
        self.split = PerAgentMessages(len(state.points), state.names(),
                                      command.names() if command else ())
        self.clouds = {states[0]: self.split.states,
                       **{name: self.split.commands for name in commands}}
        self.prefix = namespace
        self.available: dict[str, str] = {}
        self.source: dict[str, str] = {}
        for name, kind in recorded.items():
            if name not in self.clouds:
                self.available[name], self.source[name] = kind, name
                continue
            wanted = 'odom' if name == states[0] else None
            for topic, type_name in self.split.topics.items():
                if (topic.endswith('/odom')) == (wanted == 'odom'):
                    self.available[f'{namespace}/{topic}'] = type_name
                    self.source[f'{namespace}/{topic}'] = name

    def messages(self, topic: str, data: bytes) -> list[tuple[str, bytes]]:
        """Return the ``(topic, bytes)`` a recorded message is replayed as.

        :raises ReplayError: for a cloud that does not decode.
        """
        split = self.clouds.get(topic)
        if split is None:
            return [(topic, data)]
        try:
            return [(f'{self.prefix}/{name}', out) for name, out in split(decode_cloud(data))]
        except MalformedMessage as exc:
            raise ReplayError('--republish', f'per_agent: a cloud of {topic}: {exc}') from None


def format_ns(ns: int) -> str:
    """Format a time in ns as seconds with nine decimals, exactly (no float rounding)."""
    sign = '-' if ns < 0 else ''
    ns = abs(ns)
    return f'{sign}{ns // _NS}.{ns % _NS:09d}'


def _check_number(option: str, value: float, low: float, strict: bool) -> float:
    value = float(value)
    if not math.isfinite(value) or value < low or (strict and value == low):
        relation = '>' if strict else '>='
        raise ReplayError(option, f'must be a finite number {relation} {low:g}, got {value:g}')
    return value


def _message_classes(recorded: dict[str, str], selected: Iterable[str], bag: str,
                     say: Callable[[str], None]) -> dict[str, type]:
    """Return the message class of each selected topic whose type is installed (the others
    skipped with one warning).

    :raises ReplayError: if none is.
    """
    classes: dict[str, type] = {}
    unknown = []
    for name in selected:
        try:
            classes[name] = message_class(recorded[name])
        except (DefinitionNotFoundError, ValueError):
            unknown.append(f'{name} ({recorded[name] or "no schema"})')
    if unknown:
        say(f'replay: warning: skipping topics whose message types are not '
            f"installed: {', '.join(unknown)}")
    if not classes:
        raise ReplayError(bag, 'none of the selected topics has an installed message type')
    return classes


def _offered_qos(name: str, offers: str, say: Callable[[str], None]) -> QoSProfile:
    """Return the QoS to offer on topic ``name`` from its recorded offers (the default QoS,
    with a warning, if they cannot be read)."""
    try:
        return replay_qos(parse_qos_profiles(offers))
    except BagError as exc:
        say(f'replay: warning: {name}: {exc}; offering the default QoS')
        return replay_qos([])


class Player(Node):
    """A node that republishes a bag's messages with their recorded timing.

    The bag is opened and the options are checked before the node exists, so invalid input
    raises without leaving a node behind. The player spins itself (its own executor, in the
    thread calling :meth:`play`): do not add it to another executor.

    :param bag: the bag (directory or ``.mcap`` file), or an open :class:`BagReader`.
    :param rate: time scaling: wall seconds per bag second are ``1 / rate``.
    :param loop: start again from the start offset after the last message, until stopped.
    :param topics: replay only these topics (all when None).
    :param regex: replay only topics matching this pattern (:func:`select_topics`).
    :param exclude: do not replay topics matching this pattern.
    :param start_offset: seconds into the bag at which to start; earlier messages are skipped.
    :param clock: publish /clock (rosgraph_msgs/Clock) from bag time; a recorded /clock is
        then not replayed.
    :param clock_rate: /clock publications per wall second.
    :param wait_subscribers: before the start, wait until a replayed topic (or /clock) has
        this many matched subscriptions (one subscriber of any topic, for 1); in any case
        the player waits for discovery to settle (:data:`DISCOVERY_MIN`,
        :data:`DISCOVERY_QUIET`), so a subscriber that was there before gets the first
        message.
    :param wait_timeout: longest wait (s) for those subscribers and discovery; then play
        anyway (0: at once).
    :param delay: wall seconds to wait before the first message (after the subscribers).
    :param progress: stream for the progress line (None: no progress).
    :param say: receives warning and information lines (default: stderr).
    :param live: a :class:`~flock_swarm.foxglove_ws.LiveServer` that serves every replayed message
        too (its recorded bytes, logged at its recorded time), or None.
    :param node_name: name of the node.
    :param republish: ``as_recorded`` (the recorded topics) or ``per_agent``: a batched bag's
        clouds as the per-agent transport's topics (:class:`PerAgentView`); the topic filters
        then choose among those.
    :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``namespace``...).
    :raises BagError: if the bag cannot be read.
    :raises ReplayError: for an invalid option or a selection without replayable topics.
    """

    def __init__(self, bag: BagReader | Path | str, *, rate: float = 1.0, loop: bool = False,
                 topics: Sequence[str] | None = None, regex: str | None = None,
                 exclude: str | None = None, start_offset: float = 0.0, clock: bool = False,
                 clock_rate: float = 100.0, wait_subscribers: int = 0,
                 wait_timeout: float = 10.0, delay: float = 0.0,
                 progress: TextIO | None = None, say: Callable[[str], None] | None = None,
                 live=None, node_name: str = 'replay', republish: str = 'as_recorded',
                 **kwargs) -> None:
        """Open the bag, check the options, create the node and its publishers."""
        self._say = say if say is not None else (
            lambda line: print(line, file=sys.stderr, flush=True))
        self._rate = _check_number('--rate', rate, 0.0, strict=True)
        self._clock_period = 1.0 / _check_number('--clock-rate', clock_rate, 0.0, strict=True)
        offset = _check_number('--start-offset', start_offset, 0.0, strict=False)
        self._wait_timeout = _check_number('--wait-timeout', wait_timeout, 0.0, strict=False)
        self._delay = _check_number('--delay', delay, 0.0, strict=False)
        if (not isinstance(wait_subscribers, Integral) or isinstance(wait_subscribers, bool)
                or wait_subscribers < 0):
            raise ReplayError('--wait-for-subscribers',
                              f'must be a whole number >= 0, got {wait_subscribers}')
        self._wait_subscribers = int(wait_subscribers)
        self._loop = bool(loop)
        self._progress = progress
        self._reader = bag if isinstance(bag, BagReader) else BagReader(Path(bag))
        if self._reader.warning:
            self._say(f'replay: warning: {self._reader.warning}')
        recorded = self._reader.topics()
        if not recorded:
            name = bag if not isinstance(bag, BagReader) else 'the bag'
            raise ReplayError('BAG', f'{name} holds no topics, so nothing to replay (a '
                              'recording stopped before its first message?)')
        if republish not in REPUBLISH:
            raise ReplayError('--republish', f"must be one of {', '.join(REPUBLISH)}, got "
                              f'{republish!r}')
        self._view = PerAgentView(self._reader, recorded) if republish == 'per_agent' else None
        if self._view is not None:
            recorded = self._view.available
        selected = select_topics(recorded, topics, regex, exclude, clock)
        if clock and CLOCK_TOPIC in recorded:
            self._say(f'[replay] --clock: the recorded {CLOCK_TOPIC} is not replayed; '
                      f'{CLOCK_TOPIC} follows bag time at {1.0 / self._clock_period:g} Hz')
        classes = _message_classes(recorded, selected, str(self._reader.path), self._say)
        timeline = bag_timeline(self._reader)
        self._bag_start, self._bag_end = timeline if timeline is not None else (0, 0)
        self._offset_ns = round(offset * _NS)
        if self._offset_ns > self._bag_end - self._bag_start:
            raise ReplayError('--start-offset', f'{offset:g} s is past the end of the bag '
                              f'(duration {format_ns(self._bag_end - self._bag_start)} s)')
        source = self._view.source if self._view is not None else {n: n for n in classes}
        self._sources = sorted({source[name] for name in classes})
        offers = recorded_offers(self._reader, self._sources)
        qos = {name: _offered_qos(name, offers.get(source[name], ''), self._say)
               for name in classes}
        super().__init__(node_name, **kwargs)
        self._topic_pubs: dict[str, Publisher] = {
            name: self.create_publisher(cls, name, qos[name]) for name, cls in classes.items()}
        self._clock_pub = (self.create_publisher(Clock, CLOCK_TOPIC, CLOCK_QOS) if clock
                           else None)
        self._live = live
        if live is not None:
            live.add_topics((pub.topic_name, recorded[name])
                            for name, pub in self._topic_pubs.items())
        self._stop = threading.Event()
        self._executor: SingleThreadedExecutor | None = None
        # Wall time (monotonic) and bag time (ns) at which the current pass started.
        self._wall_zero = 0.0
        self._pass_start_ns = self._bag_start + self._offset_ns
        self._next_clock = math.inf
        self._next_progress = 0.0
        self._progress_shown = False
        self._created = time.monotonic()

    @property
    def topics(self) -> list[str]:
        """The topics replayed, in bag order."""
        return list(self._topic_pubs)

    @property
    def qos_profiles(self) -> dict[str, QoSProfile]:
        """The QoS offered on each replayed topic."""
        return {name: pub.qos_profile for name, pub in self._topic_pubs.items()}

    @property
    def duration_ns(self) -> int:
        """Time (ns) from the first to the last message of the bag."""
        return self._bag_end - self._bag_start

    def stop(self) -> None:
        """Ask the running :meth:`play` to return soon (within :data:`MAX_WAIT`).

        Safe to call from any thread; a later :meth:`play` starts afresh.
        """
        self._stop.set()

    def play(self, max_passes: int | None = None) -> PlayResult:
        """Replay the bag: wait for subscribers, then publish every message on schedule.

        Ctrl-C (or a shutdown of the node's context, or :meth:`stop`) ends the playback
        early; the result then says ``interrupted``.

        :param max_passes: stop after this many passes through the bag (None: one, or
            endless with ``loop``).
        :return: what was published.
        """
        result = PlayResult(published=dict.fromkeys(self._topic_pubs, 0))
        self._stop.clear()
        self._executor = SingleThreadedExecutor(context=self.context)
        self._executor.add_node(self)
        try:
            result.matched = self._wait_for_subscribers()
            self._spin_until(time.monotonic() + self._delay)
            while not self._stop.is_set():
                result.passes += 1
                published = self._play_pass(result)
                if (not self._loop or published == 0
                        or (max_passes is not None and result.passes >= max_passes)):
                    break
            result.interrupted = self._stop.is_set()
        except (KeyboardInterrupt, ExternalShutdownException):
            # Ctrl-C: rclpy's signal handler shuts the context down and, when the signal
            # lands in a wait, raises KeyboardInterrupt there. Either way the playback ends.
            result.interrupted = True
        except Exception:
            # A signal shuts the context down asynchronously: a publish at that moment fails
            # with "context is invalid". That is the shutdown, not a fault.
            if self.context.ok():
                raise
            result.interrupted = True
        finally:
            if self._progress_shown:
                self._show_progress(final=True)
            self._executor.remove_node(self)
            self._executor.shutdown()
            self._executor = None
        return result

    def other_clocks(self) -> list[str]:
        """Return the nodes (fully qualified) that publish ``/clock`` besides this player's
        ``--clock`` publisher, as discovery shows them now (``[]``: none, or no ``--clock``).
        """
        if self._clock_pub is None or self.count_publishers(CLOCK_TOPIC) <= 1:
            return []
        names = [f'{i.node_namespace.rstrip("/")}/{i.node_name}'
                 for i in self.get_publishers_info_by_topic(CLOCK_TOPIC)]
        own = f'{self.get_namespace().rstrip("/")}/{self.get_name()}'
        if own in names:
            names.remove(own)
        return sorted(name if not name.split('/')[-1].startswith('_NODE_NAME_UNKNOWN')
                      else UNNAMED for name in names)

    def _check_clock(self, final: bool) -> None:
        """Refuse to play beside another ``/clock`` publisher.

        :param final: refuse now even if the node of a publisher is not named yet
            (discovery names a node a little after its publishers).
        :raises ClockTaken: when discovery shows one.
        """
        others = self.other_clocks()
        if others and (final or UNNAMED not in others):
            raise ClockTaken('ROS_DOMAIN_ID', (
                f'another node publishes {CLOCK_TOPIC} on domain {self.context.get_domain_id()} '
                f'(nodes: {", ".join(others)}): --clock would make a second clock; give each '
                'run a domain of its own'))

    def _wait_for_subscribers(self) -> bool:
        """Wait until a topic has the subscribers asked for and discovery has settled (see
        :class:`Player`'s ``wait_subscribers``); return whether the subscribers came.

        With ``clock``, the wait lasts DISCOVERY_MIN s at least and looks for another
        ``/clock`` publisher all along.

        :raises ClockTaken: when another node publishes ``/clock``.
        """
        publishers = list(self._topic_pubs.values())
        if self._clock_pub is not None:
            publishers.append(self._clock_pub)
        needed = self._wait_subscribers
        start = time.monotonic()
        deadline = start + self._wait_timeout
        if self._clock_pub is not None:
            deadline = max(deadline, self._created + DISCOVERY_MIN)
        seen, changed = None, start
        while not self._stop.is_set():
            now = time.monotonic()
            if self._clock_pub is not None:
                # Every return below comes at DISCOVERY_MIN or later: checked finally then.
                self._check_clock(final=now >= self._created + DISCOVERY_MIN)
            counts = [pub.get_subscription_count() for pub in publishers]
            graph = (counts, sorted(self.get_node_names_and_namespaces()))
            if graph != seen:
                seen, changed = graph, now
            reached = max(counts) >= needed
            if reached and now >= max(self._created + DISCOVERY_MIN,
                                      changed + DISCOVERY_QUIET):
                return True
            if now >= deadline:
                if reached:
                    return True
                self._say(f'replay: warning: after {self._wait_timeout:g} s, no replayed '
                          f'topic has {needed} subscriber(s); playing anyway')
                return False
            self._spin_once(min(MAX_WAIT, deadline - now))
        return False

    def _bag_now(self, wall: float) -> int:
        return self._pass_start_ns + round((wall - self._wall_zero) * self._rate * _NS)

    def _play_pass(self, result: PlayResult) -> int:
        """Publish the messages from the start offset to the end once; return their number."""
        start_ns = self._bag_start + self._offset_ns
        self._pass_start_ns = start_ns
        self._wall_zero = time.monotonic()
        if self._clock_pub is not None:
            # The pass's first tick is its start, exactly (not the bag time of the moment the
            # first message is read, which a loaded machine delays); the others follow bag time.
            self._publish_clock(self._wall_zero)
            result.clock_ticks += 1
            self._next_clock = self._wall_zero + self._clock_period
        published = 0
        for message in self._reader.messages(self._sources):
            if message.log_time_ns < start_ns:
                continue
            due = self._wall_zero + (message.log_time_ns - start_ns) / _NS / self._rate
            if not self._wait_until(due, result):
                break
            data = message.data if type(message.data) is bytes else bytes(message.data)
            out = ([(message.topic, data)] if self._view is None
                   else self._view.messages(message.topic, data))
            for topic, data in out:
                publisher = self._topic_pubs.get(topic)
                if publisher is None:
                    continue
                publisher.publish(data)
                if self._live is not None:
                    self._live.set_time(message.log_time_ns)
                    self._live.write(publisher.topic_name, data, message.log_time_ns)
                result.published[topic] += 1
                published += 1
            result.max_lateness = max(result.max_lateness, time.monotonic() - due)
        return published

    def _wait_until(self, due: float, result: PlayResult) -> bool:
        """Publish /clock ticks and progress until the wall time ``due``; False if stopped."""
        while True:
            now = time.monotonic()
            if now >= self._next_clock:
                self._publish_clock(now)
                result.clock_ticks += 1
                # After a stall, carry on from now rather than publish a burst of ticks.
                self._next_clock = max(self._next_clock + self._clock_period, now)
            if self._progress is not None and now >= self._next_progress:
                self._show_progress()
                self._next_progress = now + PROGRESS_PERIOD
            if self._stop.is_set():
                return False
            if now >= due:
                return True
            wake = min(due, self._next_clock, now + MAX_WAIT)
            if self._progress is not None:
                wake = min(wake, self._next_progress)
            self._spin_once(wake - now)

    def _spin_until(self, until: float) -> None:
        while not self._stop.is_set():
            remaining = until - time.monotonic()
            if remaining <= 0:
                return
            self._spin_once(min(remaining, MAX_WAIT))

    def _spin_once(self, timeout: float) -> None:
        """Wait, serving the node's services; raise once the context is shut down.

        The executor's wait overshoots now and then by a few ms, so the last
        :data:`SLEEP_MARGIN` before a deadline is slept instead (overshoot ~0.1 ms).
        """
        if timeout > SLEEP_MARGIN:
            self._executor.spin_once(timeout_sec=timeout - SLEEP_MARGIN)
        elif timeout > 0:
            time.sleep(timeout)
        if not self.context.ok():
            raise ExternalShutdownException()

    def _publish_clock(self, wall: float) -> None:
        ns = self._bag_now(wall)
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(ns, _NS)
        self._clock_pub.publish(msg)

    def _show_progress(self, final: bool = False) -> None:
        stream = self._progress
        bag_now = min(self._bag_now(time.monotonic()), self._bag_end)
        line = (f'[RUNNING]  Bag Time {format_ns(bag_now)}  Duration '
                f'{format_ns(bag_now - self._bag_start)}/{format_ns(self.duration_ns)}')
        try:
            tty = stream.isatty()
        except (AttributeError, ValueError):
            tty = False
        if tty:
            stream.write(f'\r{line}' + ('\n' if final else ''))
        else:
            stream.write(f'{line}\n')
        stream.flush()
        self._progress_shown = True
