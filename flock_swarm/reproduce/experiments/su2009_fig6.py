"""Su, Wang, Lin 2009, Fig. 6 and Theorem 2 (iii): a Lorenz leader under protocol (33); the
centre of mass converges exponentially, as the closed form (48) says."""

from flock_swarm.reproduce.common import fmt
from flock_swarm.reproduce.experiment import FractionClaim, SetUp
from flock_swarm.reproduce.experiments.su2009_fig2 import SU09
from flock_swarm.reproduce.experiments.su2009_fig5 import Fig5

#: A run follows (48) when its COM error stays within this many metres per second of dt of
#: it: every agent holds f_gamma(t_k) over a step while the leader integrates the Lorenz
#: equations, which leaves a residual of about dt/2 f_gamma'; test_su2009 allows dt
#: (|e(0)| + |e'(0)| + the range of f_gamma) and checks that it halves with dt, and the
#: Lorenz acceleration of Fig. 6 ranges over hundreds of m/s^2.
CLOSED_FORM_SLACK_PER_DT = 100.0


def follows_closed_form(m: dict) -> bool:
    """Return whether a run's COM error follows (48) to within the sampling residual."""
    dev = m.get('closed_form_position_dev')
    return dev is not None and dev <= CLOSED_FORM_SLACK_PER_DT * m['dt']


class Fig6(Fig5):
    """Su 2009 Fig. 6 (Section V.B, protocol (33)) and Theorem 2 (iii)."""

    key = 'su2009_fig6'
    title = 'Su 2009, Fig. 6 and Theorem 2 (iii): Lorenz leader, protocol (33)'
    paper = SU09
    claim = (
        'Section V.B, Fig. 6 (as Fig. 5): "under the protocol (33), the position and '
        'velocity of the COM **converge exponentially** to those of the virtual leader"; '
        'Theorem 2 (iii) gives the COM error in closed form, eq. (48) for c2^2 < 4 c1 '
        '(here c1 = c2 = 0.5, decay rate c2 / 2 = 0.25 1/s).')
    order = 130.0
    ros = ('duration=4',)
    ros_quick = ('duration=0.1',)
    rows = tuple((label, key, paper.replace('fluctuates', '-> 0 exponentially'))
                 for label, key, paper in Fig5.rows) + (
        ('max ‖e - e_(48)‖ over the run [m], e = qbar - q_gamma', 'closed_form_position_dev',
         '0'),
        ("max ‖e' - e'_(48)‖ over the run [m/s]", 'closed_form_velocity_dev', '0'))
    criterion = FractionClaim(
        f'the COM error follows the closed form (48) over the whole run to within '
        f'{CLOSED_FORM_SLACK_PER_DT:g} dt m (the sampling residual: every agent holds '
        'f_gamma(t_k) over a step while the leader integrates the Lorenz equations)',
        follows_closed_form, 'COM error follows (48)')
    setups = (SetUp('reproduce_su2009_fig6', 'as printed'),)
    columns = (('max ‖e - e_(48)‖ over the run [m]', 'closed_form_position_dev', '0'),
               ('‖qbar - q_gamma‖ at t_final [m]', 'com_position_error', '-> 0'),
               ('‖pbar - p_gamma‖ at t_final [m/s]', 'com_velocity_error', '-> 0'))
    misprints = (
        'Su, Wang, Lin 2009, eq. (48) (COM error for c2^2 < 4 c1): the velocity formula lacks '
        'a factor c2 / 2. As printed, its sine coefficient is -w e0 - (c2/2 e0 + v0) / w with '
        'w = sqrt(4 c1 - c2^2) / 2, which solves (45) only for c2 = 2; the derivative of '
        '(48)\'s own position gives -(c1 e0 + c2/2 v0) / w. Found by test/test_su2009.py; the '
        'Fig. 6 comparison below uses the corrected form.',
        'Su, Wang, Lin 2009, eq. (45) writes p̄_γ (an overbar) in the COM velocity equation, '
        'where ṗ_γ = f_γ is meant (the line above derives ū = f_γ - c1 (q̄ - q_γ) - '
        'c2 (p̄ - p_γ)).',
        'Su, Wang, Lin 2009, the sentence closing the proof of Theorem 2 (iii) gives the rate '
        'of the case c2^2 > 4 c1 as (c2 - sqrt(4 c1 - c2^2)) / 2, the square root of a '
        'negative number in that case; the theorem\'s statement (tau) and the exponents of '
        '(46) have (c2 - sqrt(c2^2 - 4 c1)) / 2. (The same sentence calls the rates "time '
        'constants"; they are in 1/s.)')

    def discuss(self, m: dict) -> str:
        """Return how closely the COM error follows (48), and why not exactly."""
        return (
            'The COM converges as the paper says: ‖qbar - q_gamma‖ = '
            f'{fmt(m["com_position_error"])} m and ‖pbar - p_gamma‖ = '
            f'{fmt(m["com_velocity_error"])} m/s at t = {fmt(m["t_final"])} s (at most '
            f'{fmt(m["com_position_error_max_late"])} m and '
            f'{fmt(m["com_velocity_error_max_late"])} m/s over the last third). The recorded '
            'COM error follows the closed form (48) of Theorem 2 (iii) (velocity corrected, '
            f'see "Misprints") to within {fmt(m["closed_form_position_dev"])} m and '
            f'{fmt(m["closed_form_velocity_dev"])} m/s over the whole run. The residual comes '
            'from sampling, not from the theorem: every agent holds f_gamma(t_k) over a step '
            'while the leader integrates the Lorenz equations, so an error of about dt/2 '
            'f_gamma\' enters (45) (dt = 2 ms; the Lorenz acceleration changes by hundreds of '
            'm/s^2 per second). The log-scale figure shows the COM error levelling off there '
            'while the closed form keeps decaying; the test suite checks that this residual '
            'halves with dt.')

    def headline(self, res: dict) -> tuple[str, str]:
        """Return the paper's claim and our final COM error and distance to (48)."""
        m = res['metrics']
        return ('COM error -> 0 exponentially, eq. (48)',
                f'{fmt(m["com_position_error"])} m at 30 s; (48) within '
                f'{fmt(m["closed_form_position_dev"])} m')


EXPERIMENT = Fig6()
