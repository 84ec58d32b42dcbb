"""Sliders for the motion models: move an alpha, watch the cloud and the density change.

Each widget has a pure callback (parameters -> matplotlib Figure, unit-tested
and timed in ``benchmarks/bench_motion.py``) and a builder that wires
ipywidgets sliders to it. The callbacks seed their own generator from the
``seed`` argument, so the same slider values always draw the same picture.
"""

from __future__ import annotations

from functools import partial

import numpy as np
from numpy.typing import ArrayLike

from ..motion import (
    move_velocity,
    odometry_pdf_xy,
    sample_odometry,
    sample_velocity,
    velocity_pdf,
    velocity_variances,
)
from . import with_hint

__all__ = [
    "DEMOS",
    "DEMO_VARIANTS",
    "DEFAULT_ODOMETRY_U",
    "OdometryCloudView",
    "VelocityCloudView",
    "figure_png",
    "odometry_cloud_figure",
    "odometry_widget",
    "velocity_cloud_figure",
    "velocity_position_density",
    "velocity_widget",
]

#: The motion the odometry widget shows: turn a little, drive 1 m, turn back.
DEFAULT_ODOMETRY_U = ((0.0, 0.0, 0.0), (1.0, 0.25, 0.5))


def _two_panels(figsize=(8.0, 3.6)):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=80)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.13, top=0.9, wspace=0.08)
    return fig, axes


def _finish(fig, axes, extent, title_left, title_right):
    for ax in axes:
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    axes[0].set_title(title_left, fontsize=9)
    axes[1].set_title(title_right, fontsize=9)
    return fig


def _grid(extent, resolution):
    x0, x1, y0, y1 = extent
    xs = x0 + (np.arange(resolution) + 0.5) * (x1 - x0) / resolution
    ys = y0 + (np.arange(resolution) + 0.5) * (y1 - y0) / resolution
    X, Y = np.meshgrid(xs, ys)
    return np.stack([X, Y], -1)


class _Blitter:
    """Cache a figure's static parts; re-render only the artists that change.

    The background (axes, ticks, labels, titles) is drawn once with the
    dynamic artists hidden; each frame restores it and draws just the
    dynamic artists and the axes frames on top (matplotlib "blitting").
    """

    def __init__(self, fig, artists_by_axes):
        self.fig = fig
        self.artists_by_axes = artists_by_axes
        self.background = None

    def png(self) -> bytes:
        import io

        from PIL import Image

        canvas = self.fig.canvas
        if self.background is None:
            dynamic = [a for _, arts in self.artists_by_axes for a in arts]
            for a in dynamic:
                a.set_visible(False)
            canvas.draw()
            self.background = canvas.copy_from_bbox(self.fig.bbox)
            for a in dynamic:
                a.set_visible(True)
        canvas.restore_region(self.background)
        renderer = canvas.get_renderer()
        for ax, arts in self.artists_by_axes:
            for a in arts:
                a.draw(renderer)
            for spine in ax.spines.values():
                spine.draw(renderer)
        buf = io.BytesIO()
        Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).save(
            buf, format="png", compress_level=1)
        return buf.getvalue()


def figure_png(fig) -> bytes:
    """Render a figure to PNG bytes (what a widget sends to the browser).

    Fast settings: the figure's own dpi, no tight bounding box, light compression.

    Examples
    --------
    >>> figure_png(odometry_cloud_figure(n=10, resolution=10))[:4]
    b'\\x89PNG'
    """
    import io

    buf = io.BytesIO()
    fig.canvas.print_png(buf, pil_kwargs={"compress_level": 1})
    return buf.getvalue()


class OdometryCloudView:
    """A two-panel figure kept alive between redraws: density grid (left), samples (right).

    :meth:`update` draws new samples and a new density into the *existing*
    artists, which is several times faster than building a figure; the
    widget sends :meth:`png` to the browser after each update.

    Examples
    --------
    >>> view = OdometryCloudView(n=200)
    >>> fig = view.update(0.1, 0.01, 0.05, 0.01)
    >>> view.scatter.get_offsets().shape, view.png()[:4]
    ((200, 2), b'\\x89PNG')
    """

    def __init__(self, n: int = 500, seed: int = 0, u=DEFAULT_ODOMETRY_U, resolution: int = 80,
                 extent=(-0.6, 1.8, -0.95, 1.45), min_std: float = 1e-3):
        self.n, self.seed, self.u, self.extent, self.min_std = int(n), int(seed), u, tuple(extent), float(min_std)
        self._grid = _grid(self.extent, resolution)
        self.fig, self.axes = _two_panels()
        self.image = self.axes[0].imshow(np.zeros((resolution, resolution)), origin="lower", extent=self.extent,
                                         cmap="viridis", interpolation="nearest")
        self.scatter = self.axes[1].scatter(np.zeros(self.n), np.zeros(self.n), s=3, color="tab:red", alpha=0.5,
                                            linewidths=0)
        start = np.asarray(u[0], dtype=float)
        end = np.asarray(u[1], dtype=float)
        for ax, c in zip(self.axes, ("w", "k")):
            ax.plot([0, end[0] - start[0]], [0, end[1] - start[1]], ls="--", color=c, lw=1)
        _finish(self.fig, self.axes, self.extent, "density p(x, y | u)", f"{self.n} samples")
        self._blit = _Blitter(self.fig, [(self.axes[0], [self.image, self.axes[0].lines[0]]),
                                         (self.axes[1], [self.scatter, self.axes[1].lines[0]])])

    def update(self, alpha1: float, alpha2: float, alpha3: float, alpha4: float, seed: int | None = None):
        """Redraw for new alphas (and optionally a new seed); returns the figure."""
        alphas = [alpha1, alpha2, alpha3, alpha4]
        rng = np.random.default_rng(self.seed if seed is None else seed)
        cloud = sample_odometry(np.zeros((self.n, 3)), self.u, alphas, rng, min_std=self.min_std)
        P = odometry_pdf_xy(self._grid, self.u, [0.0, 0.0, 0.0], alphas, min_std=self.min_std)
        self.image.set_data(P)
        self.image.set_clim(0.0, max(float(P.max()), 1e-12))
        self.scatter.set_offsets(cloud[:, :2])
        return self.fig

    def png(self) -> bytes:
        """The current figure as PNG bytes (only the changing artists are re-rendered)."""
        return self._blit.png()


def odometry_cloud_figure(alpha1: float = 0.05, alpha2: float = 0.01, alpha3: float = 0.02,
                          alpha4: float = 0.02, n: int = 500, seed: int = 0, u=DEFAULT_ODOMETRY_U,
                          resolution: int = 80, extent=(-0.6, 1.8, -0.95, 1.45), min_std: float = 1e-3):
    """Callback: ``n`` odometry-model samples (right) next to the position density (left).

    Parameters
    ----------
    alpha1..alpha4 : float
        PR's noise parameters (>= 0).
    n : int
        Number of samples drawn.
    seed : int
        Seed of the generator (same seed, same cloud).
    u : pair of poses
        The odometry readings ``(prev_odom, odom)``.
    resolution : int
        Density grid cells per side.
    extent : (x0, x1, y0, y1)
        Axes limits in metres.
    min_std : float
        Floor on the noise standard deviations so that all-zero alphas still
        draw (a point mass cannot be drawn as a density).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> fig = odometry_cloud_figure(0.1, 0.01, 0.05, 0.01, n=100)
    >>> len(fig.axes), fig.axes[1].collections[0].get_offsets().shape
    (2, (100, 2))
    """
    view = OdometryCloudView(n=n, seed=seed, u=u, resolution=resolution, extent=extent, min_std=min_std)
    return view.update(alpha1, alpha2, alpha3, alpha4)


def _slider_box(sliders: dict, draw, initial_png: bytes):
    """Sliders above an Image widget; every change re-renders through ``draw(**values) -> png``."""
    import ipywidgets as w

    image = w.Image(value=initial_png, format="png")

    def on_change(_change=None):
        image.value = draw(**{k: s.value for k, s in sliders.items()})

    for s in sliders.values():
        s.observe(on_change, names="value")
    box = w.VBox([w.HBox(list(sliders.values())[:4]), w.HBox(list(sliders.values())[4:]), image])
    box.sliders, box.image, box.redraw = sliders, image, on_change
    return box


def odometry_widget(n: int = 500, **kwargs):
    """Sliders alpha1..alpha4 (and seed) redrawing an :class:`OdometryCloudView`.

    Returns an ``ipywidgets.VBox`` (sliders and an image); ``box.sliders``
    holds the sliders by name and ``box.image`` the picture.

    Examples
    --------
    >>> box = odometry_widget(n=50)
    >>> old = box.image.value
    >>> box.sliders["alpha1"].value = 0.3          # what a reader's drag does
    >>> box.image.value != old
    True
    """
    import ipywidgets as w

    def slider(name, value, top):
        return w.FloatSlider(value=value, min=0.0, max=top, step=top / 100, description=name,
                             continuous_update=False, readout_format=".3f",
                             layout=w.Layout(width="240px"), style={"description_width": "50px"})

    sliders = {"alpha1": slider("alpha1", 0.05, 0.5), "alpha2": slider("alpha2", 0.01, 0.1),
               "alpha3": slider("alpha3", 0.02, 0.5), "alpha4": slider("alpha4", 0.02, 0.5),
               "seed": w.IntSlider(value=0, min=0, max=20, description="seed", continuous_update=False)}
    view = OdometryCloudView(n=n, **kwargs)

    def draw(alpha1, alpha2, alpha3, alpha4, seed):
        view.update(alpha1, alpha2, alpha3, alpha4, seed)
        return view.png()

    box = _slider_box(sliders, draw, draw(**{k: s.value for k, s in sliders.items()}))
    box.view = view
    return with_hint(box)


class VelocityCloudView:
    """Like :class:`OdometryCloudView`, for the velocity model (alpha1..alpha6, v, omega).

    The left panel is the position density ``p(x, y | v, omega)``: the
    density of :func:`localize.motion.velocity_pdf` integrated over the final
    heading, in closed form (:func:`velocity_position_density`), averaged
    over ``supersample**2`` points of each pixel, its colour proportional to
    the square root of the density. The right panel shows the
    samples and, for every tenth one, its final heading as a short line:
    ``alpha5`` and ``alpha6`` (the extra final rotation) turn only these
    headings, never the positions or the density.

    Examples
    --------
    >>> view = VelocityCloudView(n=50, resolution=20)
    >>> fig = view.update(*[0.01] * 6, v=1.0, omega=0.5)
    >>> view.scatter.get_offsets().shape
    (50, 2)
    """

    def __init__(self, n: int = 500, seed: int = 0, dt: float = 1.0, resolution: int = 90, supersample: int = 2,
                 extent=(-1.0, 1.8, -1.2, 1.6), min_std: float = 1e-3):
        self.n, self.seed, self.dt, self.extent, self.min_std = int(n), int(seed), float(dt), tuple(extent), min_std
        self.resolution, self.supersample = int(resolution), int(supersample)
        self._grid = _grid(self.extent, self.resolution * self.supersample)
        self.fig, self.axes = _two_panels()
        from matplotlib.collections import LineCollection
        from matplotlib.colors import PowerNorm

        # colour ~ sqrt(density): the density diverges like 1/distance at the start pose, which at v = 0 is
        # inside the cloud; on a linear scale the rest of that cloud would be a few dim pixels
        self.image = self.axes[0].imshow(np.zeros((resolution, resolution)), origin="lower", extent=self.extent,
                                         cmap="viridis", interpolation="nearest", norm=PowerNorm(0.5))
        self.scatter = self.axes[1].scatter(np.zeros(self.n), np.zeros(self.n), s=3, color="tab:red", alpha=0.5,
                                            linewidths=0)

        self.headings = LineCollection([], colors="tab:blue", linewidths=0.6, alpha=0.8)
        self.axes[1].add_collection(self.headings)
        self.arcs = [ax.plot([], [], ls="--", color=c, lw=1)[0] for ax, c in zip(self.axes, ("w", "k"))]
        _finish(self.fig, self.axes, self.extent, "density p(x, y | v, omega), colour ~ its square root",
                f"{self.n} samples, final heading of every 10th (blue)")
        self._blit = _Blitter(self.fig, [(self.axes[0], [self.image, self.arcs[0]]),
                                         (self.axes[1], [self.scatter, self.headings, self.arcs[1]])])

    def update(self, alpha1: float, alpha2: float, alpha3: float, alpha4: float, alpha5: float, alpha6: float,
               v: float = 1.0, omega: float = 0.8, seed: int | None = None):
        """Redraw for new parameters; returns the figure."""
        alphas = [alpha1, alpha2, alpha3, alpha4, alpha5, alpha6]
        rng = np.random.default_rng(self.seed if seed is None else seed)
        cloud = sample_velocity(np.zeros((self.n, 3)), (v, omega), self.dt, alphas, rng, min_std=self.min_std)
        fine = velocity_position_density(self._grid, (v, omega), self.dt, alphas, min_std=self.min_std)
        r, s = self.resolution, self.supersample
        P = fine.reshape(r, s, r, s).mean(axis=(1, 3))          # the pixel's mean density
        self.image.set_data(P)
        self.image.set_clim(0.0, max(float(P.max()), 1e-12))
        self.scatter.set_offsets(cloud[:, :2])
        some = cloud[::10]
        tips = some[:, :2] + 0.08 * np.stack([np.cos(some[:, 2]), np.sin(some[:, 2])], axis=-1)
        self.headings.set_segments(np.stack([some[:, :2], tips], axis=1))
        t = np.linspace(0.0, self.dt, 40)
        arc = move_velocity(np.zeros((40, 3)), v * t, omega * t, 1.0)     # the noise-free arc
        for line in self.arcs:
            line.set_data(arc[:, 0], arc[:, 1])
        return self.fig

    def png(self) -> bytes:
        """The current figure as PNG bytes (only the changing artists are re-rendered)."""
        return self._blit.png()


def velocity_position_density(xy: ArrayLike, u: ArrayLike, dt: float, alphas: ArrayLike,
                              min_std: float = 0.0) -> np.ndarray:
    """The velocity model's density of the new *position* ``p(x, y | v, omega)``, from the pose ``(0, 0, 0)``.

    :func:`localize.motion.velocity_pdf` integrated over the final heading.
    The heading enters that density only through the final-rotation noise
    ``gamma`` (a wrapped normal in the heading); the integral of a density
    over its whole circle is 1, so the position density is the same formula
    with ``gamma`` uniform over the circle, times ``2*pi``. Computed that way
    (``gamma``'s standard deviation set to a full turn, whose wrapped normal
    is uniform to 1e-8), it does not depend on ``alpha5`` and ``alpha6`` and
    stays smooth when they are 0, where summing ``velocity_pdf`` over a few
    headings saw a needle in the heading and left isolated pixels.

    Examples
    --------
    >>> a = [0.01] * 6
    >>> p = velocity_position_density([[1.0, 0.0], [1.0, 0.3]], (1.0, 0.0), 1.0, a)
    >>> p.round(3)
    array([31.831,  0.   ])
    >>> bool(np.allclose(p, velocity_position_density([[1.0, 0.0], [1.0, 0.3]], (1.0, 0.0), 1.0, a[:4] + [0, 0],
    ...                                                min_std=1e-3)))
    True
    """
    xy = np.asarray(xy, dtype=float)
    if xy.shape[-1:] != (2,):
        raise ValueError(f"xy must have shape (..., 2) (x, y in metres); got shape {xy.shape}")
    full_turn = (2.0 * np.pi / float(dt)) ** 2

    def uniform_heading(v, w, a):
        var_v, var_w, _ = velocity_variances(v, w, a)
        return var_v, var_w, np.full(np.shape(var_v), full_turn)

    poses = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], axis=-1)
    return 2.0 * np.pi * velocity_pdf(poses, u, [0.0, 0.0, 0.0], dt, alphas, noise=uniform_heading, min_std=min_std)


def velocity_cloud_figure(alpha1: float = 0.01, alpha2: float = 0.01, alpha3: float = 0.01,
                          alpha4: float = 0.01, alpha5: float = 0.01, alpha6: float = 0.01,
                          v: float = 1.0, omega: float = 0.8, n: int = 500, seed: int = 0, **kwargs):
    """Callback: velocity-model samples (right) next to the position density (left).

    Parameters as in :func:`localize.motion.sample_velocity`; ``kwargs`` go to
    :class:`VelocityCloudView` (``dt``, ``resolution``, ``supersample``, ``extent``).

    Examples
    --------
    >>> fig = velocity_cloud_figure(n=50, resolution=20)
    >>> len(fig.axes)
    2
    """
    view = VelocityCloudView(n=n, seed=seed, **kwargs)
    return view.update(alpha1, alpha2, alpha3, alpha4, alpha5, alpha6, v, omega)


def velocity_widget(n: int = 500, **kwargs):
    """Sliders alpha1..alpha6, v and omega redrawing a :class:`VelocityCloudView`.

    Examples
    --------
    >>> box = velocity_widget(n=50, resolution=20)
    >>> sorted(box.sliders)[:3], "omega" in box.sliders
    (['alpha1', 'alpha2', 'alpha3'], True)
    """
    import ipywidgets as w

    def slider(name, value, lo, hi):
        return w.FloatSlider(value=value, min=lo, max=hi, step=(hi - lo) / 100, description=name,
                             continuous_update=False, readout_format=".3f",
                             layout=w.Layout(width="240px"), style={"description_width": "50px"})

    sliders = {f"alpha{k}": slider(f"alpha{k}", 0.01, 0.0, 0.1) for k in range(1, 7)}
    sliders["v"] = slider("v", 1.0, -1.0, 1.5)
    sliders["omega"] = slider("omega", 0.8, -2.0, 2.0)
    view = VelocityCloudView(n=n, **kwargs)

    def draw(**p):
        view.update(**p)
        return view.png()

    box = _slider_box(sliders, draw, draw(**{k: s.value for k, s in sliders.items()}))
    box.view = view
    return with_hint(box)


#: Zero-argument demos of each widget's callback at its default parameters
#: (checked by tests/test_widgets_common.py, timed by benchmarks/bench_widgets.py).
DEMOS = {
    "odometry": partial(odometry_cloud_figure),
    "velocity": partial(velocity_cloud_figure),
}
#: Other slider positions whose figures must differ from the defaults.
DEMO_VARIANTS = {
    "odometry": [partial(odometry_cloud_figure, alpha1=0.3), partial(odometry_cloud_figure, alpha3=0.3)],
    "velocity": [partial(velocity_cloud_figure, alpha5=0.08), partial(velocity_cloud_figure, omega=-0.5)],
}
