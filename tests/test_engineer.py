"""Issue 44, the engineer's run: report.png, pose covariance, a known start, the map check, --build-map's map,
the --help a newcomer reads, the hints when a run ends lost."""

from __future__ import annotations

import csv
import dataclasses
import io as stdio
import json

import numpy as np
import pytest

from localize import cli, io, maps, sim
from localize.demo import make_demo
from localize.io.ros import write_pgm
from localize.pipeline import check_map, localize_log, read_map_file
from localize.settings import RunSettings


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """A short simulated office log (60 scans), its map and true poses."""
    return make_demo(tmp_path_factory.mktemp("demo"), np.random.default_rng(0), steps=60)


@pytest.fixture(scope="module")
def demo_run(demo, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    status, stdout, err = run_cli("run", "--map", demo.map_path, "--log", demo.log_path, "--reference",
                                  demo.truth_path, "--particles", 4000, "--out", out)
    assert status == 0, err
    return out, stdout


# ---------------------------------------------------------------------------- report, covariance, final pose
def test_report_png_is_written_and_listed(demo_run):
    out, stdout = demo_run
    png = out / "report.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((out / "summary.json").read_text())
    assert "report.png" in summary["files"]
    assert summary["reference"]["scans_matched"] == 60 and summary["reference"]["median_error_m"] < 0.5


def test_report_trajectory_lies_on_free_cells_and_legend(demo):
    """What a check can see in the picture: the trajectory's points on the map's free cells, the legend's labels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from localize.plot.report import report_figure

    grid, log = io.read_map(demo.map_path), io.read_log(demo.log_path)
    res = localize_log(grid, log, RunSettings(particles=3000), rng=np.random.default_rng(0))
    fig = report_figure(grid, res.trace, demo.poses)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[0].startswith("final particles") and "reference" in labels and "start" in labels
    pts = np.vstack([c.get_offsets() for c in ax.collections if c.get_label().startswith("estimate")])
    assert len(pts) == len(log)
    loc = res.state == "localized"
    assert np.mean(grid.is_free(res.estimates[loc, :2])) > 0.95
    plt.close(fig)


def test_covariance_columns_symmetric_psd_and_match_the_particles(demo_run, demo):
    out, stdout = demo_run
    rows = list(csv.DictReader(open(out / "trajectory.csv")))
    names = list(cli.COV_COLUMNS)
    assert list(rows[0])[-6:] == names
    for r in rows:
        c = np.zeros((3, 3))
        for n, (i, j) in cli.COV_COLUMNS.items():
            c[i, j] = c[j, i] = float(r[n])
        assert np.linalg.eigvalsh(c).min() > -1e-9
    summary = json.loads((out / "summary.json").read_text())
    fp = summary["final_pose"]
    assert np.allclose(fp["covariance"], np.array(fp["covariance"]).T)
    assert "final pose: x" in stdout
    # the covariance matches the particles' (a localized run: one cluster; the last scan's kept cloud)
    grid, log = io.read_map(demo.map_path), io.read_log(demo.log_path)
    res = localize_log(grid, log, RunSettings(particles=3000), rng=np.random.default_rng(0), snapshot_every=1,
                       snapshot_particles=None)
    k = int(np.flatnonzero(res.state == "localized")[-1])
    p, w = res.snapshots[k]
    near = np.hypot(*(p[:, :2] - res.estimates[k, :2]).T) < 1.0
    w = w[near] / w[near].sum()
    d = p[near] - res.estimates[k]
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    emp = (d * w[:, None]).T @ d
    n_eff = 1.0 / np.sum(w ** 2)
    tol = 4 * np.sqrt(2.0 / n_eff)  # relative sampling error of a variance, 4 sigma
    diag_ratio = np.diag(res.covariances[k]) / np.diag(emp)
    assert np.all(np.abs(diag_ratio - 1) < tol), (diag_ratio, tol)


# ---------------------------------------------------------------------------- a known start
def _start(demo, dx):
    p = demo.poses[0].copy()
    p[0] += dx
    return tuple(p)


def test_correct_initial_pose_tracks_from_scan_0(demo):
    grid, log = io.read_map(demo.map_path), io.read_log(demo.log_path)
    res = localize_log(grid, log, RunSettings(particles=3000, initial_pose=_start(demo, 0.0)),
                       rng=np.random.default_rng(0))
    err = np.hypot(*(res.estimates[:, :2] - demo.poses[:, :2]).T)
    first = int(np.flatnonzero(res.state == "localized")[0])
    assert first <= 3 and err[0] < 0.5 and np.median(err) < 0.3


def test_wrong_initial_pose_is_not_a_confident_track_and_recovers(demo):
    """5 m off (in free space): no confident wrong track -- the state is not localized there (searching: the filter
    was never localized, so it cannot be 'lost' in StateRules' sense), the filter restarts global localization
    (--restart-after) and ends localized near the truth."""
    grid, log = io.read_map(demo.map_path), io.read_log(demo.log_path)
    start = _start(demo, -5.0)
    assert grid.is_free(np.array([start[:2]]))[0]
    res = localize_log(grid, log, RunSettings(particles=5000, initial_pose=start), rng=np.random.default_rng(0))
    err = np.hypot(*(res.estimates[:, :2] - demo.poses[:, :2]).T)
    assert err[0] > 4.0
    # no confident wrong track: while the estimate is metres off, the state is searching or lost, not localized
    # (at most a few scans localized before the scans' misfit turns it lost: StateRules.hold_lost)
    wrong = err > 1.0
    assert np.sum(wrong & (res.state == "localized")) <= 6
    assert set(res.state[wrong]) <= {"searching", "lost", "localized"} and wrong[:10].all()
    assert not (res.state[:10] == "localized").any()
    # the restart policy (--restart-after 5) draws a new cloud over the map, which finds the robot
    assert any("global localization again" in t for _, t in res.trace.events)
    assert res.state[-1] == "localized" and np.median(err[-10:]) < 0.5


def test_initial_pose_from_the_command_line_and_amcl(tmp_path, demo):
    s = cli._settings.parse_options(["--initial-pose", "1", "-2", "0.5", "--initial-std", "0.2", "0.2", "0.1"])
    assert s.initial_pose == (1.0, -2.0, 0.5) and s.initial_std == (0.2, 0.2, 0.1)
    amcl = tmp_path / "amcl.yaml"
    amcl.write_text("amcl:\n  ros__parameters:\n    max_particles: 3000\n    min_particles: 500\n"
                    f"    initial_pose_x: {demo.poses[0, 0]:.3f}\n    initial_pose_y: {demo.poses[0, 1]:.3f}\n"
                    f"    initial_pose_a: {demo.poses[0, 2]:.3f}\n    initial_cov_xx: 0.04\n")
    status, out, err = run_cli("run", "--map", demo.map_path, "--log", demo.log_path, "--amcl-params", amcl,
                               "--scans", "0:10", "--out", tmp_path / "o")
    assert status == 0, err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["settings"]["initial_pose"] == pytest.approx(demo.poses[0].round(3).tolist())
    assert summary["settings"]["initial_std"][0] == pytest.approx(0.2)


# ---------------------------------------------------------------------------- the map check
def _ros_map(path, img, free_thresh):
    write_pgm(path.with_suffix(".pgm"), img)
    path.write_text(f"image: {path.with_suffix('.pgm').name}\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\n"
                    f"negate: 0\noccupied_thresh: 0.65\nfree_thresh: {free_thresh}\n")
    return path


def _building_image():
    """A 10 m x 6 m room (walls, white floor) in a wide grey (205, map_saver's unknown) border."""
    img = np.full((200, 200), 205, dtype=np.uint8)
    img[70:130, 50:150] = 0
    img[71:129, 51:149] = 254
    return img


def test_map_warning_fires_when_unknown_reads_as_free(tmp_path, demo):
    path = _ros_map(tmp_path / "grey.yaml", _building_image(), 0.25)
    grid = read_map_file(path)
    c = check_map(grid, path)
    assert c.warnings and "free_thresh 0.25" in c.warnings[0] and "205" in c.warnings[0]
    assert c.robot_m2 == pytest.approx(58 * 98 * 0.01) and c.free_m2 > 5 * c.robot_m2
    status, out, err = run_cli("run", "--map", path, "--log", demo.log_path, "--scans", "0:3", "--quiet",
                               "--out", tmp_path / "o")
    assert status == 0 and "free_thresh 0.25" in err
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["particles"] == 20_000 and summary["map_check"]["warnings"]


def test_no_map_warning_on_normal_maps(tmp_path):
    path = _ros_map(tmp_path / "ok.yaml", _building_image(), 0.196)
    assert check_map(read_map_file(path), path).warnings == ()
    assert check_map(maps.office()).warnings == ()
    willow = "/work/shared/data/willow/willow-2010-02-18-0.10.yaml"
    from pathlib import Path

    if Path(willow).is_file():
        assert check_map(read_map_file(willow), Path(willow)).warnings == ()


# ---------------------------------------------------------------------------- --build-map saves its map
def test_build_map_round_trip(tmp_path):
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(8), n_steps=30, dt=0.5, angles=io.carmen_angles(181),
                        max_range=12.0, sensor="ideal")
    log = io.LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles,
                      max_range=run.max_range)
    path = io.write_carmen_log(tmp_path / "sim.log.gz", log)
    status, out, err = run_cli("run", "--log", path, "--build-map", "--resolution", 0.1, "--track",
                               "--particles", 300, "--quiet", "--out", tmp_path / "b")
    assert status == 0, err
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert {"map.yaml", "map.pgm"} <= set(summary["files"])
    from localize.mapping import map_from_log

    built = map_from_log(io.read_log(path), resolution=0.1)
    back = io.read_map(tmp_path / "b" / "map.yaml")
    assert back.shape == built.shape and np.allclose(back.origin, built.origin)
    assert np.array_equal(back.free, built.free) and np.array_equal(back.occupied, built.occupied)
    status, _, err = run_cli("run", "--map", tmp_path / "b" / "map.yaml", "--log", path, "--track", "--particles",
                             300, "--quiet", "--out", tmp_path / "c")
    assert status == 0, err


# ---------------------------------------------------------------------------- --reference errors
@pytest.mark.parametrize("text, message", [
    ("time,x,y\n0,1,2\n", "names no column theta"),
    ("0,1,2,zero\n", ":1: expected numbers"),
    ("100,1,2,0\n101,1,2,0\n", "match none of the log's scans"),
])
def test_bad_reference_files_are_clear_errors(tmp_path, demo, text, message):
    ref = tmp_path / "ref.csv"
    ref.write_text(text)
    status, _, err = run_cli("run", "--map", demo.map_path, "--log", demo.log_path, "--reference", ref,
                             "--scans", "0:3", "--particles", 200, "--out", tmp_path / "o")
    assert status == 2 and message in err and "Traceback" not in err


def test_map_warning_when_free_space_far_exceeds_what_the_scans_cover(demo):
    """The demo's office (204 m^2 free) against one scan of a laser that sees 1 m: the scans cover far less;
    against the whole demo log they do not."""
    grid, log = io.read_map(demo.map_path), io.read_log(demo.log_path)
    few = log.select(slice(0, 1))
    c = check_map(grid, None, log)
    assert c.scanned_m2 > 20 and not any("scans cover" in w for w in c.warnings)
    short = dataclasses.replace(few, ranges=np.minimum(few.ranges, 1.0))   # a laser that sees 1 m
    c = check_map(grid, None, short)
    assert c.scanned_m2 < 204 / 5 and any("times the" in w for w in c.warnings)


# ---------------------------------------------------------------------------- the demo's terminal
def test_demo_terminal_reads_for_a_first_time_user(tmp_path):
    import re

    status, text, err = run_cli("demo", "--out", tmp_path / "d", "--no-animate", "--seed", 0)
    assert status == 0, err
    lines = text.splitlines()
    assert sum("from scan" in line for line in lines) == 1                              # one convergence number
    # what "lost" means, beside it: the demo's own summary with a lost stretch (seed 0 is not lost at present)
    summary = json.loads((tmp_path / "d" / "summary.json").read_text())
    summary["state"]["lost_intervals"] = [[40, 45]]
    report = cli._report(summary, summary["scans"], [], smooth=False).splitlines()
    k = next(i for i, line in enumerate(report) if "lost at scans 40-45" in line)
    assert report[k + 1].strip().startswith("(lost: the filter had been localized")
    assert not any(line.strip().startswith("(lost:") for line in lines if "lost at scans" not in text)
    speed = re.search(r"([\d.]+)x real time", text).group(1)
    assert re.fullmatch(r"[1-9]\.\d|[1-9]\d?0*|0\.0*[1-9]\d?", speed), speed           # two significant figures
    assert re.search(r"median error \d\.\d\d m while localized", text)
    assert "final pose: x" in text


# ---------------------------------------------------------------------------- the result bag's covariance
def test_result_bag_amcl_pose_carries_the_covariance(tmp_path, demo):
    """/amcl_pose's 6x6 row-major covariance holds trajectory.csv's x, y, yaw terms at indices 0, 1, 5."""
    pytest.importorskip("rosbags")
    from rosbags.highlevel import AnyReader

    from localize.io import rosbag

    bag = rosbag.write_rosbag_log(tmp_path / "demo.bag", io.read_log(demo.log_path), storage="rosbag1")
    status, _, err = run_cli("run", "--map", demo.map_path, "--log", bag, "--particles", 2000, "--scans", "0:20",
                             "--quiet", "--out", tmp_path / "o")
    assert status == 0, err
    rows = list(csv.DictReader(open(tmp_path / "o" / "trajectory.csv")))
    with AnyReader([tmp_path / "o" / "localization.bag"]) as r:
        covs = [r.deserialize(raw, c.msgtype).pose.covariance.reshape(6, 6)
                for c, _, raw in r.messages() if c.topic == "/amcl_pose"]
    assert len(covs) == len(rows) == 20
    idx = [0, 1, 5]
    for row, c6 in zip(rows, covs):
        c = c6[np.ix_(idx, idx)]
        for n, (i, j) in cli.COV_COLUMNS.items():
            assert c[i, j] == pytest.approx(float(row[n]), rel=1e-5, abs=1e-12)
        assert np.allclose(c, c.T) and c6[2, 2] == 0 and c6[0, 0] > 0


def test_initial_pose_errors(demo):
    grid, log = io.read_map(demo.map_path), io.read_log(demo.log_path)
    with pytest.raises(ValueError, match="outside the map"):
        localize_log(grid, log, RunSettings(particles=100, initial_pose=(-50.0, 3.0, 0.0)),
                     rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="either --track"):
        localize_log(grid, log, RunSettings(particles=100, initial_pose=(5.0, 3.0, 0.0), track=True),
                     rng=np.random.default_rng(0))
