"""The "How to add" recipes of docs/architecture.md, each built from exactly the files it lists.

A law, a leader model and a plant are two files: the module and one entry-point line, here
written as a plugin distribution on ``PYTHONPATH`` (the module and the ``entry_points.txt``
that ``pip install`` leaves of the package's ``setup.py``). A world backend, a metric and a
command change flock_swarm itself: the test copies the package into a temporary directory,
edits exactly the files the recipe names there, and runs the copy. Each test reads the
recipe's file count from the page, so the page and the test cannot drift apart.
"""

import json
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import textwrap

import pytest

from test_plants_analysis import plant_example

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / 'docs' / 'architecture.md'
TIMEOUT = 120

LAW = '''
from dataclasses import dataclass
from typing import ClassVar

from flock_swarm.plugin import Law


@dataclass(frozen=True)
class Pulled(Law):
    """Velocity consensus and a linear pull towards the leader."""

    name: ClassVar[str] = 'pulled'
    r: float = 4.0
    k: float = 1.0

    @property
    def radius(self):
        return self.r

    def pair(self, qi, pi, qj, pj, w):
        return pj - pi

    def combine(self, q, p, s, leader, agents, dt):
        if leader is None:
            return s
        return s - self.k * (q - leader.q) - self.k * (p - leader.p)
'''

LEADER = '''
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flock_swarm.plugin import LeaderModel


@dataclass(frozen=True)
class Braking(LeaderModel):
    """A leader that slows down at rate ``c``."""

    name: ClassVar[str] = 'braking'
    c: float = 0.5

    def acceleration(self, t, q, p):
        return -self.c * np.asarray(p)
'''


def recipe_files(what: str) -> str:
    """Return the file count the page's recipe gives (``'2'``, ``'2 or 3'``...)."""
    found = re.search(rf'\*\*An? {what}: ([\w ]+?) files?[.,]', PAGE.read_text())
    assert found, what
    return found.group(1)


def plugin_site(tmp_path: Path, group: str, module: str, source: str, entry: str) -> Path:
    """Write the recipe's two files as a distribution: the module, and its entry point."""
    site = tmp_path / 'site'
    site.mkdir()
    (site / f'{module}.py').write_text(source)
    info = site / 'my_recipe-1.0.dist-info'
    info.mkdir()
    (info / 'METADATA').write_text('Metadata-Version: 2.1\nName: my-recipe\nVersion: 1.0\n')
    (info / 'entry_points.txt').write_text(f'[{group}]\n{entry}\n')
    assert sorted(p.name for p in site.rglob('*') if p.is_file()) == sorted(
        [f'{module}.py', 'METADATA', 'entry_points.txt'])
    return site


def scenario(tmp_path: Path, **sections) -> Path:
    """Write a small 2-D scenario; ``sections`` replace its top-level keys."""
    data = {'name': 'recipe', 'dim': 2, 'n_agents': 8, 'dt': 0.05, 'duration': 1.0, 'seed': 3,
            'protocol': {'name': 'su_informed', 'r': 4.0, 'd': 3.3, 'eps': 0.1, 'h': 0.9,
                         'a': 5.0, 'b': 5.0, 'c1': 0.5, 'c2': 0.5},
            'informed': {'select': 'all'},
            'initial': {'position_box': [[0, 6], [0, 6]], 'velocity_box': [[0, 1], [0, 1]]},
            'leader': {'model': 'constant_velocity', 'position': [3, 3], 'velocity': [1, 0]}}
    data.update(sections)
    path = tmp_path / 'recipe.yaml'
    path.write_text(json.dumps(data))
    return path


def run(args: list, pythonpath: Path, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python ARGS`` with ``pythonpath`` first on the path; it must succeed."""
    env = dict(os.environ, PYTHONPATH=str(pythonpath))
    done = subprocess.run([sys.executable, *map(str, args)], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert done.returncode == 0 and 'Traceback' not in done.stderr, done.stderr
    return done


def sim(path: Path, out: Path, pythonpath: Path, cwd: Path | None = None) -> dict:
    """Run ``sim`` on a scenario; return its summary."""
    run(['-m', 'flock_swarm.cli.sim', path, '--quiet', '--out', out], pythonpath, cwd)
    return json.loads((out / 'summary.json').read_text())


def test_a_law_is_two_files(tmp_path):
    assert recipe_files('law') == '2'
    site = plugin_site(tmp_path, 'flock_swarm.laws', 'my_law', LAW, 'pulled = my_law:Pulled')
    summary = sim(scenario(tmp_path, protocol={'name': 'pulled', 'k': 2.0}), tmp_path / 'out',
                  site)
    assert summary['status'] == 'completed' and summary['protocol'] == 'pulled'


def test_a_leader_model_is_two_files(tmp_path):
    assert recipe_files('leader model') == '2'
    site = plugin_site(tmp_path, 'flock_swarm.leaders', 'my_leader', LEADER,
                       'braking = my_leader:Braking')
    leader = {'model': 'braking', 'c': 0.5, 'position': [3, 3], 'velocity': [1, 0]}
    summary = sim(scenario(tmp_path, leader=leader), tmp_path / 'out', site)
    assert summary['status'] == 'completed'
    # The leader braked: its final speed is about exp(-c t) of the initial 1 m/s.
    speed = run(['-c', 'import numpy as np, sys; s = np.load(sys.argv[1]); '
                 'print(np.linalg.norm(s["leader_p"][-1]))', tmp_path / 'out' /
                 'timeseries.npz'], site).stdout
    assert float(speed) == pytest.approx(0.6065, abs=1e-3)


def test_a_plant_is_two_files_and_the_robot_agent_drives_it(tmp_path):
    """docs/extending.md's velocity plant: flown by ``sim``, and among the plants the robot
    agent drives without an edit of robot_agent.py (it kept its own list of them)."""
    assert recipe_files('plant model') == '2'
    site = plugin_site(tmp_path, 'flock_swarm.plants', 'kinematic', plant_example(),
                       'kinematic = kinematic:Kinematic')
    summary = sim(scenario(tmp_path, plant={'model': 'kinematic', 'max_speed': 1.5}),
                  tmp_path / 'out', site)
    assert summary['status'] == 'completed'
    drives = run(['-c', 'from flock_swarm.nodes.robot_agent import velocity_plants; '
                  'print(velocity_plants())'], site).stdout
    assert drives.strip() == "['kinematic', 'unicycle', 'velocity_lag']"


def package_copy(tmp_path: Path) -> Path:
    """Return a directory holding a copy of flock_swarm and its docs, to edit a recipe in."""
    copy = tmp_path / 'copy'
    shutil.copytree(ROOT / 'flock_swarm', copy / 'flock_swarm',
                    ignore=shutil.ignore_patterns('__pycache__', '*.so'))
    for so in (ROOT / 'flock_swarm').glob('*.so'):
        shutil.copy(so, copy / 'flock_swarm' / so.name)
    shutil.copytree(ROOT / 'docs', copy / 'docs', ignore=shutil.ignore_patterns('figures'))
    return copy


def edit(path: Path, old: str, new: str) -> None:
    """Replace the one occurrence of ``old`` in ``path`` by ``new``."""
    text = path.read_text()
    assert text.count(old) == 1, (path, old)
    path.write_text(text.replace(old, new))


def outputs_table_matches(copy: Path) -> None:
    """Check the copy's docs/outputs.md against its SUMMARY_KEYS, as test_summary_keys does
    (its ``markdown_row``)."""
    run(['-c', textwrap.dedent('''\
        import sys
        from pathlib import Path
        sys.path.append(sys.argv[1])
        from test_summary_keys import markdown_row
        from flock_swarm.core.summary import SUMMARY_KEYS
        text = Path('docs/outputs.md').read_text()
        section = text[text.index('## `summary.json`'):text.index('## `timeseries.npz`')]
        rows = [line for line in section.splitlines() if line.startswith('| `')]
        assert rows == [markdown_row(k) for k in SUMMARY_KEYS], rows[:2]
        '''), ROOT / 'test'], copy, cwd=copy)


def test_a_metric_is_two_or_three_files(tmp_path):
    """A per-step metric (core/metrics.py), its summary key (core/summary.py) and its line in
    docs/outputs.md: ``sim`` records and reports it, and the docs' table still matches."""
    assert recipe_files('metric') == '2 or 3'
    copy = package_copy(tmp_path)
    core = copy / 'flock_swarm' / 'core'
    edit(core / 'metrics.py', "'min_pair_distance', 'components')",
         "'min_pair_distance', 'components', 'speed_max')")
    edit(core / 'metrics.py', "        'components': float(count),\n",
         "        'components': float(count),\n"
         "        'speed_max': float(np.linalg.norm(p, axis=1).max()),\n")
    edit(core / 'summary.py', "\nSUMMARY_KEYS: tuple[SummaryKey, ...] = (\n",
         "\nSUMMARY_KEYS: tuple[SummaryKey, ...] = (\n"
         "    _K('speed_max', FINAL, 'the largest speed at `t_final` [m/s]',\n"
         "       _final('metric_speed_max'), sweep=True, series='metric_speed_max'),\n")
    table = copy / 'docs' / 'outputs.md'
    lines = table.read_text().splitlines(keepends=True)
    first = next(k for k, line in enumerate(lines) if line.startswith('| `n_agents`'))
    lines.insert(first, '| `speed_max` | final | the largest speed at `t_final` [m/s] | '
                 'yes, at times | sim, world, analyze |\n')
    table.write_text(''.join(lines))
    outputs_table_matches(copy)
    summary = sim(scenario(tmp_path), tmp_path / 'out', copy, cwd=copy)
    assert summary['speed_max'] > 0.0
    run(['-c', 'import numpy as np, sys; s = np.load(sys.argv[1]); '
         'assert s["metric_speed_max"].shape == s["t"].shape',
         tmp_path / 'out' / 'timeseries.npz'], copy)


BACKEND = '''

class Frozen(DoubleIntegrator):
    """Agents that stay where they are (a recipe's backend)."""

    name = 'frozen'

    def step(self, u, twists, dt):
        """Leave every agent where it is."""


'''


@pytest.mark.ros
def test_a_world_backend_is_one_file(tmp_path, ros_domain):
    """A backend class and its FACTORIES entry in engine/backends.py: ``swarm --backend``
    and the world take it, and the world integrates with it."""
    import numpy as np
    assert recipe_files('world backend') == '1'
    copy = package_copy(tmp_path)
    backends = copy / 'flock_swarm' / 'engine' / 'backends.py'
    edit(backends, '\n#: Every backend by its name', BACKEND + '#: Every backend by its name')
    edit(backends, 'WorldBackend]] = {\n', "WorldBackend]] = {\n    'frozen': Frozen,\n")
    run(['-m', 'flock_swarm.cli.swarm', 'demo', '--backend', 'frozen', '--set', 'duration=0.2',
         '--no-plots', '--domain-id', ros_domain, '--out', tmp_path / 'out'], copy, copy)
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['status'] == 'completed' and summary['missed_commands'] == 0
    with np.load(tmp_path / 'out' / 'timeseries.npz') as series:
        assert np.array_equal(series['q'][-1], series['q'][0])


COMMAND = '''
"""``hello``: says how many agents a scenario has."""

import argparse
import sys

from flock_swarm.console import EXIT_USAGE, OneLineParser
from flock_swarm.core.errors import ScenarioError
from flock_swarm.presets import load


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog='hello', description=__doc__)
    parser.add_argument('scenario')
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        sc = load(args.scenario)
    except ScenarioError as exc:
        print(f'hello: error: {exc}', file=sys.stderr)
        return EXIT_USAGE
    print(f'{sc.name}: {sc.n_agents} agents')
    return 0


if __name__ == '__main__':
    sys.exit(main())
'''


def test_a_command_is_two_files(tmp_path):
    """``flock_swarm/cli/hello.py`` and its console script (the installed entry points of
    setup.py): listed by console.commands(), found by the swarm runner, and it runs."""
    assert recipe_files('command') == '2'
    copy = package_copy(tmp_path)
    (copy / 'flock_swarm' / 'cli' / 'hello.py').write_text(COMMAND)
    from importlib.metadata import distribution
    dist = distribution('flock-swarm')
    info = copy / f'flock_swarm-{dist.version}.dist-info'
    info.mkdir()
    (info / 'METADATA').write_text(dist.read_text('METADATA'))
    (info / 'entry_points.txt').write_text(
        dist.read_text('entry_points.txt').replace(
            '[console_scripts]\n', '[console_scripts]\nhello = flock_swarm.cli.hello:main\n'))
    listed = run(['-c', 'from flock_swarm.console import commands; '
                  'from flock_swarm.nodes.swarm_runner import executable; '
                  'print(commands()["hello"], executable("hello")[-1])'], copy, copy).stdout
    assert listed == 'flock_swarm.cli.hello flock_swarm.cli.hello\n'
    said = run(['-m', 'flock_swarm.cli.hello', 'demo'], copy, copy).stdout
    assert said == 'demo: 30 agents\n'
