"""bench/compare_sweeps.py: the point-by-point comparison of two Fig. 3 sweep caches."""

import json
import statistics
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / 'bench' / 'compare_sweeps.py'


def write_cache(path: Path, etas: dict) -> Path:
    """Write a ``fig3_runs.jsonl`` with ``{(n, delta): [eta of seed 0, 1, ...]}``."""
    lines = [json.dumps({'n_agents': n, 'delta': delta, 'seed': seed, 'eta': eta})
             for (n, delta), values in etas.items() for seed, eta in enumerate(values)]
    path.write_text('\n'.join(lines) + '\n')
    return path


def run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)],
                          capture_output=True, text=True, timeout=60)


def test_means_differences_and_equal_seeds(tmp_path):
    old = write_cache(tmp_path / 'old.jsonl', {(100, 0.1): [0.1, 0.2, 0.3, 0.4],
                                               (300, 0.5): [0.5, 0.5, 0.6, 0.6]})
    new = write_cache(tmp_path / 'new.jsonl', {(100, 0.1): [0.1, 0.2, 0.3, 0.8],
                                               (300, 0.5): [0.5, 0.5, 0.6, 0.6]})
    res = run(old, new)
    assert res.returncode == 0, res.stderr
    rows = {tuple(line.split()[:2]): line.split() for line in res.stdout.splitlines()[1:-1]}
    # Point (100, 0.1): means 0.25 and 0.35, three of four seeds equal.
    assert rows[('100', '0.1')][3:6] == ['0.2500', '0.3500', '0.1000']
    assert rows[('100', '0.1')][7] == '3'
    assert rows[('300', '0.5')][5] == '0.0000' and rows[('300', '0.5')][7] == '4'
    # 2 SE of (100, 0.1): sqrt((var_old + var_new) / 4) * 2 with ddof = 1.
    se = ((statistics.variance([0.1, 0.2, 0.3, 0.4])
           + statistics.variance([0.1, 0.2, 0.3, 0.8])) / 4) ** 0.5
    assert res.stdout.splitlines()[-1] == f'largest |diff| / 2 SE: {0.1 / (2 * se):.2f}'


def test_no_shared_runs_and_missing_file_exit_2(tmp_path):
    old = write_cache(tmp_path / 'old.jsonl', {(100, 0.1): [0.1, 0.2]})
    new = write_cache(tmp_path / 'new.jsonl', {(500, 0.1): [0.1, 0.2]})
    res = run(old, new)
    assert res.returncode == 2 and 'share no' in res.stderr
    res = run(tmp_path / 'absent.jsonl', new)
    assert res.returncode == 2 and 'no such file' in res.stderr
