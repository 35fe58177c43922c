"""Launch the robot agent on one robot (needs a system ROS 2 install, as every launch file).

ros2 launch flock_swarm robot_agent_launch.py scenario:=fleet.yaml agent_id:=2 \
    robots:=tb3_0,tb3_1,tb3_2 profile:=turtlebot3
ros2 launch flock_swarm robot_agent_launch.py scenario:=fleet.yaml agent_id:=0 \
    robots:=uav0,uav1 profile:=px4_mavros geofence:=-5,-5,0,5,5,3

Arguments (``--show-args``): ``scenario`` (preset name or YAML path, with a ``plant:`` of a
velocity-commanded robot), ``agent_id``, ``robots`` (the robots' names, their namespaces, in
agent order), ``profile`` (a key of :data:`flock_swarm.nodes.robot_profiles.PROFILES`: which
topics, message types and frames), the safety bounds ``max_speed``, ``max_accel``,
``max_yaw_rate``, ``stale_after`` and ``geofence``, and ``estop_topic``. docs/robots.md tells
what each profile maps and how to run the same node without ``ros2 launch``; the parameters
come from :func:`flock_swarm.nodes.robot_profiles.robot_agent_parameters`, tested without
``launch``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from flock_swarm.nodes.robot_profiles import ARGUMENTS, robot_agent_parameters


def robot_agent(context):
    """Return the robot agent with the profile's parameters and the arguments."""
    values = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    return [Node(package='flock_swarm', executable='robot_agent', output='screen',
                 parameters=[robot_agent_parameters(values)])]


def generate_launch_description():
    """Declare the arguments and the node."""
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, default, description in ARGUMENTS]
        + [OpaqueFunction(function=robot_agent)])
