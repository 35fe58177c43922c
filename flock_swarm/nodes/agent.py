"""The agent node: one robot computing its acceleration from its neighbours and the leader.

It subscribes to the odometry of every agent (one topic per agent, as real robots would
broadcast it), selects the neighbours within ``r`` (or the scenario's fixed graph), adds the
leader's state if informed, and calls the same law function as ``sim``
(:func:`flock_swarm.core.protocols.local_control`). The command is stamped with the odometry
stamp it answers. Adaptive state (Zhou's gain ``h_i``) lives here.
"""

import re
import sys
from dataclasses import dataclass, field

import numpy as np
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node

from flock_swarm.core.dynamics import LeaderState
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.protocols import advance_adaptive, local_control, local_neighbours
from flock_swarm.core.pseudo_leaders import Reselector
from flock_swarm.core.scenario import Scenario, all_pairs_weights, realize
from flock_swarm.nodes.common import (COMMON_PARAMS, LEADER_ACCEL, LEADER_ODOM, LOCKSTEP_QOS,
                                      StepClock, accel_vector, cmd_topic, declare,
                                      declare_common, load_scenario, make_accel, odom_topic,
                                      odometry_state, run_node, timer_period)


@dataclass
class StepInputs:
    """What an agent has received for one step."""

    odom: dict = field(default_factory=dict)
    leader_odom: tuple | None = None
    leader_accel: np.ndarray | None = None


class AgentController:
    """The decision logic of agent ``i`` (no ROS): collect a step's inputs, answer it once.

    :ivar answered: the last step answered (``-1`` before the first).
    """

    def __init__(self, sc: Scenario, agent_id: int) -> None:
        """Create the controller of agent ``agent_id`` of scenario ``sc``."""
        if not 0 <= agent_id < sc.n_agents:
            raise ScenarioError('agent_id', f'must be in [0, {sc.n_agents - 1}] '
                                f'(n_agents = {sc.n_agents}), got {agent_id}')
        self.sc = sc
        self.i = agent_id
        real = realize(sc)
        self.weights = real.adjacency
        # The whole swarm's law data: re-selecting pseudo-leaders needs everybody's flags.
        self.swarm = real.agents
        self.reselector = Reselector(sc.law) if sc.informed.reselect and \
            self.weights is None else None
        self.pending: dict[int, StepInputs] = {}
        self.answered = -1

    @property
    def informed(self) -> bool:
        """Return whether this agent currently gets the leader's information."""
        return bool(self.swarm.informed[self.i])

    def inputs(self, k: int) -> StepInputs | None:
        """Return the buffer of step ``k`` (``None`` for a step already answered)."""
        if k <= self.answered:
            return None
        return self.pending.setdefault(k, StepInputs())

    def ready(self, k: int) -> bool:
        """Return whether step ``k`` has every agent's odometry and the leader's state."""
        box = self.pending.get(k)
        return (box is not None and len(box.odom) == self.sc.n_agents
                and box.leader_odom is not None and box.leader_accel is not None)

    def answer(self, k: int) -> np.ndarray:
        """Compute the command of step ``k`` from its complete inputs, advance adaptive state.

        :param k: the step (must be :meth:`ready`).
        :return: ``u_i``.
        """
        box = self.pending.pop(k)
        for old in [s for s in self.pending if s < k]:
            del self.pending[old]
        self.answered = k
        q = np.array([box.odom[j][0] for j in range(self.sc.n_agents)])
        p = np.array([box.odom[j][1] for j in range(self.sc.n_agents)])
        leader = LeaderState(box.leader_odom[0], box.leader_odom[1], box.leader_accel)
        return self.command(q, p, leader)

    def command(self, q: np.ndarray, p: np.ndarray, leader: LeaderState) -> np.ndarray:
        """Return ``u_i`` for the swarm state ``(q, p)`` and advance the adaptive gain."""
        law, i = self.sc.law, self.i
        if self.reselector is not None:
            edges = all_pairs_weights(q.shape[0], None, q, law) if law.all_pairs \
                else disk_graph(q, law.radius, law.strict_radius)
            self.reselector.update(self.swarm, edges)
        ids, w = local_neighbours(law, i, q, self.weights)
        own = self.swarm.subset(np.array([i]))
        u = local_control(law, q[i], p[i], q[ids], p[ids], w, leader, own, self.sc.dt)
        if own.adaptive is not None:
            advance_adaptive(law, q[i:i + 1], p[i:i + 1], leader, own, self.sc.dt)
            self.swarm.adaptive[i] = own.adaptive[0]
        return u


class AgentNode(Node):
    """Agent ``agent_id``: odometry of all agents and the leader in, ``cmd_accel`` out."""

    def __init__(self, **kwargs) -> None:
        """Create the node; ``kwargs`` go to :class:`rclpy.node.Node` (context, namespace...)."""
        kwargs.setdefault('automatically_declare_parameters_from_overrides', True)
        name = kwargs.pop('node_name', None)
        super().__init__(name or 'agent', **kwargs)
        declare_common(self)
        agent_id = declare(self, 'agent_id', 0, 'index i of this agent (0-based)')
        if not isinstance(agent_id, int):
            raise ScenarioError('agent_id', f'expected an integer, got {agent_id!r}')
        sc = load_scenario(self, COMMON_PARAMS | {'agent_id'})
        self.scenario = sc
        self.controller = AgentController(sc, agent_id)
        self.clock = StepClock(sc.dt)
        self.lockstep = self.get_parameter('mode').value == 'lockstep'
        self.cmd_pub = self.create_publisher(AccelStamped, cmd_topic(agent_id), LOCKSTEP_QOS)
        for j in range(sc.n_agents):
            self.create_subscription(Odometry, odom_topic(j),
                                     lambda msg, j=j: self.on_odom(j, msg), LOCKSTEP_QOS)
        self.create_subscription(Odometry, LEADER_ODOM, self.on_leader_odom, LOCKSTEP_QOS)
        self.create_subscription(AccelStamped, LEADER_ACCEL, self.on_leader_accel,
                                 LOCKSTEP_QOS)
        self.latest: StepInputs = StepInputs()
        self.latest_stamp = None
        self.outbox: list[AccelStamped] = []
        if self.lockstep:
            self.create_timer(0.01, self.flush)
        else:
            self.create_timer(timer_period(self, sc.dt), self.on_timer)

    def on_odom(self, j: int, msg: Odometry) -> None:
        """Store agent ``j``'s odometry for its step."""
        state = odometry_state(msg, self.scenario.dim)
        self.latest.odom[j] = state
        if j == self.controller.i:
            self.latest_stamp = msg.header.stamp
        self.stash(msg.header.stamp, lambda box: box.odom.__setitem__(j, state))

    def on_leader_odom(self, msg: Odometry) -> None:
        """Store the leader's position and velocity for its step."""
        state = odometry_state(msg, self.scenario.dim)
        self.latest.leader_odom = state
        self.stash(msg.header.stamp, lambda box: setattr(box, 'leader_odom', state))

    def on_leader_accel(self, msg: AccelStamped) -> None:
        """Store the leader's acceleration ``f_gamma`` for its step."""
        a = accel_vector(msg, self.scenario.dim)
        self.latest.leader_accel = a
        self.stash(msg.header.stamp, lambda box: setattr(box, 'leader_accel', a))

    def stash(self, stamp, store) -> None:
        """Lockstep: put an input into the buffer of its stamp's step, answer if complete."""
        if self.lockstep:
            k = self.clock.step_of(stamp)
            box = self.controller.inputs(k)
            if box is not None:
                store(box)
                self.try_answer(k)

    def try_answer(self, k: int) -> None:
        """Publish the command of step ``k`` once its inputs are complete."""
        if self.controller.ready(k):
            u = self.controller.answer(k)
            self.outbox.append(make_accel(u, self.clock.stamp(k)))
            self.flush()

    def flush(self) -> None:
        """Publish queued commands once the world's subscription is matched.

        A command published before the match would be lost and cost the world a timeout.
        """
        if self.outbox and self.cmd_pub.get_subscription_count() > 0:
            for msg in self.outbox:
                self.cmd_pub.publish(msg)
            self.outbox.clear()

    def on_timer(self) -> None:
        """Realtime mode: answer with the latest known states (zero-order hold)."""
        latest, n = self.latest, self.scenario.n_agents
        if len(latest.odom) < n or latest.leader_odom is None or latest.leader_accel is None:
            return
        q = np.array([latest.odom[j][0] for j in range(n)])
        p = np.array([latest.odom[j][1] for j in range(n)])
        leader = LeaderState(latest.leader_odom[0], latest.leader_odom[1], latest.leader_accel)
        u = self.controller.command(q, p, leader)
        self.cmd_pub.publish(make_accel(u, self.latest_stamp))


def main(args: list[str] | None = None) -> int:
    """Run one agent node (``ros2 run flock_swarm agent --ros-args -p agent_id:=3``).

    The node is named ``agent_<id>`` unless remapped with ``__node:=``.
    """
    argv = sys.argv if args is None else args
    found = [m.group(1) for a in argv for m in [re.search(r'^agent_id:=(\d+)$', a)] if m]
    name = f'agent_{found[-1]}' if found else 'agent'
    return run_node('agent', lambda: AgentNode(node_name=name), args)


if __name__ == '__main__':
    sys.exit(main())
