"""Flocking laws: the plugin API (:mod:`.base`), its evaluation (:mod:`.evaluation`), and one
module per paper."""

from flock_swarm.core.laws.base import (AgentData, Law, LawContext, LawSetup, ObserverGroup,
                                        StepViolation)
from flock_swarm.core.laws.evaluation import (advance_state, antisymmetry_problem, control,
                                              group_control, group_sums, local_control, pair_sums,
                                              swarm_control)

__all__ = ['AgentData', 'Law', 'LawContext', 'LawSetup', 'ObserverGroup', 'StepViolation',
           'advance_state', 'antisymmetry_problem', 'control', 'group_control', 'group_sums',
           'local_control', 'pair_sums', 'swarm_control']
