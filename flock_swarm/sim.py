"""The reference simulator: a whole swarm, vectorised over agents, from one scenario.

``sim SCENARIO [--set key=value ...] [--seed N] [--out DIR]`` runs a preset (or a YAML file)
and writes ``DIR/summary.json`` and ``DIR/timeseries.npz`` (see ``docs/outputs.md``).
The step uses the same law functions as the agent node (:mod:`flock_swarm.core.protocols`).
"""

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from flock_swarm import __version__
from flock_swarm.core.dynamics import LeaderState, VirtualLeader, step_agents
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.graphs import EdgeList, disk_graph, fixed_graph
from flock_swarm.core.metrics import STEP_METRICS, RunMetrics, step_metrics
from flock_swarm.core.protocols import advance_adaptive, swarm_control
from flock_swarm.core.pseudo_leaders import Reselector
from flock_swarm.core.scenario import Realization, Scenario, all_pairs_weights, realize
from flock_swarm.core.stability import check_step

#: Exit status for invalid input (as argparse uses).
EXIT_USAGE = 2
#: Exit status when the state stopped being finite.
EXIT_DIVERGED = 1


@dataclass
class SimResult:
    """What a run produced: the summary (``summary.json``) and the recorded time series."""

    summary: dict
    series: dict[str, np.ndarray] = field(default_factory=dict)


class Recorder:
    """Collects subsampled states and metrics into growing lists, then stacks them."""

    def __init__(self) -> None:
        """Create an empty recorder."""
        self.rows: dict[str, list] = {}

    def add(self, **values) -> None:
        """Append one recorded instant."""
        for key, value in values.items():
            self.rows.setdefault(key, []).append(np.array(value, copy=True))

    def arrays(self) -> dict[str, np.ndarray]:
        """Return the recorded columns as arrays (first axis: time)."""
        return {key: np.stack(rows) for key, rows in self.rows.items()}


class RunLog:
    """Whole-run metrics and the subsampled time series, fed one step at a time.

    The one bookkeeping of a run, shared by ``sim``, the world node and ``analyze``: every
    step updates the whole-run metrics from the step's edges; every ``record_every``-th step
    and the last are measured with :func:`step_metrics` and recorded.
    """

    def __init__(self, eta_tolerance: float, collision_distance: float, radius: float,
                 strict: bool, record_every: int) -> None:
        """Create the log.

        :param eta_tolerance: velocity tolerance of ``eta``.
        :param collision_distance: pairs closer than this count as collisions.
        :param radius: radius of the r-disk graph whose components are counted.
        :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
        :param record_every: subsampling of the time series.
        """
        self.eta_tolerance = eta_tolerance
        self.radius, self.strict, self.every = radius, strict, record_every
        self.metrics = RunMetrics(collision_distance)
        self.rec = Recorder()
        self.latest: dict = {}

    @classmethod
    def for_scenario(cls, sc: Scenario) -> 'RunLog':
        """Return the log of a scenario's run."""
        return cls(sc.eta_tolerance, sc.collision_distance, sc.law.radius,
                   sc.law.strict_radius, sc.record_every)

    def observe(self, k: int, t: float, q: np.ndarray, p: np.ndarray, u: np.ndarray,
                leader: LeaderState, informed: np.ndarray, edges: EdgeList,
                edges_radius: float, last: bool, **extra) -> dict | None:
        """Fold in step ``k``; return its metrics when it is recorded, else ``None``.

        :param edges: the step's graph, complete within ``edges_radius``.
        :param extra: further per-step arrays to record (e.g. adaptive gains ``h``).
        """
        self.metrics.update_from_edges(q, edges, edges_radius)
        if k % self.every and not last:
            return None
        now = step_metrics(q, p, leader, self.eta_tolerance, self.radius, self.strict)
        self.metrics.update(q, now['min_pair_distance'])
        self.rec.add(t=t, q=q, p=p, u=u, leader_q=leader.q, leader_p=leader.p,
                     leader_a=leader.a, informed=informed, **extra,
                     **{f'metric_{name}': now[name] for name in STEP_METRICS})
        self.latest = now
        return now


def interaction_graph(sc: Scenario, real: Realization, q: np.ndarray,
                      static: EdgeList | None) -> EdgeList:
    """Return the interaction edges at positions ``q`` (the fixed graph when there is one).

    :param sc: the scenario.
    :param real: its realisation.
    :param q: positions.
    :param static: the precomputed fixed graph, or ``None``.
    :return: the edge list.
    """
    if static is not None:
        return static
    if sc.law.all_pairs:
        return all_pairs_weights(sc.n_agents, None, q, sc.law)
    return disk_graph(q, sc.law.radius, sc.law.strict_radius)


def static_graph(sc: Scenario, real: Realization) -> EdgeList | None:
    """Return the time-invariant edge list of a fixed-graph scenario, or ``None``."""
    if real.adjacency is None:
        return None
    if sc.law.all_pairs:
        return all_pairs_weights(sc.n_agents, real.adjacency, np.zeros((sc.n_agents, sc.dim)),
                                 sc.law)
    return fixed_graph(real.adjacency)


def simulate(sc: Scenario, progress: Callable[[str], None] | None = None,
             progress_every: float = 2.0) -> SimResult:
    """Run a scenario to its end and return the summary and the recorded time series.

    :param sc: the validated scenario.
    :param progress: called with a one-line status roughly every ``progress_every`` seconds.
    :param progress_every: wall-clock seconds between progress lines.
    :return: the result; ``summary['status']`` is ``completed``, ``interrupted`` or
        ``diverged``.
    """
    real = realize(sc)
    q, p = real.q0.copy(), real.p0.copy()
    agents = real.agents
    leader = VirtualLeader(sc.leader.field, sc.leader.position, sc.leader.velocity)
    intrinsic = sc.intrinsic.build() if sc.intrinsic is not None else None
    static = static_graph(sc, real)
    log = RunLog.for_scenario(sc)
    started = time.monotonic()
    # Divergence is detected explicitly below, so NumPy's overflow warnings would only repeat it.
    with np.errstate(over='ignore', invalid='ignore'):
        status, step, reselections = _run_loop(
            sc, real, q, p, agents, leader, intrinsic, static, log, progress, progress_every)
    series = log.rec.arrays()
    summary = build_summary(sc, real, series, log.metrics, step, status)
    summary['pseudo_leader_reselections'] = reselections
    summary['wall_time_s'] = round(time.monotonic() - started, 3)
    return SimResult(summary, series)


def _run_loop(sc, real, q, p, agents, leader, intrinsic, static, log, progress,
              progress_every):
    """Advance the swarm to the end (or divergence, or Ctrl-C); return how it ended."""
    law, dt, steps = sc.law, sc.dt, sc.steps
    status, step = 'completed', 0
    started = last = time.monotonic()
    reselector = Reselector(law) if sc.informed.reselect and static is None else None
    try:
        for step in range(steps + 1):
            state = leader.state
            edges = interaction_graph(sc, real, q, static)
            if reselector is not None:
                reselector.update(agents, edges)
            u = swarm_control(law, q, p, edges, state, agents, dt)
            if not (np.isfinite(u).all() and np.isfinite(q).all() and np.isfinite(p).all()):
                status = 'diverged'
                break
            if static is None:
                # r-disk edges cover every pair within the radius; all-pairs edges every pair.
                covered, radius = edges, np.inf if law.all_pairs else law.radius
            else:
                covered = disk_graph(q, sc.collision_distance)
                radius = sc.collision_distance
            log.observe(step, step * dt, q, p, u, state, agents.informed, covered, radius,
                        step == steps,
                        **({'h': agents.adaptive} if agents.adaptive is not None else {}))
            if step == steps:
                break
            advance_adaptive(law, q, p, state, agents, dt)
            q, p = step_agents(q, p, u, dt, intrinsic)
            leader.step(dt)
            now = time.monotonic()
            if progress is not None and now - last >= progress_every:
                last = now
                rate = (step + 1) / max(now - started, 1e-9)
                progress(f'[sim] t = {(step + 1) * dt:.2f}/{sc.duration:g} s  '
                         f'step {step + 1}/{steps}  eta = {log.latest.get("eta", 0):.2f}  '
                         f'mismatch = {log.latest.get("velocity_mismatch_max", 0):.3g}  '
                         f'({rate:.0f} steps/s)')
    except KeyboardInterrupt:
        status = 'interrupted'
    return status, step, 0 if reselector is None else reselector.count


def build_summary(sc: Scenario, real: Realization, series: dict, run: RunMetrics,
                  step: int, status: str) -> dict:
    """Return the ``summary.json`` mapping from the last recorded instant and the run totals.

    :param sc: the scenario.
    :param real: its realisation.
    :param series: the recorded time series.
    :param run: the whole-run metrics.
    :param step: the last step reached.
    :param status: ``completed``, ``interrupted`` or ``diverged``.
    :return: the summary (keys of DESIGN.md plus provenance).
    """
    last = {k: float(series[f'metric_{k}'][-1]) for k in STEP_METRICS}
    summary = {
        'n_agents': sc.n_agents,
        't_final': float(series['t'][-1]),
        'steps': int(step),
        'eta': last['eta'],
        'eta_tolerance': sc.eta_tolerance,
        'velocity_mismatch_max': last['velocity_mismatch_max'],
        'com_position_error': last['com_position_error'],
        'com_velocity_error': last['com_velocity_error'],
        'min_pair_distance': run.min_pair_distance,
        'collisions': len(run.collision_pairs),
        'collision_distance': sc.collision_distance,
        'components_final': int(last['components']),
        'informed': [int(i) for i in np.flatnonzero(series['informed'][0])],
        'scenario': sc.name,
        'seed': sc.seed,
        'protocol': sc.law.name,
        'dt': sc.dt,
        'status': status,
        'flock_swarm_version': __version__,
    }
    if real.selection is not None:
        summary['pseudo_leader_certificate'] = {
            'lambda_max': real.selection.lambda_max, 'alpha': real.selection.alpha,
            'satisfied': real.selection.satisfied, 'components': real.selection.components}
    if 'h' in series:
        summary['adaptive_gain_final'] = [float(x) for x in series['h'][-1]]
    return summary


def write_outputs(result: SimResult, out: Path, sc: Scenario) -> None:
    """Write ``summary.json``, ``timeseries.npz`` and the scenario used, into ``out``.

    :param result: the run.
    :param out: the output directory (created).
    :param sc: the scenario (its mapping is written as ``scenario.json`` for provenance).
    """
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / 'timeseries.npz', **result.series)
    (out / 'scenario.json').write_text(json.dumps(sc.raw, indent=2, default=jsonable) + '\n')
    # summary.json last: its presence means the other files are complete.
    tmp = out / 'summary.json.tmp'
    tmp.write_text(json.dumps(result.summary, indent=2, default=jsonable) + '\n')
    tmp.replace(out / 'summary.json')


def ensure_writable(out: Path) -> None:
    """Create ``out`` if needed and check that files can be written there.

    :param out: a directory.
    :raises OSError: when it cannot be created or written.
    """
    out.mkdir(parents=True, exist_ok=True)
    probe = out / '.write_test'
    probe.write_text('')
    probe.unlink()


def jsonable(value):
    """Return a JSON-serialisable form of NumPy values (``inf`` becomes ``null``)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if value == float('inf'):
        return None
    raise TypeError(f'not JSON serialisable: {type(value).__name__}')


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line naming the option, like scenario errors.

    ``sim: error: --seed: invalid int value: 'x'`` instead of argparse's usage block followed
    by ``sim: error: argument --seed: ...``; exit status 2 as argparse's.
    """

    def error(self, message: str):
        """Print ``PROG: error: OPTION: reason (see PROG --help)`` and exit with status 2."""
        required = 'the following arguments are required: '
        unknown = 'unrecognized arguments: '
        if message.startswith('argument '):
            message = message[len('argument '):]
        elif message.startswith(required):
            message = f'{message[len(required):]}: required'
        elif message.startswith(unknown):
            message = f'{message[len(unknown):]}: unrecognized argument(s)'
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``sim``."""
    parser = OneLineParser(
        prog='sim', description='Run a flocking scenario with the reference simulator.')
    parser.add_argument('scenario', help='preset name (see --list) or path to a YAML file')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE',
                        help='override one value, e.g. --set protocol.c1=0.8 (repeatable)')
    parser.add_argument('--seed', type=int, help='random seed (replaces the scenario seed)')
    parser.add_argument('--out', type=Path, help='output directory (default: out/SCENARIO)')
    parser.add_argument('--plots', action='store_true', help='also write PNG figures')
    parser.add_argument('--quiet', action='store_true', help='no progress output')
    parser.add_argument('--allow-unstable', action='store_true',
                        help='run even when dt violates a stability bound')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``sim`` from the command line; return the exit status."""
    parser = build_parser()
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == '--list':
        from flock_swarm.scenarios import preset_names
        print('\n'.join(preset_names()))
        return 0
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        # --help, or an argument error already printed: the status, as for every other error.
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    from flock_swarm.scenarios import load
    try:
        sc = load(args.scenario, args.overrides, args.seed)
        if args.seed is not None and args.seed < 0:
            raise ScenarioError('--seed', f'must be >= 0, got {args.seed}')
        violations = check_step(sc, realize(sc))
        if violations and not args.allow_unstable:
            raise ScenarioError('dt', violations[0].message(sc.dt).split(': ', 1)[1])
    except ScenarioError as exc:
        print(f'sim: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    out = args.out if args.out is not None else Path('out') / sc.name
    try:
        ensure_writable(out)
    except OSError as exc:
        print(f'sim: error: --out: cannot write to {out}: {exc.strerror}', file=sys.stderr)
        return EXIT_USAGE
    say = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    if say:
        say(f'[sim] {sc.name}: {sc.n_agents} agents, {sc.law.name}, {sc.steps} steps '
            f'of {sc.dt:g} s, seed {sc.seed}')
    result = simulate(sc, progress=say)
    try:
        write_outputs(result, out, sc)
        if args.plots:
            from flock_swarm.plots import plot_timeseries
            for path in plot_timeseries(result.series, out, sc.name):
                if say:
                    say(f'[sim] wrote {path}')
    except OSError as exc:
        print(f'sim: error: --out: writing {out} failed: {exc.strerror}', file=sys.stderr)
        return EXIT_USAGE
    s = result.summary
    if say:
        say(f'[sim] {s["status"]} at t = {s["t_final"]:g} s: eta = {s["eta"]:.3f}, '
            f'velocity mismatch = {s["velocity_mismatch_max"]:.3g}, '
            f'collisions = {s["collisions"]}, components = {s["components_final"]} '
            f'({s["wall_time_s"]:.1f} s wall)')
        say(f'[sim] wrote {out / "summary.json"} and {out / "timeseries.npz"}')
    if s['status'] == 'diverged':
        print(f'sim: error: the state stopped being finite at step {s["steps"]}; '
              'reduce dt', file=sys.stderr)
        return EXIT_DIVERGED
    return 130 if s['status'] == 'interrupted' else 0


if __name__ == '__main__':
    sys.exit(main())
