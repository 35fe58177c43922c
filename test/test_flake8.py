"""Lint the Python sources with flake8, as ament_flake8 does under ``colcon test``."""

from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parent.parent
# Source trees checked, whichever of them exist.
TARGETS = ('flock_swarm', 'test', 'bench', 'launch', 'examples')
# ament_flake8's line limit (ROS 2 code style).
MAX_LINE_LENGTH = 99


def test_flake8():
    """Find no flake8 findings in the package, its tests, benchmarks, launch files, examples."""
    paths = [name for name in TARGETS if (ROOT / name).is_dir()]
    result = subprocess.run(
        [sys.executable, '-m', 'flake8', f'--max-line-length={MAX_LINE_LENGTH}', *paths],
        cwd=ROOT, capture_output=True, text=True, check=False)
    report = (result.stdout + result.stderr).strip()
    assert result.returncode == 0, f'flake8 findings ({len(report.splitlines())}):\n{report}'
