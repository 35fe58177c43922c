"""Unit tests of ``flock_swarm.core.graphs`` against brute-force and hand-built graphs."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from flock_swarm.core import graphs
from flock_swarm.core.graphs import EdgeList


def brute_force_pairs(q, r, strict):
    """Return the sorted pairs ``i < j`` with ``||q_i - q_j|| < r`` (or ``<= r``), O(n^2)."""
    pairs = []
    for i in range(q.shape[0]):
        for j in range(i + 1, q.shape[0]):
            dist = np.linalg.norm(q[i] - q[j])
            if (dist < r) if strict else (dist <= r):
                pairs.append((i, j))
    return pairs


def edge_list(n, pairs, weight=None):
    """Return an :class:`EdgeList` built from a list of pairs."""
    arr = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    w = np.ones(len(arr)) if weight is None else np.asarray(weight, dtype=float)
    return EdgeList(n, arr[:, 0], arr[:, 1], w)


# --------------------------------------------------------------------------------------------
# disk_graph


@pytest.mark.parametrize('strict', [True, False])
@pytest.mark.parametrize('r', [0.05, 0.15, 0.4, 2.0])
@pytest.mark.parametrize('dim', [2, 3])
def test_disk_graph_matches_brute_force(dim, r, strict):
    rng = np.random.default_rng(100 + dim)
    q = rng.uniform(0.0, 1.0, size=(60, dim))
    edges = graphs.disk_graph(q, r, strict)
    expected = brute_force_pairs(q, r, strict)
    assert edges.n == 60
    assert list(zip(edges.i.tolist(), edges.j.tolist())) == expected
    assert_allclose(edges.weight, 1.0, rtol=0.0)


@pytest.mark.parametrize('strict', [True, False])
@pytest.mark.parametrize('n', [2, 5, 30, graphs.BRUTE_FORCE_MAX, graphs.BRUTE_FORCE_MAX + 1])
def test_disk_graph_every_pair_and_tree_give_the_same_edges(n, strict, monkeypatch):
    # Integer grid points: many pairs exactly r = 5 apart (3-4-5), the hardest case.
    rng = np.random.default_rng(n)
    q = rng.integers(0, 12, size=(n, 2)).astype(float)
    edges = {}
    for limit in (0, n):
        monkeypatch.setattr(graphs, 'BRUTE_FORCE_MAX', limit)
        edges[limit] = graphs.disk_graph(q, 5.0, strict)
    assert_array_equal(edges[0].i, edges[n].i)
    assert_array_equal(edges[0].j, edges[n].j)
    assert list(zip(edges[n].i.tolist(), edges[n].j.tolist())) == \
        brute_force_pairs(q, 5.0, strict)


@pytest.mark.parametrize('q, r', [
    ([[0.0, 0.0], [3.0, 4.0]], 5.0),              # 3-4-5 triangle
    ([[0.0, 0.0, 0.0], [1.0, 2.0, 2.0]], 3.0),    # 1 + 4 + 4 = 9
    ([[-1.0, 2.0], [4.0, 14.0]], 13.0),           # 5-12-13 triangle
])
def test_disk_graph_boundary_strict_and_closed(q, r):
    # Distances are exact in binary floating point: the pair sits exactly on the circle.
    q = np.array(q)
    assert graphs.disk_graph(q, r, strict=True).size == 0
    closed = graphs.disk_graph(q, r, strict=False)
    assert_array_equal(closed.i, [0])
    assert_array_equal(closed.j, [1])


def test_disk_graph_default_is_strict():
    q = np.array([[0.0, 0.0], [3.0, 4.0]])
    assert graphs.disk_graph(q, 5.0).size == 0


@pytest.mark.parametrize('n', [0, 1])
def test_disk_graph_empty_for_fewer_than_two(n):
    edges = graphs.disk_graph(np.zeros((n, 2)), 1.0)
    assert edges.n == n
    assert edges.size == 0
    assert edges.i.size == edges.j.size == edges.weight.size == 0


def test_disk_graph_edges_sorted():
    rng = np.random.default_rng(3)
    edges = graphs.disk_graph(rng.uniform(0.0, 1.0, size=(80, 2)), 0.3)
    assert np.all(edges.i < edges.j)
    keys = edges.i * 80 + edges.j
    assert np.all(np.diff(keys) > 0)


# --------------------------------------------------------------------------------------------
# fixed_graph, complete_graph, edges_to_adjacency


def test_fixed_graph_from_matrix():
    # Path 0-1-2 with weights 2 and 3, plus an edge 0-3 of weight 0.5; diagonal is ignored.
    a = np.array([[-2.5, 2.0, 0.0, 0.5],
                  [2.0, -5.0, 3.0, 0.0],
                  [0.0, 3.0, -3.0, 0.0],
                  [0.5, 0.0, 0.0, -0.5]])
    edges = graphs.fixed_graph(a, coupling=10.0)
    assert edges.n == 4
    got = sorted(zip(edges.i.tolist(), edges.j.tolist(), edges.weight.tolist()))
    assert got == [(0, 1, 20.0), (0, 3, 5.0), (1, 2, 30.0)]


def test_fixed_graph_adjacency_round_trip():
    rng = np.random.default_rng(8)
    upper = np.triu(rng.uniform(0.0, 1.0, size=(7, 7)) * (rng.random((7, 7)) < 0.4), k=1)
    a = upper + upper.T
    assert_allclose(graphs.edges_to_adjacency(graphs.fixed_graph(a)), a, rtol=0.0, atol=0.0)


@pytest.mark.parametrize('n', [0, 1, 2, 5, 30])
def test_complete_graph_size(n):
    edges = graphs.complete_graph(n)
    assert edges.size == n * (n - 1) // 2
    assert len(set(zip(edges.i.tolist(), edges.j.tolist()))) == edges.size
    assert np.all(edges.i < edges.j)
    assert_allclose(edges.weight, 1.0)
    if n > 1:
        assert_array_equal(graphs.degrees(edges), np.full(n, n - 1))


# --------------------------------------------------------------------------------------------
# Barabasi-Albert


def is_connected(adj):
    """Return whether a dense adjacency is connected (breadth-first search)."""
    n = adj.shape[0]
    seen = {0}
    frontier = [0]
    while frontier:
        v = frontier.pop()
        for u in np.flatnonzero(adj[v]):
            if int(u) not in seen:
                seen.add(int(u))
                frontier.append(int(u))
    return len(seen) == n


@pytest.mark.parametrize('n, m0, m', [(200, 5, 5), (50, 3, 2), (30, 4, 1), (10, 2, 2)])
def test_barabasi_albert_structure(n, m0, m):
    adj = graphs.barabasi_albert(n, m0, m, np.random.default_rng(7))
    assert adj.shape == (n, n)
    assert_array_equal(adj, adj.T)
    assert_array_equal(np.diag(adj), 0.0)
    assert set(np.unique(adj).tolist()) <= {0.0, 1.0}
    # Initial clique m0 (m0 - 1)/2 edges, then m new edges per added vertex.
    assert adj.sum() / 2 == m0 * (m0 - 1) // 2 + (n - m0) * m
    assert is_connected(adj)
    # Every vertex added after the clique brings exactly m edges to earlier vertices.
    for v in range(m0, n):
        assert adj[v, :v].sum() == m


def test_barabasi_albert_single_seed_vertex():
    # m0 = m = 1 is inside the documented domain (m0 >= m, 1 <= m <= m0): the first new vertex
    # can only attach to vertex 0, after which preferential attachment is well defined. The
    # result must be a tree: n - 1 edges, connected.
    n = 12
    adj = graphs.barabasi_albert(n, 1, 1, np.random.default_rng(0))
    assert adj.sum() / 2 == n - 1
    assert is_connected(adj)


def test_barabasi_albert_deterministic_per_seed():
    a = graphs.barabasi_albert(100, 5, 3, np.random.default_rng(42))
    b = graphs.barabasi_albert(100, 5, 3, np.random.default_rng(42))
    c = graphs.barabasi_albert(100, 5, 3, np.random.default_rng(43))
    assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_barabasi_albert_prefers_high_degree():
    # Preferential attachment: over many graphs the initial clique members (which start with the
    # highest degree) end with a larger mean degree than the last added vertices (degree m).
    rng = np.random.default_rng(1)
    first, last = [], []
    for _ in range(20):
        deg = graphs.barabasi_albert(100, 3, 2, rng).sum(axis=1)
        first.append(deg[:3].mean())
        last.append(deg[-10:].mean())
    assert np.mean(first) > 3.0 * np.mean(last)


# --------------------------------------------------------------------------------------------
# diffusive_matrix, components, degrees


def test_diffusive_matrix():
    rng = np.random.default_rng(2)
    upper = np.triu(rng.uniform(0.0, 2.0, size=(9, 9)) * (rng.random((9, 9)) < 0.5), k=1)
    a = upper + upper.T + np.diag(rng.uniform(-5.0, 5.0, 9))   # junk diagonal is replaced
    b = graphs.diffusive_matrix(a)
    assert_allclose(b.sum(axis=1), 0.0, atol=1e-13)
    off = ~np.eye(9, dtype=bool)
    assert_allclose(b[off], a[off], rtol=0.0, atol=0.0)
    assert_allclose(np.diag(b), -upper.sum(axis=0) - upper.sum(axis=1), rtol=1e-14)
    # -B is a graph Laplacian: positive semi-definite.
    assert np.linalg.eigvalsh(b).max() <= 1e-12


def test_diffusive_matrix_hand_value():
    a = np.array([[0.0, 1.0, 2.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    expected = np.array([[-3.0, 1.0, 2.0], [1.0, -1.0, 0.0], [2.0, 0.0, -2.0]])
    assert_allclose(graphs.diffusive_matrix(a), expected, rtol=0.0, atol=0.0)
    # The input is not modified.
    assert_array_equal(np.diag(a), 0.0)


@pytest.mark.parametrize('n, pairs, count', [
    (0, [], 0),
    (1, [], 1),
    (5, [], 5),
    (5, [(0, 1), (1, 2), (2, 3), (3, 4)], 1),                   # path
    (7, [(0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5)], 3),   # two triangles + isolated 6
    (6, [(0, 5), (1, 4), (2, 3)], 3),                            # perfect matching
])
def test_components_known_graphs(n, pairs, count):
    got, labels = graphs.components(edge_list(n, pairs))
    assert got == count
    assert labels.shape == (n,)
    for i, j in pairs:
        assert labels[i] == labels[j]
    assert len(set(labels.tolist())) == count


def test_components_labels_separate_groups():
    _, labels = graphs.components(edge_list(7, [(0, 1), (1, 2), (3, 4), (4, 5)]))
    assert labels[0] != labels[3]
    assert labels[6] not in (labels[0], labels[3])


def test_degrees():
    # Star on 5 vertices centred at 2, plus the edge 0-1.
    edges = edge_list(6, [(0, 2), (1, 2), (2, 3), (2, 4), (0, 1)], weight=[9, 9, 9, 9, 9])
    assert_array_equal(graphs.degrees(edges), [2, 2, 4, 1, 1, 0])


def test_degrees_match_dense_adjacency():
    rng = np.random.default_rng(4)
    edges = graphs.disk_graph(rng.uniform(0.0, 1.0, size=(50, 2)), 0.2)
    dense = graphs.edges_to_adjacency(edges)
    assert_array_equal(graphs.degrees(edges), dense.sum(axis=1))


# --------------------------------------------------------------------------------------------
# VerletDiskGraph


def drifting_fragments(rng, n, dim, steps):
    """Yield positions of fragments moving apart at different velocities, with jitter."""
    q = rng.uniform(0.0, 4.0, size=(n, dim))
    velocity = rng.normal(0.0, 0.3, size=(4, dim))[rng.integers(4, size=n)] + 0.5
    for _ in range(steps):
        yield q
        q = q + velocity + rng.normal(0.0, 0.02, size=q.shape)


@pytest.mark.parametrize('fewest', [0, 1000])
@pytest.mark.parametrize('strict', [True, False])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('skin', [0.05, 0.5])
def test_verlet_disk_graph_is_the_disk_graph_at_every_step(dim, strict, skin, fewest,
                                                           monkeypatch):
    monkeypatch.setattr(graphs.VerletDiskGraph, 'FEWEST_TO_REFRESH', fewest)
    rng = np.random.default_rng(7 + dim)
    graph = graphs.VerletDiskGraph(1.0, strict, skin)
    for q in drifting_fragments(rng, 80, dim, 60):
        edges, exact = graph.edges(q), graphs.disk_graph(q, 1.0, strict)
        assert_array_equal(edges.i, exact.i)
        assert_array_equal(edges.j, exact.j)
        assert_array_equal(edges.weight, exact.weight)
    assert 1 <= graph.searches <= 60


def test_verlet_disk_graph_keeps_candidates_of_a_rigidly_moving_swarm():
    rng = np.random.default_rng(5)
    q = rng.uniform(0.0, 5.0, size=(50, 2))
    graph = graphs.VerletDiskGraph(1.0)
    for k in range(100):
        assert_array_equal(graph.edges(q + 0.3 * k).i, graphs.disk_graph(q, 1.0).i)
    assert graph.searches == 1


def test_verlet_disk_graph_of_stacked_swarms_is_block_diagonal():
    # Three swarms drawn in the same box: one disk graph each, never linked to one another.
    rng = np.random.default_rng(9)
    walks = [list(drifting_fragments(rng, 30, 2, 40)) for _ in range(3)]
    graph = graphs.VerletDiskGraph(1.0, blocks=3)
    for parts in zip(*walks):
        edges = graph.edges(np.concatenate(parts))
        expected_i, expected_j = [], []
        for b, q in enumerate(parts):
            own = graphs.disk_graph(q, 1.0)
            expected_i.append(own.i + 30 * b)
            expected_j.append(own.j + 30 * b)
        assert edges.n == 90
        assert_array_equal(edges.i, np.concatenate(expected_i))
        assert_array_equal(edges.j, np.concatenate(expected_j))
    with pytest.raises(ValueError, match='equal groups'):
        graph.edges(np.zeros((91, 2)))


def flock_with_stragglers(rng, drift):
    """Yield a rigid flock drifting by ``drift`` per step and three stragglers crossing it."""
    flock = rng.uniform(0.0, 6.0, size=(60, 2))
    stragglers = np.array([[-3.0, 1.0], [-3.0, 3.0], [9.0, 5.0]])
    # The last one runs far beyond the flock (and, stacked, past the next group's range).
    speed = np.array([[0.3, 0.0], [0.25, 0.05], [0.6, 0.0]])
    for k in range(80):
        yield np.concatenate((flock + drift * k, stragglers + (drift + speed) * k))


@pytest.mark.parametrize('blocks', [1, 3])
def test_verlet_disk_graph_searches_stragglers_again_not_the_flock(blocks, monkeypatch):
    monkeypatch.setattr(graphs.VerletDiskGraph, 'FEWEST_TO_REFRESH', 0)
    rng = np.random.default_rng(21)
    walks = [flock_with_stragglers(rng, np.array([0.05, 0.02 * b])) for b in range(blocks)]
    graph = graphs.VerletDiskGraph(1.0, blocks=blocks)
    for parts in zip(*walks):
        edges = graph.edges(np.concatenate(parts))
        own = [graphs.disk_graph(q, 1.0) for q in parts]
        assert_array_equal(edges.i, np.concatenate([g.i + 63 * b for b, g in enumerate(own)]))
        assert_array_equal(edges.j, np.concatenate([g.j + 63 * b for b, g in enumerate(own)]))
    assert graph.searches == 1
    assert graph.refreshes > 10


def test_verlet_disk_graph_searches_plainly_while_nothing_lasts():
    # New random positions at every step: no candidate list survives a step.
    rng = np.random.default_rng(13)
    graph = graphs.VerletDiskGraph(0.2)
    for _ in range(40):
        q = rng.uniform(0.0, 1.0, size=(50, 2))
        edges, exact = graph.edges(q), graphs.disk_graph(q, 0.2)
        assert_array_equal(edges.i, exact.i)
        assert_array_equal(edges.j, exact.j)
    assert graph.plain_searches >= 30
    assert graph.searches + graph.plain_searches == 40
