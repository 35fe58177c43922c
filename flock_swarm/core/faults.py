"""Faults of a law or a leader model during a run, each told as one line.

A law or a leader model from a plugin is code this package has never seen: mid-run it may
raise, return an array of the wrong shape, or return values that are not finite. The start
checks (:func:`flock_swarm.core.run.check_law_output`) evaluate it once, at the initial
state; these helpers guard every later evaluation, in ``sim`` (:mod:`flock_swarm.core.run`)
and in the nodes (the agents' :class:`~flock_swarm.nodes.controller.AgentController`, the
leader node), so that both tell the same fault with the same line: the component (its entry
point), the agent and the step. :class:`RunFault` carries it; the run ends with status
``failed``.

A non-finite command is the law's fault when the state it was given is plausible; when the
state has grown beyond the nodes' input limits (it is blowing up: ``dt`` beyond a stability
bound), the run has diverged instead (:func:`state_blew_up`).
"""

from typing import Callable, Sequence

import numpy as np

from flock_swarm.core.errors import PluginError, one_line
from flock_swarm.core.laws.base import Law
from flock_swarm.core.laws.evaluation import shape_problem
from flock_swarm.core.leaders.base import LeaderModel, LeaderState, VirtualLeader
from flock_swarm.core.registry import LAW_GROUP, LEADER_GROUP, entries

#: The nodes' default input limits (``max_abs_position``, ``max_abs_velocity`` in
#: ``nodes/guard.py``): beyond them a state is no plausible swarm, and a law that overflows
#: on it has met a diverging run, not a fault of its own.
PLAUSIBLE_POSITION = 1e6
PLAUSIBLE_VELOCITY = 1e4
#: Agents a fault line names before ``(and K more)``.
NAMED_AGENTS = 5

#: Kinds of fault (the ``kind`` of :class:`RunFault`, and of a node's fault report).
RAISED, SHAPE, NON_FINITE = 'raised', 'shape', 'non_finite'


class RunFault(Exception):
    """A law or leader model failed during a run; ``str()`` is the one line telling it.

    :ivar line: the line (component, what went wrong, the agents, the step).
    :ivar kind: :data:`RAISED`, :data:`SHAPE` or :data:`NON_FINITE`.
    :ivar agents: the agents concerned (empty for the leader model, or when not known).
    :ivar step: the step.
    """

    def __init__(self, line: str, kind: str, step: int, agents: Sequence[int] = ()) -> None:
        """Create the fault (see the class)."""
        super().__init__(line)
        self.line, self.kind, self.step = line, kind, int(step)
        self.agents = tuple(int(i) for i in agents)


def law_label(law: Law) -> str:
    """Return how a fault names a law: ``law flock_swarm.laws:NAME (module:Class)``."""
    entry = entries(LAW_GROUP).get(law.name)
    return f'law {entry.label if entry is not None else law.name}'


def leader_label(model: LeaderModel) -> str:
    """Return how a fault names a leader model: ``leader model flock_swarm.leaders:NAME (...)``."""
    entry = entries(LEADER_GROUP).get(model.name)
    return f'leader model {entry.label if entry is not None else model.name}'


def agents_text(agents: Sequence[int]) -> str:
    """Return ``agent 3`` or ``agents 3, 5, 8 (and 2 more)``."""
    agents = [int(i) for i in agents]
    if len(agents) == 1:
        return f'agent {agents[0]}'
    named = ', '.join(str(i) for i in agents[:NAMED_AGENTS])
    more = len(agents) - NAMED_AGENTS
    return f'agents {named}' + (f' (and {more} more)' if more > 0 else '')


def evaluate_law(law: Law, step: int, ids: Sequence[int], dim: int,
                 evaluate: Callable[[], np.ndarray],
                 locate: Callable[[int], np.ndarray] | None = None) -> np.ndarray:
    """Return ``evaluate()``, the law's commands of the agents ``ids``, checked.

    :param law: the law.
    :param step: the step evaluated.
    :param ids: the agents evaluated, in the order of the rows.
    :param dim: the scenario's dimension.
    :param evaluate: computes the commands, shape ``(len(ids), dim)``.
    :param locate: evaluates the law for the agent of one row alone (given the row): after
        an exception it finds the first agent whose evaluation raises too, for the line
        (``None``: the line names every agent of ``ids``).
    :return: the commands (rows may be non-finite: see :func:`non_finite_rows`).
    :raises RunFault: when the law raised, or returned no array of shape ``(len(ids), dim)``.
    """
    try:
        u = evaluate()
    except PluginError as exc:
        # The law's evaluation checks each output's shape at every step (core/laws/evaluation.py):
        # its line (key, law, hook, time) stays whole.
        raise RunFault(f'{law_label(law)}: {exc} (step {step})', SHAPE, step, ids) from None
    except Exception as exc:  # noqa: BLE001 - whatever a plugin raises is reported
        agents = _first_raising(ids, locate) or list(ids)
        raise RunFault(f'{law_label(law)} raised {type(exc).__name__} at step {step} '
                       f'({agents_text(agents)}): {one_line(str(exc))}', RAISED, step,
                       agents) from None
    if not isinstance(u, np.ndarray) or u.shape != (len(ids), dim):
        problem = shape_problem(law, 'combine()', u, (len(ids), dim))
        raise RunFault(f'{law_label(law)}: {unnamed(law, problem)} at step {step}', SHAPE, step,
                       ids)
    return u


def unnamed(law: Law, reason: str) -> str:
    """Return a law's error without the law's name in front (the entry point names it)."""
    prefix = f'{law.name}: '
    return reason[len(prefix):] if reason.startswith(prefix) else reason


def _first_raising(ids: Sequence[int], locate: Callable[[int], np.ndarray] | None) -> list[int]:
    """Return ``[i]``, the first agent of ``ids`` whose evaluation alone raises, or ``[]``."""
    if locate is None:
        return []
    for row, i in enumerate(ids):
        try:
            locate(row)
        except Exception:  # noqa: BLE001 - the agent that raises is the answer
            return [int(i)]
    return []


def evaluate_state(law: Law, step: int, ids: Sequence[int], advance: Callable[[], None]) -> None:
    """Advance a law's adaptive state (``advance()``), telling an exception as a fault.

    :raises RunFault: when the law's ``state_rate`` raised.
    """
    try:
        advance()
    except PluginError as exc:
        raise RunFault(f'{law_label(law)}: {exc} (step {step})', SHAPE, step, ids) from None
    except Exception as exc:  # noqa: BLE001 - whatever a plugin raises is reported
        raise RunFault(f'{law_label(law)}: state_rate() raised {type(exc).__name__} at step '
                       f'{step} ({agents_text(ids)}): {one_line(str(exc))}', RAISED, step,
                       ids) from None


def non_finite_rows(u: np.ndarray) -> np.ndarray:
    """Return the mask of the rows of ``u`` that are not finite."""
    return ~np.isfinite(u).all(axis=1)


def non_finite_fault(law: Law, step: int, agents: Sequence[int]) -> RunFault:
    """Return the fault of a law that gave the ``agents`` non-finite commands at ``step``."""
    return RunFault(f'{law_label(law)} returned a non-finite command at step {step} '
                    f'({agents_text(agents)})', NON_FINITE, step, agents)


def state_blew_up(q: np.ndarray, p: np.ndarray, leader: LeaderState | None = None) -> bool:
    """Return whether the swarm's (or the leader's) state is beyond any plausible run.

    A law that returns non-finite commands for such a state met a diverging run
    (:data:`PLAUSIBLE_POSITION`, :data:`PLAUSIBLE_VELOCITY`).
    """
    parts = [(q, PLAUSIBLE_POSITION), (p, PLAUSIBLE_VELOCITY)]
    if leader is not None:
        parts += [(leader.q, PLAUSIBLE_POSITION), (leader.p, PLAUSIBLE_VELOCITY)]
    return any(not (np.abs(x) <= bound).all() for x, bound in parts)


def leader_state(leader: VirtualLeader, step: int, dim: int) -> LeaderState:
    """Return the leader's state at ``step``, its model's acceleration checked.

    :param leader: the virtual leader.
    :param step: its step (for the line).
    :param dim: the scenario's dimension.
    :return: the state (non-finite when the leader's integration overflowed: a diverged
        run, not a fault of the model).
    :raises RunFault: when the model raised, or returned an acceleration that is no array
        of shape ``(dim,)``, or a non-finite one at a finite state.
    """
    try:
        state = leader.state
    except Exception as exc:  # noqa: BLE001 - whatever a plugin raises is reported
        raise leader_raised(leader.model, step, exc) from None
    a = state.a
    fault = _shape_fault(leader.model, a, step, dim)
    if fault is not None:
        raise fault
    if not np.isfinite(a).all() and np.isfinite(state.q).all() and np.isfinite(state.p).all():
        raise RunFault(f'{leader_label(leader.model)}: acceleration() returned a non-finite '
                       f'value at step {step}', NON_FINITE, step)
    return state


def advance_leader(leader: VirtualLeader, dt: float, step: int, dim: int) -> None:
    """Advance the leader by ``dt`` from ``step``, telling an exception of its model.

    RK4 evaluates the model between the steps too; an acceleration of the wrong shape there
    makes the integration itself raise (or, for shape ``(1,)``, broadcast), so after an
    exception the model is asked again at the step's times: a wrong shape is told as such.

    :param leader: the virtual leader.
    :param dt: the step [s].
    :param step: the step advanced from.
    :param dim: the scenario's dimension.
    :raises RunFault: when the model raised or returned the wrong shape.
    """
    try:
        leader.step(dt)
    except Exception as exc:  # noqa: BLE001 - whatever a plugin raises is reported
        fault = None
        try:
            state = leader.state
            for k, t in ((step, step * dt), (step + 1, (step + 1) * dt)):
                fault = fault or _shape_fault(
                    leader.model, leader.model.acceleration(t, state.q, state.p), k, dim)
        except Exception:  # noqa: BLE001 - then the exception above is the fault
            pass
        raise fault or leader_raised(leader.model, step, exc) from None


def _shape_fault(model: LeaderModel, a, step: int, dim: int) -> RunFault | None:
    """Return the fault of an acceleration ``a`` that is no array of shape ``(dim,)``."""
    if isinstance(a, np.ndarray) and a.shape == (dim,):
        return None
    got = f'shape {a.shape}' if isinstance(a, np.ndarray) else type(a).__name__
    return RunFault(f'{leader_label(model)}: acceleration() returned {got} at step {step}, '
                    f'not shape {(dim,)}', SHAPE, step)


def leader_raised(model: LeaderModel, step: int, exc: Exception) -> RunFault:
    """Return the fault of a leader model that raised ``exc`` at ``step``."""
    return RunFault(f'{leader_label(model)} raised {type(exc).__name__} at step {step}: '
                    f'{one_line(str(exc))}', RAISED, step)
