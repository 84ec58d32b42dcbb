"""Tests of localize.motion: kinematics, sampler == density, normalisation, invariances, bad input.

Statistical tests use fixed seeds and tolerances derived from the sample size
(5 standard errors unless said otherwise); each also shows that a plausible
wrong model would fail the same check.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from localize.geometry import compose, relative, wrap_angle
from localize.motion import (
    forward_pdf_xy,
    motion_model_odometry,
    motion_model_velocity,
    move_odometry,
    move_velocity,
    odometry_pdf,
    odometry_pdf_xy,
    odometry_to_control,
    odometry_variances,
    sample_forward,
    sample_motion_model_odometry,
    sample_motion_model_velocity,
    sample_odometry,
    sample_velocity,
    velocity_pdf,
    velocity_variances,
)

ALPHAS = np.array([0.05, 0.02, 0.02, 0.05])
VALPHAS = np.array([0.02, 0.01, 0.02, 0.02, 0.01, 0.02])

finite = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
angle = st.floats(-3 * math.pi, 3 * math.pi, allow_nan=False, allow_infinity=False)
pose_st = st.tuples(finite, finite, angle).map(np.array)


def grid3(x0, x1, y0, y1, hx, nth):
    """Cell centres of a regular (x, y, theta) grid and the cell volume."""
    xs = np.arange(x0, x1, hx) + hx / 2
    ys = np.arange(y0, y1, hx) + hx / 2
    ths = -math.pi + (np.arange(nth) + 0.5) * (2 * math.pi / nth)
    X, Y, T = np.meshgrid(xs, ys, ths, indexing="ij")
    return np.stack([X, Y, T], -1), hx * hx * 2 * math.pi / nth


# ----------------------------------------------------------------------------
# deterministic kinematics
# ----------------------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(pose_st, pose_st, pose_st)
def test_zero_noise_odometry_reproduces_relative_motion(pose, o0, o1):
    """With alphas = 0 the sampler applies exactly the motion between the two odometry readings."""
    rng = np.random.default_rng(0)
    out = sample_odometry(pose[None], (o0, o1), np.zeros(4), rng)[0]
    expected = compose(pose, relative(o0, o1))
    np.testing.assert_allclose(out[:2], expected[:2], rtol=0, atol=1e-9)
    assert abs(wrap_angle(out[2] - expected[2])) < 1e-9
    # and equals the noise-free kinematics of the control
    np.testing.assert_allclose(out, move_odometry(pose, *odometry_to_control(o0, o1)), rtol=0, atol=1e-12)


def test_zero_noise_velocity_matches_circular_arc_and_straight_line():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 2.5], [3.0, 1.0, -3.0]])
    rng = np.random.default_rng(0)
    for v, w, dt in [(1.0, 0.5, 2.0), (-0.7, 1.3, 0.5), (0.4, -2.0, 1.0)]:
        out = sample_velocity(poses, (v, w), dt, np.zeros(6), rng)
        r = v / w
        th = poses[:, 2]
        x = poses[:, 0] - r * np.sin(th) + r * np.sin(th + w * dt)       # PR eq. 5.9
        y = poses[:, 1] + r * np.cos(th) - r * np.cos(th + w * dt)
        np.testing.assert_allclose(out[:, 0], x, atol=1e-12)
        np.testing.assert_allclose(out[:, 1], y, atol=1e-12)
        np.testing.assert_allclose(out[:, 2], wrap_angle(th + w * dt), atol=1e-12)
    # straight line: exact, and the limit omega -> 0 is continuous and finite
    out = sample_velocity(poses, (1.5, 0.0), 2.0, np.zeros(6), rng)
    np.testing.assert_array_equal(out[:, 2], poses[:, 2])
    np.testing.assert_allclose(out[:, 0], poses[:, 0] + 3.0 * np.cos(poses[:, 2]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out[:, 1], poses[:, 1] + 3.0 * np.sin(poses[:, 2]), rtol=0, atol=1e-15)
    for w in (1e-300, 1e-12, -1e-8):
        tiny = sample_velocity(poses, (1.5, w), 2.0, np.zeros(6), rng)
        assert np.all(np.isfinite(tiny))
        np.testing.assert_allclose(tiny[:, :2], out[:, :2], atol=1e-7)


def test_odometry_to_control_examples():
    r1, t, r2 = odometry_to_control([0, 0, 0], [0, 2, 0])
    assert (round(r1, 12), round(t, 12), round(r2, 12)) == (round(math.pi / 2, 12), 2.0, round(-math.pi / 2, 12))
    # odometry frame with an arbitrary origin: only the relative motion matters
    a = odometry_to_control([5, 5, 1.0], compose([5, 5, 1.0], [0, 2, 0]))
    np.testing.assert_allclose(a, (math.pi / 2, 2.0, -math.pi / 2), atol=1e-12)
    # turning in place: rot1 = 0, the turn is rot2
    assert odometry_to_control([1, 1, 3.0], [1, 1, -3.0]) == (0.0, 0.0, pytest.approx(wrap_angle(-6.0)))
    # vectorised
    r1, t, r2 = odometry_to_control(np.zeros((4, 3)), np.array([[1, 0, 0]] * 4))
    assert r1.shape == (4,) and np.all(t == 1)


# ----------------------------------------------------------------------------
# readable == fast
# ----------------------------------------------------------------------------

def test_fast_samplers_equal_readable_versions():
    rng = np.random.default_rng(7)
    for _ in range(30):
        pose = rng.normal(size=3) * [2, 2, 3]
        u = (rng.normal(size=3), rng.normal(size=3))
        for noise, sign in [("squared", -1), ("absolute", 1)]:
            a = rng.uniform(0, 0.2, 4)
            seed = int(rng.integers(1 << 30))
            fast = sample_odometry(pose[None], u, a, np.random.default_rng(seed), noise=noise, sign=sign)[0]
            slow = sample_motion_model_odometry(pose, u, a, np.random.default_rng(seed), noise=noise, sign=sign)
            np.testing.assert_allclose(fast, slow, atol=1e-12)
            va = rng.uniform(0, 0.1, 6)
            vu = (rng.normal(), rng.normal())
            fast = sample_velocity(pose[None], vu, 0.8, va, np.random.default_rng(seed), noise=noise, sign=sign)[0]
            slow = sample_motion_model_velocity(pose, vu, 0.8, va, np.random.default_rng(seed), noise=noise, sign=sign)
            np.testing.assert_allclose(fast, slow, atol=1e-9)


def test_fast_densities_equal_readable_versions():
    rng = np.random.default_rng(8)
    for i in range(40):
        prev = rng.normal(size=3)
        u = (rng.normal(size=3), rng.normal(size=3))
        a = rng.uniform(0.01, 1.0, 4) if i % 2 else rng.uniform(0.001, 0.05, 4)
        # test points: near the mean motion (where the density is large) and random
        mean = move_odometry(prev, *odometry_to_control(*u))
        # far in the tails the fast version may drop terms below 1e-10 of the peak
        peak = motion_model_odometry(mean, u, prev, a)
        for q in (mean + rng.normal(size=3) * 0.1, rng.normal(size=3)):
            fast = float(odometry_pdf(q, u, prev, a))
            slow = motion_model_odometry(q, u, prev, a)
            assert fast == pytest.approx(slow, rel=1e-9, abs=1e-10 * peak)
        va = rng.uniform(0.005, 0.2, 6)
        vu = (rng.normal(), rng.normal())
        mean = move_velocity(prev, vu[0], vu[1], 1.3)
        peak = motion_model_velocity(mean, vu, prev, 1.3, va)
        for q in (mean + rng.normal(size=3) * 0.05, rng.normal(size=3)):
            fast = float(velocity_pdf(q, vu, prev, 1.3, va))
            slow = motion_model_velocity(q, vu, prev, 1.3, va)
            assert fast == pytest.approx(slow, rel=1e-7, abs=1e-10 * peak)


def test_fast_sampler_broadcasts_per_pose_controls():
    rng = np.random.default_rng(3)
    poses = rng.normal(size=(5, 3))
    o0, o1 = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    out = sample_odometry(poses, (o0, o1), np.zeros(4), rng)
    for k in range(5):
        np.testing.assert_allclose(out[k], move_odometry(poses[k], *odometry_to_control(o0[k], o1[k])), atol=1e-12)
    dens = odometry_pdf(out + 0.01, (o0, o1), poses, ALPHAS)
    assert dens.shape == (5,)
    for k in range(5):
        assert dens[k] == pytest.approx(motion_model_odometry(out[k] + 0.01, (o0[k], o1[k]), poses[k], ALPHAS))


# ----------------------------------------------------------------------------
# the density integrates to one over (x, y, theta)
# ----------------------------------------------------------------------------

def test_odometry_density_integrates_to_one_and_table_5_5_to_the_translation():
    u = ([0.0, 0.0, 0.0], [1.0, 0.3, 0.4])
    pts, dv = grid3(-0.5, 2.0, -1.0, 1.5, 0.0125, 90)
    p = odometry_pdf(pts, u, [0.0, 0.0, 0.0], ALPHAS)
    assert p.sum() * dv == pytest.approx(1.0, abs=1e-6)       # midpoint rule on a smooth, well-covered density
    # without the Jacobian 1/trans_hat (PR table 5.5 as printed) the integral is E[trans_hat] = trans
    d = np.hypot(pts[..., 0], pts[..., 1])
    trans = odometry_to_control(*u)[1]
    assert (p * d).sum() * dv == pytest.approx(trans, abs=1e-3)
    assert abs((p * d).sum() * dv - 1.0) > 0.03


def test_odometry_density_integrates_to_one_with_large_noise_in_polar_coordinates():
    """Short motion, large noise: the wrapped angles and the backwards branch both matter.

    The mass piles up near the start (the density has a 1/r singularity there),
    so the quadrature is done in polar coordinates around the start, where
    dx dy = r dr dphi is exact. The midpoint rule on this periodic, smooth
    integrand is very accurate; tolerance 1e-6.
    """
    u = ([0.0, 0.0, 0.0], [0.2, 0.0, 1.0])
    a = np.array([0.5, 0.5, 1.0, 0.5])
    nr, nphi, nth = 300, 120, 48
    hr = 6.0 / nr
    r = (np.arange(nr) + 0.5) * hr
    phi = -math.pi + (np.arange(nphi) + 0.5) * 2 * math.pi / nphi
    th = -math.pi + (np.arange(nth) + 0.5) * 2 * math.pi / nth
    R, PHI, TH = np.meshgrid(r, phi, th, indexing="ij")
    pts = np.stack([R * np.cos(PHI), R * np.sin(PHI), TH], -1)
    p = odometry_pdf(pts, u, [0.0, 0.0, 0.0], a)
    cell = hr * (2 * math.pi / nphi) * (2 * math.pi / nth)
    assert (p * R).sum() * cell == pytest.approx(1.0, abs=1e-6)
    # the backwards branch carries real mass here: without it the integral is far below one
    from localize.motion import _odometry_density_block

    r1, t, r2 = odometry_to_control(*u)
    s1, s_t, s2 = (np.sqrt(v) for v in odometry_variances(r1, t, r2, a))
    no_mirror = _odometry_density_block(pts.reshape(-1, 3), np.zeros((pts.size // 3, 3)), r1, t, r2, s1, s_t, s2,
                                        True, False).reshape(R.shape)
    assert (no_mirror * R).sum() * cell < 0.7


def test_position_marginal_is_the_density_integrated_over_heading():
    u = ([0.0, 0.0, 0.0], [1.0, 0.5, 0.2])
    pts, _ = grid3(0.5, 1.3, 0.2, 0.8, 0.1, 120)
    full = odometry_pdf(pts, u, [0.0, 0.0, 0.0], ALPHAS).sum(axis=-1) * (2 * math.pi / 120)
    xy = odometry_pdf_xy(pts[:, :, 0, :2], u, [0.0, 0.0, 0.0], ALPHAS)
    np.testing.assert_allclose(full, xy, rtol=1e-6, atol=1e-9)


def test_velocity_density_integrates_to_one():
    pts, dv = grid3(-0.2, 1.6, -0.6, 1.2, 0.015, 60)
    p = velocity_pdf(pts, (1.0, 0.8), [0.0, 0.0, 0.0], 1.0, VALPHAS)
    assert p.sum() * dv == pytest.approx(1.0, abs=1e-4)
    # straight-line command: same, and finite everywhere
    pts, dv = grid3(0.3, 1.7, -0.6, 0.6, 0.015, 60)
    p = velocity_pdf(pts, (1.0, 0.0), [0.0, 0.0, 0.0], 1.0, [0.02, 0.01, 0.02, 0.02, 0.01, 0.02], min_std=0.05)
    assert np.all(np.isfinite(p))
    assert p.sum() * dv == pytest.approx(1.0, abs=1e-4)


def test_forward_density_integrates_to_one():
    h = 0.01
    xs = np.arange(-1.0, 3.0, h) + h / 2
    X, Y = np.meshgrid(xs, xs - 2.0)
    p = forward_pdf_xy(np.stack([X, Y], -1), [0.0, 0.0, 0.3], 1.0, 0.1, 0.2)
    assert p.sum() * h * h == pytest.approx(1.0, abs=1e-3)


# ----------------------------------------------------------------------------
# sampler and density describe the same distribution
# ----------------------------------------------------------------------------

def _moments(pts, p, dv):
    w = (p * dv).reshape(-1)
    x = pts.reshape(-1, 3)
    m = w.sum()
    mean = w @ x / m
    c = x - mean
    cov = (c * w[:, None]).T @ c / m
    return m, mean, cov


def _check_moments(samples, mean, cov, n_se=5.0):
    """Sample mean and covariance within n_se standard errors of the model's.

    Standard errors come from the sample size: sqrt(var/n) for the means, and
    sqrt((E[c_i^2 c_j^2] - cov_ij^2)/n) for the covariances (fourth moments
    estimated from the samples, because a banana-shaped cloud is not Gaussian).
    """
    n = len(samples)
    sm = samples.mean(axis=0)
    c = samples - sm
    sc = c.T @ c / (n - 1)
    se_mean = np.sqrt(np.diag(cov) / n)
    m4 = np.einsum("ni,nj->ij", c * c, c * c) / n
    se_cov = np.sqrt((m4 - sc**2) / n)
    ok = np.all(np.abs(sm - mean) <= n_se * se_mean) and np.all(np.abs(sc - cov) <= n_se * se_cov)
    return bool(ok), sm, sc


@pytest.mark.slow
def test_odometry_sampler_moments_match_density():
    rng = np.random.default_rng(2024)
    u = ([0.0, 0.0, 0.0], [1.0, 0.3, 0.4])
    a = np.array([0.1, 0.05, 0.05, 0.1])
    n = 100_000
    s = sample_odometry(np.zeros((n, 3)), u, a, rng)
    pts, dv = grid3(-0.7, 2.1, -1.3, 1.7, 0.02, 90)
    pts = pts[:, :, 30:80]                      # heading window that holds the mass
    p = odometry_pdf(pts, u, [0.0, 0.0, 0.0], a)
    m, mean, cov = _moments(pts, p, dv)
    assert m == pytest.approx(1.0, abs=2e-3)
    ok, sm, sc = _check_moments(s, mean, cov)
    assert ok, (sm, mean, sc, cov)
    # a wrong model fails the same check: variances from |.| instead of squares
    p_wrong = odometry_pdf(pts, u, [0.0, 0.0, 0.0], a, noise="absolute")
    _, mean_w, cov_w = _moments(pts, p_wrong, dv)
    assert not _check_moments(s, mean_w, cov_w)[0]


@pytest.mark.slow
def test_velocity_sampler_moments_match_density():
    rng = np.random.default_rng(2025)
    n = 100_000
    s = sample_velocity(np.zeros((n, 3)), (1.0, 0.8), 1.0, VALPHAS, rng)
    pts, dv = grid3(0.2, 1.5, -0.2, 1.0, 0.01, 90)
    pts = pts[:, :, 45:75]
    p = velocity_pdf(pts, (1.0, 0.8), [0.0, 0.0, 0.0], 1.0, VALPHAS)
    m, mean, cov = _moments(pts, p, dv)
    assert m == pytest.approx(1.0, abs=3e-3)
    ok, sm, sc = _check_moments(s, mean, cov)
    assert ok, (sm, mean, sc, cov)
    # PR table 5.1 without the final rotation gamma describes a different heading spread
    p_wrong = velocity_pdf(pts, (1.0, 0.8), [0.0, 0.0, 0.0], 1.0, VALPHAS * [1, 1, 1, 1, 0.25, 0.25])
    _, mean_w, cov_w = _moments(pts, p_wrong, dv)
    assert not _check_moments(s, mean_w, cov_w)[0]


def test_ks_test_on_the_x_marginal_of_the_odometry_model():
    """The x coordinate of 1e5 samples against the CDF obtained by integrating the density."""
    rng = np.random.default_rng(11)
    u = ([0.0, 0.0, 0.0], [1.0, 0.3, 0.4])
    a = np.array([0.1, 0.05, 0.05, 0.1])
    x = sample_odometry(np.zeros((100_000, 3)), u, a, rng)[:, 0]
    h = 0.004
    xs = np.arange(-0.6, 2.2, h) + h / 2
    ys = np.arange(-1.4, 1.8, h) + h / 2
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    px = odometry_pdf_xy(np.stack([X, Y], -1), u, [0.0, 0.0, 0.0], a).sum(axis=1) * h
    cdf_knots = np.concatenate([[0.0], np.cumsum(px) * h])
    edges = np.concatenate([xs - h / 2, [xs[-1] + h / 2]])
    assert cdf_knots[-1] == pytest.approx(1.0, abs=1e-3)

    def cdf(v):
        return np.interp(v, edges, cdf_knots / cdf_knots[-1])

    res = stats.kstest(x, cdf)
    assert res.pvalue > 1e-3, res
    # a wrong model (no Jacobian, renormalised) is rejected
    pxw = (odometry_pdf_xy(np.stack([X, Y], -1), u, [0, 0, 0], a) * np.hypot(X, Y)).sum(axis=1) * h
    kw = np.concatenate([[0.0], np.cumsum(pxw)])
    assert stats.kstest(x, lambda v: np.interp(v, edges, kw / kw[-1])).pvalue < 1e-6


def test_chi_square_on_the_heading_of_the_velocity_model():
    """Heading histogram of 1e5 samples vs the density's heading marginal (chi-square)."""
    rng = np.random.default_rng(12)
    th = sample_velocity(np.zeros((100_000, 3)), (1.0, 0.8), 1.0, VALPHAS, rng)[:, 2]
    pts, dv = grid3(0.2, 1.5, -0.2, 1.0, 0.02, 180)
    p = velocity_pdf(pts, (1.0, 0.8), [0.0, 0.0, 0.0], 1.0, VALPHAS).sum(axis=(0, 1)) * dv   # per theta cell
    edges = -math.pi + np.arange(181) * (2 * math.pi / 180)
    counts, _ = np.histogram(th, edges)
    keep = p * len(th) > 20
    # pool the tails into one bin so every expected count is large
    exp_ = np.append(p[keep] / p.sum() * len(th), len(th) * (1 - p[keep].sum() / p.sum()))
    obs = np.append(counts[keep], len(th) - counts[keep].sum())
    chi2 = ((obs - exp_) ** 2 / np.maximum(exp_, 1e-9)).sum()
    dof = len(obs) - 1
    assert stats.chi2.sf(chi2, dof) > 1e-3, (chi2, dof)


def test_forward_model_samples_match_its_density():
    rng = np.random.default_rng(13)
    s = sample_forward(np.tile([0.0, 0.0, 0.5], (100_000, 1)), 1.0, 0.1, 0.2, rng)
    # heading noise only: the heading equals the direction of travel
    np.testing.assert_allclose(wrap_angle(np.arctan2(s[:, 1], s[:, 0]) - s[:, 2]), 0.0, atol=1e-9)
    d = np.hypot(s[:, 0], s[:, 1])
    assert abs(d.mean() - 1.0) < 5 * 0.1 / math.sqrt(len(d))
    # chi-square on a 2-D histogram against the density integrated over the cells
    edges = np.linspace(-0.2, 1.4, 33)
    h = edges[1] - edges[0]
    sub = 8
    fine = edges[0] + (np.arange(32 * sub) + 0.5) * h / sub
    X, Y = np.meshgrid(fine, fine, indexing="ij")
    pf = forward_pdf_xy(np.stack([X, Y], -1), [0.0, 0.0, 0.5], 1.0, 0.1, 0.2) * (h / sub) ** 2
    expected = pf.reshape(32, sub, 32, sub).sum(axis=(1, 3)) * len(s)
    counts, _, _ = np.histogram2d(s[:, 0], s[:, 1], [edges, edges])
    keep = expected > 20
    chi2 = ((counts[keep] - expected[keep]) ** 2 / expected[keep]).sum()
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-3


# ----------------------------------------------------------------------------
# noise conventions
# ----------------------------------------------------------------------------

def test_noise_conventions_and_sign():
    r = (0.3, 2.0, -0.1)
    sq = odometry_variances(*r, ALPHAS)
    ab = odometry_variances(*r, ALPHAS, "absolute")
    np.testing.assert_allclose(sq, [0.05 * 0.09 + 0.02 * 4, 0.02 * 4 + 0.05 * 0.1, 0.05 * 0.01 + 0.02 * 4])
    np.testing.assert_allclose(ab, [0.05 * 0.3 + 0.02 * 2, 0.02 * 2 + 0.05 * 0.4, 0.05 * 0.1 + 0.02 * 2])

    def seed001(r1, t, r2, a):      # alpha4 * |rot1 + rot2| in the translation, as one report writes it
        return a[0] * abs(r1) + a[1] * abs(t), a[2] * abs(t) + a[3] * abs(r1 + r2), a[0] * abs(r2) + a[1] * abs(t)

    np.testing.assert_allclose(odometry_variances(*r, ALPHAS, seed001)[1], 0.02 * 2 + 0.05 * 0.2)
    np.testing.assert_allclose(velocity_variances(2.0, -0.5, VALPHAS, "absolute"),
                               [0.02 * 2 + 0.01 * 0.5, 0.02 * 2 + 0.02 * 0.5, 0.01 * 2 + 0.02 * 0.5])
    # the sign mirrors each sample about the noise-free motion: same distribution
    u = ([0, 0, 0], [1.0, 0.0, 0.0])
    plus = sample_odometry(np.zeros((5, 3)), u, [0, 0, 0.1, 0], np.random.default_rng(1), sign=1)
    minus = sample_odometry(np.zeros((5, 3)), u, [0, 0, 0.1, 0], np.random.default_rng(1), sign=-1)
    np.testing.assert_allclose(plus[:, 0] - 1.0, -(minus[:, 0] - 1.0), atol=1e-12)


def test_squared_noise_depends_on_the_update_rate_absolute_does_not():
    """Driving 2 m in n steps: the spread of squared-noise models shrinks like 1/sqrt(n)."""
    rng = np.random.default_rng(5)
    n_p = 40_000
    spreads = {}
    for noise in ("squared", "absolute"):
        for n in (1, 8):
            p = np.zeros((n_p, 3))
            for k in range(n):
                u = ([2.0 * k / n, 0, 0], [2.0 * (k + 1) / n, 0, 0])
                p = sample_odometry(p, u, [0, 0, 0.05, 0], rng, noise=noise)
            spreads[noise, n] = p[:, 0].std()
    # along-track std: squared sqrt(n * a * (2/n)^2) = 2 sqrt(a / n); absolute sqrt(n * a * 2/n) = sqrt(2 a)
    tol = 5 / math.sqrt(2 * n_p)
    assert spreads["squared", 1] / spreads["squared", 8] == pytest.approx(math.sqrt(8), rel=3 * tol)
    assert spreads["absolute", 1] / spreads["absolute", 8] == pytest.approx(1.0, rel=3 * tol)


# ----------------------------------------------------------------------------
# wrapping and invariance
# ----------------------------------------------------------------------------

def test_angles_wrap():
    rng = np.random.default_rng(0)
    poses = np.tile([0.0, 0.0, math.pi - 1e-3], (2000, 1))
    u = ([0, 0, 3.0], [0.1, 0.0, -3.0])
    s = sample_odometry(poses, u, ALPHAS, rng)
    assert np.all(s[:, 2] >= -math.pi) and np.all(s[:, 2] < math.pi)
    v = sample_velocity(poses, (1.0, 3.0), 2.0, VALPHAS, rng)
    assert np.all(v[:, 2] >= -math.pi) and np.all(v[:, 2] < math.pi)
    # densities do not care which representative of an angle they get
    q = np.array([0.1, 0.01, 2.5])
    base = odometry_pdf(q, u, [0, 0, 3.1], ALPHAS)
    assert base > 0
    for shift in (2 * math.pi, -4 * math.pi):
        assert odometry_pdf(q + [0, 0, shift], u, [0, 0, 3.1 - shift], ALPHAS) == pytest.approx(base, rel=1e-9)
        uu = ([0, 0, 3.0 + shift], [0.1, 0.0, -3.0 - shift])
        assert odometry_pdf(q, uu, [0, 0, 3.1], ALPHAS) == pytest.approx(base, rel=1e-9)
        vb = velocity_pdf([1.0, 0.1, 0.2], (1.0, 0.2), [0, 0, 0], 1.0, VALPHAS)
        assert velocity_pdf([1.0, 0.1, 0.2 + shift], (1.0, 0.2), [0, 0, shift], 1.0, VALPHAS) == pytest.approx(vb)


@settings(max_examples=40, deadline=None)
@given(pose_st, pose_st, pose_st, st.integers(0, 2**31 - 1))
def test_invariant_to_moving_the_whole_world(world, odom_frame, start, seed):
    """Moving the robot (world frame) and, independently, the odometry frame changes nothing."""
    rng = np.random.default_rng(seed)
    o0 = np.array([0.3, -0.2, 0.1])
    o1 = np.array([1.1, 0.4, 0.7])
    u = (o0, o1)
    u_moved = (compose(odom_frame, o0), compose(odom_frame, o1))
    s = sample_odometry(np.tile(start, (50, 1)), u, ALPHAS, np.random.default_rng(seed))
    s_moved = sample_odometry(np.tile(compose(world, start), (50, 1)), u_moved, ALPHAS, np.random.default_rng(seed))
    np.testing.assert_allclose(s_moved[:, :2], compose(world, s)[:, :2], atol=1e-8)
    assert np.all(np.abs(wrap_angle(s_moved[:, 2] - compose(world, s)[:, 2])) < 1e-8)
    q = s[:5] + rng.normal(size=(5, 3)) * 0.05
    p = odometry_pdf(q, u, start, ALPHAS)
    p_moved = odometry_pdf(compose(world, q), u_moved, compose(world, start), ALPHAS)
    np.testing.assert_allclose(p_moved, p, rtol=1e-6, atol=1e-12)
    pv = velocity_pdf(q, (1.0, 0.5), start, 1.0, VALPHAS)
    pv_moved = velocity_pdf(compose(world, q), (1.0, 0.5), compose(world, start), 1.0, VALPHAS)
    np.testing.assert_allclose(pv_moved, pv, rtol=1e-6, atol=1e-12)


# ----------------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------------

U = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])


@pytest.mark.parametrize("call, match", [
    (lambda r: sample_odometry(np.zeros((3, 3)), U, [-0.1, 0, 0, 0], r), "alphas"),
    (lambda r: sample_odometry(np.zeros((3, 3)), U, [0.1, 0, 0], r), "alphas"),
    (lambda r: odometry_pdf(np.zeros(3), U, np.zeros(3), [0.1, 0.1, 0.1, -1]), "alphas"),
    (lambda r: sample_velocity(np.zeros((3, 3)), (1.0, 0.0), 1.0, [0.1] * 5 + [-0.1], r), "alphas"),
    (lambda r: velocity_pdf(np.zeros(3), (1.0, 0.0), np.zeros(3), 1.0, [np.nan] * 6), "alphas"),
    (lambda r: sample_odometry(np.zeros((3, 2)), U, [0.1] * 4, r), "poses"),
    (lambda r: sample_odometry(np.zeros((3, 3)), ([0, 0], [1, 0]), [0.1] * 4, r), r"u\[0\]"),
    (lambda r: sample_odometry(np.zeros((3, 3)), np.zeros(3), [0.1] * 4, r), "u must be the pair"),
    (lambda r: sample_odometry(np.zeros((3, 3)), ([0, 0, 0], [1, np.nan, 0]), [0.1] * 4, r), r"u\[1\]"),
    (lambda r: sample_odometry(np.zeros((3, 3)), (np.zeros((2, 3)), [1, 0, 0]), [0.1] * 4, r), "broadcast"),
    (lambda r: odometry_pdf(np.zeros((3, 3)), U, np.zeros((2, 3)), [0.1] * 4), "broadcast"),
    (lambda r: odometry_pdf(np.zeros((3, 4)), U, np.zeros(3), [0.1] * 4), "pose"),
    (lambda r: odometry_pdf(np.zeros(3), U, [0, np.nan, 0], [0.1] * 4), "prev_pose"),
    (lambda r: sample_velocity(np.zeros((3, 3)), (1.0, 0.0), 0.0, [0.1] * 6, r), "dt"),
    (lambda r: sample_velocity(np.zeros((3, 3)), (1.0, 0.0), -1.0, [0.1] * 6, r), "dt"),
    (lambda r: velocity_pdf(np.zeros(3), (1.0, 0.0), np.zeros(3), np.nan, [0.1] * 6), "dt"),
    (lambda r: sample_velocity(np.zeros((3, 3)), (np.nan, 0.0), 1.0, [0.1] * 6, r), "u"),
    (lambda r: sample_velocity(np.zeros((3, 3)), (1.0, 0.0, 2.0), 1.0, [0.1] * 6, r), "u"),
    (lambda r: sample_odometry(np.zeros((3, 3)), U, [0.1] * 4, r, sign=0), "sign"),
    (lambda r: sample_odometry(np.zeros((3, 3)), U, [0.1] * 4, r, noise="cubic"), "noise"),
    (lambda r: sample_forward(np.zeros((3, 3)), 1.0, -0.1, 0.1, r), "sigma_distance"),
    (lambda r: sample_forward(np.zeros((3, 3)), np.nan, 0.1, 0.1, r), "distance"),
    (lambda r: forward_pdf_xy(np.zeros((3, 3)), np.zeros(3), 1.0, 0.1, 0.1), "xy"),
    (lambda r: odometry_pdf(np.zeros(3), U, np.zeros(3), [0.1] * 4, min_std=-1), "min_std"),
])
def test_bad_input_raises_value_error_naming_the_parameter(call, match):
    with pytest.raises(ValueError, match=match):
        call(np.random.default_rng(0))


def test_rng_must_be_a_generator():
    with pytest.raises(TypeError, match="rng"):
        sample_odometry(np.zeros((3, 3)), U, [0.1] * 4, 42)


def test_degenerate_density_is_an_error_unless_min_std():
    # turning in place: rot1 and trans are exactly 0 and so is the rot1 noise
    u = ([0, 0, 0], [0, 0, 1.0])
    with pytest.raises(ValueError, match="degenerate.*rot1.*min_std"):
        odometry_pdf([0.0, 0.0, 1.0], u, [0, 0, 0], ALPHAS)
    p = odometry_pdf([0.01, 0.0, 1.0], u, [0, 0, 0], ALPHAS, min_std=0.01)
    assert np.isfinite(p) and p > 0
    with pytest.raises(ValueError, match="degenerate"):
        velocity_pdf([1.0, 0.0, 0.0], (1.0, 0.0), [0, 0, 0], 1.0, np.zeros(6))
    # at the start position the density is large but finite
    assert np.isfinite(odometry_pdf([0.0, 0.0, 0.0], U, [0, 0, 0], [1, 1, 1, 1]))


def test_particle_movers_live_in_motion_and_keep_their_old_names():
    import localize
    from localize import mcl, motion

    for name in ("OdometryMotion", "ReversibleOdometry", "VelocityMotion"):
        assert getattr(mcl, name) is getattr(motion, name)
    assert localize.OdometryMotion is motion.OdometryMotion and localize.VelocityMotion is motion.VelocityMotion
    with pytest.raises(ValueError, match="alphas"):
        motion.OdometryMotion((0.1, 0.1))
    with pytest.raises(ValueError, match="min_trans"):
        motion.ReversibleOdometry((0.1,) * 4, min_trans=-1.0)
    with pytest.raises(ValueError, match="dt"):
        motion.VelocityMotion((0.1,) * 6, dt=0.0)


def test_fast_paths_equal_readable_versions_across_the_block_boundary():
    # the fast samplers and densities work in cache-sized blocks of _BLOCK poses; the poses on both sides
    # of a block boundary (and the random numbers they use) must be those of the one-pose-at-a-time oracle
    from localize.motion import _BLOCK

    m = _BLOCK + 7
    rng = np.random.default_rng(21)
    poses = rng.normal(size=(m, 3)) * [3.0, 3.0, 2.0]
    u = ([0.1, -0.2, 0.3], [0.9, 0.4, -0.5])
    fast = sample_odometry(poses, u, ALPHAS, np.random.default_rng(5))
    fast_v = sample_velocity(poses, (0.7, 0.4), 0.5, VALPHAS, np.random.default_rng(6))
    oracle = np.random.default_rng(5)
    oracle_v = np.random.default_rng(6)
    slow = np.array([sample_motion_model_odometry(p, u, ALPHAS, oracle) for p in poses])
    slow_v = np.array([sample_motion_model_velocity(p, (0.7, 0.4), 0.5, VALPHAS, oracle_v) for p in poses])
    np.testing.assert_allclose(fast, slow, atol=1e-12)
    np.testing.assert_allclose(fast_v, slow_v, atol=1e-9)
    dens = odometry_pdf(fast, u, poses, ALPHAS)
    for k in (0, _BLOCK - 2, _BLOCK - 1, _BLOCK, _BLOCK + 1, m - 1):
        assert dens[k] == pytest.approx(motion_model_odometry(fast[k], u, poses[k], ALPHAS), rel=1e-9)


def test_a_turn_on_the_spot_with_a_creeping_odometry_point_keeps_the_particles_together():
    """A robot turns 7 degrees on the spot while its odometry point (a few cm off the axis) creeps 5 mm
    sideways. Decomposed as "turn 90 degrees towards the creep, drive 5 mm, turn back 83 degrees", the
    textbook noise (growing with rot1**2 + rot2**2) scatters the particles by half a metre; counted as a
    turn on the spot, they spread by the translation noise of that turn, sqrt(a3 t^2 + a4 turn^2), and are
    moved by the step as measured (no bias from dropping its direction)."""
    from localize.motion import ReversibleOdometry, sample_odometry

    alphas = (0.05, 0.01, 0.02, 0.05)
    n = 20000
    t, turn = 0.005, 0.12
    for sideways in (1.0, -1.0):
        u = ([0.0, 0.0, 0.0], [0.0, sideways * t, turn])
        move = ReversibleOdometry(alphas)
        expected_sd = math.sqrt(alphas[2] * t**2 + alphas[3] * turn**2)
        assert move.on_the_spot(t, turn) == pytest.approx(expected_sd)
        q = move(np.zeros((n, 3)), u, np.random.default_rng(4))
        sd = np.hypot(*q[:, :2].std(axis=0))
        assert abs(sd / expected_sd - 1) < 5 / math.sqrt(2 * n), sd          # std of a std: sd / sqrt(2n)
        assert abs(q[:, 1].mean() - sideways * t) < 5 * expected_sd / math.sqrt(n)
        assert abs(wrap_angle(q[:, 2] - turn).mean()) < 5 * math.sqrt(alphas[0]) * turn / math.sqrt(n) + 1e-4
        plain = sample_odometry(np.zeros((n, 3)), u, alphas, np.random.default_rng(4), min_trans=1e-3)
        assert np.hypot(*plain[:, :2].std(axis=0)) > 0.4                    # the textbook decomposition
    # a drive is a drive: 30 cm ahead while turning 7 degrees is moved exactly as the plain model does
    drive = ([0.0, 0.0, 0.0], [0.3, 0.01, turn])
    assert 0.3 > ReversibleOdometry(alphas).on_the_spot(0.3, turn)
    a = ReversibleOdometry(alphas)(np.zeros((100, 3)), drive, np.random.default_rng(5))
    b = sample_odometry(np.zeros((100, 3)), drive, alphas, np.random.default_rng(5), min_trans=1e-3)
    assert np.array_equal(a, b)
