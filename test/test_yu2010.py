"""Yu, Chen, Cao 2010 (Systems & Control Letters 59), Section 4.1, on the simulator.

Oracles from the paper: the closed loop (36) and Theorem 1 (ii) (every agent reaches the
leader's velocity) and (iv) (the pinned agents observing a component of the leader's position
follow it on average: ``(1/3) sum_{i=1..3} r_i1 -> r_o1``, ``(1/3) sum_{i=4..6} r_i2 -> r_o2``).
"""

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.sparse.csgraph import connected_components

from flock_swarm.presets import load
from flock_swarm.core.run import simulate

# Section 4.1: a, b, c_bar, r_s, c; agents 1-3 (ids 0-2) observe component 1 (index 0),
# agents 4-6 (ids 3-5) component 2 (index 1), with unit gains D_i = H_i^T.
A_PAIR, B_PAIR, C_BAR, R_S, C_VEL = 1.0, 20.0, 0.2, 1.0, 5.0
OBSERVERS = {0: (0, 1, 2), 1: (3, 4, 5)}
# Run length. The pinned agents' centroid, once the group moves as one, obeys a damped loop
# with gains scaled by 3 / 20 (three pinned agents of twenty, unit gains) and rotated by the
# leader's A = 0.1 [[0, -1], [1, 0]]: it decays like exp(-0.075 t), a time constant of about
# 13 s. The group's internal relaxation to a local minimum of U is slower and comes with
# rearrangements (velocity mismatch bumps of ~0.1 m/s up to t ~ 40 s). The paper stops at
# 30 s; 90 s (about seven centroid time constants) brings both errors to the cm level.
DURATION = 90.0
# Errors are judged over the last 10 s, which covers a full swing of the slow oscillation.
WINDOW = 10.0
# Allowed errors at the end: 5 cm/s and 5 cm, against initial errors of 1.2 m/s and 0.4 m
# (measured over the window: 0.012 m/s, 0.007 m).
VELOCITY_TOL = 0.05
POSITION_TOL = 0.05


@pytest.fixture(scope='module')
def series():
    """Return the recorded series of the Section 4.1 preset run for ``DURATION`` s."""
    return simulate(load('yu2010_sec41', [f'duration={DURATION}', 'record_every=40'])).series


def control_eq36(q, p, q_o, p_o):
    """Return the input of (36) without the intrinsic term ``A v_i``, for every agent."""
    n = len(q)
    u = np.zeros_like(q)
    for i in range(n):
        for j in range(n):
            dq = q[j] - q[i]
            dist2 = dq @ dq
            if i != j and dist2 <= R_S * R_S:
                u[i] += (A_PAIR - B_PAIR * np.exp(-dist2 / C_BAR)) * dq + C_VEL * (p[j] - p[i])
    for component, ids in OBSERVERS.items():
        for i in ids:
            u[i, component] -= (q[i, component] - q_o[component]) \
                + (p[i, component] - p_o[component])
    return u


def test_control_law_is_eq36(series):
    # The recorded u_k is the law at the recorded state: exact up to rounding.
    for k in (0, 1, len(series['t']) // 3, len(series['t']) - 1):
        expected = control_eq36(series['q'][k], series['p'][k], series['leader_q'][k],
                                series['leader_p'][k])
        assert_allclose(series['u'][k], expected, rtol=1e-9,
                        atol=1e-9 * np.abs(expected).max())


def test_leader_rotates_as_eq35():
    # v_o' = A v_o, A = 0.1 [[0, -1], [1, 0]]: v_o(t) is v_o(0) rotated by 0.1 t; r_o follows.
    s = simulate(load('yu2010_sec41', ['duration=20', 'record_every=200'])).series
    angle = 0.1 * s['t']
    rot = np.stack((np.stack((np.cos(angle), -np.sin(angle)), -1),
                    np.stack((np.sin(angle), np.cos(angle)), -1)), -2)
    v0 = np.array([1.0, 1.0])
    assert_allclose(s['leader_p'], rot @ v0, atol=1e-9)
    # r_o(t) = r_o(0) + A^-1 (v_o(t) - v_o(0)), A^-1 = 10 [[0, 1], [-1, 0]].
    dv = s['leader_p'] - v0
    assert_allclose(s['leader_q'], 10.0 * np.stack((dv[:, 1], -dv[:, 0]), -1), atol=1e-8)


def test_network_stays_connected(series):
    # Assumption 2 of Theorem 1 holds along the run (one component of the r_s-disk graph).
    for q in series['q']:
        close = np.linalg.norm(q[:, None] - q[None], axis=-1) <= R_S
        assert connected_components(close, directed=False)[0] == 1


def test_velocities_reach_the_leader(series):
    # Theorem 1 (ii): all agents move with the leader's velocity asymptotically.
    mismatch = np.linalg.norm(series['p'] - series['leader_p'][:, None], axis=-1).max(axis=1)
    late = series['t'] >= DURATION - WINDOW
    assert mismatch[0] > 1.0
    assert mismatch[late].max() <= VELOCITY_TOL


def test_pinned_centroids_follow_the_leader(series):
    # Theorem 1 (iv): the mean of r_i1 over agents 1-3 tends to r_o1, and of r_i2 over 4-6 to
    # r_o2, although each of them sees one component of the leader only.
    late = series['t'] >= DURATION - WINDOW
    for component, ids in OBSERVERS.items():
        error = series['q'][:, list(ids), component].mean(axis=1) \
            - series['leader_q'][:, component]
        assert np.abs(error[:20]).max() > 0.2
        assert np.abs(error[late]).max() <= POSITION_TOL
