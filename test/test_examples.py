"""The example package (examples/flock_swarm_examples), installed and built as a user's would be.

It adds a law (``cucker_smale``) and a leader model (``figure_eight``) to flock_swarm through
entry points only. A copy of it is pip-installed into a directory of its own (put on
``PYTHONPATH``: the project's virtualenv stays as it is, so no other test sees the plugins),
and a copy of it is built with ``colcon build`` next to a copy of flock_swarm. Then ``sim``
runs its scenario; its own tests (written against :mod:`flock_swarm.testing` only) pass; a
lockstep ROS run of the colcon install equals ``sim`` bit for bit; and a broken copy of the
plugin gets one error line naming its entry point and exit status 2.
"""

import json
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from flock_swarm.testing import compare_runs, SIM_ONLY
from conftest import (BUILD_TIMEOUT, copy_sources, REPO, RUN_TIMEOUT, run_installed,
                      subprocess_env)

pytestmark = pytest.mark.ros

EXAMPLE = REPO / 'examples' / 'flock_swarm_examples'
PACKAGE = 'flock_swarm_examples'
SCENARIO = 'config/cucker_smale_figure_eight.yaml'
#: One second of the scenario, every step recorded (the ROS run against sim).
SHORT = ['--set', 'duration=1.0', '--set', 'record_every=1']
#: What the package itself builds or leaves behind in a source tree.
NOT_COPIED = shutil.ignore_patterns('build', 'install', 'log', '*.egg-info', '__pycache__',
                                    '.pytest_cache')


def run(command: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    """Run ``command`` to its end (bounded), capturing its output."""
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=RUN_TIMEOUT)


def with_plugin(site: Path, **extra: str) -> dict[str, str]:
    """Return the subprocess environment with the pip-installed example on ``PYTHONPATH``."""
    env = subprocess_env(**extra)
    env['PYTHONPATH'] = os.pathsep.join(
        [str(site)] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    return env


def outputs(out: Path) -> tuple[dict, dict]:
    """Return the summary and the time series a run wrote to ``out``."""
    with np.load(out / 'timeseries.npz') as data:
        series = {name: data[name] for name in data.files}
    return json.loads((out / 'summary.json').read_text()), series


@pytest.fixture(scope='module')
def source(tmp_path_factory) -> Path:
    """Return a copy of the example package's sources (builds never touch the working tree)."""
    dest = tmp_path_factory.mktemp('example') / PACKAGE
    shutil.copytree(EXAMPLE, dest, ignore=NOT_COPIED)
    return dest


@pytest.fixture(scope='module')
def site(source, tmp_path_factory) -> Path:
    """Return the directory the example is pip-installed into (``pip install --target``)."""
    target = tmp_path_factory.mktemp('site')
    result = subprocess.run([sys.executable, '-m', 'pip', 'install', '--quiet', '--no-input',
                             '--no-deps', '--no-build-isolation', '--target', str(target),
                             str(source)], capture_output=True, text=True,
                            timeout=BUILD_TIMEOUT)
    assert result.returncode == 0, result.stderr[-3000:]
    return target


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> Path:
    """Return a colcon workspace holding flock_swarm and the example, built."""
    ws = tmp_path_factory.mktemp('colcon') / 'ws'
    copy_sources(ws / 'src' / 'flock_swarm')
    # The example sits inside flock_swarm's tree, where colcon does not look (it stops at a
    # package): its directory is a base path of its own.
    result = subprocess.run(
        [sys.executable, '-m', 'colcon', 'build', '--base-paths', 'src',
         'src/flock_swarm/examples'], cwd=ws,
        env=subprocess_env(COLCON_HOME=str(ws / 'colcon_home')), capture_output=True,
        text=True, timeout=BUILD_TIMEOUT)
    assert result.returncode == 0, f'colcon build failed:\n{result.stdout}\n{result.stderr}'
    return ws


def test_sim_lists_and_runs_the_examples_law_and_leader(site, source, tmp_path):
    env = with_plugin(site)
    listing = run(['sim', '--list'], env, tmp_path)
    assert listing.returncode == 0, listing.stderr
    for name in ('cucker_smale', 'figure_eight'):
        line, = [x for x in listing.stdout.splitlines() if x.split()[:1] == [name]]
        assert f'[{PACKAGE}]' in line, line
    result = run(['sim', str(source / SCENARIO), '--out', str(tmp_path / 'sim')], env, tmp_path)
    assert result.returncode == 0, result.stderr
    summary, series = outputs(tmp_path / 'sim')
    assert (summary['protocol'], summary['status']) == ('cucker_smale', 'completed')
    # After one loop of the figure eight every agent moves with the leader (within the
    # scenario's eta tolerance): the informed agents track it, the others align with them.
    assert summary['eta'] == 1.0
    assert summary['components_final'] == 1


def test_the_examples_own_tests_pass(site, source):
    result = run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider', 'test'],
                 with_plugin(site), source)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    # The example's five tests and its check_law test (issue 24).
    assert re.search(r'\b6 passed\b', result.stdout), result.stdout[-2000:]


def test_colcon_builds_the_example_and_its_ros_run_equals_sim(workspace, tmp_path, ros_domain):
    share = workspace / 'install' / PACKAGE / 'share'
    assert (share / PACKAGE / 'package.xml').is_file()
    assert (share / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()
    scenario = share / PACKAGE / SCENARIO
    assert scenario.is_file()
    env = subprocess_env()
    # The installed commands, as `ros2 run flock_swarm sim` and `... swarm` would start them.
    lib = workspace / 'install' / 'flock_swarm' / 'lib' / 'flock_swarm'
    sim = run_installed(workspace, [str(lib / 'sim'), str(scenario), *SHORT, '--out',
                                    str(tmp_path / 'sim')], env)
    assert sim.returncode == 0, sim.stderr
    ros = run_installed(workspace, [str(lib / 'swarm'), str(scenario), *SHORT, '--no-plots',
                                    '--domain-id', str(ros_domain), '--out',
                                    str(tmp_path / 'ros')], env)
    assert ros.returncode == 0, ros.stderr
    want, want_series = outputs(tmp_path / 'sim')
    got, got_series = outputs(tmp_path / 'ros')
    assert got['missed_commands'] == 0 and got['leader_missed'] == 0
    want = {k: v for k, v in want.items() if k not in SIM_ONLY}
    assert compare_runs(want, want_series, got, got_series, atol=0.0) == []
    assert got['protocol'] == 'cucker_smale' and got['steps'] == 50


def break_import(module: Path) -> None:
    """Make the module fail to import."""
    module.write_text('import flock_swarm_examples.no_such_module\n' + module.read_text())


def drop_combine(module: Path) -> None:
    """Remove the law's ``combine`` method (it is the last one of the class)."""
    text = module.read_text()
    module.write_text(text[:text.index('    def combine(')].rstrip() + '\n')


@pytest.mark.parametrize('breakage, reason', [
    (break_import, "cannot be imported: ModuleNotFoundError: No module named "
                   "'flock_swarm_examples.no_such_module'"),
    (drop_combine, 'does not define combine'),
])
def test_a_broken_plugin_gets_one_line_naming_its_entry_point(site, source, tmp_path,
                                                              breakage, reason):
    broken = tmp_path / 'site'
    shutil.copytree(site, broken)
    breakage(broken / PACKAGE / 'cucker_smale.py')
    env = with_plugin(broken)
    for command in ('sim', 'swarm'):
        result = run([command, str(source / SCENARIO), '--out', str(tmp_path / command)], env,
                     tmp_path)
        assert result.returncode == 2, result.stderr
        lines = result.stderr.splitlines()
        assert len(lines) == 1, result.stderr
        assert lines[0].startswith(f'{command}: error: protocol.name: '
                                   'flock_swarm.laws:cucker_smale '
                                   '(flock_swarm_examples.cucker_smale:CuckerSmale): '), lines[0]
        assert lines[0].endswith(reason), lines[0]


def test_no_line_of_flock_swarm_names_the_example():
    """The law and the leader reach flock_swarm through entry points alone."""
    names = re.compile(r'cucker|smale|figure.?eight|lissajous|flock_swarm_examples', re.I)
    found = [f'{path.relative_to(REPO)}:{n}: {line.strip()}'
             for path in sorted((REPO / 'flock_swarm').rglob('*')) if path.is_file()
             and path.suffix in ('.py', '.yaml', '.txt', '.md', '.json')
             for n, line in enumerate(path.read_text().splitlines(), 1) if names.search(line)]
    assert found == []
