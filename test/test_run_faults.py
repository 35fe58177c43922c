"""Faults during a run end it within a bounded time, in one line, keeping what was recorded.

Issue 23, items 1 (a law, a leader model or a node that fails mid-run) and 4 (a full disk).
Real commands in real processes (``sim``, ``swarm`` in its three layouts, the ``ros2 run``
executables), real DDS (each test its own domain), plugins found through a real installed
distribution (:mod:`faulty_plugins`), and a real small filesystem (a tmpfs the test mounts
and unmounts: :func:`conftest.small_filesystem`).
"""

import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest
import yaml
from numpy.testing import assert_array_equal

from flock_swarm.bag import BagReader
from flock_swarm.cli.analyze import main as analyze_main
from flock_swarm.cli.sim import main as sim_main
from flock_swarm.core.faults import RunFault
from flock_swarm.core.scenario import parse_scenario
from flock_swarm.nodes.controller import AgentController
from flock_swarm.nodes.swarm_runner import InProcessSwarm, executable, resolve_scenario
from flock_swarm.nodes.supervisor import stop
from flock_swarm.presets import load
from flock_swarm.testing import wait_for
from broken_law import nan_command_for
from conftest import small_filesystem, subprocess_env
from faulty_plugins import FAULT_STEP, faulty_scenario, install_faulty
from test_faults import Lines

#: Wall-clock bound of one run (a hung run fails instead of blocking the suite).
RUN_TIMEOUT = 120.0


@pytest.fixture(scope='module')
def site(tmp_path_factory):
    """A site directory registering the faulty laws and leader models (for PYTHONPATH)."""
    where = tmp_path_factory.mktemp('site')
    install_faulty(where)
    return where


def command(name, *args, env, timeout=RUN_TIMEOUT):
    """Run a console script of the package; return the completed process."""
    return subprocess.run(executable(name) + [str(a) for a in args], env=env,
                          capture_output=True, text=True, timeout=timeout)


def summary_of(out):
    """Return the ``summary.json`` of a run."""
    return json.loads((out / 'summary.json').read_text())


# ----------------------------------------------------------------------------------------------
# sim: a law or leader model that fails mid-run


@pytest.mark.parametrize('law, leader, fragments', [
    ('raises_mid_run', 'constant_velocity',
     ['law flock_swarm.laws:raises_mid_run (faulty_plugins:Raises) raised ZeroDivisionError '
      f'at step {FAULT_STEP} (agent 2): the gain of the failing agent']),
    ('nan_mid_run', 'constant_velocity',
     ['law flock_swarm.laws:nan_mid_run (faulty_plugins:NotFinite) returned a non-finite '
      f'command at step {FAULT_STEP} (agent 2)']),
    ('shape_mid_run', 'constant_velocity',
     ['law flock_swarm.laws:shape_mid_run (faulty_plugins:WrongShape): ',
      f'combine() returned shape (6, 1), not (6, 2) at t = 1 s (step {FAULT_STEP})']),
    ('pull', 'raises_mid_run',
     ['leader model flock_swarm.leaders:raises_mid_run (faulty_plugins:Stalls) raised '
      f'RuntimeError at step {FAULT_STEP - 1}: the leader lost its track']),
    ('pull', 'shape_mid_run',
     ['leader model flock_swarm.leaders:shape_mid_run (faulty_plugins:Widens): '
      f'acceleration() returned shape (3,) at step {FAULT_STEP}, not shape (2,)']),
], ids=['law-raises', 'law-nan', 'law-shape', 'leader-raises', 'leader-shape'])
def test_sim_ends_a_run_whose_law_or_leader_model_fails_in_one_line(
        tmp_path, site, law, leader, fragments):
    """A plugin that fails at step 20 of 40: ``sim`` exits 1 with one line naming its entry
    point, the agent and the step (no traceback), and writes everything up to the fault:
    the summary (status ``failed``, the line as ``failure``) and the 20 finite instants
    before it. A leader model of the wrong shape is not broadcast into the state."""
    out = tmp_path / 'out'
    proc = command('sim', faulty_scenario(tmp_path / 'faulty.yaml', law, leader), '--out',
                   out, '--quiet', env=subprocess_env(PYTHONPATH=str(site)))
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith('sim: error: '), proc.stderr
    for fragment in fragments:
        assert fragment in lines[0]
    summary = summary_of(out)
    assert summary['status'] == 'failed'
    assert lines[0] == f'sim: error: {summary["failure"]}'
    with np.load(out / 'timeseries.npz') as series:
        assert series['t'].shape == (FAULT_STEP,)
        for name in series.files:
            assert np.isfinite(series[name]).all(), name


def test_sim_tells_a_law_non_finite_output_from_a_diverged_state(tmp_path, site, capsys):
    """A law's NaN at a plausible state is the law's fault (``failed``, naming it); a state
    that overflowed because ``dt`` is beyond a stability bound has ``diverged`` ("reduce
    dt"), although the law's output stopped being finite there too."""
    out = tmp_path / 'nan'
    proc = command('sim', faulty_scenario(tmp_path / 'nan.yaml', 'nan_mid_run'), '--out', out,
                   '--quiet', env=subprocess_env(PYTHONPATH=str(site)))
    assert proc.returncode == 1
    assert 'returned a non-finite command' in proc.stderr and 'reduce dt' not in proc.stderr
    assert summary_of(out)['status'] == 'failed'
    unstable = tmp_path / 'unstable'
    assert sim_main(['zhou2012_sec51', '--out', str(unstable), '--quiet', '--allow-unstable',
                     '--set', 'dt=0.02', '--set', 'duration=20']) == 1
    err = capsys.readouterr().err
    assert 'the state stopped being finite' in err and 'reduce dt' in err
    summary = summary_of(unstable)
    assert summary['status'] == 'diverged' and 'failure' not in summary


# ----------------------------------------------------------------------------------------------
# swarm: a law or leader model that fails mid-run, in every layout


@pytest.mark.parametrize('layout, node', [([], '/agents'),
                                          (['--processes', '--container'], '/agents'),
                                          (['--processes'], '/agent_2')],
                         ids=['one-process', 'container', 'processes'])
def test_a_law_that_raises_mid_run_fails_swarm_at_once(tmp_path, site, ros_domain, layout,
                                                       node):
    """The agent node hosting agent 2 reports its law's exception on ``swarm/faults`` and
    exits 1; the world ends the run as ``failed`` at that step, without waiting out a step
    timeout (no command is missed), and ``swarm`` exits 1 with the line naming the node,
    the law's entry point, the agent and the step (no traceback). The bag is finalised and
    holds every step up to the fault."""
    out = tmp_path / 'run'
    proc = command('swarm', faulty_scenario(tmp_path / 'faulty.yaml', 'raises_mid_run',
                                            n_agents=3),
                   '--out', out, '--no-plots', '--domain-id', ros_domain, *layout,
                   env=subprocess_env(PYTHONPATH=str(site)))
    assert proc.returncode == 1, proc.stderr
    assert 'Traceback' not in proc.stderr, proc.stderr
    summary = summary_of(out)
    assert summary['status'] == 'failed' and summary['steps'] == FAULT_STEP
    assert summary['failure'] == (
        f'{node}: law flock_swarm.laws:raises_mid_run (faulty_plugins:Raises) raised '
        f'ZeroDivisionError at step {FAULT_STEP} (agent 2): the gain of the failing agent')
    assert summary['missed_commands'] == 0
    assert proc.stderr.splitlines()[-1] == f'swarm: error: {summary["failure"]}'
    assert (out / 'bag' / 'metadata.yaml').is_file()
    counts = BagReader(out / 'bag').message_counts()
    assert counts['/agent_0/odom'] == FAULT_STEP + 1
    assert counts['/agent_2/cmd_accel'] == FAULT_STEP


def test_a_leader_model_of_the_wrong_shape_is_not_broadcast(tmp_path, site, ros_domain):
    """The leader node checks its model's acceleration before it publishes: a wrong shape at
    step 20 is reported (one line naming the node, the model's entry point and the step),
    never published; the run fails and ``swarm`` exits 1 without a traceback."""
    out = tmp_path / 'run'
    proc = command('swarm', faulty_scenario(tmp_path / 'faulty.yaml', 'pull', 'shape_mid_run'),
                   '--out', out, '--no-plots', '--domain-id', ros_domain,
                   env=subprocess_env(PYTHONPATH=str(site)))
    assert proc.returncode == 1 and 'Traceback' not in proc.stderr, proc.stderr
    summary = summary_of(out)
    assert summary['status'] == 'failed'
    assert summary['failure'] == (
        '/leader: leader model flock_swarm.leaders:shape_mid_run (faulty_plugins:Widens): '
        f'acceleration() returned shape (3,) at step {FAULT_STEP}, not shape (2,)')
    counts = BagReader(out / 'bag').message_counts()
    assert counts['/leader/odom'] == counts['/leader/accel'] == FAULT_STEP


# ----------------------------------------------------------------------------------------------
# The world notices a dead peer


@pytest.mark.parametrize('victim, sig, fragment, bound', [
    # Three step timeouts of 1 s, plus the stall of DDS when a process dies (up to 2 s
    # measured, docs/ros.md "Faults").
    ('agents', signal.SIGKILL, 'agents 0, 1, 2, 3 (node /agents) sent no command for 3 steps '
     'in a row', 3 * 1.0 + 5.0),
    # peer_timeout (2 s) after the graph lost it, checked once a second.
    ('leader', signal.SIGTERM, 'the leader left the ROS graph (no publisher for 2 s)',
     2.0 + 1.0 + 3.0),
], ids=['agents-killed', 'leader-exits'])
def test_a_dead_peer_ends_the_run_as_failed_within_a_bound(tmp_path, ros_domain, victim, sig,
                                                           fragment, bound):
    """The ``agents`` process killed (SIGKILL), or the leader exiting, mid-run: the world
    ends the run as ``failed`` within a few step timeouts (its summary written) instead of
    zeroing every remaining step, logs one line naming them, finalises the bag and exits
    with status 1."""
    path = resolve_scenario('demo', ['n_agents=4', 'informed.count=2', 'duration=1000'], None,
                            tmp_path / 'run')
    out = tmp_path / 'run'
    env = subprocess_env(ROS_DOMAIN_ID=str(ros_domain))
    ros_args = ['--ros-args', '-p', f'scenario:={path}']
    quiet = {'env': env, 'stdout': subprocess.DEVNULL, 'stderr': subprocess.DEVNULL}
    peers = {name: subprocess.Popen(executable(name) + ros_args, **quiet)
             for name in ('leader', 'agents')}
    world = subprocess.Popen(executable('world') + ros_args + [
        '-p', f'out_dir:={out}', '-p', 'step_timeout:=1.0', '-p', 'peer_timeout:=2.0'],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    log = Lines(world.stderr)
    try:
        wait_for(lambda: log.max_step() >= 50, 60, 'the world to pass step 50')
        peers[victim].send_signal(sig)
        began = time.monotonic()
        # The run has ended once its summary is written; the world then exits (after at most
        # 2 s waiting for the others to acknowledge the end on swarm/status).
        wait_for(lambda: (out / 'summary.json').is_file(), RUN_TIMEOUT, 'the summary')
        took = time.monotonic() - began
        world.wait(timeout=RUN_TIMEOUT)
    finally:
        stop([*peers.values(), world])
    errors = [line for line in log.lines if '[ERROR]' in line]
    assert world.returncode == 1, ''.join(log.lines[-10:])
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'failed' and fragment in summary['failure']
    assert len(errors) == 1 and summary['failure'] in errors[0]
    assert took < bound, f'the world took {took:.1f} s to end the run'
    assert (out / 'bag' / 'metadata.yaml').is_file()
    if victim == 'agents':
        assert summary['missed_commands_per_agent'] == [3] * 4


# ----------------------------------------------------------------------------------------------
# Non-finite commands of a law


def test_non_finite_commands_of_a_law_fail_the_run_by_default_and_are_counted(
        tmp_path, ros_domain, monkeypatch):
    """A law that gives agent 1 NaN from step 5 on: by default the agents node reports it
    and the world ends the run as ``failed`` at step 5 (counted: one non-finite command of
    agent 1); with ``non_finite:=zero`` the zero command goes on and every one is counted
    per agent in the summary, the time series and ``/swarm/metrics``."""
    nan_command_for(monkeypatch, 1, after=5)
    path = resolve_scenario('demo', ['n_agents=4', 'informed.count=2', 'duration=0.5',
                                     'record_every=1'], None, tmp_path / 'failed')
    sc = parse_scenario(yaml.safe_load(path.read_text()))
    with InProcessSwarm(path, tmp_path / 'failed', domain_id=ros_domain) as swarm:
        swarm.spin_to_end(RUN_TIMEOUT)
    summary = summary_of(tmp_path / 'failed')
    assert summary['status'] == 'failed' and summary['steps'] == 5
    assert summary['failure'] == ('/agents: law flock_swarm.laws:su_informed '
                                  '(flock_swarm.core.laws.su2009:SuInformed) returned a '
                                  'non-finite command at step 5 (agent 1)')
    assert summary['non_finite_commands_per_agent'] == [0, 1, 0, 0]
    assert summary['missed_commands'] == 0

    monkeypatch.undo()
    nan_command_for(monkeypatch, 1, after=5)
    out = tmp_path / 'zero'
    with InProcessSwarm(path, out, domain_id=ros_domain,
                        agent_params={'non_finite': 'zero'}) as swarm:
        swarm.spin_to_end(RUN_TIMEOUT)
    summary = summary_of(out)
    counted = sc.steps + 1 - 5
    assert summary['status'] == 'completed' and 'failure' not in summary
    assert summary['non_finite_commands_per_agent'] == [0, counted, 0, 0]
    with np.load(out / 'timeseries.npz') as series:
        assert series['non_finite_commands'][:, 1].tolist() == \
            [0] * 5 + list(range(1, counted + 1))
    metrics = [{kv.key: kv.value for kv in msg.status[0].values}
               for _, msg in BagReader(out / 'bag').decoded(['/swarm/metrics'])]
    flagged = [int(m['step']) for m in metrics if json.loads(m['non_finite_this_step'])]
    assert flagged == list(range(5, sc.steps + 1))
    assert int(metrics[-1]['non_finite_commands']) == counted
    # analyze counts them from the bag as the world did.
    assert analyze_main([str(out / 'bag'), '--out', str(tmp_path / 'analysis'),
                         '--no-anim']) == 0
    analysed = summary_of(tmp_path / 'analysis')
    assert analysed['non_finite_commands_per_agent'] == [0, counted, 0, 0]
    with np.load(tmp_path / 'analysis' / 'timeseries.npz') as again, \
            np.load(out / 'timeseries.npz') as world:
        assert_array_equal(again['non_finite_commands'], world['non_finite_commands'])


def test_controller_fails_on_a_non_finite_command_by_default(monkeypatch):
    """The agents' decision without ROS: a non-finite command is a :class:`RunFault` naming
    the law, the agent and the step, unless the state it met has blown up (then it is zero,
    and the world tells the divergence)."""
    nan_command_for(monkeypatch, 1)
    sc = load('demo', ['n_agents=4', 'informed.count=2'])
    ctrl = AgentController(sc, [0, 1], now=0.0)
    real = ctrl.real
    from flock_swarm.core.leaders.base import VirtualLeader
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity).state
    with pytest.raises(RunFault, match=r'returned a non-finite command at step 7 \(agent 1\)'):
        ctrl.command(real.q0, real.p0, leader, 7)
    u = ctrl.command(real.q0 * 1e7, real.p0, leader, 8)
    assert (u[1] == 0).all() and ctrl.zeroed == []


# ----------------------------------------------------------------------------------------------
# A full disk


def fill(disk):
    """Fill the filesystem of ``disk`` (a directory) to the last block."""
    block = bytes(1 << 16)
    with open(disk / 'filler', 'wb', buffering=0) as stream:
        try:
            while True:
                stream.write(block)
        except OSError:
            pass


def test_a_full_disk_ends_sim_with_one_line_and_no_file_that_looks_valid(tmp_path):
    """``sim`` on a full 3 MB tmpfs: one line naming the file and the error, exit status 1
    (the run failed to write its outputs; it was 2, the status of invalid input), and nothing
    left behind (no truncated or empty output, no temporary file)."""
    with small_filesystem(tmp_path / 'disk', '3m') as disk:
        (disk / 'run').mkdir()
        fill(disk)
        proc = command('sim', 'demo', '--set', 'duration=2', '--out', disk / 'run', '--quiet',
                       env=subprocess_env())
        left = sorted(os.listdir(disk / 'run'))
    assert proc.returncode == 1
    assert proc.stderr == (f'sim: error: --out: cannot write {disk / "run" / "timeseries.npz"}: '
                           'No space left on device\n')
    assert left == []


@pytest.mark.parametrize('plots', [['--no-plots'], []], ids=['no-plots', 'plots'])
def test_a_full_disk_ends_swarm_in_one_line_and_claims_no_file_it_did_not_write(
        tmp_path, ros_domain, plots):
    """``swarm demo --set duration=60`` into a 3 MB tmpfs: the bag fills it; the run ends
    (status ``recording_failed`` where a summary could still be written) with one line
    naming the file and the error, exit status 1 and no traceback; ``swarm`` lists only the
    files that exist; no empty or temporary file is left to look valid; the bag is readable
    up to its last complete chunk."""
    with small_filesystem(tmp_path / 'disk', '3m') as disk:
        out = disk / 'run'
        proc = command('swarm', 'demo', '--set', 'duration=60', '--out', out,
                       '--domain-id', ros_domain, *plots, env=subprocess_env())
        files = [path for path in out.rglob('*') if path.is_file()]
        empty = [path for path in files if path.stat().st_size == 0]
        temporary = [path for path in files if path.name.startswith('.')]
        reader = BagReader(out / 'bag')
        recovered, counts = reader.recovered, reader.message_counts()
        summary = summary_of(out) if (out / 'summary.json').is_file() else None
    assert proc.returncode == 1, proc.stderr
    assert 'Traceback' not in proc.stderr and 'EOFError' not in proc.stderr, proc.stderr
    bag_file = out / 'bag' / 'bag_0.mcap'
    assert f'cannot write {bag_file}: No space left on device' in proc.stderr
    wrote = [line for line in proc.stderr.splitlines() if line.startswith('[swarm] wrote ')]
    for line in wrote:
        for name in line[len('[swarm] wrote '):].split(', '):
            assert name in {str(path) for path in files} | {str(out / 'bag')}, name
    assert empty == [] and temporary == []
    assert recovered and counts['/agent_0/odom'] > 10
    if summary is not None:
        assert summary['status'] == 'recording_failed'
        assert summary['failure'].startswith(f'recording failed: cannot write {bag_file}')
    else:
        assert proc.stderr.splitlines()[-1].startswith(
            f'swarm: error: the world wrote no {out / "summary.json"}')
