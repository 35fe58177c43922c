"""The virtual leader node: publishes ``/leader/odom`` and ``/leader/accel`` every tick.

Lockstep mode: driven by ``/clock``; on tick ``t_k`` the leader advances its model to step
``k`` (RK4, the same :class:`~flock_swarm.core.leaders.base.VirtualLeader` as ``sim``) and
publishes its state stamped ``t_k``. Realtime mode: a wall-clock timer of period ``dt``
advances and publishes.

A model that raises, or returns an acceleration of the wrong shape (or a non-finite one at a
finite state), is not broadcast: the node reports the fault to the world on ``swarm/faults``
(:class:`~flock_swarm.nodes.fault_report.FaultReporter`), logs one line and exits with
status 1, and the world ends the run as ``failed``.
"""

import sys
import time

from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from flock_swarm.contract import (CLOCK, CLOCK_QOS, LEADER_ACCEL, LEADER_ODOM, LOCKSTEP_QOS,
                                  qos_profile)
from flock_swarm.core.faults import RunFault, advance_leader, leader_state
from flock_swarm.core.leaders.base import VirtualLeader
from flock_swarm.nodes.clock import StepClock
from flock_swarm.nodes.fault_report import FaultReporter
from flock_swarm.nodes.ros_graph import agent_hosts, follow_world
from flock_swarm.nodes.parameters import (COMMON_PARAMS, KEEP_RUNNING, NodeParameters, Param,
                                          init_node)
from flock_swarm.nodes.spin import run_node, wall_timer
from flock_swarm.nodes.wire import AccelEncoder, OdometryEncoder

#: The leader's parameters, in the order they are read and checked.
LEADER_PARAMS = COMMON_PARAMS + (
    Param('expect_subscribers', -1, 'subscribers each leader topic must have before the first '
          'tick is answered (given as -1: the world plus one per node hosting agents; reads '
          'back as that number once the leader has found them)'),
    Param('start_timeout', 30.0, 'seconds to wait for expect_subscribers'),
    KEEP_RUNNING,
)


class LeaderNode(Node):
    """Publishes the virtual leader's state ``(q_gamma, p_gamma, f_gamma)``."""

    def __init__(self, **kwargs) -> None:
        """Create the node; ``kwargs`` go to :class:`rclpy.node.Node` (context, namespace...)."""
        init_node(super().__init__, 'leader', kwargs)
        params = self.params = NodeParameters(self, LEADER_PARAMS)
        self.scenario = sc = params.load_scenario()
        # expect_subscribers: -1 reads back the number waited for, once it is known.
        params.will_settle('expect_subscribers')
        params.declare()
        self.clock = StepClock(sc.dt)
        self.model = VirtualLeader(sc.leader.model, sc.leader.position, sc.leader.velocity)
        self.step = 0
        self.target = -1
        # Lockstep: hold the first tick until every agent and the world have matched the
        # leader's topics, so nobody misses step 0 (bounded by start_timeout).
        self.expect = params['expect_subscribers']
        self.start_timeout = params['start_timeout']
        self.matched = False
        self.t0 = time.monotonic()
        self.world_finished = follow_world(self, params['keep_running'])
        qos = qos_profile(LOCKSTEP_QOS)
        self.odom_pub = self.create_publisher(Odometry, LEADER_ODOM, qos)
        self.accel_pub = self.create_publisher(AccelStamped, LEADER_ACCEL, qos)
        self.odom_encoder, self.accel_encoder = OdometryEncoder('leader'), AccelEncoder()
        self.reporter = FaultReporter(self)
        #: The line of the model's fault that ended this node's part of the run, or ``None``.
        self.failure: str | None = None
        if params['mode'] == 'lockstep':
            self.create_subscription(Clock, CLOCK, self.on_clock, qos_profile(CLOCK_QOS))
            self.retry = wall_timer(self, 0.01, self.flush)
        else:
            wall_timer(self, params.timer_period(sc.dt), self.on_timer)

    def on_clock(self, msg: Clock) -> None:
        """Advance to the tick's step and publish (a repeated tick republishes)."""
        k = self.clock.step_of(msg.clock)
        if k < self.step:
            self.get_logger().warning(f'clock went back to step {k} (at {self.step}); ignored')
            return
        self.target = k
        self.flush()

    def flush(self) -> None:
        """Answer the latest tick once the subscribers are matched (or waited long enough)."""
        if self.target < 0:
            return
        if not self.matched:
            need = self.expect
            if need < 0:
                hosts = agent_hosts(self, self.scenario.n_agents)
                need = None if hosts is None else hosts + 1
            counts = (self.odom_pub.get_subscription_count(),
                      self.accel_pub.get_subscription_count())
            waited = time.monotonic() - self.t0
            if (need is None or min(counts) < need) and waited < self.start_timeout:
                return
            if need is not None and self.expect < 0:
                self.params.settle('expect_subscribers', need)
            self.matched = True
            self.retry.cancel()
        target, self.target = self.target, -1
        self.guarded(self.answer_tick, target)

    def answer_tick(self, target: int) -> None:
        """Advance the model to step ``target`` and publish its state."""
        self.advance_to(target)
        self.publish()

    def advance_to(self, target: int) -> None:
        """Advance the model to step ``target``."""
        while self.step < target:
            advance_leader(self.model, self.scenario.dt, self.step, self.scenario.dim)
            self.step += 1

    def on_timer(self) -> None:
        """Realtime mode: publish the current state, then advance one step."""
        self.guarded(self.publish_and_advance)

    def publish_and_advance(self) -> None:
        """Realtime mode: publish the current state, then advance one step."""
        self.publish()
        self.advance_to(self.step + 1)

    def guarded(self, act, *args) -> None:
        """Do ``act(*args)`` unless the model failed before; report its fault, and stop, if
        it fails now."""
        if self.failure is not None:
            return
        try:
            act(*args)
        except RunFault as fault:
            self.failure = self.reporter.report(fault, self.clock.stamp(fault.step)).line

    def close(self) -> None:
        """Let a fault report reach the world (called on shutdown)."""
        if self.failure is not None:
            self.reporter.wait_acknowledged()

    def publish(self) -> None:
        """Publish the state of the current step (serialised by :mod:`flock_swarm.nodes.wire`).

        :raises RunFault: when the model's acceleration is not one to broadcast.
        """
        state = leader_state(self.model, self.step, self.scenario.dim)
        ns = self.clock.ns(self.step)
        self.odom_pub.publish(self.odom_encoder.encode(ns, state.q.tolist(), state.p.tolist()))
        self.accel_pub.publish(self.accel_encoder.encode(ns, state.a.tolist()))


def main(args: list[str] | None = None) -> int:
    """Run the leader node (``ros2 run flock_swarm leader``)."""
    built: list[LeaderNode] = []
    status = run_node('leader', lambda: built.append(LeaderNode()) or built[0], args,
                      until=lambda node: node.world_finished() or node.failure is not None,
                      completed=lambda node: node.world_finished.completed())
    return 1 if status == 0 and built and built[0].failure is not None else status


if __name__ == '__main__':
    sys.exit(main())
