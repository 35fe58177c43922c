"""The world records how its run ended in the bag, and ``analyze`` reports it (issue 38).

A failed run (an agent's law gave a non-finite command), a run stopped mid-way and a
completed one, each flown by the real nodes in one process on a real DDS domain; the bag is
read back with the package's reader and analysed by the real ``analyze`` command. Before,
``analyze`` guessed the status from the steps the bag holds and called the failed run
``interrupted``.
"""

import json

import pytest

from flock_swarm.bag import BagReader
from flock_swarm.cli.analyze import main as analyze_main
from flock_swarm.nodes.swarm_runner import InProcessSwarm, resolve_scenario
from flock_swarm.nodes.recording import END_RECORD
from broken_law import nan_command_for

#: Wall-clock bound of one run (a hung run fails instead of blocking the suite).
RUN_TIMEOUT = 120.0
#: A small run of the demo preset (25 steps of 0.02 s).
SETS = ['n_agents=4', 'informed.count=2', 'duration=0.5', 'record_every=1']


def summary_of(out):
    """Return the ``summary.json`` in ``out``."""
    return json.loads((out / 'summary.json').read_text())


def fly(tmp_path, name, domain, stop_at=None):
    """Fly the small demo in one process into ``tmp_path / name``, to its end or until the
    world has opened step ``stop_at`` (then closed, as a stop signal closes it); return the
    output directory, the world's summary and the end its bag records."""
    out = tmp_path / name
    path = resolve_scenario('demo', SETS, None, out)
    with InProcessSwarm(path, out, domain_id=domain) as swarm:
        if stop_at is None:
            swarm.spin_to_end(RUN_TIMEOUT)
        else:
            swarm.spin_until(lambda: swarm.world.k >= stop_at, RUN_TIMEOUT)
    return out, summary_of(out), BagReader(out / 'bag').metadata(END_RECORD)


def analysed(tmp_path, out):
    """Run ``analyze`` on the bag of the run in ``out``; return its summary."""
    where = tmp_path / f'{out.name}_analysis'
    assert analyze_main([str(out / 'bag'), '--out', str(where), '--no-anim']) == 0
    return summary_of(where)


@pytest.mark.ros
def test_analyze_of_a_failed_run_says_failed_with_the_worlds_line(
        tmp_path, ros_domain, monkeypatch, capfd):
    """Agent 1's law gives NaN from step 5 on: the world ends the run ``failed`` with one
    line, records that end in the bag, and ``analyze`` of the bag reports ``failed`` with
    the same line, in its summary and on its terminal (it said ``interrupted``)."""
    nan_command_for(monkeypatch, 1, after=5)
    out, world, end = fly(tmp_path, 'failed', ros_domain)
    assert world['status'] == 'failed' and world['steps'] == 5
    assert 'returned a non-finite command at step 5 (agent 1)' in world['failure']
    assert end == {'status': 'failed', 'steps': '5', 'failure': world['failure']}
    capfd.readouterr()
    ours = analysed(tmp_path, out)
    assert ours['status'] == 'failed' and ours['failure'] == world['failure']
    err = capfd.readouterr().err
    assert f'[analyze] failed at t = {world["t_final"]:g} s' in err
    assert f'[analyze] the run failed: {world["failure"]}\n' in err
    # The failure line in its place, after the status, as the world writes it.
    keys = list(ours)
    assert keys.index('failure') == keys.index('status') + 1


@pytest.mark.ros
def test_analyze_of_a_stopped_and_of_a_completed_run_says_so(tmp_path, ros_domain, capfd):
    """A run whose world is closed at step 3 (as a stop signal closes it) records
    ``interrupted``; a run to its end records ``completed``; ``analyze`` reports each, with
    no failure line."""
    stopped, world, end = fly(tmp_path, 'stopped', ros_domain, stop_at=3)
    assert world['status'] == 'interrupted'
    assert end == {'status': 'interrupted', 'steps': str(world['steps'])}
    ours = analysed(tmp_path, stopped)
    assert ours['status'] == 'interrupted' and 'failure' not in ours
    assert 'the run failed' not in capfd.readouterr().err

    done, world, end = fly(tmp_path, 'done', ros_domain)
    assert world['status'] == 'completed' and world['steps'] == 25
    assert end == {'status': 'completed', 'steps': '25'}
    ours = analysed(tmp_path, done)
    assert ours['status'] == 'completed' and 'failure' not in ours
