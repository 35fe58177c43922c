"""The reference simulator: output contract, determinism, and agreement with per-agent laws."""

import json
import platform
import resource

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose

from flock_swarm.core.dynamics import step_agents
from flock_swarm.core.leaders.base import VirtualLeader
from flock_swarm.core.graphs import diffusive_matrix, disk_graph
from flock_swarm.core.laws.base import AgentData
from flock_swarm.core.laws.evaluation import advance_state, local_control
from flock_swarm.core.pseudo_leaders import minor_lambda_max
from flock_swarm.core.scenario import realize
from flock_swarm.core import run
from flock_swarm.core.run import keep_freed_memory, simulate, simulate_stack, stack_mismatch
from flock_swarm.presets import load
from flock_swarm.cli.sim import main

SUMMARY_KEYS = {'n_agents', 't_final', 'steps', 'eta', 'eta_tolerance', 'velocity_mismatch_max',
                'com_position_error', 'com_velocity_error', 'min_pair_distance', 'collisions',
                'collision_distance', 'components_final', 'informed', 'scenario', 'seed'}


def test_cli_writes_summary_and_timeseries(tmp_path):
    out = tmp_path / 'demo'
    assert main(['demo', '--out', str(out), '--quiet', '--plots',
                 '--set', 'duration=4', '--set', 'record_every=5']) == 0
    summary = json.loads((out / 'summary.json').read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary['scenario'] == 'demo' and summary['n_agents'] == 30
    assert summary['steps'] == 200 and summary['t_final'] == pytest.approx(4.0)
    assert len(summary['informed']) == 10
    series = np.load(out / 'timeseries.npz')
    k = 200 // 5 + 1
    assert series['t'].shape == (k,)
    for name in ('q', 'p', 'u'):
        assert series[name].shape == (k, 30, 2)
    for name in ('leader_q', 'leader_p', 'leader_a'):
        assert series[name].shape == (k, 2)
    # The leader moves at constant velocity (1, 1) from (10, 10).
    assert_allclose(series['leader_q'][-1], [14.0, 14.0], atol=1e-12)
    assert np.isfinite(series['q']).all()
    assert (out / 'trajectories.png').stat().st_size > 1000
    assert (out / 'metrics.png').stat().st_size > 1000
    assert json.loads((out / 'scenario.json').read_text())['name'] == 'demo'


def test_runs_are_deterministic_and_seed_dependent():
    sc = load('demo', ['duration=2'])
    a, b = simulate(sc), simulate(sc)
    assert_allclose(a.series['q'], b.series['q'], rtol=0, atol=0)
    c = simulate(load('demo', ['duration=2'], seed=2))
    assert not np.allclose(a.series['q'][0], c.series['q'][0])


@pytest.mark.parametrize('preset, overrides', [
    ('demo', ['duration=1']),
    ('su2009_fig6', ['duration=0.5']),
    ('yu2010_sec41', ['duration=1']),
    ('zhou2012_sec51', ['duration=0.2']),
    ('jadbabaie2003_leader', ['duration=2']),
    ('os2003_sink', ['duration=1']),
])
def test_simulator_equals_a_per_agent_loop(preset, overrides):
    """Vectorised simulation == every agent applying ``local_control`` to its neighbours.

    The loop below is how the agent node computes its command: neighbours within r (or the
    fixed graph's weights, or every agent for laws acting on all pairs), the same law.
    """
    sc = load(preset, overrides + ['record_every=1'])
    result = simulate(sc)
    real = realize(sc)
    law, dt = sc.law, sc.dt
    q, p = real.q0.copy(), real.p0.copy()
    agents = AgentData(real.agents.informed.copy(), real.agents.data,
                       {key: value.copy() for key, value in real.agents.state.items()})
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity)
    intrinsic = sc.intrinsic.velocity_field() if sc.intrinsic is not None else None
    n = sc.n_agents
    for step in range(sc.steps):
        state = leader.state
        if real.adjacency is not None:
            weights = real.adjacency
        elif law.all_pairs:
            weights = law.w * adjacency_of(disk_graph(q, law.radius, law.strict_radius), n)
        else:
            weights = adjacency_of(disk_graph(q, law.radius, law.strict_radius), n)
        u = np.zeros_like(q)
        for i in range(n):
            others = np.array([j for j in range(n) if j != i and
                               (law.all_pairs or weights[i, j] > 0)], dtype=int)
            u[i] = local_control(law, q[i], p[i], q[others], p[others], weights[i, others],
                                 state, agents.subset(np.array([i])), dt)
        assert_allclose(u, result.series['u'][step], rtol=1e-9, atol=1e-9)
        advance_state(law, q, p, state, agents, dt)
        q, p = step_agents(q, p, u, dt, intrinsic)
        leader.step(dt)
    assert_allclose(q, result.series['q'][-1], rtol=1e-9, atol=1e-9)
    assert_allclose(p, result.series['p'][-1], rtol=1e-9, atol=1e-9)


def adjacency_of(edges, n):
    a = np.zeros((n, n))
    a[edges.i, edges.j] = a[edges.j, edges.i] = 1.0
    return a


def test_divergence_is_reported_and_no_nan_is_written(tmp_path):
    out = tmp_path / 'unstable'
    status = main(['zhou2012_sec51', '--out', str(out), '--quiet', '--allow-unstable',
                   '--set', 'dt=0.02', '--set', 'duration=20'])
    assert status == 1
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'diverged'
    series = np.load(out / 'timeseries.npz')
    for name in series.files:
        assert np.isfinite(series[name]).all(), name


def test_pseudo_leaders_are_reselected_when_the_disk_graph_switches():
    """Zhou 2012 Section 4.4: with a switching r-disk graph, Theorem 1 is re-applied."""
    sc = load('zhou2012_sec51', [
        'graph={type: disk}', 'informed={select: pseudo_leaders, reselect: true}',
        'protocol.r=2.0', 'n_agents=12', 'duration=2', 'dt=0.002', 'seed=3',
        'intrinsic={model: none}',
        'leader={model: constant_velocity, position: [6, 6, 6], velocity: [1, 1, 1]}'])
    result = simulate(sc)
    assert result.summary['pseudo_leader_reselections'] > 0
    informed = result.series['informed']
    assert (informed.sum(axis=1) >= 1).all()
    # Every recorded informed set satisfies Theorem 1 on the graph of that instant.
    for q, chosen in zip(result.series['q'], informed):
        edges = disk_graph(q, 2.0)
        a = adjacency_of(edges, 12)
        lam = minor_lambda_max(sc.law.w * diffusive_matrix(a), np.flatnonzero(chosen))
        assert lam + sc.law.alpha < 0.0


def fig3_realisations(n, side, fractions, duration):
    """Return Su 2009 Fig. 3 scenarios at ``n`` agents: one per (seed, informed fraction)."""
    return [load('su2009_fig3', [f'duration={duration}', f'n_agents={n}',
                                 f'initial.position_box=[[0, {side}], [0, {side}]]'],
                 seed, {'informed.fraction': fraction})
            for seed, fraction in enumerate(fractions)]


def assert_same_run(stacked, alone):
    """Assert that a stacked realisation recorded what its own run recorded (to 1e-9)."""
    assert set(stacked.series) == set(alone.series)
    for name, values in alone.series.items():
        assert_allclose(stacked.series[name], values, rtol=0, atol=1e-9, err_msg=name)
    for key, value in alone.summary.items():
        if isinstance(value, float) and key != 'wall_time_s':
            assert stacked.summary[key] == pytest.approx(value, rel=0, abs=1e-9), key
        elif key != 'wall_time_s':
            assert stacked.summary[key] == value, key


def test_stacked_realisations_equal_their_own_runs():
    # Same N, different seeds (initial draws) and informed fractions; 2 s at dt = 0.02.
    scenarios = fig3_realisations(40, 28.3, (0.1, 0.5, 1.0, 0.25), 2.0)
    stacked = simulate_stack(scenarios)
    assert [r.summary['seed'] for r in stacked] == [0, 1, 2, 3]
    for sc, res in zip(scenarios, stacked):
        alone = simulate(sc)
        assert len(alone.summary['informed']) == round(sc.informed.fraction * 40)
        assert_same_run(res, alone)


@pytest.mark.parametrize('fault, status', [('state', 'diverged'), ('law', 'failed')])
def test_a_diverging_realisation_leaves_the_stack_and_the_others_go_on(monkeypatch, fault,
                                                                       status):
    # The Su laws do not diverge at moderate positions: for informed agents beyond x = 25,
    # which some realisations reach at different steps, one never, make the state overflow
    # (diverged), or the law give NaN inputs at that plausible state (failed: the law's
    # fault, told apart from a divergence).
    real_control, real_step, informed = run.swarm_control, run.step_agents, []

    def failing(law, q, p, edges, leader, agents, dt, *t):
        u = real_control(law, q, p, edges, leader, agents, dt, *t)
        informed[:] = [(q[:, 0] > 25.0) & agents.informed]
        if fault == 'law':
            u[informed[0]] = np.nan
        return u

    def overflowing(q, p, u, dt, intrinsic):
        q, p = real_step(q, p, u, dt, intrinsic)
        p[informed[0]] = np.inf
        return q, p

    monkeypatch.setattr(run, 'swarm_control', failing)
    if fault == 'state':
        monkeypatch.setattr(run, 'step_agents', overflowing)
    scenarios = fig3_realisations(20, 20.0, (1.0, 0.0, 0.5), 4.0)
    alone = [simulate(sc) for sc in scenarios]
    assert [r.summary['status'] for r in alone] == [status, 'completed', status]
    assert alone[0].summary['steps'] != alone[2].summary['steps']
    for res, own in zip(simulate_stack(scenarios), alone):
        assert res.summary['steps'] == own.summary['steps']
        assert_same_run(res, own)


@pytest.mark.parametrize('override, reason', [
    ('n_agents=21', 'n_agents'), ('dt=0.01', 'dt'), ('protocol.c1=0.6', 'protocol'),
    ('leader.velocity=[1, 1]', 'leader'),
    ('graph={type: barabasi_albert, m0: 3, m: 2}', 'r-disk')])
def test_realisations_that_differ_in_more_than_their_draw_do_not_stack(override, reason):
    base = fig3_realisations(20, 20.0, (0.5,), 1.0)[0]
    other = load('su2009_fig3', ['duration=1', 'n_agents=20',
                                 'initial.position_box=[[0, 20.0], [0, 20.0]]', override], 1)
    assert reason in stack_mismatch([base, other])
    with pytest.raises(ValueError, match=reason):
        simulate_stack([base, other])
    assert stack_mismatch([other]) is None


@pytest.mark.skipif(platform.libc_ver()[0] != 'glibc', reason='mallopt is glibc\'s')
def test_freed_arrays_are_kept_for_the_next_ones():
    # A "step" of eight 1 MB temporaries, all freed at its end: by default glibc trims the
    # freed top of its heap and faults the pages in again at the next step (2048 each).
    def step():
        temporaries = [np.ones(1 << 17) for _ in range(8)]
        return sum(float(t.sum()) for t in temporaries)

    keep_freed_memory()
    step()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(50):
        step()
    assert resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before < 5000


@pytest.mark.parametrize('preset, overrides', [
    ('demo', ['dt=1.0', 'duration=2']),
    ('zhou2012_sec51', ['dt=0.01']),
    ('yu2010_sec41', ['dt=0.05', 'duration=1']),
])
def test_prepare_refuses_the_dt_sim_refuses_with_the_same_line(capsys, preset, overrides):
    """The one scenario preparation: sim's error line is prepare's error, word for word."""
    from flock_swarm.core.errors import ScenarioError
    from flock_swarm.presets import StepError, load_mapping, prepare
    args = [x for o in overrides for x in ('--set', o)]
    assert main([preset, *args, '--quiet']) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith('sim: error: dt: ') and '\n' not in line
    with pytest.raises(StepError) as refused:
        prepare(preset, overrides)
    assert f'sim: error: {refused.value}' == line
    assert isinstance(refused.value, ScenarioError) and refused.value.key == 'dt'
    assert refused.value.violations
    # A node's way in: the mapping it read plus its parameters as parsed values.
    base = load_mapping(preset)
    kept = json.dumps(base, sort_keys=True)
    extra = {k: yaml_value(v) for k, v in (o.split('=', 1) for o in overrides)}
    with pytest.raises(ScenarioError) as from_mapping:
        prepare(base, extra=extra)
    assert str(from_mapping.value) == str(refused.value)
    assert json.dumps(base, sort_keys=True) == kept, 'the given mapping is not modified'
    # --allow-unstable: prepared all the same, realisation included.
    sc, real = prepare(preset, overrides, allow_unstable=True)
    assert sc.dt == extra['dt'] and real.q0.shape == (sc.n_agents, sc.dim)


def yaml_value(text):
    """Return a ``--set`` value as a node's parameter holds it (parsed)."""
    from flock_swarm.scenario_yaml import parse_value
    return parse_value(text)


def test_prepare_returns_what_sim_runs():
    """Overrides, the seed and the mapping's copy: the scenario sim runs and its draw."""
    from flock_swarm.presets import load_mapping, prepare
    sc, real = prepare('demo', ['n_agents=6', 'informed.count=2'], seed=11)
    assert (sc.n_agents, sc.seed, sc.raw['seed']) == (6, 11, 11)
    again = realize(load('demo', ['n_agents=6', 'informed.count=2'], seed=11))
    np.testing.assert_array_equal(real.q0, again.q0)
    np.testing.assert_array_equal(real.agents.informed, again.agents.informed)
    from_mapping, _ = prepare(load_mapping('demo'), ['n_agents=6', 'informed.count=2'], 11)
    assert from_mapping.raw == sc.raw
    assert prepare({**load_mapping('demo'), 'name': 'x'})[0].name == 'x'


def test_the_last_line_leads_with_the_scenarios_headline(tmp_path, capsys):
    """Su 2009 Fig. 6 is about the centre of mass: its line gives the COM error and the claim."""
    assert main(['su2009_fig6', '--set', 'duration=1', '--out', str(tmp_path / 'f6')]) == 0
    lines = capsys.readouterr().err.splitlines()
    s = json.loads((tmp_path / 'f6' / 'summary.json').read_text())
    assert lines[-2] == (
        f'[sim] completed at t = 1 s: COM position error = {s["com_position_error"]:.3g} m, '
        f'COM velocity error = {s["com_velocity_error"]:.3g} m/s '
        f'(Su 2009 Fig. 6: -> 0 exponentially); collisions = 0, components = '
        f'{s["components_final"]} ({s["wall_time_s"]:.1f} s wall)')
    # eta stays in the summary (and off the line of a run that is not about it).
    assert 'eta' in s and 'eta' not in lines[-2]


def test_without_a_headline_the_last_line_is_as_it_was(tmp_path, capsys):
    """A scenario that names no headline (a user's file from before) prints eta and mismatch."""
    from flock_swarm.presets import load_mapping
    data = load_mapping('demo')
    del data['metrics']['headline']
    path = tmp_path / 'mine.yaml'
    path.write_text(yaml.safe_dump(data))
    assert main([str(path), '--set', 'duration=1', '--out', str(tmp_path / 'o')]) == 0
    line = capsys.readouterr().err.splitlines()[-2]
    s = json.loads((tmp_path / 'o' / 'summary.json').read_text())
    assert line == (f'[sim] completed at t = 1 s: eta = {s["eta"]:.3f}, velocity mismatch = '
                    f'{s["velocity_mismatch_max"]:.3g}, collisions = {s["collisions"]}, '
                    f'components = {s["components_final"]} ({s["wall_time_s"]:.1f} s wall)')
    assert json.loads((tmp_path / 'o' / 'scenario.json').read_text()) == dict(data, duration=1)


@pytest.mark.parametrize('preset, shown, hidden', [
    ('su2009_fig6', '  COM error = ', 'eta = '),
    ('demo', '  eta = ', 'COM'),
])
def test_progress_lines_lead_with_the_headline(preset, shown, hidden):
    lines = []
    simulate(load(preset, ['duration=0.04']), progress=lines.append, progress_every=0.0)
    assert lines and all(shown in line and hidden not in line for line in lines)
