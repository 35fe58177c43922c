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
from flock_swarm.core.run import RunResult
from flock_swarm.core.scenario import Scenario
from flock_swarm.outputs import plain_json
from flock_swarm.reproduce.common import FIG_SIZE, cell, fmt, pyplot, save_figure
from flock_swarm.reproduce.questions import (LEADER_KEY, TIMES, TOLERANCES, question_keys,
                                             three_questions, time_key, tolerance_key)
from flock_swarm.reproduce.stats import mean_interval
from flock_swarm.study.cache import read_cache
from flock_swarm.study.spec import Run

#: Where the committed caches of the studies live (relative to the repository root).
SEEDS_CACHE = Path('docs/reproduction/runs')
#: --quick: seeds per study (its runs shortened as the experiment's own quick run).
QUICK_SEEDS = 2
#: Seeds per set-up where a run costs under :data:`CHEAP_RUN_S` of computing, and where more.
SEEDS_CHEAP, SEEDS_COSTLY = 50, 20
CHEAP_RUN_S = 60.0
#: The first seed of the held-out set: every set-up is judged again on as many seeds from
#: here (disjoint from the first set, which starts at 1), cached apart
#: (``NAME_heldout.jsonl``); a verdict that differs between the two sets is *fragile*.
HELD_OUT_FIRST = 1001
#: The suffix of a held-out set's cache.
HELD_OUT_SUFFIX = '_heldout'


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

    def __call__(self, run: Run, sc: Scenario, result: RunResult) -> dict:
        """Return the record (non-finite values as ``None``)."""
        s, series = result.summary, result.series
        metrics: dict[str, Any] = self.experiment.analyse(sc, s, series)
        if {'q', 'p', 'leader_p', 'informed'} <= series.keys():
            # The three questions of every study (flock_swarm.reproduce.questions); an
            # experiment's own analysis keeps its keys.
            metrics = {**three_questions(sc, series), **metrics}
        metrics['settling_time'] = settling_time(series, sc.eta_tolerance)
        gains = s.get('adaptive_gain_final')
        if gains:
            metrics['adaptive_gain_mean'] = float(np.mean(gains))
        metrics['n_agents'] = sc.n_agents
        return {'point': plain_json(run.point), 'seed': run.seed, 'metrics': plain_json(metrics),
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


def mean_with_interval(values: list) -> dict:
    """Return the mean of the finite numbers of ``values``, its 95 % t interval (``None``
    below two values) and their count."""
    nums = [float(v) for v in values
            if v is not None and not isinstance(v, (str, bool)) and math.isfinite(float(v))]
    mean, interval = mean_interval(nums)
    return {'count': len(nums), 'mean': mean if nums else None,
            'interval': list(interval) if interval else None}


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
                      for _, key, _ in exp.columns},
            'questions': {key: mean_with_interval([m.get(key) for m in metrics])
                          for key in question_keys()}})
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
              cached_only: bool = False, live: Callable[[str], None] | None = None,
              held_out: bool | None = None) -> dict:
    """Run (or resume, or only read) the set-ups of one experiment; return their summary.

    Each set-up runs on its seeds (from 1) and, unless ``quick``, on as many held-out seeds
    from :data:`HELD_OUT_FIRST`: each set-up's summary then carries ``held_out`` (the
    criterion's judgement on those seeds) and ``fragile`` (whether the two verdicts differ).

    :param exp: the experiment.
    :param cache_dir: where the caches ``NAME.jsonl`` (and ``NAME_heldout.jsonl``) live.
    :param backend: where missing runs go.
    :param say: progress lines.
    :param quick: the experiment's ``--quick`` overrides and :data:`QUICK_SEEDS` seeds.
    :param cached_only: run nothing; use what the caches hold.
    :param live: rewrites the terminal's progress line, or ``None``.
    :param held_out: whether to judge the held-out seeds too (default: unless ``quick``).
    """
    held_out = not quick if held_out is None else held_out
    groups, notes, second = [], {}, []
    for setup in exp.setups:
        found = _setup_groups(exp, setup, cache_dir, backend, say, quick, cached_only, live)
        groups += found
        notes.update({label: setup.notes[label] for label, _, _ in found
                      if label in setup.notes})
        if held_out:
            second += _setup_groups(exp, setup, cache_dir, backend, say, quick, cached_only,
                                    live, held_out=True)
    res = summarise(exp, groups, notes)
    if held_out:
        attach_held_out(res, exp, second)
    # A spec written in the experiment's module has no file for `sweep` to read.
    res['commands'] = [f'sweep {s.name}' if isinstance(s.spec, str)
                       else 'python -m flock_swarm.reproduce --seeds-only' for s in exp.setups]
    res['caches'] = [str(cache_dir / f'{s.name}.jsonl') for s in exp.setups]
    return res


def _setup_groups(exp, setup, cache_dir: Path, backend, say, quick: bool, cached_only: bool,
                  live, held_out: bool = False) -> list[tuple[str, list[dict], int]]:
    """Return ``(label, completed records, planned seeds)`` of each point of a set-up, run
    (or read) on its own seeds or, with ``held_out``, on the held-out ones."""
    from flock_swarm.study.execute import execute
    seeds = QUICK_SEEDS if quick else None
    if held_out:
        spec, _ = study_runs(setup.spec, tuple(exp.quick) if quick else (), seeds)
        seeds = {'first': HELD_OUT_FIRST, 'count': len(spec.seeds)}
    spec, runs = study_runs(setup.spec, tuple(exp.quick) if quick else (), seeds)
    path = cache_dir / f'{spec.name}{HELD_OUT_SUFFIX if held_out else ""}.jsonl'
    if cached_only:
        cache = read_cache(path, ('digest', 'status'), say) if path.exists() else {}
        records = [cache[r.digest] for r in runs if r.digest in cache]
    else:
        records = execute(runs, path, SeedRecorder(exp), backend, spec.stack_agents, say,
                          live, prefix=spec.name + (HELD_OUT_SUFFIX if held_out else ''))[
                              'records']
    records = [r for r in records if r['status'] == 'completed']
    points = []
    for run in runs:
        if run.point not in points:
            points.append(run.point)
    return [(point_label(setup, point), [r for r in records if r['point'] == plain_json(point)],
             len(spec.seeds)) for point in points]


def attach_held_out(res: dict, exp, groups: list[tuple[str, list[dict], int]]) -> None:
    """Judge each set-up of :func:`summarise`'s ``res`` again on its held-out records
    (``groups``, in the same order); mark it ``fragile`` when the verdicts differ."""
    for setup, (label, records, planned) in zip(res['setups'], groups):
        judged = exp.criterion.judge(records)
        setup['held_out'] = {'label': label, 'seeds': len(records), 'planned': planned,
                             'judged': judged,
                             'stats': {key: distribution([r['metrics'].get(key)
                                                          for r in records])
                                       for _, key, _ in exp.columns},
                             'questions': {
                                 key: mean_with_interval([r['metrics'].get(key)
                                                          for r in records])
                                 for key in question_keys()}}
        setup['fragile'] = bool(records) and judged['verdict'] != setup['judged']['verdict']


def margin(judged: dict) -> float | None:
    """Return how far the interval clears the nearer edge of the band that supports the claim
    (negative: by how much it misses it; ``None`` without an interval).

    A reproduced verdict with a margin of 0.002 rests on an edge; the report says so.
    """
    interval, band = judged.get('interval'), judged.get('band')
    if not interval or not band:
        return None
    edges = [interval[0] - band[0]]
    if judged.get('statistic') != 'fraction of seeds':
        # A fraction's upper end (1) cannot be passed: only its lower edge counts.
        edges.append(band[1] - interval[1])
    return float(min(edges))


def run_studies(cache_dir: Path, backend, say: Callable[[str], None], quick: bool = False,
                cached_only: bool = False, live: Callable[[str], None] | None = None,
                long: bool = False, figures: Path = Path('docs/figures'),
                experiments=None, only: frozenset[str] | None = None) -> dict[str, dict]:
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
    :param only: the keys of the experiments whose studies run (or resume); the others only
        read their caches (``None``: every one).
    """
    from flock_swarm.reproduce.catalogue import all_experiments
    out = {}
    for exp in all_experiments() if experiments is None else experiments:
        read_only = (not long or quick) if exp.long_study else cached_only
        if only is not None and exp.key not in only:
            read_only = True
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


def section(exp, res: dict, figures: Path = Path('figures')) -> list[str]:
    """Return the report lines of an experiment's study: per set-up, the criterion's
    statistic with its interval and verdict (on both seed sets), the three questions, the
    curves' figure, then the distributions.

    :param figures: the figures' directory relative to the report.
    """
    lines = ['', '**Over seeds.** Each set-up is judged on its own by the criterion above '
             '(95 % intervals; the first set-up is the paper\'s), on its seeds from 1 and '
             f'again on held-out seeds from {HELD_OUT_FIRST}; a verdict that differs between '
             'the two sets is marked **fragile**. The margin is how far the interval clears '
             'the nearer edge of the values that support the claim (negative: how far it '
             'misses).', '',
             '| set-up | seeds (planned) | computing per run [s] | statistic [95 % interval] | '
             'margin | verdict | held-out seeds: statistic | held-out verdict |',
             '|---|---|---|---|---|---|---|---|']
    for s in res['setups']:
        lines.append(f'| {cell(s["label"])} | {s["seeds"]} ({s["planned"]}) | '
                     f'{fmt(s["cost_s"])} | {cell(judgement_text(s["judged"]))} | '
                     f'{fmt(margin(s["judged"]))} | **{s["judged"]["verdict"]}** | '
                     + held_out_cells(s) + ' |')
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
    lines += questions_lines(res)
    if res.get('curves_figure'):
        lines += ['', f'![{exp.key}: eta over tolerances and over time]'
                  f'({(figures / res["curves_figure"]).as_posix()})']
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


def held_out_cells(setup: dict) -> str:
    """Return the held-out columns of a set-up's row: its statistic and its verdict
    (**fragile** when it differs from the first set's)."""
    held = setup.get('held_out')
    if held is None:
        return 'not run | -'
    if not held['seeds']:
        return f'none of {held["planned"]} cached yet | -'
    verdict = f'**{held["judged"]["verdict"]}**'
    if setup.get('fragile'):
        verdict += ' (**fragile**)'
    return (f'{held["seeds"]} of {held["planned"]}: '
            f'{cell(judgement_text(held["judged"]))} | {verdict}')


def _mean_cell(d: dict) -> str:
    """Return ``mean [low, high]`` of :func:`mean_with_interval`'s result."""
    if not d or d['mean'] is None:
        return 'n/a'
    ci = f' [{fmt(d["interval"][0])}, {fmt(d["interval"][1])}]' if d['interval'] else ''
    return fmt(d['mean']) + ci


def answered(setup: dict) -> tuple[dict | None, str]:
    """Return the three questions' statistics of a set-up and which seeds they come from:
    its own seeds where their records answer them, else the held-out seeds' (records
    cached before the questions were recorded do not answer them)."""
    for q, which in ((setup.get('questions'), 'seeds from 1'),
                     ((setup.get('held_out') or {}).get('questions'), 'held-out seeds')):
        if q and q['whole_linked']['count']:
            return q, which
    return None, ''


def column_stats(setup: dict, key: str) -> dict | None:
    """Return the distribution of a column's metric over a set-up's seeds from 1, or over
    its held-out seeds where the first set's cached records lack it (``None``: neither)."""
    for stats in (setup.get('stats'), (setup.get('held_out') or {}).get('stats')):
        if stats and key in stats and stats[key]['count']:
            return stats[key]
    return None


def questions_cell(res: dict | None) -> str:
    """Return the summary's cell of the three questions for a study's first set-up (the
    paper's): whole (linked to an informed agent), with the leader (the group's velocity
    error), agreement (eta at 0.05 and 0.2 m/s), each a mean [95 % interval]."""
    if not res or not res.get('setups'):
        return '-'
    q, which = answered(res['setups'][0])
    if q is None:
        return 'not recorded yet'
    return (f'({which}, {q["whole_linked"]["count"]}) whole {_mean_cell(q["whole_linked"])}; '
            f'with leader {_mean_cell(q[LEADER_KEY])} m/s; '
            f'eta@0.05 {_mean_cell(q[tolerance_key(0.05)])}, '
            f'@0.2 {_mean_cell(q[tolerance_key(0.2)])}')


def questions_lines(res: dict) -> list[str]:
    """Return the three questions' table of a study: per set-up, is the flock whole, does
    it move with the leader, do the agents agree with it (eta over tolerances and over time),
    each a mean over the seeds with its 95 % interval."""
    setups = [(s, *answered(s)) for s in res['setups']]
    setups = [(s, q, which) for s, q, which in setups if q is not None]
    if not setups:
        return ['', 'The three questions (whole, with the leader, agreement) need runs recorded '
                'since they were added to the records: none of this study\'s cached runs has '
                'them yet.']
    tol = [tolerance_key(t) for t in TOLERANCES]
    times = [time_key(f) for f in TIMES]
    lines = ['', 'Three questions, apart (means over the seeds, 95 % intervals): **whole** - the '
             'fraction of agents in the largest component at t_final, and linked to an informed '
             'agent; **with the leader** - the velocity error of the group\'s mean '
             '`||mean p_i - p_gamma||` [m/s]; **agreement** - eta at t_final over tolerances, '
             'and eta at the scenario\'s tolerance over time (fractions of the run).', '',
             '| set-up | seeds | largest component | linked to informed | group velocity error '
             '[m/s] | ' + ' | '.join(f'eta @ {t:g} m/s' for t in TOLERANCES) + ' | '
             + ' | '.join(f'eta @ {round(100 * f)} % of t' for f in TIMES) + ' |',
             '|---|---|---|---|---|' + '---|' * (len(tol) + len(times))]
    for s, q, which in setups:
        count = max(v['count'] for v in q.values())
        lines.append(f'| {cell(s["label"])} | {count} ({which}) | '
                     f'{_mean_cell(q["whole_largest"])} | {_mean_cell(q["whole_linked"])} | '
                     f'{_mean_cell(q[LEADER_KEY])} | '
                     + ' | '.join(_mean_cell(q[k]) for k in tol + times) + ' |')
    return lines


def curves_figure(res: dict, title: str, path: Path) -> str | None:
    """Draw each set-up's eta against the tolerance (at t_final) and over time (at the
    scenario's tolerance), means over the seeds with their 95 % intervals; return the file's
    name (``None`` when no cached run has the curves yet)."""
    setups = [(s, answered(s)[0]) for s in res['setups']]
    setups = [(s, q) for s, q in setups if q is not None]
    if not setups:
        return None
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=FIG_SIZE)
    for s, q in setups:
        for ax, keys, x in ((ax1, [tolerance_key(t) for t in TOLERANCES], TOLERANCES),
                            (ax2, [time_key(f) for f in TIMES], TIMES)):
            d = [q[k] for k in keys]
            mean = np.array([np.nan if v['mean'] is None else v['mean'] for v in d])
            low = np.array([v['interval'][0] if v['interval'] else m for v, m in zip(d, mean)])
            high = np.array([v['interval'][1] if v['interval'] else m
                             for v, m in zip(d, mean)])
            ax.errorbar(x, mean, yerr=[mean - low, high - mean], marker='o', ms=3, capsize=2,
                        label=s['label'])
    ax1.set_xscale('log')
    ax1.set_xlabel('tolerance [m/s]')
    ax1.set_ylabel('eta at t_final')
    ax1.set_title(f'{title}: eta over tolerances', fontsize=8)
    ax2.set_xlabel('fraction of the run')
    ax2.set_ylabel("eta at the scenario's tolerance")
    ax2.set_title('eta over time', fontsize=8)
    for ax in (ax1, ax2):
        ax.set_ylim(-0.02, 1.02)
        ax.grid(True, alpha=0.3)
    ax1.legend(loc='best', fontsize=7)
    return save_figure(fig, path).name


def _seed_text(seeds: list[int]) -> str:
    """Return ``seeds 1 .. 20`` or the list."""
    if not seeds:
        return 'none yet'
    if len(seeds) == 1:
        return f'seed {seeds[0]}'
    if seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f'seeds {seeds[0]} .. {seeds[-1]}'
    return 'seeds ' + ', '.join(map(str, seeds))
