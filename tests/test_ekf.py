"""Tests of localize.ekf: Jacobians, the filterpy plumbing, the table 7.2 oracle, the UKF."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from localize.ekf import (
    EKFLocalizer,
    UKFLocalizer,
    ekf_localization_known_correspondences,
    landmark_jacobian,
    landmark_measurement,
    numerical_jacobian,
    odometry_controls,
    odometry_jacobians,
    odometry_motion,
    velocity_jacobians,
    velocity_motion,
)
from localize.geometry import wrap_angle

LMS = np.array([[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0], [0.0, -5.0], [4.0, 4.0]])
ALPHAS = np.array([0.02, 0.01, 0.01, 0.02, 0.001, 0.001])


# --------------------------------------------------------------------------- linear special case


def test_ekf_machinery_equals_filterpy_kalman_filter_on_linear_model(rng):
    """With fx(x) = F x + B u and hx(x) = H x the EKF *is* the Kalman filter."""
    F = np.eye(3) + 0.1 * rng.normal(size=(3, 3))
    B = rng.normal(size=(3, 2))
    Q = np.diag([0.02, 0.03, 0.01])
    H = rng.normal(size=(2, 3))
    R = np.diag([0.1, 0.05])
    x0 = np.array([0.3, -0.2, 0.1])
    P0 = np.diag([0.5, 0.4, 0.1])

    kf = KalmanFilter(dim_x=3, dim_z=2, dim_u=2)
    kf.F, kf.B, kf.Q, kf.H, kf.R = F, B, Q, H, R
    kf.x, kf.P = x0.reshape(3, 1).copy(), P0.copy()

    ekf = EKFLocalizer(LMS, 0.1, 0.1, ALPHAS, mean=x0, cov=P0)
    for _ in range(8):
        u = rng.normal(size=2) * 0.1
        z = rng.normal(size=2) * 0.3
        kf.predict(u=u.reshape(2, 1))
        ekf.predict_model(lambda x, u=u: F @ x + B @ u, F, Q)
        np.testing.assert_allclose(ekf.mean, kf.x.ravel(), atol=1e-12)
        np.testing.assert_allclose(ekf.cov, kf.P, atol=1e-12)
        kf.update(z.reshape(2, 1))
        ekf.update_model(z, lambda x: H @ x, H, R)
        np.testing.assert_allclose(ekf.mean, kf.x.ravel(), atol=1e-12)
        np.testing.assert_allclose(ekf.cov, kf.P, atol=1e-12)
    # the heading stayed well inside (-pi, pi), so wrapping never changed anything
    assert abs(ekf.mean[2]) < 3.0


# --------------------------------------------------------------------------- Jacobians


@pytest.mark.parametrize("w", [0.7, -1.3, 1e-2, 1e-4, 0.0])
@pytest.mark.parametrize("theta", [0.3, 3.1, -2.0])
def test_velocity_jacobians_match_numerical(w, theta):
    pose = np.array([1.0, -2.0, theta])
    u = np.array([0.8, w])
    G, V = velocity_jacobians(pose, u, 0.5)
    Gn = numerical_jacobian(lambda p: velocity_motion(p, u, 0.5), pose, angle_rows=(2,))
    Vn = numerical_jacobian(lambda c: velocity_motion(pose, c, 0.5), u, angle_rows=(2,))
    np.testing.assert_allclose(G, Gn, atol=1e-7)
    np.testing.assert_allclose(V, Vn, atol=1e-7)


def test_velocity_motion_equals_textbook_arc():
    x, y, th, v, w, dt = 1.0, 2.0, 0.4, 0.9, 0.6, 0.7
    r = v / w
    want = [x - r * np.sin(th) + r * np.sin(th + w * dt), y + r * np.cos(th) - r * np.cos(th + w * dt), th + w * dt]
    np.testing.assert_allclose(velocity_motion([x, y, th], [v, w], dt), want, atol=1e-12)
    # and it is vectorised over poses
    poses = np.tile([x, y, th], (4, 1))
    assert velocity_motion(poses, [v, w], dt).shape == (4, 3)


@pytest.mark.parametrize("theta", [0.0, 2.5, -3.0])
def test_odometry_jacobians_match_numerical(theta):
    pose = np.array([0.5, 1.5, theta])
    u = np.array([0.4, 1.2, -0.3])
    G, V = odometry_jacobians(pose, u)
    Gn = numerical_jacobian(lambda p: odometry_motion(p, u), pose, angle_rows=(2,))
    Vn = numerical_jacobian(lambda c: odometry_motion(pose, c), u, angle_rows=(2,))
    np.testing.assert_allclose(G, Gn, atol=1e-7)
    np.testing.assert_allclose(V, Vn, atol=1e-7)


def test_odometry_controls_reproduce_relative_motion(rng):
    for _ in range(20):
        a = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        b = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        c = odometry_controls([a, b])
        moved = odometry_motion(a, c)
        np.testing.assert_allclose(moved[:2], b[:2], atol=1e-9)
        assert abs(wrap_angle(moved[2] - b[2])) < 1e-9


def test_landmark_jacobian_matches_numerical(rng):
    for _ in range(20):
        pose = np.array([*rng.uniform(-4, 4, 2), rng.uniform(-np.pi, np.pi)])
        m = rng.uniform(-6, 6, 2)
        H = landmark_jacobian(pose, m)
        Hn = numerical_jacobian(lambda p, m=m: landmark_measurement(p, m), pose, angle_rows=(1,))
        np.testing.assert_allclose(H, Hn, atol=1e-6)


def test_landmark_jacobian_agrees_with_sensors_module():
    sensors = pytest.importorskip("localize.sensors")
    if not hasattr(sensors, "LandmarkModel"):
        pytest.skip("localize.sensors has no LandmarkModel yet")
    model = sensors.LandmarkModel(LMS, 0.1, 0.05)
    pose = np.array([0.7, -1.1, 0.9])
    for j in range(len(LMS)):
        np.testing.assert_allclose(landmark_jacobian(pose, LMS[j]), model.jacobian(pose, j), atol=1e-9)
        np.testing.assert_allclose(landmark_measurement(pose, LMS[j]), model.expected(pose[None])[0, j], atol=1e-9)


def test_landmark_jacobian_rejects_pose_on_landmark():
    with pytest.raises(ValueError, match="coincides"):
        landmark_jacobian([5.0, 0.0, 0.0], [5.0, 0.0])


# --------------------------------------------------------------------------- EKF vs the table 7.2 oracle


def _toy_run(rng, steps=25, dt=0.5):
    """A tiny landmark run (test double for localize.sim): true poses, controls, sightings."""
    pose = np.array([0.0, -3.0, 0.0])
    poses, us, zs = [], [], []
    for t in range(steps):
        u = np.array([1.0, 0.35 + 0.1 * np.sin(t)])
        pose = velocity_motion(pose, u + rng.normal(0, 0.02, 2), dt)
        z = np.array([landmark_measurement(pose, m) for m in LMS])
        z += rng.normal(0, [0.1, 0.03], z.shape)
        z[:, 1] = wrap_angle(z[:, 1])
        poses.append(pose)
        us.append(u)
        zs.append(z)
    return np.array(poses), np.array(us), zs


def test_ekf_localizer_equals_table_7_2_oracle(rng):
    poses, us, zs = _toy_run(rng)
    mu, Sigma = np.array([0.1, -2.9, 0.05]), np.diag([0.2, 0.2, 0.05])
    ekf = EKFLocalizer(LMS, 0.1, 0.03, ALPHAS, dt=0.5, mean=mu, cov=Sigma)
    ids = np.arange(len(LMS))
    for u, z in zip(us, zs):
        mu, Sigma = ekf_localization_known_correspondences(mu, Sigma, u, z, ids, LMS, ALPHAS, 0.1, 0.03, dt=0.5)
        ekf.step(u, z, ids)
        np.testing.assert_allclose(ekf.mean, mu, atol=1e-9)
        # Joseph form (filterpy) and (I - KH) Sigma agree up to rounding
        np.testing.assert_allclose(ekf.cov, Sigma, atol=1e-9)
    assert np.linalg.norm(ekf.mean[:2] - poses[-1, :2]) < 0.3


def test_ekf_and_ukf_track_the_toy_run(rng):
    poses, us, zs = _toy_run(rng)
    kw = dict(dt=0.5, mean=[0.4, -3.4, 0.2], cov=np.diag([0.3, 0.3, 0.1]))
    filters = [EKFLocalizer(LMS, 0.1, 0.03, ALPHAS, **kw), UKFLocalizer(LMS, 0.1, 0.03, ALPHAS, **kw)]
    for f in filters:
        err = []
        for u, z, p in zip(us, zs, poses):
            f.step(u, z, np.arange(len(LMS)))
            err.append(np.linalg.norm(f.mean[:2] - p[:2]))
        assert np.mean(err[5:]) < 0.15, type(f).__name__
        assert np.all(np.linalg.eigvalsh(f.cov) > 0)


def test_ukf_approaches_ekf_when_nearly_linear():
    """With a tiny covariance the sigma points barely feel the curvature: UKF ~ EKF."""
    kw = dict(dt=1.0, mean=[1.0, 1.0, 0.5], cov=np.eye(3) * 1e-6)
    e, u = EKFLocalizer(LMS, 0.1, 0.03, ALPHAS * 1e-4, **kw), UKFLocalizer(LMS, 0.1, 0.03, ALPHAS * 1e-4, **kw)
    z = np.array([landmark_measurement([1.5, 1.3, 0.8], m) for m in LMS[:2]])
    for f in (e, u):
        f.predict([0.5, 0.3])
        f.update(z, [0, 1])
    np.testing.assert_allclose(u.mean, e.mean, atol=1e-6)
    np.testing.assert_allclose(u.cov, e.cov, rtol=1e-3, atol=1e-12)


@pytest.mark.parametrize("cls", [EKFLocalizer, UKFLocalizer])
def test_heading_across_the_seam_is_handled(cls):
    """A robot heading ~pi: bearings and headings wrap; the mean must not jump to 0."""
    truth = np.array([0.0, 0.0, np.pi - 0.01])
    f = cls(LMS, 0.1, 0.02, ALPHAS, dt=1.0, mean=[0.0, 0.0, -np.pi + 0.02], cov=np.diag([0.01, 0.01, 0.01]))
    z = np.array([landmark_measurement(truth, m) for m in LMS])
    f.update(z, np.arange(len(LMS)))
    assert abs(wrap_angle(f.mean[2] - truth[2])) < 0.02
    assert -np.pi <= f.mean[2] < np.pi


def test_ml_association_recovers_ids(rng):
    truth = np.array([1.0, 0.5, 0.3])
    f = EKFLocalizer(LMS, 0.1, 0.03, ALPHAS, mean=truth + [0.1, -0.1, 0.02], cov=np.eye(3) * 0.05)
    ids = rng.permutation(len(LMS))
    z = np.array([landmark_measurement(truth, LMS[j]) for j in ids])
    assert f.associate(z).tolist() == ids.tolist()
    f.update(z)  # unknown correspondences
    assert np.linalg.norm(f.mean[:2] - truth[:2]) < 0.05


def test_empty_update_is_noop():
    f = UKFLocalizer(LMS, 0.1, 0.03, ALPHAS, mean=[1, 2, 0.5], cov=np.eye(3) * 0.1)
    e = EKFLocalizer(LMS, 0.1, 0.03, ALPHAS, mean=[1, 2, 0.5], cov=np.eye(3) * 0.1)
    for g in (f, e):
        g.update(np.zeros((0, 2)), np.zeros(0, dtype=int))
        np.testing.assert_allclose(g.mean, [1, 2, 0.5])


def test_odometry_motion_model_filter(rng):
    """The odometry variant predicts with (prev_odom, odom) pairs."""
    f = EKFLocalizer(LMS, 0.1, 0.03, [0.01, 0.01, 0.01, 0.01], motion="odometry", mean=[0, 0, 0],
                     cov=np.eye(3) * 1e-4)
    f.predict([[10.0, 10.0, 0.0], [11.0, 10.0, 0.0]])
    np.testing.assert_allclose(f.mean, [1.0, 0.0, 0.0], atol=1e-12)
    assert f.cov[0, 0] > 1e-4


@pytest.mark.parametrize("kwargs, match", [
    (dict(landmarks=[[1, 2, 3]]), "landmarks"),
    (dict(sigma_range=0.0), "sigma_range"),
    (dict(sigma_bearing=-1.0), "sigma_bearing"),
    (dict(alphas=[0.1] * 4), "alphas"),
    (dict(motion="ackermann"), "motion"),
    (dict(dt=0.0), "dt"),
    (dict(cov=-np.eye(3)), "cov"),
    (dict(mean=[0, 0]), "mean"),
])
def test_bad_input_is_rejected(kwargs, match):
    args = dict(landmarks=LMS, sigma_range=0.1, sigma_bearing=0.1, alphas=ALPHAS)
    args.update(kwargs)
    for cls in (EKFLocalizer, UKFLocalizer):
        with pytest.raises(ValueError, match=match):
            cls(**args)


def test_bad_ids_are_rejected():
    f = EKFLocalizer(LMS, 0.1, 0.1, ALPHAS)
    with pytest.raises(ValueError, match="ids"):
        f.update([[1.0, 0.0]], [7])
    with pytest.raises(ValueError, match="ids"):
        f.update([[1.0, 0.0]], [0, 1])
    with pytest.raises(ValueError, match="u"):
        f.predict([1.0, 2.0, 3.0])


def test_vectorised_association_equals_the_loop(rng):
    f = EKFLocalizer(LMS, 0.2, 0.1, ALPHAS, mean=[0.5, -1.0, 2.0], cov=np.diag([2.0, 1.0, 0.5]))
    for _ in range(20):
        z = np.column_stack([rng.uniform(0.5, 9, 6), rng.uniform(-np.pi, np.pi, 6)])
        assert f.associate(z).tolist() == f.associate_loop(z).tolist()


def test_ekf_and_landmark_model_share_the_zero_distance_test():
    """One on-the-landmark test (``r < ON_LANDMARK``) for the EKF and the landmark model.

    Nearer than a nanometre both raise; a micrometre away both give the same
    (huge but finite) Jacobian; the EKF skips a sighting taken on the landmark.
    """
    from localize.sensors import ON_LANDMARK, LandmarkModel

    model = LandmarkModel(LMS, 0.1, 0.05)
    for d in (0.0, 0.1 * ON_LANDMARK):
        pose = [LMS[0][0] + d, LMS[0][1], 0.0]
        with pytest.raises(ValueError, match="coincides"):
            landmark_jacobian(pose, LMS[0])
        with pytest.raises(ValueError, match="coincides"):
            model.jacobian(pose, 0)
    pose = [LMS[0][0] + 1e-6, LMS[0][1], 0.0]
    np.testing.assert_array_equal(landmark_jacobian(pose, LMS[0]), model.jacobian(pose, 0))
    f = EKFLocalizer(LMS, 0.1, 0.05, [0.01] * 6, mean=[LMS[0][0], LMS[0][1], 0.0], cov=np.eye(3) * 0.1)
    before = f.cov
    f.update([[0.0, 0.3]], ids=[0])
    np.testing.assert_array_equal(f.cov, before)
    assert f.model is not None and f.R1.tolist() == model.R.tolist()


def test_associate_skips_a_landmark_under_the_robot_like_its_oracle():
    f = EKFLocalizer(LMS, 0.1, 0.05, [0.01] * 6, mean=[LMS[1][0], LMS[1][1], 0.2], cov=np.eye(3) * 0.05)
    z = [[0.0, 0.0], [float(np.hypot(*np.subtract(LMS[0], LMS[1]))), 0.0]]
    assert f.associate(z).tolist() == f.associate_loop(z).tolist()
    assert 1 not in f.associate(z).tolist()
