"""The three questions every study over seeds answers apart, and eta as a curve.

A single number at one instant (eta, the fraction of agents within a tolerance of the
leader's velocity at ``t_final``) mixes three different failures: the flock may have broken
into pieces, the whole flock may trail the leader, or the flock may follow the leader while
some agents still wobble around its velocity. Each run's record therefore answers

1. **Is the flock whole?** ``whole_largest``: the fraction of agents in the largest connected
   component of the interaction graph at ``t_final``; ``whole_linked``: the fraction sharing a
   component with an informed agent (Su, Wang, Lin 2009, Theorem 1 (ii): exactly these reach
   the leader's velocity).
2. **Does it move with the leader?** ``group_velocity_error``: ``||mean_i p_i - p_gamma||`` at
   ``t_final`` [m/s], the velocity error of the group's mean (a group that trails the leader
   shows here, one that only disagrees within itself does not).
3. **Do the agents agree with the leader?** eta at the tolerances :data:`TOLERANCES`
   (``eta_at_<tol>``) at ``t_final``, and eta at the scenario's tolerance at the fractions
   :data:`TIMES` of the run (``eta_t<percent>``): a curve over tolerances and over time, so a
   reader sees whether a verdict sits on an edge.

The numbers come from the run's recorded time series (``timeseries.npz``'s arrays) and the
scenario: nothing here runs a simulation.
"""

import numpy as np

from flock_swarm.core.graphs import components, disk_graph, fixed_graph
from flock_swarm.core.scenario import Scenario, realize

#: The velocity tolerances [m/s] of the eta curve (the issue's 0.02-0.5 m/s).
TOLERANCES = (0.02, 0.05, 0.1, 0.2, 0.5)
#: The instants of the eta-over-time curve, as fractions of the run.
TIMES = (0.5, 2.0 / 3.0, 5.0 / 6.0, 1.0)
#: The keys of the whole / with-leader answers (in the records and the report's columns).
WHOLE_KEYS = ('whole_largest', 'whole_linked')
LEADER_KEY = 'group_velocity_error'


def tolerance_key(tolerance: float) -> str:
    """Return the record key of eta at ``tolerance`` (``eta_at_0.05``)."""
    return f'eta_at_{tolerance:g}'


def time_key(fraction: float) -> str:
    """Return the record key of eta at a fraction of the run (``eta_t67``)."""
    return f'eta_t{round(100 * fraction)}'


def question_keys() -> tuple[str, ...]:
    """Return every key :func:`three_questions` writes, in the report's order."""
    return (*WHOLE_KEYS, LEADER_KEY, *(tolerance_key(t) for t in TOLERANCES),
            *(time_key(f) for f in TIMES))


def interaction_components(sc: Scenario, q: np.ndarray) -> np.ndarray:
    """Return the component label of every agent in the scenario's interaction graph at
    positions ``q``: the r-disk graph, or the scenario's fixed graph (Zhou 2012, Yu 2010's
    fixed topologies)."""
    if sc.graph_type != 'disk':
        adjacency = realize(sc).adjacency
        if adjacency is not None:
            return components(fixed_graph(adjacency))[1]
    return components(disk_graph(q, sc.law.radius, sc.law.strict_radius))[1]


def eta_at(p: np.ndarray, leader_p: np.ndarray, tolerance: float) -> float:
    """Return the fraction of agents with ``||p_i - p_gamma|| <= tolerance``.

    :param p: velocities ``(n, dim)``.
    :param leader_p: the leader's velocity ``(dim,)``.
    :param tolerance: [m/s].
    """
    return float(np.mean(np.linalg.norm(p - leader_p, axis=-1) <= tolerance))


def three_questions(sc: Scenario, series: dict) -> dict:
    """Return the answers of one run to the three questions (see the module).

    :param sc: the run's scenario.
    :param series: its recorded time series: ``t``, ``q``, ``p`` (K x N x dim), ``leader_p``
        (K x dim) and ``informed`` (K x N).
    :return: ``{key: value}`` for :func:`question_keys`.
    """
    q, p, leader_p = series['q'][-1], series['p'][-1], series['leader_p'][-1]
    n = q.shape[0]
    labels = interaction_components(sc, q)
    informed = np.asarray(series['informed'][0], dtype=bool)
    out = {'whole_largest': float(np.bincount(labels).max() / n),
           'whole_linked': float(np.isin(labels, np.unique(labels[informed])).sum() / n)
           if informed.any() else 0.0,
           LEADER_KEY: float(np.linalg.norm(p.mean(axis=0) - leader_p))}
    for tol in TOLERANCES:
        out[tolerance_key(tol)] = eta_at(p, leader_p, tol)
    t = series['t']
    for fraction in TIMES:
        # The last recorded instant at or before the fraction of the run.
        k = int(np.searchsorted(t, t[-1] * fraction + 1e-9, side='right')) - 1
        out[time_key(fraction)] = eta_at(series['p'][max(k, 0)], series['leader_p'][max(k, 0)],
                                         sc.eta_tolerance)
    return out
