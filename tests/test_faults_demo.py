"""``localize demo`` and the output folder under faults (issue 39, finding 1).

The demo takes the folder's lock first and stages its simulated map, log and
truth with the run's results: an interrupted, refused or failing demo leaves
``--out`` byte for byte as it was. A full disk or a read-only folder is a
sentence naming ``--out``; no lock file is left behind. The property tests
interrupt a run at any function call of the package and check that the folder
holds the earlier run or the new one, whole.
"""

from __future__ import annotations

import errno
import io as stdio
import json
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import localize
from localize import _output, cli, demo, reliability

PACKAGE = str(Path(localize.__file__).parent)
SMALL = ("--particles", 100, "--steps", 10, "--no-animate", "--quiet")


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every entry of the folder (hidden ones too) with its bytes."""
    return {p.name: (p.read_bytes() if p.is_file() else b"<dir>") for p in sorted(folder.iterdir())}


@pytest.fixture()
def seed1(tmp_path):
    out = tmp_path / "d"
    status, _, err = run_cli("demo", "--out", out, "--seed", 1, *SMALL)
    assert status == 0, err
    before = snapshot(out)
    assert set(before) == {"map.dat", "robot.log", "truth.tum", "trajectory.csv", "trajectory.tum", "report.png",
                           "summary.json"}
    return out, before


def test_the_demo_files_are_listed_in_the_summary_with_their_final_paths(seed1):
    out, _ = seed1
    s = json.loads((out / "summary.json").read_text())
    assert s["files"] == ["map.dat", "robot.log", "truth.tum", "trajectory.csv", "trajectory.tum", "report.png",
                          "summary.json"]
    assert s["settings"]["map"] == str(out / "map.dat") and s["settings"]["log"] == str(out / "robot.log")
    assert s["demo"]["truth"] == "truth.tum" and s["demo"]["final_error_m"] >= 0


def test_an_interrupted_demo_leaves_the_earlier_demo_byte_for_byte(seed1, monkeypatch):
    out, before = seed1

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "localize_log", interrupted)  # after the simulated files were written
    status, _, err = run_cli("demo", "--out", out, "--seed", 2, *SMALL)
    assert status == 130 and f"nothing written to {out}" in err
    assert snapshot(out) == before  # truth.tum and map.dat still of seed 1


def test_a_demo_refused_by_the_lock_of_a_run_in_progress_leaves_the_folder_as_it_was(seed1):
    out, before = seed1
    with _output.RunOutput(out) as first:
        first.open()
        status, _, err = run_cli("demo", "--out", out, "--seed", 2, *SMALL)
        assert status == 2 and "is writing this folder" in err and "Traceback" not in err
    assert snapshot(out) == before


def test_a_demo_interrupted_while_its_summary_is_rewritten_leaves_no_empty_summary(seed1, monkeypatch):
    out, before = seed1
    real = cli.write_summary
    calls = []

    def second_write_breaks(path, summary):
        calls.append(path)
        if len(calls) == 2:  # the demo's rewrite with its score
            Path(path).write_text("")
            raise KeyboardInterrupt
        return real(path, summary)

    monkeypatch.setattr(cli, "write_summary", second_write_breaks)
    status, _, err = run_cli("demo", "--out", out, "--seed", 2, *SMALL)
    assert status == 130 and len(calls) == 2
    assert snapshot(out) == before


@pytest.mark.parametrize("code, words", [(errno.ENOSPC, "the disk is full"),
                                         (errno.EROFS, "the file system is read-only")])
def test_a_full_disk_while_writing_the_map_is_a_sentence_and_leaves_no_partial_map(seed1, monkeypatch, code, words):
    out, before = seed1
    real = demo.write_cmu_map

    def half_then_full(path, grid):
        Path(path).write_bytes(real(path, grid).read_bytes()[:100])
        raise OSError(code, "simulated", str(path))

    monkeypatch.setattr(demo, "write_cmu_map", half_then_full)
    status, _, err = run_cli("demo", "--out", out, "--seed", 2, *SMALL)
    assert status == 2 and "[Errno" not in err and "Traceback" not in err
    assert err.startswith(f"localize: error: --out {out}: cannot write the results ({words}: "), err
    assert f"nothing written to {out}" in err
    assert snapshot(out) == before


def test_a_full_disk_at_lock_time_leaves_no_stale_lock(tmp_path, monkeypatch):
    out = tmp_path / "o"
    out.mkdir()
    real = Path.write_text

    def full(self, *args, **kwargs):
        if self.name == _output._HOLDER:
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full)
    status, _, err = run_cli("demo", "--out", out, "--seed", 2, *SMALL)
    assert status == 2 and "[Errno" not in err
    assert f"--out {out}: cannot write into the output folder (the disk is full: " in err
    assert snapshot(out) == {}  # no .localize.lock, no staging folder


@pytest.mark.skipif(not hasattr(sys, "getuid") or sys.getuid() == 0, reason="root may write anywhere")
def test_a_read_only_folder_is_named(seed1):  # pragma: no cover - CI runs as root
    out, before = seed1
    out.chmod(0o500)
    try:
        status, _, err = run_cli("demo", "--out", out, "--seed", 2, *SMALL)
    finally:
        out.chmod(0o700)
    assert status == 2 and f"--out {out}: cannot write" in err and snapshot(out) == before


# ------------------------------------------------------------------ interrupts at any point (hypothesis)
class InterruptAt:
    """A trace function that raises KeyboardInterrupt at the n-th call of a function of the package.

    Counted inside the command (``_cmd_demo``; an interrupt while ``main`` parses the arguments is another
    matter, reported separately), and not while :meth:`RunOutput.commit` moves files or :meth:`RunOutput.close`
    releases the lock: there SIGINT is blocked (a real Ctrl-C waits).
    """

    def __init__(self, n: int) -> None:
        self.n, self.calls, self.fired = n, 0, False

    def __call__(self, frame, event, arg):
        if event != "call" or not frame.f_code.co_filename.startswith(PACKAGE) or self.fired:
            return None
        f, inside = frame, False
        while f is not None:
            if f.f_code.co_name in ("commit", "close") and f.f_code.co_filename == _output.__file__:
                return None
            inside = inside or (f.f_code.co_name == "_cmd_demo" and f.f_code.co_filename == cli.__file__)
            f = f.f_back
        if not inside:
            return None
        self.calls += 1
        if self.calls == self.n:
            self.fired = True
            raise KeyboardInterrupt
        return None


def interrupted_run(argv, n):
    reliability._CALIBRATIONS.clear()      # every run calibrates its state afresh: the same calls each time
    trace = InterruptAt(n)
    sys.settrace(trace)
    try:
        status, _, err = run_cli(*argv)
    finally:
        sys.settrace(None)
    return status, err, trace


def _complete(folder: Path) -> bool:
    """The folder holds one whole run: its summary lists files that are all there, and nothing else of a run."""
    s = json.loads((folder / "summary.json").read_text())
    return set(s["files"]) == {n for n in snapshot(folder)}


@pytest.fixture(scope="module")
def demo_calls(tmp_path_factory):
    """How many calls of the package's functions the small demo the tests interrupt makes (the range to interrupt
    in)."""
    calls = []
    for _ in range(2):    # the first run in the process also fills the package's caches: the second counts
        out = tmp_path_factory.mktemp("count") / "d"
        status, _, trace = interrupted_run(("demo", "--out", out, "--seed", 2, *SMALL), 0)
        assert status == 0
        calls.append(trace.calls)
    assert min(calls) > 1000  # the simulation, the filter and the writers: many points to stop at
    return min(calls)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fraction=st.floats(0, 1))
def test_a_demo_interrupted_at_any_call_leaves_one_whole_demo(tmp_path_factory, demo_calls, fraction):
    out = tmp_path_factory.mktemp("any") / "d"
    assert run_cli("demo", "--out", out, "--seed", 1, *SMALL)[0] == 0
    before = snapshot(out)
    n = 1 + int(fraction * (demo_calls - 1))
    status, err, trace = interrupted_run(("demo", "--out", out, "--seed", 2, *SMALL), n)
    assert trace.fired
    assert status == 130 and "interrupted" in err, err
    after = snapshot(out)
    if after != before:  # interrupted after the commit (printing): the seed-2 demo, whole
        assert "nothing written" not in err
        assert _complete(out) and json.loads(after["summary.json"])["settings"]["seed"] == 2
    # else interrupted before the commit: byte for byte the seed-1 demo
    assert not [n for n in after if n.startswith(".")]  # no lock, no staging folder


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fraction=st.floats(0, 1), earlier=st.booleans())
def test_a_new_demo_folder_interrupted_at_any_call_is_removed_or_whole(tmp_path_factory, demo_calls, fraction,
                                                                        earlier):
    base = tmp_path_factory.mktemp("new")
    out = base / "new" / "d"
    if earlier:
        out.mkdir(parents=True)
        (out / "notes.txt").write_text("the user's own file")
    n = 1 + int(fraction * (demo_calls - 1))
    status, err, trace = interrupted_run(("demo", "--out", out, "--seed", 2, *SMALL), n)
    assert trace.fired and status == 130
    if (out / "summary.json").exists():  # interrupted after the commit (printing): the demo, whole
        files = set(json.loads((out / "summary.json").read_text())["files"])
        assert set(snapshot(out)) == files | ({"notes.txt"} if earlier else set()) and "nothing written" not in err
        assert not earlier or (out / "notes.txt").read_text() == "the user's own file"
    elif earlier:
        assert snapshot(out) == {"notes.txt": b"the user's own file"}
    else:
        assert not (base / "new").exists()  # the folders made for the run are gone


# ------------------------------------------------------------------ the lock file removed while held
def test_a_lock_on_a_file_its_holder_removed_is_detected(tmp_path):
    from filelock import FileLock

    lock = FileLock(tmp_path / _output.LOCK_NAME, timeout=0)
    lock.acquire()
    try:
        assert _output._names_the_locked_file(lock)
        (tmp_path / _output.LOCK_NAME).unlink()  # what a finishing holder does while a second run opens the file
        assert not _output._names_the_locked_file(lock)
    finally:
        lock.release()


def test_a_stale_lock_is_given_back_and_the_new_file_taken(tmp_path, monkeypatch):
    answers = iter([False, True])
    monkeypatch.setattr(_output, "_names_the_locked_file", lambda lock: next(answers))
    out = tmp_path / "o"
    with _output.RunOutput(out) as o:
        o.open()
        assert (out / _output.LOCK_NAME).exists() and o._lock is not None and o._lock.is_locked
        o.path("summary.json").write_text("{}")
        o.commit()
    assert snapshot(out) == {"summary.json": b"{}"}


# ------------------------------------------------------------------ any demo (hypothesis)
@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), steps=st.integers(2, 12))
def test_any_demo_writes_one_whole_run_whose_score_is_its_files(tmp_path_factory, seed, steps):
    import numpy as np

    from localize import io

    out = tmp_path_factory.mktemp("anydemo") / "d"
    status, _, err = run_cli("demo", "--out", out, "--seed", seed, "--steps", steps, "--particles", 100,
                             "--no-animate", "--quiet")
    assert status == 0, err
    assert _complete(out)
    s = json.loads((out / "summary.json").read_text())
    t_est, est = io.read_tum(out / "trajectory.tum")
    t_true, truth = io.read_tum(out / "truth.tum")
    assert len(est) == len(truth) == steps and np.allclose(t_est, t_true)
    final = float(np.hypot(*(est[-1, :2] - truth[-1, :2])))
    assert abs(s["demo"]["final_error_m"] - final) <= 1e-3  # rounded to mm, from the files as written
    assert s["settings"]["seed"] == seed
