"""How a robot run went: the figures docs/robots.md gives for the realtime engine runs.

    python bench/engine_realtime.py OUT_DIR [OUT_DIR ...] [--at 5 10 20 30]
    python bench/engine_realtime.py --fly agents --ways predict off --seconds 30 --out DIR

For each run directory (``swarm ... --backend mujoco --out OUT_DIR``: its ``summary.json`` and
``timeseries.npz``), or each run it flies first (``--fly``: examples/robots/tb3_fleet.yaml in
realtime, the world stepping the engine, in this process as ``swarm`` runs it; ``agents``: the
agent nodes with each ``latency`` of ``--ways``; ``bridge``: six robot agents with each
``integrate_from``), it prints the distance of the robots' axle centroid from the leader at the
given times, the robot contacts and collisions of the summary, eta, the share of samples in
which a robot drives backwards and the largest forward speed (the plant state's ``v``, the
engine's robots read back).
"""

import argparse
import json
from pathlib import Path

import numpy as np

#: The fleet of the tests and docs/robots.md.
FLEET = Path(__file__).resolve().parents[1] / 'examples' / 'robots' / 'tb3_fleet.yaml'


def fly(kind: str, way: str, seconds: float, out: Path) -> Path:
    """Fly the fleet in realtime against the engine for ``seconds``; return its directory.

    :param kind: ``agents`` (the agent nodes, ``latency:=way``) or ``bridge`` (robot agents,
        ``integrate_from:=way``).
    """
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.robot_agent import RobotAgentNode
    from flock_swarm.testing import Swarm
    out = out / f'{kind}_{way}'
    bridge = kind == 'bridge'
    with Swarm(FLEET, out, [f'duration={seconds!r}'], mode='realtime',
               world_params={'backend': 'mujoco'}, agents=[] if bridge else None,
               agent_params=None if bridge else {'latency': way}) as swarm:
        if bridge:
            for i in range(6):
                swarm.add(RobotAgentNode(
                    context=swarm.context, node_name=f'robot_agent_{i}', parameter_overrides=[
                        Parameter('scenario', value=str(out / 'scenario.yaml')),
                        Parameter('agent_id', value=i), Parameter('integrate_from', value=way)]))
        swarm.run(seconds * 4 + 60.0)
    return out


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
    parser.add_argument('runs', nargs='*', type=Path)
    parser.add_argument('--at', type=float, nargs='+', default=[5.0, 10.0, 20.0, 30.0])
    parser.add_argument('--fly', choices=('agents', 'bridge'))
    parser.add_argument('--ways', nargs='+', default=['predict', 'off'],
                        help="agents: latency values; bridge: integrate_from values")
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--out', type=Path, default=Path('out') / 'engine_realtime')
    args = parser.parse_args()
    runs = list(args.runs)
    if args.fly:
        runs += [fly(args.fly, way, args.seconds, args.out) for way in args.ways]
    for out in runs:
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
