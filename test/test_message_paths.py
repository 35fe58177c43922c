"""Both message paths of the lockstep nodes: the compiled one (flock_swarm._rclbatch, the
default when built, so every other ROS test of the suite runs on it) and pure rclpy, the
fallback (run here for a representative set of the equivalence and fault tests).

Chosen for the fallback: the one-process equivalence (test_nodes, test_testing), the
network model in every layout (test_network_ros: one process, container, a process per
agent), the adaptive state in one process (test_adaptive_state), the guard's rejections and
counts under forged messages, a stalled step offered again, and a law's non-finite commands
(test_faults, test_run_faults). About 12 runs of a few agents: the rest of the suite runs
on the compiled path.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from flock_swarm.nodes import batch
from flock_swarm.nodes.world import main as world_main
from flock_swarm.testing import Swarm, assert_matches_sim

pytestmark = pytest.mark.ros

TEST_DIR = Path(__file__).resolve().parent
#: The tests run again on the pure-rclpy path.
FALLBACK_TESTS = [
    'test_nodes.py::test_a_steps_commands_are_taken_at_once_and_give_sims_run',
    'test_testing.py::test_a_lockstep_run_matches_sim_bit_for_bit',
    'test_network_ros.py::test_delay_loss_and_noise_match_sim_in_every_layout',
    'test_adaptive_state.py::test_zhou_matches_sim_in_every_layout[one process]',
    'test_faults.py::test_faulty_messages_are_rejected_counted_and_harmless',
    'test_faults.py::test_stalled_step_is_offered_again_with_backoff',
    'test_run_faults.py::test_non_finite_commands_of_a_law_fail_the_run_by_default_and_are_'
    'counted',
]
#: Wall-clock bound of the fallback's pytest run.
FALLBACK_TIMEOUT = 900.0
#: N = 300, a few steps at the demo's density (bench/bench_ros.py's scenario).
N300 = ['n_agents=300', 'informed.count=100', 'initial.position_box=[[0, 63.246], [0, 63.246]]',
        'duration=0.1', 'record_every=1']


def test_the_compiled_path_is_the_default_and_the_environment_forces_rclpy(
        tmp_path, ros_domain, monkeypatch):
    monkeypatch.delenv(batch.ENV, raising=False)
    overrides = ['n_agents=3', 'informed.count=1', 'duration=0.04']
    with Swarm('demo', tmp_path / 'c', overrides, domain_id=ros_domain) as swarm:
        assert swarm.world.c_path and swarm.agents.c_path
        swarm.spin_to_end(60)
        assert swarm.world.steps_at_once > 0
    monkeypatch.setenv(batch.ENV, 'rclpy')
    with Swarm('demo', tmp_path / 'rclpy', overrides, domain_id=ros_domain) as swarm:
        assert not swarm.world.c_path and not swarm.agents.c_path
        assert swarm.world.cmd_take is None and swarm.agents.batch_out is None


def test_a_bad_message_path_is_one_line_and_status_2(tmp_path, ros_domain, capfd, monkeypatch):
    monkeypatch.delenv(batch.ENV, raising=False)
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    monkeypatch.chdir(tmp_path)
    assert world_main(['world', '--ros-args', '-p', 'message_path:=fast']) == 2
    out, err = capfd.readouterr()
    assert err == "world: error: message_path: must be 'auto', 'c' or 'rclpy', got 'fast'\n"
    monkeypatch.setenv(batch.ENV, 'fast')
    assert world_main(['world']) == 2
    out, err = capfd.readouterr()
    assert err == f"world: error: {batch.ENV}: must be 'auto', 'c' or 'rclpy', got 'fast'\n"
    # Refused before anything was written.
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize('layout', [{}, {'processes': True, 'container': True}],
                         ids=['one process', 'container'])
def test_300_agents_on_the_compiled_path_match_sim(tmp_path, ros_domain, monkeypatch, layout):
    monkeypatch.setenv(batch.ENV, 'c')
    run = assert_matches_sim('demo', tmp_path / 'run', N300, domain_id=ros_domain, atol=0,
                             timeout=300, **layout)
    assert run.summary['n_agents'] == 300


def test_the_fallback_passes_the_equivalence_and_fault_tests(tmp_path):
    env = dict(os.environ, **{batch.ENV: 'rclpy'})
    result = subprocess.run(
        [sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider', '-p', 'no:randomly',
         '--rootdir', str(TEST_DIR.parent)] + [str(TEST_DIR / t) for t in FALLBACK_TESTS],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=FALLBACK_TIMEOUT)
    tail = '\n'.join(result.stdout.splitlines()[-15:])
    assert result.returncode == 0, tail
    assert ' passed' in tail and 'failed' not in tail and 'skipped' not in tail, tail
