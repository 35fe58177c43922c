"""Bad input, property-based: scenario files through ``sim``, ROS parameters through the nodes.

The property (issue 6): every generated input either runs, and then everything it wrote is
finite, or stops with exit status 2 and exactly one line naming the offending key; never a
traceback. Scenario files are mutations of the real presets in ``config/`` (wrong types,
out-of-range numbers, NaN and infinities, missing and unknown keys, wrong vector lengths,
huge values, strings where numbers go, scaled paper values), shortened to a few steps and
fed to :func:`flock_swarm.cli.sim.main` in-process, as files and as ``--set`` / ``--seed``
arguments. ROS parameters are generated ``parameter_overrides`` of the world, leader and
agent nodes, built in a per-test ``rclpy.Context`` on the test's own domain id; the nodes'
``main()`` is checked on malformed ``--ros-args``.

Generated numbers are either plainly invalid or cheap to run: a *valid* but expensive value
(a step of a microsecond, a hundred thousand agents, a duration of hours) is a long run, not
bad input, so the strategies below draw moderate numbers on a coarse grid and the huge ones
far beyond every limit. Examples are derandomized (the same inputs on every run) and the
budgets keep the file around 20 s on two cores. Every input that once broke the property is
kept below as a plain regression case, next to the fix's commit.
"""

import contextlib
import copy
import datetime
import io
import json
import math
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, example, given, settings, strategies as st

from flock_swarm.cli import sim
from flock_swarm.core.errors import ScenarioError, one_line
from flock_swarm.core.scenario import TOP_KEYS
from flock_swarm.core.summary import SUMMARY_KEYS
from flock_swarm.scenario_yaml import apply_override, parse_yaml
from flock_swarm.presets import load_mapping, preset_names

#: Steps every generated run is cut to (the property is about input, not long runs).
SHORT_STEPS = 3
#: Names an error line may start with besides the scenario's own top-level keys.
CLI_KEYS = ('scenario', '<scenario>', '--seed', '--set', '--out')

#: Budgets: the whole file stays under about a minute on two cores.
SIM_EXAMPLES = 600
CLI_EXAMPLES = 200
HEADLINE_EXAMPLES = 100


def short(data: dict) -> dict:
    """Return a preset mapping cut to :data:`SHORT_STEPS` steps, every step recorded."""
    out = copy.deepcopy(data)
    out['duration'] = SHORT_STEPS * out['dt']
    out['record_every'] = 1
    return out


BASES = {name: short(load_mapping(name)) for name in preset_names()}


# --------------------------------------------------------------------------------------------
# Strategies


#: Numbers out of every range, or not numbers at all though they parse as numbers elsewhere.
SPECIAL_NUMBERS = st.sampled_from([
    0, -1, -1.0, 0.0, -0.5, 1e300, -1e300, 1e15, -1e15, 10 ** 30, -(10 ** 30), 2 ** 63,
    10 ** 400, float('nan'), float('inf'), float('-inf'), 1e-300, 5e-324, -5e-324])
#: Moderate numbers on a grid of 1/8: in and out of every parameter's range, never a tiny step.
MODERATE_NUMBERS = st.one_of(st.integers(-1000, 1000),
                             st.integers(-8000, 8000).map(lambda k: k / 8))
#: Values of the wrong type: strings (also ones that read like numbers), lists, mappings,
#: booleans, null, YAML timestamps and binary.
WRONG_TYPES = st.one_of(
    st.sampled_from(['1.0', '1e3', 'nan', '.inf', 'abc', '', 'true', '[1, 2]', 'null']),
    st.text(max_size=6),
    st.booleans(), st.none(),
    st.lists(st.one_of(MODERATE_NUMBERS, SPECIAL_NUMBERS), max_size=4),
    st.dictionaries(st.sampled_from(['x', 'r', 'model']), MODERATE_NUMBERS, max_size=2),
    st.just(datetime.date(2001, 12, 14)), st.just(b'\x00\xff'))
BAD_VALUES = st.one_of(SPECIAL_NUMBERS, MODERATE_NUMBERS, WRONG_TYPES)
#: A duration: a long valid one is a long run, not bad input, so moderate ones are <= 0.
BAD_DURATIONS = st.one_of(SPECIAL_NUMBERS, st.integers(-1000, 0), WRONG_TYPES)
#: Factors for a float of a preset: mostly valid neighbours of the paper's value, so runs
#: happen too (at most 100 times longer or denser than the shortened preset).
SCALES = st.sampled_from([-1.0, 0.0, 0.5, 2.0, 10.0, 100.0])
#: Keys no schema has, plus keys that belong to another section or protocol.
UNKNOWN_KEYS = st.one_of(st.sampled_from(['gain', 'radius', 'c3', 'A', 'params', 'name',
                                          'n_agents', 'position']),
                         st.text(min_size=1, max_size=6))


def bad_values(path: tuple) -> st.SearchStrategy:
    """Return the strategy of replacement values for the key at ``path``."""
    return BAD_DURATIONS if path == ('duration',) else BAD_VALUES


def paths(node, prefix=()):
    """Yield the path (tuple of keys and indices) of every value inside ``node``."""
    if prefix:
        yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from paths(value, prefix + (key,))
    elif isinstance(node, list):
        for k, value in enumerate(node):
            yield from paths(value, prefix + (k,))


def lookup(data, path):
    """Return the value at ``path`` inside ``data``, or ``None`` where there is none."""
    for part in path:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def parent_of(data, path):
    """Return the container holding ``path`` and the key or index of it there."""
    node = data
    for part in path[:-1]:
        node = node[part]
    return node, path[-1]


@st.composite
def mutated_scenarios(draw):
    """Draw a preset and apply one to three mutations; return ``(name, mapping, log)``."""
    name = draw(st.sampled_from(sorted(BASES)))
    data = copy.deepcopy(BASES[name])
    log = []
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(sorted(paths(data), key=repr)))
        if draw(st.integers(0, 9)) == 0:
            data[draw(UNKNOWN_KEYS)] = draw(BAD_VALUES)
            log.append(('unknown', ()))
            continue
        parent, key = parent_of(data, where)
        value = parent[key]
        ops = ['replace', 'delete']
        if isinstance(value, float):
            ops += ['scale', 'scale']
        if isinstance(value, list):
            ops.append('lengthen')
        if isinstance(value, dict):
            ops.append('unknown')
        op = draw(st.sampled_from(ops))
        if op == 'replace':
            parent[key] = draw(bad_values(where))
        elif op == 'scale':
            parent[key] = value * draw(SCALES)
        elif op == 'delete':
            del parent[key]
        elif op == 'lengthen':
            value.append(copy.deepcopy(value[-1]) if value else draw(MODERATE_NUMBERS))
        else:
            value[draw(UNKNOWN_KEYS)] = draw(BAD_VALUES)
        log.append((op, where))
    return name, data, log


#: ``--set`` value text that is not YAML for a number (a digit string could be a valid, long run).
RAW_TEXT = st.text(alphabet=st.characters(exclude_categories=('Nd', 'Cs')), max_size=8)


@st.composite
def cli_overrides(draw):
    """Draw a preset and ``--set`` / ``--seed`` arguments; return ``(name, args)``."""
    name = draw(st.sampled_from(sorted(BASES)))
    args = []
    for _ in range(draw(st.integers(1, 3))):
        if draw(st.integers(0, 4)) == 0:
            path = (draw(UNKNOWN_KEYS),)
        else:
            path = draw(st.sampled_from(sorted(paths(BASES[name]), key=repr)))
        base = lookup(BASES[name], path)
        if isinstance(base, float) and draw(st.booleans()):
            value = base * draw(SCALES)
        else:
            value = draw(bad_values(path))
        text = draw(st.one_of(
            st.just(yaml.safe_dump(value, default_flow_style=True).removesuffix('\n...\n')
                    .rstrip('\n')), RAW_TEXT))
        args += ['--set', f'{".".join(str(part) for part in path)}={text}']
    if draw(st.booleans()):
        seeds = st.one_of(st.integers(0, 2 ** 32), st.integers(-10 ** 30, 10 ** 30), RAW_TEXT)
        args += ['--seed', str(draw(seeds))]
    return name, args


def read_as_sim(text: str, args: list[str]):
    """Return the mapping ``sim`` validates: the file with the ``--set`` overrides applied."""
    try:
        data = parse_yaml(text)
        for flag, value in zip(args[::2], args[1::2]):
            if flag == '--set':
                data = apply_override(data, value)
    except (yaml.YAMLError, ScenarioError, TypeError, AttributeError):
        return data if isinstance(data, dict) else None
    return data


# --------------------------------------------------------------------------------------------
# Running sim and judging the outcome


def run_sim(text: str, extra: list[str] = ()) -> tuple[int, str, Path,
                                                       tempfile.TemporaryDirectory]:
    """Run ``sim`` in-process on scenario text; return status, stderr, output dir, tmp dir.

    Warnings are printed to the captured stderr as the command line would show them.
    """
    tmp = tempfile.TemporaryDirectory(prefix='flock_prop_')
    path = Path(tmp.name) / 'scenario.yaml'
    path.write_text(text)
    out = Path(tmp.name) / 'out'
    err, std = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std), \
            warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        status = sim.main([str(path), '--out', str(out), '--quiet', *extra])
    text_err = err.getvalue() + ''.join(
        warnings.formatwarning(w.message, w.category, w.filename, w.lineno) for w in caught)
    return status, text_err, out, tmp


def numbers_in(value, where='summary'):
    """Yield ``(where, number)`` for every number inside a JSON value."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return
    if isinstance(value, (int, float)):
        yield where, value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from numbers_in(item, f'{where}.{key}')
    elif isinstance(value, list):
        for k, item in enumerate(value):
            yield from numbers_in(item, f'{where}[{k}]')


def assert_outputs_finite(out: Path) -> None:
    """Assert that ``summary.json`` and ``timeseries.npz`` hold only finite numbers."""
    summary = json.loads((out / 'summary.json').read_text())
    for where, number in numbers_in(summary):
        assert math.isfinite(number), f'{where} = {number}'
    with np.load(out / 'timeseries.npz') as series:
        for name in series.files:
            arr = series[name]
            if np.issubdtype(arr.dtype, np.number):
                assert np.isfinite(arr).all(), f'timeseries {name} is not finite'


def rendered_paths(node, prefix=''):
    """Yield every dotted path inside ``node`` as an error line writes it (``a.b[2]``)."""
    if isinstance(node, dict):
        for key, value in node.items():
            path = f'{prefix}.{one_line(str(key))}' if prefix else one_line(str(key))
            yield path
            yield from rendered_paths(value, path)
    elif isinstance(node, list):
        for k, value in enumerate(node):
            yield f'{prefix}[{k}]'
            yield from rendered_paths(value, f'{prefix}[{k}]')


def assert_one_line_error(status: int, err: str, data=None, prog: str = 'sim',
                          keys=CLI_KEYS) -> str:
    """Assert a usage error: status 2 and one line ``PROG: error: KEY: reason``; return KEY.

    KEY is a path of the input ``data`` or one of the schema's (a missing key), or one of
    ``keys`` (the file, a command-line option, a ROS parameter).
    """
    assert status == 2, f'exit status {status}, stderr: {err!r}'
    assert 'Traceback' not in err, err
    assert err.endswith('\n') and err.count('\n') == 1 and '\r' not in err, \
        f'expected exactly one line, got {err!r}'
    head = f'{prog}: error: '
    assert err.startswith(head), f'not "{head}KEY: reason": {err!r}'
    rest = err[len(head):-1]
    present = set(rendered_paths(data)) if data is not None else set()
    for match in re.finditer(': ', rest):
        key = rest[:match.start()]
        root = re.split(r'[.\[]', key, maxsplit=1)[0]
        if key in present or root in TOP_KEYS or key in keys:
            return key
    raise AssertionError(f'no key named: {err!r}')


def assert_runs_or_names_key(data, extra: list[str] = ()) -> None:
    """The property, for one scenario mapping (and extra ``sim`` arguments)."""
    text = dump(data)
    status, err, out, tmp = run_sim(text, extra)
    event(f'exit status {status}')
    with tmp:
        if status == 0:
            assert err == '', f'a successful quiet run printed {err!r}'
            assert_outputs_finite(out)
        else:
            # The keys as sim read them: YAML may turn a key such as '1e100' into a number.
            assert_one_line_error(status, err, read_as_sim(text, list(extra)))


def dump(data) -> str:
    """Return ``data`` as YAML text (block style, as the presets are written)."""
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


# --------------------------------------------------------------------------------------------
# Regressions: what the properties below found, one case per fix

#: A value that deletes its key in :func:`changed`.
DELETE = object()


def changed(name: str, changes: dict) -> dict:
    """Return preset ``name`` (shortened) with ``{dotted.path: value}`` applied.

    A numeric path part indexes a list; the value :data:`DELETE` removes the key.
    """
    data = copy.deepcopy(BASES[name])
    for dotted, value in changes.items():
        path = tuple(int(part) if part.isdigit() else part for part in dotted.split('.'))
        parent, key = parent_of(data, path)
        if value is DELETE:
            del parent[key]
        else:
            parent[key] = value
    return data


@pytest.mark.parametrize('name, changes, key', [
    # TypeError: unhashable type (the protocol table was indexed with a list or mapping).
    ('demo', {'protocol.name': []}, 'protocol.name'),
    ('su2009_fig7', {'protocol.name': {'x': 1}}, 'protocol.name'),
    # OverflowError: an integer beyond the float range converted to float.
    ('su2009_fig2', {'protocol.eps': 10 ** 400}, 'protocol.eps'),
    ('demo', {'leader.velocity.1': -(10 ** 309)}, 'leader.velocity[1]'),
    # TypeError: not JSON serialisable (a date or binary value written to scenario.json).
    ('su2009_fig7', {'description': datetime.date(2001, 12, 14)}, 'description'),
    ('demo', {'name': b'\x00\xff'}, 'name'),
    ('os2003_sink', {'informed.count': datetime.date(2001, 12, 14)}, 'informed.count'),
    # ValueError from scipy's KD-tree: squared distances of 1e300 m overflow.
    ('demo', {'leader.position.1': 1e300}, 'leader.position[1]'),
    ('os2003_sink', {'initial.position_box.1.1': -1e300}, 'initial.position_box[1][1]'),
    # ValueError from NumPy: 'Maximum allowed dimension exceeded' (10^15 agents).
    ('jadbabaie2003_leader', {'n_agents': 10 ** 15}, 'n_agents'),
    ('demo', {'n_agents': 1e300}, 'n_agents'),
    # OverflowError: steps = round(duration / dt) of an infinite quotient.
    ('demo', {'dt': 5e-324}, 'dt'),
    ('su2009_fig6', {'dt': 1e-300, 'duration': 1e12}, 'dt'),
    ('demo', {'duration': 1e12}, 'duration'),
    # summary.json held min_pair_distance = Infinity (not JSON) for a single agent.
    ('su2009_fig5', {'n_agents': 1}, 'n_agents'),
    # Issue 24: a seed beyond int64 ran in sim but died in swarm and the nodes.
    ('demo', {'seed': 2 ** 64}, 'seed'),
    # Issue 24: values the informed selection or an explicit initial state ignored silently.
    ('demo', {'informed.select': 'all'}, 'informed.count'),
    ('zhou2012_sec51', {'informed.fraction': 0.5}, 'informed.fraction'),
    ('su2009_fig2', {'informed.select': 'first', 'informed.ids': [1, 2]}, 'informed.ids'),
    ('demo', {'initial.velocities': [[0.0, 0.0]] * 30}, 'initial.velocity_box'),
    # Two lines: an unknown key holding a line break was printed as it was.
    ('os2003_sink', {'graph.a\nb': 1}, 'graph.a\\nb'),
    ('demo', {'\x1a\u2028': 1}, '\\x1a\\u2028'),
])
def test_regression(name, changes, key):
    """Each input once broke the property (a traceback); now it names its key."""
    data = changed(name, changes)
    status, err, out, tmp = run_sim(dump(data))
    with tmp:
        assert assert_one_line_error(status, err, data) == key


@pytest.mark.parametrize('name, changes', [
    # ValueError from NumPy: uniform(0.0, -0.0) raises 'high - low < 0'.
    ('os2003_sink', {'initial.velocity_box.1.1': -0.0}),
])
def test_regression_runs(name, changes):
    """Each input once broke the property (a traceback); now it runs, with finite outputs."""
    status, err, out, tmp = run_sim(dump(changed(name, changes)))
    with tmp:
        assert status == 0, err
        assert_outputs_finite(out)


@pytest.mark.parametrize('name', ['../escaped', '/tmp/flock_absolute', 'a\x00b', '..', ''])
def test_regression_name_is_one_directory(name, tmp_path, monkeypatch, capsys):
    """Without --out, sim writes to out/<name>: a name that is a path was followed out of it.

    '/tmp/x' wrote the outputs to /tmp/x, '../x' beside out/, and a NUL ended sim with a
    ValueError from mkdir (a traceback).
    """
    monkeypatch.chdir(tmp_path)
    data = dict(BASES['demo'], name=name)
    Path('scenario.yaml').write_text(dump(data))
    status = sim.main(['scenario.yaml', '--quiet'])
    err = capsys.readouterr().err
    assert assert_one_line_error(status, err, data) == 'name'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['scenario.yaml']


@pytest.mark.parametrize('text, extra, key', [
    # ValueError, AttributeError, RecursionError from PyYAML's constructors and composer.
    ('n_agents: 1' + '0' * 5000 + '\n', [], 'scenario'),
    ('dt: !!int abc\n', [], 'scenario'),
    ('dt: !!timestamp 2001-13-45\n', [], 'scenario'),
    ('dt: ' + '[' * 2000 + ']' * 2000 + '\n', [], 'scenario'),
    (None, ['--set', 'dt=!!float abc'], '--set'),
    # argparse's usage block before its error line (and SystemExit out of main()).
    (None, ['--seed', 'abc'], '--seed'),
    (None, ['--seed', '1.5'], '--seed'),
    (None, ['--set'], '--set'),
    # Issue 24: a billion laughs (MemoryError after 56 s), a key given twice (last one won),
    # an alias to itself, --out '' (wrote into the current directory), a seed beyond int64.
    ('l0: &l0 [a, a, a, a, a, a, a, a, a, a]\n' + ''.join(
        f'l{k}: &l{k} [{", ".join([f"*l{k - 1}"] * 10)}]\n' for k in range(1, 9))
     + 'description: *l8\n', [], 'scenario'),
    ('dt: 0.1\ndt: 0.2\n', [], 'scenario'),
    ('dt: &a [*a]\n', [], 'scenario'),
    (None, ['--set', 'description=[&a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1], &b [*a, *a, *a, *a, *a, '
            '*a, *a, *a, *a, *a], &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b], [*c, *c, *c, *c, '
            '*c, *c, *c, *c, *c, *c]]'], '--set'),
    (None, ['--out', ''], '--out'),
    (None, ['--seed', str(2 ** 63)], 'seed'),
])
def test_regression_cli(text, extra, key):
    """Malformed YAML or arguments: one line naming the file or the option, status 2."""
    status, err, out, tmp = run_sim(dump(BASES['demo']) if text is None else text, extra)
    with tmp:
        assert assert_one_line_error(status, err) == key


# --------------------------------------------------------------------------------------------
# Scenario files


@pytest.mark.parametrize('name', sorted(BASES))
def test_every_shortened_preset_runs(name):
    """The unmutated bases run: the mutations below start from valid scenarios."""
    status, err, out, tmp = run_sim(dump(BASES[name]))
    with tmp:
        assert status == 0, err
        assert_outputs_finite(out)


@settings(derandomize=True, database=None, max_examples=SIM_EXAMPLES, deadline=None)
@given(mutated_scenarios())
def test_mutated_scenario_runs_or_names_the_key(case):
    """Mutated presets: run with finite outputs, or exit 2 with one line naming the key."""
    name, data, log = case
    assert_runs_or_names_key(data)


@settings(derandomize=True, database=None, max_examples=CLI_EXAMPLES, deadline=None)
@given(cli_overrides())
def test_overrides_and_seed_run_or_name_the_key(case):
    """``--set`` and ``--seed`` on the presets: the same property, through the command line."""
    name, args = case
    assert_runs_or_names_key(BASES[name], args)


#: Items of a headline: every summary key (measures and not), near misses, and bad values.
HEADLINE_ITEMS = st.one_of(
    st.sampled_from([k.name for k in SUMMARY_KEYS]
                    + ['com_error', 'ETA', '', 'components', 'metric_eta', 'eta ']),
    BAD_VALUES)
#: ``metrics.headline``: lists of items (repeats too), or anything else.
HEADLINES = st.one_of(st.lists(HEADLINE_ITEMS, max_size=4), BAD_VALUES)
#: ``metrics.claim``: any text (line breaks, control and format characters, too long), or not
#: text at all.
CLAIMS = st.one_of(st.text(st.characters(exclude_categories=('Cs',)), max_size=120),
                   BAD_VALUES)


@settings(derandomize=True, database=None, max_examples=HEADLINE_EXAMPLES, deadline=None)
@given(st.sampled_from(sorted(BASES)), HEADLINES, st.one_of(st.none(), CLAIMS))
@example('su2009_fig6', ['com_position_error', 'com_error'], None)
@example('su2009_fig6', ['eta', 'eta'], None)
@example('demo', 'eta', None)
@example('demo', [], None)
@example('os2003_sink', ['seed'], 'one flock')
@example('demo', None, 'Su 2009:\n-> 0')
@example('demo', None, 'x' * 101)
@example('demo', ['x' * 10 ** 6], None)
def test_any_headline_runs_or_names_the_key(name, headline, claim):
    """``metrics.headline`` and ``metrics.claim`` (issue 24): the same property."""
    data = copy.deepcopy(BASES[name])
    if headline is not None:
        data['metrics']['headline'] = headline
    if claim is not None:
        data['metrics']['claim'] = claim
    assert_runs_or_names_key(data)


# --------------------------------------------------------------------------------------------
# ROS parameters of the nodes

#: Examples per node kind; a node with its publishers and subscriptions takes ~20-60 ms here.
NODE_EXAMPLES = 150
#: The agents of the small scenario the nodes are built on (cheap to construct).
NODE_AGENTS = 3
#: Every parameter of each node kind (its own, the common ones, the input limits).
NODE_PARAMS = {
    'world': ('out_dir', 'record', 'step_timeout', 'start_timeout', 'marker_every',
              'metrics_every', 'expect_subscribers', 'expect_telemetry_subscribers',
              'staleness', 'pace', 'max_abs_position',
              'max_abs_velocity', 'max_abs_accel'),
    'leader': ('expect_subscribers', 'start_timeout'),
    'agent': ('agent_id', 'agent_ids', 'leader_timeout', 'leader_start_timeout',
              'max_abs_position', 'max_abs_velocity', 'max_abs_accel'),
}
COMMON_NODE_PARAMS = ('scenario', 'seed', 'mode', 'realtime_factor', 'use_sim_time')
#: Scenario keys given as ROS parameters (overrides of single values), and unknown ones.
OVERRIDE_PARAMS = ('n_agents', 'dt', 'duration', 'dim', 'protocol.c1', 'protocol.name',
                   'protocol.h', 'informed.count', 'informed.select', 'leader.position',
                   'leader.model', 'metrics.eta_tolerance', 'metrics.headline',
                   'metrics.claim', 'record_every', 'gain',
                   'protocol.gain', 'leader.position.x')

INT64 = st.integers(-2 ** 63, 2 ** 63 - 1)
ROS_FLOATS = st.one_of(st.sampled_from([0.0, -1.0, 1e300, -1e300, float('nan'), float('inf'),
                                        float('-inf'), 5e-324, 0.5, 2.0, 30.0]),
                       st.floats(allow_nan=True, allow_infinity=True))
#: Any value a ROS parameter can hold (homogeneous arrays), small integers often: a valid but
#: huge n_agents would only be slow to construct.
ROS_VALUES = st.one_of(
    st.booleans(), st.integers(-3, 5), INT64, ROS_FLOATS, st.text(max_size=8),
    st.sampled_from(['lockstep', 'realtime', 'all', '0-2', '1,1', '2-0', 'demo', 'nope',
                     'su_informed', 'disk', 'ids', '/nonexistent/x.yaml']),
    st.lists(st.booleans(), min_size=1, max_size=3), st.lists(INT64, min_size=1, max_size=3),
    st.lists(st.integers(-1, 4), min_size=1, max_size=3),
    st.lists(ROS_FLOATS, min_size=1, max_size=3),
    st.lists(st.text(max_size=4), min_size=1, max_size=3))


@pytest.fixture(scope='module')
def node_scenario(tmp_path_factory) -> Path:
    """Return a small scenario file for the nodes (the demo with a few agents)."""
    data = copy.deepcopy(BASES['demo'])
    data.update(n_agents=NODE_AGENTS, informed={'select': 'random', 'count': 1})
    path = tmp_path_factory.mktemp('node_scenario') / 'small.yaml'
    path.write_text(dump(data))
    return path


@st.composite
def node_parameters(draw, kind: str):
    """Draw one to three parameter overrides of a node kind as ``{name: value}``."""
    names = NODE_PARAMS[kind] + COMMON_NODE_PARAMS + OVERRIDE_PARAMS
    return draw(st.dictionaries(st.sampled_from(names), ROS_VALUES, min_size=1, max_size=3))


def build_node(kind: str, context, overrides: dict, scenario: Path, out: Path):
    """Construct a node of ``kind`` with ``overrides`` on top of the small scenario."""
    from rclpy.parameter import Parameter

    from flock_swarm.nodes.agent import AgentNode
    from flock_swarm.nodes.leader import LeaderNode
    from flock_swarm.nodes.world import WorldNode
    values = {'scenario': str(scenario)}
    if kind == 'world':
        values['out_dir'] = str(out)
    values.update(overrides)
    params = [Parameter(name, value=value) for name, value in values.items()]
    cls = {'world': WorldNode, 'leader': LeaderNode, 'agent': AgentNode}[kind]
    return cls(context=context, parameter_overrides=params)


def assert_builds_or_names_key(kind: str, context, overrides: dict, scenario: Path) -> None:
    """The property for ROS parameters: the node is built, or one line names the parameter.

    ``run_node`` prints that line as ``NODE: error: KEY: reason`` with exit status 2; the
    line is the :class:`ScenarioError`'s message, checked here without the process.
    """
    with tempfile.TemporaryDirectory(prefix='flock_prop_node_') as tmp:
        if isinstance(overrides.get('out_dir'), str):
            # Never a path outside the example's directory ('' would be out/ in the tree).
            overrides = dict(overrides, out_dir=str(
                Path(tmp) / ('od_' + overrides['out_dir'].replace('/', '_'))))
        try:
            node = build_node(kind, context, overrides, scenario, Path(tmp) / 'out')
        except ScenarioError as exc:
            event(f'{kind}: error')
            assert_one_line_error(2, f'{kind}: error: {exc}\n', None, prog=kind,
                                  keys=(*overrides, *NODE_PARAMS[kind], *COMMON_NODE_PARAMS))
            return
        event(f'{kind}: built')
        try:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
        finally:
            node.destroy_node()


@pytest.mark.parametrize('kind, overrides, key', [
    # The world publishes /clock: following it, it never started and logged nothing.
    ('world', {'use_sim_time': True}, 'use_sim_time'),
    ('leader', {'use_sim_time': 'yes'}, 'use_sim_time'),
    ('world', {'pace': -1.0}, 'pace'),
    ('world', {'pace': float('inf')}, 'pace'),
    # TypeError: a list compared with a number, or made into a path.
    ('world', {'start_timeout': [True, False]}, 'start_timeout'),
    ('world', {'out_dir': [2, 2]}, 'out_dir'),
    ('leader', {'scenario': False}, 'scenario'),
    # ValueError: embedded null byte (a NUL in a path, through the Python API).
    ('world', {'out_dir': 'a\x00b'}, 'out_dir'),
    # ValueError: a timer period of NaN (an infinite factor gave a busy 0 ns timer).
    ('agent', {'realtime_factor': float('nan'), 'mode': 'realtime'}, 'realtime_factor'),
    ('agent', {'realtime_factor': float('inf'), 'mode': 'realtime'}, 'realtime_factor'),
    # Issue 24: an infinite timeout was taken (a missing agent then held the world forever).
    ('world', {'step_timeout': float('inf')}, 'step_timeout'),
    ('world', {'start_timeout': float('inf')}, 'start_timeout'),
])
def test_node_parameter_regression(kind, overrides, key, ros_context, node_scenario, tmp_path):
    """Each override once broke a node's construction (or was taken); now it names its key."""
    with pytest.raises(ScenarioError) as err:
        build_node(kind, ros_context, overrides, node_scenario, tmp_path / 'out')
    assert err.value.key == key


@pytest.mark.parametrize('kind, ros_args, key', [
    # rclpy.init raised RCLError: a traceback, exit status 1 (and rcl's own log line).
    ('leader', ['-p', 'foo'], '--ros-args'),
    ('agent', ['-p', 'seed:=[1,'], '--ros-args'),
    ('world', ['-p'], '--ros-args'),
    ('leader', ['--params-file', '/nonexistent/params.yaml'], '--ros-args'),
    ('agent', ['-r', 'foo'], '--ros-args'),
    # Through the whole executable: a value of the wrong type.
    ('agent', ['-p', 'seed:=abc'], 'seed'),
    ('world', ['-p', 'step_timeout:=[1, 2]'], 'step_timeout'),
    # Issue 24: .inf was accepted while .nan was refused.
    ('world', ['-p', 'step_timeout:=.inf'], 'step_timeout'),
])
def test_node_main_bad_arguments(kind, ros_args, key, ros_domain, monkeypatch, capfd,
                                 node_scenario):
    """A node's ``main()``: exit status 2 and one line naming the argument, on stderr alone."""
    import importlib
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_domain))
    main = importlib.import_module(f'flock_swarm.nodes.{kind}').main
    status = main([kind, '--ros-args', '-p', f'scenario:={node_scenario}', *ros_args])
    out, err = capfd.readouterr()
    assert assert_one_line_error(status, err, None, prog=kind, keys=('--ros-args', key)) == key
    assert out == ''


@pytest.mark.parametrize('kind', sorted(NODE_PARAMS))
@settings(derandomize=True, database=None, max_examples=NODE_EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_node_parameters_build_or_name_the_key(kind, ros_context, node_scenario, data):
    """Generated ``parameter_overrides``: the node is built or stops naming the parameter.

    One context (and domain id) serves every example of a node kind: the fixtures are
    deliberately shared across examples, each example destroys its node.
    """
    overrides = data.draw(node_parameters(kind), label='overrides')
    assert_builds_or_names_key(kind, ros_context, overrides, node_scenario)


# --------------------------------------------------------------------------------------------
# Sweep expressions (issue 24): any expression of the language evaluates or is refused, fast

#: Operands that make results grow: big exponents, long lists, large integers.
EXPR_ATOMS = st.sampled_from(['2', '10', '999', '1000', '0.5', '1e300', 'n', '[1]', '[n, 1]',
                              '[[0.0] * 1000]', '10 ** 1000', '-3'])


@st.composite
def expressions(draw, depth: int = 0) -> str:
    """Draw an expression of the sweep language, nested up to four levels."""
    if depth >= 4 or draw(st.integers(0, 3)) == 0:
        return draw(EXPR_ATOMS)
    kind = draw(st.integers(0, 2))
    if kind == 0:
        op = draw(st.sampled_from(['+', '-', '*', '/', '//', '%', '**']))
        return f'({draw(expressions(depth + 1))}) {op} ({draw(expressions(depth + 1))})'
    if kind == 1:
        return f'[{draw(expressions(depth + 1))}, {draw(expressions(depth + 1))}]'
    func = draw(st.sampled_from(['sqrt', 'exp', 'log', 'floor', 'abs', 'round', 'int', 'max']))
    args = [draw(expressions(depth + 1)) for _ in range(2 if func in ('round', 'max') else 1)]
    return f'{func}({", ".join(args)})'


@settings(derandomize=True, database=None, max_examples=300, deadline=2000)
@given(expressions())
def test_expressions_evaluate_or_are_refused_within_the_budget(text):
    """A value within the budget, or one ExpressionError line; never a hang or a traceback."""
    from flock_swarm.study.expr import MAX_INT_BITS, MAX_ITEMS, Expression, ExpressionError
    try:
        value = Expression(text).evaluate({'n': 7})
    except ExpressionError as exc:
        assert '\n' not in one_line(str(exc))
        return

    def check(v):
        if isinstance(v, list):
            return sum(check(item) for item in v)
        assert not isinstance(v, int) or v.bit_length() <= 2 * MAX_INT_BITS
        return 1
    assert check(value) <= MAX_ITEMS


# Launch arguments (launch/swarm_launch.py, decided by flock_swarm.launch_plan)

#: Launch argument texts: numbers, flags, informed selections and override lists, good and bad.
LAUNCH_TEXTS = st.one_of(
    st.text(max_size=10),
    st.sampled_from(['0', '1', '2', '4', '-1', '1e3', 'true', 'false', 'first', 'random',
                     'lockstep', 'realtime', 'duration=1', 'duration=-5; n_agents=3', ';', '=',
                     'protocol.c1=[1, 2]', 'n_agents=abc', 'informed.count=2; n_agents=4',
                     'initial.position_box=[[0, 5], [0, 5]]', 'a.b.c=1', 'duration=']))
#: The arguments drawn (not ``container``: false with a huge n_agents plans a process each).
LAUNCH_KEYS = ('scenario', 'n_agents', 'informed_count', 'informed_select', 'overrides',
               'mode', 'foxglove')


@given(st.dictionaries(st.sampled_from(LAUNCH_KEYS), LAUNCH_TEXTS, max_size=4))
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_launch_arguments_plan_or_name_the_argument(args):
    """Any launch arguments: the processes are planned, or one line names an argument or a
    scenario key (never another exception)."""
    from flock_swarm.launch_plan import swarm_processes
    try:
        specs = swarm_processes(**args)
    except ScenarioError as exc:
        event('launch: error')
        assert '\n' not in str(exc) and exc.key
        return
    event('launch: planned')
    assert [spec.name for spec in specs][:2] == ['world', 'leader']
