"""Parameter studies: the machinery under ``sweep`` and the reproduction's Fig. 3 sweep.

:mod:`~flock_swarm.study.spec` (the spec and its plan of runs), :mod:`~flock_swarm.study.expr`
(derived values), :mod:`~flock_swarm.study.cache` (the resumable cache),
:mod:`~flock_swarm.study.execute` (stacks, backends, progress) and
:mod:`~flock_swarm.study.tables` (tidy and aggregated tables, figures).
"""
