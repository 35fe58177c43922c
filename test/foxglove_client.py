"""A small client of the Foxglove WebSocket protocol, written over ``websockets`` for the tests.

It speaks the ``foxglove.sdk.v1`` subprotocol as foxglove/ws-protocol ``docs/spec.md``
describes it, independently of ``foxglove-sdk``: JSON text frames (``serverInfo``,
``advertise``, ``unadvertise``, ``subscribe``) and little-endian binary frames (opcode 0x01
message data: u32 subscription id, u64 log time [ns], payload; opcode 0x02 time: u64 [ns]).
"""

import json
import struct
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOL = 'foxglove.sdk.v1'
OP_MESSAGE_DATA = 0x01
OP_TIME = 0x02
_MESSAGE_HEADER = struct.Struct('<BIQ')
_TIME = struct.Struct('<BQ')


class FoxgloveClient:
    """One connection: the channels advertised, the messages and times received.

    :param url: ``ws://host:port``.
    :param timeout: seconds to wait for the connection.
    :param max_queue: frames the connection buffers before it stops reading the socket
        (a client that never calls :meth:`pump` then stalls the TCP stream).
    :param sock: an already connected socket (a small receive buffer, say).
    """

    def __init__(self, url: str, timeout: float = 10.0, max_queue: int = 16,
                 sock=None) -> None:
        """Connect and wait for the server's ``serverInfo``."""
        self.ws = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=timeout,
                          max_size=None, max_queue=max_queue, sock=sock)
        self.server_info: dict | None = None
        #: channel id -> advertised channel (``topic``, ``encoding``, ``schemaName`` ...).
        self.channels: dict[int, dict] = {}
        #: every channel ever advertised, unadvertised ones (at the server's end) included.
        self.advertised: dict[int, dict] = {}
        #: subscription id -> channel id.
        self.subscriptions: dict[int, int] = {}
        #: ``(topic, log_time_ns, payload)`` in order of arrival.
        self.messages: list[tuple[str, int, bytes]] = []
        #: server times received [ns].
        self.times: list[int] = []
        #: the topics of each ``advertise`` message, in order of arrival.
        self.advertise_ops: list[list[str]] = []
        #: status messages of the server (a refused subscription, say).
        self.statuses: list[dict] = []
        self.closed = False
        self.pump_until(lambda: self.server_info is not None, timeout, 'serverInfo')

    @property
    def subprotocol(self) -> str | None:
        """The subprotocol the server chose."""
        return self.ws.subprotocol

    def topics(self) -> dict[str, dict]:
        """Return every channel advertised so far by topic (also those since unadvertised)."""
        return {channel['topic']: channel for channel in self.advertised.values()}

    def handle(self, frame: str | bytes) -> None:
        """Take one frame from the server into the client's state."""
        if isinstance(frame, str):
            message = json.loads(frame)
            if message['op'] == 'serverInfo':
                self.server_info = message
            elif message['op'] == 'advertise':
                self.advertise_ops.append([channel['topic'] for channel in message['channels']])
                self.channels.update({channel['id']: channel for channel in message['channels']})
                self.advertised.update(self.channels)
            elif message['op'] == 'unadvertise':
                for channel_id in message['channelIds']:
                    self.channels.pop(channel_id, None)
            elif message['op'] == 'status':
                self.statuses.append(message)
            return
        if frame[0] == OP_MESSAGE_DATA:
            _, subscription, log_time = _MESSAGE_HEADER.unpack_from(frame)
            topic = self.advertised[self.subscriptions[subscription]]['topic']
            self.messages.append((topic, log_time, bytes(frame[_MESSAGE_HEADER.size:])))
        elif frame[0] == OP_TIME:
            self.times.append(_TIME.unpack_from(frame)[1])

    def pump(self, timeout: float) -> bool:
        """Handle the frames that arrive within ``timeout`` s of each other; False once closed."""
        while not self.closed:
            try:
                self.handle(self.ws.recv(timeout=timeout))
            except TimeoutError:
                return True
            except ConnectionClosed:
                self.closed = True
        return False

    def pump_until(self, condition, timeout: float, what: str) -> None:
        """Handle frames until ``condition()`` holds; raise after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while not condition():
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self.closed:
                raise TimeoutError(f'no {what} from the server within {timeout:g} s')
            try:
                self.handle(self.ws.recv(timeout=min(remaining, 0.5)))
            except TimeoutError:
                pass
            except ConnectionClosed:
                self.closed = True

    def subscribe(self, topics) -> None:
        """Subscribe to the advertised channels of ``topics`` (one subscription each)."""
        wanted = set(topics)
        requests = []
        for channel_id, channel in self.channels.items():
            if channel['topic'] in wanted and channel_id not in self.subscriptions.values():
                subscription = len(self.subscriptions) + 1
                self.subscriptions[subscription] = channel_id
                requests.append({'id': subscription, 'channelId': channel_id})
        self.ws.send(json.dumps({'op': 'subscribe', 'subscriptions': requests}))

    def close(self) -> None:
        """Close the connection."""
        self.ws.close()
