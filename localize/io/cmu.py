"""CMU 16-831 homework files: the Wean Hall map (``wean.dat``) and robot logs.

**Map** (BeeSoft format, as read by the original CARMEN/BeeSoft C loaders)::

    robot_specifications->global_mapsize_x  8000      # cm
    robot_specifications->global_mapsize_y  8000      # cm
    robot_specifications->resolution 10               # cm per cell
    robot_specifications->autoshifted_x 0
    robot_specifications->autoshifted_y 0

    global_map[0]: 800 800                            # size_y size_x
    <one text line per x cell, each holding the size_y values of that column>

Text line ``k`` after the ``global_map`` line holds the cells with ``x = k``;
the ``m``-th value on it is the cell with ``y = m`` (x to the right, y up). The
two numbers of ``global_map[0]:`` are read, as the original C loaders do, as
``size_y size_x``: the count of values on a line, then the count of lines (the
``global_mapsize_x/y`` header lines, when present, must agree). Values are the
probability that the cell is **free** — walls near 0, floor near 1 — and
``-1`` marks unknown cells (any other value outside [0, 1] is an error). :func:`read_cmu_map` converts to
the :class:`~localize.OccupancyGrid` convention: occupancy probability
``1 - value``, NaN for unknown, rows indexed by y.

**Log**: one record per line, x, y and ranges in centimetres, angles in
radians, time stamps in seconds::

    O x y theta ts                                     # odometry
    L x y theta xl yl thetal r1 ... r180 ts            # laser scan

``x y theta`` is the robot's odometry pose, ``xl yl thetal`` the laser's pose
in the same (arbitrary) odometry frame — 25 cm ahead of the robot centre on
the course's robot. Beam 1 points to the robot's right; the beams sweep
counter-clockwise in 1 degree steps (-90 ... +89 degrees). Readings of 8000 cm
and more mean "no return".
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._checks import check_grid
from ..geometry import compose
from ..grid import OccupancyGrid
from ._common import (
    FormatError,
    LaserLog,
    ParseWarning,
    SkipCounter,
    median_offset,
    parse_floats,
    read_lines,
    read_records,
)

__all__ = ["read_cmu_map", "write_cmu_map", "read_cmu_log", "write_cmu_log", "CMU_ANGLES", "CMU_MAX_RANGE",
           "CMU_NO_RETURN_CM", "CMU_SENSOR_OFFSET"]

PathLike = str | os.PathLike

#: Beam angles of the CMU logs: -90 ... +89 degrees, counter-clockwise, in radians.
CMU_ANGLES: NDArray[np.float64] = np.radians(np.arange(-90.0, 90.0, 1.0))
CMU_ANGLES.setflags(write=False)
#: Readings at or above 8000 cm (80 m) mean "no return".
CMU_MAX_RANGE = 80.0
#: What a CMU log writes for "no return" (centimetres): every reading at or above ``max_range``.
CMU_NO_RETURN_CM = 8183
#: The laser sits 25 cm ahead of the robot centre.
CMU_SENSOR_OFFSET: NDArray[np.float64] = np.array([0.25, 0.0, 0.0])
CMU_SENSOR_OFFSET.setflags(write=False)

_HEADER_PREFIX = "robot_specifications->"


def read_cmu_map(path: PathLike) -> OccupancyGrid:
    """Read a CMU 16-831 (BeeSoft) map such as ``wean.dat`` into an :class:`~localize.OccupancyGrid`.

    Parameters
    ----------
    path : str or path-like
        The map file (optionally gzip-compressed).

    Returns
    -------
    OccupancyGrid
        Occupancy probability ``1 - P(free)``, NaN for unknown cells, rows = y,
        columns = x, origin ``(0, 0)``, resolution in metres (10 cm -> 0.1).

    Raises
    ------
    FormatError
        (a ``ValueError``) ``file:line: what was expected`` for a missing
        ``global_map[0]`` line, a header that disagrees with the data, a line
        with the wrong number of values, non-numeric or NaN values, values
        outside [0, 1] other than -1 (unknown), or missing/extra lines.

    Examples
    --------
    >>> p = tmp_text("tiny.dat", '''robot_specifications->global_mapsize_x  30
    ... robot_specifications->global_mapsize_y  20
    ... robot_specifications->resolution 10
    ...
    ... global_map[0]: 2 3
    ... 1 0
    ... 1 1
    ... -1 1
    ... ''')
    >>> g = read_cmu_map(p)      # 3 lines (x = 0, 1, 2) of 2 values (y = 0, 1)
    >>> g.shape, g.resolution
    ((2, 3), 0.1)
    >>> g.data                   # row = y; the wall (P(free) = 0) is at x = 0, y = 1
    array([[ 0.,  0., nan],
           [ 1.,  0.,  0.]])
    """
    lines = read_lines(path)
    header, size_y, size_x, size_line = _cmu_header(path, lines)
    res_cm = _checked_resolution(path, header, size_x, size_y, size_line)
    p_free = np.array(_cmu_rows(path, lines, size_x, size_y, size_line))  # [x, y]
    occ = np.where(p_free < 0, np.nan, 1.0 - p_free)
    return OccupancyGrid(occ.T, res_cm / 100.0, origin=(0.0, 0.0))


def _cmu_header_line(path: PathLike, n: int, line: str) -> tuple[str, float]:
    parts = line[len(_HEADER_PREFIX):].split()
    if len(parts) != 2:
        raise FormatError(path, n, f"a header line is '{_HEADER_PREFIX}name value'; got {line!r}")
    try:
        val = float(parts[1])
    except ValueError:
        raise FormatError(path, n, f"header {parts[0]} must be a number; got {parts[1]!r}") from None
    if not np.isfinite(val):
        raise FormatError(path, n, f"header {parts[0]} must be finite; got {parts[1]!r}")
    return parts[0], val


def _cmu_header(path: PathLike, lines) -> tuple[dict[str, tuple[float, int]], int, int, int]:
    """The header lines up to ``global_map[0]: size_y size_x``: ``({name: (value, line)}, size_y, size_x, line)``."""
    header: dict[str, tuple[float, int]] = {}
    for n, raw in lines:
        line = raw.strip()
        if not line:
            continue
        if line.startswith(_HEADER_PREFIX):
            name, val = _cmu_header_line(path, n, line)
            header[name] = (val, n)
            continue
        if line.startswith("global_map[0]:"):
            parts = line[len("global_map[0]:"):].split()
            try:
                size_y, size_x = (int(p) for p in parts)
            except ValueError:
                raise FormatError(path, n, f"expected 'global_map[0]: size_y size_x' with two integers; got {line!r}") from None
            if size_x <= 0 or size_y <= 0:
                raise FormatError(path, n, f"map sizes must be positive; got {size_y} {size_x}")
            return header, size_y, size_x, n
        raise FormatError(path, n, f"expected a '{_HEADER_PREFIX}...' header line or 'global_map[0]: size_y size_x'; "
                                   f"got {line[:60]!r}")
    raise FormatError(path, None, "no 'global_map[0]: size_y size_x' line: this is not a CMU/BeeSoft map")


def _checked_resolution(path: PathLike, header: dict[str, tuple[float, int]], size_x: int, size_y: int,
                        size_line: int) -> float:
    """The resolution (cm per cell), checked with the map sizes the header states; autoshifts warned about."""
    res_cm = header.get("resolution", (10.0, 0))[0]
    if res_cm <= 0:
        raise FormatError(path, header["resolution"][1], f"resolution must be positive (cm per cell); got {res_cm:g}")
    for axis, size in (("x", size_x), ("y", size_y)):
        key = f"global_mapsize_{axis}"
        if key in header:
            cm, ln = header[key]
            if abs(cm / res_cm - size) > 0.5:
                raise FormatError(
                    path, ln,
                    f"{key} {cm:g} cm at resolution {res_cm:g} cm means {cm / res_cm:g} cells along {axis}, "
                    f"but line {size_line} ('global_map[0]: {size_y} {size_x}' = size_y size_x) declares {size}")
    for key in ("autoshifted_x", "autoshifted_y"):
        if key in header and header[key][0] != 0:
            warnings.warn(f"{path}:{header[key][1]}: {key} = {header[key][0]:g} is ignored (the map origin is "
                          "placed at (0, 0) as in the course's loader)", ParseWarning, stacklevel=3)
    return res_cm


def _cmu_rows(path: PathLike, lines, size_x: int, size_y: int, size_line: int) -> list[NDArray[np.float64]]:
    """The ``size_x`` lines of ``size_y`` probabilities of free space (-1 unknown) after the header."""
    rows: list[NDArray[np.float64]] = []
    for n, raw in lines:
        line = raw.strip()
        if not line:
            continue
        if len(rows) == size_x:
            raise FormatError(path, n, f"extra data: the header (line {size_line}) declares {size_x} lines of "
                                       f"values, this is line {len(rows) + 1} of them")
        tokens = line.split()
        if len(tokens) != size_y:
            raise FormatError(path, n, f"expected {size_y} values (one per y cell, from line {size_line}); "
                                       f"got {len(tokens)}")
        vals = parse_floats(tokens, path, n, f"map line for x = {len(rows)}")
        bad_vals = ((vals < 0.0) | (vals > 1.0)) & (vals != -1.0)
        if np.any(bad_vals):
            k = int(np.flatnonzero(bad_vals)[0])
            raise FormatError(path, n, f"value {k + 1} is {tokens[k]}, expected a probability of free space in "
                                       "[0, 1] or -1 for unknown")
        rows.append(vals)
    if len(rows) != size_x:
        raise FormatError(path, None, f"the header (line {size_line}) declares {size_x} lines of values "
                                      f"(one per x cell); the file ends after {len(rows)}")
    return rows


def write_cmu_map(path: PathLike, grid: OccupancyGrid, decimals: int = 6) -> Path:
    """Write an :class:`~localize.OccupancyGrid` as a CMU 16-831 (BeeSoft) map.

    The inverse of :func:`read_cmu_map`: P(free) = 1 - occupancy, -1 for
    unknown, one text line per x cell. The origin is not stored by the format
    (it must be ``(0, 0)``); the resolution must be a whole number of cm.

    Examples
    --------
    >>> g = OccupancyGrid(np.array([[0.0, 1.0, np.nan]]), 0.1)
    >>> p = write_cmu_map(tmp_dir() / "m.dat", g)
    >>> print(p.read_text())    # doctest: +NORMALIZE_WHITESPACE
    robot_specifications->global_mapsize_x  30
    robot_specifications->global_mapsize_y  10
    robot_specifications->resolution 10
    robot_specifications->autoshifted_x 0
    robot_specifications->autoshifted_y 0
    <BLANKLINE>
    global_map[0]: 1 3
    1
    0
    -1
    >>> np.array_equal(read_cmu_map(p).data, g.data, equal_nan=True)
    True
    """
    check_grid(grid)
    if np.any(np.abs(grid.origin) > 1e-9):
        raise ValueError(f"the CMU map format has no origin: grid.origin must be (0, 0); got {tuple(grid.origin)}")
    res_cm = grid.resolution * 100.0
    if abs(res_cm - round(res_cm)) > 1e-6:
        raise ValueError(f"the CMU map format stores the resolution in whole cm; got {res_cm:g} cm")
    res_cm = int(round(res_cm))
    h, w = grid.shape
    p_free = np.where(np.isnan(grid.data), -1.0, np.round(1.0 - grid.data, decimals)).T  # [x, y]
    out = Path(path)
    with open(out, "w") as f:
        f.write(f"{_HEADER_PREFIX}global_mapsize_x  {w * res_cm}\n")
        f.write(f"{_HEADER_PREFIX}global_mapsize_y  {h * res_cm}\n")
        f.write(f"{_HEADER_PREFIX}resolution {res_cm}\n")
        f.write(f"{_HEADER_PREFIX}autoshifted_x 0\n{_HEADER_PREFIX}autoshifted_y 0\n\n")
        f.write(f"global_map[0]: {h} {w}\n")
        for col in p_free:
            f.write(" ".join(f"{v:g}" for v in col) + "\n")
    return out


def read_cmu_log(
    path: PathLike,
    sensor_offset: tuple[float, float, float] | None = None,
    max_range: float = CMU_MAX_RANGE,
    on_error: str = "raise",
) -> LaserLog:
    """Read a CMU 16-831 robot log (``robotdata1.log``) into a :class:`LaserLog` in SI units.

    Parameters
    ----------
    path : str or path-like
        The log (optionally gzip-compressed).
    sensor_offset : (dx, dy, dtheta), optional
        Pose of the laser in the robot frame, metres and radians. By default it
        is measured from the file: the median of the laser poses seen from the
        robot poses of the ``L`` records (25 cm ahead on the course's robot).
    max_range : float
        Readings at or above it (metres) mean "no return"; 80 m (8000 cm).
    on_error : {"raise", "skip"}
        A malformed record (wrong number of fields, non-numeric, NaN, negative
        range) raises :class:`FormatError` (``file:line: what was expected``) by
        default; with ``"skip"`` it is skipped and counted in one
        :class:`ParseWarning` and in ``log.skipped``. Unknown record types are
        always rejected: the format has only ``O`` and ``L`` (and we allow
        ``#`` comment lines and blank lines).

    Returns
    -------
    LaserLog
        ``odometry`` is the robot pose of each ``L`` record (metres),
        ``odom_times``/``odom_poses`` the ``O`` records, ``poses`` is None (the
        course's logs have no ground truth), angles are :data:`CMU_ANGLES`.

    Examples
    --------
    >>> scan = " ".join(["150"] * 179 + ["8183"])
    >>> p = tmp_text("robot.log", f"O 100 200 0.5 0.01\\nL 100 200 0 125 200 0 {scan} 0.02\\n")
    >>> log = read_cmu_log(p)
    >>> log
    LaserLog('cmu', scans=1, beams=180 [-90.0..89.0 deg], duration=0.0 s, max_range=80 m, reference poses=no)
    >>> log.odometry[0], log.sensor_offset.round(3), log.ranges[0, :2], log.no_return.sum()
    (array([1., 2., 0.]), array([0.25, 0.  , 0.  ]), array([1.5, 1.5]), np.int64(1))
    """
    if on_error not in ("raise", "skip"):
        raise ValueError(f"on_error must be 'raise' or 'skip'; got {on_error!r}")
    n_beams = CMU_ANGLES.size
    n_l = 1 + 6 + n_beams + 1
    skips = SkipCounter(path)
    odo_t: list[float] = []
    odo_p: list[NDArray] = []
    scan_t: list[float] = []
    scan_lines: list[int] = []
    robot: list[NDArray] = []
    laser: list[NDArray] = []
    ranges: list[NDArray] = []

    def bad(n: int, msg: str) -> None:
        skips.malformed(n, msg, on_error)

    for n, tokens in read_records(path):
        kind = tokens[0]
        if kind == "O":
            if len(tokens) != 5:
                bad(n, f"an odometry record is 'O x y theta ts' (5 fields); got {len(tokens)}")
                continue
            v = skips.floats(tokens[1:], n, "odometry record 'O x y theta ts'", on_error)
            if v is None:
                continue
            odo_t.append(v[3])
            odo_p.append(np.array([v[0] / 100.0, v[1] / 100.0, v[2]]))
        elif kind == "L":
            if len(tokens) != n_l:
                bad(n, f"a laser record is 'L x y theta xl yl thetal r1 ... r{n_beams} ts' ({n_l} fields); "
                       f"got {len(tokens)}")
                continue
            v = skips.floats(tokens[1:], n, "laser record 'L x y theta xl yl thetal r1..r180 ts'", on_error)
            if v is None:
                continue
            r = v[6:6 + n_beams]
            if np.any(r < 0):
                k = int(np.flatnonzero(r < 0)[0])
                bad(n, f"range r{k + 1} is {tokens[7 + k]}, expected a distance >= 0 cm")
                continue
            scan_t.append(v[-1])
            scan_lines.append(n)
            robot.append(np.array([v[0] / 100.0, v[1] / 100.0, v[2]]))
            laser.append(np.array([v[3] / 100.0, v[4] / 100.0, v[5]]))
            ranges.append(r / 100.0)
        else:
            raise FormatError(path, n, f"unknown record type {kind[:20]!r}: a CMU 16-831 log has only "
                                       "'O x y theta ts' and 'L x y theta xl yl thetal r1..r180 ts' records")
    if not scan_t:
        raise FormatError(path, None, "no laser records ('L ...'): nothing to localize with")
    skips.warn()
    robot_a, laser_a = np.array(robot), np.array(laser)
    meta: dict = {"units": "converted from cm to m", "records": {"O": len(odo_t), "L": len(scan_t)},
                  "scan_lines": np.array(scan_lines)}
    if sensor_offset is None:
        off, spread = median_offset(robot_a, laser_a)
        meta["sensor_offset_source"] = f"median of laser poses seen from robot poses (max deviation {spread:.3f} m)"
    else:
        off = np.asarray(sensor_offset, dtype=float)
        meta["sensor_offset_source"] = "given"
    return LaserLog(
        times=np.array(scan_t), odometry=robot_a, ranges=np.array(ranges), angles=CMU_ANGLES.copy(),
        max_range=float(max_range), sensor_offset=off, poses=None,
        odom_times=np.array(odo_t).reshape(-1), odom_poses=np.array(odo_p).reshape(-1, 3),
        source=str(path), format="cmu", skipped=skips.as_dict(), meta=meta,
    )


def write_cmu_log(path: PathLike, log: LaserLog, decimals: int = 3, angle_decimals: int = 6) -> Path:
    """Write a :class:`LaserLog` as a CMU 16-831 log (cm, 180 beams from -90 degrees).

    The format (one record per line, centimetres, radians, seconds)::

        O x y theta ts
        L x y theta xl yl thetal r1 ... r180 ts

    ``x y theta`` is the odometry pose of the robot centre, ``xl yl thetal``
    the laser's pose in the same frame (``sensor_offset`` ahead). ``O``
    records are written for the log's odometry records, interleaved with the
    ``L`` records by time (an ``O`` record first at equal times); readings at
    or above ``max_range`` are written as 8183 cm (:data:`CMU_NO_RETURN_CM`),
    other ranges rounded to whole cm, positions to ``decimals`` digits of a
    cm, angles to ``angle_decimals`` digits of a radian. The log must have the
    CMU beam layout (:data:`CMU_ANGLES`) and a ``max_range`` below 81.83 m. A
    simulated run is written through :meth:`localize.sim.RangeRun.to_log`
    (or :func:`localize.sim.write_cmu_log`).

    Examples
    --------
    >>> log = LaserLog(times=[0.0, 0.1], odometry=[[1, 2, 0.1], [1.1, 2, 0.1]], ranges=np.full((2, 180), 3.0),
    ...                angles=CMU_ANGLES, max_range=80.0, sensor_offset=CMU_SENSOR_OFFSET)
    >>> p = write_cmu_log(tmp_dir() / "r.log", log)
    >>> back = read_cmu_log(p)
    >>> bool(np.allclose(back.odometry, log.odometry)), back.sensor_offset.round(3).tolist()
    (True, [0.25, 0.0, 0.0])
    """
    if not isinstance(log, LaserLog):
        raise TypeError(f"log must be a LaserLog; got {type(log).__name__}")
    if log.n_beams != CMU_ANGLES.size or not np.allclose(log.angles, CMU_ANGLES, atol=1e-9):
        raise ValueError("the CMU format stores 180 beams at -90..+89 degrees; select or resample the beams first "
                         "(a simulation: range_run(..., angles=CMU_ANGLES), its default)")
    if log.max_range * 100.0 >= CMU_NO_RETURN_CM:
        raise ValueError(f"max_range must be below {CMU_NO_RETURN_CM / 100} m to be written (a CMU log writes "
                         f"{CMU_NO_RETURN_CM} cm for no return); got {log.max_range}")
    laser = compose(log.odometry, log.sensor_offset)
    records: list[tuple[float, int, str]] = []
    fmt = f"{{:.{int(decimals)}f}}"
    afmt = f"{{:.{int(angle_decimals)}f}}"

    def pose(p: NDArray) -> str:
        return f"{fmt.format(p[0] * 100)} {fmt.format(p[1] * 100)} {afmt.format(p[2])}"

    for k in range(len(log)):
        # whole cm; a reading just below max_range must not round up to "no return"
        below = np.minimum(np.round(log.ranges[k] * 100.0), np.ceil(log.max_range * 100.0) - 1.0)
        r = np.where(log.ranges[k] >= log.max_range, float(CMU_NO_RETURN_CM), below)
        txt = f"L {pose(log.odometry[k])} {pose(laser[k])} " + " ".join(f"{v:.0f}" for v in r)
        records.append((float(log.times[k]), 1, txt + f" {log.times[k]:.6f}"))
    for t, p in zip(log.odom_times, log.odom_poses):
        records.append((float(t), 0, f"O {pose(p)} {t:.6f}"))
    records.sort(key=lambda r: (r[0], r[1]))
    out = Path(path)
    with open(out, "w") as f:
        for _, _, txt in records:
            f.write(txt + "\n")
    return out
