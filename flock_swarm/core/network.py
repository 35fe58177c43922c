"""The network between the agents: delay, loss, noise and sampled communication.

The scenario's ``network:`` section (:func:`parse_network`) gives a :class:`NetworkSpec`;
:class:`NetworkState` applies it to a run, one step at a time, for the whole swarm (``sim``)
or for the agents one process hosts (the agents' controller): both get the same rows.
``docs/network.md`` states the semantics; in short:

- every ``period`` steps each agent sends its state ``(q_j, p_j)`` over each directed link
  ``j -> i`` of the step (the pairs of the interaction graph at the sending step: within
  the radius for an r-disk graph, the edges of a fixed graph, every pair for a law acting
  on all pairs); the leader sends its state to the informed agents the same way;
- a message sent at step ``k'`` is lost with the channel's probability, or arrives at
  ``k' + d`` with the delay ``d`` drawn for it; at step ``k`` agent ``i`` holds, of each
  sender, the most recent message that has arrived by ``k`` (its *age* is ``k - k'``),
  with the Gaussian errors drawn for that message added; a message older than
  ``max_age`` is dropped;
- a sender of which ``i`` holds nothing is not a neighbour (before a first message, after
  ``max_age``); on an r-disk graph a sender is a neighbour when the position held of it is
  within the radius of ``i``'s own position (the current one under the ``communication``
  delay model, the one of the message's sending step under ``input``);
- under ``compensation: predict`` every state the law uses, of age ``a`` steps, is first
  extrapolated to the current step at constant acceleration (``q + p s + f s^2 / 2``, ``p +
  f s``, ``s = a dt``; a neighbour's message carries its sender's acceleration over the step
  before it was sent, the leader's its own), before the r-disk neighbour decision;
- an informed agent without any held leader state applies the law of an uninformed agent
  (``combine`` with ``leader=None``).

The section is read by :mod:`flock_swarm.core.network_spec`, the statistics are kept by
:mod:`flock_swarm.core.network_stats` (both names are this module's too).

Every draw is a pure function of ``(seed, stream, step, receiver, sender)`` through the
splitmix64 hash (:func:`uniforms`), vectorised in NumPy: the result does not depend on the
order of evaluation, on which agents a process evaluates, or on the number of processes.
The memory is the links of the last ``max_age`` sending steps (a few numbers per link) and
the agents' own states over those steps: never an ``N x N`` array.
"""

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from flock_swarm.core.graphs import EdgeList, within_radius
from flock_swarm.core.laws.base import AgentData, Law
from flock_swarm.core.laws.evaluation import control, state_rates
from flock_swarm.core.leaders.base import LeaderState
from flock_swarm.core.network_spec import (CHANNEL_KEYS, Channel, COMPENSATIONS, Delay,
                                           DELAY_LAWS, DELAY_MODELS, Loss, LOSS_MODELS,
                                           MAX_WINDOW, NETWORK_KEYS, NetworkSpec,
                                           parse_network, STEP_TOLERANCE, steps_of)
from flock_swarm.core.network_stats import (_statistics, ReportedUse, STATISTICS, Tally,
                                            USAGE_LABELS)

#: The section (:mod:`flock_swarm.core.network_spec`) and the statistics
#: (:mod:`flock_swarm.core.network_stats`) are also this module's names, as they were.
__all__ = ['CHANNEL_KEYS', 'COMPENSATIONS', 'Channel', 'DELAY_LAWS', 'DELAY_MODELS', 'Delay',
           'LEADER', 'LOSS_MODELS', 'Loss', 'MAX_WINDOW', 'NETWORK_KEYS', 'NetworkSpec',
           'NetworkState', 'Held', 'ReportedUse', 'STATISTICS', 'STEP_TOLERANCE', 'Tally',
           'USAGE_LABELS', 'extrapolated', 'neighbourhood_of', 'normals', 'parse_network',
           'predicted_leader', 'splitmix64', 'steps_of', 'uniforms']

#: The sender id of the virtual leader in the draws (no agent has it: ids are < 10**6).
LEADER = 0xFFFFFFFF

# The streams of the draws: one per kind, so that no two draws of a message share a value.
_DELAY, _LOSS, _GE_STEP, _GE_START, _NOISE = 1, 2, 3, 4, 16
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1, _MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_GOLDEN_INT, _MIX1_INT, _MIX2_INT = 0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB
_MASK64 = (1 << 64) - 1
#: The arrival of a lost message: never.
_NEVER = np.iinfo(np.int64).max


# --------------------------------------------------------------------------------------------
# The generator


def splitmix64(x: np.ndarray) -> np.ndarray:
    """Return splitmix64's output for the states ``x`` (Steele, Lea, Flood 2014).

    ``z = x + 0x9E3779B97F4A7C15``, then ``z ^= z >> 30; z *= 0xBF58476D1CE4E5B9;
    z ^= z >> 27; z *= 0x94D049BB133111EB; z ^= z >> 31``, all modulo ``2**64``.

    :param x: ``uint64`` array.
    :return: ``uint64`` array of the same shape.
    """
    # In place on one new array: the same integer arithmetic with a third of the temporaries.
    z = x + _GOLDEN
    z ^= z >> _S30
    z *= _MIX1
    z ^= z >> _S27
    z *= _MIX2
    z ^= z >> _S31
    return z


def _splitmix64_int(x: int) -> int:
    """Return :func:`splitmix64` of one integer, in Python's integers (a key's prefix)."""
    z = (x + _GOLDEN_INT) & _MASK64
    z = ((z ^ (z >> 30)) * _MIX1_INT) & _MASK64
    z = ((z ^ (z >> 27)) * _MIX2_INT) & _MASK64
    return z ^ (z >> 31)


def uniforms(seed: int, stream: int, step, receiver: np.ndarray,
             sender: np.ndarray) -> np.ndarray:
    """Return one uniform in ``[0, 1)`` per ``(step, receiver, sender)``, a pure function.

    The key is hashed in a chain: ``h = s(s(s(s(s(seed) ^ stream) ^ step) ^ receiver) ^
    sender)`` with ``s`` = :func:`splitmix64`; the top 53 bits of ``h`` give the uniform.

    :param seed: the scenario's seed.
    :param stream: the kind of draw (delay, loss, noise component...).
    :param step: the sending step (an int or an array broadcast with the ids).
    :param receiver: receiving agent ids.
    :param sender: sending agent ids (:data:`LEADER` for the leader).
    :return: float array, the broadcast shape of ``step``, ``receiver`` and ``sender``.
    """
    with np.errstate(over='ignore'):
        if np.ndim(step) == 0:
            # One step: the chain's scalar prefix in Python's integers (the same bits).
            h = _splitmix64_int(_splitmix64_int(seed % (1 << 64)) ^ stream)
            h = np.uint64(_splitmix64_int(h ^ (int(step) & _MASK64)))
        else:
            h = splitmix64(np.full(1, seed % (1 << 64), dtype=np.uint64))
            h = splitmix64(h ^ np.uint64(stream))
            h = splitmix64(h ^ np.asarray(step).astype(np.uint64))
        h = splitmix64(h ^ np.asarray(receiver).astype(np.uint64))
        h = splitmix64(h ^ np.asarray(sender).astype(np.uint64))
    return (h >> np.uint64(11)).astype(np.float64) * 2.0 ** -53


def normals(seed: int, stream: int, step, receiver: np.ndarray,
            sender: np.ndarray) -> np.ndarray:
    """Return standard normal draws (Box-Muller on two streams ``stream``, ``stream + 1``)."""
    u1 = uniforms(seed, stream, step, receiver, sender)
    u2 = uniforms(seed, stream + 1, step, receiver, sender)
    return np.sqrt(-2.0 * np.log1p(-u1)) * np.cos(2.0 * np.pi * u2)


# --------------------------------------------------------------------------------------------
# A run's messages


@dataclass
class _Sent:
    """The messages of one sending step over one channel (directed links, sorted by key).

    The columns are packed in two arrays, so that a message is moved with two takes:
    ``ints`` (key, sending step, receiver, sender) and ``floats`` (weight, position,
    velocity and, on the leader's channel, acceleration). ``due`` maps an arrival step to
    the rows arriving then (ascending); a step's entry is removed when it is taken in.
    """

    step: int
    ints: np.ndarray
    floats: np.ndarray
    arrival: np.ndarray
    lost: int
    bad: np.ndarray | None
    due: dict[int, np.ndarray]

    @property
    def key(self) -> np.ndarray:
        """Return the links' keys (``receiver * 2**32 + sender``, ascending)."""
        return self.ints[:, 0]

    @property
    def receiver(self) -> np.ndarray:
        """Return the receivers."""
        return self.ints[:, 2]


@dataclass
class Held:
    """What the receivers hold at a step, one row per (receiver, sender) with a message.

    :ivar receiver: receiving agents.
    :ivar sender: sending agents (:data:`LEADER` for the leader).
    :ivar age: ``k - k'`` [steps].
    :ivar weight: the link's weight at sending.
    :ivar q: the position held (with its error).
    :ivar p: the velocity held (with its error).
    :ivar a: the leader's acceleration held (leader channel only).
    """

    receiver: np.ndarray
    sender: np.ndarray
    age: np.ndarray
    weight: np.ndarray
    q: np.ndarray
    p: np.ndarray
    a: np.ndarray | None = None


class _Link:
    """One channel's messages over the last ``max_age`` sending steps.

    Besides the sending steps' records (``sent``: the messages in flight, the
    Gilbert-Elliott chains, the delivered count), the link keeps a table of what is held:
    per directed link, sorted by key, the newest message arrived so far (packed as in
    :class:`_Sent`). Each step merges in only the messages arriving at it, so :meth:`held`
    is a view of the table rather than a search through every sending step of the window
    (measured at N = 1000: the search was most of the model's cost). The table's arrays are
    replaced, never written in place, so a :class:`Held` handed out stays valid.
    """

    def __init__(self, channel: Channel, seed: int, dim: int, window: int) -> None:
        self.channel, self.seed, self.dim, self.window = channel, seed, dim, window
        self.sent: deque[_Sent] = deque()
        self.key = np.zeros(0, dtype=np.int64)
        self.ints = np.zeros((0, 4), dtype=np.int64)
        self.floats: np.ndarray | None = None

    def send(self, k: int, receiver: np.ndarray, sender: np.ndarray, weight: np.ndarray,
             q: np.ndarray, p: np.ndarray, a: np.ndarray | None = None) -> None:
        """Send step ``k``'s messages (states already gathered per link, sender's values),
        then take in the messages arriving at ``k`` (called once per step, in order)."""
        while self.sent and self.sent[0].step < k - self.window:
            self.sent.popleft()
        if k % self.channel.period == 0:
            self.sent.append(self._messages(k, receiver, sender, weight, q, p, a))
        self._arrive(k)

    def _messages(self, k, receiver, sender, weight, q, p, a) -> _Sent:
        """Return step ``k``'s messages with their losses, delays and errors drawn."""
        ch, seed, dim = self.channel, self.seed, self.dim
        size = receiver.size
        ints = np.empty((size, 4), dtype=np.int64)
        ints[:, 0] = receiver.astype(np.int64) * (LEADER + 1) + sender.astype(np.int64)
        ints[:, 1], ints[:, 2], ints[:, 3] = k, receiver, sender
        floats = np.empty((size, 1 + (2 if a is None else 3) * dim))
        floats[:, 0], floats[:, 1:1 + dim], floats[:, 1 + dim:1 + 2 * dim] = weight, q, p
        if a is not None:
            floats[:, 1 + 2 * dim:] = a
        order = np.argsort(ints[:, 0], kind='stable')
        # take(): the same rows as fancy indexing, several times faster on 2-D arrays.
        ints, floats = ints.take(order, axis=0), floats.take(order, axis=0)
        key, receiver, sender = ints[:, 0], ints[:, 2], ints[:, 3]
        lost, bad = self._lost(k, key, receiver, sender)
        if ch.delay.low == ch.delay.high:
            # A fixed delay draws nothing (Delay.draw would return it for any uniform).
            arrival = np.where(lost, _NEVER, k + ch.delay.low)
        else:
            delay = ch.delay.draw(uniforms(seed, _DELAY, k, receiver, sender))
            arrival = np.where(lost, _NEVER, k + delay)
        for c in range(dim):
            if ch.noise_position > 0.0:
                floats[:, 1 + c] += ch.noise_position * normals(seed, _NOISE + 2 * c, k,
                                                                receiver, sender)
            if ch.noise_velocity > 0.0:
                floats[:, 1 + dim + c] += ch.noise_velocity * normals(
                    seed, _NOISE + 2 * (3 + c), k, receiver, sender)
        rows = np.flatnonzero(~lost)
        if ch.delay.low == ch.delay.high:
            due = {k + ch.delay.low: rows}
        else:
            # Stable: the rows arriving at one step stay ascending, i.e. sorted by key.
            rows = rows[np.argsort(arrival[rows], kind='stable')]
            steps, starts = np.unique(arrival[rows], return_index=True)
            due = dict(zip(steps.tolist(), np.split(rows, starts[1:])))
        return _Sent(k, ints, floats, arrival, size - rows.size, bad, due)

    def _arrive(self, k: int) -> None:
        """Merge the messages arriving at ``k`` into the table; drop what left the window."""
        for sent in self.sent:
            rows = sent.due.pop(k, None)
            if rows is not None and rows.size:
                self._merge(sent, rows)
        step = self.ints[:, 1]
        if step.size and step.min() < k - self.window:
            keep = np.flatnonzero(step >= k - self.window)
            self.key, self.ints, self.floats = \
                self.key.take(keep), self.ints.take(keep, axis=0), self.floats.take(keep, axis=0)

    def _merge(self, sent: _Sent, rows: np.ndarray) -> None:
        """Put the messages ``rows`` of ``sent`` into the table where they are newer."""
        key = sent.key.take(rows)
        size = self.key.size
        if size == 0:
            self.key = key
            self.ints, self.floats = sent.ints.take(rows, axis=0), sent.floats.take(rows, axis=0)
            return
        pos = np.searchsorted(self.key, key)
        at = np.minimum(pos, size - 1)
        found = self.key.take(at) == key
        # A message sent earlier than the one held (random delays) does not replace it.
        replace = np.flatnonzero(found & (self.ints[:, 1].take(at) < sent.step))
        new = np.flatnonzero(~found)
        # The merged table as rows of [table; sent]: a held row moves down by the new keys
        # before it, the new ones go in between, a replaced one takes the message's row.
        # (Row indices built in 1-D, the rows moved by one take: fancy assignment of 2-D rows
        # is several times slower.)
        before = pos.take(new)
        source = np.empty(size + new.size, dtype=np.int64)
        to_held = np.arange(size) + np.searchsorted(before, np.arange(size), side='right')
        source[to_held] = np.arange(size)
        source[before + np.arange(new.size)] = size + rows.take(new)
        source[to_held.take(pos.take(replace))] = size + rows.take(replace)
        ints = np.concatenate([self.ints, sent.ints]).take(source, axis=0)
        self.floats = np.concatenate([self.floats, sent.floats]).take(source, axis=0)
        self.ints, self.key = ints, ints[:, 0].copy()

    def _lost(self, k, key, receiver, sender) -> tuple[np.ndarray, np.ndarray | None]:
        loss, seed = self.channel.loss, self.seed
        if not loss.active:
            return np.zeros(key.size, dtype=bool), None
        if loss.model == 'bernoulli':
            return uniforms(seed, _LOSS, k, receiver, sender) < loss.p, None
        # The chain of a link continues from its state at the channel's previous sending
        # step; a link that did not exist then starts from the stationary distribution.
        bad = uniforms(seed, _GE_START, k, receiver, sender) < loss.bad_fraction
        prev = self.sent[-1] if self.sent else None
        if prev is not None and prev.step == k - self.channel.period and prev.key.size:
            at = np.minimum(np.searchsorted(prev.key, key), prev.key.size - 1)
            known = prev.key[at] == key
            u = uniforms(seed, _GE_STEP, k, receiver, sender)
            was = prev.bad[at]
            moved = np.where(was, u >= loss.p_bad_good, u < loss.p_good_bad)
            bad = np.where(known, moved, bad)
        p_loss = np.where(bad, loss.loss_bad, loss.loss_good)
        return uniforms(seed, _LOSS, k, receiver, sender) < p_loss, bad

    def held(self, k: int, receivers: np.ndarray | None) -> Held:
        """Return, per link, the most recent message arrived by ``k`` within the window.

        :param k: the step last sent (:meth:`send` took in the arrivals up to it).
        :param receivers: the receivers to return (``None``: all).
        """
        ints, floats, dim = self.ints, self.floats, self.dim
        if floats is None or ints.shape[0] == 0:
            empty = np.zeros(0, dtype=np.int64)
            return Held(empty, empty, empty, np.zeros(0), np.zeros((0, dim)),
                        np.zeros((0, dim)), np.zeros((0, dim)))
        if receivers is not None:
            keep = receivers[ints[:, 2]]
            if not keep.all():
                keep = np.flatnonzero(keep)
                ints, floats = ints.take(keep, axis=0), floats.take(keep, axis=0)
        a = floats[:, 1 + 2 * dim:] if floats.shape[1] > 1 + 2 * dim else None
        return Held(ints[:, 2], ints[:, 3], k - ints[:, 1], floats[:, 0],
                    floats[:, 1:1 + dim], floats[:, 1 + dim:1 + 2 * dim], a)

    def delivered(self, receivers: np.ndarray | None) -> tuple[int, int]:
        """Return (messages not lost, messages) of the channel's latest sending step."""
        if not self.sent:
            return 0, 0
        sent = self.sent[-1]
        if receivers is None:
            return sent.arrival.size - sent.lost, sent.arrival.size
        mask = receivers[sent.receiver]
        lost = sent.arrival == _NEVER
        return int((mask & ~lost).sum()), int(mask.sum())


#: How the neighbours are decided on the held states: an r-disk graph (the radius), a fixed
#: graph (its edges), a law acting on all pairs over an r-disk graph (weights within r).
DISK, FIXED, ALL_PAIRS_DISK = 'disk', 'fixed', 'all_pairs_disk'


class NetworkState:
    """A run's messages, fed the true states every step, asked for the held ones.

    ``sim`` feeds the whole swarm and evaluates every agent; the agents' controller feeds
    the same true states (it receives every odometry) and evaluates the agents it hosts
    (``ids``): the draws being pure functions of the link, both get the same rows.
    """

    def __init__(self, spec: NetworkSpec, seed: int, n: int, dim: int, law: Law,
                 neighbourhood: str, coupling: float = 1.0) -> None:
        """Create the state of a run.

        :param spec: the ``network:`` section.
        :param seed: the scenario's seed (keys every draw).
        :param n: the number of agents.
        :param dim: the dimension.
        :param law: the law (its radius and strictness decide r-disk neighbours).
        :param neighbourhood: :data:`DISK`, :data:`FIXED` or :data:`ALL_PAIRS_DISK`.
        :param coupling: the law's coupling weight (weights of :data:`ALL_PAIRS_DISK`).
        """
        self.spec, self.n, self.dim, self.law = spec, n, dim, law
        self.neighbourhood, self.coupling = neighbourhood, coupling
        window = spec.max_age
        self.links = _Link(spec.agents, seed, dim, window)
        self.leader_links = _Link(spec.leader, seed, dim, window)
        # The agents' own states over the window (only the input delay model uses them).
        own = (window + 1, n, dim) if spec.model == 'input' else (0, n, dim)
        self.own_q, self.own_p = np.zeros(own), np.zeros(own)
        # Under predict every message carries its sender's acceleration over the step before
        # it was sent (what the sender's last command did; it knows its own velocities).
        self.own_a = np.zeros(own if spec.predict else (0, n, dim))
        self.last_p: tuple[int, np.ndarray] | None = None
        self.step = -1
        self.leader_now: LeaderState | None = None
        # Since the last recorded instant (a record every few steps would otherwise alias
        # with a period).
        self.tally = Tally()
        #: The counts of the last step (:class:`Tally`'s order), as :meth:`control` or
        #: :meth:`observe` counted them.
        self.counts = [0, 0, 0, 0, -1]

    def send(self, k: int, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
             edges: EdgeList, informed: np.ndarray, receivers: np.ndarray | None = None) -> None:
        """Send step ``k``'s messages: every agent's state over the step's links.

        :param k: the step (called once per step, in order).
        :param q: true positions of every agent.
        :param p: true velocities of every agent.
        :param leader: the leader's true state (``None``: lost, nothing sent).
        :param edges: the undirected interaction graph at ``k`` (its pairs are the links).
        :param informed: which agents receive the leader's state.
        :param receivers: the agents whose incoming messages to keep (``None``: all).
        """
        self.step, self.leader_now = k, leader
        acc = self._acceleration(k, p) if self.spec.predict else None
        if self.spec.model == 'input':
            w = self.spec.max_age + 1
            self.own_q[k % w], self.own_p[k % w] = q, p
            if acc is not None:
                self.own_a[k % w] = acc
        rec = np.concatenate([edges.i, edges.j]).astype(np.int64)
        snd = np.concatenate([edges.j, edges.i]).astype(np.int64)
        weight = np.concatenate([edges.weight, edges.weight])
        if receivers is not None:
            keep = receivers[rec]
            rec, snd, weight = rec[keep], snd[keep], weight[keep]
        self.links.send(k, rec, snd, weight, q.take(snd, axis=0), p.take(snd, axis=0),
                        None if acc is None else acc.take(snd, axis=0))
        if not self.spec.leader.active:
            # Informed agents then use the leader's current state (_combine): nothing to send.
            return
        lrec = np.flatnonzero(informed if receivers is None else informed & receivers)
        if leader is None:
            # A lost leader (an agent node past its timeout) sends nothing this step.
            lrec = lrec[:0]
        m = lrec.size
        sent = [np.zeros((0, self.dim))] * 3 if leader is None else \
            [np.broadcast_to(x, (m, self.dim)) for x in (leader.q, leader.p, leader.a)]
        self.leader_links.send(k, lrec, np.full(m, LEADER, dtype=np.int64), np.ones(m), *sent)

    def _acceleration(self, k: int, p: np.ndarray) -> np.ndarray:
        """Return every agent's acceleration over its last step, ``(p(k) - p(k')) /
        ((k - k') dt)`` with ``k'`` the step sent before (zero at the first)."""
        last, self.last_p = self.last_p, (k, p.copy())
        if last is None:
            return np.zeros_like(p)
        return (p - last[1]) / ((k - last[0]) * self.spec.dt)

    def control(self, ids: np.ndarray | None, q: np.ndarray, p: np.ndarray,
                agents: AgentData, dt: float, t: float = 0.0) -> tuple[np.ndarray, dict]:
        """Return ``u`` of the agents ``ids`` on the held states, and the step's statistics.

        :param ids: the agents to evaluate (ascending), ``None`` for all.
        :param q: true positions of every agent at the current step.
        :param p: true velocities of every agent.
        :param agents: per-agent data of ``ids`` (``agents.subset(ids)``; all for ``None``).
        :param dt: the step.
        :param t: the time of the step (for a ``combine`` that takes it).
        :return: ``u`` of ``ids`` and ``{'network_delivered', 'network_age_mean',
            'network_age_max'}`` of their incoming links (ages in seconds; NaN when none).
        """
        law = self.law
        if ids is None:
            # Every agent: no mask of the hosted ones, and a row is the agent's id.
            ids, hosted = np.arange(self.n), None
            row = ids
        else:
            ids = np.asarray(ids)
            hosted = self._mask(ids)
            row = np.full(self.n, -1, dtype=np.int64)
            row[ids] = np.arange(ids.size)
        held, own_q, own_p, use, weight = self._used(hosted, q, p)
        chosen = np.flatnonzero(use)
        # Column-major, as pair_sums hands them: the laws' per-component arithmetic then runs
        # on contiguous memory (measured: 3x faster squared norms at N = 1000); gathered and
        # laid out in one copy (take along the transposed rows).
        ends = [np.take(x.T, chosen, axis=1).T for x in (own_q, own_p, held.q, held.p)]
        to_i = law.pair(*ends, weight.take(chosen))
        at = row.take(held.receiver.take(chosen))
        s = np.empty((ids.size, to_i.shape[1]))
        for col in range(to_i.shape[1]):
            s[:, col] = np.bincount(at, weights=to_i[:, col], minlength=ids.size)
        u = self._combine(ids, row, q, p, s, agents, dt,
                          lambda *args: control(law, *args, t=t))
        return u, self._count(hosted, held.age.take(chosen), dt)

    def observe(self, q: np.ndarray, p: np.ndarray, dt: float) -> dict:
        """Count the current step's statistics of every agent's links, as :meth:`control`
        of all agents does, without evaluating the law (an observer: the world node).

        :param q: true positions of every agent at the current step (after :meth:`send`).
        :param p: true velocities of every agent.
        :param dt: the step.
        :return: the step's statistics (as :meth:`control`'s).
        """
        held, _, _, use, _ = self._used(None, q, p)
        return self._count(None, held.age[use], dt)

    def _used(self, hosted: np.ndarray | None, q: np.ndarray, p: np.ndarray) -> tuple:
        """Return the held messages of ``hosted`` (``None``: all), the receivers' own states,
        which messages make neighbours and their weights."""
        law = self.law
        held = self.links.held(self.step, hosted)
        if self.spec.predict:
            # Each neighbour's state at the current step at the constant acceleration its
            # message carries: (q + p s + f s^2 / 2, p + f s), s = a dt, before the
            # neighbours are decided.
            held = replace(held, **dict(zip('qp', extrapolated(
                held.q, held.p, held.a, held.age * self.spec.dt))))
        own_q, own_p = self._own(held.receiver, held.age, q, p)
        use = np.ones(held.receiver.size, dtype=bool)
        weight = held.weight
        if self.neighbourhood != FIXED:
            dq = held.q - own_q
            near = within_radius(np.einsum('ek,ek->e', dq, dq), law.radius, law.strict_radius)
            if self.neighbourhood == DISK:
                use = near
            else:
                weight = np.where(near, self.coupling, 0.0)
        return held, own_q, own_p, use, weight

    def _count(self, hosted: np.ndarray | None, ages: np.ndarray, dt: float) -> dict:
        """Fold a step's deliveries and ``ages`` (of the messages used) into the tally;
        return the step's statistics."""
        got, total = self.links.delivered(hosted)
        age_sum, age_max = int(ages.sum()), int(ages.max()) if ages.size else -1
        sending = self.step % self.spec.agents.period == 0
        self.counts = [got if sending else 0, total if sending else 0, age_sum, ages.size,
                       age_max]
        self.tally.add(self.counts)
        return _statistics([got, total, age_sum, ages.size, age_max], dt)

    def recorded(self, dt: float) -> dict:
        """Return the statistics of the steps since the last call, and start anew.

        ``network_delivered``: of the messages sent at those steps, the fraction not lost;
        ``network_age_mean`` and ``network_age_max``: the mean and largest age [s] of the
        neighbour states the law used at those steps (NaN when none).
        """
        return self.tally.take(dt)

    def usage(self, ids: np.ndarray, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Return, per agent of ``ids``, what :meth:`control` used at the current step.

        Realtime mode: each agent reports it with its command (``docs/network.md``), and
        the world adds the real transport's age to the ages.

        :param ids: the agents (ascending), as given to :meth:`control`.
        :param q: true positions of every agent at the current step (as for :meth:`control`).
        :param p: true velocities of every agent.
        :return: shape ``(m, 5)``, the columns of :data:`USAGE_LABELS`: messages of the
            current step to the agent delivered and sent (0 at a step that sends none), the
            sum of the ages [steps] of the neighbour states used, their number, and the
            largest (-1 when none).
        """
        ids = np.asarray(ids)
        hosted = self._mask(ids)
        row = np.full(self.n, -1, dtype=np.int64)
        row[ids] = np.arange(ids.size)
        held, _, _, use, _ = self._used(hosted, q, p)
        at, ages = row[held.receiver[use]], held.age[use]
        out = np.zeros((ids.size, len(USAGE_LABELS)))
        out[:, 4] = -1.0
        out[:, 2] = np.bincount(at, weights=ages, minlength=ids.size)
        out[:, 3] = np.bincount(at, minlength=ids.size)
        np.maximum.at(out[:, 4], at, ages)
        sent = self.links.sent[-1] if self.links.sent else None
        if sent is not None and sent.step == self.step:
            mine = hosted[sent.receiver]
            to = row[sent.receiver[mine]]
            got = sent.arrival[mine] != np.iinfo(np.int64).max
            out[:, 0] = np.bincount(to, weights=got, minlength=ids.size)
            out[:, 1] = np.bincount(to, minlength=ids.size)
        return out

    def advance_state(self, ids: np.ndarray | None, q: np.ndarray, p: np.ndarray,
                      agents: AgentData, dt: float, t: float = 0.0) -> None:
        """Advance the law's adaptive state in place with the leader's state held.

        The same explicit step as :func:`flock_swarm.core.laws.evaluation.advance_state`, each
        informed agent using the leader's state it holds (own state as in :meth:`control`).
        A ``state_rate`` that takes the pair sums receives ``s=None`` under the network model
        (the sums of the held states are :meth:`control`'s, not kept).
        """
        if not agents.state:
            return
        ids = np.arange(self.n) if ids is None else np.asarray(ids)
        row = np.full(self.n, -1, dtype=np.int64)
        row[ids] = np.arange(ids.size)

        def rate(qg, pg, sg, leader, group, dt_):
            return state_rates(self.law, qg, pg, leader, group, None, t)
        rates = self._combine(ids, row, q, p, None, agents, dt, rate)
        for key, value in rates.items():
            agents.state[key] += dt * value

    def _own(self, receiver: np.ndarray, age: np.ndarray, q: np.ndarray,
             p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return each receiver's own state: current, or at the message's sending step
        (extrapolated from it to the current step at constant velocity under ``predict``)."""
        if self.spec.model == 'communication':
            return q.take(receiver, axis=0), p.take(receiver, axis=0)
        slot = (self.step - age) % (self.spec.max_age + 1)
        own_q, own_p = self.own_q[slot, receiver], self.own_p[slot, receiver]
        if self.spec.predict:
            own_q, own_p = extrapolated(own_q, own_p, self.own_a[slot, receiver],
                                        age * self.spec.dt)
        return own_q, own_p

    def _combine(self, ids, row, q, p, s, agents, dt, fn):
        """Apply ``fn(q, p, s, leader, group, dt)`` per group of agents sharing a leader state.

        Uninformed agents use the leader's true state, as without the section (they do not
        receive it); informed agents the one they hold (``None`` when they hold none), with
        their own state at its sending step under the ``input`` model.
        """
        leader = self.leader_now
        qs, ps = q[ids], p[ids]
        # Without a leader channel every informed agent holds the leader's current state (age
        # 0, so its own state is current under either delay model too).
        if not self.spec.leader.active or not agents.informed.any():
            return fn(qs, ps, s, leader, agents, dt)
        held = self.leader_links.held(self.step, self._mask(ids))
        key = np.full(ids.size, -1, dtype=np.int64)  # -1: the true leader
        key[agents.informed] = -2  # -2: informed, nothing held
        at = row[held.receiver]
        informed_rows = agents.informed[at]
        at, which = at[informed_rows], np.flatnonzero(informed_rows)
        noisy = self.spec.leader.noise_position > 0 or self.spec.leader.noise_velocity > 0
        key[at] = at if noisy else held.age[which]
        groups = {}
        for value in np.unique(key):
            members = np.flatnonzero(key == value)
            if value == -1:
                groups[value] = (members, leader, qs[members], ps[members])
            elif value == -2:
                groups[value] = (members, None, qs[members], ps[members])
            else:
                first = which[np.searchsorted(at, members[0])]
                state = LeaderState(held.q[first], held.p[first], held.a[first])
                if self.spec.predict:
                    state = predicted_leader(state, held.age[first] * self.spec.dt)
                own_q, own_p = qs[members], ps[members]
                if self.spec.model == 'input':
                    own_q, own_p = self._own(ids[members], np.full(members.size,
                                                                   held.age[first]), q, p)
                groups[value] = (members, state, own_q, own_p)
        out = None
        for members, state, own_q, own_p in groups.values():
            part = fn(own_q, own_p, None if s is None else s[members], state,
                      agents.subset(members), dt)
            out = _scatter(out, members, part, ids.size)
        return out

    def _mask(self, ids: np.ndarray) -> np.ndarray:
        mask = np.zeros(self.n, dtype=bool)
        mask[ids] = True
        return mask


def predicted_leader(state: LeaderState, s: float) -> LeaderState:
    """Return a held leader state extrapolated by ``s`` seconds at constant acceleration.

    ``q + p s + a s^2 / 2``, ``p + a s``, ``a`` (the leader's message carries its
    acceleration ``f_gamma``).

    :param state: the state held.
    :param s: its age [s].
    """
    return LeaderState(*extrapolated(state.q, state.p, state.a, s), state.a)


def extrapolated(q: np.ndarray, p: np.ndarray, a: np.ndarray, s) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(q + p s + a s^2 / 2, p + a s)``: a state extrapolated by ``s`` seconds at
    the constant acceleration ``a``.

    :param q: positions, ``(dim,)`` or one row per state.
    :param p: velocities, as ``q``.
    :param a: accelerations, as ``q``.
    :param s: the time [s]: a number, or one per row of ``q``.
    """
    s = np.asarray(s, dtype=float)
    if s.ndim:
        s = s[:, None]
    return q + p * s + a * (0.5 * s * s), p + a * s


def _scatter(out, members: np.ndarray, part, size: int):
    """Put a group's rows (an array or a mapping of arrays) into the full result."""
    if isinstance(part, dict):
        out = {} if out is None else out
        for key, value in part.items():
            if key not in out:
                out[key] = np.zeros((size, *np.shape(value)[1:]))
            out[key][members] = value
        return out
    if out is None:
        out = np.zeros((size, *part.shape[1:]))
    out[members] = part
    return out


def neighbourhood_of(graph_type: str, all_pairs: bool) -> str:
    """Return how a law on a graph type decides its neighbours on held states."""
    if graph_type != 'disk':
        return FIXED
    return ALL_PAIRS_DISK if all_pairs else DISK
