"""The layers of docs/architecture.md, checked on the imports of every module of the package.

commands (``flock_swarm.cli``) -> public API (``plugin``, ``testing``) -> libraries (nodes,
analysis, study, reproduction) -> io (bags, scenario files, outputs, the topic contract) ->
core. A module imports only its own layer and the layers below it; the core imports no
rclpy, YAML, plotting, bag or file and process modules. Imports are read from the source
(every ``import``, also inside functions), so a lazy import counts like any other.
"""

import ast
import importlib
from pathlib import Path
import re
import sys

import pytest

from conftest import imported_modules

PACKAGE = Path(__file__).resolve().parent.parent / 'flock_swarm'
#: The layers, lowest first, and the modules of each (a name covers its submodules).
LAYERS = {
    'core': ('flock_swarm.core',),
    'io': ('flock_swarm.bag', 'flock_swarm.contract', 'flock_swarm.console',
           'flock_swarm.foxglove_ws', 'flock_swarm.outputs', 'flock_swarm.plots',
           'flock_swarm.presets', 'flock_swarm.scenario_yaml'),
    'libraries': ('flock_swarm.nodes', 'flock_swarm.engine', 'flock_swarm.analysis',
                  'flock_swarm.study',
                  'flock_swarm.reproduce', 'flock_swarm.launch_plan', 'flock_swarm.security'),
    'public': ('flock_swarm.plugin', 'flock_swarm.testing'),
    'commands': ('flock_swarm.cli',),
}
ORDER = list(LAYERS)
#: Entry modules that run a command when executed with ``python -m`` (a way in, not a library).
ENTRY_MODULES = {'flock_swarm.reproduce.__main__'}
#: What the numerical core must not import: ROS, YAML, plotting, bags, files and processes.
CORE_FORBIDDEN = ('rclpy', 'rosidl_runtime_py', 'rosbags', 'yaml', 'matplotlib', 'mcap',
                  'json', 'pathlib', 'shutil', 'tempfile', 'subprocess', 'socket', 'pickle',
                  'io', 'os')


def module_name(path: Path) -> str:
    """Return the dotted name of a package file."""
    parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def layer_of(name: str) -> str | None:
    """Return the layer of a flock_swarm module (``None``: the package root and its
    ``__version__``, which every layer may import)."""
    for layer, prefixes in LAYERS.items():
        if any(name == p or name.startswith(p + '.') for p in prefixes):
            return layer
    return None


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob('*.py'))}


def test_every_module_has_a_layer():
    unplaced = [m for m in MODULES if m != 'flock_swarm' and layer_of(m) is None]
    assert not unplaced, f'modules in no layer (add them to LAYERS and docs/architecture.md): ' \
                         f'{unplaced}'


@pytest.mark.parametrize('name', sorted(m for m in MODULES if layer_of(m) == 'core'))
def test_the_core_imports_no_ros_yaml_plotting_or_io(name):
    bad = sorted(i for i in imported_modules(MODULES[name])
                 if i.split('.')[0] in CORE_FORBIDDEN
                 or (i.startswith('flock_swarm.') and layer_of(i) not in ('core', None)))
    assert not bad, f'{name} imports {bad}'


@pytest.mark.parametrize('name', sorted(m for m in MODULES if layer_of(m) is not None))
def test_a_module_imports_only_its_layer_and_those_below(name):
    if name in ENTRY_MODULES:
        return
    own = ORDER.index(layer_of(name))
    above = sorted(i for i in imported_modules(MODULES[name])
                   if i.startswith('flock_swarm.') and layer_of(i) is not None
                   and ORDER.index(layer_of(i)) > own)
    assert not above, f'{name} ({ORDER[own]}) imports {above} from a layer above it'


def test_the_layer_check_sees_a_violation(tmp_path):
    # The check itself: a core module importing rclpy and a command is caught.
    bad = tmp_path / 'bad.py'
    bad.write_text('import numpy\n\n\ndef f():\n    import rclpy\n'
                   '    from flock_swarm.cli import sim\n')
    found = imported_modules(bad)
    assert {'rclpy', 'flock_swarm.cli'} <= found
    assert layer_of('flock_swarm.cli.sim') == 'commands'
    assert ORDER.index('commands') > ORDER.index('core')


# -- docs/architecture.md -----------------------------------------------------------------

PAGE = PACKAGE.parent / 'docs' / 'architecture.md'


def page_layers() -> dict[str, str]:
    """Return every module path the page's "Modules" section names (``nodes/world.py``,
    ``reproduce/experiments/*.py``), mapped to the layer heading it is named under."""
    section = PAGE.read_text().split('\n## Modules\n', 1)[1].split('\n## ', 1)[0]
    named: dict[str, str] = {}
    layer = None
    for line in section.splitlines():
        if line.startswith('### '):
            layer = line[4:].strip()
        elif line.startswith('| `') and layer is not None:
            named[line.split('`')[1]] = layer
    return named


def test_the_architecture_page_names_every_module_under_its_layer():
    """Every module of the package is in the page's table of its layer (as LAYERS places it),
    and the page names no module that is not there."""
    named = page_layers()
    assert set(named.values()) == set(LAYERS)
    misplaced = []
    for name, path in MODULES.items():
        if path.name == '__init__.py':
            continue
        rel = path.relative_to(PACKAGE).as_posix()
        key = rel if rel in named else f'{path.parent.relative_to(PACKAGE).as_posix()}/*.py'
        if named.get(key) != layer_of(name):
            misplaced.append(f'{rel}: {named.get(key, "not on the page")}, {layer_of(name)} '
                             'by LAYERS')
    assert misplaced == []
    files = {p.relative_to(PACKAGE).as_posix() for p in MODULES.values()}
    stale = [n for n in named if n not in files and not n.endswith('/*.py')]
    assert stale == []


def test_the_architecture_page_refers_to_nothing_outside_the_repository():
    """Every path the page names relative to the repository is in it (the page pointed to a
    design file that never was)."""
    root = PACKAGE.parent
    text = PAGE.read_text()
    assert 'shared/' not in text and '../' not in text
    for path in set(re.findall(r'\b((?:docs|examples|launch|config|test)/[\w./-]+\w)', text)):
        assert (root / path).exists() or (root / path).with_suffix('').exists(), path


def test_an_agent_name_is_built_only_by_the_contract():
    """``agent_{i}`` is spelled in contract.py alone (six modules built it); the engine's
    MJCF bodies carry the same prefix through the model it compiles."""
    spelled = [p.relative_to(PACKAGE).as_posix() for p in MODULES.values()
               if "f'agent_{" in p.read_text()]
    assert spelled == ['engine/mujoco_world.py']


# -- sizes (issue 40) -----------------------------------------------------------------------

#: Issue 40's limits for the ROS layer: lines of the world's plumbing and of its stepper...
FILE_LINES = {'nodes/world.py': 300, 'nodes/stepper.py': 500}
#: ... lines of any function (from its ``def`` to its last line, docstring included) ...
FUNCTION_LINES = 80
#: ... and methods of any class (the functions defined in its body).
CLASS_METHODS = 25


def oversized(path: Path) -> list[str]:
    """Return the functions of ``path`` over :data:`FUNCTION_LINES` lines and its classes
    with over :data:`CLASS_METHODS` methods, one line each."""
    found = []
    functions = (ast.FunctionDef, ast.AsyncFunctionDef)
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, functions):
            lines = node.end_lineno - node.lineno + 1
            if lines > FUNCTION_LINES:
                found.append(f'{path.name}:{node.lineno} {node.name}: {lines} lines')
        elif isinstance(node, ast.ClassDef):
            methods = sum(isinstance(item, functions) for item in node.body)
            if methods > CLASS_METHODS:
                found.append(f'{path.name}:{node.lineno} {node.name}: {methods} methods')
    return found


def test_the_nodes_keep_issue_40s_sizes():
    """world.py <= 300 lines, stepper.py <= 500, no function in nodes/ over 80 lines and no
    class there with over 25 methods (the world and its stepper had grown to 711 and 878
    lines, WorldStepper to 30 methods, WorldNode.__init__ to 129 lines)."""
    lines = {rel: len((PACKAGE / rel).read_text().splitlines()) for rel in FILE_LINES}
    assert {rel: n for rel, n in lines.items() if n > FILE_LINES[rel]} == {}
    found = [line for path in sorted((PACKAGE / 'nodes').rglob('*.py'))
             for line in oversized(path)]
    assert found == []


def test_the_size_check_sees_a_long_function_and_a_large_class(tmp_path):
    # The check itself: 81 lines and 26 methods are caught, 80 and 25 are not.
    body = ''.join(f'    x{k} = {k}\n' for k in range(79))
    large = ''.join(f'    def m{k}(self):\n        pass\n' for k in range(26))
    fits = ''.join(f'    def m{k}(self):\n        pass\n' for k in range(25))
    source = tmp_path / 'big.py'
    source.write_text(f'def long():\n{body}    return 0\n\n\ndef fits():\n{body}\n\n'
                      f'class Large:\n{large}\n\nclass Fits:\n{fits}')
    assert oversized(source) == ['big.py:1 long: 81 lines', 'big.py:166 Large: 26 methods']


def test_the_old_name_of_the_swarm_runner_warns_and_gives_it():
    """nodes/harness.py (the production runner behind ``swarm``, renamed: it is not a test
    harness) still imports, as the swarm runner itself, with a DeprecationWarning."""
    sys.modules.pop('flock_swarm.nodes.harness', None)
    with pytest.warns(DeprecationWarning, match='import flock_swarm.nodes.swarm_runner'):
        old = importlib.import_module('flock_swarm.nodes.harness')
    assert old is importlib.import_module('flock_swarm.nodes.swarm_runner')
