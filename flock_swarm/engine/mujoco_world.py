"""N differential-drive robots on a plane in the MuJoCo physics engine, driven by ``cmd_vel``.

The robot model is an MJCF shipped with this package (``turtlebot3_burger.xml``, written from
the TurtleBot3 Burger's published specifications, each number cited in the file and in
docs/robots.md). :class:`EngineWorld` builds N copies of it programmatically (``mujoco.MjSpec``,
one ``attach`` per robot under the prefix ``agent_<i>/``), turns each robot's velocity command
``(v, omega)`` into wheel-speed setpoints by the differential-drive kinematics, steps the engine
and reads back each robot's pose and velocity. Robot-robot contact is physical (the engine's
collision detection) and counted: the distinct pairs of robots in contact during the last step
and over the whole run.
"""

from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

#: The robot models shipped with the package: name -> MJCF file in this package.
MODELS = {'turtlebot3_burger': 'turtlebot3_burger.xml'}


@dataclass(frozen=True)
class DiffDrive:
    """A differential-drive robot's kinematics and limits.

    :param wheel_radius: ``r`` (m).
    :param wheel_separation: ``b``, the distance between the wheels' contact points (m).
    :param max_linear: the largest forward speed ``|v|`` (m/s).
    :param max_angular: the largest yaw rate ``|omega|`` (rad/s).
    """

    wheel_radius: float
    wheel_separation: float
    max_linear: float
    max_angular: float

    def wheel_speeds(self, v: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Return the wheel speeds ``(left, right)`` (rad/s, N x 2) for body twists.

        Differential-drive kinematics (Siegwart, Nourbakhsh, Scaramuzza, *Introduction to
        Autonomous Mobile Robots*, 2nd ed., eq. (3.9)): ``w_l = (v - omega b / 2) / r``,
        ``w_r = (v + omega b / 2) / r``, after ``v`` and ``omega`` are clamped to the limits.

        :param v: forward speeds (m/s), shape (N,).
        :param omega: yaw rates (rad/s), shape (N,).
        :return: wheel speeds, shape (N, 2).
        """
        v = np.clip(np.asarray(v, dtype=float), -self.max_linear, self.max_linear)
        omega = np.clip(np.asarray(omega, dtype=float), -self.max_angular, self.max_angular)
        half = 0.5 * self.wheel_separation * omega
        return np.stack([(v - half) / self.wheel_radius, (v + half) / self.wheel_radius], axis=-1)


#: The TurtleBot3 Burger (the numbers of turtlebot3_burger.xml: [D] wheels, [S] limits).
TURTLEBOT3_BURGER = DiffDrive(wheel_radius=0.033, wheel_separation=0.160, max_linear=0.22,
                              max_angular=2.84)
#: Kinematics and limits of each shipped model.
KINEMATICS = {'turtlebot3_burger': TURTLEBOT3_BURGER}


def robot_mjcf(model: str = 'turtlebot3_burger') -> str:
    """Return the MJCF text of a shipped robot model.

    :param model: a key of :data:`MODELS`.
    :return: the XML text.
    :raises ValueError: for an unknown model (one line naming it and the known ones).
    """
    if model not in MODELS:
        raise ValueError(f'engine model: unknown robot model {model!r} '
                         f'(known: {", ".join(sorted(MODELS))})')
    return resources.files(__package__).joinpath(MODELS[model]).read_text(encoding='utf-8')


def yaw_of(quat: np.ndarray) -> np.ndarray:
    """Return the yaw (rad) of unit quaternions ``(w, x, y, z)`` (..., 4), ZYX convention."""
    w, x, y, z = (quat[..., k] for k in range(4))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class EngineWorld:
    """N copies of a robot model on a plane, stepped by MuJoCo.

    :param positions: initial ``(x, y)`` of each robot's axle centre (N x 2, m).
    :param headings: initial yaw of each robot (N, rad).
    :param model: the robot model (a key of :data:`MODELS`).
    :param timestep: the engine's step (s); each :meth:`step` runs ``round(period /
        timestep)`` of them.
    :param speeds: initial forward speed of each robot (N, m/s; default: at rest), its wheels
        rolling with it.
    """

    def __init__(self, positions: np.ndarray, headings: np.ndarray,
                 model: str = 'turtlebot3_burger', timestep: float = 0.002,
                 speeds: np.ndarray | None = None) -> None:
        positions = np.asarray(positions, dtype=float)
        headings = np.asarray(headings, dtype=float)
        if (positions.ndim != 2 or positions.shape[1] != 2
                or headings.shape != positions[:, 0].shape):
            raise ValueError('engine: positions must be N x 2 and headings N '
                             f'(got {positions.shape} and {headings.shape})')
        if not (np.isfinite(timestep) and timestep > 0.0):
            raise ValueError(f'engine timestep: must be a positive number (got {timestep!r})')
        self.n = len(positions)
        text = robot_mjcf(model)
        self.kinematics = KINEMATICS[model]
        spec = mujoco.MjSpec()
        spec.modelname = f'flock_swarm_{model}_x{self.n}'
        spec.option.timestep = timestep
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        floor = spec.worldbody.add_geom()
        floor.name = 'floor'
        floor.type = mujoco.mjtGeom.mjGEOM_PLANE
        floor.size = [0.0, 0.0, 0.05]
        for i, ((x, y), yaw) in enumerate(zip(positions, headings)):
            frame = spec.worldbody.add_frame()
            frame.pos = [x, y, 0.0]
            frame.quat = [np.cos(yaw / 2.0), 0.0, 0.0, np.sin(yaw / 2.0)]
            spec.attach(mujoco.MjSpec.from_string(text), prefix=f'agent_{i}/', frame=frame)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        name = mujoco.mjtObj
        self._body = np.array([mujoco.mj_name2id(m, name.mjOBJ_BODY, f'agent_{i}/base')
                               for i in range(self.n)])
        joint = [mujoco.mj_name2id(m, name.mjOBJ_JOINT, f'agent_{i}/root') for i in range(self.n)]
        self._qpos = np.array([m.jnt_qposadr[j] for j in joint])
        self._qvel = np.array([m.jnt_dofadr[j] for j in joint])
        self._actuators = np.array([
            [mujoco.mj_name2id(m, name.mjOBJ_ACTUATOR, f'agent_{i}/wheel_{side}_motor')
             for side in ('left', 'right')] for i in range(self.n)])
        # Each geom's robot (-1: the floor), to tell robot-robot contacts from floor contacts.
        robot_of_body = np.full(m.nbody, -1)
        for i, b in enumerate(self._body):
            robot_of_body[m.body_rootid == b] = i
        self._robot_of_geom = robot_of_body[m.geom_bodyid]
        if speeds is not None:
            speeds = np.asarray(speeds, dtype=float)
            self.data.qvel[self._qvel] = speeds * np.cos(headings)
            self.data.qvel[self._qvel + 1] = speeds * np.sin(headings)
            wheels = [m.jnt_dofadr[m.actuator_trnid[a, 0]] for a in self._actuators.ravel()]
            self.data.qvel[wheels] = np.repeat(speeds / self.kinematics.wheel_radius, 2)
        mujoco.mj_forward(m, self.data)
        self.contacts_step: set[tuple[int, int]] = set()
        self.contacts_run: set[tuple[int, int]] = set()
        self.steps = 0

    @property
    def time(self) -> float:
        """The engine's time (s)."""
        return float(self.data.time)

    def set_twists(self, v: np.ndarray, omega: np.ndarray) -> None:
        """Set each robot's body twist command (the ``cmd_vel`` of REP 103: ``linear.x``,
        ``angular.z``), held until the next call.

        :param v: forward speeds (m/s), shape (N,).
        :param omega: yaw rates (rad/s), shape (N,).
        """
        self.data.ctrl[self._actuators] = self.kinematics.wheel_speeds(v, omega)

    def step(self, period: float) -> None:
        """Advance the engine by ``period`` seconds with the commands held (zero-order hold).

        The robot-robot pairs in contact at any engine step of it are in
        :attr:`contacts_step` and added to :attr:`contacts_run`.

        :param period: the time to advance (s), a whole number of engine timesteps.
        """
        substeps = max(1, int(round(period / self.model.opt.timestep)))
        pairs: set[tuple[int, int]] = set()
        for _ in range(substeps):
            mujoco.mj_step(self.model, self.data)
            pairs.update(self._robot_pairs_in_contact())
        self.contacts_step = pairs
        self.contacts_run.update(pairs)
        self.steps += 1

    def _robot_pairs_in_contact(self) -> set[tuple[int, int]]:
        """Return the distinct robot pairs ``(i, j)``, ``i < j``, in contact now."""
        ncon = self.data.ncon
        if ncon == 0:
            return set()
        geoms = self.data.contact.geom[:ncon]
        a = self._robot_of_geom[geoms[:, 0]]
        b = self._robot_of_geom[geoms[:, 1]]
        keep = (a >= 0) & (b >= 0) & (a != b)
        return {(int(min(i, j)), int(max(i, j))) for i, j in zip(a[keep], b[keep])}

    def poses(self) -> np.ndarray:
        """Return each robot's ``(x, y, yaw)`` (N x 3): the axle centre and the heading."""
        qpos = self.data.qpos
        xy = np.stack([qpos[self._qpos], qpos[self._qpos + 1]], axis=-1)
        quat = np.stack([qpos[self._qpos + k] for k in range(3, 7)], axis=-1)
        return np.column_stack([xy, yaw_of(quat)])

    def velocities(self) -> np.ndarray:
        """Return each robot's world-frame ``(vx, vy, yaw_rate)`` (N x 3).

        A free joint's first three velocities are the linear velocity in the world frame, its
        last three the angular velocity in the body frame (MuJoCo documentation, "Floating
        objects"); a robot upright on the plane has its body z along the world's.
        """
        qvel = self.data.qvel
        return np.stack([qvel[self._qvel], qvel[self._qvel + 1], qvel[self._qvel + 5]], axis=-1)
