"""The command line under faults (issue 16): nothing lost, nothing mixed up.

Interrupted runs, two runs on one folder, stale files of an earlier run, an
unwritable or impossible ``--out``, runs too big for the memory, options out of
range, warnings from the readers, and the help text. Small simulated CMU files,
few particles and scans: every run here takes well under a second.
"""

from __future__ import annotations

import io as stdio
import json
import re
import subprocess
import sys
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from localize import _output, _resources, cli, io, maps, sim
from localize.grid import OccupancyGrid

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("faults")
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(4), n_steps=12, dt=0.5, speed=0.4,
                        sensor_offset=(0.25, 0.0, 0.0), max_range=12.0)
    return io.write_cmu_map(d / "office.dat", grid), sim.write_cmu_log(d / "office.log", run)


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


def small(files, out, *extra):
    m, lg = files
    return run_cli("run", "--map", m, "--log", lg, "--particles", 100, "--scans", "0:4", "--out", out, *extra)


def listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ------------------------------------------------------------------ item 2: atomic outputs
def test_interrupted_animation_leaves_the_earlier_run_untouched(files, tmp_path, monkeypatch):
    out = tmp_path / "o"
    assert small(files, out, "--seed", 1)[0] == 0
    before = {n: (out / n).read_bytes() for n in listing(out)}
    assert set(before) == {"trajectory.csv", "trajectory.tum", "report.png", "summary.json"}

    def interrupted(folder, *args, **kwargs):
        (Path(folder) / "particles.gif").write_bytes(b"GIF89a half a frame")
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "write_animation", interrupted)
    status, _, err = small(files, out, "--seed", 2, "--animate", "--frames", 2)
    assert status == 130
    assert "interrupted" in err and f"nothing written to {out}" in err and "earlier run" in err
    # the folder holds the earlier run, whole: no new trajectory, no partial GIF, no staging folder
    assert listing(out) == sorted(before)
    assert all((out / n).read_bytes() == b for n, b in before.items())


def test_a_ctrl_c_that_python_swallows_still_stops_the_results(files, tmp_path, monkeypatch):
    """matplotlib's writers run weakref callbacks; a KeyboardInterrupt raised in one is only printed."""
    import signal

    out = tmp_path / "o"
    assert small(files, out, "--seed", 1)[0] == 0
    before = {n: (out / n).read_bytes() for n in listing(out)}

    class Finalizer:
        def __del__(self):
            signal.raise_signal(signal.SIGINT)  # the handler's KeyboardInterrupt is "ignored" in __del__

    def animation(folder, *args, **kwargs):
        Finalizer()  # dropped at once
        (Path(folder) / "particles.gif").write_bytes(b"GIF89a")
        return [Path(folder) / "particles.gif"]

    monkeypatch.setattr(cli, "write_animation", animation)
    hook = sys.unraisablehook
    status, _, err = small(files, out, "--seed", 2, "--animate")
    assert status == 130 and "nothing written" in err
    assert listing(out) == sorted(before) and all((out / n).read_bytes() == b for n, b in before.items())
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler was restored
    assert sys.unraisablehook is hook


def test_a_failing_run_removes_the_folder_it_created(files, tmp_path, monkeypatch):
    out = tmp_path / "new" / "deeper"

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(cli, "write_summary", broken)
    status, _, err = small(files, out)
    assert status == 2 and "disk full" in err and "nothing written" in err
    assert not (tmp_path / "new").exists()


def test_results_of_an_earlier_run_that_this_run_does_not_produce_are_removed(files, tmp_path):
    out = tmp_path / "o"
    status, _, err = small(files, out, "--animate", "--frames", 2, "--quiet")
    assert status == 0, err
    assert "particles.gif" in listing(out)
    status, text, err = small(files, out)
    assert status == 0, err
    assert listing(out) == ["report.png", "summary.json", "trajectory.csv", "trajectory.tum"]
    assert f"removed particles.gif of an earlier run from {out}" in text
    assert "animation" not in json.loads((out / "summary.json").read_text())
    assert json.loads((out / "summary.json").read_text())["files"] == ["trajectory.csv", "trajectory.tum", "report.png",
                                                                          "summary.json"]


def test_a_second_run_on_a_folder_being_written_is_refused(files, tmp_path):
    out = tmp_path / "o"
    with _output.RunOutput(out) as first:
        first.open()
        status, _, err = small(files, out)
        assert status == 2
        assert f"--out {out}: another run (pid " in err and "is writing this folder" in err
    assert small(files, out)[0] == 0  # free again once the first run is done
    assert listing(out) == ["report.png", "summary.json", "trajectory.csv", "trajectory.tum"]  # no lock or staging left


def test_the_lock_holds_across_processes_and_dies_with_its_holder(files, tmp_path):
    out = tmp_path / "o"
    code = ("import sys; from localize._output import RunOutput; o = RunOutput(sys.argv[1]).open(); "
            "print('locked', flush=True); sys.stdin.read()")
    holder = subprocess.Popen([sys.executable, "-c", code, str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True, cwd=ROOT)
    try:
        assert holder.stdout.readline().strip() == "locked"
        status, _, err = small(files, out)
        assert status == 2 and f"pid {holder.pid}" in err
    finally:
        holder.kill()  # killed, not closed: the kernel releases the flock
        holder.wait()
    status, _, err = small(files, out)
    assert status == 0, err
    assert not list(out.glob(".localize-partial-*"))


def test_commit_writes_the_summary_last(tmp_path):
    """summary.json marks a complete run: it is moved into place after every other file."""
    order = []
    real = _output.os.replace

    def spy(src, dst):
        order.append(Path(dst).name)
        real(src, dst)

    with _output.RunOutput(tmp_path / "o") as o:
        o.open()
        for name in ("summary.json", "trajectory.csv", "particles.gif"):
            o.path(name).write_text(name)
        _output.os.replace = spy
        try:
            written, removed = o.commit()
        finally:
            _output.os.replace = real
    assert order[-1] == "summary.json" and sorted(order) == ["particles.gif", "summary.json", "trajectory.csv"]
    assert removed == [] and [p.name for p in written] == order


# ------------------------------------------------------------------ item 3: --out checked first
def test_an_impossible_out_is_reported_before_the_filter_runs(files, tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")

    def no_filter(*args, **kwargs):  # the run must stop before filtering
        raise AssertionError("the filter ran before --out was checked")

    monkeypatch.setattr(cli, "localize_log", no_filter)
    for out, message in ((blocker / "out", "cannot create the output folder"),
                         (blocker, "exists and is not a folder")):
        status, _, err = small(files, out)
        assert status == 2, err
        assert err.startswith(f"localize: error: --out {out}: {message}"), err


def test_bad_input_leaves_no_output_folder_behind(files, tmp_path):
    out = tmp_path / "new" / "o"
    status, _, err = run_cli("run", "--map", files[0], "--log", tmp_path / "missing.log", "--out", out)
    assert status == 2 and err == f"localize: error: {tmp_path / 'missing.log'}: no such file\n"
    assert not (tmp_path / "new").exists()


@pytest.mark.skipif(not hasattr(sys, "getuid") or sys.getuid() == 0, reason="root may write anywhere")
def test_an_unwritable_out_is_reported_before_the_filter_runs(files, tmp_path, monkeypatch):
    locked = tmp_path / "ro"
    locked.mkdir()
    locked.chmod(0o500)
    monkeypatch.setattr(cli, "localize_log", lambda *a, **k: pytest.fail("the filter ran"))
    try:
        status, _, err = small(files, locked)
    finally:
        locked.chmod(0o700)
    assert status == 2 and f"--out {locked}: cannot write" in err


# ------------------------------------------------------------------ item 4: memory
def test_too_many_particles_are_refused_before_allocating(files, tmp_path, monkeypatch):
    monkeypatch.setattr(_resources, "available_memory", lambda: 1024**3)
    status, _, err = small(files, tmp_path / "o", "--particles", 100_000_000)
    assert status == 2 and "Traceback" not in err
    assert re.search(r"--particles 100000000 needs about [\d.]+ GB of memory .* only 1\.0 GB is available", err), err
    assert not (tmp_path / "o").exists()


def test_a_run_no_machine_can_hold_is_refused_without_a_memory_error(files, tmp_path):
    status, _, err = small(files, tmp_path / "o", "--particles", 10**13)   # about 15 PB
    assert status == 2 and "needs about" in err and "PB" in err


@pytest.mark.parametrize("sensor", ["likelihood", "beam"])
def test_memory_estimate_is_above_the_measured_peak(files, sensor):
    """The estimate is honest: above what a run allocates (tracemalloc), and not absurdly above it."""
    m, lg = files
    log = io.read_log(lg).select(slice(0, 4))
    cli.localize_log(io.read_map(m), log, n_particles=50, rng=np.random.default_rng(0), sensor=sensor)  # imports
    grid = io.read_map(m)  # a fresh map: its sensor tables are built inside the measurement
    n, beams = 4000, 30
    tracemalloc.start()
    try:
        cli.localize_log(grid, log, n_particles=n, rng=np.random.default_rng(0), sensor=sensor, beams=beams,
                         min_motion=(0.0, 0.0))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    est = _resources.estimate_run_bytes(n, beams, sensor, n_cells=grid.data.size)
    assert peak <= est <= 6 * peak, (peak, est)


# ------------------------------------------------------------------ item 7: messages
def test_a_map_without_free_cells_is_named(files, tmp_path):
    walls = io.write_cmu_map(tmp_path / "walls.dat", OccupancyGrid(np.ones((40, 60)), 0.1))
    status, _, err = run_cli("run", "--map", walls, "--log", files[1], "--out", tmp_path / "o")
    assert status == 2 and f"localize: error: {walls}: the map has no free cell" in err


@pytest.mark.parametrize("option, value, message", [
    ("--seed", "-1", "argument --seed: expected a whole number >= 0"),
    ("--seed", "x", "argument --seed: expected a whole number"),
    ("--restart-after", "-2", "argument --restart-after: expected a whole number >= 0"),
    ("--temper", "2", "argument --temper: expected a number in (0, 1]"),
    ("--temper", "0", "argument --temper: expected a number in (0, 1]"),
    ("--injection", "1", "argument --injection: expected a fraction in [0, 1)"),
])
def test_options_are_checked_when_parsed_naming_the_option(option, value, message, capsys):
    # the files do not exist: a check made only after loading them would report them instead
    status = cli.main(["run", "--map", "missing.dat", "--log", "missing.log", option, value])
    assert status == 2
    assert message in capsys.readouterr().err


# ------------------------------------------------------------------ item 8: readers' warnings
def test_time_stamps_going_backwards_are_warned_about_with_their_line(files, tmp_path):
    lines = files[1].read_text().splitlines()
    scans = [k for k, t in enumerate(lines) if t.startswith("L ")]
    k = scans[2]
    fields = lines[k].split()
    fields[-1] = "0.0001"  # earlier than scan 1
    lines[k] = " ".join(fields)
    bad = tmp_path / "back.log"
    bad.write_text("\n".join(lines) + "\n")
    status, _, err = run_cli("run", "--map", files[0], "--log", bad, "--particles", 100, "--scans", "0:4",
                             "--out", tmp_path / "o")
    assert status == 0, err
    assert f"localize: warning: {bad}:{k + 1}: time stamp 0.0001 is earlier than the previous scan's" in err


def test_reader_warnings_are_printed_in_one_style_not_as_python_warnings(tmp_path):
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(8), n_steps=6, dt=0.5, angles=io.carmen_angles(181),
                        max_range=12.0, sensor="ideal")
    log = io.LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles,
                      max_range=run.max_range)
    path = io.write_carmen_log(tmp_path / "sim.log", log)
    text = path.read_text().splitlines()
    text.insert(4, "FOOBAR 1 2 3")
    path.write_text("\n".join(text) + "\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        status, _, err = run_cli("run", "--log", path, "--build-map", "--resolution", 0.1, "--particles", 100,
                                 "--out", tmp_path / "o")
    assert status == 0, err
    assert f"localize: warning: {path}: skipped 1 FOOBAR records (unknown record type) (first at line 5)" in err
    assert not [w for w in caught if issubclass(w.category, io.ParseWarning)]


# ------------------------------------------------------------------ item 10: polish
def test_version(capsys):
    from localize import __version__

    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"localize {__version__}"


@pytest.mark.parametrize("sub", ["run", "map"])
def test_help_description_is_wrapped(sub, capsys):
    assert cli.main([sub, "--help"]) == 0
    text = capsys.readouterr().out
    paragraph = text.split("\n\n")[1]  # usage, then the description
    assert len(paragraph.splitlines()) > 1 and max(len(x) for x in paragraph.splitlines()) <= 79


def test_help_examples_are_the_readme_commands(capsys):
    readme = (ROOT / "README.md").read_text()
    commands = [line.split("#")[0].strip() for line in readme.splitlines() if line.startswith("localize run --")]
    commands = [c for c in commands if c != "localize run --help"]
    assert len(commands) >= 2
    assert cli.main(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for c in commands:
        assert " ".join(c.split()) in text, c


# ------------------------------------------------------------------ the map sub-command
@pytest.fixture(scope="module")
def corrected_log(tmp_path_factory):
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(8), n_steps=6, dt=0.5, angles=io.carmen_angles(181),
                        max_range=12.0, sensor="ideal")
    log = io.LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles,
                      max_range=run.max_range)
    return io.write_carmen_log(tmp_path_factory.mktemp("map") / "sim.log", log)


def test_map_writes_yaml_and_pgm_together_or_not_at_all(corrected_log, tmp_path, monkeypatch):
    from localize import mapping

    target = tmp_path / "maps" / "office.yaml"
    assert run_cli("map", "--log", corrected_log, "--out", target, "--resolution", 0.2, "--quiet")[0] == 0
    assert listing(target.parent) == ["office.pgm", "office.yaml"]
    old = {p: p.read_bytes() for p in target.parent.iterdir()}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(mapping, "map_from_log", interrupted)
    status, _, err = run_cli("map", "--log", corrected_log, "--out", target, "--resolution", 0.1)
    assert status == 130 and "nothing written" in err
    assert {p: p.read_bytes() for p in target.parent.iterdir()} == old
    status, _, err = run_cli("map", "--log", corrected_log, "--out", tmp_path / "new" / "office.yaml")
    assert status == 130 and not (tmp_path / "new").exists()


def test_map_out_must_be_a_yaml_name_checked_before_mapping(corrected_log, tmp_path):
    status, _, err = run_cli("map", "--log", corrected_log, "--out", tmp_path / "office.pgm")
    assert status == 2 and "must end in .yaml" in err and not list(tmp_path.iterdir())


# ------------------------------------------------------------------ property: any option value
NUMERIC_OPTIONS = ["--particles", "--seed", "--beams", "--max-range", "--sigma-hit", "--temper", "--injection",
                   "--resolution", "--frames", "--scans"]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(option=st.sampled_from(NUMERIC_OPTIONS),
       value=st.text(max_size=12) | st.floats().map(repr) | st.integers(-10**20, 10**20).map(str))
def test_any_option_value_is_accepted_or_rejected_naming_the_option(tmp_path, capsys, option, value):
    missing = tmp_path / "missing.log"
    status = cli.main(["run", "--map", str(missing), "--log", str(missing), "--out", str(tmp_path / "o"),
                       option, value])
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err
    assert f"argument {option}" in err or f"{missing}: no such file" in err, err
    assert not (tmp_path / "o").exists()


def test_a_ctrl_c_raised_in_a_finalizer_without_a_signal_still_stops_the_results(files, tmp_path, monkeypatch):
    """A KeyboardInterrupt that Python can only report as 'Exception ignored' (raised while a generator is
    closed or an object finalized) is a Ctrl-C all the same: the run is not published."""
    out = tmp_path / "o"
    assert small(files, out, "--seed", 1)[0] == 0
    before = {n: (out / n).read_bytes() for n in listing(out)}

    class Finalizer:
        def __del__(self):
            raise KeyboardInterrupt  # swallowed by Python, seen by the unraisable hook

    real = cli.write_summary

    def summary_then_finalizer(path, summary):
        Finalizer()
        return real(path, summary)

    monkeypatch.setattr(cli, "write_summary", summary_then_finalizer)
    status, _, err = small(files, out, "--seed", 2)
    assert status == 130 and "nothing written" in err
    assert listing(out) == sorted(before) and all((out / n).read_bytes() == b for n, b in before.items())


def test_a_log_that_understates_its_maximum_range_is_run_with_the_range_its_readings_show(tmp_path):
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(8), n_steps=8, dt=0.5, angles=io.carmen_angles(181),
                        max_range=12.0)
    log = io.LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles, max_range=12.0,
                      poses=run.poses)
    path = io.write_carmen_log(tmp_path / "sim.log", log)
    text = path.read_text()
    assert "PARAM robot_front_laser_max 12 " in text
    path.write_text(text.replace("PARAM robot_front_laser_max 12 ", "PARAM robot_front_laser_max 2.5 "))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        status, _, err = run_cli("run", "--log", path, "--build-map", "--resolution", 0.1, "--particles", 200,
                                 "--out", tmp_path / "o")
    assert status == 0, err
    assert not [w for w in caught if "maximum range" in str(w.message)]   # said once, in the command line's style
    said = [line for line in err.splitlines() if "maximum range" in line]
    assert len(said) == 1 and said[0].startswith(f"localize: warning: {path}: the log states a maximum range of "
                                                 "2.5 m, but ")
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["max_range"]["stated_m"] == 2.5
    assert summary["max_range"]["used_m"] == 12.0          # the laser's own no-return value, its real reach
