"""Benchmark of the bag writer on a lockstep step of a large swarm.

    python bench/bench_bag.py [--n 1000] [--steps 30] [--compression zstd|lz4|none] [--profile]

Writes ``--steps`` steps of N odometries (encoded at once, as the world encodes them) and N
commands into a fresh bag with ``BagWriter.write_serialized_many``, as the world's
``BagSink`` does once a step, and prints the milliseconds a step (encoding included) and the
bag's size. ``--profile`` adds the top of a cProfile of the loop.
"""

import argparse
import cProfile
import pstats
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.qos import QoSProfile

from flock_swarm.bag.writer import BagWriter
from flock_swarm.nodes.wire import AccelEncoder, OdometryBatchEncoder


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=1000, help='agents (default: 1000)')
    parser.add_argument('--steps', type=int, default=30, help='steps (default: 30)')
    parser.add_argument('--compression', default='zstd', choices=['zstd', 'lz4', 'none'])
    parser.add_argument('--profile', action='store_true', help='print a cProfile of the loop')
    args = parser.parse_args(argv)
    n = args.n
    odometry = OdometryBatchEncoder([f'agent_{i}' for i in range(n)])
    command = AccelEncoder()
    rng = np.random.default_rng(0)
    q, p = rng.normal(size=(n, 2)) * 50.0, rng.normal(size=(n, 2))
    odom_topics = [f'/agent_{i}/odom' for i in range(n)]
    cmd_topics = [f'/agent_{i}/cmd_accel' for i in range(n)]
    with tempfile.TemporaryDirectory() as tmp:
        bag = BagWriter(Path(tmp) / 'bag', compression=args.compression)
        qos = QoSProfile(depth=10)
        for odom, cmd in zip(odom_topics, cmd_topics):
            bag.add_topic(odom, Odometry, qos)
            bag.add_topic(cmd, AccelStamped, qos)
        prof = cProfile.Profile() if args.profile else None
        start = time.perf_counter()
        if prof is not None:
            prof.enable()
        for k in range(args.steps):
            t_ns = k * 20_000_000
            q = q + 0.02 * p
            cmds = [command.encode(t_ns, (float(x), 0.1, 0.0)) for x in q[:, 0]]
            bag.write_serialized_many(zip(cmd_topics, cmds), t_ns)
            bag.write_serialized_many(zip(odom_topics, odometry.encode(t_ns, q, p)), t_ns)
        if prof is not None:
            prof.disable()
        per_step = (time.perf_counter() - start) / args.steps
        bag.close()
        size = sum(f.stat().st_size for f in (Path(tmp) / 'bag').iterdir())
    print(f'N = {n}, {args.steps} steps, {args.compression}: {per_step * 1e3:.2f} ms a step '
          f'(encoding included), bag {size / 2**20:.1f} MiB')
    if prof is not None:
        pstats.Stats(prof, stream=sys.stdout).sort_stats('tottime').print_stats(10)
    return 0


if __name__ == '__main__':
    sys.exit(main())
