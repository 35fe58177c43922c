"""Bags written by BagWriter, read back by independent readers and by BagReader.

One bag holds every message type the swarm records, with known values and many small chunks.
It is checked with the raw ``mcap`` reader (profile, schema and channel encodings, counts),
``mcap_ros2``'s CDR decoder driven by our schema text, ``rosbags`` (which reads
``metadata.yaml`` and parses our definitions into its own type store), and BagReader, whole and
cut short.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys
import textwrap

from ament_index_python.packages import get_package_share_directory
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import AccelStamped, Point
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk, StreamReader
from mcap.writer import Writer
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
import pytest
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rosgraph_msgs.msg import Clock
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray
import yaml

from flock_swarm.bag import (
    BagError, BagReader, BagWriter, encoded_definition, message_definition, parse_qos_profiles,
    type_hash, type_name_of)
from flock_swarm.nodes.wire import AccelEncoder, OdometryEncoder

#: Simulation steps recorded in the test bag.
STEPS = 60
#: Agents in the test bag (odometry for each, commands from agent 0 only).
AGENTS = 2
#: Step length (ns): 20 Hz.
DT_NS = 50_000_000
#: First stamp: a wall-clock-like epoch time, to exercise large nanosecond counts.
T0_NS = 1_700_000_000 * 10**9
#: Markers every MARKER_EVERY steps, metrics every METRICS_EVERY steps.
MARKER_EVERY = 5
METRICS_EVERY = 10
#: Small chunks, so that the bag has many of them.
CHUNK_SIZE = 2048
#: Provenance record written when the bag opens.
PROVENANCE = {'scenario': 'olfati_saber_2006_alg2', 'seed': '7', 'n_agents': str(AGENTS)}

#: QoS of each topic: reliable state, best-effort visualisation, latched metrics.
STATE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
MARKER_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
METRICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         deadline=Duration(seconds=2, nanoseconds=500))


def stamp(t_ns: int) -> Time:
    """Return the builtin_interfaces/Time of a nanosecond count."""
    return Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def odometry(t_ns: int, frame: str, x: float, y: float) -> Odometry:
    """Return an odometry message with distinct, exactly known values."""
    msg = Odometry()
    msg.header.stamp = stamp(t_ns)
    msg.header.frame_id = 'world'
    msg.child_frame_id = frame
    msg.pose.pose.position.x = x
    msg.pose.pose.position.y = y
    msg.pose.covariance[0] = x / 8.0
    msg.pose.covariance[35] = -y
    msg.twist.twist.linear.x = 0.5 * x
    msg.twist.twist.linear.y = -0.25 * y
    return msg


def markers(t_ns: int, k: int) -> MarkerArray:
    """Return a marker array: agents as a sphere list, one velocity arrow, neighbour edges."""
    header = Header(stamp=stamp(t_ns), frame_id='world')
    # Colours exactly representable in float32, so round trips compare equal.
    agents = Marker(header=header, ns='agents', id=0, type=Marker.SPHERE_LIST,
                    action=Marker.ADD, color=ColorRGBA(r=0.25, g=0.5, b=1.0, a=1.0),
                    points=[Point(x=float(i), y=0.1 * k, z=0.0) for i in range(AGENTS)],
                    text=f'step {k}')
    agents.scale.x = agents.scale.y = agents.scale.z = 0.2
    arrow = Marker(header=header, ns='velocities', id=1, type=Marker.ARROW,
                   points=[Point(x=0.0, y=0.0, z=0.0), Point(x=1.0, y=0.5 * k, z=0.0)],
                   color=ColorRGBA(r=1.0, g=0.0, b=0.0, a=0.75))
    edges = Marker(header=header, ns='edges', id=2, type=Marker.LINE_LIST,
                   points=[Point(x=0.0, y=0.0, z=0.0), Point(x=1.0, y=0.1 * k, z=0.0)],
                   colors=[ColorRGBA(r=0.5, g=0.5, b=0.5, a=1.0)] * 2)
    return MarkerArray(markers=[agents, arrow, edges])


def metrics(t_ns: int, k: int) -> DiagnosticArray:
    """Return a diagnostics array with two flocking metrics."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp(t_ns)
    msg.status = [DiagnosticStatus(
        level=DiagnosticStatus.WARN if k % 20 == 0 else DiagnosticStatus.OK,
        name='flock_swarm: metrics', message=f'step {k}', hardware_id='sim',
        values=[KeyValue(key='eta', value=f'{k / STEPS:.3f}'),
                KeyValue(key='components', value='1')])]
    return msg


def expected_messages() -> list[tuple[str, int, object]]:
    """Return every message of the test bag, ``(topic, t_ns, message)`` in write order."""
    written = []
    for k in range(STEPS):
        t_ns = T0_NS + k * DT_NS
        written.append(('/clock', t_ns, Clock(clock=stamp(t_ns))))
        written.append(('/leader/odom', t_ns, odometry(t_ns, 'leader', 0.5 * k, 1.0)))
        accel = AccelStamped()
        accel.header.stamp = stamp(t_ns)
        accel.header.frame_id = 'world'
        accel.accel.linear.x = 0.01 * k
        written.append(('/leader/accel', t_ns, accel))
        for i in range(AGENTS):
            written.append((f'/agent_{i}/odom', t_ns,
                            odometry(t_ns, f'agent_{i}', 0.5 * k - i, 2.0 * i)))
        command = AccelStamped()
        command.header.stamp = stamp(t_ns)
        command.accel.linear.x = -0.125 * k
        command.accel.linear.y = 0.0625
        written.append(('/agent_0/cmd_accel', t_ns, command))
        if k % MARKER_EVERY == 0:
            written.append(('/swarm/markers', t_ns, markers(t_ns, k)))
        if k % METRICS_EVERY == 0:
            written.append(('/swarm/metrics', t_ns, metrics(t_ns, k)))
    return written


#: Topic, message class and offered QoS, in the order they are added.
TOPICS = [
    ('/clock', Clock, STATE_QOS),
    ('/leader/odom', Odometry, STATE_QOS),
    ('/leader/accel', AccelStamped, STATE_QOS),
    *[(f'/agent_{i}/odom', Odometry, STATE_QOS) for i in range(AGENTS)],
    ('/agent_0/cmd_accel', 'geometry_msgs/msg/AccelStamped', STATE_QOS),
    ('/swarm/markers', MarkerArray, MARKER_QOS),
    ('/swarm/metrics', DiagnosticArray, METRICS_QOS),
]


def by_topic(items: list[tuple[str, object]]) -> dict[str, list[object]]:
    """Group ``(topic, value)`` pairs by topic, keeping their order."""
    grouped: dict[str, list[object]] = {}
    for topic, value in items:
        grouped.setdefault(topic, []).append(value)
    return grouped


def element_type(ros_type: str) -> str:
    """Return the element type of an rclpy array or sequence field type."""
    if ros_type.startswith('sequence<'):
        return ros_type[len('sequence<'):-1].split(',')[0]
    return ros_type.split('[')[0]


def plain(value: object) -> object:
    """Normalise a scalar from any decoder (a ``byte`` may come back as bytes or int)."""
    if isinstance(value, (bytes, bytearray)) and len(value) == 1:
        return value[0]
    return value


def assert_matches(actual: object, expected: object, path: str = 'msg') -> None:
    """Check a message decoded by another library field by field against the rclpy original."""
    for name, ros_type in expected.get_fields_and_field_types().items():
        got, want = getattr(actual, name), getattr(expected, name)
        where = f'{path}.{name}'
        if hasattr(want, 'get_fields_and_field_types'):
            assert_matches(got, want, where)
        elif ros_type.startswith('sequence<') or '[' in ros_type:
            assert len(got) == len(want), where
            for i, (got_item, want_item) in enumerate(zip(got, want)):
                if hasattr(want_item, 'get_fields_and_field_types'):
                    assert_matches(got_item, want_item, f'{where}[{i}]')
                else:
                    assert plain(got_item) == plain(want_item), f'{where}[{i}]'
        else:
            assert plain(got) == plain(want), where


def write_bag(path: Path, written: list[tuple[str, int, object]]) -> None:
    """Write the test bag."""
    with BagWriter(path, chunk_size=CHUNK_SIZE,
                   custom_metadata={'flock_swarm.scenario': PROVENANCE}) as bag:
        for topic, msg_type, qos in TOPICS:
            bag.add_topic(topic, msg_type, qos)
        for topic, t_ns, msg in written:
            bag.write(topic, msg, t_ns)
        bag.add_metadata('flock_swarm.result', {'collisions': '0'})
        assert sum(bag.message_counts.values()) == len(written)


@pytest.fixture(scope='module')
def written() -> list[tuple[str, int, object]]:
    """Every message of the test bag, in write order."""
    return expected_messages()


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory, written) -> Path:
    """The test bag directory, written once for the module."""
    path = tmp_path_factory.mktemp('bags') / 'swarm_run'
    write_bag(path, written)
    return path


def mcap_file(bag: Path) -> Path:
    """Return the MCAP file of a bag directory."""
    return bag / f'{bag.name}_0.mcap'


def test_bag_layout(bag):
    """The directory holds exactly metadata.yaml and <name>_0.mcap, as rosbag2 writes it."""
    assert sorted(p.name for p in bag.iterdir()) == ['metadata.yaml', 'swarm_run_0.mcap']


def test_raw_mcap_structure(bag, written):
    """Profile ros2, ros2msg schemas holding our definitions, cdr channels, counts, chunks."""
    with mcap_file(bag).open('rb') as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        raw = [(channel.topic, message) for _, channel, message in reader.iter_messages()]
    assert header.profile == 'ros2'
    assert header.library.startswith('flock_swarm ')
    assert summary.statistics.chunk_count >= 10
    schemas = {schema.name: schema for schema in summary.schemas.values()}
    assert len(summary.schemas) == len(schemas), 'one schema per type'
    assert set(schemas) == {type_name_of(msg_type) for _, msg_type, _ in TOPICS}
    for name, schema in schemas.items():
        assert schema.encoding == 'ros2msg'
        assert schema.data.decode() == message_definition(name)
    channels = {channel.topic: channel for channel in summary.channels.values()}
    assert list(channels) == [topic for topic, _, _ in TOPICS]
    for topic, msg_type, qos in TOPICS:
        channel = channels[topic]
        assert channel.message_encoding == 'cdr'
        assert summary.schemas[channel.schema_id].name == type_name_of(msg_type)
        assert set(channel.metadata) == {'offered_qos_profiles', 'topic_type_hash'}
        assert channel.metadata['topic_type_hash'] == type_hash(type_name_of(msg_type))
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
        assert parse_qos_profiles(channel.metadata['offered_qos_profiles']) == [qos]
    counts = {topic: len(items) for topic, items in by_topic(
        [(topic, msg) for topic, _, msg in written]).items()}
    assert {channels_topic: summary.statistics.channel_message_counts[channel.id]
            for channels_topic, channel in channels.items()} == counts
    assert {topic: len(items) for topic, items in by_topic(raw).items()} == counts
    assert all(message.log_time == message.publish_time for _, message in raw)
    assert [message.log_time for _, message in raw] == sorted(t for _, t, _ in written)


def test_mcap_ros2_decodes_with_our_schemas(bag, written):
    """mcap_ros2 builds its CDR decoders from our schema text and gets back every value."""
    with mcap_file(bag).open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = by_topic([(channel.topic, value) for _, channel, _, value
                            in reader.iter_decoded_messages(log_time_order=False)])
    expected = by_topic([(topic, msg) for topic, _, msg in written])
    assert decoded.keys() == expected.keys()
    for topic, messages in expected.items():
        assert len(decoded[topic]) == len(messages)
        for got, want in zip(decoded[topic], messages):
            assert_matches(got, want, topic)


def test_rosbags_reads_the_bag_directory(bag, written):
    """rosbags reads metadata.yaml and, from our definitions alone, decodes every message."""
    store = get_typestore(Stores.EMPTY)
    expected = by_topic([(topic, (t_ns, msg)) for topic, t_ns, msg in written])
    with RosbagsReader(bag) as reader:
        assert reader.message_count == len(written)
        assert reader.start_time == T0_NS
        assert reader.ros_distro == 'jazzy'
        for connection in reader.connections:
            assert connection.msgcount == len(expected[connection.topic])
            assert connection.ext.serialization_format == 'cdr'
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        for connection in reader.connections:
            # The RIHS01 hash of the types parsed from our text is the installed type's hash.
            assert store.hash_rihs01(connection.msgtype) == connection.digest
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert qos['/swarm/metrics'][0].depth == 1
        assert qos['/swarm/metrics'][0].deadline.sec == 2
        assert qos['/swarm/metrics'][0].deadline.nsec == 500
        decoded = by_topic([(c.topic, (t_ns, store.deserialize_cdr(raw, c.msgtype)))
                            for c, t_ns, raw in reader.messages()])
    for topic, messages in expected.items():
        assert [t for t, _ in decoded[topic]] == [t for t, _ in messages]
        for (_, got), (_, want) in zip(decoded[topic], messages):
            assert_matches(got, want, topic)


def test_rosbags_builtin_jazzy_types_agree(bag, written):
    """rosbags' own Jazzy type store decodes the odometry the same way."""
    store = get_typestore(Stores.ROS2_JAZZY)
    with RosbagsReader(bag) as reader:
        connections = [c for c in reader.connections if c.topic == '/leader/odom']
        decoded = [store.deserialize_cdr(raw, c.msgtype)
                   for c, _, raw in reader.messages(connections=connections)]
    expected = [msg for topic, _, msg in written if topic == '/leader/odom']
    assert len(decoded) == len(expected)
    for got, want in zip(decoded, expected):
        assert_matches(got, want)


def test_bag_reader_round_trip(bag, written):
    """BagReader returns every message in write order, equal to what was written."""
    reader = BagReader(bag)
    assert not reader.recovered
    assert reader.warning is None
    assert reader.topics() == {topic: type_name_of(t) for topic, t, _ in TOPICS}
    pairs = list(reader.decoded())
    assert [(m.topic, m.log_time_ns) for m, _ in pairs] == [(t, s) for t, s, _ in written]
    assert [msg for _, msg in pairs] == [msg for _, _, msg in written]
    counts = reader.message_counts()
    assert counts == {topic: len(v) for topic, v in
                      by_topic([(t, m) for t, _, m in written]).items()}
    qos = {topic: q for topic, _, q in TOPICS}
    for message, _ in pairs[:20]:
        assert message.publish_time_ns == message.log_time_ns
        assert parse_qos_profiles(message.offered_qos_profiles) == [qos[message.topic]]


def test_bag_reader_on_mcap_file_and_topic_filter(bag, written):
    """Opening the .mcap directly works, and a topic filter keeps only those topics."""
    reader = BagReader(mcap_file(bag))
    assert reader.bag_metadata is None
    wanted = {'/swarm/markers', '/agent_1/odom'}
    got = [(m.topic, msg) for m, msg in reader.decoded(wanted)]
    assert got == [(topic, msg) for topic, _, msg in written if topic in wanted]
    assert [m.topic for m in reader.messages('/clock')] == ['/clock'] * STEPS


def test_metadata_yaml(bag, written):
    """metadata.yaml is rosbag2_bagfile_information version 9 with the right counts and times."""
    text = (bag / 'metadata.yaml').read_text()
    info = yaml.safe_load(text)['rosbag2_bagfile_information']
    assert list(info) == [
        'version', 'storage_identifier', 'duration', 'starting_time', 'message_count',
        'topics_with_message_count', 'compression_format', 'compression_mode',
        'relative_file_paths', 'files', 'custom_data', 'ros_distro']
    first, last = T0_NS, T0_NS + (STEPS - 1) * DT_NS
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['duration'] == {'nanoseconds': last - first}
    assert info['starting_time'] == {'nanoseconds_since_epoch': first}
    assert info['message_count'] == len(written)
    assert info['relative_file_paths'] == ['swarm_run_0.mcap']
    assert info['files'] == [{'path': 'swarm_run_0.mcap',
                              'starting_time': {'nanoseconds_since_epoch': first},
                              'duration': {'nanoseconds': last - first},
                              'message_count': len(written)}]
    assert info['compression_format'] == info['compression_mode'] == ''
    assert info['custom_data'] is None
    assert info['ros_distro'] == 'jazzy'
    counts = by_topic([(topic, msg) for topic, _, msg in written])
    topics = info['topics_with_message_count']
    assert [entry['topic_metadata']['name'] for entry in topics] == [t for t, _, _ in TOPICS]
    for entry, (topic, msg_type, qos) in zip(topics, TOPICS):
        meta = entry['topic_metadata']
        assert entry['message_count'] == len(counts[topic])
        assert meta['type'] == type_name_of(msg_type)
        assert meta['serialization_format'] == 'cdr'
        assert meta['type_description_hash'] == type_hash(meta['type'])
        assert isinstance(meta['offered_qos_profiles'], list)
        assert parse_qos_profiles(yaml.safe_dump(meta['offered_qos_profiles'])) == [qos]
    state = topics[0]['topic_metadata']['offered_qos_profiles'][0]
    assert state['history'] == 'keep_last' and state['reliability'] == 'reliable'
    assert state['durability'] == 'volatile'
    # The bag metadata is mirrored in the MCAP file, as rosbag2's update_metadata does.
    mirrored = BagReader(bag).metadata('rosbag2')
    assert yaml.safe_load(mirrored['serialized_metadata']) == info


def test_dump_yaml_is_pyyamls_text(bag):
    """dump_yaml lays out mappings, lists and scalars itself (PyYAML's emitter took seconds
    for a bag of 2000 topics): the text is _RosbagDumper's character for character, on the
    bag's metadata and on data with every kind of scalar PyYAML quotes, folds or refuses."""
    from flock_swarm.bag.yaml_emitter import _pyyaml_dump, dump_yaml
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())
    assert dump_yaml(metadata) == _pyyaml_dump(metadata)
    assert (bag / 'metadata.yaml').read_text() == _pyyaml_dump(metadata)
    awkward = ['', 'yes', 'No', 'null', '~', '123', '0x1f', '1e3', '.inf', '2001-12-14', 'x:',
               ': a', '#c', '-', '- a', "it's", '"d"', '[1]', '{a}', '*a', '&a', '!t', '%',
               '@x', '`', '|', '>', '?', '<<', '=', 'é', 'ключ', 'a b', ' lead', 'trail ',
               'a\nb', 'x' * 2000, '/agent_1/odom']
    samples = [{'k': word} for word in awkward] + [{word: 1} for word in awkward if word]
    samples += [[word] for word in awkward]
    samples += [
        {'a': {}, 'b': [], 'c': None, 'd': True, 'e': False, 'f': -(10**30), 'g': 0},
        [{'a': 1, 'b': [1, {'c': 'd'}]}, 'x', None],
        {'a': [[1, 2]]}, {'a': [{}]}, {'a': 1.5}, {}, [], 'scalar', None, 7,
        {'list': [{'deep': {'er': [{'x': ''}]}}], 'z': 'RIHS01_00'},
    ]
    for data in samples:
        assert dump_yaml(data) == _pyyaml_dump(data), data


def test_custom_metadata_records(bag):
    """Metadata records given at creation and added later come back by name."""
    reader = BagReader(bag)
    assert reader.metadata('flock_swarm.scenario') == PROVENANCE
    assert reader.metadata('flock_swarm.result') == {'collisions': '0'}
    assert reader.metadata('no_such_record') is None
    with mcap_file(bag).open('rb') as stream:
        raw = {record.name: dict(record.metadata)
               for record in make_reader(stream).iter_metadata()}
    assert raw['flock_swarm.scenario'] == PROVENANCE
    assert raw['flock_swarm.result'] == {'collisions': '0'}


def chunk_layout(path: Path) -> list[tuple[int, int, int]]:
    """Return ``(start, end, messages)`` of every chunk record, read with the mcap library."""
    layout = []
    with path.open('rb') as stream:
        reader = StreamReader(stream, emit_chunks=True)
        for record in reader.records:
            if isinstance(record, Chunk):
                messages = sum(isinstance(r, Message) for r in breakup_chunk(record))
                layout.append(messages)
    with path.open('rb') as stream:
        indexes = make_reader(stream).get_summary().chunk_indexes
    return [(index.chunk_start_offset, index.chunk_start_offset + index.chunk_length, count)
            for index, count in zip(indexes, layout)]


def cut_copy(source: Path, target: Path, size: int) -> Path:
    """Copy the first ``size`` bytes of a file."""
    target.write_bytes(source.read_bytes()[:size])
    return target


def assert_recovered_prefix(reader: BagReader, written, count: int) -> None:
    """The reader recovered exactly the first ``count`` messages, all decodable and equal."""
    assert reader.recovered
    assert reader.warning is not None and '\n' not in reader.warning
    pairs = list(reader.decoded())
    assert len(pairs) == count
    assert [(m.topic, m.log_time_ns, msg) for m, msg in pairs] == written[:count]
    assert sum(reader.message_counts().values()) == count


@pytest.mark.parametrize('where', ['middle', 'first_chunk_and_3_bytes',
                                   'second_chunk_and_3_bytes', 'inside_first_chunk'])
def test_truncated_file_reads_complete_chunks(bag, written, tmp_path, where):
    """A file cut short yields the messages of its complete chunks and says what was lost."""
    source = mcap_file(bag)
    layout = chunk_layout(source)
    size = {
        'middle': source.stat().st_size // 2,
        'first_chunk_and_3_bytes': layout[0][1] + 3,
        'second_chunk_and_3_bytes': layout[1][1] + 3,
        'inside_first_chunk': layout[0][0] + 20,
    }[where]
    complete = [count for _, end, count in layout if end <= size]
    expected = sum(complete)
    reader = BagReader(cut_copy(source, tmp_path / 'cut.mcap', size))
    assert_recovered_prefix(reader, written, expected)
    assert reader.warning.startswith('cut.mcap is truncated: ')
    assert f'read {expected} message' in reader.warning
    assert f'from {len(complete)} complete chunk' in reader.warning
    if where == 'middle':
        assert 0 < expected < len(written)
        assert reader.metadata('flock_swarm.scenario') == PROVENANCE


def test_truncated_summary_keeps_every_message(bag, written, tmp_path):
    """A file cut inside its summary section still yields every message."""
    source = mcap_file(bag)
    reader = BagReader(cut_copy(source, tmp_path / 'cut.mcap', source.stat().st_size - 20))
    assert_recovered_prefix(reader, written, len(written))
    assert 'only the index was lost' in reader.warning


def test_truncated_bag_directory_mentions_metadata_count(bag, written, tmp_path):
    """In a bag directory, the warning also gives the count metadata.yaml promised."""
    copy = tmp_path / bag.name
    shutil.copytree(bag, copy)
    cut = mcap_file(copy)
    cut_copy(mcap_file(bag), cut, cut.stat().st_size // 3)
    reader = BagReader(copy)
    assert reader.recovered
    assert reader.warning.endswith(f'metadata.yaml lists {len(written)} messages')
    count = sum(reader.message_counts().values())
    assert_recovered_prefix(reader, written, count)


# Records 200 clock messages in 512-byte chunks, then dies without closing or flushing.
KILLED_RECORDER = textwrap.dedent('''
    import os
    import sys
    from pathlib import Path

    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock

    from flock_swarm.bag import BagWriter

    writer = BagWriter(Path(sys.argv[1]), chunk_size=512)
    writer.add_topic('/clock', Clock)
    for k in range(200):
        writer.write('/clock', Clock(clock=Time(sec=k)), k)
    os._exit(0)
''')
#: A 512-byte chunk fills up with 12 Clock records of 43 bytes (9-byte prefix, 22 bytes of
#: channel, sequence and times, 12 bytes of CDR), so a killed recorder loses at most 12.
KILLED_RECORDER_MAX_LOSS = 512 // 43 + 1


def test_killed_recorder_leaves_readable_prefix(tmp_path):
    """A recorder killed mid-run leaves no metadata.yaml and an MCAP whose chunks are on disk."""
    path = tmp_path / 'killed'
    subprocess.run([sys.executable, '-c', KILLED_RECORDER, str(path)], check=True, timeout=120)
    assert not (path / 'metadata.yaml').exists()
    reader = BagReader(path)
    assert reader.recovered
    assert 'was not closed' in reader.warning
    stamps = [msg.clock.sec for _, msg in reader.decoded()]
    assert 200 - KILLED_RECORDER_MAX_LOSS <= len(stamps) < 200
    assert stamps == list(range(len(stamps)))


def test_not_a_bag(tmp_path):
    """Paths that are not ROS 2 MCAP bags raise BagError with a one-line message."""
    text = tmp_path / 'notes.mcap'
    text.write_text('not a bag\nsecond line\n')
    empty = tmp_path / 'empty.mcap'
    empty.write_bytes(b'')
    other = tmp_path / 'other.mcap'
    with other.open('wb') as stream:
        writer = Writer(stream)
        writer.start(profile='', library='test')
        writer.finish()
    empty_dir = tmp_path / 'empty_dir'
    empty_dir.mkdir()
    for path in [text, empty, other, empty_dir, tmp_path / 'missing']:
        with pytest.raises(BagError) as info:
            BagReader(path)
        message = str(info.value)
        assert '\n' not in message
        assert path.name in message
    assert issubclass(BagError, ValueError)


def test_message_definition_of_odometry():
    """Odometry.msg verbatim, then each dependency once, in rosbag2's depth-first order."""
    text = message_definition('nav_msgs/msg/Odometry')
    share = Path(get_package_share_directory('nav_msgs'))
    assert text.startswith((share / 'msg' / 'Odometry.msg').read_text())
    for dependency in ('geometry_msgs/PoseWithCovariance', 'std_msgs/Header',
                       'builtin_interfaces/Time'):
        assert text.count(f'MSG: {dependency}\n') == 1
    headers = [line[len('MSG: '):] for line in text.splitlines() if line.startswith('MSG: ')]
    assert headers == [
        'geometry_msgs/PoseWithCovariance', 'geometry_msgs/Pose', 'geometry_msgs/Point',
        'geometry_msgs/Quaternion', 'geometry_msgs/TwistWithCovariance', 'geometry_msgs/Twist',
        'geometry_msgs/Vector3', 'std_msgs/Header', 'builtin_interfaces/Time']
    assert text.count('=' * 80 + '\n') == len(headers)
    assert '\n\n' + '=' * 80 + '\nMSG: std_msgs/Header\n' in text
    assert encoded_definition('nav_msgs/Odometry').encoding == 'ros2msg'


def test_marker_array_definition_lists_each_type_once():
    """A deep type: constants and sequences add no dependency, shared ones appear once."""
    text = message_definition('visualization_msgs/msg/MarkerArray')
    headers = [line for line in text.splitlines() if line.startswith('MSG: ')]
    assert len(headers) == len(set(headers))
    assert 'MSG: visualization_msgs/Marker' in headers
    assert 'MSG: std_msgs/ColorRGBA' in headers
    assert not any(h.split('/')[-1] in ('uint8', 'int32', 'string') for h in headers)


def fake_interface_package(prefix: Path, package: str, files: dict[str, str]) -> None:
    """Install a package with the given interface files in an ament prefix."""
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / package).touch()
    (prefix / 'share' / package / 'msg').mkdir(parents=True)
    for name, text in files.items():
        (prefix / 'share' / package / 'msg' / name).write_text(text)


def delimiter(kind: str, type_name: str) -> str:
    """Return rosbag2's two-line delimiter before a dependency."""
    return f"{'=' * 80}\n{kind}: {type_name}\n"


def test_definition_parsing_follows_rosbag2_rules(tmp_path, monkeypatch):
    """Bounded types, comments, defaults and short names are handled as rosbag2's regex does."""
    package = 'flock_bag_rules_msgs'
    root = textwrap.dedent('''\
        # Leaf leaf_in_a_comment is not a field.
        uint8 MODE_A=1
        string<=8 bounded_name
        int32[<=3] bounded_ints
        Leaf[<=2] few_leaves
        Leaf[] leaves
          builtin_interfaces/Time[4] stamps
        float64 gain 1.5  # Zed in a trailing comment
        Zed zed
    ''')
    leaf = 'float32 value\nbuiltin_interfaces/Time stamp\n'
    zed = 'Leaf leaf\nbuiltin_interfaces/Duration wait\n'
    fake_interface_package(tmp_path, package,
                           {'Root.msg': root, 'Leaf.msg': leaf, 'Zed.msg': zed})
    monkeypatch.setenv('AMENT_PREFIX_PATH', f"{tmp_path}:{os.environ['AMENT_PREFIX_PATH']}")
    share = Path(get_package_share_directory('builtin_interfaces')) / 'msg'
    time_text = (share / 'Time.msg').read_text()
    duration_text = (share / 'Duration.msg').read_text()
    assert message_definition(f'{package}/msg/Root') == (
        root + '\n' + delimiter('MSG', 'builtin_interfaces/Time') + time_text
        + '\n' + delimiter('MSG', f'{package}/Leaf') + leaf
        + '\n' + delimiter('MSG', f'{package}/Zed') + zed
        + '\n' + delimiter('MSG', 'builtin_interfaces/Duration') + duration_text)


def test_idl_fallback(tmp_path, monkeypatch):
    """A type with no .msg file is stored from its .idl file, encoding ros2idl."""
    package = 'flock_bag_idl_msgs'
    only = '#include "flock_bag_idl_msgs/msg/Part.idl"\nmodule flock_bag_idl_msgs {};\n'
    part = 'module flock_bag_idl_msgs { module msg { struct Part { double x; }; }; };\n'
    fake_interface_package(tmp_path, package, {'Only.idl': only, 'Part.idl': part})
    monkeypatch.setenv('AMENT_PREFIX_PATH', f"{tmp_path}:{os.environ['AMENT_PREFIX_PATH']}")
    definition = encoded_definition(f'{package}/msg/Only')
    assert definition.encoding == 'ros2idl'
    assert definition.text == (delimiter('IDL', f'{package}/msg/Only') + only + '\n'
                               + delimiter('IDL', f'{package}/msg/Part') + part)


def test_type_names():
    """Type names come from classes, instances and strings; other things are refused."""
    assert type_name_of(Odometry) == 'nav_msgs/msg/Odometry'
    assert type_name_of(Odometry()) == 'nav_msgs/msg/Odometry'
    assert type_name_of('nav_msgs/Odometry') == 'nav_msgs/msg/Odometry'
    with pytest.raises(ValueError):
        type_name_of('Odometry')
    with pytest.raises(TypeError):
        type_name_of(dict)


def test_writer_refuses_non_empty_directory_and_files(tmp_path):
    """The bag path may be new or an empty directory, nothing else."""
    occupied = tmp_path / 'occupied'
    occupied.mkdir()
    (occupied / 'data.txt').write_text('keep me')
    with pytest.raises(FileExistsError, match='occupied'):
        BagWriter(occupied)
    afile = tmp_path / 'afile'
    afile.write_text('')
    with pytest.raises(FileExistsError, match='afile'):
        BagWriter(afile)
    empty = tmp_path / 'empty'
    empty.mkdir()
    BagWriter(empty).close()
    assert (empty / 'metadata.yaml').is_file()


def test_writer_misuse(tmp_path):
    """Misuse fails loudly; closing twice is harmless; a closed writer writes nothing more."""
    writer = BagWriter(tmp_path / 'bag')
    writer.add_topic('/clock', Clock)
    writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    with pytest.raises(ValueError, match='already recorded'):
        writer.add_topic('/clock', Odometry)
    with pytest.raises(ValueError, match='absolute'):
        writer.add_topic('clock', Clock)
    with pytest.raises(KeyError, match='/odom'):
        writer.write('/odom', Odometry(), 0)
    with pytest.raises(TypeError, match='rosgraph_msgs/msg/Clock'):
        writer.write('/clock', Odometry(), 0)
    with pytest.raises(ValueError, match='non-negative'):
        writer.write('/clock', Clock(), -1)
    with pytest.raises(ValueError, match='reserved'):
        writer.add_metadata('rosbag2', {})
    with pytest.raises(TypeError):
        writer.add_metadata('numbers', {'seed': 7})
    with pytest.raises(ValueError, match='compression'):
        BagWriter(tmp_path / 'other', compression='gzip')
    writer.write('/clock', Clock(), 5)
    writer.close()
    writer.close()
    assert writer.closed
    with pytest.raises(ValueError, match='closed'):
        writer.write('/clock', Clock(), 6)
    assert writer.message_counts == {'/clock': 1}


def test_empty_bag(tmp_path):
    """A bag without messages has rosbag2's empty-bag times and reads back empty."""
    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic('/clock', Clock)
    info = yaml.safe_load((tmp_path / 'empty' / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert info['message_count'] == 0
    assert info['duration'] == {'nanoseconds': 0}
    assert info['starting_time'] == {'nanoseconds_since_epoch': 2**63 - 1}
    reader = BagReader(tmp_path / 'empty')
    assert reader.topics() == {'/clock': 'rosgraph_msgs/msg/Clock'}
    assert reader.message_counts() == {'/clock': 0}
    assert list(reader.messages()) == []
    assert not reader.recovered


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_chunk_compression(tmp_path, compression):
    """Each chunk compression is written as named and reads back."""
    path = tmp_path / 'bag'
    with BagWriter(path, chunk_size=256, compression=compression) as writer:
        writer.add_topic('/clock', Clock)
        for k in range(50):
            writer.write('/clock', Clock(clock=Time(sec=k)), k)
    with mcap_file(path).open('rb') as stream:
        indexes = make_reader(stream).get_summary().chunk_indexes
    assert len(indexes) > 1
    assert {index.compression for index in indexes} == {'' if compression == 'none'
                                                        else compression}
    assert [msg.clock.sec for _, msg in BagReader(path).decoded()] == list(range(50))


def _write_steps(path: Path, batched: bool, steps: int = 120, **options) -> BagWriter:
    """Record ``steps`` lockstep steps of 1 + 3 odometry and 3 commands, as the world does.

    ``options`` go to the writer (split limits).

    The messages come from flock_swarm.nodes.wire: rclpy leaves padding bytes uninitialised,
    so its bytes of one message may differ from call to call.
    """
    odom = [OdometryEncoder(f'agent_{i}').encode(0, (float(i + k), 0.0), (0.0, 0.0))
            for k in range(2) for i in range(3)]
    cmd = AccelEncoder().encode(0, (0.0, 0.0))
    with BagWriter(path, chunk_size=3000, **options) as writer:
        writer.add_topic('/clock', Clock)
        for i in range(3):
            writer.add_topic(f'/agent_{i}/odom', Odometry)
            writer.add_topic(f'/agent_{i}/cmd_accel', AccelStamped)
        for k in range(steps):
            clock = serialize_message(Clock(clock=Time(sec=k)))
            step = [('/clock', clock)]
            step += [(f'/agent_{i}/odom', odom[3 * (k % 2) + i]) for i in range(3)]
            step += [(f'/agent_{i}/cmd_accel', cmd) for i in (2, 0, 1)]
            if batched:
                writer.write_serialized_many(step[:4], k * 20_000_000)
                writer.write_serialized_many(step[4:], k * 20_000_000)
            else:
                for topic, data in step:
                    writer.write_serialized(topic, data, k * 20_000_000)
    return writer


def test_batched_writes_make_the_same_file_through_the_fast_path(tmp_path, monkeypatch):
    """write_serialized_many writes byte for byte what write_serialized does message by
    message (chunk boundaries inside a batch included), and with the pinned mcap it does so
    without mcap's per-message path."""
    one = _write_steps(tmp_path / 'one' / 'bag', batched=False)
    import mcap.writer

    def refused(*args, **kwargs):
        raise AssertionError('write_serialized_many fell back to Writer.add_message')

    monkeypatch.setattr(mcap.writer.Writer, 'add_message', refused)
    many = _write_steps(tmp_path / 'many' / 'bag', batched=True)
    with mcap_file(one.path).open('rb') as stream:
        assert len(make_reader(stream).get_summary().chunk_indexes) > 3
    assert one.mcap_path.read_bytes() == many.mcap_path.read_bytes()
    assert (one.path / 'metadata.yaml').read_text() == (many.path / 'metadata.yaml').read_text()
    assert many.message_counts == one.message_counts


def test_batched_writes_mixed_with_single_ones_and_late_topics(tmp_path):
    """Batches, single messages and a topic added mid-run in the same chunks (a channel
    indexed several times in a chunk, by both paths): the file of the per-message path."""
    odom = OdometryEncoder('agent_0').encode(0, (1.0, 2.0), (0.0, 0.0))
    cmd = AccelEncoder().encode(0, (0.0, 0.0))
    paths = []
    for batched in (False, True):
        path = tmp_path / ('many' if batched else 'one') / 'bag'
        with BagWriter(path, chunk_size=5000) as writer:
            writer.add_topic('/agent_0/odom', Odometry)
            writer.add_topic('/agent_0/cmd_accel', AccelStamped)
            for k in range(60):
                if k == 20:
                    writer.add_topic('/clock', Clock)
                step = [('/agent_0/odom', odom), ('/agent_0/cmd_accel', cmd)] * (1 + k % 3)
                if k >= 20:
                    step.append(('/clock', serialize_message(Clock(clock=Time(sec=k)))))
                if batched and k % 4:
                    writer.write_serialized_many(step, k * STEP_NS)
                else:
                    for topic, data in step:
                        writer.write_serialized(topic, data, k * STEP_NS)
                if k % 5 == 0:
                    writer.write_serialized('/agent_0/cmd_accel', cmd, k * STEP_NS)
        paths.append(path)
    one, many = paths
    with mcap_file(one).open('rb') as stream:
        assert len(make_reader(stream).get_summary().chunk_indexes) > 5
    assert mcap_file(one).read_bytes() == mcap_file(many).read_bytes()
    assert (one / 'metadata.yaml').read_text() == (many / 'metadata.yaml').read_text()


def test_batched_writes_fall_back_without_the_chunk_builder(tmp_path, monkeypatch):
    """Where mcap's internals are not what the fast path expects, each message goes the
    public way: the same file."""
    one = _write_steps(tmp_path / 'one' / 'bag', batched=False, steps=20)
    monkeypatch.setattr(BagWriter, '_fast_path', lambda self: None)
    many = _write_steps(tmp_path / 'many' / 'bag', batched=True, steps=20)
    assert one.mcap_path.read_bytes() == many.mcap_path.read_bytes()


def test_mcaps_private_writer_is_reached_through_one_adapter_with_its_version(tmp_path):
    """Only bag/mcap_chunk.py names mcap's private attributes, and it hands them out for the
    pinned mcap series alone: another series takes the public path."""
    from flock_swarm.bag.mcap_chunk import installed_mcap, MCAP_SERIES, open_chunk
    package = Path(__file__).resolve().parent.parent / 'flock_swarm'
    naming = sorted(p.relative_to(package).as_posix() for p in package.rglob('*.py')
                    if '_Writer__' in p.read_text())
    assert naming == ['bag/mcap_chunk.py']
    pinned = (package.parent / 'requirements' / 'run.txt').read_text()
    assert f'mcap=={MCAP_SERIES}.' in pinned and installed_mcap().startswith(MCAP_SERIES + '.')
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/clock', Clock)
        assert open_chunk(writer._writer) is not None
        assert open_chunk(writer._writer, '1.7.0') is None
        assert open_chunk(writer._writer, '2.6.0') is None


def test_batched_writes_misuse(tmp_path):
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/clock', Clock)
        data = serialize_message(Clock())
        with pytest.raises(KeyError, match='/odom'):
            writer.write_serialized_many([('/clock', data), ('/odom', data)], 0)
        with pytest.raises(ValueError, match='non-negative'):
            writer.write_serialized_many([('/clock', data)], -1)
        writer.write_serialized_many([], 5)
        assert writer.message_counts == {'/clock': 0}


# -- split bags ----------------------------------------------------------------------------

#: Time between two steps of :func:`_write_steps` [ns].
STEP_NS = 20_000_000


def split_layout(path: Path) -> tuple[dict, list[Path]]:
    """Return the bag's metadata and its MCAP files in the order metadata.yaml lists them."""
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return info, [path / name for name in info['relative_file_paths']]


def file_times(path: Path) -> list[tuple[str, int]]:
    """The ``(topic, log time)`` of every message of one MCAP file, read by ``mcap``."""
    with path.open('rb') as stream:
        return [(channel.topic, message.log_time)
                for _, channel, message in make_reader(stream).iter_messages()]


def test_split_by_size(tmp_path):
    """Files of just over the limit, each complete; together the whole bag, as written."""
    one = _write_steps(tmp_path / 'one' / 'bag', batched=True)
    split = _write_steps(tmp_path / 'split' / 'bag', batched=True, max_bagfile_size=7000)
    info, files = split_layout(split.path)
    assert [f.name for f in files] == [f'bag_{k}.mcap' for k in range(len(files))]
    assert len(files) >= 5 and split.mcap_paths == files
    assert sorted(split.path.iterdir()) == sorted(files + [split.path / 'metadata.yaml'])
    # rosbag2's rule: a file is left once it is larger than the limit, so every file but
    # the last ended above it, and none is empty.
    assert all(f.stat().st_size > 7000 for f in files[:-1])
    for path, entry in zip(files, info['files']):
        times = file_times(path)
        assert entry['path'] == path.name and entry['message_count'] == len(times) > 0
        assert entry['starting_time']['nanoseconds_since_epoch'] == min(t for _, t in times)
        assert entry['duration']['nanoseconds'] == max(t for _, t in times) - min(
            t for _, t in times)
    assert info['message_count'] == sum(e['message_count'] for e in info['files'])
    assert info['message_count'] == 120 * 7
    whole = BagReader(one.path)
    assert [(m.topic, m.log_time_ns, m.data) for m in BagReader(split.path).messages()] == \
        [(m.topic, m.log_time_ns, m.data) for m in whole.messages()]
    with RosbagsReader(split.path) as reader:
        assert reader.message_count == 120 * 7
        assert sorted((c.topic, t) for c, t, _ in reader.messages()) == sorted(
            (m.topic, m.log_time_ns) for m in whole.messages())


def test_split_by_duration_keeps_a_batch_in_one_file(tmp_path):
    """A file spans at most the limit, the next starts past it; a step is never cut."""
    split = _write_steps(tmp_path / 'bag', batched=True, steps=100,
                         max_bagfile_duration=0.25)
    info, files = split_layout(split.path)
    # 100 steps of 0.02 s, a file per 13 steps (0 .. 0.24 s after its first): 8 files.
    assert len(files) == 8
    starts = []
    for path in files:
        times = [t for _, t in file_times(path)]
        assert max(times) - min(times) <= 250_000_000
        assert len(times) == 7 * len(set(times))
        starts.append(min(times))
    assert all(b - a > 250_000_000 for a, b in zip(starts, starts[1:]))


def test_split_by_size_keeps_a_step_in_one_file(tmp_path):
    """A step written message by message (the world writes its states, then the commands,
    at the same time) stays in one file, also when a chunk fills in its middle: a split
    waits for the next time (docs/ros.md, "Splitting the bag")."""
    with BagWriter(tmp_path / 'bag', chunk_size=500, max_bagfile_size=1000) as writer:
        writer.add_topic('/clock', Clock)
        writer.add_topic('/odom', Odometry)
        for k in range(60):
            writer.write('/clock', Clock(clock=Time(sec=k)), k * STEP_NS)
            for i in range(3):
                writer.write('/odom', odometry(k * STEP_NS, f'agent_{i}', k, 0), k * STEP_NS)
    _, files = split_layout(tmp_path / 'bag')
    assert len(files) >= 3
    file_of: dict[int, Path] = {}
    for path in files:
        times = file_times(path)
        assert len(times) % 4 == 0
        for _, t in times:
            assert file_of.setdefault(t, path) == path, f'step at {t} ns in two files'
    assert len(file_of) == 60


def test_every_file_carries_schemas_channels_and_custom_records(tmp_path):
    with BagWriter(tmp_path / 'bag', chunk_size=500, max_bagfile_duration=0.1,
                   custom_metadata={'flock_swarm': {'scenario': 'demo'}}) as writer:
        writer.add_topic('/clock', Clock)
        for k in range(40):
            writer.write('/clock', Clock(clock=Time(sec=k)), k * STEP_NS)
            if k == 5:
                writer.add_topic('/late', Odometry)
                writer.add_metadata('late_record', {'k': '5'})
            if k >= 5:
                writer.write('/late', odometry(k * STEP_NS, 'agent_0', k, 0), k * STEP_NS)
    _, files = split_layout(tmp_path / 'bag')
    # The first file holds steps 0..5, where the late topic and record came.
    assert len(files) >= 3 and max(t for _, t in file_times(files[0])) == 5 * STEP_NS
    for path in files:
        with path.open('rb') as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            records = {record.name: record.metadata for record in reader.iter_metadata()}
        assert sorted(c.topic for c in summary.channels.values()) == ['/clock', '/late']
        assert records['flock_swarm'] == {'scenario': 'demo'}
        assert records['late_record'] == {'k': '5'}
        assert 'rosbag2' in records


def test_abandoned_split_bag_keeps_its_finished_files(tmp_path):
    """No metadata.yaml: the files are read in split order (bag_10 after bag_9), the
    finished ones whole, the open one up to its last complete chunk."""
    path = tmp_path / 'bag'
    writer = BagWriter(path, chunk_size=500, max_bagfile_size=1000)
    writer.add_topic('/clock', Clock)
    for k in range(200):
        writer.write('/clock', Clock(clock=Time(sec=k)), k * STEP_NS)
    files = writer.mcap_paths
    writer.abandon()
    assert len(files) > 11 and not (path / 'metadata.yaml').exists()
    finished = sum(len(file_times(file)) for file in files[:-1])
    reader = BagReader(path)
    assert reader.files == files
    assert reader.recovered and files[-1].name in reader.warning
    secs = [msg.clock.sec for _, msg in reader.decoded()]
    assert secs == list(range(len(secs))) and finished < len(secs) <= 200


@pytest.mark.parametrize('options, message', [
    ({'max_bagfile_size': -1}, 'max_bagfile_size'),
    ({'max_bagfile_duration': -0.5}, 'max_bagfile_duration'),
    ({'max_bagfile_duration': float('nan')}, 'max_bagfile_duration'),
    ({'max_bagfile_duration': float('inf')}, 'max_bagfile_duration'),
])
def test_split_limits_are_checked(tmp_path, options, message):
    with pytest.raises(ValueError, match=message):
        BagWriter(tmp_path / 'bag', **options)
    assert not (tmp_path / 'bag').exists()


def padded_messages() -> list:
    """Return messages of every type the world serialises itself, with CDR padding in each
    (after a ``byte`` before a string, a ``bool`` before a sequence, a string before an
    8-byte field, empty sequences of doubles)."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Empty, String
    marker = Marker(ns='a', type=Marker.SPHERE_LIST, frame_locked=True, text='x',
                    points=[Point(x=1.0), Point(y=2.0)], colors=[ColorRGBA(r=0.5)])
    marker.header.frame_id = 'map'
    marker.mesh_file.data = [1, 2, 3]
    status = DiagnosticStatus(level=b'\x01', name='flock_swarm/metrics', message='ok',
                              hardware_id='flock_swarm',
                              values=[KeyValue(key='eta', value='0.5'),
                                      KeyValue(key='n', value='4')])
    diagnostics = DiagnosticArray(status=[status, DiagnosticStatus()])
    diagnostics.header.stamp = Time(sec=3, nanosec=7)
    return [diagnostics, MarkerArray(markers=[marker, Marker()]), String(data='hé'), Empty(),
            JointState(name=['a', 'bc'], position=[1.0, 2.0]), Odometry(), Clock()]


@pytest.mark.parametrize('msg', padded_messages(), ids=lambda m: type(m).__name__)
def test_serialize_is_rclpys_bytes_with_zero_padding(msg):
    """:func:`serialize` (what the world publishes and records) gives rclpy's bytes, except
    that every byte where they differ, the padding rclpy leaves uninitialised, is zero."""
    from rclpy.serialization import deserialize_message
    from flock_swarm.bag.writer import serialize
    ours, theirs = serialize(msg), serialize_message(msg)
    assert len(ours) == len(theirs)
    assert deserialize_message(ours, type(msg)) == msg
    assert all(ours[i] == 0 for i in range(len(ours)) if ours[i] != theirs[i])
    assert serialize(msg) == ours


def test_bag_writer_writes_messages_with_zero_padding(tmp_path):
    """Two bags of the same messages written by :meth:`BagWriter.write` are the same
    bytes (the DiagnosticArray's padding varied from call to call through rclpy)."""
    messages = padded_messages()
    paths = [tmp_path / 'a' / 'bag', tmp_path / 'b' / 'bag']
    for path in paths:
        with BagWriter(path) as writer:
            writer.add_topic('/swarm/metrics', DiagnosticArray)
            for k in range(50):
                writer.write('/swarm/metrics', messages[0], k * STEP_NS)
    first = sorted(p.name for p in paths[0].iterdir())
    assert first == sorted(p.name for p in paths[1].iterdir())
    for name in first:
        assert (paths[0] / name).read_bytes() == (paths[1] / name).read_bytes(), name
