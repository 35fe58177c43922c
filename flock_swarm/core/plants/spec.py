"""The scenario's ``plant:`` section: which plant the agents are and how they are commanded.

``plant: {model: NAME, command: accel|cmd_vel, frame: body|world, ...parameters}``; absent,
the papers' double integrator commanded by accelerations (today's runs, bit for bit).
docs/scenarios.md and docs/plants.md describe it.
"""

from dataclasses import dataclass
from typing import Any

from flock_swarm.core.checks import choice, mapping, only
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.plants.base import Plant
from flock_swarm.core.plants.models import DoubleIntegrator

#: The keys of the ``plant:`` section besides the model's parameters.
PLANT_KEYS = ('model', 'command', 'frame')


@dataclass(frozen=True)
class PlantSpec:
    """The scenario's ``plant:`` section: the model, the command interface and its frame."""

    model: Plant = DoubleIntegrator()
    command: str = 'accel'
    frame: str = 'world'

    @property
    def default(self) -> bool:
        """Whether the agents are the papers' double integrators (today's exact code path)."""
        return self.model.name == 'double_integrator'


def parse_plant(value: Any, dim: int, plant_class) -> PlantSpec:
    """Validate the scenario's ``plant:`` section.

    :param value: the section (``None``: absent, the double integrator).
    :param dim: the scenario's dimension.
    :param plant_class: ``name -> class`` (the registry's lookup, raising one line).
    :return: the spec.
    :raises ScenarioError: naming the first invalid key.
    """
    section = mapping(value, 'plant')
    if not section:
        return PlantSpec()
    model = plant_class(section.get('model', 'double_integrator'))
    if dim not in model.dims:
        raise ScenarioError('plant.model', f'the {model.name} plant needs dim = '
                            f'{" or ".join(map(str, model.dims))}, got {dim}')
    only(section, (*PLANT_KEYS, *model.param_keys()), 'plant.')
    instance = model.from_section(section, 'plant.')
    instance.validate(dim, 'plant.')
    command = choice(section.get('command', model.commands[0]), 'plant.command',
                     model.commands)
    frame = choice(section.get('frame', model.frames[0]), 'plant.frame', model.frames)
    return PlantSpec(instance, command, frame)


def command_interface(sc, override: str) -> str:
    """Return a node's command interface: its parameter ``override`` if set, else the
    scenario's ``plant.command``.

    :param sc: the scenario (a :class:`~flock_swarm.core.scenario.Scenario`).
    :param override: the node's ``command`` parameter (``''``: the scenario's).
    :raises ScenarioError: naming ``command`` when the plant does not take it.
    """
    command = override or sc.plant.command
    if command not in sc.plant.model.commands:
        raise ScenarioError('command', f'the {sc.plant.model.name} plant takes '
                            f'{" or ".join(sc.plant.model.commands)} commands, got {command!r}')
    return command
