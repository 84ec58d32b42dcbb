"""Tests of the sensor-model chapter's figures and widgets (callbacks without a browser)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from localize.maps import office
from localize.plot.sensors import plot_beam_pdf, plot_likelihood_field, plot_ranges, plot_scan_on_map
from localize.sensors import BeamModel, LikelihoodField
from localize.widgets.sensors import (
    beam_density_widget,
    normalise_weights,
    pose_scan_figure,
    pose_scan_widget,
    pseudo_density_figure,
)


@pytest.fixture(scope="module")
def setup():
    g = office()
    model = BeamModel(g, 8.0, method="march")
    angles = np.linspace(-np.pi / 2, np.pi / 2, 31)
    true = np.array([6.0, 5.5, 0.2])
    z = model.sample(true[None], angles, np.random.default_rng(0))[0]
    return g, model, angles, true, z


def teardown_function():
    plt.close("all")


def test_normalise_weights():
    assert normalise_weights(1, 1, 1, 1) == (0.25, 0.25, 0.25, 0.25)
    with pytest.raises(ValueError, match="positive"):
        normalise_weights(0, 0, 0, 0)
    with pytest.raises(ValueError, match=">= 0"):
        normalise_weights(1, -1, 0, 0)


def _curve(fig):
    line = [ln for ln in fig.axes[0].lines if ln.get_label().startswith("p(z")][0]
    return np.asarray(line.get_ydata())


def test_pseudo_density_redraws_with_each_parameter():
    base = _curve(pseudo_density_figure())
    for name, value in [("z_hit", 0.3), ("z_short", 0.5), ("z_max", 0.4), ("z_rand", 0.5),
                        ("sigma_hit", 0.5), ("lambda_short", 2.0), ("z_expected", 3.0)]:
        other = _curve(pseudo_density_figure(**{name: value}))
        assert not np.allclose(base, other), name
    plt.close("all")


def test_pseudo_density_bar_has_the_max_mass_as_area():
    fig = pseudo_density_figure(z_hit=0.6, z_short=0.1, z_max=0.2, z_rand=0.1)
    container = [c for c in fig.axes[0].containers if c.get_label().startswith("max range")][0]
    bar = container.patches[0]
    assert bar.get_width() * bar.get_height() == pytest.approx(0.2)


def test_beam_density_widget_has_the_six_sliders():
    wid = beam_density_widget()
    names = {c.description for c in wid.children if hasattr(c, "description")}
    assert {"z_hit", "z_short", "z_max", "z_rand", "sigma_hit", "lambda_short"} <= names


def test_pose_scan_figure_reports_the_weight(setup):
    g, model, angles, true, z = setup
    fig = pose_scan_figure(g, model, angles, z, *true[:2], np.degrees(true[2]), reference_pose=true)
    assert "exp(0.0)" in fig.axes[0].get_title()
    assert fig.log_likelihood == pytest.approx(model.log_likelihood(true[None], z, angles)[0])
    far = pose_scan_figure(g, model, angles, z, 6.0, 5.9, np.degrees(true[2]), reference_pose=true)
    assert far.log_likelihood < fig.log_likelihood - 5
    # works with a likelihood field too (no expected scan drawn)
    lf = LikelihoodField(g, 8.0)
    fig2 = pose_scan_figure(g, lf, angles, z, *true[:2], 10.0)
    assert np.isfinite(fig2.log_likelihood)


def test_pose_scan_widget_wires_three_sliders(setup):
    g, model, angles, true, z = setup
    wid = pose_scan_widget(g, model, angles, z, start=true, reference_pose=true)
    names = [c.description for c in wid.children if hasattr(c, "description") and c.description]
    assert names[:3] == ["x [m]", "y [m]", "heading [deg]"]


def test_plot_helpers(setup):
    g, model, angles, true, z = setup
    ax = plot_beam_pdf(model, 3.0)
    assert ax.get_ylabel() == "density [1/m]"
    ax = plot_scan_on_map(g, true, angles, measured=z, expected=model.expected(true[None], angles)[0],
                          max_range=8.0, zoom=3.0)
    assert ax.get_xlim() == pytest.approx((3.0, 9.0))
    ax = plot_ranges(angles, measured=z, max_range=8.0)
    assert len(ax.lines) == 2
    im = plot_likelihood_field(LikelihoodField(g, 8.0))
    assert im.get_array().shape == g.shape
