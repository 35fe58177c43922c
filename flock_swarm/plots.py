"""Figures of a run from its time series (matplotlib, imported lazily, headless backend)."""

from pathlib import Path

import numpy as np


def plot_timeseries(series: dict[str, np.ndarray], out: Path, title: str) -> list[Path]:
    """Write ``trajectories.png`` and ``metrics.png`` for a recorded run.

    :param series: the arrays of ``timeseries.npz``.
    :param out: the output directory.
    :param title: figure title (the scenario name).
    :return: the written paths.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    q, lq, informed = series['q'], series['leader_q'], series['informed'][0]
    fig, ax = plt.subplots(figsize=(6, 6))
    for i in range(q.shape[1]):
        ax.plot(q[:, i, 0], q[:, i, 1], lw=0.6, color='tab:red' if informed[i] else 'tab:blue',
                alpha=0.7)
    ax.plot(lq[:, 0], lq[:, 1], 'k--', lw=1.2, label='virtual leader')
    ax.scatter(q[-1, :, 0], q[-1, :, 1], s=10, c=np.where(informed, 'tab:red', 'tab:blue'),
               zorder=3, label='agents at t_final (red: informed)')
    ax.plot(lq[-1, 0], lq[-1, 1], 'k*', ms=14)
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_title(f'{title}: trajectories (x-y projection)')
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    paths = [out / 'trajectories.png']
    fig.savefig(paths[0], dpi=110)
    plt.close(fig)

    t = series['t']
    panels = (('metric_eta', 'eta'), ('metric_velocity_mismatch_max', 'max ||p_i - p_gamma||'),
              ('metric_com_position_error', '||q_com - q_gamma||'),
              ('metric_min_pair_distance', 'min pair distance'),
              ('metric_components', 'components'))
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 9), sharex=True)
    for ax, (key, label) in zip(axes, panels):
        ax.plot(t, series[key], lw=1.2)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel('t [s]')
    axes[0].set_title(f'{title}: flocking metrics')
    fig.tight_layout()
    paths.append(out / 'metrics.png')
    fig.savefig(paths[1], dpi=110)
    plt.close(fig)
    return paths
