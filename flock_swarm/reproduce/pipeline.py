"""The whole reproduction, end to end: the runs, the studies over seeds, the results and the
report, as ``python -m flock_swarm.reproduce`` asks (its command line is
:mod:`flock_swarm.cli.reproduce`)."""

import argparse
import json
import shlex
import sys
import time
from pathlib import Path
from datetime import datetime, timezone
from typing import Any, Callable

from flock_swarm.console import EXIT_USAGE
from flock_swarm.outputs import plain_json
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

#: The committed results of the presets' and ROS runs (one JSON per experiment, without its
#: study over seeds, which its own cache holds; ``meta.json``: the run that wrote them): what
#: ``--cached-seeds`` renders the report from when ``--out`` holds no run.
RESULTS = Path('docs/reproduction/results')


def run(args: argparse.Namespace, argv_used: list[str]) -> int:
    """Run the reproduction; return the exit status (2 for a scheduler it cannot reach).

    :param args: the options of :func:`flock_swarm.cli.reproduce.build_parser` (checked).
    :param argv_used: the command line's arguments, recorded in the report.
    """
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
    if args.results is None and not plan.quick:
        args.results = RESULTS
    if args.cached_seeds and not args.fresh and committed(args):
        return render_committed(args, plan, meta, say)
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
            return EXIT_USAGE
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
        (results_dir / f'{exp.key}.json').write_text(json.dumps(plain_json(res), indent=2) + '\n')
    meta['wall_min'] = (time.monotonic() - started) / 60.0
    meta['ros_executed'] = sum(1 for r in ros.values() if not r.get('reused'))
    meta['ros_total'] = len(ros)
    meta['history'] = record_invocation(args.out, meta, plan)
    write_report(results, ros, plan, meta, args.report, args.figures)
    (results_dir / 'meta.json').write_text(json.dumps(plain_json(meta), indent=2) + '\n')
    if args.results is not None:
        write_committed(args.results, results, meta)
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
                          args.fig3_curves, args.figures,
                          only=frozenset(args.studies) if args.studies else None)
    meta['wall_min'] = (time.monotonic() - started) / 60.0
    write_seeds_report(studies, meta, args.report, args.figures)
    say(f'[reproduce] wrote {args.report}; {meta["wall_min"]:.1f} min')
    return 0


def write_committed(where: Path, results: dict[str, dict], meta: dict) -> None:
    """Write the results the report was rendered from, without the studies over seeds (their
    caches hold them), for :func:`render_committed`.

    :param where: the directory (``--results``).
    :param results: every experiment's JSON result, by key.
    :param meta: the invocation's provenance.
    """
    where.mkdir(parents=True, exist_ok=True)
    for key, res in results.items():
        kept = {k: v for k, v in res.items() if k != 'seeds'}
        (where / f'{key}.json').write_text(json.dumps(plain_json(kept), indent=1) + '\n')
    (where / 'meta.json').write_text(json.dumps(plain_json(meta), indent=1) + '\n')


def committed(args: argparse.Namespace) -> bool:
    """Return whether the report is to be rendered from ``--results`` alone: ``--out`` holds
    no preset run, and ``--results`` holds every experiment's result."""
    runs = args.out / 'runs'
    if runs.is_dir() and any(runs.iterdir()):
        return False
    where = args.results
    return where is not None and (where / 'meta.json').is_file() and all(
        (where / f'{exp.key}.json').is_file() for exp in all_experiments())


def render_committed(args: argparse.Namespace, plan: Plan, meta: dict,
                     say: Callable[[str], None]) -> int:
    """Write the report from the committed results and the caches over seeds: run nothing
    (the figures of the presets stay as they were drawn by the run that wrote the results)."""
    started = time.monotonic()
    ran = json.loads((args.results / 'meta.json').read_text())
    seeds_dir = args.seeds_cache or (args.out / 'seeds' if plan.quick else SEEDS_CACHE)
    studies = run_studies(seeds_dir, SerialBackend(), say, plan.quick, True, None, False,
                          args.figures)
    results: dict[str, dict] = {}
    for exp in all_experiments():
        res = json.loads((args.results / f'{exp.key}.json').read_text())
        if exp.key in studies:
            res['seeds'] = studies[exp.key]
        results[exp.key] = res
    ros = {key: res['ros'] for key, res in results.items() if 'ros' in res}
    meta['seeds_cache'] = str(seeds_dir)
    meta['rendered_from'] = {'where': str(args.results), 'command': ran['command'],
                             'date': ran['date'], 'git': ran['git']}
    for key in ('simulations', 'ros_note', 'ros_wall_s', 'ros_total', 'history', 'out'):
        meta[key] = ran[key]
    meta['ros_executed'] = 0
    meta['simulations'] = dict(ran['simulations'], executed=0, wall_s=0.0, core_seconds=0.0)
    meta['wall_min'] = (time.monotonic() - started) / 60.0
    write_report(results, ros, plan, meta, args.report, args.figures)
    say(f'[reproduce] wrote {args.report} from the committed results in {args.results} (run '
        f'{ran["date"]}, commit {ran["git"]}) and the caches over seeds: nothing ran; '
        f'{meta["wall_min"]:.1f} min')
    return 0
