"""What ``launch/swarm_launch.py`` starts, for which arguments: importable without ``launch``.

``ros2 launch`` needs a system ROS 2 install (``launch_ros`` imports
``composition_interfaces``, which has no PyPI wheel), so the launch file is a thin layer:
it declares :data:`LAUNCH_ARGUMENTS` and turns each :class:`NodeSpec` of
:func:`swarm_processes` into a ``launch_ros.actions.Node``. The decisions (which
executables, with which parameters, which one ends the launch) live here, where the tests
check them in the virtualenv.
"""

from dataclasses import dataclass, field

from flock_swarm.core.errors import ScenarioError
from flock_swarm.foxglove_ws import DEFAULT_PORT

#: The launch arguments: name, default, description (``ros2 launch ... --show-args``).
LAUNCH_ARGUMENTS = (
    ('scenario', 'demo', 'scenario preset name or path to a YAML file'),
    ('n_agents', '0', 'number of agents (0: the scenario value)'),
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


def swarm_processes(scenario: str = 'demo', n_agents: str = '0', mode: str = 'lockstep',
                    out_dir: str = '', container: str = 'true', foxglove: str = 'false',
                    foxglove_port: str = str(DEFAULT_PORT)) -> list[NodeSpec]:
    """Return the processes of a launch, for the launch arguments as given (strings).

    :param scenario: preset name or path (validated here, with ``n_agents``).
    :param n_agents: number of agents; ``0`` keeps the scenario's.
    :param mode: ``lockstep`` or ``realtime``.
    :param out_dir: the world's output directory (empty: its default).
    :param container: ``true``: the agents in one ``agents`` process; ``false``: one
        ``agent`` process each.
    :param foxglove: ``true``: add ``foxglove_server``.
    :param foxglove_port: its port.
    :return: world (ends the launch), leader, the agents' process(es), and the live view.
    :raises ScenarioError: for an invalid argument or scenario, naming it.
    """
    from flock_swarm.presets import load
    count = _integer('n_agents', n_agents, 0, 10**6)
    if mode not in ('lockstep', 'realtime'):
        raise ScenarioError('mode', f'must be lockstep or realtime, got {mode!r}')
    common = {'scenario': scenario, 'mode': mode}
    if count > 0:
        common['n_agents'] = count
    n = load(scenario, extra={'n_agents': count} if count > 0 else None).n_agents
    specs = [NodeSpec('world', 'world', dict(common, out_dir=out_dir), ends_launch=True,
                      output='screen'),
             NodeSpec('leader', 'leader', dict(common))]
    if parse_flag('container', container):
        specs.append(NodeSpec('agents', 'agents', dict(common)))
    else:
        specs += [NodeSpec('agent', f'agent_{i}', dict(common, agent_id=i)) for i in range(n)]
    if parse_flag('foxglove', foxglove):
        port = _integer('foxglove_port', foxglove_port, 0, 65535)
        specs.append(NodeSpec('foxglove_server', 'foxglove_server',
                              dict(common, port=port), output='screen'))
    return specs
