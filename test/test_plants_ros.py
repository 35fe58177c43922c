"""Robot plants in ROS: a lockstep run equals sim bit for bit (velocity_lag, unicycle).

The world integrates the plant with the core's ``step``; the agents read the plant state off
the odometry (the unicycle's heading as its yaw quaternion) and convert the law's acceleration
with the core's ``command``, into a ``Twist`` on ``cmd_vel`` (or the world converts their
``cmd_accel``): the same arithmetic as ``sim``, so the series agree exactly. The runs through
``cmd_vel`` use the exact conversion (the default; the velocity lag's with an assumed lag
``conversion_tau`` off the true one), the unicycle commanded by acceleration the naive one.
"""

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from numpy.testing import assert_array_equal

from flock_swarm.testing import assert_matches_sim

#: A small demo swarm packed within each other's radius, a record every other step.
DEMO = ['n_agents=6', 'informed.count=3', 'duration=0.2', 'record_every=2',
        'initial.position_box=[[0, 6], [0, 6]]']
UNICYCLE = 'plant={model: unicycle, ell: 0.3, max_speed: 1.5, max_yaw_rate: 2.0, ' \
    'max_accel: 4.0}'
VELOCITY_LAG = 'plant={model: velocity_lag, tau: 0.15, max_speed: 1.5, max_accel: 5.0, ' \
    'conversion: exact, conversion_tau: 0.12}'
#: The layouts of a ROS run: keyword arguments of assert_matches_sim.
LAYOUTS = {'one process': {},
           'processes, container': {'processes': True, 'container': True}}
RUN_TIMEOUT = 240.0


@pytest.mark.ros
@pytest.mark.parametrize('layout', LAYOUTS)
@pytest.mark.parametrize('plant', [UNICYCLE, VELOCITY_LAG], ids=['unicycle', 'velocity_lag'])
def test_a_robot_plant_through_cmd_vel_matches_sim(tmp_path, ros_domain, plant, layout):
    run = assert_matches_sim('demo', tmp_path / 'run', DEMO + [plant], domain_id=ros_domain,
                             atol=0, timeout=RUN_TIMEOUT, **LAYOUTS[layout])
    series = run.timeseries()
    sc = run.scenario
    plant, xs = sc.plant.model, series['plant_state']
    assert xs.shape[:2] == (6, 6) and np.ptp(xs[:, :, 0]) > 0
    assert plant.conversion == 'exact'
    # The bag, read by an independent reader: one Twist per agent and step, the core's
    # conversion of the recorded state and acceleration; odometry carrying the plant state.
    steps = {round(t / sc.dt): r for r, t in enumerate(series['t'])}
    twists, odometry = {}, {}
    with open(run.out / 'bag' / 'bag_0.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages():
            if channel.topic.endswith('/cmd_vel'):
                assert schema.name == 'geometry_msgs/msg/Twist'
                twists.setdefault(channel.topic, []).append((message.log_time, msg))
            elif channel.topic.startswith('/agent_') and channel.topic.endswith('/odom'):
                odometry[(channel.topic, message.log_time)] = msg
    assert sorted(twists) == [f'/agent_{i}/cmd_vel' for i in range(6)]
    for i in range(6):
        got = twists[f'/agent_{i}/cmd_vel']
        assert len(got) == sc.steps + 1
        for t_ns, msg in got:
            r = steps.get(round(t_ns * 1e-9 / sc.dt))
            if r is None:
                continue
            x = xs[r, i:i + 1]
            linear, angular = plant.twist(x, plant.command(x, series['u'][r, i:i + 1], sc.dt),
                                          sc.plant.frame)
            assert_array_equal([msg.linear.x, msg.linear.y, msg.linear.z], linear[0])
            assert_array_equal([msg.angular.x, msg.angular.y, msg.angular.z], angular[0])
            odom = odometry[(f'/agent_{i}/odom', t_ns)]
            pose, twist = odom.pose.pose, odom.twist.twist
            assert_array_equal(plant.from_odometry(
                np.array([[pose.position.x, pose.position.y, pose.position.z]]),
                np.array([[pose.orientation.x, pose.orientation.y, pose.orientation.z,
                           pose.orientation.w]]),
                np.array([[twist.linear.x, twist.linear.y, twist.linear.z]]),
                np.array([[twist.angular.x, twist.angular.y, twist.angular.z]]), 2), x)


@pytest.mark.ros
def test_the_unicycle_commanded_by_acceleration_matches_sim_per_agent_process(tmp_path,
                                                                              ros_domain):
    assert_matches_sim('demo', tmp_path / 'run',
                       DEMO + [UNICYCLE.replace('model: unicycle', 'model: unicycle, '
                                                'command: accel, conversion: naive')],
                       domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT, processes=True)


@pytest.mark.ros
def test_realtime_robots_follow_their_twists(tmp_path, ros_domain):
    """Realtime: the world holds each robot's latest Twist (zero-order hold) on its timer."""
    from flock_swarm.testing import run_swarm
    run = run_swarm('demo', tmp_path / 'run', DEMO[:-1] + ['duration=1.0', UNICYCLE],
                    domain_id=ros_domain, timeout=RUN_TIMEOUT, mode='realtime')
    assert run.summary['status'] == 'completed' and run.summary['mode'] == 'realtime'
    series = run.timeseries()
    xs = series['plant_state']
    assert np.isfinite(xs).all()
    # The robots drove under their limits, and turned.
    assert 0 < np.abs(xs[1:, :, 4]).max() <= 1.5
    assert np.abs(xs[1:, :, 5]).max() <= 2.0
    assert np.ptp(series['heading'], axis=0).max() > 0
    counts = run.bag().message_counts()
    assert all(counts[f'/agent_{i}/cmd_vel'] > 0 for i in range(6))


@pytest.mark.ros
@pytest.mark.parametrize('node, value, line', [
    ('agent', 'cmd_vel', "agent: error: command: the double_integrator plant takes accel "
     "commands, got 'cmd_vel'"),
    ('world', 'twist', "world: error: command: invalid value 'twist'")])
def test_a_command_interface_the_plant_does_not_take_is_one_line(ros_domain, monkeypatch,
                                                                 capfd, node, value, line):
    import importlib
    main = importlib.import_module(f'flock_swarm.nodes.{node}').main
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    status = main([node, '--ros-args', '-p', 'scenario:=demo', '-p', f'command:={value}',
                   '-p', 'record:=false'] if node == 'world' else
                  [node, '--ros-args', '-p', 'scenario:=demo', '-p', f'command:={value}'])
    out, err = capfd.readouterr()
    assert status == 2 and out == ''
    assert err == line + '\n'
