"""The world's peers on the ROS graph: who the start waits for, who left, another world.

:class:`WorldPeers` is the part of the world node (:mod:`flock_swarm.nodes.world`) that
reads the ROS graph: before the start, whether every agent's node and the leader are
discovered and subscribed (:meth:`WorldPeers.ready_to_start`, naming who is missing every
:data:`WAIT_LOG_EVERY` seconds); and once a second (:meth:`WorldPeers.check_claims`) two
nodes claiming one agent, a peer gone from the graph (the run fails after
``peer_timeout``), another world or a replay on the same domain (the start is refused).
What the start waits for (``expect_subscribers``, ``expect_telemetry_subscribers``) and the
pace are read here too (:meth:`WorldPeers.init_waiting`).
"""

import time

from flock_swarm.core.errors import ScenarioError
from flock_swarm.nodes.ros_graph import check_claims

#: Seconds between the waiting world's lines naming who it waits for.
WAIT_LOG_EVERY = 5.0


def id_list(ids: list[int]) -> str:
    """Return agent ids as ``agent 3`` or ``agents 0-2, 5``."""
    runs: list[list[int]] = []
    for i in ids:
        if runs and runs[-1][1] == i - 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    text = ', '.join(str(a) if a == b else f'{a}-{b}' for a, b in runs)
    return f'agent {text}' if len(ids) == 1 else f'agents {text}'


class WorldPeers:
    """The world node's view of the ROS graph (a part of
    :class:`~flock_swarm.nodes.world.WorldNode`: it reads the node's topics and stepper)."""

    def init_waiting(self, params) -> None:
        """Read what the start waits for and the pace (``params``: the node's
        :class:`~flock_swarm.nodes.parameters.NodeParameters`); nobody refused, nothing
        waited yet."""
        self.expect_subscribers = params['expect_subscribers']
        self.expect_telemetry = params['expect_telemetry_subscribers']
        self.pace = params['pace']
        #: Lockstep with ``pace``: the next step is held until its wall time.
        self.paced = False
        #: The pace in force (:meth:`pace_now`) and the step and wall time it counts from
        #: (``None``: the start of the run).
        self.pace_in_force = self.pace
        self.pace_anchor: tuple[int, float] | None = None
        self.created = self.wait_logged = time.monotonic()
        #: Why the world refused to start (another world on the domain), or ``None``.
        self.refusal: ScenarioError | None = None
        self.other_world_reported = False
        self.subscribers_needed = self.expect_subscribers
        self.duplicates: set[int] = set()
        # The node that published each agent's commands, as the graph last told.
        self.hosts: dict[int, str] = {}

    def ready_to_start(self) -> bool:
        """Return whether every agent and the leader are discovered and subscribed; say who
        is missing every :data:`WAIT_LOG_EVERY` seconds. Another world (or a replay) on the
        domain sets :attr:`refusal` and stops the timer: ``main`` and the swarm runner end the run
        with that line, and ``expect_subscribers`` given as -1 reads back the count found.
        """
        self.refusal = self.refusal or self.other_worlds()
        if self.refusal is not None:
            # Not raised here: an executor logs an exception of a callback with its traceback.
            self.timer.cancel()
            return False
        missing = self.waiting_for()
        if not missing:
            if self.expect_subscribers < 0:
                self.params.settle('expect_subscribers', self.subscribers_needed)
            return True
        now = time.monotonic()
        if now - self.wait_logged >= WAIT_LOG_EVERY:
            self.wait_logged = now
            self.get_logger().info(f'waiting {now - self.created:.0f} s for ' + '; '.join(missing))
        return False

    def waiting_for(self) -> list[str]:
        """Return what the start still waits for, one phrase each (empty: nothing)."""
        n, missing = self.scenario.n_agents, []
        # The batched transport's hosts publish one topic for all their agents.
        source = getattr(self.intake, 'commands_topic', 'their cmd_accel')
        if self.expect_subscribers < 0:
            claims = self.intake.claims(n)
            absent = [i for i in range(n) if i not in claims]
            if absent:
                missing.append(f'{id_list(absent)} (nobody publishes {source})')
            need = len(set().union(*claims.values())) if claims else 1
        else:
            need = self.expect_subscribers
            absent = [i for i, t in enumerate(self.cmd_topics) if self.count_publishers(t) < 1]
            if absent:
                missing.append(f'{id_list(absent)} (nobody publishes their cmd_accel)')
        self.subscribers_needed = need
        short = [i for i, pub in enumerate(self.odom_pubs) if pub.get_subscription_count() < need]
        if short and not self.intake.topics:
            missing.append(f'{need} subscriber(s) of {self.odom_pubs[0].topic_name}')
        elif short:
            missing.append(f'{need} subscriber(s) of the odometry of {id_list(short)}')
        for pub in (self.telemetry.marker_pub, self.telemetry.metrics_pub):
            if pub.get_subscription_count() < self.expect_telemetry:
                missing.append(f'{self.expect_telemetry} subscriber(s) of {pub.topic_name}')
        if self.count_publishers(self.leader_odom_topic) < 1:
            missing.append(f'the leader (nobody publishes {self.leader_odom_topic})')
        if self.clock_pub.get_subscription_count() < 1:
            missing.append(f'a subscriber of {self.clock_pub.topic_name} (the leader)')
        return missing

    def other_worlds(self) -> ScenarioError | None:
        """Return the refusal to start beside another world on the same ROS domain (two runs
        would mix their messages): another publisher of ``/clock`` or ``swarm/status``
        (``None``: nobody else)."""
        topics = [pub.topic_name for pub in (self.clock_pub, self.status_pub)]
        if all(self.count_publishers(topic) <= 1 for topic in topics):
            return None
        nodes = sorted({f'{i.node_namespace.rstrip("/")}/{i.node_name}'
                        for topic in topics for i in self.get_publishers_info_by_topic(topic)
                        if not i.node_name.startswith('_NODE_NAME_UNKNOWN')})
        return ScenarioError('ROS_DOMAIN_ID', (
            f'another world or a replay publishes {" or ".join(topics)} on domain '
            f'{self.context.get_domain_id()} (nodes: {", ".join(nodes)}): give each run a '
            'domain of its own'))

    def check_claims(self) -> None:
        """Once a second: report two nodes publishing commands for the same agent (a
        duplicate agent_id), and another world on the domain; fail the run when a peer that
        answered before has been gone from the ROS graph for ``peer_timeout`` seconds."""
        n = self.scenario.n_agents
        claims = self.intake.claims(n)
        if self.intake.topics:
            # Two nodes publishing one agent's command topic (a duplicate agent_id).
            check_claims(self, n, self.duplicates, claims=claims)
        for i, nodes in claims.items():
            self.hosts[i] = ', '.join(f'{ns.rstrip("/")}/{name}' for ns, name in nodes)
        st = self.stepper
        if st.started and not st.done:
            leader_gone = self.count_publishers(self.leader_odom_topic) == 0
            self.fail(st.graph_gone([i for i in range(n) if i not in claims], leader_gone,
                                    time.monotonic(), lambda i: self.hosts.get(i, '')))
        # After the start (a run in one process starts before discovery could show another
        # world; a realtime world starts at once): said once, the run goes on.
        if (self.stepper.started or not self.lockstep) and not self.other_world_reported:
            other = self.other_worlds()
            if other is not None:
                self.other_world_reported = True
                self.get_logger().error(f'{other} (this run\'s messages mix with its)')
