"""``analyze``: metrics and figures rebuilt from a bag agree with the world's own outputs.

Two bags are recorded once per module through the real nodes (:func:`run_in_process`): a
2-D ``demo`` with every step recorded, and a short 3-D ``su2009_fig6`` with its preset's
subsampling. Copies of them made with :class:`BagWriter` provide a tampered scenario, a
truncated file and a bag without the ``flock_swarm`` metadata record.
"""

import json
from pathlib import Path
import signal
import subprocess
import sys

import numpy as np
from numpy.testing import assert_allclose
from PIL import Image
import pytest

from flock_swarm.analysis import analyze, load_run
from flock_swarm.cli.analyze import main
from flock_swarm.bag import BagReader, BagWriter
from flock_swarm.core.metrics import STEP_METRICS
from flock_swarm.plots import plot_analysis
from flock_swarm.nodes.swarm_runner import resolve_scenario, run_in_process, unique_domain
from flock_swarm.presets import load
from flock_swarm.core.run import simulate

pytestmark = pytest.mark.ros

#: Wall-clock bound of one recording (a hung run fails instead of blocking the suite).
RUN_TIMEOUT = 120.0
#: Keys of the world's summary that describe the process, not the run.
PROCESS_KEYS = {'wall_time_s', 'bag', 'resent_steps', 'rejected_messages', 'leader_events',
                'duplicate_agent_ids', 'bag_error', 'command_latency_ms'}
#: The figures of every analysis.
FIGURES = ('trajectories.png', 'snapshots.png', 'velocity_mismatch.png', 'com_error.png',
           'min_distance.png', 'components.png', 'eta.png')
#: Smallest plausible size of a figure with content [bytes].
MIN_FIGURE_BYTES = 8_000


def record(out: Path, preset: str, overrides: list[str]) -> Path:
    """Fly a scenario through the ROS nodes, recording a bag; return the output directory."""
    # Module-scoped, so not the function-scoped ros_domain fixture: the same helper.
    domain = unique_domain()
    scenario = resolve_scenario(preset, overrides, None, out)
    summary = run_in_process(scenario, out, domain_id=domain, timeout=RUN_TIMEOUT)
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    return out


@pytest.fixture(scope='module')
def flat(tmp_path_factory):
    """A 2-D lockstep run recorded at every step, and its analysis with --verify."""
    run = record(tmp_path_factory.mktemp('flat') / 'run', 'demo',
                 ['n_agents=4', 'informed.count=2', 'duration=2', 'record_every=1'])
    out = run / 'analysis'
    status = main([str(run / 'bag'), '--out', str(out), '--verify', '--quiet',
                   '--snapshots', '0,1,2'])
    return run, out, status


@pytest.fixture(scope='module')
def spatial(tmp_path_factory):
    """A 3-D run (Su 2009 Fig. 6, shortened; the preset records every 25th step)."""
    run = record(tmp_path_factory.mktemp('spatial') / 'run', 'su2009_fig6', ['duration=0.2'])
    out = run / 'analysis'
    return run, out, analyze(load_run(run / 'bag'), out)


def world_outputs(run: Path) -> tuple[dict, dict]:
    with np.load(run / 'timeseries.npz') as data:
        series = dict(data)
    return json.loads((run / 'summary.json').read_text()), series


def copy_bag(source: Path, target: Path, metadata: dict[str, str] | None,
             chunk_size: int = 1 << 20) -> Path:
    """Copy a bag message by message; ``metadata`` replaces the flock_swarm record (None: drop
    it and the /swarm/scenario topic, which holds the same: a bag without its scenario)."""
    reader = BagReader(source)
    dropped = set() if metadata is not None else {'/swarm/scenario'}
    with BagWriter(target, chunk_size=chunk_size) as writer:
        if metadata is not None:
            writer.add_metadata('flock_swarm', metadata)
        for topic, type_name in reader.topics().items():
            if topic not in dropped:
                writer.add_topic(topic, type_name)
        for message in reader.messages():
            if message.topic not in dropped:
                writer.write_serialized(message.topic, message.data, message.log_time_ns)
    return target


def assert_summaries_agree(ours: dict, world: dict) -> None:
    assert set(world) - PROCESS_KEYS <= set(ours)
    for key in sorted(set(world) - PROCESS_KEYS):
        if isinstance(world[key], float):
            assert ours[key] == pytest.approx(world[key], rel=0, abs=1e-9), key
        else:
            assert ours[key] == world[key], key


def test_summary_equals_the_worlds(flat):
    run, out, status = flat
    assert status == 0
    world, _ = world_outputs(run)
    ours = json.loads((out / 'summary.json').read_text())
    assert_summaries_agree(ours, world)
    assert ours['status'] == 'completed' and ours['complete_steps'] == world['steps'] + 1
    assert ours['bag_warning'] is None


def test_timeseries_equal_the_worlds(flat):
    run, out, _ = flat
    _, world = world_outputs(run)
    with np.load(out / 'timeseries.npz') as ours:
        assert sorted(ours.files) == sorted(world)
        for name, values in world.items():
            assert ours[name].dtype == values.dtype, name
            assert_allclose(ours[name], values, rtol=0, atol=1e-12, err_msg=name)


def test_subsampled_3d_run_agrees_with_the_world(spatial):
    """record_every = 25: the same instants, and the run metrics over every step."""
    run, _, result = spatial
    world, series = world_outputs(run)
    assert_summaries_agree(result.summary, world)
    assert series['t'].shape == (5,) and series['q'].shape == (5, 10, 3)
    for name, values in series.items():
        assert_allclose(result.series[name], values, rtol=0, atol=1e-12, err_msg=name)


def test_csv_holds_the_metric_series(flat):
    _, out, _ = flat
    lines = (out / 'timeseries.csv').read_text().splitlines()
    assert lines[0].split(',') == ['t', *STEP_METRICS]
    table = np.loadtxt(out / 'timeseries.csv', delimiter=',', skiprows=1)
    with np.load(out / 'timeseries.npz') as series:
        assert table.shape == (series['t'].shape[0], 1 + len(STEP_METRICS))
        assert_allclose(table[:, 0], series['t'], rtol=0, atol=0)
        for column, name in enumerate(STEP_METRICS, start=1):
            assert_allclose(table[:, column], series[f'metric_{name}'], rtol=1e-15, atol=0)


def assert_figures(out: Path) -> None:
    for name in FIGURES:
        path = out / name
        assert path.stat().st_size > MIN_FIGURE_BYTES, name
        with Image.open(path) as image:
            assert image.format == 'PNG' and min(image.size) > 200, name
    with Image.open(out / 'flock.gif') as gif:
        assert gif.format == 'GIF' and gif.n_frames > 1
        assert gif.n_frames <= 150 and max(gif.size) <= 400


def test_figures_and_animation(flat):
    _, out, _ = flat
    assert_figures(out)


def test_3d_figures_and_animation(spatial):
    _, out, result = spatial
    assert_figures(out)
    assert [p.name for p in result.files][-1] == 'summary.json'
    with Image.open(out / 'snapshots.png') as image:
        width, height = image.size
    # One panel per default snapshot time: first, middle, last.
    assert width > 2.5 * height


def test_plots_take_sim_series(tmp_path):
    """The figure functions need only a time series and scenario facts, not a bag."""
    sc = load('su2009_fig6', ['duration=0.1', 'record_every=5'])
    series = simulate(sc).series
    paths = plot_analysis(series, tmp_path, radius=sc.law.radius, title=sc.name,
                          informed=[0, 3], snapshots=[0.0, 0.1], animate=False)
    assert [p.name for p in paths] == list(FIGURES)


def test_verify_passes_on_a_lockstep_bag(flat):
    _, out, status = flat
    summary = json.loads((out / 'summary.json').read_text())
    assert status == 0 and summary['verify_passed'] is True
    assert summary['verify_max_position_error'] <= 1e-9
    assert summary['verify_max_velocity_error'] <= 1e-9
    assert summary['verify_steps_compared'] == 101


def test_verify_fails_when_the_stored_seed_is_not_the_runs(flat, tmp_path, capsys):
    """The recording is untouched; its metadata claims another seed, so sim disagrees."""
    run, _, _ = flat
    metadata = BagReader(run / 'bag').metadata('flock_swarm')
    scenario = json.loads(metadata['scenario'])
    scenario['seed'] += 1
    tampered = copy_bag(run / 'bag', tmp_path / 'tampered',
                        dict(metadata, scenario=json.dumps(scenario),
                             seed=str(scenario['seed'])))
    status = main([str(tampered), '--out', str(tmp_path / 'out'), '--verify', '--no-anim',
                   '--quiet'])
    err = capsys.readouterr().err
    assert status == 1
    assert err.count('\n') == 1 and err.startswith('analyze: verify failed: ')
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['verify_passed'] is False
    assert summary['verify_max_position_error'] > 1.0


def test_truncated_bag_is_analysed_up_to_its_last_complete_step(flat, tmp_path, capsys):
    run, _, _ = flat
    copy = copy_bag(run / 'bag', tmp_path / 'cut', BagReader(run / 'bag').metadata(
        'flock_swarm'), chunk_size=8_000)
    mcap = copy / 'cut_0.mcap'
    with mcap.open('r+b') as stream:
        stream.truncate(mcap.stat().st_size // 2)
    status = main([str(copy), '--out', str(tmp_path / 'out'), '--no-anim', '--quiet'])
    err = capsys.readouterr().err
    assert status == 0
    assert '[analyze] warning: cut_0.mcap is truncated: read ' in err
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['status'] == 'truncated' and 'truncated' in summary['bag_warning']
    assert 10 < summary['steps'] < 100
    assert summary['complete_steps'] == summary['steps'] + 1
    _, series = world_outputs(run)
    with np.load(tmp_path / 'out' / 'timeseries.npz') as ours:
        k = ours['t'].shape[0]
        assert_allclose(ours['q'], series['q'][:k], rtol=0, atol=0)


def test_a_bag_cut_after_its_data_section_is_truncated_though_every_step_survived(
        flat, tmp_path, capsys):
    run, _, _ = flat
    copy = copy_bag(run / 'bag', tmp_path / 'cut', BagReader(run / 'bag').metadata(
        'flock_swarm'), chunk_size=8_000)
    mcap = copy / 'cut_0.mcap'
    with mcap.open('r+b') as stream:
        stream.truncate(mcap.stat().st_size - 20)  # inside the summary: only the index lost
    assert main([str(copy), '--out', str(tmp_path / 'out'), '--no-anim', '--quiet']) == 0
    assert 'is truncated after its data section' in capsys.readouterr().err
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    world, _ = world_outputs(run)
    assert summary['steps'] == world['steps']
    assert summary['status'] == 'truncated' and 'only the index' in summary['bag_warning']


def test_bag_without_scenario_uses_the_options(flat, tmp_path, capsys):
    """Any rosbag2 bag with /agent_<i>/odom: radius and tolerances come from the command line."""
    run, _, _ = flat
    plain = copy_bag(run / 'bag', tmp_path / 'plain', None)
    assert main([str(plain), '--out', str(tmp_path / 'x'), '--quiet']) == 2
    assert 'give --radius' in capsys.readouterr().err
    world, series = world_outputs(run)
    status = main([str(plain), '--out', str(tmp_path / 'out'), '--radius', '4',
                   '--eta-tolerance', str(world['eta_tolerance']), '--collision-distance',
                   str(world['collision_distance']), '--no-anim', '--quiet'])
    assert status == 0
    assert 'from the options' in capsys.readouterr().err
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    # Nothing in the bag says which agents were informed: "unknown", not an empty list.
    assert summary['scenario'] is None and summary['informed'] == 'unknown'
    for key in ('n_agents', 'steps', 'eta', 'velocity_mismatch_max', 'com_position_error',
                'min_pair_distance', 'collisions', 'components_final'):
        assert summary[key] == pytest.approx(world[key], rel=0, abs=1e-9), key
    with np.load(tmp_path / 'out' / 'timeseries.npz') as ours:
        assert_allclose(ours['t'], series['t'], rtol=0, atol=1e-9)
        for name in ('q', 'p', 'u', 'leader_q', 'leader_p', 'leader_a',
                     *(f'metric_{m}' for m in STEP_METRICS)):
            assert_allclose(ours[name], series[name], rtol=0, atol=0, err_msg=name)


def test_a_bag_whose_plugin_law_is_not_installed_names_the_plugin(flat, tmp_path, capsys):
    """Issue 24: not 'the bag has no flock_swarm scenario metadata' but the missing law."""
    run, _, _ = flat
    metadata = BagReader(run / 'bag').metadata('flock_swarm')
    scenario = json.loads(metadata['scenario'])
    scenario['protocol']['name'] = 'cucker_smale'
    bag = copy_bag(run / 'bag', tmp_path / 'plugin',
                   dict(metadata, scenario=json.dumps(scenario)))
    assert main([str(bag), '--out', str(tmp_path / 'x'), '--quiet']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "recorded with the law 'cucker_smale' (protocol.name)" in err[0]
    assert 'install the package that provides it, or give --radius' in err[0]
    # With --radius it is analysed like a bag without its scenario.
    assert main([str(bag), '--out', str(tmp_path / 'y'), '--radius', '4', '--no-anim',
                 '--quiet']) == 0


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'flock_swarm.cli.analyze', *args],
                          capture_output=True, text=True, timeout=120, check=False)


@pytest.mark.parametrize('case', ['not_a_bag', 'missing', 'unwritable_out'])
def test_bad_input_is_one_line_and_status_2(flat, tmp_path, capfd, case):
    """One line, status 2: ``not_a_bag`` through a real process, the others by ``main(argv)``
    in this process with its file descriptors captured (a process took about a second)."""
    run, _, _ = flat
    if case == 'not_a_bag':
        bag = tmp_path / 'notes.mcap'
        bag.write_text('these are not the bytes of an MCAP file\n')
        args = [str(bag), '--out', str(tmp_path / 'out')]
    elif case == 'missing':
        args = [str(tmp_path / 'nowhere'), '--out', str(tmp_path / 'out')]
    else:
        blocker = tmp_path / 'file'
        blocker.write_text('')
        args = [str(run / 'bag'), '--out', str(blocker / 'out'), '--no-anim']
    if case == 'not_a_bag':
        result = run_cli(*args, '--quiet')
    else:
        capfd.readouterr()
        status = main([*args, '--quiet'])
        out = capfd.readouterr()
        result = subprocess.CompletedProcess(['analyze', *args], status, out.out, out.err)
    assert result.returncode == 2
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith('analyze: error: '), result.stderr
    assert 'Traceback' not in result.stderr and result.stdout == ''


@pytest.fixture(scope='module')
def long_bag(tmp_path_factory):
    """The ``demo`` preset as it ships (30 agents, 40 s): a bag that takes seconds to read."""
    return record(tmp_path_factory.mktemp('long') / 'run', 'demo', []) / 'bag'


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_a_signal_while_reading_ends_analyze_with_its_status_and_no_verdict(
        long_bag, tmp_path, sig):
    # The signal comes as soon as analyze catches it, while the bag is read: a handler's
    # KeyboardInterrupt raised in rclpy's deserialisation used to surface as a TypeError
    # taken for an undecodable message, after which the run was analysed without it and
    # verified (exit 0).
    from flock_swarm.nodes.supervisor import catches
    from flock_swarm.testing import wait_for
    out = tmp_path / 'out'
    process = subprocess.Popen(
        [sys.executable, '-m', 'flock_swarm.cli.analyze', str(long_bag), '--no-anim',
         '--verify', '--out', str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # SIGTERM: Python catches SIGINT from its start; analyze's handlers catch SIGTERM too.
        wait_for(lambda: catches(process.pid, signal.SIGTERM), RUN_TIMEOUT, 'the handlers')
        process.send_signal(sig)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
        process.wait()
    assert process.returncode == 128 + int(sig), stderr
    assert stderr.splitlines()[-1] == 'analyze: interrupted', stderr
    assert 'do not decode' not in stderr and 'completed' not in stderr, stderr
    assert 'verify' not in stdout
    assert not (out / 'summary.json').exists()


def test_messages_off_their_topics_layout_and_undecodable_ones_read_as_before(flat, tmp_path):
    """The swarm's messages are read a topic's batch at a time straight from their bytes
    (issue 38: analyze --verify within 2x of sim); one whose layout differs from its topic's
    (a longer frame id) is read on its own with the same values, and bytes that
    do not decode are skipped with the note, as when rclpy read every message."""
    from rclpy.serialization import deserialize_message, serialize_message
    from nav_msgs.msg import Odometry
    run, _, _ = flat
    reader = BagReader(run / 'bag')
    target = tmp_path / 'bag'
    odom = [m for m in reader.messages('/agent_1/odom')]
    changed, broken = odom[5].log_time_ns, odom[9].log_time_ns
    with BagWriter(target) as writer:
        writer.add_metadata('flock_swarm', reader.metadata('flock_swarm'))
        for topic, type_name in reader.topics().items():
            writer.add_topic(topic, type_name)
        for message in reader.messages():
            data = message.data
            if message.topic == '/agent_1/odom' and message.log_time_ns == changed:
                msg = deserialize_message(data, Odometry)
                msg.header.frame_id = 'a_frame_id_longer_than_the_others'
                data = serialize_message(msg)
            elif message.topic == '/agent_1/odom' and message.log_time_ns == broken:
                data = data[:40]
            writer.write_serialized(message.topic, data, message.log_time_ns)
    before, after = load_run(run / 'bag'), load_run(target)
    assert after.notes[0].startswith("1 message(s) that do not decode as their type skipped (a "
                                     "faulty writer's, recorded as received; first: "
                                     f'/agent_1/odom at {broken} ns (')
    assert 'odometry skipped' in after.notes[1]
    kept = np.isin(before.steps, after.steps)
    assert kept.sum() == len(before.steps) - 1
    np.testing.assert_array_equal(after.q, before.q[kept])
    np.testing.assert_array_equal(after.p, before.p[kept])


def test_an_interrupted_run_is_analysed_as_the_world_summarised_it(tmp_path, ros_domain):
    """A lockstep run stopped by SIGINT mid-run: its bag ends with the odometry of a step
    the world never closed (no command of it came). analyze's summary (t_final, the COM
    errors...) and series equal the world's, as for a completed run; they differed by that
    step (t_final 335 s against the world's 334.5 s)."""
    from flock_swarm.nodes.swarm_runner import executable
    from flock_swarm.testing import wait_for
    out = tmp_path / 'run'
    sets = ['n_agents=2', 'informed.count=1', 'dt=0.05', 'duration=1000', 'record_every=7']
    proc = subprocess.Popen(
        executable('swarm') + ['demo', *[a for s in sets for a in ('--set', s)], '--out',
                               str(out), '--no-plots', '--domain-id', str(ros_domain)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        mcap = out / 'bag' / 'bag_0.mcap'
        wait_for(lambda: mcap.is_file() and mcap.stat().st_size > 200_000, RUN_TIMEOUT,
                 'the world to step')
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=RUN_TIMEOUT)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 130, err[-2000:]
    world, series = world_outputs(out)
    assert world['status'] == 'interrupted'
    analysis = tmp_path / 'analysis'
    assert main([str(out / 'bag'), '--out', str(analysis), '--no-anim', '--quiet']) == 0
    ours = json.loads((analysis / 'summary.json').read_text())
    assert_summaries_agree(ours, world)
    with np.load(analysis / 'timeseries.npz') as data:
        assert sorted(data.files) == sorted(series)
        for name in series:
            np.testing.assert_array_equal(data[name], series[name], err_msg=name)
