"""Unit tests of the leader models' velocity fields, the integrators and the virtual leader."""

import numpy as np
from numpy.testing import assert_allclose
import pytest
from scipy.linalg import expm

from flock_swarm.core import dynamics as dyn
from flock_swarm.core import registry
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.leaders import models
from flock_swarm.core.leaders.base import VirtualLeader

# Yu, Chen, Cao 2010 Section 4.1: the leader's velocity field v' = A v.
YU_A = 0.1 * np.array([[0.0, -1.0], [1.0, 0.0]])


def linear(a) -> models.Linear:
    """Return the linear model ``p' = A p``."""
    return models.Linear(tuple(tuple(row) for row in np.asarray(a).tolist()))


def exact_linear_solution(a, q0, p0, t):
    """Return ``(q(t), p(t))`` of ``q' = p, p' = A p`` for invertible ``A``.

    ``p(t) = expm(A t) p0`` and ``q(t) = q0 + A^-1 (expm(A t) - I) p0``.
    """
    e = expm(a * t)
    return q0 + np.linalg.solve(a, (e - np.eye(a.shape[0])) @ p0), e @ p0


# --------------------------------------------------------------------------------------------
# Integrators


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('dt, steps', [(0.1, 500), (0.01, 1000), (0.25, 40)])
def test_double_integrator_exact_for_constant_input(dim, dt, steps):
    rng = np.random.default_rng(dim)
    q0 = rng.uniform(-5.0, 5.0, size=(7, dim))
    p0 = rng.uniform(-1.0, 1.0, size=(7, dim))
    u = rng.uniform(-0.5, 0.5, size=(7, dim))
    q, p = q0, p0
    for _ in range(steps):
        q, p = dyn.step_double_integrator(q, p, u, dt)
    t = steps * dt
    scale = np.abs(q0).max() + np.abs(p0).max() * t + np.abs(u).max() * t * t
    assert_allclose(q, q0 + p0 * t + 0.5 * u * t * t, rtol=1e-12, atol=1e-12 * scale)
    assert_allclose(p, p0 + u * t, rtol=1e-12, atol=1e-12 * (1.0 + np.abs(u).max() * t))


def test_double_integrator_returns_new_arrays():
    q = np.zeros((2, 2))
    p = np.ones((2, 2))
    q1, p1 = dyn.step_double_integrator(q, p, np.ones((2, 2)), 0.5)
    # One step by hand: q = 0 + 1 * 0.5 + 1 * 0.25 / 2, p = 1 + 0.5.
    assert_allclose(q1, 0.625, rtol=0.0)
    assert_allclose(p1, 1.5, rtol=0.0)
    assert_allclose(q, 0.0, rtol=0.0)
    assert_allclose(p, 1.0, rtol=0.0)


@pytest.mark.parametrize('dt', [0.01, 0.1, 1.0])
def test_rk4_with_zero_field_equals_double_integrator(dt):
    rng = np.random.default_rng(9)
    q, p, u = (rng.uniform(-3.0, 3.0, size=(5, 3)) for _ in range(3))
    zero = models.ConstantVelocity().velocity_field()
    q_rk, p_rk = dyn.rk4_step(q, p, u, dt, zero)
    q_di, p_di = dyn.step_double_integrator(q, p, u, dt)
    assert_allclose(q_rk, q_di, rtol=1e-13, atol=1e-13)
    assert_allclose(p_rk, p_di, rtol=1e-13, atol=1e-13)


def test_step_agents_dispatch():
    rng = np.random.default_rng(10)
    q, p, u = (rng.uniform(-1.0, 1.0, size=(4, 2)) for _ in range(3))
    field = linear(YU_A).velocity_field()
    assert_allclose(dyn.step_agents(q, p, u, 0.1, None)[0],
                    q + 0.1 * p + 0.005 * u, rtol=1e-14)
    # With a field the step is RK4 (differs from the double integrator by O(dt |A p|)).
    q_rk, _ = dyn.rk4_step(q, p, u, 0.1, field)
    assert_allclose(dyn.step_agents(q, p, u, 0.1, field)[0], q_rk, rtol=0.0, atol=0.0)


def run_rk4_linear(dt, t_final, q0, p0):
    """Integrate ``q' = p, p' = A p`` with RK4 and return the final state."""
    field = linear(YU_A).velocity_field()
    q, p = q0.copy(), p0.copy()
    for _ in range(int(round(t_final / dt))):
        q, p = dyn.rk4_step(q, p, 0.0, dt, field)
    return q, p


def test_rk4_linear_field_matches_rotation():
    q0 = np.array([[0.5, -0.5]])
    p0 = np.array([[1.0, 2.0]])
    t = 20.0
    q, p = run_rk4_linear(0.1, t, q0, p0)
    q_exact, p_exact = exact_linear_solution(YU_A, q0[0], p0[0], t)
    # RK4's global error is O(t (|A| dt)^4 |p|) ~ 1e-9 here (forward Euler's would be ~1e-2).
    assert_allclose(p[0], p_exact, rtol=1e-8)
    assert_allclose(q[0], q_exact, rtol=1e-8)
    # The field is a rotation: the speed is conserved (RK4 to O((0.1 dt)^5) per step).
    assert_allclose(np.linalg.norm(p), np.linalg.norm(p0), rtol=1e-9)


def test_rk4_fourth_order_convergence():
    q0 = np.array([[0.0, 0.0]])
    p0 = np.array([[1.0, 2.0]])
    t = 20.0
    q_exact, p_exact = exact_linear_solution(YU_A, q0[0], p0[0], t)
    errors = []
    for dt in (2.0, 1.0, 0.5):
        q, p = run_rk4_linear(dt, t, q0, p0)
        errors.append(np.linalg.norm(np.concatenate((q[0] - q_exact, p[0] - p_exact))))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    # Global error C dt^4: halving dt divides it by 2^4 = 16.
    assert_allclose(ratios, 16.0, rtol=0.05)


# --------------------------------------------------------------------------------------------
# Virtual leader


@pytest.mark.parametrize('dim', [2, 3])
def test_virtual_leader_constant_acceleration_exact(dim):
    acc = np.array([-0.3, 0.3, 0.1])[:dim]
    q0 = np.array([10.0, 10.0, 10.0])[:dim]
    p0 = np.array([1.0, 1.0, -2.0])[:dim]
    leader = VirtualLeader(models.ConstantAcceleration(tuple(acc)), q0, p0)
    dt, steps = 0.05, 600
    for _ in range(steps):
        leader.step(dt)
    t = dt * steps
    state = leader.state
    assert_allclose(state.q, q0 + p0 * t + 0.5 * acc * t * t, rtol=1e-12)
    assert_allclose(state.p, p0 + acc * t, rtol=1e-12)
    assert_allclose(state.a, acc, rtol=0.0)


def test_virtual_leader_constant_velocity():
    leader = VirtualLeader(models.ConstantVelocity(), [10.0, 10.0], [1.0, 1.0])
    for _ in range(100):
        leader.step(0.1)
    assert_allclose(leader.state.q, [20.0, 20.0], rtol=1e-13)
    assert_allclose(leader.state.p, [1.0, 1.0], rtol=0.0)
    assert_allclose(leader.state.a, [0.0, 0.0], atol=0.0)


def test_virtual_leader_state_is_a_copy():
    leader = VirtualLeader(models.ConstantVelocity(), [1.0, 2.0], [3.0, 4.0])
    state = leader.state
    state.q[:] = 0.0
    assert_allclose(leader.state.q, [1.0, 2.0], rtol=0.0)


def test_virtual_leader_linear_field_matches_exact():
    q0, p0 = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    leader = VirtualLeader(linear(YU_A), q0, p0)
    for _ in range(300):
        leader.step(0.1)
    q_exact, p_exact = exact_linear_solution(YU_A, q0, p0, 30.0)
    assert_allclose(leader.state.q, q_exact, rtol=1e-8, atol=1e-8)
    assert_allclose(leader.state.p, p_exact, rtol=1e-8, atol=1e-8)
    assert_allclose(leader.state.a, YU_A @ p_exact, rtol=1e-8, atol=1e-8)


# --------------------------------------------------------------------------------------------
# Vector fields


def test_lorenz_hand_value():
    # p = (1, 2, 3): (10 (2 - 1), 28 * 1 - 1 * 3 - 2, 1 * 2 - (8/3) * 3) = (10, 23, -6).
    p = np.array([1.0, 2.0, 3.0])
    expected = np.array([10.0, 23.0, -6.0])
    assert_allclose(models.lorenz(p, 10.0, 28.0, 8.0 / 3.0), expected, rtol=1e-15)
    assert_allclose(models.Lorenz().velocity_field()(p), expected, rtol=1e-15)


def test_lu_hand_value():
    # a = 36, b = 3, c = 20 at (1, 2, 3): (36 (2 - 1), 20 * 2 - 1 * 3, 1 * 2 - 3 * 3).
    p = np.array([1.0, 2.0, 3.0])
    expected = np.array([36.0, 37.0, -7.0])
    assert_allclose(models.lu(p, 36.0, 3.0, 20.0), expected, rtol=1e-15)
    assert_allclose(models.Lu().velocity_field()(p), expected, rtol=1e-15)


def test_field_params_override_defaults():
    # Lorenz with rho = 20 at (1, 2, 3): second component 20 - 3 - 2 = 15.
    p = np.array([1.0, 2.0, 3.0])
    assert_allclose(models.Lorenz(rho=20.0).velocity_field()(p), [10.0, 15.0, -6.0],
                    rtol=1e-15)
    # Lu with c = 10: 10 * 2 - 3 = 17.
    assert_allclose(models.Lu(c=10.0).velocity_field()(p), [36.0, 17.0, -7.0],
                    rtol=1e-15)


@pytest.mark.parametrize('model', [models.Lorenz, models.Lu])
def test_fields_vectorise_over_agents(model):
    rng = np.random.default_rng(12)
    p = rng.uniform(-5.0, 5.0, size=(6, 3))
    f = model().velocity_field()
    batch = f(p)
    assert batch.shape == (6, 3)
    for k in range(6):
        assert_allclose(batch[k], f(p[k]), rtol=1e-15)


def test_constant_and_linear_fields():
    p = np.array([[1.0, 2.0], [-3.0, 0.5]])
    const = models.ConstantAcceleration((0.5, -1.0)).velocity_field()(p)
    assert_allclose(const, [[0.5, -1.0], [0.5, -1.0]], rtol=0.0)
    # A p for A = 0.1 [[0, -1], [1, 0]]: (-0.1 p_y, 0.1 p_x).
    lin = linear(YU_A).velocity_field()(p)
    assert_allclose(lin, [[-0.2, 0.1], [-0.05, -0.3]], rtol=1e-15)


def test_unknown_model_raises():
    with pytest.raises(ScenarioError, match='unknown leader model'):
        registry.leader_class('vanderpol')


def test_model_without_a_jacobian_is_unchecked():
    # A model that does not define its Jacobian must not silently get another model's.
    assert models.LeaderModel.jacobian(models.Lorenz(), np.array([1.0, 2.0, 3.0])) is None


def test_time_dependent_model_is_no_velocity_field():
    class Swing(models.LeaderModel):
        name = 'swing'
        autonomous = False

        def acceleration(self, t, q, p):
            return np.full_like(p, np.cos(t))

    with pytest.raises(ValueError, match='depends on time'):
        Swing().velocity_field()


def test_models_are_comparable_and_printable():
    # Models are frozen dataclasses: equal parameters compare equal (runs stack only with
    # equal leaders), and the repr names the model and the parameters.
    a = models.Lorenz(rho=20.0)
    assert a == models.Lorenz(rho=20.0)
    assert a != models.Lorenz(rho=28.0)
    assert 'Lorenz' in repr(a) and 'rho=20.0' in repr(a)


@pytest.mark.parametrize('spec', [
    models.Lorenz(),
    models.Lorenz(sigma=5.0, rho=20.0, beta=1.0),
    models.Lu(),
    models.Lu(a=30.0, b=2.0, c=15.0),
    linear(0.1 * np.array([[0.0, -1.0, 0.0],
                           [1.0, 0.0, 0.0],
                           [0.0, 0.0, -2.0]])),
    models.ConstantAcceleration((1.0, 2.0, 3.0)),
    models.ConstantVelocity(),
])
def test_jacobian_matches_finite_differences(spec):
    rng = np.random.default_rng(13)
    f = spec.velocity_field()
    step = 1e-6
    for p in rng.uniform(-10.0, 10.0, size=(5, 3)):
        fd = np.empty((3, 3))
        for k in range(3):
            e = np.zeros(3)
            e[k] = step
            fd[:, k] = (f(p + e) - f(p - e)) / (2.0 * step)
        # The fields are at most quadratic, so central differences are exact up to round-off.
        assert_allclose(spec.jacobian(p), fd, rtol=0.0, atol=1e-7)
