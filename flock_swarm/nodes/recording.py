"""Where the world's messages go besides the wire: sinks, and the bag as one of them.

The world (a :class:`RecordedNode`) hands every message it publishes or receives to each of
its sinks as ``write(topic, data, t_ns)`` (the serialised bytes, the simulation time of their
step); :class:`BagSink` queues them and writes them to the MCAP bag once a step.
"""

import json
import os
import shutil
from pathlib import Path
from typing import Callable, Protocol, Sequence

import yaml

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from flock_swarm import __version__
from flock_swarm.bag.writer import serialize
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.scenario import Realization, Scenario
from flock_swarm.contract import LOCKSTEP_QOS, OBSTACLES, SCENARIO, qos_profile
from flock_swarm.nodes.wire import MalformedMessage
from flock_swarm.outputs import json_text


class MessageSink(Protocol):
    """A consumer of the world's messages (the bag; a live viewer could be another)."""

    def add_topic(self, name: str, msg_type: type, qos) -> None:
        """Declare a topic before its first message."""

    def write(self, topic: str, data: bytes, t_ns: int) -> None:
        """Take one serialised message of simulation time ``t_ns`` [ns]."""

    # Optional: write_many(topics, data, t_ns), the same as write for each message in turn
    # (RecordedNode.record_messages uses it where a sink has it).

    def flush(self) -> None:
        """Deliver what was taken (called once a step)."""

    def close(self) -> None:
        """Deliver the rest and finish (idempotent)."""


def provenance(sc: Scenario, real: Realization, mode: str) -> dict[str, str]:
    """Return the run's provenance as the bag's ``flock_swarm`` metadata record holds it:
    the scenario (JSON text), its name, seed, informed set (JSON), mode and version.

    :param sc: the scenario.
    :param real: its realisation (the informed set).
    :param mode: ``lockstep`` or ``realtime``.
    """
    return {
        'scenario': json_text(sc.raw, indent=None).strip(),
        'scenario_name': sc.name,
        'seed': str(sc.seed),
        'informed': json.dumps(real.informed_ids),
        'mode': mode,
        'flock_swarm_version': __version__,
    }


#: The MCAP metadata record in which the world records how its run ended (``status``, and
#: ``failure`` for a failed run): ``analyze`` reports that status, not one guessed from the
#: steps the bag holds.
END_RECORD = 'flock_swarm_end'


def end_record(status: str, failure: str | None, steps: int) -> dict[str, str]:
    """Return the world's end as the bag's :data:`END_RECORD` holds it.

    :param status: how the run ended (``completed``, ``failed``, ``interrupted``...).
    :param failure: the line telling why it failed, or ``None``.
    :param steps: the last step reached.
    """
    record = {'status': status, 'steps': str(steps)}
    if failure is not None:
        record['failure'] = failure
    return record


def _is_provenance(topic: str) -> bool:
    """Whether ``topic`` (absolute, in any namespace) is the run's ``/swarm/scenario`` or its
    ``/swarm/obstacles``: what the world records at its start, before the run."""
    return any(topic == f'/{name}' or topic.endswith(f'/{name}')
               for name in (SCENARIO, OBSTACLES))


def provenance_text(record: dict[str, str]) -> str:
    """Return the text of ``/swarm/scenario``: the provenance record as a YAML mapping, its
    scenario, seed and informed set as YAML values (the scenario as its YAML text shows it).

    :param record: :func:`provenance`'s record.
    """
    data = dict(record, scenario=json.loads(record['scenario']), seed=int(record['seed']),
                informed=json.loads(record['informed']))
    return yaml.safe_dump(data, sort_keys=False, width=float('inf'))


class BagSink:
    """The rosbag2-compatible MCAP bag of a run, written once a step.

    :ivar error: why writing failed (``None``: it did not).
    """

    def __init__(self, path: Path, sc: Scenario, real: Realization, mode: str,
                 failed: Callable[[str], None], max_bagfile_size: int = 0,
                 max_bagfile_duration: float = 0.0) -> None:
        """Open the bag at ``path`` (a directory) with the run's provenance as metadata.

        :param path: the bag directory (must be empty or absent).
        :param sc: the scenario (stored as metadata, with its seed and informed set).
        :param real: its realisation.
        :param mode: ``lockstep`` or ``realtime``.
        :param failed: called with the reason when writing fails (the run stops).
        :param max_bagfile_size: split the bag at this file size [bytes] (0: never).
        :param max_bagfile_duration: split the bag at this span of simulation time [s]
            (0: never); see :class:`~flock_swarm.bag.BagWriter`.
        :raises ScenarioError: naming ``out_dir`` or ``record`` when the bag cannot be made.
        """
        from flock_swarm.bag import (BagWriter, DefinitionNotFoundError, message_definition,
                                     type_name_of)
        if path.exists() and any(path.iterdir()):
            raise ScenarioError('out_dir', f'{path} already holds a bag; choose another out_dir')
        # Every schema is found before the bag file exists: a failure leaves nothing behind.
        # The agents' adaptive state is a topic only for a law that has one.
        types = (Clock, Odometry, AccelStamped, Twist, MarkerArray, DiagnosticArray) \
            + ((JointState,) if real.agents.state else ())
        for msg_type in types:
            try:
                message_definition(type_name_of(msg_type))
            except DefinitionNotFoundError as exc:
                raise ScenarioError('record', f'{exc} (AMENT_PREFIX_PATH='
                                    f'{os.environ.get("AMENT_PREFIX_PATH", "")!r}); '
                                    'set it to the prefixes holding the ROS message '
                                    'packages, or -p record:=false') from None
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.bag = BagWriter(path, max_bagfile_size=max_bagfile_size,
                                 max_bagfile_duration=max_bagfile_duration)
        except OSError as exc:
            raise ScenarioError('out_dir', f'cannot write to {path.parent}: {exc.strerror}') \
                from None
        self.bag.add_metadata('flock_swarm', provenance(sc, real, mode))
        self.path = path
        self.failed = failed
        self.error: str | None = None
        # Messages waiting for the bag, written once a step: runs of one time each,
        # (t_ns, topics, data) in the order they came.
        self.runs: list[tuple[int, list[str], list[bytes]]] = []

    def __str__(self) -> str:
        """Return ``the bag PATH`` (for log lines)."""
        return f'the bag {self.path}'

    def add_topic(self, name: str, msg_type: type, qos) -> None:
        """Add a topic (its schema and QoS) to the bag."""
        if self.bag is not None:
            self.bag.add_topic(name, msg_type, qos)

    def write(self, topic: str, data: bytes, t_ns: int) -> None:
        """Queue a message for the bag (written by :meth:`flush`, once a step)."""
        self.write_many((topic,), (data,), t_ns)

    def write_many(self, topics: Sequence[str], data: Sequence[bytes], t_ns: int) -> None:
        """Queue messages ``data[m]`` on ``topics[m]``, all of time ``t_ns`` (as :meth:`write`
        for each in turn)."""
        if self.bag is not None:
            runs = self.runs
            if runs and runs[-1][0] == t_ns:
                runs[-1][1].extend(topics)
                runs[-1][2].extend(data)
            else:
                runs.append((t_ns, list(topics), list(data)))

    def flush(self) -> None:
        """Write the queued messages, in the order they were queued, a run of equal times at
        once (:meth:`~flock_swarm.bag.BagWriter.write_serialized_batch`)."""
        runs, self.runs = self.runs, []
        if self.bag is None or not runs:
            return
        try:
            for t_ns, topics, data in runs:
                self.bag.write_serialized_batch(topics, data, t_ns)
        except OSError as exc:
            self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        """Give the bag up when it cannot be written (a full disk, say).

        The bag is left as it is on disk: every chunk completed before the failure is
        readable (``analyze`` says how much it recovered), and no ``metadata.yaml`` claims it
        complete.
        """
        self.error = self._error(exc)
        bag, self.bag = self.bag, None
        try:
            bag.abandon()
        except OSError:
            pass
        self.failed(self.error)

    @property
    def empty(self) -> bool:
        """Whether the bag is open and nothing of the run was written or queued to it (the run
        was stopped before it began): the provenance the world records at its start
        (``/swarm/scenario``) is no recording of the run."""
        if self.bag is None:
            return False
        ran = [topic for topic, count in self.bag.message_counts.items()
               if count and not _is_provenance(topic)]
        return not ran and all(_is_provenance(topic) for _, topics, _ in self.runs
                               for topic in topics)

    def discard(self) -> None:
        """Remove the bag directory: a run stopped before anything was recorded leaves no
        empty bag to look like a recording (and ``swarm --out`` can be used again)."""
        self.runs = []
        bag, self.bag = self.bag, None
        try:
            if bag is not None:
                bag.abandon()
        finally:
            shutil.rmtree(self.path, ignore_errors=True)

    def record_end(self, status: str, failure: str | None, steps: int) -> None:
        """Record how the run ended (:data:`END_RECORD`) after what is queued; a bag that
        can no longer be written says nothing (its error is told already)."""
        self.flush()
        if self.bag is None:
            return
        try:
            self.bag.add_metadata(END_RECORD, end_record(status, failure, steps))
        except OSError as exc:
            self._fail(exc)

    def close(self) -> None:
        """Write what is queued, finalise the bag (MCAP summary and ``metadata.yaml``).

        :raises OSError: when finalising fails (:attr:`error` says why); the complete chunks
            stay readable.
        """
        self.flush()
        if self.bag is not None:
            bag, self.bag = self.bag, None
            try:
                bag.close()
            except OSError as exc:
                self.error = self._error(exc, bag)
                raise

    def _error(self, exc: OSError, bag=None) -> str:
        """Return ``cannot write FILE: REASON`` for a failed write of the bag: the file
        the error names, else the open MCAP file."""
        bag = bag or self.bag
        name = exc.filename or (bag.mcap_path if bag is not None else self.path)
        return f'cannot write {name}: {exc.strerror or exc}'


class RecordedNode(Node):
    """A node whose publications and subscriptions also go to its sinks, as the same bytes.

    A subclass sets ``clock`` (a :class:`~flock_swarm.nodes.clock.StepClock`), ``guard``
    (an :class:`~flock_swarm.nodes.guard.InputGuard`) and ``k`` (the open step) before it
    subscribes, and fills ``sinks`` before it creates its topics.
    """

    def __init__(self, name: str, **kwargs) -> None:
        """Create the node, without sinks yet (``kwargs``: :class:`rclpy.node.Node`'s)."""
        super().__init__(name, **kwargs)
        self.sinks: list[MessageSink] = []

    def recorded_publisher(self, msg_type, topic: str, qos):
        """Create a publisher whose topic every sink knows."""
        pub = self.create_publisher(msg_type, topic, qos)
        for sink in self.sinks:
            sink.add_topic(pub.topic_name, msg_type, qos)
        return pub

    def publish_recorded(self, pub, msg, t_ns: int) -> None:
        """Publish ``msg`` (a message, or its bytes) and record it: the same bytes for both
        (a message serialised with its padding zeroed, so a run's bag is reproducible)."""
        data = msg if isinstance(msg, bytes) else serialize(msg)
        pub.publish(data)
        self.record_message(pub.topic_name, data, t_ns)

    def record_message(self, topic: str, data: bytes, t_ns: int) -> None:
        """Hand a serialised message of simulation time ``t_ns`` [ns] to every sink."""
        for sink in self.sinks:
            sink.write(topic, data, t_ns)

    def record_messages(self, topics: Sequence[str], data: Sequence[bytes], t_ns: int) -> None:
        """Hand serialised messages ``data[m]`` of ``topics[m]``, all of simulation time
        ``t_ns`` [ns], to every sink: as :meth:`record_message` for each in turn, at once
        where the sink takes a batch (``write_many``)."""
        for sink in self.sinks:
            many = getattr(sink, 'write_many', None)
            if many is not None:
                many(topics, data, t_ns)
            else:
                for topic, message in zip(topics, data):
                    sink.write(topic, message, t_ns)

    def recorded_subscription(self, msg_type, topic: str, decode: Callable,
                              handler: Callable, take: Callable[[bytes], None] | None = None
                              ) -> str:
        """Subscribe to ``topic``; record each message as received, then hand it on.

        The subscription takes the serialised bytes, so the bag stores what came over the
        wire (faulty messages included) without serialising it again; ``handler`` gets
        ``decode(data)`` (:mod:`flock_swarm.nodes.wire`: its first item is the stamp [ns]).
        Bytes that are no message of the type are recorded at the open step and rejected
        (``malformed``). Return the resolved topic name.

        :param take: gets the bytes instead, unrecorded: a node that queues a step's
            messages to handle them at once records them itself, and hands any it does not
            take at once to :meth:`take_recorded`.
        """
        qos = qos_profile(LOCKSTEP_QOS)
        name = self.create_subscription(
            msg_type, topic,
            take or (lambda data: self.take_recorded(name, data, decode, handler)),
            qos, raw=True).topic_name
        for sink in self.sinks:
            sink.add_topic(name, msg_type, qos)
        return name

    def take_recorded(self, name: str, data: bytes, decode: Callable,
                      handler: Callable) -> None:
        """Record a message received on ``name`` and hand ``decode(data)`` to ``handler``
        (see :meth:`recorded_subscription`)."""
        try:
            msg = decode(data)
        except MalformedMessage as exc:
            self.record_message(name, data, self.clock.ns(self.k))
            self.guard.reject(name, 'malformed', str(exc))
            return
        self.record_message(name, data, self.clock.ns(max(self.clock.step_at(msg[0]), 0)))
        handler(msg)
