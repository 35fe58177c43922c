"""Clean starts and stops of the node processes: no FATAL line and no traceback at the end of
a run or at a signal, and leader and agents started by hand end with the world's run."""

import json
import os
import signal
import subprocess

import pytest

from flock_swarm.console import EXIT_SIGNAL
from flock_swarm.nodes.harness import executable, resolve_scenario
from flock_swarm.testing import wait_for

RUN_TIMEOUT = 240.0
SMALL = ['n_agents=2', 'informed.count=1', 'dt=0.05', 'initial.position_box=[[0, 5], [0, 5]]']


def start_all(scenario, out, env, logs, agents: int) -> list[subprocess.Popen]:
    """Start leader, ``agents`` agent processes and the world, each with its own log file;
    return the processes, the world last."""
    ros_args = ['--ros-args', '-p', f'scenario:={scenario}']
    commands = [executable('leader') + ros_args]
    commands += [executable('agent') + ros_args + ['-p', f'agent_id:={i}']
                 for i in range(agents)]
    commands.append(executable('world') + ros_args + ['-p', f'out_dir:={out}'])
    procs = []
    for i, command in enumerate(commands):
        log = open(logs / f'node{i}.log', 'w')
        procs.append(subprocess.Popen(command, env=env, stdout=log, stderr=log))
        log.close()
    return procs


def assert_clean(logs) -> None:
    """No log of ``logs`` holds a FATAL line or a traceback."""
    for path in sorted(logs.glob('*.log')):
        text = path.read_text()
        assert 'FATAL' not in text and 'Traceback' not in text, f'{path.name}:\n{text[-3000:]}'


def reap(procs) -> None:
    """Kill what is left (after a failed assertion) and wait for every process."""
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def test_nodes_started_by_hand_end_with_the_run(tmp_path, ros_domain):
    """A completed run: the world announces its end on swarm/status, the leader and each
    agent process exit by themselves with status 0; nobody logs FATAL or a traceback."""
    out = tmp_path / 'run'
    scenario = resolve_scenario('demo', SMALL + ['duration=2'], None, out)
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    procs = start_all(scenario, out, env, tmp_path, agents=2)
    try:
        # No signal: every process ends by itself.
        statuses = [proc.wait(timeout=RUN_TIMEOUT) for proc in procs]
    finally:
        reap(procs)
    assert statuses == [0] * len(procs), statuses
    assert json.loads((out / 'summary.json').read_text())['status'] == 'completed'
    assert_clean(tmp_path)
    leader_log = (tmp_path / 'node0.log').read_text()
    assert 'the world finished its run (completed); exiting' in leader_log


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_to_every_node_stops_them_cleanly(tmp_path, ros_domain, sig):
    """SIGINT / SIGTERM to every process mid-run (as Ctrl-C in a launch terminal): the
    signal's exit status (130, 143) from every node, no FATAL, no traceback; the world keeps
    what it recorded."""
    out = tmp_path / 'run'
    scenario = resolve_scenario('demo', SMALL + ['duration=1000'], None, out)
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    procs = start_all(scenario, out, env, tmp_path, agents=2)
    mcap = out / 'bag' / 'bag_0.mcap'
    try:
        wait_for(lambda: mcap.is_file() and mcap.stat().st_size > 20_000, RUN_TIMEOUT,
                 'the world to step')
        for proc in procs:
            proc.send_signal(sig)
        statuses = [proc.wait(timeout=60) for proc in procs]
    finally:
        reap(procs)
    assert statuses == [EXIT_SIGNAL[sig]] * len(procs), statuses
    assert json.loads((out / 'summary.json').read_text())['status'] == 'interrupted'
    assert_clean(tmp_path)


def test_swarm_processes_run_ends_cleanly(tmp_path, ros_domain):
    """``swarm SCENARIO --processes --container``: status 0, no FATAL, no traceback."""
    out = tmp_path / 'run'
    sets = [arg for item in SMALL + ['duration=2'] for arg in ('--set', item)]
    res = subprocess.run(executable('swarm') + ['demo', *sets, '--processes', '--container',
                                                '--out', str(out), '--no-plots',
                                                '--domain-id', str(ros_domain)],
                         capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert res.returncode == 0, res.stderr[-3000:]
    assert 'FATAL' not in res.stderr and 'Traceback' not in res.stderr, res.stderr[-3000:]
    assert json.loads((out / 'summary.json').read_text())['status'] == 'completed'
