"""The world node: integrates every agent, publishes odometry and ``/clock``, records the bag.

Lockstep mode (default, deterministic): for step ``k`` the world publishes ``/clock`` ``t_k``
and every ``/agent_<i>/odom`` stamped ``t_k``, then waits until every agent's
``cmd_accel`` and the leader's state for ``t_k`` are in, or the per-step timeout expires (a
late or missing agent gets a zero command: counted, logged, published on ``/swarm/metrics``
and recorded). It then integrates exactly (the same :func:`step_agents` as ``sim``) to
``t_{k+1}``. Realtime mode: a wall-clock timer steps with the latest commands (zero-order
hold).

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

import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from flock_swarm.contract import (CLOCK, CLOCK_QOS, FAULTS, FAULTS_QOS, LEADER_ACCEL,
                                  LEADER_ODOM, LOCKSTEP_QOS, RUNNING, STATUS, STATUS_QOS,
                                  cmd_topic, odom_topic, qos_profile)
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.faults import NON_FINITE
from flock_swarm.core.summary import with_failure
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.fault_report import FaultReport
from flock_swarm.nodes.graph import agent_hosts, check_claims, command_claims
from flock_swarm.nodes.guard import LIMIT_PARAMS, InputGuard, Limits
from flock_swarm.nodes.markers import Telemetry
from flock_swarm.nodes.parameters import COMMON_PARAMS, NodeParameters, Param, init_node
from flock_swarm.nodes.recording import BagSink, RecordedNode
from flock_swarm.nodes.spin import run_node
from flock_swarm.nodes.stepper import (SETTING_PARAMS, CommandInbox, Observation,
                                       WorldSettings, WorldStepper)
from flock_swarm.nodes.wire import (OdometryBatchEncoder, decode_accel, decode_odometry,
                                    encode_clock)
from flock_swarm.outputs import (SpooledRecorder, json_text, write_error, write_outputs,
                                 write_text)


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
          'start (-1: one per node hosting agents)'),
    Param('expect_telemetry_subscribers', 0, 'subscribers /swarm/markers and /swarm/metrics '
          'must have before the start (a live-view bridge: 1)', lambda v: v >= 0,
          'must be 0 or more, not {value}'),
) + LIMIT_PARAMS


class WorldNode(RecordedNode):
    """Integrates the swarm, publishes odometry and ``/clock``, records everything."""

    def __init__(self, progress: Callable[[str], None] | None = None, **kwargs) -> None:
        """Create the node.

        :param progress: called with a one-line status every two seconds (the runner prints
            it); ``None`` logs it instead.
        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        init_node(super().__init__, 'world', kwargs)
        params = self.params = NodeParameters(self, WORLD_PARAMS)
        sc = self.scenario = params.load_scenario()
        self.progress = progress
        self.mode = params['mode']
        settings = WorldSettings.from_parameters(params.values, self.mode == 'lockstep')
        self.lockstep = settings.lockstep
        self.record = params['record']
        self.expect_subscribers = params['expect_subscribers']
        self.expect_telemetry = params['expect_telemetry_subscribers']
        out_dir = params['out_dir']
        self.out = Path(out_dir) if out_dir else Path('out') / f'{sc.name}_ros'
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
        self.odom_encoder = OdometryBatchEncoder([f'agent_{i}' for i in range(sc.n_agents)])
        self.state_topics = [pub.topic_name for pub in [self.clock_pub] + self.odom_pubs]
        # The current step's serialised /clock and odometry, offered again if it stalls.
        self.step_bytes: list[tuple] = []
        self.telemetry = Telemetry(self, sc.law.radius, self.stepper.real.agents.informed)
        subscribe = self.recorded_subscription
        self.cmd_handlers = [lambda msg, i=i: self.on_command(i, msg)
                             for i in range(sc.n_agents)]
        self.cmd_topics = [subscribe(AccelStamped, cmd_topic(i), decode_accel,
                                     self.cmd_handlers[i],
                                     (lambda data, i=i: self.queue_command(i, data))
                                     if self.lockstep else None)
                           for i in range(sc.n_agents)]
        # Lockstep: a step's commands are queued as bytes and taken at once (take_commands).
        self.inbox = CommandInbox(self.stepper, self.guard, self.cmd_topics)
        self.create_timer(1.0, self.check_claims)
        self.leader_odom_topic = subscribe(Odometry, LEADER_ODOM, decode_odometry,
                                           self.on_leader_odom)
        self.leader_accel_topic = subscribe(AccelStamped, LEADER_ACCEL, decode_accel,
                                            self.on_leader_accel)
        self.create_subscription(DiagnosticArray, FAULTS, self.on_fault, qos_profile(FAULTS_QOS))
        self.timer = self.create_timer(0.01, self.on_lockstep_timer) if self.lockstep else \
            self.create_timer(params.timer_period(sc.dt), self.on_realtime_timer)

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
            t_ns, topics = self.clock.ns(k), self.cmd_topics
            for i, data in queue:
                self.record_message(topics[i], data, t_ns)
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
        duplicate agent_id); fail the run when a peer that answered before has been gone
        from the ROS graph for ``peer_timeout`` seconds."""
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

    def publish_states(self, t_ns: int) -> None:
        """Publish ``/clock`` and every agent's odometry for time ``t_ns``, and record them."""
        st = self.stepper
        sent = [(self.clock_pub, encode_clock(t_ns))]
        sent += zip(self.odom_pubs, self.odom_encoder.encode(t_ns, st.q, st.p))
        for pub, data in sent:
            pub.publish(data)
        for sink in self.sinks:
            for name, (_, data) in zip(self.state_topics, sent):
                sink.write(name, data, t_ns)
            sink.flush()
        self.step_bytes = sent

    def go_on(self, obs: Observation) -> None:
        """After a step observed: finish after the last, else integrate (or diverge)."""
        self.telemetry.emit(obs, self.guard.counts())
        line = self.stepper.progress_line(time.monotonic())
        if line is not None:
            (self.progress or self.get_logger().info)(line)
        if obs.last:
            self.finish('completed')
        elif not self.done and not self.stepper.advance(obs.u):
            self.finish('diverged')

    # -- lockstep -----------------------------------------------------------------------------

    def ready_to_start(self) -> bool:
        """Return whether every agent and the leader are discovered and subscribed."""
        if self.expect_subscribers < 0:
            need = agent_hosts(self, self.scenario.n_agents)
            if need is None:
                return False
        else:
            need = self.expect_subscribers
            if any(self.count_publishers(t) < 1 for t in self.cmd_topics):
                return False
        if any(pub.get_subscription_count() < need for pub in self.odom_pubs):
            return False
        if any(pub.get_subscription_count() < self.expect_telemetry
               for pub in (self.telemetry.marker_pub, self.telemetry.metrics_pub)):
            return False
        return (self.count_publishers(self.leader_odom_topic) >= 1
                and self.clock_pub.get_subscription_count() >= 1)

    def on_lockstep_timer(self) -> None:
        """Start when everybody is there; turn an expired step into zero commands.

        Queued commands are taken one by one once the queue stopped growing for a tick (an
        agent is missing, or a message was doubled), and before a step times out.
        """
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
            for pub, data in self.step_bytes:
                pub.publish(data)

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
            self.begin_step()

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
        result = self.stepper.result(time.monotonic(), self.guard.counts(),
                                     sorted(self.duplicates), self.bag_error,
                                     str(self.out / 'bag') if self.record else None)
        for sink in self.sinks:
            try:
                sink.close()
            except OSError as exc:
                self.get_logger().error(f'cannot finalise {sink}: {exc.strerror or exc}; its '
                                        'complete chunks stay readable')
        if result is None:
            self.spool.discard()
            return
        self.result = result
        try:
            self.written = write_outputs(result, self.out, self.scenario)
        except OSError as exc:
            self.outputs_failed(exc)
        else:
            self.spool.discard()

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

    def close(self) -> None:
        """Called on shutdown: keep what was recorded (status ``interrupted``), and let the
        announcement of the end reach the leader and agents before the node goes."""
        if self.stepper.end('interrupted'):
            self.write_results()
        self.status_pub.wait_for_all_acked(Duration(seconds=2))


def main(args: list[str] | None = None) -> int:
    """Run the world node (``ros2 run flock_swarm world``); it exits after the last step.

    The exit status is 2 for invalid configuration, 1 when the run failed (a fault of a law,
    a leader model or a node), when recording failed or an output could not be written,
    else 0.
    """
    built: list[WorldNode] = []
    status = run_node('world', lambda: built.append(WorldNode()) or built[0], args,
                      until=lambda node: node.done)
    failed = built and (built[0].status in ('recording_failed', 'failed')
                        or built[0].bag_error or built[0].write_error)
    return 1 if status == 0 and failed else status


if __name__ == '__main__':
    sys.exit(main())
