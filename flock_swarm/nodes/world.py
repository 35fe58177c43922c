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
:class:`~flock_swarm.nodes.stepper.WorldStepper` (no ROS); this node is its plumbing, by
concern: the message paths of the state out and the commands in
(:mod:`flock_swarm.nodes.world_io`), the other inputs (:mod:`flock_swarm.nodes.world_inputs`),
the peers on the ROS graph (:mod:`flock_swarm.nodes.world_peers`), the outputs and the end
(:mod:`flock_swarm.nodes.world_end`), telemetry (:mod:`flock_swarm.nodes.markers`).
"""

import math
import sys
import time
from typing import Callable

from std_msgs.msg import String

from flock_swarm.console import EXIT_USAGE
from flock_swarm.contract import RUNNING, STATUS, STATUS_QOS, qos_profile
from flock_swarm.nodes.batch import MESSAGE_PATH, use_c_path
from flock_swarm.nodes.cloud import BATCHED
from flock_swarm.nodes.transport import (TRANSPORT, BatchedCommandIntake,
                                         batched_state_publisher, transport_of)
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.guard import LIMIT_PARAMS, InputGuard, Limits
from flock_swarm.nodes.markers import Telemetry
from flock_swarm.nodes.parameters import COMMON_PARAMS, NodeParameters, Param, init_node
from flock_swarm.nodes.recording import RecordedNode
from flock_swarm.nodes.spin import run_node, wall_timer
from flock_swarm.nodes.stepper import Observation, WorldStepper
from flock_swarm.nodes.world_end import WorldEnd
from flock_swarm.nodes.world_inputs import WorldInputs
from flock_swarm.nodes.world_io import command_intake, state_publisher
# WAIT_LOG_EVERY and id_list: the start's wait, importable from here as before.
from flock_swarm.nodes.world_peers import WAIT_LOG_EVERY, WorldPeers, id_list  # noqa: F401
from flock_swarm.nodes.world_settings import SETTING_PARAMS, WorldSettings

#: Why the world refuses ``use_sim_time:=true`` (and how the parameter reads back).
SIM_TIME_REFUSED = ('must be false: the world publishes /clock itself (it is the simulation '
                    'clock); the leader and the agents accept either value')


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
) + LIMIT_PARAMS + (MESSAGE_PATH, TRANSPORT)


class WorldNode(WorldInputs, WorldPeers, WorldEnd, RecordedNode):
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
        # The transport (nodes/transport.py): a topic per agent, or the swarm's state as
        # one message and each agents host's commands as one.
        self.batched = transport_of(sc, params['transport'], self.mode) == BATCHED
        self.init_waiting(params)
        # expect_subscribers: -1 reads back the number waited for, once it is known.
        params.will_settle('expect_subscribers')
        self.open_outputs(params['out_dir'])
        self.stepper = WorldStepper(sc, settings, self.get_logger(), recorder=self.spool)
        self.clock = StepClock(sc.dt)
        self.guard = InputGuard(self.clock, Limits.from_parameters(params.values),
                                self.get_logger().warning)
        self.open_bag()
        # Not recorded: the bag's own end (and summary.json) tell a replay how the run ended.
        self.status_pub = self.create_publisher(String, STATUS, qos_profile(STATUS_QOS))
        self.status_pub.publish(String(data=RUNNING))
        self.state_out = batched_state_publisher(self, self.stepper) if self.batched else \
            state_publisher(self, self.stepper, self.c_path)
        self.telemetry = Telemetry(self, sc.law.radius, self.stepper.real.agents.informed,
                                   sc.headline, sc.obstacles)
        self.intake = BatchedCommandIntake(self, self.stepper, self.step_may_close) \
            if self.batched else command_intake(self, self.stepper, self.step_may_close,
                                                self.c_path)
        self.subscribe_agents(per_agent=not self.batched)
        wall_timer(self, 1.0, self.check_claims)
        self.subscribe_leader()
        self.publish_provenance()
        self.timer = wall_timer(self, 0.01, self.on_lockstep_timer) if self.lockstep else \
            wall_timer(self, params.timer_period(sc.dt), self.on_realtime_timer)

    # The stepper's state and the message paths' topics, as the runner and the tests read
    # them off the node.
    k = property(lambda self: self.stepper.k, doc='The open step.')
    done = property(lambda self: self.stepper.done, doc='Whether the run has ended.')
    status = property(lambda self: self.stepper.status, doc='How the run ended (or running).')
    leader_lost = property(lambda self: self.stepper.leader.lost, doc='The leader is lost.')
    bag_error = property(lambda self: None if self.bag is None else self.bag.error,
                         doc='Why recording failed, or ``None``.')
    steps_at_once = property(lambda self: self.intake.inbox.steps_at_once,
                             doc='Steps whose commands were taken in one pass.')
    clock_pub = property(lambda self: self.state_out.clock_pub, doc='``/clock``.')
    odom_pubs = property(lambda self: self.state_out.odom_pubs, doc='The state publishers.')
    cmd_topics = property(lambda self: self.intake.topics, doc="The agents' command topics.")
    cmd_take = property(lambda self: getattr(self.intake, 'take_all', None),
                        doc="The compiled path's hold on the command subscriptions.")

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
        if self.intake.stalled():
            self.intake.take()
            return
        due = self.stepper.tick(time.monotonic(), self.ready_to_start)
        if due == 'timeout' and len(self.intake):
            k = self.k
            self.intake.take()
            if self.k != k or self.done:
                return
        if due == 'begin':
            self.begin_step()
        elif due == 'timeout':
            self.finish_step(timed_out=True)
        elif due == 'resend':
            # Offered again, not recorded again (see LockstepStepper.resent).
            self.state_out.resend()

    def begin_step(self) -> None:
        """Publish ``/clock`` and every odometry for the current step."""
        self.stepper.begin_step(time.monotonic())
        self.state_out.publish(self.clock.ns(self.k))

    def step_may_close(self) -> None:
        """Close the open lockstep step once it is complete (every input in)."""
        if self.stepper.complete():
            self.finish_step(timed_out=False)

    def finish_step(self, timed_out: bool) -> None:
        """Close the current step: zero commands for absentees, record, integrate, go on
        (or fail, when agents have stopped answering: ``LockstepStepper.silent_agents``)."""
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
        self.state_out.publish(self.clock.ns(st.k))
        self.go_on(st.realtime_close(now, time.monotonic()))

    def destroy_node(self) -> None:
        """Release the compiled path's hold on the subscriptions and publishers, then
        destroy the node."""
        # getattr: a node whose construction failed has neither.
        for path in (getattr(self, 'intake', None), getattr(self, 'state_out', None)):
            if path is not None:
                path.release()
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
