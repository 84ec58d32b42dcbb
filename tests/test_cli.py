"""Tests of the command line (localize.cli, ``python -m localize``) on simulated CMU-format data."""

from __future__ import annotations

import argparse
import csv
import io as stdio
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from localize import cli, io, maps, pipeline, settings, sim
from localize.geometry import angle_diff
from localize.motion import ReversibleOdometry


@pytest.fixture(scope="module")
def sim_files(tmp_path_factory):
    """A simulated robot in the office world, written as a CMU map and a CMU log."""
    d = tmp_path_factory.mktemp("cli")
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(4), n_steps=80, dt=0.5, speed=0.4,
                        sensor_offset=(0.25, 0.0, 0.0), max_range=12.0, n_clutter=3)
    return io.write_cmu_map(d / "office.dat", grid), sim.write_cmu_log(d / "office.log", run), run


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


def test_run_localizes_globally_and_writes_outputs(sim_files, tmp_path):
    map_path, log_path, run = sim_files
    status, out, err = run_cli("run", "--map", map_path, "--log", log_path, "--particles", 3000, "--seed", 2,
                               "--out", tmp_path / "o")
    assert status == 0, err
    assert err == ""  # not a terminal: no progress bar
    assert "80 scans, 3000 particles" in out and "trajectory.csv" in out
    rows = list(csv.DictReader(open(tmp_path / "o" / "trajectory.csv")))
    assert len(rows) == len(run) and list(rows[0])[:4] == ["time", "x", "y", "theta"]
    est = np.array([[float(r["x"]), float(r["y"]), float(r["theta"])] for r in rows])
    assert np.allclose([float(r["time"]) for r in rows], run.times, atol=1e-6)
    # global localization found the robot: the last 20 estimates are close to the true poses
    err_xy = np.hypot(*(est[-20:, :2] - run.poses[-20:, :2]).T)
    assert np.median(err_xy) < 0.3
    assert np.median(np.abs(angle_diff(est[-20:, 2], run.poses[-20:, 2]))) < np.radians(10)
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    for key in ("particles", "scans", "seconds_per_scan", "real_time_factor", "convergence_step", "settings"):
        assert key in s
    assert s["particles"] == 3000 and s["scans"] == 80 and s["real_time_factor"] > 0
    assert s["convergence_step"] is not None and s["convergence_step"] < 70
    assert s["settings"]["log_format"] == "cmu" and s["settings"]["seed"] == 2


def test_same_seed_same_trajectory(sim_files, tmp_path):
    map_path, log_path, _ = sim_files
    args = ["run", "--map", map_path, "--log", log_path, "--particles", 300, "--scans", "0:15", "--quiet"]
    assert run_cli(*args, "--seed", 5, "--out", tmp_path / "a")[0] == 0
    assert run_cli(*args, "--seed", 5, "--out", tmp_path / "b")[0] == 0
    assert run_cli(*args, "--seed", 6, "--out", tmp_path / "c")[0] == 0
    a, b, c = ((tmp_path / x / "trajectory.csv").read_text() for x in "abc")
    assert a == b and a != c and len(a.splitlines()) == 16


def test_tracking_with_reference_poses_and_build_map(tmp_path):
    """A CARMEN log with reference poses: --build-map, --track, error columns in the outputs."""
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(8), n_steps=40, dt=0.5, angles=io.carmen_angles(181),
                        max_range=12.0, sensor="ideal")
    log = io.LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles,
                      max_range=run.max_range)
    path = io.write_carmen_log(tmp_path / "sim.log.gz", log)  # both pose triples equal: reference poses
    status, out, err = run_cli("run", "--log", path, "--build-map", "--resolution", 0.1, "--track",
                               "--particles", 500, "--out", tmp_path / "t")
    assert status == 0, err
    rows = list(csv.DictReader(open(tmp_path / "t" / "trajectory.csv")))
    assert {"ref_x", "ref_y", "ref_theta", "error"} <= set(rows[0])
    assert np.median([float(r["error"]) for r in rows]) < 0.1
    s = json.loads((tmp_path / "t" / "summary.json").read_text())
    assert s["convergence_step_reference"] == 0 and s["median_error_m"] < 0.1
    assert "median error" in out
    # the map sub-command writes a map_server map that the run command reads back
    status, out, err = run_cli("map", "--log", path, "--out", tmp_path / "m" / "office.yaml", "--resolution", 0.1)
    assert status == 0, err
    g = io.read_map(tmp_path / "m" / "office.yaml")
    assert g.resolution == pytest.approx(0.1) and g.occupied.sum() > 200


def test_animation_gif(sim_files, tmp_path):
    map_path, log_path, _ = sim_files
    status, _, err = run_cli("run", "--map", map_path, "--log", log_path, "--particles", 200, "--scans", "0:6",
                             "--animate", "--frames", 3, "--quiet", "--out", tmp_path / "g")
    assert status == 0, err
    gif = tmp_path / "g" / "particles.gif"
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames >= 3
    s = json.loads((tmp_path / "g" / "summary.json").read_text())
    assert "particles.gif" in s["animation"]


def test_progress_bar_only_on_a_terminal():
    class Tty(stdio.StringIO):
        def isatty(self):
            return True

    t = Tty()
    p = cli.Progress(4, stream=t)
    for k in range(1, 5):
        p.update_to(k)
    p.close()
    assert "100%" in t.getvalue() and "4/4 scans" in t.getvalue() and t.getvalue().endswith("\n")
    piped = stdio.StringIO()
    p = cli.Progress(4, stream=piped)
    p.update_to(4)
    p.close()
    assert piped.getvalue() == ""


@pytest.mark.parametrize(
    "argv, message",
    [
        (["run", "--log", "LOG"], "give --map FILE, or --build-map"),
        (["run", "--log", "LOG", "--map", "MAP", "--build-map"], "either --map or --build-map"),
        (["run", "--log", "LOG", "--build-map"], "needs reference poses"),
        (["run", "--log", "LOG", "--map", "LOG"], "cannot tell the map format"),
        (["run", "--log", "MAP", "--map", "MAP"], "cannot tell the log format"),
        (["run", "--log", "LOG", "--map", "MAP", "--map-format", "ros"], "expected 'key: value'"),
        (["run", "--log", "LOG", "--map", "MAP", "--not-free-is-occupied"], "ROS map_server maps only"),
        (["run", "--log", "nothing.log", "--map", "MAP"], "nothing.log: no such file"),
        (["map", "--log", "LOG", "--out", "x.yaml"], "no reference poses"),
    ],
)
def test_errors_are_reported_without_traceback(sim_files, argv, message):
    map_path, log_path, _ = sim_files
    argv = [str(log_path) if a == "LOG" else str(map_path) if a == "MAP" else a for a in argv]
    status, out, err = run_cli(*argv)
    assert status == 2
    assert err.startswith("localize: error: ") and message in err and "Traceback" not in err


def test_bad_file_content_names_file_and_line(sim_files, tmp_path):
    map_path, log_path, _ = sim_files
    lines = log_path.read_text().splitlines()
    lines[3] = lines[3][: len(lines[3]) // 2]  # a truncated record
    bad = tmp_path / "bad.log"
    bad.write_text("\n".join(lines) + "\n")
    status, _, err = run_cli("run", "--map", map_path, "--log", bad)
    assert status == 2 and f"{bad}:4: " in err and "188 fields" in err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["run", "--log", "x", "--map", "y", "--particles", "0"], "expected a whole number >= 1"),
        (["run", "--log", "x", "--map", "y", "--particles", "many"], "expected a whole number"),
        (["run", "--log", "x", "--map", "y", "--sensor", "sonar"], "invalid choice"),
        (["run", "--log", "x", "--map", "y", "--scans", "a:b"], "START:STOP"),
        (["run", "--map", "y"], "--log"),
        ([], "required"),
    ],
)
def test_bad_arguments(argv, message, capsys):
    status = cli.main(argv)
    assert status == 2
    assert message in capsys.readouterr().err


def test_map_help_documents_every_option(capsys):
    assert cli.main(["map", "--help"]) == 0
    text = capsys.readouterr().out
    parser = cli.build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    for a in action.choices["map"]._actions:
        if a.dest == "help":
            continue
        assert a.help and a.option_strings[0] in text
    assert "example" in text.lower()


def test_run_help_reads_in_a_minute(capsys):
    """``localize run --help``: under 120 lines, grouped, every option with its default, three examples."""
    assert cli.main(["run", "--help"]) == 0
    text = capsys.readouterr().out
    assert len(text.splitlines()) < 120
    for group in ("input:", "sensor:", "filter:", "recovery:", "output:", "examples:"):
        assert "\n" + group in text, group
    parser = cli.build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    shown = [a for a in action.choices["run"]._actions if a.dest != "help" and a.help != argparse.SUPPRESS]
    assert len(shown) > 40
    for a in shown:
        assert "(default" in a.help or "(required)" in a.help, f"{a.option_strings[0]}: no default shown"
        assert len(a.help) < 80 and "Example" not in a.help, a.option_strings[0]  # one line; rationale elsewhere
    examples = text.split("examples:")[1].split("\n\n")[0]
    assert sum(line.strip().startswith("localize run ") for line in examples.splitlines()) == 3


def test_advice_when_a_run_ends_lost_or_searching(sim_files, tmp_path):
    """A run that never localizes (3 particles) says which setting to try, and why."""
    map_path, log_path, _ = sim_files
    status, out, err = run_cli("run", "--map", map_path, "--log", log_path, "--particles", 3, "--kld", 0,
                               "--scans", "0:8", "--out", tmp_path / "a")
    assert status == 0, err
    assert "NOT localized" in out and "try --particles 6: never localized with 3 particles" in out
    status, out, err = run_cli("run", "--map", map_path, "--log", log_path, "--particles", 3, "--kld", 0,
                               "--max-range", 0.5, "--scans", "0:8", "--out", tmp_path / "b")
    assert "try --max-range / --min-range" in out


def test_python_dash_m_entry_point(tmp_path):
    r = subprocess.run([sys.executable, "-m", "localize", "--help"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0 and "usage: localize" in r.stdout and "run" in r.stdout


def test_converged_at():
    assert pipeline.converged_at([1.0, 0.1, 0.1, 0.1], hold=2) == 1
    assert pipeline.converged_at([0.1, 1.0, 0.1], hold=2) == 2  # the end of the log counts
    assert pipeline.converged_at([1.0, 1.0]) is None
    with pytest.raises(ValueError, match="hold"):
        pipeline.converged_at([0.1], hold=0)


def test_localize_log_validates(sim_files):
    map_path, log_path, _ = sim_files
    grid, log = io.read_map(map_path), io.read_log(log_path)
    with pytest.raises(TypeError, match="rng"):
        pipeline.localize_log(grid, log, rng=None)
    with pytest.raises(ValueError, match="init"):
        pipeline.localize_log(grid, log, rng=np.random.default_rng(0), init="somewhere")
    with pytest.raises(ValueError, match="reference poses"):
        pipeline.localize_log(grid, log, rng=np.random.default_rng(0), init="reference")
    with pytest.raises(ValueError, match="sensor must be"):
        pipeline.make_sensor("sonar", grid, 10.0, np.zeros(3))
    with pytest.raises(ValueError, match="alphas"):
        ReversibleOdometry((0.1, 0.1))


def test_beam_sensor_runs(sim_files, tmp_path):
    map_path, log_path, _ = sim_files
    status, _, err = run_cli("run", "--map", map_path, "--log", log_path, "--sensor", "beam", "--particles", 200,
                             "--scans", "0:5", "--quiet", "--out", tmp_path / "b")
    assert status == 0, err
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["settings"]["sensor"] == "beam"


def test_reversible_odometry_matches_plain_model_going_forward():
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    from localize.motion import sample_odometry

    u = ([0.0, 0.0, 0.1], [0.5, 0.1, 0.3])
    p = np.zeros((1000, 3))
    a = ReversibleOdometry((0.05, 0.01, 0.02, 0.05))(p, u, rng_a)
    b = sample_odometry(p, u, (0.05, 0.01, 0.02, 0.05), rng_b, min_trans=1e-3)
    assert np.array_equal(a, b)
    # backwards: mean displacement is the odometry's (within 5 standard errors), headings as reported
    back = ([0.0, 0.0, 0.0], [-0.3, 0.0, 0.2])
    q = ReversibleOdometry((0.05, 0.01, 0.02, 0.05))(np.zeros((20000, 3)), back, np.random.default_rng(1))
    se = q[:, 0].std() / np.sqrt(len(q))
    assert abs(q[:, 0].mean() + 0.3) < 5 * se + 1e-3 and abs(np.median(q[:, 2]) - 0.2) < 0.01


def test_dash_m_module_does_not_run_on_import():
    import importlib

    mod = importlib.import_module("localize.__main__")
    assert hasattr(mod, "main")
    assert Path(mod.__file__).name == "__main__.py"


def test_animation_time_counts_in_the_total_and_titles_state_the_filters_particles(sim_files, tmp_path):
    map_path, log_path, _ = sim_files
    status, _, err = run_cli("run", "--map", map_path, "--log", log_path, "--particles", 1500, "--scans", "0:4",
                             "--animate", "--frames", 2, "--quiet", "--out", tmp_path / "t")
    assert status == 0, err
    s = json.loads((tmp_path / "t" / "summary.json").read_text())
    assert s["seconds_animation"] > 0
    assert s["seconds_total"] >= s["seconds_animation"] + s["seconds_reading_files"]
    from localize.plot.mcl import _frame_title

    assert _frame_title(2, 1000, 1500) == "step 2: 1500 particles (1000 drawn)"   # the snapshots hold 1000


def test_map_summary_counts_unknown_cells_apart():
    g = maps.office(0.1)
    data = np.array(g.data)
    data[:10, :] = np.nan                                    # 10 rows of unknown cells
    summary = pipeline.map_summary(localize_grid(data, g.resolution))
    assert "2000 unknown" in summary and f"{int(np.sum(data > 0.5))} occupied" in summary


def localize_grid(data, resolution):
    from localize import OccupancyGrid

    return OccupancyGrid(data, resolution)


# ---------------------------------------------------------------------------- the honest state
def _as_log(run, **changes):
    d = dict(times=run.times, odometry=run.odometry, ranges=run.ranges, angles=run.angles,
             max_range=run.max_range, poses=run.poses, sensor_offset=run.sensor_offset)
    d.update(changes)
    return io.LaserLog(**d)


@pytest.fixture(scope="module")
def rooms_run():
    """An asymmetric world of random rooms (the office world is symmetric under a half turn)."""
    grid = maps.random_rooms((150, 100), 0.1, np.random.default_rng(3))
    run = sim.range_run(grid, np.random.default_rng(2), n_steps=150, dt=0.5, speed=0.4, max_range=12.0, n_clutter=3)
    return grid, run


STATE_KW = dict(n_particles=3000, temper=0.3, sensor_params={"sigma_hit": 0.2}, min_range=0.05)


def _err(res, run):
    return np.hypot(*(res.estimates[:, :2] - run.poses[:, :2]).T)


def test_state_localizes_on_a_good_run(rooms_run):
    grid, run = rooms_run
    res = pipeline.localize_log(grid, _as_log(run), rng=np.random.default_rng(0), **STATE_KW)
    e = _err(res, run)
    k = res.trace.first_localized()
    assert k is not None and res.state[-1] == "localized"
    assert np.median(e[res.state == "localized"]) < 0.3
    assert set(np.unique(res.state)) <= {"searching", "localized", "lost"}
    assert np.all(res.state[:k] == "searching")


@pytest.mark.parametrize("dead", [0.0, 12.0, 0.03])          # all zero, all "no return", all below min_range
def test_dead_laser_is_reported_not_localized(rooms_run, dead, tmp_path):
    grid, run = rooms_run
    log = _as_log(run, ranges=np.full_like(run.ranges, dead))
    res = pipeline.localize_log(grid, log, rng=np.random.default_rng(0), **STATE_KW)
    assert res.trace.first_localized() is None and np.all(res.state == "searching")
    assert np.all(res.trace.n_valid == 0)
    summary = cli.summarize(res, log, 3000, log.poses, {})
    assert summary["state"]["scans_without_valid_readings"] == len(log)
    assert summary["state"]["final_state"] == "searching"
    line = cli.headline(summary)
    assert line.startswith("NOT localized") and f"{len(log)} of {len(log)} scans had no valid reading" in line


def test_corrupt_odometry_record_is_rejected_and_reported(rooms_run):
    grid, run = rooms_run
    odo = np.array(run.odometry)
    odo[70] = [1e15, 1e15, 0.3]                        # one corrupt record (the 1e15)
    res = pipeline.localize_log(grid, _as_log(run, odometry=odo), rng=np.random.default_rng(0), **STATE_KW)
    ev = [k for k, text in res.trace.events if "odometry" in text and "impossible" in text]
    assert ev == [70, 71]                              # into and out of the bad record
    assert np.all(np.abs(res.estimates) < 100)         # never thrown to 1e13 m
    e = _err(res, run)
    assert res.state[-1] == "localized" and e[-1] < 0.5


def test_kidnapping_turns_the_state_lost(rooms_run):
    grid, _ = rooms_run
    run = sim.range_run(grid, np.random.default_rng(2), n_steps=150, dt=0.5, speed=0.4, max_range=12.0,
                        n_clutter=3, kidnap_at=[90])
    res = pipeline.localize_log(grid, _as_log(run), rng=np.random.default_rng(0), **STATE_KW)
    assert res.state[89] == "localized"
    lost = [a for a, b in res.trace.lost_intervals() if a >= 90]
    assert lost and lost[0] <= 100                     # noticed within ten scans
    e = _err(res, run)
    # while it says "localized" after the kidnapping it is right (or it has not noticed yet)
    late = (res.state == "localized") & (np.arange(len(e)) > lost[0])
    assert np.all(e[late] < 1.0)


def test_never_converging_robot_stays_searching():
    """A robot in a long, featureless corridor: its scans cannot tell where along it it is."""
    from localize.grid import OccupancyGrid

    d = np.zeros((30, 600))                    # 60 m x 3 m, walls all round, ends beyond the laser's 12 m
    d[:3] = d[-3:] = 1
    d[:, :3] = d[:, -3:] = 1
    g = OccupancyGrid(d, 0.1)
    run = sim.range_run(g, np.random.default_rng(0), n_steps=120, dt=0.5, speed=0.4, max_range=12.0, n_clutter=0,
                        waypoints=[[22.0, 1.5], [38.0, 1.5]], start=[22.0, 1.5, 0.0])
    for seed in range(3):
        res = pipeline.localize_log(g, _as_log(run), rng=np.random.default_rng(seed), **STATE_KW)
        assert res.trace.first_localized() is None, seed
        assert cli.headline(cli.summarize(res, _as_log(run), 3000, None, {})).startswith("NOT localized")


def test_state_column_and_summary_section(sim_files, tmp_path):
    m, lg, _ = sim_files
    out = tmp_path / "o"
    status, text, _ = run_cli("run", "--map", m, "--log", lg, "--particles", "2000", "--out", out)
    assert status == 0
    rows = list(csv.DictReader(open(out / "trajectory.csv")))
    assert {r["state"] for r in rows} <= {"searching", "localized", "lost"}
    s = json.loads((out / "summary.json").read_text())
    assert {"first_localized_scan", "lost_intervals", "final_state"} <= set(s["state"])
    assert ("localized from scan" in text) or ("NOT localized" in text)
    # the probability state's two columns: p_localized = sqrt(b m) never exceeds p_place = sqrt(m) (both rounded
    # down, so not even by a rounding step)
    p = np.array([float(r["p_localized"]) for r in rows])
    place = np.array([float(r["p_place"]) for r in rows])
    assert np.all((0 <= p) & (p <= place) & (place <= 1)) and p.max() >= 0.95
    # summary.json's final values are the last row's, exactly (both rounded down to four decimals), and the
    # terminal's headline rounds that down again: it never reads 0.95 for a value below it
    assert (s["state"]["final_p_localized"], s["state"]["final_p_place"]) == (p[-1], place[-1])
    two = rows[-1]["p_localized"][:4]          # "0.9999" -> "0.99": the written value cut, not floor(v * 100)
    assert f"p_localized {two} at the end" in text or f"p_localized {two}, p_place" in text
    # the threshold state has neither
    status, _, _ = run_cli("run", "--map", m, "--log", lg, "--particles", "2000", "--state", "thresholds",
                           "--out", tmp_path / "t")
    assert status == 0
    rows = list(csv.DictReader(open(tmp_path / "t" / "trajectory.csv")))
    assert all(r["p_localized"] == r["p_place"] == "" for r in rows)
    assert not {"final_p_localized", "final_p_place"} & set(json.loads((tmp_path / "t" / "summary.json").read_text())["state"])


def test_particles_auto_is_one_per_kld_bin_of_the_free_space_within_bounds():
    from localize.grid import OccupancyGrid
    from localize.kld import pose_bins

    office = maps.office()
    area = office.free.sum() * office.resolution ** 2
    assert pose_bins(office) == round(area / (0.5 * 0.5) * 36)          # 36 heading bins of 10 degrees
    assert pipeline.auto_particles(office) == pose_bins(office)
    lo, hi = pipeline.AUTO_PARTICLES
    small = OccupancyGrid(np.zeros((40, 40)), 0.1)                      # 16 m^2: below the lower bound
    big = OccupancyGrid(np.zeros((1000, 1000)), 0.1)                    # 10,000 m^2: above the upper bound
    assert (pipeline.auto_particles(small), pipeline.auto_particles(big)) == (lo, hi)
    # the CLI's default is "auto"; the pipeline resolves it with the map, and says so without one
    args = cli.build_parser().parse_args(["run", "--log", "x.log", "--map", "m.yaml"])
    assert args.particles == "auto"
    s = cli.run_kwargs(args, grid=office)["settings"]
    assert s.particles == pipeline.kld_sampling(s, s.particles).n_max == pose_bins(office)
    with pytest.raises(ValueError, match="sizes the cloud from the map: pass grid"):
        pipeline.resolve_particles(settings.from_namespace(args).particles, None)
    assert settings.from_namespace(cli.build_parser().parse_args(["run", "--log", "x", "--map", "m", "--particles",
                                                                  "700"])).particles == 700


@pytest.mark.parametrize("value", ["0", "lots", "-5", "2.5"])
def test_particles_option_names_what_it_accepts(value, capsys):
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["run", "--log", "x", "--map", "m", "--particles", value])
    assert "expected a whole number >= 1 or 'auto'" in capsys.readouterr().err
