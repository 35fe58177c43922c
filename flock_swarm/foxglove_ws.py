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
  the swarm runner's process, :func:`flock_swarm.nodes.swarm_runner.run_processes`): a bridge node
  subscribing to the contract topics with ``raw=True`` and forwarding the bytes
  (:mod:`flock_swarm.nodes.foxglove_server`).

A latched topic (``/swarm/obstacles``, published once before the run) keeps its last
message in the server, which sends it again when a client subscribes to it, so a viewer that
connects after the start still draws the map (:meth:`LiveServer.latch`).

A slow or stalled client never stalls the run: ``channel.log`` only queues, the SDK keeps a
bounded queue per client (``message_backlog_size``) and drops that client's oldest messages
when it is full, and the bridge subscribes best-effort, so it never holds a writer back.

The SDK's server closes a connection with an empty close frame, which a client reads as
status 1005 (no status), and its ``stop()`` takes no code (issue 38). So the server listens
on a loopback port of its own, and the address clients connect to is a relay's
(:class:`CloseCodeRelay`): it passes the bytes through both ways and gives the server's
close frame a status, 1001 (going away) when the server stops.
"""

import socket
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


#: Close status a client sees when the server stops (RFC 6455: "going away").
CLOSE_GOING_AWAY = 1001
#: Close status a client sees when the SDK drops it while the server runs (its control
#: queue overflowed: a client that does not read). IANA: "try again later", an overload.
CLOSE_TRY_AGAIN_LATER = 1013
#: The reason sent with each status.
CLOSE_REASONS = {CLOSE_GOING_AWAY: b'server stopped',
                 CLOSE_TRY_AGAIN_LATER: b'message backlog full'}
#: Where the SDK's server listens, behind the relay (:class:`CloseCodeRelay`).
RELAYED_HOST = '127.0.0.1'
#: Bytes a relay reads from a socket at a time.
RELAY_CHUNK = 1 << 16

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


def close_frame(code: int) -> bytes:
    """Return an unmasked WebSocket close frame (server to client) with ``code`` and its
    reason (:data:`CLOSE_REASONS`)."""
    payload = struct.pack('>H', code) + CLOSE_REASONS.get(code, b'')
    return bytes((0x88, len(payload))) + payload


class CloseRewriter:
    """Follows the server-to-client byte stream of one WebSocket connection, frame by frame,
    and gives an empty close frame (the SDK's) a status code; every other byte passes as is.

    The stream begins with the server's HTTP response to the upgrade; a response other than
    ``101`` is passed through untouched, and so is everything after it.

    :param code: returns the status to put in an empty close frame, asked when one comes.
    """

    def __init__(self, code) -> None:
        """Start before the HTTP response."""
        self.code = code
        self.pending = b''  # an incomplete HTTP response or frame header
        self.skip = 0  # payload bytes of the current frame still to pass
        self.http = True
        self.raw = False

    def feed(self, data: bytes) -> bytes:
        """Return the bytes to send on for ``data``, the next bytes the server sent."""
        if self.raw:
            return data
        if self.pending:
            data = self.pending + data
            self.pending = b''
        out = []
        pos = 0
        if self.http:
            end = data.find(b'\r\n\r\n')
            if end < 0:
                self.pending = data
                return b''
            self.http = False
            if not data.startswith(b'HTTP/1.1 101'):
                self.raw = True
                return data
            pos = end + 4
            out.append(data[:pos])
        size = len(data)
        while pos < size:
            if self.skip:
                take = min(self.skip, size - pos)
                out.append(data[pos:pos + take])
                pos += take
                self.skip -= take
                continue
            if size - pos < 2:
                self.pending = data[pos:]
                break
            first, second = data[pos], data[pos + 1]
            length = second & 0x7F
            header = 2 + {126: 2, 127: 8}.get(length, 0) + (4 if second & 0x80 else 0)
            if size - pos < header:
                self.pending = data[pos:]
                break
            if length == 126:
                length = int.from_bytes(data[pos + 2:pos + 4], 'big')
            elif length == 127:
                length = int.from_bytes(data[pos + 2:pos + 10], 'big')
            if first == 0x88 and length == 0 and header == 2:
                out.append(close_frame(self.code()))
            else:
                out.append(data[pos:pos + header])
                self.skip = length
            pos += header
        return b''.join(out)


class CloseCodeRelay:
    """A TCP relay in front of the SDK's server: clients connect to its address, each
    connection is passed to the server on ``upstream`` and its bytes are relayed both ways,
    the server's through a :class:`CloseRewriter` (a close frame with a status).

    Two daemon threads a connection, which close its sockets once both ways have ended
    (the client's or the server's close); :meth:`close` waits a bounded time for the server to
    end each connection and then cuts those that are left (a client that does not read).

    :param host: the address clients connect to.
    :param port: its TCP port (0: any free port).
    :param upstream: the SDK server's ``(host, port)``.
    :raises OSError: when the address cannot be bound.
    """

    def __init__(self, host: str, port: int, upstream: tuple[str, int]) -> None:
        """Bind, listen and start accepting."""
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)[0]
        self.listener = socket.socket(family, kind, proto)
        try:
            self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.listener.bind(address)
            self.listener.listen()
        except OSError:
            self.listener.close()
            raise
        self.port = self.listener.getsockname()[1]
        self.upstream = upstream
        #: Whether the server is stopping (:data:`CLOSE_GOING_AWAY`, else the SDK dropped a
        #: client: :data:`CLOSE_TRY_AGAIN_LATER`).
        self.stopping = False
        self.lock = threading.Lock()
        #: Open connections: ``(client socket, server socket, relay thread)``.
        self.connections: list[tuple[socket.socket, socket.socket, threading.Thread]] = []
        self.acceptor = threading.Thread(target=self._accept, name='foxglove-relay',
                                         daemon=True)
        self.acceptor.start()

    def code(self) -> int:
        """The status of a close frame the server sends now."""
        return CLOSE_GOING_AWAY if self.stopping else CLOSE_TRY_AGAIN_LATER

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return  # closed
            try:
                server = socket.create_connection(self.upstream)
            except OSError:
                client.close()
                continue
            for sock in (client, server):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            thread = threading.Thread(target=self._serve, args=(client, server),
                                      name='foxglove-relay', daemon=True)
            with self.lock:
                self.connections.append((client, server, thread))
            thread.start()

    def _serve(self, client: socket.socket, server: socket.socket) -> None:
        """Relay one connection both ways until both have ended; then close its sockets."""
        incoming = threading.Thread(target=self._pipe, args=(client, server, None),
                                    name='foxglove-relay-in', daemon=True)
        incoming.start()
        self._pipe(server, client, CloseRewriter(self.code))
        incoming.join()
        with self.lock:
            self.connections = [c for c in self.connections if c[0] is not client]
        client.close()
        server.close()

    @staticmethod
    def _pipe(source: socket.socket, sink: socket.socket,
              rewriter: CloseRewriter | None) -> None:
        """Relay ``source`` to ``sink`` until ``source`` ends; then end ``sink``'s writing."""
        try:
            while True:
                data = source.recv(RELAY_CHUNK)
                if not data:
                    break
                if rewriter is not None:
                    data = rewriter.feed(data)
                sink.sendall(data)
        except OSError:
            pass  # a connection reset, or cut by close()
        try:
            sink.shutdown(socket.SHUT_WR)
        except OSError:
            pass

    def close(self, timeout: float) -> None:
        """Stop accepting; wait at most ``timeout`` s for the connections to end, then cut
        those left (a client that does not read)."""
        try:
            self.listener.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.listener.close()
        deadline = time.monotonic() + timeout
        with self.lock:
            connections = list(self.connections)
        for _, _, thread in connections:
            thread.join(max(0.0, deadline - time.monotonic()))
        for client, server, thread in connections:
            for sock in (client, server):
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass  # closed already
            thread.join(1.0)


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
        self.closed = False
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
            # The SDK's server on a loopback port of its own; clients reach it through the
            # relay on the address asked for (its close frames with a status).
            self.server = foxglove.start_server(
                name=SERVER_NAME, host=RELAYED_HOST, port=0, context=self.context,
                capabilities=[foxglove.Capability.Time], message_backlog_size=backlog,
                server_listener=Listener())
        except RuntimeError as exc:
            raise OSError(f'cannot serve on {RELAYED_HOST}:0: {" ".join(str(exc).split())}'
                          ) from None
        try:
            self.relay = CloseCodeRelay(host, port, (RELAYED_HOST, self.server.port))
        except OSError as exc:
            self.server.stop()
            reason = exc.strerror or ' '.join(str(exc).split())
            raise OSError(f'cannot serve on {host}:{port}: {reason}') from None
        self.host = host

    @property
    def port(self) -> int:
        """The TCP port clients connect to (the relay's)."""
        return self.relay.port

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
        in a daemon thread, and the relay cuts the connections still open after ``timeout``:
        a ``swarm`` or ``replay`` ends on time whatever its clients do. A client that reads
        sees the close frame with status :data:`CLOSE_GOING_AWAY` (the relay's).
        """
        if self.closed:
            return
        self.closed = True
        deadline = time.monotonic() + timeout
        self.relay.stopping = True
        for channel in self.channels.values():
            channel.close()
        self.channels = {}
        stopper = threading.Thread(target=self.server.stop, name='foxglove-stop', daemon=True)
        stopper.start()
        stopper.join(timeout)
        self.relay.close(max(0.0, deadline - time.monotonic()))

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
