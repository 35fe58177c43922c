"""The command line of the reproduction (``python -m flock_swarm.reproduce``,
``scripts/reproduce``)."""

import argparse
import json
import shlex
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable

from flock_swarm.reproduce.catalogue import all_experiments
from flock_swarm.reproduce.common import FIG_MAX_BYTES
from flock_swarm.reproduce.execution import (ROS_DOMAIN_BASE, ros_experiments, run_ros,
                                             run_simulations)
from flock_swarm.reproduce.plan import Plan
from flock_swarm.reproduce.report import (git_revision, machine, record_invocation, write_report,
                                          write_seeds_report)
from flock_swarm.reproduce.seeds import SEEDS_CACHE, run_studies
from flock_swarm.study.execute import (DaskBackend, LocalPool, SerialBackend, SweepError,
                                       terminal_line)
from flock_swarm.study.spec import plain


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``python -m flock_swarm.reproduce``."""
    parser = argparse.ArgumentParser(
        prog='python -m flock_swarm.reproduce',
        description='Run every experiment of the papers and write the reproduction report.')
    parser.add_argument('--out', type=Path, default=Path('out/reproduce'),
                        help='runs, caches and JSON results (default: out/reproduce)')
    parser.add_argument('--report', type=Path, default=Path('docs/reproduction.md'),
                        help='the Markdown report (default: docs/reproduction.md)')
    parser.add_argument('--figures', type=Path, default=Path('docs/figures'),
                        help='the report\'s PNG figures (default: docs/figures)')
    parser.add_argument('--realisations', type=int,
                        help='realisations per point of Su 2009 Fig. 3 (default: 10; '
                        '1 with --quick)')
    parser.add_argument('--quick', action='store_true',
                        help='tiny sizes and durations, for tests (numbers are no reproduction)')
    parser.add_argument('--skip-ros', action='store_true', help='skip the ROS node runs')
    parser.add_argument('--jobs', type=int, default=2, help='worker processes (default: 2)')
    parser.add_argument('--scheduler', metavar='ADDRESS',
                        help='run the simulations on the Dask scheduler at ADDRESS, or "local" '
                        '(see docs/sweeps.md)')
    parser.add_argument('--fresh', action='store_true', help='ignore cached runs')
    parser.add_argument('--seeds-cache', type=Path, metavar='DIR',
                        help='the caches of the experiments over seeds (default: '
                        f'{SEEDS_CACHE}, the committed ones; OUT/seeds with --quick)')
    parser.add_argument('--fig3-curves', action='store_true',
                        help='run (or resume) the four Su 2009 Fig. 3 curves (hours); '
                        'without it the report draws what their caches hold')
    parser.add_argument('--seeds-only', action='store_true',
                        help='only the experiments over seeds and the Fig. 3 curves: no '
                        'presets, no ROS runs; the report holds their sections alone')
    parser.add_argument('--cached-seeds', action='store_true',
                        help='run nothing new over seeds: the distributions use what the '
                        'caches hold (the report states the counts)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the reproduction from the command line; return the exit status (130 when
    interrupted: every finished run is in its cache, and the same command resumes)."""
    try:
        return run(argv)
    except KeyboardInterrupt:
        print('reproduce: interrupted; every finished run is kept in its cache (--out and '
              'the studies\' caches); run the same command again to resume', file=sys.stderr)
        return 130


def run(argv: list[str] | None = None) -> int:
    """Run the reproduction; return the exit status (see :func:`main`)."""
    args = build_parser().parse_args(argv)
    if args.realisations is not None and args.realisations < 1:
        print('reproduce: error: --realisations must be >= 1', file=sys.stderr)
        return 2
    if args.jobs < 1:
        print('reproduce: error: --jobs must be >= 1', file=sys.stderr)
        return 2
    argv_used = sys.argv[1:] if argv is None else list(argv)
    started = time.monotonic()

    def say(line: str) -> None:
        """Print a progress line to stderr."""
        print(line, file=sys.stderr, flush=True)

    meta: dict[str, Any] = {
        'command': 'python -m flock_swarm.reproduce' + ''.join(
            f' {shlex.quote(a)}' for a in argv_used),
        'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M'),
        'git': git_revision(), 'machine': machine(), 'jobs': args.jobs, 'out': str(args.out)}
    plan = Plan.make(args.quick, args.realisations)
    args.out.mkdir(parents=True, exist_ok=True)

    if args.seeds_only:
        return seeds_only(args, plan, meta, say)
    ros: dict[str, dict] = {}
    ros_started = time.monotonic()
    if args.skip_ros:
        meta['ros_note'] = 'skipped (`--skip-ros`).'
    else:
        for index, exp in enumerate(ros_experiments()):
            ros[exp.key] = run_ros(exp, index, args.out, plan.quick, args.fresh, say)
        done = [f'`{r["command"]}`' for r in ros.values()]
        meta['ros_note'] = (f'{len(ros)} runs, one per paper, domain ids {ROS_DOMAIN_BASE}-'
                            f'{ROS_DOMAIN_BASE + len(ros) - 1}: ' + ', '.join(done) + '.')
    meta['ros_wall_s'] = time.monotonic() - ros_started

    backend = None
    if args.scheduler is not None:
        try:
            backend = DaskBackend(args.scheduler, args.jobs)
        except SweepError as exc:
            print(f'reproduce: error: {exc}', file=sys.stderr)
            return 2
    live = terminal_line if sys.stderr.isatty() else None
    try:
        sims = run_simulations(plan, args.out, args.jobs, args.fresh, say, live=live,
                               backend=backend)
        seeds_dir = args.seeds_cache or (args.out / 'seeds' if plan.quick else SEEDS_CACHE)
        pool = backend or (SerialBackend() if args.jobs <= 1 else LocalPool(args.jobs, say))
        meta['seeds_cache'] = str(seeds_dir)
        studies = run_studies(seeds_dir, pool, say, plan.quick, args.cached_seeds, live,
                              args.fig3_curves, args.figures)
    finally:
        if backend is not None:
            backend.close()
    meta['simulations'] = {k: sims[k] for k in ('executed', 'cached', 'core_seconds',
                                                'core_seconds_all', 'wall_s')}
    results: dict[str, dict] = {}
    results_dir = args.out / 'results'
    results_dir.mkdir(parents=True, exist_ok=True)
    for exp in all_experiments():
        res = exp.result(plan, sims, args.out, args.figures)
        if exp.key in ros:
            res['ros'] = ros[exp.key]
        if exp.key in studies:
            res['seeds'] = studies[exp.key]
        results[exp.key] = res
        (results_dir / f'{exp.key}.json').write_text(json.dumps(plain(res), indent=2) + '\n')
    meta['wall_min'] = (time.monotonic() - started) / 60.0
    meta['ros_executed'] = sum(1 for r in ros.values() if not r.get('reused'))
    meta['ros_total'] = len(ros)
    meta['history'] = record_invocation(args.out, meta, plan)
    write_report(results, ros, plan, meta, args.report, args.figures)
    (results_dir / 'meta.json').write_text(json.dumps(plain(meta), indent=2) + '\n')
    sizes = {p.name: p.stat().st_size for p in args.figures.glob('*.png')}
    for name, size in sorted(sizes.items()):
        if size > FIG_MAX_BYTES:
            say(f'[reproduce] warning: {name} is {size / 1000:.0f} kB (> 150 kB)')
    say(f'[reproduce] wrote {args.report} and {len(sizes)} figures in {args.figures} '
        f'({sum(sizes.values()) / 1e6:.2f} MB); results in {results_dir}; '
        f'{meta["wall_min"]:.1f} min')
    return 0


def seeds_only(args: argparse.Namespace, plan: Plan, meta: dict,
               say: Callable[[str], None]) -> int:
    """Run (or read) the studies over seeds and the Fig. 3 curves; write their report alone."""
    started = time.monotonic()
    seeds_dir = args.seeds_cache or (args.out / 'seeds' if plan.quick else SEEDS_CACHE)
    meta['seeds_cache'] = str(seeds_dir)
    live = terminal_line if sys.stderr.isatty() else None
    pool = SerialBackend() if args.jobs <= 1 else LocalPool(args.jobs, say)
    studies = run_studies(seeds_dir, pool, say, plan.quick, args.cached_seeds, live,
                          args.fig3_curves, args.figures)
    meta['wall_min'] = (time.monotonic() - started) / 60.0
    write_seeds_report(studies, meta, args.report, args.figures)
    say(f'[reproduce] wrote {args.report}; {meta["wall_min"]:.1f} min')
    return 0
