"""Benchmark of ``analyze --verify`` against ``sim`` on the same scenario (issue 38).

    python bench/bench_analyze.py [--scenario zhou2012_sec51] [--set KEY=VALUE ...]
                                  [--bag DIR] [--repeat 1]

Records the scenario through the ROS nodes (``swarm``, lockstep, one process; skipped with
``--bag``, a bag of that scenario recorded before), then times ``sim SCENARIO`` and
``analyze BAG --verify --no-anim`` as separate processes, one after the other, ``--repeat``
times, and prints each one's wall time and CPU time (user + system of the process) and the
ratio analyze / sim of both. The target: analyze within 2x of sim. The default scenario is
the 60,000-step one of the issue (10 agents, Zhou 2012 Section 5.1). The CPU ratio is the
steadier one on a shared machine (the wall ratio moves with whatever else runs).
"""

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Largest accepted ratio analyze --verify / sim.
TARGET = 2.0


def timed(command: list[str]) -> tuple[float, float]:
    """Run ``command``; return its wall time and CPU time [s] (user + system)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.monotonic()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    wall = time.monotonic() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; return 0 when every ratio meets the target, else 1."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenario', default='zhou2012_sec51')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE')
    parser.add_argument('--bag', type=Path, help='a bag of the scenario recorded before')
    parser.add_argument('--repeat', type=int, default=1)
    parser.add_argument('--domain-id', default='229', help='ROS domain of the recording')
    args = parser.parse_args(argv)
    sets = [arg for item in args.overrides for arg in ('--set', item)]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        bag = args.bag
        if bag is None:
            print(f'recording {args.scenario} through the nodes ...', flush=True)
            wall, _ = timed(['swarm', args.scenario, *sets, '--out', str(root / 'run'),
                             '--no-plots', '--domain-id', args.domain_id])
            bag = root / 'run' / 'bag'
            print(f'recorded in {wall:.1f} s', flush=True)
        print(f'{"run":>4} {"sim wall":>9} {"sim cpu":>8} {"analyze wall":>13} '
              f'{"analyze cpu":>12} {"wall ratio":>11} {"cpu ratio":>10}')
        ok = True
        for run in range(args.repeat):
            sim = timed(['sim', args.scenario, *sets, '--out', str(root / f'sim{run}'),
                         '--quiet'])
            analyze = timed(['analyze', str(bag), '--verify', '--no-anim', '--quiet',
                             '--out', str(root / f'analysis{run}')])
            wall, cpu = analyze[0] / sim[0], analyze[1] / sim[1]
            ok = ok and cpu <= TARGET
            print(f'{run:>4} {sim[0]:>8.1f}s {sim[1]:>7.1f}s {analyze[0]:>12.1f}s '
                  f'{analyze[1]:>11.1f}s {wall:>11.2f} {cpu:>10.2f}', flush=True)
    print(f'target: analyze --verify within {TARGET:g}x of sim (CPU time): '
          f'{"PASS" if ok else "FAIL"}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
