"""The world's time series streamed to disk: the same arrays as in memory, no rows kept."""

import re
import tracemalloc

import numpy as np
import pytest

from flock_swarm.core.run import Recorder
from flock_swarm.core.scenario import parse_scenario
from flock_swarm.outputs import SpooledRecorder
from flock_swarm.presets import load
from flock_swarm.core.run import simulate


def rows_of(series: dict[str, np.ndarray]) -> list[dict]:
    """Split a time series into the per-instant rows a RunLog records."""
    count = len(series['t'])
    return [{key: (values[k].item() if values.ndim == 1 else values[k])
             for key, values in series.items()} for k in range(count)]


@pytest.fixture(scope='module')
def adaptive_series():
    """A real run's series with every kind of column: floats, booleans, adaptive gains h."""
    sc = parse_scenario(dict(load('zhou2012_sec51').raw, duration=0.2, record_every=1))
    series = simulate(sc).series
    assert 'h' in series and series['informed'].dtype == bool
    return series


def test_spooled_arrays_equal_the_in_memory_ones(adaptive_series, tmp_path):
    """Values, dtypes and shapes: what np.stack of the rows gives, column by column."""
    memory, spooled = Recorder(), SpooledRecorder(tmp_path)
    for row in rows_of(adaptive_series):
        memory.add(**row)
        spooled.add(**row)
    expected, got = memory.arrays(), spooled.arrays()
    assert spooled.count == memory.count == len(adaptive_series['t'])
    assert list(got) == list(expected)
    for key in expected:
        assert got[key].dtype == expected[key].dtype, key
        assert got[key].shape == expected[key].shape, key
        np.testing.assert_array_equal(got[key], expected[key], err_msg=key)
        np.testing.assert_array_equal(got[key], adaptive_series[key], err_msg=key)


def test_rows_are_on_disk_not_in_memory(tmp_path):
    """Each instant's bytes are in the spool files; the recorder's memory does not grow."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(10, 2))
    rec = SpooledRecorder(tmp_path)
    rec.add(t=0.0, q=q, informed=q[:, 0] > 0)
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for k in range(1, 2001):
        rec.add(t=k * 0.02, q=q + k, informed=q[:, 0] > 0)
    grown = sum(stat.size_diff for stat in
                tracemalloc.take_snapshot().compare_to(before, 'filename'))
    tracemalloc.stop()
    # 2000 instants of 10 x 2 positions are 320 kB of float64: none of it stays in memory
    # (the files' write buffers are a few kB, and were allocated at the first instant).
    assert grown < 20_000
    assert rec.rows == {}
    got = rec.arrays()
    # Read back through the file: one record an instant of t (8 bytes), q (160 bytes) and
    # informed (10 booleans).
    assert [path.stat().st_size for path in rec.spool.iterdir()] == [2001 * (8 + 160 + 10)]
    np.testing.assert_array_equal(got['q'][-1], q + 2000)
    assert got['t'][-1] == 2000 * 0.02


def test_discard_removes_the_spool(tmp_path):
    rec = SpooledRecorder(tmp_path / 'out')
    rec.add(t=0.0, q=np.zeros((3, 2)))
    spool = rec.spool
    assert spool.parent == tmp_path / 'out' and spool.name.startswith('.timeseries-')
    rec.discard()
    assert not spool.exists() and rec.spool is None
    assert list((tmp_path / 'out').iterdir()) == []


@pytest.mark.parametrize('second, message', [
    ({'q': np.zeros((4, 2))}, "column 'q': a row of shape (4, 2) after rows of shape (3, 2)"),
    ({'q': np.zeros((3, 2), dtype=complex)}, "column 'q': a complex128 row after float64"),
    ({'q': np.zeros((3, 2)), 'h': 1.0}, "columns ['h', 'q'] are not the first instant's"),
])
def test_a_row_that_does_not_fit_its_column_is_refused(tmp_path, second, message):
    rec = SpooledRecorder(tmp_path)
    rec.add(q=np.zeros((3, 2)))
    with pytest.raises(ValueError, match=re.escape(message)):
        rec.add(**second)
