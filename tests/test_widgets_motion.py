"""Tests of localize.widgets.motion: the callbacks draw what the models say, redraws change the picture."""

from __future__ import annotations

import io

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from PIL import Image  # noqa: E402

from localize.motion import odometry_pdf_xy, sample_odometry  # noqa: E402
from localize.widgets import motion as wm  # noqa: E402


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def test_odometry_callback_draws_the_model():
    fig = wm.odometry_cloud_figure(0.1, 0.01, 0.05, 0.01, n=300, seed=4)
    dens_ax, cloud_ax = fig.axes
    offsets = cloud_ax.collections[0].get_offsets()
    expected = sample_odometry(np.zeros((300, 3)), wm.DEFAULT_ODOMETRY_U, [0.1, 0.01, 0.05, 0.01],
                               np.random.default_rng(4), min_std=1e-3)
    np.testing.assert_allclose(offsets, expected[:, :2])
    img = dens_ax.images[0].get_array()
    x0, x1, y0, y1 = (-0.6, 1.8, -0.95, 1.45)
    # the pixel in row i, column j is the density at that cell's centre
    i, j = 40, 55
    xy = [x0 + (j + 0.5) * (x1 - x0) / 80, y0 + (i + 0.5) * (y1 - y0) / 80]
    ref = odometry_pdf_xy(xy, wm.DEFAULT_ODOMETRY_U, [0, 0, 0], [0.1, 0.01, 0.05, 0.01], min_std=1e-3)
    assert img[i, j] == pytest.approx(float(ref))


def test_view_redraw_changes_picture_and_returns_to_same_bytes():
    view = wm.OdometryCloudView(n=200)
    view.update(0.05, 0.01, 0.02, 0.02)
    a = view.png()
    view.update(0.3, 0.01, 0.02, 0.02)
    b = view.png()
    view.update(0.05, 0.01, 0.02, 0.02)
    c = view.png()
    assert a != b
    assert a == c
    assert a[:8] == b"\x89PNG\r\n\x1a\n"


def test_fast_redraw_matches_a_full_render():
    """The blitted PNG shows the same picture as drawing the whole figure (up to antialiasing)."""
    for view in (wm.OdometryCloudView(n=300), wm.VelocityCloudView(n=300, resolution=30, n_theta=8)):
        view.update(*([0.1, 0.01, 0.05, 0.01] if isinstance(view, wm.OdometryCloudView) else [0.02] * 6))
        fast = _pixels(view.png())
        full = _pixels(wm.figure_png(view.fig))
        assert fast.shape == full.shape
        assert (np.abs(fast - full) > 40).mean() < 0.01


def test_zero_alphas_still_draw():
    fig = wm.odometry_cloud_figure(0.0, 0.0, 0.0, 0.0)
    assert np.isfinite(fig.axes[0].images[0].get_array()).all()
    fig = wm.velocity_cloud_figure(*[0.0] * 6, n=20, resolution=20, n_theta=8)
    assert np.isfinite(fig.axes[0].images[0].get_array()).all()


def test_velocity_callback_straight_line_and_turn():
    straight = wm.VelocityCloudView(n=100, resolution=20, n_theta=8)
    straight.update(*[0.01] * 6, v=1.0, omega=0.0)
    xy = straight.scatter.get_offsets()
    assert abs(np.mean(xy[:, 1])) < 0.05 and np.mean(xy[:, 0]) == pytest.approx(1.0, abs=0.05)
    straight.update(*[0.01] * 6, v=1.0, omega=1.0)
    assert np.mean(straight.scatter.get_offsets()[:, 1]) > 0.3


def test_widget_builders_redraw_on_slider_change():
    pytest.importorskip("ipywidgets")
    for build, name, value in ((wm.odometry_widget, "alpha1", 0.3), (wm.velocity_widget, "omega", -1.0)):
        box = build(n=100)
        assert set(box.sliders) >= {"alpha1", "alpha2", "alpha3", "alpha4"}
        before = box.image.value
        box.sliders[name].value = value
        assert box.image.value != before
        assert box.image.value[:4] == b"\x89PNG"


def test_demos_declared():
    assert set(wm.DEMOS) == {"odometry", "velocity"}
    for name, alts in wm.DEMO_VARIANTS.items():
        assert name in wm.DEMOS and alts
