"""Parameter studies: sweep any scenario key over many seeds, locally or on a Dask cluster.

``sweep SPEC [--out DIR] [--jobs N | --scheduler ADDRESS|local] [--seeds R] [--set k=v ...]``
expands the spec (a YAML file, see ``docs/sweeps.md``; ``config/sweeps/`` holds shipped ones,
found by name) into runs, runs those not yet in ``DIR/runs.jsonl`` and writes
``DIR/runs.csv`` (one row per run), ``DIR/summary.csv`` (mean, std, standard error, count,
range per point and metric) and one figure per metric. Interrupted (Ctrl-C) or killed, it
keeps every finished run; run again, it does only the missing ones.
"""

import argparse
import os
import sys
from pathlib import Path

from flock_swarm.console import (EXIT_INTERRUPTED, EXIT_RUNTIME, EXIT_USAGE, OneLineParser,
                                 StopSignals, out_dir)
from flock_swarm.core.errors import ScenarioError, one_line


def spec_path(name_or_path: str) -> Path:
    """Return the spec file of a path or of a shipped spec's name (``su2009_fig3``).

    :raises ScenarioError: when nothing matches.
    """
    from flock_swarm.presets import resolve
    return resolve(name_or_path, 'sweeps', 'spec')


def max_jobs() -> int:
    """Return the most worker processes ``--jobs`` may ask for: four per core, 64 at least.

    Each is a Python process with NumPy and SciPy; ``--jobs 100000`` would start them all.
    """
    return max(64, 4 * (os.cpu_count() or 1))


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``sweep``."""
    parser = OneLineParser(prog='sweep', description='Run a parameter study over a scenario.')
    parser.add_argument('spec', help='sweep spec: a YAML file or a shipped name '
                        '(config/sweeps/NAME.yaml)')
    parser.add_argument('--out', type=out_dir, help='output directory (default: out/sweeps/NAME)')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 1,
                        help='local worker processes (default: all cores; 1: this process)')
    parser.add_argument('--scheduler', metavar='ADDRESS',
                        help='run on the Dask scheduler at ADDRESS (tcp://host:8786), or '
                        '"local" for a LocalCluster of --jobs workers')
    parser.add_argument('--connect-timeout', type=float, default=10.0, metavar='S',
                        help='seconds to wait for the scheduler, and for a worker when it has '
                        'none (default: 10)')
    parser.add_argument('--seeds', type=int, metavar='R',
                        help='seeds 0 .. R-1 per point (replaces the spec\'s seeds)')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE', help='override a scenario value of every run '
                        '(repeatable)')
    parser.add_argument('--fresh', action='store_true', help='ignore the cache of earlier runs')
    parser.add_argument('--allow-unstable', action='store_true',
                        help='run points whose dt violates a stability bound')
    parser.add_argument('--no-plots', action='store_true', help='write the tables only')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress output')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``sweep`` from the command line; return the exit status (after a stop signal,
    that signal's: :data:`~flock_swarm.console.EXIT_SIGNAL`)."""
    # SIGTERM and SIGHUP stop the sweep as Ctrl-C does: every finished run stays cached.
    with StopSignals(interrupt=True) as stop:
        try:
            return _main(argv, stop)
        except KeyboardInterrupt:
            # Before the runs (while the spec is read or the grid planned): nothing to keep.
            print('sweep: interrupted before any run started', file=sys.stderr)
            return stop.status(EXIT_INTERRUPTED)


def _main(argv: list[str] | None, stop: StopSignals) -> int:
    """:func:`main` with the stop signals turned into ``KeyboardInterrupt`` (``stop``)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    from flock_swarm.study import execute as ex
    from flock_swarm.study import tables
    from flock_swarm.study.spec import plan_runs, read_spec, times_within

    def fail(message: str) -> int:
        print(f'sweep: error: {one_line(message)}', file=sys.stderr)
        return EXIT_USAGE

    say = (lambda line: None) if args.quiet else \
        (lambda line: print(line, file=sys.stderr, flush=True))
    if args.jobs < 1:
        return fail(f'--jobs: must be >= 1, got {args.jobs}')
    if args.jobs > max_jobs():
        return fail(f'--jobs: at most {max_jobs()} (four per core of this machine, 64 at '
                    f'least), got {args.jobs}')
    if args.seeds is not None and args.seeds < 1:
        return fail(f'--seeds: must be >= 1, got {args.seeds}')
    if not 0 < args.connect_timeout < float('inf'):
        return fail(f'--connect-timeout: must be a number of seconds > 0, got '
                    f'{args.connect_timeout}')
    try:
        path = spec_path(args.spec)
        spec = read_spec(path, tuple(args.overrides), args.seeds)
        spec, dropped = times_within(spec)
        if dropped:
            say(f'[sweep] times: {", ".join(f"{t:g}" for t in dropped)} s dropped: after the '
                'end of the runs set by --set duration')
        runs = plan_runs(spec, args.allow_unstable, say)
    except ScenarioError as exc:
        return fail(str(exc))
    out = args.out if args.out is not None else Path('out') / 'sweeps' / spec.name
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / '.write_test').write_text('')
        (out / '.write_test').unlink()
    except OSError as exc:
        return fail(f'--out: cannot write to {out}: {exc.strerror}')
    try:
        if args.scheduler is not None:
            backend = ex.DaskBackend(args.scheduler, args.jobs, args.connect_timeout)
        elif args.jobs == 1:
            backend = ex.SerialBackend()
        else:
            backend = ex.LocalPool(args.jobs, say)
    except ex.SweepError as exc:
        return fail(str(exc))
    live = ex.terminal_line if sys.stderr.isatty() and not args.quiet else None
    say(f'[sweep] {spec.name}: {len(runs) // len(spec.seeds)} points x {len(spec.seeds)} '
        f'seeds of {spec.scenario}')
    try:
        done = ex.execute(runs, out / 'runs.jsonl', ex.MetricRecorder(spec.metrics, spec.times),
                          backend, spec.stack_agents, say, live, args.fresh)
    except KeyboardInterrupt:
        print(f'sweep: interrupted; every finished run is kept in {out / "runs.jsonl"} '
              '(run the same command again to go on)', file=sys.stderr)
        return stop.status(EXIT_INTERRUPTED)
    except ex.ClusterError as exc:
        print(f'sweep: error: {one_line(str(exc))}', file=sys.stderr)
        return EXIT_RUNTIME
    except ex.SweepError as exc:
        return fail(str(exc))
    finally:
        backend.close()
    rows = tables.tidy_rows(spec, done['records'])
    stats = tables.aggregate(spec, rows)
    tables.write_csv(out / 'runs.csv', tables.tidy_columns(spec), rows)
    tables.write_csv(out / 'summary.csv', [a.key for a in spec.axes] + list(tables.STATISTICS),
                     stats)
    written = [] if args.no_plots else tables.figures(spec, stats, out)
    diverged = sum(1 for r in rows if r['status'] == 'diverged')
    say(f'[sweep] wrote {out / "runs.csv"} ({len(rows)} runs, {done["executed"]} run now, '
        f'{done["cached"]} reused{f", {diverged} diverged" if diverged else ""}), '
        f'{out / "summary.csv"} and {len(written)} figure(s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
