"""Benchmark of the lockstep ROS pipeline against its messaging floor, recording and memory.

    python bench/bench_ros.py [--sizes 5 10 20 50 100] [--layouts one container processes]
                              [--steps 300] [--repeat 3] [--memory] [--json out/bench/ros.json]
                              [--transports per_agent batched]

For each layout and N it runs, in fresh processes and one after the other:

``pipeline``
    world + leader + N agents (``swarm demo`` at the demo's density, lockstep, recording on):
    steps per second from the world's own clock (``steps / wall_time_s``, start-up and
    discovery excluded) and the real-time factor ``steps dt / wall``.
``no-record``
    the same run with ``record:=false``.
``floor``
    the same publish/subscribe pattern, with the same message types, QoS, executor
    (EventsExecutor) and process layout, but empty callbacks: a world publishing ``/clock``
    and N odometry messages per step and waiting for N commands and the leader's two
    messages; a leader answering each tick; agent hosts answering once they have every
    odometry and the leader's state. Messages are built once and reused; subscriptions
    deliver rclpy messages (the typed API every rclpy node uses by default). A stalled step
    is offered again by the world node's rule (``WorldStepper.resent``: after max(0.5 s,
    3x the previous step), then doubling); re-offered steps are counted for every run.
``raw floor``
    the same with serialised bytes: every message of the run serialised before the clock
    starts, raw subscriptions (``raw=True``) reading the step off the bytes. This is how the
    pipeline's nodes move messages (``flock_swarm.nodes.wire``), and the lowest cost of the
    pattern in rclpy.
``C floor``
    the raw floor's bytes moved as the pipeline's nodes move them on the compiled path
    (``flock_swarm.nodes.batch``, issue 28): ``/clock`` and the odometry published in one
    call, a step's commands (the agent host: its odometry) taken at once from the first
    message's callback, the host's commands published in one call. Not run when the
    extension is not built or ``FLOCK_SWARM_MESSAGE_PATH=rclpy`` (the pipeline then runs
    on rclpy too).

``batched`` (``--transports batched``; issue 41)
    the pipeline with ``swarm --transport batched`` (the swarm's state as one PointCloud2 a
    step, the agents host's commands as one: docs/ros.md, "Transports"), recording on and
    off, in the ``one`` and ``container`` layouts, beside ``sim``'s steps/s on the same
    scenario in the same invocation (``sim``'s own ``wall_time_s``: the limit without ROS).
    Targets: N = 1000 in one process >= 200 steps/s with recording and >= 0.3 of ``sim``;
    N = 10,000 >= 50 steps/s, its cost per agent-step within 1.3x that at N = 1000.

Each variant runs ``--repeat`` times, interleaved, and the best run counts (on a shared
machine the least disturbed one); every run is in the JSON.

Layouts: ``one`` (every node in one process, the agents in one container node),
``container`` (three processes: world | leader | agents container), ``processes`` (world,
leader and one process per agent, like ``ros2 run flock_swarm agent`` on robots). The
``processes`` layout runs ``max(50, 10 S / N)`` steps (S: ``--steps``), gives the world a
60 s step timeout and a 300 s start timeout, and beyond 20 agents uses SUBNET discovery
(``--discovery auto``, see :data:`LOCALHOST_PROCESS_AGENTS`). A (layout, N) whose runs fail
(no summary, missed commands, or longer than 900 s) is reported as a failed row and the
benchmark goes on.

Besides the rates, each row gives the pipeline's microseconds per agent-step (``1e6 / (steps/s
N)``, so that growth with N shows in one table; the floors' are in the JSON), its seconds
outside the steps (launch to the first step: imports, entity creation, discovery, matching;
plus the teardown after the last) and the peak RSS of its largest process.

Targets (issue 5): pipeline >= 70 % of the floor's steps/s at every N (checked against
both floors); N = 100 in one
process >= 20 steps/s; recording costs <= 10 % (pipeline against no-record). Issue 17, with
``--sizes 100 200 500 1000``: cost per agent-step at N = 1000 within 1.5x that at N = 100 in
each layout, N = 1000 at >= 25 steps/s with recording. Issue 28, with ``--sizes 100 300 1000 2000
--layouts one container``: pipeline >= 70 % of the C floor at N = 100 and 1000, N = 100 in
one process >= 500 steps/s, N = 1000 >= 50 steps/s with recording (real time at dt = 0.02),
cost per agent-step at N = 2000 within 1.3x that at N = 100. The memory check
(``--memory``; ``--memory-n N`` agents, default 30) runs the one-process pipeline for S and
10 S steps and compares peak RSS (target: < 1.2x).
"""

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from flock_swarm.console import accept_sigint
from flock_swarm.nodes.swarm_runner import process_environment
from flock_swarm.nodes.supervisor import stop

#: The demo scenario's density (30 agents in 20 m x 20 m), kept at every N.
DENSITY = 30 / 400.0
#: Wall-clock bound of one benchmark run.
RUN_TIMEOUT = 900.0
#: Domain id of the benchmark runs (isolated from the test suite's 1-200).
DOMAIN = 220
#: Why there is no C floor when the extension is built (the path is forced to rclpy).
ENV_RCLPY = 'FLOCK_SWARM_MESSAGE_PATH=rclpy'


def scenario_overrides(n: int, steps: int) -> list[str]:
    """Return the ``--set`` overrides of the demo at ``n`` agents and ``steps`` steps."""
    side = math.sqrt(n / DENSITY)
    return [f'n_agents={n}', f'informed.count={max(1, n // 3)}',
            f'initial.position_box=[[0, {side:.3f}], [0, {side:.3f}]]',
            f'duration={steps * 0.02:.2f}', 'record_every=10']


# ----------------------------------------------------------------------------------------------
# The messaging floor: the pipeline's topics and messages, empty callbacks

#: Steps before the floor's clock starts (discovery settles, first samples repaired).
WARMUP = 10
#: Seconds between the floor world's reports while it waits for discovery.
REPORT_PERIOD = 30.0


class Wire:
    """How the floor moves messages: rclpy's typed messages, or serialised bytes.

    ``typed``: messages built once and refilled, subscriptions deserialise (what an rclpy
    node with empty callbacks costs). ``raw``: every message of the run serialised before
    the clock starts, raw subscriptions (``raw=True``) that read the step off the bytes: the
    lowest cost of the pattern in rclpy, and the way the pipeline's nodes move messages.
    """

    def __init__(self, raw: bool, n: int, last: int) -> None:
        """Prepare the messages of steps ``0..last`` (``raw``) or the reusable ones."""
        from geometry_msgs.msg import AccelStamped
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock

        from flock_swarm.nodes.wire import AccelEncoder, OdometryEncoder, encode_clock
        self.raw = raw
        if raw:
            ns = [k * 1_000_000_000 for k in range(last + 1)]
            odom = [OdometryEncoder(f'agent_{i}') for i in range(n)]
            self.clock = [encode_clock(t) for t in ns]
            self.odom = [[enc.encode(t, (0.0, 0.0), (0.0, 0.0)) for enc in odom] for t in ns]
            self.accel = [AccelEncoder().encode(t, (0.0, 0.0)) for t in ns]
            leader = OdometryEncoder('leader')
            self.leader_odom = [leader.encode(t, (0.0, 0.0), (0.0, 0.0)) for t in ns]
        else:
            self.clock_msg, self.odom_msgs = Clock(), [Odometry() for _ in range(n)]
            self.accel_msg, self.leader_msg = AccelStamped(), Odometry()

    def step_of(self, msg) -> int:
        """Return the step a received message is stamped with."""
        return int.from_bytes(msg[4:8], 'little') if self.raw else msg.header.stamp.sec

    def step_of_clock(self, msg) -> int:
        """Return the step of a received ``/clock``."""
        return int.from_bytes(msg[4:8], 'little') if self.raw else msg.clock.sec

    def states(self, k: int) -> tuple:
        """Return ``/clock`` and the odometry messages of step ``k``."""
        if self.raw:
            return self.clock[k], self.odom[k]
        self.clock_msg.clock.sec = k
        for msg in self.odom_msgs:
            msg.header.stamp.sec = k
        return self.clock_msg, self.odom_msgs

    def command(self, k: int):
        """Return a command (and the leader's acceleration) of step ``k``."""
        if self.raw:
            return self.accel[k]
        self.accel_msg.header.stamp.sec = k
        return self.accel_msg

    def leader_state(self, k: int) -> tuple:
        """Return the leader's odometry and acceleration of step ``k``."""
        if self.raw:
            return self.leader_odom[k], self.accel[k]
        self.leader_msg.header.stamp.sec = k
        return self.leader_msg, self.command(k)


def floor_nodes(role: str, n: int, steps: int, hosts: int, agent_ids: list[int], context,
                raw: bool = False, c: bool = False):
    """Return the floor's nodes for one process and its shared state.

    :param role: ``one`` (all), ``world``, ``leader`` or ``agents``.
    :param n: number of agents.
    :param steps: steps to time (after ``WARMUP``).
    :param hosts: processes hosting agents (subscribers the world waits for).
    :param agent_ids: the agents this process hosts (role ``one`` or ``agents``).
    :param context: the rclpy context.
    :param raw: move serialised bytes (see :class:`Wire`).
    :param c: with ``raw``, move a step's messages with the compiled extension
        (:mod:`flock_swarm.nodes.batch`) as the pipeline's nodes do on the C path: the world
        publishes ``/clock`` and the odometry in one call and takes the rest of a step's
        commands from the first one's callback, the agent host likewise with the odometry
        and its commands.
    """
    from geometry_msgs.msg import AccelStamped
    from nav_msgs.msg import Odometry
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock

    from flock_swarm import contract
    from flock_swarm.contract import CLOCK, LEADER_ACCEL, LEADER_ODOM, cmd_topic, odom_topic
    from flock_swarm.nodes.batch import BatchPublish, BatchTake
    from flock_swarm.nodes.stepper import RESEND_PERIOD, first_resend_wait, next_resend_wait
    CLOCK_QOS, LOCKSTEP_QOS = (contract.qos_profile(q) for q in (contract.CLOCK_QOS,
                                                                 contract.LOCKSTEP_QOS))
    nodes, state = [], {'step': 0, 'cmds': 0, 'leader': 0, 't0': None, 't1': None,
                        'started': False, 'stall': 0.0, 'wait': RESEND_PERIOD,
                        'began': 0.0, 'last_step_s': 0.0, 'resends': 0,
                        'report': time.monotonic() + REPORT_PERIOD}
    wire = Wire(raw or c, n, WARMUP + steps)
    kw = {'raw': True} if raw or c else {}
    # The extension's takers and publishers (closed before the nodes are destroyed).
    state['held'] = []

    if role in ('one', 'world'):
        world = Node('floor_world', context=context)
        clock_pub = world.create_publisher(Clock, CLOCK, CLOCK_QOS)
        odom_pubs = [world.create_publisher(Odometry, odom_topic(i), LOCKSTEP_QOS)
                     for i in range(n)]

        def tick(again: bool = False):
            # The world node's rule for a stalled step (``WorldStepper.resent``): offered
            # again after first_resend_wait(the previous step), then with
            # doubling waits, so an overloaded layout is not flooded with copies.
            now = time.monotonic()
            if again:
                state['resends'] += 1
                state['wait'] = next_resend_wait(state['wait'], state['last_step_s'])
            else:
                state['began'] = now
                state['wait'] = first_resend_wait(state['last_step_s'])
            state['stall'] = now + state['wait']
            clock, odom = wire.states(state['step'])
            if c:
                out.publish_to(targets, [clock] + odom)
                return
            clock_pub.publish(clock)
            for pub, msg in zip(odom_pubs, odom):
                pub.publish(msg)

        def arrived(msg, kind):
            if wire.step_of(msg) != state['step']:
                return
            state[kind] += 1
            if state['cmds'] >= n and state['leader'] >= 2:
                state['cmds'] = state['leader'] = 0
                state['last_step_s'] = time.monotonic() - state['began']
                state['step'] += 1
                if state['step'] == WARMUP:
                    state['t0'], state['cpu0'] = time.perf_counter(), time.process_time()
                if state['step'] == WARMUP + steps:
                    state['t1'], state['cpu1'] = time.perf_counter(), time.process_time()
                else:
                    tick()

        cmd_take = []

        def on_command(msg):
            arrived(msg, 'cmds')
            for _, more in cmd_take[0].take() if cmd_take else ():
                arrived(more, 'cmds')

        cmd_subs = [world.create_subscription(AccelStamped, cmd_topic(i), on_command,
                                              LOCKSTEP_QOS, **kw) for i in range(n)]
        if c:
            cmd_take.append(BatchTake(cmd_subs))
            out = BatchPublish([clock_pub] + odom_pubs)
            targets = np.arange(n + 1, dtype=np.int64)
            state['held'] += [cmd_take[0], out]
        world.create_subscription(Odometry, LEADER_ODOM, lambda m: arrived(m, 'leader'),
                                  LOCKSTEP_QOS, **kw)
        world.create_subscription(AccelStamped, LEADER_ACCEL, lambda m: arrived(m, 'leader'),
                                  LOCKSTEP_QOS, **kw)

        def on_timer():
            if state['started']:
                if state['t1'] is None and time.monotonic() > state['stall']:
                    state['cmds'] = state['leader'] = 0
                    tick(again=True)
                return
            if all(p.get_subscription_count() >= hosts for p in odom_pubs) \
                    and clock_pub.get_subscription_count() >= 1 \
                    and all(world.count_publishers(f'/{cmd_topic(i)}') for i in range(n)) \
                    and world.count_publishers(f'/{LEADER_ODOM}'):
                state['started'] = True
                tick()
            elif time.monotonic() > state['report']:
                # Progress of discovery, for layouts that take minutes to discover.
                state['report'] = time.monotonic() + REPORT_PERIOD
                matched = min(p.get_subscription_count() for p in odom_pubs)
                commands = sum(world.count_publishers(f'/{cmd_topic(i)}') > 0
                               for i in range(n))
                print(f'floor world: waiting for discovery: every odometry matched by >= '
                      f'{matched} of {hosts} hosts, /clock by '
                      f'{clock_pub.get_subscription_count()}, command publishers {commands} '
                      f'of {n}, leader {world.count_publishers(f"/{LEADER_ODOM}")}',
                      file=sys.stderr, flush=True)

        world.create_timer(0.01, on_timer)
        nodes.append(world)

    if role in ('one', 'leader'):
        leader = Node('floor_leader', context=context)
        l_odom = leader.create_publisher(Odometry, LEADER_ODOM, LOCKSTEP_QOS)
        l_accel = leader.create_publisher(AccelStamped, LEADER_ACCEL, LOCKSTEP_QOS)

        def on_clock(msg):
            odom, accel = wire.leader_state(wire.step_of_clock(msg))
            l_odom.publish(odom)
            l_accel.publish(accel)

        leader.create_subscription(Clock, CLOCK, on_clock, CLOCK_QOS, **kw)
        nodes.append(leader)

    if role in ('one', 'agents'):
        host = Node('floor_agents', context=context)
        pubs = [host.create_publisher(AccelStamped, cmd_topic(i), LOCKSTEP_QOS)
                for i in agent_ids]
        box = {'step': -1, 'odom': 0, 'leader': 0, 'answers': 0}

        def got(msg, kind):
            k = wire.step_of(msg)
            if k != box['step']:
                box.update(step=k, odom=0, leader=0, answers=0)
            box[kind] += 1
            # Once per complete set of odometry: a step the world offers again (commands
            # sent before its subscriptions matched are lost) is answered again, as the
            # agents do.
            if box['leader'] >= 2 and box['odom'] // n > box['answers']:
                box['answers'] = box['odom'] // n
                cmd = wire.command(k)
                if c:
                    answer.publish_to(rows, [cmd] * len(pubs))
                    return
                for pub in pubs:
                    pub.publish(cmd)

        odom_take = []

        def on_odom(msg):
            got(msg, 'odom')
            for _, more in odom_take[0].take() if odom_take else ():
                got(more, 'odom')

        odom_subs = [host.create_subscription(Odometry, odom_topic(j), on_odom, LOCKSTEP_QOS,
                                              **kw) for j in range(n)]
        if c:
            odom_take.append(BatchTake(odom_subs))
            answer = BatchPublish(pubs)
            rows = np.arange(len(pubs), dtype=np.int64)
            state['held'] += [odom_take[0], answer]
        host.create_subscription(Odometry, LEADER_ODOM, lambda m: got(m, 'leader'),
                                 LOCKSTEP_QOS, **kw)
        host.create_subscription(AccelStamped, LEADER_ACCEL, lambda m: got(m, 'leader'),
                                 LOCKSTEP_QOS, **kw)
        nodes.append(host)
    return nodes, state


def run_floor_role(args) -> int:
    """Run the floor's nodes of one process (``--role``); the world prints its steps/s."""
    import rclpy
    from rclpy.context import Context

    from flock_swarm.nodes.spin import make_executor, middleware_defaults
    context = Context()
    middleware_defaults()   # the floors publish as the pipeline's nodes do
    rclpy.init(context=context, domain_id=args.domain)
    ids = list(range(args.n)) if args.agent_ids is None else args.agent_ids
    nodes, state = floor_nodes(args.role, args.n, args.steps, args.hosts, ids, context,
                               raw=args.raw, c=args.c)
    ex = make_executor(context)
    for node in nodes:
        ex.add_node(node)
    deadline = time.monotonic() + RUN_TIMEOUT
    try:
        while context.ok() and time.monotonic() < deadline and state['t1'] is None:
            ex.spin_once(timeout_sec=0.05)
    except KeyboardInterrupt:
        pass
    if state['t1'] is not None:
        print(json.dumps({'steps_per_s': args.steps / (state['t1'] - state['t0']),
                          'resent_steps': state['resends'],
                          # CPU of every thread of this process (DDS's included) per step:
                          # steadier than the rate on a shared machine.
                          'cpu_ms_per_step':
                              1e3 * (state['cpu1'] - state['cpu0']) / args.steps}), flush=True)
    ex.shutdown()
    for held in state['held']:
        held.close()
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown(context=context)
    return 0


# ----------------------------------------------------------------------------------------------
# Orchestration


#: ROS_AUTOMATIC_DISCOVERY_RANGE of the runs (``--discovery``; ``auto``: see
#: :func:`discovery_range`).
DISCOVERY = ['auto']
#: With LOCALHOST, rmw_fastrtps gives Fast DDS 127.0.0.1 as its one initial peer, and Fast
#: DDS announces itself there to participant ids 0-3 only (``s_maximumInitialPeersRange``
#: = 4): 52 processes (N = 50 in the ``processes`` layout) never all discovered one another
#: here. ``auto`` switches to SUBNET (multicast, which reaches every participant) beyond
#: this many agents in that layout.
LOCALHOST_PROCESS_AGENTS = 20
#: The world's step timeout in the ``processes`` layout [s]: tens of agent processes on two
#: cores take seconds a step, and a command zeroed on the default 2 s would end the run as
#: a failure instead of measuring it.
PROCESS_STEP_TIMEOUT = 60.0
#: The world's start timeout in the ``processes`` layout [s] (discovery of ~100 processes).
PROCESS_START_TIMEOUT = 300.0


def discovery_range(layout: str, n: int) -> str:
    """Return the ROS_AUTOMATIC_DISCOVERY_RANGE of a run of ``layout`` at ``n`` agents."""
    if DISCOVERY[0] != 'auto':
        return DISCOVERY[0]
    return 'SUBNET' if layout == 'processes' and n > LOCALHOST_PROCESS_AGENTS else 'LOCALHOST'


def _env(layout: str, n: int) -> dict:
    # Across processes as swarm --processes sets it up (the large-swarm DDS profile from 200
    # agents on), so that floors and pipeline move their messages over the same transport.
    env = process_environment(0 if layout == 'one' else n, DOMAIN,
                              {k: v for k, v in os.environ.items()
                               if k != 'ROS_AUTOMATIC_DISCOVERY_RANGE'})
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = discovery_range(layout, n)
    return env


def floor(layout: str, n: int, steps: int, raw: bool = False, c: bool = False) -> dict:
    """Return the floor's steps/s and re-offered steps for a layout (``raw``: serialised
    bytes, see :class:`Wire`; ``c``: moved by the compiled extension)."""
    me = [sys.executable, str(Path(__file__).resolve()), '--n', str(n), '--steps', str(steps),
          '--domain', str(DOMAIN)] + (['--raw'] if raw else []) + (['--c'] if c else [])
    env = _env(layout, n)
    if layout == 'one':
        out = subprocess.run(me + ['--role', 'one', '--hosts', '1'], capture_output=True,
                             text=True, timeout=RUN_TIMEOUT, env=env)
        return last_json(out.stdout)
    hosts = [['--agent-ids'] + [str(i) for i in range(n)]] if layout == 'container' else [
        ['--agent-ids', str(i)] for i in range(n)]
    procs = [subprocess.Popen(me + ['--role', 'leader'], env=env)]
    procs += [subprocess.Popen(me + ['--role', 'agents'] + ids, env=env) for ids in hosts]
    try:
        out = subprocess.run(me + ['--role', 'world', '--hosts', str(len(hosts))],
                             stdout=subprocess.PIPE, text=True, timeout=RUN_TIMEOUT, env=env)
    finally:
        stop(procs, timeout=20)
    return last_json(out.stdout)


def last_json(stdout: str) -> dict:
    """Return the last JSON line a floor world printed (Fast DDS logs to stdout too)."""
    for line in reversed(stdout.splitlines()):
        if line.startswith('{'):
            return json.loads(line)
    raise RuntimeError('the floor world printed no result')


def swarm_command(layout: str, n: int, steps: int, out: Path, record: bool,
                  transport: str = 'per_agent') -> list[str]:
    """Return the ``swarm`` command of a pipeline run (``transport``: ``swarm --transport``)."""
    cmd = [sys.executable, '-m', 'flock_swarm.cli.swarm', 'demo', '--out', str(out), '--no-plots',
           '--domain-id', str(DOMAIN), '--transport', transport]
    for item in scenario_overrides(n, steps):
        cmd += ['--set', item]
    if layout == 'container':
        # Three processes matching 4 N endpoints: at N = 1000 on two shared cores the run
        # spent 22 s outside its steps (docs/performance.md), close to the default 30 s.
        cmd += ['--processes', '--container', '--start-timeout', str(PROCESS_START_TIMEOUT)]
    elif layout == 'processes':
        cmd += ['--processes', '--step-timeout', str(PROCESS_STEP_TIMEOUT),
                '--start-timeout', str(PROCESS_START_TIMEOUT)]
    if not record:
        cmd.append('--no-record')
    return cmd


def wait_bounded(proc: subprocess.Popen, timeout: float):
    """Wait for ``proc`` at most ``timeout`` s; return its resource usage, or ``None``.

    ``None``: it was still running and has been stopped (SIGINT, so that the world closes
    its outputs, then the runner's own teardown; SIGKILL after 30 s).
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return usage
        time.sleep(0.2)
    stop([proc], timeout=30)
    return None


def pipeline(layout: str, n: int, steps: int, record: bool, transport: str = 'per_agent') -> dict:
    """Run the pipeline once; return steps/s, real-time factor, microseconds per agent-step,
    the seconds outside the steps (start-up and teardown) and the child's peak RSS."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'run'
        launched = time.monotonic()
        proc = subprocess.Popen(swarm_command(layout, n, steps, out, record, transport),
                                env=_env(layout, n), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        usage = wait_bounded(proc, RUN_TIMEOUT)
        elapsed = time.monotonic() - launched
        if usage is None:
            raise RuntimeError(f'{layout} N={n}: did not finish within {RUN_TIMEOUT:g} s '
                               '(stopped)')
        summary_path = out / 'summary.json'
        if not summary_path.is_file():
            raise RuntimeError(f'{layout} N={n}: swarm exited {proc.returncode} without a '
                               'summary')
        summary = json.loads(summary_path.read_text())
    if summary['status'] != 'completed' or summary['missed_commands']:
        raise RuntimeError(f'{layout} N={n}: {summary["status"]}, '
                           f'{summary["missed_commands"]} missed commands')
    rate = summary['steps'] / summary['wall_time_s']
    return {'steps_per_s': rate, 'rtf': rate * summary['dt'],
            'us_per_agent_step': 1e6 / (rate * n),
            # Launch to the first step (imports, entity creation, discovery, matching) plus
            # the teardown after the last: the process's life outside the world's steps.
            'outside_steps_s': elapsed - summary['wall_time_s'],
            'resent_steps': summary['resent_steps'],
            'peak_rss_mib': usage.ru_maxrss / 1024.0}


def sim_rate(n: int, steps: int) -> dict:
    """Run ``sim`` once on the pipeline's scenario (no figures); return its steps/s (from its
    summary's ``wall_time_s``: the steps alone) and microseconds per agent-step."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, '-m', 'flock_swarm.cli.sim', 'demo', '--out',
               str(Path(tmp) / 'sim'), '-q']
        for item in scenario_overrides(n, steps):
            cmd += ['--set', item]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, timeout=RUN_TIMEOUT)
        summary = json.loads((Path(tmp) / 'sim' / 'summary.json').read_text())
    rate = summary['steps'] / summary['wall_time_s']
    return {'steps_per_s': rate, 'us_per_agent_step': 1e6 / (rate * n)}


def batched_rows(layouts: list[str], sizes: list[int], steps: int,
                 repeat: int) -> tuple[list[dict], list[dict]]:
    """Run the batched transport (``swarm --transport batched``, recording on and off) and
    ``sim`` at each N, interleaved, best of ``repeat``; print and return the rows and the
    failed ones. ``sim`` is the limit: the same scenario without ROS."""
    rows, failed = [], []
    print(f'{"batched":>10} {"N":>5} {"sim":>8} {"pipeline":>9} {"/ sim":>6} {"no-rec":>7} '
          f'{"RTF":>6} {"us/a-st":>8} {"sim us":>7} {"outside":>8} {"RSS MiB":>8}  '
          '[steps/s; us per agent-step, s outside the steps]', flush=True)
    for layout in [name for name in layouts if name != 'processes']:
        for n in sizes:
            sims, fulls, bares = [], [], []
            try:
                for _ in range(repeat):
                    sims.append(sim_rate(n, steps))
                    fulls.append(pipeline(layout, n, steps, record=True, transport='batched'))
                    bares.append(pipeline(layout, n, steps, record=False, transport='batched'))
            except (RuntimeError, subprocess.SubprocessError, ValueError) as exc:
                failed.append({'layout': layout, 'n': n, 'transport': 'batched',
                               'error': str(exc), 'pipeline_runs': rates(fulls)})
                print(f'{"batched " + layout:>10} {n:>5} failed: {exc}', flush=True)
                continue
            best = max(sims, key=lambda r: r['steps_per_s'])
            full = max(fulls, key=lambda r: r['steps_per_s'])
            bare = max(bares, key=lambda r: r['steps_per_s'])
            row = {'layout': layout, 'n': n, 'steps': steps, 'transport': 'batched',
                   'sim': best['steps_per_s'], 'sim_runs': rates(sims),
                   'sim_us_per_agent_step': best['us_per_agent_step'],
                   'pipeline': full['steps_per_s'], 'pipeline_runs': rates(fulls),
                   'no_record': bare['steps_per_s'], 'no_record_runs': rates(bares),
                   'ratio_to_sim': full['steps_per_s'] / best['steps_per_s'],
                   'rtf': full['rtf'], 'us_per_agent_step': full['us_per_agent_step'],
                   'outside_steps_s': full['outside_steps_s'],
                   'resent_steps': [r['resent_steps'] for r in fulls],
                   'peak_rss_mib': full['peak_rss_mib']}
            rows.append(row)
            print(f'{layout:>10} {n:>5} {row["sim"]:8.1f} {row["pipeline"]:9.1f} '
                  f'{row["ratio_to_sim"]:6.2f} {row["no_record"]:7.1f} {row["rtf"]:6.2f} '
                  f'{row["us_per_agent_step"]:8.1f} {row["sim_us_per_agent_step"]:7.1f} '
                  f'{row["outside_steps_s"]:8.1f} {row["peak_rss_mib"]:8.0f}', flush=True)
    return rows, failed


def batched_checks(rows: list[dict]) -> list[tuple[str, bool]]:
    """Return issue 41's targets over the batched rows."""
    checks = [(f'batched {r["layout"]} N=1000: >= 200 steps/s with recording '
               f'({r["pipeline"]:.1f})', r['pipeline'] >= 200) for r in rows if r['n'] == 1000]
    checks += [(f'batched {r["layout"]} N=1000: >= 0.3 of sim ({r["ratio_to_sim"]:.2f})',
                r['ratio_to_sim'] >= 0.3) for r in rows if r['n'] == 1000]
    checks += [(f'batched {r["layout"]} N=10000: >= 50 steps/s ({r["pipeline"]:.1f})',
                r['pipeline'] >= 50) for r in rows if r['n'] == 10000]
    for layout in {r['layout'] for r in rows}:
        by_n = {r['n']: r for r in rows if r['layout'] == layout}
        if 1000 in by_n and 10000 in by_n:
            growth = by_n[10000]['us_per_agent_step'] / by_n[1000]['us_per_agent_step']
            checks.append((f'batched {layout}: cost per agent-step at N=10000 within 1.3x that '
                           f'at N=1000 ({growth:.2f}x)', growth <= 1.3))
    return checks


def rates(runs: list[dict]) -> list[float]:
    """Return the steps/s of each run."""
    return [r['steps_per_s'] for r in runs]


def machine() -> dict:
    """Return a description of this machine."""
    cpu = ''
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                cpu = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    return {'cpus': os.cpu_count(), 'cpu_model': cpu, 'python': platform.python_version(),
            'platform': platform.platform(), 'load_average': os.getloadavg()}


def growth_checks(rows: list[dict], layouts: list[str], n: int,
                  bound: float) -> list[tuple[str, bool]]:
    """Return, for each layout measured at N = 100 and ``n``, whether the cost per
    agent-step at ``n`` is within ``bound`` times that at N = 100."""
    checks = []
    for layout in layouts:
        by_n = {r['n']: r for r in rows if r['layout'] == layout}
        if 100 in by_n and n in by_n:
            growth = by_n[n]['us_per_agent_step'] / by_n[100]['us_per_agent_step']
            checks.append((f'{layout}: cost per agent-step at N={n} within {bound:g}x that at '
                           f'N=100 ({growth:.2f}x)', growth <= bound))
    return checks


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (or one floor process with ``--role``)."""
    # Started in the background from a script, SIGINT would be ignored here and in every
    # process started (their teardown then waits out stop()'s timeout on each).
    accept_sigint()
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[5, 10, 20, 50, 100])
    parser.add_argument('--layouts', nargs='+', default=['one', 'container', 'processes'],
                        choices=['one', 'container', 'processes'])
    parser.add_argument('--steps', type=int, default=300, help='steps per run')
    parser.add_argument('--repeat', type=int, default=3,
                        help='interleaved runs of each variant; the best counts')
    parser.add_argument('--max-process-agents', type=int, default=100,
                        help='largest N run in the one-process-per-agent layout')
    parser.add_argument('--memory', action='store_true',
                        help='also compare peak RSS of S and 10 S steps (one process, the '
                        'first of --transports)')
    parser.add_argument('--memory-n', type=int, default=30,
                        help='agents of the memory runs (default: 30)')
    parser.add_argument('--json', type=Path, help='write the results here')
    parser.add_argument('--transports', nargs='+', default=['per_agent'],
                        choices=['per_agent', 'batched'],
                        help="the transports measured (batched: 'one' and 'container' layouts, "
                        "beside sim's steps/s at the same N)")
    parser.add_argument('--discovery', default='auto', choices=['auto', 'LOCALHOST', 'SUBNET'],
                        help='ROS_AUTOMATIC_DISCOVERY_RANGE of the runs (default auto: '
                        f'LOCALHOST, SUBNET for the processes layout beyond '
                        f'{LOCALHOST_PROCESS_AGENTS} agents)')
    parser.add_argument('--role', choices=['one', 'world', 'leader', 'agents'],
                        help=argparse.SUPPRESS)
    parser.add_argument('--n', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--hosts', type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument('--agent-ids', type=int, nargs='+', help=argparse.SUPPRESS)
    parser.add_argument('--domain', type=int, default=DOMAIN, help=argparse.SUPPRESS)
    parser.add_argument('--raw', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--c', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role is not None:
        return run_floor_role(args)
    DISCOVERY[0] = args.discovery
    print(f'# bench_ros: {" ".join(sys.argv)}', flush=True)
    info = machine()
    print(f'# machine: {info}', flush=True)
    rows, failed = [], []
    from flock_swarm.nodes.batch import use_c_path, why_not_built
    with_c = use_c_path()
    if not with_c:
        print(f'# no C floor: the pipeline runs on pure rclpy ({why_not_built() or ENV_RCLPY})',
              flush=True)
    if 'per_agent' in args.transports:
        print(f'{"layout":>10} {"N":>4} {"floor":>8} {"raw fl.":>8} {"C fl.":>8} {"pipeline":>9} '
              f'{"ratio":>6} {"raw r.":>6} {"C r.":>6} {"no-rec":>7} {"rec cost":>8} {"RTF":>6} '
              f'{"us/a-st":>8} {"outside":>8} {"RSS MiB":>8}  '
              '[steps/s; us per agent-step, s outside the steps]',
              flush=True)
    for layout in args.layouts if 'per_agent' in args.transports else []:
        for n in args.sizes:
            if layout == 'processes' and n > args.max_process_agents:
                continue
            steps = args.steps if layout != 'processes' else max(50, args.steps * 10 // n)
            # Interleaved repeats, best of each: the run least disturbed by whatever else the
            # shared machine was doing.
            fls, raws, cs, fulls, bares = [], [], [], [], []
            try:
                for _ in range(args.repeat):
                    fls.append(floor(layout, n, steps))
                    raws.append(floor(layout, n, steps, raw=True))
                    if with_c:
                        cs.append(floor(layout, n, steps, c=True))
                    fulls.append(pipeline(layout, n, steps, record=True))
                    bares.append(pipeline(layout, n, steps, record=False))
            except (RuntimeError, subprocess.TimeoutExpired, ValueError) as exc:
                # Kept as a failed row (the other rows still count and are written).
                failed.append({'layout': layout, 'n': n, 'steps': steps,
                               'discovery': discovery_range(layout, n), 'error': str(exc),
                               'floor_runs': rates(fls), 'raw_floor_runs': rates(raws),
                               'c_floor_runs': rates(cs),
                               'pipeline_runs': rates(fulls)})
                print(f'{layout:>10} {n:>4} failed: {exc}', flush=True)
                continue
            fl, raw = max(rates(fls)), max(rates(raws))
            c_fl = max(rates(cs)) if cs else math.nan
            full = max(fulls, key=lambda r: r['steps_per_s'])
            bare = max(bares, key=lambda r: r['steps_per_s'])
            row = {'layout': layout, 'n': n, 'steps': steps, 'floor': fl, 'raw_floor': raw,
                   'discovery': discovery_range(layout, n),
                   'c_floor': c_fl, 'c_path': with_c,
                   'floor_runs': rates(fls), 'raw_floor_runs': rates(raws),
                   'c_floor_runs': rates(cs),
                   'pipeline_runs': rates(fulls), 'no_record_runs': rates(bares),
                   # Steps offered again (stalled: see WorldStepper.resent), per run.
                   'resent_steps': {name: [r['resent_steps'] for r in runs] for name, runs in
                                    (('floor', fls), ('raw_floor', raws), ('c_floor', cs),
                                     ('pipeline', fulls), ('no_record', bares))},
                   'pipeline': full['steps_per_s'], 'rtf': full['rtf'],
                   'us_per_agent_step': full['us_per_agent_step'],
                   'floor_us_per_agent_step': 1e6 / (fl * n),
                   'raw_floor_us_per_agent_step': 1e6 / (raw * n),
                   'outside_steps_s': full['outside_steps_s'],
                   'peak_rss_mib': full['peak_rss_mib'],
                   'no_record': bare['steps_per_s'],
                   'ratio': full['steps_per_s'] / fl, 'raw_ratio': full['steps_per_s'] / raw,
                   'c_ratio': full['steps_per_s'] / c_fl,
                   'recording_cost': 1.0 - full['steps_per_s'] / bare['steps_per_s']}
            rows.append(row)
            print(f'{layout:>10} {n:>4} {fl:8.1f} {raw:8.1f} {c_fl:8.1f} {row["pipeline"]:9.1f} '
                  f'{row["ratio"]:6.2f} {row["raw_ratio"]:6.2f} {row["c_ratio"]:6.2f} '
                  f'{row["no_record"]:7.1f} '
                  f'{100 * row["recording_cost"]:7.1f}% {row["rtf"]:6.2f} '
                  f'{row["us_per_agent_step"]:8.1f} {row["outside_steps_s"]:8.1f} '
                  f'{row["peak_rss_mib"]:8.0f}', flush=True)
    checks = [(f'{r["layout"]} N={r["n"]}: pipeline >= 70% of the floor', r['ratio'] >= 0.7)
              for r in rows]
    checks += [(f'{r["layout"]} N={r["n"]}: pipeline >= 70% of the raw-bytes floor',
                r['raw_ratio'] >= 0.7) for r in rows]
    checks += [(f'{r["layout"]} N={r["n"]}: recording costs <= 10%',
                r['recording_cost'] <= 0.10) for r in rows]
    checks += [(f'one N=100: >= 20 steps/s ({r["pipeline"]:.1f})', r['pipeline'] >= 20)
               for r in rows if r['layout'] == 'one' and r['n'] == 100]
    # Issue 17: the cost of an agent-step may not grow much with N.
    checks += growth_checks(rows, args.layouts, 1000, 1.5)
    checks += [(f'{r["layout"]} N=1000: >= 25 steps/s with recording ({r["pipeline"]:.1f})',
                r['pipeline'] >= 25) for r in rows if r['n'] == 1000]
    # Issue 28 (the compiled message path).
    checks += [(f'{r["layout"]} N={r["n"]}: pipeline >= 70% of the C floor '
                f'({r["c_ratio"]:.2f})', r['c_ratio'] >= 0.7)
               for r in rows if r['n'] in (100, 1000) and with_c]
    checks += [(f'one N=100: >= 500 steps/s ({r["pipeline"]:.1f})', r['pipeline'] >= 500)
               for r in rows if r['layout'] == 'one' and r['n'] == 100]
    checks += [(f'{r["layout"]} N=1000: >= 50 steps/s with recording, real time at dt = 0.02 '
                f'({r["pipeline"]:.1f})', r['pipeline'] >= 50)
               for r in rows if r['n'] == 1000]
    checks += growth_checks(rows, args.layouts, 2000, 1.3)
    if 'batched' in args.transports:
        batched, failed_batched = batched_rows(args.layouts, args.sizes, args.steps, args.repeat)
        rows += batched
        failed += failed_batched
        checks += batched_checks(batched)
    checks += [(f'{r["layout"]} N={r["n"]}: measured ({r["error"]})', False) for r in failed]
    memory = None
    if args.memory:
        # The first transport asked for (per_agent unless only batched is measured).
        transport = args.transports[0]
        short = pipeline('one', args.memory_n, args.steps, record=True, transport=transport)
        long = pipeline('one', args.memory_n, 10 * args.steps, record=True,
                        transport=transport)
        memory = {'n': args.memory_n, 'steps': args.steps, 'short_mib': short['peak_rss_mib'],
                  'long_mib': long['peak_rss_mib'], 'transport': transport,
                  'ratio': long['peak_rss_mib'] / short['peak_rss_mib']}
        print(f'memory (one process, {transport}, N = {args.memory_n}): {args.steps} steps '
              f'{short["peak_rss_mib"]:.0f} '
              f'MiB, {10 * args.steps} steps {long["peak_rss_mib"]:.0f} MiB peak RSS: '
              f'{memory["ratio"]:.3f}x', flush=True)
        checks.append((f'{transport}: 10x longer run peaks < 1.2x memory',
                       memory['ratio'] < 1.2))
    for name, ok in checks:
        print(f'{"PASS" if ok else "FAIL"}  {name}', flush=True)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'command': ' '.join(sys.argv), 'machine': info,
                                         'rows': rows, 'failed': failed, 'memory': memory,
                                         'checks': checks}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
