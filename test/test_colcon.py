"""``colcon build`` installs the package, and the installed world node runs from the install.

The package sources (what git tracks plus untracked, non-ignored files) are copied into a
throwaway workspace and built with colcon from the test environment (PyPI's
colcon-common-extensions, pinned in requirements/test.txt). The installed executables, data
files and ament index marker are checked, then the *installed* world runs a few lockstep steps
with nobody else on its domain, so every step ends by its timeout with zero commands.
"""

import json
import os
from pathlib import Path
import subprocess
import sys
import textwrap

import pytest

from conftest import BUILD_TIMEOUT, copy_sources, run_installed, subprocess_env

pytestmark = pytest.mark.ros

PACKAGE = 'flock_swarm'
EXECUTABLES = ('leader', 'agent', 'world', 'sim', 'swarm', 'sweep', 'foxglove_server',
               'robot_agent', 'engine_robots')
#: The world run: demo with 3 agents for 0.06 s at dt = 0.02 s, i.e. steps 0..3, each closed
#: by the step timeout (no agent or leader runs), starting at once.
N_AGENTS = 3
STEPS = 3
WORLD_ARGS = ['-p', 'scenario:=demo', '-p', f'n_agents:={N_AGENTS}', '-p', 'informed.count:=1',
              '-p', 'duration:=0.06', '-p', 'start_timeout:=0.0', '-p', 'step_timeout:=0.05']
#: What the installed world script does (setuptools' entry-point script): load the console
#: script from the first ``flock-swarm`` distribution on sys.path; print where the package and
#: the world's module come from.
IMPORT_CHECK = textwrap.dedent("""\
    import sys
    from importlib.metadata import distribution

    import flock_swarm

    print(flock_swarm.__file__)
    world, = [ep for ep in distribution('flock-swarm').entry_points
              if ep.group == 'console_scripts' and ep.name == 'world']
    print(sys.modules[world.load().__module__].__file__)
""")


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> Path:
    """Copy the sources into ``ws/src/flock_swarm``, run ``colcon build``, return ``ws``."""
    ws = tmp_path_factory.mktemp('colcon') / 'ws'
    copy_sources(ws / 'src' / PACKAGE)
    # An empty COLCON_HOME: no user defaults (~/.colcon) change the build.
    result = subprocess.run(
        [sys.executable, '-m', 'colcon', 'build', '--base-paths', 'src'], cwd=ws,
        env=subprocess_env(COLCON_HOME=str(ws / 'colcon_home')), capture_output=True, text=True,
        timeout=BUILD_TIMEOUT)
    assert result.returncode == 0, f'colcon build failed:\n{result.stdout}\n{result.stderr}'
    (ws / 'build_output.txt').write_text(result.stdout + result.stderr)
    return ws


def test_colcon_build_gives_no_setuptools_warning(workspace):
    # setuptools warns on options it does not know (tests_require was dropped from it); the
    # test dependency is in package.xml (test_depend) and requirements/test.txt.
    output = (workspace / 'build_output.txt').read_text()
    assert 'Unknown distribution option' not in output, output
    assert 'tests_require' not in output, output


def test_colcon_build_takes_the_virtualenv_as_an_ament_prefix(workspace):
    # scripts/env.sh puts .venv on AMENT_PREFIX_PATH (it holds the wheels' ament index) and
    # gives it the local_setup.sh every prefix has: colcon used to warn that it had none.
    output = (workspace / 'build_output.txt').read_text()
    assert "doesn't contain any 'local_setup.*' files" not in output, output


def test_colcon_build_installs_package(workspace):
    prefix = workspace / 'install' / PACKAGE
    for name in EXECUTABLES:
        exe = prefix / 'lib' / PACKAGE / name
        assert exe.is_file(), exe
        assert os.access(exe, os.X_OK), exe
    share = prefix / 'share'
    assert (share / PACKAGE / 'package.xml').is_file()
    assert (share / PACKAGE / 'config' / 'demo.yaml').is_file()
    assert (share / PACKAGE / 'config' / 'sweeps' / 'su2009_fig3.yaml').is_file()
    assert (share / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()


def test_installed_package_shadows_the_working_tree(workspace):
    result = run_installed(workspace, ['python', '-c', IMPORT_CHECK], subprocess_env())
    assert result.returncode == 0, result.stderr
    install = (workspace / 'install' / PACKAGE).resolve()
    paths = [Path(line).resolve() for line in result.stdout.splitlines()]
    assert len(paths) == 2
    for path in paths:
        assert path.is_relative_to(install), path
    shebang = (install / 'lib' / PACKAGE / 'world').read_text().splitlines()[0]
    assert shebang == f'#!{sys.executable}'


def test_colcon_build_compiles_the_c_message_path(workspace):
    check = 'from flock_swarm.nodes import batch; print(batch.extension().__file__)'
    result = run_installed(workspace, ['python', '-c', check], subprocess_env())
    assert result.returncode == 0, result.stderr
    built = Path(result.stdout.strip()).resolve()
    assert built.is_relative_to((workspace / 'install' / PACKAGE).resolve()), built
    assert built.name.startswith('_rclbatch.') and built.suffix == '.so'


def test_installed_world_runs_lockstep_steps(workspace, tmp_path, ros_domain):
    out = tmp_path / 'out'
    env = subprocess_env(ROS_DOMAIN_ID=str(ros_domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    exe = f'install/{PACKAGE}/lib/{PACKAGE}/world'
    result = run_installed(workspace, [exe, '--ros-args', *WORLD_ARGS, '-p', f'out_dir:={out}'],
                           env)
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed'
    assert summary['steps'] == STEPS
    # Steps 0..STEPS each end by the timeout with a zero command for every agent.
    assert summary['missed_commands'] == N_AGENTS * (STEPS + 1)
    assert summary['missed_commands_per_agent'] == [STEPS + 1] * N_AGENTS
    assert summary['leader_missed'] == STEPS + 1
    assert (out / 'bag' / 'metadata.yaml').is_file()


def test_installed_world_rejects_invalid_parameter(workspace, tmp_path, ros_domain):
    env = subprocess_env(ROS_DOMAIN_ID=str(ros_domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    exe = f'install/{PACKAGE}/lib/{PACKAGE}/world'
    out = tmp_path / 'out'
    result = run_installed(workspace, [exe, '--ros-args', *WORLD_ARGS, '-p', 'protocol.h:=1.5',
                                       '-p', f'out_dir:={out}'], env)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith('world: error: protocol.h'), lines[0]
