"""Writing a run's results: ``summary.json``, ``timeseries.npz`` and strict JSON text.

The file side of :mod:`flock_swarm.core.run` (which does no I/O), shared by ``sim``, the
world node, ``analyze`` and ``reproduce``; the files are described in ``docs/outputs.md``.
"""

import json
import math
from pathlib import Path
import shutil
import tempfile
from typing import BinaryIO

import numpy as np

from flock_swarm.core.run import Recorder, SimResult
from flock_swarm.core.scenario import Scenario


class SpooledRecorder(Recorder):
    """A :class:`~flock_swarm.core.run.Recorder` that streams each instant to disk.

    A long run's time series then costs no memory while it runs (the in-memory recorder
    holds a few kB of arrays per recorded instant, which a 30-minute realtime soak showed as
    0.25 MiB a minute). Each column goes to its own file of raw C-order values with the
    dtype and shape of its first row, in a hidden directory made in ``directory`` (the run's
    output directory, created if needed); :meth:`arrays` reads them back as the arrays the
    in-memory recorder stacks (the same values, dtypes and shapes), and :meth:`discard`
    removes the files once ``timeseries.npz`` is written. A killed process leaves them
    behind, holding every instant but what the files had buffered (a few kB each).

    :param directory: where the spool directory goes (made by :meth:`open`, or at the first
        instant).
    """

    def __init__(self, directory: Path) -> None:
        """Create the recorder; its spool directory is made by :meth:`open`."""
        super().__init__()
        self._parent = Path(directory)
        self._spool: Path | None = None
        # column -> [dtype, shape of one row, open file, rows written]
        self._columns: dict[str, list] = {}

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
        """Append one recorded instant to the columns' files.

        :raises ValueError: if a column's row changes shape, or has a type its first row's
            dtype cannot hold without the promotion stacking would have made.
        :raises OSError: if the spool cannot be written.
        """
        self.open()
        for key, value in values.items():
            row = np.asarray(value)
            column = self._columns.get(key)
            if column is None:
                stream: BinaryIO = (self._spool / f'{len(self._columns)}.bin').open('xb')
                column = self._columns[key] = [row.dtype, row.shape, stream, 0]
            dtype, shape, stream, _ = column
            if row.shape != shape:
                raise ValueError(f'time series column {key!r}: a row of shape {row.shape} '
                                 f'after rows of shape {shape}')
            if np.result_type(dtype, row.dtype) != dtype:
                raise ValueError(f'time series column {key!r}: a {row.dtype} row after '
                                 f'{dtype} rows')
            stream.write(np.ascontiguousarray(row, dtype=dtype).tobytes())
            column[3] += 1
        self.count += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """Read the recorded columns back as arrays (first axis: time).

        :raises OSError: if a spool file cannot be read.
        """
        out = {}
        for index, (key, (dtype, shape, stream, rows)) in enumerate(self._columns.items()):
            stream.flush()
            data = np.fromfile(self._spool / f'{index}.bin', dtype=dtype)
            out[key] = data.reshape((rows, *shape))
        return out

    def discard(self) -> None:
        """Close and remove the spool files (after ``timeseries.npz`` is written)."""
        for column in self._columns.values():
            column[2].close()
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
