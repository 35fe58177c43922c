"""The base class of plant models and the scenario's ``plant:`` section.

A plant is what an agent physically is: the papers' double integrator, a robot under a
velocity controller, a differential-drive robot. The law always computes an acceleration
``u`` for a point with position and velocity ``(q, p)``; the plant says which ``(q, p)`` that
is (:meth:`Plant.law_state`), turns ``u`` into the command it executes (:meth:`Plant.command`:
integrated from the measured velocity over the command period, saturated, transformed) and
advances its own state under that command (:meth:`Plant.step`). Velocity commands also travel
as ``geometry_msgs/Twist`` (:meth:`Plant.twist`, :meth:`Plant.from_twist`).

Every method is pure NumPy, vectorised over agents: a state is an ``(n, S)`` array whose
columns :meth:`Plant.state_names` names, a command an ``(n, C)`` array named by
:meth:`Plant.command_names`. ``sim`` and the ROS nodes call the same methods, so a lockstep
ROS run equals ``sim`` bit for bit. Models are found by name through the entry-point group
``flock_swarm.plants`` (:mod:`flock_swarm.core.registry`); docs/plants.md describes them.
"""

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core.checks import choice, number
from flock_swarm.core.errors import ScenarioError

#: The agents' command interfaces: an acceleration (``AccelStamped`` on ``cmd_accel``) or a
#: velocity (``Twist`` on ``cmd_vel``).
COMMANDS = ('accel', 'cmd_vel')
#: Frames of a ``Twist`` command (REP 103/105): the robot's own (``base_link``) or ``world``.
FRAMES = ('body', 'world')
#: The conversions of the law's acceleration into a command (``plant.conversion``): ``exact``
#: inverts the plant's known discrete dynamics so that one step delivers the law's velocity
#: change; ``naive`` integrates ``p + u T`` and hands it over as it is (the runs before the
#: exact conversion, reproduced bit for bit). docs/plants.md gives the equations.
CONVERSIONS = ('exact', 'naive')


def pad3(a: np.ndarray) -> np.ndarray:
    """Return ``(n, k)`` rows (``k <= 3``) padded with zeros to ``(n, 3)`` (a Vector3 each)."""
    out = np.zeros((a.shape[0], 3))
    out[:, :a.shape[1]] = a
    return out


@dataclass(frozen=True)
class Plant:
    """Base class of plant models: parameters as frozen dataclass fields, plus the dynamics.

    Subclasses set :attr:`name` (equal to their entry-point name) and implement
    :meth:`state_names`, :meth:`command_names`, :meth:`initial_state`, :meth:`law_state`,
    :meth:`command` and :meth:`step`; velocity plants also :meth:`twist` and
    :meth:`from_twist`. Fields annotated ``float`` are required parameters unless they have
    a default; a default of ``None`` means "no limit". Every plant has the keyword-only field
    :attr:`conversion` (``plant.conversion``), one of the class's :attr:`conversions`, which
    :meth:`command` reads.
    """

    #: Scenario name of the model (``plant.model``).
    name: ClassVar[str] = ''
    #: One line naming the source of the model (``sim --list``).
    citation: ClassVar[str] = ''
    #: The dimensions the model is defined in.
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    #: The command interfaces it takes (:data:`COMMANDS`), the default first.
    commands: ClassVar[tuple[str, ...]] = ('accel',)
    #: The ``Twist`` frames it takes (:data:`FRAMES`), the default first.
    frames: ClassVar[tuple[str, ...]] = ('world',)
    #: Whether its odometry carries a heading (orientation and yaw rate) besides the
    #: position and the linear velocity.
    oriented: ClassVar[bool] = False
    #: The conversions it offers (:data:`CONVERSIONS`), the default first.
    conversions: ClassVar[tuple[str, ...]] = ('exact',)
    #: Whether it is a differential-drive robot (what the physics engine's robots are:
    #: ``backend: mujoco`` needs one).
    differential_drive: ClassVar[bool] = False

    #: How :meth:`command` turns the law's acceleration into the command (one of
    #: :attr:`conversions`; a name, not a number, keyword-only so a subclass's fields may
    #: be required).
    conversion: str = dataclasses.field(default='exact', kw_only=True,
                                        metadata={'choices': 'conversions'})

    @classmethod
    def param_keys(cls) -> tuple[str, ...]:
        """Return the scenario keys of the parameters (beside ``model``, ``command``...)."""
        return tuple(f.name for f in dataclasses.fields(cls) if f.init)

    @classmethod
    def from_section(cls, section: dict, prefix: str) -> 'Plant':
        """Return the model of a ``plant:`` section (every parameter a number, but the names
        of a field whose metadata lists its ``choices``, as ``conversion``).

        :param section: the section's mapping.
        :param prefix: the dotted key of the section, ``'plant.'``.
        :return: the model (not yet validated).
        :raises ScenarioError: naming the first invalid key.
        """
        values = {f.name: (choice(section[f.name], prefix + f.name,
                                  getattr(cls, f.metadata['choices']))
                           if 'choices' in f.metadata else
                           number(section[f.name], prefix + f.name))
                  for f in dataclasses.fields(cls) if f.init and f.name in section}
        for f in dataclasses.fields(cls):
            if f.init and f.name not in values and f.default is dataclasses.MISSING:
                raise ScenarioError(prefix + f.name, f'missing (the {cls.name} plant needs it)')
        return cls(**values)

    def validate(self, dim: int, prefix: str) -> None:
        """Raise :class:`ScenarioError` for parameters outside the model's domain.

        The default: every numeric parameter given must be ``> 0`` (time constants, lengths,
        limits).

        :param dim: the scenario's dimension.
        :param prefix: the dotted key of the section, ``'plant.'``.
        """
        for key in self.number_keys():
            value = getattr(self, key)
            if value is not None and value <= 0.0:
                raise ScenarioError(prefix + key, f'must be > 0, got {value!r}')

    @classmethod
    def number_keys(cls) -> tuple[str, ...]:
        """Return the keys of the numeric parameters (:meth:`param_keys` but the choices)."""
        return tuple(f.name for f in dataclasses.fields(cls)
                     if f.init and 'choices' not in f.metadata)

    def limits(self) -> dict[str, float | None]:
        """Return the model's limits by name (``None``: unlimited)."""
        return {key: getattr(self, key) for key in self.number_keys()
                if key.startswith('max_')}

    def state_names(self, dim: int) -> tuple[str, ...]:
        """Return the names of the state's columns."""
        raise NotImplementedError

    def command_names(self, dim: int) -> tuple[str, ...]:
        """Return the names of the command's columns."""
        raise NotImplementedError

    def initial_state(self, q0: np.ndarray, p0: np.ndarray) -> np.ndarray:
        """Return the plant state ``(n, S)`` of the scenario's initial positions and velocities.

        :param q0: initial positions ``(n, dim)`` (the robots' positions).
        :param p0: initial velocities ``(n, dim)``.
        """
        raise NotImplementedError

    def law_state(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return what the law sees of the state: positions and velocities ``(n, dim)``."""
        raise NotImplementedError

    def command(self, x: np.ndarray, u: np.ndarray, period: float) -> np.ndarray:
        """Return the command ``(n, C)`` the plant executes for the law's acceleration ``u``,
        by the model's :attr:`conversion`.

        :param x: the measured state ``(n, S)``.
        :param u: the law's accelerations ``(n, dim)``.
        :param period: the command period [s] (the step in lockstep).
        """
        raise NotImplementedError

    def step(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Return the state after ``dt`` with ``cmd`` held (a new array)."""
        raise NotImplementedError

    @classmethod
    def velocity_commanded(cls) -> bool:
        """Return whether it takes velocity commands (``cmd_vel`` among :attr:`commands`:
        what a real robot's driver takes, so what the robot agent drives)."""
        return 'cmd_vel' in cls.commands

    def commanded_state(self, x: np.ndarray, cmd: np.ndarray) -> np.ndarray:
        """Return state rows ``x`` with their velocities replaced by the velocity commands
        ``cmd`` (the robot agent's ``integrate_from:=command``, docs/robots.md).

        The default, for a state ``(q, v)`` commanded by a velocity set-point ``v_sp``: the
        second half of the columns replaced by the command.

        :param x: state rows ``(n, S)``.
        :param cmd: the commands sent ``(n, C)``.
        :return: a new array.
        """
        out = np.array(x, dtype=float)
        out[:, out.shape[1] // 2:] = cmd
        return out

    def twist(self, x: np.ndarray, cmd: np.ndarray,
              frame: str) -> tuple[np.ndarray, np.ndarray]:
        """Return the command as ``Twist`` vectors: ``(linear (n, 3), angular (n, 3))``.

        :param x: the state the command was computed from.
        :param cmd: the command.
        :param frame: ``body`` or ``world`` (REP 103: x forward, y left, z up).
        """
        raise ValueError(f'the {self.name} plant takes no velocity command')

    def from_twist(self, x: np.ndarray, linear: np.ndarray, angular: np.ndarray,
                   frame: str) -> np.ndarray:
        """Return the command of ``Twist`` vectors: the inverse of :meth:`twist`.

        :param x: the state the command is applied to.
        :param linear: ``(n, 3)``.
        :param angular: ``(n, 3)``.
        :param frame: ``body`` or ``world``.
        """
        raise ValueError(f'the {self.name} plant takes no velocity command')

    def odometry(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return the state as ``nav_msgs/Odometry`` fields, each row one agent.

        The default, for a plant whose state is ``(q, p)`` like the double integrator's:
        the position, the identity orientation, the velocity in the world frame, no turn.

        :param x: the states ``(n, S)``.
        :return: ``(position (n, 3), orientation (n, 4) as x, y, z, w, linear (n, 3),
            angular (n, 3))``.
        """
        q, p = self.law_state(x)
        orientation = np.zeros((x.shape[0], 4))
        orientation[:, 3] = 1.0
        return pad3(q), orientation, pad3(p), np.zeros((x.shape[0], 3))

    def from_odometry(self, position: np.ndarray, orientation: np.ndarray, linear: np.ndarray,
                      angular: np.ndarray, dim: int) -> np.ndarray:
        """Return the states of odometry fields: the inverse of :meth:`odometry`, exact.

        :param position: ``(n, 3)``.
        :param orientation: ``(n, 4)``, x, y, z, w.
        :param linear: ``(n, 3)``.
        :param angular: ``(n, 3)``.
        :param dim: the scenario's dimension.
        """
        return np.concatenate([position[:, :dim], linear[:, :dim]], axis=1).astype(float)

    def recorded(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Return the arrays of the state the time series records beside ``q`` and ``p``.

        The default: the whole state as ``plant_state`` (``(n, S)``).
        """
        return {'plant_state': x}
