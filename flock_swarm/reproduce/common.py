"""What every paper module of the reproduction shares: the experiment record, number
formatting, a few analysis helpers and the figures' look."""

import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from flock_swarm import plots
from flock_swarm.core.graphs import components, disk_graph
from flock_swarm.core.scenario import Scenario
from flock_swarm.presets import resolve


#: Figures: small PNGs (the report's figures together stay well under 2.5 MB).
FIG_DPI = 80
FIG_SIZE = (8.0, 3.3)
FIG_MAX_BYTES = 150_000

#: Half-width bounds [m] of the configuration view around the leader (Su Figs. 2, 7).
VIEW_MIN, VIEW_MAX = 15.0, 60.0


@dataclass(frozen=True)
class Experiment:
    """One experiment of the five papers (a preset) and how the report treats it.

    :ivar key: the preset name, also the name of its JSON result and figure.
    :ivar title: section title.
    :ivar paper: the paper, short citation.
    :ivar claim: the paper's claim, quoted with section and figure (Markdown).
    :ivar quick: ``--set`` overrides of ``--quick`` mode.
    :ivar ros: ``--set`` overrides of the version run through the ROS nodes, or ``None``.
    :ivar ros_quick: the same in ``--quick`` mode.
    """

    key: str
    title: str
    paper: str
    claim: str
    quick: tuple[str, ...] = ()
    ros: tuple[str, ...] | None = None
    ros_quick: tuple[str, ...] = ()


def fmt(value: Any) -> str:
    """Format a number of the report (4 significant digits; the one formatter used).

    :param value: a number, bool, string or ``None``.
    :return: the text.
    """
    if value is None:
        return 'n/a'
    if isinstance(value, bool):
        return 'yes' if value else 'no'
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if not np.isfinite(value):
            return 'inf' if value > 0 else ('-inf' if value < 0 else 'nan')
        if value == 0.0:
            return '0'
        return f'{float(value):.4g}'
    return str(value)


def preset_notes(preset: str) -> str:
    """Return the header comment of a preset file (what we chose where the paper is silent)."""
    lines = []
    for line in resolve(preset).read_text().splitlines():
        if not line.startswith('#'):
            break
        lines.append(line.lstrip('#').strip())
    return ' '.join(lines)


def set_args(overrides: Iterable[str]) -> str:
    """Return ``--set`` options for a command line."""
    return ''.join(f' --set {shlex.quote(o)}' for o in overrides)


def linked_to_informed(q: np.ndarray, informed: np.ndarray, sc: Scenario) -> int:
    """Return how many agents share an r-disk component with an informed agent.

    Su 2009 Theorem 1 (ii): those ("informed and type I uninformed agents") reach the
    desired velocity.
    """
    _, labels = components(disk_graph(q, sc.law.radius, sc.law.strict_radius))
    return int(np.isin(labels, np.unique(labels[informed])).sum())


def com_errors(series: dict) -> tuple[np.ndarray, np.ndarray]:
    """Return the COM errors ``qbar - q_gamma`` and ``pbar - p_gamma`` over time."""
    return (series['q'].mean(axis=1) - series['leader_q'],
            series['p'].mean(axis=1) - series['leader_p'])


def late(series: dict, fraction: float = 1.0 / 3.0) -> np.ndarray:
    """Return the mask of recorded instants in the last ``fraction`` of the run."""
    t = series['t']
    return t >= t[-1] * (1.0 - fraction) - 1e-12


def plural(count: int, noun: str) -> str:
    """Return ``'1 agent'`` or ``'3 agents'``."""
    return f'{count} {noun}{"" if count == 1 else "s"}'


def pyplot():
    """Return ``matplotlib.pyplot`` as :mod:`flock_swarm.plots` sets it up, with the report's
    small fonts."""
    plt = plots.pyplot()
    plt.rcParams.update({'font.size': 8, 'axes.titlesize': 9, 'legend.fontsize': 7})
    return plt


def save_figure(fig, path: Path) -> Path:
    """Save a figure as a small PNG (:data:`FIG_DPI`) and close it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    return plots.save_figure(fig, path, FIG_DPI)


def draw_configuration(ax, sc: Scenario, series: dict, k: int, title: str) -> None:
    """Draw the 2-D configuration at recorded instant ``k`` (:func:`flock_swarm.plots.draw_flock`:
    edges, velocities, informed agents circled, the leader) around the leader's flock."""
    q, p = series['q'][k], series['p'][k]
    informed = series['informed'][k].astype(bool)
    lq = series['leader_q'][k]
    # The view follows the leader's flock (the paper's plot (f)); groups that split off far
    # away would otherwise shrink it to a dot, so they are counted in the title instead.
    gap = np.abs(q - lq).max(axis=1)
    near = gap[gap <= VIEW_MAX]
    half = float(np.clip(near.max() + 3.0 if near.size else VIEW_MIN, VIEW_MIN, VIEW_MAX))
    plots.draw_flock(ax, q, p, lq, informed, sc.law.radius, strict=sc.law.strict_radius,
                     center=lq, half=half, size=8.0)
    outside = int((gap > half).sum())
    if outside:
        title += f'\n{outside} agents outside this view (split off)'
    ax.set_title(title)
    ax.legend(handles=plots.legend_handles(bool(informed.any()), bool(informed.all())),
              loc='best')


def draw_last_net(ax, sc: Scenario, q: np.ndarray) -> None:
    """Draw the final positions and their r-disk edges."""
    from matplotlib.collections import LineCollection
    edges = disk_graph(q, sc.law.radius, sc.law.strict_radius)
    ax.add_collection(LineCollection(np.stack((q[edges.i, :2], q[edges.j, :2]), axis=1),
                                     colors='tab:blue', linewidths=0.5))
    ax.scatter(q[:, 0], q[:, 1], s=6, c='tab:blue', label='t_final')


def cell(text: str) -> str:
    """Return text fit for a Markdown table cell (pipes escaped)."""
    return text.replace('|', '\\|')
