"""The world's backends (flock_swarm.engine.backends): one interface, chosen by name.

Each backend steps as the integrator it stands for, bit for bit (the double integrator as
``step_agents``, the plant model as its ``command``/``from_twist`` and ``step``, MuJoCo as the
engine driven directly), reads out the state the law sees, and tells its contacts. The lockstep
ROS runs that equal ``sim`` with each backend are in test_plants_ros.py, test_engine_world.py
and test_nodes.py.
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from flock_swarm.core.dynamics import step_agents
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.scenario import realize
from flock_swarm.engine.backends import (BACKENDS, DoubleIntegrator, MujocoBackend,
                                         PlantModel, WorldBackend, make_backend,
                                         sim_integrator)
from flock_swarm.presets import load

UNICYCLE = 'plant={model: unicycle, ell: 0.1, max_speed: 0.22, max_yaw_rate: 2.84}'
LAG = 'plant={model: velocity_lag, tau: 0.2, max_speed: 1.5}'


def scenario(*overrides: str):
    """Return a four-agent demo scenario of five steps."""
    return load('demo', ['n_agents=4', 'informed.count=2', 'duration=0.5', 'dt=0.1',
                         *overrides])


def commands(sc, k: int) -> np.ndarray:
    """Return step ``k``'s accelerations, the same for every backend."""
    return np.random.default_rng(k).normal(size=(sc.n_agents, sc.dim))


def test_the_double_integrator_steps_as_step_agents():
    sc = scenario()
    real = realize(sc)
    backend = make_backend('plant', sc, real)
    assert type(backend) is DoubleIntegrator and backend.plant is None and backend.x is None
    q, p = real.q0.copy(), real.p0.copy()
    assert_array_equal(backend.q, q)
    for k in range(5):
        backend.step(commands(sc, k), None, sc.dt)
        q, p = step_agents(q, p, commands(sc, k), sc.dt, None)
        assert backend.q.tobytes() == q.tobytes() and backend.p.tobytes() == p.tobytes()
    assert backend.recorded() == {} and not backend.counts_contacts
    assert backend.contacts_step == backend.contacts_run == frozenset()


@pytest.mark.parametrize('plant', [LAG, UNICYCLE])
def test_the_plant_model_steps_as_the_plant(plant):
    """Accelerations converted by the plant's ``command``; for the unicycle, Twists too."""
    sc = scenario(plant)
    real = realize(sc)
    backend = make_backend('plant', sc, real)
    model = sc.plant.model
    assert type(backend) is PlantModel and backend.plant is model
    x = model.initial_state(real.q0, real.p0)
    for k in range(5):
        twists = None
        if model.name == 'unicycle' and k % 2:
            twists = np.zeros((sc.n_agents, 6))
            twists[:, 0], twists[:, 5] = 0.1 * k, -0.2
            cmd = model.from_twist(x, twists[:, :3], twists[:, 3:], sc.plant.frame)
        else:
            cmd = model.command(x, commands(sc, k), sc.dt)
        backend.step(commands(sc, k), twists, sc.dt)
        x = model.step(x, cmd, sc.dt)
        assert backend.x.tobytes() == x.tobytes()
        q, p = model.law_state(x)
        assert backend.q.tobytes() == q.tobytes() and backend.p.tobytes() == p.tobytes()
    assert backend.recorded().keys() == model.recorded(x).keys()
    assert not backend.counts_contacts and backend.contacts_run == frozenset()


def test_mujoco_steps_as_the_engine_and_counts_contacts():
    """Two robots driven into each other: the backend's state is the engine's, driven the
    same way directly, and the pair's contact is counted."""
    from flock_swarm.engine.backend import EngineBackend
    sc = load('demo', ['n_agents=2', 'informed.count=1', 'duration=1.0', 'dt=0.05', UNICYCLE,
                       'initial={positions: [[0.0, 0.0], [0.3, 0.0]], '
                       'velocities: [[0.0, 0.0], [0.0, 0.0]]}'])
    real = realize(sc)
    backend = make_backend('mujoco', sc, real)
    assert type(backend) is MujocoBackend and backend.counts_contacts
    engine = EngineBackend('unicycle', sc.plant.model.initial_state(real.q0, real.p0))
    assert backend.x.tobytes() == engine.state().tobytes()
    twists = np.zeros((2, 6))
    twists[:, 0] = [0.2, -0.2]
    for _ in range(20):
        backend.step(np.zeros((2, 2)), twists, sc.dt)
        x = engine.step(None, twists[:, [0, 5]], sc.dt)
        assert backend.x.tobytes() == x.tobytes()
    assert backend.contacts_run == engine.contacts_run == {(0, 1)}


def test_the_backend_is_chosen_by_name_in_one_place():
    """Every name the world's ``backend`` parameter takes makes a backend (and ``sim``'s
    integrator: none for ``plant``, the engine's for ``mujoco``); the engine refuses a plant
    it has no robot for (one line naming ``backend``), an unknown name is an error naming
    the known ones."""
    sc = scenario(UNICYCLE)
    assert BACKENDS == ('plant', 'mujoco')
    for name in BACKENDS:
        assert isinstance(make_backend(name, sc, realize(sc)), WorldBackend)
    assert sim_integrator('plant', sc) is None
    real = realize(sc)
    engine = sim_integrator('mujoco', sc)(sc.plant.model.initial_state(real.q0, real.p0))
    assert engine.summary() == {'robot_contacts': 0}
    for refused in (lambda: make_backend('mujoco', scenario(), realize(scenario())),
                    lambda: sim_integrator('mujoco', scenario())):
        with pytest.raises(ScenarioError, match='backend: mujoco drives differential-drive'):
            refused()
    for unknown in (lambda: make_backend('ode', sc, realize(sc)),
                    lambda: sim_integrator('ode', sc)):
        with pytest.raises(ValueError, match="unknown backend 'ode' \\(known: plant, mujoco"):
            unknown()
