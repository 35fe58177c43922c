"""Beyond the papers: the critical input delay of second-order linear consensus, runs
against the analytic oracle ``tau*`` (Olfati-Saber & Murray 2004, Sec. VIII)."""

import json
import math
from pathlib import Path

import numpy as np

from flock_swarm.core.laws.linear import critical_delay, sampled_delay_radius
from flock_swarm.core.scenario import Scenario
from flock_swarm.reproduce.common import FIG_SIZE, fmt, pyplot, save_figure
from flock_swarm.reproduce.experiment import Experiment, FractionClaim, SetUp

#: The study's spec (``config/sweeps/``): a ring of four, the delays around tau*.
SPEC = 'reproduce_linear_critical_delay'
#: The run of the experiment's own figure: just above tau* (36 steps, 1.11 tau*).
FIGURE_DELAY = 0.36


def laplacian_eigenvalues(sc: Scenario) -> np.ndarray:
    """Return the positive Laplacian eigenvalues of the scenario's fixed graph."""
    adj = np.asarray(sc.graph['adjacency'], dtype=float)
    lams = np.linalg.eigvalsh(np.diag(adj.sum(axis=1)) - adj)
    return lams[lams > 1e-9]


def disagreement(series: dict) -> np.ndarray:
    """Return, per recorded instant, the largest distance of a state from the average."""
    q, p = series['q'], series['p']
    dq = q - q.mean(axis=1, keepdims=True)
    dp = p - p.mean(axis=1, keepdims=True)
    return np.maximum(np.linalg.norm(dq, axis=2).max(axis=1),
                      np.linalg.norm(dp, axis=2).max(axis=1))


#: Below this fraction of its largest value the disagreement is round-off (the agents'
#: positions grow with the common drift, their differences cannot fall below ~1e-16 of them).
FLOOR = 1e-9


def growth_rate(series: dict) -> float:
    """Return the least-squares slope [1/s] of ``log(disagreement)`` over the second half of
    the time it stays above round-off (:data:`FLOOR`; the first half's transient left out):
    negative when the run converges."""
    t, dis = series['t'], disagreement(series)
    above = dis > FLOOR * dis.max()
    end = t[np.flatnonzero(above)[-1]]
    late = above & (t >= end / 2)
    return float(np.polyfit(t[late], np.log(dis[late]), 1)[0])


def study_overrides() -> tuple[str, ...]:
    """Return the spec's fixed values as ``--set`` overrides (the figure's run is one of the
    study's points, not a copy of its set-up)."""
    from flock_swarm.presets import resolve
    from flock_swarm.study.spec import read_spec
    spec = read_spec(resolve(SPEC, 'sweeps', 'spec'))
    return tuple(f'{key}={json.dumps(value)}' for key, value in spec.fixed)


class CriticalDelay(Experiment):
    """Linear consensus (``linear_consensus``) on a ring of four under an input delay."""

    key = 'linear_critical_delay'
    title = 'Beyond the papers: the critical delay of linear consensus'
    paper = 'Olfati-Saber & Murray 2004'
    claim = (
        'Section VIII (for second-order agents as in Ren & Beard 2008, Sec. 4.2): on a fixed '
        'connected undirected graph with both states delayed by tau (the `input` delay '
        'model), each disagreement mode obeys s^2 + lambda (k_v s + k_p) exp(-s tau) = 0 '
        'for a Laplacian eigenvalue lambda, and consensus holds **for tau < tau\\***, the '
        'smallest delay at which a root reaches the imaginary axis (the largest lambda '
        'decides; `flock_swarm.core.laws.linear.critical_delay`); above it the disagreement '
        'grows. The network model is put to this oracle: runs against tau / tau\\*.')
    order = 1010.0
    preset = 'demo'
    quick = ('duration=2',)
    ros = None
    rows = (('delay tau [s]', 'tau', '-'),
            ('tau* [s] (continuous oracle)', 'tau_star', '-'),
            ('tau / tau*', 'tau_ratio', '-'),
            ('growth rate of the disagreement, fitted [1/s]', 'growth_rate', '-'),
            ('growth rate of the sampled system, ln(radius) / dt [1/s]',
             'growth_rate_sampled', '-'))
    criterion = FractionClaim(
        'the disagreement decays (a negative fitted growth rate over the second half of the '
        '20 s run, or of its part above round-off) when tau < tau\\* and grows when '
        'tau > tau\\*',
        lambda m: (m['growth_rate'] < 0.0) == (m['tau_ratio'] < 1.0),
        'converges iff tau < tau*',
        why='The oracle is a theorem of the continuous system; the run is its exact '
        'zero-order-hold sampling at dt = 0.01 s, whose own boundary lies within one step of '
        'tau* (the sampled system\'s spectral radius is in the table): a point between the two '
        'is where the sampling, not the network model, decides. We ask it of at least 90 % of '
        'the seeds at every delay.')
    columns = (('tau / tau*', 'tau_ratio', '-'),
               ('fitted growth rate [1/s]', 'growth_rate', '-'),
               ('sampled system\'s rate [1/s]', 'growth_rate_sampled', '-'))
    misprints = ()

    @property
    def overrides(self) -> tuple[str, ...]:
        """Return the study's set-up with the figure's delay."""
        return study_overrides() + (f'network.delay={FIGURE_DELAY}',)

    @property
    def setups(self) -> tuple[SetUp, ...]:
        """Return the study: one point per delay, labelled by tau / tau*."""
        from flock_swarm.reproduce.seeds import study_runs
        from flock_swarm.presets import load
        spec, runs = study_runs(SPEC, seeds=1)
        sc = load(spec.scenario, [f'{k}={json.dumps(v)}' for k, v in spec.fixed])
        tau_star = min(critical_delay(lam, sc.law.k_p, sc.law.k_v)[0]
                       for lam in laplacian_eigenvalues(sc))
        labels = {}
        for run in runs:
            tau = run.point['network.delay']
            labels[(str(tau),)] = f'tau = {tau:g} s ({tau / tau_star:.3f} tau*)'
        return (SetUp(SPEC, labels=labels),)

    def analyse(self, sc: Scenario, summary: dict, series: dict) -> dict:
        """Return the delay, the oracle's tau*, the fitted and the sampled growth rates."""
        law, dt = sc.law, sc.dt
        steps = sc.network.agents.delay.low
        lams = laplacian_eigenvalues(sc)
        tau_star = min(critical_delay(lam, law.k_p, law.k_v)[0] for lam in lams)
        radius = max(sampled_delay_radius(lam, steps, dt, law.k_p, law.k_v) for lam in lams)
        return {'tau': steps * dt, 'delay_steps': steps, 'tau_star': tau_star,
                'tau_ratio': steps * dt / tau_star, 'growth_rate': growth_rate(series),
                'growth_rate_sampled': math.log(radius) / dt,
                'sampled_radius': radius,
                'disagreement_initial': float(disagreement(series)[0]),
                'disagreement_final': float(disagreement(series)[-1])}

    def discuss(self, m: dict) -> str:
        """Return what the figure's run shows."""
        return (f'At tau = {fmt(m["tau"])} s ({fmt(m["tau_ratio"])} tau*) the disagreement '
                f'goes from {fmt(m["disagreement_initial"])} to '
                f'{fmt(m["disagreement_final"])} in the run; its fitted growth rate '
                f'{fmt(m["growth_rate"])} 1/s against the sampled system\'s '
                f'{fmt(m["growth_rate_sampled"])} 1/s.')

    def figure(self, sc: Scenario, summary: dict, series: dict, m: dict, path: Path) -> Path:
        """Draw the run's disagreement over time."""
        plt = pyplot()
        fig, ax = plt.subplots(1, 1, figsize=FIG_SIZE)
        ax.semilogy(series['t'], np.maximum(disagreement(series), 1e-300))
        ax.set_xlabel('t [s]')
        ax.set_ylabel('largest distance from the average state')
        ax.set_title(f'tau = {fmt(m["tau"])} s = {fmt(m["tau_ratio"])} tau*')
        ax.grid(True, alpha=0.3, which='both')
        return save_figure(fig, path)

    def headline(self, res: dict) -> tuple[str, str]:
        """Return the oracle and the figure run's rate."""
        m = res['metrics']
        return (f'converges iff tau < tau* = {fmt(m["tau_star"])} s',
                f'at {fmt(m["tau_ratio"])} tau*: rate {fmt(m["growth_rate"])} 1/s')

    def run_study(self, cache_dir: Path, backend, say, quick: bool, cached_only: bool, live,
                  figures: Path) -> dict | None:
        """Run (or read) the study, then draw the runs against tau / tau*."""
        from flock_swarm.reproduce.seeds import QUICK_SEEDS, study_runs
        from flock_swarm.study.cache import read_cache
        res = super().run_study(cache_dir, backend, say, quick, cached_only, live, figures)
        spec, runs = study_runs(SPEC, tuple(self.quick) if quick else (),
                                QUICK_SEEDS if quick else None)
        cache = read_cache(cache_dir / f'{spec.name}.jsonl', ('digest', 'status'), say)
        points = [cache[r.digest]['metrics'] for r in runs
                  if r.digest in cache and cache[r.digest]['status'] == 'completed']
        res['points'] = [{k: m[k] for k in ('tau_ratio', 'growth_rate', 'growth_rate_sampled',
                                            'delay_steps', 'tau_star')} for m in points]
        if points:
            res['figure'] = self.study_figure(points, spec, figures / f'{self.key}_study.png')
        return res

    def study_figure(self, points: list[dict], spec, path: Path) -> str:
        """Draw the fitted growth rate of every run against tau / tau*, with the sampled
        system's rate over every delay in steps and the continuous tau*."""
        from flock_swarm.presets import load
        sc = load(spec.scenario, [f'{k}={json.dumps(v)}' for k, v in spec.fixed])
        law, dt, lams = sc.law, sc.dt, laplacian_eigenvalues(sc)
        tau_star = points[0]['tau_star']
        runs = max(sum(1 for p in points if p['delay_steps'] == d)
                   for d in {p['delay_steps'] for p in points})
        top = max(p['delay_steps'] for p in points) + 4
        steps = np.arange(0, top + 1)
        rate = [max(math.log(sampled_delay_radius(lam, int(d), dt, law.k_p, law.k_v))
                    for lam in lams) / dt for d in steps]
        plt = pyplot()
        fig, ax = plt.subplots(1, 1, figsize=FIG_SIZE)
        ax.plot(steps * dt / tau_star, rate, color='tab:gray', lw=1,
                label='sampled system (dt = 0.01 s): ln(radius) / dt')
        ax.scatter([p['tau_ratio'] for p in points], [p['growth_rate'] for p in points],
                   s=8, color='tab:blue', zorder=3, label=f'runs ({runs} per delay at most)')
        ax.axvline(1.0, color='tab:red', ls='--', lw=1, label='tau* (continuous oracle)')
        ax.axhline(0.0, color='black', lw=0.5)
        ax.set_xlabel('tau / tau*')
        ax.set_ylabel('growth rate of the disagreement [1/s]')
        ax.set_title('linear consensus on a ring of four under an input delay')
        ax.legend(loc='upper left')
        ax.grid(True, alpha=0.3)
        return save_figure(fig, path).name

    def seeds_section(self, res: dict, figures: Path) -> list[str]:
        """Return the study's lines and its figure."""
        from flock_swarm.reproduce.experiments.network_study import BEYOND_ORACLE
        lines = ['', BEYOND_ORACLE] + super().seeds_section(res, figures)
        if res.get('figure'):
            lines += ['', f'![{self.key} over seeds]({(figures / res["figure"]).as_posix()})']
        return lines


EXPERIMENT = CriticalDelay()
