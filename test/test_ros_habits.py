"""What ROS users do by habit (issue 24, item 4): ``use_sim_time``, a waiting world that says
who it waits for, a second world on the same domain, parameters that read back the values in
use; issue 38: byte-reproducible bags, the world's end logged under ``ros2 run``."""

import json
import signal
import subprocess
import time

import pytest

from flock_swarm.core.run import simulate
from flock_swarm.outputs import json_text
from flock_swarm.testing import SIM_ONLY, Swarm, compare_runs

pytestmark = pytest.mark.ros

RUN_TIMEOUT = 240.0
SMALL = ['n_agents=3', 'informed.count=1', 'duration=0.3', 'record_every=1']


def steady(node) -> bool:
    """Return whether every timer of ``node`` runs on the steady clock."""
    from rclpy.clock import ClockType
    return bool(node.timers) and all(t.clock.clock_type == ClockType.STEADY_TIME
                                     for t in node.timers)


def test_the_world_refuses_use_sim_time_with_one_line(tmp_path, ros_domain, monkeypatch,
                                                      capfd):
    """The world publishes ``/clock``: following it, it never started and logged nothing."""
    from flock_swarm.nodes.world import main
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    status = main(['world', '--ros-args', '-p', 'use_sim_time:=true', '-p',
                   f'out_dir:={tmp_path / "out"}'])
    out, err = capfd.readouterr()
    assert status == 2 and out == ''
    assert err == ('world: error: use_sim_time: must be false: the world publishes /clock '
                   'itself (it is the simulation clock); the leader and the agents accept '
                   'either value\n')


def test_a_use_sim_time_of_the_wrong_type_is_one_line(tmp_path, ros_domain, monkeypatch,
                                                      capfd):
    """rclpy logs a line of its own first (while it creates the node) and carries on with
    wall time: the node refuses to."""
    from flock_swarm.nodes.leader import main
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    status = main(['leader', '--ros-args', '-p', 'use_sim_time:=1'])
    _, err = capfd.readouterr()
    assert status == 2
    assert err.endswith('\nleader: error: use_sim_time: expected true or false, got 1\n')


def test_leader_and_agents_run_at_full_speed_under_use_sim_time(tmp_path, ros_domain):
    """Their ROS clock follows ``/clock``, their timers the steady clock (on the ROS clock
    they slowed from ~500 to ~22 steps/s), and the run is ``sim``'s, bit for bit;
    ``expect_subscribers`` reads back the number waited for."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.leader import LeaderNode
    with Swarm('demo', tmp_path / 'run', SMALL, domain_id=ros_domain,
               agent_params={'use_sim_time': True}) as swarm:
        swarm.remove(swarm.leader)
        leader = swarm.add(LeaderNode(context=swarm.context, parameter_overrides=swarm.parameters(
            expect_subscribers=2, use_sim_time=True)))
        for node in (leader, swarm.agents):
            assert node.get_clock().ros_time_is_active
            assert steady(node)
            assert node.get_parameter('use_sim_time').value is True
        assert steady(swarm.world) and not swarm.world.get_clock().ros_time_is_active
        # Given as -1, expect_subscribers reads back the number waited for once known.
        assert swarm.world.get_parameter('expect_subscribers').value == -1
        swarm.spin_until(lambda: swarm.world.k >= 1, RUN_TIMEOUT, 'the first step')
        assert swarm.world.get_parameter('expect_subscribers').value == 1  # the container
        swarm.spin_until(lambda: leader.matched, RUN_TIMEOUT, 'the leader to start')
        assert leader.get_parameter('expect_subscribers').value == 2  # the world, the container
        assert not leader.set_parameters([Parameter('expect_subscribers', value=5)])[0].successful
        run = swarm.run(RUN_TIMEOUT)
    summary = run.summary
    assert summary['status'] == 'completed' and not summary['missed_commands']
    ref = simulate(run.scenario)
    want = {k: v for k, v in json.loads(json_text(ref.summary)).items() if k not in SIM_ONLY}
    assert compare_runs(want, ref.series, summary, run.timeseries(), 0.0) == []


@pytest.mark.parametrize('kind', ['world', 'leader', 'agent'])
def test_use_sim_time_is_read_only(kind, tmp_path, ros_context):
    """``ros2 param set NODE use_sim_time true`` is refused with a reason, not "successful"
    while nothing follows the new clock."""
    import importlib

    from rclpy.parameter import Parameter
    module = importlib.import_module(f'flock_swarm.nodes.{kind}')
    cls = {'world': 'WorldNode', 'leader': 'LeaderNode', 'agent': 'AgentNode'}[kind]
    params = [Parameter('scenario', value='demo')]
    if kind == 'world':
        params.append(Parameter('out_dir', value=str(tmp_path / 'out')))
    node = getattr(module, cls)(context=ros_context, parameter_overrides=params)
    try:
        descriptor = node.describe_parameter('use_sim_time')
        assert descriptor.read_only and descriptor.description
        result, = node.set_parameters([Parameter('use_sim_time', value=True)])
        assert not result.successful and 'read-only' in result.reason
        assert node.get_parameter('use_sim_time').value is False
        assert not node.get_clock().ros_time_is_active
    finally:
        close = getattr(node, 'close', None)
        if close is not None:
            close()
        node.destroy_node()


def test_id_list_names_agents_in_ranges():
    from flock_swarm.nodes.world import id_list
    assert id_list([3]) == 'agent 3'
    assert id_list([0, 1, 2, 5, 7, 8]) == 'agents 0-2, 5, 7-8'


def test_a_waiting_world_says_who_is_missing(tmp_path, ros_context, capfd):
    """Every few seconds (WAIT_LOG_EVERY) a line names the agents, the leader and the
    subscribers the start waits for; it logged nothing before."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes import world as world_module
    assert 2.0 <= world_module.WAIT_LOG_EVERY <= 10.0
    world = world_module.WorldNode(context=ros_context, parameter_overrides=[
        Parameter('scenario', value='demo'), Parameter('n_agents', value=4),
        Parameter('informed.count', value=1), Parameter('out_dir', value=str(tmp_path / 'o'))])
    try:
        assert not world.ready_to_start()  # just created: no line yet
        world.wait_logged -= world_module.WAIT_LOG_EVERY
        assert not world.ready_to_start()
        assert not world.ready_to_start()  # one line per period
    finally:
        world.close()
        world.destroy_node()
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if '[world]: waiting ' in line]
    assert len(lines) == 1, err
    assert lines[0].endswith(
        's for agents 0-3 (nobody publishes their cmd_accel); 1 subscriber(s) of the odometry '
        'of agents 0-3; the leader (nobody publishes /leader/odom); a subscriber of /clock '
        '(the leader)'), lines[0]


def test_a_second_world_on_the_domain_is_refused_with_one_line(tmp_path, ros_domain,
                                                               monkeypatch, capfd):
    """A world that finds another world (or a replay) on its domain before its start refuses
    (a by-hand run mixed silently with another before). The first world may refuse too if it
    sees the second before the second has gone; a world that has started does not look."""
    from flock_swarm.nodes.swarm_runner import executable
    from flock_swarm.nodes.supervisor import stop
    from flock_swarm.nodes.world import main
    from conftest import subprocess_env
    env = subprocess_env(ROS_DOMAIN_ID=str(ros_domain))
    args = ['--ros-args', '-p', 'scenario:=demo', '-p', 'start_timeout:=60.0']
    first = subprocess.Popen(executable('world') + args + ['-p', f'out_dir:={tmp_path / "a"}'],
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
        status = main(['world'] + args + ['-p', f'out_dir:={tmp_path / "b"}'])
        out, err = capfd.readouterr()
    finally:
        stop([first])
    assert status == 2 and out == ''
    assert err.endswith(f'world: error: ROS_DOMAIN_ID: another world or a replay publishes '
                        f'/clock or /swarm/status on domain {ros_domain} (nodes: /world): '
                        'give each run a domain of its own\n'), err
    # Before that line, at most the lines of a wait (if discovery took 5 s).
    assert all('waiting' in line for line in err.splitlines()[:-1]), err


def test_an_in_process_swarm_beside_another_world_is_refused(tmp_path, ros_domain):
    """The swarm runner (``swarm``) raises the world's refusal (``swarm`` prints it as one line);
    here the swarm waits for an absent agent, so it meets the other world before its
    start."""
    from flock_swarm.core.errors import ScenarioError
    from flock_swarm.nodes.swarm_runner import executable, run_in_process
    from flock_swarm.nodes.supervisor import stop
    from conftest import subprocess_env
    env = subprocess_env(ROS_DOMAIN_ID=str(ros_domain))
    first = subprocess.Popen(executable('world') + [
        '--ros-args', '-p', 'scenario:=demo', '-p', 'start_timeout:=60.0', '-p',
        f'out_dir:={tmp_path / "a"}'], env=env, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    try:
        with pytest.raises(ScenarioError) as err:
            run_in_process('demo', tmp_path / 'b', domain_id=ros_domain, agents=[0],
                           world_params={'start_timeout': 60.0}, timeout=RUN_TIMEOUT)
    finally:
        stop([first])
    assert str(err.value) == (f'ROS_DOMAIN_ID: another world or a replay publishes /clock or '
                              f'/swarm/status on domain {ros_domain} (nodes: /world): give '
                              'each run a domain of its own')
    assert not (tmp_path / 'b' / 'summary.json').exists()
    assert not (tmp_path / 'b' / 'bag').exists()  # the same --out can be used again


#: A short lockstep run with obstacles: its bag holds the latched obstacle map (a
#: MarkerArray) and /swarm/metrics (DiagnosticArrays), both padded in CDR.
BYTES_RUN = ['n_agents=4', 'informed.count=2', 'duration=1',
             'obstacles={spheres: [{centre: [30, 30], radius: 3}], '
             'walls: [{point: [0, -2], normal: [0, 1]}]}']


def test_identical_lockstep_runs_write_byte_identical_bags(tmp_path, ros_domain):
    """Issue 38: two identical runs differed in 200 of 201 ``/swarm/metrics`` messages, only
    in CDR alignment padding (rclpy leaves it uninitialised). Every file of the two bag
    directories (the MCAP and ``metadata.yaml``) is now the same, byte for byte: a bag
    records no wall time, so nothing is excluded."""
    from conftest import subprocess_env
    bags = []
    for name in ('a', 'b'):
        out = tmp_path / name
        run = subprocess.run(
            ['swarm', 'demo', *[a for s in BYTES_RUN for a in ('--set', s)], '--no-plots',
             '--out', str(out), '--domain-id', str(ros_domain)],
            env=subprocess_env(), capture_output=True, text=True, timeout=RUN_TIMEOUT)
        assert run.returncode == 0, run.stderr
        bags.append(out / 'bag')
    files = sorted(p.name for p in bags[0].iterdir())
    assert files == sorted(p.name for p in bags[1].iterdir()) == ['bag_0.mcap',
                                                                  'metadata.yaml']
    for name in files:
        assert (bags[0] / name).read_bytes() == (bags[1] / name).read_bytes(), name


@pytest.mark.parametrize('stop', [None, signal.SIGINT])
def test_the_world_logs_its_end_once_under_ros2_run(tmp_path, ros_domain, stop):
    """Issue 38: a world started by hand (``ros2 run``) logged nothing at its end, not even
    after SIGINT, and its progress lines read ``[world]: [world] t = ...``. It now ends its
    log with how the run ended and the files written (as ``swarm`` prints them), completed
    or interrupted, and names itself once per line."""
    import os
    import re

    from test_node_stops import SMALL, reap, start_all
    from flock_swarm.nodes.swarm_runner import resolve_scenario
    from flock_swarm.testing import wait_for
    out = tmp_path / 'run'
    duration = 'duration=2' if stop is None else 'duration=1000'
    scenario = resolve_scenario('demo', SMALL + [duration], None, out)
    procs = start_all(scenario, out, dict(os.environ, ROS_DOMAIN_ID=str(ros_domain)),
                      tmp_path, agents=2)
    world, log = procs[-1], tmp_path / 'node3.log'
    try:
        if stop is not None:
            # Its first progress line comes after two seconds of stepping.
            wait_for(lambda: '[world]: t = ' in log.read_text(), RUN_TIMEOUT,
                     "the world's progress line")
            world.send_signal(stop)
        statuses = [proc.wait(timeout=RUN_TIMEOUT) for proc in procs]
    finally:
        reap(procs)
    assert statuses == [0, 0, 0, 0 if stop is None else 130], statuses
    text = log.read_text()
    assert '[world] ' not in text, text
    if stop is not None:
        assert re.search(r'\[INFO\] \[[\d.]+\] \[world\]: t = [\d.]+/1000 s  step ', text)
    lines = text.splitlines()
    status = 'completed' if stop is None else 'interrupted'
    level = 'INFO' if stop is None else 'WARN'
    assert re.fullmatch(rf'\[{level}\] \[[\d.]+\] \[world\]: {status} at t = [\d.]+ s: eta = '
                        r'.*, collisions = 0, missed commands = 0 \([\d.]+ s wall\)',
                        lines[-2]), lines[-2:]
    assert re.fullmatch(rf'\[INFO\] \[[\d.]+\] \[world\]: wrote {re.escape(str(out / "bag"))}, '
                        rf'{re.escape(str(out / "timeseries.npz"))}, '
                        rf'{re.escape(str(out / "summary.json"))}', lines[-1]), lines[-1]


def test_the_metrics_reach_slash_diagnostics(tmp_path, ros_domain):
    """Issue 38: ``/swarm/metrics`` was a DiagnosticArray on a topic of its own, so
    rqt_robot_monitor and diagnostic_aggregator (which read ``/diagnostics``) saw nothing.
    A subscriber of ``/diagnostics`` (reliable, as those tools subscribe) now gets every
    metrics message of the run, the bytes the bag holds on ``/swarm/metrics``."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile
    from rclpy.serialization import deserialize_message

    from flock_swarm.contract import DIAGNOSTICS, METRICS_STATUS
    received = []
    with Swarm('demo', tmp_path / 'run', SMALL, domain_id=ros_domain) as swarm:
        probe = swarm.add(rclpy.create_node('diagnostics_probe', context=swarm.context))
        probe.create_subscription(DiagnosticArray, DIAGNOSTICS, received.append,
                                  QoSProfile(depth=1000), raw=True)
        swarm.spin_until(lambda: swarm.world.telemetry.diagnostics_pub
                         .get_subscription_count() >= 1, RUN_TIMEOUT, 'the probe to match')
        swarm.spin_to_end(RUN_TIMEOUT)
        recorded = [m.data for m in swarm.result().bag().messages('/swarm/metrics')]
        deadline = time.monotonic() + RUN_TIMEOUT
        while len(received) < len(recorded) and time.monotonic() < deadline:
            swarm.executor.spin_once(timeout_sec=0.1)
    assert len(recorded) > 1 and received == recorded
    assert deserialize_message(received[0], DiagnosticArray).status[0].name == METRICS_STATUS


def test_an_obstacle_run_draws_its_figures_without_matplotlib_warnings(tmp_path):
    """Issue 38: ``sim --plots`` of a scenario with obstacles printed matplotlib's "Ignoring
    fixed x limits to fulfill fixed data aspect with adjustable data limits." twice (the
    figure's limits are fixed around the paths, its aspect was adjusted on the data)."""
    from conftest import subprocess_env
    run = subprocess.run(
        ['sim', 'demo', '--set', BYTES_RUN[-1], '--set', 'duration=2', '--plots', '--out',
         str(tmp_path / 'run')], env=subprocess_env(), capture_output=True, text=True,
        timeout=RUN_TIMEOUT)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / 'run' / 'trajectories.png').is_file()
    assert [line for line in run.stderr.splitlines() if not line.startswith('[sim] ')] == []
