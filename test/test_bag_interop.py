"""Bags from another tool, and split bags, through analyze, replay and independent readers.

A real lockstep run records a bag split by ``bag_max_duration`` (the world's parameter);
``mcap`` reads each of its files, ``rosbags`` reads the directory, and ``analyze`` and
``replay`` read it whole. The same run's messages are then written again by ``rosbags``'
rosbag2 writer (MCAP storage, metadata version 9, its own CDR serialiser), as a bag from
another tool: ``analyze`` and ``replay`` read it, and a copy without a required topic is
refused in one line.
"""

import json
from pathlib import Path
import subprocess
import sys
import threading
import time

from geometry_msgs.msg import AccelStamped
from mcap.reader import make_reader
from nav_msgs.msg import Odometry
import numpy as np
from numpy.testing import assert_allclose
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2 import StoragePlugin, Writer as RosbagsWriter
from rosbags.typesys import get_typestore, Stores
import yaml

from flock_swarm.analysis import load_run
from flock_swarm.cli.analyze import main as analyze_main
from flock_swarm.bag import BagReader
from flock_swarm.core.metrics import STEP_METRICS
from flock_swarm.nodes.player import Player
from flock_swarm.nodes.swarm_runner import resolve_scenario, run_in_process, unique_domain

pytestmark = pytest.mark.ros

#: The run: 4 agents for 2 s of the demo (dt = 0.02 s: 101 steps), every step recorded.
OVERRIDES = ['n_agents=4', 'informed.count=2', 'duration=2', 'record_every=1']
#: The world's split limit [s of simulation time]: 2 s of run give five files.
MAX_DURATION = 0.45
#: The demo scenario's interaction radius r [m] (config/demo.yaml), for bags without it.
DEMO_RADIUS = '4'
#: Keys of the world's summary that describe the process, not the run.
PROCESS_KEYS = {'wall_time_s', 'bag', 'resent_steps', 'rejected_messages', 'leader_events',
                'duplicate_agent_ids', 'bag_error', 'command_latency_ms'}
#: Bound of a recording and of every wait (s).
RUN_TIMEOUT = 120.0
TIMEOUT = 15.0
#: What a ``ros2 bag record`` of the world's topics would have captured as the offered QoS.
RECORDED_QOS = Qos(QosHistory.KEEP_LAST, 100, QosReliability.RELIABLE, QosDurability.VOLATILE,
                   QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)
#: Subscriber QoS of the replay listener: reliable and deep enough for a whole topic.
LISTEN_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=500,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)


@pytest.fixture(scope='module')
def split_run(tmp_path_factory):
    """A lockstep run whose world splits the bag every MAX_DURATION seconds."""
    out = tmp_path_factory.mktemp('split') / 'run'
    # Module-scoped, so not the function-scoped ros_domain fixture: the same helper.
    domain = unique_domain()
    summary = run_in_process(resolve_scenario('demo', OVERRIDES, None, out), out,
                             domain_id=domain, timeout=RUN_TIMEOUT,
                             world_params={'bag_max_duration': MAX_DURATION})
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    # The world's time series was spooled to disk and the spool removed once written.
    assert not list(out.glob('.timeseries-*'))
    return out


@pytest.fixture(scope='module')
def foreign(split_run, tmp_path_factory):
    """The run's messages written by rosbags (deserialised and serialised by rosbags)."""
    return write_with_rosbags(split_run / 'bag', tmp_path_factory.mktemp('rosbags') / 'bag')


def write_with_rosbags(source: Path, target: Path, drop: tuple[str, ...] = ()) -> Path:
    """Write the messages of ``source`` (read by rosbags) as a rosbags MCAP bag."""
    store = get_typestore(Stores.ROS2_JAZZY)
    with RosbagsReader(source) as reader, \
            RosbagsWriter(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            conn.topic: writer.add_connection(conn.topic, conn.msgtype, typestore=store,
                                              offered_qos_profiles=[RECORDED_QOS])
            for conn in reader.connections if conn.topic not in drop}
        wanted = [conn for conn in reader.connections if conn.topic not in drop]
        for conn, t_ns, data in reader.messages(connections=wanted):
            msg = store.deserialize_cdr(data, conn.msgtype)
            writer.write(connections[conn.topic], t_ns,
                         bytes(store.serialize_cdr(msg, conn.msgtype)))
    return target


def world_outputs(run: Path) -> tuple[dict, dict]:
    with np.load(run / 'timeseries.npz') as data:
        series = dict(data)
    return json.loads((run / 'summary.json').read_text()), series


def run_analyze(capfd, *args: str, real: bool = False) -> subprocess.CompletedProcess:
    """Run ``analyze`` on ``args``: its ``main(argv)`` in this process, its file descriptors
    captured (a process took about a second of imports each time), or with ``real`` as a
    process (test_analyze_names_a_missing_required_topic keeps one)."""
    if real:
        return subprocess.run([sys.executable, '-m', 'flock_swarm.cli.analyze', *args],
                              capture_output=True, text=True, timeout=RUN_TIMEOUT, check=False)
    from flock_swarm.cli.analyze import main
    capfd.readouterr()
    try:
        status = main(list(args))
    except SystemExit as end:
        status = end.code
    out = capfd.readouterr()
    return subprocess.CompletedProcess(['analyze', *args], status, out.out, out.err)


# -- split bags ----------------------------------------------------------------------------


def test_split_bag_files_and_metadata(split_run):
    """bag_0.mcap, bag_1.mcap, ... each a complete MCAP file, all listed in metadata.yaml."""
    bag = split_run / 'bag'
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    names = [f'bag_{k}.mcap' for k in range(len(info['relative_file_paths']))]
    assert len(names) >= 4
    assert info['relative_file_paths'] == names
    assert sorted(path.name for path in bag.glob('*.mcap')) == sorted(names)
    assert [entry['path'] for entry in info['files']] == names
    previous_start = None
    topics = None
    total = 0
    for name, entry in zip(names, info['files']):
        with (bag / name).open('rb') as stream:
            reader = make_reader(stream)
            header, summary = reader.get_header(), reader.get_summary()
            times = [message.log_time for _, _, message in reader.iter_messages()]
        # Every file stands alone: the ROS 2 profile, every schema and channel.
        assert header.profile == 'ros2'
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        assert {c.message_encoding for c in summary.channels.values()} == {'cdr'}
        file_topics = {c.topic for c in summary.channels.values()}
        assert topics is None or file_topics == topics
        topics = file_topics
        assert entry['message_count'] == len(times) == summary.statistics.message_count
        start = entry['starting_time']['nanoseconds_since_epoch']
        assert start == min(times)
        assert entry['duration']['nanoseconds'] == max(times) - min(times)
        # rosbag2's rule: a file spans at most the limit; the next starts past it.
        assert max(times) - start <= MAX_DURATION * 1e9
        if previous_start is not None:
            assert start - previous_start > MAX_DURATION * 1e9
        previous_start = start
        total += len(times)
    assert total == info['message_count']


def test_split_bag_is_one_bag_for_rosbags_and_our_reader(split_run):
    """rosbags and BagReader read the whole directory: the same messages, in time order."""
    bag = split_run / 'bag'
    ours = [(m.topic, m.log_time_ns, m.data) for m in BagReader(bag).messages()]
    assert [t for _, t, _ in ours] == sorted(t for _, t, _ in ours)
    with RosbagsReader(bag) as reader:
        theirs = [(conn.topic, t_ns, bytes(data)) for conn, t_ns, data in reader.messages()]
        assert reader.message_count == len(ours)
    assert sorted(theirs) == sorted(ours)
    per_file = []
    for path in sorted(bag.glob('*.mcap')):
        with path.open('rb') as stream:
            per_file += [(channel.topic, message.log_time, message.data) for _, channel, message
                         in make_reader(stream).iter_messages()]
    assert sorted(per_file) == sorted(ours)
    # The run's 101 steps: every agent's odometry of every step is in the split bag.
    counts = BagReader(bag).message_counts()
    assert all(counts[f'/agent_{i}/odom'] == 101 for i in range(4))


def test_analyze_reads_the_split_bag_whole(split_run, tmp_path):
    """The analysis of the split bag equals the world's own outputs, and --verify passes."""
    out = tmp_path / 'analysis'
    status = analyze_main([str(split_run / 'bag'), '--out', str(out), '--verify', '--no-anim',
                           '--quiet'])
    assert status == 0
    world, series = world_outputs(split_run)
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['verify_passed'] is True and summary['complete_steps'] == 101
    for key in sorted(set(world) - PROCESS_KEYS):
        if isinstance(world[key], float):
            assert summary[key] == pytest.approx(world[key], rel=0, abs=1e-9), key
        else:
            assert summary[key] == world[key], key
    with np.load(out / 'timeseries.npz') as ours:
        for name in series:
            assert_allclose(ours[name], series[name], rtol=0, atol=0, err_msg=name)


# -- replay --------------------------------------------------------------------------------


class Listener(Node):
    """Keep the serialised bytes received on some topics."""

    def __init__(self, types: dict[str, type], **kwargs) -> None:
        super().__init__('interop_listener', **kwargs)
        self.received: dict[str, list[bytes]] = {topic: [] for topic in types}
        for topic, cls in types.items():
            self.create_subscription(cls, topic, self.received[topic].append, LISTEN_QOS,
                                     raw=True)

    @property
    def count(self) -> int:
        return sum(len(items) for items in self.received.values())


def replay_bag(ros_context, bag: Path, types: dict[str, type]) -> dict[str, list[bytes]]:
    """Replay ``types``' topics of ``bag`` at 10x; return what a subscriber received."""
    listener = Listener(types, context=ros_context)
    player = Player(bag, rate=10.0, topics=list(types), wait_subscribers=1,
                    wait_timeout=TIMEOUT, progress=None, context=ros_context)
    expected = sum(BagReader(bag).message_counts()[topic] for topic in types)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(listener)
    thread = threading.Thread(target=player.play)
    thread.start()
    try:
        deadline = time.monotonic() + TIMEOUT
        while (thread.is_alive() or listener.count < expected) \
                and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.01)
        assert listener.count == expected, f'received {listener.count} of {expected}'
        qos = player.qos_profiles
    finally:
        player.stop()
        thread.join(TIMEOUT)
        executor.shutdown()
        player.destroy_node()
        listener.destroy_node()
    for profile in qos.values():
        assert profile.reliability == ReliabilityPolicy.RELIABLE
        assert profile.durability == DurabilityPolicy.VOLATILE
    return listener.received


def rosbags_payloads(bag: Path, topics) -> dict[str, list[bytes]]:
    """The bytes of each topic as rosbags reads them, in bag order."""
    out: dict[str, list[bytes]] = {topic: [] for topic in topics}
    with RosbagsReader(bag) as reader:
        wanted = [conn for conn in reader.connections if conn.topic in out]
        for conn, _, data in reader.messages(connections=wanted):
            out[conn.topic].append(bytes(data))
    return out


REPLAYED = {'/agent_1/odom': Odometry, '/agent_2/cmd_accel': AccelStamped,
            '/leader/odom': Odometry}


def test_replay_plays_a_split_bag_across_its_files(split_run, ros_context):
    received = replay_bag(ros_context, split_run / 'bag', REPLAYED)
    assert received == rosbags_payloads(split_run / 'bag', REPLAYED)


def test_replay_plays_a_bag_written_by_rosbags(foreign, ros_context):
    """The rosbags bag's bytes, with its recorded QoS (reliable, volatile)."""
    received = replay_bag(ros_context, foreign, REPLAYED)
    assert received == rosbags_payloads(foreign, REPLAYED)


# -- bags written by rosbags ---------------------------------------------------------------


def test_rosbags_bag_is_an_mcap_rosbag2_bag_of_another_writer(foreign, split_run):
    """The foreign bag is really rosbags': its library, its file name, its metadata."""
    reader = BagReader(foreign)
    assert reader.library.startswith('rosbags') and reader.warning is None
    assert [path.name for path in reader.files] == ['bag.mcap']
    assert reader.bag_metadata['version'] == 9
    assert reader.metadata('flock_swarm') is None
    assert reader.message_counts() == BagReader(split_run / 'bag').message_counts()


def test_analyze_reads_a_bag_written_by_rosbags(foreign, split_run, tmp_path, capfd):
    """Without our metadata, --radius and the tolerances give what the world's scenario did."""
    world, series = world_outputs(split_run)
    out = tmp_path / 'analysis'
    result = run_analyze(capfd, str(foreign), '--out', str(out), '--radius', DEMO_RADIUS,
                         '--eta-tolerance', str(world['eta_tolerance']),
                         '--collision-distance', str(world['collision_distance']),
                         '--no-anim', '--quiet')
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr
    summary = json.loads((out / 'summary.json').read_text())
    for key in ('n_agents', 'steps', 'eta', 'velocity_mismatch_max', 'com_position_error',
                'com_velocity_error', 'min_pair_distance', 'collisions', 'components_final',
                'missed_commands'):
        assert summary[key] == pytest.approx(world[key], rel=0, abs=1e-9), key
    with np.load(out / 'timeseries.npz') as ours:
        assert_allclose(ours['t'], series['t'], rtol=0, atol=1e-9)
        for name in ('q', 'p', 'u', 'leader_q', 'leader_p', 'leader_a',
                     *(f'metric_{m}' for m in STEP_METRICS)):
            assert_allclose(ours[name], series[name], rtol=0, atol=0, err_msg=name)


@pytest.mark.parametrize('drop, missing', [
    (('/agent_1/odom',), '/agent_1/odom'),
    (tuple(f'/agent_{i}/odom' for i in range(4)), '/agent_<i>/odom'),
])
def test_analyze_names_a_missing_required_topic(split_run, tmp_path, capfd, drop, missing):
    """One line naming the missing topic and what analyze needs; exit status 2."""
    bag = write_with_rosbags(split_run / 'bag', tmp_path / 'bag', drop=drop)
    result = run_analyze(capfd, str(bag), '--out', str(tmp_path / 'out'), '--radius',
                         DEMO_RADIUS, '--quiet', real=drop == ('/agent_1/odom',))
    assert result.returncode == 2
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith('analyze: error: '), result.stderr
    assert missing in lines[0] and 'analyze needs /agent_<i>/odom' in lines[0]
    assert not (tmp_path / 'out').exists()


def test_analyze_notes_missing_optional_topics(split_run, tmp_path, capfd):
    """Without the leader's acceleration the run is analysed, and the note says so."""
    bag = write_with_rosbags(split_run / 'bag', tmp_path / 'bag', drop=('/leader/accel',))
    result = run_analyze(capfd, str(bag), '--out', str(tmp_path / 'out'), '--radius',
                         DEMO_RADIUS, '--no-anim', '--quiet')
    assert result.returncode == 0, result.stderr
    assert 'optional topic(s) not in the bag: /leader/accel' in result.stderr


# -- rosbags-convert -----------------------------------------------------------------------


def rosbags_convert(source: Path, target: Path, storage: str, *exclude: str) -> Path:
    """Convert a bag with the real ``rosbags-convert`` (the venv's console script)."""
    exe = Path(sys.executable).parent / 'rosbags-convert'
    args = [str(exe), '--src', str(source), '--dst', str(target), '--dst-storage', storage]
    if exclude:
        args += ['--exclude-topic', *exclude]
    result = subprocess.run(args, capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert result.returncode == 0, result.stdout + result.stderr
    return target


def test_the_scenario_survives_a_rosbags_convert_round_trip(split_run, tmp_path, capfd):
    """MCAP -> sqlite3 -> MCAP drops the MCAP metadata records and metadata.yaml's custom
    data; the scenario, seed and informed set stay on /swarm/scenario, and analyze reads them
    there: its summary is the world's."""
    sqlite = rosbags_convert(split_run / 'bag', tmp_path / 'sqlite', 'sqlite3')
    back = rosbags_convert(sqlite, tmp_path / 'mcap', 'mcap')
    reader = BagReader(back)
    assert reader.metadata('flock_swarm') is None
    assert reader.topics()['/swarm/scenario'] == 'std_msgs/msg/String'
    world, _ = world_outputs(split_run)
    run = load_run(back)
    assert run.scenario is not None and run.scenario.name == world['scenario']
    assert run.informed_known and np.flatnonzero(run.informed).tolist() == world['informed']
    assert any('from /swarm/scenario' in note for note in run.notes)
    result = run_analyze(capfd, str(back), '--out', str(tmp_path / 'out'), '--quiet',
                         '--no-anim')
    assert result.returncode == 0, result.stderr
    ours = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    for key in ('scenario', 'seed', 'informed', 'protocol', 'n_agents', 'eta',
                'velocity_mismatch_max', 'steps'):
        assert ours[key] == world[key], key


def test_a_converted_bag_without_the_scenario_topic_says_informed_unknown(
        split_run, tmp_path, capfd):
    sqlite = rosbags_convert(split_run / 'bag', tmp_path / 'sqlite', 'sqlite3',
                             '/swarm/scenario')
    back = rosbags_convert(sqlite, tmp_path / 'mcap', 'mcap')
    result = run_analyze(capfd, str(back), '--out', str(tmp_path / 'x'), '--quiet', '--no-anim')
    assert result.returncode == 2 and 'give --radius' in result.stderr
    result = run_analyze(capfd, str(back), '--out', str(tmp_path / 'out'), '--radius',
                         DEMO_RADIUS, '--quiet', '--no-anim')
    assert result.returncode == 0, result.stderr
    ours = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert ours['scenario'] is None and ours['informed'] == 'unknown'


@pytest.mark.parametrize('field, value, note', [
    ('message_count', 7, 'metadata.yaml lists 7 messages but the files hold {found}; the files '
     'were read'),
    ('version', 99, "metadata.yaml is version 99, newer than the 9 this reader knows; its "
     "fields were read as version 9's"),
], ids=['message_count', 'version'])
def test_metadata_that_disagrees_with_the_files_is_flagged(split_run, tmp_path, field, value,
                                                           note):
    """A sound bag whose metadata.yaml lists a wrong message_count, or a version this reader
    does not know, was read without a word: the reader's warning says so (analyze prints
    it), the files are read as they are."""
    import shutil
    bag = shutil.copytree(split_run / 'bag', tmp_path / 'bag')
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())
    meta['rosbag2_bagfile_information'][field] = value
    (bag / 'metadata.yaml').write_text(yaml.safe_dump(meta))
    sound, edited = BagReader(split_run / 'bag'), BagReader(bag)
    found = sum(sound.message_counts().values())
    assert sound.warning is None
    assert edited.warning == note.format(found=found) and not edited.recovered
    assert edited.message_counts() == sound.message_counts()
