"""Running the reproduction: every experiment's preset run and the sweeps some experiments
run beside it (Su Fig. 3; on the machinery of :mod:`flock_swarm.study`, with its caches), and
the ROS runs against ``sim``."""

import json
import shutil
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from flock_swarm import __version__
from flock_swarm.core.headline import run_mapping
from flock_swarm.core.summary import compared_metrics
from flock_swarm.core.run import simulate
from flock_swarm.core.scenario import Scenario
from flock_swarm.outputs import plain_json, write_outputs
from flock_swarm.presets import load, prepare
from flock_swarm.reproduce.catalogue import all_experiments
from flock_swarm.reproduce.common import fmt, set_args
from flock_swarm.reproduce.experiment import Experiment
from flock_swarm.reproduce.plan import Plan
from flock_swarm.study.execute import LocalPool, Progress, SerialBackend, execute


#: ROS domain ids of the node runs: ROS_DOMAIN_BASE + index, one per run.
ROS_DOMAIN_BASE = 150

#: Wall-clock limit of one node run [s].
ROS_TIMEOUT = 300.0


def cached_preset(out: Path, sc: Scenario) -> dict | None:
    """Return the cached summary of a preset run when it ran this very scenario, else ``None``.

    :param out: the run's directory.
    :param sc: the scenario about to run.
    :return: the summary or ``None``.
    """
    try:
        summary = json.loads((out / 'summary.json').read_text())
        ran = json.loads((out / 'scenario.json').read_text())
    except (OSError, ValueError):
        return None
    if not (out / 'timeseries.npz').is_file():
        return None
    # The headline changes what is printed, not the run: a run from before it was chosen counts.
    same = isinstance(ran, dict) \
        and run_mapping(ran) == json.loads(json.dumps(plain_json(run_mapping(sc.raw))))
    if same and summary.get('flock_swarm_version') == __version__ \
            and summary.get('status') == 'completed':
        return summary
    return None


def run_task(task: dict) -> dict:
    """Run one preset job of the pool (``key``, ``preset``, ``overrides``, ``out``).

    :return: its summary.
    """
    sc, _ = prepare(task['preset'], task['overrides'])
    result = simulate(sc)
    write_outputs(result, Path(task['out']), sc)
    return {'kind': 'preset', 'key': task['key'], 'summary': result.summary}


def run_simulations(plan: Plan, out: Path, jobs: int, fresh: bool,
                    say: Callable[[str], None], presets: bool = True,
                    live: Callable[[str], None] | None = None, backend=None,
                    experiments: tuple[Experiment, ...] | None = None) -> dict:
    """Run the experiments' presets, then the sweeps they run beside them (caches reused).

    :param plan: what to run.
    :param out: the output directory.
    :param jobs: worker processes.
    :param fresh: ignore the caches.
    :param say: progress output.
    :param presets: also run the presets (``False``: the sweeps only).
    :param live: rewrites the terminal's progress line (see :class:`Progress`), or ``None``.
    :param backend: where the runs go (default: ``jobs`` local worker processes, or this
        process for one job; a :class:`~flock_swarm.study.execute.DaskBackend` for a
        cluster).
    :param experiments: the experiments (default: the catalogue's).
    :return: ``{'summaries': {key: summary}, 'sweeps': {key: [records]}, 'executed': n,
        'cached': n, 'core_seconds': s, 'core_seconds_all': s, 'wall_s': s}``.
    """
    started = time.monotonic()
    if backend is None:
        backend = SerialBackend() if jobs <= 1 else LocalPool(jobs, say)
    if experiments is None:
        experiments = all_experiments()
    summaries, tasks, cached = {}, [], 0
    for exp in experiments if presets else ():
        if not exp.runs_preset:
            continue
        overrides = exp.preset_overrides(plan.quick)
        sc, _ = prepare(exp.scenario, overrides)
        run_dir = out / 'runs' / exp.key
        summary = None if fresh else cached_preset(run_dir, sc)
        if summary is not None:
            summaries[exp.key] = summary
            cached += 1
        else:
            tasks.append({'kind': 'preset', 'key': exp.key, 'preset': exp.scenario,
                          'overrides': overrides, 'out': str(run_dir),
                          'weight': sc.steps * sc.n_agents, 'cost': sc.steps * sc.n_agents ** 2})
    # The long runs first, so that they do not end up alone at the end.
    tasks.sort(key=lambda t: -t['cost'])
    core = 0.0
    if tasks:
        say(f'[reproduce] presets: {len(tasks)} to run, {cached} reused from {out}; on '
            f'{backend.name}')
        progress = Progress(len(tasks), sum(t['weight'] for t in tasks), say, live,
                            prefix='reproduce')
        for task, res in backend.results(run_task, tasks):
            summaries[res['key']] = res['summary']
            core += res['summary']['wall_time_s']
            progress.step(1, task['weight'], f'{res["key"]}: {res["summary"]["status"]}')
    sweeps, executed = {}, len(tasks)
    for exp in experiments:
        sweep = exp.sweep(plan)
        if sweep is None:
            continue
        done = execute(sweep.runs, out / sweep.cache, sweep.recorder, backend,
                       sweep.stack_agents, say, live, fresh, prefix='reproduce',
                       describe=sweep.describe)
        sweeps[exp.key] = done['records']
        executed += done['executed']
        cached += done['cached']
        core += done['core_seconds']
    used = sum(x['wall_time_s'] for x in summaries.values()) \
        + sum(r['wall_time_s'] for records in sweeps.values() for r in records)
    return {'summaries': summaries, 'sweeps': sweeps, 'executed': executed, 'cached': cached,
            'core_seconds': core, 'core_seconds_all': used,
            'wall_s': time.monotonic() - started}


def ros_experiments() -> list[Experiment]:
    """Return the experiments run through the ROS nodes (one per paper)."""
    return [e for e in all_experiments() if e.ros is not None]


def run_ros(exp: Experiment, index: int, out: Path, quick: bool, fresh: bool,
            say: Callable[[str], None]) -> dict:
    """Run an experiment through world, leader and agents (lockstep, one process) and sim.

    :param exp: the experiment.
    :param index: its index among the ROS runs (domain id ``ROS_DOMAIN_BASE + index``).
    :param out: the output directory (the run goes to ``out/ros/<key>``).
    :param quick: use the ``--quick`` overrides.
    :param fresh: ignore a cached result.
    :param say: progress output.
    :return: the comparison (flat mapping; ``error`` set when the run failed).
    """
    from flock_swarm.analysis.compare import compare_runs
    from flock_swarm.nodes.swarm_runner import resolve_scenario, run_in_process

    overrides = list(exp.ros_quick if quick else exp.ros)
    run_dir = out / 'ros' / exp.key
    result_path = run_dir / 'comparison.json'
    domain = ROS_DOMAIN_BASE + index
    command = f'swarm {exp.scenario}{set_args(overrides)} --domain-id {domain}'
    if not fresh and result_path.is_file():
        old = json.loads(result_path.read_text())
        if old.get('command') == command and old.get('flock_swarm_version') == __version__ \
                and 'error' not in old:
            say(f'[reproduce] ROS {exp.key}: reused {result_path}')
            return dict(old, reused=True)
    if run_dir.exists():
        shutil.rmtree(run_dir)
    path = resolve_scenario(exp.scenario, overrides, None, run_dir)
    sc = load(str(path))
    say(f'[reproduce] ROS {exp.key}: world + leader + {sc.n_agents} agents, lockstep, '
        f'{sc.steps} steps, domain {domain}')
    last = [0.0]

    def progress(line: str) -> None:
        """Print the world's progress line at most every 10 s."""
        now = time.monotonic()
        if now - last[0] >= 10.0:
            last[0] = now
            say(f'    {line}')

    started = time.monotonic()
    res: dict[str, Any] = {'command': command, 'overrides': overrides, 'domain_id': domain,
                           'flock_swarm_version': __version__}
    try:
        ros = run_in_process(path, run_dir, domain_id=domain, timeout=ROS_TIMEOUT,
                             progress=progress)
    except Exception as exc:  # a failed node run is reported in the report, not fatal
        res['error'] = f'{type(exc).__name__}: {exc}'
        say(f'[reproduce] ROS {exp.key}: failed: {res["error"]}')
        return res
    wall = time.monotonic() - started
    sim = simulate(sc)
    with np.load(run_dir / 'timeseries.npz') as data:
        ros_series = {k: data[k] for k in data.files}
    # sim is the reference, the ROS run the run under test.
    comparison = compare_runs(sim.summary, sim.series, ros, ros_series)
    res.update(comparison.side_by_side(COMPARED, 'sim', 'ros'))
    res['recorded_instants'] = int(ros_series['t'].shape[0])
    for name in ('q', 'p'):
        res[f'max_dev_{name}'] = (comparison.max_deviation[name] if comparison.same_instants
                                  else None)
    res.update({'n_agents': sc.n_agents, 'steps': sc.steps, 'ros_wall_s': round(wall, 1),
                'ros_steps_per_s': round(sc.steps / wall, 1),
                'ros_missed_commands': int(ros.get('missed_commands', 0)),
                'ros_status': ros.get('status')})
    result_path.write_text(json.dumps(plain_json(res), indent=2) + '\n')
    say(f'[reproduce] ROS {exp.key}: {res["ros_status"]} in {wall:.1f} s, max |q_ros - q_sim| '
        f'= {fmt(res["max_dev_q"])} m')
    return plain_json(res)


#: The summary metrics compared between the ROS run and sim.
COMPARED = compared_metrics()
