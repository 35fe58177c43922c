"""The nodes' decisions without ROS: the world's stepper and the agents' controller.

Every time is passed in, so these tests drive the timeouts, the resend policy and the
leader's loss through exact instants, with no node, no DDS and no wall clock.
"""

import logging
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from flock_swarm.core.dynamics import step_agents
from flock_swarm.core.leaders.base import LeaderState, VirtualLeader
from flock_swarm.core.laws.evaluation import swarm_control
from flock_swarm.core.run import interaction_graph, static_graph
from flock_swarm.core.scenario import realize
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.controller import AgentController
from flock_swarm.nodes.guard import InputGuard, Limits
from flock_swarm.nodes.leader_watch import LeaderWatch
from flock_swarm.nodes.stepper import WorldSettings, WorldStepper
from flock_swarm.presets import load
from broken_law import nan_command_for

LOG = logging.getLogger('test_stepper')


def small(*overrides: str):
    """Return a four-agent demo scenario of two steps, every step recorded."""
    return load('demo', ['n_agents=4', 'informed.count=2', 'duration=0.2', 'dt=0.1',
                         'record_every=1', *overrides])


def leader_at(sc, k: int) -> LeaderState:
    """Return the virtual leader's state at step ``k`` (as the leader node computes it)."""
    leader = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity)
    for _ in range(k):
        leader.step(sc.dt)
    return leader.state


def started(sc, **settings) -> WorldStepper:
    """Return a lockstep stepper created at t = 0, started and with step 0 open at t = 0."""
    st = WorldStepper(sc, WorldSettings(start_timeout=0.0, **settings), LOG, now=0.0)
    assert st.tick(0.0, lambda: True) == 'begin' and st.started
    st.begin_step(0.0)
    return st


def give_leader(st: WorldStepper, state: LeaderState, k: int, now: float) -> None:
    """Hand the stepper the leader's odometry and acceleration of step ``k``."""
    st.leader_state(k, now, q=state.q.copy(), p=state.p.copy())
    st.leader_state(k, now, a=state.a.copy())


def test_the_decisions_import_without_rclpy():
    """The stepper, the controller, the leader watch, the inboxes, the input guard, the
    clock, the wire codec and the parameter tables load in a process without rclpy."""
    code = ('import sys\n'
            'import flock_swarm.nodes.stepper, flock_swarm.nodes.controller\n'
            'import flock_swarm.nodes.inbox, flock_swarm.nodes.guard, flock_swarm.nodes.clock\n'
            'import flock_swarm.nodes.wire, flock_swarm.nodes.parameters\n'
            'print(sorted(m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "rosidl_runtime_py", "builtin_interfaces", "nav_msgs")))\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, timeout=60)
    assert out.stdout.strip() == '[]'


def test_a_step_is_assembled_and_a_missing_command_zeroed_after_the_timeout(caplog):
    """Commands in for three of four agents: the step waits, is offered again after 0.5 s,
    closes at its 2 s timeout with a zero for the fourth, and integrates as step_agents."""
    sc = small()
    st = started(sc)
    u_in = np.array([[0.5, -0.25], [1.0, 2.0], [-3.0, 0.125]])
    for i in range(3):
        assert st.command(i, 0, u_in[i], 0.1) is False
    give_leader(st, leader_at(sc, 0), 0, 0.1)
    assert not st.complete()
    assert st.tick(0.4, lambda: True) is None
    assert st.tick(0.5, lambda: True) == 'resend' and st.resends == 1
    assert st.tick(2.0, lambda: True) == 'timeout'
    with caplog.at_level(logging.WARNING, logger=LOG.name):
        obs = st.close_step(True, 2.0)
    assert 'no command from agent(s) [3]' in caplog.text
    assert obs.missing == [3] and obs.k == 0 and not obs.last
    assert_array_equal(obs.u, np.vstack([u_in, np.zeros((1, 2))]))
    assert obs.metrics['missed_this_step'] == '[3]' and obs.problems == ['1 missing command(s)']
    assert list(st.missed) == [0, 0, 0, 1]
    real = realize(sc)
    assert st.advance(obs.u)
    q, p = step_agents(real.q0, real.p0, obs.u, sc.dt,
                       sc.intrinsic.velocity_field() if sc.intrinsic is not None else None)
    assert_array_equal(st.q, q)
    assert_array_equal(st.p, p)
    assert st.k == 1 and st.window() == (0, 1)
    # Agent 3's command for the step just closed is late; agent 0's (repeated) is not.
    assert st.command(3, 0, u_in[0], 2.1) is True
    assert st.command(0, 0, u_in[0], 2.1) is False


def test_every_command_and_the_leader_complete_a_step():
    """A step with every command and the leader's state is complete before its timeout."""
    sc = small()
    st = started(sc)
    for i in range(4):
        st.command(i, 0, np.ones(2), 0.01)
    assert not st.complete()
    give_leader(st, leader_at(sc, 0), 0, 0.02)
    assert st.complete()
    obs = st.close_step(False, 0.05)
    assert obs.missing == [] and st.last_step_s == 0.05
    assert_array_equal(obs.leader.q, leader_at(sc, 0).q)


def test_commands_taken_at_once_close_the_step_as_one_by_one():
    """commands_all (the world's batched path) gives the observation that the same commands
    given one by one give, bit for bit; a later command of one agent replaces its row."""
    sc = small()
    u_in = np.array([[0.5, -0.25], [1.0, 2.0], [-3.0, 0.125], [1e-300, -7.0]])
    leader = leader_at(sc, 0)
    one, batch = started(sc), started(sc)
    for i in range(4):
        one.command(i, 0, u_in[i], 0.01)
    batch.commands_all(0, u_in)
    for st in (one, batch):
        give_leader(st, leader, 0, 0.02)
        assert st.complete()
    a, b = one.close_step(False, 0.05), batch.close_step(False, 0.05)
    assert a.missing == b.missing == []
    assert a.u.tobytes() == b.u.tobytes() and b.u is not u_in
    assert a.metrics == b.metrics
    assert one.advance(a.u) and batch.advance(b.u)
    assert one.q.tobytes() == batch.q.tobytes() and one.p.tobytes() == batch.p.tobytes()
    # A command of the wrong step is ignored; a repeated one for the open step replaces.
    for st in (one, batch):
        st.begin_step(0.1)
    batch.commands_all(0, u_in)
    assert not batch.commands
    batch.commands_all(1, u_in)
    batch.command(2, 1, np.array([9.0, 9.0]), 0.11)
    give_leader(batch, leader_at(sc, 1), 1, 0.12)
    assert_array_equal(batch.close_step(False, 0.15).u[2], [9.0, 9.0])


def test_resend_waits_back_off_once_a_step_has_finished():
    """Before any step finished, a stalled step is offered every 0.5 s; after a 1 s step,
    first after three times that (3 s), then after twice as long each time (6 s, 12 s), and
    never later than half the step timeout."""
    sc = small()
    st = started(sc, step_timeout=30.0)
    assert st.resend_at == 0.5
    st.resent(0.5)
    assert st.resend_at == 1.0 and st.resends == 1
    for i in range(4):
        st.command(i, 0, np.zeros(2), 0.9)
    give_leader(st, leader_at(sc, 0), 0, 1.0)
    st.advance(st.close_step(False, 1.0).u)
    st.begin_step(1.0)
    assert st.resend_wait == 3.0 and st.tick(3.9, lambda: True) is None
    assert st.tick(4.0, lambda: True) == 'resend'
    assert st.resend_at == 10.0
    st.resent(10.0)
    assert st.resend_at == 22.0
    short = started(sc, step_timeout=0.3)
    assert short.resend_at == 0.15


def test_the_start_waits_for_everybody_or_the_start_timeout(caplog):
    """Nobody there: no start before the start timeout (5 s), then a start with a warning;
    step 0 waits out what is left of the start timeout, later steps the step timeout."""
    sc = small()
    st = WorldStepper(sc, WorldSettings(start_timeout=5.0), LOG, now=0.0)
    assert st.tick(4.9, lambda: False) is None and not st.started
    with caplog.at_level(logging.WARNING, logger=LOG.name):
        assert st.tick(5.0, lambda: False) == 'begin'
    assert 'start timeout: starting without every agent or the leader' in caplog.text
    st.begin_step(5.0)
    assert st.deadline == 7.0
    early = WorldStepper(sc, WorldSettings(start_timeout=5.0), LOG, now=0.0)
    assert early.tick(1.0, lambda: True) == 'begin'
    early.begin_step(1.0)
    assert early.deadline == 5.0


def test_the_leader_lost_and_back(caplog):
    """A step closed without the leader's state loses it (the next step waits for no
    leader); a leader message brings it back; both are events of the summary."""
    sc = small()
    st = started(sc)
    for i in range(4):
        st.command(i, 0, np.zeros(2), 0.1)
    assert not st.complete()
    with caplog.at_level(logging.INFO, logger=LOG.name):
        obs = st.close_step(True, 2.0)
        assert 'leader lost at step 0' in caplog.text
        assert st.leader.lost and st.leader_missed == 1
        assert obs.metrics['leader'] == 'lost' and 'leader lost' in obs.problems
        # The leader state used is the last known: the scenario's initial one.
        assert_array_equal(obs.leader.q, sc.leader.position)
        st.advance(obs.u)
        st.begin_step(2.0)
        for i in range(4):
            st.command(i, 1, np.zeros(2), 2.1)
        assert st.complete()
        give_leader(st, leader_at(sc, 1), 1, 2.2)
        assert 'leader back at step 1' in caplog.text
    assert not st.leader.lost
    assert st.leader.events == [[0, 'lost'], [1, 'back']]


def test_leader_watch_counts_each_loss_once():
    """Losing a lost leader changes nothing; hearing it ends the loss once."""
    watch = LeaderWatch(seen_at=5.0)
    assert watch.silent_for(5.5) == 0.5 and not watch.ever_heard
    assert watch.heard(0, 6.0) is False
    assert watch.lose(3) is True and watch.lose(4) is False
    assert watch.heard(5, 7.0) is True and watch.heard(6, 7.1) is False
    assert watch.events == [[3, 'lost'], [5, 'back']] and watch.silent_for(8.1) == 1.0


def test_the_summary_of_a_run_to_its_end():
    """Two steps to the end: the summary has the scenario's totals and the world's counts,
    the series every step from the initial state."""
    sc = small()
    st = started(sc)
    # Before anything was recorded (a world stopped before its first step): no time series,
    # and no measure in the summary, but everything the run knows (issue 23).
    empty = st.result(0.0, {}, [], None, None)
    assert empty.series == {} and empty.summary['steps'] == 0
    assert empty.summary['t_final'] is None and empty.summary['eta'] is None
    assert empty.summary['n_agents'] == 4 and empty.summary['missed_commands'] == 0
    real = realize(sc)
    for k in range(sc.steps + 1):
        for i in range(4 if k != 1 else 3):
            st.command(i, k, np.full(2, 0.5), 1.0 * k)
        give_leader(st, leader_at(sc, k), k, 1.0 * k)
        obs = st.close_step(k == 1, 1.0 * k + 0.5)
        if obs.last:
            break
        st.advance(obs.u)
        st.begin_step(1.0 * k + 0.5)
    assert obs.last and obs.k == sc.steps == 2 and obs.markers and obs.metrics is not None
    assert st.end('completed') and not st.end('interrupted')
    res = st.result(4.0, {'late': 2}, [1], None, '/x/bag')
    s = res.summary
    assert s['status'] == 'completed' and s['steps'] == 2 and s['t_final'] == pytest.approx(0.2)
    assert s['mode'] == 'lockstep' and s['missed_commands'] == 1
    assert s['missed_commands_per_agent'] == [0, 0, 0, 1]
    assert s['rejected_messages'] == {'late': 2} and s['duplicate_agent_ids'] == [1]
    assert s['bag'] == '/x/bag' and s['bag_error'] is None and s['wall_time_s'] == 4.0
    assert s['leader_events'] == [] and s['command_latency_ms'] is None
    assert s['n_agents'] == 4 and s['informed'] == list(real.informed_ids)
    assert res.series['q'].shape == (3, 4, 2)
    assert_array_equal(res.series['q'][0], real.q0)
    assert_array_equal(res.series['u'][1][3], np.zeros(2))


def test_realtime_holds_commands_and_zeroes_stale_ones(caplog):
    """Realtime: the latest command is held; one older than the staleness is zero (logged
    once); a command answering a published step gives a latency."""
    sc = small()
    st = WorldStepper(sc, WorldSettings(lockstep=False, staleness=0.5), LOG, now=0.0)
    st.realtime_begin(1.0)
    obs = st.realtime_close(1.0, 1.01)
    assert obs.missing == [] and st.started
    st.command(2, 0, np.array([0.25, 0.5]), 1.2)
    assert st.latency.count == 1
    assert st.advance(obs.u)
    with caplog.at_level(logging.INFO, logger=LOG.name):
        st.realtime_begin(1.6)
        obs = st.realtime_close(1.6, 1.61)
    assert obs.missing == [0, 1, 3]
    assert_array_equal(obs.u, [[0, 0], [0, 0], [0.25, 0.5], [0, 0]])
    assert caplog.text.count('sent no command for 0.5 s') == 3
    assert st.result(2.0, {}, [], None, None).summary['mode'] == 'realtime'


def inputs_of(ctrl: AgentController, sc, k: int, q, p, leader: LeaderState | None) -> None:
    """Fill the controller's buffer of step ``k`` as the node does from messages."""
    box = ctrl.inputs(k)
    for j in range(sc.n_agents):
        box.odom[j] = (tuple(q[j]), tuple(p[j]))
    if leader is not None:
        box.leader_odom = (tuple(leader.q), tuple(leader.p))
        box.leader_accel = tuple(leader.a)


def sim_commands(sc, q, p, leader):
    """Return every agent's command as ``sim`` computes it."""
    real = realize(sc)
    edges = interaction_graph(sc, real, q, static_graph(sc, real))
    return swarm_control(sc.law, q, p, edges, leader, real.agents, sc.dt)


def test_controller_answers_what_sim_computes():
    """The commands of hosted agents 1 and 3 for a complete step are sim's rows."""
    sc = small()
    real = realize(sc)
    ctrl = AgentController(sc, [1, 3], LOG, now=0.0)
    leader = leader_at(sc, 0)
    inputs_of(ctrl, sc, 0, real.q0, real.p0, leader)
    assert ctrl.ready(0, 0.0)
    u = ctrl.answer(0)
    assert_array_equal(u, sim_commands(sc, real.q0, real.p0, leader)[[1, 3]])
    assert ctrl.answered == 0 and ctrl.inputs(0) is None


def test_a_step_stored_at_once_answers_what_sim_computes():
    """A step's odometry stored in one pass (``put_all``, the batched path) gives sim's
    commands bit for bit; a later message of one agent (``put``) replaces its row."""
    sc = small()
    real = realize(sc)
    ctrl = AgentController(sc, [0, 2], LOG, now=0.0)
    leader = leader_at(sc, 0)
    box = ctrl.inputs(0)
    box.put(1, ((9.0, 9.0), (9.0, 9.0)))
    box.put_all(np.stack((real.q0, real.p0), axis=1))
    assert not box.odom and box.has_odometry(sc.n_agents)
    box.leader_odom, box.leader_accel = (tuple(leader.q), tuple(leader.p)), tuple(leader.a)
    assert ctrl.ready(0, 0.0)
    assert_array_equal(ctrl.answer(0), sim_commands(sc, real.q0, real.p0, leader)[[0, 2]])
    box = ctrl.inputs(1)
    box.put_all(np.stack((real.q0, real.p0), axis=1))
    box.put(3, ((1.0, 2.0), (3.0, 4.0)))
    q, p, _ = box.swarm(sc.n_agents)
    assert_array_equal(q[3], [1.0, 2.0]) and assert_array_equal(p[3], [3.0, 4.0])
    assert_array_equal(q[:3], real.q0[:3])


@pytest.mark.parametrize('bad, value', [('position', np.nan), ('position', np.inf),
                                        ('position', 2e6), ('velocity', -2e4)])
def test_a_batch_the_guard_might_reject_is_left_to_the_one_by_one_checks(bad, value):
    """pass_batch accepts only what check would accept for every message, and counts
    nothing: the caller checks a refused batch message by message."""
    clock = StepClock(0.02)
    guard = InputGuard(clock, Limits(), LOG.warning)
    q, p = np.zeros((5, 3)), np.ones((5, 3))
    topics = [f'/agent_{j}/odom' for j in range(5)]
    values = lambda: ((q, 1e6), (p, 1e4))  # noqa: E731
    assert guard.pass_batch(topics, 60_000_000, values()) == 3
    assert guard.latest == dict.fromkeys(topics, 3)
    assert guard.pass_batch(topics, 60_000_001, values()) is None      # off the grid
    (q if bad == 'position' else p)[2, 1] = value
    assert guard.pass_batch(topics, 80_000_000, values()) is None
    assert not guard.rejected and guard.latest == dict.fromkeys(topics, 3)


def test_controller_waits_for_the_leader_then_applies_the_uninformed_law(caplog):
    """Odometry complete, no leader state: the step waits leader_start_timeout before the
    leader was ever heard, leader_timeout after, counted from its last message."""
    sc = small()
    real = realize(sc)
    ctrl = AgentController(sc, [0, 1, 2, 3], LOG, leader_timeout=1.0,
                           leader_start_timeout=30.0, now=0.0)
    inputs_of(ctrl, sc, 0, real.q0, real.p0, None)
    with caplog.at_level(logging.INFO, logger=LOG.name):
        assert not ctrl.ready(0, 0.0) and ctrl.waiting() == 0
        assert not ctrl.ready(0, 29.9)
        assert ctrl.ready(0, 30.0) and ctrl.leader.lost
        assert 'no leader state for 1 s at step 0' in caplog.text
        ctrl.answer(0)
        ctrl.leader_heard(1, 31.0)
        assert not ctrl.leader.lost and 'leader back at step 1' in caplog.text
    inputs_of(ctrl, sc, 1, real.q0, real.p0, None)
    assert not ctrl.ready(1, 31.0)
    ctrl.leader_heard(1, 31.8)
    assert not ctrl.ready(1, 32.5)
    assert ctrl.ready(1, 32.9) and ctrl.leader.lost


def test_controller_realtime_answers_from_the_latest_inputs():
    """Realtime: nothing before every odometry is in; a leader silent for leader_timeout is
    lost, and the commands are then those without the leader."""
    sc = small()
    real = realize(sc)
    ctrl = AgentController(sc, [0, 1, 2, 3], LOG, leader_timeout=1.0, now=0.0)
    assert ctrl.realtime_answer(0.1) is None
    leader = leader_at(sc, 0)
    for j in range(4):
        ctrl.latest.odom[j] = (tuple(real.q0[j]), tuple(real.p0[j]))
    ctrl.latest.leader_odom = (tuple(leader.q), tuple(leader.p))
    ctrl.latest.leader_accel = tuple(leader.a)
    ctrl.latest_step = 0
    assert_array_equal(ctrl.realtime_answer(0.5), sim_commands(sc, real.q0, real.p0, leader))
    with_leader = ctrl.realtime_answer(0.9)
    without = ctrl.realtime_answer(1.5)
    assert ctrl.leader.lost and not np.array_equal(with_leader, without)


def test_controller_publishes_zero_for_a_non_finite_command(monkeypatch, caplog):
    """With ``non_finite='zero'``, a law returning NaN for agent 1 gives it a zero command,
    counted at every step and logged once; the other agent's command is untouched."""
    nan_command_for(monkeypatch, 1)
    sc = small()
    real = realize(sc)
    ctrl = AgentController(sc, [1, 2], LOG, now=0.0, non_finite='zero')
    leader = leader_at(sc, 0)
    want = sim_commands(sc, real.q0, real.p0, leader)
    with caplog.at_level(logging.WARNING, logger=LOG.name):
        for k in range(2):
            inputs_of(ctrl, sc, k, real.q0, real.p0, leader)
            assert ctrl.ready(k, 0.0)
            u = ctrl.answer(k)
            assert_array_equal(u[0], np.zeros(2))
            assert_array_equal(u[1], want[2])
    assert ctrl.non_finite == {1: 2}
    assert caplog.text.count('agent 1: the law gave a non-finite command') == 1


@pytest.mark.parametrize('preset, shown, hidden', [
    ('su2009_fig6', '  COM error = ', 'eta = '),
    ('demo', '  eta = 0.00  mismatch = 0  missed = 0', 'COM'),
])
def test_the_worlds_progress_line_leads_with_the_headline(preset, shown, hidden):
    """The demo's progress lines give what its experiment is about (eta before a headline)."""
    sc = load(preset, ['duration=0.04'])
    st = WorldStepper(sc, WorldSettings(), LOG, now=0.0)
    line = st.progress_line(10.0, every=0.0)
    assert line.startswith('[world] t = 0.00/0.04 s') and shown in line and hidden not in line
