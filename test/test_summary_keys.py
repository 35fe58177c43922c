"""The table of summary keys: it drives the summary, the sweep's metrics, the comparisons and
the documentation, so that a new key is one new row."""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flock_swarm import testing
from flock_swarm.core import run, summary
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.run import simulate
from flock_swarm.core.summary import SUMMARY_KEYS, SummaryKey
from flock_swarm.presets import load, preset_names
from flock_swarm.study import execute, spec

DOCS = Path(__file__).resolve().parents[1] / 'docs' / 'outputs.md'
NAMES = [k.name for k in SUMMARY_KEYS]
#: Runs that between them write every key the core computes (the certificate needs a
#: pseudo-leader selection, the adaptive gains Zhou's law, the network statistics a
#: ``network:`` section).
RUNS = [(name, []) for name in preset_names()] + [
    ('zhou2012_sec52', ['informed={select: pseudo_leaders}']),
    ('demo', ['network={delay: 0.04, loss: 0.1}']),
    ('demo', ['obstacles={spheres: [{centre: [-20, -20], radius: 1}]}'])]
#: Keys only a run with their section writes.
CONDITIONAL = {'pseudo_leader_certificate', 'network_delivered', 'network_age_mean',
               'network_age_max', 'obstacle_clearance_min', 'obstacle_penetrations',
               'obstacle_collisions'}


@pytest.fixture(scope='module')
def summaries():
    """Return the summary of 20 steps of every preset (and one pseudo-leader selection)."""
    out = []
    for name, overrides in RUNS:
        dt = load(name).dt
        out.append(simulate(load(name, [*overrides, f'duration={20 * dt!r}'])).summary)
    # A run whose law gives a non-finite command writes the key telling the failure.
    sc = load('demo', ['n_agents=5', 'informed.count=2', 'duration=0.5'])
    calls, real_control = [], run.swarm_control

    def nan_from_step_3(*args):
        calls.append(1)
        u = real_control(*args)
        return u * np.nan if len(calls) > 3 else u
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(run, 'swarm_control', nan_from_step_3)
        failed = simulate(sc).summary
    assert failed['status'] == 'failed'
    out.append(failed)
    # sim --backend mujoco: the engine tells the robots' contacts.
    from functools import partial

    from flock_swarm.engine.backend import EngineBackend
    from test_robots_ros import FLEET_FILE
    out.append(simulate(load(str(FLEET_FILE), ['duration=0.2']),
                        integrator=partial(EngineBackend, 'unicycle')).summary)
    return out


def test_the_table_is_well_formed():
    assert len(set(NAMES)) == len(NAMES)
    for key in SUMMARY_KEYS:
        assert key.kind in summary.KINDS, key
        assert key.description and key.writers, key
        assert set(key.writers) <= set(summary.EVERY_RUN), key
        assert not key.default or key.sweep, f'{key.name}: a default metric is sweepable'
        assert key.series is None or key.sweep, key


def test_every_key_sim_writes_is_in_the_table_in_its_order(summaries):
    computed = {k.name for k in SUMMARY_KEYS if k.value is not None}
    written = set()
    for s in summaries:
        assert list(s) == [n for n in NAMES if n in s], 'summary.json follows the table order'
        assert set(s) <= set(NAMES)
        written |= set(s)
        # Every key the core computes for any run is there unless the run has nothing for it.
        assert computed - CONDITIONAL <= set(s)
    # ... and between them the runs write every row whose writers include sim.
    assert written == {k.name for k in SUMMARY_KEYS if summary.SIM in k.writers}


def test_the_summary_of_the_table_with_every_given_key_is_the_whole_table():
    from flock_swarm.core.metrics import RunMetrics
    from flock_swarm.core.obstacles import ObstacleMetrics, ObstacleSpec
    from flock_swarm.core.pseudo_leaders import PseudoLeaderSelection
    facts = summary.RunFacts(3, 0.1, 0.2, 0.3, 'x', 4, 'law',
                             PseudoLeaderSelection((0,), -1.0, 0.5, True, 1), {'h': 'gain_h'})
    series = {'t': np.array([0.0, 0.1]), 'informed': np.array([[True, False, True]] * 2),
              'h': np.ones((2, 3)), **{f'metric_{m}': np.zeros(2) for m in
                                       ('eta', 'velocity_mismatch_max', 'com_position_error',
                                        'com_velocity_error', 'min_pair_distance',
                                        'components')},
              **{f'network_{m}': np.ones(2) for m in ('delivered', 'age_mean', 'age_max')}}
    given = {k.name: k.name for k in SUMMARY_KEYS if k.value is None and k.kind != 'law state'}
    run_metrics = RunMetrics(0.3)
    run_metrics.obstacles = ObstacleMetrics(ObstacleSpec(spheres=(((0.0, 0.0), 1.0),)), 0.3)
    out = summary.summary_of(summary.SummaryInputs(facts, series, run_metrics, 1,
                                                   'completed'), **given)
    # The law's own state key stands where the table's law-state row is.
    assert list(out) == [('gain_h' if n == 'adaptive_gain_final' else n) for n in NAMES]
    assert out['informed'] == [0, 2] and out['gain_h'] == [1.0, 1.0, 1.0]
    with pytest.raises(KeyError, match='not a given key of the summary table: speed'):
        summary.summary_of(summary.SummaryInputs(facts, series, RunMetrics(0.3), 1, 'x'),
                           speed=1.0)


def test_the_sweep_metrics_and_the_comparisons_come_from_the_table():
    assert spec.SUMMARY_METRICS == summary.sweep_metrics() == (
        'eta', 'velocity_mismatch_max', 'com_position_error', 'com_velocity_error',
        'min_pair_distance', 'collisions', 'components_final', 'network_delivered',
        'network_age_mean', 'network_age_max', 'obstacle_clearance_min',
        'obstacle_penetrations', 'obstacle_collisions', 'n_agents', 't_final', 'steps',
        'pseudo_leader_reselections')
    assert spec.TIMED_METRICS == summary.timed_series() == {
        'eta': 'metric_eta', 'velocity_mismatch_max': 'metric_velocity_mismatch_max',
        'com_position_error': 'metric_com_position_error',
        'com_velocity_error': 'metric_com_velocity_error',
        'min_pair_distance': 'metric_min_pair_distance',
        'components_final': 'metric_components', 'network_delivered': 'network_delivered',
        'network_age_mean': 'network_age_mean', 'network_age_max': 'network_age_max',
        'obstacle_clearance_min': 'obstacle_clearance'}
    assert spec.DEFAULT_METRICS == summary.default_metrics() == (
        'eta', 'velocity_mismatch_max', 'collisions', 'components_final')
    assert set(testing.SIM_ONLY) == set(summary.sim_only_keys()) == {
        'wall_time_s', 'pseudo_leader_reselections'}
    assert summary.compared_metrics() == (
        'eta', 'velocity_mismatch_max', 'com_position_error', 'com_velocity_error',
        'min_pair_distance', 'collisions', 'components_final', 'network_delivered',
        'network_age_mean', 'network_age_max', 'obstacle_clearance_min',
        'obstacle_penetrations', 'obstacle_collisions')


def speed_final(inputs):
    """A new key: the mean speed of the agents at the last recorded instant."""
    return float(np.linalg.norm(inputs.series['p'][-1], axis=1).mean())


def test_adding_a_summary_key_touches_one_table(monkeypatch, tmp_path):
    """One new row: sim writes the key in its place, and a sweep may collect it."""
    row = SummaryKey('speed_final', summary.FINAL, 'mean speed at `t_final` [m/s]', speed_final,
                     sweep=True)
    at = NAMES.index('components_final') + 1
    monkeypatch.setattr(summary, 'SUMMARY_KEYS', SUMMARY_KEYS[:at] + (row,) + SUMMARY_KEYS[at:])
    result = simulate(load('demo', ['duration=0.5']))
    keys = list(result.summary)
    assert keys[keys.index('components_final') + 1] == 'speed_final'
    assert result.summary['speed_final'] == pytest.approx(
        np.linalg.norm(result.series['p'][-1], axis=1).mean(), rel=1e-12)
    # The sweep: a spec may name it, and the record of a run collects it.
    parsed = spec.parse_spec({'scenario': 'demo', 'metrics': ['eta', 'speed_final']})
    assert parsed.metrics == ('eta', 'speed_final')
    run = spec.plan_runs(dataclasses.replace(parsed, overrides=('duration=0.5',)))[0]
    record = execute.MetricRecorder(parsed.metrics)(run, run.scenario(), result)
    assert record['speed_final'] == result.summary['speed_final']
    with pytest.raises(ScenarioError, match='known: .*speed_final'):
        spec.parse_spec({'scenario': 'demo', 'metrics': ['nope']})
    # Without the row, none of it exists.
    monkeypatch.undo()
    assert 'speed_final' not in simulate(load('demo', ['duration=0.5'])).summary
    with pytest.raises(ScenarioError, match="unknown metric 'speed_final'"):
        spec.parse_spec({'scenario': 'demo', 'metrics': ['speed_final']})


def markdown_row(key: SummaryKey) -> str:
    """Return the row of docs/outputs.md for a key of the table."""
    sweep = ''
    if key.sweep:
        sweep = 'yes' + (', default' if key.default else '')
        sweep += ', at times' if key.series else ''
    return (f'| `{key.name}` | {key.kind} | {key.description} | {sweep} | '
            f'{", ".join(key.writers)} |')


def test_docs_outputs_lists_the_table():
    text = DOCS.read_text()
    section = text[text.index('## `summary.json`'):text.index('## `timeseries.npz`')]
    rows = [line for line in section.splitlines() if line.startswith('| `')]
    assert rows == [markdown_row(k) for k in SUMMARY_KEYS]


def test_a_summary_is_plain_json(summaries):
    for s in summaries:
        assert json.loads(json.dumps(s)) == s


def test_reading_the_table_imports_no_numpy():
    """The pytest plugin (flock_swarm.testing) reads the table; it must stay cheap to import."""
    code = ('import sys, flock_swarm.core.summary as s, flock_swarm.testing as t; '
            'assert s.sim_only_keys() and t.SIM_ONLY; '
            'assert "numpy" not in sys.modules, "numpy imported"')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
