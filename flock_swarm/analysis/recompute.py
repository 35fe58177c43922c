"""The metrics of a run rebuilt from a bag, recomputed as the world node computes them.

:func:`recompute` replays the recorded states through :class:`flock_swarm.core.run.RunLog`
(the code ``sim`` and the world use: :func:`flock_swarm.core.metrics.step_metrics`,
:class:`flock_swarm.core.metrics.RunMetrics`); :func:`summarize` builds the run's
``summary.json`` from them, the world's summary for the same run.
"""

import numpy as np

from flock_swarm import __version__
from flock_swarm.analysis.bagrun import Progress, RunData, Ticker
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.metrics import STEP_METRICS, RunMetrics
from flock_swarm.core.run import RunLog, build_summary
from flock_swarm.core.scenario import realize


def recompute(run: RunData, record_every: int | None = None,
              progress: Progress | None = None) -> tuple[dict[str, np.ndarray], RunMetrics]:
    """Recompute the metrics of every step as the world node does, and the time series.

    Every complete step updates the whole-run metrics from its r-disk edges
    (:meth:`RunMetrics.update_from_edges`: minimum distance, collision pairs); every
    ``record_every``-th step and the last are recorded with :func:`step_metrics`, exactly as
    in ``WorldStepper.observe`` (and ``sim`` for r-disk scenarios).

    :param run: the run.
    :param record_every: subsampling of the series (default: the scenario's).
    :param progress: called with a line every few seconds.
    :return: the series (the arrays of ``timeseries.npz``) and the whole-run metrics.
    """
    log = RunLog(run.eta_tolerance, run.collision_distance, run.radius, run.strict_radius,
                 record_every or run.record_every)
    last = len(run.steps) - 1
    tick = Ticker(progress)
    # The non-finite commands counted so far, per agent, recorded as the world records them.
    non_finite = None if run.non_finite_at is None else np.zeros(run.n_agents, dtype=int)
    for row, k in enumerate(run.steps):
        q, p = run.q[row], run.p[row]
        leader = LeaderState(run.leader_q[row], run.leader_p[row], run.leader_a[row])
        extra = {}
        if non_finite is not None:
            non_finite[run.non_finite_at.get(int(k), [])] += 1
            extra['non_finite_commands'] = non_finite.copy()
        log.observe(int(k), float(run.t[row]), q, p, run.u[row], leader, run.informed,
                    disk_graph(q, run.radius, run.strict_radius), run.radius, row == last,
                    **extra)
        tick(lambda: f'[analyze] metrics: step {row + 1}/{last + 1}')
    return log.rec.arrays(), log.metrics


def _status(run: RunData) -> str:
    if run.scenario is not None and run.steps[-1] >= run.scenario.steps:
        return 'completed'
    if run.warning is not None:
        return 'truncated'
    return 'interrupted' if run.scenario is not None else 'completed'


def summarize(run: RunData, series: dict[str, np.ndarray], metrics: RunMetrics) -> dict:
    """Return ``summary.json``: the world's summary for the same run, from the bag.

    :param run: the run.
    :param series: its recomputed series.
    :param metrics: its whole-run metrics.
    :return: the keys of ``docs/outputs.md``, provenance, the world's ``mode`` and
        missed-command counts, and where the data came from (``bag``, ``complete_steps``,
        ``bag_warning``).
    """
    status = _status(run)
    last_step = int(run.steps[-1])
    if run.scenario is not None:
        summary = build_summary(run.scenario, realize(run.scenario), series, metrics,
                                last_step, status)
    else:
        final = {name: float(series[f'metric_{name}'][-1]) for name in STEP_METRICS}
        summary = {
            'n_agents': run.n_agents, 't_final': float(series['t'][-1]), 'steps': last_step,
            'eta': final['eta'], 'eta_tolerance': run.eta_tolerance,
            'velocity_mismatch_max': final['velocity_mismatch_max'],
            'com_position_error': final['com_position_error'],
            'com_velocity_error': final['com_velocity_error'],
            'min_pair_distance': metrics.min_pair_distance,
            'collisions': len(metrics.collision_pairs),
            'collision_distance': run.collision_distance,
            'components_final': int(final['components']),
            'informed': [int(i) for i in np.flatnonzero(run.informed)],
            'scenario': None, 'seed': None, 'protocol': None, 'dt': run.dt, 'status': status,
            'flock_swarm_version': __version__,
        }
    summary.update({
        'mode': run.mode,
        'missed_commands': int(sum(run.missed_commands_per_agent)),
        'missed_commands_per_agent': run.missed_commands_per_agent,
        **({} if run.non_finite_at is None else {
            'non_finite_commands_per_agent': [int(x) for x in np.bincount(
                [i for ids in run.non_finite_at.values() for i in ids],
                minlength=run.n_agents)]}),
        'leader_missed': run.leader_missed,
        'bag': str(run.bag),
        'complete_steps': int(len(run.steps)),
        'bag_warning': run.warning,
    })
    return summary
