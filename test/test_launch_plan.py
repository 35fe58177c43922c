"""The launch description's logic (flock_swarm/launch_plan.py), without ``ros2 launch``.

``launch/swarm_launch.py`` needs ``launch_ros`` (a system ROS 2 install); what it starts
for which arguments is :func:`swarm_processes`, checked here. The launch file itself is
read as text: it must declare every argument of :data:`LAUNCH_ARGUMENTS` through the
plan, and hold no decisions of its own.
"""

import ast
from pathlib import Path

import pytest

from flock_swarm.core.errors import ScenarioError
from flock_swarm.launch_plan import LAUNCH_ARGUMENTS, parse_flag, swarm_processes

LAUNCH_FILE = Path(__file__).resolve().parents[1] / 'launch' / 'swarm_launch.py'


def by_name(specs) -> dict:
    return {spec.name: spec for spec in specs}


def test_default_is_world_leader_and_one_agents_container():
    specs = swarm_processes()
    assert [(s.executable, s.name) for s in specs] == [
        ('world', 'world'), ('leader', 'leader'), ('agents', 'agents')]
    world, leader, agents = specs
    assert world.ends_launch and not leader.ends_launch and not agents.ends_launch
    assert world.output == 'screen'
    assert world.parameters == {'scenario': 'demo', 'mode': 'lockstep', 'out_dir': ''}
    assert leader.parameters == agents.parameters == {'scenario': 'demo', 'mode': 'lockstep'}


def test_one_process_per_agent_with_the_scenario_count():
    # The demo preset flies 30 agents (config/demo.yaml).
    specs = by_name(swarm_processes(container='false'))
    agents = [spec for name, spec in specs.items() if name.startswith('agent_')]
    assert len(agents) == 30
    assert {spec.executable for spec in agents} == {'agent'}
    assert [spec.parameters['agent_id'] for spec in agents] == list(range(30))
    assert 'agents' not in specs


def test_arguments_reach_every_node():
    specs = swarm_processes(scenario='su2009_fig6', n_agents='4', mode='realtime',
                            out_dir='out/x', container='False', foxglove='true',
                            foxglove_port='9000')
    names = [spec.name for spec in specs]
    assert names == ['world', 'leader', 'agent_0', 'agent_1', 'agent_2', 'agent_3',
                     'foxglove_server']
    for spec in specs:
        assert spec.parameters['scenario'] == 'su2009_fig6'
        assert spec.parameters['mode'] == 'realtime'
        assert spec.parameters['n_agents'] == 4
    assert by_name(specs)['world'].parameters['out_dir'] == 'out/x'
    assert by_name(specs)['foxglove_server'].parameters['port'] == 9000
    assert by_name(specs)['agent_3'].parameters['agent_id'] == 3


@pytest.mark.parametrize('kwargs, key', [
    ({'n_agents': 'many'}, 'n_agents'),
    ({'n_agents': '-1'}, 'n_agents'),
    ({'mode': 'fast'}, 'mode'),
    ({'container': 'maybe'}, 'container'),
    ({'foxglove': 'true', 'foxglove_port': '70000'}, 'foxglove_port'),
    ({'scenario': 'no_such_preset'}, 'scenario'),
    ({'informed_count': 'some'}, 'informed_count'),
    ({'n_agents': '4'}, 'informed.count'),  # the demo informs 10: say how many of the 4
    ({'overrides': 'duration'}, 'overrides'),
    ({'overrides': '=5'}, 'overrides'),
    ({'overrides': 'duration=-5'}, 'duration'),
    ({'overrides': 'no_such_key=1'}, 'no_such_key'),
    ({'informed_select': 'best'}, 'informed.select'),
])
def test_invalid_arguments_name_the_argument(kwargs, key):
    with pytest.raises(ScenarioError) as info:
        swarm_processes(**kwargs)
    assert info.value.key == key and '\n' not in str(info.value)


def test_informed_set_and_overrides_reach_every_node():
    """``n_agents:=4`` on the demo (which informs 10 agents) works with ``informed_count``;
    ``overrides`` are ``swarm --set`` assignments, a list of lists passed as its YAML text."""
    specs = swarm_processes(n_agents='4', informed_count='2', informed_select='first',
                            container='false', overrides='duration=10; protocol.c1=0.8;'
                            ' initial.position_box=[[0, 5], [0, 5]]; n_agents=7')
    assert [spec.name for spec in specs] == ['world', 'leader'] + [f'agent_{i}'
                                                                   for i in range(4)]
    for spec in specs:
        params = spec.parameters
        assert params['n_agents'] == 4  # the argument wins over the same key in overrides
        assert params['informed.count'] == 2 and params['informed.select'] == 'first'
        assert params['duration'] == 10 and params['protocol.c1'] == 0.8
        assert params['initial.position_box'] == '[[0, 5], [0, 5]]'


def test_the_overrides_argument_reads_like_set():
    from flock_swarm.launch_plan import parse_overrides
    assert parse_overrides('') == {} and parse_overrides(' ; ') == {}
    assert parse_overrides('a.b=[1, 2]; c=true;d=x') == {'a.b': [1, 2], 'c': True, 'd': 'x'}


@pytest.mark.parametrize('text, value', [('true', True), ('True', True), ('1', True),
                                         ('false', False), ('0', False), ('off', False)])
def test_parse_flag(text, value):
    assert parse_flag('container', text) is value


def test_launch_file_declares_the_plans_arguments_and_defers_to_it():
    tree = ast.parse(LAUNCH_FILE.read_text())
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                and node.module == 'flock_swarm.launch_plan' for alias in node.names}
    assert imported == {'LAUNCH_ARGUMENTS', 'swarm_processes'}
    calls = {node.func.id for node in ast.walk(tree)
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
    assert {'swarm_processes', 'DeclareLaunchArgument', 'Node'} <= calls
    # The defaults the launch file declares are the plan's.
    assert dict((name, default) for name, default, _ in LAUNCH_ARGUMENTS)['container'] == 'true'
    assert swarm_processes(**{name: default for name, default, _ in LAUNCH_ARGUMENTS}) \
        == swarm_processes()
