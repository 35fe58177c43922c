"""``swarm``: fly a scenario through the real ROS 2 nodes, in one process or several.

``swarm SCENARIO [--set key=value ...] [--seed N] [--out DIR] [--processes]
[--foxglove [PORT]]`` resolves the scenario (with overrides and seed) into
``DIR/scenario.yaml``, starts every node on that file, prints progress, and ends when the
world has recorded its last step. Outputs: ``DIR/bag/`` (rosbag2 MCAP),
``DIR/summary.json``, ``DIR/timeseries.npz`` and figures. With ``--foxglove`` the run is
served live over the Foxglove WebSocket protocol (:mod:`flock_swarm.foxglove_ws`). A thin
command over :mod:`flock_swarm.nodes.swarm_runner`.
"""

import argparse
import math
import os
import sys
from pathlib import Path

from flock_swarm.console import (claim_domain, DomainBusy, EXIT_FAILURE, EXIT_INTERRUPTED,
                                 EXIT_USAGE, OneLineParser, StopSignals, out_dir, signal_name)
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.headline import result_line
from flock_swarm.engine import BACKENDS
from flock_swarm.foxglove_ws import DEFAULT_HOST, DEFAULT_PORT, ServeError, start_live
from flock_swarm.nodes.swarm_runner import (read_scenario, resolve_scenario, run_in_process,
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
    parser.add_argument('--out', type=out_dir, help='output directory (default: out/SCENARIO_ros)')
    parser.add_argument('--processes', action='store_true',
                        help='run every node as its own OS process (default: one process)')
    parser.add_argument('--container', action='store_true',
                        help='with --processes: host all agents in one process (`agents`)')
    parser.add_argument('--hosts', type=int, default=1, metavar='K',
                        help='with --processes --container: split the agents over K `agents` '
                        'processes by id ranges (default 1)')
    parser.add_argument('--mode', choices=('lockstep', 'realtime'), default='lockstep')
    parser.add_argument('--domain-id', type=int,
                        help='ROS domain id (default: $ROS_DOMAIN_ID or 0); one run per '
                        'domain: a second swarm on it is refused')
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
    parser.add_argument('--pace', type=float, default=0.0, metavar='FACTOR',
                        help='lockstep: at most FACTOR simulated seconds per wall second '
                        '(1: real time, to watch a run; default 0: as fast as it goes)')
    parser.add_argument('--backend', choices=BACKENDS, default='plant',
                        help="what the world integrates the agents with: 'plant' (the "
                        "scenario's plant model, as sim) or 'mujoco' (the physics engine; "
                        'plant.model unicycle; docs/robots.md)')
    parser.add_argument('--transport', choices=('per_agent', 'batched'),
                        help="how a step's messages move (the scenario's transport key, "
                        "default per_agent): 'per_agent' (a topic per agent) or 'batched' "
                        "(the swarm's state as one PointCloud2, each agents host's commands "
                        'as one; docs/ros.md, "Transports")')
    parser.add_argument('--wait-for-viewer', action='store_true',
                        help='with --foxglove: start the run once a viewer has subscribed')
    parser.add_argument('--foxglove-host', default=DEFAULT_HOST, metavar='HOST',
                        help=f'address the --foxglove server binds (default {DEFAULT_HOST}: '
                        'this machine only)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``swarm`` from the command line; return the exit status.

    0 when the run completed, 1 when it did not (diverged, failed, recording failed),
    2 for invalid input, and after a stop signal that signal's status
    (:data:`~flock_swarm.console.EXIT_SIGNAL`): the world finalises its bag and summary
    first, whatever the layout.
    """
    with StopSignals() as stop:
        return _main(argv, stop)


def _main(argv: list[str] | None, stop: StopSignals) -> int:
    """:func:`main` with the stop signals caught (``stop``)."""
    args = build_parser().parse_args(argv)
    say = _say
    try:
        if args.domain_id is None:
            args.domain_id = _environment_domain()
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
        if not args.pace >= 0 or math.isinf(args.pace):
            raise ScenarioError('--pace', f'must be finite and >= 0, got {args.pace}')
        if args.pace and args.mode != 'lockstep':
            raise ScenarioError('--pace', 'paces lockstep runs; realtime runs take '
                                '--realtime-factor')
        if args.wait_for_viewer and args.foxglove is None:
            raise ScenarioError('--wait-for-viewer', 'goes with --foxglove')
        if args.container and not args.processes:
            raise ScenarioError('--container', 'goes with --processes (a one-process run '
                                'always hosts the agents in one container node)')
        if args.hosts != 1 and not args.container:
            raise ScenarioError('--hosts', 'goes with --processes --container')
        if args.hosts < 1:
            raise ScenarioError('--hosts', f'must be >= 1, got {args.hosts}')
        name = Path(args.scenario).stem
        out = args.out if args.out is not None else Path('out') / f'{name}_ros'
        # --no-record writes no bag: one already there is not in its way.
        if not args.no_record and (out / 'bag').exists() and any((out / 'bag').iterdir()):
            raise ScenarioError('--out', f'{out / "bag"} already holds a bag; choose another '
                                '--out')
        # Held until the run ends: a second swarm (or a replay --clock) on the domain is
        # refused at once (before it writes anything) instead of mixing its messages with
        # this run's.
        held = claim_domain(args.domain_id, f'swarm {args.scenario}')
    except DomainBusy as exc:
        print(f'swarm: error: --domain-id: {exc}', file=sys.stderr)
        return EXIT_USAGE
    except ScenarioError as exc:
        print(f'swarm: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    try:
        overrides = args.overrides + ([f'transport={args.transport}'] if args.transport else [])
        scenario = resolve_scenario(args.scenario, overrides, args.seed, out,
                                    args.allow_unstable)
    except (ScenarioError, OSError) as exc:
        if held is not None:
            held.close()
        key = '--out: ' if isinstance(exc, OSError) else ''
        print(f'swarm: error: {key}{exc}', file=sys.stderr)
        return EXIT_USAGE
    live = None
    try:
        # Bound before the nodes start, so a port in use is a usage error, not a failed run.
        live = (None if args.foxglove is None
                else start_live(args.foxglove_host, args.foxglove, '--foxglove'))
        return _run(args, scenario, out, live, say, stop)
    except ServeError as exc:
        print(f'swarm: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    finally:
        if live is not None:
            live.close()
        if held is not None:
            held.close()


def _environment_domain() -> int:
    """Return the domain ``$ROS_DOMAIN_ID`` names (0 when unset or empty, as ROS reads it).

    :raises ScenarioError: when it is not a whole number.
    """
    text = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if not text:
        return 0
    if not text.isdigit():
        raise ScenarioError('ROS_DOMAIN_ID', f'must be a domain id in [0, 232], got {text!r}')
    return int(text)


def _run(args: argparse.Namespace, scenario: Path, out: Path, live, say,
         stop: StopSignals) -> int:
    """Run the resolved scenario as ``args`` say (serving it on ``live``); return the status
    (a stop signal's, when one ended the run)."""
    sc = read_scenario(scenario)
    if not args.processes:
        layout = 'one process (agents in one container node)'
    elif args.container and args.hosts > 1:
        layout = f'{args.hosts + 2} processes (agents in {args.hosts} container processes)'
    elif args.container:
        layout = 'three processes (agents in one container process)'
    else:
        layout = 'separate processes (one per agent)'
    say(f'[swarm] {sc.name}: world + leader + {sc.n_agents} agents in {layout}, {args.mode}, '
        f'{sc.steps} steps of {sc.dt:g} s, ROS_DOMAIN_ID={args.domain_id}')
    world_params = {'start_timeout': args.start_timeout}
    if args.pace:
        world_params['pace'] = args.pace
    if args.no_record:
        world_params['record'] = False
    if args.backend != 'plant':
        world_params['backend'] = args.backend
    if live is not None:
        # Every channel is advertised before the address is announced: a client connecting
        # on the announcement gets them all at once, not while the nodes are being built
        # (a subscription sent the moment the last channel appeared could be lost with it).
        from flock_swarm.contract import contract_topics
        live.add_topics(contract_topics(sc.n_agents, '/', bool(sc.law.initial_state(1)),
                                        sc.transport == 'batched'))
        say(f'[swarm] live view on {live.url} (Foxglove / Lichtblick: open a connection, '
            'Foxglove WebSocket)')
        if args.wait_for_viewer:
            say('[swarm] waiting for a viewer to subscribe (--wait-for-viewer; Ctrl-C stops)')
            try:
                # Polled, so a stop signal that only notes itself (StopSignals) ends the wait.
                while not live.wait_for_viewer(timeout=0.2):
                    if stop.stopped:
                        raise KeyboardInterrupt
            except KeyboardInterrupt:
                say('[swarm] interrupted before the run started')
                return stop.status(EXIT_INTERRUPTED)
    if args.processes:
        summary = run_processes(scenario, out, args.mode, args.domain_id, args.step_timeout,
                                realtime_factor=args.realtime_factor,
                                container=args.container, hosts=args.hosts,
                                world_params=world_params,
                                live=live, allow_unstable=args.allow_unstable,
                                stop=lambda: stop.first, say=say)
    else:
        try:
            summary = run_in_process(scenario, out, args.mode, args.domain_id,
                                     args.step_timeout, args.executor, progress=say,
                                     realtime_factor=args.realtime_factor,
                                     world_params=world_params, live=live,
                                     allow_unstable=args.allow_unstable,
                                     stop=lambda: stop.stopped)
        except ScenarioError as exc:
            # The world refused to start (another world on the domain: docs/ros.md).
            print(f'swarm: error: {exc}', file=sys.stderr)
            return EXIT_USAGE
    if stop.stopped:
        say(f'[swarm] stopped by {signal_name(stop.first)}')
    if not summary or not (out / 'summary.json').is_file():
        # A full disk may have stopped it: the summary in memory says why.
        why = summary.get('failure') if summary else None
        print(f'swarm: error: the world wrote no {out / "summary.json"}'
              + (f' ({why})' if why else ''), file=sys.stderr)
        return stop.status(EXIT_FAILURE)
    status = 0 if summary['status'] == 'completed' else EXIT_FAILURE
    written = [out / 'timeseries.npz']
    with stop.held():
        if not args.no_plots and written[0].is_file():
            import numpy as np
            from flock_swarm.outputs import write_error
            from flock_swarm.plots import plot_timeseries
            try:
                with np.load(written[0]) as data:
                    written += plot_timeseries(dict(data), out, sc.name, sc.obstacles)
            except OSError as exc:
                print(f'swarm: error: {write_error(exc)}', file=sys.stderr)
                status = EXIT_FAILURE
    say('[swarm] ' + result_line(summary, sc.headline, ('collisions', 'missed_commands')))
    # Only what is there: a run stopped before its first step has no bag and no time series.
    bag = [] if args.no_record else [out / 'bag']
    written = [path for path in [*bag, out / 'summary.json', *written] if path.exists()]
    say('[swarm] wrote ' + ', '.join(str(path) for path in written))
    if summary.get('failure'):
        print(f'swarm: error: {summary["failure"]}', file=sys.stderr)
    elif summary['status'] == 'interrupted' and not stop.stopped:
        # The status 1 needs its reason: a stop signal reached the world, not swarm.
        print('swarm: error: the world was stopped by a signal sent to it, not to swarm; the '
              f'run is interrupted at t = {summary["t_final"]:g} s', file=sys.stderr)
    return stop.status(status)


def _say(line: str) -> None:
    """Print a progress or result line on stderr."""
    try:
        print(line, file=sys.stderr, flush=True)
    except OSError:
        # The terminal went away (SIGHUP): the run still finalises and exits as it should.
        pass


if __name__ == '__main__':
    sys.exit(main())
