"""Figures of discrete beliefs: bars over a hallway, numbers over coloured tiles, heat maps.

Used by the chapters on the Bayes filter and on histogram localization and by
:mod:`localize.widgets.histogram`. Each function draws on the ``ax`` it is
given (or a new one) and returns what it drew.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from . import new_axes

__all__ = ["draw_bars", "draw_tiles", "draw_heat", "TILE_COLORS"]

#: Soft versions of the tile colours, so that black numbers stay readable on them.
TILE_COLORS = {"red": "#f4a6a6", "green": "#a8dba8", "blue": "#a6c8f4", "yellow": "#f6e7a1"}


def draw_bars(belief: ArrayLike, ax=None, world: ArrayLike | None = None, truth: int | None = None,
              color: str = "tab:blue", ylim: float | None = None, title: str | None = None):
    """Bar chart of a 1-D belief; door cells (``world == 1``) shaded, the true cell marked.

    Examples
    --------
    >>> bars = draw_bars([0.25, 0.75], world=[1, 0], truth=1)
    >>> len(bars)
    2
    """
    _, ax = new_axes(ax, figsize=(7, 2.4))
    b = np.asarray(belief, dtype=float)
    x = np.arange(len(b))
    if world is not None:
        for i in np.flatnonzero(np.asarray(world) == 1):
            ax.axvspan(i - 0.5, i + 0.5, color="0.88", zorder=0)
    bars = ax.bar(x, b, color=color, width=0.8, zorder=2)
    if truth is not None:
        ax.plot([truth], [b.max() * 1.05 if b.max() > 0 else 0.05], "v", color="tab:red", zorder=3)
    ax.set_xlim(-0.6, len(b) - 0.4)
    step = max(1, len(b) // 10)
    ax.set_xticks(np.arange(0, len(b), step))
    ax.set_ylim(0, ylim if ylim is not None else max(b.max() * 1.15, 1e-3))
    ax.set_xlabel("cell")
    ax.set_ylabel("belief")
    if title:
        ax.set_title(title)
    return bars


def draw_tiles(world: ArrayLike, belief: ArrayLike | None = None, ax=None, digits: int = 3,
               truth: tuple[int, int] | None = None, title: str | None = None, colors=None):
    """The tile world (row 0 at the top), each tile coloured by its label, optionally with belief numbers.

    Examples
    --------
    >>> from localize.maps import tile_world
    >>> img = draw_tiles(tile_world(), np.full((5, 7), 1 / 35))
    >>> img.get_array().shape
    (5, 7, 3)
    """
    import matplotlib.colors as mcolors

    _, ax = new_axes(ax, figsize=(5, 3.2))
    w = np.asarray(world)
    cmap = dict(TILE_COLORS, **(colors or {}))
    labels = sorted(set(w.ravel().tolist()), key=str)
    fallback = ["#dddddd", "#bbbbbb", "#999999", "#eeeeee"]
    rgb = np.zeros(w.shape + (3,))
    for n, lab in enumerate(labels):
        rgb[w == lab] = mcolors.to_rgb(cmap.get(lab, fallback[n % len(fallback)]))
    img = ax.imshow(rgb, origin="upper", interpolation="nearest")
    ax.set_xticks(np.arange(w.shape[1]))
    ax.set_yticks(np.arange(w.shape[0]))
    ax.vlines(np.arange(1, w.shape[1]) - 0.5, -0.5, w.shape[0] - 0.5, color="white", lw=2)
    ax.hlines(np.arange(1, w.shape[0]) - 0.5, -0.5, w.shape[1] - 0.5, color="white", lw=2)
    if belief is not None:
        b = np.asarray(belief, dtype=float)
        top = b.max()
        for (r, c), v in np.ndenumerate(b):
            ax.text(c, r, f"{v:.{digits}f}".lstrip("0") if v < 1 else f"{v:.2f}", ha="center", va="center",
                    fontsize=8, fontweight="bold" if v == top else "normal")
    if truth is not None:
        ax.add_patch(__import__("matplotlib.patches", fromlist=["Circle"]).Circle(
            (truth[1], truth[0]), 0.42, fill=False, color="black", lw=2))
    if title:
        ax.set_title(title)
    return img


def draw_heat(belief: ArrayLike, ax=None, extent=None, origin: str = "upper", cmap: str = "viridis",
              title: str | None = None, colorbar: bool = False, log_floor: float | None = None):
    """A 2-D belief as a heat map. Returns the image.

    With ``log_floor`` (e.g. ``1e-8``) the colours show ``log10(belief)``
    clipped below at ``log10(log_floor)``, which makes small but non-zero
    belief visible next to a tall peak.

    Examples
    --------
    >>> img = draw_heat(np.eye(3) / 3)
    >>> img.get_array().shape
    (3, 3)
    """
    fig, ax = new_axes(ax)
    b = np.asarray(belief, dtype=float)
    label = "belief"
    if log_floor is not None:
        b = np.log10(np.maximum(b, log_floor))
        label = "log10 belief"
    img = ax.imshow(b, origin=origin, extent=extent, cmap=cmap, interpolation="nearest")
    if colorbar:
        fig.colorbar(img, ax=ax, shrink=0.8, label=label)
    if title:
        ax.set_title(title)
    return img
