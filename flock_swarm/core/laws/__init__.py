"""Flocking laws: the base class and its evaluation (:mod:`.base`), one module per paper."""

from flock_swarm.core.laws.base import (AgentData, Law, LawContext, LawSetup, ObserverGroup,
                                        StepViolation, advance_state, group_control,
                                        local_control, pair_sums, swarm_control)

__all__ = ['AgentData', 'Law', 'LawContext', 'LawSetup', 'ObserverGroup', 'StepViolation',
           'advance_state', 'group_control', 'local_control', 'pair_sums', 'swarm_control']
