"""The world's stepping without ROS: commands in, the step closed, the swarm integrated.

:class:`WorldStepper` owns what the world node decides: the open step and the commands
received for it, the leader's buffered states and its loss
(:class:`~flock_swarm.nodes.leader_watch.LeaderWatch`), the agents' adaptive state of each
step (a law's ``h_i``, recorded as ``sim`` records it), the integration (by the backend,
:mod:`flock_swarm.engine.backends`: the same
:func:`~flock_swarm.core.dynamics.step_agents` as ``sim`` for the double integrator), the
faults that end the run (a peer that stopped answering or left the ROS graph, a fault a node
reported), the run log and the summary. The two modes are two strategies over it
(:mod:`flock_swarm.nodes.world_modes`): lockstep (the step timeout and the agents that missed
it, zero command; the resend policy of a stalled step) and realtime (held commands, stale
ones zeroed); ``WorldStepper(sc, settings, ...)`` makes the one of ``settings.lockstep``.
Its settings and timing rules are :mod:`flock_swarm.nodes.world_settings`'. The node turns
messages into its calls and its :class:`Observation` into messages; every time is passed in
(seconds of a monotonic clock), so the stepper runs as well from a unit test. In lockstep, a
step's commands are queued as bytes and handed over at once (:class:`CommandInbox`).
"""

import json
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from flock_swarm.contract import state_labels, state_slices
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.graphs import EdgeList, disk_graph
from flock_swarm.core.headline import progress_text
from flock_swarm.core.metrics import step_metrics
from flock_swarm.core.network import ReportedUse, Tally
from flock_swarm.core.plants.spec import command_interface
from flock_swarm.core.run import (LinkObserver, Recorder, RunLog, RunResult, build_summary,
                                  observed_pairs, static_graph)
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.engine.backends import make_backend
from flock_swarm.nodes.guard import InputGuard
from flock_swarm.nodes.inbox import StepInbox
from flock_swarm.nodes.leader_watch import LeaderWatch, Log
from flock_swarm.nodes.wire import AccelBatch
# The settings and timing rules, importable from here as before (docs/ros.md).
from flock_swarm.nodes.world_settings import (  # noqa: F401
    LEADER_KEEP, PUBLISHED_KEEP, RESEND_PERIOD, RESEND_SLOWER, SETTING_PARAMS,
    LatencyHistogram, WorldSettings, first_resend_wait, next_resend_wait)


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

    #: The mode's state its subclass sets (none in the other mode): lockstep, the agents'
    #: links observed (``network:``); realtime, what each command used and the latencies.
    net: LinkObserver | None = None
    used: ReportedUse | None = None
    latency: LatencyHistogram | None = None

    def __new__(cls, sc: Scenario, settings: WorldSettings, *args, **kwargs) -> 'WorldStepper':
        """Return the stepper of the settings' mode: ``WorldStepper(...)`` makes a
        :class:`~flock_swarm.nodes.world_modes.LockstepStepper` or a
        :class:`~flock_swarm.nodes.world_modes.RealtimeStepper`."""
        if cls is WorldStepper:
            # Imported here: the modes' module builds on this one.
            from flock_swarm.nodes.world_modes import LockstepStepper, RealtimeStepper
            cls = LockstepStepper if settings.lockstep else RealtimeStepper
        return super().__new__(cls)

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
        self.k = 0
        self._init_inputs(sc)
        self.run_log = RunLog.for_scenario(sc, recorder)
        # The statistics since the last recorded instant, and since the last /swarm/metrics.
        self.net_record, self.net_metrics = Tally(), Tally()
        self.metrics_now: dict = {}
        self.done = False
        self.started = False
        self.status = 'running'
        self.resends = 0
        self.t_created = self.t_wall0 = time.monotonic() if now is None else now
        self.t_last_progress = self.t_wall0

    def _init_inputs(self, sc: Scenario) -> None:
        """Start with nothing heard: the leader's initial state, the agents' initial
        adaptive state, no command missed, no fault."""
        n = sc.n_agents
        self.leader_odom: dict[int, tuple] = {}
        self.leader_accel: dict[int, np.ndarray] = {}
        self.last_leader = LeaderState(sc.leader.position.copy(), sc.leader.velocity.copy(),
                                       np.zeros(sc.dim))
        self.leader = LeaderWatch()
        # The agents' adaptive state (empty for a law without): the value of every agent at
        # the open step, an agent's last one held until its next comes (its initial value
        # before).
        self.state = {key: value.copy() for key, value in self.real.agents.state.items()}
        shapes = {key: value.shape[1:] for key, value in self.state.items()}
        self.state_labels = state_labels(shapes)
        self.state_layout = state_slices(shapes)
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
        """Take agent ``i``'s (checked) command for step ``k`` arrived at ``now``; return
        whether it came too late (the mode's rule)."""
        raise NotImplementedError

    def twist(self, i: int, linear: Sequence[float], angular: Sequence[float],
              now: float) -> None:
        """Take agent ``i``'s (checked) velocity command, arrived at ``now``."""
        raise NotImplementedError

    def agent_state(self, i: int, k: int, values: Sequence[float]) -> None:
        """Take agent ``i``'s (checked) adaptive state of step ``k``: the values of
        :attr:`state_labels`, in order, held until the next (lockstep: of the open step
        only)."""
        row = np.asarray(values, dtype=float)
        for key, shape, part in self.state_layout:
            self.state[key][i] = row[part].reshape(shape)

    def twist_rows(self) -> np.ndarray | None:
        """Return the Twist rows the plants execute this step, or ``None``: the world applies
        the accelerations. A missing (lockstep) or stale (realtime) Twist is a stop (zero)."""
        raise NotImplementedError

    def complete(self) -> bool:
        """Return whether the open step has every input it waits for (a realtime step waits
        for none: its timer closes it)."""
        return False

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
               bag_error: str | None, bag: str | None) -> RunResult:
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
            'command_latency_ms': None if self.latency is None else self.latency.summary_ms(),
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
        return RunResult(summary, series)


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
        (``LockstepStepper.commands_all``); return the step, or ``None``: then the caller
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
