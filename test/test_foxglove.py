"""The live view: a real client of the Foxglove WebSocket protocol against every way in.

The client (test/foxglove_client.py) is written over ``websockets`` from the protocol's
specification, not from ``foxglove-sdk``; the bag it is compared with is read by the ``mcap``
library and the advertised schemas are parsed by ``mcap_ros2``: three independent readers.
"""

import collections
import os
from pathlib import Path
import re
import signal
import socket
import subprocess
import threading
import time

from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
import pytest

from flock_swarm.testing import wait_for
from foxglove_client import FoxgloveClient, SUBPROTOCOL
from flock_swarm.bag.msgdefs import message_definition
from flock_swarm.console import EXIT_INTERRUPTED
from flock_swarm.contract import contract_topics
from flock_swarm.foxglove_ws import (CLOSE_GOING_AWAY, CLOSE_REASONS, CLOSE_TIMEOUT,
                                     CloseRewriter, LiveServer, close_frame, message_stamp_ns,
                                     start_live)
from flock_swarm.nodes.swarm_runner import (InProcessSwarm, executable, resolve_scenario,
                                            unique_domain)

pytestmark = pytest.mark.ros

#: Agents of the recorded runs.
N = 3
#: The contract (docs/ros.md): every topic of a run of N agents and its message type.
CONTRACT = {'/clock': 'rosgraph_msgs/msg/Clock',
            '/leader/odom': 'nav_msgs/msg/Odometry',
            '/leader/accel': 'geometry_msgs/msg/AccelStamped',
            '/swarm/markers': 'visualization_msgs/msg/MarkerArray',
            '/swarm/metrics': 'diagnostic_msgs/msg/DiagnosticArray',
            **{f'/agent_{i}/odom': 'nav_msgs/msg/Odometry' for i in range(N)},
            **{f'/agent_{i}/cmd_accel': 'geometry_msgs/msg/AccelStamped' for i in range(N)}}
#: The demo shortened to ``N`` agents and 1 s (50 steps).
RUN = [f'n_agents={N}', 'informed.count=1', 'duration=1']
#: Wall-clock bound of a run, a connection or a playback [s].
TIMEOUT = 60.0
#: The close status and reason a client sees when the server stops.
GOING_AWAY = (CLOSE_GOING_AWAY, CLOSE_REASONS[CLOSE_GOING_AWAY].decode())


def bag_messages(bag: Path) -> tuple[dict, dict]:
    """Read a bag with the ``mcap`` library.

    :return: ``{(topic, log_time): {bytes, ...}}`` and ``{schema name: schema text}``.
    """
    messages: dict[tuple[str, int], set[bytes]] = {}
    with next(bag.glob('*.mcap')).open('rb') as stream:
        reader = make_reader(stream)
        schemas = {s.name: s.data.decode() for s in reader.get_summary().schemas.values()}
        for _, channel, message in reader.iter_messages():
            messages.setdefault((channel.topic, message.log_time), set()).add(message.data)
    return messages, schemas


def check_advertised(client: FoxgloveClient, schemas: dict) -> dict:
    """Every contract topic is advertised as ROS 2 CDR with the bag's schema; return decoders.

    :return: topic -> a CDR decoder built by ``mcap_ros2`` from the advertised schema.
    """
    assert client.subprotocol == SUBPROTOCOL
    assert 'time' in client.server_info['capabilities']
    channels = client.topics()
    assert set(CONTRACT) <= set(channels)
    decoders = {}
    for topic, type_name in CONTRACT.items():
        channel = channels[topic]
        assert (channel['encoding'], channel['schemaEncoding'], channel['schemaName']) == (
            'cdr', 'ros2msg', type_name), topic
        assert channel['schema'] == schemas[type_name], topic
        decoders[topic] = DecoderFactory().decoder_for('cdr', Schema(
            id=1, name=type_name, encoding='ros2msg', data=channel['schema'].encode()))
        assert decoders[topic] is not None, topic
    return decoders


def unpadded(data: bytes) -> set[bytes]:
    """Return ``data`` and, if it ends in up to 3 zero bytes that pad it to a multiple of 4,
    ``data`` without them.

    Fast DDS pads a serialised payload to a multiple of 4 bytes on the wire, so a subscriber
    receives the world's 1213-byte ``MarkerArray`` as 1216 bytes (rosbag2 records those);
    the world records the bytes it serialised.
    """
    forms = {data}
    if len(data) % 4 == 0:
        forms |= {data[:len(data) - pad] for pad in (1, 2, 3) if not any(data[-pad:])}
    return forms


def check_received(client: FoxgloveClient, bag: Path, decoders: dict,
                   wire: bool = False) -> None:
    """The client got every contract topic, each message the bag's bytes at the bag's time.

    :param wire: the server forwarded what a DDS subscriber received (the bridge): the bag's
        bytes plus the wire's padding to a multiple of 4, at most.
    """
    recorded, _ = bag_messages(bag)
    got = {topic for topic, _, _ in client.messages}
    missing = set(CONTRACT) - got
    assert not missing, (sorted(missing), collections.Counter(
        topic for topic, _, _ in client.messages), {
        i: (c['topic'], i in client.channels, i in client.subscriptions.values())
        for i, c in client.advertised.items() if c['topic'] in missing}, client.statuses)
    for topic, t_ns, data in client.messages:
        forms = unpadded(data) if wire else {data}
        assert forms & recorded.get((topic, t_ns), set()), (topic, t_ns)
        decoded = decoders[topic](data)
        if topic == '/clock':
            assert decoded.clock.sec * 10**9 + decoded.clock.nanosec == t_ns
        elif topic.endswith('/odom'):
            assert decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec == t_ns
    clock_times = {t for topic, t in recorded if topic == '/clock'}
    assert client.times and set(client.times) <= clock_times


def fly(tmp_path: Path, domain: int, live: LiveServer | None, overrides=(), connect=None,
        world_params: dict | None = None):
    """Fly the demo with ``N`` agents in this process, served on ``live``.

    :param connect: called with the swarm once its nodes exist and before the first step;
        returns the client to read with while the swarm flies.
    :param world_params: further parameters of the world.
    :return: ``(summary, client, bag directory)``.
    """
    out = tmp_path / 'run'
    scenario = resolve_scenario('demo', [*RUN, *overrides], None, out)
    with InProcessSwarm(scenario, out, domain_id=domain, world_params=world_params) as swarm:
        if live is not None:
            swarm.serve(live)
        client = connect(swarm) if connect is not None else None
        reader = None
        if client is not None:
            reader = threading.Thread(target=client.pump, args=(2.0,))
            reader.start()
        try:
            swarm.spin_to_end(TIMEOUT)
        finally:
            if reader is not None:
                reader.join()
        summary = swarm.summary()
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    return summary, client, out / 'bag'


def announced(proc: subprocess.Popen, pattern: str) -> re.Match:
    """Read ``proc``'s stderr up to the line matching ``pattern`` (the server's address)."""
    lines = []
    for line in proc.stderr:
        found = re.search(pattern, line)
        if found:
            return found
        lines.append(line)
    pytest.fail(f'no line matching {pattern!r} on stderr: {"".join(lines)!r}')


def swarm_main(argv: list[str], capsys) -> tuple[int, str]:
    """Run ``swarm``'s ``main(argv)`` in this process; return its status and standard error
    (the one-line errors: a process each took 0.3-2 s, most of it imports)."""
    from flock_swarm.cli.swarm import main
    capsys.readouterr()
    try:
        status = main(argv)
    except SystemExit as end:
        status = end.code
    captured = capsys.readouterr()
    assert captured.out == ''
    return status, captured.err


def subscribed_client(url: str, topics=tuple(CONTRACT), **kwargs) -> FoxgloveClient:
    """Connect, wait for ``topics`` to be advertised, subscribe to all of them.

    :param kwargs: passed to :class:`FoxgloveClient`.
    """
    client = FoxgloveClient(url, **kwargs)
    client.pump_until(lambda: set(topics) <= set(client.topics()), TIMEOUT, 'advertise')
    client.subscribe(topics)
    return client


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """A run served on a live server while it records, and the client that watched it."""
    tmp_path = tmp_path_factory.mktemp('live')
    domain = unique_domain()
    with start_live(port=0) as live:
        def connect(swarm):
            client = subscribed_client(live.url)
            # Subscribed before the first step: the server has a sink on every channel.
            wait_for(lambda: all(c.has_sinks() for c in live.channels.values()), TIMEOUT,
                     'the subscriptions to reach the server')
            return client
        summary, client, bag = fly(tmp_path, domain, live, connect=connect)
    client.close()
    return summary, client, bag


def test_one_process_run_is_served_with_the_recorded_bytes(recorded):
    summary, client, bag = recorded
    decoders = check_advertised(client, bag_messages(bag)[1])
    check_received(client, bag, decoders)
    # Subscribed before the start, the client saw every message of the run (TCP, no drops):
    # every recorded message of the contract's topics (/swarm/scenario is recorded, not served).
    recorded_count = sum(len(v) for (topic, _), v in bag_messages(bag)[0].items()
                         if topic in CONTRACT)
    assert len(client.messages) == recorded_count
    clock_times = {t for topic, t in bag_messages(bag)[0] if topic == '/clock'}
    assert set(client.times) == clock_times and len(clock_times) == summary['steps'] + 1


def test_replay_serves_the_bag(recorded, ros_domain):
    _, _, bag = recorded
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    command = executable('replay') + [str(bag), '--foxglove', '0', '--loop', '--rate', '5']
    proc = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        url = announced(proc, r'live view on (ws://\S+)').group(1)
        assert url.startswith('ws://127.0.0.1:')
        client = subscribed_client(url)
        decoders = check_advertised(client, bag_messages(bag)[1])
        client.pump_until(lambda: {t for t, _, _ in client.messages} >= set(CONTRACT),
                          TIMEOUT, 'a message on every topic')
        proc.send_signal(signal.SIGINT)
        # Still connected: the replay's end closes the connection with a status.
        assert not client.pump(TIMEOUT)
        assert (client.ws.close_code, client.ws.close_reason) == GOING_AWAY
        check_received(client, bag, decoders)
        proc.stderr.read()
        assert proc.wait(timeout=TIMEOUT) == EXIT_INTERRUPTED
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_foxglove_server_bridges_a_run_started_node_by_node(tmp_path, ros_domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    # The node takes the scenario file every node of the run takes (for the agents' topics).
    scenario = resolve_scenario('demo', RUN, None, tmp_path / 'run')
    proc = subprocess.Popen(executable('foxglove_server') + [
        '--ros-args', '-p', f'scenario:={scenario}', '-p', 'port:=0'],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        found = announced(proc, r'serving (\d+) topics on (ws://\S+)')
        assert int(found.group(1)) == len(CONTRACT)
        client = subscribed_client(found.group(2))

        def connect(swarm):
            # The bridge's subscriptions are matched before the first step: each topic the
            # world publishes has the agents' (or leader's) subscriber and the bridge's.
            world = swarm.world
            telemetry = [world.telemetry.marker_pub, world.telemetry.metrics_pub]
            wait_for(lambda: all(pub.get_subscription_count() >= 2
                                 for pub in [world.clock_pub, *world.odom_pubs])
                     and all(pub.get_subscription_count() >= 1 for pub in telemetry),
                     TIMEOUT, "the bridge's subscriptions")
            return client
        _, client, bag = fly(tmp_path, ros_domain, None, connect=connect)
        client.close()
        decoders = check_advertised(client, bag_messages(bag)[1])
        check_received(client, bag, decoders, wire=True)
        watcher = FoxgloveClient(found.group(2))
        proc.send_signal(signal.SIGINT)
        # A client connected when the node stops sees the connection closed with a status.
        assert not watcher.pump(TIMEOUT)
        assert (watcher.ws.close_code, watcher.ws.close_reason) == GOING_AWAY
        assert proc.wait(timeout=TIMEOUT) == EXIT_INTERRUPTED
        assert 'Traceback' not in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize('layout', [[], ['--processes', '--container']])
def test_swarm_serves_its_run(tmp_path, ros_domain, layout):
    """``swarm --foxglove 0``: one process (the world's recorded bytes), or three processes
    (a bridge node in the runner's process); a client that connects on the announcement,
    and sees the connection closed with status 1001 when the run is over (issue 38: 1005,
    no status). 4 s of simulation paced at 2, at least 2 s (time to connect) in either
    layout: unpaced, a viewer of every channel would pace the one process to real time (it
    flew 20 s), and the processes took 20 s of simulation to give the client its time."""
    out = tmp_path / 'run'
    command = executable('swarm') + ['demo', *[f'--set={o}' for o in RUN], '--set=duration=4',
                                     '--out', str(out), '--no-plots', '--foxglove', '0',
                                     '--pace', '2', '--domain-id', str(ros_domain), *layout]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        client = subscribed_client(announced(proc, r'live view on (ws://\S+)').group(1))
        # Every channel was there before the announcement: the first advertisement has all.
        assert set(CONTRACT) <= set(client.advertise_ops[0]), client.advertise_ops
        # The client reads until the run is over and the server has gone.
        assert not client.pump(TIMEOUT)
        assert (client.ws.close_code, client.ws.close_reason) == GOING_AWAY
        assert proc.wait(timeout=TIMEOUT) == 0
        log = proc.stderr.read()
        assert 'Traceback' not in log, log
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert client.messages, log
    assert 'warning' not in log, log
    decoders = check_advertised(client, bag_messages(out / 'bag')[1])
    check_received(client, out / 'bag', decoders, wire=bool(layout))


def test_a_run_without_recording_is_served_by_the_world_sink(tmp_path, ros_domain):
    """No bag, the same live view: the server is one of the world's sinks, no DDS subscriber
    is added (every odometry topic has the one agents container as its only subscriber)."""
    with start_live(port=0) as live:
        def connect(swarm):
            client = subscribed_client(live.url)
            wait_for(lambda: all(c.has_sinks() for c in live.channels.values()), TIMEOUT,
                     'the subscriptions to reach the server')
            world = swarm.world
            assert all(pub.get_subscription_count() <= 1 for pub in world.odom_pubs)
            return client
        summary, client, bag = fly(tmp_path, ros_domain, live, connect=connect,
                                   world_params={'record': False})
    client.close()
    assert not bag.exists()
    check_advertised(client, {name: message_definition(name) for name in CONTRACT.values()})
    assert {topic for topic, _, _ in client.messages} >= set(CONTRACT)
    clock = [t for topic, t, _ in client.messages if topic == '/clock']
    assert clock == sorted(clock) and clock[-1] == summary['steps'] * 20_000_000


def test_a_stalled_client_does_not_stall_the_world(tmp_path, ros_domain):
    """A client that subscribes to everything and never reads: the server drops, the world
    flies on (every command in time) and the run ends as it would without the client."""
    live = start_live(port=0)
    try:
        stalled = None

        def connect(swarm):
            nonlocal stalled
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.connect(('127.0.0.1', live.port))
            stalled = subscribed_client(live.url, list(live.channels), max_queue=1, sock=sock)
            wait_for(lambda: all(c.has_sinks() for c in live.channels.values()), TIMEOUT,
                     'the subscriptions to reach the server')
            return None
        # A pace of its own: a client of every channel would pace the run at LIVE_PACE.
        summary, _, bag = fly(tmp_path, ros_domain, live,
                              overrides=['n_agents=10', 'informed.count=3', 'duration=30'],
                              connect=connect, world_params={'pace': 1000.0})
    finally:
        started = time.monotonic()
        live.close()
        # The client never read the close frame: the relay cut its connection at the bound.
        closing = time.monotonic() - started
    sent = sum(len(v) for (topic, _), v in bag_messages(bag)[0].items()
               if not topic.endswith('/swarm/scenario'))  # recorded, not served
    assert not stalled.pump(2.0)  # what it holds, then the cut connection
    stalled.close()
    assert summary['steps'] == 1500
    assert closing < CLOSE_TIMEOUT + 1.0
    # The server had more for the client than it could hold: it dropped, nobody waited.
    assert len(stalled.messages) < sent


@pytest.mark.parametrize('argv, message', [
    (['--foxglove', '70000'], '--foxglove: the port must be an integer in [0, 65535], got '
     '70000'),
    (['--foxglove', '0', '--foxglove-host', '256.0.0.1'], '--foxglove: cannot serve on '
     '256.0.0.1:0'),
])
def test_swarm_refuses_a_bad_address_in_one_line(tmp_path, capsys, argv, message):
    """In this process (``main(argv)``): test_a_port_in_use_is_one_line_and_status_2 runs the
    commands as processes."""
    status, err = swarm_main(['demo', '--out', str(tmp_path / 'o'), *argv], capsys)
    assert status == 2
    assert err.startswith(f'swarm: error: {message}') and err.count('\n') == 1


def test_a_port_in_use_is_one_line_and_status_2(tmp_path):
    with LiveServer(port=0) as busy:
        for argv, prefix in (
                (executable('swarm') + ['demo', '--out', str(tmp_path / 'o'), '--foxglove',
                                        str(busy.port)], 'swarm: error: --foxglove: '),
                (executable('replay') + [str(tmp_path), '--foxglove', str(busy.port)],
                 'replay: error: --foxglove: '),
                (executable('foxglove_server') + ['--ros-args', '-p', f'port:={busy.port}'],
                 'foxglove_server: error: port: ')):
            res = subprocess.run(argv, capture_output=True, text=True, timeout=TIMEOUT)
            assert res.returncode == 2, argv
            assert res.stderr.startswith(prefix) and res.stderr.count('\n') == 1, res.stderr
            assert 'in use' in res.stderr


def test_contract_topics_follow_the_namespace_but_clock_stays_global():
    assert dict(contract_topics(N)) == CONTRACT
    topics = [topic for topic, _ in contract_topics(2, '/team_a')]
    assert topics[0] == '/clock'
    assert all(t.startswith('/team_a/') for t in topics[1:]) and len(topics) == 9


def test_message_stamp_of_every_contract_type():
    from builtin_interfaces.msg import Time
    from rclpy.serialization import serialize_message
    from flock_swarm.bag.msgdefs import message_class
    stamp = Time(sec=12, nanosec=340_000_000)
    for type_name in set(CONTRACT.values()):
        msg = message_class(type_name)()
        if type_name == 'rosgraph_msgs/msg/Clock':
            msg.clock = stamp
        elif type_name == 'visualization_msgs/msg/MarkerArray':
            assert message_stamp_ns(type_name, serialize_message(msg)) is None
            marker = message_class('visualization_msgs/msg/Marker')()
            marker.header.stamp = stamp
            msg.markers = [marker]
        else:
            msg.header.stamp = stamp
        assert message_stamp_ns(type_name, serialize_message(msg)) == 12_340_000_000, type_name
    assert message_stamp_ns('nav_msgs/msg/Odometry', b'\x00\x01') is None


# -- pacing and waiting for a viewer (issue 24) ------------------------------------------------


def test_pace_holds_a_lockstep_run_to_real_time_or_a_factor(tmp_path, ros_domain):
    """``pace`` (``swarm --pace``): a lockstep run takes at least its duration / pace of wall
    time, and is still ``sim``'s run bit for bit (pacing only waits between steps)."""
    from flock_swarm.testing import assert_matches_sim
    run = assert_matches_sim('demo', tmp_path / 'run', RUN, domain_id=ros_domain, atol=0,
                             world_params={'pace': 2.0})
    # 1 s of simulation at twice real time: 0.5 s of wall time at least.
    assert run.summary['wall_time_s'] >= 0.49


def start_waiting_swarm(out, ros_domain: int) -> subprocess.Popen:
    """Start a 0.1 s ``swarm demo --foxglove 0 --wait-for-viewer`` writing to ``out``."""
    command = executable('swarm') + ['demo', *[f'--set={o}' for o in RUN], '--set=duration=0.1',
                                     '--out', str(out), '--no-plots', '--foxglove', '0',
                                     '--wait-for-viewer', '--domain-id', str(ros_domain)]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)


def test_swarm_waits_for_the_first_viewer(tmp_path, ros_domain):
    """``--wait-for-viewer``: the run starts once a client subscribed, so the viewer sees it
    from step 0, even a run too short to be caught otherwise."""
    out = tmp_path / 'run'
    proc = start_waiting_swarm(out, ros_domain)
    try:
        url = announced(proc, r'live view on (ws://\S+)').group(1)
        announced(proc, r'waiting for a viewer to subscribe')
        assert not (out / 'summary.json').exists()
        client = subscribed_client(url)
        client.pump(TIMEOUT)
        assert proc.wait(timeout=TIMEOUT) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    clock = [t for topic, t, _ in client.messages if topic == '/clock']
    assert clock and clock[0] == 0 and clock[-1] == 100_000_000


def test_a_viewer_of_every_channel_paces_the_run_and_gets_all_of_it(tmp_path, ros_domain):
    """Issue 38: unpaced, the server outran a viewer subscribed to everything and dropped
    its oldest messages. A one-process lockstep run whose every channel is watched now takes
    LIVE_PACE (real time) unless ``--pace`` gives a pace: at least its duration of wall time,
    and the viewer gets every message of the run."""
    from flock_swarm.foxglove_ws import LIVE_PACE
    with start_live(port=0) as live:
        def connect(swarm):
            client = subscribed_client(live.url, list(live.channels))
            wait_for(lambda: live.watched, TIMEOUT, 'the subscriptions to reach the server')
            return client
        summary, client, bag = fly(tmp_path, ros_domain, live, connect=connect)
    client.close()
    # 50 steps of 0.02 s: the last begins 0.98 s after the first at real time.
    assert LIVE_PACE == 1.0 and summary['wall_time_s'] >= 0.97
    recorded = collections.Counter(topic for topic, _ in bag_messages(bag)[0]
                                   if topic in CONTRACT)
    assert collections.Counter(topic for topic, _, _ in client.messages) == recorded


def test_the_run_waits_for_every_subscription_of_the_viewer(tmp_path, ros_domain):
    """Issue 38: ``--wait-for-viewer`` started the run at a viewer's first subscription; an
    app subscribes channel by channel, so the channels it subscribed to next missed the
    start. The run now starts once the viewer's subscriptions have settled: here one channel
    every 0.1 s, and every channel gets every message of the run."""
    out = tmp_path / 'run'
    proc = start_waiting_swarm(out, ros_domain)
    try:
        url = announced(proc, r'live view on (ws://\S+)').group(1)
        client = FoxgloveClient(url)
        client.pump_until(lambda: set(CONTRACT) <= set(client.topics()), TIMEOUT, 'advertise')
        for topic in CONTRACT:
            client.subscribe([topic])
            client.pump(0.1)  # returns after 0.1 s without a frame
        client.pump(TIMEOUT)
        assert proc.wait(timeout=TIMEOUT) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    served = collections.Counter(topic for topic, _, _ in client.messages)
    recorded = collections.Counter(topic for topic, _ in bag_messages(out / 'bag')[0]
                                   if topic in CONTRACT)
    assert served == recorded and set(served) == set(CONTRACT)


@pytest.mark.parametrize('argv, message', [
    (['--pace', '-1'], '--pace: must be finite and >= 0, got -1.0'),
    (['--pace', 'inf'], '--pace: must be finite and >= 0, got inf'),
    (['--pace', '1', '--mode', 'realtime'], '--pace: paces lockstep runs; realtime runs take '
     '--realtime-factor'),
    (['--wait-for-viewer'], '--wait-for-viewer: goes with --foxglove'),
])
def test_swarm_refuses_a_bad_pace_or_wait_in_one_line(tmp_path, capsys, argv, message):
    """In this process, as test_swarm_refuses_a_bad_address_in_one_line."""
    status, err = swarm_main(['demo', '--out', str(tmp_path / 'o'), *argv], capsys)
    assert status == 2
    assert err == f'swarm: error: {message}\n'
    assert not (tmp_path / 'o').exists()


def test_swarm_ends_within_the_close_bound_after_a_client_closed(tmp_path, ros_domain):
    """A client that closes its connection cleanly during the run: ``swarm`` still exits
    within CLOSE_TIMEOUT (+1 s of process exit) of its last line (docs/foxglove.md)."""
    from websockets.sync.client import connect
    out = tmp_path / 'run'
    command = executable('swarm') + ['demo', *[f'--set={o}' for o in RUN], '--set=duration=4',
                                     '--out', str(out), '--no-plots', '--no-record',
                                     '--foxglove', '0', '--domain-id', str(ros_domain)]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        url = announced(proc, r'live view on (ws://\S+)').group(1)
        ws = connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=TIMEOUT)
        assert '"serverInfo"' in ws.recv(timeout=TIMEOUT)
        started = time.monotonic()
        ws.close()
        assert time.monotonic() - started < 1.0  # the server answers the close at once
        last = time.monotonic()
        for _ in proc.stderr:
            last = time.monotonic()
        assert proc.wait(timeout=TIMEOUT) == 0
        assert time.monotonic() - last < CLOSE_TIMEOUT + 1.0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_client_sees_the_server_stop_with_status_1001():
    """Issue 38: the SDK closes with an empty close frame (a client reads 1005, no status)
    and its ``stop()`` takes no code. Through the relay a reading client sees 1001 (going
    away) with a reason, and what it sends still reaches the server (its subscription)."""
    with start_live(port=0) as live:
        live.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
        client = subscribed_client(live.url, ['/clock'])
        wait_for(lambda: live.watched, TIMEOUT, 'the subscription to reach the server')
        live.write('/clock', b'\x00\x01\x00\x00' + bytes(8), 5)
        client.pump_until(lambda: client.messages, TIMEOUT, 'the message')
        reader = threading.Thread(target=client.pump, args=(TIMEOUT,))
        reader.start()
        started = time.monotonic()
        live.close()
        closing = time.monotonic() - started
        reader.join(TIMEOUT)
    assert client.messages == [('/clock', 5, b'\x00\x01\x00\x00' + bytes(8))]
    assert client.closed and (client.ws.close_code, client.ws.close_reason) == GOING_AWAY
    assert closing < CLOSE_TIMEOUT


def test_the_close_rewriter_gives_only_an_empty_close_frame_a_status():
    """The relay follows the server's frames across any split of the stream: the HTTP
    response, frames of 7-, 16- and 64-bit lengths (a payload that looks like a close frame
    included) pass byte for byte; only the SDK's empty close frame gets the status."""
    response = b'HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n\r\n'
    frames = [b'\x81\x05hello', b'\x82\x7e\x01\x2c' + b'\x88\x00' * 150,
              b'\x82\x7f' + (70000).to_bytes(8, 'big') + bytes(70000), b'\x89\x00']
    stream = response + b''.join(frames) + b'\x88\x00'
    expected = response + b''.join(frames) + close_frame(CLOSE_GOING_AWAY)
    assert close_frame(CLOSE_GOING_AWAY) == b'\x88\x10\x03\xe9server stopped'
    for size in (1, 3, 7, 1000, len(stream)):
        rewriter = CloseRewriter(lambda: CLOSE_GOING_AWAY)
        out = b''.join(rewriter.feed(stream[i:i + size]) for i in range(0, len(stream), size))
        assert out == expected, size
    # A refused upgrade is not WebSocket: passed as it is.
    refused = b'HTTP/1.1 400 Bad Request\r\n\r\n\x88\x00'
    assert CloseRewriter(lambda: CLOSE_GOING_AWAY).feed(refused) == refused


#: A sphere far from the demo's agents: the run has an obstacle map and flies as before.
FAR_SPHERE = 'obstacles={spheres: [{centre: [500.0, 500.0], radius: 1.0}]}'


def test_a_viewer_that_connects_after_the_start_gets_the_latched_obstacles(tmp_path, ros_domain):
    """The world publishes ``/swarm/obstacles`` once, before the run and before any client
    is connected: the server keeps it and sends it to the client when it subscribes."""
    with start_live(port=0) as live:
        def connect(swarm):
            # The map was written at the world's start, with no client connected.
            assert live.latched.get('/swarm/obstacles') is not None
            client = subscribed_client(live.url, topics=[*CONTRACT, '/swarm/obstacles'])
            client.pump_until(lambda: any(t == '/swarm/obstacles' for t, _, _ in
                                          client.messages), TIMEOUT, 'the obstacle map')
            return client
        _, client, bag = fly(tmp_path, ros_domain, live, overrides=[FAR_SPHERE],
                             connect=connect)
    client.close()
    recorded, schemas = bag_messages(bag)
    channel = client.topics()['/swarm/obstacles']
    assert (channel['encoding'], channel['schemaName']) == (
        'cdr', 'visualization_msgs/msg/MarkerArray')
    assert channel['schema'] == schemas['visualization_msgs/msg/MarkerArray']
    maps = [(t, data) for topic, t, data in client.messages if topic == '/swarm/obstacles']
    # Once, the bytes the bag recorded at t = 0: the map's sphere, as RViz draws it.
    assert len(maps) == 1 and maps[0][0] == 0
    assert maps[0][1] in recorded[('/swarm/obstacles', 0)]
    decoded = DecoderFactory().decoder_for('cdr', Schema(
        id=1, name=channel['schemaName'], encoding='ros2msg',
        data=channel['schema'].encode()))(maps[0][1])
    assert [(m.pose.position.x, m.pose.position.y, m.scale.x) for m in decoded.markers] == [
        (500.0, 500.0, 2.0)]


def test_the_bridge_serves_the_latched_obstacles_of_a_run_started_before_it(
        tmp_path, ros_domain):
    """``foxglove_server`` (here in a thread, as ``swarm --processes --foxglove`` runs it)
    started after the world published the map: its transient-local subscription gets it,
    and a client that subscribes after that gets it from the server."""
    from flock_swarm.nodes.foxglove_server import BackgroundBridge
    scenario = resolve_scenario('demo', [*RUN, FAR_SPHERE], None, tmp_path / 'bridge')
    with start_live(port=0) as live:
        bridges = []

        def connect(swarm):
            bridge = BackgroundBridge(live, ros_domain, {'scenario': str(scenario)})
            bridges.append(bridge)
            wait_for(lambda: bridge.node.counts['/swarm/obstacles'] == 1, TIMEOUT,
                     'the bridge to receive the latched map')
            client = subscribed_client(live.url, topics=['/swarm/obstacles'])
            client.pump_until(lambda: client.messages, TIMEOUT, 'the obstacle map')
            return client
        try:
            _, client, bag = fly(tmp_path, ros_domain, None, overrides=[FAR_SPHERE],
                                 connect=connect)
        finally:
            for bridge in bridges:
                bridge.close()
    client.close()
    recorded, _ = bag_messages(bag)
    assert [(topic, t) for topic, t, _ in client.messages] == [('/swarm/obstacles', 0)]
    assert unpadded(client.messages[0][2]) & recorded[('/swarm/obstacles', 0)]
