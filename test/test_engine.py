"""The MuJoCo world of flock_swarm.engine: kinematics, limits, contacts, determinism."""

import numpy as np
import pytest

from flock_swarm.engine.mujoco_world import EngineWorld
from flock_swarm.engine.mujoco_world import robot_mjcf
from flock_swarm.engine.mujoco_world import TURTLEBOT3_BURGER
from flock_swarm.engine.mujoco_world import yaw_of


def drive(world: EngineWorld, v, omega, seconds: float, period: float = 0.02) -> None:
    """Hold the twists ``(v, omega)`` for ``seconds`` of engine time."""
    for _ in range(int(round(seconds / period))):
        world.set_twists(v, omega)
        world.step(period)


def test_wheel_speeds_are_the_differential_drive_kinematics():
    r, b = TURTLEBOT3_BURGER.wheel_radius, TURTLEBOT3_BURGER.wheel_separation
    w = TURTLEBOT3_BURGER.wheel_speeds(np.array([0.1, 0.0]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(w, [[0.1 / r, 0.1 / r], [-b / 2 / r, b / 2 / r]], rtol=1e-12)


def test_wheel_speeds_clamp_to_the_published_limits():
    w = TURTLEBOT3_BURGER.wheel_speeds(np.array([5.0, -5.0]), np.array([0.0, 0.0]))
    np.testing.assert_allclose(w[:, 0] * TURTLEBOT3_BURGER.wheel_radius, [0.22, -0.22])
    w = TURTLEBOT3_BURGER.wheel_speeds(np.array([0.0]), np.array([50.0]))
    r, b = TURTLEBOT3_BURGER.wheel_radius, TURTLEBOT3_BURGER.wheel_separation
    np.testing.assert_allclose((w[0, 1] - w[0, 0]) * r / b, 2.84)


def test_the_model_cites_its_numbers():
    text = robot_mjcf()
    for fact in ('0.22 m/s', '2.84 rad/s', '1 kg', 'wheels.separation 0.160',
                 'wheels.radius 0.033', 'emanual.robotis.com'):
        assert fact in text


def test_an_unknown_model_is_one_line_naming_it():
    with pytest.raises(ValueError, match=r"unknown robot model 'husky' \(known: turtlebot3"):
        EngineWorld([[0.0, 0.0]], [0.0], model='husky')


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match='positions must be N x 2'):
        EngineWorld([[0.0, 0.0, 0.0]], [0.0])


def test_n_robots_are_built_from_one_model():
    world = EngineWorld([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [0.0, 1.0, -2.0])
    assert world.model.nu == 6
    np.testing.assert_allclose(world.poses(), [[0, 0, 0], [1, 0, 1], [0, 1, -2]], atol=1e-9)


def test_a_robot_tracks_its_twist():
    world = EngineWorld([[0.0, 0.0], [1.0, 0.0]], [0.0, np.pi / 2])
    drive(world, [0.15, 0.0], [0.0, 1.0], 2.0)
    vel = world.velocities()
    np.testing.assert_allclose(vel[0], [0.15, 0.0, 0.0], atol=0.01)
    np.testing.assert_allclose(vel[1], [0.0, 0.0, 1.0], atol=0.02)
    # The turning robot turns in place: its axle centre stays within a few millimetres.
    np.testing.assert_allclose(world.poses()[1, :2], [1.0, 0.0], atol=0.01)
    assert world.poses()[0, 0] > 0.2


def test_speed_commands_beyond_the_limits_are_held_at_them():
    world = EngineWorld([[0.0, 0.0], [2.0, 0.0]], [0.0, 0.0])
    drive(world, [3.0, 0.0], [0.0, 30.0], 2.0)
    vel = world.velocities()
    assert 0.2 < vel[0, 0] <= 0.22 + 0.005
    assert 2.5 < vel[1, 2] <= 2.84 + 0.05


def test_robots_apart_have_no_contact_and_a_head_on_meeting_one_pair():
    world = EngineWorld([[0.0, 0.0], [0.6, 0.0], [0.0, 2.0]], [0.0, np.pi, 0.0])
    drive(world, [0.0, 0.0, 0.2], [0.0, 0.0, 0.0], 0.5)
    assert world.contacts_run == set()
    drive(world, [0.2, 0.2, 0.2], [0.0, 0.0, 0.0], 2.0)
    assert world.contacts_run == {(0, 1)}
    assert world.contacts_step == {(0, 1)}
    # Bodies do not pass through one another: each chassis reaches 0.038 m ahead of its axle
    # (a 0.140 m box centred 0.032 m behind it), so the axles stay 0.076 m apart, less the
    # contact's millimetre of softness.
    gap = np.linalg.norm(world.poses()[0, :2] - world.poses()[1, :2])
    assert 0.07 < gap < 0.08


def test_the_engine_is_deterministic():
    runs = []
    for _ in range(2):
        world = EngineWorld([[0.0, 0.0], [0.3, 0.1]], [0.0, 2.0])
        drive(world, [0.2, 0.1], [0.5, -1.0], 1.0)
        runs.append(np.concatenate([world.poses().ravel(), world.velocities().ravel()]))
    assert runs[0].tobytes() == runs[1].tobytes()


def test_yaw_of_a_quaternion():
    angles = np.array([-3.0, -1.0, 0.0, 0.5, 3.0])
    quat = np.stack([np.cos(angles / 2), 0 * angles, 0 * angles, np.sin(angles / 2)], axis=-1)
    np.testing.assert_allclose(yaw_of(quat), angles, atol=1e-12)


def test_the_backend_starts_at_the_plant_state_and_steps_like_the_unicycle():
    from flock_swarm.core.plants.models import Unicycle
    from flock_swarm.engine.backend import EngineBackend
    plant = Unicycle(ell=0.1, max_speed=0.22, max_yaw_rate=2.84)
    x0 = plant.initial_state(np.array([[0.0, 0.0], [1.0, 1.0]]),
                             np.array([[0.1, 0.0], [0.0, 0.1]]))
    backend = EngineBackend('unicycle', x0)
    np.testing.assert_allclose(backend.state()[:, :4], x0[:, :4], atol=1e-6)
    x_plant, x_engine = x0, x0
    cmd = np.array([[0.15, 0.3], [0.1, -0.2]])
    for _ in range(100):
        x_plant = plant.step(x_plant, cmd, 0.02)
        x_engine = backend.step(x_engine, cmd, 0.02)
    # Two seconds of the same commands: the engine's robots end within a few centimetres of
    # the exact kinematics (wheel servo lag, soft contacts), at the commanded speeds.
    np.testing.assert_allclose(x_engine[:, :2], x_plant[:, :2], atol=0.03)
    np.testing.assert_allclose(x_engine[:, 4:], cmd, atol=0.01)
    assert backend.contacts_run == set()


def test_the_backend_needs_differential_drive_robots():
    from flock_swarm.core.errors import ScenarioError
    from flock_swarm.engine.backend import EngineBackend
    with pytest.raises(ScenarioError, match="backend: mujoco drives differential-drive robots: "
                                            "it needs plant.model unicycle, got 'velocity_lag'"):
        EngineBackend('velocity_lag', np.zeros((2, 4)))


def sim_main(argv: list[str], capfd):
    """Run ``sim``'s ``main(argv)`` in this process, its file descriptors captured (a process
    took about a second of imports); return ``(status, stderr)``."""
    from flock_swarm.cli.sim import main
    capfd.readouterr()
    try:
        status = main([str(arg) for arg in argv])
    except SystemExit as end:
        status = end.code
    return status, capfd.readouterr().err


def test_sim_flies_the_fleet_against_the_engine(tmp_path, capfd):
    """``sim FILE --backend mujoco``: the engine integrates; a plant it has no robot for is
    one line with exit status 2."""
    import json
    from pathlib import Path
    fleet = Path(__file__).resolve().parents[1] / 'examples' / 'robots' / 'tb3_fleet.yaml'
    status, err = sim_main([fleet, '--backend', 'mujoco', '--set', 'duration=2',
                            '--out', tmp_path / 'mj', '--quiet'], capfd)
    assert status == 0, err
    summary = json.loads((tmp_path / 'mj' / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['collisions'] == 0
    assert summary['robot_contacts'] == 0
    status, err = sim_main(['demo', '--backend', 'mujoco', '--out', tmp_path / 'di'], capfd)
    assert status == 2
    assert err.splitlines() == [
        "sim: error: backend: mujoco drives differential-drive robots: it needs plant.model "
        "unicycle, got 'double_integrator'"]


def test_sim_counts_the_robots_that_touch_as_the_world_does(tmp_path, capfd):
    """``sim --backend mujoco`` writes ``robot_contacts`` (the world's summary key): two
    robots placed 0.15 m apart, less than a Burger's 0.178 m width, touch at once (the
    world's count of the same set-up: test_engine_world.py)."""
    import json
    from pathlib import Path
    fleet = Path(__file__).resolve().parents[1] / 'examples' / 'robots' / 'tb3_fleet.yaml'
    status, err = sim_main([fleet, '--backend', 'mujoco', '--set', 'duration=1.0', '--set',
                            'n_agents=2', '--set', 'informed.count=2', '--set',
                            'initial.positions=[[0.0, 0.0], [0.0, 0.15]]', '--set',
                            'initial.velocities=[[0.1, 0.0], [0.1, 0.0]]',
                            '--out', tmp_path / 'touch', '--quiet'], capfd)
    assert status == 0, err
    summary = json.loads((tmp_path / 'touch' / 'summary.json').read_text())
    assert summary['robot_contacts'] == 1
    # Without the engine there is nothing to count: the key is absent.
    status, err = sim_main([fleet, '--set', 'duration=0.5', '--out', tmp_path / 'plant',
                            '--quiet'], capfd)
    assert status == 0, err
    assert 'robot_contacts' not in json.loads((tmp_path / 'plant' / 'summary.json').read_text())
