"""Tests of localize.smooth: the forward and backward pass over a recorded log and their combination."""

from __future__ import annotations

import csv
import io as _io
import json
from dataclasses import replace

import numpy as np
import pytest

from localize import cli, pipeline, settings, sim, smooth
from localize.geometry import relative, wrap_angle
from localize.io import LaserLog
from localize.maps import office
from localize.mcl import ReversibleOdometry
from localize.runloop import RunTrace, run_filter


# ------------------------------------------------------------------ helpers
def _trace(poses, state, spread=None) -> RunTrace:
    """A RunTrace with the given estimates and states (the rest neutral), for testing the combination alone."""
    p = np.asarray(poses, dtype=float)
    t = len(p)
    z = np.zeros(t)
    return RunTrace(poses=p, means=p.copy(), stds=np.full((t, 3), 0.1),
                    spread=np.full(t, 0.1) if spread is None else np.asarray(spread), best_weight=np.ones(t),
                    n_eff=z + 100, n_particles=np.full(t, 100), n_injected=np.zeros(t, int), p_inject=z.copy(),
                    updated=np.ones(t, bool), resampled=np.zeros(t, bool), degenerate=np.zeros(t, bool),
                    n_valid=np.full(t, 30), fit=np.full(t, np.nan), on_map=np.ones(t),
                    state=np.asarray(state, dtype="<U9"), events=[], beam_evaluations=0, seconds=0.0)


def _office_log(seed: int, n: int = 40) -> tuple[LaserLog, np.ndarray]:
    run = sim.range_run(office(), np.random.default_rng(seed), n_steps=n, speed=0.5,
                        angles=np.linspace(-np.pi / 2, np.pi / 2, 61), max_range=8.0)
    log = LaserLog(times=run.times, odometry=run.odometry, ranges=run.ranges, angles=run.angles,
                   max_range=run.max_range, poses=run.poses)
    return log, run.poses


def _cli_kwargs(*options: str, grid=None) -> dict:
    """``{"settings": RunSettings}`` of ``localize run`` with ``options`` (``--particles auto`` sized on ``grid``)."""
    s = settings.from_namespace(cli.build_parser().parse_args(["run", "--log", "-", "--map", "-", *options]))
    if grid is not None:
        s = replace(s, particles=pipeline.resolve_particles(s.particles, grid))
    return {"settings": s}


def _err(est, truth):
    return np.hypot(*(np.asarray(est)[:, :2] - np.asarray(truth)[:, :2]).T)


# ------------------------------------------------------------------ going backwards in time
def test_reversed_log_controls_are_the_inverse_relative_poses():
    log, _ = _office_log(0, 10)
    back = smooth.reverse_log(log)
    assert np.array_equal(back.ranges, log.ranges[::-1]) and np.array_equal(back.poses, log.poses[::-1])
    # step k of the reversed log goes from scan T-k to scan T-1-k: the inverse of the forward step
    bwd = relative(back.odometry[:-1], back.odometry[1:])[::-1]
    inv = relative(log.odometry[1:], log.odometry[:-1])
    assert np.allclose(bwd, inv)
    fwd = relative(log.odometry[:-1], log.odometry[1:])
    moving = np.abs(fwd[:, 0]) > 0.05
    assert moving.sum() > 5 and np.all(np.sign(bwd[moving, 0]) == -np.sign(fwd[moving, 0]))  # it drives backwards


def test_backward_motion_of_the_reversible_model_lands_on_the_earlier_pose():
    """Noise-free, the reversed odometry pair carries the robot from pose k+1 back to pose k (backward driving)."""
    log, _ = _office_log(1, 12)
    move = ReversibleOdometry((0.0, 0.0, 0.0, 0.0))
    odo = log.odometry
    rng = np.random.default_rng(0)
    # the simulated odometry is noisy, so compare against where the odometry itself says the robot was
    for k in range(len(log) - 1):
        start = odo[k + 1][None, :]
        got = move(start, (odo[k + 1], odo[k]), rng)[0]
        assert np.allclose(got[:2], odo[k, :2], atol=1e-9)
        assert abs(np.angle(np.exp(1j * (got[2] - odo[k, 2])))) < 1e-9


def test_reverse_trace_twice_is_the_identity():
    tr = _trace(np.arange(15.0).reshape(5, 3), ["searching", "searching", "localized", "localized", "lost"])
    tr = replace(tr, events=[(1, "a"), (4, "b")])
    back = smooth.reverse_trace(tr)
    assert list(back.state) == ["lost", "localized", "localized", "searching", "searching"]
    assert back.events == [(0, "b"), (3, "a")]
    again = smooth.reverse_trace(back)
    assert np.array_equal(again.poses, tr.poses) and again.events == tr.events


# ------------------------------------------------------------------ the combination
def test_agreeing_passes_are_averaged_by_their_spreads():
    t = 6
    pf = np.tile([1.0, 1.0, 0.0], (t, 1))
    pb = np.tile([1.3, 1.0, 0.1], (t, 1))
    loc = ["localized"] * t
    s = smooth.combine(_trace(pf, loc, np.full(t, 0.1)), _trace(pb, loc, np.full(t, 0.2)))
    assert list(s.passes) == ["both"] * t and list(s.source) == ["both"] * t
    # inverse-variance weights 1/0.01 and 1/0.04: 0.8 and 0.2
    assert np.allclose(s.poses[:, 0], 0.8 * 1.0 + 0.2 * 1.3)
    assert np.all((s.poses[:, 2] > 0) & (s.poses[:, 2] < 0.05))
    assert np.all(s.spread < 0.1)
    summ = s.summary()
    assert summ["passes"]["both"] == t and summ["share_agree_where_both_localized"] == 1.0


def test_only_one_pass_localized_and_neither():
    t = 8
    p = np.zeros((t, 3))
    f = _trace(p, ["searching"] * 3 + ["localized"] * 3 + ["lost"] * 2)
    b = _trace(p + [5.0, 0, 0], ["localized"] * 2 + ["searching"] * 6)
    s = smooth.combine(f, b)
    assert list(s.passes) == ["backward"] * 2 + ["none"] + ["forward"] * 3 + ["none"] * 2
    assert list(s.state) == ["localized"] * 2 + ["lost"] + ["localized"] * 3 + ["lost"] * 2
    assert np.allclose(s.poses[:2, 0], 5.0) and np.allclose(s.poses[2:, 0], 0.0)
    # where neither is localized, the estimate is that of the pass localized more recently in its own time
    f3 = _trace(p, ["searching"] * 4 + ["localized"] * 4)
    b3 = _trace(p + [5.0, 0, 0], ["localized"] * 2 + ["lost"] * 2 + ["localized"] * 4)
    s3 = smooth.combine(f3, b3)
    assert list(s3.passes[:4]) == ["backward", "backward", "none", "none"]
    assert np.allclose(s3.poses[:4, 0], 5.0) and list(s3.state[2:4]) == ["lost", "lost"]
    s2 = smooth.combine(_trace(p, ["searching"] * t), _trace(p, ["searching"] * t))
    assert set(s2.state) == {"searching"} and s2.first_localized() is None        # honest: neither pass localized
    assert "never localized" in smooth.headline(s2.summary())


def test_a_disagreement_goes_to_the_pass_whose_estimates_fit_the_scans():
    t = 20
    right = np.tile([1.0, 2.0, 0.0], (t, 1))
    wrong = np.tile([8.0, 2.0, 0.0], (t, 1))
    f = _trace(wrong, ["searching"] * 2 + ["localized"] * 18)        # forward locked onto a look-alike place
    b = _trace(right, ["localized"] * 15 + ["searching"] * 5)
    rng = np.random.default_rng(0)
    noise = rng.normal(0, 0.02, t)

    def fit(poses, scans):                   # the scans fit the right place at 0.8, the wrong one at 0.6
        return np.where(np.asarray(poses)[:, 0] < 4, 0.8, 0.6) + noise[np.asarray(scans)]

    s = smooth.combine(f, b, fit)
    assert list(s.passes[:2]) == ["backward"] * 2 and set(s.passes[2:15]) == {"disagree"}
    assert set(s.source[:15]) == {"backward"}
    # forward alone at scans 15-19 followed the same wrong place: not trusted, not localized
    assert np.allclose(s.poses[:, 0], 1.0)
    assert list(s.state) == ["localized"] * 15 + ["lost"] * 5
    (d,) = s.summary()["disagreements"]
    assert d["scans"] == [2, 14] and d["chosen"] == "backward" and d["distrusted_scans"] == [[15, 19]]
    assert d["fit_backward"] > d["fit_forward"]
    line = smooth.headline(s.summary())
    assert "agree on 0% of the 13 scans" in line and "backward taken" in line


def test_a_lone_pass_is_overruled_where_the_other_passs_estimate_fits_the_scans_clearly_better():
    t = 30
    right = np.tile([1.0, 2.0, 0.0], (t, 1))
    wrong = np.tile([8.0, 2.0, 0.0], (t, 1))
    noise = np.random.default_rng(2).normal(0, 0.02, t)

    def fit(poses, scans):                   # the scans fit the right place at 0.8, the wrong one at 0.6
        return np.where(np.asarray(poses)[:, 0] < 4, 0.8, 0.6) + noise[np.asarray(scans)]

    # forward: right and localized, then lost, then re-localized at a look-alike place (scans 14-19), then right
    # again; the backward pass, right throughout, is lost at 12-19 (localized on both sides), its estimate still at
    # the right place
    f = _trace(np.vstack([right[:10], wrong[10:20], right[20:]]),
               ["localized"] * 10 + ["lost"] * 4 + ["localized"] * 16)
    b = _trace(right, ["localized"] * 12 + ["lost"] * 8 + ["localized"] * 10)
    s = smooth.combine(f, b, fit)
    assert list(s.passes[14:20]) == ["forward"] * 6
    assert list(s.state[14:20]) == ["lost"] * 6 and np.allclose(s.poses[14:20, 0], 1.0)   # no claim; the better one
    (o,) = s.summary()["overruled"]
    assert o["scans"] == [14, 19] and o["pass"] == "forward" and o["fit_backward"] > o["fit_forward"]
    assert "overruled on scans 14-19 (forward)" in smooth.headline(s.summary())
    # a lone pass whose place fits at least as well as the other's estimate keeps its claim
    s2 = smooth.combine(_trace(right, f.state), b, fit)
    assert list(s2.state[14:20]) == ["localized"] * 6 and s2.summary()["overruled"] == []
    # without a fit function nothing can overrule
    assert list(smooth.combine(f, b).state[14:20]) == ["localized"] * 6
    # a pass still *searching* there (the backward pass's own start: never localized so far in its time) has no
    # place to offer: its estimate is the best of a fresh cloud on the few scans it has seen, which it fits by
    # selection, and it overrules nothing however well it fits
    t2 = 20
    f3 = _trace(np.vstack([right[:10], wrong[10:t2]]), ["localized"] * 10 + ["lost"] * 4 + ["localized"] * 6)
    b3 = _trace(right[:t2], ["localized"] * 12 + ["searching"] * 8)
    s3 = smooth.combine(f3, b3, fit)
    assert s3.summary()["overruled"] == [] and list(s3.state[14:]) == ["localized"] * 6


def test_a_disagreement_the_scans_cannot_settle_is_not_localized():
    t = 12
    f = _trace(np.tile([8.0, 2.0, 0.0], (t, 1)), ["localized"] * t)
    b = _trace(np.tile([1.0, 2.0, 0.0], (t, 1)), ["localized"] * t)
    noise = np.random.default_rng(1).normal(0, 0.05, (2, t))

    def fit(poses, scans):                   # a symmetric world: both places fit equally well
        return 0.8 + noise[(np.asarray(poses)[:, 0] < 4).astype(int), np.asarray(scans)]

    s = smooth.combine(f, b, fit)
    assert set(s.passes) == {"disagree"}
    assert set(s.state) == {"searching"}                  # honest: two places, no way to tell
    assert s.summary()["disagreements"][0]["reason"].startswith("ambiguous")
    assert "ambiguous" in smooth.headline(s.summary())


# ------------------------------------------------------------------ real filtering of a simulated log
@pytest.mark.parametrize("seed", [0, 3])
def test_smoothing_localizes_the_start_that_the_forward_pass_searched(seed):
    """Office world, CLI defaults (20,000 particles): the forward pass needs a few scans, the backward pass has
    localized long before it reaches the start, so the smoothed trajectory is localized from scan 0."""
    log, truth = _office_log(seed)
    res = smooth.smooth_log(office(), log, rng=np.random.default_rng(seed),
                            **_cli_kwargs("--particles", "20000", "--max-range", "8"))
    fw = res.smooth.forward
    assert fw.state[0] == "searching" and fw.first_localized() >= 2
    assert res.trace.first_localized() == 0 and res.state[0] == "localized"
    e = _err(res.estimates, truth)
    assert np.all(e[res.state == "localized"] < 0.5)
    assert np.mean(res.state == "localized") > np.mean(fw.state == "localized")
    summ = res.smooth.summary()
    assert sum(summ["passes"].values()) == len(log)
    assert summ["share_agree_where_both_localized"] > 0.9


@pytest.mark.parametrize("seed", [1, 38])
def test_smoothing_fixes_a_forward_pass_localized_in_the_wrong_place(seed):
    """Seeds 1 and 38: with these settings the forward pass locks onto a wrong place of the office and says
    "localized"; the backward pass is right. The scan fit gives the stretch to the backward pass, and no smoothed
    scan claims a wrong place. Measured with the default state (the probability, stop 53; this test's criteria over
    seeds 0-59): the forward pass calls a wrong place localized at
    more than 10 scans in seeds 1, 2, 4, 5, 26, 38 and 53 (with the threshold state: 1, 2, 4, 5, 22, 28, 33, 41, 43,
    49 and 53). Smoothing fixes 1, 38 and 53; in 2, 4 and 5 both passes agree on the wrong place at some scans,
    which smoothing cannot fix, and in 26 two smoothed scans keep a wrong claim (the forward pass's 30)."""
    log, truth = _office_log(seed)
    res = smooth.smooth_log(office(), log, rng=np.random.default_rng(seed),
                            **_cli_kwargs("--particles", "20000", "--max-range", "8"))
    fw = res.smooth.forward
    e_f, e = _err(fw.poses, truth), _err(res.estimates, truth)
    if np.sum((fw.state == "localized") & (e_f > 1.0)) <= 10:
        pytest.skip(f"seed {seed}: the forward pass no longer fails with these defaults; pick a seed where it does")
    loc = res.state == "localized"
    assert np.all(e[loc] < 0.5)                                  # no smoothed scan claims a wrong place ...
    right_fw = np.sum((fw.state == "localized") & (e_f < 0.5))
    assert loc.sum() >= 10 and loc.sum() > right_fw + 5         # ... and clearly more scans are rightly localized
    assert any(d["chosen"] == "backward" for d in res.smooth.summary()["disagreements"])


# ------------------------------------------------------------------ the command line
def _demo_files(tmp_path, steps=40):
    from localize.demo import make_demo

    return make_demo(tmp_path / "demo", np.random.default_rng(0), steps=steps)


def test_cli_smooth_writes_and_states_which_passes_agree(tmp_path):
    d = _demo_files(tmp_path)
    out, err = _io.StringIO(), _io.StringIO()
    code = cli.main(["run", "--map", str(d.map_path), "--log", str(d.log_path), "--smooth", "--particles", "20000",
                     "--out", str(tmp_path / "out")], stdout=out, stderr=err)
    assert code == 0, err.getvalue()
    text = out.getvalue()
    assert "forward and backward pass" in text and "localized from scan" in text
    with open(tmp_path / "out" / "trajectory.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 40
    assert {r["passes"] for r in rows} <= set(smooth.PASSES)
    assert {r["source"] for r in rows} <= {"both", "forward", "backward", "none"}
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["settings"]["smooth"] is True
    assert sum(summary["smooth"]["passes"].values()) == 40
    assert summary["state"]["first_localized_scan"] == 0           # the smoothed trajectory's state
    assert "--smooth" in cli.build_parser()._subparsers._group_actions[0].choices["run"].format_help()


def test_cli_without_smooth_is_unchanged(tmp_path):
    d = _demo_files(tmp_path, steps=10)
    code = cli.main(["run", "--map", str(d.map_path), "--log", str(d.log_path), "--particles", "2000",
                     "--out", str(tmp_path / "out"), "--quiet"], stdout=_io.StringIO(), stderr=_io.StringIO())
    assert code == 0
    with open(tmp_path / "out" / "trajectory.csv") as fh:
        head = fh.readline().strip().split(",")
    assert "passes" not in head and head[:7] == ["time", "x", "y", "theta", "spread", "n_eff", "state"]
    assert "smooth" not in json.loads((tmp_path / "out" / "summary.json").read_text())


# ------------------------------------------------------------------ bad input
def test_bad_input_is_reported():
    log, _ = _office_log(0, 5)
    p = np.zeros((5, 3))
    tr = _trace(p, ["localized"] * 5)
    with pytest.raises(ValueError, match="different logs: forward has 5 scans, backward 4"):
        smooth.combine(tr, _trace(p[:4], ["localized"] * 4))
    with pytest.raises(TypeError, match="backward must be a localize.runloop.RunTrace"):
        smooth.combine(tr, "not a trace")
    with pytest.raises(ValueError, match="agree_distance"):
        smooth.combine(tr, tr, agree_distance=0.0)
    with pytest.raises(ValueError, match="agree_heading"):
        smooth.smooth_log(office(), log, rng=np.random.default_rng(0), agree_heading=-1.0)
    with pytest.raises(ValueError, match="window"):
        smooth.combine(tr, tr, window=-1)
    with pytest.raises(TypeError, match="grid must be an OccupancyGrid"):
        smooth.smooth_log("map.yaml", log, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="at least 2 scans"):
        smooth.smooth_log(office(), log.select([0]), rng=np.random.default_rng(0))
    with pytest.raises(TypeError, match="RunTrace"):
        smooth.reverse_trace(np.zeros(3))


def test_cli_smooth_on_a_one_scan_log_is_an_error_not_a_traceback(tmp_path):
    d = _demo_files(tmp_path, steps=5)
    err = _io.StringIO()
    code = cli.main(["run", "--map", str(d.map_path), "--log", str(d.log_path), "--scans", "0:1", "--smooth",
                     "--particles", "2000", "--out", str(tmp_path / "out")], stdout=_io.StringIO(), stderr=err)
    assert code == 2
    assert "localize: error: --smooth needs a log of at least 2 scans" in err.getvalue()
    assert not (tmp_path / "out" / "summary.json").exists()


def test_run_filter_is_the_driver_of_both_passes(monkeypatch):
    """No second filtering loop: both passes go through localize.runloop.run_filter."""
    calls = []
    import localize.runloop as runloop

    def spy(*a, **k):
        calls.append(a[1])
        return run_filter(*a, **k)

    monkeypatch.setattr(runloop, "run_filter", spy)
    log, _ = _office_log(0, 6)
    smooth.smooth_log(office(), log, rng=np.random.default_rng(0), n_particles=500, kld=None)
    assert calls == [6, 6]


def test_with_odometry_a_losing_pass_is_distrusted_only_while_it_follows_its_wrong_place():
    t = 20
    right = np.tile([1.0, 2.0, 0.0], (t, 1))
    fpos = right.copy()
    fpos[2:10] = [8.0, 2.0, 0.0]                        # forward: a look-alike place, then it jumps back (scan 10)
    f = _trace(fpos, ["searching"] * 2 + ["localized"] * 18)
    bpos = right.copy()
    bpos[10:] = [5.0, 5.0, 1.0]                          # backward: right, not yet localized at 10-19
    b = _trace(bpos, ["localized"] * 10 + ["searching"] * 10)
    odo = np.zeros((t, 3))                               # the robot stands still

    def fit(poses, scans):
        return np.where(np.hypot(*(np.asarray(poses)[:, :2] - [1.0, 2.0]).T) < 0.5, 0.8, 0.5) + 0.01 * np.sin(scans)

    s = smooth.combine(f, b, fit, odometry=odo)
    (d,) = s.summary()["disagreements"]
    assert d["scans"] == [2, 9] and d["chosen"] == "backward" and "distrusted_scans" not in d
    assert list(s.source[10:]) == ["forward"] * 10 and set(s.state) == {"localized"}
    assert np.allclose(s.poses[:, :2], [1.0, 2.0])
    # without odometry the whole localized run of the losing pass is distrusted
    s2 = smooth.combine(f, b, fit)
    assert s2.summary()["disagreements"][0]["distrusted_scans"] == [[10, 19]]
    with pytest.raises(ValueError, match="odometry must have shape"):
        smooth.combine(f, b, fit, odometry=np.zeros((3, 3)))


def test_where_neither_pass_is_localized_the_better_fitting_estimate_is_used():
    t = 12
    p = np.zeros((t, 3))
    f = _trace(p, ["searching"] * 3 + ["localized"] * 3 + ["lost"] * 6)
    # backward: localized at 9-11 (its start), lost at 2-8, localized again at 0-1
    b = _trace(p + [5.0, 0, 0], ["localized"] * 2 + ["lost"] * 7 + ["localized"] * 3)

    def fit(poses, scans):                                    # the backward pass's place fits the scans
        return np.where(np.asarray(poses)[:, 0] > 4, 0.9, 0.3)

    s = smooth.combine(f, b, fit)
    assert s.passes[2] == "none" and s.poses[2, 0] == 5.0          # forward has found no place yet there
    assert list(s.passes[6:9]) == ["none"] * 3 and np.allclose(s.poses[6:9, 0], 5.0)   # both lost: the scans decide
    assert list(s.state[6:9]) == ["lost"] * 3                      # still honest: neither pass is localized
    # a pass still searching is not compared: the estimate is the other pass's, however well the fresh one fits
    b2 = _trace(p + [5.0, 0, 0], ["localized"] * 2 + ["searching"] * 10)
    s2 = smooth.combine(f, b2, fit)
    assert list(s2.passes[6:]) == ["none"] * 6 and np.allclose(s2.poses[6:, 0], 0.0)


@pytest.mark.data
@pytest.mark.slow
def test_real_log_smoothed_from_the_first_scan(shared_data):
    """ACES, first 200 scans, map from the corrected poses, raw odometry, CLI defaults: the forward pass
    searches at the start, the smoothed trajectory is localized from scan 0 and every scan it calls
    localized is within 1 m of the corrected pose."""
    from localize import io as lio
    from localize.mapping import map_from_log

    p = shared_data / "carmen" / "aces-corrected.log.gz"
    if not p.exists():
        pytest.skip(f"{p} not found")
    log = lio.read_log(p).select(slice(0, 200))
    grid = map_from_log(log, resolution=0.05)
    res = smooth.smooth_log(grid, log, rng=np.random.default_rng(0), **_cli_kwargs(grid=grid))
    fw = res.smooth.forward
    assert fw.first_localized() >= 2 and res.trace.first_localized() == 0
    loc = res.state == "localized"
    e = _err(res.estimates, log.poses)
    assert loc.mean() > np.mean(fw.state == "localized") and np.all(e[loc] < 1.0)


def test_agreeing_headings_are_the_weighted_circular_mean_bit_for_bit():
    """Where both passes agree, the heading is geometry.circular_mean of the two, weighted by the inverse squared
    spreads: bit for bit the weighted angle mean combine wrote out before (across the +-pi seam too), and not the
    unweighted mean (which a dropped weight would give)."""
    from types import SimpleNamespace

    rng = np.random.default_rng(3)
    n = 2000
    th_f = wrap_angle(np.pi + rng.normal(0.0, 0.2, n))                       # around the seam
    th_b = wrap_angle(th_f + rng.normal(0.0, 0.1, n))
    sp_f, sp_b = rng.uniform(0.001, 0.5, n), rng.uniform(0.001, 0.5, n)
    sp_f[::50] = np.nan                                                     # a spread the run could not measure
    poses_f = np.c_[rng.normal(size=(n, 2)), th_f]
    poses_b = np.c_[poses_f[:, :2] + rng.normal(0.0, 0.1, (n, 2)), th_b]
    stds = np.full((n, 3), 0.1)
    fw = SimpleNamespace(poses=poses_f, stds=stds, spread=sp_f)
    bw = SimpleNamespace(poses=poses_b, stds=stds, spread=sp_b)
    got = smooth._estimates(fw, bw, np.zeros(n, dtype=bool), np.ones(n, dtype=bool))[0][:, 2]
    wf = 1.0 / np.maximum(np.nan_to_num(sp_f, nan=1.0), 0.01) ** 2
    wb = 1.0 / np.maximum(np.nan_to_num(sp_b, nan=1.0), 0.01) ** 2
    old = wrap_angle(np.arctan2(wf * np.sin(th_f) + wb * np.sin(th_b), wf * np.cos(th_f) + wb * np.cos(th_b)))
    assert np.array_equal(got, old)
    unweighted = wrap_angle(np.arctan2(np.sin(th_f) + np.sin(th_b), np.cos(th_f) + np.cos(th_b)))
    assert np.mean(np.abs(wrap_angle(got - unweighted)) > 1e-3) > 0.5
