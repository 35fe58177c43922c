"""The bridge to real robots with real components: the robot agent (flock_swarm.nodes.robot_agent)
driving robots in the physics engine in a process of its own (engine_robots, odometry sent with
added latency) behind the real leader node, in realtime; and the safety layer's stops and
limits under faults, node by node (stale odometry, e-stop, geofence, a foreign frame).
"""

import math
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from flock_swarm.nodes.swarm_runner import executable
from flock_swarm.nodes.robot_profiles import ARGUMENTS, PROFILES, robot_agent_parameters
from flock_swarm.testing import spin_until

pytestmark = pytest.mark.ros

#: Six TurtleBot3 Burgers behind a leader circling at 0.1 m/s on a 1 m radius, Su 2009
#: protocol (10) at the robots' scale (docs/robots.md shows the file).
FLEET_FILE = Path(__file__).resolve().parents[1] / 'examples' / 'robots' / 'tb3_fleet.yaml'
FLEET = yaml.safe_load(FLEET_FILE.read_text())


@pytest.fixture
def fleet(tmp_path):
    """Return the path of the fleet's scenario file."""
    path = tmp_path / 'tb3_fleet.yaml'
    path.write_text(yaml.safe_dump(FLEET))
    return path


def start(name: str, scenario, domain: int, *params: str) -> subprocess.Popen:
    """Start executable ``name`` on the scenario (stderr kept for the test to read)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    args = ['--ros-args', '-p', f'scenario:={scenario}', '-p', 'mode:=realtime']
    for p in params:
        args += ['-p', p]
    return subprocess.Popen(executable(name) + args, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen) -> str:
    """Stop a process with SIGINT (kill after a bound); return its stderr."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
    return err


class Probe:
    """A test node's view of the robots: each one's latest odometry and the leader's."""

    def __init__(self, node, names, leader='leader/odom'):
        from nav_msgs.msg import Odometry
        from rclpy.qos import qos_profile_sensor_data
        self.odom = {}
        self.received = {}
        self.leader = None
        for j, robot in enumerate(names):
            node.create_subscription(Odometry, f'{robot}/odom',
                                     lambda m, j=j: self.put(j, m), qos_profile_sensor_data)
        node.create_subscription(Odometry, leader, lambda m: setattr(self, 'leader', m),
                                 qos_profile_sensor_data)
        self.clock = node.get_clock()

    def put(self, j, msg):
        self.odom[j] = msg
        self.received[j] = self.clock.now().nanoseconds * 1e-9


def law_points(odoms, ell):
    """Return the points ``ell`` ahead of the axles and their world velocities (Lawton 2003)."""
    q, p = [], []
    for m in odoms:
        o = m.pose.pose.orientation
        yaw = math.atan2(2 * (o.w * o.z + o.x * o.y), 1 - 2 * (o.y ** 2 + o.z ** 2))
        c, s = math.cos(yaw), math.sin(yaw)
        v, w = m.twist.twist.linear.x, m.twist.twist.angular.z * ell
        q.append([m.pose.pose.position.x + ell * c, m.pose.pose.position.y + ell * s])
        p.append([v * c - w * s, v * s + w * c])
    return np.array(q), np.array(p)


def robot_agents(context, scenario, n, executor, **extra):
    """Create ``n`` robot agents in this process (one per robot), added to ``executor``."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.robot_agent import RobotAgentNode
    nodes = []
    for i in range(n):
        given = {'scenario': str(scenario), 'agent_id': i, **extra}
        node = RobotAgentNode(context=context, node_name=f'robot_agent_{i}',
                              parameter_overrides=[Parameter(k, value=v)
                                                   for k, v in given.items()])
        executor.add_node(node)
        nodes.append(node)
    return nodes


def test_six_engine_robots_flock_behind_a_circling_leader_through_the_bridge(
        fleet, ros_domain, ros_context):
    """The engine in its own process (odometry 50 ms late), the leader node, six robot agents:
    in realtime the robots take the leader's velocity, keep apart and never touch."""
    from flock_swarm.nodes.spin import make_executor
    engine = start('engine_robots', fleet, ros_domain, 'latency:=0.05')
    leader = start('leader', fleet, ros_domain)
    executor = make_executor(ros_context)
    probe_node = None
    agents = []
    try:
        import rclpy
        probe_node = rclpy.create_node('probe', context=ros_context)
        probe = Probe(probe_node, [f'agent_{i}' for i in range(6)])
        executor.add_node(probe_node)
        agents = robot_agents(ros_context, fleet, 6, executor)
        spin_until(executor, lambda: all(a.last_stop == '' and a.commands for a in agents),
                   90, 'every robot agent to command motion')
        start_pos = {j: (m.pose.pose.position.x, m.pose.pose.position.y)
                     for j, m in probe.odom.items()}
        started = time.monotonic()
        closest = math.inf

        def flown():
            nonlocal closest
            if len(probe.odom) == 6:
                xy = np.array([[m.pose.pose.position.x, m.pose.pose.position.y]
                               for m in probe.odom.values()])
                d = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(6) * 9
                closest = min(closest, d.min())
            return time.monotonic() - started > 12.0
        spin_until(executor, flown, 60, '12 s of flight')
        q, p = law_points([probe.odom[j] for j in range(6)], FLEET['plant']['ell'])
        lv = probe.leader.twist.twist.linear
        mismatch = np.linalg.norm(p - [lv.x, lv.y], axis=1)
        moved = [math.dist(start_pos[j], (probe.odom[j].pose.pose.position.x,
                                          probe.odom[j].pose.pose.position.y))
                 for j in range(6)]
        # Flocking: every robot moves with the leader's velocity (eta = 1 at 0.05 m/s), the
        # flock stays connected in the r-disk graph, and nobody comes near a collision.
        assert mismatch.max() < FLEET['metrics']['eta_tolerance'], mismatch
        assert min(moved) > 0.6, moved
        assert closest > 0.5, closest
        dq = np.linalg.norm(q[:, None] - q[None], axis=-1)
        assert (dq < FLEET['protocol']['r']).sum() >= 2 * 5
        assert all(a.safety.counts['estop'] == 0 for a in agents)
    finally:
        for node in agents + ([probe_node] if probe_node else []):
            executor.remove_node(node)
            node.destroy_node()
        lead_err = finish(leader)
        engine_err = finish(engine)
    # The engine counts robot-robot contacts physically and tells each new pair: none.
    assert 'robots in contact' not in engine_err, engine_err
    assert 'error' not in lead_err.lower(), lead_err


def test_odometry_older_than_the_bound_stops_the_robot(fleet, ros_domain, ros_context):
    """Odometry stamped 0.3 s before it arrives (engine latency) is stale for a robot agent
    that counts ages from the stamps with a 0.2 s bound: it sends zero commands only."""
    from geometry_msgs.msg import Twist
    from flock_swarm.nodes.spin import make_executor
    import rclpy
    engine = start('engine_robots', fleet, ros_domain, 'latency:=0.3')
    leader = start('leader', fleet, ros_domain)
    executor = make_executor(ros_context)
    node = rclpy.create_node('probe', context=ros_context)
    executor.add_node(node)
    sent = []
    node.create_subscription(Twist, 'agent_0/cmd_vel', sent.append, 10)
    agents = robot_agents(ros_context, fleet, 1, executor, stale_clock='stamp',
                          stale_after=0.2)
    try:
        spin_until(executor, lambda: agents[0].states[0] is not None and len(sent) > 20, 90,
                   'odometry and commands')
        assert agents[0].last_stop == 'stale_own'
        assert all(m.linear.x == 0.0 and m.angular.z == 0.0 for m in sent)
    finally:
        for n in agents + [node]:
            executor.remove_node(n)
            n.destroy_node()
        finish(leader)
        finish(engine)


class FakeRobot:
    """A test node playing a robot's odometry and the leader for one robot agent."""

    def __init__(self, node, frame='world'):
        from geometry_msgs.msg import AccelStamped, Twist
        from nav_msgs.msg import Odometry
        from rclpy.qos import QoSDurabilityPolicy, QoSProfile, qos_profile_sensor_data
        from std_msgs.msg import Bool
        self.node = node
        self.frame = frame
        self.odom_pubs = [node.create_publisher(Odometry, f'agent_{i}/odom',
                                                qos_profile_sensor_data) for i in range(6)]
        self.leader_pub = node.create_publisher(Odometry, 'leader/odom', qos_profile_sensor_data)
        self.accel_pub = node.create_publisher(AccelStamped, 'leader/accel',
                                               qos_profile_sensor_data)
        self.estop_pub = node.create_publisher(Bool, 'swarm/estop', QoSProfile(
            depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL))
        self.cmds = []
        node.create_subscription(Twist, 'agent_0/cmd_vel', self.cmds.append, 10)
        self.position = [0.0, 0.0]

    def publish(self, frame=None):
        """Publish every robot's odometry (robot 0 at :attr:`position`) and the leader's."""
        from geometry_msgs.msg import AccelStamped
        from nav_msgs.msg import Odometry
        stamp = self.node.get_clock().now().to_msg()
        for i, pub in enumerate(self.odom_pubs):
            m = Odometry()
            m.header.stamp, m.header.frame_id = stamp, frame or self.frame
            m.pose.pose.position.x = self.position[0] if i == 0 else 1.0 * i
            m.pose.pose.position.y = self.position[1] if i == 0 else 0.5
            m.pose.pose.orientation.w = 1.0
            # Robot 0 drives forward at 0.2 m/s: above the agent's speed limit of 0.1.
            m.twist.twist.linear.x = 0.2 if i == 0 else 0.0
            pub.publish(m)
        m = Odometry()
        m.header.stamp, m.header.frame_id = stamp, 'world'
        m.pose.pose.position.x, m.twist.twist.linear.x = 5.0, 0.2
        self.leader_pub.publish(m)
        a = AccelStamped()
        a.header.stamp, a.header.frame_id = stamp, 'world'
        self.accel_pub.publish(a)


@pytest.fixture
def safety_rig(fleet, ros_context):
    """A robot agent with a geofence and tight limits, a fake robot fleet, an executor."""
    import rclpy
    from flock_swarm.nodes.spin import make_executor
    executor = make_executor(ros_context)
    node = rclpy.create_node('fake_robots', context=ros_context)
    executor.add_node(node)
    robot = FakeRobot(node)
    agent = robot_agents(ros_context, fleet, 1, executor, max_speed=0.1, max_yaw_rate=0.5,
                         max_accel=0.4, stale_after=0.3, geofence='-2,-2,2,2')[0]
    yield executor, robot, agent
    for n in (agent, node):
        executor.remove_node(n)
        n.destroy_node()


def feed_until(executor, robot, condition, what, timeout=30.0, **kwargs):
    """Publish the fake robots' state every 50 ms until ``condition`` holds."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        robot.publish(**kwargs)
        end = time.monotonic() + 0.05
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)


def test_the_safety_layer_in_the_node_limits_and_stops(safety_rig):
    """Limits hold on every command sent; the e-stop, stale odometry, a geofence breach and
    a foreign frame each stop the robot, and it moves again when the fault clears."""
    executor, robot, agent = safety_rig

    def moving():
        return agent.last_stop == '' and robot.cmds and robot.cmds[-1].linear.x > 0.05
    feed_until(executor, robot, lambda: moving() and len(robot.cmds) > 10,
               'the robot to move toward the leader')
    # Limits: speed, yaw rate, and the change between consecutive commands (0.4 m/s^2 over
    # one 50 ms period, with the timer's jitter).
    speeds = [math.hypot(m.linear.x, m.linear.y) for m in robot.cmds]
    assert max(speeds) <= 0.1 + 1e-12 and agent.safety.counts['saturated'] > 0
    assert max(abs(m.angular.z) for m in robot.cmds) <= 0.5 + 1e-12
    steps = np.abs(np.diff(speeds))
    assert steps.max() <= 0.4 * 0.2

    def stopped(reason):
        return lambda: (agent.last_stop == reason and robot.cmds[-1].linear.x == 0.0
                        and robot.cmds[-1].angular.z == 0.0)
    from std_msgs.msg import Bool
    robot.estop_pub.publish(Bool(data=True))
    feed_until(executor, robot, stopped('estop'), 'the e-stop')
    robot.estop_pub.publish(Bool(data=False))
    feed_until(executor, robot, moving, 'motion after the e-stop')
    # Stale odometry: nothing published for longer than stale_after.
    spin_until(executor, stopped('stale_own'), 10, 'the stale-odometry stop')
    feed_until(executor, robot, moving, 'motion after fresh odometry')
    robot.position = [2.5, 0.0]
    feed_until(executor, robot, stopped('geofence'), 'the geofence stop')
    robot.position = [0.0, 0.0]
    feed_until(executor, robot, moving, 'motion back inside the fence')
    # A frame other than the world frame is refused: the robot's state goes stale.
    feed_until(executor, robot, stopped('stale_own'), 'the refusal of a foreign frame',
               frame='odom')
    assert agent.refused['agent_0/odom'] > 0
    assert agent.safety.counts['estop'] >= 1 and agent.safety.counts['geofence'] >= 1


def test_the_estop_obeys_a_default_qos_publisher_and_stays_latched(safety_rig, fleet,
                                                                   ros_context):
    """Issue 38: the e-stop was subscribed transient-local only, so a volatile publisher
    (``ros2 topic pub``'s default, as docs/robots.md's line uses it) was ignored. A
    default-QoS publisher now engages and releases it; a robot agent started after a latched
    publisher engaged it still starts stopped."""
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import Bool

    from flock_swarm.contract import ESTOP
    from flock_swarm.nodes.robot_agent import RobotAgentNode
    executor, robot, agent = safety_rig
    plain = robot.node.create_publisher(Bool, ESTOP, QoSProfile(depth=10))
    assert plain.qos_profile.durability == DurabilityPolicy.VOLATILE

    def moving():
        return agent.last_stop == '' and robot.cmds and robot.cmds[-1].linear.x > 0.05

    def stopped():
        return (agent.last_stop == 'estop' and robot.cmds[-1].linear.x == 0.0
                and robot.cmds[-1].angular.z == 0.0)
    feed_until(executor, robot, moving, 'the robot to move toward the leader')
    spin_until(executor, lambda: plain.get_subscription_count() >= 1, 30,
               'the robot agent to match the volatile publisher')
    plain.publish(Bool(data=True))
    feed_until(executor, robot, stopped, 'the e-stop from a volatile publisher')
    plain.publish(Bool(data=False))
    feed_until(executor, robot, moving, 'the release from a volatile publisher')
    estops = agent.safety.counts['estop']
    robot.estop_pub.publish(Bool(data=True))
    feed_until(executor, robot, stopped, 'the e-stop from a latched publisher')
    late = RobotAgentNode(context=ros_context, node_name='late_robot_agent',
                          parameter_overrides=[Parameter('scenario', value=str(fleet)),
                                               Parameter('agent_id', value=1)])
    executor.add_node(late)
    try:
        feed_until(executor, robot, lambda: late.estop and late.last_stop == 'estop',
                   'a robot agent started later to see the latched e-stop')
        assert agent.safety.counts['estop'] > estops
        plain.publish(Bool(data=False))
        feed_until(executor, robot, lambda: moving() and not late.estop,
                   'the release of both robot agents by the volatile publisher')
    finally:
        executor.remove_node(late)
        late.destroy_node()


def test_bad_bridge_parameters_are_one_line(fleet, ros_domain):
    """A bad parameter of the robot agent: one line naming it, exit status 2."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    for param, key in (('geofence:=1,2,3', 'geofence'), ('robots:=a,b', 'robots'),
                       ('max_speed:=-1.0', 'max_speed'), ('mode:=lockstep', 'mode'),
                       ('twist_frame:=sideways', 'twist_frame'), ('agent_id:=6', 'agent_id'),
                       ('integrate_from:=ahead', 'integrate_from')):
        res = subprocess.run(executable('robot_agent') + [
            '--ros-args', '-p', f'scenario:={fleet}', '-p', param], env=env,
            capture_output=True, text=True, timeout=60)
        assert res.returncode == 2, (param, res.stderr)
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and re.match(rf'robot_agent: error: {key}: ', lines[0]), lines


def test_the_bridge_asks_the_plant_whether_it_takes_velocity_commands(ros_domain):
    """A plant without ``cmd_vel`` among its commands is refused, the plants that have it
    named from the registry (the node kept its own list of them)."""
    from flock_swarm.nodes.robot_agent import velocity_plants
    assert velocity_plants() == ['unicycle', 'velocity_lag']
    res = subprocess.run(executable('robot_agent') + ['--ros-args', '-p', 'scenario:=demo'],
                         env=dict(os.environ, ROS_DOMAIN_ID=str(ros_domain)),
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert res.stderr == ('robot_agent: error: plant.model: the robot agent drives '
                          "velocity-commanded robots (unicycle or velocity_lag), got "
                          "'double_integrator'\n")


def test_the_profiles_make_the_launch_parameters():
    defaults = {name: default for name, default, _ in ARGUMENTS}
    for profile in PROFILES:
        params = robot_agent_parameters({**defaults, 'profile': profile, 'robots': 'a,b'})
        assert params['odom_topic'].count('{robot}') == 1
        assert params['max_speed'] == 0.22 and params['agent_id'] == 0
    assert robot_agent_parameters({**defaults, 'profile': 'px4_mavros'})['cmd_vel_topic'] == \
        '/{robot}/mavros/setpoint_velocity/cmd_vel_unstamped'
    with pytest.raises(ValueError, match=r"unknown robot profile 'roomba'"):
        robot_agent_parameters({**defaults, 'profile': 'roomba'})


def test_the_node_and_the_launch_file_take_the_safety_defaults_from_one_table():
    """The robot agent's parameters and the launch file's arguments were two lists."""
    from flock_swarm.core.safety import ROBOT_DEFAULTS
    from flock_swarm.nodes.robot_agent import ROBOT_PARAMS
    node = {p.name: (p.default, p.description) for p in ROBOT_PARAMS}
    launch = {name: (float(default), description) for name, default, description in ARGUMENTS
              if name in ROBOT_DEFAULTS}
    assert node['max_speed'] == (0.22, 'safety: largest linear speed (m/s)')
    assert {name: node[name] for name in ROBOT_DEFAULTS} == launch == ROBOT_DEFAULTS


def test_the_robot_topics_and_their_qos_come_from_the_contract():
    """The robot agent's and the simulated fleet's topics and QoS (the QoS were rclpy
    profiles of the node modules): the same profiles as before, named in the contract."""
    from rclpy.qos import QoSProfile, QoSReliabilityPolicy, qos_profile_sensor_data

    from flock_swarm.contract import qos_profile, ROBOT_CMD_QOS, SENSOR_QOS
    from flock_swarm.nodes.robot_agent import ROBOT_PARAMS
    assert qos_profile(SENSOR_QOS) == qos_profile_sensor_data
    assert qos_profile(ROBOT_CMD_QOS) == QoSProfile(
        depth=1, reliability=QoSReliabilityPolicy.RELIABLE)
    node = {p.name: p.default for p in ROBOT_PARAMS}
    assert [node[k] for k in ('odom_topic', 'cmd_vel_topic', 'estop_topic', 'robot_pattern')] \
        == ['{robot}/odom', '{robot}/cmd_vel', '/swarm/estop', 'agent_{i}']


def test_motion_capture_poses_give_the_robot_its_estimated_velocity(fleet, ros_context):
    """``odom_type:=pose``: PoseStamped of a robot driving at 0.1 m/s along its heading (the
    y axis) give the robot agent the state of a unicycle at 0.1 m/s, heading pi/2."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import qos_profile_sensor_data

    from flock_swarm.nodes.spin import make_executor
    executor = make_executor(ros_context)
    node = rclpy.create_node('mocap', context=ros_context)
    executor.add_node(node)
    pub = node.create_publisher(PoseStamped, '/vrpn_mocap/agent_0/pose',
                                qos_profile_sensor_data)
    agent = robot_agents(ros_context, fleet, 1, executor, odom_type='pose',
                         odom_topic='/vrpn_mocap/{robot}/pose', pose_filter_tau=0.0)[0]
    try:
        k = 0

        def sent_until_estimated():
            nonlocal k
            msg = PoseStamped()
            msg.header.frame_id = 'world'
            ns = k * 10_000_000
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            msg.pose.position.y = 0.1 * ns * 1e-9
            msg.pose.orientation.z = msg.pose.orientation.w = math.sqrt(0.5)
            pub.publish(msg)
            k += 1
            x = agent.states[0]
            return x is not None and abs(x[4] - 0.1) < 1e-6
        spin_until(executor, sent_until_estimated, 30, 'the estimated velocity')
        x = agent.states[0]
        assert 2 * math.atan2(x[2], x[3]) == pytest.approx(math.pi / 2)
        assert x[5] == pytest.approx(0.0, abs=1e-9)
    finally:
        for n in (agent, node):
            executor.remove_node(n)
            n.destroy_node()
