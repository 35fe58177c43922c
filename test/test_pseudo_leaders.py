"""Unit tests of the pseudo-leader selection of Zhou et al. 2012 (Theorems 1, 2, Section 4)."""

import numpy as np
from numpy.testing import assert_allclose
import pytest

from flock_swarm.core import graphs
from flock_swarm.core import pseudo_leaders as pl

# Zhou12 Section 5.1: the 10 x 10 diffusive matrix B (copied from the paper).
ZHOU_B = np.array([
    [-7, 1, 1, 0, 1, 0, 1, 1, 1, 1],
    [1, -4, 0, 0, 0, 1, 1, 1, 0, 0],
    [1, 0, -4, 1, 0, 0, 0, 0, 1, 1],
    [0, 0, 1, -3, 1, 1, 0, 0, 0, 0],
    [1, 0, 0, 1, -2, 0, 0, 0, 0, 0],
    [0, 1, 0, 1, 0, -2, 0, 0, 0, 0],
    [1, 1, 0, 0, 0, 0, -2, 0, 0, 0],
    [1, 1, 0, 0, 0, 0, 0, -2, 0, 0],
    [1, 0, 1, 0, 0, 0, 0, 0, -2, 0],
    [1, 0, 1, 0, 0, 0, 0, 0, 0, -2],
], dtype=float)
# Zhou12 Section 5.1: common coupling weight and the Lu system's Assumption A1 constant.
ZHOU_W = 70.0
ZHOU_ALPHA = 60.3402


def independent_lambda_max(adjacency, w, removed):
    """Return lambda_max of ``w B`` without ``removed``, B built here as ``A - diag(A 1)``."""
    a = np.array(adjacency, dtype=float)
    np.fill_diagonal(a, 0.0)
    b = a - np.diag(a.sum(axis=1))
    keep = [k for k in range(a.shape[0]) if k not in set(removed)]
    if not keep:
        return -np.inf
    return np.linalg.eigvalsh(w * b[np.ix_(keep, keep)]).max()


def path_adjacency(n):
    """Return the adjacency of the path 0 - 1 - ... - (n-1)."""
    a = np.zeros((n, n))
    idx = np.arange(n - 1)
    a[idx, idx + 1] = a[idx + 1, idx] = 1.0
    return a


def block_diagonal(*blocks):
    """Return the block-diagonal matrix of the given square blocks."""
    n = sum(b.shape[0] for b in blocks)
    out = np.zeros((n, n))
    start = 0
    for b in blocks:
        k = b.shape[0]
        out[start:start + k, start:start + k] = b
        start += k
    return out


def test_paper_matrix_is_diffusive_and_symmetric():
    assert_allclose(ZHOU_B, ZHOU_B.T, atol=0.0)
    assert_allclose(ZHOU_B.sum(axis=1), 0.0, atol=0.0)
    assert_allclose(graphs.diffusive_matrix(ZHOU_B), ZHOU_B, atol=0.0)


def test_paper_minor_without_first_three_agents():
    # Zhou12 Section 5.1: deleting the first three row-column pairs gives lambda_max(B_7) = -1.
    assert_allclose(pl.minor_lambda_max(ZHOU_B, [0, 1, 2]), -1.0, rtol=1e-12)
    assert_allclose(pl.minor_lambda_max(ZHOU_W * ZHOU_B, (0, 1, 2)), -ZHOU_W, rtol=1e-12)
    # ... which satisfies lambda_max(B_7) < -alpha / w = -0.8620.
    assert pl.minor_lambda_max(ZHOU_B, [0, 1, 2]) < -ZHOU_ALPHA / ZHOU_W


def test_minor_lambda_max_edge_cases():
    # Nothing removed: the diffusive matrix has the eigenvalue 0 (constant vector).
    assert_allclose(pl.minor_lambda_max(ZHOU_B, []), 0.0, atol=1e-12)
    assert pl.minor_lambda_max(ZHOU_B, range(10)) == -np.inf
    # One vertex left: the 1 x 1 minor is its diagonal entry.
    assert_allclose(pl.minor_lambda_max(ZHOU_B, range(1, 10)), -7.0, rtol=1e-15)


def test_paper_selection_satisfies_theorem_1():
    sel = pl.select_pseudo_leaders(ZHOU_B, ZHOU_W, ZHOU_ALPHA)
    lam = independent_lambda_max(ZHOU_B, ZHOU_W, sel.ids)
    assert sel.satisfied
    assert lam + ZHOU_ALPHA < 0.0
    assert_allclose(sel.lambda_max, lam, rtol=1e-12)
    assert sel.alpha == ZHOU_ALPHA
    assert sel.components == 1
    assert list(sel.ids) == sorted(set(sel.ids))
    # One pseudo-leader is not enough here: lambda_max(70 B_9) >= -43 for every single vertex.
    assert len(sel.ids) >= 2
    for k in range(10):
        assert independent_lambda_max(ZHOU_B, ZHOU_W, [k]) + ZHOU_ALPHA > 0.0


def test_paper_selection_is_the_papers_set():
    # Degrees are 7, 4, 4, 3, 2, ...: adding by decreasing degree (ties: lower id) tries {0},
    # {0, 1}, {0, 1, 2}; the first two fail Theorem 1 and the third is the paper's set.
    assert independent_lambda_max(ZHOU_B, ZHOU_W, [0, 1]) + ZHOU_ALPHA > 0.0
    sel = pl.select_pseudo_leaders(ZHOU_B, ZHOU_W, ZHOU_ALPHA)
    assert sel.ids == (0, 1, 2)
    assert_allclose(sel.lambda_max, -ZHOU_W, rtol=1e-12)


def test_paper_selection_accepts_zero_diagonal_adjacency():
    # The same graph given as a 0/1 adjacency (zero diagonal) selects the same set.
    adj = ZHOU_B.copy()
    np.fill_diagonal(adj, 0.0)
    assert pl.select_pseudo_leaders(adj, ZHOU_W, ZHOU_ALPHA).ids == \
        pl.select_pseudo_leaders(ZHOU_B, ZHOU_W, ZHOU_ALPHA).ids


@pytest.mark.parametrize('adjacency', [
    path_adjacency(12),
    ZHOU_B,
    graphs.barabasi_albert(60, 5, 5, np.random.default_rng(3)),
    np.ones((6, 6)) - np.eye(6),
], ids=['path', 'zhou_B', 'barabasi_albert', 'complete'])
@pytest.mark.parametrize('w', [0.5, 70.0])
def test_theorem_2_one_pseudo_leader_on_connected_graph(adjacency, w):
    # Zhou12 Section 4.2: alpha = 0 and a connected graph: any single agent suffices (Lemma 2).
    sel = pl.select_pseudo_leaders(adjacency, w, 0.0)
    assert len(sel.ids) == 1
    assert sel.satisfied
    assert sel.components == 1
    assert independent_lambda_max(adjacency, w, sel.ids) < 0.0


def test_greedy_picks_highest_degree_first():
    # Star centred at 3 plus a pendant edge: the centre has the highest degree.
    a = np.zeros((6, 6))
    for leaf in (0, 1, 2, 4):
        a[3, leaf] = a[leaf, 3] = 1.0
    a[4, 5] = a[5, 4] = 1.0
    assert pl.select_pseudo_leaders(a, 1.0, 0.0).ids == (3,)


def test_three_components_get_one_each():
    # Zhou12 Section 4.3: each connected component needs its own pseudo-leaders.
    a = block_diagonal(path_adjacency(4), np.ones((3, 3)) - np.eye(3), path_adjacency(5))
    labels = np.repeat([0, 1, 2], [4, 3, 5])
    sel = pl.select_pseudo_leaders(a, 1.0, 0.0)
    assert sel.components == 3
    assert sel.satisfied
    assert sorted(labels[list(sel.ids)].tolist()) == [0, 1, 2]
    assert independent_lambda_max(a, 1.0, sel.ids) < 0.0
    # Without a pseudo-leader in one component its minor keeps the eigenvalue 0.
    for comp in range(3):
        others = [i for i in sel.ids if labels[i] != comp]
        assert_allclose(independent_lambda_max(a, 1.0, others), 0.0, atol=1e-12)


@pytest.mark.parametrize('alpha', [0.0, 0.5, 2.0])
def test_components_with_positive_alpha(alpha):
    a = block_diagonal(ZHOU_B * (1 - np.eye(10)), path_adjacency(6), np.zeros((1, 1)))
    labels = np.repeat([0, 1, 2], [10, 6, 1])
    sel = pl.select_pseudo_leaders(a, 1.0, alpha)
    assert sel.components == 3
    assert set(labels[list(sel.ids)].tolist()) == {0, 1, 2}
    assert sel.satisfied
    assert independent_lambda_max(a, 1.0, sel.ids) + alpha < 0.0
    # The isolated vertex (16) is necessarily its own pseudo-leader.
    assert 16 in sel.ids


def test_select_for_graph_on_disk_graph():
    rng = np.random.default_rng(17)
    q = rng.uniform(0.0, 10.0, size=(40, 2))
    r = 2.0
    edges = graphs.disk_graph(q, r)
    # Brute-force adjacency of the same disk graph and its components.
    dist = np.linalg.norm(q[:, None, :] - q[None, :, :], axis=-1)
    adj = ((dist < r) & ~np.eye(40, dtype=bool)).astype(float)
    count, labels = graphs.components(edges)
    sel = pl.select_for_graph(edges, 1.0, 0.0)
    assert sel.components == count
    assert set(labels[list(sel.ids)].tolist()) == set(range(count))
    assert sel.satisfied
    assert independent_lambda_max(adj, 1.0, sel.ids) < 0.0
    # Edge weights are ignored: the selection depends on the unit adjacency only.
    heavy = graphs.EdgeList(edges.n, edges.i, edges.j, 5.0 * np.ones(edges.size))
    assert pl.select_for_graph(heavy, 1.0, 0.0).ids == sel.ids


@pytest.mark.parametrize('alpha', [0.5, 3.0])
def test_select_for_graph_with_alpha(alpha):
    rng = np.random.default_rng(18)
    q = rng.uniform(0.0, 6.0, size=(30, 3))
    edges = graphs.disk_graph(q, 2.5)
    adj = graphs.edges_to_adjacency(edges)
    sel = pl.select_for_graph(edges, 2.0, alpha)
    assert sel.satisfied
    assert independent_lambda_max(adj, 2.0, sel.ids) + alpha < 0.0
