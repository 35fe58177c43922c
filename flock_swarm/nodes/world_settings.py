"""The world's settings and timing rules: its parameters, the resend policy of a stalled
lockstep step, and the realtime command latencies (ROS-free: the stepper's and the node's).
"""

import bisect
import math
from dataclasses import dataclass
from typing import Any, Callable

from flock_swarm.core.plants.base import COMMANDS
from flock_swarm.engine.backends import BACKENDS
from flock_swarm.nodes.parameters import Param

#: Seconds after which a stalled lockstep step is first offered again (see ``resent``).
RESEND_PERIOD = 0.5
#: A step is stalled only once it has taken this many times as long as the step before it,
#: and each further offer of the same step waits twice as long as the last.
RESEND_SLOWER = 3.0
#: Realtime: steps the leader's buffered states are kept for.
LEADER_KEEP = 10
#: Realtime: steps the publication time of odometry is kept for (command latencies).
PUBLISHED_KEEP = 100


def first_resend_wait(last_step_s: float, step_timeout: float = float('inf')) -> float:
    """Seconds before a step is first offered again, given the previous step's duration.

    At most half the step timeout, so that every step is offered at least twice before a
    missing command is zeroed: with a step timeout below ``RESEND_PERIOD`` a sample DDS
    dropped (a reader not matched yet, a participant that joined or died) was never offered
    again, and the agent lost the step.
    """
    return min(max(RESEND_PERIOD, RESEND_SLOWER * last_step_s), step_timeout / 2)


def next_resend_wait(wait: float, last_step_s: float) -> float:
    """Seconds before the next offer of a step offered again after ``wait``.

    Doubling once a step's duration is known (an overloaded swarm); before the first step
    has finished (``last_step_s`` 0) a lost sample means a reader not yet matched, and the
    step is offered every ``wait`` as long as it stalls.
    """
    return 2.0 * wait if last_step_s > 0 else wait


class LatencyHistogram:
    """Latencies in constant memory: 100 log-spaced bins per decade from 1 us to 100 s.

    Percentiles are read off the bins (their upper edges: at most 2.3 % high), so a soak of
    any length costs the same few kilobytes.
    """

    EDGES = [10.0 ** (-6 + k / 100.0) for k in range(801)]

    def __init__(self) -> None:
        """Create an empty histogram."""
        self.counts = [0] * (len(self.EDGES) + 1)
        self.count = 0
        self.max = 0.0

    def add(self, seconds: float) -> None:
        """Add one latency [s]."""
        self.counts[bisect.bisect_left(self.EDGES, seconds)] += 1
        self.count += 1
        self.max = max(self.max, seconds)

    def summary_ms(self) -> dict:
        """Return ``count``, ``p50``, ``p90``, ``p99`` and ``max`` in milliseconds."""
        out = {'count': self.count}
        for name, q in (('p50', 0.5), ('p90', 0.9), ('p99', 0.99)):
            target, seen, value = q * self.count, 0, None
            for k, c in enumerate(self.counts):
                seen += c
                if c and seen >= target:
                    value = self.EDGES[min(k, len(self.EDGES) - 1)]
                    break
            out[name] = None if value is None else round(1e3 * min(value, self.max), 3)
        out['max'] = round(1e3 * self.max, 3) if self.count else None
        return out


@dataclass(frozen=True)
class WorldSettings:
    """The world's own parameters (see ``docs/ros.md``).

    :ivar lockstep: lockstep (``True``) or realtime mode.
    :ivar step_timeout: lockstep: seconds before a missing command is zeroed.
    :ivar start_timeout: lockstep: seconds to wait for everybody before starting anyway.
    :ivar staleness: realtime: seconds a held command or the leader state stays valid.
    :ivar marker_every: markers every this many steps.
    :ivar metrics_every: metrics every this many steps.
    :ivar max_missed_steps: lockstep: an agent that answered before and then misses this
        many steps in a row ends the run as ``failed`` (0: never, it is zeroed to the end).
    :ivar peer_timeout: seconds an agent's host or the leader may be gone from the ROS graph
        (it answered before) before the run ends as ``failed`` (0: never).
    :ivar command: the command interface the world applies: ``''`` (the scenario's
        ``plant.command``), ``accel`` or ``cmd_vel``.
    :ivar backend: what integrates the agents: ``plant`` (the plant model, as ``sim``) or
        ``mujoco`` (the physics engine, :mod:`flock_swarm.engine.backend`).
    """

    lockstep: bool = True
    step_timeout: float = 2.0
    start_timeout: float = 30.0
    staleness: float = 0.5
    marker_every: int = 10
    metrics_every: int = 10
    max_missed_steps: int = 3
    peer_timeout: float = 6.0
    command: str = ''
    backend: str = 'plant'

    @classmethod
    def from_parameters(cls, values: dict, lockstep: bool) -> 'WorldSettings':
        """Return the settings of the parameters of :data:`SETTING_PARAMS` read.

        :param values: ``{name: value}``, every setting included.
        :param lockstep: the mode.
        """
        return cls(lockstep, **{param.name: values[param.name] for param in SETTING_PARAMS})


def _setting(name: str, description: str, check: Callable[[Any], bool]) -> Param:
    """Return the parameter of a setting, defaulting to :class:`WorldSettings`'s value."""
    return Param(name, getattr(WorldSettings, name), description, check)


#: The world's settings as parameters: description and the check each value must pass.
SETTING_PARAMS = (
    # Finite, as swarm's --step-timeout and --start-timeout: with .inf a missing agent would
    # hold the world forever.
    _setting('step_timeout', 'lockstep: seconds to wait for commands before a missing agent '
             'gets a zero command', lambda v: 0 < v < math.inf),
    _setting('start_timeout', 'lockstep: seconds to wait for agents and leader to appear and '
             'answer step 0 before starting anyway', lambda v: 0 <= v < math.inf),
    _setting('marker_every', 'publish markers every N steps', lambda v: v >= 1),
    _setting('metrics_every', 'publish metrics every N steps', lambda v: v >= 1),
    _setting('staleness', 'realtime: seconds a held command (or the leader state) stays valid; '
             'an older command counts as missing (zero), an older leader state as lost',
             lambda v: v > 0),
    _setting('max_missed_steps', 'lockstep: an agent that answered before and then misses '
             'this many steps in a row (each after step_timeout) ends the run as failed; 0: '
             'never (it gets zero commands to the end)', lambda v: v >= 0),
    _setting('peer_timeout', 'seconds an agent\'s node or the leader may be gone from the ROS '
             'graph (it had answered before) before the run ends as failed; 0: never',
             lambda v: 0 <= v < float('inf')),
    _setting('command', "the agents' command interface the world applies: '' (the scenario's "
             'plant.command), accel (cmd_accel) or cmd_vel (Twist on cmd_vel)',
             lambda v: v in ('', *COMMANDS)),
    _setting('backend', "what integrates the agents: 'plant' (the scenario's plant model, "
             "as sim) or 'mujoco' (the physics engine: differential-drive robots that touch, "
             'plant.model unicycle; docs/robots.md)', lambda v: v in BACKENDS),
)
