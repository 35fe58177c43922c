"""Benchmark of the reference simulator against a per-agent Python loop of the same law.

    python bench/bench_sim.py [--sizes 100 1000 10000 100000] [--baseline-sizes 100 300]
                              [--steps 20] [--repeats 5] [--json out/bench/sim.json]

Scenario: Su, Wang, Lin 2009 Fig. 3 (density N / L^2 = 0.05, protocol (10), 10 % informed,
2-D). For each N it times the steps of :func:`flock_swarm.core.run.simulate` itself (neighbour
search, law, integration, whole-run metrics; the first ``--steps`` steps from the preset's
random start), best of ``--repeats`` runs for N below 10000, and reports steps/s and the
time per agent-step. The baseline is the straightforward implementation most published flocking
code uses: a Python loop over agents and, for each, over every other agent, with scalar
``math``. It is checked to produce the same accelerations as ``sim`` (to 1e-9) before it is
timed, so the comparison is between two implementations of one law.

Targets (issue 5), printed with PASS or FAIL against the measured ratio: ``sim`` at least
100 times the baseline's steps/s at N = 300; time per agent-step at N = 100000 within 1.5
times that at N = 1000.
"""

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from flock_swarm.core.dynamics import step_agents
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.laws.evaluation import swarm_control
from flock_swarm.core.laws.su2009 import SuParams
from flock_swarm.core.leaders.base import VirtualLeader
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.reproduce.report import machine
from flock_swarm.presets import load
from flock_swarm.core.run import simulate

#: Issue 5: sim's speed over the per-agent loop at N = SPEEDUP_N, at least SPEEDUP_MIN.
SPEEDUP_N, SPEEDUP_MIN = 300, 100.0
#: Issue 5: time per agent-step at the largest N over that at LINEAR_N, at most LINEAR_MAX.
LINEAR_N, LINEAR_MAX = 1000, 1.5


def fig3_scenario(n: int, steps: int) -> Scenario:
    """Return Su 2009 Fig. 3's preset at ``n`` agents (density 0.05), ``steps`` steps long."""
    side = math.sqrt(n / 0.05)
    return load('su2009_fig3', [f'n_agents={n}',
                                f'initial.position_box=[[0, {side}], [0, {side}]]',
                                f'duration={steps * 0.02}', 'dt=0.02'])


def time_sim_steps(n: int, steps: int, repeats: int) -> float:
    """Return the wall time of one step of ``sim`` at ``n`` agents.

    ``simulate`` reports progress after every step when asked to (``progress_every=0``):
    the time between the first and the last report, over the steps between them, leaves
    out the setup, the first step and the final record.

    :param n: number of agents.
    :param steps: steps per run.
    :param repeats: runs; the fastest counts.
    :return: seconds per step.
    """
    best = math.inf
    sc = fig3_scenario(n, steps + 1)
    for _ in range(repeats):
        stamps: list[float] = []
        simulate(sc, progress=lambda line: stamps.append(time.perf_counter()),
                 progress_every=0.0)
        best = min(best, (stamps[-1] - stamps[0]) / (len(stamps) - 1))
    return best


def baseline_accelerations(law: SuParams, q: list, p: list, leader_q, leader_p,
                           informed: list) -> list:
    """Return Su 2009 eq. (10) for every agent with nested Python loops and ``math``."""
    eps, h, a, b = law.eps, law.h, law.a, law.b
    r_a = (math.sqrt(1 + eps * law.r ** 2) - 1) / eps
    d_a = (math.sqrt(1 + eps * law.d ** 2) - 1) / eps
    c = abs(a - b) / math.sqrt(4 * a * b)
    n, dim = len(q), len(q[0])
    out = []
    for i in range(n):
        acc = [0.0] * dim
        for j in range(n):
            if j == i:
                continue
            diff = [q[j][k] - q[i][k] for k in range(dim)]
            sq = sum(x * x for x in diff)
            if sq >= law.r * law.r:
                continue
            root = math.sqrt(1 + eps * sq)
            z = (root - 1) / eps
            s = z / r_a
            rho = 1.0 if s < h else (0.5 * (1 + math.cos(math.pi * (s - h) / (1 - h)))
                                     if s <= 1 else 0.0)
            w = z - d_a + c
            phi = 0.5 * ((a + b) * w / math.sqrt(1 + w * w) + (a - b))
            for k in range(dim):
                acc[k] += rho * phi * diff[k] / root + rho * (p[j][k] - p[i][k])
        if informed[i]:
            for k in range(dim):
                acc[k] -= law.c1 * (q[i][k] - leader_q[k]) + law.c2 * (p[i][k] - leader_p[k])
        out.append(acc)
    return out


def time_baseline(sc: Scenario, steps: int) -> float:
    """Check the baseline against ``sim``'s law, then return its mean step time."""
    real = realize(sc)
    q, p = real.q0.copy(), real.p0.copy()
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity).state
    informed = real.agents.informed.tolist()
    reference = swarm_control(sc.law, q, p, disk_graph(q, sc.law.radius), leader,
                              real.agents, sc.dt)
    got = np.array(baseline_accelerations(sc.law, q.tolist(), p.tolist(), leader.q.tolist(),
                                          leader.p.tolist(), informed))
    np.testing.assert_allclose(got, reference, rtol=1e-9, atol=1e-9)
    start = time.perf_counter()
    for _ in range(steps):
        u = np.array(baseline_accelerations(sc.law, q.tolist(), p.tolist(), leader.q.tolist(),
                                            leader.p.tolist(), informed))
        q, p = step_agents(q, p, u, sc.dt, None)
    return (time.perf_counter() - start) / steps


def verdict(ok: bool) -> str:
    """Return ``PASS`` or ``FAIL``."""
    return 'PASS' if ok else 'FAIL'


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print (and optionally save) the table and the targets."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[100, 1000, 10000, 100000])
    parser.add_argument('--baseline-sizes', type=int, nargs='+', default=[100, SPEEDUP_N])
    parser.add_argument('--steps', type=int, default=20)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--json', type=Path, help='also write the results here')
    args = parser.parse_args(argv)
    host = machine()
    print(f'# {host["nproc"]} CPUs ({host["cpu_model"]}), Python {host["python"]}, '
          f'load average {" ".join(f"{x:.2f}" for x in host["load_average"])}', flush=True)
    results = {'machine': host, 'steps': args.steps, 'sim': {}, 'baseline': {},
               'targets': {}}
    for n in sorted(set(args.sizes) | set(args.baseline_sizes)):
        step = time_sim_steps(n, args.steps, args.repeats if n < 10000 else 1)
        results['sim'][n] = {'step_s': step, 'steps_per_s': 1 / step,
                             'us_per_agent_step': step / n * 1e6}
        print(f'sim       N = {n:>6}: {1 / step:9.1f} steps/s  '
              f'{step / n * 1e6:6.2f} us/agent-step', flush=True)
    for n in args.baseline_sizes:
        steps = max(2, args.steps // 10)
        step = time_baseline(fig3_scenario(n, steps), steps)
        speedup = step / results['sim'][n]['step_s']
        results['baseline'][n] = {'step_s': step, 'steps_per_s': 1 / step,
                                  'sim_speedup': speedup}
        print(f'baseline  N = {n:>6}: {1 / step:9.2f} steps/s  sim is {speedup:.0f}x faster',
              flush=True)
    if SPEEDUP_N in results['baseline']:
        speedup = results['baseline'][SPEEDUP_N]['sim_speedup']
        ok = speedup >= SPEEDUP_MIN
        results['targets']['speedup'] = {'n': SPEEDUP_N, 'measured': speedup,
                                         'target': SPEEDUP_MIN, 'pass': ok}
        print(f'target: sim >= {SPEEDUP_MIN:.0f}x the per-agent loop at N = {SPEEDUP_N}: '
              f'{verdict(ok)} ({speedup:.0f}x)')
    sizes = sorted(results['sim'])
    if len(sizes) > 1 and LINEAR_N in results['sim'] and sizes[-1] > LINEAR_N:
        ratio = (results['sim'][sizes[-1]]['us_per_agent_step']
                 / results['sim'][LINEAR_N]['us_per_agent_step'])
        ok = ratio <= LINEAR_MAX
        results['targets']['linear'] = {'largest_n': sizes[-1], 'measured': ratio,
                                        'target': LINEAR_MAX, 'pass': ok}
        print(f'target: time per agent-step at N = {sizes[-1]} <= {LINEAR_MAX:g} x that at '
              f'N = {LINEAR_N}: {verdict(ok)} ({ratio:.2f})')
    finish(results, args.json)
    return 0


def finish(results: dict, path: Path | None) -> None:
    """Add and print the load average at the end; write ``results`` to ``path`` if given."""
    results['load_average_end'] = list(os.getloadavg())
    print(f'# load average at the end: '
          f'{" ".join(f"{x:.2f}" for x in results["load_average_end"])}')
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=2) + '\n')


if __name__ == '__main__':
    raise SystemExit(main())
