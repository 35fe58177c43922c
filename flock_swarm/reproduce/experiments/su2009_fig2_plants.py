"""Beyond the papers: Su 2009 Fig. 2 as double integrators, velocity-lag robots and
unicycles (issue 26)."""

from flock_swarm.core.scenario import Scenario
from flock_swarm.reproduce.common import fmt
from flock_swarm.reproduce.experiment import ETA_MARGIN, MeanClaim, SetUp
from flock_swarm.reproduce.experiments.network_study import NetworkFig2
from flock_swarm.reproduce.mechanisms import lag_fraction, run_delivered_fraction
from flock_swarm.reproduce.seeds import column_stats

#: The section's opening line.
BEYOND_PLANTS = (
    '*Beyond the papers.* The papers\' agents are double integrators. Here the same law flies '
    'robots (`plant:`, `docs/plants.md`): the law\'s acceleration turned into a velocity '
    'setpoint for a robot under a velocity controller with a first-order lag, or into forward '
    'speed and yaw rate for a differential-drive robot through the point ahead of its axle, '
    'by the exact conversion (one step delivers the law\'s velocity change) and by the naive '
    'one (the velocity p + u dt handed over as it is). Seeds 1 .. 20 of each are the same '
    'draws as the double '
    'integrators\' seeds 1 .. 20; the criterion is the paper\'s own, asked of each plant.')


class Fig2Plants(NetworkFig2):
    """Su 2009 Fig. 2 on three plants beside the papers' double integrator."""

    key = 'su2009_fig2_plants'
    title = 'Beyond the papers: Su 2009 Fig. 2 flown by robots'
    claim = (
        'None: the paper\'s agents are double integrators. The question: does Fig. 2\'s "86 '
        'of the 100 agents move with the desired velocity" survive robots that take velocity '
        'commands, with a lag of 0.1 s or 0.5 s, or that cannot move sideways (unicycles)?')
    order = 1002.0
    preset = 'su2009_fig2'
    overrides = ('plant={model: unicycle, ell: 0.1}',)
    spec = 'reproduce_su2009_fig2_plants'
    beyond = BEYOND_PLANTS
    criterion = MeanClaim(
        'eta', 0.86, ETA_MARGIN, 'eta at t_final (the fraction of agents with the desired '
        'velocity)',
        why='Fig. 2\'s criterion (the paper\'s 86 of 100 taken as typical, a mean within 5 '
        'agents of it), asked of each plant: the first set-up is the papers\' double '
        'integrator.')

    columns = NetworkFig2.columns + (
        ('delivered fraction of the law\'s velocity change per step', 'delivered_fraction',
         '1 (double integrator)'),
        ('its prediction', 'predicted_fraction', '-'),
        ('delivered change across the law\'s, relative', 'delivered_residual', '0'))

    def analyse(self, sc: Scenario, summary: dict, series: dict) -> dict:
        """Return Fig. 2's numbers and, for a robot plant, the mechanism: the fraction of
        the law's velocity change a step delivers over the run's recorded states, and its
        prediction (:mod:`flock_swarm.reproduce.mechanisms`)."""
        out = super().analyse(sc, summary, series)
        plant = sc.plant.model
        if sc.plant.default or 'plant_state' not in series:
            return out
        out['delivered_fraction'], out['delivered_residual'] = run_delivered_fraction(
            plant, series, sc.dt)
        if plant.name == 'velocity_lag':
            out['predicted_fraction'] = lag_fraction(plant.tau, sc.dt, plant.conversion,
                                                     plant.conversion_tau)
        return out

    def mechanism(self, res: dict) -> str:
        """Return each plant's delivered fraction (measured [predicted])."""
        parts = []
        for s in (res.get('seeds') or {}).get('setups', [])[1:]:
            measured = column_stats(s, 'delivered_fraction')
            if measured is None:
                continue
            predicted = column_stats(s, 'predicted_fraction')
            parts.append(f'{s["label"]}: {fmt(measured["mean"])}'
                         + (f' (predicted {fmt(predicted["mean"])})' if predicted else ''))
        if not parts:
            return ''
        return 'delivered fraction of u dt per step - ' + '; '.join(parts)

    @property
    def setups(self) -> tuple[SetUp, ...]:
        """Return the double integrators (the Fig. 2 study), then the three plants."""
        labels = {
            ("{'model': 'velocity_lag', 'tau': 0.1}",): 'velocity lag, tau = 0.1 s',
            ("{'model': 'velocity_lag', 'tau': 0.5}",): 'velocity lag, tau = 0.5 s',
            ("{'model': 'unicycle', 'ell': 0.1}",): 'unicycle, ell = 0.1 m',
            ("{'model': 'velocity_lag', 'tau': 0.1, 'conversion': 'naive'}",):
                'velocity lag, tau = 0.1 s, naive conversion',
            ("{'model': 'velocity_lag', 'tau': 0.5, 'conversion': 'naive'}",):
                'velocity lag, tau = 0.5 s, naive conversion',
            ("{'model': 'unicycle', 'ell': 0.1, 'conversion': 'naive'}",):
                'unicycle, ell = 0.1 m, naive conversion'}
        return (SetUp('reproduce_su2009_fig2', 'double integrator (the Fig. 2 study)'),
                SetUp(self.spec, labels=labels))


EXPERIMENT = Fig2Plants()
