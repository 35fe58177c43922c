"""Scenario files: schema, validation, overrides, and the realisation of a run.

A scenario is a plain mapping (read from YAML by :mod:`flock_swarm.presets`) describing a
whole run. :func:`parse_scenario` validates every value and returns a frozen
:class:`Scenario`; the first invalid value raises :class:`ScenarioError` naming its dotted
key. :func:`realize` turns a scenario and its seed into initial states, the informed set and
the interaction graph, deterministically, so every node of a ROS run and the simulator agree.

Agent ids are 0-based everywhere (``agent_0`` is the papers' agent 1).
"""

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from flock_swarm.core import registry
from flock_swarm.core.checks import (choice, integer, mapping, matrix, number, only, positive,
                                     text, vector)
from flock_swarm.core.errors import PluginError, ScenarioError
from flock_swarm.core.graphs import barabasi_albert, complete_graph, disk_graph
from flock_swarm.core.headline import HEADLINE_KEYS, Headline, parse_headline
from flock_swarm.core.laws.base import AgentData, Law, LawContext, LawSetup, ObserverGroup
from flock_swarm.core.laws.evaluation import antisymmetry_problem
from flock_swarm.core.leaders.base import LeaderModel, parse_model
from flock_swarm.core.network_spec import NetworkSpec, parse_network
from flock_swarm.core.obstacles import ObstacleSpec, parse_obstacles
from flock_swarm.core.plants.spec import PlantSpec, parse_plant
from flock_swarm.core.pseudo_leaders import PseudoLeaderSelection, select_pseudo_leaders

TOP_KEYS = ('name', 'description', 'reference', 'dim', 'n_agents', 'dt', 'duration', 'seed',
            'record_every', 'protocol', 'graph', 'informed', 'observers', 'initial', 'leader',
            'intrinsic', 'metrics', 'network', 'obstacles', 'plant', 'transport')
#: How the ROS nodes move a step's messages (``transport``; ``sim`` ignores it): one topic per
#: agent (the default), or the whole swarm's state and each host's commands as one message
#: each (docs/ros.md, "Transports").
TRANSPORTS = ('per_agent', 'batched')
#: ``intrinsic.model`` values besides the registered autonomous leader models.
INTRINSIC_SPECIAL = ('none', 'same_as_leader')
GRAPH_TYPES = ('disk', 'fixed', 'barabasi_albert')
INFORMED_SELECT = ('all', 'random', 'first', 'highest_degree', 'ids', 'pseudo_leaders')

#: The most agents a scenario may have: ten times the largest swarm the simulator is
#: benchmarked on (bench/bench_sim.py); beyond it NumPy refuses the arrays or memory runs out.
MAX_AGENTS = 1_000_000
#: The shortest step [s]: the ROS nodes stamp step ``k`` with ``k dt`` in whole nanoseconds.
MIN_DT = 1e-9
#: The longest run [s]: the seconds of a ROS stamp (builtin_interfaces/Time.sec) are int32.
MAX_DURATION = 2 ** 31 - 1
#: The largest seed: the nodes take the seed as a ROS integer parameter, an int64 (NumPy's
#: generator takes any integer >= 0); one range for ``sim``, ``swarm``, the nodes and
#: ``sweep``, so that a seed ``sim`` accepts runs in ROS too.
MAX_SEED = 2 ** 63 - 1
#: What each ``informed.select`` reads besides itself (and ``reselect``): any other of
#: ``count``, ``fraction``, ``ids`` given with it would be ignored, so it is refused.
INFORMED_USES = {'all': (), 'random': ('count', 'fraction'), 'first': ('count', 'fraction'),
                 'highest_degree': ('count', 'fraction'), 'ids': ('ids',),
                 'pseudo_leaders': ()}


def _box(value: Any, key: str, dim: int) -> np.ndarray:
    # + 0.0 turns -0.0 into 0.0: NumPy's uniform(0.0, -0.0) raises 'high - low < 0'.
    box = matrix(value, key, dim, 2) + 0.0
    for k in range(dim):
        if box[k, 0] > box[k, 1]:
            raise ScenarioError(f'{key}[{k}]',
                                f'lower bound {box[k, 0]} > upper bound {box[k, 1]}')
    return box


# --------------------------------------------------------------------------------------------
# The parsed scenario


@dataclass(frozen=True)
class LeaderSpec:
    """The virtual leader: its model and initial state."""

    model: LeaderModel
    position: np.ndarray
    velocity: np.ndarray


@dataclass(frozen=True)
class InformedSpec:
    """How the informed agents (pseudo-leaders) are chosen."""

    select: str
    count: int | None = None
    fraction: float | None = None
    ids: tuple[int, ...] = ()
    reselect: bool = False


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (see ``docs/scenarios.md`` for every key)."""

    name: str
    description: str
    reference: str
    dim: int
    n_agents: int
    dt: float
    duration: float
    seed: int
    record_every: int
    law: Law
    graph_type: str
    graph: dict
    informed: InformedSpec
    observers: tuple[ObserverGroup, ...]
    position_box: np.ndarray | None
    velocity_box: np.ndarray | None
    positions: np.ndarray | None
    velocities: np.ndarray | None
    leader: LeaderSpec
    intrinsic: LeaderModel | None
    eta_tolerance: float
    collision_distance: float
    raw: dict
    headline: Headline = Headline()
    #: The ``network:`` section (``docs/network.md``); inactive when absent or all zero.
    network: NetworkSpec = NetworkSpec()
    #: The ``obstacles:`` section (``docs/obstacles.md``); inactive when absent.
    obstacles: ObstacleSpec = ObstacleSpec()
    #: The ``plant:`` section (``docs/plants.md``); the double integrator when absent.
    plant: PlantSpec = PlantSpec()
    #: The ROS transport (:data:`TRANSPORTS`).
    transport: str = TRANSPORTS[0]

    @property
    def steps(self) -> int:
        """Return the number of steps, ``round(duration / dt)``."""
        return int(round(self.duration / self.dt))


def parse_scenario(data: Any) -> Scenario:
    """Validate a scenario mapping and return the :class:`Scenario`.

    :param data: the mapping, as read from YAML.
    :return: the scenario.
    :raises ScenarioError: on the first invalid value.
    """
    data = mapping(data, '<scenario>')
    only(data, TOP_KEYS, '')
    for section in ('informed', 'initial'):
        if isinstance(data.get(section), dict) and None in data[section].values():
            # null removes a key (--set informed.count=null, after --set informed.select=all);
            # the scenario as run (``raw``) holds only the keys that count.
            data = {**data, section: {k: v for k, v in data[section].items() if v is not None}}
    for key in ('dim', 'n_agents', 'dt', 'duration', 'protocol', 'leader'):
        if key not in data:
            raise ScenarioError(key, 'missing required key')
    name = text(data.get('name'), 'name', 'unnamed')
    # The name is the default output directory (out/<name>, out/<name>_ros): one plain
    # path component, so a scenario file cannot send the outputs anywhere else.
    if name in ('', '.', '..') or any(c in name for c in '/\\\0'):
        raise ScenarioError('name', f'must be usable as a directory name (no /, \\ or NUL, '
                            f'not . or ..), got {name!r}')
    dim = integer(data['dim'], 'dim')
    if dim not in (2, 3):
        raise ScenarioError('dim', f'must be 2 or 3, got {dim}')
    n = integer(data['n_agents'], 'n_agents')
    # Two at least: the closest approach, collisions and graph components of summary.json are
    # pair metrics, and with one agent they have no finite value to write.
    if not 2 <= n <= MAX_AGENTS:
        raise ScenarioError('n_agents', f'must be in [2, {MAX_AGENTS}], got {n}')
    dt = positive(data['dt'], 'dt')
    if dt < MIN_DT:
        raise ScenarioError('dt', f'must be >= {MIN_DT:g} s (ROS stamps count whole '
                            f'nanoseconds), got {dt!r}')
    duration = positive(data['duration'], 'duration')
    if duration > MAX_DURATION:
        raise ScenarioError('duration', f'must be <= {MAX_DURATION} s (ROS stamps count '
                            f'seconds in 32 bits), got {duration!r}')
    if duration < dt:
        raise ScenarioError('duration', f'must be >= dt ({dt}), got {duration}')
    seed = integer(data.get('seed', 0), 'seed')
    if seed < 0:
        raise ScenarioError('seed', f'must be >= 0, got {seed}')
    if seed > MAX_SEED:
        raise ScenarioError('seed', f'must be <= 2**63 - 1 (a ROS int64 parameter), got {seed}')
    record_every = integer(data.get('record_every', 1), 'record_every')
    if record_every < 1:
        raise ScenarioError('record_every', f'must be >= 1, got {record_every}')

    protocol = mapping(data['protocol'], 'protocol')
    graph_type, graph = _parse_graph(mapping(data.get('graph'), 'graph'), n)
    leader_raw = data['leader'].get('model') if isinstance(data['leader'], dict) else None
    law = _parse_law(protocol, LawContext(dim, n, graph_type,
                                          leader_raw if isinstance(leader_raw, str) else None))
    if graph_type not in law.graph_types:
        raise ScenarioError('graph.type', f'{law.name} supports only the '
                            f'{" or ".join(law.graph_types)} graph')
    informed = _parse_informed(mapping(data.get('informed'), 'informed'), n, law)
    observers = _parse_observers(data.get('observers'), n, dim, law)
    init = mapping(data.get('initial'), 'initial')
    only(init, ('position_box', 'velocity_box', 'positions', 'velocities'), 'initial.')
    positions = (matrix(init['positions'], 'initial.positions', n, dim)
                 if 'positions' in init else None)
    velocities = (matrix(init['velocities'], 'initial.velocities', n, dim)
                  if 'velocities' in init else None)
    position_box = _box(init['position_box'], 'initial.position_box', dim) \
        if 'position_box' in init else None
    velocity_box = _box(init['velocity_box'], 'initial.velocity_box', dim) \
        if 'velocity_box' in init else None
    for given, box in (('positions', 'position_box'), ('velocities', 'velocity_box')):
        if given in init and box in init:
            raise ScenarioError(f'initial.{box}', f'given with initial.{given}, which replace '
                                'it: give one of them')
    if positions is None and position_box is None:
        raise ScenarioError('initial.position_box', 'missing (or give initial.positions)')
    if velocities is None and velocity_box is None:
        raise ScenarioError('initial.velocity_box', 'missing (or give initial.velocities)')
    leader = _parse_leader(mapping(data['leader'], 'leader'), dim)
    intrinsic = _parse_intrinsic(mapping(data.get('intrinsic'), 'intrinsic'), dim, leader)
    metrics = mapping(data.get('metrics'), 'metrics')
    only(metrics, ('eta_tolerance', 'collision_distance', *HEADLINE_KEYS), 'metrics.')
    eta_tol = positive(metrics.get('eta_tolerance', law.eta_tolerance), 'metrics.eta_tolerance')
    coll = positive(metrics.get('collision_distance', 0.1), 'metrics.collision_distance')
    network = parse_network(data.get('network'), dt)
    obstacles = parse_obstacles(data.get('obstacles'), dim, law)
    plant = parse_plant(data.get('plant'), dim, registry.plant_class)
    transport = data.get('transport', TRANSPORTS[0])
    if transport not in TRANSPORTS:
        raise ScenarioError('transport', f"must be 'per_agent' or 'batched', got {transport!r}")
    if intrinsic is not None and not plant.default:
        raise ScenarioError('plant.model', f'the {plant.model.name} plant has no intrinsic '
                            'dynamics: give intrinsic.model: none, or the double_integrator')
    return Scenario(name, text(data.get('description'), 'description', ''),
                    text(data.get('reference'), 'reference', ''),
                    dim, n, dt, duration, seed, record_every, law, graph_type, graph, informed,
                    observers, position_box, velocity_box, positions, velocities, leader,
                    intrinsic, eta_tol, coll, data, parse_headline(metrics), network, obstacles,
                    plant, transport)


def _parse_law(section: dict, ctx: LawContext) -> Law:
    if 'name' not in section:
        raise ScenarioError('protocol.name', 'missing (expected one of: '
                            f'{", ".join(registry.names(registry.LAW_GROUP))})')
    cls = registry.law_class(section['name'])
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    only(section, ('name', *fields), 'protocol.')
    for name, f in fields.items():
        if name not in section and f.default is dataclasses.MISSING \
                and f.default_factory is dataclasses.MISSING:
            raise ScenarioError(f'protocol.{name}', f'missing (protocol {cls.name} has no '
                                'default for it)')
    values = {}
    for key, value in section.items():
        if key == 'name':
            continue
        kind = _field_kind(fields[key].type)
        if kind == 'int':
            values[key] = integer(value, f'protocol.{key}')
        elif kind == 'str':
            values[key] = text(value, f'protocol.{key}', '')
        elif kind == 'tuple':
            values[key] = _numbers(value, f'protocol.{key}')
        else:
            values[key] = number(value, f'protocol.{key}')
    try:
        law = cls(**values)
    except Exception as exc:  # noqa: BLE001 - whatever a plugin's constructor raises
        raise PluginError('protocol.name', f'{cls.name}: cannot be built from the protocol '
                          f'section: {type(exc).__name__}: {exc}') from None
    law.validate(ctx)
    problem = antisymmetry_problem(law, ctx.dim)
    if problem is not None:
        raise PluginError('protocol.name', problem)
    return law


def _field_kind(annotation: Any) -> str:
    """Return ``int``, ``str``, ``tuple`` or ``float``: how a law field is read from YAML.

    :param annotation: the field's annotation (a type, or its text under
        ``from __future__ import annotations``).
    """
    name = annotation if isinstance(annotation, str) else getattr(annotation, '__name__', '')
    name = name.split('[', 1)[0].strip().lower()
    return name if name in ('int', 'str', 'tuple') else 'float'


def _numbers(value: Any, key: str) -> tuple:
    """Return a law's vector field (a YAML list of numbers, or of such lists) as tuples.

    Tuples keep the law a hashable frozen dataclass (sweeps and stacks compare laws).
    """
    if not isinstance(value, (list, tuple)) or not value:
        raise ScenarioError(key, f'expected a non-empty list of numbers, got {value!r}')
    if isinstance(value[0], (list, tuple)):
        rows = tuple(_numbers(row, f'{key}[{k}]') for k, row in enumerate(value))
        if len({len(row) for row in rows}) > 1:
            raise ScenarioError(key, 'expected rows of one length, got lengths '
                                f'{[len(row) for row in rows]}')
        return rows
    return tuple(number(v, f'{key}[{k}]') for k, v in enumerate(value))


def _parse_graph(section: dict, n: int) -> tuple[str, dict]:
    kind = choice(section.get('type', 'disk'), 'graph.type', GRAPH_TYPES)
    if kind == 'disk':
        only(section, ('type',), 'graph.')
        return kind, {}
    if kind == 'fixed':
        only(section, ('type', 'adjacency'), 'graph.')
        if 'adjacency' not in section:
            raise ScenarioError('graph.adjacency', 'missing (required for a fixed graph)')
        adj = matrix(section['adjacency'], 'graph.adjacency', n, n)
        if not np.allclose(adj, adj.T):
            raise ScenarioError('graph.adjacency', 'must be symmetric')
        off = adj - np.diag(np.diag(adj))
        if (off < 0).any():
            raise ScenarioError('graph.adjacency', 'off-diagonal weights must be >= 0')
        return kind, {'adjacency': off}
    only(section, ('type', 'm0', 'm'), 'graph.')
    m0 = integer(section.get('m0', 5), 'graph.m0')
    m = integer(section.get('m', 5), 'graph.m')
    if not 1 <= m0 <= n:
        raise ScenarioError('graph.m0', f'must be in [1, n_agents = {n}], got {m0}')
    if not 1 <= m <= m0:
        raise ScenarioError('graph.m', f'must be in [1, m0 = {m0}], got {m}')
    return kind, {'m0': m0, 'm': m}


def _parse_informed(section: dict, n: int, law: Law) -> InformedSpec:
    only(section, ('select', 'count', 'fraction', 'ids', 'reselect'), 'informed.')
    select = choice(section.get('select', 'all'), 'informed.select', INFORMED_SELECT)
    for key in ('count', 'fraction', 'ids'):
        # A value the selection would ignore: the run would not be what the file says.
        if key in section and key not in INFORMED_USES[select]:
            raise ScenarioError(f'informed.{key}', f'not used by informed.select: {select} '
                                '(remove one of them; --set informed.KEY=null removes a key)')
    # Every value given is validated, also those the selection does not use: the scenario is
    # recorded as run (scenario.json, the bag's metadata), so it must hold only sound values.
    count = fraction = None
    ids: tuple[int, ...] = ()
    if 'count' in section:
        count = integer(section['count'], 'informed.count')
        if not 0 <= count <= n:
            raise ScenarioError('informed.count', f'must be in [0, {n}], got {count}')
    if 'fraction' in section:
        fraction = number(section['fraction'], 'informed.fraction')
        if not 0.0 <= fraction <= 1.0:
            raise ScenarioError('informed.fraction', f'must be in [0, 1], got {fraction}')
    if 'ids' in section or select == 'ids':
        raw = section.get('ids')
        if not isinstance(raw, (list, tuple)):
            raise ScenarioError('informed.ids', f'expected a list of agent ids, got {raw!r}')
        ids = tuple(integer(v, f'informed.ids[{k}]') for k, v in enumerate(raw))
        for k, v in enumerate(ids):
            if not 0 <= v < n:
                raise ScenarioError(f'informed.ids[{k}]', f'agent id must be in [0, {n - 1}], '
                                    f'got {v}')
        if len(set(ids)) != len(ids):
            raise ScenarioError('informed.ids', 'duplicate agent ids')
    if select in ('random', 'first', 'highest_degree'):
        if (count is None) == (fraction is None):
            raise ScenarioError('informed.count', f'give exactly one of count or fraction '
                                f'for select: {select}')
    else:
        count = fraction = None
    if select != 'ids':
        ids = ()
    if select == 'pseudo_leaders' and law.pseudo_leader_gains() is None:
        raise ScenarioError('informed.select', f'pseudo_leaders needs a law with the gains '
                            f'(w, alpha) of Zhou et al. Theorem 1; {law.name} has none')
    reselect = section.get('reselect', False)
    if not isinstance(reselect, bool):
        raise ScenarioError('informed.reselect', f'expected true or false, got {reselect!r}')
    if reselect and select != 'pseudo_leaders':
        raise ScenarioError('informed.reselect', 'only with select: pseudo_leaders')
    return InformedSpec(select, count, fraction, ids, reselect)


def _parse_observers(value: Any, n: int, dim: int, law: Law) -> tuple[ObserverGroup, ...]:
    if value is None:
        return ()
    if not law.uses_observers:
        raise ScenarioError('observers', f'not used by protocol {law.name} (only by laws '
                            'with pinned observers, such as yu_pinning_observer)')
    if not isinstance(value, list):
        raise ScenarioError('observers', 'expected a list of observer groups')
    groups = []
    seen: set[int] = set()
    for g, raw in enumerate(value):
        key = f'observers[{g}]'
        section = mapping(raw, key)
        only(section, ('ids', 'H', 'H_tilde', 'D', 'D_tilde'), key + '.')
        for name in ('ids', 'H', 'H_tilde', 'D', 'D_tilde'):
            if name not in section:
                raise ScenarioError(f'{key}.{name}', 'missing')
        ids_raw = section['ids']
        if not isinstance(ids_raw, list) or not ids_raw:
            raise ScenarioError(f'{key}.ids', 'expected a non-empty list of agent ids')
        ids = tuple(integer(v, f'{key}.ids[{k}]') for k, v in enumerate(ids_raw))
        for k, v in enumerate(ids):
            if not 0 <= v < n:
                raise ScenarioError(f'{key}.ids[{k}]', f'agent id must be in [0, {n - 1}]')
            if v in seen:
                raise ScenarioError(f'{key}.ids[{k}]', f'agent {v} is in two observer groups')
            seen.add(v)
        h = section['H']
        m = len(h) if isinstance(h, list) else 0
        if m < 1:
            raise ScenarioError(f'{key}.H', 'expected an m x dim matrix with m >= 1')
        mats = {'H': matrix(h, f'{key}.H', m, dim),
                'H_tilde': matrix(section['H_tilde'], f'{key}.H_tilde', m, dim),
                'D': matrix(section['D'], f'{key}.D', dim, m),
                'D_tilde': matrix(section['D_tilde'], f'{key}.D_tilde', dim, m)}
        groups.append(ObserverGroup(ids, mats['D'] @ mats['H'],
                                    mats['D_tilde'] @ mats['H_tilde']))
    return tuple(groups)


def _parse_leader(section: dict, dim: int) -> LeaderSpec:
    cls = registry.leader_class(section.get('model'))
    state = ('model', 'position', 'velocity') if cls.moving else ('model', 'position')
    model = parse_model(cls, section, dim, 'leader.', state)
    own = model.initial_state(dim)
    if own is not None:
        given = [key for key in state[1:] if key in section]
        if given:
            raise ScenarioError(f'leader.{given[0]}', f'set by the {model.name} model from its '
                                'parameters (its initial_state): remove it')
        position, velocity = _own_state(model, own, dim)
        return LeaderSpec(model, position, velocity if cls.moving else np.zeros(dim))
    if 'position' not in section:
        raise ScenarioError('leader.position', 'missing')
    position = vector(section['position'], 'leader.position', dim)
    if not cls.moving:
        return LeaderSpec(model, position, np.zeros(dim))
    if 'velocity' not in section:
        raise ScenarioError('leader.velocity', 'missing')
    return LeaderSpec(model, position, vector(section['velocity'], 'leader.velocity', dim))


def _own_state(model: LeaderModel, own: Any, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Return a leader model's own initial state, checked like the scenario's keys."""
    try:
        position, velocity = (np.asarray(v, dtype=float).ravel().tolist() for v in own)
    except (TypeError, ValueError):
        raise PluginError('leader.model', f'{model.name}: initial_state() must return '
                          f'(position, velocity), got {own!r}') from None
    return (vector(position, 'leader.position (initial_state)', dim),
            vector(velocity, 'leader.velocity (initial_state)', dim))


def _parse_intrinsic(section: dict, dim: int, leader: LeaderSpec) -> LeaderModel | None:
    """Return the agents' intrinsic dynamics ``f(p)``: ``None`` for the plain double integrator."""
    raw = section.get('model', 'none')
    loaded = registry.usable(registry.LEADER_GROUP)
    if isinstance(raw, str) and raw in registry.names(registry.LEADER_GROUP) \
            and raw not in loaded:
        registry.leader_class(raw, 'intrinsic.model')  # a broken plugin: its own error
    autonomous = [name for name, cls in loaded.items() if cls.autonomous and not cls.still]
    name = choice(section.get('model', 'none'), 'intrinsic.model',
                  (*INTRINSIC_SPECIAL, *autonomous))
    if name == 'none':
        only(section, ('model',), 'intrinsic.')
        return None
    if name == 'same_as_leader':
        only(section, ('model',), 'intrinsic.')
        if not leader.model.autonomous:
            raise ScenarioError('intrinsic.model', f'same_as_leader needs a leader model that '
                                f'depends on the velocity only; {leader.model.name} does not')
        return None if leader.model.still else leader.model
    return parse_model(registry.leader_class(name, 'intrinsic.model'), section, dim,
                       'intrinsic.', ('model',))


# --------------------------------------------------------------------------------------------
# Realisation


@dataclass
class Realization:
    """Everything a run starts from, derived deterministically from a scenario and its seed.

    :ivar q0: initial positions ``(n, dim)``.
    :ivar p0: initial velocities ``(n, dim)``.
    :ivar agents: per-agent law data (informed flags, gains, adaptive state).
    :ivar adjacency: the fixed weight matrix ``W`` (already scaled) or ``None`` (disk graph).
    :ivar selection: the pseudo-leader certificate when chosen by Theorem 1.
    :ivar setup: what the law sees of the run (:meth:`Law.agent_data`,
        :meth:`Law.step_bounds`).
    """

    q0: np.ndarray
    p0: np.ndarray
    agents: AgentData
    adjacency: np.ndarray | None
    selection: PseudoLeaderSelection | None
    setup: LawSetup

    @property
    def informed_ids(self) -> list[int]:
        """Return the ids of the informed agents."""
        return [int(k) for k in np.flatnonzero(self.agents.informed)]


def realize(sc: Scenario) -> Realization:
    """Draw the initial state, graph and informed set of a scenario from its seed.

    The generator ``numpy.random.default_rng(seed)`` is used in a fixed order: positions,
    velocities, graph, informed set.

    :param sc: the scenario.
    :return: the realisation.
    """
    rng = np.random.default_rng(sc.seed)
    n, dim = sc.n_agents, sc.dim
    q0 = sc.positions.copy() if sc.positions is not None else rng.uniform(
        sc.position_box[:, 0], sc.position_box[:, 1], size=(n, dim))
    p0 = sc.velocities.copy() if sc.velocities is not None else rng.uniform(
        sc.velocity_box[:, 0], sc.velocity_box[:, 1], size=(n, dim))
    unit_adj = None
    if sc.graph_type == 'fixed':
        unit_adj = sc.graph['adjacency']
    elif sc.graph_type == 'barabasi_albert':
        unit_adj = barabasi_albert(n, sc.graph['m0'], sc.graph['m'], rng)
    informed = np.zeros(n, dtype=bool)
    selection = None
    spec = sc.informed
    if spec.select == 'all':
        informed[:] = True
    elif spec.select in ('random', 'first', 'highest_degree'):
        count = spec.count if spec.count is not None else int(round(spec.fraction * n))
        if spec.select == 'random':
            chosen = rng.choice(n, size=count, replace=False)
        elif spec.select == 'first':
            chosen = np.arange(count)
        else:
            chosen = highest_degree(unit_adj if unit_adj is not None
                                    else _disk_adjacency(q0, sc.law), count)
        informed[chosen] = True
    elif spec.select == 'ids':
        informed[list(spec.ids)] = True
    else:
        adj = unit_adj if unit_adj is not None else _disk_adjacency(q0, sc.law)
        selection = select_pseudo_leaders(adj, *sc.law.pseudo_leader_gains())
        informed[list(selection.ids)] = True
    for group in sc.observers:
        informed[list(group.ids)] = True
    setup = law_setup(sc, informed, unit_adj)
    agents = AgentData(informed, sc.law.agent_data(setup), sc.law.initial_state(n))
    weights = None
    if unit_adj is not None:
        weights = unit_adj * sc.law.coupling_weight
    return Realization(q0, p0, agents, weights, selection, setup)


def law_setup(sc: Scenario, informed: np.ndarray, adjacency: np.ndarray | None) -> LawSetup:
    """Return what the scenario's law sees of a realised run (:class:`LawSetup`).

    :param sc: the scenario.
    :param informed: the informed agents at ``t = 0``.
    :param adjacency: the graph's weights before the law's coupling weight, or ``None``.
    :return: the setup, with read-only copies of the arrays.
    """
    def frozen(a: np.ndarray | None) -> np.ndarray | None:
        if a is None:
            return None
        out = np.array(a, copy=True)
        out.flags.writeable = False
        return out
    return LawSetup(dim=sc.dim, n_agents=sc.n_agents, graph_type=sc.graph_type,
                    leader_model=sc.leader.model.name, dt=sc.dt, adjacency=frozen(adjacency),
                    informed=frozen(informed), observers=sc.observers)


def highest_degree(adjacency: np.ndarray, count: int) -> np.ndarray:
    """Return the ``count`` agents of highest degree, ties to the lower id ([Zhou12] 5.2).

    Section 5.2 of Zhou et al. 2012 pins "the 6 nodes with the largest degrees" of its
    Barabasi-Albert graph.

    :param adjacency: the unit adjacency matrix (weights > 0 are edges).
    :param count: how many.
    :return: their ids, highest degree first.
    """
    degree = (adjacency > 0).sum(axis=1)
    return np.argsort(-degree, kind='stable')[:count]


def _disk_adjacency(q: np.ndarray, law: Law) -> np.ndarray:
    edges = disk_graph(q, law.radius, law.strict_radius)
    adj = np.zeros((q.shape[0], q.shape[0]))
    adj[edges.i, edges.j] = adj[edges.j, edges.i] = 1.0
    return adj


def all_pairs_weights(n: int, weights: np.ndarray | None, q: np.ndarray, law: Law):
    """Return the complete graph with coupling weights (for laws acting on all pairs).

    :param n: number of agents.
    :param weights: the fixed weight matrix, or ``None`` for the r-disk graph scaled by ``w``.
    :param q: positions (for the r-disk graph).
    :param law: the law.
    :return: the edge list.
    """
    full = complete_graph(n)
    mat = weights if weights is not None else law.coupling_weight * _disk_adjacency(q, law)
    return dataclasses.replace(full, weight=mat[full.i, full.j])
