"""The built-in plant models: double integrator, velocity lag, unicycle.

Each is registered under its ``name`` in the entry-point group ``flock_swarm.plants``
(setup.py), exactly as a user's plant would be. docs/plants.md gives the equations.
"""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core.dynamics import step_double_integrator
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.plants.base import CONVERSIONS, Plant, pad3


@dataclass(frozen=True)
class _Holonomic(Plant):
    """A plant whose state is the law's ``(q, velocity)`` itself, ``dim`` columns each."""

    #: The symbols of the velocity's and the command's columns.
    symbols: ClassVar[tuple[str, str]] = ('p', 'u')

    def state_names(self, dim: int) -> tuple[str, ...]:
        """Return ``q_x.., <velocity>_x..``."""
        axes = 'xyz'[:dim]
        return (*(f'q_{a}' for a in axes), *(f'{self.symbols[0]}_{a}' for a in axes))

    def command_names(self, dim: int) -> tuple[str, ...]:
        """Return ``<command>_x..``."""
        return tuple(f'{self.symbols[1]}_{a}' for a in 'xyz'[:dim])

    def initial_state(self, q0: np.ndarray, p0: np.ndarray) -> np.ndarray:
        """Return ``[q0, p0]``: the agents start moving with the scenario's velocities."""
        return np.concatenate([q0, p0], axis=1)

    def law_state(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(q, velocity)``."""
        d = x.shape[1] // 2
        return x[:, :d], x[:, d:]


@dataclass(frozen=True)
class DoubleIntegrator(_Holonomic):
    """The papers' agent ``q' = p, p' = u`` under a zero-order hold ([Su09] eq. (1)).

    Its state is ``(q, p)``, its command the acceleration ``u`` itself. A run with this plant
    takes today's code path (:func:`~flock_swarm.core.dynamics.step_agents`): the methods
    here serve callers that treat every plant alike.
    """

    name: ClassVar[str] = 'double_integrator'
    citation: ClassVar[str] = "Su, Wang, Lin 2009, eq. (1): q' = p, p' = u, exact zero-order hold"
    conversions: ClassVar[tuple[str, ...]] = CONVERSIONS

    def command(self, x: np.ndarray, u: np.ndarray, period: float) -> np.ndarray:
        """Return ``u`` (a copy): the double integrator executes the acceleration, whatever
        the conversion (both deliver the law exactly)."""
        return np.array(u, dtype=float)

    def step(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance exactly (:func:`~flock_swarm.core.dynamics.step_double_integrator`)."""
        q, p = self.law_state(x)
        return np.concatenate(step_double_integrator(q, p, cmd, dt), axis=1)


@dataclass(frozen=True)
class VelocityLag(_Holonomic):
    """A robot under a velocity controller: first-order tracking of a velocity setpoint.

    ``q' = v``, ``v' = (v_sp - v) / tau``, the setpoint ``v_sp`` held over a step and
    discretised exactly (the lag is linear). The law asks for the velocity ``w = p + u T``
    after the command period ``T`` (its acceleration integrated from the measured velocity
    ``p``); :meth:`command` turns ``w`` into the setpoint (``conversion``):

    - ``exact`` (the default): ``w``'s norm saturated at ``max_speed``, its distance from ``p``
      at ``(1 - e) tau max_accel``, then the exact zero-order hold inverted,
      ``v_sp = p + (w - p) / (1 - e)``, ``e = exp(-T / conversion_tau)``: after one period
      the velocity is ``w`` (to rounding, when ``conversion_tau = tau``).
    - ``naive``: ``v_sp = w`` saturated the same way (the distance at ``tau max_accel``): the
      velocity reaches only ``p + (1 - e) (w - p)`` after a period, the law with every gain
      divided by ``T / (tau (1 - e))`` roughly (the runs before the exact conversion).

    Either way the lag's acceleration ``(v_sp - v) / tau`` is largest at the start of a step,
    ``|v_sp - p| / tau <= max_accel``. Ground robots (2-D) and multirotors under a velocity
    controller (3-D).
    """

    name: ClassVar[str] = 'velocity_lag'
    citation: ClassVar[str] = ("first-order lag v' = (v_sp - v) / tau, exact discretisation; "
                               'speed and acceleration limits')
    commands: ClassVar[tuple[str, ...]] = ('cmd_vel', 'accel')
    frames: ClassVar[tuple[str, ...]] = ('world',)
    symbols: ClassVar[tuple[str, str]] = ('v', 'v_sp')
    conversions: ClassVar[tuple[str, ...]] = CONVERSIONS

    #: Time constant of the velocity controller [s].
    tau: float = 0.1
    #: Largest speed [m/s] (``None``: unlimited).
    max_speed: float | None = None
    #: Largest acceleration [m/s^2] (``None``: unlimited).
    max_accel: float | None = None
    #: The time constant the exact conversion assumes [s] (``None``: ``tau``): a robot whose
    #: lag is known only roughly.
    conversion_tau: float | None = None

    def validate(self, dim: int, prefix: str) -> None:
        """Check every number ``> 0``, and ``conversion_tau`` only with the exact conversion."""
        super().validate(dim, prefix)
        if self.conversion_tau is not None and self.conversion != 'exact':
            raise ScenarioError(prefix + 'conversion_tau', 'only with conversion: exact (the '
                                f'{self.conversion} conversion assumes no lag)')

    def command(self, x: np.ndarray, u: np.ndarray, period: float) -> np.ndarray:
        """Return the saturated setpoint ``v_sp`` (see the class).

        The exact conversion: with ``a = 1 - exp(-T / tau_c)`` (``tau_c`` the assumed lag,
        ``conversion_tau`` or ``tau``) the setpoint ``v_sp = p + (w - p) / a`` held over ``T``
        gives ``v(t) = p + (w - p) (1 - exp(-t / tau)) / a``: for ``tau_c = tau`` the velocity
        moves along the segment from ``p`` (``t = 0``) to ``w`` (``t = T``) and never leaves
        it, so it stays within ``max(|p|, |w|) <= max_speed`` (a convex set holds the segment)
        although ``|v_sp|`` itself may exceed ``max_speed``. With ``tau_c < tau`` it stops
        short of ``w`` (fraction ``(1 - exp(-T / tau)) / a < 1``), still on the segment; with
        ``tau_c > tau`` it overshoots ``w`` by that fraction and may exceed ``max_speed``. The
        acceleration ``(v_sp - v) / tau`` is largest at ``t = 0``: ``|w - p| <= a tau
        max_accel`` keeps it within ``max_accel``.
        """
        p = x[:, x.shape[1] // 2:]
        wanted = p + u * period
        if self.max_speed is not None:
            wanted = wanted * _shrink(np.linalg.norm(wanted, axis=1), self.max_speed)[:, None]
        if self.conversion == 'naive':
            reach = 1.0
        else:
            reach = -np.expm1(-period / (self.conversion_tau or self.tau))
        if self.max_accel is not None:
            change = wanted - p
            wanted = p + change * _shrink(np.linalg.norm(change, axis=1),
                                          reach * self.tau * self.max_accel)[:, None]
        if self.conversion == 'naive':
            return wanted
        return p + (wanted - p) / reach

    def step(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance exactly: ``v = v_sp + (v - v_sp) e``, ``q += v_sp dt + (v - v_sp) tau (1 - e)``
        with ``e = exp(-dt / tau)``."""
        q, v = self.law_state(x)
        gap = v - cmd
        rest = -np.expm1(-dt / self.tau)
        return np.concatenate([q + cmd * dt + gap * (self.tau * rest), cmd + gap * (1.0 - rest)],
                              axis=1)

    def twist(self, x: np.ndarray, cmd: np.ndarray,
              frame: str) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(v_sp, 0)`` in the world frame (the robot has no heading here)."""
        _frame(self, frame)
        return pad3(cmd), np.zeros((cmd.shape[0], 3))

    def from_twist(self, x: np.ndarray, linear: np.ndarray, angular: np.ndarray,
                   frame: str) -> np.ndarray:
        """Return ``v_sp`` from a world-frame ``Twist``."""
        _frame(self, frame)
        return np.array(linear[:, :x.shape[1] // 2], dtype=float)


@dataclass(frozen=True)
class Unicycle(Plant):
    """A differential-drive robot steered through the point at distance ``ell`` ahead of the
    axle (the near-identity diffeomorphism).

    Kinematics: ``x' = v cos(theta)``, ``y' = v sin(theta)``, ``theta' = omega``, inputs the
    forward speed ``v`` and yaw rate ``omega``, held over a step and integrated exactly.
    The law sees the point ``q = (x, y) + ell (cos theta, sin theta)`` and its velocity
    ``p = R(theta) (v, ell omega)`` (Lawton, Beard, Young 2003, Sec. II, the "hand
    position"; Olfati-Saber 2002, near-identity diffeomorphisms for SE(2) vehicles). The
    command steers the point to the desired velocity ``w = p + u T`` (``conversion``):

    - ``naive``: it inverts that map at the current heading, ``v = c w_x + s w_y``,
      ``omega = (-s w_x + c w_y) / ell``: the point has velocity ``w`` at the start of the
      step, but the robot turns by ``omega T`` during it and the velocity with it.
    - ``exact`` (the default): it inverts the map at the heading the robot has after the
      period, ``theta + omega T`` (:func:`exact_turn`), so the point's velocity after one
      held step is ``w`` (to rounding).

    Then it saturates (the accelerations first, from the executed ``v``, ``omega``; then
    ``max_speed`` and ``max_yaw_rate``).

    The heading is held as the unit quaternion ``(qz, qw) = (sin(theta / 2), cos(theta / 2))``
    of a yaw rotation: exactly what ``nav_msgs/Odometry`` carries, so an agent rebuilds the
    world's state bit for bit; ``theta`` is recorded beside it (``heading``).
    """

    name: ClassVar[str] = 'unicycle'
    citation: ClassVar[str] = ('Lawton, Beard, Young 2003 Sec. II / Olfati-Saber 2002: unicycle '
                               'steered by the point ell ahead of the axle')
    dims: ClassVar[tuple[int, ...]] = (2,)
    commands: ClassVar[tuple[str, ...]] = ('cmd_vel', 'accel')
    frames: ClassVar[tuple[str, ...]] = ('body', 'world')
    oriented: ClassVar[bool] = True
    conversions: ClassVar[tuple[str, ...]] = CONVERSIONS
    differential_drive: ClassVar[bool] = True

    #: Distance of the steered point ahead of the axle [m].
    ell: float = 0.1
    #: Largest forward speed [m/s] (``None``: unlimited).
    max_speed: float | None = None
    #: Largest yaw rate [rad/s] (``None``: unlimited).
    max_yaw_rate: float | None = None
    #: Largest forward acceleration [m/s^2] (``None``: unlimited).
    max_accel: float | None = None
    #: Largest yaw acceleration [rad/s^2] (``None``: unlimited).
    max_yaw_accel: float | None = None

    def state_names(self, dim: int) -> tuple[str, ...]:
        """Return ``x, y, qz, qw, v, omega`` (heading as a yaw quaternion)."""
        return ('x', 'y', 'qz', 'qw', 'v', 'omega')

    def command_names(self, dim: int) -> tuple[str, ...]:
        """Return ``v, omega``."""
        return ('v', 'omega')

    def initial_state(self, q0: np.ndarray, p0: np.ndarray) -> np.ndarray:
        """Return robots at ``q0`` heading along ``p0`` (``theta = 0`` where it is zero), driving
        at ``|p0|`` (saturated) with no yaw rate."""
        theta = np.arctan2(p0[:, 1], p0[:, 0])
        v = np.linalg.norm(p0, axis=1)
        if self.max_speed is not None:
            v = np.minimum(v, self.max_speed)
        n = q0.shape[0]
        return np.column_stack([q0[:, 0], q0[:, 1], np.sin(0.5 * theta), np.cos(0.5 * theta),
                                v, np.zeros(n)])

    def heading(self, x: np.ndarray) -> np.ndarray:
        """Return ``theta`` in ``(-pi, pi]`` of states ``x``."""
        c, s = self._cos_sin(x)
        return np.arctan2(s, c)

    def _cos_sin(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        qz, qw = x[:, 2], x[:, 3]
        return qw * qw - qz * qz, 2.0 * qz * qw

    def commanded_state(self, x: np.ndarray, cmd: np.ndarray) -> np.ndarray:
        """Return state rows ``x`` with ``(v, omega)`` replaced by the commands'."""
        out = np.array(x, dtype=float)
        out[:, 4:6] = cmd[:, :2]
        return out

    def law_state(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the point ahead of the axle and its velocity ``R(theta) (v, ell omega)``."""
        c, s = self._cos_sin(x)
        v, w = x[:, 4], x[:, 5] * self.ell
        q = np.column_stack([x[:, 0] + self.ell * c, x[:, 1] + self.ell * s])
        p = np.column_stack([v * c - w * s, v * s + w * c])
        return q, p

    def command(self, x: np.ndarray, u: np.ndarray, period: float) -> np.ndarray:
        """Return ``(v, omega)`` steering the point to ``p + u T`` (see the class)."""
        _, p = self.law_state(x)
        wanted = p + u * period
        c, s = self._cos_sin(x)
        # The wanted velocity in the body frame: forward, left.
        ahead = c * wanted[:, 0] + s * wanted[:, 1]
        left = c * wanted[:, 1] - s * wanted[:, 0]
        if self.conversion == 'naive':
            v = ahead
            w = left / self.ell
        else:
            turn = exact_turn(ahead, left, period / self.ell)
            ct, st = np.cos(turn), np.sin(turn)
            v = ct * ahead + st * left
            w = turn / period
        if self.max_accel is not None:
            v = np.clip(v, x[:, 4] - self.max_accel * period, x[:, 4] + self.max_accel * period)
        if self.max_yaw_accel is not None:
            w = np.clip(w, x[:, 5] - self.max_yaw_accel * period,
                        x[:, 5] + self.max_yaw_accel * period)
        if self.max_speed is not None:
            v = np.clip(v, -self.max_speed, self.max_speed)
        if self.max_yaw_rate is not None:
            w = np.clip(w, -self.max_yaw_rate, self.max_yaw_rate)
        return np.column_stack([v, w])

    def step(self, x: np.ndarray, cmd: np.ndarray, dt: float) -> np.ndarray:
        """Advance exactly with ``(v, omega)`` held: the arc
        ``(x, y) += v dt sinc(omega dt / 2) (cos, sin)(theta + omega dt / 2)``, the heading
        rotated by ``omega dt`` (quaternion product, renormalised)."""
        v, w = cmd[:, 0], cmd[:, 1]
        half = 0.5 * w * dt
        # A yaw rotation by half the turn is the quaternion (sin, cos) of a quarter of it.
        ch, sh = np.cos(0.5 * half), np.sin(0.5 * half)
        qz, qw = x[:, 2], x[:, 3]
        # The mid-step heading: the current one rotated by half the turn.
        mz, mw = qz * ch + qw * sh, qw * ch - qz * sh
        cm, sm = mw * mw - mz * mz, 2.0 * mz * mw
        # np.sinc is sin(pi a) / (pi a): finite at a straight drive (omega = 0).
        arc = v * dt * np.sinc(half / np.pi)
        nz, nw = mz * ch + mw * sh, mw * ch - mz * sh
        norm = np.hypot(nz, nw)
        return np.column_stack([x[:, 0] + arc * cm, x[:, 1] + arc * sm, nz / norm, nw / norm,
                                v, w])

    def twist(self, x: np.ndarray, cmd: np.ndarray,
              frame: str) -> tuple[np.ndarray, np.ndarray]:
        """Return ``((v, 0, 0), (0, 0, omega))`` in the body frame, or the linear part
        ``v (cos theta, sin theta, 0)`` in the world frame."""
        _frame(self, frame)
        n = cmd.shape[0]
        angular = np.zeros((n, 3))
        angular[:, 2] = cmd[:, 1]
        if frame == 'body':
            return pad3(cmd[:, :1]), angular
        c, s = self._cos_sin(x)
        return pad3(np.column_stack([cmd[:, 0] * c, cmd[:, 0] * s])), angular

    def from_twist(self, x: np.ndarray, linear: np.ndarray, angular: np.ndarray,
                   frame: str) -> np.ndarray:
        """Return ``(v, omega)``: ``linear.x`` in the body frame (exact), the projection of
        ``linear`` on the heading in the world frame (to rounding)."""
        _frame(self, frame)
        if frame == 'body':
            v = linear[:, 0]
        else:
            c, s = self._cos_sin(x)
            v = c * linear[:, 0] + s * linear[:, 1]
        return np.column_stack([v, angular[:, 2]]).astype(float)

    def odometry(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return the axle's position, the heading as orientation, and the body-frame twist
        ``(v, 0, 0)``, ``(0, 0, omega)`` (REP 105: an odometry's twist is in its child frame).
        """
        n = x.shape[0]
        orientation = np.zeros((n, 4))
        orientation[:, 2:] = x[:, 2:4]
        angular = np.zeros((n, 3))
        angular[:, 2] = x[:, 5]
        return pad3(x[:, :2]), orientation, pad3(x[:, 4:5]), angular

    def from_odometry(self, position: np.ndarray, orientation: np.ndarray, linear: np.ndarray,
                      angular: np.ndarray, dim: int) -> np.ndarray:
        """Return the states of odometry fields (:meth:`odometry`'s inverse, exact).

        A yaw-only orientation is assumed (a ground robot); its ``z``, ``w`` are the heading.
        """
        return np.column_stack([position[:, 0], position[:, 1], orientation[:, 2],
                                orientation[:, 3], linear[:, 0], angular[:, 2]]).astype(float)

    def recorded(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Return the state and the heading ``theta`` (``heading``, ``(n,)``)."""
        return {'plant_state': x, 'heading': self.heading(x)}


#: The largest number of iterations of :func:`exact_turn` (it stops earlier at a fixed point).
TURN_ITERATIONS = 100
#: Cells per radian of :func:`exact_turn`'s search for the nearest root when it is not unique.
TURN_GRID = 32


def exact_turn(ahead: np.ndarray, left: np.ndarray, ratio: float) -> np.ndarray:
    """Return the turn ``delta = omega T`` of the unicycle's exact conversion, per robot.

    The point ``ell`` ahead of the axle, ``(v, omega)`` held over ``T``, has the velocity
    ``R(theta + delta) (v, ell omega)`` at the end. Equal to the wanted ``w``, whose body-frame
    components at the current heading are ``(ahead, left)``: ``(v, ell omega) = R(delta)^T
    (ahead, left)``, i.e. ``v = cos(delta) ahead + sin(delta) left`` and, with ``r = T / ell``,

        ``g(delta) = delta + r (ahead sin(delta) - left cos(delta)) = 0``.

    With ``k = r |w|``: ``g(-k) <= 0 <= g(k)``, so a root lies in ``[-k, k]``, and ``g' = 1 +
    r (ahead cos(delta) + left sin(delta)) >= 1 - k``: for ``k < 1`` (``|w| T < ell``) the
    root is unique. For ``k >= 1`` several may exist; the conversion takes the one nearest
    the naive turn ``delta_0 = r left``, searched on a grid of :data:`TURN_GRID` cells per
    radian over ``[-k, k]`` (the sign change whose cell is nearest ``delta_0``; two roots
    within one cell, near a tangency, are missed). The root is then polished by Newton's
    method kept inside its bracket (bisection when a Newton step leaves it; the bracket's
    ends are kept by the sign of ``g``, ``g(lo) <= 0 <= g(hi)``), at most
    :data:`TURN_ITERATIONS` times, stopping when no robot's iterate changes any more (a fixed
    point: more iterations would give the same bits, so a robot's turn does not depend on the
    others in the batch).

    :param ahead: the wanted velocity along the heading ``(n,)``.
    :param left: the wanted velocity across it ``(n,)``.
    :param ratio: ``T / ell``.
    :return: the turns ``(n,)`` [rad].
    """
    k = ratio * np.hypot(ahead, left)
    lo, hi = -k, k.copy()
    delta = np.clip(ratio * left, lo, hi)
    for i in np.flatnonzero(k >= 1.0):
        # A robot whose root may not be unique: the sign change nearest the naive turn, on
        # its own grid (cells of at most 1 / TURN_GRID rad).
        grid = k[i] * np.linspace(-1.0, 1.0, int(np.ceil(2.0 * k[i] * TURN_GRID)) + 1)
        g = grid + ratio * (ahead[i] * np.sin(grid) - left[i] * np.cos(grid))
        change = (g[:-1] <= 0.0) != (g[1:] <= 0.0)
        gap = np.maximum(np.maximum(grid[:-1] - delta[i], delta[i] - grid[1:]), 0.0)
        cell = np.argmin(np.where(change, gap, np.inf))
        delta[i] = min(max(delta[i], grid[cell]), grid[cell + 1])
        # The bracket's ends by sign: g(lo) <= 0 <= g(hi), lo above hi where g falls.
        lo[i], hi[i] = (grid[cell], grid[cell + 1]) if g[cell] <= 0.0 else \
            (grid[cell + 1], grid[cell])
    for _ in range(TURN_ITERATIONS):
        sd, cd = np.sin(delta), np.cos(delta)
        g = delta + ratio * (ahead * sd - left * cd)
        slope = 1.0 + ratio * (ahead * cd + left * sd)
        lo = np.where(g <= 0.0, delta, lo)
        hi = np.where(g >= 0.0, delta, hi)
        with np.errstate(divide='ignore', invalid='ignore'):
            newton = delta - g / slope
        inside = (newton > np.minimum(lo, hi)) & (newton < np.maximum(lo, hi))
        nxt = np.where(inside, newton, 0.5 * (lo + hi))
        if np.array_equal(nxt, delta):
            break
        delta = nxt
    return delta


def _shrink(norm: np.ndarray, bound: float) -> np.ndarray:
    """Return the factor bringing vectors of ``norm`` inside ``bound`` (1 when inside)."""
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(norm > bound, bound / norm, 1.0)


def _frame(plant: Plant, frame: str) -> None:
    if frame not in plant.frames:
        raise ScenarioError('plant.frame', f'the {plant.name} plant takes '
                            f'{" or ".join(plant.frames)} frame velocity commands, got {frame!r}')
