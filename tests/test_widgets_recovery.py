"""Tests of the kidnapping widget (localize.widgets.recovery) without a browser."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize.widgets import recovery as wr  # noqa: E402

SMALL = dict(n_particles=300)


def test_trial_is_deterministic_and_kidnaps_at_the_stated_step():
    run, tr = wr.kidnap_trial(**SMALL, seed=5)
    wr.kidnap_trial.cache_clear()
    run2, tr2 = wr.kidnap_trial(**SMALL, seed=5)
    np.testing.assert_array_equal(tr.poses, tr2.poses)
    jump = np.hypot(*np.diff(run.poses[:, :2], axis=0).T)
    assert int(np.argmax(jump)) + 1 == wr.KIDNAP_AT and jump.max() > 2.0      # carried away at step 12
    assert len(tr) == wr.N_STEPS


def test_the_repairs_reach_the_filter():
    _, plain = wr.kidnap_trial(augmented=False, **SMALL)
    assert plain.n_injected.sum() == 0                                  # no repair: nothing injected
    _, fixed = wr.kidnap_trial(augmented=False, injection=0.1, **SMALL)
    assert np.all(fixed.n_injected[fixed.resampled] == np.round(0.1 * fixed.n_particles[fixed.resampled]))
    _, aug = wr.kidnap_trial(**SMALL)
    k = wr.KIDNAP_AT
    assert aug.n_injected[k:k + 3].max() > 0.5 * aug.n_particles[k]     # augmented: a new global search


def test_a_high_temperature_calms_the_bursts_while_localized():
    hot = wr.kidnap_summary(*wr.kidnap_trial(temperature=1.0))
    calm = wr.kidnap_summary(*wr.kidnap_trial(temperature=36.0))
    assert hot["injected_localized"] > 0.02 and calm["injected_localized"] < 0.5 * hot["injected_localized"]


def test_figure_reports_what_the_filter_did():
    fig = wr.kidnap_figure()
    s = fig.summary
    assert s == wr.kidnap_summary(*wr.kidnap_trial())
    assert "recovered: 21 steps after" in fig.axes[0].get_title()          # the default robot is found again
    assert f"{s['injected_localized']:.0%}" in fig.axes[1].get_title()
    plt.close(fig)


@pytest.mark.parametrize("bad, match", [(dict(alpha_slow=0.5, alpha_fast=0.2), "alpha_slow < alpha_fast"),
                                        (dict(injection=1.0), "injection"), (dict(temperature=0.5), "temperature"),
                                        (dict(n_particles=10), "n_particles")])
def test_bad_settings_are_named(bad, match):
    with pytest.raises(ValueError, match=match):
        wr.kidnap_trial(**bad)


def test_widget_shows_an_error_not_a_traceback_for_an_invalid_setting():
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        w = wr.kidnap_widget(n_particles=300)
    out = w.children[-1]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):      # outside a kernel the Output widget passes prints through
        w.children[1].value = 0.5              # alpha_slow 0.5 = alpha_fast 0.5: invalid
    text = buf.getvalue() + "".join(o.get("text", "") for o in out.outputs)
    assert "not a valid setting" in text and "alpha_slow" in text
    plt.close("all")
