"""The physics engine as the world's integrator: a drop-in for the unicycle plant's ``step``.

A world with ``backend: mujoco`` advances its robots with :meth:`EngineBackend.step` instead
of the plant's exact unicycle kinematics: the same ``(v, omega)`` commands (the agents'
``cmd_vel``) go to the engine's wheel servos, the engine steps, and the state rows the plant
model holds (``x, y, qz, qw, v, omega``) are read back from the engine's bodies. So the world
records the same bag and time series, and the laws see the same points (``ell`` ahead of the
axle), whichever integrates. Robot-robot contacts are counted by the engine
(:attr:`EngineBackend.contacts_step`, :attr:`EngineBackend.contacts_run`).
"""

import numpy as np

from flock_swarm.core import registry
from flock_swarm.core.errors import ScenarioError
from flock_swarm.engine.mujoco_world import EngineWorld


def check_plant(plant_name: str) -> None:
    """Raise :class:`ScenarioError` (key ``backend``) unless the engine has robots of the
    scenario's plant: a differential-drive one (the plant says so,
    :attr:`~flock_swarm.core.plants.base.Plant.differential_drive`)."""
    if not registry.plant_class(plant_name).differential_drive:
        drives = [name for name, cls in registry.usable(registry.PLANT_GROUP).items()
                  if cls.differential_drive]
        raise ScenarioError('backend', 'mujoco drives differential-drive robots: it needs '
                            f'plant.model {" or ".join(drives)}, got {plant_name!r}')


class EngineBackend:
    """N differential-drive robots in the engine, started at a unicycle plant's state.

    :param plant_name: the scenario's plant model (must be ``unicycle``).
    :param x0: the plant's initial state rows ``(n, 6)``: ``x, y, qz, qw, v, omega``.
    :param model: the engine's robot model.
    :raises ScenarioError: for a plant the engine's robots are not.
    """

    def __init__(self, plant_name: str, x0: np.ndarray, model: str = 'turtlebot3_burger'
                 ) -> None:
        check_plant(plant_name)
        x0 = np.asarray(x0, dtype=float)
        yaw = 2.0 * np.arctan2(x0[:, 2], x0[:, 3])
        self.world = EngineWorld(x0[:, :2], yaw, model=model, speeds=x0[:, 4])

    @property
    def contacts_step(self) -> set[tuple[int, int]]:
        """Return the robot pairs in contact during the last step."""
        return self.world.contacts_step

    @property
    def contacts_run(self) -> set[tuple[int, int]]:
        """Return the robot pairs that have touched since the start."""
        return self.world.contacts_run

    def summary(self) -> dict:
        """Return the summary keys the engine tells (``sim --backend mujoco``'s, as the
        world's): ``robot_contacts``, the robot pairs that touched over the run."""
        return {'robot_contacts': len(self.world.contacts_run)}

    def state(self) -> np.ndarray:
        """Return the robots' state rows ``(n, 6)`` as the unicycle plant holds them."""
        poses, vels = self.world.poses(), self.world.velocities()
        yaw = poses[:, 2]
        c, s = np.cos(yaw), np.sin(yaw)
        return np.column_stack([poses[:, 0], poses[:, 1], np.sin(0.5 * yaw), np.cos(0.5 * yaw),
                                c * vels[:, 0] + s * vels[:, 1], vels[:, 2]])

    def step(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance the robots by ``dt`` under the commands ``(v, omega)`` held; return the new
        state rows (the engine's: ``x`` is not used, the engine holds the truth).

        :param x: the current state rows (the signature of the plant's ``step``).
        :param cmd: the commands ``(n, 2)``.
        :param dt: the step (s).
        :return: the state rows after the step.
        """
        self.world.set_twists(cmd[:, 0], cmd[:, 1])
        self.world.step(dt)
        return self.state()
