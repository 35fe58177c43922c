"""Latency prediction (flock_swarm.core.latency): a measured plant state carried forward to
the moment a command applies, through the plant's own exact step, against independent
formulas; the identity when the state is current (lockstep); the agents' controller using it
in realtime only."""

import copy
import math
import os
import subprocess

import numpy as np
import pytest

from flock_swarm.core.latency import CommandHistory, extrapolate, hold
from flock_swarm.core.plants.models import DoubleIntegrator, Unicycle, VelocityLag
from flock_swarm.nodes.swarm_runner import executable
from flock_swarm.nodes.controller import AgentController
from flock_swarm.presets import prepare
from test_robots_ros import FLEET, FLEET_FILE

RNG = np.random.default_rng(36)
#: Two states of each plant: a robot at rest and one moving (and turning).
STATES = {
    'velocity_lag': (VelocityLag(tau=0.1), np.array([[0.0, 0.0, 0.0, 0.0],
                                                     [1.0, -2.0, 0.3, -0.1]])),
    'unicycle': (Unicycle(ell=0.1), np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
                                              [1.0, 2.0, math.sin(0.4), math.cos(0.4),
                                               0.2, 0.7]])),
    'double_integrator': (DoubleIntegrator(), np.array([[0.0, 0.0, 0.0, 0.0],
                                                        [1.0, -2.0, 0.3, -0.1]])),
}


@pytest.mark.parametrize('name', sorted(STATES))
def test_a_current_state_is_predicted_as_it_is_bit_for_bit(name):
    """Lockstep: the state is exact and of the step the command applies at: the prediction
    is the identity, whatever commands were sent before."""
    plant, x = STATES[name]
    history = CommandHistory(plant, accelerations=name == 'double_integrator', period=0.05)
    history.sent(0.05, RNG.normal(size=(2, 2)))
    history.sent(0.10, RNG.normal(size=(2, 2)))
    for t in (0.0, 0.05, 0.10, 0.15):
        assert np.array_equal(history.predict(x, t, t), x)
        assert np.array_equal(history.predict(x, t + 0.05, t), x)
    assert np.array_equal(extrapolate(plant, x, 0.0), x)


def test_a_velocity_lag_robot_is_predicted_by_the_exact_lag():
    """``v(t) = v_sp + (v0 - v_sp) exp(-t / tau)`` and its integral over each command's span,
    the measurement taken mid-span."""
    tau = 0.1
    plant, x = STATES['velocity_lag']
    c1, c2 = np.array([[0.2, 0.1], [-0.1, 0.0]]), np.array([[0.0, 0.3], [0.1, 0.1]])
    history = CommandHistory(plant)
    history.sent(0.00, c1)
    history.sent(0.05, c2)
    got = history.predict(x, 0.02, 0.12)

    def lag(q, v, v_sp, h):
        e = math.exp(-h / tau)
        return q + v_sp * h + (v - v_sp) * tau * (1 - e), v_sp + (v - v_sp) * e
    q, v = x[:, :2], x[:, 2:]
    q, v = lag(q, v, c1, 0.03)
    q, v = lag(q, v, c2, 0.07)
    np.testing.assert_allclose(got, np.hstack([q, v]), rtol=0, atol=1e-15)


def test_a_unicycle_is_predicted_along_its_arcs():
    """Each command ``(v, omega)`` held: the axle on a circle of radius ``v / omega`` (fine
    Euler integration as the independent reference), the heading turned by ``omega h``."""
    plant, x = STATES['unicycle']
    cmds = [np.array([[0.2, 0.0], [0.1, -1.0]]), np.array([[0.15, 0.5], [0.22, 2.0]])]
    history = CommandHistory(plant)
    history.sent(0.05, cmds[0])
    history.sent(0.10, cmds[1])
    got = history.predict(x, 0.0, 0.18)
    # The reference: before the first command the robot keeps its (v, omega).
    theta = 2.0 * np.arctan2(x[:, 2], x[:, 3])
    pos, n = x[:, :2].copy(), 20000
    for cmd, span in ((x[:, 4:6], 0.05), (cmds[0], 0.05), (cmds[1], 0.08)):
        h = span / n
        for _ in range(n):
            mid = theta + 0.5 * cmd[:, 1] * h
            pos += cmd[:, :1] * h * np.column_stack([np.cos(mid), np.sin(mid)])
            theta = theta + cmd[:, 1] * h
    np.testing.assert_allclose(got[:, :2], pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(2.0 * np.arctan2(got[:, 2], got[:, 3]),
                               np.remainder(theta + np.pi, 2 * np.pi) - np.pi, atol=1e-12)
    np.testing.assert_array_equal(got[:, 4:], cmds[1])


def test_accelerations_sent_are_the_double_integrators_exact_hold():
    """``q + p h + u h^2 / 2``, ``p + u h`` per span; the rows of a host's commands picked."""
    plant, x = STATES['double_integrator']
    u = np.array([[1.0, 0.0], [0.0, 2.0], [5.0, 5.0]])
    history = CommandHistory(plant, accelerations=True, period=0.05)
    history.sent(0.0, u)
    got = history.predict(x, 0.0, 0.1, rows=[0, 1])
    h, a = 0.1, u[:2]
    want = np.hstack([x[:, :2] + x[:, 2:] * h + 0.5 * a * h * h, x[:, 2:] + a * h])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


def test_each_row_is_predicted_from_its_own_measurement_time():
    """Two robots measured at different times, one already past the apply time: the older
    one is carried further, the other is returned as it is; a command noted again for the
    same time replaces the first."""
    plant, x = STATES['velocity_lag']
    history = CommandHistory(plant)
    history.sent(0.0, np.array([[9.0, 9.0], [9.0, 9.0]]))
    history.sent(0.0, np.array([[0.5, 0.0], [0.5, 0.0]]))
    assert len(history.times) == 1
    got = history.predict(x, np.array([0.0, 0.2]), 0.1)
    want = plant.step(x[:1], np.array([[0.5, 0.0]]), 0.1)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], x[1])


@pytest.mark.parametrize('name', sorted(STATES))
def test_neighbours_are_extrapolated_at_constant_velocity(name):
    """No commands known: the plant keeps its velocity (a unicycle its ``v``, ``omega``)."""
    plant, x = STATES[name]
    ages = np.array([0.3, 0.1])
    got = extrapolate(plant, x, ages)
    if name == 'unicycle':
        np.testing.assert_array_equal(got[:, 4:], x[:, 4:])
        theta = 2.0 * np.arctan2(x[:, 2], x[:, 3])
        v, w = x[:, 4], x[:, 5]
        # The exact arc: the chord of a circle of radius v / omega.
        with np.errstate(invalid='ignore', divide='ignore'):
            dx = np.where(w == 0, v * ages * np.cos(theta),
                          v / w * (np.sin(theta + w * ages) - np.sin(theta)))
            dy = np.where(w == 0, v * ages * np.sin(theta),
                          v / w * (np.cos(theta) - np.cos(theta + w * ages)))
        np.testing.assert_allclose(got[:, :2] - x[:, :2], np.column_stack([dx, dy]),
                                   atol=1e-15)
    else:
        np.testing.assert_allclose(got, np.hstack([x[:, :2] + x[:, 2:] * ages[:, None],
                                                   x[:, 2:]]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(hold(plant, x, 0.05).shape, (2, 2))


def fleet_controller(latency: str) -> AgentController:
    """Return the controller of all six robots of the TurtleBot3 fleet (cmd_vel)."""
    sc, _ = prepare(copy.deepcopy(FLEET))
    return AgentController(sc, range(6), now=0.0, latency=latency, velocity=True)


def fleet_inputs(controller: AgentController):
    """Return the fleet's initial state, its odometry rows and the leader's odometry."""
    plant, real = controller.plant, controller.real
    x = plant.initial_state(real.q0, real.p0)
    position, orientation, linear, angular = plant.odometry(x)
    rows = [(position[j, :2], linear[j, :2], orientation[j, 2:], np.array([angular[j, 2], 0.0]))
            for j in range(len(x))]
    leader = (np.zeros(2), np.array([0.1, 0.0]))
    return x, rows, leader


def test_the_controller_predicts_in_realtime_only():
    """Lockstep (``answer``): the commands are those of the measured state whatever
    ``latency`` says, bit for bit. Realtime: the states are predicted to the step after the
    newest odometry's (the next world tick), the robots through the commands sent."""
    lockstep = {}
    for latency in ('predict', 'off'):
        c = fleet_controller(latency)
        x, rows, leader = fleet_inputs(c)
        box = c.inputs(4)
        for j, row in enumerate(rows):
            box.put(j, row)
        box.leader_odom, box.leader_accel = leader, np.zeros(2)
        u = c.answer(4)
        lockstep[latency] = (u, c.velocity_commands(u, 'body'))
        assert c.apply_at is None
    for a, b in zip(lockstep['predict'], lockstep['off']):
        for m, n in zip(a, b):
            np.testing.assert_array_equal(m, n)
    c = fleet_controller('predict')
    x, rows, leader = fleet_inputs(c)
    sent = np.array([[0.1, 0.5]] * 6)
    c.history.sent(4 * c.sc.dt, sent)
    for j, row in enumerate(rows):
        c.heard(j, 4, row, now=100.0)
    c.latest.leader_odom, c.latest.leader_accel = leader, np.zeros(2)
    c.leader.heard(4, 100.0)
    # 0.01 s after step 4's odometry came: the command applies at step 5's tick.
    u = c.realtime_answer(100.01)
    assert c.apply_at == 5 * c.sc.dt
    np.testing.assert_array_equal(c.x, c.plant.step(x, sent, 5 * c.sc.dt - 4 * c.sc.dt))
    q, p = c.plant.law_state(c.x)
    want = c.command(q, p, c.latest.swarm(6)[2], k=4)
    np.testing.assert_array_equal(u, want)
    # A timer that fires late (1.3 periods after the odometry): the command applies at 6.
    c.realtime_answer(100.0 + 1.3 * c.sc.dt)
    assert c.apply_at == 6 * c.sc.dt


def test_a_bad_latency_is_one_line(ros_domain):
    """The agents' ``latency`` parameter: one line naming it, exit status 2."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    res = subprocess.run(executable('agents') + ['--ros-args', '-p', f'scenario:={FLEET_FILE}',
                                                 '-p', 'latency:=ahead'],
                         env=env, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip().splitlines() == [
        "agents: error: latency: must be 'predict' or 'off', got 'ahead'"]
