"""``localize demo``: a first run without downloaded data (localize.demo and the CLI sub-command)."""

from __future__ import annotations

import csv
import io as stdio
import json

import numpy as np
import pytest

from localize import cli, io
from localize.demo import make_demo


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


def test_demo_data_is_deterministic_and_the_map_is_imperfect(tmp_path):
    a = make_demo(tmp_path / "a", np.random.default_rng(3), steps=40)
    make_demo(tmp_path / "b", np.random.default_rng(3), steps=40)
    for name in ("map.dat", "robot.log", "truth.tum"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    grid = io.read_map(a.map_path)
    log = io.read_log(a.log_path)
    assert len(log) == 40 and np.allclose(log.sensor_offset, [0.25, 0, 0], atol=1e-3)
    # the cupboard is in the map but not in the world
    x0, y0, x1, y1 = a.cupboard
    c = np.array([[(x0 + x1) / 2, (y0 + y1) / 2]])
    assert not grid.is_free(c)[0] and a.world.is_free(c)[0]
    # the truth file reads back as the simulated poses
    t, poses = io.read_tum(a.truth_path)
    assert np.allclose(t, a.times) and np.allclose(poses[:, :2], a.poses[:, :2], atol=1e-6)


def state_from_columns(rows, localized_at=0.95, lost_below=0.7):
    """The state as the docs derive it from ``trajectory.csv``'s ``p_localized`` and ``p_place``."""
    cur, out = "searching", []
    for r in rows:
        p, place = float(r["p_localized"]), float(r["p_place"])
        if p >= localized_at:
            cur = "localized"
        elif cur == "localized" and (p < lost_below or place < localized_at):
            cur = "lost"
        out.append(cur)
    return out


@pytest.mark.parametrize("seed", [0, 1, 8])
def test_demo_localizes_the_simulated_robot(tmp_path, seed):
    out = tmp_path / "demo"
    status, text, err = run_cli("demo", "--out", out, "--no-animate", "--seed", seed)
    assert status == 0, err
    for name in ("map.dat", "robot.log", "truth.tum", "trajectory.csv", "trajectory.tum", "summary.json"):
        assert (out / name).is_file(), name
    s = json.loads((out / "summary.json").read_text())
    d = s["demo"]
    # 150 scans, 'auto' particles (5,000 found the robot in only 5-6 of 10 seeds): found within 0.5 m early,
    # then tracked to about 0.2 m
    assert d["convergence_step_truth"] is not None and d["convergence_step_truth"] < 60
    assert d["median_error_after_convergence_m"] < 0.35
    assert "against the true poses" in text and "evo_ape tum" in text
    assert "localize run --map" in text  # the command to rerun or vary
    # the state is a function of the two probability columns, by the documented thresholds
    with open(out / "trajectory.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["state"] for r in rows] == state_from_columns(rows)
    if seed == 8:   # a seed where a look-alike turns the filter lost while p_localized is still above 0.7
        assert any(r["state"] == "lost" and float(r["p_localized"]) >= 0.7 for r in rows)


def test_demo_writes_an_animation(tmp_path):
    out = tmp_path / "anim"
    status, _, err = run_cli("demo", "--out", out, "--steps", 12, "--particles", 300, "--frames", 4, "--quiet")
    assert status == 0, err
    assert (out / "particles.gif").stat().st_size > 1000
    assert json.loads((out / "summary.json").read_text())["animation"][0] == "particles.gif"
