"""Read rosbag2 MCAP bags, including truncated ones, without rosbag2_py.

:class:`BagReader` opens a bag directory (with or without ``metadata.yaml``) or a single
``.mcap`` file. A finished file is read through its summary section (schemas, channels, chunk
and metadata indexes); a file without a usable footer (the recorder was killed, the disk filled
up, the copy was cut short) is scanned record by record up to its last complete chunk, and the
reader says so in :attr:`BagReader.recovered` and :attr:`BagReader.warning`.
"""

import bisect
from collections import Counter
from dataclasses import dataclass, field
import heapq
from io import BytesIO
from pathlib import Path
import re
import struct
from typing import Any, BinaryIO, Callable, Iterable, Iterator

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Channel, Chunk, ChunkIndex, Footer, Header, McapRecord, Message, Metadata, MetadataIndex,
    Schema, Statistics)
from mcap.stream_reader import breakup_chunk, get_chunk_data_stream
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy)
from rclpy.serialization import deserialize_message
import yaml

from flock_swarm.bag.msgdefs import DefinitionNotFoundError, message_class
from flock_swarm.bag.writer import METADATA_FILENAME, METADATA_VERSION, PROFILE

#: The eight bytes that open and close every MCAP file.
MAGIC = b'\x89MCAP0\r\n'
# Opcode byte and record length that precede every record body.
_PREFIX = struct.Struct('<BQ')
# A footer record: prefix and three fields (summary start, summary offset start, CRC).
_FOOTER_SIZE = _PREFIX.size + 8 + 8 + 4
# Opcodes the MCAP specification defines (0x80 and above are private records).
_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)


class BagError(ValueError):
    """The path is not a readable ROS 2 MCAP bag; the message is one line."""


class UndecodableMessage(BagError):
    """A message whose bytes do not decode as its type (a faulty writer's, recorded as
    received).

    :ivar message: the message.
    :ivar reason: why, in one line.
    """

    def __init__(self, message: 'BagMessage', reason: str) -> None:
        """Create the error (one line: topic, time, type, reason)."""
        super().__init__(f'message on {message.topic} at {message.log_time_ns} ns does not '
                         f'decode as {message.type_name} ({reason})')
        self.message = message
        self.reason = reason


@dataclass(frozen=True)
class BagMessage:
    """One recorded message, still serialised."""

    #: Topic name, such as ``/agent_0/odom``.
    topic: str
    #: Message type, such as ``nav_msgs/msg/Odometry``.
    type_name: str
    #: Receive time (ns): the bag's time axis.
    log_time_ns: int
    #: CDR-serialised message.
    data: bytes = field(repr=False)
    #: The channel's ``offered_qos_profiles`` YAML (see :func:`parse_qos_profiles`).
    offered_qos_profiles: str = field(default='', repr=False)
    #: Publish time (ns); equal to the log time in bags written by this package.
    publish_time_ns: int = 0


@dataclass(frozen=True)
class _ChunkRef:
    """Where a chunk is and what it may hold."""

    offset: int
    start_ns: int
    # Channels with messages in the chunk; None when the file does not say.
    channel_ids: frozenset[int] | None


@dataclass
class _McapFile:
    """What one MCAP file holds, from its summary or from a scan."""

    path: Path
    header: Header
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    chunks: list[_ChunkRef] = field(default_factory=list)
    # Messages outside chunks (unchunked writers): (file offset, message).
    loose: list[tuple[int, Message]] = field(default_factory=list)
    metadata: list[Metadata] = field(default_factory=list)
    counts: Counter = field(default_factory=Counter)
    # Why the file was scanned rather than read through its summary, when data may be lost.
    warning: str | None = None

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())


def parse_qos_profiles(text: str) -> list[QoSProfile]:
    """Parse an ``offered_qos_profiles`` string (rosbag2 metadata version 9, or older ints).

    :param text: the channel metadata value, for example :attr:`BagMessage.offered_qos_profiles`.
    :return: the profiles; empty if none was recorded.
    :raises BagError: if the text is not a list of QoS mappings.
    """
    if not text.strip():
        return []
    try:
        items = yaml.safe_load(text)
        if not isinstance(items, list):
            raise TypeError('not a list')
        return [_qos_from_dict(item) for item in items]
    except (yaml.YAMLError, TypeError, KeyError, ValueError) as exc:
        raise BagError(f'offered_qos_profiles is not a list of QoS profiles ({exc})') from None


def _policy(enum: type, value: Any) -> Any:
    if isinstance(value, int) and not isinstance(value, bool):
        return enum(value)
    return enum[str(value).upper()]


def _duration(value: dict[str, int]) -> Duration:
    return Duration(nanoseconds=int(value['sec']) * 10**9 + int(value['nsec']))


def _qos_from_dict(item: dict[str, Any]) -> QoSProfile:
    history = _policy(HistoryPolicy, item['history'])
    return QoSProfile(
        history=history,
        depth=int(item['depth']),
        reliability=_policy(ReliabilityPolicy, item['reliability']),
        durability=_policy(DurabilityPolicy, item['durability']),
        deadline=_duration(item['deadline']),
        lifespan=_duration(item['lifespan']),
        liveliness=_policy(LivelinessPolicy, item['liveliness']),
        liveliness_lease_duration=_duration(item['liveliness_lease_duration']),
        avoid_ros_namespace_conventions=bool(item['avoid_ros_namespace_conventions']))


def _read_record(stream: BinaryIO, offset: int, size: int) -> tuple[int, int, bytes] | None:
    """Return ``(opcode, length, body)`` of the record at ``offset``, or None if cut short."""
    if offset + _PREFIX.size > size:
        return None
    stream.seek(offset)
    opcode, length = _PREFIX.unpack(stream.read(_PREFIX.size))
    if offset + _PREFIX.size + length > size:
        return None
    return opcode, length, stream.read(length)


def _parse(opcode: int, length: int, body: bytes) -> McapRecord:
    """Parse a record body with the mcap library's record classes."""
    stream = ReadDataStream(BytesIO(body))
    parsers = {
        Opcode.HEADER: Header.read, Opcode.FOOTER: Footer.read, Opcode.SCHEMA: Schema.read,
        Opcode.CHANNEL: Channel.read, Opcode.CHUNK: Chunk.read,
        Opcode.CHUNK_INDEX: ChunkIndex.read, Opcode.METADATA: Metadata.read,
        Opcode.METADATA_INDEX: MetadataIndex.read, Opcode.STATISTICS: Statistics.read,
    }
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, length)
    return parsers[opcode](stream)


def _open_mcap(path: Path) -> _McapFile:
    """Index one MCAP file, through its summary if it has a usable one, else by scanning."""
    try:
        size = path.stat().st_size
        stream = path.open('rb')
    except OSError as exc:
        raise BagError(f'cannot read {path}: {exc.strerror}') from None
    with stream:
        if stream.read(len(MAGIC)) != MAGIC:
            raise BagError(f'{path} is not an MCAP file (it does not start with the MCAP magic)')
        record = _read_record(stream, len(MAGIC), size)
        if record is None or record[0] != Opcode.HEADER:
            raise BagError(f'{path} is an empty or damaged MCAP file (no header record)')
        try:
            header = _parse(*record)
        except Exception as exc:
            raise BagError(f'{path} has a damaged MCAP header ({_one_line(exc)})') from None
        if header.profile != PROFILE:
            raise BagError(f'{path} is an MCAP file with profile {header.profile!r}, '
                           f'not a ROS 2 bag (profile {PROFILE!r})')
        mcap = _McapFile(path, header)
        try:
            indexed = _read_summary(stream, size, mcap)
        except Exception:
            # Any inconsistency in the summary: the data section is the ground truth.
            indexed = False
        if not indexed:
            mcap = _McapFile(path, header)
            _scan(stream, size, mcap)
        return mcap


def _read_summary(stream: BinaryIO, size: int, mcap: _McapFile) -> bool:
    """Fill ``mcap`` from the summary section; return False if the file has no usable one."""
    footer_offset = size - len(MAGIC) - _FOOTER_SIZE
    if footer_offset < len(MAGIC):
        return False
    stream.seek(size - len(MAGIC))
    if stream.read(len(MAGIC)) != MAGIC:
        return False
    record = _read_record(stream, footer_offset, size - len(MAGIC))
    if record is None or record[0] != Opcode.FOOTER:
        return False
    footer = _parse(*record)
    if not len(MAGIC) < footer.summary_start < footer_offset:
        return False
    statistics = None
    chunk_indexes: list[ChunkIndex] = []
    metadata_indexes: list[MetadataIndex] = []
    offset = footer.summary_start
    while offset < footer_offset:
        record = _read_record(stream, offset, footer_offset)
        if record is None:
            return False
        opcode, length, body = record
        if opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.CHUNK_INDEX,
                      Opcode.METADATA_INDEX, Opcode.STATISTICS):
            parsed = _parse(opcode, length, body)
            if isinstance(parsed, Schema):
                mcap.schemas[parsed.id] = parsed
            elif isinstance(parsed, Channel):
                mcap.channels[parsed.id] = parsed
            elif isinstance(parsed, ChunkIndex):
                chunk_indexes.append(parsed)
            elif isinstance(parsed, MetadataIndex):
                metadata_indexes.append(parsed)
            else:
                statistics = parsed
        offset += _PREFIX.size + length
    if statistics is None or (statistics.message_count and not chunk_indexes):
        # Messages outside chunks, or no statistics to count them: scan instead.
        return False
    mcap.counts.update({channel_id: count for channel_id, count
                        in statistics.channel_message_counts.items() if count})
    mcap.chunks = [
        _ChunkRef(index.chunk_start_offset, index.message_start_time,
                  frozenset(index.message_index_offsets) or None)
        for index in chunk_indexes]
    for index in metadata_indexes:
        record = _read_record(stream, index.offset, size)
        if record is None or record[0] != Opcode.METADATA:
            return False
        mcap.metadata.append(_parse(*record))
    return True


def _one_line(text: object) -> str:
    return ' '.join(str(text).split())


def _scan(stream: BinaryIO, size: int, mcap: _McapFile) -> None:
    """Fill ``mcap`` by reading records from the start, stopping at the first incomplete one."""
    offset = len(MAGIC)
    data_end = False
    problem = None
    while True:
        if offset == size:
            problem = 'not closed'
            break
        record = _read_record(stream, offset, size)
        if record is None:
            problem = 'cut'
            break
        opcode, length, body = record
        if opcode not in _KNOWN_OPCODES and opcode < 0x80:
            problem = f'damaged at byte {offset} (invalid record opcode {opcode:#04x})'
            break
        try:
            if opcode == Opcode.FOOTER:
                return
            if opcode == Opcode.DATA_END:
                data_end = True
            elif opcode == Opcode.CHUNK:
                _scan_chunk(_parse(opcode, length, body), offset, mcap)
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE, Opcode.METADATA):
                parsed = _parse(opcode, length, body)
                if isinstance(parsed, Schema):
                    mcap.schemas[parsed.id] = parsed
                elif isinstance(parsed, Channel):
                    mcap.channels[parsed.id] = parsed
                elif isinstance(parsed, Message):
                    mcap.loose.append((offset, parsed))
                    mcap.counts[parsed.channel_id] += 1
                else:
                    mcap.metadata.append(parsed)
        except Exception as exc:
            _reraise_interrupt(exc)
            problem = f'damaged at byte {offset} ({_one_line(exc) or type(exc).__name__})'
            break
        offset += _PREFIX.size + length
    name = mcap.path.name
    read = (f'read {_count(mcap.message_count, "message")} from '
            f'{_count(len(mcap.chunks), "complete chunk")}')
    if data_end:
        mcap.warning = (f'{name} is truncated after its data section: all '
                        f'{_count(mcap.message_count, "message")} were read, only the index '
                        'was lost')
    elif problem == 'cut':
        mcap.warning = (f'{name} is truncated: {read}; the rest is lost (the last '
                        f'{_count(size - offset, "byte")} are an incomplete record)')
    elif problem == 'not closed':
        mcap.warning = (f'{name} was not closed (no summary or footer): {read}; anything the '
                        'writer had not yet written is lost')
    else:
        mcap.warning = f'{name} is {problem}: {read}; the rest is lost'


def _reraise_interrupt(exc: BaseException) -> None:
    """Raise the ``KeyboardInterrupt`` that ``exc`` hides, if any.

    A stop signal whose handler raises while rclpy's deserialisation builds the message
    surfaces as pybind11's ``TypeError`` ("Unable to convert function return value ..."),
    chained from the ``KeyboardInterrupt``: the message is sound, the process was asked to
    stop, so the interrupt goes on rather than the message being reported as undecodable.

    :param exc: the exception the deserialisation raised.
    :raises KeyboardInterrupt: if ``exc`` was caused by one.
    """
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            raise KeyboardInterrupt from None
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}{'' if number == 1 else 's'}"


def _scan_chunk(chunk: Chunk, offset: int, mcap: _McapFile) -> None:
    """Decompress and check a chunk, then take in its schemas, channels and message counts."""
    records = breakup_chunk(chunk, validate_crc=True)
    channel_ids = set()
    for record in records:
        if isinstance(record, Schema):
            mcap.schemas[record.id] = record
        elif isinstance(record, Channel):
            mcap.channels[record.id] = record
        elif isinstance(record, Message):
            channel_ids.add(record.channel_id)
    # Counted only once the whole chunk decoded, so a bad chunk adds nothing.
    for record in records:
        if isinstance(record, Message):
            mcap.counts[record.channel_id] += 1
    mcap.chunks.append(_ChunkRef(offset, chunk.message_start_time, frozenset(channel_ids)))


# A message record's fields before its data: channel id, sequence, log time, publish time.
_MESSAGE_HEAD = struct.Struct('<HIQQ')


def _message_key(found: tuple[int, int, int, int, bytes]) -> tuple[int, int]:
    return found[0], found[1]


@dataclass
class _Run:
    """An opened chunk's wanted messages, sorted, and the position of the next one."""

    messages: list[tuple[int, int, int, int, bytes]]
    position: int
    #: The messages' log times (sorted).
    times: list[int]


def _index_suffix(path: Path) -> tuple[str, int]:
    match = re.search(r'_(\d+)$', path.stem)
    if match is None:
        return path.stem, -1
    return path.stem[:match.start()], int(match.group(1))


class BagReader:
    """Read the topics, metadata and messages of a ROS 2 MCAP bag.

    :param path: a bag directory (``metadata.yaml`` is used when present, otherwise every
        ``*.mcap`` in it, in split order) or one ``.mcap`` file.
    :raises BagError: if the path is missing, holds no MCAP file, or a file is not a ROS 2
        MCAP bag.
    """

    def __init__(self, path: Path) -> None:
        """Open the bag and index its files (messages are read lazily)."""
        self._path = Path(path)
        self._bag_metadata: dict[str, Any] | None = None
        notes: list[str] = []
        self._files = [_open_mcap(file) for file in self._bag_files(notes)]
        notes += [file.warning for file in self._files if file.warning]
        self._recovered = any(file.warning for file in self._files)
        if self._bag_metadata is not None:
            listed = self._bag_metadata.get('message_count')
            found = sum(file.message_count for file in self._files)
            if self._recovered and isinstance(listed, int) and listed != found:
                notes.append(f'{METADATA_FILENAME} lists {listed} messages')
            elif isinstance(listed, int) and listed != found:
                # A sound set of files whose metadata says otherwise: edited, or written by
                # a faulty tool; the files are what is read.
                notes.append(f'{METADATA_FILENAME} lists {listed} messages but the files hold '
                             f'{found}; the files were read')
            version = self._bag_metadata.get('version')
            if isinstance(version, int) and version > METADATA_VERSION:
                notes.append(f'{METADATA_FILENAME} is version {version}, newer than the '
                             f'{METADATA_VERSION} this reader knows; its fields were read as '
                             f'version {METADATA_VERSION}\'s')
        self._warning = '; '.join(notes) or None
        self._classes: dict[str, type] = {}

    def _bag_files(self, notes: list[str]) -> list[Path]:
        path = self._path
        if not path.exists():
            raise BagError(f'no such bag: {path}')
        if not path.is_dir():
            return [path]
        files: list[Path] = []
        metadata_file = path / METADATA_FILENAME
        if metadata_file.is_file():
            try:
                info = yaml.safe_load(metadata_file.read_text(encoding='utf-8'))
                info = info['rosbag2_bagfile_information']
                storage = info['storage_identifier']
                relative = [str(name) for name in info['relative_file_paths']]
            except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as exc:
                notes.append(f'{METADATA_FILENAME} is unreadable ({_one_line(exc)}); '
                             'read the .mcap files of the directory instead')
            else:
                if storage != 'mcap':
                    raise BagError(f'{path} is a rosbag2 bag in storage {storage!r}; '
                                   'only mcap bags can be read')
                self._bag_metadata = info
                for name in relative:
                    # Bags from older rosbag2 versions list paths with the directory name.
                    candidates = [path / name, path / Path(name).name]
                    found = next((c for c in candidates if c.is_file()), None)
                    if found is None:
                        raise BagError(f'{path}: {name}, listed in {METADATA_FILENAME}, '
                                       'is missing')
                    files.append(found)
        if not files:
            files = sorted(path.glob('*.mcap'), key=_index_suffix)
        if not files:
            raise BagError(f'{path} is not a bag: it holds no .mcap file')
        return files

    @property
    def path(self) -> Path:
        """The path the bag was opened from."""
        return self._path

    @property
    def files(self) -> list[Path]:
        """The MCAP files read, in order."""
        return [file.path for file in self._files]

    @property
    def recovered(self) -> bool:
        """Whether a file was not properly closed, so messages may be missing."""
        return self._recovered

    @property
    def warning(self) -> str | None:
        """What went wrong and how much was read, in one line; None for a sound bag."""
        return self._warning

    @property
    def bag_metadata(self) -> dict[str, Any] | None:
        """``rosbag2_bagfile_information`` from ``metadata.yaml``, if the bag has one."""
        return self._bag_metadata

    @property
    def library(self) -> str:
        """The writer library named in the (first) MCAP header."""
        return self._files[0].header.library

    def topics(self) -> dict[str, str]:
        """Return the recorded topics and their message types, in channel order.

        :return: topic name to ``pkg/msg/Type``.
        """
        topics: dict[str, str] = {}
        for file in self._files:
            for channel in file.channels.values():
                schema = file.schemas.get(channel.schema_id)
                topics.setdefault(channel.topic, schema.name if schema else '')
        return topics

    def message_counts(self) -> dict[str, int]:
        """Return the number of (readable) messages per topic, zero counts included.

        :return: topic name to message count.
        """
        counts = dict.fromkeys(self.topics(), 0)
        for file in self._files:
            for channel_id, count in file.counts.items():
                channel = file.channels.get(channel_id)
                if channel is not None:
                    counts[channel.topic] += count
        return counts

    def metadata(self, name: str) -> dict[str, str] | None:
        """Return an MCAP metadata record by name (the last one written, as rosbag2 does).

        :param name: record name, such as ``rosbag2`` or a provenance record.
        :return: its key-value pairs, or None if the bag has no such record.
        """
        found = None
        for file in self._files:
            for record in file.metadata:
                if record.name == name:
                    found = dict(record.metadata)
        return found

    def messages(self, topics: Iterable[str] | str | None = None) -> Iterator[BagMessage]:
        """Iterate over the recorded messages in log-time order (file order among equals).

        :param topics: only these topics; all when None.
        :return: an iterator of :class:`BagMessage`.
        :raises BagError: if a chunk of a finished file turns out damaged.
        """
        return (BagMessage(topic, type_name, log_time, data, qos, publish_time)
                for log_time, (topic, type_name, qos), data, publish_time
                in self.records(topics))

    def records(self, topics: Iterable[str] | str | None = None
                ) -> Iterator[tuple[int, tuple[str, str, str], bytes, int]]:
        """Iterate over the messages as :meth:`messages` does, as plain tuples (for a reader
        of millions of messages: no object a message).

        :param topics: only these topics; all when None.
        :return: an iterator of ``(log time [ns], (topic, type name, offered QoS profiles),
            data, publish time [ns])``; the middle tuple is the same object for every
            message of a topic.
        :raises BagError: if a chunk of a finished file turns out damaged.
        """
        wanted = {topics} if isinstance(topics, str) else (
            None if topics is None else set(topics))
        streams = [self._file_messages(file, wanted) for file in self._files]
        if len(streams) == 1:
            return streams[0]
        return heapq.merge(*streams, key=lambda record: record[0])

    def decoded(self, topics: Iterable[str] | str | None = None,
                undecodable: Callable[[BagMessage, str], None] | None = None
                ) -> Iterator[tuple[BagMessage, Any]]:
        """Iterate over the messages with their deserialised rclpy objects.

        :param topics: only these topics; all when None.
        :param undecodable: called with a message whose bytes do not decode as its type
            (a faulty writer's, recorded as received) and the reason; the message is then
            skipped. ``None``: such a message raises.
        :return: an iterator of ``(BagMessage, message)`` pairs.
        :raises BagError: if a message type is not installed or a message does not decode
            (without ``undecodable``).
        """
        for message in self.messages(topics):
            try:
                decoded = self.decode(message)
            except UndecodableMessage as exc:
                if undecodable is None:
                    raise
                undecodable(message, exc.reason)
                continue
            yield message, decoded

    def decode(self, message: BagMessage) -> Any:
        """Return the deserialised rclpy object of one message of this bag.

        :param message: a message from :meth:`messages`.
        :return: the message object.
        :raises BagError: if its type is not installed.
        :raises UndecodableMessage: if its bytes do not decode as its type.
        :raises KeyboardInterrupt: a stop signal that came during the deserialisation.
        """
        cls = self._classes.get(message.type_name)
        if cls is None:
            try:
                cls = message_class(message.type_name)
            except (DefinitionNotFoundError, ValueError) as exc:
                raise BagError(f'cannot decode topic {message.topic}: {exc}') from None
            self._classes[message.type_name] = cls
        try:
            return deserialize_message(message.data, cls)
        except Exception as exc:
            _reraise_interrupt(exc)
            raise UndecodableMessage(message, _one_line(exc)) from None

    def _file_messages(self, file: _McapFile, wanted: set[str] | None
                       ) -> Iterator[tuple[int, tuple[str, str, str], bytes, int]]:
        """Merge one file's chunks by time, as the mcap library's indexed reader does.

        The messages come in the order of ``(log time, file offset of their chunk, index of
        the record in the chunk)``. A chunk's wanted messages, sorted so, are read off in a
        run for as long as no other chunk has an earlier one (chunks of one recording follow
        each other in time: one heap operation a chunk rather than two a message).
        """
        channels = {channel_id: channel for channel_id, channel in file.channels.items()
                    if wanted is None or channel.topic in wanted}
        described = {}
        for channel_id, channel in channels.items():
            schema = file.schemas.get(channel.schema_id)
            described[channel_id] = (channel.topic, schema.name if schema else '',
                                     channel.metadata.get('offered_qos_profiles', ''))
        # Heap entries: (time, file offset, index in chunk, item); -1 marks an unopened chunk,
        # which sorts before the messages of chunks further on at the same time. An opened
        # chunk's entry is its sorted messages with the position of the next one (_Run).
        heap: list[tuple[int, int, int, Any]] = []
        for chunk in file.chunks:
            if chunk.channel_ids is None or not chunk.channel_ids.isdisjoint(channels):
                heap.append((chunk.start_ns, chunk.offset, -1, chunk))
        for offset, message in file.loose:
            if message.channel_id in channels:
                heap.append((message.log_time, offset, 0, message))
        heapq.heapify(heap)
        with file.path.open('rb') as stream:
            size = file.path.stat().st_size
            while heap:
                _, offset, _, item = heapq.heappop(heap)
                if isinstance(item, _ChunkRef):
                    found = self._chunk_messages(stream, size, item, file, channels)
                    if found:
                        found.sort(key=_message_key)
                        heapq.heappush(heap, (found[0][0], offset, found[0][1],
                                              _Run(found, 0, [m[0] for m in found])))
                    continue
                if isinstance(item, Message):
                    yield (item.log_time, described[item.channel_id], item.data,
                           item.publish_time)
                    continue
                found, position, times = item.messages, item.position, item.times
                end = len(found)
                if heap:
                    # Up to the first message the heap's next entry comes before: one of a
                    # chunk further on (offset > ours) goes after ours at the same time.
                    after, other = heap[0][0], heap[0][1]
                    end = (bisect.bisect_right if other > offset else bisect.bisect_left)(
                        times, after, position)
                    end = max(end, position + 1)
                for log_time, _, channel_id, publish_time, data in found[position:end]:
                    yield log_time, described[channel_id], data, publish_time
                if end < len(found):
                    heapq.heappush(heap, (found[end][0], offset, found[end][1],
                                          _Run(found, end, times)))

    @staticmethod
    def _chunk_messages(stream: BinaryIO, size: int, chunk: _ChunkRef, file: _McapFile,
                        channels: dict[int, Channel]) -> list[tuple[int, int, int, int, bytes]]:
        """Return ``(log time, record index, channel id, publish time, data)`` of the messages
        of ``channels`` in a chunk, read straight from its (decompressed, CRC-checked) bytes.

        :raises BagError: if the chunk is damaged.
        """
        record = _read_record(stream, chunk.offset, size)
        try:
            if record is None or record[0] != Opcode.CHUNK:
                raise ValueError('no chunk record there')
            body, length = get_chunk_data_stream(_parse(*record), validate_crc=True)
            data = body.read(length)
            found = []
            offset = index = 0
            while offset < length:
                opcode, record_length = _PREFIX.unpack_from(data, offset)
                start = offset + _PREFIX.size
                offset = start + record_length
                if offset > length:
                    raise ValueError(f'a record of {record_length} bytes runs past the end '
                                     'of the chunk')
                if opcode == Opcode.MESSAGE:
                    if record_length < _MESSAGE_HEAD.size:
                        raise ValueError(f'a message record of {record_length} bytes')
                    channel_id, _, log_time, publish_time = _MESSAGE_HEAD.unpack_from(data,
                                                                                      start)
                    if channel_id in channels:
                        found.append((log_time, index, channel_id, publish_time,
                                      data[start + _MESSAGE_HEAD.size:offset]))
                index += 1
            return found
        except Exception as exc:
            _reraise_interrupt(exc)
            raise BagError(f'{file.path}: chunk at byte {chunk.offset} is damaged '
                           f'({_one_line(exc)})') from None
