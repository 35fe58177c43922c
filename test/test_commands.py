"""Commands over libraries: every command a module of flock_swarm.cli, imported by no library.

The console scripts of the commands point into :mod:`flock_swarm.cli`; the node executables
keep their ``main`` in their node module; no module outside :mod:`flock_swarm.cli` imports
it (``python -m flock_swarm.reproduce``'s ``__main__`` is itself a way in to a command).
"""

import ast
import json
import os
from pathlib import Path
import subprocess
import sys

import pytest

from conftest import imported_modules

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / 'flock_swarm'
#: Modules that run a command when executed (``python -m``): entry points, not libraries.
ENTRY_MODULES = {PACKAGE / 'reproduce' / '__main__.py'}
#: A small demo whose dt (0.2 s) is beyond its velocity-consensus bound (about 0.098 s).
UNSTABLE = ['--set', 'n_agents=3', '--set', 'informed.count=1', '--set', 'duration=1',
            '--set', 'dt=0.2']
#: Wall-clock bound of one command.
TIMEOUT = 120.0


def console_scripts() -> dict[str, str]:
    """Return the console scripts of setup.py, name to ``module:function``."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    entries = [ast.literal_eval(e) for e in value.elts]
                    return dict(tuple(part.strip() for part in e.split('=')) for e in entries)
    raise AssertionError('setup.py declares no console_scripts')


#: The commands and their ``module:function`` (setup.py's console scripts into flock_swarm.cli).
COMMANDS = {name: target for name, target in console_scripts().items()
            if target.startswith('flock_swarm.cli.')}


def test_no_library_imports_a_command():
    offenders = []
    for path in sorted(PACKAGE.rglob('*.py')):
        if (PACKAGE / 'cli') in path.parents or path in ENTRY_MODULES:
            continue
        for name in imported_modules(path):
            if name == 'flock_swarm.cli' or name.startswith('flock_swarm.cli.'):
                offenders.append(f'{path.relative_to(ROOT)} imports {name}')
    assert offenders == []


def test_every_command_is_a_module_of_the_cli_package():
    scripts = console_scripts()
    assert COMMANDS == {name: f'flock_swarm.cli.{name}:main' for name in COMMANDS}
    assert set(COMMANDS) >= {'sim', 'swarm', 'sweep', 'analyze', 'replay'}
    for name, target in scripts.items():
        if name not in COMMANDS:
            assert target.startswith('flock_swarm.nodes.'), (name, target)
    modules = {path.stem for path in (PACKAGE / 'cli').glob('*.py')} - {'__init__'}
    assert modules == set(COMMANDS) | {'reproduce'}


def test_the_package_reads_its_commands_from_setup_py():
    """The swarm runner and the docs' examples take the commands from setup.py's console scripts
    (as installed): one list, no copy to keep in step."""
    from flock_swarm.console import commands, executables
    from flock_swarm.nodes.swarm_runner import executable
    assert executables() == console_scripts()
    assert commands() == {name: target.split(':')[0] for name, target in COMMANDS.items()}
    assert executable('no_such_command')[-1] == 'flock_swarm.nodes.no_such_command'


def test_every_exit_status_is_named_once_in_the_console():
    """The exit statuses are console.py's table alone (status 1 had four names: sim's
    EXIT_DIVERGED and EXIT_FAILED, analyze's EXIT_VERIFY_FAILED beside EXIT_FAILURE)."""
    named = sorted(f'{path.relative_to(PACKAGE)}: {line.strip()}'
                   for path in PACKAGE.rglob('*.py') if path.name != 'console.py'
                   for line in path.read_text().splitlines() if line.startswith('EXIT_'))
    assert named == []


def test_the_commands_share_the_console_plumbing():
    """Exit statuses and argument errors come from flock_swarm.console, not from each other."""
    for path in sorted((PACKAGE / 'cli').glob('*.py')):
        if path.stem == '__init__':
            continue
        imported = imported_modules(path)
        assert 'flock_swarm.console' in imported, path.name
        assert not any(name.startswith('flock_swarm.cli.') for name in imported), path.name


def command(name: str, args: list[str]) -> subprocess.CompletedProcess:
    """Run ``python -m flock_swarm.cli.NAME ARGS``."""
    return subprocess.run([sys.executable, '-m', f'flock_swarm.cli.{name}', *args],
                          capture_output=True, text=True, timeout=TIMEOUT)


def test_swarm_refuses_the_dt_sim_refuses_with_the_same_line(tmp_path):
    sim = command('sim', ['demo', *UNSTABLE, '--out', str(tmp_path / 'sim'), '--quiet'])
    swarm = command('swarm', ['demo', *UNSTABLE, '--out', str(tmp_path / 'swarm')])
    assert sim.returncode == swarm.returncode == 2
    assert sim.stderr.startswith('sim: error: dt: 0.2 exceeds the stability bound')
    assert swarm.stderr == sim.stderr.replace('sim: ', 'swarm: ', 1)
    assert not (tmp_path / 'swarm' / 'bag').exists()


@pytest.mark.ros
def test_swarm_allow_unstable_runs_it_as_sim_allow_unstable_does(tmp_path, ros_domain):
    out = tmp_path / 'swarm'
    run = command('swarm', ['demo', *UNSTABLE, '--allow-unstable', '--no-plots', '--no-record',
                            '--out', str(out), '--domain-id', str(ros_domain)])
    assert run.returncode == 0, run.stderr[-2000:]
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    sim = command('sim', ['demo', *UNSTABLE, '--allow-unstable', '--out', str(tmp_path / 'sim'),
                          '--quiet'])
    assert sim.returncode == 0, sim.stderr
    want = json.loads((tmp_path / 'sim' / 'summary.json').read_text())
    assert summary['steps'] == want['steps'] and summary['eta'] == want['eta']


@pytest.mark.ros
@pytest.mark.parametrize('node', ['world', 'leader', 'agent', 'agents'])
def test_every_node_refuses_the_dt_sim_refuses_with_the_same_line(tmp_path, node, ros_domain):
    sim = command('sim', ['demo', *UNSTABLE, '--out', str(tmp_path / 'sim'), '--quiet'])
    params = ['-p', 'scenario:=demo', '-p', 'n_agents:=3', '-p', 'informed.count:=1',
              '-p', 'duration:=1.0', '-p', 'dt:=0.2']
    if node == 'world':
        params += ['-p', f'out_dir:={tmp_path / "world"}']
    run = subprocess.run([node, '--ros-args', *params], capture_output=True, text=True,
                         timeout=TIMEOUT, env=dict(os.environ, ROS_DOMAIN_ID=str(ros_domain)))
    assert sim.returncode == run.returncode == 2, run.stderr
    assert run.stderr == sim.stderr.replace('sim: ', f'{node}: ', 1)
    assert not (tmp_path / 'world').exists()


@pytest.mark.parametrize('name', ['swarm', 'replay', 'world', 'agents'])
def test_a_ros_domain_id_that_is_no_number_is_one_line(tmp_path, monkeypatch, capsys, name):
    """``ROS_DOMAIN_ID=abc``: one line naming the variable and status 2, from the commands
    (swarm raised ValueError while it built its parser) and the nodes (rcl's RCLError)."""
    from importlib import import_module
    monkeypatch.setenv('ROS_DOMAIN_ID', 'abc')
    if name in ('swarm', 'replay'):
        main = import_module(f'flock_swarm.cli.{name}').main
        args = ['demo', '--out', str(tmp_path / 'out')] if name == 'swarm' else [
            str(tmp_path / 'bag')]
    else:
        module = import_module(f'flock_swarm.nodes.{name.rstrip("s")}')
        main = module.main if name == 'world' else module.container_main
        args = [name, '--ros-args', '-p', 'scenario:=demo', '-p',
                f'out_dir:={tmp_path / "out"}']
    status = main(args)
    captured = capsys.readouterr()
    assert status == 2 and captured.out == ''
    assert captured.err == (f"{name}: error: ROS_DOMAIN_ID: must be a domain id in [0, 232], "
                            "got 'abc'\n")
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('option, value, line', [
    ('--rate', '1e-300', '--rate: must be >= 0.001 (a bag second would last more than 1000 s), '
     'got 1e-300'),
    ('--delay', '1e300', '--delay: must be at most 3600 s, got 1e+300'),
    ('--wait-timeout', 'inf', '--wait-timeout: must be at most 3600 s, got inf'),
    ('--start-offset', '1e300', "--start-offset: must be at most 9e+09 s (the nanoseconds of a "
     "bag's time axis), got 1e+300"),
], ids=['rate', 'delay', 'wait-timeout', 'start-offset'])
def test_replay_refuses_timings_it_could_never_play(tmp_path, capsys, option, value, line):
    """A replay that would wait 1e300 s (or overflow the bag's time axis: OverflowError
    before) is refused with one line and status 2."""
    from flock_swarm.cli.replay import main
    assert main([str(tmp_path / 'bag'), option, value]) == 2
    assert capsys.readouterr().err == f'replay: error: {line}\n'


@pytest.mark.ros
def test_swarm_no_record_runs_beside_a_bag_it_leaves_alone(tmp_path, ros_domain):
    """``--no-record`` writes no bag, so one already in ``--out`` is no reason to refuse (it
    was); the bag is left as it was and not listed among the files written."""
    out = tmp_path / 'run'
    (out / 'bag').mkdir(parents=True)
    (out / 'bag' / 'bag_0.mcap').write_bytes(b'an earlier recording')
    run = command('swarm', ['demo', *UNSTABLE, '--allow-unstable', '--no-plots', '--no-record',
                            '--out', str(out), '--domain-id', str(ros_domain)])
    assert run.returncode == 0, run.stderr[-2000:]
    assert (out / 'bag' / 'bag_0.mcap').read_bytes() == b'an earlier recording'
    assert run.stderr.splitlines()[-1] == (f'[swarm] wrote {out / "summary.json"}, '
                                           f'{out / "timeseries.npz"}')


def test_env_sh_never_deletes_a_venv_it_did_not_make(tmp_path):
    """A ``.venv`` that cannot be executed and carries no stamp of scripts/env.sh (somebody
    else's) is left alone: one line and status 1 (it was removed and rebuilt)."""
    root = tmp_path / 'checkout'
    (root / 'scripts').mkdir(parents=True)
    (root / 'scripts' / 'env.sh').write_text((ROOT / 'scripts' / 'env.sh').read_text())
    venv = root / '.venv'
    (venv / 'bin').mkdir(parents=True)
    (venv / 'bin' / 'python').write_text('not an interpreter\n')
    (venv / 'notes.txt').write_text('my own files\n')
    env = {key: value for key, value in os.environ.items()
           if key not in ('VIRTUAL_ENV', 'PYTHON')}
    env['PATH'] = os.pathsep.join(part for part in env['PATH'].split(os.pathsep)
                                  if not part.startswith(str(ROOT / '.venv')))
    run = subprocess.run(['bash', '-c', 'source scripts/env.sh'], cwd=root, env=env,
                         capture_output=True, text=True, timeout=TIMEOUT)
    assert run.returncode == 1, run.stderr
    assert run.stderr.splitlines()[-1] == (
        f'[env] error: {venv} cannot be used (broken) and was not made by scripts/env.sh (no '
        '.flock_swarm_stamp in it): move it away or remove it yourself, then run again')
    assert (venv / 'notes.txt').read_text() == 'my own files\n'


@pytest.mark.parametrize('command', ['analyze', 'replay', 'sim', 'sweep'])
def test_every_command_with_a_quiet_option_takes_its_short_form(command):
    """``analyze -q`` was refused while ``replay -q`` worked: the short form is the same
    option everywhere."""
    from importlib import import_module
    parser = import_module(f'flock_swarm.cli.{command}').build_parser()
    assert parser.parse_args(['-q', 'ARG']).quiet is True
    assert parser.parse_args(['ARG']).quiet is False
