"""Verdicts that carry their uncertainty: confidence intervals and the three-word rule.

A claim of a paper becomes a statistic over seeds with a band of values that support it
(:class:`~flock_swarm.reproduce.experiment.MeanClaim`,
:class:`~flock_swarm.reproduce.experiment.FractionClaim`). The statistic's 95 % confidence
interval then decides: **reproduced** when the interval lies inside the band, **not
reproduced** when it lies outside it, **inconclusive** when it straddles an edge. More seeds
narrow the interval, so an inconclusive verdict says how much the data can tell, not that the
experiment failed.
"""

import math

import numpy as np
from scipy import stats as sps

#: Confidence level of every interval of the report.
LEVEL = 0.95

REPRODUCED = 'reproduced'
NOT_REPRODUCED = 'not reproduced'
INCONCLUSIVE = 'inconclusive'
#: No records to judge (a cache not filled yet); not a verdict.
NOT_RUN = 'not run yet'


def wilson(met: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Return the Wilson score interval of a fraction ``met / n``.

    E. B. Wilson 1927: the interval of the success probability ``p`` whose score test does not
    reject at ``level``; unlike ``p ± z sqrt(p (1 - p) / n)`` it stays inside [0, 1] and does
    not collapse to a point at 0 or n successes.

    :param met: successes.
    :param n: trials (``0``: the whole of [0, 1]).
    :param level: confidence level.
    :return: ``(low, high)``.
    """
    if n == 0:
        return 0.0, 1.0
    z = float(sps.norm.ppf(0.5 + level / 2.0))
    p = met / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # At 0 or n successes the closed form rounds to within an ulp of the end it must equal.
    low = 0.0 if met == 0 else max(0.0, centre - half)
    high = 1.0 if met == n else min(1.0, centre + half)
    return low, high


def t_interval(mean: float, std: float, n: int, level: float = LEVEL
               ) -> tuple[float, float] | None:
    """Return Student's t interval of a mean from its sample statistics.

    :param mean: the sample mean.
    :param std: the sample standard deviation (``ddof = 1``).
    :param n: the sample size (below 2: no interval, ``None``).
    :param level: confidence level.
    :return: ``(low, high)`` or ``None``.
    """
    if n < 2:
        return None
    half = float(sps.t.ppf(0.5 + level / 2.0, n - 1)) * std / math.sqrt(n)
    return mean - half, mean + half


def mean_interval(values: list[float], level: float = LEVEL
                  ) -> tuple[float, tuple[float, float] | None]:
    """Return the mean of ``values`` and its t interval (``None`` below two values)."""
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        return math.nan, None
    std = float(arr.std(ddof=1)) if arr.size > 1 else 0.0
    return float(arr.mean()), t_interval(float(arr.mean()), std, int(arr.size), level)


def decide(interval: tuple[float, float] | None, band: tuple[float, float]) -> str:
    """Return the verdict of a confidence interval against the band of values that support
    the claim.

    :param interval: the statistic's interval (``None``: too few values to have one).
    :param band: ``(low, high)``; an end may be infinite.
    :return: :data:`REPRODUCED` when the interval lies inside the band,
        :data:`NOT_REPRODUCED` when it lies outside it, else :data:`INCONCLUSIVE`.
    """
    if interval is None:
        return INCONCLUSIVE
    low, high = interval
    if band[0] <= low and high <= band[1]:
        return REPRODUCED
    if high < band[0] or low > band[1]:
        return NOT_REPRODUCED
    return INCONCLUSIVE


def combine(verdicts: list[str]) -> str:
    """Return the verdict of a claim made of several parts that must all hold (the anchors of
    a figure): reproduced when every part is, not reproduced when one is not, else
    inconclusive (:data:`NOT_RUN` when no part has data yet)."""
    if all(v == NOT_RUN for v in verdicts):
        return NOT_RUN
    if NOT_REPRODUCED in verdicts:
        return NOT_REPRODUCED
    if all(v == REPRODUCED for v in verdicts):
        return REPRODUCED
    return INCONCLUSIVE
