"""The network model (``network:``) in the ROS nodes: a lockstep run equals ``sim`` bit for bit.

Every host keeps the whole swarm's messages (every agent's odometry reaches it) and evaluates
its own agents on them; the world keeps the same messages to record the statistics. The draws
being keyed by the link, the layout does not matter. Realtime mode refuses the section.
"""

import subprocess
import sys

import numpy as np
import pytest

from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.network import NetworkState, neighbourhood_of
from flock_swarm.core.scenario import realize
from flock_swarm.presets import prepare
from flock_swarm.testing import assert_matches_sim

#: Delay (uniform, 1 to 3 steps), loss, noise and a leader channel of its own on a small
#: demo swarm packed within each other's radius; a record every third step, so that the
#: statistics of several steps are folded into each record.
DEMO = ['n_agents=8', 'informed.count=3', 'duration=0.4', 'record_every=3',
        'initial.position_box=[[0, 8], [0, 8]]',
        'network={delay: {law: uniform, min: 0.02, max: 0.06}, loss: 0.2, '
        'noise: {position: 0.01, velocity: 0.005}, leader: {delay: 0.04, loss: 0.1}}']
#: Zhou's law on its fixed graph with adaptive gains, under the input delay model.
ZHOU = ['duration=0.05', 'network={delay: 0.005, loss: 0.1, leader: {delay: 0.01}, '
        'model: input}']
#: The layouts of a ROS run: keyword arguments of assert_matches_sim.
LAYOUTS = {'one process': {},
           'processes, container': {'processes': True, 'container': True},
           'process per agent': {'processes': True}}
#: Wall-clock bound of one run (a hung run fails instead of blocking the suite).
RUN_TIMEOUT = 240.0


@pytest.mark.ros
@pytest.mark.parametrize('layout', LAYOUTS)
def test_delay_loss_and_noise_match_sim_in_every_layout(tmp_path, ros_domain, layout):
    run = assert_matches_sim('demo', tmp_path / 'run', DEMO, domain_id=ros_domain, atol=0,
                             timeout=RUN_TIMEOUT, **LAYOUTS[layout])
    series = run.timeseries()
    # The model did act: messages were lost and the information used was old.
    assert 0.0 < run.summary['network_delivered'] < 1.0
    assert run.summary['network_age_max'] >= 0.04
    assert series['network_delivered'].shape == series['t'].shape == (8,)
    assert np.isnan(series['network_age_mean'][0])
    assert np.isfinite(series['network_age_mean'][1:]).all()


@pytest.mark.ros
def test_zhou_on_its_fixed_graph_under_an_input_delay_matches_sim(tmp_path, ros_domain):
    """Zhou's gains advance on the leader's held state in each host as in sim."""
    run = assert_matches_sim('zhou2012_sec51', tmp_path / 'run', ZHOU, domain_id=ros_domain,
                             atol=0, timeout=RUN_TIMEOUT)
    assert 0.0 < run.summary['network_delivered'] < 1.0
    assert run.summary['network_age_max'] > 0.0


def test_realtime_mode_refuses_an_active_section_in_one_line(tmp_path):
    from flock_swarm.nodes.harness import resolve_scenario
    with pytest.raises(ScenarioError, match='^network: not applied in realtime mode yet'):
        resolve_scenario('demo', ['network={delay: 0.04}'], None, tmp_path / 'rt',
                         mode='realtime')
    # Lockstep takes it, and realtime takes an inactive section.
    resolve_scenario('demo', ['network={delay: 0.04}'], None, tmp_path / 'ls')
    resolve_scenario('demo', ['network={delay: 0}'], None, tmp_path / 'zero', mode='realtime')
    assert (tmp_path / 'ls' / 'scenario.yaml').is_file()
    assert (tmp_path / 'zero' / 'scenario.yaml').is_file()


def test_swarm_refuses_realtime_with_a_network_before_starting_a_node(tmp_path):
    proc = subprocess.run(
        [sys.executable, '-m', 'flock_swarm.cli.swarm', 'demo', '--mode', 'realtime',
         '--out', str(tmp_path / 'out'), '--set', 'network={loss: 0.1}'],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        'swarm: error: network: not applied in realtime mode yet: run it in lockstep mode or '
        'with sim (docs/network.md)']


def test_an_observer_counts_the_statistics_control_counts():
    """The world's bookkeeping (:meth:`NetworkState.observe`) gives the statistics of
    :meth:`NetworkState.control` of every agent, step by step and per record."""
    sc, _ = prepare('demo', DEMO, None)
    agents = realize(sc).agents
    q = np.random.default_rng(3).uniform(0.0, 8.0, (sc.n_agents, sc.dim))
    p = np.zeros_like(q)
    ruler, observer = (NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                                    neighbourhood_of(sc.graph_type, False)) for _ in range(2))
    leader = LeaderState(np.zeros(2), np.ones(2), np.zeros(2))
    none = np.zeros(sc.n_agents, dtype=bool)
    for k in range(12):
        q = q + 0.01 * k
        edges = disk_graph(q, sc.law.radius, sc.law.strict_radius)
        ruler.send(k, q, p, leader, edges, agents.informed)
        observer.send(k, q, p, leader, edges, none)
        expected = ruler.control(None, q, p, agents, sc.dt)[1]
        np.testing.assert_array_equal(list(observer.observe(q, p, sc.dt).values()),
                                      list(expected.values()))
        if k % 4 == 3:
            np.testing.assert_array_equal(list(observer.recorded(sc.dt).values()),
                                          list(ruler.recorded(sc.dt).values()))


@pytest.mark.ros
def test_a_node_started_in_realtime_refuses_an_active_section(tmp_path, ros_context):
    """A node started by hand (``ros2 run``), not through ``swarm``, refuses it too."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.harness import resolve_scenario
    from flock_swarm.nodes.leader import LeaderNode
    path = resolve_scenario('demo', ['n_agents=3', 'informed.count=1', 'network={loss: 0.1}'],
                            None, tmp_path)
    with pytest.raises(ScenarioError, match='^network: not applied in realtime mode yet'):
        LeaderNode(context=ros_context, parameter_overrides=[
            Parameter('scenario', value=str(path)), Parameter('mode', value='realtime')])
    node = LeaderNode(context=ros_context, parameter_overrides=[
        Parameter('scenario', value=str(path)), Parameter('mode', value='lockstep')])
    try:
        assert node.scenario.network.active
    finally:
        node.destroy_node()
