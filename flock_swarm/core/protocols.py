"""The flocking laws: one implementation each, shared by the simulator and the agent node.

A law is split in two pure functions so that the same code serves a whole swarm (vectorised
over edges) and a single agent that only knows its neighbours:

``pair(qi, pi, qj, pj, w) -> (E, k)``
    the contribution of neighbour ``j`` to agent ``i`` for a batch of ``E`` directed edges
    ``j -> i`` with edge weights ``w``; summed over the neighbours of each agent.
``combine(q, p, s, leader, agents, dt) -> (n, dim)``
    the control input of each agent from its own state, the summed pair terms ``s``, the
    virtual leader and the per-agent data (informed flag, gains, adaptive state).

:func:`swarm_control` evaluates a law on an undirected edge list (each pair once, using
antisymmetry where the law has it); :func:`group_control` evaluates it for a subset of the
agents (the one agent of an agent node, or the agents a container hosts) from the edges
that touch them; :func:`local_control` evaluates it for one agent and a list of its
neighbours' states. All three call the same ``pair`` and ``combine``.
"""

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.dynamics import LeaderState
from flock_swarm.core.graphs import EdgeList


@dataclass
class AgentData:
    """Per-agent data of a law, indexed like the agents it is passed with.

    :ivar informed: ``h_i`` of [Su09] eq. (10): ``True`` for agents that see the leader.
    :ivar nav_gains: per-agent navigation gain matrices ``(n, 2, dim, dim)`` for [Yu10]
        eq. (7) (``D_i H_i`` and ``D~_i H~_i``), or ``None``.
    :ivar adaptive: per-agent adaptive gain ``h_i`` of [Zhou12] eq. (4), or ``None``.
    """

    informed: np.ndarray
    nav_gains: np.ndarray | None = None
    adaptive: np.ndarray | None = None

    def subset(self, idx: np.ndarray) -> 'AgentData':
        """Return the data of the agents ``idx``."""
        return AgentData(
            self.informed[idx],
            None if self.nav_gains is None else self.nav_gains[idx],
            None if self.adaptive is None else self.adaptive[idx])


@dataclass(frozen=True)
class Protocol:
    """Base class of the laws: parameters as frozen dataclass fields, plus the law itself."""

    #: Scenario name of the law.
    name: ClassVar[str] = ''
    #: Whether ``pair(j -> i) = -pair(i -> j)``, so each undirected pair is evaluated once.
    antisymmetric: ClassVar[bool] = True
    #: Whether the pair term acts between *all* pairs (weights select the coupled ones).
    all_pairs: ClassVar[bool] = False
    #: Whether the r-disk neighbourhood is ``< r`` (``True``) or ``<= r``.
    strict_radius: ClassVar[bool] = True

    @property
    def radius(self) -> float:
        """Return the interaction radius of the r-disk graph."""
        raise NotImplementedError

    def pair(self, qi: np.ndarray, pi: np.ndarray, qj: np.ndarray, pj: np.ndarray,
             w: np.ndarray) -> np.ndarray:
        """Return the contribution of ``j`` to ``i`` for each directed edge."""
        raise NotImplementedError

    def combine(self, q: np.ndarray, p: np.ndarray, s: np.ndarray,
                leader: LeaderState | None, agents: AgentData, dt: float) -> np.ndarray:
        """Return the control input of each agent.

        ``leader=None`` means the leader's state is not known (a lost leader): every agent
        then applies the law of an uninformed agent, without any navigational term.
        """
        raise NotImplementedError

    def adaptive_rate(self, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                      agents: AgentData) -> np.ndarray | None:
        """Return ``d/dt`` of the adaptive gains, or ``None`` for a law without any."""
        return None


# --------------------------------------------------------------------------------------------
# Su, Wang, Lin 2009 (and Olfati-Saber 2006 Algorithm 2)


@dataclass(frozen=True)
class SuParams(Protocol):
    """Parameters of the protocols of [Su09] (Olfati-Saber's ``psi_alpha`` of [OS06]).

    :ivar r: interaction radius ``r`` (Euclidean).
    :ivar d: desired distance ``d < r``.
    :ivar eps: sigma-norm parameter ``epsilon``.
    :ivar h: bump plateau of ``rho_h``, in ``(0, 1)``.
    :ivar a: attraction limit of ``phi`` (``0 < a <= b``).
    :ivar b: repulsion limit of ``phi``.
    :ivar c1: position navigation gain.
    :ivar c2: velocity navigation gain.
    """

    r: float = 4.0
    d: float = 3.3
    eps: float = 0.1
    h: float = 0.2
    a: float = 5.0
    b: float = 5.0
    c1: float = 0.5
    c2: float = 0.5

    #: Whether only informed agents (``h_i = 1``) get navigational feedback.
    partial: ClassVar[bool] = False
    #: Whether the leader's acceleration ``f_gamma`` is fed forward.
    feedforward: ClassVar[bool] = False

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    @property
    def r_alpha(self) -> float:
        """Return ``r_alpha = ||r||_sigma``."""
        return float(pot.sigma_of_distance(self.r, self.eps))

    @property
    def d_alpha(self) -> float:
        """Return ``d_alpha = ||d||_sigma``."""
        return float(pot.sigma_of_distance(self.d, self.eps))

    def pair(self, qi, pi, qj, pj, w):
        """Return ``phi_alpha(||q_j - q_i||_sigma) n_ij + a_ij (p_j - p_i)``.

        The gradient term ``-grad_{q_i} psi_alpha`` and velocity consensus of [Su09] eq. (7),
        with ``a_ij = rho_h(||q_j - q_i||_sigma / r_alpha)`` (eq. (8)) and
        ``n_ij = (q_j - q_i) / sqrt(1 + eps ||q_j - q_i||^2)``.
        """
        dq = qj - qi
        sq = pot.squared_norm(dq)
        # sqrt(1 + eps ||dq||^2) is shared by the sigma-norm and n_ij; the sigma-norm in the
        # cancellation-free form of pot.sigma_of_distance, from ||dq||^2 directly.
        root = np.sqrt(1.0 + self.eps * sq)
        z = sq / (root + 1.0)
        r_a, d_a = self.r_alpha, self.d_alpha
        # The bump of the action phi_alpha is a_ij: evaluated once for both terms.
        a_ij = pot.bump(z / r_a, self.h)
        # phi_alpha n_ij = (phi_alpha / root) dq: one scalar per edge, then per component.
        coef = pot.phi_alpha(z, r_a, d_a, self.h, self.a, self.b, a_ij)
        coef /= root
        out = np.empty_like(dq)
        for k in range(dq.shape[1]):
            np.multiply(dq[:, k], coef, out=out[:, k])
            out[:, k] += (pj[:, k] - pi[:, k]) * a_ij
        return out

    def combine(self, q, p, s, leader, agents, dt):
        """Add the navigational feedback of [Su09] eq. (7), (10), (33) or Section V.C."""
        if leader is None:
            return s
        nav = -self.c1 * (q - leader.q) - self.c2 * (p - leader.p)
        if self.feedforward:
            nav = nav + leader.a
        if self.partial:
            nav = agents.informed[:, None] * nav
        return s + nav


@dataclass(frozen=True)
class OlfatiSaber2006(SuParams):
    """[Su09] eq. (7): Olfati-Saber's Algorithm 2, every agent informed."""

    name: ClassVar[str] = 'olfati_saber_2006'


@dataclass(frozen=True)
class SuInformed(SuParams):
    """[Su09] eq. (10): navigational feedback only for informed agents (``h_i = 1``)."""

    name: ClassVar[str] = 'su_informed'
    partial: ClassVar[bool] = True


@dataclass(frozen=True)
class SuAccel(SuParams):
    """[Su09] eq. (33): every agent informed, leader acceleration ``f_gamma`` fed forward."""

    name: ClassVar[str] = 'su_accel'
    feedforward: ClassVar[bool] = True


@dataclass(frozen=True)
class SuInformedAccel(SuParams):
    """[Su09] Section V.C: ``h_i [f_gamma + c1 (q_gamma - q_i) + c2 (p_gamma - p_i)]``."""

    name: ClassVar[str] = 'su_informed_accel'
    partial: ClassVar[bool] = True
    feedforward: ClassVar[bool] = True


# --------------------------------------------------------------------------------------------
# Olfati-Saber 2003: the (alpha, alpha) protocol with the sink PD term


@dataclass(frozen=True)
class OlfatiSaber2003Sink(Protocol):
    """[OS03] eq. (22) (the (alpha, alpha) protocol) plus the sink PD term eq. (40).

    :ivar d: desired distance ``d_alpha``.
    :ivar r: interaction radius ``r``.
    :ivar a: attraction limit of the penalty eq. (20), ``0 < a < b``.
    :ivar b: repulsion limit.
    :ivar delta: plateau of the influence map eq. (4).
    :ivar k: smoothness order of the influence map.
    :ivar c_d: velocity-matching (dissipation) gain of eq. (22).
    :ivar c1: sink position gain of eq. (40).
    :ivar c2: sink velocity gain of eq. (40).
    """

    name: ClassVar[str] = 'os2003_sink'

    d: float = 7.0
    r: float = 8.4
    a: float = 1.0
    b: float = 5.0
    delta: float = 0.2
    k: int = 1
    c_d: float = 1.0
    c1: float = 0.1
    c2: float = 0.5

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def pair(self, qi, pi, qj, pj, w):
        """Return ``phi_alpha(||q_j - q_i|| - d_alpha) n_ij + c_d (p_j - p_i)`` ([OS03] (22)).

        ``n_ij`` is the unit vector from ``q_i`` to ``q_j`` (zero for coincident agents).
        """
        dq = qj - qi
        dist = np.sqrt(np.einsum('ek,ek->e', dq, dq))
        safe = np.where(dist > 0.0, dist, 1.0)
        unit = np.where(dist[:, None] > 0.0, dq / safe[:, None], 0.0)
        action = pot.os2003_action(dist - self.d, self.d, self.r, self.a, self.b,
                                   self.delta, self.k)
        return action[:, None] * unit + self.c_d * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt):
        """Add the sink PD term ``-c1 (q_i - q_d) - c2 (p_i - p_d)`` ([OS03] eq. (40))."""
        if leader is None:
            return s
        return s - self.c1 * (q - leader.q) - self.c2 * (p - leader.p)


# --------------------------------------------------------------------------------------------
# Zhou et al. 2012: pseudo-leaders with adaptive gains


@dataclass(frozen=True)
class ZhouPseudoLeader(Protocol):
    """[Zhou12] eq. (4): diffusive velocity coupling, APF gradient, adaptive pseudo-leaders.

    The APF acts between *all* pairs (eq. (4) sums ``j != i`` and the Lyapunov function of
    Theorem 1 sums every pair); the velocity coupling uses the weights ``w_ij`` of the graph.

    :ivar sigma: sigma-norm parameter.
    :ivar c1: APF attraction weight of eq. (3).
    :ivar c2: APF repulsion weight of eq. (3).
    :ivar w: common coupling weight, ``W = w B`` (Section 4.2).
    :ivar k: adaptation rate ``k_i`` of ``h_i' = k_i ||v_i - v_l||^2``.
    :ivar h0: initial adaptive gain ``h_i(0)``.
    :ivar alpha: constant of Assumption A1 of the intrinsic dynamics (pseudo-leader choice).
    :ivar r: radius of the r-disk graph when the scenario uses one (Section 4.4).
    """

    name: ClassVar[str] = 'zhou_pseudo_leader'
    all_pairs: ClassVar[bool] = True

    sigma: float = 0.1
    c1: float = 0.5
    c2: float = 0.5
    w: float = 70.0
    k: float = 0.01
    h0: float = 1.0
    alpha: float = 60.3402
    r: float = 4.0

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def pair(self, qi, pi, qj, pj, w):
        """Return ``V'(s) n_ij + w_ij (p_j - p_i)`` with ``s = ||p_j - p_i||_sigma``.

        ``-grad_{p_i} V_ij = V'(s) (p_j - p_i) / sqrt(1 + sigma ||p_j - p_i||^2)`` for the APF
        of eq. (3); ``w_ij`` is the (already scaled) coupling weight of the edge.
        """
        dq = qj - qi
        s = pot.sigma_norm(dq, self.sigma)
        gradient = pot.zhou_potential_derivative(s, self.c1, self.c2)[:, None] \
            * pot.sigma_grad(dq, self.sigma)
        return gradient + w[:, None] * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt):
        """Add ``u3 = -h_i (v_i - v_l)`` for pseudo-leaders ([Zhou12] eq. (4))."""
        if leader is None:
            return s
        gain = np.where(agents.informed, agents.adaptive, 0.0)
        return s - gain[:, None] * (p - leader.p)

    def adaptive_rate(self, q, p, leader, agents):
        """Return ``h_i' = k ||v_i - v_l||^2`` for pseudo-leaders, ``0`` otherwise."""
        if leader is None:
            return np.zeros(q.shape[0])
        err = p - leader.p
        return np.where(agents.informed, self.k * np.einsum('nk,nk->n', err, err), 0.0)


# --------------------------------------------------------------------------------------------
# Yu, Chen, Cao 2010: pinning observer-based navigation feedback


@dataclass(frozen=True)
class YuPinningObserver(Protocol):
    """[Yu10] eq. (3), (7), (36): pair force, velocity consensus, partial observations.

    The intrinsic term ``f(r_i, v_i)`` of eq. (3) is the scenario's ``intrinsic`` field,
    integrated by the world; the per-agent gains ``D_i H_i`` and ``D~_i H~_i`` come from the
    scenario's ``observers``.

    :ivar a: attraction gain of the pair force.
    :ivar b: repulsion gain (``b > a``).
    :ivar c_bar: repulsion width ``c_bar``.
    :ivar r_s: interaction range (neighbours ``||r_j - r_i|| <= r_s``).
    :ivar c: velocity coupling strength.
    """

    name: ClassVar[str] = 'yu_pinning_observer'
    strict_radius: ClassVar[bool] = False

    a: float = 1.0
    b: float = 20.0
    c_bar: float = 0.2
    r_s: float = 1.0
    c: float = 5.0

    @property
    def radius(self) -> float:
        """Return ``r_s``."""
        return self.r_s

    @property
    def d(self) -> float:
        """Return the equilibrium distance ``sqrt(c_bar ln(b / a))``."""
        return float(np.sqrt(self.c_bar * np.log(self.b / self.a)))

    def pair(self, qi, pi, qj, pj, w):
        """Return ``[a - b exp(-||r_ij||^2 / c_bar)] (r_j - r_i) + c (v_j - v_i)``."""
        dq = qj - qi
        dist = np.sqrt(np.einsum('ek,ek->e', dq, dq))
        return pot.yu_pair_gain(dist, self.a, self.b, self.c_bar)[:, None] * dq \
            + self.c * (pj - pi)

    def combine(self, q, p, s, leader, agents, dt):
        """Add ``-D_i H_i (r_i - r_o) - D~_i H~_i (v_i - v_o)`` ([Yu10] eq. (7))."""
        if agents.nav_gains is None or leader is None:
            return s
        pos = np.einsum('nab,nb->na', agents.nav_gains[:, 0], q - leader.q)
        vel = np.einsum('nab,nb->na', agents.nav_gains[:, 1], p - leader.p)
        return s - pos - vel


# --------------------------------------------------------------------------------------------
# Jadbabaie, Lin, Morse 2003: nearest-neighbour heading alignment with a leader


@dataclass(frozen=True)
class JadbabaieLeader(Protocol):
    """[Jadbabaie03] eq. (38): Vicsek heading average, the leader counted when within ``r``.

    Agents move at the common speed ``speed``; headings live in ``[0, 2 pi)`` as in the paper.
    In the double-integrator world each agent commands the acceleration that reaches the
    averaged velocity ``speed (cos theta, sin theta)`` in one step: ``u = (target - p) / dt``.

    :ivar r: neighbourhood radius (``<= r``).
    :ivar speed: common constant speed ``v``.
    """

    name: ClassVar[str] = 'jadbabaie_leader'
    antisymmetric: ClassVar[bool] = False
    strict_radius: ClassVar[bool] = False

    r: float = 1.0
    speed: float = 1.0

    @property
    def radius(self) -> float:
        """Return ``r``."""
        return self.r

    def pair(self, qi, pi, qj, pj, w):
        """Return ``(theta_j, 1)``: neighbour heading and a count, summed over neighbours."""
        return np.stack((heading(pj), np.ones(pj.shape[0])), axis=-1)

    def combine(self, q, p, s, leader, agents, dt):
        """Average ``theta_i``, the neighbours' and (when within ``r``) ``theta_0``; eq. (38)."""
        if leader is None:
            b, theta_0 = np.zeros(q.shape[0]), 0.0
        else:
            gap = q - leader.q
            b = (np.einsum('nk,nk->n', gap, gap) <= self.r * self.r).astype(float)
            theta_0 = heading(leader.p[None, :])
        theta = (heading(p) + s[:, 0] + b * theta_0) / (1.0 + s[:, 1] + b)
        target = self.speed * np.stack((np.cos(theta), np.sin(theta)), axis=-1)
        return (target - p) / dt


def heading(p: np.ndarray) -> np.ndarray:
    """Return the heading of 2-D velocities in ``[0, 2 pi)`` ([Jadbabaie03] Section II).

    :param p: velocities, shape ``(n, 2)``.
    :return: angles, shape ``(n,)``.
    """
    theta = np.mod(np.arctan2(p[:, 1], p[:, 0]), 2.0 * np.pi)
    # mod() rounds tiny negative angles up to exactly 2 pi, outside [0, 2 pi).
    return np.where(theta >= 2.0 * np.pi, 0.0, theta)


# --------------------------------------------------------------------------------------------
# Registry and evaluation

PROTOCOLS: dict[str, type[Protocol]] = {
    cls.name: cls for cls in (OlfatiSaber2006, SuInformed, SuAccel, SuInformedAccel,
                              OlfatiSaber2003Sink, ZhouPseudoLeader, YuPinningObserver,
                              JadbabaieLeader)
}


def pair_sums(law: Protocol, q: np.ndarray, p: np.ndarray, edges: EdgeList) -> np.ndarray:
    """Return ``s_i = sum_{j in N_i} pair(i <- j)`` for every agent of an undirected graph.

    Each undirected edge is evaluated once when the law is antisymmetric, twice otherwise;
    the sums use :func:`numpy.bincount`, so the cost is linear in the number of edges.

    :param law: the law.
    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param edges: the interaction graph.
    :return: the sums, shape ``(n, k)``.
    """
    n = q.shape[0]
    i, j = edges.i, edges.j
    # The edge ends gathered component by component (take() is several times faster than
    # fancy indexing, with the same values): the (e, dim) arrays are then column-major, so
    # the per-component arithmetic of the laws and the sums below run on contiguous memory
    # (the values do not depend on the layout).
    qt, pt = np.ascontiguousarray(q.T), np.ascontiguousarray(p.T)
    qi, pi, qj, pj = qt.take(i, 1).T, pt.take(i, 1).T, qt.take(j, 1).T, pt.take(j, 1).T
    to_i = law.pair(qi, pi, qj, pj, edges.weight)
    out = np.empty((n, to_i.shape[1]))
    if law.antisymmetric:
        # pair(j <- i) = -pair(i <- j): subtracting its sums is adding those of its negation.
        for col in range(to_i.shape[1]):
            out[:, col] = (np.bincount(i, weights=to_i[:, col], minlength=n)
                           - np.bincount(j, weights=to_i[:, col], minlength=n))
        return out
    to_j = law.pair(qj, pj, qi, pi, edges.weight)
    for col in range(to_i.shape[1]):
        out[:, col] = (np.bincount(i, weights=to_i[:, col], minlength=n)
                       + np.bincount(j, weights=to_j[:, col], minlength=n))
    return out


def swarm_control(law: Protocol, q: np.ndarray, p: np.ndarray, edges: EdgeList,
                  leader: LeaderState, agents: AgentData, dt: float) -> np.ndarray:
    """Return the control input of every agent of a swarm.

    :param law: the law.
    :param q: positions, shape ``(n, dim)``.
    :param p: velocities, shape ``(n, dim)``.
    :param edges: the interaction graph (all pairs with weights for ``law.all_pairs``).
    :param leader: the virtual leader's state.
    :param agents: per-agent data.
    :param dt: the step (used by laws that reach a target in one step).
    :return: ``u``, shape ``(n, dim)``.
    """
    return law.combine(q, p, pair_sums(law, q, p, edges), leader, agents, dt)


def group_control(law: Protocol, ids: np.ndarray, q: np.ndarray, p: np.ndarray,
                  edges: EdgeList, leader: LeaderState | None, group: AgentData,
                  dt: float) -> np.ndarray:
    """Return the control input of the agents ``ids`` only (agent nodes and containers).

    Only the edges that touch ``ids`` are evaluated, in the order :func:`swarm_control`
    sums them, so each row equals the corresponding row of :func:`swarm_control` on the
    whole graph: what an agent computes is what the simulator computes for it.

    :param law: the law.
    :param ids: the agents to control (ascending, distinct), shape ``(m,)``.
    :param q: positions of every agent, shape ``(n, dim)``.
    :param p: velocities of every agent, shape ``(n, dim)``.
    :param edges: the interaction graph of the whole swarm (as :func:`swarm_control`).
    :param leader: the virtual leader's state as these agents know it (``None``: lost, the
        uninformed law for all of them).
    :param group: per-agent data of ``ids`` (``agents.subset(ids)``).
    :param dt: the step.
    :return: ``u`` of ``ids``, shape ``(m, dim)``.
    """
    hosted = np.zeros(q.shape[0], dtype=bool)
    hosted[ids] = True
    touch = hosted[edges.i] | hosted[edges.j]
    near = dataclasses.replace(edges, i=edges.i[touch], j=edges.j[touch],
                               weight=edges.weight[touch])
    s = pair_sums(law, q, p, near)[ids]
    return law.combine(q[ids], p[ids], s, leader, group, dt)


def local_control(law: Protocol, q_self: np.ndarray, p_self: np.ndarray,
                  q_nb: np.ndarray, p_nb: np.ndarray, w_nb: np.ndarray,
                  leader: LeaderState, agent: AgentData, dt: float) -> np.ndarray:
    """Return the control input of one agent from its neighbours' states.

    The agent node's entry point: the same ``pair`` and ``combine`` as :func:`swarm_control`.

    :param law: the law.
    :param q_self: own position, shape ``(dim,)``.
    :param p_self: own velocity, shape ``(dim,)``.
    :param q_nb: neighbour positions, shape ``(m, dim)`` (``m`` may be 0).
    :param p_nb: neighbour velocities, shape ``(m, dim)``.
    :param w_nb: edge weights, shape ``(m,)``.
    :param leader: the virtual leader's state as this agent knows it.
    :param agent: this agent's data (arrays of length 1).
    :param dt: the step.
    :return: ``u``, shape ``(dim,)``.
    """
    m = q_nb.shape[0]
    qi = np.broadcast_to(q_self, (m, q_self.shape[0]))
    pi = np.broadcast_to(p_self, (m, p_self.shape[0]))
    s = law.pair(qi, pi, q_nb, p_nb, w_nb).sum(axis=0, keepdims=True)
    return law.combine(q_self[None], p_self[None], s, leader, agent, dt)[0]


def advance_adaptive(law: Protocol, q: np.ndarray, p: np.ndarray, leader: LeaderState | None,
                     agents: AgentData, dt: float) -> None:
    """Advance adaptive gains in place by one explicit step (sampled like ``u``).

    ``h_i(t + dt) = h_i(t) + dt k_i ||v_i(t) - v_l(t)||^2`` ([Zhou12] eq. (4)), consistent
    with the zero-order hold on the input.

    :param law: the law.
    :param q: positions at the start of the step.
    :param p: velocities at the start of the step.
    :param leader: the leader at the start of the step.
    :param agents: per-agent data, updated in place.
    :param dt: the step.
    """
    rate = law.adaptive_rate(q, p, leader, agents)
    if rate is not None and agents.adaptive is not None:
        agents.adaptive += dt * rate
