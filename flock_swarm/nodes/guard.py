"""Input checks of the nodes: a message that must not reach a command is rejected and counted.

Every odometry, leader state and command a node receives passes :meth:`InputGuard.check`
first. It is rejected (counted by reason, the first of each kind per topic logged) when

- its ``header.frame_id`` is not the fixed frame ``world``, or an odometry's
  ``child_frame_id`` is not the one of its topic (``agent_<j>`` on ``agent_<j>/odom``,
  ``leader`` on ``leader/odom``): a message meant for somebody else;
- a value is NaN or infinite, or beyond the absurd-magnitude limits (:class:`Limits`);
- its stamp is not a step of the simulation clock (``t_k = k dt`` exactly), or is older
  than the last accepted stamp on the same topic (stale or out of order). The same stamp
  again is accepted: the world re-offers a stalled lockstep step;
- its bytes are not a message of the topic's type at all (``malformed``, counted by the
  node that decodes them, see :mod:`flock_swarm.nodes.wire`).

Reasons (the keys of :meth:`InputGuard.counts`): ``frame``, ``non_finite``, ``magnitude``,
``off_grid_stamp``, ``stale_stamp``, ``malformed``; the world adds ``late`` (a command for a
step it has already closed) and ``future`` (for a step it has not opened).
"""

import math
from collections import Counter
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from flock_swarm.contract import FRAME
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.parameters import Param


@dataclass(frozen=True)
class Limits:
    """Largest plausible magnitudes; anything beyond is a fault, not a state.

    :ivar position: largest ``|q|`` component [m].
    :ivar velocity: largest ``|p|`` component [m/s].
    :ivar accel: largest ``|u|`` or ``|f_gamma|`` component [m/s^2].
    """

    position: float = 1e6
    velocity: float = 1e4
    accel: float = 1e6

    @classmethod
    def from_parameters(cls, values: dict) -> 'Limits':
        """Return the limits of the ``max_abs_*`` parameters (:data:`LIMIT_PARAMS`) read."""
        return cls(**{field: float(values[f'max_abs_{field}']) for field in
                      ('position', 'velocity', 'accel')})


def _limit(field: str, unit: str) -> Param:
    """Return the ``max_abs_<field>`` parameter, defaulting to :class:`Limits`'s value."""
    return Param(f'max_abs_{field}', getattr(Limits, field),
                 f'inputs with a component beyond this [{unit}] are rejected',
                 lambda v: math.isfinite(v) and v > 0,
                 'must be a finite number > 0, got {value!r}')


#: The input limits' parameters (the world's and the agents').
LIMIT_PARAMS = (_limit('position', 'm'), _limit('velocity', 'm/s'), _limit('accel', 'm/s^2'))


class InputGuard:
    """Checks received messages; counts and logs what it rejects.

    :ivar rejected: rejections by reason.
    """

    def __init__(self, clock: StepClock, limits: Limits, warn: Callable[[str], None]) -> None:
        """Create the guard.

        :param clock: the simulation clock (stamps must be its steps).
        :param limits: the magnitude limits.
        :param warn: logs one line (the first rejection of each reason on each topic).
        """
        self.clock = clock
        self.limits = limits
        self.warn = warn
        self.rejected: Counter = Counter()
        self.latest: dict[str, int] = {}
        self._told: set[tuple[str, str]] = set()

    def check(self, topic: str, stamp_ns: int, frame_id: str,
              values: Iterable[tuple[Iterable[float], float]],
              child: tuple[str, str] | None = None,
              window: tuple[int, int] | None = None, ordered: bool = True) -> int | None:
        """Return the step of an acceptable message, or ``None`` (rejected and counted).

        :param topic: the topic it came on.
        :param stamp_ns: its ``header.stamp`` [ns].
        :param frame_id: its ``header.frame_id``.
        :param values: ``(components, limit)`` pairs to check for finiteness and magnitude.
        :param child: ``(child_frame_id, expected)`` for odometry.
        :param window: ``(first, last)`` steps acceptable now (the world's lockstep: the
            step just closed and the open one); outside it the message is ``late`` or
            ``future``, and does not move the topic's latest stamp.
        :param ordered: reject a stamp older than the topic's latest accepted one. A
            lockstep agent passes ``False`` and judges staleness by the steps it has
            answered instead: one forged far-future stamp must not make it reject the
            genuine messages that follow.
        """
        fault = None
        if frame_id != FRAME:
            fault = ('frame', f'frame_id {frame_id!r}, not {FRAME!r}')
        elif child is not None and child[0] != child[1]:
            fault = ('frame', f'child_frame_id {child[0]!r}, not {child[1]!r}')
        else:
            for components, limit in values:
                for x in components:
                    # One comparison per value on the hot path: NaN and inf fail it too.
                    if not -limit <= x <= limit:
                        fault = ('magnitude', f'a value beyond {limit:g}') if math.isfinite(x) \
                            else ('non_finite', 'a NaN or infinite value')
                        break
                if fault is not None:
                    break
        k = self.clock.step_at(stamp_ns)
        if fault is None and stamp_ns != self.clock.ns(k):
            fault = ('off_grid_stamp',
                     f'stamp {stamp_ns} ns is not a step of dt = {self.clock.dt:g} s')
        if fault is None and window is not None and not window[0] <= k <= window[1]:
            fault = ('late', f'stamp of step {k} before step {window[0]}') if k < window[0] \
                else ('future', f'stamp of step {k} after step {window[1]}')
        if fault is None and ordered and k < self.latest.get(topic, -1):
            fault = ('stale_stamp', f'stamp of step {k} after step {self.latest[topic]}')
        if fault is not None:
            self.reject(topic, *fault)
            return None
        self.latest[topic] = k
        return k

    def pass_batch(self, topics: Iterable[str], stamp_ns: int,
                   values: Iterable[tuple[np.ndarray, float]]) -> int | None:
        """Return the step of messages that :meth:`check` would each accept (unordered, no
        window), or ``None`` when one of them might not: the caller then checks them one by
        one, which counts and logs. Nothing is counted here.

        :param topics: the topics they came on (each one's latest stamp becomes this one).
        :param stamp_ns: their common stamp [ns].
        :param values: ``(array, limit)`` pairs, every component of the array checked (NaN
            and inf fail the comparison, as in :meth:`check`). The frame ids are the
            caller's to have matched.
        """
        for array, limit in values:
            if not (np.abs(array) <= limit).all():
                return None
        k = self.clock.step_at(stamp_ns)
        if stamp_ns != self.clock.ns(k):
            return None
        self.latest.update(dict.fromkeys(topics, k))
        return k

    def reject(self, topic: str, kind: str, detail: str) -> None:
        """Count a rejection of ``kind`` on ``topic``; log the first of each kind per topic."""
        self.rejected[kind] += 1
        if (topic, kind) not in self._told:
            self._told.add((topic, kind))
            self.warn(f'rejected a message on {topic}: {detail} (further ones are counted)')

    def counts(self) -> dict[str, int]:
        """Return the rejections by reason (for the summary)."""
        return dict(sorted(self.rejected.items()))
