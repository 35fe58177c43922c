"""The safety layer (flock_swarm.core.safety): every rule on its own, and their order."""

import numpy as np
import pytest

from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.safety import ESTOP, GEOFENCE, NON_FINITE, STALE_LEADER, STALE_OWN
from flock_swarm.core.safety import SafetyLayer, SafetyLimits

FRESH = {'own_stamp': 10.0, 'leader_stamp': 10.0, 'position': np.zeros(2), 'estop': False}


def run(limits: SafetyLimits, linear, yaw: float = 0.0, now: float = 10.0, **state):
    """Return the verdict of one fresh layer on one command."""
    return SafetyLayer(limits).filter(now, np.asarray(linear, dtype=float), yaw,
                                      **{**FRESH, **state})


def test_no_limits_pass_the_command_unchanged():
    v = run(SafetyLimits(), [0.3, -0.2, 0.0], 1.5)
    assert v.stop == '' and not v.saturated
    np.testing.assert_array_equal(v.linear, [0.3, -0.2, 0.0])
    assert v.yaw_rate == 1.5


def test_speed_is_shortened_along_its_direction():
    v = run(SafetyLimits(max_speed=0.2), [0.3, 0.4, 0.0])
    np.testing.assert_allclose(v.linear, [0.12, 0.16, 0.0], rtol=1e-12)
    assert v.saturated


def test_yaw_rate_is_clipped():
    assert run(SafetyLimits(max_yaw_rate=2.84), [0, 0, 0], -5.0).yaw_rate == -2.84
    assert run(SafetyLimits(max_yaw_rate=2.84), [0, 0, 0], 1.0).yaw_rate == 1.0


def test_acceleration_limits_the_change_per_second():
    layer = SafetyLayer(SafetyLimits(max_accel=0.5))
    fresh = FRESH | {'own_stamp': 0.0, 'leader_stamp': 0.0}
    # The first command starts from rest: no time has passed, so it is zero.
    first = layer.filter(0.0, np.array([1.0, 0.0, 0.0]), 0.0, **fresh)
    np.testing.assert_array_equal(first.linear, [0.0, 0.0, 0.0])
    assert first.saturated and first.stop == ''
    second = layer.filter(0.1, np.array([1.0, 0.0, 0.0]), 0.0, **fresh)
    np.testing.assert_allclose(second.linear, [0.05, 0.0, 0.0], rtol=1e-12)
    # The change is shortened along its direction.
    third = layer.filter(0.2, np.array([0.05, 1.0, 0.0]), 0.0, **fresh)
    np.testing.assert_allclose(third.linear, [0.05, 0.05, 0.0], rtol=1e-12)
    # A stop resets the ramp: the next command starts again from zero.
    layer.filter(0.3, np.array([1.0, 1.0, 0.0]), 0.0, **FRESH | {'estop': True})
    fourth = layer.filter(0.5, np.array([1.0, 0.0, 0.0]), 0.0, **fresh)
    np.testing.assert_allclose(fourth.linear, [0.1, 0.0, 0.0], rtol=1e-12)


def test_emergency_stop_zeroes_the_command():
    v = run(SafetyLimits(), [0.2, 0.0, 0.0], 1.0, estop=True)
    assert v.stop == ESTOP and v.yaw_rate == 0.0
    np.testing.assert_array_equal(v.linear, np.zeros(3))


@pytest.mark.parametrize('state, reason', [
    ({'own_stamp': 9.4}, STALE_OWN), ({'own_stamp': None}, STALE_OWN),
    ({'leader_stamp': 9.0}, STALE_LEADER), ({'leader_stamp': None}, STALE_LEADER)])
def test_stale_state_stops(state, reason):
    v = run(SafetyLimits(stale_after=0.5), [0.2, 0.0, 0.0], 1.0, **state)
    assert v.stop == reason
    np.testing.assert_array_equal(v.linear, np.zeros(3))


def test_state_just_within_the_bound_passes():
    assert run(SafetyLimits(stale_after=0.5), [0.2, 0, 0], own_stamp=9.5).stop == ''


@pytest.mark.parametrize('position, stop', [([0.0, 0.0], ''), ([2.1, 0.0], GEOFENCE),
                                            ([0.0, -1.01], GEOFENCE), ([2.0, 1.0], ''),
                                            (None, GEOFENCE)])
def test_geofence(position, stop):
    limits = SafetyLimits(fence_min=(-2.0, -1.0), fence_max=(2.0, 1.0))
    assert run(limits, [0.1, 0, 0], position=position).stop == stop


def test_a_3d_fence_checks_altitude_and_a_ground_robots_plane():
    limits = SafetyLimits(fence_min=(-2.0, -2.0, 0.0), fence_max=(2.0, 2.0, 1.5))
    assert run(limits, [0.1, 0, 0], position=np.array([0.0, 0.0, 1.6])).stop == GEOFENCE
    assert run(limits, [0.1, 0, 0], position=np.array([0.0, 0.0])).stop == ''


def test_non_finite_commands_stop():
    assert run(SafetyLimits(), [np.nan, 0, 0]).stop == NON_FINITE
    assert run(SafetyLimits(), [0, 0, 0], np.inf).stop == NON_FINITE


def test_rules_fire_in_order_and_are_counted():
    layer = SafetyLayer(SafetyLimits(stale_after=0.5, fence_min=(0, 0), fence_max=(1, 1)))
    v = layer.filter(10.0, np.array([np.nan, 0, 0]), 0.0, own_stamp=None, leader_stamp=None,
                     position=np.array([5.0, 5.0]), estop=True)
    assert v.stop == ESTOP
    v = layer.filter(10.0, np.array([np.nan, 0, 0]), 0.0, own_stamp=None, leader_stamp=None,
                     position=np.array([5.0, 5.0]), estop=False)
    assert v.stop == STALE_OWN
    assert layer.counts[ESTOP] == 1 and layer.counts[STALE_OWN] == 1


@pytest.mark.parametrize('limits, key', [
    (SafetyLimits(max_speed=0.0), 'safety.max_speed'),
    (SafetyLimits(max_accel=-1.0), 'safety.max_accel'),
    (SafetyLimits(max_yaw_rate=float('nan')), 'safety.max_yaw_rate'),
    (SafetyLimits(stale_after=float('inf')), 'safety.stale_after'),
    (SafetyLimits(fence_min=(0.0, 0.0), fence_max=(1.0,)), 'safety.fence_max'),
    (SafetyLimits(fence_min=(0.0,), fence_max=(1.0,)), 'safety.fence_min'),
    (SafetyLimits(fence_min=(0.0, 2.0), fence_max=(1.0, 1.0)), 'safety.fence_max')])
def test_bad_limits_are_one_line_naming_the_key(limits, key):
    with pytest.raises(ScenarioError) as err:
        SafetyLayer(limits)
    assert err.value.key == key and '\n' not in str(err.value)
