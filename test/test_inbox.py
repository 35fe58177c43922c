"""A lockstep step's messages queued as bytes and taken at once, without ROS.

The world's :class:`CommandInbox` and the agents' :class:`OdometryInbox` take a step in one
pass only when it is one stamp of every sender in the senders' layout and the guard would
accept every message; anything else is left to the nodes' message-by-message checks. The
bytes are those of :mod:`flock_swarm.nodes.wire` (checked against rclpy in test_wire.py);
no rclpy is imported here.
"""

import logging

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from flock_swarm.core.leaders.base import VirtualLeader
from flock_swarm.core.scenario import realize
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.controller import AgentController, OdometryInbox
from flock_swarm.nodes.guard import InputGuard, Limits
from flock_swarm.nodes.inbox import StepInbox
from flock_swarm.nodes.stepper import CommandInbox, WorldSettings, WorldStepper
from flock_swarm.nodes.wire import AccelBatch, AccelEncoder, OdometryBatchEncoder
from flock_swarm.presets import load

LOG = logging.getLogger('test_inbox')
N = 4
DIM = 2


@pytest.fixture(scope='module')
def sc():
    """Return a four-agent demo scenario of two steps."""
    return load('demo', [f'n_agents={N}', 'informed.count=2', 'duration=0.2', 'dt=0.1'])


def guard_of(sc) -> InputGuard:
    """Return an input guard on the scenario's clock (default limits)."""
    return InputGuard(StepClock(sc.dt), Limits(), LOG.warning)


def commands(sc, k: int, u: np.ndarray) -> list[tuple[int, bytes]]:
    """Return every agent's command of step ``k`` as the agents send it: ``(i, bytes)``."""
    encoder = AccelEncoder()
    return [(i, encoder.encode(StepClock(sc.dt).ns(k), u[i].tolist())) for i in range(N)]


def odometry(sc, k: int, q: np.ndarray, p: np.ndarray) -> list[tuple[int, bytes]]:
    """Return every agent's odometry of step ``k`` as the world sends it: ``(j, bytes)``."""
    encoder = OdometryBatchEncoder([f'agent_{j}' for j in range(N)])
    return list(enumerate(encoder.encode(StepClock(sc.dt).ns(k), q, p)))


def open_world(sc) -> tuple[WorldStepper, CommandInbox]:
    """Return a lockstep stepper with step 0 open, and its command inbox."""
    st = WorldStepper(sc, WorldSettings(start_timeout=0.0), LOG, now=0.0)
    assert st.tick(0.0, lambda: True) == 'begin'
    st.begin_step(0.0)
    topics = [f'/agent_{i}/cmd_accel' for i in range(N)]
    return st, CommandInbox(st, guard_of(sc), topics)


def test_the_queue_is_taken_in_order_and_stalls_only_when_it_stops_growing():
    """A queue that grew since the last tick is not stalled; one that did not is, until it
    is taken; taking gives the messages in their order of arrival and empties it."""
    inbox = StepInbox(3, AccelBatch(3))
    assert not inbox.stalled() and len(inbox) == 0  # empty: nothing to take
    inbox.put(2, b'c')
    assert not inbox.stalled()
    inbox.put(0, b'a')
    assert not inbox.stalled()
    assert inbox.stalled() and inbox.stalled()
    assert inbox.take() == [(2, b'c'), (0, b'a')] and len(inbox) == 0
    inbox.put(1, b'b')
    assert not inbox.stalled()  # counted afresh after a take


def test_decode_needs_one_message_of_every_sender(sc):
    """decode gives the stamp and values of one message per sender, in the senders' order
    whatever the order of arrival; a missing sender or a duplicate gives None."""
    u = np.arange(N * DIM, dtype=float).reshape(N, DIM)
    step = commands(sc, 1, u)
    inbox = StepInbox(N, AccelBatch(N))
    ns, lin = inbox.decode(step[::-1])
    assert ns == StepClock(sc.dt).ns(1)
    assert_array_equal(lin[:, 0, :DIM], u)
    assert inbox.decode(step[:-1]) is None
    assert inbox.decode(step[:-1] + [step[0]]) is None


def test_the_world_takes_a_complete_step_at_once(sc):
    """Every agent's command of the open step: put says take it, take_step hands the
    stepper the commands at once and the step closes as with the commands one by one."""
    st, inbox = open_world(sc)
    u = np.array([[0.5, -0.25], [1.0, 2.0], [-3.0, 0.125], [1e-300, -7.0]])
    step = commands(sc, 0, u)
    assert [inbox.put(i, data) for i, data in step] == [False, False, False, True]
    queue = inbox.take()
    assert queue == step and inbox.take_step(queue) == 0
    assert inbox.steps_at_once == 1
    assert_array_equal(st.command_rows, u) and sorted(st.commands) == list(range(N))
    assert inbox.guard.latest == dict.fromkeys(inbox.topics, 0)
    one, _ = open_world(sc)
    for i in range(N):
        one.command(i, 0, u[i], 0.0)
    assert one.close_step(False, 0.1).u.tobytes() == st.close_step(False, 0.1).u.tobytes()


def test_the_world_completes_a_step_with_the_commands_it_holds(sc):
    """Commands already handed over one by one count towards completing the step; such a
    queue is not taken at once (the stepper holds commands), so it goes one by one."""
    st, inbox = open_world(sc)
    step = commands(sc, 0, np.ones((N, DIM)))
    st.command(0, 0, np.ones(DIM), 0.0)
    assert [inbox.put(i, data) for i, data in step[1:]] == [False, False, True]
    assert inbox.take_step(inbox.take()) is None and inbox.steps_at_once == 0


@pytest.mark.parametrize('fault', ['duplicate', 'other_step', 'non_finite', 'not_started'])
def test_the_world_leaves_anything_else_to_the_one_by_one_checks(sc, fault):
    """A duplicate, a step other than the open one, a value the guard would reject, or a
    stepper not started: take_step hands nothing over and counts nothing."""
    st, inbox = open_world(sc)
    u = np.ones((N, DIM))
    k = 0
    if fault == 'non_finite':
        u[2, 1] = np.nan
    if fault == 'other_step':
        k = 1
    if fault == 'not_started':
        st = WorldStepper(sc, WorldSettings(), LOG, now=0.0)
        inbox = CommandInbox(st, guard_of(sc), inbox.topics)
    queue = commands(sc, k, u)
    if fault == 'duplicate':
        queue[3] = queue[0]
    assert inbox.take_step(queue) is None
    assert not st.commands and inbox.steps_at_once == 0
    assert not inbox.guard.rejected and not inbox.guard.latest


def agents(sc, ids=(0, 2)) -> tuple[AgentController, OdometryInbox]:
    """Return a controller of agents ``ids`` and its odometry inbox."""
    ctrl = AgentController(sc, list(ids), LOG, now=0.0)
    return ctrl, OdometryInbox(ctrl, guard_of(sc), [f'/agent_{j}/odom' for j in range(N)],
                               [f'agent_{j}' for j in range(N)])


def test_the_agents_store_a_complete_step_at_once_and_answer_it(sc):
    """Every agent's odometry of a step: put says take it, take_step stores the states at
    once, and the answer is the one from the same states stored one by one."""
    real = realize(sc)
    ctrl, inbox = agents(sc)
    step = odometry(sc, 0, real.q0, real.p0)
    assert [inbox.put(j, data) for j, data in step[::-1]] == [False, False, False, True]
    assert inbox.take_step(inbox.take()) == 0 and ctrl.latest_step == 0
    box = ctrl.inputs(0)
    assert_array_equal(box.qp, np.stack((real.q0, real.p0), axis=1))
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity).state
    box.leader_odom, box.leader_accel = (tuple(leader.q), tuple(leader.p)), tuple(leader.a)
    one, _ = agents(sc)
    other = one.inputs(0)
    for j in range(N):
        other.put(j, (tuple(real.q0[j]), tuple(real.p0[j])))
    other.leader_odom, other.leader_accel = box.leader_odom, box.leader_accel
    assert ctrl.ready(0, 0.0) and one.ready(0, 0.0)
    assert ctrl.answer(0).tobytes() == one.answer(0).tobytes()


def test_the_agents_leave_an_answered_step_or_a_fault_to_the_one_by_one_checks(sc):
    """A step already answered, a missing agent, or a position beyond the limits: nothing
    stored at once."""
    real = realize(sc)
    ctrl, inbox = agents(sc)
    ctrl.answered = 0
    assert inbox.take_step(odometry(sc, 0, real.q0, real.p0)) is None
    assert inbox.take_step(odometry(sc, 1, real.q0, real.p0)[1:]) is None
    far = real.q0.copy()
    far[1, 0] = 2e6
    assert inbox.take_step(odometry(sc, 1, far, real.p0)) is None
    assert 1 not in ctrl.pending or not ctrl.pending[1].has_odometry(N)
    assert not inbox.guard.rejected


def test_a_step_offered_again_is_answered_again_once(sc):
    """An input of the step answered last calls for its commands again, once; of an older
    step, it is stale."""
    ctrl, _ = agents(sc)
    ctrl.answered = 5
    assert ctrl.offered_again(5) == 'repeat'
    assert ctrl.offered_again(5) is None
    assert ctrl.offered_again(4) == 'stale'
    ctrl.answered = 6
    assert ctrl.offered_again(6) == 'repeat'
