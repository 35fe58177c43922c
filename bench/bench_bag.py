"""Benchmark of the bag writer on a lockstep step of a large swarm.

    python bench/bench_bag.py [--n 1000] [--steps 30] [--compression zstd|lz4|none] [--profile]
                              [--write-only]

Writes ``--steps`` steps of N odometries (encoded at once, as the world encodes them) and N
commands into a fresh bag with ``BagWriter.write_serialized_many``, as the world's
``BagSink`` does once a step, and prints the milliseconds a step (encoding included), the
seconds the bag's close takes (MCAP summary, ``metadata.yaml``) and the bag's size.
``--write-only``: every message encoded before the clock starts, and the process's CPU time
instead of the wall time (the writer's own cost, steadier on a shared machine).
``--profile`` adds the top of a cProfile of the loop.
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
    parser.add_argument('--write-only', action='store_true',
                        help='encode before the clock starts; CPU time of the writes alone')
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
        clock = time.process_time if args.write_only else time.perf_counter

        def step_messages(k: int, q: np.ndarray) -> tuple:
            t_ns = k * 20_000_000
            cmds = [command.encode(t_ns, (float(x), 0.1, 0.0)) for x in q[:, 0]]
            return t_ns, cmds, odometry.encode(t_ns, q, p)

        if args.write_only:
            steps, q0 = [], q
            for k in range(args.steps):
                q0 = q0 + 0.02 * p
                steps.append(step_messages(k, q0))
        start = clock()
        if prof is not None:
            prof.enable()
        for k in range(args.steps):
            if args.write_only:
                t_ns, cmds, odoms = steps[k]
            else:
                q = q + 0.02 * p
                t_ns, cmds, odoms = step_messages(k, q)
            bag.write_serialized_many(zip(cmd_topics, cmds), t_ns)
            bag.write_serialized_many(zip(odom_topics, odoms), t_ns)
        if prof is not None:
            prof.disable()
        per_step = (clock() - start) / args.steps
        start = time.perf_counter()
        bag.close()
        close = time.perf_counter() - start
        size = sum(f.stat().st_size for f in (Path(tmp) / 'bag').iterdir())
    what = 'CPU, writes only' if args.write_only else 'encoding included'
    print(f'N = {n}, {args.steps} steps, {args.compression}: {per_step * 1e3:.2f} ms a step '
          f'({what}), close {close:.2f} s, bag {size / 2**20:.1f} MiB')
    if prof is not None:
        pstats.Stats(prof, stream=sys.stdout).sort_stats('tottime').print_stats(10)
    return 0


if __name__ == '__main__':
    sys.exit(main())
