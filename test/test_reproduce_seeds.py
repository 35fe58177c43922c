"""The experiments over seeds (:mod:`flock_swarm.reproduce.seeds`, :mod:`~.stats`):
distributions, confidence intervals and the three-word verdicts on tiny synthetic records, the
settling time on a synthetic series, a ``--quick`` report rendered from partial caches, the
Fig. 3 curves judged at the paper's anchors, and an interrupted reproduction."""

import json
import re
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest

from flock_swarm.cli import reproduce
from flock_swarm.reproduce.catalogue import experiment
from flock_swarm.reproduce.experiments.su2009_fig3_curves import (FIG3_CURVES,
                                                                  fig3_curves_anchors,
                                                                  fig3_curves_tested)
from flock_swarm.reproduce.experiments.su2009_fig3_sweep import delta_for_eta, judge_anchors
from flock_swarm.reproduce.experiments.zhou2012_sec52 import longer_run
from flock_swarm.reproduce.seeds import distribution, settling_time, summarise
from flock_swarm.reproduce.stats import combine, decide, t_interval, wilson
from flock_swarm.study.cache import cache_line, read_cache
from flock_swarm.testing import wait_for


def test_distribution_of_a_few_values():
    # 1, 2, 3: mean 2, sample variance ((1 + 0 + 1) / 2) = 1; None and nan are missing.
    d = distribution([3, None, 1, float('nan'), 2])
    assert d == {'count': 3, 'missing': 2, 'mean': 2.0, 'std': 1.0, 'min': 1.0, 'max': 3.0}
    assert distribution([None]) == {'count': 0, 'missing': 1}
    assert distribution([5]) == {'count': 1, 'missing': 0, 'mean': 5.0, 'std': 0.0,
                                 'min': 5.0, 'max': 5.0}


def test_wilson_interval_matches_its_closed_form():
    # Wilson 1927 at 95 % (z = 1.95996): the textbook values for 0, 5 and 10 of 10.
    assert wilson(0, 10) == (0.0, pytest.approx(0.27753, abs=1e-5))
    assert wilson(5, 10) == (pytest.approx(0.23659, abs=1e-5), pytest.approx(0.76341, abs=1e-5))
    assert wilson(10, 10) == (pytest.approx(0.72247, abs=1e-5), 1.0)
    assert wilson(50, 50)[0] == pytest.approx(50 / (50 + 1.959964 ** 2), abs=1e-8)
    assert wilson(0, 0) == (0.0, 1.0)


def test_t_interval_of_a_mean():
    # Two values: t_{0.975, 1} = 12.7062; the half-width is t s / sqrt(n).
    low, high = t_interval(1.0, 2.0, 2)
    assert (high - low) / 2 == pytest.approx(12.7062 * 2.0 / np.sqrt(2), rel=1e-5)
    assert (low + high) / 2 == pytest.approx(1.0, abs=1e-12)
    assert t_interval(1.0, 0.0, 1) is None


def test_verdicts_follow_the_interval():
    band = (0.9, 1.0)
    assert decide((0.93, 1.0), band) == 'reproduced'
    assert decide((0.4, 0.7), band) == 'not reproduced'
    assert decide((0.84, 1.0), band) == 'inconclusive'
    assert decide(None, band) == 'inconclusive'
    assert decide((0.82, 0.86), (0.81, 0.91)) == 'reproduced'
    assert decide((0.92, 0.95), (0.81, 0.91)) == 'not reproduced'
    assert combine(['reproduced', 'reproduced']) == 'reproduced'
    assert combine(['reproduced', 'inconclusive']) == 'inconclusive'
    assert combine(['inconclusive', 'not reproduced']) == 'not reproduced'
    assert combine(['not run yet', 'not run yet']) == 'not run yet'


def test_a_fraction_claim_counts_seeds_and_keeps_the_premise_apart():
    claim = experiment('yu2010_sec41').criterion
    # eta = 1 on seeds 1-4 and 6; seed 5 is cut off at 0.1 s (premise failing), seed 6 misses.
    records = [{'seed': s, 'metrics': {'eta': e, 'connectivity_lost_t': lost}}
               for s, e, lost in ((1, 1.0, None), (2, 1.0, None), (3, 1.0, None),
                                  (4, 1.0, None), (5, 0.95, 0.1), (6, 0.9, None))]
    judged = claim.judge(records)
    assert (judged['n'], judged['met'], judged['premise_failed']) == (5, 4, [5])
    assert judged['interval'] == list(wilson(4, 5))
    assert judged['verdict'] == 'inconclusive'  # Wilson [0.38, 0.96] straddles 0.9
    everyone = [dict(r, seed=s) for s in range(1, 51) for r in records[:1]]
    assert claim.judge(everyone)['verdict'] == 'reproduced'  # [0.929, 1]


def test_summarise_judges_every_set_up_by_the_criterion():
    exp = experiment('su2009_fig2')
    # The claim: the mean eta within 0.05 of 0.86.
    records = [{'seed': s, 'metrics': {'eta': e, 'linked_to_informed': 80 + s,
                                       'components_final': 3}, 'wall_time_s': 2.0}
               for s, e in ((1, 0.9), (2, 0.85), (3, 0.86))]
    res = summarise(exp, [('as printed', records, 20)])
    [s] = res['setups']
    assert (s['seeds'], s['planned'], s['seed_list'], s['cost_s']) == (3, 20, [1, 2, 3], 2.0)
    mean = (0.9 + 0.85 + 0.86) / 3
    assert s['stats']['eta']['mean'] == pytest.approx(mean)
    assert s['stats']['linked_to_informed']['min'] == 81.0
    judged = s['judged']
    assert judged['estimate'] == pytest.approx(mean)
    assert judged['interval'] == pytest.approx(list(t_interval(mean, np.std(
        [0.9, 0.85, 0.86], ddof=1), 3)))
    assert judged['verdict'] == 'inconclusive'  # [0.80, 0.94] reaches past 0.81 and 0.91
    assert res['criterion'].startswith('The mean of eta at t_final')


def test_settling_time_is_the_last_entry_below_the_tolerance():
    t = np.arange(6) * 0.5
    leader = np.zeros((6, 2))
    # max ||p_i - p_l|| per instant: 1, 0.05, 0.3, 0.05, 0.02, 0.01 (tolerance 0.1).
    err = [1.0, 0.05, 0.3, 0.05, 0.02, 0.01]
    p = np.zeros((6, 2, 2))
    p[:, 1, 0] = err
    series = {'t': t, 'p': p, 'leader_p': leader}
    assert settling_time(series, 0.1) == 1.5
    assert settling_time(series, 2.0) == 0.0
    p[-1, 1, 0] = 0.5
    assert settling_time(series, 0.1) is None


def test_quick_report_renders_from_partial_caches(tmp_path, quick_reproduction):
    # The session's full quick run, copied: this test runs the reproduction again in it.
    out = tmp_path / 'out'
    shutil.copytree(quick_reproduction / 'out', out)
    common = ['--quick', '--skip-ros', '--jobs', '1', '--out', str(out),
              '--report', str(tmp_path / 'report.md'), '--figures', str(tmp_path / 'figures')]
    full = read_cache(out / 'seeds' / 'reproduce_su2009_fig2.jsonl')
    assert len(full) == 2
    # A partial cache: one of the two seeds of Fig. 2, nothing else.
    partial = tmp_path / 'partial'
    partial.mkdir()
    kept = min(full.values(), key=lambda r: r['seed'])
    (partial / 'reproduce_su2009_fig2.jsonl').write_text(cache_line(kept))
    assert reproduce.main(common + ['--cached-seeds', '--seeds-cache', str(partial)]) == 0
    text = (tmp_path / 'report.md').read_text()
    result = json.loads((out / 'results' / 'su2009_fig2.json').read_text())['seeds']
    [s] = result['setups']
    assert (s['seeds'], s['planned'], s['seed_list']) == (1, 2, [kept['seed']])
    assert s['stats']['eta']['mean'] == kept['metrics']['eta']
    assert '| as printed | 1 (2) |' in text
    assert 'as printed: 1 of 2 seeds' in text
    assert '**Incomplete:** as printed: 1 of 2 seeds' in text
    # The other studies have no records: their verdicts say so, and nothing ran for them.
    assert text.count('| not run yet |') >= 6
    assert sorted(p.name for p in partial.iterdir()) == ['reproduce_su2009_fig2.jsonl']


def fig3_curve(label, eta100, eta1000, complete=True):
    """Return a Fig. 3 curve's result whose rows give ``eta100`` at every delta of N = 100
    and ``eta1000`` at every delta of N = 1000 (N = 300, 500 between them)."""
    rows = [{'n_agents': n, 'delta': d, 'mean': e + 0.5 * d, 'std': 0.1, 'sem': 0.01,
             'count': 50, 'seeds': list(range(50))}
            for n, e in ((100, eta100), (300, eta100), (500, eta1000), (1000, eta1000))
            for d in (0.1, 0.27, 1.0)]
    curve = {'label': label, 'rows': rows, 'complete': complete, 'runs_cached': len(rows)}
    for n in (100, 300, 500, 1000):
        curve[f'delta_for_eta80_N{n}'] = delta_for_eta(rows, n, 0.8)
    return curve


def test_fig3_curves_are_judged_at_the_papers_anchors():
    curves = [fig3_curve('far', 0.1, 0.1), fig3_curve('near', 0.665, 0.75),
              fig3_curve('unfinished', 0.665, 0.75, complete=False)]
    text = '\n'.join(fig3_curves_anchors(curves))
    # The anchors: N = 100 at delta = 0.27 (0.665 + 0.135), N = 1000 at delta = 0.1.
    assert '| near | 0.8 ± 0.01 (50 runs) | 0.8 ± 0.01 (50 runs) | yes (0.27 -> 0.1) |' in text
    assert 'Of the complete curves (far, near): within 0.05 of eta = 0.8 at both anchors: ' \
        'near; at one anchor, ' in text
    assert 'at N = 100, delta = 0.27 it is near (eta 0.8); at N = 1000, delta = 0.1 it is ' \
        'near (eta 0.8)' in text
    assert 'at one anchor, at N = 100, delta = 0.27: **near**; at N = 1000, delta = 0.1: ' \
        '**near**.' in text
    assert 'falls from N = 100 to N = 1000 in: near.' in text  # far never reaches 0.8


def test_fig3_is_judged_by_the_mean_at_both_anchors():
    def rows(mean100, std100, mean1000, std1000, count=50):
        return [{'n_agents': 100, 'delta': 0.27, 'mean': mean100, 'std': std100,
                 'count': count},
                {'n_agents': 1000, 'delta': 0.1, 'mean': mean1000, 'std': std1000,
                 'count': count}]
    assert judge_anchors(rows(0.80, 0.05, 0.79, 0.05))['verdict'] == 'reproduced'
    # One anchor far off decides, whatever the other.
    assert judge_anchors(rows(0.80, 0.05, 0.21, 0.05))['verdict'] == 'not reproduced'
    # Three realisations: an interval too wide to decide.
    judged = judge_anchors(rows(0.80, 0.05, 0.79, 0.05, count=3))
    assert judged['verdict'] == 'inconclusive'
    assert judged['anchors'][0]['interval'] == pytest.approx(list(t_interval(0.80, 0.05, 3)))
    assert judge_anchors(rows(0.8, 0.05, 0.8, 0.05)[:1])['verdict'] == 'inconclusive'


def test_a_longer_run_is_compared_with_the_shorter_seed_by_seed():
    def rec(seed, t_final, settling, gain):
        return {'seed': seed, 'metrics': {'t_final': t_final, 'settling_time': settling,
                                          'adaptive_gain_max': gain}}
    short = [rec(1, 30.0, None, 40.0), rec(2, 30.0, 28.0, 50.0), rec(3, 30.0, None, 10.0)]
    long = [rec(1, 90.0, 80.0, 60.0), rec(2, 90.0, 28.0, 50.0)]  # seed 3 not run for 90 s
    text = longer_run([('30 s', short, 3), ('greedy', [], 3), ('90 s', long, 2)])
    assert text == ('Seed by seed (2 seeds run for both 30 s and 90 s; the first 30 s of a '
                    'longer run are the shorter run): settled within 30 s: 1; within 90 s: 2, '
                    'those settling only after 30 s at 80 .. 80 s. The largest adaptive gain '
                    'at 90 s is 1 .. 1.5 times its value at 30 s.')
    assert longer_run([('30 s', short, 3), ('90 s', [], 2)]) == ''


def test_the_fig3_discussion_cites_the_complete_curves_at_the_anchors():
    linear, bounded, linear300, bounded300 = [spec for spec, _ in FIG3_CURVES]
    curves = [dict(fig3_curve('a', 0.2, 0.1), spec=linear),
              dict(fig3_curve('b', 0.5, 0.0), spec=bounded),
              dict(fig3_curve('c', 0.3, 0.1, complete=False), spec=linear300),
              dict(fig3_curve('d', 0.5, 0.0), spec=bounded300)]
    text = fig3_curves_tested(curves)
    # At the anchors: 0.2 + 0.135 (N = 100, delta = 0.27), 0.1 + 0.05 (N = 1000, delta = 0.1).
    assert 'the linear term over 100 s gives eta = 0.335 and 0.15;' in text
    assert 'bounded navigation (Olfati-Saber 2006) at the same 100 s gives 0.635 and 0.05;' \
        in text
    assert 'bounded navigation over 300 s gives 0.635 and 0.05.' in text
    assert '300 s run with the linear term' not in text  # incomplete: not cited
    assert fig3_curves_tested(curves[1:]) == ''  # nothing to compare with
    assert 'Closest to the paper over both anchors' not in text  # b never reaches 0.8
    close = dict(fig3_curve('e', 0.6, 0.7), spec=bounded300)
    text = fig3_curves_tested([curves[0], close])
    assert text.endswith('Closest to the paper over both anchors: e, whose fraction needed for '
                         'eta = 0.8 is 0.4 (N = 100), 0.4 (N = 300), 0.2 (N = 500), 0.2 '
                         '(N = 1000), not falling steadily with N (the paper: 0.27 at N = 100, '
                         '0.1 at N = 1000).'), text


def test_an_interrupted_reproduction_keeps_its_runs_and_says_so_in_one_line(tmp_path):
    """SIGINT during the studies over seeds: exit status 130, one line saying how to resume,
    no traceback, every finished run in its cache."""
    seeds = tmp_path / 'seeds'
    proc = subprocess.Popen(
        [sys.executable, '-m', 'flock_swarm.reproduce', '--seeds-only', '--jobs', '2',
         '--seeds-cache', str(seeds), '--out', str(tmp_path / 'out'),
         '--report', str(tmp_path / 'report.md'), '--figures', str(tmp_path / 'figures')],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        cache = seeds / 'reproduce_su2009_fig2.jsonl'
        wait_for(lambda: cache.is_file() and cache.read_bytes().count(b'\n') >= 1, 240.0,
                 'a finished run of Su Fig. 2')
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert 'Traceback' not in err
    assert err.rstrip().splitlines()[-1].startswith('reproduce: interrupted; every finished run')
    problems = []
    assert len(read_cache(cache, report=problems.append)) >= 1 and problems == []
    assert not (tmp_path / 'report.md').exists()


def test_rekey_fig3_cache_covers_the_plan_with_the_committed_records(tmp_path):
    """scripts/rekey_fig3_cache writes the committed linear 100 s records under the report's
    digests: every planned run of the Fig. 3 sweep found, each record otherwise unchanged."""
    from pathlib import Path

    from flock_swarm.reproduce.experiments.su2009_fig3_sweep import fig3_tasks
    from flock_swarm.reproduce.plan import Plan
    root = Path(__file__).resolve().parent.parent
    done = subprocess.run([sys.executable, str(root / 'scripts' / 'rekey_fig3_cache'),
                           '--realisations', '2', '--out', str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert '0 planned runs not in the committed cache' in done.stdout
    cached = read_cache(tmp_path / 'fig3_runs.jsonl')
    planned = {run.digest for run in fig3_tasks(Plan.make(False, 2))}
    # Every line passes the cache's own reading (its check hashes the new digest too).
    assert set(cached) == planned
    written = [dict(rec, digest=digest) for digest, rec in cached.items()]
    source = root / 'docs' / 'reproduction' / 'runs' / 'reproduce_su2009_fig3_linear_100s.jsonl'
    committed = {(r['n_agents'], r['delta'], r['seed']): r
                 for r in map(json.loads, source.read_text().splitlines())}
    for rec in written:
        original = committed[(rec['n_agents'], rec['delta'], rec['seed'])]
        assert {k: v for k, v in rec.items() if k != 'digest'} == \
            {k: v for k, v in original.items() if k not in ('digest', 'check')}


def test_cached_seeds_renders_from_the_committed_results_with_no_run(tmp_path,
                                                                     quick_reproduction):
    # The session's quick run's results stand for the committed docs/reproduction/results/;
    # an empty --out: --cached-seeds renders the report from them and the caches, runs nothing.
    results, seeds = tmp_path / 'results', quick_reproduction / 'out' / 'seeds'
    shutil.copytree(quick_reproduction / 'out' / 'results', results)
    cached = {p.name: p.read_bytes() for p in seeds.iterdir()}
    out = tmp_path / 'out'
    assert reproduce.main(['--quick', '--cached-seeds', '--jobs', '1', '--out', str(out),
                           '--results', str(results), '--seeds-cache', str(seeds),
                           '--report', str(tmp_path / 'report.md'),
                           '--figures', str(tmp_path / 'figures')]) == 0
    text = (tmp_path / 'report.md').read_text()
    assert 'Nothing ran: the presets\' and ROS runs\' results are those committed in' in text
    assert 'python -m flock_swarm.reproduce --quick --skip-ros' in text  # the run that wrote them
    assert not (out / 'runs').exists() and not (out / 'results').exists()
    assert {p.name: p.read_bytes() for p in seeds.iterdir()} == cached  # read, not run
    # Every experiment's section and the summary are the ones the run itself wrote.
    original = re.split(r'^## ', (quick_reproduction / 'report.md').read_text(), flags=re.M)
    rendered = re.split(r'^## ', text, flags=re.M)
    assert rendered[2:] == original[2:] and len(rendered) == len(original) > 10
