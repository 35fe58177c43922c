"""A scenario file that is not text, not YAML or empty: one line and exit status 2 everywhere.

Every entry point that reads a scenario file is run on a binary file, a file that is not YAML
and an empty one: ``sim``, ``swarm``, and the nodes ``world``, ``leader``, ``agent`` and
``agents`` (``-p scenario:=FILE``); ``sim`` and ``swarm``, which start without rclpy, on the
variants too. On the binary file each runs as a real process (all at once); on the others its
``main`` runs in the test's process, its output captured at the file descriptors, C
libraries' included (24 processes on two cores took 42 s).
"""

import importlib
import os
import subprocess
import sys

import pytest

from flock_swarm.nodes.swarm_runner import executable

#: Wall-clock bound of one process [s].
TIMEOUT = 120.0
#: The bad files: name -> (content, what the error line says about it). The first three are
#: given to every entry point, the others to ``sim`` and ``swarm`` only.
BAD_FILES = {
    # Every byte value: 0x80 (offset 128) is the first that cannot start a UTF-8 sequence.
    'binary': (bytes(range(256)) * 4, 'not UTF-8 text (byte 0x80 at offset 128)'),
    'not_yaml': (b'n_agents: [3, 4\nprotocol: {name: su\n', 'invalid YAML at line'),
    'empty': (b'', 'empty (no YAML document)'),
    # Latin-1 text, as an editor set to another encoding would save it.
    'latin1': ('name: démo\n'.encode('latin-1'), 'not UTF-8 text (byte 0xe9 at offset 7)'),
    'nul': (b'\x00\x00\x00\x00', 'invalid YAML'),
    'comments_only': (b'# nothing here yet\n\n', 'empty (no YAML document)'),
}
#: The entry points that get only the first three files (each starts rclpy).
NODES = {'world', 'leader', 'agent', 'agents'}


def commands(path: str, out: str) -> dict[str, list[str]]:
    """Return the command of every entry point, reading the scenario file ``path``."""
    ros = ['--ros-args', '-p', f'scenario:={path}']
    return {
        'sim': [sys.executable, '-m', 'flock_swarm.cli.sim', path, '--out', out],
        'swarm': executable('swarm') + [path, '--out', out],
        'world': executable('world') + ros + ['-p', f'out_dir:={out}'],
        'leader': executable('leader') + ros,
        'agent': executable('agent') + ros + ['-p', 'agent_id:=0'],
        'agents': executable('agents') + ros,
    }


#: The ``main`` of every entry point, as ``module:function``.
MAINS = {'sim': 'flock_swarm.cli.sim:main', 'swarm': 'flock_swarm.cli.swarm:main',
         'world': 'flock_swarm.nodes.world:main', 'leader': 'flock_swarm.nodes.leader:main',
         'agent': 'flock_swarm.nodes.agent:main',
         'agents': 'flock_swarm.nodes.agent:container_main'}
#: The file every entry point reads as a real process; it reads the others in this process.
REAL_PROCESS = 'binary'


def run_main(prog: str, command: list[str], capfd) -> tuple[int, str]:
    """Run entry point ``prog``'s ``main`` in this process on ``command``'s arguments; return
    its exit status and its standard error (as the file descriptor received it)."""
    module, function = MAINS[prog].split(':')
    main = getattr(importlib.import_module(module), function)
    # The arguments after the executable's path; a node's main takes its name first, as argv.
    args = command[command.index('-m') + 2:] if '-m' in command else command[1:]
    capfd.readouterr()
    try:
        status = main([prog, *args] if prog in NODES else args)
    except SystemExit as end:
        status = end.code
    return status, capfd.readouterr().err


def test_every_entry_point_refuses_a_bad_scenario_file_in_one_line(tmp_path, ros_domain,
                                                                   monkeypatch, capfd):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    procs, results = {}, {}
    for number, (kind, (content, _)) in enumerate(BAD_FILES.items()):
        path = tmp_path / f'{kind}.yaml'
        path.write_bytes(content)
        for prog, command in commands(str(path), str(tmp_path / 'out' / kind)).items():
            if number >= 3 and prog in NODES:
                continue
            if kind == REAL_PROCESS:
                procs[kind, prog] = subprocess.Popen(command, env=env,
                                                     stdout=subprocess.DEVNULL,
                                                     stderr=subprocess.PIPE, text=True)
            else:
                results[kind, prog] = run_main(prog, command, capfd)
    for (kind, prog), proc in procs.items():
        try:
            _, stderr = proc.communicate(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            pytest.fail(f'{prog} on the {kind} file did not stop within {TIMEOUT:g} s')
        results[kind, prog] = proc.returncode, stderr
    assert len(procs) == len(MAINS) and len(results) == 24
    failures = []
    for (kind, prog), (status, stderr) in results.items():
        expected = (f'{prog}: error: scenario: {tmp_path / kind}.yaml: {BAD_FILES[kind][1]}')
        if status != 2 or not stderr.startswith(expected) or stderr.count('\n') != 1:
            failures.append(f'{prog} on {kind}: status {status}, stderr {stderr!r}')
    assert not failures, '\n'.join(failures)
    # Nothing was written for a scenario that was never read.
    assert not (tmp_path / 'out').exists() or not any((tmp_path / 'out').rglob('*.mcap'))
