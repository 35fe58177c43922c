"""What one direction of a lockstep step costs below Python: N serialised odometries moved
from one node to another, published in one call and taken in one call (the compiled path).

    python bench/bench_batch_oneway.py [--n 1000] [--steps 50]

Two nodes in one process on the EventsExecutor: ``a`` publishes one message on each of N
topics with :class:`flock_swarm.nodes.batch.BatchPublish` (one call); ``b`` takes them in
one call, either from the callback of the first message with its subscriptions registered
with the executor as the nodes do (``registered``: the executor still gets an event per
message and finds it taken), or with rcl subscriptions the executor never sees, drained by
a 1 ms timer (``hidden``). No Python runs per message in either: what is left per message is
rcl, rmw_fastrtps and Fast DDS (the write, the delivery to the reader, its listener) and,
for ``registered``, the executor's event. Printed: steps per second and the CPU time of
every thread of the process per step (steadier than the rate on a shared machine).
"""

import argparse
import sys
import time

import numpy as np


def run(n: int, steps: int, mode: str, domain: int) -> tuple[float, float]:
    """Return ``(steps/s, CPU ms per step)`` of ``steps`` one-way steps of ``n`` messages."""
    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.context import Context
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
    from rclpy.node import Node

    from flock_swarm.contract import LOCKSTEP_QOS, qos_profile
    from flock_swarm.nodes.batch import BatchPublish, BatchTake, extension
    from flock_swarm.nodes.spin import make_executor, middleware_defaults
    from flock_swarm.nodes.wire import OdometryEncoder
    context = Context()
    middleware_defaults()   # as the nodes publish (RMW_FASTRTPS_PUBLICATION_MODE decides)
    rclpy.init(context=context, domain_id=domain)
    qos = qos_profile(LOCKSTEP_QOS)
    a, b = Node('oneway_a', context=context), Node('oneway_b', context=context)
    pubs = [a.create_publisher(Odometry, f'/oneway/t{i}', qos) for i in range(n)]
    out = BatchPublish(pubs)
    msgs = [OdometryEncoder(f'agent_{i}').encode(0, (0.0, 0.0), (0.0, 0.0)) for i in range(n)]
    targets = np.arange(n, dtype=np.int64)
    got = [0]
    held, hidden = [out], []
    if mode == 'registered':
        def first(data: bytes) -> None:
            got[0] += 1 + len(held[1].take())

        held.append(BatchTake([b.create_subscription(Odometry, f'/oneway/t{i}', first, qos,
                                                     raw=True) for i in range(n)]))
    else:
        with b.handle:
            hidden = [_rclpy.Subscription(b.handle, Odometry, f'/oneway/t{i}',
                                          qos.get_c_qos_profile()) for i in range(n)]
        taker = extension().Taker([h.pointer for h in hidden])

        def poll() -> None:
            got[0] += len(taker.take()[1]) // (8 * 3)

        b.create_timer(0.001, poll)
    executor = make_executor(context)
    executor.add_node(a)
    executor.add_node(b)
    while min(p.get_subscription_count() for p in pubs) < 1:
        executor.spin_once(timeout_sec=0.05)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        got[0] = 0
        out.publish_to(targets, msgs)
        while got[0] < n:
            executor.spin_once(timeout_sec=0.05)
    t1, c1 = time.perf_counter(), time.process_time()
    executor.shutdown()
    for one in held:
        one.close()
    if hidden:
        taker.close()
        for h in hidden:
            h.destroy_when_not_in_use()
    a.destroy_node()
    b.destroy_node()
    rclpy.try_shutdown(context=context)
    return steps / (t1 - t0), 1e3 * (c1 - c0) / steps


def main(argv: list[str] | None = None) -> int:
    """Run both modes twice, interleaved, and print each run."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--n', type=int, default=1000, help='messages a step (default 1000)')
    parser.add_argument('--steps', type=int, default=50, help='steps timed (default 50)')
    parser.add_argument('--domain', type=int, default=216, help='ROS domain id')
    args = parser.parse_args(argv)
    given = sys.argv[1:] if argv is None else argv
    print(f'# python bench/bench_batch_oneway.py {" ".join(given)}')
    for _ in range(2):
        for mode in ('registered', 'hidden'):
            rate, cpu = run(args.n, args.steps, mode, args.domain)
            print(f'N = {args.n} {mode:>10}: {rate:7.1f} steps/s, {cpu:6.2f} CPU ms a step '
                  f'({1e3 * cpu / args.n:.1f} us a message)', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
