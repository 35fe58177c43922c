"""Choosing pseudo-leaders: [Zhou12] Theorems 1 and 2, Sections 4.2-4.4.

Theorem 1: with intrinsic dynamics satisfying Assumption A1 with constant ``alpha``, the set
``{i_1 .. i_m}`` of pseudo-leaders guarantees flocking if ``W_{N-m} + alpha I < 0``, where
``W_{N-m}`` is ``W = w B`` with the pseudo-leaders' rows and columns removed; equivalently
``lambda_max(W_{N-m}) + alpha < 0``. Theorem 2 is the case ``alpha = 0``. Section 4.3 applies
the rule per connected component (every component needs its own pseudo-leaders); Section 4.4
re-applies it whenever a switching graph changes.
"""

from dataclasses import dataclass

import numpy as np

from flock_swarm.core.graphs import EdgeList, components, diffusive_matrix, edges_to_adjacency


@dataclass(frozen=True)
class PseudoLeaderSelection:
    """A pseudo-leader set with its certificate.

    :ivar ids: the chosen agents (0-based, sorted).
    :ivar lambda_max: ``lambda_max(W_{N-m})`` of the minor left after removing ``ids``
        (``-inf`` when nothing is left).
    :ivar alpha: the constant of Assumption A1 the set was chosen for.
    :ivar satisfied: whether ``lambda_max + alpha < 0`` (Theorem 1's condition).
    :ivar components: number of connected components of the graph.
    """

    ids: tuple[int, ...]
    lambda_max: float
    alpha: float
    satisfied: bool
    components: int


def minor_lambda_max(weights: np.ndarray, removed) -> float:
    """Return ``lambda_max`` of ``W`` with the rows and columns ``removed`` deleted.

    :param weights: the symmetric weight matrix ``W = w B`` (diffusive: negative diagonal).
    :param removed: indices to delete.
    :return: the largest eigenvalue, ``-inf`` for an empty minor.
    """
    keep = np.setdiff1d(np.arange(weights.shape[0]), np.asarray(list(removed), dtype=int))
    if keep.size == 0:
        return float('-inf')
    return float(np.linalg.eigvalsh(weights[np.ix_(keep, keep)])[-1])


def select_pseudo_leaders(adjacency: np.ndarray, w: float, alpha: float) -> PseudoLeaderSelection:
    """Choose pseudo-leaders greedily by degree, per connected component, until Theorem 1 holds.

    In each component, agents are added in order of decreasing degree (ties: lower id first)
    until the component's minor satisfies ``lambda_max + alpha < 0``; every component gets at
    least one pseudo-leader (Section 4.3). The minor of the whole graph is block-diagonal over
    components, so the per-component conditions together give Theorem 1's condition.

    :param adjacency: symmetric 0/1 (or weighted) adjacency ``B`` off the diagonal.
    :param w: the common coupling weight (``W = w B``).
    :param alpha: the constant of Assumption A1 (``0`` for Theorem 2).
    :return: the set and its certificate.
    """
    b = diffusive_matrix(adjacency)
    weights = w * b
    n = b.shape[0]
    adj = np.array(adjacency, dtype=float)
    np.fill_diagonal(adj, 0.0)
    i, j = np.nonzero(np.triu(adj, k=1))
    count, labels = components(EdgeList(n, i, j, adj[i, j]))
    degree = -np.diag(b)
    chosen: list[int] = []
    for comp in range(count):
        members = np.flatnonzero(labels == comp)
        order = members[np.lexsort((members, -degree[members]))]
        sub = weights[np.ix_(members, members)]
        local = {int(v): k for k, v in enumerate(members)}
        picked: list[int] = []
        for v in order:
            picked.append(int(v))
            if minor_lambda_max(sub, [local[x] for x in picked]) + alpha < 0.0:
                break
        chosen.extend(picked)
    lam = minor_lambda_max(weights, chosen)
    return PseudoLeaderSelection(tuple(sorted(chosen)), lam, float(alpha),
                                 bool(lam + alpha < 0.0), count)


def select_for_graph(edges: EdgeList, w: float, alpha: float) -> PseudoLeaderSelection:
    """Choose pseudo-leaders for the current r-disk (or any) graph (Section 4.4).

    :param edges: the graph; its weights are ignored (unit adjacency).
    :param w: the common coupling weight.
    :param alpha: the constant of Assumption A1.
    :return: the set and its certificate.
    """
    unit = EdgeList(edges.n, edges.i, edges.j, np.ones(edges.size))
    return select_pseudo_leaders(edges_to_adjacency(unit), w, alpha)


def reselect(law, agents, edges: EdgeList) -> PseudoLeaderSelection:
    """Re-apply Theorem 1 to the current graph (Section 4.4), in place.

    Agents that become pseudo-leaders start from the law's initial adaptive state (``h0``);
    those that stay keep their adapted state.

    :param law: a law with pseudo-leader gains (:meth:`~flock_swarm.core.laws.base.Law.
        pseudo_leader_gains`), such as [Zhou12]'s.
    :param agents: per-agent data of the whole swarm (``informed``, ``state``), updated.
    :param edges: the current graph; edges of zero weight are not couplings.
    :return: the new selection.
    """
    keep = edges.weight > 0
    coupled = EdgeList(edges.n, edges.i[keep], edges.j[keep], edges.weight[keep])
    chosen = select_for_graph(coupled, *law.pseudo_leader_gains())
    new = np.zeros_like(agents.informed)
    new[list(chosen.ids)] = True
    fresh = new & ~agents.informed
    for key, start in law.initial_state(new.shape[0]).items():
        agents.state[key][fresh] = start[fresh]
    agents.informed[:] = new
    return chosen


class Reselector:
    """Re-applies Theorem 1 whenever the coupling graph switches ([Zhou12] Section 4.4).

    The simulator and every agent node hold one, so they re-select at the same steps.
    """

    def __init__(self, law) -> None:
        """Create it for a law with pseudo-leader gains (such as [Zhou12]'s)."""
        self.law = law
        self.previous: tuple[bytes, bytes] | None = None
        self.count = 0

    def update(self, agents, edges: EdgeList) -> bool:
        """Re-select (in place) if the graph differs from the previous call's; return whether.

        :param agents: per-agent data of the whole swarm, updated in place.
        :param edges: the current graph.
        :return: ``True`` when a re-selection happened.
        """
        keep = edges.weight > 0
        signature = (edges.i[keep].tobytes(), edges.j[keep].tobytes())
        changed = self.previous is not None and signature != self.previous
        self.previous = signature
        if changed:
            reselect(self.law, agents, edges)
            self.count += 1
        return changed
