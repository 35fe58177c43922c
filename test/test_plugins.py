"""Laws and leader models as plugins: registration through entry points, and broken plugins.

Each test registers its plugins as a real installed distribution (a ``*.dist-info``
directory with ``entry_points.txt`` on ``PYTHONPATH``, what ``pip install`` leaves behind)
and runs the real ``sim`` command in a subprocess, so the lookup goes through
``importlib.metadata`` exactly as for a user's package (examples/ tests a pip- and
colcon-installed one end to end).
"""

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from flock_swarm.core import registry

PLUGIN_MODULE = '''
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import (LeaderModel, Law, LawSetup, StepViolation, pd_dt_max,
                                require)


@dataclass(frozen=True)
class Damped(Law):
    """Velocity consensus with a linear pull towards the leader (a test law)."""

    name: ClassVar[str] = 'damped'
    r: float = 4.0
    k: float = 1.0

    @property
    def radius(self):
        return self.r

    def validate(self, ctx):
        require(self.k > 0, 'protocol.k', f'must be > 0, got {self.k}')

    def pair(self, qi, pi, qj, pj, w):
        return pj - pi

    def combine(self, q, p, s, leader, agents, dt):
        if leader is None:
            return s
        return s - self.k * (q - leader.q) - self.k * (p - leader.p)


@dataclass(frozen=True)
class DampedAvoiding(Damped):
    """Damped, taking obstacles (the beta term of Olfati-Saber 2006 is added to it)."""

    name: ClassVar[str] = 'damped_avoiding'
    accepts_obstacles: ClassVar[bool] = True
    d: float = 3.0


@dataclass(frozen=True)
class NoCombine(Law):
    name: ClassVar[str] = 'no_combine'
    r: float = 4.0

    @property
    def radius(self):
        return self.r

    def pair(self, qi, pi, qj, pj, w):
        return pj - pi


@dataclass(frozen=True)
class WrongShape(Damped):
    name: ClassVar[str] = 'wrong_shape'

    def combine(self, q, p, s, leader, agents, dt):
        return s[:, :1]


@dataclass(frozen=True)
class NotFinite(Damped):
    name: ClassVar[str] = 'not_finite'

    def combine(self, q, p, s, leader, agents, dt):
        return s * np.nan


@dataclass(frozen=True)
class Raises(Damped):
    name: ClassVar[str] = 'raises'

    def combine(self, q, p, s, leader, agents, dt):
        raise KeyError('gain')


@dataclass(frozen=True)
class Misnamed(Damped):
    name: ClassVar[str] = 'something_else'


@dataclass(frozen=True)
class Gained(Damped):
    """Damped, with a per-agent gain from the setup and a step bound (the LawSetup hooks)."""

    name: ClassVar[str] = 'gained'

    def agent_data(self, setup: LawSetup):
        # Informed agents pull twice as hard: read from the setup, not the scenario.
        return {'gain': np.where(setup.informed, 2.0 * self.k, self.k)}

    def combine(self, q, p, s, leader, agents, dt):
        if leader is None:
            return s
        return s - agents.data['gain'][:, None] * ((q - leader.q) + (p - leader.p))

    def step_bounds(self, setup: LawSetup):
        bound = pd_dt_max(2.0 * self.k, 2.0 * self.k)
        if setup.dt < bound:
            return []
        return [StepViolation('gained pull', bound, f'{setup.n_agents} agents')]


@dataclass(frozen=True)
class OldAgentData(Damped):
    """Written for the hooks that took the scenario (before LawSetup)."""

    name: ClassVar[str] = 'old_agent_data'

    def agent_data(self, sc, informed):
        return {'gain': np.full(sc.n_agents, self.k)}


@dataclass(frozen=True)
class OldStepBounds(Damped):
    name: ClassVar[str] = 'old_step_bounds'

    def step_bounds(self, sc, real):
        return []


class NotALaw:
    name = 'not_a_law'


@dataclass(frozen=True)
class MeanClaimed(Damped):
    """The neighbour-mean pattern (a count column) wrongly claiming antisymmetry."""

    name: ClassVar[str] = 'mean_claimed'
    antisymmetric: ClassVar[bool] = True

    def pair(self, qi, pi, qj, pj, w):
        return np.concatenate((pj - pi, np.ones((pj.shape[0], 1))), axis=1)

    def combine(self, q, p, s, leader, agents, dt):
        mean = s[:, :-1] / np.maximum(s[:, -1:], 1.0)
        return mean if leader is None else mean - self.k * (p - leader.p)


@dataclass(frozen=True)
class MeanDefault(MeanClaimed):
    """The neighbour-mean pattern keeping the default (antisymmetric = False)."""

    name: ClassVar[str] = 'mean_default'
    antisymmetric: ClassVar[bool] = False


@dataclass(frozen=True, kw_only=True)
class Required(Damped):
    """A law with a field without default (keyword-only: after the inherited defaults)."""

    name: ClassVar[str] = 'required'
    gain: float

    def combine(self, q, p, s, leader, agents, dt):
        return s if leader is None else s - self.gain * (p - leader.p)


@dataclass(frozen=True)
class Vectored(Damped):
    """Per-axis gains: a vector-valued field."""

    name: ClassVar[str] = 'vectored'
    gains: tuple[float, ...] = (1.0, 1.0)

    def combine(self, q, p, s, leader, agents, dt):
        return s if leader is None else s - np.asarray(self.gains) * (p - leader.p)


@dataclass(frozen=True)
class LateShape(Damped):
    """Right at first, a wrong shape from t = 1 s on (time-aware combine)."""

    name: ClassVar[str] = 'late_shape'

    def combine(self, q, p, s, leader, agents, dt, t):
        u = super().combine(q, p, s, leader, agents, dt)
        return u if t < 1.0 else u[:, :1]


@dataclass(frozen=True)
class Orbit(LeaderModel):
    """A leader on a circle of radius rho about centre, starting at its east point."""

    name: ClassVar[str] = 'orbit'
    autonomous: ClassVar[bool] = False
    omega: float = 0.5
    rho: float = 2.0
    centre: tuple = (3.0, 3.0)

    def initial_state(self, dim):
        return ([self.centre[0] + self.rho, self.centre[1]], [0.0, self.rho * self.omega])

    def acceleration(self, t, q, p):
        return -self.omega ** 2 * (q - np.asarray(self.centre))


@dataclass(frozen=True)
class Circle(LeaderModel):
    """A leader on a circle of radius v / omega (a test model, time-dependent)."""

    name: ClassVar[str] = 'circle'
    autonomous: ClassVar[bool] = False
    omega: float = 0.5

    def validate(self, dim, prefix):
        require(self.omega > 0, prefix + 'omega', f'must be > 0, got {self.omega}')

    def acceleration(self, t, q, p):
        # p(t) = (cos omega t, sin omega t) from p(0) = (1, 0): a function of time only.
        a = self.omega * np.array([-np.sin(self.omega * t), np.cos(self.omega * t)])
        return np.broadcast_to(a, p.shape).copy()
'''


def install_plugins(site, laws=(), leaders=(), package='flock-test-plugins',
                    module='fake_plugins', source=PLUGIN_MODULE):
    """Write a distribution registering ``laws`` and ``leaders`` (``name = Class``) in ``site``.

    ``source`` is the text of the module ``module`` that defines them.
    """
    site.mkdir(exist_ok=True)
    (site / f'{module}.py').write_text(source)
    info = site / f'{package.replace("-", "_")}-1.0.dist-info'
    info.mkdir()
    (info / 'METADATA').write_text(f'Metadata-Version: 2.1\nName: {package}\nVersion: 1.0\n')
    lines = ['[flock_swarm.laws]'] + [f'{n} = {module}:{c}' for n, c in laws if c]
    lines += ['[flock_swarm.leaders]'] + [f'{n} = {module}:{c}' for n, c in leaders]
    (info / 'entry_points.txt').write_text('\n'.join(lines) + '\n')


def scenario(tmp_path, protocol, leader=None):
    """Write a small 2-D scenario with the given protocol (and leader) sections; return it."""
    path = tmp_path / 'plugin.yaml'
    path.write_text(textwrap.dedent(f'''\
        name: plugin
        dim: 2
        n_agents: 12
        dt: 0.05
        duration: 2.0
        seed: 3
        protocol: {json.dumps(protocol)}
        informed: {{select: all}}
        initial: {{position_box: [[0, 6], [0, 6]], velocity_box: [[0, 1], [0, 1]]}}
        leader: {json.dumps(leader or {'model': 'constant_velocity', 'position': [3, 3],
                                       'velocity': [1, 0]})}
        '''))
    return path


def sim(site, *args, out=None):
    """Run the ``sim`` command with the plugins of ``site``; return the completed process."""
    env = dict(os.environ, PYTHONPATH=str(site))
    cmd = [sys.executable, '-m', 'flock_swarm.cli.sim', *map(str, args), '--quiet']
    if out is not None:
        cmd += ['--out', str(out)]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)


def assert_one_line_error(proc, *fragments):
    """The command failed with status 2 and exactly one stderr line holding ``fragments``."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert 'Traceback' not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_builtin_laws_and_models_are_registered_by_flock_swarm():
    laws = registry.entries(registry.LAW_GROUP)
    assert {'olfati_saber_2006', 'su_informed', 'su_accel', 'su_informed_accel', 'os2003_sink',
            'zhou_pseudo_leader', 'yu_pinning_observer', 'jadbabaie_leader'} <= set(laws)
    leaders = registry.entries(registry.LEADER_GROUP)
    assert {'constant_velocity', 'constant_acceleration', 'lorenz', 'lu', 'linear',
            'sink'} <= set(leaders)
    for entry in [*laws.values(), *leaders.values()]:
        if entry.value.startswith('flock_swarm.'):
            assert entry.package == 'flock_swarm'
            assert registry.load(entry.group, entry.name).name == entry.name


def test_a_plugin_law_and_leader_run_in_sim_and_are_listed(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped')], leaders=[('circle', 'Circle')])
    listing = sim(site, '--list')
    assert listing.returncode == 0, listing.stderr
    damped = [line for line in listing.stdout.splitlines() if line.split()[:1] == ['damped']]
    assert damped and '[flock-test-plugins]' in damped[0] and 'Velocity consensus' in damped[0]
    assert any(line.split()[:1] == ['circle'] for line in listing.stdout.splitlines())
    path = scenario(tmp_path, {'name': 'damped', 'k': 2.0},
                    {'model': 'circle', 'omega': 0.5, 'position': [3, 3], 'velocity': [1, 0]})
    proc = sim(site, path, out=tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['protocol'] == 'damped' and summary['status'] == 'completed'
    series = np.load(tmp_path / 'out' / 'timeseries.npz')
    # The circle leader keeps its speed: |p| = 1 all along (RK4, 40 steps of 0.05 s).
    np.testing.assert_allclose(np.linalg.norm(series['leader_p'], axis=1), 1.0, rtol=1e-6)


def test_a_plugin_law_opts_in_to_obstacles(tmp_path):
    """A law with ``accepts_obstacles = True`` flies with the scenario's obstacles (its field
    ``d`` gives d_beta = 0.6 d); one without is refused in one line."""
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped'), ('damped_avoiding', 'DampedAvoiding')])
    walls = {'walls': [{'point': [0, -1], 'normal': [0, 1]}]}
    path = scenario(tmp_path, {'name': 'damped_avoiding', 'k': 2.0})
    data = path.read_text() + f'obstacles: {json.dumps(walls)}\n'
    path.write_text(data)
    proc = sim(site, path, out=tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['obstacle_penetrations'] == 0
    # The wall is within r' = 1.2 * 0.6 * 3 m of the agents at the start: the term acted.
    assert 1.0 <= summary['obstacle_clearance_min'] < 2.16
    path.write_text(data.replace("damped_avoiding", "damped"))
    assert_one_line_error(sim(site, path), 'obstacles: protocol damped does not accept '
                          'obstacles')


@pytest.mark.parametrize('entry, fragments', [
    (('broken', 'missing_module:Law'), ('flock_swarm.laws:broken', 'cannot be imported',
                                        'ModuleNotFoundError')),
    (('no_combine', 'NoCombine'), ('flock_swarm.laws:no_combine', 'does not define combine')),
    (('not_a_law', 'NotALaw'), ('flock_swarm.laws:not_a_law', 'is not a subclass')),
    (('misnamed', 'Misnamed'), ('flock_swarm.laws:misnamed', "names itself 'something_else'")),
    (('wrong_shape', 'WrongShape'), ('flock_swarm.laws:wrong_shape', 'returned shape (12, 1)')),
    (('not_finite', 'NotFinite'), ('flock_swarm.laws:not_finite', 'non-finite')),
    (('raises', 'Raises'), ('flock_swarm.laws:raises', 'raised KeyError')),
])
def test_a_broken_plugin_law_is_one_line_naming_its_entry_point(tmp_path, entry, fragments):
    site = tmp_path / 'site'
    name, target = entry
    install_plugins(site, laws=[(name, target if ':' not in target else None)])
    if ':' in target:  # an entry point naming a module that does not exist
        ep = site / 'flock_test_plugins-1.0.dist-info' / 'entry_points.txt'
        ep.write_text(f'[flock_swarm.laws]\n{name} = {target}\n')
    proc = sim(site, scenario(tmp_path, {'name': name}), out=tmp_path / 'out')
    assert_one_line_error(proc, 'protocol.name', *fragments)
    assert not (tmp_path / 'out' / 'summary.json').exists()


def test_invalid_plugin_parameters_name_the_key(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped')], leaders=[('circle', 'Circle')])
    proc = sim(site, scenario(tmp_path, {'name': 'damped', 'k': -1.0}))
    assert_one_line_error(proc, 'protocol.k: must be > 0, got -1.0')
    proc = sim(site, scenario(tmp_path, {'name': 'damped', 'gain': 1.0}))
    assert_one_line_error(proc, 'protocol.gain: unknown key')
    proc = sim(site, scenario(tmp_path, {'name': 'damped'},
                              {'model': 'circle', 'omega': 0, 'position': [0, 0],
                               'velocity': [1, 0]}))
    assert_one_line_error(proc, 'leader.omega: must be > 0, got 0.0')


def test_a_time_dependent_leader_cannot_be_intrinsic_dynamics(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped')], leaders=[('circle', 'Circle')])
    path = scenario(tmp_path, {'name': 'damped'},
                    {'model': 'circle', 'position': [0, 0], 'velocity': [1, 0]})
    path.write_text(path.read_text() + 'intrinsic: {model: same_as_leader}\n')
    assert_one_line_error(sim(site, path), 'intrinsic.model: same_as_leader needs')
    path.write_text(path.read_text().replace('same_as_leader', 'circle'))
    assert_one_line_error(sim(site, path), 'intrinsic.model: unknown value')


def test_two_packages_registering_one_name_is_an_error(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped')])
    install_plugins(site, laws=[('damped', 'Damped')], package='other-plugins',
                    module='other_plugins')
    proc = sim(site, scenario(tmp_path, {'name': 'damped'}))
    assert_one_line_error(proc, 'flock_swarm.laws:damped', 'also registered by package')


def test_a_plugin_law_reads_its_setup_in_agent_data_and_step_bounds(tmp_path):
    """The LawSetup hooks: per-agent data from the informed set, a step bound from dt."""
    site = tmp_path / 'site'
    install_plugins(site, laws=[('gained', 'Gained'), ('damped', 'Damped')])
    protocol = {'name': 'gained', 'k': 2.0}
    path = scenario(tmp_path, protocol)
    path.write_text(path.read_text().replace('{select: all}', '{select: first, count: 4}'))
    proc = sim(site, path, '--set', 'record_every=1', out=tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    series = np.load(tmp_path / 'out' / 'timeseries.npz')
    # Alone with the leader at t = 0 (pair sums aside), an informed agent's pull is twice an
    # uninformed one's: u = s - gain ((q - q_l) + (p - p_l)) with the gains of agent_data.
    law_u = series['u'][0]
    q, p = series['q'][0], series['p'][0]
    lq, lp = series['leader_q'][0], series['leader_p'][0]
    damped = sim(site, path, '--set', 'protocol.name=damped', '--set', 'record_every=1',
                 out=tmp_path / 'damped')
    assert damped.returncode == 0, damped.stderr
    base_u = np.load(tmp_path / 'damped' / 'timeseries.npz')['u'][0]
    pull = (q - lq) + (p - lp)
    gain = np.where(np.arange(12) < 4, 4.0, 2.0)[:, None]
    # Damped pulls with k on each term: u_damped = s - k pull; so u_gained = u_damped
    # - (gain - k) pull.
    np.testing.assert_allclose(law_u, base_u - (gain - 2.0) * pull, rtol=0, atol=1e-12)
    # dt = 0.05 is within the bound 2 / (2 k) = 0.5; dt = 0.5 is not: the same one line as
    # for a built-in law.
    proc = sim(site, path, '--set', 'dt=0.5')
    assert_one_line_error(proc, 'dt: 0.5 exceeds the stability bound 0.5 of the gained pull '
                          '(12 agents); use dt < 0.5')
    # --allow-unstable runs it anyway (to its end or to divergence, but it runs).
    sim(site, path, '--set', 'dt=0.5', '--allow-unstable', out=tmp_path / 'unstable')
    assert json.loads((tmp_path / 'unstable' / 'summary.json').read_text())['dt'] == 0.5


@pytest.mark.parametrize('name, target, old', [
    ('old_agent_data', 'OldAgentData', 'agent_data(self, sc, informed)'),
    ('old_step_bounds', 'OldStepBounds', 'step_bounds(self, sc, real)'),
])
def test_a_law_written_for_the_scenario_hooks_gets_one_line_saying_what_to_change(
        tmp_path, name, target, old):
    site = tmp_path / 'site'
    install_plugins(site, laws=[(name, target)])
    proc = sim(site, scenario(tmp_path, {'name': name}), out=tmp_path / 'out')
    hook = old.split('(')[0]
    assert_one_line_error(proc, f'protocol.name: flock_swarm.laws:{name} ', 'LawSetup',
                          f'change {old} to {hook}(self, setup)', 'docs/extending.md')
    assert not (tmp_path / 'out' / 'summary.json').exists()
    # Listing the plugins names it the same way, as broken (issue 24: a broken plugin fails
    # only the runs that use it, so the listing itself succeeds).
    listing = sim(site, '--list')
    assert listing.returncode == 0, listing.stderr
    line = [ln for ln in listing.stdout.splitlines() if ln.split()[:1] == [name]][0]
    assert 'BROKEN' in line and f'flock_swarm.laws:{name}' in line and f'change {old}' in line


def test_the_plugin_facade_exports_every_type_its_hooks_mention():
    """Every class in the annotations of Law's and LeaderModel's hooks is in plugin.__all__."""
    import typing

    from flock_swarm import plugin
    exported = {getattr(plugin, name) for name in plugin.__all__}
    seen = set()
    for base in (plugin.Law, plugin.LeaderModel, plugin.LawSetup, plugin.AgentData):
        for attr in vars(base).values():
            func = attr.fget if isinstance(attr, property) else getattr(attr, '__func__', attr)
            if not callable(func):
                continue
            for hint in typing.get_type_hints(func).values():
                stack = [hint]
                while stack:
                    t = stack.pop()
                    stack.extend(typing.get_args(t))
                    if isinstance(t, type) and t.__module__.startswith('flock_swarm'):
                        seen.add(t)
    assert {plugin.LawContext, plugin.LawSetup, plugin.LeaderState, plugin.AgentData,
            plugin.StepViolation} <= seen
    assert seen <= exported, sorted(t.__name__ for t in seen - exported)
    for name in ('LawSetup', 'ObserverGroup', 'StepViolation'):
        assert typing.get_type_hints(getattr(plugin, name))  # each a typed dataclass
    # Nothing else public: what plugin.py imports it exports (pytest's rewriting adds '@' names).
    assert set(plugin.__all__) == {n for n in vars(plugin) if n[0].isalpha()}


def test_py_typed_ships_with_the_package():
    from importlib.resources import files
    assert files('flock_swarm').joinpath('py.typed').is_file()
    setup_py = (Path(__file__).resolve().parents[1] / 'setup.py').read_text()
    # The package's data (the engine's robot model beside it) lists py.typed.
    assert re.search(r"package_data=\{package_name: \[[^]]*'py\.typed'", setup_py)


#: What core/laws/base.py may import: leaves of the core (the laws' base builds on nothing else).
CORE_LEAF_IMPORTS = {'flock_swarm.core.graphs', 'flock_swarm.core.leaders.base',
                     'flock_swarm.core.checks', 'flock_swarm.core.errors'}


def test_the_law_base_module_imports_nothing_above_it():
    """core/laws/base.py imports (also under TYPE_CHECKING) only leaves of the core."""
    import flock_swarm.core.laws.base as base
    ours = {m for m in _imports(Path(base.__file__).read_text()) if m.startswith('flock_swarm')}
    assert ours <= CORE_LEAF_IMPORTS, ours - CORE_LEAF_IMPORTS
    assert 'TYPE_CHECKING' not in Path(base.__file__).read_text()
    # And the leaves themselves import no other flock_swarm module than errors/checks.
    for leaf in CORE_LEAF_IMPORTS:
        module = __import__(leaf, fromlist=['_'])
        text = Path(module.__file__).read_text()
        others = {m for m in _imports(text) if m.startswith('flock_swarm')}
        assert others <= {'flock_swarm.core.errors', 'flock_swarm.core.checks'}, (leaf, others)


def _imports(text: str) -> set[str]:
    import ast
    out = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_no_import_cycle_among_the_core_modules():
    """The graph of flock_swarm.core imports (type-only ones included) has no cycle."""
    import flock_swarm.core as core
    root = Path(core.__file__).resolve().parent
    modules = {}
    for path in root.rglob('*.py'):
        rel = path.relative_to(root.parent.parent).with_suffix('')
        name = '.'.join(rel.parts).removesuffix('.__init__')
        modules[name] = {m for m in _imports(path.read_text())
                         if m.startswith('flock_swarm.core')}
    state = {}

    def visit(name, trail):
        if state.get(name) == 'done':
            return
        assert state.get(name) != 'open', ' -> '.join(trail + [name])
        state[name] = 'open'
        for dep in sorted(modules.get(name, ())):
            if dep in modules and dep != name:
                visit(dep, trail + [name])
        state[name] = 'done'
    for name in sorted(modules):
        visit(name, [])


@pytest.mark.parametrize('module', ['flock_swarm.core.laws.base', 'flock_swarm.core.stability',
                                    'flock_swarm.core.registry', 'flock_swarm.core.scenario',
                                    'flock_swarm.core.run', 'flock_swarm.core.summary',
                                    'flock_swarm.plugin'])
def test_each_core_module_imports_alone_in_a_fresh_interpreter(module):
    proc = subprocess.run([sys.executable, '-c', f'import {module}'], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


# -- issue 24: a plugin API without traps -----------------------------------------------------


def test_a_false_antisymmetric_claim_is_one_line_when_the_law_is_loaded(tmp_path):
    """The neighbour-mean pattern claiming antisymmetry would be silently wrong: refused."""
    site = tmp_path / 'site'
    install_plugins(site, laws=[('mean_claimed', 'MeanClaimed'),
                                ('mean_default', 'MeanDefault')])
    proc = sim(site, scenario(tmp_path, {'name': 'mean_claimed'}), out=tmp_path / 'out')
    assert_one_line_error(proc, 'protocol.name: mean_claimed: declares antisymmetric = True',
                          'pair(i <- j) + pair(j <- i)', 'antisymmetric: ClassVar[bool] = False')
    assert not (tmp_path / 'out' / 'summary.json').exists()
    # Without the claim (the default), it runs.
    proc = sim(site, scenario(tmp_path, {'name': 'mean_default'}), out=tmp_path / 'ok')
    assert proc.returncode == 0, proc.stderr


def test_a_required_law_field_missing_from_the_yaml_is_one_line(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('required', 'Required')])
    proc = sim(site, scenario(tmp_path, {'name': 'required'}))
    assert_one_line_error(proc, 'protocol.gain: missing (protocol required has no default')
    proc = sim(site, scenario(tmp_path, {'name': 'required', 'gain': 2.0}), out=tmp_path / 'o')
    assert proc.returncode == 0, proc.stderr


def test_a_vector_valued_law_field_reads_a_yaml_list(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('vectored', 'Vectored')])
    proc = sim(site, scenario(tmp_path, {'name': 'vectored', 'gains': [1.0, 3]}),
               out=tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / 'out' / 'summary.json').read_text())['status'] == 'completed'
    proc = sim(site, scenario(tmp_path, {'name': 'vectored', 'gains': [1.0, 'x']}))
    assert_one_line_error(proc, "protocol.gains[1]: expected a number, got 'x'")
    proc = sim(site, scenario(tmp_path, {'name': 'vectored', 'gains': 2.0}))
    assert_one_line_error(proc, 'protocol.gains: expected a non-empty list of numbers')


def test_a_wrong_shape_at_a_later_step_is_one_line_naming_the_law_and_time(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('late_shape', 'LateShape')])
    proc = sim(site, scenario(tmp_path, {'name': 'late_shape'}), out=tmp_path / 'out')
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in proc.stderr, proc.stderr
    assert ('protocol.name: late_shape: combine() returned shape (12, 1), not (12, 2) '
            'at t = 1 s') in lines[0]


def test_a_leader_model_may_set_its_own_initial_state(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped')], leaders=[('orbit', 'Orbit')])
    path = scenario(tmp_path, {'name': 'damped'}, {'model': 'orbit', 'rho': 2.0,
                                                   'centre': [1.0, 1.0]})
    proc = sim(site, path, '--set', 'record_every=1', out=tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    series = np.load(tmp_path / 'out' / 'timeseries.npz')
    np.testing.assert_array_equal(series['leader_q'][0], [3.0, 1.0])
    np.testing.assert_array_equal(series['leader_p'][0], [0.0, 1.0])
    # On its circle all along (RK4): |q - centre| = rho.
    np.testing.assert_allclose(np.linalg.norm(series['leader_q'] - 1.0, axis=1), 2.0,
                               rtol=1e-6)
    path = scenario(tmp_path, {'name': 'damped'}, {'model': 'orbit', 'position': [0, 0]})
    assert_one_line_error(sim(site, path), 'leader.position: set by the orbit model')


def test_a_broken_or_duplicate_plugin_fails_only_the_runs_that_use_it(tmp_path):
    site = tmp_path / 'site'
    install_plugins(site, laws=[('damped', 'Damped'), ('no_combine', 'NoCombine')],
                    leaders=[('circle', 'Circle')])
    install_plugins(site, laws=[('damped', 'Damped')], leaders=[('circle', 'Circle')],
                    package='other-plugins', module='other_plugins')
    ep = site / 'flock_test_plugins-1.0.dist-info' / 'entry_points.txt'
    # The leaders' section is the file's last: a leader model that cannot be imported.
    ep.write_text(ep.read_text() + 'broken = missing_module:Model\n')
    builtin = scenario(tmp_path, {'name': 'olfati_saber_2006'})
    proc = sim(site, builtin, out=tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    listing = sim(site, '--list')
    assert listing.returncode == 0, listing.stderr
    rows = {line.split()[0]: line for line in listing.stdout.splitlines()
            if line.startswith('  ')}
    assert 'BROKEN' in rows['no_combine'] and 'does not define combine' in rows['no_combine']
    assert 'BROKEN' in rows['broken'] and 'ModuleNotFoundError' in rows['broken']
    assert 'BROKEN' in rows['damped'] and 'also registered by package' in rows['damped']
    assert 'BROKEN' in rows['circle'] and 'also registered by package' in rows['circle']
    assert 'BROKEN' not in rows['olfati_saber_2006'] and 'BROKEN' not in rows['lorenz']
    assert_one_line_error(sim(site, scenario(tmp_path, {'name': 'no_combine'})),
                          'does not define combine')
    path = scenario(tmp_path, {'name': 'olfati_saber_2006'},
                    {'model': 'circle', 'position': [0, 0], 'velocity': [1, 0]})
    assert_one_line_error(sim(site, path), 'flock_swarm.leaders:circle',
                          'also registered by package')
    # An intrinsic model naming a broken plugin gets its reason, not 'unknown value'.
    path = scenario(tmp_path, {'name': 'olfati_saber_2006'})
    path.write_text(path.read_text() + 'intrinsic: {model: broken}\n')
    assert_one_line_error(sim(site, path), 'flock_swarm.leaders:broken', 'cannot be imported')


def test_a_plugin_reusing_a_built_in_name_is_ignored_and_named(tmp_path):
    """Another package registering ``olfati_saber_2006`` and ``lorenz`` made both names
    unusable (the presets with them failed) and ``sim --list`` called the built-in BROKEN:
    the built-ins stay, the plugin's entries are listed as IGNORED with its package."""
    site = tmp_path / 'site'
    install_plugins(site, laws=[('olfati_saber_2006', 'Damped')], leaders=[('lorenz', 'Circle')],
                    package='squatter-plugins', module='squatter_plugins')
    out = tmp_path / 'out'
    proc = sim(site, 'su2009_fig6', '--set', 'duration=0.1', out=out)
    assert proc.returncode == 0, proc.stderr
    assert json.loads((out / 'summary.json').read_text())['status'] == 'completed'
    proc = sim(site, scenario(tmp_path, {'name': 'olfati_saber_2006'}), out=tmp_path / 'o2')
    assert proc.returncode == 0, proc.stderr
    listing = sim(site, '--list')
    rows = [line for line in listing.stdout.splitlines() if line.startswith('  ')]
    assert not any('BROKEN' in line for line in rows), listing.stdout
    builtin = [line for line in rows if line.split()[:2] == ['olfati_saber_2006', '[flock_swarm]']]
    assert len(builtin) == 1
    ignored = [line.split(None, 2) for line in rows if 'IGNORED' in line]
    assert ignored == [
        ['olfati_saber_2006', '[squatter-plugins]', "IGNORED: flock_swarm.laws:olfati_saber_2006 "
         "(squatter_plugins:Damped): 'olfati_saber_2006' is a built-in name of flock_swarm; "
         'register the plugin under another name'],
        ['lorenz', '[squatter-plugins]', "IGNORED: flock_swarm.leaders:lorenz "
         "(squatter_plugins:Circle): 'lorenz' is a built-in name of flock_swarm; register the "
         'plugin under another name']]
