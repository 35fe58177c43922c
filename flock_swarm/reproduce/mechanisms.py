"""The mechanisms the studies beyond the papers measure, each beside its prediction.

- **A plant's delivered fraction** (:func:`delivered_fraction`): how much of the law's
  velocity change ``u T`` one command period actually delivers. The law assumes a double
  integrator, for which ``p(t + T) = p + u T`` exactly; a robot plant executes a command
  converted from ``u``, and a conversion that delivers only a fraction ``f`` of ``u T`` flies
  the same law with every gain multiplied by about ``f``. Measured by replaying a run's own
  recorded states through the plant's exact one-step response; predicted, for the velocity
  lag, by :func:`lag_fraction`: ``1 - exp(-T / tau)`` for the naive conversion (the setpoint
  ``p + u T`` handed over as it is, 0.181 at ``T = 0.02 s``, ``tau = 0.1 s``) and
  ``(1 - exp(-T / tau)) / (1 - exp(-T / tau_c))`` for the exact one that assumes the lag
  ``tau_c`` (1 when it is right).

The drag of a communication delay on a moving flock is :mod:`flock_swarm.core.delay_drag`'s.
"""

import math

import numpy as np

from flock_swarm.core.plants.base import Plant


def lag_fraction(tau: float, period: float, conversion: str = 'exact',
                 conversion_tau: float | None = None) -> float:
    """Return the predicted delivered fraction of a velocity-lag plant (see the module).

    :param tau: the plant's time constant [s].
    :param period: the command period ``T`` [s].
    :param conversion: ``exact`` or ``naive``.
    :param conversion_tau: the lag the exact conversion assumes (``None``: ``tau``).
    """
    reached = -math.expm1(-period / tau)
    if conversion == 'naive':
        return reached
    assumed = tau if conversion_tau is None else conversion_tau
    return reached / -math.expm1(-period / assumed)


def delivered_fraction(plant: Plant, x: np.ndarray, u: np.ndarray,
                       period: float) -> tuple[float, float]:
    """Return the fraction of the law's velocity change that one period delivers, and the
    part of the delivered change that is not along it, both over all rows.

    The state ``x`` (rows of agents, as many instants as wanted stacked) is stepped exactly
    under the command the plant's conversion makes of ``u``; with ``dv`` the change of the
    velocity the law sees and ``w = u T`` the law's,
    ``f = sum dv . w / sum |w|^2`` and ``residual = sqrt(sum |dv - f w|^2 / sum |w|^2)``
    (0 when every change is along the law's, as for the velocity lag unsaturated).

    :param plant: the plant model (its conversion included).
    :param x: plant states ``(n, S)``.
    :param u: the law's accelerations ``(n, dim)``.
    :param period: the command period ``T`` [s] (the step, in lockstep and ``sim``).
    :return: ``(f, residual)``; ``(nan, nan)`` when every ``u`` is zero.
    """
    _, before = plant.law_state(x)
    _, after = plant.law_state(plant.step(x, plant.command(x, u, period), period))
    dv, w = after - before, u * period
    norm = float(np.sum(w * w))
    if norm == 0.0:
        return math.nan, math.nan
    f = float(np.sum(dv * w)) / norm
    return f, math.sqrt(float(np.sum((dv - f * w) ** 2)) / norm)


def run_delivered_fraction(plant: Plant, series: dict, dt: float) -> tuple[float, float]:
    """Return :func:`delivered_fraction` over every recorded instant of a run: its plant
    states (``plant_state``) and the law's accelerations at them (``u``).

    :param plant: the run's plant model.
    :param series: the run's time series (``plant_state`` K x N x S, ``u`` K x N x dim).
    :param dt: the run's step (its command period).
    """
    x, u = series['plant_state'], series['u']
    return delivered_fraction(plant, x.reshape(-1, x.shape[-1]), u.reshape(-1, u.shape[-1]),
                              dt)


#: The drag's measurement: a patch of Su 2009 Fig. 2's alpha-lattice (a hexagon of the
#: triangular lattice at the preset's d), every agent uninformed, moving at 1 m/s along x.
DRAG_AGENTS, DRAG_SPEED = 37, 1.0


def delay_drag(delay: float, compensation: str = 'none') -> dict:
    """Return the drag of a communication delay on a translating flock, measured by a
    ``sim`` run of Fig. 2's law beside the first-order prediction
    (:func:`flock_swarm.core.delay_drag.predict_drag`).

    The run: :data:`DRAG_AGENTS` agents on the lattice patch at :data:`DRAG_SPEED` m/s, no
    informed agent, ``network: {delay, compensation}``; the braking rate of the first step
    that uses the delayed messages is ``(v_bar[d] - v_bar[d + 1]) / (dt v_bar[d])``.

    :param delay: the delay [s] (a whole number of Fig. 2's steps).
    :param compensation: ``none`` or ``predict``.
    :return: ``{'measured': rate [1/s], 'predicted': beta_0 [1/s]}`` (the prediction is that
        of no compensation; with ``predict`` the drag's cause is removed, so 0 is its
        prediction).
    """
    from flock_swarm.core import delay_drag as dd
    from flock_swarm.core.run import simulate
    from flock_swarm.presets import prepare
    fig2, _ = prepare('su2009_fig2')
    q = dd.triangular_lattice(DRAG_AGENTS, fig2.law.d)
    steps = round(delay / fig2.dt)
    sc, _ = prepare('su2009_fig2', extra={
        'n_agents': DRAG_AGENTS, 'duration': (steps + 2) * fig2.dt, 'record_every': 1,
        'informed': {'select': 'first', 'count': 0},
        'initial': {'positions': q.tolist(), 'velocities': [[DRAG_SPEED, 0.0]] * DRAG_AGENTS},
        'network': {'delay': delay, 'compensation': compensation}})
    v = simulate(sc).series['p'].mean(axis=1)[:, 0]
    predicted = dd.predict_drag(fig2.law, q, [DRAG_SPEED, 0.0], delay).rate
    return {'measured': float((v[steps] - v[steps + 1]) / fig2.dt / v[steps]),
            'predicted': 0.0 if compensation == 'predict' else float(predicted)}


def held_age(loss: float) -> float:
    """Return the mean age [steps] of the neighbour states used under Bernoulli loss ``loss``
    with a message every step and a state kept through one lost refresh (``max_age`` 1).

    Of a link present at two steps in a row, the current message is used with probability
    ``1 - p`` (age 0), the previous one with ``p (1 - p)`` (age 1), none with ``p^2``: the
    mean age of the states used is ``p (1 - p) / ((1 - p) + p (1 - p)) = p / (1 + p)``.

    :param loss: the loss probability ``p`` in ``[0, 1)``.
    """
    return loss / (1.0 + loss)
