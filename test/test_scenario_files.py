"""A scenario file that is not text, not YAML or empty: one line and exit status 2 everywhere.

Every entry point that reads a scenario file is run as a real process on a binary file, a
file that is not YAML and an empty one: ``sim``, ``swarm``, and the nodes ``world``,
``leader``, ``agent`` and ``agents`` (``-p scenario:=FILE``); ``sim`` and ``swarm``, which
start without rclpy, on the variants too. They run concurrently, so the test costs about one
slow start.
"""

import os
import subprocess
import sys

import pytest

from flock_swarm.nodes.harness import executable

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


def test_every_entry_point_refuses_a_bad_scenario_file_in_one_line(tmp_path, ros_domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    procs = {}
    for number, (kind, (content, _)) in enumerate(BAD_FILES.items()):
        path = tmp_path / f'{kind}.yaml'
        path.write_bytes(content)
        for prog, command in commands(str(path), str(tmp_path / 'out' / kind)).items():
            if number >= 3 and prog in NODES:
                continue
            procs[kind, prog] = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                                                 stderr=subprocess.PIPE, text=True)
    failures = []
    for (kind, prog), proc in procs.items():
        try:
            _, stderr = proc.communicate(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            pytest.fail(f'{prog} on the {kind} file did not stop within {TIMEOUT:g} s')
        expected = (f'{prog}: error: scenario: {tmp_path / kind}.yaml: {BAD_FILES[kind][1]}')
        if proc.returncode != 2 or not stderr.startswith(expected) or stderr.count('\n') != 1:
            failures.append(f'{prog} on {kind}: status {proc.returncode}, stderr {stderr!r}')
    assert not failures, '\n'.join(failures)
    # Nothing was written for a scenario that was never read.
    assert not (tmp_path / 'out').exists() or not any((tmp_path / 'out').rglob('*.mcap'))
