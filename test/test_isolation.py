"""Isolation: a publisher on another ROS domain cannot move the swarm; on the same one it can.

An intruder (its own ``rclpy.Context``) forges every input of the lockstep loop (each
agent's ``cmd_accel`` and ``odom``, the leader's ``odom`` and ``accel``, ``/clock``), stamped
with the step the world is on, as fast as the run goes. On another domain the recorded run is
bit for bit the run without it; on the run's own domain, impersonating an absent agent, it
steers that agent with every command it sends (so the first result is not vacuous).

The multi-host case runs the world and the rest of the swarm in two network namespaces joined
by a veth pair: DDS crosses the link only with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``.
"""

import json
import os
import re
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from flock_swarm.core.scenario import parse_scenario
from flock_swarm.scenario_yaml import parse_yaml
from flock_swarm.nodes.swarm_runner import (InProcessSwarm, executable, resolve_scenario,
                                            run_in_process)

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parent.parent
#: A small, fast lockstep run: three agents, one informed, ten steps, every step recorded.
OVERRIDES = ['n_agents=3', 'informed.count=1', 'duration=0.2', 'record_every=1']
#: Wall-clock bound of one run (a run that hangs fails instead of blocking CI).
RUN_TIMEOUT = 60.0
#: The forged command, position and velocity; z carries a mark (the scenario is planar).
FORGED_ACCEL = (3.0, -3.0, 7.0)
FORGED_POSITION = (50.0, -50.0, 7.0)
FORGED_VELOCITY = (5.0, 5.0, 7.0)
#: The series a lockstep run records; the isolated run must reproduce each bit for bit.
SERIES = ('t', 'q', 'p', 'u', 'leader_q', 'leader_p', 'leader_a', 'informed')


class Intruder:
    """A node of its own context on ``domain`` forging the swarm's messages.

    :param domain: its ROS domain id.
    :param n_agents: the swarm's size (one forged command and odometry per agent).
    :param dt: the scenario's step (the forged stamps are the world's).
    :param impersonate: answer every ``agent_<i>/odom`` of these agents with a forged command
        stamped like it, as agent ``i`` would (it then subscribes to every odometry topic, as
        an agent host does).
    """

    def __init__(self, domain: int, n_agents: int, dt: float, impersonate=()) -> None:
        """Create the context, the node, its publishers and subscriptions."""
        import rclpy
        from geometry_msgs.msg import AccelStamped
        from nav_msgs.msg import Odometry
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock

        from flock_swarm import contract
        from flock_swarm.contract import CLOCK, LEADER_ACCEL, LEADER_ODOM, cmd_topic, odom_topic
        from flock_swarm.nodes.clock import StepClock
        CLOCK_QOS, LOCKSTEP_QOS = (contract.qos_profile(q) for q in (contract.CLOCK_QOS,
                                                                     contract.LOCKSTEP_QOS))
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node('intruder', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.clock = StepClock(dt)
        pub, sub = self.node.create_publisher, self.node.create_subscription
        self.forged = self.answered = 0
        #: Forged commands heard back on the intruder's own domain (its messages do flow).
        self.heard = 0
        sub(AccelStamped, cmd_topic(0), self._hear, LOCKSTEP_QOS)
        if impersonate:
            # Exactly what an agent host has: its agents' command topics, every odometry.
            self.cmd = {i: pub(AccelStamped, cmd_topic(i), LOCKSTEP_QOS) for i in impersonate}
            for i in range(n_agents):
                sub(Odometry, odom_topic(i), lambda msg, i=i: self._answer(i, msg),
                    LOCKSTEP_QOS)
            return
        self.cmd = {i: pub(AccelStamped, cmd_topic(i), LOCKSTEP_QOS) for i in range(n_agents)}
        self.odom = [pub(Odometry, odom_topic(i), LOCKSTEP_QOS) for i in range(n_agents)]
        self.leader_odom = pub(Odometry, LEADER_ODOM, LOCKSTEP_QOS)
        self.leader_accel = pub(AccelStamped, LEADER_ACCEL, LOCKSTEP_QOS)
        self.clock_pub = pub(Clock, CLOCK, CLOCK_QOS)

    def _hear(self, msg) -> None:
        if msg.accel.linear.z == FORGED_ACCEL[2]:
            self.heard += 1

    def _answer(self, i: int, msg) -> None:
        if i in self.cmd:
            self.cmd[i].publish(self.accel(msg.header.stamp))
            self.answered += 1

    def accel(self, stamp):
        """Return the forged command with ``stamp``."""
        from geometry_msgs.msg import AccelStamped
        msg = AccelStamped()
        msg.header.stamp, msg.header.frame_id = stamp, 'world'
        lin = msg.accel.linear
        lin.x, lin.y, lin.z = FORGED_ACCEL
        return msg

    def odometry(self, stamp, child: str):
        """Return a forged odometry with ``stamp`` for ``child``."""
        from nav_msgs.msg import Odometry
        msg = Odometry()
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = stamp, 'world', child
        pos, vel = msg.pose.pose.position, msg.twist.twist.linear
        pos.x, pos.y, pos.z = FORGED_POSITION
        vel.x, vel.y, vel.z = FORGED_VELOCITY
        return msg

    def forge(self, k: int) -> None:
        """Publish a forged input of every kind for step ``k`` (and ``/clock`` at ``k + 1``)."""
        from rosgraph_msgs.msg import Clock
        stamp = self.clock.stamp(k)
        for i, odom in enumerate(self.odom):
            self.cmd[i].publish(self.accel(stamp))
            odom.publish(self.odometry(stamp, f'agent_{i}'))
        self.leader_odom.publish(self.odometry(stamp, 'leader'))
        self.leader_accel.publish(self.accel(stamp))
        self.clock_pub.publish(Clock(clock=self.clock.stamp(k + 1)))
        self.forged += 1

    def spin(self) -> None:
        """Handle what has arrived (answers and echoes), without waiting."""
        self.executor.spin_once(timeout_sec=0.0)

    def close(self) -> None:
        """Destroy the node and the context."""
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def scenario_file(tmp_path: Path) -> Path:
    """Return the resolved small scenario."""
    return resolve_scenario('demo', OVERRIDES, None, tmp_path / 'scenario')


def series(out: Path) -> dict:
    """Return the recorded time series of a run."""
    with np.load(out / 'timeseries.npz') as data:
        return {name: data[name] for name in data.files}


def run_under_attack(scenario: Path, out: Path, domain: int, intruder: Intruder,
                     forge: bool, **swarm_args) -> dict:
    """Run the swarm on ``domain`` while the intruder forges (or answers) every step.

    :return: the summary.
    """
    with InProcessSwarm(scenario, out, domain_id=domain, world_params={'record': False},
                        **swarm_args) as swarm:
        deadline = time.monotonic() + RUN_TIMEOUT
        while not swarm.world.done:
            swarm.executor.spin_once(timeout_sec=0.005)
            if forge:
                intruder.forge(swarm.world.k)
            intruder.spin()
            if time.monotonic() > deadline:
                raise TimeoutError(f'the run did not finish within {RUN_TIMEOUT:g} s')
        swarm.world.close()
        return swarm.summary()


def test_discovery_is_limited_to_localhost_by_default():
    """Tests run with discovery on this machine only (scripts/env.sh, test/conftest.py)."""
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'


def test_the_demo_runs_on_a_domain_of_its_own(tmp_path, ros_domain):
    """scripts/demo: its default domain is neither 0 nor a test's; ROS_DOMAIN_ID overrides it.

    The run itself uses the test's domain (running on the demo's fixed default would meet a
    demo someone else runs on this machine); the default is read from the script.
    """
    script = ROOT / 'scripts' / 'demo'
    default = re.search(r'^export ROS_DOMAIN_ID="\$\{ROS_DOMAIN_ID:-(\d+)\}"$',
                        script.read_text(), re.MULTILINE)
    assert default, 'scripts/demo sets no default ROS_DOMAIN_ID'
    assert int(default[1]) not in range(0, 201), 'the demo would share a domain with a test'
    run = subprocess.run([str(script), str(tmp_path / 'demo'), '--set', 'duration=0.004',
                          '--no-plots'], env=dict(os.environ, ROS_DOMAIN_ID=str(ros_domain)),
                         capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert run.returncode == 0, run.stderr[-2000:]
    assert f'ROS_DOMAIN_ID={ros_domain}' in run.stderr
    assert json.loads((tmp_path / 'demo' / 'summary.json').read_text())['status'] == 'completed'


def test_a_publisher_on_another_domain_cannot_move_the_swarm(tmp_path, ros_domain,
                                                             other_ros_domain):
    """Forged inputs of every kind on another domain: the run is bit for bit the clean one."""
    scenario = scenario_file(tmp_path)
    sc = parse_scenario(parse_yaml(scenario.read_text()))
    clean = run_in_process(scenario, tmp_path / 'clean', domain_id=ros_domain,
                           timeout=RUN_TIMEOUT, world_params={'record': False})
    intruder = Intruder(other_ros_domain, sc.n_agents, sc.dt)
    try:
        attacked = run_under_attack(scenario, tmp_path / 'attacked', ros_domain, intruder,
                                    forge=True)
        # The intruder's messages do flow on its own domain: it is not a dud.
        deadline = time.monotonic() + 10.0
        while intruder.heard == 0 and time.monotonic() < deadline:
            intruder.forge(0)
            intruder.executor.spin_once(timeout_sec=0.05)
    finally:
        intruder.close()
    assert intruder.heard > 0, 'the intruder never heard its own forged commands'
    assert intruder.forged > sc.steps
    for summary in (clean, attacked):
        assert summary['status'] == 'completed'
        assert summary['missed_commands'] == 0 and summary['leader_missed'] == 0
    assert attacked['rejected_messages'] == clean['rejected_messages']
    want, got = series(tmp_path / 'clean'), series(tmp_path / 'attacked')
    for name in SERIES:
        assert_array_equal(got[name], want[name], err_msg=name)


def test_an_intruder_on_the_same_domain_steers_the_agent_it_impersonates(tmp_path,
                                                                         ros_domain):
    """The converse: on the run's domain, forged commands for an absent agent 0 are applied.

    The world cannot tell the intruder from agent 0: every step of agent 0 is integrated with
    the intruder's command, so its trajectory (and, through the interaction, every other
    agent's) leaves the clean run's. Without SROS2 access control this is what any process on
    the domain can do (docs/security.md).
    """
    scenario = scenario_file(tmp_path)
    sc = parse_scenario(parse_yaml(scenario.read_text()))
    clean = run_in_process(scenario, tmp_path / 'clean', domain_id=ros_domain,
                           timeout=RUN_TIMEOUT, world_params={'record': False})
    intruder = Intruder(ros_domain, sc.n_agents, sc.dt, impersonate=(0,))
    try:
        summary = run_under_attack(scenario, tmp_path / 'steered', ros_domain, intruder,
                                   forge=False, agents=range(1, sc.n_agents))
    finally:
        intruder.close()
    assert summary['status'] == 'completed'
    assert summary['missed_commands'] == 0, 'every step got agent 0 command from the intruder'
    assert intruder.answered >= sc.steps + 1
    got, want = series(tmp_path / 'steered'), series(tmp_path / 'clean')
    assert_array_equal(got['u'][:, 0], np.broadcast_to(FORGED_ACCEL[:2], got['u'][:, 0].shape))
    assert not np.array_equal(got['q'][-1], want['q'][-1])
    assert clean['status'] == 'completed'


# --------------------------------------------------------------------------------------------
# Two hosts on one machine: network namespaces and a veth pair

#: The /30 of the veth pair. It exists only inside the two namespaces the test creates (their
#: own network stacks, no route out), so no packet of the test ever leaves them.
WORLD_ADDRESS, SWARM_ADDRESS, PREFIX = '10.213.0.1', '10.213.0.2', 30
#: Bytes the world's end of the link must receive in the SUBNET run (DDS discovery and ten
#: steps of three agents move some 80 kB; the LOCALHOST run moves none).
LINK_BYTES = 10_000


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """Run ``ip ARGS``."""
    return subprocess.run(['ip', *args], capture_output=True, text=True, check=check,
                          timeout=20)


def netns_unavailable() -> str | None:
    """Return why network namespaces cannot be created here, or ``None`` if they can."""
    if os.geteuid() != 0:
        return 'network namespaces need root (ip netns add); running as uid ' \
            f'{os.geteuid()}'
    if shutil.which('ip') is None:
        return "no 'ip' command (iproute2) to create network namespaces"
    probe = f'flkprobe{uuid.uuid4().hex[:8]}'
    made = ip('netns', 'add', probe, check=False)
    if made.returncode != 0:
        return f'ip netns add failed: {made.stderr.strip() or made.returncode}'
    ip('netns', 'del', probe, check=False)
    return None


@pytest.fixture
def two_hosts():
    """Create namespaces ``world`` and ``swarm`` joined by a veth pair; remove them after.

    :return: ``{'world': (namespace, interface), 'swarm': (namespace, interface)}``.
    """
    reason = netns_unavailable()
    if reason is not None:
        pytest.skip(reason)
    tag = uuid.uuid4().hex[:8]
    hosts = {'world': (f'flkw{tag}', f'fw{tag}'), 'swarm': (f'flka{tag}', f'fa{tag}')}
    made = []
    try:
        for ns, _ in hosts.values():
            ip('netns', 'add', ns)
            made.append(ns)
        ip('link', 'add', hosts['world'][1], 'type', 'veth', 'peer', 'name', hosts['swarm'][1])
        for (ns, dev), address in ((hosts['world'], WORLD_ADDRESS),
                                   (hosts['swarm'], SWARM_ADDRESS)):
            ip('link', 'set', dev, 'netns', ns)
            ip('-n', ns, 'addr', 'add', f'{address}/{PREFIX}', 'dev', dev)
            ip('-n', ns, 'link', 'set', 'lo', 'up')
            ip('-n', ns, 'link', 'set', dev, 'up')
        yield hosts
    finally:
        for ns in made:
            # Our own processes only: nothing else runs in a namespace this fixture made.
            for pid in ip('netns', 'pids', ns, check=False).stdout.split():
                try:
                    os.kill(int(pid), 9)
                except ProcessLookupError:
                    pass
            ip('netns', 'del', ns, check=False)


def received_bytes(ns: str, dev: str) -> int:
    """Return the bytes interface ``dev`` of namespace ``ns`` has received."""
    stats = json.loads(ip('-n', ns, '-s', '-j', 'link', 'show', dev).stdout)
    return int(stats[0]['stats64']['rx']['bytes'])


def run_across(hosts: dict, scenario: Path, out: Path, domain: int, discovery: str,
               world_params: dict, agent_ids: tuple[str, ...] = ()) -> tuple[dict, int]:
    """Run the world in one namespace, the leader and the agents in the other.

    The world runs as ``world``, the agents in one ``agents`` process, or with ``agent_ids``
    one ``agents_<k>`` process per id range, as ``ros2 run`` would start them. Fast DDS keeps
    to UDP (no shared memory, which namespaces do not separate), so every message crosses
    the veth link or nothing does.

    :return: the world's summary and the bytes its end of the link received.
    """
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE=discovery,
               FASTDDS_BUILTIN_TRANSPORTS='UDPv4')
    (world_ns, world_if), swarm_ns = hosts['world'], hosts['swarm'][0]
    before = received_bytes(world_ns, world_if)

    def start(ns: str, name: str, params: dict, node: str = '') -> subprocess.Popen:
        args = [arg for k, v in dict(scenario=str(scenario), **params).items()
                for arg in ('-p', f'{k}:={v}')] + (['-r', f'__node:={node}'] if node else [])
        log = open(out.parent / f'{out.name}_{node or name}.log', 'w')
        with log:
            return subprocess.Popen(['ip', 'netns', 'exec', ns, *executable(name),
                                     '--ros-args', *args], env=env, stdout=log, stderr=log)

    out.parent.mkdir(parents=True, exist_ok=True)
    others = [start(swarm_ns, 'leader', {})]
    others += ([start(swarm_ns, 'agents', {'agent_ids': ids}, f'agents_{k}')
                for k, ids in enumerate(agent_ids)] or [start(swarm_ns, 'agents', {})])
    world = start(world_ns, 'world', dict(out_dir=str(out), **world_params))
    try:
        assert world.wait(timeout=RUN_TIMEOUT) == 0, (out.parent / f'{out.name}_world.log') \
            .read_text()[-2000:]
    finally:
        for proc in [world, *others]:
            if proc.poll() is None:
                proc.send_signal(2)
        for proc in [world, *others]:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    return json.loads((out / 'summary.json').read_text()), \
        received_bytes(world_ns, world_if) - before


def test_world_and_agents_in_separate_network_namespaces(tmp_path, ros_domain, two_hosts):
    """Two hosts on one machine: DDS over a veth link, every command on time.

    With ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` the world discovers the leader and the
    agents across the link (multicast discovery on the veth, no ``ROS_STATIC_PEERS``) and the
    run misses no command. With ``LOCALHOST`` (the project's default) nothing crosses: the
    world starts alone after its start timeout and every command is missing.
    """
    scenario = scenario_file(tmp_path)
    sc = parse_scenario(parse_yaml(scenario.read_text()))
    summary, link = run_across(two_hosts, scenario, tmp_path / 'subnet', ros_domain, 'SUBNET',
                               {'start_timeout': 20.0, 'record': False})
    assert summary['status'] == 'completed'
    assert summary['steps'] == sc.steps
    assert summary['missed_commands'] == 0 and summary['leader_missed'] == 0
    assert link > LINK_BYTES, f'only {link} bytes crossed the link'
    alone, link = run_across(two_hosts, scenario, tmp_path / 'localhost', ros_domain,
                             'LOCALHOST', {'start_timeout': 2.0, 'step_timeout': 0.1,
                                           'record': False})
    assert alone['missed_commands'] == sc.n_agents * (sc.steps + 1)
    assert link < LINK_BYTES / 10, f'{link} bytes crossed the link with LOCALHOST discovery'


def test_batched_hosts_by_id_ranges_across_namespaces_equal_sim(tmp_path, ros_domain,
                                                                two_hosts):
    """The batched transport across the veth link (issue 41, many hosts): the world alone in
    one namespace, the leader and three ``agents`` hosts by id ranges in the other, each
    taking the one state cloud and answering with one command cloud. The lockstep run equals
    ``sim`` bit for bit, and its traffic crossed the link."""
    from flock_swarm.analysis.compare import compare_runs
    from flock_swarm.bag import BagReader
    from flock_swarm.nodes.cloud import decode_cloud
    from flock_swarm.core.run import simulate
    from flock_swarm.nodes.swarm_runner import id_ranges
    from flock_swarm.outputs import json_text
    from flock_swarm.testing import SIM_ONLY

    scenario = resolve_scenario('demo', ['n_agents=6', 'informed.count=3', 'duration=0.2',
                                         'record_every=1', 'transport=batched',
                                         'initial.position_box=[[0, 6], [0, 6]]'],
                                None, tmp_path / 'scenario')
    sc = parse_scenario(parse_yaml(scenario.read_text()))
    ranges = tuple(id_ranges(sc.n_agents, 3))
    assert ranges == ('0-1', '2-3', '4-5')
    out = tmp_path / 'run'
    summary, link = run_across(two_hosts, scenario, out, ros_domain, 'SUBNET',
                               {'start_timeout': 20.0}, agent_ids=ranges)
    assert summary['status'] == 'completed'
    assert summary['missed_commands'] == 0 and summary['leader_missed'] == 0
    assert link > LINK_BYTES, f'only {link} bytes crossed the link'
    # The batched transport: a state cloud a step, and each step the command cloud of each
    # host, its id range (a step still open is offered again: its clouds may come twice).
    bag = BagReader(out / 'bag')
    assert not [topic for topic in bag.topics() if topic.startswith('/agent_')]
    assert bag.message_counts()['/swarm/states'] == sc.steps + 1
    clouds = {(m.log_time_ns, tuple(decode_cloud(bytes(m.data)).ids().tolist()))
              for m in bag.messages('/swarm/commands')}
    assert clouds == {(round(k * sc.dt * 1e9), ids) for k in range(sc.steps + 1)
                      for ids in ((0, 1), (2, 3), (4, 5))}
    ref = simulate(sc)
    want = {k: v for k, v in json.loads(json_text(ref.summary)).items() if k not in SIM_ONLY}
    problems = compare_runs(want, ref.series, summary, series(out), 0.0).problems
    assert not problems, '\n'.join(problems)
