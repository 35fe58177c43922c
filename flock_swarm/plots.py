"""Figures of a run from its time series (matplotlib, imported lazily, headless backend).

Every function takes the arrays of ``timeseries.npz`` (``t``, ``q``, ``p``, ``leader_q``,
``leader_p``, ``informed``, ``metric_*``; see ``docs/outputs.md``) and the scenario facts it
needs (interaction radius, informed ids...), never a bag, so the same figures come from
``sim``, from the ROS world's own recording and from ``analyze``. The dimension is the last
axis of ``q``: 3-D runs get 3-D axes. Figures follow Su, Wang, Lin 2009 (Figs. 2, 5, 6):
neighbour relations as solid lines, velocities as arrows, the virtual leader as a hexagram,
informed agents circled. A scenario's obstacles (``obstacles:``) are drawn by
:func:`draw_obstacles` in every figure of positions (trajectories, snapshots, animation).
"""

from pathlib import Path
import shutil
from typing import Callable, Sequence

import numpy as np

from flock_swarm.core.graphs import disk_graph
from flock_swarm.core.obstacles import ObstacleSpec


def plot_timeseries(series: dict[str, np.ndarray], out: Path, title: str,
                    obstacles: ObstacleSpec | None = None) -> list[Path]:
    """Write ``trajectories.png`` and ``metrics.png`` (and ``network.png`` for a run with a
    ``network:`` section) for a recorded run.

    :param series: the arrays of ``timeseries.npz``.
    :param out: the output directory.
    :param title: figure title (the scenario name).
    :param obstacles: the scenario's obstacles (``None``: none), drawn with the paths.
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
    if obstacles is not None and obstacles.active:
        # Around the paths (the view they set), never widening it to the walls' extent.
        ax.autoscale_view()
        xlim, ylim = ax.get_xlim(), ax.get_ylim()
        draw_obstacles(ax, obstacles)
        ax.set_xlim(xlim)
        ax.set_ylim(ylim)
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    # With obstacles the limits are fixed (above): the box keeps the aspect, where 'datalim'
    # made matplotlib warn "Ignoring fixed x limits ..." at every draw.
    fixed = obstacles is not None and obstacles.active
    ax.set_aspect('equal', adjustable='box' if fixed else 'datalim')
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
    if 'network_delivered' in series:
        paths.append(plot_network(series, out, title=title))
    return paths


#: Colour of the informed agents (pseudo-leaders, pinned observers), as on ``/swarm/markers``.
INFORMED_COLOR = 'tab:red'
#: Colour of the other agents.
AGENT_COLOR = 'tab:blue'
#: Colour of the virtual leader and its path.
LEADER_COLOR = 'black'
#: Colour of the neighbour relations (edges of the r-disk graph).
EDGE_COLOR = '0.6'
#: A six-pointed star (matplotlib's regular star polygon): Su 2009's hexagram for the leader.
HEXAGRAM = (6, 1, 0)
#: Names of the coordinates, for labels.
AXES = ('x', 'y', 'z')
#: Colours of the coordinates in the per-component plots.
AXIS_COLORS = ('tab:blue', 'tab:orange', 'tab:green')
#: Resolution of the PNG figures [dots per inch].
FIGURE_DPI = 110
#: The longest velocity arrow of a flock drawing, as a fraction of the drawing's width.
ARROW_FRACTION = 0.08
#: Margin around a flock drawing, as a fraction of its width (and at least this many radii).
MARGIN_FRACTION = 0.08
MARGIN_RADII = 0.25
#: Ratio of the largest to the smallest minimum distance above which its axis is logarithmic.
LOG_SCALE_SPAN = 100.0
#: Animation defaults: at most this many frames, this resolution and frame rate (a GIF of a
#: few hundred kilobytes).
ANIMATION_MAX_FRAMES = 150
ANIMATION_DPI = 70
ANIMATION_FPS = 15
#: Colour and opacity of the obstacles (as on ``/swarm/markers``).
OBSTACLE_COLOR = (0.55, 0.45, 0.35)
OBSTACLE_ALPHA = 0.45


def draw_obstacles(ax, obstacles: ObstacleSpec | None, center: np.ndarray | None = None,
                   half: float | None = None) -> list:
    """Draw a scenario's obstacles onto ``ax`` (2-D or 3-D): spheres (discs in 2-D) and walls.

    A wall is the half-space behind its surface: in 2-D a shaded half-plane, in 3-D a square
    of its plane; both are drawn large enough to cross the view (``center``, ``half``, by
    default the axes' current limits), and nothing is drawn for ``None`` or an empty map. The
    axes' limits are the caller's to set.

    :param ax: a 2-D axes, or a 3-D one.
    :param obstacles: the obstacles.
    :param center: centre of the view.
    :param half: half-width of the view.
    :return: the artists drawn.
    """
    if obstacles is None or not obstacles.active:
        return []
    three = hasattr(ax, 'get_zlim')
    if center is None or half is None:
        limits = [ax.get_xlim(), ax.get_ylim()] + ([ax.get_zlim()] if three else [])
        center = np.array([(lo + hi) / 2 for lo, hi in limits])
        half = max((hi - lo) / 2 for lo, hi in limits)
    artists = []
    style = {'color': OBSTACLE_COLOR, 'alpha': OBSTACLE_ALPHA}
    if three:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
        ball = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
        for (c, r) in obstacles.spheres:
            x, y, z = (np.asarray(c)[:, None, None] + r * ball)
            artists.append(ax.plot_surface(x, y, z, linewidth=0, **style))
        for point, normal in zip(obstacles.points, obstacles.normals):
            # Two directions in the plane, and its point closest to the view's centre.
            e1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(normal, e1)
            foot = center - normal * np.dot(center - point, normal)
            side = half
            corners = [foot + side * (a * e1 + b * e2)
                       for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            artists.append(ax.add_collection3d(Poly3DCollection([corners], **style)))
        return artists
    from matplotlib.patches import Circle, Polygon
    # A 3-D map on 2-D axes (the x-y projection of plot_timeseries): spheres by their
    # outline, walls standing on the plane (normal without z) by their trace; other walls
    # cover the whole projection and are left out.
    for (c, r) in obstacles.spheres:
        artists.append(ax.add_patch(Circle(c[:2], r, zorder=0.5, lw=0, **style)))
    for point, normal in zip(obstacles.points, obstacles.normals):
        if normal.shape[0] == 3 and abs(normal[2]) > 1e-12:
            continue
        point, normal, center = point[:2], normal[:2], center[:2]
        along = np.array([-normal[1], normal[0]])
        # Far enough to cross the view whatever the wall's point (its foot near the centre).
        foot = center - normal * np.dot(center - point, normal)
        reach = 4.0 * half
        corners = [foot + reach * along, foot - reach * along,
                   foot - reach * along - reach * normal, foot + reach * along - reach * normal]
        artists.append(ax.add_patch(Polygon(corners, closed=True, zorder=0.5, lw=0, **style)))
    return artists


def pyplot():
    """Return ``matplotlib.pyplot`` on the headless Agg backend, imported on first use."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def informed_mask(series: dict[str, np.ndarray],
                  informed: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
    """Return the informed agents as a boolean mask over the N agents.

    :param series: the time series (``q`` gives N).
    :param informed: ids or a boolean mask; ``None`` takes ``series['informed'][0]`` (nobody
        when the series has no such array).
    :return: the mask, shape ``(N,)``.
    :raises ValueError: if a mask has the wrong length or an id is out of range.
    """
    n = series['q'].shape[1]
    if informed is None:
        if 'informed' not in series:
            return np.zeros(n, dtype=bool)
        informed = series['informed'][0]
    values = np.asarray(informed)
    if values.dtype == bool:
        if values.shape != (n,):
            raise ValueError(f'informed mask has shape {values.shape}, expected ({n},)')
        return values.copy()
    ids = values.astype(int).ravel()
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ValueError(f'informed ids must be in [0, {n}), got {ids.tolist()}')
    mask = np.zeros(n, dtype=bool)
    mask[ids] = True
    return mask


def snapshot_indices(t: np.ndarray, times: Sequence[float] | None = None) -> list[int]:
    """Return the recorded instants nearest to the requested times, without repeats.

    :param t: the recorded times [s].
    :param times: the wanted times [s]; ``None``: the first, middle and last instants.
    :return: indices into ``t``, in the order asked.
    """
    if times is None:
        times = (t[0], 0.5 * (t[0] + t[-1]), t[-1])
    indices: list[int] = []
    for wanted in times:
        k = int(np.argmin(np.abs(t - wanted)))
        if k not in indices:
            indices.append(k)
    return indices


def _colors(mask: np.ndarray) -> np.ndarray:
    return np.where(mask, INFORMED_COLOR, AGENT_COLOR)


def _new_axes(fig, dim: int, *position):
    return fig.add_subplot(*position, projection='3d' if dim == 3 else None)


def _bounds(points: np.ndarray, radius: float | None) -> tuple[np.ndarray, float]:
    """Return the centre and half-width of an equal-aspect box around ``points`` (M x dim)."""
    points = points[np.isfinite(points).all(axis=1)]
    if points.size == 0:
        return np.zeros(2), 1.0
    low, high = points.min(axis=0), points.max(axis=0)
    half = 0.5 * float((high - low).max())
    margin = max(MARGIN_FRACTION * 2 * half, MARGIN_RADII * (radius or 0.0), 0.5)
    return 0.5 * (low + high), half + margin


def _set_limits(ax, center: np.ndarray, half: float) -> None:
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    if center.shape[0] == 3:
        ax.set_zlim(center[2] - half, center[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_zlabel('z [m]')
    else:
        ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')


def _arrow_scale(p: np.ndarray, half: float) -> float:
    """Return metres of arrow per m/s: the longest arrow is a fixed share of the view."""
    top = float(np.nanmax(np.linalg.norm(p, axis=-1), initial=0.0))
    return ARROW_FRACTION * 2 * half / top if top > 0 else 0.0


def legend_handles(any_informed: bool, all_informed: bool) -> list:
    """Return the legend entries of :func:`draw_flock`: agents (those present), leader, edges,
    velocities."""
    from matplotlib.lines import Line2D
    handles = []
    if not all_informed:
        handles.append(Line2D([], [], ls='none', marker='o', color=AGENT_COLOR, label='agent'))
    if any_informed:
        handles.append(Line2D([], [], ls='none', marker='o', color=INFORMED_COLOR, mfc='none',
                              ms=10, label='informed agent'))
    handles.append(Line2D([], [], ls='none', marker=HEXAGRAM, color=LEADER_COLOR, ms=12,
                          label='virtual leader'))
    handles.append(Line2D([], [], color=EDGE_COLOR, label='neighbours (r-disk)'))
    handles.append(Line2D([], [], color='0.2', marker='>', ms=5, label='velocity'))
    return handles


def _line_handles(mask: np.ndarray) -> list:
    """Return legend entries for agents' lines: uninformed and informed, those present."""
    from matplotlib.lines import Line2D
    handles = []
    if not mask.all():
        handles.append(Line2D([], [], color=AGENT_COLOR, label='agent'))
    if mask.any():
        handles.append(Line2D([], [], color=INFORMED_COLOR, label='informed agent'))
    return handles


def draw_flock(ax, q: np.ndarray, p: np.ndarray, leader_q: np.ndarray, informed: np.ndarray,
               radius: float, *, strict: bool = True, center: np.ndarray | None = None,
               half: float | None = None, arrow_scale: float | None = None,
               size: float = 18.0, obstacles: ObstacleSpec | None = None) -> list:
    """Draw one instant of the flock as in Su 2009 Figs. 2, 5, 6 onto ``ax`` (2-D or 3-D).

    Neighbour relations (``||q_i - q_j|| < r``) are solid lines, velocities arrows, the
    virtual leader ``q_gamma`` a hexagram, informed agents circled.

    :param ax: a 2-D axes, or a 3-D one for ``dim = 3``.
    :param q: positions ``(N, dim)``.
    :param p: velocities ``(N, dim)``.
    :param leader_q: the leader's position ``(dim,)``.
    :param informed: the informed mask ``(N,)``.
    :param radius: the interaction radius ``r``.
    :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
    :param center: centre of the view (default: around the flock and the leader).
    :param half: half-width of the view.
    :param arrow_scale: metres of arrow per m/s (default: the longest arrow is
        :data:`ARROW_FRACTION` of the view).
    :param size: marker area of an agent [pt^2].
    :param obstacles: the scenario's obstacles (:func:`draw_obstacles`; ``None``: none).
    :return: the artists drawn (an animation removes them before the next frame).
    """
    dim = q.shape[1]
    if center is None or half is None:
        center, half = _bounds(np.vstack([q, leader_q[None]]), radius)
    if arrow_scale is None:
        arrow_scale = _arrow_scale(p, half)
    edges = disk_graph(q, radius, strict)
    segments = np.stack([q[edges.i], q[edges.j]], axis=1)
    colors = _colors(informed)
    arrows = p * arrow_scale
    artists = draw_obstacles(ax, obstacles, center, half)
    if dim == 3:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection
        artists.append(ax.add_collection3d(
            Line3DCollection(segments, colors=EDGE_COLOR, linewidths=0.7)))
        if arrow_scale > 0:
            artists.append(ax.quiver(q[:, 0], q[:, 1], q[:, 2], arrows[:, 0], arrows[:, 1],
                                     arrows[:, 2], colors=colors, arrow_length_ratio=0.3,
                                     linewidths=0.8))
        artists.append(ax.scatter(q[:, 0], q[:, 1], q[:, 2], s=size, c=colors,
                                  depthshade=False))
        artists.append(ax.scatter(q[informed, 0], q[informed, 1], q[informed, 2], s=size * 5,
                                  facecolors='none', edgecolors=INFORMED_COLOR,
                                  linewidths=0.9, depthshade=False))
        artists.append(ax.scatter([leader_q[0]], [leader_q[1]], [leader_q[2]], s=size * 10,
                                  marker=HEXAGRAM, c=LEADER_COLOR, depthshade=False))
    else:
        from matplotlib.collections import LineCollection
        artists.append(ax.add_collection(
            LineCollection(segments, colors=EDGE_COLOR, linewidths=0.7, zorder=1)))
        if arrow_scale > 0:
            artists.append(ax.quiver(q[:, 0], q[:, 1], arrows[:, 0], arrows[:, 1],
                                     color=colors, angles='xy', scale_units='xy', scale=1.0,
                                     width=0.004, headwidth=4, headlength=5, zorder=2))
        artists.append(ax.scatter(q[:, 0], q[:, 1], s=size, c=colors, zorder=3))
        artists.append(ax.scatter(q[informed, 0], q[informed, 1], s=size * 5,
                                  facecolors='none', edgecolors=INFORMED_COLOR,
                                  linewidths=0.9, zorder=3))
        artists += ax.plot(leader_q[0], leader_q[1], ls='none', marker=HEXAGRAM, ms=14,
                           color=LEADER_COLOR, zorder=4)
    _set_limits(ax, center, half)
    return artists


def save_figure(fig, path: Path, dpi: int = FIGURE_DPI) -> Path:
    """Save a figure as PNG at ``dpi`` and close it; return ``path``."""
    plt = pyplot()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def plot_trajectories(series: dict[str, np.ndarray], out: Path, *, title: str = '',
                      informed: Sequence[int] | np.ndarray | None = None,
                      filename: str = 'trajectories.png',
                      obstacles: ObstacleSpec | None = None) -> Path:
    """Draw every agent's path and the leader's (Su 2009 Figs. 5-6 (c)); 3-D runs in 3-D.

    Paths start at a small open circle and end at a dot; informed agents are red and circled
    at the end; the leader's path is dashed, its final position a hexagram.

    :param series: the time series (``q``, ``leader_q``; ``informed`` unless given).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param informed: informed ids or mask (default: from the series).
    :param filename: the file name in ``out``.
    :param obstacles: the scenario's obstacles (``None``: none).
    :return: the written path.
    """
    plt = pyplot()
    q, lq = series['q'], series['leader_q']
    mask = informed_mask(series, informed)
    dim = q.shape[2]
    colors = _colors(mask)
    fig = plt.figure(figsize=(6.4, 6.0))
    ax = _new_axes(fig, dim, 1, 1, 1)
    paths = np.swapaxes(q, 0, 1)
    if dim == 3:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection
        ax.add_collection3d(Line3DCollection(paths, colors=colors, linewidths=0.7, alpha=0.8))
        ax.scatter(*q[0].T, s=10, facecolors='none', edgecolors=colors, depthshade=False)
        ax.scatter(*q[-1].T, s=14, c=colors, depthshade=False)
        ax.scatter(*q[-1, mask].T, s=70, facecolors='none', edgecolors=INFORMED_COLOR,
                   depthshade=False)
        ax.plot(*lq.T, ls='--', color=LEADER_COLOR, lw=1.2)
        ax.scatter(*lq[-1], marker=HEXAGRAM, s=160, c=LEADER_COLOR, depthshade=False)
    else:
        from matplotlib.collections import LineCollection
        ax.add_collection(LineCollection(paths, colors=colors, linewidths=0.7, alpha=0.8))
        ax.scatter(q[0, :, 0], q[0, :, 1], s=10, facecolors='none', edgecolors=colors)
        ax.scatter(q[-1, :, 0], q[-1, :, 1], s=14, c=colors, zorder=3)
        ax.scatter(q[-1, mask, 0], q[-1, mask, 1], s=70, facecolors='none',
                   edgecolors=INFORMED_COLOR, zorder=3)
        ax.plot(lq[:, 0], lq[:, 1], ls='--', color=LEADER_COLOR, lw=1.2)
        ax.plot(lq[-1, 0], lq[-1, 1], ls='none', marker=HEXAGRAM, ms=13, color=LEADER_COLOR)
    center, half = _bounds(np.vstack([q.reshape(-1, dim), lq]), None)
    draw_obstacles(ax, obstacles, center, half)
    _set_limits(ax, center, half)
    from matplotlib.lines import Line2D
    handles = _line_handles(mask)
    handles += [Line2D([], [], color=LEADER_COLOR, ls='--', marker=HEXAGRAM, ms=9,
                       label='virtual leader'),
                Line2D([], [], ls='none', marker='o', mfc='none', color='0.3', ms=4,
                       label=f't = {series["t"][0]:g} s'),
                Line2D([], [], ls='none', marker='o', color='0.3', ms=4,
                       label=f't = {series["t"][-1]:g} s')]
    ax.legend(handles=handles, loc='best', fontsize=8)
    ax.set_title(f'{title}: trajectories'.lstrip(': '))
    if dim == 2:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def plot_snapshots(series: dict[str, np.ndarray], out: Path, *, radius: float,
                   times: Sequence[float] | None = None, strict: bool = True, title: str = '',
                   informed: Sequence[int] | np.ndarray | None = None,
                   filename: str = 'snapshots.png',
                   obstacles: ObstacleSpec | None = None) -> Path:
    """Draw the flock at chosen instants, one panel each (Su 2009 Fig. 2 (a)-(e), 5-6 (a)-(b)).

    :param series: the time series (``t``, ``q``, ``p``, ``leader_q``).
    :param out: the output directory.
    :param radius: the interaction radius ``r`` of the neighbour edges.
    :param times: the times [s] (nearest recorded instant); default first, middle, last.
    :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
    :param title: the run's name, for the title.
    :param informed: informed ids or mask (default: from the series).
    :param filename: the file name in ``out``.
    :param obstacles: the scenario's obstacles (``None``: none).
    :return: the written path.
    """
    plt = pyplot()
    t, q, p, lq = series['t'], series['q'], series['p'], series['leader_q']
    mask = informed_mask(series, informed)
    dim = q.shape[2]
    chosen = snapshot_indices(t, times)
    cols = len(chosen)
    fig = plt.figure(figsize=(4.3 * cols, 4.7 if dim == 3 else 4.5))
    for n, k in enumerate(chosen):
        ax = _new_axes(fig, dim, 1, cols, n + 1)
        draw_flock(ax, q[k], p[k], lq[k], mask, radius, strict=strict, obstacles=obstacles)
        ax.set_title(f't = {t[k]:.4g} s', fontsize=10)
        if dim == 2:
            ax.tick_params(labelsize=8)
    fig.legend(handles=legend_handles(bool(mask.any()), bool(mask.all())),
               loc='lower center', ncol=5, fontsize=8, frameon=False)
    fig.suptitle(f'{title}: configurations and velocities (r = {radius:g} m)'.lstrip(': '))
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    return save_figure(fig, Path(out) / filename)


def _time_axis(ax, t: np.ndarray) -> None:
    ax.grid(True, alpha=0.3)
    ax.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)


def plot_velocity_mismatch(series: dict[str, np.ndarray], out: Path, *, title: str = '',
                           informed: Sequence[int] | np.ndarray | None = None,
                           filename: str = 'velocity_mismatch.png') -> Path:
    """Plot every agent's ``p_i - p_gamma`` per component and its norm (Su 2009 Figs. 5-6 (d)).

    :param series: the time series (``t``, ``p``, ``leader_p``).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param informed: informed ids or mask (default: from the series); informed agents red.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    t = series['t']
    mismatch = series['p'] - series['leader_p'][:, None, :]
    mask = informed_mask(series, informed)
    dim = mismatch.shape[2]
    fig, axes = plt.subplots(dim + 1, 1, figsize=(7.5, 2.1 * (dim + 1)), sharex=True)
    panels = [(mismatch[:, :, c], rf'$p_{{i,{AXES[c]}}} - p_{{\gamma,{AXES[c]}}}$ [m/s]')
              for c in range(dim)]
    panels.append((np.linalg.norm(mismatch, axis=2), r'$\|p_i - p_\gamma\|$ [m/s]'))
    colors = _colors(mask)
    for ax, (values, label) in zip(axes, panels):
        for line, color in zip(ax.plot(t, values, lw=0.8, alpha=0.85), colors):
            line.set_color(color)
        ax.axhline(0.0, color='0.3', lw=0.6)
        ax.set_ylabel(label, fontsize=9)
        _time_axis(ax, t)
    axes[0].legend(handles=_line_handles(mask), loc='upper right', fontsize=8)
    axes[-1].set_xlabel('t [s]')
    axes[0].set_title(f'{title}: velocity convergence to the leader'.lstrip(': '))
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def plot_com_error(series: dict[str, np.ndarray], out: Path, *, title: str = '',
                   filename: str = 'com_error.png') -> Path:
    """Plot ``mean q - q_gamma``, ``mean p - p_gamma`` per component (Su 2009 Figs. 5-6 (e), (f)).

    :param series: the time series (``t``, ``q``, ``p``, ``leader_q``, ``leader_p``).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    t = series['t']
    dq = series['q'].mean(axis=1) - series['leader_q']
    dp = series['p'].mean(axis=1) - series['leader_p']
    fig, axes = plt.subplots(2, 1, figsize=(7.5, 5.6), sharex=True)
    for ax, values, symbol, unit in ((axes[0], dq, 'q', 'm'), (axes[1], dp, 'p', 'm/s')):
        for c in range(values.shape[1]):
            ax.plot(t, values[:, c], lw=1.2, color=AXIS_COLORS[c],
                    label=rf'$\bar {symbol}_{AXES[c]} - {symbol}_{{\gamma,{AXES[c]}}}$')
        ax.axhline(0.0, color='0.3', lw=0.6)
        ax.set_ylabel(rf'$\bar {symbol} - {symbol}_\gamma$ [{unit}]')
        ax.legend(loc='upper right', fontsize=8, ncol=values.shape[1])
        _time_axis(ax, t)
    axes[0].set_title(f'{title}: centre of mass minus virtual leader'.lstrip(': '))
    axes[1].set_xlabel('t [s]')
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def plot_min_distance(series: dict[str, np.ndarray], out: Path, *, title: str = '',
                      collision_distance: float | None = None,
                      filename: str = 'min_distance.png') -> Path:
    """Plot the smallest distance between two agents against time.

    :param series: the time series (``t``, ``metric_min_pair_distance``).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param collision_distance: drawn as a dashed line when given.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    t, d = series['t'], series['metric_min_pair_distance']
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    ax.plot(t, d, lw=1.2, color=AGENT_COLOR, label=r'$\min_{i \neq j} \|q_i - q_j\|$')
    if collision_distance is not None:
        ax.axhline(collision_distance, color=INFORMED_COLOR, ls='--', lw=1.0,
                   label=f'collision distance {collision_distance:g} m')
    finite = d[np.isfinite(d) & (d > 0)]
    if finite.size and finite.max() > LOG_SCALE_SPAN * finite.min():
        # Agents that merge (Su's laws allow it) take the distance down by decades.
        ax.set_yscale('log')
    else:
        ax.set_ylim(bottom=0.0)
    ax.set_xlabel('t [s]')
    ax.set_ylabel('distance [m]')
    ax.legend(loc='best', fontsize=8)
    _time_axis(ax, t)
    ax.set_title(f'{title}: minimum inter-agent distance'.lstrip(': '))
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def plot_components(series: dict[str, np.ndarray], out: Path, *, title: str = '',
                    radius: float | None = None, filename: str = 'components.png') -> Path:
    """Plot the number of connected components of the r-disk graph against time.

    :param series: the time series (``t``, ``metric_components``).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param radius: the radius ``r``, for the label.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    from matplotlib.ticker import MaxNLocator
    t, count = series['t'], series['metric_components']
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    ax.step(t, count, where='post', lw=1.2, color=AGENT_COLOR)
    ax.set_ylim(0, max(float(np.max(count)), 1.0) + 0.5)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel('t [s]')
    ax.set_ylabel('connected components')
    _time_axis(ax, t)
    graph = f'r-disk graph, r = {radius:g} m' if radius is not None else 'r-disk graph'
    ax.set_title(f'{title}: connected components ({graph})'.lstrip(': '))
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def plot_eta(series: dict[str, np.ndarray], out: Path, *, title: str = '',
             eta_tolerance: float | None = None, filename: str = 'eta.png') -> Path:
    """Plot ``eta``, the fraction of agents moving with the leader's velocity (Su 2009 V.A).

    :param series: the time series (``t``, ``metric_eta``).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param eta_tolerance: the tolerance of ``||p_i - p_gamma||``, for the label.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    t, eta = series['t'], series['metric_eta']
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    ax.plot(t, eta, lw=1.2, color=AGENT_COLOR)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel('t [s]')
    rule = (rf'$\|p_i - p_\gamma\| \leq {eta_tolerance:g}$' if eta_tolerance is not None
            else r'$\|p_i - p_\gamma\|$ within tolerance')
    ax.set_ylabel(r'$\eta$')
    _time_axis(ax, t)
    ax.set_title(f'{title}: fraction of agents with {rule}'.lstrip(': '))
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def plot_network(series: dict[str, np.ndarray], out: Path, *, title: str = '',
                 filename: str = 'network.png') -> Path:
    """Plot the network statistics of a run with a ``network:`` section (``docs/network.md``).

    Two panels over time: the fraction of the agents' messages delivered, and the mean and
    largest age of the neighbour states the law used. Each recorded instant holds the steps
    since the one before; instants without a value (NaN: no link used, or, from a realtime
    bag, no ``/swarm/metrics`` since) are left out.

    :param series: the time series (``t``, ``network_delivered``, ``network_age_mean``,
        ``network_age_max``).
    :param out: the output directory.
    :param title: the run's name, for the title.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    t = series['t']
    fig, axes = plt.subplots(2, 1, figsize=(7.5, 5.2), sharex=True)
    panels = ((axes[0], (('network_delivered', 'delivered', AGENT_COLOR),)),
              (axes[1], (('network_age_mean', 'mean age', AGENT_COLOR),
                         ('network_age_max', 'largest age', INFORMED_COLOR))))
    for ax, lines in panels:
        for key, label, color in lines:
            values = np.asarray(series[key], dtype=float)
            shown = np.isfinite(values)
            ax.plot(t[shown], values[shown], lw=1.2, marker='.', ms=3, color=color,
                    label=label)
        _time_axis(ax, t)
    axes[0].set_ylim(-0.03, 1.03)
    axes[0].set_ylabel('messages delivered')
    axes[1].set_ylabel('age of the states used [s]')
    axes[1].legend(loc='upper right', fontsize=8)
    axes[1].set_xlabel('t [s]')
    axes[0].set_title(f'{title}: the network between the agents'.lstrip(': '))
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)


def animate_flock(series: dict[str, np.ndarray], out: Path, *, radius: float,
                  strict: bool = True, title: str = '',
                  informed: Sequence[int] | np.ndarray | None = None,
                  max_frames: int = ANIMATION_MAX_FRAMES, dpi: int = ANIMATION_DPI,
                  fps: int = ANIMATION_FPS, filename: str = 'flock.gif',
                  mp4: bool = True, obstacles: ObstacleSpec | None = None) -> list[Path]:
    """Animate the flock (:func:`draw_flock` per frame) into a GIF, and an MP4 with ffmpeg.

    At most ``max_frames`` evenly spaced recorded instants are drawn. The view follows the
    flock with a fixed width (the largest extent of the flock and leader over the run), so
    distances compare across frames (a scale bar of length ``r`` in 2-D, the view's width in
    the title in 3-D); velocity arrows are scaled per frame; the leader's path is dashed.

    :param series: the time series (``t``, ``q``, ``p``, ``leader_q``).
    :param out: the output directory.
    :param radius: the interaction radius ``r`` of the neighbour edges.
    :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
    :param title: the run's name, for the title.
    :param informed: informed ids or mask (default: from the series).
    :param max_frames: the most frames to draw.
    :param dpi: resolution (the figure is 5 x 5 inches).
    :param fps: frames per second.
    :param filename: the GIF's file name in ``out`` (the MP4 has the same stem).
    :param mp4: also write an MP4 when ffmpeg is on ``PATH`` (skipped silently otherwise).
    :param obstacles: the scenario's obstacles (``None``: none), drawn in every frame.
    :return: the written paths (GIF first).
    """
    plt = pyplot()
    from matplotlib import animation
    t, q, p, lq = series['t'], series['q'], series['p'], series['leader_q']
    mask = informed_mask(series, informed)
    dim = q.shape[2]
    frames = np.unique(np.linspace(0, t.shape[0] - 1, min(t.shape[0], max_frames))
                       .round().astype(int))
    half = max(_bounds(np.vstack([q[k], lq[k][None]]), radius)[1] for k in frames)
    fig = plt.figure(figsize=(5.0, 5.0))
    ax = _new_axes(fig, dim, 1, 1, 1)
    # The view moves with the flock, so coordinates on the axes would change every frame:
    # no ticks (drawing them was also half the cost of a frame); a scale bar instead.
    ax.set_xticks([])
    ax.set_yticks([])
    if dim == 3:
        ax.set_zticks([])
        ax.plot(*lq.T, ls='--', lw=0.8, color='0.5', axlim_clip=True)
    else:
        from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar
        ax.plot(*lq.T, ls='--', lw=0.8, color='0.5')
        ax.add_artist(AnchoredSizeBar(ax.transData, radius, f'r = {radius:g} m',
                                      'lower right', frameon=False, size_vertical=0,
                                      label_top=True))
    drawn: list = []

    def draw(n: int) -> None:
        # Replacing the flock's artists, not clearing the axes, keeps the axes themselves.
        k = frames[n]
        for artist in drawn:
            artist.remove()
        center = _bounds(np.vstack([q[k], lq[k][None]]), radius)[0]
        drawn[:] = draw_flock(ax, q[k], p[k], lq[k], mask, radius, strict=strict,
                              center=center, half=half, size=14.0, obstacles=obstacles)
        box = f', view {2 * half:.3g} m wide' if dim == 3 else ''
        ax.set_title(f'{title}  t = {t[k]:.2f} s{box}'.strip(), fontsize=10)

    anim = animation.FuncAnimation(fig, draw, frames=len(frames), interval=1000.0 / fps)
    gif = Path(out) / filename
    anim.save(gif, writer=animation.PillowWriter(fps=fps), dpi=dpi)
    paths = [gif]
    if mp4 and shutil.which('ffmpeg') and animation.writers.is_available('ffmpeg'):
        video = gif.with_suffix('.mp4')
        anim.save(video, writer=animation.FFMpegWriter(fps=fps), dpi=dpi)
        paths.append(video)
    plt.close(fig)
    return paths


def plot_analysis(series: dict[str, np.ndarray], out: Path, *, radius: float,
                  strict: bool = True, title: str = '',
                  informed: Sequence[int] | np.ndarray | None = None,
                  eta_tolerance: float | None = None, collision_distance: float | None = None,
                  snapshots: Sequence[float] | None = None, animate: bool = True,
                  progress: Callable[[Path], None] | None = None,
                  obstacles: ObstacleSpec | None = None) -> list[Path]:
    """Write every figure of ``analyze`` for one run (and ``flock.gif`` unless told not to).

    Files: ``trajectories.png``, ``snapshots.png``, ``velocity_mismatch.png``,
    ``com_error.png``, ``min_distance.png``, ``components.png``, ``eta.png``, with a
    ``network:`` section ``network.png``, ``flock.gif`` (and ``flock.mp4`` when ffmpeg is on
    ``PATH``).

    :param series: the time series (the arrays of ``timeseries.npz``).
    :param out: the output directory (it must exist).
    :param radius: the interaction radius ``r``.
    :param strict: ``< r`` (``True``) or ``<= r`` neighbourhoods.
    :param title: the run's name.
    :param informed: informed ids or mask (default: from the series).
    :param eta_tolerance: tolerance of ``eta``, for the label.
    :param collision_distance: drawn on the minimum-distance plot.
    :param snapshots: snapshot times [s] (default first, middle, last).
    :param animate: write the animation.
    :param progress: called with each path once written.
    :param obstacles: the scenario's obstacles (``None``: none), drawn in the trajectories,
        the snapshots and the animation.
    :return: the written paths.
    """
    mask = informed_mask(series, informed)
    jobs: list[Callable[[], Path | list[Path]]] = [
        lambda: plot_trajectories(series, out, title=title, informed=mask, obstacles=obstacles),
        lambda: plot_snapshots(series, out, radius=radius, times=snapshots, strict=strict,
                               title=title, informed=mask, obstacles=obstacles),
        lambda: plot_velocity_mismatch(series, out, title=title, informed=mask),
        lambda: plot_com_error(series, out, title=title),
        lambda: plot_min_distance(series, out, title=title,
                                  collision_distance=collision_distance),
        lambda: plot_components(series, out, title=title, radius=radius),
        lambda: plot_eta(series, out, title=title, eta_tolerance=eta_tolerance),
    ]
    if 'network_delivered' in series:
        jobs.append(lambda: plot_network(series, out, title=title))
    if animate:
        jobs.append(lambda: animate_flock(series, out, radius=radius, strict=strict,
                                          title=title, informed=mask, obstacles=obstacles))
    written: list[Path] = []
    for job in jobs:
        result = job()
        for path in result if isinstance(result, list) else [result]:
            written.append(path)
            if progress is not None:
                progress(path)
    return written


def plot_errorbars(lines: dict[str, tuple[list, list, list]], out: Path, *, xlabel: str,
                   ylabel: str, title: str = '', filename: str = 'metric.png') -> Path:
    """Plot one metric against a swept value, one line with error bars per label.

    The layout of Su, Wang, Lin 2009 Fig. 3 (eta against the informed fraction, one line
    per group size), for any metric of a sweep.

    :param lines: ``{label: (x, mean, error)}``, each list ordered by x.
    :param out: the output directory.
    :param xlabel: the x axis (the swept key).
    :param ylabel: the y axis (the metric).
    :param title: the figure's title.
    :param filename: the file name in ``out``.
    :return: the written path.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    numeric = all(isinstance(v, (int, float)) for x, _, _ in lines.values() for v in x)
    for k, (label, (x, mean, error)) in enumerate(lines.items()):
        where = x if numeric else list(range(len(x)))
        ax.errorbar(where, mean, yerr=error, marker='o', ms=3, capsize=2, lw=1,
                    color=f'C{k % 10}', label=label or None)
        if not numeric:
            ax.set_xticks(where, [str(v) for v in x])
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    if any(lines):
        ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, Path(out) / filename)
