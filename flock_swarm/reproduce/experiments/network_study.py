"""Beyond the papers (issues 25 and 26): Su 2009 Fig. 2 under a network model and on other
plants, and the critical delay of the linear law. Shared by the experiment modules
``su2009_fig2_delay``, ``su2009_fig2_loss``, ``su2009_fig2_plants`` and
``linear_critical_delay`` (this module holds no experiment)."""

from pathlib import Path

import numpy as np

from flock_swarm.reproduce import stats
from flock_swarm.reproduce.common import FIG_SIZE, cell, fmt, pyplot, save_figure
from flock_swarm.reproduce.experiment import ETA_MARGIN, MeanClaim, SetUp
from flock_swarm.reproduce.experiments.su2009_fig2 import Fig2

#: The heading line every section of the part opens with.
BEYOND = ('*Beyond the papers.* The papers assume that every agent knows its neighbours\' '
          'exact current state. Here the same experiment runs under the network model of '
          '`docs/network.md` (issue 25), seed for seed against the ideal network; the '
          'criterion is the paper\'s own, asked of each network: **reproduced** means the '
          'paper\'s claim survives that network.')

#: The heading line of the linear law's oracle experiment.
BEYOND_ORACLE = ('*Beyond the papers.* The network model against an analytic oracle: a run '
                 'per seed and delay, each judged against the continuous tau\\*; the figure '
                 'shows the runs\' fitted growth rates over tau / tau\\* beside the exact '
                 'rate of the sampled system.')

#: The metrics of a Fig. 2 run under a network shown with their 95 % intervals.
INTERVAL_METRICS = (('eta at t_final', 'eta'),
                    ('max ‖p_i - p_gamma‖ at t_final [m/s]', 'velocity_mismatch_max'),
                    ('r-disk components at t_final', 'components_final'),
                    ('pairs ever closer than 0.5 m', 'collisions'))


def interval_table(setups: list[dict], records: dict[str, list[dict]],
                   metrics: tuple[tuple[str, str], ...] = INTERVAL_METRICS) -> list[str]:
    """Return a Markdown table: per set-up, each metric's mean and its 95 % t interval.

    :param setups: the study's set-ups (their ``label``).
    :param records: the runs' metrics by set-up label.
    :param metrics: ``(what, key)`` of the columns.
    """
    heads = [f'{cell(what)} (`{key}`; mean [95 % interval])' for what, key in metrics]
    lines = ['| set-up | ' + ' | '.join(heads)
             + ' |', '|---|' + '---|' * len(metrics)]
    for s in setups:
        row = []
        for _, key in metrics:
            values = [float(m[key]) for m in records.get(s['label'], [])
                      if m.get(key) is not None and np.isfinite(float(m[key]))]
            mean, interval = stats.mean_interval(values)
            row.append('n/a' if not values else f'{fmt(mean)} [{fmt(interval[0])}, '
                       f'{fmt(interval[1])}]' if interval else fmt(mean))
        lines.append(f'| {cell(s["label"])} | ' + ' | '.join(row) + ' |')
    return lines


def setup_metrics(setups, cache_dir: Path, quick: bool, quick_overrides: tuple, say,
                  axis: str = '') -> tuple[dict[str, list[dict]], dict[str, float]]:
    """Return the cached runs' metrics of every set-up's points by label, and each label's
    value of ``axis`` (for points that set it to a number).

    :param setups: the experiment's set-ups.
    :param cache_dir: where the caches ``NAME.jsonl`` live.
    :param quick: ``--quick`` (its overrides and seeds, as the study ran them).
    :param quick_overrides: the experiment's ``--quick`` overrides.
    :param say: progress lines.
    :param axis: the swept key whose values place the points on a figure, or ``''``.
    """
    from flock_swarm.reproduce.seeds import QUICK_SEEDS, point_label, study_runs
    from flock_swarm.study.cache import read_cache
    records: dict[str, list[dict]] = {}
    values: dict[str, float] = {}
    for setup in setups:
        spec, runs = study_runs(setup.spec, tuple(quick_overrides) if quick else (),
                                QUICK_SEEDS if quick else None)
        cache = read_cache(cache_dir / f'{spec.name}.jsonl', ('digest', 'status'), say)
        for run in runs:
            label = point_label(setup, run.point)
            records.setdefault(label, [])
            if isinstance(run.point.get(axis), (int, float)):
                values[label] = float(run.point[axis])
            rec = cache.get(run.digest)
            if rec is not None and rec['status'] == 'completed':
                records[label].append(rec['metrics'])
    return records, values


class NetworkFig2(Fig2):
    """Su 2009 Fig. 2 over seeds along one ``network.*`` axis (a subclass names the axis).

    The runs and their analysis are Fig. 2's; the section adds every metric's mean with its
    95 % interval per network and a figure of them against the axis.
    """

    order = 1000.0
    #: The swept key, its unit and the spec (``config/sweeps/``).
    axis, unit, spec = '', '', ''
    #: The section's opening line.
    beyond = BEYOND
    paper_count = 86
    paper_figure = 'Fig. 2'
    ros = None
    misprints = ()
    columns = (('eta at t_final', 'eta', '0.86'),
               ('max ‖p_i - p_gamma‖ at t_final [m/s]', 'velocity_mismatch_max', '-'),
               ('r-disk components at t_final', 'components_final', '-'),
               ('pairs ever closer than 0.5 m', 'collisions', '-'))
    criterion = MeanClaim(
        'eta', 0.86, ETA_MARGIN, 'eta at t_final (the fraction of agents with the desired '
        'velocity)',
        why='Fig. 2\'s criterion (the paper\'s 86 of 100 taken as typical, a mean within 5 '
        'agents of it), asked of each network: the first set-up is the ideal network.')

    def analyse(self, sc, summary: dict, series: dict) -> dict:
        """Return Fig. 2's numbers and the network's statistics of the run (the fraction of
        messages delivered, the mean age [s] of the neighbour states the law used)."""
        out = super().analyse(sc, summary, series)
        for key in ('network_delivered', 'network_age_mean'):
            if isinstance(summary.get(key), (int, float)) and np.isfinite(summary[key]):
                out[key] = float(summary[key])
        return out

    @property
    def setups(self) -> tuple[SetUp, ...]:
        """Return the one set-up: the spec, its points labelled by the axis value."""
        return (SetUp(self.spec, labels=self.labels()),)

    def labels(self) -> dict:
        """Return the label of each point by its axis value (text)."""
        from flock_swarm.reproduce.seeds import study_runs
        _, runs = study_runs(self.spec, seeds=1)
        out = {}
        for run in runs:
            value = run.point[self.axis]
            out[(str(value),)] = 'ideal network' if value == 0 else \
                f'{self.axis.split(".", 1)[1]} {value:g}{self.unit}'
        return out

    def run_study(self, cache_dir: Path, backend, say, quick: bool, cached_only: bool, live,
                  figures: Path) -> dict | None:
        """Run (or read) the study, then keep each set-up's metrics and draw the figure."""
        res = super().run_study(cache_dir, backend, say, quick, cached_only, live, figures)
        records, values = setup_metrics(self.setups, cache_dir, quick, self.quick, say,
                                        self.axis)
        res['metrics_by_setup'] = records
        res['axis_values'] = values
        if any(records.values()):
            res['figure'] = self.study_figure(res, figures / f'{self.key}_study.png').name
        return res

    def seeds_section(self, res: dict, figures: Path) -> list[str]:
        """Return the study's lines, the metrics' intervals and the figure."""
        lines = ['', self.beyond] + super().seeds_section(res, figures)
        lines += ['', 'Means with their 95 % t intervals over the seeds (collisions: pairs '
                  'ever closer than 0.5 m in the run):', '']
        lines += interval_table(res['setups'], res.get('metrics_by_setup', {}))
        if res.get('figure'):
            lines += ['', f'![{self.key} over seeds]({(figures / res["figure"]).as_posix()})']
        return lines

    def study_figure(self, res: dict, path: Path) -> Path:
        """Draw each metric's mean and 95 % interval against the axis."""
        plt = pyplot()
        fig, axes = plt.subplots(1, 4, figsize=(FIG_SIZE[0] * 1.25, FIG_SIZE[1]))
        labels = [s['label'] for s in res['setups']]
        numeric = all(label in res['axis_values'] for label in labels)
        x = np.array([res['axis_values'][label] for label in labels]) if numeric \
            else np.arange(len(labels))
        for ax, (what, key) in zip(axes, INTERVAL_METRICS):
            means, lows, highs = [], [], []
            for label in labels:
                values = [float(m[key]) for m in res['metrics_by_setup'].get(label, [])
                          if m.get(key) is not None and np.isfinite(float(m[key]))]
                mean, interval = stats.mean_interval(values)
                interval = interval or (mean, mean)
                means.append(mean)
                lows.append(mean - interval[0])
                highs.append(interval[1] - mean)
            ax.errorbar(x, means, yerr=[lows, highs], marker='o', ms=3, capsize=2)
            if key == 'eta':
                ax.axhspan(*self.criterion.band, color='tab:green', alpha=0.15,
                           label='paper ± 5 agents')
                ax.set_ylim(-0.02, 1.02)
                ax.legend(loc='best')
            if numeric:
                ax.set_xlabel(f'{self.axis}'
                              f'{" [" + self.unit.strip() + "]" if self.unit else ""}')
            else:
                ax.set_xticks(x, [label.split(' (')[0] for label in labels], rotation=30,
                              ha='right')
            ax.set_title(what, fontsize=8)
            ax.grid(True, alpha=0.3)
        return save_figure(fig, path)
