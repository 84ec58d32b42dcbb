"""ROS bags whose messages lie (issue 39, finding 2), and property tests over their fields.

Odometry and /tf quaternions that are not of unit length are normalised (as tf2
does); a zero or NaN one is an error naming the topic and the message. A
LaserScan layout that cannot be (angle_increment 0, NaN, or not fitting
angle_min, angle_max and the beam count; range_min above range_max) is an error
naming the scan and the field.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from localize import io  # noqa: E402
from localize.io import FormatError, rosbag  # noqa: E402

TS1 = get_typestore(Stores.ROS1_NOETIC)
TS1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms\n", "tf2_msgs/msg/TFMessage"))
TY = TS1.types
SCAN_T, ODOM_T, TF_T = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"
ANGLES = np.radians(np.arange(-90.0, 90.0, 2.0))
FAST = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def hdr(t, frame):
    T, H = TY["builtin_interfaces/msg/Time"], TY["std_msgs/msg/Header"]
    return H(seq=0, stamp=T(sec=int(t), nanosec=int(round((t - int(t)) * 1e9))), frame_id=frame)


def scan(t, n=ANGLES.size, angle_min=float(ANGLES[0]), angle_max=float(ANGLES[-1]),
         angle_increment=float(ANGLES[1] - ANGLES[0]), range_min=0.1, range_max=10.0, frame="base_link"):
    return TY[SCAN_T](header=hdr(t, frame), angle_min=angle_min, angle_max=angle_max, angle_increment=angle_increment,
                      time_increment=0.0, scan_time=0.0, range_min=range_min, range_max=range_max,
                      ranges=np.full(n, 3.0, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))


def quat(x=0.0, y=0.0, z=0.0, w=1.0):
    return TY["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w))


def odom(t, x, yaw, scale=1.0, q=None):
    q = quat(0.0, 0.0, scale * np.sin(yaw / 2), scale * np.cos(yaw / 2)) if q is None else q
    P, V3 = TY["geometry_msgs/msg/Point"], TY["geometry_msgs/msg/Vector3"]
    pose = TY["geometry_msgs/msg/PoseWithCovariance"](
        pose=TY["geometry_msgs/msg/Pose"](position=P(x=x, y=0.0, z=0.0), orientation=q), covariance=np.zeros(36))
    tw = TY["geometry_msgs/msg/TwistWithCovariance"](
        twist=TY["geometry_msgs/msg/Twist"](linear=V3(x=0.0, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)),
        covariance=np.zeros(36))
    return TY[ODOM_T](header=hdr(t, "odom"), child_frame_id="base_link", pose=pose, twist=tw)


def tf(t, parent, child, x, y, q):
    V3 = TY["geometry_msgs/msg/Vector3"]
    return TY["geometry_msgs/msg/TransformStamped"](
        header=hdr(t, parent), child_frame_id=child,
        transform=TY["geometry_msgs/msg/Transform"](translation=V3(x=x, y=y, z=0.0), rotation=q))


def write(path, messages):
    with Writer1(path) as w:
        conns = {}
        for topic, typ, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=TS1)
            w.write(conns[topic], int(round(t * 1e9)), TS1.serialize_ros1(msg, typ))
    return path


def bag(tmp_path, n=5, scans=None, odoms=None, extra=()):
    """Scans at 1.0, 1.5, ... s with odometry around each; ``scans``/``odoms`` replace message k."""
    msgs = list(extra)
    for k in range(n):
        t = 1.0 + 0.5 * k
        msgs.append(("/odom", ODOM_T, t - 0.01, (odoms or {}).get(k, odom(t - 0.01, 0.1 * k, 0.3 * k))))
        msgs.append(("/scan", SCAN_T, t, (scans or {}).get(k, scan(t))))
    msgs.append(("/odom", ODOM_T, 1.0 + 0.5 * n, odom(1.0 + 0.5 * n, 0.1 * n, 0.3 * n)))
    return write(tmp_path / "b.bag", sorted(msgs, key=lambda m: m[2]))


# ------------------------------------------------------------------ odometry quaternions
@pytest.mark.parametrize("scale", [2.0, 0.5])
def test_an_odometry_quaternion_of_the_wrong_length_gives_the_right_heading(tmp_path, scale):
    exact = io.read_rosbag(bag(tmp_path)).odometry
    (tmp_path / "b.bag").unlink()
    scaled = io.read_rosbag(bag(tmp_path, odoms={k: odom(1.0 + 0.5 * k - 0.01, 0.1 * k, 0.3 * k, scale=scale)
                                                 for k in range(5)})).odometry
    assert np.allclose(scaled, exact, atol=1e-9)  # without normalising: headings off by up to tens of degrees


@pytest.mark.parametrize("q, shown", [((0, 0, 0, 0), "(0, 0, 0, 0)"), ((0, 0, np.nan, 1), "(0, 0, nan, 1)")])
def test_a_zero_or_nan_odometry_quaternion_names_the_topic_and_message(tmp_path, q, shown):
    b = bag(tmp_path, odoms={2: odom(1.99, 0.2, 0.6, q=quat(*q))})
    with pytest.raises(FormatError, match=r"/odom: message 2 \(stamp 1\.990000000 s\): the orientation quaternion "
                                          r"\(x, y, z, w\) = " + re.escape(shown) + " has no direction"):
        io.read_rosbag(b)


def test_a_zero_tf_static_quaternion_names_the_message_and_frames(tmp_path):
    static = ("/tf_static", TF_T, 0.5, TY[TF_T](transforms=[tf(0.5, "base_link", "laser", 0.2, 0.0, quat(0, 0, 0, 0))]))
    b = bag(tmp_path, scans={k: scan(1.0 + 0.5 * k, frame="laser") for k in range(5)}, extra=[static])
    with pytest.raises(FormatError, match=r"/tf_static: message 0, transform base_link -> laser: the orientation "
                                          r"quaternion .* has no direction"):
        io.read_rosbag(b)


# ------------------------------------------------------------------ scan layouts
@pytest.mark.parametrize("fields, message", [
    ({"angle_increment": 0.0}, "angle_increment is 0 with 90 beams: every beam would point at angle_min"),
    ({"angle_increment": float("nan")}, "angle_increment is nan; expected a finite number"),
    ({"angle_increment": float(ANGLES[1] - ANGLES[0]) / 2}, "angle_increment does not fit angle_min, angle_max"),
    ({"range_min": 20.0}, r"range_min \(20 m\) is above range_max \(10 m\): no reading could be valid"),
    ({"range_max": 0.0}, "range_max is 0.0; expected a positive number"),
])
@pytest.mark.parametrize("k", [0, 3])
def test_a_scan_layout_that_cannot_be_names_the_scan_and_the_field(tmp_path, fields, message, k):
    b = bag(tmp_path, scans={k: scan(1.0 + 0.5 * k, **fields)})
    with pytest.raises(FormatError, match=rf"/scan: scan {k} \(stamp {1.0 + 0.5 * k:.9f} s\): {message}"):
        io.read_rosbag(b)


def test_a_changed_layout_names_the_field_that_changed(tmp_path):
    b = bag(tmp_path, scans={2: scan(2.0, range_max=12.0)})
    with pytest.raises(FormatError, match=r"/scan: scan 2 has another layout than scan 0: range_max 12\.0 "
                                          r"\(scan 0: 10\.0\)") as e:
        io.read_rosbag(b)
    assert str(e.value).count("range_max") == 1  # names what differs, not two layouts to compare by eye


def test_a_scanner_turning_clockwise_and_an_off_by_one_angle_max_are_read(tmp_path):
    inc = float(ANGLES[1] - ANGLES[0])
    b = bag(tmp_path, scans={k: scan(1.0 + 0.5 * k, angle_min=float(ANGLES[-1]), angle_max=float(ANGLES[0]),
                                     angle_increment=-inc) for k in range(5)})
    assert np.allclose(io.read_rosbag(b).angles, ANGLES[::-1], atol=1e-6)
    (tmp_path / "b.bag").unlink()
    b = bag(tmp_path, scans={k: scan(1.0 + 0.5 * k, angle_max=float(ANGLES[-1]) + inc) for k in range(5)})
    assert np.allclose(io.read_rosbag(b).angles, ANGLES, atol=1e-6)


# ------------------------------------------------------------------ hypothesis: the fields of the messages
@FAST
@given(scale=st.floats(0.05, 20.0), sign=st.sampled_from([1.0, -1.0]), yaws=st.lists(st.floats(-3.1, 3.1),
                                                                                       min_size=6, max_size=6))
def test_any_odometry_quaternion_length_gives_the_unit_quaternion_heading(tmp_path, scale, sign, yaws):
    path = tmp_path / "b.bag"
    odoms = {k: odom(1.0 + 0.5 * k - 0.01, 0.1 * k, yaws[k], scale=sign * scale) for k in range(5)}
    path.unlink(missing_ok=True)
    log = io.read_rosbag(bag(tmp_path, odoms=odoms))
    assert np.allclose(log.odom_poses[:5, 2], np.array(yaws[:5]), atol=1e-9)  # q and -q are one rotation


@FAST
@given(n=st.integers(1, 50), a_min=st.floats(-3.2, 0.0), inc=st.just(0.0) | st.floats(1e-3, 0.2) | st.floats(-0.2, -1e-3), end_error=st.integers(-3, 3),
       r_min=st.floats(0.0, 5.0), r_max=st.floats(0.01, 30.0), bad=st.sampled_from([None, "angle_min", "angle_max",
                                                                                   "angle_increment", "range_min",
                                                                                   "range_max"]))
def test_any_scan_layout_is_read_as_written_or_named(tmp_path, n, a_min, inc, end_error, r_min, r_max, bad):
    fields = {"n": n, "angle_min": a_min, "angle_increment": inc,
              "angle_max": a_min + (n - 1 + end_error) * inc, "range_min": r_min, "range_max": r_max}
    if bad is not None:
        fields[bad] = float("nan")
    f32 = {k: float(np.float32(v)) for k, v in fields.items() if k != "n"}
    path = tmp_path / "b.bag"
    path.unlink(missing_ok=True)
    b = bag(tmp_path, scans={k: scan(1.0 + 0.5 * k, **fields) for k in range(5)})
    impossible = (bad is not None or r_min > f32["range_max"] or (n > 1 and f32["angle_increment"] == 0)
                  or (n > 1 and abs(end_error) > 1))
    assume(not (n > 1 and abs(end_error) == 1 and f32["angle_increment"] == 0))
    if impossible:
        with pytest.raises(FormatError, match=r"/scan: scan 0 \(stamp 1\.000000000 s\): ") as e:
            io.read_rosbag(b)
        named = bad or ("range_min" if r_min > f32["range_max"] else "angle_increment")
        assert named in e.value.reason
        return
    log = io.read_rosbag(b)
    assert log.angles.size == n and log.max_range == pytest.approx(f32["range_max"], rel=1e-6)
    assert np.allclose(log.angles, f32["angle_min"] + f32["angle_increment"] * np.arange(n), atol=1e-5)
    expected = 3.0 if f32["range_min"] <= 3.0 <= f32["range_max"] else log.max_range  # else: no return
    assert np.allclose(log.ranges, expected)


@FAST
@given(x=st.floats(-1.0, 1.0), y=st.floats(-1.0, 1.0), yaw=st.floats(-3.1, 3.1), scale=st.floats(0.05, 20.0),
       zero=st.booleans())
def test_any_tf_static_mounting_reads_as_written_or_a_zero_rotation_is_named(tmp_path, x, y, yaw, scale, zero):
    q = quat(0, 0, 0, 0) if zero else quat(0.0, 0.0, scale * np.sin(yaw / 2), scale * np.cos(yaw / 2))
    static = ("/tf_static", TF_T, 0.5, TY[TF_T](transforms=[tf(0.5, "base_link", "laser", x, y, q)]))
    path = tmp_path / "b.bag"
    path.unlink(missing_ok=True)
    b = bag(tmp_path, scans={k: scan(1.0 + 0.5 * k, frame="laser") for k in range(5)}, extra=[static])
    if zero:
        with pytest.raises(FormatError, match="/tf_static: message 0, transform base_link -> laser"):
            io.read_rosbag(b)
        return
    off = io.read_rosbag(b).sensor_offset
    assert np.allclose(off, [x, y, yaw], atol=1e-9)


def test_write_then_read_keeps_a_unit_quaternion_bit_for_bit(tmp_path):
    """Valid input reads as before: a unit quaternion is not rescaled (its last bits stay)."""
    yaw = 0.7
    q = rosbag.yaw_to_quaternion(yaw)
    b = bag(tmp_path, odoms={0: odom(0.99, 0.0, 0.0, q=quat(0.0, 0.0, q[2], q[3]))})
    assert io.read_rosbag(b).odom_poses[0, 2] == rosbag.quaternion_to_yaw([0.0, 0.0, q[2], q[3]])
