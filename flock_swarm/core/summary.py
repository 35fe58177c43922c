"""The keys of ``summary.json``: one table, from which every list of them is derived.

:data:`SUMMARY_KEYS` holds one :class:`SummaryKey` per key, in the order ``summary.json``
writes them: its kind, its meaning (``docs/outputs.md`` lists the same keys), how the core
computes it (or that a front end gives it), whether a sweep can collect it and at which
recorded series, and whether a comparison of a ROS run with ``sim`` skips it. From the table:

- :func:`summary_of` writes a summary (``sim``, the world node and ``analyze`` through
  :func:`flock_swarm.core.run.build_summary`);
- :func:`sweep_metrics`, :func:`timed_series` and :func:`default_metrics` are what a sweep
  spec may collect (:mod:`flock_swarm.study.spec`);
- :func:`sim_only_keys` are the keys a comparison with ``sim`` leaves out.

A new summary key is one new row here (and its line in ``docs/outputs.md``, which a test
compares with this table).

The module imports only the standard library when it is imported (NumPy when a summary is
written), so the pytest plugin :mod:`flock_swarm.testing` reads the table at no cost.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping

from flock_swarm import __version__

if TYPE_CHECKING:  # pragma: no cover - types only, kept out of the import (see above)
    import numpy as np

    from flock_swarm.core.metrics import RunMetrics
    from flock_swarm.core.pseudo_leaders import PseudoLeaderSelection

#: A metric of the last recorded instant (``t_final``).
FINAL = 'final'
#: A metric over the whole run.
WHOLE_RUN = 'whole-run'
#: The size and length of the run, and the settings its metrics were taken with.
RUN_SETTING = 'setting'
#: Where the run came from and how it ended.
PROVENANCE = 'provenance'
#: The final value of a law's adaptive state (``Law.state_summary``).
LAW_STATE = 'law state'
#: The bookkeeping of a ROS run (world node) or of its analysis (``analyze``).
BOOKKEEPING = 'bookkeeping'
KINDS = (FINAL, WHOLE_RUN, RUN_SETTING, PROVENANCE, LAW_STATE, BOOKKEEPING)

#: Who writes a key: ``sim``, the ``world`` node, ``analyze`` of a bag.
SIM, WORLD, ANALYZE = 'sim', 'world', 'analyze'
EVERY_RUN = (SIM, WORLD, ANALYZE)

#: What a value function returns for a key the run has nothing to say about.
ABSENT = object()


@dataclass(frozen=True)
class RunFacts:
    """What a summary says about a run besides its recorded series and whole-run metrics.

    :ivar n_agents: the number of agents.
    :ivar dt: the step [s].
    :ivar eta_tolerance: the velocity tolerance of ``eta``.
    :ivar collision_distance: pairs closer than it collide.
    :ivar scenario: the scenario's name (``None``: unknown, a bag without its scenario).
    :ivar seed: the seed (``None``: unknown).
    :ivar protocol: the law's name (``None``: unknown).
    :ivar selection: the pseudo-leader certificate, when the informed set was chosen by it.
    :ivar law_state: ``{state key: summary key}`` of the law (``Law.state_summary``).
    :ivar informed_known: whether the informed set is known (``False``: a bag without its
        scenario; the summary says ``unknown``, not an empty list).
    """

    n_agents: int
    dt: float
    eta_tolerance: float
    collision_distance: float
    scenario: str | None = None
    seed: int | None = None
    protocol: str | None = None
    selection: PseudoLeaderSelection | None = None
    law_state: Mapping[str, str] = field(default_factory=dict)
    informed_known: bool = True


@dataclass(frozen=True)
class SummaryInputs:
    """Everything a summary is computed from (the argument of :attr:`SummaryKey.value`).

    :ivar facts: the run's size, settings and provenance.
    :ivar series: the recorded time series (``metric_*`` arrays, ``t``, ``informed``...).
    :ivar run: the whole-run metrics.
    :ivar step: the last step reached.
    :ivar status: how the run ended.
    """

    facts: RunFacts
    series: Mapping[str, np.ndarray]
    run: RunMetrics
    step: int
    status: str


@dataclass(frozen=True)
class SummaryKey:
    """One key of ``summary.json``.

    :ivar name: the key.
    :ivar kind: one of :data:`KINDS`.
    :ivar description: its meaning, as ``docs/outputs.md`` gives it.
    :ivar value: computes it from :class:`SummaryInputs` (:data:`ABSENT`: not written for
        this run); ``None``: a front end gives it (:func:`summary_of`'s ``given``).
    :ivar sweep: whether a sweep spec may collect it (a scalar).
    :ivar default: whether a sweep collects it when its spec names no metrics.
    :ivar series: the recorded series holding it per instant (a sweep collects it at
        given times too), or ``None``.
    :ivar sim_only: whether it describes the simulator rather than the swarm's run (its
        wall time, its own count): a comparison of a ROS run with ``sim`` skips it.
    :ivar writers: who writes it (``sim``, ``world``, ``analyze``).
    """

    name: str
    kind: str
    description: str
    value: Callable[[SummaryInputs], Any] | None = None
    sweep: bool = False
    default: bool = False
    series: str | None = None
    sim_only: bool = False
    writers: tuple[str, ...] = EVERY_RUN


def _final(series: str, cast: type = float) -> Callable[[SummaryInputs], Any]:
    """Return the value function of a metric at the last recorded instant (null when the
    run recorded none: a world stopped before its first step)."""
    return lambda x: cast(x.series[series][-1]) if x.series else None


def _informed(x: SummaryInputs) -> list[int] | str | None:
    import numpy as np
    if not x.facts.informed_known:
        return 'unknown'
    if not x.series:
        return None
    return [int(i) for i in np.flatnonzero(x.series['informed'][0])]


def _certificate(x: SummaryInputs) -> Any:
    sel = x.facts.selection
    if sel is None:
        return ABSENT
    return {'lambda_max': sel.lambda_max, 'alpha': sel.alpha, 'satisfied': sel.satisfied,
            'components': sel.components}


def _network(series: str, reduce: str) -> Callable[[SummaryInputs], Any]:
    """Return the value function of a network statistic from its recorded series.

    Absent without a ``network:`` section; ``None`` when no recorded instant had a value
    (no link used, no message sent).
    """
    def value(x: SummaryInputs) -> Any:
        import numpy as np
        if series not in x.series:
            return ABSENT
        values = np.asarray(x.series[series], dtype=float)
        values = values[np.isfinite(values)]
        if not values.size:
            return None
        return float(values.max() if reduce == 'max' else values.mean())
    return value


def _obstacles(name: str) -> Callable[[SummaryInputs], Any]:
    """Return the value function of a whole-run obstacle metric (absent without obstacles;
    null when no instant was measured)."""
    def value(x: SummaryInputs) -> Any:
        found = getattr(x.run, 'obstacles', None)
        if found is None:
            return ABSENT
        if name == 'clearance_min':
            return found.clearance_min if found.clearance_min != float('inf') else None
        return len(getattr(found, name))
    return value


_K = SummaryKey
#: Every key of ``summary.json``, in the order it is written.
SUMMARY_KEYS: tuple[SummaryKey, ...] = (
    _K('n_agents', RUN_SETTING, 'number of agents', lambda x: x.facts.n_agents, sweep=True),
    _K('t_final', RUN_SETTING, 'time of the last recorded instant [s]',
       _final('t'), sweep=True),
    _K('steps', RUN_SETTING, 'the last step reached', lambda x: int(x.step), sweep=True),
    _K('eta', FINAL, 'fraction of agents with `||p_i - p_gamma|| <= eta_tolerance` at '
       '`t_final`', _final('metric_eta'), sweep=True, default=True, series='metric_eta'),
    _K('eta_tolerance', RUN_SETTING, 'the velocity tolerance of `eta` [m/s]',
       lambda x: x.facts.eta_tolerance),
    _K('velocity_mismatch_max', FINAL, '`max_i ||p_i - p_gamma||` at `t_final`',
       _final('metric_velocity_mismatch_max'), sweep=True, default=True,
       series='metric_velocity_mismatch_max'),
    _K('com_position_error', FINAL, '`||mean q - q_gamma||` at `t_final`',
       _final('metric_com_position_error'), sweep=True, series='metric_com_position_error'),
    _K('com_velocity_error', FINAL, '`||mean p - p_gamma||` at `t_final`',
       _final('metric_com_velocity_error'), sweep=True, series='metric_com_velocity_error'),
    _K('min_pair_distance', WHOLE_RUN, 'smallest distance between two agents over the whole '
       'run (exact whenever it is below the interaction radius, on a fixed graph below '
       '`collision_distance`, for a law acting on all pairs of an r-disk graph always; '
       'above it, over the recorded steps)', lambda x: x.run.min_pair_distance, sweep=True,
       series='metric_min_pair_distance'),
    _K('collisions', WHOLE_RUN, 'distinct pairs ever closer than `collision_distance`',
       lambda x: len(x.run.collision_pairs), sweep=True, default=True),
    _K('collision_distance', RUN_SETTING, 'pairs closer than it collide [m]',
       lambda x: x.facts.collision_distance),
    _K('components_final', FINAL, 'connected components of the r-disk graph at `t_final`',
       _final('metric_components', int), sweep=True, default=True, series='metric_components'),
    _K('informed', PROVENANCE, 'ids of the informed agents (pseudo-leaders, pinned '
       'observers) at the start', _informed),
    _K('scenario', PROVENANCE, 'the scenario\'s name', lambda x: x.facts.scenario),
    _K('seed', PROVENANCE, 'the seed', lambda x: x.facts.seed),
    _K('protocol', PROVENANCE, 'the law (`protocol.name`)', lambda x: x.facts.protocol),
    _K('dt', RUN_SETTING, 'the step [s]', lambda x: x.facts.dt),
    _K('status', PROVENANCE, '`completed`, `interrupted` (a stop signal: everything up to '
       'then is written; stopped before the first step, the measures are null), `diverged` '
       '(the state stopped being finite; the last finite recorded state is written, exit '
       'status 1) or `failed` (a fault of the law or the leader model, or in a ROS run of a '
       'node, or another process of the run died: everything up to the fault is written, '
       'exit status 1); a ROS run also `recording_failed`, its analysis `truncated`',
       lambda x: x.status),
    _K('failure', PROVENANCE, 'status `failed` or `recording_failed`: the one line telling '
       'the fault (the law or leader model by its entry point, or the node, with the agent '
       'and the step; or the file that could not be written; `analyze`: as the world '
       'recorded it in the bag); absent otherwise'),
    _K('flock_swarm_version', PROVENANCE, 'the package version that ran it',
       lambda x: __version__),
    _K('pseudo_leader_certificate', PROVENANCE, 'Zhou\'s Theorem 1 certificate '
       '`lambda_max(W_{N-m})`, `alpha`, `satisfied`, `components` (when chosen by '
       '`select: pseudo_leaders`)', _certificate),
    _K('adaptive_gain_final', LAW_STATE, 'Zhou\'s adaptive gains `h_i` at `t_final` '
       '(`zhou_pseudo_leader`; a ROS run records them from the agents\' `/agent_<i>/state`)'),
    _K('pseudo_leader_reselections', WHOLE_RUN, 'how often `sim` re-selected the '
       'pseudo-leaders (`reselect: true`)', sweep=True, sim_only=True, writers=(SIM,)),
    _K('network_delivered', WHOLE_RUN, 'with a `network:` section: the fraction of the '
       'agents\' messages not lost (each recorded instant\'s, of the steps since the one '
       'before, averaged)', _network('network_delivered', 'mean'), sweep=True,
       series='network_delivered', writers=(SIM, WORLD, ANALYZE)),
    _K('network_age_mean', WHOLE_RUN, 'with a `network:` section: the mean age [s] of the '
       'neighbour states the law used (each recorded instant\'s, of the steps since the one '
       'before, averaged; in realtime mode the real transport\'s age included: '
       'docs/network.md)', _network('network_age_mean', 'mean'), sweep=True,
       series='network_age_mean', writers=(SIM, WORLD, ANALYZE)),
    _K('network_age_max', WHOLE_RUN, 'with a `network:` section: the largest age [s] of a '
       'neighbour state the law used over the whole run', _network('network_age_max', 'max'),
       sweep=True, series='network_age_max', writers=(SIM, WORLD, ANALYZE)),
    _K('obstacle_clearance_min', WHOLE_RUN, 'with an `obstacles:` section: the smallest '
       'distance [m] from an agent to an obstacle\'s surface over the whole run (negative: an '
       'agent was inside)', _obstacles('clearance_min'), sweep=True,
       series='obstacle_clearance'),
    _K('obstacle_penetrations', WHOLE_RUN, 'with an `obstacles:` section: distinct '
       '(agent, obstacle) pairs with the agent ever inside the obstacle',
       _obstacles('penetrations'), sweep=True),
    _K('obstacle_collisions', WHOLE_RUN, 'with an `obstacles:` section: distinct (agent, '
       'obstacle) pairs ever closer than `collision_distance`', _obstacles('collisions'),
       sweep=True),
    _K('mode', BOOKKEEPING, '`lockstep` or `realtime`', writers=(WORLD, ANALYZE)),
    _K('missed_commands', BOOKKEEPING, 'commands that did not come in time (a zero command '
       'was applied)', writers=(WORLD, ANALYZE)),
    _K('missed_commands_per_agent', BOOKKEEPING, 'the same, per agent',
       writers=(WORLD, ANALYZE)),
    _K('non_finite_commands_per_agent', BOOKKEEPING, 'commands the law gave non-finite, per '
       'agent, as the agent nodes reported them (`swarm/faults`): the first fails the run, '
       'unless the agents run with `non_finite:=zero` (a zero command is applied instead)',
       writers=(WORLD, ANALYZE)),
    _K('rejected_messages', BOOKKEEPING, 'messages the world\'s input guard rejected, by '
       'reason', writers=(WORLD,)),
    _K('leader_events', BOOKKEEPING, 'when the leader was lost and found again',
       writers=(WORLD,)),
    _K('duplicate_agent_ids', BOOKKEEPING, 'agent ids claimed by more than one node',
       writers=(WORLD,)),
    _K('bag_error', BOOKKEEPING, 'why recording failed, or null', writers=(WORLD,)),
    _K('command_latency_ms', BOOKKEEPING, 'realtime mode: latency of the agents\' commands '
       '[ms]', writers=(WORLD,)),
    _K('resent_steps', BOOKKEEPING, 'times a stalled lockstep step was offered again',
       writers=(WORLD,)),
    _K('leader_missed', BOOKKEEPING, 'steps closed without the leader\'s state',
       writers=(WORLD, ANALYZE)),
    _K('wall_time_s', PROVENANCE, 'wall-clock time of the run [s]', sim_only=True,
       writers=(SIM, WORLD)),
    _K('bag', BOOKKEEPING, 'the bag\'s path (null: not recorded)', writers=(WORLD, ANALYZE)),
    _K('robot_contacts', WHOLE_RUN, '`backend: mujoco` (sim\'s and the world\'s): distinct '
       'pairs of robots that touched in the physics engine over the run (absent otherwise)',
       writers=(SIM, WORLD)),
    _K('complete_steps', BOOKKEEPING, 'steps of the bag with every agent\'s state',
       writers=(ANALYZE,)),
    _K('bag_warning', BOOKKEEPING, 'what was wrong with the bag (a cut recording), or null',
       writers=(ANALYZE,)),
    _K('verify_max_position_error', BOOKKEEPING, '`analyze --verify`: largest `|q - q_sim|`',
       writers=(ANALYZE,)),
    _K('verify_max_velocity_error', BOOKKEEPING, '`analyze --verify`: largest `|p - p_sim|`',
       writers=(ANALYZE,)),
    _K('verify_steps_compared', BOOKKEEPING, '`analyze --verify`: steps compared',
       writers=(ANALYZE,)),
    _K('verify_tolerance', BOOKKEEPING, '`analyze --verify`: the accepted deviation',
       writers=(ANALYZE,)),
    _K('verify_passed', BOOKKEEPING, '`analyze --verify`: whether every deviation is within '
       'it', writers=(ANALYZE,)),
)
del _K


def summary_of(inputs: SummaryInputs, **given: Any) -> dict:
    """Return ``summary.json``: every key of :data:`SUMMARY_KEYS` the run has, in order.

    A computed key is written unless its value is :data:`ABSENT`; the law's adaptive state
    (``inputs.facts.law_state``, its final recorded value where it was recorded) goes where
    the table's first :data:`LAW_STATE` row is; a key a front end gives is written when it
    is in ``given``.

    :param inputs: what the summary is computed from.
    :param given: values of the keys without a value function (``wall_time_s=...``).
    :return: the summary.
    :raises KeyError: for a given key the table does not have (add its row).
    """
    unknown = sorted(set(given) - {k.name for k in SUMMARY_KEYS if k.value is None})
    if unknown:
        raise KeyError(f'not a given key of the summary table: {", ".join(unknown)}')
    out: dict[str, Any] = {}
    state_done = False
    for key in SUMMARY_KEYS:
        if key.kind == LAW_STATE:
            if not state_done:
                state_done = True
                for state, name in inputs.facts.law_state.items():
                    # A bag recorded without the agents' state (/agent_<i>/state) gives its
                    # analysis no series of it.
                    if state in inputs.series:
                        out[name] = [float(x) for x in inputs.series[state][-1]]
            continue
        if key.value is None:
            if key.name in given:
                out[key.name] = given[key.name]
            continue
        value = key.value(inputs)
        if value is not ABSENT:
            out[key.name] = value
    return out


def with_failure(summary: Mapping[str, Any], status: str, line: str) -> dict:
    """Return ``summary`` with ``status`` and the line telling the failure (``failure``, in
    its place: after ``status``).

    :param summary: a summary (:func:`summary_of`).
    :param status: the run's status (``failed``, ``recording_failed``).
    :param line: why.
    """
    out: dict[str, Any] = {}
    for key, value in summary.items():
        if key != 'failure':
            out[key] = status if key == 'status' else value
        if key == 'status':
            out['failure'] = line
    return out


def _is_measure(key: SummaryKey) -> bool:
    return key.kind in (FINAL, WHOLE_RUN) and key.value is not None


def sweep_metrics() -> tuple[str, ...]:
    """Return the keys a sweep may collect: the run's measures, then its size and counts."""
    keys = [k for k in SUMMARY_KEYS if k.sweep]
    return tuple(k.name for k in sorted(keys, key=lambda k: not _is_measure(k)))


def timed_series() -> dict[str, str]:
    """Return ``{key: series}`` of the sweep metrics also recorded at every instant."""
    return {k.name: k.series for k in SUMMARY_KEYS if k.sweep and k.series is not None}


def default_metrics() -> tuple[str, ...]:
    """Return the metrics a sweep collects when its spec names none."""
    return tuple(k.name for k in SUMMARY_KEYS if k.default)


def sim_only_keys() -> tuple[str, ...]:
    """Return the keys that describe the simulator, not the run (a comparison skips them)."""
    return tuple(k.name for k in SUMMARY_KEYS if k.sim_only)


def compared_metrics() -> tuple[str, ...]:
    """Return the run's measures (final-step and whole-run metrics the core computes)."""
    return tuple(k.name for k in SUMMARY_KEYS if _is_measure(k))
