"""The scans' evidence on the odometry's sign (localize.scanmatch, localize run --odometry-sign)."""

import json

import numpy as np
import pytest
from test_expand import _backing_up_run

from localize import cli, io
from localize.geometry import compose, relative
from localize.scanmatch import check_odometry_sign, reports_reversing, scan_points, step_fit


def _office_run(signed: bool, seed: int = 0):
    """test_expand's furnished room: a robot drives 0.25 m steps, backing up on some; odometry noisy, signed or not.

    (In a corridor the check reverses nothing it cannot see: test_a_scan_that_cannot_tell...)
    """
    from localize.raycast import cast

    grid = _backing_up_run()[0]
    rng = np.random.default_rng(seed)
    back = np.zeros(60, dtype=bool)
    back[[10, 11, 12, 30, 31, 45]] = True
    steps = np.c_[np.where(back, -0.25, 0.25), np.zeros(60), rng.normal(0, 0.05, 60)]
    poses = np.zeros((61, 3))
    poses[0] = [3.0, 5.0, 0.0]
    for k, s in enumerate(steps):
        poses[k + 1] = compose(poses[k], s)
    logged = steps + rng.normal(0, [0.01, 0.005, 0.005], steps.shape)       # odometry noise
    if not signed:
        logged[:, 0] = np.abs(logged[:, 0])
    odo = np.zeros_like(poses)
    for k, s in enumerate(logged):
        odo[k + 1] = compose(odo[k], s)
    angles = io.carmen_angles(181)
    ranges = cast(grid, poses, angles, 20.0, method="march") + rng.normal(0, 0.01, (61, 181))
    log = io.LaserLog(times=np.arange(61.0), odometry=odo, ranges=np.clip(ranges, 0, 20.0), angles=angles,
                      max_range=20.0, poses=poses)
    return grid, log, np.flatnonzero(back)


def test_unsigned_odometry_gets_exactly_the_backing_up_steps_reversed():
    grid, log, back = _office_run(signed=False)
    assert not reports_reversing(log.odometry)
    chk = check_odometry_sign(log.ranges, log.angles, log.odometry, log.max_range)
    assert chk.checked == 60
    assert chk.reversed.tolist() == back.tolist()
    assert np.all(chk.fits[:, 1] < 0.5 * chk.fits[:, 0])
    # integrated again, the corrected odometry's steps match the robot's within the odometry noise
    err = relative(chk.odometry[:-1], chk.odometry[1:]) - relative(log.poses[:-1], log.poses[1:])
    assert np.abs(err[:, 0]).max() < 0.05
    assert chk.odometry[0].tolist() == log.odometry[0].tolist()


def test_signed_odometry_is_left_alone():
    grid, log, back = _office_run(signed=True)
    assert reports_reversing(log.odometry)
    chk = check_odometry_sign(log.ranges, log.angles, log.odometry, log.max_range)
    assert chk.reversed.size == 0 and chk.checked == 60
    fixed, got = cli.check_log_odometry(log)                         # auto: signed odometry is not checked
    assert got is None and fixed is log
    fixed, got = cli.check_log_odometry(log, "check")
    assert got.reversed.size == 0 and fixed is log


def test_a_scan_that_cannot_tell_the_directions_apart_changes_nothing():
    """A featureless corridor, seen only sideways: forwards and backwards fit alike, and nothing is reversed."""
    n = 11
    odo = np.c_[np.arange(n) * 0.3, np.zeros(n), np.zeros(n)]
    side = np.radians(np.linspace(20, 160, 71))
    angles = np.concatenate([-side[::-1], side])          # walls 1 m to the right and left, no end in sight
    ranges = np.tile(1.0 / np.abs(np.sin(angles)), (n, 1))
    chk = check_odometry_sign(ranges, angles, odo, 30.0)
    assert chk.reversed.size == 0 and chk.checked == n - 1


def test_the_check_keeps_a_cloud_with_a_robot_whose_odometry_misses_its_backing_up():
    """test_expand's room: without the check (trust) the cloud ends about 1.5 m off; with it, on the robot."""
    grid, log = _backing_up_run(step=0.1, n_forward=30, n_back=8)
    kw = dict(n_particles=2000, init="reference", kld=None, min_motion=(0.0, 0.0), restart_after=0)
    final = {}
    for mode in ("trust", "auto"):
        res = cli.localize_log(grid, log, rng=np.random.default_rng(0), odometry_sign=mode, **kw)
        final[mode] = float(np.hypot(*(res.estimates[-1, :2] - log.poses[-1, :2])))
        if mode == "auto":
            assert res.odometry_check.reversed.tolist() == list(range(30, 38))
        else:
            assert res.odometry_check is None
    assert final["trust"] > 1.0 and final["auto"] < 0.3, final


def test_run_reports_the_reversed_steps(tmp_path):
    grid, log, back = _office_run(signed=False)
    map_path = io.write_ros_map(tmp_path / "office.yaml", grid)
    log_path = io.write_carmen_log(tmp_path / "run.log", log)
    out = tmp_path / "out"
    status = cli.main(["run", "--map", str(map_path), "--log", str(log_path), "--particles", "3000", "--seed", "0",
                       "--quiet", "--out", str(out)])
    assert status == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["odometry_sign"]["reversed_steps"] == back.tolist()
    assert s["settings"]["odometry_sign"] == "auto"


def test_scan_points_and_fit():
    pts = scan_points([1.0, 0.01, 5.0], [0.0, 0.0, 0.5], max_range=5.0, min_range=0.05,
                      sensor_offset=(0.1, 0.0, 0.0))
    assert pts.round(6).tolist() == [[1.1, 0.0]]           # too short and no-return left out; the laser's offset
    assert step_fit(pts, np.zeros((0, 2)), (0, 0, 0)) == pytest.approx(0.09)     # nothing to compare: no fit
    assert step_fit(pts, pts, (0, 0, 0)) == 0.0


@pytest.mark.parametrize("kw, words", [
    (dict(ratio=0.0), "ratio must be in (0, 1]"),
    (dict(ratio=1.5), "ratio must be in (0, 1]"),
    (dict(trunc=-1.0), "trunc"),
])
def test_bad_settings_say_what_is_wrong(kw, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)").replace("]", r"\]")):
        check_odometry_sign(np.ones((2, 3)), np.zeros(3), np.zeros((2, 3)), 30.0, **kw)


def test_mismatched_scans_and_odometry_say_so():
    with pytest.raises(ValueError, match="one row per odometry pose"):
        check_odometry_sign(np.ones((3, 3)), np.zeros(3), np.zeros((2, 3)), 30.0)
    with pytest.raises(ValueError, match="odometry_sign must be one of auto, check, trust"):
        cli.check_log_odometry(_office_run(True)[1], "yes")


def test_smoothing_checks_the_log_once_and_both_passes_use_the_corrected_odometry():
    """Played backwards, every step of unsigned odometry reads as reversing: the check is made on the log as
    recorded, before the passes."""
    from localize import smooth

    grid, log, back = _office_run(signed=False)
    assert reports_reversing(smooth.reverse_log(log).odometry)           # "auto" would skip the backward pass
    res = smooth.smooth_log(grid, log, rng=np.random.default_rng(0), n_particles=2000, init="reference", kld=None,
                            min_motion=(0.0, 0.0), restart_after=0)
    assert res.odometry_check.reversed.tolist() == back.tolist()
    assert res.forward.odometry_check is None and res.backward.odometry_check is None    # trusted: already checked
    for e in (res.forward.estimates, res.backward.estimates[::-1]):               # each pass tracks the robot
        assert np.hypot(*(e[:, :2] - log.poses[:, :2]).T).max() < 0.5
    trusted = smooth.smooth_log(grid, log, rng=np.random.default_rng(0), n_particles=2000, init="reference",
                                kld=None, min_motion=(0.0, 0.0), restart_after=0, odometry_sign="trust")
    assert trusted.odometry_check is None                                        # ... which the log as logged does not
    for e in (trusted.forward.estimates, trusted.backward.estimates[::-1]):      # (measured: 1.65 and 1.34 m off)
        assert np.hypot(*(e[:, :2] - log.poses[:, :2]).T).max() > 1.0
