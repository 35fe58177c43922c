"""The suite's tiers (issue 39): the ``ros`` and ``slow`` markers set in test/conftest.py,
``--quick``, ``--record-durations``, and the test ROS domain ids from
``FLOCK_SWARM_TEST_DOMAINS``."""

import json
import os
import subprocess
import sys

import pytest

from conftest import (DURATIONS, QUICK, REPO, ROS_FIXTURES, SLOW, dds_functions,
                      load_durations, names_command, write_durations)
from flock_swarm.nodes.swarm_runner import (DOMAIN_RANGES, DOMAINS_VARIABLE, domain_ranges,
                                            release_domain, unique_domain)

#: A test module that starts DDS in several ways, and in none.
MODULE = '''
import subprocess

import rclpy


def spin_a_node():
    rclpy.init()


def helper():
    return spin_a_node()


def run_swarm_cli(tmp_path):
    return subprocess.run(['/venv/bin/swarm', 'demo'])


def run_tool(tool):
    return subprocess.run([tool])


def test_direct():
    spin_a_node()


def test_through_a_helper():
    helper()


def test_a_command_line():
    run_swarm_cli(None)


def test_a_frame_id_is_no_command():
    assert {'frame_id': 'world', 'dir': 'swarm'}


def test_a_tool(tool):
    run_tool(tool)
'''


def test_names_of_a_module_that_start_dds(tmp_path):
    path = tmp_path / 'test_module.py'
    path.write_text(MODULE)
    dds, processes = dds_functions(str(path))
    assert dds >= {'spin_a_node', 'helper', 'run_swarm_cli', 'test_direct',
                   'test_through_a_helper', 'test_a_command_line'}
    assert 'test_a_frame_id_is_no_command' not in dds and 'test_a_tool' not in dds
    # A test that starts a process is ros when a parameter names a command that starts DDS.
    assert {'run_tool', 'test_a_tool', 'run_swarm_cli'} <= processes


@pytest.mark.parametrize('value, bare, starts', [
    ('swarm', True, True), ('swarm', False, False), ('world', False, False),
    ('swarm demo --set duration=1', False, True), ('/venv/bin/replay', False, True),
    ('flock_swarm.cli.swarm', False, True), (['agents', '--ros-args'], True, True),
    ('sim demo', False, False), ('leader models differ', False, True), ('', True, False),
    (3, True, False)])
def test_a_command_that_starts_dds_is_named(value, bare, starts):
    assert names_command(value, bare) == starts


def test_this_sessions_markers_follow_the_fixtures_and_the_durations(request):
    """Every collected test of this session that uses a ROS fixture is ``ros``; every test
    measured at >= 1 s is ``slow``, and one not measured unless it is core's; the QUICK tests
    are lockstep equivalences."""
    durations = load_durations()
    items = request.session.items
    assert items
    for item in items:
        if ROS_FIXTURES & set(item.fixturenames):
            assert item.get_closest_marker('ros'), item.nodeid
        if durations.get(item.nodeid, (0.0, 0.0))[0] >= SLOW:
            assert item.get_closest_marker('slow'), item.nodeid
    assert len(QUICK) == 5 and all(any(word in q for word in ('match', 'lockstep', 'equals_sim'))
                                   for q in QUICK)
    # Not measured yet: slow, as this module is not core's (it starts processes).
    measured = durations.get(request.node.nodeid)
    slow = measured is None or measured[0] >= SLOW
    assert bool(request.node.get_closest_marker('slow')) == slow


def test_durations_round_trip(tmp_path):
    path = tmp_path / 'durations.json'
    times = {'test/test_a.py::test_x[1-2]': (1.234, 0.5), 'test/test_b.py::test_y': (0.0, 0.0)}
    write_durations(times, path)
    assert load_durations(path) == {'test/test_a.py::test_x[1-2]': (1.23, 0.5),
                                    'test/test_b.py::test_y': (0.0, 0.0)}
    assert json.loads(path.read_text())['test/test_a.py'] == {'test_x[1-2]': [1.23, 0.5]}
    # The committed file holds every test of the suite's files it names, as [total, setup].
    committed = load_durations(DURATIONS)
    assert len(committed) > 1000
    assert all(total >= setup >= 0 for total, setup in committed.values())


def pytest_run(*args: str, env=None) -> subprocess.CompletedProcess:
    """Run pytest on this repository's tests in a process of its own."""
    return subprocess.run([sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', *args],
                          cwd=REPO, capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, **(env or {})))


def test_record_durations_writes_the_tests_that_ran(tmp_path):
    path = tmp_path / 'durations.json'
    res = pytest_run('-q', 'test/test_headline.py', '--record-durations', str(path))
    assert res.returncode == 0, res.stdout + res.stderr
    recorded = load_durations(path)
    assert recorded and all(k.startswith('test/test_headline.py::') for k in recorded)
    ran = int(res.stdout.split(' passed')[0].rsplit(maxsplit=1)[-1])
    assert len(recorded) == ran


def test_quick_keeps_the_fast_tests_and_the_equivalences():
    files = sorted({q.split('::')[0] for q in QUICK})
    res = pytest_run('--collect-only', '-q', '--quick', *files)
    assert res.returncode == 0, res.stdout + res.stderr
    selected = {line for line in res.stdout.splitlines() if '::' in line}
    assert set(QUICK) <= selected
    durations = load_durations()
    assert all(durations.get(t, (0.0, 0.0))[0] < SLOW for t in selected - set(QUICK))
    assert 'deselected' in res.stdout.splitlines()[-1]


def test_domain_ranges_come_from_the_variable():
    assert domain_ranges(None) == domain_ranges(' ') == DOMAIN_RANGES == ((1, 101), (223, 232))
    assert domain_ranges('30-59, 223-232') == ((30, 59), (223, 232))
    assert domain_ranges('7-7') == ((7, 7),)
    for text, why in [('x', "'x' is not a range lo-hi"), ('5-3', "'5-3': a range lo-hi needs"),
                      ('1-233', "'1-233': a range lo-hi needs 0 <= lo <= hi <= 232"),
                      ('1-10,5-20', "'5-20' overlaps 1-10"), ('1-2,', "'' is not a range")]:
        with pytest.raises(ValueError) as err:
            domain_ranges(text)
        assert str(err.value).startswith(f'{DOMAINS_VARIABLE}: {why}'), str(err.value)
        assert '\n' not in str(err.value)


def test_unique_domains_stay_in_the_variables_ranges(monkeypatch):
    # Outside the default ranges, which the other test processes of the machine hold ids of.
    monkeypatch.setenv(DOMAINS_VARIABLE, '190-194,180-184')
    handed = [unique_domain() for _ in range(5)]
    try:
        assert set(handed) <= {*range(190, 195), *range(180, 185)} and len(set(handed)) == 5
    finally:
        for domain in handed:
            release_domain(domain)


def test_a_bad_variable_stops_pytest_with_one_line():
    res = pytest_run('--collect-only', '-q', 'test/test_headline.py',
                     env={DOMAINS_VARIABLE: '1-300'})
    assert res.returncode == 2, res.stdout + res.stderr
    assert res.stderr.strip() == (f"Exit: error: {DOMAINS_VARIABLE}: '1-300': a range lo-hi "
                                  'needs 0 <= lo <= hi <= 232 (higher ids overflow the DDS port '
                                  'range)')
