"""The live view of ``--foxglove``: the swarm's topics over the Foxglove WebSocket protocol.

The Foxglove app and Lichtblick connect to ``ws://localhost:8765`` and show every topic of
the contract (``/clock``, ``/leader/odom``, ``/leader/accel``, ``/agent_<i>/odom``,
``/agent_<i>/cmd_accel``, ``/swarm/markers``, ``/swarm/metrics``) as a ROS 2 connection
would: each channel carries its ``ros2msg`` schema (the same text the bag records,
:mod:`flock_swarm.bag.msgdefs`) and ``cdr`` messages, the serialised bytes passed through
as they are, and the server's time is simulation time.

Three ways in, one :class:`LiveServer` under each:

- ``swarm ... --foxglove [PORT]`` in one process: :class:`LiveSink`, one of the world's
  message sinks (:class:`~flock_swarm.nodes.recording.MessageSink`), hands the server every
  message the world publishes or receives, without another DDS subscriber (the cheapest,
  docs/performance.md);
- ``replay BAG --foxglove [PORT]``: the player hands it the bag's bytes on schedule;
- ``foxglove_server`` for runs started node by node and ``swarm --processes --foxglove`` (in
  the harness's process, :func:`flock_swarm.nodes.harness.run_processes`): a bridge node
  subscribing to the contract topics with ``raw=True`` and forwarding the bytes
  (:mod:`flock_swarm.nodes.foxglove_server`).

A latched topic (``/swarm/obstacles``, published once before the run) keeps its last
message in the server, which sends it again when a client subscribes to it, so a viewer that
connects after the start still draws the map (:meth:`LiveServer.latch`).

A slow or stalled client never stalls the run: ``channel.log`` only queues, the SDK keeps a
bounded queue per client (``message_backlog_size``) and drops that client's oldest messages
when it is full, and the bridge subscribes best-effort, so it never holds a writer back.
"""

import struct
import threading
import time
from typing import Iterable

from flock_swarm.bag.msgdefs import encoded_definition, type_name_of
from flock_swarm.contract import MARKERS_TYPE

#: Default port of the Foxglove WebSocket protocol (what the apps try first).
DEFAULT_PORT = 8765
#: Default address: this machine only. Anything else is an explicit choice (``--foxglove-host``).
DEFAULT_HOST = '127.0.0.1'
#: Message encoding of every channel: the CDR bytes of the ROS 2 wire, unchanged.
MESSAGE_ENCODING = 'cdr'
#: Name the server announces to its clients.
SERVER_NAME = 'flock_swarm'
#: Longest wait [s] for the server to stop when the run ends (:meth:`LiveServer.close`).
CLOSE_TIMEOUT = 2.0
#: A viewer subscribes channel by channel: :meth:`LiveServer.wait_for_viewer` returns once
#: no further subscription has come for this long [s] after the first.
VIEWER_SETTLE = 0.5
#: The pace [simulated s per wall s] of a one-process lockstep run while a viewer watches
#: every channel, unless ``--pace`` gives one (:attr:`LiveSink.pace`): unpaced, the server
#: outran such a viewer and dropped its oldest messages (issue 38).
LIVE_PACE = 1.0
#: How often [s] a :class:`LiveSink` looks whether every channel is watched.
WATCH_PERIOD = 0.2


_NS = 10**9
_TIME = {0: struct.Struct('>iI'), 1: struct.Struct('<iI')}


def message_stamp_ns(type_name: str, data: bytes) -> int | None:
    """Return the simulation-time stamp [ns] of a serialised contract message.

    ``Clock``, ``Odometry``, ``AccelStamped``, ``JointState`` (the agents' adaptive state)
    and ``DiagnosticArray`` begin with their time (the clock, or the header's stamp); a
    ``MarkerArray`` with its length and then the first marker's header. The world records
    each message at that stamp.

    :param type_name: ``pkg/msg/Type`` of the message.
    :param data: the CDR bytes.
    :return: the stamp, or None when the bytes carry none (an empty marker array, or bytes
        too short or not plain CDR).
    """
    offset = 8 if type_name == MARKERS_TYPE else 4
    if len(data) < offset + 8 or data[0] != 0 or data[1] not in _TIME:
        return None
    if type_name == MARKERS_TYPE and _TIME[data[1]].unpack_from(data, 4)[0] == 0:
        return None
    sec, nanosec = _TIME[data[1]].unpack_from(data, offset)
    return sec * _NS + nanosec


class LiveServer:
    """A Foxglove WebSocket server whose channels take CDR bytes of ROS 2 messages.

    It has its own ``foxglove.Context``, so two servers in one process (tests) never share a
    channel. Use it as a context manager, or call :meth:`close`.

    :param host: address to bind (default :data:`DEFAULT_HOST`, this machine only).
    :param port: TCP port (0: any free port, see :attr:`port`).
    :param backlog: messages queued per client before its oldest are dropped (None: the
        SDK's default, 1024).
    :raises OSError: when the address cannot be bound (one line, naming it).
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 backlog: int | None = None) -> None:
        """Start the server; it has no channels yet (:meth:`add_topic`)."""
        import foxglove
        self.context = foxglove.Context()
        self.channels: dict[str, object] = {}
        self.time_ns = -1
        #: The latched topics and their last message ``(bytes, t_ns)`` (None: none yet).
        self.latched: dict[str, tuple[bytes, int] | None] = {}
        #: Set once a client has subscribed to a channel (:meth:`wait_for_viewer`).
        self.viewer = threading.Event()
        #: When the last subscription came (monotonic) [s].
        self.subscribed_at = 0.0
        viewer = self.viewer
        resend = self._resend
        server = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:
                server.subscribed_at = time.monotonic()
                viewer.set()
                resend(channel.topic)
        try:
            self.server = foxglove.start_server(
                name=SERVER_NAME, host=host, port=port, context=self.context,
                capabilities=[foxglove.Capability.Time], message_backlog_size=backlog,
                server_listener=Listener())
        except RuntimeError as exc:
            raise OSError(f'cannot serve on {host}:{port}: {" ".join(str(exc).split())}'
                          ) from None
        self.host = host

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return self.server.port

    @property
    def url(self) -> str:
        """The address a client connects to, ``ws://HOST:PORT``."""
        host = f'[{self.host}]' if ':' in self.host else self.host
        return f'ws://{host}:{self.port}'

    def add_topic(self, topic: str, msg_type: object) -> None:
        """Advertise ``topic`` with the ``ros2msg`` schema of its type (once per topic).

        :param topic: the fully qualified topic name.
        :param msg_type: the message class or ``pkg/msg/Type``.
        :raises DefinitionNotFoundError: when the type's ``.msg`` files are not installed.
        """
        if topic in self.channels:
            return
        from foxglove import Channel, Schema
        definition = encoded_definition(type_name_of(msg_type))
        schema = Schema(name=definition.type_name, encoding=definition.encoding,
                        data=definition.text.encode('utf-8'))
        self.channels[topic] = Channel(topic, schema=schema, message_encoding=MESSAGE_ENCODING,
                                       context=self.context)

    def add_topics(self, topics: Iterable[tuple[str, object]]) -> None:
        """Advertise every ``(topic, type)`` pair (:meth:`add_topic`)."""
        for topic, msg_type in topics:
            self.add_topic(topic, msg_type)

    def latch(self, topic: str) -> None:
        """Keep the last message of ``topic`` and send it to each client that subscribes.

        As a ROS 2 transient-local publisher does for a late subscriber: the obstacle map is
        published once, before any viewer is likely to be connected. A client subscribed
        earlier receives the message again then (the same bytes at the same time).

        :param topic: an advertised topic (:meth:`add_topic`).
        """
        self.latched.setdefault(topic, None)

    def write(self, topic: str, data: bytes, t_ns: int) -> None:
        """Send a message's CDR bytes, logged at ``t_ns``, to the clients subscribed to it.

        A topic that was not advertised is ignored (the viewer shows the contract only).

        :param topic: the topic.
        :param data: the serialised message, passed through unchanged.
        :param t_ns: its simulation time [ns].
        """
        channel = self.channels.get(topic)
        if channel is not None:
            if topic in self.latched:
                self.latched[topic] = (data, t_ns)
            channel.log(data, log_time=t_ns)

    def _resend(self, topic: str) -> None:
        """Send a latched topic's last message again (a client has just subscribed to it)."""
        last = self.latched.get(topic)
        channel = self.channels.get(topic)
        if last is not None and channel is not None:
            channel.log(last[0], log_time=last[1])

    def wait_for_viewer(self, timeout: float | None = None) -> bool:
        """Wait until a client has subscribed to a channel, and then until its further
        subscriptions have come (none for :data:`VIEWER_SETTLE` s): ``swarm
        --wait-for-viewer`` starts the run then, so every channel the viewer subscribes to is
        served from step 0 (a viewer subscribes channel by channel; the run used to start at
        its first subscription).

        :param timeout: seconds to wait at most (``None``: no limit; Ctrl-C still ends it).
        :return: whether a viewer subscribed and its subscriptions settled.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            now = time.monotonic()
            quiet = now - self.subscribed_at
            if self.viewer.is_set() and quiet >= VIEWER_SETTLE:
                return True
            if deadline is not None and now >= deadline:
                return False
            step = 0.2 if deadline is None else min(0.2, deadline - now)
            if self.viewer.is_set():
                time.sleep(min(step, VIEWER_SETTLE - quiet))
            else:
                self.viewer.wait(step)

    @property
    def watched(self) -> bool:
        """Whether every channel has a subscriber (a viewer watches everything)."""
        return bool(self.channels) and all(c.has_sinks() for c in self.channels.values())

    def set_time(self, t_ns: int) -> None:
        """Broadcast ``t_ns`` as the server's time, unless it is the time last broadcast."""
        if t_ns != self.time_ns:
            self.time_ns = t_ns
            self.server.broadcast_time(t_ns)

    def close(self, timeout: float = CLOSE_TIMEOUT) -> None:
        """Close the channels and stop the server, waiting at most ``timeout`` s (idempotent).

        The SDK's ``stop`` waits until every client has closed its connection: a client that
        does not read never sees the close frame and holds it up for as long as the client's
        own keepalive takes (47 s with ``websockets``' defaults, measured). So ``stop`` runs
        in a daemon thread, left behind after ``timeout``: a ``swarm`` or ``replay`` ends on
        time whatever its clients do (the process's exit ends the thread).
        """
        for channel in self.channels.values():
            channel.close()
        self.channels = {}
        stopper = threading.Thread(target=self.server.stop, name='foxglove-stop', daemon=True)
        stopper.start()
        stopper.join(timeout)

    def __enter__(self) -> 'LiveServer':
        """Return the server."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Close the server."""
        self.close()


class LiveSink:
    """A message sink of the world serving its messages (a
    :class:`~flock_swarm.nodes.recording.MessageSink`).

    The world hands every message of the contract it publishes or receives to its sinks
    once a step, as the bytes on the wire: this sink forwards those to a
    :class:`LiveServer`, so a one-process run is served without another DDS subscriber
    (docs/performance.md). The server's topics are advertised beforehand
    (:func:`flock_swarm.contract.contract_topics`); the server is the caller's to close.

    :param live: the server.
    """

    def __init__(self, live: LiveServer) -> None:
        """Serve on ``live``."""
        self.live = live
        self._pace = 0.0
        self._looked = -WATCH_PERIOD

    @property
    def pace(self) -> float:
        """The pace the world takes unless it has one of its own (``--pace``):
        :data:`LIVE_PACE` while every channel is watched, so the viewer gets the whole run
        (the lossless live mode), else 0 (as fast as it goes)."""
        now = time.monotonic()
        if now - self._looked >= WATCH_PERIOD:
            self._looked = now
            self._pace = LIVE_PACE if self.live.watched else 0.0
        return self._pace

    def add_topic(self, name: str, msg_type, qos) -> None:
        """Advertise a topic the world creates (a no-op for one already advertised), latched
        when its publisher is (transient local: ``/swarm/obstacles``)."""
        self.live.add_topic(name, msg_type)
        if getattr(getattr(qos, 'durability', None), 'name', '') == 'TRANSIENT_LOCAL':
            self.live.latch(name)

    def write(self, topic: str, data: bytes, t_ns: int) -> None:
        """Serve one message at simulation time ``t_ns``, the server's time from then on."""
        self.live.set_time(t_ns)
        self.live.write(topic, data, t_ns)

    def flush(self) -> None:
        """Nothing to do: every message is sent as it is written."""

    def close(self) -> None:
        """Nothing to do: the server outlives the world."""


class ServeError(ValueError):
    """A port or address the server cannot use; the message is one line naming the option."""

    def __init__(self, option: str, reason: str) -> None:
        """Create the error.

        :param option: the option or parameter, such as ``--foxglove``.
        :param reason: what is wrong, one line.
        """
        super().__init__(f'{option}: {reason}')
        self.option = option
        self.reason = reason


def start_live(host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, option: str = '--foxglove',
               backlog: int | None = None) -> 'LiveServer':
    """Start a :class:`LiveServer`, or raise a one-line error naming ``option``.

    :param host: address to bind.
    :param port: TCP port, 0 to 65535 (0: any free port).
    :param option: the option or parameter the port came from, for the error message.
    :param backlog: messages queued per client (:class:`LiveServer`).
    :return: the running server.
    :raises ServeError: for a port out of range, an address that cannot be bound, or
        ``foxglove-sdk`` not installed.
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ServeError(option, f'the port must be an integer in [0, 65535], got {port!r}')
    try:
        return LiveServer(host, port, backlog)
    except OSError as exc:
        raise ServeError(option, str(exc)) from None
    except ImportError:
        # A system ROS install has the rest from rosdep, but not this PyPI package.
        raise ServeError(option, 'the live view needs the foxglove-sdk package '
                         '(pip install -r requirements/run.txt)') from None
