"""Parameter studies (``sweep``): spec, safe expressions, cache, backends, interruptions.

One small study (two axes, a derived box side, three seeds, a metric at a time) is run in
this process (``--jobs 1``), on two local worker processes and on a Dask cluster of a real
``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1: the tables must be the
same (all but the wall-time column). A second study, of longer runs, is run once
uninterrupted, then with a local worker process SIGKILLed mid-sweep, with a Dask worker
SIGKILLed mid-sweep (the scheduler hands its tasks to the other worker), and with the sweep
SIGINTed and resumed: every table must equal the uninterrupted one. The CSVs are read back with
:mod:`csv`, and a row is checked against a run of ``sim``'s own code path.
"""

import contextlib
import csv
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flock_swarm.testing import wait_for
from flock_swarm.console import EXIT_SIGNAL
from flock_swarm.core.errors import ScenarioError
from flock_swarm.reproduce.experiments.su2009_fig3_sweep import fig3_tasks
from flock_swarm.reproduce.plan import Plan
from flock_swarm.presets import load
from flock_swarm.core.run import simulate
from flock_swarm.study.cache import cache_line, read_cache
from flock_swarm.study.execute import Job, Progress, make_jobs
from flock_swarm.study.expr import Expression, ExpressionError
from flock_swarm.study.spec import Run, parse_spec, plan_runs, points, read_spec
from flock_swarm.cli.sweep import main, spec_path
from flock_swarm.console import EXIT_RUNTIME

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parent.parent
#: The small study: 2 x 2 points, 3 seeds, 1 s runs of 10 and 16 agents.
SMALL = {
    'name': 'small', 'scenario': 'su2009_fig3', 'set': {'duration': 1.0},
    'grid': {'n_agents': [10, 16], 'informed.fraction': [0.25, 1.0]},
    'derived': {'initial.position_box':
                '[[0.0, sqrt(n_agents / 0.05)], [0.0, sqrt(n_agents / 0.05)]]'},
    'seeds': 3, 'metrics': ['eta', 'velocity_mismatch_max', 'collisions'], 'times': [0.0],
    'stack_agents': 20,
}
#: The study that is interrupted: 16 runs of about 0.2 s each, one run per job.
LONG = dict(SMALL, name='long', set={'duration': 6.0}, seeds=4, stack_agents=1)


def write_spec(path: Path, spec: dict) -> Path:
    """Write a spec file."""
    path.write_text(json.dumps(spec))
    return path


def read_csv(path: Path, drop=('wall_time_s',)) -> list[dict]:
    """Read a CSV back with :mod:`csv`, without the columns in ``drop``."""
    with open(path, newline='') as stream:
        return [{k: v for k, v in row.items() if k not in drop}
                for row in csv.DictReader(stream)]


def sweep_process(*args: str) -> subprocess.Popen:
    """Start the ``sweep`` executable."""
    return subprocess.Popen([str(BIN / 'sweep'), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def cache_lines(path: Path) -> int:
    """Return how many complete lines the cache holds."""
    return path.read_bytes().count(b'\n') if path.exists() else 0


def children(pid: int) -> list[int]:
    """Return the worker processes (multiprocessing spawn children) of ``pid``."""
    found = []
    for task in Path(f'/proc/{pid}/task').iterdir():
        for child in (task / 'children').read_text().split():
            try:
                cmdline = Path(f'/proc/{child}/cmdline').read_bytes()
            except OSError:
                continue
            if b'spawn_main' in cmdline:
                found.append(int(child))
    return found


@pytest.fixture(scope='module')
def small_serial(tmp_path_factory):
    """Run the small study with ``--jobs 1``; return its directory."""
    root = tmp_path_factory.mktemp('small')
    spec = write_spec(root / 'small.yaml', SMALL)
    assert main([str(spec), '--jobs', '1', '--out', str(root / 'serial'), '--quiet']) == 0
    return root


@pytest.fixture(scope='module')
def long_serial(tmp_path_factory):
    """Run the long study uninterrupted with ``--jobs 1``; return its directory."""
    root = tmp_path_factory.mktemp('long')
    spec = write_spec(root / 'long.yaml', LONG)
    assert main([str(spec), '--jobs', '1', '--out', str(root / 'serial'), '--quiet',
                 '--no-plots']) == 0
    return root


# --------------------------------------------------------------------------------------------
# Expressions


def test_expressions_compute_numbers_and_lists():
    side = Expression('[[0.0, sqrt(n_agents / 0.05)], [0.0, sqrt(n_agents / 0.05)]]')
    # Su 2009 V.A: N = 100 at density 0.05 is the preset's box side sqrt(2000).
    assert side.evaluate({'n_agents': 100}) == [[0.0, 44.721359549995796]] * 2
    assert side.names() == {'n_agents'}
    dotted = Expression('round(informed.fraction * 2 ** 3 - -1, 2)')
    assert dotted.evaluate({'informed.fraction': 0.5}) == 5
    assert Expression('max(1, int(log(exp(2.0))))').evaluate({}) == 2


@pytest.mark.parametrize('text', [
    "__import__('os').system('true')", '(1).real', "'text'", 'lambda: 1', 'x[0]',
    '[x for x in y]', 'open(1)', 'round(x, ndigits=1)', 'a if b else c', 'True', '1 <'])
def test_expressions_outside_the_language_are_rejected(text):
    with pytest.raises(ExpressionError):
        Expression(text)


@pytest.mark.parametrize('text, values', [('sqrt(x - 10)', {'x': 1}), ('1 / x', {'x': 0}),
                                          ('2 ** x', {'x': 5000}), ('y + 1', {'x': 1})])
def test_failing_expressions_say_so(text, values):
    with pytest.raises(ExpressionError, match='fails|larger|unknown name'):
        Expression(text).evaluate(values)


# --------------------------------------------------------------------------------------------
# Specs and plans


def test_the_shipped_fig3_spec_is_the_reproductions_sweep():
    spec = read_spec(spec_path('su2009_fig3'), seeds=1)
    runs = plan_runs(spec)
    assert len(runs) == 40 and spec.seeds == (0,)
    assert [r.digest for r in runs] == [r.digest for r in fig3_tasks(Plan(False, 1))]


@pytest.mark.parametrize('spec', ['reproduce_su2009_fig6', 'reproduce_os2003_sink',
                                  'reproduce_jadbabaie2003_linked'])
def test_a_headline_reruns_nothing(spec):
    """The presets' headlines (issue 24) changed no run: the committed caches hold them all."""
    runs = plan_runs(read_spec(spec_path(spec)))
    cached = read_cache(ROOT / 'docs' / 'reproduction' / 'runs' / f'{spec}.jsonl')
    assert runs and all(r.digest in cached for r in runs)
    # Any other headline or claim: the same digests.
    other = plan_runs(read_spec(spec_path(spec), overrides=(
        'metrics.headline=[min_pair_distance]', 'metrics.claim=another claim')))
    assert [r.digest for r in other] == [r.digest for r in runs]
    assert other[0].scenario().headline.keys == ('min_pair_distance',)


def test_plan_is_seed_major_largest_first_with_common_seeds():
    runs = plan_runs(parse_spec(SMALL))
    assert [(r.point['n_agents'], r.point['informed.fraction'], r.seed) for r in runs[:5]] \
        == [(16, 0.25, 0), (16, 1.0, 0), (10, 0.25, 0), (10, 1.0, 0), (16, 0.25, 1)]
    assert len(runs) == 12 and len({r.digest for r in runs}) == 12
    sc = runs[2].scenario()
    assert sc.seed == 0 and sc.duration == 1.0 and sc.informed.fraction == 0.25
    np.testing.assert_array_equal(sc.position_box, [[0.0, math.sqrt(200.0)]] * 2)


def test_zipped_axes_vary_together_within_the_grid():
    spec = parse_spec({'scenario': 'su2009_fig7', 'grid': {'n_agents': [10, 20]},
                       'zip': {'protocol.c1': [0.2, 0.5], 'protocol.c2': [0.4, 1.0]}})
    assert points(spec) == [{'n_agents': n, 'protocol.c1': c1, 'protocol.c2': c2}
                            for n in (10, 20) for c1, c2 in ((0.2, 0.4), (0.5, 1.0))]
    assert (spec.plot_x, spec.plot_line) == ('n_agents', 'protocol.c1')
    with pytest.raises(ScenarioError, match='zip: lists of different lengths'):
        parse_spec({'scenario': 'su2009_fig7', 'zip': {'dt': [0.01], 'duration': [1, 2]}})


def test_stacks_keep_the_order_and_split_evenly():
    runs = [Run({'delta': d}, seed, {}, f'{seed}/{n}/{d}', n, 10, f'{n} {seed}')
            for seed in range(2) for n in (300, 100) for d in range(10)]
    jobs = make_jobs(runs, stack_agents=1000)
    assert [r for job in jobs for r in job.runs] == runs
    # Per seed: 10 runs of N = 300 in stacks of at most 3, then one stack of 10 of N = 100.
    assert [len(job.runs) for job in jobs] == [3, 3, 2, 2, 10] * 2
    assert jobs[0].weight == 3 * 300 * 10
    unstackable = [Run({}, 0, {}, str(k), 5, 1, None) for k in range(3)]
    assert make_jobs(unstackable, 1000) == [Job((r,)) for r in unstackable]


def test_progress_lines_without_a_terminal_are_periodic():
    lines = []
    progress = Progress(4, 400.0, lines.append, every=3600.0)
    progress.step(1, 100.0, 'one')
    progress.step(2, 200.0, 'two')
    assert lines == []
    progress.step(1, 100.0, 'last')
    assert len(lines) == 1 and '4/4 runs' in lines[0] and 'ETA 0.0 min' in lines[0]


def test_progress_on_a_terminal_rewrites_one_line():
    live, said = [], []
    progress = Progress(2, 20.0, said.append, live=live.append)
    progress.step(1, 10.0, 'half')
    progress.step(1, 10.0, 'all')
    assert said == [] and len(live) == 2
    assert '1/2 runs' in live[0] and 'ETA' in live[0] and not live[0].endswith('\n')
    assert live[1].endswith('\n')


@pytest.mark.parametrize('change, named', [
    ({'grdi': {}}, 'grdi: unknown spec key'),
    ({'grid': {'n_agents': [10, -5]}}, "n_agents=-5"),
    ({'grid': {'protocol.c1': [0.5, 'fast']}}, 'protocol.c1'),
    ({'derived': {'initial.position_box': '[[0.0, sqrt(n_agents - 12)], [0.0, 1.0]]'}},
     'derived.initial.position_box'),
    ({'derived': {'initial.position_box': 'sqrt(N)'}}, "derived.initial.position_box: "
                                                       "unknown name 'N'"),
    ({'derived': {'initial.position_box': "__import__('os')"}},
     'derived.initial.position_box'),
    ({'metrics': ['eta', 'happiness']}, 'metrics[1]'),
    ({'times': [5.0]}, 'times: 5 s is after the end'),
    ({'seeds': 0}, 'seeds'),
    ({'plot': {'x': 'dt'}}, 'plot.x'),
])
def test_bad_specs_are_one_line_naming_the_key(tmp_path, capsys, change, named):
    spec = write_spec(tmp_path / 'bad.yaml', {**SMALL, **change})
    assert main([str(spec), '--jobs', '1', '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('sweep: error: ') and named in err, err
    assert not (tmp_path / 'out' / 'runs.jsonl').exists()


def test_an_unreachable_scheduler_is_one_line_naming_it(tmp_path, capsys):
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        address = f'tcp://127.0.0.1:{sock.getsockname()[1]}'
    spec = write_spec(tmp_path / 'small.yaml', SMALL)
    assert main([str(spec), '--scheduler', address, '--connect-timeout', '1',
                 '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and f'--scheduler: cannot reach {address}' in err, err
    assert not (tmp_path / 'out' / 'runs.jsonl').exists()


# --------------------------------------------------------------------------------------------
# Results


def test_tables_hold_every_run_once_with_sims_numbers(small_serial):
    rows = read_csv(small_serial / 'serial' / 'runs.csv', drop=())
    assert len(rows) == 12
    assert len({(r['n_agents'], r['informed.fraction'], r['seed']) for r in rows}) == 12
    assert {r['status'] for r in rows} == {'completed'}
    assert all(len(r['scenario_hash']) == 16 and r['flock_swarm_version'] for r in rows)
    # One row against sim's own code path on the same scenario.
    row = next(r for r in rows if (r['n_agents'], r['informed.fraction'], r['seed'])
               == ('16', '0.25', '2'))
    side = math.sqrt(16 / 0.05)
    sc = load('su2009_fig3', ['duration=1.0'], 2,
              {'n_agents': 16, 'informed.fraction': 0.25,
               'initial.position_box': [[0.0, side], [0.0, side]]})
    summary = simulate(sc).summary
    assert float(row['eta']) == summary['eta']
    assert float(row['velocity_mismatch_max']) == summary['velocity_mismatch_max']
    assert int(row['collisions']) == summary['collisions']
    # The aggregate, recomputed from the tidy rows.
    stats = read_csv(small_serial / 'serial' / 'summary.csv', drop=())
    assert len(stats) == 4 * 5
    for stat in stats:
        values = [float(r[stat['metric']]) for r in rows
                  if (r['n_agents'], r['informed.fraction'])
                  == (stat['n_agents'], stat['informed.fraction'])]
        assert int(stat['count']) == 3
        assert float(stat['mean']) == pytest.approx(np.mean(values), rel=1e-12, abs=1e-15)
        assert float(stat['std']) == pytest.approx(np.std(values, ddof=1), rel=1e-9,
                                                   abs=1e-15)
        assert float(stat['sem']) == pytest.approx(float(stat['std']) / math.sqrt(3))
        assert (float(stat['min']), float(stat['max'])) == (min(values), max(values))
    figures = sorted(p.name for p in (small_serial / 'serial').glob('*.png'))
    assert figures == ['collisions.png', 'eta.png', 'eta_at_0.png', 'velocity_mismatch_max.png',
                       'velocity_mismatch_max_at_0.png']


def test_local_pool_gives_the_same_tables(small_serial):
    out = small_serial / 'pool'
    assert main([str(small_serial / 'small.yaml'), '--jobs', '2', '--out', str(out),
                 '--quiet', '--no-plots']) == 0
    assert read_csv(out / 'runs.csv') == read_csv(small_serial / 'serial' / 'runs.csv')
    assert (out / 'summary.csv').read_bytes() \
        == (small_serial / 'serial' / 'summary.csv').read_bytes()


#: The environment of the Dask processes.
DASK_ENV = dict(os.environ, DASK_DISTRIBUTED__WORKER__DAEMON='False')


def dask_worker(address: str) -> subprocess.Popen:
    """Start a real ``dask worker`` process of the scheduler at ``address``."""
    # --no-nanny: a worker is one process, so that a SIGKILL really ends it.
    return subprocess.Popen([str(BIN / 'dask'), 'worker', address, '--nthreads', '1',
                             '--no-nanny', '--host', '127.0.0.1', '--no-dashboard'],
                            env=DASK_ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@contextlib.contextmanager
def dask_cluster(tmp_path: Path, workers: int = 2):
    """Run a real ``dask scheduler`` and ``workers`` ``dask worker`` processes on 127.0.0.1.

    :return: (context) the scheduler's address, the list of the worker processes (a worker
        appended to it is stopped with the others) and the scheduler's process.
    """
    info = tmp_path / 'scheduler.json'
    scheduler = subprocess.Popen([str(BIN / 'dask'), 'scheduler', '--host', '127.0.0.1',
                                  '--port', '0', '--no-dashboard', '--scheduler-file',
                                  str(info)],
                                 env=DASK_ENV, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
    started: list[subprocess.Popen] = []
    try:
        wait_for(info.exists, 60.0, 'the Dask scheduler file')
        address = json.loads(info.read_text())['address']
        assert address.startswith('tcp://127.0.0.1:')
        started.extend(dask_worker(address) for _ in range(workers))
        yield address, started, scheduler
    finally:
        # SIGKILL: the tests are done with the cluster, and a graceful close of a worker
        # took up to a 20 s bound per process on a busy machine, for nothing a test reads.
        for proc in [*started, scheduler]:
            proc.kill()
            proc.wait(timeout=20)


@pytest.fixture(scope='session')
def session_cluster(tmp_path_factory):
    """One real Dask cluster of two workers for the session's tests that use a working one
    (:func:`shared_cluster`); started once: a new cluster's workers took seconds to start
    and to import the simulator at their first task."""
    with dask_cluster(tmp_path_factory.mktemp('dask')) as (address, workers, scheduler):
        yield address, workers, scheduler


@pytest.fixture
def shared_cluster(session_cluster):
    """Return the session's cluster (address, workers, scheduler), with two live workers: one
    that an earlier test killed is replaced."""
    address, workers, scheduler = session_cluster
    assert scheduler.poll() is None, 'the session\'s Dask scheduler exited'
    for k, proc in enumerate(workers):
        if proc.poll() is not None:
            workers[k] = dask_worker(address)
    return session_cluster


def test_a_dask_cluster_gives_the_same_tables(small_serial, tmp_path, shared_cluster):
    address, _, _ = shared_cluster
    out = tmp_path / 'dask'
    assert main([str(small_serial / 'small.yaml'), '--scheduler', address,
                 '--out', str(out), '--quiet', '--no-plots']) == 0
    assert read_csv(out / 'runs.csv') == read_csv(small_serial / 'serial' / 'runs.csv')
    assert (out / 'summary.csv').read_bytes() \
        == (small_serial / 'serial' / 'summary.csv').read_bytes()


def test_a_killed_dask_worker_has_its_runs_redone(long_serial, tmp_path, shared_cluster):
    out = tmp_path / 'dask-killed'
    address, workers, _ = shared_cluster
    killed = workers[0]
    status, err = hit_mid_sweep(long_serial / 'long.yaml', out, 1, lambda proc: killed.kill(),
                                '--scheduler', address)
    assert killed.wait(timeout=30) == -signal.SIGKILL
    assert status == 0, err
    assert len(read_cache(out / 'runs.jsonl')) == 16
    assert cache_lines(out / 'runs.jsonl') == 16
    assert read_csv(out / 'runs.csv') == read_csv(long_serial / 'serial' / 'runs.csv')


# --------------------------------------------------------------------------------------------
# Interruptions and the cache


def hit_mid_sweep(spec: Path, out: Path, finished: int, hit, *backend: str
                  ) -> tuple[int, str]:
    """Run ``sweep`` on two workers, call ``hit(process)`` once ``finished`` runs are cached.

    :param backend: where the sweep runs (default: ``--jobs 2``, two local processes).
    :return: the exit status and the standard error.
    """
    proc = sweep_process(str(spec), *(backend or ('--jobs', '2')), '--out', str(out),
                         '--no-plots')
    try:
        wait_for(lambda: cache_lines(out / 'runs.jsonl') >= finished, 120.0,
                 f'{finished} finished run(s)')
        hit(proc)
        _, err = proc.communicate(timeout=180)
    finally:
        proc.kill()
    return proc.returncode, err


def running(pid: int) -> bool:
    """Return whether process ``pid`` is running (``R`` in ``/proc/PID/stat``): a worker
    busy with a run, not one waiting on its pipe for the next task."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text()
    except OSError:
        return False
    return stat.rpartition(')')[2].split()[0] == 'R'


def kill_a_worker(proc: subprocess.Popen) -> None:
    """SIGKILL one of the sweep's two worker processes while it runs a task (one killed
    between a result and its next task held no job: nothing to redo)."""
    wait_for(lambda: len(children(proc.pid)) == 2, 30.0, 'two worker processes')
    busy: list[int] = []
    wait_for(lambda: busy.extend(p for p in children(proc.pid) if running(p)) or busy, 30.0,
             'a worker process running a task')
    os.kill(busy[0], signal.SIGKILL)


def test_a_killed_worker_process_has_its_runs_redone(long_serial):
    out = long_serial / 'killed'
    status, err = hit_mid_sweep(long_serial / 'long.yaml', out, 1, kill_a_worker)
    assert status == 0, err
    assert 'died (exit code -9); its job is redone' in err
    assert len(read_cache(out / 'runs.jsonl')) == 16
    assert cache_lines(out / 'runs.jsonl') == 16
    assert read_csv(out / 'runs.csv') == read_csv(long_serial / 'serial' / 'runs.csv')


def test_sigterm_stops_a_sweep_as_ctrl_c_does(long_serial):
    """SIGTERM to sweep: the finished runs are kept, one line says so, exit status 143."""
    out = long_serial / 'terminated'
    status, err = hit_mid_sweep(long_serial / 'long.yaml', out, 2,
                                lambda proc: proc.send_signal(signal.SIGTERM))
    assert status == EXIT_SIGNAL[signal.SIGTERM], err
    assert err.rstrip().splitlines()[-1].startswith('sweep: interrupted; every finished run')
    problems = []
    kept = read_cache(out / 'runs.jsonl', report=problems.append)
    assert problems == [] and 2 <= len(kept) < 16


def test_an_interrupted_sweep_resumes_to_the_same_table(long_serial):
    out = long_serial / 'interrupted'
    status, err = hit_mid_sweep(long_serial / 'long.yaml', out, 2,
                                lambda proc: proc.send_signal(signal.SIGINT))
    assert status == 130, err
    assert err.rstrip().splitlines()[-1].startswith('sweep: interrupted; every finished run')
    problems = []
    kept = read_cache(out / 'runs.jsonl', report=problems.append)
    assert problems == [] and 2 <= len(kept) < 16
    resumed = subprocess.run([str(BIN / 'sweep'), str(long_serial / 'long.yaml'), '--jobs', '2',
                              '--out', str(out), '--no-plots'], capture_output=True, text=True,
                             timeout=180)
    assert resumed.returncode == 0, resumed.stderr
    assert f'{16 - len(kept)} to run' in resumed.stderr and f'{len(kept)} reused' in resumed.stderr
    assert read_csv(out / 'runs.csv') == read_csv(long_serial / 'serial' / 'runs.csv')


def test_corrupt_cache_lines_are_reported_and_rerun(small_serial, tmp_path, capsys):
    cache = tmp_path / 'out' / 'runs.jsonl'
    cache.parent.mkdir()
    lines = (small_serial / 'serial' / 'runs.jsonl').read_text().splitlines(keepends=True)
    edited = lines[3].replace('"seed": ', '"seed": 1', 1)
    cache.write_text(''.join(lines[:3]) + edited + ''.join(lines[4:-1]) + lines[-1][:30])
    assert main([str(small_serial / 'small.yaml'), '--jobs', '1', '--out', str(cache.parent),
                 '--no-plots']) == 0
    err = capsys.readouterr().err
    assert f'{cache}:4: unusable cache line (its check does not match' in err
    assert f'{cache}:12: unusable cache line (not a complete JSON line' in err
    assert '2 to run in' in err and '10 reused' in err
    assert read_csv(cache.parent / 'runs.csv') \
        == read_csv(small_serial / 'serial' / 'runs.csv')


def test_cache_lines_round_trip_and_need_their_check(tmp_path):
    path = tmp_path / 'runs.jsonl'
    good = {'digest': 'abc', 'status': 'completed', 'eta': 0.25}
    path.write_text(cache_line(good) + json.dumps(good | {'digest': 'def'}) + '\n')
    problems = []
    assert read_cache(path, report=problems.append) == {'abc': good}
    assert len(problems) == 1 and ':2: unusable cache line' in problems[0]


def test_scenario_errors_name_the_point():
    spec = parse_spec({**SMALL, 'grid': {'n_agents': [10, 0]}})
    with pytest.raises(ScenarioError, match='n_agents=0'):
        plan_runs(spec)


def test_every_seed_is_prepared_as_the_first_is(tmp_path, capsys):
    """Each seed's realisation goes through presets.prepare: a seed whose own Barabasi-Albert
    graph puts dt beyond the step bound is refused, naming it (only the first seed's was
    checked; the others' scenarios were re-parsed without the checks)."""
    spec = {'scenario': 'zhou2012_sec52', 'seeds': [1, 2, 7],
            'set': {'n_agents': 20, 'duration': 0.1, 'informed.count': 2,
                    'graph': {'type': 'barabasi_albert', 'm0': 2, 'm': 1}},
            'grid': {'dt': [0.0012, 0.0024]}}
    assert len(plan_runs(parse_spec({**spec, 'seeds': [1, 2]}))) == 4
    line = sweep_error(tmp_path, capsys, spec)
    assert line.startswith('sweep: error: dt=0.0024, seed=7: dt: '), line
    assert len(plan_runs(parse_spec(spec), allow_unstable=True)) == 6


# --------------------------------------------------------------------------------------------
# Issue 24: bounded inputs, no silent acceptance


def sweep_error(tmp_path: Path, capsys, spec: dict, *args: str) -> str:
    """Run ``sweep`` on a spec that must be refused; return its one error line."""
    path = write_spec(tmp_path / 'spec.yaml', spec)
    assert main([str(path), '--jobs', '1', '--out', str(tmp_path / 'out'), *args]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('sweep: error: '), err
    assert not (tmp_path / 'out' / 'runs.jsonl').exists()
    return err.strip()


def test_a_binary_spec_is_one_line_like_a_binary_scenario(tmp_path, capsys):
    path = tmp_path / 'spec.yaml'
    path.write_bytes(b'\x89PNG\r\n\x1a\n\x00\xff')
    assert main([str(path), '--out', str(tmp_path / 'out')]) == 2
    assert capsys.readouterr().err == (f'sweep: error: spec: {path}: not UTF-8 text (byte 0x89 '
                                       'at offset 0); a sweep spec is a YAML file\n')


def test_a_spec_with_a_key_twice_is_refused(tmp_path, capsys):
    path = tmp_path / 'spec.yaml'
    path.write_text('name: a\nscenario: demo\nseeds: 2\nseeds: 3\n')
    assert main([str(path), '--out', str(tmp_path / 'out')]) == 2
    assert capsys.readouterr().err == (f"sweep: error: spec: {path}: invalid YAML at line 4: "
                                       "duplicate key 'seeds' (a key may be given once)\n")


@pytest.mark.parametrize('text, why', [
    ('[1] * 1000000000', 'a list of 1000000000 numbers: the budget of an expression is 100000'),
    ('[1] * 10000000', 'a list of 10000000 numbers'),
    ('[[0.0] * 1000] * 1000', 'a list of 1000000 numbers'),
    ('(10 ** 1000) ** 1000', 'an integer of about 3322000 bits: the budget of an expression '
                             'is 10000 bits'),
    ('(10 ** 999) * (10 ** 999) * (10 ** 999) * (10 ** 999)', 'an integer of about'),
    ('2 ** 2 ** 2 ** 2 ** 2', 'exponent 65536 is larger than 1000'),
    ('((2 ** 1000) ** 1000) ** 1000', 'an integer of about 1001000 bits'),
    ('round(n_agents, -10 ** 9)', 'round to -1000000000 digits: at most 1000'),
    ('1' * 1001, '1001 characters: an expression has at most 1000'),
    ('+'.join(['1'] * 150), 'operations and operands: an expression has at most 200'),
])
def test_expressions_beyond_the_budget_are_refused_before_computing(text, why):
    with pytest.raises(ExpressionError, match=re.escape(why)):
        Expression(text).evaluate({'n_agents': 10})


def test_a_derived_value_beyond_the_budget_is_one_line(tmp_path, capsys):
    err = sweep_error(tmp_path, capsys, {**SMALL, 'derived': {'description': '[1] * 10 ** 9'}})
    assert err.startswith("sweep: error: derived.description: '[1] * 10 ** 9': a list of ")


def test_a_grid_above_the_bound_is_refused_before_it_is_expanded(tmp_path, capsys):
    grid = {f'protocol.{key}': [0.1 * k for k in range(1, 21)]
            for key in ('c1', 'c2', 'a', 'b', 'h', 'eps')}
    err = sweep_error(tmp_path, capsys, {**SMALL, 'grid': grid, 'derived': {}})
    assert err == ("sweep: error: grid: 64000000 points (the product of the axes' lengths): at "
                   'most 10000 per sweep (split the study into several specs)')


@pytest.mark.parametrize('seeds, why', [
    (10 ** 30, 'seeds: 1000000000000000000000000000000 seeds: at most 1000000 runs in all'),
    ({'first': 2 ** 63 - 1, 'count': 2}, 'seeds: a seed must be <= 2**63 - 1'),
    ([0, 2 ** 64], 'seeds: a seed must be <= 2**63 - 1'),
    (300_000, 'seeds: 4 points x 300000 seeds = 1200000 runs: at most 1000000 per sweep'),
])
def test_seeds_are_bounded_like_the_scenarios(seeds, why, tmp_path, capsys):
    assert why in sweep_error(tmp_path, capsys, {**SMALL, 'seeds': seeds})


def test_seeds_option_beyond_the_bound_is_one_line(tmp_path, capsys):
    assert 'at most 1000000 runs in all' in sweep_error(tmp_path, capsys, SMALL, '--seeds',
                                                        str(10 ** 12))


def test_planning_shows_its_progress(monkeypatch):
    import flock_swarm.study.spec as spec_module
    monkeypatch.setattr(spec_module, 'PLAN_EVERY', 2)
    lines = []
    plan_runs(parse_spec(SMALL), say=lines.append)
    assert lines == ['[sweep] planning: 2/4 points checked',
                     '[sweep] planning: 4/4 points checked']


@pytest.mark.parametrize('key', ['n_agents', 'informed.fraction', 'informed',
                                 'initial.position_box', 'initial.position_box.x'])
def test_set_on_a_key_the_points_set_is_refused(key, tmp_path, capsys):
    err = sweep_error(tmp_path, capsys, SMALL, '--set', f'{key}=1')
    assert err.startswith(f'sweep: error: --set: {key} is set per point by the spec (')


def test_set_wins_over_the_specs_set_and_is_validated(tmp_path, capsys):
    runs = plan_runs(parse_spec(SMALL, ('duration=0.5',)))
    assert {run.data['duration'] for run in runs} == {0.5}
    assert sweep_error(tmp_path, capsys, SMALL, '--set', 'duration=-5').endswith(
        'duration: must be > 0, got -5')
    assert 'protocol.c1' in sweep_error(tmp_path, capsys, SMALL, '--set', 'protocol.c1=abc')


def test_times_after_a_shortened_run_are_dropped_with_a_notice(tmp_path, capsys):
    spec = write_spec(tmp_path / 'spec.yaml', {**SMALL, 'times': [0.0, 0.5], 'seeds': 1})
    assert main([str(spec), '--jobs', '1', '--out', str(tmp_path / 'out'), '--no-plots',
                 '--set', 'duration=0.2']) == 0
    err = capsys.readouterr().err
    assert '[sweep] times: 0.5 s dropped: after the end of the runs set by --set duration' in err
    header = (tmp_path / 'out' / 'runs.csv').read_text().splitlines()[0]
    assert 'eta@0' in header and 'eta@0.5' not in header
    # A spec whose own times lie after its own runs' end is still refused.
    (tmp_path / 'again').mkdir()
    assert 'times: 5 s is after the end' in sweep_error(tmp_path / 'again', capsys,
                                                        {**SMALL, 'times': [5.0]})


@pytest.mark.parametrize('value', ['-1', '0', 'inf', 'nan'])
def test_connect_timeout_must_be_positive(value, tmp_path, capsys):
    err = sweep_error(tmp_path, capsys, SMALL, '--connect-timeout', value)
    assert err.startswith('sweep: error: --connect-timeout: must be a number of seconds > 0')


def test_unusable_cache_lines_are_reported_once(small_serial, tmp_path, capsys):
    cache = tmp_path / 'out' / 'runs.jsonl'
    cache.parent.mkdir()
    lines = (small_serial / 'serial' / 'runs.jsonl').read_text().splitlines(keepends=True)
    cache.write_text(''.join(lines[:-1]) + lines[-1][:30])
    args = [str(small_serial / 'small.yaml'), '--jobs', '1', '--out', str(cache.parent),
            '--no-plots']
    assert main(args) == 0
    err = capsys.readouterr().err
    assert err.count('unusable cache line') == 1
    assert (Path(f'{cache}.unusable')).read_text() == lines[-1][:30] + '\n'
    assert main(args) == 0
    assert 'unusable cache line' not in capsys.readouterr().err


def test_a_scheduler_without_workers_is_one_line_with_the_runtime_status(tmp_path, capsys):
    spec = write_spec(tmp_path / 'small.yaml', SMALL)
    with dask_cluster(tmp_path, workers=0) as (address, _, _):
        status = main([str(spec), '--scheduler', address, '--connect-timeout', '2',
                       '--out', str(tmp_path / 'out'), '--quiet'])
    err = capsys.readouterr().err
    assert status == EXIT_RUNTIME == 3
    assert err.startswith(f'sweep: error: --scheduler: no Dask worker for 2 s at {address} (0 '
                          'of ') and err.count('\n') == 1
    assert err.endswith(' jobs done, kept in the cache); start workers and run the same command '
                        'again\n')


#: The study whose Dask scheduler is killed: 16 runs of about a second, one run per job.
LOST = dict(LONG, name='lost', set={'duration': 40.0})


def test_a_lost_scheduler_is_one_line_and_the_rerun_reuses_the_cache(long_serial, tmp_path):
    spec = write_spec(tmp_path / 'lost.yaml', LOST)
    out = tmp_path / 'lost'
    with dask_cluster(tmp_path) as (address, _, scheduler):
        status, err = hit_mid_sweep(spec, out, 1, lambda proc: scheduler.kill(),
                                    '--scheduler', address)
    assert status == EXIT_RUNTIME, err
    last = err.rstrip().splitlines()[-1]
    assert last.startswith(f'sweep: error: --scheduler: lost the Dask scheduler at {address} (')
    assert last.endswith('jobs done, kept in the cache); run the same command again to go on')
    assert 'Traceback' not in err
    kept = read_cache(out / 'runs.jsonl')
    assert 1 <= len(kept) < 16
    resumed = subprocess.run([str(BIN / 'sweep'), str(spec), '--jobs', '2', '--out', str(out),
                              '--no-plots'], capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f'{len(kept)} reused' in resumed.stderr


@pytest.mark.parametrize('value', ['7', str(2 ** 70)])
def test_set_seed_is_refused_with_where_the_seeds_come_from(value, tmp_path, capsys):
    """``--set seed=...`` was replaced by each run's seed (0, 1, ...) without a word."""
    err = sweep_error(tmp_path, capsys, SMALL, '--set', f'seed={value}')
    assert err == ("sweep: error: --set: seed: every run takes its seed from the spec's seeds; "
                   'give --seeds R (0 .. R-1) or the spec key seeds (a list, or {first, '
                   'count})')


@pytest.mark.parametrize('key, axis', [('n_agents', 'n_agents'),
                                       ('informed', 'informed.fraction'),
                                       ('initial.position_box', 'initial.position_box')],
                         ids=['axis', 'holding-an-axis', 'derived'])
def test_a_specs_set_key_the_points_set_is_refused(key, axis, tmp_path, capsys):
    """A key of the spec's ``set:`` that is also an axis (or a derived value) was silently
    replaced by the point's value."""
    fixed = {'duration': 1.0, key: {'fraction': 0.5} if key == 'informed' else 12}
    err = sweep_error(tmp_path, capsys, {**SMALL, 'set': fixed})
    kind = 'a derived value' if key == 'initial.position_box' else 'an axis'
    # A mapping's error names the value the point replaces (informed.fraction).
    leaf = axis if key == 'informed' else key
    assert err == (f'sweep: error: set.{leaf}: is also set per point ({kind}: {axis}), whose '
                   'value would replace it; remove it from set')


def test_an_axis_below_a_mapping_of_the_set_refines_it(tmp_path):
    """An axis under a mapping the set gives (network.loss: {model: ...} with the axis
    network.loss.loss_bad) refines it: the set's other keys stay, nothing is refused."""
    spec = parse_spec({'scenario': 'demo', 'set': {'duration': 0.2, 'network.loss': {
        'model': 'gilbert_elliott', 'p_good_bad': 0.1, 'p_bad_good': 0.5}},
        'grid': {'network.loss.loss_bad': [1.0, 0.8]}, 'seeds': 1})
    last = plan_runs(spec)[-1].scenario().network.agents.loss
    assert (last.model, last.p_good_bad, last.loss_bad) == ('gilbert_elliott', 0.1, 0.8)


def test_a_specs_set_seed_is_refused(tmp_path, capsys):
    err = sweep_error(tmp_path, capsys, {**SMALL, 'set': {'duration': 1.0, 'seed': 3}})
    assert err == ('sweep: error: set.seed: every run takes its seed from the spec key seeds '
                   '(a count, a list, or {first, count}); move it there')


def test_a_signal_while_a_large_grid_is_planned_is_one_line_and_its_status(tmp_path):
    """SIGTERM while the 10,000 points of a grid are checked: one line, status 143 (it was
    KeyboardInterrupt's traceback, and Ctrl-C's 130 for SIGTERM too)."""
    values = [round(0.1 * k, 1) for k in range(1, 11)]
    spec = write_spec(tmp_path / 'big.yaml', {
        'name': 'big', 'scenario': 'demo', 'grid': {
            'protocol.c1': values, 'protocol.c2': values, 'protocol.a': values,
            'duration': [float(k) for k in range(1, 11)]}})
    proc = sweep_process(str(spec), '--jobs', '1', '--out', str(tmp_path / 'out'))
    try:
        line = proc.stderr.readline()
        assert line.startswith('[sweep] planning: 1000/10000 points checked'), line
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == EXIT_SIGNAL[signal.SIGTERM], err
    assert err.splitlines()[-1] == 'sweep: interrupted before any run started', err
    assert 'Traceback' not in err


def test_jobs_beyond_four_per_core_are_refused(tmp_path, capsys):
    from flock_swarm.cli.sweep import max_jobs
    err = sweep_error(tmp_path, capsys, SMALL, '--jobs', '100000')
    assert err == (f'sweep: error: --jobs: at most {max_jobs()} (four per core of this machine, '
                   '64 at least), got 100000')
