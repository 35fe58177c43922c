"""The experiments over many seeds: distributions, the fraction of seeds meeting each claim, and
the verdicts.

Each study is a sweep spec of ``config/sweeps/`` (``reproduce_<experiment>.yaml``: the preset,
its variants as axes, the seeds, from seed 1: the preset's own seed stays the figure); its runs
go through :func:`flock_swarm.study.execute.execute` (the stacks, backends and checked,
resumable cache of ``sweep``) with :class:`SeedRecorder`, which keeps the experiment's own
analysis of each run (the numbers of its table) instead of ``sweep``'s summary columns. The
caches (``NAME.jsonl``, one line per run) are small and committed under
``docs/reproduction/runs/``: the report renders from whatever they hold and states the count.
"""

import math
from dataclasses import dataclass, field, replace
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
#: A claim counts as reproduced when at least this fraction of the seeds meets it.
MAJORITY = 0.5


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


def analyses() -> dict[str, Callable[[Scenario, dict, dict], dict]]:
    """Return the analysis of each preset a study runs (the experiments' own)."""
    from flock_swarm.reproduce.catalogue import ANALYSES
    return ANALYSES


@dataclass(frozen=True)
class SeedRecorder:
    """The record of one run of a study: point, seed, the experiment's analysis, provenance.

    :ivar preset: the preset whose analysis applies (the spec's ``scenario``).
    """

    preset: str

    def __call__(self, run: Run, sc: Scenario, result: SimResult) -> dict:
        """Return the record (non-finite values as ``None``)."""
        s, series = result.summary, result.series
        metrics: dict[str, Any] = analyses()[self.preset](sc, s, series)
        metrics['settling_time'] = settling_time(series, sc.eta_tolerance)
        gains = s.get('adaptive_gain_final')
        if gains:
            metrics['adaptive_gain_mean'] = float(np.mean(gains))
        metrics['n_agents'] = sc.n_agents
        return {'point': plain(run.point), 'seed': run.seed, 'metrics': plain(metrics),
                'status': s['status'], 'wall_time_s': s['wall_time_s'],
                'flock_swarm_version': __version__}


@dataclass(frozen=True)
class Study:
    """One experiment over seeds: its specs, the paper's claim per seed, what is shown.

    :ivar key: the experiment.
    :ivar specs: ``(spec name, label)`` of each set-up; the first is the paper's.
    :ivar claim: the claim a seed meets, in words (Markdown).
    :ivar meets: whether a run's metrics meet it.
    :ivar shown: ``(label, metric, the paper's value)`` of the distribution table.
    :ivar labels: a label per point of a spec with axes (its axis values), else the spec's.
    """

    key: str
    specs: tuple[tuple[str, str], ...]
    claim: str
    meets: Callable[[dict], bool]
    shown: tuple[tuple[str, str, str], ...]
    labels: dict = field(default_factory=dict)
    #: A sentence comparing the set-ups seed by seed (from ``summarise``'s groups), or None.
    paired: Callable[[list[tuple[str, list[dict], int]]], str] | None = None


def _eta_at_least(level: float) -> Callable[[dict], bool]:
    """Return the claim "eta >= level" (the paper's count of agents or more)."""
    return lambda m: m['eta'] is not None and m['eta'] >= level - 1e-12


def longer_run(groups: list[tuple[str, list[dict], int]]) -> str:
    """Return what the last set-up (the same runs, longer) says of the first, seed by seed:
    how many of the seeds run both ways settle within each horizon, when, and how much the
    largest adaptive gain grew in the extra time ('' without a seed in common)."""
    short = {r['seed']: r['metrics'] for r in groups[0][1]}
    long = {r['seed']: r['metrics'] for r in groups[-1][1]}
    both = sorted(set(short) & set(long))
    if not both or len(groups) < 2:
        return ''
    t_short = max(short[k]['t_final'] for k in both)
    t_long = max(long[k]['t_final'] for k in both)
    settled = [k for k in both if long[k]['settling_time'] is not None]
    late = [long[k]['settling_time'] for k in settled if short[k]['settling_time'] is None]
    growth = [long[k]['adaptive_gain_max'] / short[k]['adaptive_gain_max'] for k in both
              if short[k].get('adaptive_gain_max') and long[k].get('adaptive_gain_max')]
    text = (f'Seed by seed ({len(both)} seeds run for both {fmt(t_short)} s and '
            f'{fmt(t_long)} s; the first {fmt(t_short)} s of a longer run are the shorter '
            f'run): settled within {fmt(t_short)} s: '
            f'{sum(1 for k in both if short[k]["settling_time"] is not None)}; within '
            f'{fmt(t_long)} s: {len(settled)}')
    if late:
        text += (f', those settling only after {fmt(t_short)} s at {fmt(min(late))} .. '
                 f'{fmt(max(late))} s')
    if growth:
        text += (f'. The largest adaptive gain at {fmt(t_long)} s is {fmt(min(growth))} .. '
                 f'{fmt(max(growth))} times its value at {fmt(t_short)} s')
    return text + '.'


def _all_aligned(m: dict) -> bool:
    """Jadbabaie Theorem 4: every follower ends within the heading tolerance of theta_0."""
    return m['followers_aligned'] == m['n_agents']


SU_ETA_ROWS = (('eta at t_final', 'eta', ''),
               ('agents linked to an informed agent', 'linked_to_informed', '-'),
               ('r-disk components at t_final', 'components_final', '-'))
STUDIES = (
    Study('su2009_fig2', (('reproduce_su2009_fig2', 'as printed'),),
          'eta >= 0.86 (at least the paper\'s 86 of 100 agents with p_gamma, 0.05 m/s)',
          _eta_at_least(0.86), ((SU_ETA_ROWS[0][0], 'eta', '0.86'),) + SU_ETA_ROWS[1:]),
    Study('su2009_fig7', (('reproduce_su2009_fig7', ''),),
          'eta >= 0.89 (at least the paper\'s 89 of 100 agents with p_gamma, 0.05 m/s)',
          _eta_at_least(0.89), ((SU_ETA_ROWS[0][0], 'eta', '0.89'),) + SU_ETA_ROWS[1:]
          + (('max ‖p_i - p_gamma‖ at t_final [m/s]', 'velocity_mismatch_max', '-'),),
          labels={('informed', 'linear'): 'as printed (f_gamma to the informed, linear)',
                  ('all', 'linear'): 'f_gamma to all',
                  ('informed', 'bounded'): 'bounded navigation (Olfati-Saber 2006)',
                  ('all', 'bounded'): 'f_gamma to all, bounded navigation'}),
    Study('os2003_sink', (('reproduce_os2003_sink', '300 s'),
                          ('reproduce_os2003_sink_600s', '600 s')),
          'one flock whose topology no longer switches (1 component, no switch over the last '
          'quarter of the run)',
          lambda m: m['components_final'] == 1 and m['topology_changes_last_quarter'] == 0,
          (('time of the last topology switch [s]', 'last_topology_change_t', 'finite'),
           ('switches over the last quarter', 'topology_changes_last_quarter', '0'),
           ('r-disk components at t_final', 'components_final', '1'),
           ('‖qbar - q_d‖ at t_final [m]', 'com_position_error', '-'))),
    Study('zhou2012_sec51', (('reproduce_zhou2012_sec51', 'as printed'),),
          'every velocity within the tolerance (0.1 m/s) of the leader\'s at 30 s (eta = 1)',
          _eta_at_least(1.0),
          (('max ‖v_i - v_l‖ at t_final [m/s]', 'velocity_mismatch_max', '-> 0'),
           ('settling time [s] (max ‖v_i - v_l‖ stays <= 0.1 m/s)', 'settling_time',
            '< 30'),
           ('max change of pair distances over the last 5 s [m]',
            'pair_distance_drift_last_5s', '-> 0'),
           ('largest adaptive gain h_i at t_final', 'adaptive_gain_max', '-'))),
    Study('zhou2012_sec52', (('reproduce_zhou2012_sec52', 'the 6 highest-degree agents'),
                             ('reproduce_zhou2012_sec52_greedy', 'greedy Theorem 1 set'),
                             ('reproduce_zhou2012_sec52_90s',
                              'the 6 highest-degree agents, run for 90 s (settling after the '
                              'paper\'s 30 s counts here)')),
          'converged within the run: max ‖v_i - v_l‖ <= 0.1 m/s from some time on (a settling '
          'time exists)',
          lambda m: m['settling_time'] is not None,
          (('settling time [s] (max ‖v_i - v_l‖ stays <= 0.1 m/s)', 'settling_time', '< 30'),
           ('max ‖v_i - v_l‖ at t_final [m/s]', 'velocity_mismatch_max', '-> 0'),
           ('largest max ‖v_i - v_l‖ during the run [m/s]', 'velocity_mismatch_peak', '-'),
           ('lambda_max of the minor of the informed set', 'lambda_max_minor_ours', '-0.9284'),
           ('largest adaptive gain h_i at t_final (h(0) = 1)', 'adaptive_gain_max', '-'),
           ('mean adaptive gain at t_final', 'adaptive_gain_mean', '-')),
          paired=longer_run),
    Study('yu2010_sec41', (('reproduce_yu2010_sec41', 'as printed'),),
          'every velocity within the tolerance of the leader\'s at t_final (eta = 1, Theorem 1 '
          '(ii))',
          _eta_at_least(1.0),
          (('max ‖v_i - v_o‖ at t_final [m/s]', 'velocity_mismatch_max', '-> 0'),
           ('|r_a1 - r_o1| at t_final [m]', 'ra_error_component1', '-> 0'),
           ('|r_a2 - r_o2| at t_final [m]', 'ra_error_component2', '-> 0'),
           ('max |r_a - r_o| over the last 5 s [m]', 'ra_error_max_late', '-> 0'))),
    Study('jadbabaie2003_leader',
          (('reproduce_jadbabaie2003_linked', 'premise holding (jadbabaie2003_linked)'),
           ('reproduce_jadbabaie2003_leader', 'the preset (premise failing)')),
          'every follower within 1e-3 rad of theta_0 at t_final', _all_aligned,
          (('followers aligned', 'followers_aligned', 'all'),
           ('fraction of steps with every follower linked', 'linked_fraction_of_steps',
            'premise'),
           ('max |theta_i - theta_0| at t_final [rad]', 'heading_error_max', '-> 0'))),
)
STUDY_OF = {s.key: s for s in STUDIES}


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


def point_label(study: Study, spec_label: str, point: dict) -> str:
    """Return the label of a set-up: the spec's, or its point's axis values."""
    if not point:
        return spec_label
    key = tuple(str(v) for v in point.values())
    return study.labels.get(key, ', '.join(f'{k} = {v}' for k, v in point.items()))


def summarise(study: Study, groups: list[tuple[str, list[dict], int]]) -> dict:
    """Return the distributions, fractions and verdict of a study.

    :param study: the study.
    :param groups: ``(label, records, planned seeds)`` per set-up, the paper's first.
    :return: ``{'setups': [...], 'verdict': text, 'claim': text}``.
    """
    setups = []
    for label, records, planned in groups:
        metrics = [r['metrics'] for r in records]
        met = sum(1 for m in metrics if study.meets(m))
        setups.append({
            'label': label, 'seeds': len(records), 'planned': planned,
            'seed_list': sorted(r['seed'] for r in records),
            'met': met, 'fraction': met / len(records) if records else None,
            'stats': {key: distribution([m.get(key) for m in metrics])
                      for _, key, _ in study.shown}})
    out = {'setups': setups, 'verdict': verdict(setups), 'claim': study.claim}
    if study.paired is not None:
        out['paired'] = study.paired(groups)
    return out


def verdict(setups: list[dict]) -> str:
    """Return the verdict: ``reproduced`` when most seeds of the paper's set-up (the first)
    meet the claim, ``reproduced under X`` when most of a variant's do, else ``not
    reproduced`` (``not run yet`` without records)."""
    if not setups or not setups[0]['seeds']:
        return 'not run yet'
    if setups[0]['fraction'] >= MAJORITY:
        return 'reproduced'
    for s in setups[1:]:
        if s['seeds'] and s['fraction'] >= MAJORITY:
            return f'reproduced under variant: {s["label"]}'
    return 'not reproduced'


def study_runs(name: str, overrides: tuple[str, ...] = (), seeds: int | None = None):
    """Return the spec of a study and its planned runs (``--quick``: overrides, few seeds)."""
    from flock_swarm.presets import resolve
    from flock_swarm.study.spec import plan_runs, read_spec
    spec = read_spec(resolve(name, 'sweeps', 'spec'), overrides, seeds)
    # The quick overrides win over the spec's own fixed values (a 300 s run, say).
    keys = {o.split('=', 1)[0] for o in overrides}
    spec = replace(spec, fixed=tuple((k, v) for k, v in spec.fixed if k not in keys))
    return spec, plan_runs(spec)


def run_studies(cache_dir: Path, backend, say: Callable[[str], None], quick: bool = False,
                cached_only: bool = False, live: Callable[[str], None] | None = None
                ) -> dict[str, dict]:
    """Run (or resume, or only read) every study; return its summary by experiment.

    :param cache_dir: where the caches ``NAME.jsonl`` live.
    :param backend: where missing runs go.
    :param say: progress lines.
    :param quick: the experiments' ``--quick`` overrides and :data:`QUICK_SEEDS` seeds.
    :param cached_only: run nothing; use what the caches hold.
    :param live: rewrites the terminal's progress line, or ``None``.
    """
    from flock_swarm.reproduce.catalogue import EXPERIMENTS
    from flock_swarm.study.execute import execute
    quick_of = {e.key: e.quick for e in EXPERIMENTS}
    out = {}
    for study in STUDIES:
        groups = []
        for name, label in study.specs:
            spec, runs = study_runs(name, tuple(quick_of.get(study.key, ())) if quick else (),
                                    QUICK_SEEDS if quick else None)
            path = cache_dir / f'{spec.name}.jsonl'
            if cached_only:
                cache = read_cache(path, ('digest', 'status'), say)
                records = [cache[r.digest] for r in runs if r.digest in cache]
            else:
                records = execute(runs, path, SeedRecorder(spec.scenario), backend,
                                  spec.stack_agents, say, live, prefix=spec.name)['records']
            records = [r for r in records if r['status'] == 'completed']
            points = []
            for run in runs:
                if run.point not in points:
                    points.append(run.point)
            for point in points:
                mine = [r for r in records if r['point'] == plain(point)]
                groups.append((point_label(study, label, point), mine, len(spec.seeds)))
        res = summarise(study, groups)
        res['commands'] = [f'sweep {name}' for name, _ in study.specs]
        res['caches'] = [str(cache_dir / f'{name}.jsonl') for name, _ in study.specs]
        out[study.key] = res
    return out


def _stat(d: dict) -> str:
    """Return ``mean ± std [min, max]`` of a distribution."""
    if not d['count']:
        return 'n/a' + (f' ({d["missing"]} without a value)' if d['missing'] else '')
    text = f'{fmt(d["mean"])} ± {fmt(d["std"])} [{fmt(d["min"])}, {fmt(d["max"])}]'
    return text + (f'; {d["missing"]} without a value' if d['missing'] else '')


def section(study: Study, res: dict) -> list[str]:
    """Return the report lines of a study: the table of distributions and the verdict."""
    lines = ['', f'**Over seeds.** Claim per seed: {res["claim"]}. Verdict: '
             f'**{res["verdict"]}**.', '',
             '| set-up | seeds (planned) | meeting the claim | '
             + ' | '.join(f'{cell(label)} (`{key}`; paper: {cell(paper)})'
                          for label, key, paper in study.shown) + ' |',
             '|---|---|---|' + '---|' * len(study.shown)]
    for s in res['setups']:
        frac = f'{s["met"]} of {s["seeds"]} ({fmt(s["fraction"])})' if s['seeds'] else '-'
        lines.append(f'| {cell(s["label"])} | {s["seeds"]} ({s["planned"]}) | {frac} | '
                     + ' | '.join(cell(_stat(s['stats'][key])) for _, key, _ in study.shown)
                     + ' |')
    if res.get('paired'):
        lines += ['', res['paired']]
    seeds = sorted({x for s in res['setups'] for x in s['seed_list']})
    lines += ['', 'Values: mean ± standard deviation [min, max] over the seeds run '
              f'({_seed_text(seeds)}). Commands: '
              + ', '.join(f'`{c}`' for c in res['commands'])
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
    if seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f'seeds {seeds[0]} .. {seeds[-1]}'
    return 'seeds ' + ', '.join(map(str, seeds))
