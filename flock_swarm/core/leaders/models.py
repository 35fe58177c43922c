"""The built-in leader models: constant velocity or acceleration, Lorenz, Lu, linear, sink.

Each is registered under its ``name`` in the entry-point group ``flock_swarm.leaders``
(setup.py), exactly as a user's model would be. The chaotic and linear models also serve as
the agents' intrinsic dynamics (``intrinsic.model``, [Zhou12] eq. (1), [Yu10] eq. (36)).
"""

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from flock_swarm.core.checks import mapping, matrix, number, only, vector
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.leaders.base import LeaderModel


@dataclass(frozen=True)
class ConstantVelocity(LeaderModel):
    """A leader moving at constant velocity, ``p' = 0`` ([Su09] Section V.A, Fig. 2)."""

    name: ClassVar[str] = 'constant_velocity'
    citation: ClassVar[str] = 'Su, Wang, Lin 2009, Section V.A: p_gamma constant (Fig. 2, 3)'
    still: ClassVar[bool] = True

    def acceleration(self, t, q, p):
        """Return zero."""
        return np.zeros_like(p)

    def jacobian(self, p):
        """Return zero."""
        return np.zeros((p.shape[-1], p.shape[-1]))


@dataclass(frozen=True)
class Sink(ConstantVelocity):
    """A fixed point ``(q_d, p_d) = (q_d, 0)`` the flock gathers at ([OS03] eq. (40))."""

    name: ClassVar[str] = 'sink'
    citation: ClassVar[str] = 'Olfati-Saber 2003, eq. (40): a sink (q_d, 0)'
    moving: ClassVar[bool] = False


@dataclass(frozen=True)
class ConstantAcceleration(LeaderModel):
    """A leader with constant acceleration ``f_gamma`` ([Su09] Section V.C, Fig. 7).

    :ivar f_gamma: the acceleration, one value per dimension (scenario key
        ``acceleration``).
    """

    name: ClassVar[str] = 'constant_acceleration'
    citation: ClassVar[str] = 'Su, Wang, Lin 2009, Section V.C: constant f_gamma (Fig. 7)'

    f_gamma: tuple = ()
    _acc: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Keep ``f_gamma`` as an array for the ODE."""
        object.__setattr__(self, '_acc', np.asarray(self.f_gamma, dtype=float))

    @classmethod
    def param_keys(cls):
        """Return ``('acceleration',)``."""
        return ('acceleration',)

    @classmethod
    def from_section(cls, section, dim, prefix):
        """Read ``acceleration`` (required), a vector of ``dim`` numbers."""
        if 'acceleration' not in section:
            raise ScenarioError(prefix + 'acceleration', 'missing')
        return cls(tuple(vector(section['acceleration'], prefix + 'acceleration', dim)
                         .tolist()))

    def acceleration(self, t, q, p):
        """Return ``f_gamma`` broadcast to ``p``'s shape."""
        return np.broadcast_to(self._acc, p.shape).copy()

    def jacobian(self, p):
        """Return zero."""
        return np.zeros((p.shape[-1], p.shape[-1]))


def lorenz(p: np.ndarray, sigma: float, rho: float, beta: float) -> np.ndarray:
    """Return the Lorenz vector field applied to velocities ([Su09] Section V.B).

    ``(sigma (y - x), rho x - x z - y, x y - beta z)`` with ``(x, y, z) = p``.

    :param p: velocities, shape ``(..., 3)``.
    :return: accelerations, shape ``(..., 3)``.
    """
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack((sigma * (y - x), rho * x - x * z - y, x * y - beta * z), axis=-1)


def lu(p: np.ndarray, a: float, b: float, c: float) -> np.ndarray:
    """Return the Lu system ``R x + T(x)`` applied to velocities ([Zhou12] Section 5.1).

    ``(a (y - x), c y - x z, x y - b z)`` with ``(x, y, z) = p``.

    :param p: velocities, shape ``(..., 3)``.
    :return: accelerations, shape ``(..., 3)``.
    """
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    return np.stack((a * (y - x), c * y - x * z, x * y - b * z), axis=-1)


@dataclass(frozen=True)
class _Chaotic(LeaderModel):
    """A 3-D chaotic velocity field whose parameters sit in a ``params:`` subsection."""

    dims: ClassVar[tuple[int, ...]] = (3,)

    @classmethod
    def param_keys(cls):
        """Return ``('params',)``: the parameters are one nested mapping."""
        return ('params',)

    @classmethod
    def from_section(cls, section, dim, prefix):
        """Read the optional ``params:`` mapping (defaults: the papers' values)."""
        params = mapping(section.get('params'), prefix + 'params')
        names = tuple(f.name for f in cls.__dataclass_fields__.values() if f.init)
        only(params, names, prefix + 'params.')
        return cls(**{k: number(v, f'{prefix}params.{k}') for k, v in params.items()})


@dataclass(frozen=True)
class Lorenz(_Chaotic):
    """The Lorenz system as a velocity field ([Su09] Section V.B, Figs. 5 and 6).

    :ivar sigma: Prandtl number.
    :ivar rho: Rayleigh number.
    :ivar beta: geometric factor.
    """

    name: ClassVar[str] = 'lorenz'
    citation: ClassVar[str] = 'Su, Wang, Lin 2009, Section V.B: Lorenz leader velocity'

    sigma: float = 10.0
    rho: float = 28.0
    beta: float = 8.0 / 3.0

    def acceleration(self, t, q, p):
        """Return the Lorenz field at ``p``."""
        return lorenz(p, self.sigma, self.rho, self.beta)

    def jacobian(self, p):
        """Return the Lorenz Jacobian at ``p``."""
        x, y, z = p
        return np.array([[-self.sigma, self.sigma, 0.0],
                         [self.rho - z, -1.0, -x],
                         [y, x, -self.beta]])


@dataclass(frozen=True)
class Lu(_Chaotic):
    """The Lu system ``R x + T(x)`` as a velocity field ([Zhou12] Section 5.1).

    :ivar a: linear coupling.
    :ivar b: damping of the third component.
    :ivar c: growth of the second component.
    """

    name: ClassVar[str] = 'lu'
    citation: ClassVar[str] = 'Zhou et al. 2012, Section 5.1: Lu system (a, b, c) = (36, 3, 20)'

    a: float = 36.0
    b: float = 3.0
    c: float = 20.0

    def acceleration(self, t, q, p):
        """Return the Lu field at ``p``."""
        return lu(p, self.a, self.b, self.c)

    def jacobian(self, p):
        """Return the Lu Jacobian at ``p``."""
        x, y, z = p
        return np.array([[-self.a, self.a, 0.0],
                         [-z, self.c, -x],
                         [y, x, -self.b]])


@dataclass(frozen=True)
class Linear(LeaderModel):
    """A linear velocity field ``p' = A p`` ([Yu10] Section 4.1: a rotating leader).

    :ivar A: the matrix, ``dim x dim`` (rows as tuples).
    """

    name: ClassVar[str] = 'linear'
    citation: ClassVar[str] = 'Yu, Chen, Cao 2010, Section 4.1: v_o\' = A v_o'

    A: tuple = ()
    _mat: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Keep ``A`` as an array for the ODE."""
        object.__setattr__(self, '_mat', np.asarray(self.A, dtype=float))

    @classmethod
    def from_section(cls, section, dim, prefix):
        """Read ``A`` (required), a ``dim x dim`` matrix."""
        if 'A' not in section:
            raise ScenarioError(prefix + 'A', 'missing (required for the linear model)')
        mat = matrix(section['A'], prefix + 'A', dim, dim)
        return cls(tuple(tuple(row) for row in mat.tolist()))

    def acceleration(self, t, q, p):
        """Return ``A p``."""
        return p @ self._mat.T

    def jacobian(self, p):
        """Return ``A``."""
        return self._mat.copy()
