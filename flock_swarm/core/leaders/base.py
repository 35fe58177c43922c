"""The virtual leader: the base class of leader models, its state, and its integrator.

A leader model is one frozen dataclass: its parameters are the fields, read from the
scenario's ``leader:`` section beside ``model``, ``position`` and ``velocity`` (or from the
``intrinsic:`` section when agents share the model as intrinsic dynamics). It carries its
own validation, its ODE ``p' = f(t, q, p)`` and, for the step-size check, its Jacobian.
The virtual leader obeys ``q' = p, p' = f(t, q, p)`` ([Su09] eq. (6), [Zhou12] eq. (2),
[Yu10] eq. (1)), advanced by classical RK4.

Models are found by name through the entry-point group ``flock_swarm.leaders``
(:mod:`flock_swarm.core.registry`); docs/extending.md shows how to add one.
"""

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np

from flock_swarm.core.checks import mapping, number, only, vector
from flock_swarm.core.errors import ScenarioError

VelocityField = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class LeaderState:
    """The virtual leader's state: position, velocity and acceleration ``f_gamma``."""

    q: np.ndarray
    p: np.ndarray
    a: np.ndarray


@dataclass(frozen=True)
class LeaderModel:
    """Base class of leader models: parameters as frozen dataclass fields, plus the ODE.

    Subclasses set :attr:`name` (equal to their entry-point name) and implement
    :meth:`acceleration`; they may override :meth:`validate`, :meth:`jacobian`,
    :meth:`initial_state` (a model whose path fixes where it starts) and
    :meth:`from_section` (for a YAML layout other than one key per field).
    """

    #: Scenario name of the model (``leader.model``).
    name: ClassVar[str] = ''
    #: One line naming the paper and equation (``sim --list``); empty: the docstring's first.
    citation: ClassVar[str] = ''
    #: Whether the acceleration depends on the velocity only, ``f(p)``: such a model can
    #: also be the agents' intrinsic dynamics (``intrinsic.model``).
    autonomous: ClassVar[bool] = True
    #: Whether the acceleration is identically zero (agents sharing it need no RK4).
    still: ClassVar[bool] = False
    #: Whether the scenario gives ``leader.velocity`` (a sink stands still).
    moving: ClassVar[bool] = True
    #: The dimensions the model is defined in.
    dims: ClassVar[tuple[int, ...]] = (2, 3)

    @classmethod
    def param_keys(cls) -> tuple[str, ...]:
        """Return the scenario keys of the parameters (beside ``model``, ``position``...)."""
        return tuple(f.name for f in dataclasses.fields(cls) if f.init)

    @classmethod
    def from_section(cls, section: dict, dim: int, prefix: str) -> 'LeaderModel':
        """Return the model of a scenario section (keys other than the state are parameters).

        Fields annotated ``float`` or ``int`` read a number, ``tuple`` a vector of ``dim``
        numbers. The state keys (``model``, ``position``, ``velocity``) are the caller's.

        :param section: the ``leader:`` (or ``intrinsic:``) mapping.
        :param dim: the scenario's dimension.
        :param prefix: the dotted key of the section, e.g. ``'leader.'``.
        :return: the model (not yet validated).
        :raises ScenarioError: naming the first invalid key.
        """
        values: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            if not f.init or f.name not in section:
                continue
            key = prefix + f.name
            kind = f.type if isinstance(f.type, str) else getattr(f.type, '__name__', '')
            if kind.startswith('tuple'):
                values[f.name] = tuple(vector(section[f.name], key, dim).tolist())
            elif kind == 'int':
                values[f.name] = int(number(section[f.name], key))
            else:
                values[f.name] = number(section[f.name], key)
        return cls(**values)

    def validate(self, dim: int, prefix: str) -> None:
        """Raise :class:`ScenarioError` for parameters outside the model's domain.

        :param dim: the scenario's dimension.
        :param prefix: the dotted key of the section, e.g. ``'leader.'``.
        """

    def acceleration(self, t: float, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Return ``p' = f(t, q, p)`` for states of shape ``(..., dim)``."""
        raise NotImplementedError

    def velocity_field(self) -> VelocityField:
        """Return ``f(p)`` of an autonomous model (the agents' intrinsic dynamics)."""
        if not self.autonomous:
            raise ValueError(f'leader model {self.name} depends on time or position')
        return lambda p: self.acceleration(0.0, p, p)

    def initial_state(self, dim: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Return the leader's own ``(q_gamma(0), p_gamma(0))``, or ``None`` (the default).

        ``None``: the scenario gives ``leader.position`` (and ``leader.velocity``). A model
        whose parameters fix its start (a circle's centre, radius and phase) returns it;
        the scenario then must not give either key.

        :param dim: the scenario's dimension.
        :return: the position and velocity, each of ``dim`` numbers, or ``None``.
        """
        return None

    def jacobian(self, p: np.ndarray) -> np.ndarray | None:
        """Return ``df/dp`` at one velocity (the RK4 step-size check), or ``None``: unchecked."""
        return None


def parse_model(model: type[LeaderModel], section: dict, dim: int, prefix: str,
                state_keys: tuple[str, ...]) -> LeaderModel:
    """Return the validated model of a scenario section.

    :param model: the model's class.
    :param section: the section's mapping.
    :param dim: the scenario's dimension.
    :param prefix: the dotted key of the section.
    :param state_keys: the keys of the section that are not parameters.
    :return: the model.
    :raises ScenarioError: naming the first invalid key.
    """
    if dim not in model.dims:
        raise ScenarioError('dim', f'the {model.name} model needs dim = '
                            f'{" or ".join(map(str, model.dims))}, got {dim}')
    only(mapping(section, prefix.rstrip('.')), (*state_keys, *model.param_keys()), prefix)
    instance = model.from_section(section, dim, prefix)
    instance.validate(dim, prefix)
    return instance


class VirtualLeader:
    """The virtual leader ``q' = p, p' = f(t, q, p)`` of [Su09] eq. (6), advanced by RK4."""

    def __init__(self, model: LeaderModel, q0: np.ndarray, p0: np.ndarray) -> None:
        """Create the leader at ``t = 0``.

        :param model: its model.
        :param q0: initial position ``q_gamma(0)``.
        :param p0: initial velocity ``p_gamma(0)``.
        """
        self.model = model
        self._q = np.array(q0, dtype=float)
        self._p = np.array(p0, dtype=float)
        self._t = 0.0
        self._steps = 0

    @property
    def state(self) -> LeaderState:
        """Return the current state, with ``a = f(t, q, p)`` evaluated now."""
        return LeaderState(self._q.copy(), self._p.copy(),
                           self.model.acceleration(self._t, self._q, self._p))

    def step(self, dt: float) -> None:
        """Advance the leader by ``dt`` (classical RK4; exact for polynomial motion)."""
        f, t, q, p = self.model.acceleration, self._t, self._q, self._p
        k1q, k1p = p, f(t, q, p)
        q2, p2 = q + 0.5 * dt * k1q, p + 0.5 * dt * k1p
        k2q, k2p = p2, f(t + 0.5 * dt, q2, p2)
        q3, p3 = q + 0.5 * dt * k2q, p + 0.5 * dt * k2p
        k3q, k3p = p3, f(t + 0.5 * dt, q3, p3)
        q4, p4 = q + dt * k3q, p + dt * k3p
        k4q, k4p = p4, f(t + dt, q4, p4)
        self._q = q + (dt / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        self._p = p + (dt / 6.0) * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
        # Time as a step count times dt, not a running sum: t_k = k dt exactly as stamped.
        self._steps += 1
        self._t = self._steps * dt
