"""Tests of the sensor-tuning widget (localize.widgets.tuning) without a browser."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize.widgets import tuning as wt  # noqa: E402


def test_the_scan_sees_clutter_the_map_does_not_know():
    run, angles = wt.cluttered_scans()
    assert run.clutter.shape[0] == 8
    assert np.sum(np.isnan(run.world.data) | (run.world.data > 0.5)) > np.sum(np.isnan(run.grid.data) | (run.grid.data > 0.5))


def test_tempering_widens_the_posterior_and_raises_the_ess_monotonically():
    ess = [wt.tuning_figure(temper=t).ess for t in (1.0, 0.3, 0.1, 0.03)]
    plt.close("all")
    assert all(a < b for a, b in zip(ess, ess[1:]))
    assert ess[0] < 0.05 * 1800 and ess[-1] > 0.5 * 1700       # untempered: a handful; gamma = 0.03: most particles


def test_a_narrow_sigma_hit_is_sharper():
    assert wt.tuning_figure(sigma_hit=0.1).ess < wt.tuning_figure(sigma_hit=0.4).ess
    plt.close("all")


def test_residual_correlation_and_suggested_temper():
    rng = np.random.default_rng(3)
    e = rng.normal(size=(50, 200))
    ar = np.empty_like(e)                      # AR(1) along the scan with rho = 0.6
    ar[:, 0] = e[:, 0]
    for b in range(1, e.shape[1]):
        ar[:, b] = 0.6 * ar[:, b - 1] + np.sqrt(1 - 0.36) * e[:, b]
    rho = wt.residual_correlation(ar)
    assert abs(rho - 0.6) < 5 * (1 - 0.36) / np.sqrt(ar.size)          # standard error of a lag-1 correlation
    assert abs(wt.suggest_temper(rho) - 0.25) < 0.03
    assert wt.suggest_temper(-0.3) == 1.0                               # anti-correlated beams: no tempering
    with pytest.raises(ValueError, match="rho"):
        wt.suggest_temper(1.0)
    with pytest.raises(ValueError, match="pairs"):
        wt.residual_correlation([[np.nan, 1.0]])


@pytest.mark.parametrize("bad, match", [(dict(temper=0.0), "temper"), (dict(sigma_hit=5.0), "sigma_hit"),
                                        (dict(kind="sonar"), "kind")])
def test_bad_settings_are_named(bad, match):
    with pytest.raises(ValueError, match=match):
        wt.tuning_figure(**bad)
