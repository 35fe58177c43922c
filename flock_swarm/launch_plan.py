"""What ``launch/swarm_launch.py`` starts, for which arguments: importable without ``launch``.

``ros2 launch`` needs a system ROS 2 install (``launch_ros`` imports
``composition_interfaces``, which has no PyPI wheel), so the launch file is a thin layer:
it declares :data:`LAUNCH_ARGUMENTS` and turns each :class:`NodeSpec` of
:func:`swarm_processes` into a ``launch_ros.actions.Node``. The decisions (which
executables, with which parameters, which one ends the launch) live here, where the tests
check them in the virtualenv.
"""

from dataclasses import dataclass, field
from typing import Any

from flock_swarm.contract import agent_name
from flock_swarm.core.errors import ScenarioError, one_line
from flock_swarm.foxglove_ws import DEFAULT_PORT
from flock_swarm.scenario_yaml import parse_value

#: The launch arguments: name, default, description (``ros2 launch ... --show-args``).
LAUNCH_ARGUMENTS = (
    ('scenario', 'demo', 'scenario preset name or path to a YAML file'),
    ('n_agents', '0', 'number of agents (0: the scenario value)'),
    ('informed_count', '0', 'number of informed agents, informed.count (0: the scenario '
     'value; a preset\'s count above a smaller n_agents needs it)'),
    ('informed_select', '', 'how the informed agents are chosen, informed.select (first, '
     'random, ...; empty: the scenario value)'),
    ('overrides', '', 'further scenario overrides, as swarm --set: key=value assignments '
     "separated by ';', e.g. 'duration=10; protocol.c1=0.8'"),
    ('mode', 'lockstep', 'lockstep or realtime'),
    ('out_dir', '', 'output directory of the world (bag/, summary.json); empty: '
     'out/<scenario>_ros'),
    ('container', 'true', 'true: every agent in one `agents` process (the default: a step '
     'costs N odometry deliveries); false: one `agent` process per agent, as on robots'),
    ('foxglove', 'false', 'true: also start foxglove_server, the live view for Foxglove / '
     'Lichtblick'),
    ('foxglove_port', str(DEFAULT_PORT), 'port of foxglove_server (bound to 127.0.0.1)'),
)
_TRUE = ('true', '1', 'yes', 'on')
_FALSE = ('false', '0', 'no', 'off')


@dataclass(frozen=True)
class NodeSpec:
    """One process of the launch: a flock_swarm executable, its node name and parameters."""

    executable: str
    name: str
    parameters: dict = field(default_factory=dict)
    #: The launch ends when this process exits (the world, after its last step).
    ends_launch: bool = False
    #: ``screen`` (progress on the terminal) or ``log``.
    output: str = 'log'


def parse_flag(name: str, text: str) -> bool:
    """Return a launch argument's truth value (``true``/``false``, ``1``/``0`` ...).

    :raises ScenarioError: naming the argument, for anything else.
    """
    value = str(text).strip().lower()
    if value in _TRUE or value in _FALSE:
        return value in _TRUE
    raise ScenarioError(name, f'must be true or false, got {text!r}')


def _integer(name: str, text: str, low: int, high: int) -> int:
    try:
        value = int(str(text).strip())
    except ValueError:
        raise ScenarioError(name, f'must be an integer, got {text!r}') from None
    if not low <= value <= high:
        raise ScenarioError(name, f'must be in [{low}, {high}], got {value}')
    return value


def parse_overrides(text: str) -> dict[str, Any]:
    """Return the ``overrides`` launch argument as ``{dotted.key: value}``.

    :param text: ``key=value`` assignments separated by ``;`` (values as YAML, as ``--set``).
    :raises ScenarioError: naming ``overrides`` for an assignment without ``=`` or key.
    """
    out: dict[str, Any] = {}
    for part in str(text).split(';'):
        part = part.strip()
        if not part:
            continue
        key, eq, value = part.partition('=')
        if not eq or not key.strip():
            raise ScenarioError('overrides', f'expected key=value assignments separated by '
                                f"';', got {one_line(part)!r}")
        try:
            out[key.strip()] = parse_value(value.strip())
        except ScenarioError as exc:
            raise ScenarioError('overrides', f'{key.strip()}: {exc.reason}') from None
    return out


def swarm_processes(scenario: str = 'demo', n_agents: str = '0', mode: str = 'lockstep',
                    out_dir: str = '', container: str = 'true', foxglove: str = 'false',
                    foxglove_port: str = str(DEFAULT_PORT), informed_count: str = '0',
                    informed_select: str = '', overrides: str = '') -> list[NodeSpec]:
    """Return the processes of a launch, for the launch arguments as given (strings).

    :param scenario: preset name or path (validated here, with ``n_agents``).
    :param n_agents: number of agents; ``0`` keeps the scenario's.
    :param mode: ``lockstep`` or ``realtime``.
    :param out_dir: the world's output directory (empty: its default).
    :param container: ``true``: the agents in one ``agents`` process; ``false``: one
        ``agent`` process each.
    :param foxglove: ``true``: add ``foxglove_server``.
    :param foxglove_port: its port.
    :param informed_count: ``informed.count`` (``0``: the scenario's).
    :param informed_select: ``informed.select`` (empty: the scenario's).
    :param overrides: further ``key=value`` overrides separated by ``;``
        (:func:`parse_overrides`); the arguments above win over them.
    :return: world (ends the launch), leader, the agents' process(es), and the live view.
    :raises ScenarioError: for an invalid argument or scenario, naming it.
    """
    from flock_swarm.presets import load
    from flock_swarm.nodes.parameters import parameter_value
    count = _integer('n_agents', n_agents, 0, 10**6)
    informed = _integer('informed_count', informed_count, 0, 10**6)
    if mode not in ('lockstep', 'realtime'):
        raise ScenarioError('mode', f'must be lockstep or realtime, got {mode!r}')
    extra = parse_overrides(overrides)
    for key, value in (('n_agents', count), ('informed.count', informed),
                       ('informed.select', informed_select.strip())):
        if value:
            extra[key] = value
    n = load(scenario, extra=extra or None).n_agents
    # As node parameters: a value no ROS parameter holds (a list of lists) as its YAML text,
    # which the nodes read back as YAML (flock_swarm.nodes.parameters.scenario_overrides).
    common = {'scenario': scenario, 'mode': mode}
    common.update((key, parameter_value(value)) for key, value in extra.items())
    specs = [NodeSpec('world', 'world', dict(common, out_dir=out_dir), ends_launch=True,
                      output='screen'),
             NodeSpec('leader', 'leader', dict(common))]
    if parse_flag('container', container):
        specs.append(NodeSpec('agents', 'agents', dict(common)))
    else:
        specs += [NodeSpec('agent', agent_name(i), dict(common, agent_id=i)) for i in range(n)]
    if parse_flag('foxglove', foxglove):
        port = _integer('foxglove_port', foxglove_port, 0, 65535)
        specs.append(NodeSpec('foxglove_server', 'foxglove_server',
                              dict(common, port=port), output='screen'))
    return specs
