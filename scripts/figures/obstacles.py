"""Draw docs/figures/obstacles.png: a flock of Algorithm 3 past a sphere, between two walls.

    python scripts/figures/obstacles.py [--out docs/figures]

40 agents of ``olfati_saber_2006`` with Olfati-Saber 2006's parameters (d = 7, r = 1.2 d,
eps = 0.1, h = 0.2, a = b = 5, the bounded navigational feedback of his gamma-agent) follow
a leader at 3 m/s along x into a corridor between two walls, past a sphere in its middle;
the obstacle section takes its defaults (d' = 0.6 d, r' = 1.2 d', the beta term's gains).
tests/test_obstacles.py runs this script, so the figure stays reproducible.
"""

import argparse
from pathlib import Path

from flock_swarm.core.run import simulate
from flock_swarm.plots import plot_trajectories
from flock_swarm.presets import prepare

SCENE = {
    'name': 'obstacles', 'dim': 2, 'n_agents': 40, 'dt': 0.02, 'duration': 40.0, 'seed': 7,
    'record_every': 10,
    'protocol': {'name': 'olfati_saber_2006', 'r': 8.4, 'd': 7.0, 'eps': 0.1, 'h': 0.2,
                 'a': 5.0, 'b': 5.0, 'c1': 0.5, 'c2': 0.5, 'navigation': 'bounded'},
    'initial': {'position_box': [[0.0, 30.0], [0.0, 30.0]],
                'velocity_box': [[0.0, 1.0], [-0.5, 0.5]]},
    'leader': {'model': 'constant_velocity', 'position': [15.0, 15.0], 'velocity': [3.0, 0.0]},
    'obstacles': {'spheres': [{'centre': [75.0, 15.0], 'radius': 6.0}],
                  'walls': [{'point': [0.0, -6.0], 'normal': [0.0, 1.0]},
                            {'point': [0.0, 36.0], 'normal': [0.0, -1.0]}]},
}


def main(argv: list[str] | None = None) -> int:
    """Run the scene and write its trajectories; print the obstacle metrics."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path, default=Path('docs/figures'))
    args = parser.parse_args(argv)
    sc, _ = prepare(SCENE)
    result = simulate(sc)
    args.out.mkdir(parents=True, exist_ok=True)
    path = plot_trajectories(result.series, args.out, title='Algorithm 3: a sphere, two walls',
                             filename='obstacles.png', obstacles=sc.obstacles)
    s = result.summary
    print(f'{path}: clearance {s["obstacle_clearance_min"]:.3f} m, penetrations '
          f'{s["obstacle_penetrations"]}, collisions {s["collisions"]}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
