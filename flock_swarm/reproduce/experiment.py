"""An experiment of the reproduction as one object: set-up, analysis, table rows, figure,
headline, criterion and verdict.

Each experiment is a subclass of :class:`Experiment` in a module of
:mod:`flock_swarm.reproduce.experiments` holding an instance as ``EXPERIMENT``; the catalogue
(:mod:`flock_swarm.reproduce.catalogue`) finds it there, and the pipeline and the report
(:mod:`~flock_swarm.reproduce.execution`, :mod:`~flock_swarm.reproduce.seeds`,
:mod:`~flock_swarm.reproduce.report`) only call its methods. ``docs/reproduction/README.md``
("Adding an experiment") has a worked example.

The criterion is the paper's claim as a statistic over seeds, stated before any number
(:class:`MeanClaim`: a mean against the paper's value; :class:`FractionClaim`: the fraction
of seeds meeting a per-seed claim); its confidence interval gives the verdict
(:func:`flock_swarm.reproduce.stats.decide`).
"""

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from flock_swarm.core.run import check_step
from flock_swarm.core.scenario import Scenario
from flock_swarm.outputs import plain_json
from flock_swarm.presets import prepare
from flock_swarm.reproduce import seeds, stats
from flock_swarm.reproduce.common import (FIG_SIZE, cell, fmt, preset_notes, pyplot, save_figure,
                                          set_args)
from flock_swarm.reproduce.plan import Plan

#: A claim the paper makes of its protocol (a theorem, "the flock forms") holds for almost
#: every draw, not for one: we ask it of at least this fraction of the seeds.
MOST = 0.9

#: The papers read a count of agents off one realisation ("86 of the 100 agents"); taken as
#: typical, we accept a mean eta within this many (5 agents in 100) of it.
ETA_MARGIN = 0.05


def _split(records: list[dict], premise: Callable[[dict], bool] | None
           ) -> tuple[list[dict], list[int]]:
    """Return the records whose run meets the premise, and the seeds of the others."""
    if premise is None:
        return list(records), []
    kept = [r for r in records if premise(r['metrics'])]
    return kept, sorted(r['seed'] for r in records if not premise(r['metrics']))


def _finite(value: Any) -> bool:
    """Return whether a metric holds a finite number."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


@dataclass(frozen=True)
class MeanClaim:
    """The paper's value of a quantity, taken as what a typical seed gives: the mean over the
    seeds, with its 95 % t interval, against the paper's value ± ``margin``.

    :ivar metric: the per-run metric (a key of the experiment's analysis).
    :ivar paper: the paper's value.
    :ivar margin: how far from it still supports the claim, with ``why``.
    :ivar what: the metric in words.
    :ivar why: why this statistic and margin (one sentence).
    :ivar premise: runs that fail it do not test the claim (listed, left out), or ``None``.
    :ivar premise_text: the premise in words.
    """

    metric: str
    paper: float
    margin: float
    what: str
    why: str = ''
    premise: Callable[[dict], bool] | None = None
    premise_text: str = ''

    @property
    def band(self) -> tuple[float, float]:
        """Return the values that support the claim."""
        return self.paper - self.margin, self.paper + self.margin

    def short(self) -> str:
        """Return the criterion in a few words (the summary table)."""
        low, high = self.band
        return f'mean {self.metric} in [{fmt(low)}, {fmt(high)}]'

    def statement(self) -> str:
        """Return the criterion in full (stated before the numbers)."""
        low, high = self.band
        text = (f'The mean of {self.what} (`{self.metric}`) over the seeds, with its 95 % t '
                f'interval, against the paper\'s {fmt(self.paper)} ± {fmt(self.margin)}: '
                f'**reproduced** when the interval lies within [{fmt(low)}, {fmt(high)}], '
                '**not reproduced** when it lies outside it, **inconclusive** when it '
                'straddles an end.')
        return text + (f' {self.why}' if self.why else '') + _premise(self)

    def judge(self, records: list[dict]) -> dict:
        """Return the statistic, its interval and the verdict over ``records``."""
        kept, failed = _split(records, self.premise)
        values = [r['metrics'].get(self.metric) for r in kept]
        values = [float(v) for v in values if _finite(v)]
        mean, interval = stats.mean_interval(values)
        return {'statistic': f'mean {self.metric}', 'n': len(values),
                'estimate': mean if values else None,
                'interval': list(interval) if interval else None, 'band': list(self.band),
                'verdict': stats.decide(interval, self.band) if values else stats.NOT_RUN,
                'premise_failed': failed}


@dataclass(frozen=True)
class FractionClaim:
    """A claim each seed meets or not, and the fraction of seeds that must meet it: the
    fraction, with its 95 % Wilson interval, against ``at_least``.

    :ivar per_seed: the claim of one seed in words.
    :ivar meets: whether a run's metrics meet it.
    :ivar label: the per-seed claim in a few words (the summary table).
    :ivar at_least: the fraction of seeds the paper's claim asks for.
    :ivar why: why this fraction (one sentence).
    :ivar premise: runs that fail it do not test the claim (listed, left out), or ``None``.
    :ivar premise_text: the premise in words.
    """

    per_seed: str
    meets: Callable[[dict], bool]
    label: str
    at_least: float = MOST
    why: str = ('The paper claims it of the protocol, not of one draw; a fraction can only be '
                'bounded away from 1, so we ask for at least 90 % of the seeds.')
    premise: Callable[[dict], bool] | None = None
    premise_text: str = ''

    @property
    def band(self) -> tuple[float, float]:
        """Return the fractions that support the claim."""
        return self.at_least, 1.0

    def short(self) -> str:
        """Return the criterion in a few words (the summary table)."""
        return f'at least {self.at_least:.0%} of seeds: {self.label}'

    def statement(self) -> str:
        """Return the criterion in full (stated before the numbers)."""
        text = (f'The fraction of seeds on which {self.per_seed}, with its 95 % Wilson '
                f'interval: **reproduced** when the interval lies at or above '
                f'{fmt(self.at_least)}, **not reproduced** when it lies below, '
                '**inconclusive** when it contains it.')
        return text + (f' {self.why}' if self.why else '') + _premise(self)

    def judge(self, records: list[dict]) -> dict:
        """Return the fraction, its interval and the verdict over ``records``."""
        kept, failed = _split(records, self.premise)
        met = sum(1 for r in kept if self.meets(r['metrics']))
        n = len(kept)
        interval = stats.wilson(met, n)
        verdict = stats.decide(interval, self.band) if n else stats.NOT_RUN
        if not n and failed:
            # Every run failed the premise: the claim was not put to the test.
            verdict = stats.INCONCLUSIVE
        return {'statistic': 'fraction of seeds', 'n': n, 'met': met,
                'estimate': met / n if n else None, 'interval': list(interval),
                'band': list(self.band), 'verdict': verdict, 'premise_failed': failed}


def _premise(claim: MeanClaim | FractionClaim) -> str:
    """Return the sentence on the claim's premise ('' without one)."""
    if claim.premise is None:
        return ''
    return (f' Premise: {claim.premise_text}; the seeds that fail it do not test the claim: '
            'they are listed and left out of the statistic.')


@dataclass(frozen=True)
class SetUp:
    """One set-up of an experiment over seeds: a sweep spec (the preset, its overrides, the
    seeds), every run of which the experiment analyses and its criterion judges.

    :ivar spec: the name of ``config/sweeps/NAME.yaml``, or the spec mapping itself
        (:func:`seed_spec`).
    :ivar label: the set-up's label (a spec with axes: see ``labels``).
    :ivar labels: the label of each point of a spec with axes, by its axis values.
    :ivar notes: a note on a set-up, by label: what it is equivalent to, what it costs.
    """

    spec: str | dict
    label: str = ''
    labels: dict = field(default_factory=dict)
    notes: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        """Return the spec's name (also its cache's)."""
        return self.spec if isinstance(self.spec, str) else self.spec['name']


def seed_spec(name: str, preset: str, overrides: dict | None = None, count: int = 50) -> dict:
    """Return a sweep spec over seeds ``1 .. count`` of a preset (a :class:`SetUp` without a
    file in ``config/sweeps/``).

    :param name: the spec's name, also its cache's (``docs/reproduction/runs/NAME.jsonl``).
    :param preset: the scenario.
    :param overrides: ``{key: value}`` set on every run.
    :param count: seeds (50 where a run costs under a minute, else 20).
    """
    return {'name': name, 'scenario': preset, 'set': dict(overrides or {}),
            'seeds': {'first': 1, 'count': count}}


class Experiment:
    """One experiment of a paper. Subclass it, set the attributes, override what differs.

    :cvar key: the experiment's name: its JSON result, figure and report section.
    :cvar title: the section title.
    :cvar paper: the paper, short citation.
    :cvar claim: the paper's claim, quoted with section and figure (Markdown).
    :cvar order: the report's order (smaller first).
    :cvar preset: the scenario it runs (default: ``key``).
    :cvar overrides: ``--set`` overrides of its run (its set-up beside the preset).
    :cvar quick: further overrides of ``--quick`` mode (tests).
    :cvar ros: overrides of the version run through the ROS nodes, or ``None``.
    :cvar ros_quick: the same in ``--quick`` mode.
    :cvar rows: the table, ``(what, metric key, the paper's value)``.
    :cvar criterion: the paper's claim as a statistic over seeds.
    :cvar setups: the runs over seeds that the criterion judges; the first is the paper's.
    :cvar columns: the distributions shown over seeds, ``(what, metric, the paper's value)``.
    :cvar per_seed: metrics listed seed by seed under the distributions, ``(what, metric)``.
    :cvar misprints: misprints of the paper found while reproducing this experiment.
    """

    key = ''
    title = ''
    paper = ''
    claim = ''
    order = 1000.0
    preset = ''
    overrides: tuple[str, ...] = ()
    quick: tuple[str, ...] = ()
    ros: tuple[str, ...] | None = None
    ros_quick: tuple[str, ...] = ()
    rows: tuple[tuple[str, str, str], ...] = ()
    criterion: MeanClaim | FractionClaim | None = None
    setups: tuple[SetUp, ...] = ()
    columns: tuple[tuple[str, str, str], ...] = ()
    per_seed: tuple[tuple[str, str], ...] = ()
    misprints: tuple[str, ...] = ()
    #: Whether the experiment's own result comes from one run of its preset.
    runs_preset = True

    def __repr__(self) -> str:
        """Return ``<Experiment key>``."""
        return f'<{type(self).__name__} {self.key}>'

    @property
    def scenario(self) -> str:
        """Return the preset it runs."""
        return self.preset or self.key

    # -- set-up ----------------------------------------------------------------------------

    def preset_overrides(self, quick: bool) -> list[str]:
        """Return the ``--set`` overrides of the experiment's run."""
        return list(self.overrides) + (list(self.quick) if quick else [])

    def sweep(self, plan: Plan):
        """Return the sweep it runs beside (or instead of) its preset, or ``None``.

        :return: a :class:`Sweep` or ``None``.
        """
        return None

    # -- analysis, table, figure -----------------------------------------------------------

    def analyse(self, sc: Scenario, summary: dict, series: dict) -> dict:
        """Return the numbers of one run (default: the summary's numbers)."""
        return {k: v for k, v in summary.items() if _finite(v)}

    def discuss(self, m: dict) -> str:
        """Return "where we differ and why", written from the numbers ('' for none)."""
        return ''

    def mechanism(self, res: dict) -> str:
        """Return the study's mechanism as measured beside its prediction, for the summary
        (a study beyond the papers overrides it; '' for none).

        :param res: the experiment's JSON result (with ``seeds`` when it has a study).
        """
        return ''

    def figure(self, sc: Scenario, summary: dict, series: dict, m: dict, path: Path) -> Path:
        """Draw the experiment's figure (default: eta and the largest velocity mismatch
        over time) and return its path."""
        plt = pyplot()
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=FIG_SIZE)
        t = series['t']
        ax1.plot(t, series['metric_eta'], color='tab:green')
        ax1.set_ylim(-0.02, 1.02)
        ax1.set_xlabel('t [s]')
        ax1.set_ylabel(f'eta (tolerance {fmt(summary["eta_tolerance"])} m/s)')
        ax1.set_title('eta over time')
        ax2.semilogy(t, np.maximum(series['metric_velocity_mismatch_max'], 1e-12))
        ax2.set_xlabel('t [s]')
        ax2.set_ylabel('max ‖p_i - p_gamma‖ [m/s]')
        ax2.set_title('largest velocity mismatch')
        ax2.grid(True, alpha=0.3, which='both')
        return save_figure(fig, path)

    def headline(self, res: dict) -> tuple[str, str]:
        """Return the paper's and our headline for the summary (default: the first row)."""
        if not self.rows:
            return '', ''
        label, key, paper = self.rows[0]
        return f'{label}: {paper}', fmt(res['metrics'].get(key))

    def result(self, plan: Plan, sims: dict, out: Path, figures: Path) -> dict:
        """Analyse the experiment's run, draw its figure, and return its JSON result.

        :param plan: the plan (quick or not).
        :param sims: :func:`~flock_swarm.reproduce.execution.run_simulations`' result.
        :param out: the output directory (the run's files are in ``out/runs/<key>``).
        :param figures: where the figure goes.
        """
        summary = sims['summaries'][self.key]
        overrides = self.preset_overrides(plan.quick)
        sc, real = prepare(self.scenario, overrides, allow_unstable=True)
        with np.load(out / 'runs' / self.key / 'timeseries.npz') as data:
            series = {k: data[k] for k in data.files}
        metrics = self.analyse(sc, summary, series)
        fig = self.figure(sc, summary, series, metrics, figures / f'{self.key}.png')
        return {'key': self.key, 'title': self.title, 'preset': self.scenario,
                'overrides': overrides,
                'command': f'sim {self.scenario}{set_args(overrides)}', 'seed': sc.seed,
                'n_agents': sc.n_agents, 'dt': sc.dt, 'duration': sc.duration,
                'stability_violations': len(check_step(sc, real)),
                'summary': plain_json(summary), 'metrics': plain_json(metrics), 'figure': fig.name}

    # -- the report ------------------------------------------------------------------------

    def body(self, res: dict, plan: Plan, figures: Path) -> list[str]:
        """Return the section's lines between the criterion and the figure: the run, its
        table, the discussion, the study over seeds.

        :param res: the experiment's JSON result.
        :param plan: what ran.
        :param figures: the figures' directory relative to the report.
        """
        lines = [f'**Run.** `{res["command"]}` (seed {res["seed"]}, {res["n_agents"]} '
                 f'agents, dt = {fmt(res["dt"])} s, {fmt(res["duration"])} s, '
                 f'{fmt(res["summary"]["wall_time_s"])} s wall). Preset notes: '
                 f'{preset_notes(self.scenario)}', '']
        if res['stability_violations']:
            lines += [f'Note: the step-size check reports {res["stability_violations"]} '
                      'violated bound(s) for this scenario.', '']
        lines += self.table(res['metrics'])
        text = self.discuss(dict(res['metrics'], n_agents=res['n_agents']))
        if text:
            lines += ['', '**Where we differ and why.** ' + text]
        if 'seeds' in res:
            lines += self.seeds_section(res['seeds'], figures)
        return lines

    def table(self, metrics: dict) -> list[str]:
        """Return the Markdown rows ``| what (`key`) | paper | ours |`` of the run."""
        lines = ['| quantity | paper | ours |', '|---|---|---|']
        for label, key, paper in self.rows:
            if key in metrics:
                lines.append(f'| {cell(label)} (`{key}`) | {cell(paper)} | '
                             f'{cell(fmt(metrics[key]))} |')
        return lines

    # -- over seeds ------------------------------------------------------------------------

    #: Whether its study runs only when asked (``--fig3-curves``: hours of computing).
    long_study = False

    def run_study(self, cache_dir: Path, backend, say: Callable[[str], None], quick: bool,
                  cached_only: bool, live: Callable[[str], None] | None, figures: Path
                  ) -> dict | None:
        """Run (or resume, or only read) the runs over seeds; return their summary, or
        ``None`` without set-ups (:func:`flock_swarm.reproduce.seeds.run_study`)."""
        if not self.setups:
            return None
        res = seeds.run_study(self, cache_dir, backend, say, quick, cached_only, live)
        res['curves_figure'] = seeds.curves_figure(res, self.key,
                                                   figures / f'{self.key}_curves.png')
        return res

    def seeds_section(self, res: dict, figures: Path) -> list[str]:
        """Return the report lines of the study over seeds.

        :param res: :meth:`run_study`'s result.
        :param figures: the figures' directory relative to the report.
        """
        return seeds.section(self, res, figures)

    def judge(self, res: dict) -> dict:
        """Return the experiment's verdicts: ``{'verdict': the paper's set-up's, 'over':
        its statistic in words, 'setups': [(label, verdict)]}``.

        :param res: the experiment's JSON result (with ``seeds`` when it has a study).
        """
        study = res.get('seeds')
        if not study or not study['setups']:
            return {'verdict': stats.NOT_RUN, 'over': 'no study over seeds',
                    'setups': []}
        first = study['setups'][0]
        over = f'{first["label"]}: {first["seeds"]} of {first["planned"]} seeds; ' \
            + seeds.judgement_text(first['judged'])
        clear = seeds.margin(first['judged'])
        if clear is not None:
            over += f', margin {fmt(clear)}'
        held = first.get('held_out')
        if held is not None:
            over += (f'; held-out seeds ({held["seeds"]} of {held["planned"]}): '
                     + (seeds.judgement_text(held['judged']) + f', {held["judged"]["verdict"]}'
                        if held['seeds'] else 'none cached yet'))

        def verdict(s: dict) -> str:
            return s['judged']['verdict'] + (' (fragile)' if s.get('fragile') else '')
        return {'verdict': first['judged']['verdict'], 'over': over,
                'fragile': bool(first.get('fragile')),
                'setups': [(s['label'], verdict(s)) for s in study['setups']]}


@dataclass(frozen=True)
class Sweep:
    """A sweep an experiment runs beside its preset (Su Fig. 3: every (N, delta) point).

    :ivar runs: the planned runs.
    :ivar cache: the cache file's name in the output directory.
    :ivar recorder: makes each run's record (:data:`flock_swarm.study.execute.Recorder`).
    :ivar stack_agents: about how many agents a stack holds.
    :ivar describe: the progress text of a finished stack, or ``None``.
    """

    runs: list
    cache: str
    recorder: Callable
    stack_agents: int
    describe: Callable | None = None
