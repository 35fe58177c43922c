"""The one place that reaches into ``mcap``'s private writer: its open chunk, for batched writes.

``mcap.writer.Writer`` keeps its chunk builder, statistics, chunk indexes and output stream in
name-mangled attributes (``_Writer__...``). ``BagWriter.write_serialized_batch`` writes a
lockstep step's messages straight into the open chunk, the same bytes as one
``Writer.add_message`` each (tested byte for byte), at a fraction of the cost. Only this
module names those attributes. :func:`open_chunk` hands them out only for the ``mcap`` release
series they were read from (:data:`MCAP_SERIES`, the one ``requirements/run.txt`` pins) and
only when every part is there; otherwise the writer takes ``mcap``'s public path.
"""

from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from io import BytesIO
from typing import Any

from mcap.writer import IndexType, Writer

#: The ``mcap`` release series (major.minor) whose private writer this module reads.
MCAP_SERIES = '1.6'
#: The private attributes of ``Writer`` used here (without the ``_Writer__`` prefix).
WRITER_PARTS = ('chunk_builder', 'statistics', 'chunk_size', 'chunk_indices',
                'maybe_finalize_chunk', 'stream', 'record_builder', 'flush', 'index_types')


@lru_cache(maxsize=None)
def installed_mcap() -> str:
    """Return the installed ``mcap`` version (``''`` when its metadata is not found; read
    once)."""
    try:
        return version('mcap')
    except PackageNotFoundError:
        return ''


class OpenChunk:
    """The private parts of one ``mcap`` writer that a batched write uses.

    :param writer: the writer (its parts are read when used: ``mcap`` resets the chunk
        builder in place, and may swap its buffer, when a chunk is finished).
    """

    def __init__(self, writer: Writer) -> None:
        self._writer = writer

    def _part(self, name: str) -> Any:
        return getattr(self._writer, f'_Writer__{name}')

    @property
    def builder(self) -> Any:
        """Return the chunk builder (``num_messages``, message times, ``message_indices``)."""
        return self._part('chunk_builder')

    @property
    def statistics(self) -> Any:
        """Return the writer's statistics (message count, times, per-channel counts)."""
        return self._part('statistics')

    @property
    def limit(self) -> int:
        """Return the chunk size after which the writer finishes a chunk."""
        return self._part('chunk_size')

    def buffer(self) -> BytesIO:
        """Return the open chunk's record buffer."""
        return self.builder.record_writer._buffer

    def chunk_count(self) -> int:
        """Return how many chunks the writer has finished."""
        return len(self._part('chunk_indices'))

    def finalize(self) -> None:
        """Let the writer finish the open chunk if it is over the chunk size."""
        self._part('maybe_finalize_chunk')()

    def write_message_indexes(self, data: bytes, channels: list[int],
                              offsets: list[int]) -> None:
        """Write the message index records ``data`` after the chunk just finished, and enter
        their offsets in its ChunkIndex as the writer would.

        :param data: the records, one per channel, in ``channels`` order.
        :param channels: the channel ids.
        :param offsets: each record's offset within ``data``.
        """
        start = self._part('stream').tell()
        chunk_index = self._part('chunk_indices')[-1]
        chunk_index.message_index_offsets.update(zip(channels, (o + start for o in offsets)))
        chunk_index.message_index_length = len(data)
        self._part('record_builder').write(data)
        self._part('flush')()


def open_chunk(writer: Writer, mcap_version: str | None = None) -> OpenChunk | None:
    """Return the writer's open chunk, or ``None`` where a batched write must take the public
    path: another ``mcap`` series than :data:`MCAP_SERIES`, a part missing, or chunking or
    message indexes off.

    :param writer: the writer.
    :param mcap_version: the ``mcap`` version to check (default: the installed one).
    """
    found = installed_mcap() if mcap_version is None else mcap_version
    if found.split('.')[:2] != MCAP_SERIES.split('.'):
        return None
    if any(not hasattr(writer, f'_Writer__{name}') for name in WRITER_PARTS):
        return None
    chunk = OpenChunk(writer)
    stats = chunk.statistics
    if getattr(getattr(chunk.builder, 'record_writer', None), '_buffer', None) is None \
            or not isinstance(chunk.limit, int) \
            or not hasattr(stats, 'channel_message_counts') \
            or not hasattr(chunk.builder, 'message_indices') \
            or not chunk._part('index_types') & IndexType.MESSAGE:
        return None
    return chunk
