"""Su, Wang, Lin 2009, Fig. 3: the sweep of eta against the informed fraction delta per group
size N (its plan, the record of each run, the aggregation over realisations, the paper's
anchors and their verdict), on the machinery of :mod:`flock_swarm.study`."""

from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from flock_swarm import __version__
from flock_swarm.core.run import RunResult
from flock_swarm.core.scenario import Scenario
from flock_swarm.reproduce import stats
from flock_swarm.reproduce.common import fmt, linked_to_informed, pyplot, save_figure
from flock_swarm.reproduce.experiment import ETA_MARGIN
from flock_swarm.reproduce.plan import Plan
from flock_swarm.study.spec import Run, SweepSpec, parse_spec, plan_runs

#: Su, Wang, Lin 2009, Section V.A: Fig. 3 keeps the density N / L^2 at this value.
FIG3_DENSITY = 0.05

#: Realisations per (N, delta) point in Su 2009 Fig. 3.
FIG3_PAPER_REALISATIONS = 50

#: Su 2009 Section V.A: the eta level the text reads off Fig. 3, and the delta it quotes.
FIG3_PAPER_ETA = 0.8
FIG3_PAPER_DELTA = {100: 0.27, 1000: 0.10}

#: Fig. 3 runs also record eta at these tolerances [m/s] (the paper gives none) ...
FIG3_TOLERANCES = (0.05, 0.15, 0.5, 1.0)

#: ... and eta every this many seconds (the paper gives no run length).
FIG3_ETA_EVERY = 10.0

#: The loose tolerance [m/s] the report also shows Fig. 3 at.
FIG3_LOOSE = 1.0

#: Fig. 3 runs of one N and seed are stacked (:func:`~flock_swarm.core.run.simulate_stack`) up
#: to about this many agents per stack: the per-step cost of Python is then paid once for
#: several swarms (measured: 0.70 against 1.20 CPU-s per 30 s run at N = 300 stacked by 10,
#: 9 % less at N = 1000 stacked by 2), and the pool still gets several jobs per realisation.
FIG3_STACK_AGENTS = 3000


def figure_fig3(rows: list[dict], loose: list[dict], tolerance: float | None,
                path: Path) -> Path:
    """Draw Su 2009 Fig. 3: mean eta against delta per N (error bars: standard error).

    :param rows: the aggregated eta at the preset's tolerance.
    :param loose: the same at the loose tolerance ``FIG3_LOOSE`` (dashed).
    :param tolerance: the preset's tolerance, for the legend.
    :param path: the PNG to write.
    :return: ``path``.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for k, n in enumerate(sorted({r['n_agents'] for r in rows})):
        pts = sorted((r for r in rows if r['n_agents'] == n and r['count']),
                     key=lambda r: r['delta'])
        if not pts:
            continue
        color = f'C{k}'
        ax.errorbar([r['delta'] for r in pts], [r['mean'] for r in pts],
                    yerr=[r['sem'] for r in pts], marker='o', ms=3, capsize=2, lw=1,
                    color=color, label=f'N = {n} ({min(r["count"] for r in pts)} runs/point)')
        dashed = sorted((r for r in loose if r['n_agents'] == n), key=lambda r: r['delta'])
        ax.plot([r['delta'] for r in dashed], [r['mean'] for r in dashed], ls='--', lw=0.8,
                color=color)
    ax.plot([], [], 'k-', lw=1, label=f'tolerance {fmt(tolerance)} m/s (preset)')
    ax.plot([], [], 'k--', lw=0.8, label=f'tolerance {FIG3_LOOSE:g} m/s')
    ax.axhline(FIG3_PAPER_ETA, color='0.5', ls=':', lw=1)
    for n, delta in FIG3_PAPER_DELTA.items():
        ax.plot(delta, FIG3_PAPER_ETA, 'kx', ms=8)
        ax.annotate(f'paper, N = {n}', (delta, FIG3_PAPER_ETA), textcoords='offset points',
                    xytext=(4, 4), fontsize=7)
    ax.set_xlabel('fraction of informed agents delta')
    ax.set_ylabel('eta (mean over realisations)')
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlim(0.0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.set_title('Su 2009 Fig. 3: eta vs delta, density 0.05 (x: the text\'s 80 % points)')
    ax.legend(loc='lower right', ncol=2)
    return save_figure(fig, path)


def fig3_record(run: Run, sc: Scenario, result: RunResult) -> dict:
    """Return the cache record of one run of the Fig. 3 sweep from its result.

    The recorder of the sweep machinery (:func:`flock_swarm.study.execute.run_job`, which
    adds the run's ``digest``).

    :param run: the run (see :func:`fig3_tasks`).
    :param sc: its scenario.
    :param result: its result.
    :return: the record (one JSON line of ``fig3_runs.jsonl``).
    """
    s, series = result.summary, result.series
    mismatch = np.linalg.norm(series['p'][-1] - series['leader_p'][-1], axis=1)
    t = series['t']
    every = np.searchsorted(t, np.arange(0.0, t[-1] + 1e-9, FIG3_ETA_EVERY))
    return {'kind': 'fig3', 'n_agents': run.point['n_agents'],
            'delta': run.point['informed.fraction'], 'seed': run.seed, 'duration': sc.duration,
            'informed': len(s['informed']), 'eta': s['eta'],
            'eta_tolerance': s['eta_tolerance'],
            'eta_by_tolerance': {f'{tol:g}': float(np.mean(mismatch <= tol))
                                 for tol in FIG3_TOLERANCES},
            'eta_times': [float(x) for x in t[every]],
            'eta_over_time': [float(x) for x in series['metric_eta'][every]],
            'linked_to_informed': linked_to_informed(
                series['q'][-1], series['informed'][0].astype(bool), sc),
            'velocity_mismatch_max': s['velocity_mismatch_max'],
            'components_final': s['components_final'], 'collisions': s['collisions'],
            'status': s['status'], 'wall_time_s': s['wall_time_s'],
            'flock_swarm_version': __version__}


def fig3_spec(plan: Plan) -> SweepSpec:
    """Return the Fig. 3 sweep of a plan as a sweep spec (``config/sweeps/su2009_fig3.yaml``).

    Seeds are the realisation indices ``0 .. R-1``, shared by every (N, delta): the points
    of one realisation use common random numbers, and a larger ``R`` only adds seeds.
    """
    side = f'sqrt(n_agents / {FIG3_DENSITY!r})'
    return parse_spec({'name': 'su2009_fig3', 'scenario': 'su2009_fig3',
                       'grid': {'n_agents': list(plan.sizes),
                                'informed.fraction': [float(d) for d in plan.fractions]},
                       'derived': {'initial.position_box': f'[[0.0, {side}], [0.0, {side}]]'},
                       'seeds': plan.realisations, 'stack_agents': FIG3_STACK_AGENTS},
                      plan.fig3_overrides)


def fig3_tasks(plan: Plan) -> list[Run]:
    """Return the runs of the Fig. 3 sweep, realisation by realisation, largest N first."""
    return plan_runs(fig3_spec(plan))


def aggregate_fig3(records: Iterable[dict],
                   value: Callable[[dict], float] | None = None) -> list[dict]:
    """Average eta over realisations for every (N, delta) point of Su 2009 Fig. 3.

    :param records: one record per run, with ``n_agents``, ``delta``, ``seed``, ``eta``.
    :param value: what to average (default: the record's ``eta``).
    :return: rows ``{n_agents, delta, mean, std, sem, count, seeds}`` sorted by N, delta.
    """
    groups: dict[tuple[int, float], list[dict]] = {}
    for rec in records:
        groups.setdefault((int(rec['n_agents']), float(rec['delta'])), []).append(rec)
    rows = []
    for (n, delta), recs in sorted(groups.items()):
        eta = np.array([r['eta'] if value is None else value(r) for r in recs], dtype=float)
        std = float(eta.std(ddof=1)) if eta.size > 1 else 0.0
        rows.append({'n_agents': n, 'delta': delta, 'mean': float(eta.mean()), 'std': std,
                     'sem': std / np.sqrt(eta.size), 'count': int(eta.size),
                     'seeds': sorted(int(r['seed']) for r in recs)})
    return rows


def eta_at(record: dict, t: float) -> float | None:
    """Return a Fig. 3 run's eta at time ``t`` (recorded every 10 s), or ``None``."""
    times = record.get('eta_times', [])
    for time_k, eta in zip(times, record.get('eta_over_time', [])):
        if abs(time_k - t) < 1e-6:
            return float(eta)
    return None


def delta_for_eta(rows: list[dict], n_agents: int, level: float) -> float | None:
    """Return the smallest delta at which the mean eta of size N reaches ``level``.

    Linear interpolation between the swept fractions; ``None`` if never reached.
    """
    pts = sorted((r['delta'], r['mean']) for r in rows if r['n_agents'] == n_agents)
    for (d0, e0), (d1, e1) in zip([(0.0, 0.0)] + pts, pts):
        if e1 >= level:
            if e1 == e0 or e0 >= level:
                return float(d1)
            return float(d0 + (level - e0) * (d1 - d0) / (e1 - e0))
    return None


def describe_fig3(job, records: list[dict]) -> str:
    """Return the progress text of a finished stack of Fig. 3 runs."""
    first = records[0]
    return (f'Fig. 3 N = {first["n_agents"]} seed {first["seed"]}, {len(records)} stacked: '
            f'{sum(r["wall_time_s"] for r in records):.1f} s')


def anchor_row(curve: dict, n: int) -> dict | None:
    """Return a curve's row at the paper's anchor of size ``n`` (None: not run)."""
    delta = FIG3_PAPER_DELTA[n]
    return next((r for r in curve['rows']
                 if r['n_agents'] == n and abs(r['delta'] - delta) < 1e-9), None)


def anchor_eta(curve: dict, n: int) -> float | None:
    """Return a curve's mean eta at the paper's anchor of size ``n`` (None: not run)."""
    row = anchor_row(curve, n)
    return None if row is None else row['mean']


class AnchorClaim:
    """Su 2009 Fig. 3 as a statistic: at each of the paper's two anchors (eta = 0.8 at
    delta = 0.27 for N = 100 and at 0.10 for N = 1000), the mean eta over the realisations
    with its 95 % t interval, against 0.8 ± :data:`~flock_swarm.reproduce.experiment.ETA_MARGIN`;
    the claim holds when it holds at both anchors."""

    band = (FIG3_PAPER_ETA - ETA_MARGIN, FIG3_PAPER_ETA + ETA_MARGIN)

    def short(self) -> str:
        """Return the criterion in a few words (the summary table)."""
        return (f'mean eta in [{fmt(self.band[0])}, {fmt(self.band[1])}] at both anchors')

    def statement(self) -> str:
        """Return the criterion in full (stated before the numbers)."""
        anchors = ' and '.join(f'N = {n}, delta = {d:g}' for n, d in FIG3_PAPER_DELTA.items())
        return (f'At each of the paper\'s anchors ({anchors}), the mean eta over the '
                'realisations, with its 95 % t interval, against the paper\'s '
                f'{fmt(FIG3_PAPER_ETA)} ± {fmt(ETA_MARGIN)}: **reproduced** when both '
                f'intervals lie within [{fmt(self.band[0])}, {fmt(self.band[1])}], **not '
                'reproduced** when one lies outside it, **inconclusive** otherwise. The paper '
                'reads the fraction needed off its averaged curves; the mean at the anchor is '
                'that reading with its uncertainty.')

    def judge(self, rows: list[dict]) -> dict:
        """Return each anchor's mean, interval and verdict, and the claim's verdict."""
        anchors = []
        for n, delta in FIG3_PAPER_DELTA.items():
            row = next((r for r in rows if r['n_agents'] == n
                        and abs(r['delta'] - delta) < 1e-9), None)
            if row is None:
                anchors.append({'n_agents': n, 'delta': delta, 'n': 0, 'estimate': None,
                                'interval': None, 'verdict': stats.NOT_RUN})
                continue
            interval = stats.t_interval(row['mean'], row['std'], row['count'])
            anchors.append({'n_agents': n, 'delta': delta, 'n': row['count'],
                            'estimate': row['mean'],
                            'interval': list(interval) if interval else None,
                            'verdict': stats.decide(interval, self.band)})
        return {'anchors': anchors, 'band': list(self.band),
                'verdict': stats.combine([a['verdict'] for a in anchors])}


def judge_anchors(rows: list[dict]) -> dict:
    """Return :meth:`AnchorClaim.judge` of aggregated rows."""
    return AnchorClaim().judge(rows)


def anchors_text(judged: dict) -> str:
    """Return ``N = 100: 0.31 [0.27, 0.35]; N = 1000: ...`` of an anchor judgement."""
    parts = []
    for a in judged['anchors']:
        if a['estimate'] is None:
            parts.append(f'N = {a["n_agents"]}: not run')
            continue
        ci = (f' [{fmt(a["interval"][0])}, {fmt(a["interval"][1])}]' if a['interval']
              else ' (no interval)')
        parts.append(f'N = {a["n_agents"]}, delta = {a["delta"]:g}: mean eta '
                     f'{fmt(a["estimate"])}{ci} ({a["n"]} runs)')
    return '; '.join(parts)
