"""ROS bags in and out (localize.io.rosbag, localize.io.tum, the CLI's bag path).

The bags are written with rosbags' own writers (ROS 1 ``.bag``, ROS 2 sqlite3 and
MCAP) from the first 200 scans of the real Intel Research Lab log, with the
laser mounted off-centre on ``/tf_static``; localizing from them must give
exactly the trajectory of the original log with the same seed. Bad bags are
made with rosbags directly.
"""

from __future__ import annotations

import csv
import io as stdio
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from localize import cli, io, mapping, maps  # noqa: E402
from localize.io import rosbag  # noqa: E402
from localize.io.tum import read_tum, write_tum  # noqa: E402

OFFSET = (0.12, -0.03, 0.02)  # the laser's mounting on /tf_static (x, y, yaw)
N_SCANS = 200
FORMATS = [("rosbag1", "odometry", "intel.bag"), ("sqlite3", "tf", "intel_sqlite"), ("mcap", "odometry", "intel_mcap")]


def run_cli(*argv):
    out, err = stdio.StringIO(), stdio.StringIO()
    status = cli.main([str(a) for a in argv], stdout=out, stderr=err)
    return status, out.getvalue(), err.getvalue()


def trajectory(path: Path) -> tuple[list[list[str]], list[dict]]:
    rows = list(csv.DictReader(open(path)))
    return [[r["x"], r["y"], r["theta"]] for r in rows], rows


# ------------------------------------------------------------------ fixtures on the Intel log
@pytest.fixture(scope="module")
def intel(shared_data, tmp_path_factory):
    """The first 200 Intel scans (laser offset replaced by OFFSET), their map, and the log file."""
    path = shared_data / "carmen" / "intel-corrected.log.gz"
    if not path.exists():
        pytest.skip(f"{path} not found")
    log = io.read_log(path).select(slice(0, N_SCANS))
    log = replace(log, sensor_offset=np.array(OFFSET))
    d = tmp_path_factory.mktemp("intel")
    grid = mapping.map_from_log(log, resolution=0.1)
    map_path = io.write_ros_map(d / "intel.yaml", grid)
    return path, log, map_path, d


@pytest.fixture(scope="module")
def bags(intel):
    _, log, _, d = intel
    return {fmt: rosbag.write_rosbag_log(d / name, log, storage=fmt, odometry=odo) for fmt, odo, name in FORMATS}


@pytest.fixture(scope="module")
def carmen_run(intel):
    path, _, map_path, d = intel
    out = d / "from_log"
    status, _, err = run_cli("run", "--map", map_path, "--log", path, "--scans", f"0:{N_SCANS}", "--laser-pose",
                             *OFFSET, "--particles", 1000, "--seed", 5, "--out", out, "--quiet")
    assert status == 0, err
    return out


# ------------------------------------------------------------------ reading
@pytest.mark.data
@pytest.mark.parametrize("fmt", [f[0] for f in FORMATS])
def test_bag_reads_back_the_log(intel, bags, fmt):
    _, log, _, _ = intel
    back = io.read_rosbag(bags[fmt])
    assert back.format == fmt and len(back) == N_SCANS and back.poses is None
    assert np.allclose(back.times, log.times, rtol=0, atol=1e-9)
    assert np.allclose(back.odometry, log.odometry, rtol=0, atol=1e-12)
    # float32 ranges and angles come back as the log's decimals, bit for bit
    assert np.array_equal(back.ranges, log.ranges)
    assert np.array_equal(back.angles, log.angles)
    assert back.max_range == log.max_range
    assert np.allclose(back.sensor_offset, OFFSET, rtol=0, atol=1e-12)
    assert back.meta["scan_topic"] == "/scan" and back.meta["base_frame"] == "base_link"
    assert ("/tf" in back.meta["odometry"]) == (dict((f[0], f[1]) for f in FORMATS)[fmt] == "tf")
    assert io.is_rosbag(bags[fmt])


@pytest.mark.data
@pytest.mark.slow
@pytest.mark.parametrize("fmt", [f[0] for f in FORMATS])
def test_cli_localizes_the_bag_exactly_as_the_log(intel, bags, carmen_run, fmt, tmp_path):
    _, _, map_path, _ = intel
    out = tmp_path / "from_bag"
    status, _, err = run_cli("run", "--map", map_path, "--log", bags[fmt], "--particles", 1000, "--seed", 5,
                             "--out", out, "--quiet")
    assert status == 0, err
    a, rows_a = trajectory(carmen_run / "trajectory.csv")
    b, rows_b = trajectory(out / "trajectory.csv")
    assert len(a) == len(b) == N_SCANS
    assert a == b  # the same estimates, digit for digit
    assert [r["time"] for r in rows_a] == [r["time"] for r in rows_b]
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["log_format"] == fmt
    assert s["settings"]["laser_pose"] == list(OFFSET)
    # the result bag: one /amcl_pose per scan, equal to the trajectory, and particle clouds
    res = out / ("localization.bag" if fmt == "rosbag1" else "localization_bag")
    assert res.exists() and not res.with_name(res.name + ".partial").exists()
    with AnyReader([res]) as r:
        topics = {c.topic: c.msgtype for c in r.connections}
        assert topics["/amcl_pose"] == "geometry_msgs/msg/PoseWithCovarianceStamped"
        cloud = "/particlecloud" if fmt == "rosbag1" else "/particle_cloud"
        assert topics[cloud] == "geometry_msgs/msg/PoseArray"
        poses, n_clouds = [], 0
        for c, _, raw in r.messages():
            m = r.deserialize(raw, c.msgtype)
            if c.topic == "/amcl_pose":
                q = m.pose.pose.orientation
                poses.append([m.pose.pose.position.x, m.pose.pose.position.y,
                              float(rosbag.quaternion_to_yaw([q.x, q.y, q.z, q.w]))])
                cov = m.pose.covariance.reshape(6, 6)
                assert cov[0, 0] >= 0 and cov[1, 1] >= 0 and np.allclose(cov, cov.T)
            else:
                n_clouds += 1
                assert len(m.poses) == 1000
    assert len(poses) == N_SCANS and n_clouds >= 2
    assert np.allclose(poses, np.array(b, dtype=float), atol=2e-6)


@pytest.mark.data
def test_tum_output_reads_back_and_gives_the_ape(carmen_run):
    """trajectory.tum and reference.tum hold the estimates and the corrected poses; APE from them."""
    t, est = read_tum(carmen_run / "trajectory.tum")
    t_ref, ref = read_tum(carmen_run / "reference.tum")
    _, rows = trajectory(carmen_run / "trajectory.csv")
    assert np.allclose(t, [float(r["time"]) for r in rows], atol=1e-9) and np.array_equal(t, t_ref)
    for poses, keys in ((est, ("x", "y", "theta")), (ref, ("ref_x", "ref_y", "ref_theta"))):
        csv_poses = np.array([[float(r[k]) for k in keys] for r in rows])
        assert np.allclose(poses[:, :2], csv_poses[:, :2], atol=1e-6)
        assert np.allclose(np.angle(np.exp(1j * (poses[:, 2] - csv_poses[:, 2]))), 0, atol=1e-6)
    ape = np.hypot(*(est[:, :2] - ref[:, :2]).T)  # what evo_ape computes (translation part, no alignment)
    assert np.allclose(ape, [float(r["error"]) for r in rows], atol=1e-4)
    for line in (carmen_run / "trajectory.tum").read_text().splitlines():
        if not line.startswith("#"):
            assert len(line.split(" ")) == 8 and not line.endswith(" ")  # evo's reader: 8 fields, no trailing blank


def test_tum_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.normal(size=(50, 2)) * 10, rng.uniform(-np.pi, np.pi, 50)])
    t = np.cumsum(rng.uniform(0.05, 0.2, 50))
    p = write_tum(tmp_path / "a.tum", t, poses)
    t2, back = read_tum(p)
    assert np.allclose(t2, t, atol=1e-9) and np.allclose(back[:, :2], poses[:, :2], atol=1e-6)
    assert np.allclose(np.angle(np.exp(1j * (back[:, 2] - poses[:, 2]))), 0, atol=1e-8)
    (tmp_path / "bad.tum").write_text("1 2 3 4 5 6 7\n")
    with pytest.raises(io.FormatError, match="bad.tum:1: a TUM line has 8 fields"):
        read_tum(tmp_path / "bad.tum")
    with pytest.raises(ValueError, match="finite"):
        write_tum(tmp_path / "c.tum", [0.0], [[np.nan, 0, 0]])


# ------------------------------------------------------------------ bags made by hand
TS1 = get_typestore(Stores.ROS1_NOETIC)
ANGLES = np.radians(np.arange(-90.0, 90.0, 2.0))


def _hdr(t, frame):
    T, H = TS1.types["builtin_interfaces/msg/Time"], TS1.types["std_msgs/msg/Header"]
    return H(seq=0, stamp=T(sec=int(t), nanosec=int(round((t - int(t)) * 1e9))), frame_id=frame)


def _scan(t, ranges, frame="laser", range_min=0.1, range_max=10.0):
    S = TS1.types["sensor_msgs/msg/LaserScan"]
    return S(header=_hdr(t, frame), angle_min=float(ANGLES[0]), angle_max=float(ANGLES[-1]),
             angle_increment=float(ANGLES[1] - ANGLES[0]), time_increment=0.0, scan_time=0.0,
             range_min=range_min, range_max=range_max, ranges=np.asarray(ranges, dtype=np.float32),
             intensities=np.zeros(0, dtype=np.float32))


def _odom(t, x, y, th):
    ty = TS1.types
    V3, P, Q = ty["geometry_msgs/msg/Vector3"], ty["geometry_msgs/msg/Point"], ty["geometry_msgs/msg/Quaternion"]
    q = rosbag.yaw_to_quaternion(th)
    pose = ty["geometry_msgs/msg/PoseWithCovariance"](
        pose=ty["geometry_msgs/msg/Pose"](position=P(x=x, y=y, z=0.0), orientation=Q(x=0.0, y=0.0, z=q[2], w=q[3])),
        covariance=np.zeros(36))
    tw = ty["geometry_msgs/msg/TwistWithCovariance"](
        twist=ty["geometry_msgs/msg/Twist"](linear=V3(x=0.0, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0)),
        covariance=np.zeros(36))
    return ty["nav_msgs/msg/Odometry"](header=_hdr(t, "odom"), child_frame_id="base_link", pose=pose, twist=tw)


def _write(path, messages):
    """A ROS 1 bag of (topic, msgtype, time, message)."""
    with Writer1(path) as w:
        conns = {}
        for topic, typ, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=TS1)
            w.write(conns[topic], int(round(t * 1e9)), TS1.serialize_ros1(msg, typ))
    return path


SCAN_T, ODOM_T = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"


def _good(n=6, scans=True, odom=True, scan_times=None, extra_scan_topic=False):
    msgs = []
    times = np.arange(1.0, 1.0 + 0.5 * n, 0.5) if scan_times is None else scan_times
    for k, t in enumerate(times):  # recorded in order every 0.5 s; the header stamps are t
        rec = 1.0 + 0.5 * k
        if odom:
            msgs.append(("/odom", ODOM_T, rec - 0.01, _odom(rec - 0.01, 0.1 * k, 0.0, 0.05 * k)))
            msgs.append(("/odom", ODOM_T, rec + 0.2, _odom(rec + 0.2, 0.1 * k + 0.04, 0.0, 0.05 * k + 0.02)))
        if scans:
            msgs.append(("/scan", SCAN_T, rec, _scan(t, np.full(ANGLES.size, 3.0), frame="base_link")))
            if extra_scan_topic:
                msgs.append(("/rear/scan", SCAN_T, rec, _scan(t, np.full(ANGLES.size, 3.0), frame="base_link")))
    return msgs


def test_hand_made_bag_interpolates_odometry_and_reads_invalid_readings(tmp_path):
    r = np.full(ANGLES.size, 3.0)
    r[:4] = [np.nan, np.inf, -np.inf, 0.05]  # invalid, no return, too close, below range_min
    r[4] = 12.0  # above range_max
    msgs = [("/scan", SCAN_T, 0.5, _scan(0.5, r, frame="base_link")),  # before the odometry starts: dropped
            ("/odom", ODOM_T, 0.9, _odom(0.9, 0.0, 0.0, 3.0)), ("/odom", ODOM_T, 1.9, _odom(1.9, 1.0, 0.5, -3.0)),
            ("/scan", SCAN_T, 1.15, _scan(1.15, r, frame="base_link"))]
    bag = _write(tmp_path / "a.bag", msgs)
    log = io.read_rosbag(bag)
    assert log.skipped == {"scans outside the odometry's time span": 1}
    assert len(log) == 1 and log.max_range == 10.0 and log.times[0] == 1.15
    assert np.array_equal(log.ranges[0, :5], np.full(5, 10.0)) and log.ranges[0, 5] == 3.0
    assert log.meta["invalid_readings"] == 5
    # a quarter of the way from 0.9 s to 1.9 s; the heading crosses +-pi the short way
    assert np.allclose(log.odometry[0], [0.25, 0.125, 3.0 + 0.25 * (2 * np.pi - 6.0)], atol=1e-12)
    assert np.allclose(log.angles, ANGLES, atol=1e-7) and np.allclose(log.sensor_offset, 0)
    # the CLI says which scans it dropped; --min-range turns short readings into "no return"
    args = cli.build_parser().parse_args(["run", "--log", str(bag), "--build-map", "--min-range", "3.5"])
    err = stdio.StringIO()
    log2 = cli._load(args, err)
    assert "skipped 1 scans outside the odometry's time span" in err.getvalue()
    assert np.all(log2.ranges[0] == 10.0)


def test_laser_chain_upside_down_mount_and_odometry_on_tf(tmp_path):
    ty = TS1.types
    TS1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms\n", "tf2_msgs/msg/TFMessage"))
    V3, Q = ty["geometry_msgs/msg/Vector3"], ty["geometry_msgs/msg/Quaternion"]
    TFM = TS1.types["tf2_msgs/msg/TFMessage"]

    def tf(t, parent, child, x, y, q):
        return ty["geometry_msgs/msg/TransformStamped"](
            header=_hdr(t, parent), child_frame_id=child,
            transform=ty["geometry_msgs/msg/Transform"](translation=V3(x=x, y=y, z=0.3), rotation=Q(*q)))

    flipped = (1.0, 0.0, 0.0, 0.0)  # roll = pi: the laser hangs upside down, facing forward
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", 1.0,
             TFM(transforms=[tf(1.0, "base_footprint", "base_link", 0.1, 0.0, (0.0, 0.0, 0.0, 1.0)),
                             tf(1.0, "base_link", "laser", 0.2, 0.05, flipped)]))]
    r = np.linspace(1.0, 5.0, ANGLES.size)
    for k in range(4):
        t = 1.0 + 0.5 * k
        q = rosbag.yaw_to_quaternion(0.1 * k)
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t, TFM(transforms=[
            tf(t, "map", "odom", 5.0, 5.0, (0.0, 0.0, 0.0, 1.0)),  # AMCL's own output: not odometry
            tf(t, "odom", "base_footprint", 0.2 * k, 0.0, (0.0, 0.0, q[2], q[3]))])))
        msgs.append(("/scan", SCAN_T, t, _scan(t, r)))
    bag = _write(tmp_path / "chain.bag", msgs)
    log = io.read_rosbag(bag)
    assert log.meta["odometry"] == "/tf transform odom -> base_footprint"
    # with an Odometry topic too, that is the default, and --odom-topic /tf picks the transform
    wheel = [("/wheel/odom", ODOM_T, 1.0 + 0.5 * k, _odom(1.0 + 0.5 * k, -1.0 * k, 0.0, 0.0)) for k in range(4)]
    wheel = [(t, ty, s, replace(m, child_frame_id="base_footprint")) for t, ty, s, m in wheel]
    bag2 = _write(tmp_path / "both.bag", msgs + wheel)
    assert np.allclose(io.read_rosbag(bag2).odometry[:, 0], [0.0, -1.0, -2.0, -3.0])
    assert np.allclose(io.read_rosbag(bag2, odom_topic="/tf").odometry[:, 0], [0.0, 0.2, 0.4, 0.6])
    assert np.allclose(log.sensor_offset, [0.3, 0.05, 0.0], atol=1e-12)
    assert "upside down" in log.meta["sensor_offset_source"]
    # mirrored: the beam that pointed at angle a now points at -a, order kept increasing
    assert np.allclose(log.angles, -ANGLES[::-1], atol=1e-7) and np.allclose(log.ranges[0], r[::-1], atol=1e-6)
    assert np.allclose(log.odometry[:, 0], [0.0, 0.2, 0.4, 0.6], atol=1e-12)
    # --laser-pose overrides /tf_static
    log2 = io.read_rosbag(bag, laser_pose=(0.0, 0.0, 0.0))
    assert np.allclose(log2.sensor_offset, 0) and np.allclose(log2.angles, ANGLES, atol=1e-7)


def _check_rejected(tmp_path, bag, match, *extra):
    """The CLI refuses the bag with a clear message and writes nothing."""
    out = tmp_path / "out"
    grid_yaml = io.write_ros_map(tmp_path / "m.yaml", maps.office(0.1))
    status, _, err = run_cli("run", "--map", grid_yaml, "--log", bag, "--out", out, "--quiet", *extra)
    assert status == 2
    assert err.startswith("localize: error: ") and "Traceback" not in err
    assert str(bag.name) in err, err
    assert match in err, err
    assert not out.exists()
    return err


def test_bag_without_scan_topic_lists_its_topics(tmp_path):
    bag = _write(tmp_path / "noscan.bag", _good(scans=False))
    err = _check_rejected(tmp_path, bag, "no laser scan topic (sensor_msgs/msg/LaserScan)")
    assert "/odom (nav_msgs/msg/Odometry)" in err


def test_bag_with_two_scan_topics_needs_scan_topic(tmp_path):
    bag = _write(tmp_path / "two.bag", _good(extra_scan_topic=True))
    _check_rejected(tmp_path, bag, "2 laser scan topics (/rear/scan, /scan); choose one with --scan-topic")
    assert len(io.read_rosbag(bag, scan_topic="/rear/scan")) == 6
    with pytest.raises(io.FormatError, match="--scan-topic /front: no such topic"):
        io.read_rosbag(bag, scan_topic="/front")


def test_scans_without_odometry(tmp_path):
    bag = _write(tmp_path / "noodom.bag", _good(odom=False))
    _check_rejected(tmp_path, bag, "scans without odometry")
    # odometry that ends before the scans begin
    msgs = [("/odom", ODOM_T, 0.1, _odom(0.1, 0, 0, 0)), ("/odom", ODOM_T, 0.2, _odom(0.2, 0, 0, 0))]
    msgs += [m for m in _good(odom=False)]
    _check_rejected(tmp_path, _write(tmp_path / "late.bag", msgs), "falls within the odometry's time span")


def test_time_going_backwards(tmp_path):
    bag = _write(tmp_path / "back.bag", _good(scan_times=[1.0, 1.5, 1.2, 2.0]))
    _check_rejected(tmp_path, bag, "time goes backwards on /scan: message 2")


@pytest.mark.parametrize("storage", ["rosbag1", "sqlite3", "mcap"])
def test_truncated_bag(tmp_path, storage):
    log = io.LaserLog(times=np.arange(1, 41) * 0.5, odometry=np.zeros((40, 3)), ranges=np.full((40, 90), 3.0),
                      angles=ANGLES, max_range=10.0)
    name = "t.bag" if storage == "rosbag1" else "t_bag"
    bag = rosbag.write_rosbag_log(tmp_path / name, log, storage=storage)
    f = bag if storage == "rosbag1" else next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])
    _check_rejected(tmp_path, bag, "damaged, truncated")


def test_bag_without_laser_mounting_needs_laser_pose(tmp_path):
    msgs = [m for m in _good()]
    msgs = [(t, ty, s, (_scan(s, np.full(ANGLES.size, 3.0), frame="laser") if t == "/scan" else m))
            for t, ty, s, m in msgs]
    bag = _write(tmp_path / "nomount.bag", msgs)
    _check_rejected(tmp_path, bag, "give the laser's mounting pose with --laser-pose")
    assert np.allclose(io.read_rosbag(bag, laser_pose=(0.2, 0, 0)).sensor_offset, [0.2, 0, 0])


def test_topic_options_are_for_bags_only(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("ODOM 0 0 0 0 0 0 0 h 0\n")
    status, _, err = run_cli("run", "--build-map", "--log", log, "--scan-topic", "/scan", "--out", tmp_path / "o")
    assert status == 2 and "--scan-topic and --odom-topic apply to ROS bags only" in err


@pytest.mark.parametrize("version", [1, 2])
@pytest.mark.parametrize("frame, n", [("map", 3), ("world", 1), ("m", 0), ("a_long_frame", 2)])
def test_particle_cloud_bytes_equal_rosbags_serializer(version, frame, n):
    ts = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
    poses = np.random.default_rng(n).normal(size=(n, 3))
    t_ns = 1_700_000_123_456_789_012
    ty = ts.types
    T, H = ty["builtin_interfaces/msg/Time"], ty["std_msgs/msg/Header"]
    stamp = T(sec=t_ns // 10**9, nanosec=t_ns % 10**9)
    hdr = H(seq=0, stamp=stamp, frame_id=frame) if version == 1 else H(stamp=stamp, frame_id=frame)
    P, Q, Pose = ty["geometry_msgs/msg/Point"], ty["geometry_msgs/msg/Quaternion"], ty["geometry_msgs/msg/Pose"]
    q = rosbag.yaw_to_quaternion(poses[:, 2]) if n else np.zeros((0, 4))
    msg = ty["geometry_msgs/msg/PoseArray"](header=hdr, poses=[
        Pose(position=P(x=float(a[0]), y=float(a[1]), z=0.0), orientation=Q(x=0.0, y=0.0, z=float(b[2]), w=float(b[3])))
        for a, b in zip(poses, q)])
    want = ts.serialize_ros1(msg, msg.__msgtype__) if version == 1 else ts.serialize_cdr(msg, msg.__msgtype__)
    assert rosbag._pose_array_bytes(version, t_ns, frame, poses) == bytes(want)


@pytest.mark.data
def test_evo_reads_the_tum_output_and_agrees_on_the_ape(carmen_run):
    """With evo installed (it is not part of the test extra: it pulls in pandas and seaborn)."""
    evo_fi = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics

    est = evo_fi.read_tum_trajectory_file(str(carmen_run / "trajectory.tum"))
    ref = evo_fi.read_tum_trajectory_file(str(carmen_run / "reference.tum"))
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    _, rows = trajectory(carmen_run / "trajectory.csv")
    ours = np.array([float(r["error"]) for r in rows])
    assert len(ape.error) == N_SCANS
    assert np.allclose(ape.error, ours, atol=1e-4)
    assert ape.get_statistic(metrics.StatisticsType.rmse) == pytest.approx(np.sqrt(np.mean(ours**2)), abs=1e-4)


def test_many_readings_above_range_max_are_discarded_as_ros_says_and_warned_about(tmp_path):
    """A driver whose range_max (10 m) is shorter than the laser's reach: ROS and AMCL discard the readings above
    it, and so does the reader; the run says how many there were. One stray value above it says nothing."""
    from localize import pipeline

    rng = np.random.default_rng(3)
    msgs = []
    for k in range(6):
        t = 1.0 + 0.5 * k
        msgs.append(("/odom", ODOM_T, t - 0.01, _odom(t - 0.01, 0.1 * k, 0.0, 0.0)))
        msgs.append(("/odom", ODOM_T, t + 0.2, _odom(t + 0.2, 0.1 * k + 0.04, 0.0, 0.0)))
        msgs.append(("/scan", SCAN_T, t, _scan(t, rng.uniform(0.5, 25.0, ANGLES.size), frame="base_link")))
    bag = _write(tmp_path / "far.bag", msgs)
    said = []
    log = pipeline.read_log_file(bag, warn=said.append)
    over = log.meta["above_range_max"]
    assert over["readings"] == over["distinct"] > 200 and 10.0 < over["largest"] <= 25.0
    assert log.max_range == 10.0 and np.all(log.ranges <= 10.0)            # discarded: "no return"
    assert len(said) == 1 and said[0].startswith(f"{bag}: {over['share']:.0%} of the readings ({over['distinct']} "
                                                 "distinct values, up to ")
    assert "range_max (10 m)" in said[0]
    one = [("/odom", ODOM_T, 0.9, _odom(0.9, 0.0, 0.0, 0.0)), ("/odom", ODOM_T, 1.9, _odom(1.9, 1.0, 0.0, 0.0)),
           ("/scan", SCAN_T, 1.15, _scan(1.15, np.r_[12.0, np.full(ANGLES.size - 1, 3.0)], frame="base_link"))]
    said.clear()
    assert pipeline.read_log_file(_write(tmp_path / "one.bag", one), warn=said.append).meta["above_range_max"] == \
        {"readings": 1, "distinct": 1, "largest": 12.0, "share": 1 / ANGLES.size}
    assert said == []
