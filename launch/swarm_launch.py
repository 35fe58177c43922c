"""Launch the world, the leader and the agents of a scenario (needs a system ROS 2 install).

ros2 launch flock_swarm swarm_launch.py scenario:=su2009_fig6
ros2 launch flock_swarm swarm_launch.py scenario:=demo n_agents:=12 mode:=realtime
ros2 launch flock_swarm swarm_launch.py n_agents:=4 informed_count:=2 \
    overrides:='duration=10; protocol.c1=0.8'
ros2 launch flock_swarm swarm_launch.py scenario:=demo container:=false   # a process per agent
ros2 launch flock_swarm swarm_launch.py scenario:=demo foxglove:=true     # and the live view

Arguments (``--show-args``): ``scenario`` (preset name or YAML path), ``n_agents`` (0: the
scenario's), ``informed_count`` and ``informed_select`` (the informed set; 0 / empty: the
scenario's), ``overrides`` (further ``key=value`` assignments separated by ``;``, as ``swarm
--set``), ``mode`` (lockstep or realtime), ``out_dir`` (where the world writes bag/ and
summary.json), ``container`` (default true: every agent in one ``agents`` process; false:
one ``agent`` process per agent, which takes minutes for the demo on two cores),
``foxglove`` and ``foxglove_port`` (the live view, ``foxglove_server``). The launch ends
when the world has recorded its last step.

``ros2 launch`` needs a system ROS 2 install: ``launch_ros`` imports
``composition_interfaces``, which has no PyPI wheel. In the virtualenv use ``swarm``
(``swarm demo --processes --container`` starts the same three processes). Which processes
start with which parameters is decided by :func:`flock_swarm.launch_plan.swarm_processes`,
tested without ``launch``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from flock_swarm.launch_plan import LAUNCH_ARGUMENTS, swarm_processes


def swarm_nodes(context):
    """Return the nodes :func:`swarm_processes` chooses for the launch arguments."""
    values = {name: LaunchConfiguration(name).perform(context)
              for name, _, _ in LAUNCH_ARGUMENTS}
    return [Node(package='flock_swarm', executable=spec.executable, name=spec.name,
                 output=spec.output, parameters=[spec.parameters],
                 on_exit=Shutdown() if spec.ends_launch else None)
            for spec in swarm_processes(**values)]


def generate_launch_description():
    """Declare the arguments and the nodes."""
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, default, description in LAUNCH_ARGUMENTS]
        + [OpaqueFunction(function=swarm_nodes)])
