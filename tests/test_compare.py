"""Tests of localize.compare: scenarios, the shared data, metrics, and the chapter's two claims.

The two statistical claims of the chapter are checked with small but
sufficient Monte Carlo runs (fixed seeds):

* scenario 1 (tracking): the EKF and MCL are NEES-consistent;
* scenario 3 (global localization): MCL succeeds in >= 90% of seeds (and the
  EKF, started from a guess, fails in most of them).
"""

import numpy as np
import pytest

from localize import compare as C
from localize.metrics import nees_bounds
from localize.sensors import LandmarkModel

# --------------------------------------------------------------------------- scenarios and data


def test_six_scenarios_with_their_properties():
    s = C.SCENARIOS
    assert list(s) == ["tracking", "large_prior", "global", "kidnapping", "ambiguity", "heading_noise"]
    assert s["global"].prior == "global" and s["kidnapping"].kidnap_step is not None
    assert not s["ambiguity"].known_ids and s["ambiguity"].prior == "symmetric"
    assert s["heading_noise"].alphas[3] > 10 * s["tracking"].alphas[3]
    # the square of the ambiguity scenario is symmetric under a quarter turn
    sq = s["ambiguity"].landmarks[:4]
    rot = sq @ np.array([[0.0, 1.0], [-1.0, 0.0]])
    assert {tuple(p) for p in np.round(rot, 9)} == {tuple(p) for p in np.round(sq, 9)}


@pytest.mark.parametrize("change, match", [
    (dict(prior="flat"), "prior"),
    (dict(n_steps=3), "n_steps"),
    (dict(mcl_inflation=0.5), "mcl_inflation"),
    (dict(kidnap_step=100), "kidnap_step"),
    (dict(sense_every=0), "sense_every"),
    (dict(n_particles=0), "n_particles"),
])
def test_bad_scenarios_are_rejected(change, match):
    with pytest.raises(ValueError, match=match):
        C.scenario("tracking", **change)
    with pytest.raises(ValueError, match="name"):
        C.scenario("nowhere")


def test_simulate_shapes_sensing_and_kidnap():
    sc = C.scenario("kidnapping", n_steps=30, kidnap_step=12, sense_every=3)
    d = C.simulate(sc, np.random.default_rng(3))
    assert d.truth.shape == (30, 3) and d.controls.shape == (30, 2) and len(d.z) == len(d.ids) == 30
    np.testing.assert_allclose(d.controls, np.tile([sc.v, sc.w], (30, 1)))
    # sightings only every third step, and only of landmarks within range
    for t in range(30):
        if (t + 1) % 3:
            assert len(d.z[t]) == 0
        else:
            r_true = np.hypot(*(sc.landmarks[d.ids[t]] - d.truth[t, :2]).T)
            assert np.all(r_true <= sc.max_range)
            assert np.all(np.abs(d.z[t][:, 0] - r_true) < 6 * sc.sigma_range)
    steps = np.hypot(*np.diff(d.truth[:, :2], axis=0).T)
    assert steps[11] > 1.0 and np.all(np.delete(steps, 11) < 0.6)   # the kidnap is the only jump


def test_same_seed_same_everything_and_filters_share_data():
    sc = C.scenario("tracking", n_steps=15, n_particles=200)
    a = C.run_filters(sc, 7, snapshot_steps=(0, 14))
    b = C.run_filters(sc, 7)
    for n in C.FILTERS:
        np.testing.assert_array_equal(a.estimates[n], b.estimates[n])
    np.testing.assert_array_equal(a.truth, b.truth)
    assert set(a.snapshots) == {0, 14}
    m, P = a.snapshots[14]["EKF"]
    assert m.shape == (3,) and P.shape == (3, 3)
    assert a.snapshots[14]["MCL"].shape == (200, 3)
    # running a subset of the filters sees exactly the same data
    c = C.run_filters(sc, 7, filters=("EKF",))
    np.testing.assert_array_equal(c.estimates["EKF"], a.estimates["EKF"])
    with pytest.raises(ValueError, match="filters"):
        C.run_filters(sc, 7, filters=("PF",))


def test_symmetric_prior_puts_the_gaussian_on_one_mode_and_particles_on_all():
    sc = C.scenario("ambiguity", n_steps=10, n_particles=400)
    r = C.run_filters(sc, 2, snapshot_steps=(0,))
    parts = r.snapshots[0]["MCL"]
    # four position clusters, one per quadrant (the start is rotated about the origin)
    quad = (parts[:, 0] > 0).astype(int) * 2 + (parts[:, 1] > 0).astype(int)
    counts = np.bincount(quad, minlength=4)
    assert np.all(counts > 40), counts


# --------------------------------------------------------------------------- the anonymous-landmark model


def test_anonymous_landmarks_fast_equals_loop_oracle(rng):
    model = LandmarkModel(C.SCENARIOS["ambiguity"].landmarks, 0.2, 0.05)
    s = C.AnonymousLandmarks(model)
    poses = np.column_stack([rng.uniform(-5, 5, 50), rng.uniform(-5, 5, 50), rng.uniform(-np.pi, np.pi, 50)])
    z = model.sample([1.0, -2.0, 0.4], rng)[:3]
    fast, slow = s.log_likelihood(poses, z), s.log_likelihood_loop(poses, z)
    np.testing.assert_allclose(fast - fast.max(), slow - slow.max(), atol=1e-8)
    np.testing.assert_allclose(fast, slow, atol=1e-8)   # same normalisation too


def test_anonymous_landmarks_is_symmetric_on_the_square():
    sq = C.SCENARIOS["ambiguity"].landmarks[:4]
    model = LandmarkModel(sq, 0.2, 0.05)
    s = C.AnonymousLandmarks(model)
    p = np.array([1.0, -2.5, 0.3])
    z = model.expected(p)[0]
    a = np.arange(4) * np.pi / 2
    rots = np.column_stack([np.cos(a) * p[0] - np.sin(a) * p[1], np.sin(a) * p[0] + np.cos(a) * p[1], p[2] + a])
    ll = s.log_likelihood(rots, z)
    np.testing.assert_allclose(ll, ll[0], atol=1e-9)
    # while the model with ids prefers the truth
    ll_ids = model.log_likelihood(rots, z, np.arange(4))
    assert ll_ids[0] > ll_ids[1:].max() + 100


def test_anonymous_landmarks_rejects_models_without_sigmas():
    class NoSigma:
        def expected(self, poses):
            return np.zeros((len(poses), 1, 2))

    with pytest.raises(ValueError, match="sigma_range"):
        C.AnonymousLandmarks(NoSigma())
    with pytest.raises(TypeError, match="expected"):
        C.AnonymousLandmarks(object())


# --------------------------------------------------------------------------- metrics and tables


def test_monte_carlo_metrics_are_consistent_with_the_runs():
    sc = C.scenario("tracking", n_steps=20, n_particles=200)
    mc = C.monte_carlo(sc, range(3), filters=("EKF", "MCL"))
    r = C.run_filters(sc, 1, filters=("EKF", "MCL"))
    m = mc.metrics["EKF"]
    assert m.pos_err.shape == (3, 20) and m.nees.shape == (3, 20)
    e = np.hypot(*(r.estimates["EKF"][:, :2] - r.truth[:, :2]).T)
    np.testing.assert_allclose(m.pos_err[1], e)
    np.testing.assert_allclose(m.pos_rmse[1], np.sqrt(np.mean(e[10:] ** 2)))
    assert mc.nees_bounds == nees_bounds(3, 3)
    rows = C.summary_rows([mc])
    assert [r["filter"] for r in rows] == ["EKF", "MCL"]
    assert all(r["failure_rate"] == 0.0 for r in rows)
    table = C.format_table(rows)
    assert table.count("\n") == 3 and "± " in table and "ms/step" not in table
    assert "ms/step" in C.format_table(C.summary_rows([mc], timing=True))


def test_failure_threshold_is_applied_to_the_final_window():
    sc = C.scenario("tracking", n_steps=20)
    runs = [C.run_filters(sc, 0, filters=("EKF",))]
    runs[0].estimates["EKF"] = runs[0].truth.copy()
    runs[0].estimates["EKF"][-C.FAIL_WINDOW:, 0] += C.FAIL_THRESHOLD + 0.01   # off only at the end
    assert C._metrics(runs, "EKF").failed.tolist() == [True]
    runs[0].estimates["EKF"] = runs[0].truth.copy()
    runs[0].estimates["EKF"][: -C.FAIL_WINDOW, 0] += 5.0                      # off only early
    assert C._metrics(runs, "EKF").failed.tolist() == [False]


# --------------------------------------------------------------------------- the chapter's claims


@pytest.mark.slow
def test_scenario_1_ekf_and_mcl_are_nees_consistent():
    """Seed-averaged NEES inside the 95% chi-square band at most steps, and on average.

    With S = 25 seeds, a filter whose covariance were off by a factor of two
    (NEES ~1.5 or ~6) would fall outside the band [2.2, 3.9] at almost
    every step.
    """
    S = 25
    mc = C.monte_carlo(C.scenario("tracking"), range(S), filters=("EKF", "MCL"))
    lo, hi = mc.nees_bounds
    for name in ("EKF", "MCL"):
        per_step = mc.metrics[name].nees.mean(axis=0)
        assert mc.nees_in_band(name, from_step=5) >= 0.8, (name, per_step.round(2))
        assert lo <= per_step[5:].mean() <= hi, (name, per_step[5:].mean())


@pytest.mark.slow
def test_scenario_3_mcl_succeeds_in_90_percent_of_seeds_and_ekf_mostly_fails():
    S = 20
    mc = C.monte_carlo(C.scenario("global", n_steps=30), range(S), filters=("EKF", "MCL"))
    assert mc.metrics["MCL"].failure_rate <= 0.10, mc.metrics["MCL"].failed
    assert mc.metrics["EKF"].failure_rate >= 0.5


def test_summary_rows_report_rmse_over_all_runs_and_over_successes():
    sc = C.scenario("tracking", n_steps=20)
    runs = [C.run_filters(sc, s, filters=("EKF",)) for s in range(3)]
    runs[0].estimates["EKF"] = runs[0].estimates["EKF"] + [5.0, 0.0, 0.0]   # seed 0 fails: 5 m off throughout
    mc = C.MonteCarlo(sc, [0, 1, 2], {"EKF": C._metrics(runs, "EKF")})
    (row,) = C.summary_rows([mc])
    m = mc.metrics["EKF"]
    assert m.failed.tolist() == [True, False, False]
    assert row["failure_rate"] == pytest.approx(1 / 3)
    assert row["pos_rmse"] == pytest.approx(m.pos_rmse[1:].mean())           # successes only
    assert row["pos_rmse_all"] == pytest.approx(m.pos_rmse.mean())            # the failed run counts
    assert row["pos_rmse_all"] > 1.5 > 0.5 > row["pos_rmse"]
    table = C.format_table([row])
    assert "all runs" in table and "successes" in table and "NEES in 95% band" in table


def test_rate_tolerance_covers_binomial_scatter_at_its_stated_level():
    # 3 standard errors (+1 run) must cover nearly every count drawn at the true rate, and
    # a tolerance without the square root (or without 1/n) would not
    rng = np.random.default_rng(0)
    for p, n in [(0.3, 50), (0.05, 50), (0.8, 20)]:
        k = rng.binomial(n, p, size=20000)
        outside = np.mean(np.abs(k / n - p) > C.rate_tolerance(n, p))
        assert outside < 0.01, (p, n, outside)
        assert np.mean(np.abs(k / n - p) > 3 * np.sqrt(p * (1 - p) / n) / 4) > 0.05  # a quarter of it would not
    assert C.rate_tolerance(50, 0.0) == pytest.approx(0.02)
    with pytest.raises(ValueError, match="rate must lie"):
        C.rate_tolerance(50, 1.5)
    with pytest.raises(ValueError, match="n"):
        C.rate_tolerance(0)


def test_rates_differ_is_a_significance_test_of_two_proportions():
    assert C.rates_differ(0.8, 0.08, 50) and not C.rates_differ(0.08, 0.8, 50)
    assert not C.rates_differ(0.0, 0.0, 50) and not C.rates_differ(0.1, 0.02, 50)
    # false-positive rate at equal true rates stays below ~1% (z = 3)
    rng = np.random.default_rng(1)
    a, b = rng.binomial(50, 0.3, 5000) / 50, rng.binomial(50, 0.3, 5000) / 50
    assert np.mean([C.rates_differ(x, y, 50) for x, y in zip(a, b)]) < 0.01


def test_monte_carlo_with_a_progress_bar_gives_the_same_metrics(capsys):
    sc = C.scenario("tracking", n_steps=10, n_particles=100)
    quiet = C.monte_carlo(sc, range(2), filters=("EKF",))
    shown = C.monte_carlo(sc, range(2), filters=("EKF",), progress=True)
    assert np.array_equal(quiet.metrics["EKF"].pos_err, shown.metrics["EKF"].pos_err)
    assert "scenario tracking" in capsys.readouterr().err


def test_monte_carlo_in_worker_processes_gives_the_same_runs():
    # every seed is an independent run seeded by itself: sharing the seeds among worker processes must not
    # change any number (a pool that reordered results or reused a generator across seeds would)
    sc = C.scenario("global", n_steps=12, n_particles=200)
    one = C.monte_carlo(sc, [3, 1, 2], processes=1)
    two = C.monte_carlo(sc, [3, 1, 2], processes=2)
    for name in C.FILTERS:
        a, b = one.metrics[name], two.metrics[name]
        for attr in ("pos_err", "head_err", "nees", "failed"):
            np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr), err_msg=f"{name}.{attr}")


def test_monte_carlo_checks_processes():
    with pytest.raises(ValueError, match="processes"):
        C.monte_carlo(C.scenario("tracking", n_steps=10), range(2), processes=0)


def test_start_monte_carlo_gives_what_monte_carlo_gives_for_any_number_of_processes():
    # the experiment runs in the background; its results must be those of monte_carlo, scenario by scenario,
    # and the same with workers as without (a pool that mixed up the scenarios' jobs would fail here)
    scs = {"a": C.scenario("global", n_steps=12, n_particles=200), "b": C.scenario("tracking", n_steps=10,
                                                                                    n_particles=100)}
    serial = C.start_monte_carlo(scs, [2, 0], processes=1)
    assert serial.n_done() == 0 and serial.n_runs == 4
    pooled = C.start_monte_carlo(scs, [2, 0], processes=2)
    got_serial, got_pooled = serial.result(), pooled.result()
    assert list(got_pooled) == ["a", "b"] and pooled.n_done() == 4
    assert pooled.result() is got_pooled   # asked again: the same results
    for key, sc in scs.items():
        ref = C.monte_carlo(sc, [2, 0])
        for mc in (got_serial[key], got_pooled[key]):
            assert mc.scenario is sc and mc.seeds == [2, 0]
            for name in C.FILTERS:
                for attr in ("pos_err", "head_err", "nees", "failed"):
                    np.testing.assert_array_equal(getattr(mc.metrics[name], attr), getattr(ref.metrics[name], attr),
                                                  err_msg=f"{key} {name}.{attr}")


def test_start_monte_carlo_keys_and_checks():
    sc = C.scenario("tracking", n_steps=10, n_particles=100)
    ex = C.start_monte_carlo([sc], range(2), filters=("EKF",), processes=1)
    assert list(ex.result()) == ["tracking"] and list(ex.result()["tracking"].metrics) == ["EKF"]
    with pytest.raises(ValueError, match="names repeat"):
        C.start_monte_carlo([sc, sc], range(2), processes=1)
    with pytest.raises(TypeError, match="for one scenario use monte_carlo"):
        C.start_monte_carlo(sc, range(2), processes=1)
    with pytest.raises(TypeError, match=r"scenarios\['x'\] must be a Scenario"):
        C.start_monte_carlo({"x": "tracking"}, range(2), processes=1)
    with pytest.raises(ValueError, match="seeds"):
        C.start_monte_carlo([sc], [], processes=1)
    with pytest.raises(ValueError, match="filters"):
        C.start_monte_carlo([sc], range(2), filters=("PF",), processes=1)
    with pytest.raises(ValueError, match="processes"):
        C.start_monte_carlo([sc], range(2), processes=0)
