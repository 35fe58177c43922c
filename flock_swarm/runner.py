"""Launch-free runner: world, leader and N agents in one process or as separate processes.

``swarm SCENARIO [--set key=value ...] [--seed N] [--out DIR] [--processes]
[--foxglove [PORT]]`` resolves the scenario (with overrides and seed) into
``DIR/scenario.yaml``, starts every node on that file, prints progress, and ends when the
world has recorded its last step. Outputs: ``DIR/bag/`` (rosbag2 MCAP),
``DIR/summary.json``, ``DIR/timeseries.npz`` and figures. With ``--foxglove`` the run is
served live over the Foxglove WebSocket protocol (:mod:`flock_swarm.live`).
"""

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from flock_swarm.cli import EXIT_USAGE, OneLineParser, accept_sigint
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.run import check_law_output
from flock_swarm.core.scenario import apply_override, parse_scenario, parse_yaml, realize
from flock_swarm.live import DEFAULT_HOST, DEFAULT_PORT, ServeError, start_live
from flock_swarm.presets import config_dirs, load_mapping


def resolve_scenario(name: str, overrides: list[str], seed: int | None, out: Path) -> Path:
    """Validate the scenario with its overrides and write it to ``out/scenario.yaml``.

    :param name: preset name or path.
    :param overrides: ``key=value`` assignments.
    :param seed: seed replacing the scenario's, or ``None``.
    :param out: the output directory (created).
    :return: the path every node is started with.
    :raises ScenarioError: on invalid input.
    """
    data = load_mapping(name)
    for assignment in overrides:
        data = apply_override(data, assignment)
    if seed is not None:
        if seed < 0:
            raise ScenarioError('--seed', f'must be >= 0, got {seed}')
        data['seed'] = seed
    sc = parse_scenario(data)
    check_law_output(sc, realize(sc))
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'scenario.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def node_parameters(scenario: Path, mode: str, realtime_factor: float) -> dict:
    """Return the parameters every node gets."""
    return {'scenario': str(scenario), 'mode': mode, 'realtime_factor': float(realtime_factor)}


class InProcessSwarm:
    """World, leader and the agents in this process on one executor (a launch-free script).

    The agents are hosted by one agent node (a container: one subscription per odometry
    topic for all of them), as ``ros2 run flock_swarm agents`` hosts them. Use it as a
    context manager; tests reach the nodes (``world``, ``leader``, ``agents``), add or remove
    nodes, and spin until a condition holds::

        with InProcessSwarm(scenario, out, domain_id=7) as swarm:
            swarm.spin_until(lambda: swarm.world.k >= 100, timeout=60)
            swarm.remove(swarm.leader)

    :param scenario: the resolved scenario file.
    :param out: the output directory.
    :param mode: ``lockstep`` or ``realtime``.
    :param domain_id: the ROS domain id of the run.
    :param step_timeout: the world's per-step timeout [s].
    :param executor: ``single`` (SingleThreadedExecutor) or ``events`` (EventsExecutor).
    :param progress: callback for progress lines.
    :param agents: ids of the agents to host (``None``: all); the others stay absent.
    :param world_params: further parameters of the world node.
    :param realtime_factor: realtime mode: simulated seconds per wall second.
    :param agent_params: further parameters of the agents' node.
    :param live: a :class:`~flock_swarm.live.LiveServer` to serve the run on (see
        :meth:`serve`), or None.
    """

    def __init__(self, scenario: Path, out: Path, mode: str = 'lockstep', domain_id: int = 0,
                 step_timeout: float = 2.0, executor: str = 'events', progress=None,
                 agents=None, world_params: dict | None = None, realtime_factor: float = 1.0,
                 agent_params: dict | None = None, live=None) -> None:
        """Create the context, the nodes and the executor."""
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from flock_swarm.nodes.spin import make_executor
        from flock_swarm.nodes.world import WorldNode

        self.scenario = parse_scenario(parse_yaml(scenario.read_text()))
        self.base = node_parameters(scenario, mode, realtime_factor)
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.nodes = []
        self.executor = make_executor(self.context) if executor == 'events' \
            else SingleThreadedExecutor(context=self.context)
        try:
            self.world = self.add(WorldNode(
                progress=progress, context=self.context, parameter_overrides=self.parameters(
                    out_dir=str(out), step_timeout=step_timeout, **(world_params or {}))))
            self.leader = self.add_leader()
            hosted = range(self.scenario.n_agents) if agents is None else agents
            self.agents = self.add_agents([int(i) for i in hosted], 'agents',
                                          **(agent_params or {}))
            if live is not None:
                self.serve(live)
        except BaseException:
            self.close()
            raise

    def serve(self, live) -> None:
        """Serve the run on ``live`` (a :class:`~flock_swarm.live.LiveServer`).

        The world already holds every message of the contract once a step, as the bytes on
        the wire: a :class:`~flock_swarm.live.LiveSink` among its sinks gives them to the
        server too, at no cost in DDS deliveries (docs/performance.md).
        """
        from flock_swarm.live import LiveSink, contract_topics
        live.add_topics(contract_topics(self.scenario.n_agents, self.world.get_namespace()))
        self.world.sinks.append(LiveSink(live))

    def parameters(self, **values) -> list:
        """Return the common node parameters plus ``values`` as rclpy parameters."""
        from rclpy.parameter import Parameter
        return [Parameter(k, value=v) for k, v in dict(self.base, **values).items()]

    def add(self, node):
        """Spin ``node`` with the others; return it."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def add_leader(self):
        """Start a leader node (again, after :meth:`remove`); return it."""
        from flock_swarm.nodes.leader import LeaderNode
        return self.add(LeaderNode(context=self.context,
                                   parameter_overrides=self.parameters(expect_subscribers=2)))

    def add_agents(self, ids: list[int], name: str, **params):
        """Start an agent node hosting ``ids``; return it."""
        from flock_swarm.nodes.agent import AgentNode
        return self.add(AgentNode(node_name=name, context=self.context,
                                  parameter_overrides=self.parameters(agent_ids=ids, **params)))

    def remove(self, node) -> None:
        """Stop spinning ``node`` (a process that died, as the others see it).

        It is destroyed with the others by :meth:`close`: an executor may still hold events
        of a node it has just let go.
        """
        self.executor.remove_node(node)

    def spin_until(self, condition, timeout: float | None) -> None:
        """Spin until ``condition()`` holds or the world is done.

        :raises TimeoutError: after ``timeout`` seconds (``None``: no limit).
        """
        started = time.monotonic()
        while self.context.ok() and not self.world.done and not condition():
            self.executor.spin_once(timeout_sec=0.1)
            if timeout is not None and time.monotonic() - started > timeout:
                raise TimeoutError(f'the run did not get there within {timeout:g} s')

    def summary(self) -> dict:
        """Return the world's summary (after the world finished or :meth:`close`)."""
        return self.world.result.summary if hasattr(self.world, 'result') else {}

    def close(self) -> None:
        """Let the world write what it recorded; destroy every node and the context."""
        import rclpy
        world = getattr(self, 'world', None)
        if world is not None:
            world.close()
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        self.nodes = []
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> 'InProcessSwarm':
        """Return the swarm."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Close the swarm."""
        self.close()


def run_in_process(scenario: Path, out: Path, mode: str = 'lockstep', domain_id: int = 0,
                   step_timeout: float = 2.0, executor: str = 'events',
                   progress=None, timeout: float | None = None, agents=None,
                   world_params: dict | None = None, realtime_factor: float = 1.0,
                   live=None) -> dict:
    """Run world, leader and the agents in this process to the end (:class:`InProcessSwarm`).

    :param timeout: wall-clock limit [s] of the whole run (``None``: none).
    :return: the summary.

    The other parameters are :class:`InProcessSwarm`'s.
    """
    with InProcessSwarm(scenario, out, mode, domain_id, step_timeout, executor, progress,
                        agents, world_params, realtime_factor, live=live) as swarm:
        try:
            swarm.spin_until(lambda: False, timeout)
        except KeyboardInterrupt:
            pass
        swarm.world.close()
        return swarm.summary()


#: Modules of the executables that are not ``flock_swarm.nodes.<name>``, for ``python -m``.
MODULES = {'replay': 'flock_swarm.replay', 'swarm': 'flock_swarm.runner'}


def executable(name: str) -> list[str]:
    """Return the command of a node executable: ``ros2 run``'s, the venv's, or ``python -m``."""
    prefix_lib = Path(sys.prefix) / 'lib' / 'flock_swarm' / name
    if prefix_lib.is_file():
        return [str(prefix_lib)]
    found = shutil.which(name)
    if found:
        return [found]
    return [sys.executable, '-m', MODULES.get(name, f'flock_swarm.nodes.{name}')]


def stop(procs: list, timeout: float = 10.0) -> None:
    """End processes as Ctrl-C would (SIGINT), killing those still there after ``timeout``.

    One deadline for all: a hundred agent processes that ignore SIGINT are killed after
    ``timeout``, not after ``timeout`` each.
    """
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + timeout
    for proc in procs:
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


#: Fast DDS profile of swarms of several hundred agents across processes (docs/ros.md).
LARGE_SWARM_PROFILE = 'fastdds_large_swarm.xml'
#: From this many agents on, a run across processes applies it (unless the environment
#: names a profile of its own): at N = 500 and 1000 in the container layout, Fast DDS's
#: default shared-memory transport lost commands to the step timeout without it.
LARGE_SWARM_AGENTS = 200
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')


def process_environment(n_agents: int, domain_id: int, base: dict | None = None) -> dict:
    """Return the environment of a run's processes: the domain id, discovery on this host
    unless set, and the large-swarm Fast DDS profile for ``n_agents`` of at least
    :data:`LARGE_SWARM_AGENTS` when the environment names no profile."""
    env = dict(os.environ if base is None else base, ROS_DOMAIN_ID=str(domain_id))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if n_agents >= LARGE_SWARM_AGENTS and not any(env.get(v) for v in PROFILE_VARIABLES):
        for d in config_dirs():
            if (d / LARGE_SWARM_PROFILE).is_file():
                env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str((d / LARGE_SWARM_PROFILE).resolve())
                break
    return env


def run_processes(scenario: Path, out: Path, mode: str = 'lockstep', domain_id: int = 0,
                  step_timeout: float = 2.0, timeout: float | None = None,
                  log=None, realtime_factor: float = 1.0, container: bool = False,
                  world_params: dict | None = None, live=None) -> dict:
    """Run world, leader and the agents as separate OS processes (the ``ros2 run`` executables).

    Every agent gets its own process (``agent``, as on real robots), or with ``container``
    all agents share one (``agents``).

    :param scenario: the resolved scenario file.
    :param out: the output directory.
    :param mode: ``lockstep`` or ``realtime``.
    :param domain_id: ``ROS_DOMAIN_ID`` of every process.
    :param step_timeout: the world's per-step timeout [s].
    :param timeout: wall-clock limit [s] of the whole run.
    :param log: file object receiving the agents' and leader's output (default: discarded).
    :param realtime_factor: realtime mode: simulated seconds per wall second.
    :param container: host every agent in one ``agents`` process.
    :param world_params: further parameters of the world node.
    :param live: a :class:`~flock_swarm.live.LiveServer` to serve the run on, through a
        bridge node spun by a thread of this process
        (:class:`~flock_swarm.nodes.foxglove_server.BackgroundBridge`), or None.
    :return: the summary.
    """
    sc = parse_scenario(parse_yaml(scenario.read_text()))
    env = process_environment(sc.n_agents, domain_id)

    def ros_args(values: dict) -> list[str]:
        out_args = ['--ros-args']
        for k, v in values.items():
            out_args += ['-p', f'{k}:={v}']
        return out_args

    base = node_parameters(scenario, mode, realtime_factor)
    sink = log if log is not None else subprocess.DEVNULL
    others = [subprocess.Popen(executable('leader') + ros_args(base), env=env, stdout=sink,
                               stderr=sink)]
    hosts = [executable('agents') + ros_args(base)] if container else [
        executable('agent') + ros_args(dict(base, agent_id=i)) for i in range(sc.n_agents)]
    for command in hosts:
        others.append(subprocess.Popen(command, env=env, stdout=sink, stderr=sink))
    bridge = None
    if live is not None:
        from flock_swarm.nodes.foxglove_server import BackgroundBridge
        bridge = BackgroundBridge(live, domain_id, base)
        # The bridge's subscriptions are best effort: it must have matched the leader's and
        # the agents' publishers before the first step, and the world waits for it as one
        # more subscriber of every odometry topic and for its markers' and metrics' one.
        bridge.wait_matched(['/leader/odom', '/leader/accel'] + [
            f'/agent_{i}/cmd_accel' for i in range(sc.n_agents)], 30.0)
        world_params = dict(world_params or {}, expect_subscribers=len(hosts) + 1,
                            expect_telemetry_subscribers=1)
    world = subprocess.Popen(executable('world') + ros_args(
        dict(base, out_dir=str(out), step_timeout=step_timeout, **(world_params or {}))),
        env=env)
    try:
        world.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        world.send_signal(signal.SIGINT)
        world.wait(timeout=30)
        raise TimeoutError(f'the run did not finish within {timeout:g} s') from None
    finally:
        stop(others)
        if bridge is not None:
            silent = bridge.node.silent()
            if silent:
                print('[swarm] warning: the live view got no message on ' + ', '.join(silent),
                      file=sys.stderr, flush=True)
            bridge.close()
    summary = out / 'summary.json'
    return json.loads(summary.read_text()) if summary.is_file() else {}


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
        scenario = resolve_scenario(args.scenario, args.overrides, args.seed, out)
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
    sc = parse_scenario(parse_yaml(scenario.read_text()))
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
        from flock_swarm.live import contract_topics
        live.add_topics(contract_topics(sc.n_agents, '/'))
        say(f'[swarm] live view on {live.url} (Foxglove / Lichtblick: open a connection, '
            'Foxglove WebSocket)')
    if args.processes:
        summary = run_processes(scenario, out, args.mode, args.domain_id, args.step_timeout,
                                realtime_factor=args.realtime_factor,
                                container=args.container, world_params=world_params,
                                live=live)
    else:
        summary = run_in_process(scenario, out, args.mode, args.domain_id, args.step_timeout,
                                 args.executor, progress=say,
                                 realtime_factor=args.realtime_factor,
                                 world_params=world_params, live=live)
    if not summary:
        print('swarm: error: the world wrote no summary', file=sys.stderr)
        return 1
    if not args.no_plots and (out / 'timeseries.npz').is_file():
        import numpy as np
        from flock_swarm.plots import plot_timeseries
        with np.load(out / 'timeseries.npz') as data:
            plot_timeseries(dict(data), out, sc.name)
    say(f'[swarm] {summary["status"]} at t = {summary["t_final"]:g} s: eta = '
        f'{summary["eta"]:.3f}, velocity mismatch = {summary["velocity_mismatch_max"]:.3g}, '
        f'collisions = {summary["collisions"]}, missed commands = '
        f'{summary.get("missed_commands", 0)} ({summary.get("wall_time_s", 0):.1f} s wall)')
    say('[swarm] wrote ' + ('' if args.no_record else f'{out}/bag, ')
        + f'{out}/summary.json, {out}/timeseries.npz'
        + ('' if args.no_plots else f', {out}/trajectories.png, {out}/metrics.png'))
    return 0 if summary['status'] == 'completed' else 1


if __name__ == '__main__':
    sys.exit(main())
