"""The reproduction report (``python -m flock_swarm.reproduce``): quick run, numbers, caches.

The quick run (tiny sizes and durations, no ROS) writes report, figures and JSON results into
``tmp_path``; the report must have a section per experiment whose numbers are exactly those
of the JSON results. The Fig. 3 sweep is checked on its own: the mean over realisations, and
a resumable cache (a second invocation runs nothing again; more realisations run only the
new ones).
"""

import json
import re

import numpy as np
from numpy.testing import assert_allclose
import pytest

from flock_swarm.cli import reproduce
from flock_swarm.reproduce import execution, su2009
from flock_swarm.reproduce.catalogue import EXPERIMENTS
from flock_swarm.reproduce.common import FIG_MAX_BYTES, fmt
from flock_swarm.reproduce.execution import run_simulations
from flock_swarm.reproduce.su2009 import Plan, aggregate_fig3, delta_for_eta, fig3_tasks
from flock_swarm.study import execute
from flock_swarm.study.cache import cache_line, read_cache
from flock_swarm.study.execute import make_jobs, run_job

# A table row of the report: "| what (`key`) | paper | ours |".
ROW = re.compile(r'\(`(?P<key>[\w.]+)`\) \| (?P<paper>.*?) \| (?P<ours>[^|]*) \|$')


def sections(text):
    """Split the report into ``{heading: body}`` at its level-2 headings."""
    parts = re.split(r'^## (.+)$', text, flags=re.MULTILINE)
    return dict(zip(parts[1::2], parts[2::2]))


@pytest.fixture(scope='module')
def quick_run(tmp_path_factory):
    """Run ``--quick --skip-ros`` once into a temporary directory."""
    root = tmp_path_factory.mktemp('reproduce')
    status = reproduce.main(['--quick', '--skip-ros', '--jobs', '2', '--out', str(root / 'out'),
                             '--report', str(root / 'report.md'),
                             '--figures', str(root / 'figures')])
    assert status == 0
    return root


def test_report_has_a_section_per_experiment(quick_run):
    text = (quick_run / 'report.md').read_text()
    found = sections(text)
    for exp in EXPERIMENTS:
        assert exp.title in found, exp.key
        body = found[exp.title]
        assert '**Paper**' in body
        assert f'{exp.key}.png' in body
    assert 'python -m flock_swarm.reproduce --quick --skip-ros' in text
    assert 'nproc' in text and 'CPU model' in text
    assert 'averages **1 realisation**' in found[EXPERIMENTS[1].title]


def test_report_numbers_are_the_json_results(quick_run):
    found = sections((quick_run / 'report.md').read_text())
    for exp in EXPERIMENTS:
        result = json.loads((quick_run / 'out' / 'results' / f'{exp.key}.json').read_text())
        rows = {m['key']: m['ours'] for m in map(ROW.search, found[exp.title].splitlines())
                if m}
        metrics = result['metrics']
        table_keys = set(rows)
        assert table_keys, exp.key
        assert table_keys <= set(metrics), exp.key
        for key, ours in rows.items():
            assert ours == fmt(metrics[key]), (exp.key, key)
        if exp.key != 'su2009_fig3':
            summary = result['summary']
            for key in table_keys & set(summary):
                assert fmt(summary[key]) == rows[key], (exp.key, key)


def test_fig3_table_is_the_cached_runs(quick_run):
    records = list(read_cache(quick_run / 'out' / 'fig3_runs.jsonl').values())
    result = json.loads((quick_run / 'out' / 'results' / 'su2009_fig3.json').read_text())
    plan = Plan.make(True, None)
    assert len(records) == len(plan.sizes) * len(plan.fractions) * plan.realisations
    text = sections((quick_run / 'report.md').read_text())[EXPERIMENTS[1].title]
    for row in result['rows']:
        eta = [r['eta'] for r in records
               if r['n_agents'] == row['n_agents'] and r['delta'] == row['delta']]
        assert row['mean'] == pytest.approx(np.mean(eta))
        assert f'{fmt(row["mean"])} ({fmt(row["std"])}, {row["count"]})' in text


def test_figures_exist_and_are_small(quick_run):
    figures = sorted((quick_run / 'figures').glob('*.png'))
    assert {p.stem for p in figures} == {e.key for e in EXPERIMENTS}
    for path in figures:
        assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
        assert 1000 < path.stat().st_size < FIG_MAX_BYTES, path.name
    assert sum(p.stat().st_size for p in figures) < 2_500_000


def test_aggregate_fig3_averages_over_realisations():
    records = [{'n_agents': 100, 'delta': 0.1, 'seed': s, 'eta': e}
               for s, e in enumerate([0.2, 0.4, 0.9])]
    records += [{'n_agents': 100, 'delta': 0.5, 'seed': 0, 'eta': 1.0},
                {'n_agents': 300, 'delta': 0.1, 'seed': 1, 'eta': 0.3}]
    rows = {(r['n_agents'], r['delta']): r for r in aggregate_fig3(records)}
    assert set(rows) == {(100, 0.1), (100, 0.5), (300, 0.1)}
    one = rows[(100, 0.1)]
    assert one['count'] == 3 and one['seeds'] == [0, 1, 2]
    assert_allclose(one['mean'], 0.5, rtol=0, atol=1e-15)
    assert_allclose(one['std'], np.std([0.2, 0.4, 0.9], ddof=1), rtol=1e-14)
    assert_allclose(one['sem'], one['std'] / np.sqrt(3), rtol=1e-14)
    assert rows[(100, 0.5)]['std'] == 0.0 and rows[(100, 0.5)]['count'] == 1
    # eta = 0.8 is crossed between delta = 0.1 (mean 0.5) and 0.5 (mean 1.0): 0.1 + 0.4 * 0.6.
    assert_allclose(delta_for_eta(aggregate_fig3(records), 100, 0.8), 0.34, atol=1e-12)
    assert delta_for_eta(aggregate_fig3(records), 300, 0.8) is None


def test_read_cache_skips_a_truncated_line(tmp_path):
    path = tmp_path / 'fig3_runs.jsonl'
    good = {'digest': 'abc', 'n_agents': 10, 'delta': 0.5, 'seed': 0, 'eta': 0.25}
    path.write_text(cache_line(good) + cache_line(good | {'digest': 'def'})[:20])
    assert read_cache(path) == {'abc': good}


def test_fig3_sweep_is_resumable(tmp_path, monkeypatch):
    ran = []
    real_run_task, real_record = execution.run_task, su2009.fig3_record

    def counting(task):
        ran.append((task['kind'], None, None, None))
        return real_run_task(task)

    def counting_record(run, sc, result):
        ran.append(('fig3', run.n_agents, run.point['informed.fraction'], run.seed))
        return real_record(run, sc, result)

    monkeypatch.setattr(execution, 'run_task', counting)
    monkeypatch.setattr(su2009, 'fig3_record', counting_record)
    plan = Plan(True, 2, (12,), (0.25, 0.5), ('duration=0.5',))
    quiet = (lambda line: None)
    first = run_simulations(plan, tmp_path, 1, False, quiet)
    fig3_first = [r for r in ran if r[0] == 'fig3']
    assert len(fig3_first) == 4 and first['cached'] == 0
    assert len(first['fig3']) == 4

    ran.clear()
    second = run_simulations(plan, tmp_path, 1, False, quiet)
    assert ran == [] and second['executed'] == 0
    assert second['fig3'] == first['fig3']

    more = Plan(True, 3, (12,), (0.25, 0.5), ('duration=0.5',))
    third = run_simulations(more, tmp_path, 1, False, quiet)
    assert sorted(ran) == [('fig3', 12, 0.25, 2), ('fig3', 12, 0.5, 2)]
    assert len(third['fig3']) == 6
    rows = aggregate_fig3(third['fig3'])
    assert [r['count'] for r in rows] == [3, 3]


def test_fig3_sweep_alone_stacks_runs_and_resumes(tmp_path, monkeypatch):
    jobs = []
    real_run_job = execute.run_job

    def counting(job, recorder):
        jobs.append([(r.n_agents, r.point['informed.fraction'], r.seed) for r in job.runs])
        return real_run_job(job, recorder)

    monkeypatch.setattr(execute, 'run_job', counting)
    monkeypatch.setattr(su2009, 'FIG3_STACK_AGENTS', 24)
    plan = Plan(True, 2, (12, 30), (0.25, 0.5, 1.0), ('duration=0.5',))
    quiet = (lambda line: None)
    first = run_simulations(plan, tmp_path, 1, False, quiet, presets=False)
    assert first['summaries'] == {} and first['executed'] == 12
    # N = 12: stacks of two and one per seed; N = 30: one run per stack.
    assert sorted(len(j) for j in jobs) == [1] * 8 + [2, 2]
    assert all(len({(n, seed) for n, _, seed in job}) == 1 for job in jobs)
    assert len(read_cache(tmp_path / 'fig3_runs.jsonl')) == 12

    jobs.clear()
    second = run_simulations(plan, tmp_path, 1, False, quiet, presets=False)
    assert jobs == [] and second['executed'] == 0 and second['cached'] == 12
    assert second['fig3'] == first['fig3']


def test_a_stacked_fig3_run_equals_its_own_run():
    plan = Plan(True, 1, (15,), (0.2, 0.6, 1.0), ('duration=1',))
    runs = fig3_tasks(plan)
    [stack] = make_jobs(runs, stack_agents=45)
    stacked = run_job(stack, su2009.fig3_record)
    alone = [run_job(job, su2009.fig3_record)[0] for job in make_jobs(runs, stack_agents=1)]
    for a, b in zip(stacked, alone):
        assert {k: v for k, v in a.items() if k != 'wall_time_s'} \
            == {k: v for k, v in b.items() if k != 'wall_time_s'}
