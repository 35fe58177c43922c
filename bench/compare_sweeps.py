"""Compare two Fig. 3 sweep caches point by point: a change of numerics against Monte Carlo error.

    python bench/compare_sweeps.py OLD/fig3_runs.jsonl NEW/fig3_runs.jsonl [--key eta]

For every (N, delta) of NEW, over the seeds both caches hold: the two means of ``--key``,
their difference, twice its standard error (the runs of the two caches taken as independent
samples) and how many seeds gave exactly the same value. A change that only moves the
law's last bits changes single runs (the flocking dynamics amplify a one-ulp difference)
but not the means beyond their error; the last line gives the largest |difference| / 2 SE.
"""

import argparse
import collections
import json
import sys
from pathlib import Path

import numpy as np


def load(path: Path) -> dict:
    """Return ``{(n_agents, delta): {seed: record}}`` of a ``fig3_runs.jsonl``."""
    runs: dict = collections.defaultdict(dict)
    for line in path.read_text().splitlines():
        if line.strip():
            rec = json.loads(line)
            runs[(rec['n_agents'], rec['delta'])][rec['seed']] = rec
    return runs


def main(argv: list[str] | None = None) -> int:
    """Print the comparison; return 0, or 2 when the caches share no runs."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('old', type=Path)
    parser.add_argument('new', type=Path)
    parser.add_argument('--key', default='eta', help='record field to compare (default: eta)')
    args = parser.parse_args(argv)
    for path in (args.old, args.new):
        if not path.is_file():
            parser.error(f'{path}: no such file')
    old, new = load(args.old), load(args.new)
    print(f'{"N":>5} {"delta":>6} {"seeds":>5} {"old mean":>9} {"new mean":>9} {"diff":>8} '
          f'{"2 SE":>7} {"equal":>5}')
    worst, compared = 0.0, 0
    for point in sorted(new):
        seeds = sorted(set(old.get(point, {})) & set(new[point]))
        if not seeds:
            continue
        try:
            a = np.array([float(old[point][s][args.key]) for s in seeds])
            b = np.array([float(new[point][s][args.key]) for s in seeds])
        except (KeyError, TypeError, ValueError):
            parser.error(f'--key {args.key}: not a number in every record')
        compared += 1
        se = np.sqrt((a.var(ddof=1) + b.var(ddof=1)) / len(seeds)) if len(seeds) > 1 else 0.0
        diff = b.mean() - a.mean()
        if se > 0:
            worst = max(worst, abs(diff) / (2.0 * se))
        print(f'{point[0]:>5} {point[1]:>6} {len(seeds):>5} {a.mean():9.4f} {b.mean():9.4f} '
              f'{diff:8.4f} {2 * se:7.4f} {int(np.sum(a == b)):>5}')
    if not compared:
        print('compare_sweeps: error: the two caches share no (N, delta, seed)', file=sys.stderr)
        return 2
    print(f'largest |diff| / 2 SE: {worst:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
