"""Running the reproduction: the presets and the Fig. 3 sweep (on the machinery of
:mod:`flock_swarm.study`, with its caches), the ROS runs against ``sim``, and each experiment's
JSON result."""

import json
import shutil
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from flock_swarm import __version__
from flock_swarm.core.run import check_step, simulate
from flock_swarm.core.scenario import Scenario
from flock_swarm.outputs import write_outputs
from flock_swarm.presets import load, prepare
from flock_swarm.reproduce import su2009
from flock_swarm.reproduce.catalogue import ANALYSES, EXPERIMENTS, FIGURES
from flock_swarm.reproduce.common import Experiment, fmt, set_args
from flock_swarm.reproduce.su2009 import Plan, describe_fig3, fig3_tasks
from flock_swarm.study.execute import LocalPool, Progress, SerialBackend, execute
from flock_swarm.study.spec import plain


#: ROS domain ids of the node runs: ROS_DOMAIN_BASE + index, one per run.
ROS_DOMAIN_BASE = 150

#: Wall-clock limit of one node run [s].
ROS_TIMEOUT = 300.0


def preset_overrides(exp: Experiment, quick: bool) -> list[str]:
    """Return the ``--set`` overrides of an experiment's preset run."""
    return list(exp.quick) if quick else []


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
    same = ran == json.loads(json.dumps(plain(sc.raw)))
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
                    live: Callable[[str], None] | None = None, backend=None) -> dict:
    """Run the presets, then the Fig. 3 sweep through the sweep machinery (caches reused).

    :param plan: what to run.
    :param out: the output directory.
    :param jobs: worker processes.
    :param fresh: ignore the caches.
    :param say: progress output.
    :param presets: also run the presets (``False``: the Fig. 3 sweep only).
    :param live: rewrites the terminal's progress line (see :class:`Progress`), or ``None``.
    :param backend: where the runs go (default: ``jobs`` local worker processes, or this
        process for one job; a :class:`~flock_swarm.study.execute.DaskBackend` for a
        cluster).
    :return: ``{'summaries': {key: summary}, 'fig3': [records], 'executed': n, 'cached': n,
        'core_seconds': s, 'wall_s': s}``.
    """
    started = time.monotonic()
    if backend is None:
        backend = SerialBackend() if jobs <= 1 else LocalPool(jobs, say)
    summaries, tasks, cached = {}, [], 0
    for exp in EXPERIMENTS if presets else ():
        if exp.key == 'su2009_fig3':
            continue
        overrides = preset_overrides(exp, plan.quick)
        sc, _ = prepare(exp.key, overrides)
        run_dir = out / 'runs' / exp.key
        summary = None if fresh else cached_preset(run_dir, sc)
        if summary is not None:
            summaries[exp.key] = summary
            cached += 1
        else:
            tasks.append({'kind': 'preset', 'key': exp.key, 'preset': exp.key,
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
    sweep = execute(fig3_tasks(plan), out / 'fig3_runs.jsonl', su2009.fig3_record, backend,
                    su2009.FIG3_STACK_AGENTS, say, live, fresh, prefix='reproduce',
                    describe=describe_fig3)
    fig3 = sweep['records']
    used = sum(x['wall_time_s'] for x in summaries.values()) \
        + sum(r['wall_time_s'] for r in fig3)
    return {'summaries': summaries, 'fig3': fig3, 'executed': len(tasks) + sweep['executed'],
            'cached': cached + sweep['cached'], 'core_seconds': core + sweep['core_seconds'],
            'core_seconds_all': used, 'wall_s': time.monotonic() - started}


def ros_experiments() -> list[Experiment]:
    """Return the experiments run through the ROS nodes (one per paper)."""
    return [e for e in EXPERIMENTS if e.ros is not None]


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
    from flock_swarm.nodes.harness import resolve_scenario, run_in_process

    overrides = list(exp.ros_quick if quick else exp.ros)
    run_dir = out / 'ros' / exp.key
    result_path = run_dir / 'comparison.json'
    domain = ROS_DOMAIN_BASE + index
    command = f'swarm {exp.key}{set_args(overrides)} --domain-id {domain}'
    if not fresh and result_path.is_file():
        old = json.loads(result_path.read_text())
        if old.get('command') == command and old.get('flock_swarm_version') == __version__ \
                and 'error' not in old:
            say(f'[reproduce] ROS {exp.key}: reused {result_path}')
            return dict(old, reused=True)
    if run_dir.exists():
        shutil.rmtree(run_dir)
    path = resolve_scenario(exp.key, overrides, None, run_dir)
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
    result_path.write_text(json.dumps(plain(res), indent=2) + '\n')
    say(f'[reproduce] ROS {exp.key}: {res["ros_status"]} in {wall:.1f} s, max |q_ros - q_sim| '
        f'= {fmt(res["max_dev_q"])} m')
    return plain(res)


#: The summary metrics compared between the ROS run and sim.
COMPARED = ('eta', 'velocity_mismatch_max', 'com_position_error', 'com_velocity_error',
            'min_pair_distance', 'collisions', 'components_final')


def experiment_result(exp: Experiment, plan: Plan, summary: dict, out: Path,
                      figures: Path) -> dict:
    """Analyse one preset run, draw its figure, and return its JSON result.

    :param exp: the experiment.
    :param plan: the plan (quick or not).
    :param summary: the run's summary.
    :param out: the output directory (the run's files are in ``out/runs/<key>``).
    :param figures: where the figure goes.
    :return: the result mapping.
    """
    overrides = preset_overrides(exp, plan.quick)
    sc, real = prepare(exp.key, overrides, allow_unstable=True)
    with np.load(out / 'runs' / exp.key / 'timeseries.npz') as data:
        series = {k: data[k] for k in data.files}
    metrics = ANALYSES[exp.key](sc, summary, series)
    fig = FIGURES[exp.key](sc, summary, series, metrics, figures / f'{exp.key}.png')
    return {'key': exp.key, 'title': exp.title, 'preset': exp.key, 'overrides': overrides,
            'command': f'sim {exp.key}{set_args(overrides)}', 'seed': sc.seed,
            'n_agents': sc.n_agents, 'dt': sc.dt, 'duration': sc.duration,
            'stability_violations': len(check_step(sc, real)),
            'summary': plain(summary), 'metrics': plain(metrics), 'figure': fig.name}
