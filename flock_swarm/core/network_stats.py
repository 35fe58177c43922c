"""The network's statistics: what a run's links delivered and how old the states used were.

:class:`Tally` folds the counts of :class:`~flock_swarm.core.network.NetworkState` (``sim``
and the world) over the recorded steps; :class:`ReportedUse` does the same in realtime mode
from what each agent reports with its command (:data:`USAGE_LABELS`).
"""

import numpy as np

#: The recorded statistics (time series, ``summary.json``, ``/swarm/metrics``).
STATISTICS = ('network_delivered', 'network_age_mean', 'network_age_max')
#: What an agent reports with each command in realtime mode (:meth:`NetworkState.usage`).
USAGE_LABELS = ('delivered', 'sent', 'age_sum', 'links', 'age_max')


class Tally:
    """A network statistic folded over steps: ``[delivered, sent, age sum, ages, age max]``
    (messages not lost, messages sent, the ages [steps] of the neighbour states used summed,
    their number, the largest or -1)."""

    def __init__(self) -> None:
        """Create an empty tally."""
        self.values = [0, 0, 0, 0, -1]

    def add(self, counts: list) -> None:
        """Fold one step's counts in."""
        v = self.values
        for c in range(4):
            v[c] += counts[c]
        v[4] = max(v[4], counts[4])

    def take(self, dt: float) -> dict:
        """Return ``network_delivered``, ``network_age_mean``, ``network_age_max`` [s] of the
        steps folded in (NaN where nothing was), and start anew."""
        out = _statistics(self.values, dt)
        self.values = [0, 0, 0, 0, -1]
        return out


class ReportedUse:
    """Realtime mode: the age of the information the agents' applied commands used.

    Each agent reports with its command (stamped with the step ``k_i`` of the odometry it
    answers) what it used (:meth:`NetworkState.usage`: the modelled ages). The world applies
    a held command at its step ``K >= k_i``: each neighbour state the command used is then
    ``K - k_i`` steps older still (the real transport, the agents' timers, the hold). The
    deliveries of a report count once, at the first step its command is applied.
    """

    def __init__(self, n: int, keep: int = 100) -> None:
        """Create the bookkeeping of ``n`` agents, keeping ``keep`` steps of reports."""
        self.reports: list[dict[int, np.ndarray]] = [{} for _ in range(n)]
        self.counted = np.full(n, -1, dtype=np.int64)
        self.keep = keep

    def report(self, i: int, k: int, values) -> None:
        """Take agent ``i``'s report (:data:`USAGE_LABELS`) of its command of step ``k``."""
        held = self.reports[i]
        held[k] = np.asarray(values, dtype=float)
        for old in [s for s in held if s < k - self.keep]:
            del held[old]

    def step(self, k: int, applied: np.ndarray) -> list:
        """Return the step's counts (:class:`Tally`'s order) of the commands applied at ``k``.

        :param k: the world's step.
        :param applied: per agent, the step its applied command answers (-1: none applied,
            a zero command).
        """
        counts = [0, 0, 0, 0, -1]
        for i in np.flatnonzero(applied >= 0).tolist():
            answered = int(applied[i])
            row = self.reports[i].get(answered)
            if row is None:
                continue
            got, sent, age_sum, links, age_max = (int(round(x)) for x in row)
            extra = k - answered
            counts[2] += age_sum + links * extra
            counts[3] += links
            if links:
                counts[4] = max(counts[4], age_max + extra)
            if self.counted[i] != answered:
                self.counted[i] = answered
                counts[0] += got
                counts[1] += sent
        return counts


def _statistics(tally: list[int], dt: float) -> dict:
    """Return the recorded statistics of ``[delivered, sent, age sum, ages, age max]``."""
    got, total, age_sum, count, age_max = tally
    return {'network_delivered': got / total if total else np.nan,
            'network_age_mean': age_sum / count * dt if count else np.nan,
            'network_age_max': age_max * dt if count else np.nan}
