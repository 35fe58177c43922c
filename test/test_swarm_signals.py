"""Signals finalise, everywhere, and ``swarm --processes`` supervises its children (issue 23,
items 2 and 3): real processes, real signals (``os.kill``, ``os.killpg``), bounded waits.

Each command runs in a session of its own, so that a signal to its process group reaches it
and its children only; every pid of the group is gathered before the signal and must be gone
after the command exits (no orphan). The exit statuses are the console's table
(:data:`flock_swarm.console.EXIT_SIGNAL`).
"""

import json
import os
from pathlib import Path
import select
import signal
import subprocess
import time

import numpy as np
import pytest

from flock_swarm.bag import BagReader
from flock_swarm.console import EXIT_SIGNAL
from flock_swarm.nodes.swarm_runner import executable, resolve_scenario, run_in_process
from flock_swarm.nodes.supervisor import catches
from flock_swarm.testing import wait_for

pytestmark = pytest.mark.ros

TIMEOUT = 120.0
#: A small swarm that would fly for a long time: it is stopped by the test.
LONG = ['n_agents=2', 'informed.count=1', 'dt=0.05', 'duration=1000',
        'initial.position_box=[[0, 5], [0, 5]]']


def sets(overrides: list[str]) -> list[str]:
    return [arg for item in overrides for arg in ('--set', item)]


def start(command: list[str]) -> subprocess.Popen:
    """Start ``command`` in a session (and process group) of its own."""
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def _stat(pid: int) -> list[str] | None:
    """Return the fields of ``/proc/PID/stat`` after the command name (state first)."""
    try:
        return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return None


def group_pids(pgid: int) -> set[int]:
    """Return the pids of the live processes of process group ``pgid``."""
    found = set()
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            fields = _stat(int(entry.name))
            if fields is not None and int(fields[2]) == pgid and fields[0] != 'Z':
                found.add(int(entry.name))
    return found


def alive(pid: int) -> bool:
    """Return whether ``pid`` is a live process (a zombie is not)."""
    fields = _stat(pid)
    return fields is not None and fields[0] != 'Z'


def stepping(out: Path) -> bool:
    """Return whether the world's bag holds more than its first chunk's header."""
    mcap = out / 'bag' / 'bag_0.mcap'
    return mcap.is_file() and mcap.stat().st_size > 20_000


def finish(proc: subprocess.Popen) -> str:
    """Wait (bounded) for ``proc``; return its stderr; kill its group if it hangs."""
    try:
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return err


def assert_finalised(out: Path, status: str = 'interrupted') -> dict:
    """The run's outputs are complete: a finalised bag, the summary with ``status``, the
    time series, and no temporary file."""
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == status and summary['steps'] > 0, summary
    assert (out / 'bag' / 'metadata.yaml').is_file()
    reader = BagReader(out / 'bag')
    assert not reader.recovered  # finalised: summary section and index
    assert reader.message_counts()['/agent_0/odom'] >= summary['steps']
    with np.load(out / 'timeseries.npz') as series:
        assert len(series['t']) > 0
    assert not list(out.glob('.timeseries-*')) and not list(out.glob('*.tmp'))
    return summary


# -- swarm --processes: logs and supervision ---------------------------------------------------

@pytest.mark.parametrize('container', [True, False], ids=['container', 'agent-per-process'])
def test_swarm_processes_logs_every_child(tmp_path, ros_domain, container):
    """Each child's output goes to OUT/logs/<name>.log: world, leader, agents or agent_<i>."""
    out = tmp_path / 'run'
    res = subprocess.run(executable('swarm') + [
        'demo', *sets(LONG[:-2] + ['duration=1']), '--processes', '--out', str(out),
        '--no-plots', '--domain-id', str(ros_domain)] + (['--container'] if container else []),
        capture_output=True, text=True, timeout=TIMEOUT)
    assert res.returncode == 0, res.stderr[-3000:]
    hosts = ['agents'] if container else ['agent_0', 'agent_1']
    logs = out / 'logs'
    assert sorted(p.name for p in logs.iterdir()) == sorted(
        f'{name}.log' for name in ['world', 'leader', *hosts])
    for name in ['leader', *hosts]:
        assert 'the world finished its run (completed); exiting' in \
            (logs / f'{name}.log').read_text(), name
    assert json.loads((out / 'summary.json').read_text())['status'] == 'completed'


def swarm_under_way(out: Path, domain: int, container: bool
                    ) -> tuple[subprocess.Popen, set[int]]:
    """Start ``swarm demo --processes`` (LONG, two agents) into ``out``; return it and the
    pids of its process group once every child runs and the world steps."""
    proc = start(executable('swarm') + [
        'demo', *sets(LONG), '--processes', '--out', str(out), '--no-plots',
        '--domain-id', str(domain)] + (['--container'] if container else []))
    children = 3 if container else 4
    try:
        wait_for(lambda: len(group_pids(proc.pid)) == 1 + children, TIMEOUT,
                 f'swarm and its {children} children')
        wait_for(lambda: stepping(out), TIMEOUT, 'the world to step')
    except BaseException:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return proc, group_pids(proc.pid)


@pytest.mark.parametrize('sig, group', [
    (signal.SIGINT, False), (signal.SIGTERM, False), (signal.SIGINT, True),
    (signal.SIGHUP, False)],
    ids=['sigint-to-swarm', 'sigterm-to-swarm', 'sigint-to-group', 'sighup-to-swarm'])
def test_swarm_processes_signal_stops_every_child(tmp_path, ros_domain, sig, group):
    """``swarm --processes --container`` stopped by a signal to it alone or to its group:
    the world finalises bag and summary, swarm prints the summary and exits with the
    signal's status, and every child's pid is gone."""
    out = tmp_path / 'run'
    proc, pids = swarm_under_way(out, ros_domain, container=True)
    try:
        (os.killpg if group else os.kill)(proc.pid, sig)
    finally:
        err = finish(proc)
    assert proc.returncode == EXIT_SIGNAL[sig], err[-3000:]
    assert 'Traceback' not in err and 'KeyboardInterrupt' not in err, err[-3000:]
    summary = assert_finalised(out)
    assert f'[swarm] interrupted at t = {summary["t_final"]:g} s' in err
    assert [pid for pid in pids if alive(pid)] == []


def test_swarm_agent_processes_sigterm_stops_every_child(tmp_path, ros_domain):
    """The same with a process per agent (no --container), SIGTERM to swarm alone."""
    out = tmp_path / 'run'
    proc, pids = swarm_under_way(out, ros_domain, container=False)
    try:
        os.kill(proc.pid, signal.SIGTERM)
    finally:
        err = finish(proc)
    assert proc.returncode == EXIT_SIGNAL[signal.SIGTERM], err[-3000:]
    assert_finalised(out)
    assert [pid for pid in pids if alive(pid)] == []


def test_swarm_processes_killed_child_fails_the_run(tmp_path, ros_domain):
    """The agents' process SIGKILLed mid-run: the run ends (status failed, exit status 1)
    with the bag and summary finalised; the first error line names the dead child and the
    step; no child survives."""
    out = tmp_path / 'run'
    proc, pids = swarm_under_way(out, ros_domain, container=True)
    try:
        agents = [pid for pid in pids
                  if b'/agents\0' in Path(f'/proc/{pid}/cmdline').read_bytes()]
        assert len(agents) == 1, agents
        os.kill(agents[0], signal.SIGKILL)
    finally:
        err = finish(proc)
    assert proc.returncode == 1, err[-3000:]
    summary = assert_finalised(out, 'failed')
    errors = [line for line in err.splitlines() if line.startswith('swarm: error: ')]
    log = out / 'logs' / 'agents.log'
    # The log's tail follows, or the line says the log is empty (never a colon and nothing).
    assert errors[0] == (
        f'swarm: error: agents (pid {agents[0]}) was killed by SIGKILL during the run; the '
        f'world ended the run as failed at step {summary["steps"]}; '
        + (f'the last lines of {log}:' if log.read_text() else f'its log {log} is empty')
    ), err[-3000:]
    assert [pid for pid in pids if alive(pid)] == []


# -- one-process swarm, sim, the world -----------------------------------------------------------

@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['sigint', 'sigterm'])
def test_one_process_swarm_signal_finalises(tmp_path, ros_domain, sig):
    """SIGINT / SIGTERM to a one-process swarm: a finalised bag, summary.json with status
    interrupted, the time series, no temporary file; the signal's exit status."""
    out = tmp_path / 'run'
    proc = start(executable('swarm') + ['demo', *sets(LONG), '--out', str(out), '--no-plots',
                                        '--domain-id', str(ros_domain)])
    try:
        wait_for(lambda: stepping(out), TIMEOUT, 'the world to step')
        os.kill(proc.pid, sig)
    finally:
        err = finish(proc)
    assert proc.returncode == EXIT_SIGNAL[sig], err[-3000:]
    assert 'Traceback' not in err, err[-3000:]
    assert_finalised(out)
    assert err.splitlines()[-1] == f'[swarm] wrote {out / "bag"}, {out / "summary.json"}, ' \
        f'{out / "timeseries.npz"}'


def read_line(proc: subprocess.Popen, text: str) -> str:
    """Read ``proc``'s stderr until a line holding ``text`` (bounded)."""
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stderr], [], [], 0.1)
        if ready:
            line = proc.stderr.readline()
            if text in line:
                return line
            if not line:
                break
    raise AssertionError(f'no line with {text!r} on stderr')


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['sigint', 'sigterm'])
def test_sim_signal_finalises(tmp_path, sig):
    """SIGINT / SIGTERM to sim mid-run: summary.json (interrupted) and timeseries.npz up to
    then, no temporary file, the signal's exit status."""
    out = tmp_path / 'sim'
    proc = start(executable('sim') + ['demo', '--set', 'duration=100000', '--out', str(out)])
    try:
        read_line(proc, '[sim] t = ')  # the loop is under way (a progress line)
        os.kill(proc.pid, sig)
    finally:
        err = finish(proc)
    assert proc.returncode == EXIT_SIGNAL[sig], err
    assert 'Traceback' not in err, err
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'interrupted' and summary['steps'] > 0
    with np.load(out / 'timeseries.npz') as series:
        assert series['t'][-1] == pytest.approx(summary['t_final'])
    written = sorted(p.name for p in out.iterdir())
    assert written == ['scenario.json', 'summary.json', 'timeseries.npz']


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['sigint', 'sigterm'])
@pytest.mark.parametrize('moment', ['building', 'start-wait'])
def test_world_stopped_before_its_first_step(tmp_path, ros_domain, sig, moment):
    """A world alone (nobody to start with) stopped while it builds its node or in its start
    wait: summary.json with status interrupted and null measures, no bag (said in one line),
    no temporary file, the signal's exit status."""
    out = tmp_path / 'world'
    scenario = resolve_scenario('demo', LONG, None, tmp_path / 'resolved')
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    proc = subprocess.Popen(executable('world') + ['--ros-args', '-p', f'scenario:={scenario}',
                                                   '-p', f'out_dir:={out}'],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        # Its handlers are installed first thing in main, before the node is built; the bag
        # directory exists once the node is built and the world waits for the others.
        wait_for(lambda: catches(proc.pid, signal.SIGTERM), TIMEOUT, 'the handlers')
        if moment == 'start-wait':
            wait_for(lambda: (out / 'bag').is_dir(), TIMEOUT, 'the start wait')
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == EXIT_SIGNAL[sig], err
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'interrupted' and summary['steps'] == 0
    assert summary['t_final'] is None and summary['eta'] is None and summary['bag'] is None
    assert sorted(p.name for p in out.iterdir()) == ['scenario.json', 'summary.json']
    said = [line for line in err.splitlines() if 'nothing was recorded' in line]
    assert len(said) == 1 and said[0].endswith(
        f'the run ended (interrupted) before its first step: nothing was recorded, no bag '
        f'written; {out / "summary.json"} says so'), err


# -- one exit status per signal, across commands -------------------------------------------------

@pytest.fixture(scope='module')
def small_bag(tmp_path_factory) -> Path:
    """A bag of a few hundred steps (an analysis of it takes seconds)."""
    from flock_swarm.nodes.swarm_runner import unique_domain
    out = tmp_path_factory.mktemp('bag') / 'run'
    scenario = resolve_scenario('demo', LONG[:-2] + ['duration=30'], None, out)
    summary = run_in_process(scenario, out, domain_id=unique_domain(), timeout=TIMEOUT)
    assert summary['status'] == 'completed'
    return out / 'bag'


def test_analyze_sigterm_exit_status(small_bag, tmp_path):
    """SIGTERM to analyze: one line, status 143 (as 130 after Ctrl-C)."""
    proc = start(executable('analyze') + [str(small_bag), '--out', str(tmp_path / 'an')])
    try:
        wait_for(lambda: catches(proc.pid, signal.SIGTERM), TIMEOUT, 'the handlers')
        os.kill(proc.pid, signal.SIGTERM)
    finally:
        err = finish(proc)
    assert proc.returncode == EXIT_SIGNAL[signal.SIGTERM], err
    assert err.splitlines()[-1] == 'analyze: interrupted'


@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGHUP], ids=['sigterm', 'sighup'])
def test_replay_signal_exit_status(small_bag, ros_domain, sig):
    """SIGTERM / SIGHUP stop replay as Ctrl-C does, with the signal's status."""
    proc = subprocess.Popen(executable('replay') + [str(small_bag), '--loop'],
                            env=dict(os.environ, ROS_DOMAIN_ID=str(ros_domain)),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        read_line(proc, '[RUNNING]')
        os.kill(proc.pid, sig)
    finally:
        err = finish(proc)
    assert proc.returncode == EXIT_SIGNAL[sig], err
    assert 'Traceback' not in err and err.splitlines()[-1].startswith('[replay] stopped: ')


# -- one run per domain ---------------------------------------------------------------------

def test_a_second_run_on_a_busy_domain_is_refused_at_once(tmp_path, ros_domain, monkeypatch,
                                                          capsys):
    """Beside a running one-process swarm, ``swarm --processes --container`` and ``replay
    --clock`` on its domain are refused with one line and status 2 before they start a node
    or write a file (the second swarm's world used to zero every command while its agents
    followed the first world's clock); the first run goes on and finalises."""
    from flock_swarm.cli.replay import main as replay
    from flock_swarm.cli.swarm import main as swarm
    first = tmp_path / 'first'
    proc = start(executable('swarm') + ['demo', *sets(LONG), '--out', str(first), '--no-plots',
                                        '--domain-id', str(ros_domain)])
    try:
        wait_for(lambda: stepping(first), TIMEOUT, 'the first world to step')
        second = tmp_path / 'second'
        status = swarm(['demo', '--processes', '--container', '--out', str(second),
                        '--domain-id', str(ros_domain)])
        swarm_err = capsys.readouterr().err
        monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
        replay_status = replay([str(first / 'bag'), '--clock'])
        replay_err = capsys.readouterr().err
        os.kill(proc.pid, signal.SIGINT)
    finally:
        err = finish(proc)
    busy = (f'domain {ros_domain} is in use by a run of this machine (swarm demo, pid '
            f'{proc.pid}): give each run a domain of its own\n')
    assert status == 2 and swarm_err == f'swarm: error: --domain-id: {busy}', swarm_err
    assert not second.exists()
    assert replay_status == 2 and replay_err == f'replay: error: ROS_DOMAIN_ID: {busy}'
    assert proc.returncode == EXIT_SIGNAL[signal.SIGINT], err[-3000:]
    assert_finalised(first)


def world_of(pids: set[int]) -> int:
    """Return the pid of the world among a run's processes."""
    worlds = [pid for pid in pids if b'/world\0' in Path(f'/proc/{pid}/cmdline').read_bytes()]
    assert len(worlds) == 1, worlds
    return worlds[0]


def test_sigint_to_the_world_alone_says_why_swarm_exits_1(tmp_path, ros_domain):
    """SIGINT to the world process only: the run is finalised as interrupted and swarm exits
    1 (the run did not complete, swarm was not signalled) with a last line saying why (it
    said nothing)."""
    out = tmp_path / 'run'
    proc, pids = swarm_under_way(out, ros_domain, container=True)
    try:
        os.kill(world_of(pids), signal.SIGINT)
    finally:
        err = finish(proc)
    assert proc.returncode == 1, err[-3000:]
    summary = assert_finalised(out)
    assert err.splitlines()[-1] == (
        'swarm: error: the world was stopped by a signal sent to it, not to swarm; the run is '
        f'interrupted at t = {summary["t_final"]:g} s'), err[-3000:]
    assert [pid for pid in pids if alive(pid)] == []


def test_sigkill_of_the_world_names_how_it_died_and_its_log(tmp_path, ros_domain):
    """SIGKILL to the world: besides 'wrote no summary.json', one line says the world was
    killed by SIGKILL, followed by its log's last lines."""
    out = tmp_path / 'run'
    proc, pids = swarm_under_way(out, ros_domain, container=True)
    world = world_of(pids)
    try:
        os.kill(world, signal.SIGKILL)
    finally:
        err = finish(proc)
    assert proc.returncode == 1, err[-3000:]
    lines = err.splitlines()
    log = out / 'logs' / 'world.log'
    # Its log's tail follows, or the line says the log is empty (what the world had written
    # may have been in its buffers).
    tail = log.read_text().splitlines()[-20:]
    said = (f'swarm: error: world (pid {world}) was killed by SIGKILL before it wrote '
            f'{out / "summary.json"}; '
            + (f'the last lines of {log}:' if tail else f'its log {log} is empty'))
    assert said in lines, err[-3000:]
    first = lines.index(said)
    assert lines[first + 1:first + 1 + len(tail)] == [f'  | {line}' for line in tail]
    assert lines[-1] == f'swarm: error: the world wrote no {out / "summary.json"}'
    assert [pid for pid in pids if alive(pid)] == []


def test_a_dead_child_with_an_empty_log_is_said_so(tmp_path, capsys):
    """'the last lines of agent_1.log:' was followed by nothing for a child that wrote none."""
    from flock_swarm.nodes.supervisor import Child, report_death
    log = tmp_path / 'agent_1.log'
    log.write_text('')
    child = Child('agent_1', subprocess.Popen(['sh', '-c', 'exit 3']), log)
    child.proc.wait(timeout=TIMEOUT)
    report_death(child, 12)
    assert capsys.readouterr().err == (
        f'swarm: error: agent_1 (pid {child.proc.pid}) exited with status 3 during the run; '
        f'the world ended the run as failed at step 12; its log {log} is empty\n')
