"""Benchmark: what serving a one-process ``swarm`` live over Foxglove costs in steps/s.

    python bench/bench_foxglove.py [--sizes 10 100] [--steps 200] [--repeat 1]
                                   [--json out/bench/foxglove.json]

For each N, every variant runs in a fresh process (the demo at the demo's density,
lockstep, recording on, the same runs as ``bench/bench_ros.py``'s one-process pipeline), one
after the other and interleaved over ``--repeat`` rounds; the best run of each counts:

``off``      no server (``swarm`` without ``--foxglove``);
``tee``      ``--foxglove`` as ``swarm`` serves: the world's bytes handed to the server by
             one of its sinks (:class:`flock_swarm.foxglove_ws.LiveSink`), no client connected;
``client``   the same with one client subscribed to every topic and reading;
``stalled``  the same with one client subscribed to every topic that never reads (its TCP
             receive buffer 4 KiB): the server must drop, the world must not wait;
``bridge``   the alternative: a bridge node
             (:class:`flock_swarm.nodes.foxglove_server.LiveBridge`) in the same process
             subscribing to every topic, one client reading.

The client is the tests' (test/foxglove_client.py) in a process of its own, as the Foxglove
app would be; it reports the messages it received. Steps/s come from the world's own clock
(``steps / wall_time_s``, start-up excluded); the ratio is against ``off`` at the same N.
CPU ms per step is the swarm process's CPU time (all its threads, the server's included)
over the run, divided by its steps: on a shared machine it is the steadier of the two.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from bench_ros import scenario_overrides  # noqa: E402

VARIANTS = ('off', 'tee', 'client', 'stalled', 'bridge')
#: Domain id of the benchmark runs (isolated from the test suite's 1-200 and bench_ros's 220).
DOMAIN = 221
#: Wall-clock bound of one run [s].
RUN_TIMEOUT = 300.0


def run_client(port: int, channels: int, stalled: bool) -> int:
    """Be the client process: subscribe to every topic, read (or not) until the server goes.

    Prints ``subscribed`` once the subscription is sent; ``stalled`` waits for a line on
    stdin before it reads at all. Reading ends after a second without a message.

    :return: the messages received.
    """
    from foxglove_client import FoxgloveClient
    sock = None
    if stalled:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(('127.0.0.1', port))
    client = FoxgloveClient(f'ws://127.0.0.1:{port}', max_queue=1 if stalled else 16,
                            sock=sock)
    client.pump_until(lambda: len(client.channels) >= channels, 10, 'advertise')
    client.subscribe(client.topics())
    print('subscribed', flush=True)
    if stalled:
        sys.stdin.readline()
    client.pump(1.0)
    client.close()
    return len(client.messages)


def start_client(live, stalled: bool) -> subprocess.Popen:
    """Start a client process and wait until it has subscribed to every channel."""
    proc = subprocess.Popen([sys.executable, __file__, '--role', 'viewer', '--port',
                             str(live.port), '--n', str(len(live.channels))]
                            + (['--stalled'] if stalled else []),
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == 'subscribed'
    deadline = time.monotonic() + 10
    while not all(channel.has_sinks() for channel in live.channels.values()):
        if time.monotonic() > deadline:
            raise TimeoutError('the client did not subscribe within 10 s')
        time.sleep(0.01)
    return proc


def run_role(variant: str, n: int, steps: int) -> dict:
    """Fly one run of ``variant`` in this process; return its numbers."""
    from flock_swarm.foxglove_ws import start_live
    from flock_swarm.nodes.foxglove_server import LiveBridge
    from flock_swarm.nodes.swarm_runner import InProcessSwarm, resolve_scenario
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'run'
        scenario = resolve_scenario('demo', scenario_overrides(n, steps), None, out)
        live = None if variant == 'off' else start_live(port=0)
        client = None
        received = None
        try:
            # A pace of its own: a client of every channel would pace the run to real time
            # (foxglove_ws.LIVE_PACE), and this measures the cost per step as fast as it goes.
            with InProcessSwarm(scenario, out, domain_id=DOMAIN,
                                world_params={'pace': 1e9}) as swarm:
                if variant == 'bridge':
                    swarm.add(LiveBridge(live, context=swarm.context,
                                         parameter_overrides=swarm.parameters()))
                elif live is not None:
                    swarm.serve(live)
                if variant in ('client', 'stalled', 'bridge'):
                    client = start_client(live, variant == 'stalled')
                cpu = time.process_time()
                swarm.spin_to_end(RUN_TIMEOUT)
                cpu = time.process_time() - cpu
                summary = swarm.summary()
        finally:
            if client is not None:
                # The client reads what is still queued for it (the stalled one from now on)
                # until a second passes without a message, then says how many it got.
                received = int(client.communicate('read\n', timeout=120)[0].split()[-1])
            if live is not None:
                live.close()
    return {'variant': variant, 'n': n, 'steps': summary['steps'],
            'wall_time_s': summary['wall_time_s'],
            'steps_per_s': summary['steps'] / summary['wall_time_s'],
            'cpu_ms_per_step': 1e3 * cpu / summary['steps'],
            'missed_commands': summary['missed_commands'], 'status': summary['status'],
            'client_messages': received}


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (or one run with ``--role``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10, 100])
    parser.add_argument('--steps', type=int, default=200, help='steps per run')
    parser.add_argument('--repeat', type=int, default=1, help='interleaved rounds; best counts')
    parser.add_argument('--variants', nargs='+', default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument('--json', type=Path, help='write every run here')
    parser.add_argument('--role', choices=VARIANTS + ('viewer',), help=argparse.SUPPRESS)
    parser.add_argument('--n', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--port', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--stalled', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role == 'viewer':
        print(run_client(args.port, args.n, args.stalled))
        return 0
    if args.role is not None:
        print(json.dumps(run_role(args.role, args.n, args.steps)))
        return 0
    print(f'# bench_foxglove: {" ".join(sys.argv)}; load average {os.getloadavg()[0]:.2f}',
          flush=True)
    runs = []
    for n in args.sizes:
        for _ in range(args.repeat):
            for variant in args.variants:
                started = time.monotonic()
                res = subprocess.run([sys.executable, __file__, '--role', variant, '--n', str(n),
                                      '--steps', str(args.steps)], capture_output=True,
                                     text=True, timeout=RUN_TIMEOUT + 60)
                if res.returncode != 0:
                    print(f'{variant} N={n} failed:\n{res.stderr[-2000:]}', file=sys.stderr)
                    return 1
                run = json.loads(res.stdout.strip().splitlines()[-1])
                run['process_s'] = time.monotonic() - started
                runs.append(run)
    print(f'{"N":>4} {"variant":>8} {"steps/s":>8} {"ratio":>6} {"CPU ms/step":>11} '
          f'{"ratio":>6} {"missed":>6} {"client msgs":>11}')
    for n in args.sizes:
        best = {}
        for run in runs:
            if run['n'] == n and run['steps_per_s'] > best.get(run['variant'], {}).get(
                    'steps_per_s', 0):
                best[run['variant']] = run
        base = best.get('off', {})
        for variant in args.variants:
            run = best[variant]
            ratio = (f'{run["steps_per_s"] / base["steps_per_s"]:.2f}' if base else '-')
            cpu = min(r['cpu_ms_per_step'] for r in runs
                      if r['n'] == n and r['variant'] == variant)
            cpu_base = min((r['cpu_ms_per_step'] for r in runs
                            if r['n'] == n and r['variant'] == 'off'), default=None)
            cpu_ratio = f'{cpu / cpu_base:.2f}' if cpu_base else '-'
            msgs = '-' if run['client_messages'] is None else str(run['client_messages'])
            print(f'{n:>4} {variant:>8} {run["steps_per_s"]:>8.1f} {ratio:>6} {cpu:>11.3f} '
                  f'{cpu_ratio:>6} {run["missed_commands"]:>6} {msgs:>11}')
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(runs, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
