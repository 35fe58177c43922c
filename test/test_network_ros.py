"""The network model (``network:``) in the ROS nodes: a lockstep run equals ``sim`` bit for bit.

Every host keeps the whole swarm's messages (every agent's odometry reaches it) and evaluates
its own agents on them; the world keeps the same messages to record the statistics. The draws
being keyed by the link, the layout does not matter. In realtime mode the model comes on top
of the real transport: the agents report what each command used, the world adds the age the
command had when applied. The statistics are on ``/swarm/metrics`` and ``analyze`` gets them
back from the bag.
"""

import math

import numpy as np
import pytest

from flock_swarm.analysis.bagrun import load_run
from flock_swarm.analysis.analyze_run import analyze
from flock_swarm.analysis.recompute import recompute
from flock_swarm.bag import BagReader
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.network import (STATISTICS, USAGE_LABELS, NetworkState, ReportedUse,
                                      neighbourhood_of)
from flock_swarm.core.scenario import realize
from flock_swarm.presets import prepare
from flock_swarm.testing import assert_matches_sim, run_swarm

#: Delay (uniform, 1 to 3 steps), loss, noise and a leader channel of its own on a small
#: demo swarm packed within each other's radius; a record every third step, so that the
#: statistics of several steps are folded into each record.
DEMO = ['n_agents=8', 'informed.count=3', 'duration=0.4', 'record_every=3',
        'initial.position_box=[[0, 8], [0, 8]]',
        'network={delay: {law: uniform, min: 0.02, max: 0.06}, loss: 0.2, '
        'noise: {position: 0.01, velocity: 0.005}, leader: {delay: 0.04, loss: 0.1}}']
#: The same with the delay compensation: every held state (the leader's too) extrapolated by
#: its age before the neighbours are decided.
DEMO_PREDICT = [*DEMO[:-1], DEMO[-1][:-1] + ', compensation: predict}']
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
@pytest.mark.parametrize('layout, overrides', [
    *((layout, DEMO) for layout in LAYOUTS), ('one process', DEMO_PREDICT)],
    ids=[*LAYOUTS, 'one process, predict'])
def test_delay_loss_and_noise_match_sim_in_every_layout(tmp_path, ros_domain, layout,
                                                        overrides):
    """``compensation: predict`` runs in the agents' controller as in sim: one layout is
    enough, the layouts themselves being checked without it."""
    run = assert_matches_sim('demo', tmp_path / 'run', overrides, domain_id=ros_domain, atol=0,
                             timeout=RUN_TIMEOUT, **LAYOUTS[layout])
    assert run.scenario.network.compensation == ('predict' if overrides is DEMO_PREDICT
                                                 else 'none')
    series = run.timeseries()
    # The model did act: messages were lost and the information used was old.
    assert 0.0 < run.summary['network_delivered'] < 1.0
    assert run.summary['network_age_max'] >= 0.04
    assert series['network_delivered'].shape == series['t'].shape == (8,)
    assert np.isnan(series['network_age_mean'][0])
    assert np.isfinite(series['network_age_mean'][1:]).all()
    # Live on /swarm/metrics (in the bag), of the steps since the message before ...
    told = metrics_in_bag(run.out / 'bag')
    assert told and all(set(STATISTICS) <= set(values) for values in told)
    assert all(0.0 < float(values['network_delivered']) < 1.0 for values in told[1:])
    # ... and analyze counts them again from the bag alone, as sim does.
    analysed, _ = recompute(load_run(run.out / 'bag'))
    for key in STATISTICS:
        np.testing.assert_array_equal(analysed[key], series[key])


def metrics_in_bag(bag) -> list[dict[str, str]]:
    """Return the values of every ``/swarm/metrics`` message of a bag, in order."""
    return [{kv.key: kv.value for kv in msg.status[0].values}
            for _, msg in BagReader(bag).decoded(['/swarm/metrics'])]


@pytest.mark.ros
def test_zhou_on_its_fixed_graph_under_an_input_delay_matches_sim(tmp_path, ros_domain):
    """Zhou's gains advance on the leader's held state in each host as in sim."""
    run = assert_matches_sim('zhou2012_sec51', tmp_path / 'run', ZHOU, domain_id=ros_domain,
                             atol=0, timeout=RUN_TIMEOUT)
    assert 0.0 < run.summary['network_delivered'] < 1.0
    assert run.summary['network_age_max'] > 0.0


@pytest.mark.parametrize('overrides', [DEMO, DEMO_PREDICT], ids=['none', 'predict'])
def test_an_observer_counts_the_statistics_control_counts(overrides):
    """The world's bookkeeping (:meth:`NetworkState.observe`) gives the statistics of
    :meth:`NetworkState.control` of every agent, step by step and per record (with the
    prediction deciding the neighbours too)."""
    sc, _ = prepare('demo', overrides, None)
    agents = realize(sc).agents
    q = np.random.default_rng(3).uniform(0.0, 8.0, (sc.n_agents, sc.dim))
    ruler, observer = (NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                                    neighbourhood_of(sc.graph_type, False)) for _ in range(2))
    leader = LeaderState(np.zeros(2), np.ones(2), np.zeros(2))
    none = np.zeros(sc.n_agents, dtype=bool)
    # Moving: the prediction moves the held positions, so it changes who is a neighbour.
    p = np.full_like(q, 0.5)
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


#: Realtime: a fixed delay of 3 steps and loss 0.3 on eight agents within each other's radius
#: (56 directed links a step), 2 simulated seconds at the realtime factor 1.
REALTIME = ['n_agents=8', 'informed.count=3', 'duration=2', 'record_every=5',
            'initial.position_box=[[0, 2], [0, 2]]', 'network={delay: 0.06, loss: 0.3}']


@pytest.mark.ros
def test_realtime_applies_the_model_on_top_of_the_transport(tmp_path, ros_domain):
    """The ages recorded are the modelled ones plus the real transport's (at least one step:
    a command answers odometry already published), the delivered fraction the model's."""
    run = run_swarm('demo', tmp_path / 'run', REALTIME, domain_id=ros_domain,
                    timeout=RUN_TIMEOUT, mode='realtime')
    summary, series, dt = run.summary, run.timeseries(), run.scenario.dt
    assert summary['status'] == 'completed' and summary['mode'] == 'realtime'
    ages = series['network_age_mean'][np.isfinite(series['network_age_mean'])]
    oldest = series['network_age_max'][np.isfinite(series['network_age_max'])]
    assert ages.size >= series['t'].size - 2
    # The modelled delay (3 steps) and one step of transport at least; the modelled age is
    # at most max_age (3 + 1 steps), and the transport here takes well under 0.5 s.
    assert (ages >= 0.06 + dt - 1e-12).all() and (oldest >= ages).all()
    assert summary['network_age_max'] < 0.08 + 0.5
    # Each message the agents sent was lost with probability 0.3, whatever the transport
    # did: the delivered fraction of their reports is within 4.5 sigma of 0.7.
    reports = BagReader(tmp_path / 'run' / 'bag')
    got = sent = 0
    for i in range(8):
        for _, msg in reports.decoded([f'/agent_{i}/network']):
            assert tuple(msg.name) == USAGE_LABELS
            got, sent = got + msg.position[0], sent + msg.position[1]
    assert sent >= 2000
    assert abs(got / sent - 0.7) <= 4.5 * math.sqrt(0.7 * 0.3 / sent)
    assert abs(summary['network_delivered'] - 0.7) < 0.05
    # The world told them live, and analyze takes them from there (a realtime run cannot
    # be recounted: the ages are the transport's).
    told = metrics_in_bag(tmp_path / 'run' / 'bag')
    assert told and all(set(STATISTICS) <= set(values) for values in told)
    analysis = analyze(load_run(tmp_path / 'run' / 'bag'), tmp_path / 'analysis', animate=False)
    analysed = analysis.series
    assert (tmp_path / 'analysis' / 'network.png').stat().st_size > 10_000
    assert np.nanmin(analysed['network_age_mean']) >= 0.06 + dt - 1e-12
    assert abs(np.nanmean(analysed['network_delivered']) - 0.7) < 0.05


def test_each_agents_usage_adds_up_to_the_statistics_of_control():
    """What each agent reports in realtime (:meth:`NetworkState.usage`) is its share of the
    step's counts, whichever agents a host evaluates."""
    sc, _ = prepare('demo', DEMO, None)
    agents = realize(sc).agents
    q = np.random.default_rng(5).uniform(0.0, 8.0, (sc.n_agents, sc.dim))
    p = np.zeros_like(q)
    net = NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                       neighbourhood_of(sc.graph_type, False))
    leader = LeaderState(np.zeros(2), np.ones(2), np.zeros(2))
    split = np.arange(3), np.arange(3, sc.n_agents)
    for k in range(10):
        q = q + 0.01 * k
        net.send(k, q, p, leader, disk_graph(q, sc.law.radius, sc.law.strict_radius),
                 agents.informed)
        net.control(None, q, p, agents, sc.dt)
        rows = net.usage(np.arange(sc.n_agents), q, p)
        np.testing.assert_array_equal(np.concatenate([net.usage(ids, q, p) for ids in split]),
                                      rows)
        got, total, age_sum, links, age_max = net.counts
        assert rows[:, 0].sum() == got and rows[:, 1].sum() == total
        assert rows[:, 2].sum() == age_sum and rows[:, 3].sum() == links
        assert rows[:, 4].max() == age_max


def test_the_world_adds_the_age_a_command_had_when_applied():
    use = ReportedUse(2)
    # Agent 0's command of step 5 used 3 states (ages 1, 2, 3) of 4 messages sent it at 5,
    # of which 3 arrived; agent 1 reported nothing.
    use.report(0, 5, [3, 4, 6, 3, 3])
    assert use.step(7, np.array([5, 4])) == [3, 4, 6 + 3 * 2, 3, 3 + 2]
    # Held one step more: the states are older still, the deliveries not counted again.
    assert use.step(8, np.array([5, -1])) == [0, 0, 6 + 3 * 3, 3, 3 + 3]
    # A zero command (stale, -1) used nothing.
    assert use.step(9, np.array([-1, -1])) == [0, 0, 0, 0, -1]
