"""The nodes' parameters: one declarative table per node, the scenario and its overrides.

Each node lists its own parameters once, as a tuple of :class:`Param` (name, default,
description, check, read-only); :data:`COMMON_PARAMS` are every node's. From the table come
the node's parameter set (so a new parameter can never be mistaken for a scenario override),
the reading and checking of the given values (:meth:`Param.read`) and the read-only
declarations (:meth:`NodeParameters.declare`).

Every node reads the same scenario (parameter ``scenario``: a preset name or a path); any
other parameter whose name is a dotted scenario key overrides that single value, e.g.
``ros2 run flock_swarm agent --ros-args -p agent_id:=3 -p scenario:=demo -p protocol.c1:=0.8``.
Every parameter is then declared read-only with the value the node uses, every scenario key
included (:func:`scenario_parameters`), so the parameter services tell the truth about a run.

The given parameters are read through rclpy's public API: the nodes are created with
``automatically_declare_parameters_from_overrides`` (:func:`init_node`), which declares each
given parameter (``-p``, a params file, ``parameter_overrides``), and
:class:`NodeParameters` lists them before declaring its own. The tables and checks import no
rclpy (the world's stepper and the input guard hold theirs).
"""

import array
import copy
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np
import yaml

from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.scenario import Scenario
from flock_swarm.scenario_yaml import parse_yaml
from flock_swarm.presets import load_mapping, prepare

#: rclpy's parameter of every node: the node's ROS clock follows ``/clock`` when true.
USE_SIM_TIME = 'use_sim_time'
#: Parameters every rclpy node has; they are not scenario overrides.
ROS_PARAMS = {USE_SIM_TIME, 'start_type_description_service'}
#: How ``use_sim_time`` reads back on the leader and the agents (they accept either value).
SIM_TIME_DESCRIPTION = (
    'the node\'s ROS clock follows /clock (read at start). The node runs at the same speed '
    'either way: its steps come from the world\'s /clock and odometry stamps, and its timers '
    'run on the steady clock')
#: The largest integer a ROS parameter holds (int64).
INT64_MAX = 2 ** 63 - 1


@dataclass(frozen=True)
class Param:
    """One parameter of a node.

    :ivar name: the parameter's name.
    :ivar default: its value when not given; its type is the parameter's type.
    :ivar description: what it is, shown by ``ros2 param describe``.
    :ivar check: whether a value of the right type is valid (``None``: any is).
    :ivar problem: the reason given for an invalid value, formatted with ``value``.
    :ivar free_typed: takes more than the default's type and the node checks the value
        itself (``agent_ids``: a string of ids and ranges or an integer array).
    :ivar read_only: refuse ``ros2 param set``. Every parameter is read once, at the start,
        so each is read-only: a change is refused with a reason instead of succeeding and
        being ignored (docs/ros.md).
    """

    name: str
    default: Any
    description: str
    check: Callable[[Any], bool] | None = None
    problem: str = 'invalid value {value!r}'
    free_typed: bool = False
    read_only: bool = True

    def read(self, given: Mapping[str, Any]) -> Any:
        """Return the value given for the parameter (or its default), checked.

        :param given: the node's given parameters, ``{name: value}``.
        :raises ScenarioError: naming the parameter when its value is not of the default's
            type (:func:`typed_value`) or fails :attr:`check`.
        """
        if self.name not in given:
            value = self.default
        elif self.free_typed:
            value = given[self.name]
        else:
            value = typed_value(self.name, given[self.name], self.default)
        if self.check is not None and not self.check(value):
            raise ScenarioError(self.name, self.problem.format(value=value))
        return value


#: Every node's parameters (``seed`` reads back the seed of the run: :meth:`load_scenario`).
COMMON_PARAMS = (
    Param('scenario', 'demo', 'scenario preset name or path to a YAML file'),
    Param('mode', 'lockstep', 'lockstep (deterministic, world waits for every agent) or realtime',
          lambda v: v in ('lockstep', 'realtime'), 'must be lockstep or realtime, got {value!r}'),
    Param('realtime_factor', 1.0,
          'realtime mode: simulated seconds per wall second (same for every node)',
          lambda v: math.isfinite(v) and v > 0, 'must be finite and > 0, got {value!r}'),
    Param('seed', -1, 'random seed of the run (given as -1: the scenario seed, and it reads '
          'back as that seed)', lambda v: v >= -1,
          'must be -1 (the scenario seed) or >= 0, got {value!r}'),
    Param('allow_unstable', False, 'run a dt beyond the stability bounds of the scenario '
          "(as sim's --allow-unstable); refused with the bound it violates otherwise"),
)
#: The leader's and the agents' own parameter on the world's end (:func:`follow_world`).
KEEP_RUNNING = Param('keep_running', False, 'keep running after the world announced the end '
                     'of its run on swarm/status')


def read_table(table: Iterable[Param], given: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``{name: value}`` of every parameter of ``table``, read and checked in order.

    :param table: the parameters.
    :param given: the given parameters, ``{name: value}``.
    :raises ScenarioError: naming the first invalid parameter.
    """
    return {param.name: param.read(given) for param in table}


def as_list(value: Any) -> Any:
    """Return a parameter value with its arrays as lists (rclpy gives ``array.array``)."""
    return list(value) if isinstance(value, (list, tuple, array.array, np.ndarray)) else value


def typed_value(name: str, value: Any, default: Any) -> Any:
    """Return ``value`` if it has the type of ``default`` (a float for a float default).

    :raises ScenarioError: naming ``name`` otherwise.
    """
    if isinstance(default, bool):
        ok, what = isinstance(value, bool), 'true or false'
    elif isinstance(default, int):
        ok, what = isinstance(value, int) and not isinstance(value, bool), 'an integer'
    elif isinstance(default, float):
        ok, what = (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and not math.isnan(value)), 'a number'
        value = float(value) if ok else value
    elif isinstance(default, str):
        # No NUL: rcl passes strings as C strings, and paths cannot hold one.
        ok, what = isinstance(value, str) and '\0' not in value, 'a string (without NUL)'
    else:
        return value
    if not ok:
        raise ScenarioError(name, f'expected {what}, got {value!r}')
    return value


def scenario_overrides(given: Mapping[str, Any], own: Iterable[str],
                       base: dict) -> dict[str, Any]:
    """Return the given parameters that override scenario keys (all but the node's own).

    A value a ROS parameter cannot hold (a nested list, an empty list or mapping, null) is
    given as a string of its YAML text (as :func:`scenario_parameters` declares it): a string
    for a key whose value in ``base`` is not a string is read as YAML when that gives such a
    value.

    :param given: the node's given parameters, ``{name: value}``, in the order given.
    :param own: names of the node's own parameters.
    :param base: the scenario file's mapping.
    :return: ``{dotted.key: value}``.
    """
    own = set(own)
    out = {}
    for name, value in given.items():
        if name in own or name in ROS_PARAMS or name.startswith('qos_overrides.'):
            continue
        if isinstance(value, str) and not isinstance(lookup(base, name), str):
            try:
                parsed = parse_yaml(value)
            except yaml.YAMLError:
                parsed = value
            if parsed is None or isinstance(parsed, (list, dict)):
                value = parsed
        out[name] = value
    return out


def lookup(data: dict, dotted: str) -> Any:
    """Return the value of a dotted key in a nested mapping (``None`` when absent)."""
    for part in dotted.split('.'):
        if not isinstance(data, dict):
            return None
        data = data.get(part)
    return data


def parameter_value(value: Any) -> Any:
    """Return a scenario value as a ROS parameter value: scalars and flat arrays as they are
    (numbers of mixed types as floats), anything else as a string of its YAML flow text."""
    def fits(v: Any) -> bool:
        return (isinstance(v, (bool, float)) or (isinstance(v, str) and '\0' not in v)
                or (isinstance(v, int) and -INT64_MAX - 1 <= v <= INT64_MAX))
    if fits(value):
        return value
    if isinstance(value, list) and value and all(fits(v) for v in value):
        kinds = {bool if isinstance(v, bool) else str if isinstance(v, str) else 'number'
                 for v in value}
        if kinds == {'number'} and not all(isinstance(v, int) for v in value):
            return [float(v) for v in value]
        if len(kinds) == 1:
            return value
    text = yaml.safe_dump(value, default_flow_style=True, width=float('inf'))
    return text.removesuffix('\n...\n').strip()


def scenario_parameters(sc: Scenario) -> dict[str, Any]:
    """Return every scenario key a run uses as ``{dotted.key: parameter value}``.

    The keys of the scenario (its file and overrides) and the defaults it was given for the
    ones it left out: protocol gains, ``record_every``, metrics...; nested mappings become
    dotted names (``protocol.c1``). Given back as overrides, they reproduce the scenario.
    """
    data = copy.deepcopy(sc.raw)
    for key, value in (('name', sc.name), ('description', sc.description),
                       ('reference', sc.reference), ('seed', sc.seed),
                       ('record_every', sc.record_every)):
        data.setdefault(key, value)
    for section, defaults in (
            ('graph', {'type': sc.graph_type}),
            ('metrics', {'eta_tolerance': sc.eta_tolerance,
                         'collision_distance': sc.collision_distance}),
            ('protocol', {f.name: getattr(sc.law, f.name) for f in dataclasses.fields(sc.law)
                          if f.init and isinstance(getattr(sc.law, f.name),
                                                   (bool, int, float, str))})):
        if isinstance(data.get(section) or {}, dict):
            data[section] = dict(defaults, **(data.get(section) or {}))
    out: dict[str, Any] = {}

    def flatten(section: dict, prefix: str) -> None:
        for key, value in section.items():
            if isinstance(value, dict) and value:
                flatten(value, f'{prefix}{key}.')
            else:
                out[f'{prefix}{key}'] = parameter_value(value)
    flatten(data, '')
    return out


def init_node(init: Callable[..., None], name: str, kwargs: dict) -> None:
    """Create a node with every given parameter declared, so that :class:`NodeParameters`
    can list them through rclpy's public API.

    :param init: the node's base ``__init__`` (bound: ``super().__init__``).
    :param name: the node's name.
    :param kwargs: the keyword arguments of :class:`rclpy.node.Node` (context, namespace,
        ``parameter_overrides``...).
    :raises ScenarioError: for a given parameter without a type (an empty array): rclpy
        cannot declare it.
    """
    for param in kwargs.get('parameter_overrides') or ():
        if param.value is None:
            raise ScenarioError(param.name, _UNTYPED)
    try:
        init(name, automatically_declare_parameters_from_overrides=True, **kwargs)
    except ValueError as exc:
        # rclpy refuses to declare a value without a type: on the command line, an empty
        # array (-p key:=[]); which key it was, rclpy does not say.
        if isinstance(exc, ScenarioError) or 'PARAMETER_NOT_SET' not in str(exc):
            raise
        raise ScenarioError('--ros-args', f'a parameter {_UNTYPED}') from None


_UNTYPED = ('has no value of any type (an empty array []): give its elements, or its YAML '
            "text as a string ('[]')")


class NodeParameters:
    """A node's parameters: the given values read and checked from the node's table, then
    declared read-only with the values the node uses.

    :ivar given: the given parameters, ``{name: value}``, in the order given.
    :ivar values: ``{name: value}`` of the table's parameters.
    :ivar scenario: the scenario (after :meth:`load_scenario`).
    """

    def __init__(self, node, table: Sequence[Param], sim_time_refused: str | None = None,
                 sim_time_description: str = SIM_TIME_DESCRIPTION) -> None:
        """Read the parameters of ``table`` given to ``node`` (created by :func:`init_node`).

        :param node: the node, before it declared any parameter of its own.
        :param table: its parameters (:data:`COMMON_PARAMS` and its own).
        :param sim_time_refused: the reason ``use_sim_time:=true`` is refused (the world's:
            it publishes ``/clock`` itself); ``None``: accepted.
        :param sim_time_description: how ``use_sim_time`` reads back (``ros2 param describe``).
        :raises ScenarioError: naming the first invalid parameter.
        """
        self.node = node
        self.table = {param.name: param for param in table}
        names = node.list_parameters([], 0).names
        self.given = {param.name: as_list(param.value)
                      for param in node.get_parameters(list(names))
                      if param.name not in ROS_PARAMS}
        # rclpy declared it before us (and only logs a value of the wrong type).
        self.sim_time = typed_value(USE_SIM_TIME, node.get_parameter(USE_SIM_TIME).value, False)
        if self.sim_time and sim_time_refused is not None:
            raise ScenarioError(USE_SIM_TIME, sim_time_refused)
        self.sim_time_description = sim_time_description
        self.values = read_table(table, self.given)
        self.scenario: Scenario | None = None
        #: Parameters the node settles once it knows their value (:meth:`settle`).
        self._settled: set[str] = set()
        self._settling = False

    def __getitem__(self, name: str) -> Any:
        """Return the value of parameter ``name``."""
        return self.values[name]

    def timer_period(self, dt: float) -> float:
        """Return the wall-clock period of a realtime-mode timer for simulation step ``dt``."""
        return dt / self.values['realtime_factor']

    def load_scenario(self) -> Scenario:
        """Load the scenario named by the ``scenario`` parameter, with ``seed`` and the
        given scenario overrides (every given parameter not in the table).

        ``seed`` takes the seed of the run.

        :return: the validated scenario.
        :raises ScenarioError: on any invalid value.
        """
        name, seed = self.values['scenario'], self.values['seed']
        base = load_mapping(name)
        # The one preparation of every front end (sim's too): validation, a plugin law that
        # raises or returns unusable commands, and a dt beyond a stability bound all fail
        # here, in one line, not in a callback of the running node.
        sc, _ = prepare(base, seed=None if seed == -1 else seed,
                        extra=scenario_overrides(self.given, self.table, base),
                        allow_unstable=self.values['allow_unstable'])
        self.values['seed'] = sc.seed
        self.scenario = sc
        return sc

    def declare(self, **in_use: Any) -> None:
        """Declare every parameter read-only with the value the node uses: the table's (with
        ``in_use`` replacing values the node worked out, e.g. ``out_dir``) and every scenario
        key the run uses (:func:`scenario_parameters`), so that ``ros2 param dump`` writes a
        file that reproduces the run. A given parameter that is neither (a section given as
        YAML text, ``qos_overrides.*``) is not left declared.

        :param in_use: values that replace the ones read.
        """
        self.values.update(in_use)
        declared = set()
        for param in self.table.values():
            self._declare(param.name, self.values[param.name], param.description,
                          param.free_typed, param.read_only and param.name not in self._settled)
            declared.add(param.name)
        for key, value in scenario_parameters(self.scenario).items():
            if key not in declared:
                self._declare(key, value, f'scenario key {key} (read at start)')
                declared.add(key)
        for name in self.given:
            if name not in declared:
                self.node.undeclare_parameter(name)
        # Read-only too: `ros2 param set NODE use_sim_time true` is refused with the reason
        # instead of answering "successful" for a clock no timer of the node follows.
        self._declare(USE_SIM_TIME, self.sim_time, self.sim_time_description)

    @property
    def settled(self) -> frozenset[str]:
        """Return the parameters the node settles itself (:meth:`will_settle`)."""
        return frozenset(self._settled)

    def will_settle(self, name: str) -> None:
        """Declare ``name`` (by :meth:`declare`) so that the node can :meth:`settle` it later.

        rclpy offers no public way to change a read-only parameter, so such a parameter is
        declared writable and a set-parameters callback refuses every change the node does not
        make itself: ``ros2 param set`` is refused as for a read-only one.

        :param name: a parameter of the table, before :meth:`declare`.
        """
        if not self._settled:
            self.node.add_on_set_parameters_callback(self._refuse_outside_changes)
        self._settled.add(name)

    def settle(self, name: str, value: Any) -> None:
        """Make parameter ``name`` (see :meth:`will_settle`) read back ``value``: a default the
        node resolves once it knows it (``expect_subscribers`` -1 becomes the number of
        subscribers waited for, known at the start). ``ros2 param set`` stays refused.

        :param name: a parameter of the table.
        :param value: the value in use, of the parameter's type.
        """
        from rclpy.parameter import Parameter
        self.values[name] = value
        self._settling = True
        try:
            result = self.node.set_parameters([Parameter(name, value=value)])[0]
        finally:
            self._settling = False
        if not result.successful:
            self.node.get_logger().warning(f'{name} reads back its given value, not {value!r}: '
                                           f'{result.reason}')

    def _refuse_outside_changes(self, params):
        """Refuse a change of a settled parameter unless the node itself settles it."""
        from rcl_interfaces.msg import SetParametersResult
        for param in params:
            if param.name in self._settled and not self._settling:
                return SetParametersResult(
                    successful=False,
                    reason=f'parameter {param.name!r} cannot be set because it is read-only')
        return SetParametersResult(successful=True)

    def _declare(self, name: str, value: Any, description: str, free_typed: bool = False,
                 read_only: bool = True) -> None:
        """Declare ``name`` with ``value`` (replacing its declaration from the given value)."""
        # Imported here: the tables and checks above are used without rclpy.
        from rcl_interfaces.msg import ParameterDescriptor
        node = self.node
        if node.has_parameter(name):
            node.undeclare_parameter(name)
        # The node's own declaration: the guard of settled parameters lets it through.
        self._settling = True
        try:
            node.declare_parameter(name, value, ParameterDescriptor(
                description=description, read_only=read_only, dynamic_typing=free_typed),
                ignore_override=True)
        finally:
            self._settling = False
