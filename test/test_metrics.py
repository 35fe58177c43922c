"""Unit tests of the flocking metrics in ``flock_swarm.core.metrics``."""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from flock_swarm.core import metrics as mt
from flock_swarm.core import potentials as pot
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.graphs import EdgeList, disk_graph
from flock_swarm.core.registry import laws


def hand_configuration():
    """Return three agents on the x-axis at 0, 1, 10 and a leader at (3, 0) moving at (1, 1)."""
    q = np.array([[0.0, 0.0], [1.0, 0.0], [10.0, 0.0]])
    p = np.array([[1.0, 1.0], [1.0, 1.05], [2.0, 1.0]])
    leader = LeaderState(np.array([3.0, 0.0]), np.array([1.0, 1.0]), np.zeros(2))
    return q, p, leader


def test_step_metrics_hand_values():
    q, p, leader = hand_configuration()
    m = mt.step_metrics(q, p, leader, eta_tolerance=0.1, radius=2.0)
    assert set(m) == set(mt.STEP_METRICS)
    # Mismatches ||p_i - p_gamma|| = 0, 0.05, 1: two of three within 0.1.
    assert_allclose(m['eta'], 2.0 / 3.0, rtol=1e-15)
    assert_allclose(m['velocity_mismatch_max'], 1.0, rtol=1e-15)
    # Mean position (11/3, 0), leader (3, 0): error 2/3.
    assert_allclose(m['com_position_error'], 2.0 / 3.0, rtol=1e-14)
    # Mean velocity (4/3, 3.05/3) - (1, 1) = (1/3, 0.05/3): norm sqrt(1 + 0.0025)/3.
    assert_allclose(m['com_velocity_error'], math.sqrt(1.0025) / 3.0, rtol=1e-14)
    assert_allclose(m['min_pair_distance'], 1.0, rtol=1e-15)
    # Radius 2: {0, 1} and {2}.
    assert m['components'] == 2.0


@pytest.mark.parametrize('radius, strict, count', [
    (1.0, True, 3.0),      # the pair 0-1 sits exactly at distance 1: not a neighbour under '<'
    (1.0, False, 2.0),     # ... but is under '<='
    (9.0, True, 2.0),      # 1-2 at distance 9, same story
    (9.0, False, 1.0),
    (0.5, True, 3.0),
    (100.0, True, 1.0),
])
def test_step_metrics_components(radius, strict, count):
    q, p, leader = hand_configuration()
    assert mt.step_metrics(q, p, leader, 0.1, radius, strict)['components'] == count


def test_step_metrics_eta_tolerance_is_inclusive():
    # eta counts ||p_i - p_gamma|| <= tolerance; 0.5 is exact in binary.
    q = np.zeros((2, 2))
    p = np.array([[1.5, 1.0], [1.0, 1.0]])
    leader = LeaderState(np.zeros(2), np.array([1.0, 1.0]), np.zeros(2))
    assert mt.step_metrics(q + [[0.0, 0.0], [5.0, 0.0]], p, leader, 0.5, 1.0)['eta'] == 1.0
    assert mt.step_metrics(q + [[0.0, 0.0], [5.0, 0.0]], p, leader, 0.25, 1.0)['eta'] == 0.5


def test_min_pair_distance_matches_brute_force():
    rng = np.random.default_rng(40)
    for dim in (2, 3):
        q = rng.uniform(0.0, 10.0, size=(50, dim))
        brute = min(np.linalg.norm(q[i] - q[j]) for i in range(50) for j in range(i + 1, 50))
        assert_allclose(mt.min_pair_distance(q), brute, rtol=1e-14)


@pytest.mark.parametrize('n', [0, 1])
def test_min_pair_distance_infinite_for_fewer_than_two(n):
    assert mt.min_pair_distance(np.zeros((n, 2))) == math.inf


def test_close_pairs_hand_values():
    q = np.array([[0.0, 0.0], [0.3, 0.0], [5.0, 0.0], [5.0, 0.4], [0.0, 0.5]])
    # Distances: 0-1 0.3, 2-3 0.4, 0-4 0.5 (not < 0.5), 1-4 sqrt(0.34) = 0.583.
    assert mt.close_pairs(q, 0.5) == {(0, 1), (2, 3)}


def test_run_metrics_counts_distinct_pairs_over_updates():
    run = mt.RunMetrics(collision_distance=0.5)
    frames = [
        # Step 1: 0-1 collide.
        np.array([[0.0, 0.0], [0.2, 0.0], [5.0, 0.0], [10.0, 0.0]]),
        # Step 2: 0-1 still colliding (same pair), 2-3 not yet.
        np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 0.0], [6.0, 0.0]]),
        # Step 3: nobody collides.
        np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0], [6.0, 0.0]]),
        # Step 4: 2-3 and 1-2 collide.
        np.array([[0.0, 0.0], [4.8, 0.0], [5.0, 0.0], [5.3, 0.0]]),
    ]
    for q in frames:
        run.update(q, mt.min_pair_distance(q))
    assert run.collision_pairs == {(0, 1), (1, 2), (2, 3)}
    assert len(run.collision_pairs) == 3
    # Smallest distance over the run: 0.1 at step 2.
    assert_allclose(run.min_pair_distance, 0.1, rtol=1e-15)


def test_run_metrics_no_collision():
    run = mt.RunMetrics(collision_distance=0.1)
    q = np.array([[0.0, 0.0], [1.0, 0.0]])
    run.update(q, mt.min_pair_distance(q))
    assert run.collision_pairs == set()
    assert_allclose(run.min_pair_distance, 1.0, rtol=0.0)


def su_energy_double_loop(q, p, leader, law, informed, c1):
    """Return Su09 eq. (12)-(13) literally: 1/2 sum_i [sum_{j != i} psi + h_i c1 |q~|^2 + |p~|^2].

    ``psi_alpha`` is a scalar call per ordered pair; the sigma-norm is the textbook formula.
    """
    total = 0.0
    n = q.shape[0]
    for i in range(n):
        u_i = 0.0
        for j in range(n):
            if j != i:
                dist = np.linalg.norm(q[i] - q[j])
                z = (math.sqrt(1.0 + law.eps * dist * dist) - 1.0) / law.eps
                u_i += float(pot.psi_alpha(z, law.r_alpha, law.d_alpha, law.h, law.a, law.b))
        dq = q[i] - leader.q
        dp = p[i] - leader.p
        u_i += float(informed[i]) * c1 * float(dq @ dq)
        total += 0.5 * (u_i + float(dp @ dp))
    return total


@pytest.mark.parametrize('name', ['olfati_saber_2006', 'su_informed'])
@pytest.mark.parametrize('dim', [2, 3])
def test_su_energy_matches_double_loop(name, dim):
    rng = np.random.default_rng(41 + dim)
    law = laws()[name]()
    n = 9
    q = rng.uniform(0.0, 8.0, size=(n, dim))
    p = rng.uniform(-1.0, 1.0, size=(n, dim))
    informed = rng.random(n) < 0.5
    leader = LeaderState(rng.uniform(0.0, 8.0, dim), rng.uniform(-1.0, 1.0, dim), np.zeros(dim))
    expected = su_energy_double_loop(q, p, leader, law, informed, law.c1)
    assert_allclose(mt.su_energy(q, p, leader, law, informed, law.c1), expected, rtol=1e-12)


def test_su_energy_two_agents_at_rest_at_desired_distance():
    # psi_alpha(d_alpha) = 0, both at rest with the leader, leader at agent 0, agent 1 uninformed:
    # Q = 1/2 [0 + 0] + 1/2 [0 + 0] = 0; informing agent 1 adds 1/2 c1 d^2.
    law = laws()['su_informed']()
    q = np.array([[0.0, 0.0], [law.d, 0.0]])
    p = np.array([[1.0, 1.0], [1.0, 1.0]])
    leader = LeaderState(np.zeros(2), np.array([1.0, 1.0]), np.zeros(2))
    assert_allclose(mt.su_energy(q, p, leader, law, np.array([True, False]), law.c1), 0.0,
                    atol=1e-13)
    assert_allclose(mt.su_energy(q, p, leader, law, np.array([True, True]), law.c1),
                    0.5 * law.c1 * law.d ** 2, rtol=1e-12)


@pytest.mark.parametrize('collision_distance', [0.05, 0.3, 2.0])
def test_update_from_edges_matches_a_full_search(collision_distance):
    """Collision pairs and minimum distance from the step's edges == a brute-force search."""
    rng = np.random.default_rng(11)
    radius = 1.0
    fast, full = mt.RunMetrics(collision_distance), mt.RunMetrics(collision_distance)
    for _ in range(5):
        q = rng.uniform(0.0, 3.0, size=(40, 2))
        fast.update_from_edges(q, disk_graph(q, radius), radius)
        gaps = np.linalg.norm(q[:, None] - q[None], axis=-1)
        i, j = np.nonzero(np.triu(gaps < collision_distance, k=1))
        full.collision_pairs |= set(zip(i.tolist(), j.tolist()))
        full.min_pair_distance = min(full.min_pair_distance, gaps[np.triu_indices(40, 1)].min())
    assert fast.collision_pairs == full.collision_pairs
    assert fast.min_pair_distance == pytest.approx(full.min_pair_distance, rel=1e-12)


@pytest.mark.parametrize('collision_distance', [0.3, 2.0])
def test_stacked_swarms_get_the_metrics_of_their_own_runs(collision_distance):
    # Two swarms of 30 agents doing small random walks (collisions persist and change), stacked.
    rng = np.random.default_rng(4)
    radius = 1.0
    q = [rng.uniform(0.0, 3.0, size=(30, 2)) for _ in range(2)]
    alone = [mt.RunMetrics(collision_distance) for _ in range(2)]
    stacked = [mt.RunMetrics(collision_distance) for _ in range(2)]
    for _ in range(20):
        q = [x + rng.normal(0.0, 0.05, size=x.shape) for x in q]
        for run, x in zip(alone, q):
            run.update_from_edges(x, disk_graph(x, radius), radius)
        both = np.concatenate(q)
        own = [disk_graph(x, radius) for x in q]
        edges = EdgeList(60, np.concatenate([own[0].i, own[1].i + 30]),
                         np.concatenate([own[0].j, own[1].j + 30]),
                         np.ones(own[0].size + own[1].size))
        mt.update_stacked_from_edges(stacked, both, edges, radius)
    for a, b in zip(alone, stacked):
        assert a.collision_pairs and a.collision_pairs == b.collision_pairs
        assert a.min_pair_distance == b.min_pair_distance
