"""The run machinery: a whole swarm, vectorised over agents, stepped from one scenario.

:func:`simulate` (and :func:`simulate_stack`, several realisations side by side) runs a scenario
to its end; :class:`RunLog` is the bookkeeping of a run (whole-run metrics and the subsampled
time series) shared by ``sim``, the world node and ``analyze``; :func:`build_summary` assembles
``summary.json`` (see ``docs/outputs.md``); :func:`check_law_output` and :func:`check_step`
are the checks before a run. The step uses the same law functions as the agent node
(:mod:`flock_swarm.core.laws`). No file I/O here: :mod:`flock_swarm.outputs` writes.
"""

import ctypes
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from flock_swarm.core.dynamics import step_agents
from flock_swarm.core.faults import (RunFault, advance_leader, evaluate_law, evaluate_state,
                                     leader_state, non_finite_fault, non_finite_rows,
                                     state_blew_up, unnamed)
from flock_swarm.core.graphs import EdgeList, VerletDiskGraph, disk_graph, fixed_graph
from flock_swarm.core.headline import progress_text
from flock_swarm.core.metrics import (STEP_METRICS, RunMetrics, step_metrics,
                                      update_stacked_from_edges)
from flock_swarm.core.laws.base import AgentData, Law, StepViolation
from flock_swarm.core.laws.evaluation import (advance_state, group_control, output_problem,
                                              pair_sums, swarm_control)
from flock_swarm.core.leaders.base import LeaderState, VirtualLeader
from flock_swarm.core.network import NetworkState, neighbourhood_of
from flock_swarm.core.obstacles import (Geometry, ObstacleMetrics, ObstacleSpec, check_start,
                                        geometry, with_obstacles)
from flock_swarm.core.obstacles import step_bounds as obstacle_step_bounds
from flock_swarm.core.pseudo_leaders import Reselector
from flock_swarm.core.errors import PluginError
from flock_swarm.core.registry import LAW_GROUP, entries
from flock_swarm.core.scenario import Realization, Scenario, all_pairs_weights, realize
from flock_swarm.core.stability import model_bounds
from flock_swarm.core.summary import RunFacts, SummaryInputs, summary_of

#: glibc's mallopt() parameters (malloc.h) and the values simulate() sets: blocks below
#: 32 MB come from the heap, and up to 64 MB freed at its top are kept (see keep_freed_memory).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_HEAP_MMAP_THRESHOLD, _HEAP_TRIM_THRESHOLD = 32 << 20, 64 << 20


@dataclass
class RunResult:
    """What a run produced: the summary (``summary.json``) and the recorded time series."""

    summary: dict
    series: dict[str, np.ndarray] = field(default_factory=dict)


class Recorder:
    """Collects subsampled states and metrics into growing lists, then stacks them.

    The in-memory recorder of ``sim`` and ``analyze``; a recorder that keeps the rows
    elsewhere (the world's :class:`flock_swarm.outputs.SpooledRecorder`, on disk) overrides
    :meth:`add` and :meth:`arrays` and keeps :attr:`count`.
    """

    def __init__(self) -> None:
        """Create an empty recorder."""
        self.rows: dict[str, list] = {}
        #: Instants recorded so far.
        self.count = 0

    def add(self, **values) -> None:
        """Append one recorded instant."""
        for key, value in values.items():
            self.rows.setdefault(key, []).append(np.array(value, copy=True))
        self.count += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """Return the recorded columns as arrays (first axis: time)."""
        return {key: np.stack(rows) for key, rows in self.rows.items()}


class RunLog:
    """Whole-run metrics and the subsampled time series, fed one step at a time.

    The one bookkeeping of a run, shared by ``sim``, the world node and ``analyze``: every
    step updates the whole-run metrics from the step's edges; every ``record_every``-th step
    and the last are measured with :func:`step_metrics` and recorded.
    """

    def __init__(self, eta_tolerance: float, collision_distance: float, radius: float,
                 strict: bool, record_every: int, recorder: Recorder | None = None,
                 obstacles: ObstacleSpec | None = None) -> None:
        """Create the log.

        :param eta_tolerance: velocity tolerance of ``eta``.
        :param collision_distance: pairs closer than this count as collisions.
        :param radius: radius of the r-disk graph whose components are counted.
        :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
        :param record_every: subsampling of the time series.
        :param recorder: where the recorded instants go (default: a :class:`Recorder`
            in memory).
        :param obstacles: the run's obstacles (``None`` or inactive: a run without; the
            agent-obstacle metrics are then neither measured nor recorded).
        """
        self.eta_tolerance = eta_tolerance
        self.radius, self.strict, self.every = radius, strict, record_every
        self.metrics = RunMetrics(collision_distance)
        if obstacles is not None and obstacles.active:
            self.metrics.obstacles = ObstacleMetrics(obstacles, collision_distance)
        #: The smallest agent-obstacle clearance of the last instant folded in.
        self.clearance = float('inf')
        self.rec = Recorder() if recorder is None else recorder
        self.latest: dict = {}

    @classmethod
    def for_scenario(cls, sc: Scenario, recorder: Recorder | None = None) -> 'RunLog':
        """Return the log of a scenario's run (``recorder`` as in :class:`RunLog`)."""
        return cls(sc.eta_tolerance, sc.collision_distance, sc.law.radius,
                   sc.law.strict_radius, sc.record_every, recorder, sc.obstacles)

    def observe(self, k: int, t: float, q: np.ndarray, p: np.ndarray, u: np.ndarray,
                leader: LeaderState, informed: np.ndarray, edges: EdgeList,
                edges_radius: float, last: bool, **extra) -> dict | None:
        """Fold in step ``k``; return its metrics when it is recorded, else ``None``.

        :param edges: the step's graph, complete within ``edges_radius``.
        :param extra: further per-step arrays to record (e.g. adaptive gains ``h``).
        """
        self.metrics.update_from_edges(q, edges, edges_radius)
        self.fold_obstacles(q)
        return self.record(k, t, q, p, u, leader, informed, last, **extra)

    def fold_obstacles(self, q: np.ndarray, geo: Geometry | None = None) -> None:
        """Fold one step's agent-obstacle clearances into the whole-run metrics (every step).

        Part of :meth:`observe`; a stack of runs (:func:`simulate_stack`) calls it for each,
        with the step's :class:`~flock_swarm.core.obstacles.Geometry` it computed already.
        """
        if self.metrics.obstacles is not None:
            self.clearance = self.metrics.obstacles.update(q, geo)

    def record(self, k: int, t: float, q: np.ndarray, p: np.ndarray, u: np.ndarray,
               leader: LeaderState, informed: np.ndarray, last: bool,
               **extra) -> dict | None:
        """Measure and record step ``k`` if it is a recorded one; return its metrics or ``None``.

        The part of :meth:`observe` after the whole-run metrics, for callers that fold those
        in themselves (a stack of runs, :func:`simulate_stack`).
        """
        if k % self.every and not last:
            return None
        now = step_metrics(q, p, leader, self.eta_tolerance, self.radius, self.strict)
        self.metrics.update(q, now['min_pair_distance'])
        found = self.metrics.obstacles
        if found is not None:
            # The instant's smallest clearance (folded in by fold_obstacles this step), and
            # the counts so far (/swarm/metrics shows them live).
            extra = {**extra, 'obstacle_clearance': self.clearance}
            now = dict(now, obstacle_clearance=self.clearance,
                       obstacle_penetrations=len(found.penetrations),
                       obstacle_collisions=len(found.collisions))
        self.rec.add(t=t, q=q, p=p, u=u, leader_q=leader.q, leader_p=leader.p,
                     leader_a=leader.a, informed=informed, **extra,
                     **{f'metric_{name}': now[name] for name in STEP_METRICS})
        self.latest = now
        return now


def interaction_graph(sc: Scenario, real: Realization, q: np.ndarray,
                      static: EdgeList | None) -> EdgeList:
    """Return the interaction edges at positions ``q`` (the fixed graph when there is one).

    :param sc: the scenario.
    :param real: its realisation.
    :param q: positions.
    :param static: the precomputed fixed graph, or ``None``.
    :return: the edge list.
    """
    if static is not None:
        return static
    if sc.law.all_pairs:
        return all_pairs_weights(sc.n_agents, None, q, sc.law)
    return disk_graph(q, sc.law.radius, sc.law.strict_radius)


class LinkObserver:
    """The network statistics of a run's agent links, counted without evaluating the law.

    An observer of a lockstep run (the world node, ``analyze`` on a bag) sends, step by
    step, the messages between the agents ``sim`` sends (nobody informed: the statistics are
    of the agents' links) and counts what the agents use
    (:meth:`~flock_swarm.core.network.NetworkState.observe`): the statistics ``sim`` records.
    """

    def __init__(self, sc: Scenario, real: Realization, static: EdgeList | None) -> None:
        """Create the observer of a run of ``sc`` (its ``network:`` section active)."""
        self.sc, self.real, self.static = sc, real, static
        self.net = NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                                neighbourhood_of(sc.graph_type, sc.law.all_pairs),
                                sc.law.coupling_weight)
        self.nobody = np.zeros(sc.n_agents, dtype=bool)

    def step(self, k: int, q: np.ndarray, p: np.ndarray) -> list[int]:
        """Send step ``k``'s messages and return its counts
        (:class:`~flock_swarm.core.network.Tally`'s order).

        :param k: the step (every step, in order).
        :param q: the agents' positions at ``k``.
        :param p: their velocities.
        """
        sc = self.sc
        self.net.send(k, q, p, None, interaction_graph(sc, self.real, q, self.static),
                      self.nobody)
        self.net.observe(q, p, sc.dt)
        return self.net.counts


def whole_run_pairs(sc: Scenario, q: np.ndarray, static: EdgeList | None,
                    edges: EdgeList) -> tuple[EdgeList, float]:
    """Return the pairs a step's whole-run metrics are folded from, and the radius they cover
    completely (:meth:`~flock_swarm.core.metrics.RunMetrics.update_from_edges`).

    ``sim``'s rule, which the world node and ``analyze`` follow so that their
    ``min_pair_distance`` and ``collisions`` are ``sim``'s: on a fixed graph, the pairs
    closer than ``collision_distance`` (its edges say nothing of distances); otherwise the
    step's interaction graph, which covers every pair within ``r`` (r-disk edges) or every
    pair (a law acting on all pairs).

    :param sc: the scenario.
    :param q: positions.
    :param static: the fixed graph (:func:`static_graph`), or ``None``.
    :param edges: the step's interaction graph (:func:`interaction_graph`); unused on a
        fixed graph.
    :return: ``(pairs, radius)``.
    """
    if static is not None:
        return disk_graph(q, sc.collision_distance), sc.collision_distance
    return edges, np.inf if sc.law.all_pairs else sc.law.radius


def observed_pairs(sc: Scenario, real: Realization, q: np.ndarray, static: EdgeList | None,
                   disk: EdgeList) -> tuple[EdgeList, float]:
    """Return :func:`whole_run_pairs` for an observer of a run that has the step's r-disk
    graph rather than its interaction graph (the world node, ``analyze``).

    :param sc: the scenario.
    :param real: its realisation.
    :param q: positions.
    :param static: the fixed graph (:func:`static_graph`), or ``None``.
    :param disk: the r-disk graph at ``q`` (``r``, ``strict_radius`` of the law).
    :return: ``(pairs, radius)``.
    """
    graph = interaction_graph(sc, real, q, None) if sc.law.all_pairs and static is None \
        else disk
    return whole_run_pairs(sc, q, static, graph)


def static_graph(sc: Scenario, real: Realization) -> EdgeList | None:
    """Return the time-invariant edge list of a fixed-graph scenario, or ``None``."""
    if real.adjacency is None:
        return None
    if sc.law.all_pairs:
        return all_pairs_weights(sc.n_agents, real.adjacency, np.zeros((sc.n_agents, sc.dim)),
                                 sc.law)
    return fixed_graph(real.adjacency)


def check_law_output(sc: Scenario, real: Realization) -> None:
    """Evaluate the scenario's law once at the initial state; raise if its output is unusable.

    A law from a plugin is code this package has never seen: an exception, a wrong shape or
    non-finite values are reported before the run as one line naming its entry point, not
    as a traceback or a silently diverged run. The leader model's acceleration at ``t = 0``
    is checked the same way (an exception, a wrong shape, a non-finite value): mid-run,
    :mod:`flock_swarm.core.faults` checks every later step.

    :param sc: the scenario.
    :param real: its realisation.
    :raises PluginError: naming the entry point and what went wrong.
    :raises ScenarioError: for an agent that starts inside an obstacle.
    """
    check_start(sc.obstacles, real.q0)
    try:
        leader = leader_state(VirtualLeader(sc.leader.model, sc.leader.position,
                                            sc.leader.velocity), 0, sc.dim)
    except RunFault as fault:
        raise PluginError('leader.model', fault.line) from None
    entry = entries(LAW_GROUP).get(sc.law.name)
    label = entry.label if entry is not None else sc.law.name
    try:
        with np.errstate(all='ignore'):
            edges = interaction_graph(sc, real, real.q0, static_graph(sc, real))
            u = swarm_control(sc.law, real.q0, real.p0, edges, leader, real.agents, sc.dt)
            u = with_obstacles(sc.obstacles, u, real.q0, real.p0)
    except PluginError as exc:
        raise PluginError('protocol.name', f'{label}: {unnamed(sc.law, exc.reason)}') from None
    except Exception as exc:  # noqa: BLE001 - whatever a plugin raises is reported
        raise PluginError('protocol.name', f'{label}: raised {type(exc).__name__} at the '
                          f'initial state: {exc}') from None
    problem = output_problem(sc.law, 'combine()', u, (sc.n_agents, sc.dim))
    if problem is not None:
        raise PluginError('protocol.name', f'{label}: {unnamed(sc.law, problem)} at the '
                          'initial state')


def check_step(sc: Scenario, real: Realization) -> list[StepViolation]:
    """Return the bounds the scenario's ``dt`` violates (empty when it is fine).

    The law's own bounds (:meth:`~flock_swarm.core.laws.base.Law.step_bounds`, given the
    run's :class:`~flock_swarm.core.laws.base.LawSetup`), the beta term's of the obstacles
    (:func:`~flock_swarm.core.obstacles.step_bounds`), then RK4's for the leader model
    and the intrinsic dynamics (:func:`~flock_swarm.core.stability.model_bounds`).

    :param sc: the scenario.
    :param real: its realisation (fixed graphs, informed set).
    :return: the violations.
    """
    found = list(sc.law.step_bounds(real.setup)) + obstacle_step_bounds(sc.obstacles, sc.dt)
    for part, model in (('leader model', sc.leader.model), ('intrinsic dynamics', sc.intrinsic)):
        found += model_bounds(part, model, sc.leader.velocity, sc.dim, sc.dt)
    return found


def simulate(sc: Scenario, progress: Callable[[str], None] | None = None,
             progress_every: float = 2.0, integrator: Callable | None = None,
             on_step: Callable[[int, np.ndarray, np.ndarray], None] | None = None
             ) -> RunResult:
    """Run a scenario to its end and return the summary and the recorded time series.

    :param sc: the validated scenario.
    :param progress: called with a one-line status roughly every ``progress_every`` seconds.
    :param progress_every: wall-clock seconds between progress lines.
    :param integrator: ``None`` (the plant steps itself), or a factory called with the
        plant's initial state, returning what integrates the agents instead: an object with
        ``state()`` (the state rows it starts from) and the plant's ``step(x, cmd, dt)``
        (the physics engine, :class:`flock_swarm.engine.backend.EngineBackend`: ``sim
        --backend mujoco``, as the world's ``backend``), and optionally ``summary()``: summary
        keys of its own (the engine's ``robot_contacts``).
    :param on_step: called with every step's number, positions and velocities (views of
        the state the next step overwrites: copy what is kept), whatever ``record_every``
        records: ``analyze --verify`` compares every step without the metrics of each.
    :return: the result; ``summary['status']`` is ``completed``, ``interrupted``,
        ``diverged`` (the state stopped being finite) or ``failed`` (a fault of the law or
        the leader model: ``summary['failure']`` tells it in one line).
    """
    return simulate_stack([sc], progress, progress_every, integrator, on_step)[0]


def simulate_stack(scenarios: list[Scenario], progress: Callable[[str], None] | None = None,
                   progress_every: float = 2.0,
                   integrator: Callable | None = None,
                   on_step: Callable[[int, np.ndarray, np.ndarray], None] | None = None
                   ) -> list[RunResult]:
    """Run independent realisations side by side in one vectorised state; return each result.

    A Monte Carlo sweep pays the per-step cost of Python once for the whole stack instead of
    once per run. Each realisation is drawn by :func:`realize` from its own scenario (seed,
    informed set, initial boxes) and the stack's graph links no two of them, with every
    realisation's edges in the order of its own run: each result is that of
    :func:`simulate` on its scenario alone, up to the summation order of the metrics.
    Realisations that diverge, or whose law gives a non-finite command, leave the stack at
    that step; the others go on. A law or leader model that raises (or returns the wrong
    shape) fails every realisation still running.

    :param scenarios: the realisations; more than one must agree in everything but seed,
        informed set and initial state (:func:`stack_mismatch`).
    :param progress: called with a one-line status (of the first realisation still running)
        roughly every ``progress_every`` seconds.
    :param progress_every: wall-clock seconds between progress lines.
    :param integrator: :func:`simulate`'s (a single realisation only: it holds one swarm).
    :param on_step: :func:`simulate`'s (with a stack: the stacked rows).
    :return: one result per scenario, in order; ``summary['wall_time_s']`` is the stack's
        wall time divided among its realisations.
    :raises ValueError: when the scenarios cannot share a stack.
    """
    reason = stack_mismatch(scenarios)
    if reason is not None:
        raise ValueError(f'cannot stack these scenarios: {reason}')
    keep_freed_memory()
    sc = scenarios[0]
    reals = [realize(s) for s in scenarios]
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity)
    intrinsic = sc.intrinsic.velocity_field() if sc.intrinsic is not None else None
    if integrator is not None and len(scenarios) != 1:
        raise ValueError('an integrator runs one realisation, not a stack')
    stack = _Stack(scenarios, reals, static_graph(sc, reals[0]) if len(reals) == 1 else None,
                   integrator)
    started = time.monotonic()
    # Divergence is detected explicitly below, so NumPy's overflow warnings would only repeat it.
    with np.errstate(over='ignore', invalid='ignore'):
        _run_loop(stack, leader, intrinsic, progress, progress_every, on_step)
    wall = (time.monotonic() - started) / len(scenarios)
    results = []
    for g, (s, real) in enumerate(zip(scenarios, reals)):
        status, step = stack.outcome[g]
        log = stack.logs[g]
        if not log.rec.count and g in stack.failures:
            # A fault before the first recorded instant (the start checks passed, so the
            # law or model is not deterministic): there is no run to summarise.
            raise RunFault(stack.failures[g], 'raised', step)
        series = log.rec.arrays()
        failure = {'failure': stack.failures[g]} if g in stack.failures else {}
        # An integrator may tell summary keys of its own (the engine: robot_contacts).
        told = getattr(stack.integrator, 'summary', None)
        summary = build_summary(
            s, real, series, log.metrics, step, status,
            pseudo_leader_reselections=0 if stack.reselector is None else stack.reselector.count,
            wall_time_s=round(wall, 3), **failure, **(told() if told else {}))
        results.append(RunResult(summary, series))
    return results


def keep_freed_memory() -> None:
    """Let the C library keep freed memory for the next arrays rather than return it.

    A step allocates and frees temporaries of a few hundred kB (one value per edge); by
    default glibc gives such blocks back to the kernel (munmap, heap trimming) and takes
    them again at the next step, a page fault per 4 kB. Measured on a stack of three
    N = 1000 Fig. 3 runs: 495 000 -> 19 000 minor page faults in 400 steps, 0.7 -> 0.07 s of
    system time, 7.1 -> 5.2 ms per step. Process-wide and idempotent; nothing happens where
    the C library has no ``mallopt`` (it is glibc's).
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (AttributeError, OSError, TypeError):
        return
    mallopt(_M_MMAP_THRESHOLD, _HEAP_MMAP_THRESHOLD)
    mallopt(_M_TRIM_THRESHOLD, _HEAP_TRIM_THRESHOLD)


def stack_mismatch(scenarios: list[Scenario]) -> str | None:
    """Return why scenarios cannot run in one stack (:func:`simulate_stack`), or ``None``.

    One scenario always can. Several need an r-disk graph (no fixed graph, no law acting on
    all pairs, no re-selected pseudo-leaders) and must agree in everything a step or the
    record depends on: dimension, size, step, duration, law, leader, intrinsic dynamics,
    recording and metric settings.
    """
    if not scenarios:
        return 'no scenario'
    if len(scenarios) == 1:
        return None
    first = scenarios[0]
    for sc in scenarios:
        if sc.network.active:
            # Each run's messages are keyed by its own seed and kept per link: one at a time.
            return f'{sc.name}: a run with a network model runs alone'
        if sc.graph_type != 'disk' or sc.law.all_pairs or sc.informed.reselect:
            return f'{sc.name}: only r-disk graphs without re-selection stack'
        same = {'dim': sc.dim == first.dim, 'n_agents': sc.n_agents == first.n_agents,
                'dt': sc.dt == first.dt, 'duration': sc.steps == first.steps,
                'protocol': sc.law == first.law, 'intrinsic': sc.intrinsic == first.intrinsic,
                'record_every': sc.record_every == first.record_every,
                'metrics': (sc.eta_tolerance, sc.collision_distance)
                == (first.eta_tolerance, first.collision_distance),
                'leader': sc.leader.model == first.leader.model
                and np.array_equal(sc.leader.position, first.leader.position)
                and np.array_equal(sc.leader.velocity, first.leader.velocity),
                'observers': bool(sc.observers) == bool(first.observers),
                'obstacles': sc.obstacles == first.obstacles,
                'plant': sc.plant == first.plant}
        differ = [key for key, ok in same.items() if not ok]
        if differ:
            return f'{sc.name} (seed {sc.seed}) differs in {", ".join(differ)}'
    return None


class _Stack:
    """The state of the realisations of :func:`simulate_stack` still running.

    Agents ``b m .. (b + 1) m - 1`` of the arrays belong to the ``b``-th realisation in
    ``active``; a realisation that ends early (diverges) is cut out of the arrays.
    """

    def __init__(self, scenarios: list[Scenario], reals: list[Realization],
                 static: EdgeList | None, integrator: Callable | None = None) -> None:
        """Stack the initial states, per-agent data and logs of the realisations."""
        sc = scenarios[0]
        self.scenarios, self.reals, self.static = scenarios, reals, static
        self.size = sc.n_agents
        self.logs = [RunLog.for_scenario(s) for s in scenarios]
        self.outcome: dict[int, tuple[str, int]] = {}
        #: The line telling why a realisation failed (status ``failed``), by realisation.
        self.failures: dict[int, str] = {}
        self.active = list(range(len(scenarios)))
        self.q = np.concatenate([r.q0 for r in reals])
        self.p = np.concatenate([r.p0 for r in reals])
        #: The plant (``plant:``), ``None`` for the double integrator: today's exact path.
        self.plant = None if sc.plant.default else sc.plant.model
        #: The plant's state; ``q``, ``p`` are what the law sees of it.
        self.x: np.ndarray | None = None
        if self.plant is not None:
            self.x = self.plant.initial_state(self.q, self.p)
            self.q, self.p = self.plant.law_state(self.x)
        #: What steps the plant instead of its own ``step`` (``simulate``'s integrator).
        self.integrator = None
        if integrator is not None:
            self.integrator = integrator(self.x)
            self.x = self.integrator.state()
            self.q, self.p = self.plant.law_state(self.x)
        self.agents = stack_agents([r.agents for r in reals])
        self.reselector = Reselector(sc.law) if sc.informed.reselect and static is None \
            else None
        self._disk = static is None and not sc.law.all_pairs
        self.graph = self._new_graph()
        #: ``(q, its Geometry)``: the obstacle geometry of the positions ``q`` (the same
        #: array object: a step replaces ``q``, never writes into it).
        self.geometry: tuple[np.ndarray, Geometry] | None = None
        #: The messages between the agents (``network:``), ``None`` without the section.
        self.net = NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                                neighbourhood_of(sc.graph_type, sc.law.all_pairs),
                                sc.law.coupling_weight) if sc.network.active else None

    def _new_graph(self) -> VerletDiskGraph | None:
        """Return the r-disk graph tracker of the active realisations (``None``: not r-disk)."""
        if not self._disk:
            return None
        law = self.scenarios[0].law
        return VerletDiskGraph(law.radius, law.strict_radius, blocks=len(self.active))

    def edges(self) -> EdgeList:
        """Return the interaction graph at the current positions."""
        if self.graph is not None:
            return self.graph.edges(self.q)
        return interaction_graph(self.scenarios[0], self.reals[0], self.q, self.static)

    def failed(self, *arrays: np.ndarray) -> np.ndarray:
        """Return, per active realisation, whether any of its rows is not finite."""
        if all(np.isfinite(a).all() for a in arrays):
            return np.zeros(len(self.active), dtype=bool)
        ok = np.ones(self.q.shape[0], dtype=bool)
        for a in arrays:
            ok &= np.isfinite(a).all(axis=1)
        return ~ok.reshape(len(self.active), self.size).all(axis=1)

    def end(self, gone: np.ndarray, status: str | dict[int, str], step: int,
            failures: dict[int, str] | None = None) -> np.ndarray:
        """End the realisations flagged in ``gone`` at ``step``; return the rows kept.

        :param status: their status, or ``{b: status}`` for each flagged realisation ``b``
            (its index among the active ones).
        :param failures: ``{b: line}``: why realisation ``b`` failed.
        """
        keep = np.repeat(~gone, self.size)
        for b in np.flatnonzero(gone).tolist():
            g = self.active[b]
            self.outcome[g] = (status if isinstance(status, str) else status[b], step)
            if failures and b in failures:
                self.failures[g] = failures[b]
        self.active = [g for g, out in zip(self.active, gone.tolist()) if not out]
        self.q, self.p = self.q[keep], self.p[keep]
        if self.x is not None:
            self.x = self.x[keep]
        self.agents = self.agents.subset(keep)
        self.graph = self._new_graph()
        return keep

    def finish(self, status: str, step: int, failure: str | None = None) -> None:
        """End every realisation still running (``failure``: why they failed)."""
        for g in self.active:
            self.outcome[g] = (status, step)
            if failure is not None:
                self.failures[g] = failure

    def control(self, law: Law, edges: EdgeList, leader: LeaderState, dt: float,
                step: int) -> np.ndarray:
        """Return the law's commands of every active row (:func:`swarm_control`), checked.

        :raises RunFault: when the law raised (naming the first agent that raises alone) or
            returned the wrong shape.
        """
        q, p, agents = self.q, self.p, self.agents

        t = step * dt

        obstacles, geo = self.scenarios[0].obstacles, self.obstacle_geometry()

        def alone(row: int) -> np.ndarray:
            one = np.array([row])
            return with_obstacles(obstacles, group_control(law, one, q, p, edges, leader,
                                                           agents.subset(one), dt, t),
                                  q[one], p[one])
        return evaluate_law(law, step, np.arange(q.shape[0]) % self.size, q.shape[1],
                            lambda: with_obstacles(obstacles, swarm_control(
                                law, q, p, edges, leader, agents, dt, t), q, p, geo),
                            alone)

    def obstacle_geometry(self) -> Geometry | None:
        """Return the agents' geometry relative to the obstacles at the current positions,
        computed once a step for the beta term and the metrics (``None``: no obstacles)."""
        spec = self.scenarios[0].obstacles
        if not spec.active:
            return None
        if self.geometry is None or self.geometry[0] is not self.q:
            self.geometry = (self.q, geometry(spec, self.q))
        return self.geometry[1]

    def end_non_finite(self, u: np.ndarray, leader: LeaderState, law: Law,
                       step: int) -> np.ndarray | None:
        """End the realisations given a non-finite command; return the other rows of ``u``.

        A realisation whose state has blown up (:func:`state_blew_up`) has ``diverged``; in
        the others the law gave a non-finite command at a plausible state: ``failed``,
        naming the law, the agents and the step.

        :return: the commands of the realisations still running (``None``: none is).
        """
        if np.isfinite(u).all():
            return u
        m = self.size
        bad = non_finite_rows(u).reshape(len(self.active), m)
        gone = bad.any(axis=1)
        status, failures = {}, {}
        for b in np.flatnonzero(gone).tolist():
            rows = slice(b * m, (b + 1) * m)
            if state_blew_up(self.q[rows], self.p[rows], leader):
                status[b] = 'diverged'
            else:
                status[b] = 'failed'
                failures[b] = non_finite_fault(law, step, np.flatnonzero(bad[b])).line
        u = u[self.end(gone, status, step, failures)]
        return u if self.active else None

    def extra(self, rows: slice) -> dict:
        """Return the per-agent protocol state (and the plant's state) to record for some rows."""
        plant = {} if self.plant is None else self.plant.recorded(self.x[rows])
        return {**{key: value[rows] for key, value in self.agents.state.items()}, **plant}

    def advance(self, u: np.ndarray, dt: float, intrinsic) -> None:
        """Advance every agent one step under the law's commands ``u``.

        The double integrator (no ``plant:``) integrates exactly as ever
        (:func:`step_agents`); another plant turns ``u`` into its command and steps itself
        (:mod:`flock_swarm.core.plants`), the law seeing its new ``law_state``.
        """
        if self.plant is None:
            self.q, self.p = step_agents(self.q, self.p, u, dt, intrinsic)
            return
        step = self.plant.step if self.integrator is None else self.integrator.step
        self.x = step(self.x, self.plant.command(self.x, u, dt), dt)
        self.q, self.p = self.plant.law_state(self.x)


def stack_agents(parts: list[AgentData]) -> AgentData:
    """Return the per-agent data of several realisations, stacked in order."""
    return AgentData.concatenate(parts)


def _run_loop(stack: _Stack, leader: VirtualLeader, intrinsic, progress, progress_every,
              on_step=None):
    """Advance the stack to the end (or divergence or failure of all, or Ctrl-C); record how
    each ended."""
    sc = stack.scenarios[0]
    law, dt, steps, every = sc.law, sc.dt, sc.steps, sc.record_every
    step = 0
    started = last = time.monotonic()
    try:
        for step in range(steps + 1):
            gone = stack.failed(stack.q, stack.p)
            if gone.any():
                stack.end(gone, 'diverged', step)
            if not stack.active:
                return
            state = leader_state(leader, step, sc.dim)
            edges = stack.edges()
            if stack.reselector is not None:
                stack.reselector.update(stack.agents, edges)
            n_rows = stack.q.shape[0]
            if stack.net is None:
                u = stack.control(law, edges, state, dt, step)
            else:
                stack.net.send(step, stack.q, stack.p, state, edges, stack.agents.informed)
                u = evaluate_law(law, step, np.arange(n_rows) % stack.size, sc.dim,
                                 lambda: with_obstacles(sc.obstacles, stack.net.control(
                                     None, stack.q, stack.p, stack.agents, dt, step * dt)[0],
                                     stack.q, stack.p, stack.obstacle_geometry()))
            u = stack.end_non_finite(u, state, law, step)
            if u is None:
                return
            if u.shape[0] != n_rows:
                edges = stack.edges()
            q, p, m = stack.q, stack.p, stack.size
            if on_step is not None:
                on_step(step, q, p)
            covered, radius = whole_run_pairs(sc, q, stack.static, edges)
            logs = [stack.logs[g] for g in stack.active]
            update_stacked_from_edges([log.metrics for log in logs], q, covered, radius,
                                      None if stack.graph is None else stack.graph.sq_dist)
            if sc.obstacles.active:
                geo = stack.obstacle_geometry()
                for b, log in enumerate(logs):
                    log.fold_obstacles(q[b * m:(b + 1) * m], geo.part(b * m, (b + 1) * m))
            if step % every == 0 or step == steps:
                net_stats = {} if stack.net is None else stack.net.recorded(dt)
                for b, log in enumerate(logs):
                    rows = slice(b * m, (b + 1) * m)
                    log.record(step, step * dt, q[rows], p[rows], u[rows], state,
                               stack.agents.informed[rows], step == steps,
                               **stack.extra(rows), **net_stats)
            if step == steps:
                break
            if stack.net is None:
                evaluate_state(law, step, range(m), lambda: advance_state(
                    law, q, p, state, stack.agents, dt, lambda: pair_sums(law, q, p, edges),
                    step * dt))
            else:
                evaluate_state(law, step, range(m), lambda: stack.net.advance_state(
                    None, q, p, stack.agents, dt, step * dt))
            stack.advance(u, dt, intrinsic)
            advance_leader(leader, dt, step, sc.dim)
            now = time.monotonic()
            if progress is not None and now - last >= progress_every:
                last = now
                rate = (step + 1) / max(now - started, 1e-9)
                latest = logs[0].latest
                stacked = f'  {len(logs)} stacked' if len(stack.scenarios) > 1 else ''
                progress(f'[sim] t = {(step + 1) * dt:.2f}/{sc.duration:g} s  '
                         f'step {step + 1}/{steps}  {progress_text(latest, sc.headline)}  '
                         f'({rate:.0f} steps/s){stacked}')
    except KeyboardInterrupt:
        stack.finish('interrupted', step)
        return
    except RunFault as fault:
        # A fault of the law or the leader model: every realisation meets it (one stack).
        stack.finish('failed', step, fault.line)
        return
    stack.finish('completed', step)


def build_summary(sc: Scenario, real: Realization, series: dict, run: RunMetrics,
                  step: int, status: str, **given) -> dict:
    """Return the ``summary.json`` mapping from the last recorded instant and the run totals.

    The keys, their order and their values are those of the table of summary keys
    (:data:`flock_swarm.core.summary.SUMMARY_KEYS`).

    :param sc: the scenario.
    :param real: its realisation.
    :param series: the recorded time series.
    :param run: the whole-run metrics.
    :param step: the last step reached.
    :param status: ``completed``, ``interrupted``, ``diverged`` or ``failed``.
    :param given: the keys a front end gives (``wall_time_s``...), written in their place.
    :return: the summary (the keys of ``docs/outputs.md``, provenance included).
    """
    return summary_of(SummaryInputs(run_facts(sc, real), series, run, step, status), **given)


def run_facts(sc: Scenario, real: Realization) -> RunFacts:
    """Return what a summary says about a scenario's run besides its series (:class:`RunFacts`).

    :param sc: the scenario.
    :param real: its realisation (the pseudo-leader certificate).
    """
    return RunFacts(sc.n_agents, sc.dt, sc.eta_tolerance, sc.collision_distance, sc.name,
                    sc.seed, sc.law.name, real.selection, sc.law.state_summary)
