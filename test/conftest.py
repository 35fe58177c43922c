"""Fixtures specific to this repository's tests.

The generic ones (``ros_domain``, ``other_ros_domain``, ``flock_swarm_run``,
``in_process_swarm``) and the wait helpers come from :mod:`flock_swarm.testing`, the pytest
plugin every user's tests get too.
"""

import contextlib
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

# DDS discovery stays on this machine unless the caller asked otherwise (scripts/env.sh sets
# the same default), so a test run never talks to, or hears from, another host, also in the
# tests that start processes without a ros_domain fixture.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

REPO = Path(__file__).resolve().parents[1]
#: Top-level entries of a working tree that are not package sources (virtualenv, run outputs,
#: colcon's own directories), left out even if a global gitignore does not list them.
NOT_SOURCES = {'.venv', 'out', 'build', 'install', 'log'}
#: Wall-clock bounds: a build or a run that hangs fails the test instead of blocking CI.
BUILD_TIMEOUT = 300.0
RUN_TIMEOUT = 120.0


def start_nodes(scenario, domain: int, out, agents: int, world_args=(),
                world_stderr=subprocess.DEVNULL):
    """Start the leader, ``agents`` agent processes and the world (the ros2 run executables).

    :return: ``(others, world)``: the leader's and agents' processes, and the world's.
    """
    from flock_swarm.nodes.harness import executable
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    ros_args = ['--ros-args', '-p', f'scenario:={scenario}']
    quiet = {'env': env, 'stdout': subprocess.DEVNULL, 'stderr': subprocess.DEVNULL}
    others = [subprocess.Popen(executable('leader') + ros_args, **quiet)]
    others += [subprocess.Popen(executable('agent') + ros_args + ['-p', f'agent_id:={i}'],
                                **quiet) for i in range(agents)]
    world = subprocess.Popen(executable('world') + ros_args + ['-p', f'out_dir:={out}',
                                                               *world_args],
                             env=env, stdout=subprocess.DEVNULL, stderr=world_stderr,
                             text=True)
    return others, world


@contextlib.contextmanager
def small_filesystem(where: Path, size: str):
    """Mount a tmpfs of ``size`` (``mount -o size=``, e.g. ``3m``) on ``where`` for the block
    (the tests run as root), unmounted after it: a real disk that fills up.

    Skips the test, with the reason, only when mounting fails (no root, no mount(8), a
    container without the capability).
    """
    import pytest
    where.mkdir(parents=True, exist_ok=True)
    if shutil.which('mount') is None or os.geteuid() != 0:
        pytest.skip('a small tmpfs needs root and mount(8): not available here')
    res = subprocess.run(['mount', '-t', 'tmpfs', '-o', f'size={size}', 'tmpfs', str(where)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs here: {res.stderr.strip()}')
    try:
        yield where
    finally:
        subprocess.run(['umount', '-l', str(where)], check=False)


def source_files() -> list[str]:
    """Return the package sources: tracked and untracked non-ignored files, relative paths."""
    listed = subprocess.run(
        ['git', 'ls-files', '-z', '--cached', '--others', '--exclude-standard'],
        cwd=REPO, capture_output=True, check=True, timeout=60).stdout.decode()
    return [f for f in listed.split('\0')
            if f and f.split('/', 1)[0] not in NOT_SOURCES and (REPO / f).is_file()]


def copy_sources(dest: Path) -> None:
    """Copy the package sources (:func:`source_files`) into ``dest``, as a fresh clone has them."""
    for rel in source_files():
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, dest / rel)


def subprocess_env(**extra: str) -> dict[str, str]:
    """Return the environment of the test's subprocesses: this venv's bin on PATH, as env.sh.

    :param extra: further variables to set.
    :return: the environment.
    """
    env = dict(os.environ, **extra)
    venv_bin = str(Path(sys.executable).parent)
    env['PATH'] = os.pathsep.join([venv_bin, env.get('PATH', '')])
    # The ROS wheels' message packages are indexed under the venv (scripts/env.sh exports it).
    prefixes = [p for p in env.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    if sys.prefix not in prefixes:
        env['AMENT_PREFIX_PATH'] = os.pathsep.join([sys.prefix, *prefixes])
    return env


def run_installed(ws: Path, command: list[str], env: dict[str, str]):
    """Run ``command`` in ``ws`` after sourcing the workspace's ``install/setup.bash``."""
    return subprocess.run(['bash', '-c', 'source install/setup.bash && exec "$@"', 'bash',
                           *command], cwd=ws, env=env, capture_output=True, text=True,
                          timeout=RUN_TIMEOUT)


def imported_modules(path) -> set[str]:
    """Return every absolute module name a source file imports, at any depth of the file.

    ``from a.b import c`` counts as ``a.b`` and ``a.b.c`` (``c`` may be a module).
    """
    import ast
    found = set()
    for node in ast.walk(ast.parse(Path(path).read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f'{node.module}.{alias.name}' for alias in node.names)
    return found


#: How long a pytest-xdist worker waits for another's quick reproduction (it takes about a
#: minute alone, two or three beside the other worker's tests).
QUICK_REPRODUCTION_WAIT = 600.0


@pytest.fixture(scope='session')
def quick_reproduction(tmp_path_factory) -> Path:
    """Run ``python -m flock_swarm.reproduce --quick --skip-ros`` once for the whole session
    (about a minute) into a temporary directory: ``out/``, ``report.md``, ``figures/``.

    Read-only for the tests that share it; a test that runs the reproduction again copies
    ``out/`` first (test_reproduce_seeds). Under pytest-xdist (scripts/test's default) the
    workers share one run: it goes in the session's common temporary directory, and the first
    worker to need it runs it holding a lock while the others wait (at most
    :data:`QUICK_REPRODUCTION_WAIT`) and then read it. (xdist's ``--dist loadgroup`` would
    send its tests to one worker instead, but 3.8.0 cannot mark a test's id under pytest 9.2.)
    """
    import fcntl
    import threading
    from flock_swarm.cli import reproduce
    base = tmp_path_factory.getbasetemp()
    if os.environ.get('PYTEST_XDIST_WORKER'):
        base = base.parent  # the session's, shared by its workers (each has a directory in it)
    root, done = base / 'quick_reproduction', base / 'quick_reproduction.done'
    with open(base / 'quick_reproduction.lock', 'w') as lock:
        # flock blocks without a timeout: it waits in a thread, the test for at most the bound.
        locked = threading.Event()
        threading.Thread(target=lambda: (fcntl.flock(lock, fcntl.LOCK_EX), locked.set()),
                         daemon=True).start()
        assert locked.wait(QUICK_REPRODUCTION_WAIT), (
            f'another worker held {lock.name} for {QUICK_REPRODUCTION_WAIT:.0f} s')
        if not done.exists():
            shutil.rmtree(root, ignore_errors=True)  # what a failed attempt left
            status = reproduce.main(['--quick', '--skip-ros', '--jobs', '2',
                                     '--out', str(root / 'out'),
                                     '--report', str(root / 'report.md'),
                                     '--figures', str(root / 'figures')])
            assert status == 0
            done.touch()
    return root
