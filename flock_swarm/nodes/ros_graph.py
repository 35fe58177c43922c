"""What a node learns from the ROS graph: who hosts the agents, duplicate hosts, the world's end.

The world and the leader wait for one subscriber per node hosting agents before they start
(:func:`agent_hosts`); the world and every agent host report two nodes commanding the same
agent (:func:`check_claims`); the leader and the agents follow the world's announcement of the
end of its run (:func:`follow_world`).
"""

import functools
from typing import Callable, Iterable

from rclpy.node import Node, NodeNameNonExistentError

from flock_swarm.contract import COMMANDS, RUNNING, STATUS, STATUS_QOS, cmd_topic, qos_profile


def command_claims(node: Node, n_agents: int) -> dict[int, list[tuple[str, str]]]:
    """Return, for each agent whose ``agent_<i>/cmd_accel`` has a publishing node, the
    ``(namespace, name)`` of every such node (sorted).

    One graph query per node of the graph, not one per agent topic: each query walks the
    whole graph cache, so asking topic by topic cost O(N^2) per call (116 ms at N = 1000,
    made every second by the world and by every agent host, and every 10 ms by the world
    while it waits for the start; docs/performance.md). A node that left the graph between
    the two queries is skipped.

    :param node: the node asking (its namespace resolves the topics).
    :param n_agents: the swarm's size.
    """
    index = _command_topics(node.resolve_topic_name(cmd_topic(0)), n_agents)
    claims: dict[int, set[tuple[str, str]]] = {}
    for name, namespace in set(node.get_node_names_and_namespaces()):
        try:
            topics = node.get_publisher_names_and_types_by_node(name, namespace)
        except NodeNameNonExistentError:
            continue
        for topic, _ in topics:
            i = index.get(topic)
            if i is not None:
                claims.setdefault(i, set()).add((namespace, name))
    return {i: sorted(nodes) for i, nodes in claims.items()}


@functools.lru_cache(maxsize=8)
def _command_topics(first: str, n_agents: int) -> dict[str, int]:
    """Return ``{resolved agent_<i>/cmd_accel: i}`` given the resolved topic of agent 0."""
    head, _, tail = first.rpartition(cmd_topic(0))
    return {f'{head}{cmd_topic(i)}{tail}': i for i in range(n_agents)}


def agent_hosts(node: Node, n_agents: int) -> int | None:
    """Return how many nodes host the swarm's agents, or ``None`` while one is not there yet.

    A host is a node publishing on some ``agent_<i>/cmd_accel``: an agent node, or a
    container hosting many agents. Each host subscribes to every odometry topic and to the
    leader's, so the counts the world and the leader wait for follow from it.

    :param node: the node asking (its namespace resolves the topics).
    :param n_agents: the swarm's size.
    :return: the number of distinct hosting nodes, or ``None`` if some agent has none.
    """
    claims = command_claims(node, n_agents)
    if len(claims) < n_agents:
        # The batched transport: a host publishes its agents' commands as one message on
        # swarm/commands (nodes/transport.py), and subscribes to the leader all the same.
        batched = node.count_publishers(node.resolve_topic_name(COMMANDS))
        return batched or None
    return len(set().union(*claims.values()))


def check_claims(node: Node, n_agents: int, reported: set[int],
                 hosted: Iterable[int] = (),
                 claims: dict[int, list[tuple[str, str]]] | None = None) -> None:
    """Log an error for each agent that two nodes publish commands for (a duplicate agent_id).

    The world asks about every agent; an agent host about its own (``hosted``), counting
    itself as one of the claimants even before the graph lists its publishers. Each agent is
    reported once: its id is added to ``reported`` (the world's summary lists them).

    :param node: the node asking.
    :param n_agents: the swarm's size.
    :param reported: the agents reported so far (updated).
    :param hosted: the agents ``node`` itself commands (none for the world).
    :param claims: :func:`command_claims`, when the caller asked the graph already.
    """
    me = (node.get_namespace(), node.get_name())
    mine = {int(i) for i in hosted}
    if claims is None:
        claims = command_claims(node, n_agents)
    for i in sorted(mine or claims):
        others = [claimant for claimant in claims.get(i, ()) if claimant != me]
        claimants = ([me] if i in mine else []) + others
        if len(claimants) > 1 and i not in reported:
            reported.add(i)
            names = ', '.join(f'{ns.rstrip("/")}/{name}' for ns, name in claimants)
            node.get_logger().error(f'agent {i} is claimed by {len(claimants)} nodes ({names}): '
                                    'a duplicate agent_id')


def follow_world(node: Node, keep_running: bool) -> Callable[[], bool]:
    """Subscribe ``node`` to the world's ``swarm/status``; return whether it should stop.

    When the world announces the end of its run, the node logs it and, unless
    ``keep_running``, its ``run_node`` loop ends with exit status 0.

    :param node: a leader or agent node.
    :param keep_running: the node's ``keep_running`` parameter.
    :return: a predicate, true once the world finished and the node is not to keep running;
        its ``completed()`` says whether the world announced ``completed`` (its run ended by
        itself, not by a signal or a failure) and the node is not to keep running.
    """
    from std_msgs.msg import String
    ended: list[str] = []

    def on_status(msg: String) -> None:
        if msg.data != RUNNING and not ended:
            ended.append(msg.data)
            node.get_logger().info(f'the world finished its run ({msg.data})' +
                                   ('' if keep_running else '; exiting'))
    node.create_subscription(String, STATUS, on_status, qos_profile(STATUS_QOS))

    def finished() -> bool:
        return bool(ended) and not keep_running
    # A node kept running after the end is stopped by its user: that stop is an interruption
    # (status 130), not the end of its run.
    finished.completed = lambda: ended == ['completed'] and not keep_running
    return finished
