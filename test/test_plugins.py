"""Laws and leader models as plugins: registration through entry points, and broken plugins.

Each test registers its plugins as a real installed distribution (a ``*.dist-info``
directory with ``entry_points.txt`` on ``PYTHONPATH``, what ``pip install`` leaves behind)
and runs the real ``sim`` command in a subprocess, so the lookup goes through
``importlib.metadata`` exactly as for a user's package (examples/ tests a pip- and
colcon-installed one end to end).
"""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from flock_swarm.core import registry

PLUGIN_MODULE = '''
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import LeaderModel, Law, require


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


class NotALaw:
    name = 'not_a_law'


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
                    module='fake_plugins'):
    """Write a distribution registering ``laws`` and ``leaders`` (``name = Class``) in ``site``."""
    site.mkdir(exist_ok=True)
    (site / f'{module}.py').write_text(PLUGIN_MODULE)
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
