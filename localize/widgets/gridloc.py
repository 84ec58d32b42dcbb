"""Grid localization in (x, y, theta): what the cell size and the heading bins buy.

:func:`grid_resolution_figure` is the callback: it runs the grid localizer of
the chapter on grid localization (:class:`localize.gridloc.GridLocalizer`) on
that chapter's simulated run — the office, a drive along the corridor and
into a room, 12-beam scans — with the chosen cell size and number of heading
bins, and draws the final belief and the position error along the path.
:func:`grid_resolution_widget` wires two selectors to it.

The number of heading bins must make the beam spacing (30 degrees) a whole
number of bins, so that one table of expected ranges serves every beam; hence
the choices 12, 24, 36 and 72.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import interactive_app

__all__ = ["CELL_SIZES", "HEADING_BINS", "chapter_run", "grid_run", "grid_resolution_figure",
           "grid_resolution_widget", "DEMOS", "DEMO_VARIANTS"]

#: Cell sizes offered (metres): blocks of 10, 8, 5 and 4 cells of the 5 cm office map.
CELL_SIZES = (0.5, 0.4, 0.25, 0.2)
#: Heading bins offered: 30, 15, 10 and 5 degree bins (the 30 degree beam spacing is a whole number of bins).
HEADING_BINS = (12, 24, 36, 72)
ANGLES = np.radians(np.arange(0, 360, 30.0))
MAX_RANGE = 8.0
ALPHAS = (0.02, 0.002, 0.02, 0.002)


@lru_cache(maxsize=1)
def chapter_run():
    """The chapter's data: ``(fine map, odometry (T, 3), true poses (T, 3), scans (T, 12))``.

    The same commanded path, noise and seed as the chapter on grid
    localization, so the widget replays the run the chapter discusses.

    Examples
    --------
    >>> fine, odom, truth, scans = chapter_run()
    >>> odom.shape, scans.shape, fine.resolution
    ((22, 3), (22, 12), 0.05)
    """
    from .. import maps, motion, raycast

    fine = maps.office(0.05)
    odom = [[2.0, 5.5, 0.0]]
    for _ in range(15):
        odom.append([odom[-1][0] + 0.5, 5.5, 0.0])
    odom.append([odom[-1][0], 5.5, -np.pi / 2])
    for _ in range(5):
        odom.append([odom[-1][0], odom[-1][1] - 0.5, -np.pi / 2])
    odom = np.array(odom)
    rng = np.random.default_rng(3)
    truth = [odom[0]]
    for t in range(1, len(odom)):
        truth.append(motion.sample_odometry(truth[-1][None], (odom[t - 1], odom[t]), ALPHAS, rng)[0])
    truth = np.array(truth)
    scans = raycast.cast(fine, truth, ANGLES, MAX_RANGE, method="march")
    scans = np.clip(scans + rng.normal(0.0, 0.05, scans.shape), 0.0, MAX_RANGE)
    scans[rng.random(scans.shape) < 0.05] = MAX_RANGE
    for a in (odom, truth, scans):
        a.setflags(write=False)
    return fine, odom, truth, scans


@lru_cache(maxsize=8)
def grid_run(cell: float = 0.2, n_headings: int = 36):
    """Run the grid localizer with ``cell`` metres and ``n_headings`` bins on :func:`chapter_run`.

    Returns a dict with the coarse ``grid``, the number of bins ``n_bins``,
    per-step ``position_error`` and ``heading_error`` (radians) and
    ``estimates`` (T, 3), the final ``marginal`` over (row, col), and the
    odometry's own ``odometry_error``. Cached; treat as read-only.

    Examples
    --------
    >>> r = grid_run(0.5, 12)
    >>> r["n_bins"], r["position_error"].shape
    (11520, (22,))
    """
    from ..geometry import angle_diff
    from ..gridloc import GridLocalizer, coarsen

    cell = float(cell)
    if not any(abs(cell - c) < 1e-9 for c in CELL_SIZES):
        raise ValueError(f"cell must be one of {CELL_SIZES} metres; got {cell}")
    if int(n_headings) not in HEADING_BINS:
        raise ValueError(f"n_headings must be one of {HEADING_BINS} (the 30 degree beam spacing must be a whole "
                         f"number of bins); got {n_headings}")
    fine, odom, truth, scans = chapter_run()
    grid = coarsen(fine, int(round(cell / fine.resolution)))
    loc = GridLocalizer(grid, int(n_headings), ANGLES, MAX_RANGE, sigma_hit=max(0.2, grid.resolution), alphas=ALPHAS)
    est = []
    for t in range(len(odom)):
        if t > 0:
            loc.predict((odom[t - 1], odom[t]))
        loc.update(scans[t])
        est.append(loc.estimate())
    est = np.array(est)
    return {"grid": grid, "n_bins": int(loc.n_cells), "estimates": est,
            "position_error": np.hypot(*(est[:, :2] - truth[:, :2]).T),
            "heading_error": np.abs(angle_diff(est[:, 2], truth[:, 2])),
            "odometry_error": np.hypot(*(odom[:, :2] - truth[:, :2]).T),
            "marginal": loc.marginal_xy()}


def grid_resolution_figure(cell: float = 0.2, n_headings: int = 36, figsize=(11, 3.8)):
    """The callback: final belief on the map (left), position error along the path (right).

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> fig = grid_resolution_figure(0.5, 12)
    >>> fig.axes[1].get_title()[:17]
    '0.50 m cells x 12'
    >>> plt.close(fig)
    """
    from matplotlib.figure import Figure

    from ..plot import draw_map

    r = grid_run(float(cell), int(n_headings))
    _, _, truth, _ = chapter_run()
    grid = r["grid"]
    fig = Figure(figsize=figsize)
    ax, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.6, 1]})
    draw_map(grid, ax=ax, alpha=0.5)
    m = r["marginal"]
    ax.imshow(np.ma.masked_less(m / m.max(), 1e-3), origin="lower", extent=grid.extent, cmap="viridis", alpha=0.9)
    ax.plot(truth[:, 0], truth[:, 1], color="tab:blue", lw=1, label="truth")
    ax.plot(r["estimates"][:, 0], r["estimates"][:, 1], "o", ms=2.5, color="tab:red", label="grid estimate")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("final belief over (x, y) and the estimates along the path", fontsize=9)
    xmin, xmax, ymin, ymax = grid.extent
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    pe = r["position_error"]
    ax2.plot(pe, color="tab:red", label="grid filter")
    ax2.plot(r["odometry_error"], "--", color="tab:gray", label="odometry alone")
    ax2.axhline(grid.resolution, color="0.7", lw=1)
    ax2.text(0.3, grid.resolution * 1.04, "cell size", fontsize=8)
    ax2.set_ylim(0, 0.8)                         # fixed: comparable between settings
    ax2.set_xlabel("step")
    ax2.set_ylabel("position error [m]")
    ax2.legend(loc="upper left", fontsize=8)
    ax2.set_title(f"{grid.resolution:.2f} m cells x {int(n_headings)} headings = {r['n_bins']:,} bins\n"
                  f"mean error after step 3: {pe[3:].mean():.3f} m, "
                  f"{np.degrees(r['heading_error'][3:].mean()):.1f}°", fontsize=9)
    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.13, top=0.86, wspace=0.22)
    return fig


def grid_resolution_widget(cell: float = 0.2, n_headings: int = 36):
    """Selectors for the cell size and the number of heading bins; see :func:`grid_resolution_figure`.

    Examples
    --------
    >>> wid = grid_resolution_widget(0.5, 12)
    >>> [c.description for c in wid.children[:2]]
    ['cell size [m]', 'heading bins']
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    import ipywidgets as W

    return interactive_app(
        grid_resolution_figure,
        cell=W.ToggleButtons(options=list(CELL_SIZES), value=float(cell), description="cell size [m]"),
        n_headings=W.ToggleButtons(options=list(HEADING_BINS), value=int(n_headings), description="heading bins"),
        figsize=W.fixed((11, 3.8)),
    )


#: Zero-argument demos returning the widget's default figure (see tests/test_widgets_common.py).
DEMOS = {"grid_resolution": lambda: grid_resolution_figure()}
#: Other settings whose figures must differ from the default.
DEMO_VARIANTS = {"grid_resolution": [lambda: grid_resolution_figure(0.5, 12), lambda: grid_resolution_figure(0.2, 12),
                                     lambda: grid_resolution_figure(0.4, 24)]}
