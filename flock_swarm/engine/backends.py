"""What integrates the world's agents: one interface, a backend per integrator, chosen by name.

The world node (:class:`~flock_swarm.nodes.stepper.WorldStepper`) holds one
:class:`WorldBackend` and calls only its interface:

- :meth:`WorldBackend.step`: advance every agent over one step under the commands held (the
  agents' accelerations ``u``, or their velocity commands as Twist rows);
- the state read-out: :attr:`WorldBackend.q` and :attr:`WorldBackend.p` (what the law sees),
  :attr:`WorldBackend.x` and :attr:`WorldBackend.plant` (the plant's state rows and model,
  what the odometry carries), :meth:`WorldBackend.recorded` (the plant state the time series
  records);
- the contacts: :attr:`WorldBackend.contacts_step`, :attr:`WorldBackend.contacts_run`, and
  :attr:`WorldBackend.counts_contacts` (whether the backend detects any).

The backends: :class:`DoubleIntegrator` (the papers' ``q += p dt + u dt^2 / 2, p += u dt``,
the exact path ``sim`` takes without a ``plant:`` section), :class:`PlantModel` (the
scenario's plant model, as ``sim``) and :class:`MujocoBackend` (the physics engine,
:mod:`flock_swarm.engine.backend`). :func:`make_backend` is the one place that picks one
from the world's ``backend`` parameter and the scenario (:data:`FACTORIES`), and
:func:`sim_integrator` what ``sim --backend`` integrates with; a new backend is one class
here and its entry in :data:`FACTORIES`.
"""

from functools import partial
from typing import Callable

import numpy as np

from flock_swarm.core.dynamics import step_agents
from flock_swarm.core.scenario import Realization, Scenario

NO_CONTACTS: frozenset = frozenset()


class WorldBackend:
    """The interface of what integrates the world's agents (see the module).

    :ivar name: the backend's name.
    :ivar plant: the plant model (``None``: the double integrator's exact path).
    :ivar x: the plant's state rows (``None`` for the double integrator).
    :ivar q: positions, what the law sees.
    :ivar p: velocities, what the law sees.
    """

    name = ''
    #: Whether the backend detects contacts (its counts go to the metrics and the summary).
    counts_contacts = False
    plant = None
    x: np.ndarray | None = None

    def __init__(self, q0: np.ndarray, p0: np.ndarray) -> None:
        """Start at positions ``q0`` and velocities ``p0`` (copied)."""
        self.q, self.p = q0.copy(), p0.copy()

    def step(self, u: np.ndarray, twists: np.ndarray | None, dt: float) -> None:
        """Advance every agent by ``dt``.

        :param u: the agents' accelerations held over the step ``(N, dim)``.
        :param twists: their velocity commands, rows ``(linear x, y, z, angular x, y, z)``
            ``(N, 6)``, or ``None``: the accelerations are the commands.
        :param dt: the step [s].
        """
        raise NotImplementedError

    def recorded(self) -> dict:
        """Return the plant state the time series records (none for the double integrator)."""
        return {}

    @property
    def contacts_step(self) -> frozenset | set:
        """Return the agent pairs in contact during the last step (none undetected)."""
        return NO_CONTACTS

    @property
    def contacts_run(self) -> frozenset | set:
        """Return the agent pairs that have touched since the start (none undetected)."""
        return NO_CONTACTS


class DoubleIntegrator(WorldBackend):
    """The papers' double integrator, integrated exactly as ``sim`` does
    (:func:`~flock_swarm.core.dynamics.step_agents`, with the scenario's intrinsic
    dynamics)."""

    name = 'double_integrator'

    def __init__(self, sc: Scenario, real: Realization) -> None:
        """Start at the realisation's initial state."""
        super().__init__(real.q0, real.p0)
        self.intrinsic = sc.intrinsic.velocity_field() if sc.intrinsic is not None else None

    def step(self, u: np.ndarray, twists: np.ndarray | None, dt: float) -> None:
        """Advance by ``dt`` with ``u`` held (``twists``: none for this backend)."""
        self.q, self.p = step_agents(self.q, self.p, u, dt, self.intrinsic)


class PlantModel(WorldBackend):
    """The scenario's plant model, stepped as ``sim`` steps it: its command is the
    conversion of the accelerations (:meth:`~flock_swarm.core.plants.base.Plant.command`) or
    of the Twists (:meth:`~flock_swarm.core.plants.base.Plant.from_twist`)."""

    name = 'plant'

    def __init__(self, sc: Scenario, real: Realization) -> None:
        """Start at the plant's state of the realisation's initial state."""
        self.plant = sc.plant.model
        self.frame = sc.plant.frame
        self.x = self.plant.initial_state(real.q0.copy(), real.p0.copy())
        self.q, self.p = self.plant.law_state(self.x)

    def command(self, u: np.ndarray, twists: np.ndarray | None, dt: float) -> np.ndarray:
        """Return the command every plant executes this step (see the class)."""
        if twists is None:
            return self.plant.command(self.x, u, dt)
        return self.plant.from_twist(self.x, twists[:, :3], twists[:, 3:], self.frame)

    def step(self, u: np.ndarray, twists: np.ndarray | None, dt: float) -> None:
        """Advance by ``dt`` under the command of ``u`` or ``twists`` (:meth:`command`)."""
        self.x = self.integrate(self.x, self.command(u, twists, dt), dt)
        self.q, self.p = self.plant.law_state(self.x)

    def integrate(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Return the state rows after ``dt`` under ``cmd``: the plant model's exact step."""
        return self.plant.step(x, cmd, dt)

    def recorded(self) -> dict:
        """Return the plant's state to record (``plant_state``, the unicycle's heading)."""
        return self.plant.recorded(self.x)


class MujocoBackend(PlantModel):
    """The physics engine integrating the robots instead of the plant model: the same
    commands to the engine's wheel servos, the plant's state rows read back
    (:class:`~flock_swarm.engine.backend.EngineBackend`); it detects robot-robot contacts.

    :raises ScenarioError: naming ``backend`` for a plant the engine's robots are not.
    """

    name = 'mujoco'
    counts_contacts = True

    def __init__(self, sc: Scenario, real: Realization) -> None:
        """Start the engine's robots at the plant's initial state."""
        # Imported here: MuJoCo loads only for a world that uses it.
        from flock_swarm.engine.backend import EngineBackend, check_plant
        check_plant(sc.plant.model.name)
        super().__init__(sc, real)
        self.engine = EngineBackend(self.plant.name, self.x)
        self.x = self.engine.state()
        self.q, self.p = self.plant.law_state(self.x)

    def integrate(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Return the robots' state rows after the engine stepped ``dt`` under ``cmd``."""
        return self.engine.step(x, cmd, dt)

    @property
    def contacts_step(self) -> set:
        """Return the robot pairs in contact during the last step."""
        return self.engine.contacts_step

    @property
    def contacts_run(self) -> set:
        """Return the robot pairs that have touched since the start."""
        return self.engine.contacts_run


def _plant(sc: Scenario, real: Realization) -> WorldBackend:
    """Return the double integrator without a ``plant:`` section (``sim``'s exact path), the
    plant model with one."""
    return DoubleIntegrator(sc, real) if sc.plant.default else PlantModel(sc, real)


#: Every backend by its name (the world's ``backend`` parameter, ``swarm --backend``, ``sim
#: --backend``): ``plant`` (the scenario's plant model integrates, as ``sim``) or ``mujoco``
#: (the physics engine); its factory takes the scenario and its realisation.
FACTORIES: dict[str, Callable[[Scenario, Realization], WorldBackend]] = {
    'plant': _plant, 'mujoco': MujocoBackend}
#: The names, in the order ``swarm --backend`` lists them.
BACKENDS = tuple(FACTORIES)


def _known(name: str) -> str:
    """Return ``name`` if it is one of :data:`BACKENDS`, else raise ``ValueError``."""
    if name not in BACKENDS:
        raise ValueError(f'backend: unknown backend {name!r} (known: {", ".join(BACKENDS)})')
    return name


def make_backend(name: str, sc: Scenario, real: Realization) -> WorldBackend:
    """Return the backend ``name`` (one of :data:`BACKENDS`) for the scenario, at its initial
    state: ``plant`` is the double integrator without a ``plant:`` section (``sim``'s exact
    path), the plant model with one.

    :param name: the world's ``backend`` parameter.
    :param sc: the scenario.
    :param real: its realisation (the initial state).
    :raises ScenarioError: naming ``backend`` when the backend cannot take the scenario.
    :raises ValueError: for a name not in :data:`BACKENDS`.
    """
    return FACTORIES[_known(name)](sc, real)


def sim_integrator(name: str, sc: Scenario) -> Callable | None:
    """Return what integrates ``sim``'s agents for the backend ``name`` (``sim --backend``,
    the world's names): ``None`` for ``plant`` (the plant model steps itself,
    :func:`~flock_swarm.core.run.simulate`), the engine's factory for ``mujoco``.

    :raises ScenarioError: naming ``backend`` when the engine has no robot of the plant.
    :raises ValueError: for a name not in :data:`BACKENDS`.
    """
    if _known(name) == 'plant':
        return None
    # Imported here: MuJoCo loads only for a run that uses it.
    from flock_swarm.engine.backend import EngineBackend, check_plant
    check_plant(sc.plant.model.name)
    return partial(EngineBackend, sc.plant.model.name)
