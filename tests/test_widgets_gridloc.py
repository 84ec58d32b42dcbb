"""Tests of the grid-resolution widget (localize.widgets.gridloc) without a browser."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize.widgets import gridloc as wg  # noqa: E402


def test_the_run_is_the_chapters_and_read_only():
    fine, odom, truth, scans = wg.chapter_run()
    assert odom.shape == truth.shape == (22, 3) and scans.shape == (22, 12)
    assert abs(np.hypot(*(truth[-1, :2] - odom[-1, :2])) - 0.30) < 0.005      # chapter 3: "ends 0.30 m from"
    with pytest.raises(ValueError):
        scans[0, 0] = 1.0


def test_bins_and_accuracy_follow_the_resolution():
    coarse, fine = wg.grid_run(0.5, 12), wg.grid_run(0.2, 36)
    assert coarse["n_bins"] == 11_520 and fine["n_bins"] == 216_000
    # the chapter's table: 0.236 m and 0.128 m mean position error after step 3
    assert abs(coarse["position_error"][3:].mean() - 0.236) < 0.002
    assert abs(fine["position_error"][3:].mean() - 0.128) < 0.002
    assert fine["position_error"][-1] < fine["odometry_error"][-1]


@pytest.mark.parametrize("bad, match", [((0.3, 36), "cell"), ((0.2, 18), "n_headings")])
def test_bad_settings_are_named(bad, match):
    with pytest.raises(ValueError, match=match):
        wg.grid_run(*bad)


def test_figure_titles_state_the_bins_and_axes_are_fixed():
    a, b = wg.grid_resolution_figure(0.5, 12), wg.grid_resolution_figure(0.2, 72)
    assert "11,520 bins" in a.axes[1].get_title() and "432,000 bins" in b.axes[1].get_title()
    assert a.axes[1].get_ylim() == b.axes[1].get_ylim()
    plt.close(a)
    plt.close(b)
