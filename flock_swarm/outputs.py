"""Writing a run's results: ``summary.json``, ``timeseries.npz`` and strict JSON text.

The file side of :mod:`flock_swarm.core.run` (which does no I/O), shared by ``sim``, the
world node, ``analyze`` and ``reproduce``; the files are described in ``docs/outputs.md``.
"""

import json
import math
from pathlib import Path
import shutil
import tempfile
from typing import BinaryIO, Callable

import numpy as np

from flock_swarm.core.run import Recorder, SimResult
from flock_swarm.core.scenario import Scenario


class _Column:
    """One column of the spool: its row dtype and shape, its file, the rows in the file.

    :param path: the column's file (created), or ``None`` for a column kept in memory.
    """

    def __init__(self, path: Path | None, dtype: np.dtype, shape: tuple[int, ...]) -> None:
        self.path, self.dtype, self.shape = path, dtype, shape
        # Unbuffered: a row is in the file once add() returns, and a failed write is seen
        # at once (the file is then cut back to its whole rows).
        self.stream: BinaryIO | None = None if path is None else open(path, 'xb', buffering=0)
        self.rows = 0
        # Rows kept in memory after the spool failed.
        self.memory: list[np.ndarray] = []

    def write(self, row: np.ndarray) -> None:
        data = memoryview(np.ascontiguousarray(row, dtype=self.dtype).tobytes())
        while data:
            data = data[self.stream.write(data):]
        self.rows += 1

    def cut_back(self) -> None:
        """Close the file at its last whole row (a failed write may have left a part)."""
        try:
            self.stream.truncate(self.rows * self.dtype.itemsize * int(np.prod(self.shape)))
        finally:
            self.stream.close()
            self.stream = None


class SpooledRecorder(Recorder):
    """A :class:`~flock_swarm.core.run.Recorder` that streams each instant to disk.

    A long run's time series then costs no memory while it runs (the in-memory recorder
    holds a few kB of arrays per recorded instant, which a 30-minute realtime soak showed as
    0.13 MiB a minute). Each column goes to its own file of raw C-order values with the
    dtype and shape of its first row, in a hidden directory made in ``directory`` (the run's
    output directory, created if needed); :meth:`arrays` reads them back as the arrays the
    in-memory recorder stacks (the same values, dtypes and shapes), and :meth:`discard`
    removes the files once ``timeseries.npz`` is written. Rows are written unbuffered, so a
    killed process leaves every recorded instant in the files.

    When the spool cannot be written (a full disk, say), the files are cut back to their
    whole rows and closed, ``failed`` is called with the reason once, and the later instants
    are kept in memory: :meth:`arrays` still returns every instant.

    :param directory: where the spool directory goes (made by :meth:`open`, or at the first
        instant).
    :param failed: called with a one-line reason when the recorder falls back to memory.
    """

    def __init__(self, directory: Path, failed: Callable[[str], None] | None = None) -> None:
        """Create the recorder; its spool directory is made by :meth:`open`."""
        super().__init__()
        self._parent = Path(directory)
        self._failed = failed
        self._spool: Path | None = None
        self._columns: dict[str, _Column] = {}
        #: Why the spool was given up (``None``: it was not).
        self.error: str | None = None

    @property
    def spool(self) -> Path | None:
        """The directory holding the columns' files (``None`` before :meth:`open`)."""
        return self._spool

    def open(self) -> None:
        """Make the spool directory now (and ``directory`` if needed), if not yet made.

        :raises OSError: if the directory cannot be created or written.
        """
        if self._spool is None:
            self._parent.mkdir(parents=True, exist_ok=True)
            self._spool = Path(tempfile.mkdtemp(prefix='.timeseries-', dir=self._parent))

    def add(self, **values) -> None:
        """Append one recorded instant to the columns' files (or to memory, see above).

        :raises ValueError: if a column's row changes shape, or has a type its first row's
            dtype cannot hold without the promotion stacking would have made.
        """
        rows = {key: np.asarray(value) for key, value in values.items()}
        for key, row in rows.items():
            column = self._columns.get(key)
            if column is not None and row.shape != column.shape:
                raise ValueError(f'time series column {key!r}: a row of shape {row.shape} '
                                 f'after rows of shape {column.shape}')
            if column is not None and np.result_type(column.dtype, row.dtype) != column.dtype:
                raise ValueError(f'time series column {key!r}: a {row.dtype} row after '
                                 f'{column.dtype} rows')
        written = set()
        if self.error is None:
            try:
                self.open()
                for key, row in rows.items():
                    column = self._columns.get(key)
                    if column is None:
                        column = self._columns[key] = _Column(
                            self._spool / f'{len(self._columns)}.bin', row.dtype, row.shape)
                    column.write(row)
                    written.add(key)
            except OSError as exc:
                self._fall_back(exc)
        if self.error is not None:
            # The columns whose file did not take this instant's row keep it in memory.
            for key, row in rows.items():
                column = self._columns.get(key)
                if column is None:
                    column = self._columns[key] = _Column(None, row.dtype, row.shape)
                if key not in written:
                    column.memory.append(np.array(row, dtype=column.dtype, copy=True))
        self.count += 1

    def _fall_back(self, exc: OSError) -> None:
        self.error = f'cannot write the time series to {self._spool or self._parent}: ' \
            f'{exc.strerror or exc}; keeping it in memory'
        for column in self._columns.values():
            if column.stream is not None:
                try:
                    column.cut_back()
                except OSError:
                    pass
        if self._failed is not None:
            self._failed(self.error)

    def arrays(self) -> dict[str, np.ndarray]:
        """Read the recorded columns back as arrays (first axis: time).

        :raises OSError: if a spool file cannot be read.
        """
        out = {}
        for key, column in self._columns.items():
            parts = []
            if column.rows:
                data = np.fromfile(column.path, dtype=column.dtype,
                                   count=column.rows * int(np.prod(column.shape)))
                parts.append(data.reshape((column.rows, *column.shape)))
            if column.memory:
                parts.append(np.stack(column.memory))
            out[key] = parts[0] if len(parts) == 1 else np.concatenate(parts)
        return out

    def discard(self) -> None:
        """Close and remove the spool files (after ``timeseries.npz`` is written)."""
        for column in self._columns.values():
            if column.stream is not None:
                column.stream.close()
        self._columns.clear()
        if self._spool is not None:
            shutil.rmtree(self._spool, ignore_errors=True)
            self._spool = None


def write_outputs(result: SimResult, out: Path, sc: Scenario) -> None:
    """Write ``summary.json``, ``timeseries.npz`` and the scenario used, into ``out``.

    :param result: the run.
    :param out: the output directory (created).
    :param sc: the scenario (its mapping is written as ``scenario.json`` for provenance).
    """
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / 'timeseries.npz', **result.series)
    (out / 'scenario.json').write_text(json_text(sc.raw))
    # summary.json last: its presence means the other files are complete.
    tmp = out / 'summary.json.tmp'
    tmp.write_text(json_text(result.summary))
    tmp.replace(out / 'summary.json')


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
    """Return ``value`` with NumPy values as Python ones and non-finite floats as ``None``.

    ``json.dumps`` writes ``inf`` and ``nan`` as ``Infinity`` and ``NaN``, which are not JSON
    (and it never asks a ``default`` hook about floats), so values are cleaned first.
    """
    if isinstance(value, dict):
        return {key: plain_json(item) for key, item in value.items()}
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
