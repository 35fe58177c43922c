"""Olfati-Saber 2006, Section VIII, Fig. 10: 150 agents split around obstacles and rejoin
behind them (Algorithm 3)."""

from flock_swarm.reproduce.experiments.olfati_saber2006_obstacles import (SOURCES,
                                                                          ObstacleExperiment,
                                                                          obstacle_claim,
                                                                          obstacle_setups)


class Rejoin(ObstacleExperiment):
    """Olfati-Saber 2006, Fig. 10."""

    key = 'olfati_saber2006_rejoin'
    title = 'Olfati-Saber 2006, Fig. 10: split around obstacles and rejoin'
    claim = (
        'Section VIII, Fig. 10 (150 agents in 2-D, Algorithm 3: alpha + beta + gamma; '
        'd = 7, r = 1.2 d, d\' = 0.6 d, r\' = 1.2 d\'; six obstacles of radii 10, 4, 2, 5, '
        '5, 3): the flock performs a "**split/rejoin maneuver**": it splits to pass around '
        'the obstacles and rejoins into one flock behind them, no agent colliding with an '
        'obstacle. The paper shows it as snapshots and gives no number.' + SOURCES)
    order = 220.0
    manoeuvre = 'passing the obstacles'
    criterion = obstacle_claim('splits around the obstacles and rejoins')
    setups = obstacle_setups(key)


EXPERIMENT = Rejoin()
