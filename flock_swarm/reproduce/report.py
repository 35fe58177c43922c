"""The Markdown report: provenance, the summary of every experiment's criterion and verdict,
the papers' misprints, one section per experiment, the ROS comparison. Everything particular
to an experiment comes from its object (:class:`~flock_swarm.reproduce.experiment.Experiment`):
this module names none."""

import json
import os
import platform
import subprocess
from pathlib import Path

from flock_swarm import __version__
from flock_swarm.outputs import plain_json
from flock_swarm.reproduce import stats
from flock_swarm.reproduce.catalogue import all_experiments
from flock_swarm.reproduce.common import cell, fmt
from flock_swarm.reproduce.execution import COMPARED
from flock_swarm.reproduce.plan import Plan
from flock_swarm.reproduce.seeds import SEEDS_CHEAP, SEEDS_COSTLY, questions_cell


def machine() -> dict:
    """Return the machine's description: CPUs, CPU model, Python, load at the start."""
    model = 'unknown'
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                model = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    return {'nproc': os.cpu_count(), 'cpu_model': model, 'python': platform.python_version(),
            'platform': platform.platform(), 'load_average': list(os.getloadavg())}


def git_revision() -> str:
    """Return the checked-out commit (short hash), with a note when the code has changes."""
    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=root,
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'flock_swarm',
                                'config', 'scripts'], cwd=root, capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return 'unknown'
    return head + (' plus uncommitted changes in flock_swarm/, config/ or scripts/'
                   if dirty else '')


#: How a verdict is reached, for the report's preamble.
RULE = (
    'Each experiment states its criterion before any number: the paper\'s claim as a '
    'statistic over seeds (a mean against the paper\'s value with a margin, or the fraction '
    'of seeds meeting a per-seed claim), with its 95 % confidence interval (Student\'s t for '
    'means, Wilson for fractions). The verdict is **reproduced** when the interval lies inside '
    'the values that support the claim, **not reproduced** when it lies outside them, '
    '**inconclusive** when it straddles an edge. Every set-up (variant) is judged on its own; '
    'the summary\'s verdict is that of the paper\'s set-up, the first of each table, and '
    f'the variants\' follow it. Seeds: {SEEDS_CHEAP} per set-up where a run costs under a '
    f'minute of computing, {SEEDS_COSTLY} where it costs more (each table says which).')


def ros_section(res: dict) -> list[str]:
    """Return the report lines of a ROS run against sim."""
    if res is None:
        return []
    lines = ['', f'**Through the ROS 2 nodes.** `{res["command"]}` (world, leader and every '
             'agent in one process, lockstep, `flock_swarm.nodes.swarm_runner.run_in_process`), '
             'and `sim` on the same resolved scenario:', '']
    if 'error' in res:
        return lines + [f'The node run failed: `{res["error"]}`; no comparison.']
    lines += ['| metric | sim | ROS nodes |', '|---|---|---|']
    for key in COMPARED:
        lines.append(f'| {key} | {fmt(res["sim_" + key])} | {fmt(res["ros_" + key])} |')
    dev = res['max_dev_q']
    if dev is None:
        lines += ['', 'The ROS run recorded different instants from sim\'s, so no trajectory '
                  'deviation is computed.']
    else:
        exact = dev == 0 and res['max_dev_p'] == 0
        lines += ['', f'Max deviation over the {res["recorded_instants"]} recorded instants: '
                  f'|q_ROS - q_sim| = {fmt(dev)} m, |p_ROS - p_sim| = {fmt(res["max_dev_p"])} '
                  'm/s ' + ('(bit-identical). ' if exact else
                            '(rounding level: the agent node adds its neighbours\' terms in '
                            'one pass, `local_control`, sim in two `bincount` passes, '
                            '`pair_sums`, so the floating-point sums can differ in the last '
                            'bit). ')
                  + f'{res["n_agents"]} agents, {res["steps"]} steps through the nodes in '
                  f'{fmt(res["ros_wall_s"])} s ({fmt(res["ros_steps_per_s"])} steps/s), '
                  f'{res["ros_missed_commands"]} missed commands, status {res["ros_status"]}.']
        differ = [k for k in COMPARED if fmt(res['sim_' + k]) != fmt(res['ros_' + k])]
        if differ == ['min_pair_distance']:
            lines[-1] += (
                ' The closest approach differs although the trajectories agree: it is '
                'tracked exactly only below a radius and otherwise taken at the recorded '
                'instants (docs/outputs.md), and for this fixed-graph law sim tracks it below '
                'the collision distance while the world node tracks it within the law\'s '
                'radius, so the world node sees a closer pair between recorded instants.')
        elif differ:
            lines[-1] += (f' {", ".join(differ)} differ although the trajectories agree: '
                          'they are whole-run bookkeeping, not state.')
    return lines


def verdict_cell(judged: dict) -> str:
    """Return the summary's verdict: the paper's set-up's, then each variant's."""
    if judged['verdict'] == stats.NOT_RUN:
        return stats.NOT_RUN
    text = f'**{judged["verdict"]}**'
    if judged.get('fragile'):
        text += ' (**fragile**: the held-out seeds differ)'
    others = [f'{label}: {verdict}' for label, verdict in judged['setups'][1:]]
    return text + (f' (variants: {"; ".join(others)})' if others else '')


def misprints(experiments) -> list[str]:
    """Return the misprints the experiments found in their papers, in the report's order."""
    return [text for exp in experiments for text in exp.misprints]


def record_invocation(out: Path, meta: dict, plan: Plan) -> list[dict]:
    """Append this invocation to ``out/invocations.jsonl``; return those that ran anything.

    The report lists them: with the caches, its runs may come from several invocations.
    """
    entry = {'command': meta['command'], 'date': meta['date'], 'git': meta['git'],
             'quick': plan.quick, 'realisations': plan.realisations,
             'wall_min': round(meta['wall_min'], 2),
             'sim_runs': meta['simulations']['executed'],
             'sim_cpu_min': round(meta['simulations']['core_seconds'] / 60.0, 2),
             'sim_wall_min': round(meta['simulations']['wall_s'] / 60.0, 2),
             'ros_runs': meta['ros_executed'], 'ros_wall_min': round(meta['ros_wall_s'] / 60, 2),
             'nproc': meta['machine']['nproc'], 'cpu_model': meta['machine']['cpu_model'],
             'load_average': meta['machine']['load_average']}
    append_invocation(out, entry)
    history = []
    for line in (out / 'invocations.jsonl').read_text().splitlines():
        try:
            item = json.loads(line)
        except ValueError:
            continue
        if item.get('quick') == plan.quick and (item.get('sim_runs') or item.get('ros_runs')):
            history.append(item)
    return history


def append_invocation(out: Path, entry: dict) -> None:
    """Append one invocation's record to ``out/invocations.jsonl`` (also ``bench_sweep``'s,
    whose runs the report then uses)."""
    with open(out / 'invocations.jsonl', 'a') as log:
        log.write(json.dumps(plain_json(entry)) + '\n')


def write_report(results: dict[str, dict], ros: dict[str, dict], plan: Plan, meta: dict,
                 report: Path, figures: Path) -> Path:
    """Write the Markdown report.

    :param results: the JSON result of every experiment, by key.
    :param ros: the ROS comparisons, by experiment key.
    :param plan: what ran.
    :param meta: provenance: command, machine, wall times, counts.
    :param report: the report's path.
    :param figures: the figures' directory.
    :return: the report's path.
    """
    rel = Path(os.path.relpath(figures, report.parent))
    mach = meta['machine']
    sims = meta['simulations']
    lines = [
        '# Reproduction report',
        '',
        'Every experiment of the five papers (the presets of `docs/scenarios.md`), run with the '
        'reference simulator on its preset (the papers\' numbers; `config/<preset>.yaml`), '
        'set against what the paper claims. All numbers below are written by the run; none is '
        'typed by hand.'
        + (' **This is a `--quick` run (tiny sizes and durations): its numbers are not a '
           'reproduction.**' if plan.quick else ''),
        '',
        '## How this report was made',
        '',
        f'- This report was written by `{meta["command"]}` (run from the repository root; '
        '`scripts/reproduce` with the same options is equivalent).',
        f'- Date: {meta["date"]} (UTC); commit {meta["git"]}; flock_swarm {__version__}.',
        f'- Machine: {mach["nproc"]} CPUs (`nproc`), CPU model "{mach["cpu_model"]}" '
        f'(`/proc/cpuinfo`), Python {mach["python"]}, {mach["platform"]}; load average '
        f'{", ".join(f"{x:.2f}" for x in mach["load_average"])} at the start (the machine is '
        'shared).',
        f'- Wall time of this invocation: {meta["wall_min"]:.1f} min in all; simulations '
        f'{sims["wall_s"] / 60:.1f} min on {meta["jobs"]} worker process(es) '
        f'({sims["executed"]} runs, {sims["core_seconds"] / 60:.1f} CPU-min), '
        f'{sims["cached"]} simulation runs reused from the cache in `{meta["out"]}`; ROS '
        f'runs {meta["ros_wall_s"] / 60:.1f} min ({meta["ros_executed"]} executed, '
        f'{meta["ros_total"] - meta["ros_executed"]} reused). All simulation runs used here '
        'took '
        f'{sims["core_seconds_all"] / 60:.1f} CPU-min when they ran.'
        + (' It ran nothing new: it rendered the report from the cached runs below.'
           if sims['executed'] == 0 and meta['ros_executed'] == 0 else ''),
    ]
    rendered = meta.get('rendered_from')
    if rendered:
        lines.append(
            f'- Nothing ran: the presets\' and ROS runs\' results are those committed in '
            f'`{rendered["where"]}/` by `{rendered["command"]}` on {rendered["date"]} (UTC, '
            f'commit {rendered["git"]}), the studies over seeds come from their caches, and '
            'the presets\' figures are the ones that run drew.')
    lines += [
        '- The runs used here were computed by these invocations (from '
        f'`{meta["out"]}/invocations.jsonl`; '
        f'{sum(item["wall_min"] for item in meta["history"]):.1f} min of wall time in all):',
        '',
        '| date (UTC) | command | wall [min] | simulation runs (CPU-min) | ROS runs (min) | '
        'load at start |',
        '|---|---|---|---|---|---|',
    ]
    for item in meta['history']:
        lines.append(
            f'| {item["date"]} | `{item["command"]}` | {item["wall_min"]:.1f} | '
            f'{item["sim_runs"]} ({item["sim_cpu_min"]:.1f}) | {item["ros_runs"]} '
            f'({item["ros_wall_min"]:.1f}) | '
            f'{", ".join(f"{x:.2f}" for x in item["load_average"])} |')
    lines += [
        '',
        '- Caches: presets in `OUT/runs/`, the sweeps some experiments run beside their preset '
        'in `OUT/*.jsonl` (one JSON line per run, keyed by a hash of the scenario and package '
        'version), the ROS runs in '
        '`OUT/ros/`. Re-running the command resumes; a larger `--realisations` adds only the '
        'missing runs. Every full run also writes its results to `docs/reproduction/results/` '
        '(committed): `--cached-seeds` with no run in OUT renders the report from them.',
        f'- ROS runs: {meta["ros_note"]}',
        '',
        '- Over seeds: each experiment\'s study (`config/sweeps/reproduce_*.yaml`, seeds from '
        '1; the preset\'s own seed stays the figure) is cached in `'
        f'{meta.get("seeds_cache", "docs/reproduction/runs")}/` (one JSON line per run, '
        'committed, resumed by every invocation; `--cached-seeds` runs nothing new).',
        f'- Verdicts: {RULE}',
        '',
        '## Summary',
        '',
        'Each row: the paper\'s claim, our run of the preset, the criterion and its verdict '
        'over seeds (and on the held-out seeds), then the three questions apart for the '
        'paper\'s set-up (is the flock whole: the fraction linked to an informed agent; does it '
        'move with the leader: the group\'s velocity error; do the agents agree: eta at two '
        'tolerances) and, for a study beyond the papers, its mechanism measured beside its '
        'prediction.',
        '',
        '| experiment | paper | ours (the preset\'s seed) | criterion | over seeds (the '
        'paper\'s set-up; 95 % interval) | verdict | whole / with leader / agreement | '
        'mechanism |',
        '|---|---|---|---|---|---|---|---|',
    ]
    experiments = all_experiments()
    for exp in experiments:
        res = results.get(exp.key)
        if res is None:
            lines.append(f'| {exp.title} | | not run | | | | | |')
            continue
        paper, ours = exp.headline(res)
        judged = exp.judge(res)
        lines.append(f'| [{exp.title}](#{anchor(exp.title)}) | {paper} | {ours} | '
                     f'{cell(exp.criterion.short())} | {cell(judged["over"])} | '
                     f'{verdict_cell(judged)} | {cell(questions_cell(res.get("seeds")))} | '
                     f'{cell(exp.mechanism(res) or "-")} |')
    lines += ['', '## Misprints in the papers', '']
    lines += [f'- {text}' for text in misprints(experiments)]
    for exp in experiments:
        lines += ['', f'## {exp.title}', '']
        res = results.get(exp.key)
        if res is None:
            lines.append('Not run in this invocation.')
            continue
        lines += [f'**Paper** ({exp.paper}). {exp.claim}', '',
                  f'**Criterion** (stated before the numbers). {exp.criterion.statement()}', '']
        lines += exp.body(res, plan, rel)
        lines += ros_section(ros.get(exp.key))
        lines += ['', f'![{exp.key}]({(rel / res["figure"]).as_posix()})']
    report.parent.mkdir(parents=True, exist_ok=True)
    report.write_text('\n'.join(lines) + '\n')
    return report


def anchor(title: str) -> str:
    """Return the GitHub-style anchor of a Markdown heading."""
    keep = ''.join(c for c in title.lower() if c.isalnum() or c in ' -_')
    return keep.replace(' ', '-')


def write_seeds_report(studies: dict[str, dict], meta: dict, report: Path,
                       figures: Path) -> Path:
    """Write the report of the studies over seeds alone (``--seeds-only``): a summary of the
    criteria and verdicts, then one section per experiment.

    :param studies: :func:`~flock_swarm.reproduce.seeds.run_studies`' result.
    :param meta: provenance: command, date, commit, machine, cache.
    :param report: the report's path.
    :param figures: the figures' directory.
    :return: the report's path.
    """
    rel = Path(os.path.relpath(figures, report.parent))
    mach = meta['machine']
    experiments = [e for e in all_experiments() if e.key in studies]
    lines = [
        '# Reproduction over seeds', '',
        f'Written by `{meta["command"]}` on {meta["date"]} (UTC), commit {meta["git"]}, '
        f'flock_swarm {__version__}, from the caches in `{meta["seeds_cache"]}/` (one JSON '
        f'line per run; {meta["wall_min"]:.1f} min; load average '
        f'{", ".join(f"{x:.2f}" for x in mach["load_average"])} at the start on '
        f'{mach["nproc"]} CPUs). Every number is written by the run. {RULE}', '',
        '| experiment | criterion | the paper\'s set-up over seeds (95 % interval) | '
        'verdict | whole / with leader / agreement | mechanism |', '|---|---|---|---|---|---|']
    for exp in experiments:
        judged = exp.judge({'seeds': studies[exp.key]})
        lines.append(f'| [{exp.title}](#{anchor(exp.title)}) | {cell(exp.criterion.short())} '
                     f'| {cell(judged["over"])} | {verdict_cell(judged)} | '
                     f'{cell(questions_cell(studies[exp.key]))} | '
                     f'{cell(exp.mechanism({"seeds": studies[exp.key]}) or "-")} |')
    for exp in experiments:
        lines += ['', f'## {exp.title}', '',
                  f'**Criterion** (stated before the numbers). {exp.criterion.statement()}']
        lines += exp.seeds_section(studies[exp.key], rel)
    report.parent.mkdir(parents=True, exist_ok=True)
    report.write_text('\n'.join(lines) + '\n')
    return report
