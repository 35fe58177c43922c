"""Memory the world's recording holds as a run gets longer: time series and bag writer.

    python bench/bench_memory.py [--minutes 6] [--agents 10]

The soak (``bench_soak.py``: 10 agents, realtime at 50 Hz, ``record_every`` 50, 1 MiB bag
chunks) grew about 0.25 MiB a minute. This benchmark feeds the two parts of the world that
keep something per step with the soak's data rate, without ROS, and reports the Python
memory they hold (``tracemalloc``) at the end of each simulated minute:

- the run log's recorder: the in-memory :class:`~flock_swarm.core.run.Recorder` against the
  world's :class:`~flock_swarm.outputs.SpooledRecorder` (one recorded instant a second);
- the bag writer: one file against a bag split every minute (``max_bagfile_duration``):
  mcap's writer keeps one chunk index per chunk until its file is finished.

The writer's open chunk (up to 1 MiB, compressed when full) makes its figure saw-tooth;
compare the same phase (odd minutes with odd minutes).
"""

import argparse
import gc
from pathlib import Path
import tempfile
import tracemalloc

from builtin_interfaces.msg import Time
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock

from flock_swarm.bag import BagWriter
from flock_swarm.core.dynamics import LeaderState
from flock_swarm.core.run import RunLog
from flock_swarm.nodes.wire import AccelEncoder, OdometryEncoder
from flock_swarm.outputs import SpooledRecorder

#: The soak's rates: dt = 0.02 s (50 steps a second), one recorded instant a second.
STEPS_PER_MINUTE = 3000
RECORDED_PER_MINUTE = 60


def held_mib() -> float:
    """Return the Python memory traced now [MiB], after a garbage collection."""
    gc.collect()
    return tracemalloc.get_traced_memory()[0] / 2**20


def recorder_minutes(n: int, minutes: int, spooled: bool) -> list[float]:
    """Memory held by a run log after each minute of recorded instants."""
    rng = np.random.default_rng(1)
    q, p = rng.normal(size=(n, 2)) * 5, rng.normal(size=(n, 2))
    leader = LeaderState(np.zeros(2), np.ones(2), np.zeros(2))
    informed = np.arange(n) < n // 3
    held = []
    with tempfile.TemporaryDirectory() as tmp:
        tracemalloc.start()
        log = RunLog(0.1, 0.1, 4.0, True, 1, SpooledRecorder(Path(tmp)) if spooled else None)
        for k in range(minutes * RECORDED_PER_MINUTE):
            log.record(k, float(k), q + k, p, p, leader, informed, False)
            if k % RECORDED_PER_MINUTE == RECORDED_PER_MINUTE - 1:
                held.append(held_mib())
        tracemalloc.stop()
    return held


def writer_minutes(n: int, minutes: int, split: bool) -> tuple[list[float], int]:
    """Memory held by a bag writer after each minute of the world's messages."""
    clock = serialize_message(Clock(clock=Time(sec=1)))
    odom = [OdometryEncoder(f'agent_{i}') for i in range(n)]
    accel = AccelEncoder()
    held = []
    with tempfile.TemporaryDirectory() as tmp:
        tracemalloc.start()
        writer = BagWriter(Path(tmp) / 'bag', max_bagfile_duration=60.0 if split else 0.0)
        writer.add_topic('/clock', Clock)
        for i in range(n):
            writer.add_topic(f'/agent_{i}/odom', Odometry)
            writer.add_topic(f'/agent_{i}/cmd_accel', AccelStamped)
        for k in range(minutes * STEPS_PER_MINUTE):
            t_ns = k * 20_000_000
            step = [('/clock', clock)]
            step += [(f'/agent_{i}/odom',
                      odom[i].encode(t_ns, (0.01 * k + i, 0.5 * i), (1.0, 0.0)))
                     for i in range(n)]
            step += [(f'/agent_{i}/cmd_accel', accel.encode(t_ns, (0.1 * (k % 30), 0.0)))
                     for i in range(n)]
            writer.write_serialized_many(step, t_ns)
            if k % STEPS_PER_MINUTE == STEPS_PER_MINUTE - 1:
                held.append(held_mib())
        tracemalloc.stop()
        files = len(writer.mcap_paths)
        writer.close()
    return held, files


def main(argv: list[str] | None = None) -> int:
    """Print the memory held after each simulated minute."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=int, default=6)
    parser.add_argument('--agents', type=int, default=10)
    args = parser.parse_args(argv)

    def show(label: str, held: list[float]) -> None:
        per_minute = (held[-1] - held[0]) / max(len(held) - 1, 1)
        print(f'{label:34s} {" ".join(f"{h:6.3f}" for h in held)}   '
              f'({per_minute:+.3f} MiB/min)', flush=True)

    print(f'# {args.agents} agents, {args.minutes} simulated minutes; Python memory held '
          '[MiB] after each minute (tracemalloc)', flush=True)
    show('recorder, in memory', recorder_minutes(args.agents, args.minutes, False))
    show('recorder, spooled to disk', recorder_minutes(args.agents, args.minutes, True))
    held, _ = writer_minutes(args.agents, args.minutes, False)
    show('bag writer, one file', held)
    held, files = writer_minutes(args.agents, args.minutes, True)
    show(f'bag writer, split each minute ({files})', held)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
