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
from dataclasses import dataclass, field
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


@dataclass
class _Records:
    """What one pass over a CARMEN log keeps: scans of each kind, ODOM, NEFF and PARAM records, in file order."""

    path: PathLike
    on_error: str
    skips: SkipCounter
    params: dict[str, str] = field(default_factory=dict)
    # per kind of scan: (line, record, t, ranges, laser pose, robot pose, angles, max_range)
    scans: dict[str, list] = field(default_factory=lambda: {"FLASER": [], "ROBOTLASER1": []})
    odom: list[tuple[int, float, NDArray]] = field(default_factory=list)  # (record index, t, pose)
    neff: list[tuple[int, float]] = field(default_factory=list)  # (record index, value)
    record: int = 0  # order of the records kept (scans, ODOM, NEFF)
    beams: dict[str, tuple[int, int]] = field(default_factory=dict)  # kind -> (n, first line)

    def bad(self, n: int, msg: str) -> None:
        self.skips.malformed(n, msg, self.on_error)

    def same_beams(self, kind: str, n: int, nb: int) -> bool:
        """True if a scan of ``nb`` readings matches the first of its kind (else it is reported)."""
        if kind in self.beams and self.beams[kind][0] != nb:
            self.bad(n, f"expected {self.beams[kind][0]} readings like the first {kind} (line {self.beams[kind][1]}); "
                        f"got {nb}")
            return False
        return True

    def keep_scan(self, kind: str, n: int, item: tuple) -> None:
        self.beams.setdefault(kind, (item[1].size, n))
        t, r, lp, rp, ang, mr = item
        self.scans[kind].append((n, self.record, t, r, lp, rp, ang, mr))
        self.record += 1


def _flaser_count(rec: _Records, n: int, tokens: list[str]) -> int | None:
    """The reading count of a FLASER record, checked against its length (None: reported)."""
    try:
        nb = int(tokens[1]) if len(tokens) > 1 else -1
    except ValueError:
        rec.bad(n, f"FLASER field 2 is the number of readings; got {tokens[1]!r}")
        return None
    if nb < 2:
        rec.bad(n, f"FLASER needs a reading count >= 2 in field 2; got {tokens[1] if len(tokens) > 1 else 'nothing'}")
        return None
    if len(tokens) not in (nb + 9, nb + 11):
        rec.bad(n, f"FLASER with {nb} readings has {nb + 11} fields (FLASER n r1..r{nb} x y theta "
                   f"odom_x odom_y odom_theta timestamp host logger_timestamp); got {len(tokens)}")
        return None
    return nb


def _take_flaser(rec: _Records, n: int, tokens: list[str]) -> None:
    nb = _flaser_count(rec, n, tokens)
    if nb is None or not rec.same_beams("FLASER", n, nb):
        return
    v = rec.skips.floats(tokens[2:nb + 9], n, "FLASER", rec.on_error)
    if v is None:
        return
    r = v[:nb]
    if np.any(r < 0):
        rec.bad(n, f"FLASER reading {int(np.flatnonzero(r < 0)[0]) + 1} is negative; expected a range >= 0 m")
        return
    rec.keep_scan("FLASER", n, (v[nb + 6], r, v[nb:nb + 3], v[nb + 3:nb + 6], None, None))


def _take_robotlaser(rec: _Records, n: int, tokens: list[str]) -> None:
    parsed = _parse_robotlaser(tokens, rec.path, n)
    if isinstance(parsed, str):
        rec.bad(n, parsed)
        return
    if not rec.same_beams("ROBOTLASER1", n, parsed[0].size):
        return
    r, lp, rp, t, ang, mr = parsed
    rec.keep_scan("ROBOTLASER1", n, (t, r, lp, rp, ang, mr))


def _take_odom(rec: _Records, n: int, tokens: list[str]) -> None:
    if len(tokens) < 8:
        rec.bad(n, f"ODOM is 'ODOM x y theta tv rv accel timestamp host logger_timestamp' (10 fields); "
                   f"got {len(tokens)}")
        return
    if len(tokens) not in (8, 10):
        rec.bad(n, f"ODOM has 10 fields (ODOM x y theta tv rv accel timestamp host logger_timestamp); "
                   f"got {len(tokens)}")
        return
    v = rec.skips.floats(tokens[1:8], n, "ODOM", rec.on_error)
    if v is None:
        return
    rec.odom.append((rec.record, v[6], v[:3]))
    rec.record += 1


def _take_param(rec: _Records, n: int, tokens: list[str]) -> None:
    if len(tokens) < 3:
        rec.bad(n, f"PARAM is 'PARAM name value ...'; got {len(tokens)} field(s)")
        return
    rec.params[tokens[1]] = tokens[2]


def _take_neff(rec: _Records, n: int, tokens: list[str]) -> None:
    if len(tokens) not in (2, 5):
        rec.bad(n, f"NEFF is 'NEFF value [timestamp host logger_timestamp]' (2 or 5 fields); got {len(tokens)}")
        return
    v = rec.skips.floats(tokens[1:2], n, "NEFF", rec.on_error)
    if v is None:
        return
    rec.neff.append((rec.record, float(v[0])))


_TAKE = {"FLASER": _take_flaser, "ROBOTLASER1": _take_robotlaser, "ODOM": _take_odom, "PARAM": _take_param,
         "NEFF": _take_neff}


def _read_records(path: PathLike, on_error: str) -> _Records:
    rec = _Records(path=path, on_error=on_error, skips=SkipCounter(path))
    for n, tokens in read_records(path):
        kind = tokens[0]
        take = _TAKE.get(kind)
        if take is not None:
            take(rec, n, tokens)
        elif _KEYWORD.match(kind):
            rec.skips.add(f"{kind} records ({'not used' if kind in KNOWN_SKIPPED else 'unknown record type'})", n)
        else:
            raise FormatError(path, n, f"expected a CARMEN record type such as FLASER, ROBOTLASER1, ODOM or "
                                       f"PARAM at the start of the line; got {kind[:30]!r}")
    return rec


def _chosen_scans(rec: _Records, laser: str) -> tuple[str, list]:
    """The scan records to use (``laser``, or FLASER if any, else ROBOTLASER1); the others counted as skipped."""
    use = laser
    if use == "auto":
        use = "FLASER" if rec.scans["FLASER"] else "ROBOTLASER1"
    other = "ROBOTLASER1" if use == "FLASER" else "FLASER"
    for n, *_ in rec.scans[other]:
        rec.skips.add(f"{other} records (not used: reading {use})", n)
    chosen = rec.scans[use]
    if not chosen:
        what = "FLASER or ROBOTLASER1" if laser == "auto" else use
        seen = "; ".join(f"{n} {k}" for k, n in rec.skips.counts.items())
        raise FormatError(rec.path, None, f"no {what} scan records: nothing to localize with"
                          + (f" (skipped: {seen})" if seen else "")
                          + (" -- is this a CARMEN log?" if not rec.odom and not rec.params else ""))
    return use, chosen


def _max_range(max_range: float | None, file_max: float | None, params: dict[str, str], ranges: NDArray
               ) -> tuple[float, str]:
    """The maximum range and where it came from (given, the records, a PARAM, the saturation value, a default)."""
    if max_range is not None:
        return float(max_range), "given"
    if file_max is not None and file_max > 0:
        return file_max, "ROBOTLASER1 maximum_range field"
    if "robot_front_laser_max" in params and _is_float(params["robot_front_laser_max"]):
        return float(params["robot_front_laser_max"]), "PARAM robot_front_laser_max"
    top = float(ranges.max())
    count = int(np.count_nonzero(ranges == top))
    if count >= max(2, int(0.001 * ranges.size)):
        return top, f"largest reading, repeated {count} times (saturation)"
    return max(81.83, top + 0.01), "default 81.83 m (SICK LMS; no saturation value found)"


def _mounting(robot_pose: NDArray, laser_pose: NDArray, params: dict[str, str], meta: dict) -> NDArray:
    """The laser's mounting pose: from the two pose triples when they are rigidly related, else the PARAM."""
    off, spread = median_offset(robot_pose, laser_pose)
    if spread < 0.01:
        meta["sensor_offset_source"] = "laser poses seen from robot poses"
        return off
    off = np.zeros(3)
    fo = params.get("robot_frontlaser_offset")
    if fo is not None and _is_float(fo):
        off[0] = float(fo)
    meta["sensor_offset_source"] = ("PARAM robot_frontlaser_offset (laser and robot poses are not rigidly "
                                    f"related: spread {spread:.2f} m)")
    return off


def _odometry(rec: _Records, use: str, scan_rec: NDArray, robot_pose: NDArray, same: bool,
              reanchored: bool | None, meta: dict) -> tuple[NDArray, NDArray, NDArray]:
    """The odometry of each scan (re-anchored ODOM chain of corrected logs, or the scan's own pose triple)."""
    odom_rec = np.array([o[0] for o in rec.odom], dtype=int)
    odom_t = np.array([o[1] for o in rec.odom], dtype=float)
    odom_p = np.array([o[2] for o in rec.odom], dtype=float).reshape(-1, 3)
    anchor_idx = np.searchsorted(odom_rec, scan_rec + 1)  # first ODOM after each scan
    has_next = anchor_idx < len(odom_rec)
    if reanchored is None:
        reanchored = False
        if same and has_next[:-1].any():
            idx = anchor_idx[:-1][has_next[:-1]]
            d = odom_p[idx] - robot_pose[:-1][has_next[:-1]]
            d[:, 2] = wrap_angle(d[:, 2])
            reanchored = bool(np.all(np.abs(d) < 1e-4, axis=1).mean() >= 0.9)
    if reanchored:
        meta["odometry"] = ("re-anchored ODOM chain: last ODOM before each scan seen from the ODOM anchor after "
                            "the previous scan, accumulated from the first corrected pose")
        return _reanchored_chain(robot_pose, scan_rec, odom_rec, odom_p, anchor_idx), odom_t, odom_p
    meta["odometry"] = "FLASER odometry triple" if use == "FLASER" else "ROBOTLASER1 robot pose"
    return robot_pose.copy(), odom_t, odom_p


def _neff_per_scan(neff: list[tuple[int, float]], scan_rec: NDArray) -> NDArray[np.float64]:
    """The NEFF value that follows each scan (NaN where none does)."""
    nf = np.full(scan_rec.size, np.nan)
    if neff:
        nrec = np.array([r for r, _ in neff])
        nval = np.array([v for _, v in neff])
        k = np.searchsorted(scan_rec, nrec, side="right") - 1  # the scan each NEFF follows
        ok = k >= 0
        nf[k[ok]] = nval[ok]
    return nf


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
    rec = _read_records(path, on_error)
    use, chosen = _chosen_scans(rec, laser)
    rec.skips.warn()
    lines = np.array([c[0] for c in chosen])
    scan_rec = np.array([c[1] for c in chosen])
    times = np.array([c[2] for c in chosen])
    ranges = np.array([c[3] for c in chosen])
    laser_pose = np.array([c[4] for c in chosen])
    robot_pose = np.array([c[5] for c in chosen])
    meta: dict = {"scan_records": use, "first_scan_line": int(lines[0])}
    if use == "FLASER":
        angles, file_max = carmen_angles(ranges.shape[1]), None
    else:
        angles, file_max = chosen[0][6], float(np.median([c[7] for c in chosen]))
    mr, meta["max_range_source"] = _max_range(max_range, file_max, rec.params, ranges)
    same = np.allclose(laser_pose, robot_pose, atol=1e-6)
    off = _mounting(robot_pose, laser_pose, rec.params, meta)
    poses = robot_pose.copy() if same else None
    meta["poses"] = "corrected (both pose triples agree)" if same else "none (pose triples differ: raw log)"
    odometry, odom_t, odom_p = _odometry(rec, use, scan_rec, robot_pose, same, reanchored, meta)
    meta["neff"] = _neff_per_scan(rec.neff, scan_rec)
    meta["scan_lines"] = lines
    meta["timestamps_monotonic"] = bool(np.all(np.diff(times) >= 0))
    meta["timestamps_distinct"] = float(np.unique(times).size / times.size)
    return LaserLog(
        times=times, odometry=odometry, ranges=ranges, angles=angles, max_range=mr, sensor_offset=off,
        poses=poses, odom_times=odom_t, odom_poses=odom_p, source=str(path), format="carmen",
        params=rec.params, skipped=rec.skips.as_dict(), meta=meta,
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
