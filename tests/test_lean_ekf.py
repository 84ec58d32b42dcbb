"""The lean paths of the filters' steps (motion, EKF and UKF prediction, UKF sigma points) change no number.

Each lean path skips per-call checks of what was checked once (alphas, dt, options)
or reuses what was computed from the same inputs; every test below compares it
with the checked public functions, bit for bit.
"""

import numpy as np
import pytest

from localize import compare as C
from localize import motion
from localize.ekf import (
    EKFLocalizer,
    UKFLocalizer,
    _residual_x,
    _velocity_process_cov,
    velocity_jacobians,
    velocity_motion,
    velocity_noise,
)
from localize.geometry import wrap_angle

ALPHAS = np.array([0.02, 0.005, 0.3, 0.4, 0.05, 0.06])


# ---------------------------------------------------------------- the velocity motion model


@pytest.mark.parametrize("options", [{}, {"noise": "absolute"}, {"sign": -1}, {"min_std": 0.05},
                                     {"noise": lambda v, w, a: (0.01 + 0 * v, 0.02 + 0 * w, 0.001 + 0 * v)}])
@pytest.mark.parametrize("u", [(0.6, 0.2), (1.0, 0.0), (0.0, 0.0)])
def test_velocity_motion_object_equals_sample_velocity(options, u):
    poses = np.random.default_rng(1).uniform(-3, 3, (500, 3))
    lean = motion.VelocityMotion(ALPHAS, 0.5, **options)(poses, u, np.random.default_rng(2))
    ref = motion.sample_velocity(poses, u, 0.5, ALPHAS, np.random.default_rng(2), **options)
    assert np.array_equal(lean, ref)


def test_velocity_motion_object_per_particle_controls():
    rng = np.random.default_rng(3)
    poses, u = rng.uniform(-3, 3, (300, 3)), rng.uniform(-1, 1, (300, 2))
    assert np.array_equal(motion.VelocityMotion(ALPHAS, 0.2)(poses, u, np.random.default_rng(4)),
                          motion.sample_velocity(poses, u, 0.2, ALPHAS, np.random.default_rng(4)))


def test_velocity_motion_object_checks_options_once_and_inputs_each_call():
    with pytest.raises(ValueError, match="sign"):
        motion.VelocityMotion(ALPHAS, 0.5, sign=2)
    with pytest.raises(ValueError, match="min_std"):
        motion.VelocityMotion(ALPHAS, 0.5, min_std=-1.0)
    m = motion.VelocityMotion(ALPHAS, 0.5)
    with pytest.raises(ValueError, match="finite"):
        m(np.zeros((3, 3)), (np.nan, 0.1), np.random.default_rng(0))
    with pytest.raises(ValueError, match="poses"):
        m(np.full((3, 3), np.inf), (0.5, 0.1), np.random.default_rng(0))
    with pytest.raises(TypeError):
        m(np.zeros((3, 3)), (0.5, 0.1), "not a generator")
    with pytest.raises(ValueError, match="noise"):
        motion.VelocityMotion(ALPHAS, 0.5, noise="cubed")(np.zeros((3, 3)), (0.5, 0.1), np.random.default_rng(0))
    # an option sample_velocity does not know is still its error, at the call
    with pytest.raises(TypeError):
        motion.VelocityMotion(ALPHAS, 0.5, colour="red")(np.zeros((3, 3)), (0.5, 0.1), np.random.default_rng(0))


def test_move_velocity_kernel_equals_checked_function():
    p = np.random.default_rng(5).uniform(-np.pi, np.pi, (200, 3))
    for v, w in ((0.6, 0.2), (1.0, 0.0), (-0.3, 2.5)):
        assert np.array_equal(motion._move_velocity(p, v, w, 0.5), motion.move_velocity(p, v, w, 0.5))


# ---------------------------------------------------------------- the EKF and UKF prediction


@pytest.mark.parametrize("u", [(0.6, 0.2), (1.0, 0.0), (0.3, -1e-5), (-0.4, 3.0)])
def test_process_covariance_equals_the_public_functions(u):
    pose, uu, dt = np.array([1.0, -2.0, 0.7]), np.array(u), 0.5
    G, Q = _velocity_process_cov(pose, uu, dt, ALPHAS)
    G_ref, V = velocity_jacobians(pose, uu, dt)
    Q_ref = V @ velocity_noise(uu, dt, ALPHAS) @ V.T
    Q_ref[2, 2] += float(motion.velocity_variances(uu[0], uu[1], ALPHAS)[2]) * dt**2
    assert np.array_equal(G, G_ref) and np.array_equal(Q, Q_ref)


def test_ekf_prediction_moves_the_mean_as_velocity_motion_does():
    f = EKFLocalizer([[5.0, 0.0]], 0.1, 0.05, ALPHAS, dt=0.5, mean=[1.0, 2.0, 3.1], cov=np.eye(3) * 0.01)
    before = f.mean
    f.predict([0.8, 0.5])
    assert np.array_equal(f.mean, velocity_motion(before, [0.8, 0.5], 0.5))
    with pytest.raises(ValueError, match="finite"):
        f.predict([np.nan, 0.5])


def test_residual_x_wraps_as_wrap_angle():
    rng = np.random.default_rng(6)
    for _ in range(200):
        a, b = rng.normal(0, 5, 3), rng.normal(0, 5, 3)
        d = np.array(a) - b
        d[2] = wrap_angle(d[2])
        assert np.array_equal(_residual_x(a, b), d)
    for edge in (np.pi, -np.pi, np.nextafter(np.pi, 0), 3 * np.pi, -3 * np.pi):
        assert _residual_x([0.0, 0.0, edge], [0.0, 0.0, 0.0])[2] == wrap_angle(edge)


# ---------------------------------------------------------------- the UKF's sigma points


class _AlwaysFreshUKF(UKFLocalizer):
    """The UKF that draws its sigma points again at every occasion (the path before the memory)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.kf.sigmas_of = lambda x, P: self.kf.points_fn.sigma_points(x, P)     # no memory, in predict too

    def _refresh_sigmas(self):
        self.kf.sigmas_f = self.kf.points_fn.sigma_points(self.kf.x, self.kf.P)


@pytest.mark.parametrize("name", ["tracking", "global", "heading_noise"])
def test_ukf_sigma_cache_changes_no_number(name):
    sc = C.scenario(name)
    d = C.simulate(sc, np.random.default_rng(11))
    kw = dict(dt=sc.dt, mean=d.start + [0.3, -0.2, 0.1], cov=sc.prior_cov)
    a = UKFLocalizer(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw)
    b = _AlwaysFreshUKF(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw)
    for u, z, ids in zip(d.controls, d.z, d.ids):
        for f in (a, b):
            f.predict(u)
            f.update(z, ids if sc.known_ids else None)
        assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)
        # the stored sigma points are always those of the current belief
        assert np.array_equal(a.kf.sigmas_f, a.kf.points_fn.sigma_points(a.kf.x, a.kf.P))


def test_ukf_sigma_cache_notices_a_belief_set_from_outside():
    f = UKFLocalizer([[5.0, 0.0], [0.0, 5.0]], 0.1, 0.05, ALPHAS, cov=np.eye(3) * 0.1)
    f.predict([0.5, 0.1])
    f.kf.P = f.kf.P * 2.0                        # a user edits the filterpy object directly
    f.update([[4.5, 0.1]], [0])
    g = UKFLocalizer([[5.0, 0.0], [0.0, 5.0]], 0.1, 0.05, ALPHAS, cov=np.eye(3) * 0.1)
    g.predict([0.5, 0.1])
    g.reset(g.mean, g.cov * 2.0)
    g.update([[4.5, 0.1]], [0])
    assert np.allclose(f.mean, g.mean, atol=1e-12) and np.allclose(f.cov, g.cov, atol=1e-12)


def test_residual_z_wraps_as_wrap_angle():
    from localize.ekf import _residual_z

    rng = np.random.default_rng(7)
    edges = [np.pi, -np.pi, np.nextafter(np.pi, 0), np.nextafter(-np.pi, 0), 0.0, -0.0, 3 * np.pi, np.nan]
    for _ in range(300):
        k = rng.integers(1, 6)
        a, b = rng.normal(0, 3, 2 * k), rng.normal(0, 3, 2 * k)
        if rng.random() < 0.3:
            a[1::2] = rng.choice(edges, k)
            b[1::2] = 0.0
        d = np.array(a) - b
        d[1::2] = wrap_angle(d[1::2])
        assert np.array_equal(_residual_z(a, b), d, equal_nan=True)


class _FilterpyEKF(EKFLocalizer):
    """The EKF whose corrections go through update_model, i.e. filterpy's own update (the path before)."""

    def _update_sighting(self, zk, m, H):
        from localize.ekf import _residual_z
        from localize.sensors import range_bearing

        self.update_model(zk, lambda x: range_bearing(x, m), H, self.R1, residual=_residual_z)


@pytest.mark.parametrize("name", ["tracking", "large_prior", "global", "kidnapping", "heading_noise"])
def test_ekf_lean_update_equals_filterpy_update(name):
    sc = C.scenario(name)
    d = C.simulate(sc, np.random.default_rng(12))
    kw = dict(dt=sc.dt, mean=d.start + [0.3, -0.2, 0.1], cov=sc.prior_cov)
    a = EKFLocalizer(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw)
    b = _FilterpyEKF(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw)
    _in_lockstep(a, b, sc, d, ("S", "K", "y", "x_post", "P_post", "z"))


def _in_lockstep(a, b, sc, d, attrs):
    """Step filters ``a`` and ``b`` through the simulated run ``d``: after every step their beliefs, and after
    every correction the filterpy attributes ``attrs``, are equal bit for bit."""
    for u, z, ids in zip(d.controls, d.z, d.ids):
        for f in (a, b):
            f.step(u, z, ids if sc.known_ids else None)
        assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)
        if len(z):
            for attr in attrs:
                assert np.array_equal(getattr(a.kf, attr), getattr(b.kf, attr)), attr


class _FilterpyUpdateUKF(UKFLocalizer):
    """The UKF whose correction calls filterpy's own update, one hx call per sigma point (the path before)."""

    def update(self, z, ids=None):
        from localize.sensors import range_bearing

        zz, ii = self._sightings(z, ids)
        if len(zz) == 0:
            return
        if ii is None:
            ii = self.associate(zz)
        lms = self.landmarks[ii]
        self.kf.sigmas_f = self.kf.points_fn.sigma_points(self.kf.x, self.kf.P)
        self.kf.update(zz.reshape(-1), R=np.kron(np.eye(len(zz)), self.R1),
                       hx=lambda x: range_bearing(x, lms).reshape(-1))
        self._fix()
        self.kf.sigmas_f = self.kf.points_fn.sigma_points(self.kf.x, self.kf.P)


@pytest.mark.parametrize("name", ["tracking", "large_prior", "kidnapping", "ambiguity", "heading_noise"])
def test_ukf_update_all_equals_filterpy_update(name):
    sc = C.scenario(name)
    d = C.simulate(sc, np.random.default_rng(13))
    kw = dict(dt=sc.dt, mean=d.start + [0.3, -0.2, 0.1], cov=sc.prior_cov)
    a = UKFLocalizer(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw)
    b = _FilterpyUpdateUKF(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw)
    _in_lockstep(a, b, sc, d, ("sigmas_h", "S", "K", "y", "x_post", "P_post", "z"))
