"""Beyond the papers: Su 2009 Fig. 2 under a fixed communication delay (0 to 0.5 s)."""

from flock_swarm.reproduce.experiments.network_study import NetworkFig2


class Fig2Delay(NetworkFig2):
    """Su 2009 Fig. 2, each neighbour's state as old as the delay (``communication`` model)."""

    key = 'su2009_fig2_delay'
    title = 'Beyond the papers: Su 2009 Fig. 2 under a communication delay'
    claim = (
        'None: the paper assumes exact, current neighbour states. The question: does Fig. 2\'s '
        '"86 of the 100 agents move with the desired velocity" survive a delay of 0.02-0.5 s '
        'on every neighbour\'s state (the `communication` delay model, the leader\'s state '
        'to the informed agents undelayed)?')
    order = 1000.0
    preset = 'su2009_fig2'
    overrides = ('network.delay=0.1',)
    axis, unit, spec = 'network.delay', ' s', 'reproduce_su2009_fig2_delay'


EXPERIMENT = Fig2Delay()
