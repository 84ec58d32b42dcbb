"""Tests of localize.io: CMU 16-831 maps and logs, CARMEN logs, ROS map_server maps.

Every fixture is written here by hand (never copied from ../shared/data), small
enough to check by eye. Each kind of bad input is tested: it must either be
rejected with ``file:line: what was expected`` or skipped with a counted warning.
"""

from __future__ import annotations

import gzip
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from localize import io
from localize.geometry import compose
from localize.grid import OccupancyGrid
from localize.io import FormatError, LaserLog, ParseWarning


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def raises_at(path: Path, line: int | None, match: str):
    """pytest.raises for a FormatError located at ``path:line``."""
    where = re.escape(str(path) + (f":{line}" if line is not None else "")) + ": "
    return pytest.raises(FormatError, match=where + ".*" + match)


# ============================================================================ CMU map
CMU_MAP = """robot_specifications->global_mapsize_x  40
robot_specifications->global_mapsize_y  30
robot_specifications->resolution 10
robot_specifications->autoshifted_x 0
robot_specifications->autoshifted_y 0

global_map[0]: 3 4
0 0 0
1 0.9 -1
1 1 0.25
1 1 1
"""
# 4 text lines = x = 0..3; 3 values per line = y = 0..2.


def test_cmu_map_orientation_and_values(tmp_path):
    g = io.read_cmu_map(write(tmp_path, "m.dat", CMU_MAP))
    assert g.shape == (3, 4) and g.resolution == pytest.approx(0.1)
    assert np.allclose(g.origin, 0.0)
    # text line x = 0 is all walls (P(free) = 0): the left column of the map, every y
    assert np.all(g.data[:, 0] == 1.0)
    # x = 1, y = 1 has P(free) 0.9 -> occupancy 0.1 ; x = 1, y = 2 unknown
    assert g.data[1, 1] == pytest.approx(0.1)
    assert np.isnan(g.data[2, 1])
    # x = 2, y = 2: P(free) 0.25 -> occupancy 0.75, the top row (largest y)
    assert g.data[2, 2] == pytest.approx(0.75)
    # world point (0.05, 0.25) = x cell 0, y cell 2 is a wall; (0.35, 0.15) = x 3, y 1 is free
    assert not g.is_free([[0.05, 0.25]])[0] and g.is_free([[0.35, 0.15]])[0]
    # the trap: reading the file as P(occupied) would make the walls free
    assert g.free.sum() == 7 and g.occupied.sum() == 4 and g.unknown.sum() == 1


def test_cmu_map_roundtrip_and_gzip(tmp_path, rng):
    d = rng.uniform(0, 1, size=(7, 5)).round(3)
    d[2, 3] = np.nan
    g = OccupancyGrid(d, 0.1)
    p = io.write_cmu_map(tmp_path / "w.dat", g)
    back = io.read_cmu_map(p)
    assert np.allclose(back.data, g.data, equal_nan=True, atol=1e-6) and back.shape == (7, 5)
    gz = tmp_path / "w.dat.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    assert np.allclose(io.read_cmu_map(gz).data, g.data, equal_nan=True, atol=1e-6)
    with pytest.raises(ValueError, match="origin"):
        io.write_cmu_map(tmp_path / "x.dat", OccupancyGrid(d, 0.1, origin=(1.0, 0.0)))
    with pytest.raises(ValueError, match="whole cm"):
        io.write_cmu_map(tmp_path / "x.dat", OccupancyGrid(d, 0.125))
    with pytest.raises(TypeError, match="OccupancyGrid"):
        io.write_cmu_map(tmp_path / "x.dat", d)


@pytest.mark.parametrize(
    "edit, line, match",
    [
        (lambda s: s.replace("global_mapsize_x  40", "global_mapsize_x  50"), 1, "means 5 cells along x"),
        (lambda s: s.replace("1 0.9 -1\n", "1 0.9\n"), 9, "expected 3 values"),
        (lambda s: s.replace("1 1 0.25\n", "1 1 zero\n"), 10, "'zero', expected a number"),
        (lambda s: s.replace("1 1 0.25\n", "1 1 nan\n"), 10, "expected a finite number"),
        (lambda s: s.replace("1 1 0.25\n", "1 1 1.5\n"), 10, "expected a probability of free space"),
        # only -1 means unknown: other values below 0 are errors, not silently unknown cells (issue 16)
        (lambda s: s.replace("1 1 0.25\n", "1 1 -0.5\n"), 10, "value 3 is -0.5, expected a probability"),
        (lambda s: s.replace("1 1 0.25\n", "-7 1 0.25\n"), 10, "value 1 is -7, expected a probability"),
        (lambda s: s + "1 1 1\n", 12, "extra data"),
        (lambda s: s.replace("1 1 1\n", ""), None, "declares 4 lines .* ends after 3"),
        (lambda s: s.replace("global_map[0]: 3 4", "global_map[0]: 3"), 7, "two integers"),
        (lambda s: s.replace("robot_specifications->resolution 10", "robot_specifications->resolution ten"), 3,
         "must be a number"),
        (lambda s: s.replace("global_map[0]: 3 4\n", ""), 7, "expected a 'robot_specifications"),
        (lambda s: "\n".join(s.splitlines()[:5]) + "\n", None, "no 'global_map"),
    ],
)
def test_cmu_map_bad_input(tmp_path, edit, line, match):
    p = write(tmp_path, "bad.dat", edit(CMU_MAP))
    with raises_at(p, line, match):
        io.read_cmu_map(p)


def test_cmu_map_empty_and_missing(tmp_path):
    p = write(tmp_path, "empty.dat", "")
    with raises_at(p, None, "empty"):
        io.read_cmu_map(p)
    with raises_at(tmp_path / "nope.dat", None, "no such file"):
        io.read_cmu_map(tmp_path / "nope.dat")


def test_cmu_map_autoshift_warns(tmp_path):
    p = write(tmp_path, "s.dat", CMU_MAP.replace("autoshifted_x 0", "autoshifted_x 5"))
    with pytest.warns(ParseWarning, match="autoshifted_x"):
        io.read_cmu_map(p)


# ============================================================================ CMU log
def l_record(robot_cm, laser_cm, ranges_cm, ts):
    head = " ".join(f"{v:g}" for v in (*robot_cm, *laser_cm))
    return f"L {head} " + " ".join(f"{r:g}" for r in ranges_cm) + f" {ts}"


def cmu_log_text():
    r1 = [150.0] * 180
    r1[0] = 100.0     # beam 1: the robot's right
    r1[90] = 300.0    # beam 91: straight ahead
    r1[179] = 8183.0  # no return
    # robot at (100, 200) cm facing +y (theta = pi/2); the laser 25 cm ahead is at (100, 225)
    th = np.pi / 2
    lines = [
        "O 100 200 1.5707963 0.000",
        l_record((100, 200, th), (100, 225, th), r1, 0.010),
        "O 110 200 1.5707963 0.100",
        l_record((110, 200, th), (110, 225, th), [8000.0] * 180, 0.110),
    ]
    return "\n".join(lines) + "\n"


def test_cmu_log_units_angles_offset(tmp_path):
    log = io.read_cmu_log(write(tmp_path, "r.log", cmu_log_text()))
    assert len(log) == 2 and log.n_beams == 180 and log.format == "cmu"
    assert np.allclose(log.odometry[0], [1.0, 2.0, np.pi / 2])
    assert np.allclose(log.sensor_offset, [0.25, 0.0, 0.0], atol=1e-6)
    assert np.allclose(log.times, [0.01, 0.11])
    assert log.odom_poses.shape == (2, 3) and np.allclose(log.odom_poses[1], [1.1, 2.0, np.pi / 2])
    assert np.degrees(log.angles[0]) == pytest.approx(-90) and np.degrees(log.angles[-1]) == pytest.approx(89)
    assert log.ranges[0, 0] == pytest.approx(1.0) and log.ranges[0, 90] == pytest.approx(3.0)
    # 8000 cm and above is "no return"; 7999 would not be
    assert log.no_return[0].tolist() == [False] * 179 + [True] and log.no_return[1].all()
    # beam 1 points to the robot's right: robot faces +y, so its right is +x
    laser = log.laser_poses(log.odometry)[0]
    end = laser[:2] + log.ranges[0, 0] * np.array([np.cos(laser[2] + log.angles[0]), np.sin(laser[2] + log.angles[0])])
    assert np.allclose(laser, [1.0, 2.25, np.pi / 2], atol=1e-6)
    assert np.allclose(end, [2.0, 2.25], atol=1e-6)
    assert log.motions().round(6).tolist() == [[0.0, -0.1, 0.0]]  # moved 10 cm along +x = to its right


def test_cmu_log_given_offset(tmp_path):
    log = io.read_cmu_log(write(tmp_path, "r.log", cmu_log_text()), sensor_offset=(0.2, 0.0, 0.0))
    assert np.allclose(log.sensor_offset, [0.2, 0, 0])
    assert log.meta["sensor_offset_source"] == "given"


def test_cmu_log_roundtrip(tmp_path, rng):
    k = 4
    odo = np.column_stack([rng.uniform(-5, 5, k), rng.uniform(-5, 5, k), rng.uniform(-3, 3, k)])
    z = rng.uniform(0.2, 30, size=(k, 180)).round(2)
    z[0, :10] = 80.0
    log = LaserLog(times=np.arange(k) * 0.2, odometry=odo, ranges=z, angles=io.CMU_ANGLES, max_range=80.0,
                   sensor_offset=io.CMU_SENSOR_OFFSET, odom_times=[0.05], odom_poses=[[1.0, 2.0, 0.5]])
    back = io.read_cmu_log(io.write_cmu_log(tmp_path / "rt.log", log))
    assert np.allclose(back.odometry, odo, atol=1e-4)
    assert np.allclose(back.ranges[~log.no_return], z[~log.no_return], atol=0.005)
    assert back.no_return[0, :10].all() and back.no_return.sum() == 10
    assert np.allclose(back.sensor_offset, [0.25, 0, 0], atol=1e-4)
    assert np.allclose(back.odom_poses, [[1.0, 2.0, 0.5]], atol=1e-4)
    with pytest.raises(ValueError, match="180 beams"):
        io.write_cmu_log(tmp_path / "x.log", log.select_beams(step=2))


def test_cmu_log_reads_what_the_simulator_writes(tmp_path):
    sim = pytest.importorskip("localize.sim")
    from localize.maps import office

    run = sim.range_run(office(), np.random.default_rng(3), n_steps=6, sensor_offset=(0.25, 0, 0), sensor="ideal")
    log = io.read_log(sim.write_cmu_log(tmp_path / "sim.log", run))
    assert log.format == "cmu" and len(log) == len(run)
    assert np.allclose(log.odometry, run.odometry, atol=1e-4)
    assert np.allclose(log.sensor_offset, [0.25, 0, 0], atol=1e-4)
    hit = run.ranges < run.max_range
    assert np.allclose(log.ranges[hit], run.ranges[hit], atol=0.006)
    assert log.no_return[~hit].all()


@pytest.mark.parametrize(
    "bad_line, match",
    [
        ("O 100 200 0.5", "5 fields"),
        ("O 100 200 x 0.1", "field 3 is 'x'"),
        ("O 100 nan 0.5 0.1", "expected a finite number"),
        ("L 1 2 3 4 5 6 " + " ".join(["100"] * 100) + " 0.2", "188 fields"),
        ("L 1 2 3 4 5 6 " + " ".join(["100"] * 179) + " -5 0.2", "r180 is -5"),
        ("L 1 2 3 4 5 6 " + " ".join(["100"] * 179) + " inf 0.2", "finite"),
    ],
)
def test_cmu_log_bad_records(tmp_path, bad_line, match):
    text = cmu_log_text().splitlines()
    text.insert(2, bad_line)
    p = write(tmp_path, "bad.log", "\n".join(text) + "\n")
    with raises_at(p, 3, match):
        io.read_cmu_log(p)
    # or skipped, counted, and announced
    with pytest.warns(ParseWarning, match=r"skipped 1 malformed records \(first at line 3"):
        log = io.read_cmu_log(p, on_error="skip")
    assert len(log) == 2 and log.skipped == {"malformed records": 1}


def test_cmu_log_unknown_type_empty_and_no_scans(tmp_path):
    p = write(tmp_path, "u.log", cmu_log_text() + "X 1 2 3\n")
    with raises_at(p, 5, "unknown record type 'X'"):
        io.read_cmu_log(p, on_error="skip")  # never skipped: the format has only O and L
    p = write(tmp_path, "e.log", "")
    with raises_at(p, None, "empty"):
        io.read_cmu_log(p)
    p = write(tmp_path, "o.log", "O 1 2 3 4\n# a comment\n\n")
    with raises_at(p, None, "no laser records"):
        io.read_cmu_log(p)
    with pytest.raises(ValueError, match="on_error"):
        io.read_cmu_log(p, on_error="ignore")


def test_truncated_gzip_is_reported(tmp_path):
    data = gzip.compress((cmu_log_text() * 50).encode())
    p = tmp_path / "cut.log.gz"
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match="damaged or truncated"):
        io.read_cmu_log(p)


@pytest.mark.parametrize("reader", [io.read_cmu_log, io.read_log, io.detect_log_format, io.read_cmu_map])
def test_corrupted_gzip_bytes_are_reported(tmp_path, reader):
    """Flipped deflate bytes mid-stream (not a truncation) used to end in a raw zlib.error (issue 16)."""
    text = (cmu_log_text() * 40) if reader is not io.read_cmu_map else CMU_MAP + "\n" * 3000
    data = gzip.compress(text.encode())
    kinds = set()
    for pos in range(12, len(data) - 8, max(1, (len(data) - 20) // 60)):
        b = bytearray(data)
        b[pos] ^= 0x5A
        p = tmp_path / "flip.gz"
        p.write_bytes(bytes(b))
        try:
            reader(p)
        except FormatError as e:
            assert e.path == str(p) and (e.line is None or e.line >= 1)
            kinds.add("damaged" if "damaged" in str(e) else "other")
    assert "damaged" in kinds  # the corruption was found, and reported as a FormatError


# ============================================================================ CARMEN
def flaser(n, ranges, pose, odom, ts):
    r = " ".join(f"{v:g}" for v in ranges)
    p = " ".join(f"{v:g}" for v in (*pose, *odom))
    return f"FLASER {n} {r} {p} {ts} host {ts}"


def carmen_text():
    return "\n".join([
        "# message formats defined: PARAM SYNC ODOM FLASER RLASER",
        "PARAM robot_front_laser_max 81.9 nohost 0",
        "PARAM robot_frontlaser_offset 0.0 nohost 0",
        "ODOM 0 0 0 0 0 0 0.0 host 0.0",
        flaser(4, [1, 2, 3, 81.9], (0, 0, 0), (0, 0, 0), 0.1),
        "NEFF 12.5",
        "RAWLASER1 0 -1.57 3.14 0.01 81.9 0.01 0 2 1 1 0 0.2 host 0.2",
        "ODOM 0.5 0 0.1 0 0 0 0.2 host 0.2",
        "TRUEPOS 1 2 3 4 5 6 0.25 host 0.25",
        "FOOBAR something new",
        flaser(4, [1.5, 2, 3, 4], (0.5, 0, 0.1), (0.5, 0, 0.1), 0.3),
        "",
    ])


def test_carmen_basic(tmp_path):
    p = write(tmp_path, "c.log", carmen_text())
    with pytest.warns(ParseWarning) as rec:
        log = io.read_carmen_log(p)
    msg = str(rec[0].message)
    assert "1 RAWLASER1 records (not used) (first at line 7)" in msg
    assert "1 TRUEPOS records (not used)" in msg and "1 FOOBAR records (unknown record type) (first at line 10)" in msg
    assert log.skipped == {"RAWLASER1 records (not used)": 1, "TRUEPOS records (not used)": 1,
                           "FOOBAR records (unknown record type)": 1}
    assert len(log) == 2 and log.n_beams == 4 and log.max_range == 81.9
    assert log.meta["max_range_source"] == "PARAM robot_front_laser_max"
    assert log.no_return.tolist() == [[False, False, False, True], [False] * 4]
    assert log.params["robot_frontlaser_offset"] == "0.0"
    assert np.allclose(log.odometry, [[0, 0, 0], [0.5, 0, 0.1]])
    assert log.poses is not None and np.allclose(log.poses, log.odometry)  # both triples agree
    assert np.allclose(log.meta["neff"], [12.5, np.nan], equal_nan=True)
    assert np.allclose(log.times, [0.1, 0.3]) and len(log.odom_times) == 2


@pytest.mark.parametrize("n, step, last", [(180, 1.0, 89.0), (181, 1.0, 90.0), (360, 0.5, 89.5), (361, 0.5, 90.0)])
def test_carmen_angles(n, step, last):
    a = np.degrees(io.carmen_angles(n))
    assert a[0] == pytest.approx(-90) and a[-1] == pytest.approx(last) and np.allclose(np.diff(a), step)


def test_carmen_max_range_inferred(tmp_path):
    lines = [flaser(4, [1, 50, 50, 2], (0, 0, 0), (0, 0, 0), 0.1), flaser(4, [50, 3, 50, 50], (0, 0, 0), (0, 0, 0), 0.2)]
    log = io.read_carmen_log(write(tmp_path, "s.log", "\n".join(lines) + "\n"))
    assert log.max_range == 50.0 and "saturation" in log.meta["max_range_source"]
    lines = [flaser(3, [1, 2, 3], (0, 0, 0), (0, 0, 0), 0.1)]
    log = io.read_carmen_log(write(tmp_path, "t.log", "\n".join(lines) + "\n"))
    assert log.max_range == pytest.approx(81.83) and not log.no_return.any()
    assert io.read_carmen_log(write(tmp_path, "u.log", lines[0] + "\n"), max_range=2.5).no_return.sum() == 1


def test_carmen_reanchored_odometry_chain(tmp_path):
    """A corrected log: ODOM re-anchored to the corrected pose after each scan, then raw increments."""
    corrected = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.2], [2.0, 0.5, 0.6]])
    raw_step = np.array([[0.9, 0.05, 0.15], [1.1, 0.2, 0.45]])  # what the wheels said (differs from truth)
    lines = []
    for k in range(3):
        c = corrected[k]
        lines.append(flaser(3, [1, 2, 3], c, c, k))
        lines.append(f"ODOM {c[0]} {c[1]} {c[2]} 0 0 0 0 host 0")  # the anchor
        lines.append("NEFF 10")
        if k < 2:
            half = compose(c, raw_step[k] / 2)
            full = compose(c, raw_step[k])
            lines.append(f"ODOM {half[0]} {half[1]} {half[2]} 0 0 0 {k + 0.3} host 0")
            lines.append(f"ODOM {full[0]} {full[1]} {full[2]} 0 0 0 {k + 0.6} host 0")
    log = io.read_carmen_log(write(tmp_path, "corr.log", "\n".join(lines) + "\n"))
    assert log.meta["odometry"].startswith("re-anchored")
    assert np.allclose(log.poses, corrected)
    assert np.allclose(log.motions(), raw_step, atol=1e-9)  # the real increments, not the corrected ones
    assert np.allclose(log.odometry[0], corrected[0])
    plain = io.read_carmen_log(tmp_path / "corr.log", reanchored=False)
    assert np.allclose(plain.odometry, corrected)  # forced off: FLASER odometry triple


def test_carmen_raw_log_offset_and_no_reference(tmp_path):
    """Raw log: the first triple is the laser pose (robot odometry + offset), no reference poses."""
    off = np.array([0.12, 0.0, 0.0])
    lines = []
    for k, odo in enumerate(np.array([[0, 0, 0.0], [0.3, 0.1, 0.5], [0.6, 0.4, 1.0]])):
        lp = compose(odo, off)
        lines.append(flaser(3, [1, 2, 3], lp, odo, k * 0.1))
    log = io.read_carmen_log(write(tmp_path, "raw.log", "\n".join(lines) + "\n"))
    assert np.allclose(log.sensor_offset, off) and log.poses is None
    assert log.meta["odometry"] == "FLASER odometry triple"


def test_carmen_robotlaser1(tmp_path):
    n = 5
    rng_ = " ".join(["2.0"] * n)
    # type start fov res maxr acc remission_mode n ranges nrem [] laser(3) robot(3) tv rv fwd side turn ts host lts
    rec = (f"ROBOTLASER1 0 -1.5708 3.1416 0.7854 30.0 0.01 0 {n} {rng_} 0 "
           "1.2 0 0 1.0 0 0 0 0 0 0 0 5.0 host 5.0")
    log = io.read_carmen_log(write(tmp_path, "rl.log", rec + "\n" + rec.replace(" 5.0 host", " 6.0 host") + "\n"))
    assert log.n_beams == n and log.max_range == 30.0
    assert np.allclose(np.degrees(log.angles), [-90, -45, 0, 45, 90], atol=1e-3)
    assert np.allclose(log.sensor_offset, [0.2, 0, 0]) and np.allclose(log.odometry[0], [1.0, 0, 0])
    assert np.allclose(log.times, [5.0, 6.0])
    bad = rec.replace(f" {n} {rng_} 0 ", f" {n} {rng_} 2 ")
    p = write(tmp_path, "rl_bad.log", bad + "\n")
    with raises_at(p, 1, "2 remission values has"):
        io.read_carmen_log(p)


def test_carmen_prefers_flaser_and_counts_the_other(tmp_path):
    rec = "ROBOTLASER1 0 -1.5708 3.1416 0.7854 30.0 0.01 0 5 2 2 2 2 2 0 1.2 0 0 1.0 0 0 0 0 0 0 0 5.0 host 5.0"
    text = carmen_text() + rec + "\n"
    with pytest.warns(ParseWarning, match="1 ROBOTLASER1 records \\(not used: reading FLASER\\)"):
        log = io.read_carmen_log(write(tmp_path, "both.log", text))
    assert log.n_beams == 4
    with pytest.warns(ParseWarning):
        log = io.read_carmen_log(tmp_path / "both.log", laser="ROBOTLASER1")
    assert log.n_beams == 5


@pytest.mark.parametrize(
    "bad_line, match",
    [
        ("FLASER 4 1 2 3 0 0 0 0 0 0 0.5 host 0.5", "FLASER with 4 readings has 15 fields"),
        ("FLASER four 1 2 3 4 0 0 0 0 0 0 0.5 host 0.5", "number of readings"),
        ("FLASER 4 1 2 x 4 0 0 0 0 0 0 0.5 host 0.5", "field 3 is 'x'"),
        ("FLASER 4 1 2 NaN 4 0 0 0 0 0 0 0.5 host 0.5", "finite"),
        ("FLASER 4 1 -2 3 4 0 0 0 0 0 0 0.5 host 0.5", "reading 2 is negative"),
        ("FLASER 3 1 2 3 0 0 0 0 0 0 0.5 host 0.5", "expected 4 readings like the first FLASER"),
        ("ODOM 1 2 3", "10 fields"),
        ("ODOM 1 2 three 0 0 0 0.5 host 0.5", "field 3 is 'three'"),
        ("NEFF", "NEFF value"),
        ("PARAM lonely", "PARAM name value"),
    ],
)
def test_carmen_bad_records(tmp_path, bad_line, match):
    lines = carmen_text().splitlines()
    lines.insert(5, bad_line)  # line 6, after the first scan
    p = write(tmp_path, "bad.log", "\n".join(lines) + "\n")
    with raises_at(p, 6, match), warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        io.read_carmen_log(p)
    with pytest.warns(ParseWarning, match=r"1 malformed records \(first at line 6"):
        log = io.read_carmen_log(p, on_error="skip")
    assert log.skipped["malformed records"] == 1 and len(log) == 2


def test_carmen_garbage_empty_no_scans(tmp_path):
    p = write(tmp_path, "g.log", "PARAM a b\n3.14 is not a record\n")
    with raises_at(p, 2, "expected a CARMEN record type"):
        io.read_carmen_log(p, on_error="skip")
    p = write(tmp_path, "e.log", "")
    with raises_at(p, None, "empty"):
        io.read_carmen_log(p)
    p = write(tmp_path, "n.log", "PARAM a b\nODOM 0 0 0 0 0 0 0 h 0\n")
    with raises_at(p, None, "no FLASER or ROBOTLASER1 scan records"):
        io.read_carmen_log(p)


def test_carmen_gzip_by_content_and_writer(tmp_path):
    log = LaserLog(times=[0.0, 0.5], odometry=[[0, 0, 0], [0.4, 0.1, 0.3]], ranges=[[1.0, 2.0], [81.83, 1.0]],
                   angles=io.carmen_angles(2), max_range=81.83)
    p = io.write_carmen_log(tmp_path / "w.log.gz", log)
    assert p.read_bytes()[:2] == b"\x1f\x8b"
    renamed = tmp_path / "no_suffix.log"
    renamed.write_bytes(p.read_bytes())  # compression is detected from content, not the name
    back = io.read_log(renamed)
    assert back.format == "carmen" and np.allclose(back.odometry, log.odometry, atol=1e-6)
    assert back.no_return.tolist() == [[False, False], [True, False]]
    with pytest.raises(ValueError, match="FLASER beams"):
        io.write_carmen_log(tmp_path / "x.log", LaserLog(times=[0], odometry=[[0, 0, 0]], ranges=[[1.0, 1.0]],
                                                        angles=[0.0, 0.1], max_range=5))


# ============================================================================ ROS map_server
def ros_map(tmp_path, img, yaml_extra="", name="m"):
    io.write_pgm(tmp_path / f"{name}.pgm", np.asarray(img, dtype=np.uint8))
    y = tmp_path / f"{name}.yaml"
    y.write_text(f"image: {name}.pgm\nresolution: 0.05\norigin: [-2.0, 1.0, 0.0]\n" + yaml_extra)
    return y


IMG = [[0, 0, 0, 0],
       [0, 254, 150, 205],
       [254, 254, 254, 220]]


def test_ros_trinary_orientation_and_origin(tmp_path):
    g = io.read_ros_map(ros_map(tmp_path, IMG, "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"))
    assert g.shape == (3, 4) and g.resolution == 0.05 and np.allclose(g.origin, [-2.0, 1.0])
    # image top row (walls) becomes the top row of the map: row index 2 (largest y)
    assert np.all(g.data[2] == 1.0)
    assert np.allclose(g.data[0], [0, 0, 0, 0])  # 220 -> p = 0.137 < 0.196: free
    assert g.data[1, 1] == 0.0 and np.isnan(g.data[1, 2]) and np.isnan(g.data[1, 3])  # grey wall 150: unknown
    # the world point in image pixel (row 0, col 1), top left, is in a wall; pixel (2, 1) is free
    assert not g.is_free([[-2.0 + 0.075, 1.0 + 2.5 * 0.05]])[0] and g.is_free([[-2.0 + 0.075, 1.0 + 0.025]])[0]


def test_ros_grey_walls_fixes(tmp_path):
    y = ros_map(tmp_path, IMG)
    assert io.read_ros_map(y, occupied_thresh=0.3).data[1, 2] == 1.0  # 150: p = 0.41 > 0.3
    g = io.read_ros_map(y, not_free="occupied")
    assert g.data[1, 2] == 1.0 and g.data[1, 3] == 1.0 and not g.unknown.any()
    with pytest.raises(ValueError, match="not_free"):
        io.read_ros_map(y, not_free="maybe")


def test_ros_negate_scale_raw(tmp_path):
    neg = io.read_ros_map(ros_map(tmp_path, IMG, "negate: 1\n", name="n"))
    assert np.all(neg.data[2] == 0.0)  # black is free when negated
    sc = io.read_ros_map(ros_map(tmp_path, IMG, "mode: scale\n", name="s"))
    p = (255 - 150) / 255
    assert sc.data[1, 2] == pytest.approx((p - 0.196) / (0.65 - 0.196))
    raw = io.read_ros_map(ros_map(tmp_path, [[0, 50, 100, 255]], "mode: raw\n", name="r"))
    assert np.allclose(raw.data[0], [0.0, 0.5, 1.0, np.nan], equal_nan=True)
    assert io.read_ros_map(tmp_path / "r.yaml", mode="trinary").data[0, 0] == 1.0  # override the YAML


def test_ros_png_rgb_and_alpha(tmp_path):
    from PIL import Image

    rgba = np.zeros((1, 3, 4), dtype=np.uint8)
    rgba[0, 0] = [254, 254, 254, 255]
    rgba[0, 1] = [150, 150, 150, 255]
    rgba[0, 2] = [150, 150, 150, 0]  # transparent: unknown in scale mode
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    (tmp_path / "a.yaml").write_text("image: a.png\nresolution: 1\norigin: [0, 0, 0]\nmode: scale\n")
    g = io.read_ros_map(tmp_path / "a.yaml")
    assert g.data[0, 0] == 0.0 and 0 < g.data[0, 1] < 1 and np.isnan(g.data[0, 2])
    Image.fromarray(rgba[..., :3], "RGB").save(tmp_path / "b.png")
    (tmp_path / "b.yaml").write_text("image: b.png\nresolution: 1\norigin: [0, 0, 0]\n")
    assert np.allclose(io.read_ros_map(tmp_path / "b.yaml").data, [[0, np.nan, np.nan]], equal_nan=True)


def test_ros_roundtrip(tmp_path):
    d = np.array([[0.0, 1.0, np.nan], [0.1, 0.9, 0.4]])
    g = OccupancyGrid(d, 0.25, origin=(1.5, -3.0))
    back = io.read_ros_map(io.write_ros_map(tmp_path / "rt.yaml", g))
    assert np.allclose(back.data, [[0, 1, np.nan], [0, 1, np.nan]], equal_nan=True)
    assert back.resolution == 0.25 and np.allclose(back.origin, [1.5, -3.0])
    with pytest.raises(ValueError, match=r"\.yaml"):
        io.write_ros_map(tmp_path / "rt.pgm", g)


@pytest.mark.parametrize(
    "yaml, line, match",
    [
        ("resolution: 0.05\norigin: [0, 0, 0]\n", None, "missing key 'image'"),
        ("image: m.pgm\nresolution: fine\norigin: [0, 0, 0]\n", 2, "resolution must be a number"),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", 2, "resolution must be a number"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n", 3, r"origin must be \[x, y, yaw\]"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\n", 4, "negate must be"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: fancy\n", 4, "mode must be one of"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 0.7\n", 4, "must be below"),
        ("image: other.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", 1, "does not exist"),
        ("image: m.pgm\nresolution: 0.05\nresolution: 0.1\norigin: [0, 0, 0]\n", 3, "appears twice"),
        ("image: m.pgm\nmeta:\n  nested: 1\n", 2, "has no value"),
        ("just some words\n", 1, "expected 'key: value'"),
    ],
)
def test_ros_bad_yaml(tmp_path, yaml, line, match):
    io.write_pgm(tmp_path / "m.pgm", np.zeros((2, 2), dtype=np.uint8))
    y = write(tmp_path, "m.yaml", yaml)
    with raises_at(y, line, match):
        io.read_ros_map(y)


def test_ros_yaw_warns_and_image_given(tmp_path):
    y = ros_map(tmp_path, IMG)
    y.write_text(y.read_text().replace("origin: [-2.0, 1.0, 0.0]", "origin: [-2.0, 1.0, 0.5]"))
    with pytest.warns(ParseWarning, match="yaw 0.5 rad is ignored"):
        io.read_ros_map(y)
    with raises_at(tmp_path / "m.pgm", None, "give the YAML file"):
        io.read_ros_map(tmp_path / "m.pgm")
    with raises_at(tmp_path / "m.pgm", None, "pass the map_server YAML"):
        io.read_map(tmp_path / "m.pgm")


def test_pgm_plain_and_bad(tmp_path):
    p = tmp_path / "p2.pgm"
    p.write_bytes(b"P2\n# comment\n2 2\n255\n0 10\n20 255\n")
    assert io.read_pgm(p).tolist() == [[0, 10], [20, 255]]
    p.write_bytes(b"P2\n2 2\n255\n0 10 20\n")
    with raises_at(p, None, "4 pixels; the file holds 3"):
        io.read_pgm(p)
    p.write_bytes(b"P5\n4 4\n255\n" + bytes(10))
    with raises_at(p, None, r"4 x 4 pixels \(16 bytes\).*only 10"):
        io.read_pgm(p)
    p.write_bytes(b"P5\n2 2\n255\n" + bytes(10))
    with raises_at(p, None, "header and data disagree"):
        io.read_pgm(p)
    p.write_bytes(b"P6\n2 2\n255\n" + bytes(12))
    with raises_at(p, 1, "expected a PGM image"):
        io.read_pgm(p)
    p.write_bytes(b"P5\n2 x\n255\n" + bytes(4))
    with raises_at(p, 2, "must be a positive integer"):
        io.read_pgm(p)
    p.write_bytes(b"P5\n2 2\n100\n" + bytes([0, 0, 0, 200]))
    with raises_at(p, None, "exceeds the header's maxval"):
        io.read_pgm(p)
    p.write_bytes(b"P5\n2 1\n65535\n" + bytes([1, 0, 255, 255]))
    assert io.read_pgm(p).tolist() == [[256, 65535]]


# ============================================================================ detection
def test_detect_formats(tmp_path):
    assert io.detect_map_format(write(tmp_path, "a.dat", CMU_MAP)) == "cmu"
    assert io.detect_map_format(ros_map(tmp_path, IMG)) == "ros"
    assert io.detect_log_format(write(tmp_path, "a.log", cmu_log_text())) == "cmu"
    assert io.detect_log_format(write(tmp_path, "b.log", carmen_text())) == "carmen"
    gz = tmp_path / "c.gz"
    gz.write_bytes(gzip.compress(cmu_log_text().encode()))
    assert io.detect_log_format(gz) == "cmu" and len(io.read_log(gz)) == 2
    assert io.read_map(tmp_path / "a.dat").shape == (3, 4)
    p = write(tmp_path, "x.txt", "hello world\n")
    with raises_at(p, 1, "cannot tell the map format"):
        io.detect_map_format(p)
    p = write(tmp_path, "y.txt", "\n\n3.0 4.0\n")
    with raises_at(p, 3, "cannot tell the log format"):
        io.detect_log_format(p)
    p = write(tmp_path, "z.txt", "# only a comment\n")
    with raises_at(p, None, "no records"):
        io.detect_log_format(p)
    with pytest.raises(ValueError, match="format must be one of"):
        io.read_log(tmp_path / "a.log", format="rosbag")
    with pytest.raises(ValueError, match="format must be one of"):
        io.read_map(tmp_path / "a.dat", format="png")
    # the format can be forced: a CMU log read as CARMEN fails loudly, not silently
    with raises_at(tmp_path / "a.log", None, r"no FLASER or ROBOTLASER1 scan records.*2 O records \(unknown"):
        io.read_log(tmp_path / "a.log", format="carmen")


def test_ros_yaml_missing_a_key_names_it(tmp_path):
    """A YAML without image or resolution used to get 'cannot tell the map format' (issue 16)."""
    ros_map(tmp_path, IMG)
    full = (tmp_path / "m.yaml").read_text().splitlines()
    for key in ("image", "resolution", "origin"):
        p = write(tmp_path, f"no-{key}.yaml", "\n".join(x for x in full if not x.startswith(key + ":")) + "\n")
        assert io.detect_map_format(p) == "ros"
        with raises_at(p, None, f"missing key '{key}'"):
            io.read_map(p)


# ============================================================================ time stamps
def test_readers_record_scan_lines_and_time_stamp_problems(tmp_path):
    """Non-monotonic and repeated time stamps are found with the first offending line (issue 16)."""
    cmu = cmu_log_text().replace(" 0.11\n", " 0.005\n")  # the second scan goes back in time
    p = write(tmp_path, "back.log", cmu)
    log = io.read_cmu_log(p)
    assert log.meta["scan_lines"].tolist() == [2, 4]
    assert io.time_stamp_problems(log) == [
        f"{p}:4: time stamp 0.005 is earlier than the previous scan's 0.01 (1 of 2 scans go back in time)"]
    c = write(tmp_path, "same.log", carmen_text().replace("0.3 host 0.3", "0.1 host 0.1"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        log = io.read_carmen_log(c)
    assert log.meta["scan_lines"].tolist() == [5, 11]
    assert io.time_stamp_problems(log) == [f"{c}:11: time stamp 0.1 repeats the previous scan's (1 of 2 scans)"]
    assert io.time_stamp_problems(log.select([1])) == []
    assert log.select([1]).meta["scan_lines"].tolist() == [11]   # per-scan meta follows select()
    assert io.time_stamp_problems(io.read_cmu_log(write(tmp_path, "ok.log", cmu_log_text()))) == []


# ============================================================================ LaserLog
def test_laserlog_validation_and_helpers():
    base = dict(times=[0.0, 1.0], odometry=np.zeros((2, 3)), ranges=np.ones((2, 3)), angles=[-1, 0, 1],
                max_range=5.0)
    log = LaserLog(**base)
    assert repr(log).startswith("LaserLog('arrays', scans=2, beams=3")
    assert log.duration == 1.0 and log.select([1]).times.tolist() == [1.0]
    with pytest.raises(ValueError, match="picks nothing"):
        log.select(slice(5, None))
    with pytest.raises(ValueError, match="count must be between 1 and the 3 beams"):
        log.select_beams(count=4)
    with pytest.raises(ValueError, match="no reference poses"):
        log.laser_poses()
    for key, value, match in [
        ("ranges", np.ones((2, 2)), r"angles must have shape \(2,\)"),
        ("ranges", [[1, -1, 1], [1, 1, 1]], "ranges must be finite and >= 0"),
        ("ranges", [[1, np.nan, 1], [1, 1, 1]], "ranges must be finite"),
        ("odometry", np.zeros((3, 3)), r"odometry must have shape \(2, 3\)"),
        ("times", [], "non-empty"),
        ("max_range", 0.0, "max_range must be a finite number of metres > 0"),
        ("angles", [0, 1], r"angles must have shape \(3,\)"),
    ]:
        with pytest.raises(ValueError, match=match):
            LaserLog(**{**base, key: value})
    with pytest.raises(ValueError, match="poses must have shape"):
        LaserLog(**base, poses=np.zeros((3, 3)))
    off = LaserLog(**base, sensor_offset=(0.25, 0, 0), poses=[[1, 1, np.pi / 2], [0, 0, 0]])
    assert np.allclose(off.laser_poses()[0], [1, 1.25, np.pi / 2])
    assert np.allclose(off.robot_poses_from_laser(off.laser_poses()), off.poses)
    assert np.array_equal(log.ranges.flags.writeable, False)
