"""A law broken on purpose, for the tests of what an agent does with a non-finite command."""

import math

from flock_swarm.nodes import controller as controller_module


def nan_command_for(monkeypatch, agent: int, after: int = 0) -> None:
    """Make the agents' law (in this process) return NaN as ``agent``'s command, every step
    from the ``after``-th evaluation on (each answered step evaluates it once).

    :param monkeypatch: the test's ``monkeypatch`` fixture (undoes it after the test).
    :param agent: the agent whose command becomes NaN (it must be hosted by the caller).
    :param after: evaluations left sound first.
    """
    real_control = controller_module.group_control
    calls = []

    def broken(law, ids, *args):
        u = real_control(law, ids, *args)
        calls.append(1)
        if len(calls) > after:
            u[list(ids).index(agent)] = math.nan
        return u

    monkeypatch.setattr(controller_module, 'group_control', broken)
