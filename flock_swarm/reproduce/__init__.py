"""Reproduction report: every experiment of the five papers, run and set against their claims.

``python -m flock_swarm.reproduce [--out out/reproduce] [--report docs/reproduction.md]
[--figures docs/figures] [--realisations R] [--quick] [--skip-ros] [--jobs 2] [--fresh]``
(or ``scripts/reproduce ...``) runs each experiment (the presets of ``docs/scenarios.md``)
with the reference simulator on its preset (the papers' numbers), the sweep of Su, Wang, Lin 2009
Fig. 3 over ``R`` realisations per point, and one shortened experiment per paper through the
real ROS 2 nodes (lockstep, one process); it then writes one JSON result per experiment
(``OUT/results/<experiment>.json``), one figure per experiment and the Markdown report.

Every run is cached in ``OUT`` and reused when its scenario and the package version match:
presets in ``OUT/runs/<experiment>/`` (``summary.json``, ``timeseries.npz``), the Fig. 3
sweep as JSON lines in ``OUT/fig3_runs.jsonl`` (one line per run, appended as runs finish;
the machinery of ``sweep``, :mod:`flock_swarm.study`),
the ROS runs in ``OUT/ros/<experiment>/``. An interrupted reproduction therefore resumes
where it stopped, and a larger ``--realisations`` only runs the missing realisations.
``--fresh`` ignores the caches.

The package: one module per experiment in :mod:`flock_swarm.reproduce.experiments` (an
:class:`~flock_swarm.reproduce.experiment.Experiment`: set-up, analysis, table rows,
discussion, figure, headline, criterion, the set-ups it runs over seeds), found by
:mod:`~flock_swarm.reproduce.catalogue`; the verdicts' statistics in
:mod:`~flock_swarm.reproduce.stats`; the runs and caches in
:mod:`~flock_swarm.reproduce.execution` and :mod:`~flock_swarm.reproduce.seeds`; the Markdown
in :mod:`~flock_swarm.reproduce.report`, which names no experiment; the whole of it in
:mod:`~flock_swarm.reproduce.pipeline`; the command line is :mod:`flock_swarm.cli.reproduce`.
"""

from flock_swarm.reproduce.catalogue import all_experiments

__all__ = ['all_experiments']
