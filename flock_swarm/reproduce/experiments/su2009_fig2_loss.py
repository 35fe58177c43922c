"""Beyond the papers: Su 2009 Fig. 2 under message loss (0 to 0.5)."""

from flock_swarm.reproduce.experiments.network_study import NetworkFig2


class Fig2Loss(NetworkFig2):
    """Su 2009 Fig. 2, each neighbour's message of a step lost with a probability."""

    key = 'su2009_fig2_loss'
    title = 'Beyond the papers: Su 2009 Fig. 2 under message loss'
    claim = (
        'None: the paper assumes every neighbour\'s state arrives. The question: does Fig. '
        '2\'s "86 of the 100 agents move with the desired velocity" survive losing each '
        'neighbour\'s message of a step with probability 0.05-0.5 (independent Bernoulli '
        'losses; a receiver keeps the last state it got through one lost refresh, '
        '`docs/network.md`; the leader\'s state undisturbed)?')
    order = 1001.0
    preset = 'su2009_fig2'
    overrides = ('network.loss=0.2',)
    axis, unit, spec = 'network.loss', '', 'reproduce_su2009_fig2_loss'


EXPERIMENT = Fig2Loss()
