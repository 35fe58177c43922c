"""Where the one-process pipeline's start-up goes: node construction, then the wait to step 0.

    python bench/startup_ros.py [--n 1000]

Builds the in-process swarm (``swarm demo`` at the demo's density, as ``bench_ros.py
--layouts one``) with a timer around the construction of each node, then spins until the
world has opened step 1 and prints the seconds of each part: the world's node (its N
odometry publishers and N command subscriptions, the bag), the leader, the agents'
container (N odometry subscriptions, N command publishers), and the wait from the last
node's construction to step 0 and to step 1 (discovery and matching, then the first step,
which waits for the agents' readers to match the world's writers).
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    """Time the start-up of the one-process pipeline and print it."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--n', type=int, default=1000, help='agents (default: 1000)')
    parser.add_argument('--domain', type=int, default=218, help='ROS domain id')
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_ros import scenario_overrides

    from flock_swarm.nodes import agent, leader, world
    from flock_swarm.nodes.swarm_runner import InProcessSwarm, resolve_scenario
    built: dict[str, float] = {}
    for module, cls in ((world, 'WorldNode'), (leader, 'LeaderNode'), (agent, 'AgentNode')):
        original = getattr(module, cls).__init__

        def timed(self, *a, _original=original, _name=cls, **kw):
            t0 = time.perf_counter()
            _original(self, *a, **kw)
            built[_name] = time.perf_counter() - t0

        getattr(module, cls).__init__ = timed
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'run'
        path = resolve_scenario('demo', scenario_overrides(args.n, 20), None, out)
        t0 = time.perf_counter()
        with InProcessSwarm(path, out, domain_id=args.domain) as swarm:
            t_built = time.perf_counter()
            swarm.spin_until(lambda: swarm.world.k >= 0 and swarm.world.stepper.started, 600)
            t_started = time.perf_counter()
            swarm.spin_until(lambda: swarm.world.k >= 1, 600)
            t_first = time.perf_counter()
    print(f'# python bench/startup_ros.py {" ".join(sys.argv[1:] if argv is None else argv)}')
    print(f'N = {args.n}: nodes built in {t_built - t0:.2f} s (world {built["WorldNode"]:.2f}, '
          f'leader {built["LeaderNode"]:.2f}, agents {built["AgentNode"]:.2f}); step 0 opened '
          f'{t_started - t_built:.2f} s later, step 1 after {t_first - t_started:.2f} s more; '
          f'{t_first - t0:.2f} s in all')
    return 0


if __name__ == '__main__':
    sys.exit(main())
