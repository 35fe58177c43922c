"""Beyond the papers: Su 2009 Fig. 2 under a fixed communication delay (0 to 0.5 s), its
mechanism (the drag of stale neighbour positions on a moving flock) and its remedies."""

from functools import lru_cache

from flock_swarm.reproduce.common import fmt
from flock_swarm.reproduce.experiment import SetUp
from flock_swarm.reproduce.experiments.network_study import NetworkFig2
from flock_swarm.reproduce.mechanisms import DRAG_AGENTS, DRAG_SPEED, delay_drag

#: The remedies' studies (``config/sweeps/``): the ``input`` delay model and
#: ``compensation: predict`` at one and five steps of delay.
REMEDIES = ('reproduce_su2009_fig2_delay_remedies', 'reproduce_su2009_fig2_delay_input_predict')
#: The delays [s] whose drag the summary measures beside its prediction.
DRAG_DELAYS = (0.02, 0.1)


@lru_cache(maxsize=None)
def _drag(delay: float, compensation: str) -> dict:
    return delay_drag(delay, compensation)


def remedy_label(point: dict) -> str:
    """Return ``delay 0.02 s, input + predict`` for a remedy's point."""
    model = point.get('network.model', 'input')
    compensation = point.get('network.compensation', 'predict')
    parts = [model] + ([compensation] if compensation != 'none' else [])
    return f'delay {point["network.delay"]:g} s, {" + ".join(parts)}'


class Fig2Delay(NetworkFig2):
    """Su 2009 Fig. 2, each neighbour's state as old as the delay (``communication`` model),
    then the remedies."""

    key = 'su2009_fig2_delay'
    title = 'Beyond the papers: Su 2009 Fig. 2 under a communication delay'
    claim = (
        'None: the paper assumes exact, current neighbour states. The question: does Fig. 2\'s '
        '"86 of the 100 agents move with the desired velocity" survive a delay of 0.02-0.5 s '
        'on every neighbour\'s state (the `communication` delay model, the leader\'s state '
        'to the informed agents undelayed)? The mechanism (docs/network.md): an agent sets its '
        'neighbours\' positions, sent a delay D ago, against its own current one, so in a '
        'flock moving at v each neighbour appears v D behind and the gradient term brakes the '
        'whole flock at the rate beta_0 = D v^T J v / |v|^2 (J: the mean Hessian of the pair '
        'potential over the neighbours). The remedies: `compensation: predict` (each held '
        'state extrapolated by its age) and the `input` model (the own state as old as the '
        'neighbours\').')
    order = 1000.0
    preset = 'su2009_fig2'
    overrides = ('network.delay=0.1',)
    axis, unit, spec = 'network.delay', ' s', 'reproduce_su2009_fig2_delay'

    @property
    def setups(self) -> tuple[SetUp, ...]:
        """Return the delays (the first the ideal network), then the remedies."""
        from flock_swarm.reproduce.seeds import study_runs
        remedies = []
        for name in REMEDIES:
            _, runs = study_runs(name, seeds=1)
            labels = {tuple(str(v) for v in run.point.values()): remedy_label(run.point)
                      for run in runs}
            remedies.append(SetUp(name, labels=labels))
        return (*super().setups, *remedies)

    def mechanism(self, res: dict) -> str:
        """Return the first-step braking rate of a translating lattice, measured by a run
        beside the prediction, without and with the compensation."""
        parts = []
        for delay in DRAG_DELAYS:
            none, predict = _drag(delay, 'none'), _drag(delay, 'predict')
            parts.append(f'D = {delay:g} s: {fmt(none["measured"])} /s (predicted '
                         f'{fmt(none["predicted"])}), with predict {fmt(predict["measured"])} /s')
        return (f'braking rate of {DRAG_AGENTS} uninformed agents on the alpha-lattice at '
                f'{DRAG_SPEED:g} m/s - ' + '; '.join(parts))


EXPERIMENT = Fig2Delay()
