"""Faults a node reports to the world on ``swarm/faults``: a failed law, a failed leader model.

An agent node whose law raises, returns the wrong shape or a non-finite command, and a
leader node whose model fails, tell the world at once (:class:`FaultReporter`) instead of
leaving it to wait out a step timeout for every remaining step: the world ends the run as
``failed`` with the report's line (:class:`FaultReport`). A non-finite command replaced by
zero (the agents' ``non_finite:=zero``) is reported too, not fatal, so the world counts it
per agent.

A report is a ``diagnostic_msgs/DiagnosticArray`` (a standard message, as ``/swarm/metrics``)
with one status: level ``ERROR`` (the run must end) or ``WARN`` (counted), ``name`` the
reporting node, ``message`` the one line, and the values ``kind``, ``step`` and ``agents``
(a JSON list). The topic is latched (``contract.FAULTS_QOS``), so a world that matches a
failed node late still gets its report.
"""

import json
from dataclasses import dataclass

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.node import Node

from flock_swarm.contract import FAULTS, FAULTS_QOS, qos_profile
from flock_swarm.core.faults import RunFault

#: The ``name`` prefix of a report's status: ``flock_swarm/fault <node>``.
REPORT_NAME = 'flock_swarm/fault'
#: Levels of ``diagnostic_msgs/DiagnosticStatus``.
WARN, ERROR = 1, 2
#: Seconds a failed node waits for the world to acknowledge its report before it exits.
ACK_TIMEOUT = 2.0


@dataclass(frozen=True)
class FaultReport:
    """A fault as a node reports it.

    :ivar node: the reporting node's fully qualified name.
    :ivar line: the one line (the node, then the fault: component, agents, step).
    :ivar kind: :data:`~flock_swarm.core.faults.RAISED`, ``SHAPE`` or ``NON_FINITE``.
    :ivar step: the step.
    :ivar agents: the agents concerned (empty: the leader model).
    :ivar fatal: whether the run must end.
    """

    node: str
    line: str
    kind: str
    step: int
    agents: tuple[int, ...]
    fatal: bool

    @classmethod
    def of(cls, node: Node, fault: RunFault, fatal: bool = True) -> 'FaultReport':
        """Return the report of ``fault`` by ``node`` (its line prefixed with the node)."""
        name = node.get_fully_qualified_name()
        return cls(name, f'{name}: {fault.line}', fault.kind, fault.step, fault.agents, fatal)

    def to_msg(self, stamp: Time) -> DiagnosticArray:
        """Return the report as a message stamped ``stamp`` (the step's time)."""
        status = DiagnosticStatus(level=bytes([ERROR if self.fatal else WARN]),
                                  name=f'{REPORT_NAME} {self.node}', message=self.line,
                                  hardware_id='flock_swarm')
        status.values = [KeyValue(key='kind', value=self.kind),
                         KeyValue(key='step', value=str(self.step)),
                         KeyValue(key='agents', value=json.dumps(list(self.agents)))]
        msg = DiagnosticArray()
        msg.header.stamp = stamp
        msg.status = [status]
        return msg

    @classmethod
    def from_msg(cls, msg: DiagnosticArray) -> list['FaultReport']:
        """Return the reports a message holds (statuses that are not, or are malformed, are
        left out: the topic is open to anybody)."""
        found = []
        for status in msg.status:
            if not status.name.startswith(REPORT_NAME + ' '):
                continue
            values = {kv.key: kv.value for kv in status.values}
            try:
                agents = tuple(int(i) for i in json.loads(values.get('agents', '[]')))
                step = int(values.get('step', '-1'))
            except (TypeError, ValueError):
                continue
            found.append(cls(status.name[len(REPORT_NAME) + 1:], status.message,
                             values.get('kind', ''), step, agents,
                             status.level == bytes([ERROR])))
        return found


class FaultReporter:
    """Reports a node's faults on ``swarm/faults`` and in its log (one line each)."""

    def __init__(self, node: Node) -> None:
        """Create the publisher on ``node``."""
        self.node = node
        self.pub = node.create_publisher(DiagnosticArray, FAULTS, qos_profile(FAULTS_QOS))

    def report(self, fault: RunFault, stamp: Time, fatal: bool = True) -> FaultReport:
        """Publish ``fault`` (fatal: also logged as an error line); return the report."""
        report = FaultReport.of(self.node, fault, fatal)
        if fatal:
            self.node.get_logger().error(f'{fault.line}; the run fails')
        self.pub.publish(report.to_msg(stamp))
        return report

    def wait_acknowledged(self) -> None:
        """Wait (at most :data:`ACK_TIMEOUT`) until every subscriber has the reports."""
        self.pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT))
