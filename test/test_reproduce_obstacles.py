"""Olfati-Saber 2006's obstacle experiments in the reproduction (Section VIII, Figs. 10, 11).

The presets hold the paper's numbers (d, r, d', r', eps, h, the obstacle matrices) and our
choices where it is silent (gamma and beta gains with ``c2 = 2 sqrt(c1)``, beta strongest);
the analysis of a real run agrees with the run's summary and with the geometry read back from
its time series; the per-seed claim fails when any of its parts fails; both experiments are
in the catalogue with their sweep specs.
"""

import math

import numpy as np
import pytest

from flock_swarm.core.graphs import components, disk_graph
from flock_swarm.core.run import simulate
from flock_swarm.presets import load
from flock_swarm.reproduce.catalogue import all_experiments, experiment
from flock_swarm.reproduce.experiments.olfati_saber2006_obstacles import (
    clearances, passed_mask, spheres, squeezed_and_rejoined)
from flock_swarm.reproduce.seeds import study_runs

#: [OS06] Fig. 11 and Fig. 10: the obstacle matrices (centre, radius).
FIG11 = [((150.0, 30.0), 25.0), ((150.0, 100.0), 25.0)]
FIG10 = [((100.0, 20.0), 10.0), ((110.0, 60.0), 4.0), ((120.0, 40.0), 2.0),
         ((130.0, -20.0), 5.0), ((150.0, 40.0), 5.0), ((160.0, 0.0), 3.0)]
PRESETS = {'olfati_saber2006_squeeze': FIG11, 'olfati_saber2006_rejoin': FIG10}


@pytest.mark.parametrize('name', sorted(PRESETS))
def test_the_presets_hold_the_papers_numbers(name):
    sc = load(name)
    assert (sc.n_agents, sc.dim) == (150, 2)
    law, obs = sc.law, sc.obstacles
    # Section VIII: d = 7, r = 1.2 d, d' = 0.6 d, r' = 1.2 d', eps = 0.1, a = b = 5,
    # h = 0.2 for phi_alpha and 0.9 for phi_beta.
    assert (law.d, law.eps, law.a, law.b, law.h) == (7.0, 0.1, 5.0, 5.0, 0.2)
    assert law.r == pytest.approx(1.2 * law.d)
    assert obs.d_beta == pytest.approx(0.6 * law.d)
    assert obs.r_beta == pytest.approx(1.2 * obs.d_beta)
    assert (obs.h, obs.eps) == (0.9, 0.1)
    assert [(tuple(c), r) for c, r in spheres(sc)] == PRESETS[name]
    # Ours: the usual tuning c2 = 2 sqrt(c1) of each gain pair, the beta term strongest.
    assert law.c2 == pytest.approx(2.0 * math.sqrt(law.c1))
    assert obs.c2_beta == pytest.approx(2.0 * math.sqrt(obs.c1_beta))
    assert obs.c1_beta > law.c1 and law.navigation == 'bounded'


def test_clearance_and_passage_are_the_geometry():
    discs = [(np.array([150.0, 30.0]), 25.0), (np.array([150.0, 100.0]), 25.0)]
    q = np.array([[150.0, 65.0], [176.0, 30.0], [100.0, 30.0]])
    np.testing.assert_allclose(clearances(q, discs),
                               [[10.0, 10.0], [1.0, math.hypot(26.0, 70.0) - 25.0],
                                [25.0, math.hypot(50.0, 70.0) - 25.0]])
    assert passed_mask(q, discs).tolist() == [False, True, False]


@pytest.fixture(scope='module')
def squeeze_run():
    """Return a real run of the squeezing experiment with 20 agents (the analysis' input)."""
    sc = load('olfati_saber2006_squeeze', ['n_agents=20', 'duration=60'])
    result = simulate(sc)
    exp = experiment('olfati_saber2006_squeeze')
    return sc, result, exp.analyse(sc, result.summary, result.series)


def test_the_analysis_of_a_run_is_its_summary_and_its_series(squeeze_run):
    sc, result, m = squeeze_run
    s, series = result.summary, result.series
    assert m['clearance_min'] == s['obstacle_clearance_min']
    assert m['penetrations'] == s['obstacle_penetrations'] == 0
    assert m['components_final'] == s['components_final']
    # The summary's clearance is folded in at every step, the series' only when recorded.
    recorded = clearances(series['q'], spheres(sc)).min()
    assert recorded >= m['clearance_min'] > 0
    np.testing.assert_allclose(series['obstacle_clearance'].min(), recorded)
    q = series['q'][-1]
    assert m['agents_passed'] == int((q[:, 0] > 175.0).sum())
    _, labels = components(disk_graph(q, sc.law.radius, sc.law.strict_radius))
    assert m['largest_component_final'] == np.bincount(labels).max()
    assert m['trailing_distance'] == pytest.approx(series['leader_q'][-1, 0] - q[:, 0].min())
    assert m['n_agents'] == 20 and m['eta_tolerance'] == sc.eta_tolerance


def test_the_claim_fails_when_any_part_fails(squeeze_run):
    _, _, m = squeeze_run
    good = dict(m, agents_passed=m['n_agents'], components_final=1,
                velocity_mismatch_max=0.0)
    assert squeezed_and_rejoined(good)
    for bad in ({'penetrations': 1}, {'clearance_min': -0.1}, {'clearance_min': 0.0},
                {'agents_passed': m['n_agents'] - 1}, {'components_final': 2},
                {'velocity_mismatch_max': m['eta_tolerance'] * 1.01}):
        assert not squeezed_and_rejoined(dict(good, **bad)), bad


@pytest.mark.parametrize('key', sorted(PRESETS))
def test_both_experiments_are_in_the_catalogue_with_their_specs(key):
    assert key in [e.key for e in all_experiments()]
    exp = experiment(key)
    assert exp.scenario == key and exp.criterion.statement().startswith('The fraction')
    (first, first_runs), (longer, longer_runs), (linear, linear_runs) = [
        study_runs(s.spec) for s in exp.setups]
    assert first.scenario == longer.scenario == linear.scenario == key
    assert [r.seed for r in first_runs] == list(range(1, 51))
    # 50 seeds: a 300 s run costs 12-14 s, under the report's one-minute rule.
    assert [r.seed for r in longer_runs] == list(range(1, 51))
    assert dict(longer.fixed)['duration'] == 300.0
    assert [r.seed for r in linear_runs] == list(range(1, 51))
    assert dict(linear.fixed)['protocol.navigation'] == 'linear'
