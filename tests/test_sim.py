"""Tests of localize.sim: determinism, collision-free paths, odometry noise, scans, landmarks, log writer."""

import importlib.util

import numpy as np
import pytest

from localize import io, maps, sim
from localize.geometry import compose, relative, wrap_angle
from localize.motion import move_velocity, odometry_to_control
from localize.raycast import cast

HAVE_SENSORS = importlib.util.find_spec("localize.sensors") is not None
FEW = np.radians(np.arange(-90, 91, 15.0))


@pytest.fixture(scope="module")
def office():
    return maps.office()


@pytest.fixture(scope="module")
def ideal_run(office):
    return sim.range_run(office, np.random.default_rng(4), n_steps=60, angles=FEW, sensor="ideal",
                         sensor_offset=(0.25, 0.0, 0.0), kidnap_at=[40])


def test_same_seed_same_run_and_different_seed_different(office):
    a = sim.range_run(office, np.random.default_rng(1), n_steps=20, angles=FEW, sensor="ideal")
    b = sim.range_run(office, np.random.default_rng(1), n_steps=20, angles=FEW, sensor="ideal")
    c = sim.range_run(office, np.random.default_rng(2), n_steps=20, angles=FEW, sensor="ideal")
    for f in ("poses", "odometry", "ranges", "clutter"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert not np.allclose(a.poses, c.poses)


def test_run_is_frozen_and_read_only(ideal_run):
    with pytest.raises(AttributeError):
        ideal_run.poses = None
    with pytest.raises(ValueError):
        ideal_run.poses[0, 0] = 1.0


def test_trajectory_is_collision_free_and_moves(ideal_run):
    d = ideal_run.world.distance_at(ideal_run.poses[:, :2])
    assert np.all(d >= 0.25)
    steps = np.hypot(*np.diff(ideal_run.poses[:, :2], axis=0).T)[~ideal_run.kidnapped[1:]]
    assert np.all(steps <= 0.3 + 1e-9)
    assert np.mean(steps > 0.29) > 0.5, "the robot should mostly drive, not spin"
    # segments between poses are clear too (checked at many points)
    for k in np.flatnonzero(~ideal_run.kidnapped[1:]) + 1:
        t = np.linspace(0, 1, 20)[:, None]
        pts = ideal_run.poses[k - 1, :2] + t * (ideal_run.poses[k, :2] - ideal_run.poses[k - 1, :2])
        assert np.all(ideal_run.world.distance_at(pts) >= 0.25)


def test_waypoint_route_is_followed(office):
    wps = [[2.0, 5.0], [18.0, 5.0]]
    run = sim.range_run(office, np.random.default_rng(0), n_steps=70, angles=[], start=[1.5, 5.0, 0.0],
                        waypoints=wps, n_clutter=0)
    assert np.hypot(*(run.poses[-1, :2] - wps[-1])) < 0.31
    assert np.all(np.abs(run.poses[:, 1] - 5.0) < 0.35)
    with pytest.raises(ValueError, match="passes within"):
        sim.wander_path(office, 20, np.random.default_rng(0), start=[1.5, 5.5, 0.0], waypoints=[[1.5, 9.0]])


def test_odometry_frame_has_arbitrary_origin_but_true_shape(ideal_run):
    assert np.hypot(*(ideal_run.odometry[0, :2] - ideal_run.poses[0, :2])) > 1.0
    # relative motions agree with the truth up to the small odometry noise
    d_true = relative(ideal_run.poses[:39], ideal_run.poses[1:40])
    d_odo = relative(ideal_run.odometry[:39], ideal_run.odometry[1:40])
    err = np.hypot(*(d_true[:, :2] - d_odo[:, :2]).T)
    assert np.median(err) < 0.06 and err.max() < 0.25
    assert np.max(np.abs(wrap_angle(d_true[:, 2] - d_odo[:, 2]))) < 0.4


def test_odometry_noise_matches_the_alphas():
    """Standardised errors of (rot1, trans, rot2) have unit variance: the alphas are variances (PR)."""
    rng = np.random.default_rng(3)
    T = 4001
    th = np.cumsum(rng.normal(0, 0.3, T))
    xy = np.cumsum(0.5 * np.stack([np.cos(th), np.sin(th)], 1), axis=0)
    truth = np.column_stack([xy, wrap_angle(th)])
    alphas = np.array([0.05, 0.002, 0.01, 0.003])
    odo = sim.odometry_readings(truth, alphas, rng, origin=[0.0, 0.0, 0.0])
    r1, t, r2 = (np.asarray(v) for v in odometry_to_control(truth[:-1], truth[1:]))
    o1, ot, o2 = (np.asarray(v) for v in odometry_to_control(odo[:-1], odo[1:]))
    z = [wrap_angle(o1 - r1) / np.sqrt(alphas[0] * r1**2 + alphas[1] * t**2),
         (ot - t) / np.sqrt(alphas[2] * t**2 + alphas[3] * (r1**2 + r2**2)),
         wrap_angle(o2 - r2) / np.sqrt(alphas[0] * r2**2 + alphas[1] * t**2)]
    for name, zz in zip(("rot1", "trans", "rot2"), z):
        # the variance of a sample variance of n unit normals is 2/n
        assert abs(np.var(zz) - 1) < 5 * np.sqrt(2 / zz.size), (name, np.var(zz))
        assert abs(np.mean(zz)) < 5 / np.sqrt(zz.size), name


def test_no_noise_odometry_is_exact_and_origin_respected():
    truth = np.array([[0, 0, 0], [1, 0, 0.5], [1.5, 0.5, 1.0]], float)
    odo = sim.odometry_readings(truth, np.zeros(4), np.random.default_rng(0), origin=[3.0, -2.0, 1.0])
    assert np.allclose(odo[0], [3.0, -2.0, 1.0])
    for k in (1, 2):
        assert np.allclose(relative(odo[k - 1], odo[k]), relative(truth[k - 1], truth[k]))


def test_kidnapping(ideal_run):
    assert ideal_run.kidnap_steps.tolist() == [40]
    jump = np.hypot(*(ideal_run.poses[40, :2] - ideal_run.poses[39, :2]))
    odo_step = relative(ideal_run.odometry[39], ideal_run.odometry[40])
    assert jump > 0.6 or abs(wrap_angle(ideal_run.poses[40, 2] - ideal_run.poses[39, 2])) > 0.5
    assert abs(odo_step[0] - 0.3) < 0.1 and abs(odo_step[1]) < 0.1      # an ordinary step ahead
    with pytest.raises(ValueError, match="kidnap_at"):
        sim.range_run(maps.office(), np.random.default_rng(0), n_steps=10, kidnap_at=[10], angles=[])


def test_ideal_scans_are_exact_casts_in_the_true_world(ideal_run):
    expected = cast(ideal_run.world, ideal_run.sensor_poses, ideal_run.angles, ideal_run.max_range, method="exact")
    assert np.allclose(ideal_run.ranges, expected)
    assert np.allclose(ideal_run.sensor_poses[:, :2] - ideal_run.poses[:, :2],
                       0.25 * np.column_stack([np.cos(ideal_run.poses[:, 2]), np.sin(ideal_run.poses[:, 2])]))


def test_clutter_makes_readings_shorter_than_the_map_says(office):
    run = sim.range_run(office, np.random.default_rng(5), n_steps=80, n_clutter=15, sensor="ideal")
    in_map = cast(run.grid, run.sensor_poses, run.angles, run.max_range, method="exact")
    assert np.all(run.ranges <= in_map + 1e-9)                 # clutter only ever shortens a beam
    assert np.mean(run.ranges < in_map - 0.2) > 0.005          # ... and it is seen
    assert run.clutter.shape == (15, 4)
    assert run.world.occupied.sum() > run.grid.occupied.sum()


def test_custom_sensor_object(office):
    class Const:
        def sample(self, poses, angles, rng):
            return np.full((len(poses), len(angles)), 2.0)

    run = sim.range_run(office, np.random.default_rng(0), n_steps=4, angles=FEW, sensor=Const())
    assert np.all(run.ranges == 2.0)
    with pytest.raises(ValueError, match="sensor must be"):
        sim.range_run(office, np.random.default_rng(0), n_steps=4, angles=FEW, sensor="laser")


@pytest.mark.skipif(not HAVE_SENSORS, reason="localize.sensors not written yet")
def test_beam_model_scans_have_failures(office):
    run = sim.range_run(office, np.random.default_rng(6), n_steps=40)
    exact = cast(run.world, run.sensor_poses, run.angles, run.max_range, method="exact")
    hit = exact < run.max_range
    assert np.all((run.ranges >= 0) & (run.ranges <= run.max_range))
    n = hit.sum()
    p_max = np.mean(run.ranges[hit] >= run.max_range)          # missed returns where a wall is in range
    assert abs(p_max - sim.DEFAULT_SCAN_NOISE["z_max"]) < 5 * np.sqrt(0.05 * 0.95 / n) + 0.02
    short = np.mean(run.ranges[hit] < exact[hit] - 0.3)
    assert short > 0.02                                        # short readings and random ones
    close = np.abs(run.ranges - exact) < 0.15
    assert np.mean(close[hit]) > 0.75                          # but most beams hit what is there


@pytest.mark.skipif(not HAVE_SENSORS, reason="localize.sensors not written yet")
def test_a_beam_with_nothing_in_range_reads_no_return(office):
    """Where no wall lies within range, the simulated laser says so (max_range) from its hit part, as a real
    scanner does; with no_return=False (PR's sampler) the hit part reads a few centimetres short of the range."""
    runs = [sim.range_run(office, np.random.default_rng(6), n_steps=40, max_range=5.0, scan_noise=noise)
            for noise in (None, {"no_return": False})]
    exact = cast(runs[0].world, runs[0].sensor_poses, runs[0].angles, runs[0].max_range, method="exact")
    far = exact >= runs[0].max_range
    n = int(far.sum())
    assert n > 500
    real, plain = (r.ranges[far] for r in runs)
    p = sim.DEFAULT_SCAN_NOISE["z_hit"] + sim.DEFAULT_SCAN_NOISE["z_max"]
    assert abs(np.mean(real == 5.0) - p) < 5 * np.sqrt(p * (1 - p) / n)
    assert np.mean(plain == 5.0) < 0.1 < np.mean((plain > 4.8) & (plain < 5.0))
    np.testing.assert_array_equal(runs[0].ranges[~far], runs[1].ranges[~far])   # every other beam as before


def test_bad_arguments(office):
    rng = np.random.default_rng(0)
    with pytest.raises(TypeError, match="rng"):
        sim.range_run(office, 0)
    with pytest.raises(TypeError, match="grid"):
        sim.range_run(np.zeros((5, 5)), rng)
    with pytest.raises(ValueError, match="n_steps"):
        sim.range_run(office, rng, n_steps=0)
    with pytest.raises(ValueError, match="alphas"):
        sim.range_run(office, rng, alphas=[0.1, 0.1], angles=[])
    with pytest.raises(ValueError, match="max_range"):
        sim.range_run(office, rng, max_range=-1)
    with pytest.raises(ValueError, match="within radius"):
        sim.wander_path(office, 5, rng, start=[0.05, 0.05, 0.0])
    with pytest.raises(ValueError, match="k must be"):
        sim.range_run(office, rng, n_steps=3, angles=[]).control(0)


# ------------------------------------------------------------------ landmarks
def test_landmark_run_sightings_are_consistent():
    run = sim.landmark_run(np.random.default_rng(8), n_steps=300, sigma_range=0.1, sigma_bearing=0.03)
    assert run.z.shape == (len(run.ids), 2) and run.steps.shape == run.ids.shape
    d = run.landmarks[run.ids] - run.poses[run.steps, :2]
    r = np.hypot(d[:, 0], d[:, 1])
    b = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - run.poses[run.steps, 2])
    assert np.all(r <= run.max_range)
    er = (run.z[:, 0] - r) / 0.1
    eb = wrap_angle(run.z[:, 1] - b) / 0.03
    n = er.size
    assert n > 500
    for e in (er, eb):
        assert abs(e.mean()) < 5 / np.sqrt(n) and abs(e.var() - 1) < 5 * np.sqrt(2 / n)
    # all visible landmarks were seen: count equals the visibility mask
    D = run.landmarks[None] - run.poses[:, None, :2]
    assert n == int((np.hypot(D[..., 0], D[..., 1]) <= run.max_range).sum())
    z, ids = run.sightings(5)
    assert np.array_equal(ids, run.ids[run.steps == 5])


def test_landmark_run_field_of_view_and_noise_free_motion():
    u = np.tile([0.5, 0.1], (9, 1))
    run = sim.landmark_run(np.random.default_rng(0), n_steps=10, controls=u, velocity_alphas=np.zeros(6),
                           fov=np.pi / 2, sigma_bearing=0.0, sigma_range=0.0)
    for k in range(1, 10):
        assert np.allclose(run.poses[k], move_velocity(run.poses[k - 1], 0.5, 0.1, run.dt))
    assert np.all(np.abs(run.z[:, 1]) <= np.pi / 4 + 1e-12)
    assert np.array_equal(run.controls[0], [0.0, 0.0])


def test_landmark_run_expected_matches_sensor_model_if_present():
    sensors = pytest.importorskip("localize.sensors")
    run = sim.landmark_run(np.random.default_rng(0), n_steps=30, sigma_range=0.0, sigma_bearing=0.0)
    model = sensors.LandmarkModel(run.landmarks, sigma_range=0.1, sigma_bearing=0.05)
    exp = np.asarray(model.expected(run.poses[run.steps]))               # (K, L, 2)
    got = exp[np.arange(len(run.ids)), run.ids]
    assert np.allclose(got[:, 0], run.z[:, 0])
    assert np.allclose(wrap_angle(got[:, 1] - run.z[:, 1]), 0.0)


def test_landmark_run_bad_arguments():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="landmarks"):
        sim.landmark_run(rng, landmarks=[1.0, 2.0])
    with pytest.raises(ValueError, match="controls"):
        sim.landmark_run(rng, n_steps=5, controls=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="fov"):
        sim.landmark_run(rng, fov=0.0)
    with pytest.raises(ValueError, match="sigma_range"):
        sim.landmark_run(rng, sigma_range=-0.1)


# ---------------------------------------------------------------- CMU log
def test_write_cmu_log_format(tmp_path, office):
    run = sim.range_run(office, np.random.default_rng(9), n_steps=4, sensor="ideal", sensor_offset=(0.25, 0, 0),
                        max_range=8.0)
    path = sim.write_cmu_log(tmp_path / "sim.log", run)
    lines = path.read_text().splitlines()
    assert [ln.split()[0] for ln in lines] == ["O", "L"] * 4
    L = np.array(lines[3].split()[1:], dtype=float)
    assert L.size == 187
    assert np.allclose(L[:3], [run.odometry[1, 0] * 100, run.odometry[1, 1] * 100, run.odometry[1, 2]], atol=1e-3)
    laser = compose(run.odometry[1], [0.25, 0, 0])
    assert np.allclose(L[3:6], [laser[0] * 100, laser[1] * 100, laser[2]], atol=1e-3)
    r = L[6:186]
    no_return = run.ranges[1] >= run.max_range
    assert np.all(r[no_return] == 8183)
    # whole cm; a reading just below max_range stays below it (799 cm, not the 800 cm that would read as no return)
    assert np.allclose(r[~no_return], np.minimum(np.round(run.ranges[1, ~no_return] * 100), run.max_range * 100 - 1))
    assert L[-1] == pytest.approx(run.times[1])


def test_write_cmu_log_round_trips_through_the_reader(tmp_path, office):
    cmu = pytest.importorskip("localize.io.cmu")
    run = sim.range_run(office, np.random.default_rng(10), n_steps=6, sensor="ideal", sensor_offset=(0.25, 0, 0))
    log = cmu.read_cmu_log(sim.write_cmu_log(tmp_path / "sim.log", run))
    assert len(log) == 6
    assert np.allclose(log.odometry, run.odometry, atol=1e-4)
    assert np.allclose(log.sensor_offset, [0.25, 0, 0], atol=1e-4)
    hit = run.ranges < run.max_range
    assert np.allclose(log.ranges[hit], run.ranges[hit], atol=0.006)
    assert np.all(log.ranges[~hit] >= log.max_range)


def test_a_simulated_run_converts_to_a_log_that_the_io_writer_writes(tmp_path, office):
    run = sim.range_run(office, np.random.default_rng(11), n_steps=5, sensor_offset=(0.25, 0, 0), max_range=8.0)
    log = run.to_log()
    assert np.array_equal(log.ranges, run.ranges) and np.array_equal(log.poses, run.poses)
    assert np.array_equal(log.odom_poses, run.odometry) and log.max_range == run.max_range
    a = io.write_cmu_log(tmp_path / "io.log", log).read_text()
    assert a == sim.write_cmu_log(tmp_path / "sim.log", run).read_text()
    assert sim.CMU_ANGLES is io.CMU_ANGLES
    with pytest.raises(ValueError, match="max_range must be below 81.83"):
        sim.write_cmu_log(tmp_path / "far.log", sim.range_run(office, np.random.default_rng(0), n_steps=2,
                                                               max_range=90.0))


def test_write_cmu_log_rejects_other_layouts(tmp_path, office):
    run = sim.range_run(office, np.random.default_rng(0), n_steps=2, angles=FEW, sensor="ideal")
    with pytest.raises(ValueError, match="180 beams"):
        sim.write_cmu_log(tmp_path / "x.log", run)
    with pytest.raises(TypeError, match="RangeRun"):
        sim.write_cmu_log(tmp_path / "x.log", object())


# ----------------------------------------------------------------- corridor
def test_corridor_run_statistics():
    run = sim.corridor_run(np.random.default_rng(0), n_steps=4000, sigma_move=0.3, p_hit=0.7, p_false=0.2)
    steps = np.mod(np.diff(run.positions) + run.length / 2, run.length) - run.length / 2
    assert abs(steps.mean() - 1.0) < 5 * 0.3 / np.sqrt(steps.size)
    assert abs(steps.std() / 0.3 - 1) < 5 * np.sqrt(0.5 / steps.size)
    door = run.at_door(run.positions)
    for mask, p in ((door, 0.7), (~door, 0.2)):
        f = run.z[mask].mean()
        assert abs(f - p) < 5 * np.sqrt(p * (1 - p) / mask.sum())
    assert np.all((run.positions >= 0) & (run.positions < run.length))


def test_corridor_helpers():
    run = sim.corridor_run(np.random.default_rng(0), n_steps=3, start=19.5)
    assert run.length == 20.0
    assert run.at_door([2.5, 3.0, 22.5]).tolist() == [True, False, True]     # wraps around
    assert np.allclose(np.exp(run.log_likelihood([2.5, 3.5], 0)), [0.2, 0.9])
    assert run.ring_mean([19.0, 1.0]) == pytest.approx(0.0, abs=1e-9) or run.ring_mean([19.0, 1.0]) == pytest.approx(20.0)
    assert np.allclose(run.ring_error(run.positions + 19.0), 1.0)
    with pytest.raises(ValueError, match="doors"):
        sim.corridor_run(np.random.default_rng(0), doors=[0, 2, 1])
    with pytest.raises(ValueError, match="p_hit"):
        sim.corridor_run(np.random.default_rng(0), p_hit=1.0)


def _blocked_turn_runs(poses):
    """Signs of the on-the-spot turns, split into runs of consecutive blocked steps."""
    step = relative(poses[:-1], poses[1:])
    blocked = np.hypot(step[:, 0], step[:, 1]) < 1e-12
    runs, cur = [], []
    for b, dth in zip(blocked, step[:, 2]):
        if b:
            cur.append(np.sign(dth))
        elif cur:
            runs.append(cur)
            cur = []
    return runs + ([cur] if cur else [])


def test_open_side_blocked_robot_keeps_turning_one_way_and_stays_clear(office):
    rng = np.random.default_rng(3)
    poses, _ = sim.wander_path(office, 400, rng, when_blocked="open_side")
    runs = _blocked_turn_runs(poses)
    assert sum(len(r) > 1 for r in runs) >= 3          # the office blocks the robot often enough to test
    assert all(len(set(r)) == 1 for r in runs)          # never left-right-left on the spot
    assert np.all(office.distance_at(poses[:, :2]) >= 0.25)
    # the default dithers: some blocked run turns both ways (the behaviour the option exists to avoid)
    rand, _ = sim.wander_path(office, 400, np.random.default_rng(3))
    assert any(len(set(r)) == 2 for r in _blocked_turn_runs(rand))


def test_when_blocked_is_checked(office):
    with pytest.raises(ValueError, match="when_blocked must be 'random' or 'open_side'"):
        sim.wander_path(office, 5, np.random.default_rng(0), when_blocked="left")
