"""Simulated robots: the physics engine in a process of its own, behaving as a robot fleet does.

``ros2 run flock_swarm engine_robots --ros-args -p scenario:=FILE -p latency:=0.05``. Not our
world: it knows nothing of steps, agents or the leader. Like a fleet of TurtleBot3 drivers it
takes ``geometry_msgs/Twist`` on ``{robot}/cmd_vel`` (body frame; the last command held, zero
before the first and after ``cmd_timeout``, as the TurtleBot3 driver's own watchdog does),
steps N robots in MuJoCo (:class:`~flock_swarm.engine.mujoco_world.EngineWorld`) on a wall-clock
timer, and publishes each robot's ``nav_msgs/Odometry`` on ``{robot}/odom`` (the pose in
``frame``, the twist in the body frame ``{robot}/base_footprint``, REP 105), stamped when the
state was read and sent ``latency`` seconds later: the transport and processing delay of a
real robot's odometry. The robots start at the scenario's initial positions, heading along
the initial velocities. Robot-robot contacts are counted (:attr:`EngineRobotsNode.world`) and
logged when a new pair touches.
"""

import collections
import math
import sys
import time

import numpy as np
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node

from flock_swarm.contract import (AGENT_PATTERN, FRAME, qos_profile, ROBOT_CMD_VEL, ROBOT_ODOM,
                                  SENSOR_QOS)
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.scenario import realize
from flock_swarm.engine.mujoco_world import MODELS, EngineWorld
from flock_swarm.nodes.parameters import COMMON_PARAMS, NodeParameters, Param, init_node
from flock_swarm.nodes.robot_agent import CMD_QOS, robot_names
from flock_swarm.nodes.spin import run_node, wall_timer

#: The simulated robots' parameters (after every node's).
ENGINE_PARAMS = COMMON_PARAMS + (
    Param('model', 'turtlebot3_burger', 'the robot model (an MJCF of flock_swarm.engine)',
          lambda v: v in MODELS, f'must be one of {sorted(MODELS)}, got {{value!r}}'),
    Param('robots', '', "the robots' names, comma-separated; '' names them by robot_pattern"),
    Param('robot_pattern', AGENT_PATTERN, "a robot's name from its index {i}",
          lambda v: '{i}' in v, "must contain '{{i}}', got {value!r}"),
    Param('frame', FRAME, 'the frame of the published poses (header.frame_id)'),
    Param('latency', 0.0, 'seconds between reading a state and publishing its odometry',
          lambda v: math.isfinite(v) and 0.0 <= v <= 10.0, 'must be in [0, 10], got {value!r}'),
    Param('cmd_timeout', 0.5, 'seconds after the last cmd_vel the robot stops',
          lambda v: math.isfinite(v) and v > 0, 'must be > 0, got {value!r}'),
)


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """Return the quaternion ``(x, y, z, w)`` of a rotation by ``yaw`` about z."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


class EngineRobotsNode(Node):
    """N robots in the physics engine behind the ``cmd_vel`` and ``odom`` of each."""

    def __init__(self, **kwargs) -> None:
        """Create the node.

        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        name = kwargs.pop('node_name', None)
        init_node(super().__init__, name or 'engine_robots', kwargs)
        params = self.params = NodeParameters(self, ENGINE_PARAMS)
        sc = self.scenario = params.load_scenario()
        if sc.dim != 2:
            raise ScenarioError('dim', f'the engine\'s robots drive on a plane: dim must be 2, '
                                f'got {sc.dim}')
        params.declare()
        real = realize(sc)
        q0, p0 = real.q0, real.p0
        self.world = EngineWorld(q0, np.arctan2(p0[:, 1], p0[:, 0]), model=params['model'])
        self.names = robot_names(params['robots'], params['robot_pattern'], sc.n_agents)
        self.dt = sc.dt
        self.frame = params['frame']
        self.latency = params['latency']
        self.cmd_timeout = params['cmd_timeout']
        n = sc.n_agents
        self.v = np.zeros(n)
        self.omega = np.zeros(n)
        self.heard = np.full(n, -math.inf)
        sensor = qos_profile(SENSOR_QOS)
        self.pubs = [self.create_publisher(Odometry, ROBOT_ODOM.replace('{robot}', robot),
                                           sensor) for robot in self.names]
        for j, robot in enumerate(self.names):
            self.create_subscription(Twist, ROBOT_CMD_VEL.replace('{robot}', robot),
                                     lambda msg, j=j: self.on_cmd(j, msg), CMD_QOS)
        #: Odometry read but not yet sent: ``(due, messages)``, oldest first.
        self.outbox: collections.deque = collections.deque()
        self.touched: set[tuple[int, int]] = set()
        wall_timer(self, params.timer_period(sc.dt), self.on_timer)
        if self.latency > 0.0:
            wall_timer(self, min(0.005, self.latency / 4.0), self.send_due)

    def on_cmd(self, j: int, msg: Twist) -> None:
        """Hold robot ``j``'s body twist."""
        self.v[j], self.omega[j] = msg.linear.x, msg.angular.z
        self.heard[j] = time.monotonic()

    def on_timer(self) -> None:
        """Step the engine by one ``dt`` with the held commands; read and queue the odometry."""
        silent = time.monotonic() - self.heard > self.cmd_timeout
        world = self.world
        world.set_twists(np.where(silent, 0.0, self.v), np.where(silent, 0.0, self.omega))
        world.step(self.dt)
        new = world.contacts_run - self.touched
        if new:
            self.get_logger().warning(f'robots in contact: {sorted(new)}')
            self.touched |= new
        stamp = self.get_clock().now().to_msg()
        poses, vels = world.poses(), world.velocities()
        messages = []
        for j, robot in enumerate(self.names):
            msg = Odometry()
            msg.header.stamp = stamp
            msg.header.frame_id = self.frame
            msg.child_frame_id = f'{robot}/base_footprint'
            x, y, yaw = poses[j]
            msg.pose.pose.position.x, msg.pose.pose.position.y = float(x), float(y)
            o = msg.pose.pose.orientation
            o.x, o.y, o.z, o.w = yaw_quaternion(float(yaw))
            c, s = math.cos(yaw), math.sin(yaw)
            vx, vy, wz = vels[j]
            # The twist in the body frame (REP 105: the child frame's).
            msg.twist.twist.linear.x = float(c * vx + s * vy)
            msg.twist.twist.linear.y = float(-s * vx + c * vy)
            msg.twist.twist.angular.z = float(wz)
            messages.append(msg)
        self.outbox.append((time.monotonic() + self.latency, messages))
        if self.latency == 0.0:
            self.send_due()

    def send_due(self) -> None:
        """Publish the queued odometry whose latency has passed."""
        now = time.monotonic()
        while self.outbox and self.outbox[0][0] <= now:
            _, messages = self.outbox.popleft()
            for pub, msg in zip(self.pubs, messages):
                pub.publish(msg)


def main(args: list[str] | None = None) -> int:
    """Run the simulated robots (``ros2 run flock_swarm engine_robots``)."""
    return run_node('engine_robots', EngineRobotsNode, args)


if __name__ == '__main__':
    sys.exit(main())
