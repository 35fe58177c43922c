"""The plant models (core/plants): registry, the ``plant:`` section, and each model's numerics.

Oracles: closed forms of the first-order lag and of the unicycle's arc, composition of exact
steps, the near-identity map's inverse, and the double integrator's zero-order hold.
"""

import subprocess

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flock_swarm.core import registry
from flock_swarm.core.dynamics import step_double_integrator
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.plants.spec import PlantSpec, parse_plant
from flock_swarm.core.plants.models import DoubleIntegrator, Unicycle, VelocityLag
from flock_swarm.core.scenario import parse_scenario
from flock_swarm.presets import load_mapping


def states(seed: int, n: int, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return (rng.uniform(-5, 5, (n, dim)), rng.uniform(-1, 1, (n, dim)),
            rng.uniform(-3, 3, (n, dim)))


def test_the_built_in_plants_are_registered_like_plugins():
    assert registry.names(registry.PLANT_GROUP) == ['double_integrator', 'unicycle',
                                                    'velocity_lag']
    assert registry.plant_class('unicycle') is Unicycle
    with pytest.raises(ScenarioError, match=r'^plant\.model: unknown plant model .bicycle.'):
        registry.plant_class('bicycle')


def sim_main(argv: list[str], capfd) -> subprocess.CompletedProcess:
    """Run ``sim``'s ``main(argv)`` in this process, its file descriptors captured (a process
    took about a second of imports; ``sim``'s real processes are test_scenario_validation's).
    """
    from flock_swarm.cli.sim import main
    capfd.readouterr()
    try:
        status = main(argv)
    except SystemExit as end:
        status = end.code
    out = capfd.readouterr()
    return subprocess.CompletedProcess(['sim', *argv], status, out.out, out.err)


def test_sim_list_shows_the_plants(capfd):
    result = sim_main(['--list'], capfd)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    section = out.split('plant models (plant.model):')[1]
    for name in ('double_integrator', 'velocity_lag', 'unicycle'):
        assert name in section


def test_an_absent_section_is_todays_double_integrator():
    data = load_mapping('su2009_fig2')
    assert parse_scenario(data).plant == PlantSpec()
    assert PlantSpec().default and PlantSpec().command == 'accel'


@pytest.mark.parametrize('section, dim, key, reason', [
    ({'model': 'unicycle'}, 3, 'plant.model', 'needs dim = 2'),
    ({'model': 'velocity_lag', 'tau': -1}, 2, 'plant.tau', 'must be > 0'),
    ({'model': 'velocity_lag', 'tau': 'x'}, 2, 'plant.tau', 'expected a number'),
    ({'model': 'velocity_lag', 'ell': 1}, 2, 'plant.ell', 'unknown key'),
    ({'model': 'unicycle', 'max_yaw_rate': 0}, 2, 'plant.max_yaw_rate', 'must be > 0'),
    ({'model': 'double_integrator', 'command': 'cmd_vel'}, 2, 'plant.command',
     'expected one of: accel'),
    ({'model': 'velocity_lag', 'frame': 'body'}, 2, 'plant.frame', 'expected one of: world'),
    ({'model': 'velocity_lag', 'conversion': 'foo'}, 2, 'plant.conversion',
     'expected one of: exact, naive'),
    ({'model': 'unicycle', 'conversion': 1}, 2, 'plant.conversion', 'unknown value 1'),
    ({'model': 'velocity_lag', 'conversion_tau': 0}, 2, 'plant.conversion_tau', 'must be > 0'),
    ({'model': 'velocity_lag', 'conversion': 'naive', 'conversion_tau': 0.2}, 2,
     'plant.conversion_tau', 'only with conversion: exact'),
    ({'model': 'unicycle', 'conversion_tau': 0.2}, 2, 'plant.conversion_tau', 'unknown key'),
    ({'model': 'unicycle', 'frame': 'map'}, 2, 'plant.frame', 'expected one of: body, world'),
    ('unicycle', 2, 'plant', 'expected a mapping'),
])
def test_an_invalid_section_names_its_key(section, dim, key, reason):
    with pytest.raises(ScenarioError) as err:
        parse_plant(section, dim, registry.plant_class)
    assert err.value.key == key and reason in err.value.reason
    assert '\n' not in str(err.value)


def test_defaults_per_plant():
    spec = parse_plant({'model': 'unicycle', 'ell': 0.2, 'max_speed': 0.22}, 2,
                       registry.plant_class)
    assert (spec.command, spec.frame) == ('cmd_vel', 'body')
    assert spec.model == Unicycle(ell=0.2, max_speed=0.22)
    assert spec.model.limits() == {'max_speed': 0.22, 'max_yaw_rate': None,
                                   'max_accel': None, 'max_yaw_accel': None}
    spec = parse_plant({'model': 'velocity_lag', 'command': 'accel'}, 3, registry.plant_class)
    assert (spec.command, spec.frame, spec.model.tau) == ('accel', 'world', 0.1)
    # The exact conversion is the default; a choice, not a limit nor a number.
    assert spec.model.conversion == 'exact' and spec.model.conversion_tau is None
    assert spec.model.limits() == {'max_speed': None, 'max_accel': None}
    spec = parse_plant({'model': 'double_integrator', 'conversion': 'naive'}, 2,
                       registry.plant_class)
    assert spec.default and spec.model.conversion == 'naive'


def test_intrinsic_dynamics_need_the_double_integrator():
    data = load_mapping('zhou2012_sec51')
    data['plant'] = {'model': 'velocity_lag'}
    with pytest.raises(ScenarioError, match='^plant.model: the velocity_lag plant has no'):
        parse_scenario(data)


@pytest.mark.parametrize('dim', [2, 3])
def test_the_double_integrator_plant_is_the_zero_order_hold(dim):
    q, p, u = states(1, 7, dim)
    plant = DoubleIntegrator()
    x = plant.initial_state(q, p)
    assert len(plant.state_names(dim)) == x.shape[1] == 2 * dim
    cmd = plant.command(x, u, 0.01)
    assert_array_equal(cmd, u)
    q1, p1 = plant.law_state(plant.step(x, cmd, 0.01))
    want = step_double_integrator(q, p, u, 0.01)
    assert_array_equal(q1, want[0])
    assert_array_equal(p1, want[1])
    with pytest.raises(ValueError, match='takes no velocity command'):
        plant.twist(x, cmd, 'world')


@pytest.mark.parametrize('dim', [2, 3])
def test_the_velocity_lag_is_the_exact_solution_of_the_linear_lag(dim):
    q, p, u = states(2, 9, dim)
    plant = VelocityLag(tau=0.3, conversion='naive')
    x = plant.initial_state(q, p)
    assert_array_equal(plant.law_state(x)[0], q)
    assert_array_equal(plant.law_state(x)[1], p)
    v_sp = plant.command(x, u, 0.05)
    assert_allclose(v_sp, p + 0.05 * u, rtol=0, atol=1e-15)
    dt = 0.4
    q1, v1 = plant.law_state(plant.step(x, v_sp, dt))
    e = np.exp(-dt / 0.3)
    # v(t) = v_sp + (v0 - v_sp) e^{-t/tau}, q(t) = q0 + v_sp t + (v0 - v_sp) tau (1 - e^{-t/tau})
    assert_allclose(v1, v_sp + (p - v_sp) * e, rtol=1e-13, atol=1e-14)
    assert_allclose(q1, q + v_sp * dt + (p - v_sp) * 0.3 * (1 - e), rtol=1e-13, atol=1e-14)
    # Exact: two half steps are one step.
    half = plant.step(plant.step(x, v_sp, dt / 2), v_sp, dt / 2)
    assert_allclose(half, plant.step(x, v_sp, dt), rtol=1e-13, atol=1e-13)


def test_the_velocity_lag_saturates_speed_then_acceleration():
    q, p, u = states(3, 200, 3)
    plant = VelocityLag(tau=0.2, max_speed=1.0, max_accel=2.0, conversion='naive')
    p = p / np.maximum(1.0, np.linalg.norm(p, axis=1))[:, None]
    x = plant.initial_state(q, p)
    v_sp = plant.command(x, 50 * u, 0.1)
    assert np.linalg.norm(v_sp, axis=1).max() <= 1.0 + 1e-12
    # The lag's acceleration (v_sp - v) / tau is largest at the start of a step.
    assert (np.linalg.norm(v_sp - p, axis=1) / 0.2).max() <= 2.0 + 1e-12
    fine = x
    for _ in range(100):
        before = fine[:, 3:]
        fine = plant.step(fine, v_sp, 0.001)
        assert (np.linalg.norm(fine[:, 3:] - before, axis=1) / 0.001).max() <= 2.0 + 1e-9
    x[:, 3:] *= 0.5
    small = plant.command(x, 1e-3 * u, 0.1)
    assert_allclose(small, 0.5 * p + 1e-4 * u, rtol=0, atol=1e-15)


def test_the_velocity_lag_speaks_twist_in_the_world_frame():
    q, p, u = states(4, 5, 2)
    plant = VelocityLag()
    x = plant.initial_state(q, p)
    cmd = plant.command(x, u, 0.1)
    linear, angular = plant.twist(x, cmd, 'world')
    assert linear.shape == angular.shape == (5, 3)
    assert_array_equal(linear[:, 2], 0.0)
    assert_array_equal(plant.from_twist(x, linear, angular, 'world'), cmd)
    with pytest.raises(ScenarioError, match='^plant.frame: the velocity_lag plant takes world'):
        plant.twist(x, cmd, 'body')


def unicycle_states(seed: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    theta = rng.uniform(-np.pi, np.pi, n)
    return np.column_stack([rng.uniform(-5, 5, (n, 2)), np.sin(theta / 2), np.cos(theta / 2),
                            rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)])


def test_the_unicycle_law_state_is_the_point_ahead_of_the_axle():
    plant = Unicycle(ell=0.25)
    x = unicycle_states(5, 8)
    theta = plant.heading(x)
    q, p = plant.law_state(x)
    heading = np.column_stack([np.cos(theta), np.sin(theta)])
    normal = np.column_stack([-np.sin(theta), np.cos(theta)])
    assert_allclose(q, x[:, :2] + 0.25 * heading, rtol=0, atol=1e-14)
    assert_allclose(p, x[:, 4:5] * heading + 0.25 * x[:, 5:6] * normal, rtol=0, atol=1e-14)
    # The point's velocity is the time derivative of its position (a tiny exact step).
    dt = 1e-6
    q1, _ = plant.law_state(plant.step(x, x[:, 4:], dt))
    assert_allclose((q1 - q) / dt, p, rtol=0, atol=1e-5)


def test_the_naive_unicycle_command_inverts_the_near_identity_map():
    plant = Unicycle(ell=0.2, conversion='naive')
    x = unicycle_states(6, 50)
    u = np.random.default_rng(7).uniform(-2, 2, (50, 2))
    cmd = plant.command(x, u, 0.1)
    executed = x.copy()
    executed[:, 4:] = cmd
    _, p_done = plant.law_state(executed)
    _, p = plant.law_state(x)
    assert_allclose(p_done, p + 0.1 * u, rtol=0, atol=1e-13)


@pytest.mark.parametrize('conversion', ['exact', 'naive'])
def test_the_unicycle_command_saturates(conversion):
    plant = Unicycle(ell=0.1, max_speed=0.22, max_yaw_rate=2.84, max_accel=1.0,
                     max_yaw_accel=5.0, conversion=conversion)
    x = unicycle_states(8, 300)
    x[:, 4] = np.clip(x[:, 4], -0.22, 0.22)
    u = np.random.default_rng(9).uniform(-50, 50, (300, 2))
    cmd = plant.command(x, u, 0.1)
    assert np.abs(cmd[:, 0]).max() <= 0.22 and np.abs(cmd[:, 1]).max() <= 2.84
    assert np.abs(cmd[:, 0] - x[:, 4]).max() <= 0.1 + 1e-15
    below = np.abs(x[:, 5]) <= 2.84
    assert np.abs(cmd[below, 1] - x[below, 5]).max() <= 0.5 + 1e-15


def test_the_unicycle_step_is_the_exact_arc():
    plant = Unicycle(ell=0.1)
    # A quarter turn at v = 1, omega = pi / 2 for 1 s from the origin heading +x: a quarter
    # circle of radius 2 / pi, ending at (2 / pi, 2 / pi) heading +y.
    x = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0]])
    end = plant.step(x, np.array([[1.0, np.pi / 2]]), 1.0)
    assert_allclose(end[0, :2], [2 / np.pi, 2 / np.pi], rtol=0, atol=1e-15)
    assert_allclose(plant.heading(end), [np.pi / 2], rtol=0, atol=1e-15)
    assert_allclose(end[0, 4:], [1.0, np.pi / 2])
    # Straight drive, and exactness: ten small steps are one step.
    straight = plant.step(x, np.array([[2.0, 0.0]]), 0.5)
    assert_allclose(straight[0, :4], [1.0, 0.0, 0.0, 1.0], rtol=0, atol=1e-15)
    xs = unicycle_states(10, 20)
    cmd = np.random.default_rng(11).uniform(-1, 1, (20, 2))
    many = xs
    for _ in range(10):
        many = plant.step(many, cmd, 0.03)
    one = plant.step(xs, cmd, 0.3)
    assert_allclose(many[:, :2], one[:, :2], rtol=0, atol=1e-13)
    assert_allclose(np.cos(plant.heading(many) - plant.heading(one)), 1.0, rtol=0, atol=1e-14)
    assert_allclose(np.hypot(many[:, 2], many[:, 3]), 1.0, rtol=0, atol=1e-15)


def test_the_unicycle_starts_heading_along_its_initial_velocity():
    plant = Unicycle(max_speed=1.0)
    q0 = np.array([[1.0, 2.0], [0.0, 0.0]])
    p0 = np.array([[0.0, 0.5], [-3.0, 0.0]])
    x = plant.initial_state(q0, p0)
    assert_allclose(plant.heading(x), [np.pi / 2, np.pi], rtol=0, atol=1e-15)
    assert_array_equal(x[:, :2], q0)
    assert_array_equal(x[:, 4:], [[0.5, 0.0], [1.0, 0.0]])


def test_the_unicycle_speaks_twist_in_either_frame():
    plant = Unicycle()
    x = unicycle_states(12, 6)
    cmd = np.random.default_rng(13).uniform(-1, 1, (6, 2))
    linear, angular = plant.twist(x, cmd, 'body')
    assert_array_equal(linear[:, 1:], 0.0)
    assert_array_equal(angular[:, :2], 0.0)
    assert_array_equal(plant.from_twist(x, linear, angular, 'body'), cmd)
    linear, angular = plant.twist(x, cmd, 'world')
    theta = plant.heading(x)
    assert_allclose(linear[:, :2], cmd[:, :1] * np.column_stack([np.cos(theta), np.sin(theta)]),
                    rtol=0, atol=1e-15)
    assert_allclose(plant.from_twist(x, linear, angular, 'world'), cmd, rtol=0, atol=1e-15)


@pytest.mark.parametrize('plant, dim', [(DoubleIntegrator(), 3), (VelocityLag(), 2),
                                        (VelocityLag(), 3), (Unicycle(), 2)])
def test_odometry_carries_the_state_exactly(plant, dim):
    q, p, _ = states(14, 6, dim)
    x = plant.initial_state(q, p)
    position, orientation, linear, angular = plant.odometry(x)
    assert position.shape == linear.shape == angular.shape == (6, 3)
    assert_allclose(np.linalg.norm(orientation, axis=1), 1.0, rtol=0, atol=1e-15)
    assert_array_equal(plant.from_odometry(position, orientation, linear, angular, dim), x)
    if plant.oriented:
        assert_allclose(2 * np.arctan2(orientation[:, 2], orientation[:, 3]),
                        np.arctan2(p[:, 1], p[:, 0]), rtol=0, atol=1e-14)


def small(plant=None, **changes) -> dict:
    data = load_mapping('su2009_fig2')
    data.update({'n_agents': 12, 'duration': 2.0, 'record_every': 10, **changes})
    if plant is not None:
        data['plant'] = plant
    return data


def test_sim_with_the_double_integrator_named_is_todays_run():
    from flock_swarm.core.run import simulate
    plain = simulate(parse_scenario(small()))
    named = simulate(parse_scenario(small({'model': 'double_integrator'})))
    assert set(plain.series) == set(named.series)
    for key, value in plain.series.items():
        assert_array_equal(named.series[key], value)
    drop = ('wall_time_s',)
    assert {k: v for k, v in plain.summary.items() if k not in drop} == \
        {k: v for k, v in named.summary.items() if k not in drop}


@pytest.mark.parametrize('section', [{'model': 'velocity_lag', 'tau': 0.3, 'max_speed': 2.0},
                                     {'model': 'unicycle', 'ell': 0.2, 'max_speed': 2.0,
                                      'max_yaw_rate': 3.0}])
def test_sim_runs_the_plant_and_records_its_state(section):
    from flock_swarm.core.run import simulate
    sc = parse_scenario(small(section, record_every=1))
    plant = sc.plant.model
    result = simulate(sc)
    series = result.series
    assert result.summary['status'] == 'completed'
    xs = series['plant_state']
    assert xs.shape == (101, 12, len(plant.state_names(2)))
    assert_array_equal(xs[0], plant.initial_state(*parse_realised(sc)))
    for k in range(101):
        # The law sees the plant's law_state; the next state is the plant's step under the
        # command of the law's recorded acceleration.
        q, p = plant.law_state(xs[k])
        assert_array_equal(series['q'][k], q)
        assert_array_equal(series['p'][k], p)
        if k < 100:
            assert_array_equal(xs[k + 1], plant.step(xs[k], plant.command(xs[k], series['u'][k],
                                                                          sc.dt), sc.dt))
    speed = np.abs(xs[1:, :, 4]) if plant.oriented else np.linalg.norm(xs[1:, :, 2:], axis=2)
    assert speed.max() <= 2.0 + 1e-12
    if plant.oriented:
        assert_array_equal(series['heading'], plant.heading(xs.reshape(-1, 6)).reshape(101, 12))
    # The summary's metrics are the law's: the velocity mismatch of the last recorded (q, p).
    mismatch = np.linalg.norm(series['p'][-1] - series['leader_p'][-1], axis=1).max()
    assert result.summary['velocity_mismatch_max'] == pytest.approx(mismatch, abs=1e-12)


def parse_realised(sc):
    from flock_swarm.core.scenario import realize
    real = realize(sc)
    return real.q0, real.p0


def test_seeds_with_a_plant_stack_like_single_runs():
    from flock_swarm.core.run import simulate, simulate_stack
    scs = [parse_scenario(small({'model': 'unicycle'}, seed=s)) for s in (1, 2)]
    stacked = simulate_stack(scs)
    for sc, res in zip(scs, stacked):
        alone = simulate(sc)
        assert_allclose(res.series['plant_state'], alone.series['plant_state'], rtol=0,
                        atol=1e-12)
    with pytest.raises(ValueError, match='differs in plant'):
        simulate_stack([parse_scenario(small({'model': 'unicycle'})),
                        parse_scenario(small({'model': 'unicycle', 'ell': 0.3}))])


# The conversions (issue 36, item 1): exact delivers the law's velocity change in one step;
# naive is the conversion before it, reproduced bit for bit.

def old_command(plant, x, u, period):
    """The conversion of both robot plants before the exact one (main at 36a587c), written
    out again: the wanted velocity ``p + u T`` handed over as it is, then saturated."""
    with np.errstate(divide='ignore', invalid='ignore'):
        if isinstance(plant, VelocityLag):
            p = x[:, x.shape[1] // 2:]
            v_sp = p + u * period
            if plant.max_speed is not None:
                norm = np.linalg.norm(v_sp, axis=1)
                v_sp = v_sp * np.where(norm > plant.max_speed, plant.max_speed / norm,
                                       1.0)[:, None]
            if plant.max_accel is not None:
                change = v_sp - p
                norm, bound = np.linalg.norm(change, axis=1), plant.tau * plant.max_accel
                v_sp = p + change * np.where(norm > bound, bound / norm, 1.0)[:, None]
            return v_sp
    _, p = plant.law_state(x)
    wanted = p + u * period
    c, s = x[:, 3] * x[:, 3] - x[:, 2] * x[:, 2], 2.0 * x[:, 2] * x[:, 3]
    v = c * wanted[:, 0] + s * wanted[:, 1]
    w = (c * wanted[:, 1] - s * wanted[:, 0]) / plant.ell
    v = np.clip(v, x[:, 4] - plant.max_accel * period, x[:, 4] + plant.max_accel * period)
    v = np.clip(v, -plant.max_speed, plant.max_speed)
    w = np.clip(w, -plant.max_yaw_rate, plant.max_yaw_rate)
    return np.column_stack([v, w])


#: Short named runs with limits that bind, and the SHA-256 of their final plant state at
#: main 36a587c (before the exact conversion), computed there by ``hashlib.sha256(np.
#: ascontiguousarray(series['plant_state'][-1]).tobytes())`` of ``small(plant)``.
FINGERPRINTS = [
    ({'model': 'velocity_lag', 'tau': 0.1, 'max_speed': 2.0, 'max_accel': 8.0},
     '3b2cfdd6c335176d9c7134013068c8a74355023587296093635393c79d32f1f5'),
    ({'model': 'unicycle', 'ell': 0.2, 'max_speed': 2.0, 'max_yaw_rate': 3.0, 'max_accel': 4.0},
     'ea9a59386f9579275ee7edbba8da2ae5c1e958d1b85147d127ab4710c6e2504c')]


@pytest.mark.parametrize('section, digest', FINGERPRINTS, ids=['velocity_lag', 'unicycle'])
def test_the_naive_conversion_reproduces_the_old_runs_bit_for_bit(section, digest):
    import hashlib
    from flock_swarm.core.run import simulate
    naive = {**section, 'conversion': 'naive'}
    final = simulate(parse_scenario(small(naive))).series['plant_state'][-1]
    assert hashlib.sha256(np.ascontiguousarray(final).tobytes()).hexdigest() == digest
    # Every step, against the old formula written out again in this file.
    sc = parse_scenario(small(naive, record_every=1))
    plant, series = sc.plant.model, simulate(sc).series
    xs = series['plant_state']
    for k in range(xs.shape[0] - 1):
        assert_array_equal(xs[k + 1], plant.step(xs[k], old_command(plant, xs[k],
                                                                    series['u'][k], sc.dt),
                                                 sc.dt))
    # The default now differs: the exact conversion.
    exact = simulate(parse_scenario(small(section))).series['plant_state'][-1]
    assert not np.array_equal(exact, final)


@pytest.mark.parametrize('section', [{'model': 'velocity_lag', 'tau': 0.1},
                                     {'model': 'velocity_lag', 'tau': 0.5},
                                     {'model': 'unicycle', 'ell': 0.2}],
                         ids=['velocity_lag_0.1', 'velocity_lag_0.5', 'unicycle'])
def test_the_exact_conversion_delivers_the_laws_velocity_every_step(section):
    """A sim run, no limits, the command period the step: the law sees ``p + u dt`` after
    each step (for the unicycle, the point ahead of the axle)."""
    from flock_swarm.core.run import simulate
    sc = parse_scenario(small(section, record_every=1))
    series = simulate(sc).series
    p, u = series['p'], series['u']
    assert np.abs(u).max() > 0.1
    assert_allclose(p[1:], p[:-1] + u[:-1] * sc.dt, rtol=0, atol=1e-12)
    # The naive conversion delivers a fraction (the lag's 1 - exp(-dt / tau)).
    series = simulate(parse_scenario(small({**section, 'conversion': 'naive'},
                                           record_every=1))).series
    if section['model'] == 'velocity_lag':
        reach = -np.expm1(-sc.dt / section['tau'])
        assert_allclose(series['p'][1:], series['p'][:-1] + reach * series['u'][:-1] * sc.dt,
                        rtol=0, atol=1e-12)


def test_the_exact_velocity_lag_conversion_in_3d_and_its_assumed_lag():
    q, p, _ = states(20, 30, 3)
    plant = VelocityLag(tau=0.1)
    x = plant.initial_state(q, p)
    rng = np.random.default_rng(21)
    for _ in range(50):
        u = rng.uniform(-3, 3, (30, 3))
        nxt = plant.step(x, plant.command(x, u, 0.02), 0.02)
        assert_allclose(nxt[:, 3:], x[:, 3:] + u * 0.02, rtol=0, atol=1e-14)
        x = nxt
    # A lag assumed wrong delivers (1 - e) / (1 - e_assumed) of the law's change.
    for assumed in (0.05, 0.2):
        wrong = VelocityLag(tau=0.1, conversion_tau=assumed)
        nxt = wrong.step(x, wrong.command(x, u, 0.02), 0.02)
        fraction = np.expm1(-0.02 / 0.1) / np.expm1(-0.02 / assumed)
        assert_allclose(nxt[:, 3:], x[:, 3:] + fraction * u * 0.02, rtol=0, atol=1e-14)


def test_the_exact_velocity_lag_conversion_keeps_the_limits_inside_the_step():
    """The velocity moves on the segment from ``p`` to the saturated target: never above
    ``max_speed`` inside the step, although the setpoint may be; the acceleration never above
    ``max_accel``."""
    q, p, u = states(3, 200, 3)
    plant = VelocityLag(tau=0.2, max_speed=1.0, max_accel=2.0)
    p = p / np.maximum(1.0, np.linalg.norm(p, axis=1))[:, None]
    x = plant.initial_state(q, p)
    v_sp = plant.command(x, 50 * u, 0.1)
    assert np.linalg.norm(v_sp, axis=1).max() > 1.0
    assert (np.linalg.norm(v_sp - p, axis=1) / 0.2).max() <= 2.0 + 1e-12
    fine = x
    for _ in range(100):
        before = fine[:, 3:]
        fine = plant.step(fine, v_sp, 0.001)
        assert np.linalg.norm(fine[:, 3:], axis=1).max() <= 1.0 + 1e-12
        assert (np.linalg.norm(fine[:, 3:] - before, axis=1) / 0.001).max() <= 2.0 + 1e-9
    # Unsaturated, the target after the period is p + u T exactly.
    x[:, 3:] *= 0.5
    small_u = 1e-3 * u
    done = plant.step(x, plant.command(x, small_u, 0.1), 0.1)
    assert_allclose(done[:, 3:], 0.5 * p + 1e-4 * u, rtol=0, atol=1e-15)


def test_the_exact_unicycle_turn_solves_its_equation_batch_or_alone():
    from flock_swarm.core.plants import models
    plant = Unicycle(ell=0.1)
    x = unicycle_states(22, 300)
    u = np.random.default_rng(23).uniform(-20, 20, (300, 2))
    for period in (0.02, 0.1, 0.5):
        _, p = plant.law_state(x)
        wanted = p + u * period
        cmd = plant.command(x, u, period)
        _, p1 = plant.law_state(plant.step(x, cmd, period))
        assert_allclose(p1, wanted, rtol=0, atol=1e-12)
        # A robot's command does not depend on the others in the batch (the agent nodes
        # convert their own row; sim converts all at once).
        alone = np.vstack([plant.command(x[i:i + 1], u[i:i + 1], period) for i in range(300)])
        assert_array_equal(alone, cmd)
    # Several roots (|w| T >= ell): the one nearest the naive turn, within a grid cell.
    rng = np.random.default_rng(24)
    ahead, left, ratio = rng.uniform(-10, 10, 40), rng.uniform(-10, 10, 40), 2.0
    turn = models.exact_turn(ahead, left, ratio)
    for a, b, d in zip(ahead, left, turn):
        k = ratio * np.hypot(a, b)
        grid = np.linspace(-k, k, 200001)
        g = grid + ratio * (a * np.sin(grid) - b * np.cos(grid))
        roots = grid[:-1][np.sign(g[:-1]) != np.sign(g[1:])]
        assert abs(d + ratio * (a * np.sin(d) - b * np.cos(d))) < 1e-12 * max(1.0, k)
        nearest = np.abs(roots - ratio * b).min()
        assert abs(d - ratio * b) <= nearest + 1.0 / models.TURN_GRID


def test_a_bad_conversion_is_one_line_and_status_2(capfd):
    out = sim_main(['demo', '--set', 'plant={model: velocity_lag, conversion: foo}'], capfd)
    assert out.returncode == 2 and out.stdout == ''
    assert out.stderr == ("sim: error: plant.conversion: unknown value 'foo' (expected one of: "
                          "exact, naive)\n")


def lag_oracle_scenario(tau, conversion, duration):
    """Four velocity-lag robots on a ring (Laplacian eigenvalues 0, 2, 2, 4) under the
    linear law at a loop gain near the sampled double integrator's limit (``lam dt k_v``
    = 1.92 for ``lam = 4``), nobody informed."""
    ring = [[0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1], [1, 0, 1, 0]]
    return parse_scenario({
        'name': 'lag_oracle', 'dim': 2, 'n_agents': 4, 'dt': 0.01, 'duration': duration,
        'seed': 3, 'record_every': 10,
        'protocol': {'name': 'linear_consensus', 'k_p': 1000.0, 'k_v': 48.0},
        'graph': {'type': 'fixed', 'adjacency': ring},
        'informed': {'select': 'first', 'count': 0},
        'initial': {'position_box': [[-1, 1], [-1, 1]], 'velocity_box': [[-1, 1], [-1, 1]]},
        'leader': {'model': 'constant_velocity', 'position': [0, 0], 'velocity': [0, 0]},
        'plant': {'model': 'velocity_lag', 'tau': tau, 'conversion': conversion}})


@pytest.mark.parametrize('conversion', ['naive', 'exact'])
def test_the_critical_lag_of_the_linear_law(conversion):
    """The oracle (``linear.critical_lag``): below ``tau_c`` the run diverges, above it it
    converges, and the sampled loop's spectral radius crosses 1 at ``tau_c``."""
    from flock_swarm.core.laws import linear
    from flock_swarm.core.run import simulate
    dt, k_p, k_v = 0.01, 1000.0, 48.0
    tau_c = linear.critical_lag(4.0, dt, k_p, k_v, conversion)
    # The eigenvalue 2 is stable at every lag; 4 decides.
    assert linear.critical_lag(2.0, dt, k_p, k_v, conversion) == 0.0
    assert tau_c == pytest.approx({'naive': 0.0023858, 'exact': 0.0037424}[conversion],
                                  rel=1e-4)
    assert linear.sampled_lag_radius(4.0, tau_c * (1 - 1e-6), dt, k_p, k_v, conversion) > 1.0
    assert linear.sampled_lag_radius(4.0, tau_c * (1 + 1e-6), dt, k_p, k_v, conversion) < 1.0
    # The model is the plant's own arithmetic: one step of each basis state.
    plant = VelocityLag(tau=0.9 * tau_c, conversion=conversion)
    x = np.eye(2)
    u = -4.0 * (k_p * x[:, :1] + k_v * x[:, 1:])
    assert_allclose(plant.step(x, plant.command(x, u, dt), dt).T,
                    linear.sampled_lag_matrix(4.0, 0.9 * tau_c, dt, k_p, k_v, conversion),
                    rtol=0, atol=1e-12)
    # Runs at 0.8 and 1.25 tau_c: the agents' spread about their mean, its growth rate fitted
    # over 1 .. 3 s (after the other root's transient, above round-off), against the loop's
    # ln(radius) / dt.
    for factor, sign in ((0.8, 1.0), (1.25, -1.0)):
        series = simulate(lag_oracle_scenario(factor * tau_c, conversion, 3.0)).series
        dq = series['q'] - series['q'].mean(axis=1, keepdims=True)
        spread = np.linalg.norm(dq, axis=2).max(axis=1)
        late = series['t'] >= 1.0 - 1e-9
        rate = np.polyfit(series['t'][late], np.log(spread[late]), 1)[0]
        radius = linear.sampled_lag_radius(4.0, factor * tau_c, dt, k_p, k_v, conversion)
        assert sign * rate > 1.0
        assert rate == pytest.approx(np.log(radius) / dt, rel=0.05)


def test_a_plant_tells_its_capabilities():
    """The robot agent and the engine ask the plant what it is, not its name: a plant of
    another name with the same classes' capabilities is taken as they are."""
    from flock_swarm.core.plants.models import DoubleIntegrator, Unicycle, VelocityLag

    class Rover(Unicycle):
        name = 'rover'

    assert [c.velocity_commanded() for c in (DoubleIntegrator, VelocityLag, Unicycle, Rover)] \
        == [False, True, True, True]
    assert [c.differential_drive for c in (DoubleIntegrator, VelocityLag, Unicycle, Rover)] \
        == [False, False, True, True]
    x = np.array([[1.0, 2.0, 0.1, 0.99, 0.3, 0.7]])
    np.testing.assert_array_equal(Rover().commanded_state(x, np.array([[0.05, -0.2]])),
                                  [[1.0, 2.0, 0.1, 0.99, 0.05, -0.2]])
