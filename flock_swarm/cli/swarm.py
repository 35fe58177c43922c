"""``swarm``: fly a scenario through the real ROS 2 nodes, in one process or several.

``swarm SCENARIO [--set key=value ...] [--seed N] [--out DIR] [--processes]
[--foxglove [PORT]]`` resolves the scenario (with overrides and seed) into
``DIR/scenario.yaml``, starts every node on that file, prints progress, and ends when the
world has recorded its last step. Outputs: ``DIR/bag/`` (rosbag2 MCAP),
``DIR/summary.json``, ``DIR/timeseries.npz`` and figures. With ``--foxglove`` the run is
served live over the Foxglove WebSocket protocol (:mod:`flock_swarm.foxglove_ws`). A thin
command over :mod:`flock_swarm.nodes.harness`.
"""

import argparse
import math
import os
import sys
from pathlib import Path

from flock_swarm.console import EXIT_USAGE, OneLineParser, accept_sigint
from flock_swarm.core.errors import ScenarioError
from flock_swarm.foxglove_ws import DEFAULT_HOST, DEFAULT_PORT, ServeError, start_live
from flock_swarm.nodes.harness import (read_scenario, resolve_scenario, run_in_process,
                                       run_processes)


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``swarm``."""
    parser = OneLineParser(
        prog='swarm', description='Fly a scenario through the real ROS 2 nodes (world, leader, '
        'N agents) and record it.')
    parser.add_argument('scenario', help='preset name or path to a YAML file')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE', help='override one scenario value (repeatable)')
    parser.add_argument('--seed', type=int, help='random seed (replaces the scenario seed)')
    parser.add_argument('--out', type=Path, help='output directory (default: out/SCENARIO_ros)')
    parser.add_argument('--processes', action='store_true',
                        help='run every node as its own OS process (default: one process)')
    parser.add_argument('--container', action='store_true',
                        help='with --processes: host all agents in one process (`agents`)')
    parser.add_argument('--mode', choices=('lockstep', 'realtime'), default='lockstep')
    parser.add_argument('--domain-id', type=int,
                        default=int(os.environ.get('ROS_DOMAIN_ID', '0') or 0),
                        help='ROS domain id (default: $ROS_DOMAIN_ID or 0)')
    parser.add_argument('--realtime-factor', type=float, default=1.0,
                        help='realtime mode: simulated seconds per wall second')
    parser.add_argument('--step-timeout', type=float, default=2.0,
                        help='lockstep: seconds the world waits for a command')
    parser.add_argument('--start-timeout', type=float, default=30.0,
                        help='lockstep: seconds the world waits for every node to be '
                        'discovered and to answer step 0 (default: 30; tens of agent '
                        'processes may need longer)')
    parser.add_argument('--executor', choices=('single', 'events'), default='events',
                        help='executor of the one-process run (events: rclpy.experimental.'
                        'EventsExecutor, about twice as fast here)')
    parser.add_argument('--allow-unstable', action='store_true',
                        help='run even when dt violates a stability bound (as sim)')
    parser.add_argument('--no-plots', action='store_true', help='skip the PNG figures')
    parser.add_argument('--no-record', action='store_true',
                        help='do not write the bag (summary and time series are still written)')
    parser.add_argument('--foxglove', type=int, nargs='?', const=DEFAULT_PORT, metavar='PORT',
                        help='serve the run live to Foxglove / Lichtblick over the Foxglove '
                        f'WebSocket protocol (default port {DEFAULT_PORT}; 0: any free port)')
    parser.add_argument('--foxglove-host', default=DEFAULT_HOST, metavar='HOST',
                        help=f'address the --foxglove server binds (default {DEFAULT_HOST}: '
                        'this machine only)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``swarm`` from the command line; return the exit status."""
    accept_sigint()
    args = build_parser().parse_args(argv)
    say = (lambda line: print(line, file=sys.stderr, flush=True))
    try:
        if not 0 <= args.domain_id <= 232:
            raise ScenarioError('--domain-id', f'must be in [0, 232], got {args.domain_id}')
        if args.realtime_factor <= 0:
            raise ScenarioError('--realtime-factor',
                                f'must be > 0, got {args.realtime_factor}')
        if not args.step_timeout > 0 or math.isinf(args.step_timeout):
            raise ScenarioError('--step-timeout',
                                f'must be finite and > 0, got {args.step_timeout}')
        if not args.start_timeout >= 0 or math.isinf(args.start_timeout):
            raise ScenarioError('--start-timeout',
                                f'must be finite and >= 0, got {args.start_timeout}')
        if args.container and not args.processes:
            raise ScenarioError('--container', 'goes with --processes (a one-process run '
                                'always hosts the agents in one container node)')
        name = Path(args.scenario).stem
        out = args.out if args.out is not None else Path('out') / f'{name}_ros'
        if (out / 'bag').exists() and any((out / 'bag').iterdir()):
            raise ScenarioError('--out', f'{out / "bag"} already holds a bag; choose another '
                                '--out')
        scenario = resolve_scenario(args.scenario, args.overrides, args.seed, out,
                                    args.allow_unstable)
        # Bound before the nodes start, so a port in use is a usage error, not a failed run.
        live = (None if args.foxglove is None
                else start_live(args.foxglove_host, args.foxglove, '--foxglove'))
    except (ScenarioError, ServeError) as exc:
        print(f'swarm: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f'swarm: error: --out: {exc}', file=sys.stderr)
        return EXIT_USAGE
    try:
        return _run(args, scenario, out, live, say)
    finally:
        if live is not None:
            live.close()


def _run(args: argparse.Namespace, scenario: Path, out: Path, live, say) -> int:
    """Run the resolved scenario as ``args`` say (serving it on ``live``); return the status."""
    sc = read_scenario(scenario)
    if not args.processes:
        layout = 'one process (agents in one container node)'
    elif args.container:
        layout = 'three processes (agents in one container process)'
    else:
        layout = 'separate processes (one per agent)'
    say(f'[swarm] {sc.name}: world + leader + {sc.n_agents} agents in {layout}, {args.mode}, '
        f'{sc.steps} steps of {sc.dt:g} s, ROS_DOMAIN_ID={args.domain_id}')
    world_params = {'start_timeout': args.start_timeout}
    if args.no_record:
        world_params['record'] = False
    if live is not None:
        # Every channel is advertised before the address is announced: a client connecting
        # on the announcement gets them all at once, not while the nodes are being built
        # (a subscription sent the moment the last channel appeared could be lost with it).
        from flock_swarm.contract import contract_topics
        live.add_topics(contract_topics(sc.n_agents, '/'))
        say(f'[swarm] live view on {live.url} (Foxglove / Lichtblick: open a connection, '
            'Foxglove WebSocket)')
    if args.processes:
        summary = run_processes(scenario, out, args.mode, args.domain_id, args.step_timeout,
                                realtime_factor=args.realtime_factor,
                                container=args.container, world_params=world_params,
                                live=live, allow_unstable=args.allow_unstable)
    else:
        summary = run_in_process(scenario, out, args.mode, args.domain_id, args.step_timeout,
                                 args.executor, progress=say,
                                 realtime_factor=args.realtime_factor,
                                 world_params=world_params, live=live,
                                 allow_unstable=args.allow_unstable)
    return _report(args, sc.name, out, summary, say)


def _report(args: argparse.Namespace, name: str, out: Path, summary: dict, say) -> int:
    """Plot, print the summary line and the files written (those that exist, and only
    those: a full disk may have stopped one); return the exit status."""
    from flock_swarm.outputs import write_error
    if not summary or not (out / 'summary.json').is_file():
        why = summary.get('failure') if summary else None
        print(f'swarm: error: the world wrote no {out / "summary.json"}'
              + (f' ({why})' if why else ''), file=sys.stderr)
        return 1
    status = 0 if summary['status'] == 'completed' else 1
    written = [path for path in (out / 'summary.json', out / 'timeseries.npz')
               if path.is_file()]
    if not args.no_record and (out / 'bag').is_dir():
        written.insert(0, out / 'bag')
    if not args.no_plots and (out / 'timeseries.npz').is_file():
        import numpy as np
        from flock_swarm.plots import plot_timeseries
        try:
            with np.load(out / 'timeseries.npz') as data:
                written += plot_timeseries(dict(data), out, name)
        except OSError as exc:
            print(f'swarm: error: {write_error(exc)}', file=sys.stderr)
            status = 1
    say(f'[swarm] {summary["status"]} at t = {summary["t_final"]:g} s: eta = '
        f'{summary["eta"]:.3f}, velocity mismatch = {summary["velocity_mismatch_max"]:.3g}, '
        f'collisions = {summary["collisions"]}, missed commands = '
        f'{summary.get("missed_commands", 0)} ({summary.get("wall_time_s", 0):.1f} s wall)')
    say('[swarm] wrote ' + ', '.join(str(path) for path in written))
    if summary.get('failure'):
        print(f'swarm: error: {summary["failure"]}', file=sys.stderr)
    return status


if __name__ == '__main__':
    sys.exit(main())
