"""The robot agent: one flocking agent on a real robot, its velocity command behind a safety layer.

``ros2 run flock_swarm robot_agent --ros-args -p agent_id:=2 -p robots:=tb3_0,tb3_1,tb3_2``.
A node of its own rather than a mode of the agent node: the agent node answers the world's
steps (lockstep or realtime) on the contract's topics and equals ``sim`` bit for bit; the robot
agent answers nobody. It runs on the robot's wall clock, hears each robot's state from the
robot's own topics, and every command it sends passes the safety layer
(:mod:`flock_swarm.core.safety`). Mixing the two would put a wall clock, topic patterns and a
safety layer on the path of the bit-identical runs.

Inputs: each robot's ``nav_msgs/Odometry`` (``odom_type:=odometry``; the twist in the body
frame, REP 105) or a motion-capture ``geometry_msgs/PoseStamped`` (``odom_type:=pose``: the
velocity estimated by :class:`~flock_swarm.core.robot_state.PoseDifferentiator`), on
``odom_topic`` with ``{robot}`` replaced by each robot's name (``robots``: a list of names, the
robots' namespaces, or ``robot_pattern`` with ``{i}``); the leader's ``nav_msgs/Odometry`` and
``geometry_msgs/AccelStamped``; an emergency stop (``std_msgs/Bool``, latched). Every message's
``header.frame_id`` must be ``world_frame``: another is refused (one line per topic, then
counted), so its state goes stale and the robot stops. Output: ``geometry_msgs/Twist`` on
``cmd_vel_topic``, in the plant's frame (``twist_frame``).

The command: the scenario's law at the point the plant says (``plant.model``: ``unicycle``,
the point ``ell`` ahead of the axle, or ``velocity_lag``), over the neighbours whose state is
fresh and within ``r`` (the r-disk graph), turned into a velocity by the plant's own
``command`` and ``twist`` (the same code ``sim`` runs), from the states predicted to the
moment the command is sent (``integrate_from:=predict``, because odometry arrives late: the
robot's own state through the commands it was sent since it was measured, the others' at
constant velocity, :mod:`flock_swarm.core.latency`), then filtered by the safety layer.
docs/robots.md maps the topics of TurtleBot3, Husky, Jackal, PX4 (MAVROS) and motion capture.
"""

import dataclasses
import math
import sys
import time

import numpy as np
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node
from std_msgs.msg import Bool

from flock_swarm.contract import (AGENT_PATTERN, ESTOP, ESTOP_QOS, FRAME, LEADER_ACCEL,
                                  LEADER_ODOM, qos_profile, ROBOT_CMD_QOS, ROBOT_CMD_VEL,
                                  ROBOT_ODOM, SENSOR_QOS)
from flock_swarm.core import registry
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.latency import CommandHistory, extrapolate
from flock_swarm.core.laws.evaluation import local_control
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.robot_state import (PoseDifferentiator, from_command, plant_state,
                                          world_velocity)
from flock_swarm.core.safety import ROBOT_DEFAULTS, SafetyLayer, SafetyLimits
from flock_swarm.core.scenario import realize
from flock_swarm.nodes.parameters import COMMON_PARAMS, NodeParameters, Param, init_node
from flock_swarm.nodes.spin import run_node, wall_timer

#: A robot's velocity commands (the contract's :data:`~flock_swarm.contract.ROBOT_CMD_QOS`).
CMD_QOS = qos_profile(ROBOT_CMD_QOS)


def velocity_plants() -> list[str]:
    """Return the registered plants a robot agent drives: those that take velocity commands
    (:meth:`~flock_swarm.core.plants.base.Plant.velocity_commanded`), by name."""
    return [name for name, cls in registry.usable(registry.PLANT_GROUP).items()
            if cls.velocity_commanded()]


def _positive(name: str, default: float, description: str) -> Param:
    return Param(name, default, description, lambda v: math.isfinite(v) and v > 0,
                 'must be a positive number, got {value!r}')


def _choice(name: str, default: str, options: tuple[str, ...], description: str) -> Param:
    return Param(name, default, description, lambda v: v in options,
                 f'must be {" or ".join(options)}, got {{value!r}}')


#: The robot agent's parameters (after every node's; ``mode`` is realtime only).
ROBOT_PARAMS = tuple(
    dataclasses.replace(p, default='realtime', check=lambda v: v == 'realtime',
                        problem='the robot agent runs in realtime only, got {value!r}')
    if p.name == 'mode' else p for p in COMMON_PARAMS) + (
    Param('agent_id', 0, "this robot's index among the robots (0-based)",
          lambda v: v >= 0, 'must be >= 0, got {value!r}'),
    Param('robots', '', "the robots' names (their namespaces), comma-separated, in agent "
          "order; '' names them by robot_pattern"),
    Param('robot_pattern', AGENT_PATTERN, "a robot's name from its index {i}, when robots is ''",
          lambda v: '{i}' in v, "must contain '{{i}}', got {value!r}"),
    Param('odom_topic', ROBOT_ODOM, "each robot's state topic ({robot}: its name)",
          lambda v: '{robot}' in v, "must contain '{{robot}}', got {value!r}"),
    _choice('odom_type', 'odometry', ('odometry', 'pose'), 'nav_msgs/Odometry, or '
            'geometry_msgs/PoseStamped (motion capture; velocity estimated)'),
    Param('cmd_vel_topic', ROBOT_CMD_VEL, "this robot's velocity command ({robot}: its "
          'name)'),
    Param('leader_odom_topic', LEADER_ODOM, "the leader's nav_msgs/Odometry (world frame)"),
    Param('leader_accel_topic', LEADER_ACCEL, "the leader's geometry_msgs/AccelStamped"),
    Param('estop_topic', ESTOP, 'the emergency stop (std_msgs/Bool, latched or not): true '
          'stops this robot until false'),
    Param('world_frame', FRAME, 'the frame every pose must be in (header.frame_id); a message '
          'in another is refused'),
    _choice('twist_frame', 'plant', ('plant', 'body', 'world'), "cmd_vel's frame: the "
            "scenario's plant.frame (unicycle: body by default, velocity_lag: world), body "
            'or world'),
    _choice('stale_clock', 'received', ('received', 'stamp'), "a state's age: since it was "
            "received (this node's steady clock; robust to clocks out of sync) or since its "
            "header stamp (this node's ROS clock; counts transport latency too)"),
    _choice('integrate_from', 'predict', ('predict', 'command', 'measured'), "predict: the "
            'law and the conversion act on the states predicted to the moment the command is '
            "sent (the robot's own through the commands sent since it was measured, the "
            "others' at constant velocity; docs/robots.md); command: the law's acceleration "
            'integrated from the last command sent; measured: from the measured velocity '
            "(sim's conversion exactly)"),
    Param('pose_filter_tau', 0.05, 'odom_type pose: time constant of the velocity estimate '
          '(s, 0: raw differences)', lambda v: math.isfinite(v) and v >= 0,
          'must be >= 0, got {value!r}'),
    *(_positive(name, default, description)
      for name, (default, description) in ROBOT_DEFAULTS.items()),
    Param('geofence', '', "safety: 'xmin,ymin,xmax,ymax' or 'xmin,ymin,zmin,xmax,ymax,zmax' "
          "in world_frame (m); '' for none"),
)


def parse_geofence(text: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Return the geofence's corners from ``'xmin,ymin,xmax,ymax'`` (or six values).

    :raises ScenarioError: naming ``geofence`` on anything else.
    """
    if text.strip() == '':
        return (), ()
    try:
        values = [float(v) for v in text.split(',')]
    except ValueError:
        values = []
    if len(values) not in (4, 6):
        raise ScenarioError('geofence', "expected 'xmin,ymin,xmax,ymax' or "
                            f"'xmin,ymin,zmin,xmax,ymax,zmax', got {text!r}")
    half = len(values) // 2
    return tuple(values[:half]), tuple(values[half:])


def robot_names(robots: str, pattern: str, n: int) -> list[str]:
    """Return the ``n`` robots' names from the ``robots`` list or the pattern.

    :raises ScenarioError: when the list does not name ``n`` distinct robots.
    """
    if robots.strip() == '':
        return [pattern.replace('{i}', str(i)) for i in range(n)]
    names = [name.strip() for name in robots.split(',')]
    if len(names) != n or len(set(names)) != n or '' in names:
        raise ScenarioError('robots', f'must name the scenario\'s {n} robots, distinct, got '
                            f'{robots!r}')
    return names


class RobotAgentNode(Node):
    """One robot's agent: the robots' and the leader's states in, a safe ``cmd_vel`` out."""

    def __init__(self, **kwargs) -> None:
        """Create the node.

        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        name = kwargs.pop('node_name', None)
        init_node(super().__init__, name or 'robot_agent', kwargs)
        params = self.params = NodeParameters(self, ROBOT_PARAMS)
        sc = self.scenario = params.load_scenario()
        plant = self.plant = sc.plant.model
        if not plant.velocity_commanded():
            raise ScenarioError('plant.model', 'the robot agent drives velocity-commanded '
                                f'robots ({" or ".join(velocity_plants())}), got {plant.name!r}')
        i = self.agent_id = params['agent_id']
        if i >= sc.n_agents:
            raise ScenarioError('agent_id', f'must be below n_agents = {sc.n_agents}, got {i}')
        self.names = robot_names(params['robots'], params['robot_pattern'], sc.n_agents)
        fence_min, fence_max = parse_geofence(params['geofence'])
        self.safety = SafetyLayer(SafetyLimits(
            max_speed=params['max_speed'], max_accel=params['max_accel'],
            max_yaw_rate=params['max_yaw_rate'], stale_after=params['stale_after'],
            fence_min=fence_min, fence_max=fence_max))
        frame = params['twist_frame']
        self.twist_frame = sc.plant.frame if frame == 'plant' else frame
        if self.twist_frame not in plant.frames:
            raise ScenarioError('twist_frame', f'the {plant.name} plant takes '
                                f'{" or ".join(plant.frames)} frame commands, got {frame!r}')
        params.declare()
        self.agent = realize(sc).agents.subset(np.array([i]))
        self.period = params.timer_period(sc.dt)
        self.world_frame = params['world_frame']
        self.by_stamp = params['stale_clock'] == 'stamp'
        n = sc.n_agents
        #: Each robot's state row, and when it was measured (see ``stale_clock``).
        self.states: list[np.ndarray | None] = [None] * n
        self.stamps: list[float | None] = [None] * n
        self.positions: list[np.ndarray | None] = [None] * n
        self.leader_odom: tuple[np.ndarray, np.ndarray] | None = None
        self.leader_accel = np.zeros(sc.dim)
        self.leader_stamp: float | None = None
        self.estop = False
        #: Messages refused for their frame, by topic (the first of each is logged).
        self.refused: dict[str, int] = {}
        self.last_stop = ''
        self.commands = 0
        self.from_sent = params['integrate_from'] == 'command'
        #: ``integrate_from:=predict``: the commands sent, in force from when they were sent,
        #: and when each robot's state was measured (both on the steady clock).
        self.predicting = params['integrate_from'] == 'predict'
        self.history = CommandHistory(plant)
        self.taken = np.zeros(n)
        #: The own state the last command was converted from (predicted, or as measured).
        self.x_now: np.ndarray | None = None
        #: The last command sent, as the plant's command row (zero before the first).
        self.sent = np.zeros((1, len(plant.command_names(sc.dim))))
        self.differentiators = [PoseDifferentiator(params['pose_filter_tau']) for _ in range(n)]
        self._subscribe(params)
        self.cmd_topic = params['cmd_vel_topic'].replace('{robot}', self.names[i])
        self.cmd_pub = self.create_publisher(Twist, self.cmd_topic, CMD_QOS)
        wall_timer(self, self.period, self.on_timer)

    def _subscribe(self, params: NodeParameters) -> None:
        """Subscribe to every robot's state, the leader's and the e-stop (the topics and
        message type the parameters name)."""
        sensor = qos_profile(SENSOR_QOS)
        pose = params['odom_type'] == 'pose'
        for j, robot in enumerate(self.names):
            topic = params['odom_topic'].replace('{robot}', robot)
            self.create_subscription(PoseStamped if pose else Odometry, topic,
                                     lambda msg, j=j, topic=topic: self.on_state(j, topic, msg),
                                     sensor)
        self.create_subscription(Odometry, params['leader_odom_topic'], self.on_leader_odom,
                                 sensor)
        self.create_subscription(AccelStamped, params['leader_accel_topic'],
                                 self.on_leader_accel, sensor)
        for spec in ESTOP_QOS:   # latched and volatile publishers both reach it
            self.create_subscription(Bool, params['estop_topic'], self.on_estop,
                                     qos_profile(spec))

    # -- inputs -------------------------------------------------------------------------------

    def now(self) -> float:
        """Return the time the ages count on (see ``stale_clock``)."""
        if self.by_stamp:
            return self.get_clock().now().nanoseconds * 1e-9
        return time.monotonic()

    def measured(self, header) -> float:
        """Return when a message was measured: its stamp, or now (``stale_clock:=received``)."""
        if self.by_stamp:
            return header.stamp.sec + header.stamp.nanosec * 1e-9
        return time.monotonic()

    def taken_at(self, header) -> float:
        """Return when a state was measured, on the steady clock: now, less the transport
        lag its stamp tells against this node's ROS clock when that lag is plausible (from 0
        to ``stale_after``: the clocks agree), else now (the lag is unknown)."""
        received = time.monotonic()
        lag = self.get_clock().now().nanoseconds * 1e-9 - (header.stamp.sec
                                                           + header.stamp.nanosec * 1e-9)
        return received - lag if 0.0 <= lag <= self.params['stale_after'] else received

    def in_world_frame(self, topic: str, frame_id: str) -> bool:
        """Return whether a message is in the world frame; log the first refusal of a topic."""
        if frame_id == self.world_frame:
            return True
        if topic not in self.refused:
            self.get_logger().error(f'{topic}: frame_id {frame_id!r} is not world_frame '
                                    f'{self.world_frame!r}: its messages are refused')
        self.refused[topic] = self.refused.get(topic, 0) + 1
        return False

    def on_state(self, j: int, topic: str, msg) -> None:
        """Store robot ``j``'s state (Odometry or PoseStamped) as its plant's state row."""
        if not self.in_world_frame(topic, msg.header.frame_id):
            return
        pose = msg.pose.pose if isinstance(msg, Odometry) else msg.pose
        position = np.array([pose.position.x, pose.position.y, pose.position.z])
        orientation = np.array([pose.orientation.x, pose.orientation.y, pose.orientation.z,
                                pose.orientation.w])
        at = self.measured(msg.header)
        if isinstance(msg, Odometry):
            twist = msg.twist.twist
            velocity = world_velocity(orientation, np.array(
                [twist.linear.x, twist.linear.y, twist.linear.z]))
            yaw_rate = twist.angular.z
        else:
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            est = self.differentiators[j]
            if not est.update(stamp, position, orientation):
                return
            velocity, yaw_rate = est.velocity, est.yaw_rate
        self.states[j] = plant_state(self.plant, self.scenario.dim, position,
                                     orientation, velocity, yaw_rate)
        self.positions[j] = position
        self.stamps[j] = at
        if self.predicting:
            self.taken[j] = self.taken_at(msg.header)

    def on_leader_odom(self, msg: Odometry) -> None:
        """Store the leader's position and velocity (both in the world frame: the contract)."""
        topic = self.params['leader_odom_topic']
        if not self.in_world_frame(topic, msg.header.frame_id):
            return
        dim = self.scenario.dim
        pos, vel = msg.pose.pose.position, msg.twist.twist.linear
        self.leader_odom = (np.array([pos.x, pos.y, pos.z][:dim]),
                            np.array([vel.x, vel.y, vel.z][:dim]))
        self.leader_stamp = self.measured(msg.header)

    def on_leader_accel(self, msg: AccelStamped) -> None:
        """Store the leader's acceleration."""
        if not self.in_world_frame(self.params['leader_accel_topic'], msg.header.frame_id):
            return
        a = msg.accel.linear
        self.leader_accel = np.array([a.x, a.y, a.z][:self.scenario.dim])

    def on_estop(self, msg: Bool) -> None:
        """Engage or release the emergency stop, from either subscription
        (:data:`~flock_swarm.contract.ESTOP_QOS`): a latched publisher's message comes
        through both, and the same value twice changes nothing."""
        if bool(msg.data) != self.estop:
            self.get_logger().warning('emergency stop ' + ('engaged' if msg.data else
                                                           'released'))
        self.estop = bool(msg.data)

    # -- the command --------------------------------------------------------------------------

    def law_command(self, now: float) -> tuple[np.ndarray, float]:
        """Return the plant's velocity command ``(linear (3,), yaw rate)`` from the law."""
        sc, plant, i = self.scenario, self.plant, self.agent_id
        stale = self.params['stale_after']
        fresh = [j for j in range(sc.n_agents) if j != i and self.states[j] is not None
                 and now - self.stamps[j] <= stale]
        x_self = self.states[i][None]
        if self.predicting:
            t = time.monotonic()
            x_self = self.history.predict(x_self, self.taken[i], t)
        q_self, p_self = (a[0] for a in plant.law_state(x_self))
        if fresh:
            x_nb = np.array([self.states[j] for j in fresh])
            if self.predicting:
                x_nb = extrapolate(plant, x_nb, t - self.taken[fresh])
            q_nb, p_nb = plant.law_state(x_nb)
            near = np.linalg.norm(q_nb - q_self, axis=1) < sc.law.radius
            q_nb, p_nb = q_nb[near], p_nb[near]
        else:
            q_nb = p_nb = np.zeros((0, sc.dim))
        leader = None
        if self.leader_odom is not None and now - self.leader_stamp <= stale:
            leader = LeaderState(self.leader_odom[0], self.leader_odom[1], self.leader_accel)
        u = local_control(sc.law, q_self, p_self, q_nb, p_nb, np.ones(len(q_nb)), leader,
                          self.agent, sc.dt)
        x_cmd = from_command(plant, x_self, self.sent) if self.from_sent else x_self
        cmd = plant.command(x_cmd, u[None], self.period)
        self.x_now = x_self
        linear, angular = plant.twist(x_self, cmd, self.twist_frame)
        return linear[0], float(angular[0, 2])

    def on_timer(self) -> None:
        """Compute, filter and publish this robot's command."""
        now = self.now()
        i = self.agent_id
        linear, yaw_rate = np.zeros(3), 0.0
        ready = self.states[i] is not None and self.leader_odom is not None
        self.x_now = None
        if ready:
            with np.errstate(all='ignore'):
                linear, yaw_rate = self.law_command(now)
        verdict = self.safety.filter(now, linear, yaw_rate, own_stamp=self.stamps[i],
                                     leader_stamp=self.leader_stamp,
                                     position=self.positions[i], estop=self.estop)
        if verdict.stop != self.last_stop:
            self.get_logger().warning(f'safety: stop ({verdict.stop})' if verdict.stop
                                      else 'safety: moving')
            self.last_stop = verdict.stop
        if self.states[i] is not None:
            x = self.states[i][None] if self.x_now is None else self.x_now
            self.sent = self.plant.from_twist(x, verdict.linear[None],
                                              np.array([[0.0, 0.0, verdict.yaw_rate]]),
                                              self.twist_frame)
            if self.predicting:
                self.history.sent(time.monotonic(), self.sent)
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.linear.z = (float(v) for v in verdict.linear)
        msg.angular.z = verdict.yaw_rate
        self.cmd_pub.publish(msg)
        self.commands += 1


def main(args: list[str] | None = None) -> int:
    """Run the robot agent (``ros2 run flock_swarm robot_agent``)."""
    return run_node('robot_agent', RobotAgentNode, args)


if __name__ == '__main__':
    sys.exit(main())
