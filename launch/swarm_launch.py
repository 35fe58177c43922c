"""Launch the world, the leader and N agents of a scenario.

ros2 launch flock_swarm swarm_launch.py scenario:=su2009_fig6
ros2 launch flock_swarm swarm_launch.py scenario:=demo n_agents:=12 mode:=realtime
ros2 launch flock_swarm swarm_launch.py scenario:=demo n_agents:=100 container:=true

Arguments: ``scenario`` (preset name or YAML path), ``n_agents`` (0: the scenario's),
``mode`` (lockstep or realtime), ``out_dir`` (where the world writes bag/ and summary.json),
``container`` (true: every agent in one ``agents`` process instead of one process each).
The launch ends when the world has recorded its last step.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from flock_swarm.scenarios import load


def swarm_nodes(context):
    """Return the world, leader and agent nodes for the chosen scenario."""
    scenario = LaunchConfiguration('scenario').perform(context)
    n_agents = int(LaunchConfiguration('n_agents').perform(context))
    mode = LaunchConfiguration('mode').perform(context)
    out_dir = LaunchConfiguration('out_dir').perform(context)
    container = LaunchConfiguration('container').perform(context).lower() in ('true', '1')
    common = {'scenario': scenario, 'mode': mode}
    if n_agents > 0:
        common['n_agents'] = n_agents
    n = load(scenario, extra={'n_agents': n_agents} if n_agents > 0 else None).n_agents
    nodes = [
        Node(package='flock_swarm', executable='world', name='world', output='screen',
             parameters=[dict(common, out_dir=out_dir)], on_exit=Shutdown()),
        Node(package='flock_swarm', executable='leader', name='leader',
             parameters=[common]),
    ]
    if container:
        nodes.append(Node(package='flock_swarm', executable='agents', name='agents',
                          parameters=[common]))
    else:
        nodes += [Node(package='flock_swarm', executable='agent', name=f'agent_{i}',
                       parameters=[dict(common, agent_id=i)]) for i in range(n)]
    return nodes


def generate_launch_description():
    """Declare the arguments and the nodes."""
    return LaunchDescription([
        DeclareLaunchArgument('scenario', default_value='demo',
                              description='scenario preset name or path to a YAML file'),
        DeclareLaunchArgument('n_agents', default_value='0',
                              description='number of agents (0: the scenario value)'),
        DeclareLaunchArgument('mode', default_value='lockstep',
                              description='lockstep or realtime'),
        DeclareLaunchArgument('out_dir', default_value='',
                              description='output directory of the world (bag/, summary)'),
        DeclareLaunchArgument('container', default_value='false',
                              description='host every agent in one process (agents)'),
        OpaqueFunction(function=swarm_nodes),
    ])
