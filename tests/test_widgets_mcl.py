"""Tests of the MCL player widget (localize.widgets.mcl) without a browser.

The generic checks (deterministic demos, variants that redraw) live in
tests/test_widgets_common.py; here: the callback's contract, its cache, the
widget wiring, and that the figure shows what the filter did.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize.widgets import mcl as wm  # noqa: E402

SMALL = dict(n_particles=300, n_steps=4, n_beams=12)


def test_simulate_is_deterministic_and_snapshots_every_step():
    run_a, tr_a = wm.simulate(**SMALL)
    run_b, tr_b = wm.simulate(**SMALL)
    assert len(tr_a) == 4 and sorted(tr_a.snapshots) == [0, 1, 2, 3]
    np.testing.assert_array_equal(tr_a.poses, tr_b.poses)
    np.testing.assert_array_equal(run_a.poses, run_b.poses)
    p, w = tr_a.snapshots[2]
    assert p.shape == (tr_a.n_particles[2], 3) and abs(w.sum() - 1) < 1e-9
    # a different seed gives a different run
    _, tr_c = wm.simulate(seed=1, **SMALL)
    assert not np.array_equal(tr_a.poses, tr_c.poses)


def test_parameters_reach_the_filter():
    _, tr = wm.simulate(threshold=1.0, **SMALL)
    assert tr.resampled.all()                         # threshold 1: resample at every step
    _, tr0 = wm.simulate(threshold=0.0, **SMALL)
    assert not tr0.resampled.any()                    # threshold 0: never
    _, tr_beam = wm.simulate(sensor="beam", **SMALL)
    assert not np.array_equal(tr_beam.poses, tr.poses)


@pytest.mark.parametrize("bad, match", [
    (dict(n_particles=5), "n_particles"),
    (dict(resampler="roulette"), "resampler"),
    (dict(alpha_scale=0.0), "alpha_scale"),
    (dict(sigma_hit=-1.0), "sigma_hit"),
    (dict(sensor="sonar"), "sensor"),
])
def test_bad_parameters_are_named(bad, match):
    with pytest.raises(ValueError, match=match):
        wm.simulate(**{**SMALL, **bad})


def test_figure_shows_the_step_and_the_error():
    run, tr = wm.simulate(**SMALL)
    fig = wm.mcl_run_figure(run, tr, 3)
    try:
        ax, ax2 = fig.axes[:2]
        assert ax.get_title().startswith("step 3:")
        assert f"{tr.n_particles[3]} particles" in ax.get_title()
        # the error curve: the red part ends at the current step
        red = ax2.lines[1]
        assert len(red.get_xdata()) == 4
    finally:
        plt.close(fig)
    with pytest.raises(ValueError, match="step"):
        wm.mcl_run_figure(run, tr, 4)


def test_cache_reuses_runs_and_keeps_only_one():
    cache = {}
    f1 = wm.mcl_widget_figure(1, cache=cache, **SMALL)
    (key1,) = cache
    run1 = cache[key1][0]
    f2 = wm.mcl_widget_figure(3, cache=cache, **SMALL)        # only the step changed: same run object
    assert cache[key1][0] is run1
    f3 = wm.mcl_widget_figure(3, cache=cache, **{**SMALL, "n_particles": 200})
    assert len(cache) == 1 and key1 not in cache
    for f in (f1, f2, f3):
        plt.close(f)


def test_player_builds_and_redraws():
    ipw = pytest.importorskip("ipywidgets")
    w = wm.mcl_player(n_steps=3, n_particles=200)
    assert isinstance(w, ipw.VBox)
    controls, out = w.children
    sliders = [c for box in controls.children for c in box.children]
    names = {getattr(c, "description", "") for c in sliders}
    assert {"particles", "resampler", "N_eff/N <", "alpha ×", "sigma_hit [m]", "step", "play"} <= names
    step = next(c for c in sliders if c.description == "step")
    assert step.max == 2
    plt.close("all")
