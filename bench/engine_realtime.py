"""How a robot run went: the figures docs/robots.md gives for the realtime engine runs.

    python bench/engine_realtime.py OUT_DIR [OUT_DIR ...] [--at 5 10 20 30]

For each run directory (``swarm ... --backend mujoco --out OUT_DIR``: its ``summary.json`` and
``timeseries.npz``) it prints the distance of the robots' axle centroid from the leader at the
given times, the robot contacts and collisions of the summary, eta, the share of samples in
which a robot drives backwards and the largest forward speed (the plant state's ``v``, the
engine's robots read back).
"""

import argparse
import json
from pathlib import Path

import numpy as np


def figures(out: Path, at: list[float]) -> dict:
    """Return the figures of the run in ``out`` (see the module)."""
    summary = json.loads((out / 'summary.json').read_text())
    series = np.load(out / 'timeseries.npz')
    t, x, leader = series['t'], series['plant_state'], series['leader_q']
    gap = np.linalg.norm(x[:, :, :2].mean(axis=1) - leader, axis=1)
    v = x[:, :, 4]
    return {'centroid_gap': {s: float(gap[np.argmin(np.abs(t - s))]) for s in at
                             if s <= t[-1] + 1e-9},
            'robot_contacts': summary.get('robot_contacts'),
            'collisions': summary.get('collisions'), 'eta': summary.get('eta'),
            'backwards': float((v < 0.0).mean()), 'peak_speed': float(np.abs(v).max())}


def main() -> int:
    """Print one line per run."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('runs', nargs='+', type=Path)
    parser.add_argument('--at', type=float, nargs='+', default=[5.0, 10.0, 20.0, 30.0])
    args = parser.parse_args()
    for out in args.runs:
        f = figures(out, args.at)
        gaps = ' / '.join(f'{g:.3f}' for g in f['centroid_gap'].values())
        times = ' / '.join(f'{s:g}' for s in f['centroid_gap'])
        print(f'{out}: centroid from the leader {gaps} m at {times} s; robot contacts '
              f"{f['robot_contacts']}, collisions {f['collisions']}, eta {f['eta']:.3f}; "
              f"backwards {100 * f['backwards']:.1f} % of samples; peak speed "
              f"{f['peak_speed']:.3f} m/s")
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
