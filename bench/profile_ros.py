"""Where a lockstep step's time goes: the one-process pipeline with its handlers timed.

    python bench/profile_ros.py [--n 5] [--steps 2000] [--no-record]

Runs ``swarm demo`` in one process (world, leader and the agents' container on one
EventsExecutor, as ``bench_ros.py --layouts one`` does) with a timer around each handler and
hot function of the nodes, and prints microseconds per step for each, inclusive (nested
rows are indented under the row that calls them), the recording's share (queueing and
writing the bag's messages: a CPU-time measure of the recording cost, steadier than the
difference of two runs' rates), and the rest of the wall time: decoding, rclpy, DDS and the
executor in the spinning thread, and the waits for the middleware's threads.

cProfile cannot say this: the EventsExecutor calls the Python callbacks from C++, so its
cumulative times are lost, and py-spy cannot attach on these machines. The timers cost
about half a microsecond a call, included in the rows.
"""

import argparse
import math
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

#: (module, class or None, function, label, depth) of what is timed, in print order.
TIMED = [
    # A command is queued; the last of a step takes the step's commands (at once, or one
    # by one through on_command) and closes the step: both inside this row.
    ('flock_swarm.nodes.world_io', 'CommandIntake', 'queue', 'world: a command in', 0),
    ('flock_swarm.nodes.world_inputs', 'WorldInputs', 'on_leader_odom',
     'world: leader odometry in', 0),
    ('flock_swarm.nodes.world_inputs', 'WorldInputs', 'on_leader_accel',
     'world: leader accel in', 0),
    ('flock_swarm.nodes.world', 'WorldNode', 'finish_step', 'world: close the step', 1),
    ('flock_swarm.nodes.world_modes', 'LockstepStepper', 'close_step',
     'zero absentees, observe', 2),
    ('flock_swarm.nodes.stepper', 'WorldStepper', 'observe', 'record, metrics, telemetry', 3),
    ('flock_swarm.core.run', 'RunLog', 'observe', 'time series and run metrics', 4),
    ('flock_swarm.nodes.stepper', None, 'disk_graph', 'the r-disk graph', 4),
    ('flock_swarm.nodes.world', 'WorldNode', 'go_on', 'telemetry, integrate', 2),
    ('flock_swarm.nodes.markers', 'Telemetry', 'emit', 'markers and metrics out', 3),
    ('flock_swarm.nodes.stepper', 'WorldStepper', 'advance', 'integrate', 3),
    ('flock_swarm.nodes.world_end', 'WorldEnd', 'finish',
     'the end: outputs, bag closed (once)', 3),
    ('flock_swarm.nodes.world', 'WorldNode', 'begin_step', 'open the next step', 2),
    ('flock_swarm.nodes.world_io', 'StatePublisher', 'publish', '/clock and odometry out', 3),
    ('flock_swarm.nodes.recording', 'RecordedNode', 'record_message',
     'recording: queue a message', 0),
    ('flock_swarm.nodes.recording', 'RecordedNode', 'record_messages',
     'recording: queue a batch', 0),
    ('flock_swarm.bag.writer', 'BagWriter', 'write_serialized_batch',
     'recording: write to the bag', 0),
    ('flock_swarm.nodes.agent', 'AgentNode', 'on_odom', 'agents: an odometry in', 0),
    ('flock_swarm.nodes.agent', 'AgentNode', 'try_answer', 'agents: answer the step', 1),
    ('flock_swarm.nodes.controller', 'AgentController', 'command', 'graph and law', 2),
    ('flock_swarm.nodes.agent', 'AgentNode', 'publish_commands', 'commands out', 2),
    ('flock_swarm.nodes.agent', 'AgentNode', 'on_leader_odom', 'agents: leader odometry in', 0),
    ('flock_swarm.nodes.agent', 'AgentNode', 'on_leader_accel', 'agents: leader accel in', 0),
    ('flock_swarm.nodes.leader', 'LeaderNode', 'on_clock', 'leader: a tick', 0),
]


#: Rows of the recording, timed inside the handlers above them (not added to their sum).
RECORDING = ('record_message', 'record_messages', 'write_serialized_batch')


def instrument(totals: dict) -> None:
    """Wrap every function of ``TIMED`` with a timer adding to ``totals[label]``."""
    import importlib
    for module_name, cls, func, label, _ in TIMED:
        owner = importlib.import_module(module_name)
        if cls is not None:
            owner = getattr(owner, cls)
        original = getattr(owner, func)
        cell = totals[label]

        def timed(*args, _original=original, _cell=cell, **kwargs):
            t0 = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                _cell[0] += 1
                _cell[1] += time.perf_counter() - t0

        setattr(owner, func, timed)


def main(argv: list[str] | None = None) -> int:
    """Run the instrumented pipeline and print the breakdown."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--n', type=int, default=5, help='agents (default: 5)')
    parser.add_argument('--steps', type=int, default=2000, help='steps (default: 2000)')
    parser.add_argument('--no-record', action='store_true', help='record:=false')
    parser.add_argument('--domain', type=int, default=219, help='ROS domain id')
    args = parser.parse_args(argv)
    totals: dict = defaultdict(lambda: [0, 0.0])
    instrument(totals)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_ros import scenario_overrides

    from flock_swarm.nodes.swarm_runner import InProcessSwarm, resolve_scenario
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'run'
        path = resolve_scenario('demo', scenario_overrides(args.n, args.steps), None, out)
        with InProcessSwarm(path, out, domain_id=args.domain,
                            world_params={'record': not args.no_record}) as swarm:
            swarm.spin_until(lambda: swarm.world.k >= 1, 60)
            for cell in totals.values():
                cell[:] = [0, 0.0]
            k0, t0 = swarm.world.k, time.perf_counter()
            swarm.spin_until(lambda: swarm.world.done, 3600)
            wall, steps = time.perf_counter() - t0, swarm.world.k - k0
    per = 1e6 / steps
    print(f'# python bench/profile_ros.py {" ".join(sys.argv[1:] if argv is None else argv)}')
    print(f'N = {args.n}, {steps} steps in {wall:.2f} s: {steps / wall:.1f} steps/s, '
          f'{wall * per:.0f} us per step')
    top = 0.0
    for _, _, func, label, depth in TIMED:
        calls, seconds = totals[label]
        if depth == 0 and func not in RECORDING:
            top += seconds
        print(f'{"  " * depth}{label:<{44 - 2 * depth}} {seconds * per:8.1f} us/step  '
              f'({calls / steps:.1f} calls/step)')
    rest = wall - top
    recording = sum(totals[label][1] for _, _, func, label, _ in TIMED if func in RECORDING)
    print(f'{"recording in all (within the rows above)":<44} {recording * per:8.1f} us/step  '
          f'({100 * recording / wall:.1f} % of the wall time)')
    print(f'{"rest: decoding, rclpy, DDS, executor, waits":<44} {rest * per:8.1f} us/step  '
          f'({100 * rest / wall:.0f} %)')
    return 0 if math.isfinite(wall) else 1


if __name__ == '__main__':
    sys.exit(main())
