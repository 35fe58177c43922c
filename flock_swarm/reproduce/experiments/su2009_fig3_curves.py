"""Su, Wang, Lin 2009, Fig. 3 under four variants: linear and bounded navigational feedback,
100 s and 300 s runs (specs ``config/sweeps/reproduce_su2009_fig3_*.yaml``), each curve
judged on its own at the paper's anchors."""

from pathlib import Path
from typing import Any, Callable

from flock_swarm.outputs import plain_json
from flock_swarm.reproduce.common import fmt, pyplot, save_figure
from flock_swarm.reproduce.experiments import su2009_fig3_sweep as sweep
from flock_swarm.reproduce.experiments.su2009_fig3_sweep import (FIG3_PAPER_DELTA,
                                                                 FIG3_PAPER_ETA, aggregate_fig3,
                                                                 anchor_eta, anchor_row,
                                                                 delta_for_eta)
from flock_swarm.reproduce.plan import FIG3_SIZES
from flock_swarm.reproduce.seeds import SEEDS_CHEAP
from flock_swarm.study.spec import plan_runs

#: Issue 15, section 3: the four Fig. 3 curves, ``(spec, label)`` (config/sweeps/).
FIG3_CURVES = (('reproduce_su2009_fig3_linear_100s', 'linear navigation, 100 s'),
               ('reproduce_su2009_fig3_bounded_100s', 'bounded navigation, 100 s'),
               ('reproduce_su2009_fig3_linear_300s', 'linear navigation, 300 s'),
               ('reproduce_su2009_fig3_bounded_300s', 'bounded navigation, 300 s'))


def fig3_curves(cache_dir: Path, backend, say: Callable[[str], None], run: bool,
                figures: Path, live: Callable[[str], None] | None = None) -> dict:
    """Read (``run``: run or resume) the four Fig. 3 curves; aggregate and draw them.

    :param cache_dir: where the caches ``SPEC.jsonl`` live.
    :param backend: where missing runs go when ``run``.
    :param say: progress lines.
    :param run: run the missing runs (hours for the full curves) instead of only reading.
    :param figures: where ``su2009_fig3_curves.png`` goes.
    :param live: rewrites the terminal's progress line, or ``None``.
    :return: ``{'curves': [{label, spec, runs_planned, runs_cached, realisations_min,
        realisations_max, complete, rows, delta_for_eta80_N<n>}], 'figure': name}``
        (no figure while every cache is empty).
    """
    from flock_swarm.presets import resolve
    from flock_swarm.study.cache import read_cache
    from flock_swarm.study.execute import execute
    from flock_swarm.study.spec import read_spec
    curves = []
    for name, label in FIG3_CURVES:
        spec = read_spec(resolve(name, 'sweeps', 'spec'))
        runs = plan_runs(spec)
        path = cache_dir / f'{name}.jsonl'
        if run:
            records = execute(runs, path, sweep.fig3_record, backend, spec.stack_agents, say,
                              live, prefix=name, describe=sweep.describe_fig3)['records']
        else:
            cache = read_cache(path, ('digest', 'status'), say)
            records = [cache[r.digest] for r in runs if r.digest in cache]
        records = [r for r in records if r['status'] == 'completed']
        rows = aggregate_fig3(records)
        points = len(runs) // len(spec.seeds)
        counts = [r['count'] for r in rows]
        curve: dict[str, Any] = {
            'label': label, 'spec': name, 'runs_planned': len(runs),
            'runs_cached': len(records), 'realisations_planned': len(spec.seeds),
            'realisations_min': min(counts) if len(rows) == points else 0,
            'realisations_max': max(counts, default=0),
            'complete': len(records) == len(runs), 'rows': rows,
            'points': points,
            'cost_s': sum(r['wall_time_s'] for r in records) / len(records) if records else None,
            'judged': sweep.judge_anchors(rows)}
        for n in FIG3_SIZES:
            curve[f'delta_for_eta80_N{n}'] = delta_for_eta(rows, n, FIG3_PAPER_ETA)
        curves.append(curve)
    fig = None
    if any(c['runs_cached'] for c in curves):
        fig = figure_fig3_curves(curves, figures / 'su2009_fig3_curves.png').name
    return {'curves': plain_json(curves), 'figure': fig}


def figure_fig3_curves(curves: list[dict], path: Path) -> Path:
    """Draw the four Fig. 3 curves (one panel each) against the paper's two anchors."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(8.0, 5.6), sharex=True, sharey=True)
    for ax, curve in zip(axes.flat, curves):
        for k, n in enumerate(FIG3_SIZES):
            pts = sorted((r for r in curve['rows'] if r['n_agents'] == n),
                         key=lambda r: r['delta'])
            if pts:
                ax.errorbar([r['delta'] for r in pts], [r['mean'] for r in pts],
                            yerr=[r['sem'] for r in pts], marker='o', ms=2.5, capsize=2,
                            lw=1, color=f'C{k}', label=f'N = {n}')
        for n, delta in FIG3_PAPER_DELTA.items():
            ax.plot(delta, FIG3_PAPER_ETA, 'kx', ms=7)
        ax.axhline(FIG3_PAPER_ETA, color='0.5', ls=':', lw=1)
        done = 'complete' if curve['complete'] else \
            f'{curve["runs_cached"]} of {curve["runs_planned"]} runs'
        ax.set_title(f'{curve["label"]} ({done})')
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlim(0.0, 1.02)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc='lower right')
    for ax in axes[1]:
        ax.set_xlabel('delta (x: the paper\'s anchors)')
    for ax in axes[:, 0]:
        ax.set_ylabel('mean eta')
    return save_figure(fig, path)


def fig3_curves_section(res: dict, figures: Path) -> list[str]:
    """Return the report lines of the four Fig. 3 curves (from whatever the caches hold).

    :param res: :func:`fig3_curves`' result.
    :param figures: the figures' directory relative to the report.
    """
    lines = ['', '### The four curves: linear and bounded navigation, 100 s and 300 s', '',
             'Sweep specs `config/sweeps/reproduce_su2009_fig3_*.yaml` (the grid above; the '
             'density 0.05 kept), run by `python -m flock_swarm.reproduce --fig3-curves` (hours '
             'on two cores, resumable) into the caches beside the other studies; every '
             'invocation draws whatever they hold. The paper\'s anchors: delta = 0.27 at '
             'N = 100 and 0.10 at N = 1000 for eta = 0.8, and "the larger the group, the '
             'smaller the fraction needed".', '',
             '| curve | runs (planned) | realisations per point | delta at eta = 0.8, N = 100 '
             '(paper 0.27) | N = 300 | N = 500 | N = 1000 (paper 0.10) | status |',
             '|---|---|---|---|---|---|---|---|']
    for c in res['curves']:
        real = (f'{c["realisations_min"]}' if c['realisations_min'] == c['realisations_max']
                else f'{c["realisations_min"]} - {c["realisations_max"]}')
        status = 'complete' if c['complete'] else ('not run yet' if not c['runs_cached']
                                                   else 'incomplete')
        lines.append(f'| {c["label"]} | {c["runs_cached"]} ({c["runs_planned"]}) | '
                     f'{real} (of {c["realisations_planned"]}) | '
                     + ' | '.join(fmt(c[f'delta_for_eta80_N{n}']) for n in FIG3_SIZES)
                     + f' | {status} |')
    lines += fig3_curves_anchors(res['curves'])
    lines += curve_verdicts(res['curves'])
    if res['figure'] is not None:
        lines += ['', f'![su2009_fig3_curves]({(figures / res["figure"]).as_posix()})']
    return lines


def curve_verdicts(curves: list[dict]) -> list[str]:
    """Return the verdict of each curve on its own, by the criterion of Fig. 3 (the mean eta
    at both anchors with its 95 % t interval against 0.8 ± 0.05)."""
    lines = ['', 'Each curve judged on its own by the criterion above (none is picked among '
             'the four):', '', '| curve | at the anchors: mean eta [95 % interval] (runs) | '
             'verdict |', '|---|---|---|']
    for c in curves:
        lines.append(f'| {c["label"]} | {sweep.anchors_text(c["judged"])} | '
                     f'**{c["judged"]["verdict"]}** |')
    lines += ['', f'*{FIG3_CURVES[0][1]}* is the preset\'s own sweep above: the same '
              'runs (equal in every field but the wall time; the spec only names the '
              'default `protocol.navigation: linear`), so its verdict is the preset\'s.']
    for c in curves:
        missing = SEEDS_CHEAP - c['realisations_planned']
        if missing > 0 and c['cost_s'] is not None:
            lines += ['', f'*{c["label"]}* keeps {c["realisations_planned"]} realisations per '
                      f'point although a run costs {fmt(c["cost_s"])} s of computing on '
                      f'average: the {missing} more per point of a {SEEDS_CHEAP}-realisation '
                      f'curve would take about {missing * c["points"] * c["cost_s"] / 60:.0f} '
                      'CPU-minutes, beyond the 40 a study was given in this round.']
    return lines


def fig3_curves_anchors(curves: list[dict]) -> list[str]:
    """Return the report lines comparing each curve with the paper at its anchor points
    (eta = 0.8 at delta = 0.27 for N = 100 and 0.10 for N = 1000) and its trend, with the
    verdict written from the numbers."""
    lines = ['', 'Mean eta over the realisations at the paper\'s two anchor points (the '
             f'paper: {FIG3_PAPER_ETA:g} at both) and the trend of the fraction needed:', '',
             '| curve | eta at N = 100, delta = 0.27 | eta at N = 1000, delta = 0.1 | '
             'delta at eta = 0.8 falls from N = 100 to 1000 |', '|---|---|---|---|']
    scores = []
    for c in curves:
        at = {n: anchor_row(c, n) for n in FIG3_PAPER_DELTA}
        needed = [c[f'delta_for_eta80_N{n}'] for n in FIG3_SIZES]
        if c['runs_cached'] and None not in needed:
            falls = 'yes' if needed[-1] < needed[0] else 'no'
            trend = f'{falls} ({fmt(needed[0])} -> {fmt(needed[-1])})'
        else:
            trend = 'n/a'
        cells = [f'{fmt(r["mean"])} ± {fmt(r["sem"])} ({r["count"]} runs)' if r else 'n/a'
                 for r in at.values()]
        lines.append(f'| {c["label"]} | {cells[0]} | {cells[1]} | {trend} |')
        if c['complete'] and all(at.values()):
            scores.append((sum(abs(r['mean'] - FIG3_PAPER_ETA) for r in at.values()), c,
                           at, trend))
    if scores:
        done = ', '.join(c['label'] for _, c, _, _ in scores)
        near = [c['label'] for _, c, at, _ in scores
                if all(abs(r['mean'] - FIG3_PAPER_ETA) <= 0.05 for r in at.values())]
        parts = []
        for n, delta in FIG3_PAPER_DELTA.items():
            _, c, at, _ = min(scores, key=lambda item: abs(item[2][n]['mean'] - FIG3_PAPER_ETA))
            parts.append(f'at N = {n}, delta = {delta:g} it is {c["label"]} (eta '
                         f'{fmt(at[n]["mean"])})')
        falls = [c['label'] for _, c, _, trend in scores if trend.startswith('yes')]
        each = []
        for n, delta in FIG3_PAPER_DELTA.items():
            close = [c['label'] for _, c, at, _ in scores
                     if abs(at[n]['mean'] - FIG3_PAPER_ETA) <= 0.05]
            each.append(f'at N = {n}, delta = {delta:g}: '
                        + (', '.join(f'**{c}**' for c in close) if close else 'none'))
        lines += ['', f'Of the complete curves ({done}): within 0.05 of eta = 0.8 at both '
                  'anchors: ' + (', '.join(near) if near else '**none**') + '; at one anchor, '
                  + '; '.join(each) + '. Closest to '
                  'the paper ' + '; '.join(parts) + '. The fraction needed for eta = 0.8 '
                  'falls from N = 100 to N = 1000 in: '
                  + (', '.join(falls) if falls else 'none') + '.']
    return lines


def fig3_curves_tested(curves: list[dict]) -> str:
    """Return what the complete Fig. 3 curves say of the bounded-navigation and run-length
    hypotheses, against the linear 100 s curve at the paper's anchors ('' without them)."""
    by_spec = {c['spec']: c for c in curves if c['complete']}
    base = by_spec.get(FIG3_CURVES[0][0])
    if base is None:
        return ''
    (small, d_small), (large, d_large) = sorted(FIG3_PAPER_DELTA.items())
    ref = [anchor_eta(base, small), anchor_eta(base, large)]
    parts = []
    for spec, what in ((FIG3_CURVES[1][0], 'bounded navigation (Olfati-Saber 2006) at the '
                        'same 100 s'),
                       (FIG3_CURVES[2][0], 'a 300 s run with the linear term'),
                       (FIG3_CURVES[3][0], 'bounded navigation over 300 s')):
        c = by_spec.get(spec)
        if c is None:
            continue
        got = [anchor_eta(c, small), anchor_eta(c, large)]
        parts.append(f'{what} gives {fmt(got[0])} and {fmt(got[1])}')
    if not parts:
        return ''
    text = (f'The four curves below test the last two hypotheses. At the paper\'s anchors '
            f'(N = {small}, delta = {d_small:g}; N = {large}, delta = {d_large:g}; the paper: '
            f'eta = {FIG3_PAPER_ETA:g} at both) the linear term over 100 s gives eta = '
            f'{fmt(ref[0])} and {fmt(ref[1])}; ' + '; '.join(parts) + '.')
    best = min(by_spec.values(), key=lambda c: sum(
        abs((anchor_eta(c, n) or 0.0) - FIG3_PAPER_ETA) for n in (small, large)))
    needed = [best[f'delta_for_eta80_N{n}'] for n in FIG3_SIZES]
    if None not in needed:
        falls = all(b < a for a, b in zip(needed, needed[1:]))
        text += (f' Closest to the paper over both anchors: {best["label"]}, whose fraction '
                 'needed for eta = 0.8 is ' + ', '.join(
                     f'{fmt(d)} (N = {n})' for d, n in zip(needed, FIG3_SIZES))
                 + (', falling with every larger group as the paper says' if falls else
                    ', not falling steadily with N')
                 + f' (the paper: {d_small:g} at N = {small}, {d_large:g} at N = {large}).')
    return text
