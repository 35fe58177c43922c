"""The base class of the flocking laws, what they are given, and their evaluation.

A law is one frozen dataclass: its parameters are the fields (read from the scenario's
``protocol:`` section), and everything specific to it travels with it: the validation of
its parameters, its explicit-step stability bound, its per-agent data and adaptive state,
the graphs it supports. Laws are found by name through the entry-point group
``flock_swarm.laws`` (:mod:`flock_swarm.core.registry`); the built-in ones are registered
the same way. docs/extending.md shows how to write one.

A law never sees the whole scenario. Its hooks receive two small frozen objects defined
here: :class:`LawContext` (dimension, size, graph type, leader model: what ``validate``
checks the parameters against) and :class:`LawSetup` (that plus the step, the fixed graph's
adjacency, the informed set and the observer groups of the realised run: what
``agent_data`` and ``step_bounds`` need). This module is a leaf of the core: it imports
nothing above the graphs and the leader's state, so the scenario, the registry and the
stability helpers import it and not the other way round.

A law is split in two pure functions so that the same code serves a whole swarm (vectorised
over edges) and a single agent that only knows its neighbours:

``pair(qi, pi, qj, pj, w) -> (E, k)``
    the contribution of neighbour ``j`` to agent ``i`` for a batch of ``E`` directed edges
    ``j -> i`` with edge weights ``w``; summed over the neighbours of each agent.
``combine(q, p, s, leader, agents, dt) -> (n, dim)``
    the control input of each agent from its own state, the summed pair terms ``s``, the
    virtual leader and the per-agent data (informed flag, gains, adaptive state).

:func:`swarm_control` evaluates a law on an undirected edge list (each pair once, using
antisymmetry where the law has it); :func:`group_control` evaluates it for a subset of the
agents (the one agent of an agent node, or the agents a container hosts) from the edges
that touch them; :func:`local_control` evaluates it for one agent and a list of its
neighbours' states. All three call the same ``pair`` and ``combine``.
"""

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from flock_swarm.core.graphs import EdgeList
from flock_swarm.core.leaders.base import LeaderState


@dataclass
class AgentData:
    """Per-agent data of a law, indexed like the agents it is passed with.

    :ivar informed: ``h_i`` of [Su09] eq. (10): ``True`` for agents that see the leader.
    :ivar data: constant per-agent arrays of the law (first axis: agents), e.g. the
        navigation gains ``D_i H_i`` of [Yu10] eq. (7) under ``'nav_gains'``.
    :ivar state: adaptive per-agent state (first axis: agents), advanced every step by
        :func:`advance_state` from :meth:`Law.state_rate` and recorded in the time series
        under its key, e.g. the gains ``h_i`` of [Zhou12] eq. (4) under ``'h'``.
    """

    informed: np.ndarray
    data: dict[str, np.ndarray] = field(default_factory=dict)
    state: dict[str, np.ndarray] = field(default_factory=dict)

    def subset(self, idx: np.ndarray) -> 'AgentData':
        """Return the data of the agents ``idx`` (copies of the arrays)."""
        return AgentData(self.informed[idx], {k: v[idx] for k, v in self.data.items()},
                         {k: v[idx] for k, v in self.state.items()})

    @staticmethod
    def concatenate(parts: list['AgentData']) -> 'AgentData':
        """Return the data of several groups of agents, stacked in order."""
        first = parts[0]
        return AgentData(np.concatenate([a.informed for a in parts]),
                         {k: np.concatenate([a.data[k] for a in parts]) for k in first.data},
                         {k: np.concatenate([a.state[k] for a in parts]) for k in first.state})


@dataclass(frozen=True)
class LawContext:
    """What a law may check its parameters against (:meth:`Law.validate`).

    :ivar dim: the dimension, 2 or 3.
    :ivar n_agents: the number of agents.
    :ivar graph_type: ``disk``, ``fixed`` or ``barabasi_albert``.
    :ivar leader_model: the name of the leader model (``leader.model``), if given as text.
    """

    dim: int
    n_agents: int
    graph_type: str
    leader_model: str | None = None


@dataclass(frozen=True)
class ObserverGroup:
    """One group of pinned observers of [Yu10] eq. (6)-(7): agents sharing ``H``, ``D``.

    :ivar ids: the agents of the group (0-based).
    :ivar pos_gain: ``D H``, the gain on the position error, shape ``(dim, dim)``.
    :ivar vel_gain: ``D~ H~``, the gain on the velocity error, shape ``(dim, dim)``.
    """

    ids: tuple[int, ...]
    pos_gain: np.ndarray
    vel_gain: np.ndarray


@dataclass(frozen=True, kw_only=True)
class LawSetup(LawContext):
    """What a law sees of a realised run (:meth:`Law.agent_data`, :meth:`Law.step_bounds`).

    Everything of :class:`LawContext`, plus what the scenario's seed drew. The arrays are
    read-only copies: the run's own per-agent data may change (re-selected pseudo-leaders),
    this stays as it was at ``t = 0``.

    :ivar dt: the step [s].
    :ivar adjacency: the weights of the fixed graph (``graph.type: fixed``, as given) or of
        the drawn Barabasi-Albert graph (0/1), ``(n, n)`` with a zero diagonal, before the
        law's :attr:`Law.coupling_weight`; ``None`` for the r-disk graph.
    :ivar informed: ``h_i`` of [Su09] eq. (10): the informed agents at ``t = 0``, ``(n,)``.
    :ivar observers: the scenario's ``observers`` groups (only for a law with
        :attr:`Law.uses_observers`; empty otherwise).
    """

    dt: float
    adjacency: np.ndarray | None = None
    informed: np.ndarray
    observers: tuple[ObserverGroup, ...] = ()


@dataclass(frozen=True)
class StepViolation:
    """One violated bound: what it protects, the largest stable ``dt``, and why."""

    part: str
    dt_max: float
    detail: str

    def message(self, dt: float) -> str:
        """Return the one-line message for a run with step ``dt``."""
        return (f'dt: {dt:g} exceeds the stability bound {self.dt_max:.4g} of the '
                f'{self.part} ({self.detail}); use dt < {self.dt_max:.4g}')


@dataclass(frozen=True)
class Law:
    """Base class of the laws: parameters as frozen dataclass fields, plus the law itself.

    Subclasses set :attr:`name` (equal to their entry-point name), implement
    :attr:`radius`, :meth:`pair` and :meth:`combine`, and override what else applies. The
    optional hooks, each with the default that leaves it out:

    - :meth:`validate` ``(ctx: LawContext)``: check the parameters;
    - :meth:`agent_data` ``(setup: LawSetup)``: constant per-agent arrays;
    - :meth:`initial_state` ``(n)`` and :meth:`state_rate`: adaptive per-agent state;
    - :meth:`step_bounds` ``(setup: LawSetup)``: the explicit-step stability bound;
    - :attr:`coupling_weight`: the factor of the graph's weights in ``pair``'s ``w``;
    - :meth:`pseudo_leader_gains`: lets scenarios choose the informed agents by the
      certificate of [Zhou12] Theorem 1 (``informed.select: pseudo_leaders``);
    - :attr:`uses_observers`: lets scenarios give pinned observer groups (``observers:``,
      read in :meth:`agent_data` from ``setup.observers``).

    The last three are what the core itself needs from a law beyond evaluating it: how the
    edges are weighted and which scenario sections (pseudo-leader selection, observers)
    make sense for it; a law that has none of them leaves them alone.
    """

    #: Scenario name of the law (``protocol.name``).
    name: ClassVar[str] = ''
    #: One line naming the paper and equation (``sim --list``); empty: the docstring's first.
    citation: ClassVar[str] = ''
    #: Whether ``pair(j -> i) = -pair(i -> j)``, so each undirected pair is evaluated once.
    antisymmetric: ClassVar[bool] = True
    #: Whether the pair term acts between *all* pairs (weights select the coupled ones).
    all_pairs: ClassVar[bool] = False
    #: Whether the r-disk neighbourhood is ``< r`` (``True``) or ``<= r``.
    strict_radius: ClassVar[bool] = True
    #: The interaction graphs (``graph.type``) the law is defined on.
    graph_types: ClassVar[tuple[str, ...]] = ('disk', 'fixed', 'barabasi_albert')
    #: Whether the law uses the scenario's ``observers`` groups ([Yu10] eq. (6)-(7)).
    uses_observers: ClassVar[bool] = False
    #: Default ``metrics.eta_tolerance`` [m/s] of its scenarios.
    eta_tolerance: ClassVar[float] = 0.1
    #: Summary keys for the final value of adaptive state: ``{state key: summary key}``.
    state_summary: ClassVar[dict[str, str]] = {}

    @property
    def radius(self) -> float:
        """Return the interaction radius of the r-disk graph."""
        raise NotImplementedError

    @property
    def coupling_weight(self) -> float:
        """Return the factor of the graph's weights in ``pair``'s ``w`` ([Zhou12] 4.2: ``w B``).

        Applied to the fixed graph's adjacency (:attr:`LawSetup.adjacency`) and, for a law
        acting on all pairs, to the r-disk graph's 0/1 adjacency.
        """
        return 1.0

    def validate(self, ctx: LawContext) -> None:
        """Raise :class:`~flock_swarm.core.errors.ScenarioError` for invalid parameters.

        Called once the parameters are read; name the key (``protocol.<field>``).

        :param ctx: the scenario's dimension, size, graph and leader model.
        """

    def pair(self, qi: np.ndarray, pi: np.ndarray, qj: np.ndarray, pj: np.ndarray,
             w: np.ndarray) -> np.ndarray:
        """Return the contribution of ``j`` to ``i`` for each directed edge."""
        raise NotImplementedError

    def combine(self, q: np.ndarray, p: np.ndarray, s: np.ndarray,
                leader: LeaderState | None, agents: AgentData, dt: float) -> np.ndarray:
        """Return the control input of each agent.

        ``leader=None`` means the leader's state is not known (a lost leader): every agent
        then applies the law of an uninformed agent, without any navigational term.
        """
        raise NotImplementedError

    def agent_data(self, setup: LawSetup) -> dict[str, np.ndarray]:
        """Return the law's constant per-agent arrays of a run (``AgentData.data``).

        Called once the run's informed set is drawn; each array's first axis is the agents.

        :param setup: the run's size, dimension, step, graph, informed set and observers.
        :return: ``{key: array}``, e.g. ``{'nav_gains': (n, 2, dim, dim)}`` for [Yu10].
        """
        return {}

    def initial_state(self, n: int) -> dict[str, np.ndarray]:
        """Return the law's adaptive state at ``t = 0`` (``AgentData.state``)."""
        return {}

    def state_rate(self, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                   agents: AgentData) -> dict[str, np.ndarray]:
        """Return ``d/dt`` of each adaptive state (keys of ``agents.state``)."""
        return {}

    def pseudo_leader_gains(self) -> tuple[float, float] | None:
        """Return ``(w, alpha)`` for choosing pseudo-leaders by [Zhou12] Theorem 1, or ``None``.

        ``None`` (the default) refuses ``informed.select: pseudo_leaders`` for the law.
        """
        return None

    def step_bounds(self, setup: LawSetup) -> list[StepViolation]:
        """Return the explicit-step stability bounds the run's ``dt`` violates.

        A run whose ``dt`` violates a bound is refused before it starts, unless told to
        run anyway (``--allow-unstable``);
        :func:`flock_swarm.core.stability.consensus_bounds` bounds a PD navigation term plus
        velocity consensus.

        :param setup: the run's size, dimension, step (``setup.dt``), graph and informed set.
        :return: the violations, empty when ``setup.dt`` is fine.
        """
        return []


def pair_sums(law: Law, q: np.ndarray, p: np.ndarray, edges: EdgeList) -> np.ndarray:
    """Return ``s_i = sum_{j in N_i} pair(i <- j)`` for every agent of an undirected graph.

    Each undirected edge is evaluated once when the law is antisymmetric, twice otherwise;
    the sums use :func:`numpy.bincount`, so the cost is linear in the number of edges.

    :param law: the law.
    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param edges: the interaction graph.
    :return: the sums, shape ``(n, k)``.
    """
    n = q.shape[0]
    i, j = edges.i, edges.j
    # The edge ends gathered component by component (take() is several times faster than
    # fancy indexing, with the same values): the (e, dim) arrays are then column-major, so
    # the per-component arithmetic of the laws and the sums below run on contiguous memory
    # (the values do not depend on the layout).
    qt, pt = np.ascontiguousarray(q.T), np.ascontiguousarray(p.T)
    qi, pi, qj, pj = qt.take(i, 1).T, pt.take(i, 1).T, qt.take(j, 1).T, pt.take(j, 1).T
    to_i = law.pair(qi, pi, qj, pj, edges.weight)
    out = np.empty((n, to_i.shape[1]))
    if law.antisymmetric:
        # pair(j <- i) = -pair(i <- j): subtracting its sums is adding those of its negation.
        for col in range(to_i.shape[1]):
            out[:, col] = (np.bincount(i, weights=to_i[:, col], minlength=n)
                           - np.bincount(j, weights=to_i[:, col], minlength=n))
        return out
    to_j = law.pair(qj, pj, qi, pi, edges.weight)
    for col in range(to_i.shape[1]):
        out[:, col] = (np.bincount(i, weights=to_i[:, col], minlength=n)
                       + np.bincount(j, weights=to_j[:, col], minlength=n))
    return out


def swarm_control(law: Law, q: np.ndarray, p: np.ndarray, edges: EdgeList,
                  leader: LeaderState, agents: AgentData, dt: float) -> np.ndarray:
    """Return the control input of every agent of a swarm.

    :param law: the law.
    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param edges: the interaction graph (all pairs with weights for ``law.all_pairs``).
    :param leader: the virtual leader's state.
    :param agents: per-agent data.
    :param dt: the step (used by laws that reach a target in one step).
    :return: ``u``, shape ``(n, dim)``.
    """
    return law.combine(q, p, pair_sums(law, q, p, edges), leader, agents, dt)


def group_control(law: Law, ids: np.ndarray, q: np.ndarray, p: np.ndarray,
                  edges: EdgeList, leader: LeaderState | None, group: AgentData,
                  dt: float) -> np.ndarray:
    """Return the control input of the agents ``ids`` only (agent nodes and containers).

    Only the edges that touch ``ids`` are evaluated, in the order :func:`swarm_control`
    sums them, so each row equals the corresponding row of :func:`swarm_control` on the
    whole graph: what an agent computes is what the simulator computes for it.

    :param law: the law.
    :param ids: the agents to control (ascending, distinct), shape ``(m,)``.
    :param q: positions of every agent, shape ``(n, dim)``.
    :param p: velocities of every agent, shape ``(n, dim)``.
    :param edges: the interaction graph of the whole swarm (as :func:`swarm_control`).
    :param leader: the virtual leader's state as these agents know it (``None``: lost, the
        uninformed law for all of them).
    :param group: per-agent data of ``ids`` (``agents.subset(ids)``).
    :param dt: the step.
    :return: ``u`` of ``ids``, shape ``(m, dim)``.
    """
    hosted = np.zeros(q.shape[0], dtype=bool)
    hosted[ids] = True
    touch = hosted[edges.i] | hosted[edges.j]
    near = dataclasses.replace(edges, i=edges.i[touch], j=edges.j[touch],
                               weight=edges.weight[touch])
    s = pair_sums(law, q, p, near)[ids]
    return law.combine(q[ids], p[ids], s, leader, group, dt)


def local_control(law: Law, q_self: np.ndarray, p_self: np.ndarray,
                  q_nb: np.ndarray, p_nb: np.ndarray, w_nb: np.ndarray,
                  leader: LeaderState, agent: AgentData, dt: float) -> np.ndarray:
    """Return the control input of one agent from its neighbours' states.

    The agent node's entry point: the same ``pair`` and ``combine`` as :func:`swarm_control`.

    :param law: the law.
    :param q_self: own position, shape ``(dim,)``.
    :param p_self: own velocity, shape ``(dim,)``.
    :param q_nb: neighbour positions, shape ``(m, dim)`` (``m`` may be 0).
    :param p_nb: neighbour velocities, shape ``(m, dim)``.
    :param w_nb: edge weights, shape ``(m,)``.
    :param leader: the virtual leader's state as this agent knows it.
    :param agent: this agent's data (arrays of length 1).
    :param dt: the step.
    :return: ``u``, shape ``(dim,)``.
    """
    m = q_nb.shape[0]
    qi = np.broadcast_to(q_self, (m, q_self.shape[0]))
    pi = np.broadcast_to(p_self, (m, p_self.shape[0]))
    s = law.pair(qi, pi, q_nb, p_nb, w_nb).sum(axis=0, keepdims=True)
    return law.combine(q_self[None], p_self[None], s, leader, agent, dt)[0]


def advance_state(law: Law, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                  agents: AgentData, dt: float) -> None:
    """Advance the adaptive state in place by one explicit step (sampled like ``u``).

    ``x_i(t + dt) = x_i(t) + dt x_i'(t)``, e.g. ``h_i(t + dt) = h_i(t) + dt k_i
    ||v_i(t) - v_l(t)||^2`` ([Zhou12] eq. (4)), consistent with the zero-order hold on the
    input.

    :param law: the law.
    :param q: positions at the start of the step.
    :param p: velocities at the start of the step.
    :param leader: the leader at the start of the step.
    :param agents: per-agent data, updated in place.
    :param dt: the step.
    """
    if not agents.state:
        return
    for key, rate in law.state_rate(q, p, leader, agents).items():
        agents.state[key] += dt * rate


def output_problem(u, n: int, dim: int) -> str | None:
    """Return what is wrong with a law's control input, or ``None`` when it is sound.

    :param u: what ``combine`` returned for ``n`` agents.
    :param n: the number of agents.
    :param dim: the dimension.
    """
    if not isinstance(u, np.ndarray):
        return f'combine() returned {type(u).__name__}, not a NumPy array'
    if u.shape != (n, dim):
        return f'combine() returned shape {u.shape} for {n} agents in {dim}-D, not {(n, dim)}'
    if not np.isfinite(u).all():
        return 'combine() returned non-finite values at the initial state'
    return None
