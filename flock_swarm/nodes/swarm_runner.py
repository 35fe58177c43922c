"""The swarm runner: world, leader and N agents in one process or as separate OS processes.

What ``swarm`` runs (:mod:`flock_swarm.cli.swarm`), what the testing API runs
(:mod:`flock_swarm.testing`: its ``Swarm`` is :class:`InProcessSwarm`) and what the
reproduction runs through the nodes (:mod:`flock_swarm.reproduce.execution`):

- :func:`resolve_scenario`: a preset or a file, with overrides and a seed, validated and
  written to ``DIR/scenario.yaml``, the one file every node starts on;
- :class:`InProcessSwarm` and :func:`run_in_process`: every node in this process on one
  executor (the agents in one container node);
- :func:`run_processes`: every node as its own process (the ``ros2 run`` executables,
  :func:`executable`), in the environment of :func:`process_environment`, supervised by
  :class:`~flock_swarm.nodes.supervisor.Supervisor` (logs, watching, stopping in order);
- :class:`SwarmRun`: what a finished run left in its output directory.

The run ends when the world has recorded its last step: ``DIR/bag/`` (rosbag2 MCAP),
``DIR/summary.json``, ``DIR/timeseries.npz``. Optionally served live over the Foxglove
WebSocket protocol (:mod:`flock_swarm.foxglove_ws`). Importing this module imports no rclpy,
NumPy or YAML (the testing API's pytest plugin imports it in every pytest run): those come
with the first run.
"""

from __future__ import annotations

import itertools
import json
import os
from pathlib import Path
import shutil
import sys
import time
from typing import Any, Callable, Iterable, TYPE_CHECKING

from flock_swarm import contract
from flock_swarm.console import commands
from flock_swarm.core.errors import ScenarioError
from flock_swarm.nodes.supervisor import LOG_DIR, Supervisor, report_death, report_exit

if TYPE_CHECKING:
    import numpy as np

    from flock_swarm.bag import BagReader
    from flock_swarm.core.scenario import Scenario
    from flock_swarm.foxglove_ws import LiveServer

#: Wall-clock bound [s] of one whole test run when the caller gives none (a hung run fails).
RUN_TIMEOUT = 240.0
#: Domain ids handed out by :func:`unique_domain`: the ranges the ROS 2 docs ("The
#: ROS_DOMAIN_ID") recommend on Linux, 1-101 and 215-232, less 0 (everybody's default, left to
#: people's own runs) and 215-222 (222 is scripts/demo's, the rest left to people's own runs).
#: Ids 102-214 can clash with the ephemeral ports the OS hands out, and ids above 232 overflow
#: the DDS port range.
DOMAIN_RANGES = ((1, 101), (223, 232))
#: How many ids :func:`unique_domain` hands out before one repeats (with the default ranges).
DOMAIN_SPAN = sum(hi - lo + 1 for lo, hi in DOMAIN_RANGES)
#: The environment variable that replaces :data:`DOMAIN_RANGES`: ``lo-hi[,lo-hi...]``, each
#: range within 0-232 (``FLOCK_SWARM_TEST_DOMAINS=30-59``: two test sessions on one machine
#: that must not share ids, or a network whose other users hold the default ranges).
DOMAINS_VARIABLE = 'FLOCK_SWARM_TEST_DOMAINS'

_domains = itertools.count()
#: The domain ids this process holds, with the open lock file of each (see unique_domain).
_held: dict[int, Any] = {}
#: The ids handed out when every id is held elsewhere.
_fallback = itertools.count()


def unique_domain() -> int:
    """Return a ROS domain id not handed out before in this process, in 1-101 or 223-232
    (:data:`DOMAIN_RANGES`: within ROS's recommended ranges) or in the ranges
    ``$FLOCK_SWARM_TEST_DOMAINS`` names (:func:`domain_ranges`), and held by no other process
    of this machine.

    Ids are spread over the ranges by process id, and each is held with a lock file (under
    the temporary directory, ``flock_swarm_domains/``) until the process exits: a world
    refuses to start beside another on its domain (docs/ros.md), so two test processes on
    one machine (discovery is limited to it) must not meet. When every id is held, the next
    one is shared (111 ids a process before one repeats).
    """
    ranges = domain_ranges(os.environ.get(DOMAINS_VARIABLE))
    for _ in range(sum(hi - lo + 1 for lo, hi in ranges)):
        domain = _domain_at(os.getpid() * 37 + next(_domains), ranges)
        if _hold(domain):
            return domain
    # Every id is held by another process: the next of this process's own sequence (so two
    # calls still differ).
    return _domain_at(os.getpid() * 37 + next(_fallback), ranges)


def domain_ranges(text: str | None) -> tuple[tuple[int, int], ...]:
    """Return the domain id ranges :func:`unique_domain` hands out: ``text`` read as
    ``lo-hi[,lo-hi...]`` (the value of :data:`DOMAINS_VARIABLE`), or :data:`DOMAIN_RANGES`
    when it is unset or blank.

    :param text: the variable's value, or ``None``.
    :return: the ranges, inclusive, in the given order.
    :raises ValueError: one line naming the variable and the part it cannot use (not
        ``lo-hi``, ``lo > hi``, outside 0-232, two ranges overlapping).
    """
    if text is None or not text.strip():
        return DOMAIN_RANGES
    ranges: list[tuple[int, int]] = []
    for part in text.split(','):
        bounds = part.strip().split('-')
        if len(bounds) != 2 or not all(b.strip().isdigit() for b in bounds):
            raise ValueError(f'{DOMAINS_VARIABLE}: {part.strip()!r} is not a range lo-hi of '
                             f'domain ids (expected lo-hi[,lo-hi...], e.g. 30-59,223-232)')
        lo, hi = (int(b) for b in bounds)
        if not 0 <= lo <= hi <= 232:
            raise ValueError(f'{DOMAINS_VARIABLE}: {part.strip()!r}: a range lo-hi needs '
                             '0 <= lo <= hi <= 232 (higher ids overflow the DDS port range)')
        for other in ranges:
            if lo <= other[1] and other[0] <= hi:
                raise ValueError(f'{DOMAINS_VARIABLE}: {part.strip()!r} overlaps '
                                 f'{other[0]}-{other[1]}')
        ranges.append((lo, hi))
    return tuple(ranges)


def release_domain(domain: int) -> None:
    """Let other processes have ``domain`` again (a test is done with it)."""
    lock = _held.pop(domain, None)
    if lock is not None:
        lock.close()


def _domain_at(index: int, ranges=DOMAIN_RANGES) -> int:
    """Return the domain id at position ``index`` (modulo their number) of ``ranges``."""
    n = index % sum(hi - lo + 1 for lo, hi in ranges)
    for lo, hi in ranges:
        if n <= hi - lo:
            return lo + n
        n -= hi - lo + 1
    raise AssertionError('unreachable: n is below the ranges\' total')


def _hold(domain: int) -> bool:
    """Hold ``domain`` for this process (a lock on its file); return whether it is ours."""
    import fcntl
    import tempfile
    if domain in _held:
        return True
    folder = Path(tempfile.gettempdir()) / 'flock_swarm_domains'
    try:
        folder.mkdir(exist_ok=True)
        lock = open(folder / f'{domain}.lock', 'a')
    except OSError:
        return True  # no lock files here: spread by process id only, as before
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.close()
        return False
    _held[domain] = lock
    return True


def resolve_scenario(name: str, overrides: Iterable[str], seed: int | None, out: Path,
                     allow_unstable: bool = False) -> Path:
    """Prepare the scenario as ``sim`` does and write it to ``out/scenario.yaml``.

    The one preparation of every front end (:func:`flock_swarm.presets.prepare`): overrides,
    seed, validation, the law-output check and, unless ``allow_unstable``, the step-size
    bound, refused with the line ``sim`` prints. The nodes started on the file prepare it
    again, with the same result.

    :param name: preset name or path.
    :param overrides: ``key=value`` assignments.
    :param seed: seed replacing the scenario's, or ``None``.
    :param out: the output directory (created).
    :param allow_unstable: accept a ``dt`` beyond a stability bound (``--allow-unstable``).
    :return: the path every node is started with.
    :raises ScenarioError: on invalid input.
    """
    import yaml

    from flock_swarm.presets import prepare

    if seed is not None and seed < 0:
        raise ScenarioError('--seed', f'must be >= 0, got {seed}')
    sc, _ = prepare(name, overrides, seed, allow_unstable=allow_unstable)
    out.mkdir(parents=True, exist_ok=True)
    path = out / 'scenario.yaml'
    path.write_text(yaml.safe_dump(sc.raw, sort_keys=False))
    return path


def read_scenario(path: Path) -> Scenario:
    """Return the validated scenario of a resolved scenario file (prepared when it was
    written: :func:`~flock_swarm.presets.reread`)."""
    from flock_swarm.presets import reread
    from flock_swarm.scenario_yaml import parse_yaml
    return reread(parse_yaml(Path(path).read_text()))


def node_parameters(scenario: Path, mode: str, realtime_factor: float,
                    allow_unstable: bool = False) -> dict:
    """Return the parameters every node gets (``allow_unstable`` only when set)."""
    params = {'scenario': str(scenario), 'mode': mode, 'realtime_factor': float(realtime_factor)}
    if allow_unstable:
        params['allow_unstable'] = True
    return params


class SwarmRun:
    """What a finished run left in its output directory, read back from the files.

    :param out: the run's output directory (``summary.json``, ``timeseries.npz``, ``bag/``).
    :raises AssertionError: when the run wrote no ``summary.json``.
    """

    def __init__(self, out: Path) -> None:
        """Read the scenario and the summary the run wrote."""
        self.out = Path(out)
        summary = self.out / 'summary.json'
        if not summary.is_file():
            raise AssertionError(f'the run wrote no {summary}')
        #: The ``summary.json`` mapping.
        self.summary: dict = json.loads(summary.read_text())
        #: The resolved scenario file every node ran on.
        self.scenario_path = self.out / 'scenario.yaml'
        #: The validated scenario.
        self.scenario: Scenario = read_scenario(self.scenario_path)

    def timeseries(self) -> dict[str, np.ndarray]:
        """Return the recorded time series (``timeseries.npz``) as arrays."""
        import numpy as np

        with np.load(self.out / 'timeseries.npz') as data:
            return {name: data[name] for name in data.files}

    def bag(self) -> BagReader:
        """Return a reader of the recorded bag (:class:`flock_swarm.bag.BagReader`).

        :raises AssertionError: when the run recorded no bag (``record: False``).
        """
        from flock_swarm.bag import BagReader

        if not (self.out / 'bag').is_dir():
            raise AssertionError(f'the run recorded no bag in {self.out / "bag"}')
        return BagReader(self.out / 'bag')

    def messages(self, topics: Iterable[str] | str) -> list:
        """Return the messages of ``topics`` in the bag as ``(BagMessage, rclpy message)``."""
        return list(self.bag().decoded(topics))


class InProcessSwarm:
    """World, leader and the agents in this process on one executor (a launch-free swarm).

    ``swarm`` without ``--processes`` runs one, and so do tests: it is the testing API's
    :class:`flock_swarm.testing.Swarm`. The scenario is resolved as ``swarm`` resolves it
    (:func:`resolve_scenario`: a preset name or a path, with ``key=value`` overrides and a
    seed) into ``out/scenario.yaml``, and every node starts on that file. The agents are
    hosted by one agent node (a container: one subscription per odometry topic for all of
    them), as ``ros2 run flock_swarm agents`` hosts them. Use it as a context manager; reach
    the nodes (``world``, ``leader``, ``agents``), add or remove nodes, spin until a condition
    holds (bounded, failing with a message) or to the end, and read the outputs back::

        with InProcessSwarm('demo', out, ['n_agents=5'], domain_id=7) as swarm:
            swarm.spin_until(lambda: swarm.world.k >= 100, timeout=60, what='step 100')
            swarm.remove(swarm.leader)
        run = swarm.result()

    :param scenario: a preset name or a scenario file.
    :param out: the output directory (created).
    :param overrides: ``key=value`` assignments, as ``swarm --set``.
    :param seed: a seed replacing the scenario's, or ``None``.
    :param domain_id: the ROS domain id of the run (``None``: :func:`unique_domain`).
    :param mode: ``lockstep`` or ``realtime``.
    :param step_timeout: the world's per-step timeout [s].
    :param executor: ``single`` (SingleThreadedExecutor) or ``events`` (EventsExecutor).
    :param progress: callback for progress lines.
    :param agents: ids of the agents to host (``None``: all); the others stay absent.
    :param world_params: further parameters of the world node.
    :param realtime_factor: realtime mode: simulated seconds per wall second.
    :param agent_params: further parameters of the agents' node.
    :param live: a :class:`~flock_swarm.foxglove_ws.LiveServer` to serve the run on (see
        :meth:`serve`), or None.
    :param allow_unstable: accept a ``dt`` beyond a stability bound (every node is told so).
    :raises ScenarioError: for an invalid scenario, before any node exists.
    """

    def __init__(self, scenario: str | Path, out: Path, overrides: Iterable[str] = (),
                 seed: int | None = None, domain_id: int | None = None, *,
                 mode: str = 'lockstep', step_timeout: float = 2.0, executor: str = 'events',
                 progress: Callable[[str], None] | None = None,
                 agents: Iterable[int] | None = None, world_params: dict | None = None,
                 realtime_factor: float = 1.0, agent_params: dict | None = None,
                 live: LiveServer | None = None, allow_unstable: bool = False) -> None:
        """Resolve the scenario; create the context, the nodes and the executor."""
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from flock_swarm.nodes.spin import make_executor, middleware_defaults
        from flock_swarm.nodes.world import WorldNode

        self.out = Path(out)
        self.domain_id = unique_domain() if domain_id is None else domain_id
        #: The resolved scenario file every node runs on.
        self.scenario_path = resolve_scenario(str(scenario), list(overrides), seed, self.out,
                                              allow_unstable)
        self.scenario = read_scenario(self.scenario_path)
        self.base = node_parameters(self.scenario_path, mode, realtime_factor, allow_unstable)
        self.closed = False
        self.context = Context()
        middleware_defaults()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        self.nodes = []
        self.executor = make_executor(self.context) if executor == 'events' \
            else SingleThreadedExecutor(context=self.context)
        try:
            self.world = self.add(WorldNode(
                progress=progress, context=self.context, parameter_overrides=self.parameters(
                    out_dir=str(self.out), step_timeout=step_timeout, **(world_params or {}))))
            self.leader = self.add_leader()
            hosted = range(self.scenario.n_agents) if agents is None else agents
            # No agent hosted (``agents=[]``): the test brings its own, robot agents say.
            self.agents = self.add_agents([int(i) for i in hosted], 'agents',
                                          **(agent_params or {})) if len(hosted) else None
            if live is not None:
                self.serve(live)
        except BaseException:
            self.close()
            raise

    def serve(self, live: LiveServer) -> None:
        """Serve the run on ``live`` (a :class:`~flock_swarm.foxglove_ws.LiveServer`).

        The world already holds every message of the contract once a step, as the bytes on
        the wire: a :class:`~flock_swarm.foxglove_ws.LiveSink` among its sinks gives them to
        the server too, at no cost in DDS deliveries (docs/performance.md).
        """
        from flock_swarm.contract import contract_topics
        from flock_swarm.foxglove_ws import LiveSink
        live.add_topics(contract_topics(self.scenario.n_agents, self.world.get_namespace(),
                                        bool(self.world.stepper.state), self.world.batched))
        self.world.sinks.append(LiveSink(live))
        if self.world.obstacles_map is not None:
            # Published at the world's start, before this sink: the server keeps the map
            # (latched) for the viewers that subscribe later.
            from flock_swarm.contract import OBSTACLES_TYPE
            topic = self.world.obstacles_pub.topic_name
            live.add_topic(topic, OBSTACLES_TYPE)
            live.latch(topic)
            live.write(topic, self.world.obstacles_map, 0)

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

    def spin_until(self, condition: Callable[[], Any], timeout: float,
                   what: str = 'the condition') -> None:
        """Spin every node until ``condition`` holds.

        :param condition: checked after every callback (or every 0.1 s without one).
        :param timeout: wall-clock bound [s].
        :param what: what is awaited, for the failure message.
        :raises AssertionError: on the timeout, or when the world finished first.
        """
        world = self.world
        deadline = time.monotonic() + timeout
        while not condition():
            if world.refusal is not None:
                raise world.refusal
            if world.done:
                raise AssertionError(f'the run ended ({world.status} at step {world.k}) '
                                     f'before {what}')
            if time.monotonic() > deadline:
                raise AssertionError(f'timed out after {timeout:g} s waiting for {what} '
                                     f'(the world is at step {world.k})')
            self.executor.spin_once(timeout_sec=0.1)

    def spin_to_end(self, timeout: float | None = None,
                    stop: Callable[[], Any] | None = None) -> None:
        """Spin until the world is done (or the context is shut down, by Ctrl-C).

        :param timeout: wall-clock bound [s] (``None``: no limit).
        :param stop: ends the spin early when it returns a true value (a stop signal came:
            :class:`~flock_swarm.console.StopSignals`), checked every 0.1 s at most.
        :raises TimeoutError: after ``timeout`` seconds.
        """
        started = time.monotonic()
        while self.context.ok() and not self.world.done and not (stop and stop()):
            self.executor.spin_once(timeout_sec=0.1)
            if self.world.refusal is not None:
                raise self.world.refusal
            if timeout is not None and time.monotonic() - started > timeout:
                raise TimeoutError(f'the run did not finish within {timeout:g} s')

    def run(self, timeout: float = RUN_TIMEOUT) -> SwarmRun:
        """Spin until the world has recorded its last step; close; return the outputs.

        :param timeout: wall-clock bound [s] of the rest of the run.
        :raises AssertionError: on the timeout.
        """
        world = self.world
        self.spin_until(lambda: world.done, timeout, 'the world to finish')
        self.close()
        return self.result()

    def summary(self) -> dict:
        """Return the world's summary (after the world finished or :meth:`close`)."""
        return self.world.result.summary if hasattr(self.world, 'result') else {}

    def result(self) -> SwarmRun:
        """Return the outputs (once the world finished, or after :meth:`close`)."""
        return SwarmRun(self.out)

    def close(self) -> None:
        """Let the world write what it recorded; destroy every node and the context (once)."""
        import rclpy
        if self.closed:
            return
        self.closed = True
        world = getattr(self, 'world', None)
        if world is not None:
            world.close()
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        self.nodes = []
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> InProcessSwarm:
        """Return the swarm."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Close the swarm."""
        self.close()


def run_in_process(scenario: Path, out: Path, mode: str = 'lockstep', domain_id: int = 0,
                   step_timeout: float = 2.0, executor: str = 'events',
                   progress: Callable[[str], None] | None = None,
                   timeout: float | None = None, agents: Iterable[int] | None = None,
                   world_params: dict | None = None, realtime_factor: float = 1.0,
                   live: LiveServer | None = None, allow_unstable: bool = False,
                   stop: Callable[[], Any] | None = None) -> dict:
    """Run world, leader and the agents in this process to the end (:class:`InProcessSwarm`).

    Ctrl-C, or ``stop`` returning a true value, ends the run early; the world still writes
    what it recorded (status ``interrupted``).

    :param scenario: the resolved scenario file (or a preset name or a file: it is resolved
        into ``out/scenario.yaml``).
    :param timeout: wall-clock limit [s] of the whole run (``None``: none).
    :param stop: polled while the run goes on: a stop signal came
        (:class:`~flock_swarm.console.StopSignals`).
    :return: the summary.
    :raises TimeoutError: after ``timeout`` seconds.

    The other parameters are :class:`InProcessSwarm`'s.
    """
    with InProcessSwarm(scenario, out, domain_id=domain_id, mode=mode,
                        step_timeout=step_timeout, executor=executor, progress=progress,
                        agents=agents, world_params=world_params,
                        realtime_factor=realtime_factor, live=live,
                        allow_unstable=allow_unstable) as swarm:
        try:
            swarm.spin_to_end(timeout, stop)
        except KeyboardInterrupt:
            pass
        swarm.world.close()
        return swarm.summary()


def executable(name: str) -> list[str]:
    """Return the command of a node executable: ``ros2 run``'s, the venv's, or ``python -m``
    (a command's module from setup.py's console scripts, :func:`~flock_swarm.console.commands`,
    else ``flock_swarm.nodes.<name>``)."""
    prefix_lib = Path(sys.prefix) / 'lib' / 'flock_swarm' / name
    if prefix_lib.is_file():
        return [str(prefix_lib)]
    found = shutil.which(name)
    if found:
        return [found]
    return [sys.executable, '-m', commands().get(name, f'flock_swarm.nodes.{name}')]


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
        from flock_swarm.presets import config_dirs
        for d in config_dirs():
            if (d / LARGE_SWARM_PROFILE).is_file():
                env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str((d / LARGE_SWARM_PROFILE).resolve())
                break
    return env


def id_ranges(n_agents: int, hosts: int) -> list[str]:
    """Return ``hosts`` contiguous ``agent_ids`` ranges (``'0-499'``) covering ``n_agents``
    agents, as even as they divide."""
    bounds = [round(k * n_agents / hosts) for k in range(hosts + 1)]
    return [f'{lo}-{hi - 1}' for lo, hi in zip(bounds[:-1], bounds[1:])]


def _ros_args(values: dict) -> list[str]:
    """Return ``--ros-args -p key:=value ...`` of a node's parameters."""
    out_args = ['--ros-args']
    for k, v in values.items():
        out_args += ['-p', f'{k}:={v}']
    return out_args


def _matched_bridge(live: LiveServer, domain_id: int, base: dict, sc: Scenario):
    """Return the live view's bridge node, spun by a thread of this process, once it has
    matched the leader's and the agents' publishers.

    The bridge's subscriptions are best effort: it must have matched the leader's and the
    agents' publishers (their adaptive state's too, for a law with one) before the first
    step, and the world waits for it as one more subscriber of every odometry topic and for
    its markers' and metrics' one.
    """
    from flock_swarm.nodes.foxglove_server import BackgroundBridge
    bridge = BackgroundBridge(live, domain_id, base)
    adaptive = range(sc.n_agents) if sc.law.initial_state(1) else ()
    bridge.wait_matched([contract.absolute(name) for name in (
        contract.LEADER_ODOM, contract.LEADER_ACCEL,
        *(contract.cmd_topic(i) for i in range(sc.n_agents)),
        *(contract.state_topic(i) for i in adaptive))], 30.0)
    return bridge


def _close_bridge(bridge) -> None:
    """Close the live view's bridge, warning of the topics it got no message on."""
    silent = bridge.node.silent()
    if silent:
        print('[swarm] warning: the live view got no message on ' + ', '.join(silent),
              file=sys.stderr, flush=True)
    bridge.close()


def _start_agents(children: Supervisor, base: dict, n: int, container: bool,
                  hosts: int) -> None:
    """Start the ``n`` agents' processes: one ``agent`` each, or with ``container`` one
    ``agents`` process (``hosts`` of them by id ranges, named ``agents_<k>``)."""
    if container and hosts > 1:
        for k, ids in enumerate(id_ranges(n, min(hosts, n))):
            name = f'agents_{k}'
            children.start(name, executable('agents') + _ros_args(
                dict(base, agent_ids=ids)) + ['-r', f'__node:={name}'])
    elif container:
        children.start('agents', executable('agents') + _ros_args(base))
    else:
        for i in range(n):
            children.start(contract.agent_name(i),
                           executable('agent') + _ros_args(dict(base, agent_id=i)))


def run_processes(scenario: Path, out: Path, mode: str = 'lockstep', domain_id: int = 0,
                  step_timeout: float = 2.0, timeout: float | None = None,
                  realtime_factor: float = 1.0, container: bool = False,
                  world_params: dict | None = None, live: LiveServer | None = None,
                  allow_unstable: bool = False, stop: Callable[[], int | None] | None = None,
                  say: Callable[[str], None] | None = None, hosts: int = 1) -> dict:
    """Run world, leader and the agents as separate OS processes (the ``ros2 run`` executables).

    Every agent gets its own process (``agent``, as on real robots), or with ``container``
    all agents share one (``agents``). The processes are supervised as ``ros2 launch`` does
    (:mod:`flock_swarm.nodes.supervisor`): their output goes to ``out/logs/<name>.log``; a
    process that dies ends the run (the world finalises with status ``failed``, and the dead
    process and the tail of its log are printed); a stop signal is forwarded to the world
    first, then the others are stopped. No child outlives the call.

    :param scenario: the resolved scenario file.
    :param out: the output directory.
    :param mode: ``lockstep`` or ``realtime``.
    :param domain_id: ``ROS_DOMAIN_ID`` of every process.
    :param step_timeout: the world's per-step timeout [s].
    :param timeout: wall-clock limit [s] of the whole run.
    :param realtime_factor: realtime mode: simulated seconds per wall second.
    :param container: host every agent in one ``agents`` process (``hosts`` of them).
    :param hosts: with ``container``, split the agents over this many ``agents`` processes
        by id ranges (``agent_ids``; named ``agents_0``, ``agents_1``, ...).
    :param world_params: further parameters of the world node.
    :param live: a :class:`~flock_swarm.foxglove_ws.LiveServer` to serve the run on, through a
        bridge node spun by a thread of this process
        (:class:`~flock_swarm.nodes.foxglove_server.BackgroundBridge`), or None.
    :param allow_unstable: tell every node to accept a ``dt`` beyond a stability bound.
    :param stop: returns the stop signal this process received (``None``: none yet), polled
        while the run goes on (:class:`~flock_swarm.console.StopSignals`).
    :param say: where the report of a dead process goes (default: stderr).
    :return: the summary the world wrote (empty when it wrote none).
    :raises TimeoutError: after ``timeout`` seconds (the world is stopped first).
    """
    sc = read_scenario(scenario)
    base = node_parameters(scenario, mode, realtime_factor, allow_unstable)
    children = Supervisor(out / LOG_DIR, process_environment(sc.n_agents, domain_id))
    bridge = None
    try:
        children.start('leader', executable('leader') + _ros_args(base))
        _start_agents(children, base, sc.n_agents, container, hosts)
        if live is not None:
            bridge = _matched_bridge(live, domain_id, base, sc)
            # One subscriber per agent host (every child so far but the leader), and the bridge.
            world_params = dict(world_params or {}, expect_subscribers=len(children.children),
                                expect_telemetry_subscribers=1)
        world = children.start('world', executable('world') + _ros_args(
            dict(base, out_dir=str(out), step_timeout=step_timeout, **(world_params or {}))),
            echo=sys.stderr)
        outcome = children.watch(world, stop or (lambda: None), timeout)
    finally:
        children.stop_all()
        if bridge is not None:
            _close_bridge(bridge)
    path = out / 'summary.json'
    summary = json.loads(path.read_text()) if path.is_file() else {}
    if outcome.dead is not None:
        report_death(outcome.dead, summary.get('steps'), say)
    if not summary and world.proc.returncode not in (0, None):
        # Killed (SIGKILL, the OOM killer) or failed before its summary: say how, and what
        # its log holds, not only that no summary was written (the other processes may have
        # ended on its death first, and been reported above).
        report_exit(world, f'before it wrote {path}', say)
    if outcome.timed_out:
        raise TimeoutError(f'the run did not finish within {timeout:g} s')
    return summary
