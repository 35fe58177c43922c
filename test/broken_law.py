"""A law broken on purpose, for the tests of what an agent does with a non-finite command."""

import math

from flock_swarm.nodes import controller as controller_module


def nan_command_for(monkeypatch, agent: int) -> None:
    """Make the agents' law (in this process) return NaN as ``agent``'s command, every step.

    :param monkeypatch: the test's ``monkeypatch`` fixture (undoes it after the test).
    :param agent: the agent whose command becomes NaN (it must be hosted by the caller).
    """
    real_control = controller_module.group_control

    def broken(law, ids, *args):
        u = real_control(law, ids, *args)
        u[list(ids).index(agent)] = math.nan
        return u

    monkeypatch.setattr(controller_module, 'group_control', broken)
