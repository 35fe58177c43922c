"""Writing a run's results: ``summary.json``, ``timeseries.npz`` and strict JSON text.

The file side of :mod:`flock_swarm.core.run` (which does no I/O), shared by ``sim``, the
world node, ``analyze`` and ``reproduce``; the files are described in ``docs/outputs.md``.
"""

import json
import math
import os
from pathlib import Path
import shutil
import tempfile
from typing import BinaryIO, Callable

import numpy as np

from flock_swarm.core.run import Recorder, RunResult
from flock_swarm.core.scenario import Scenario


class SpooledRecorder(Recorder):
    """A :class:`~flock_swarm.core.run.Recorder` that streams each instant to disk.

    A long run's time series then costs no memory while it runs (the in-memory recorder
    holds a few kB of arrays per recorded instant: 0.13 MiB a minute of the realtime soak,
    ``bench/bench_memory.py``). Each instant is one fixed-size record of raw values (a NumPy
    structured dtype with one field per column, of the dtype and shape of the first
    instant's row), appended with one unbuffered write to ``rows.bin`` in a hidden directory
    made in ``directory`` (the run's output directory, created if needed). :meth:`arrays`
    reads them back as the arrays the in-memory recorder stacks (the same values, dtypes and
    shapes), and :meth:`discard` removes the directory once ``timeseries.npz`` is written.
    A killed process leaves every recorded instant in the file.

    When the file cannot be written (a full disk, say), it is cut back to its whole records
    and closed, ``failed`` is called with the reason once, and the later instants are kept
    in memory: :meth:`arrays` still returns every instant.

    :param directory: where the spool directory goes (made by :meth:`open`, or at the first
        instant).
    :param failed: called with a one-line reason when the recorder falls back to memory.
    """

    #: The records' file in the spool directory.
    FILENAME = 'rows.bin'

    def __init__(self, directory: Path, failed: Callable[[str], None] | None = None) -> None:
        """Create the recorder; its spool directory is made by :meth:`open`."""
        super().__init__()
        self._parent = Path(directory)
        self._failed = failed
        self._spool: Path | None = None
        self._stream: BinaryIO | None = None
        # The record layout, fixed by the first instant.
        self._record: np.dtype | None = None
        self._on_disk = 0
        # Records kept in memory after the spool failed.
        self._memory: list[np.ndarray] = []
        #: Why the spool was given up (``None``: it was not).
        self.error: str | None = None

    @property
    def spool(self) -> Path | None:
        """The directory holding ``rows.bin`` (``None`` before :meth:`open`)."""
        return self._spool

    def open(self) -> None:
        """Make the spool directory now (and ``directory`` if needed), if not yet made.

        :raises OSError: if the directory cannot be created or written.
        """
        if self._spool is None:
            self._parent.mkdir(parents=True, exist_ok=True)
            self._spool = Path(tempfile.mkdtemp(prefix='.timeseries-', dir=self._parent))

    def add(self, **values) -> None:
        """Append one recorded instant to the file (or to memory, see above).

        :raises ValueError: if the instant's columns are not the first instant's, a row
            changes shape, or has a type its column's dtype cannot hold without the
            promotion stacking would have made.
        """
        rows = {key: np.asarray(value) for key, value in values.items()}
        if self._record is None:
            self._record = np.dtype([(key, row.dtype, row.shape) for key, row in rows.items()])
        fields = self._record.fields
        if set(rows) != set(fields):
            raise ValueError(f'time series columns {sorted(rows)} are not the first '
                             f'instant\'s {sorted(fields)}')
        record = np.zeros((), dtype=self._record)
        for key, row in rows.items():
            field = fields[key][0]
            dtype, shape = field.subdtype or (field, ())
            if row.shape != shape:
                raise ValueError(f'time series column {key!r}: a row of shape {row.shape} '
                                 f'after rows of shape {shape}')
            if np.result_type(dtype, row.dtype) != dtype:
                raise ValueError(f'time series column {key!r}: a {row.dtype} row after '
                                 f'{dtype} rows')
            record[key] = row
        if self.error is None:
            try:
                self._write(record.tobytes())
                self._on_disk += 1
            except OSError as exc:
                self._fall_back(exc)
        if self.error is not None:
            self._memory.append(record)
        self.count += 1

    def _write(self, data: bytes) -> None:
        if self._stream is None:
            self.open()
            # Unbuffered: a record is in the file once add() returns, and a failed write is
            # seen at once.
            self._stream = open(self._spool / self.FILENAME, 'xb', buffering=0)
        view = memoryview(data)
        while view:
            view = view[self._stream.write(view):]

    def _fall_back(self, exc: OSError) -> None:
        self.error = f'cannot write the time series to {self._spool or self._parent}: ' \
            f'{exc.strerror or exc}; keeping it in memory'
        if self._stream is not None:
            try:
                # A failed write may have left part of a record.
                self._stream.truncate(self._on_disk * self._record.itemsize)
            except OSError:
                pass
            finally:
                self._stream.close()
                self._stream = None
        if self._failed is not None:
            self._failed(self.error)

    def arrays(self) -> dict[str, np.ndarray]:
        """Read the recorded columns back as arrays (first axis: time).

        :raises OSError: if the spool file cannot be read.
        """
        if self._record is None:
            return {}
        parts = []
        if self._on_disk:
            parts.append(np.fromfile(self._spool / self.FILENAME, dtype=self._record,
                                     count=self._on_disk))
        if self._memory:
            parts.append(np.stack(self._memory))
        table = parts[0] if len(parts) == 1 else np.concatenate(parts)
        return {key: np.ascontiguousarray(table[key]) for key in self._record.names}

    def close(self) -> None:
        """Close the file, keeping it (when ``timeseries.npz`` could not be written)."""
        if self._stream is not None:
            self._stream.close()
            self._stream = None

    def discard(self) -> None:
        """Close and remove the spool (after ``timeseries.npz`` is written)."""
        self.close()
        if self._spool is not None:
            shutil.rmtree(self._spool, ignore_errors=True)
            self._spool = None


def write_outputs(result: RunResult, out: Path, sc: Scenario) -> list[Path]:
    """Write ``timeseries.npz``, the scenario used and ``summary.json`` into ``out``.

    Each file is written whole under a temporary name and renamed into place
    (:func:`write_atomically`), ``summary.json`` last: its presence means the other files
    are complete, and a failed write (a full disk) leaves no file that looks valid.

    A run that recorded no instant (stopped before its first step) has no time series: no
    ``timeseries.npz`` is written, rather than an archive without arrays.

    :param result: the run.
    :param out: the output directory (created).
    :param sc: the scenario (its mapping is written as ``scenario.json`` for provenance).
    :return: the files written.
    :raises OSError: naming the file that could not be written (``filename``); the files
        before it are written.
    """
    out.mkdir(parents=True, exist_ok=True)
    series = [write_timeseries(out / 'timeseries.npz', result.series)] if result.series else []
    return series + [write_text(out / 'scenario.json', json_text(sc.raw)),
                     write_text(out / 'summary.json', json_text(result.summary))]


def write_atomically(path: Path, write: Callable[[BinaryIO], None]) -> Path:
    """Write ``path`` through a temporary file next to it, renamed into place once whole.

    So ``path`` is either complete or as it was: a write that fails (a full disk) removes
    the temporary file and leaves no truncated or empty file that would look valid.

    :param path: the file.
    :param write: writes the content into the binary file it is given.
    :return: ``path``.
    :raises OSError: when it cannot be written, its ``filename`` the path (not the
        temporary name) and its ``strerror`` the reason.
    """
    path = Path(path)
    tmp = path.with_name(f'.{path.name}.tmp')
    try:
        with open(tmp, 'wb') as stream:
            write(stream)
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
        raise
    return path


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`write_atomically`)."""
    return write_atomically(path, lambda stream: stream.write(text.encode('utf-8')))


def write_timeseries(path: Path, series: dict[str, np.ndarray]) -> Path:
    """Write a time series as a compressed ``.npz`` atomically (:func:`write_atomically`)."""
    return write_atomically(path, lambda stream: np.savez_compressed(stream, **series))


def write_error(exc: OSError) -> str:
    """Return ``cannot write FILE: REASON``, the line of a failed write."""
    return f'cannot write {exc.filename}: {exc.strerror or exc}'


def ensure_writable(out: Path) -> None:
    """Create ``out`` if needed and check that files can be written there.

    :param out: a directory.
    :raises OSError: when it cannot be created or written.
    """
    out.mkdir(parents=True, exist_ok=True)
    probe = out / '.write_test'
    probe.write_text('')
    probe.unlink()


def plain_json(value):
    """Return ``value`` as JSON reads it back: NumPy values as Python ones, tuples and arrays
    as lists, mapping keys as strings, non-finite floats as ``None``.

    ``json.dumps`` writes ``inf`` and ``nan`` as ``Infinity`` and ``NaN``, which are not JSON
    (and it never asks a ``default`` hook about floats), so values are cleaned first. The one
    such routine: outputs, a sweep's cache and digests, the reproduction's results.
    """
    if isinstance(value, dict):
        return {str(key): plain_json(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_json(item) for item in value]
    if isinstance(value, np.ndarray):
        return plain_json(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def json_text(value, indent: int | None = 2) -> str:
    """Return strict JSON for ``value`` (see :func:`plain_json`), with a final newline."""
    return json.dumps(plain_json(value), indent=indent, allow_nan=False) + '\n'
