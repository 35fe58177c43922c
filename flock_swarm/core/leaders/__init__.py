"""Leader models: the base class and the built-in models (see :mod:`.base`, :mod:`.models`)."""

from flock_swarm.core.leaders.base import LeaderModel, LeaderState, VirtualLeader

__all__ = ['LeaderModel', 'LeaderState', 'VirtualLeader']
