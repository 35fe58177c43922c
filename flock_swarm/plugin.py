"""The public API for writing a law, a leader model or a plant in one file (docs/extending.md).

A law subclasses :class:`Law`, a leader model :class:`LeaderModel`, a plant :class:`Plant`
(docs/plants.md); all are frozen dataclasses whose fields are their parameters. Register the
class under its ``name`` in your package's entry points (groups ``flock_swarm.laws``,
``flock_swarm.leaders`` and ``flock_swarm.plants``), and ``sim``, the nodes, ``swarm`` and
the reproduction machinery find it like a built-in one.

Every type the hooks' signatures mention is here: a law's hooks receive a
:class:`LawContext` (``validate``) or a :class:`LawSetup` (``agent_data``, ``step_bounds``,
with its :class:`ObserverGroup` items), never the whole scenario; ``combine`` (with the
time ``t``) and ``state_rate`` (with the neighbour sums ``s`` and ``t``) receive a
:class:`LeaderState` and :class:`AgentData`; ``step_bounds``
returns :class:`StepViolation` items. A leader model's hooks receive plain values (the
dimension, the section's key prefix, states as arrays). The package ships ``py.typed``.
"""

from flock_swarm.core.checks import require
from flock_swarm.core.errors import PluginError, ScenarioError
from flock_swarm.core.laws.base import (AgentData, Law, LawContext, LawSetup, ObserverGroup,
                                        StepViolation)
from flock_swarm.core.leaders.base import LeaderModel, LeaderState, VelocityField
from flock_swarm.core.plants.base import Plant
from flock_swarm.core.stability import consensus_bounds, pd_dt_max

__all__ = ['AgentData', 'Law', 'LawContext', 'LawSetup', 'LeaderModel', 'LeaderState',
           'ObserverGroup', 'Plant', 'PluginError', 'ScenarioError', 'StepViolation',
           'VelocityField', 'consensus_bounds', 'pd_dt_max', 'require']
