"""The reproduction report (``python -m flock_swarm.reproduce``): quick run, numbers, caches.

The quick run (tiny sizes and durations, no ROS) writes report, figures and JSON results into
``tmp_path``; the report must have a section per experiment whose numbers are exactly those
of the JSON results. The Fig. 3 sweep is checked on its own: the mean over realisations, and
a resumable cache (a second invocation runs nothing again; more realisations run only the
new ones). An experiment is one object: the docs' worked example, saved as the only module of a
package, is all the report needs. Su Fig. 7 with f_gamma to every agent is Fig. 2 in the
leader's frame, as the report says of that variant.
"""

import json
import re
from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose
import pytest

from flock_swarm.cli import reproduce
from flock_swarm.reproduce import catalogue, execution
from flock_swarm.reproduce.catalogue import all_experiments
from flock_swarm.reproduce.common import FIG_MAX_BYTES, fmt
from flock_swarm.reproduce.execution import run_simulations
from flock_swarm.reproduce.experiment import Experiment
from flock_swarm.reproduce.experiments import su2009_fig3_sweep as su2009
from flock_swarm.reproduce.experiments.su2009_fig3_sweep import (aggregate_fig3, delta_for_eta,
                                                                 fig3_tasks)
from flock_swarm.reproduce.plan import Plan
from flock_swarm.study import execute
from flock_swarm.study.cache import cache_line, read_cache
from flock_swarm.study.execute import make_jobs, run_job

# A table row of the report: "| what (`key`) | paper | ours |".
ROW = re.compile(r'\(`(?P<key>[\w.]+)`\) \| (?P<paper>.*?) \| (?P<ours>[^|]*) \|$')


def sections(text):
    """Split the report into ``{heading: body}`` at its level-2 headings."""
    parts = re.split(r'^## (.+)$', text, flags=re.MULTILINE)
    return dict(zip(parts[1::2], parts[2::2]))


@pytest.fixture
def quick_run(quick_reproduction):
    """The session's ``--quick --skip-ros`` run (conftest.quick_reproduction)."""
    return quick_reproduction


def test_report_has_a_section_per_experiment(quick_run):
    text = (quick_run / 'report.md').read_text()
    found = sections(text)
    for exp in all_experiments():
        assert exp.title in found, exp.key
        body = found[exp.title]
        assert '**Paper**' in body
        assert f'{exp.key}.png' in body
    assert 'python -m flock_swarm.reproduce --quick --skip-ros' in text
    assert 'nproc' in text and 'CPU model' in text
    assert 'averages **1 realisation**' in found[all_experiments()[1].title]


def test_report_numbers_are_the_json_results(quick_run):
    found = sections((quick_run / 'report.md').read_text())
    for exp in all_experiments():
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
    text = sections((quick_run / 'report.md').read_text())[all_experiments()[1].title]
    for row in result['rows']:
        eta = [r['eta'] for r in records
               if r['n_agents'] == row['n_agents'] and r['delta'] == row['delta']]
        assert row['mean'] == pytest.approx(np.mean(eta))
        assert f'{fmt(row["mean"])} ({fmt(row["std"])}, {row["count"]})' in text


def test_figures_exist_and_are_small(quick_run):
    figures = sorted((quick_run / 'figures').glob('*.png'))
    # One per experiment, and the study figures some draw of their runs over seeds.
    keys = {e.key for e in all_experiments()}
    # (and the curves of eta over tolerances and time of every study).
    assert {p.stem.removesuffix('_study').removesuffix('_curves') for p in figures} == keys
    assert {p.stem for p in figures} >= keys
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
    assert len(first['sweeps']['su2009_fig3']) == 4

    ran.clear()
    second = run_simulations(plan, tmp_path, 1, False, quiet)
    assert ran == [] and second['executed'] == 0
    assert second['sweeps']['su2009_fig3'] == first['sweeps']['su2009_fig3']

    more = Plan(True, 3, (12,), (0.25, 0.5), ('duration=0.5',))
    third = run_simulations(more, tmp_path, 1, False, quiet)
    assert sorted(ran) == [('fig3', 12, 0.25, 2), ('fig3', 12, 0.5, 2)]
    assert len(third['sweeps']['su2009_fig3']) == 6
    rows = aggregate_fig3(third['sweeps']['su2009_fig3'])
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
    assert second['sweeps']['su2009_fig3'] == first['sweeps']['su2009_fig3']


def test_a_stacked_fig3_run_equals_its_own_run():
    plan = Plan(True, 1, (15,), (0.2, 0.6, 1.0), ('duration=1',))
    runs = fig3_tasks(plan)
    [stack] = make_jobs(runs, stack_agents=45)
    stacked = run_job(stack, su2009.fig3_record)
    alone = [run_job(job, su2009.fig3_record)[0] for job in make_jobs(runs, stack_agents=1)]
    for a, b in zip(stacked, alone):
        assert {k: v for k, v in a.items() if k != 'wall_time_s'} \
            == {k: v for k, v in b.items() if k != 'wall_time_s'}


def test_fig7_with_feedforward_to_all_is_fig2_in_the_leaders_frame():
    """Su Fig. 7 with f_gamma fed to every agent is Fig. 2 seen from the leader: each agent's
    acceleration relative to the leader's is the same, so the relative trajectories of a seed
    agree to rounding while the absolute ones part (the report says so of that variant)."""
    from flock_swarm.core.run import simulate
    from flock_swarm.presets import load
    for seed in (1, 2, 3):
        fig2 = simulate(load('su2009_fig2', ['duration=20'], seed)).series
        fig7 = simulate(load('su2009_fig7', ['duration=20', 'protocol.feedforward_to=all'],
                             seed)).series
        assert_allclose(fig7['t'], fig2['t'], rtol=0, atol=0)
        for state in ('q', 'p'):
            rel2 = fig2[state] - fig2[f'leader_{state}'][:, None]
            rel7 = fig7[state] - fig7[f'leader_{state}'][:, None]
            assert_allclose(rel7, rel2, rtol=0, atol=1e-6)
        # Not the same run: the leader of Fig. 7 accelerates away from Fig. 2's.
        assert np.abs(fig7['leader_p'][-1] - fig2['leader_p'][-1]).max() > 5.0
        assert_allclose(fig7['metric_eta'], fig2['metric_eta'], rtol=0, atol=0)


def docs_example() -> str:
    """Return the worked example of docs/reproduction/README.md ("Adding an experiment")."""
    text = (Path(__file__).resolve().parents[1] / 'docs' / 'reproduction'
            / 'README.md').read_text()
    section = text.split('## Adding an experiment', 1)[1]
    return re.search(r'```python\n(.*?)```', section, flags=re.DOTALL).group(1)


def test_the_docs_example_experiment_is_one_module(tmp_path, monkeypatch):
    """The docs' example, saved as the only module of an experiments package, is all the
    report needs: it runs the experiment and its seeds, and renders its summary row, section,
    criterion, verdict and figure (no other file names it)."""
    package = tmp_path / 'lib' / 'myexperiments'
    package.mkdir(parents=True)
    (package / '__init__.py').write_text('')
    (package / 'su2009_thm2_overdamped.py').write_text(docs_example())
    monkeypatch.syspath_prepend(str(tmp_path / 'lib'))
    monkeypatch.setattr(catalogue, 'PACKAGES', ('myexperiments',))
    [exp] = all_experiments()
    assert exp.key == 'su2009_thm2_overdamped'
    out = tmp_path / 'out'
    assert reproduce.main(['--quick', '--skip-ros', '--jobs', '1', '--out', str(out),
                           '--report', str(tmp_path / 'report.md'),
                           '--figures', str(tmp_path / 'figures'),
                           '--seeds-cache', str(tmp_path / 'seeds')]) == 0
    text = (tmp_path / 'report.md').read_text()
    result = json.loads((out / 'results' / f'{exp.key}.json').read_text())
    assert result['command'] == 'sim su2009_fig6 --set protocol.c2=2.0 --set duration=1'
    body = sections(text)[exp.title]
    assert body.index('**Criterion**') < body.index('**Run.**')
    assert f'(`closed_form_position_dev`) | 0 | ' \
        f'{fmt(result["metrics"]["closed_form_position_dev"])} |' in body
    assert '| c1 = 0.5, c2 = 2 | 2 (2) |' in body
    verdict = result['seeds']['setups'][0]['judged']['verdict']
    assert verdict in ('reproduced', 'not reproduced', 'inconclusive')
    row = next(line for line in text.splitlines() if line.startswith(f'| [{exp.title}]'))
    assert f'| **{verdict}** |' in row
    assert (tmp_path / 'figures' / f'{exp.key}.png').is_file()
    assert len(read_cache(tmp_path / 'seeds' / 'reproduce_su2009_thm2_overdamped.jsonl')) == 2


def test_the_catalogue_orders_registered_experiments_and_refuses_a_second_key(monkeypatch):
    class Tiny(Experiment):
        key, title, order = 'tiny', 'A tiny experiment', 105.0

    monkeypatch.setattr(catalogue, '_REGISTERED', [])
    catalogue.register(Tiny())
    keys = [e.key for e in all_experiments()]
    assert keys[:3] == ['su2009_fig2', 'tiny', 'su2009_fig3']
    assert catalogue.experiment('tiny').title == 'A tiny experiment'
    catalogue.register(Tiny())
    with pytest.raises(ValueError, match="two experiments named 'tiny'"):
        all_experiments()


def test_yu_connectivity_finds_the_first_split_and_who_is_cut_off():
    from types import SimpleNamespace
    from flock_swarm.reproduce.experiments.yu2010_sec41 import connectivity
    sc = SimpleNamespace(law=SimpleNamespace(radius=1.0, strict_radius=False))
    q = np.zeros((3, 4, 2))
    q[:, :, 0] = [0.0, 0.8, 1.6, 2.4]       # a chain of neighbours 0.8 m apart
    q[1:, 3, 0] = 5.0                       # agent 3 cut off from the second instant on
    series = {'t': np.array([0.0, 0.1, 0.2]), 'q': q,
              'metric_components': np.array([1, 2, 2])}
    assert connectivity(sc, series) == {'connectivity_lost_t': 0.1, 'cut_off_agents': 1}
    series['metric_components'] = np.array([1, 1, 1])
    assert connectivity(sc, series) == {'connectivity_lost_t': None, 'cut_off_agents': 0}


def test_a_preset_run_from_before_its_headline_is_reused(tmp_path):
    """A cached preset run whose scenario.json has no headline (issue 24) is the same run."""
    from flock_swarm.core.run import simulate
    from flock_swarm.outputs import write_outputs
    from flock_swarm.presets import load
    sc = load('su2009_fig6', ['duration=0.02'])
    result = simulate(sc)
    write_outputs(result, tmp_path, sc)
    ran = json.loads((tmp_path / 'scenario.json').read_text())
    assert ran['metrics'].pop('headline') and ran['metrics'].pop('claim')
    (tmp_path / 'scenario.json').write_text(json.dumps(ran))
    assert execution.cached_preset(tmp_path, sc) == result.summary
    # A changed run is not reused; nor is a scenario.json that is not a mapping.
    assert execution.cached_preset(tmp_path, load('su2009_fig6', ['duration=0.04'])) is None
    (tmp_path / 'scenario.json').write_text('[1, 2]')
    assert execution.cached_preset(tmp_path, sc) is None
