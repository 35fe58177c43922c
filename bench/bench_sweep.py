"""Benchmark of the Su 2009 Fig. 3 Monte Carlo sweep: measure a subset, project the full sweep.

    python bench/bench_sweep.py [--realisations 2] [--jobs 2] [--out DIR] [--json FILE]
                                [--full-realisations 50] [--scheduler ADDRESS|local]
                                [--sizes N ...] [--fractions D ...] [--set KEY=VALUE ...]

Runs the sweep of ``python -m flock_swarm.reproduce`` alone (no presets, no ROS runs, no
report): every (N, delta) point of Fig. 3 (N = 100, 300, 500, 1000; ten informed fractions),
100 s at dt = 0.02 (5000 steps) per run, with ``--realisations`` seeds per point, stacked and
spread over ``--jobs`` worker processes exactly as the reproduction runs them (the sweep
machinery, :mod:`flock_swarm.study`), or over a Dask cluster with ``--scheduler``. The subset
holds whole realisations, i.e. the full sweep's mix of sizes and fractions, so the full
sweep's wall time is projected as ``measured wall x full realisations / realisations``;
the pool's idle tail at the end makes this projection err on the long side.

Without ``--out`` the runs go to a fresh temporary directory (a measurement, nothing
reused). With ``--out`` the cache there is used and extended like the reproduction's, so
``--realisations 50 --out out/reproduce`` *is* the full sweep (resumable, with a progress
bar), and ``scripts/reproduce --realisations 50`` then reuses it for the report.

``--sizes``, ``--fractions`` and ``--set`` (for example ``--set duration=20``) make a smaller
grid, to compare backends in a few minutes; the projection then holds for that grid only.
"""

import argparse
import json
import os
import platform
import resource
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from flock_swarm.reproduce.execution import run_simulations
from flock_swarm.reproduce.experiments.su2009_fig3_sweep import FIG3_PAPER_REALISATIONS
from flock_swarm.reproduce.plan import FIG3_FRACTIONS, FIG3_SIZES, Plan
from flock_swarm.reproduce.report import append_invocation, git_revision, machine
from flock_swarm.study.execute import DaskBackend, SweepError, terminal_line

#: The issue's target for the full sweep on a 2-core machine [min].
TARGET_MIN = 60.0


def cpu_seconds() -> float:
    """Return the CPU time used so far by this process and its finished children [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def per_size(records: list[dict]) -> dict[int, dict]:
    """Return, per N, the runs measured and their mean and total cost [CPU-s]."""
    out = {}
    for n in sorted({r['n_agents'] for r in records}):
        cost = np.array([r['wall_time_s'] for r in records if r['n_agents'] == n])
        out[n] = {'runs': int(cost.size), 'mean_s': float(cost.mean()),
                  'total_s': float(cost.sum())}
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the subset, print the measurement and the projection; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--realisations', type=int, default=2,
                        help='seeds per (N, delta) point to run (default: 2)')
    parser.add_argument('--full-realisations', type=int, default=FIG3_PAPER_REALISATIONS,
                        help='realisations of the sweep to project to (default: 50)')
    parser.add_argument('--jobs', type=int, default=2, help='worker processes (default: 2)')
    parser.add_argument('--out', type=Path,
                        help='run cache to use and extend (default: a fresh temporary one)')
    parser.add_argument('--json', type=Path, help='also write the results here')
    parser.add_argument('--scheduler', metavar='ADDRESS',
                        help='run on the Dask scheduler at ADDRESS, or "local" (a LocalCluster '
                        'of --jobs single-threaded workers, started before the clock)')
    parser.add_argument('--sizes', type=int, nargs='+', default=list(FIG3_SIZES),
                        help='group sizes N (default: the paper\'s four)')
    parser.add_argument('--fractions', type=float, nargs='+', default=list(FIG3_FRACTIONS),
                        help='informed fractions (default: the reproduction\'s ten)')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE', help='override a value of every run')
    args = parser.parse_args(argv)
    if args.realisations < 1 or args.full_realisations < 1 or args.jobs < 1:
        parser.error('--realisations, --full-realisations and --jobs must be >= 1')
    command = 'python bench/bench_sweep.py' + ''.join(
        f' {shlex.quote(a)}' for a in (sys.argv[1:] if argv is None else argv))
    plan = Plan(False, args.realisations, tuple(args.sizes), tuple(args.fractions),
                tuple(args.overrides))
    host = machine()
    started = time.strftime('%Y-%m-%d %H:%M', time.gmtime())
    revision = git_revision()
    print(f'# {command}')
    print(f'# {host["nproc"]} CPUs ({host["cpu_model"]}), Python {platform.python_version()}, '
          f'load average {" ".join(f"{x:.2f}" for x in host["load_average"])} at the start')
    backend = None
    if args.scheduler is not None:
        try:
            backend = DaskBackend(args.scheduler, args.jobs)
        except SweepError as exc:
            parser.error(str(exc))
    print(f'# sweep: N = {", ".join(map(str, plan.sizes))}; '
          f'delta = {", ".join(f"{d:g}" for d in plan.fractions)}; '
          f'{args.realisations} realisation(s) each; '
          f'{backend.name if backend is not None else f"{args.jobs} worker(s)"}', flush=True)

    def say(line: str) -> None:
        """Print a progress line to stderr."""
        print(line, file=sys.stderr, flush=True)

    live = terminal_line if sys.stderr.isatty() else None
    with tempfile.TemporaryDirectory(prefix='bench_sweep_') as scratch:
        out = args.out if args.out is not None else Path(scratch)
        cpu0, wall0 = cpu_seconds(), time.monotonic()
        try:
            sims = run_simulations(plan, out, args.jobs, False, say, presets=False, live=live,
                                   backend=backend)
        finally:
            if backend is not None:
                backend.close()
        wall, cpu = time.monotonic() - wall0, cpu_seconds() - cpu0
    load_end = list(os.getloadavg())
    if args.out is not None and sims['executed']:
        # The reproduction's report lists the invocations that computed its runs.
        append_invocation(args.out, {
            'command': command, 'date': started, 'git': revision, 'quick': False,
            'realisations': args.realisations, 'wall_min': round(wall / 60.0, 2),
            'sim_runs': sims['executed'], 'sim_cpu_min': round(cpu / 60.0, 2),
            'sim_wall_min': round(wall / 60.0, 2), 'ros_runs': 0, 'ros_wall_min': 0.0,
            'nproc': host['nproc'], 'cpu_model': host['cpu_model'],
            'load_average': host['load_average']})
    runs = len(sims['sweeps']['su2009_fig3'])
    full_runs = runs // args.realisations * args.full_realisations
    measured = sims['executed'] == runs
    projected = wall / args.realisations * args.full_realisations if measured else None
    result = {'command': command, 'machine': host, 'load_average_end': load_end,
              'realisations': args.realisations, 'jobs': args.jobs, 'runs': runs,
              'executed': sims['executed'], 'wall_s': wall, 'cpu_s': cpu,
              'runs_per_min': sims['executed'] / wall * 60.0,
              'cpu_per_run_s': cpu / max(sims['executed'], 1),
              'parallel_efficiency': cpu / wall / args.jobs,
              'per_size': per_size(sims['sweeps']['su2009_fig3']),
              'full_realisations': args.full_realisations, 'full_runs': full_runs,
              'projected_full_wall_min': None if projected is None else projected / 60.0}
    print(f'measured: {sims["executed"]} runs ({sims["cached"]} reused) in {wall / 60:.2f} min '
          f'wall, {cpu / 60:.2f} CPU-min: {result["runs_per_min"]:.1f} runs/min, '
          f'{result["cpu_per_run_s"]:.2f} CPU-s per run, the workers busy '
          f'{100 * result["parallel_efficiency"]:.0f} % of the time')
    for n, row in result['per_size'].items():
        print(f'  N = {n:>4}: {row["runs"]:>4} runs, {row["mean_s"]:6.2f} s per run '
              f'(share of its stack), {row["total_s"] / 60:6.2f} min in all')
    print(f'load average at the end: {" ".join(f"{x:.2f}" for x in load_end)}')
    paper_grid = (plan.sizes, plan.fractions, plan.fig3_overrides) \
        == (FIG3_SIZES, FIG3_FRACTIONS, ())
    if projected is None:
        print('projection: none (runs were reused from --out; measure into a fresh directory)')
    elif not paper_grid:
        print(f'projection: this grid ({full_runs} runs, {args.full_realisations} '
              f'realisations) takes {projected / 60:.1f} min wall (not the full sweep)')
    else:
        verdict = 'PASS' if projected / 60.0 < TARGET_MIN else 'FAIL'
        print(f'projection: the full sweep ({full_runs} runs, {args.full_realisations} '
              f'realisations) takes {wall / 60:.2f} min x {args.full_realisations} / '
              f'{args.realisations} = {projected / 60:.1f} min wall on {args.jobs} worker(s)')
        print(f'target: full sweep under {TARGET_MIN:.0f} min: {verdict} '
              f'({projected / 60:.1f} min projected)')
    print(f'full sweep: python bench/bench_sweep.py --realisations {args.full_realisations} '
          f'--jobs {args.jobs} --out out/reproduce')
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
