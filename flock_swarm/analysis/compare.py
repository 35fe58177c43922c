"""Comparing runs: one function, reference first, for every comparison of two runs.

:func:`compare_runs` sets a run under test (a ROS run, a bag) against a reference (``sim``'s
run of the same scenario, or any expected outputs), summary and time series alike. Its
arguments are always in that order, reference first::

    comparison = compare_runs(sim.summary, sim.series, ros_summary, ros_series, atol=0.0)
    comparison.problems          # one line per difference beyond atol ([]: they match)
    comparison.max_deviation     # {'q': max |q_run - q_ref|, ...} per float series

The testing API (:func:`flock_swarm.testing.compare_runs`, :func:`~flock_swarm.testing.
assert_matches_sim`) and the reproduction's ROS runs
(:mod:`flock_swarm.reproduce.execution`) use it. ``analyze --verify`` (:func:`verify_run`)
measures something else, the distance ``||q_i - q_i^sim||`` of every agent at every step
the bag kept, after re-running ``sim`` to the bag's last step; it lives here beside it.
"""

from dataclasses import dataclass
import math
from typing import Any, Iterable, Iterator

import numpy as np

from flock_swarm.analysis.bagrun import AnalyzeError, METADATA_RECORD, Progress, RunData
from flock_swarm.core.summary import sim_only_keys

#: Default largest deviation from ``sim`` that ``--verify`` accepts (m, m/s). A lockstep run
#: reproduces ``sim`` bit for bit; the margin only absorbs a different floating-point library.
VERIFY_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Comparison:
    """How a run differs from its reference (:func:`compare_runs`)."""

    #: The reference summary and the summary of the run under test.
    reference: dict
    summary: dict
    #: One line per difference beyond the tolerance (empty: the runs match).
    problems: list[str]
    #: ``max |run - reference|`` of every float series of the reference that the run has in
    #: the same shape (``None`` for one missing or of another shape).
    max_deviation: dict[str, float | None]
    #: Whether both runs recorded the same instants (their ``t`` have one shape).
    same_instants: bool

    @property
    def matches(self) -> bool:
        """Return whether the runs agree to the tolerance everywhere."""
        return not self.problems

    def side_by_side(self, keys: Iterable[str], reference_label: str,
                     label: str) -> dict[str, Any]:
        """Return ``{REFLABEL_key: reference value, LABEL_key: run's value}`` for ``keys``.

        :param keys: summary keys (a key either side lacks gives ``None``).
        :param reference_label: the reference's prefix, such as ``sim``.
        :param label: the run's prefix, such as ``ros``.
        """
        out: dict[str, Any] = {}
        for key in keys:
            out[f'{reference_label}_{key}'] = self.reference.get(key)
            out[f'{label}_{key}'] = self.summary.get(key)
        return out


def compare_runs(reference: dict, reference_series: dict, summary: dict, series: dict,
                 atol: float = 0.0) -> Comparison:
    """Compare a run with its reference: every key of the reference, to ``atol``.

    Every key of ``reference`` (the summary, nested mappings and lists included) and every
    array of ``reference_series`` must be in the run; numbers and float arrays may differ by
    ``atol`` (0: bit for bit), everything else must be equal. Keys the run has beyond the
    reference's are not differences, nor are the reference's keys that describe the
    simulator rather than the run (:func:`~flock_swarm.core.summary.sim_only_keys`:
    ``wall_time_s``, ``pseudo_leader_reselections``), which no world or analysis writes: a
    ``sim`` summary read from disk is compared as the testing API compares it.

    :param reference: the reference summary (``sim``'s, or the expected one).
    :param reference_series: the reference time series.
    :param summary: the summary of the run under test.
    :param series: the time series of the run under test.
    :param atol: the absolute tolerance.
    :return: the differences and the largest deviation of each series.
    """
    own = set(sim_only_keys())
    reference_run = {key: value for key, value in reference.items() if key not in own}
    problems = [f'summary {line}' for line in _differences('', reference_run, summary, atol)]
    deviation: dict[str, float | None] = {}
    for name, ref in reference_series.items():
        if name not in series:
            problems.append(f'series {name}: missing')
            deviation[name] = None
            continue
        ref, value = np.asarray(ref), np.asarray(series[name])
        if ref.shape != value.shape:
            problems.append(f'series {name}: shape {value.shape}, want {ref.shape}')
            deviation[name] = None
        elif ref.dtype.kind == 'f' or value.dtype.kind == 'f':
            diff = np.abs(value.astype(float) - ref.astype(float))
            deviation[name] = float(diff.max()) if diff.size else 0.0
            bad = (diff > atol) | (np.isnan(value) != np.isnan(ref))
            if bad.any():
                first = np.unravel_index(int(np.argmax(bad)), bad.shape)
                problems.append(f'series {name}: {int(bad.sum())} of {bad.size} values differ '
                                f'by more than {atol:g} (max {float(np.nanmax(diff)):.3g}, '
                                f'first at index {tuple(int(i) for i in first)})')
        elif not np.array_equal(ref, value):
            problems.append(f'series {name}: {int((ref != value).sum())} values differ')
    same = ('t' in reference_series and 't' in series
            and np.shape(reference_series['t']) == np.shape(series['t']))
    return Comparison(reference, summary, problems, deviation, same)


def _differences(where: str, want: Any, got: Any, atol: float) -> Iterator[str]:
    """Yield ``key: got X, want Y`` for every leaf of ``want`` that ``got`` does not match."""
    if isinstance(want, dict):
        for key, value in want.items():
            path = f'{where}.{key}' if where else key
            if not isinstance(got, dict) or key not in got:
                yield f'{path}: missing'
            else:
                yield from _differences(path, value, got[key], atol)
    elif isinstance(want, list) and isinstance(got, list) and len(want) == len(got):
        for i, (a, b) in enumerate(zip(want, got)):
            yield from _differences(f'{where}[{i}]', a, b, atol)
    elif (isinstance(want, float) and isinstance(got, (int, float))
          and not isinstance(got, bool)):
        if not (abs(got - want) <= atol or got == want
                or (math.isnan(got) and math.isnan(want))):
            yield f'{where}: got {got!r}, want {want!r} (atol {atol:g})'
    elif want != got:
        yield f'{where}: got {got!r}, want {want!r}'


@dataclass(frozen=True)
class Verification:
    """How far the recorded trajectory is from ``sim`` run on the stored scenario and seed."""

    #: ``max_k max_i ||q_i - q_i^sim||`` [m] over the compared steps.
    max_position_error: float
    #: ``max_k max_i ||p_i - p_i^sim||`` [m/s].
    max_velocity_error: float
    #: Number of steps compared.
    steps_compared: int
    #: The largest accepted error.
    tolerance: float

    @property
    def passed(self) -> bool:
        """Return whether both errors are within the tolerance."""
        return max(self.max_position_error, self.max_velocity_error) <= self.tolerance


def check_verifiable(run: RunData) -> None:
    """Raise unless the run's bag stores the scenario that ``--verify`` re-runs.

    :param run: the run.
    :raises AnalyzeError: for a bag without the scenario record.
    """
    if run.scenario is None:
        raise AnalyzeError('--verify needs the scenario stored in the bag (MCAP metadata '
                           f'record {METADATA_RECORD!r}); this bag has none')


def verify_run(run: RunData, tolerance: float = VERIFY_TOLERANCE,
               progress: Progress | None = None) -> Verification:
    """Re-run ``sim`` on the bag's scenario and seed; compare positions and velocities.

    The simulation runs to the last complete step of the bag and records every step; each
    complete step of the bag is compared with the simulated state of the same step.

    :param run: a run whose bag stores its scenario.
    :param tolerance: the largest accepted error (m and m/s).
    :param progress: forwarded to :func:`flock_swarm.core.run.simulate`.
    :return: the largest errors.
    :raises AnalyzeError: if the bag has no scenario.
    """
    from flock_swarm.core.run import simulate
    from flock_swarm.presets import reread

    check_verifiable(run)
    sc = run.scenario
    data = dict(sc.raw)
    last = int(run.steps[-1])
    if last < sc.steps:
        data['duration'] = max(last, 1) * sc.dt
    ref = reread(data)
    # Every step's state, taken as sim steps (its metrics only at its recorded instants,
    # as sim computes them: recording every step cost more than the simulation).
    states = {'q': np.empty((ref.steps + 1, ref.n_agents, ref.dim)),
              'p': np.empty((ref.steps + 1, ref.n_agents, ref.dim))}
    stepped = [0]

    def keep(step: int, q: np.ndarray, p: np.ndarray) -> None:
        states['q'][step], states['p'][step] = q, p
        stepped[0] = step + 1

    simulate(ref, progress=progress, on_step=keep)
    simulated = stepped[0]
    reference = {key: value[:simulated] for key, value in states.items()}
    rows = np.flatnonzero(run.steps < simulated)
    if rows.size < len(run.steps):
        # The simulation diverged before the recording ended: no agreement there.
        return Verification(float('inf'), float('inf'), int(rows.size), tolerance)
    k = run.steps[rows]
    dq = np.linalg.norm(run.q[rows] - reference['q'][k], axis=2)
    dp = np.linalg.norm(run.p[rows] - reference['p'][k], axis=2)
    return Verification(float(dq.max()), float(dp.max()), int(rows.size), tolerance)
