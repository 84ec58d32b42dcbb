"""Tests of chapter 9's replay widget (localize.widgets.reallog) without a browser."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize.geometry import compose  # noqa: E402
from localize.widgets import reallog as wr  # noqa: E402


@pytest.fixture(scope="module")
def run():
    return wr.demo_run()


def test_the_replay_is_the_command_lines_run(run):
    """log_run keeps the particles of every scan but estimates exactly as localize_log (localize run) does."""
    from localize.pipeline import localize_log

    res = localize_log(run.grid, _log(), rng=np.random.default_rng(0),
                       particles=3000)
    np.testing.assert_array_equal(res.estimates, run.trace.poses)
    assert sorted(run.trace.snapshots) == list(range(len(run)))
    assert all(len(p) <= 500 for p, _ in run.trace.snapshots.values())


def _log():
    from localize.maps import office
    from localize.sim import range_run

    sim = range_run(office(0.1), np.random.default_rng(909), n_steps=80, dt=0.5, speed=0.4,
                    sensor_offset=(0.25, 0.0, 0.0), max_range=12.0, n_clutter=4)
    return sim.to_log()


def test_the_state_and_error_in_the_figure_are_the_runs(run):
    err = np.hypot(*(run.trace.poses[:, :2] - run.reference[:, :2]).T)
    for k in (0, 10, len(run) - 1):
        fig = wr.reallog_figure(k, run)
        assert fig.state == run.trace.state[k]
        assert fig.error == pytest.approx(err[k])
        assert fig._suptitle.get_text().startswith(f"scan {k} of {len(run)}: {run.trace.state[k].upper()}")
        plt.close(fig)
    assert run.trace.state[0] == "searching" and run.trace.state[-1] == "localized"


def test_the_scan_is_drawn_from_the_estimate_through_the_laser_offset(run):
    k = len(run) - 1
    fig = wr.reallog_figure(k, run)
    line = [ln for ln in fig.axes[0].lines if ln.get_label() == "scan drawn at the estimate"][0]
    ends = np.column_stack(line.get_data())
    laser = compose(run.trace.poses[k], run.log.sensor_offset)
    r = run.log.ranges[k]
    hit = r < run.log.max_range
    expected = laser[:2] + r[hit, None] * np.column_stack([np.cos(laser[2] + run.log.angles[hit]),
                                                           np.sin(laser[2] + run.log.angles[hit])])
    np.testing.assert_allclose(ends, expected)
    # a localized estimate puts the end points on the map's walls: most within 0.3 m of an obstacle
    d = run.grid.distance_at(ends, outside=np.inf)
    assert np.mean(d < 0.3) > 0.8, np.mean(d < 0.3)
    wrong = ends + [1.0, 0.0]                          # the same scan a metre off: mostly off the walls
    assert np.mean(run.grid.distance_at(wrong, outside=np.inf) < 0.3) < 0.6
    plt.close(fig)


def test_the_particles_shown_are_the_snapshot_of_that_scan(run):
    for k in (0, 20):
        fig = wr.reallog_figure(k, run)
        pts = fig.axes[0].collections[-1].get_offsets()
        np.testing.assert_array_equal(np.asarray(pts), run.trace.snapshots[k][0][:, :2])
        plt.close(fig)
    spread0 = np.std(run.trace.snapshots[0][0][:, :2], axis=0).max()
    spread_end = np.std(run.trace.snapshots[len(run) - 1][0][:, :2], axis=0).max()
    assert spread0 > 2.0 and spread_end < 0.5       # uniform over the office at first, one cloud at the end


@pytest.mark.parametrize("bad", [-1, 80, 2.5, True, "3"])
def test_a_scan_outside_the_run_is_refused_with_the_range(run, bad):
    with pytest.raises(ValueError, match=r"scan must be a whole number in \[0, 79\]"):
        wr.reallog_figure(bad, run)


def test_a_run_without_snapshots_says_how_to_make_one(run):
    from dataclasses import replace

    bare = replace(run, trace=replace(run.trace, snapshots={}))
    with pytest.raises(ValueError, match="make it with log_run"):
        wr.reallog_figure(3, bare)


def test_the_widget_slider_spans_the_run(run):
    wid = wr.reallog_widget(run, scan=4)
    slider = wid.children[0]
    assert (slider.description, slider.min, slider.max, slider.value) == ("scan", 0, len(run) - 1, 4)
    plt.close("all")


def test_the_zoom_panel_is_centred_on_the_estimate(run):
    k = 30
    fig = wr.reallog_figure(k, run, zoom=3.0)
    x, y = run.trace.poses[k, :2]
    assert fig.axes[1].get_xlim() == pytest.approx((x - 3.0, x + 3.0))
    assert fig.axes[1].get_ylim() == pytest.approx((y - 3.0, y + 3.0))
    plt.close(fig)
    with pytest.raises(ValueError, match="zoom must be a positive number"):
        wr.reallog_figure(k, run, zoom=0.0)
