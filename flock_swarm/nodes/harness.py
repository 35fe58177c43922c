"""Deprecated: the old name of :mod:`flock_swarm.nodes.swarm_runner`.

The production runner behind ``swarm`` (and the testing API's ``Swarm``) was named
``harness`` until issue 40 renamed it: it is not a test harness. docs/extending.md named
``flock_swarm.nodes.harness.InProcessSwarm`` and ``run_processes`` for users, so importing
this module still works: it warns (``DeprecationWarning``) and gives
:mod:`flock_swarm.nodes.swarm_runner` itself, every name the same object. Import that instead.
"""

import sys
import warnings

from flock_swarm.nodes import swarm_runner

warnings.warn('flock_swarm.nodes.harness is deprecated: import flock_swarm.nodes.swarm_runner',
              DeprecationWarning, stacklevel=2)
sys.modules[__name__] = swarm_runner
