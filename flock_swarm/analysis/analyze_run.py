"""``analyze``'s work on a run rebuilt from its bag: recompute, summarise, verify, write.

:func:`analyze` writes ``timeseries.npz``, ``timeseries.csv``, ``scenario.json`` (when the bag
stores the scenario), the figures and ``summary.json`` (``docs/analysis.md``); the run comes
from :func:`flock_swarm.analysis.bagrun.load_run`.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flock_swarm.analysis.bagrun import Progress, RunData
from flock_swarm.analysis.compare import VERIFY_TOLERANCE, Verification, verify_run
from flock_swarm.analysis.recompute import recompute, summarize
from flock_swarm.core.metrics import STEP_METRICS
from flock_swarm.outputs import json_text, write_text, write_timeseries


@dataclass
class Analysis:
    """What :func:`analyze` produced."""

    #: ``summary.json``.
    summary: dict
    #: ``timeseries.npz``.
    series: dict[str, np.ndarray]
    #: Every file written, ``summary.json`` last.
    files: list[Path] = field(default_factory=list)
    verification: Verification | None = None


def write_csv(series: dict[str, np.ndarray], path: Path) -> Path:
    """Write the metric time series as CSV: ``t`` and the metrics of :data:`STEP_METRICS`.

    :param series: the time series.
    :param path: the file.
    :return: the path.
    """
    columns = ['t'] + [f'metric_{name}' for name in STEP_METRICS]
    table = np.column_stack([series[name] for name in columns])
    np.savetxt(path, table, fmt='%.17g', delimiter=',', comments='',
               header=','.join(['t', *STEP_METRICS]))
    return path


def analyze(run: RunData, out: Path, *, snapshots: Sequence[float] | None = None,
            animate: bool = True, verify: bool = False,
            verify_tolerance: float = VERIFY_TOLERANCE, record_every: int | None = None,
            progress: Progress | None = None) -> Analysis:
    """Recompute the metrics of a run and write its outputs and figures into ``out``.

    Files: ``timeseries.npz``, ``timeseries.csv``, ``scenario.json`` (when the bag stores the
    scenario), the figures of :func:`flock_swarm.plots.plot_analysis`, and ``summary.json``
    last (atomically: its presence means the other files are complete).

    :param run: the run, from :func:`load_run`.
    :param out: the output directory (created).
    :param snapshots: snapshot times [s] (default: first, middle and last instants).
    :param animate: write ``flock.gif``.
    :param verify: compare with ``sim`` (:func:`verify_run`) and add ``verify_*`` keys.
    :param verify_tolerance: the largest accepted deviation.
    :param record_every: subsampling of the series (default: the scenario's).
    :param progress: called with one-line progress messages.
    :return: the summary, the series, the files written and the verification.
    :raises OSError: if ``out`` cannot be written.
    """
    from flock_swarm.plots import plot_analysis
    series, metrics = recompute(run, record_every, progress)
    summary = summarize(run, series, metrics)
    verification = None
    if verify:
        verification = verify_run(run, verify_tolerance, progress)
        summary.update({
            'verify_max_position_error': verification.max_position_error,
            'verify_max_velocity_error': verification.max_velocity_error,
            'verify_steps_compared': verification.steps_compared,
            'verify_tolerance': verification.tolerance,
            'verify_passed': verification.passed,
        })
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = [write_timeseries(out / 'timeseries.npz', series),
             write_csv(series, out / 'timeseries.csv')]
    if run.scenario is not None:
        files.append(write_text(out / 'scenario.json', json_text(run.scenario.raw)))

    def wrote(path: Path) -> None:
        files.append(path)
        if progress is not None:
            progress(f'[analyze] wrote {path}')

    plot_analysis(series, out, radius=run.radius, strict=run.strict_radius, title=run.name,
                  informed=run.informed, eta_tolerance=run.eta_tolerance,
                  collision_distance=run.collision_distance, snapshots=snapshots,
                  animate=animate, progress=wrote,
                  obstacles=run.scenario.obstacles if run.scenario is not None else None)
    files.append(write_text(out / 'summary.json', json_text(summary)))
    return Analysis(summary, series, files, verification)


def default_out(bag: Path) -> Path:
    """Return the default output directory: ``<bag>_analysis`` next to the bag.

    :param bag: the bag directory or ``.mcap`` file.
    :return: for ``out/demo_ros/bag``, ``out/demo_ros/bag_analysis``.
    """
    bag = Path(bag)
    if not bag.name:
        bag = bag.resolve()
    stem = bag.stem if bag.suffix == '.mcap' else bag.name
    return bag.parent / f'{stem}_analysis'
