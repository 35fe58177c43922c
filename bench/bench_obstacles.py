"""Benchmark of the obstacles' cost: ``sim``'s step with and without 10 obstacles.

    python bench/bench_obstacles.py [--n 1000] [--steps 60] [--repeats 5]
                                    [--json out/bench/obstacles.json]

Scenario: Su, Wang, Lin 2009 Fig. 3 at ``--n`` agents (density N / L^2 = 0.05, protocol (10),
10 % informed, 2-D), once in free space and once with 10 obstacles in the square: 8 spheres
of radius 2 on a ring and 2 walls along two of its sides, so that the flock meets them from
the first step (the agents start at least ``r'`` from every obstacle's surface and in
range of them after a few steps). The two runs are timed in one invocation, interleaved
(free, obstacles, free, obstacles...), best of ``--repeats``, so that the machine's load
affects both alike. The time of a step is that of :func:`flock_swarm.core.run.simulate`
itself (neighbour search, law, beta term, integration, whole-run metrics including the
agent-obstacle clearances), between its first and last progress reports: the process's CPU
time (``time.process_time``; NumPy runs on one thread here), which the other processes of a
shared machine disturb far less than the wall time, printed too.

Target (issue 27): the step with obstacles within 1.3 times the free-space step at
N = 1000, printed with PASS or FAIL. At the default size and length the obstacle run's final
state, recorded clearances and obstacle metrics are also checked against their SHA-256 under
the code before the speed-ups (``bit for bit as before`` or ``DIFFERENT``).
"""

import argparse
import hashlib
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from flock_swarm.core.obstacles import beta_pairs
from flock_swarm.core.run import RunResult, simulate
from flock_swarm.core.scenario import Scenario
from flock_swarm.presets import load
from flock_swarm.reproduce.report import machine

#: Issue 27: the step with 10 obstacles at most this many times the free-space step.
RATIO_MAX = 1.3
#: The default run, and the :func:`fingerprint` of its obstacle run as the code before the
#: beta term's and metrics' speed-ups computed it (main at 34110fe): the speed-ups must leave
#: it bit for bit unchanged.
DEFAULT_RUN = (1000, 60)
DEFAULT_FINGERPRINT = '5c8c4e6f5dd8a2b8dee685c1c63b17f75caa191ef4c4d8cba23de61a6ad01517'
#: The obstacles: spheres on a ring, walls on two sides of the square.
SPHERES, SPHERE_RADIUS, WALLS = 8, 2.0, 2


def obstacles_section(side: float) -> dict:
    """Return the ``obstacles:`` section for a square of ``side`` metres."""
    ring = [(side / 2 + 0.3 * side * math.cos(a), side / 2 + 0.3 * side * math.sin(a))
            for a in np.linspace(0.0, 2 * math.pi, SPHERES, endpoint=False)]
    return {'spheres': [{'centre': list(c), 'radius': SPHERE_RADIUS} for c in ring],
            'walls': [{'point': [-1.0, 0.0], 'normal': [1.0, 0.0]},
                      {'point': [0.0, -1.0], 'normal': [0.0, 1.0]}][:WALLS]}


def scenarios(n: int, steps: int) -> tuple[Scenario, Scenario]:
    """Return Fig. 3 at ``n`` agents without and with the obstacles, from one start.

    The start is the preset's draw with the agents that fall within ``r'`` of an obstacle
    moved by the seed's generator until none does: both runs start from it.
    """
    side = math.sqrt(n / 0.05)
    base = [f'n_agents={n}', f'initial.position_box=[[0, {side}], [0, {side}]]',
            f'duration={steps * 0.02}', 'dt=0.02']
    section = obstacles_section(side)
    with_obstacles = load('su2009_fig3', base + [f'obstacles={json.dumps(section)}'])
    spec = with_obstacles.obstacles
    rng = np.random.default_rng(27)
    q = rng.uniform(0.0, side, (n, 2))
    while True:
        near = np.unique(beta_pairs(spec, q)[0])
        if not near.size:
            break
        q[near] = rng.uniform(0.0, side, (near.size, 2))
    start = {'initial.positions': q.tolist(), 'initial.position_box': None}
    free = load('su2009_fig3', base, extra=start)
    return free, load('su2009_fig3', base + [f'obstacles={json.dumps(section)}'],
                      extra=start)


def fingerprint(result: RunResult) -> str:
    """Return a SHA-256 of a run's final state (the last recorded ``q``, ``p``, ``u``), its
    recorded clearances and its obstacle metrics: equal only if bit for bit equal."""
    digest = hashlib.sha256()
    for key in ('q', 'p', 'u', 'obstacle_clearance'):
        if key in result.series:
            value = result.series[key] if key == 'obstacle_clearance' else result.series[key][-1]
            digest.update(np.ascontiguousarray(value).tobytes())
    keys = ('obstacle_clearance_min', 'obstacle_penetrations', 'obstacle_collisions')
    digest.update(repr([result.summary.get(key) for key in keys]).encode())
    return digest.hexdigest()


def step_time(sc: Scenario) -> tuple[float, float, RunResult]:
    """Return the CPU and wall seconds per step of one run of ``sc``, and its result."""
    stamps: list[tuple[float, float]] = []
    result = simulate(sc, progress=lambda line: stamps.append((time.process_time(),
                                                               time.perf_counter())),
                      progress_every=0.0)
    steps = len(stamps) - 1
    return ((stamps[-1][0] - stamps[0][0]) / steps, (stamps[-1][1] - stamps[0][1]) / steps,
            result)


def main(argv: list[str] | None = None) -> int:
    """Time the two runs, print the ratio and the verdict; return 0 (1: the target missed)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=1000, help='agents (default 1000)')
    parser.add_argument('--steps', type=int, default=60, help='steps per run (default 60)')
    parser.add_argument('--repeats', type=int, default=5, help='runs of each (default 5)')
    parser.add_argument('--json', type=Path, help='also write the results here')
    args = parser.parse_args(argv)
    free, obstructed = scenarios(args.n, args.steps)
    best = {'free': math.inf, 'obstacles': math.inf}
    wall = dict(best)
    results = {}
    for _ in range(args.repeats):
        for name, sc in (('free', free), ('obstacles', obstructed)):
            cpu, elapsed, results[name] = step_time(sc)
            best[name], wall[name] = min(best[name], cpu), min(wall[name], elapsed)
    ratio = best['obstacles'] / best['free']
    s = results['obstacles'].summary
    state = fingerprint(results['obstacles'])
    verdict = 'PASS' if ratio <= RATIO_MAX else 'FAIL'
    print(f'N = {args.n}, {args.steps} steps, best of {args.repeats} (interleaved), '
          f'load average {os.getloadavg()[0]:.2f} at the end')
    print(f'free space:          {1e3 * best["free"]:.2f} ms/step CPU '
          f'({1e3 * wall["free"]:.2f} wall)')
    print(f'{SPHERES} spheres, {WALLS} walls: {1e3 * best["obstacles"]:.2f} ms/step CPU '
          f'({1e3 * wall["obstacles"]:.2f} wall); closest agent '
          f'{s["obstacle_clearance_min"]:.3g} m from a surface, '
          f'{s["obstacle_penetrations"]} penetrations')
    if (args.n, args.steps) == DEFAULT_RUN:
        same = 'bit for bit as before' if state == DEFAULT_FINGERPRINT else 'DIFFERENT'
        print(f'obstacle run\'s final state: {same} (sha256 {state[:16]}...)')
    print(f'ratio {ratio:.3f} CPU, {wall["obstacles"] / wall["free"]:.3f} wall '
          f'(target <= {RATIO_MAX}): {verdict}')
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({
            'machine': machine(), 'n': args.n, 'steps': args.steps, 'repeats': args.repeats,
            'cpu_seconds_per_step': best, 'wall_seconds_per_step': wall, 'ratio': ratio,
            'target': RATIO_MAX, 'obstacle_clearance_min': s['obstacle_clearance_min'],
            'obstacle_penetrations': s['obstacle_penetrations'],
            'fingerprint': state}, indent=2) + '\n')
    return 0 if verdict == 'PASS' else 1


if __name__ == '__main__':
    raise SystemExit(main())
