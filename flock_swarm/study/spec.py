"""A sweep's spec (the YAML file of ``sweep``) and the plan of runs it expands to.

The spec names a scenario (preset or file), axes over any ``--set`` path (a grid, and
optionally lists varied together), derived values computed from the axes, the seeds of every
point, the summary metrics to collect (optionally also at several times) and the figure's
layout. See ``docs/sweeps.md`` for the format; :func:`parse_spec` checks all of it, and
:func:`plan_runs` resolves and validates every run's scenario, before any run starts.
"""

import dataclasses
import hashlib
import itertools
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from flock_swarm import __version__
from flock_swarm.core import summary
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.headline import run_mapping
from flock_swarm.core.run import stack_mismatch
from flock_swarm.core.scenario import MAX_SEED, Scenario
from flock_swarm.outputs import plain_json
from flock_swarm.scenario_yaml import read_yaml_file
from flock_swarm.study.expr import Expression, ExpressionError

#: The keys of a spec file.
SPEC_KEYS = ('name', 'description', 'scenario', 'set', 'grid', 'zip', 'derived', 'seeds',
             'metrics', 'times', 'plot', 'stack_agents')
#: Scalar summary keys (``summary.json``) a sweep can collect: those of the table of summary
#: keys marked for sweeps (:func:`flock_swarm.core.summary.sweep_metrics`).
SUMMARY_METRICS = summary.sweep_metrics()
#: Summary metrics that are also recorded over time (``timeseries.npz``), by series name.
TIMED_METRICS = summary.timed_series()
#: Default metrics when a spec names none.
DEFAULT_METRICS = summary.default_metrics()
#: How a law's own summary key (``Law.state_summary``: one value per agent) becomes a sweep
#: metric: ``KEY.STAT``, e.g. ``adaptive_gain_final.max``.
LAW_METRIC_STATS = {'min': min, 'mean': lambda xs: sum(xs) / len(xs), 'max': max}
#: Runs of one stack hold about this many agents in all (see :mod:`flock_swarm.study.execute`).
STACK_AGENTS = 3000
#: Most points of a sweep: each point's scenario is built and validated before any run (a few
#: milliseconds each: 10 000 points plan in about half a minute); a larger grid is refused
#: before it is expanded (10^7 points would plan for hours).
MAX_POINTS = 10_000
#: Most runs (points x seeds) of a sweep: the plan holds every run's scenario in memory.
MAX_RUNS = 1_000_000
#: Planning reports its progress every this many points.
PLAN_EVERY = 1000


@dataclass(frozen=True)
class Axis:
    """One swept ``--set`` path and its values."""

    key: str
    values: tuple


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep spec.

    :ivar name: the study's name (default output directory ``out/sweeps/NAME``).
    :ivar scenario: preset name or scenario file.
    :ivar overrides: ``key=value`` overrides of every run (``sweep --set``), applied first.
    :ivar fixed: ``{path: value}`` of every run (the spec's ``set``), applied next.
    :ivar grid: axes of the Cartesian product, in order.
    :ivar zipped: axes varied together (one more factor of the product).
    :ivar derived: ``(path, expression)`` computed from the axes, in order.
    :ivar seeds: the seeds of every point (common random numbers across points).
    :ivar metrics: summary keys collected per run.
    :ivar times: times [s] at which the timed metrics are also collected.
    :ivar plot_x: the figures' x axis; ``plot_line``: one line per value of this axis.
    :ivar stack_agents: about how many agents one stack of runs holds.
    """

    name: str
    scenario: str
    overrides: tuple[str, ...] = ()
    fixed: tuple[tuple[str, Any], ...] = ()
    grid: tuple[Axis, ...] = ()
    zipped: tuple[Axis, ...] = ()
    derived: tuple[tuple[str, Expression], ...] = ()
    seeds: tuple[int, ...] = (0,)
    metrics: tuple[str, ...] = DEFAULT_METRICS
    times: tuple[float, ...] = ()
    plot_x: str | None = None
    plot_line: str | None = None
    stack_agents: int = STACK_AGENTS
    description: str = ''

    @property
    def axes(self) -> tuple[Axis, ...]:
        """Return every axis (grid, then zipped)."""
        return self.grid + self.zipped

    def columns(self) -> list[str]:
        """Return the metric columns of a run: the metrics, then each timed one per time."""
        timed = summary.timed_series()
        return list(self.metrics) + [timed_column(m, t) for t in self.times
                                     for m in self.metrics if m in timed]


@dataclass(frozen=True)
class Run:
    """One planned run: its point, seed and fully resolved scenario mapping.

    :ivar point: the axis values (the table's columns), by path.
    :ivar seed: the seed.
    :ivar data: the scenario mapping as run (overrides, point, derived values and seed in).
    :ivar digest: the cache key (:func:`scenario_digest`).
    :ivar n_agents: N; ``steps``: steps (their product is the run's cost).
    :ivar stack_key: runs with equal keys can share a stack (:func:`simulate_stack`);
        ``None``: this run cannot be stacked.
    """

    point: dict
    seed: int
    data: dict = field(repr=False)
    digest: str
    n_agents: int
    steps: int
    stack_key: str | None = None

    @property
    def weight(self) -> int:
        """Return the run's cost in agent-steps."""
        return self.n_agents * self.steps

    def scenario(self) -> Scenario:
        """Return the run's validated scenario (prepared when it was planned)."""
        from flock_swarm.presets import reread
        return reread(self.data)


def timed_column(metric: str, t: float) -> str:
    """Return the column of a metric at time ``t``: ``eta@50``."""
    return f'{metric}@{t:g}'


def scenario_digest(sc: Scenario) -> str:
    """Return the cache key of a run: a hash of its scenario as run and the package version.

    The scenario's headline (``metrics.headline``, ``metrics.claim``) is left out: it changes
    what is printed, not the run.
    """
    text = json.dumps(plain_json(run_mapping(sc.raw)), sort_keys=True)
    return hashlib.sha1(f'{text}|{__version__}'.encode()).hexdigest()[:16]


def read_spec(path: Path, overrides: tuple[str, ...] = (), seeds: int | None = None
              ) -> SweepSpec:
    """Read and check a spec file.

    :param path: the YAML file.
    :param overrides: ``sweep --set`` overrides of every run.
    :param seeds: replaces the spec's seeds by ``0 .. seeds - 1`` when given.
    :return: the spec.
    :raises ScenarioError: naming the offending key.
    """
    data = read_yaml_file(path, 'spec', 'a sweep spec')
    if not isinstance(data, dict):
        raise ScenarioError('spec', f'{path}: expected a mapping at the top level')
    data.setdefault('name', path.stem)
    if seeds is not None:
        data['seeds'] = seeds
    if isinstance(data.get('scenario'), str):
        data['scenario'] = near_spec(path, data['scenario'])
    return parse_spec(data, overrides)


def near_spec(spec: Path, scenario: str) -> str:
    """Return a spec's ``scenario:`` with a relative file path taken from the spec's folder.

    A spec and its scenario file travel together (``sweep`` runs from any directory); a
    preset name (no ``.yaml`` suffix, no ``/``) and an absolute path stay as they are, by the
    rule :func:`flock_swarm.presets.resolve` tells a path from a preset name with.

    :param spec: the spec file.
    :param scenario: its ``scenario:`` value.
    :return: the scenario to load.
    """
    candidate = Path(scenario)
    is_path = candidate.suffix in ('.yaml', '.yml') or os.sep in scenario
    if not is_path or candidate.is_absolute():
        return scenario
    return str(spec.parent / candidate)


def parse_spec(data: dict, overrides: tuple[str, ...] = ()) -> SweepSpec:
    """Check a spec mapping and return the :class:`SweepSpec`.

    :param data: the mapping (see ``docs/sweeps.md``).
    :param overrides: ``key=value`` overrides of every run.
    :return: the spec.
    :raises ScenarioError: naming the offending key.
    """
    unknown = sorted(set(map(str, data)) - set(SPEC_KEYS))
    if unknown:
        raise ScenarioError(unknown[0], f'unknown spec key (known: {", ".join(SPEC_KEYS)})')
    name = data.get('name', 'sweep')
    if not isinstance(name, str) or not name or any(c in name for c in '/\\\0') \
            or name in ('.', '..'):
        raise ScenarioError('name', f'must be usable as a directory name, got {name!r}')
    scenario = data.get('scenario')
    if not isinstance(scenario, str) or not scenario:
        raise ScenarioError('scenario', 'missing: a preset name or a scenario file')
    fixed = tuple(_paths(data.get('set') or {}, 'set').items())
    grid = _axes(data.get('grid') or {}, 'grid')
    zipped = _axes(data.get('zip') or {}, 'zip')
    lengths = {len(a.values) for a in zipped}
    if len(lengths) > 1:
        raise ScenarioError('zip', f'lists of different lengths ({sorted(lengths)}): '
                            'zipped axes vary together')
    axes = grid + zipped
    keys = [a.key for a in axes]
    for key in keys:
        if keys.count(key) > 1:
            raise ScenarioError(key, 'swept twice (in grid and zip)')
        if key == 'seed':
            raise ScenarioError(key, 'the seeds are set by the spec key seeds')
    derived = []
    known = set(keys)
    for key, text in _paths(data.get('derived') or {}, 'derived').items():
        if key in known:
            raise ScenarioError(f'derived.{key}', 'is also an axis')
        if not isinstance(text, (str, int, float)) or isinstance(text, bool):
            raise ScenarioError(f'derived.{key}', f'expected an expression, got {text!r}')
        try:
            expr = Expression(str(text))
        except ExpressionError as exc:
            raise ScenarioError(f'derived.{key}', str(exc)) from None
        missing = sorted(expr.names() - known - {'pi'})
        if missing:
            raise ScenarioError(f'derived.{key}', f'unknown name {missing[0]!r} '
                                f'(axes and earlier derived values: '
                                f'{", ".join(sorted(known)) or "none"})')
        derived.append((key, expr))
        known.add(key)
    _check_overrides(overrides, keys, [key for key, _ in derived])
    _check_fixed(fixed, keys, [key for key, _ in derived])
    seeds = _seeds(data.get('seeds', 1))
    count = math.prod(len(a.values) for a in grid) * (len(zipped[0].values) if zipped else 1)
    if count > MAX_POINTS:
        raise ScenarioError('grid', f'{count} points (the product of the axes\' lengths): at '
                            f'most {MAX_POINTS} per sweep (split the study into several specs)')
    if count * len(seeds) > MAX_RUNS:
        raise ScenarioError('seeds', f'{count} points x {len(seeds)} seeds = '
                            f'{count * len(seeds)} runs: at most {MAX_RUNS} per sweep')
    metrics = _metrics(data.get('metrics', list(summary.default_metrics())))
    times = _times(data.get('times', []))
    plot = data.get('plot') or {}
    if not isinstance(plot, dict):
        raise ScenarioError('plot', f'expected a mapping {{x: AXIS, line: AXIS}}, got {plot!r}')
    for key in sorted(set(map(str, plot)) - {'x', 'line'}):
        raise ScenarioError(f'plot.{key}', 'unknown key (known: x, line)')
    plot_x = plot.get('x', keys[0] if keys else None)
    plot_line = plot.get('line', next((k for k in keys if k != plot_x), None))
    for key, value in (('plot.x', plot_x), ('plot.line', plot_line)):
        if value is not None and value not in keys:
            raise ScenarioError(key, f'{value!r} is not an axis (axes: {", ".join(keys)})')
    stack = data.get('stack_agents', STACK_AGENTS)
    if isinstance(stack, bool) or not isinstance(stack, int) or stack < 1:
        raise ScenarioError('stack_agents', f'expected a positive integer, got {stack!r}')
    description = data.get('description', '')
    if not isinstance(description, str):
        raise ScenarioError('description', f'expected text, got {description!r}')
    return SweepSpec(name, scenario, tuple(overrides), fixed, grid, zipped, tuple(derived),
                     seeds, metrics, times, plot_x, plot_line, stack,
                     description)


def _check_overrides(overrides: tuple[str, ...], axes: list[str], derived: list[str]) -> None:
    """Refuse a ``sweep --set`` of a key the spec sets per point (an axis or a derived value).

    The point's value would replace it silently; a key inside such a key (or one holding
    it, such as ``informed`` for the axis ``informed.fraction``) would mix both.
    """
    for assignment in overrides:
        key = assignment.split('=', 1)[0].strip()
        if key == 'seed':
            # It was replaced by each run's seed without a word (any value, even > 2**64).
            raise ScenarioError('--set', 'seed: every run takes its seed from the spec\'s '
                                'seeds; give --seeds R (0 .. R-1) or the spec key seeds (a '
                                'list, or {first, count})')
        for kind, names in (('an axis', axes), ('a derived value', derived)):
            for name in names:
                if key == name or key.startswith(f'{name}.') or name.startswith(f'{key}.'):
                    raise ScenarioError('--set', f'{key} is set per point by the spec ({kind}: '
                                        f'{name}); change the spec instead')


def _check_fixed(fixed: tuple[tuple[str, Any], ...], axes: list[str],
                 derived: list[str]) -> None:
    """Refuse a key of the spec's ``set:`` that the spec also sets per point (or ``seed``).

    The point's value (or the run's seed) would replace it silently.
    """
    for key, value in fixed:
        if key == 'seed':
            raise ScenarioError('set.seed', 'every run takes its seed from the spec key seeds '
                                '(a count, a list, or {first, count}); move it there')
        for kind, names in (('an axis', axes), ('a derived value', derived)):
            for name in names:
                # A point's value replaces what the set gave at its key or below it; an axis
                # below a mapping of the set refines it (network.loss: {model: ...} with the
                # axis network.loss.loss_bad) unless the mapping gives that key too.
                for leaf in _leaves(key, value):
                    if leaf == name or leaf.startswith(f'{name}.') \
                            or name.startswith(f'{leaf}.'):
                        raise ScenarioError(f'set.{leaf}', f'is also set per point ({kind}: '
                                            f'{name}), whose value would replace it; remove '
                                            'it from set')


def _leaves(key: str, value: Any) -> list[str]:
    """Return the dotted paths of the values a ``set:`` entry gives: ``key`` itself, or the
    leaves of a mapping (an empty mapping counts as a value)."""
    if not isinstance(value, dict) or not value:
        return [key]
    return [leaf for sub, item in value.items() for leaf in _leaves(f'{key}.{sub}', item)]


def _paths(section: Any, key: str) -> dict[str, Any]:
    """Return a mapping of dotted ``--set`` paths, checked."""
    if not isinstance(section, dict):
        raise ScenarioError(key, f'expected a mapping of scenario keys, got {section!r}')
    out = {}
    for path, value in section.items():
        parts = str(path).split('.')
        if not isinstance(path, str) or not all(p.isidentifier() for p in parts):
            raise ScenarioError(f'{key}.{path}', 'expected a dotted scenario key such as '
                                'protocol.c1')
        out[path] = value
    return out


def _axes(section: Any, key: str) -> tuple[Axis, ...]:
    """Return the axes of ``grid`` or ``zip``."""
    axes = []
    for path, values in _paths(section, key).items():
        if not isinstance(values, list) or not values:
            raise ScenarioError(f'{key}.{path}', f'expected a non-empty list of values, '
                                f'got {values!r}')
        if len({json.dumps(plain_json(v), sort_keys=True) for v in values}) < len(values):
            raise ScenarioError(f'{key}.{path}', 'a value is listed twice')
        axes.append(Axis(path, tuple(values)))
    return tuple(axes)


def _seeds(value: Any) -> tuple[int, ...]:
    """Return the seeds: a count (``0 .. n - 1``), a list, or ``{first, count}``.

    Each seed in ``[0, MAX_SEED]`` (the scenario's range), at most :data:`MAX_RUNS` of them;
    a count is checked before its range is built.
    """
    seeds = _seed_range(value)
    # A range's length and end without building it (len() fails past sys.maxsize).
    count, last = (seeds.stop - seeds.start, seeds.stop - 1) if isinstance(seeds, range) \
        else (len(seeds), max(seeds))
    if count > MAX_RUNS:
        raise ScenarioError('seeds', f'{count} seeds: at most {MAX_RUNS} runs in all')
    if last > MAX_SEED:
        raise ScenarioError('seeds', f'a seed must be <= 2**63 - 1 (the scenario\'s seed '
                            f'range), got {last}')
    return tuple(seeds)


def _seed_range(value: Any) -> range | list[int]:
    """Return the seeds of :func:`_seeds`, unchecked against the bounds (a range of a count)."""
    if isinstance(value, dict):
        extra = sorted(set(map(str, value)) - {'first', 'count'})
        if extra:
            raise ScenarioError(f'seeds.{extra[0]}', 'unknown key (known: first, count)')
        first, count = value.get('first', 0), value.get('count')
        if not _natural(first) or not _natural(count) or count < 1:
            raise ScenarioError('seeds', f'expected first >= 0 and count >= 1, got {value!r}')
        return range(first, first + count)
    if isinstance(value, list):
        if not value or not all(_natural(s) for s in value):
            raise ScenarioError('seeds', f'expected a list of integers >= 0, got {value!r}')
        if len(set(value)) < len(value):
            raise ScenarioError('seeds', 'a seed is listed twice')
        return value
    if not _natural(value) or value < 1:
        raise ScenarioError('seeds', f'expected a count >= 1, a list or {{first, count}}, '
                            f'got {value!r}')
    return range(value)


def _natural(value: Any) -> bool:
    """Return whether ``value`` is an integer >= 0 (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def law_metric(name: Any) -> tuple[str, str] | None:
    """Return ``(summary key, statistic)`` of a law-state metric ``KEY.STAT``, else ``None``."""
    if not isinstance(name, str):
        return None
    key, dot, stat = name.rpartition('.')
    return (key, stat) if dot and key and stat in LAW_METRIC_STATS else None


def metric_value(summary_: dict, name: str) -> Any:
    """Return a run's value of a sweep metric: a summary key, or a law-state statistic."""
    law = law_metric(name)
    if law is None:
        return summary_[name]
    values = summary_.get(law[0])
    return LAW_METRIC_STATS[law[1]](values) if values else None


def _metrics(value: Any) -> tuple[str, ...]:
    """Return the metrics, each a scalar summary key or a law-state statistic ``KEY.STAT``.

    Which law-state keys a run writes depends on its law: :func:`plan_runs` checks them
    against the scenario's.
    """
    if not isinstance(value, list) or not value:
        raise ScenarioError('metrics', f'expected a non-empty list, got {value!r}')
    known = summary.sweep_metrics()
    for k, name in enumerate(value):
        if name not in known and law_metric(name) is None:
            raise ScenarioError(f'metrics[{k}]', f'unknown metric {name!r} (known: '
                                f'{", ".join(known)}; and a law\'s own summary key as KEY.'
                                f'{"/".join(LAW_METRIC_STATS)}, e.g. '
                                'adaptive_gain_final.max)')
    if len(set(value)) < len(value):
        raise ScenarioError('metrics', 'a metric is listed twice')
    return tuple(value)


def _times(value: Any) -> tuple[float, ...]:
    """Return the times [s] the timed metrics are also collected at."""
    if not isinstance(value, list):
        raise ScenarioError('times', f'expected a list of times [s], got {value!r}')
    out = []
    for k, t in enumerate(value):
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not t >= 0:
            raise ScenarioError(f'times[{k}]', f'expected a time >= 0 [s], got {t!r}')
        out.append(float(t))
    if len(set(out)) < len(out):
        raise ScenarioError('times', 'a time is listed twice')
    return tuple(out)


def times_within(spec: SweepSpec) -> tuple[SweepSpec, tuple[float, ...]]:
    """Return the spec without the ``times`` after a duration shortened by ``sweep --set``.

    ``sweep su2009_fig3 --set duration=10`` asks for short runs of a study that also
    collects its metrics at 50 s: those columns cannot exist, and the user chose it on the
    command line, so they are dropped (the caller says so) instead of refusing the sweep. A
    spec whose own ``times`` lie after its own runs' end is still refused by
    :func:`plan_runs`.

    :param spec: the spec.
    :return: the spec to run and the times dropped (none: ``spec`` itself).
    """
    from flock_swarm.scenario_yaml import parse_value
    duration = None
    for assignment in spec.overrides:
        key, _, text = assignment.partition('=')
        if key.strip() == 'duration':
            duration = parse_value(text)
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) \
            or not duration > 0:
        return spec, ()  # no duration given, or an invalid one: the plan refuses it
    dropped = tuple(t for t in spec.times if t > duration)
    if not dropped:
        return spec, ()
    kept = tuple(t for t in spec.times if t <= duration)
    return dataclasses.replace(spec, times=kept), dropped


def points(spec: SweepSpec) -> list[dict]:
    """Return the spec's points (axis values by path): the grid's product, then ``zip``."""
    factors = [[(a.key, v) for v in a.values] for a in spec.grid]
    if spec.zipped:
        factors.append([tuple(pair for a in spec.zipped for pair in [(a.key, a.values[k])])
                        for k in range(len(spec.zipped[0].values))])
    out = []
    for combo in itertools.product(*factors):
        point = {}
        for item in combo:
            if isinstance(item[0], tuple):
                point.update(dict(item))
            else:
                point[item[0]] = item[1]
        out.append(point)
    return out


def resolve_point(spec: SweepSpec, point: dict) -> dict:
    """Return every value a point sets: the spec's ``set``, the axes, the derived values.

    :raises ScenarioError: when a derived value fails (naming it and the point).
    """
    return {**dict(spec.fixed), **point_values(spec, point)}


def point_values(spec: SweepSpec, point: dict) -> dict:
    """Return the values a point sets itself: the axes, then the derived values.

    :raises ScenarioError: when a derived value fails (naming it and the point).
    """
    values = dict(point)
    for key, expr in spec.derived:
        try:
            values[key] = expr.evaluate(values)
        except ExpressionError as exc:
            raise ScenarioError(f'derived.{key}', str(exc)) from None
    return values


def plan_runs(spec: SweepSpec, allow_unstable: bool = False,
              say: Callable[[str], None] | None = None) -> list[Run]:
    """Return every run of the spec, each scenario resolved and validated.

    Each point's scenario is the scenario file, with the spec's ``set``, then ``sweep
    --set`` (which so wins over ``set``: the command line is the user's last word), then
    the point's axes and derived values (``--set`` of those is refused by
    :func:`parse_spec`), then the seed.

    Order: seed by seed (the runs of one seed are the points of one realisation, with
    common random numbers), and within a seed the points of largest cost (N x steps) first
    so that long runs do not end up alone at the end. A larger seed count only adds runs.

    :param spec: the spec.
    :param allow_unstable: accept points whose dt violates a stability bound (as
        ``sim --allow-unstable``).
    :param say: told the planning's progress every :data:`PLAN_EVERY` points of a larger
        sweep (planning checks each point's scenario: about 3 ms a point).
    :raises ScenarioError: naming the point and the key a scenario rejects.
    """
    from flock_swarm.presets import load_mapping, prepare, set_values
    base = load_mapping(spec.scenario)
    try:
        base = set_values(base, dict(spec.fixed))
    except ScenarioError as exc:
        raise ScenarioError('set', str(exc)) from None
    resolved = []
    todo = points(spec)
    for number, point in enumerate(todo, 1):
        if say is not None and number % PLAN_EVERY == 0:
            say(f'[sweep] planning: {number}/{len(todo)} points checked')
        values = point_values(spec, point)
        where = ', '.join(f'{k}={v!r}' for k, v in point.items())
        sc = _prepared(where, lambda: prepare(base, spec.overrides, spec.seeds[0],
                                              extra=values, allow_unstable=allow_unstable))
        _law_metrics(spec.metrics, sc)
        for t in spec.times:
            if t > sc.duration + 0.5 * sc.dt:
                raise ScenarioError('times', f'{t:g} s is after the end of the run '
                                    f'({sc.duration:g} s)')
        resolved.append((point, sc))
    order = sorted(range(len(resolved)),
                   key=lambda k: -resolved[k][1].n_agents * resolved[k][1].steps)
    runs = []
    for seed in spec.seeds:
        for k in order:
            point, first = resolved[k]
            data = dict(first.raw, seed=seed)
            # Each further seed is a realisation of its own: prepared (and so checked: the
            # law's output at its initial state, the step size) like the first.
            sc = first if seed == spec.seeds[0] else _prepared(
                ', '.join([*(f'{key}={value!r}' for key, value in point.items()),
                           f'seed={seed}']),
                lambda: prepare(data, seed=seed, allow_unstable=allow_unstable))
            runs.append(Run(point, seed, data, scenario_digest(sc), sc.n_agents, sc.steps,
                            stack_key(sc)))
    return runs


def _prepared(where: str, prepare: Callable[[], tuple[Scenario, Any]]) -> Scenario:
    """Return the scenario of one run as :func:`~flock_swarm.presets.prepare` prepares it,
    an error naming the run (its point, ``where``) and the key."""
    from flock_swarm.presets import StepError
    try:
        return prepare()[0]
    except StepError as exc:
        raise ScenarioError(where or 'dt', f'dt: {exc.reason} (sweep --allow-unstable '
                            'runs it anyway)') from None
    except ScenarioError as exc:
        if exc.key in ('scenario', '--set'):
            raise
        raise ScenarioError(where or 'set', str(exc)) from None


def _law_metrics(metrics: tuple[str, ...], sc: Scenario) -> None:
    """Refuse a law-state metric whose key the scenario's law does not write."""
    own = tuple(sc.law.state_summary.values())
    for k, name in enumerate(metrics):
        law = law_metric(name)
        if law is not None and law[0] not in own:
            raise ScenarioError(f'metrics[{k}]', f'{name}: protocol {sc.law.name} writes no '
                                f'summary key {law[0]!r} (its own keys: '
                                f'{", ".join(own) or "none"})')


def stack_key(sc: Scenario) -> str | None:
    """Return the key under which runs may share a stack, or ``None`` if this one cannot.

    Realisations of one stack differ only in seed, informed set and initial state
    (:func:`stack_mismatch`); the key is the rest of the scenario mapping, plus the seed so
    that a stack holds one realisation's points (an interrupted sweep then has finished
    whole realisations first, as Fig. 3 has always run).
    """
    if stack_mismatch([sc, sc]) is not None:
        return None
    rest = {k: v for k, v in sc.raw.items() if k not in ('informed', 'initial', 'name')}
    return json.dumps(plain_json(rest), sort_keys=True)
