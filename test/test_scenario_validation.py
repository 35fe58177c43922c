"""Bad scenario input: one-line errors naming the key, exit status 2, no traceback.

The commands' one-line errors are checked in this process (:func:`run_tool`: the command's
``main(argv)``, its standard error captured), which is what the executable runs; one test per
command still starts the real executable (see run_tool), so that what a shell sees is checked
too.
"""

import copy
import importlib
import subprocess
import sys

import pytest
import yaml

from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.run import check_step
from flock_swarm.core.scenario import parse_scenario, realize
from flock_swarm.scenario_yaml import apply_override, parse_value
from flock_swarm.core.stability import packing_degree, pd_dt_max, pd_stable
from flock_swarm.presets import load, load_mapping, preset_names

BASE = {
    'name': 'base', 'dim': 2, 'n_agents': 5, 'dt': 0.01, 'duration': 1.0, 'seed': 3,
    'protocol': {'name': 'su_informed', 'r': 4.0, 'd': 3.3, 'eps': 0.1, 'h': 0.9,
                 'a': 5.0, 'b': 5.0, 'c1': 0.5, 'c2': 0.5},
    'informed': {'select': 'random', 'count': 2},
    'initial': {'position_box': [[0, 5], [0, 5]], 'velocity_box': [[0, 1], [0, 1]]},
    'leader': {'model': 'constant_velocity', 'position': [0, 0], 'velocity': [1, 1]},
}


def with_value(path: str, value):
    """Return a copy of BASE with one dotted key set (``None`` deletes it)."""
    data = copy.deepcopy(BASE)
    node = data
    parts = path.split('.')
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    if value is None:
        node.pop(parts[-1], None)
    else:
        node[parts[-1]] = value
    return data


def test_base_is_valid():
    sc = parse_scenario(BASE)
    assert sc.steps == 100
    assert sc.law.name == 'su_informed'


@pytest.mark.parametrize('path, value, key', [
    ('protocol.r', -1.0, 'protocol.r'),
    ('protocol.r', 0.0, 'protocol.r'),
    ('protocol.d', 4.0, 'protocol.d'),                  # d >= r
    ('protocol.d', 5.0, 'protocol.d'),
    ('protocol.h', 0.0, 'protocol.h'),                  # h outside (0, 1)
    ('protocol.h', 1.0, 'protocol.h'),
    ('protocol.eps', 0.0, 'protocol.eps'),              # eps <= 0
    ('protocol.eps', -0.1, 'protocol.eps'),
    ('protocol.c1', float('nan'), 'protocol.c1'),       # NaN
    ('protocol.c2', float('inf'), 'protocol.c2'),       # infinite
    ('protocol.a', 'five', 'protocol.a'),               # not a number
    ('protocol.b', 1.0, 'protocol.b'),                  # b < a
    ('protocol.name', 'boids', 'protocol.name'),        # unknown protocol
    ('protocol.name', None, 'protocol.name'),
    ('protocol.gain', 1.0, 'protocol.gain'),            # unknown key
    ('n_agents', 0, 'n_agents'),                        # N < 1
    ('n_agents', 2.5, 'n_agents'),
    ('dim', 4, 'dim'),
    ('dt', 0.0, 'dt'),
    ('dt', float('nan'), 'dt'),
    ('duration', -1.0, 'duration'),
    ('seed', -1, 'seed'),
    ('record_every', 0, 'record_every'),
    ('colour', 'red', 'colour'),                        # unknown top-level key
    ('informed.count', None, 'informed.count'),
    ('informed.fraction', 1.5, 'informed.fraction'),    # fraction outside [0, 1]
    ('informed.select', 'clever', 'informed.select'),
    ('leader.model', 'spiral', 'leader.model'),         # unknown leader model
    ('leader.position', [0, 0, 0], 'leader.position'),  # wrong vector length
    ('leader.velocity', [1], 'leader.velocity'),
    ('leader.velocity', [1, float('nan')], 'leader.velocity[1]'),
    ('initial.position_box', [[0, 5]], 'initial.position_box'),
    ('initial.position_box', [[5, 0], [0, 5]], 'initial.position_box[0]'),
    ('initial.velocity_box', None, 'initial.velocity_box'),
    ('graph.type', 'ring', 'graph.type'),
    ('metrics.eta_tolerance', 0.0, 'metrics.eta_tolerance'),
])
def test_invalid_value_names_the_key(path, value, key):
    data = with_value(path, value)
    if path == 'informed.fraction':
        del data['informed']['count']
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert err.value.key == key
    assert '\n' not in str(err.value)


@pytest.mark.parametrize('section, key', [
    ({'name': 'zhou_pseudo_leader', 'w': -1.0}, 'protocol.w'),
    ({'name': 'yu_pinning_observer', 'b': 0.5}, 'protocol.b'),
    ({'name': 'os2003_sink', 'delta': 1.5}, 'protocol.delta'),
    ({'name': 'os2003_sink', 'k': 1.5}, 'protocol.k'),
    ({'name': 'jadbabaie_leader', 'speed': 0.0}, 'protocol.speed'),
])
def test_invalid_law_parameters(section, key):
    data = with_value('protocol', section)
    data['informed'] = {'select': 'all'}
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert err.value.key == key


@pytest.mark.parametrize('metrics, key, reason', [
    ({'headline': 'com_position_error'}, 'metrics.headline',
     "expected a non-empty list of summary keys (one or more of: eta, "),
    ({'headline': []}, 'metrics.headline', 'expected a non-empty list'),
    ({'headline': {'eta': 1}}, 'metrics.headline', 'expected a non-empty list'),
    ({'headline': ['eta', 'com_error']}, 'metrics.headline[1]',
     "'com_error' is not a summary key (expected one of: eta, velocity_mismatch_max, "
     'com_position_error, com_velocity_error, min_pair_distance, collisions, '
     'components_final, network_delivered, network_age_mean, network_age_max, '
     'obstacle_clearance_min, obstacle_penetrations, obstacle_collisions)'),
    ({'headline': ['seed']}, 'metrics.headline[0]',
     "'seed' is a summary key that does not measure the run"),
    ({'headline': [0.5]}, 'metrics.headline[0]', 'expected a summary key'),
    ({'headline': [['eta']]}, 'metrics.headline[0]', 'expected a summary key'),
    ({'headline': ['eta', 'eta']}, 'metrics.headline[1]', 'eta is named twice'),
    ({'headline': ['x' * 10 ** 6]}, 'metrics.headline[0]', "'xxxxxxxx"),
    ({'claim': 'Su 2009 Fig. 6:\n-> 0'}, 'metrics.claim', 'must be one line'),
    ({'claim': 'a\u2028b'}, 'metrics.claim', 'must be one line'),
    ({'claim': 'x' * 101}, 'metrics.claim', 'at most 100 characters'),
    ({'claim': ['Fig. 6']}, 'metrics.claim', 'expected text'),
    ({'claim': float('nan')}, 'metrics.claim', 'expected text'),
])
def test_a_bad_headline_names_its_key(metrics, key, reason):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(with_value('metrics', metrics))
    assert err.value.key == key
    assert reason in err.value.reason
    # One short line, whatever the value held (the list of the measures a headline may name
    # is in it).
    assert '\n' not in str(err.value) and len(str(err.value)) < 400


def test_the_headline_defaults_to_eta_and_the_velocity_mismatch():
    sc = parse_scenario(BASE)
    assert sc.headline.keys == ('eta', 'velocity_mismatch_max') and sc.headline.claim == ''
    sc = parse_scenario(with_value('metrics', {
        'eta_tolerance': 0.2, 'headline': ['com_position_error', 'eta'],
        'claim': 'Su 2009 Fig. 6: -> 0'}))
    assert sc.headline.keys == ('com_position_error', 'eta')
    assert sc.headline.claim == 'Su 2009 Fig. 6: -> 0' and sc.eta_tolerance == 0.2
    assert sc.raw['metrics']['headline'] == ['com_position_error', 'eta']


def test_lorenz_needs_three_dimensions():
    data = with_value('leader', {'model': 'lorenz', 'position': [0, 0], 'velocity': [1, 1]})
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert err.value.key == 'dim'


def test_jadbabaie_is_planar():
    data = with_value('dim', 3)
    data['protocol'] = {'name': 'jadbabaie_leader'}
    data['initial'] = {'position_box': [[0, 1]] * 3, 'velocity_box': [[0, 1]] * 3}
    data['leader'] = {'model': 'constant_velocity', 'position': [0, 0, 0],
                      'velocity': [1, 0, 0]}
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert err.value.key == 'dim'


def test_informed_ids_out_of_range_and_duplicates():
    with pytest.raises(ScenarioError) as err:
        parse_scenario(with_value('informed', {'select': 'ids', 'ids': [0, 7]}))
    assert err.value.key == 'informed.ids[1]'
    with pytest.raises(ScenarioError) as err:
        parse_scenario(with_value('informed', {'select': 'ids', 'ids': [1, 1]}))
    assert err.value.key == 'informed.ids'


def test_fixed_graph_must_be_symmetric():
    adj = [[0, 1, 0, 0, 0]] + [[0] * 5 for _ in range(4)]
    with pytest.raises(ScenarioError) as err:
        parse_scenario(with_value('graph', {'type': 'fixed', 'adjacency': adj}))
    assert err.value.key == 'graph.adjacency'


def test_observers_only_for_yu():
    data = with_value('observers', [{'ids': [0], 'H': [[1, 0]], 'H_tilde': [[1, 0]],
                                     'D': [[1], [0]], 'D_tilde': [[1], [0]]}])
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert err.value.key == 'observers'


def test_override_sets_nested_values_and_is_validated():
    data = apply_override(BASE, 'protocol.c1=0.8')
    assert parse_scenario(data).law.c1 == 0.8
    assert BASE['protocol']['c1'] == 0.5  # the input is not modified
    data = apply_override(BASE, 'initial.position_box=[[0, 1], [0, 1]]')
    assert parse_scenario(data).position_box.tolist() == [[0, 1], [0, 1]]
    with pytest.raises(ScenarioError) as err:
        apply_override(BASE, 'protocol.c1')
    assert err.value.key == '--set'
    with pytest.raises(ScenarioError) as err:
        apply_override(BASE, 'dim.x=1')
    assert err.value.key == 'dim'


def test_realize_is_deterministic_per_seed():
    a, b = realize(parse_scenario(BASE)), realize(parse_scenario(BASE))
    assert (a.q0 == b.q0).all() and (a.p0 == b.p0).all()
    assert a.informed_ids == b.informed_ids and len(a.informed_ids) == 2
    other = realize(parse_scenario(with_value('seed', 4)))
    assert not (other.q0 == a.q0).all()


@pytest.mark.parametrize('name', preset_names())
def test_every_preset_is_valid_and_stable(name):
    sc = load(name)
    assert sc.name == name
    assert check_step(sc, realize(sc)) == []
    assert load_mapping(name).get('reference'), 'every preset cites its source'


@pytest.mark.parametrize('name', preset_names())
def test_every_preset_names_the_metrics_that_matter_for_it(name):
    """The paper's statistic (docs/reproduction.md) leads; a paper's preset says its claim."""
    metrics = load_mapping(name)['metrics']
    assert metrics['headline'] == list(load(name).headline.keys)
    if name != 'demo':
        assert load(name).headline.claim.startswith(load_mapping(name)['reference'].split(',')[0])


@pytest.mark.parametrize('name, keys', [
    ('su2009_fig6', ('com_position_error', 'com_velocity_error')),
    ('su2009_fig5', ('com_position_error', 'com_velocity_error')),
    ('su2009_fig2', ('eta', 'components_final')),
    ('os2003_sink', ('components_final', 'collisions')),
])
def test_a_papers_preset_leads_with_its_claims_statistic(name, keys):
    assert load(name).headline.keys == keys


def test_presets_cover_every_paper_experiment():
    expected = {'demo', 'su2009_fig2', 'su2009_fig3', 'su2009_fig5', 'su2009_fig6',
                'su2009_fig7', 'os2003_sink', 'zhou2012_sec51', 'zhou2012_sec52',
                'yu2010_sec41', 'jadbabaie2003_leader'}
    assert expected <= set(preset_names())


def test_zhou_step_too_large_is_flagged_with_the_bound():
    sc = load('zhou2012_sec51', ['dt=0.01'])
    violations = check_step(sc, realize(sc))
    assert violations and violations[0].part == 'velocity coupling'
    # |lambda_min(70 B)| bounds the explicit coupling: dt < 2 / |lambda_min|.
    assert 0.001 < violations[0].dt_max < 0.01
    assert 'exceeds the stability bound' in violations[0].message(0.01)


@pytest.mark.parametrize('kp, kv', [(0.5, 0.5), (1.0, 2.0), (0.1, 5.0), (4.0, 1.0)])
def test_pd_bound_matches_jury_criterion(kp, kv):
    # The zero-order-hold map has det = 1 - kv dt + kp dt^2 / 2 and
    # trace = 2 - kv dt - kp dt^2 / 2; Jury: det < 1 <=> dt < 2 kv / kp, and
    # 1 + det + trace > 0 <=> dt < 2 / kv (1 + det > |trace| holds for every dt > 0).
    bound = min(2.0 * kv / kp, 2.0 / kv)
    assert pd_dt_max(kp, kv) == pytest.approx(bound, rel=1e-6)
    assert pd_stable(kp, kv, 0.99 * bound)
    assert not pd_stable(kp, kv, 1.01 * bound)


def test_undamped_zero_order_hold_is_never_stable():
    # det = 1 + kp dt^2 / 2 > 1 for kv = 0.
    assert not pd_stable(1.0, 0.0, 1e-3)


def test_packing_degree():
    # Agents at least 2 apart within radius 2 of a point in the plane: the area bound
    # ((2 + 1) / 1)^2 - 1 = 8 >= 6, the hexagonal kissing number.
    assert packing_degree(2.0, 2.0, 2) == 8
    assert packing_degree(2.0, 2.0, 3) == 26


# The tests that start a command as a real process (``python -m flock_swarm.cli.TOOL``), one
# per command: test_an_empty_out_is_refused (sim, swarm, sweep, analyze, reproduce) and
# test_tools_bad_arguments_are_one_line_exit_2 (replay); the others call its ``main(argv)``
# in this process (run_tool).


def run_tool(tool: str, args, capsys, real: bool = False) -> subprocess.CompletedProcess:
    """Run command ``tool`` (``sim``, ``swarm``...) with ``args``; return its exit status and
    standard error as :func:`subprocess.run` would.

    :param capsys: the test's capture of this process's output.
    :param real: start the executable as a process instead of calling its ``main(argv)`` in
        this process (an exit by ``SystemExit``, argparse's, gives its code).
    """
    if real:
        return subprocess.run([sys.executable, '-m', f'flock_swarm.cli.{tool}', *args],
                              capture_output=True, text=True, timeout=120)
    capsys.readouterr()
    main = importlib.import_module(f'flock_swarm.cli.{tool}').main
    try:
        status = main(list(args))
    except SystemExit as end:
        status = end.code
    out = capsys.readouterr()
    return subprocess.CompletedProcess([tool, *args], status, out.out, out.err)


def run_sim(capsys, *args):
    """Run ``sim`` with ``args`` in this process (:func:`run_tool`)."""
    return run_tool('sim', args, capsys)


@pytest.mark.parametrize('args, key', [
    (['demo', '--set', 'protocol.r=-1'], 'protocol.r'),
    (['demo', '--set', 'protocol.h=1.5'], 'protocol.h'),
    (['demo', '--set', 'informed.count=99'], 'informed.count'),
    (['demo', '--set', 'n_agents=0'], 'n_agents'),
    (['demo', '--set', 'leader.model=warp'], 'leader.model'),
    (['demo', '--set', 'protocol.c1=.nan'], 'protocol.c1'),
    (['demo', '--set', 'nonsense'], '--set'),
    (['no_such_preset'], 'scenario'),
    (['zhou2012_sec51', '--set', 'dt=0.01'], 'dt'),
    (['su2009_fig6', '--set', 'metrics.headline=[eta, com]'], 'metrics.headline[1]'),
    (['su2009_fig6', '--set', 'metrics.claim=[1, 2]'], 'metrics.claim'),
])
def test_cli_bad_input_is_one_line_exit_2(args, key, tmp_path, capsys):
    res = run_sim(capsys, *args, '--out', str(tmp_path / 'o'))
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith(f'sim: error: {key}')
    assert 'Traceback' not in res.stderr
    assert not (tmp_path / 'o' / 'summary.json').exists()


def test_cli_invalid_yaml_file(tmp_path, capsys):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('dim: [2\n')
    res = run_sim(capsys, str(bad), '--out', str(tmp_path / 'o'))
    assert res.returncode == 2
    assert res.stderr.startswith('sim: error: scenario:') and 'invalid YAML' in res.stderr


def test_cli_unknown_key_in_file(tmp_path, capsys):
    data = dict(BASE, colour='red')
    path = tmp_path / 'extra.yaml'
    path.write_text(yaml.safe_dump(data))
    res = run_sim(capsys, str(path), '--out', str(tmp_path / 'o'))
    assert res.returncode == 2
    assert res.stderr.startswith('sim: error: colour: unknown key')


def test_cli_unwritable_output(tmp_path, capsys):
    blocker = tmp_path / 'file'
    blocker.write_text('not a directory')
    res = run_sim(capsys, 'demo', '--out', str(blocker / 'sub'))
    assert res.returncode == 2
    assert res.stderr.startswith('sim: error: --out:')
    assert len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize('text, value', [('1e-3', 0.001), ('5E-4', 0.0005), ('1.0e-3', 0.001),
                                         ('-2e+1', -20.0), ('0.001', 0.001)])
def test_exponents_without_a_dot_are_numbers(text, value):
    assert parse_value(text) == value


def test_exponent_override_reaches_the_scenario():
    assert load('demo', ['dt=1e-3']).dt == 0.001


def test_exponents_in_files_are_numbers(tmp_path):
    path = tmp_path / 'exp.yaml'
    path.write_text(yaml.safe_dump(BASE).replace('dt: 0.01', 'dt: 1e-2'))
    assert load(str(path)).dt == 0.01


@pytest.mark.parametrize('tool, args, start', [
    ('swarm', ['demo', '--domain-id', 'x'], "swarm: error: --domain-id: invalid int value: 'x'"),
    ('swarm', ['demo', '--mode', 'warp'], 'swarm: error: --mode: invalid choice'),
    ('swarm', ['demo', '--container'], 'swarm: error: --container: goes with --processes'),
    ('swarm', [], 'swarm: error: scenario: required'),
    ('swarm', ['demo', '--start-timeout', '-1'], 'swarm: error: --start-timeout: must be'),
    ('swarm', ['demo', '--start-timeout', 'nan'], 'swarm: error: --start-timeout: must be'),
    ('swarm', ['demo', '--step-timeout', '0'], 'swarm: error: --step-timeout: must be'),
    ('swarm', ['demo', '--step-timeout', 'nan'], 'swarm: error: --step-timeout: must be'),
    ('analyze', ['bag', '--record-every', '0'], 'analyze: error: --record-every'),
    ('replay', ['bag', '--bogus'], 'replay: error: --bogus: unrecognized argument(s)'),
    ('sweep', ['su2009_fig3', '--jobs', '0'], 'sweep: error: --jobs: must be >= 1'),
    ('sweep', ['su2009_fig3', '--seeds', 'x'], "sweep: error: --seeds: invalid int value: 'x'"),
    ('sweep', ['nope'], "sweep: error: spec: unknown sweeps preset 'nope'"),
])
def test_tools_bad_arguments_are_one_line_exit_2(tool, args, start, capsys):
    res = run_tool(tool, args, capsys, real=tool == 'replay')
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith(start), res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr


# --------------------------------------------------------------------------------------------
# Issue 24: bounded inputs, no silent acceptance

#: A "billion laughs": nine levels of ten aliases, 10**9 strings from a few hundred bytes.
LAUGHS = 'l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]\n' + ''.join(
    f'l{k}: &l{k} [{", ".join([f"*l{k - 1}"] * 10)}]\n' for k in range(1, 9))


def billion_laughs(field: str) -> str:
    """Return a scenario file (demo's keys) whose ``field`` is the last level of laughs."""
    lines = yaml.safe_dump(load_mapping('demo'), default_flow_style=True, width=10 ** 6)
    return f'{LAUGHS}scenario_keys: {lines}{field}: *l8\n'


@pytest.mark.parametrize('field', ['description', 'dt'])
def test_yaml_aliases_expanding_too_far_are_one_line(field, tmp_path, capsys):
    path = tmp_path / 'laughs.yaml'
    path.write_text(billion_laughs(field))
    res = run_sim(capsys, str(path), '--out', str(tmp_path / 'o'))
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith(f'sim: error: scenario: {path}: invalid YAML at line 2: '
                                 'aliases would expand the document by ')
    assert len(res.stderr.strip().splitlines()) == 1 and 'MemoryError' not in res.stderr


def test_yaml_aliases_are_bounded_in_set_values_too():
    value = '[' + ', '.join(f'&l{k} [' + ', '.join([f'*l{k - 1}' if k else '1'] * 10) + ']'
                            for k in range(9)) + ']'
    with pytest.raises(ScenarioError, match=r'^--set: cannot parse value .*aliases would '
                       r'expand the document by \d+ nodes \(at most 10000\); refused$'):
        apply_override({}, f'description={value}')


def test_a_few_small_aliases_still_read():
    data = parse_value('{a: &box [[0.0, 5.0], [0.0, 5.0]], b: *box}')
    assert data == {'a': [[0.0, 5.0], [0.0, 5.0]], 'b': [[0.0, 5.0], [0.0, 5.0]]}


def test_a_node_that_contains_itself_is_refused():
    with pytest.raises(ScenarioError, match='an alias refers to a node that contains it'):
        parse_value('&a [1, *a]')


def test_duplicate_yaml_keys_are_refused_with_their_line(tmp_path, capsys):
    path = tmp_path / 'twice.yaml'
    path.write_text(yaml.safe_dump(BASE) + 'dt: 0.02\n')
    res = run_sim(capsys, str(path), '--out', str(tmp_path / 'o'))
    assert res.returncode == 2
    assert res.stderr.strip() == (f"sim: error: scenario: {path}: invalid YAML at line "
                                  f"{len(path.read_text().splitlines())}: duplicate key 'dt' "
                                  '(a key may be given once)')
    with pytest.raises(ScenarioError, match="duplicate key 'x'"):
        parse_value('{x: 1, x: 2}')
    # A key merged with << may be overridden: that is what YAML's merge means.
    assert parse_value('{base: &b {x: 1}, c: {<<: *b, x: 2}}')['c'] == {'x': 2}


def test_huge_values_in_errors_are_cut_to_one_readable_line():
    data = with_value('description', list(range(300_000)))
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert len(str(err.value)) < 500 and str(err.value).startswith('description: expected')
    cut = ScenarioError('description', 'got ' + repr(list(range(300_000))))
    assert len(str(cut)) <= 420 and str(cut).endswith(' characters in all)')


@pytest.mark.parametrize('seed, ok', [(0, True), (2 ** 63 - 1, True), (2 ** 63, False),
                                      (10 ** 30, False), (-1, False)])
def test_one_seed_range_for_every_front_end(seed, ok):
    data = with_value('seed', seed)
    if ok:
        assert parse_scenario(data).seed == seed
    else:
        with pytest.raises(ScenarioError, match='^seed: must be'):
            parse_scenario(data)


@pytest.mark.parametrize('tool', ['sim', 'swarm'])
def test_a_seed_beyond_int64_is_one_line_in_sim_and_swarm(tool, tmp_path, capsys):
    res = run_tool(tool, ['demo', '--seed', str(2 ** 64), '--out', str(tmp_path / 'o')], capsys)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == (f'{tool}: error: seed: must be <= 2**63 - 1 (a ROS int64 '
                                  f'parameter), got {2 ** 64}')


@pytest.mark.parametrize('informed, key, other', [
    ({'select': 'ids', 'ids': [0, 1], 'count': 5}, 'informed.count', 'select: ids'),
    ({'select': 'all', 'count': 3}, 'informed.count', 'select: all'),
    ({'select': 'first', 'fraction': 0.5, 'ids': [1, 2]}, 'informed.ids', 'select: first'),
    ({'select': 'pseudo_leaders', 'fraction': 0.5}, 'informed.fraction',
     'select: pseudo_leaders'),
])
def test_informed_keys_the_selection_ignores_are_refused(informed, key, other):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(with_value('informed', informed))
    assert err.value.key == key and f'not used by informed.{other}' in err.value.reason


def test_null_removes_an_informed_key():
    sc = load('demo', ['informed.select=all', 'informed.count=null'])
    assert sc.informed.select == 'all' and 'count' not in sc.raw['informed']


@pytest.mark.parametrize('given, box', [('positions', 'position_box'),
                                        ('velocities', 'velocity_box')])
def test_explicit_initial_state_and_its_box_are_refused_together(given, box):
    data = with_value(f'initial.{given}', [[0.0, 0.0]] * 5)
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data)
    assert err.value.key == f'initial.{box}' and f'initial.{given}' in err.value.reason


def test_a_scenario_path_that_is_a_directory_says_so(tmp_path, capsys):
    (tmp_path / 'dir.yaml').mkdir()
    res = run_sim(capsys, str(tmp_path / 'dir.yaml'))
    assert res.returncode == 2
    assert res.stderr.strip() == (f'sim: error: scenario: {tmp_path / "dir.yaml"} is a '
                                  'directory, not a YAML file')


@pytest.mark.parametrize('tool, args', [('sim', ['demo']), ('swarm', ['demo']),
                                        ('sweep', ['su2009_fig3']), ('analyze', ['bag']),
                                        ('reproduce', [])])
def test_an_empty_out_is_refused(tool, args, tmp_path):
    res = subprocess.run([sys.executable, '-m', f'flock_swarm.cli.{tool}', *args, '--out', ''],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert '--out: must name a directory, got an empty path' in res.stderr
    assert 'Traceback' not in res.stderr and list(tmp_path.iterdir()) == []


def test_a_run_of_more_steps_than_the_bound_is_refused_at_once(tmp_path, capsys):
    """``duration=2147483000 dt=1e-9`` (2e18 steps) was accepted and hung."""
    res = run_sim(capsys, 'demo', '--set', 'duration=2147483000', '--set', 'dt=1e-9',
                  '--allow-unstable', '--out', str(tmp_path / 'o'))
    assert res.returncode == 2
    assert res.stderr == ('sim: error: duration: 2.14748e+09 s in steps of dt = 1e-09 s is '
                          '2.15e+18 steps: at most 1e+08 a run (a longer dt or a shorter '
                          'duration)\n')
    assert not (tmp_path / 'o').exists()


def test_a_million_agents_in_the_default_box_are_refused_at_once(tmp_path, capsys):
    """``n_agents=1000000`` in the preset's box (every agent within reach of most): no output
    for 60 s and SIGTERM ignored before; now one line naming ``n_agents`` and the pairs."""
    res = run_sim(capsys, 'demo', '--set', 'n_agents=1000000', '--out', str(tmp_path / 'o'))
    assert res.returncode == 2
    assert res.stderr == ('sim: error: n_agents: 1000000 agents interact in about 5.3e+10 '
                          'pairs at the start (radius 4 m): at most 1e+07 a step; spread them '
                          'out (initial.position_box) or take fewer\n')


def test_many_agents_spread_out_are_not_refused():
    """The bound is on the pairs, not on the agents: 100,000 agents 300 m apart pass."""
    from flock_swarm.presets import check_pairs, initial_pairs
    sc = parse_scenario(with_value('n_agents', 100_000) | {
        'initial': {'position_box': [[0, 1e5], [0, 1e5]], 'velocity_box': [[0, 1], [0, 1]]}})
    real = realize(sc)
    assert initial_pairs(sc, real) < 1000
    check_pairs(sc, real)


def test_a_device_given_as_the_scenario_is_read_not_called_missing(tmp_path, capsys):
    """``sim /dev/null`` said 'no such file'; it is read, as an empty file."""
    res = run_sim(capsys, '/dev/null', '--out', str(tmp_path / 'o'))
    assert res.returncode == 2
    assert res.stderr == ('sim: error: scenario: /dev/null: empty (no YAML document); a '
                          'scenario is a mapping of keys such as n_agents and protocol\n')
