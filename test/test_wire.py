"""The CDR codec of the hot-path messages, checked both ways against rclpy's serialisation."""

import math
import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import AccelStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from flock_swarm.nodes.wire import (AccelBatch, AccelEncoder, MalformedMessage, OdometryBatch,
                                    OdometryBatchEncoder, OdometryEncoder, StateEncoder,
                                    decode_accel, decode_clock, decode_odometry, decode_state,
                                    encode_clock)

floats = st.floats(allow_nan=False, width=64)
vec3 = st.tuples(floats, floats, floats)
#: Stamps a message can carry: int32 seconds, uint32 nanoseconds (rclpy checks the ranges).
stamps = st.tuples(st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1))
frames = st.text(max_size=40).filter(lambda s: '\0' not in s)
#: An adaptive state's labels and values (JointState's name and position), of equal length.
labelled = st.integers(0, 6).flatmap(lambda n: st.tuples(
    st.lists(st.text(min_size=1, max_size=12).filter(lambda s: '\0' not in s), min_size=n,
             max_size=n),
    st.lists(st.floats(width=64), min_size=n, max_size=n)))


def odometry(sec, nanosec, frame, child, pos, vel, orientation=(0.0, 0.0, 0.0, 1.0)):
    """Return an rclpy Odometry with these fields (others default)."""
    msg = Odometry()
    msg.header.stamp = Time(sec=sec, nanosec=nanosec)
    msg.header.frame_id, msg.child_frame_id = frame, child
    p, o, v = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist.linear
    p.x, p.y, p.z = pos
    o.x, o.y, o.z, o.w = orientation
    v.x, v.y, v.z = vel
    return msg


def accel(sec, nanosec, frame, lin):
    """Return an rclpy AccelStamped with these fields."""
    msg = AccelStamped()
    msg.header.stamp = Time(sec=sec, nanosec=nanosec)
    msg.header.frame_id = frame
    msg.accel.linear.x, msg.accel.linear.y, msg.accel.linear.z = lin
    return msg


@settings(max_examples=100, deadline=None)
@given(stamps, frames, frames, vec3, vec3)
def test_decode_odometry_reads_what_rclpy_writes(stamp, frame, child, pos, vel):
    data = serialize_message(odometry(*stamp, frame, child, pos, vel))
    assert decode_odometry(data) == (stamp[0] * 10**9 + stamp[1], frame, child, pos, vel)


@settings(max_examples=100, deadline=None)
@given(stamps, frames, vec3)
def test_decode_accel_reads_what_rclpy_writes(stamp, frame, lin):
    data = serialize_message(accel(*stamp, frame, lin))
    assert decode_accel(data) == (stamp[0] * 10**9 + stamp[1], frame, lin)


def joint_state(sec, nanosec, frame, names, positions):
    """Return an rclpy JointState with these fields (velocity and effort empty)."""
    msg = JointState()
    msg.header.stamp = Time(sec=sec, nanosec=nanosec)
    msg.header.frame_id = frame
    msg.name, msg.position = list(names), list(positions)
    return msg


def same_floats(a, b) -> bool:
    """Whether two float sequences are equal, NaN equal to NaN."""
    return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                          equal_nan=True)


@settings(max_examples=100, deadline=None)
@given(stamps, frames, labelled)
def test_decode_state_reads_what_rclpy_writes(stamp, frame, state):
    names, positions = state
    data = serialize_message(joint_state(*stamp, frame, names, positions))
    ns, got_frame, got_names, got = decode_state(data)
    assert (ns, got_frame, got_names) == (stamp[0] * 10**9 + stamp[1], frame, tuple(names))
    assert same_floats(got, positions)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, (2**31 - 1) * 10**9), labelled)
def test_encoded_state_is_what_rclpy_reads(ns, state):
    names, positions = state
    encoder = StateEncoder(names)
    msg = deserialize_message(encoder.encode(ns, positions), JointState)
    assert (msg.header.stamp, msg.header.frame_id, list(msg.name)) == \
        (Time(sec=ns // 10**9, nanosec=ns % 10**9), 'world', list(names))
    assert same_floats(msg.position, positions)
    assert len(msg.velocity) == len(msg.effort) == 0
    # Reusable: the bytes depend on this call's stamp and values only.
    assert encoder.encode(ns, positions) == StateEncoder(names).encode(ns, positions)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, (2**31 - 1) * 10**9), st.text(min_size=1, max_size=20).filter(
    lambda s: '\0' not in s), vec3, vec3)
def test_encoded_odometry_is_what_rclpy_reads(ns, child, pos, vel):
    msg = deserialize_message(OdometryEncoder(child).encode(ns, pos, vel), Odometry)
    assert msg == odometry(*divmod(ns, 10**9), 'world', child, pos, vel)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, (2**31 - 1) * 10**9), vec3)
def test_encoded_accel_and_clock_are_what_rclpy_reads(ns, lin):
    assert deserialize_message(AccelEncoder().encode(ns, lin), AccelStamped) == \
        accel(*divmod(ns, 10**9), 'world', lin)
    assert deserialize_message(encode_clock(ns), Clock) == \
        Clock(clock=Time(sec=ns // 10**9, nanosec=ns % 10**9))
    assert decode_clock(encode_clock(ns)) == ns


def test_two_dimensional_vectors_leave_z_zero_and_encoders_are_reusable():
    enc = OdometryEncoder('agent_3')
    enc.encode(5, (1.0, 2.0, 3.0), (4.0, 5.0, 6.0))
    data = enc.encode(7, [0.5, -0.5], [1.5, -1.5])
    assert decode_odometry(data) == (7, 'world', 'agent_3', (0.5, -0.5, 3.0), (1.5, -1.5, 6.0))
    # A 2-D run never writes z, and z starts at 0 in a fresh encoder.
    fresh = OdometryEncoder('agent_3').encode(7, [0.5, -0.5], [1.5, -1.5])
    assert decode_odometry(fresh)[3:] == ((0.5, -0.5, 0.0), (1.5, -1.5, 0.0))
    # The bytes are independent of earlier calls' values once every vector is written.
    assert enc.encode(9, (1.0, 1.0, 0.0), (2.0, 2.0, 0.0)) == \
        OdometryEncoder('agent_3').encode(9, (1.0, 1.0, 0.0), (2.0, 2.0, 0.0))


def test_non_finite_values_pass_through_for_the_guard_to_judge():
    data = serialize_message(odometry(1, 0, 'world', 'agent_0', (math.nan, math.inf, 0.0),
                                      (-math.inf, 0.0, 0.0)))
    _, _, _, pos, vel = decode_odometry(data)
    assert math.isnan(pos[0]) and pos[1] == math.inf and vel[0] == -math.inf


def test_big_endian_cdr_is_read():
    """rclpy writes little-endian only; a big-endian peer's message is built by hand."""
    be = bytearray(b'\x00\x00\x00\x00') + struct.pack('>iI', 3, 7)
    be += struct.pack('>I', 6) + b'world\0' + bytes(2)      # -> payload offset 20
    be += bytes(4) + struct.pack('>3d', 1.0, -2.0, 0.5) + bytes(24)
    assert decode_accel(bytes(be)) == (3_000_000_007, 'world', (1.0, -2.0, 0.5))


GOOD_ODOM = serialize_message(odometry(1, 2, 'world', 'agent_0', (1.0, 2.0, 3.0),
                                       (4.0, 5.0, 6.0)))
GOOD_ACCEL = serialize_message(accel(1, 2, 'world', (1.0, 2.0, 3.0)))
# rclpy's JointState bytes end in unused capacity; the encoder's end with the message.
GOOD_STATE = StateEncoder(('h', 'e[0]', 'e[1]')).encode(1_000_000_002, (1.0, 2.0, 3.0))


# Named ids, not the bytes: serialize_message leaves CDR's alignment padding as it found the
# buffer, so the bytes differ between processes, and pytest-xdist's workers must collect the
# same test ids.
@pytest.mark.parametrize('decode, good', [(decode_odometry, GOOD_ODOM),
                                          (decode_accel, GOOD_ACCEL),
                                          (decode_state, GOOD_STATE)],
                         ids=['odometry', 'accel', 'state'])
def test_every_truncation_is_malformed(decode, good):
    for size in range(len(good)):
        with pytest.raises(MalformedMessage):
            decode(good[:size])
    decode(good)


@pytest.mark.parametrize('data, reason', [
    (b'', 'encapsulation'),
    (b'\x00\x02\x00\x00' + GOOD_ACCEL[4:], 'encapsulation'),      # a PL_CDR / XCDR2 kind
    (b'\x01\x01\x00\x00' + GOOD_ACCEL[4:], 'encapsulation'),
    (GOOD_ACCEL[:12] + struct.pack('<I', 0) + GOOD_ACCEL[16:], 'NUL'),   # zero length
    (GOOD_ACCEL[:12] + struct.pack('<I', 10**6) + GOOD_ACCEL[16:], 'NUL'),  # beyond the end
    (GOOD_ACCEL[:16] + b'world!' + GOOD_ACCEL[22:], 'NUL'),            # no terminator
    (GOOD_ACCEL[:16] + b'w\xffrld\0' + GOOD_ACCEL[22:], 'UTF-8'),
], ids=['empty', 'pl-cdr-be', 'unknown-kind', 'zero-length', 'length-beyond-end',
        'no-terminator', 'bad-utf8'])
def test_malformed_bytes_raise_with_a_reason(data, reason):
    with pytest.raises(MalformedMessage, match=reason):
        decode_accel(data)


def test_a_state_claiming_more_names_or_values_than_its_bytes_is_malformed():
    names_at = 4 + 8 + 4 + len('world\0')        # the name count, 4-aligned after frame_id
    names_at += -names_at % 4
    with pytest.raises(MalformedMessage, match='names'):
        decode_state(GOOD_STATE[:names_at] + struct.pack('<I', 10**6) + GOOD_STATE[names_at + 4:])
    values_at = len(GOOD_STATE) - 8 - 3 * 8 - 4 - 4  # the position count, before its padding
    with pytest.raises(MalformedMessage, match='truncated JointState'):
        decode_state(GOOD_STATE[:values_at] + struct.pack('<I', 4) + GOOD_STATE[values_at + 4:])


@pytest.mark.parametrize('dim, n', [(2, 100), (3, 7), (2, 1)])
def test_markers_written_as_cdr_are_the_rclpy_markers(dim, n):
    """swarm_markers_cdr (what the world publishes) is swarm_markers's message, serialised."""
    import numpy as np
    from visualization_msgs.msg import MarkerArray

    from flock_swarm.core.graphs import disk_graph
    from flock_swarm.nodes.markers import swarm_markers, swarm_markers_cdr
    rng = np.random.default_rng(n)
    q, p = rng.uniform(0.0, 30.0, (n, dim)), rng.normal(size=(n, dim))
    edges, informed = disk_graph(q, 4.0), rng.random(n) < 0.3
    assert n < 50 or edges.size > 50
    typed = swarm_markers(q, p, q[0] + 1.0, informed, edges, Time(sec=3, nanosec=5), 'world',
                          0.3)
    ours = swarm_markers_cdr(q, p, q[0] + 1.0, informed, edges, 3_000_000_005, 'world', 0.3)
    # Compared after serialisation: colours are float32 on the wire.
    assert deserialize_message(ours, MarkerArray) == \
        deserialize_message(serialize_message(typed), MarkerArray)


#: Agents 0..11: child ids of one and of two digits (the pose's offset differs).
BATCH_N = 12


def batch_messages(stamp=(3, 500)):
    """Return a step's odometry of BATCH_N agents as rclpy serialises it, and the states."""
    rng = np.random.default_rng(7)
    states = rng.normal(scale=50.0, size=(BATCH_N, 2, 3))
    data = [serialize_message(odometry(*stamp, 'world', f'agent_{j}', *states[j].tolist()))
            for j in range(BATCH_N)]
    return data, states


def test_odometry_batch_reads_what_rclpy_writes():
    data, states = batch_messages()
    batch = OdometryBatch([f'agent_{j}' for j in range(BATCH_N)])
    ns, got = batch.decode(data)
    assert ns == 3_000_000_500
    assert got.shape == (BATCH_N, 2, 3) and got.tobytes() == states.tobytes()
    # ... and what the world's encoders write, read as decode_odometry reads it one by one.
    sent = [OdometryEncoder(f'agent_{j}').encode(ns, *states[j, :, :2].tolist())
            for j in range(BATCH_N)]
    one_by_one = [decode_odometry(msg)[3:] for msg in sent]
    assert batch.decode(sent)[1].tolist() == [list(map(list, s)) for s in one_by_one]


def zero_odometry(nanosec, frame, child):
    """Return a serialised odometry of stamp 3 s + ``nanosec`` at the origin, at rest."""
    return serialize_message(odometry(3, nanosec, frame, child, (0, 0, 0), (0, 0, 0)))


def _swap(data, j, msg):
    return data[:j] + [msg] + data[j + 1:]


@pytest.mark.parametrize('spoil', [
    lambda d: _swap(d, 4, d[5]),                                 # agent 5 twice, 4 missing
    lambda d: _swap(d, 4, None),                                 # agent 4 not in
    lambda d: d[:-1],                                            # one agent short
    lambda d: _swap(d, 11, zero_odometry(500, 'world', 'agent_12')),  # another child id
    lambda d: _swap(d, 2, zero_odometry(500, 'map', 'agent_2')),       # another frame
    lambda d: _swap(d, 3, zero_odometry(501, 'world', 'agent_3')),     # another stamp
    lambda d: _swap(d, 6, d[6] + b'\0' * 8),                    # longer than the layout
    lambda d: _swap(d, 0, b'\x00\x00' + d[0][2:]),               # big-endian header
])
def test_odometry_batch_leaves_anything_else_to_the_one_by_one_path(spoil):
    data, _ = batch_messages()
    assert OdometryBatch([f'agent_{j}' for j in range(BATCH_N)]).decode(spoil(data)) is None


def batch_commands(stamp=(3, 500)):
    """Return a step's commands of BATCH_N agents as rclpy serialises them, and the values."""
    lin = np.random.default_rng(8).normal(scale=5.0, size=(BATCH_N, 3))
    return [serialize_message(accel(*stamp, 'world', lin[i].tolist()))
            for i in range(BATCH_N)], lin


def test_accel_batch_reads_what_rclpy_and_the_agents_write():
    data, lin = batch_commands()
    ns, got = AccelBatch(BATCH_N).decode(data)
    assert ns == 3_000_000_500 and got.shape == (BATCH_N, 1, 3)
    assert got[:, 0].tobytes() == lin.tobytes()
    sent = [AccelEncoder().encode(ns, lin[i].tolist()) for i in range(BATCH_N)]
    assert [decode_accel(msg)[2] for msg in sent] == [tuple(row) for row in got[:, 0]]
    assert AccelBatch(BATCH_N).decode(sent)[1].tobytes() == got.tobytes()


# A command carries no agent id: the world puts each where its topic says, so an agent
# heard twice leaves another's place empty (None).
@pytest.mark.parametrize('spoil', [
    lambda d: _swap(d, 4, None),                                 # agent 4 not in
    lambda d: d[:-1],                                            # one agent short
    lambda d: _swap(d, 2, serialize_message(accel(3, 500, 'map', (0, 0, 0)))),  # frame
    lambda d: _swap(d, 3, serialize_message(accel(3, 501, 'world', (0, 0, 0)))),  # stamp
    lambda d: _swap(d, 6, d[6] + b'\0' * 8),                    # longer than the layout
    lambda d: _swap(d, 0, b'\x00\x00' + d[0][2:]),               # big-endian header
])
def test_accel_batch_leaves_anything_else_to_the_one_by_one_path(spoil):
    data, _ = batch_commands()
    assert AccelBatch(BATCH_N).decode(spoil(data)) is None


@pytest.mark.parametrize('dim', [2, 3])
def test_accel_batch_encoder_writes_the_encoders_bytes(dim):
    """The agents' commands encoded at once are, row by row, AccelEncoder's bytes (non-finite
    values and -0.0 included), and encoding again overwrites stamp and vectors."""
    from flock_swarm.nodes.wire import AccelBatchEncoder
    rng = np.random.default_rng(dim)
    batch = AccelBatchEncoder(BATCH_N)
    for ns in (1_020_000_000, 7, 0):
        u = rng.normal(size=(BATCH_N, dim))
        u[0, 0], u[1, -1], u[2, 0] = np.nan, -0.0, np.inf
        assert batch.encode(ns, u) == [AccelEncoder().encode(ns, row) for row in u.tolist()]
        msg = deserialize_message(batch.encode(ns, u)[3], AccelStamped)
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == ns
        assert [msg.accel.linear.x, msg.accel.linear.y, msg.accel.linear.z][:dim] == \
            u[3].tolist()
    assert AccelBatchEncoder(0).encode(5, np.zeros((0, 2))) == []


@pytest.mark.parametrize('dim', [2, 3])
def test_odometry_batch_encoder_writes_the_encoders_bytes(dim):
    """A step encoded at once is, message by message, what rclpy reads as the states (and
    the one-message encoder's bytes); encoding again overwrites stamp and vectors."""
    rng = np.random.default_rng(dim)
    children = [f'agent_{j}' for j in range(BATCH_N)]
    batch = OdometryBatchEncoder(children)
    for ns in (1_020_000_000, 7):
        q, p = rng.normal(size=(BATCH_N, dim)), rng.normal(size=(BATCH_N, dim))
        sent = batch.encode(ns, q, p)
        assert sent == [OdometryEncoder(c).encode(ns, q[j].tolist(), p[j].tolist())
                        for j, c in enumerate(children)]
        for j, data in enumerate(sent):
            msg = deserialize_message(data, Odometry)
            assert msg.child_frame_id == children[j] and msg.header.frame_id == 'world'
            assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == ns
            pos, vel = msg.pose.pose.position, msg.twist.twist.linear
            assert [pos.x, pos.y, pos.z][:dim] == q[j].tolist()
            assert [vel.x, vel.y, vel.z][:dim] == p[j].tolist()
            assert dim == 3 or pos.z == vel.z == 0.0


def test_large_swarm_dds_profile_holds_a_step_of_1000_odometries():
    """config/fastdds_large_swarm.xml (docs/ros.md): its shared-memory segment holds a
    lockstep step of 1000 agents' odometry and commands, its port queue their number."""
    import xml.etree.ElementTree as ET
    from pathlib import Path
    root = ET.parse(Path(__file__).resolve().parent.parent / 'config'
                    / 'fastdds_large_swarm.xml').getroot()
    ns = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    shm = [d for d in root.iterfind('f:transport_descriptors/f:transport_descriptor', ns)
           if d.findtext('f:type', namespaces=ns) == 'SHM']
    assert len(shm) == 1
    step = 1000 * (len(OdometryEncoder('agent_999').encode(0, (0, 0), (0, 0)))
                   + len(AccelEncoder().encode(0, (0, 0))))
    assert int(shm[0].findtext('f:segment_size', namespaces=ns)) >= 2 * step
    assert int(shm[0].findtext('f:port_queue_capacity', namespaces=ns)) >= 2 * 2000
    used = [t.text for t in root.iterfind('f:participant/f:rtps/f:userTransports/'
                                          'f:transport_id', ns)]
    assert shm[0].findtext('f:transport_id', namespaces=ns) in used


def test_twist_both_directions_against_rclpy():
    """A robot plant's velocity command (cmd_vel) as rclpy serialises it."""
    from geometry_msgs.msg import Twist, Vector3
    from flock_swarm.nodes.wire import decode_twist, encode_twist
    linear, angular = (0.22, -1e-300, 3.5), (0.0, -0.0, 2.84)
    msg = Twist(linear=Vector3(x=linear[0], y=linear[1], z=linear[2]),
                angular=Vector3(x=angular[0], y=angular[1], z=angular[2]))
    assert encode_twist(linear, angular) == serialize_message(msg)
    assert decode_twist(serialize_message(msg)) == (linear, angular)
    with pytest.raises(MalformedMessage):
        decode_twist(serialize_message(msg)[:40])


def test_oriented_odometry_carries_the_heading_against_rclpy():
    """An oriented plant's odometry (the unicycle's): orientation z, w and the yaw rate
    written where rclpy puts them, read back one by one and in a batch."""
    from flock_swarm.nodes.wire import OdometryBatchEncoder, decode_heading
    children = ['agent_0', 'agent_1']
    q, v = np.array([[1.0, 2.0], [-3.0, 0.5]]), np.array([[0.2, 0.0], [-0.1, 0.0]])
    heading = np.array([[0.6, 0.8], [-1.0, 0.0]])
    yaw_rate = np.array([[1.5, 0.0], [-2.0, 0.0]])
    blobs = OdometryBatchEncoder(children, oriented=True).encode(7, q, v, heading, yaw_rate)
    for j, data in enumerate(blobs):
        msg = deserialize_message(data, Odometry)
        o = msg.pose.pose.orientation
        assert (o.x, o.y, o.z, o.w) == (0.0, 0.0, *heading[j])
        assert msg.twist.twist.angular.z == yaw_rate[j, 0]
        assert (msg.twist.twist.linear.x, msg.pose.pose.position.y) == (v[j, 0], q[j, 1])
        assert decode_heading(data) == (tuple(heading[j]), (yaw_rate[j, 0], 0.0))
        assert data == serialize_message(msg)
    _, states = OdometryBatch(children, oriented=True).decode(blobs)
    np.testing.assert_array_equal(states[:, :, :2], np.stack([q, v, heading, yaw_rate], axis=1))
