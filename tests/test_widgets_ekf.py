"""Tests of the EKF-versus-MCL widget callbacks and the chapter's figures (no browser)."""

import io

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

from localize import compare as C  # noqa: E402
from localize.plot.ekf import covariance_ellipse, plot_beliefs, plot_errors, plot_nees  # noqa: E402
from localize.widgets.ekf import DEMO_VARIANTS, DEMOS, noise_figure, noise_runs  # noqa: E402


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=40)
    plt.close(fig)
    return buf.getvalue()


def test_noise_runs_apply_the_noise_settings():
    runs = noise_runs(heading_noise=10.0, sigma_bearing=0.1, sense_every=3, n_particles=50, n_seeds=2, n_steps=12,
                      seed=5, anonymous=True)
    assert [r.seed for r in runs] == [5, 6]
    sc = runs[0].scenario
    base = C.scenario("tracking")
    np.testing.assert_allclose(sc.alphas[:2], base.alphas[:2])
    np.testing.assert_allclose(sc.alphas[2:], 10 * base.alphas[2:])
    assert sc.sigma_bearing == 0.1 and sc.sense_every == 3 and not sc.known_ids
    assert sum(len(z) for z in runs[0].data.z[:2]) == 0 and len(runs[0].data.z[2]) > 0
    assert 11 in runs[0].snapshots


def test_noise_figure_is_deterministic_and_reacts_to_the_sliders():
    kw = dict(n_seeds=1, n_steps=12, n_particles=80)
    a = _png(noise_figure(**kw))
    assert a == _png(noise_figure(**kw))
    assert a != _png(noise_figure(heading_noise=20.0, **kw))
    fig = noise_figure(anonymous=False, **kw)
    assert "identified" in fig._suptitle.get_text()
    assert "lost" in fig.axes[1].get_title()
    plt.close(fig)


@pytest.mark.parametrize("kw, match", [
    (dict(heading_noise=0.0), "heading_noise"),
    (dict(sigma_bearing=-1.0), "sigma_bearing"),
    (dict(n_particles=5), "n_particles"),
    (dict(n_seeds=0), "n_seeds"),
])
def test_noise_runs_reject_bad_settings(kw, match):
    with pytest.raises(ValueError, match=match):
        noise_runs(**kw)


def test_demos_follow_the_widget_convention():
    assert set(DEMOS) == set(DEMO_VARIANTS) == {"noise_widget"}


def test_chapter_figures_draw_from_a_run_and_a_monte_carlo():
    sc = C.scenario("ambiguity", n_steps=12, n_particles=200)
    run = C.run_filters(sc, 0, snapshot_steps=(0, 11))
    fig = plot_beliefs(run, [0, 11])
    assert len(fig.axes) == 4
    # one ellipse per Gaussian filter in the top row, a particle quiver in the bottom row
    from matplotlib.patches import Circle, Ellipse
    from matplotlib.quiver import Quiver
    assert sum(isinstance(p, Ellipse) and not isinstance(p, Circle) for p in fig.axes[0].patches) == 2
    assert any(isinstance(c, Quiver) for c in fig.axes[2].collections)
    plt.close(fig)
    with pytest.raises(ValueError, match="not recorded"):
        plot_beliefs(run, [5])
    mc = C.monte_carlo(C.scenario("tracking", n_steps=12, n_particles=100), range(2))
    for f in (plot_errors, plot_nees):
        ax = f(mc)
        assert len(ax.lines) >= 3
        plt.close(ax.figure)
    with pytest.raises(ValueError, match="what"):
        plot_errors(mc, what="speed")


def test_covariance_ellipse_axes_follow_the_eigenvectors():
    c = np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]])   # eigenvalues 3 (along x=y) and 1
    e = covariance_ellipse([0, 0, 0], c, n_std=1.0)
    assert np.isclose(e.width, 2 * np.sqrt(3)) and np.isclose(e.height, 2.0)
    assert np.isclose(e.angle % 180, 45.0)
    with pytest.raises(ValueError, match="n_std"):
        covariance_ellipse([0, 0, 0], c, n_std=0)
    plt.close("all")
