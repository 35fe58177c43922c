"""The reproduction's command line: ``python -m flock_swarm.reproduce``, ``scripts/reproduce``.

A thin command over :func:`flock_swarm.reproduce.pipeline.run` (see :mod:`flock_swarm.reproduce`
for what it runs and writes).
"""

import argparse
import sys
from pathlib import Path

from flock_swarm.console import EXIT_INTERRUPTED, EXIT_USAGE, StopSignals, out_dir
from flock_swarm.reproduce import pipeline
from flock_swarm.reproduce.pipeline import RESULTS
from flock_swarm.reproduce.seeds import SEEDS_CACHE


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``python -m flock_swarm.reproduce``."""
    parser = argparse.ArgumentParser(
        prog='python -m flock_swarm.reproduce',
        description='Run every experiment of the papers and write the reproduction report.')
    parser.add_argument('--out', type=out_dir, default=Path('out/reproduce'),
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
    parser.add_argument('--studies', nargs='+', metavar='KEY',
                        help='with --seeds-only: run (or resume) only these experiments\' '
                        'studies (their keys, as in docs/reproduction.md\'s figures); the '
                        'others are read from their caches')
    parser.add_argument('--cached-seeds', action='store_true',
                        help='run nothing new over seeds: the distributions use what the '
                        'caches hold (the report states the counts); when OUT holds no '
                        'preset run either, run nothing at all: the presets\' and ROS runs\' '
                        'results come from --results (the report says so)')
    parser.add_argument('--results', type=Path, metavar='DIR',
                        help='the committed results of the presets\' and ROS runs, written by '
                        f'every full run (default: {RESULTS}; none with --quick)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the reproduction from the command line; return the exit status (130 when
    interrupted, 143 after SIGTERM, 129 after SIGHUP: every finished run is in its cache,
    and the same command resumes)."""
    args = build_parser().parse_args(argv)
    if args.realisations is not None and args.realisations < 1:
        print('reproduce: error: --realisations must be >= 1', file=sys.stderr)
        return EXIT_USAGE
    if args.jobs < 1:
        print('reproduce: error: --jobs must be >= 1', file=sys.stderr)
        return EXIT_USAGE
    if args.studies:
        from flock_swarm.reproduce.catalogue import all_experiments
        known = [exp.key for exp in all_experiments()]
        unknown = [key for key in args.studies if key not in known]
        if unknown or not args.seeds_only:
            print(f'reproduce: error: --studies: unknown experiment {unknown[0]!r} (known: '
                  f'{", ".join(known)})' if unknown else
                  'reproduce: error: --studies needs --seeds-only', file=sys.stderr)
            return EXIT_USAGE
    # SIGTERM and SIGHUP stop it as Ctrl-C does, with the status of the signal.
    with StopSignals(interrupt=True) as stop:
        try:
            return pipeline.run(args, sys.argv[1:] if argv is None else list(argv))
        except KeyboardInterrupt:
            print('reproduce: interrupted; every finished run is kept in its cache (--out and '
                  'the studies\' caches); run the same command again to resume',
                  file=sys.stderr)
            return stop.status(EXIT_INTERRUPTED)


if __name__ == '__main__':
    sys.exit(main())
