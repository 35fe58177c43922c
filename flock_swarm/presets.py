"""Presets (the scenario files of config/) and scenario files: lookup, YAML, ``--set``.

:func:`prepare` is the one preparation of a run for every front end (``sim``, ``sweep`` and
the reproduction call it): load, overrides, seed, validation, the law's output and the
step-size check, each failure one :class:`ScenarioError` line.
"""

import copy
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Iterable

import yaml

from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.laws.base import StepViolation
from flock_swarm.core.run import check_law_output, check_step
from flock_swarm.core.scenario import Realization, Scenario, parse_scenario, realize
from flock_swarm.scenario_yaml import apply_override, read_yaml_file

PACKAGE = 'flock_swarm'
#: Most steps of a run (``duration / dt``): beyond, a run would not end in a lifetime
#: (``duration=2147483000 dt=1e-9`` is 2e18 steps) and was accepted without a word.
MAX_STEPS = 100_000_000
#: Most interacting agent pairs at the start of a run: the law's work and memory of every
#: step grow with them (about 1.3 us a pair at the start check, measured at N = 10,000), so
#: ``n_agents=1000000`` in a box of 30 agents' size (5e10 pairs) hung without a word.
MAX_PAIRS = 10_000_000
#: Agents sampled to estimate the pairs of a larger swarm (every k-th agent).
PAIR_SAMPLE = 5000


def config_dirs() -> list[Path]:
    """Return the directories searched for presets, in order.

    The installed share directory (found through the ament index, as ``ros2 run`` users and
    ``colcon build`` installs have it), then the ``config/`` folder next to the package
    sources (a checkout or an editable install).
    """
    dirs = []
    try:
        from ament_index_python.packages import (PackageNotFoundError,
                                                 get_package_share_directory)
        try:
            dirs.append(Path(get_package_share_directory(PACKAGE)) / 'config')
        except (PackageNotFoundError, LookupError, ValueError, OSError):
            pass
    except ImportError:
        pass
    dirs.append(Path(__file__).resolve().parent.parent / 'config')
    seen, out = set(), []
    for d in dirs:
        if d.is_dir() and d.resolve() not in seen:
            seen.add(d.resolve())
            out.append(d)
    return out


def preset_names(folder: str = '') -> list[str]:
    """Return the names of the available presets (of sweep specs with ``folder='sweeps'``)."""
    names = set()
    for d in config_dirs():
        names.update(p.stem for p in (d / folder).glob('*.yaml')
                     if not p.stem.endswith('_params'))
    return sorted(names)


def resolve(name_or_path: str, folder: str = '', key: str = 'scenario') -> Path:
    """Return the file of a preset name or a path.

    :param name_or_path: ``su2009_fig2`` or ``path/to/file.yaml``.
    :param folder: the presets' folder under ``config/`` (``sweeps`` for sweep specs).
    :param key: the name errors give the argument.
    :return: an existing path.
    :raises ScenarioError: when nothing matches.
    """
    candidate = Path(name_or_path)
    if candidate.suffix in ('.yaml', '.yml') or os.sep in name_or_path:
        if candidate.is_dir():
            raise ScenarioError(key, f'{name_or_path} is a directory, not a YAML file')
        if not candidate.exists():
            raise ScenarioError(key, f'no such file: {name_or_path}')
        # A device or a pipe (/dev/null, a shell's <(...)) is read as it is: what it holds
        # is judged as a file's content would be (/dev/null: an empty file).
        return candidate
    for d in config_dirs():
        path = d / folder / f'{name_or_path}.yaml'
        if path.is_file():
            return path
    kind = f'{folder} preset' if folder else 'preset'
    raise ScenarioError(key, f'unknown {kind} {name_or_path!r} '
                        f'(presets: {", ".join(preset_names(folder)) or "none found"})')


def load_mapping(name_or_path: str) -> dict:
    """Read a scenario file into a mapping (no validation yet).

    :param name_or_path: preset name or path.
    :return: the mapping.
    :raises ScenarioError: for a file that cannot be read, is not UTF-8 text (a binary file,
        say), is not YAML, is empty, or holds no mapping.
    """
    path = resolve(name_or_path)
    data = read_yaml_file(path, 'scenario', 'a scenario')
    if data is None:
        raise ScenarioError('scenario', f'{path}: empty (no YAML document); a scenario is a '
                            'mapping of keys such as n_agents and protocol')
    if not isinstance(data, dict):
        raise ScenarioError('scenario', f'{path}: expected a mapping at the top level')
    data.setdefault('name', path.stem)
    return data


def load(name_or_path: str, overrides: Iterable[str] = (), seed: int | None = None,
         extra: dict[str, Any] | None = None) -> Scenario:
    """Read, override and validate a scenario.

    :param name_or_path: preset name or path.
    :param overrides: ``key=value`` assignments (dotted keys), applied in order.
    :param seed: replaces the scenario's seed when given.
    :param extra: further ``{dotted.key: value}`` overrides (already parsed values).
    :return: the validated scenario.

    Validation only: a front end about to run the scenario calls :func:`prepare`, which
    adds the law-output and step-size checks.
    """
    return parse_scenario(_resolved(load_mapping(name_or_path), overrides, seed, extra))


def _resolved(data: dict, overrides: Iterable[str], seed: int | None,
              extra: Mapping[str, Any] | None) -> dict:
    """Return ``data`` with the ``--set`` overrides, then ``extra``, then the seed applied."""
    for assignment in overrides:
        data = apply_override(data, assignment)
    data = set_values(data, extra or {})
    if seed is not None:
        data['seed'] = seed
    return data


def set_values(data: dict, values: Mapping[str, Any]) -> dict:
    """Return ``data`` with ``{dotted.key: value}`` set in order, values already parsed.

    :param data: the scenario mapping (not modified).
    :param values: the values (a sweep's ``set`` or point, ROS parameters).
    :return: the new mapping.
    """
    for key, value in values.items():
        data = apply_override(data, f'{key}={yaml.safe_dump(value, default_flow_style=True)}')
    return data


class StepError(ScenarioError):
    """A ``dt`` that violates a stability bound (:func:`prepare`); key ``dt``.

    :ivar violations: every violated bound, the first one in the message.
    """

    def __init__(self, dt: float, violations: list[StepViolation]) -> None:
        """Create the error from the violated bounds (at least one).

        :param dt: the scenario's step.
        :param violations: the bounds it violates.
        """
        super().__init__('dt', violations[0].message(dt).split(': ', 1)[1])
        self.violations = violations


def reread(data: Mapping[str, Any]) -> Scenario:
    """Return the scenario of a mapping :func:`prepare` prepared before, read back: a run's
    resolved scenario file, a bag's recorded scenario, a planned sweep run.

    Validated (:func:`~flock_swarm.core.scenario.parse_scenario`), not checked again: its
    law-output and step-size checks passed, or ``--allow-unstable`` waived them, when it was
    prepared. Beside :func:`load` (values read, nothing run), the one named way around
    :func:`prepare` (docs/architecture.md, "Where each fact lives").

    :param data: the prepared scenario's mapping (``Scenario.raw``; not modified).
    """
    return parse_scenario(copy.deepcopy(dict(data)))


def prepare(scenario: str | os.PathLike | Mapping[str, Any], overrides: Iterable[str] = (),
            seed: int | None = None, *, extra: Mapping[str, Any] | None = None,
            allow_unstable: bool = False) -> tuple[Scenario, Realization]:
    """Load, override, validate and check a scenario: the preparation of every run.

    In order: read the scenario (a preset name, a file, or a mapping already read from
    YAML), apply the ``--set`` ``overrides``, then the ``extra`` values, then the ``seed``;
    validate every value (:func:`~flock_swarm.core.scenario.parse_scenario`); draw the
    realisation; evaluate the law once at the initial state
    (:func:`~flock_swarm.core.run.check_law_output`: a plugin that raises or returns
    unusable commands); check ``dt`` against the stability bounds
    (:func:`~flock_swarm.core.run.check_step`). ``sim`` prints the error as
    ``sim: error: <error>``; a node or another front end prints the same line after its own
    prefix, so every front end refuses the same ``dt`` with the same words.

    From a node: read the ``scenario`` parameter's file with :func:`load_mapping` (its
    values tell how to read a parameter given as text), turn the node's parameters that
    name scenario keys into ``{dotted.key: value}`` and pass both::

        base = load_mapping(node.get_parameter('scenario').value)
        sc, real = prepare(base, extra=scenario_overrides(node, own, base), seed=seed)

    :param scenario: preset name, path of a YAML file, or the scenario mapping (not
        modified: the overrides apply to a copy; a mapping without ``name`` is ``unnamed``).
    :param overrides: ``key=value`` assignments (dotted keys, YAML values), in order.
    :param seed: replaces the scenario's seed when given (a negative one is refused as the
        ``seed`` key).
    :param extra: further ``{dotted.key: value}`` overrides with values already parsed
        (ROS parameters, a sweep's point), applied after ``overrides``.
    :param allow_unstable: skip the step-size check (``--allow-unstable``).
    :return: the validated scenario (``scenario.raw``: the mapping as run, to write to a
        file) and its realisation.
    :raises ScenarioError: naming the first invalid key; :class:`StepError` (key ``dt``)
        for a ``dt`` beyond a stability bound; a
        :class:`~flock_swarm.core.registry.PluginError` for a law that fails at the initial
        state.
    """
    if isinstance(scenario, Mapping):
        data = copy.deepcopy(dict(scenario))
    else:
        data = load_mapping(os.fspath(scenario))
    sc = parse_scenario(_resolved(data, overrides, seed, extra))
    if sc.steps > MAX_STEPS:
        raise ScenarioError('duration', f'{sc.duration:g} s in steps of dt = {sc.dt:g} s is '
                            f'{sc.steps:.3g} steps: at most {MAX_STEPS:.0e} a run (a longer '
                            'dt or a shorter duration)')
    real = realize(sc)
    check_pairs(sc, real)
    check_law_output(sc, real)
    if not allow_unstable:
        violations = check_step(sc, real)
        if violations:
            raise StepError(sc.dt, violations)
    return sc, real


def initial_pairs(sc: Scenario, real: Realization) -> int:
    """Return the number of interacting agent pairs at the start (estimated above
    :data:`PAIR_SAMPLE` agents, from every k-th agent, scaled to the whole swarm).

    :param sc: the scenario.
    :param real: its realisation.
    :return: the pairs of the fixed graph, of an all-pairs law, or within the law's radius.
    """
    import numpy as np
    from scipy.spatial import cKDTree

    n = sc.n_agents
    if real.adjacency is not None:
        return int(np.count_nonzero(np.triu(real.adjacency, 1)))  # symmetric (checked)
    if sc.law.all_pairs:
        return n * (n - 1) // 2
    stride = -(-n // PAIR_SAMPLE)
    sample = real.q0[::stride]
    m = len(sample)
    tree = cKDTree(sample)
    within = (int(tree.count_neighbors(tree, sc.law.radius)) - m) // 2
    return within if stride == 1 else round(within * n * (n - 1) / (m * (m - 1)))


def check_pairs(sc: Scenario, real: Realization) -> None:
    """Refuse a swarm whose agents interact in more than :data:`MAX_PAIRS` pairs at the start.

    :param sc: the scenario.
    :param real: its realisation.
    :raises ScenarioError: naming ``n_agents``, with the estimated pairs.
    """
    n = sc.n_agents
    if n * (n - 1) // 2 <= MAX_PAIRS:
        return
    pairs = initial_pairs(sc, real)
    if pairs > MAX_PAIRS:
        raise ScenarioError('n_agents', f'{n} agents interact in about {pairs:.2g} pairs at '
                            f'the start (radius {sc.law.radius:g} m): at most {MAX_PAIRS:.0e} '
                            'a step; spread them out (initial.position_box) or take fewer')
