"""The agent node: robots computing their accelerations from their neighbours and the leader.

An agent node subscribes to the odometry of every agent (one topic per agent, as real robots
would broadcast it), selects the neighbours within ``r`` (or the scenario's fixed graph), adds
the leader's state if informed, and calls the same law functions as ``sim``
(:func:`flock_swarm.core.protocols.group_control`). Each command is stamped with the
odometry stamp it answers. Adaptive state (Zhou's gain ``h_i``) lives here.

One node hosts one agent (``ros2 run flock_swarm agent --ros-args -p agent_id:=3``, the
robot's own process) or many (``ros2 run flock_swarm agents``, a container): the hosted
agents share one subscription per odometry topic and one evaluation of the law per step, so
a step costs ``N`` odometry deliveries per container instead of ``N`` per agent. Each hosted
agent still publishes on its own ``agent_<i>/cmd_accel``.
"""

import re
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node

from flock_swarm.core.dynamics import LeaderState
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.protocols import advance_adaptive, group_control
from flock_swarm.core.pseudo_leaders import Reselector
from flock_swarm.core.run import interaction_graph, static_graph
from flock_swarm.core.scenario import Scenario, realize
from flock_swarm.nodes.common import (COMMON_PARAMS, LEADER_ACCEL, LEADER_ODOM, LOCKSTEP_QOS,
                                      StepClock, claimants, cmd_topic, declare, declare_common,
                                      load_scenario, odom_topic, run_node, timer_period)
from flock_swarm.nodes.guard import LIMIT_PARAMS, InputGuard, declare_limits
from flock_swarm.nodes.wire import AccelEncoder, MalformedMessage, decode_accel, decode_odometry

#: Steps an agent buffers inputs for at once (lockstep needs two: the open step and the next).
MAX_PENDING = 8

AGENT_PARAMS = COMMON_PARAMS | LIMIT_PARAMS | {'agent_id', 'agent_ids', 'leader_timeout',
                                               'leader_start_timeout'}


@dataclass
class StepInputs:
    """What the hosted agents have received for one step."""

    odom: dict = field(default_factory=dict)
    leader_odom: tuple | None = None
    leader_accel: np.ndarray | None = None

    def has_odometry(self, n_agents: int) -> bool:
        """Return whether every agent's odometry is in."""
        return len(self.odom) == n_agents

    @property
    def has_leader(self) -> bool:
        """Return whether the leader's state (odometry and acceleration) is in."""
        return self.leader_odom is not None and self.leader_accel is not None

    def swarm(self, n_agents: int) -> tuple[np.ndarray, np.ndarray, LeaderState | None]:
        """Return ``(q, p, leader)`` (``leader`` ``None`` when it is not in)."""
        odom = self.odom
        qp = np.array([odom[j] for j in range(n_agents)])
        leader = LeaderState(np.array(self.leader_odom[0]), np.array(self.leader_odom[1]),
                             np.array(self.leader_accel)) if self.has_leader else None
        return qp[:, 0], qp[:, 1], leader


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

    :ivar answered: the last step answered (``-1`` before the first).
    """

    def __init__(self, sc: Scenario, ids: Sequence[int]) -> None:
        """Create the controller of agents ``ids`` (ascending, distinct) of scenario ``sc``."""
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
        return self.command(*box.swarm(self.sc.n_agents))

    def command(self, q: np.ndarray, p: np.ndarray, leader: LeaderState | None) -> np.ndarray:
        """Return ``u`` of the hosted agents for the swarm state ``(q, p)``; advance gains."""
        law, ids = self.sc.law, self.ids
        edges = interaction_graph(self.sc, self.real, q, self.static)
        if self.reselector is not None:
            self.reselector.update(self.swarm, edges)
        group = self.swarm.subset(ids)
        u = group_control(law, ids, q, p, edges, leader, group, self.sc.dt)
        if group.adaptive is not None:
            advance_adaptive(law, q[ids], p[ids], leader, group, self.sc.dt)
            self.swarm.adaptive[ids] = group.adaptive
        return u


class AgentNode(Node):
    """Hosts agents (one by default): odometry of all agents and the leader in, commands out."""

    def __init__(self, default_agent_ids: str = '', **kwargs) -> None:
        """Create the node.

        :param default_agent_ids: the ``agent_ids`` default (``'all'`` for the container).
        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        kwargs.setdefault('automatically_declare_parameters_from_overrides', True)
        name = kwargs.pop('node_name', None)
        super().__init__(name or 'agent', **kwargs)
        declare_common(self)
        agent_id = declare(self, 'agent_id', 0, 'index i of this agent (0-based)')
        if not isinstance(agent_id, int) or isinstance(agent_id, bool):
            raise ScenarioError('agent_id', f'expected an integer, got {agent_id!r}')
        spec = declare(self, 'agent_ids', default_agent_ids,
                       "agents this node hosts: '' (agent_id alone), 'all', ids and ranges "
                       "such as '0-9,12', or an integer array")
        sc = load_scenario(self, AGENT_PARAMS)
        self.scenario = sc
        self.controller = AgentController(sc, parse_agent_ids(spec, agent_id, sc.n_agents))
        self.clock = StepClock(sc.dt)
        self.lockstep = self.get_parameter('mode').value == 'lockstep'
        self.leader_timeout = declare(
            self, 'leader_timeout', 1.0, 'seconds without the leader state (lockstep: for a '
            'step whose odometry is complete) before the agents apply the uninformed law, '
            'until it returns; below the world step_timeout')
        if isinstance(self.leader_timeout, bool) or \
                not isinstance(self.leader_timeout, (int, float)) or self.leader_timeout <= 0:
            raise ScenarioError('leader_timeout', f'must be > 0, got {self.leader_timeout!r}')
        self.leader_start_timeout = declare(
            self, 'leader_start_timeout', 30.0, 'lockstep: seconds to wait for the leader\'s '
            'first state (it answers its first tick only once every node has matched its '
            'topics, up to its own start_timeout) before the agents apply the uninformed law')
        if not self.leader_start_timeout > 0:
            raise ScenarioError('leader_start_timeout',
                                f'must be > 0, got {self.leader_start_timeout!r}')
        self.leader_ever_heard = False
        self.guard = InputGuard(self.clock, declare_limits(self), self.get_logger().warning)
        self.cmd_pubs = [self.create_publisher(AccelStamped, cmd_topic(int(i)), LOCKSTEP_QOS)
                         for i in self.controller.ids]
        # Raw subscriptions: the bytes are decoded by flock_swarm.nodes.wire (see there why).
        self.odom_topics = [odom_topic(j) for j in range(sc.n_agents)]
        self.children = [f'agent_{j}' for j in range(sc.n_agents)]
        for j in range(sc.n_agents):
            self.create_subscription(Odometry, odom_topic(j),
                                     lambda data, j=j: self.on_odom(j, data), LOCKSTEP_QOS,
                                     raw=True)
        self.create_subscription(Odometry, LEADER_ODOM, self.on_leader_odom, LOCKSTEP_QOS,
                                 raw=True)
        self.create_subscription(AccelStamped, LEADER_ACCEL, self.on_leader_accel,
                                 LOCKSTEP_QOS, raw=True)
        self.latest: StepInputs = StepInputs()
        self.latest_stamp: int | None = None
        self.encoder = AccelEncoder()
        self.outbox: list[tuple[int, bytes]] = []
        self.matched = [False] * len(self.cmd_pubs)
        self.sent: list[tuple[int, bytes]] = []
        self.repeated = -1
        self.leader_lost = False
        self.leader_seen_at = time.monotonic()
        self.waiting_since: float | None = None
        self.duplicates: set[int] = set()
        self.create_timer(1.0, self.check_claims)
        if self.lockstep:
            self.create_timer(0.01, self.on_lockstep_timer)
        else:
            self.create_timer(timer_period(self, sc.dt), self.on_timer)

    # -- inputs -------------------------------------------------------------------------------

    def on_odom(self, j: int, data: bytes) -> None:
        """Check and store agent ``j``'s odometry (serialised) for its step."""
        checked = self.check_odometry(self.odom_topics[j], data, self.children[j])
        if checked is None:
            return
        k, state = checked
        self.latest.odom[j] = state
        self.latest_stamp = self.clock.ns(k)
        if self.lockstep:
            box = self.controller.inputs(k)
            if box is None:
                self.answered_again(k, self.odom_topics[j])
            else:
                box.odom[j] = state
                self.try_answer(k)

    def check_odometry(self, topic: str, data: bytes,
                       child: str) -> tuple[int, tuple[tuple, tuple]] | None:
        """Return the step and ``(q, p)`` of an acceptable odometry message, or ``None``."""
        try:
            ns, frame, child_id, pos, vel = decode_odometry(data)
        except MalformedMessage as exc:
            self.guard.reject(topic, 'malformed', str(exc))
            return None
        lim = self.guard.limits
        k = self.guard.check(topic, ns, frame, ((pos, lim.position), (vel, lim.velocity)),
                             (child_id, child), ordered=not self.lockstep)
        if k is None:
            return None
        dim = self.scenario.dim
        return k, (pos[:dim], vel[:dim])

    def on_leader_odom(self, data: bytes) -> None:
        """Check and store the leader's position and velocity (serialised) for its step."""
        checked = self.check_odometry(LEADER_ODOM, data, 'leader')
        if checked is None:
            return
        k, state = checked
        self.leader_heard(k)
        self.latest.leader_odom = state
        self.stash(k, lambda box: setattr(box, 'leader_odom', state), LEADER_ODOM)

    def on_leader_accel(self, data: bytes) -> None:
        """Check and store the leader's acceleration ``f_gamma`` (serialised) for its step."""
        try:
            ns, frame, lin = decode_accel(data)
        except MalformedMessage as exc:
            self.guard.reject(LEADER_ACCEL, 'malformed', str(exc))
            return
        k = self.guard.check(LEADER_ACCEL, ns, frame, ((lin, self.guard.limits.accel),),
                             ordered=not self.lockstep)
        if k is None:
            return
        self.leader_heard(k)
        a = lin[:self.scenario.dim]
        self.latest.leader_accel = a
        self.stash(k, lambda box: setattr(box, 'leader_accel', a), LEADER_ACCEL)

    # -- the leader lost and found --------------------------------------------------------------

    def leader_heard(self, k: int) -> None:
        """Note a leader message of step ``k``; a lost leader is back."""
        self.leader_seen_at = time.monotonic()
        self.leader_ever_heard = True
        if self.waiting_since is not None:
            # A step waiting for the leader's state has half of it now: the timeout counts
            # from here, or its other half could be given up on the moment it is due.
            self.waiting_since = self.leader_seen_at
        if self.leader_lost:
            self.leader_lost = False
            self.get_logger().info(f'leader back at step {k}: informed agents track it again')

    def lose_leader(self, k: int) -> None:
        """Switch to the uninformed law (logged once per loss)."""
        if not self.leader_lost:
            self.leader_lost = True
            self.get_logger().warning(
                f'no leader state for {self.leader_timeout:g} s at step {k}: the uninformed '
                'law applies until it returns')

    # -- lockstep -------------------------------------------------------------------------------

    def stash(self, k: int, store, topic: str) -> None:
        """Lockstep: put an input into the buffer of step ``k``, answer if complete."""
        if not self.lockstep:
            return
        box = self.controller.inputs(k)
        if box is None:
            self.answered_again(k, topic)
        else:
            store(box)
            self.try_answer(k)

    def answered_again(self, k: int, topic: str) -> None:
        """An input for step ``k``, already answered: repeat the commands once if the world
        offers that step again, else reject the input as stale."""
        if k == self.controller.answered:
            if self.repeated != k:
                # The world offers a stalled step again: our commands may have been lost.
                self.repeated = k
                self.outbox.extend(self.sent)
                self.flush()
        else:
            self.guard.reject(topic, 'stale_stamp',
                              f'stamp of step {k} after step {self.controller.answered} was '
                              'answered')

    def try_answer(self, k: int) -> None:
        """Answer step ``k`` once every odometry is in, and the leader's state or its timeout."""
        box = self.controller.pending.get(k)
        if box is None or not box.has_odometry(self.scenario.n_agents):
            return
        if not box.has_leader and not self.leader_lost:
            now = time.monotonic()
            if self.waiting_since is None:
                self.waiting_since = now
            # A leader not heard yet may still be matching the swarm's topics: it answers
            # its first tick only then, which can take longer than leader_timeout.
            patience = self.leader_timeout if self.leader_ever_heard \
                else self.leader_start_timeout
            if now - self.waiting_since < patience:
                return
            self.lose_leader(k)
        self.waiting_since = None
        self.publish_commands(self.controller.answer(k), self.clock.ns(k))

    def on_lockstep_timer(self) -> None:
        """Answer a step that waits for the leader once its timeout is over; send the queue."""
        if self.waiting_since is not None and self.controller.pending:
            self.try_answer(max(self.controller.pending))
        self.flush()

    def publish_commands(self, u: np.ndarray, stamp_ns: int) -> None:
        """Queue one command per hosted agent (serialised) and send what the world can
        receive."""
        encode = self.encoder.encode
        self.sent = [(row, encode(stamp_ns, a)) for row, a in enumerate(u.tolist())]
        self.outbox.extend(self.sent)
        self.flush()

    def flush(self) -> None:
        """Publish queued commands whose topic the world's subscription has matched.

        A command published before the match would be lost and cost the world a timeout.
        A topic once matched is not asked again (the question costs more than the publish):
        should the world go and come back, it offers its open step again and gets the
        commands repeated (see :meth:`answered_again`).
        """
        if not self.outbox:
            return
        waiting, matched = [], self.matched
        for row, msg in self.outbox:
            pub = self.cmd_pubs[row]
            if matched[row] or pub.get_subscription_count() > 0:
                matched[row] = True
                pub.publish(msg)
            else:
                waiting.append((row, msg))
        self.outbox = waiting

    # -- realtime and housekeeping ---------------------------------------------------------------

    def on_timer(self) -> None:
        """Realtime mode: answer with the latest known states (zero-order hold)."""
        latest = self.latest
        if not latest.has_odometry(self.scenario.n_agents):
            return
        q, p, leader = latest.swarm(self.scenario.n_agents)
        if leader is not None and time.monotonic() - self.leader_seen_at > self.leader_timeout:
            self.lose_leader(self.clock.step_at(self.latest_stamp))
        if self.leader_lost:
            leader = None
        self.publish_commands(self.controller.command(q, p, leader), self.latest_stamp)

    def check_claims(self) -> None:
        """Report another node publishing commands for one of our agents (a duplicate id)."""
        me = (self.get_namespace(), self.get_name())
        for i in self.controller.ids:
            others = [f'{ns.rstrip("/")}/{name}' for ns, name in claimants(self, int(i))
                      if (ns, name) != me]
            if others and i not in self.duplicates:
                self.duplicates.add(int(i))
                self.get_logger().error(f'agent_id {i} is also claimed by {", ".join(others)}: '
                                        'two nodes command the same agent')

    def close(self) -> None:
        """Log what was rejected (called on shutdown)."""
        if self.guard.rejected:
            self.get_logger().warning(f'rejected inputs: {self.guard.counts()}')


def main(args: list[str] | None = None) -> int:
    """Run one agent node (``ros2 run flock_swarm agent --ros-args -p agent_id:=3``).

    The node is named ``agent_<id>`` unless remapped with ``__node:=``.
    """
    argv = sys.argv if args is None else args
    found = [m.group(1) for a in argv for m in [re.search(r'^agent_id:=(\d+)$', a)] if m]
    name = f'agent_{found[-1]}' if found else 'agent'
    return run_node('agent', lambda: AgentNode(node_name=name), args)


def container_main(args: list[str] | None = None) -> int:
    """Run a container hosting many agents (``ros2 run flock_swarm agents``).

    It hosts every agent of the scenario unless ``-p agent_ids:='0-49'`` says otherwise; the
    node is named ``agents``.
    """
    return run_node('agents', lambda: AgentNode(default_agent_ids='all', node_name='agents'),
                    args)


if __name__ == '__main__':
    sys.exit(main())
