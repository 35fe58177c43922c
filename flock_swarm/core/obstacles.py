"""Obstacles: the beta-agents of Olfati-Saber 2006 (Section VII, Algorithm 3), and their metrics.

R. Olfati-Saber, "Flocking for Multi-Agent Dynamic Systems: Algorithms and Theory", IEEE TAC
51(3), 2006, pp. 401-420 (technical report CIT-CDS 2004-005) ([OS06]). An obstacle is a
sphere (a ball of centre ``y_k`` and radius ``R_k``; a disc in 2-D) or a wall (the
half-space behind a hyperplane through ``y_k`` with unit normal ``a_k`` pointing to the free
space; a line in 2-D). For an agent (alpha-agent) ``i`` at ``(q_i, p_i)`` and obstacle ``k``
the beta-agent ``(qh_ik, ph_ik)`` is the agent's projection on the obstacle's boundary
([OS06] Section VII-A); the beta term of Algorithm 3 ([OS06] Section VII-B) repels the agent
from every beta-agent closer than the obstacle sensing range ``r'`` and damps its velocity
relative to it:

``u_i^beta = c1_beta sum_k phi_beta(||qh_ik - q_i||_s) n_ik + c2_beta sum_k b_ik (ph_ik - p_i)``

with ``n_ik = sigma_eps(qh_ik - q_i)``, ``phi_beta(z) = rho_h(z / d_beta) (sigma_1(z - d_beta)
- 1)``, ``b_ik = rho_h(||qh_ik - q_i||_s / d_beta)`` and ``d_beta = ||d'||_s``. The term is a
function of one agent's own state and the obstacle map: :func:`beta_term` gives the same row
for an agent whether it is evaluated alone (an agent node), with the agents of a container,
or with the whole swarm (``sim``), so a lockstep ROS run equals ``sim`` bit for bit.

The scenario's ``obstacles:`` section (:func:`parse_obstacles`, ``docs/obstacles.md``) gives
an :class:`ObstacleSpec`; without it (or with no sphere and no wall) the spec is inactive and
a run is what it was before obstacles existed.
"""

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from flock_swarm.core import potentials as pot
from flock_swarm.core.checks import mapping, number, only, positive, vector
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.laws.base import StepViolation
from flock_swarm.core.stability import pd_dt_max

OBSTACLE_KEYS = ('spheres', 'walls', 'd_beta', 'r_beta', 'c1_beta', 'c2_beta', 'h', 'eps')
#: [OS06] Section VIII: the desired distance to obstacles ``d' = 0.6 d`` (``d`` the law's
#: desired inter-agent distance) and the obstacle sensing range ``r' = 1.2 d'``.
D_BETA_OF_D = 0.6
R_BETA_OF_D_BETA = 1.2
#: [OS06]'s bump plateau of ``phi_beta`` and ``b_ik`` and its sigma-norm parameter.
H_BETA = 0.9
EPS_BETA = 0.1
#: The default position gain of the beta term (``docs/obstacles.md``: our choice, above the
#: built-in laws' navigation gains as [OS06]'s ordering of the gains wants it); the velocity
#: gain defaults to ``2 sqrt(c1_beta)``, the usual tuning of [OS06]'s gain pairs.
C1_BETA = 10.0
#: A unit normal's length may differ from 1 by this much (YAML decimals such as 0.7071).
UNIT_TOLERANCE = 1e-3
#: The most obstacles of one kind: the map travels in every message of the obstacles topic
#: and is evaluated for every agent at every step.
MAX_OBSTACLES = 10_000


@dataclass(frozen=True)
class ObstacleSpec:
    """The obstacle map and the beta term's parameters (the ``obstacles:`` section).

    Tuples, not arrays: the spec is compared and hashed like a law (stacked sweeps).

    :ivar spheres: ``((centre, radius), ...)``, each centre a tuple of ``dim`` numbers.
    :ivar walls: ``((point, unit normal), ...)``, the normal pointing to the free space.
    :ivar d_beta: the desired agent-obstacle distance ``d'`` [m] (Euclidean).
    :ivar r_beta: the obstacle sensing range ``r'`` [m] (Euclidean).
    :ivar c1_beta: the position gain of the beta term.
    :ivar c2_beta: its velocity gain.
    :ivar h: the bump plateau of ``phi_beta`` and ``b_ik``, in ``(0, 1)``.
    :ivar eps: the sigma-norm parameter of the beta term.
    """

    spheres: tuple = ()
    walls: tuple = ()
    d_beta: float = 0.0
    r_beta: float = 0.0
    c1_beta: float = C1_BETA
    c2_beta: float = 2.0 * np.sqrt(C1_BETA)
    h: float = H_BETA
    eps: float = EPS_BETA

    @property
    def active(self) -> bool:
        """Return whether there is any obstacle (otherwise a run is as without the section)."""
        return bool(self.spheres or self.walls)

    @property
    def count(self) -> int:
        """Return the number of obstacles: the spheres (ids ``0..S-1``), then the walls."""
        return len(self.spheres) + len(self.walls)

    @property
    def dim(self) -> int:
        """Return the space's dimension (0 without obstacles)."""
        first = self.spheres or self.walls
        return len(first[0][0]) if first else 0

    def _rows(self, rows: list) -> np.ndarray:
        """Return vectors as a ``(len(rows), dim)`` array (also when there are none of a kind,
        where a plain reshape cannot infer the width)."""
        return np.array(rows, dtype=float).reshape(len(rows), self.dim)

    @cached_property
    def centres(self) -> np.ndarray:
        """Return the spheres' centres ``y_k``, ``(S, dim)``."""
        return self._rows([c for c, _ in self.spheres])

    @cached_property
    def radii(self) -> np.ndarray:
        """Return the spheres' radii ``R_k``, ``(S,)``."""
        return np.array([r for _, r in self.spheres], dtype=float)

    @cached_property
    def points(self) -> np.ndarray:
        """Return a point ``y_k`` of each wall, ``(W, dim)``."""
        return self._rows([y for y, _ in self.walls])

    @cached_property
    def normals(self) -> np.ndarray:
        """Return the walls' unit normals ``a_k`` (normalised), ``(W, dim)``."""
        a = self._rows([n for _, n in self.walls])
        return a / np.sqrt(pot.squared_norm(a))[:, None] if a.size else a

    @cached_property
    def offsets(self) -> np.ndarray:
        """Return ``a_k . y_k`` of each wall, ``(W,)``: the signed distance is
        ``a_k . q - a_k . y_k``."""
        return _dot(self.points, self.normals) if self.walls else np.zeros(0)

    @cached_property
    def sensing_shell(self) -> tuple[np.ndarray, np.ndarray]:
        """Return ``((R + r')^2, (R - r')^2 or -1)`` per sphere: the squared distances from
        the centre between which the surface is within the sensing range."""
        inner = np.where(self.radii > self.r_beta, (self.radii - self.r_beta) ** 2, -1.0)
        return (self.radii + self.r_beta) ** 2, inner

    @cached_property
    def sigma_d_beta(self) -> float:
        """Return ``d_beta = ||d'||_sigma`` ([OS06] Section VII-B)."""
        return float(pot.sigma_of_distance(self.d_beta, self.eps))

    def as_dict(self) -> dict:
        """Return the map as plain lists (the obstacles topic, ``docs/obstacles.md``)."""
        return {'spheres': [{'centre': list(c), 'radius': r} for c, r in self.spheres],
                'walls': [{'point': list(y), 'normal': list(a)} for y, a in self.walls]}


def parse_obstacles(value: Any, dim: int, law: Any) -> ObstacleSpec:
    """Validate the scenario's ``obstacles:`` section.

    :param value: the section (``None``: absent).
    :param dim: the scenario's dimension.
    :param law: the scenario's law: it must accept obstacles (``Law.accepts_obstacles``);
        its field ``d``, when it has one, gives the default ``d_beta = 0.6 d``.
    :return: the spec (inactive when absent).
    :raises ScenarioError: naming the first invalid key.
    """
    if value is None:
        return ObstacleSpec()
    section = mapping(value, 'obstacles')
    if not getattr(law, 'accepts_obstacles', False):
        raise ScenarioError('obstacles', f'protocol {law.name} does not accept obstacles '
                            '(docs/obstacles.md lists the laws that do)')
    only(section, OBSTACLE_KEYS, 'obstacles.')
    spheres = tuple(_sphere(raw, f'obstacles.spheres[{k}]', dim)
                    for k, raw in enumerate(_list(section.get('spheres'), 'obstacles.spheres')))
    walls = tuple(_wall(raw, f'obstacles.walls[{k}]', dim)
                  for k, raw in enumerate(_list(section.get('walls'), 'obstacles.walls')))
    if 'd_beta' in section:
        d_beta = positive(section['d_beta'], 'obstacles.d_beta')
    else:
        d = getattr(law, 'd', None)
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not d > 0:
            raise ScenarioError('obstacles.d_beta', f'missing (protocol {law.name} has no '
                                'desired distance d to take 0.6 d from)')
        d_beta = D_BETA_OF_D * float(d)
    r_beta = positive(section.get('r_beta', R_BETA_OF_D_BETA * d_beta), 'obstacles.r_beta')
    c1 = positive(section.get('c1_beta', C1_BETA), 'obstacles.c1_beta')
    c2 = positive(section.get('c2_beta', 2.0 * np.sqrt(c1)), 'obstacles.c2_beta')
    h = number(section.get('h', H_BETA), 'obstacles.h')
    if not 0.0 < h < 1.0:
        raise ScenarioError('obstacles.h', f'must be in (0, 1), got {section["h"]!r}')
    eps = positive(section.get('eps', EPS_BETA), 'obstacles.eps')
    return ObstacleSpec(spheres, walls, d_beta, r_beta, c1, c2, h, eps)


def _list(value: Any, key: str) -> list:
    if value is None:
        return []
    if not isinstance(value, list):
        raise ScenarioError(key, f'expected a list, got {value!r}'[:200])
    if len(value) > MAX_OBSTACLES:
        raise ScenarioError(key, f'at most {MAX_OBSTACLES} entries, got {len(value)}')
    return value


def _entry(raw: Any, key: str, names: tuple[str, str]) -> dict:
    """Return one sphere's or wall's mapping, with exactly its two keys."""
    section = mapping(raw, key)
    only(section, names, key + '.')
    for name in names:
        if name not in section:
            raise ScenarioError(f'{key}.{name}', 'missing')
    return section


def _sphere(raw: Any, key: str, dim: int) -> tuple:
    section = _entry(raw, key, ('centre', 'radius'))
    centre = vector(section['centre'], f'{key}.centre', dim)
    return tuple(centre.tolist()), positive(section['radius'], f'{key}.radius')


def _wall(raw: Any, key: str, dim: int) -> tuple:
    section = _entry(raw, key, ('point', 'normal'))
    point = vector(section['point'], f'{key}.point', dim)
    normal = vector(section['normal'], f'{key}.normal', dim)
    length = float(np.sqrt(pot.squared_norm(normal)))
    if abs(length - 1.0) > UNIT_TOLERANCE:
        raise ScenarioError(f'{key}.normal', f'must be a unit vector, got length {length:.6g}')
    return tuple(point.tolist()), tuple(normal.tolist())


# --------------------------------------------------------------------------------------------
# Geometry


def _sphere_sq(spec: ObstacleSpec, q: np.ndarray) -> np.ndarray:
    """Return ``||q_i - y_k||^2`` for every sphere and agent, ``(S, m)``.

    Obstacle-major, one difference per component: each obstacle's row is contiguous over
    the agents (its reductions over the agents run on contiguous memory, several times
    faster than across an ``(m, S)`` array), and no ``(m, S, dim)`` temporary is made.
    Elementwise, so an agent's column is the same in any batch.
    """
    qt = q.T
    out = spec.centres[:, 0, None] - qt[0][None, :]
    out *= out
    for k in range(1, q.shape[1]):
        d = spec.centres[:, k, None] - qt[k][None, :]
        d *= d
        out += d
    return out


def _wall_signed(spec: ObstacleSpec, q: np.ndarray) -> np.ndarray:
    """Return the signed distances ``a_k . q_i - a_k . y_k`` to the walls, ``(W, m)``."""
    a, qt = spec.normals, q.T
    out = a[:, 0, None] * qt[0][None, :]
    for k in range(1, q.shape[1]):
        out += a[:, k, None] * qt[k][None, :]
    out -= spec.offsets[:, None]
    return out


@dataclass(frozen=True)
class Geometry:
    """Where the agents are relative to the obstacles at one instant: what the beta term
    (:func:`beta_pairs`) and the metrics (:meth:`ObstacleMetrics.update`) both read, computed
    once a step by the simulator (:func:`geometry`).

    :ivar sq: ``||q_i - y_k||^2`` to each sphere's centre, ``(S, m)``.
    :ivar signed: the signed distance to each wall, ``(W, m)``.
    :ivar ks: with ``i_s``, the (sphere, agent) pairs with a clearance below ``r'``
        (``sq < (R + r')^2``), obstacle-major (``np.nonzero``'s order); ``sq_in`` their
        ``sq``.
    :ivar kw: with ``iw``, the (wall, agent) pairs with a signed distance below ``r'``, in
        the same order; ``signed_in`` their signed distances.
    """

    sq: np.ndarray
    signed: np.ndarray
    ks: np.ndarray
    i_s: np.ndarray
    sq_in: np.ndarray
    kw: np.ndarray
    iw: np.ndarray
    signed_in: np.ndarray

    def part(self, lo: int, hi: int) -> 'Geometry':
        """Return the geometry of the agents ``lo .. hi - 1`` (one run of a stack)."""
        if lo == 0 and hi == self.sq.shape[1] == self.signed.shape[1]:
            return self
        s = (self.i_s >= lo) & (self.i_s < hi)
        w = (self.iw >= lo) & (self.iw < hi)
        return Geometry(self.sq[:, lo:hi], self.signed[:, lo:hi], self.ks[s], self.i_s[s] - lo,
                        self.sq_in[s], self.kw[w], self.iw[w] - lo, self.signed_in[w])


def geometry(spec: ObstacleSpec, q: np.ndarray) -> Geometry:
    """Return the :class:`Geometry` of the agents ``q``.

    The pairs within ``r'`` are found once, for the beta term's sensed pairs (a subset) and
    for the metrics (the closest pair and the close ones are among them, when any is within
    ``r'``): one comparison and one ``np.flatnonzero`` of each kind's whole array a step.
    """
    m = q.shape[0]
    none = np.zeros(0, dtype=np.intp)
    ks = i_s = kw = iw = none
    sq_in = signed_in = np.zeros(0)
    sq = signed = np.zeros((0, m))
    # np.flatnonzero and a divmod, not np.nonzero on the (count, m) mask: the same indices in
    # the same (row-major) order, at about a third of the cost.
    if spec.spheres:
        sq = _sphere_sq(spec, q)
        ks, i_s = np.divmod(np.flatnonzero(sq < spec.sensing_shell[0][:, None]), m)
        sq_in = sq[ks, i_s]
    if spec.walls:
        signed = _wall_signed(spec, q)
        kw, iw = np.divmod(np.flatnonzero(signed < spec.r_beta), m)
        signed_in = signed[kw, iw]
    return Geometry(sq, signed, ks, i_s, sq_in, kw, iw, signed_in)


def clearances(spec: ObstacleSpec, q: np.ndarray) -> np.ndarray:
    """Return each agent's signed distance to each obstacle's surface (``< 0``: inside).

    Spheres first, then walls: ``||q_i - y_k|| - R_k`` and ``a_k . (q_i - y_k)``.

    :param spec: the obstacles.
    :param q: positions, ``(m, dim)``.
    :return: ``(m, count)``.
    """
    out = np.empty((spec.count, q.shape[0]))
    n_s = len(spec.spheres)
    if spec.spheres:
        np.subtract(np.sqrt(_sphere_sq(spec, q)), spec.radii[:, None], out=out[:n_s])
    if spec.walls:
        out[n_s:] = _wall_signed(spec, q)
    return out.T


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Return ``u . v`` over the last axis, one component at a time, in order.

    Elementwise operations only (no BLAS, no reduction whose order depends on the array's
    length): an agent's value is the same in any batch, as lockstep ROS needs.
    """
    out = u[..., 0] * v[..., 0]
    for k in range(1, u.shape[-1]):
        out = out + u[..., k] * v[..., k]
    return out


def sphere_beta_agents(q: np.ndarray, p: np.ndarray, centre: np.ndarray,
                       radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the beta-agents ``(qh_ik, ph_ik)`` of agents on spheres ([OS06] Section VII-A).

    ``mu = R_k / ||q_i - y_k||``, ``a_k = (q_i - y_k) / ||q_i - y_k||``, ``P = I - a_k a_k^T``:
    ``qh_ik = mu q_i + (1 - mu) y_k`` (the closest point of the surface) and
    ``ph_ik = mu P p_i`` (the velocity's tangential part, scaled to the surface).

    :param q: agent positions, one per pair, ``(E, dim)``.
    :param p: agent velocities, ``(E, dim)``.
    :param centre: the spheres' centres, ``(E, dim)``.
    :param radius: their radii, ``(E,)``.
    :return: ``(qh, ph)``, each ``(E, dim)``.
    """
    # Broadcasting over the short last axis (not pot.rowwise): the pairs within range are
    # few, and for few rows the call overhead is what costs.
    diff = q - centre
    dist = np.sqrt(_dot(diff, diff))[:, None]
    mu = radius[:, None] / dist
    a = diff / dist
    qh = mu * q + (1.0 - mu) * centre
    return qh, mu * (p - a * _dot(a, p)[:, None])


def wall_beta_agents(q: np.ndarray, p: np.ndarray, point: np.ndarray,
                     normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the beta-agents ``(qh_ik, ph_ik)`` of agents on walls ([OS06] Section VII-A).

    ``P_k = I - a_k a_k^T``: ``qh_ik = P_k q_i + (I - P_k) y_k = q_i - a_k a_k^T (q_i - y_k)``
    (the foot of the perpendicular) and ``ph_ik = P_k p_i`` (the velocity along the wall).

    :param q: agent positions, one per pair, ``(E, dim)``.
    :param p: agent velocities, ``(E, dim)``.
    :param point: a point of each wall, ``(E, dim)``.
    :param normal: the walls' unit normals, ``(E, dim)``.
    :return: ``(qh, ph)``, each ``(E, dim)``.
    """
    qh = q - normal * _dot(normal, q - point)[:, None]
    ph = p - normal * _dot(normal, p)[:, None]
    return qh, ph


def phi_beta(z: np.ndarray, d_beta: float, h: float) -> np.ndarray:
    """Return the repulsive action ``phi_beta(z) = rho_h(z / d_beta) (sigma_1(z - d_beta) - 1)``.

    [OS06] Section VII-B: negative below ``d_beta`` (a push away from the obstacle) and zero
    from ``d_beta`` on.

    :param z: sigma-norm distances to beta-agents, any shape.
    :param d_beta: ``||d'||_sigma``.
    :param h: the bump plateau.
    :return: the actions.
    """
    return pot.bump(np.asarray(z, dtype=float) / d_beta, h) * (pot.sigma_1(z - d_beta) - 1.0)


def _near(spec: ObstacleSpec, geo: Geometry) -> tuple[tuple, tuple]:
    """Return ``((k, i) of the spheres, (k, i) of the walls)`` within the sensing range,
    each obstacle-major (by obstacle, then agent: each agent's obstacles in order).

    From the geometry's pairs below ``r'``: the spheres' with the inner bound (``sq >
    (R - r')^2``, which rarely excludes any), the walls' with ``signed > -r'`` (together
    ``|signed| < r'``: the same pairs in the same order as testing the whole array).
    """
    spheres = walls = (np.zeros(0, dtype=np.intp),) * 2
    if geo.ks.size:
        keep = geo.sq_in > spec.sensing_shell[1][geo.ks]
        spheres = (geo.ks[keep], geo.i_s[keep])
    if geo.kw.size:
        keep = geo.signed_in > -spec.r_beta
        walls = (geo.kw[keep], geo.iw[keep])
    return spheres, walls


def beta_pairs(spec: ObstacleSpec, q: np.ndarray,
               geo: Geometry | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return the (agent, obstacle) pairs within the sensing range, agent-major.

    An obstacle is a beta-neighbour of agent ``i`` when its beta-agent is closer than ``r'``
    (Euclidean; [OS06] Section VII-B), i.e. when ``|clearance| < r'``: for a sphere
    ``(R - r')^2 < ||q_i - y_k||^2 < (R + r')^2``, compared without a square root.

    :param spec: the obstacles.
    :param q: positions, ``(m, dim)``.
    :param geo: their :class:`Geometry` when the caller has it.
    :return: ``(agents, obstacles)``, index arrays sorted by agent then obstacle.
    """
    (ks, i_s), (kw, iw) = _near(spec, geometry(spec, q) if geo is None else geo)
    agent = np.concatenate([i_s, iw])
    obstacle = np.concatenate([ks, kw + len(spec.spheres)])
    order = np.lexsort((obstacle, agent))
    return agent[order], obstacle[order]


def beta_term(spec: ObstacleSpec, q: np.ndarray, p: np.ndarray,
              geo: Geometry | None = None) -> np.ndarray:
    """Return ``u_i^beta`` of [OS06] Algorithm 3 for each agent (zero without obstacles near).

    Vectorised over the (agent, obstacle) pairs within the sensing range
    (:func:`beta_pairs`); each agent's sum runs over its spheres, then its walls, each in
    the map's order, so a row depends only on that agent's state: the same whether the
    agent is evaluated alone, with others, or with the whole swarm.

    :param spec: the obstacles and the term's parameters.
    :param q: positions, ``(m, dim)``.
    :param p: velocities, ``(m, dim)``.
    :param geo: the agents' :class:`Geometry` when the caller has it.
    :return: ``(m, dim)``.
    """
    m, dim = q.shape
    out = np.zeros((m, dim))
    if not spec.active or m == 0:
        return out
    (ks, i_s), (kw, iw) = _near(spec, geometry(spec, q) if geo is None else geo)
    if not i_s.size and not iw.size:
        return out
    # Each kind's pairs, obstacle-major; concatenated, every agent's pairs keep their order.
    parts = []
    if i_s.size:
        qi, pi = q[i_s], p[i_s]
        qh, ph = sphere_beta_agents(qi, pi, spec.centres[ks], spec.radii[ks])
        parts.append((qh - qi, ph - pi))
    if iw.size:
        qi, pi = q[iw], p[iw]
        qh, ph = wall_beta_agents(qi, pi, spec.points[kw], spec.normals[kw])
        parts.append((qh - qi, ph - pi))
    if len(parts) == 1:
        (dq, dp), agent = parts[0], (i_s if i_s.size else iw)
    else:
        dq, dp = np.concatenate([parts[0][0], parts[1][0]]), np.concatenate([parts[0][1],
                                                                             parts[1][1]])
        agent = np.concatenate([i_s, iw])
    sq = _dot(dq, dq)
    root = np.sqrt(1.0 + spec.eps * sq)
    # ||qh - q||_sigma in the cancellation-free form (pot.sigma_of_distance), from ||dq||^2.
    z = sq / (root + 1.0)
    d_b = spec.sigma_d_beta
    # b_ik = rho_h(||qh_ik - q_i||_sigma / d_beta); phi_beta shares the bump.
    b = pot.bump(z / d_b, spec.h)
    action = b * (pot.sigma_1(z - d_b) - 1.0)
    # phi_beta n_ik = (phi_beta / sqrt(1 + eps ||dq||^2)) dq, n_ik = sigma_eps(qh_ik - q_i);
    # ph_ik - p_i the velocity relative to the beta-agent.
    term = dq * (spec.c1_beta * action / root)[:, None] + dp * (spec.c2_beta * b)[:, None]
    # add.at adds each agent's pairs in their order, from 0: the row depends on the agent's
    # own pairs only (one call for every component: bincount needs one a component).
    np.add.at(out, agent, term)
    return out


def step_bounds(spec: ObstacleSpec, dt: float) -> list[StepViolation]:
    """Return the violated explicit-step bound of the beta term (empty when ``dt`` is fine).

    Near a surface the term is a PD feedback on the agent's normal coordinate ``x``: the
    damping ``c2_beta b_ik`` with ``b_ik = 1`` on the bump's plateau, and a stiffness
    ``c1_beta (1 - sigma_1(-d_beta)) < 2 c1_beta`` (``phi_beta`` at the surface times the
    slope of ``n_ik``, ``1``); :func:`~flock_swarm.core.stability.pd_dt_max` of the
    bound ``(2 c1_beta, c2_beta)``.

    :param spec: the obstacles.
    :param dt: the scenario's step.
    :return: the violation, or nothing.
    """
    if not spec.active:
        return []
    bound = pd_dt_max(2.0 * spec.c1_beta, spec.c2_beta)
    if dt < bound:
        return []
    return [StepViolation('beta term of the obstacles', bound,
                          f'c1_beta = {spec.c1_beta:g}, c2_beta = {spec.c2_beta:g}')]


def inside(spec: ObstacleSpec, q: np.ndarray) -> tuple[int, int] | None:
    """Return the first ``(agent, obstacle)`` with the agent inside the obstacle, or ``None``."""
    if not spec.active:
        return None
    found = np.argwhere(clearances(spec, q) <= 0.0)
    return None if found.size == 0 else (int(found[0, 0]), int(found[0, 1]))


def check_start(spec: ObstacleSpec, q0: np.ndarray) -> None:
    """Refuse a run in which an agent starts inside (or on) an obstacle.

    :param spec: the obstacles.
    :param q0: the initial positions (drawn or given).
    :raises ScenarioError: naming the obstacle and the agent.
    """
    hit = inside(spec, q0)
    if hit is None:
        return
    agent, k = hit
    n_s = len(spec.spheres)
    key = f'obstacles.spheres[{k}]' if k < n_s else f'obstacles.walls[{k - n_s}]'
    where = ', '.join(f'{x:.6g}' for x in q0[agent])
    raise ScenarioError(key, f'agent {agent} starts inside it (at [{where}]): move the '
                        'obstacle or the initial positions')


# --------------------------------------------------------------------------------------------
# Metrics


class ObstacleMetrics:
    """Whole-run obstacle metrics, folded in step by step.

    :ivar clearance_min: the smallest agent-obstacle clearance over the run [m] (negative:
        an agent was inside an obstacle).
    :ivar penetrations: distinct ``(agent, obstacle)`` pairs with the agent ever inside.
    :ivar collisions: distinct pairs ever closer than the collision distance.
    """

    def __init__(self, spec: ObstacleSpec, collision_distance: float) -> None:
        """Create the metrics of a run with the obstacles ``spec``."""
        self.spec, self.collision_distance = spec, collision_distance
        # (R_k + collision distance)^2: the squared centre distances of a collision.
        self._shell = (spec.radii + collision_distance) ** 2
        self.clearance_min = float('inf')
        self.penetrations: set[tuple[int, int]] = set()
        self.collisions: set[tuple[int, int]] = set()
        # The keys (agent * count + obstacle) found at the previous instant: pairs mostly
        # stay close for many steps, and only the new ones go through the sets of tuples.
        self._close: set[int] = set()
        self._inside: set[int] = set()
        # The geometry's pairs within r' hold every close pair when the collision distance
        # is at most r', and the closest pair when some pair's clearance is below this
        # bound: r' less a margin far above the rounding of sq < (R + r')^2 (ObstacleMetrics
        # ._update_within).
        self._within = collision_distance <= spec.r_beta
        self._bound = spec.r_beta - 1e-9 * (spec.r_beta + float(spec.radii.max(initial=0.0)))

    def _fold(self, found: set, keys: np.ndarray, last: set[int]) -> set[int]:
        """Add the pairs of ``keys`` not in ``last`` to ``found``; return this instant's."""
        now = set(keys.tolist())
        count = self.spec.count
        found.update(divmod(key, count) for key in now - last)
        return now

    def update(self, q: np.ndarray, geo: Geometry | None = None) -> float:
        """Fold in one instant (``geo``: its :class:`Geometry`, when the caller has it);
        return its smallest clearance."""
        spec, cd = self.spec, self.collision_distance
        n_s = len(spec.spheres)
        geo = geometry(spec, q) if geo is None else geo
        if self._within:
            now = self._update_within(q, geo)
            if now is not None:
                return now
        lows = []
        sq = signed = None
        if spec.spheres and q.shape[0]:
            sq = geo.sq
            # sqrt is monotonic: the root of each sphere's least square is its least distance.
            lows.append((np.sqrt(sq.min(axis=1)) - spec.radii).min())
        if spec.walls and q.shape[0]:
            signed = geo.signed
            lows.append(signed.min())
        now = float(min(lows)) if lows else float('inf')
        self.clearance_min = min(self.clearance_min, now)
        if now < cd:
            keys, clear = [], []
            # flatnonzero and a divmod: np.nonzero's indices, in its order, cheaper (_near).
            if sq is not None:
                k, i = np.divmod(np.flatnonzero(sq < self._shell[:, None]),
                                 sq.shape[1])
                keys.append(i * spec.count + k)
                clear.append(np.sqrt(sq[k, i]) - spec.radii[k])
            if signed is not None:
                k, i = np.divmod(np.flatnonzero(signed < cd), signed.shape[1])
                keys.append(i * spec.count + (k + n_s))
                clear.append(signed[k, i])
            keys_all, clear_all = np.concatenate(keys), np.concatenate(clear)
            self._close = self._fold(self.collisions, keys_all[clear_all < cd], self._close)
            self._inside = self._fold(self.penetrations, keys_all[clear_all < 0.0],
                                      self._inside)
        else:
            self._close = self._inside = set()
        return now

    def _update_within(self, q: np.ndarray, geo: Geometry) -> float | None:
        """:meth:`update` from the geometry's pairs within ``r'`` only, bit for bit (``None``:
        they do not settle it, no pair being clearly within ``r'`` or an agent not finite).

        Every other pair has ``sq >= (R + r')^2`` (computed), so a clearance of at least
        ``r'`` less a few roundings of ``R + r'``, or ``signed >= r'``: when a pair within
        has a clearance below ``self._bound``, the smallest clearance is a pair's within,
        and ``min`` is exact (as are ``sqrt`` and the subtraction of ``R``, both monotonic
        and correctly rounded: the least ``sqrt(sq) - R`` is ``sqrt(min sq) - R``). The
        close pairs (``sq < (R + cd)^2``, ``signed < cd``, ``cd <= r'``) are all within.
        """
        spec, cd = self.spec, self.collision_distance
        lows = []
        clear_s = None
        if geo.ks.size:
            clear_s = np.sqrt(geo.sq_in) - spec.radii[geo.ks]
            lows.append(clear_s.min())
        if geo.kw.size:
            lows.append(geo.signed_in.min())
        # A NaN or infinite position is no pair's (sum: one pass; an overflow falls back too).
        if not lows or not min(lows) < self._bound or not np.isfinite(q.sum()):
            return None
        now = float(min(lows))
        self.clearance_min = min(self.clearance_min, now)
        if now < cd:
            count, keys, clear = spec.count, [], []
            if clear_s is not None:
                close = geo.sq_in < self._shell[geo.ks]
                keys.append(geo.i_s[close] * count + geo.ks[close])
                clear.append(clear_s[close])
            if geo.kw.size:
                close = geo.signed_in < cd
                keys.append(geo.iw[close] * count + (geo.kw[close] + len(spec.spheres)))
                clear.append(geo.signed_in[close])
            keys_all, clear_all = np.concatenate(keys), np.concatenate(clear)
            self._close = self._fold(self.collisions, keys_all[clear_all < cd], self._close)
            self._inside = self._fold(self.penetrations, keys_all[clear_all < 0.0],
                                      self._inside)
        else:
            self._close = self._inside = set()
        return now


def with_obstacles(spec: ObstacleSpec, u: np.ndarray, q: np.ndarray, p: np.ndarray,
                   geo: Geometry | None = None) -> np.ndarray:
    """Return a law's commands with the beta term added ([OS06] Algorithm 3).

    ``u_i = u_i^alpha + u_i^gamma`` (the law) ``+ u_i^beta``; without obstacles ``u`` itself,
    unchanged (a run without the section is bit for bit what it was).

    :param spec: the obstacles.
    :param u: the law's commands of the agents ``q``, ``(m, dim)``.
    :param q: their positions.
    :param p: their velocities.
    :param geo: their :class:`Geometry` when the caller has it.
    :return: the commands.
    """
    if not spec.active:
        return u
    return u + beta_term(spec, q, p, geo)
