"""The network model (``network:``, :mod:`flock_swarm.core.network`): its validation, its
semantics, its layout-independent draws, the delay compensation, and the oracles of the
linear consensus law and of the delay's drag on a moving flock."""

import dataclasses

import numpy as np
import pytest
import yaml

from flock_swarm.core import delay_drag
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.laws import linear
from flock_swarm.core.laws.base import AgentData
from flock_swarm.core.laws.evaluation import swarm_control
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.network import (LEADER, NetworkState, neighbourhood_of, parse_network,
                                      uniforms)
from flock_swarm.core.run import simulate
from flock_swarm.core.scenario import parse_scenario, realize
from flock_swarm.presets import load, preset_names

DT = 0.01


# --------------------------------------------------------------------------------------------
# The section


def test_absent_or_zero_section_is_inactive():
    assert not parse_network(None, DT).active
    zero = {'delay': 0, 'loss': 0.0, 'noise': {'position': 0, 'velocity': 0}, 'period': 1,
            'leader': {'delay': 0.0, 'loss': {'model': 'bernoulli', 'p': 0}},
            'model': 'input'}
    assert not parse_network(zero, DT).active


def test_times_become_steps():
    uniform = {'law': 'uniform', 'min': 0.02, 'max': 0.05}
    spec = parse_network({'delay': 0.1, 'leader': {'delay': uniform}}, DT)
    assert (spec.agents.delay.law, spec.agents.delay.low, spec.agents.delay.high) == \
        ('fixed', 10, 10)
    assert (spec.leader.delay.low, spec.leader.delay.high) == (2, 5)
    # Default max_age: the oldest lossless age plus one period (one lost refresh survives).
    assert spec.max_age == 10 + 1
    geo = parse_network({'delay': {'law': 'geometric', 'mean': 0.03, 'max': 0.2},
                         'max_age': 0.5}, DT)
    assert geo.agents.delay.p == pytest.approx(1 / 4) and geo.agents.delay.high == 20
    assert geo.max_age == 50


@pytest.mark.parametrize('section, key', [
    ({'delay': 0.015}, 'network.delay'),
    ({'delay': -0.1}, 'network.delay'),
    ({'delay': 'long'}, 'network.delay'),
    ({'delay': {'law': 'normal'}}, 'network.delay.law'),
    ({'delay': {'law': 'uniform', 'min': 0.05}}, 'network.delay.max'),
    ({'delay': {'law': 'uniform', 'min': 0.05, 'max': 0.02}}, 'network.delay.max'),
    ({'delay': {'law': 'geometric', 'max': 0.1}}, 'network.delay.mean'),
    ({'delay': {'law': 'fixed', 'value': 0.1, 'extra': 1}}, 'network.delay.extra'),
    ({'loss': 1.5}, 'network.loss'),
    ({'loss': {'model': 'gilbert_elliott', 'p_good_bad': 0.1}}, 'network.loss.p_bad_good'),
    ({'loss': {'model': 'gilbert_elliott', 'p_good_bad': 0.1, 'p_bad_good': 0.5,
               'loss_bad': 2}}, 'network.loss.loss_bad'),
    ({'loss': {'model': 'burst'}}, 'network.loss.model'),
    ({'noise': {'position': -1}}, 'network.noise.position'),
    ({'noise': {'heading': 1}}, 'network.noise.heading'),
    ({'period': 0}, 'network.period'),
    ({'period': 1.5}, 'network.period'),
    ({'model': 'output'}, 'network.model'),
    ({'compensation': 'extrapolate'}, 'network.compensation'),
    ({'compensation': ['predict']}, 'network.compensation'),
    ({'delay': 0.1, 'max_age': 0.05}, 'network.max_age'),
    ({'leader': {'delay': 0.001}}, 'network.leader.delay'),
    ({'leader': {'model': 'input'}}, 'network.leader.model'),
    ({'latency': 1}, 'network.latency'),
    ([1, 2], 'network'),
])
def test_invalid_values_name_their_key(section, key):
    with pytest.raises(ScenarioError) as err:
        parse_network(section, DT)
    assert err.value.key == key
    assert '\n' not in str(err.value)


def test_the_scenario_reads_the_section_and_sim_refuses_bad_values_in_one_line():
    sc = load('demo', ['network={delay: 0.04, loss: 0.05}'])
    assert sc.network.active and sc.network.agents.delay.low == 2
    with pytest.raises(ScenarioError, match='network.delay'):
        load('demo', ['network={delay: 0.03}'])


# --------------------------------------------------------------------------------------------
# The generator


def test_draws_are_pure_functions_of_the_link():
    receiver, sender = np.arange(200) % 17, np.arange(200) // 17
    keep = receiver != sender  # swapping the two ends of a link j -> j changes nothing
    receiver, sender = receiver[keep], sender[keep]
    whole = uniforms(7, 2, 41, receiver, sender)
    part = uniforms(7, 2, 41, receiver[50:80][::-1], sender[50:80][::-1])
    np.testing.assert_array_equal(part, whole[50:80][::-1])
    assert np.all((whole >= 0) & (whole < 1))
    # Seed, stream, step, receiver and sender all change the draw.
    for other in (uniforms(8, 2, 41, receiver, sender), uniforms(7, 3, 41, receiver, sender),
                  uniforms(7, 2, 42, receiver, sender), uniforms(7, 2, 41, sender, receiver)):
        assert np.mean(other == whole) < 0.05


def run_with_states(sc):
    """Return the result of ``sc`` recorded at every step."""
    return simulate(dataclasses.replace(sc, record_every=1))


def replay_rows(sc, series, ids):
    """Feed ``sc``'s recorded true states to a :class:`NetworkState`; return ``u`` of ``ids``.

    What the agents' controller does: it receives every agent's state and the leader's, and
    evaluates the agents it hosts.
    """
    real = realize(sc)
    net = NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                       neighbourhood_of(sc.graph_type, sc.law.all_pairs),
                       sc.law.coupling_weight)
    hosted = np.zeros(sc.n_agents, dtype=bool)
    hosted[ids] = True
    group = real.agents.subset(ids)
    rows = []
    for k in range(series['t'].size):
        q, p = series['q'][k], series['p'][k]
        leader = LeaderState(series['leader_q'][k], series['leader_p'][k],
                             series['leader_a'][k])
        edges = disk_graph(q, sc.law.radius, sc.law.strict_radius)
        net.send(k, q, p, leader, edges, series['informed'][k], receivers=hosted)
        rows.append(net.control(ids, q, p, group, sc.dt)[0])
    return np.array(rows)


@pytest.mark.parametrize('model, compensation', [
    ('communication', 'none'), ('input', 'none'), ('communication', 'predict'),
    ('input', 'predict')])
def test_a_subset_of_receivers_gets_sim_rows_bit_for_bit(model, compensation):
    """The controller's path (a subset of the agents, their links only) equals ``sim``."""
    sc = load('demo', ['duration=0.6', 'network={delay: {law: uniform, min: 0, max: 0.1}, '
                       'loss: {model: gilbert_elliott, p_good_bad: 0.2, p_bad_good: 0.5, '
                       'loss_bad: 0.8}, noise: {position: 0.05, velocity: 0.02}, '
                       'leader: {delay: 0.04, loss: 0.2, noise: {velocity: 0.1}}, '
                       f'model: {model}, compensation: {compensation}}}'])
    assert sc.network.compensation == compensation
    series = run_with_states(sc).series
    ids = np.array([1, 4, 5, 11, 20, 29])
    rows = replay_rows(sc, series, ids)
    np.testing.assert_array_equal(rows, series['u'][:, ids])
    others = np.setdiff1d(np.arange(sc.n_agents), ids)
    np.testing.assert_array_equal(replay_rows(sc, series, others), series['u'][:, others])


# --------------------------------------------------------------------------------------------
# Semantics


def two_agents(network, steps=12):
    """Return a NetworkState of two linked agents fed ``steps`` steps of ``q = (k, -k)``."""
    spec = parse_network(yaml.safe_load(network), DT)
    net = NetworkState(spec, 0, 2, 2, load('demo').law, 'fixed')
    edge = dataclasses.replace(disk_graph(np.zeros((2, 2)), 1.0), weight=np.ones(1))
    leader = LeaderState(np.zeros(2), np.zeros(2), np.zeros(2))
    ages = []
    for k in range(steps):
        q = np.array([[k, 0.0], [-k, 0.0]])
        net.send(k, q, np.zeros((2, 2)), leader, edge, np.zeros(2, dtype=bool))
        held = net.links.held(k, None)
        if held.receiver.size:
            # The state held is the one of its sending step.
            sign = np.where(held.sender == 0, 1.0, -1.0)
            np.testing.assert_array_equal(held.q[:, 0], sign * (k - held.age))
        ages.append(held.age.tolist())
    return ages


def test_a_fixed_delay_holds_nothing_before_the_first_message_then_that_old_state():
    ages = two_agents('{delay: 0.03}')
    assert ages[:3] == [[]] * 3
    assert ages[3:] == [[3, 3]] * 9


def test_a_period_refreshes_every_m_steps():
    ages = two_agents('{delay: 0.01, period: 3}')
    assert ages[:1] == [[]]
    assert [a[0] for a in ages[1:]] == [1, 2, 3] * 3 + [1, 2]


def test_max_age_drops_old_information():
    # max_age 0: only the messages of the step itself; a lost one leaves nothing held.
    ages = two_agents('{loss: 0.5, max_age: 0}', steps=40)
    assert all(age == 0 for a in ages for age in a)
    assert 0 < sum(len(a) for a in ages) < 80
    # The default keeps a state through one lost refresh: loss 1 leaves nothing ever.
    assert parse_network({'loss': 1.0}, DT).max_age == 1
    assert two_agents('{loss: 1.0}', steps=4) == [[]] * 4


def test_loss_one_makes_every_agent_isolated():
    """Loss 1 on every link: each agent's input is the law without any neighbour."""
    sc = load('demo', ['duration=1', 'network={loss: 1.0}'])
    result = run_with_states(sc)
    series, real = result.series, realize(sc)
    for k in range(series['t'].size):
        leader = LeaderState(series['leader_q'][k], series['leader_p'][k],
                             series['leader_a'][k])
        alone = sc.law.combine(series['q'][k], series['p'][k],
                               np.zeros((sc.n_agents, sc.dim)), leader, real.agents, sc.dt)
        np.testing.assert_array_equal(series['u'][k], alone)
    assert np.all(series['network_delivered'] == 0.0)
    assert np.all(np.isnan(series['network_age_mean']))
    assert result.summary['network_delivered'] == 0.0
    assert result.summary['network_age_mean'] is None


@pytest.mark.parametrize('loss', [
    {'model': 'bernoulli', 'p': 0.3},
    {'model': 'gilbert_elliott', 'p_good_bad': 0.1, 'p_bad_good': 0.3, 'loss_good': 0.05,
     'loss_bad': 0.9}])
def test_the_delivered_fraction_is_within_its_binomial_interval(loss):
    """Over L independent links a step's delivered count is binomial(L, 1 - p).

    For Gilbert-Elliott ``p`` is the stationary loss ``pi_b loss_bad + (1 - pi_b) loss_good``
    with ``pi_b = p_gb / (p_gb + p_bg)``: each link's chain starts in it and stays in it.
    """
    spec = parse_network({'loss': loss}, DT)
    lo = spec.agents.loss
    p = lo.p if lo.model == 'bernoulli' else \
        lo.bad_fraction * lo.loss_bad + (1 - lo.bad_fraction) * lo.loss_good
    n = 150
    net = NetworkState(spec, 11, n, 2, load('demo').law, 'fixed')
    i, j = np.triu_indices(n, 1)
    edges = dataclasses.replace(disk_graph(np.zeros((1, 2)), 1.0), n=n, i=i, j=j,
                                weight=np.ones(i.size))
    links = 2 * i.size
    half = 4.0 * np.sqrt(p * (1 - p) / links)  # 4 sigma: a false alarm 6e-5 per check
    leader = LeaderState(np.zeros(2), np.zeros(2), np.zeros(2))
    for k in range(3):
        net.send(k, np.zeros((n, 2)), np.zeros((n, 2)), leader, edges,
                 np.zeros(n, dtype=bool))
        got, total = net.links.delivered(None)
        assert total == links
        assert abs(got / total - (1 - p)) < half


def test_the_leader_channel_reaches_informed_agents_only():
    spec = parse_network({'leader': {'delay': 0.02}}, DT)
    net = NetworkState(spec, 0, 3, 2, load('demo').law, 'disk')
    none = disk_graph(np.array([[0.0, 0], [100, 0], [200, 0]]), 1.0)
    for k in range(4):
        net.send(k, np.zeros((3, 2)), np.zeros((3, 2)),
                 LeaderState(np.full(2, float(k)), np.zeros(2), np.zeros(2)), none,
                 np.array([True, False, True]))
    held = net.leader_links.held(3, None)
    assert held.age.tolist() == [2, 2]
    assert held.receiver.tolist() == [0, 2] and set(held.sender.tolist()) == {LEADER}
    np.testing.assert_array_equal(held.q, [[1, 1], [1, 1]])


# --------------------------------------------------------------------------------------------
# Oracles of the linear law


@pytest.mark.parametrize('name', sorted(preset_names()))
def test_an_all_zero_section_is_bit_identical_to_none(name):
    dt = load(name).dt
    short = f'duration={10 * dt!r}'
    zero = 'network={delay: 0, loss: 0, noise: {position: 0, velocity: 0}, period: 1, ' \
        'leader: {delay: 0, loss: 0}, model: input}'
    plain = simulate(load(name, [short]))
    same = simulate(load(name, [short, zero]))
    for result in (plain, same):
        result.summary.pop('wall_time_s')
    assert same.summary == plain.summary
    assert same.series.keys() == plain.series.keys()
    for key, value in plain.series.items():
        np.testing.assert_array_equal(same.series[key], value, err_msg=key)


def ring(n):
    """Return the adjacency of the undirected ring on ``n`` vertices."""
    adj = np.zeros((n, n))
    for a in range(n):
        adj[a, (a + 1) % n] = adj[(a + 1) % n, a] = 1.0
    return adj


K_P, K_V = 1.0, 1.0


def critical_delay(lam):
    """Return ``(tau*, omega)`` of the mode of eigenvalue ``lam`` at the test's gains."""
    return linear.critical_delay(lam, K_P, K_V)


def discrete_radius(lam, d, dt):
    """Return the spectral radius of the sampled mode with an input delay of ``d`` steps."""
    return linear.sampled_delay_radius(lam, d, dt, K_P, K_V)


def oracle_scenario(delay_steps, dt, duration):
    n = 4
    return parse_scenario({
        'name': 'oracle', 'dim': 2, 'n_agents': n, 'dt': dt, 'duration': duration, 'seed': 3,
        'record_every': 25,
        'protocol': {'name': 'linear_consensus', 'k_p': K_P, 'k_v': K_V},
        'graph': {'type': 'fixed', 'adjacency': ring(n).tolist()},
        'informed': {'select': 'first', 'count': 0},
        'initial': {'position_box': [[-1, 1], [-1, 1]], 'velocity_box': [[-1, 1], [-1, 1]]},
        'leader': {'model': 'constant_velocity', 'position': [0, 0], 'velocity': [0, 0]},
        'network': {'delay': delay_steps * dt, 'model': 'input'}})


def disagreement(series):
    """Return, per recorded instant, the largest distance of a state from the average."""
    q, p = series['q'], series['p']
    dq = q - q.mean(axis=1, keepdims=True)
    dp = p - p.mean(axis=1, keepdims=True)
    return np.maximum(np.linalg.norm(dq, axis=2).max(axis=1),
                      np.linalg.norm(dp, axis=2).max(axis=1))


def test_the_critical_input_delay_of_the_linear_law():
    """A run at 0.9 tau* converges to consensus, one at 1.1 tau* diverges.

    The ring of four has Laplacian eigenvalues 0, 2, 2, 4; ``tau* = 0.3237 s`` (``lam =
    4``). With ``dt = 0.02 s`` (``tau* / dt = 16.19``) the sampled system's critical delay
    is 16 steps (0.32 s): the discrete boundary is within one step of the continuous one
    (with ``dt = 0.01 s``, 32 steps against 32.37). 0.9 tau* and 1.1 tau* round to 15 and 18
    steps (0.93 and 1.11 tau*), whose sampled modes have spectral radii 0.99777 and
    1.00588 per step: over 40 s (2000 steps), a factor 0.01 and 1e5.
    """
    dt = 0.02
    lams = np.linalg.eigvalsh(np.diag(ring(4).sum(axis=1)) - ring(4))[1:]
    taus = [critical_delay(lam)[0] for lam in lams]
    tau = min(taus)
    assert tau == taus[-1] and lams[-1] == pytest.approx(4.0)
    assert tau == pytest.approx(0.3237046, abs=1e-6)
    # The continuous crossing: |s^2 + lam (k_v s + k_p) e^{-s tau}| vanishes at s = i w.
    w = critical_delay(4.0)[1]
    s = 1j * w
    assert abs(s ** 2 + 4.0 * (K_V * s + K_P) * np.exp(-s * tau)) < 1e-9
    d_star = next(d for d in range(1, 60) if discrete_radius(4.0, d, dt) > 1.0)
    assert abs(d_star - tau / dt) <= 1.0
    stable, unstable = round(0.9 * tau / dt), round(1.1 * tau / dt)
    assert discrete_radius(4.0, stable, dt) < 1.0 < discrete_radius(4.0, unstable, dt)
    below = disagreement(simulate(oracle_scenario(stable, dt, 40.0)).series)
    above = disagreement(simulate(oracle_scenario(unstable, dt, 40.0)).series)
    assert below[-1] < 1e-1 * below[0]
    assert above[-1] > 1e2 * above[0]


def test_without_delay_the_linear_law_tracks_the_leader():
    """Informed agents reach the leader's state; the rest follow through the ring."""
    data = oracle_scenario(0, 0.02, 20.0).raw
    data = {**data, 'informed': {'select': 'ids', 'ids': [0]}, 'network': None,
            'protocol': {'name': 'linear_consensus', 'k_p': 2.0, 'k_v': 2.0, 'c1': 2.0,
                         'c2': 3.0},
            'leader': {'model': 'constant_velocity', 'position': [1, 2], 'velocity': [0.5, 0]}}
    result = simulate(parse_scenario(data))
    q, lq = result.series['q'][-1], result.series['leader_q'][-1]
    np.testing.assert_allclose(q, np.broadcast_to(lq, q.shape), atol=1e-2)


def test_a_sweep_may_vary_every_network_key_and_collect_its_statistics():
    from flock_swarm.study.spec import parse_spec, plan_runs
    parsed = parse_spec({
        'scenario': 'demo', 'set': {'duration': 0.1},
        'grid': {'network.delay': [0, 0.04], 'network.loss': [0, 0.2],
                 'network.noise.position': [0.01], 'network.noise.velocity': [0.0],
                 'network.period': [2], 'network.model': ['input'],
                 'network.max_age': [0.2], 'network.leader.delay': [0.02],
                 'network.leader.loss': [0.1], 'network.leader.noise.position': [0.0],
                 'network.leader.noise.velocity': [0.0], 'network.leader.period': [1],
                 'network.compensation': ['predict']},
        'metrics': ['eta', 'network_delivered', 'network_age_mean', 'network_age_max']})
    runs = plan_runs(parsed)
    assert len(runs) == 4
    scenarios = [run.scenario() for run in runs]
    assert {sc.network.agents.delay.low for sc in scenarios} == {0, 2}
    assert all(sc.network.model == 'input' and sc.network.max_age == 10 for sc in scenarios)
    assert all(sc.network.compensation == 'predict' for sc in scenarios)
    assert all(run.stack_key is None for run in runs)
    with pytest.raises(ScenarioError, match='network.delay'):
        plan_runs(parse_spec({'scenario': 'demo', 'grid': {'network.delay': [0.03]}}))


def test_the_recorded_statistics_cover_every_step_since_the_previous_instant():
    """With period 2 and a record every 2 steps, each instant sees ages 1 and 0 (no aliasing)."""
    data = oracle_scenario(0, 0.02, 0.2).raw
    sc = parse_scenario({**data, 'record_every': 2, 'network': {'period': 2}})
    series = simulate(sc).series
    dt = 0.02
    assert series['network_age_mean'][0] == 0.0
    np.testing.assert_allclose(series['network_age_mean'][1:], 0.5 * dt, rtol=1e-12)
    np.testing.assert_allclose(series['network_age_max'][1:], dt, rtol=1e-12)
    assert np.all(series['network_delivered'] == 1.0)


# --------------------------------------------------------------------------------------------
# Delay compensation on a uniformly moving lattice

#: The lattice's common velocity [m/s] and the leader's acceleration [m/s^2].
V, LEADER_ACCEL = np.array([1.0, 0.5]), np.array([0.3, -0.2])
#: Fig. 2's law and step; agents 0 .. 4 informed.
FIG2 = load('su2009_fig2')
INFORMED = 5


def lattice_start(count=19, seed=4):
    """Return a triangular patch at Fig. 2's spacing, jittered by up to 0.2 m: every pair is
    nearer than 3.7 m or farther than 5.3 m (the radius is 4 m, the shift under test 0.07 m)."""
    q = delay_drag.triangular_lattice(count, FIG2.law.d)
    return q + np.random.default_rng(seed).uniform(-0.2, 0.2, q.shape)


def leader_at(t):
    """Return the virtual leader at ``t``: constant acceleration from (1, 2) at (0.5, 0.5)."""
    q0, p0 = np.array([1.0, 2.0]), np.array([0.5, 0.5])
    return LeaderState(q0 + p0 * t + 0.5 * LEADER_ACCEL * t * t, p0 + LEADER_ACCEL * t,
                       LEADER_ACCEL.copy())


def moving_lattice(network, steps=8, accel=(0.0, 0.0)):
    """Feed a NetworkState ``steps`` steps of the lattice translating at :data:`V` (at the
    uniform acceleration ``accel`` from it), and of an accelerating leader; return its ``u`` at
    the last step, the states and the agents."""
    law, dt = FIG2.law, FIG2.dt
    q0 = lattice_start()
    n = q0.shape[0]
    agents = AgentData(np.arange(n) < INFORMED)
    net = NetworkState(parse_network(network, dt), 1, n, 2, law, 'disk')
    accel = np.asarray(accel)
    for k in range(steps):
        t = k * dt
        q, p = q0 + V * t + 0.5 * accel * t * t, np.tile(V + accel * t, (n, 1))
        net.send(k, q, p, leader_at(k * dt), disk_graph(q, law.radius, law.strict_radius),
                 agents.informed)
    u = net.control(None, q, p, agents, dt)[0]
    return u, q, p, agents, (steps - 1) * dt


@pytest.mark.parametrize('model', ['communication', 'input'])
def test_predict_gives_the_undelayed_law_on_a_uniformly_moving_lattice(model):
    """At constant velocity the prediction ``q + p a dt`` is exact (the leader's, at constant
    acceleration, too): the law's output is the one on current states, to rounding."""
    u, q, p, agents, t = moving_lattice({'delay': 0.06, 'leader': {'delay': 0.04},
                                         'model': model, 'compensation': 'predict'})
    law = FIG2.law
    exact = swarm_control(law, q, p, disk_graph(q, law.radius, law.strict_radius),
                          leader_at(t), agents, FIG2.dt)
    assert np.abs(exact).max() > 0.5
    np.testing.assert_allclose(u, exact, rtol=0, atol=1e-12)
    # Without it: under the communication model the delay drags every agent; under the
    # input model the relative states are exact, only the informed agents' differ (the
    # leader's acceleration since the message was sent).
    stale = moving_lattice({'delay': 0.06, 'leader': {'delay': 0.04}, 'model': model})[0]
    if model == 'communication':
        assert np.abs(stale - exact)[INFORMED:].min() > 0.05
    else:
        np.testing.assert_allclose(stale[INFORMED:], exact[INFORMED:], rtol=0, atol=1e-12)
        assert np.abs(stale - exact)[:INFORMED].min() > 1e-3


@pytest.mark.parametrize('model', ['communication', 'input'])
def test_predict_carries_the_acceleration_of_a_uniformly_accelerating_lattice(model):
    """Each message carries its sender's acceleration over the step before it was sent
    (``(p(k') - p(k' - 1)) / dt``); at a uniform acceleration the prediction ``(q + p s + f
    s^2 / 2, p + f s)`` is then exact: the law's output is the one on current states, where a
    constant-velocity prediction would leave every neighbour ``f s^2 / 2`` and ``f s`` off."""
    accel = (0.8, -0.5)
    u, q, p, agents, t = moving_lattice({'delay': 0.06, 'leader': {'delay': 0.04},
                                         'model': model, 'compensation': 'predict'},
                                        accel=accel)
    law = FIG2.law
    exact = swarm_control(law, q, p, disk_graph(q, law.radius, law.strict_radius),
                          leader_at(t), agents, FIG2.dt)
    np.testing.assert_allclose(u, exact, rtol=0, atol=1e-9)
    # The acceleration carried: zero at the first step sent; over the steps since the one
    # sent before otherwise (realtime may skip steps).
    net = NetworkState(parse_network({'delay': 0.06, 'compensation': 'predict'}, FIG2.dt), 1,
                       q.shape[0], 2, law, 'disk')
    assert np.array_equal(net._acceleration(0, p), np.zeros_like(p))
    np.testing.assert_allclose(net._acceleration(3, p + 3 * FIG2.dt * np.array(accel)),
                               np.tile(accel, (q.shape[0], 1)), rtol=1e-12)


def test_without_compensation_the_neighbours_appear_shifted_by_minus_v_d():
    """Under the communication model every neighbour held is ``v D`` behind its current
    position: the law's output is the law on the neighbours at ``q_j - v D`` (evaluated
    pair by pair here), the agent's own state current."""
    delay = 0.06
    u, q, p, agents, t = moving_lattice({'delay': delay})
    law, n = FIG2.law, q.shape[0]
    s = np.zeros((n, 2))
    for i in range(n):
        for j in range(n):
            seen = q[j] - V * delay
            if j != i and np.linalg.norm(seen - q[i]) < law.radius:
                s[i] += law.pair(q[i:i + 1], p[i:i + 1], seen[None], p[j:j + 1], np.ones(1))[0]
    expected = law.combine(q, p, s, leader_at(t), agents, FIG2.dt)
    np.testing.assert_allclose(u, expected, rtol=0, atol=1e-12)


def test_the_default_is_no_compensation_bit_for_bit():
    """A run without the key equals one with ``compensation: none`` in every output."""
    net = 'network={delay: 0.04, loss: 0.1, leader: {delay: 0.02}}'
    plain = simulate(load('demo', ['duration=0.5', net]))
    none = simulate(load('demo', ['duration=0.5', net[:-1] + ', compensation: none}']))
    assert load('demo', [net]).network.compensation == 'none'
    for result in (plain, none):
        result.summary.pop('wall_time_s')
    assert none.summary == plain.summary
    for key, value in plain.series.items():
        np.testing.assert_array_equal(none.series[key], value, err_msg=key)


# --------------------------------------------------------------------------------------------
# The oracle of the delay's drag on a moving flock


def test_the_drag_oracle_on_a_chain_is_the_hand_formula():
    """A chain of N agents at the spacing d along x, moving along x: each link adds
    ``phi_alpha'(d_alpha) d^2 / (1 + eps d^2)`` to both its ends, ``phi_alpha'(d_alpha) = a``
    (``a = b``, ``d_alpha / r_alpha = 0.727 < h = 0.9``), so ``beta_0 = D a d^2 / (1 + eps
    d^2) 2 (N - 1) / N``; across the chain nothing (the links' Jacobians are ``g g^T``)."""
    law, n, delay = FIG2.law, 7, 0.02
    q = np.stack([law.d * np.arange(n), np.zeros(n)], axis=1)
    pred = delay_drag.predict_drag(law, q, [1.0, 0.0], delay)
    link = law.a * law.d ** 2 / (1.0 + law.eps * law.d ** 2)
    assert pred.rate == pytest.approx(delay * link * 2 * (n - 1) / n, rel=1e-12)
    np.testing.assert_allclose(pred.acceleration, [-link * 2 * (n - 1) / n * delay, 0.0],
                               rtol=1e-12, atol=1e-15)
    across = delay_drag.predict_drag(law, q, [0.0, 1.0], delay)
    assert abs(across.rate) < 1e-12
    # a_ij = 1 on every link (the bump's plateau): K_bar = 2 (N - 1) / N.
    assert pred.consensus[0, 0] == pytest.approx(2 * (n - 1) / n, rel=1e-12)
    # The interior of a triangular lattice: 3 a d^2 / (1 + eps d^2) in every direction.
    hexagon = delay_drag.predict_drag(law, delay_drag.triangular_lattice(7, law.d),
                                      [0.6, 0.8], delay)
    np.testing.assert_allclose(hexagon.per_agent[0], 3 * link * np.eye(2), rtol=1e-12)


def test_the_analytic_jacobians_are_the_pair_terms_derivatives():
    """The Hessians of psi_alpha equal the central differences of the law's own pair term."""
    x = np.random.default_rng(2).uniform(-4.5, 4.5, (200, 2))
    x = x[np.linalg.norm(x, axis=1) > 0.3]
    np.testing.assert_allclose(delay_drag.su_jacobians(FIG2.law, x),
                               delay_drag.numeric_jacobians(FIG2.law, x), rtol=0, atol=1e-6)


def drag_run(count, velocity, delay, duration=0.6):
    """Return ``(t, p)`` of a sim run of an uninformed triangular patch at Fig. 2's law and
    spacing, moving at ``velocity``, under a communication delay; every step recorded."""
    q = delay_drag.triangular_lattice(count, FIG2.law.d) + 20.0
    data = {**FIG2.raw, 'n_agents': count, 'duration': duration, 'record_every': 1,
            'informed': {'select': 'first', 'count': 0},
            'initial': {'positions': q.tolist(),
                        'velocities': np.tile(velocity, (count, 1)).tolist()},
            'network': {'delay': delay}}
    series = simulate(parse_scenario(data)).series
    return q, series['t'], series['p']


@pytest.mark.parametrize('count, velocity, delay', [(37, [1.0, 0.0], 0.02),
                                                    (30, [0.6, 0.8], 0.04)])
def test_the_drag_oracle_predicts_the_braking_of_a_sim_run(count, velocity, delay):
    """A patch of Fig. 2's alpha-lattice moving at 1 m/s, nobody informed, under a
    communication delay: the first step with messages brakes it at ``beta_0`` (within 1 %:
    the neglected terms are O((v D)^2)), the next half second at the settled rate (within
    2 %: the lattice's slow deformation is neglected). The ideal network conserves it."""
    q, t, p = drag_run(count, velocity, delay)
    pred = delay_drag.predict_drag(FIG2.law, q, velocity, delay)
    d = round(delay / FIG2.dt)
    along = p.mean(axis=1) @ np.asarray(velocity)
    # Nothing is held before the first messages arrive: no force, no braking.
    np.testing.assert_allclose(along[:d + 1], 1.0, rtol=1e-12)
    first = (along[d] - along[d + 1]) / FIG2.dt
    assert first == pytest.approx(pred.rate, rel=0.01)
    settled = delay_drag.measured_rate(t[d + 5:d + 26], p[d + 5:d + 26], velocity)
    assert settled == pytest.approx(pred.settled_rate, rel=0.02)
    assert pred.settled_rate < 0.95 * pred.rate
    ideal = drag_run(count, velocity, 0.0, duration=0.2)[2].mean(axis=1) @ velocity
    np.testing.assert_allclose(ideal, 1.0, rtol=1e-12)
