"""The smaller findings of issue 39 (item 5) that live in the readers and checks.

A laser mounting pose far off the robot (``--laser-pose 1e308 0 0``) or in
degrees is refused with a sentence instead of numpy overflow warnings; a
(3, 3) particle array whose third column is not headings gets a warning even
when its rows do not look transposed; an AMCL file whose laser_min_range is
not below laser_max_range names both.
"""

from __future__ import annotations

import io as stdio
import warnings

import numpy as np
import pytest

from localize import amcl, cli, io, maps, sim
from localize._checks import PoseShapeWarning, check_poses
from localize.io import FormatError


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("small")
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(4), n_steps=6, dt=0.5, speed=0.4,
                        sensor_offset=(0.25, 0.0, 0.0), max_range=12.0)
    return io.write_cmu_map(d / "office.dat", grid), sim.write_cmu_log(d / "office.log", run)


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no numpy RuntimeWarning may escape (others: the libraries)
        status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("pose, message", [
    (("1e308", 0, 0), "must place the laser within 100 m of the robot's centre; got (1e+308, 0, 0)"),
    ((0, "-250", 0), "must place the laser within 100 m"),
    ((0.2, 0, 90), "its yaw must be radians in [-2 pi, 2 pi]; got (0.2, 0, 90): degrees?"),
])
def test_a_laser_pose_off_the_robot_is_a_sentence_not_numpy_warnings(files, tmp_path, pose, message):
    m, lg = files
    status, _, err = run_cli("run", "--map", m, "--log", lg, "--particles", 100, "--laser-pose", *pose,
                             "--out", tmp_path / "o", "--quiet")
    assert status == 2 and "Warning" not in err and "Traceback" not in err
    assert err.startswith("localize: error: sensor_offset (the laser's mounting pose, --laser-pose)") and message in err
    assert not (tmp_path / "o").exists()


def test_a_reasonable_laser_pose_is_still_taken(files, tmp_path):
    m, lg = files
    status, _, err = run_cli("run", "--map", m, "--log", lg, "--particles", 100, "--scans", "0:3",
                             "--laser-pose", 0.25, 0, 0, "--out", tmp_path / "o", "--quiet")
    assert status == 0, err


def test_a_3_by_3_array_whose_third_column_is_not_headings_warns():
    p = np.array([[1.0, 2.0, 3.5], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])  # neither reading has headings
    with pytest.warns(PoseShapeWarning, match=r"third column \[3\.5, 6\.0, 9\.0\] does not look like headings .*"
                                              r"nor does its third row"):
        check_poses(p)


def test_a_3_by_3_array_of_three_particles_or_a_symmetric_one_is_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_poses(np.array([[1.0, 2.0, 0.1], [5.0, 6.0, -0.2], [9.0, 8.0, 0.3]]))
        check_poses(np.array([[1.0, 2.0, 7.0], [2.0, 5.0, 8.0], [7.0, 8.0, 9.0]]))  # the same both ways


def test_amcl_ranges_that_leave_no_valid_reading_are_named(tmp_path):
    p = tmp_path / "amcl.yaml"
    p.write_text("amcl:\n  ros__parameters:\n    laser_min_range: 5.0\n    laser_max_range: 4.0\n")
    with pytest.raises(FormatError, match=r"amcl\.yaml:3: laser_min_range \(5\) must be below laser_max_range \(4\)"):
        amcl.read_amcl_params(p)


# ------------------------------------------------------------------ the command line's own share of item 5
def test_a_max_range_below_the_min_range_names_both_options(files, tmp_path):
    status, _, err = run_cli("run", "--map", files[0], "--log", files[1], "--out", tmp_path / "o",
                             "--max-range", "1e-9", "--quiet")
    assert status == 2 and "--min-range" in err and "--max-range" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_a_one_cell_map_reports_no_convergence_while_never_localized(files, tmp_path):
    import json

    from PIL import Image

    Image.new("L", (1, 1), 254).save(tmp_path / "one.pgm")
    (tmp_path / "one.yaml").write_text("image: one.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n"
                                      "occupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\n")
    status, text, err = run_cli("run", "--map", tmp_path / "one.yaml", "--log", files[1], "--out", tmp_path / "o",
                                "--particles", "200")
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert status == 0 and "NOT localized" in text
    assert summary["state"]["first_localized_scan"] is None and summary["convergence_step"] is None


def test_ctrl_c_while_parsing_or_importing_gives_a_sentence_not_a_traceback(monkeypatch, capsys):
    import importlib.abc
    import sys

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    status, _, err = run_cli("run", "--help")
    assert status == 130 and err.strip() == "localize: interrupted; nothing written"

    class Interrupt(importlib.abc.MetaPathFinder):       # Ctrl-C while localize.cli loads its libraries
        def find_spec(self, name, path, target=None):
            if name == "localize.cli":
                raise KeyboardInterrupt
            return None

    monkeypatch.delitem(sys.modules, "localize.cli")
    monkeypatch.setattr(sys, "meta_path", [Interrupt(), *sys.meta_path])
    from localize.__main__ import main as console_main  # what python -m localize and the localize command run

    assert console_main() == 130
    assert capsys.readouterr().err.strip() == "localize: interrupted; nothing written"


def test_an_allocation_that_fails_anyway_is_a_sentence(files, tmp_path, monkeypatch):
    def no_memory(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(cli, "localize_log", no_memory)
    status, _, err = run_cli("run", "--map", files[0], "--log", files[1], "--out", tmp_path / "o", "--quiet")
    assert status == 2 and "out of memory" in err and "--particles" in err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
