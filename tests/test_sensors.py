"""Tests of localize.sensors (beam model, likelihood field, landmarks) and localize.beam_learning."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from localize import OccupancyGrid
from localize.beam_learning import fit_beam_model
from localize.maps import office
from localize.raycast import RayCaster
from localize.sensors import BeamModel, LandmarkModel, LikelihoodField, check_ranges, select_beams, sensor_poses

MAXR = 8.0


@pytest.fixture(scope="module")
def grid():
    return office()


@pytest.fixture(scope="module")
def caster(grid):
    return RayCaster(grid, MAXR, method="march")


@pytest.fixture(scope="module")
def beam(grid, caster):
    return BeamModel(grid, MAXR, 0.75, 0.1, 0.05, 0.1, sigma_hit=0.15, lambda_short=0.7, caster=caster)


# ------------------------------------------------------- normalisation
@pytest.mark.parametrize("zstar", [0.02, 0.3, 2.0, 7.9, 8.0])
def test_each_component_is_normalised(zstar):
    m = BeamModel(None, MAXR, sigma_hit=0.3, lambda_short=1.5)

    def comp(name):
        return lambda z: float(m.components(z, zstar)[name])

    pts = [zstar] if zstar < MAXR else None
    hit = integrate.quad(comp("p_hit"), 0, MAXR, points=pts, limit=200)[0]
    short = integrate.quad(comp("p_short"), 0, max(zstar, m.z_floor), limit=200)[0]
    rand = integrate.quad(comp("p_rand"), 0, MAXR, limit=200)[0]
    assert hit == pytest.approx(1.0, abs=1e-6)
    assert short == pytest.approx(1.0, abs=1e-6)
    assert rand == pytest.approx(1.0, abs=1e-9)
    assert float(m.components(MAXR, zstar)["p_max"]) == 1.0


@pytest.mark.parametrize("zstar", [0.05, 1.0, 4.0, 7.95, 8.0])
def test_density_plus_max_mass_integrates_to_one(zstar):
    m = BeamModel(None, MAXR, 0.6, 0.2, 0.1, 0.1, sigma_hit=0.2, lambda_short=0.8)
    # continuous part: integrate pdf over [0, max_range) (the point mass sits at max_range only)
    f = lambda z: float(m.pdf(min(z, MAXR * (1 - 1e-12)), zstar))  # noqa: E731
    cont = integrate.quad(f, 0, MAXR, points=[zstar] if zstar < MAXR else None, limit=400)[0]
    assert cont + m.z_max == pytest.approx(1.0, abs=1e-6)
    # the wrong normalisation (no truncation mass) would fail near the ends
    assert abs(cont - (1 - m.z_max)) < 1e-6


def test_pdf_is_the_weighted_sum_of_components():
    m = BeamModel(None, MAXR, 0.6, 0.2, 0.1, 0.1, sigma_hit=0.2, lambda_short=0.8)
    z = np.array([0.0, 0.5, 3.0, 3.1, 7.99, 8.0, 9.0])
    c = m.components(z, 3.0)
    want = 0.6 * c["p_hit"] + 0.2 * c["p_short"] + 0.1 * c["p_max"] + 0.1 * c["p_rand"]
    np.testing.assert_allclose(m.pdf(z, 3.0), want)
    # hand values: hit at the expected range, short below it, max at max_range
    assert m.pdf(3.0, 3.0) == pytest.approx(
        0.6 * stats.norm.pdf(0, scale=0.2) / (stats.norm.cdf(25) - stats.norm.cdf(-15))
        + 0.2 * 0.8 * math.exp(-2.4) / (1 - math.exp(-2.4)) + 0.1 / MAXR)
    assert m.pdf(9.0, 3.0) == pytest.approx(0.1 + 0.6 * stats.norm.pdf(5.0 / 0.2) / 0.2)


def test_fast_log_pdf_matches_readable_pdf():
    m = BeamModel(None, MAXR, 0.6, 0.2, 0.1, 0.1, sigma_hit=0.2, lambda_short=0.8)
    rng = np.random.default_rng(0)
    zs = rng.uniform(0, MAXR, (50, 20))
    zs[0] = 0.0
    zs[1] = MAXR
    z = np.concatenate([rng.uniform(0, MAXR, 18), [MAXR, 0.0]])
    want = np.log(m.pdf(z, zs))
    np.testing.assert_allclose(m.beam_log_pdf(z, zs), want, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(m.beam_log_pdf(z, zs.astype(np.float32)), want, rtol=1e-4, atol=1e-4)


# ------------------------------------------------------------ sampling
def test_sampling_matches_the_distribution():
    m = BeamModel(None, MAXR, 0.6, 0.2, 0.1, 0.1, sigma_hit=0.2, lambda_short=0.8)
    n = 200_000
    z = m.sample_expected(np.full(n, 3.0), np.random.default_rng(1))
    assert z.min() >= 0 and z.max() <= MAXR
    frac_max = np.mean(z == MAXR)
    assert abs(frac_max - 0.1) < 5 * math.sqrt(0.1 * 0.9 / n)
    # compare the empirical CDF to the integral of the density at a few points
    for t in [0.5, 2.0, 2.9, 3.1, 5.0]:
        p = integrate.quad(lambda x: float(m.pdf(x, 3.0)), 0, t, points=[3.0] if t > 3 else None)[0]
        se = math.sqrt(p * (1 - p) / n)
        assert abs(np.mean(z <= t) - p) < 5 * se, t


def test_sample_scans_from_poses(beam, grid):
    rng = np.random.default_rng(2)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 31)
    z = beam.sample([[6.0, 5.5, 0.0], [15.0, 3.0, 1.0]], angles, rng)
    assert z.shape == (2, 31)
    assert np.all((z >= 0) & (z <= MAXR))
    z2 = beam.sample([[6.0, 5.5, 0.0], [15.0, 3.0, 1.0]], angles, np.random.default_rng(2))
    np.testing.assert_array_equal(z, z2)


def test_a_beam_with_nothing_in_range_reads_no_return_not_a_hit_short_of_it(grid):
    """A ray that hits nothing reads max_range from the hit part (a real laser's "no return"), never an end point
    a few sigma_hit short of it; short and random readings, and every beam that hits something, are drawn as
    before (the same random stream)."""
    m = BeamModel(grid, 3.0, z_hit=0.8, z_short=0.1, z_max=0.05, z_rand=0.05, sigma_hit=0.1, method="exact",
                  no_return=True)
    poses = grid.sample_free(200, np.random.default_rng(1))
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    expected = m.expected(poses, angles)
    far = expected >= m.max_range
    assert 0.2 < far.mean() < 0.9                                   # both kinds of beam occur
    z = m.sample_expected(expected, np.random.default_rng(2))
    n = int(far.sum())
    share = np.mean(z[far] == m.max_range)                          # hit + max parts: 0.85
    assert abs(share - 0.85) < 5 * math.sqrt(0.85 * 0.15 / n)
    near_max = far & (z > m.max_range - 5 * m.sigma_hit) & (z < m.max_range)
    # only the random part reaches there (5 sigma of 3 m: 1/6 of its 5%) and the short part, far less
    assert near_max.sum() < 5 * (0.05 / 6 + 0.02) * n
    moved = np.where(far, m.max_range - 1.0, expected)              # the far beams expected elsewhere ...
    z2 = m.sample_expected(moved, np.random.default_rng(2))
    np.testing.assert_array_equal(z[~far], z2[~far])                # ... change no other beam's reading
    plain = BeamModel(grid, 3.0, z_hit=0.8, z_short=0.1, z_max=0.05, z_rand=0.05, sigma_hit=0.1, method="exact")
    zp = plain.sample_expected(expected, np.random.default_rng(2))  # PR's sampler: the hit part short of the range
    assert np.mean(zp[far] == m.max_range) < 0.1 < np.mean((zp[far] > m.max_range - 0.5) & (zp[far] < m.max_range))
    np.testing.assert_array_equal(zp[~far], z[~far])
    ll = [b.log_likelihood(poses[:5], zp[0], angles) for b in (m, plain)]
    np.testing.assert_array_equal(*ll)                              # the likelihoods do not depend on it


# --------------------------------------------------------- pose ranking
def _displaced(true, rng, k=12):
    d = np.column_stack([rng.choice([-1, 1], k) * rng.uniform(0.25, 0.6, k),
                         rng.choice([-1, 1], k) * rng.uniform(0.25, 0.6, k),
                         rng.choice([-1, 1], k) * rng.uniform(0.1, 0.3, k)])
    return true + d


@pytest.mark.parametrize("true", [[6.0, 5.5, 0.3], [3.0, 2.5, 2.0], [16.0, 9.0, -1.2]])
def test_both_models_rank_the_true_pose_first(beam, grid, true):
    rng = np.random.default_rng(7)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 61)
    true = np.array(true)
    scan = beam.sample(true[None], angles, rng)[0]
    cands = np.vstack([true, _displaced(true, rng)])
    cands = cands[grid.is_free(cands)]
    lf = LikelihoodField(grid, MAXR, 0.85, 0.15, sigma_hit=0.15)
    for model in (beam, lf):
        ll = model.log_likelihood(cands, scan, angles)
        assert np.argmax(ll) == 0, type(model).__name__
        assert np.all(ll[0] > ll[1:] + 1.0)


def test_log_likelihood_equals_sum_of_log_pdf(beam):
    angles = np.linspace(-1.5, 1.5, 25)
    poses = np.array([[6.0, 5.5, 0.3], [6.2, 5.6, 0.2]])
    z = beam.sample(poses[:1], angles, np.random.default_rng(3))[0]
    zs = beam.expected(poses, angles)
    want = np.log(beam.pdf(z, zs)).sum(axis=1)
    np.testing.assert_allclose(beam.log_likelihood(poses, z, angles), want, rtol=1e-4)
    np.testing.assert_allclose(beam.log_likelihood_expected(z, zs), want, rtol=1e-9)


def test_beam_model_casts_by_the_compact_table_unless_told(grid):
    """Issue 41: ``BeamModel(grid, 20)`` (a homework call) builds the 8-bit table under its 90 MB budget,
    not the 16-bit 360-bin one (460 MB on an 800 x 800 map); an explicit method or caster still wins."""
    plain = BeamModel(grid, 20.0)
    assert plain.caster.method == "compact"
    h, w = grid.shape
    assert plain.caster.compact_table.nbytes <= 90e6 < 2 * 800 * 800 * 360
    assert plain.caster.compact_table.nbytes < 2 * h * w * 360    # what "lut" would have taken here
    assert BeamModel(grid, 20.0, method="lut").caster.method == "lut"
    rc = RayCaster(grid, 20.0, method="march")
    assert BeamModel(grid, 20.0, caster=rc).caster is rc
    # the compact default scores scans like the exact caster within its documented range error
    angles = np.linspace(-np.pi / 2, np.pi / 2, 19)
    pose = np.array([[6.0, 5.5, 0.3]])
    exact = BeamModel(grid, 20.0, method="exact")
    z = exact.expected(pose, angles)[0]
    err = np.abs(plain.expected(pose, angles) - exact.expected(pose, angles))
    bound = 2 * grid.resolution + z * np.pi / plain.caster.n_bins + 20.0 / 510
    assert np.mean(err <= bound) >= 0.9


def test_beam_subsampling_and_tempering(grid, caster):
    angles = np.linspace(-1.5, 1.5, 181)
    poses = np.array([[6.0, 5.5, 0.3], [6.2, 5.6, 0.2]])
    full = BeamModel(grid, MAXR, caster=caster)
    z = full.sample(poses[:1], angles, np.random.default_rng(4))[0]
    sub = BeamModel(grid, MAXR, caster=caster, max_beams=10)
    k = select_beams(181, 10)
    np.testing.assert_allclose(sub.log_likelihood(poses, z, angles), full.log_likelihood(poses, z[k], angles[k]))
    tem = BeamModel(grid, MAXR, caster=caster, temper=0.25)
    np.testing.assert_allclose(tem.log_likelihood(poses, z, angles), 0.25 * full.log_likelihood(poses, z, angles))


def test_sensor_offset_is_applied(grid, caster):
    angles = np.linspace(-1.0, 1.0, 9)
    robot = np.array([[6.0, 5.5, 0.5]])
    off = (0.25, 0.05, 0.1)
    m = BeamModel(grid, MAXR, caster=caster, sensor_offset=off)
    sp = sensor_poses(robot, off)
    np.testing.assert_allclose(sp[0], [6.0 + 0.25 * math.cos(0.5) - 0.05 * math.sin(0.5),
                                       5.5 + 0.25 * math.sin(0.5) + 0.05 * math.cos(0.5), 0.6])
    np.testing.assert_allclose(m.expected(robot, angles), caster.cast(sp, angles))


# --------------------------------------------------- likelihood field
def test_likelihood_field_fast_matches_reference(grid):
    lf = LikelihoodField(grid, MAXR, 0.8, 0.2, sigma_hit=0.2, sensor_offset=(0.2, 0.0, 0.0))
    rng = np.random.default_rng(5)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 37)
    z = rng.uniform(0.1, 9.0, 37)  # some beyond max_range: skipped
    poses = np.vstack([grid.sample_free(20, rng), [[0.05, 0.05, 3.0], [-5.0, 30.0, 0.0]]])
    fast = lf.log_likelihood(poses, z, angles)
    ref = lf.log_likelihood_reference(poses, z, angles)
    np.testing.assert_allclose(fast, ref, rtol=1e-5, atol=1e-4)


def test_likelihood_field_point_probability():
    g = OccupancyGrid.from_ascii("#.........", resolution=1.0)
    lf = LikelihoodField(g, 20.0, 0.9, 0.1, sigma_hit=1.0, max_dist=3.0)
    assert lf.point_log_prob(0.0) == pytest.approx(math.log(0.9 * stats.norm.pdf(0) + 0.1 / 20))
    assert lf.point_log_prob(7.0) == pytest.approx(lf.point_log_prob(3.0))
    # a scan with only max-range readings scores 0 everywhere
    assert lf.log_likelihood([[5.5, 0.5, 0.0]], [20.0, 25.0], [0.0, 1.0]).tolist() == [0.0]
    # end point on the wall beats one in the open
    ll = lf.log_likelihood([[5.5, 0.5, np.pi], [7.5, 0.5, np.pi]], [5.0], [0.0])
    assert ll[0] > ll[1]


def test_short_term_lifts_only_the_beams_that_score_below_a_likely_short_reading(grid):
    plain = LikelihoodField(grid, MAXR, 0.9, 0.1, sigma_hit=0.1)
    short = LikelihoodField(grid, MAXR, 0.9, 0.1, sigma_hit=0.1, z_short=0.2, lambda_short=0.5)
    # the floor is PR's short density plus the random term: log(z_rand/max_range + z_short lambda e^(-lambda z))
    assert short.short_floor(1.0) == pytest.approx(math.log(0.1 / MAXR + 0.2 * 0.5 * math.exp(-0.5)))
    assert plain.short_floor([0.5, 3.0]) == pytest.approx([math.log(0.1 / MAXR)] * 2)
    rng = np.random.default_rng(3)
    poses = grid.sample_free(30, rng)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 25)
    z = rng.uniform(0.1, MAXR + 1.0, 25)
    fast = short.log_likelihood(poses, z, angles)
    np.testing.assert_allclose(fast, short.log_likelihood_reference(poses, z, angles), rtol=1e-5, atol=1e-4)
    # beam by beam: the floor replaces a score only where the score is lower, so no pose loses
    per_beam = np.stack([plain.log_likelihood(poses, z[k:k + 1], angles[k:k + 1]) for k in range(25)], axis=1)
    returned = z < MAXR
    expect = np.where(returned, np.maximum(per_beam, short.short_floor(z)), 0.0).sum(axis=1)
    np.testing.assert_allclose(fast, expect, rtol=1e-5, atol=1e-4)
    assert np.all(fast >= plain.log_likelihood(poses, z, angles) - 1e-4)
    # a short reading ending in the open, far from walls, is a likely unmapped obstacle; on a wall it is a hit
    pose = [[6.0, 5.5, np.pi / 2]]                         # the wall at y = 6.4 is 0.9 m ahead
    open_end = [0.4]                                       # ends 0.5 m short of it, in free space
    assert short.log_likelihood(pose, open_end, [0.0])[0] > plain.log_likelihood(pose, open_end, [0.0])[0] + 1.0
    assert short.log_likelihood(pose, [0.9], [0.0])[0] == pytest.approx(plain.log_likelihood(pose, [0.9], [0.0])[0])
    assert "z_short=0.2" in repr(short) and "z_short" not in repr(plain)


@pytest.mark.parametrize("kw, what", [({"z_short": -0.1}, "z_short"), ({"z_short": 1.5}, "z_short"),
                                      ({"z_short": float("nan")}, "z_short"), ({"lambda_short": 0.0}, "lambda_short"),
                                      ({"lambda_short": "fast"}, "lambda_short")])
def test_short_term_rejects_bad_weights(grid, kw, what):
    with pytest.raises((ValueError, TypeError), match=what):
        LikelihoodField(grid, MAXR, **kw)


# ---------------------------------------------- product versus sum of beams
def test_product_of_beams_separates_poses_that_the_sum_hardly_does(beam):
    """Seed 001 summed per-beam densities; the principled rule multiplies them (adds logs)."""
    angles = np.linspace(-np.pi / 2, np.pi / 2, 61)
    true = np.array([[6.0, 5.5, 0.3]])
    wrong = np.array([[6.0, 5.8, 0.3]])
    z = beam.sample(true, angles, np.random.default_rng(9))[0]
    p_true = beam.pdf(z, beam.expected(true, angles))
    p_wrong = beam.pdf(z, beam.expected(wrong, angles))
    ratio_product = np.exp(np.log(p_true).sum() - np.log(p_wrong).sum())
    ratio_sum = p_true.sum() / p_wrong.sum()
    assert ratio_product > 1e6 and ratio_sum < 10


# -------------------------------------------------------------- bad input
def test_bad_mixture_weights_and_parameters():
    with pytest.raises(ValueError, match="sum to 1"):
        BeamModel(None, MAXR, 0.8, 0.1, 0.1, 0.1)
    with pytest.raises(ValueError, match="z_hit must be a mixture weight"):
        BeamModel(None, MAXR, 1.1, -0.1, 0.0, 0.0)
    with pytest.raises(ValueError, match="z_short must be a mixture weight"):
        BeamModel(None, MAXR, 0.9, -0.1, 0.1, 0.1)
    with pytest.raises(ValueError, match="sigma_hit"):
        BeamModel(None, MAXR, sigma_hit=0.0)
    with pytest.raises(ValueError, match="sigma_hit"):
        BeamModel(None, MAXR, sigma_hit=-1.0)
    with pytest.raises(ValueError, match="lambda_short"):
        BeamModel(None, MAXR, lambda_short=0.0)
    with pytest.raises(ValueError, match="max_range"):
        BeamModel(None, -1.0)
    with pytest.raises(ValueError, match="temper"):
        BeamModel(None, MAXR, temper=2.0)
    with pytest.raises(ValueError, match="sum to 1"):
        LikelihoodField(office(), MAXR, 0.5, 0.1)
    with pytest.raises(ValueError, match="sigma_hit"):
        LikelihoodField(office(), MAXR, sigma_hit=0)
    with pytest.raises(ValueError, match="sensor_offset"):
        BeamModel(None, MAXR, sensor_offset=(1.0, 2.0))


def test_bad_scans(beam):
    angles = np.linspace(-1, 1, 3)
    pose = [[6.0, 5.5, 0.0]]
    with pytest.raises(ValueError, match="empty"):
        beam.log_likelihood(pose, [], [])
    with pytest.raises(ValueError, match=">= 0"):
        beam.log_likelihood(pose, [1.0, -0.1, 2.0], angles)
    with pytest.raises(ValueError, match="NaN"):
        beam.log_likelihood(pose, [1.0, np.nan, 2.0], angles)
    with pytest.raises(ValueError, match="same length"):
        beam.log_likelihood(pose, [1.0, 2.0], angles)
    with pytest.raises(ValueError, match="NaN or infinite"):
        beam.log_likelihood([[np.nan, 5.5, 0.0]], [1.0, 1.0, 1.0], angles)
    with pytest.raises(ValueError, match=">= 0"):
        beam.pdf(-1.0, 2.0)
    with pytest.raises(TypeError, match="rng"):
        beam.sample(pose, angles, rng=0)


def test_readings_beyond_max_range_are_clipped(beam):
    angles = np.linspace(-1, 1, 3)
    pose = [[6.0, 5.5, 0.0]]
    a = beam.log_likelihood(pose, [1.0, 50.0, np.inf], angles)
    b = beam.log_likelihood(pose, [1.0, MAXR, MAXR], angles)
    np.testing.assert_allclose(a, b)
    np.testing.assert_array_equal(check_ranges([1.0, 9.0, np.inf], MAXR), [1.0, MAXR, MAXR])


def test_poses_outside_the_map_get_a_finite_low_score(beam, grid):
    angles = np.linspace(-np.pi / 2, np.pi / 2, 31)
    z = beam.sample([[6.0, 5.5, 0.3]], angles, np.random.default_rng(11))[0]
    ll = beam.log_likelihood([[6.0, 5.5, 0.3], [-10.0, 5.0, 0.0], [10.0, 0.05, 0.0]], z, angles)
    assert np.all(np.isfinite(ll)) and ll[0] > ll[1] + 50 and ll[0] > ll[2] + 50
    lf = LikelihoodField(grid, MAXR)
    ll = lf.log_likelihood([[6.0, 5.5, 0.3], [-10.0, 5.0, 0.0], [1e6, -1e6, 0.0]], z, angles)
    assert np.all(np.isfinite(ll)) and ll[0] > ll[1] and ll[0] > ll[2]


def test_model_without_map():
    m = BeamModel(None, MAXR)
    with pytest.raises(ValueError, match="no map"):
        m.log_likelihood([[0, 0, 0]], [1.0], [0.0])


# ------------------------------------------------------------ landmarks
def test_landmark_jacobian_matches_finite_differences():
    lm = LandmarkModel([[3.0, 4.0], [-2.0, 1.0], [0.5, -3.0]], 0.1, 0.05)
    pose = np.array([0.4, -0.3, 2.9])
    for k in range(3):
        H = lm.jacobian(pose, k)
        num = np.zeros((2, 3))
        for d in range(3):
            e = np.zeros(3)
            e[d] = 1e-6
            zp = lm.expected(pose + e, [k])[0, 0]
            zm = lm.expected(pose - e, [k])[0, 0]
            diff = zp - zm
            diff[1] = (diff[1] + np.pi) % (2 * np.pi) - np.pi
            num[:, d] = diff / 2e-6
        np.testing.assert_allclose(H, num, atol=1e-6)


def test_landmark_log_likelihood_and_sampling():
    lm = LandmarkModel([[3.0, 4.0], [-2.0, 1.0]], 0.2, 0.1)
    pose = np.array([0.5, 0.5, 3.1])
    z = np.array([[4.1, 0.3], [2.4, -3.1]])
    e = lm.expected(pose)[0]
    db = (z[:, 1] - e[:, 1] + np.pi) % (2 * np.pi) - np.pi
    want = stats.norm.logpdf(z[:, 0], e[:, 0], 0.2).sum() + stats.norm.logpdf(db, 0, 0.1).sum()
    assert lm.log_likelihood(pose, z, [0, 1])[0] == pytest.approx(want)
    # sampling: sample mean and spread of the range error
    rng = np.random.default_rng(0)
    zz = np.array([lm.sample(pose, rng, ids=[0])[0] for _ in range(4000)])
    assert abs(zz[:, 0].mean() - e[0, 0]) < 5 * 0.2 / math.sqrt(4000)
    assert zz[:, 0].std() == pytest.approx(0.2, rel=0.06)
    assert np.all((zz[:, 1] >= -np.pi) & (zz[:, 1] < np.pi))
    assert lm.log_likelihood(pose, np.zeros((0, 2)), []).tolist() == [0.0]
    with pytest.raises(ValueError, match="ids"):
        lm.log_likelihood(pose, z, [0, 5])
    with pytest.raises(ValueError, match="coincides"):
        lm.jacobian([3.0, 4.0, 0.0], 0)
    with pytest.raises(ValueError, match="sigma_range"):
        LandmarkModel([[0, 0]], 0.0, 0.1)


# ---------------------------------------------------------- EM learning
def test_em_recovers_known_parameters_from_simulated_scans(grid, caster):
    true = dict(z_hit=0.7, z_short=0.12, z_max=0.06, z_rand=0.12, sigma_hit=0.12, lambda_short=0.9)
    model = BeamModel(grid, MAXR, **true, caster=caster)
    rng = np.random.default_rng(21)
    poses = grid.sample_free(400, rng)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 61)
    zs = model.expected(poses, angles)
    keep = zs < MAXR  # beams that see a wall; no-return beams only inform z_max
    z = model.sample_expected(zs, rng)
    fit = fit_beam_model(z[keep], zs[keep], MAXR)
    assert fit.converged
    # EM increases the likelihood (up to the approximate sigma update, which ignores truncation)
    assert np.all(np.diff(fit.log_likelihood) > -1e-4)
    assert fit.log_likelihood[-1] > fit.log_likelihood[0] + 0.1
    n = keep.sum()
    for k in ("z_hit", "z_short", "z_max", "z_rand"):
        se = math.sqrt(true[k] * (1 - true[k]) / n)
        assert abs(fit.params[k] - true[k]) < 6 * se + 0.005, (k, fit.params[k])
    assert fit.params["sigma_hit"] == pytest.approx(true["sigma_hit"], rel=0.05)
    assert fit.params["lambda_short"] == pytest.approx(true["lambda_short"], rel=0.1)


def test_em_exact_lambda_beats_closed_form_when_truncation_matters():
    true = BeamModel(None, 10.0, 0.5, 0.4, 0.05, 0.05, sigma_hit=0.1, lambda_short=0.3)
    rng = np.random.default_rng(4)
    zs = rng.uniform(1.0, 3.0, 40_000)  # z* short compared with 1 / lambda
    z = true.sample_expected(zs, rng)
    exact = fit_beam_model(z, zs, 10.0).params["lambda_short"]
    closed = fit_beam_model(z, zs, 10.0, exact_lambda=False).params["lambda_short"]
    assert abs(exact - 0.3) < 0.1
    assert abs(closed - 0.3) > 3 * abs(exact - 0.3)


def test_em_bad_input():
    with pytest.raises(ValueError, match="same number"):
        fit_beam_model([1.0, 2.0], [1.0], 10.0)
    with pytest.raises(ValueError, match="init"):
        fit_beam_model([1.0], [1.0], 10.0, init={"z_hit": 1.0})


def test_plain_gaussian_model_gives_finite_or_minus_inf_logs_without_warnings():
    """z_hit = 1 (the plain Gaussian model of seed 003): far readings give -inf, no warning, no NaN."""
    m = BeamModel(None, MAXR, 1.0, 0.0, 0.0, 0.0, sigma_hit=0.1)
    zs = np.array([[2.0, 2.0, 0.01, MAXR]])
    z = np.array([2.05, 7.0, 0.0, MAXR])
    out = m.beam_log_pdf(z, zs)
    with np.errstate(divide="ignore", under="ignore"):
        want = np.log(m.pdf(z, zs))
    np.testing.assert_allclose(out[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-9)
    assert out[0, 1] < -1000 and not np.isnan(out).any()
    # a model without the uniform floor but with z_max also takes the log-space path
    m2 = BeamModel(None, MAXR, 0.9, 0.1, 0.0, 0.0, sigma_hit=0.1)
    fast = m2.beam_log_pdf(z[:3], zs[:, :3])
    with np.errstate(divide="ignore", under="ignore"):
        slow = np.log(m2.pdf(z[:3], zs[:, :3]))
    ok = np.isfinite(slow)
    np.testing.assert_allclose(fast[ok], slow[ok], rtol=1e-9)
    assert np.all(fast[~ok] < -500)  # the log-space sum stays finite where the density underflows
