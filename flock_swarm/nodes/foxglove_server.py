"""``foxglove_server``: a node that serves a running swarm's topics to Foxglove / Lichtblick.

It subscribes to every topic of the contract with ``raw=True`` and hands the bytes, as they
came over the wire, to a :class:`~flock_swarm.foxglove_ws.LiveServer`, logged at the message's
stamp; ``/clock`` sets the server's time. For runs started node by node::

    foxglove_server --ros-args -p scenario:=demo [-p port:=8765] [-p host:=127.0.0.1]

``swarm --processes --foxglove`` spins the same node in a thread of its own process
(:class:`BackgroundBridge`); a one-process ``swarm --foxglove`` needs none: the world hands
the server its bytes directly, as one of its sinks (:class:`~flock_swarm.foxglove_ws.LiveSink`).
"""

import sys
import threading
import time
from typing import Callable

import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from flock_swarm import contract
from flock_swarm.bag.msgdefs import message_class
from flock_swarm.contract import (CLOCK_TYPE, OBSTACLES, OBSTACLES_QOS, OBSTACLES_TYPE,
                                  absolute, contract_topics, qos_profile)
from flock_swarm.core.errors import ScenarioError
from flock_swarm.foxglove_ws import (DEFAULT_HOST, DEFAULT_PORT, LiveServer, ServeError,
                                     message_stamp_ns, start_live)
from flock_swarm.nodes.parameters import COMMON_PARAMS, NodeParameters, Param, init_node
from flock_swarm.nodes.spin import make_executor, middleware_defaults, run_node

BRIDGE_QOS = qos_profile(contract.BRIDGE_QOS)
#: The node's parameters (the others override scenario keys, as in every node).
BRIDGE_PARAMS = COMMON_PARAMS + (
    Param('host', DEFAULT_HOST, 'address the server binds (127.0.0.1: this machine only)'),
    Param('port', DEFAULT_PORT, 'TCP port of the server (0: any)'),
)


class LiveBridge(Node):
    """Subscribes to the contract topics (raw bytes) and forwards them to a server.

    Parameters: ``scenario`` (and its overrides, as every node: the number of agents),
    ``host`` and ``port`` (of the server it starts when given none).

    :param live: the server, or None to start one from ``host`` and ``port`` (closed by
        :meth:`close`).
    :param kwargs: forwarded to :class:`rclpy.node.Node` (context, namespace...).
    :raises ScenarioError: for an invalid parameter, or an address that cannot be bound.
    """

    def __init__(self, live: LiveServer | None = None, **kwargs) -> None:
        """Create the node, its server if needed, and its subscriptions."""
        init_node(super().__init__, kwargs.pop('node_name', 'foxglove_server'), kwargs)
        params = self.params = NodeParameters(self, BRIDGE_PARAMS)
        sc = params.load_scenario()
        params.declare()
        host, port = params['host'], params['port']
        self.owned = live is None
        if live is None:
            try:
                live = start_live(host, port, 'port')
            except ServeError as exc:
                raise ScenarioError(exc.option, exc.reason) from None
        self.live = live
        self.received = 0
        #: Messages forwarded per topic.
        self.counts: dict[str, int] = {}
        self.time_ns = 0
        self.subscriptions_by_topic = {}
        for topic, type_name in contract_topics(sc.n_agents, self.get_namespace(),
                                                bool(sc.law.initial_state(1)),
                                                sc.transport == 'batched'):
            sub = self.create_subscription(
                message_class(type_name), topic, self._forward(topic, type_name), BRIDGE_QOS,
                raw=True)
            self.subscriptions_by_topic[sub.topic_name] = sub
            self.counts[sub.topic_name] = 0
            live.add_topic(sub.topic_name, type_name)
        if sc.obstacles.active:
            # The map is published once before the run, latched: a reliable, transient-local
            # subscription gets it however late the bridge starts, and the server keeps it
            # for the viewers that connect later still.
            sub = self.create_subscription(
                message_class(OBSTACLES_TYPE), OBSTACLES,
                self._forward(absolute(OBSTACLES, self.get_namespace()), OBSTACLES_TYPE),
                qos_profile(OBSTACLES_QOS), raw=True)
            self.subscriptions_by_topic[sub.topic_name] = sub
            self.counts[sub.topic_name] = 0
            live.add_topic(sub.topic_name, OBSTACLES_TYPE)
            live.latch(sub.topic_name)

    def unmatched(self, topics) -> list[str]:
        """Return those of ``topics`` that no publisher has matched yet."""
        return [t for t in topics if self.subscriptions_by_topic[t].get_publisher_count() < 1]

    def silent(self) -> list[str]:
        """Return the topics no message came in on, each with its matched publishers."""
        return [f'{t} ({self.subscriptions_by_topic[t].get_publisher_count()} publishers '
                'matched)' for t, n in self.counts.items() if n == 0]

    def _forward(self, topic: str, type_name: str) -> Callable[[bytes], None]:
        clock = type_name == CLOCK_TYPE
        counts = self.counts

        def on_data(data: bytes) -> None:
            stamp = message_stamp_ns(type_name, data)
            t_ns = self.time_ns if stamp is None else stamp
            if clock and t_ns > self.time_ns:
                # A step offered again (the world's resend) does not turn time back.
                self.time_ns = t_ns
                self.live.set_time(t_ns)
            self.live.write(topic, data, t_ns)
            self.received += 1
            counts[topic] += 1
        return on_data

    def close(self) -> None:
        """Stop the server if this node started it."""
        if self.owned:
            self.live.close()


class BackgroundBridge:
    """A :class:`LiveBridge` on its own context and domain, spun by a thread of this process.

    ``swarm --processes --foxglove`` serves this way: the runner's process keeps the server
    it bound (no second process racing for the port), while the nodes run elsewhere. Use it
    as a context manager.

    :param live: the server.
    :param domain_id: the run's ROS domain id.
    :param parameters: the bridge's parameters (``scenario`` and the like).
    """

    def __init__(self, live: LiveServer, domain_id: int, parameters: dict) -> None:
        """Create the context and the node, and start spinning."""
        self.context = Context()
        middleware_defaults()
        rclpy.init(context=self.context, domain_id=domain_id)
        try:
            self.node = LiveBridge(live, context=self.context, parameter_overrides=[
                Parameter(name, value=value) for name, value in parameters.items()])
        except BaseException:
            rclpy.try_shutdown(context=self.context)
            raise
        self.executor = make_executor(self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, name='foxglove-bridge', daemon=True)
        self.thread.start()

    def wait_matched(self, topics, timeout: float) -> list[str]:
        """Wait until a publisher matched each of ``topics``; return those still unmatched.

        Run before the world starts, so that a best-effort bridge that discovers the leader
        or the agents late does not miss their messages from the first step.
        """
        deadline = time.monotonic() + timeout
        left = self.node.unmatched(topics)
        while left and time.monotonic() < deadline:
            time.sleep(0.05)
            left = self.node.unmatched(left)
        return left

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.1)

    def close(self) -> None:
        """Stop spinning; destroy the node and the context (the server stays open)."""
        self._stop.set()
        self.thread.join()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> 'BackgroundBridge':
        """Return the bridge."""
        return self

    def __exit__(self, *exc_info) -> None:
        """Close the bridge."""
        self.close()


def main(args: list[str] | None = None) -> int:
    """Run ``foxglove_server``: serve the contract topics of a running swarm (a bridge node).

    ``foxglove_server --ros-args -p scenario:=demo [-p port:=8765] [-p host:=127.0.0.1]``;
    the scenario gives the number of agents. Invalid input: one line, exit status 2.

    :param args: command-line arguments (``None``: ``sys.argv``).
    :return: the exit status.
    """
    def factory() -> LiveBridge:
        bridge = LiveBridge()
        print(f'[foxglove_server] serving {len(bridge.live.channels)} topics on '
              f'{bridge.live.url}', file=sys.stderr, flush=True)
        return bridge

    return run_node('foxglove_server', factory, args)


if __name__ == '__main__':
    sys.exit(main())
