"""Tests of the example law and leader, through flock_swarm's public testing API only.

The fixtures ``ros_domain`` and ``flock_swarm_run`` come from the ``flock_swarm`` pytest
plugin (installed with flock_swarm); the ROS runs are launch-free: world, leader and agents
spin in the test's process on a domain of its own.
"""

from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose

from flock_swarm.plugin import LawSetup
from flock_swarm.testing import assert_matches_sim, check_law
from flock_swarm_examples.cucker_smale import CuckerSmale
from flock_swarm_examples.figure_eight import FigureEight

SCENARIO = Path(__file__).resolve().parents[1] / 'config' / 'cucker_smale_figure_eight.yaml'
#: A few seconds of the scenario, every step recorded: quick, and enough to compare.
SHORT = ['duration=1.0', 'record_every=1']


def test_two_agents_align_with_the_papers_weight():
    """[CS07] eq. (1) for two agents at distance 2: ``a_12 = K / (1 + 4)^beta``."""
    law = CuckerSmale(K=2.0, beta=0.5)
    qi, pi = np.array([[0.0, 0.0]]), np.array([[1.0, 0.0]])
    qj, pj = np.array([[2.0, 0.0]]), np.array([[0.0, 3.0]])
    to_i = law.pair(qi, pi, qj, pj, np.ones(1))
    assert_allclose(to_i, 2.0 / np.sqrt(5.0) * np.array([[-1.0, 3.0]]), rtol=1e-15)
    # Antisymmetric, as the class says: the pair's momentum is conserved.
    assert_allclose(law.pair(qj, pj, qi, pi, np.ones(1)), -to_i, rtol=1e-15)


def test_the_law_passes_check_law():
    """Its antisymmetry claim, its shapes over a short run, one agent vs container vs sim."""
    report = check_law(SCENARIO, SHORT, steps=10)
    assert report['steps'] == 10 and report['agents'] == 12
    check_law(CuckerSmale(K=2.0, beta=0.5))


def test_the_leader_flies_the_figure_eight(flock_swarm_run):
    """The recorded leader follows ``q(0) + (A sin wt, B sin 2wt)`` (RK4 error only)."""
    run = flock_swarm_run(SCENARIO, ['duration=4.0', 'n_agents=3', 'informed.count=1'])
    assert run.summary['status'] == 'completed'
    leader = run.scenario.raw['leader']
    w, a, b = leader['omega'], leader['width'], leader['height']
    series = run.timeseries()
    t, q = series['t'], series['leader_q']
    want = np.array(leader['position']) + np.stack([a * np.sin(w * t),
                                                    b * np.sin(2 * w * t)], axis=1)
    assert_allclose(q, want, rtol=0, atol=1e-9)
    # What the nodes published on /leader/odom is that same path.
    odom = [msg.pose.pose.position for _, msg in run.messages('/leader/odom')]
    assert len(odom) == run.summary['steps'] + 1
    assert_allclose([[p.x, p.y] for p in odom[::run.scenario.record_every]], want,
                    rtol=0, atol=1e-9)


def test_the_lockstep_ros_run_equals_sim_bit_for_bit(tmp_path, ros_domain):
    run = assert_matches_sim(SCENARIO, tmp_path / 'run', SHORT, domain_id=ros_domain, atol=0)
    assert run.summary['protocol'] == 'cucker_smale'


def test_the_leader_model_is_time_dependent():
    """``f(t)`` changes with ``t`` at a fixed state: not an autonomous ODE."""
    model = FigureEight(omega=0.5, width=2.0, height=1.0)
    p = np.zeros((2,))
    assert not model.autonomous
    assert_allclose(model.acceleration(0.0, p, p), [0.0, 0.0], atol=0)
    t = np.pi / 2.0
    assert_allclose(model.acceleration(t, p, p),
                    [-2.0 * 0.25 * np.sin(0.5 * t), -4.0 * 0.25 * np.sin(t)], rtol=1e-15)


def test_the_step_bound_of_the_leader_tracking():
    """``dt`` at or beyond ``min(2 c2 / c1, 2 / c2)`` is refused, below it accepted."""
    law = CuckerSmale(c1=1.0, c2=2.0)

    def setup(dt, informed):
        return LawSetup(dim=2, n_agents=3, graph_type='disk', dt=dt,
                        informed=np.array(informed))
    assert law.step_bounds(setup(0.99, [True, False, False])) == []
    (violation,) = law.step_bounds(setup(1.0, [True, False, False]))
    assert violation.part == 'leader tracking' and violation.dt_max == 1.0
    assert 'use dt < 1' in violation.message(1.0)
    # Without an informed agent nobody tracks the leader: nothing to bound.
    assert law.step_bounds(setup(5.0, [False, False, False])) == []
