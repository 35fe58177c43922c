"""The world node: integrates every agent, publishes odometry and ``/clock``, records the bag.

Lockstep mode (default, deterministic): for step ``k`` the world publishes ``/clock`` ``t_k``
and every ``/agent_<i>/odom`` stamped ``t_k``, then waits until every agent's
``cmd_accel`` and the leader's state for ``t_k`` are in, or the per-step timeout expires (a
late or missing agent gets a zero command: counted, logged, published on ``/swarm/metrics``
and recorded). It then integrates exactly (the same :func:`step_agents` as ``sim``) to
``t_{k+1}``. Realtime mode: a wall-clock timer steps with the latest commands (zero-order
hold).

Every message the world publishes or receives is written to a rosbag2-compatible MCAP bag
in ``out_dir/bag``, with the scenario, seed and informed set as MCAP metadata; the run's
``summary.json`` and ``timeseries.npz`` go to ``out_dir``.
"""

import json
import os
import sys
import time
from itertools import groupby
from operator import itemgetter
from pathlib import Path
from typing import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from visualization_msgs.msg import MarkerArray

from flock_swarm import __version__
from flock_swarm.core.dynamics import LeaderState, step_agents
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.metrics import step_metrics
from flock_swarm.core.scenario import realize
from flock_swarm.core.run import RunLog, SimResult, build_summary
from flock_swarm.nodes.common import (CLOCK, CLOCK_QOS, COMMON_PARAMS, FRAME, LEADER_ACCEL,
                                      LEADER_ODOM, LOCKSTEP_QOS, MARKERS, METRICS,
                                      TELEMETRY_QOS, LatencyHistogram, StepClock, agent_hosts,
                                      claimants, cmd_topic, declare, declare_common,
                                      load_scenario, odom_topic, run_node, timer_period)
from flock_swarm.nodes.guard import LIMIT_PARAMS, InputGuard, declare_limits
from flock_swarm.nodes.wire import (MalformedMessage, OdometryEncoder, decode_accel,
                                    decode_odometry, encode_clock)
from flock_swarm.nodes.markers import OK, WARN, metrics_message, swarm_markers_cdr
from flock_swarm.outputs import SpooledRecorder, json_text, write_outputs

#: Seconds after which a stalled lockstep step is first offered again (see ``resend_step``).
RESEND_PERIOD = 0.5
#: A step is stalled only once it has taken this many times as long as the step before it,
#: and each further offer of the same step waits twice as long as the last.
RESEND_SLOWER = 3.0


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


WORLD_PARAMS = COMMON_PARAMS | LIMIT_PARAMS | {
    'out_dir', 'record', 'step_timeout', 'start_timeout', 'marker_every', 'metrics_every',
    'expect_subscribers', 'staleness', 'bag_max_size', 'bag_max_duration'}


class WorldNode(Node):
    """Integrates the swarm, publishes odometry and ``/clock``, records everything."""

    def __init__(self, progress: Callable[[str], None] | None = None, **kwargs) -> None:
        """Create the node.

        :param progress: called with a one-line status every two seconds (the runner prints
            it); ``None`` logs it instead.
        :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
        """
        kwargs.setdefault('automatically_declare_parameters_from_overrides', True)
        super().__init__('world', **kwargs)
        declare_common(self)
        out_dir = declare(self, 'out_dir', '', 'directory for bag/, summary.json and '
                          'timeseries.npz (empty: out/<scenario>_ros)')
        self.record = declare(self, 'record', True, 'write the MCAP bag')
        self.bag_max_size = declare(self, 'bag_max_size', 0,
                                    'split the bag into bag_0.mcap, bag_1.mcap, ... once a '
                                    'file is larger than this many bytes (0: no split)')
        self.bag_max_duration = declare(self, 'bag_max_duration', 0.0,
                                        'split the bag once a file spans more than this many '
                                        'seconds of simulation time (0: no split)')
        self.step_timeout = declare(self, 'step_timeout', 2.0,
                                    'lockstep: seconds to wait for commands before a missing '
                                    'agent gets a zero command')
        self.start_timeout = declare(self, 'start_timeout', 30.0,
                                     'lockstep: seconds to wait for agents and leader to '
                                     'appear and answer step 0 before starting anyway')
        self.marker_every = declare(self, 'marker_every', 10, 'publish markers every N steps')
        self.metrics_every = declare(self, 'metrics_every', 10, 'publish metrics every N steps')
        self.expect_subscribers = declare(self, 'expect_subscribers', -1,
                                          'subscribers each odometry topic must have before '
                                          'the start (-1: one per node hosting agents)')
        self.staleness = declare(self, 'staleness', 0.5,
                                 'realtime: seconds a held command (or the leader state) '
                                 'stays valid; an older command counts as missing (zero), '
                                 'an older leader state as lost')
        for key, value, ok in (('step_timeout', self.step_timeout, self.step_timeout > 0),
                               ('start_timeout', self.start_timeout, self.start_timeout >= 0),
                               ('marker_every', self.marker_every, self.marker_every >= 1),
                               ('metrics_every', self.metrics_every, self.metrics_every >= 1),
                               ('staleness', self.staleness, self.staleness > 0),
                               ('bag_max_size', self.bag_max_size, self.bag_max_size >= 0),
                               ('bag_max_duration', self.bag_max_duration,
                                0 <= self.bag_max_duration < float('inf'))):
            if not ok:
                raise ScenarioError(key, f'invalid value {value!r}')
        sc = self.scenario = load_scenario(self, WORLD_PARAMS)
        self.progress = progress
        self.lockstep = self.get_parameter('mode').value == 'lockstep'
        self.out = Path(out_dir) if out_dir else Path('out') / f'{sc.name}_ros'
        self.real = realize(sc)
        self.q, self.p = self.real.q0.copy(), self.real.p0.copy()
        self.intrinsic = sc.intrinsic.build() if sc.intrinsic is not None else None
        self.clock = StepClock(sc.dt)
        n = sc.n_agents
        self.k = 0
        self.commands: dict[int, np.ndarray] = {}
        self.held = np.zeros((n, sc.dim))
        self.leader_odom: dict[int, tuple] = {}
        self.leader_accel: dict[int, np.ndarray] = {}
        self.last_leader = LeaderState(sc.leader.position.copy(), sc.leader.velocity.copy(),
                                       np.zeros(sc.dim))
        self.missed = np.zeros(n, dtype=int)
        self.leader_missed = 0
        self.leader_lost = False
        self.leader_events: list[list] = []
        self.leader_seen_at = -np.inf
        self.held_at = np.full(n, -np.inf)
        self.stale_agents: set[int] = set()
        self.duplicates: set[int] = set()
        self.guard = InputGuard(self.clock, declare_limits(self), self.get_logger().warning)
        self.bag_error: str | None = None
        # Messages waiting for the bag: (topic, data, t_ns), written once a step.
        self.records: list[tuple[str, bytes, int]] = []
        self.last_missing: set[int] = set()
        # Realtime: wall time each step's odometry went out, and how long commands took.
        self.published_at: dict[int, float] = {}
        self.latency = LatencyHistogram()
        self.done = False
        self.started = False
        self.status = 'running'
        self.deadline = 0.0
        self.resend_at = 0.0
        self.resend_wait = RESEND_PERIOD
        self.resends = 0
        self.step_began = 0.0
        self.last_step_s = 0.0
        self.t_created = self.t_wall0 = time.monotonic()
        self.t_last_progress = self.t_wall0
        self.metrics_now: dict = {}

        self.bag = self._open_bag() if self.record else None
        # The time series goes to disk as it is recorded: memory stays flat on long runs.
        try:
            self.log = RunLog.for_scenario(sc, SpooledRecorder(self.out))
        except OSError as exc:
            raise ScenarioError('out_dir', f'cannot write to {self.out}: {exc.strerror}') \
                from None
        self.clock_pub = self._publisher(Clock, CLOCK, CLOCK_QOS)
        self.odom_pubs = [self._publisher(Odometry, odom_topic(i), LOCKSTEP_QOS)
                          for i in range(n)]
        self.odom_encoders = [OdometryEncoder(f'agent_{i}') for i in range(n)]
        self.state_topics = [pub.topic_name for pub in [self.clock_pub] + self.odom_pubs]
        # The current step's serialised /clock and odometry, offered again by resend_step.
        self.step_bytes: list[tuple] = []
        self.marker_pub = self._publisher(MarkerArray, MARKERS, TELEMETRY_QOS)
        self.metrics_pub = self._publisher(DiagnosticArray, METRICS, TELEMETRY_QOS)
        self.cmd_topics = [self._subscribe(AccelStamped, cmd_topic(i), decode_accel,
                                           lambda msg, i=i: self.on_command(i, msg))
                           for i in range(n)]
        self.create_timer(1.0, self.check_claims)
        self.leader_odom_topic = self._subscribe(Odometry, LEADER_ODOM, decode_odometry,
                                                 self.on_leader_odom)
        self.leader_accel_topic = self._subscribe(AccelStamped, LEADER_ACCEL, decode_accel,
                                                  self.on_leader_accel)
        if self.lockstep:
            self.timer = self.create_timer(0.01, self.on_lockstep_timer)
        else:
            self.timer = self.create_timer(timer_period(self, sc.dt), self.on_realtime_timer)

    # -- recording ----------------------------------------------------------------------------

    def _open_bag(self):
        from flock_swarm.bag import (BagWriter, DefinitionNotFoundError, message_definition,
                                     type_name_of)
        path = self.out / 'bag'
        if path.exists() and any(path.iterdir()):
            raise ScenarioError('out_dir', f'{path} already holds a bag; choose another out_dir')
        # Every schema is found before the bag file exists: a failure leaves nothing behind.
        for msg_type in (Clock, Odometry, AccelStamped, MarkerArray, DiagnosticArray):
            try:
                message_definition(type_name_of(msg_type))
            except DefinitionNotFoundError as exc:
                raise ScenarioError('record', f'{exc} (AMENT_PREFIX_PATH='
                                    f'{os.environ.get("AMENT_PREFIX_PATH", "")!r}); '
                                    'set it to the prefixes holding the ROS message '
                                    'packages, or -p record:=false') from None
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            bag = BagWriter(path, max_bagfile_size=self.bag_max_size,
                            max_bagfile_duration=self.bag_max_duration)
        except OSError as exc:
            raise ScenarioError('out_dir', f'cannot write to {self.out}: {exc.strerror}') \
                from None
        sc = self.scenario
        bag.add_metadata('flock_swarm', {
            'scenario': json_text(sc.raw, indent=None).strip(),
            'scenario_name': sc.name,
            'seed': str(sc.seed),
            'informed': json.dumps(self.real.informed_ids),
            'mode': self.get_parameter('mode').value,
            'flock_swarm_version': __version__,
        })
        return bag

    def _record_topic(self, name: str, msg_type, qos) -> None:
        if self.bag is not None:
            self.bag.add_topic(name, msg_type, qos)

    def _publisher(self, msg_type, topic: str, qos):
        pub = self.create_publisher(msg_type, topic, qos)
        self._record_topic(pub.topic_name, msg_type, qos)
        return pub

    def _publish(self, pub, msg, t_ns: int) -> None:
        """Publish ``msg`` (a message, or its bytes) and record it: the same bytes for both."""
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        pub.publish(data)
        self._write(pub.topic_name, data, t_ns)

    def _write(self, topic: str, data: bytes, t_ns: int) -> None:
        """Queue a message for the bag (written by :meth:`flush_records`, once a step)."""
        if self.bag is not None:
            self.records.append((topic, data, t_ns))

    def flush_records(self) -> None:
        """Write the queued messages, in the order they were queued, a run of equal times at
        once (:meth:`~flock_swarm.bag.BagWriter.write_serialized_many`)."""
        queue, self.records = self.records, []
        if self.bag is None or not queue:
            return
        try:
            for t_ns, run in groupby(queue, key=itemgetter(2)):
                self.bag.write_serialized_many([(topic, data) for topic, data, _ in run], t_ns)
        except OSError as exc:
            self.recording_failed(exc)

    def recording_failed(self, exc: OSError) -> None:
        """Stop the run cleanly when the bag cannot be written (a full disk, say).

        The bag is left as it is on disk: every chunk completed before the failure is
        readable (``analyze`` says how much it recovered), and no ``metadata.yaml`` claims it
        complete. The run ends with status ``recording_failed``.
        """
        self.bag_error = f'{exc.strerror or exc} ({self.out / "bag"})'
        self.get_logger().error(f'recording failed: {self.bag_error}; stopping the run, the '
                                'bag keeps every chunk written before')
        bag, self.bag = self.bag, None
        try:
            bag.abandon()
        except OSError:
            pass
        self.finish('recording_failed')

    def _subscribe(self, msg_type, topic: str, decode: Callable, handler: Callable) -> str:
        """Subscribe to ``topic``; record each message as received, then hand it on.

        The subscription takes the serialised bytes, so the bag stores what came over the
        wire (faulty messages included) without serialising it again; ``handler`` gets
        ``decode(data)`` (:mod:`flock_swarm.nodes.wire`: its first item is the stamp [ns]).
        Bytes that are no message of the type are recorded at the open step and rejected
        (``malformed``). Return the resolved topic name.
        """
        def on_data(data: bytes) -> None:
            try:
                msg = decode(data)
            except MalformedMessage as exc:
                self._write(name, data, self.clock.ns(self.k))
                self.guard.reject(name, 'malformed', str(exc))
                return
            self._write(name, data, self.clock.ns(max(self.clock.step_at(msg[0]), 0)))
            handler(msg)

        name = self.create_subscription(msg_type, topic, on_data, LOCKSTEP_QOS,
                                        raw=True).topic_name
        self._record_topic(name, msg_type, LOCKSTEP_QOS)
        return name

    # -- inputs -------------------------------------------------------------------------------

    def on_command(self, i: int, msg: tuple) -> None:
        """Check and store agent ``i``'s command ``(stamp_ns, frame_id, linear)`` (lockstep:
        for the current step; realtime: held)."""
        ns, frame, lin = msg
        topic = self.cmd_topics[i]
        k = self.guard.check(topic, ns, frame, ((lin, self.guard.limits.accel),),
                             window=self.window())
        if k is None:
            return
        u = lin[:self.scenario.dim]
        if not self.lockstep:
            now = time.monotonic()
            self.held[i] = u
            self.held_at[i] = now
            sent = self.published_at.get(k)
            if sent is not None:
                self.latency.add(now - sent)
        elif not self.started or self.done:
            return
        elif k == self.k:
            self.commands[i] = u
            self._maybe_finish()
        elif i in self.last_missing:
            # The step just closed went without this command: it came too late. (A repeated
            # command for that step, after the world re-offered it, is no fault.)
            self.guard.reject(topic, 'late', f'a command for step {k} at step {self.k}')

    def window(self) -> tuple[int, int] | None:
        """Return the steps whose inputs the world accepts now (lockstep: the open step and
        the one just closed; realtime: any)."""
        return (self.k - 1, self.k) if self.lockstep else None

    def on_leader_odom(self, msg: tuple) -> None:
        """Check and store the leader's position and velocity of its step (``msg``: see
        :func:`~flock_swarm.nodes.wire.decode_odometry`)."""
        ns, frame, child, pos, vel = msg
        lim = self.guard.limits
        k = self.guard.check(self.leader_odom_topic, ns, frame,
                             ((pos, lim.position), (vel, lim.velocity)), (child, 'leader'),
                             self.window())
        if k is not None:
            self.leader_heard(k)
            dim = self.scenario.dim
            self.leader_odom[k] = (np.array(pos[:dim]), np.array(vel[:dim]))
            self._maybe_finish()

    def on_leader_accel(self, msg: tuple) -> None:
        """Check and store the leader's acceleration of its step."""
        ns, frame, lin = msg
        k = self.guard.check(self.leader_accel_topic, ns, frame,
                             ((lin, self.guard.limits.accel),), window=self.window())
        if k is not None:
            self.leader_heard(k)
            self.leader_accel[k] = np.array(lin[:self.scenario.dim])
            self._maybe_finish()

    def leader_heard(self, k: int) -> None:
        """Note a leader message; a lost leader is back (logged, recorded in the metrics)."""
        self.leader_seen_at = time.monotonic()
        if self.leader_lost and self.started:
            self.leader_lost = False
            self.leader_events.append([self.k, 'back'])
            self.get_logger().info(f'leader back at step {self.k} (its state of step {k})')

    def lose_leader(self) -> None:
        """Note that the leader is gone (logged, recorded in the metrics)."""
        if not self.leader_lost:
            self.leader_lost = True
            self.leader_events.append([self.k, 'lost'])
            self.get_logger().warning(f'leader lost at step {self.k}: steps go on without '
                                      'waiting for it')

    def check_claims(self) -> None:
        """Report two nodes publishing commands for the same agent (a duplicate agent_id)."""
        for i in range(self.scenario.n_agents):
            nodes = claimants(self, i)
            if len(nodes) > 1 and i not in self.duplicates:
                self.duplicates.add(i)
                names = ', '.join(f'{ns.rstrip("/")}/{name}' for ns, name in nodes)
                self.get_logger().error(f'agent {i} is claimed by {len(nodes)} nodes ({names}): '
                                        'a duplicate agent_id')

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
        return (self.count_publishers(self.leader_odom_topic) >= 1
                and self.clock_pub.get_subscription_count() >= 1)

    def on_lockstep_timer(self) -> None:
        """Start when everybody is there; turn an expired step into zero commands."""
        if self.done:
            return
        now = time.monotonic()
        if not self.started:
            if self.ready_to_start() or now - self.t_created >= self.start_timeout:
                if not self.ready_to_start():
                    self.get_logger().warning('start timeout: starting without every agent '
                                              'or the leader')
                self.started = True
                self.t_wall0 = now
                self.begin_step()
            return
        if now >= self.deadline:
            self.finish_step(timed_out=True)
        elif now >= self.resend_at:
            self.resend_step()

    def resend_step(self) -> None:
        """Publish the current step's ``/clock`` and odometry again (not recorded again).

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
        self.resend_at = time.monotonic() + self.resend_wait
        for pub, data in self.step_bytes:
            pub.publish(data)

    def begin_step(self) -> None:
        """Publish ``/clock`` and every odometry for the current step."""
        self.commands = {}
        now = time.monotonic()
        self.step_began = now
        self.deadline = now + self.step_timeout
        if self.k == 0:
            # Step 0 completes the start: the world has matched the others' endpoints, but
            # an agent's reader may not have matched the world's writers yet (DDS matches
            # each side on its own), so step 0 waits out what is left of start_timeout.
            self.deadline = max(self.deadline, self.t_created + self.start_timeout)
        self.resend_wait = first_resend_wait(self.last_step_s, self.step_timeout)
        self.resend_at = now + self.resend_wait
        self.publish_states(self.clock.ns(self.k))

    def publish_states(self, t_ns: int) -> None:
        """Publish ``/clock`` and every agent's odometry for time ``t_ns``, and record them."""
        sent = [(self.clock_pub, encode_clock(t_ns))]
        sent += [(pub, enc.encode(t_ns, q, p)) for pub, enc, q, p in
                 zip(self.odom_pubs, self.odom_encoders, self.q.tolist(), self.p.tolist())]
        for pub, data in sent:
            pub.publish(data)
        if self.bag is not None:
            self.records += [(name, data, t_ns) for name, (_, data) in
                             zip(self.state_topics, sent)]
            self.flush_records()
        self.step_bytes = sent

    def _maybe_finish(self) -> None:
        if (self.lockstep and self.started and not self.done
                and len(self.commands) == self.scenario.n_agents
                and (self.leader_lost
                     or (self.k in self.leader_odom and self.k in self.leader_accel))):
            self.finish_step(timed_out=False)

    def finish_step(self, timed_out: bool) -> None:
        """Close the current step: zero commands for absentees, record, integrate, go on."""
        sc, k, n = self.scenario, self.k, self.scenario.n_agents
        u = np.zeros((n, sc.dim))
        missing = [i for i in range(n) if i not in self.commands]
        for i, ui in self.commands.items():
            u[i] = ui
        leader_missing = k not in self.leader_odom or k not in self.leader_accel
        if missing:
            self.missed[missing] += 1
            self.get_logger().warning(
                f'step {k}: no command from agent(s) {missing} within {self.step_timeout:g} s; '
                'zero command applied')
        self.last_missing = set(missing)
        if leader_missing:
            self.leader_missed += 1
            self.lose_leader()
        else:
            q_l, p_l = self.leader_odom.pop(k)
            self.last_leader = LeaderState(q_l, p_l, self.leader_accel.pop(k))
        for old in [s for s in self.leader_odom if s < k]:
            del self.leader_odom[old]
        for old in [s for s in self.leader_accel if s < k]:
            del self.leader_accel[old]
        if not timed_out:
            # How long a step takes now (a timed-out step says nothing about that).
            self.last_step_s = time.monotonic() - self.step_began
        self.observe(u, missing)
        if self.done:
            return
        self.advance(u)
        self.begin_step()

    # -- shared stepping ----------------------------------------------------------------------

    def observe(self, u: np.ndarray, missing: list[int]) -> None:
        """Record the state of the current step, publish telemetry, finish after the last."""
        sc, k = self.scenario, self.k
        law = sc.law
        leader = self.last_leader
        stamp, t_ns = self.clock.stamp(k), self.clock.ns(k)
        edges = disk_graph(self.q, law.radius, law.strict_radius)
        last = k >= sc.steps
        now = self.log.observe(k, k * sc.dt, self.q, self.p, u, leader,
                               self.real.agents.informed, edges, law.radius, last)
        if now is not None:
            self.metrics_now = now
        if k % self.marker_every == 0 or last:
            self._publish(self.marker_pub, swarm_markers_cdr(
                self.q, self.p, leader.q, self.real.agents.informed, edges, t_ns, FRAME,
                0.1 * law.radius), t_ns)
        event = bool(self.leader_events) and self.leader_events[-1][0] == k
        if k % self.metrics_every == 0 or missing or last or event:
            if not self.metrics_now:
                self.metrics_now = step_metrics(self.q, self.p, leader, sc.eta_tolerance,
                                                law.radius, law.strict_radius)
            values = dict(self.metrics_now, step=k, missed_commands=int(self.missed.sum()),
                          missed_this_step=json.dumps(missing),
                          leader_missed=self.leader_missed,
                          leader='lost' if self.leader_lost else 'ok',
                          rejected_messages=json.dumps(self.guard.counts()))
            problems = ([f'{len(missing)} missing command(s)'] if missing else []) \
                + (['leader lost'] if self.leader_lost else [])
            self._publish(self.metrics_pub, metrics_message(
                values, stamp, WARN if problems else OK, ', '.join(problems) or 'ok'), t_ns)
        self._progress()
        if last:
            self.finish('completed')

    def advance(self, u: np.ndarray) -> None:
        """Integrate every agent over one step with ``u`` held."""
        self.q, self.p = step_agents(self.q, self.p, u, self.scenario.dt, self.intrinsic)
        self.k += 1
        if not (np.isfinite(self.q).all() and np.isfinite(self.p).all()):
            self.finish('diverged')

    def on_realtime_timer(self) -> None:
        """Realtime mode: step with the latest commands (zero-order hold)."""
        if self.done:
            return
        k = self.k
        t_ns = self.clock.ns(k)
        if k in self.leader_odom and k in self.leader_accel:
            q_l, p_l = self.leader_odom[k]
            self.last_leader = LeaderState(q_l, p_l, self.leader_accel[k])
        elif self.leader_odom:
            latest = max(self.leader_odom)
            if latest in self.leader_accel:
                q_l, p_l = self.leader_odom[latest]
                self.last_leader = LeaderState(q_l, p_l, self.leader_accel[latest])
        for old in [s for s in self.leader_odom if s < k - 10]:
            del self.leader_odom[old]
        for old in [s for s in self.leader_accel if s < k - 10]:
            del self.leader_accel[old]
        now = time.monotonic()
        if not self.started:
            # Staleness counts from the first step, not from the node's construction.
            self.held_at[:] = now
            self.leader_seen_at = max(self.leader_seen_at, now)
        if now - self.leader_seen_at > self.staleness:
            self.lose_leader()
        self.publish_states(t_ns)
        self.published_at[k] = time.monotonic()
        self.published_at.pop(k - 100, None)
        u = self.held.copy()
        stale = np.flatnonzero(now - self.held_at > self.staleness)
        u[stale] = 0.0
        self.missed[stale] += 1
        self.note_stale({int(i) for i in stale})
        self.started = True
        self.observe(u, [int(i) for i in stale])
        if not self.done:
            self.advance(u)

    def note_stale(self, stale: set[int]) -> None:
        """Realtime: log agents whose held command went stale (zero from now) or came back."""
        for i in sorted(stale - self.stale_agents):
            self.get_logger().warning(f'step {self.k}: agent {i} sent no command for '
                                      f'{self.staleness:g} s; zero command until it does')
        for i in sorted(self.stale_agents - stale):
            self.get_logger().info(f'step {self.k}: agent {i} commands again')
        self.stale_agents = stale

    def _progress(self) -> None:
        now = time.monotonic()
        if now - self.t_last_progress < 2.0:
            return
        self.t_last_progress = now
        sc, m = self.scenario, self.metrics_now
        line = (f'[world] t = {self.k * sc.dt:.2f}/{sc.duration:g} s  step {self.k}/{sc.steps}'
                f'  {self.k / max(now - self.t_wall0, 1e-9):.1f} steps/s'
                f'  eta = {m.get("eta", 0.0):.2f}'
                f'  mismatch = {m.get("velocity_mismatch_max", 0.0):.3g}'
                f'  missed = {int(self.missed.sum())}')
        if self.progress is not None:
            self.progress(line)
        else:
            self.get_logger().info(line)

    # -- the end ------------------------------------------------------------------------------

    def finish(self, status: str) -> None:
        """Write ``summary.json`` and ``timeseries.npz``, close the bag; idempotent."""
        if self.done:
            return
        self.done = True
        self.status = status
        self.timer.cancel()
        self.write_results()

    def write_results(self) -> None:
        """Write what was recorded so far (also on an interrupted run)."""
        if not self.log.rec.count:
            self.close_bag()
            return
        series = self.log.rec.arrays()
        summary = build_summary(self.scenario, self.real, series, self.log.metrics, self.k,
                                self.status)
        summary.update({
            'mode': self.get_parameter('mode').value,
            'missed_commands': int(self.missed.sum()),
            'missed_commands_per_agent': [int(x) for x in self.missed],
            'rejected_messages': self.guard.counts(),
            'leader_events': self.leader_events,
            'duplicate_agent_ids': sorted(self.duplicates),
            'bag_error': self.bag_error,
            'command_latency_ms': None if self.lockstep else self.latency.summary_ms(),
            'resent_steps': self.resends,
            'leader_missed': self.leader_missed,
            'wall_time_s': round(time.monotonic() - self.t_wall0, 3),
            'bag': str(self.out / 'bag') if self.record else None,
        })
        self.result = SimResult(summary, series)
        self.close_bag()
        try:
            write_outputs(self.result, self.out, self.scenario)
        except OSError as exc:
            self.get_logger().error(f'cannot write the run\'s outputs to {self.out}: '
                                    f'{exc.strerror or exc}; the time series stays in '
                                    f'{self.log.rec.spool}')
        else:
            self.log.rec.discard()

    def close_bag(self) -> None:
        """Write what is queued, finalise the bag (MCAP summary and metadata.yaml)."""
        self.flush_records()
        if self.bag is not None:
            bag, self.bag = self.bag, None
            try:
                bag.close()
            except OSError as exc:
                self.bag_error = f'{exc.strerror or exc} ({self.out / "bag"})'
                self.get_logger().error(f'cannot finalise the bag: {self.bag_error}; its '
                                        'complete chunks stay readable')

    def close(self) -> None:
        """Called on shutdown: keep what was recorded (status ``interrupted``)."""
        if not self.done:
            self.done = True
            self.status = 'interrupted'
            self.write_results()


def main(args: list[str] | None = None) -> int:
    """Run the world node (``ros2 run flock_swarm world``); it exits after the last step.

    The exit status is 2 for invalid configuration, 1 when recording failed, else 0.
    """
    built = []

    def factory() -> WorldNode:
        built.append(WorldNode())
        return built[0]

    status = run_node('world', factory, args, until=lambda node: node.done)
    if status == 0 and built and (built[0].status == 'recording_failed'
                                  or built[0].bag_error):
        return 1
    return status


if __name__ == '__main__':
    sys.exit(main())
