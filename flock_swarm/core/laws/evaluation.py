"""The evaluation of a law (:mod:`flock_swarm.core.laws.base`): over a swarm, a group, one agent.

:func:`swarm_control` evaluates a law on an undirected edge list (each pair once, using
antisymmetry where the law has it); :func:`group_control` evaluates it for a subset of the
agents (the one agent of an agent node, or the agents a container hosts) from the edges
that touch them; :func:`local_control` evaluates it for one agent and a list of its
neighbours' states. All three call the same ``pair`` and ``combine`` and check the shapes
of what they return at every step (:class:`~flock_swarm.core.errors.PluginError`, one line
naming the law); :func:`antisymmetry_problem` checks a law's ``antisymmetric`` claim on
random states when a scenario loads it. :func:`state_rates` and :func:`advance_state` step
a law's adaptive state.
"""

import dataclasses
from typing import Callable

import numpy as np

from flock_swarm.core.errors import PluginError
from flock_swarm.core.graphs import EdgeList
from flock_swarm.core.laws.base import AgentData, Law, accepted
from flock_swarm.core.leaders.base import LeaderState

#: States :func:`antisymmetry_problem` evaluates ``pair`` on, and the relative deviation it
#: accepts (rounding: the built-in laws are antisymmetric to the last bit).
ANTISYMMETRY_SAMPLES = 64
ANTISYMMETRY_RTOL = 1e-9


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
