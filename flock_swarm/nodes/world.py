"""The world node: integrates every agent, publishes odometry and ``/clock``, records the bag.

Lockstep mode (default, deterministic): for step ``k`` the world publishes ``/clock`` ``t_k``
and every ``/agent_<i>/odom`` stamped ``t_k``, then waits until every agent's
``cmd_accel`` and the leader's state for ``t_k`` are in (and, for a law with adaptive state,
every ``/agent_<i>/state`` of ``t_k``), or the per-step timeout expires (a late or missing
agent gets a zero command: counted, logged, published on ``/swarm/metrics`` and recorded).
It then integrates exactly (the same :func:`step_agents` as ``sim``) to ``t_{k+1}``.
Realtime mode: a wall-clock timer steps with the latest commands (zero-order hold).

A fault ends the run as ``failed`` within a bounded time, with one line naming the node or
component, the agent and the step (docs/ros.md, "Faults"): a fault an agent or the leader
reports on ``swarm/faults`` (its law or model raised, returned the wrong shape or a
non-finite value) at once; an agent that answered before and then misses
``max_missed_steps`` steps in a row (lockstep); an agent's node or the leader gone from the
ROS graph for ``peer_timeout`` seconds.

Every message the world publishes or receives is written to a rosbag2-compatible MCAP bag
in ``out_dir/bag``, with the scenario, seed and informed set as MCAP metadata; the run's
``summary.json`` and ``timeseries.npz`` go to ``out_dir``. The decisions are those of
:class:`~flock_swarm.nodes.stepper.WorldStepper` (no ROS); this node is its plumbing.
"""

import math
import shutil
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from flock_swarm.bag.writer import serialize
from flock_swarm.contract import (CLOCK, CLOCK_QOS, FAULTS, FAULTS_QOS, FRAME, LEADER_ACCEL,
                                  LEADER_ODOM, LOCKSTEP_QOS, OBSTACLES, OBSTACLES_QOS, RUNNING,
                                  SCENARIO, SCENARIO_QOS, STATUS, STATUS_QOS, cmd_topic,
                                  cmd_vel_topic, network_topic, odom_topic, qos_profile,
                                  state_topic)
from flock_swarm.console import EXIT_USAGE
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.faults import NON_FINITE
from flock_swarm.core.headline import result_line
from flock_swarm.core.network import USAGE_LABELS
from flock_swarm.core.summary import with_failure
from flock_swarm.nodes.batch import (MESSAGE_PATH, BatchPublish, BatchTake, release,
                                     use_c_path)
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.fault_report import FaultReport
from flock_swarm.nodes.graph import check_claims, command_claims
from flock_swarm.nodes.guard import LIMIT_PARAMS, InputGuard, Limits
from flock_swarm.nodes.markers import Telemetry, obstacle_markers
from flock_swarm.nodes.parameters import COMMON_PARAMS, NodeParameters, Param, init_node
from flock_swarm.nodes.recording import BagSink, RecordedNode, provenance, provenance_text
from flock_swarm.nodes.spin import run_node, wall_timer
from flock_swarm.nodes.stepper import (SETTING_PARAMS, CommandInbox, Observation,
                                       WorldSettings, WorldStepper)
from flock_swarm.nodes.wire import (MalformedMessage, OdometryBatchEncoder, decode_accel,
                                    decode_odometry, decode_state, decode_twist, encode_clock,
                                    odometry_rows)
from flock_swarm.outputs import (SpooledRecorder, json_text, write_error, write_outputs,
                                 write_text)

#: A law's adaptive state may take any finite value: only a non-finite one is rejected.
STATE_LIMIT = sys.float_info.max


#: Why the world refuses ``use_sim_time:=true`` (and how the parameter reads back).
SIM_TIME_REFUSED = ('must be false: the world publishes /clock itself (it is the simulation '
                    'clock); the leader and the agents accept either value')


#: Seconds between the waiting world's lines naming who it waits for.
WAIT_LOG_EVERY = 5.0


def id_list(ids: list[int]) -> str:
    """Return agent ids as ``agent 3`` or ``agents 0-2, 5``."""
    runs: list[list[int]] = []
    for i in ids:
        if runs and runs[-1][1] == i - 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    text = ', '.join(str(a) if a == b else f'{a}-{b}' for a, b in runs)
    return f'agent {text}' if len(ids) == 1 else f'agents {text}'


def _split_bound(name: str, default: int | float, description: str) -> Param:
    """Return a bag-splitting parameter: 0 (no split) or a finite bound."""
    return Param(name, default, description, lambda v: 0 <= v < float('inf'))


#: The world's parameters, in the order they are read and checked.
WORLD_PARAMS = COMMON_PARAMS + (
    Param('out_dir', '', 'directory for bag/, summary.json and timeseries.npz (given empty: '
          'out/<scenario>_ros; reads back as the directory written)'),
    Param('record', True, 'write the MCAP bag'),
    _split_bound('bag_max_size', 0, 'split the bag into bag_0.mcap, bag_1.mcap, ... once a '
                 'file is larger than this many bytes (0: no split)'),
    _split_bound('bag_max_duration', 0.0, 'split the bag once a file spans more than this '
                 'many seconds of simulation time (0: no split)'),
) + SETTING_PARAMS + (
    Param('expect_subscribers', -1, 'subscribers each odometry topic must have before the '
          'start (given as -1: one per node hosting agents; reads back as that number once '
          'the world has found them)'),
    Param('pace', 0.0, 'lockstep: at most this many simulated seconds per wall second (0: as '
          'fast as the nodes go; 1: real time, to watch a run live)',
          lambda v: math.isfinite(v) and v >= 0, 'must be finite and >= 0, got {value!r}'),
    Param('expect_telemetry_subscribers', 0, 'subscribers /swarm/markers and /swarm/metrics '
          'must have before the start (a live-view bridge: 1)', lambda v: v >= 0,
          'must be 0 or more, not {value}'),
) + LIMIT_PARAMS + (MESSAGE_PATH,)


class WorldNode(RecordedNode):
    """Integrates the swarm, publishes odometry and ``/clock``, records everything."""

    def __init__(self, progress: Callable[[str], None] | None = None, **kwargs) -> None:
        """Create the node.

        :param progress: called with a one-line status every two seconds (the runner prints
            it); ``None`` logs it instead.
        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        init_node(super().__init__, 'world', kwargs)
        params = self.params = NodeParameters(
            self, WORLD_PARAMS, SIM_TIME_REFUSED, 'always false: the world publishes /clock')
        sc = self.scenario = params.load_scenario()
        self.progress = progress
        self.mode = params['mode']
        settings = WorldSettings.from_parameters(params.values, self.mode == 'lockstep')
        self.lockstep = settings.lockstep
        # Lockstep on the compiled path (flock_swarm.nodes.batch): a step's commands are
        # taken at once from its first command's callback; /clock and the odometry go out
        # in one call. Decided first: a refusal leaves nothing behind.
        self.c_path = use_c_path(params['message_path']) and self.lockstep
        self.record = params['record']
        self.expect_subscribers = params['expect_subscribers']
        self.expect_telemetry = params['expect_telemetry_subscribers']
        self.pace = params['pace']
        #: Lockstep with ``pace``: the next step is held until its wall time.
        self.paced = False
        #: The pace in force (:meth:`pace_now`) and the step and wall time it counts from
        #: (``None``: the start of the run).
        self.pace_in_force = self.pace
        self.pace_anchor: tuple[int, float] | None = None
        self.created = self.wait_logged = time.monotonic()
        #: Why the world refused to start (another world on the domain), or ``None``.
        self.refusal: ScenarioError | None = None
        self.other_world_reported = False
        self.subscribers_needed = self.expect_subscribers
        out_dir = params['out_dir']
        self.out = Path(out_dir) if out_dir else Path('out') / f'{sc.name}_ros'
        # expect_subscribers: -1 reads back the number waited for, once it is known.
        params.will_settle('expect_subscribers')
        params.declare(out_dir=str(self.out))
        # The time series goes to disk as it is recorded: memory stays flat on long runs.
        self.spool = SpooledRecorder(self.out, self.get_logger().warning)
        self.stepper = WorldStepper(sc, settings, self.get_logger(), recorder=self.spool)
        self.clock = StepClock(sc.dt)
        self.duplicates: set[int] = set()
        # The node that published each agent's commands, as the graph last told.
        self.hosts: dict[int, str] = {}
        #: The files of the run's outputs written, and why writing one failed (or ``None``).
        self.written: list[Path] = []
        self.write_error: str | None = None
        self.guard = InputGuard(self.clock, Limits.from_parameters(params.values),
                                self.get_logger().warning)
        self.bag = BagSink(self.out / 'bag', sc, self.stepper.real, self.mode,
                           self.recording_failed, max_bagfile_size=params['bag_max_size'],
                           max_bagfile_duration=params['bag_max_duration']) \
            if self.record else None
        try:
            self.spool.open()
        except OSError as exc:
            raise ScenarioError('out_dir', f'cannot write to {self.out}: {exc.strerror}') \
                from None
        self.sinks = [] if self.bag is None else [self.bag]
        # Not recorded: the bag's own end (and summary.json) tell a replay how the run ended.
        self.status_pub = self.create_publisher(String, STATUS, qos_profile(STATUS_QOS))
        self.status_pub.publish(String(data=RUNNING))
        lockstep_qos = qos_profile(LOCKSTEP_QOS)
        self.clock_pub = self.recorded_publisher(Clock, CLOCK, qos_profile(CLOCK_QOS))
        self.odom_pubs = [self.recorded_publisher(Odometry, odom_topic(i), lockstep_qos)
                          for i in range(sc.n_agents)]
        plant = self.stepper.plant
        self.odom_encoder = OdometryBatchEncoder([f'agent_{i}' for i in range(sc.n_agents)],
                                                 oriented=plant is not None and plant.oriented)
        self.state_pubs = [self.clock_pub] + self.odom_pubs
        self.state_topics = [pub.topic_name for pub in self.state_pubs]
        # The current step's serialised /clock and odometry, offered again if it stalls.
        self.step_bytes: list[bytes] = []
        self.telemetry = Telemetry(self, sc.law.radius, self.stepper.real.agents.informed,
                                   sc.headline, sc.obstacles)
        subscribe = self.recorded_subscription
        self.cmd_handlers = [lambda msg, i=i: self.on_command(i, msg)
                             for i in range(sc.n_agents)]
        self.cmd_topics = [subscribe(AccelStamped, cmd_topic(i), decode_accel,
                                     self.cmd_handlers[i],
                                     (lambda data, i=i: self.queue_command(i, data))
                                     if self.lockstep else None)
                           for i in range(sc.n_agents)]
        # A law's adaptive state (none: no topic), recorded and checked like the commands.
        self.agent_state_topics = [subscribe(JointState, state_topic(i), decode_state,
                                             lambda msg, i=i: self.on_agent_state(i, msg))
                                   for i in range(sc.n_agents)] \
            if self.stepper.state else []
        # Realtime with the network model: what each command used, recorded like the state.
        self.network_topics = [subscribe(JointState, network_topic(i), decode_state,
                                         lambda msg, i=i: self.on_network_report(i, msg))
                               for i in range(sc.n_agents)] \
            if self.stepper.used is not None else []
        # A robot plant's velocity commands (cmd_vel): unstamped, recorded at the open step.
        self.twist_topics = [subscribe(Twist, cmd_vel_topic(i), decode_twist, None,
                                       lambda data, i=i: self.on_twist(i, data))
                             for i in range(sc.n_agents)] if self.stepper.velocity else []
        # Lockstep: a step's commands are queued as bytes and taken at once (take_commands).
        self.inbox = CommandInbox(self.stepper, self.guard, self.cmd_topics)
        # Lockstep on the compiled path: see self.c_path.
        subs = {sub.topic_name: sub for sub in self.subscriptions}
        self.cmd_take = BatchTake([subs[name] for name in self.cmd_topics]) \
            if self.c_path else None
        self.state_out = BatchPublish([self.clock_pub] + self.odom_pubs) \
            if self.c_path else None
        self.state_targets = np.arange(1 + sc.n_agents, dtype=np.int64)
        wall_timer(self, 1.0, self.check_claims)
        self.leader_odom_topic = subscribe(Odometry, LEADER_ODOM, decode_odometry,
                                           self.on_leader_odom)
        self.leader_accel_topic = subscribe(AccelStamped, LEADER_ACCEL, decode_accel,
                                            self.on_leader_accel)
        self.create_subscription(DiagnosticArray, FAULTS, self.on_fault, qos_profile(FAULTS_QOS))
        # Latched, and recorded at t = 0: the bag keeps the scenario where tools that drop
        # MCAP metadata (rosbags-convert) keep it too (analyze reads it there).
        self.scenario_pub = self.recorded_publisher(String, SCENARIO, qos_profile(SCENARIO_QOS))
        self.publish_recorded(self.scenario_pub, String(data=provenance_text(
            provenance(sc, self.stepper.real, self.mode))), 0)
        #: The obstacle map's bytes as published (None without obstacles): a live view
        #: served after the start sends them to its viewers (InProcessSwarm.serve).
        self.obstacles_map: bytes | None = None
        if sc.obstacles.active:
            # The map for viewers, latched and recorded at t = 0 (docs/obstacles.md).
            self.obstacles_pub = self.recorded_publisher(MarkerArray, OBSTACLES,
                                                         qos_profile(OBSTACLES_QOS))
            self.obstacles_map = serialize(obstacle_markers(
                sc.obstacles, sc.dim, self.clock.stamp(0), FRAME))
            self.publish_recorded(self.obstacles_pub, self.obstacles_map, 0)
        for sink in self.sinks:
            sink.flush()
        self.timer = wall_timer(self, 0.01, self.on_lockstep_timer) if self.lockstep else \
            wall_timer(self, params.timer_period(sc.dt), self.on_realtime_timer)

    # The stepper's state, as the runner and the tests read it off the node.
    k = property(lambda self: self.stepper.k, doc='The open step.')
    done = property(lambda self: self.stepper.done, doc='Whether the run has ended.')
    status = property(lambda self: self.stepper.status, doc='How the run ended (or running).')
    leader_lost = property(lambda self: self.stepper.leader.lost, doc='The leader is lost.')
    bag_error = property(lambda self: None if self.bag is None else self.bag.error,
                         doc='Why recording failed, or ``None``.')
    steps_at_once = property(lambda self: self.inbox.steps_at_once,
                             doc='Steps whose commands were taken in one pass.')

    # -- messages in and out ------------------------------------------------------------------

    def queue_command(self, i: int, data: bytes) -> None:
        """Lockstep: queue agent ``i``'s command (serialised); take the queue once it can
        complete the step."""
        if self.inbox.put(i, data):
            self.take_commands()
        if self.cmd_take is not None:
            for j, more in self.cmd_take.take():
                if self.inbox.put(j, more):
                    self.take_commands()

    def take_commands(self) -> None:
        """Lockstep: handle the queued commands, at once when they are the open step's
        command of every agent (:meth:`CommandInbox.take_step`: recorded here in their order
        of arrival), else message by message in the order they came
        (:meth:`~RecordedNode.take_recorded`, :meth:`on_command`: each judged, counted and
        recorded as it would have been on arrival).
        """
        queue = self.inbox.take()
        k = self.inbox.take_step(queue)
        if k is not None:
            topics = self.cmd_topics
            self.record_messages([topics[i] for i, _ in queue], [data for _, data in queue],
                                 self.clock.ns(k))
            self._maybe_finish()
            return
        for i, data in queue:
            self.take_recorded(self.cmd_topics[i], data, decode_accel, self.cmd_handlers[i])

    def on_command(self, i: int, msg: tuple) -> None:
        """Check agent ``i``'s command ``(stamp_ns, frame_id, linear)`` and hand it on."""
        ns, frame, lin = msg
        topic = self.cmd_topics[i]
        k = self.guard.check(topic, ns, frame, ((lin, self.guard.limits.accel),),
                             window=self.stepper.window())
        if k is None:
            return
        if self.stepper.command(i, k, lin[:self.scenario.dim], time.monotonic()):
            self.guard.reject(topic, 'late', f'a command for step {k} at step {self.k}')
        self._maybe_finish()

    def on_twist(self, i: int, data: bytes) -> None:
        """Record agent ``i``'s velocity command (serialised) at the open step; a finite one
        goes to the stepper (:meth:`WorldStepper.twist`)."""
        topic = self.twist_topics[i]
        self.record_message(topic, data, self.clock.ns(self.k))
        try:
            linear, angular = decode_twist(data)
        except MalformedMessage as exc:
            self.guard.reject(topic, 'malformed', str(exc))
            return
        if not np.isfinite(linear + angular).all():
            self.guard.reject(topic, 'non_finite', f'a non-finite velocity command at step '
                              f'{self.k}')
            return
        self.stepper.twist(i, linear, angular, time.monotonic())
        self._maybe_finish()

    def check_labelled(self, topic: str, msg: tuple, expected: tuple[str, ...],
                       what: str) -> tuple[int, tuple[float, ...]] | None:
        """Return the step and values of a labelled message ``(stamp_ns, frame_id, labels,
        values)`` (a ``JointState``) whose labels are ``expected``, or ``None`` (rejected).

        :param what: the labels' owner in the rejection (``"state"``: "not the law's").
        """
        ns, frame, labels, values = msg
        if labels != expected:
            whose = "the law's " if what == 'state' else ''
            self.guard.reject(topic, 'malformed', f'{what} labels {list(labels)}, not '
                              f'{whose}{list(expected)}')
            return None
        k = self.guard.check(topic, ns, frame, ((values, STATE_LIMIT),),
                             window=self.stepper.window())
        return None if k is None else (k, values)

    def on_agent_state(self, i: int, msg: tuple) -> None:
        """Check agent ``i``'s adaptive state ``(stamp_ns, frame_id, labels, values)`` and
        hand it on (its labels must be the law's)."""
        checked = self.check_labelled(self.agent_state_topics[i], msg,
                                      self.stepper.state_labels, 'state')
        if checked is not None:
            self.stepper.agent_state(i, *checked)
            self._maybe_finish()

    def on_network_report(self, i: int, msg: tuple) -> None:
        """Check agent ``i``'s report of what its command used ``(stamp_ns, frame_id,
        labels, values)`` and hand it on (realtime with the network model)."""
        checked = self.check_labelled(self.network_topics[i], msg, USAGE_LABELS, 'report')
        if checked is not None:
            self.stepper.network_report(i, *checked)

    def on_leader_odom(self, msg: tuple) -> None:
        """Check the leader's position and velocity of its step (``msg``: see
        :func:`~flock_swarm.nodes.wire.decode_odometry`) and hand them on."""
        ns, frame, child, pos, vel = msg
        lim, dim = self.guard.limits, self.scenario.dim
        k = self.guard.check(self.leader_odom_topic, ns, frame,
                             ((pos, lim.position), (vel, lim.velocity)), (child, 'leader'),
                             self.stepper.window())
        if k is not None:
            self.stepper.leader_state(k, time.monotonic(), q=np.array(pos[:dim]),
                                      p=np.array(vel[:dim]))
            self._maybe_finish()

    def on_leader_accel(self, msg: tuple) -> None:
        """Check the leader's acceleration of its step and hand it on."""
        ns, frame, lin = msg
        k = self.guard.check(self.leader_accel_topic, ns, frame,
                             ((lin, self.guard.limits.accel),), window=self.stepper.window())
        if k is not None:
            self.stepper.leader_state(k, time.monotonic(),
                                      a=np.array(lin[:self.scenario.dim]))
            self._maybe_finish()

    def on_fault(self, msg: DiagnosticArray) -> None:
        """Take the faults a node reports: count non-finite commands, fail the run on a fatal
        one (:class:`~flock_swarm.nodes.fault_report.FaultReport`)."""
        for report in FaultReport.from_msg(msg):
            self.stepper.fault_reported(report.step, report.agents, report.kind == NON_FINITE)
            if report.fatal:
                self.fail(report.line)

    def check_claims(self) -> None:
        """Once a second: report two nodes publishing commands for the same agent (a
        duplicate agent_id), and another world on the domain; fail the run when a peer that
        answered before has been gone from the ROS graph for ``peer_timeout`` seconds."""
        n = self.scenario.n_agents
        claims = command_claims(self, n)
        check_claims(self, n, self.duplicates, claims=claims)
        for i, nodes in claims.items():
            self.hosts[i] = ', '.join(f'{ns.rstrip("/")}/{name}' for ns, name in nodes)
        st = self.stepper
        if st.started and not st.done:
            leader_gone = self.count_publishers(self.leader_odom_topic) == 0
            self.fail(st.graph_gone([i for i in range(n) if i not in claims], leader_gone,
                                    time.monotonic(), lambda i: self.hosts.get(i, '')))
        # After the start (a run in one process starts before discovery could show another
        # world; a realtime world starts at once): said once, the run goes on.
        if (self.stepper.started or not self.lockstep) and not self.other_world_reported:
            other = self.other_worlds()
            if other is not None:
                self.other_world_reported = True
                self.get_logger().error(f'{other} (this run\'s messages mix with its)')

    def publish_states(self, t_ns: int) -> None:
        """Publish ``/clock`` and every agent's odometry for time ``t_ns``, and record them."""
        st = self.stepper
        rows = (st.q, st.p) if st.plant is None else odometry_rows(st.plant, st.x,
                                                                   self.scenario.dim)
        sent = [encode_clock(t_ns)]
        sent += self.odom_encoder.encode(t_ns, *rows)
        self.send(sent)
        self.record_messages(self.state_topics, sent, t_ns)
        for sink in self.sinks:
            sink.flush()
        self.step_bytes = sent

    def send(self, sent: list[bytes]) -> None:
        """Publish ``/clock`` and every odometry (their bytes, in that order)."""
        if self.state_out is not None:
            self.state_out.publish_to(self.state_targets, sent)
            return
        for pub, data in zip(self.state_pubs, sent):
            pub.publish(data)

    def go_on(self, obs: Observation) -> None:
        """After a step observed: finish after the last, else integrate (or diverge)."""
        self.telemetry.emit(obs, self.guard.counts())
        line = self.stepper.progress_line(time.monotonic())
        if line is not None:
            if self.progress is not None:
                self.progress(line)
            else:   # the logger names the node itself: no second [world]
                self.get_logger().info(line.removeprefix('[world] '))
        if obs.last:
            self.finish('completed')
        elif not self.done and not self.stepper.advance(obs.u):
            self.finish('diverged')

    # -- lockstep -----------------------------------------------------------------------------

    def ready_to_start(self) -> bool:
        """Return whether every agent and the leader are discovered and subscribed; say who
        is missing every :data:`WAIT_LOG_EVERY` seconds. Another world (or a replay) on the
        domain sets :attr:`refusal` and stops the timer: ``main`` and the harness end the run
        with that line, and ``expect_subscribers`` given as -1 reads back the count found.
        """
        self.refusal = self.refusal or self.other_worlds()
        if self.refusal is not None:
            # Not raised here: an executor logs an exception of a callback with its traceback.
            self.timer.cancel()
            return False
        missing = self.waiting_for()
        if not missing:
            if self.expect_subscribers < 0:
                self.params.settle('expect_subscribers', self.subscribers_needed)
            return True
        now = time.monotonic()
        if now - self.wait_logged >= WAIT_LOG_EVERY:
            self.wait_logged = now
            self.get_logger().info(f'waiting {now - self.created:.0f} s for ' + '; '.join(missing))
        return False

    def waiting_for(self) -> list[str]:
        """Return what the start still waits for, one phrase each (empty: nothing)."""
        n, missing = self.scenario.n_agents, []
        if self.expect_subscribers < 0:
            claims = command_claims(self, n)
            absent = [i for i in range(n) if i not in claims]
            if absent:
                missing.append(f'{id_list(absent)} (nobody publishes their cmd_accel)')
            need = len(set().union(*claims.values())) if claims else 1
        else:
            need = self.expect_subscribers
            absent = [i for i, t in enumerate(self.cmd_topics) if self.count_publishers(t) < 1]
            if absent:
                missing.append(f'{id_list(absent)} (nobody publishes their cmd_accel)')
        self.subscribers_needed = need
        short = [i for i, pub in enumerate(self.odom_pubs) if pub.get_subscription_count() < need]
        if short:
            missing.append(f'{need} subscriber(s) of the odometry of {id_list(short)}')
        for pub in (self.telemetry.marker_pub, self.telemetry.metrics_pub):
            if pub.get_subscription_count() < self.expect_telemetry:
                missing.append(f'{self.expect_telemetry} subscriber(s) of {pub.topic_name}')
        if self.count_publishers(self.leader_odom_topic) < 1:
            missing.append(f'the leader (nobody publishes {self.leader_odom_topic})')
        if self.clock_pub.get_subscription_count() < 1:
            missing.append(f'a subscriber of {self.clock_pub.topic_name} (the leader)')
        return missing

    def other_worlds(self) -> ScenarioError | None:
        """Return the refusal to start beside another world on the same ROS domain (two runs
        would mix their messages): another publisher of ``/clock`` or ``swarm/status``
        (``None``: nobody else)."""
        topics = [pub.topic_name for pub in (self.clock_pub, self.status_pub)]
        if all(self.count_publishers(topic) <= 1 for topic in topics):
            return None
        nodes = sorted({f'{i.node_namespace.rstrip("/")}/{i.node_name}'
                        for topic in topics for i in self.get_publishers_info_by_topic(topic)
                        if not i.node_name.startswith('_NODE_NAME_UNKNOWN')})
        return ScenarioError('ROS_DOMAIN_ID', (
            f'another world or a replay publishes {" or ".join(topics)} on domain '
            f'{self.context.get_domain_id()} (nodes: {", ".join(nodes)}): give each run a '
            'domain of its own'))

    def on_lockstep_timer(self) -> None:
        """Start when everybody is there; turn an expired step into zero commands.

        Queued commands are taken one by one once the queue stopped growing for a tick (an
        agent is missing, or a message was doubled), and before a step times out.
        """
        if self.paced:
            if time.monotonic() >= self.pace_due():
                self.paced = False
                self.begin_step()
            return
        if self.inbox.stalled():
            self.take_commands()
            return
        due = self.stepper.tick(time.monotonic(), self.ready_to_start)
        if due == 'timeout' and len(self.inbox):
            k = self.k
            self.take_commands()
            if self.k != k or self.done:
                return
        if due == 'begin':
            self.begin_step()
        elif due == 'timeout':
            self.finish_step(timed_out=True)
        elif due == 'resend':
            # Offered again, not recorded again (see WorldStepper.resent).
            self.send(self.step_bytes)

    def begin_step(self) -> None:
        """Publish ``/clock`` and every odometry for the current step."""
        self.stepper.begin_step(time.monotonic())
        self.publish_states(self.clock.ns(self.k))

    def _maybe_finish(self) -> None:
        if self.stepper.complete():
            self.finish_step(timed_out=False)

    def finish_step(self, timed_out: bool) -> None:
        """Close the current step: zero commands for absentees, record, integrate, go on
        (or fail, when agents have stopped answering: :meth:`WorldStepper.silent_agents`)."""
        obs = self.stepper.close_step(timed_out, time.monotonic())
        self.go_on(obs)
        if not self.done:
            self.fail(self.stepper.silent_agents(obs.k, lambda i: self.hosts.get(i, '')))
        if not self.done:
            pace = self.pace_now()
            if pace != self.pace_in_force:
                self.pace_in_force, self.pace_anchor = pace, (self.k, time.monotonic())
            if pace and time.monotonic() < self.pace_due():
                self.paced = True  # the lockstep timer begins it when due
                return
            self.begin_step()

    def pace_now(self) -> float:
        """Return the pace in force: ``pace`` when given, else a sink's (a live view whose
        every channel a viewer watches: :attr:`flock_swarm.foxglove_ws.LiveSink.pace`),
        else 0 (as fast as it goes)."""
        if self.pace:
            return self.pace
        return max((getattr(sink, 'pace', 0.0) for sink in self.sinks), default=0.0)

    def pace_due(self) -> float:
        """Return the monotonic time at which the pace in force lets the open step begin."""
        k0, wall0 = self.pace_anchor or (0, self.stepper.t_wall0)
        return wall0 + (self.k - k0) * self.scenario.dt / self.pace_in_force

    # -- realtime -----------------------------------------------------------------------------

    def on_realtime_timer(self) -> None:
        """Realtime mode: step with the latest commands (zero-order hold)."""
        st = self.stepper
        if st.done:
            return
        now = time.monotonic()
        st.realtime_begin(now)
        self.publish_states(self.clock.ns(st.k))
        self.go_on(st.realtime_close(now, time.monotonic()))

    # -- the end ------------------------------------------------------------------------------

    def finish(self, status: str, failure: str | None = None) -> None:
        """Write ``summary.json`` and ``timeseries.npz``, close the bag; idempotent.

        :param status: how the run ended.
        :param failure: the line telling why it failed (``failed``, ``recording_failed``).
        """
        if self.stepper.end(status, failure):
            self.timer.cancel()
            self.write_results()

    def fail(self, line: str | None) -> None:
        """End the run as ``failed`` with ``line`` (one error line in the log); nothing
        when ``line`` is ``None`` or the run has ended."""
        if line is None or self.done:
            return
        self.get_logger().error(f'run failed: {line}')
        self.finish('failed', line)

    def recording_failed(self, reason: str) -> None:
        """Stop the run cleanly when the bag cannot be written (status ``recording_failed``).

        The bag keeps every chunk written before (see :class:`BagSink`).
        """
        self.get_logger().error(f'recording failed: {reason}; stopping the run, the bag '
                                'keeps every chunk written before')
        self.finish('recording_failed', f'recording failed: {reason}')

    def write_results(self) -> None:
        """Announce the end on ``swarm/status``; write what was recorded so far (also on an
        interrupted run), close the sinks."""
        # Commands that came but were still queued are judged, counted and recorded too.
        self.take_commands()
        self.status_pub.publish(String(data=self.stepper.status))
        recorded = self.bag is not None
        if recorded and self.bag.empty:
            # Stopped before the first step (a signal in the start wait): no empty bag.
            self.bag.discard()
            self.sinks.remove(self.bag)
            recorded = False
            self.get_logger().warning(
                f'the run ended ({self.stepper.status}) before its first step: nothing was '
                f'recorded, no bag written; {self.out / "summary.json"} says so')
        result = self.stepper.result(time.monotonic(), self.guard.counts(),
                                     sorted(self.duplicates), self.bag_error,
                                     str(self.out / 'bag') if recorded else None)
        for sink in self.sinks:
            try:
                sink.close()
            except OSError as exc:
                self.get_logger().error(f'cannot finalise {sink}: {exc.strerror or exc}; its '
                                        'complete chunks stay readable')
        self.result = result
        try:
            self.written = write_outputs(result, self.out, self.scenario)
        except OSError as exc:
            self.outputs_failed(exc)
        else:
            self.spool.discard()
        if self.progress is None:
            self.log_end(recorded)

    def log_end(self, recorded: bool) -> None:
        """Log how the run ended and the files written, as ``swarm`` prints them: a world
        logging its progress (``ros2 run``, ``swarm --processes``) ends its log with them,
        after a stop signal too."""
        log = self.get_logger()
        summary = self.result.summary
        line = result_line(summary, self.scenario.headline, ('collisions', 'missed_commands'))
        (log.info if summary.get('status') == 'completed' else log.warning)(line)
        paths = ([self.out / 'bag'] if recorded else []) + [
            path for path in self.written if path.name != 'scenario.json']
        log.info('wrote ' + ', '.join(str(path) for path in paths))

    def outputs_failed(self, exc: OSError) -> None:
        """A file of the outputs could not be written: log one line naming it, keep the
        spooled time series, and still write ``summary.json`` if it was not the one that
        failed, with status ``recording_failed`` and the line (``failure``; a run that had
        failed already keeps its own)."""
        self.spool.close()
        line = write_error(exc)
        self.write_error = line
        self.get_logger().error(f'{line}; the time series stays in {self.spool.spool}')
        self.written = [path for path in (self.out / 'timeseries.npz',
                                          self.out / 'scenario.json')
                        if path.is_file() and str(path) != exc.filename]
        summary = self.out / 'summary.json'
        if str(summary) == exc.filename:
            return
        before = self.result.summary
        self.result.summary = with_failure(
            before, before['status'] if 'failure' in before else 'recording_failed',
            before.get('failure', line))
        try:
            self.written.append(write_text(summary, json_text(self.result.summary)))
        except OSError as again:
            self.get_logger().error(write_error(again))

    def peer_died(self) -> None:
        """End the run with status ``failed``: a supervisor saw another process of the run
        die (:data:`~flock_swarm.console.FAIL_SIGNAL`); keep what was recorded."""
        self.fail(f'another process of the run died (the supervisor said so at step {self.k})')

    def close(self) -> None:
        """Called on shutdown: keep what was recorded (status ``interrupted``), and let the
        announcement of the end reach the leader and agents before the node goes."""
        if self.refusal is not None:
            # Announce nothing on swarm/status: the other world's leader and agents hear it.
            # Leave no bag behind either (it holds nothing of a run): out_dir can be reused.
            self.stepper.end('refused')
            for sink in self.sinks:
                sink.close()
            self.spool.discard()
            if self.bag is not None:
                shutil.rmtree(self.bag.path, ignore_errors=True)
            return
        if self.stepper.end('interrupted'):
            self.write_results()
        self.status_pub.wait_for_all_acked(Duration(seconds=2))

    def destroy_node(self) -> None:
        """Release the compiled path's hold on the subscriptions and publishers, then
        destroy the node."""
        # getattr: a node whose construction failed has neither.
        release(getattr(self, 'cmd_take', None), getattr(self, 'state_out', None))
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the world node (``ros2 run flock_swarm world``); it exits after the last step.

    The exit status is 2 for invalid configuration, 1 when the run failed (a fault of a law,
    a leader model or a node, or a supervisor reported a dead process:
    :data:`~flock_swarm.console.FAIL_SIGNAL`), when recording failed or an output could not
    be written, that of the signal after a stop signal
    (:data:`~flock_swarm.console.EXIT_SIGNAL`: the run ends ``interrupted``), else 0.
    """
    built: list[WorldNode] = []
    status = run_node('world', lambda: built.append(WorldNode()) or built[0], args,
                      until=lambda node: node.done or node.refusal is not None,
                      on_fail=WorldNode.peer_died,
                      completed=lambda node: node.done and node.stepper.status == 'completed')
    if built and built[0].refusal is not None:
        print(f'world: error: {built[0].refusal}', file=sys.stderr)
        return EXIT_USAGE
    failed = built and (built[0].status in ('recording_failed', 'failed')
                        or built[0].bag_error or built[0].write_error)
    return 1 if status == 0 and failed else status


if __name__ == '__main__':
    sys.exit(main())
