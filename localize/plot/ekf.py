"""Figures of the EKF-versus-MCL chapter: Gaussian ellipses next to particle clouds.

Every function draws onto a given ``ax`` (or a new one) and returns what it
made. The data come from :mod:`localize.compare` (a :class:`~localize.compare.Run`
for one seed, a :class:`~localize.compare.MonteCarlo` for many).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .._checks import check_positive
from . import draw_poses, new_axes

__all__ = [
    "FILTER_COLORS",
    "FILTER_STYLES",
    "covariance_ellipse",
    "draw_gaussian_belief",
    "draw_landmarks",
    "plot_beliefs",
    "plot_errors",
    "plot_nees",
]

#: One colour per filter, used by every figure of the chapter.
FILTER_COLORS = {"EKF": "tab:blue", "UKF": "tab:green", "MCL": "tab:red", "truth": "black"}
#: Line style per filter. The EKF and the UKF often agree to the pixel: the UKF is drawn wide and
#: underneath, the EKF dashed on top of it, so that both stay visible where they coincide.
FILTER_STYLES = {"EKF": {"ls": "--", "lw": 1.6, "zorder": 4}, "UKF": {"ls": "-", "lw": 3.2, "alpha": 0.75, "zorder": 3},
                 "MCL": {"ls": "-", "lw": 1.5, "zorder": 2}}
#: The NEES of a consistent filter averages the state's dimension, 3 for (x, y, theta).
_NEES_EXPECTED = 3.0
#: Average NEES below this is drawn at it, so that the log axis keeps a bottom.
_NEES_FLOOR = 1e-2


def covariance_ellipse(mean: ArrayLike, cov: ArrayLike, ax=None, n_std: float = 2.0, **kwargs):
    """Draw the ``n_std``-sigma ellipse of the x-y marginal of a pose Gaussian.

    ``n_std=2`` encloses about 86% of a 2-D Gaussian's mass
    (``1 - exp(-n_std**2 / 2)``). Returns the ``Ellipse`` patch.

    Examples
    --------
    >>> e = covariance_ellipse([1.0, 2.0, 0.0], np.diag([4.0, 1.0, 0.1]))
    >>> round(float(e.width), 6), round(float(e.height), 6)
    (8.0, 4.0)
    """
    from matplotlib.patches import Ellipse

    _, ax = new_axes(ax)
    m = np.asarray(mean, dtype=float).reshape(-1)
    c = np.asarray(cov, dtype=float)[:2, :2]
    check_positive(n_std, "n_std", "standard deviations")
    vals, vecs = np.linalg.eigh(0.5 * (c + c.T))
    vals = np.maximum(vals, 0.0)
    angle = np.degrees(np.arctan2(vecs[1, 1], vecs[0, 1]))
    kwargs.setdefault("fill", False)
    kwargs.setdefault("lw", 1.8)
    e = Ellipse((m[0], m[1]), 2 * n_std * np.sqrt(vals[1]), 2 * n_std * np.sqrt(vals[0]), angle=angle, **kwargs)
    ax.add_patch(e)
    return e


def draw_gaussian_belief(mean: ArrayLike, cov: ArrayLike, ax=None, color="tab:blue", n_std: float = 2.0,
                         length: float = 1.0, label: str | None = None, **kwargs):
    """A Gaussian pose belief: the x-y ellipse and a wedge of ``±n_std`` heading sigmas.

    Extra keyword arguments (``ls``, ``lw``, ``zorder``, ...) style the ellipse.
    Returns ``(ellipse, wedge_lines)``.

    Examples
    --------
    >>> e, lines = draw_gaussian_belief([0, 0, 0], np.diag([1.0, 1.0, 0.04]))
    >>> len(lines)
    3
    """
    _, ax = new_axes(ax)
    m = np.asarray(mean, dtype=float).reshape(3)
    e = covariance_ellipse(m, cov, ax=ax, n_std=n_std, color=color, label=label, **kwargs)
    s = float(np.sqrt(max(np.asarray(cov, dtype=float)[2, 2], 0.0)))
    lines = []
    for d, ls in ((0.0, "-"), (-n_std * s, ":"), (n_std * s, ":")):
        a = m[2] + d
        (ln,) = ax.plot([m[0], m[0] + length * np.cos(a)], [m[1], m[1] + length * np.sin(a)], color=color,
                        ls=ls, lw=1.5)
        lines.append(ln)
    return e, lines


def draw_landmarks(landmarks: ArrayLike, ax=None, labels: bool = True, **kwargs):
    """Landmarks as black stars, numbered. Returns the scatter artist."""
    _, ax = new_axes(ax)
    lm = np.asarray(landmarks, dtype=float).reshape(-1, 2)
    kwargs.setdefault("marker", "*")
    kwargs.setdefault("s", 140)
    kwargs.setdefault("color", "k")
    sc = ax.scatter(lm[:, 0], lm[:, 1], zorder=4, **kwargs)
    if labels:
        for j, (x, y) in enumerate(lm):
            ax.annotate(str(j), (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8)
    return sc


def plot_beliefs(run, steps, axes=None, pad: float = 2.0, n_std: float = 2.0, max_particles: int = 400,
                 zoom: float | None = None):
    """The chapter's key figure: beliefs of all filters on the same steps.

    Top row: the EKF's and the UKF's 2-sigma ellipses (with heading wedges;
    the EKF dashed over the UKF, see :data:`FILTER_STYLES`); bottom row: MCL's
    particle cloud. One column per step, same limits in a column; the true
    pose is the black robot.

    Parameters
    ----------
    run : localize.compare.Run
        A run recorded with ``snapshot_steps`` containing ``steps``.
    steps : sequence of int
    axes : array of Axes, shape (2, len(steps)), optional
    pad : float
        Margin around the landmarks, metres.
    zoom : float, optional
        Half-width (metres) of a window centred on the true pose of each step,
        instead of the whole landmark field: for beliefs a few centimetres
        wide, which the whole field shows as dots. The robot and the heading
        wedges are then drawn at the window's scale.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    from . import draw_robot

    steps = list(steps)
    if not steps:
        raise ValueError("steps must name at least one recorded step")
    missing = [s for s in steps if s not in run.snapshots]
    if missing:
        raise ValueError(f"steps {missing} were not recorded; run with snapshot_steps including them "
                         f"(recorded: {sorted(run.snapshots)})")
    if axes is None:
        fig, axes = plt.subplots(2, len(steps), figsize=(3.2 * len(steps), 6.4), squeeze=False)
    else:
        axes = np.asarray(axes).reshape(2, len(steps))
        fig = axes[0, 0].figure
    if zoom is not None:
        check_positive(zoom, "zoom", "metres")
    lm = run.scenario.landmarks
    lo, hi = lm.min(axis=0) - pad, lm.max(axis=0) + pad
    scale = 1.0 if zoom is None else zoom / 2.0       # robot radius and wedge length follow the window
    for c, t in enumerate(steps):
        snap = run.snapshots[t]
        truth = run.truth[t]
        if zoom is not None:
            lo, hi = truth[:2] - zoom, truth[:2] + zoom
        for r in range(2):
            ax = axes[r, c]
            draw_landmarks(lm, ax=ax, labels=False, s=80)
            draw_robot(truth, ax=ax, radius=0.35 if zoom is None else zoom / 8, color="k")
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal")
            ax.tick_params(labelsize=7)
        for name in ("EKF", "UKF"):
            if name in snap:
                m, P = snap[name]
                draw_gaussian_belief(m, P, ax=axes[0, c], color=FILTER_COLORS[name], n_std=n_std, label=name,
                                     length=scale, **FILTER_STYLES[name])
        if "MCL" in snap:
            parts = snap["MCL"]
            if len(parts) > max_particles:
                parts = parts[np.linspace(0, len(parts) - 1, max_particles).astype(int)]
            axes[1, c].set_xlim(lo[0], hi[0])
            draw_poses(parts, ax=axes[1, c], color=FILTER_COLORS["MCL"], alpha=0.5, length=0.4 * scale)
        axes[0, c].set_title(f"step {t}", fontsize=9)
    axes[0, 0].set_ylabel("EKF / UKF (2σ)")
    axes[1, 0].set_ylabel("MCL particles")
    axes[0, 0].legend(loc="lower left", fontsize=7)
    fig.suptitle(run.scenario.title, fontsize=10)
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.05, top=0.9, wspace=0.3, hspace=0.2)   # fixed: no tight_layout
    return fig


def plot_errors(mc, ax=None, what: str = "position", band: tuple[float, float] = (10, 90)):
    """Error over time across seeds: median line and a percentile band per filter.

    ``what`` is ``"position"`` (metres) or ``"heading"`` (degrees).
    Returns the axes.
    """
    _, ax = new_axes(ax, figsize=(6, 3.2))
    if what not in ("position", "heading"):
        raise ValueError(f"what must be 'position' or 'heading'; got {what!r}")
    t = np.arange(mc.n_steps)
    for name, m in mc.metrics.items():
        e = m.pos_err if what == "position" else np.degrees(m.head_err)
        lo, hi = np.percentile(e, band, axis=0)
        col = FILTER_COLORS.get(name, None)
        ax.fill_between(t, lo, hi, color=col, alpha=0.15, lw=0)
        ax.plot(t, np.median(e, axis=0), color=col, label=name, **FILTER_STYLES.get(name, {}))
    if what == "position":
        ax.axhline(mc.fail_threshold, color="gray", ls="--", lw=1, label="failure threshold")
    return _per_step_axes(ax, "position error [m]" if what == "position" else "heading error [deg]",
                          f"{mc.scenario.title}: median and {band[0]}-{band[1]}% band, {mc.n_seeds} seeds")


def _per_step_axes(ax, ylabel: str, title: str):
    """Label a per-step plot of the Monte Carlo runs: log y axis, steps along x, a small legend."""
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    return ax


def plot_nees(mc, ax=None):
    """Average NEES over seeds, per step and filter, with the 95% chi-square band.

    Inside the band the filter's covariance matches its actual errors; above
    it the filter is overconfident, below it too cautious (Bar-Shalom, Li and
    Kirubarajan 2001, section 5.4). Returns the axes.
    """
    _, ax = new_axes(ax, figsize=(6, 3.2))
    t = np.arange(mc.n_steps)
    lo, hi = mc.nees_bounds
    ax.axhspan(lo, hi, color="gray", alpha=0.2, label="95% band (consistent)")
    ax.axhline(_NEES_EXPECTED, color="gray", lw=0.8)
    for name, m in mc.metrics.items():
        ax.plot(t, np.maximum(m.nees.mean(axis=0), _NEES_FLOOR), color=FILTER_COLORS.get(name), label=name,
                **FILTER_STYLES.get(name, {}))
    return _per_step_axes(ax, "average NEES", f"{mc.scenario.title}: NEES, {mc.n_seeds} seeds")
