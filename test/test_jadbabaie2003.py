"""Jadbabaie, Lin, Morse 2003 (IEEE TAC 48(6)), Section III: leader following, on the simulator.

Oracles from the paper: the heading update (38) in its matrix form (39),
``theta(t+1) = (I + D + B)^-1 ((I + A) theta(t) + B 1 theta_0)`` with the graph of the
followers (A, D) and the followers seeing the leader (B), and Theorem 4: followers linked to
their leader (here: the graph with the leader is connected at every step) converge to
``theta_0``. Agents move at a common constant speed.
"""

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.sparse.csgraph import connected_components

from flock_swarm.core.scenario import parse_scenario
from flock_swarm.core.run import simulate

THETA_0 = np.pi / 4
# One step of the discrete model is one step dt of the simulator.
DT = 0.1


def headings(p):
    """Return headings in [0, 2 pi) of velocities ``p`` (the paper's representation)."""
    return np.mod(np.arctan2(p[..., 1], p[..., 0]), 2.0 * np.pi)


def run(positions, theta, *, r, speed, steps, leader_position=(0.0, 0.0)):
    """Simulate followers starting at ``positions`` with headings ``theta``."""
    velocities = speed * np.stack((np.cos(theta), np.sin(theta)), axis=-1)
    sc = parse_scenario({
        'dim': 2, 'n_agents': len(positions), 'dt': DT, 'duration': steps * DT,
        'record_every': 1, 'protocol': {'name': 'jadbabaie_leader', 'r': r, 'speed': speed},
        'initial': {'positions': np.asarray(positions).tolist(),
                    'velocities': velocities.tolist()},
        'leader': {'model': 'constant_velocity', 'position': list(leader_position),
                   'velocity': [speed * np.cos(THETA_0), speed * np.sin(THETA_0)]}})
    return simulate(sc).series


def neighbour_matrices(q, q_leader, r):
    """Return ``A`` (followers within r, 'in or on the circle') and ``b`` (leader within r)."""
    dist = np.linalg.norm(q[:, None] - q[None], axis=-1)
    adjacency = (dist <= r).astype(float)
    np.fill_diagonal(adjacency, 0.0)
    b = (np.linalg.norm(q - q_leader, axis=-1) <= r).astype(float)
    return adjacency, b


def test_tight_cluster_follows_the_closed_form():
    # Five followers within 0.3 m of each other and of the leader, r = 3: the graph with the
    # leader stays complete, so (39) is F = 1 1^T / (n + 1) and every follower's heading error
    # after t >= 1 steps is (n / (n + 1))^t times the initial mean error (Theorem 4 in closed
    # form). Headings are averaged as numbers in [0, 2 pi), as in the paper.
    rng = np.random.default_rng(38)
    n = 5
    theta = rng.uniform(0.0, 2.0 * np.pi, n)
    s = run(rng.uniform(-0.3, 0.3, (n, 2)), theta, r=3.0, speed=1.0, steps=80)
    dist = np.linalg.norm(s['q'][:, :, None] - s['q'][:, None], axis=-1)
    assert dist.max() <= 3.0
    assert np.linalg.norm(s['q'] - s['leader_q'][:, None], axis=-1).max() <= 3.0
    steps = np.arange(len(s['t']))
    expected = THETA_0 + (n / (n + 1.0)) ** steps * np.mean(theta - THETA_0)
    assert_allclose(headings(s['p'][1:]), np.repeat(expected[1:, None], n, axis=1),
                    rtol=0, atol=1e-12)
    # Theorem 4: theta -> theta_0 (here within (5/6)^80 * 2 rad ~ 1e-6 rad).
    assert_allclose(headings(s['p'][-1]), THETA_0, atol=2e-6)


@pytest.mark.parametrize('speed', [1.0, 0.25])
def test_speed_is_the_common_speed(speed):
    # Every agent moves at the common constant speed; the random initial velocities have other
    # magnitudes, so this holds from the first step on.
    rng = np.random.default_rng(7)
    s = run(rng.uniform(-1.0, 1.0, (6, 2)), rng.uniform(0.0, 2.0 * np.pi, 6), r=1.5,
            speed=speed, steps=30)
    assert_allclose(np.linalg.norm(s['p'][1:], axis=-1), speed, rtol=1e-12)
    assert_allclose(np.linalg.norm(s['leader_p'], axis=-1), speed, rtol=1e-12)


def test_followers_linked_to_the_leader_converge_by_eq39():
    # A 3 x 3 grid at spacing 0.75 with r = 1: followers see their grid neighbours only and
    # the leader, inside the grid, sees some of them. At speed 0.1 m/s the graph with the
    # leader stays connected (checked), so Theorem 4 applies; each step must be (39) exactly.
    grid = np.array([(x, y) for y in range(3) for x in range(3)], dtype=float) * 0.75
    grid -= grid.mean(axis=0)
    grid[4] += (0.0, 0.3)
    rng = np.random.default_rng(4)
    r = 1.0
    s = run(grid, rng.uniform(0.0, 2.0 * np.pi, 9), r=r, speed=0.1, steps=400,
            leader_position=(0.0, -0.2))
    theta = headings(s['p'])
    n = len(grid)
    sees_leader = []
    for k in range(len(s['t']) - 1):
        adjacency, b = neighbour_matrices(s['q'][k], s['leader_q'][k], r)
        full = np.zeros((n + 1, n + 1))
        full[1:, 1:], full[0, 1:], full[1:, 0] = adjacency, b, b
        assert connected_components(full, directed=False)[0] == 1
        sees_leader.append(b.sum())
        lhs = np.eye(n) + np.diag(adjacency.sum(axis=1) + b)
        rhs = (np.eye(n) + adjacency) @ theta[k] + b * THETA_0
        assert_allclose(theta[k + 1], np.linalg.solve(lhs, rhs), rtol=0, atol=1e-12)
    assert 0 < min(sees_leader) and max(sees_leader) < n  # the leader is not everyone's
    assert np.abs(theta[0] - THETA_0).max() > 1.0
    assert_allclose(theta[-1], THETA_0, atol=1e-9)
