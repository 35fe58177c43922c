"""The reference simulator: a whole swarm, vectorised over agents, from one scenario.

``sim SCENARIO [--set key=value ...] [--seed N] [--out DIR]`` runs a preset (or a YAML file)
and writes ``DIR/summary.json`` and ``DIR/timeseries.npz`` (see ``docs/outputs.md``).
A thin command over :mod:`flock_swarm.core.run` (the run) and :mod:`flock_swarm.outputs`
(the files).
"""

import argparse
import signal
import sys
from pathlib import Path

from flock_swarm.console import (EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_USAGE, OneLineParser,
                                 StopSignals, out_dir, signal_name)
from flock_swarm.core.errors import PluginError, ScenarioError
from flock_swarm.core import registry
from flock_swarm.core.faults import RunFault
from flock_swarm.core.headline import result_line
from flock_swarm.core.run import simulate
from flock_swarm.engine.backends import BACKENDS, sim_integrator
from flock_swarm.outputs import ensure_writable, write_error, write_outputs


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``sim``."""
    parser = OneLineParser(
        prog='sim', description='Run a flocking scenario with the reference simulator.')
    parser.add_argument('scenario', help='preset name (see --list) or path to a YAML file')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE',
                        help='override one value, e.g. --set protocol.c1=0.8 (repeatable)')
    parser.add_argument('--seed', type=int, help='random seed (replaces the scenario seed)')
    parser.add_argument('--out', type=out_dir, help='output directory (default: out/SCENARIO)')
    parser.add_argument('--plots', action='store_true', help='also write PNG figures')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress output')
    parser.add_argument('--backend', choices=BACKENDS, default='plant',
                        help="what integrates the agents: 'plant' (the scenario's plant "
                        "model) or 'mujoco' (the physics engine, as the world's backend: "
                        'plant.model unicycle; docs/robots.md)')
    parser.add_argument('--allow-unstable', action='store_true',
                        help='run even when dt violates a stability bound')
    return parser


def listing() -> str:
    """Return the ``sim --list`` text: presets, laws and leader models with their sources.

    A plugin that cannot be used (an import error, a name registered twice...) is listed as
    ``BROKEN`` with the reason; it fails only the runs that use it.
    """
    from flock_swarm.presets import preset_names
    lines = ['presets (sim NAME):']
    lines += [f'  {name}' for name in preset_names()]
    for title, group in (('laws (protocol.name):', registry.LAW_GROUP),
                         ('leader models (leader.model):', registry.LEADER_GROUP),
                         ('plant models (plant.model):', registry.PLANT_GROUP)):
        found = registry.status(group)
        width = max((len(name) for name in found), default=0)
        lines += ['', title]
        for name, (entry, cls, problem) in found.items():
            what = registry.describe(cls) if problem is None else f'BROKEN: {problem}'
            lines.append(f'  {name:<{width}}  [{entry.package}]  {what}')
        for entry in registry.shadowed(group):
            # The built-in of that name is listed above and works; the other one is named.
            lines.append(f'  {entry.name:<{width}}  [{entry.package}]  IGNORED: '
                         f'{entry.label}: {entry.name!r} is a built-in name of '
                         f'{found[entry.name][0].package}; register the plugin under another '
                         'name')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    """Run ``sim`` from the command line; return the exit status.

    0 when the run completed, 1 when it diverged, 2 for invalid input, and after a stop
    signal (SIGINT, SIGTERM, SIGHUP) that signal's status
    (:data:`~flock_swarm.console.EXIT_SIGNAL`), with everything recorded until then written.
    """
    with StopSignals(interrupt=True) as stop:
        try:
            return _main(argv, stop)
        except KeyboardInterrupt:
            # A stop signal before the run began (the run itself catches it and ends
            # 'interrupted'; its outputs are written with the signals held).
            print(f'sim: stopped by {signal_name(stop.first or signal.SIGINT)} before the run '
                  'began; nothing written', file=sys.stderr)
            return stop.status(EXIT_INTERRUPTED)


def _main(argv: list[str] | None, stop: StopSignals) -> int:
    """:func:`main` with the stop signals turned into ``KeyboardInterrupt`` (``stop``)."""
    parser = build_parser()
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == '--list':
        try:
            print(listing(), end='')
        except ScenarioError as exc:
            print(f'sim: error: {exc}', file=sys.stderr)
            return EXIT_USAGE
        return 0
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        # --help, or an argument error already printed: the status, as for every other error.
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    from flock_swarm.presets import prepare
    try:
        sc, _ = prepare(args.scenario, args.overrides, args.seed,
                        allow_unstable=args.allow_unstable)
    except ScenarioError as exc:
        print(f'sim: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    try:
        integrator = sim_integrator(args.backend, sc)
    except ScenarioError as exc:
        print(f'sim: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    out = args.out if args.out is not None else Path('out') / sc.name
    try:
        ensure_writable(out)
    except OSError as exc:
        print(f'sim: error: --out: cannot write to {out}: {exc.strerror}', file=sys.stderr)
        return EXIT_USAGE
    say = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    if say:
        say(f'[sim] {sc.name}: {sc.n_agents} agents, {sc.law.name}, {sc.steps} steps '
            f'of {sc.dt:g} s, seed {sc.seed}')
    try:
        result = simulate(sc, progress=say, integrator=integrator)
    except (RunFault, PluginError) as exc:
        # A fault before the first recorded instant (nothing to write), or a law's output of
        # the wrong shape at some step: the run cannot go on (a failed run, not a usage error).
        print(f'sim: error: {exc}', file=sys.stderr)
        return EXIT_FAILURE
    with stop.held():
        return _finish(result, sc, out, args, say, stop)


def _finish(result, sc, out: Path, args: argparse.Namespace, say, stop: StopSignals) -> int:
    """Write the outputs of ``result`` and say how the run ended; return the exit status."""
    try:
        written = write_outputs(result, out, sc)
        if args.plots and result.series:
            from flock_swarm.plots import plot_timeseries
            for path in plot_timeseries(result.series, out, sc.name, sc.obstacles):
                if say:
                    say(f'[sim] wrote {path}')
    except OSError as exc:
        # The input was valid and the run done: its outputs could not be written (a full
        # disk), a failed run (status 1), not invalid input (2).
        print(f'sim: error: --out: {write_error(exc)}', file=sys.stderr)
        return EXIT_FAILURE
    s = result.summary
    if say:
        if stop.stopped:
            say(f'[sim] stopped by {signal_name(stop.first)}')
        say('[sim] ' + result_line(s, sc.headline, ('collisions', 'components_final')))
        if result.series:
            say(f'[sim] wrote {written[-1]} and {written[0]}')
        else:
            say(f'[sim] wrote {out / "summary.json"} (nothing was recorded: no time series)')
    if s['status'] == 'failed':
        print(f'sim: error: {s["failure"]}', file=sys.stderr)
        return EXIT_FAILURE
    if s['status'] == 'diverged':
        print(f'sim: error: the state stopped being finite at step {s["steps"]}; '
              'reduce dt', file=sys.stderr)
        return EXIT_FAILURE
    return stop.status(EXIT_INTERRUPTED) if s['status'] == 'interrupted' else 0


if __name__ == '__main__':
    sys.exit(main())
