"""Validation on real robot data (../shared/data or $LOCALIZE_DATA); skipped cleanly when absent.

* every CARMEN log and the Willow Garage ROS map read without error, with the
  numbers the data's README states;
* maps of the Intel lab and Freiburg 079 built from the corrected poses agree
  with the scans;
* MCL with the real scans and the real odometry increments tracks the corrected
  poses (median position error < 0.15 m) from the first corrected pose;
* global localization on the built maps converges (error < 0.5 m for 20 scans in
  a row) within a stated number of scans in most seeds.

Subsets of the scans keep the file under a minute on one core.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from localize import cli, io, mapping
from localize.geometry import angle_diff, relative

pytestmark = [pytest.mark.data, pytest.mark.slow]

LOGS = {  # name: (scans, beams, README's median odometry error per scan: metres, degrees)
    "intel": (910, 180, 0.05, 2.6),
    "freiburg-079": (4791, 360, 0.03, 0.7),
    "aces": (440, 180, None, None),
    "csail": (406, 361, None, None),
}
EVERY = {"intel": 1, "freiburg-079": 4}  # scans used for mapping and global localization


def carmen(shared_data, name):
    p = shared_data / "carmen" / f"{name}-corrected.log.gz"
    if not p.exists():
        pytest.skip(f"{p} not found")
    return p


@pytest.fixture(scope="module")
def logs(shared_data):
    return {name: io.read_log(carmen(shared_data, name)) for name in ("intel", "freiburg-079")}


@pytest.fixture(scope="module")
def built(logs):
    return {name: mapping.map_from_log(log, resolution=0.05, every=EVERY[name]) for name, log in logs.items()}


@pytest.mark.parametrize("name", list(LOGS))
def test_carmen_logs_read(shared_data, name):
    scans, beams, odo_m, odo_deg = LOGS[name]
    log = io.read_log(carmen(shared_data, name))
    assert log.format == "carmen" and len(log) == scans and log.n_beams == beams
    assert log.poses is not None and log.meta["odometry"].startswith("re-anchored")
    assert np.allclose(log.sensor_offset, 0.0)
    assert 40.0 <= log.max_range <= 82.0
    assert log.no_return.mean() < 0.2
    if odo_m is not None:
        m, c = log.motions(), relative(log.poses[:-1], log.poses[1:])
        e_xy = np.median(np.hypot(*(m - c)[:, :2].T))
        e_th = np.degrees(np.median(np.abs(angle_diff(m[:, 2], c[:, 2]))))
        assert abs(e_xy - odo_m) < 0.015 and abs(e_th - odo_deg) < 0.5, (e_xy, e_th)


def test_willow_map_and_its_grey_walls(shared_data):
    y = shared_data / "willow" / "willow-2010-02-18-0.10.yaml"
    if not y.exists():
        pytest.skip(f"{y} not found")
    strict = io.read_map(y)
    assert strict.shape == (608, 566) and strict.resolution == pytest.approx(0.1)
    assert np.allclose(strict.origin, 0.0)
    # map_server semantics: most walls (grey 100-200) are unknown, very few cells occupied
    assert strict.occupied.sum() < 1000 and strict.unknown.sum() > 200_000
    walls = io.read_map(y, not_free="occupied")
    assert not walls.unknown.any() and walls.free.sum() == strict.free.sum()
    lowered = io.read_map(y, occupied_thresh=0.2)
    assert lowered.occupied.sum() > 9000  # the grey walls now count as walls
    # either way a laser cannot cross a wall: unknown cells block rays by default
    assert np.array_equal(strict.obstacles, walls.obstacles)


@pytest.mark.parametrize("name", ["intel", "freiburg-079"])
def test_built_maps_agree_with_the_scans(logs, built, name):
    log, grid = logs[name], built[name]
    # the robot drove through free space
    assert grid.is_free(log.poses).mean() > 0.97
    # scan end points (at the corrected poses) lie on or next to occupied cells
    sub = log.select(slice(0, None, 25))
    hit = ~sub.no_return & (sub.ranges < 20.0)
    laser = sub.laser_poses()
    a = laser[:, 2:3] + sub.angles[None, :]
    ends = np.stack([laser[:, 0:1] + sub.ranges * np.cos(a), laser[:, 1:2] + sub.ranges * np.sin(a)], -1)[hit]
    d = grid.distance_at(ends, outside=np.inf)
    assert np.mean(d <= 0.1) > 0.9


def track(log, grid, every=1, n=500, seed=0):
    sub = log.select(slice(0, None, every))
    res = cli.localize_log(grid, sub, n_particles=n, rng=np.random.default_rng(seed), init="reference",
                           beams=60, max_range=30.0, alphas=(0.02, 0.005, 0.01, 0.02), temper=1.0,
                           min_motion=(0.0, 0.0), sensor_params={"sigma_hit": 0.15})
    return np.hypot(*(res.estimates[:, :2] - sub.poses[:, :2]).T)


def test_tracking_intel(logs, built):
    err = track(logs["intel"], built["intel"])
    print(f"\nintel tracking, 910 scans, 500 particles: median {np.median(err):.3f} m, "
          f"90% {np.percentile(err, 90):.3f} m, max {err.max():.3f} m")
    assert np.median(err) < 0.15 and np.percentile(err, 90) < 0.3


def test_tracking_freiburg(logs, built):
    """Scans 0-800 (three minutes of driving).

    At scans 837-846 the real odometry reports about 0.9 m forward while the
    corrected poses move about 0.9 m backward: no odometry noise model explains
    that, and a tracking filter without recovery loses the robot there (global
    re-localization, chapter 8, is the cure). The test stops before it.
    """
    log = logs["freiburg-079"].select(slice(0, 800))
    err = track(log, built["freiburg-079"])
    print(f"\nfreiburg-079 tracking, scans 0-800, 500 particles: median {np.median(err):.3f} m, "
          f"90% {np.percentile(err, 90):.3f} m, max {err.max():.3f} m")
    assert np.median(err) < 0.15 and np.percentile(err, 90) < 0.3


def test_freiburg_odometry_glitch_is_real(logs):
    log = logs["freiburg-079"].select(slice(836, 848))
    m, c = log.motions(), relative(log.poses[:-1], log.poses[1:])
    assert m[:, 0].sum() > 0.5 and c[:, 0].sum() < -0.5


def test_freiburg_odometry_never_reports_backing_up(logs):
    """The appendix's (book/13_appendix_defaults) explanation of Freiburg's failures: the odometry's speed has no sign, and the two start scans
    that fail at every seed are the runs in which the robot backs up most often."""
    log = logs["freiburg-079"]
    m, c = log.motions(), relative(log.poses[:-1], log.poses[1:])
    assert not np.any(m[:, 0] < -1e-3)                        # the odometry never drives backwards ...
    backing = (c[:, 0] < -0.05) & (m[:, 0] >= 0)               # ... while the robot backs up by > 5 cm
    assert 80 <= backing.sum() <= 150                          # "about a hundred of its steps"
    b = (c[:, 0] < -0.02) & (m[:, 0] >= 0)
    per_run = {s: int(b[s:s + 299].sum()) for s in _bench().start_scans(len(log), 300, 20)}
    assert sorted(per_run, key=per_run.get)[-2:] == [709, 1182], per_run
    assert (per_run[709], per_run[1182]) == (37, 50), per_run


def test_freiburg_odometry_creeps_sideways_while_the_robot_turns_on_the_spot(logs):
    """The appendix (book/13_appendix_defaults, which computes them too): in 117 of Freiburg's steps the odometry point moves a few millimetres *sideways* while the robot
    turns (the corrected poses move 2 cm, median); as "turn towards the destination, drive, turn" (PR table 5.6)
    those steps get rot1 near 90 degrees and a translation noise of about half a metre; ReversibleOdometry counts
    them as turns on the spot, with a few centimetres (the appendix's numbers)."""
    from localize.motion import ReversibleOdometry, odometry_to_control, odometry_variances

    log = logs["freiburg-079"]
    move = ReversibleOdometry(cli.DEFAULTS["alphas"])
    od = np.asarray(log.odometry)
    s, c = relative(od[:-1], od[1:]), relative(log.poses[:-1], log.poses[1:])
    t = np.hypot(s[:, 0], s[:, 1])
    spot = np.array([move.min_trans < tt <= move.on_the_spot(tt, th) for tt, th in zip(t, s[:, 2])])
    rot1, trans, rot2 = odometry_to_control(od[:-1], od[1:], move.min_trans)
    sideways = spot & (np.minimum(np.abs(rot1), np.pi - np.abs(rot1)) > np.pi / 4)
    assert sideways.sum() == 117, sideways.sum()                                   # the appendix
    assert np.median(t[sideways]) < 0.01 and np.median(np.hypot(*c[sideways, :2].T)) < 0.03
    textbook = np.sqrt(odometry_variances(rot1, trans, rot2, cli.DEFAULTS["alphas"])[1][sideways])
    on_spot = np.array([move.on_the_spot(tt, th) for tt, th in zip(t[sideways], s[sideways, 2])])
    # "from about 0.46 m to about 3 cm"
    assert abs(np.median(textbook) - 0.46) < 0.01 and abs(np.median(on_spot) - 0.03) < 0.002, (
        np.median(textbook), np.median(on_spot))


@pytest.mark.parametrize("name", list(LOGS))
def test_the_scans_reverse_only_steps_in_which_the_robot_backed_up(shared_data, name):
    """--odometry-sign: on Freiburg (unsigned odometry) the scans reverse about 80 steps, every one of them a step
    in which the corrected poses move backwards; on the logs whose odometry has a sign, checked anyway, none."""
    from localize.scanmatch import check_odometry_sign, reports_reversing

    log = io.read_log(carmen(shared_data, name))
    chk = check_odometry_sign(log.ranges, log.angles, log.odometry, log.max_range, sensor_offset=log.sensor_offset)
    c = relative(log.poses[:-1], log.poses[1:])
    assert chk.checked > 0.75 * np.sum(np.hypot(*log.motions()[:, :2].T) >= 0.05)
    if name == "freiburg-079":
        assert not reports_reversing(log.odometry)
        assert (chk.reversed.size, chk.checked) == (77, 3631), (chk.reversed.size, chk.checked)   # the appendix
        assert np.all(c[chk.reversed, 0] < 0)                             # not one wrong reversal
        backing = (c[:, 0] < -0.05) & (np.hypot(*log.motions()[:, :2].T) >= 0.05)
        assert np.isin(np.flatnonzero(backing), chk.reversed).mean() > 0.9  # and nearly every clear one found
    else:
        assert reports_reversing(log.odometry)
        assert chk.reversed.size == 0


@pytest.mark.parametrize("name, n_scans, within", [("intel", 130, 100), ("freiburg-079", 240, 200)])
def test_global_localization_converges_in_most_seeds(logs, built, name, n_scans, within):
    every = EVERY[name]
    sub = logs[name].select(slice(0, n_scans * every, every))
    steps = []
    for seed in range(3):
        kw = cli.run_kwargs(cli.build_parser().parse_args(["run", "--log", "-", "--map", "-"]),  # CLI defaults
                            grid=built[name])
        res = cli.localize_log(built[name], sub, rng=np.random.default_rng(seed), **kw)
        err = np.hypot(*(res.estimates[:, :2] - sub.poses[:, :2]).T)
        steps.append(cli.converged_at(err, 0.5, hold=20))
    print(f"\n{name} global localization, CLI defaults, every {every} scan(s): "
          f"converged at scans {steps}")
    ok = [s is not None and s <= within for s in steps]
    assert sum(ok) >= 2, steps


def test_one_command_on_the_intel_log(shared_data, tmp_path):
    """`localize run --log intel --build-map` end to end (first 150 scans)."""
    import json

    out = tmp_path / "intel"
    status = cli.main(["run", "--log", str(carmen(shared_data, "intel")), "--build-map", "--scans", "0:150",
                       "--particles", "10000", "--seed", "1", "--quiet", "--out", str(out)])
    assert status == 0
    s = json.loads((out / "summary.json").read_text())
    print(f"\nlocalize run on intel scans 0-150: converged at {s['convergence_step_reference']}, "
          f"median error after {s['median_error_after_convergence_m']} m, {s['real_time_factor']}x real time")
    assert s["scans"] == 150 and s["real_time_factor"] is not None
    assert s["convergence_step_reference"] is not None and s["median_error_after_convergence_m"] < 0.5


def _bench():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_global.py"
    spec = importlib.util.spec_from_file_location("bench_global", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_which_runs_start_in_the_unknown_region(shared_data, tmp_path, capsys):
    """benchmarks/global_unknown.py: Willow start 1016 of the held-out draw spends 45 of its first 91 scans (those by
    which a run must find the robot) in the region the degraded map leaves unknown, start 1000 none; the table splits
    the runs so, and names the failure."""
    import importlib.util
    from pathlib import Path

    if not (shared_data / "willow").exists():
        pytest.skip("the Willow map is not there")
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "global_unknown.py"
    spec = importlib.util.spec_from_file_location("global_unknown", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    runs = tmp_path / "runs.jsonl"
    runs.write_text("".join(json.dumps({"name": "willow", "start": start, "seed": 1000, "scans": 300,
                                        "success": ok}) + "\n" for start, ok in ((1016, False), (1000, True))))
    assert mod.main([str(runs)]) == 0
    out = capsys.readouterr().out
    assert "| willow | 1 | 0 | 1 | 1 |" in out                 # split by the region, one success each side
    early, total = (int(v) for v in re.search(r"willow 1016 \(seed 1000\): (\d+) of the first 30% of the scans, "
                                               r"(\d+) of all", out).groups())
    assert 30 <= early <= 91 and early < total <= 300       # measured: 45 of the first 91, 101 of 300
    (tmp_path / "empty.jsonl").write_text("")
    (tmp_path / "bad.jsonl").write_text('{"name": "willow"\n')
    for bad, says in (("missing.jsonl", "no such file"), ("empty.jsonl", "no runs"), ("bad.jsonl", "line 1")):
        with pytest.raises(SystemExit):
            mod.main([str(tmp_path / bad)])
        assert says in capsys.readouterr().err


def test_benchmark_success_rule():
    """The rule of benchmarks/bench_global.py on made-up trajectories (no data needed)."""
    b = _bench()
    ref = np.zeros((100, 3))
    est = np.zeros((100, 3))
    est[:20, 0] = 5.0                                    # wrong for 20 scans, then right
    j = b.judge(est, ref)
    assert j["success"] and j["converged_at"] == 20
    late = est.copy()
    late[:40, 0] = 5.0                                   # right only after 30% of the run
    assert not b.judge(late, ref)["success"]
    lost = est.copy()
    lost[70:, 0] = 1.5                                   # right, then more than 1 m off
    assert not b.judge(lost, ref)["success"]
    head = est.copy()
    head[:, 2] = np.radians(20)                          # position right, heading 20 degrees off
    assert not b.judge(head, ref)["success"]


def test_degraded_map_disagrees_like_a_real_one():
    from localize.maps import office

    b = _bench()
    g = office(0.05)
    d = b.degrade_map(g, np.random.default_rng(0))
    grown = d.occupied & g.free
    assert grown.sum() > 0.05 * g.occupied.sum()          # thicker walls and added obstacles
    assert (g.occupied & ~d.occupied & ~d.unknown).sum() > 0   # some obstacles erased
    assert 0.02 < d.unknown.sum() / g.free.sum() < 0.08     # one region unknown (5% of the free area)


def test_benchmark_small_version(shared_data, capsys):
    """A small version of benchmarks/bench_global.py: one start, one seed, 120 scans of two logs."""
    carmen(shared_data, "intel")
    b = _bench()
    assert b.main(["--logs", "intel", "willow", "--starts", "1", "--seeds", "1", "--scans", "120",
                   "--workers", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| intel") or line.startswith("| willow")]
    assert len(rows) == 4                              # the runs' table, then what the state said scan by scan
    for r in rows[:2]:
        cells = [c.strip() for c in r.strip("|").split("|")]
        assert cells[1] == "1" and cells[2].split("/")[1].startswith("1")
    for r in rows[2:]:
        cells = [c.strip() for c in r.strip("|").split("|")]
        assert cells[1] == "120" and int(cells[2]) <= 120       # scans, of them localized
    assert "Calibration of `p_localized`" in out         # the default state is the probability's: its reliability
    assert "| p_localized | scans | mean p | share within 1 m | difference |" in out


def test_simulated_laser_reports_no_return_where_nothing_is_in_range():
    """bench_global's Willow laser: a beam with nothing within max_range reads max_range, not a hit near it."""
    from localize.maps import office
    from localize.sensors import BeamModel

    b = _bench()
    g = office()
    laser = BeamModel(g, 3.0, z_hit=0.8, z_short=0.1, z_max=0.05, z_rand=0.05, sigma_hit=0.1, method="exact")
    poses = g.sample_free(200, np.random.default_rng(1))
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    expected = laser.expected(poses, angles)
    far = expected >= laser.max_range
    assert 0.2 < far.mean() < 0.9                          # both kinds of beam occur
    plain = laser.sample(poses, angles, np.random.default_rng(2))
    z = b._NoReturn(laser).sample(poses, angles, np.random.default_rng(2))
    near_max = far & (plain > laser.max_range - 0.5) & (plain < laser.max_range)
    assert near_max.sum() > 100                            # the plain model draws end points in mid-air ...
    assert np.all(z[near_max] == laser.max_range)          # ... which the wrapped laser reports as no return
    same = ~far | (plain < laser.max_range - 5 * laser.sigma_hit)
    np.testing.assert_array_equal(z[same], plain[same])    # every other reading is drawn unchanged
