"""The analysis of a recorded run: bag -> run data -> metrics, summary, comparison, files.

The library under ``analyze`` (:mod:`flock_swarm.cli.analyze`), split by concern:

- :mod:`~flock_swarm.analysis.bagrun`: :func:`load_run` reads a bag into :class:`RunData`;
- :mod:`~flock_swarm.analysis.recompute`: :func:`recompute` the metrics as the world does,
  :func:`summarize` them into ``summary.json``;
- :mod:`~flock_swarm.analysis.compare`: :func:`compare_runs`, the one comparison of a run
  with its reference (reference first), and :func:`verify_run` (``--verify``);
- :mod:`~flock_swarm.analysis.analyze_run`: :func:`analyze` writes every output of a run.

::

    from flock_swarm.analysis import analyze, load_run

    run = load_run('out/demo_ros/bag')
    result = analyze(run, 'out/demo_ros/analysis', verify=True)
"""

from flock_swarm.analysis.bagrun import AnalyzeError, load_run, RunData
from flock_swarm.analysis.compare import (compare_runs, Comparison, VERIFY_TOLERANCE,
                                          Verification, verify_run)
from flock_swarm.analysis.analyze_run import Analysis, analyze, default_out, write_csv
from flock_swarm.analysis.recompute import recompute, summarize

__all__ = ['Analysis', 'analyze', 'AnalyzeError', 'compare_runs', 'Comparison', 'default_out',
           'load_run', 'recompute', 'RunData', 'summarize', 'VERIFY_TOLERANCE', 'Verification',
           'verify_run', 'write_csv']
