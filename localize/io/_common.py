"""Shared pieces of the readers: the :class:`LaserLog` container, errors, file opening."""

from __future__ import annotations

import gzip
import io as _io
import os
import warnings
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import check_max_range
from ..geometry import as_poses, compose, inverse, relative

__all__ = ["FormatError", "ParseWarning", "LaserLog", "open_text", "read_lines", "SkipCounter", "time_stamp_problems"]

PathLike = str | os.PathLike

#: What reading a damaged gzip stream raises: EOFError when it ends early, BadGzipFile (an
#: OSError) for a bad header or CRC, zlib.error for corrupted deflate bytes in the middle.
GZIP_ERRORS = (EOFError, OSError, zlib.error)


class FormatError(ValueError):
    """A file does not follow its format. The message reads ``file:line: what was expected``.

    Subclass of :class:`ValueError`; ``path`` and ``line`` (1-based, or None when the
    problem concerns the whole file) are kept as attributes.

    Examples
    --------
    >>> e = FormatError("robot.log", 12, "an ODOM record has 9 fields; got 4")
    >>> str(e)
    'robot.log:12: an ODOM record has 9 fields; got 4'
    >>> isinstance(e, ValueError)
    True
    """

    def __init__(self, path: PathLike | None, line: int | None, message: str) -> None:
        self.path = str(path) if path is not None else "<input>"
        self.line = line
        self.reason = message
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {message}")


class ParseWarning(UserWarning):
    """Records of a file were skipped (counted and summarised in one warning per file)."""


class SkipCounter:
    """Counts skipped records by reason and emits one summary :class:`ParseWarning`.

    Examples
    --------
    >>> c = SkipCounter("a.log")
    >>> c.add("RAWLASER1 records (not used)", 3)
    >>> c.add("RAWLASER1 records (not used)", 7)
    >>> c.as_dict()
    {'RAWLASER1 records (not used)': 2}
    """

    def __init__(self, path: PathLike | None) -> None:
        self.path = str(path) if path is not None else "<input>"
        self.counts: dict[str, int] = {}
        self.first_line: dict[str, int] = {}
        self.first_reason: dict[str, str] = {}

    def add(self, kind: str, line: int, reason: str = "") -> None:
        if kind not in self.counts:
            self.counts[kind] = 0
            self.first_line[kind] = line
            self.first_reason[kind] = reason
        self.counts[kind] += 1

    def as_dict(self) -> dict[str, int]:
        return dict(self.counts)

    def malformed(self, line: int, message: str, on_error: str = "raise") -> None:
        """A record that breaks its format: raise :class:`FormatError` or, with ``on_error="skip"``, count it.

        Examples
        --------
        >>> c = SkipCounter("a.log")
        >>> c.malformed(4, "expected 5 fields; got 3", on_error="skip")
        >>> c.as_dict()
        {'malformed records': 1}
        >>> c.malformed(9, "expected 5 fields; got 2")
        Traceback (most recent call last):
        ...
        localize.io._common.FormatError: a.log:9: expected 5 fields; got 2
        """
        if on_error == "raise":
            raise FormatError(self.path, line, message)
        self.add("malformed records", line, message)

    def floats(self, tokens: list[str], line: int, what: str, on_error: str = "raise") -> NDArray[np.float64] | None:
        """:func:`parse_floats` of one record; a field that is not a finite number is :meth:`malformed`
        (with ``on_error="skip"``: counted, and None returned so that the reader skips the record).

        Examples
        --------
        >>> c = SkipCounter("a.log")
        >>> c.floats(["1", "2.5"], 3, "O record")
        array([1. , 2.5])
        >>> c.floats(["1", "x"], 4, "O record", on_error="skip") is None, c.as_dict()
        (True, {'malformed records': 1})
        """
        try:
            return parse_floats(tokens, self.path, line, what)
        except FormatError as e:
            self.malformed(line, e.reason, on_error)
            return None

    def warn(self, stacklevel: int = 3) -> None:
        if not self.counts:
            return
        parts = []
        for kind, n in self.counts.items():
            extra = f": {self.first_reason[kind]}" if self.first_reason[kind] else ""
            parts.append(f"{n} {kind} (first at line {self.first_line[kind]}{extra})")
        warnings.warn(f"{self.path}: skipped " + "; ".join(parts), ParseWarning, stacklevel=stacklevel)


def open_text(path: PathLike) -> _io.TextIOBase:
    """Open a text file for reading, transparently un-gzipping it if it is compressed.

    Compression is recognised from the file's first two bytes (the gzip magic
    number), not from its name. Raises :class:`FormatError` for a missing or
    empty file.

    Examples
    --------
    >>> import gzip
    >>> p = tmp_dir() / "x.log"     # no .gz suffix needed
    >>> with gzip.open(p, "wt") as f:
    ...     _ = f.write("ODOM 1 2 3\\n")
    >>> with open_text(p) as f:
    ...     f.read()
    'ODOM 1 2 3\\n'
    """
    p = Path(path)
    if not p.exists():
        raise FormatError(p, None, "no such file")
    if p.is_dir():
        raise FormatError(p, None, "is a directory, expected a file")
    with open(p, "rb") as f:
        head = f.read(2)
    if not head:
        raise FormatError(p, None, "the file is empty")
    if head == b"\x1f\x8b":
        return _io.TextIOWrapper(gzip.open(p, "rb"), encoding="utf-8", errors="replace")
    return open(p, encoding="utf-8", errors="replace")


def read_lines(path: PathLike) -> Iterator[tuple[int, str]]:
    """Yield ``(line_number, line)`` of a (possibly gzipped) text file, 1-based.

    A gzip stream that ends early or holds corrupted bytes is reported as a
    :class:`FormatError` naming the line after the last complete one.
    """
    n = 0
    with open_text(path) as f:
        try:
            for n, line in enumerate(f, start=1):  # noqa: B007
                yield n, line
        except GZIP_ERRORS as exc:
            raise FormatError(path, n + 1, f"the compressed stream is damaged or truncated ({exc})") from None


def read_records(path: PathLike) -> Iterator[tuple[int, list[str]]]:
    """Yield ``(line_number, tokens)`` of each record of a text log: the lines that are neither blank nor
    ``#`` comments, split at white space (the CMU and CARMEN logs)."""
    for n, raw in read_lines(path):
        tokens = raw.split()
        if tokens and not tokens[0].startswith("#"):
            yield n, tokens


def parse_floats(tokens: list[str], path: PathLike | None, line: int, what: str) -> NDArray[np.float64]:
    """Convert tokens to finite floats or raise ``FormatError`` naming the first bad one."""
    try:
        vals = np.array(tokens, dtype=float)
    except ValueError:
        for k, t in enumerate(tokens):
            try:
                float(t)
            except ValueError:
                raise FormatError(path, line, f"{what}: field {k + 1} is {t!r}, expected a number") from None
        raise  # pragma: no cover - unreachable
    if not np.all(np.isfinite(vals)):
        k = int(np.flatnonzero(~np.isfinite(vals))[0])
        raise FormatError(path, line, f"{what}: field {k + 1} is {tokens[k]!r}, expected a finite number")
    return vals


#: Entries of ``LaserLog.meta`` that hold one value per scan (kept in step by ``select``).
_PER_SCAN_META = ("scan_lines", "neff")


#: The farthest a laser can sit from the robot's centre (metres): a mounting pose beyond it is a mistake
#: (``--laser-pose 1e308 0 0``, centimetres for metres) that would overflow the sensor model's arithmetic.
MAX_SENSOR_OFFSET = 100.0


def _sensor_offset(value: ArrayLike) -> NDArray[np.float64]:
    """The laser's mounting pose (dx, dy, dtheta) in the robot's frame, checked: on the robot, in radians.

    Examples
    --------
    >>> _sensor_offset([0.25, 0.0, 0.0]).tolist()
    [0.25, 0.0, 0.0]
    >>> _sensor_offset([1e308, 0.0, 0.0])
    Traceback (most recent call last):
    ...
    ValueError: sensor_offset (the laser's mounting pose, --laser-pose) must place the laser within 100 m of the robot's centre; got (1e+308, 0, 0): metres, not centimetres?
    """
    raw = np.asarray(value, dtype=float)
    if raw.shape != (3,):
        raise ValueError(f"sensor_offset must be one pose (dx, dy, dtheta); got shape {raw.shape}")
    shown = ", ".join(f"{v:g}" for v in raw)
    if np.all(np.isfinite(raw)) and float(np.hypot(raw[0], raw[1])) > MAX_SENSOR_OFFSET:
        raise ValueError(f"sensor_offset (the laser's mounting pose, --laser-pose) must place the laser within "
                         f"{MAX_SENSOR_OFFSET:g} m of the robot's centre; got ({shown}): metres, not centimetres?")
    if np.isfinite(raw[2]) and abs(raw[2]) > 2 * np.pi + 1e-9:
        raise ValueError(f"sensor_offset (the laser's mounting pose, --laser-pose): its yaw must be radians in "
                         f"[-2 pi, 2 pi]; got ({shown}): degrees? convert with np.radians")
    return as_poses(raw, "sensor_offset")


@dataclass(frozen=True, eq=False)
class LaserLog:
    """A robot log of laser scans and odometry, in SI units, whatever file it came from.

    Attributes
    ----------
    times : ndarray, shape (K,)
        Time stamp of each scan in seconds, as logged (some logs round them; use
        record order, not time, to sequence scans).
    odometry : ndarray, shape (K, 3)
        Odometry pose of the robot centre when each scan was taken, in the
        odometry frame (arbitrary origin: only differences carry information).
        Consecutive pairs are the controls ``u = (odometry[k-1], odometry[k])``
        of the odometry motion model.
    ranges : ndarray, shape (K, B)
        Ranges in metres; readings ``>= max_range`` mean "no return".
    angles : ndarray, shape (B,)
        Beam angles in radians relative to the laser's heading, counter-clockwise
        (beam 0 points to the robot's right, -pi/2, for a 180-degree scanner).
    max_range : float
        Readings at or above this value are "no return" (metres).
    sensor_offset : ndarray, shape (3,)
        Pose ``(dx, dy, dtheta)`` of the laser in the robot frame.
    poses : ndarray, shape (K, 3), or None
        Reference poses of the robot centre in the map frame, when the file
        carries them (e.g. SLAM-corrected CARMEN logs); None otherwise.
    odom_times, odom_poses : ndarray, shapes (M,) and (M, 3)
        Every odometry record of the file (CMU ``O`` lines, CARMEN ``ODOM``).
    source, format : str
        The file it was read from and its format name.
    params : dict
        ``PARAM name value`` entries of CARMEN logs (strings).
    skipped : dict
        Counts of records skipped while reading, by kind.
    meta : dict
        How ambiguous choices were resolved (where ``max_range`` and the odometry
        came from, ...); readers also store ``meta["scan_lines"]``, the line
        number of each scan in its file (see :func:`time_stamp_problems`).

    Examples
    --------
    >>> log = LaserLog(times=[0.0, 0.5], odometry=[[0, 0, 0], [0.1, 0, 0]],
    ...                ranges=[[1.0, 80.0], [0.9, 80.0]], angles=[-0.1, 0.1], max_range=80.0)
    >>> len(log), log.n_beams, log.no_return.sum(axis=1).tolist()
    (2, 2, [1, 1])
    >>> log.motions().round(3)
    array([[0.1, 0. , 0. ]])
    """

    times: NDArray[np.float64]
    odometry: NDArray[np.float64]
    ranges: NDArray[np.float64]
    angles: NDArray[np.float64]
    max_range: float
    sensor_offset: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    poses: NDArray[np.float64] | None = None
    odom_times: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    odom_poses: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    source: str = "<memory>"
    format: str = "arrays"
    params: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        def fix(name: str, value) -> None:
            object.__setattr__(self, name, value)

        times = np.asarray(self.times, dtype=float)
        if times.ndim != 1 or times.size == 0:
            raise ValueError(f"times must be a non-empty 1-D array of seconds; got shape {times.shape}")
        k = times.size
        if not np.all(np.isfinite(times)):
            raise ValueError("times must be finite")
        odo = as_poses(self.odometry, "odometry")
        if odo.shape != (k, 3):
            raise ValueError(f"odometry must have shape ({k}, 3) (one pose per scan); got {odo.shape}")
        rng_ = np.asarray(self.ranges, dtype=float)
        if rng_.ndim != 2 or rng_.shape[0] != k or rng_.shape[1] == 0:
            raise ValueError(f"ranges must have shape ({k}, B) with B >= 1 beams; got {rng_.shape}")
        if not np.all(np.isfinite(rng_)) or np.any(rng_ < 0):
            raise ValueError("ranges must be finite and >= 0 metres (use max_range for no return)")
        ang = np.asarray(self.angles, dtype=float)
        if ang.shape != (rng_.shape[1],):
            raise ValueError(f"angles must have shape ({rng_.shape[1]},) (one per beam); got {ang.shape}")
        if not np.all(np.isfinite(ang)):
            raise ValueError("angles must be finite")
        mr = check_max_range(self.max_range)
        off = _sensor_offset(self.sensor_offset)
        poses = None
        if self.poses is not None:
            poses = as_poses(self.poses, "poses")
            if poses.shape != (k, 3):
                raise ValueError(f"poses must have shape ({k}, 3) or be None; got {poses.shape}")
        ot = np.asarray(self.odom_times, dtype=float).reshape(-1)
        op = np.asarray(self.odom_poses, dtype=float).reshape(-1, 3)
        if ot.shape[0] != op.shape[0]:
            raise ValueError(f"odom_times ({ot.shape[0]}) and odom_poses ({op.shape[0]}) differ in length")
        for arr in (times, odo, rng_, ang, off, ot, op):
            arr.setflags(write=False)
        if poses is not None:
            poses.setflags(write=False)
        fix("times", times)
        fix("odometry", odo)
        fix("ranges", rng_)
        fix("angles", ang)
        fix("max_range", mr)
        fix("sensor_offset", off)
        fix("poses", poses)
        fix("odom_times", ot)
        fix("odom_poses", op)

    # ------------------------------------------------------------ queries
    def __len__(self) -> int:
        return int(self.times.size)

    @property
    def n_beams(self) -> int:
        """Number of beams per scan."""
        return int(self.angles.size)

    @property
    def duration(self) -> float:
        """Time from the first to the last scan in seconds (0 for one scan)."""
        return float(self.times[-1] - self.times[0])

    @property
    def no_return(self) -> NDArray[np.bool_]:
        """Mask ``(K, B)`` of readings that mean "no return" (``>= max_range``)."""
        return self.ranges >= self.max_range

    def motions(self) -> NDArray[np.float64]:
        """Odometry motion between consecutive scans in the robot frame, shape (K-1, 3).

        Row ``k`` is ``relative(odometry[k], odometry[k+1])``: forward, left and
        turn of scan ``k+1`` seen from scan ``k``.
        """
        if len(self) < 2:
            return np.zeros((0, 3))
        return relative(self.odometry[:-1], self.odometry[1:])

    def laser_poses(self, robot_poses: ArrayLike | None = None) -> NDArray[np.float64]:
        """Poses of the laser for robot poses (default: the reference ``poses``)."""
        if robot_poses is None:
            if self.poses is None:
                raise ValueError("this log has no reference poses; pass robot_poses")
            robot_poses = self.poses
        return compose(as_poses(robot_poses, "robot_poses"), self.sensor_offset)

    def robot_poses_from_laser(self, laser_poses: ArrayLike) -> NDArray[np.float64]:
        """Robot-centre poses for given laser poses (undoes ``sensor_offset``)."""
        return compose(as_poses(laser_poses, "laser_poses"), inverse(self.sensor_offset))

    def select(self, index) -> "LaserLog":
        """A new log with only the scans picked by ``index`` (slice, indices or mask).

        Odometry records are kept whole; odometry poses at the scans stay in the
        same frame, so motions between the kept scans remain correct.

        Examples
        --------
        >>> log = LaserLog(times=[0, 1, 2], odometry=np.zeros((3, 3)), ranges=np.ones((3, 4)),
        ...                angles=np.linspace(-1, 1, 4), max_range=5.0)
        >>> len(log.select(slice(0, None, 2)))
        2
        """
        idx = np.arange(len(self))[index]
        idx = np.atleast_1d(idx)
        if idx.size == 0:
            raise ValueError("select() would leave no scan; index picks nothing")
        meta = {**self.meta, "selected": True}
        for key in _PER_SCAN_META:  # per-scan entries follow the scans
            v = meta.get(key)
            if isinstance(v, np.ndarray) and v.shape[:1] == (len(self),):
                meta[key] = v[idx]
        return replace(
            self,
            times=self.times[idx],
            odometry=self.odometry[idx],
            ranges=self.ranges[idx],
            poses=None if self.poses is None else self.poses[idx],
            meta=meta,
        )

    def select_beams(self, step: int = 1, count: int | None = None) -> "LaserLog":
        """A new log keeping every ``step``-th beam, or ``count`` evenly spread beams.

        Examples
        --------
        >>> log = LaserLog(times=[0], odometry=np.zeros((1, 3)), ranges=np.ones((1, 180)),
        ...                angles=np.radians(np.arange(-90, 90)), max_range=5.0)
        >>> log.select_beams(count=60).n_beams, log.select_beams(step=4).n_beams
        (60, 45)
        """
        b = self.n_beams
        if count is not None:
            count = int(count)
            if not 1 <= count <= b:
                raise ValueError(f"count must be between 1 and the {b} beams of the log; got {count}")
            idx = np.unique(np.round(np.linspace(0, b - 1, count)).astype(int))
        else:
            step = int(step)
            if step < 1:
                raise ValueError(f"step must be a positive integer; got {step}")
            idx = np.arange(0, b, step)
        return replace(self, ranges=self.ranges[:, idx], angles=self.angles[idx])

    def __repr__(self) -> str:
        deg = np.degrees(self.angles)
        return (
            f"LaserLog({self.format!r}, scans={len(self)}, beams={self.n_beams} "
            f"[{deg[0]:.1f}..{deg[-1]:.1f} deg], duration={self.duration:.1f} s, "
            f"max_range={self.max_range:g} m, reference poses={'yes' if self.poses is not None else 'no'})"
        )


def median_offset(robot: NDArray[np.float64], laser: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Median pose of ``laser`` seen from ``robot`` and the largest deviation from it (m)."""
    rel = relative(robot, laser)
    med = np.median(rel, axis=0)
    med[2] = float(np.arctan2(np.median(np.sin(rel[:, 2])), np.median(np.cos(rel[:, 2]))))
    spread = float(np.max(np.hypot(rel[:, 0] - med[0], rel[:, 1] - med[1]))) if len(rel) else 0.0
    return med, spread


def time_stamp_problems(log: LaserLog) -> list[str]:
    """Sentences about scan time stamps that go backwards or repeat, naming the first offending line.

    Filters sequence scans by record order, so such logs still work; but
    durations and real-time factors computed from them mean nothing, and a
    user should hear about it (the command line prints these as warnings).
    Each sentence reads ``file:line: ...`` when the reader recorded the scans'
    line numbers (``meta["scan_lines"]``), else ``file: scan k: ...``.

    Examples
    --------
    >>> log = LaserLog(times=[0.0, 1.0, 0.5, 0.5, 2.0], odometry=np.zeros((5, 3)), ranges=np.ones((5, 2)),
    ...                angles=[0.0, 0.1], max_range=5.0, source="r.log",
    ...                meta={"scan_lines": np.array([3, 5, 7, 9, 11])})
    >>> for m in time_stamp_problems(log):
    ...     print(m)
    r.log:7: time stamp 0.5 is earlier than the previous scan's 1 (1 of 5 scans go back in time)
    r.log:9: time stamp 0.5 repeats the previous scan's (1 of 5 scans)
    """
    t = np.asarray(log.times, dtype=float)
    if t.size < 2:
        return []
    lines = log.meta.get("scan_lines")
    lines = np.asarray(lines) if lines is not None and len(lines) == t.size else None

    def where(k: int) -> str:
        return f"{log.source}:{int(lines[k])}" if lines is not None else f"{log.source}: scan {k}"

    dt = np.diff(t)
    out = []
    back = np.flatnonzero(dt < 0)
    if back.size:
        k = int(back[0]) + 1
        out.append(f"{where(k)}: time stamp {t[k]:.10g} is earlier than the previous scan's {t[k - 1]:.10g} "
                   f"({back.size} of {t.size} scans go back in time)")
    same = np.flatnonzero(dt == 0)
    if same.size:
        k = int(same[0]) + 1
        out.append(f"{where(k)}: time stamp {t[k]:.10g} repeats the previous scan's ({same.size} of {t.size} scans)")
    return out
