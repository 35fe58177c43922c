"""The law API without traps (issue 24, item 3), in-process.

Laws defined here are registered for a test by replacing the registry's lookup
(``registry.law_class``), so they go through the real scenario loading, run loop and checks;
test_plugins.py does the same with installed distributions and the real ``sim`` command.
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_array_equal

from flock_swarm.core import registry
from flock_swarm.core.errors import PluginError, ScenarioError
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.laws import base, evaluation
from flock_swarm.core.laws.base import AgentData, Law
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.run import simulate
from flock_swarm.presets import prepare
from flock_swarm.study.spec import metric_value, plan_runs, read_spec
from flock_swarm.testing import check_law


@dataclass(frozen=True)
class Consensus(Law):
    """Velocity consensus plus a PD pull to the leader (antisymmetric, claimed)."""

    name: ClassVar[str] = 'consensus'
    antisymmetric: ClassVar[bool] = True
    r: float = 4.0
    k: float = 1.0

    @property
    def radius(self):
        return self.r

    def pair(self, qi, pi, qj, pj, w):
        return w[:, None] * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt, t):
        if leader is None:
            return s
        return s - self.k * (q - leader.q) - self.k * (p - leader.p)


@dataclass(frozen=True)
class OldCombine(Consensus):
    """Written to the API before the time: combine without t."""

    name: ClassVar[str] = 'old_combine'

    def combine(self, q, p, s, leader, agents, dt):
        return s


@dataclass(frozen=True)
class Clock(Consensus):
    """u = t in every component: what combine is given as the time."""

    name: ClassVar[str] = 'clock'

    def combine(self, q, p, s, leader, agents, dt, t):
        return np.full(q.shape, t)


@dataclass(frozen=True)
class NeighbourMean(Consensus):
    """The neighbour-mean pattern: a count column, so not antisymmetric (the default)."""

    name: ClassVar[str] = 'neighbour_mean'
    antisymmetric: ClassVar[bool] = False

    def pair(self, qi, pi, qj, pj, w):
        return np.concatenate((pj, np.ones((pj.shape[0], 1))), axis=1)

    def combine(self, q, p, s, leader, agents, dt, t):
        return s[:, :-1] / np.maximum(s[:, -1:], 1.0) - p


@dataclass(frozen=True)
class NeighbourMeanClaimed(NeighbourMean):
    name: ClassVar[str] = 'neighbour_mean_claimed'
    antisymmetric: ClassVar[bool] = True


@dataclass(frozen=True)
class NeighbourAdaptive(Consensus):
    """A gain driven by the neighbours' velocity errors: e' = ||s_i||^2 (uses state_rate's s)."""

    name: ClassVar[str] = 'neighbour_adaptive'
    state_summary: ClassVar[dict[str, str]] = {'e': 'neighbour_error_final'}

    def initial_state(self, n):
        return {'e': np.zeros(n)}

    def state_rate(self, q, p, leader, agents, s, t):
        return {'e': np.einsum('nk,nk->n', s, s)}


@dataclass(frozen=True)
class Global(Consensus):
    """Uses the whole group it is given (the centre of mass): a container differs from sim."""

    name: ClassVar[str] = 'global'

    def combine(self, q, p, s, leader, agents, dt, t):
        return s - (q - q.mean(axis=0))


@dataclass(frozen=True)
class Blowup(Consensus):
    """Non-finite from t = 0.05 s on."""

    name: ClassVar[str] = 'blowup'

    def combine(self, q, p, s, leader, agents, dt, t):
        return s / 0.0 if t >= 0.05 else s


@dataclass(frozen=True)
class Gains(Consensus):
    """A vector-valued field."""

    name: ClassVar[str] = 'gains'
    gains: tuple[float, ...] = (1.0, 1.0)


@dataclass(frozen=True, kw_only=True)
class NeedsGain(Consensus):
    """A field without default: the scenario must give it."""

    name: ClassVar[str] = 'needs_gain'
    gain: float


TEST_LAWS = {cls.name: cls for cls in (Consensus, OldCombine, Clock, NeighbourMean,
                                       NeighbourMeanClaimed, NeighbourAdaptive, Global, Blowup,
                                       Gains, NeedsGain)}


@pytest.fixture
def laws(monkeypatch):
    """Make the test laws loadable by name, the registered ones as ever."""
    real = registry.law_class

    def lookup(name):
        return TEST_LAWS[name] if name in TEST_LAWS else real(name)

    monkeypatch.setattr(registry, 'law_class', lookup)


def mapping(name: str, **protocol) -> dict:
    """Return a small 2-D scenario with the law ``name``."""
    return {'name': 'api', 'dim': 2, 'n_agents': 6, 'dt': 0.01, 'duration': 0.1, 'seed': 4,
            'record_every': 1, 'protocol': {'name': name, **protocol},
            'informed': {'select': 'first', 'count': 3},
            'initial': {'position_box': [[0, 3], [0, 3]], 'velocity_box': [[-1, 1], [-1, 1]]},
            'leader': {'model': 'constant_velocity', 'position': [1, 1], 'velocity': [1, 0]}}


def random_swarm(n=7, dim=2, seed=0):
    rng = np.random.default_rng(seed)
    q, p = rng.uniform(0, 4, (n, dim)), rng.uniform(-1, 1, (n, dim))
    leader = LeaderState(np.zeros(dim), np.ones(dim), np.zeros(dim))
    return q, p, disk_graph(q, 4.0, True), leader, AgentData(np.arange(n) < 3)


def test_the_default_is_not_antisymmetric_and_every_builtin_law_claims_it_rightly():
    assert Law.antisymmetric is False
    for name, cls in registry.usable(registry.LAW_GROUP).items():
        for dim in (2, 3):
            if name == 'jadbabaie_leader' and dim == 3:
                continue
            assert evaluation.antisymmetry_problem(cls(), dim) is None, name


def test_a_false_antisymmetric_claim_is_named_and_refused_when_the_scenario_loads(laws):
    problem = evaluation.antisymmetry_problem(NeighbourMeanClaimed(), 2)
    assert problem.startswith('neighbour_mean_claimed: declares antisymmetric = True')
    with pytest.raises(PluginError, match='protocol.name: neighbour_mean_claimed: declares'):
        prepare(mapping('neighbour_mean_claimed'))


def test_the_neighbour_mean_pattern_is_right_with_the_default():
    q, p, edges, leader, agents = random_swarm()
    u = evaluation.swarm_control(NeighbourMean(), q, p, edges, leader, agents, 0.1)
    for i in range(q.shape[0]):
        nb = np.concatenate((edges.j[edges.i == i], edges.i[edges.j == i]))
        want = (p[nb].mean(axis=0) if nb.size else np.zeros(2)) - p[i]
        np.testing.assert_allclose(u[i], want, rtol=1e-12, atol=1e-12)


def test_combine_gets_the_time_and_an_old_combine_is_called_without_it(laws):
    assert base.accepted(Clock, 'combine') == {'t'}
    assert base.accepted(OldCombine, 'combine') == frozenset()
    assert base.accepted(NeighbourAdaptive, 'state_rate') == {'s', 't'}
    q, p, edges, leader, agents = random_swarm()
    assert_array_equal(evaluation.swarm_control(Clock(), q, p, edges, leader, agents, 0.1, 2.5),
                       2.5)
    evaluation.swarm_control(OldCombine(), q, p, edges, leader, agents, 0.1, 2.5)
    sc, _ = prepare(mapping('clock'))
    series = simulate(sc).series
    # u at every recorded step is the step's time k dt.
    assert_array_equal(series['u'][:, 0, 0], series['t'])
    sc, _ = prepare(mapping('old_combine'))
    assert simulate(sc).summary['status'] == 'completed'


def test_state_rate_gets_the_neighbour_sums(laws):
    sc, real = prepare(mapping('neighbour_adaptive'))
    res = simulate(sc)
    q0, p0 = real.q0, real.p0
    s0 = evaluation.pair_sums(sc.law, q0, p0, disk_graph(q0, 4.0, True))
    np.testing.assert_allclose(res.series['e'][1], sc.dt * np.einsum('nk,nk->n', s0, s0),
                               rtol=1e-12)
    assert res.summary['neighbour_error_final'] == [float(x) for x in res.series['e'][-1]]


@pytest.mark.parametrize('which', ['swarm', 'group', 'local'])
def test_a_wrong_shape_at_any_step_is_one_line_naming_the_law(which):
    @dataclass(frozen=True)
    class Late(Consensus):
        name: ClassVar[str] = 'late'

        def combine(self, q, p, s, leader, agents, dt, t):
            return s if t < 1.0 else s[:, :1]

    q, p, edges, leader, agents = random_swarm()
    ids = np.array([1, 2])

    def call(t):
        if which == 'swarm':
            return evaluation.swarm_control(Late(), q, p, edges, leader, agents, 0.1, t)
        if which == 'group':
            return evaluation.group_control(Late(), ids, q, p, edges, leader,
                                            agents.subset(ids), 0.1, t)
        return evaluation.local_control(Late(), q[0], p[0], q[1:], p[1:], np.ones(6), leader,
                                        agents.subset(np.array([0])), 0.1, t)

    call(0.5)
    with pytest.raises(PluginError) as err:
        call(1.5)
    rows = {'swarm': 7, 'group': 2, 'local': 1}[which]
    assert str(err.value) == (f'protocol.name: late: combine() returned shape ({rows}, 1), '
                              f'not ({rows}, 2) at t = 1.5 s')


def test_a_pair_of_the_wrong_length_is_refused():
    @dataclass(frozen=True)
    class Short(Consensus):
        name: ClassVar[str] = 'short'

        def pair(self, qi, pi, qj, pj, w):
            return (pj - pi)[1:]

    q, p, edges, leader, agents = random_swarm()
    with pytest.raises(PluginError, match=r'short: pair\(\) returned shape'):
        evaluation.swarm_control(Short(), q, p, edges, leader, agents, 0.1)


def test_a_rate_for_an_unknown_state_is_refused():
    @dataclass(frozen=True)
    class Stray(NeighbourAdaptive):
        def state_rate(self, q, p, leader, agents):
            return {'x': np.zeros(q.shape[0])}

    q, p, edges, leader, _ = random_swarm()
    agents = AgentData(np.ones(7, bool), state={'e': np.zeros(7)})
    with pytest.raises(PluginError, match=r"state_rate\(\) returned 'x', not a key"):
        evaluation.advance_state(Stray(), q, p, leader, agents, 0.1)


def test_a_required_field_and_a_vector_field(laws):
    with pytest.raises(ScenarioError, match='protocol.gain: missing .protocol needs_gain has '
                                            'no default for it.'):
        prepare(mapping('needs_gain'))
    assert prepare(mapping('needs_gain', gain=2))[0].law.gain == 2.0
    with pytest.raises(ScenarioError, match='protocol.gains'):
        prepare(mapping('gains', gains=[]))
    sc, _ = prepare(mapping('gains', gains=[1, 2.5]))
    assert sc.law.gains == (1.0, 2.5) and hash(sc.law)
    sc, _ = prepare(mapping('gains', gains=[[1, 2], [3, 4]]))
    assert sc.law.gains == ((1.0, 2.0), (3.0, 4.0))
    with pytest.raises(ScenarioError, match=r'protocol.gains: expected rows of one length'):
        prepare(mapping('gains', gains=[[1, 2], [3]]))


@settings(derandomize=True, database=None, max_examples=150, deadline=None)
@given(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=3),
                    lambda inner: st.lists(inner, max_size=4), max_leaves=8))
def test_any_value_of_a_vector_field_is_read_or_one_line_naming_it(value):
    real = registry.law_class
    registry.law_class = lambda name: TEST_LAWS[name] if name in TEST_LAWS else real(name)
    try:
        sc, _ = prepare(mapping('gains', gains=value))
    except ScenarioError as exc:
        assert str(exc).startswith('protocol.gains'), exc
        assert '\n' not in str(exc)
    else:
        assert isinstance(sc.law.gains, tuple) and hash(sc.law) is not None
    finally:
        registry.law_class = real


@pytest.mark.parametrize('scenario, overrides', [
    ('su2009_fig2', ['n_agents=12']), ('su2009_fig7', ['n_agents=12']),
    ('os2003_sink', ['n_agents=12']), ('zhou2012_sec51', []), ('yu2010_sec41', []),
    ('jadbabaie2003_leader', ['n_agents=12']), ('su2009_fig6', ['n_agents=12'])])
def test_check_law_passes_every_builtin_law(scenario, overrides):
    report = check_law(scenario, overrides, steps=5)
    assert report['steps'] == 5 and report['largest_local_deviation'] <= 1e-9


def test_check_law_takes_a_law_instance(laws):
    report = check_law(Consensus(k=2.0))
    assert report == {'steps': 20, 'agents': 8, 'largest_local_deviation': report[
        'largest_local_deviation']}
    check_law(NeighbourMean())
    check_law(NeighbourAdaptive())


@pytest.mark.parametrize('law, fragment', [
    (NeighbourMeanClaimed(), 'refused: protocol.name: neighbour_mean_claimed: declares '
                             'antisymmetric = True'),
    (Global(), 'global: group_control of agents 0..3 (a container) differs from '
               'swarm_control (sim)'),
    (Blowup(), r'step 5 (t = 0.05 s): blowup: combine() returned non-finite values'),
])
def test_check_law_names_what_is_wrong(laws, law, fragment):
    with pytest.raises(AssertionError) as err:
        check_law(law)
    assert fragment in str(err.value)


def test_a_sweep_spec_scenario_path_is_relative_to_the_spec(tmp_path, monkeypatch):
    folder = tmp_path / 'study'
    folder.mkdir()
    (folder / 'mine.yaml').write_text('name: mine\n' + '\n'.join(
        f'{k}: {v}' for k, v in mapping('olfati_saber_2006').items() if k != 'name'))
    spec = folder / 'spec.yaml'
    spec.write_text('scenario: mine.yaml\ngrid: {protocol.c1: [0.5, 1.0]}\n'
                    'metrics: [eta]\n')
    monkeypatch.chdir(tmp_path)
    runs = plan_runs(read_spec(spec))
    assert len(runs) == 2 and runs[0].data['name'] == 'mine'
    # A preset name stays a preset name.
    spec.write_text('scenario: su2009_fig2\ngrid: {protocol.c1: [0.5]}\n')
    assert read_spec(spec).scenario == 'su2009_fig2'


def test_a_laws_summary_keys_are_sweep_metrics(tmp_path):
    spec = tmp_path / 'spec.yaml'
    spec.write_text('scenario: zhou2012_sec51\nset: {duration: 0.1}\n'
                    'grid: {protocol.k: [0.01]}\nmetrics: [eta, adaptive_gain_final.max]\n')
    assert len(plan_runs(read_spec(spec))) == 1
    assert metric_value({'adaptive_gain_final': [1.0, 3.0]}, 'adaptive_gain_final.max') == 3.0
    assert metric_value({'adaptive_gain_final': [1.0, 3.0]}, 'adaptive_gain_final.mean') == 2.0
    spec.write_text(spec.read_text().replace('zhou2012_sec51', 'su2009_fig2').replace(
        'protocol.k', 'protocol.c1'))
    with pytest.raises(ScenarioError, match=r"metrics\[1\]: adaptive_gain_final.max: protocol "
                                            r"su_informed writes no summary key"):
        plan_runs(read_spec(spec))
    spec.write_text('scenario: su2009_fig2\nmetrics: [eta.median]\n')
    with pytest.raises(ScenarioError, match=r"metrics\[0\]: unknown metric 'eta.median'"):
        read_spec(spec)
