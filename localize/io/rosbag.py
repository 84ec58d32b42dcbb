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

import math
import os
import shutil
from dataclasses import dataclass, field
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


@dataclass
class _Messages:
    """What one pass over the bag collects: the scans, the odometry samples and the transforms."""

    scan_topic: str
    odom_topics: list[str]
    root: Path
    stamps: list[int] = field(default_factory=list)
    rec: list[int] = field(default_factory=list)
    ranges: list[NDArray] = field(default_factory=list)
    layout: tuple | None = None
    frame: str = ""
    odo: list[tuple[int, float, float, float, str, str]] = field(default_factory=list)
    dyn: dict[tuple[str, str], list[tuple[int, NDArray]]] = field(default_factory=dict)
    static: dict[tuple[str, str], NDArray] = field(default_factory=dict)
    tf_count: dict[str, int] = field(default_factory=dict)


#: (field, value) pairs of a LaserScan's layout, in the order of the layout tuple.
_LAYOUT_FIELDS = ("beams", "angle_min", "angle_increment", "range_min", "range_max")


def _layout_problem(msg: Any, n: int) -> str | None:
    """What makes a LaserScan's layout impossible (a field and why), or None."""
    a_min, a_max, inc = float(msg.angle_min), float(msg.angle_max), float(msg.angle_increment)
    r_min, r_max = float(msg.range_min), float(msg.range_max)
    for name, v in (("angle_min", a_min), ("angle_max", a_max), ("angle_increment", inc), ("range_min", r_min),
                    ("range_max", r_max)):
        if not np.isfinite(v):
            return f"{name} is {v}; expected a finite number"
    if not r_max > 0:
        return f"range_max is {r_max}; expected a positive number of metres"
    if r_min > r_max:
        return f"range_min ({r_min:g} m) is above range_max ({r_max:g} m): no reading could be valid"
    if n > 1 and inc == 0:
        return f"angle_increment is 0 with {n} beams: every beam would point at angle_min"
    # the last beam ends at angle_max; drivers that count one beam more or less are accepted
    if n > 1 and abs((a_max - a_min) / inc - (n - 1)) > 1.0 + 1e-3:
        return (f"angle_increment does not fit angle_min, angle_max and the {n} beams: angle_min {a_min:g} + "
                f"{n - 1} x angle_increment {inc:g} = {a_min + (n - 1) * inc:g} rad, but angle_max is {a_max:g} rad")
    return None


def _take_scan(m: _Messages, msg: Any, rec_time: int) -> None:
    n = len(msg.ranges)
    lay = (n, float(msg.angle_min), float(msg.angle_increment), float(msg.range_min), float(msg.range_max))
    k = len(m.stamps)
    if lay != m.layout:  # the first scan, or one that changed: is it a possible layout?
        problem = _layout_problem(msg, n)
        if problem is not None:
            raise FormatError(m.root, None, f"{m.scan_topic}: scan {k} (stamp {_stamp(msg.header) / _NS_PER_S:.9f} s):"
                                            f" {problem}")
    if m.layout is None:
        m.layout, m.frame = lay, msg.header.frame_id
        if n == 0:
            raise FormatError(m.root, None, f"{m.scan_topic}: the first scan has no ranges")
    elif lay != m.layout:
        changed = ", ".join(f"{f} {a!r} (scan 0: {b!r})" for f, a, b in zip(_LAYOUT_FIELDS, lay, m.layout) if a != b)
        raise FormatError(m.root, None, f"{m.scan_topic}: scan {k} has another layout than scan 0: {changed}; "
                                        "expected one laser with a fixed layout")
    m.stamps.append(_stamp(msg.header))
    m.rec.append(int(rec_time))
    m.ranges.append(np.asarray(msg.ranges, dtype=np.float32))


def _unit_quaternion(q: Any, where: str) -> list[float]:
    """``(x, y, z, w)`` scaled to unit length (tf2 does the same); a zero or NaN one is an error naming ``where``."""
    v = [float(q.x), float(q.y), float(q.z), float(q.w)]
    n = math.sqrt(sum(c * c for c in v))
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"{where}: the orientation quaternion (x, y, z, w) = ({', '.join(f'{c:g}' for c in v)}) "
                         "has no direction (zero or not a number); expected a unit quaternion")
    return v if abs(n - 1.0) <= 1e-9 else [c / n for c in v]


def _take_odom(m: _Messages, msg: Any) -> None:
    p = msg.pose.pose
    where = f"{m.odom_topics[0]}: message {len(m.odo)} (stamp {_stamp(msg.header) / _NS_PER_S:.9f} s)"
    try:
        q = _unit_quaternion(p.orientation, where)
    except ValueError as exc:
        raise FormatError(m.root, None, str(exc)) from None
    m.odo.append((_stamp(msg.header), float(p.position.x), float(p.position.y), float(quaternion_to_yaw(q)),
                  msg.header.frame_id, msg.child_frame_id))


def _take_tf(m: _Messages, topic: str, msg: Any) -> None:
    k = m.tf_count[topic] = m.tf_count.get(topic, -1) + 1
    for tr in msg.transforms:
        t, r = tr.transform.translation, tr.transform.rotation
        key = (tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"))
        try:
            mat = _matrix([t.x, t.y, t.z], _unit_quaternion(r, f"{topic}: message {k}, transform {key[0]} -> "
                                                               f"{key[1]}"))
        except ValueError as exc:
            raise FormatError(m.root, None, str(exc)) from None
        if topic.endswith("tf_static"):
            m.static[key] = mat
        else:
            m.dyn.setdefault(key, []).append((_stamp(tr.header), mat))


def _collect(root: Path, reader, conns, scan_t: str, odom_t: list[str]) -> _Messages:
    m = _Messages(scan_topic=scan_t, odom_topics=odom_t, root=root)
    for conn, rec_time, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        if conn.topic == scan_t:
            _take_scan(m, msg, rec_time)
        elif conn.topic in odom_t:
            _take_odom(m, msg)
        else:
            _take_tf(m, conn.topic, msg)
    if not m.stamps:
        raise FormatError(root, None, f"{scan_t} holds no messages")
    return m


def _odometry_topic(m: _Messages, meta: dict) -> tuple[NDArray, NDArray, str, str]:
    topic = m.odom_topics[0]
    o_st = np.array([o[0] for o in m.odo], dtype=np.int64)
    if o_st.size == 0:
        raise FormatError(m.root, None, f"scans without odometry: {topic} holds no messages")
    _check_time(m.root, topic, o_st)
    o_pose = np.array([o[1:4] for o in m.odo], dtype=float)
    parent, base = m.odo[0][4].lstrip("/") or "odom", m.odo[0][5].lstrip("/") or "base_link"
    meta["odometry"] = f"nav_msgs/Odometry on {topic} ({parent} -> {base})"
    meta["odom_topic"] = topic
    return o_st, o_pose, parent, base


def _odometry_tf(m: _Messages, meta: dict, topics: dict[str, str], odom_frame: str | None, frame: str
                 ) -> tuple[NDArray, NDArray, str, str]:
    pairs = sorted(m.dyn)
    if not pairs:
        raise FormatError(m.root, None, f"scans without odometry: the bag has no {ODOM_TYPE} topic and no "
                                        f"transforms on /tf; {_topic_list(topics)}")
    if odom_frame is not None:
        cands = [p for p in pairs if p[0] == odom_frame]
    else:
        cands = [p for p in pairs if p[0] == "odom"] or [p for p in pairs if p[0] not in _GLOBAL_FRAMES]
    if len(cands) > 1:  # keep the one whose child reaches the laser through static transforms
        linked = [p for p in cands if _tf_graph_pose(m.static, p[1], frame) is not None]
        cands = linked if linked else cands
    if len(cands) != 1:
        listed = ", ".join(f"{a} -> {b}" for a, b in pairs)
        raise FormatError(m.root, None, f"scans without odometry: cannot tell the odometry transform on /tf "
                                        f"(transforms there: {listed}); expected one odom -> base transform, or a "
                                        f"{ODOM_TYPE} topic (--odom-topic)")
    parent, base = cands[0]
    seq = m.dyn[cands[0]]
    o_st = np.array([s for s, _ in seq], dtype=np.int64)
    _check_time(m.root, f"/tf ({parent} -> {base})", o_st)
    o_pose = np.array([[t[0, 3], t[1, 3], np.arctan2(t[1, 0], t[0, 0])] for _, t in seq])
    meta["odometry"] = f"/tf transform {parent} -> {base}"
    return o_st, o_pose, parent, base


def _laser_mounting(m: _Messages, meta: dict, laser_pose, parent: str, base: str, frame: str
                    ) -> tuple[NDArray, bool]:
    """The laser's pose in the base frame (x, y, yaw) and whether it is mounted upside down."""
    if laser_pose is not None:
        off = np.asarray(laser_pose, dtype=float).reshape(-1)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ValueError(f"laser_pose must be three finite numbers (x, y, yaw); got {laser_pose!r}")
        meta["sensor_offset_source"] = "given (laser_pose / --laser-pose)"
        return off, False
    edges = dict(m.static)
    for key, seq in m.dyn.items():  # constant transforms on /tf count as static
        if key != (parent, base) and all(np.allclose(t, seq[0][1], atol=1e-9) for _, t in seq):
            edges.setdefault(key, seq[0][1])
    t = _tf_graph_pose(edges, base, frame)
    if t is None:
        known = sorted({f for k in m.static for f in k})
        raise FormatError(m.root, None, f"no transform from the base frame '{base}' to the laser frame '{frame}' "
                                        f"on /tf_static (frames there: {', '.join(known) or 'none'}); give the "
                                        "laser's mounting pose with --laser-pose X Y YAW (metres, radians; "
                                        "0 0 0 if the laser sits at the robot's centre)")
    off = np.array([t[0, 3], t[1, 3], np.arctan2(t[1, 0], t[0, 0])])
    flip = bool(t[2, 2] < 0)
    if abs(t[2, 2]) < np.cos(np.radians(5.0)):
        meta["sensor_tilt_warning"] = f"the laser is tilted {np.degrees(np.arccos(abs(t[2, 2]))):.1f} degrees"
    meta["sensor_offset_source"] = f"/tf_static chain {base} -> {frame}" + (" (mounted upside down)" if flip else "")
    return off, flip


def _scan_arrays(m: _Messages) -> tuple[NDArray, NDArray, NDArray, float, float, tuple[NDArray, NDArray]]:
    """Beam angles, ranges (no return = range_max), the invalid-reading mask, range_max, range_min, and the
    finite readings above range_max with the scan of each, ``(scans, readings)`` (ROS discards them; a run
    warns when they are many)."""
    n_beams, a_min, a_inc, r_min, r_max = m.layout
    deg = np.pi / 180.0
    a0 = float(_decimal(np.float32([a_min]), scale=deg)[0])
    da = float(_decimal(np.float32([a_inc]), scale=deg)[0])
    angles = a0 + da * np.arange(n_beams)
    mr = float(_decimal(np.float32([r_max]))[0])
    mn = float(_decimal(np.float32([r_min]))[0])
    ranges = _decimal(np.vstack(m.ranges))
    finite, over = np.isfinite(ranges), ranges > mr
    bad = ~finite | (ranges < mn) | over
    rows, cols = np.nonzero(finite & over)
    above = (rows, ranges[rows, cols])
    ranges[bad] = mr
    return angles, ranges, bad, mr, mn, above


def _interpolate(o_st: NDArray, o_pose: NDArray, ts: NDArray, meta: dict) -> NDArray:
    """The odometry pose at each scan time: linear between the samples around it (AMCL asks tf the same)."""
    j = np.clip(np.searchsorted(o_st, ts, side="right") - 1, 0, max(o_st.size - 2, 0))
    odom = np.empty((ts.size, 3))
    if o_st.size == 1:
        odom[:] = o_pose[0]
        return odom
    t0, t1 = o_st[j], o_st[j + 1]
    frac = (ts - t0) / (t1 - t0)
    p0, p1 = o_pose[j], o_pose[j + 1]
    odom[:, :2] = p0[:, :2] + frac[:, None] * (p1[:, :2] - p0[:, :2])
    odom[:, 2] = wrap_angle(p0[:, 2] + frac * wrap_angle(p1[:, 2] - p0[:, 2]))
    exact0, exact1 = frac == 0, frac == 1
    odom[exact0], odom[exact1] = p0[exact0], p1[exact1]
    meta["largest_odometry_gap_s"] = round(float(np.max(t1 - t0)) / _NS_PER_S, 6)
    return odom


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
    m = _collect(root, reader, [c for c in reader.connections if c.topic in wanted], scan_t, odom_t)
    frame = m.frame.lstrip("/")
    stamps = np.asarray(m.stamps, dtype=np.int64)
    meta: dict[str, Any] = {"scan_topic": scan_t, "scan_frame": frame, "bag_format": fmt}
    if np.all(stamps == 0):
        stamps = np.asarray(m.rec, dtype=np.int64)
        meta["scan_stamps"] = "header stamps are zero: the bag's record times are used"
    _check_time(root, scan_t, stamps)
    if odom_t:
        o_st, o_pose, parent, base = _odometry_topic(m, meta)
    else:
        o_st, o_pose, parent, base = _odometry_tf(m, meta, topics, odom_frame, frame)
    keep = np.append(o_st[1:] != o_st[:-1], True)  # equal stamps: keep the last sample of each
    o_st, o_pose = o_st[keep], o_pose[keep]
    o_pose[:, 2] = wrap_angle(o_pose[:, 2])
    meta["base_frame"], meta["odom_frame"] = base, parent
    off, flip = _laser_mounting(m, meta, laser_pose, parent, base, frame)
    angles, ranges, bad, mr, mn, above = _scan_arrays(m)
    if flip:
        angles, ranges = -angles[::-1], ranges[:, ::-1]
    inside = (stamps >= o_st[0]) & (stamps <= o_st[-1])
    dropped = int((~inside).sum())
    if not np.any(inside):
        raise FormatError(root, None, f"scans without odometry: none of the {stamps.size} scans on {scan_t} "
                                      f"({stamps[0] / _NS_PER_S:.3f} .. {stamps[-1] / _NS_PER_S:.3f} s) falls within the "
                                      f"odometry's time span ({o_st[0] / _NS_PER_S:.3f} .. {o_st[-1] / _NS_PER_S:.3f} s)")
    meta["invalid_readings"] = int(bad[inside].sum())  # NaN, inf, outside [range_min, range_max]: no return
    scan_of, over = above
    over = over[inside[scan_of]]                        # those of the scans kept
    if over.size:                                       # discarded, as ROS specifies; counted for the run's warning
        meta["above_range_max"] = {"readings": int(over.size), "distinct": int(np.unique(over).size),
                                   "largest": float(over.max()), "share": float(over.size / ranges[inside].size)}
    ts = stamps[inside]
    odom = _interpolate(o_st, o_pose, ts, meta)
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

