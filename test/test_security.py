"""The SROS2 policy (config/sros2_policy.xml): one enclave per node, exactly the node's topics.

The expected topics are built here from the names in :mod:`flock_swarm.contract`, and
checked once more against the ROS graph of live world, leader and agent nodes; the policy is
read with an XML parser of its own, not with the generator that wrote it.
"""

import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest

from flock_swarm import contract
from flock_swarm.security import main as security_main, policy

ROOT = Path(__file__).resolve().parent.parent
POLICY = ROOT / 'config' / 'sros2_policy.xml'
#: The swarm the shipped policy is for: the demo's (scripts/demo flies su2009_fig6).
N_AGENTS = 10
#: What any rclpy node publishes and the services it offers, besides the swarm's own topics.
ROSOUT, PARAMETER_EVENTS = '/rosout', '/parameter_events'
PARAMETER_SERVICES = ('describe_parameters', 'get_parameter_types', 'get_parameters',
                      'get_type_description', 'list_parameters', 'set_parameters',
                      'set_parameters_atomically')


def absolute(name: str) -> str:
    """Return a topic name resolved in the root namespace, as the nodes run."""
    return name if name.startswith('/') else '/' + name


def expected(n: int) -> dict[str, tuple[set, set]]:
    """Return ``{node: (published, subscribed)}``, from the topic names of the contract."""
    odom = {contract.odom_topic(i) for i in range(n)}
    cmds = {contract.cmd_topic(i) for i in range(n)}
    # Each agent's adaptive state (a topic only for a law with one): to the world.
    states = {contract.state_topic(i) for i in range(n)}
    # Each agent's network report (realtime with a network: section only): to the world.
    reports = {contract.network_topic(i) for i in range(n)}
    # A robot plant's velocity commands (docs/plants.md): to the world.
    twists = {contract.cmd_vel_topic(i) for i in range(n)}
    leader = {contract.LEADER_ODOM, contract.LEADER_ACCEL}
    # The batched transport's clouds: the swarm's state from the world, each host's commands.
    clouds = ({contract.STATES}, {contract.COMMANDS})
    status = {contract.STATUS}  # the world announces the end of its run to the others
    # The world also publishes the run's scenario (latched, recorded at t = 0), and the
    # obstacle map of a scenario with obstacles (the same).
    # A law or leader model failing mid-run is reported on swarm/faults, to the world.
    faults = {contract.FAULTS}
    # The metrics go to /diagnostics too (rqt_robot_monitor, diagnostic_aggregator).
    nodes = {'world': ({contract.CLOCK, contract.MARKERS, contract.METRICS, contract.SCENARIO,
                        contract.OBSTACLES, contract.DIAGNOSTICS} | odom | clouds[0] | status,
                       cmds | clouds[1] | states | reports | twists | leader | faults),
             'leader': (leader | faults, {contract.CLOCK} | status)}
    for i in range(n):
        nodes[f'agent_{i}'] = ({contract.cmd_topic(i), contract.state_topic(i),
                                contract.network_topic(i), contract.cmd_vel_topic(i)}
                               | clouds[1] | faults, odom | clouds[0] | leader | status)
    return {node: ({absolute(t) for t in pub} | {ROSOUT, PARAMETER_EVENTS},
                   {absolute(t) for t in sub}) for node, (pub, sub) in nodes.items()}


def read_policy(path: Path) -> dict[str, dict]:
    """Return ``{enclave path: {'node', 'ns', 'publish', 'subscribe', 'reply'}}`` of a policy.

    Fails on anything but the SROS2 0.2.0 elements the swarm needs (ALLOW rules only).
    """
    root = ElementTree.parse(path).getroot()
    assert root.tag == 'policy' and root.get('version') == '0.2.0'
    (enclaves,) = list(root)
    assert enclaves.tag == 'enclaves'
    out = {}
    for enclave in enclaves:
        assert enclave.tag == 'enclave'
        (profiles,) = list(enclave)
        (profile,) = list(profiles)
        assert profile.tag == 'profile'
        rules = {'publish': set(), 'subscribe': set(), 'reply': set()}
        for group in profile:
            assert group.tag in ('topics', 'services'), group.tag
            assert set(group.attrib.values()) == {'ALLOW'}, group.attrib
            for rule in group.attrib:
                rules[rule] |= {item.text for item in group}
        out[enclave.get('path')] = dict(node=profile.get('node'), ns=profile.get('ns'),
                                        **rules)
    return out


def test_shipped_policy_is_the_generated_one(capsys):
    """config/sros2_policy.xml is ``python -m flock_swarm.security 10``, verbatim."""
    assert security_main([str(N_AGENTS)]) == 0
    assert capsys.readouterr().out == POLICY.read_text() == policy(N_AGENTS)


def test_policy_grants_each_node_exactly_its_topics():
    """One enclave per node (/flock_swarm/<node>); its grants are the node's topics."""
    read = read_policy(POLICY)
    want = expected(N_AGENTS)
    assert set(read) == {f'/flock_swarm/{node}' for node in want}
    for node, (published, subscribed) in want.items():
        grant = read[f'/flock_swarm/{node}']
        assert (grant['node'], grant['ns']) == (node, '/')
        assert {absolute(t) for t in grant['publish']} == published, node
        assert {absolute(t) for t in grant['subscribe']} == subscribed, node
        assert grant['reply'] == {f'~{name}' for name in PARAMETER_SERVICES}, node


@pytest.mark.ros
@pytest.mark.parametrize('scenario, adaptive', [('su2009_fig6', False),
                                                ('zhou2012_sec51', True)])
def test_policy_matches_the_topics_of_live_nodes(tmp_path, ros_domain, scenario, adaptive):
    """World, leader and an agent as built: the ROS graph shows exactly the policy's names
    (the agents' adaptive-state topics only for a law with adaptive state, Zhou's)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.agent import AgentNode
    from flock_swarm.nodes.leader import LeaderNode
    from flock_swarm.nodes.world import WorldNode
    read = read_policy(POLICY)
    context = Context()
    rclpy.init(context=context, domain_id=ros_domain)
    base = [Parameter('scenario', value=scenario)]
    # A lockstep run has no network reports (realtime with a network: section only); the
    # presets have no obstacles: their world publishes no map.
    optional = {absolute(contract.network_topic(i)) for i in range(N_AGENTS)}
    optional.add(absolute(contract.OBSTACLES))
    # Nor velocity commands (a robot plant commanded by velocity only, docs/plants.md).
    optional |= {absolute(contract.cmd_vel_topic(i)) for i in range(N_AGENTS)}
    # Nor the batched transport's clouds (transport: batched only, docs/ros.md).
    optional |= {absolute(contract.STATES), absolute(contract.COMMANDS)}
    if not adaptive:
        optional |= {absolute(contract.state_topic(i)) for i in range(N_AGENTS)}
    nodes = []
    try:
        nodes.append(WorldNode(context=context, parameter_overrides=base + [
            Parameter('record', value=False), Parameter('out_dir', value=str(tmp_path))]))
        nodes.append(LeaderNode(context=context, parameter_overrides=base))
        nodes.append(AgentNode(node_name='agent_3', context=context,
                               parameter_overrides=base + [Parameter('agent_id', value=3)]))
        probe = nodes[0]

        def graph(name: str) -> tuple[set, set, set]:
            return ({t for t, _ in probe.get_publisher_names_and_types_by_node(name, '/')},
                    {t for t, _ in probe.get_subscriber_names_and_types_by_node(name, '/')},
                    {t for t, _ in probe.get_service_names_and_types_by_node(name, '/')})

        for node in nodes:
            name = node.get_name()
            grant = read[f'/flock_swarm/{name}']
            want = ({absolute(t) for t in grant['publish']} - optional,
                    {absolute(t) for t in grant['subscribe']} - optional,
                    {f'/{name}/{s[1:]}' for s in grant['reply']})
            deadline = time.monotonic() + 10.0
            while graph(name) != want and time.monotonic() < deadline:
                time.sleep(0.05)
            assert graph(name) == want, name
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
