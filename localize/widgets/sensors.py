"""Interactive tools of the sensor-model chapter.

* :func:`pseudo_density_figure` / :func:`beam_density_widget`: sliders for the
  six intrinsic parameters of the beam model redraw its pseudo-density.
* :func:`pose_scan_figure` / :func:`pose_scan_widget`: place a pose on the map
  (x, y, heading sliders) and compare its ray-cast scan with a measured one;
  the title shows the scan's log-likelihood and its weight relative to the
  true pose.

The ``*_figure`` callbacks are plain functions (parameters in, Figure out),
unit-tested without a browser; the ``*_widget`` builders only wire sliders to
them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..grid import OccupancyGrid
from ..sensors import BeamModel
from . import interactive_app, slider

__all__ = ["normalise_weights", "pseudo_density_figure", "beam_density_widget", "pose_scan_figure",
           "pose_scan_widget", "pose_scan_start", "DEMOS", "DEMO_VARIANTS"]


def normalise_weights(z_hit: float, z_short: float, z_max: float, z_rand: float) -> tuple[float, float, float, float]:
    """Scale four non-negative slider values so that they sum to one.

    Four independent sliders cannot keep a sum of one; the widget divides
    by their sum (and shows the result). All zero raises ``ValueError``.

    Examples
    --------
    >>> normalise_weights(2, 1, 0.5, 0.5)
    (0.5, 0.25, 0.125, 0.125)
    """
    w = np.array([z_hit, z_short, z_max, z_rand], dtype=float)
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"the mixture weights must be finite and >= 0; got {w.tolist()}")
    if w.sum() <= 0:
        raise ValueError("at least one mixture weight must be positive")
    w = w / w.sum()
    return tuple(float(v) for v in w)  # type: ignore[return-value]


def pseudo_density_figure(z_hit: float = 0.7, z_short: float = 0.1, z_max: float = 0.1, z_rand: float = 0.1,
                          sigma_hit: float = 0.2, lambda_short: float = 0.5, z_expected: float = 5.0,
                          max_range: float = 10.0):
    """The beam model's pseudo-density for the given parameters (weights normalised).

    Returns the matplotlib Figure; its title lists the normalised weights.

    Examples
    --------
    >>> fig = pseudo_density_figure(z_hit=1, z_short=1, z_max=1, z_rand=1)
    >>> fig.axes[0].get_title()
    'z_hit 0.25, z_short 0.25, z_max 0.25, z_rand 0.25, sigma_hit 0.2 m, lambda_short 0.5 /m'
    """
    import matplotlib.pyplot as plt

    from ..plot.sensors import plot_beam_pdf

    w = normalise_weights(z_hit, z_short, z_max, z_rand)
    model = BeamModel(None, max_range, *w, sigma_hit=sigma_hit, lambda_short=lambda_short)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    plot_beam_pdf(model, z_expected, ax=ax)
    ax.set_title(f"z_hit {w[0]:.2f}, z_short {w[1]:.2f}, z_max {w[2]:.2f}, z_rand {w[3]:.2f}, "
                 f"sigma_hit {sigma_hit:g} m, lambda_short {lambda_short:g} /m", fontsize=9)
    fig.tight_layout()
    return fig


def beam_density_widget(max_range: float = 10.0):
    """Sliders for ``z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short`` and ``z*``.

    Returns the ``ipywidgets.interactive`` object (display it in a notebook).

    Examples
    --------
    >>> wid = beam_density_widget()
    >>> [c.description for c in wid.children[:3]]
    ['z_hit', 'z_short', 'z_max']
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    import ipywidgets as w

    return interactive_app(
        pseudo_density_figure,
        z_hit=slider(0.7, 0.0, 1.0, 0.05, "z_hit"),
        z_short=slider(0.1, 0.0, 1.0, 0.05, "z_short"),
        z_max=slider(0.1, 0.0, 1.0, 0.05, "z_max"),
        z_rand=slider(0.1, 0.0, 1.0, 0.05, "z_rand"),
        sigma_hit=slider(0.2, 0.02, 1.0, 0.02, "sigma_hit"),
        lambda_short=slider(0.5, 0.05, 3.0, 0.05, "lambda_short"),
        z_expected=slider(5.0, 0.5, max_range, 0.25, "z*"),
        max_range=w.fixed(float(max_range)),
    )


def pose_scan_figure(grid: OccupancyGrid, model, angles: ArrayLike, measured: ArrayLike, x: float, y: float,
                     theta_deg: float, reference_pose: ArrayLike | None = None):
    """Map, the chosen pose's ray-cast scan against the measured scan, and the resulting weight.

    Parameters
    ----------
    grid : OccupancyGrid
    model : BeamModel or LikelihoodField
        Anything with ``log_likelihood(poses, ranges, angles)``; a
        :class:`BeamModel` also draws the expected scan.
    angles, measured : array_like
        The measured scan.
    x, y, theta_deg : float
        The pose to test (heading in degrees, for the slider).
    reference_pose : array_like, optional
        Usually the true pose: the title then gives the weight of the chosen
        pose relative to it, ``exp(ll - ll_ref)``.

    Returns
    -------
    matplotlib.figure.Figure
        Its ``log_likelihood`` attribute holds the value shown.
    """
    import matplotlib.pyplot as plt

    from ..plot.sensors import plot_ranges, plot_scan_on_map

    pose = np.array([x, y, np.radians(theta_deg)])
    angles = np.asarray(angles, dtype=float)
    measured = np.asarray(measured, dtype=float)
    ll = float(model.log_likelihood(pose[None], measured, angles)[0])
    expected = model.expected(pose[None], angles)[0] if hasattr(model, "expected") else None
    offset = getattr(model, "sensor_offset", (0.0, 0.0, 0.0))
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [1.6, 1]})
    plot_scan_on_map(grid, pose, angles, measured=measured, expected=expected, max_range=model.max_range, ax=ax0,
                     sensor_offset=offset)
    plot_ranges(angles, measured=measured, expected=expected, max_range=model.max_range, ax=ax1)
    title = f"pose ({x:.2f} m, {y:.2f} m, {theta_deg:.0f} deg): log-likelihood {ll:.1f}"
    if reference_pose is not None:
        ref = float(model.log_likelihood(np.asarray(reference_pose, dtype=float)[None], measured, angles)[0])
        rel = ll - ref
        title += f", weight relative to the true pose exp({rel:.1f})"
    ax0.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.log_likelihood = ll
    return fig


def pose_scan_widget(grid: OccupancyGrid, model, angles: ArrayLike, measured: ArrayLike,
                     start: ArrayLike = (1.0, 1.0, 0.0), reference_pose: ArrayLike | None = None):
    """Sliders placing a pose on the map (x, y in metres, heading in degrees); see :func:`pose_scan_figure`.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.sensors import LikelihoodField
    >>> g = office()
    >>> wid = pose_scan_widget(g, LikelihoodField(g, 8.0), [0.0], [1.0], start=(6.0, 5.5, 0.0))
    >>> [c.description for c in wid.children[:3]]
    ['x [m]', 'y [m]', 'heading [deg]']
    >>> [c.value for c in wid.children[:3]]              # on the slider steps: cell centres, whole degrees
    [6.05, 5.45, 0.0]
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    import ipywidgets as w

    (x0, x1, step), (y0, y1, _), (t0, t1, t_step) = _pose_slider_ranges(grid)
    x, y, theta_deg = pose_scan_start(grid, start)
    return interactive_app(
        pose_scan_figure,
        grid=w.fixed(grid), model=w.fixed(model), angles=w.fixed(np.asarray(angles)),
        measured=w.fixed(np.asarray(measured)), reference_pose=w.fixed(reference_pose),
        x=slider(x, x0, x1, step, "x [m]"),
        y=slider(y, y0, y1, step, "y [m]"),
        theta_deg=slider(theta_deg, t0, t1, t_step, "heading [deg]", fmt=".0f"),
    )


def _pose_slider_ranges(grid: OccupancyGrid):
    """(min, max, step) of the x, y and heading sliders: x and y on cell *centres*, heading on whole 2 degrees.

    Cell centres, not cell edges: a pose exactly on an edge would fall into one
    cell or the other depending on the last bit of the slider's value, so that
    returning to the same readout could give another figure.
    """
    xmin, xmax, ymin, ymax = grid.extent
    r = grid.resolution
    step = r * max(1, int(np.ceil(0.05 / r - 1e-9)))    # at least 5 cm, a whole number of cells
    cols = int(np.floor((xmax - xmin - r / 2) / step + 1e-9))
    rows = int(np.floor((ymax - ymin - r / 2) / step + 1e-9))
    return ((xmin + r / 2, xmin + r / 2 + cols * step, step), (ymin + r / 2, ymin + r / 2 + rows * step, step),
            (-180.0, 180.0, 2.0))


def pose_scan_start(grid: OccupancyGrid, start: ArrayLike) -> tuple[float, float, float]:
    """The slider position nearest to ``start`` = (x, y, theta in radians): ``(x, y, theta_deg)`` on the sliders' steps.

    Use it for the static figure after the widget, so that the figure shows
    exactly the widget's starting position.

    Examples
    --------
    >>> from localize.maps import office
    >>> pose_scan_start(office(), (6.6000000000000005, 5.6000000000000005, 0.3))
    (6.65, 5.65, 18.0)
    """
    start = np.asarray(start, dtype=float).reshape(3)
    out = []
    for v, (lo, hi, st) in zip((start[0], start[1], np.degrees(start[2])), _pose_slider_ranges(grid)):
        k = np.clip(np.round((v - lo) / st), 0, round((hi - lo) / st))
        out.append(round(float(lo + k * st), 6))
    return tuple(out)


def _pose_scan_demo(dx: float = 0.4):
    """The pose tool at its default: the office, a true pose, a simulated scan, a displaced guess."""
    from .. import maps

    grid = maps.office()
    model = BeamModel(grid, 8.0, z_hit=0.75, z_short=0.1, z_max=0.05, z_rand=0.1, sigma_hit=0.15,
                      lambda_short=0.5, method="march")
    angles = np.radians(np.arange(-90.0, 91.0, 6.0))
    true_pose = np.array([10.0, 5.5, 0.3])
    measured = model.sample(true_pose[None], angles, np.random.default_rng(5))[0]
    return pose_scan_figure(grid, model, angles, measured, true_pose[0] + dx, true_pose[1] + 0.2,
                            float(np.degrees(true_pose[2])), reference_pose=true_pose)


#: Zero-argument demos returning each widget's default figure (see tests/test_widgets_common.py).
DEMOS = {
    "pseudo_density": lambda: pseudo_density_figure(),
    "pose_scan": lambda: _pose_scan_demo(),
}
#: Other slider positions whose figures must differ from the defaults.
DEMO_VARIANTS = {
    "pseudo_density": [lambda: pseudo_density_figure(sigma_hit=0.5), lambda: pseudo_density_figure(z_rand=0.3)],
    "pose_scan": [lambda: _pose_scan_demo(dx=0.0)],
}
