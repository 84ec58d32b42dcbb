"""ROS bags as logs: laser scans, odometry and the laser's mounting pose, read with ``rosbags``.

Reads ROS 1 bags (``robot.bag``) and ROS 2 bags (a folder with ``metadata.yaml`` and
sqlite3 ``.db3`` or ``.mcap`` files) without a ROS installation, through the pure-Python
`rosbags <https://ternaris.gitlab.io/rosbags/>`_ package (``pip install "localize[ros]"``).

What is read, and the conventions applied (those of ROS AMCL, so that a bag
localizes here as it would on the robot):

* **Scans** -- ``sensor_msgs/LaserScan``: beam ``k`` points at
  ``angle_min + k * angle_increment`` in the laser's frame (``header.frame_id``);
  readings that are NaN, infinite, below ``range_min`` or above ``range_max`` mean
  "no return" and become ``range_max`` (AMCL does the same). The message stores
  float32: ranges are widened to the float64 of their shortest decimal (``1.23``,
  not ``1.2300000190734863``; laser drivers quantise to millimetres), angles to
  the float64 of their shortest decimal in degrees (``1 deg`` is ``pi/180``
  exactly).
* **Odometry** -- ``nav_msgs/Odometry`` messages (pose of ``child_frame_id`` in
  ``header.frame_id``), or, when the bag has none, the ``odom -> base`` transform
  on ``/tf``. Each scan gets the odometry pose at its own time stamp,
  interpolated linearly between the two odometry samples around it (AMCL asks
  tf for the same). Scans outside the odometry's time span are dropped and
  counted in ``log.skipped``.
* **Laser mounting** -- the chain of transforms from the base frame to the scan's
  frame on ``/tf_static`` (and constant ones on ``/tf``), reduced to the plane:
  ``sensor_offset = (x, y, yaw)``. A laser mounted upside down (its z axis
  pointing down) has its beam order mirrored. ``laser_pose=`` overrides this,
  and is needed when the bag holds no such transform.
* **Topics** -- found by type when there is one of each; otherwise name them with
  ``scan_topic=`` / ``odom_topic=``. A bag without them raises a
  :class:`~localize.io.FormatError` listing the topics and types it holds.

Time stamps are the messages' ``header.stamp``; a topic whose stamps go backwards
is an error (bags recorded with simulated time and a restarted clock do this).

:func:`write_rosbag_log` writes a :class:`~localize.io.LaserLog` as a bag (scans,
odometry, the laser's mounting on ``/tf_static``), and :func:`write_result_bag`
the output of a run: ``geometry_msgs/PoseWithCovarianceStamped`` on
``/amcl_pose`` and the particle cloud as ``geometry_msgs/PoseArray``, so that
the estimate can be replayed beside the data.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry import quaternion_to_yaw, wrap_angle, yaw_to_quaternion
from ._common import FormatError, LaserLog

__all__ = ["is_rosbag", "bag_topics", "read_rosbag", "write_rosbag_log", "write_result_bag", "BAG_FORMATS",
           "SCAN_TYPE", "ODOM_TYPE", "TF_TYPES", "yaw_to_quaternion", "quaternion_to_yaw"]

PathLike = str | os.PathLike

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
#: The bag formats: ROS 1 ``.bag``; ROS 2 with sqlite3 or MCAP storage.
BAG_FORMATS = ("rosbag1", "sqlite3", "mcap")
_GLOBAL_FRAMES = ("map", "world", "earth")
#: Bag time stamps are integer nanoseconds.
_NS_PER_S = 1e9
_TFMESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms\n"


def _rosbags():
    try:
        import rosbags  # noqa: F401
    except ImportError:  # pragma: no cover - the test suite installs it
        raise ImportError('reading and writing ROS bags needs the rosbags package: pip install "localize[ros]" '
                          "(or pip install rosbags)") from None
    from rosbags import highlevel, rosbag1, rosbag2, typesys

    return highlevel, rosbag1, rosbag2, typesys


# ============================================================================ small helpers
def _rotation(q: Sequence[float]) -> NDArray[np.float64]:
    x, y, z, w = (float(v) for v in q)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError(f"a rotation quaternion must have a positive finite norm; got {tuple(q)}")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _matrix(t: Sequence[float], q: Sequence[float]) -> NDArray[np.float64]:
    m = np.eye(4)
    m[:3, :3] = _rotation(q)
    m[:3, 3] = t
    return m


def _decimal(values: NDArray, scale: float = 1.0) -> NDArray[np.float64]:
    """Widen float32 ``values`` to the float64 of their shortest decimal (7 significant digits) in ``scale`` units.

    A value is replaced only when the decimal rounds back to the same float32,
    so the result is always consistent with what the message stored.

    Examples
    --------
    >>> _decimal(np.float32([1.23, 0.0, 81.83])).tolist()
    [1.23, 0.0, 81.83]
    >>> bool(_decimal(np.float32([np.pi / 180]), scale=np.pi / 180)[0] == np.pi / 180)
    True
    """
    f32 = np.asarray(values, dtype=np.float32)
    f64 = f32.astype(np.float64)
    out = f64.copy()
    u = f64 / scale
    ok = np.isfinite(u) & (u != 0)
    if np.any(ok):
        mag = np.floor(np.log10(np.abs(u[ok])))
        digits = np.clip(6 - mag, -20, 20)
        p = 10.0 ** np.abs(digits)
        r = np.where(digits >= 0, np.round(u[ok] * p) / p, np.round(u[ok] / p) * p)
        cand = r * scale if scale != 1.0 else r
        same = cand.astype(np.float32) == f32[ok]
        sub = out[ok]
        sub[same] = cand[same]
        out[ok] = sub
    return out


def _stamp(header: Any) -> int:
    s = header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


# ============================================================================ detection
def _bag_root(path: PathLike) -> Path:
    """The path rosbags opens: the ``.bag`` file, or the ROS 2 bag folder."""
    p = Path(path)
    if p.is_file() and p.suffix in (".db3", ".mcap") and (p.parent / "metadata.yaml").is_file():
        return p.parent
    return p


def is_rosbag(path: PathLike) -> bool:
    """True if ``path`` is a ROS 1 bag (``#ROSBAG V2.0`` header) or a ROS 2 bag folder (or a file in one).

    Examples
    --------
    >>> d = tmp_dir()
    >>> is_rosbag(d), (d / "metadata.yaml").write_text("rosbag2_bagfile_information: {}") > 0, is_rosbag(d)
    (False, True, True)
    """
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file()
    if not p.is_file():
        return False
    if p.suffix in (".db3", ".mcap") and (p.parent / "metadata.yaml").is_file():
        return True
    with open(p, "rb") as f:
        head = f.read(13)
    return head.startswith(b"#ROSBAG V2.0") or head.startswith(b"\x89MCAP")


def _open_reader(path: PathLike):
    highlevel, _, _, typesys = _rosbags()
    root = _bag_root(path)
    if not root.exists():
        raise FormatError(root, None, "no such file or folder")
    if root.is_file() and root.suffix == ".mcap" and not (root.parent / "metadata.yaml").is_file():
        raise FormatError(root, None, "an MCAP file without its ROS 2 metadata.yaml; pass the bag folder "
                                      "(the one `ros2 bag record` wrote)")
    try:
        reader = highlevel.AnyReader([root], default_typestore=typesys.get_typestore(typesys.Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags raises its own error classes, sqlite3/struct errors on damage
        raise FormatError(root, None, f"cannot open the bag (damaged, truncated or not a bag?): {exc}") from None
    return root, reader


def bag_topics(path: PathLike) -> dict[str, str]:
    """Topics of a bag and their message types, e.g. ``{"/scan": "sensor_msgs/msg/LaserScan"}``."""
    _, reader = _open_reader(path)
    try:
        return {c.topic: c.msgtype for c in reader.connections}
    finally:
        reader.close()


def _topic_list(topics: dict[str, str]) -> str:
    if not topics:
        return "the bag holds no topics"
    return "the bag holds: " + ", ".join(f"{t} ({m})" for t, m in sorted(topics.items()))


def _choose(root: Path, topics: dict[str, str], types: Sequence[str], given: str | None, what: str,
            option: str, required: bool = True) -> list[str]:
    if given is not None:
        if given not in topics:
            raise FormatError(root, None, f"{option} {given}: no such topic; {_topic_list(topics)}")
        if topics[given] not in types:
            raise FormatError(root, None, f"{option} {given}: the topic holds {topics[given]}, expected "
                                          f"{' or '.join(types)}")
        return [given]
    cands = sorted(t for t, m in topics.items() if m in types)
    if len(cands) > 1:
        raise FormatError(root, None, f"the bag has {len(cands)} {what} topics ({', '.join(cands)}); choose one "
                                      f"with {option}")
    if not cands and required:
        raise FormatError(root, None, f"the bag has no {what} topic ({types[0]}); {_topic_list(topics)}")
    return cands


# ============================================================================ reading
def _check_time(root: Path, topic: str, stamps: NDArray[np.int64]) -> None:
    d = np.diff(stamps)
    if np.any(d < 0):
        k = int(np.flatnonzero(d < 0)[0]) + 1
        raise FormatError(root, None, f"time goes backwards on {topic}: message {k} has the stamp "
                                      f"{stamps[k] / _NS_PER_S:.9f} s, earlier than message {k - 1} at "
                                      f"{stamps[k - 1] / _NS_PER_S:.9f} s (a restarted clock or a merged bag?); "
                                      "expected non-decreasing header stamps")


def _tf_graph_pose(edges: dict[tuple[str, str], NDArray], start: str, goal: str) -> NDArray | None:
    """The 4x4 transform of ``goal`` in ``start`` through a chain of ``edges[(parent, child)]``."""
    if start == goal:
        return np.eye(4)
    nbr: dict[str, list[tuple[str, NDArray]]] = {}
    for (a, b), m in edges.items():
        nbr.setdefault(a, []).append((b, m))
        nbr.setdefault(b, []).append((a, np.linalg.inv(m)))
    seen = {start: np.eye(4)}
    todo = [start]
    while todo:
        a = todo.pop(0)
        for b, m in nbr.get(a, []):
            if b not in seen:
                seen[b] = seen[a] @ m
                if b == goal:
                    return seen[b]
                todo.append(b)
    return None


def read_rosbag(
    path: PathLike,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    laser_pose: ArrayLike | None = None,
    odom_frame: str | None = None,
) -> LaserLog:
    """Read the laser scans and odometry of a ROS 1 or ROS 2 bag into a :class:`~localize.io.LaserLog`.

    Parameters
    ----------
    path : path
        A ROS 1 ``.bag`` file, or a ROS 2 bag folder (``metadata.yaml`` with
        ``.db3`` or ``.mcap`` files; a file inside it works too).
    scan_topic : str, optional
        The ``sensor_msgs/LaserScan`` topic (needed when the bag has several).
    odom_topic : str, optional
        The ``nav_msgs/Odometry`` topic, or a ``/tf`` topic to use the
        ``odom -> base`` transform (default: the bag's one Odometry topic,
        else ``/tf``).
    laser_pose : (x, y, yaw), optional
        Mounting pose of the laser in the robot's base frame (metres,
        radians); overrides ``/tf_static`` and is needed when it has none.
    odom_frame : str, optional
        Parent frame of the odometry transform on ``/tf`` (default ``odom``,
        or the one non-global parent frame there).

    Returns
    -------
    LaserLog
        ``format`` is ``"rosbag1"``, ``"sqlite3"`` or ``"mcap"``; ``meta``
        names the topics, frames and how each choice was made; no reference
        poses (``poses`` is None).

    Raises
    ------
    FormatError
        A damaged bag, missing or ambiguous topics (the message lists the
        bag's topics and types), time stamps that go backwards, scans
        without odometry, scans of varying layout.

    Examples
    --------
    >>> log = LaserLog(times=[1.0, 1.5, 2.0], odometry=[[0, 0, 0], [0.1, 0, 0.05], [0.2, 0, 0.1]],
    ...                ranges=np.full((3, 4), 2.5), angles=np.radians([-90.0, -30, 30, 90]), max_range=8.0,
    ...                sensor_offset=(0.2, 0.0, 0.0))
    >>> bag = write_rosbag_log(tmp_dir() / "robot.bag", log)
    >>> back = read_rosbag(bag)
    >>> back.format, len(back), back.sensor_offset.round(6).tolist(), np.degrees(back.angles).round(3).tolist()
    ('rosbag1', 3, [0.2, 0.0, 0.0], [-90.0, -30.0, 30.0, 90.0])
    >>> bool(np.allclose(back.odometry, log.odometry, atol=1e-12)), bool(np.array_equal(back.ranges, log.ranges))
    (True, True)
    """
    root, reader = _open_reader(path)
    try:
        return _read(root, reader, scan_topic, odom_topic, laser_pose, odom_frame)
    except FormatError:
        raise
    except Exception as exc:  # damage found while reading messages
        raise FormatError(root, None, f"cannot read the bag (damaged or truncated?): "
                                      f"{type(exc).__name__}: {exc}") from None
    finally:
        reader.close()


def _read(root: Path, reader, scan_topic, odom_topic, laser_pose, odom_frame) -> LaserLog:
    topics = {c.topic: c.msgtype for c in reader.connections}
    fmt = "rosbag1" if not reader.is2 else ("mcap" if any(p.suffix == ".mcap" for p in _storage_files(root))
                                            else "sqlite3")
    scan_t = _choose(root, topics, (SCAN_TYPE,), scan_topic, "laser scan", "--scan-topic")[0]
    use_tf_odom = odom_topic is not None and topics.get(odom_topic) in TF_TYPES
    odom_t = [] if use_tf_odom else _choose(root, topics, (ODOM_TYPE,), odom_topic, "odometry", "--odom-topic",
                                            required=False)
    tf_topics = [t for t, m in topics.items() if m in TF_TYPES]
    wanted = {scan_t, *odom_t, *tf_topics}
    conns = [c for c in reader.connections if c.topic in wanted]

    scan_stamps: list[int] = []
    scan_rec: list[int] = []
    scan_ranges: list[NDArray] = []
    layout: tuple | None = None
    frame = ""
    odo: list[tuple[int, float, float, float, str, str]] = []
    dyn: dict[tuple[str, str], list[tuple[int, NDArray]]] = {}
    static: dict[tuple[str, str], NDArray] = {}
    for conn, rec_time, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        if conn.topic == scan_t:
            n = len(msg.ranges)
            lay = (n, float(msg.angle_min), float(msg.angle_increment), float(msg.range_min), float(msg.range_max))
            if layout is None:
                layout, frame = lay, msg.header.frame_id
                if n == 0:
                    raise FormatError(root, None, f"{scan_t}: the first scan has no ranges")
            elif lay != layout:
                k = len(scan_stamps)
                raise FormatError(root, None, f"{scan_t}: scan {k} has the layout (beams, angle_min, "
                                              f"angle_increment, range_min, range_max) = {lay}, scan 0 had {layout}; "
                                              "expected one laser with a fixed layout")
            scan_stamps.append(_stamp(msg.header))
            scan_rec.append(int(rec_time))
            scan_ranges.append(np.asarray(msg.ranges, dtype=np.float32))
        elif conn.topic in odom_t:
            p = msg.pose.pose
            q = p.orientation
            yaw = float(quaternion_to_yaw([q.x, q.y, q.z, q.w]))
            odo.append((_stamp(msg.header), float(p.position.x), float(p.position.y), yaw, msg.header.frame_id,
                        msg.child_frame_id))
        else:
            is_static = conn.topic.endswith("tf_static")
            for tr in msg.transforms:
                t, r = tr.transform.translation, tr.transform.rotation
                key = (tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"))
                m = _matrix([t.x, t.y, t.z], [r.x, r.y, r.z, r.w])
                if is_static:
                    static[key] = m
                else:
                    dyn.setdefault(key, []).append((_stamp(tr.header), m))
    if not scan_stamps:
        raise FormatError(root, None, f"{scan_t} holds no messages")
    assert layout is not None
    n_beams, a_min, a_inc, r_min, r_max = layout
    frame = frame.lstrip("/")
    stamps = np.asarray(scan_stamps, dtype=np.int64)
    meta: dict[str, Any] = {"scan_topic": scan_t, "scan_frame": frame, "bag_format": fmt}
    if np.all(stamps == 0):
        stamps = np.asarray(scan_rec, dtype=np.int64)
        meta["scan_stamps"] = "header stamps are zero: the bag's record times are used"
    _check_time(root, scan_t, stamps)

    # ---------------------------------------------------------------- odometry
    if odom_t:
        o_st = np.array([o[0] for o in odo], dtype=np.int64)
        if o_st.size == 0:
            raise FormatError(root, None, f"scans without odometry: {odom_t[0]} holds no messages")
        _check_time(root, odom_t[0], o_st)
        o_pose = np.array([o[1:4] for o in odo], dtype=float)
        parent, base = odo[0][4].lstrip("/") or "odom", odo[0][5].lstrip("/") or "base_link"
        meta["odometry"] = f"nav_msgs/Odometry on {odom_t[0]} ({parent} -> {base})"
        meta["odom_topic"] = odom_t[0]
    else:
        pairs = sorted(dyn)
        if not pairs:
            raise FormatError(root, None, f"scans without odometry: the bag has no {ODOM_TYPE} topic and no "
                                          f"transforms on /tf; {_topic_list(topics)}")
        if odom_frame is not None:
            cands = [p for p in pairs if p[0] == odom_frame]
        else:
            cands = [p for p in pairs if p[0] == "odom"] or [p for p in pairs if p[0] not in _GLOBAL_FRAMES]
        if len(cands) > 1:  # keep the one whose child reaches the laser through static transforms
            linked = [p for p in cands if _tf_graph_pose(static, p[1], frame) is not None]
            cands = linked if linked else cands
        if len(cands) != 1:
            listed = ", ".join(f"{a} -> {b}" for a, b in pairs)
            raise FormatError(root, None, f"scans without odometry: cannot tell the odometry transform on /tf "
                                          f"(transforms there: {listed}); expected one odom -> base transform, or a "
                                          f"{ODOM_TYPE} topic (--odom-topic)")
        parent, base = cands[0]
        seq = dyn[cands[0]]
        o_st = np.array([s for s, _ in seq], dtype=np.int64)
        _check_time(root, f"/tf ({parent} -> {base})", o_st)
        o_pose = np.array([[m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])] for _, m in seq])
        meta["odometry"] = f"/tf transform {parent} -> {base}"
    # equal stamps: keep the last sample of each
    keep = np.append(o_st[1:] != o_st[:-1], True)
    o_st, o_pose = o_st[keep], o_pose[keep]
    o_pose[:, 2] = wrap_angle(o_pose[:, 2])
    meta["base_frame"], meta["odom_frame"] = base, parent

    # ---------------------------------------------------------------- laser mounting
    if laser_pose is not None:
        off = np.asarray(laser_pose, dtype=float).reshape(-1)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ValueError(f"laser_pose must be three finite numbers (x, y, yaw); got {laser_pose!r}")
        flip = False
        meta["sensor_offset_source"] = "given (laser_pose / --laser-pose)"
    else:
        edges = dict(static)
        for key, seq in dyn.items():  # constant transforms on /tf count as static
            if key != (parent, base) and all(np.allclose(m, seq[0][1], atol=1e-9) for _, m in seq):
                edges.setdefault(key, seq[0][1])
        m = _tf_graph_pose(edges, base, frame)
        if m is None:
            known = sorted({f for k in static for f in k})
            raise FormatError(root, None, f"no transform from the base frame '{base}' to the laser frame '{frame}' "
                                          f"on /tf_static (frames there: {', '.join(known) or 'none'}); give the "
                                          "laser's mounting pose with --laser-pose X Y YAW (metres, radians; "
                                          "0 0 0 if the laser sits at the robot's centre)")
        off = np.array([m[0, 3], m[1, 3], np.arctan2(m[1, 0], m[0, 0])])
        flip = bool(m[2, 2] < 0)
        if abs(m[2, 2]) < np.cos(np.radians(5.0)):
            meta["sensor_tilt_warning"] = f"the laser is tilted {np.degrees(np.arccos(abs(m[2, 2]))):.1f} degrees"
        meta["sensor_offset_source"] = f"/tf_static chain {base} -> {frame}" + (" (mounted upside down)" if flip
                                                                                  else "")
    # ---------------------------------------------------------------- scans and pairing
    deg = np.pi / 180.0
    a0 = float(_decimal(np.float32([a_min]), scale=deg)[0])
    da = float(_decimal(np.float32([a_inc]), scale=deg)[0])
    angles = a0 + da * np.arange(n_beams)
    mr = float(_decimal(np.float32([r_max]))[0])
    mn = float(_decimal(np.float32([r_min]))[0])
    if not (np.isfinite(mr) and mr > 0):
        raise FormatError(root, None, f"{scan_t}: range_max is {r_max}; expected a positive number of metres")
    raw = np.vstack(scan_ranges)
    ranges = _decimal(raw)
    bad = ~np.isfinite(ranges) | (ranges < mn) | (ranges > mr)
    ranges[bad] = mr
    if flip:
        angles, ranges = -angles[::-1], ranges[:, ::-1]
    inside = (stamps >= o_st[0]) & (stamps <= o_st[-1])
    dropped = int((~inside).sum())
    if not np.any(inside):
        raise FormatError(root, None, f"scans without odometry: none of the {stamps.size} scans on {scan_t} "
                                      f"({stamps[0] / _NS_PER_S:.3f} .. {stamps[-1] / _NS_PER_S:.3f} s) falls within the "
                                      f"odometry's time span ({o_st[0] / _NS_PER_S:.3f} .. {o_st[-1] / _NS_PER_S:.3f} s)")
    meta["invalid_readings"] = int(bad[inside].sum())  # NaN, inf, outside [range_min, range_max]: no return
    ts = stamps[inside]
    j = np.clip(np.searchsorted(o_st, ts, side="right") - 1, 0, max(o_st.size - 2, 0))
    odom = np.empty((ts.size, 3))
    if o_st.size == 1:
        odom[:] = o_pose[0]
    else:
        t0, t1 = o_st[j], o_st[j + 1]
        frac = (ts - t0) / (t1 - t0)
        p0, p1 = o_pose[j], o_pose[j + 1]
        odom[:, :2] = p0[:, :2] + frac[:, None] * (p1[:, :2] - p0[:, :2])
        odom[:, 2] = wrap_angle(p0[:, 2] + frac * wrap_angle(p1[:, 2] - p0[:, 2]))
        exact0, exact1 = frac == 0, frac == 1
        odom[exact0], odom[exact1] = p0[exact0], p1[exact1]
        meta["largest_odometry_gap_s"] = round(float(np.max(t1 - t0)) / _NS_PER_S, 6)
    skipped = {"scans outside the odometry's time span": dropped} if dropped else {}
    meta.update({"range_min": mn, "scans_in_bag": int(stamps.size)})
    return LaserLog(times=ts / _NS_PER_S, odometry=odom, ranges=ranges[inside], angles=angles,
                    max_range=mr, sensor_offset=off, poses=None, odom_times=o_st / _NS_PER_S, odom_poses=o_pose,
                    source=str(root), format=fmt, skipped=skipped, meta=meta)


def _storage_files(root: Path) -> list[Path]:
    return [root] if root.is_file() else sorted(root.iterdir())


# ============================================================================ writing
def _typestore(version: int):
    _, _, _, typesys = _rosbags()
    if version == 1:
        ts = typesys.get_typestore(typesys.Stores.ROS1_NOETIC)
        ts.register(typesys.get_types_from_msg(_TFMESSAGE_MSG, "tf2_msgs/msg/TFMessage"))
        return ts
    return typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)


class _BagOut:
    """A bag being written to a temporary name; renamed into place on success, removed on failure."""

    def __init__(self, path: PathLike, storage: str) -> None:
        if storage not in BAG_FORMATS:
            raise ValueError(f"storage must be one of {BAG_FORMATS}; got {storage!r}")
        _, rosbag1, rosbag2, _ = _rosbags()
        self.path = Path(path)
        self.version = 1 if storage == "rosbag1" else 2
        self.tmp = self.path.with_name(self.path.name + ".partial")
        _remove(self.tmp)
        if self.version == 1:
            self.writer = rosbag1.Writer(self.tmp)
        else:
            plugin = rosbag2.StoragePlugin.MCAP if storage == "mcap" else rosbag2.StoragePlugin.SQLITE3
            self.writer = rosbag2.Writer(self.tmp, version=9, storage_plugin=plugin)
        self.ts = _typestore(self.version)
        self.types = self.ts.types
        self.conns: dict[str, Any] = {}

    def __enter__(self) -> "_BagOut":
        self.writer.open()
        return self

    def connection(self, topic: str, msgtype: str, latching: bool = False):
        if topic not in self.conns:
            if self.version == 1:
                self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=self.ts,
                                                               latching=1 if latching else None)
            else:
                self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=self.ts)
        return self.conns[topic]

    def write(self, topic: str, msg: Any, t_ns: int, latching: bool = False) -> None:
        conn = self.connection(topic, msg.__msgtype__, latching)
        data = self.ts.serialize_ros1(msg, msg.__msgtype__) if self.version == 1 else \
            self.ts.serialize_cdr(msg, msg.__msgtype__)
        self.writer.write(conn, int(t_ns), data)

    def write_raw(self, topic: str, msgtype: str, data: bytes, t_ns: int) -> None:
        self.writer.write(self.connection(topic, msgtype), int(t_ns), data)

    def header(self, t_ns: int, frame: str):
        T, H = self.types["builtin_interfaces/msg/Time"], self.types["std_msgs/msg/Header"]
        stamp = T(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000))
        return H(seq=0, stamp=stamp, frame_id=frame) if self.version == 1 else H(stamp=stamp, frame_id=frame)

    def pose(self, x: float, y: float, th: float):
        P, Q, Pose = (self.types[f"geometry_msgs/msg/{n}"] for n in ("Point", "Quaternion", "Pose"))
        q = yaw_to_quaternion(th)
        return Pose(position=P(x=float(x), y=float(y), z=0.0),
                    orientation=Q(x=0.0, y=0.0, z=float(q[2]), w=float(q[3])))

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            try:
                self.writer.close()
            except Exception:  # noqa: BLE001 - already failing
                pass
            _remove(self.tmp)
            return
        self.writer.close()
        _remove(self.path)
        os.replace(self.tmp, self.path)


def _pose_array_bytes(version: int, t_ns: int, frame: str, poses: NDArray) -> bytes:
    """``geometry_msgs/PoseArray`` serialised with numpy (ROS 1 or CDR): a particle cloud is 1000s of poses.

    Byte for byte what rosbags' serializers produce (tested), without building a Python object per pose.
    """
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    body = np.zeros((p.shape[0], 7))
    body[:, :2] = p[:, :2]
    q = yaw_to_quaternion(p[:, 2])
    body[:, 5], body[:, 6] = q[:, 2], q[:, 3]
    sec, nsec = int(t_ns // 1_000_000_000), int(t_ns % 1_000_000_000)
    name = frame.encode()
    if version == 1:
        head = np.array([0, sec, nsec, len(name)], dtype="<u4").tobytes() + name
        return head + np.array([p.shape[0]], dtype="<u4").tobytes() + body.astype("<f8").tobytes()
    out = bytearray(b"\x00\x01\x00\x00")  # CDR, little endian
    data = bytearray(np.array([sec], dtype="<i4").tobytes() + np.array([nsec, len(name) + 1], dtype="<u4").tobytes())
    data += name + b"\x00"
    data += b"\x00" * (-len(data) % 4) + np.array([p.shape[0]], dtype="<u4").tobytes()
    if p.shape[0]:
        data += b"\x00" * (-len(data) % 8) + body.astype("<f8").tobytes()
    return bytes(out + data)


def _remove(p: Path) -> None:
    if p.is_dir():
        shutil.rmtree(p)
    elif p.exists():
        p.unlink()


def _ns(times: NDArray[np.float64]) -> NDArray[np.int64]:
    return np.round(np.asarray(times, dtype=float) * _NS_PER_S).astype(np.int64)


def write_rosbag_log(
    path: PathLike,
    log: LaserLog,
    storage: str = "rosbag1",
    odometry: str = "odometry",
    scan_topic: str = "/scan",
    odom_topic: str = "/odom",
    frames: tuple[str, str, str] = ("odom", "base_link", "laser"),
    time_offset: float = 0.0,
) -> Path:
    """Write a :class:`~localize.io.LaserLog` as a ROS bag (with rosbags' own writer).

    Scans go to ``scan_topic`` as ``sensor_msgs/LaserScan`` (readings at or
    above ``max_range`` as ``+inf``, REP 117's "no return"), the odometry pose at
    each scan as ``nav_msgs/Odometry`` on ``odom_topic`` (``odometry="odometry"``)
    or as the ``odom -> base_link`` transform on ``/tf`` (``odometry="tf"``),
    and the laser's mounting (``log.sensor_offset``) once on ``/tf_static``.

    Parameters
    ----------
    path : path
        A ``.bag`` file (``storage="rosbag1"``) or a ROS 2 bag folder
        (``"sqlite3"`` or ``"mcap"``). An existing bag there is replaced.
    log : LaserLog
        Its times must not go backwards.
    storage : {"rosbag1", "sqlite3", "mcap"}
    odometry : {"odometry", "tf"}
    scan_topic, odom_topic : str
    frames : (odom, base, laser)
        Frame names.
    time_offset : float
        Seconds added to every time stamp (bag times must not be negative).

    Returns
    -------
    Path
    """
    if not isinstance(log, LaserLog):
        raise TypeError(f"log must be a LaserLog; got {type(log).__name__}")
    if odometry not in ("odometry", "tf"):
        raise ValueError(f"odometry must be 'odometry' or 'tf'; got {odometry!r}")
    t_ns = _ns(log.times + float(time_offset))
    if np.any(np.diff(t_ns) < 0):
        raise ValueError("the log's times go backwards; a bag needs non-decreasing time stamps "
                         "(renumber them, e.g. with a fixed scan period)")
    if t_ns[0] < 0:
        raise ValueError(f"bag time stamps must not be negative; the first is {t_ns[0] / _NS_PER_S} s (use time_offset)")
    f_odom, f_base, f_laser = frames
    inc = float(log.angles[1] - log.angles[0]) if log.n_beams > 1 else 0.0
    if log.n_beams > 2 and not np.allclose(np.diff(log.angles), inc, atol=1e-9):
        raise ValueError("a LaserScan needs evenly spaced beams; the log's angles are not")
    with _BagOut(path, storage) as out:
        ty = out.types
        V3, Q = ty["geometry_msgs/msg/Vector3"], ty["geometry_msgs/msg/Quaternion"]
        Tr, TS, TFM = ty["geometry_msgs/msg/Transform"], ty["geometry_msgs/msg/TransformStamped"], \
            ty["tf2_msgs/msg/TFMessage"]

        def tf(t, parent, child, pose):
            q = yaw_to_quaternion(pose[2])
            return TS(header=out.header(t, parent), child_frame_id=child,
                      transform=Tr(translation=V3(x=float(pose[0]), y=float(pose[1]), z=0.0),
                                   rotation=Q(x=0.0, y=0.0, z=float(q[2]), w=float(q[3]))))

        out.write("/tf_static", TFM(transforms=[tf(t_ns[0], f_base, f_laser, log.sensor_offset)]), t_ns[0],
                  latching=True)
        Scan = ty[SCAN_TYPE]
        Odo, PwC, TwC = ty[ODOM_TYPE], ty["geometry_msgs/msg/PoseWithCovariance"], \
            ty["geometry_msgs/msg/TwistWithCovariance"]
        Tw = ty["geometry_msgs/msg/Twist"]
        zero_cov = np.zeros(36)
        for k in range(len(log)):
            t = t_ns[k]
            o = log.odometry[k]
            if odometry == "odometry":
                msg = Odo(header=out.header(t, f_odom), child_frame_id=f_base,
                          pose=PwC(pose=out.pose(*o), covariance=zero_cov),
                          twist=TwC(twist=Tw(linear=V3(x=0.0, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)),
                                    covariance=zero_cov))
                out.write(odom_topic, msg, t)
            else:
                out.write("/tf", TFM(transforms=[tf(t, f_odom, f_base, o)]), t)
            r = np.where(log.ranges[k] >= log.max_range, np.inf, log.ranges[k]).astype(np.float32)
            out.write(scan_topic, Scan(header=out.header(t, f_laser), angle_min=float(log.angles[0]),
                                       angle_max=float(log.angles[-1]), angle_increment=inc, time_increment=0.0,
                                       scan_time=0.0, range_min=0.0, range_max=float(log.max_range), ranges=r,
                                       intensities=np.zeros(0, dtype=np.float32)), t)
    return Path(path)


def write_result_bag(
    path: PathLike,
    times: ArrayLike,
    poses: ArrayLike,
    covariances: ArrayLike | None = None,
    particles: dict[int, NDArray] | None = None,
    storage: str = "rosbag1",
    frame: str = "map",
) -> Path:
    """Write a localization result as a bag: ``/amcl_pose`` and the particle cloud.

    ``/amcl_pose`` gets one ``geometry_msgs/PoseWithCovarianceStamped`` per
    scan (covariance of x, y and yaw in the 6x6 row-major layout, zeros when
    ``covariances`` is None); the particle cloud, ``geometry_msgs/PoseArray``
    on ``/particlecloud`` (ROS 1 AMCL's name) or ``/particle_cloud`` (nav2's),
    at the scans that ``particles`` (scan index -> (M, 3) poses) holds.
    The bag is written under a temporary name and renamed when complete.

    Examples
    --------
    >>> p = write_result_bag(tmp_dir() / "out.bag", [1.0, 2.0], [[0, 0, 0], [1, 0, 0.5]],
    ...                      particles={1: np.zeros((5, 3))})
    >>> sorted(bag_topics(p).items())                          # doctest: +NORMALIZE_WHITESPACE
    [('/amcl_pose', 'geometry_msgs/msg/PoseWithCovarianceStamped'),
     ('/particlecloud', 'geometry_msgs/msg/PoseArray')]
    """
    t_ns = _ns(times)
    est = np.asarray(poses, dtype=float).reshape(-1, 3)
    if est.shape[0] != t_ns.size:
        raise ValueError(f"poses must have one row per time; got {est.shape[0]} poses for {t_ns.size} times")
    cov = None if covariances is None else np.asarray(covariances, dtype=float).reshape(-1, 3, 3)
    if t_ns.size and t_ns.min() <= 0:
        t_ns = t_ns - t_ns.min() + 1
    cloud_topic = "/particlecloud" if storage == "rosbag1" else "/particle_cloud"
    with _BagOut(path, storage) as out:
        ty = out.types
        PwCS, PwC, PA = (ty[f"geometry_msgs/msg/{n}"] for n in ("PoseWithCovarianceStamped", "PoseWithCovariance",
                                                                 "PoseArray"))
        idx = (0, 1, 5)
        for k in range(t_ns.size):
            c6 = np.zeros((6, 6))
            if cov is not None:
                c6[np.ix_(idx, idx)] = cov[k]
            out.write("/amcl_pose", PwCS(header=out.header(t_ns[k], frame),
                                         pose=PwC(pose=out.pose(*est[k]), covariance=c6.reshape(-1))), t_ns[k])
            if particles and k in particles:
                out.write_raw(cloud_topic, PA.__msgtype__,
                              _pose_array_bytes(out.version, t_ns[k], frame, particles[k]), t_ns[k])
    return Path(path)

