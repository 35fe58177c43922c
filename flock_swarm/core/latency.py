"""Latency prediction: a measured plant state carried forward to the moment a command applies.

In realtime an agent acts on a state measured some time ago (odometry's transport, a timer's
phase), and its command reaches the robot later still. The velocity in that state is stale:
a conversion that integrates the law's acceleration from it (``v_sp = p + u T``) closes the
robot's velocity loop on an old value and oscillates (docs/robots.md). Yet the agent knows what
happened since the measurement: it sent the commands the robot executed in the meantime. So it
predicts the state at the moment its next command applies, through the plant's own exact
``step`` (``velocity_lag``: the exact lag; ``unicycle``: arcs):

    x_hat = step(... step(step(x(t_m), c_0, t_1 - t_m), c_1, t_2 - t_1) ..., c_n, t_a - t_n)

where ``c_j`` is the command in force from ``t_j`` (the last one sent before), ``t_m`` the
measurement time and ``t_a`` the time the next command applies. Before the first command known
(and for a neighbour, whose commands an agent does not know), the plant holds its velocity:
it is given the command it executes now (:func:`hold`: ``velocity_lag`` ``v_sp = v``, a
constant velocity; ``unicycle`` its ``v``, ``omega``, an arc; the double integrator ``u = 0``).

``t_a <= t_m`` (lockstep: the state is exact and current) returns the state unchanged, bit for
bit. No ROS: the agent nodes (:mod:`flock_swarm.nodes.controller`) and the robot agent
(:mod:`flock_swarm.nodes.robot_agent`) both use :class:`CommandHistory` and
:func:`extrapolate`.
"""

from typing import Sequence

import numpy as np

from flock_swarm.core.plants.base import Plant

#: The agents' ``latency`` choices: predict the state (the default in realtime), or act on
#: the measured state as it is.
LATENCY_PREDICT, LATENCY_OFF = 'predict', 'off'
LATENCY_CHOICES = (LATENCY_PREDICT, LATENCY_OFF)


def _advance(plant: Plant, x: np.ndarray, spans: np.ndarray, command) -> None:
    """Step the rows of ``x`` in place by ``spans`` (one per row; a row whose span is <= 0
    stays as it is), each group of equal span in one call of ``plant.step``.

    :param command: ``command(sel, h) -> commands`` of the rows ``sel`` held over ``h``.
    """
    for h in np.unique(spans[spans > 0.0]):
        sel = np.flatnonzero(spans == h)
        x[sel] = plant.step(x[sel], command(sel, float(h)), float(h))


def hold(plant: Plant, x: np.ndarray, h: float) -> np.ndarray:
    """Return the commands under which states ``x`` keep their velocities over ``h``: a
    velocity-commanded plant's own twist read back as its command (``from_twist`` of its
    ``odometry``: ``velocity_lag`` ``v_sp = v``, ``unicycle`` ``(v, omega)``, an arc), another
    plant's conversion of a zero acceleration (the double integrator's ``u = 0``)."""
    if 'cmd_vel' not in plant.commands:
        d = plant.law_state(x[:1])[0].shape[1]
        return plant.command(x, np.zeros((len(x), d)), h)
    _, _, linear, angular = plant.odometry(x)
    return plant.from_twist(x, linear, angular, 'body' if 'body' in plant.frames else 'world')


def extrapolate(plant: Plant, x: np.ndarray, ages: np.ndarray | float) -> np.ndarray:
    """Return states ``x`` carried forward by ``ages`` [s] at constant velocity (:func:`hold`,
    through the plant's ``step``); a row whose age is <= 0 is returned as it is.

    :param x: state rows ``(n, S)``.
    :param ages: one age per row, or one for all.
    """
    out = np.array(x, dtype=float)
    spans = np.broadcast_to(np.asarray(ages, dtype=float), (len(out),))
    _advance(plant, out, spans, lambda sel, h: hold(plant, out[sel], h))
    return out


class CommandHistory:
    """The commands a host sent to its robots, each with the time it is in force from.

    :param plant: the robots' plant model.
    :param accelerations: the commands are the law's accelerations, converted by the plant at
        the start of each span (``plant.command(x, u, period)``: what a world that takes
        accelerations does); ``False``: they are the plant's own commands (``cmd_vel``).
    :param period: the conversion's period (``accelerations``).
    :param keep: how many commands are kept (a span before the oldest holds the velocity).
    """

    def __init__(self, plant: Plant, accelerations: bool = False, period: float = 0.0,
                 keep: int = 32) -> None:
        self.plant, self.accelerations, self.period, self.keep = \
            plant, accelerations, period, keep
        self.times: list[float] = []
        self.commands: list[np.ndarray] = []

    def sent(self, t: float, commands: np.ndarray) -> None:
        """Note ``commands`` (one row per robot) in force from time ``t``: they replace any
        noted in force from ``t`` or later (a robot holds the newest command)."""
        while self.times and self.times[-1] >= t:
            self.times.pop()
            self.commands.pop()
        self.times.append(float(t))
        self.commands.append(np.array(commands, dtype=float))
        del self.times[:-self.keep], self.commands[:-self.keep]

    def predict(self, x: np.ndarray, t_measured: np.ndarray | float, t_apply: float,
                rows: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
        """Return the states ``x``, measured at ``t_measured``, predicted to ``t_apply``
        under the commands in force in between (see the module); a row with ``t_apply <=
        t_measured`` is returned as it is, bit for bit.

        :param x: state rows ``(m, S)``.
        :param t_measured: one time per row, or one for all.
        :param t_apply: when the next command applies.
        :param rows: the rows of the noted commands that are ``x``'s (default: all, in order).
        """
        plant = self.plant
        out = np.array(x, dtype=float)
        start = np.broadcast_to(np.asarray(t_measured, dtype=float), (len(out),))
        # The spans: before the first command known (held velocity), then each command's.
        edges = [-np.inf, *self.times, float(t_apply)]
        for j in range(len(edges) - 1):
            spans = min(edges[j + 1], t_apply) - np.maximum(start, edges[j])
            if j == 0:
                _advance(plant, out, spans, lambda sel, h: hold(plant, out[sel], h))
                continue
            sent = self.commands[j - 1]
            if rows is not None:
                sent = sent[np.asarray(rows)]

            def command(sel: np.ndarray, h: float, sent: np.ndarray = sent) -> np.ndarray:
                if self.accelerations:
                    return plant.command(out[sel], sent[sel], self.period)
                return sent[sel]
            _advance(plant, out, spans, command)
        return out
