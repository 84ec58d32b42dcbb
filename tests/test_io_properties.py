"""Property tests of localize.io (hypothesis): round trips of every writer and reader, and readers under
arbitrary corruption of a valid file.

* Round trips: CMU map, CMU log, CARMEN log, ROS map_server map: what a writer writes, its reader
  reads back (to the precision the format stores).
* Corruption: a valid file truncated at any byte, with bytes flipped, or gzip-compressed and then
  damaged, is either read or rejected with the reader's own :class:`~localize.io.FormatError` naming
  the file (``file:line: ...`` or ``file: ...`` for whole-file problems) -- never another exception.

The files are small (a few kB) and the example counts modest, so that the whole module runs in a few
seconds in the normal suite.
"""

from __future__ import annotations

import gzip
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from localize import io
from localize.grid import OccupancyGrid
from localize.io import FormatError, LaserLog, ParseWarning

PROPS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
CORRUPT = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def quiet(fn, *args, **kwargs):
    """Call a reader with its ParseWarnings (skipped records, ignored yaw) silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParseWarning)
        return fn(*args, **kwargs)


# ============================================================================ strategies
def occupancy(shape_max: int = 12, allow_nan: bool = True):
    cell = st.floats(0.0, 1.0) | (st.just(np.nan) if allow_nan else st.floats(0.0, 1.0))
    return arrays(np.float64, st.tuples(st.integers(1, shape_max), st.integers(1, shape_max)), elements=cell)


@st.composite
def laser_logs(draw, angles, max_range, n_max: int = 4):
    k = draw(st.integers(1, n_max))
    b = angles.size
    t0 = draw(st.floats(0.0, 1e4))
    dts = draw(arrays(np.float64, k, elements=st.floats(0.001, 5.0)))
    times = t0 + np.cumsum(dts)
    xy = draw(arrays(np.float64, (k, 2), elements=st.floats(-500.0, 500.0)))
    th = draw(arrays(np.float64, (k, 1), elements=st.floats(-3.14, 3.14)))
    ranges = draw(arrays(np.float64, (k, b), elements=st.floats(0.0, max_range) | st.just(max_range)))
    return dict(times=times, odometry=np.hstack([xy, th]), ranges=ranges, angles=angles, max_range=max_range)


# ============================================================================ round trips
@PROPS
@given(data=occupancy(), res_cm=st.integers(1, 50))
def test_cmu_map_round_trip(tmp_path, data, res_cm):
    g = OccupancyGrid(data, res_cm / 100.0)
    back = io.read_cmu_map(io.write_cmu_map(tmp_path / "m.dat", g))
    assert back.shape == g.shape and back.resolution == pytest.approx(g.resolution)
    assert np.array_equal(np.isnan(back.data), np.isnan(g.data))
    ok = ~np.isnan(g.data)
    assert np.allclose(back.data[ok], g.data[ok], atol=1e-6)


@PROPS
@given(d=laser_logs(io.CMU_ANGLES, io.CMU_MAX_RANGE),
       offset=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)))
def test_cmu_log_round_trip(tmp_path, d, offset):
    log = LaserLog(**d, sensor_offset=offset)
    back = io.read_cmu_log(io.write_cmu_log(tmp_path / "r.log", log))
    assert len(back) == len(log) and back.n_beams == 180
    assert np.allclose(back.times, log.times, atol=1e-6)
    assert np.allclose(back.odometry[:, :2], log.odometry[:, :2], atol=1e-5)       # 1e-3 cm
    assert np.allclose(back.odometry[:, 2], log.odometry[:, 2], atol=1e-6)
    assert np.array_equal(back.no_return, log.no_return)
    close = ~log.no_return
    assert np.allclose(back.ranges[close], log.ranges[close], atol=0.01 + 1e-9)    # whole cm, below max_range
    assert np.allclose(back.sensor_offset[:2], offset[:2], atol=1e-4)


@PROPS
@given(d=laser_logs(io.carmen_angles(181), 1.0, n_max=4), mr_cm=st.integers(100, 8191))
def test_carmen_log_round_trip(tmp_path, d, mr_cm):
    mr = mr_cm / 100.0
    d = {**d, "max_range": mr, "ranges": d["ranges"] * mr}
    log = LaserLog(**d)
    for name in ("r.log", "r.log.gz"):
        back = quiet(io.read_carmen_log, io.write_carmen_log(tmp_path / name, log))
        assert len(back) == len(log) and back.max_range == pytest.approx(mr)
        assert np.allclose(back.times, log.times, atol=1e-6)
        assert np.allclose(back.odometry, log.odometry, atol=2e-6)
        assert np.allclose(back.ranges, np.minimum(log.ranges, mr), atol=5e-4 + 1e-9)


@PROPS
@given(data=arrays(np.float64, st.tuples(st.integers(1, 12), st.integers(1, 12)),
                   elements=st.sampled_from([0.0, 1.0, np.nan])),
       res_mm=st.integers(1, 1000), ox=st.integers(-10**5, 10**5), oy=st.integers(-10**5, 10**5))
def test_ros_map_round_trip(tmp_path, data, res_mm, ox, oy):
    g = OccupancyGrid(data, res_mm / 1000.0, origin=(ox / 1000.0, oy / 1000.0))
    back = io.read_ros_map(io.write_ros_map(tmp_path / "m.yaml", g))
    assert np.array_equal(back.data, g.data, equal_nan=True)
    assert back.resolution == pytest.approx(g.resolution) and np.allclose(back.origin, g.origin, atol=1e-9)


# ============================================================================ corruption
def cmu_log_bytes() -> bytes:
    ranges = np.linspace(0.5, 9.0, 180)[None, :] * np.array([[1.0], [1.1], [0.9]])
    ranges[1, 5] = 80.0
    log = LaserLog(times=[0.5, 1.0, 1.5], odometry=[[1.0, 2.0, 0.1], [1.2, 2.0, 0.15], [1.4, 2.1, 0.2]],
                   ranges=ranges, angles=io.CMU_ANGLES, max_range=80.0, sensor_offset=io.CMU_SENSOR_OFFSET,
                   odom_times=[0.4, 0.9], odom_poses=[[1.0, 2.0, 0.1], [1.1, 2.0, 0.12]])
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return io.write_cmu_log(Path(d) / "a.log", log).read_bytes()


def carmen_bytes() -> bytes:
    n = 8
    lines = [
        "# message formats defined: PARAM SYNC ODOM FLASER",
        "PARAM robot_front_laser_max 81.9 nohost 0",
        "PARAM robot_frontlaser_offset 0.1 nohost 0",
        "ODOM 0 0 0 0 0 0 0.0 host 0.0",
        f"FLASER {n} " + " ".join(["1.5"] * n) + " 0.1 0 0 0 0 0 0.1 host 0.1",
        "NEFF 12.5",
        "SYNC 1 2 3",
        "ODOM 0.5 0 0.1 0 0 0 0.2 host 0.2",
        f"FLASER {n} " + " ".join(["2.25"] * n) + " 0.6 0 0.1 0.5 0 0.1 0.3 host 0.3",
        "ROBOTLASER1 0 -1.5708 3.1416 0.7854 81.9 0.01 0 5 1 2 3 4 5 0 0.6 0 0.1 0.5 0 0.1 0 0 0 0 0 0.35 h 0.35",
    ]
    return ("\n".join(lines) + "\n").encode()


CMU_MAP = (b"robot_specifications->global_mapsize_x  40\nrobot_specifications->global_mapsize_y  30\n"
           b"robot_specifications->resolution 10\nrobot_specifications->autoshifted_x 0\n"
           b"robot_specifications->autoshifted_y 0\n\nglobal_map[0]: 3 4\n0 0 0\n1 0.9 -1\n1 1 0.25\n1 1 1\n")
ROS_YAML = b"image: m.pgm\nresolution: 0.05\norigin: [-2.0, 1.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n" \
           b"free_thresh: 0.196\n"
PGM = b"P5\n# a map\n4 3\n255\n" + bytes([0, 0, 0, 0, 0, 254, 150, 205, 254, 254, 254, 220])

VALID = {
    "cmu_log": (cmu_log_bytes(), io.read_cmu_log),
    "carmen": (carmen_bytes(), io.read_carmen_log),
    "cmu_map": (CMU_MAP, io.read_cmu_map),
    "any_log": (cmu_log_bytes(), io.read_log),
    "any_map": (CMU_MAP, io.read_map),
}


def flip(data: bytes, edits) -> bytes:
    b = bytearray(data)
    for pos, value in edits:
        b[pos % len(b)] = value
    return bytes(b)


@st.composite
def corruptions(draw, data: bytes):
    """A valid file's bytes, damaged: truncated, bytes replaced, or gzip-compressed then damaged."""
    kind = draw(st.sampled_from(["truncate", "flip", "gzip-truncate", "gzip-flip", "gzip-ok"]))
    if kind.startswith("gzip"):
        data = gzip.compress(data, mtime=0)
    edits = st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), min_size=1, max_size=4)
    if kind.endswith("truncate"):
        return data[: draw(st.integers(0, len(data) - 1))]
    if kind.endswith("flip"):
        return flip(data, draw(edits))
    return data


def assert_read_or_format_error(reader, path: Path, allowed=None) -> None:
    allowed = {str(path)} if allowed is None else allowed
    try:
        quiet(reader, path)
    except FormatError as e:
        assert e.path in allowed, str(e)
        assert e.line is None or e.line >= 1, str(e)
        assert str(e).startswith(e.path + (f":{e.line}: " if e.line is not None else ": ")), str(e)


@pytest.mark.parametrize("name", list(VALID))
def test_the_valid_files_are_read(tmp_path, name):
    data, reader = VALID[name]
    p = tmp_path / "f"
    p.write_bytes(data)
    quiet(reader, p)


def make_corruption_test(name: str):
    data, reader = VALID[name]

    @CORRUPT
    @given(bad=corruptions(data))
    def test(tmp_path, bad):
        p = tmp_path / f"{name}.bad"
        p.write_bytes(bad)
        assert_read_or_format_error(reader, p)

    test.__name__ = f"test_corrupted_{name}_is_read_or_rejected_with_file_and_line"
    return test


for _name in VALID:
    globals()[f"test_corrupted_{_name}_is_read_or_rejected_with_file_and_line"] = make_corruption_test(_name)


@CORRUPT
@given(bad_yaml=corruptions(ROS_YAML), bad_pgm=st.none() | corruptions(PGM))
def test_corrupted_ros_map_is_read_or_rejected_with_file_and_line(tmp_path, bad_yaml, bad_pgm):
    y, img = tmp_path / "m.yaml", tmp_path / "m.pgm"
    y.write_bytes(bad_yaml)
    img.write_bytes(PGM if bad_pgm is None else bad_pgm)
    assert_read_or_format_error(io.read_ros_map, y, allowed={str(y), str(img)})
    assert_read_or_format_error(io.read_pgm, img)


def png_bytes() -> bytes:
    import io as stdio

    from PIL import Image

    buf = stdio.BytesIO()
    Image.fromarray(np.array([[0, 0, 0, 0], [0, 254, 150, 205], [254, 254, 254, 220]], dtype=np.uint8)).save(
        buf, format="PNG")
    return buf.getvalue()


PNG = png_bytes()


@CORRUPT
@given(bad=corruptions(PNG))
def test_corrupted_png_map_image_is_read_or_rejected_with_file(tmp_path, bad):
    y, img = tmp_path / "m.yaml", tmp_path / "m.png"
    y.write_bytes(ROS_YAML.replace(b"m.pgm", b"m.png"))
    img.write_bytes(bad)
    assert_read_or_format_error(io.read_ros_map, y, allowed={str(y), str(img)})
