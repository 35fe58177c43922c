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
``combine(q, p, s, leader, agents, dt, t) -> (n, dim)``
    the control input of each agent from its own state, the summed pair terms ``s``, the
    virtual leader, the per-agent data (informed flag, gains, adaptive state) and the time.

:func:`swarm_control` evaluates a law on an undirected edge list (each pair once, using
antisymmetry where the law has it); :func:`group_control` evaluates it for a subset of the
agents (the one agent of an agent node, or the agents a container hosts) from the edges
that touch them; :func:`local_control` evaluates it for one agent and a list of its
neighbours' states. All three call the same ``pair`` and ``combine`` and check the shapes
of what they return at every step (:class:`~flock_swarm.core.errors.PluginError`, one line
naming the law); :func:`antisymmetry_problem` checks a law's ``antisymmetric`` claim on
random states when a scenario loads it.

Hooks that grew a parameter (``combine``'s time ``t``, ``state_rate``'s neighbour sums ``s``
and time ``t``) are called the old way for a law written before: :func:`accepted` reads each
class's signature once.
"""

import dataclasses
import inspect
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, ClassVar

import numpy as np

from flock_swarm.core.errors import PluginError
from flock_swarm.core.graphs import EdgeList
from flock_swarm.core.leaders.base import LeaderState

#: The parameters a hook gained after plugins were written to it: a law whose method does not
#: take one is called without it (:func:`accepted`).
NEWER_PARAMETERS = {'combine': ('t',), 'state_rate': ('s', 't')}
#: States :func:`antisymmetry_problem` evaluates ``pair`` on, and the relative deviation it
#: accepts (rounding: the built-in laws are antisymmetric to the last bit).
ANTISYMMETRY_SAMPLES = 64
ANTISYMMETRY_RTOL = 1e-9


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
    - :meth:`initial_state` ``(n)`` and :meth:`state_rate` ``(q, p, leader, agents, s, t)``:
      adaptive per-agent state, driven by the neighbours through ``s`` if need be;
    - :meth:`step_bounds` ``(setup: LawSetup)``: the explicit-step stability bound;
    - :attr:`coupling_weight`: the factor of the graph's weights in ``pair``'s ``w``;
    - :meth:`pseudo_leader_gains`: lets scenarios choose the informed agents by the
      certificate of [Zhou12] Theorem 1 (``informed.select: pseudo_leaders``);
    - :attr:`uses_observers`: lets scenarios give pinned observer groups (``observers:``,
      read in :meth:`agent_data` from ``setup.observers``);
    - :attr:`accepts_obstacles`: lets scenarios give obstacles (``obstacles:``), whose
      beta term the core adds to the law's control.

    The last three are what the core itself needs from a law beyond evaluating it: how the
    edges are weighted and which scenario sections (pseudo-leader selection, observers)
    make sense for it; a law that has none of them leaves them alone.
    """

    #: Scenario name of the law (``protocol.name``).
    name: ClassVar[str] = ''
    #: One line naming the paper and equation (``sim --list``); empty: the docstring's first.
    citation: ClassVar[str] = ''
    #: Whether ``pair(j -> i) = -pair(i -> j)``, so each undirected pair is evaluated once.
    #: ``False`` by default: evaluating both directions is right for every law, the claim
    #: only saves half the pair evaluations (checked by :func:`antisymmetry_problem`).
    antisymmetric: ClassVar[bool] = False
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
    #: Whether the scenario's ``obstacles:`` section may be used with the law: the beta term
    #: of Olfati-Saber 2006 Algorithm 3 (:func:`flock_swarm.core.obstacles.beta_term`) is
    #: then added to ``combine``'s output (docs/obstacles.md). A law with a float field
    #: ``d`` (its desired inter-agent distance) gets the default ``d_beta = 0.6 d``.
    accepts_obstacles: ClassVar[bool] = False

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
                leader: LeaderState | None, agents: AgentData, dt: float,
                t: float = 0.0) -> np.ndarray:
        """Return the control input of each agent.

        ``leader=None`` means the leader's state is not known (a lost leader): every agent
        then applies the law of an uninformed agent, without any navigational term. A law
        whose ``combine`` has no ``t`` parameter (written before it was given) is called
        without it.

        :param q: the agents' positions, ``(n, dim)``.
        :param p: their velocities, ``(n, dim)``.
        :param s: the sums of ``pair`` over each agent's neighbours, ``(n, k)``.
        :param leader: the virtual leader's state, or ``None`` (lost).
        :param agents: the agents' data (informed flags, constant arrays, adaptive state).
        :param dt: the step [s].
        :param t: the time of the step [s], ``k dt``.
        :return: ``u``, ``(n, dim)``.
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
                   agents: AgentData, s: np.ndarray | None = None,
                   t: float = 0.0) -> dict[str, np.ndarray]:
        """Return ``d/dt`` of each adaptive state (keys of ``agents.state``).

        A law whose ``state_rate`` has no ``s`` or ``t`` parameter (written before they were
        given) is called without them; the sums are then not evaluated for it.

        :param q: the agents' positions, ``(n, dim)``.
        :param p: their velocities, ``(n, dim)``.
        :param leader: the virtual leader's state, or ``None`` (lost).
        :param agents: the agents' data; ``agents.state`` holds the current state.
        :param s: the sums of ``pair`` over each agent's neighbours, ``(n, k)``, as
            ``combine`` receives them (an adaptive law driven by its neighbours' errors).
        :param t: the time of the step [s].
        :return: ``{key: rate}``, each shaped like ``agents.state[key]``.
        """
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


@lru_cache(maxsize=None)
def accepted(cls: type, hook: str) -> frozenset[str]:
    """Return which of a hook's newer parameters (:data:`NEWER_PARAMETERS`) a law class takes.

    Read from the signature once per class (cached), not at every step: a ``combine``
    without ``t``, or a ``state_rate`` without ``s`` and ``t``, is a law written to the
    earlier API and is called the way it was written.

    :param cls: the law's class.
    :param hook: ``'combine'`` or ``'state_rate'``.
    :return: the names among the hook's newer parameters that the method accepts.
    """
    newer = NEWER_PARAMETERS[hook]
    try:
        params = inspect.signature(getattr(cls, hook)).parameters
    except (TypeError, ValueError):
        return frozenset(newer)
    if any(par.kind is par.VAR_KEYWORD for par in params.values()):
        return frozenset(newer)
    named = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return frozenset(name for name in newer if name in params and params[name].kind in named)


def shape_problem(law: 'Law', hook: str, out, shape: tuple) -> str | None:
    """Return what is wrong with the shape of a law's output, or ``None`` when it fits.

    :param law: the law (named in the message).
    :param hook: what returned ``out``, as the message names it (``pair()``,
        ``combine()``, ``state_rate()['h']``).
    :param out: what it returned.
    :param shape: the expected shape; ``None`` in it accepts any length on that axis.
    """
    if not isinstance(out, np.ndarray):
        return f'{law.name}: {hook} returned {type(out).__name__}, not a NumPy array'
    if len(out.shape) != len(shape) or any(
            want is not None and got != want for got, want in zip(out.shape, shape)):
        want = ', '.join('k' if w is None else str(w) for w in shape)
        return f'{law.name}: {hook} returned shape {out.shape}, not ({want})'

    return None


def output_problem(law: 'Law', hook: str, out, shape: tuple) -> str | None:
    """Return what is wrong with a law's output (shape, then finiteness), or ``None``.

    The check behind every output a law gives: :func:`pair_sums`, :func:`control` and
    :func:`advance_state` raise on a wrong shape at any step; a non-finite output (a
    diverging run, or a law that divides by zero) is for the caller to handle, with this
    message.

    :param law: the law (named in the message).
    :param hook: the method that returned ``out``.
    :param out: what it returned.
    :param shape: the expected shape (``None``: any length on that axis).
    """
    problem = shape_problem(law, hook, out, shape)
    if problem is not None:
        return problem
    if not np.isfinite(out).all():
        rows = np.flatnonzero(~np.isfinite(out.reshape(out.shape[0], -1)).all(axis=1))
        shown = ', '.join(map(str, rows[:5].tolist())) + (', ...' if rows.size > 5 else '')
        return f'{law.name}: {hook} returned non-finite values (rows {shown})'
    return None


def _raise_shape(law: 'Law', hook: str, out, shape: tuple, t: float | None) -> None:
    problem = shape_problem(law, hook, out, shape)
    if problem is not None:
        when = '' if t is None else f' at t = {t:g} s'
        raise PluginError('protocol.name', problem + when)


def control(law: 'Law', q: np.ndarray, p: np.ndarray, s: np.ndarray,
            leader: LeaderState | None, agents: AgentData, dt: float,
            t: float = 0.0) -> np.ndarray:
    """Return ``combine``'s control input, called with or without the time, shape-checked.

    :param law: the law.
    :param q: positions of the agents controlled, ``(m, dim)``.
    :param p: their velocities, ``(m, dim)``.
    :param s: their pair sums, ``(m, k)``.
    :param leader: the virtual leader's state (``None``: lost).
    :param agents: their data.
    :param dt: the step.
    :param t: the time of the step.
    :return: ``u``, ``(m, dim)``.
    :raises PluginError: when ``u`` has another shape (one line naming the law and ``t``).
    """
    if 't' in accepted(type(law), 'combine'):
        u = law.combine(q, p, s, leader, agents, dt, t=t)
    else:
        u = law.combine(q, p, s, leader, agents, dt)
    _raise_shape(law, 'combine()', u, q.shape, t)
    return u


def pair_sums(law: Law, q: np.ndarray, p: np.ndarray, edges: EdgeList) -> np.ndarray:
    """Return ``s_i = sum_{j in N_i} pair(i <- j)`` for every agent of an undirected graph.

    Each undirected edge is evaluated once when the law is antisymmetric, twice otherwise;
    the sums use :func:`numpy.bincount`, so the cost is linear in the number of edges.

    :param law: the law.
    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param edges: the interaction graph.
    :return: the sums, shape ``(n, k)``.
    :raises PluginError: when ``pair`` returns another shape than ``(E, k)``.
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
    _raise_shape(law, 'pair()', to_i, (i.shape[0], None), None)
    out = np.empty((n, to_i.shape[1]))
    if law.antisymmetric:
        # pair(j <- i) = -pair(i <- j): subtracting its sums is adding those of its negation.
        for col in range(to_i.shape[1]):
            out[:, col] = (np.bincount(i, weights=to_i[:, col], minlength=n)
                           - np.bincount(j, weights=to_i[:, col], minlength=n))
        return out
    to_j = law.pair(qj, pj, qi, pi, edges.weight)
    _raise_shape(law, 'pair()', to_j, to_i.shape, None)
    for col in range(to_i.shape[1]):
        out[:, col] = (np.bincount(i, weights=to_i[:, col], minlength=n)
                       + np.bincount(j, weights=to_j[:, col], minlength=n))
    return out


def swarm_control(law: Law, q: np.ndarray, p: np.ndarray, edges: EdgeList,
                  leader: LeaderState, agents: AgentData, dt: float,
                  t: float = 0.0) -> np.ndarray:
    """Return the control input of every agent of a swarm.

    :param law: the law.
    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param edges: the interaction graph (all pairs with weights for ``law.all_pairs``).
    :param leader: the virtual leader's state.
    :param agents: per-agent data.
    :param dt: the step (used by laws that reach a target in one step).
    :param t: the time of the step (``combine``'s ``t``).
    :return: ``u``, shape ``(n, dim)``.
    """
    return control(law, q, p, pair_sums(law, q, p, edges), leader, agents, dt, t)


def group_sums(law: Law, ids: np.ndarray, q: np.ndarray, p: np.ndarray,
               edges: EdgeList) -> np.ndarray:
    """Return the pair sums of the agents ``ids`` only, as :func:`pair_sums` gives them.

    Only the edges that touch ``ids`` are evaluated, in the order :func:`pair_sums` sums
    them, so each row equals the corresponding row of the whole graph's sums.

    :param law: the law.
    :param ids: the agents (ascending, distinct), shape ``(m,)``.
    :param q: positions of every agent, shape ``(n, dim)``.
    :param p: velocities of every agent, shape ``(n, dim)``.
    :param edges: the interaction graph of the whole swarm.
    :return: the sums of ``ids``, shape ``(m, k)``.
    """
    hosted = np.zeros(q.shape[0], dtype=bool)
    hosted[ids] = True
    touch = hosted[edges.i] | hosted[edges.j]
    near = dataclasses.replace(edges, i=edges.i[touch], j=edges.j[touch],
                               weight=edges.weight[touch])
    return pair_sums(law, q, p, near)[ids]


def group_control(law: Law, ids: np.ndarray, q: np.ndarray, p: np.ndarray,
                  edges: EdgeList, leader: LeaderState | None, group: AgentData,
                  dt: float, t: float = 0.0) -> np.ndarray:
    """Return the control input of the agents ``ids`` only (agent nodes and containers).

    Only the edges that touch ``ids`` are evaluated (:func:`group_sums`), so each row
    equals the corresponding row of :func:`swarm_control` on the whole graph: what an agent
    computes is what the simulator computes for it.

    :param law: the law.
    :param ids: the agents to control (ascending, distinct), shape ``(m,)``.
    :param q: positions of every agent, shape ``(n, dim)``.
    :param p: velocities of every agent, shape ``(n, dim)``.
    :param edges: the interaction graph of the whole swarm (as :func:`swarm_control`).
    :param leader: the virtual leader's state as these agents know it (``None``: lost, the
        uninformed law for all of them).
    :param group: per-agent data of ``ids`` (``agents.subset(ids)``).
    :param dt: the step.
    :param t: the time of the step.
    :return: ``u`` of ``ids``, shape ``(m, dim)``.
    """
    s = group_sums(law, ids, q, p, edges)
    return control(law, q[ids], p[ids], s, leader, group, dt, t)


def local_control(law: Law, q_self: np.ndarray, p_self: np.ndarray,
                  q_nb: np.ndarray, p_nb: np.ndarray, w_nb: np.ndarray,
                  leader: LeaderState, agent: AgentData, dt: float,
                  t: float = 0.0) -> np.ndarray:
    """Return the control input of one agent from its neighbours' states.

    A robot's entry point when it knows only its neighbours: the same ``pair`` and
    ``combine`` as :func:`swarm_control`.

    :param law: the law.
    :param q_self: own position, shape ``(dim,)``.
    :param p_self: own velocity, shape ``(dim,)``.
    :param q_nb: neighbour positions, shape ``(m, dim)`` (``m`` may be 0).
    :param p_nb: neighbour velocities, shape ``(m, dim)``.
    :param w_nb: edge weights, shape ``(m,)``.
    :param leader: the virtual leader's state as this agent knows it.
    :param agent: this agent's data (arrays of length 1).
    :param dt: the step.
    :param t: the time of the step.
    :return: ``u``, shape ``(dim,)``.
    """
    m = q_nb.shape[0]
    qi = np.broadcast_to(q_self, (m, q_self.shape[0]))
    pi = np.broadcast_to(p_self, (m, p_self.shape[0]))
    terms = law.pair(qi, pi, q_nb, p_nb, w_nb)
    _raise_shape(law, 'pair()', terms, (m, None), t)
    s = terms.sum(axis=0, keepdims=True)
    return control(law, q_self[None], p_self[None], s, leader, agent, dt, t)[0]


def state_rates(law: Law, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                agents: AgentData, sums: Callable[[], np.ndarray] | None = None,
                t: float = 0.0) -> dict[str, np.ndarray]:
    """Return ``state_rate``'s rates, called with what the law's signature takes, checked.

    :param law: the law.
    :param q: positions of the agents, ``(m, dim)``.
    :param p: their velocities.
    :param leader: the leader's state (``None``: lost).
    :param agents: their data, with the current adaptive state.
    :param sums: returns the agents' pair sums (called only for a ``state_rate`` that
        takes ``s``; ``None``: none known, the law receives ``s=None``).
    :param t: the time of the step.
    :return: ``{key: rate}``.
    :raises PluginError: for a key that is not a state, or a rate of another shape.
    """
    takes = accepted(type(law), 'state_rate')
    kwargs = {}
    if 's' in takes:
        kwargs['s'] = None if sums is None else sums()
    if 't' in takes:
        kwargs['t'] = t
    rates = law.state_rate(q, p, leader, agents, **kwargs)
    for key, rate in rates.items():
        if key not in agents.state:
            raise PluginError('protocol.name', f'{law.name}: state_rate() returned {key!r}, '
                              f'not a key of initial_state() ({", ".join(agents.state)})')
        _raise_shape(law, f'state_rate()[{key!r}]', rate, agents.state[key].shape, t)
    return rates


def advance_state(law: Law, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                  agents: AgentData, dt: float, sums: Callable[[], np.ndarray] | None = None,
                  t: float = 0.0) -> None:
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
    :param sums: returns the pair sums of these agents at the start of the step (see
        :func:`state_rates`).
    :param t: the time at the start of the step.
    """
    if not agents.state:
        return
    for key, rate in state_rates(law, q, p, leader, agents, sums, t).items():
        agents.state[key] += dt * rate


def antisymmetry_problem(law: Law, dim: int) -> str | None:
    """Return why a law's ``antisymmetric = True`` claim is false, or ``None``.

    ``pair(i <- j)`` and ``pair(j <- i)`` are evaluated on :data:`ANTISYMMETRY_SAMPLES`
    random pairs (a fixed seed: the same verdict every time) at distances up to the law's
    radius, with random velocities and weights; they must cancel to
    :data:`ANTISYMMETRY_RTOL`. A false claim would make every run silently wrong (the
    second direction is never evaluated), in ``sim`` and ROS alike.

    :param law: the law (a law that claims nothing passes).
    :param dim: the scenario's dimension.
    :return: one line naming the law and the worst pair, or ``None``.
    """
    if not law.antisymmetric:
        return None
    rng = np.random.default_rng(0)
    radius = float(law.radius)
    scale = radius if np.isfinite(radius) and radius > 0 else 1.0
    m = ANTISYMMETRY_SAMPLES
    qi = rng.uniform(-scale, scale, (m, dim))
    heading = rng.normal(size=(m, dim))
    heading /= np.linalg.norm(heading, axis=1, keepdims=True)
    qj = qi + heading * rng.uniform(0.05, 0.95, (m, 1)) * scale
    pi, pj = rng.uniform(-1.0, 1.0, (m, dim)), rng.uniform(-1.0, 1.0, (m, dim))
    w = rng.uniform(0.5, 2.0, m)
    with np.errstate(all='ignore'):
        to_i = law.pair(qi, pi, qj, pj, w)
        to_j = law.pair(qj, pj, qi, pi, w)
    for out in (to_i, to_j):
        problem = shape_problem(law, 'pair()', out, (m, None))
        if problem is not None:
            return problem
    ok = np.isfinite(to_i).all(axis=1) & np.isfinite(to_j).all(axis=1)
    if not ok.any():
        return None
    err = np.abs(to_i[ok] + to_j[ok]).max(axis=1)
    size = np.maximum(np.abs(to_i[ok]).max(axis=1), np.abs(to_j[ok]).max(axis=1))
    bad = err > ANTISYMMETRY_RTOL * size
    if not bad.any():
        return None
    worst = int(np.argmax(np.where(bad, err, -1.0)))
    gap = float(np.linalg.norm((qj - qi)[ok][worst]))
    return (f'{law.name}: declares antisymmetric = True, but pair(i <- j) + pair(j <- i) '
            f'= {err[worst]:.3g}, not 0, for agents {gap:.3g} m apart: set '
            'antisymmetric: ClassVar[bool] = False (or fix pair) (docs/extending.md)')
