"""Writing a run's results: ``summary.json``, ``timeseries.npz`` and strict JSON text.

The file side of :mod:`flock_swarm.core.run` (which does no I/O), shared by ``sim``, the
world node, ``analyze`` and ``reproduce``; the files are described in ``docs/outputs.md``.
"""

import json
import math
from pathlib import Path

import numpy as np

from flock_swarm.core.run import SimResult
from flock_swarm.core.scenario import Scenario


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
