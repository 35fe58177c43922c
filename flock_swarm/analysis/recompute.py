"""The metrics of a run rebuilt from a bag, recomputed as the world node computes them.

:func:`recompute` replays the recorded states through :class:`flock_swarm.core.run.RunLog`
(the code ``sim`` and the world use: :func:`flock_swarm.core.metrics.step_metrics`,
:class:`flock_swarm.core.metrics.RunMetrics`); :func:`summarize` builds the run's
``summary.json`` from them, the world's summary for the same run.
"""

import numpy as np

from flock_swarm.analysis.bagrun import Progress, RunData, Ticker
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.metrics import RunMetrics
from flock_swarm.core.network_stats import STATISTICS, Tally
from flock_swarm.core.run import LinkObserver, RunLog, observed_pairs, run_facts, static_graph
from flock_swarm.core.scenario import realize
from flock_swarm.core.summary import RunFacts, SummaryInputs, summary_of


def recompute(run: RunData, record_every: int | None = None,
              progress: Progress | None = None) -> tuple[dict[str, np.ndarray], RunMetrics]:
    """Recompute the metrics of every step as the world node does, and the time series.

    Every complete step updates the whole-run metrics from the pairs ``sim`` and the world
    take them from (:func:`~flock_swarm.core.run.observed_pairs`; the r-disk edges for a bag
    without a scenario) (:meth:`RunMetrics.update_from_edges`: minimum distance, collision
    pairs); every ``record_every``-th step and the last are recorded with
    :func:`step_metrics`, with the law's adaptive state, exactly as in
    ``WorldStepper.observe`` (and ``sim``), a robot plant's recorded state with them
    (``plant_state``, the unicycle's ``heading``). With a ``network:`` section the statistics of
    the agents' links are recorded too: recounted as the world counts them for a lockstep
    run (:class:`~flock_swarm.core.run.LinkObserver`, ``sim``'s), and for a realtime run
    taken from ``/swarm/metrics`` (the world measured them: each recorded instant has the
    latest message's since the one recorded before, NaN without one).

    :param run: the run.
    :param record_every: subsampling of the series (default: the scenario's).
    :param progress: called with a line every few seconds.
    :return: the series (the arrays of ``timeseries.npz``) and the whole-run metrics.
    """
    sc = run.scenario
    # The obstacles come with the bag's scenario (the world records it at t = 0).
    log = RunLog(run.eta_tolerance, run.collision_distance, run.radius, run.strict_radius,
                 record_every or run.record_every,
                 obstacles=sc.obstacles if sc is not None else None)
    # The row recorded whatever record_every says: the last complete one, except in a sound
    # bag of a run stopped before its end (interrupted, failed), where the world records its
    # last step only when it falls on record_every, so its summary's t_final and final
    # metrics are those of its last recorded instant: the same here.
    last = len(run.steps) - 1
    if sc is not None and not run.recovered and run.steps[-1] < sc.steps:
        last = -1
    tick = Ticker(progress)
    real = realize(sc) if sc is not None else None
    static = static_graph(sc, real) if sc is not None else None
    # The non-finite commands counted so far, per agent, recorded as the world records them.
    non_finite = None if run.non_finite_at is None else np.zeros(run.n_agents, dtype=int)
    network = sc is not None and sc.network.active
    observer = LinkObserver(sc, real, static) if network and run.mode != 'realtime' else None
    tally, told = Tally(), None
    observed = run.steps if run.last_observed else run.steps[:-1]
    for row, k in enumerate(observed):
        q, p = run.q[row], run.p[row]
        leader = LeaderState(run.leader_q[row], run.leader_p[row], run.leader_a[row])
        covered, radius = disk_graph(q, run.radius, run.strict_radius), run.radius
        if sc is not None:
            covered, radius = observed_pairs(sc, real, q, static, covered)
        extra = {key: values[row] for key, values in run.state.items()}
        if non_finite is not None:
            non_finite[run.non_finite_at.get(int(k), [])] += 1
            extra['non_finite_commands'] = non_finite.copy()
        if network:
            if observer is not None:
                tally.add(observer.step(int(k), q, p))
            told = run.network_at.get(int(k), told)
            if k % log.every == 0 or row == last:
                nan = dict.fromkeys(STATISTICS, np.nan)
                extra.update(tally.take(run.dt) if observer is not None else told or nan)
                told = None
        if run.plant_state is not None and (k % log.every == 0 or row == last):
            # The plant's state as sim and the world record it (the unicycle's heading too).
            extra.update(sc.plant.model.recorded(run.plant_state[row]))
        log.observe(int(k), float(run.t[row]), q, p, run.u[row], leader, run.informed,
                    covered, radius, row == last, **extra)
        tick(lambda: f'[analyze] metrics: step {row + 1}/{len(run.steps)}')
    return log.rec.arrays(), log.metrics


def _status(run: RunData) -> str:
    # A cut file is `truncated` even when every step survived (cut after its data section:
    # only the index is lost), as docs/analysis.md says: the bag is not as the world wrote it.
    if run.recovered:
        return 'truncated'
    if run.end is not None and run.end.get('status'):
        # The world recorded how its run ended (failed with its line, interrupted...).
        return run.end['status']
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
    facts = (run_facts(run.scenario, realize(run.scenario)) if run.scenario is not None
             else RunFacts(run.n_agents, run.dt, run.eta_tolerance, run.collision_distance,
                           informed_known=run.informed_known))
    counted = {} if run.non_finite_at is None else {
        'non_finite_commands_per_agent': [int(x) for x in np.bincount(
            [i for ids in run.non_finite_at.values() for i in ids],
            minlength=run.n_agents)]}
    status = _status(run)
    if run.end is not None and status == run.end.get('status') and 'failure' in run.end:
        # The world's line, as its summary has it.
        counted['failure'] = run.end['failure']
    return summary_of(SummaryInputs(facts, series, metrics, int(run.steps[-1]), status),
                      mode=run.mode,
                      missed_commands=int(sum(run.missed_commands_per_agent)),
                      missed_commands_per_agent=run.missed_commands_per_agent,
                      leader_missed=run.leader_missed, bag=str(run.bag),
                      complete_steps=int(len(run.steps)), bag_warning=run.warning, **counted)
