"""Unit tests of the flocking laws in ``flock_swarm.core.laws``.

The agent node calls :func:`group_control`, the simulator :func:`swarm_control`, and a robot
that only has its neighbours' states :func:`local_control`; the first block of tests checks
that all three give the same input for every law, the rest checks the laws
against the papers (antisymmetry, invariances, hand-computed two-agent cases, navigation terms).
"""

import math

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from flock_swarm.core.laws import evaluation as pr
from flock_swarm.core.laws import jadbabaie2003 as jad
from flock_swarm.core.graphs import EdgeList, disk_graph
from flock_swarm.core.laws.base import AgentData
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.registry import laws

PROTOCOLS = laws()

DT = 0.1
# Every law in 2-D, and in 3-D where it allows (Jadbabaie's headings are planar).
LAW_DIMS = [(name, dim) for name in sorted(PROTOCOLS)
            for dim in ((2,) if name == 'jadbabaie_leader' else (2, 3))]
ANTISYMMETRIC_LAW_DIMS = [(name, dim) for name, dim in LAW_DIMS if name != 'jadbabaie_leader']
SU_LAWS = ['olfati_saber_2006', 'su_informed', 'su_accel', 'su_informed_accel']


def empty_edges(n):
    """Return a graph on ``n`` vertices without edges."""
    none = np.zeros(0, dtype=np.intp)
    return EdgeList(n, none, none, np.zeros(0))


def pair_edge(n=2):
    """Return the graph with the single edge 0-1."""
    return EdgeList(n, np.array([0]), np.array([1]), np.ones(1))


def make_swarm(name, dim, seed, n=24):
    """Return ``(law, q, p, edges, leader, agents)`` for a random swarm of ``n`` agents.

    Positions fill a box of side ``2.5 r`` so that each agent has several neighbours. Laws acting
    on all pairs get the complete graph with weights ``w`` on the r-disk edges (the scenario's
    construction), written out here with a brute-force distance matrix.
    """
    law = PROTOCOLS[name]()
    rng = np.random.default_rng(seed)
    side = 2.5 * law.radius
    q = rng.uniform(0.0, side, size=(n, dim))
    p = rng.uniform(-1.0, 1.0, size=(n, dim))
    informed = rng.random(n) < 0.4
    nav_gains = None
    adaptive = None
    if name == 'yu_pinning_observer':
        # D_i H_i = D~_i H~_i = e_k e_k^T: informed agent i observes component k = i mod dim.
        nav_gains = np.zeros((n, 2, dim, dim))
        for i in np.flatnonzero(informed):
            nav_gains[i, :, i % dim, i % dim] = 1.0
    if name == 'zhou_pseudo_leader':
        adaptive = rng.uniform(0.5, 2.0, size=n)
    leader = LeaderState(rng.uniform(0.0, side, size=dim), rng.uniform(-1.0, 1.0, size=dim),
                         rng.uniform(-0.5, 0.5, size=dim))
    edges = build_edges(law, q)
    return law, q, p, edges, leader, AgentData(
        informed, {} if nav_gains is None else {'nav_gains': nav_gains},
        {} if adaptive is None else {'h': adaptive})


def build_edges(law, q):
    """Return the interaction graph of a law at positions ``q``."""
    if not law.all_pairs:
        return disk_graph(q, law.radius, law.strict_radius)
    n = q.shape[0]
    i, j = np.triu_indices(n, k=1)
    dist = np.linalg.norm(q[j] - q[i], axis=1)
    return EdgeList(n, i, j, law.w * (dist < law.radius))


def neighbours(edges, i):
    """Return the neighbours of ``i`` and the weights of the edges to them."""
    as_i = edges.i == i
    as_j = edges.j == i
    nb = np.concatenate((edges.j[as_i], edges.i[as_j]))
    w = np.concatenate((edges.weight[as_i], edges.weight[as_j]))
    return nb, w


# --------------------------------------------------------------------------------------------
# (a) the agent node and the simulator compute the same input


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('name, dim', LAW_DIMS)
def test_local_control_equals_swarm_control(name, dim, seed):
    law, q, p, edges, leader, agents = make_swarm(name, dim, seed)
    u = pr.swarm_control(law, q, p, edges, leader, agents, DT)
    assert u.shape == q.shape
    assert edges.size > 0
    scale = np.abs(u).max()
    for i in range(q.shape[0]):
        nb, w = neighbours(edges, i)
        u_i = pr.local_control(law, q[i], p[i], q[nb], p[nb], w, leader,
                               agents.subset(np.array([i])), DT)
        assert u_i.shape == (dim,)
        assert_allclose(u_i, u[i], rtol=1e-12, atol=1e-12 * scale)


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('name, dim', LAW_DIMS)
def test_group_control_is_swarm_control_of_the_group(name, dim, seed):
    """The rows an agent node (one id) or a container (many) computes are sim's, bit for bit."""
    law, q, p, edges, leader, agents = make_swarm(name, dim, seed)
    u = pr.swarm_control(law, q, p, edges, leader, agents, DT)
    rng = np.random.default_rng(seed)
    n = q.shape[0]
    for ids in (np.array([0]), np.array([n - 1]), np.sort(rng.choice(n, 7, replace=False)),
                np.arange(n)):
        u_group = pr.group_control(law, ids, q, p, edges, leader, agents.subset(ids), DT)
        assert u_group.shape == (ids.size, dim)
        assert_array_equal(u_group, u[ids])


@pytest.mark.parametrize('name, dim', LAW_DIMS)
def test_lost_leader_is_the_uninformed_law(name, dim):
    """``leader=None`` (an agent that lost the leader) drops exactly the navigational terms."""
    law, q, p, edges, leader, agents = make_swarm(name, dim, 3)
    u = pr.swarm_control(law, q, p, edges, None, agents, DT)
    if name == 'jadbabaie_leader':
        # Eq. (38) without agent 0: the same as a leader too far away to be a neighbour.
        far = LeaderState(q.max(axis=0) + 10 * law.radius, leader.p, leader.a)
        assert_array_equal(u, pr.swarm_control(law, q, p, edges, far, agents, DT))
    else:
        assert_array_equal(u, pr.pair_sums(law, q, p, edges))
    if name in ('su_informed', 'su_informed_accel'):
        nobody = AgentData(np.zeros_like(agents.informed))
        assert_allclose(u, pr.swarm_control(law, q, p, edges, leader, nobody, DT),
                        rtol=0, atol=1e-12)
    rates = law.state_rate(q, p, None, agents)
    assert not any(rate.any() for rate in rates.values())


# --------------------------------------------------------------------------------------------
# (b), (c) pairwise antisymmetry, translation and Galilean invariance


@pytest.mark.parametrize('name, dim', ANTISYMMETRIC_LAW_DIMS)
def test_pair_sums_add_up_to_zero(name, dim):
    law, q, p, edges, _, _ = make_swarm(name, dim, seed=3)
    sums = pr.pair_sums(law, q, p, edges)
    assert np.abs(sums).max() > 0.0
    total = sums.sum(axis=0)
    assert_allclose(total, 0.0, atol=1e-12 * np.abs(sums).sum())


@pytest.mark.parametrize('name, dim', ANTISYMMETRIC_LAW_DIMS)
def test_pair_is_antisymmetric_edge_by_edge(name, dim):
    # pair(j -> i) = -pair(i -> j), evaluated both ways (not through pair_sums' shortcut).
    law, q, p, edges, _, _ = make_swarm(name, dim, seed=4)
    i, j = edges.i, edges.j
    forward = law.pair(q[i], p[i], q[j], p[j], edges.weight)
    backward = law.pair(q[j], p[j], q[i], p[i], edges.weight)
    assert_allclose(forward, -backward, rtol=1e-12, atol=1e-12 * np.abs(forward).max())


@pytest.mark.parametrize('name, dim', LAW_DIMS)
def test_pair_sums_translation_invariant(name, dim):
    law, q, p, edges, leader, agents = make_swarm(name, dim, seed=5)
    shift = np.array([37.25, -12.5, 4.0])[:dim]
    shifted_edges = build_edges(law, q + shift)
    assert_array_equal(shifted_edges.i, edges.i)
    assert_array_equal(shifted_edges.j, edges.j)
    before = pr.pair_sums(law, q, p, edges)
    after = pr.pair_sums(law, q + shift, p, shifted_edges)
    assert_allclose(after, before, rtol=1e-9, atol=1e-9 * np.abs(before).max())
    # Moving the leader along, the whole input is unchanged too.
    moved = LeaderState(leader.q + shift, leader.p, leader.a)
    u0 = pr.swarm_control(law, q, p, edges, leader, agents, DT)
    u1 = pr.swarm_control(law, q + shift, p, shifted_edges, moved, agents, DT)
    assert_allclose(u1, u0, rtol=1e-9, atol=1e-9 * np.abs(u0).max())


@pytest.mark.parametrize('name, dim', ANTISYMMETRIC_LAW_DIMS)
def test_pair_sums_galilean_invariant(name, dim):
    # All these pair terms depend on velocities only through p_j - p_i.
    law, q, p, edges, _, _ = make_swarm(name, dim, seed=6)
    boost = np.array([3.0, -1.5, 0.25])[:dim]
    before = pr.pair_sums(law, q, p, edges)
    after = pr.pair_sums(law, q, p + boost, edges)
    assert_allclose(after, before, rtol=1e-10, atol=1e-10 * np.abs(before).max())


@pytest.mark.parametrize('name', ['olfati_saber_2006', 'su_accel', 'os2003_sink'])
@pytest.mark.parametrize('dim', [2, 3])
def test_centre_of_mass_obeys_navigation_only(name, dim):
    # Su09 proof of Theorem 2 (iii): by antisymmetry the mean input is
    # f_gamma - c1 (q_bar - q_gamma) - c2 (p_bar - p_gamma) (f_gamma only for eq. (33)).
    law, q, p, edges, leader, agents = make_swarm(name, dim, seed=7)
    u = pr.swarm_control(law, q, p, edges, leader, agents, DT)
    expected = -law.c1 * (q.mean(axis=0) - leader.q) - law.c2 * (p.mean(axis=0) - leader.p)
    if name == 'su_accel':
        expected = expected + leader.a
    assert_allclose(u.mean(axis=0), expected, rtol=1e-10, atol=1e-10 * np.abs(u).max())


# --------------------------------------------------------------------------------------------
# (d) hand-checked two-agent cases


def two_agents(dist, direction, p_common=(0.3, -0.2, 0.1)):
    """Return positions ``dist`` apart along ``direction`` and equal velocities."""
    direction = np.asarray(direction, dtype=float)
    unit = direction / np.linalg.norm(direction)
    q = np.stack((np.array([1.0, 2.0, 3.0])[:unit.size], np.array([1.0, 2.0, 3.0])[:unit.size]
                  + dist * unit))
    p = np.tile(np.asarray(p_common)[:unit.size], (2, 1))
    return q, p, unit


@pytest.mark.parametrize('name', SU_LAWS)
@pytest.mark.parametrize('direction', [(1.0, 0.0), (0.6, -0.8), (1.0, 2.0, -2.0)])
def test_su_two_agents_at_desired_distance_do_not_interact(name, direction):
    # phi_alpha(d_alpha) = rho_h(d_alpha / r_alpha) phi(0) = 0 and equal velocities.
    law = PROTOCOLS[name]()
    q, p, _ = two_agents(law.d, direction)
    assert_allclose(pr.pair_sums(law, q, p, pair_edge()), 0.0, atol=1e-13)


@pytest.mark.parametrize('name', SU_LAWS)
@pytest.mark.parametrize('direction', [(1.0, 0.0), (1.0, 2.0, -2.0)])
def test_su_two_close_agents_repel(name, direction):
    law = PROTOCOLS[name]()   # r = 4, d = 3.3, eps = 0.1, h = 0.2, a = b = 5
    dist = 2.0
    q, p, unit = two_agents(dist, direction)
    sums = pr.pair_sums(law, q, p, pair_edge())
    # By hand: z = ||q_ij||_sigma = (sqrt(1 + 0.1 * 4) - 1)/0.1 = 1.8322; a = b gives c = 0 and
    # phi(x) = 5 x / sqrt(1 + x^2); n_ij = (q_j - q_i)/sqrt(1.4).
    z, r_a, d_a = (((math.sqrt(1.0 + 0.1 * x * x) - 1.0) / 0.1) for x in (dist, 4.0, 3.3))
    x = z / r_a
    rho = 1.0 if x < 0.2 else 0.5 * (1.0 + math.cos(math.pi * (x - 0.2) / 0.8))
    phi = 5.0 * (z - d_a) / math.sqrt(1.0 + (z - d_a) ** 2)
    along = rho * phi * dist / math.sqrt(1.4)
    assert along < 0.0
    assert_allclose(sums[0], along * unit, rtol=1e-12)
    assert_allclose(sums[1], -along * unit, rtol=1e-12)
    # Force on 0 points away from 1.
    assert np.dot(sums[0], q[1] - q[0]) < 0.0


@pytest.mark.parametrize('name', SU_LAWS)
def test_su_agents_beyond_range_do_not_interact(name):
    # Even if coupled by the graph, rho_h(z / r_alpha) = 0 for ||q_ij|| >= r kills both terms.
    law = PROTOCOLS[name]()
    q = np.array([[0.0, 0.0], [law.r, 0.0]])
    p = np.array([[1.0, 0.0], [-1.0, 0.5]])
    assert_allclose(pr.pair_sums(law, q, p, pair_edge()), 0.0, atol=1e-14)


@pytest.mark.parametrize('name', SU_LAWS)
def test_su_velocity_consensus_on_the_plateau(name):
    # Two agents at d (no gradient force) and within h r_alpha: a_ij = 1, so the pair term is
    # p_j - p_i. With h = 0.9 (Su09 Fig. 2), d_alpha = 4.45 < h r_alpha = 5.51.
    law = PROTOCOLS[name](h=0.9)
    q = np.array([[0.0, 0.0], [law.d, 0.0]])
    p = np.array([[1.0, 0.0], [-1.0, 0.5]])
    assert_allclose(pr.pair_sums(law, q, p, pair_edge()), [[-2.0, 0.5], [2.0, -0.5]],
                    rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize('dim', [2, 3])
def test_yu_two_agents_at_paper_distance_balance(dim):
    # Yu10 Section 4.1: a = 1, b = 20, c_bar = 0.2 balance at d = 0.7740; the gain there is
    # within 4e-4 of zero (4-digit rounding of the root, slope 7.74), times ||r_ij|| = 0.774.
    law = PROTOCOLS['yu_pinning_observer']()
    q, p, _ = two_agents(0.7740, np.ones(dim))
    assert_allclose(pr.pair_sums(law, q, p, pair_edge()), 0.0, atol=4e-4)
    q, p, _ = two_agents(law.d, np.ones(dim))
    assert_allclose(pr.pair_sums(law, q, p, pair_edge()), 0.0, atol=1e-13)
    assert_allclose(law.d, 0.7740, atol=5e-5)


def test_yu_two_agents_hand_value():
    # At ||r_ij|| = 0.5: gain = 1 - 20 exp(-0.25 / 0.2) = 1 - 20 e^-1.25; force on 0 is
    # gain (r_1 - r_0) + c (v_1 - v_0) with c = 5.
    law = PROTOCOLS['yu_pinning_observer']()
    q = np.array([[0.0, 0.0], [0.3, 0.4]])
    p = np.array([[0.0, 0.0], [0.1, -0.2]])
    gain = 1.0 - 20.0 * math.exp(-1.25)
    expected = gain * np.array([0.3, 0.4]) + 5.0 * np.array([0.1, -0.2])
    sums = pr.pair_sums(law, q, p, pair_edge())
    assert_allclose(sums[0], expected, rtol=1e-13)
    assert_allclose(sums[1], -expected, rtol=1e-13)


@pytest.mark.parametrize('dim', [2, 3])
def test_os2003_two_agents(dim):
    law = PROTOCOLS['os2003_sink']()   # d = 7, r = 8.4, a = 1, b = 5
    # At d: psi_alpha(0) = 0 and sigma_alpha(0) = 0, so phi_alpha(0) = 0.
    q, p, _ = two_agents(law.d, np.ones(dim))
    assert_allclose(pr.pair_sums(law, q, p, pair_edge()), 0.0, atol=1e-14)
    # Closer: repulsion; a little farther: attraction. (Near r the rho' psi_alpha / r term of
    # eq. (23) dominates and psi_hat decreases to 0, so the action turns negative again.)
    for dist, sign in ((5.0, -1.0), (7.5, 1.0)):
        q, p, unit = two_agents(dist, np.ones(dim))
        s = pr.pair_sums(law, q, p, pair_edge())
        assert sign * np.dot(s[0], unit) > 0.0
        assert_allclose(np.abs(s[0]), np.abs(np.dot(s[0], unit)) * unit, rtol=1e-12)


def test_os2003_two_agents_plateau_hand_value():
    # At dist 1 < delta r = 1.68 the influence map is 1 and phi_alpha = sigma_alpha(1 - 7).
    # With a = 1, b = 5: c = 4 / (2 sqrt 5); sigma(z) = 3 (z + c)/sqrt(1 + (z + c)^2) - 2.
    law = PROTOCOLS['os2003_sink']()
    q = np.array([[0.0, 0.0], [0.6, 0.8]])
    p = np.array([[0.0, 0.0], [0.5, 0.0]])
    c = 4.0 / (2.0 * math.sqrt(5.0))
    z = 1.0 - 7.0
    sigma = 3.0 * (z + c) / math.sqrt(1.0 + (z + c) ** 2) - 2.0
    expected = sigma * np.array([0.6, 0.8]) + 1.0 * np.array([0.5, 0.0])
    assert_allclose(pr.pair_sums(law, q, p, pair_edge())[0], expected, rtol=1e-12)


@pytest.mark.parametrize('dim', [2, 3])
def test_zhou_two_agents_at_potential_minimum(dim):
    # V is minimal at ||q_ij||_sigma = sqrt(c2/c1) = 1; with sigma = 0.1 that is the distance
    # sqrt(((1 * 0.1 + 1)^2 - 1) / 0.1) = sqrt(2.1). Equal velocities: no coupling either.
    law = PROTOCOLS['zhou_pseudo_leader']()
    q, p, _ = two_agents(math.sqrt(2.1), np.ones(dim))
    edges = EdgeList(2, np.array([0]), np.array([1]), np.array([law.w]))
    assert_allclose(pr.pair_sums(law, q, p, edges), 0.0, atol=1e-13)


def test_zhou_velocity_coupling_uses_edge_weight():
    # At the APF minimum only w_ij (v_j - v_i) remains.
    law = PROTOCOLS['zhou_pseudo_leader']()
    q = np.array([[0.0, 0.0], [math.sqrt(2.1), 0.0]])
    p = np.array([[0.0, 1.0], [0.5, 0.0]])
    edges = EdgeList(2, np.array([0]), np.array([1]), np.array([70.0]))
    assert_allclose(pr.pair_sums(law, q, p, edges), [[35.0, -70.0], [-35.0, 70.0]],
                    rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------------------------
# (e) navigation terms


def isolated_swarm(dim, seed, n=6):
    """Return far-apart agents with a random leader (no pair terms)."""
    rng = np.random.default_rng(seed)
    q = 1000.0 * np.arange(n)[:, None] * np.ones(dim) + rng.uniform(-1.0, 1.0, (n, dim))
    p = rng.uniform(-2.0, 2.0, size=(n, dim))
    leader = LeaderState(rng.uniform(-5.0, 5.0, dim), rng.uniform(-1.0, 1.0, dim),
                         rng.uniform(-1.0, 1.0, dim))
    informed = np.array([True, False, True, False, False, True])[:n]
    return q, p, leader, informed


# Which navigation terms each law applies, from Su09 eq. (7), (10), (33) and Section V.C.
SU_NAVIGATION = [
    ('olfati_saber_2006', False, False),
    ('su_informed', True, False),
    ('su_accel', False, True),
    ('su_informed_accel', True, True),
]


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('name, only_informed, feedforward', SU_NAVIGATION)
def test_su_navigation_terms(name, only_informed, feedforward, dim):
    law = PROTOCOLS[name]()
    q, p, leader, informed = isolated_swarm(dim, seed=20)
    agents = AgentData(informed)
    edges = disk_graph(q, law.r)
    assert edges.size == 0
    nav = -0.5 * (q - leader.q) - 0.5 * (p - leader.p)
    if feedforward:
        nav = nav + leader.a
    if only_informed:
        nav = np.where(informed[:, None], nav, 0.0)
    u = pr.swarm_control(law, q, p, edges, leader, agents, DT)
    assert_allclose(u, nav, rtol=1e-13, atol=1e-13)
    # The agent node with no neighbours gets the same.
    for i in range(q.shape[0]):
        u_i = pr.local_control(law, q[i], p[i], np.zeros((0, dim)), np.zeros((0, dim)),
                               np.zeros(0), leader, agents.subset(np.array([i])), DT)
        assert_allclose(u_i, nav[i], rtol=1e-13, atol=1e-13)


def test_su_informed_uninformed_agent_gets_nothing():
    law = PROTOCOLS['su_informed']()
    q = np.array([[5.0, -3.0]])
    p = np.array([[1.0, 2.0]])
    leader = LeaderState(np.zeros(2), np.zeros(2), np.array([1.0, 1.0]))
    u = pr.swarm_control(law, q, p, empty_edges(1), leader, AgentData(np.array([False])), DT)
    assert_allclose(u, 0.0, atol=0.0)
    # Informed: -0.5 (5, -3) - 0.5 (1, 2) = (-3, 0.5).
    u = pr.swarm_control(law, q, p, empty_edges(1), leader, AgentData(np.array([True])), DT)
    assert_allclose(u, [[-3.0, 0.5]], rtol=1e-15)


@pytest.mark.parametrize('dim', [2, 3])
def test_os2003_sink_term(dim):
    law = PROTOCOLS['os2003_sink']()
    q, p, leader, informed = isolated_swarm(dim, seed=21)
    u = pr.swarm_control(law, q, p, empty_edges(q.shape[0]), leader, AgentData(informed), DT)
    # OS03 eq. (40) with the sink at the leader: -c1 (q - q_d) - c2 (p - p_d), every agent.
    assert_allclose(u, -0.1 * (q - leader.q) - 0.5 * (p - leader.p), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize('dim', [2, 3])
def test_zhou_pseudo_leader_feedback_and_adaptive_rate(dim):
    law = PROTOCOLS['zhou_pseudo_leader']()
    q, p, leader, informed = isolated_swarm(dim, seed=22)
    h = np.linspace(0.5, 3.0, q.shape[0])
    agents = AgentData(informed, state={'h': h.copy()})
    u = pr.swarm_control(law, q, p, empty_edges(q.shape[0]), leader, agents, DT)
    err = p - leader.p
    # Zhou12 eq. (4): u3 = -h_i (v_i - v_l) for pseudo-leaders, 0 otherwise.
    assert_allclose(u, np.where(informed[:, None], -h[:, None] * err, 0.0), rtol=1e-14)
    rate = law.state_rate(q, p, leader, agents)['h']
    expected = np.where(informed, 0.01 * np.sum(err * err, axis=1), 0.0)
    assert_allclose(rate, expected, rtol=1e-14)


@pytest.mark.parametrize('dim', [2, 3])
def test_yu_observer_feedback_acts_on_observed_component_only(dim):
    law = PROTOCOLS['yu_pinning_observer']()
    q, p, leader, _ = isolated_swarm(dim, seed=23, n=3)
    # Agent 0 observes component 0, agent 1 component 1 (Yu10 Section 4.1), agent 2 nothing.
    gains = np.zeros((3, 2, dim, dim))
    gains[0, :, 0, 0] = 1.0
    gains[1, :, 1, 1] = 1.0
    agents = AgentData(np.array([True, True, False]), {'nav_gains': gains})
    u = pr.swarm_control(law, q, p, empty_edges(3), leader, agents, DT)
    dq, dp = q - leader.q, p - leader.p
    expected = np.zeros((3, dim))
    expected[0, 0] = -dq[0, 0] - dp[0, 0]
    expected[1, 1] = -dq[1, 1] - dp[1, 1]
    assert_allclose(u, expected, rtol=1e-14, atol=0.0)


def test_yu_observer_feedback_with_different_position_and_velocity_gains():
    # -D_i H_i (r_i - r_o) - D~_i H~_i (v_i - v_o) with D H = 2 e_0 e_0^T, D~ H~ = 3 e_1 e_1^T.
    law = PROTOCOLS['yu_pinning_observer']()
    gains = np.zeros((1, 2, 2, 2))
    gains[0, 0, 0, 0] = 2.0
    gains[0, 1, 1, 1] = 3.0
    leader = LeaderState(np.array([1.0, 1.0]), np.array([0.5, 0.5]), np.zeros(2))
    u = pr.swarm_control(law, np.array([[2.0, 5.0]]), np.array([[4.0, 1.5]]), empty_edges(1),
                         leader, AgentData(np.array([True]), {'nav_gains': gains}), DT)
    # (-2 (2 - 1), -3 (1.5 - 0.5)) = (-2, -3).
    assert_allclose(u, [[-2.0, -3.0]], rtol=1e-15)


def test_yu_without_observers_has_no_navigation():
    law = PROTOCOLS['yu_pinning_observer']()
    q, p, leader, informed = isolated_swarm(2, seed=24)
    u = pr.swarm_control(law, q, p, empty_edges(q.shape[0]), leader, AgentData(informed), DT)
    assert_allclose(u, 0.0, atol=0.0)


def unit_velocity(theta):
    """Return the 2-D unit vector of heading ``theta``."""
    return np.array([math.cos(theta), math.sin(theta)])


@pytest.mark.parametrize('theta_i, theta_0, expected', [
    (0.3, 1.1, 0.7),
    (2.0, 4.0, 3.0),
    # Paper's convention, headings in [0, 2 pi): 5.9 and 0.1 average to 3.0, not to ~0.
    (5.9, 0.1, 3.0),
])
@pytest.mark.parametrize('speed', [1.0, 2.5])
def test_jadbabaie_isolated_agent_follows_leader(theta_i, theta_0, expected, speed):
    law = jad.JadbabaieLeader(r=5.0, speed=speed)
    q = np.array([[0.0, 0.0]])
    p = 0.7 * unit_velocity(theta_i)[None, :]
    # Leader exactly on the circle (3-4-5 triangle): "in or on" counts it (eq. (38), b_i = 1).
    leader = LeaderState(np.array([3.0, 4.0]), 1.3 * unit_velocity(theta_0), np.zeros(2))
    u = pr.swarm_control(law, q, p, empty_edges(1), leader, AgentData(np.array([False])), DT)
    # theta_i(t+1) = (theta_i + theta_0) / 2; the input reaches speed (cos, sin) in one step.
    assert_allclose(p[0] + u[0] * DT, speed * unit_velocity(expected), rtol=1e-12, atol=1e-12)


def test_jadbabaie_leader_out_of_range_is_ignored():
    law = jad.JadbabaieLeader(r=5.0, speed=2.0)
    p = 0.5 * unit_velocity(1.0)[None, :]
    leader = LeaderState(np.array([3.0, 4.0 + 1e-9]), unit_velocity(3.0), np.zeros(2))
    u = pr.swarm_control(law, np.zeros((1, 2)), p, empty_edges(1), leader,
                         AgentData(np.array([True])), DT)
    # Heading kept, speed set to 2.
    assert_allclose(p[0] + u[0] * DT, 2.0 * unit_velocity(1.0), rtol=1e-12)


def test_jadbabaie_average_of_neighbours():
    # Agents 0, 1 neighbours (distance 0.5 <= r = 1), agent 2 alone; leader far away.
    # Headings 0.01 and 2 pi - 0.01 average to pi (Jadbabaie03 Section VI's example).
    law = jad.JadbabaieLeader(r=1.0, speed=1.0)
    q = np.array([[0.0, 0.0], [0.5, 0.0], [10.0, 0.0]])
    p = np.stack((unit_velocity(0.01), unit_velocity(2.0 * math.pi - 0.01), unit_velocity(2.0)))
    leader = LeaderState(np.array([100.0, 100.0]), unit_velocity(0.0), np.zeros(2))
    edges = disk_graph(q, law.r, law.strict_radius)
    u = pr.swarm_control(law, q, p, edges, leader, AgentData(np.zeros(3, dtype=bool)), DT)
    target = p + u * DT
    assert_allclose(target[0], unit_velocity(math.pi), rtol=1e-12, atol=1e-12)
    assert_allclose(target[1], unit_velocity(math.pi), rtol=1e-12, atol=1e-12)
    assert_allclose(target[2], unit_velocity(2.0), rtol=1e-12, atol=1e-12)


def test_jadbabaie_three_way_average_with_leader():
    # Agent 0 with neighbour 1 (heading 1.0) and the leader (heading 2.0) in range: (0.5+1+2)/3.
    law = jad.JadbabaieLeader(r=1.0, speed=1.0)
    q = np.array([[0.0, 0.0], [0.0, 0.9]])
    p = np.stack((unit_velocity(0.5), unit_velocity(1.0)))
    leader = LeaderState(np.array([0.0, -0.9]), unit_velocity(2.0), np.zeros(2))
    edges = disk_graph(q, law.r, law.strict_radius)
    u = pr.swarm_control(law, q, p, edges, leader, AgentData(np.zeros(2, dtype=bool)), DT)
    assert_allclose(p[0] + u[0] * DT, unit_velocity(3.5 / 3.0), rtol=1e-12)
    # Agent 1 sees agent 0 but the leader is 1.8 away: (1.0 + 0.5) / 2.
    assert_allclose(p[1] + u[1] * DT, unit_velocity(0.75), rtol=1e-12)


def test_heading_range_and_values():
    rng = np.random.default_rng(30)
    p = rng.normal(size=(500, 2))
    theta = jad.heading(p)
    assert np.all((theta >= 0.0) & (theta < 2.0 * math.pi))
    assert_allclose(np.cos(theta), p[:, 0] / np.linalg.norm(p, axis=1), rtol=1e-12, atol=1e-12)
    assert_allclose(np.sin(theta), p[:, 1] / np.linalg.norm(p, axis=1), rtol=1e-12, atol=1e-12)
    # Hand values: east 0, north pi/2, west pi, south 3 pi/2.
    axes = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    assert_allclose(jad.heading(axes), [0.0, math.pi / 2, math.pi, 1.5 * math.pi], rtol=1e-15)


@pytest.mark.parametrize('tiny', [1e-17, 1e-300])
def test_heading_stays_below_two_pi_for_tiny_negative_angles(tiny):
    # Jadbabaie03 Section II: headings are represented in [0, 2 pi). A velocity just below the
    # positive x-axis has atan2 = -tiny; mod 2 pi rounds 2 pi - tiny to 2 pi itself.
    theta = jad.heading(np.array([[1.0, -tiny]]))
    assert 0.0 <= theta[0] < 2.0 * math.pi


# --------------------------------------------------------------------------------------------
# (f) adaptive gains


def test_advance_adaptive_increments_informed_only():
    law = PROTOCOLS['zhou_pseudo_leader'](k=0.05)
    q = np.zeros((3, 3))
    p = np.array([[1.0, 2.0, 2.0], [3.0, 0.0, 4.0], [0.0, 0.0, 1.0]])
    leader = LeaderState(np.zeros(3), np.zeros(3), np.zeros(3))
    agents = AgentData(np.array([True, False, True]), state={'h': np.array([1.0, 1.0, 2.0])})
    pr.advance_state(law, q, p, leader, agents, 0.2)
    # ||e_v||^2 = 9, 25, 1: h += 0.2 * 0.05 * (9, -, 1) = (0.09, 0, 0.01).
    assert_allclose(agents.state['h'], [1.09, 1.0, 2.01], rtol=1e-15)


def test_advance_adaptive_repeated_steps():
    law = PROTOCOLS['zhou_pseudo_leader']()
    q = np.zeros((2, 2))
    p = np.array([[3.0, 4.0], [1.0, 0.0]])
    leader = LeaderState(np.zeros(2), np.zeros(2), np.zeros(2))
    agents = AgentData(np.array([True, True]), state={'h': np.ones(2)})
    for _ in range(10):
        pr.advance_state(law, q, p, leader, agents, 0.1)
    # 10 steps of 0.1 * 0.01 * (25, 1).
    assert_allclose(agents.state['h'], [1.25, 1.01], rtol=1e-13)


@pytest.mark.parametrize('name', [n for n in sorted(PROTOCOLS) if n != 'zhou_pseudo_leader'])
def test_advance_adaptive_noop_for_laws_without_adaptation(name):
    law = PROTOCOLS[name]()
    agents = AgentData(np.array([True, True]), state={'h': np.array([1.0, 2.0])})
    leader = LeaderState(np.zeros(2), np.zeros(2), np.zeros(2))
    pr.advance_state(law, np.zeros((2, 2)), np.ones((2, 2)), leader, agents, 0.1)
    assert_allclose(agents.state['h'], [1.0, 2.0], rtol=0.0)
