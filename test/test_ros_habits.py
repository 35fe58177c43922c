"""What ROS users do by habit (issue 24, item 4): ``use_sim_time``, a waiting world that says
who it waits for, a second world on the same domain, parameters that read back the values in
use."""

import json

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
    they slowed from ~500 to ~22 steps/s), and the run is ``sim``'s, bit for bit."""
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
