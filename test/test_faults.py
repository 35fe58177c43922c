"""Faults: lost agents, a lost leader, killed processes, full disks and faulty messages.

Every case runs the real nodes on real DDS (each test its own domain id): in one process
(:class:`flock_swarm.nodes.swarm_runner.InProcessSwarm`, where a test can remove and restart
nodes) or as the ``ros2 run`` executables in their own processes.
"""

import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from numpy.testing import assert_allclose, assert_array_equal
from rclpy.node import Node

from flock_swarm.cli.analyze import main as analyze_main
from flock_swarm.nodes import stepper as world_module
from flock_swarm.bag import BagReader
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.laws.evaluation import swarm_control
from flock_swarm.core.scenario import parse_scenario, realize
from flock_swarm.nodes.agent import AgentNode
from flock_swarm.contract import LOCKSTEP_QOS, qos_profile
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.stepper import LatencyHistogram
from flock_swarm.nodes.wire import decode_odometry
from flock_swarm.nodes.swarm_runner import InProcessSwarm, executable, resolve_scenario
from flock_swarm.nodes.supervisor import stop
from flock_swarm.core.run import interaction_graph, simulate, static_graph
from flock_swarm.testing import wait_for
from broken_law import nan_command_for
from conftest import small_filesystem, start_nodes
from ros_messages import make_accel, make_odometry

pytestmark = pytest.mark.ros

#: Wall-clock bound of one run (a hung run fails instead of blocking the suite).
RUN_TIMEOUT = 120.0


def scenario_of(tmp_path, overrides, preset='demo'):
    """Resolve a scenario into ``tmp_path/run``; return ``(path, scenario, out)``."""
    out = tmp_path / 'run'
    path = resolve_scenario(preset, overrides, None, out)
    return path, parse_scenario(yaml.safe_load(path.read_text())), out


# ----------------------------------------------------------------------------------------------
# Faulty messages never reach a command


#: Serialised bytes that decode as nothing: a CDR header, then a string without its NUL.
MALFORMED = b'\x00\x01\x00\x00' + bytes(8) + b'\x40\x00\x00\x00garbage'


class FaultyPublisher(Node):
    """Publishes, every 10 ms, one faulty message of each kind on the swarm's topics."""

    def __init__(self, world, **kwargs) -> None:
        """Create the node; ``world`` tells it the current step."""
        super().__init__('faulty', **kwargs)
        self.world = world
        self.clock = world.clock
        qos = qos_profile(LOCKSTEP_QOS)
        self.odom = self.create_publisher(Odometry, 'agent_0/odom', qos)
        self.leader = self.create_publisher(Odometry, 'leader/odom', qos)
        self.cmd = self.create_publisher(AccelStamped, 'agent_1/cmd_accel', qos)
        self.sent = 0
        self.create_timer(0.01, self.publish_faults)

    def publish_faults(self) -> None:
        """Send one message per fault, stamped around the world's current step."""
        k = self.world.k
        good_q, good_p = [1.0, 2.0], [0.1, 0.2]
        now, old = self.clock.stamp(k), self.clock.stamp(max(k - 5, 0))
        off_grid = self.clock.stamp(k)
        off_grid.nanosec += 1
        faults = [
            make_odometry([math.nan, 0.0], good_p, now, 'agent_0'),
            make_odometry([1e9, 0.0], good_p, now, 'agent_0'),
            make_odometry(good_q, [math.inf, 0.0], now, 'agent_0'),
            make_odometry(good_q, good_p, now, 'agent_7'),
            make_odometry(good_q, good_p, off_grid, 'agent_0'),
        ]
        wrong_frame = make_odometry(good_q, good_p, now, 'agent_0')
        wrong_frame.header.frame_id = 'map'
        faults.append(wrong_frame)
        if k >= 6:
            faults.append(make_odometry(good_q, good_p, old, 'agent_0'))
        # Well-formed but stamped far beyond the run: it must not make the genuine
        # odometry that follows look stale (it once stalled every agent).
        faults.append(make_odometry(good_q, good_p, self.clock.stamp(k + 10_000), 'agent_0'))
        for msg in faults:
            self.odom.publish(msg)
        self.leader.publish(make_odometry([math.nan, 0.0], good_p, now, 'leader'))
        self.leader.publish(make_odometry(good_q, good_p, now, 'agent_0'))
        self.cmd.publish(make_accel([math.nan, 0.0], now))
        self.cmd.publish(make_accel([1e12, 0.0], now))
        self.cmd.publish(make_accel([0.5, 0.5], self.clock.stamp(k + 3)))
        # Bytes that are no message at all (a foreign or corrupted writer).
        for pub in (self.odom, self.leader, self.cmd):
            pub.publish(MALFORMED)
        self.sent += 1


def test_faulty_messages_are_rejected_counted_and_harmless(tmp_path, ros_domain, capfd):
    path, sc, out = scenario_of(tmp_path, ['n_agents=4', 'informed.count=2', 'duration=2',
                                           'record_every=1'])
    # The faulty node publishes agent 1's commands, so the world counts it as a host of
    # agents that never subscribes to the odometry: it starts after its start timeout.
    with InProcessSwarm(path, out, domain_id=ros_domain,
                        world_params={'start_timeout': 3.0}) as swarm:
        faulty = swarm.add(FaultyPublisher(swarm.world, context=swarm.context))
        swarm.spin_to_end(RUN_TIMEOUT)
        assert faulty.sent > 20
        agent_rejections = swarm.agents.guard.counts()
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    # Nothing faulty reached a command: the run is the simulator's run.
    ref = simulate(sc).series
    with np.load(out / 'timeseries.npz') as ros:
        for name in ('q', 'p', 'u'):
            assert_allclose(ros[name], ref[name], rtol=0, atol=1e-9, err_msg=name)
    for kind in ('non_finite', 'magnitude', 'frame', 'off_grid_stamp', 'stale_stamp',
                 'malformed'):
        assert agent_rejections.get(kind, 0) > 0, (kind, agent_rejections)
    world_rejections = summary['rejected_messages']
    for kind in ('non_finite', 'magnitude', 'frame', 'future', 'malformed'):
        assert world_rejections.get(kind, 0) > 0, (kind, world_rejections)
    # The faulty messages were recorded as received (nothing received is lost).
    counts = BagReader(out / 'bag').message_counts()
    assert counts['/agent_1/cmd_accel'] > sc.steps + 1
    # ... and analyze reads the bag past the ones that decode as nothing, saying so.
    assert analyze_main([str(out / 'bag'), '--out', str(tmp_path / 'analysis'),
                         '--no-anim']) == 0
    assert 'do not decode' in capfd.readouterr().err


def test_duplicate_agent_id_is_reported(tmp_path, ros_domain):
    path, sc, out = scenario_of(tmp_path, ['n_agents=3', 'informed.count=1', 'duration=1000'])
    with InProcessSwarm(path, out, domain_id=ros_domain,
                        world_params={'record': False}) as swarm:
        twin = swarm.add_agents([1], 'agent_1')
        # Claims are checked once a second by every node.
        swarm.spin_until(lambda: twin.duplicates and swarm.agents.duplicates
                         and swarm.world.duplicates, RUN_TIMEOUT)
        assert twin.duplicates == {1} and swarm.agents.duplicates == {1}
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['duplicate_agent_ids'] == [1]


def test_non_finite_command_is_published_as_zero(tmp_path, ros_domain, monkeypatch, capfd):
    """A law that returns NaN for agent 1 at every step, the agents run with
    ``non_finite:=zero``: the agent node publishes a zero command for it (counted, logged
    once) instead of one the world would reject, so the world misses no command and records
    agent 1's input as zero."""
    nan_command_for(monkeypatch, 1)
    path, sc, out = scenario_of(tmp_path, ['n_agents=4', 'informed.count=2', 'duration=0.5',
                                           'record_every=1'])
    with InProcessSwarm(path, out, domain_id=ros_domain,
                        agent_params={'non_finite': 'zero'}) as swarm:
        swarm.spin_to_end(RUN_TIMEOUT)
        counts = dict(swarm.agents.controller.non_finite)
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    assert 'non_finite' not in summary['rejected_messages']
    assert counts == {1: sc.steps + 1}
    with np.load(out / 'timeseries.npz') as ros:
        assert_array_equal(ros['u'][:, 1], np.zeros((sc.steps + 1, sc.dim)))
        assert np.abs(ros['u'][:, 0]).max() > 0
    assert capfd.readouterr().err.count('agent 1: the law gave a non-finite command') == 1


# ----------------------------------------------------------------------------------------------
# The leader disappears and comes back


def test_late_leader_is_waited_for_at_the_start(tmp_path, ros_domain):
    """A leader that answers its first tick later than leader_timeout (slow discovery) is
    waited for: the informed agents track it from step 0, the run is sim's run. (Once
    failed in CI: two informed agents applied the uninformed law at step 0.)"""
    path, sc, out = scenario_of(tmp_path, ['n_agents=4', 'informed.count=2', 'duration=0.5',
                                           'record_every=1'])
    with InProcessSwarm(path, out, domain_id=ros_domain, step_timeout=10.0,
                        agent_params={'leader_timeout': 0.2}) as swarm:
        swarm.remove(swarm.leader)
        # The world opens step 0; the agents have its odometry but no leader state.
        swarm.spin_until(lambda: swarm.agents.controller.pending.get(0) is not None
                         and swarm.agents.controller.pending[0].has_odometry(4), RUN_TIMEOUT)
        t0 = time.monotonic()
        swarm.spin_until(lambda: time.monotonic() - t0 > 0.6, RUN_TIMEOUT)
        assert swarm.agents.controller.answered == -1 and not swarm.agents.leader_lost
        swarm.leader = swarm.add_leader()
        swarm.spin_to_end(RUN_TIMEOUT)
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    assert summary['leader_events'] == []
    ref = simulate(sc).series
    with np.load(out / 'timeseries.npz') as ros:
        assert_allclose(ros['q'], ref['q'], rtol=0, atol=1e-9)


def test_stalled_step_is_offered_again_with_backoff(tmp_path, ros_domain):
    """A step left open is offered again after RESEND_PERIOD (or RESEND_SLOWER times the
    step before, if longer), then after twice as long each time: an overloaded swarm is not
    flooded with copies (50 agent processes once ran at 0.5 steps/s, 3 offers a step)."""
    overrides = ['n_agents=3', 'informed.count=1', 'duration=10', 'record_every=1']
    path, _, out = scenario_of(tmp_path, overrides)
    with InProcessSwarm(path, out, domain_id=ros_domain, step_timeout=30.0) as swarm:
        world = swarm.world.stepper
        swarm.spin_until(lambda: world.k >= 5, RUN_TIMEOUT)
        swarm.remove(swarm.agents)
        # The step in progress may still close (its commands were in); the next one stalls.
        offers, stalled = [], None
        while len(offers) < 3:
            count = world.resends
            swarm.spin_until(lambda: world.resends > count, RUN_TIMEOUT)
            if stalled is None:
                stalled, began, first_wait = world.k, world.step_began, max(
                    world_module.RESEND_PERIOD, world_module.RESEND_SLOWER * world.last_step_s)
            # When the world offered the step (it sets resend_at = then + resend_wait).
            offers.append(world.resend_at - world.resend_wait)
        assert world.k == stalled, 'no command came, so the step must still be open'
    # Timers fire late, never early: each offer is at least its wait after the last one.
    assert offers[0] - began >= first_wait
    assert offers[1] - offers[0] >= 2.0 * first_wait
    assert offers[2] - offers[1] >= 4.0 * first_wait


class LosesOffers(AgentNode):
    """An agent node that loses the first ``offers`` copies of each odometry message of step
    ``step`` (DDS drops a sample that reaches a reader not matched yet)."""

    def __init__(self, step: int, offers: int, **kwargs) -> None:
        """Create the node; the other arguments are :class:`AgentNode`'s."""
        super().__init__(**kwargs)
        self.step, self.offers = step, offers
        self.lost = [0] * self.scenario.n_agents

    def on_odom(self, j: int, data: bytes) -> None:
        """Drop the message if it is one of the lost ones; handle it otherwise."""
        if self.clock.step_at(decode_odometry(data)[0]) == self.step \
                and self.lost[j] < self.offers:
            self.lost[j] += 1
            return
        super().on_odom(j, data)


def run_losing_offers(tmp_path, ros_domain, step: int, offers: int) -> tuple[dict, list]:
    """Run 3 agents (agent 0 in a :class:`LosesOffers` node) with a 0.3 s step timeout,
    below RESEND_PERIOD; return the summary and how many copies agent 0 lost per topic."""
    path, _, out = scenario_of(tmp_path, ['n_agents=3', 'informed.count=1', 'duration=0.5',
                                          'record_every=1'])
    with InProcessSwarm(path, out, domain_id=ros_domain, step_timeout=0.3, agents=[1, 2],
                        world_params={'start_timeout': 10.0}) as swarm:
        lossy = swarm.add(LosesOffers(step, offers, node_name='agent_0',
                                      context=swarm.context,
                                      parameter_overrides=swarm.parameters(agent_ids=[0])))
        swarm.spin_to_end(RUN_TIMEOUT)
    return json.loads((out / 'summary.json').read_text()), lossy.lost


def test_step_is_offered_again_within_a_short_step_timeout(tmp_path, ros_domain):
    """With a step timeout (0.3 s) below RESEND_PERIOD a step is still offered again
    before its commands are zeroed (after half the timeout): an agent that lost the first
    offer of step 3 answers the second. (It was never offered again.)"""
    summary, lost = run_losing_offers(tmp_path, ros_domain, step=3, offers=1)
    assert lost == [1, 1, 1]
    assert summary['status'] == 'completed'
    assert summary['missed_commands'] == 0 and summary['resent_steps'] >= 1


def test_step_zero_waits_out_the_start_timeout(tmp_path, ros_domain):
    """Step 0 completes the start: an agent whose readers match the world's writers late
    (it loses 6 offers of step 0, 0.15 s apart: 3 step timeouts) still answers step 0,
    which is offered again until start_timeout (10 s here) is over. (Reproducing a CI
    failure on a loaded machine once zeroed steps 0-7 of every agent.)"""
    summary, lost = run_losing_offers(tmp_path, ros_domain, step=0, offers=6)
    assert lost == [6, 6, 6]
    assert summary['status'] == 'completed'
    assert summary['missed_commands'] == 0 and summary['leader_missed'] == 0


def test_lost_leader_fallback_and_return(tmp_path, ros_domain):
    path, sc, out = scenario_of(tmp_path, ['n_agents=5', 'informed.count=2', 'duration=20',
                                           'record_every=1', 'protocol.name=su_informed'])
    with InProcessSwarm(path, out, domain_id=ros_domain, step_timeout=1.0,
                        agent_params={'leader_timeout': 0.2}) as swarm:
        swarm.spin_until(lambda: swarm.world.k >= 50, RUN_TIMEOUT)
        swarm.remove(swarm.leader)
        swarm.spin_until(lambda: swarm.world.leader_lost and swarm.world.k >= 150, RUN_TIMEOUT)
        swarm.leader = swarm.add_leader()
        swarm.spin_to_end(RUN_TIMEOUT)
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    (lost_at, lost), (back_at, back) = summary['leader_events']
    assert (lost, back) == ('lost', 'back') and 50 <= lost_at < 150 <= back_at < sc.steps
    real = realize(sc)
    static = static_graph(sc, real)
    with np.load(out / 'timeseries.npz') as ros:
        q, p, u = ros['q'], ros['p'], ros['u']
        leader = [LeaderState(ros['leader_q'][s], ros['leader_p'][s], ros['leader_a'][s])
                  for s in range(q.shape[0])]
        for s in (lost_at + 2, back_at - 2):
            # While it is lost, every agent applies the uninformed law.
            edges = interaction_graph(sc, real, q[s], static)
            assert_allclose(u[s], swarm_control(sc.law, q[s], p[s], edges, None, real.agents,
                                                sc.dt), rtol=0, atol=1e-9)
        for s in (back_at + 2, sc.steps):
            # Back: the informed agents track the (caught-up) leader again.
            edges = interaction_graph(sc, real, q[s], static)
            assert_allclose(u[s], swarm_control(sc.law, q[s], p[s], edges, leader[s],
                                                real.agents, sc.dt), rtol=0, atol=1e-9)
    # The restarted leader caught up with the clock: its state is the model's at t_k.
    ref = simulate(sc).series
    with np.load(out / 'timeseries.npz') as ros:
        assert_allclose(ros['leader_q'][-1], ref['leader_q'][-1], rtol=0, atol=1e-9)
    # Both transitions are in the bag's /swarm/metrics.
    states = []
    for _, msg in BagReader(out / 'bag').decoded(['/swarm/metrics']):
        values = {kv.key: kv.value for kv in msg.status[0].values}
        states.append((int(values['step']), values['leader']))
    assert (lost_at, 'lost') in states and (back_at, 'ok') in states


# ----------------------------------------------------------------------------------------------
# A lost agent: lockstep (zero after the step timeout), realtime (held, then zero), restart


class Lines:
    """Collects a process's stderr lines in a thread (so waits can look for one)."""

    def __init__(self, stream) -> None:
        """Start reading ``stream``."""
        self.lines: list[str] = []
        self.thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self.thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line)

    def has(self, text: str) -> bool:
        """Return whether some line contains ``text``."""
        return any(text in line for line in list(self.lines))

    def max_step(self) -> int:
        """Return the latest step a progress line reported (``-1`` before the first)."""
        steps = [int(m.group(1)) for line in list(self.lines)
                 for m in [re.search(r' step (\d+)/', line)] if m]
        return max(steps, default=-1)


def test_killed_agent_process_is_zeroed_then_rejoins(tmp_path, ros_domain):
    """SIGKILL to an agent process: its commands are zeroed until it restarts, the others'
    never. The step timeout (5 s) stays well above the stalls of DDS itself when a
    participant dies or joins (up to 2 s measured on a loaded 2-core machine, docs/ros.md
    "Faults"): with 0.3 s, CI runs zeroed commands of the other agents. DDS runs over UDP
    only: with Fast DDS's shared memory a restarted process once stayed deaf for the rest of
    a run (the Fast DDS restart problem docs/ros.md names), which is not what this tests."""
    path, sc, out = scenario_of(tmp_path, ['n_agents=3', 'informed.count=1', 'duration=60'])
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain), FASTDDS_BUILTIN_TRANSPORTS='UDPv4')
    ros_args = ['--ros-args', '-p', f'scenario:={path}']
    logs = []

    def agent(i):
        logs.append(tmp_path / f'agent_{i}_{len(logs)}.log')
        with logs[-1].open('w') as err:
            return subprocess.Popen(executable('agent') + ros_args + ['-p', f'agent_id:={i}'],
                                    env=env, stdout=subprocess.DEVNULL, stderr=err)

    procs = [subprocess.Popen(executable('leader') + ros_args, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    agents = [agent(i) for i in range(3)]
    world = subprocess.Popen(executable('world') + ros_args + [
        '-p', f'out_dir:={out}', '-p', 'step_timeout:=5.0'], env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    log = Lines(world.stderr)
    restarted = None
    try:
        wait_for(lambda: log.max_step() >= 100, 60, 'the world to pass step 100')
        agents[1].kill()
        agents[1].wait()
        wait_for(lambda: log.has('no command from agent(s) [1]'), 30,
                 'the world to miss agent 1')
        restarted = agent(1)
        try:
            world.wait(timeout=RUN_TIMEOUT)
        except subprocess.TimeoutExpired:
            pytest.fail(f'the world did not finish in {RUN_TIMEOUT:g} s; it logged\n'
                        + ''.join(log.lines[-5:]) + 'and the restarted agent\n'
                        + logs[-1].read_text()[-2000:])
    finally:
        stop(procs + agents + [world] + ([restarted] if restarted else []), timeout=20)
    assert world.returncode == 0, ''.join(log.lines[-20:])
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed'
    missed = summary['missed_commands_per_agent']
    warnings = [line for line in log.lines if '[WARN]' in line or '[ERROR]' in line]
    assert missed[0] == missed[2] == 0 and 0 < missed[1] < sc.steps // 2, ''.join(warnings)
    # Every missed step is in the log; the restarted agent answered the last step.
    clock = StepClock(sc.dt)
    stamps = [clock.step_of(msg.header.stamp)
              for _, msg in BagReader(out / 'bag').decoded(['/agent_1/cmd_accel'])]
    assert stamps[-1] == sc.steps
    assert len(set(stamps)) >= sc.steps + 1 - missed[1]


def test_realtime_lost_agent_is_held_then_zeroed(tmp_path, ros_domain):
    """Realtime: agents gone at step 60 (1.2 s): their last commands held for about the
    staleness, then zero to the end (4 s: 125 zero steps or so; it was 6 s of real time)."""
    path, sc, out = scenario_of(tmp_path, ['n_agents=3', 'informed.count=1', 'duration=4',
                                           'record_every=1', 'dt=0.02'])
    with InProcessSwarm(path, out, mode='realtime', domain_id=ros_domain,
                        world_params={'staleness': 0.3}) as swarm:
        swarm.spin_until(lambda: swarm.world.k >= 60, RUN_TIMEOUT)
        killed_at = swarm.world.k
        swarm.remove(swarm.agents)
        swarm.spin_to_end(RUN_TIMEOUT)
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed'
    with np.load(out / 'timeseries.npz') as ros:
        u = ros['u']
    assert np.abs(u[killed_at - 5]).sum() > 0
    zero = np.flatnonzero(np.abs(u).sum(axis=(1, 2)) == 0)
    first_zero = zero[zero > killed_at][0]
    # Held for about the staleness (0.3 s = 15 steps at real time), then zero to the end.
    assert 5 <= first_zero - killed_at <= 40
    # (Commands already in flight when the node went may still land in the first steps.)
    held = u[killed_at + 2:first_zero]
    assert_array_equal(held, np.broadcast_to(held[0], held.shape))
    assert (np.abs(u[first_zero:]).sum(axis=(1, 2)) == 0).all()
    latency = summary['command_latency_ms']
    assert latency['count'] > 100 and 0 < latency['p50'] <= latency['p99'] <= latency['max']
    stale_steps = sc.steps + 1 - first_zero
    for missed in summary['missed_commands_per_agent']:
        # Plus the steps at the start before the first command arrived.
        assert stale_steps <= missed <= stale_steps + 25


def test_latency_histogram_percentiles():
    rng = np.random.default_rng(5)
    samples = rng.lognormal(np.log(2e-3), 0.8, 20_000)
    hist = LatencyHistogram()
    for x in samples:
        hist.add(float(x))
    got = hist.summary_ms()
    assert got['count'] == samples.size and got['max'] == round(1e3 * samples.max(), 3)
    for name, q in (('p50', 50), ('p90', 90), ('p99', 99)):
        exact = 1e3 * np.percentile(samples, q)
        # Read off bin edges 2.3 % apart.
        assert exact <= got[name] <= exact * 1.024, name


# ----------------------------------------------------------------------------------------------
# Killed or starved recorder


def test_sigkilled_world_bag_is_recovered_by_analyze(tmp_path, ros_domain, capsys):
    path, sc, out = scenario_of(tmp_path, ['n_agents=2', 'informed.count=1', 'duration=1000'])
    procs, world = start_nodes(path, ros_domain, out, 2)
    mcap = out / 'bag' / 'bag_0.mcap'
    try:
        wait_for(lambda: mcap.is_file() and mcap.stat().st_size > 300_000, 120,
                 'the world to record a few chunks')
        world.send_signal(signal.SIGKILL)
        world.wait(timeout=30)
    finally:
        stop(procs + [world])
    assert not (out / 'bag' / 'metadata.yaml').exists()
    assert analyze_main([str(out / 'bag'), '--out', str(tmp_path / 'recovered'),
                         '--no-anim']) == 0
    err = capsys.readouterr().err
    assert 'bag_0.mcap was not closed (no summary or footer): read ' in err
    assert ' complete chunks' in err
    summary = json.loads((tmp_path / 'recovered' / 'summary.json').read_text())
    assert summary['status'] == 'truncated' and summary['complete_steps'] > 100
    # All but at most one chunk (1 MiB uncompressed) of the recorded steps are recovered.
    per_step = 2 * 716 + 2 * 68 + 716 + 68 + 20
    counts = BagReader(out / 'bag').message_counts()
    assert counts['/agent_0/odom'] >= summary['complete_steps']
    assert summary['complete_steps'] * per_step > mcap.stat().st_size


@pytest.fixture
def small_disk(tmp_path):
    """A 256 KiB tmpfs (as root); skip with the reason where it cannot be mounted."""
    with small_filesystem(tmp_path / 'small', '256k') as where:
        yield where


def test_full_disk_stops_cleanly_and_keeps_the_bag(tmp_path, small_disk, ros_domain):
    path = resolve_scenario('demo', ['n_agents=4', 'informed.count=2', 'duration=2000'], None,
                            tmp_path / 'scenario')
    sc = parse_scenario(yaml.safe_load(path.read_text()))
    out = small_disk / 'run'
    with InProcessSwarm(path, out, domain_id=ros_domain) as swarm:
        swarm.spin_to_end(RUN_TIMEOUT)
        world = swarm.world
        assert world.status == 'recording_failed'
        assert 'No space left on device' in world.bag_error
        assert 0 < world.k < sc.steps
    assert not (out / 'bag' / 'metadata.yaml').exists()
    reader = BagReader(out / 'bag')
    assert reader.recovered
    assert reader.message_counts()['/agent_0/odom'] > 10


def test_full_disk_under_the_time_series_keeps_it_in_memory(tmp_path, small_disk, ros_domain,
                                                            capfd):
    """The world's spooled time series fills the disk (no bag): the run goes on, the series
    falls back to memory with one warning, and its every instant equals sim's."""
    path = resolve_scenario('demo', ['n_agents=4', 'informed.count=2', 'duration=24',
                                     'record_every=1'], None, tmp_path / 'scenario')
    sc = parse_scenario(yaml.safe_load(path.read_text()))
    with InProcessSwarm(path, small_disk / 'run', domain_id=ros_domain,
                        world_params={'record': False}) as swarm:
        swarm.spin_until(lambda: swarm.world.done, RUN_TIMEOUT)
        world = swarm.world
        assert world.status == 'completed'
        series = world.result.series
    # About 300 bytes an instant: the 256 KiB disk fills well before the 1201st instant.
    assert world.spool.error is not None and 'No space left on device' in world.spool.error
    assert capfd.readouterr().err.count('keeping it in memory') == 1
    reference = simulate(sc).series
    assert series['t'].shape == reference['t'].shape == (sc.steps + 1,)
    for name in ('t', 'q', 'p', 'u', 'leader_q', 'leader_p', 'informed'):
        assert_allclose(series[name], reference[name], rtol=0, atol=1e-9, err_msg=name)


def test_stop_kills_processes_that_ignore_sigint_on_one_deadline():
    """``stop`` gives every process the same deadline: five stubborn processes are killed
    after ``timeout`` in all (one ``timeout`` each would take five times as long)."""
    code = ('import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); '
            'print("up", flush=True); time.sleep(120)')
    procs = [subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True)
             for _ in range(5)]
    try:
        assert [p.stdout.readline() for p in procs] == ['up\n'] * 5
        began = time.monotonic()
        stop(procs, timeout=1.0)
        elapsed = time.monotonic() - began
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()
            p.stdout.close()
    assert [p.returncode for p in procs] == [-signal.SIGKILL] * 5
    assert elapsed < 4.0


def test_step_zero_is_offered_at_a_steady_period():
    """Before any step has finished, a stalled step is a reader not yet matched, not an
    overloaded swarm: it is offered every RESEND_PERIOD (four offers inside the 2 s default
    step timeout), and the doubling begins once a step duration is known. The first offer
    again comes after at most half the step timeout."""
    wait = world_module.first_resend_wait(0.0)
    assert wait == world_module.RESEND_PERIOD
    assert world_module.next_resend_wait(wait, 0.0) == wait
    assert world_module.next_resend_wait(wait, 0.01) == 2.0 * wait
    assert world_module.first_resend_wait(1.0) == world_module.RESEND_SLOWER * 1.0
    assert world_module.first_resend_wait(0.0, step_timeout=2.0) == world_module.RESEND_PERIOD
    assert world_module.first_resend_wait(0.0, step_timeout=0.3) == 0.15
    assert world_module.first_resend_wait(1.0, step_timeout=2.0) == 1.0
