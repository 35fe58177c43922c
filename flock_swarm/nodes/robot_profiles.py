"""The robot agent's topic mappings for common robots (launch/robot_agent_launch.py, docs).

Each profile is a set of :mod:`flock_swarm.nodes.robot_agent` parameters; ``{robot}`` stands
for each robot's name (its namespace), so one profile serves the whole fleet. What each
mapping rests on, and which were exercised here, is in docs/robots.md ("Robot profiles").
"""

from flock_swarm.contract import ESTOP
from flock_swarm.core.safety import ROBOT_DEFAULTS

#: Profile name -> the robot agent's parameters.
PROFILES: dict[str, dict[str, str]] = {
    # ROBOTIS TurtleBot3 (turtlebot3_bringup, one namespace per robot): Twist in the body
    # frame on cmd_vel, nav_msgs/Odometry on odom. Its odometry is in the robot's own `odom`
    # frame: the fleet needs one shared frame (docs/robots.md).
    'turtlebot3': {'odom_topic': '/{robot}/odom', 'odom_type': 'odometry',
                   'cmd_vel_topic': '/{robot}/cmd_vel', 'twist_frame': 'body',
                   'world_frame': 'odom'},
    # Clearpath Husky / Jackal (clearpath_common, namespace a200_0000 / j100_0000): Twist in
    # the body frame on cmd_vel, the EKF's odometry on platform/odom/filtered.
    'clearpath': {'odom_topic': '/{robot}/platform/odom/filtered', 'odom_type': 'odometry',
                  'cmd_vel_topic': '/{robot}/cmd_vel', 'twist_frame': 'body',
                  'world_frame': 'odom'},
    # PX4 through MAVROS (one namespace per vehicle): velocity setpoints as an unstamped Twist
    # in the local ENU frame; the local position as nav_msgs/Odometry in `map`.
    'px4_mavros': {'odom_topic': '/{robot}/mavros/local_position/odom',
                   'odom_type': 'odometry',
                   'cmd_vel_topic': '/{robot}/mavros/setpoint_velocity/cmd_vel_unstamped',
                   'twist_frame': 'world', 'world_frame': 'map'},
    # Motion capture through vrpn_mocap (one rigid body per robot, named as the robot):
    # geometry_msgs/PoseStamped in `world`, the velocity estimated by the robot agent; the
    # robot itself driven by its body-frame cmd_vel.
    'mocap': {'odom_topic': '/vrpn_mocap/{robot}/pose', 'odom_type': 'pose',
              'cmd_vel_topic': '/{robot}/cmd_vel', 'twist_frame': 'body',
              'world_frame': 'world'},
}

#: The launch file's arguments: name, default, description.
ARGUMENTS = (
    ('scenario', 'demo', 'scenario preset or YAML path (plant: velocity_lag or unicycle)'),
    ('agent_id', '0', "this robot's index among the robots"),
    ('robots', '', "the robots' names (namespaces), comma-separated, in agent order"),
    ('profile', 'turtlebot3', f'topic mapping: {", ".join(sorted(PROFILES))}'),
    *((name, str(default), description)
      for name, (default, description) in ROBOT_DEFAULTS.items()),
    ('geofence', '', "safety: 'xmin,ymin,xmax,ymax' (or with z) in the world frame"),
    ('estop_topic', ESTOP, 'emergency stop (std_msgs/Bool, latched or not)'),
)
#: Arguments passed on as numbers.
NUMBERS = tuple(ROBOT_DEFAULTS)


def robot_agent_parameters(values: dict[str, str]) -> dict:
    """Return the robot agent's parameters for the launch arguments (strings, by name).

    :param values: every argument of :data:`ARGUMENTS`.
    :return: the profile's mapping, then the arguments (numbers as numbers).
    :raises ValueError: for an unknown profile (one line naming it and the known ones).
    """
    values = dict(values)
    profile = values.pop('profile')
    if profile not in PROFILES:
        raise ValueError(f'profile: unknown robot profile {profile!r} '
                         f'(known: {", ".join(sorted(PROFILES))})')
    params: dict = dict(PROFILES[profile])
    params['agent_id'] = int(values.pop('agent_id'))
    params.update((key, float(values.pop(key))) for key in NUMBERS)
    params.update(values)
    return params
