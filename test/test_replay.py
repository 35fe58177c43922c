"""``replay``: a bag republished on real DDS, received by an in-process subscriber.

Each test has its own ``rclpy.Context`` on a unique domain id; the player plays in a
background thread while the test's thread spins the listener's executor until a condition
holds or a timeout expires. Test bags are written with :class:`BagWriter` at chosen
log times (non-uniform gaps over one second), so every expectation is known exactly.
"""

import io
import os
from pathlib import Path
import select
import signal
import subprocess
import sys
import threading
import time

from geometry_msgs.msg import AccelStamped
from mcap.writer import Writer
from nav_msgs.msg import Odometry
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from flock_swarm.bag import BagReader, BagWriter
from flock_swarm.console import EXIT_INTERRUPTED
from flock_swarm.nodes.player import (
    CLOCK_TOPIC, format_ns, Player, REPLAY_DEPTH, replay_qos, ReplayError, select_topics)
from flock_swarm.nodes.swarm_runner import resolve_scenario, run_in_process, unique_domain

pytestmark = pytest.mark.ros

#: First log time: an epoch-like time, to exercise large nanosecond counts.
T0_NS = 1_700_000_000 * 10**9
#: Topic prefix of this process: concurrent test runs on one host cannot cross-talk, even
#: when their domain ids happen to collide.
NS = f'/replay_test_{os.getpid()}'
A, B, CX = f'{NS}/a', f'{NS}/b', f'{NS}/c/x'
#: Log times (s after T0) of each topic of the test bag: uneven gaps, the bag spans 1 s.
SCHEDULE = {
    A: [0.0, 0.05, 0.3, 0.31, 0.7, 1.0],
    B: [0.1, 0.2, 0.65, 0.9],
    CX: [0.4, 0.8],
}
#: Timing tolerance (s) of a received message against its scheduled relative time. The
#: player alone publishes within 0.5 ms of the due time; here it shares the GIL with the
#: listener's thread (up to ~4 ms late), and DDS loopback delivery and the listener's wake-up
#: add about a millisecond. Measured worst: 6 ms on an idle 2-core machine, 13 ms with two
#: extra CPU-bound processes. 30 ms leaves room for a busy CI machine and is still small
#: against the 0.5-2 s spans, so a wrong rate or a skipped gap fails clearly.
TIMING_TOL = 0.03
#: Subscriber QoS: reliable and deep, as the player offers for topics recorded without QoS.
LISTEN_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=200,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
#: Bound of every wait in these tests (s).
TIMEOUT = 15.0


def payload(topic: str, i: int) -> String:
    return String(data=f'{topic} #{i}')


def write_bag(path: Path, schedule: dict[str, list[float]] = SCHEDULE,
              clock_values: list[float] | None = None, chunk_size: int = 1 << 20) -> Path:
    """Write String messages at ``T0 + t`` for each scheduled ``t``, and optionally /clock."""
    with BagWriter(path, chunk_size=chunk_size) as bag:
        for topic in schedule:
            bag.add_topic(topic, String)
        if clock_values is not None:
            bag.add_topic(CLOCK_TOPIC, Clock)
            for k, value in enumerate(clock_values):
                msg = Clock()
                msg.clock.sec = int(value)
                bag.write(CLOCK_TOPIC, msg, T0_NS + round(k * 0.1 * 1e9))
        events = sorted((t, topic, i) for topic, times in schedule.items()
                        for i, t in enumerate(times))
        for t, topic, i in events:
            bag.write(topic, payload(topic, i), T0_NS + round(t * 1e9))
    return path


def bag_messages(path: Path, topics) -> list[tuple[str, bytes, int]]:
    """The recorded ``(topic, data, log_time_ns)`` of ``topics``, read by BagReader."""
    return [(m.topic, m.data, m.log_time_ns) for m in BagReader(path).messages(topics)]


class Listener(Node):
    """Record ``(topic, data, monotonic receive time)`` of everything on some topics."""

    def __init__(self, topics: list[str] | dict[str, type], clock: bool = False,
                 **kwargs) -> None:
        super().__init__('listener', **kwargs)
        self.received: list[tuple[str, bytes, float]] = []
        self.clock: list[tuple[int, float]] = []
        types = topics if isinstance(topics, dict) else dict.fromkeys(topics, String)
        for topic, cls in types.items():
            # raw=True: the callback gets the serialized bytes, compared with the bag's.
            self.create_subscription(
                cls, topic, lambda data, topic=topic: self.received.append(
                    (topic, data, time.monotonic())), LISTEN_QOS, raw=True)
        if clock:
            self.create_subscription(Clock, CLOCK_TOPIC, self.on_clock, LISTEN_QOS)

    def on_clock(self, msg: Clock) -> None:
        self.clock.append((msg.clock.sec * 10**9 + msg.clock.nanosec, time.monotonic()))


def spin_until(executor, condition, timeout: float = TIMEOUT) -> bool:
    """Spin until ``condition()`` holds; return False if ``timeout`` passed first."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.005)
    return True


def by_topic(messages) -> dict[str, list[bytes]]:
    """The payloads of ``(topic, data, time)`` messages per topic, in their order."""
    out: dict[str, list[bytes]] = {}
    for topic, data, _ in messages:
        out.setdefault(topic, []).append(data)
    return out


def play(context, player: Player, listener: Listener, expected: int, max_passes=None,
         stop_when=None):
    """Play in a background thread until done and ``expected`` messages arrived."""
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(listener)
    box = {}
    thread = threading.Thread(target=lambda: box.update(result=player.play(max_passes)))
    thread.start()
    try:
        if stop_when is not None:
            assert spin_until(executor, lambda: stop_when(listener)), 'stop condition'
            player.stop()
        done = spin_until(executor, lambda: not thread.is_alive()
                          and len(listener.received) >= expected)
        # Anything beyond the expected messages would arrive right behind them.
        spin_until(executor, lambda: False, timeout=0.1)
    finally:
        if thread.is_alive():
            player.stop()
        thread.join(TIMEOUT)
        executor.shutdown()
    assert done, f'received {len(listener.received)} of {expected} messages'
    return box['result']


def assert_timing(received, recorded, rate: float, tol: float = TIMING_TOL) -> float:
    """Check receive times against recorded log times scaled by 1/rate; return the error."""
    t_recv0, t_log0 = received[0][2], recorded[0][2]
    errors = [(r[2] - t_recv0) - (m[2] - t_log0) / 1e9 / rate
              for r, m in zip(received, recorded)]
    worst = max(abs(e) for e in errors)
    assert worst < tol, f'timing error {worst * 1e3:.1f} ms at rate {rate}'
    return worst


@pytest.mark.parametrize('rate', [2.0, 0.5])
def test_replays_selected_topics_in_order_with_scaled_timing(tmp_path, ros_context, rate):
    bag = write_bag(tmp_path / 'bag')
    listener = Listener([A, B, CX], context=ros_context)
    player = Player(bag, rate=rate, topics=[A, B], wait_subscribers=1,
                    context=ros_context)
    try:
        recorded = bag_messages(bag, [A, B])
        result = play(ros_context, player, listener, len(recorded))
        assert result.published == {A: 6, B: 4} and result.passes == 1
        assert result.matched and not result.interrupted
        assert [(t, d) for t, d, _ in listener.received] == [(t, d) for t, d, _ in recorded]
        assert_timing(listener.received, recorded, rate)
        assert result.max_lateness < TIMING_TOL
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_clock_follows_bag_time_and_replaces_the_recorded_clock(tmp_path, ros_context):
    # The recorded /clock says 999 s: if it were replayed, the listener would see it.
    bag = write_bag(tmp_path / 'bag', clock_values=[999.0] * 5)
    notes = []
    rate, clock_rate = 2.0, 50.0
    listener = Listener([A], clock=True, context=ros_context)
    player = Player(bag, rate=rate, clock=True, clock_rate=clock_rate, topics=[A],
                    wait_subscribers=1, say=notes.append, context=ros_context)
    try:
        assert player.topics == [A]
        result = play(ros_context, player, listener, len(SCHEDULE[A]))
        assert notes == ['[replay] --clock: the recorded /clock is not replayed; /clock '
                         'follows bag time at 50 Hz']
        ticks = listener.clock
        assert len(ticks) == result.clock_ticks
        # One tick per 1/50 wall s over 1 s of bag at rate 2, plus the first.
        assert abs(len(ticks) - (1.0 / rate * clock_rate + 1)) <= 3
        stamps = [ns for ns, _ in ticks]
        assert stamps == sorted(stamps)
        assert stamps[0] == T0_NS  # the pass's first tick is its start, exactly
        assert stamps[-1] <= T0_NS + 1.0e9 + TIMING_TOL * rate * 1e9
        # Bag time runs at `rate` bag seconds per wall second.
        for ns, wall in ticks:
            expected = (wall - ticks[0][1]) * rate
            assert abs((ns - stamps[0]) / 1e9 - expected) < TIMING_TOL * rate
    finally:
        player.destroy_node()
        listener.destroy_node()


@pytest.mark.parametrize('wait', [0, 1])
def test_a_subscriber_there_before_the_replay_gets_its_first_message(
        tmp_path, ros_domain, ros_context, wait):
    """Issue 38: with ``--rate 2 --clock`` a subscriber ready before the replay (another
    participant: a process of its own) missed the first seconds of the bag, unless ``-d``
    was given; and ``--wait-for-subscribers 1`` waited for a subscriber on every publisher.
    Without any option the player now waits for discovery to settle; with 1 it waits for one
    subscriber of any topic (the listener subscribes to two of the three topics and to
    /clock), then for discovery to settle. Every message arrives, from the first."""
    import rclpy
    from rclpy.context import Context

    bag = write_bag(tmp_path / 'bag')
    other = Context()
    rclpy.init(context=other, domain_id=ros_domain)
    listener = Listener([A, B], clock=True, context=other)
    player = None
    try:
        # The listener is there (its own participant) before the player is made.
        player = Player(bag, rate=2.0, clock=True, wait_subscribers=wait, wait_timeout=10.0,
                        context=ros_context)
        recorded = bag_messages(bag, [A, B])
        result = play(other, player, listener, len(recorded))
        assert result.matched
        assert by_topic(listener.received) == by_topic(recorded)
        assert listener.clock[0][0] == T0_NS  # the first tick of the bag, too
    finally:
        if player is not None:
            player.destroy_node()
        listener.destroy_node()
        rclpy.try_shutdown(context=other)


def test_recorded_clock_is_replayed_without_clock_and_refused_with_it(tmp_path, ros_context):
    bag = write_bag(tmp_path / 'bag', clock_values=[1.0, 2.0])
    notes = []
    player = Player(bag, clock=True, say=notes.append, context=ros_context)
    try:
        assert CLOCK_TOPIC not in player.topics
        assert len(notes) == 1 and 'recorded /clock is not replayed' in notes[0]
    finally:
        player.destroy_node()
    player = Player(bag, context=ros_context)
    try:
        assert CLOCK_TOPIC in player.topics
    finally:
        player.destroy_node()
    with pytest.raises(ReplayError, match='--topics: /clock cannot be replayed with --clock'):
        Player(bag, clock=True, topics=['/clock', A], context=ros_context)


BAG_TOPICS = ['/clock', '/agent_0/odom', '/agent_1/odom', '/leader/odom', '/swarm/markers']


@pytest.mark.parametrize('kwargs, expected', [
    ({}, BAG_TOPICS),
    ({'topics': ['/leader/odom', '/agent_0/odom']}, ['/agent_0/odom', '/leader/odom']),
    ({'regex': r'^/agent_\d+/odom$'}, ['/agent_0/odom', '/agent_1/odom']),
    ({'regex': 'odom'}, ['/agent_0/odom', '/agent_1/odom', '/leader/odom']),
    ({'exclude': '^/agent_'}, ['/clock', '/leader/odom', '/swarm/markers']),
    ({'regex': 'odom', 'exclude': 'agent_1'}, ['/agent_0/odom', '/leader/odom']),
    ({'topics': ['/clock', '/leader/odom'], 'regex': 'odom'}, ['/leader/odom']),
    ({'clock': True}, BAG_TOPICS[1:]),
])
def test_select_topics(kwargs, expected):
    assert select_topics(BAG_TOPICS, **kwargs) == expected


@pytest.mark.parametrize('kwargs, message', [
    ({'topics': ['/leader/odom', '/nope']}, '--topics: not in the bag: /nope'),
    ({'regex': '('}, "--regex: invalid regular expression '('"),
    ({'exclude': '[a-'}, "--exclude: invalid regular expression '[a-'"),
    ({'regex': 'cmd_accel'}, "--regex: 'cmd_accel' matches no selected topic"),
    ({'exclude': '.'}, "--exclude: '.' leaves no topic"),
    ({'regex': 'clock', 'clock': True}, '--clock: the only selected topic is /clock'),
])
def test_select_topics_refuses(kwargs, message):
    with pytest.raises(ReplayError) as info:
        select_topics(BAG_TOPICS, **kwargs)
    assert str(info.value).startswith(message)


class Terminal(io.StringIO):
    """A progress stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_player_filters_with_regex_and_exclude(tmp_path, ros_context):
    bag = write_bag(tmp_path / 'bag')
    listener = Listener([A, B, CX], context=ros_context)
    terminal = Terminal()
    player = Player(bag, rate=4.0, regex='/[ac]', exclude='x$', wait_subscribers=1,
                    progress=terminal, context=ros_context)
    try:
        assert player.topics == [A]
        recorded = bag_messages(bag, [A])
        play(ros_context, player, listener, len(recorded))
        assert [(t, d) for t, d, _ in listener.received] == [(t, d) for t, d, _ in recorded]
        # On a terminal the progress line is rewritten in place, and ended once.
        text = terminal.getvalue()
        assert text.startswith('\r[RUNNING]  Bag Time 1700000000.')
        assert text.endswith(f'\r[RUNNING]  Bag Time {format_ns(T0_NS + 10**9)}  Duration '
                             '1.000000000/1.000000000\n')
        assert text.count('\n') == 1
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_start_offset_skips_earlier_messages(tmp_path, ros_context):
    bag = write_bag(tmp_path / 'bag')
    offset, rate = 0.5, 2.0
    listener = Listener(list(SCHEDULE), context=ros_context)
    player = Player(bag, rate=rate, start_offset=offset, wait_subscribers=1, context=ros_context)
    try:
        recorded = [m for m in bag_messages(bag, list(SCHEDULE))
                    if m[2] >= T0_NS + offset * 1e9]
        assert len(recorded) == 5
        play(ros_context, player, listener, len(recorded))
        assert [(t, d) for t, d, _ in listener.received] == [(t, d) for t, d, _ in recorded]
        assert_timing(listener.received, recorded, rate)
    finally:
        player.destroy_node()
        listener.destroy_node()
    with pytest.raises(ReplayError, match=r'--start-offset: 1.5 s is past the end of the bag'):
        Player(bag, start_offset=1.5, context=ros_context)


def test_loop_replays_again_until_stopped(tmp_path, ros_context):
    bag = write_bag(tmp_path / 'bag')
    recorded = bag_messages(bag, [A, B])
    listener = Listener([A, B], context=ros_context)
    player = Player(bag, rate=4.0, loop=True, topics=[A, B], wait_subscribers=1,
                    context=ros_context)
    try:
        result = play(ros_context, player, listener, 2 * len(recorded), max_passes=2)
        assert result.passes == 2 and result.total == 2 * len(recorded)
        assert [d for _, d, _ in listener.received] == [d for _, d, _ in recorded] * 2
        # Without a bound, the loop runs until stop(): here in the middle of the third pass.
        listener.received.clear()
        result = play(ros_context, player, listener, 0,
                      stop_when=lambda node: len(node.received) >= 2 * len(recorded) + 3)
        assert result.interrupted and result.passes == 3
        data = [d for _, d, _ in listener.received]
        assert len(data) < 3 * len(recorded)
        assert data == ([d for _, d, _ in recorded] * 3)[:len(data)]
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_replays_a_bag_of_a_ros_run(tmp_path, ros_context, ros_domain):
    """A bag the world node recorded: its recorded QoS, byte-equal payloads."""
    out = tmp_path / 'run'
    run_in_process(resolve_scenario('demo', ['n_agents=3', 'informed.count=1', 'duration=1'],
                                    None, out), out, domain_id=ros_domain, timeout=60)
    topics = ['/agent_1/odom', '/leader/accel']
    recorded = bag_messages(out / 'bag', topics)
    listener = Listener(dict(zip(topics, (Odometry, AccelStamped))), context=ros_context)
    player = Player(out / 'bag', rate=4.0, topics=topics, wait_subscribers=1, context=ros_context)
    try:
        # The world offers reliable, volatile, depth 100 on these topics (docs/ros.md).
        for qos in player.qos_profiles.values():
            assert qos.reliability == ReliabilityPolicy.RELIABLE
            assert qos.durability == DurabilityPolicy.VOLATILE and qos.depth == 100
        play(ros_context, player, listener, len(recorded))
        # Each topic in its recorded order. Across topics DDS promises no order, and the
        # world records a step's odometry and the leader's acceleration at nearly the same
        # time, so the player publishes them back to back on two writers.
        assert by_topic(listener.received) == by_topic(recorded)
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_republish_per_agent_plays_a_batched_bag_as_the_per_agent_run_recorded_it(
        tmp_path, ros_context, ros_domain):
    """``republish='per_agent'``: a batched run's clouds arrive on the per-agent topics as
    the bytes a per-agent run of the same scenario recorded (odometry, commands and Zhou's
    adaptive gains ``h``, whose JointState carries the same stamp and numbers)."""
    runs = {}
    for name, extra in (('batched', ['transport=batched']), ('per_agent', [])):
        out = runs[name] = tmp_path / name
        run_in_process(resolve_scenario('zhou2012_sec51', ['duration=0.1', *extra], None, out),
                       out, domain_id=ros_domain, timeout=60)
    expected = [m for m in BagReader(runs['per_agent'] / 'bag').messages()
                if m.topic.startswith('/agent_')]
    types = {'odom': Odometry, 'cmd_accel': AccelStamped, 'state': JointState}
    topics = {m.topic: types[m.topic.rsplit('/', 1)[1]] for m in expected}
    listener = Listener(topics, context=ros_context)
    player = Player(runs['batched'] / 'bag', rate=4.0, regex='^/agent_', republish='per_agent',
                    wait_subscribers=1, context=ros_context)
    try:
        assert sorted(player.topics) == sorted(topics)
        result = play(ros_context, player, listener, len(expected))
        assert result.total == len(expected)
        received = by_topic(listener.received)
        assert received == by_topic((m.topic, m.data, 0) for m in expected)
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_replay_qos():
    default = replay_qos([])
    assert (default.reliability, default.durability, default.history, default.depth) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, HistoryPolicy.KEEP_LAST,
        REPLAY_DEPTH)
    latched = replay_qos([QoSProfile(depth=3, reliability=ReliabilityPolicy.BEST_EFFORT,
                                     durability=DurabilityPolicy.TRANSIENT_LOCAL)])
    assert (latched.reliability, latched.durability, latched.depth) == (
        ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.TRANSIENT_LOCAL, 3)
    shallow = replay_qos([QoSProfile(depth=5)])
    assert shallow.depth == REPLAY_DEPTH
    mixed = replay_qos([QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT),
                        QoSProfile(depth=5, durability=DurabilityPolicy.TRANSIENT_LOCAL)])
    assert (mixed.reliability, mixed.durability) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)


def write_foreign_mcap(path: Path) -> Path:
    """A bare rosbag2-style .mcap (no metadata.yaml, no QoS) with one type not installed."""
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        known = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
        unknown = writer.register_schema('no_such_pkg/msg/Thing', 'ros2msg', b'int32 x')
        a = writer.register_channel(A, 'cdr', known)
        thing = writer.register_channel(f'{NS}/thing', 'cdr', unknown)
        for i, t in enumerate(SCHEDULE[A]):
            ns = T0_NS + round(t * 1e9)
            writer.add_message(a, ns, serialize_message(payload(A, i)), ns)
            writer.add_message(thing, ns, b'\x00\x01\x00\x00\x07\x00\x00\x00', ns)
        writer.finish()
    return path


def test_unknown_types_are_skipped_with_one_warning(tmp_path, ros_context):
    bag = write_foreign_mcap(tmp_path / 'foreign.mcap')
    notes = []
    listener = Listener([A], context=ros_context)
    player = Player(bag, rate=4.0, say=notes.append, wait_subscribers=1, context=ros_context)
    try:
        assert notes == ['replay: warning: skipping topics whose message types are not '
                         f'installed: {NS}/thing (no_such_pkg/msg/Thing)']
        assert player.topics == [A] and player.duration_ns == 10**9
        assert player.qos_profiles[A].depth == REPLAY_DEPTH
        recorded = bag_messages(bag, [A])
        play(ros_context, player, listener, len(recorded))
        assert [d for _, d, _ in listener.received] == [d for _, d, _ in recorded]
    finally:
        player.destroy_node()
        listener.destroy_node()


def test_truncated_bag_replays_its_recovered_prefix(tmp_path, ros_context):
    many = {A: [i / 100 for i in range(100)]}
    bag = write_bag(tmp_path / 'bag', schedule=many, chunk_size=256)
    whole = bag / 'bag_0.mcap'
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size // 2])
    recovered = bag_messages(cut, [A])
    assert 0 < len(recovered) < 100
    assert [d for _, d, _ in recovered] == [d for _, d, _ in bag_messages(bag, [A])][
        :len(recovered)]
    notes = []
    listener = Listener([A], context=ros_context)
    player = Player(cut, rate=10.0, say=notes.append, wait_subscribers=1, context=ros_context)
    try:
        # "truncated" when the cut falls inside a record, "not closed" on a record boundary.
        assert len(notes) == 1 and notes[0].startswith('replay: warning: cut.mcap ')
        assert 'truncated' in notes[0] or 'not closed' in notes[0]
        result = play(ros_context, player, listener, len(recovered))
        assert result.total == len(recovered)
        assert [d for _, d, _ in listener.received] == [d for _, d, _ in recovered]
    finally:
        player.destroy_node()
        listener.destroy_node()
    # The command line prints the reader's warning once and replays what was recovered.
    proc = run_cli([str(cut), '--rate', '20'])
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if 'warning' in line]
    assert len(warnings) == 1 and warnings[0] == notes[0]
    assert f'done: {len(recovered)} messages on 1 topic in 1 pass' in proc.stderr


def cli_env() -> dict:
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    # A domain of its own, held against every other process of the machine (pytest-xdist's
    # workers included) until this one exits: the player's publishers (its /clock too) must
    # not meet another test's nodes, and a world refuses a domain with another /clock on it.
    env['ROS_DOMAIN_ID'] = str(unique_domain())
    return env


def run_cli(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'flock_swarm.cli.replay', *args],
                          capture_output=True, text=True, timeout=60, env=cli_env())


def test_cli_plays_with_progress(tmp_path):
    bag = write_bag(tmp_path / 'bag')
    proc = run_cli([str(bag), '--rate', '2', '--clock', '--clock-rate', '20'])
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    progress = [line for line in lines if line.startswith('[RUNNING]  Bag Time ')]
    # Half a second of playing, an update every 0.5 s, plus the final one.
    assert 2 <= len(progress) <= 4
    assert progress[-1] == (f'[RUNNING]  Bag Time {format_ns(T0_NS + 10**9)}  Duration '
                            '1.000000000/1.000000000')
    assert lines[-1].startswith('[replay] done: 12 messages on 3 topics, ')
    quiet = run_cli([str(bag), '--rate', '4', '--quiet'])
    assert quiet.returncode == 0 and quiet.stderr == ''


@pytest.mark.parametrize('args, message', [
    (['{tmp}/missing'], 'no such bag: {tmp}/missing'),
    (['{tmp}/notes.txt'], '{tmp}/notes.txt is not an MCAP file'),
    (['{bag}', '--rate', '0'], '--rate: must be a finite number > 0, got 0'),
    (['{bag}', '--rate', '-2'], '--rate: must be a finite number > 0, got -2'),
    (['{bag}', '--regex', '(a'], "--regex: invalid regular expression '(a'"),
    (['{bag}', '--topics', '/nope'], '--topics: not in the bag: /nope'),
    (['{bag}', '--start-offset', '-1'], '--start-offset: must be a finite number >= 0'),
    (['{bag}', '--republish', 'per_agent'], '--republish: per_agent: the bag has no '
     'swarm/states cloud'),
])
def test_cli_bad_input_is_one_line_and_status_2(tmp_path, ros_domain, monkeypatch, capfd,
                                                args, message):
    """``main(argv)`` in this process, its file descriptors captured (a process each took
    0.3-0.8 s); test_a_bag_without_topics_is_named_in_one_line refuses through a process."""
    from flock_swarm.cli.replay import main
    bag = write_bag(tmp_path / 'bag')
    (tmp_path / 'notes.txt').write_text('not a bag\n')
    args = [a.format(tmp=tmp_path, bag=bag) for a in args]
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    capfd.readouterr()
    assert main(args) == 2
    captured = capfd.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith('replay: error: '
                                                   + message.format(tmp=tmp_path))
    assert 'Traceback' not in captured.err and captured.out == ''


def test_clock_beside_a_run_started_by_hand_is_refused_in_one_line(tmp_path, ros_domain):
    """Issue 38: ``replay --clock`` beside a run started by hand (``ros2 run`` of each node,
    not ``swarm``, so no domain lock) played on, and the domain had two /clock publishers
    (a running world only logs the second one). The player now looks on the ROS graph
    before its first tick and refuses with one line, status 2; the run goes on.

    No participant of this process on the domain: with discovery limited to this machine,
    Fast DDS did not show the world to the replay when a participant of the test's own came
    before the world (docs/replay.md)."""
    from test_node_stops import SMALL, reap, start_all
    from flock_swarm.testing import wait_for
    bag = write_bag(tmp_path / 'bag')
    out = tmp_path / 'run'
    scenario = resolve_scenario('demo', SMALL + ['duration=1000'], None, out)
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    procs = start_all(scenario, out, env, tmp_path, agents=2)
    log = tmp_path / 'node3.log'  # the world's
    try:
        # The world steps (a world still waiting for its peers would refuse the replay's
        # clock itself and exit): its first progress line comes after two seconds of it.
        wait_for(lambda: '[world]: t = ' in log.read_text(), 60.0, "the world's progress")
        proc = subprocess.run([sys.executable, '-m', 'flock_swarm.cli.replay', str(bag),
                               '--clock'], capture_output=True, text=True, timeout=60, env=env)
        running = [p.poll() for p in procs]
    finally:
        reap(procs)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == (
        f'replay: error: ROS_DOMAIN_ID: another node publishes /clock on domain {ros_domain} '
        '(nodes: /world): --clock would make a second clock; give each run a domain of its '
        'own\n')
    assert running == [None] * 4


@pytest.mark.parametrize('topic, hint', [
    ('/leader/odm', 'did you mean /leader/odom?'),
    ('leader/odom', 'did you mean /leader/odom?'),
    ('/swarm/marker', 'did you mean /swarm/markers?'),
])
def test_a_mistyped_topic_gets_the_closest_recorded_names(topic, hint):
    with pytest.raises(ReplayError) as info:
        select_topics(BAG_TOPICS, topics=[topic])
    assert str(info.value).startswith(f'--topics: not in the bag: {topic} ({hint} the bag has ')


def test_a_bag_without_topics_is_named_in_one_line(tmp_path):
    with BagWriter(tmp_path / 'empty'):
        pass
    proc = run_cli([str(tmp_path / 'empty')])
    assert proc.returncode == 2
    assert proc.stderr == (f'replay: error: BAG: {tmp_path / "empty"} holds no topics, so '
                           'nothing to replay (a recording stopped before its first message?)\n')


def test_ctrl_c_stops_a_loop_cleanly(tmp_path):
    bag = write_bag(tmp_path / 'bag')
    # The console script (setup.py), as installed by scripts/env.sh.
    script = Path(sys.prefix) / 'bin' / 'replay'
    assert script.is_file(), f'{script} is missing: run the tests with scripts/test'
    proc = subprocess.Popen([str(script), str(bag), '--loop', '--rate', '2'], env=cli_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # Stop once the player runs: its first progress line is out.
        deadline = time.monotonic() + TIMEOUT
        first = ''
        while '[RUNNING]' not in first and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stderr], [], [], 0.1)
            if ready:
                first = proc.stderr.readline()
        assert '[RUNNING]' in first
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=TIMEOUT)
        # Read through the same buffered stream: communicate() would skip what it holds.
        stderr = first + proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == EXIT_INTERRUPTED, stderr
    assert 'Traceback' not in stderr
    assert stderr.splitlines()[-1].startswith('[replay] stopped: ')
