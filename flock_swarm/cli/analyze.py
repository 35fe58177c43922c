"""``analyze BAG``: the metrics, time series and figures of a recorded run, from its bag.

``analyze BAG [--out DIR] [--verify] ...`` rebuilds every step of a run from the agents'
odometry and commands and the leader's state in a rosbag2 MCAP bag, recomputes the flocking
metrics with the code ``sim`` and the world node use and writes ``summary.json``,
``timeseries.npz``, ``timeseries.csv`` and figures (``docs/analysis.md``). The scenario
stored in the bag gives ``dt``, the radius and the tolerances; ``--verify`` re-runs ``sim``
from it and compares the trajectories. Bags without it are analysed with ``--radius``,
``--eta-tolerance`` and ``--collision-distance``. A thin command over
:mod:`flock_swarm.analysis`.
"""

import argparse
from pathlib import Path
import sys
import time

import numpy as np

from flock_swarm.analysis.bagrun import (AnalyzeError, FALLBACK_COLLISION_DISTANCE,
                                         FALLBACK_ETA_TOLERANCE, load_run, Progress)
from flock_swarm.analysis.compare import check_verifiable, VERIFY_TOLERANCE
from flock_swarm.analysis.analyze_run import analyze, default_out
from flock_swarm.bag import BagError
from flock_swarm.console import (EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_USAGE, OneLineParser,
                                 StopSignals, out_dir)
from flock_swarm.outputs import ensure_writable


def _times(text: str) -> list[float]:
    try:
        times = [float(part) for part in text.split(',') if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected times in seconds like 0,10,30, got {text!r}')
    if not times or not all(np.isfinite(times)):
        raise argparse.ArgumentTypeError(f'expected times in seconds like 0,10,30, got {text!r}')
    return times


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float('nan')
    if not value > 0 or not np.isfinite(value):
        raise argparse.ArgumentTypeError(f'must be a positive number, got {text!r}')
    return value


def _positive_int(text: str) -> int:
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f'must be a positive integer, got {text!r}')
    return int(text)


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``analyze``."""
    parser = OneLineParser(
        prog='analyze',
        description='Metrics, time series and figures of a recorded flock_swarm run.')
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('--out', type=out_dir,
                        help='output directory (default: BAG_analysis next to the bag)')
    parser.add_argument('--snapshots', type=_times, metavar='T,T,...',
                        help='snapshot times in seconds (default: first, middle, last)')
    parser.add_argument('--no-anim', action='store_true', help='do not write flock.gif')
    parser.add_argument('--record-every', type=_positive_int, metavar='N',
                        help='record every N-th step in the series (default: the scenario\'s '
                        'record_every, 1 without a scenario)')
    parser.add_argument('--verify', action='store_true',
                        help='re-run sim from the scenario and seed in the bag and compare '
                        'the trajectories (exit status 1 if they differ)')
    parser.add_argument('--verify-tolerance', type=_positive, default=VERIFY_TOLERANCE,
                        metavar='TOL', help='largest accepted deviation in m and m/s '
                        f'(default {VERIFY_TOLERANCE:g})')
    fallback = parser.add_argument_group(
        'bags without a flock_swarm scenario (ignored when the bag has one)')
    fallback.add_argument('--radius', type=_positive, metavar='R',
                          help='interaction radius r [m] (required for such bags)')
    fallback.add_argument('--eta-tolerance', type=_positive, metavar='TOL',
                          help=f'tolerance of eta [m/s] (default {FALLBACK_ETA_TOLERANCE:g})')
    fallback.add_argument('--collision-distance', type=_positive, metavar='D',
                          help='collision distance [m] '
                          f'(default {FALLBACK_COLLISION_DISTANCE:g})')
    parser.add_argument('-q', '--quiet', action='store_true',
                        help='no progress output (warnings and the --verify result remain)')
    return parser


def _check_writable(out: Path) -> None:
    try:
        ensure_writable(out)
    except OSError as exc:
        raise AnalyzeError(f'--out: cannot write to {out}: {exc.strerror or exc}') from None


def main(argv: list[str] | None = None) -> int:
    """Run ``analyze`` from the command line; return the exit status."""
    args = build_parser().parse_args(argv)

    def warn(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    say = None if args.quiet else warn
    # SIGTERM and SIGHUP stop it as Ctrl-C does, with the status of the signal.
    with StopSignals(interrupt=True) as stop:
        try:
            return _run(args, say, warn, stop)
        except KeyboardInterrupt:
            warn('analyze: interrupted')
            return stop.status(EXIT_INTERRUPTED)
        except (AnalyzeError, BagError) as exc:
            warn(f'analyze: error: {exc}')
            return EXIT_USAGE
        except OSError as exc:
            warn(f'analyze: error: {exc.filename or ""}: {exc.strerror or exc}')
            return EXIT_USAGE
        except Exception as exc:
            # One line, as promised for every failure; the type says where to look.
            warn(f'analyze: error: {type(exc).__name__}: {" ".join(str(exc).split())}')
            return EXIT_USAGE


def _unless_stopped(stop: StopSignals) -> None:
    """Raise ``KeyboardInterrupt`` if a stop signal came (one a library swallowed).

    A signal must end ``analyze`` with its status, never with a verdict on the part of the
    bag read before it.
    """
    if stop.stopped:
        raise KeyboardInterrupt


def _run(args: argparse.Namespace, say: Progress | None, warn: Progress,
         stop: StopSignals) -> int:
    started = time.monotonic()
    run = load_run(args.bag, radius=args.radius, eta_tolerance=args.eta_tolerance,
                   collision_distance=args.collision_distance, progress=say)
    _unless_stopped(stop)
    if run.warning is not None:
        warn(f'[analyze] warning: {run.warning}; analysing the {len(run.steps)} complete '
             'step(s)')
    for note in run.notes:
        warn(f'[analyze] note: {note}')
    if args.verify:
        check_verifiable(run)
    if args.verify and run.mode == 'realtime':
        warn('[analyze] note: a realtime run is asynchronous; --verify compares it with the '
             'deterministic sim anyway')
    out = args.out if args.out is not None else default_out(args.bag)
    _check_writable(out)
    if say:
        say(f'[analyze] {run.name}: {run.n_agents} agents in {run.dim}-D, '
            f'{len(run.steps)} complete steps of {run.dt:g} s')
    try:
        result = analyze(run, out, snapshots=args.snapshots, animate=not args.no_anim,
                         verify=args.verify, verify_tolerance=args.verify_tolerance,
                         record_every=args.record_every, progress=say)
    except OSError as exc:
        raise AnalyzeError(f'--out: writing {out} failed: {exc.strerror or exc}') from None
    _unless_stopped(stop)
    s = result.summary
    if say:
        say(f'[analyze] {s["status"]} at t = {s["t_final"]:g} s: eta = {s["eta"]:.3f}, '
            f'velocity mismatch = {s["velocity_mismatch_max"]:.3g}, '
            f'collisions = {s["collisions"]}, components = {s["components_final"]} '
            f'({time.monotonic() - started:.1f} s)')
        if 'failure' in s:
            # The world's line telling why its run failed, as the bag records it.
            say(f'[analyze] the run failed: {s["failure"]}')
        say(f'[analyze] wrote {len(result.files)} files to {out}')
    check = result.verification
    if check is not None:
        print(f'[analyze] verify: largest deviation from sim over {check.steps_compared} '
              f'steps: position {check.max_position_error:.3g} m, velocity '
              f'{check.max_velocity_error:.3g} m/s (tolerance {check.tolerance:g})', flush=True)
        if not check.passed:
            warn(f'analyze: verify failed: the recording deviates from sim by '
                 f'{check.max_position_error:.3g} m, {check.max_velocity_error:.3g} m/s '
                 f'(tolerance {check.tolerance:g})')
            return EXIT_FAILURE
    return 0


if __name__ == '__main__':
    sys.exit(main())
