"""A sweep's results: the tidy table (one row per run), the aggregated one, the figures.

CSV, written with :mod:`csv`: floats as Python's shortest round-trip text (``repr``), so the
numbers read back are the computed ones bit for bit; missing or non-finite values (a
diverged run) are empty cells; list values (a box) are JSON text.
"""

import csv
import json
import math
from pathlib import Path
from typing import Any, Iterable

from flock_swarm.study.spec import SweepSpec, points

#: Provenance columns of the tidy table, after the metrics.
PROVENANCE = ('status', 'wall_time_s', 'flock_swarm_version', 'scenario_hash')
#: Columns of the aggregated table after the axes.
STATISTICS = ('metric', 'count', 'mean', 'std', 'sem', 'min', 'max')


def tidy_columns(spec: SweepSpec) -> list[str]:
    """Return the tidy table's columns: axes, seed, metrics, provenance."""
    return [a.key for a in spec.axes] + ['seed'] + spec.columns() + list(PROVENANCE)


def tidy_rows(spec: SweepSpec, records: Iterable[dict]) -> list[dict]:
    """Return one row per run, ordered by point (the spec's order), then seed.

    :param spec: the spec.
    :param records: the runs' records (see :class:`~flock_swarm.study.execute.MetricRecorder`).
    :return: rows keyed by :func:`tidy_columns`.
    """
    axes = [a.key for a in spec.axes]
    rank = {_key(p): k for k, p in enumerate(points(spec))}
    seeds = {s: k for k, s in enumerate(spec.seeds)}
    rows = []
    for rec in records:
        row: dict[str, Any] = {key: rec['point'][key] for key in axes}
        row['seed'] = rec['seed']
        row.update({c: rec.get(c) for c in spec.columns()})
        row.update(status=rec['status'], wall_time_s=rec['wall_time_s'],
                   flock_swarm_version=rec['flock_swarm_version'], scenario_hash=rec['digest'])
        rows.append(row)
    rows.sort(key=lambda r: (rank[_key({k: r[k] for k in axes})], seeds[r['seed']]))
    return rows


def aggregate(spec: SweepSpec, rows: list[dict]) -> list[dict]:
    """Return, per point and metric, count, mean, std (ddof 1), standard error, min, max.

    Over the completed runs whose value is finite (``count`` says how many).

    :param spec: the spec.
    :param rows: the tidy rows.
    :return: rows keyed by the axes and :data:`STATISTICS`, ordered by point, then metric.
    """
    axes = [a.key for a in spec.axes]
    groups: dict[str, list[dict]] = {}
    for row in rows:
        groups.setdefault(_key({k: row[k] for k in axes}), []).append(row)
    out = []
    for point in points(spec):
        members = groups.get(_key(point), [])
        for column in spec.columns():
            values = [float(r[column]) for r in members if r['status'] == 'completed'
                      and r[column] is not None and math.isfinite(float(r[column]))]
            n = len(values)
            mean = math.fsum(values) / n if n else None
            std = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1)) \
                if n > 1 else (0.0 if n else None)
            out.append({**point, 'metric': column, 'count': n, 'mean': mean, 'std': std,
                        'sem': std / math.sqrt(n) if n else None,
                        'min': min(values) if n else None, 'max': max(values) if n else None})
    return out


def write_csv(path: Path, columns: list[str], rows: list[dict]) -> Path:
    """Write rows as CSV (written to a temporary file, then renamed into place)."""
    tmp = path.with_name(path.name + '.tmp')
    with open(tmp, 'w', newline='') as stream:
        writer = csv.writer(stream, lineterminator='\n')
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_cell(row.get(c)) for c in columns])
    tmp.replace(path)
    return path


def figures(spec: SweepSpec, stats: list[dict], out: Path) -> list[Path]:
    """Draw each metric's mean against ``plot.x`` (error bars: standard error).

    One line per value of ``plot.line`` (and of any further axis); none without axes.

    :param spec: the spec.
    :param stats: the aggregated rows.
    :param out: the directory of the PNGs (``METRIC.png``, ``@`` as ``_at_``).
    :return: the written paths.
    """
    if spec.plot_x is None:
        return []
    from flock_swarm.plots import plot_errorbars
    others = [a.key for a in spec.axes if a.key != spec.plot_x]
    if spec.plot_line in others:
        others.remove(spec.plot_line)
        others.insert(0, spec.plot_line)
    paths = []
    for column in spec.columns():
        lines: dict[str, tuple[list, list, list]] = {}
        for row in stats:
            if row['metric'] != column or row['mean'] is None:
                continue
            label = ', '.join(f'{k} = {_cell(row[k])}' for k in others)
            x, mean, err = lines.setdefault(label, ([], [], []))
            x.append(row[spec.plot_x])
            mean.append(row['mean'])
            err.append(row['sem'])
        if not lines:
            continue
        count = min(r['count'] for r in stats if r['metric'] == column)
        paths.append(plot_errorbars(
            lines, out, xlabel=spec.plot_x, ylabel=f'{column} (mean, SE)',
            title=f'{spec.name}: {column}, at least {count} runs per point',
            filename=f'{column.replace("@", "_at_")}.png'))
    return paths


def _key(point: dict) -> str:
    """Return a hashable key of a point's values."""
    return json.dumps(point, sort_keys=True)


def _cell(value: Any) -> str:
    """Return a CSV cell: ``repr`` of floats, JSON of lists, empty for missing values."""
    if value is None:
        return ''
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ''
    if isinstance(value, (list, tuple, dict)):
        return json.dumps(value)
    return str(value)
