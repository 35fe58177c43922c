"""Parameters that tell the truth: every scenario key and setting a node uses is a declared,
read-only ROS parameter with its effective value, read through the real parameter services;
the parameters dumped from running nodes reproduce their run."""

import importlib
import json
import os
import re
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_array_equal

from flock_swarm.console import EXIT_INTERRUPTED
from flock_swarm.nodes.swarm_runner import executable

RUN_TIMEOUT = 240.0
SERVICE_TIMEOUT = 30.0

#: A small scenario written here (not a preset), so every expected value below is this file's.
SCENARIO = {
    'name': 'params_check',
    'dim': 2,
    'n_agents': 3,
    'dt': 0.05,
    'duration': 1.5,
    'seed': 4,
    'protocol': {'name': 'su_informed', 'r': 4.0, 'd': 3.3, 'eps': 0.1, 'h': 0.9,
                 'a': 5.0, 'b': 5.0, 'c1': 0.5, 'c2': 0.5},
    'informed': {'select': 'random', 'count': 1},
    'initial': {'position_box': [[0.0, 5.0], [0.0, 5.0]],
                'velocity_box': [[0.0, 0.01], [0.0, 0.01]]},
    'leader': {'model': 'constant_velocity', 'position': [2.0, 2.0], 'velocity': [1.0, 1.0]},
}


def call(node, executor, srv_type, service: str, request):
    """Call a service of another node and return its response (bounded wait)."""
    client = node.create_client(srv_type, service)
    try:
        assert client.wait_for_service(timeout_sec=SERVICE_TIMEOUT), service
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=SERVICE_TIMEOUT)
        assert future.done(), f'{service} did not answer'
        return future.result()
    finally:
        node.destroy_client(client)


def read_parameters(node, executor, target: str) -> dict:
    """Return every parameter of node ``target`` as ``{name: value}`` (its services)."""
    from rcl_interfaces.srv import GetParameters, ListParameters
    from rclpy.parameter import parameter_value_to_python
    names = list(call(node, executor, ListParameters, f'{target}/list_parameters',
                      ListParameters.Request()).result.names)
    values = call(node, executor, GetParameters, f'{target}/get_parameters',
                  GetParameters.Request(names=names)).values
    return {name: parameter_value_to_python(v) for name, v in zip(names, values)}


def params_file(path, target: str, values: dict) -> None:
    """Write ``values`` as a ROS 2 parameters file for node ``target``, as ``ros2 param dump``
    does (dotted names nested)."""
    nested: dict = {}
    for name, value in values.items():
        *sections, last = name.split('.')
        here = nested
        for part in sections:
            here = here.setdefault(part, {})
        here[last] = list(value) if isinstance(value, (list, tuple)) else value
    path.write_text(yaml.safe_dump({target: {'ros__parameters': nested}}))


@pytest.fixture
def client(ros_context):
    """Return ``(node, executor)``: a node of the test's own to call the services with."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    node = Node('param_client', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    yield node, executor
    executor.shutdown()
    node.destroy_node()


def test_world_parameters_read_back_what_the_run_uses(tmp_path, ros_context, client,
                                                      monkeypatch):
    """``get_parameters`` answers every scenario key with its effective value (file, override,
    default), ``out_dir`` the directory written, ``seed`` the seed; each is read-only, and
    ``set_parameters`` is refused with a reason."""
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import DescribeParameters, SetParameters
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.world import WorldNode
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump(SCENARIO))
    monkeypatch.chdir(tmp_path)  # out_dir left empty: out/<name>_ros under the cwd
    node, executor = client
    world = WorldNode(context=ros_context, parameter_overrides=[
        Parameter('scenario', value=str(path)), Parameter('protocol.c1', value=0.8),
        Parameter('start_timeout', value=60.0)])
    executor.add_node(world)
    try:
        values = read_parameters(node, executor, '/world')
        assert values['n_agents'] == 3 and values['dt'] == 0.05 and values['dim'] == 2
        assert values['protocol.c1'] == 0.8  # the override
        assert values['protocol.c2'] == 0.5 and values['protocol.name'] == 'su_informed'
        assert values['leader.position'] == [2.0, 2.0]
        assert values['informed.select'] == 'random' and values['informed.count'] == 1
        # A list of lists is no ROS parameter: it reads back as its YAML text.
        assert yaml.safe_load(values['initial.position_box']) == [[0.0, 5.0], [0.0, 5.0]]
        # Keys the file leaves out read back as the defaults docs/scenarios.md gives them.
        assert values['record_every'] == 1 and values['graph.type'] == 'disk'
        assert values['seed'] == 4  # -1 (not given) is the scenario's seed
        assert values['out_dir'] == os.path.join('out', 'params_check_ros')
        assert (tmp_path / values['out_dir']).is_dir()
        assert values['step_timeout'] == 2.0 and values['start_timeout'] == 60.0
        names = ['n_agents', 'protocol.c1', 'out_dir', 'seed', 'initial.position_box',
                 'step_timeout', 'mode']
        described = call(node, executor, DescribeParameters, '/world/describe_parameters',
                         DescribeParameters.Request(names=names)).descriptors
        assert [d.name for d in described] == names
        assert all(d.read_only for d in described), [d.name for d in described]
        request = SetParameters.Request(parameters=[ParameterMsg(
            name='n_agents', value=ParameterValue(type=ParameterType.PARAMETER_INTEGER,
                                                  integer_value=5))])
        result, = call(node, executor, SetParameters, '/world/set_parameters',
                       request).results
        assert not result.successful and 'read-only' in result.reason
        assert read_parameters(node, executor, '/world')['n_agents'] == 3
    finally:
        executor.remove_node(world)
        world.close()
        world.destroy_node()


def start(kind: str, args: list[str], env: dict, log) -> subprocess.Popen:
    """Start a node executable with ``--ros-args args``, its output to ``log``."""
    return subprocess.Popen(executable(kind) + ['--ros-args', *args], env=env,
                            stdout=log, stderr=log)


def test_dumped_parameters_reproduce_the_run(tmp_path, ros_domain, ros_context, client):
    """Dump world, leader and agents while they run (their parameter services), change the
    scenario file, start a run from the dumps alone: it is the first run again."""
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump(SCENARIO))
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    node, executor = client
    common = ['-p', f'scenario:={path}', '-p', 'seed:=7', '-p', 'protocol.c1:=0.8']
    first, second = tmp_path / 'first', tmp_path / 'second'
    procs = []
    with open(tmp_path / 'nodes.log', 'w') as log:
        try:
            # The world waits (start_timeout) for the others: time to dump it.
            world = start('world', common + ['-p', f'out_dir:={first}'], env, log)
            procs.append(world)
            dumps = {'/world': read_parameters(node, executor, '/world')}
            others = [start(kind, common + ['-p', 'keep_running:=true'], env, log)
                      for kind in ('leader', 'agents')]
            procs += others
            assert world.wait(timeout=RUN_TIMEOUT) == 0
            # keep_running: the leader and the agents stay after the world's end.
            assert all(p.poll() is None for p in others)
            for target in ('/leader', '/agents'):
                dumps[target] = read_parameters(node, executor, target)
            for proc in others:
                proc.send_signal(signal.SIGINT)
                assert proc.wait(timeout=60) == EXIT_INTERRUPTED
            # The file changes; the dumps hold every key, so they do not depend on it.
            changed = dict(SCENARIO, seed=11, dt=0.1, n_agents=5,
                           protocol=dict(SCENARIO['protocol'], c1=0.3))
            path.write_text(yaml.safe_dump(changed))
            files = {}
            for target, values in dumps.items():
                files[target] = tmp_path / f'{target[1:]}.yaml'
                params_file(files[target], target, values)
            world = start('world', ['--params-file', str(files['/world']),
                                    '-p', f'out_dir:={second}'], env, log)
            others = [start(kind, ['--params-file', str(files[f'/{kind}']),
                                   '-p', 'keep_running:=false'], env, log)
                      for kind in ('leader', 'agents')]
            procs += [world] + others
            assert world.wait(timeout=RUN_TIMEOUT) == 0
            # Without keep_running the leader and the agents end with the world's run.
            for proc in others:
                assert proc.wait(timeout=60) == 0
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.kill()
                proc.wait()
    a, b = (json.loads((d / 'summary.json').read_text()) for d in (first, second))
    assert a['status'] == b['status'] == 'completed'
    for key in ('steps', 't_final', 'eta', 'velocity_mismatch_max', 'informed', 'seed', 'dt',
                'n_agents', 'missed_commands'):
        assert a[key] == b[key], key
    assert a['seed'] == 7 and a['steps'] == 30
    with np.load(first / 'timeseries.npz') as qa, np.load(second / 'timeseries.npz') as qb:
        assert_array_equal(qa['q'], qb['q'])


#: Each node kind: its module, class and parameter table.
NODE_KINDS = {'world': ('world', 'WorldNode', 'WORLD_PARAMS'),
              'leader': ('leader', 'LeaderNode', 'LEADER_PARAMS'),
              'agent': ('agent', 'AgentNode', 'AGENT_PARAMS'),
              'foxglove_server': ('foxglove_server', 'LiveBridge', 'BRIDGE_PARAMS')}


@pytest.mark.parametrize('kind', sorted(NODE_KINDS))
def test_each_node_declares_exactly_its_table_and_the_scenario(kind, tmp_path, ros_context):
    """A node's parameters are its table's (each once, the common ones first, read-only,
    with the table's description) and the scenario keys; nothing else given stays declared
    (a section given as YAML text, ``qos_overrides``)."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.parameters import COMMON_PARAMS, ROS_PARAMS, scenario_parameters
    module, class_name, table_name = NODE_KINDS[kind]
    module = importlib.import_module(f'flock_swarm.nodes.{module}')
    table = getattr(module, table_name)
    names = [param.name for param in table]
    assert len(set(names)) == len(names) and table[:len(COMMON_PARAMS)] == COMMON_PARAMS
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump(SCENARIO))
    own = {'out_dir': str(tmp_path / 'out'), 'port': 0}
    given = {'scenario': str(path), 'qos_overrides./clock.publisher.depth': 3,
             'metrics': '{eta_tolerance: 0.2}'}
    given.update((key, value) for key, value in own.items() if key in names)
    node = getattr(module, class_name)(context=ros_context, parameter_overrides=[
        Parameter(key, value=value) for key, value in given.items()])
    try:
        declared = set(node.list_parameters([], 0).names) - ROS_PARAMS
        assert declared == set(names) | set(scenario_parameters(node.params.scenario))
        assert node.get_parameter('metrics.eta_tolerance').value == 0.2
        for param in table:
            descriptor = node.describe_parameter(param.name)
            assert descriptor.description == param.description
            if param.name in node.params.settled:
                # Settled by the node once known (expect_subscribers: -1 reads back the number
                # waited for): declared writable for the node alone, refused to anyone else.
                value = node.get_parameter(param.name).value
                assert not node.set_parameters([Parameter(param.name, value=value)])[0].successful
            else:
                assert descriptor.read_only
    finally:
        close = getattr(node, 'close', None)
        if close is not None:
            close()
        node.destroy_node()


def test_the_container_reads_back_the_agents_it_hosts(tmp_path, ros_context):
    """``agent_ids`` reads back the ids a node hosts, given as ids and ranges, as ``all`` (the
    container's default) or through ``agent_id`` alone, and given back they host the same;
    ``agent_id`` reads back the agent hosted, or -1 in a node hosting several."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.agent import AgentNode
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump(SCENARIO))
    for default, given, ids in (('all', {}, [0, 1, 2]), ('', {'agent_ids': '0,2'}, [0, 2]),
                                ('', {'agent_id': 1}, [1]), ('', {'agent_ids': [2, 0]}, [0, 2])):
        params = [Parameter('scenario', value=str(path))]
        params += [Parameter(k, value=v) for k, v in given.items()]
        node = AgentNode(default_agent_ids=default, context=ros_context,
                         parameter_overrides=params)
        try:
            assert list(node.get_parameter('agent_ids').value) == ids
            assert node.controller.ids.tolist() == ids
            # agent_id reads back the one agent hosted, never a 0 a container does not mean.
            assert node.get_parameter('agent_id').value == (ids[0] if len(ids) == 1 else -1)
        finally:
            node.destroy_node()
        again = AgentNode(context=ros_context, parameter_overrides=[
            Parameter('scenario', value=str(path)), Parameter('agent_ids', value=ids)])
        try:
            assert again.controller.ids.tolist() == ids
        finally:
            again.destroy_node()


def test_a_parameter_without_a_type_is_one_line(tmp_path, ros_context, ros_domain, monkeypatch,
                                                capfd):
    """An empty array has no ROS type, so rclpy cannot declare it: through the Python API
    the error names the parameter; on the command line (``-p key:=[]``), ``--ros-args``."""
    from rclpy.parameter import Parameter

    from flock_swarm.core.errors import ScenarioError
    from flock_swarm.nodes.leader import LeaderNode, main
    path = tmp_path / 'small.yaml'
    path.write_text(yaml.safe_dump(SCENARIO))
    with pytest.raises(ScenarioError) as err:
        LeaderNode(context=ros_context, parameter_overrides=[
            Parameter('scenario', value=str(path)), Parameter('informed.ids')])
    assert err.value.key == 'informed.ids'
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    status = main(['leader', '--ros-args', '-p', f'scenario:={path}', '-p', 'informed.ids:=[]'])
    out, err_text = capfd.readouterr()
    assert status == 2 and out == ''
    assert err_text.startswith('leader: error: --ros-args: a parameter has no value of any '
                               'type') and err_text.count('\n') == 1


def test_the_parameter_tables_are_documented():
    """docs/ros.md's parameter table has a row for every parameter of the world's, the
    leader's and the agents' tables, naming the node kinds that have it."""
    from flock_swarm.nodes.parameters import COMMON_PARAMS
    text = (Path(__file__).resolve().parent.parent / 'docs' / 'ros.md').read_text()
    documented: dict[str, set[str]] = {}
    for kinds, names in re.findall(r'^\| ([a-z, ]+) \| ((?:`[a-z_]+`(?:, )?)+) \|', text, re.M):
        for name in re.findall(r'`([a-z_]+)`', names):
            documented.setdefault(name, set()).update(
                {'world', 'leader', 'agent'} if kinds == 'every node' else kinds.split(', '))
    common = {param.name for param in COMMON_PARAMS} - {'realtime_factor'}
    for kind in ('world', 'leader', 'agent'):
        module, _, table_name = NODE_KINDS[kind]
        table = getattr(importlib.import_module(f'flock_swarm.nodes.{module}'), table_name)
        for param in table:
            if param.name not in common:
                assert kind in documented.get(param.name, ()), (kind, param.name)
