"""Figures of Monte Carlo Localization: particle clouds, snapshot strips, animations, errors.

Every function draws with matplotlib and returns what it made; none runs a
filter. The data come from :func:`localize.runloop.run_mcl` (an
:class:`~localize.runloop.RunTrace` with snapshots) and a simulated run.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from matplotlib.ticker import FuncFormatter
from numpy.typing import ArrayLike

from ..geometry import as_poses
from ..grid import OccupancyGrid
from ..metrics import heading_error, position_error
from . import draw_map, draw_robot, new_axes

__all__ = [
    "draw_particles",
    "draw_belief",
    "snapshot_strip",
    "animate_snapshots",
    "plot_errors",
    "plot_particle_count",
]


def draw_particles(particles: ArrayLike, ax=None, weights: ArrayLike | None = None, color="tab:red",
                   size: float = 3.0, headings: int = 0, heading_length: float = 0.3):
    """Draw a particle cloud as dots (fast for tens of thousands), optionally with heading ticks.

    Parameters
    ----------
    particles : array_like (N, 3)
    weights : array_like (N,), optional
        When given, dot opacity follows weight / max weight (faint = unlikely).
    size : float
        Dot size in points squared.
    headings : int
        Draw heading ticks on this many particles (a deterministic subsample).
    heading_length : float
        Tick length in metres.

    Returns
    -------
    list of artists

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> arts = draw_particles(np.zeros((5, 3)), headings=5)
    >>> len(arts)
    2
    >>> plt.close("all")
    """
    _, ax = new_axes(ax)
    p = as_poses(particles, "particles").reshape(-1, 3)
    rgba = None
    if weights is not None:
        import matplotlib.colors as mcolors

        w = np.asarray(weights, dtype=float)
        if w.shape != (p.shape[0],):
            raise ValueError(f"weights must have shape ({p.shape[0]},); got {w.shape}")
        w = w / w.max() if w.max() > 0 else np.ones_like(w)
        rgba = np.tile(mcolors.to_rgba(color), (len(w), 1))
        rgba[:, 3] = 0.15 + 0.85 * w
    arts = [ax.scatter(p[:, 0], p[:, 1], s=size, c=rgba if rgba is not None else color,
                       linewidths=0, zorder=2, alpha=None if rgba is not None else 0.5)]
    if headings and p.shape[0]:
        k = np.linspace(0, p.shape[0] - 1, min(int(headings), p.shape[0])).astype(int)
        q = p[k]
        from matplotlib.collections import LineCollection

        seg = np.stack([q[:, :2], q[:, :2] + heading_length * np.column_stack([np.cos(q[:, 2]), np.sin(q[:, 2])])], 1)
        lc = LineCollection(seg, colors=color, linewidths=0.6, alpha=0.6, zorder=2)
        ax.add_collection(lc)
        arts.append(lc)
    return arts


def draw_belief(grid: OccupancyGrid, particles: ArrayLike, weights: ArrayLike | None = None,
                true_pose: ArrayLike | None = None, estimate: ArrayLike | None = None, ax=None,
                title: str | None = None, size: float = 3.0):
    """Map, particle cloud, the true robot (blue) and the estimate (green cross).

    Returns the axes.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from localize.maps import office
    >>> ax = draw_belief(office(), np.array([[5.0, 5.0, 0.0]]), true_pose=[5, 5, 0], estimate=[5, 5, 0],
    ...                  title="one particle")
    >>> ax.get_title()
    'one particle'
    >>> plt.close("all")
    """
    _, ax = new_axes(ax, figsize=(7, 4.5))
    draw_map(grid, ax=ax)
    draw_particles(particles, ax=ax, weights=weights, size=size)
    if true_pose is not None:
        draw_robot(true_pose, ax=ax, radius=0.3, color="tab:blue")
    if estimate is not None:
        e = as_poses(estimate, "estimate").reshape(3)
        ax.plot([e[0]], [e[1]], marker="x", color="tab:green", markersize=10, mew=2.5, zorder=4)
    xmin, xmax, ymin, ymax = grid.extent
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    if title is not None:
        ax.set_title(title, fontsize=9)
    return ax


def snapshot_strip(grid: OccupancyGrid, snapshots: dict, true_poses: ArrayLike | None = None,
                   estimates: ArrayLike | None = None, steps: Sequence[int] | None = None, ncols: int = 4,
                   width: float = 12.0, size: float = 2.0):
    """A grid of small maps, one per snapshot step: the cloud converging over time.

    Parameters
    ----------
    snapshots : dict
        ``step -> (particles, weights)`` as in :attr:`localize.runloop.RunTrace.snapshots`.
    true_poses, estimates : array_like (T, 3), optional
        Drawn at each snapshot's step.
    steps : sequence of int, optional
        Which snapshots, in order (default all, sorted).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from localize.maps import office
    >>> snaps = {0: (np.array([[5.0, 5.0, 0.0]]), np.ones(1)), 3: (np.array([[6.0, 5.0, 0.0]]), np.ones(1))}
    >>> fig = snapshot_strip(office(), snaps)
    >>> [ax.get_title() for ax in fig.axes]
    ['step 0 (1 particles)', 'step 3 (1 particles)']
    >>> plt.close(fig)
    """
    import matplotlib.pyplot as plt

    steps = sorted(snapshots) if steps is None else list(steps)
    if not steps:
        raise ValueError("snapshots is empty: nothing to draw")
    ncols = max(1, min(int(ncols), len(steps)))
    nrows = int(np.ceil(len(steps) / ncols))
    aspect = grid.height_m / grid.width_m
    fig, axes = plt.subplots(nrows, ncols, figsize=(width, width / ncols * aspect * nrows + 0.4 * nrows),
                             squeeze=False)
    for ax, k in zip(axes.flat, steps):
        p, w = snapshots[k]
        draw_belief(grid, p, w, None if true_poses is None else np.asarray(true_poses)[k],
                    None if estimates is None else np.asarray(estimates)[k], ax=ax,
                    title=f"step {k} ({len(p)} particles)", size=size)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_xlabel("")
        ax.set_ylabel("")
    for ax in list(axes.flat)[len(steps):]:
        ax.remove()
    fig.tight_layout()
    return fig


def _frame_title(step: int, drawn: int, n_particles: int | dict | None) -> str:
    """'step 3: 2000 particles (1000 drawn)' when a subsample is drawn, else 'step 3: 2000 particles'."""
    n = n_particles.get(step) if isinstance(n_particles, dict) else n_particles
    if n is None or int(n) == drawn:
        return f"step {step}: {drawn} particles"
    return f"step {step}: {int(n)} particles ({drawn} drawn)"


def animate_snapshots(grid: OccupancyGrid, snapshots: dict, true_poses: ArrayLike | None = None,
                      estimates: ArrayLike | None = None, interval: int = 250, figsize=(6.0, 3.8),
                      size: float = 2.0, dpi: int = 72, n_particles: int | dict | None = None,
                      truth_label: str = "true path"):
    """A matplotlib animation of the particle cloud, one frame per snapshot.

    Each frame shows the map, the weighted particles, the true (or reference)
    pose and path so far, the estimate and its trail, a legend and labelled
    axes. ``n_particles`` is the filter's particle count for the titles (an
    int, or a dict step -> count, e.g. a run's ``trace.n_particles``, which
    KLD-sampling changes) when the snapshots hold a subsample; by default the
    title counts the particles drawn, and says "drawn" if fewer than stated.

    Embed it in a notebook with ``IPython.display.HTML(localize.plot.animation_html(anim))``;
    ``dpi`` sets the frames' resolution (and so the size of the embedded HTML).
    Returns the :class:`matplotlib.animation.FuncAnimation` (its figure is
    ``anim._fig``; close it after embedding to avoid a duplicate still).

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from localize.maps import office
    >>> snaps = {k: (np.array([[5.0 + k, 5.0, 0.0]]), np.ones(1)) for k in range(3)}
    >>> path = np.array([[5.0 + k, 5.0, 0.0] for k in range(3)])
    >>> anim = animate_snapshots(office(), snaps, path, path, figsize=(3, 2))
    >>> "<script" in anim.to_jshtml(fps=4)
    True
    >>> [t.get_text() for t in anim._fig.axes[0].get_legend().get_texts()]
    ['true path', 'estimated path', 'particles']
    >>> _frame_title(3, 1000, 2000), _frame_title(3, 50, None)
    ('step 3: 2000 particles (1000 drawn)', 'step 3: 50 particles')
    >>> plt.close("all")
    """
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation

    steps = sorted(snapshots)
    if not steps:
        raise ValueError("snapshots is empty: nothing to animate")
    fig, ax = plt.subplots(figsize=figsize, dpi=dpi, layout="constrained")   # room for the axis labels
    tp = None if true_poses is None else np.asarray(true_poses)
    es = None if estimates is None else np.asarray(estimates)

    def frame(i):
        ax.clear()
        k = steps[i]
        p, w = snapshots[k]
        draw_belief(grid, p, w, None if tp is None else tp[k], None if es is None else es[k], ax=ax,
                    title=_frame_title(k, len(p), n_particles), size=size)
        if tp is not None:
            ax.plot(tp[:k + 1, 0], tp[:k + 1, 1], color="tab:blue", lw=1.2, alpha=0.8, label=truth_label)
        if es is not None:
            ax.plot(es[:k + 1, 0], es[:k + 1, 1], color="tab:green", lw=1.2, alpha=0.9, label="estimated path")
        ax.scatter([], [], s=12, color="tab:red", label="particles")     # the legend's entry for the cloud
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
        return ax.get_children()

    anim = FuncAnimation(fig, frame, frames=len(steps), interval=interval, blit=False)
    return anim


def plot_errors(estimates: ArrayLike, truth: ArrayLike, ax=None, label: str | None = None,
                kidnap_steps: Sequence[int] = (), heading: bool = True, **kwargs: Any):
    """Error versus time: position error (m, left axis, log scale) and heading error (deg, right axis).

    Errors below 1 mm are drawn at 1 mm (the bottom of the log axis). The
    heading error is dotted, in grey, on its own axis. Kidnapping steps are
    marked with vertical dotted lines. Returns the axes.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> t = np.zeros((5, 3)); e = t + [0.1, 0.0, 0.05]
    >>> ax = plot_errors(e, t, kidnap_steps=[2])
    >>> ax.get_ylabel()
    'position error [m] (log scale)'
    >>> [t.get_text() for t in ax.get_yticklabels()]     # plain numbers, from 1 mm up
    ['0.001', '0.01', '0.1', '1']
    >>> plt.close("all")
    """
    _, ax = new_axes(ax, figsize=(7, 3))
    pe = np.atleast_1d(position_error(estimates, truth))
    he = np.atleast_1d(heading_error(estimates, truth))
    steps = np.arange(len(pe))
    floor = 1e-3
    ax.plot(steps, np.maximum(pe, floor), label=label or "position error", **kwargs)
    if heading:
        ax2 = ax.twinx()
        ax2.plot(steps, np.degrees(he), color="0.45", ls=":", lw=1.2)
        ax2.set_ylabel("heading error [deg] (grey, dotted)", color="0.35")
        ax2.set_ylim(bottom=0.0)
    for k in kidnap_steps:
        ax.axvline(k, color="k", ls=":", lw=1)
    ax.set_xlabel("step")
    ax.set_ylabel("position error [m] (log scale)")
    ax.set_yscale("log")
    top = max(1.0, float(np.nanmax(pe)) * 1.5) if pe.size and np.isfinite(pe).any() else 1.0
    if len(ax.lines) > 1 + len(kidnap_steps):          # more errors drawn on these axes before: keep them in view
        top = max(top, ax.get_ylim()[1])
    ax.set_ylim(floor, top)
    ax.set_yticks([10.0**k for k in range(-3, int(np.floor(np.log10(top))) + 1)])
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: ""))
    ax.grid(True, alpha=0.3)
    return ax


def plot_particle_count(counts: ArrayLike, ax=None, label: str | None = None, **kwargs: Any):
    """Number of particles per step (KLD-sampling). Returns the axes.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> plot_particle_count([1000, 500, 200]).get_yscale()
    'log'
    >>> plt.close("all")
    """
    _, ax = new_axes(ax, figsize=(7, 3))
    c = np.asarray(counts)
    ax.plot(np.arange(len(c)), c, label=label, **kwargs)
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("particles")
    ax.grid(True, alpha=0.3)
    return ax
