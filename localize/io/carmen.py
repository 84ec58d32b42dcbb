"""CARMEN log files (``*.log``, optionally gzip-compressed): laser scans and odometry.

One record per line, metres and radians; the records read here are::

    FLASER n r1 ... rn x y theta odom_x odom_y odom_theta timestamp host logger_timestamp
    ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode
                n r1 ... rn m rem1 ... remm laser_x laser_y laser_theta robot_x robot_y robot_theta
                tv rv forward_safety side_safety turn_axis timestamp host logger_timestamp
    ODOM x y theta tv rv accel timestamp host logger_timestamp
    PARAM name value [timestamp host logger_timestamp]
    NEFF value [timestamp host logger_timestamp]   (effective sample size written by GMapping after a scan)
    # comment

Lines of every other kind (``RLASER``, ``RAWLASER1``, ``TRUEPOS``, ``SYNC`` ...) are
skipped and counted in one :class:`ParseWarning`. ``FLASER`` beams cover 180
degrees counter-clockwise from -90 degrees (the robot's right): 180 or 360
readings mean 1 or 0.5 degree steps ending one step short of +90, 181 or 361
readings include +90.

**Corrected logs.** In the SLAM-corrected logs of the Radish archive (as
produced by GMapping) both pose triples of ``FLASER`` hold the corrected pose,
and after every scan the odometry chain is re-anchored: an ``ODOM`` record
equal to the corrected pose follows, then raw odometry increments accumulate.
:func:`read_carmen_log` detects this and rebuilds a consistent odometry chain
from the real increments (the last ``ODOM`` before scan ``k+1`` seen from the
anchor of scan ``k``), and returns the corrected poses as ``log.poses``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..geometry import as_poses, compose, relative, wrap_angle
from ._common import FormatError, LaserLog, SkipCounter, median_offset, parse_floats, read_records

__all__ = ["read_carmen_log", "write_carmen_log", "carmen_angles", "KNOWN_SKIPPED"]

PathLike = str | os.PathLike

#: Record types of the CARMEN logger that this reader skips on purpose.
KNOWN_SKIPPED = frozenset({
    "RLASER", "LASER3", "LASER4", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4",
    "ROBOTLASER0", "ROBOTLASER2", "TRUEPOS", "SYNC", "SONAR", "BUMPER", "SCANMARK", "POSITIONLASER",
    "GPSNMEA", "GPSNMEAGGA", "GPSNMEARMC", "IMU", "VECTORMOVE", "ROBOTVELOCITY", "FOLLOWTRAJECTORY",
    "BASEVELOCITY", "ARMSTATE", "PANTILT", "COMMENT",
})
_KEYWORD = re.compile(r"^[A-Z][A-Z0-9_]*$")


def carmen_angles(n: int) -> NDArray[np.float64]:
    """Beam angles (radians) of a 180-degree ``FLASER`` scan with ``n`` readings.

    Examples
    --------
    >>> np.degrees(carmen_angles(180)[[0, 1, -1]]).round(3)
    array([-90., -89.,  89.])
    >>> np.degrees(carmen_angles(361)[[0, 1, -1]]).round(3)
    array([-90. , -89.5,  90. ])
    """
    n = int(n)
    if n < 2:
        raise ValueError(f"a scan needs at least 2 readings; got {n}")
    step = np.pi / (n - 1) if n % 2 == 1 else np.pi / n
    return -np.pi / 2 + step * np.arange(n)


def read_carmen_log(
    path: PathLike,
    max_range: float | None = None,
    laser: str = "auto",
    on_error: str = "raise",
    reanchored: bool | None = None,
) -> LaserLog:
    """Read a CARMEN log into a :class:`LaserLog` (metres, radians).

    Parameters
    ----------
    path : str or path-like
        The log; gzip compression is recognised from the content.
    max_range : float, optional
        Readings at or above it mean "no return". By default: the PARAM
        ``robot_front_laser_max`` if present, else the largest reading when it
        repeats (a saturation value such as 81.83 m or 50 m), else 81.83 m.
    laser : {"auto", "FLASER", "ROBOTLASER1"}
        Which scan records to use ("auto": FLASER if the log has any, else
        ROBOTLASER1); the other kind is skipped and counted.
    on_error : {"raise", "skip"}
        A malformed record of a kind this reader uses (wrong number of fields,
        non-numeric, NaN, negative range, a scan with a different beam count)
        raises :class:`FormatError` with ``file:line``; with ``"skip"`` it is
        skipped and counted in one :class:`ParseWarning` and ``log.skipped``.
    reanchored : bool, optional
        Force (or forbid) the corrected-log odometry reconstruction described in
        the module docstring; by default it is detected.

    Returns
    -------
    LaserLog
        ``poses`` holds the corrected robot poses when both pose triples of
        every scan agree (corrected logs), else None; ``meta["neff"]`` the
        NEFF values per scan (NaN where absent); ``params`` the PARAM values.

    Examples
    --------
    >>> p = tmp_text("tiny.log", '''# message formats defined: PARAM ODOM FLASER
    ... PARAM robot_front_laser_max 81.9 nohost 0
    ... ODOM 0 0 0 0 0 0 0.0 host 0.0
    ... FLASER 4 1 2 3 81.9 0 0 0 0 0 0 0.1 host 0.1
    ... RAWLASER1 ignored by this reader
    ... ODOM 0.5 0 0 0 0 0 0.2 host 0.2
    ... FLASER 4 1 2 3 81.9 0.5 0 0 0.5 0 0 0.3 host 0.3
    ... ''')
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     log = read_carmen_log(p)
    >>> print(w[0].message)
    /...tiny.log: skipped 1 RAWLASER1 records (not used) (first at line 5)
    >>> len(log), log.n_beams, log.max_range, log.motions().round(3).tolist()
    (2, 4, 81.9, [[0.5, 0.0, 0.0]])
    """
    if on_error not in ("raise", "skip"):
        raise ValueError(f"on_error must be 'raise' or 'skip'; got {on_error!r}")
    if laser not in ("auto", "FLASER", "ROBOTLASER1"):
        raise ValueError(f"laser must be 'auto', 'FLASER' or 'ROBOTLASER1'; got {laser!r}")
    skips = SkipCounter(path)
    params: dict[str, str] = {}
    # per kind of scan: lists of (line, t, ranges, laser pose, robot pose, angles, max_range)
    scans: dict[str, list] = {"FLASER": [], "ROBOTLASER1": []}
    odom: list[tuple[int, float, NDArray]] = []  # (record index, t, pose)
    neff: list[tuple[int, float]] = []  # (record index, value)
    record = 0  # order of the records we keep (scans, ODOM, NEFF)
    beams: dict[str, tuple[int, int]] = {}  # kind -> (n, first line)

    def bad(n: int, msg: str) -> None:
        skips.malformed(n, msg, on_error)

    for n, tokens in read_records(path):
        kind = tokens[0]
        if kind == "FLASER":
            try:
                nb = int(tokens[1]) if len(tokens) > 1 else -1
            except ValueError:
                bad(n, f"FLASER field 2 is the number of readings; got {tokens[1]!r}")
                continue
            if nb < 2:
                bad(n, f"FLASER needs a reading count >= 2 in field 2; got {tokens[1] if len(tokens) > 1 else 'nothing'}")
                continue
            if len(tokens) not in (nb + 9, nb + 11):
                bad(n, f"FLASER with {nb} readings has {nb + 11} fields (FLASER n r1..r{nb} x y theta "
                       f"odom_x odom_y odom_theta timestamp host logger_timestamp); got {len(tokens)}")
                continue
            if "FLASER" in beams and beams["FLASER"][0] != nb:
                bad(n, f"expected {beams['FLASER'][0]} readings like the first FLASER (line {beams['FLASER'][1]}); "
                       f"got {nb}")
                continue
            v = skips.floats(tokens[2:nb + 9], n, "FLASER", on_error)
            if v is None:
                continue
            r = v[:nb]
            if np.any(r < 0):
                bad(n, f"FLASER reading {int(np.flatnonzero(r < 0)[0]) + 1} is negative; expected a range >= 0 m")
                continue
            beams.setdefault("FLASER", (nb, n))
            scans["FLASER"].append((n, record, v[nb + 6], r, v[nb:nb + 3], v[nb + 3:nb + 6], None, None))
            record += 1
        elif kind == "ROBOTLASER1":
            parsed = _parse_robotlaser(tokens, path, n)
            if isinstance(parsed, str):
                bad(n, parsed)
                continue
            nb = parsed[0].size
            if "ROBOTLASER1" in beams and beams["ROBOTLASER1"][0] != nb:
                bad(n, f"expected {beams['ROBOTLASER1'][0]} readings like the first ROBOTLASER1 "
                       f"(line {beams['ROBOTLASER1'][1]}); got {nb}")
                continue
            beams.setdefault("ROBOTLASER1", (nb, n))
            r, lp, rp, t, ang, mr = parsed
            scans["ROBOTLASER1"].append((n, record, t, r, lp, rp, ang, mr))
            record += 1
        elif kind == "ODOM":
            if len(tokens) < 8:
                bad(n, f"ODOM is 'ODOM x y theta tv rv accel timestamp host logger_timestamp' (10 fields); "
                       f"got {len(tokens)}")
                continue
            if len(tokens) not in (8, 10):
                bad(n, f"ODOM has 10 fields (ODOM x y theta tv rv accel timestamp host logger_timestamp); "
                       f"got {len(tokens)}")
                continue
            v = skips.floats(tokens[1:8], n, "ODOM", on_error)
            if v is None:
                continue
            odom.append((record, v[6], v[:3]))
            record += 1
        elif kind == "PARAM":
            if len(tokens) < 3:
                bad(n, f"PARAM is 'PARAM name value ...'; got {len(tokens)} field(s)")
                continue
            params[tokens[1]] = tokens[2]
        elif kind == "NEFF":
            if len(tokens) not in (2, 5):
                bad(n, f"NEFF is 'NEFF value [timestamp host logger_timestamp]' (2 or 5 fields); got {len(tokens)}")
                continue
            v = skips.floats(tokens[1:2], n, "NEFF", on_error)
            if v is None:
                continue
            neff.append((record, float(v[0])))
        elif _KEYWORD.match(kind):
            if kind in KNOWN_SKIPPED:
                skips.add(f"{kind} records (not used)", n)
            else:
                skips.add(f"{kind} records (unknown record type)", n)
        else:
            raise FormatError(path, n, f"expected a CARMEN record type such as FLASER, ROBOTLASER1, ODOM or "
                                       f"PARAM at the start of the line; got {kind[:30]!r}")

    use = laser
    if use == "auto":
        use = "FLASER" if scans["FLASER"] else "ROBOTLASER1"
    other = "ROBOTLASER1" if use == "FLASER" else "FLASER"
    for n, *_ in scans[other]:
        skips.add(f"{other} records (not used: reading {use})", n)
    chosen = scans[use]
    if not chosen:
        what = "FLASER or ROBOTLASER1" if laser == "auto" else use
        seen = "; ".join(f"{n} {k}" for k, n in skips.counts.items())
        raise FormatError(path, None, f"no {what} scan records: nothing to localize with"
                          + (f" (skipped: {seen})" if seen else "")
                          + (" -- is this a CARMEN log?" if not odom and not params else ""))
    skips.warn()

    lines = np.array([c[0] for c in chosen])
    rec = np.array([c[1] for c in chosen])
    times = np.array([c[2] for c in chosen])
    ranges = np.array([c[3] for c in chosen])
    laser_pose = np.array([c[4] for c in chosen])
    robot_pose = np.array([c[5] for c in chosen])
    meta: dict = {"scan_records": use, "first_scan_line": int(lines[0])}

    # ---- beam angles and maximum range
    if use == "FLASER":
        angles = carmen_angles(ranges.shape[1])
        file_max = None
    else:
        angles = chosen[0][6]
        file_max = float(np.median([c[7] for c in chosen]))
    if max_range is not None:
        mr, src = float(max_range), "given"
    elif file_max is not None and file_max > 0:
        mr, src = file_max, "ROBOTLASER1 maximum_range field"
    elif "robot_front_laser_max" in params and _is_float(params["robot_front_laser_max"]):
        mr, src = float(params["robot_front_laser_max"]), "PARAM robot_front_laser_max"
    else:
        top = float(ranges.max())
        count = int(np.count_nonzero(ranges == top))
        if count >= max(2, int(0.001 * ranges.size)):
            mr, src = top, f"largest reading, repeated {count} times (saturation)"
        else:
            mr, src = max(81.83, top + 0.01), "default 81.83 m (SICK LMS; no saturation value found)"
    meta["max_range_source"] = src

    # ---- sensor offset and reference poses
    same = np.allclose(laser_pose, robot_pose, atol=1e-6)
    off, spread = median_offset(robot_pose, laser_pose)
    if spread < 0.01:
        meta["sensor_offset_source"] = "laser poses seen from robot poses"
    else:
        off = np.zeros(3)
        fo = params.get("robot_frontlaser_offset")
        if fo is not None and _is_float(fo):
            off[0] = float(fo)
        meta["sensor_offset_source"] = ("PARAM robot_frontlaser_offset (laser and robot poses are not rigidly "
                                        f"related: spread {spread:.2f} m)")
    poses = robot_pose.copy() if same else None
    meta["poses"] = "corrected (both pose triples agree)" if same else "none (pose triples differ: raw log)"

    # ---- odometry
    odom_rec = np.array([o[0] for o in odom], dtype=int)
    odom_t = np.array([o[1] for o in odom], dtype=float)
    odom_p = np.array([o[2] for o in odom], dtype=float).reshape(-1, 3)
    anchor_idx = np.searchsorted(odom_rec, rec + 1)  # first ODOM after each scan
    has_next = anchor_idx < len(odom_rec)
    if reanchored is None:
        if same and has_next[:-1].any():
            idx = anchor_idx[:-1][has_next[:-1]]
            d = odom_p[idx] - robot_pose[:-1][has_next[:-1]]
            d[:, 2] = wrap_angle(d[:, 2])
            ok = np.all(np.abs(d) < 1e-4, axis=1)
            reanchored = bool(ok.mean() >= 0.9)
        else:
            reanchored = False
    if reanchored:
        odometry = _reanchored_chain(robot_pose, rec, odom_rec, odom_p, anchor_idx)
        meta["odometry"] = ("re-anchored ODOM chain: last ODOM before each scan seen from the ODOM anchor after "
                            "the previous scan, accumulated from the first corrected pose")
    else:
        odometry = robot_pose.copy()
        meta["odometry"] = "FLASER odometry triple" if use == "FLASER" else "ROBOTLASER1 robot pose"

    nf = np.full(len(chosen), np.nan)
    if neff:
        nrec = np.array([r for r, _ in neff])
        nval = np.array([v for _, v in neff])
        k = np.searchsorted(rec, nrec, side="right") - 1  # the scan each NEFF follows
        ok = k >= 0
        nf[k[ok]] = nval[ok]
    meta["neff"] = nf
    meta["scan_lines"] = lines
    dt = np.diff(times)
    meta["timestamps_monotonic"] = bool(np.all(dt >= 0))
    meta["timestamps_distinct"] = float(np.unique(times).size / times.size)
    return LaserLog(
        times=times, odometry=odometry, ranges=ranges, angles=angles, max_range=mr, sensor_offset=off,
        poses=poses, odom_times=odom_t, odom_poses=odom_p, source=str(path), format="carmen",
        params=params, skipped=skips.as_dict(), meta=meta,
    )


def _is_float(s: str) -> bool:
    try:
        return bool(np.isfinite(float(s)))
    except ValueError:
        return False


def _reanchored_chain(corrected, scan_rec, odom_rec, odom_p, anchor_idx) -> NDArray[np.float64]:
    """Odometry chain of a re-anchored corrected log (see the module docstring)."""
    k_scans = len(corrected)
    out = np.empty((k_scans, 3))
    out[0] = corrected[0]
    for k in range(k_scans - 1):
        # anchor after scan k (or the corrected pose itself), last ODOM before scan k+1
        a = anchor_idx[k]
        last = np.searchsorted(odom_rec, scan_rec[k + 1]) - 1
        if a < len(odom_rec) and odom_rec[a] < scan_rec[k + 1] and last >= a:
            step = relative(odom_p[a], odom_p[last])
        else:
            step = np.zeros(3)
        out[k + 1] = compose(out[k], step)
    return out


def _parse_robotlaser(tokens: list[str], path, n: int):
    """Parse one ROBOTLASER1 line; return a message string when malformed."""
    head = "ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode n ranges m remissions " \
           "laser_pose robot_pose tv rv forward_safety side_safety turn_axis timestamp host logger_timestamp"
    if len(tokens) < 9:
        return f"a ROBOTLASER1 record is '{head}'; got only {len(tokens)} fields"
    try:
        nb = int(tokens[8])
    except ValueError:
        return f"ROBOTLASER1 field 9 is the number of readings; got {tokens[8]!r}"
    if nb < 2 or len(tokens) < 9 + nb + 1:
        return f"ROBOTLASER1 with {nb} readings is truncated ({len(tokens)} fields)"
    try:
        nrem = int(tokens[9 + nb])
    except ValueError:
        return f"ROBOTLASER1 field {10 + nb} is the number of remission values; got {tokens[9 + nb]!r}"
    expected = 9 + nb + 1 + nrem + 12 + 2
    if nrem < 0 or len(tokens) != expected:
        return (f"ROBOTLASER1 with {nb} readings and {nrem} remission values has {expected} fields ({head}); "
                f"got {len(tokens)}")
    try:
        hdr = parse_floats(tokens[2:7], path, n, "ROBOTLASER1 header")
        r = parse_floats(tokens[9:9 + nb], path, n, "ROBOTLASER1 ranges")
        tail = parse_floats(tokens[10 + nb + nrem:10 + nb + nrem + 12], path, n, "ROBOTLASER1 poses")
    except FormatError as e:
        return e.reason
    if np.any(r < 0):
        return f"ROBOTLASER1 reading {int(np.flatnonzero(r < 0)[0]) + 1} is negative; expected a range >= 0 m"
    start, _fov, res, mr = hdr[0], hdr[1], hdr[2], hdr[3]
    if res <= 0:
        return f"ROBOTLASER1 angular resolution must be positive; got {tokens[4]}"
    angles = start + res * np.arange(nb)
    return r, tail[0:3], tail[3:6], float(tail[11]), angles, float(mr)


def write_carmen_log(path: PathLike, log: LaserLog, host: str = "localize") -> Path:
    """Write a :class:`LaserLog` as a CARMEN log of ``ODOM`` and ``FLASER`` records.

    Both ``FLASER`` pose triples hold the odometry pose (the laser pose is
    odometry composed with ``sensor_offset``); a ``PARAM robot_front_laser_max``
    line records ``max_range``. The beams must follow the FLASER layout of
    :func:`carmen_angles`. A path ending in ``.gz`` is gzip-compressed.

    Examples
    --------
    >>> log = LaserLog(times=[0.0, 0.2], odometry=[[0, 0, 0], [0.3, 0.1, 0.2]], ranges=np.ones((2, 180)),
    ...                angles=carmen_angles(180), max_range=81.83)
    >>> p = write_carmen_log(tmp_dir() / "r.log.gz", log)
    >>> back = read_carmen_log(p)
    >>> bool(np.allclose(back.odometry, log.odometry)), back.max_range
    (True, 81.83)
    """
    import gzip

    if not isinstance(log, LaserLog):
        raise TypeError(f"log must be a LaserLog; got {type(log).__name__}")
    if not np.allclose(log.angles, carmen_angles(log.n_beams), atol=1e-9):
        raise ValueError("FLASER beams cover -90..+90 degrees evenly (see carmen_angles); "
                         "this log's angles do not")
    laser = compose(as_poses(log.odometry), log.sensor_offset)
    out = Path(path)
    opener = gzip.open if out.suffix == ".gz" else open
    with opener(out, "wt") as f:
        f.write("# message formats defined: PARAM ODOM FLASER\n")
        f.write(f"PARAM robot_front_laser_max {log.max_range:g} {host} 0\n")
        f.write(f"PARAM robot_frontlaser_offset {log.sensor_offset[0]:g} {host} 0\n")
        for k in range(len(log)):
            t = float(log.times[k])
            o = log.odometry[k]
            f.write(f"ODOM {o[0]:.6f} {o[1]:.6f} {o[2]:.6f} 0 0 0 {t:.6f} {host} {t:.6f}\n")
            r = " ".join(f"{v:.3f}" for v in np.minimum(log.ranges[k], log.max_range))
            lp = laser[k]
            f.write(f"FLASER {log.n_beams} {r} {lp[0]:.6f} {lp[1]:.6f} {lp[2]:.6f} "
                    f"{o[0]:.6f} {o[1]:.6f} {o[2]:.6f} {t:.6f} {host} {t:.6f}\n")
    return out
