"""Figures for the motion-model chapter: sample clouds, densities, paths.

Every function returns the matplotlib ``Figure`` it drew (or the artists, for
the ``draw_*`` helpers that draw onto a given ``ax``). Nothing here samples
implicitly: random draws take an explicit ``rng``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry import as_poses
from ..motion import (
    move_odometry,
    odometry_pdf_xy,
    odometry_to_control,
    sample_odometry,
)
from . import draw_robot, new_axes

__all__ = [
    "PR_FIG_5_9_ALPHAS",
    "draw_samples",
    "draw_odometry_path",
    "draw_density_xy",
    "density_grid_xy",
    "banana_figure",
    "density_and_samples_figure",
    "square_path_figure",
    "update_rate_figure",
]

#: Three noise settings in the spirit of PR figure 5.9: typical, large
#: rotational noise (alpha1 and alpha2 ten times larger: with a drive of a
#: metre or more the sideways spread then dwarfs the spread along the way, the
#: banana), large translational noise (alpha3 ten times larger); alpha1..alpha4.
PR_FIG_5_9_ALPHAS: tuple[tuple[float, float, float, float], ...] = (
    (0.02, 0.005, 0.02, 0.01),
    (0.2, 0.05, 0.02, 0.01),
    (0.02, 0.005, 0.2, 0.01),
)


def _figure(figsize, ncols: int = 1, nrows: int = 1, **kwargs):
    """A pyplot-free Figure (nothing accumulates in pyplot's registry)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kwargs)
    return fig, axes.ravel()


def draw_samples(samples: ArrayLike, ax=None, color="tab:red", size: float = 3.0, alpha: float = 0.5, **kwargs):
    """Scatter the positions of sampled poses. Returns the PathCollection.

    Examples
    --------
    >>> pts = draw_samples(np.zeros((10, 3)))
    >>> pts.get_offsets().shape
    (10, 2)
    """
    _, ax = new_axes(ax)
    p = as_poses(samples, "samples").reshape(-1, 3)
    return ax.scatter(p[:, 0], p[:, 1], s=size, color=color, alpha=alpha, linewidths=0, **kwargs)


def draw_odometry_path(start: ArrayLike, u, ax=None, color="k", robot_radius: float = 0.08):
    """Draw the noise-free motion of a robot at ``start``: robot, rot1-trans-rot2 path, end pose.

    Returns the noise-free end pose.

    Examples
    --------
    >>> draw_odometry_path([0, 0, 0], ((0, 0, 0), (1, 0, 0.5))).round(3)
    array([1. , 0. , 0.5])
    """
    _, ax = new_axes(ax)
    s = as_poses(start, "start").reshape(3)
    end = move_odometry(s, *odometry_to_control(*u))
    ax.plot([s[0], end[0]], [s[1], end[1]], ls="--", color=color, lw=1)
    draw_robot(s, ax=ax, radius=robot_radius, color=color)
    draw_robot(end, ax=ax, radius=robot_radius, color="0.4")
    return end


def density_grid_xy(u, alphas: ArrayLike, extent: Sequence[float], resolution: int = 120,
                    start: ArrayLike = (0.0, 0.0, 0.0), **kwargs) -> tuple[NDArray, NDArray, NDArray]:
    """Evaluate :func:`localize.motion.odometry_pdf_xy` on a regular grid over ``extent``.

    Returns ``(X, Y, P)`` of shape ``(resolution, resolution)``; cell centres.

    Examples
    --------
    >>> X, Y, P = density_grid_xy(((0, 0, 0), (1, 0, 0)), [0.1, 0.01, 0.01, 0.1], (0, 2, -1, 1), 50)
    >>> P.shape, round(float(P.sum() * 0.04 ** 2), 2)
    ((50, 50), 1.0)
    """
    x0, x1, y0, y1 = (float(e) for e in extent)
    xs = x0 + (np.arange(resolution) + 0.5) * (x1 - x0) / resolution
    ys = y0 + (np.arange(resolution) + 0.5) * (y1 - y0) / resolution
    X, Y = np.meshgrid(xs, ys)
    P = odometry_pdf_xy(np.stack([X, Y], -1), u, start, alphas, **kwargs)
    return X, Y, P


def draw_density_xy(P: ArrayLike, extent: Sequence[float], ax=None, cmap: str = "viridis", **kwargs):
    """Show a density grid (rows = y) with ``origin="lower"``. Returns the image.

    Examples
    --------
    >>> draw_density_xy(np.eye(4), (0, 1, 0, 1)).get_extent()
    [0, 1, 0, 1]
    """
    _, ax = new_axes(ax)
    img = ax.imshow(np.asarray(P), origin="lower", extent=tuple(extent), cmap=cmap, interpolation="nearest",
                    aspect="equal", **kwargs)
    return img


def _extent_around(samples: NDArray, start: NDArray, pad: float = 0.15) -> tuple[float, float, float, float]:
    pts = np.vstack([samples[:, :2], start[None, :2]])
    lo = np.percentile(pts, 0.5, axis=0)
    hi = np.percentile(pts, 99.5, axis=0)
    lo = np.minimum(lo, start[:2])
    hi = np.maximum(hi, start[:2])
    c = 0.5 * (lo + hi)
    half = 0.5 * max(hi[0] - lo[0], hi[1] - lo[1]) + pad
    return (c[0] - half, c[0] + half, c[1] - half, c[1] + half)


def banana_figure(u, alpha_sets: Sequence[ArrayLike], rng: np.random.Generator, n: int = 500,
                  start: ArrayLike = (0.0, 0.0, 0.0), titles: Sequence[str] | None = None,
                  panel_size: float = 3.2):
    """One panel of ``n`` odometry-model samples per alpha setting (like PR figure 5.9).

    All panels share their axes so that spreads can be compared by eye.

    Examples
    --------
    >>> fig = banana_figure(((0, 0, 0), (1, 0, 0)), PR_FIG_5_9_ALPHAS, np.random.default_rng(0), n=50)
    >>> len(fig.axes)
    3
    """
    s = as_poses(start, "start").reshape(3)
    clouds = [sample_odometry(np.tile(s, (n, 1)), u, a, rng) for a in alpha_sets]
    fig, axes = _figure((panel_size * len(alpha_sets), panel_size), ncols=len(alpha_sets), sharex=True, sharey=True)
    ext = _extent_around(np.vstack(clouds), s)
    for k, (ax, cloud, a) in enumerate(zip(axes, clouds, alpha_sets)):
        draw_samples(cloud, ax=ax)
        draw_odometry_path(s, u, ax=ax)
        ax.set_xlim(ext[0], ext[1])
        ax.set_ylim(ext[2], ext[3])
        ax.set_aspect("equal")
        a = np.asarray(a, dtype=float)
        ax.set_title(titles[k] if titles else "alphas = " + ", ".join(f"{v:g}" for v in a), fontsize=9)
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    return fig


def density_and_samples_figure(u, alphas: ArrayLike, rng: np.random.Generator, n: int = 500,
                               start: ArrayLike = (0.0, 0.0, 0.0), resolution: int = 120,
                               panel_size: float = 3.6):
    """Left: the position density on a grid; right: ``n`` samples on the same axes.

    Examples
    --------
    >>> fig = density_and_samples_figure(((0, 0, 0), (1, 0, 0)), [0.1, 0.01, 0.01, 0.1],
    ...                                  np.random.default_rng(0), n=50, resolution=20)
    >>> len(fig.axes[0].images), len(fig.axes[1].collections)
    (1, 1)
    """
    s = as_poses(start, "start").reshape(3)
    cloud = sample_odometry(np.tile(s, (n, 1)), u, alphas, rng)
    ext = _extent_around(cloud, s)
    _, _, P = density_grid_xy(u, alphas, ext, resolution, start=s)
    fig, axes = _figure((2 * panel_size, panel_size), ncols=2, sharex=True, sharey=True)
    draw_density_xy(P, ext, ax=axes[0])
    axes[0].set_title("density p(x, y | u, x0)", fontsize=9)
    draw_samples(cloud, ax=axes[1])
    axes[1].set_title(f"{n} samples", fontsize=9)
    for ax in axes:
        draw_odometry_path(s, u, ax=ax, color="w" if ax is axes[0] else "k")
        ax.set_xlim(ext[0], ext[1])
        ax.set_ylim(ext[2], ext[3])
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    return fig


def square_path_figure(alphas: ArrayLike, rng: np.random.Generator, n: int = 300, side: float = 2.0,
                       steps_per_side: int = 4, laps: int = 1, figsize=(5.0, 5.0)):
    """Particles driven along a square with the odometry model, their cloud drawn at every step.

    The odometry readings are those of a perfect square (``steps_per_side``
    straight steps per side, a 90 degree turn at each corner folded into the
    next step's rot1). Colours go from dark (start) to light (end).

    Examples
    --------
    >>> fig = square_path_figure([0.02, 0.005, 0.02, 0.01], np.random.default_rng(0), n=20, steps_per_side=2)
    >>> len(fig.axes[0].collections)      # one cloud per odometry step
    8
    """
    import matplotlib as mpl

    odo = [np.array([0.0, 0.0, 0.0])]
    for _lap in range(laps):
        for k in range(4):
            heading = k * np.pi / 2
            d = np.array([np.cos(heading), np.sin(heading)]) * side / steps_per_side
            for j in range(steps_per_side):
                x, y = odo[-1][:2] + d
                th = heading + (np.pi / 2 if j == steps_per_side - 1 else 0.0)
                odo.append(np.array([x, y, th]))
    particles = np.zeros((n, 3))
    fig, axes = _figure(figsize)
    ax = axes[0]
    cmap = mpl.colormaps["viridis"]
    steps = len(odo) - 1
    path = np.array(odo)
    ax.plot(path[:, 0], path[:, 1], "k--", lw=1, label="odometry (noise-free)")
    for t in range(steps):
        particles = sample_odometry(particles, (odo[t], odo[t + 1]), alphas, rng)
        draw_samples(particles, ax=ax, color=cmap(t / max(steps - 1, 1)), size=2.0, alpha=0.6)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{n} particles, {steps} odometry steps", fontsize=9)
    return fig


def update_rate_figure(alphas: ArrayLike, rng: np.random.Generator, distance: float = 2.0,
                       steps: Sequence[int] = (1, 4, 16), n: int = 500, panel_size: float = 3.0):
    """The same straight 2 m drive, split into 1, 4, 16 odometry updates, for both noise conventions.

    With PR's squared terms the cloud shrinks as updates get more frequent
    (variance per step falls with the square of the step length); with
    absolute values it does not (variance grows linearly with distance).

    Examples
    --------
    >>> fig = update_rate_figure([0.02, 0.02, 0.05, 0.01], np.random.default_rng(0), n=20, steps=(1, 2))
    >>> len(fig.axes)
    4
    """
    fig, axes = _figure((panel_size * len(steps), 2 * panel_size * 0.68), ncols=len(steps), nrows=2,
                        sharex=True, sharey=True)
    for row, noise in enumerate(("squared", "absolute")):
        for col, m in enumerate(steps):
            p = np.zeros((n, 3))
            for k in range(m):
                u = ([distance * k / m, 0.0, 0.0], [distance * (k + 1) / m, 0.0, 0.0])
                p = sample_odometry(p, u, alphas, rng, noise=noise)
            ax = axes[row * len(steps) + col]
            draw_samples(p, ax=ax)
            ax.plot([0, distance], [0, 0], "k--", lw=1)
            ax.set_title(f"{noise}, {m} step{'s' if m > 1 else ''}\nstd x {p[:, 0].std():.2f} m, "
                         f"std y {p[:, 1].std():.2f} m", fontsize=8)
            ax.set_aspect("equal")
            ax.set_ylim(-1.2, 1.2)
    for ax in axes[len(steps):]:
        ax.set_xlabel("x [m]")
    return fig
