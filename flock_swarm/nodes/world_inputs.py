"""The world's inputs besides the commands: each message checked, then handed to the stepper.

:class:`WorldInputs` is the part of the world node (:mod:`flock_swarm.nodes.world`) that
subscribes to the optional topic families and the leader, and judges what comes: the
agents' adaptive state (a law with one), what each command used (realtime with the
network model), the robots' velocity commands (``cmd_vel``), the leader's odometry and
acceleration, and the faults the nodes report on ``swarm/faults``. Every message is
recorded as received (:meth:`~flock_swarm.nodes.recording.RecordedNode.recorded_subscription`)
and checked by the input guard before the stepper sees it.
"""

import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState

from flock_swarm.contract import (FAULTS, FAULTS_QOS, LEADER_ACCEL, LEADER_ODOM,
                                  cmd_vel_topic, network_topic, qos_profile, state_topic)
from flock_swarm.core.faults import NON_FINITE
from flock_swarm.core.network import USAGE_LABELS
from flock_swarm.nodes.fault_report import FaultReport
from flock_swarm.nodes.wire import (MalformedMessage, decode_accel, decode_odometry,
                                    decode_state, decode_twist)

#: A law's adaptive state may take any finite value: only a non-finite one is rejected.
STATE_LIMIT = sys.float_info.max


class WorldInputs:
    """The world node's inputs besides the commands (a part of
    :class:`~flock_swarm.nodes.world.WorldNode`: it reads the node's stepper and guard)."""

    def subscribe_agents(self, per_agent: bool = True) -> None:
        """Subscribe to the agents' optional topic families (each absent when unused; all
        when not ``per_agent``: a transport carries them)."""
        n, st = self.scenario.n_agents if per_agent else 0, self.stepper
        subscribe = self.recorded_subscription
        # A law's adaptive state (none: no topic), recorded and checked like the commands.
        self.agent_state_topics = [subscribe(JointState, state_topic(i), decode_state,
                                             lambda msg, i=i: self.on_agent_state(i, msg))
                                   for i in range(n)] if st.state else []
        # Realtime with the network model: what each command used, recorded like the state.
        self.network_topics = [subscribe(JointState, network_topic(i), decode_state,
                                         lambda msg, i=i: self.on_network_report(i, msg))
                               for i in range(n)] if st.used is not None else []
        # A robot plant's velocity commands (cmd_vel): unstamped, recorded at the open step.
        self.twist_topics = [subscribe(Twist, cmd_vel_topic(i), decode_twist, None,
                                       lambda data, i=i: self.on_twist(i, data))
                             for i in range(n)] if st.velocity else []

    def subscribe_leader(self) -> None:
        """Subscribe to the leader's state and to the nodes' fault reports."""
        subscribe = self.recorded_subscription
        self.leader_odom_topic = subscribe(Odometry, LEADER_ODOM, decode_odometry,
                                           self.on_leader_odom)
        self.leader_accel_topic = subscribe(AccelStamped, LEADER_ACCEL, decode_accel,
                                            self.on_leader_accel)
        self.create_subscription(DiagnosticArray, FAULTS, self.on_fault, qos_profile(FAULTS_QOS))

    def on_twist(self, i: int, data: bytes) -> None:
        """Record agent ``i``'s velocity command (serialised) at the open step; a finite one
        goes to the stepper (its mode's ``twist``, :mod:`flock_swarm.nodes.world_modes`)."""
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
        self.step_may_close()

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
            self.step_may_close()

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
            self.step_may_close()

    def on_leader_accel(self, msg: tuple) -> None:
        """Check the leader's acceleration of its step and hand it on."""
        ns, frame, lin = msg
        k = self.guard.check(self.leader_accel_topic, ns, frame,
                             ((lin, self.guard.limits.accel),), window=self.stepper.window())
        if k is not None:
            self.stepper.leader_state(k, time.monotonic(),
                                      a=np.array(lin[:self.scenario.dim]))
            self.step_may_close()

    def on_fault(self, msg: DiagnosticArray) -> None:
        """Take the faults a node reports: count non-finite commands, fail the run on a fatal
        one (:class:`~flock_swarm.nodes.fault_report.FaultReport`)."""
        for report in FaultReport.from_msg(msg):
            self.stepper.fault_reported(report.step, report.agents, report.kind == NON_FINITE)
            if report.fatal:
                self.fail(report.line)
