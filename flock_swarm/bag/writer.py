"""Write rosbag2-compatible MCAP bags (ROS 2 Jazzy) without rosbag2_py.

A bag is a directory ``NAME/`` holding ``NAME_0.mcap`` (``NAME_1.mcap``, ... when the bag is
split) and, once the writer is closed, ``metadata.yaml``; ``ros2 bag info/play``, Foxglove,
``mcap`` and ``rosbags`` read it. The layout follows rosbag2's MCAP storage plugin
(``rosbag2_storage_mcap``) and ``rosbag2_cpp::SequentialWriter``:

- MCAP header profile ``ros2``;
- one schema per message type, named ``pkg/msg/Type``, encoding ``ros2msg``, data the full
  definition text (:mod:`flock_swarm.bag.msgdefs`);
- one channel per topic, message encoding ``cdr``, channel metadata ``offered_qos_profiles``
  (QoS YAML, metadata version 9) and ``topic_type_hash`` (``RIHS01_...``);
- messages serialised as rclpy does, padding zeroed (:func:`serialize`), ``log_time`` =
  ``publish_time`` = the given stamp;
- an MCAP metadata record ``rosbag2`` (``serialized_metadata``: the bag metadata as YAML),
  written when the bag opens and again when each file closes, as rosbag2's
  ``update_metadata`` does;
- ``metadata.yaml`` (``rosbag2_bagfile_information`` version 9) written on close, listing
  every file in ``relative_file_paths`` and ``files``;
- split like rosbag2's ``max_bagfile_size`` / ``max_bagfile_duration``: before a message is
  written, the open file is finished and the next one started when the file is larger than
  the size limit or the message is later than the duration limit after the file's first
  message. Every file is a complete MCAP file with all schemas and channels.

Messages are grouped in compressed chunks of about ``chunk_size`` bytes, and each finished chunk
goes to the file at once: a process killed while recording leaves an MCAP whose complete chunks
:class:`~flock_swarm.bag.reader.BagReader` recovers (at most one chunk is lost).
"""

from importlib.metadata import PackageNotFoundError, version
from collections import Counter
from itertools import chain
from operator import attrgetter
from numbers import Integral
import os
from pathlib import Path
import re
import struct
from typing import Any, BinaryIO, Iterable, Sequence

from mcap.opcode import Opcode
import numpy as np
from mcap.records import MessageIndex
from mcap.writer import CompressionType, LIBRARY_IDENTIFIER, Writer
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message

from flock_swarm.bag.mcap_chunk import open_chunk, OpenChunk
from flock_swarm.bag.msgdefs import encoded_definition, message_class, type_hash, type_name_of
from flock_swarm.bag.yaml_emitter import dump_yaml

#: MCAP profile of ROS 2 bags.
PROFILE = 'ros2'
#: Message encoding of every channel (rosbag2's default serialization format).
SERIALIZATION_FORMAT = 'cdr'
#: ``rosbag2_bagfile_information`` version written by rosbag2 on Jazzy.
METADATA_VERSION = 9
#: Storage plugin identifier in ``metadata.yaml``.
STORAGE_IDENTIFIER = 'mcap'
#: ROS distribution whose message definitions and wheels this package is built on.
ROS_DISTRO = 'jazzy'
#: Name of the bag metadata file in the bag directory.
METADATA_FILENAME = 'metadata.yaml'
#: Name of the MCAP metadata record in which rosbag2 mirrors the bag metadata.
ROSBAG2_METADATA_RECORD = 'rosbag2'
#: rosbag2's starting time for a bag without messages (``std::chrono::nanoseconds::max()``).
NO_MESSAGES_START_NS = 2**63 - 1

#: An MCAP Message record up to its data: opcode 0x05, record length, channel id, sequence,
#: log time, publish time (the MCAP specification's layout, as mcap.records.Message writes it).
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')
_MESSAGE_FIELDS = _MESSAGE_HEAD.size - 9
#: A MessageIndex record up to its entries: opcode 0x07, record length, channel id, the
#: entries' length in bytes.
_INDEX_HEAD = struct.Struct('<BQHI')
#: A MessageIndex record of one entry (log time, offset): the head above and two uint64.
_ONE_ENTRY_INDEX = struct.Struct('<BQHIQQ')
#: The same layouts as NumPy records (packed, little-endian).
_MESSAGE_DTYPE = np.dtype([('op', 'u1'), ('length', '<u8'), ('channel', '<u2'),
                           ('sequence', '<u4'), ('log_time', '<u8'), ('publish_time', '<u8')])
_MESSAGE_RECORD = np.dtype((np.void, _MESSAGE_DTYPE.itemsize))
_ONE_ENTRY_DTYPE = np.dtype([('op', 'u1'), ('length', '<u8'), ('channel', '<u2'),
                             ('size', '<u4'), ('log_time', '<u8'), ('offset', '<u8')])
_INDEX_DTYPE = np.dtype([('op', 'u1'), ('length', '<u8'), ('channel', '<u2'), ('size', '<u4')])
_INDEX_ENTRY_DTYPE = np.dtype([('log_time', '<u8'), ('offset', '<u8')])

#: The channel id of a :class:`_Topic` in the open file.
_CHANNEL_ID = attrgetter('channel_id')

try:
    # collections.Counter.update's C loop, on any mapping (mcap's defaultdict of counts too).
    from collections import _count_elements
except ImportError:  # pragma: no cover - every CPython since 3.2 has it
    def _count_elements(mapping, iterable) -> None:
        for item in iterable:
            mapping[item] = mapping.get(item, 0) + 1

_COMPRESSION = {
    'zstd': CompressionType.ZSTD,
    'lz4': CompressionType.LZ4,
    'none': CompressionType.NONE,
}


def _library() -> str:
    try:
        ours = version('flock_swarm')
    except PackageNotFoundError:
        ours = 'unknown'
    return f'flock_swarm {ours}; {LIBRARY_IDENTIFIER}'


def _duration_yaml(nanoseconds: int) -> dict[str, int]:
    # rmw_time_t as rosbag2 writes it; Infinite (2**63 - 1 ns) gives sec 9223372036,
    # nsec 854775807, RMW_DURATION_INFINITE.
    return {'sec': nanoseconds // 10**9, 'nsec': nanoseconds % 10**9}


def qos_to_dict(qos: QoSProfile) -> dict[str, Any]:
    """Convert a QoS profile to rosbag2's YAML mapping (metadata version 9).

    Policies are written as rmw's strings (``keep_last``, ``reliable``, ``transient_local``,
    ``automatic``...), durations as ``{sec, nsec}``, keys in rosbag2's order.

    :param qos: the profile the topic's publisher offers.
    :return: a plain dictionary ready for YAML.
    """
    return {
        'history': qos.history.name.lower(),
        'depth': int(qos.depth),
        'reliability': qos.reliability.name.lower(),
        'durability': qos.durability.name.lower(),
        'deadline': _duration_yaml(qos.deadline.nanoseconds),
        'lifespan': _duration_yaml(qos.lifespan.nanoseconds),
        'liveliness': qos.liveliness.name.lower(),
        'liveliness_lease_duration': _duration_yaml(qos.liveliness_lease_duration.nanoseconds),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    }


#: Plain CDR of the primitive types rclpy names (``get_fields_and_field_types``): the
#: NumPy dtype of one value, little-endian; its size is its alignment.
_CDR_PRIMITIVES = {
    'boolean': np.dtype('?'), 'octet': np.dtype('u1'), 'char': np.dtype('u1'),
    'uint8': np.dtype('u1'), 'int8': np.dtype('i1'), 'uint16': np.dtype('<u2'),
    'int16': np.dtype('<i2'), 'uint32': np.dtype('<u4'), 'int32': np.dtype('<i4'),
    'uint64': np.dtype('<u8'), 'int64': np.dtype('<i8'), 'float': np.dtype('<f4'),
    'double': np.dtype('<f8'),
}
_CDR_SCALARS = {kind: struct.Struct('<' + fmt) for kind, fmt in (
    ('boolean', '?'), ('octet', 'B'), ('char', 'B'), ('uint8', 'B'), ('int8', 'b'),
    ('uint16', 'H'), ('int16', 'h'), ('uint32', 'I'), ('int32', 'i'), ('uint64', 'Q'),
    ('int64', 'q'), ('float', 'f'), ('double', 'd'))}
_SEQUENCE = re.compile(r'sequence<(.+?)(?:, ?\d+)?>$')
_ARRAY = re.compile(r'(.+)\[(\d+)\]$')


class _Unsupported(Exception):
    """A field type :func:`serialize` does not write itself (``wstring``, ``long double``)."""


def _cdr_pad(buf: bytearray, size: int) -> None:
    """Pad ``buf`` with zeros to a multiple of ``size`` from the end of the 4-byte header."""
    buf.extend(bytes(-(len(buf) - 4) % size))


def _cdr_values(buf: bytearray, kind: str, values) -> None:
    """Append the elements ``values`` of type ``kind``, without a length (an array's
    layout; a sequence puts its length first)."""
    dtype = _CDR_PRIMITIVES.get(kind)
    if dtype is not None:
        # Aligned to the element's size even when empty, as Fast CDR does.
        _cdr_pad(buf, dtype.itemsize)
        if not len(values):
            return
        if isinstance(values, (bytes, bytearray)):
            values = list(values)
        elif isinstance(values[0], (bytes, bytearray)):     # byte[]: one bytes object each
            values = [v[0] for v in values]
        buf.extend(np.asarray(values).astype(dtype, copy=False).tobytes())
        return
    for value in values:
        _cdr_field(buf, kind, value)


def _cdr_field(buf: bytearray, kind: str, value) -> None:
    """Append one field of type ``kind`` (rclpy's type string) holding ``value``."""
    dtype = _CDR_PRIMITIVES.get(kind)
    if dtype is not None:
        if isinstance(value, (bytes, bytearray)):           # byte / octet: bytes([v])
            value = value[0]
        _cdr_pad(buf, dtype.itemsize)
        buf.extend(_CDR_SCALARS[kind].pack(value))
    elif kind == 'string' or kind.startswith('string<'):
        text = value.encode('utf-8')
        _cdr_pad(buf, 4)
        buf.extend(struct.pack('<I', len(text) + 1))
        buf.extend(text)
        buf.append(0)
    elif (match := _SEQUENCE.match(kind)) is not None:
        _cdr_pad(buf, 4)
        buf.extend(struct.pack('<I', len(value)))
        _cdr_values(buf, match.group(1), value)
    elif (match := _ARRAY.match(kind)) is not None:
        _cdr_values(buf, match.group(1), value)
    elif '/' in kind:
        _cdr_message(buf, value)
    else:
        raise _Unsupported(kind)


def _cdr_message(buf: bytearray, msg: Any) -> None:
    """Append the fields of the message ``msg`` in their declared order."""
    fields = msg.get_fields_and_field_types()
    if not fields:
        # A message of no fields is the one uint8 its type support adds; rclpy writes it
        # padded to 4 bytes as a whole message, and it is left to rclpy inside another.
        if len(buf) > 4:
            raise _Unsupported('a nested message of no fields')
        buf.extend(bytes(4))
    for name, kind in fields.items():
        _cdr_field(buf, kind, getattr(msg, name))


def serialize(msg: Any) -> bytes:
    """Return the rclpy message ``msg`` serialised as rclpy's ``serialize_message`` does
    (little-endian plain CDR, XCDR1), with every alignment padding byte zero.

    rclpy's serialisation leaves its padding bytes uninitialised, so the same message gives
    different bytes from run to run (a ``DiagnosticArray`` pads after each ``level``); a bag
    written through this function is byte-for-byte reproducible. A message with a field type
    this function does not write (``wstring``, ``long double``) is serialised by rclpy.

    :param msg: an rclpy message object.
    """
    buf = bytearray(b'\x00\x01\x00\x00')
    try:
        _cdr_message(buf, msg)
    except _Unsupported:
        return serialize_message(msg)
    return bytes(buf)


def serialize_qos_profiles(profiles: list[QoSProfile]) -> str:
    """Serialise offered QoS profiles as the ``offered_qos_profiles`` channel metadata string.

    rosbag2 stores ``YAML::Dump`` of the profile list there; an empty list is ``[]``.

    :param profiles: the profiles offered on the topic (usually one).
    :return: the YAML text, without a trailing newline as yaml-cpp writes it.
    """
    dicts = [qos_to_dict(qos) for qos in profiles]
    # Remembered by value: a world at N = 1000 registers 2000 topics with one profile, and
    # dumping it each time took 0.4 ms a topic, 0.8 s of the start-up (docs/performance.md).
    key = repr(dicts)
    text = _QOS_YAML.get(key)
    if text is None:
        text = _QOS_YAML[key] = dump_yaml(dicts).rstrip('\n')
    return text


#: The YAML of the QoS profile lists serialised so far (a handful per run), by their repr.
_QOS_YAML: dict[str, str] = {}


class _FlushingFile:
    """A binary output file whose every write reaches the operating system at once.

    The mcap writer writes whole records (a finished chunk, its message indexes, a metadata
    record), so flushing each write bounds what a killed process loses to the open chunk.
    Not an ``io.RawIOBase``, so that the mcap writer does not wrap it in a buffer of its own.
    """

    def __init__(self, path: Path) -> None:
        self._file: BinaryIO = open(path, 'xb')

    def write(self, data: bytes) -> int:
        written = self._file.write(data)
        self._file.flush()
        return written

    def tell(self) -> int:
        return self._file.tell()

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        self._file.close()


class _BagFile:
    """One MCAP file of the bag: its writer and what it holds."""

    def __init__(self, directory: Path, relative: str, chunk_size: int,
                 compression: CompressionType) -> None:
        self.relative = relative
        # Both dropped once the file is finished: mcap's writer keeps every chunk index.
        self.stream: _FlushingFile | None = _FlushingFile(directory / relative)
        self.writer: Writer | None = Writer(self.stream, chunk_size=chunk_size,
                                            compression=compression)
        self.writer.start(profile=PROFILE, library=_library())
        self.schema_ids: dict[str, int] = {}
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.count = 0

    def took(self, t_ns: int, count: int) -> None:
        """Account for ``count`` messages written at ``t_ns``."""
        self.count += count
        self.start_ns = t_ns if self.start_ns is None else min(self.start_ns, t_ns)
        self.end_ns = t_ns if self.end_ns is None else max(self.end_ns, t_ns)


def _time_span(files: list[_BagFile]) -> tuple[int, int]:
    """Return the start and duration (ns) of the messages of ``files``, as rosbag2 does."""
    starts = [file.start_ns for file in files if file.start_ns is not None]
    if not starts:
        return NO_MESSAGES_START_NS, 0
    start = min(starts)
    return start, max(file.end_ns for file in files if file.end_ns is not None) - start


def _file_entry(file: _BagFile) -> dict[str, Any]:
    """Return a file's entry under ``files:`` in ``metadata.yaml``."""
    start, duration = _time_span([file])
    return {
        'path': file.relative,
        'starting_time': {'nanoseconds_since_epoch': start},
        'duration': {'nanoseconds': duration},
        'message_count': file.count,
    }


class _PackedMessageIndex(MessageIndex):
    """mcap's MessageIndex record written with one call: its head and entries packed at once
    instead of ``start_record``, two ``write8`` calls per entry and ``finish_record`` (the
    same bytes). A chunk holds one such record per channel it carries, i.e. two per agent
    at every step: at N = 1000 mcap's own ``MessageIndex.write`` took 12 us a record, 19 ms
    a step (docs/performance.md)."""

    def write(self, stream) -> None:
        """Write the record (as ``MessageIndex.write`` does)."""
        stream.write(_index_record(self))


def _index_record(index: MessageIndex) -> bytes:
    """Return the bytes of a MessageIndex record (``MessageIndex.write``'s), packed at once."""
    records = index.records
    if len(records) == 1:
        # The usual case in a lockstep bag (a channel's one message of the chunk's step).
        return _ONE_ENTRY_INDEX.pack(Opcode.MESSAGE_INDEX, 22, index.channel_id, 16,
                                     *records[0])
    size = 16 * len(records)
    return (_INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + size, index.channel_id, size)
            + struct.pack(f'<{2 * len(records)}Q', *chain.from_iterable(records)))


def _index_records(pending: list[tuple[np.ndarray, np.ndarray, int]]
                   ) -> tuple[bytes, list[int], np.ndarray]:
    """Return a chunk's MessageIndex records (the bytes mcap writes for its message
    indices), their channels in mcap's order and each record's offset in the bytes.

    :param pending: ``(channels, offsets, log time)`` of the chunk's messages, in order.
    :return: mcap writes one record per channel in the order of the channel's first message
        in the chunk, listing the channel's ``(log time, offset)`` in order.
    """
    channels = np.concatenate([c for c, _, _ in pending])
    offsets = np.concatenate([o for _, o, _ in pending])
    times = np.concatenate([np.full(len(c), t, dtype=np.uint64) for c, _, t in pending])
    ids, first, inverse, counts = np.unique(channels, return_index=True, return_inverse=True,
                                            return_counts=True)
    order = np.argsort(first, kind='stable')
    if len(ids) == len(channels):
        # One message per channel (a lockstep chunk of about a step): one record each, in
        # the messages' order.
        records = np.empty(len(channels), _ONE_ENTRY_DTYPE)
        records['op'] = Opcode.MESSAGE_INDEX
        records['length'] = 22
        records['channel'] = channels
        records['size'] = 16
        records['log_time'] = times
        records['offset'] = offsets
        return records.tobytes(), channels.tolist(), np.arange(len(channels)) * 31
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    by_record = np.argsort(rank[inverse.reshape(-1)], kind='stable')
    per = counts[order]
    sizes = 15 + 16 * per
    at = np.cumsum(sizes) - sizes
    out = np.empty(int(sizes.sum()), dtype=np.uint8)
    heads = np.empty(len(per), _INDEX_DTYPE)
    heads['op'] = Opcode.MESSAGE_INDEX
    heads['length'] = 6 + 16 * per
    heads['channel'] = ids[order]
    heads['size'] = 16 * per
    out[at[:, None] + np.arange(15)] = heads.view(np.uint8).reshape(-1, 15)
    entries = np.empty(len(channels), _INDEX_ENTRY_DTYPE)
    entries['log_time'] = times[by_record]
    entries['offset'] = offsets[by_record]
    within = np.arange(len(channels)) - np.repeat(np.cumsum(per) - per, per)
    where = np.repeat(at, per) + 15 + 16 * within
    out[where[:, None] + np.arange(16)] = entries.view(np.uint8).reshape(-1, 16)
    return out.tobytes(), ids[order].tolist(), at


class _Topic:
    """What the writer knows of one topic."""

    def __init__(self, name: str, type_name: str, msg_class: type,
                 profiles: list[QoSProfile], type_hash: str) -> None:
        self.name = name
        self.type_name = type_name
        self.msg_class = msg_class
        self.qos_profiles = [qos_to_dict(p) for p in profiles]
        # The channel metadata string, written again in every file of a split bag.
        self.offered_qos_profiles = serialize_qos_profiles(profiles)
        self.type_hash = type_hash
        # The topic's channel in the open file (set when it is registered there).
        self.channel_id = 0
        self.count = 0


class BagWriter:
    """Record ROS 2 messages into a rosbag2-compatible MCAP bag directory.

    Use it as a context manager, or call :meth:`close`::

        with BagWriter(Path('out/run1')) as bag:
            bag.add_topic('/clock', Clock)
            bag.write('/clock', clock_msg, t_ns)

    Single-threaded: call it from one thread (an rclpy callback group, or the simulator loop).

    :param path: the bag directory to create; it must not exist or be empty.
    :param chunk_size: uncompressed size (bytes) after which a chunk is compressed and written;
        at most this much recorded data is lost if the process is killed.
    :param compression: chunk compression, ``'zstd'``, ``'lz4'`` or ``'none'``.
    :param custom_metadata: MCAP metadata records written at once, name to string mapping
        (scenario provenance, for example); more can be added with :meth:`add_metadata`.
    :param max_bagfile_size: split the bag once its open file holds more than this many bytes
        (rosbag2's ``max_bagfile_size``); 0: no split by size. Chunks go to the file whole,
        so a file ends up to one compressed chunk above the limit.
    :param max_bagfile_duration: split the bag before a message more than this many seconds
        (of message time) after the open file's first message (rosbag2's
        ``max_bagfile_duration``); 0: no split by duration.
    :raises FileExistsError: if ``path`` is a file or a non-empty directory.
    :raises ValueError: for an unknown compression, a chunk size below one byte, or a
        negative split limit.
    """

    def __init__(self, path: Path, *, chunk_size: int = 1 << 20, compression: str = 'zstd',
                 custom_metadata: dict[str, dict[str, str]] | None = None,
                 max_bagfile_size: int = 0, max_bagfile_duration: float = 0.0) -> None:
        """Create the bag directory and start its first MCAP file."""
        path = Path(path)
        if compression not in _COMPRESSION:
            raise ValueError(f'unknown bag compression {compression!r}; '
                             f"expected one of {', '.join(sorted(_COMPRESSION))}")
        if chunk_size < 1:
            raise ValueError(f'chunk_size must be at least 1 byte, got {chunk_size}')
        if not max_bagfile_size >= 0:
            raise ValueError(f'max_bagfile_size must be >= 0 bytes, got {max_bagfile_size}')
        if not max_bagfile_duration >= 0 or max_bagfile_duration == float('inf'):
            raise ValueError('max_bagfile_duration must be a finite number >= 0 of seconds, '
                             f'got {max_bagfile_duration}')
        if path.exists() and not path.is_dir():
            raise FileExistsError(f'cannot create bag directory {path}: a file of that name '
                                  'exists')
        if path.is_dir() and any(path.iterdir()):
            raise FileExistsError(f'bag directory {path} already exists and is not empty; '
                                  'choose another name or remove it')
        path.mkdir(parents=True, exist_ok=True)
        self._path = path
        self._chunk_size = chunk_size
        self._compression = _COMPRESSION[compression]
        self._max_size = int(max_bagfile_size)
        self._max_duration_ns = round(max_bagfile_duration * 1e9)
        self._topics: dict[str, _Topic] = {}
        # Messages per topic written by write_serialized_batch (the others: _Topic.count).
        self._batched: Counter[str] = Counter()
        # The open chunk's message index entries written by write_serialized_batch, not yet
        # in mcap's chunk builder: (channels, offsets in the chunk, log time) per run.
        self._pending: list[tuple[np.ndarray, np.ndarray, int]] = []
        # Custom metadata records, repeated in every file so that each one stands alone.
        self._custom: list[tuple[str, dict[str, str]]] = []
        self._files: list[_BagFile] = []
        self._closed = False
        self._open_file()
        for name, data in (custom_metadata or {}).items():
            self.add_metadata(name, data)

    def _open_file(self) -> None:
        """Start the next MCAP file with every schema, channel and custom record so far.

        The first file gets the ``rosbag2`` record at once as well as at its close; a file
        started by a split gets it at its close only, as rosbag2's ``update_metadata``
        does (one YAML dump of the whole bag's metadata per split, ~0.15 s with 60 topics).
        """
        first = not self._files
        file = _BagFile(self._path, f'{self._path.name}_{len(self._files)}.mcap',
                        self._chunk_size, self._compression)
        self._files.append(file)
        self._file, self._writer = file.stream, file.writer
        if first:
            self._write_rosbag2_record()
        for topic in self._topics.values():
            self._register(topic)
        for name, data in self._custom:
            self._add_metadata(name, data)

    def _register(self, topic: '_Topic') -> None:
        """Register a topic's schema (once per file) and channel in the open file."""
        file = self._files[-1]
        # mcap may finish the chunk when the records go into it.
        self._settle()
        if topic.type_name not in file.schema_ids:
            definition = encoded_definition(topic.type_name)
            file.schema_ids[topic.type_name] = self._writer.register_schema(
                name=topic.type_name, encoding=definition.encoding,
                data=definition.text.encode('utf-8'))
        topic.channel_id = self._writer.register_channel(
            topic=topic.name, message_encoding=SERIALIZATION_FORMAT,
            schema_id=file.schema_ids[topic.type_name],
            metadata={'offered_qos_profiles': topic.offered_qos_profiles,
                      'topic_type_hash': topic.type_hash})

    def _finish_file(self) -> None:
        """Write the open file's rosbag2 record, summary and footer, and close it."""
        try:
            self._write_rosbag2_record()
            self._settle()
            self._writer.finish()
        finally:
            self._file.close()
            self._files[-1].writer = self._files[-1].stream = None

    def _split_before(self, t_ns: int) -> None:
        """Finish the open file and start the next if a message at ``t_ns`` is over a limit.

        As rosbag2's ``SequentialWriter::should_split_bagfile``: the size of the file on
        disk above ``max_bagfile_size``, or ``t_ns`` more than ``max_bagfile_duration``
        after the file's first message. An empty file is never left behind, and messages of
        the time of the file's latest stay with it: the world writes a step (its states, then
        the commands, all at ``t_k``) in several calls, and a chunk filling between them made
        the size rule cut the step in two files.
        """
        file = self._files[-1]
        if file.count == 0 or t_ns <= file.end_ns:
            return
        if ((self._max_size and file.stream.tell() > self._max_size)
                or (self._max_duration_ns and t_ns - file.start_ns > self._max_duration_ns)):
            self._finish_file()
            self._open_file()

    @property
    def path(self) -> Path:
        """The bag directory."""
        return self._path

    @property
    def mcap_path(self) -> Path:
        """The MCAP file being written (the last one of a split bag)."""
        return self._path / self._files[-1].relative

    @property
    def mcap_paths(self) -> list[Path]:
        """Every MCAP file of the bag so far, in split order."""
        return [self._path / file.relative for file in self._files]

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far, per topic (in the order topics were added)."""
        batched = self._batched
        return {name: topic.count + batched[name] for name, topic in self._topics.items()}

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def __enter__(self) -> 'BagWriter':
        """Return the writer itself."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the bag, also after an exception: what was recorded stays readable."""
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f'bag {self._path} is closed')

    def add_topic(self, name: str, msg_type: type | str,
                  qos: QoSProfile | None = None) -> None:
        """Declare a topic: one MCAP channel, and the type's schema if it is new.

        Adding a topic again with the same type does nothing, as in rosbag2.

        :param name: fully qualified topic name, such as ``/agent_3/odom``.
        :param msg_type: the message class, or its ``pkg/msg/Type`` name.
        :param qos: the QoS profile the topic's publisher offers, recorded for replay;
            ``None`` records no profile (a player then uses its defaults).
        :raises ValueError: if the name is not absolute, or the topic exists with another type.
        :raises DefinitionNotFoundError: if the type's definition is not installed.
        """
        self._check_open()
        if not isinstance(name, str) or not name.startswith('/'):
            raise ValueError(f'topic name must be absolute (start with /), got {name!r}')
        type_name = type_name_of(msg_type)
        if name in self._topics:
            if self._topics[name].type_name != type_name:
                raise ValueError(f'topic {name} already recorded with type '
                                 f'{self._topics[name].type_name}, not {type_name}')
            return
        msg_class = msg_type if isinstance(msg_type, type) else message_class(type_name)
        topic = _Topic(name, type_name, msg_class, [] if qos is None else [qos],
                       type_hash(type_name))
        self._register(topic)
        self._topics[name] = topic

    def write(self, topic: str, msg: Any, t_ns: int) -> None:
        """Serialise a message (:func:`serialize`: its padding zero) and record it.

        :param topic: a topic declared with :meth:`add_topic`.
        :param msg: a message of the topic's type.
        :param t_ns: receive and publish time (ns), the bag's time axis; simulation time for
            a simulated run.
        :raises KeyError: if the topic was not added.
        :raises TypeError: if the message is not of the topic's type.
        """
        self._check_open()
        expected = self._topic(topic).msg_class
        if not isinstance(msg, expected):
            raise TypeError(f'topic {topic} records {type_name_of(expected)}, '
                            f'got {type(msg).__module__}.{type(msg).__qualname__}')
        self.write_serialized(topic, serialize(msg), t_ns)

    def write_serialized(self, topic: str, data: bytes, t_ns: int) -> None:
        """Record an already CDR-serialised message.

        :param topic: a topic declared with :meth:`add_topic`.
        :param data: the serialised message.
        :param t_ns: receive and publish time (ns), non-negative.
        :raises KeyError: if the topic was not added.
        :raises ValueError: if the time is negative.
        """
        self._check_open()
        entry = self._topic(topic)
        if isinstance(t_ns, bool) or not isinstance(t_ns, Integral):
            raise TypeError(f'message time must be an integer number of ns, got {t_ns!r}')
        t_ns = int(t_ns)
        if not 0 <= t_ns < 2**64:
            raise ValueError(f'message time must be a non-negative 64-bit ns count, got {t_ns}')
        self._split_before(t_ns)
        self._settle()
        # rosbag2 leaves the MCAP sequence at 0 (not assigned by the publisher).
        self._writer.add_message(channel_id=entry.channel_id, log_time=t_ns,
                                 data=bytes(data), publish_time=t_ns, sequence=0)
        entry.count += 1
        self._files[-1].took(t_ns, 1)

    def write_serialized_many(self, messages: Iterable[tuple[str, bytes]], t_ns: int) -> None:
        """Record already serialised messages, all at time ``t_ns``, in order.

        ``(topic, data)`` pairs; see :meth:`write_serialized_batch` (the same, with the
        topics and the data in two sequences).

        :param messages: ``(topic, data)`` pairs, topics declared with :meth:`add_topic`.
        :param t_ns: receive and publish time (ns) of them all, non-negative.
        :raises KeyError: if a topic was not added.
        """
        pairs = list(messages)
        self.write_serialized_batch([topic for topic, _ in pairs], [data for _, data in pairs],
                                    t_ns)

    def write_serialized_batch(self, topics: Sequence[str], data: Sequence[bytes],
                               t_ns: int) -> None:
        """Record already serialised messages, ``data[m]`` on ``topics[m]``, all at time
        ``t_ns``, in order.

        The same file as :meth:`write_serialized` once per message (tested byte for byte),
        in a fraction of the time: the messages of a lockstep step go into the open chunk
        directly, as runs of records joined into one write, instead of one
        ``mcap.records.Message`` object and seven stream writes each (12 us a message in
        ``mcap`` 1.6 against well under 1 here). That reaches into ``mcap.writer.Writer``'s
        chunk builder, through :mod:`flock_swarm.bag.mcap_chunk` alone; where it is not there
        (another ``mcap`` series, chunking off), each message goes through
        :meth:`write_serialized`.

        :param topics: the messages' topics, declared with :meth:`add_topic`.
        :param data: the serialised messages (as many as ``topics``).
        :param t_ns: receive and publish time (ns) of them all, non-negative.
        :raises KeyError: if a topic was not added.
        :raises ValueError: if the time is negative or the lengths differ.
        """
        self._check_open()
        try:
            entries = list(map(self._topics.__getitem__, topics))
        except (KeyError, TypeError):
            entries = [self._topic(topic) for topic in topics]
        if isinstance(t_ns, bool) or not isinstance(t_ns, Integral) or not 0 <= t_ns < 2**64:
            raise ValueError(f'message time must be a non-negative 64-bit ns count, got {t_ns!r}')
        if len(entries) != len(data):
            raise ValueError(f'{len(entries)} topics for {len(data)} messages')
        if not entries:
            return
        if not isinstance(data, (list, tuple)):
            data = list(data)
        t_ns = int(t_ns)
        # The batch's messages share one time: they go to one file.
        self._split_before(t_ns)
        fast = self._fast_path()
        if fast is None:
            for entry, message in zip(entries, data):
                self.write_serialized(entry.name, message, t_ns)
            return
        chunk, stats, limit = fast.builder, fast.statistics, fast.limit
        count = len(entries)
        channels = list(map(_CHANNEL_ID, entries))
        # Writer.add_message's statistics (all messages have one time: once for the batch),
        # ChunkBuilder.add_message's bookkeeping and Message.write's bytes per message, and
        # the writer's chunk-size check after each, as mcap does.
        if stats.message_count == 0:
            stats.message_start_time = t_ns
        else:
            stats.message_start_time = min(t_ns, stats.message_start_time)
        stats.message_end_time = max(t_ns, stats.message_end_time)
        stats.message_count += count
        _count_elements(stats.channel_message_counts, channels)
        _count_elements(self._batched, topics)
        if chunk.num_messages == 0:
            chunk.message_start_time = t_ns
        else:
            chunk.message_start_time = min(chunk.message_start_time, t_ns)
        chunk.message_end_time = max(chunk.message_end_time, t_ns)
        # Each record's head (Message.write's: opcode, length, channel, sequence 0, log and
        # publish time), built at once; a record is its head and its data.
        sizes = np.fromiter(map(len, data), dtype=np.int64, count=count)
        heads = np.empty(count, _MESSAGE_DTYPE)
        heads['op'] = 0x05
        heads['length'] = sizes + _MESSAGE_FIELDS
        heads['channel'] = channels
        heads['sequence'] = 0
        heads['log_time'] = heads['publish_time'] = t_ns
        heads = heads.view(_MESSAGE_RECORD).tolist()
        # Where each record ends, counted from the batch's first. The chunk is finished
        # after the record that takes it over the limit.
        ends = np.cumsum(sizes + _MESSAGE_HEAD.size)
        starts = ends - (sizes + _MESSAGE_HEAD.size)
        channel_ids = np.array(channels, dtype=np.int64)
        first = done = 0
        while first < count:
            stream = fast.buffer()
            at = stream.tell()
            # The first record ending past the limit closes this run (and the chunk).
            last = first + int(np.searchsorted(ends[first:], limit - at + done, side='right'))
            full = last < count
            stop = last + 1 if full else count
            # Its message index entries (log time, offset in the chunk), written when the
            # chunk is finished (_finish_chunk).
            self._pending.append((channel_ids[first:stop], starts[first:stop] + (at - done),
                                  t_ns))
            parts = [b''] * (2 * (stop - first))
            parts[0::2] = heads[first:stop]
            parts[1::2] = data[first:stop]
            stream.write(b''.join(parts))
            chunk.num_messages += stop - first
            done, first = int(ends[stop - 1]), stop
            if full:
                self._finish_chunk()
                # A fresh chunk (reset by mcap): its first message is the batch's next.
                chunk.message_start_time = chunk.message_end_time = t_ns
        self._files[-1].took(t_ns, count)

    def _fast_path(self) -> OpenChunk | None:
        """Return the mcap writer's open chunk (:func:`~flock_swarm.bag.mcap_chunk.open_chunk`),
        or ``None`` where a batch must take mcap's public path."""
        return open_chunk(self._writer)

    def _settle(self) -> None:
        """Put the open chunk's pending index entries (:meth:`write_serialized_batch`'s)
        into mcap's chunk builder, as its ``add_message`` would have: before mcap itself
        adds a message to the chunk or finishes it."""
        if not self._pending:
            return
        pending, self._pending = self._pending, []
        indices = OpenChunk(self._writer).builder.message_indices
        for channels, offsets, t_ns in pending:
            for channel, offset in zip(channels.tolist(), offsets.tolist()):
                index = indices.get(channel)
                if index is None:
                    index = indices[channel] = _PackedMessageIndex(channel_id=channel,
                                                                   records=[])
                index.records.append((t_ns, offset))

    def _finish_chunk(self) -> None:
        """Finish the open chunk, which is over the chunk size: as ``mcap``'s
        ``Writer.__finalize_chunk`` (compression, the Chunk record, its ChunkIndex) with the
        message indexes that follow it built here: mcap writes them one record per channel
        with several Python calls each (at N = 1000 a chunk indexes 2000 channels), here
        they are one NumPy pass and one write, the same bytes, their offsets in the
        ChunkIndex as mcap puts them."""
        chunk = OpenChunk(self._writer)
        if chunk.builder.message_indices:
            # mcap's add_message indexed some of the chunk's messages: its own way.
            self._settle()
            chunk.finalize()
            return
        pending, self._pending = self._pending, []
        count = chunk.chunk_count()
        chunk.finalize()
        if chunk.chunk_count() == count:
            # Not finished after all (never, from write_serialized_batch): as they were.
            self._pending = pending
            return
        if not pending:
            return
        data, channels, offsets = _index_records(pending)
        chunk.write_message_indexes(data, channels, offsets.tolist())

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write an MCAP metadata record (string keys and values), such as run provenance.

        It goes to the file at once, so it survives a killed process, and is repeated in
        every later file of a split bag, so that each file carries it.

        :param name: record name; ``rosbag2`` is reserved for the bag metadata.
        :param data: the key-value pairs.
        :raises ValueError: for the reserved name.
        :raises TypeError: if a key or value is not a string.
        """
        self._check_open()
        if name == ROSBAG2_METADATA_RECORD:
            raise ValueError(f'metadata record name {name!r} is reserved for rosbag2')
        self._add_metadata(name, data)
        self._custom.append((name, dict(data)))

    def _add_metadata(self, name: str, data: dict[str, str]) -> None:
        if not isinstance(name, str):
            raise TypeError(f'metadata record name must be a string, got {name!r}')
        for key, value in data.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise TypeError(f'metadata record {name!r} must map strings to strings, '
                                f'got {key!r}: {value!r}')
        self._writer.add_metadata(name, dict(data))

    def _topic(self, topic: str) -> _Topic:
        try:
            return self._topics[topic]
        except KeyError:
            raise KeyError(f'topic {topic!r} was not added to bag {self._path}; '
                           'call add_topic first') from None

    def bag_metadata(self) -> dict[str, Any]:
        """Return the bag metadata as rosbag2 writes it (``rosbag2_bagfile_information``).

        :return: the mapping under ``rosbag2_bagfile_information`` in ``metadata.yaml``.
        """
        counts = self.message_counts
        count = sum(counts.values())
        start, duration = _time_span([file for file in self._files if file.count])
        return {
            'version': METADATA_VERSION,
            'storage_identifier': STORAGE_IDENTIFIER,
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': count,
            'topics_with_message_count': [
                {
                    'topic_metadata': {
                        'name': topic.name,
                        'type': topic.type_name,
                        'serialization_format': SERIALIZATION_FORMAT,
                        'offered_qos_profiles': topic.qos_profiles,
                        'type_description_hash': topic.type_hash,
                    },
                    'message_count': counts[topic.name],
                }
                for topic in self._topics.values()
            ],
            # Chunk compression is internal to the MCAP storage; rosbag2 leaves these empty.
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [file.relative for file in self._files],
            'files': [_file_entry(file) for file in self._files],
            'custom_data': None,
            'ros_distro': ROS_DISTRO,
        }

    def _write_rosbag2_record(self) -> None:
        self._add_metadata(ROSBAG2_METADATA_RECORD,
                           {'serialized_metadata': dump_yaml(self.bag_metadata())})

    def abandon(self) -> None:
        """Stop recording without finishing the bag (after a write failed, say a full disk).

        The open file is closed as it is: its complete chunks stay readable
        (:class:`BagReader` recovers them and says so), the files finished before it by a
        split are complete, and no ``metadata.yaml`` claims the bag complete.

        :raises OSError: if even closing the file fails; the chunks on disk are unaffected.
        """
        if self._closed:
            return
        self._closed = True
        self._file.close()

    def close(self) -> None:
        """Finish the open MCAP file (summary and indexes) and write ``metadata.yaml``.

        Closing again does nothing.
        """
        if self._closed:
            return
        self._closed = True
        self._finish_file()
        text = dump_yaml({'rosbag2_bagfile_information': self.bag_metadata()})
        # Written whole then renamed: a metadata.yaml is either absent or complete, and a
        # failed write (a full disk) leaves no partial file behind either.
        tmp = self._path / f'.{METADATA_FILENAME}.tmp'
        try:
            tmp.write_text(text, encoding='utf-8')
            os.replace(tmp, self._path / METADATA_FILENAME)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise OSError(exc.errno, exc.strerror, str(self._path / METADATA_FILENAME)) \
                from None
