"""The batched transport's codec: a whole swarm's state, or a host's commands, as one
``sensor_msgs/PointCloud2`` (``transport: batched``, docs/ros.md "Transports").

With ``transport: per_agent`` (the default) a lockstep step carries ``N`` odometry messages
to every agents host and ``N`` commands back; at ``N = 1000`` DDS's per-message write and
delivery bound the run (docs/performance.md). The batched transport carries the same
numbers in one message each way: the world's state cloud (:data:`STATES`, one point per
agent: ``x y [z] vx vy [vz]``, an oriented plant's heading ``qz qw wz``, then ``id``) and
each agents host's command cloud (:data:`COMMANDS`, one point per hosted agent: ``ax ay
[az]``, a law's adaptive state under its labels, a robot plant's velocity command ``vx vy vz
wx wy wz``, then ``id``). The type is a standard one,
so ``ros2 topic echo``, rosbags and Foxglove decode it without this package, and Foxglove
and RViz draw the state cloud as points at the agents' positions.

The values are ``FLOAT64`` (the numbers are those of the per-agent messages bit for bit)
and ``id`` a ``UINT32``; a point's fields are packed without padding, the floats first in
the order above. The data field is written and read as one NumPy array: no per-agent Python
work. Decoding accepts any field order, offsets, byte order and ``FLOAT32``/integer fields
(a cloud from another tool); what is not a PointCloud2 raises
:class:`~flock_swarm.nodes.wire.MalformedMessage`. No rclpy.
"""

from dataclasses import dataclass
import struct
from typing import Sequence

import numpy as np

from flock_swarm.contract import (ACCEL_TYPE, CLOUD_TYPE, COMMANDS, FRAME, ODOMETRY_TYPE,
                                  STATE_TYPE, STATES, TWIST_TYPE, agent_name, cmd_topic,
                                  cmd_vel_topic, odom_topic, state_topic)
from flock_swarm.core.scenario import TRANSPORTS
from flock_swarm.nodes.wire import (CDR_LE, NS_PER_S, AccelEncoder, MalformedMessage,
                                    OdometryBatchEncoder, StateEncoder, _align, _header,
                                    _layout, _put_string, encode_twist)

#: The topics and their type (:mod:`flock_swarm.contract`), here for the codec's users.
__all__ = ['CLOUD_TYPE', 'COMMANDS', 'STATES', 'TRANSPORTS', 'PER_AGENT', 'BATCHED',
           'CloudEncoder', 'Cloud', 'decode_cloud', 'state_fields', 'command_fields',
           'PerAgentMessages']
#: The transports (the scenario's ``transport`` key, the nodes' ``transport`` parameter).
PER_AGENT, BATCHED = TRANSPORTS
#: The field holding an agent's id.
ID = 'id'
#: ``sensor_msgs/PointField`` datatypes and their NumPy types (little-endian).
_DATATYPES = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}
UINT32, FLOAT64 = 6, 8
#: An oriented plant's heading fields (the odometry's orientation ``z, w`` and yaw rate).
HEADING_FIELDS = ('qz', 'qw', 'wz')


def state_fields(dim: int, oriented: bool = False) -> tuple[str, ...]:
    """Return the float fields of the state cloud: position, velocity[, heading].

    :param dim: the scenario's dimension (2 or 3).
    :param oriented: the plant has a heading (then ``dim`` is 2).
    """
    axes = 'xyz'[:dim]
    return (*axes, *(f'v{a}' for a in axes), *(HEADING_FIELDS if oriented else ()))


#: A robot plant's velocity command (``cmd_vel``): the Twist's linear and angular vectors.
TWIST_FIELDS = ('vx', 'vy', 'vz', 'wx', 'wy', 'wz')


def command_fields(dim: int, state_labels: Sequence[str] = (),
                   velocity: bool = False) -> tuple[str, ...]:
    """Return the float fields of a command cloud: the acceleration, then a law's adaptive
    state under its labels (:func:`flock_swarm.contract.state_labels`), then for a robot
    plant commanded by velocity its Twist (:data:`TWIST_FIELDS`)."""
    return (*(f'a{a}' for a in 'xyz'[:dim]), *state_labels,
            *(TWIST_FIELDS if velocity else ()))


class CloudEncoder:
    """Serialised ``sensor_msgs/PointCloud2`` of float fields and ``id``:
    ``encode(ns, ids, values)``, one point per row, frame ``world`` (height 1, dense)."""

    def __init__(self, fields: Sequence[str], frame: str = FRAME) -> None:
        """Create the encoder of the float ``fields`` (``id`` follows them)."""
        self.fields = tuple(fields)
        self.width = 8 * len(self.fields)
        self.point_step = self.width + 4
        head = bytearray(CDR_LE + bytes(8))
        _put_string(head, frame)
        # height, then width at self.width_at.
        head.extend(bytes(_align(len(head), 4) - len(head)) + struct.pack('<I', 1))
        self.width_at = len(head)
        head.extend(bytes(4))
        head.extend(struct.pack('<I', len(self.fields) + 1))
        named = [(name, FLOAT64) for name in self.fields] + [(ID, UINT32)]
        for offset, (name, datatype) in enumerate(named):
            # A PointField: name, offset, datatype (a byte), count.
            head.extend(bytes(_align(len(head), 4) - len(head)))
            _put_string(head, name)
            head.extend(bytes(_align(len(head), 4) - len(head)))
            head.extend(struct.pack('<IB', 8 * offset, datatype))
            head.extend(bytes(_align(len(head), 4) - len(head)))
            head.extend(struct.pack('<I', 1))
        whole = head
        # is_bigendian, point_step, row_step (at row_at), the data's length (at row_at + 4).
        whole.extend(b'\x00')
        whole.extend(bytes(_align(len(whole), 4) - len(whole)))
        whole.extend(struct.pack('<I', self.point_step))
        self.row_at = len(whole)
        whole.extend(bytes(8))
        self.head = whole

    def encode(self, ns: int, ids: np.ndarray, values: np.ndarray) -> bytes:
        """Return the cloud stamped ``ns`` [ns] of the points ``values`` (``(n, fields)``)
        with ids ``ids`` (``n``)."""
        n = len(ids)
        head = self.head
        struct.pack_into('<iI', head, 4, *divmod(ns, NS_PER_S))
        struct.pack_into('<I', head, self.width_at, n)
        size = n * self.point_step
        struct.pack_into('<II', head, self.row_at, size, size)
        points = np.empty((n, self.point_step), dtype=np.uint8)
        points[:, :self.width] = np.ascontiguousarray(values, dtype='<f8') \
            .view(np.uint8).reshape(n, self.width)
        points[:, self.width:] = np.ascontiguousarray(ids, dtype='<u4') \
            .view(np.uint8).reshape(n, 4)
        # The data, then is_dense.
        return b''.join((head, points.data, b'\x01'))


@dataclass
class Cloud:
    """A decoded ``PointCloud2``: stamp, frame and its points.

    :ivar stamp_ns: ``header.stamp`` [ns].
    :ivar frame_id: ``header.frame_id``.
    :ivar points: the points as a NumPy structured array (one field per PointField).
    """

    stamp_ns: int
    frame_id: str
    points: np.ndarray

    def names(self) -> tuple[str, ...]:
        """Return the cloud's field names."""
        return self.points.dtype.names or ()

    def ids(self) -> np.ndarray:
        """Return the points' ids (``int64``).

        :raises MalformedMessage: without an integer ``id`` field.
        """
        if ID not in self.names() or self.points.dtype[ID].kind not in 'iu':
            raise MalformedMessage(f'no integer {ID!r} field')
        return self.points[ID].astype(np.int64)

    def columns(self, names: Sequence[str]) -> np.ndarray:
        """Return the fields ``names`` as floats, shape ``(n, len(names))``.

        :raises MalformedMessage: when one of them is missing.
        """
        missing = [name for name in names if name not in self.names()]
        if missing:
            raise MalformedMessage(f'no field {missing[0]!r} (fields {list(self.names())})')
        out = np.empty((len(self.points), len(names)))
        for j, name in enumerate(names):
            out[:, j] = self.points[name]
        return out


def decode_cloud(data: bytes) -> Cloud:
    """Return the :class:`Cloud` of a serialised ``sensor_msgs/PointCloud2``.

    :raises MalformedMessage: when ``data`` is not one (or its fields do not fit its points).
    """
    lay = _layout(data)
    ns, frame, end = _header(data, lay)
    try:
        at = _align(end, 4)
        height, width, count = struct.unpack_from(lay.order + '3I', data, at)
        at += 12
        if count > 4096:
            raise MalformedMessage(f'{count} fields')
        names, formats, offsets = [], [], []
        for _ in range(count):
            at = _align(at, 4)
            (size,) = lay.u32.unpack_from(data, at)
            name = data[at + 4:at + 3 + size].decode()
            at = _align(at + 4 + size, 4)
            offset, datatype = struct.unpack_from(lay.order + 'IB', data, at)
            at = _align(at + 5, 4)
            (many,) = lay.u32.unpack_from(data, at)
            at += 4
            if datatype not in _DATATYPES or many != 1:
                raise MalformedMessage(f'field {name!r}: datatype {datatype} count {many}')
            names.append(name)
            offsets.append(offset)
            formats.append(_DATATYPES[datatype])
        bigendian = data[at]
        at = _align(at + 1, 4)
        point_step, row_step, size = struct.unpack_from(lay.order + '3I', data, at)
        at += 12
    except (struct.error, IndexError, UnicodeDecodeError) as exc:
        raise MalformedMessage(f'truncated or garbled PointCloud2 ({exc})') from None
    n = height * width
    if len(set(names)) != len(names):
        raise MalformedMessage(f'a field named twice: {names}')
    order = '>' if bigendian else '<'
    try:
        dtype = np.dtype({'names': names, 'formats': [order + f for f in formats],
                          'offsets': offsets, 'itemsize': point_step})
    except ValueError as exc:
        raise MalformedMessage(f'fields that do not fit a point of {point_step} bytes ({exc})') \
            from None
    if size < n * point_step or at + size > len(data) or row_step * height > size:
        raise MalformedMessage(f'data of {size} bytes for {n} points of {point_step}')
    points = np.frombuffer(data, dtype=dtype, count=n, offset=at)
    return Cloud(ns, frame, points)


class PerAgentMessages:
    """The per-agent transport's messages of the batched transport's clouds (``replay
    --republish per_agent``): a state cloud as every agent's ``agent_<i>/odom``, a command
    cloud as its agents' ``agent_<i>/cmd_accel`` (and ``agent_<i>/state``, ``agent_<i>/cmd_vel``
    when it carries them), byte for byte what the per-agent world and agents publish: the same
    encoders (:mod:`flock_swarm.nodes.wire`), stamped with the cloud's stamp.

    :ivar topics: the per-agent topics (relative), in the per-agent bag's order, and their
        types.
    """

    def __init__(self, n_agents: int, state_names: Sequence[str],
                 command_names: Sequence[str]) -> None:
        """Prepare for ``n_agents`` agents, given the field names of a state cloud and of a
        command cloud (``()``: the bag has none)."""
        dim = sum(axis in state_names for axis in 'xyz')
        self.n, self.oriented = n_agents, 'qz' in state_names
        self.state = state_fields(dim, self.oriented)
        self.accel = command_fields(dim)
        self.velocity = bool(command_names) and all(f in command_names for f in TWIST_FIELDS)
        skip = {*self.accel, ID, *(TWIST_FIELDS if self.velocity else ())}
        self.labels = tuple(name for name in command_names if name not in skip)
        self.odometry = OdometryBatchEncoder([agent_name(i) for i in range(n_agents)],
                                             oriented=self.oriented)
        self.accel_encoder = AccelEncoder()
        self.state_encoder = StateEncoder(self.labels) if self.labels else None
        self.topics: dict[str, str] = {}
        for i in range(n_agents):
            if state_names:
                self.topics[odom_topic(i)] = ODOMETRY_TYPE
            if command_names:
                self.topics[cmd_topic(i)] = ACCEL_TYPE
                if self.labels:
                    self.topics[state_topic(i)] = STATE_TYPE
                if self.velocity:
                    self.topics[cmd_vel_topic(i)] = TWIST_TYPE

    def states(self, cloud: Cloud) -> list[tuple[str, bytes]]:
        """Return ``(topic, odometry)`` of every agent of a state cloud.

        :raises MalformedMessage: when it lacks a field or is not one point per agent.
        """
        values, ids = cloud.columns(self.state), cloud.ids()
        if len(ids) != self.n or not np.array_equal(np.sort(ids), np.arange(self.n)):
            raise MalformedMessage(f'{len(ids)} points, not one of each of the {self.n} agents')
        values = values[np.argsort(ids)]
        dim = len(self.accel)
        rows = [values[:, :dim], values[:, dim:2 * dim]]
        if self.oriented:
            rows += [values[:, 2 * dim:2 * dim + 2],
                     np.column_stack([values[:, 2 * dim + 2], np.zeros(self.n)])]
        messages = self.odometry.encode(cloud.stamp_ns, *rows)
        return [(odom_topic(i), data) for i, data in enumerate(messages)]

    def commands(self, cloud: Cloud) -> list[tuple[str, bytes]]:
        """Return ``(topic, message)`` of each command, adaptive state and velocity command
        of a host's command cloud, agent by agent.

        :raises MalformedMessage: when it lacks a field or names an agent out of range.
        """
        ids = cloud.ids()
        if len(ids) and (ids.min() < 0 or ids.max() >= self.n):
            raise MalformedMessage(f'ids not agents of [0, {self.n - 1}]: {ids[:8].tolist()}')
        ns, u = cloud.stamp_ns, cloud.columns(self.accel)
        state = cloud.columns(self.labels) if self.labels else None
        twist = cloud.columns(TWIST_FIELDS) if self.velocity else None
        out = []
        for j, i in enumerate(ids.tolist()):
            out.append((cmd_topic(i), self.accel_encoder.encode(ns, u[j])))
            if state is not None:
                out.append((state_topic(i), self.state_encoder.encode(ns, state[j])))
            if twist is not None:
                out.append((cmd_vel_topic(i), encode_twist(twist[j, :3], twist[j, 3:])))
        return out
