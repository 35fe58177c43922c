"""The supervisor of ``swarm --processes`` on stand-in processes: real processes, real
signals, real log files, no ROS (the runs through the real nodes are in
test_swarm_signals.py).

A stand-in world notes the first signal it catches (its number and when) in a file and
exits; stand-in leaders and agents run until SIGINT, noting when it came.
"""

import os
from pathlib import Path
import signal
import sys
import time

from flock_swarm.console import FAIL_SIGNAL
from flock_swarm.nodes.supervisor import Supervisor, catches, report_death
from flock_swarm.testing import wait_for

TIMEOUT = 30.0

#: A world: after ARGV[2] seconds it catches the stop signals and FAIL_SIGNAL, then waits
#: for one; it writes "NUMBER MONOTONIC" to ARGV[1] and exits 0.
WORLD = '''
import signal, sys, time
time.sleep(float(sys.argv[2]))
got = []
for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGUSR1):
    signal.signal(sig, lambda number, frame: got.append((number, time.monotonic())))
print('world up', flush=True)
while not got:
    time.sleep(0.01)
open(sys.argv[1], 'w').write(f'{got[0][0]} {got[0][1]}')
print(f'world told {got[0][0]}', flush=True)
'''
#: A leader or an agent: prints ARGV[2] lines, then runs until SIGINT, whose time it writes
#: to ARGV[1] (exit status 130; ARGV[1].ready once it catches it); with ARGV[3] it exits with
#: that status after the lines.
PEER = '''
import signal, sys, time
def stopped(number, frame):
    open(sys.argv[1], 'w').write(str(time.monotonic()))
    sys.exit(130)
signal.signal(signal.SIGINT, stopped)
open(sys.argv[1] + '.ready', 'w').close()
for i in range(int(sys.argv[2])):
    print(f'peer line {i}', flush=True)
if len(sys.argv) > 3:
    sys.exit(int(sys.argv[3]))
while True:
    time.sleep(0.05)
'''


def python(code: str, *args) -> list[str]:
    return [sys.executable, '-c', code, *map(str, args)]


def told(path: Path) -> tuple[int, float]:
    """Return the signal the stand-in world caught and when."""
    number, when = path.read_text().split()
    return int(number), float(when)


def test_a_stop_signal_goes_to_the_world_first_then_to_the_others(tmp_path):
    """SIGTERM to the supervisor: the world gets SIGTERM; only once it has exited are the
    leader and the agents stopped (SIGINT); every process is gone afterwards."""
    sup = Supervisor(tmp_path / 'logs', dict(os.environ))
    peers = [sup.start(name, python(PEER, tmp_path / f'{name}.stopped', 0))
             for name in ('leader', 'agents')]
    world = sup.start('world', python(WORLD, tmp_path / 'world.told', 0))
    wait_for(lambda: catches(world.proc.pid, FAIL_SIGNAL), TIMEOUT, 'the world handlers')
    # And the peers' (on a loaded machine a SIGINT may come before their handler, while
    # Python still starts: a KeyboardInterrupt, status 1).
    wait_for(lambda: all(Path(f'{tmp_path / p.name}.stopped.ready').exists() for p in peers),
             TIMEOUT, 'the peers\' handlers')
    try:
        outcome = sup.watch(world, lambda: signal.SIGTERM)
        world_exit = time.monotonic()
        sup.stop_all()
    finally:
        sup.stop_all(timeout=1.0)
    assert outcome.signal == signal.SIGTERM and outcome.dead is None
    assert told(tmp_path / 'world.told')[0] == signal.SIGTERM
    for peer in peers:
        assert peer.proc.returncode == 130
        assert float((tmp_path / f'{peer.name}.stopped').read_text()) >= world_exit - 0.2
    assert all(child.proc.poll() is not None for child in sup.children)
    assert (tmp_path / 'logs' / 'world.log').read_text().splitlines() == [
        'world up', f'world told {int(signal.SIGTERM)}']


def test_a_dead_child_fails_the_world_and_its_log_tail_is_printed(tmp_path):
    """A child exiting with status 3 ends the run: the world gets FAIL_SIGNAL; the report's
    first line names the child, then come the last lines of its log."""
    sup = Supervisor(tmp_path / 'logs', dict(os.environ))
    sup.start('leader', python(PEER, tmp_path / 'leader.stopped', 0))
    world = sup.start('world', python(WORLD, tmp_path / 'world.told', 0))
    wait_for(lambda: catches(world.proc.pid, FAIL_SIGNAL), TIMEOUT, 'the world handlers')
    agent = sup.start('agent_1', python(PEER, tmp_path / 'agent.stopped', 25, 3))
    try:
        outcome = sup.watch(world, lambda: None)
    finally:
        sup.stop_all()
    assert outcome.dead is agent and outcome.signal is None
    assert told(tmp_path / 'world.told')[0] == FAIL_SIGNAL
    lines = []
    report_death(agent, 57, lines.append)
    assert lines[0] == (f'swarm: error: agent_1 (pid {agent.proc.pid}) exited with status 3 '
                        'during the run; the world ended the run as failed at step 57; the '
                        f'last lines of {tmp_path / "logs" / "agent_1.log"}:')
    assert lines[1:] == [f'  | peer line {i}' for i in range(5, 25)]


def test_a_signal_waits_until_the_world_catches_it(tmp_path):
    """A stop signal that comes while the world is still starting (no handler yet) is sent
    once the world catches it, instead of killing it without a summary."""
    sup = Supervisor(tmp_path / 'logs', dict(os.environ))
    world = sup.start('world', python(WORLD, tmp_path / 'world.told', 1.5))
    try:
        outcome = sup.watch(world, lambda: signal.SIGINT)
    finally:
        sup.stop_all()
    assert outcome.signal == signal.SIGINT and world.proc.returncode == 0
    assert told(tmp_path / 'world.told')[0] == signal.SIGINT


def test_a_child_that_ignores_sigint_is_killed_after_the_bound(tmp_path):
    """stop_all: SIGINT, then SIGKILL after the timeout; the dead child is described."""
    sup = Supervisor(tmp_path / 'logs', dict(os.environ))
    stubborn = sup.start('agents', python(
        'import signal, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n'
        'print("up", flush=True)\nwhile True: time.sleep(0.05)'))
    wait_for(lambda: (tmp_path / 'logs' / 'agents.log').read_text() == 'up\n', TIMEOUT,
             'the child to start')
    started = time.monotonic()
    sup.stop_all(timeout=1.0)
    assert stubborn.proc.returncode == -signal.SIGKILL
    assert 1.0 <= time.monotonic() - started < 10.0
    assert stubborn.exit_text() == 'was killed by SIGKILL'
