"""Clean starts and stops of the node processes: no FATAL line and no traceback at the end of
a run or at a signal, and leader and agents started by hand end with the world's run."""

import json
import os
import signal
import subprocess
import time

import pytest

from flock_swarm.console import EXIT_SIGNAL
from flock_swarm.nodes.swarm_runner import executable, resolve_scenario
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


def launch_processes(tmp_path, out, env) -> list[subprocess.Popen]:
    """Start the processes of ``ros2 launch flock_swarm swarm_launch.py n_agents:=4
    informed_count:=2 overrides:=...`` as launch_ros starts them (the launch plan's
    executables, node names and parameters in a params file), each with its own log in
    ``tmp_path``; the world first."""
    import yaml

    from flock_swarm.launch_plan import swarm_processes
    specs = swarm_processes(n_agents='4', informed_count='2', out_dir=str(out),
                            overrides='duration=2; dt=0.05')
    procs = []
    for spec in specs:
        params = tmp_path / f'{spec.name}.params.yaml'
        params.write_text(yaml.safe_dump({'/**': {'ros__parameters': spec.parameters}}))
        log = open(tmp_path / f'{spec.name}.log', 'w')
        procs.append(subprocess.Popen(
            executable(spec.executable) + ['--ros-args', '-r', f'__node:={spec.name}',
                                           '--params-file', str(params)],
            env=env, stdout=log, stderr=log))
        log.close()
    assert [spec.name for spec in specs] == ['world', 'leader', 'agents']
    return procs


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_after_the_end_of_the_run_leaves_status_0(tmp_path, ros_domain, sig):
    """Issue 38: ``ros2 launch`` reported a leader and agents that had finished cleanly as
    dead of the SIGINT it sends them when the world exits (exit code -2): it came after
    their stop handlers were restored, or before they had taken the world's ``completed``.
    Here the signal goes to the world from the moment it has written its summary, to the
    leader and the agents from the world's exit (as launch sends it), and again every 5 ms
    until each has exited: while the nodes close and after. Every status is 0, no
    traceback."""
    out = tmp_path / 'run'
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    procs = launch_processes(tmp_path, out, env)
    world = procs[0]
    summary = out / 'summary.json'
    try:
        wait_for(lambda: summary.is_file() and summary.stat().st_size > 0, RUN_TIMEOUT,
                 'the world to write its summary')
        statuses = {}
        deadline = time.monotonic() + 60
        while len(statuses) < len(procs):
            assert time.monotonic() < deadline, f'still running: {statuses}'
            for i, proc in enumerate(procs):
                if i not in statuses and (proc is world or world.poll() is not None):
                    proc.send_signal(sig)
                    try:
                        statuses[i] = proc.wait(timeout=0.005)
                    except subprocess.TimeoutExpired:
                        pass
    finally:
        reap(procs)
    assert [statuses[i] for i in range(len(procs))] == [0, 0, 0], statuses
    assert json.loads(summary.read_text())['status'] == 'completed'
    assert_clean(tmp_path)
