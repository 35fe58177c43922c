"""The agent node: robots computing their accelerations from their neighbours and the leader.

An agent node subscribes to the odometry of every agent (one topic per agent, as real robots
would broadcast it), selects the neighbours within ``r`` (or the scenario's fixed graph), adds
the leader's state if informed, and calls the same law functions as ``sim``
(:func:`flock_swarm.core.laws.evaluation.group_control`). Each command is stamped with the
odometry stamp it answers. The decisions, and the adaptive state (Zhou's gain ``h_i``), are
those of :class:`~flock_swarm.nodes.controller.AgentController` (no ROS); this node is its
plumbing. A law that raises, returns the wrong shape or a non-finite command fails the run:
the node reports it to the world on ``swarm/faults``
(:class:`~flock_swarm.nodes.fault_report.FaultReporter`), logs one line and exits with
status 1. With ``non_finite:=zero`` a non-finite command is published as zero instead
(counted, logged, reported to the world, which counts it per agent). For a
law with adaptive state, each agent publishes the state its command was computed with on
``agent_<i>/state`` (``sensor_msgs/JointState``, stamped like the command and sent before it),
so the world records what ``sim`` records. In realtime mode with a ``network:`` section each
agent also reports, before each command, what the command used on ``agent_<i>/network``
(``sensor_msgs/JointState``, stamped like the command, names
:data:`~flock_swarm.core.network.USAGE_LABELS`): the world adds the real transport's age.

One node hosts one agent (``ros2 run flock_swarm agent --ros-args -p agent_id:=3``, the
robot's own process) or many (``ros2 run flock_swarm agents``, a container): the hosted
agents share one subscription per odometry topic and one evaluation of the law per step, so
a step costs ``N`` odometry deliveries per container instead of ``N`` per agent. Each hosted
agent still publishes on its own ``agent_<i>/cmd_accel``.

A robot plant (``plant:``, docs/plants.md) commanded by velocity (``cmd_vel``, the scenario's
``plant.command`` or the node's ``command`` parameter) also publishes its velocity command,
converted from the law's acceleration by the plant's own ``command`` and ``twist`` (the
core's, as in ``sim``), as ``geometry_msgs/Twist`` on ``agent_<i>/cmd_vel``: once per step,
never repeated (it carries no stamp: the world takes it as the open step's).

With ``transport: batched`` (:mod:`flock_swarm.nodes.transport`) a node takes the world's
one ``swarm/states`` message a step instead of the odometry topics, and publishes its agents'
commands (adaptive states, velocity commands) as one ``swarm/commands`` message: the same
controller on the same numbers (docs/ros.md, "Transports").

In realtime the agents act on every state predicted to the world's tick their commands apply
at (``latency:=predict``, the default; :meth:`AgentController.predicted
<flock_swarm.nodes.controller.AgentController.predicted>`, docs/robots.md): the hosted agents'
through the commands they were sent, the others' at constant velocity. In lockstep the states
are current and the prediction is the identity.
"""

import dataclasses
import re
import sys
import time

import numpy as np
from geometry_msgs.msg import AccelStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState, PointCloud2

from flock_swarm.contract import (agent_name, LEADER_ACCEL, LEADER_ODOM, LOCKSTEP_QOS, cmd_topic,
                                  cmd_vel_topic, network_topic, odom_topic, qos_profile,
                                  state_topic)
from flock_swarm.core.faults import RunFault, non_finite_fault
from flock_swarm.core.latency import LATENCY_CHOICES, LATENCY_PREDICT
from flock_swarm.core.network_stats import USAGE_LABELS
from flock_swarm.core.plants.base import COMMANDS
from flock_swarm.core.plants.spec import command_interface
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.controller import (NON_FINITE_FAIL, NON_FINITE_ZERO, AgentController,
                                          OdometryInbox, parse_agent_ids)
from flock_swarm.nodes.batch import (MESSAGE_PATH, BatchPublish, BatchTake, release,
                                     use_c_path)
from flock_swarm.nodes.fault_report import FaultReporter
from flock_swarm.nodes.ros_graph import check_claims, follow_world
from flock_swarm.nodes.guard import LIMIT_PARAMS, InputGuard, Limits
from flock_swarm.nodes.parameters import (COMMON_PARAMS, KEEP_RUNNING, NodeParameters, Param,
                                          init_node)
from flock_swarm.nodes.spin import run_node, wall_timer
from flock_swarm.nodes.cloud import (BATCHED, COMMANDS as COMMAND_CLOUDS, STATES, CloudEncoder,
                                     command_fields)
from flock_swarm.nodes.transport import TRANSPORT, StateCloud, host_commands, transport_of
from flock_swarm.nodes.wire import (AccelBatchEncoder, AccelEncoder, MalformedMessage,
                                    StateEncoder, decode_accel, decode_heading,
                                    decode_odometry, encode_twist)


def _timeout(name: str, default: float, description: str) -> Param:
    """Return one of the agents' timeouts [s], which must be > 0."""
    return Param(name, default, description, lambda v: v > 0, 'must be > 0, got {value!r}')


#: The ``agent_ids`` parameter (its default is the node's: ``all`` for the container).
AGENT_IDS = Param('agent_ids', '', "agents this node hosts: '' (agent_id alone), 'all', ids "
                  "and ranges such as '0-9,12', or an integer array (reads back as the ids "
                  'hosted)', free_typed=True)
#: The agents' parameters, in the order they are read and checked.
AGENT_PARAMS = COMMON_PARAMS + (
    Param('agent_id', 0, 'index i of this agent (0-based); reads back -1 in a node hosting '
          'several agents (agent_ids lists them)'),
    AGENT_IDS,
    _timeout('leader_timeout', 1.0, 'seconds without the leader state (lockstep: for a step '
             'whose odometry is complete) before the agents apply the uninformed law, until '
             'it returns; below the world step_timeout'),
    _timeout('leader_start_timeout', 30.0, 'lockstep: seconds to wait for the leader\'s first '
             'state (it answers its first tick only once every node has matched its topics, up '
             'to its own start_timeout) before the agents apply the uninformed law'),
    Param('non_finite', NON_FINITE_FAIL, "a non-finite command of the law: 'fail' ends the run "
          "(reported to the world on swarm/faults, the node exits with status 1); 'zero' "
          'publishes a zero command instead and goes on (counted, reported)',
          lambda v: v in (NON_FINITE_FAIL, NON_FINITE_ZERO),
          "must be 'fail' or 'zero', got {value!r}"),
    Param('command', '', "the command interface: '' (the scenario's plant.command), accel "
          '(cmd_accel only) or cmd_vel (a robot plant: Twist on cmd_vel too)',
          lambda v: v in ('', *COMMANDS), "must be '', 'accel' or 'cmd_vel', got {value!r}"),
    Param('latency', LATENCY_PREDICT, "realtime: 'predict' acts on each agent's state "
          'predicted to the step its command applies at (its own through the commands it was '
          "sent, the others' at constant velocity; docs/robots.md); 'off' on the states as "
          'measured. Lockstep states are current: no effect',
          lambda v: v in LATENCY_CHOICES, "must be 'predict' or 'off', got {value!r}"),
) + LIMIT_PARAMS + (KEEP_RUNNING, MESSAGE_PATH, TRANSPORT)


class AgentNode(Node):
    """Hosts agents (one by default): odometry of all agents and the leader in, commands out."""

    def __init__(self, default_agent_ids: str = '', **kwargs) -> None:
        """Create the node.

        :param default_agent_ids: the ``agent_ids`` default (``'all'`` for the container).
        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        name = kwargs.pop('node_name', None)
        init_node(super().__init__, name or 'agent', kwargs)
        table = tuple(dataclasses.replace(param, default=default_agent_ids)
                      if param is AGENT_IDS else param for param in AGENT_PARAMS)
        params = self.params = NodeParameters(self, table)
        sc = self.scenario = params.load_scenario()
        ids = parse_agent_ids(params['agent_ids'], params['agent_id'], sc.n_agents)
        params.declare(agent_ids=ids.tolist(), agent_id=int(ids[0]) if ids.size == 1 else -1)
        # A robot plant's velocity commands (cmd_vel), one topic per hosted agent.
        self.velocity = command_interface(sc, params['command']) == 'cmd_vel'
        # The batched transport (nodes/transport.py): the swarm's state as one message in, the
        # hosted agents' commands (and adaptive states) as one message out.
        self.batched = transport_of(sc, params['transport'], params['mode']) == BATCHED
        self.controller = AgentController(sc, ids, self.get_logger(),
                                          leader_timeout=params['leader_timeout'],
                                          leader_start_timeout=params['leader_start_timeout'],
                                          non_finite=params['non_finite'],
                                          latency=params['latency'],
                                          realtime_factor=params['realtime_factor'],
                                          velocity=self.velocity)
        self.reporter = FaultReporter(self)
        #: The line of the fault that ended this node's part of the run, or ``None``.
        self.failure: str | None = None
        self.clock = StepClock(sc.dt)
        self.lockstep = params['mode'] == 'lockstep'
        # Lockstep on the compiled path (flock_swarm.nodes.batch): a step's odometry is taken
        # at once from its first message's callback, the commands published at once.
        self.c_path = use_c_path(params['message_path']) and self.lockstep
        self.guard = InputGuard(self.clock, Limits.from_parameters(params.values),
                                self.get_logger().warning)
        # The hosted agents' odometry carries a heading (an oriented plant's).
        plant = self.controller.plant
        self.oriented = plant is not None and plant.oriented
        qos = qos_profile(LOCKSTEP_QOS)
        self._create_publishers(qos)
        self._create_subscriptions(qos)
        self.encoder = AccelBatchEncoder(len(self.cmd_pubs))
        self.outbox: list[tuple[int, bytes]] = []
        self.matched = [False] * len(self.pubs)
        # Every topic matched once: flush sends the outbox as it is.
        self.all_matched = False
        self.sent: list[tuple[int, bytes]] = []
        self.duplicates: set[int] = set()
        wall_timer(self, 1.0, self.check_claims)
        self.world_finished = follow_world(self, params['keep_running'])
        if self.lockstep:
            wall_timer(self, 0.01, self.on_lockstep_timer)
        else:
            wall_timer(self, params.timer_period(sc.dt), self.on_timer)

    def _create_publishers(self, qos) -> None:
        """Create the publishers :meth:`publish_commands` sends on (``self.pubs``): per hosted
        agent its command, adaptive state, network usage and velocity command, or the batched
        transport's one command cloud."""
        # The hosted agents' own topics (none with the batched transport).
        hosted = [] if self.batched else self.controller.ids
        self.cmd_pubs = [self.create_publisher(AccelStamped, cmd_topic(int(i)), qos)
                         for i in hosted]
        # A law's adaptive state, one topic per hosted agent (none for a law without).
        self.state_pubs = [self.create_publisher(JointState, state_topic(int(i)), qos)
                           for i in hosted] if self.controller.state else []
        self.state_encoder = StateEncoder(self.controller.state_labels)
        # Realtime with the network model: what each command used (docs/network.md).
        self.usage_pubs = [self.create_publisher(JointState, network_topic(int(i)), qos)
                           for i in hosted] \
            if self.controller.net is not None and not self.lockstep else []
        self.usage_encoder = StateEncoder(USAGE_LABELS)
        self.twist_pubs = [self.create_publisher(Twist, cmd_vel_topic(int(i)), qos)
                           for i in hosted] if self.velocity else []
        # What publish_commands sends on: the commands (row i: hosted agent i), states, usage,
        # velocity commands.
        self.pubs = self.cmd_pubs + self.state_pubs + self.usage_pubs + self.twist_pubs
        if self.batched:
            self.pubs = [self.create_publisher(PointCloud2, COMMAND_CLOUDS, qos)]
            self.cloud_out = CloudEncoder(command_fields(self.scenario.dim,
                                                         self.controller.state_labels,
                                                         self.velocity))

    def _create_subscriptions(self, qos) -> None:
        """Subscribe to the swarm's state (every agent's odometry, or the batched transport's
        state cloud) and the leader's, raw; hold the compiled path's take and publish."""
        sc = self.scenario
        if self.batched:
            self.states_in = StateCloud(sc.n_agents, sc.dim, self.oriented, self.guard)
            self.states_topic = self.create_subscription(PointCloud2, STATES, self.on_states,
                                                         qos, raw=True).topic_name
        # Raw subscriptions: the bytes are decoded by flock_swarm.nodes.wire (see there why).
        self.odom_topics = [odom_topic(j) for j in range(sc.n_agents)]
        self.children = [agent_name(j) for j in range(sc.n_agents)]
        # Lockstep: a step's odometry, queued as it comes, then taken in one pass.
        per_agent = not self.batched
        self.inbox = OdometryInbox(self.controller, self.guard, self.odom_topics,
                                   self.children if per_agent else [])
        odom_subs = [self.create_subscription(Odometry, odom_topic(j),
                                              lambda data, j=j: self.on_odom(j, data), qos,
                                              raw=True)
                     for j in range(sc.n_agents if per_agent else 0)]
        self.odom_take = BatchTake(odom_subs) if self.c_path and per_agent else None
        self.batch_out = BatchPublish(self.pubs) if self.c_path else None
        self.create_subscription(Odometry, LEADER_ODOM, self.on_leader_odom, qos, raw=True)
        self.create_subscription(AccelStamped, LEADER_ACCEL, self.on_leader_accel, qos,
                                 raw=True)

    leader_lost = property(lambda self: self.controller.leader.lost,
                           doc='Whether the agents apply the uninformed law (leader lost).')

    # -- inputs -------------------------------------------------------------------------------

    def on_odom(self, j: int, data: bytes) -> None:
        """Take agent ``j``'s odometry (serialised): lockstep queues it until every agent's
        is in (:meth:`take_odometry`), realtime handles it at once."""
        if not self.lockstep:
            self.on_one_odom(j, data)
            return
        self.queue_odom(j, data)
        if self.odom_take is not None:
            for i, more in self.odom_take.take():
                self.queue_odom(i, more)

    def queue_odom(self, j: int, data: bytes) -> None:
        """Lockstep: queue agent ``j``'s odometry; take the queue once every agent's is in."""
        if self.inbox.put(j, data):
            self.take_odometry()

    def take_odometry(self) -> None:
        """Lockstep: handle the queued odometry, at once when it is one step of every agent
        (:meth:`OdometryInbox.take_step`), else message by message in the order it came
        (:meth:`on_one_odom`, which judges, counts and logs each message)."""
        queue = self.inbox.take()
        k = self.inbox.take_step(queue)
        if k is not None:
            self.try_answer(k)
            return
        for j, data in queue:
            self.on_one_odom(j, data)

    def on_states(self, data: bytes) -> None:
        """Take the world's state cloud (serialised; the batched transport): lockstep stores
        the step's states at once and answers, realtime keeps them as the latest."""
        decoded = self.states_in.decode(self.states_topic, data, ordered=not self.lockstep)
        if decoded is None:
            return
        k, rows = decoded
        self.controller.heard_all(k, rows, time.monotonic())
        self.stash(k, lambda box: box.put_all(rows), self.states_topic)

    def on_one_odom(self, j: int, data: bytes) -> None:
        """Check and store agent ``j``'s odometry (serialised) for its step."""
        checked = self.check_odometry(self.odom_topics[j], data, self.children[j],
                                      self.oriented)
        if checked is None:
            return
        k, state = checked
        self.controller.heard(j, k, state, time.monotonic())
        self.stash(k, lambda box: box.put(j, state), self.odom_topics[j])

    def check_odometry(self, topic: str, data: bytes, child: str,
                       oriented: bool = False) -> tuple[int, tuple] | None:
        """Return the step and ``(q, p)`` of an acceptable odometry message (``oriented``:
        with ``(qz, qw)`` and ``(yaw rate, 0)``), or ``None``."""
        try:
            ns, frame, child_id, pos, vel = decode_odometry(data)
            heading = decode_heading(data) if oriented else ()
        except MalformedMessage as exc:
            self.guard.reject(topic, 'malformed', str(exc))
            return None
        lim = self.guard.limits
        k = self.guard.check(topic, ns, frame, ((pos, lim.position), (vel, lim.velocity)),
                             (child_id, child), ordered=not self.lockstep)
        if k is None:
            return None
        dim = self.scenario.dim
        return k, (pos[:dim], vel[:dim], *heading)

    def on_leader_odom(self, data: bytes) -> None:
        """Check and store the leader's position and velocity (serialised) for its step."""
        checked = self.check_odometry(LEADER_ODOM, data, 'leader')
        if checked is None:
            return
        k, state = checked
        self.controller.leader_heard(k, time.monotonic())
        self.controller.latest.leader_odom = state
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
        self.controller.leader_heard(k, time.monotonic())
        a = lin[:self.scenario.dim]
        self.controller.latest.leader_accel = a
        self.stash(k, lambda box: setattr(box, 'leader_accel', a), LEADER_ACCEL)

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
        offers that step again, else reject the input as stale
        (:meth:`AgentController.offered_again`)."""
        action = self.controller.offered_again(k)
        if action == 'repeat':
            self.outbox.extend(self.sent)
            self.flush()
        elif action == 'stale':
            self.guard.reject(topic, 'stale_stamp',
                              f'stamp of step {k} after step {self.controller.answered} was '
                              'answered')

    def try_answer(self, k: int) -> None:
        """Answer step ``k`` once every odometry is in, and the leader's state or its timeout."""
        if self.failure is None and self.controller.ready(k, time.monotonic()):
            self.answer(lambda: self.controller.answer(k), k)

    def answer(self, compute, k: int) -> None:
        """Publish the commands ``compute()`` returns for step ``k``; a fault of the law is
        reported instead (and this node answers no more)."""
        try:
            u = compute()
        except RunFault as fault:
            self.failure = self.reporter.report(fault, self.clock.stamp(k)).line
            return
        if self.controller.zeroed:
            # Before the commands, so that the world has it when it closes the step.
            self.reporter.report(non_finite_fault(self.scenario.law, k, self.controller.zeroed),
                                 self.clock.stamp(k), fatal=False)
        self.publish_commands(u, self.clock.ns(k))

    def on_lockstep_timer(self) -> None:
        """Take a step's odometry that stopped short of every agent's (one by one); answer a
        step that waits for the leader once its timeout is over; send the queue."""
        if self.inbox.stalled():
            self.take_odometry()
        k = self.controller.waiting()
        if k is not None:
            self.try_answer(k)
        self.flush()

    def publish_commands(self, u: np.ndarray, stamp_ns: int) -> None:
        """Queue one command per hosted agent (serialised), after its adaptive state for a
        law with one, and send what the world can receive."""
        if self.batched:
            controller = self.controller
            state = controller.state_values if controller.state else None
            twist = (lambda: controller.velocity_commands(u, self.scenario.plant.frame)) \
                if self.velocity else None
            self.sent = [(0, host_commands(self.cloud_out, controller.ids, stamp_ns, u, state,
                                           twist))]
            self.outbox.extend(self.sent)
            self.flush()
            return
        encode = self.encoder.encode
        sent = []
        if self.state_pubs:
            # Before the commands: the world's step is complete with both; sent first, the
            # state is not what keeps it waiting.
            m, encode_state = len(self.cmd_pubs), self.state_encoder.encode
            sent = [(m + row, encode_state(stamp_ns, values))
                    for row, values in enumerate(self.controller.state_values().tolist())]
        usage = self.controller.usage
        if self.usage_pubs and usage is not None:
            # Before the commands too: the world pairs each command with its report.
            first, encode_usage = len(self.cmd_pubs) + len(self.state_pubs), \
                self.usage_encoder.encode
            sent += [(first + row, encode_usage(stamp_ns, values))
                     for row, values in enumerate(usage.tolist())]
        # The commands of every hosted agent encoded at once (AccelBatchEncoder).
        self.sent = sent + list(enumerate(encode(stamp_ns, u))) if len(u) == self.encoder.n \
            else sent + [(row, AccelEncoder().encode(stamp_ns, a))
                         for row, a in enumerate(u.tolist())]
        self.outbox.extend(self.sent)
        if self.velocity:
            # Not in self.sent: an unstamped command is never repeated (see the module).
            linear, angular = self.controller.velocity_commands(u, self.scenario.plant.frame)
            first = len(self.pubs) - len(self.twist_pubs)
            self.outbox.extend((first + row, encode_twist(lin, ang)) for row, (lin, ang)
                               in enumerate(zip(linear.tolist(), angular.tolist())))
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
        if self.all_matched:
            ready, self.outbox = self.outbox, []
        else:
            waiting, ready, matched = [], [], self.matched
            for row, msg in self.outbox:
                if matched[row] or self.pubs[row].get_subscription_count() > 0:
                    matched[row] = True
                    ready.append((row, msg))
                else:
                    waiting.append((row, msg))
            self.outbox = waiting
            self.all_matched = all(matched)
        if self.batch_out is not None:
            self.batch_out.publish(ready)
            return
        for row, msg in ready:
            self.pubs[row].publish(msg)

    # -- realtime and housekeeping ---------------------------------------------------------------

    def on_timer(self) -> None:
        """Realtime mode: answer with the latest known states (zero-order hold)."""
        if self.failure is None and self.controller.latest.has_odometry(self.scenario.n_agents):
            self.answer(lambda: self.controller.realtime_answer(time.monotonic()),
                        self.controller.latest_step)

    def check_claims(self) -> None:
        """Report another node publishing commands for one of our agents (a duplicate id)."""
        check_claims(self, self.scenario.n_agents, self.duplicates, self.controller.ids)

    def destroy_node(self) -> None:
        """Release the compiled path's hold on the subscriptions and publishers, then
        destroy the node."""
        # getattr: a node whose construction failed has neither.
        release(getattr(self, 'odom_take', None), getattr(self, 'batch_out', None))
        super().destroy_node()

    def close(self) -> None:
        """Log what was rejected and what was replaced by zero; let a fault report reach
        the world (called on shutdown)."""
        if self.failure is not None:
            self.reporter.wait_acknowledged()
        if self.guard.rejected:
            self.get_logger().warning(f'rejected inputs: {self.guard.counts()}')
        if self.controller.non_finite:
            self.get_logger().warning('non-finite commands replaced by zero, per agent: '
                                      f'{dict(sorted(self.controller.non_finite.items()))}')


def main(args: list[str] | None = None) -> int:
    """Run one agent node (``ros2 run flock_swarm agent --ros-args -p agent_id:=3``).

    The node is named ``agent_<id>`` unless remapped with ``__node:=``.
    """
    argv = sys.argv if args is None else args
    found = [m.group(1) for a in argv for m in [re.search(r'^agent_id:=(\d+)$', a)] if m]
    name = agent_name(int(found[-1])) if found else 'agent'
    return run_agents('agent', lambda: AgentNode(node_name=name), args)


def container_main(args: list[str] | None = None) -> int:
    """Run a container hosting many agents (``ros2 run flock_swarm agents``).

    It hosts every agent of the scenario unless ``-p agent_ids:='0-49'`` says otherwise; the
    node is named ``agents``.
    """
    return run_agents('agents', lambda: AgentNode(default_agent_ids='all', node_name='agents'),
                      args)


def run_agents(name: str, factory, args: list[str] | None) -> int:
    """Run an agent node until the world's end or a fault of its law; return the status.

    :return: :func:`run_node`'s status, or 1 when the law failed (reported to the world).
    """
    built: list[AgentNode] = []
    status = run_node(name, lambda: built.append(factory()) or built[0], args,
                      until=lambda node: node.world_finished() or node.failure is not None,
                      completed=lambda node: node.world_finished.completed())
    return 1 if status == 0 and built and built[0].failure is not None else status


if __name__ == '__main__':
    sys.exit(main())
