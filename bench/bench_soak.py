"""Soak benchmark: a 10-agent realtime swarm for 30 minutes; missed steps, latency, memory.

    python bench/bench_soak.py [--minutes 30] [--agents 10] [--processes] [--json FILE]

It runs ``swarm demo --mode realtime`` (world, leader and the agents in one process, or
with ``--processes`` each node its own process) for the given wall time at real time
(dt = 0.02 s, 50 steps per second), records the bag as usual, and reports:

- missed steps: the steps a 50 Hz clock would have ticked in the run's wall time but the
  world's timer did not (a late timer does not catch up);
- missed commands: world steps at which an agent's held command was older than the
  world's ``staleness`` (0.5 s) and was replaced by zero;
- command latency percentiles: from the world publishing a step's odometry to each
  agent's command for it arriving (the world's constant-memory histogram);
- memory over time: the resident set size of the swarm's process (world, leader and agents;
  with ``--processes`` the world's) every 10 s (VmRSS), its value at the start (the first
  sample, 5 s in) and at the end (the last sample), and its growth per minute after the
  first minute (a least-squares slope over the samples, so one allocator step weighs little).
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: Domain id of the soak (away from the test suite's 1-200 and bench_ros's 220).
DOMAIN = 221
#: Seconds between memory samples.
SAMPLE_EVERY = 10.0


def rss_mib(pid: int) -> float | None:
    """Return the resident set size of process ``pid`` [MiB], or ``None`` once it is gone."""
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def main(argv: list[str] | None = None) -> int:
    """Run the soak and print its report."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=30.0)
    parser.add_argument('--agents', type=int, default=10)
    parser.add_argument('--processes', action='store_true',
                        help='every node its own process (default: one process)')
    parser.add_argument('--json', type=Path, help='write the report here')
    args = parser.parse_args(argv)
    duration = 60.0 * args.minutes
    side = math.sqrt(args.agents / 0.075)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'soak'
        cmd = [sys.executable, '-m', 'flock_swarm.cli.swarm', 'demo', '--mode', 'realtime',
               '--out', str(out), '--no-plots', '--domain-id', str(DOMAIN),
               '--set', f'n_agents={args.agents}', '--set', f'informed.count={args.agents // 3}',
               '--set', f'initial.position_box=[[0, {side:.3f}], [0, {side:.3f}]]',
               '--set', f'duration={duration:g}', '--set', 'record_every=50']
        if args.processes:
            cmd.append('--processes')
        print(f'# bench_soak: {" ".join(cmd)}', flush=True)
        print(f'# machine: {os.cpu_count()} CPUs, load average {os.getloadavg()}', flush=True)
        env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
        started = time.monotonic()
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        samples = []
        deadline = started + duration + 600.0
        while proc.poll() is None and time.monotonic() < deadline:
            value = rss_mib(proc.pid)
            if value is not None and time.monotonic() - started >= 5.0:
                samples.append((round(time.monotonic() - started, 1), round(value, 1)))
                if len(samples) % 6 == 1:
                    print(f'  t = {samples[-1][0]:7.1f} s  RSS {value:7.1f} MiB',
                          flush=True)
            try:
                proc.wait(timeout=SAMPLE_EVERY)
            except subprocess.TimeoutExpired:
                pass
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        summary = json.loads((out / 'summary.json').read_text())
    wall = summary['wall_time_s']
    nominal = int(wall / summary['dt'])
    after_warmup = [m for t, m in samples if t >= 60.0] or [m for _, m in samples]
    warm = [(t, m) for t, m in samples if t >= 60.0]
    slope = None
    if len(warm) >= 2:
        # MiB per second, fitted, then per minute.
        slope = round(60.0 * float(np.polyfit(*zip(*warm), 1)[0]), 3)
    report = {
        'command': cmd, 'status': summary['status'], 'steps': summary['steps'],
        'wall_time_s': wall, 'missed_steps': max(0, nominal - summary['steps']),
        'missed_commands': summary['missed_commands'],
        'missed_commands_per_agent': summary['missed_commands_per_agent'],
        'command_latency_ms': summary['command_latency_ms'],
        'rss_mib': {'first': samples[0][1] if samples else None,
                    'after_1_min': after_warmup[0] if after_warmup else None,
                    'max': max(m for _, m in samples) if samples else None,
                    'last': samples[-1][1] if samples else None},
        'rss_growth_mib_per_min': slope,
        'rss_samples': samples,
    }
    lat = report['command_latency_ms']
    print(f'status {report["status"]}: {report["steps"]} steps in {wall:.0f} s wall '
          f'({report["missed_steps"]} missed against a 50 Hz clock), '
          f'{report["missed_commands"]} stale commands zeroed', flush=True)
    print(f'command latency [ms]: p50 {lat["p50"]}, p90 {lat["p90"]}, p99 {lat["p99"]}, '
          f'max {lat["max"]} ({lat["count"]} commands)', flush=True)
    rss = report['rss_mib']
    print(f'RSS [MiB]: start {rss["first"]}, after 1 min {rss["after_1_min"]}, '
          f'max {rss["max"]}, end {rss["last"]}; growth after 1 min '
          f'{report["rss_growth_mib_per_min"]} MiB/min', flush=True)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1))
    return 0 if report['status'] == 'completed' else 1


if __name__ == '__main__':
    sys.exit(main())
