"""The registry of laws, leader models and plants: Python entry points, read once per process.

Laws are registered in the entry-point group ``flock_swarm.laws``, leader models in
``flock_swarm.leaders``, plant models in ``flock_swarm.plants``, by this package (setup.py)
and by any other installed package, in the same way: ``name = module:Class``. One registry,
one code path: the built-in laws are looked up exactly as a user's. docs/extending.md walks
through writing and registering one.

A plugin that cannot be imported, is not a subclass of the base class, lacks a method,
names itself differently from its entry point, or whose name another package registers too,
raises :class:`PluginError` (a :class:`~flock_swarm.core.errors.ScenarioError`, so every
command reports it as one line and exits with status 2), naming the entry point and the
reason -- when a run uses it, and only then: the other plugins and the built-in ones work
as ever, and :func:`status` (``sim --list``) shows it as broken with the reason.
"""

import dataclasses
import inspect
import re
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import metadata

from flock_swarm.core.errors import PluginError, ScenarioError
from flock_swarm.core.laws.base import Law, accepted
from flock_swarm.core.leaders.base import LeaderModel
from flock_swarm.core.plants.base import Plant

#: Entry-point group of the laws (``protocol.name``).
LAW_GROUP = 'flock_swarm.laws'
#: Entry-point group of the leader models (``leader.model``, ``intrinsic.model``).
LEADER_GROUP = 'flock_swarm.leaders'
#: Entry-point group of the plant models (``plant.model``).
PLANT_GROUP = 'flock_swarm.plants'

_BASES = {LAW_GROUP: Law, LEADER_GROUP: LeaderModel, PLANT_GROUP: Plant}
#: What a plugin class must define itself (not inherit from the base class).
_REQUIRED = {LAW_GROUP: ('radius', 'pair', 'combine'), LEADER_GROUP: ('acceleration',),
             PLANT_GROUP: ('state_names', 'command_names', 'initial_state', 'law_state',
                           'command', 'step')}
#: The scenario key naming a plugin of each group.
_KEYS = {LAW_GROUP: 'protocol.name', LEADER_GROUP: 'leader.model', PLANT_GROUP: 'plant.model'}
#: Law hooks that took the whole scenario before they took a
#: :class:`~flock_swarm.core.laws.base.LawSetup`: ``{hook: (old signature, what to read)}``.
_SETUP_HOOKS = {'agent_data': ('agent_data(self, sc, informed)',
                               'setup.informed, setup.observers, setup.n_agents, setup.dim'),
                'step_bounds': ('step_bounds(self, sc, real)',
                                'setup.dt, setup.adjacency, setup.informed, setup.dim')}


@dataclass(frozen=True)
class Entry:
    """One registered plugin: its name, where it points and which package registered it."""

    group: str
    name: str
    value: str
    package: str
    point: metadata.EntryPoint = field(repr=False, compare=False)
    #: Why the name cannot be used whichever package's entry runs (registered twice), or ``''``.
    conflict: str = field(default='', compare=False)

    @property
    def label(self) -> str:
        """Return ``group:name (module:Class)``, how errors name the entry point."""
        return f'{self.group}:{self.name} ({self.value})'


#: The distribution of the built-in plugins (normalised as :func:`_normal` does).
BUILTIN_PACKAGE = 'flock-swarm'


def _normal(package: str) -> str:
    """Return a distribution name normalised (PEP 503): ``flock_swarm`` -> ``flock-swarm``."""
    return re.sub(r'[-_.]+', '-', package).lower()


@lru_cache(maxsize=None)
def entries(group: str) -> dict[str, Entry]:
    """Return the registered plugins of a group by name.

    The same distribution found twice (an editable install and a colcon install side by
    side) counts once, the first on ``sys.path`` winning; two distributions registering one
    name make that name unusable (:attr:`Entry.conflict`), since which one runs would depend
    on the path order; the other names are not affected. A built-in name (this package's)
    stays the built-in's: another package's entry of that name is set aside
    (:func:`shadowed`), so the presets that use the built-in keep working.

    :param group: :data:`LAW_GROUP` or :data:`LEADER_GROUP`.
    :return: ``{name: Entry}`` in name order.
    """
    found, _SHADOWED[group] = _scan(group)
    return found


def shadowed(group: str) -> tuple[Entry, ...]:
    """Return the other packages' entries set aside because they reuse a built-in name.

    ``sim --list`` names each (its package and where it points), not the built-in.

    :param group: :data:`LAW_GROUP` or :data:`LEADER_GROUP`.
    """
    entries(group)
    return _SHADOWED[group]


#: :func:`shadowed` of each group, as the last :func:`entries` found them.
_SHADOWED: dict[str, tuple[Entry, ...]] = {}


def _scan(group: str) -> tuple[dict[str, Entry], tuple[Entry, ...]]:
    """Return :func:`entries` and :func:`shadowed` of a group."""
    found: dict[str, Entry] = {}
    aside: list[Entry] = []
    for ep in metadata.entry_points(group=group):
        dist = getattr(ep, 'dist', None)
        package = dist.metadata['Name'] if dist is not None else '?'
        entry = Entry(group, ep.name, ep.value, package, ep)
        old = found.get(ep.name)
        if old is not None and _normal(old.package) != _normal(package) and (
                BUILTIN_PACKAGE in (_normal(old.package), _normal(package))):
            builtin, other = (old, entry) if _normal(old.package) == BUILTIN_PACKAGE \
                else (entry, old)
            found[ep.name] = builtin
            aside.append(other)
            continue
        if old is not None and old.package != package and package not in old.conflict:
            found[ep.name] = dataclasses.replace(
                old, conflict=f'{entry.label}: the name {ep.name!r} is also registered by '
                f'package {old.package} ({old.value})')
        found.setdefault(ep.name, entry)
    return dict(sorted(found.items())), tuple(aside)


def _key(group: str) -> str:
    return _KEYS[group]


@lru_cache(maxsize=None)
def load(group: str, name: str) -> type:
    """Return the class registered as ``name`` in ``group``, imported and checked.

    :param group: :data:`LAW_GROUP` or :data:`LEADER_GROUP`.
    :param name: the entry-point name.
    :return: the class.
    :raises PluginError: when it is missing, cannot be imported or is not a valid plugin.
    """
    cls, problem = _loaded(group, name)
    if problem is not None:
        raise PluginError(_key(group), problem)
    return cls


@lru_cache(maxsize=None)
def _loaded(group: str, name: str) -> tuple[type | None, str | None]:
    """Return ``(class, None)``, or ``(None, why it cannot be used)``: imported once."""
    entry = entries(group).get(name)
    if entry is None:
        return None, f'no entry point {group}:{name}'
    if entry.conflict:
        return None, entry.conflict
    try:
        cls = entry.point.load()
    except Exception as exc:  # noqa: BLE001 - any failure of a plugin's import is reported
        return None, f'{entry.label}: cannot be imported: {type(exc).__name__}: {exc}'
    problem = _problem(group, name, cls)
    if problem:
        return None, f'{entry.label}: {problem}'
    if group == LAW_GROUP:
        # Which parameters combine and state_rate take is read here, once (not per step).
        for hook in ('combine', 'state_rate'):
            accepted(cls, hook)
    return cls, None


def status(group: str) -> dict[str, tuple[Entry, type | None, str | None]]:
    """Return every registered plugin of a group with its class or why it is broken.

    What ``sim --list`` shows: a broken plugin is listed with the reason, not raised.

    :param group: :data:`LAW_GROUP` or :data:`LEADER_GROUP`.
    :return: ``{name: (entry, class or None, problem or None)}`` in name order.
    """
    return {name: (entry, *_loaded(group, name)) for name, entry in entries(group).items()}


def usable(group: str) -> dict[str, type]:
    """Return the registered plugins of a group that load, by name (broken ones left out)."""
    return {name: cls for name, (_, cls, problem) in status(group).items() if problem is None}


def _problem(group: str, name: str, cls) -> str | None:
    base = _BASES[group]
    if not isinstance(cls, type) or not issubclass(cls, base):
        return f'is not a subclass of {base.__module__}.{base.__name__}'
    if not dataclasses.is_dataclass(cls) or not cls.__dataclass_params__.frozen:
        return 'is not a frozen dataclass (@dataclass(frozen=True))'
    for attr in _REQUIRED[group]:
        if getattr(cls, attr) is getattr(base, attr):
            return f'does not define {attr}'
    if cls.name != name:
        return f'names itself {cls.name!r}, not {name!r} (set name: ClassVar[str] = {name!r})'
    if group == LAW_GROUP:
        return _old_hook(cls)
    return None


def _old_hook(cls: type) -> str | None:
    """Return what to change in a law written for the hooks that took the scenario, if any.

    ``agent_data`` and ``step_bounds`` take one :class:`~flock_swarm.core.laws.base.LawSetup`;
    a law still defining them with two arguments (``sc, informed`` / ``sc, real``) is
    refused when it is loaded, with the change to make, rather than failing in the middle of
    a run with a ``TypeError``.
    """
    for hook, (old, reads) in _SETUP_HOOKS.items():
        method = getattr(cls, hook)
        if method is getattr(Law, hook):
            continue
        try:
            params = list(inspect.signature(method).parameters.values())[1:]
        except (TypeError, ValueError):
            continue
        if any(p.kind is p.VAR_POSITIONAL for p in params):
            continue
        required = [p for p in params if p.default is p.empty
                    and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        if len(required) != 1:
            return (f'{hook} must take one argument, setup (a flock_swarm.plugin.LawSetup: '
                    f'{reads}), not the scenario: change {old} to {hook}(self, setup) '
                    '(docs/extending.md)')
    return None


def describe(cls: type) -> str:
    """Return a plugin's citation, or the first line of its docstring."""
    doc = (cls.__doc__ or '').strip().splitlines()
    return cls.citation or (doc[0] if doc else '')


def names(group: str) -> list[str]:
    """Return the registered names of a group, sorted."""
    return list(entries(group))


def law_class(name: str) -> type[Law]:
    """Return the law registered as ``name`` (``protocol.name``)."""
    return _lookup(LAW_GROUP, name, 'protocol.name', 'protocol')


def leader_class(name: str, key: str = 'leader.model') -> type[LeaderModel]:
    """Return the leader model registered as ``name`` (``leader.model``)."""
    return _lookup(LEADER_GROUP, name, key, 'leader model')


def plant_class(name: str) -> type[Plant]:
    """Return the plant model registered as ``name`` (``plant.model``)."""
    return _lookup(PLANT_GROUP, name, 'plant.model', 'plant model')


def _lookup(group: str, name, key: str, what: str) -> type:
    known = names(group)
    if not isinstance(name, str) or name not in known:
        raise ScenarioError(key, f'unknown {what} {name!r} (expected one of: '
                            f'{", ".join(known) or "none registered: is flock_swarm installed?"})')
    return load(group, name)


def laws() -> dict[str, type[Law]]:
    """Return every registered law by name (each imported and checked)."""
    return {name: law_class(name) for name in names(LAW_GROUP)}


def leader_models() -> dict[str, type[LeaderModel]]:
    """Return every registered leader model by name (each imported and checked)."""
    return {name: leader_class(name) for name in names(LEADER_GROUP)}


def plants() -> dict[str, type[Plant]]:
    """Return every registered plant model by name (each imported and checked)."""
    return {name: plant_class(name) for name in names(PLANT_GROUP)}
