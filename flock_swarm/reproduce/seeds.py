"""The experiments over many seeds: distributions, the criterion's statistic with its
confidence interval, and the verdict of every set-up.

Each set-up of an experiment (:class:`~flock_swarm.reproduce.experiment.SetUp`) is a sweep
spec (``config/sweeps/reproduce_<experiment>.yaml``, or a mapping in the experiment's module:
the preset, its variants as axes, the seeds from 1, the preset's own seed staying the figure);
its runs go through :func:`flock_swarm.study.execute.execute` (the stacks, backends and
checked, resumable cache of ``sweep``) with :class:`SeedRecorder`, which keeps the
experiment's own analysis of each run (the numbers of its table) instead of ``sweep``'s
summary columns. The caches (``NAME.jsonl``, one line per run) are small and committed under
``docs/reproduction/runs/``: the report renders from whatever they hold and states the count.
"""

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from flock_swarm import __version__
from flock_swarm.core.run import SimResult
from flock_swarm.core.scenario import Scenario
from flock_swarm.reproduce.common import cell, fmt
from flock_swarm.study.cache import read_cache
from flock_swarm.study.spec import Run, plain

#: Where the committed caches of the studies live (relative to the repository root).
SEEDS_CACHE = Path('docs/reproduction/runs')
#: --quick: seeds per study (its runs shortened as the experiment's own quick run).
QUICK_SEEDS = 2
#: Seeds per set-up where a run costs under :data:`CHEAP_RUN_S` of computing, and where more.
SEEDS_CHEAP, SEEDS_COSTLY = 50, 20
CHEAP_RUN_S = 60.0


def settling_time(series: dict, tolerance: float) -> float | None:
    """Return the first recorded instant after which ``max_i ||p_i - p_leader||`` stays at or
    below ``tolerance`` (``None``: still above it at the end of the run).

    :param series: the run's time series (``t``, ``p``, ``leader_p``).
    :param tolerance: the velocity tolerance [m/s].
    """
    err = np.linalg.norm(series['p'] - series['leader_p'][:, None], axis=-1).max(axis=1)
    above = np.flatnonzero(err > tolerance)
    if above.size == 0:
        return float(series['t'][0])
    if above[-1] == err.size - 1:
        return None
    return float(series['t'][above[-1] + 1])


@dataclass(frozen=True)
class SeedRecorder:
    """The record of one run over seeds: point, seed, the experiment's analysis, provenance.

    :ivar experiment: the experiment whose analysis applies (picklable: the pool's workers
        import its module).
    """

    experiment: Any

    def __call__(self, run: Run, sc: Scenario, result: SimResult) -> dict:
        """Return the record (non-finite values as ``None``)."""
        s, series = result.summary, result.series
        metrics: dict[str, Any] = self.experiment.analyse(sc, s, series)
        metrics['settling_time'] = settling_time(series, sc.eta_tolerance)
        gains = s.get('adaptive_gain_final')
        if gains:
            metrics['adaptive_gain_mean'] = float(np.mean(gains))
        metrics['n_agents'] = sc.n_agents
        return {'point': plain(run.point), 'seed': run.seed, 'metrics': plain(metrics),
                'status': s['status'], 'wall_time_s': s['wall_time_s'],
                'flock_swarm_version': __version__}


def distribution(values: list) -> dict:
    """Return ``count, mean, std (ddof 1), min, max`` of the finite numbers of ``values``
    (``missing``: how many were ``None`` or not finite)."""
    nums = [float(v) for v in values
            if v is not None and not isinstance(v, str) and math.isfinite(float(v))]
    out: dict[str, Any] = {'count': len(nums), 'missing': len(values) - len(nums)}
    if nums:
        arr = np.array(nums)
        out.update(mean=float(arr.mean()), std=float(arr.std(ddof=1)) if arr.size > 1 else 0.0,
                   min=float(arr.min()), max=float(arr.max()))
    return out


def point_label(setup, point: dict) -> str:
    """Return the label of a set-up's point: the set-up's, or its axis values."""
    if not point:
        return setup.label
    key = tuple(str(v) for v in point.values())
    return setup.labels.get(key, ', '.join(f'{k} = {v}' for k, v in point.items()))


def summarise(exp, groups: list[tuple[str, list[dict], int]], notes: dict | None = None
              ) -> dict:
    """Return the distributions, the criterion's statistic and the verdict of each set-up.

    :param exp: the experiment (its ``criterion``, ``columns`` and ``paired``).
    :param groups: ``(label, records, planned seeds)`` per set-up, the paper's first.
    :param notes: a note per label (an equivalence, a cost), shown with the table.
    :return: ``{'setups': [...], 'criterion': text}`` (``paired``: a sentence comparing
        the set-ups seed by seed, when the experiment has one).
    """
    setups = []
    for label, records, planned in groups:
        metrics = [r['metrics'] for r in records]
        costs = [r['wall_time_s'] for r in records if r.get('wall_time_s') is not None]
        setups.append({
            'label': label, 'seeds': len(records), 'planned': planned,
            'seed_list': sorted(r['seed'] for r in records),
            'cost_s': float(np.mean(costs)) if costs else None,
            'judged': exp.criterion.judge(records),
            'note': (notes or {}).get(label, ''),
            'per_seed': [{'seed': r['seed'],
                          **{key: r['metrics'].get(key) for _, key in exp.per_seed}}
                         for r in sorted(records, key=lambda r: r['seed'])]
            if exp.per_seed else [],
            'stats': {key: distribution([m.get(key) for m in metrics])
                      for _, key, _ in exp.columns}})
    out = {'setups': setups, 'criterion': exp.criterion.statement()}
    paired = getattr(exp, 'paired', None)
    if paired is not None:
        out['paired'] = paired(groups)
    return out


def study_runs(name: str | dict, overrides: tuple[str, ...] = (), seeds: int | None = None):
    """Return the spec of a set-up and its planned runs (``--quick``: overrides, few seeds).

    :param name: the spec's name in ``config/sweeps/``, or the spec mapping.
    """
    from flock_swarm.presets import resolve
    from flock_swarm.study.spec import parse_spec, plan_runs, read_spec
    if isinstance(name, str):
        spec = read_spec(resolve(name, 'sweeps', 'spec'), overrides, seeds)
    else:
        data = dict(name)
        if seeds is not None:
            data['seeds'] = seeds
        spec = parse_spec(data, overrides)
    # The quick overrides win over the spec's own fixed values (a 300 s run, say).
    keys = {o.split('=', 1)[0] for o in overrides}
    spec = replace(spec, fixed=tuple((k, v) for k, v in spec.fixed if k not in keys))
    return spec, plan_runs(spec)


def run_study(exp, cache_dir: Path, backend, say: Callable[[str], None], quick: bool = False,
              cached_only: bool = False, live: Callable[[str], None] | None = None) -> dict:
    """Run (or resume, or only read) the set-ups of one experiment; return their summary.

    :param exp: the experiment.
    :param cache_dir: where the caches ``NAME.jsonl`` live.
    :param backend: where missing runs go.
    :param say: progress lines.
    :param quick: the experiment's ``--quick`` overrides and :data:`QUICK_SEEDS` seeds.
    :param cached_only: run nothing; use what the caches hold.
    :param live: rewrites the terminal's progress line, or ``None``.
    """
    from flock_swarm.study.execute import execute
    groups, notes = [], {}
    for setup in exp.setups:
        spec, runs = study_runs(setup.spec, tuple(exp.quick) if quick else (),
                                QUICK_SEEDS if quick else None)
        path = cache_dir / f'{spec.name}.jsonl'
        if cached_only:
            cache = read_cache(path, ('digest', 'status'), say)
            records = [cache[r.digest] for r in runs if r.digest in cache]
        else:
            records = execute(runs, path, SeedRecorder(exp), backend, spec.stack_agents, say,
                              live, prefix=spec.name)['records']
        records = [r for r in records if r['status'] == 'completed']
        points = []
        for run in runs:
            if run.point not in points:
                points.append(run.point)
        for point in points:
            mine = [r for r in records if r['point'] == plain(point)]
            label = point_label(setup, point)
            groups.append((label, mine, len(spec.seeds)))
            if label in setup.notes:
                notes[label] = setup.notes[label]
    res = summarise(exp, groups, notes)
    # A spec written in the experiment's module has no file for `sweep` to read.
    res['commands'] = [f'sweep {s.name}' if isinstance(s.spec, str)
                       else 'python -m flock_swarm.reproduce --seeds-only' for s in exp.setups]
    res['caches'] = [str(cache_dir / f'{s.name}.jsonl') for s in exp.setups]
    return res


def run_studies(cache_dir: Path, backend, say: Callable[[str], None], quick: bool = False,
                cached_only: bool = False, live: Callable[[str], None] | None = None,
                long: bool = False, figures: Path = Path('docs/figures'),
                experiments=None) -> dict[str, dict]:
    """Run (or resume, or only read) the study of every experiment; return it by key.

    :param cache_dir: where the caches ``NAME.jsonl`` live.
    :param backend: where missing runs go.
    :param say: progress lines.
    :param quick: the experiments' ``--quick`` overrides and :data:`QUICK_SEEDS` seeds.
    :param cached_only: run nothing; use what the caches hold.
    :param live: rewrites the terminal's progress line, or ``None``.
    :param long: also run the long studies (``--fig3-curves``: hours); without it they
        only read their caches, as they do in ``--quick`` mode.
    :param figures: where a study's own figure goes.
    :param experiments: the experiments (default: the catalogue's).
    """
    from flock_swarm.reproduce.catalogue import all_experiments
    out = {}
    for exp in all_experiments() if experiments is None else experiments:
        read_only = (not long or quick) if exp.long_study else cached_only
        res = exp.run_study(cache_dir, backend, say, quick, read_only, live, figures)
        if res is not None:
            out[exp.key] = res
    return out


def judgement_text(judged: dict) -> str:
    """Return ``statistic estimate [low, high]`` of a judgement (its interval at 95 %)."""
    if judged['estimate'] is None:
        return 'no seeds cached yet'
    interval = judged['interval']
    ci = f' [{fmt(interval[0])}, {fmt(interval[1])}]' if interval else ' (no interval)'
    if judged['statistic'] == 'fraction of seeds':
        return f'{judged["met"]} of {judged["n"]} meet the claim, {fmt(judged["estimate"])}{ci}'
    return f'{judged["statistic"]} {fmt(judged["estimate"])}{ci}'


def _stat(d: dict) -> str:
    """Return ``mean ± std [min, max]`` of a distribution."""
    if not d['count']:
        return 'n/a' + (f' ({d["missing"]} without a value)' if d['missing'] else '')
    text = f'{fmt(d["mean"])} ± {fmt(d["std"])} [{fmt(d["min"])}, {fmt(d["max"])}]'
    return text + (f'; {d["missing"]} without a value' if d['missing'] else '')


def section(exp, res: dict) -> list[str]:
    """Return the report lines of an experiment's study: per set-up, the criterion's
    statistic with its interval and verdict, then the distributions."""
    lines = ['', '**Over seeds.** Each set-up is judged on its own by the criterion above '
             '(95 % intervals; the first set-up is the paper\'s).', '',
             '| set-up | seeds (planned) | computing per run [s] | statistic [95 % interval] | '
             'verdict |', '|---|---|---|---|---|']
    for s in res['setups']:
        verdict = s['judged']['verdict']
        lines.append(f'| {cell(s["label"])} | {s["seeds"]} ({s["planned"]}) | '
                     f'{fmt(s["cost_s"])} | {cell(judgement_text(s["judged"]))} | '
                     f'**{verdict}** |')
    for s in res['setups']:
        if s['note']:
            lines += ['', f'*{s["label"]}*: {s["note"]}']
        failed = s['judged']['premise_failed']
        if failed:
            lines += ['', f'*{s["label"]}*: {len(failed)} of {s["seeds"]} seeds fail the '
                      f'premise and do not test the claim: {_seed_text(failed)}.']
    lines += ['', 'Distributions (mean ± standard deviation [min, max] over the seeds):', '',
              '| set-up | ' + ' | '.join(f'{cell(label)} (`{key}`; paper: {cell(paper)})'
                                         for label, key, paper in exp.columns) + ' |',
              '|---|' + '---|' * len(exp.columns)]
    for s in res['setups']:
        lines.append(f'| {cell(s["label"])} | '
                     + ' | '.join(cell(_stat(s['stats'][key])) for _, key, _ in exp.columns)
                     + ' |')
    whats = '; '.join(what for what, _ in exp.per_seed)
    for s in res['setups']:
        if s['per_seed']:
            lines += ['', f'*{s["label"]}*, seed by seed ({whats}): ' + '; '.join(
                f'{r["seed"]}: ' + ', '.join('-' if r[key] is None else fmt(r[key])
                                             for _, key in exp.per_seed)
                for r in s['per_seed']) + '.']
    if res.get('paired'):
        lines += ['', res['paired']]
    seeds = sorted({x for s in res['setups'] for x in s['seed_list']})
    lines += ['', f'Seeds run: {_seed_text(seeds)}; {SEEDS_CHEAP} per set-up where a run costs '
              f'under {CHEAP_RUN_S:g} s of computing, {SEEDS_COSTLY} where it costs more. '
              'Commands: ' + ', '.join(f'`{c}`' for c in res['commands'])
              + ' (the same runs; `python -m flock_swarm.reproduce` runs them with the '
              'experiment\'s analysis into ' + ', '.join(f'`{c}`' for c in res['caches'])
              + ').']
    short = [s for s in res['setups'] if s['seeds'] < s['planned']]
    if short:
        lines[-1] += (' **Incomplete:** ' + '; '.join(
            f'{s["label"]}: {s["seeds"]} of {s["planned"]} seeds' for s in short)
            + ' (the cache holds what the time allowed; re-running resumes).')
    return lines


def _seed_text(seeds: list[int]) -> str:
    """Return ``seeds 1 .. 20`` or the list."""
    if not seeds:
        return 'none yet'
    if len(seeds) == 1:
        return f'seed {seeds[0]}'
    if seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f'seeds {seeds[0]} .. {seeds[-1]}'
    return 'seeds ' + ', '.join(map(str, seeds))
