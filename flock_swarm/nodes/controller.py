"""The agents' decisions without ROS: a step's inputs collected, the law evaluated once.

:class:`AgentController` is what an agent node (one agent, or a container of many) decides:
which inputs belong to which step, when a step can be answered (the leader's state or its
timeout), the commands (the same law functions as ``sim``,
:func:`flock_swarm.core.laws.evaluation.group_control`) and the adaptive state, advanced as ``sim``
advances it and told with each step's commands (:meth:`AgentController.state_values`, the
state they were computed with: what ``sim`` records at that step). The node turns messages
into its calls and its commands into messages. In lockstep, a step's odometry is
queued as bytes and stored at once (:class:`OdometryInbox`).
"""

import logging
import math
import re
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from flock_swarm.contract import state_labels
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.faults import (evaluate_law, evaluate_state, non_finite_fault,
                                     non_finite_rows, state_blew_up)
from flock_swarm.core.latency import LATENCY_CHOICES, LATENCY_PREDICT, CommandHistory, extrapolate
from flock_swarm.core.laws.evaluation import advance_state, group_control, group_sums
from flock_swarm.core.network import NetworkState, neighbourhood_of
from flock_swarm.core.obstacles import with_obstacles
from flock_swarm.core.plants.models import DoubleIntegrator
from flock_swarm.core.pseudo_leaders import Reselector
from flock_swarm.core.run import interaction_graph, static_graph
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.nodes.guard import InputGuard
from flock_swarm.nodes.inbox import StepInbox
from flock_swarm.nodes.leader_watch import LeaderWatch, Log
from flock_swarm.nodes.wire import OdometryBatch, plant_states

#: Steps an agent buffers inputs for at once (lockstep needs two: the open step and the next).
MAX_PENDING = 8
#: What the agents do with a non-finite command of the law (the ``non_finite`` parameter):
#: fail the run (the default), or apply a zero command instead and go on (counted).
NON_FINITE_FAIL, NON_FINITE_ZERO = 'fail', 'zero'


@dataclass
class StepInputs:
    """What the hosted agents have received for one step.

    :ivar odom: agent ``j``'s ``(position, velocity)`` by ``j``, as messages came one by one
        (an oriented plant's odometry adds ``(qz, qw)`` and ``(yaw rate, 0)``:
        :func:`~flock_swarm.nodes.wire.odometry_rows`).
    :ivar qp: every agent's state at once, shape ``(N, 2, dim)`` (positions, velocities;
        ``(N, 4, dim)`` for an oriented plant), when a whole step's odometry came in one
        pass (:meth:`put_all`); ``None`` before.
    """

    odom: dict = field(default_factory=dict)
    leader_odom: tuple | None = None
    leader_accel: np.ndarray | None = None
    qp: np.ndarray | None = None

    def put(self, j: int, state: tuple) -> None:
        """Store agent ``j``'s ``(position, velocity)`` (the latest of a step counts)."""
        if self.qp is not None:
            self.qp[j] = state
        else:
            self.odom[j] = state

    def put_all(self, qp: np.ndarray) -> None:
        """Store every agent's state at once (``(N, 2, dim)``: it replaces what came before,
        as a message of each agent would)."""
        self.qp = qp
        self.odom.clear()

    def has_odometry(self, n_agents: int) -> bool:
        """Return whether every agent's odometry is in."""
        return self.qp is not None or len(self.odom) == n_agents

    @property
    def has_leader(self) -> bool:
        """Return whether the leader's state (odometry and acceleration) is in."""
        return self.leader_odom is not None and self.leader_accel is not None

    def swarm(self, n_agents: int, view: Callable[[np.ndarray], tuple] | None = None
              ) -> tuple[np.ndarray, np.ndarray, LeaderState | None]:
        """Return ``(q, p, leader)`` (``leader`` ``None`` when it is not in).

        :param view: turns the odometry vectors ``(N, K, dim)`` into what the law sees,
            ``(q, p)``; ``None``: they are positions and velocities.
        """
        if self.qp is not None:
            qp = self.qp
        else:
            odom = self.odom
            qp = np.array([odom[j] for j in range(n_agents)])
        leader = LeaderState(np.array(self.leader_odom[0]), np.array(self.leader_odom[1]),
                             np.array(self.leader_accel)) if self.has_leader else None
        q, p = (qp[:, 0], qp[:, 1]) if view is None else view(qp)
        return q, p, leader


def parse_agent_ids(spec: Any, agent_id: int, n_agents: int) -> np.ndarray:
    """Return the ascending ids a node hosts from its ``agent_ids`` parameter.

    :param spec: ``''`` (just ``agent_id``), ``'all'``, a string of ids and ranges such as
        ``'0-9,12'``, or a list of integers.
    :param agent_id: the ``agent_id`` parameter.
    :param n_agents: the swarm's size.
    :return: the ids.
    :raises ScenarioError: on a malformed, repeated or out-of-range id.
    """
    if isinstance(spec, str):
        text = spec.strip()
        if text == '':
            ids = [agent_id]
        elif text == 'all':
            ids = list(range(n_agents))
        else:
            ids = []
            for part in text.split(','):
                m = re.fullmatch(r'\s*(\d+)\s*(?:-\s*(\d+)\s*)?', part)
                if m is None:
                    raise ScenarioError('agent_ids', f'expected ids and ranges such as '
                                        f"'0-9,12', got {spec!r}")
                lo, hi = int(m.group(1)), int(m.group(2) or m.group(1))
                if hi < lo:
                    raise ScenarioError('agent_ids', f'empty range {part.strip()!r}')
                ids += range(lo, hi + 1)
    elif isinstance(spec, (list, tuple, np.ndarray)) and all(
            isinstance(x, (int, np.integer)) and not isinstance(x, bool) for x in spec):
        ids = [int(x) for x in spec]
    else:
        raise ScenarioError('agent_ids', f'expected a string or an integer array, got {spec!r}')
    if not ids:
        raise ScenarioError('agent_ids', 'hosts no agent')
    bad = [i for i in ids if not 0 <= i < n_agents]
    if bad:
        key = 'agent_id' if isinstance(spec, str) and spec.strip() == '' else 'agent_ids'
        raise ScenarioError(key, f'must be in [0, {n_agents - 1}] (n_agents = {n_agents}), '
                            f'got {bad[0]}')
    if len(set(ids)) != len(ids):
        raise ScenarioError('agent_ids', f'lists an agent twice: {spec!r}')
    return np.array(sorted(ids), dtype=np.intp)


class AgentController:
    """The decision logic of the agents ``ids`` (no ROS): collect a step's inputs, answer once.

    It also follows the leader (:class:`~flock_swarm.nodes.leader_watch.LeaderWatch`): a step
    whose odometry is complete waits for the leader's state at most ``leader_timeout``
    (``leader_start_timeout`` before the leader was first heard), then the uninformed law
    applies until the leader is back. A law that raises or returns the wrong shape raises
    :class:`~flock_swarm.core.faults.RunFault` (the node reports it and the run fails); so
    does a non-finite command, unless ``non_finite`` is ``'zero'``: then it is replaced by
    zero (counted per agent in ``non_finite``, the first of each agent logged). A non-finite
    command for a state that has blown up (:func:`~flock_swarm.core.faults.state_blew_up`)
    is zero in both cases: the world tells the divergence.

    :ivar answered: the last step answered (``-1`` before the first).
    :ivar zeroed: the hosted agents whose command of the last answer was replaced by zero.
    :ivar state: the hosted agents' adaptive state the last commands were computed with
        (before it advanced), ``{key: (m, ...)}``; empty for a law without.
    """

    def __init__(self, sc: Scenario, ids: Sequence[int], log: Log | None = None,
                 leader_timeout: float = 1.0, leader_start_timeout: float = 30.0,
                 now: float | None = None, non_finite: str = NON_FINITE_FAIL,
                 latency: str = LATENCY_PREDICT, realtime_factor: float = 1.0,
                 velocity: bool = False) -> None:
        """Create the controller of agents ``ids`` (ascending, distinct) of scenario ``sc``.

        :param log: where the leader's loss and non-finite commands are told (default: the
            :mod:`logging` logger ``flock_swarm.agent``).
        :param leader_timeout: seconds without the leader state before the uninformed law.
        :param leader_start_timeout: the same before the leader was first heard.
        :param now: the time [s, a monotonic clock] the leader's silence counts from.
        :param non_finite: :data:`NON_FINITE_FAIL` or :data:`NON_FINITE_ZERO` (see above).
        :param latency: realtime: ``'predict'`` (each state predicted to the step the next
            command applies, :meth:`predicted`) or ``'off'`` (the states as measured).
        :param realtime_factor: realtime: simulated seconds per wall second.
        :param velocity: the commands go out as velocities (``cmd_vel``, the plant's
            commands) rather than accelerations.
        """
        self.sc = sc
        self.ids = np.asarray(ids, dtype=np.intp)
        self.real = realize(sc)
        self.static = static_graph(sc, self.real)
        # The whole swarm's law data: re-selecting pseudo-leaders needs everybody's flags.
        self.swarm = self.real.agents
        self.reselector = Reselector(sc.law) if sc.informed.reselect and \
            self.static is None else None
        self.pending: dict[int, StepInputs] = {}
        self.answered = -1
        # The step whose commands were sent again (see offered_again).
        self.repeated = -1
        self.log = logging.getLogger('flock_swarm.agent') if log is None else log
        self.leader_timeout, self.leader_start_timeout = leader_timeout, leader_start_timeout
        self.leader = LeaderWatch(time.monotonic() if now is None else now)
        self.waiting_since: float | None = None
        # Realtime: the latest input of every kind, and the step of the latest odometry.
        self.latest = StepInputs()
        self.latest_step: int | None = None
        self.non_finite: Counter = Counter()
        # The messages between the agents (``network:``): every agent's odometry reaches
        # every host, so each host sends the whole swarm's messages as sim does and evaluates
        # its own agents on them (the draws are keyed by the link). In realtime the sending
        # step is the stamp of the latest odometry (steps the host did not see send nothing).
        self.net = NetworkState(sc.network, sc.seed, sc.n_agents, sc.dim, sc.law,
                                neighbourhood_of(sc.graph_type, sc.law.all_pairs),
                                sc.law.coupling_weight) if sc.network.active else None
        #: Realtime with the network model: what each hosted agent's last command used
        #: (:meth:`NetworkState.usage`, one row per hosted agent), reported with it.
        self.usage: np.ndarray | None = None
        self.non_finite_policy = non_finite
        self.zeroed: list[int] = []
        self.state = self.swarm.subset(self.ids).state
        shapes = {key: value.shape[1:] for key, value in self.state.items()}
        #: The labels of one agent's state (:func:`flock_swarm.contract.state_labels`).
        self.state_labels = state_labels(shapes)
        #: The plant (``None``: the double integrator, whose odometry is what the law sees)
        #: and the whole swarm's plant state of the step answered last (:meth:`law_view`).
        self.plant = None if sc.plant.default else sc.plant.model
        self.view = None if self.plant is None else self.law_view
        self.x: np.ndarray | None = None
        if latency not in LATENCY_CHOICES:
            raise ScenarioError('latency', f"must be 'predict' or 'off', got {latency!r}")
        #: Realtime: predict the states to the step the next command applies (latency).
        self.predicting = latency == LATENCY_PREDICT
        self.rate = realtime_factor
        self.velocity = velocity
        #: The plant the prediction steps (the double integrator's for the default plant).
        self.dynamics = DoubleIntegrator() if self.plant is None else self.plant
        #: The hosted agents' commands sent, each in force from the step it applies at.
        self.history = CommandHistory(self.dynamics, accelerations=not velocity,
                                      period=sc.dt)
        #: Realtime: each agent's latest odometry step, and the newest step with the
        #: monotonic time its first odometry came (where the world's ticks are).
        self.measured = np.zeros(sc.n_agents, dtype=np.int64)
        self.reference: tuple[int, float] | None = None
        #: Realtime with prediction: the time [s, simulated] the last commands apply at.
        self.apply_at: float | None = None

    def law_view(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return what the law sees, ``(q, p)``, of every agent's odometry vectors; keep the
        plant states in :attr:`x` (the hosted agents' commands are converted from them)."""
        self.x = plant_states(self.plant, rows, self.sc.dim)
        return self.plant.law_state(self.x)

    def velocity_commands(self, u: np.ndarray, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """Return the hosted agents' velocity commands for their accelerations ``u``: the
        plant's conversion from their state of the step answered (exactly what ``sim`` and
        the world compute), as ``Twist`` vectors ``(linear (m, 3), angular (m, 3))``."""
        own = self.x[self.ids]
        cmd = self.plant.command(own, u, self.sc.dt)
        if self.apply_at is not None:
            self.history.sent(self.apply_at, cmd)
        return self.plant.twist(own, cmd, frame)

    def heard(self, j: int, k: int, state: tuple, now: float) -> None:
        """Realtime: keep agent ``j``'s odometry of step ``k``, received at ``now``
        [s, monotonic], as its latest."""
        self.latest.odom[j] = state
        self.latest_step = k
        self.measured[j] = k
        if self.reference is None or k > self.reference[0]:
            self.reference = (k, now)

    def heard_all(self, k: int, rows: np.ndarray, now: float) -> None:
        """Keep every agent's odometry vectors of step ``k`` (``(N, 2 or 4, dim)``: the
        batched transport's state message), received at ``now`` [s, monotonic], as the latest
        (:meth:`heard` for each agent at once)."""
        self.latest.put_all(rows)
        self.latest_step = k
        self.measured[:] = k
        if self.reference is None or k > self.reference[0]:
            self.reference = (k, now)

    def predicted(self, q: np.ndarray, p: np.ndarray, now: float
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Return the swarm's law state ``(q, p)`` predicted to the step the commands
        computed ``now`` apply at (realtime, docs/robots.md "Latency prediction").

        The world ticks every ``dt / realtime_factor`` seconds: step ``k``'s odometry goes
        out at its tick, and a command received before the tick of step ``k + 1`` is
        applied from there. The newest step's first odometry marks its tick, so ``now`` is
        before the tick of step ``k_a = k + 1 + floor(realtime_factor (now - then) / dt)``.
        The hosted agents' states are predicted from their measured steps to ``t_a = k_a
        dt`` through the commands they were sent (:class:`CommandHistory`); the other
        agents' at constant velocity (:func:`extrapolate`).

        :param q: the law's positions as measured (every agent).
        :param p: the law's velocities as measured.
        :param now: the time [s, monotonic].
        """
        sc, ids = self.sc, self.ids
        k_ref, then = self.reference
        k_apply = k_ref + 1 + max(0, math.floor(self.rate * (now - then) / sc.dt))
        t_apply = self.apply_at = k_apply * sc.dt
        x = self.x if self.plant is not None else np.concatenate([q, p], axis=1)
        t_measured = self.measured * sc.dt
        x_hat = extrapolate(self.dynamics, x, t_apply - t_measured)
        x_hat[ids] = self.history.predict(x[ids], t_measured[ids], t_apply)
        if self.plant is not None:
            self.x = x_hat
            return self.plant.law_state(x_hat)
        return x_hat[:, :sc.dim], x_hat[:, sc.dim:]

    def inputs(self, k: int) -> StepInputs | None:
        """Return the buffer of step ``k`` (``None`` for a step already answered).

        At most ``MAX_PENDING`` steps are buffered: the one farthest ahead (a forged or
        corrupted stamp, in lockstep) makes room.
        """
        if k <= self.answered:
            return None
        if k not in self.pending and len(self.pending) >= MAX_PENDING:
            del self.pending[max(self.pending)]
        return self.pending.setdefault(k, StepInputs())

    def offered_again(self, k: int) -> str | None:
        """Return what an input of step ``k``, a step already answered, calls for.

        :return: ``'repeat'`` when it is of the step answered last, the first time: the world
            offers a stalled step again, and the commands sent for it may have been lost, so
            they are sent again (once a step); ``'stale'`` for an older step (the input is
            rejected); ``None`` for the step already repeated.
        """
        if k != self.answered:
            return 'stale'
        if self.repeated == k:
            return None
        self.repeated = k
        return 'repeat'

    def leader_heard(self, k: int, now: float) -> None:
        """Note a leader message of step ``k``; a lost leader is back."""
        back = self.leader.heard(k, now)
        if self.waiting_since is not None:
            # A step waiting for the leader's state has half of it now: the timeout counts
            # from here, or its other half could be given up on the moment it is due.
            self.waiting_since = now
        if back:
            self.log.info(f'leader back at step {k}: informed agents track it again')

    def lose_leader(self, k: int) -> None:
        """Switch to the uninformed law (logged once per loss)."""
        if self.leader.lose(k):
            self.log.warning(f'no leader state for {self.leader_timeout:g} s at step {k}: the '
                             'uninformed law applies until it returns')

    def ready(self, k: int, now: float) -> bool:
        """Return whether step ``k`` can be answered: every odometry in, and the leader's
        state or its timeout (then the leader counts as lost)."""
        box = self.pending.get(k)
        if box is None or not box.has_odometry(self.sc.n_agents):
            return False
        if not box.has_leader and not self.leader.lost:
            if self.waiting_since is None:
                self.waiting_since = now
            # A leader not heard yet may still be matching the swarm's topics: it answers
            # its first tick only then, which can take longer than leader_timeout.
            patience = self.leader_timeout if self.leader.ever_heard \
                else self.leader_start_timeout
            if now - self.waiting_since < patience:
                return False
            self.lose_leader(k)
        self.waiting_since = None
        return True

    def waiting(self) -> int | None:
        """Return the step that waits for the leader's state, or ``None``."""
        return max(self.pending) if self.waiting_since is not None and self.pending else None

    def answer(self, k: int) -> np.ndarray:
        """Compute the commands of step ``k`` from its inputs, advance adaptive state.

        :param k: the step (every agent's odometry in; without the leader's state the
            uninformed law applies).
        :return: ``u`` of the hosted agents, shape ``(m, dim)``.
        """
        box = self.pending.pop(k)
        for old in [s for s in self.pending if s < k]:
            del self.pending[old]
        self.answered = k
        return self.command(*box.swarm(self.sc.n_agents, self.view), k=k)

    def realtime_answer(self, now: float) -> np.ndarray | None:
        """Realtime: return the commands for the latest known states (``None`` before every
        agent's odometry came in), predicted to the step the commands apply at unless
        ``latency`` is ``'off'`` (:meth:`predicted`); a leader silent for ``leader_timeout``
        is lost.

        :param now: the time [s, monotonic].
        """
        latest = self.latest
        if not latest.has_odometry(self.sc.n_agents):
            return None
        q, p, leader = latest.swarm(self.sc.n_agents, self.view)
        if self.predicting and self.reference is not None:
            q, p = self.predicted(q, p, now)
        if leader is not None and self.leader.silent_for(now) > self.leader_timeout:
            self.lose_leader(self.latest_step)
        u = self.command(q, p, None if self.leader.lost else leader, k=self.latest_step or 0)
        if self.apply_at is not None and not self.velocity:
            self.history.sent(self.apply_at, u)
        if self.net is not None:
            self.usage = self.net.usage(self.ids, q, p)
        return u

    def command(self, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                k: int = 0) -> np.ndarray:
        """Return ``u`` of the hosted agents for the swarm state ``(q, p)``; advance gains.

        :param k: the step the state is of (the law's time ``t = k dt``, and the step a
            fault names).
        :raises RunFault: when the law raised, returned the wrong shape, or (unless
            ``non_finite`` is ``'zero'``) a non-finite command (see the class).
        """
        law, ids, dt = self.sc.law, self.ids, self.sc.dt
        edges = interaction_graph(self.sc, self.real, q, self.static)
        if self.reselector is not None:
            self.reselector.update(self.swarm, edges)
        group = self.swarm.subset(ids)
        t, net = k * dt, self.net
        # The obstacle map is the scenario's; each agent uses the obstacles within its sensing
        # range r' only (core.obstacles.beta_term), from its own state.
        obstacles = self.sc.obstacles

        def alone(row: int) -> np.ndarray:
            one = ids[row:row + 1]
            return with_obstacles(obstacles, group_control(law, one, q, p, edges, leader,
                                                           self.swarm.subset(one), dt, t),
                                  q[one], p[one])
        if net is None:
            u = evaluate_law(law, k, ids, self.sc.dim,
                             lambda: with_obstacles(obstacles, group_control(
                                 law, ids, q, p, edges, leader, group, dt, t), q[ids], p[ids]),
                             alone)
        else:
            if k > net.step:
                # Realtime answers the same step again until newer odometry comes: its
                # messages were sent the first time.
                net.send(k, q, p, leader, edges, self.swarm.informed)
            u = evaluate_law(law, k, ids, self.sc.dim,
                             lambda: with_obstacles(obstacles, net.control(
                                 ids, q, p, group, dt, t)[0], q[ids], p[ids]))
        if group.state:
            self.state = {key: value.copy() for key, value in group.state.items()}
            if net is None:
                evaluate_state(law, k, ids, lambda: advance_state(
                    law, q[ids], p[ids], leader, group, dt,
                    lambda: group_sums(law, ids, q, p, edges), t))
            else:
                evaluate_state(law, k, ids, lambda: net.advance_state(ids, q, p, group, dt, t))
            for key, value in group.state.items():
                self.swarm.state[key][ids] = value
        self.zeroed = []
        if np.isfinite(u).all():
            return u
        bad = non_finite_rows(u)
        blew_up = state_blew_up(q, p, leader)
        if self.non_finite_policy == NON_FINITE_FAIL and not blew_up:
            self.non_finite.update(ids[bad].tolist())
            raise non_finite_fault(law, k, ids[bad])
        for i in ids[bad].tolist():
            if not self.non_finite[i]:
                self.log.warning(f'agent {i}: the law gave a non-finite command; a zero '
                                 'command is published instead (further ones are counted)')
            self.non_finite[i] += 1
        self.zeroed = [] if blew_up else ids[bad].tolist()
        return np.where(bad[:, None], 0.0, u)

    def state_values(self) -> np.ndarray:
        """Return :attr:`state` one row per hosted agent, the values of :attr:`state_labels`.

        :return: shape ``(m, len(state_labels))``.
        """
        m = len(self.ids)
        return np.concatenate([value.reshape(m, -1) for value in self.state.values()], axis=1)


class OdometryInbox(StepInbox):
    """Lockstep: every agent's odometry of a step, queued as serialised bytes and stored in
    the step's inputs at once once every agent's is in (:mod:`flock_swarm.nodes.inbox`):
    about a microsecond an agent instead of ten.
    """

    def __init__(self, controller: AgentController, guard: InputGuard, topics: Sequence[str],
                 children: Sequence[str]) -> None:
        """Create the inbox of ``controller``'s odometry.

        :param controller: the agents' controller (its scenario gives the agents).
        :param guard: the node's input guard.
        :param topics: every agent's odometry topic, by agent.
        :param children: every agent's ``child_frame_id``, by agent.
        """
        n = controller.sc.n_agents
        plant = controller.plant
        super().__init__(n, OdometryBatch(children,
                                          oriented=plant is not None and plant.oriented))
        self.controller, self.guard, self.topics = controller, guard, topics

    def put(self, sender: int, data: bytes) -> bool:
        """Queue agent ``sender``'s odometry; return whether every agent's is in: then take
        the queue."""
        super().put(sender, data)
        return len(self.queue) == self.size

    def take_step(self, queue: Sequence[tuple[int, bytes]]) -> int | None:
        """Store the odometry of ``queue`` at once when it is one step of every agent, the
        guard passes it and the step is not answered yet; return the step, or ``None``: then
        the caller handles the messages one by one.

        :param queue: the odometry taken (:meth:`take`).
        """
        decoded = self.decode(queue)
        if decoded is None:
            return None
        ns, states = decoded
        lim = self.guard.limits
        k = self.guard.pass_batch(self.topics, ns, ((states[:, 0], lim.position),
                                                    (states[:, 1], lim.velocity)))
        box = None if k is None else self.controller.inputs(k)
        if box is None:
            return None
        self.controller.latest_step = k
        box.put_all(np.ascontiguousarray(states[:, :, :self.controller.sc.dim]))
        return k
