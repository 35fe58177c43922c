"""Olfati-Saber 2003, Section 5: flocking towards a sink; the net becomes one flock whose
topology stops switching."""

from pathlib import Path

import numpy as np

from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.scenario import Scenario
from flock_swarm.reproduce.common import (FIG_SIZE, draw_last_net, fmt, late, plural, pyplot,
                                          save_figure)
from flock_swarm.reproduce.experiment import Experiment, FractionClaim, SetUp


def invariant_flock(m: dict) -> bool:
    """Return whether a run ends as one flock whose topology no longer switches."""
    return m['components_final'] == 1 and m['topology_changes_last_quarter'] == 0


def analyse_sink(sc: Scenario, summary: dict, series: dict) -> dict:
    """Return the numbers of Olfati-Saber 2003 Section 5 (one flock, fixed topology)."""
    q = series['q'][-1]
    edges = disk_graph(q, sc.law.radius, sc.law.strict_radius)
    lengths = np.linalg.norm(q[edges.j] - q[edges.i], axis=1)
    mask = late(series, 0.25)
    previous, changes, last_change = None, 0, 0.0
    for t, qk, is_late in zip(series['t'], series['q'], mask):
        g = disk_graph(qk, sc.law.radius, sc.law.strict_radius)
        current = set(zip(g.i.tolist(), g.j.tolist()))
        if previous is not None and current != previous:
            last_change = float(t)
            changes += int(is_late)
        previous = current
    return {
        't_final': summary['t_final'],
        'components_final': summary['components_final'],
        'edges_final': edges.size,
        'topology_changes_last_quarter': changes,
        'last_topology_change_t': last_change,
        'neighbour_distance_min': float(lengths.min()) if lengths.size else None,
        'neighbour_distance_max': float(lengths.max()) if lengths.size else None,
        'com_position_error': summary['com_position_error'],
        'speed_max_final': summary['velocity_mismatch_max'],
        'collisions': summary['collisions'],
        'min_pair_distance': summary['min_pair_distance'],
    }


def discuss_sink(m: dict) -> str:
    """Return the discussion of Olfati-Saber 2003 Section 5."""
    one = m['components_final'] == 1
    fixed = invariant_flock(m)
    return (
        ('We reproduce the claim: ' if one and fixed else
         'We reproduce the flock but not yet a fixed topology: ' if one else
         'We do not reproduce the claim: ')
        + f'at t = {fmt(m["t_final"])} s the agents form '
        f'{plural(m["components_final"], "component")} with {m["edges_final"]} edges, and '
        f'the graph changed {plural(m["topology_changes_last_quarter"], "time")} over the '
        'last quarter of the run, the last time at t = '
        f'{fmt(m["last_topology_change_t"])} s (checked at the recorded instants). '
        'The paper gives only n, d_alpha = 7 and r = 1.2 d_alpha; the initial box, a, b, '
        'delta, k, c_d, c1, c2 and the run length are ours (preset header), and the paper '
        'has no number to compare against. Neighbour distances at the end range from '
        f'{fmt(m["neighbour_distance_min"])} m to {fmt(m["neighbour_distance_max"])} m '
        f'(d_alpha = 7, r = 8.4), and the agents still move (max speed '
        f'{fmt(m["speed_max_final"])} m/s). Most likely the PD term -c1 q_i keeps pressing '
        'the flock towards the sink against the pair repulsion, so the lattice is not exact, '
        'and the slow residual motion still makes and breaks edges near r.')


def figure_sink(sc: Scenario, summary: dict, series: dict, m: dict, path: Path) -> Path:
    """Draw Olfati-Saber 2003 Section 5: paths to the sink, final net; components, speed."""
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=FIG_SIZE)
    q = series['q']
    for i in range(q.shape[1]):
        ax1.plot(q[:, i, 0], q[:, i, 1], color='0.8', lw=0.4)
    ax1.scatter(q[0, :, 0], q[0, :, 1], s=5, c='tab:orange', label='t = 0')
    draw_last_net(ax1, sc, q[-1])
    ax1.plot(0.0, 0.0, 'k+', ms=10, label='sink')
    ax1.set_aspect('equal', adjustable='datalim')
    ax1.set_title('paths and final net (cf. Fig. 4)')
    ax1.set_xlabel('x [m]')
    ax1.set_ylabel('y [m]')
    ax1.legend(loc='best')
    t = series['t']
    ax2.plot(t, series['metric_components'], color='tab:purple', label='components')
    ax2.set_xlabel('t [s]')
    ax2.set_ylabel('r-disk components', color='tab:purple')
    ax3 = ax2.twinx()
    ax3.plot(t, series['metric_velocity_mismatch_max'], color='tab:green', label='max speed')
    ax3.set_ylabel('max ‖p_i‖ [m/s]', color='tab:green')
    ax2.set_title('components and largest speed')
    return save_figure(fig, path)


class Sink(Experiment):
    """Olfati-Saber 2003, Section 5."""

    key = 'os2003_sink'
    title = 'Olfati-Saber 2003, Section 5: flocking towards a sink'
    paper = 'Olfati-Saber 2003'
    claim = (
        'Section 5, Fig. 4 (n = 100 agents, random positions, zero velocities, sink '
        '(q_d, p_d) = (0, 0) through the PD term (40), d_alpha = 7, r = 1.2 d_alpha): '
        '"an initially disconnected net ... evolves into **a flock** after going through a '
        'finite number of switching events that add more edges to the initial net. The '
        '**topology of the flock is asymptotically invariant**." The paper gives no number.')
    order = 200.0
    quick = ('n_agents=20', 'duration=2')
    ros = ('n_agents=20', 'duration=20')
    ros_quick = ('n_agents=4', 'duration=0.5')
    rows = (
        ('t_final [s] (paper: not given)', 't_final', 'not given'),
        ('r-disk components at t_final', 'components_final', '1 (a flock)'),
        ('edges at t_final', 'edges_final', '-'),
        ('topology changes over the last quarter (recorded instants)',
         'topology_changes_last_quarter', '0 (invariant)'),
        ('time of the last topology change [s]', 'last_topology_change_t', 'finite'),
        ('shortest neighbour distance at t_final [m] (d_alpha = 7)', 'neighbour_distance_min',
         '-'),
        ('longest neighbour distance at t_final [m] (r = 8.4)', 'neighbour_distance_max', '-'),
        ('‖qbar - q_d‖ at t_final [m]', 'com_position_error', '-'),
        ('max speed at t_final [m/s]', 'speed_max_final', '-'),
        ('pairs ever closer than 1 m', 'collisions', '-'),
        ('closest approach [m]', 'min_pair_distance', '-'))
    criterion = FractionClaim(
        'the agents end as one flock whose topology no longer switches (1 component, no '
        'switch over the last quarter of the run)', invariant_flock,
        'one flock, no late switch')
    # The paper gives no run length; the two are reported each on its own.
    setups = (SetUp('reproduce_os2003_sink', '300 s'),
              SetUp('reproduce_os2003_sink_600s', '600 s'))
    columns = (('time of the last topology switch [s]', 'last_topology_change_t', 'finite'),
               ('switches over the last quarter', 'topology_changes_last_quarter', '0'),
               ('r-disk components at t_final', 'components_final', '1'),
               ('‖qbar - q_d‖ at t_final [m]', 'com_position_error', '-'))
    analyse = staticmethod(analyse_sink)
    discuss = staticmethod(discuss_sink)
    figure = staticmethod(figure_sink)

    def headline(self, res: dict) -> tuple[str, str]:
        """Return the paper's claim and our components and late switches."""
        m = res['metrics']
        return ('one flock, invariant topology',
                f'{m["components_final"]} component(s), '
                f'{m["topology_changes_last_quarter"]} late switches')


EXPERIMENT = Sink()
