"""Benchmark of the reference simulator against a per-agent Python loop of the same law.

    python bench/bench_sim.py [--sizes 100 1000 10000 100000] [--baseline-sizes 100 300]
                              [--steps 20] [--json out/bench/sim.json]

Scenario: Su, Wang, Lin 2009 Fig. 3 (density N / L^2 = 0.05, protocol (10), 10 % informed).
For each N it times ``sim``'s step (neighbour search, law, integration, metrics) over
``--steps`` steps after one warm-up step, and reports steps/s and the time per agent-step.
The baseline is the straightforward implementation most published flocking code uses: a
Python loop over agents and, for each, over every other agent, with scalar ``math``. It is
checked to produce the same accelerations as ``sim`` (to 1e-9) before it is timed, so the
comparison is between two implementations of one law.
"""

import argparse
import json
import math
import platform
import time
from pathlib import Path

import numpy as np

from flock_swarm.core.dynamics import VirtualLeader, step_agents
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.metrics import RunMetrics
from flock_swarm.core.protocols import SuParams, swarm_control
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.scenarios import load


def fig3_scenario(n: int, steps: int) -> Scenario:
    """Return Su 2009 Fig. 3's preset at ``n`` agents (density 0.05), ``steps`` steps long."""
    side = math.sqrt(n / 0.05)
    return load('su2009_fig3', [f'n_agents={n}',
                                f'initial.position_box=[[0, {side}], [0, {side}]]',
                                f'duration={steps * 0.02}', 'dt=0.02'])


def time_sim_steps(sc: Scenario, steps: int) -> float:
    """Return the mean wall time of one simulator step (the loop body of ``sim``)."""
    real = realize(sc)
    q, p, agents = real.q0.copy(), real.p0.copy(), real.agents
    leader = VirtualLeader(sc.leader.field, sc.leader.position, sc.leader.velocity)
    law, dt = sc.law, sc.dt
    run = RunMetrics(sc.collision_distance)

    def one_step(q, p):
        state = leader.state
        edges = disk_graph(q, law.radius, law.strict_radius)
        u = swarm_control(law, q, p, edges, state, agents, dt)
        run.update_from_edges(q, edges, law.radius)
        q, p = step_agents(q, p, u, dt, None)
        leader.step(dt)
        return q, p

    q, p = one_step(q, p)
    start = time.perf_counter()
    for _ in range(steps):
        q, p = one_step(q, p)
    return (time.perf_counter() - start) / steps


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
    leader = VirtualLeader(sc.leader.field, sc.leader.position, sc.leader.velocity).state
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


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print (and optionally save) the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[100, 1000, 10000, 100000])
    parser.add_argument('--baseline-sizes', type=int, nargs='+', default=[100, 300])
    parser.add_argument('--steps', type=int, default=20)
    parser.add_argument('--json', type=Path, help='also write the results here')
    args = parser.parse_args(argv)
    results = {'machine': {'processor': platform.processor() or platform.machine(),
                           'python': platform.python_version()},
               'sim': {}, 'baseline': {}}
    for n in sorted(set(args.sizes) | set(args.baseline_sizes)):
        step = time_sim_steps(fig3_scenario(n, args.steps), args.steps)
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
    sizes = sorted(results['sim'])
    if len(sizes) > 1 and 1000 in results['sim']:
        ratio = (results['sim'][sizes[-1]]['us_per_agent_step']
                 / results['sim'][1000]['us_per_agent_step'])
        results['linearity'] = {'largest_n': sizes[-1], 'per_agent_ratio_vs_1000': ratio}
        print(f'time per agent-step at N = {sizes[-1]} / at N = 1000: {ratio:.2f}')
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
