"""The batched transport's codec (flock_swarm.nodes.cloud): a swarm's state and a host's
commands as one sensor_msgs/PointCloud2, checked against rclpy's serialisation and read back
from a recorded bag by rosbags, the independent reader."""

import struct

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import PointCloud2, PointField

from flock_swarm.bag import BagWriter
from flock_swarm.contract import state_labels
from flock_swarm.nodes.cloud import (CloudEncoder, PerAgentMessages, command_fields, decode_cloud,
                                     state_fields)
from flock_swarm.nodes.wire import (AccelEncoder, MalformedMessage, OdometryEncoder, StateEncoder,
                                    encode_twist)

#: rosbags' PointField datatypes to NumPy types (its messages carry the constants).
NUMPY = {7: 'f4', 8: 'f8', 6: 'u4'}


def swarm(n, width, seed=0):
    """Return ``(ids, values)``: ``n`` points of ``width`` seeded floats, ids shuffled."""
    rng = np.random.default_rng(seed)
    return rng.permutation(n), rng.normal(scale=1e3, size=(n, width))


@pytest.mark.parametrize('dim, oriented', [(2, False), (3, False), (2, True)])
def test_the_state_cloud_is_the_pointcloud2_rclpy_reads(dim, oriented):
    fields = state_fields(dim, oriented)
    ids, values = swarm(7, len(fields))
    data = CloudEncoder(fields).encode(12_340_000_000, ids, values)
    msg = deserialize_message(data, PointCloud2)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12, 340_000_000)
    assert msg.header.frame_id == 'world'
    assert (msg.height, msg.width, msg.is_bigendian, msg.is_dense) == (1, 7, False, True)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == \
        [(name, 8 * j, PointField.FLOAT64, 1) for j, name in enumerate(fields)] + \
        [('id', 8 * len(fields), PointField.UINT32, 1)]
    assert msg.point_step == 8 * len(fields) + 4 and msg.row_step == 7 * msg.point_step
    points = np.frombuffer(bytes(msg.data), dtype=np.dtype(
        [(name, '<f8') for name in fields] + [('id', '<u4')]))
    np.testing.assert_array_equal(points['id'], ids)
    for j, name in enumerate(fields):
        np.testing.assert_array_equal(points[name], values[:, j])
    # rclpy's own serialisation of the message decodes to the same numbers.
    cloud = decode_cloud(serialize_message(msg))
    assert (cloud.stamp_ns, cloud.frame_id) == (12_340_000_000, 'world')
    np.testing.assert_array_equal(cloud.ids(), ids)
    np.testing.assert_array_equal(cloud.columns(fields), values)


def test_the_field_names():
    assert state_fields(2) == ('x', 'y', 'vx', 'vy')
    assert state_fields(3) == ('x', 'y', 'z', 'vx', 'vy', 'vz')
    assert state_fields(2, oriented=True) == ('x', 'y', 'vx', 'vy', 'qz', 'qw', 'wz')
    labels = state_labels({'h': (), 'e': (2,)})
    assert command_fields(2, labels) == ('ax', 'ay', 'h', 'e[0]', 'e[1]')


def test_a_recorded_cloud_reads_the_same_in_rosbags(tmp_path):
    # The state cloud and a command cloud written into a bag; rosbags (its own CDR
    # deserialiser and type store) reads the same stamps, fields and numbers.
    store = get_typestore(Stores.ROS2_JAZZY)
    state = state_fields(2)
    commands = command_fields(2, ('h',))
    ids, values = swarm(50, len(state), seed=1)
    mine, u = np.arange(10, 20), swarm(10, len(commands), seed=2)[1]
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic('/swarm/states', PointCloud2)
        bag.add_topic('/swarm/commands', PointCloud2)
        bag.write_serialized('/swarm/states', CloudEncoder(state).encode(20_000_000, ids, values),
                             20_000_000)
        bag.write_serialized('/swarm/commands',
                             CloudEncoder(commands).encode(20_000_000, mine, u), 20_000_000)
    read = {}
    with RosbagsReader(tmp_path / 'bag') as reader:
        for conn, t_ns, raw in reader.messages():
            assert conn.msgtype == 'sensor_msgs/msg/PointCloud2'
            read[conn.topic] = (t_ns, store.deserialize_cdr(raw, conn.msgtype))
    for topic, names, want_ids, want in (('/swarm/states', state, ids, values),
                                         ('/swarm/commands', commands, mine, u)):
        t_ns, msg = read[topic]
        assert t_ns == 20_000_000
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 20_000_000)
        assert msg.header.frame_id == 'world' and msg.width == len(want_ids)
        dtype = np.dtype({'names': [f.name for f in msg.fields],
                          'formats': ['<' + NUMPY[f.datatype] for f in msg.fields],
                          'offsets': [f.offset for f in msg.fields],
                          'itemsize': msg.point_step})
        points = np.frombuffer(msg.data.tobytes(), dtype=dtype)
        np.testing.assert_array_equal(points['id'], want_ids)
        np.testing.assert_array_equal(np.column_stack([points[n] for n in names]), want)


def test_a_cloud_of_another_layout_decodes():
    # Another tool's cloud: fields in another order, FLOAT32 values, big-endian data,
    # padding in the point, two rows.
    msg = PointCloud2()
    msg.header.frame_id = 'world'
    msg.height, msg.width, msg.is_bigendian, msg.point_step = 2, 2, True, 16
    msg.fields = [PointField(name='id', offset=0, datatype=PointField.UINT32, count=1),
                  PointField(name='y', offset=12, datatype=PointField.FLOAT32, count=1),
                  PointField(name='x', offset=4, datatype=PointField.FLOAT32, count=1)]
    msg.row_step = 32
    msg.data = b''.join(struct.pack('>If4xf', i, 0.5 * i, -float(i)) for i in range(4))
    cloud = decode_cloud(serialize_message(msg))
    np.testing.assert_array_equal(cloud.ids(), [0, 1, 2, 3])
    np.testing.assert_array_equal(cloud.columns(('x', 'y')),
                                  [[0.0, -0.0], [0.5, -1.0], [1.0, -2.0], [1.5, -3.0]])


def test_what_is_not_a_cloud_is_malformed():
    data = CloudEncoder(state_fields(2)).encode(0, np.arange(3), np.zeros((3, 4)))
    for cut in (8, 40, 100, len(data) - 20):
        with pytest.raises(MalformedMessage):
            decode_cloud(data[:cut])
    cloud = decode_cloud(data)
    with pytest.raises(MalformedMessage, match="no field 'z'"):
        cloud.columns(('x', 'z'))
    no_ids = PointCloud2(height=1, width=1, point_step=8, row_step=8, data=bytes(8),
                         fields=[PointField(name='x', offset=0, datatype=8, count=1)])
    with pytest.raises(MalformedMessage, match="no integer 'id'"):
        decode_cloud(serialize_message(no_ids)).ids()


def test_clouds_become_the_per_agent_messages_byte_for_byte():
    """``replay --republish per_agent``'s codec: an oriented plant's state cloud (ids
    shuffled) and two hosts' command clouds with an adaptive state and a velocity command give
    each agent's messages as the per-agent world and agents encode them."""
    n, ns, labels = 5, 1_230_000_000, ('e[0]', 'e[1]')
    ids, state = swarm(n, len(state_fields(2, True)))
    cloud = decode_cloud(CloudEncoder(state_fields(2, True)).encode(ns, ids, state))
    names = command_fields(2, labels, velocity=True)
    split = PerAgentMessages(n, cloud.names(), (*names, 'id'))
    assert (split.oriented, split.labels, split.velocity) == (True, labels, True)
    assert list(split.topics)[:5] == ['agent_0/odom', 'agent_0/cmd_accel', 'agent_0/state',
                                      'agent_0/cmd_vel', 'agent_1/odom']
    by_id = state[np.argsort(ids)]
    assert split.states(cloud) == [
        (f'agent_{i}/odom', OdometryEncoder(f'agent_{i}', oriented=True).encode(
            ns, row[0:2], row[2:4], row[4:6], (row[6], 0.0))) for i, row in enumerate(by_id)]
    _, commands = swarm(n, len(names), seed=1)
    for host in ([3, 1], [0, 2, 4]):
        got = split.commands(decode_cloud(CloudEncoder(names).encode(ns, np.array(host),
                                                                     commands[host])))
        want = []
        for i, row in zip(host, commands[host]):
            want += [(f'agent_{i}/cmd_accel', AccelEncoder().encode(ns, row[:2])),
                     (f'agent_{i}/state', StateEncoder(labels).encode(ns, row[2:4])),
                     (f'agent_{i}/cmd_vel', encode_twist(row[4:7], row[7:]))]
        assert got == want
    with pytest.raises(MalformedMessage, match='ids not agents of'):
        split.commands(decode_cloud(CloudEncoder(names).encode(ns, np.array([n]),
                                                               commands[:1])))
