"""Matplotlib drawing helpers shared by the book's figures.

Algorithms never import this package; notebooks and :mod:`localize.widgets`
do. Each function draws onto an ``ax`` it is given (or a new one) and returns
the artists it made, so that figures can be composed and animated.
Topic-specific figures live in submodules (``localize.plot.motion`` ...).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..geometry import as_poses
from ..grid import OccupancyGrid

__all__ = ["new_axes", "draw_map", "draw_poses", "draw_robot", "draw_scan", "animation_html", "MAP_CMAP"]

MAP_CMAP = "gray_r"


def new_axes(ax=None, figsize=(6, 4)):
    """Return ``(fig, ax)``: the given axes' figure, or a new figure."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
    else:
        fig = ax.figure
    return fig, ax


def draw_map(grid: OccupancyGrid, ax=None, unknown_color: str = "#c9d6e8", **kwargs):
    """Draw an occupancy grid in world coordinates (metres), obstacles dark.

    Unknown cells are drawn in ``unknown_color``. Returns the image artist.
    """
    import matplotlib.colors as mcolors

    _, ax = new_axes(ax)
    cmap = mcolors.LinearSegmentedColormap.from_list("occ", ["white", "black"]).with_extremes(bad=unknown_color)
    img = ax.imshow(np.ma.masked_invalid(grid.data), origin="lower", extent=grid.extent,
                    cmap=cmap, vmin=0.0, vmax=1.0, interpolation="nearest", **kwargs)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    return img


def draw_poses(poses: ArrayLike, ax=None, length: float | None = None, color="tab:red",
               alpha: float = 0.6, weights: ArrayLike | None = None, **kwargs):
    """Draw poses as small arrows (a particle cloud). Returns the quiver artist.

    ``length`` is the arrow length in metres (default: 2% of the axes' width).
    With ``weights`` the arrows' opacity follows the normalised weights.
    """
    _, ax = new_axes(ax)
    p = as_poses(poses).reshape(-1, 3)
    if length is None:
        x0, x1 = ax.get_xlim()
        length = 0.02 * abs(x1 - x0) if abs(x1 - x0) > 0 else 0.2
    u, v = length * np.cos(p[:, 2]), length * np.sin(p[:, 2])
    colors = color
    if weights is not None:
        import matplotlib.colors as mcolors

        w = np.asarray(weights, dtype=float)
        w = w / w.max() if w.max() > 0 else np.ones_like(w)
        rgba = np.tile(mcolors.to_rgba(color), (len(w), 1))
        rgba[:, 3] = 0.1 + 0.9 * w
        colors = rgba
        alpha = None
    return ax.quiver(p[:, 0], p[:, 1], u, v, color=colors, alpha=alpha, angles="xy",
                     scale_units="xy", scale=1.0, width=0.003, **kwargs)


def draw_robot(pose: ArrayLike, ax=None, radius: float = 0.25, color="tab:blue", **kwargs):
    """Draw a robot as a circle with a heading line. Returns (circle, line)."""
    import matplotlib.patches as mpatches

    _, ax = new_axes(ax)
    x, y, th = as_poses(pose).reshape(3)
    circ = mpatches.Circle((x, y), radius, fill=False, color=color, lw=2, **kwargs)
    ax.add_patch(circ)
    (line,) = ax.plot([x, x + radius * np.cos(th)], [y, y + radius * np.sin(th)], color=color, lw=2)
    return circ, line


def draw_scan(pose: ArrayLike, angles: ArrayLike, ranges: ArrayLike, ax=None, max_range: float | None = None,
              color="tab:orange", rays: bool = True, **kwargs):
    """Draw a range scan taken at ``pose``: beam end points, optionally the rays.

    Readings at or beyond ``max_range`` (no return) are drawn as faint rays only.
    """
    _, ax = new_axes(ax)
    x, y, th = as_poses(pose).reshape(3)
    a = th + np.asarray(angles, dtype=float)
    r = np.asarray(ranges, dtype=float)
    hit = np.ones(r.shape, bool) if max_range is None else r < max_range
    ex, ey = x + r * np.cos(a), y + r * np.sin(a)
    artists = []
    if rays:
        segs = np.stack([np.stack([np.full_like(ex, x), np.full_like(ey, y)], -1), np.stack([ex, ey], -1)], 1)
        from matplotlib.collections import LineCollection

        lc = LineCollection(segs, colors=color, alpha=0.15, linewidths=0.8)
        ax.add_collection(lc)
        artists.append(lc)
    artists.append(ax.scatter(ex[hit], ey[hit], s=6, color=color, zorder=3, **kwargs))
    return artists


_FA_ICONS = {
    "fa-minus": "&#8722;", "fa-plus": "+", "fa-fast-backward": "&#9198;", "fa-step-backward": "&#9664;&#9646;",
    "fa-play": "&#9654;", "fa-pause": "&#10074;&#10074;", "fa-step-forward": "&#9646;&#9654;",
    "fa-fast-forward": "&#9197;",
}


def animation_html(anim, **kwargs) -> str:
    """``anim.to_jshtml(**kwargs)`` made to work offline.

    Matplotlib's JavaScript player loads its button icons from a CDN
    (Font Awesome), which an offline book or a closed network cannot reach.
    This replaces the icons by Unicode symbols and drops the remote
    stylesheet; the player is otherwise unchanged.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from matplotlib import animation
    >>> fig, ax = plt.subplots()
    >>> (line,) = ax.plot([0, 1])
    >>> anim = animation.FuncAnimation(fig, lambda i: line.set_ydata([0, i]), frames=2)
    >>> html = animation_html(anim)
    >>> "https://" in html, "<script" in html
    (False, True)
    >>> plt.close(fig)
    """
    import re

    html = anim.to_jshtml(**kwargs)
    html = re.sub(r'<link[^>]*font-awesome[^>]*>', "", html)
    for cls, symbol in _FA_ICONS.items():
        html = re.sub(rf'<i class="fa {cls}"></i>', symbol, html)
    return html
