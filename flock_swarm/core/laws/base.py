"""The law plugin API: the base class of the flocking laws and what they are given.

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

Their evaluation over a swarm, a group of agents or one agent is
:mod:`flock_swarm.core.laws.evaluation`. Hooks that grew a parameter (``combine``'s time
``t``, ``state_rate``'s neighbour sums ``s`` and time ``t``) are called the old way for a
law written before: :func:`accepted` reads each class's signature once.
"""

import inspect
from dataclasses import dataclass, field
from functools import lru_cache
from typing import ClassVar

import numpy as np

from flock_swarm.core.leaders.base import LeaderState

#: The parameters a hook gained after plugins were written to it: a law whose method does not
#: take one is called without it (:func:`accepted`).
NEWER_PARAMETERS = {'combine': ('t',), 'state_rate': ('s', 't')}


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
