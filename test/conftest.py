"""Fixtures specific to this repository's tests.

The generic ones (``ros_domain``, ``other_ros_domain``, ``flock_swarm_run``,
``in_process_swarm``) and the wait helpers come from :mod:`flock_swarm.testing`, the pytest
plugin every user's tests get too.
"""

import ast
import contextlib
import functools
import json
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
    from flock_swarm.nodes.swarm_runner import executable
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


#: How long a pytest-xdist worker waits for another's quick reproduction (it took 31 s in one
#: process on a loaded machine, 78 s on two worker processes, whose start per study dominated).
QUICK_REPRODUCTION_WAIT = 600.0
#: Niceness of the quick reproduction started in the background: it yields to the tests
#: (their realtime nodes) and takes the cores they leave idle.
QUICK_REPRODUCTION_NICE = 10
#: The quick reproduction's command line (its outputs go under the directory given).
QUICK_REPRODUCTION_ARGS = ('--quick', '--skip-ros', '--jobs', '1')


def shared_temp(factory) -> Path:
    """Return the session's temporary directory that every pytest-xdist worker shares (the
    worker's own base directory's parent; the base directory without xdist)."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get('PYTEST_XDIST_WORKER') else base


def quick_reproduction_files(base: Path) -> dict[str, Path]:
    """Return the paths of the session's quick reproduction in ``base``: its outputs
    (``root``), the mark of a finished run (``done``), the lock the fixture takes, and those
    of the run started in the background (``started``, ``status``: its exit status, ``log``).
    """
    keys = ('done', 'lock', 'started', 'status', 'log')
    return {'root': base / 'quick_reproduction',
            **{key: base / f'quick_reproduction.{key}' for key in keys}}


def quick_reproduction_command(root: Path) -> list[str]:
    """Return the command line of the quick reproduction writing into ``root``."""
    return [sys.executable, '-m', 'flock_swarm.reproduce', *QUICK_REPRODUCTION_ARGS,
            '--out', str(root / 'out'), '--report', str(root / 'report.md'),
            '--figures', str(root / 'figures')]


def pytest_collection_finish(session):
    """Start the session's quick reproduction in the background (at nice 10) as soon as the
    collection holds a test that needs it (issue 39): it then runs on the cores' idle time
    (tests waiting on DDS and on child processes) while the tests before its own run. It
    held a pytest-xdist worker for its whole run when the first of its tests came, and the
    other worker, needing it as well, waited idle. Once per session (the first worker to
    collect starts it); :func:`quick_reproduction` waits for its status."""
    config = session.config
    if config.option.collectonly or not any(
            'quick_reproduction' in getattr(item, 'fixturenames', ()) for item in session.items):
        return
    files = quick_reproduction_files(shared_temp(config._tmp_path_factory))
    try:
        os.close(os.open(files['started'], os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return  # another worker's
    with files['log'].open('w') as log:
        # bash writes the exit status once the run ends (a file: every worker can read it).
        config.flock_swarm_quick_reproduction = subprocess.Popen(
            ['bash', '-c', '"$@"; echo $? > "$0.tmp" && mv "$0.tmp" "$0"', str(files['status']),
             *quick_reproduction_command(files['root'])],
            cwd=REPO, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
            preexec_fn=lambda: os.nice(QUICK_REPRODUCTION_NICE))


def pytest_sessionfinish(session, exitstatus):
    """Wait for the background quick reproduction this process started (another worker may
    still need it), at most :data:`QUICK_REPRODUCTION_WAIT`; end it at once if the session
    was interrupted."""
    proc = getattr(session.config, 'flock_swarm_quick_reproduction', None)
    if proc is None or proc.poll() is not None:
        return
    if exitstatus != pytest.ExitCode.INTERRUPTED:
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(QUICK_REPRODUCTION_WAIT)
    if proc.poll() is None:
        proc.kill()
        proc.wait()


@pytest.fixture(scope='session')
def quick_reproduction(tmp_path_factory) -> Path:
    """The session's ``python -m flock_swarm.reproduce --quick --skip-ros --jobs 1``, in a
    temporary directory: ``out/``, ``report.md``, ``figures/``.

    Read-only for the tests that share it; a test that runs the reproduction again copies
    ``out/`` first (test_reproduce_seeds). Under pytest-xdist (scripts/test's default) the
    workers share one run: it goes in the session's common temporary directory. It was
    started in the background at the collection (:func:`pytest_collection_finish`): the
    first worker to need it waits for its status holding a lock, the others wait for the
    lock (each at most :data:`QUICK_REPRODUCTION_WAIT`) and then read it. Without that start
    (a test collected otherwise) it runs here, in this process. (xdist's ``--dist
    loadgroup`` would send its tests to one worker instead, but 3.8.0 cannot mark a test's
    id under pytest 9.2.)
    """
    import fcntl
    import threading

    from flock_swarm.cli import reproduce
    from flock_swarm.testing import wait_for
    files = quick_reproduction_files(shared_temp(tmp_path_factory))
    root, done, status = files['root'], files['done'], files['status']
    with open(files['lock'], 'w') as lock:
        # flock blocks without a timeout: it waits in a thread, the test for at most the bound.
        locked = threading.Event()
        threading.Thread(target=lambda: (fcntl.flock(lock, fcntl.LOCK_EX), locked.set()),
                         daemon=True).start()
        assert locked.wait(QUICK_REPRODUCTION_WAIT), (
            f'another worker held {lock.name} for {QUICK_REPRODUCTION_WAIT:.0f} s')
        if not done.exists():
            if files['started'].exists():
                wait_for(status.exists, QUICK_REPRODUCTION_WAIT,
                         'the quick reproduction started in the background')
                code = status.read_text().strip()
                assert code == '0', (f'{" ".join(quick_reproduction_command(root))} exited '
                                     f'{code}:\n{files["log"].read_text()[-3000:]}')
            else:
                shutil.rmtree(root, ignore_errors=True)  # what a failed attempt left
                assert reproduce.main([*QUICK_REPRODUCTION_ARGS, '--out', str(root / 'out'),
                                       '--report', str(root / 'report.md'),
                                       '--figures', str(root / 'figures')]) == 0
            done.touch()
    return root


# -- tiers: the markers ``ros`` and ``slow``, scripts/test --quick --------------------------------

#: The tests' measured durations in seconds, the source of the ``slow`` marker:
#: ``{file: {test name within the file: [setup, call and teardown together, setup]}}``.
#: Written by ``scripts/test --record-durations`` (README, "Tests"), which updates the tests
#: it ran and keeps the others'.
DURATIONS = REPO / 'test' / 'durations.json'
#: A test measured at this many seconds or more is ``slow``; so is every test that uses a
#: fixture shared by several tests (scope ``module`` or ``session``) whose set-up took this
#: long in one of them: the tier that runs them pays it.
SLOW = 1.0
#: The fixtures that give a test a ROS domain (and, with it, DDS): a test that uses one,
#: directly or through another fixture, is ``ros``.
ROS_FIXTURES = frozenset({'ros_domain', 'other_ros_domain', 'ros_context', 'flock_swarm_run',
                          'in_process_swarm'})
#: Names whose use starts DDS: rclpy, the harness's runs and the node executables; a test is
#: ``ros`` when it, a fixture it uses or a function of its module it calls names one.
DDS_NAMES = frozenset({'rclpy', 'unique_domain', 'start_nodes', 'run_swarm', 'Swarm',
                       'InProcessSwarm', 'assert_matches_sim', 'executable', 'run_in_process',
                       'run_processes', 'run_installed'})
#: The executables (and the modules of the commands) that start DDS, as a test's command line
#: or one of its parameters names them.
DDS_COMMANDS = frozenset({'swarm', 'world', 'leader', 'agent', 'agents', 'foxglove_server',
                          'replay', 'robot_agent', 'flock_swarm.cli.swarm',
                          'flock_swarm.cli.replay', 'scripts/demo'})
#: ``scripts/test --quick`` runs the tests that are not ``slow`` and these: one lockstep ROS
#: run equal to ``sim`` bit for bit per front-end feature (network, plant, obstacles,
#: engine). A test named here that its collected file does not hold is an error of
#: ``--quick`` (one line, exit status 2).
QUICK = (
    'test/test_network_ros.py::test_delay_loss_and_noise_match_sim_in_every_layout[one process]',
    'test/test_plants_ros.py::test_a_robot_plant_through_cmd_vel_matches_sim[unicycle-one '
    'process]',
    'test/test_obstacles_ros.py::test_a_run_with_obstacles_matches_sim_in_every_layout[one '
    'process]',
    'test/test_engine_world.py::test_six_engine_robots_follow_a_circling_leader_in_lockstep',
    # The batched transport across processes (its one-process runs are fast tests already).
    'test/test_transport_ros.py::test_batched_in_processes_equals_sim[container]',
)


def pytest_addoption(parser):
    """The tier options: ``--quick`` and ``--record-durations``."""
    group = parser.getgroup('flock_swarm tiers')
    group.addoption('--quick', action='store_true',
                    help='run the fast tier (no test measured at >= 1 s in '
                         'test/durations.json) and the lockstep equivalences of QUICK')
    group.addoption('--record-durations', metavar='PATH', nargs='?', const=str(DURATIONS),
                    default=None,
                    help='write the durations of the tests that ran into PATH (default '
                         'test/durations.json), keeping the other tests\' entries')


def load_durations(path: Path = DURATIONS) -> dict[str, tuple[float, float]]:
    """Return the recorded ``(total, setup)`` durations by node id (``{}`` without the
    file)."""
    if not path.exists():
        return {}
    return {f'{file}::{name}': (total, setup)
            for file, tests in json.loads(path.read_text()).items()
            for name, (total, setup) in tests.items()}


def write_durations(durations: dict[str, tuple[float, float]], path: Path = DURATIONS) -> None:
    """Write ``{node id: (total, setup)}`` as ``{file: {name: [total, setup]}}``, sorted,
    rounded to 10 ms."""
    grouped: dict[str, list[str]] = {}
    for nodeid, times in sorted(durations.items()):
        file, _, name = nodeid.partition('::')
        grouped.setdefault(file, []).append(
            f'{json.dumps(name)}: {json.dumps([round(t, 2) for t in times])}')
    path.write_text('{\n' + ',\n'.join(f'{json.dumps(file)}: {{\n' + ',\n'.join(lines) + '\n}'
                                       for file, lines in grouped.items()) + '\n}\n')


def _names(node: ast.AST) -> tuple[set[str], set[str]]:
    """Return the names a function's body (not its decorators) uses: bare names and
    attributes, and string constants."""
    names, strings = set(), set()
    for stmt in getattr(node, 'body', []):
        for sub in ast.walk(stmt):
            if isinstance(sub, ast.Name):
                names.add(sub.id)
            elif isinstance(sub, ast.Attribute) and sub.attr != 'executable':  # sys.executable
                names.add(sub.attr)
            elif isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                strings.add(sub.value)
    return names, strings


#: Names whose use runs a command: a test whose parameter names a command starts DDS only if
#: it starts a process or imports a module by name to run its main (``tool='swarm'`` in a
#: command line, not ``which='swarm'``).
PROCESS_NAMES = frozenset({'subprocess', 'Popen', 'run_installed', 'import_module'})


@functools.cache
def dds_functions(path: str) -> tuple[frozenset[str], frozenset[str]]:
    """Return the functions and classes of a test module (``Class.method`` for methods) that
    start DDS: they name one of :data:`DDS_NAMES` or a command line or path of
    :data:`DDS_COMMANDS`, or call a function of the module that does; and those that start
    a process (:data:`PROCESS_NAMES`, or calling a function of the module that does).
    """
    tree = ast.parse(Path(path).read_text(), path)
    defs: dict[str, ast.AST] = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defs[node.name] = node
        if isinstance(node, ast.ClassDef):
            for sub in node.body:
                if isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    defs[f'{node.name}.{sub.name}'] = sub
    uses = {name: _names(node) for name, node in defs.items()}

    def closure(starts: set[str]) -> frozenset[str]:
        while True:  # what calls a function that starts one starts one too
            more = {name for name, (names, _) in uses.items()
                    if name not in starts and names & {s.split('.')[-1] for s in starts}}
            if not more:
                return frozenset(starts)
            starts |= more

    return (closure({name for name, (names, strings) in uses.items()
                     if names & DDS_NAMES or any(names_command(s, bare=False)
                                                 for s in strings)}),
            closure({name for name, (names, _) in uses.items() if names & PROCESS_NAMES}))


def names_command(value, bare: bool = True) -> bool:
    """Return whether ``value`` (a string, or a list or tuple of them) names a command that
    starts DDS: its first word, or that word's last path component (``/venv/bin/swarm``), is
    one of :data:`DDS_COMMANDS`.

    :param bare: whether a lone word counts (a test's parameter ``'swarm'``); else only a
        command line (``'swarm demo'``) or a path (``bin/swarm``) does, not the word
        ``'world'`` a frame id or a directory name uses.
    """
    if isinstance(value, (list, tuple)):
        return bool(value) and names_command(value[0], bare)
    if not isinstance(value, str) or not value.strip():
        return False
    first = value.split()[0]
    if value in DDS_COMMANDS and '.' in value:  # a module: flock_swarm.cli.swarm
        return True
    if not bare and first == value and '/' not in value:
        return False
    return bool({first, first.rsplit('/', 1)[-1]} & DDS_COMMANDS)


def starts_dds(item) -> bool:
    """Return whether a test starts DDS (its ``ros`` marker): it uses one of
    :data:`ROS_FIXTURES`, or it (or a fixture or function of its module it uses) does by
    :func:`dds_functions`, or it starts a process and one of its parameters names a command
    that starts DDS."""
    fixtures = set(getattr(item, 'fixturenames', ()))
    if ROS_FIXTURES & fixtures:
        return True
    path = str(item.path)
    if not path.endswith('.py'):
        return False
    dds, processes = dds_functions(path)
    name = getattr(item, 'originalname', item.name)
    cls = getattr(item, 'cls', None)
    own = {f'{cls.__name__}.{name}' if cls is not None else name} | fixtures
    if own & dds:
        return True
    callspec = getattr(item, 'callspec', None)
    return bool(own & processes and callspec
                and any(names_command(v) for v in callspec.params.values()))


def is_core_module(path: Path) -> bool:
    """Return whether a test module is core's: it imports from flock_swarm only its ROS-free,
    process-free core (``flock_swarm.core``) and starts no processes."""
    modules = imported_modules(path)
    ours = {m for m in modules if m == 'flock_swarm' or m.startswith('flock_swarm.')}
    return (all(m.startswith('flock_swarm.core') for m in ours)
            and not modules & {'subprocess', 'multiprocessing', 'rclpy'})


def shared_fixtures(item) -> set[str]:
    """Return the fixtures of this directory a test uses that several tests share (scope
    ``module``, ``package`` or ``session``), by ``file::name``."""
    info = getattr(item, '_fixtureinfo', None)
    found = set()
    for name, defs in (info.name2fixturedefs.items() if info else ()):
        for fixture in defs:
            where = Path(fixture.func.__code__.co_filename)
            if fixture.scope != 'function' and where.parent == REPO / 'test':
                found.add(f'{where.name}::{name}')
    return found


def pytest_collection_modifyitems(config, items):
    """Mark each test ``ros`` (:func:`starts_dds`) and ``slow``: measured at >= :data:`SLOW` in
    :data:`DURATIONS`, or using a shared fixture whose set-up was (:func:`shared_fixtures`);
    a test without a measurement is slow unless its module is core's. With ``--quick``, keep
    the tests that are not slow and those of :data:`QUICK`."""
    durations = load_durations()
    core = functools.cache(is_core_module)
    slow_fixtures = set()
    for item in items:
        if durations.get(item.nodeid, (0.0, 0.0))[1] >= SLOW:
            slow_fixtures |= shared_fixtures(item)
    for item in items:
        if starts_dds(item):
            item.add_marker(pytest.mark.ros)
        measured = durations.get(item.nodeid)
        if measured is None:
            slow = not core(item.path)
        else:
            slow = measured[0] >= SLOW or bool(shared_fixtures(item) & slow_fixtures)
        if slow:
            item.add_marker(pytest.mark.slow)
    if not config.getoption('quick'):
        return
    ids = {item.nodeid for item in items}
    files = {nodeid.partition('::')[0] for nodeid in ids}
    named = any('::' in arg for arg in config.args)  # tests chosen by id: only those
    missing = [nodeid for nodeid in QUICK
               if not named and nodeid.partition('::')[0] in files and nodeid not in ids]
    if missing:
        pytest.exit(f'error: --quick: {missing[0]} is not a test of its file (renamed? update '
                    'QUICK in test/conftest.py)', returncode=2)
    keep = [item for item in items
            if item.nodeid in QUICK or not item.get_closest_marker('slow')]
    config.hook.pytest_deselected(items=[item for item in items if item not in keep])
    items[:] = keep


class DurationRecorder:
    """Sum each test's setup, call and teardown durations; write them at the session's end
    (in the controller under pytest-xdist, which receives every worker's reports)."""

    def __init__(self, path: Path) -> None:
        """Record into ``path``."""
        self.path = path
        self.durations: dict[str, tuple[float, float]] = {}

    def pytest_runtest_logreport(self, report) -> None:
        """Add a phase's duration to its test's (the set-up's to both numbers)."""
        total, setup = self.durations.get(report.nodeid, (0.0, 0.0))
        self.durations[report.nodeid] = (total + report.duration,
                                         setup + (report.duration if report.when == 'setup'
                                                  else 0.0))

    def pytest_sessionfinish(self, session) -> None:
        """Merge the durations into the file's (whose entries of deleted files go)."""
        if self.durations:
            kept = {nodeid: times for nodeid, times in load_durations(self.path).items()
                    if (REPO / nodeid.partition('::')[0]).exists()}
            write_durations({**kept, **self.durations}, self.path)


def pytest_configure(config):
    """Record durations with ``--record-durations`` (not in an xdist worker)."""
    path = config.getoption('record_durations')
    if path and not hasattr(config, 'workerinput'):
        config.pluginmanager.register(DurationRecorder(Path(path)), 'flock_swarm_durations')
