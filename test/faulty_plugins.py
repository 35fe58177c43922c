"""Plugins that fail in the middle of a run, installed as a real distribution by the tests.

:func:`install_faulty` registers them (entry points) in a site directory; a process started
with that directory on ``PYTHONPATH`` (``sim``, ``swarm``, the nodes) finds them as it finds
a user's plugin. Each law pulls the agents towards the leader and fails once the leader has
passed ``x = at`` (it moves at 1 m/s from ``x = 3``: step 20 at ``dt = 0.05``), for agent
``agent`` only; each leader model fails once ``t >= at``.
"""

import json
import textwrap

from test_plugins import install_plugins

SOURCE = '''
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import LeaderModel, Law


@dataclass(frozen=True)
class Pull(Law):
    """Velocity consensus and a pull to the leader, failing mid-run (a test law)."""

    name: ClassVar[str] = 'pull'
    r: float = 4.0
    k: float = 1.0
    agent: int = 2
    at: float = 3.975

    @property
    def radius(self):
        return self.r

    def agent_data(self, setup):
        return {'index': np.arange(setup.n_agents)}

    def pair(self, qi, pi, qj, pj, w):
        return pj - pi

    def combine(self, q, p, s, leader, agents, dt):
        if leader is None:
            return s
        u = s - self.k * (q - leader.q) - self.k * (p - leader.p)
        if leader.q[0] < self.at:
            return u
        return self.fail(u, agents.data['index'] == self.agent)

    def fail(self, u, mine):
        return u


@dataclass(frozen=True)
class Raises(Pull):
    name: ClassVar[str] = 'raises_mid_run'

    def fail(self, u, mine):
        if mine.any():
            raise ZeroDivisionError('the gain of the failing agent')
        return u


@dataclass(frozen=True)
class NotFinite(Pull):
    name: ClassVar[str] = 'nan_mid_run'

    def fail(self, u, mine):
        u[mine] = np.nan
        return u


@dataclass(frozen=True)
class WrongShape(Pull):
    name: ClassVar[str] = 'shape_mid_run'

    def fail(self, u, mine):
        return u[:, :1]


@dataclass(frozen=True)
class Stalls(LeaderModel):
    """Constant velocity, then an exception from t = at (a test model)."""

    name: ClassVar[str] = 'raises_mid_run'
    autonomous: ClassVar[bool] = False
    at: float = 1.0

    def acceleration(self, t, q, p):
        if t >= self.at:
            raise RuntimeError('the leader lost its track')
        return np.zeros_like(p)


@dataclass(frozen=True)
class Widens(Stalls):
    name: ClassVar[str] = 'shape_mid_run'

    def acceleration(self, t, q, p):
        return np.zeros(p.shape[0] + (t >= self.at))
'''

#: ``(entry-point name, class)`` of the faulty laws and leader models.
LAWS = [('pull', 'Pull'), ('raises_mid_run', 'Raises'), ('nan_mid_run', 'NotFinite'),
        ('shape_mid_run', 'WrongShape')]
LEADERS = [('raises_mid_run', 'Stalls'), ('shape_mid_run', 'Widens')]
#: The step at which they fail (the leader at x = 4, t = 1 s).
FAULT_STEP = 20


def install_faulty(site):
    """Register the faulty laws and leader models in ``site`` (a directory for PYTHONPATH)."""
    install_plugins(site, LAWS, LEADERS, package='flock-faulty-plugins',
                    module='faulty_plugins', source=SOURCE)


def faulty_scenario(path, law='pull', leader='constant_velocity', n_agents=6,
                    duration=2.0):
    """Write a 2-D scenario of ``n_agents`` (all informed) flying law ``law`` behind a
    leader of model ``leader`` (at 1 m/s from x = 3); return its path."""
    path.write_text(textwrap.dedent(f'''\
        name: faulty
        dim: 2
        n_agents: {n_agents}
        dt: 0.05
        duration: {duration}
        seed: 3
        record_every: 1
        protocol: {json.dumps({'name': law})}
        informed: {{select: all}}
        initial: {{position_box: [[0, 4], [0, 4]], velocity_box: [[0, 1], [0, 1]]}}
        leader: {json.dumps({'model': leader, 'position': [3, 3], 'velocity': [1, 0]})}
        '''))
    return path
