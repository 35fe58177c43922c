"""The C message path (flock_swarm._rclbatch, flock_swarm.nodes.batch) against rclpy's own
publish and take of the same bytes: real nodes on the test's domain, real DDS.

Also run under AddressSanitizer and UndefinedBehaviorSanitizer by scripts/sanitize_rclbatch.
"""

import gc
import os
import resource
import shutil
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import AccelStamped
from rclpy.node import Node
from rclpy.serialization import serialize_message

from flock_swarm.contract import LOCKSTEP_QOS, qos_profile
from flock_swarm.core.errors import ScenarioError
from flock_swarm.nodes import batch
from flock_swarm.nodes.spin import make_executor
from flock_swarm.nodes.wire import AccelEncoder
from flock_swarm.testing import spin_until, wait_for

pytestmark = pytest.mark.ros

ext = batch.extension()
TOPICS = [f'batch_test/t{i}' for i in range(5)]
#: Calls of the reference-count and memory test.
CALLS = 100_000


def test_the_extension_is_built_in_this_environment():
    # scripts/env.sh and colcon build it; a machine without a compiler falls back, and says so.
    assert ext is not None, batch.why_not_built()


def messages(k: int, count: int) -> list[bytes]:
    """Return ``count`` distinct serialised AccelStampeds of step ``k`` (lengths differ:
    the frame ids do)."""
    out = []
    for i in range(count):
        msg = AccelStamped()
        msg.header.stamp.sec, msg.header.frame_id = k, 'f' * (i % 3)
        msg.accel.linear.x, msg.accel.linear.y = float(i), float(k)
        out.append(serialize_message(msg))
    return out


def unexpected(data: bytes) -> None:
    raise AssertionError('an executor callback got a message the take should have had')


@pytest.fixture
def nodes(ros_context):
    """A sender and a receiver node spun by one EventsExecutor; destroyed after."""
    sender = Node('batch_sender', context=ros_context)
    receiver = Node('batch_receiver', context=ros_context)
    executor = make_executor(ros_context)
    executor.add_node(sender)
    executor.add_node(receiver)
    yield sender, receiver, executor
    executor.shutdown()
    sender.destroy_node()
    receiver.destroy_node()


def two_topics(sender: Node, receiver: Node) -> tuple[list, batch.BatchTake]:
    """Return two publishers of ``sender`` and a take of ``receiver``'s subscriptions to
    them (whose callbacks must never run)."""
    qos = qos_profile(LOCKSTEP_QOS)
    pubs = [sender.create_publisher(AccelStamped, t, qos) for t in TOPICS[:2]]
    return pubs, batch.BatchTake([receiver.create_subscription(AccelStamped, t, unexpected,
                                                               qos, raw=True)
                                  for t in TOPICS[:2]])


def matched(executor, pubs, count=1):
    spin_until(executor, lambda: all(p.get_subscription_count() >= count for p in pubs), 20,
               'the subscriptions to match')


def test_batch_take_gets_what_rclpy_publishes(nodes):
    sender, receiver, executor = nodes
    qos = qos_profile(LOCKSTEP_QOS)
    pubs = [sender.create_publisher(AccelStamped, t, qos) for t in TOPICS]
    called: list[tuple[int, bytes]] = []
    subs = [receiver.create_subscription(AccelStamped, t,
                                         lambda data, i=i: called.append((i, data)), qos,
                                         raw=True) for i, t in enumerate(TOPICS)]
    take = batch.BatchTake(subs)
    try:
        matched(executor, pubs)
        sent = messages(7, len(TOPICS))
        # Topic 2 gets a second message: the take returns both, in order.
        for i in (4, 2, 0, 1, 3, 2):
            pubs[i].publish(sent[i])
        got = []
        # Not spinning: DDS delivers without the executor, which then finds nothing left.
        wait_for(lambda: got.extend(take.take()) or len(got) == 6, 20, 'six messages', 0.01)
        assert [i for i, _ in got] == [0, 1, 2, 2, 3, 4]
        assert [data for _, data in got] == [sent[0], sent[1], sent[2], sent[2], sent[3], sent[4]]
        assert take.take() == []
        for _ in range(20):
            executor.spin_once(timeout_sec=0.01)
        assert not called
    finally:
        take.close()
        take.close()


def test_batch_take_reports_sizes_and_source_stamps(nodes):
    sender, receiver, executor = nodes
    pubs, take = two_topics(sender, receiver)
    try:
        matched(executor, pubs)
        sent = messages(1, 2)
        for pub, data in zip(pubs, sent):
            pub.publish(data)
        raw = []
        wait_for(lambda: raw.append(take.native.take()) or
                 sum(len(m) for _, m in raw) == 2 * 3 * 8, 20, 'two messages', 0.01)
        data = b''.join(d for d, _ in raw)
        meta = np.frombuffer(b''.join(m for _, m in raw), dtype=np.int64).reshape(-1, 3)
        assert meta[:, 0].tolist() == [0, 1]
        assert meta[:, 1].tolist() == [len(m) for m in sent]
        assert data == b''.join(sent)
        assert (meta[:, 2] > 0).all()
    finally:
        take.close()


def test_batch_publish_reaches_rclpy_subscriptions(nodes):
    sender, receiver, executor = nodes
    qos = qos_profile(LOCKSTEP_QOS)
    pubs = [sender.create_publisher(AccelStamped, t, qos) for t in TOPICS]
    got: list[tuple[int, bytes]] = []
    for i, topic in enumerate(TOPICS):
        receiver.create_subscription(AccelStamped, topic,
                                     lambda data, i=i: got.append((i, data)), qos, raw=True)
    out = batch.BatchPublish(pubs)
    try:
        matched(executor, pubs)
        sent = messages(3, len(TOPICS))
        out.publish([(i, sent[i]) for i in (3, 0, 4, 1, 2)])
        out.publish([])
        spin_until(executor, lambda: len(got) == len(TOPICS), 20, 'every message')
        assert sorted(got) == sorted(enumerate(sent))
    finally:
        out.close()
        out.close()


def test_publishers_check_every_bound_before_publishing(nodes):
    sender, receiver, executor = nodes
    pub = sender.create_publisher(AccelStamped, TOPICS[0], qos_profile(LOCKSTEP_QOS))
    with pub.handle:
        pubs = ext.Publishers([pub.handle.pointer])
        one = np.array([1], dtype=np.int64)
        with pytest.raises(IndexError, match='publisher 1 out of range'):
            pubs.publish(b'\0' * 8, one, np.array([4], dtype=np.int64))
        with pytest.raises(ValueError, match='overrun the 8-byte buffer'):
            pubs.publish(b'\0' * 8, np.array([0, 0], dtype=np.int64),
                         np.array([4, 5], dtype=np.int64))
        with pytest.raises(ValueError, match='differ in length'):
            pubs.publish(b'', one, np.array([], dtype=np.int64))
        with pytest.raises(TypeError, match='int64'):
            pubs.publish(b'', np.array([0], dtype=np.int32), np.array([0], dtype=np.int32))
        with pytest.raises(ValueError, match='null pointer'):
            ext.Publishers([0])
        pubs.close()
        with pytest.raises(ValueError, match='closed'):
            pubs.publish(b'', one, one)


def test_an_rcl_error_is_a_python_exception_with_rcls_message(nodes):
    sender, receiver, executor = nodes
    # A publisher struct of the right size but never initialised: rcl refuses it.
    bogus = np.zeros(64, dtype=np.uint8)
    pubs = ext.Publishers([bogus.ctypes.data])
    with pytest.raises(ext.RclError, match=r'rcl_publish_serialized_message \(message 0\) '
                       r'failed \(rcl return \d+\): .*publisher'):
        pubs.publish(b'\0' * 4, np.array([0], dtype=np.int64), np.array([4], dtype=np.int64))
    taker = ext.Taker([bogus.ctypes.data])
    with pytest.raises(ext.RclError, match='rcl_take_serialized_message failed'):
        taker.take()
    taker.close()
    with pytest.raises(ValueError, match='closed'):
        taker.take()


def test_reference_counts_and_memory_stay_flat_over_many_calls(nodes):
    sender, receiver, executor = nodes
    pubs, take = two_topics(sender, receiver)
    out = batch.BatchPublish(pubs)
    try:
        matched(executor, pubs)
        data = AccelEncoder().encode(0, (1.0, 2.0, 3.0))
        blob, targets, sizes = data * 2, np.array([0, 1], dtype=np.int64), \
            np.array([len(data)] * 2, dtype=np.int64)
        taker, publishers = take.native, out.native
        watched = (blob, targets, sizes, taker, publishers)

        def calls(count):
            for _ in range(count):
                publishers.publish(blob, targets, sizes)
                taker.take()

        calls(1000)
        gc.collect()
        refs = [sys.getrefcount(x) for x in watched]
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        tracemalloc.start()
        before = tracemalloc.take_snapshot()
        calls(CALLS)
        gc.collect()
        grown = sum(s.size_diff for s in tracemalloc.take_snapshot().compare_to(before, 'lineno'))
        tracemalloc.stop()
        assert [sys.getrefcount(x) for x in watched] == refs
        assert grown < 64 * 1024, f'Python allocations grew by {grown} bytes'
        # DDS keeps the messages (history depth) whatever the number of calls.
        rss_grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0
        assert rss_grown < 32 * 1024, f'peak RSS grew by {rss_grown} KiB'
    finally:
        out.close()
        take.close()


@pytest.mark.parametrize('parameter, env, want', [
    ('rclpy', 'c', False), ('auto', 'rclpy', False), ('c', 'rclpy', ext is not None),
    ('auto', '', ext is not None), ('auto', 'auto', ext is not None)])
def test_the_path_follows_the_parameter_then_the_environment(monkeypatch, parameter, env, want):
    monkeypatch.setenv(batch.ENV, env)
    assert batch.use_c_path(parameter) is want


def test_an_unknown_path_in_the_environment_is_refused(monkeypatch):
    monkeypatch.setenv(batch.ENV, 'fast')
    with pytest.raises(ScenarioError, match=f"{batch.ENV}: must be 'auto', 'c' or 'rclpy', "
                       "got 'fast'"):
        batch.use_c_path('auto')


def test_asking_for_c_without_the_extension_names_why(monkeypatch):
    monkeypatch.setattr(batch, '_extension', None)
    monkeypatch.setattr(batch, '_missing', 'flock_swarm._rclbatch does not import: gone')
    monkeypatch.delenv(batch.ENV, raising=False)
    with pytest.raises(ScenarioError, match="message_path: 'c' needs the C extension: "
                       'flock_swarm._rclbatch does not import: gone'):
        batch.use_c_path('c')
    assert batch.use_c_path('auto') is False
    assert os.environ.get(batch.ENV) is None


def test_a_build_without_a_compiler_succeeds_and_says_why_in_one_line(tmp_path):
    root = Path(__file__).resolve().parent.parent
    for name in ('setup.py', 'setup.cfg', 'package.xml'):
        shutil.copy(root / name, tmp_path / name)
    shutil.copytree(root / 'resource', tmp_path / 'resource')
    (tmp_path / 'flock_swarm').mkdir()
    (tmp_path / 'flock_swarm' / '__init__.py').touch()
    shutil.copy(root / 'flock_swarm' / '_rclbatch.c', tmp_path / 'flock_swarm')
    result = subprocess.run([sys.executable, 'setup.py', '-q', 'build_ext', '--inplace'],
                            cwd=tmp_path, env=dict(os.environ, CC='/bin/false'),
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stderr.splitlines() if 'flock_swarm:' in line]
    assert lines == ["flock_swarm: C message path not built (command '/bin/false' failed with "
                     'exit code 1); the nodes use pure rclpy'], result.stderr
    assert not list((tmp_path / 'flock_swarm').glob('_rclbatch*.so'))
