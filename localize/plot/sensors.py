"""Figures of the sensor-model chapter: pseudo-densities, scans over the map, fields.

Each function draws on a given ``ax`` (or a new figure) and returns the
artists or the figure; none of them computes anything a test could not check
through :mod:`localize.sensors` directly.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..geometry import as_poses
from ..grid import OccupancyGrid
from . import draw_map, draw_robot, draw_scan, new_axes

__all__ = ["plot_beam_pdf", "plot_scan_on_map", "plot_ranges", "plot_likelihood_field", "COMPONENT_COLORS"]

COMPONENT_COLORS = {"p_hit": "tab:blue", "p_short": "tab:orange", "p_max": "tab:red", "p_rand": "tab:green"}
_LABELS = {"p_hit": "hit (Gaussian)", "p_short": "short (exponential)", "p_max": "max range (point mass)",
           "p_rand": "random (uniform)"}


def plot_beam_pdf(model, z_expected: float, ax=None, n: int = 800, components: bool = True,
                  max_bar_width: float | None = None):
    """Draw the beam model's pseudo-density ``p(z | z*)`` over ``[0, max_range]`` (PR figure 6.4).

    The continuous part is a curve (with the weighted components stacked
    underneath when ``components``); the max-range point mass ``z_max`` is
    drawn as a narrow bar of *area* ``z_max`` at ``max_range``, which is how
    the pseudo-density picture shows a probability mass next to densities.

    Parameters
    ----------
    model : localize.sensors.BeamModel
    z_expected : float
        The ray-cast range ``z*``.

    Returns
    -------
    matplotlib.axes.Axes

    Examples
    --------
    >>> from localize.sensors import BeamModel
    >>> ax = plot_beam_pdf(BeamModel(None, 10.0), 4.0)
    >>> ax.get_xlabel()
    'measured range z [m]'
    """
    _, ax = new_axes(ax, figsize=(7, 3.5))
    zmax = model.max_range
    z = np.linspace(0.0, zmax, n, endpoint=False)
    c = model.components(z, z_expected)
    weights = {"p_hit": model.z_hit, "p_short": model.z_short, "p_rand": model.z_rand}
    if components:
        stack = np.zeros_like(z)
        for name in ("p_rand", "p_short", "p_hit"):
            part = weights[name] * c[name]
            ax.fill_between(z, stack, stack + part, color=COMPONENT_COLORS[name], alpha=0.35, lw=0,
                            label=f"{_LABELS[name]}, weight {weights[name]:.2f}")
            stack = stack + part
    cont = sum(weights[k] * c[k] for k in weights)
    ax.plot(z, cont, color="k", lw=1.5, label="p(z | z*) (continuous part)")
    width = max_bar_width or zmax / 100
    if model.z_max > 0:
        ax.bar([zmax - width / 2], [model.z_max / width], width=width, color=COMPONENT_COLORS["p_max"], alpha=0.8,
               label=f"{_LABELS['p_max']}, mass {model.z_max:.2f}")
    ax.axvline(z_expected, color="0.4", ls=":", lw=1)
    ax.annotate("z*", (z_expected, 0), xytext=(3, 3), textcoords="offset points", color="0.3")
    ax.set_xlim(0, zmax * 1.01)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("measured range z [m]")
    ax.set_ylabel("density [1/m]")
    ax.legend(fontsize=8, loc="upper left")
    return ax


def plot_scan_on_map(grid: OccupancyGrid, pose: ArrayLike, angles: ArrayLike, measured: ArrayLike | None = None,
                     expected: ArrayLike | None = None, max_range: float | None = None, ax=None,
                     sensor_offset: ArrayLike = (0.0, 0.0, 0.0), zoom: float | None = None):
    """Draw the map, the robot, and the measured and/or expected scans from its sensor.

    Expected (ray-cast) end points are drawn in blue, measured ones in
    orange, so that where they disagree is visible at a glance (the seed 001
    report validated its ray caster with such pictures). ``zoom`` (metres)
    limits the view to a square around the robot.

    Examples
    --------
    >>> from localize.maps import office
    >>> ax = plot_scan_on_map(office(), [6.0, 5.5, 0.0], [0.0, 0.5], expected=[3.0, 2.0], max_range=8.0)
    >>> len(ax.collections) >= 2
    True
    """
    from ..sensors import sensor_poses

    _, ax = new_axes(ax, figsize=(7, 4.5))
    draw_map(grid, ax=ax)
    p = as_poses(pose).reshape(3)
    sp = sensor_poses(p[None], sensor_offset)[0]
    draw_robot(p, ax=ax, radius=0.25)
    if expected is not None:
        draw_scan(sp, angles, expected, ax=ax, max_range=max_range, color="tab:blue", rays=True,
                  label="expected (ray cast)")
    if measured is not None:
        draw_scan(sp, angles, measured, ax=ax, max_range=max_range, color="tab:orange", rays=expected is None,
                  label="measured", marker="x")
    if zoom:
        ax.set_xlim(p[0] - zoom, p[0] + zoom)
        ax.set_ylim(p[1] - zoom, p[1] + zoom)
    else:                                   # the map's extent, whatever the rays do: redraws do not rescale
        xmin, xmax, ymin, ymax = grid.extent
        ax.set_xlim(xmin, xmax)
        ax.set_ylim(ymin, ymax)
    if expected is not None or measured is not None:
        ax.legend(fontsize=8, loc="upper right")
    return ax


def plot_ranges(angles: ArrayLike, measured: ArrayLike | None = None, expected: ArrayLike | None = None,
                max_range: float | None = None, ax=None):
    """Ranges against beam angle: measured (points) and expected (line).

    Examples
    --------
    >>> ax = plot_ranges([-1.0, 0.0, 1.0], measured=[2.0, 3.0, 8.0], expected=[2.1, 3.0, 4.0], max_range=8.0)
    >>> ax.get_ylabel()
    'range [m]'
    """
    _, ax = new_axes(ax, figsize=(7, 2.8))
    deg = np.degrees(np.asarray(angles, dtype=float))
    if expected is not None:
        ax.plot(deg, expected, color="tab:blue", lw=1.5, label="expected (ray cast)")
    if measured is not None:
        ax.plot(deg, measured, "x", color="tab:orange", ms=4, label="measured")
    if max_range is not None:
        ax.axhline(max_range, color="tab:red", ls="--", lw=1, label="max range")
    ax.set_xlabel("beam angle [deg]")
    ax.set_ylabel("range [m]")
    if max_range is not None:                # fixed limits: redraws with other ranges do not rescale
        ax.set_ylim(0.0, 1.08 * float(max_range))
    if deg.size:
        pad = 0.03 * max(float(np.ptp(deg)), 1.0)
        ax.set_xlim(float(deg.min()) - pad, float(deg.max()) + pad)
    ax.legend(fontsize=8)
    return ax


def plot_likelihood_field(model, ax=None, cmap: str = "magma"):
    """Draw the likelihood field: per-cell end-point density ``exp(log p)`` over the map.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.sensors import LikelihoodField
    >>> im = plot_likelihood_field(LikelihoodField(office(), 8.0))
    >>> im.get_array().shape
    (120, 200)
    """
    _, ax = new_axes(ax, figsize=(7, 4.5))
    g = model.grid
    pad = model._pad
    table = model.table[pad:pad + g.shape[0], pad:pad + g.shape[1]]
    im = ax.imshow(np.exp(table), origin="lower", extent=g.extent, cmap=cmap, interpolation="nearest")
    ax.figure.colorbar(im, ax=ax, label="end-point density [1/m]", shrink=0.8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    return im
