"""Zhou, Wu, Yu, Small, Lu 2012, Section 5.1: 10 agents on the given graph B with pseudo-leaders
1-3; every velocity converges to the leader's."""

from pathlib import Path

import numpy as np

from flock_swarm.core.graphs import diffusive_matrix
from flock_swarm.core.pseudo_leaders import minor_lambda_max, select_pseudo_leaders
from flock_swarm.core.scenario import Scenario
from flock_swarm.reproduce.common import FIG_SIZE, fmt, pyplot, save_figure
from flock_swarm.reproduce.experiment import Experiment, FractionClaim, SetUp

ZHOU12 = 'Zhou, Wu, Yu, Small, Lu 2012'


def analyse_zhou51(sc: Scenario, summary: dict, series: dict) -> dict:
    """Return the numbers of Zhou 2012 Section 5.1 (certificate, velocities, fixed shape)."""
    adjacency = np.array(sc.graph['adjacency'], dtype=float)
    b = diffusive_matrix(adjacency)
    greedy = select_pseudo_leaders(adjacency, sc.law.w, sc.law.alpha)
    q = series['q']
    t = series['t']
    k0 = int(np.searchsorted(t, t[-1] - 5.0))

    def pair_distances(x: np.ndarray) -> np.ndarray:
        """Return the matrix of distances between agents."""
        return np.linalg.norm(x[:, None] - x[None], axis=-1)

    return {
        't_final': summary['t_final'],
        'lambda_max_B7': minor_lambda_max(b, [0, 1, 2]),
        'minus_alpha_over_w': -sc.law.alpha / sc.law.w,
        'greedy_pseudo_leaders': ' '.join(str(i + 1) for i in greedy.ids),
        'velocity_mismatch_max': summary['velocity_mismatch_max'],
        'eta_tolerance': summary['eta_tolerance'],
        'eta': summary['eta'],
        'pair_distance_drift_last_5s': float(np.abs(pair_distances(q[-1])
                                                    - pair_distances(q[k0])).max()),
        'adaptive_gain_max': float(max(summary['adaptive_gain_final'])),
        'min_pair_distance': summary['min_pair_distance'],
        'collisions': summary['collisions'],
    }


def discuss_zhou51(m: dict) -> str:
    """Return the discussion of Zhou 2012 Section 5.1."""
    same = m['greedy_pseudo_leaders'] == '1 2 3'
    still = m['pair_distance_drift_last_5s'] < 0.01
    return (
        f'The certificate is the paper\'s: lambda_max(B_7) = {fmt(m["lambda_max_B7"])} < '
        f'-alpha/w = {fmt(m["minus_alpha_over_w"])}. Our own greedy rule (by degree until '
        f'Theorem 1 holds) picks agents {m["greedy_pseudo_leaders"]}'
        + (', the paper\'s set. ' if same else '; the run uses the paper\'s 1-3. ')
        + f'At t = {fmt(m["t_final"])} s the largest velocity error is '
        f'{fmt(m["velocity_mismatch_max"])} m/s (eta = {fmt(m["eta"])} at '
        f'{fmt(m["eta_tolerance"])} m/s), and pair distances changed by at most '
        f'{fmt(m["pair_distance_drift_last_5s"])} m over the last 5 s'
        + (', so "the position errors between agents remain fixed" holds. ' if still else
           ': the shape is still settling at 30 s. ')
        + 'The random initial state is a different draw from the paper\'s; dt = 0.5 ms is '
        'ours (the explicit coupling W = 70 B needs dt < 3.5 ms).')


def figure_zhou51(sc: Scenario, summary: dict, series: dict, m: dict, path: Path) -> Path:
    """Draw Zhou 2012 Section 5.1: velocity errors (cf. Fig. 6) and adaptive gains."""
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=FIG_SIZE)
    t = series['t']
    err = np.linalg.norm(series['p'] - series['leader_p'][:, None], axis=-1)
    informed = series['informed'][0].astype(bool)
    for i in range(err.shape[1]):
        ax1.semilogy(t, np.maximum(err[:, i], 1e-12), lw=0.8,
                     color='tab:red' if informed[i] else 'tab:blue')
    ax1.plot([], [], color='tab:red', label='pseudo-leaders 1-3')
    ax1.plot([], [], color='tab:blue', label='followers')
    ax1.set_xlabel('t [s]')
    ax1.set_ylabel('‖v_i - v_l‖ [m/s]')
    ax1.set_title('velocity errors (cf. Fig. 6)')
    ax1.grid(True, alpha=0.3, which='both')
    ax1.legend(loc='best')
    for i in np.flatnonzero(informed):
        ax2.plot(t, series['h'][:, i], label=f'h_{i + 1}')
    ax2.set_xlabel('t [s]')
    ax2.set_ylabel('adaptive gain h_i')
    ax2.set_title("pseudo-leaders' adaptive gains h_i' = k ‖v_i - v_l‖^2")
    ax2.legend(loc='best')
    return save_figure(fig, path)


class Sec51(Experiment):
    """Zhou 2012, Section 5.1."""

    key = 'zhou2012_sec51'
    title = 'Zhou 2012, Section 5.1: 10 agents, graph B, pseudo-leaders 1-3'
    paper = ZHOU12
    claim = (
        'Section 5.1, Figs. 3-6 (N = 10, the given graph B, w = 70, Lü dynamics with '
        'alpha = 60.3402, h(0) = 1, k = 0.01, 30 s): deleting agents 1-3 gives '
        '**lambda_max(B_7) = -1** < -alpha / w, so agents 1-3 are pseudo-leaders (Theorem '
        '1); "the **velocities of all the group members converge to the desired velocity**. '
        'Moreover, the position errors between agents remain fixed after a period of time."')
    order = 300.0
    quick = ('duration=0.2',)
    ros = ('duration=1.5',)
    ros_quick = ('duration=0.02',)
    rows = (
        ('t_final [s]', 't_final', '30'),
        ('lambda_max(B_7), agents 1-3 removed', 'lambda_max_B7', '-1'),
        ('-alpha / w', 'minus_alpha_over_w', '-0.862'),
        ('our greedy Theorem 1 choice (1-based ids)', 'greedy_pseudo_leaders', '1 2 3'),
        ('max ‖v_i - v_l‖ at t_final [m/s]', 'velocity_mismatch_max', '-> 0'),
        ('tolerance of eta [m/s] (ours)', 'eta_tolerance', '-'),
        ('eta at t_final', 'eta', '1'),
        ('max change of pair distances over the last 5 s [m]', 'pair_distance_drift_last_5s',
         '-> 0 ("remain fixed")'),
        ('largest adaptive gain h_i at t_final', 'adaptive_gain_max', '-'),
        ('closest approach [m]', 'min_pair_distance', '-'),
        ('pairs ever closer than 0.1 m', 'collisions', '-'))
    criterion = FractionClaim(
        'every velocity is within the tolerance (0.1 m/s) of the leader\'s at 30 s (eta = 1)',
        lambda m: m['eta'] is not None and m['eta'] >= 1.0 - 1e-12, 'eta = 1 at 30 s')
    setups = (SetUp('reproduce_zhou2012_sec51', 'as printed'),)
    columns = (('max ‖v_i - v_l‖ at t_final [m/s]', 'velocity_mismatch_max', '-> 0'),
               ('settling time [s] (max ‖v_i - v_l‖ stays <= 0.1 m/s)', 'settling_time',
                '< 30'),
               ('max change of pair distances over the last 5 s [m]',
                'pair_distance_drift_last_5s', '-> 0'),
               ('largest adaptive gain h_i at t_final', 'adaptive_gain_max', '-'))
    analyse = staticmethod(analyse_zhou51)
    discuss = staticmethod(discuss_zhou51)
    figure = staticmethod(figure_zhou51)

    def headline(self, res: dict) -> tuple[str, str]:
        """Return the paper's certificate and claim, and ours."""
        m = res['metrics']
        return ('lambda_max(B_7) = -1; v_i -> v_l',
                f'{fmt(m["lambda_max_B7"])}; max error {fmt(m["velocity_mismatch_max"])} m/s')


EXPERIMENT = Sec51()
