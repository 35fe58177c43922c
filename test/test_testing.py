"""The public testing API (flock_swarm.testing) and its pytest plugin, as a user's tests see it.

The plugin is checked from outside: a pytest run in a directory of its own (no project
``pytest.ini`` or ``conftest.py``) must get the fixtures through the ``pytest11`` entry point
alone, without importing rclpy until a test needs it.
"""

import json
import os
import subprocess
import sys
import textwrap
from importlib.metadata import entry_points

import numpy as np
import pytest

from flock_swarm.testing import (assert_matches_sim, compare_runs, release_domain, SwarmRun,
                                 unique_domain, wait_for)

#: A small lockstep run: three agents, one informed, ten steps, every step recorded.
SMALL = ['n_agents=3', 'informed.count=1', 'duration=0.2', 'record_every=1']
#: Wall-clock bound of one run or one pytest subprocess.
TIMEOUT = 120.0

#: A user's test file: the fixtures only, from the plugin.
USER_TESTS = textwrap.dedent("""\
    import sys


    def test_the_plugin_imports_no_rclpy(request):
        assert request.config.pluginmanager.has_plugin('flock_swarm')
        assert 'rclpy' not in sys.modules


    def test_two_domains(ros_domain, other_ros_domain):
        def recommended(i):
            return 1 <= i <= 101 or 215 <= i <= 232
        assert recommended(ros_domain) and recommended(other_ros_domain)
        assert ros_domain != other_ros_domain


    def test_two_runs(flock_swarm_run):
        small = {small!r}
        first = flock_swarm_run('demo', small)
        second = flock_swarm_run('demo', small + ['seed=3'])
        assert first.out != second.out
        assert first.summary['status'] == second.summary['status'] == 'completed'
        assert (first.summary['seed'], second.summary['seed']) == (first.scenario.seed, 3)
""").format(small=SMALL)


def test_the_plugin_is_registered_under_pytest11():
    found = [ep for ep in entry_points(group='pytest11') if ep.name == 'flock_swarm']
    assert [ep.value for ep in found] == ['flock_swarm.testing']


@pytest.mark.ros
def test_a_users_tests_get_the_fixtures_from_the_plugin(tmp_path, ros_domain):
    (tmp_path / 'test_user.py').write_text(USER_TESTS)
    env = {k: v for k, v in os.environ.items() if k != 'PYTEST_ADDOPTS'}
    run = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                          '--rootdir', str(tmp_path), 'test_user.py'],
                         cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=TIMEOUT)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert '3 passed' in run.stdout


def test_unique_domains_stay_in_ros_recommended_ranges_and_do_not_repeat_soon():
    # The ROS 2 docs ("The ROS_DOMAIN_ID"): 0-101 are safe on Linux, 215-232 usable too; 0 is
    # everybody's default, 222 scripts/demo's. Ids other processes hold are skipped.
    ids = [unique_domain() for _ in range(30)]
    for domain in ids:
        release_domain(domain)
    assert all(1 <= i <= 101 or 223 <= i <= 232 for i in ids)
    assert len(set(ids)) == 30


def test_a_domain_another_process_holds_is_not_handed_out():
    """A world refuses to start beside another on its domain: two test processes of one
    machine never get the same id while both run."""
    child = subprocess.Popen(
        [sys.executable, '-c', 'import sys; from flock_swarm.testing import unique_domain; '
         'print(unique_domain(), flush=True); sys.stdin.read()'],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        theirs = int(child.stdout.readline())
        ours = {unique_domain() for _ in range(150)}
    finally:
        child.stdin.close()
        child.wait(timeout=TIMEOUT)
        # Give them back: the processes later tests start must find free ids.
        for domain in locals().get('ours', ()):
            release_domain(domain)
    assert theirs not in ours
    assert 1 <= theirs <= 101 or 223 <= theirs <= 232


def test_wait_for_returns_once_the_condition_holds_and_fails_with_what_it_awaited():
    calls = []
    wait_for(lambda: calls.append(1) or len(calls) >= 3, timeout=10, poll=0.001)
    assert len(calls) == 3
    with pytest.raises(AssertionError, match=r'^timed out after 0.05 s waiting for the sky$'):
        wait_for(lambda: False, timeout=0.05, what='the sky', poll=0.01)


def test_compare_runs_names_every_difference_beyond_the_tolerance():
    summary = {'eta': 0.5, 'collisions': 0, 'informed': [1, 2], 'status': 'completed',
               'nested': {'x': 1.0}}
    series = {'q': np.linspace(0.0, 1.0, 12).reshape(3, 2, 2),
              'informed': np.array([[True, False], [True, False], [True, False]])}
    copy = {k: v.copy() for k, v in series.items()}
    assert compare_runs(summary, series, json.loads(json.dumps(summary)), copy, 0.0) == []

    moved = dict(copy, q=copy['q'] + 1e-7)
    assert compare_runs(summary, series, summary, moved, 1e-6) == []
    problems = compare_runs(summary, series, summary, moved, 0.0)
    assert len(problems) == 1 and problems[0].startswith('series q: 12 of 12 values differ')

    other = dict(summary, eta=0.5 + 1e-3, collisions=1, nested={'x': 1.0})
    del other['status']
    flipped = dict(copy, informed=~copy['informed'])
    problems = compare_runs(summary, series, other, flipped, 1e-6)
    assert sorted(p.split(':')[0] for p in problems) == [
        'series informed', 'summary collisions', 'summary eta', 'summary status']
    assert 'summary status: missing' in problems


@pytest.mark.ros
def test_spin_until_waits_for_its_condition_and_fails_plainly(in_process_swarm):
    swarm = in_process_swarm('demo', SMALL, world_params={'record': False})
    swarm.spin_until(lambda: swarm.world.k >= 3, timeout=TIMEOUT, what='step 3')
    assert 3 <= swarm.world.k
    with pytest.raises(AssertionError, match=r'^timed out after 0 s waiting for never '):
        swarm.spin_until(lambda: False, timeout=0, what='never')
    with pytest.raises(AssertionError,
                       match=r'^the run ended \(completed at step \d+\) before never$'):
        swarm.spin_until(lambda: False, timeout=TIMEOUT, what='never')
    run = swarm.run()
    assert run.summary['status'] == 'completed' and run.summary['steps'] == 10


@pytest.mark.ros
def test_a_lockstep_run_matches_sim_bit_for_bit(tmp_path, ros_domain):
    run = assert_matches_sim('demo', tmp_path / 'run', SMALL, domain_id=ros_domain, atol=0)
    assert isinstance(run, SwarmRun) and run.scenario.n_agents == 3
    # The bag is there and complete: a clock tick and three commands per step.
    counts = run.bag().message_counts()
    assert counts['/clock'] == 11
    assert [counts[f'/agent_{i}/cmd_accel'] for i in range(3)] == [11, 11, 11]
    assert len(run.messages('/leader/odom')) == 11


@pytest.mark.ros
def test_a_run_that_is_not_sims_is_told_apart(tmp_path, ros_domain):
    """Agent 2 never runs: the ROS run misses its commands, so it cannot be compared."""
    with pytest.raises(AssertionError, match=r"not comparable with sim: .*'missed_commands'"):
        assert_matches_sim('demo', tmp_path / 'run', SMALL, domain_id=ros_domain,
                           agents=[0, 1], step_timeout=0.05,
                           world_params={'record': False, 'start_timeout': 2.0,
                                         'expect_subscribers': 1})
