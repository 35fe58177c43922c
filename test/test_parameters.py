"""The nodes' parameter tables without ROS: reading, checking, and what is a scenario override.

What the nodes make of these through rclpy's parameter services is test_node_parameters.py's;
every node kind against generated parameters is test_properties.py's.
"""

import math

import pytest

from flock_swarm.core.errors import ScenarioError
from flock_swarm.nodes.guard import LIMIT_PARAMS, Limits
from flock_swarm.nodes.parameters import (COMMON_PARAMS, Param, read_table, scenario_overrides,
                                          scenario_parameters)
from flock_swarm.nodes.stepper import SETTING_PARAMS, WorldSettings
from flock_swarm.presets import load, load_mapping


def test_a_parameter_not_given_is_its_default_and_a_given_one_is_typed():
    """The default when absent; a value of the default's type (an integer for a float
    default becomes a float); any other type names the parameter."""
    param = Param('step', 2.0, 'a step')
    assert param.read({}) == 2.0
    assert param.read({'step': 3}) == 3.0 and isinstance(param.read({'step': 3}), float)
    for value, what in ((True, 'a number'), ('x', 'a number'), (math.nan, 'a number')):
        with pytest.raises(ScenarioError) as err:
            param.read({'step': value})
        assert err.value.key == 'step' and err.value.reason.startswith(f'expected {what}')
    with pytest.raises(ScenarioError, match=r"^path: expected a string \(without NUL\)"):
        Param('path', '', 'a path').read({'path': 'a\0b'})
    with pytest.raises(ScenarioError, match='^count: expected an integer, got 1.5$'):
        Param('count', 0, 'a count').read({'count': 1.5})


def test_a_check_refuses_with_its_reason_and_a_free_typed_value_is_the_nodes_to_check():
    """A value failing the check names the parameter with the table's reason (the default
    reason: ``invalid value``); a free-typed parameter takes any value as given."""
    timeout = Param('timeout', 1.0, 'a timeout', lambda v: v > 0, 'must be > 0, got {value!r}')
    with pytest.raises(ScenarioError, match=r'^timeout: must be > 0, got -1\.0$'):
        timeout.read({'timeout': -1})
    every = Param('every', 10, 'a period', lambda v: v >= 1)
    with pytest.raises(ScenarioError, match='^every: invalid value 0$'):
        every.read({'every': 0})
    ids = Param('ids', '', 'ids', free_typed=True)
    assert ids.read({'ids': [3, 1]}) == [3, 1] and ids.read({}) == ''


@pytest.mark.parametrize('given, message', [
    ({'mode': 'fast'}, "mode: must be lockstep or realtime, got 'fast'"),
    ({'realtime_factor': math.inf}, 'realtime_factor: must be finite and > 0, got inf'),
    ({'realtime_factor': 0}, 'realtime_factor: must be finite and > 0, got 0.0'),
    ({'seed': -2}, 'seed: must be -1 (the scenario seed) or >= 0, got -2'),
    ({'scenario': 3}, 'scenario: expected a string (without NUL), got 3'),
    ({'max_abs_accel': math.inf}, 'max_abs_accel: must be a finite number > 0, got inf'),
    ({'max_abs_position': -1.0}, 'max_abs_position: must be a finite number > 0, got -1.0'),
    ({'step_timeout': 0.0}, 'step_timeout: invalid value 0.0'),
    ({'start_timeout': -0.5}, 'start_timeout: invalid value -0.5'),
    ({'marker_every': 0}, 'marker_every: invalid value 0'),
])
def test_the_shared_tables_name_the_invalid_parameter(given, message):
    """The common parameters, the input limits and the world's settings: one line naming
    the parameter, as the nodes print it."""
    with pytest.raises(ScenarioError) as err:
        read_table(COMMON_PARAMS + LIMIT_PARAMS + SETTING_PARAMS, given)
    assert str(err.value) == message


def test_the_tables_give_the_defaults_of_what_they_configure():
    """Read with nothing given, the limits and settings tables give Limits() and
    WorldSettings()."""
    values = read_table(LIMIT_PARAMS + SETTING_PARAMS, {})
    assert Limits.from_parameters(values) == Limits()
    assert WorldSettings.from_parameters(values, True) == WorldSettings()
    given = {'max_abs_velocity': 5, 'staleness': 2.0}
    values = read_table(LIMIT_PARAMS + SETTING_PARAMS, given)
    assert Limits.from_parameters(values) == Limits(velocity=5.0)
    assert WorldSettings.from_parameters(values, False) == WorldSettings(False, staleness=2.0)


def test_every_given_parameter_outside_the_table_is_a_scenario_override():
    """A name of the node's table is never an override, whatever it is; ROS's own and
    ``qos_overrides.*`` neither; a YAML text for a non-string key is parsed."""
    base = load_mapping('demo')
    given = {'scenario': 'demo', 'brand_new': 1, 'protocol.c1': 0.8,
             'use_sim_time': True, 'qos_overrides./clock.publisher.depth': 3,
             'initial.position_box': '[[0, 5], [0, 5]]', 'name': '[not parsed]'}
    table = COMMON_PARAMS + (Param('brand_new', 0, 'a new parameter'),)
    assert scenario_overrides(given, [p.name for p in table], base) == {
        'protocol.c1': 0.8, 'initial.position_box': [[0, 5], [0, 5]], 'name': '[not parsed]'}
    assert 'brand_new' in scenario_overrides(given, [p.name for p in COMMON_PARAMS], base)


def test_the_scenario_parameters_given_back_reproduce_the_scenario():
    """Every key a run uses, given back as overrides, loads the same scenario."""
    sc = load('demo', ['n_agents=5', 'informed.count=2'])
    declared = scenario_parameters(sc)
    assert declared['n_agents'] == 5 and declared['graph.type'] == 'disk'
    again = load('demo', extra=scenario_overrides(declared, ['seed'], load_mapping('demo')),
                 seed=sc.seed)
    assert scenario_parameters(again) == declared
