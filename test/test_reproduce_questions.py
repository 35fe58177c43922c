"""The three questions of every study (:mod:`flock_swarm.reproduce.questions`), the held-out
seed set and the fragile verdicts (:mod:`flock_swarm.reproduce.seeds`): closed forms on
synthetic series and records, then a tiny real study run on both seed sets."""

import numpy as np
import pytest

from flock_swarm.presets import prepare
from flock_swarm.reproduce import seeds
from flock_swarm.reproduce.catalogue import experiment
from flock_swarm.reproduce.experiment import Experiment, MeanClaim, SetUp, seed_spec
from flock_swarm.reproduce.questions import (TIMES, TOLERANCES, question_keys, three_questions,
                                             time_key, tolerance_key)
from flock_swarm.study.cache import read_cache
from flock_swarm.study.execute import SerialBackend


def two_groups_series(speed_error: float) -> dict:
    """Return a 2-D series of 6 agents at t = 0, 5, 10 s: agents 0-3 in a square of side 1
    (one r-disk component at r = 4, informed agent 0), agents 4-5 a pair 100 m away; the
    leader moves at (1, 0); at t_final agents 0-3 move at (1 + speed_error * i, 0) and the
    pair at rest."""
    q = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [100, 0], [100, 1]], dtype=float)
    p = np.zeros((6, 2))
    p[:4, 0] = 1.0 + speed_error * np.arange(4)
    early = np.zeros((6, 2))
    informed = np.zeros(6, dtype=bool)
    informed[0] = True
    return {'t': np.array([0.0, 5.0, 10.0]), 'q': np.stack([q, q, q]),
            'p': np.stack([early, early, p]), 'leader_p': np.tile([1.0, 0.0], (3, 1)),
            'informed': np.stack([informed] * 3)}


def test_three_questions_of_two_groups_have_their_closed_form():
    sc, _ = prepare('su2009_fig2', ['n_agents=10'])
    series = two_groups_series(0.03)
    out = three_questions(sc, series)
    assert set(out) == set(question_keys())
    # Whole: the largest component holds 4 of 6, the same 4 are linked to informed agent 0.
    assert out['whole_largest'] == pytest.approx(4 / 6)
    assert out['whole_linked'] == pytest.approx(4 / 6)
    # With the leader: the mean velocity is ((4 + 0.03 (0 + 1 + 2 + 3)) / 6, 0) against (1, 0).
    assert out['group_velocity_error'] == pytest.approx(abs((4 + 0.18) / 6 - 1.0))
    # Agreement: errors 0, 0.03, 0.06, 0.09 for the square, 1 for the pair.
    expected = {0.02: 1, 0.05: 2, 0.1: 4, 0.2: 4, 0.5: 4}
    for tol in TOLERANCES:
        assert out[tolerance_key(tol)] == pytest.approx(expected[tol] / 6)
    # Over time: at half and two thirds of the run (t = 5 s) nobody moves yet (errors 1).
    assert out[time_key(TIMES[0])] == 0.0
    assert out[time_key(1.0)] == out[tolerance_key(sc.eta_tolerance)]


def record(seed: int, eta: float) -> dict:
    return {'seed': seed, 'metrics': {'eta': eta, 'linked_to_informed': 90,
                                      'components_final': 1, 'whole_largest': 0.9},
            'wall_time_s': 1.0, 'status': 'completed'}


def test_a_verdict_that_flips_on_the_held_out_seeds_is_marked_fragile():
    exp = experiment('su2009_fig2')
    first = [record(s, e) for s, e in ((1, 0.86), (2, 0.87), (3, 0.86), (4, 0.85))]
    res = seeds.summarise(exp, [('as printed', first, 4)])
    assert res['setups'][0]['judged']['verdict'] == 'reproduced'
    held = [record(s, e) for s, e in ((1001, 0.5), (1002, 0.9), (1003, 0.2), (1004, 0.8))]
    seeds.attach_held_out(res, exp, [('as printed', held, 4)])
    [s] = res['setups']
    assert s['held_out']['judged']['verdict'] == 'inconclusive'
    assert s['fragile'] is True
    judged = exp.judge({'seeds': res})
    assert judged['fragile'] is True
    assert 'held-out seeds (4 of 4)' in judged['over']
    res.update(commands=['sweep reproduce_su2009_fig2'], caches=['fig2.jsonl'])
    text = '\n'.join(seeds.section(exp, res))
    assert '(**fragile**)' in text
    # The same verdict on both sets is not fragile.
    seeds.attach_held_out(res, exp, [('as printed', first, 4)])
    assert res['setups'][0]['fragile'] is False


def test_the_margin_is_the_distance_to_the_nearer_edge_of_the_band():
    # Band [0.81, 0.91]: the interval [0.812, 0.903] clears the lower edge by 0.002.
    judged = {'statistic': 'mean eta', 'interval': [0.812, 0.903], 'band': [0.81, 0.91]}
    assert seeds.margin(judged) == pytest.approx(0.002)
    # Missing the band: negative.
    judged['interval'] = [0.7, 0.8]
    assert seeds.margin(judged) == pytest.approx(-0.11)
    # A fraction's upper end (1) does not count: only the distance above at_least.
    fraction = {'statistic': 'fraction of seeds', 'interval': [0.93, 1.0], 'band': [0.9, 1.0]}
    assert seeds.margin(fraction) == pytest.approx(0.03)
    assert seeds.margin({'interval': None, 'band': [0, 1]}) is None


class TinyStudy(Experiment):
    """Su 2009 Fig. 2 shrunk to 12 agents and 0.1 s, two seeds."""

    key = 'tiny_study'
    criterion = MeanClaim('eta', 0.5, 0.5, 'eta at t_final')
    setups = (SetUp(seed_spec('tiny_study', 'su2009_fig2',
                              {'n_agents': 12, 'duration': 0.1}, count=2), 'tiny'),)


def test_a_study_runs_its_held_out_seeds_into_their_own_cache(tmp_path):
    exp = TinyStudy()
    said = []
    res = seeds.run_study(exp, tmp_path, SerialBackend(), said.append)
    first = read_cache(tmp_path / 'tiny_study.jsonl')
    held = read_cache(tmp_path / 'tiny_study_heldout.jsonl')
    assert sorted(r['seed'] for r in first.values()) == [1, 2]
    assert sorted(r['seed'] for r in held.values()) == [seeds.HELD_OUT_FIRST,
                                                        seeds.HELD_OUT_FIRST + 1]
    [s] = res['setups']
    assert s['held_out']['seeds'] == 2 and s['fragile'] is False
    # Every record answers the three questions; the summary has their means and intervals.
    for r in [*first.values(), *held.values()]:
        assert set(question_keys()) <= set(r['metrics'])
    assert s['questions']['whole_largest']['count'] == 2
    # Read back from the caches alone, the same judgement.
    again = seeds.run_study(exp, tmp_path, SerialBackend(), said.append, cached_only=True)
    assert again['setups'][0]['held_out']['judged'] == s['held_out']['judged']
    name = seeds.curves_figure(res, exp.key, tmp_path / 'curves.png')
    assert name == 'curves.png' and (tmp_path / 'curves.png').stat().st_size > 0


def test_studies_option_names_an_unknown_experiment_in_one_line(capsys):
    from flock_swarm.cli import reproduce
    assert reproduce.main(['--seeds-only', '--studies', 'su2009_fig2', 'nope']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown experiment 'nope'" in err[0]
    assert reproduce.main(['--studies', 'su2009_fig2']) == 2
    assert capsys.readouterr().err.strip() == 'reproduce: error: --studies needs --seeds-only'


def test_run_studies_runs_only_the_named_studies(tmp_path):
    # The named study runs into the empty cache directory; the other only reads (nothing).
    said = []
    out = seeds.run_studies(tmp_path, SerialBackend(), said.append,
                            experiments=[TinyStudy(), experiment('jadbabaie2003_linked')],
                            only=frozenset({'tiny_study'}), figures=tmp_path)
    assert out['tiny_study']['setups'][0]['seeds'] == 2
    assert out['jadbabaie2003_linked']['setups'][0]['seeds'] == 0
    names = sorted(p.name for p in tmp_path.glob('*.jsonl'))
    assert names == ['tiny_study.jsonl', 'tiny_study_heldout.jsonl']


@pytest.mark.parametrize('conversion, tau_c', [('naive', None), ('exact', None),
                                               ('exact', 0.05), ('exact', 0.2)])
def test_a_lag_plants_delivered_fraction_has_its_closed_form(conversion, tau_c):
    from flock_swarm.core.plants.models import VelocityLag
    from flock_swarm.reproduce.mechanisms import delivered_fraction, lag_fraction
    plant = VelocityLag(tau=0.1, conversion=conversion, conversion_tau=tau_c)
    rng = np.random.default_rng(3)
    x, u = rng.normal(size=(50, 4)), rng.normal(size=(50, 2))
    f, residual = delivered_fraction(plant, x, u, 0.02)
    # v_sp - v = (u T) / a held over T: v moves by (1 - e) (v_sp - v) = ((1 - e) / a) u T.
    e = np.exp(-0.02 / 0.1)
    a = 1.0 if conversion == 'naive' else 1.0 - np.exp(-0.02 / (tau_c or 0.1))
    assert f == pytest.approx((1.0 - e) / a, rel=1e-12)
    assert f == pytest.approx(lag_fraction(0.1, 0.02, conversion, tau_c), rel=1e-12)
    assert residual < 1e-12
    assert lag_fraction(0.1, 0.02, 'naive') == pytest.approx(0.18127, abs=1e-5)


@pytest.mark.parametrize('plant, expected', [
    ('{model: velocity_lag, tau: 0.1}', 1.0),
    ('{model: velocity_lag, tau: 0.1, conversion: naive}', 0.18127),
    ('{model: unicycle, ell: 0.1}', 1.0)])
def test_the_plant_study_measures_its_mechanism_on_a_run(plant, expected):
    from flock_swarm.core.run import simulate
    exp = experiment('su2009_fig2_plants')
    sc, _ = prepare('su2009_fig2', ['n_agents=12', 'duration=0.4', f'plant={plant}'])
    result = simulate(sc)
    m = exp.analyse(sc, result.summary, result.series)
    # Over the run's own states, no limit set: the exact conversions deliver the law's
    # velocity change (the unicycle's hand point too), the naive lag 1 - exp(-dt / tau).
    assert m['delivered_fraction'] == pytest.approx(expected, abs=1e-5)
    assert m['delivered_residual'] < 1e-6
    if 'velocity_lag' in plant:
        assert m['predicted_fraction'] == pytest.approx(m['delivered_fraction'], rel=1e-9)


def test_the_mean_age_under_loss_is_p_over_one_plus_p_on_a_lattice_at_rest():
    from flock_swarm.core import delay_drag as dd
    from flock_swarm.core.run import simulate
    from flock_swarm.reproduce.mechanisms import held_age
    fig2, _ = prepare('su2009_fig2')
    q = dd.triangular_lattice(37, fig2.law.d)
    sc, _ = prepare('su2009_fig2', extra={
        'n_agents': 37, 'duration': 4.0, 'record_every': 1,
        'informed': {'select': 'first', 'count': 0},
        'initial': {'positions': q.tolist(), 'velocities': [[0.0, 0.0]] * 37},
        'network': {'loss': 0.2}})
    summary = simulate(sc).summary
    # Every link persists (the lattice is at equilibrium, at rest): of about 40,000 uses the
    # mean age is p / (1 + p) = 1/6 step, to sampling error (about 0.003). (The summary
    # averages the recorded instants' means, each instant's tally since the last: one
    # record per step weighs every step alike.)
    assert summary['network_age_mean'] / sc.dt == pytest.approx(held_age(0.2), abs=0.01)
    assert summary['network_delivered'] == pytest.approx(0.8, abs=0.01)
