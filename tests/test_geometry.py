"""Tests of localize.geometry: angle wrapping, pose algebra, circular statistics."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from localize import geometry as g
from localize import wrap_angle

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
angle = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)
pose = st.tuples(st.floats(-100, 100), st.floats(-100, 100), angle).map(np.array)


@given(finite)
def test_wrap_angle_range_and_equivalence(a):
    w = wrap_angle(a)
    assert -np.pi <= w < np.pi
    # same direction: differs from a by a whole number of turns
    k = (a - w) / (2 * np.pi)
    assert abs(k - round(k)) < 1e-6 * max(1.0, abs(k))


@given(st.floats(min_value=-np.pi, max_value=np.pi, exclude_max=True))
def test_wrap_angle_identity_inside_interval(a):
    assert wrap_angle(a) == pytest.approx(a, abs=1e-15)


def test_wrap_angle_edges():
    assert wrap_angle(np.pi) == -np.pi
    assert wrap_angle(-np.pi) == -np.pi
    assert wrap_angle(3 * np.pi) == -np.pi
    assert wrap_angle(2 * np.pi) == 0.0
    # a tiny negative number whose remainder rounds up to 2*pi must not come back as +pi
    assert -np.pi <= wrap_angle(-1e-300) < np.pi
    assert -np.pi <= wrap_angle(np.nextafter(-np.pi, -4.0)) < np.pi
    out = wrap_angle(np.array([[0.0, 7.0], [-7.0, np.pi]]))
    assert out.shape == (2, 2)
    np.testing.assert_allclose(out, [[0.0, 7.0 - 2 * np.pi], [-7.0 + 2 * np.pi, -np.pi]])
    assert isinstance(wrap_angle(1.0), float)


def test_angle_diff_across_seam():
    assert g.angle_diff(np.radians(-179), np.radians(179)) == pytest.approx(np.radians(2))
    assert g.angle_diff(np.radians(179), np.radians(-179)) == pytest.approx(np.radians(-2))


@given(pose, pose)
def test_compose_inverse_roundtrip(a, b):
    c = g.compose(a, b)
    back = g.compose(g.inverse(a), c)
    np.testing.assert_allclose(back[:2], b[:2], atol=1e-8)
    assert abs(g.angle_diff(back[2], b[2])) < 1e-9
    np.testing.assert_allclose(g.relative(a, c)[:2], b[:2], atol=1e-8)


@given(pose)
def test_inverse_is_identity(p):
    e = g.compose(p, g.inverse(p))
    np.testing.assert_allclose(e[:2], 0.0, atol=1e-9)
    assert abs(g.angle_diff(e[2], 0.0)) < 1e-12


@given(pose, pose, pose)
@settings(max_examples=50)
def test_compose_associative(a, b, c):
    left = g.compose(g.compose(a, b), c)
    right = g.compose(a, g.compose(b, c))
    np.testing.assert_allclose(left[:2], right[:2], atol=1e-7)
    assert abs(g.angle_diff(left[2], right[2])) < 1e-9


def test_compose_known_values_and_broadcasting():
    a = np.array([1.0, 2.0, np.pi / 2])
    b = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, np.pi]])
    c = g.compose(a, b)
    np.testing.assert_allclose(c, [[1.0, 3.0, np.pi / 2], [0.0, 2.0, -np.pi / 2]], atol=1e-12)
    assert c.shape == (2, 3)


def test_transform_points_matches_compose():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(5, 3))
    pts = rng.normal(size=(5, 2))
    via_compose = g.compose(p, np.column_stack([pts, np.zeros(5)]))[:, :2]
    np.testing.assert_allclose(g.transform_points(p, pts), via_compose, atol=1e-12)


@pytest.mark.parametrize("bad", [[1.0, 2.0], [[1, 2, 3, 4]], 5.0])
def test_as_poses_rejects_bad_shapes(bad):
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        g.as_poses(bad)


def test_as_poses_rejects_nan():
    with pytest.raises(ValueError, match="NaN"):
        g.compose([0, 0, np.nan], [0, 0, 0])


def test_circular_mean_across_seam_and_weights():
    a = np.radians([170.0, -170.0])
    assert abs(g.angle_diff(g.circular_mean(a), np.pi)) < 1e-12
    assert g.circular_mean(a, weights=[3.0, 1.0]) == pytest.approx(np.radians(175.0), abs=0.02)
    with pytest.raises(ValueError, match="weights"):
        g.circular_mean(a, weights=[-1.0, 1.0])
    with pytest.raises(ValueError, match="sum to zero"):
        g.circular_mean(a, weights=[0.0, 0.0])


@given(st.floats(-np.pi, np.pi), st.floats(0.01, 0.3))
@settings(max_examples=25, deadline=None)
def test_circular_stats_of_wrapped_normal(mu, sigma):
    # For a wrapped normal, R = exp(-sigma^2 / 2), so circular_std estimates sigma.
    # n = 20000 samples: standard error of the mean ~ sigma/sqrt(n); allow 6 of them.
    rng = np.random.default_rng(7)
    n = 20000
    a = wrap_angle(rng.normal(mu, sigma, n))
    se = sigma / np.sqrt(n)
    assert abs(g.angle_diff(g.circular_mean(a), mu)) < 6 * se
    # std of the sample std ~ sigma/sqrt(2n)
    assert g.circular_std(a) == pytest.approx(sigma, abs=6 * sigma / np.sqrt(2 * n) + 1e-3 * sigma)


def test_circular_std_uniform_is_large():
    a = np.linspace(-np.pi, np.pi, 1000, endpoint=False)
    assert g.circular_std(a) > 5.0


def test_mean_pose_weighted():
    p = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 4.0, -np.pi + 0.1]])
    m = g.mean_pose(p, weights=[1.0, 3.0])
    np.testing.assert_allclose(m[:2], [1.5, 3.0])
    assert abs(g.angle_diff(m[2], -np.pi + 0.05)) < 1e-3
    with pytest.raises(ValueError, match="empty"):
        g.mean_pose(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="weights must have shape"):
        g.mean_pose(p, weights=[1.0, 2.0, 3.0])


@given(arrays(np.float64, st.integers(1, 20), elements=st.floats(-1e3, 1e3)))
def test_wrap_angle_vectorised_equals_scalar(a):
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    np.testing.assert_array_equal(w, [wrap_angle(float(x)) for x in a])


# --- exact=True against the bare formula (exact=False): why the exact wrap is the default
_NEAR_PI = np.nextafter(np.pi, 0.0)      # the largest float inside [-pi, pi)


def test_wrap_angle_exact_keeps_headings_inside_and_bins_in_range():
    """The bare formula moves an angle one ulp below +pi to about -pi and can return +pi itself.

    That matters wherever a wrapped heading is stored and compared: wrapping an
    already wrapped heading must change nothing (a pose that is re-wrapped by
    every step must not jump a turn), and ``+pi`` must never appear (the
    interval is half-open, so that ``+pi`` and ``-pi`` are not two headings).
    The exact wrap (the default) guarantees both; the bare formula does not.
    """
    edge = np.array([_NEAR_PI, -np.pi, np.pi, np.nextafter(-np.pi, -4.0), 3 * np.pi, -1e-300])
    exact, bare = wrap_angle(edge), wrap_angle(edge, exact=False)
    assert exact[0] == _NEAR_PI and wrap_angle(_NEAR_PI) == _NEAR_PI          # inside: untouched
    assert abs(bare[0] - _NEAR_PI) > 6.0                                      # bare: jumped a turn
    assert np.all((exact >= -np.pi) & (exact < np.pi))
    assert np.any((bare >= np.pi) | (bare < -np.pi))                          # bare: outside somewhere
    np.testing.assert_array_equal(wrap_angle(exact), exact)                   # idempotent


@given(arrays(np.float64, st.integers(1, 50), elements=st.floats(-1e4, 1e4)))
def test_wrap_angle_bare_formula_agrees_away_from_the_ends(a):
    """Inside a density or a cosine either variant serves: they differ only at the ends."""
    exact, bare = wrap_angle(a), wrap_angle(a, exact=False)
    away = np.abs(np.abs(exact) - np.pi) > 1e-9
    np.testing.assert_array_equal(exact[away], bare[away])
    np.testing.assert_allclose(np.cos(exact), np.cos(bare), atol=1e-12)
    assert wrap_angle(float(a[0]), exact=False) == pytest.approx(float(bare[0]), abs=1e-12)


def test_wrap_angle_scalar_and_array_paths_agree_at_the_ends():
    edge = [_NEAR_PI, -np.pi, np.pi, np.nextafter(-np.pi, -4.0), 3 * np.pi, -3 * np.pi, 1e10, -1e-300]
    np.testing.assert_array_equal(wrap_angle(np.array(edge)), [wrap_angle(x) for x in edge])
    assert np.isnan(wrap_angle(np.inf)) and np.isnan(wrap_angle(np.nan))
