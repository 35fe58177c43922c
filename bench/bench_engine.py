"""The physics-engine world's speed: engine steps per second at N = 6, 20, 50 robots.

    python bench/bench_engine.py [--sizes 6 20 50] [--seconds 5] [--period 0.02]
                                 [--json out/bench/engine.json]

N TurtleBot3 Burgers (flock_swarm/engine/turtlebot3_burger.xml) on a square grid 0.5 m apart,
each driven with its own constant twist (so they turn and some meet), for ``--seconds`` of
engine time in control periods of ``--period`` (the world's dt; the engine's own step is
2 ms, so one period is ``period / 0.002`` engine steps). Reported per N: engine steps per
second of wall time, control periods per second, the realtime factor (engine time over wall
time) and the robot-robot pairs that touched. The first period (building the model) is not
timed.
"""

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from flock_swarm.engine.mujoco_world import EngineWorld
from flock_swarm.reproduce.report import machine


def grid(n: int, spacing: float = 0.5) -> np.ndarray:
    """Return ``n`` positions on a square grid ``spacing`` apart (n x 2)."""
    side = math.ceil(math.sqrt(n))
    return np.array([[spacing * (k % side), spacing * (k // side)] for k in range(n)])


def bench(n: int, seconds: float, period: float) -> dict:
    """Time ``seconds`` of engine time for ``n`` robots.

    :param n: number of robots.
    :param seconds: engine time to run (s).
    :param period: control period (s).
    :return: the measurements of one size.
    """
    rng = np.random.default_rng(n)
    world = EngineWorld(grid(n), rng.uniform(-np.pi, np.pi, n))
    v = rng.uniform(0.05, 0.22, n)
    omega = rng.uniform(-1.0, 1.0, n)
    world.set_twists(v, omega)
    world.step(period)
    periods = int(round(seconds / period))
    start = time.perf_counter()
    for _ in range(periods):
        world.set_twists(v, omega)
        world.step(period)
    wall = time.perf_counter() - start
    substeps = int(round(period / world.model.opt.timestep))
    return {'n': n, 'engine_steps_per_s': periods * substeps / wall,
            'periods_per_s': periods / wall, 'realtime_factor': periods * period / wall,
            'wall_s': wall, 'pairs_touched': len(world.contacts_run)}


def main() -> int:
    """Run the benchmark and print one line per size."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[6, 20, 50])
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--period', type=float, default=0.02)
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()
    rows = []
    for n in args.sizes:
        row = bench(n, args.seconds, args.period)
        rows.append(row)
        print(f'N={n:3d}  engine steps/s {row["engine_steps_per_s"]:9.0f}  '
              f'periods/s {row["periods_per_s"]:7.1f}  realtime x{row["realtime_factor"]:6.1f}  '
              f'pairs touched {row["pairs_touched"]}')
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'machine': machine(), 'rows': rows}, indent=2))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
