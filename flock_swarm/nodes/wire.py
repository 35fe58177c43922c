"""CDR encoding and decoding of the messages every step carries: Odometry, AccelStamped, Clock,
Twist (velocity commands of robot plants), and the agents' adaptive state (JointState).

A lockstep step moves ``N`` odometry messages to every agent host and ``N`` commands back.
Through rclpy's typed API each of them is built as nested Python message objects and
(de)serialised by the C type support: 56 us to deserialise one ``nav_msgs/Odometry`` and
23 us one ``geometry_msgs/AccelStamped`` on the project's machines, more than everything
else a step does (docs/performance.md). The nodes therefore subscribe raw (``raw=True``: the
serialised bytes) and publish bytes, and this module reads and writes the three fixed
layouts, and the state's layout fixed by its labels, with :mod:`struct` at a few microseconds
per message.

The format is the OMG CDR that rmw_fastrtps and rmw_cyclonedds put on the wire (XCDR1, as
ROS 2 Jazzy uses it): a 4-byte encapsulation header (``00 01``: little-endian, ``00 00``:
big-endian, then two option bytes), then the fields in declaration order, each aligned to its
size relative to the end of the header; a string is a ``uint32`` length counting its NUL, the
bytes, the NUL. Decoding accepts both byte orders and any frame ids (the node's
:class:`~flock_swarm.nodes.guard.InputGuard` judges those); what is not a message of the
type raises :class:`MalformedMessage`. Encoding writes little-endian with zeroed padding
(rclpy leaves its padding bytes uninitialised), so a recorded bag is byte-for-byte
reproducible. The tests check both directions against rclpy's own serialisation.
"""

import struct
from typing import Sequence

import numpy as np

from flock_swarm.contract import FRAME

#: Encapsulation header of little-endian plain CDR.
CDR_LE = b'\x00\x01\x00\x00'
#: Bytes of ``PoseWithCovariance`` (position, orientation, 6 x 6 covariance) and of
#: ``TwistWithCovariance`` (linear, angular, covariance).
POSE_BYTES = (3 + 4 + 36) * 8
TWIST_BYTES = (3 + 3 + 36) * 8
#: Bytes of ``Accel`` (linear, angular), and of ``Twist``.
ACCEL_BYTES = TWIST_VECTORS_BYTES = (3 + 3) * 8
#: Offsets in an Odometry's pose of the orientation's ``z, w`` and, from the twist, of the
#: angular velocity's ``z``: what a heading adds (:data:`ORIENTED`), read as 2-float vectors
#: (the second of the angular one is the covariance's first value, zero).
HEADING_AT = 5 * 8
YAW_RATE_AT = POSE_BYTES + 5 * 8
NS_PER_S = 1_000_000_000


class MalformedMessage(ValueError):
    """Bytes that are not a CDR-serialised message of the expected type."""


class _Layout:
    """The :class:`struct.Struct` objects of one byte order."""

    def __init__(self, order: str) -> None:
        self.order = order
        self.u32 = struct.Struct(order + 'I')
        self.time = struct.Struct(order + 'iI')
        self.vec3 = struct.Struct(order + '3d')


_ORDERS = {0: _Layout('>'), 1: _Layout('<')}
_LE = _ORDERS[1]
_VEC2_LE = struct.Struct('<2d')


def _layout(data: bytes) -> _Layout:
    """Return the layout of ``data``'s byte order (from its encapsulation header)."""
    if len(data) < 12 or data[0] != 0 or data[1] not in _ORDERS:
        raise MalformedMessage('not plain CDR (encapsulation header)')
    return _ORDERS[data[1]]


def _align(offset: int, size: int) -> int:
    """Return ``offset`` (in the buffer) aligned to ``size`` relative to the CDR payload."""
    return 4 + ((offset - 4 + size - 1) & -size)


def _string(data: bytes, offset: int, lay: _Layout) -> tuple[str, int]:
    """Return the string at ``offset`` (4-aligned) and the offset just after it."""
    if offset + 4 > len(data):
        raise MalformedMessage('truncated before a string')
    (size,) = lay.u32.unpack_from(data, offset)
    end = offset + 4 + size
    if size == 0 or end > len(data) or data[end - 1] != 0:
        raise MalformedMessage('a string without its terminating NUL')
    try:
        return data[offset + 4:end - 1].decode(), end
    except UnicodeDecodeError:
        raise MalformedMessage('a string that is not UTF-8') from None


def _header(data: bytes, lay: _Layout) -> tuple[int, str, int]:
    """Return ``(stamp_ns, frame_id, offset after the header)`` of a ``std_msgs/Header``."""
    sec, nanosec = lay.time.unpack_from(data, 4)
    frame, end = _string(data, 12, lay)
    return sec * NS_PER_S + nanosec, frame, end


def _need(data: bytes, end: int, what: str) -> None:
    if len(data) < end:
        raise MalformedMessage(f'truncated {what} ({len(data)} bytes, need {end})')


def decode_odometry(data: bytes) -> tuple[int, str, str, tuple, tuple]:
    """Return ``(stamp_ns, frame_id, child_frame_id, position, linear velocity)`` of a
    serialised ``nav_msgs/Odometry`` (``position``, ``velocity``: 3 floats).

    :raises MalformedMessage: when ``data`` is not one.
    """
    lay, ns, frame, child, pose = _odometry(data)
    return (ns, frame, child, lay.vec3.unpack_from(data, pose),
            lay.vec3.unpack_from(data, pose + POSE_BYTES))


def decode_odometry_state(data: bytes) -> tuple[int, tuple[float, ...]]:
    """Return ``(stamp_ns, values)`` of a serialised ``nav_msgs/Odometry``: its 13 values
    position, linear velocity, orientation (x, y, z, w), angular velocity (what ``analyze``
    rebuilds a step of a plant from, in microseconds instead of rclpy's object tree).

    :raises MalformedMessage: when ``data`` is not one.
    """
    lay, ns, _, _, pose = _odometry(data)
    vec3 = lay.vec3
    return ns, (vec3.unpack_from(data, pose) + vec3.unpack_from(data, pose + POSE_BYTES)
                + struct.unpack_from(lay.order + '4d', data, pose + 24)
                + vec3.unpack_from(data, pose + POSE_BYTES + 24))


def _odometry(data: bytes) -> tuple[_Layout, int, str, str, int]:
    """Return ``(layout, stamp_ns, frame_id, child_frame_id, offset of the pose)`` of a
    serialised ``nav_msgs/Odometry``, checked long enough for its pose and twist."""
    lay = _layout(data)
    ns, frame, end = _header(data, lay)
    child, end = _string(data, _align(end, 4), lay)
    pose = _align(end, 8)
    _need(data, pose + POSE_BYTES + TWIST_BYTES, 'Odometry')
    return lay, ns, frame, child, pose


def decode_heading(data: bytes) -> tuple[tuple, tuple]:
    """Return ``((qz, qw), (yaw rate, 0))`` of a serialised ``nav_msgs/Odometry``: what the
    odometry of an oriented plant adds to :func:`decode_odometry`'s (see :data:`HEADING_AT`).

    :raises MalformedMessage: when ``data`` is not one.
    """
    lay, _, _, _, pose = _odometry(data)
    heading = lay.vec3.unpack_from(data, pose + HEADING_AT)[:2]
    return heading, (lay.vec3.unpack_from(data, pose + YAW_RATE_AT)[0], 0.0)


def decode_twist(data: bytes) -> tuple[tuple, tuple]:
    """Return ``(linear, angular)`` (3 floats each) of a serialised ``geometry_msgs/Twist``.

    :raises MalformedMessage: when ``data`` is not one.
    """
    lay = _layout(data)
    _need(data, 4 + TWIST_VECTORS_BYTES, 'Twist')
    return lay.vec3.unpack_from(data, 4), lay.vec3.unpack_from(data, 28)


def encode_twist(linear: Sequence[float], angular: Sequence[float]) -> bytes:
    """Return a serialised ``geometry_msgs/Twist`` (3 floats each)."""
    return CDR_LE + _LE.vec3.pack(*linear) + _LE.vec3.pack(*angular)


def decode_accel(data: bytes) -> tuple[int, str, tuple]:
    """Return ``(stamp_ns, frame_id, linear acceleration)`` of a serialised
    ``geometry_msgs/AccelStamped``.

    :raises MalformedMessage: when ``data`` is not one.
    """
    lay = _layout(data)
    ns, frame, end = _header(data, lay)
    accel = _align(end, 8)
    _need(data, accel + ACCEL_BYTES, 'AccelStamped')
    return ns, frame, lay.vec3.unpack_from(data, accel)


def decode_state(data: bytes) -> tuple[int, str, tuple[str, ...], tuple[float, ...]]:
    """Return ``(stamp_ns, frame_id, names, positions)`` of a serialised
    ``sensor_msgs/JointState``: an agent's adaptive state (labels, values), see
    :data:`flock_swarm.contract.STATE_TYPE`. Its ``velocity`` and ``effort`` are not read.

    :raises MalformedMessage: when ``data`` is not one.
    """
    lay = _layout(data)
    ns, frame, end = _header(data, lay)
    count_at = _align(end, 4)
    _need(data, count_at + 4, 'JointState')
    (count,) = lay.u32.unpack_from(data, count_at)
    names, end = [], count_at + 4
    # Each name takes 5 bytes at least: a count larger than the bytes left is no message.
    if count > len(data) - end:
        raise MalformedMessage(f'a JointState of {count} names in {len(data)} bytes')
    for _ in range(count):
        name, end = _string(data, _align(end, 4), lay)
        names.append(name)
    count_at = _align(end, 4)
    _need(data, count_at + 4, 'JointState')
    (count,) = lay.u32.unpack_from(data, count_at)
    values = _align(count_at + 4, 8) if count else count_at + 4
    # The values, then at least the counts of velocity and effort.
    _need(data, values + 8 * count + 8, 'JointState')
    positions = struct.unpack_from(f'{lay.order}{count}d', data, values)
    return ns, frame, tuple(names), positions


def decode_clock(data: bytes) -> int:
    """Return the time [ns] of a serialised ``rosgraph_msgs/Clock``.

    :raises MalformedMessage: when ``data`` is not one.
    """
    sec, nanosec = _layout(data).time.unpack_from(data, 4)
    return sec * NS_PER_S + nanosec


def encode_clock(ns: int) -> bytes:
    """Return a serialised ``rosgraph_msgs/Clock`` of time ``ns`` (>= 0)."""
    return CDR_LE + _LE.time.pack(*divmod(ns, NS_PER_S))


def _put_string(buf: bytearray, text: str) -> None:
    """Append a CDR string to ``buf`` (4-aligned first)."""
    raw = text.encode() + b'\0'
    buf.extend(bytes(_align(len(buf), 4) - len(buf)))
    buf.extend(_LE.u32.pack(len(raw)) + raw)


class _Encoder:
    """A message's bytes kept as a template; each call overwrites the stamp and the vectors.

    :ivar vectors: buffer offsets of the 3-float vectors :meth:`encode` writes.
    """

    def __init__(self, strings: Sequence[str], body: int, vectors: Sequence[int],
                 constants: Sequence[tuple[int, float]] = ()) -> None:
        buf = bytearray(CDR_LE + bytes(8))
        for text in strings:
            _put_string(buf, text)
        start = _align(len(buf), 8)
        buf.extend(bytes(start - len(buf) + body))
        for offset, value in constants:
            struct.pack_into('<d', buf, start + offset, value)
        self.buf = buf
        self.vectors = [start + v for v in vectors]

    def encode(self, ns: int, *vectors: Sequence[float]) -> bytes:
        """Return the message stamped ``ns`` [ns] with the vectors (2 or 3 floats; 2-D: z
        stays 0)."""
        buf = self.buf
        _LE.time.pack_into(buf, 4, *divmod(ns, NS_PER_S))
        for offset, v in zip(self.vectors, vectors):
            (_VEC2_LE if len(v) == 2 else _LE.vec3).pack_into(buf, offset, *v)
        return bytes(buf)


class OdometryEncoder(_Encoder):
    """Serialised ``nav_msgs/Odometry`` in frame ``world`` for one ``child_frame_id``:
    ``encode(ns, position, velocity)`` (identity orientation, zero covariances); when
    ``oriented``, ``encode(ns, position, velocity, (qz, qw), (yaw rate, 0))``."""

    def __init__(self, child: str, frame: str = FRAME, oriented: bool = False) -> None:
        """Create the encoder of ``child``'s odometry."""
        # Quaternion (x, y, z, w) follows the position: w = 1, rclpy's default.
        super().__init__((frame, child), POSE_BYTES + TWIST_BYTES,
                         (0, POSE_BYTES) + ((HEADING_AT, YAW_RATE_AT) if oriented else ()),
                         constants=((6 * 8, 1.0),))


class AccelEncoder(_Encoder):
    """Serialised ``geometry_msgs/AccelStamped`` in frame ``world``: ``encode(ns, linear)``."""

    def __init__(self, frame: str = FRAME) -> None:
        """Create the encoder."""
        super().__init__((frame,), ACCEL_BYTES, (0,))


class StateEncoder:
    """Serialised ``sensor_msgs/JointState`` of one agent's adaptive state in frame ``world``:
    ``encode(ns, values)``, the labels fixed (:func:`flock_swarm.contract.state_labels`),
    the values in ``position``, ``velocity`` and ``effort`` empty."""

    def __init__(self, labels: Sequence[str], frame: str = FRAME) -> None:
        """Create the encoder of a state labelled ``labels``."""
        buf = bytearray(CDR_LE + bytes(8))
        _put_string(buf, frame)
        buf.extend(bytes(_align(len(buf), 4) - len(buf)))
        buf.extend(_LE.u32.pack(len(labels)))
        for label in labels:
            _put_string(buf, label)
        buf.extend(bytes(_align(len(buf), 4) - len(buf)))
        buf.extend(_LE.u32.pack(len(labels)))
        if labels:
            buf.extend(bytes(_align(len(buf), 8) - len(buf)))
        self.values_at = len(buf)
        # The values, then the empty velocity and effort sequences (a count each).
        buf.extend(bytes(8 * len(labels)) + _LE.u32.pack(0) + _LE.u32.pack(0))
        self.buf = buf
        self.values = struct.Struct(f'<{len(labels)}d')

    def encode(self, ns: int, values: Sequence[float]) -> bytes:
        """Return the state stamped ``ns`` [ns] with ``values`` (one per label)."""
        buf = self.buf
        _LE.time.pack_into(buf, 4, *divmod(ns, NS_PER_S))
        self.values.pack_into(buf, self.values_at, *values)
        return bytes(buf)


class _MessageBatch:
    """A step's messages of one fixed layout per sender, decoded at once.

    The buffers are joined and read with one gather of NumPy indices: the bytes that must be
    those of the header's byte order and the ids, the stamps, and the vectors. Anything else
    (another length or byte order, another id, a duplicate or a missing sender) makes
    :meth:`decode` return ``None``, and the caller takes the messages one by one, which
    judges them.
    """

    def __init__(self, layouts: Sequence[tuple[bytes, Sequence[tuple[int, int]], Sequence[int]]]
                 ) -> None:
        """Prepare the indices from each sender's ``(template, fixed byte ranges, offsets of
        its 3-float vectors)``, sender ``j`` at index ``j``."""
        fixed, expected, stamps, vectors, lengths, start = [], [], [], [], [], 0
        for buf, ranges, offsets in layouts:
            for lo, hi in ranges:
                fixed.extend(range(start + lo, start + hi))
                expected.extend(buf[lo:hi])
            stamps.extend(range(start + 4, start + 12))
            for at in offsets:
                vectors.extend(range(start + at, start + at + 24))
            lengths.append(len(buf))
            start += len(buf)
        self.n = len(layouts)
        self.per_message = len(layouts[0][2]) if layouts else 0
        self.lengths = lengths
        self.fixed = np.array(fixed, dtype=np.intp)
        self.expected = np.array(expected, dtype=np.uint8)
        self.stamps = np.array(stamps, dtype=np.intp)
        self.vectors = np.array(vectors, dtype=np.intp)

    def decode(self, buffers: Sequence[bytes | None]) -> tuple[int, np.ndarray] | None:
        """Return ``(stamp_ns, vectors)`` of ``buffers`` (sender ``j``'s message at index
        ``j``), ``vectors`` of shape ``(N, vectors per message, 3)``, or ``None`` when they
        are not one stamp's messages of the expected layouts."""
        if len(buffers) != self.n or None in buffers \
                or list(map(len, buffers)) != self.lengths:
            return None
        raw = np.frombuffer(b''.join(buffers), dtype=np.uint8)
        if not np.array_equal(raw[self.fixed], self.expected):
            return None
        stamps = raw[self.stamps].view(_STAMP_LE)
        if not (stamps == stamps[0]).all():
            return None
        ns = int(stamps[0]['sec']) * NS_PER_S + int(stamps[0]['nanosec'])
        return ns, raw[self.vectors].view('<f8').reshape(self.n, self.per_message, 3)


def _strings_end(frame: str) -> int:
    """Return the offset just after a little-endian header's ``frame_id``."""
    return 12 + 4 + len(frame) + 1


class OdometryBatch(_MessageBatch):
    """A step's odometry of every agent decoded at once, when it has the layout the world
    writes (:class:`OdometryEncoder`: little-endian, frame ``world``, child ``agent_<j>``):
    :meth:`decode` gives the states, shape ``(N, 2, 3)`` (positions, velocities)."""

    def __init__(self, children: Sequence[str], frame: str = FRAME,
                 oriented: bool = False) -> None:
        """Prepare the indices for the agents ``children`` (``agent_<j>`` at index ``j``);
        ``oriented``: :meth:`decode` gives ``(N, 4, 3)``, the heading's vectors after the
        velocity (:data:`HEADING_AT`)."""
        extra = (HEADING_AT, YAW_RATE_AT) if oriented else ()
        layouts = []
        for child in children:
            strings = _strings_end(frame)
            child_at = _align(strings, 4)
            pose = _align(child_at + 4 + len(child) + 1, 8)
            # Header byte order and the two strings (their length fields included); the
            # padding between them is not checked (rclpy leaves it uninitialised).
            layouts.append((bytes(OdometryEncoder(child, frame).buf),
                            ((0, 2), (12, strings), (child_at, child_at + 4 + len(child) + 1)),
                            (pose, pose + POSE_BYTES, *(pose + at for at in extra))))
        super().__init__(layouts)


class AccelBatch(_MessageBatch):
    """A step's commands of ``n`` agents decoded at once, when they have the layout the
    agents write (:class:`AccelEncoder`: little-endian, frame ``world``): :meth:`decode`
    gives the linear accelerations, shape ``(n, 1, 3)``."""

    def __init__(self, n: int, frame: str = FRAME) -> None:
        """Prepare the indices for ``n`` agents (agent ``i``'s command at index ``i``)."""
        strings = _strings_end(frame)
        layout = (bytes(AccelEncoder(frame).buf), ((0, 2), (12, strings)),
                  (_align(strings, 8),))
        super().__init__([layout] * n)


class OdometryBatchEncoder:
    """Every agent's odometry of a step encoded at once: byte for byte the messages of an
    :class:`OdometryEncoder` per child, from one template of the step's buffers joined, into
    which the stamps and the vectors are written with one NumPy scatter each."""

    def __init__(self, children: Sequence[str], frame: str = FRAME,
                 oriented: bool = False) -> None:
        """Prepare the template of the agents ``children`` (agent ``j``'s message at ``j``);
        ``oriented``: :meth:`encode` takes the heading's vectors too."""
        encoders = [OdometryEncoder(child, frame, oriented) for child in children]
        joined = b''.join(bytes(enc.buf) for enc in encoders)
        self.template = np.frombuffer(joined, dtype=np.uint8).copy()
        starts = np.cumsum([0] + [len(enc.buf) for enc in encoders])
        self.bounds = list(zip(starts[:-1].tolist(), starts[1:].tolist()))
        self.stamps = starts[:-1, None] + np.arange(4, 12)
        # Buffer offsets of each message's position and velocity vectors.
        self.vectors = np.array([enc.vectors for enc in encoders], dtype=np.intp) \
            + starts[:-1, None]
        self._scatter: dict[int, np.ndarray] = {}

    def encode(self, ns: int, q: np.ndarray, p: np.ndarray, *heading: np.ndarray) -> list[bytes]:
        """Return every agent's message stamped ``ns`` [ns] with positions ``q`` and
        velocities ``p`` (``(N, dim)``, dim 2 or 3; 2-D: z stays 0); an oriented encoder
        takes ``(qz, qw)`` and ``(yaw rate, 0)`` rows too (``(N, 2)`` each, 2-D)."""
        dim = q.shape[1]
        scatter = self._scatter.get(dim)
        if scatter is None:
            # Bytes of (position, velocity[, heading, yaw rate]), dim doubles each, in the
            # order of np.stack((q, p, ...), axis=1).
            scatter = self._scatter[dim] = (self.vectors[:, :, None]
                                            + np.arange(8 * dim)).reshape(len(q), -1)
        buf = self.template
        buf[self.stamps] = np.frombuffer(_LE.time.pack(*divmod(ns, NS_PER_S)), dtype=np.uint8)
        buf[scatter] = np.stack((q, p, *heading), axis=1).astype('<f8').view(np.uint8) \
            .reshape(len(q), -1)
        blob = buf.tobytes()
        return [blob[lo:hi] for lo, hi in self.bounds]


class AccelBatchEncoder:
    """Every hosted agent's command of a step encoded at once: byte for byte an
    :class:`AccelEncoder`'s message per row (the same frame), from one template of ``n``
    messages into which the stamps and the vectors are written with one NumPy scatter each."""

    def __init__(self, n: int, frame: str = FRAME) -> None:
        """Prepare the template of ``n`` commands."""
        one = AccelEncoder(frame)
        size = len(one.buf)
        self.n = n
        self.template = np.tile(np.frombuffer(bytes(one.buf), dtype=np.uint8), n)
        starts = np.arange(n, dtype=np.intp) * size
        self.bounds = list(zip(starts.tolist(), (starts + size).tolist()))
        self.stamps = starts[:, None] + np.arange(4, 12)
        self.linear = starts + one.vectors[0]
        self._scatter: dict[int, np.ndarray] = {}

    def encode(self, ns: int, linear: np.ndarray) -> list[bytes]:
        """Return row ``j``'s command stamped ``ns`` [ns] with ``linear[j]`` (``(n, dim)``,
        dim 2 or 3; 2-D: z stays 0)."""
        dim = linear.shape[1]
        scatter = self._scatter.get(dim)
        if scatter is None:
            scatter = self._scatter[dim] = self.linear[:, None] + np.arange(8 * dim)
        buf = self.template
        buf[self.stamps] = np.frombuffer(_LE.time.pack(*divmod(ns, NS_PER_S)), dtype=np.uint8)
        buf[scatter] = np.ascontiguousarray(linear, dtype='<f8').view(np.uint8) \
            .reshape(self.n, 8 * dim)
        blob = buf.tobytes()
        return [blob[lo:hi] for lo, hi in self.bounds]


#: ``builtin_interfaces/Time`` in little-endian CDR.
_STAMP_LE = np.dtype([('sec', '<i4'), ('nanosec', '<u4')])


class CdrWriter:
    """Little-endian plain CDR, written field by field (for :mod:`flock_swarm.nodes.markers`).

    Arrays of points or colours go in with one ``tobytes`` each, which is what makes a
    ``MarkerArray`` of a hundred agents and their links cheap to build (its rclpy message
    objects cost about 20 ms every tenth step at N = 100).
    """

    def __init__(self) -> None:
        """Start a message: the encapsulation header."""
        self.buf = bytearray(CDR_LE)

    def align(self, size: int) -> None:
        """Pad with zeros to a multiple of ``size`` from the payload's start."""
        self.buf.extend(bytes(_align(len(self.buf), size) - len(self.buf)))

    def pack(self, fmt: str, *values, size: int) -> None:
        """Append ``values`` packed little-endian by ``fmt``, aligned to ``size`` first."""
        self.align(size)
        self.buf.extend(struct.pack('<' + fmt, *values))

    def string(self, text: str) -> None:
        """Append a string."""
        _put_string(self.buf, text)

    def time(self, ns: int) -> None:
        """Append a ``builtin_interfaces/Time`` (or ``Duration``) of ``ns`` [ns]."""
        self.pack('iI', *divmod(ns, NS_PER_S), size=4)

    def sequence(self, rows, size: int) -> None:
        """Append a sequence of fixed-size structs given as a C-contiguous array (a row each),
        its elements aligned to ``size``."""
        self.pack('I', len(rows), size=4)
        if len(rows):
            self.align(size)
            self.buf.extend(rows.tobytes())

    def getvalue(self) -> bytes:
        """Return the message."""
        return bytes(self.buf)


def odometry_rows(plant, x: np.ndarray, dim: int) -> list[np.ndarray]:
    """Return the vectors the odometry of plant states ``x`` carries, ``(N, dim)`` each:
    position and velocity, and for an oriented plant ``(qz, qw)`` and ``(yaw rate, 0)``
    (:class:`OdometryBatchEncoder`'s order; :meth:`~flock_swarm.core.plants.base.Plant.odometry`
    says what they are).

    :param plant: the plant model.
    :param x: the states ``(N, S)``.
    :param dim: the scenario's dimension (2 for an oriented plant).
    """
    position, orientation, linear, angular = plant.odometry(x)
    rows = [position[:, :dim], linear[:, :dim]]
    if plant.oriented:
        rows += [orientation[:, 2:4], np.column_stack([angular[:, 2], np.zeros(len(x))])]
    return rows


def plant_states(plant, rows: np.ndarray, dim: int) -> np.ndarray:
    """Return the plant states of decoded odometry vectors: :func:`odometry_rows`' inverse.

    :param plant: the plant model.
    :param rows: ``(N, 2 or 4, dim)``: position, velocity[, (qz, qw), (yaw rate, 0)].
    :param dim: the scenario's dimension.
    """
    n = rows.shape[0]
    position, linear = np.zeros((n, 3)), np.zeros((n, 3))
    position[:, :dim], linear[:, :dim] = rows[:, 0], rows[:, 1]
    orientation, angular = np.zeros((n, 4)), np.zeros((n, 3))
    if plant.oriented:
        orientation[:, 2:4], angular[:, 2] = rows[:, 2], rows[:, 3, 0]
    else:
        orientation[:, 3] = 1.0
    return plant.from_odometry(position, orientation, linear, angular, dim)
