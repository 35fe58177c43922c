"""Every experiment of the five papers, in the report's order, with its analysis, table rows,
discussion and figure, gathered from the paper modules."""

from flock_swarm.reproduce import jadbabaie2003, os2003, su2009, yu2010, zhou2012

#: The paper modules, in the report's order.
PAPERS = (su2009, os2003, zhou2012, yu2010, jadbabaie2003)
EXPERIMENTS = tuple(exp for paper in PAPERS for exp in paper.EXPERIMENTS)
EXPERIMENT_KEYS = tuple(e.key for e in EXPERIMENTS)
ANALYSES = {k: f for paper in PAPERS for k, f in paper.ANALYSES.items()}
ROWS = {k: rows for paper in PAPERS for k, rows in paper.ROWS.items()}
DISCUSSIONS = {k: f for paper in PAPERS for k, f in paper.DISCUSSIONS.items()}
FIGURES = {k: f for paper in PAPERS for k, f in paper.FIGURES.items()}
