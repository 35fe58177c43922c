"""The world's two stepping modes over one stepper: lockstep and realtime.

:class:`~flock_swarm.nodes.stepper.WorldStepper` holds what both modes share (the inputs, the
observation of a step, the integration by the backend, the faults, the summary);
``WorldStepper(sc, settings, ...)`` makes the mode's stepper of ``settings.lockstep``:

- :class:`LockstepStepper`: the world opens a step, waits for every agent's command and the
  leader's state (offering a stalled step again), zeroes what is missing at the step
  timeout, closes the step and integrates (deterministic, ``sim``'s bit for bit);
- :class:`RealtimeStepper`: a wall-clock timer steps with the latest commands (zero-order
  hold), a command older than the staleness is zero.
"""

from typing import Callable, Sequence

import numpy as np

from flock_swarm.core.faults import agents_text
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.network import ReportedUse
from flock_swarm.core.run import LinkObserver, Recorder
from flock_swarm.core.scenario import Scenario
from flock_swarm.nodes.leader_watch import Log
from flock_swarm.nodes.stepper import Observation, WorldStepper
from flock_swarm.nodes.world_settings import (LEADER_KEEP, PUBLISHED_KEEP, RESEND_PERIOD,
                                              LatencyHistogram, WorldSettings,
                                              first_resend_wait, next_resend_wait)


class LockstepStepper(WorldStepper):
    """Lockstep: a step closes once every input is in, or at its timeout.

    :ivar commands: the open step's commands by agent.
    :ivar command_rows: the same as one array, while they came at once (:meth:`commands_all`).
    :ivar twists: the open step's velocity commands by agent, (linear, angular) rows of 3.
    :ivar state_in: the agents whose adaptive state of the open step is in.
    :ivar deadline: when the open step times out.
    :ivar resend_at: when it is offered again (:meth:`resent`).
    :ivar last_step_s: how long the last step took (a timed-out one not counted).
    """

    def __init__(self, sc: Scenario, settings: WorldSettings, log: Log,
                 now: float | None = None, recorder: Recorder | None = None) -> None:
        """Create the stepper (see :class:`~flock_swarm.nodes.stepper.WorldStepper`)."""
        super().__init__(sc, settings, log, now, recorder)
        self.commands: dict[int, np.ndarray] = {}
        self.command_rows: np.ndarray | None = None
        self.twists: dict[int, np.ndarray] = {}
        self.state_in: set[int] = set()
        self.last_missing: set[int] = set()
        # The messages between the agents (``network:``): kept as the agents keep them, to
        # record the statistics sim records (the agents' links only: no leader messages,
        # nobody informed; docs/network.md).
        self.net = LinkObserver(sc, self.real, self.static) if sc.network.active else None
        self.deadline = 0.0
        self.resend_at = 0.0
        self.resend_wait = RESEND_PERIOD
        self.step_began = 0.0
        self.last_step_s = 0.0

    # -- inputs -------------------------------------------------------------------------------

    def command(self, i: int, k: int, u: np.ndarray, now: float) -> bool:
        """Take agent ``i``'s (checked) command for step ``k``; return whether it is late.

        A command for the open step is kept for it; one for the step just closed that went
        without it came too late (a repeated command for that step, after the world offered
        it again, is no fault).
        """
        self.heard[i] = True
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
        """Take agent ``i``'s (checked) velocity command: ``Twist`` carries no stamp, it
        answers the open step (an agent sends one per step, after the step's odometry, and
        never again for a step offered again)."""
        if self.started and not self.done:
            self.twists[i] = np.concatenate([linear, angular]).astype(float)

    def agent_state(self, i: int, k: int, values: Sequence[float]) -> None:
        """Take agent ``i``'s (checked) adaptive state of step ``k``: the state of the open
        step counts (it completes the step with the commands); one of the step just closed
        is a repeat, or came after the step was closed without it (its last state was
        recorded)."""
        if not self.started or self.done or k != self.k:
            return
        self.state_in.add(i)
        super().agent_state(i, k, values)

    def twist_rows(self) -> np.ndarray | None:
        """Return the open step's Twist rows (a missing one: zero, the robot stops), or
        ``None``: the world applies the accelerations."""
        if not self.velocity:
            return None
        rows = np.zeros((self.scenario.n_agents, 6))
        for i, row in self.twists.items():
            rows[i] = row
        return rows

    # -- the step -----------------------------------------------------------------------------

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


class RealtimeStepper(WorldStepper):
    """Realtime: a step is observed with the commands held (zero-order hold), a command
    older than the staleness zeroed.

    :ivar held: the latest command of every agent (zero before the first).
    :ivar latency: how long commands took to answer their step's odometry.
    """

    def __init__(self, sc: Scenario, settings: WorldSettings, log: Log,
                 now: float | None = None, recorder: Recorder | None = None) -> None:
        """Create the stepper (see :class:`~flock_swarm.nodes.stepper.WorldStepper`)."""
        super().__init__(sc, settings, log, now, recorder)
        n = sc.n_agents
        self.held = np.zeros((n, sc.dim))
        self.held_at = np.full(n, -np.inf)
        # The latest velocity command of every agent (zero: stop, before the first), when it
        # came, and the robots stopped this step (their Twist older than the staleness: a
        # zero Twist applied instead).
        self.held_twist = np.zeros((n, 6))
        self.held_twist_at = np.full(n, -np.inf)
        self.stopped = np.zeros(n, dtype=bool)
        self.stale_agents: set[int] = set()
        # Wall time each step's odometry went out, and how long commands took.
        self.published_at: dict[int, float] = {}
        self.latency = LatencyHistogram()
        # With the network model the agents report what each command used, the world adds
        # the age the command had when applied (docs/network.md).
        self.used = ReportedUse(n, PUBLISHED_KEEP) if sc.network.active else None
        #: The step each agent's held command answers (-1: none yet).
        self.held_step = np.full(n, -1, dtype=np.int64)

    # -- inputs -------------------------------------------------------------------------------

    def command(self, i: int, k: int, u: np.ndarray, now: float) -> bool:
        """Take agent ``i``'s (checked) command for step ``k``, held until the next; it is
        never late (return ``False``)."""
        self.heard[i] = True
        self.held[i] = u
        self.held_at[i] = now
        self.held_step[i] = k
        sent = self.published_at.get(k)
        if sent is not None:
            self.latency.add(now - sent)
        return False

    def twist(self, i: int, linear: Sequence[float], angular: Sequence[float],
              now: float) -> None:
        """Take agent ``i``'s (checked) velocity command, arrived at ``now``: held until the
        next, for at most the staleness."""
        self.held_twist[i] = np.concatenate([linear, angular]).astype(float)
        self.held_twist_at[i] = now

    def twist_rows(self) -> np.ndarray | None:
        """Return the held Twist rows (a stale one: zero, the robot stops), or ``None``: the
        world applies the accelerations."""
        if not self.velocity:
            return None
        rows = self.held_twist.copy()
        rows[self.stopped] = 0.0
        return rows

    # -- the step -----------------------------------------------------------------------------

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
