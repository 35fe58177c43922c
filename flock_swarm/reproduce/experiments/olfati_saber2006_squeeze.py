"""Olfati-Saber 2006, Section VIII, Fig. 11: the squeezing manoeuvre of 150 agents through
the gap between two obstacles (Algorithm 3)."""

from flock_swarm.reproduce.experiments.olfati_saber2006_obstacles import (SOURCES,
                                                                          ObstacleExperiment,
                                                                          obstacle_claim,
                                                                          obstacle_setups)


class Squeeze(ObstacleExperiment):
    """Olfati-Saber 2006, Fig. 11."""

    key = 'olfati_saber2006_squeeze'
    title = 'Olfati-Saber 2006, Fig. 11: squeezing between two obstacles'
    claim = (
        'Section VIII, Fig. 11 (150 agents in 2-D, Algorithm 3: alpha + beta + gamma; '
        'd = 7, r = 1.2 d, d\' = 0.6 d, r\' = 1.2 d\'; two obstacles of radius 25 centred '
        'at (150, 30) and (150, 100)): the flock performs a "**squeezing maneuver**": it '
        'passes through the narrow gap between the obstacles and reassembles behind them, '
        'no agent colliding with an obstacle (Algorithm 3\'s beta-agents keep every agent '
        'at least about d\' from the obstacles). The paper shows it as snapshots and gives '
        'no number.' + SOURCES)
    order = 210.0
    #: Through the ROS nodes: the first 30 s, in which the flock meets the obstacles (the
    #: agents nearest them are within r' from about t = 10 s) and starts into the gap.
    ros = ('duration=30',)
    ros_quick = ('duration=2',)
    manoeuvre = 'squeezing through the gap'
    criterion = obstacle_claim('squeezes through the gap')
    setups = obstacle_setups(key)


EXPERIMENT = Squeeze()
