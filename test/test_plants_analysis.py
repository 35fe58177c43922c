"""``analyze`` of a robot plant's bag: the plant state rebuilt from the odometry.

The world's odometry of a robot plant carries the plant state (for the unicycle the axle, its
heading and its body twist, not the point the law steers); ``analyze`` rebuilds the state
with :meth:`~flock_swarm.core.plants.base.Plant.from_odometry` and measures the law's point,
so the analysis of a lockstep bag is the world's (and ``sim``'s) run bit for bit.
"""

import json
from pathlib import Path

import numpy as np
from numpy.testing import assert_array_equal
import pytest

from flock_swarm.cli.analyze import main as analyze_main
from flock_swarm.testing import assert_matches_sim
from test_analyze import assert_summaries_agree
from test_plants_ros import DEMO, RUN_TIMEOUT, UNICYCLE, VELOCITY_LAG


@pytest.mark.ros
@pytest.mark.parametrize('plant', [UNICYCLE, VELOCITY_LAG], ids=['unicycle', 'velocity_lag'])
def test_analyze_of_a_lockstep_robot_bag_is_sims_run(tmp_path, ros_domain, plant):
    run = assert_matches_sim('demo', tmp_path / 'run', DEMO + [plant], domain_id=ros_domain,
                             atol=0, timeout=RUN_TIMEOUT)
    out = tmp_path / 'analysis'
    assert analyze_main([str(run.out / 'bag'), '--out', str(out), '--verify', '--quiet',
                         '--no-anim']) == 0
    ours = json.loads((out / 'summary.json').read_text())
    assert ours['verify_passed'] is True
    assert ours['verify_max_position_error'] == ours['verify_max_velocity_error'] == 0.0
    assert_summaries_agree(ours, run.summary)
    world = run.timeseries()
    with np.load(out / 'timeseries.npz') as data:
        series = dict(data)
    assert sorted(series) == sorted(world)
    for name, values in world.items():
        assert_array_equal(series[name], values, err_msg=name)
    assert 'plant_state' in series
    if 'unicycle' in plant:
        # The law's point is ell = 0.3 m ahead of the axle the odometry carries.
        ahead = np.linalg.norm(series['q'] - series['plant_state'][:, :, :2], axis=2)
        np.testing.assert_allclose(ahead, 0.3, rtol=1e-12)
        assert series['heading'].shape == series['t'].shape + (6,)


#: A small dense demo swarm (every pair within the radius), short.
SMALL = {'n_agents': 6, 'informed.count': 3, 'duration': 0.6,
         'initial.position_box': [[0, 6], [0, 6]]}
#: What a sweep collects of each run.
METRICS = ['eta', 'velocity_mismatch_max', 'min_pair_distance', 'collisions']


@pytest.mark.parametrize('fixed, grid', [
    ({'plant.model': 'velocity_lag', 'plant.max_speed': 1.5},
     {'plant.tau': [0.05, 0.3]}),
    ({}, {'plant.model': ['double_integrator', 'velocity_lag', 'unicycle']})],
    ids=['plant.tau', 'plant.model'])
def test_a_sweep_over_plant_keys_equals_each_sim_run(tmp_path, fixed, grid):
    """Each run of a sweep over a ``plant.*`` key is its own ``sim`` run."""
    import csv

    from flock_swarm.cli.sweep import main as sweep_main
    from flock_swarm.core.run import simulate
    from flock_swarm.presets import prepare
    spec = tmp_path / 'plants.yaml'
    spec.write_text(json.dumps({'name': 'plants', 'scenario': 'demo',
                                'set': {**SMALL, **fixed}, 'grid': grid, 'seeds': 2,
                                'metrics': METRICS}))
    assert sweep_main([str(spec), '--jobs', '1', '--out', str(tmp_path / 'out'), '--quiet',
                       '--no-plots']) == 0
    with open(tmp_path / 'out' / 'runs.csv', newline='') as stream:
        rows = list(csv.DictReader(stream))
    (key, values), = grid.items()
    assert len(rows) == 2 * len(values) and {r['status'] for r in rows} == {'completed'}
    summaries = set()
    for row in rows:
        value, = (v for v in values if str(v) == row[key])
        point = {**SMALL, **fixed, key: value}
        sc, _ = prepare('demo', [f'{k}={json.dumps(v)}' for k, v in point.items()],
                        seed=int(row['seed']))
        assert sc.plant.model.name == point.get('plant.model', 'double_integrator')
        alone = simulate(sc).summary
        for name in METRICS:
            assert float(row[name]) == alone[name], (key, row[key], name)
        summaries.add(tuple(alone[name] for name in METRICS))
    # The key made a difference.
    assert len(summaries) == len(rows)


def plant_example() -> str:
    """Return the plant plugin of docs/extending.md (section 8), the text of its module."""
    text = (Path(__file__).resolve().parents[1] / 'docs' / 'extending.md').read_text()
    section = text.split('## 8. A plant model', 1)[1]
    block = section.split('```python\n', 1)[1].split('```', 1)[0]
    assert block.startswith('# my_flock/kinematic.py\n')
    assert "'flock_swarm.plants': ['kinematic = my_flock.kinematic:Kinematic']" in section
    return block


def outputs(out: Path) -> tuple[dict, dict]:
    with np.load(out / 'timeseries.npz') as data:
        return json.loads((out / 'summary.json').read_text()), dict(data)


@pytest.mark.ros
def test_the_plant_plugin_of_the_docs_flies_in_sim_swarm_and_analyze(tmp_path, ros_domain):
    """docs/extending.md's plant, installed as a distribution (its entry point on
    ``PYTHONPATH``, what ``pip install`` leaves behind): listed, flown by ``sim``, a lockstep
    ``swarm`` run equal to it bit for bit, and its bag analysed to the same run."""
    import os
    import subprocess
    import sys

    from flock_swarm.testing import compare_runs, SIM_ONLY
    site = tmp_path / 'site'
    (site / 'my_flock').mkdir(parents=True)
    (site / 'my_flock' / '__init__.py').write_text('')
    (site / 'my_flock' / 'kinematic.py').write_text(plant_example())
    info = site / 'my_flock-1.0.dist-info'
    info.mkdir()
    (info / 'METADATA').write_text('Metadata-Version: 2.1\nName: my-flock\nVersion: 1.0\n')
    (info / 'entry_points.txt').write_text(
        '[flock_swarm.plants]\nkinematic = my_flock.kinematic:Kinematic\n')
    env = dict(os.environ, PYTHONPATH=str(site), ROS_DOMAIN_ID=str(ros_domain))

    def command(name: str, *args) -> subprocess.CompletedProcess:
        done = subprocess.run([sys.executable, '-m', f'flock_swarm.cli.{name}', *map(str, args)],
                              env=env, capture_output=True, text=True, timeout=RUN_TIMEOUT)
        assert done.returncode == 0 and 'Traceback' not in done.stderr, done.stderr
        return done

    listed = command('sim', '--list').stdout.split('plant models (plant.model):')[1]
    assert any('kinematic' in line and '[my-flock]' in line for line in listed.splitlines())
    overrides = [arg for o in DEMO + ['plant={model: kinematic, max_speed: 1.5}']
                 for arg in ('--set', o)]
    command('sim', 'demo', *overrides, '--quiet', '--out', tmp_path / 'sim')
    want, want_series = outputs(tmp_path / 'sim')
    xs = want_series['plant_state']
    assert xs.shape[1:] == (6, 4) and want['status'] == 'completed'
    # The robots drive at their setpoints, within the limit, and the limit binds.
    speeds = np.linalg.norm(xs[:, :, 2:], axis=2)
    assert speeds.max() <= 1.5 + 1e-12 and speeds[1:].max() == pytest.approx(1.5)
    command('swarm', 'demo', *overrides, '--no-plots', '--domain-id', ros_domain,
            '--out', tmp_path / 'ros')
    got, got_series = outputs(tmp_path / 'ros')
    assert got['missed_commands'] == 0
    want = {k: v for k, v in want.items() if k not in SIM_ONLY}
    assert compare_runs(want, want_series, got, got_series, atol=0.0) == []
    command('analyze', tmp_path / 'ros' / 'bag', '--out', tmp_path / 'analysis', '--verify',
            '--quiet', '--no-anim')
    ours, series = outputs(tmp_path / 'analysis')
    assert ours['verify_passed'] is True
    assert_array_equal(series['plant_state'], got_series['plant_state'])
    # The bag needs the plugin: without it, analyze names it in one line.
    del env['PYTHONPATH']
    done = subprocess.run([sys.executable, '-m', 'flock_swarm.cli.analyze',
                           str(tmp_path / 'ros' / 'bag'), '--out', str(tmp_path / 'bare')],
                          env=env, capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert done.returncode == 2 and done.stderr.count('\n') == 1, done.stderr
    assert done.stderr.startswith("analyze: error: the bag was recorded with the plant model "
                                  "'kinematic' (plant.model), which cannot be loaded here")


def test_realtime_a_stale_twist_is_a_missed_command_and_stops_the_robot(caplog):
    """Realtime, velocity commands: a Twist older than the staleness counts as the missing
    command and its robot gets a zero Twist for the step (its ``u`` zero), as a stale
    acceleration is zeroed; a fresh one drives on."""
    import logging

    from flock_swarm.nodes.stepper import WorldSettings, WorldStepper
    from test_stepper import LOG, small
    sc = small("plant={model: unicycle, ell: 0.3, max_speed: 1.5, max_yaw_rate: 2.0}")
    st = WorldStepper(sc, WorldSettings(lockstep=False, staleness=0.5), LOG, now=0.0)
    assert st.velocity
    st.realtime_begin(1.0)
    obs = st.realtime_close(1.0, 1.01)
    assert obs.missing == []
    for i in range(4):
        st.twist(i, [0.4, 0.0, 0.0], [0.0, 0.0, 0.5], 1.0)
        st.command(i, 0, np.array([0.25, 0.5]), 1.0)
    assert st.advance(obs.u)
    assert_array_equal(st.x[:, 4:], [[0.4, 0.5]] * 4)
    # Agent 2 goes on sending; the others fall silent beyond the staleness.
    st.twist(2, [0.2, 0.0, 0.0], [0.0, 0.0, -0.5], 1.55)
    st.command(2, 1, np.array([0.1, 0.2]), 1.55)
    with caplog.at_level(logging.INFO, logger=LOG.name):
        st.realtime_begin(1.6)
        obs = st.realtime_close(1.6, 1.61)
    assert obs.missing == [0, 1, 3] and st.missed.tolist() == [1, 1, 0, 1]
    assert_array_equal(obs.u, [[0, 0], [0, 0], [0.1, 0.2], [0, 0]])
    assert caplog.text.count('sent no command for 0.5 s') == 3
    before = st.x.copy()
    assert st.advance(obs.u)
    # The silent robots stopped where they were; agent 2 drives its own Twist.
    assert_array_equal(st.x[[0, 1, 3], 4:], np.zeros((3, 2)))
    assert_array_equal(st.x[[0, 1, 3], :4], before[[0, 1, 3], :4])
    assert_array_equal(st.x[2, 4:], [0.2, -0.5])
    # A Twist again: that robot drives on (no longer missing).
    st.twist(0, [0.3, 0.0, 0.0], [0.0, 0.0, 0.0], 1.7)
    st.realtime_begin(1.7)
    obs = st.realtime_close(1.7, 1.71)
    assert obs.missing == [1, 3]
    assert st.advance(obs.u)
    assert_array_equal(st.x[:, 4], [0.3, 0.0, 0.2, 0.0])


@pytest.mark.ros
def test_analyze_of_a_realtime_robot_bag_has_the_worlds_states(tmp_path, ros_domain):
    """Realtime: the world's odometry is its state, so the analysis has the world's plant
    states, headings and law points at every recorded instant."""
    from flock_swarm.analysis import load_run
    from flock_swarm.analysis.recompute import recompute
    from flock_swarm.testing import run_swarm
    run = run_swarm('demo', tmp_path / 'run', DEMO[:-1] + ['duration=0.6', UNICYCLE],
                    domain_id=ros_domain, timeout=RUN_TIMEOUT, mode='realtime')
    assert run.summary['status'] == 'completed'
    world = run.timeseries()
    bag = load_run(run.out / 'bag')
    assert bag.plant_state.shape == (len(bag.steps), 6, 6)
    series, _ = recompute(bag)
    for name in ('t', 'plant_state', 'heading', 'q', 'p'):
        assert_array_equal(series[name], world[name], err_msg=name)
