"""The public API for writing a law or a leader model in one file (docs/extending.md).

A law subclasses :class:`Law`, a leader model :class:`LeaderModel`; both are frozen
dataclasses whose fields are their parameters. Register the class under its ``name`` in
your package's entry points (groups ``flock_swarm.laws`` and ``flock_swarm.leaders``), and
``sim``, the nodes, ``swarm`` and the reproduction machinery find it like a built-in one.
"""

from flock_swarm.core.checks import require
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.laws.base import AgentData, Law, LawContext
from flock_swarm.core.leaders.base import LeaderModel, LeaderState
from flock_swarm.core.stability import StepViolation, consensus_bounds, pd_dt_max

__all__ = ['AgentData', 'Law', 'LawContext', 'LeaderModel', 'LeaderState', 'ScenarioError',
           'StepViolation', 'consensus_bounds', 'pd_dt_max', 'require']
