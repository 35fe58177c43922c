"""The world's stepping without ROS: commands in, the step closed, the swarm integrated.

:class:`WorldStepper` owns what the world node decides: the open step and the commands
received for it, the step timeout and the agents that missed it (zero command), the
leader's buffered states and its loss (:class:`~flock_swarm.nodes.leader_watch.LeaderWatch`),
the resend policy of a stalled step, the agents' adaptive state of each step (a law's
``h_i``, recorded as ``sim`` records it), the integration (the same
:func:`~flock_swarm.core.dynamics.step_agents` as ``sim``), the faults that end the run (a
peer that stopped answering or left the ROS graph, a fault a node reported), the run log
and the summary. The
node turns messages into its calls and its :class:`Observation` into messages; every time is
passed in (seconds of a monotonic clock), so the stepper runs as well from a unit test. In
lockstep, a step's commands are queued as bytes and handed over at once (:class:`CommandInbox`).
"""

import bisect
import json
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from flock_swarm.contract import state_labels, state_slices
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.graphs import EdgeList, disk_graph
from flock_swarm.core.headline import progress_text
from flock_swarm.core.metrics import step_metrics
from flock_swarm.core.network import ReportedUse, Tally
from flock_swarm.core.plants.base import COMMANDS
from flock_swarm.core.plants.spec import command_interface
from flock_swarm.core.run import (LinkObserver, Recorder, RunLog, SimResult, build_summary,
                                  observed_pairs, static_graph)
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.core.faults import agents_text
from flock_swarm.engine.backends import BACKENDS, make_backend
from flock_swarm.nodes.guard import InputGuard
from flock_swarm.nodes.inbox import StepInbox
from flock_swarm.nodes.leader_watch import LeaderWatch, Log
from flock_swarm.nodes.parameters import Param
from flock_swarm.nodes.wire import AccelBatch

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


@dataclass
class Observation:
    """A step as the world saw it: what to publish about it.

    :ivar k: the step.
    :ivar q: positions at step ``k``.
    :ivar p: velocities.
    :ivar u: the commands applied.
    :ivar leader: the leader state used.
    :ivar edges: the r-disk graph at ``q``.
    :ivar missing: agents whose command was missing (zero applied).
    :ivar markers: whether markers are due.
    :ivar metrics: the ``/swarm/metrics`` values when they are due, else ``None``.
    :ivar problems: what made the step a warning (empty: ok).
    :ivar last: whether it is the scenario's last step.
    """

    k: int
    q: np.ndarray
    p: np.ndarray
    u: np.ndarray
    leader: LeaderState
    edges: EdgeList
    missing: list[int]
    markers: bool
    metrics: dict | None
    problems: list[str]
    last: bool


class WorldStepper:
    """The world's decisions, step by step, without ROS.

    :ivar k: the open step.
    :ivar started: whether the first step was opened.
    :ivar done: whether the run has ended (``status`` says how).
    """

    def __init__(self, sc: Scenario, settings: WorldSettings, log: Log,
                 now: float | None = None, recorder: Recorder | None = None) -> None:
        """Create the stepper at the scenario's initial state.

        :param sc: the scenario.
        :param settings: the world's parameters.
        :param log: where missing commands and the leader's loss are told.
        :param now: the time of creation (start timeout counts from it); default: now.
        :param recorder: where the run log records the time series (default: in memory;
            the node streams it to disk).
        """
        self.scenario, self.settings, self.log = sc, settings, log
        self.lockstep = settings.lockstep
        self.real = realize(sc)
        self.static = static_graph(sc, self.real)
        #: What integrates the agents (:mod:`flock_swarm.engine.backends`: the double
        #: integrator, the plant model or the physics engine, by the ``backend`` setting).
        self.world = make_backend(settings.backend, sc, self.real)
        self.contacts_told: set[tuple[int, int]] = set()
        #: Whether the world applies the agents' velocity commands (``cmd_vel``).
        self.velocity = command_interface(sc, settings.command) == 'cmd_vel'
        # The open step's velocity commands by agent, (linear, angular) rows of 3 (lockstep);
        # realtime: the latest of every agent (zero: stop, before the first).
        self.twists: dict[int, np.ndarray] = {}
        self.held_twist = np.zeros((sc.n_agents, 6))
        # Realtime: when each agent's held Twist came, and the robots stopped this step (their
        # Twist older than the staleness: a zero Twist applied instead).
        self.held_twist_at = np.full(sc.n_agents, -np.inf)
        self.stopped = np.zeros(sc.n_agents, dtype=bool)
        n = sc.n_agents
        self.k = 0
        self.commands: dict[int, np.ndarray] = {}
        # The open step's commands as one array, while they came at once (commands_all).
        self.command_rows: np.ndarray | None = None
        self.held = np.zeros((n, sc.dim))
        self.held_at = np.full(n, -np.inf)
        self.stale_agents: set[int] = set()
        self.leader_odom: dict[int, tuple] = {}
        self.leader_accel: dict[int, np.ndarray] = {}
        self.last_leader = LeaderState(sc.leader.position.copy(), sc.leader.velocity.copy(),
                                       np.zeros(sc.dim))
        self.leader = LeaderWatch()
        # The agents' adaptive state (empty for a law without): the value of every agent at
        # the open step, an agent's last one held until its next comes (its initial value
        # before), and the agents whose state of the open lockstep step is in.
        self.state = {key: value.copy() for key, value in self.real.agents.state.items()}
        shapes = {key: value.shape[1:] for key, value in self.state.items()}
        self.state_labels = state_labels(shapes)
        self.state_layout = state_slices(shapes)
        self.state_in: set[int] = set()
        self.missed = np.zeros(n, dtype=int)
        # Agents that have sent a command, and the steps each has missed since its last.
        self.heard = np.zeros(n, dtype=bool)
        self.silent_steps = np.zeros(n, dtype=int)
        # Since when an agent's node (by agent) or the leader has been gone from the graph.
        self.gone_since: dict[int | str, float] = {}
        #: Non-finite commands of the law, per agent, as the agent nodes reported them.
        self.non_finite = np.zeros(n, dtype=int)
        self.non_finite_at: dict[int, list[int]] = {}
        #: The line telling why the run failed (status ``failed``), or ``None``.
        self.failure: str | None = None
        self.leader_missed = 0
        self.last_missing: set[int] = set()
        # Realtime: wall time each step's odometry went out, and how long commands took.
        self.published_at: dict[int, float] = {}
        self.latency = LatencyHistogram()
        self.run_log = RunLog.for_scenario(sc, recorder)
        # The messages between the agents (``network:``), lockstep: kept as the agents keep
        # them, to record the statistics sim records (the agents' links only: no leader
        # messages, nobody informed). Realtime: the agents report what each command used,
        # the world adds the age the command had when applied (docs/network.md).
        self.net = LinkObserver(sc, self.real, self.static) \
            if sc.network.active and self.lockstep else None
        self.used = ReportedUse(n, PUBLISHED_KEEP) \
            if sc.network.active and not self.lockstep else None
        #: Realtime: the step each agent's held command answers (-1: none yet).
        self.held_step = np.full(n, -1, dtype=np.int64)
        # The statistics since the last recorded instant, and since the last /swarm/metrics.
        self.net_record, self.net_metrics = Tally(), Tally()
        self.metrics_now: dict = {}
        self.done = False
        self.started = False
        self.status = 'running'
        self.deadline = 0.0
        self.resend_at = 0.0
        self.resend_wait = RESEND_PERIOD
        self.resends = 0
        self.step_began = 0.0
        self.last_step_s = 0.0
        self.t_created = self.t_wall0 = time.monotonic() if now is None else now
        self.t_last_progress = self.t_wall0

    # The backend's state read-out (:attr:`world`).
    q = property(lambda self: self.world.q, doc='Positions (what the law sees).')
    p = property(lambda self: self.world.p, doc='Velocities (what the law sees).')
    x = property(lambda self: self.world.x, doc="The plant's state rows (None: the double "
                 'integrator).')
    plant = property(lambda self: self.world.plant, doc='The plant model (None: the double '
                     "integrator's exact path).")

    # -- inputs -------------------------------------------------------------------------------

    def window(self) -> tuple[int, int] | None:
        """Return the steps whose inputs are accepted now (lockstep: the open step and the
        one just closed; realtime: any)."""
        return (self.k - 1, self.k) if self.lockstep else None

    def command(self, i: int, k: int, u: np.ndarray, now: float) -> bool:
        """Take agent ``i``'s (checked) command for step ``k``; return whether it is late.

        Lockstep: a command for the open step is kept for it; one for the step just closed
        that went without it came too late (a repeated command for that step, after the
        world offered it again, is no fault). Realtime: the command is held until the next.
        """
        self.heard[i] = True
        if not self.lockstep:
            self.held[i] = u
            self.held_at[i] = now
            self.held_step[i] = k
            sent = self.published_at.get(k)
            if sent is not None:
                self.latency.add(now - sent)
            return False
        if not self.started or self.done:
            return False
        if k == self.k:
            self.commands[i] = u
            self.command_rows = None
            return False
        return i in self.last_missing

    def commands_all(self, k: int, u: np.ndarray) -> None:
        """Lockstep: take every agent's (checked) command for the open step ``k`` at once
        (``u``: shape ``(N, dim)``), as :meth:`command` would one by one."""
        if self.started and not self.done and k == self.k:
            self.commands = dict(enumerate(u))
            self.command_rows = u
            self.heard[:] = True

    def twist(self, i: int, linear: Sequence[float], angular: Sequence[float],
              now: float) -> None:
        """Take agent ``i``'s (checked) velocity command, arrived at ``now``.

        ``Twist`` carries no stamp: in lockstep it answers the open step (an agent sends one
        per step, after the step's odometry, and never again for a step offered again);
        in realtime it is held until the next, for at most the staleness.
        """
        row = np.concatenate([linear, angular]).astype(float)
        if not self.lockstep:
            self.held_twist[i] = row
            self.held_twist_at[i] = now
        elif self.started and not self.done:
            self.twists[i] = row

    def agent_state(self, i: int, k: int, values: Sequence[float]) -> None:
        """Take agent ``i``'s (checked) adaptive state of step ``k``: the values of
        :attr:`state_labels`, in order.

        Lockstep: the state of the open step counts (it completes the step with the
        commands); one of the step just closed is a repeat, or came after the step was
        closed without it (its last state was recorded). Realtime: it is held until the next.
        """
        if self.lockstep:
            if not self.started or self.done or k != self.k:
                return
            self.state_in.add(i)
        row = np.asarray(values, dtype=float)
        for key, shape, part in self.state_layout:
            self.state[key][i] = row[part].reshape(shape)

    def network_report(self, i: int, k: int, values: Sequence[float]) -> None:
        """Realtime: take agent ``i``'s (checked) report of what its command of step ``k``
        used (:data:`~flock_swarm.core.network.USAGE_LABELS`)."""
        if self.used is not None:
            self.used.report(i, k, values)

    def leader_state(self, k: int, now: float, q: np.ndarray | None = None,
                     p: np.ndarray | None = None, a: np.ndarray | None = None) -> None:
        """Take the leader's (checked) odometry ``q, p`` or acceleration ``a`` of step ``k``."""
        if self.leader.heard(self.k, now):
            self.log.info(f'leader back at step {self.k} (its state of step {k})')
        if q is not None:
            self.leader_odom[k] = (q, p)
        if a is not None:
            self.leader_accel[k] = a

    def lose_leader(self) -> None:
        """Note that the leader is gone (logged, recorded in the metrics and the summary)."""
        if self.leader.lose(self.k):
            self.log.warning(f'leader lost at step {self.k}: steps go on without waiting '
                             'for it')

    # -- lockstep -----------------------------------------------------------------------------

    def tick(self, now: float, ready: Callable[[], bool]) -> str | None:
        """Return what the lockstep timer must do at ``now``.

        :param ready: whether every agent and the leader are there (asked before the start).
        :return: ``'begin'`` (the run starts: open step 0, once everybody is there or the
            start timeout is over), ``'timeout'`` (close the open step), ``'resend'`` (offer
            it again: :meth:`resent` was called) or ``None``.
        """
        if self.done:
            return None
        if not self.started:
            is_ready = ready()
            if not is_ready and now - self.t_created < self.settings.start_timeout:
                return None
            if not is_ready:
                self.log.warning('start timeout: starting without every agent or the leader')
            self.start(now)
            return 'begin'
        if now >= self.deadline:
            return 'timeout'
        if now >= self.resend_at:
            self.resent(now)
            return 'resend'
        return None

    def start(self, now: float) -> None:
        """Start the run (the wall time of the summary counts from here)."""
        self.started = True
        self.t_wall0 = now

    def begin_step(self, now: float) -> None:
        """Open the current step: no command yet, its timeout and first resend ahead."""
        self.commands = {}
        self.command_rows = None
        self.twists = {}
        self.state_in = set()
        self.step_began = now
        self.deadline = now + self.settings.step_timeout
        if self.k == 0:
            # Step 0 completes the start: the world has matched the others' endpoints, but
            # an agent's reader may not have matched the world's writers yet (DDS matches
            # each side on its own), so step 0 waits out what is left of start_timeout.
            self.deadline = max(self.deadline, self.t_created + self.settings.start_timeout)
        self.resend_wait = first_resend_wait(self.last_step_s, self.settings.step_timeout)
        self.resend_at = now + self.resend_wait

    def resent(self, now: float) -> None:
        """Note that the open step was offered again; schedule the next offer.

        DDS drops a sample that reaches a reader before the reader has matched its writer,
        and a reliable writer repairs it only at its next heartbeat (3 s in Fast DDS), so a
        stalled step is offered again until its timeout: the leader answers a repeated tick,
        and agents repeat the commands they already sent. A step counts as stalled after
        ``RESEND_PERIOD`` or ``RESEND_SLOWER`` times the previous step's duration, whichever
        is longer but at most half the step timeout (``first_resend_wait``). Once a step has
        finished, every further offer waits twice as long (``next_resend_wait``), so an
        overloaded swarm (tens of agent processes on two cores, a second or more a step) is
        not flooded with copies of every message, which made it slower still (measured: 100
        steps of 50 agent processes at 0.5 steps/s, 303 offers, 1919 commands timed out).
        """
        self.resends += 1
        self.resend_wait = next_resend_wait(self.resend_wait, self.last_step_s)
        self.resend_at = now + self.resend_wait

    def complete(self) -> bool:
        """Return whether the open lockstep step has every command and the leader's state
        (and, for a law with adaptive state, every agent's)."""
        n = self.scenario.n_agents
        return (self.lockstep and self.started and not self.done
                and len(self.commands) == n and (not self.state or len(self.state_in) == n)
                and (not self.velocity or len(self.twists) == n)
                and (self.leader.lost
                     or (self.k in self.leader_odom and self.k in self.leader_accel)))

    def close_step(self, timed_out: bool, now: float) -> Observation:
        """Close the open step: zero commands for absentees, take the leader's state.

        :param timed_out: whether the step timeout closed it.
        :param now: the time.
        :return: the step observed (recorded in the run log); :meth:`advance` follows
            unless it is the last.
        """
        sc, k, n = self.scenario, self.k, self.scenario.n_agents
        if self.command_rows is not None:
            u, missing = np.array(self.command_rows, dtype=float), []
        else:
            u = np.zeros((n, sc.dim))
            missing = [i for i in range(n) if i not in self.commands]
            for i, ui in self.commands.items():
                u[i] = ui
        if self.velocity:
            # A velocity command missing: the robot stops (a zero Twist), as robots do when
            # their cmd_vel goes silent.
            missing = sorted(set(missing) | {i for i in range(n) if i not in self.twists})
        leader_missing = k not in self.leader_odom or k not in self.leader_accel
        if missing:
            self.missed[missing] += 1
            self.log.warning(f'step {k}: no command from agent(s) {missing} within '
                             f'{self.settings.step_timeout:g} s; zero command applied')
        self.last_missing = set(missing)
        answered = np.ones(n, dtype=bool)
        answered[missing] = False
        self.silent_steps[answered] = 0
        self.silent_steps[missing] += 1
        # An agent without its command is told above; one whose command came without its
        # state is told here.
        silent = [i for i in range(n) if i not in self.state_in and i not in missing] \
            if self.state else []
        if silent:
            self.log.warning(f'step {k}: no adaptive state from agent(s) {silent} within '
                             f'{self.settings.step_timeout:g} s; their last state is recorded')
        if leader_missing:
            self.leader_missed += 1
            self.lose_leader()
        else:
            q_l, p_l = self.leader_odom.pop(k)
            self.last_leader = LeaderState(q_l, p_l, self.leader_accel.pop(k))
        self._forget_leader_before(k)
        if not timed_out:
            # How long a step takes now (a timed-out step says nothing about that).
            self.last_step_s = now - self.step_began
        return self.observe(u, missing)

    def silent_agents(self, k: int, hosts: Callable[[int], str] = lambda i: '') -> str | None:
        """Return the line of a failed run when agents that answered before have missed
        ``max_missed_steps`` steps in a row up to step ``k`` (lockstep), else ``None``.

        :param k: the step closed last.
        :param hosts: the node hosting an agent, as the graph last told (``''``: unknown).
        """
        m = self.settings.max_missed_steps
        if not self.lockstep or not m:
            return None
        silent = np.flatnonzero(self.heard & (self.silent_steps >= m)).tolist()
        if not silent:
            return None
        nodes = sorted({hosts(i) for i in silent} - {''})
        return (f'{agents_text(silent)}' + (f' (node {", ".join(nodes)})' if nodes else '')
                + f' sent no command for {m} steps in a row (steps {k - m + 1}-{k}, '
                f'{self.settings.step_timeout:g} s each): its node is gone or stalled')

    def graph_gone(self, agents: Sequence[int], leader: bool, now: float,
                   hosts: Callable[[int], str] = lambda i: '') -> str | None:
        """Note which peers the ROS graph no longer shows; return the line of a failed run
        once one has been gone ``peer_timeout`` seconds, else ``None``.

        Only a peer that answered before counts: an agent whose command came, the leader
        once heard (an agent never seen is zeroed as before, see :meth:`close_step`).

        :param agents: the agents no node publishes commands for now.
        :param leader: whether no node publishes the leader's odometry now.
        :param now: the time.
        :param hosts: the node that hosted an agent, as the graph last told.
        """
        timeout = self.settings.peer_timeout
        gone: set[int | str] = {int(i) for i in agents if self.heard[i]}
        if leader and self.leader.ever_heard:
            gone.add('leader')
        for peer in list(self.gone_since):
            if peer not in gone:
                del self.gone_since[peer]
        for peer in gone:
            self.gone_since.setdefault(peer, now)
        if not timeout:
            return None
        out = sorted((p for p in gone if now - self.gone_since[p] >= timeout), key=str)
        if not out:
            return None
        names = ['the leader' if p == 'leader' else f'agent {p}' + (
            f' (node {hosts(p)})' if hosts(p) else '') for p in out]
        return (f'{", ".join(names)} left the ROS graph (no publisher for '
                f'{timeout:g} s) at step {self.k}: its node exited or died')

    def fault_reported(self, k: int, agents: Sequence[int], non_finite: bool) -> None:
        """Count the non-finite commands an agent node reported for step ``k``.

        A report that comes after its step was observed counts at the open step, and one
        after the end not at all: so ``/swarm/metrics`` (its ``non_finite_this_step``), the
        time series and the summary count the same (``analyze`` adds them up from the bag).
        """
        if non_finite and agents and not self.done:
            self.non_finite[list(agents)] += 1
            self.non_finite_at.setdefault(max(k, self.k), []).extend(int(i) for i in agents)

    # -- realtime -----------------------------------------------------------------------------

    def realtime_begin(self, now: float) -> None:
        """Realtime: take the leader's latest complete state; lose a silent leader."""
        k = self.k
        latest = k if k in self.leader_odom and k in self.leader_accel \
            else max(self.leader_odom, default=None)
        if latest is not None and latest in self.leader_accel:
            q_l, p_l = self.leader_odom[latest]
            self.last_leader = LeaderState(q_l, p_l, self.leader_accel[latest])
        self._forget_leader_before(k - LEADER_KEEP)
        if not self.started:
            # Staleness counts from the first step, not from the node's construction.
            self.held_at[:] = now
            self.held_twist_at[:] = now
            self.leader.seen_at = max(self.leader.seen_at, now)
        if self.leader.silent_for(now) > self.settings.staleness:
            self.lose_leader()

    def realtime_close(self, now: float, published: float) -> Observation:
        """Realtime: observe the step with the held commands (a stale one zeroed).

        With velocity commands the world applies the agents' Twists: one older than the
        staleness is the missing command (counted, logged), and that robot stops for the step
        (a zero Twist, :meth:`plant_command`; its ``u`` recorded as zero), as a stale
        acceleration is zeroed. Otherwise the held accelerations are the commands.

        :param now: the time the step began (:meth:`realtime_begin`).
        :param published: the time its odometry went out.
        """
        k = self.k
        self.published_at[k] = published
        self.published_at.pop(k - PUBLISHED_KEEP, None)
        u = self.held.copy()
        old = now - self.held_at > self.settings.staleness
        if self.velocity:
            self.stopped = now - self.held_twist_at > self.settings.staleness
            u[old | self.stopped] = 0.0
            stale = np.flatnonzero(self.stopped)
        else:
            stale = np.flatnonzero(old)
        u[stale] = 0.0
        self.missed[stale] += 1
        self._note_stale({int(i) for i in stale})
        self.started = True
        return self.observe(u, [int(i) for i in stale])

    def _note_stale(self, stale: set[int]) -> None:
        """Log agents whose held command went stale (zero from now) or came back."""
        for i in sorted(stale - self.stale_agents):
            self.log.warning(f'step {self.k}: agent {i} sent no command for '
                             f'{self.settings.staleness:g} s; zero command until it does')
        for i in sorted(self.stale_agents - stale):
            self.log.info(f'step {self.k}: agent {i} commands again')
        self.stale_agents = stale

    # -- both modes ---------------------------------------------------------------------------

    def _forget_leader_before(self, k: int) -> None:
        for old in [s for s in self.leader_odom if s < k]:
            del self.leader_odom[old]
        for old in [s for s in self.leader_accel if s < k]:
            del self.leader_accel[old]

    def observe(self, u: np.ndarray, missing: list[int]) -> Observation:
        """Record the open step in the run log; return it with the telemetry due."""
        sc, k, st = self.scenario, self.k, self.settings
        law = sc.law
        leader = self.last_leader
        edges = disk_graph(self.q, law.radius, law.strict_radius)
        last = k >= sc.steps
        covered, radius = observed_pairs(sc, self.real, self.q, self.static, edges)
        net, counts = {}, None
        if self.net is not None:
            counts = self.net.step(k, self.q, self.p)
        elif self.used is not None:
            applied = self.held_step.copy()
            applied[missing] = -1
            counts = self.used.step(k, applied)
        if counts is not None:
            self.net_record.add(counts)
            self.net_metrics.add(counts)
            if k % sc.record_every == 0 or last:
                net = self.net_record.take(sc.dt)
        now = self.run_log.observe(k, k * sc.dt, self.q, self.p, u, leader,
                                   self.real.agents.informed, covered, radius, last,
                                   non_finite_commands=self.non_finite.copy(), **self.state,
                                   **net, **self.world.recorded())
        if now is not None:
            self.metrics_now = now
        events = self.leader.events
        event = bool(events) and events[-1][0] == k
        values, problems = None, []
        non_finite = sorted(set(self.non_finite_at.pop(k, [])))
        for old in [s for s in self.non_finite_at if s < k]:
            del self.non_finite_at[old]
        if k % st.metrics_every == 0 or missing or last or event or non_finite:
            if not self.metrics_now:
                self.metrics_now = step_metrics(self.q, self.p, leader, sc.eta_tolerance,
                                                law.radius, law.strict_radius)
            values = dict(self.metrics_now, step=k, missed_commands=int(self.missed.sum()),
                          missed_this_step=json.dumps(missing),
                          non_finite_commands=int(self.non_finite.sum()),
                          non_finite_this_step=json.dumps(non_finite),
                          leader_missed=self.leader_missed,
                          leader='lost' if self.leader.lost else 'ok')
            if counts is not None:
                # Of the steps since the previous message (docs/network.md).
                values.update(self.net_metrics.take(sc.dt))
            if self.world.counts_contacts:
                values.update(robot_contacts=len(self.world.contacts_run),
                              robot_contacts_this_step=len(self.world.contacts_step))
            problems = ([f'{len(missing)} missing command(s)'] if missing else []) \
                + ([f'{len(non_finite)} non-finite command(s)'] if non_finite else []) \
                + (['leader lost'] if self.leader.lost else [])
        return Observation(k, self.q, self.p, u, leader, edges, missing,
                           k % st.marker_every == 0 or last, values, problems, last)

    def twist_rows(self) -> np.ndarray | None:
        """Return the Twist rows the plants execute this step, or ``None``: the world applies
        the accelerations. A missing (lockstep) or stale (realtime) Twist is a stop (zero)."""
        if not self.velocity:
            return None
        if self.lockstep:
            rows = np.zeros((self.scenario.n_agents, 6))
            for i, row in self.twists.items():
                rows[i] = row
        else:
            rows = self.held_twist.copy()
            rows[self.stopped] = 0.0
        return rows

    def advance(self, u: np.ndarray) -> bool:
        """Integrate every agent over one step with ``u`` held (the plant under its command:
        the conversion of ``u``, or the Twists of :meth:`twist_rows`, exactly as ``sim``'s);
        return whether the state is still finite."""
        self.world.step(u, self.twist_rows(), self.scenario.dt)
        if self.world.counts_contacts:
            self._note_contacts()
        self.k += 1
        return bool(np.isfinite(self.q).all() and np.isfinite(self.p).all())

    def _note_contacts(self) -> None:
        """Log the robot pairs that touched in the engine for the first time."""
        new = self.world.contacts_run - self.contacts_told
        if new:
            self.log.warning(f'step {self.k}: robots in contact in the physics engine: '
                             f'{sorted(new)}')
            self.contacts_told |= new

    def progress_line(self, now: float, every: float = 2.0) -> str | None:
        """Return a one-line status when ``every`` seconds have passed since the last."""
        if now - self.t_last_progress < every:
            return None
        self.t_last_progress = now
        sc, m = self.scenario, self.metrics_now
        return (f'[world] t = {self.k * sc.dt:.2f}/{sc.duration:g} s  step {self.k}/{sc.steps}'
                f'  {self.k / max(now - self.t_wall0, 1e-9):.1f} steps/s'
                f'  {progress_text(m, sc.headline)}'
                f'  missed = {int(self.missed.sum())}')

    # -- the end ------------------------------------------------------------------------------

    def end(self, status: str, failure: str | None = None) -> bool:
        """End the run with ``status`` (``failure``: the line telling why it failed); return
        ``False`` when it had ended already."""
        if self.done:
            return False
        self.done = True
        self.status = status
        self.failure = failure
        return True

    def result(self, now: float, rejected: dict, duplicates: list[int],
               bag_error: str | None, bag: str | None) -> SimResult:
        """Return the run so far (no time series, and no measures in the summary, when it
        ended before anything was recorded: stopped before its first step).

        :param now: the time (for the wall time).
        :param rejected: the rejected messages by reason (the node's input guard).
        :param duplicates: agent ids claimed by more than one node.
        :param bag_error: why recording failed, or ``None``.
        :param bag: the bag's path (``None``: not recorded).
        :return: the summary (``docs/outputs.md``) and the recorded time series.
        """
        log = self.run_log
        series = log.rec.arrays()
        given = {
            'mode': 'lockstep' if self.lockstep else 'realtime',
            'missed_commands': int(self.missed.sum()),
            'missed_commands_per_agent': [int(x) for x in self.missed],
            'non_finite_commands_per_agent': [int(x) for x in self.non_finite],
            'rejected_messages': rejected,
            'leader_events': self.leader.events,
            'duplicate_agent_ids': duplicates,
            'bag_error': bag_error,
            'command_latency_ms': None if self.lockstep else self.latency.summary_ms(),
            'resent_steps': self.resends,
            'leader_missed': self.leader_missed,
            'wall_time_s': round(now - self.t_wall0, 3),
            'bag': bag,
        }
        if self.failure is not None:
            given['failure'] = self.failure
        if self.world.counts_contacts:
            given['robot_contacts'] = len(self.world.contacts_run)
        # Every key through the checked table (core/summary.py), in its order.
        summary = build_summary(self.scenario, self.real, series, log.metrics, self.k,
                                self.status, **given)
        return SimResult(summary, series)


class CommandInbox(StepInbox):
    """Lockstep: the agents' commands of the open step, queued as serialised bytes and handed
    to the stepper at once once every agent's is in (:mod:`flock_swarm.nodes.inbox`).

    :ivar steps_at_once: steps whose commands were taken in one pass (the rest went one by
        one, through the node's checks).
    """

    def __init__(self, stepper: WorldStepper, guard: InputGuard, topics: Sequence[str]) -> None:
        """Create the inbox of ``stepper``'s commands.

        :param stepper: the world's stepper (its scenario gives the agents).
        :param guard: the world's input guard.
        :param topics: every agent's command topic, by agent.
        """
        super().__init__(stepper.scenario.n_agents, AccelBatch(stepper.scenario.n_agents))
        self.stepper, self.guard, self.topics = stepper, guard, topics
        self.steps_at_once = 0

    def put(self, sender: int, data: bytes) -> bool:
        """Queue agent ``sender``'s command; return whether the queue, with the commands the
        stepper holds, can complete the open step: then take it."""
        super().put(sender, data)
        return len(self.queue) + len(self.stepper.commands) >= self.size

    def take_step(self, queue: Sequence[tuple[int, bytes]]) -> int | None:
        """Hand the stepper the commands of ``queue`` at once when they are the open step's
        command of every agent, none held yet, and the guard passes them all
        (:meth:`WorldStepper.commands_all`); return the step, or ``None``: then the caller
        handles them one by one.

        :param queue: the commands taken (:meth:`take`).
        """
        st = self.stepper
        if st.commands or not st.started or st.done:
            return None
        decoded = self.decode(queue)
        if decoded is None or self.guard.clock.step_at(decoded[0]) != st.k:
            return None
        ns, lin = decoded
        k = self.guard.pass_batch(self.topics, ns, ((lin, self.guard.limits.accel),))
        if k is None:
            return None
        st.commands_all(k, lin[:, 0, :st.scenario.dim])
        self.steps_at_once += 1
        return k
