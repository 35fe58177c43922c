"""Beyond the papers: Su 2009 Fig. 2 under message loss (0 to 0.5), its mechanism (a lost
refresh makes the state used a step older: the delay's drag, in part) and its remedy."""

from flock_swarm.reproduce.common import fmt
from flock_swarm.reproduce.experiment import SetUp
from flock_swarm.reproduce.experiments.network_study import NetworkFig2
from flock_swarm.reproduce.mechanisms import held_age
from flock_swarm.reproduce.seeds import column_stats

#: The remedy's study (``config/sweeps/``): ``compensation: predict`` under loss.
REMEDY = 'reproduce_su2009_fig2_loss_predict'


class Fig2Loss(NetworkFig2):
    """Su 2009 Fig. 2, each neighbour's message of a step lost with a probability."""

    key = 'su2009_fig2_loss'
    title = 'Beyond the papers: Su 2009 Fig. 2 under message loss'
    claim = (
        'None: the paper assumes every neighbour\'s state arrives. The question: does Fig. '
        '2\'s "86 of the 100 agents move with the desired velocity" survive losing each '
        'neighbour\'s message of a step with probability 0.05-0.5 (independent Bernoulli '
        'losses; a receiver keeps the last state it got through one lost refresh, '
        '`docs/network.md`; the leader\'s state undisturbed)? The mechanism: a lost refresh '
        'leaves the receiver a state one step old, set against its own current one: the '
        'delay\'s drag on a moving flock (the delay study), with the mean age of the states '
        'used p / (1 + p) steps; a second loss in a row removes the neighbour for a step. The '
        'remedy: `compensation: predict`.')
    order = 1001.0
    preset = 'su2009_fig2'
    overrides = ('network.loss=0.2',)
    axis, unit, spec = 'network.loss', '', 'reproduce_su2009_fig2_loss'
    columns = NetworkFig2.columns + (
        ('mean age of the neighbour states used [s]', 'network_age_mean', '0'),
        ('fraction of messages delivered', 'network_delivered', '1'))

    @property
    def setups(self) -> tuple[SetUp, ...]:
        """Return the losses (the first the ideal network), then the remedy."""
        from flock_swarm.reproduce.seeds import study_runs
        _, runs = study_runs(REMEDY, seeds=1)
        labels = {tuple(str(v) for v in run.point.values()):
                  f'loss {run.point["network.loss"]:g}, predict' for run in runs}
        return (*super().setups, SetUp(REMEDY, labels=labels))

    def mechanism(self, res: dict) -> str:
        """Return, per loss, the mean age of the states used (measured [predicted]) and the
        group's velocity error."""
        from flock_swarm.presets import prepare
        dt = prepare(self.preset)[0].dt
        parts = []
        values = (res.get('seeds') or {}).get('axis_values', {})
        for s in (res.get('seeds') or {}).get('setups', [])[1:]:
            age = column_stats(s, 'network_age_mean')
            loss = values.get(s['label'])
            if age is None or loss is None:
                continue
            parts.append(f'{s["label"]}: {fmt(age["mean"] / dt)} (predicted '
                         f'{fmt(held_age(loss))})')
        if not parts:
            return ''
        return 'mean age of the neighbour states used [steps] - ' + '; '.join(parts)


EXPERIMENT = Fig2Loss()
