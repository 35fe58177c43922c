"""The one comparison of two runs (flock_swarm.analysis.compare): reference first, then the run.

The testing API's ``compare_runs`` gives its problems (test_testing.py); the reproduction reads
its largest deviations and the metrics side by side.
"""

import numpy as np
import pytest

from flock_swarm.analysis.compare import compare_runs
from flock_swarm.testing import compare_runs as api_compare_runs


def runs():
    """Return a reference run and a run 1e-7 off it in ``q``, with one key of its own."""
    rng = np.random.default_rng(3)
    reference = {'eta': 1.0, 'collisions': 0, 'status': 'completed'}
    ref_series = {'t': np.arange(4) * 0.1, 'q': rng.normal(size=(4, 3, 2)),
                  'p': rng.normal(size=(4, 3, 2)), 'informed': np.array([True, False, True])}
    summary = dict(reference, eta=0.5, missed_commands=0)
    series = {k: v.copy() for k, v in ref_series.items()}
    series['q'] = series['q'] + 1e-7
    return reference, ref_series, summary, series


def test_the_reference_comes_first():
    reference, ref_series, summary, series = runs()
    comparison = compare_runs(reference, ref_series, summary, series, atol=1e-6)
    # eta differs; the run's own key (missed_commands) is no difference, but a key the
    # reference has and the run lacks is.
    assert comparison.problems == ['summary eta: got 0.5, want 1.0 (atol 1e-06)']
    assert not comparison.matches
    swapped = compare_runs(summary, series, reference, ref_series, atol=1e-6)
    assert 'summary missed_commands: missing' in swapped.problems


def test_the_largest_deviation_of_every_float_series():
    reference, ref_series, summary, series = runs()
    comparison = compare_runs(reference, ref_series, summary, series)
    assert comparison.same_instants
    want = float(np.abs(series['q'] - ref_series['q']).max())
    assert comparison.max_deviation['q'] == want and want > 0
    assert comparison.max_deviation['p'] == 0.0 and comparison.max_deviation['t'] == 0.0
    assert 'informed' not in comparison.max_deviation
    assert [line.split(':')[0] for line in comparison.problems] == ['summary eta', 'series q']


def test_runs_of_other_instants_have_no_deviation():
    reference, ref_series, summary, series = runs()
    shorter = {k: (v[:3] if k != 'informed' else v) for k, v in series.items()}
    del shorter['p']
    comparison = compare_runs(reference, ref_series, summary, shorter)
    assert not comparison.same_instants
    assert comparison.max_deviation['q'] is None and comparison.max_deviation['p'] is None
    assert 'series p: missing' in comparison.problems
    assert 'series q: shape (3, 3, 2), want (4, 3, 2)' in comparison.problems


def test_side_by_side_labels_each_run():
    reference, ref_series, summary, series = runs()
    comparison = compare_runs(reference, ref_series, summary, series)
    assert comparison.side_by_side(('eta', 'collisions', 'absent'), 'sim', 'ros') == {
        'sim_eta': 1.0, 'ros_eta': 0.5, 'sim_collisions': 0, 'ros_collisions': 0,
        'sim_absent': None, 'ros_absent': None}


@pytest.mark.parametrize('atol', [0.0, 1e-6])
def test_the_testing_api_gives_the_same_problems(atol):
    reference, ref_series, summary, series = runs()
    assert api_compare_runs(reference, ref_series, summary, series, atol) == \
        compare_runs(reference, ref_series, summary, series, atol).problems


def test_a_sim_summary_read_from_disk_is_compared_without_its_sim_only_keys(tmp_path):
    """``sim``'s summary.json (with ``pseudo_leader_reselections`` and ``wall_time_s``,
    which only sim writes) against a run that lacks them: no 'missing' for those (each
    comparison read from disk reported ``pseudo_leader_reselections: missing``); the other
    keys are still compared."""
    import json
    from flock_swarm.cli.sim import main
    out = tmp_path / 'sim'
    assert main(['demo', '--set', 'duration=0.2', '--out', str(out), '--quiet']) == 0
    reference = json.loads((out / 'summary.json').read_text())
    with np.load(out / 'timeseries.npz') as data:
        series = {key: data[key] for key in data.files}
    assert {'pseudo_leader_reselections', 'wall_time_s'} <= set(reference)
    run = {k: v for k, v in reference.items()
           if k not in ('pseudo_leader_reselections', 'wall_time_s')}
    assert compare_runs(reference, series, run, series).problems == []
    assert compare_runs(reference, series, dict(run, eta=-1.0), series).problems == [
        f'summary eta: got -1.0, want {reference["eta"]!r} (atol 0)']
