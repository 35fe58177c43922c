"""The batched transport through real nodes (issue 41): the swarm's state as one PointCloud2 a
step, each agents host's commands as one; a lockstep run equals sim and the per-agent run bit
for bit, in one process, in a container process and over several hosts, with the network
model, obstacles, robot plants and a law with adaptive state switched on. The bag holds the
two clouds (read back by an independent MCAP reader), and bad input is one line."""

import json
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from numpy.testing import assert_array_equal

from flock_swarm.core.run import simulate
from flock_swarm.nodes.cloud import command_fields, decode_cloud, state_fields
from flock_swarm.nodes.swarm_runner import InProcessSwarm, resolve_scenario
from flock_swarm.testing import assert_matches_sim

#: A small demo swarm packed within each other's radius, a record every other step.
DEMO = ['n_agents=6', 'informed.count=3', 'duration=0.2', 'record_every=2',
        'initial.position_box=[[0, 6], [0, 6]]']
BATCHED = ['transport=batched']
#: What each run switches on beside the transport (scenario overrides on DEMO).
FEATURES = {
    'network': ['network={delay: {law: uniform, min: 0.02, max: 0.06}, loss: 0.2, '
                'noise: {position: 0.01, velocity: 0.005}, leader: {delay: 0.04, loss: 0.1}}'],
    'obstacles': ['obstacles={walls: [{point: [-0.5, 0], normal: [1, 0]}], '
                  'spheres: [{centre: [4, 9.5], radius: 1}]}'],
    # A robot plant commanded by velocity (its Twist rides in the command cloud) and one
    # commanded by acceleration whose odometry carries a heading (qz, qw, wz in the state).
    'velocity_lag cmd_vel': ['plant={model: velocity_lag, tau: 0.15, max_speed: 1.5, '
                             'max_accel: 5.0, conversion: exact, conversion_tau: 0.12}'],
    'unicycle accel': ['plant={model: unicycle, ell: 0.3, max_speed: 1.5, max_yaw_rate: 2.0, '
                       'max_accel: 4.0, command: accel, conversion: naive}'],
}
RUN_TIMEOUT = 240.0


def read_bag(out: Path) -> dict[str, list]:
    """Return ``{topic: [(log_time, schema name, decoded message), ...]}`` of a run's bag,
    read by the mcap package's ROS 2 decoder (not ours)."""
    topics: dict[str, list] = {}
    for path in sorted((out / 'bag').glob('*.mcap')):
        with open(path, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for schema, channel, message, msg in reader.iter_decoded_messages():
                topics.setdefault(channel.topic, []).append((message.log_time, schema.name,
                                                             msg))
    return topics


def points(msg, names) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(ids, values (n, len(names)))`` of a decoded PointCloud2."""
    dtype = np.dtype({'names': [f.name for f in msg.fields],
                      'formats': [{6: '<u4', 8: '<f8'}[f.datatype] for f in msg.fields],
                      'offsets': [f.offset for f in msg.fields], 'itemsize': msg.point_step})
    data = np.frombuffer(bytes(msg.data), dtype=dtype)
    return data['id'].astype(int), np.column_stack([data[name] for name in names])


def test_batched_equals_sim_and_the_per_agent_run(tmp_path, ros_domain):
    batched = assert_matches_sim('demo', tmp_path / 'batched', DEMO + BATCHED,
                                 domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT)
    per_agent = assert_matches_sim('demo', tmp_path / 'per_agent', DEMO, domain_id=ros_domain,
                                   atol=0, timeout=RUN_TIMEOUT)
    ours, theirs = batched.timeseries(), per_agent.timeseries()
    assert sorted(ours) == sorted(theirs)
    for key in ours:
        assert_array_equal(ours[key], theirs[key], err_msg=key)
    # The bag: /clock and one state cloud a step, one command cloud a step from the one
    # host, no per-agent topic; the clouds hold the run's numbers.
    sc = batched.scenario
    bag = read_bag(batched.out)
    assert not [topic for topic in bag if topic.startswith('/agent_')]
    states, commands = bag['/swarm/states'], bag['/swarm/commands']
    assert len(states) == len(commands) == sc.steps + 1
    assert {name for _, name, _ in states + commands} == {'sensor_msgs/msg/PointCloud2'}
    t_ns, _, msg = states[0]
    assert t_ns == 0 and msg.header.frame_id == 'world' and msg.width == sc.n_agents
    ids, values = points(msg, state_fields(2))
    assert_array_equal(ids, np.arange(sc.n_agents))
    assert_array_equal(values[:, :2], ours['q'][0])
    assert_array_equal(values[:, 2:], ours['p'][0])
    for r, t in enumerate(ours['t']):
        k = round(t / sc.dt)
        t_ns, _, msg = commands[k]
        assert t_ns == round(k * sc.dt * 1e9)
        ids, u = points(msg, command_fields(2))
        assert_array_equal(ids, np.arange(sc.n_agents))
        assert_array_equal(u, ours['u'][r])


@pytest.mark.parametrize('feature', FEATURES)
def test_batched_with_a_feature_equals_sim(tmp_path, ros_domain, feature):
    assert_matches_sim('demo', tmp_path / 'run', DEMO + FEATURES[feature] + BATCHED,
                       domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT)


def test_batched_with_adaptive_state_equals_sim(tmp_path, ros_domain):
    # Zhou's gains h_i ride in the command cloud under their labels.
    run = assert_matches_sim('zhou2012_sec51', tmp_path / 'run', ['duration=0.1'] + BATCHED,
                             domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT)
    sc = run.scenario
    _, _, msg = read_bag(run.out)['/swarm/commands'][0]
    assert [f.name for f in msg.fields] == [*command_fields(sc.dim, ('h',)), 'id']


@pytest.mark.parametrize('feature, container', [('none', True), ('network', True),
                                                ('unicycle accel', True), ('none', False)],
                         ids=['container', 'container network', 'container unicycle',
                              'process per agent'])
def test_batched_in_processes_equals_sim(tmp_path, ros_domain, feature, container):
    # The agents in one container process, or each in its own (six hosts, each one command
    # cloud of one point a step).
    assert_matches_sim('demo', tmp_path / 'run', DEMO + FEATURES.get(feature, []) + BATCHED,
                       domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT, processes=True,
                       container=container)


@pytest.mark.parametrize('transport', [BATCHED, []], ids=['batched', 'per_agent'])
def test_three_host_processes_by_id_ranges_equal_sim(tmp_path, ros_domain, transport):
    # swarm --processes --container --hosts 3: three agents processes, agents 0-1, 2-3, 4-5;
    # each takes the state (one cloud, or every odometry) and commands its own agents.
    run = assert_matches_sim('demo', tmp_path / 'run', DEMO + FEATURES['network'] + transport,
                             domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT,
                             processes=True, container=True, hosts=3)
    logs = sorted(path.name for path in (run.out / 'logs').glob('agents_*.log'))
    assert logs == ['agents_0.log', 'agents_1.log', 'agents_2.log']


def test_hosts_goes_with_a_container(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'flock_swarm.cli.swarm', 'demo', '--hosts',
                             '2', '--out', str(tmp_path / 'out')],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        'swarm: error: --hosts: goes with --processes --container']


def test_batched_over_two_hosts_by_id_ranges_equals_sim(tmp_path, ros_domain):
    # Two agents hosts in one process, agents 0-2 and 3-5: each takes the one state cloud and
    # publishes one command cloud a step; the world completes a step from both.
    out = tmp_path / 'run'
    path = resolve_scenario('demo', DEMO + FEATURES['obstacles'] + BATCHED, None, out)
    with InProcessSwarm(path, out, domain_id=ros_domain, agents=[]) as swarm:
        swarm.add_agents([0, 1, 2], 'agents_a')
        swarm.add_agents([3, 4, 5], 'agents_b')
        swarm.spin_to_end(RUN_TIMEOUT)
        summary, series = swarm.summary(), swarm.result().timeseries()
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    ref = simulate(swarm.scenario)
    for key in ('q', 'p', 'u'):
        assert_array_equal(series[key], ref.series[key], err_msg=key)
    commands = read_bag(out)['/swarm/commands']
    assert len(commands) == 2 * (swarm.scenario.steps + 1)
    assert sorted(len(points(msg, ('ax',))[0]) for _, _, msg in commands[:2]) == [3, 3]


def test_a_bad_transport_is_one_line(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'flock_swarm.cli.sim', 'demo', '--set',
                             'transport=bundled', '--out', str(tmp_path / 'out')],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "sim: error: transport: must be 'per_agent' or 'batched', got 'bundled'"]


def test_a_cloud_with_foreign_ids_is_rejected():
    # The decoder of the hosts' side: a state cloud missing an agent is malformed, counted.
    from flock_swarm.nodes.cloud import CloudEncoder
    from flock_swarm.nodes.clock import StepClock
    from flock_swarm.nodes.guard import InputGuard, Limits
    from flock_swarm.nodes.transport import StateCloud
    warned = []
    guard = InputGuard(StepClock(0.02), Limits(), warned.append)
    states = StateCloud(4, 2, False, guard)
    encoder = CloudEncoder(state_fields(2))
    good = encoder.encode(40_000_000, np.array([2, 0, 3, 1]), np.arange(16.0).reshape(4, 4))
    k, rows = states.decode('swarm/states', good, ordered=True)
    assert k == 2 and rows.shape == (4, 2, 2)
    assert_array_equal(rows[0], [[4.0, 5.0], [6.0, 7.0]])
    assert states.decode('swarm/states', encoder.encode(
        40_000_000, np.arange(3), np.zeros((3, 4))), ordered=True) is None
    assert states.decode('swarm/states', good[:60], ordered=True) is None
    assert guard.counts() == {'malformed': 2}
    assert decode_cloud(good).frame_id == 'world'


def test_swarm_transport_batched_runs_the_batched_transport(tmp_path, ros_domain):
    out = tmp_path / 'run'
    result = subprocess.run([sys.executable, '-m', 'flock_swarm.cli.swarm', 'demo',
                             '--transport', 'batched', '--domain-id', str(ros_domain),
                             '--out', str(out), '--no-plots',
                             *[arg for o in DEMO for arg in ('--set', o)]],
                            capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert result.returncode == 0, result.stderr
    assert 'transport: batched' in (out / 'scenario.yaml').read_text()
    topics = read_bag(out)
    assert '/swarm/states' in topics and '/agent_0/odom' not in topics
    bad = subprocess.run([sys.executable, '-m', 'flock_swarm.cli.swarm', 'demo',
                          '--transport', 'bundled'], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and 'bundled' in bad.stderr.strip().splitlines()[-1]


@pytest.mark.parametrize('scenario, overrides', [
    ('demo', DEMO), ('demo', DEMO + FEATURES['unicycle accel']),
    ('zhou2012_sec51', ['duration=0.1'])], ids=['demo', 'unicycle', 'adaptive state'])
def test_analyze_reads_a_batched_bag_as_the_per_agent_one(tmp_path, ros_domain, scenario,
                                                          overrides):
    # analyze --verify rebuilds the batched run from its two clouds: the same series and
    # summary as from the per-agent run's topics, and sim's run within its tolerance.
    from flock_swarm.cli.analyze import main as analyze_main
    results = {}
    for name, extra in (('batched', BATCHED), ('per_agent', [])):
        run = assert_matches_sim(scenario, tmp_path / name, overrides + extra,
                                 domain_id=ros_domain, atol=0, timeout=RUN_TIMEOUT)
        out = tmp_path / f'{name}_analysis'
        assert analyze_main([str(run.out / 'bag'), '--verify', '--out', str(out), '-q',
                             '--no-anim']) == 0
        results[name] = (json.loads((out / 'summary.json').read_text()),
                         dict(np.load(out / 'timeseries.npz')))
    (ours, our_series), (theirs, their_series) = results['batched'], results['per_agent']
    assert sorted(our_series) == sorted(their_series)
    for key in our_series:
        assert_array_equal(our_series[key], their_series[key], err_msg=key)
    differ = {key for key in ours.keys() | theirs.keys() if ours.get(key) != theirs.get(key)}
    assert differ <= {'bag', 'wall_time_s'}, {k: (ours.get(k), theirs.get(k)) for k in differ}


def test_a_realtime_batched_run_misses_no_command(tmp_path, ros_domain):
    # Issue 41: realtime batched at N = 100, the world on its wall-clock timer, the host
    # answering the latest state cloud: every step has every agent's command.
    from flock_swarm.testing import run_swarm
    run = run_swarm('demo', tmp_path / 'run', ['n_agents=100', 'informed.count=33',
                                               'initial.position_box=[[0, 36.5], [0, 36.5]]',
                                               'duration=2', 'record_every=10'] + BATCHED,
                    domain_id=ros_domain, timeout=RUN_TIMEOUT, mode='realtime')
    summary = run.summary
    assert summary['status'] == 'completed' and summary['mode'] == 'realtime'
    assert summary['missed_commands'] == 0 and summary['rejected_messages'] == {}
    assert summary['command_latency_ms']['count'] > 0
    topics = read_bag(run.out)
    assert len(topics['/swarm/states']) == summary['steps'] + 1


def test_the_live_view_serves_the_state_cloud(tmp_path, ros_domain):
    # swarm --foxglove of a batched run: the viewer gets /swarm/states as a PointCloud2
    # channel (Foxglove draws it as points), the recorded bytes of every step.
    import threading

    from foxglove_client import FoxgloveClient

    from flock_swarm.foxglove_ws import start_live
    from flock_swarm.testing import wait_for
    out = tmp_path / 'run'
    path = resolve_scenario('demo', DEMO + BATCHED, None, out)
    topics = ['/clock', '/swarm/states', '/swarm/commands']
    with start_live(port=0) as live:
        with InProcessSwarm(path, out, domain_id=ros_domain) as swarm:
            swarm.serve(live)
            client = FoxgloveClient(live.url)
            client.pump_until(lambda: set(topics) <= set(client.topics()), 60.0, 'advertise')
            client.subscribe(topics)
            wait_for(lambda: all(live.channels[t].has_sinks() for t in topics), 60.0,
                     'the subscriptions to reach the server')
            reader = threading.Thread(target=client.pump, args=(2.0,))
            reader.start()
            try:
                swarm.spin_to_end(RUN_TIMEOUT)
            finally:
                reader.join()
            steps = swarm.scenario.steps
        client.close()
    channel = client.topics()['/swarm/states']
    assert (channel['encoding'], channel['schemaName']) == ('cdr', 'sensor_msgs/msg/PointCloud2')
    served = [data for topic, _, data in client.messages if topic == '/swarm/states']
    recorded = [bytes(msg.data) for _, _, msg in read_bag(out)['/swarm/states']]
    assert len(served) == steps + 1
    assert [decode_cloud(data).points.tobytes() for data in served] == recorded


def test_the_launch_files_processes_run_the_batched_transport(tmp_path, ros_domain):
    # ros2 launch flock_swarm swarm_launch.py overrides:='transport=batched': the plan's
    # processes, started with their parameters as the launch file passes them (the world
    # and the agents take it as their transport parameter, the leader and the live-view
    # bridge as the scenario key), fly the batched transport to the end.
    import os

    from flock_swarm.launch_plan import swarm_processes
    from flock_swarm.nodes.swarm_runner import executable
    out = tmp_path / 'run'
    specs = swarm_processes(overrides='transport=batched; n_agents=4; informed.count=2; '
                            'duration=0.5', out_dir=str(out))
    assert [spec.executable for spec in specs] == ['world', 'leader', 'agents']
    assert all(spec.parameters['transport'] == 'batched' for spec in specs)
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    procs = [subprocess.Popen(executable(spec.executable) + [
        '--ros-args', '-r', f'__node:={spec.name}',
        *[arg for k, v in spec.parameters.items() for arg in ('-p', f'{k}:={v}')]],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for spec in specs]
    try:
        assert procs[0].wait(timeout=RUN_TIMEOUT) == 0, procs[0].stderr.read()
        for proc in procs[1:]:
            assert proc.wait(timeout=60) == 0
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    topics = read_bag(out)
    assert '/swarm/states' in topics and '/agent_0/odom' not in topics


def test_a_host_that_stops_answering_costs_its_agents_missed_commands(tmp_path, ros_domain):
    # Two hosts by id ranges; the second goes at step 5: the world zeroes its agents'
    # commands (counted per agent, as for silent per-agent nodes) and fails the run once
    # they have missed max_missed_steps steps in a row, naming them; the first host's agents
    # miss nothing.
    out = tmp_path / 'run'
    path = resolve_scenario('demo', DEMO[:2] + ['duration=10', 'record_every=1'] + BATCHED,
                            None, out)
    with InProcessSwarm(path, out, domain_id=ros_domain, agents=[],
                        step_timeout=0.3) as swarm:
        swarm.add_agents([0, 1, 2], 'agents_a')
        gone = swarm.add_agents([3, 4, 5], 'agents_b')
        world = swarm.world
        swarm.spin_until(lambda: world.k >= 5, RUN_TIMEOUT)
        swarm.remove(gone)
        swarm.spin_until(lambda: world.done, RUN_TIMEOUT)
        summary = swarm.summary()
    assert summary['status'] == 'failed'
    # (The graph does not tell which host publishes which agent's rows: once the world has
    # asked it, the line names every host.)
    assert summary['failure'].startswith('agents 3, 4, 5 ')
    assert 'sent no command for 3 steps in a row' in summary['failure']
    missed = summary['missed_commands_per_agent']
    assert missed[:3] == [0, 0, 0] and min(missed[3:]) >= 3


def test_a_batched_world_without_hosts_says_what_it_waits_for(tmp_path, ros_domain):
    out = tmp_path / 'run'
    path = resolve_scenario('demo', DEMO + BATCHED, None, out)
    with InProcessSwarm(path, out, domain_id=ros_domain, agents=[]) as swarm:
        world = swarm.world
        assert world.waiting_for()[:2] == [
            'agents 0-5 (nobody publishes /swarm/commands)',
            '1 subscriber(s) of /swarm/states']
        swarm.add_agents(list(range(6)), 'agents')
        swarm.spin_until(lambda: not world.waiting_for(), RUN_TIMEOUT)
