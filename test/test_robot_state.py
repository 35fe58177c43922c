"""A robot's measured state as a plant state (flock_swarm.core.robot_state)."""

import math

import numpy as np
import pytest

from flock_swarm.core.plants.models import Unicycle, VelocityLag
from flock_swarm.core.robot_state import from_command, PoseDifferentiator, plant_state, rotate
from flock_swarm.core.robot_state import world_velocity
from flock_swarm.core.robot_state import yaw_of


def yaw_q(yaw: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


@pytest.mark.parametrize('yaw', [-3.0, -0.5, 0.0, 1.0, 3.1])
def test_yaw_of_and_rotate(yaw):
    assert yaw_of(yaw_q(yaw)) == pytest.approx(yaw, abs=1e-12)
    np.testing.assert_allclose(rotate(yaw_q(yaw), [1.0, 0.0, 0.0]),
                               [math.cos(yaw), math.sin(yaw), 0.0], atol=1e-12)


def test_a_body_twist_is_rotated_into_the_world():
    np.testing.assert_allclose(world_velocity(yaw_q(math.pi / 2), [0.2, 0.0, 0.0]),
                               [0.0, 0.2, 0.0], atol=1e-12)


def test_plant_states():
    from flock_swarm.core.plants.models import Unicycle, VelocityLag
    pos, vel = np.array([1.0, 2.0, 0.0]), np.array([0.0, 0.3, 0.0])
    np.testing.assert_allclose(plant_state(VelocityLag(), 2, pos, yaw_q(0.4), vel, 0.7),
                               [1.0, 2.0, 0.0, 0.3])
    x = plant_state(Unicycle(), 2, pos, yaw_q(math.pi / 2), vel, 0.7)
    np.testing.assert_allclose(x, [1.0, 2.0, math.sin(math.pi / 4), math.cos(math.pi / 4),
                                   0.3, 0.7], atol=1e-12)


def test_the_differentiator_recovers_a_constant_motion():
    est = PoseDifferentiator(tau=0.0)
    for k in range(5):
        t = 0.01 * k
        assert est.update(t, [0.2 * t, -0.1 * t, 0.0], yaw_q(0.5 * t + 3.1))
    np.testing.assert_allclose(est.velocity, [0.2, -0.1, 0.0], atol=1e-9)
    # The yaw crossed +-pi: the wrapped difference still gives the rate.
    assert est.yaw_rate == pytest.approx(0.5, abs=1e-6)


def test_the_differentiator_smooths_jitter_and_ignores_old_poses():
    rng = np.random.default_rng(3)
    raw, smooth = PoseDifferentiator(tau=0.0), PoseDifferentiator(tau=0.05)
    errors_raw, errors_smooth = [], []
    for k in range(200):
        t = k / 200.0
        pos = np.array([0.1 * t, 0.0, 0.0]) + rng.normal(0.0, 0.001, 3)
        raw.update(t, pos, yaw_q(0.0))
        smooth.update(t, pos, yaw_q(0.0))
        if k > 50:
            errors_raw.append(abs(raw.velocity[0] - 0.1))
            errors_smooth.append(abs(smooth.velocity[0] - 0.1))
    assert np.mean(errors_smooth) < 0.3 * np.mean(errors_raw)
    assert not smooth.update(0.5, [0.0, 0.0, 0.0], yaw_q(0.0))


def test_from_command_replaces_the_velocity_columns():
    """The plant says which columns are its velocities (the robot agent asked the name)."""
    x = np.array([[1.0, 2.0, 0.1, 0.99, 0.3, 0.7]])
    np.testing.assert_array_equal(from_command(Unicycle(), x, np.array([[0.05, -0.2]])),
                                  [[1.0, 2.0, 0.1, 0.99, 0.05, -0.2]])
    x = np.array([[1.0, 2.0, 0.3, 0.4]])
    np.testing.assert_array_equal(from_command(VelocityLag(), x, np.array([[0.0, 0.1]])),
                                  [[1.0, 2.0, 0.0, 0.1]])
