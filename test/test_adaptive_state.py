"""A ROS run records a law's adaptive state as ``sim`` records it (issue 23, item 5).

The agents publish the state each command was computed with on ``agent_<i>/state``
(``sensor_msgs/JointState``, docs/ros.md); the world waits for it, records it in the bag, the
time series and the summary; ``analyze`` reads it back from the bag. Checked for Zhou's gains
``h_i`` (``zhou2012_sec51``, shortened) and for a plugin law with a scalar and a vector state,
in every layout: one process, ``--processes --container``, one process per agent.
"""

import json
import logging
import os
import textwrap

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from numpy.testing import assert_array_equal

from flock_swarm import contract
from flock_swarm.analysis import analyze, load_run
from flock_swarm.core import registry
from flock_swarm.core.run import simulate
from flock_swarm.nodes.controller import AgentController
from flock_swarm.presets import load
from flock_swarm.testing import assert_matches_sim, run_swarm
from test_analyze import PROCESS_KEYS, copy_bag
from test_plugins import install_plugins
from test_stepper import give_leader, leader_at, started

LOG = logging.getLogger('test_adaptive_state')
#: Zhou 2012 Section 5.1 (10 agents, fixed graph B, adaptive gains h_i), shortened to 100 steps.
ZHOU = ['duration=0.05']
#: The layouts of a ROS run: keyword arguments of assert_matches_sim.
LAYOUTS = {'one process': {},
           'processes, container': {'processes': True, 'container': True},
           'process per agent': {'processes': True}}
#: Wall-clock bound of one run (a hung run fails instead of blocking the suite).
RUN_TIMEOUT = 240.0

PLUGIN_SOURCE = '''
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import Law, require


@dataclass(frozen=True)
class IntegralPull(Law):
    """Velocity consensus and a PI pull towards the leader with an adaptive gain (a test law).

    u_i = sum_j (p_j - p_i) - k (q_i - q_l) - g_i (p_i - p_l) - ki e_i, with the adaptive
    state e_i' = p_i - p_l (a vector) and g_i' = rate ||p_i - p_l||^2 (a scalar); 2-D.
    """

    name: ClassVar[str] = 'integral_pull'
    state_summary: ClassVar[dict[str, str]] = {'g': 'pull_gain_final'}
    r: float = 4.0
    k: float = 1.0
    ki: float = 0.2
    rate: float = 0.5
    g0: float = 1.0

    @property
    def radius(self):
        return self.r

    def validate(self, ctx):
        require(ctx.dim == 2, 'dim', f'integral_pull is 2-D, got {ctx.dim}')

    def pair(self, qi, pi, qj, pj, w):
        return pj - pi

    def combine(self, q, p, s, leader, agents, dt):
        if leader is None:
            return s
        return (s - self.k * (q - leader.q) - agents.state['g'][:, None] * (p - leader.p)
                - self.ki * agents.state['e'])

    def initial_state(self, n):
        return {'e': np.zeros((n, 2)), 'g': np.full(n, self.g0)}

    def state_rate(self, q, p, leader, agents):
        if leader is None:
            return {'e': np.zeros_like(p), 'g': np.zeros(p.shape[0])}
        err = p - leader.p
        return {'e': err, 'g': self.rate * np.einsum('nk,nk->n', err, err)}
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """Install the plugin law (for this process and its children); return its scenario file."""
    site = tmp_path / 'site'
    install_plugins(site, laws=[('integral_pull', 'IntegralPull')], package='adaptive-plugins',
                    module='adaptive_plugins', source=PLUGIN_SOURCE)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(
        [str(site)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    registry.entries.cache_clear()
    registry.load.cache_clear()
    path = tmp_path / 'integral_pull.yaml'
    path.write_text(textwrap.dedent('''\
        name: integral_pull
        dim: 2
        n_agents: 4
        dt: 0.05
        duration: 1.0
        seed: 5
        record_every: 2
        protocol: {name: integral_pull, k: 1.0, ki: 0.2, rate: 0.5}
        informed: {select: first, count: 2}
        initial: {position_box: [[0, 4], [0, 4]], velocity_box: [[0, 1], [0, 1]]}
        leader: {model: constant_velocity, position: [2, 2], velocity: [1, 0]}
        '''))
    yield path
    registry.entries.cache_clear()
    registry.load.cache_clear()


# -- the contract and the decisions, without ROS -------------------------------------------


def test_state_labels_name_each_value_in_the_laws_order():
    shapes = {'h': (), 'e': (2,), 'm': (2, 2)}
    assert contract.state_labels(shapes) == ('h', 'e[0]', 'e[1]', 'm[0]', 'm[1]', 'm[2]',
                                             'm[3]')
    assert contract.state_slices(shapes) == (('h', (), slice(0, 1)), ('e', (2,), slice(1, 3)),
                                             ('m', (2, 2), slice(3, 7)))
    assert contract.state_labels({}) == ()
    # Optional topics of the contract: only for a law with adaptive state.
    plain = dict(contract.contract_topics(2))
    adaptive = dict(contract.contract_topics(2, '/team', state=True))
    assert '/agent_0/state' not in plain
    assert set(adaptive) - {f'/team{t}' if t != '/clock' else t for t in plain} == \
        {'/team/agent_0/state', '/team/agent_1/state'}
    assert adaptive['/team/agent_1/state'] == contract.STATE_TYPE == 'sensor_msgs/msg/JointState'
    match = contract.AGENT_TOPIC.match('/team/agent_12/state')
    assert (match['ns'], match['id'], match['kind']) == ('/team', '12', 'state')


def test_the_controller_tells_the_state_its_commands_were_computed_with():
    """Driven with sim's states, a container of three of Zhou's agents tells, at every step,
    the gains sim records at that step (before they advance)."""
    sc = load('zhou2012_sec51', ['duration=0.002', 'record_every=1'])
    ref = simulate(sc).series
    ids = [0, 2, 5]
    ctrl = AgentController(sc, ids, LOG, now=0.0)
    assert ctrl.state_labels == ('h',)
    for k in range(sc.steps + 1):
        leader = leader_at(sc, k)
        u = ctrl.command(ref['q'][k], ref['p'][k], leader)
        assert_array_equal(u, ref['u'][k][ids])
        assert_array_equal(ctrl.state_values(), ref['h'][k][ids][:, None])
    # The informed agents' gains grew; the others' stay h0.
    assert (ref['h'][-1][:3] > 1.0).all() and (ref['h'][-1][3:] == 1.0).all()


def test_the_world_waits_for_every_agents_state_and_records_it():
    """A lockstep step is complete with every command, the leader's state and every agent's
    state; the series records the states given, at their step."""
    sc = load('zhou2012_sec51', ['duration=0.002', 'record_every=1'])
    n = sc.n_agents
    st = started(sc)
    assert st.state_labels == ('h',)
    give_leader(st, leader_at(sc, 0), 0, 0.0)
    st.commands_all(0, np.zeros((n, sc.dim)))
    h0 = np.linspace(1.0, 2.0, n)
    for i in range(n - 1):
        st.agent_state(i, 0, [h0[i]])
        assert not st.complete()
    st.agent_state(n - 1, 0, [h0[-1]])
    assert st.complete()
    obs = st.close_step(False, 0.1)
    assert st.advance(obs.u)
    st.begin_step(0.1)
    # A state of the step just closed (a repeat) changes nothing.
    st.agent_state(0, 0, [99.0])
    assert st.state_in == set()
    assert_array_equal(st.run_log.rec.arrays()['h'], h0[None])


def test_a_state_missing_at_the_timeout_is_told_and_its_last_value_recorded(caplog):
    sc = load('zhou2012_sec51', ['duration=0.002', 'record_every=1'])
    n = sc.n_agents
    st = started(sc, step_timeout=1.0)
    for k in range(2):
        give_leader(st, leader_at(sc, k), k, 0.0)
        st.commands_all(k, np.zeros((n, sc.dim)))
        for i in range(n if k == 0 else n - 1):
            st.agent_state(i, k, [1.0 + k + i / 10])
        if k == 0:
            assert st.complete()
            obs = st.close_step(False, 0.0)
            st.advance(obs.u)
            st.begin_step(0.0)
    assert not st.complete()
    with caplog.at_level(logging.WARNING):
        st.close_step(True, 1.0)
    assert f'step 1: no adaptive state from agent(s) [{n - 1}]' in caplog.text
    h = st.run_log.rec.arrays()['h']
    assert_array_equal(h[1, :-1], 2.0 + np.arange(n - 1) / 10)
    assert h[1, -1] == h[0, -1] == 1.0 + (n - 1) / 10


@pytest.mark.ros
def test_the_world_rejects_a_state_with_other_labels_or_non_finite_values(ros_context,
                                                                          tmp_path):
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.world import WorldNode
    world = WorldNode(context=ros_context, parameter_overrides=[
        Parameter('scenario', value='zhou2012_sec51'), Parameter('record', value=False),
        Parameter('out_dir', value=str(tmp_path))])
    try:
        assert world.agent_state_topics == [f'/agent_{i}/state' for i in range(10)]
        world.stepper.start(0.0)
        world.stepper.begin_step(0.0)
        world.on_agent_state(3, (0, 'world', ('g',), (1.0,)))
        world.on_agent_state(3, (0, 'world', ('h',), (float('nan'),)))
        world.on_agent_state(3, (0, 'map', ('h',), (1.0,)))
        assert world.guard.counts() == {'frame': 1, 'malformed': 1, 'non_finite': 1}
        assert world.stepper.state_in == set()
        world.on_agent_state(3, (0, 'world', ('h',), (1.5,)))
        assert world.stepper.state_in == {3} and world.stepper.state['h'][3] == 1.5
    finally:
        world.destroy_node()


# -- through the nodes ----------------------------------------------------------------------


def assert_analysis_is_the_worlds(run, tmp_path) -> None:
    """``analyze`` of the run's bag gives the world's summary and series (state included)."""
    result = analyze(load_run(run.out / 'bag'), tmp_path / 'analysis', animate=False)
    world = run.summary
    for key in sorted(set(world) - PROCESS_KEYS):
        assert result.summary[key] == world[key], key
    series = run.timeseries()
    assert sorted(result.series) == sorted(series)
    for name, values in series.items():
        assert_array_equal(result.series[name], values, err_msg=name)


@pytest.mark.ros
@pytest.mark.parametrize('layout', LAYOUTS)
def test_zhou_matches_sim_in_every_layout(tmp_path, ros_domain, layout):
    """Zhou's gains h_i, recorded by the world from the agents: the run is sim's bit for bit,
    summary (``adaptive_gain_final``, ``min_pair_distance`` on the fixed graph) and series."""
    run = assert_matches_sim('zhou2012_sec51', tmp_path / 'run', ZHOU, domain_id=ros_domain,
                             timeout=RUN_TIMEOUT, **LAYOUTS[layout])
    sc = run.scenario
    h = run.timeseries()['h']
    assert h.shape == (sc.steps // sc.record_every + 1, sc.n_agents)
    assert run.summary['adaptive_gain_final'] == h[-1].tolist()
    assert h[-1][:3].min() > 1.0
    if layout == 'one process':
        assert_analysis_is_the_worlds(run, tmp_path)


@pytest.mark.ros
@pytest.mark.parametrize('layout', LAYOUTS)
def test_an_adaptive_plugin_law_matches_sim_in_every_layout(tmp_path, ros_domain, plugin,
                                                            layout):
    """A plugin's scalar and vector state (``g``: K x N, ``e``: K x N x 2) and its summary
    key, through the nodes as in sim."""
    run = assert_matches_sim(plugin, tmp_path / 'run', domain_id=ros_domain,
                             timeout=RUN_TIMEOUT, **LAYOUTS[layout])
    series = run.timeseries()
    assert series['e'].shape == (11, 4, 2) and series['g'].shape == (11, 4)
    assert run.summary['pull_gain_final'] == series['g'][-1].tolist()
    assert np.abs(series['e'][-1]).min() > 0.0


@pytest.mark.ros
def test_the_bag_holds_the_state_and_analyze_reads_it_back(tmp_path, ros_domain, plugin):
    """Every step's state of every agent in the bag (read by an independent MCAP reader),
    labelled as the contract says; analyze rebuilds the world's series and summary from it,
    also from a bag without the scenario (the labels then give the keys)."""
    run = run_swarm(plugin, tmp_path / 'run', ['record_every=1'], domain_id=ros_domain,
                    timeout=RUN_TIMEOUT)
    sc, series = run.scenario, run.timeseries()
    assert run.summary['status'] == 'completed' and run.summary['missed_commands'] == 0
    got = {}
    with open(run.out / 'bag' / 'bag_0.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        channels = reader.get_summary().channels.values()
        assert {c.topic for c in channels if c.topic.endswith('/state')} == \
            {f'/agent_{i}/state' for i in range(sc.n_agents)}
        for schema, channel, message, msg in reader.iter_decoded_messages(
                topics=[f'/agent_{i}/state' for i in range(sc.n_agents)]):
            assert schema.name == 'sensor_msgs/msg/JointState'
            assert msg.header.frame_id == 'world' and list(msg.name) == ['e[0]', 'e[1]', 'g']
            assert not msg.velocity and not msg.effort
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert message.log_time == stamp
            agent = int(contract.AGENT_TOPIC.match(channel.topic)['id'])
            got[(round(stamp / (sc.dt * 1e9)), agent)] = list(msg.position)
    assert len(got) == (sc.steps + 1) * sc.n_agents
    for (k, i), values in got.items():
        assert values == [*series['e'][k, i], series['g'][k, i]], (k, i)
    assert_analysis_is_the_worlds(run, tmp_path)
    bare = copy_bag(run.out / 'bag', tmp_path / 'bare', None)
    data = load_run(bare, radius=sc.law.radius)
    assert sorted(data.state) == ['e', 'g']
    assert_array_equal(data.state['e'], series['e'])
    assert_array_equal(data.state['g'], series['g'])


@pytest.mark.ros
def test_a_realtime_run_records_each_agents_latest_state(tmp_path, ros_domain, plugin):
    run = run_swarm(plugin, tmp_path / 'run', ['record_every=1'], domain_id=ros_domain,
                    timeout=RUN_TIMEOUT, mode='realtime')
    g = run.timeseries()['g']
    assert run.summary['status'] == 'completed'
    assert g.shape == (run.scenario.steps + 1, 4) and np.isfinite(g).all()
    # The gains start at g0 and only grow (g' >= 0): held, never taken back.
    assert (g[0] == 1.0).all() and (np.diff(g, axis=0) >= 0).all() and (g[-1] > 1.0).any()
    assert run.summary['pull_gain_final'] == g[-1].tolist()
    with open(run.out / 'summary.json') as f:
        assert json.load(f)['pull_gain_final'] == g[-1].tolist()
