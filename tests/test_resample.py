"""Tests of localize.resample: validity, unbiasedness, variance, log-weights, edge cases."""

import numpy as np
import pytest
from filterpy.monte_carlo import resampling as fp
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from localize import resample as rs
from localize.diagnostics import AlmostOne

FAST = [rs.multinomial, rs.stratified, rs.systematic, rs.residual]
LOOP = [rs.multinomial_loop, rs.stratified_loop, rs.systematic_loop, rs.residual_loop]
ALL = FAST + LOOP
W4 = np.array([0.5, 0.3, 0.15, 0.05])


def offspring_samples(fn, w, reps, rng, n=None):
    """(reps, len(w)) offspring counts from ``reps`` independent resamplings."""
    out = np.empty((reps, len(w)), dtype=np.int64)
    for k in range(reps):
        out[k] = np.bincount(fn(w, rng, n=n) if n is not None else fn(w, rng), minlength=len(w))
    return out


def assert_unbiased(counts, expected, z=5.0):
    """Mean offspring within ``z`` standard errors of ``expected`` for every particle.

    The standard error comes from the sample: sqrt(var / reps); a floor of
    1/reps keeps particles whose count never varies (var = 0) from demanding
    an exact match of a mean that is exact anyway.
    """
    reps = counts.shape[0]
    mean = counts.mean(axis=0)
    se = np.sqrt(np.maximum(counts.var(axis=0, ddof=1), 1.0 / reps) / reps)
    zs = np.abs(mean - expected) / se
    assert np.all(zs < z), f"mean offspring {mean.round(4)} vs expected {np.round(expected, 4)} (z = {zs.round(1)})"


# ----------------------------------------------------------------- validity
@pytest.mark.parametrize("fn", ALL, ids=lambda f: f.__name__)
def test_returns_n_valid_indices(fn, rng):
    w = rng.random(37) ** 3
    w[[3, 10, 36]] = 0.0
    idx = fn(w, rng)
    assert idx.shape == (37,) and idx.dtype == np.int64
    assert idx.min() >= 0 and idx.max() < 37
    assert not np.isin(idx, [3, 10, 36]).any(), "a zero-weight particle was chosen"


@pytest.mark.parametrize("fn", ALL, ids=lambda f: f.__name__)
def test_n_argument_gives_n_indices(fn, rng):
    assert fn([0.2, 0.8], rng, n=7).shape == (7,)
    assert fn([0.2, 0.8], rng, n=0).shape == (0,)


@settings(max_examples=60, deadline=None)
@given(
    w=arrays(np.float64, st.integers(1, 40), elements=st.floats(0, 1e6, allow_subnormal=True)).filter(
        lambda a: a.sum() > 0
    ),
    seed=st.integers(0, 2**32 - 1),
)
def test_property_valid_indices_for_any_weights(w, seed):
    rng = np.random.default_rng(seed)
    for fn in FAST:
        idx = fn(w, rng)
        assert idx.shape == w.shape
        assert np.all((idx >= 0) & (idx < w.size))
        assert np.all(w[idx] > 0)


FLOAT_MAX = float(np.finfo(np.float64).max)


@pytest.mark.parametrize("fn", ALL, ids=lambda f: f.__name__)
@pytest.mark.parametrize("w", [[1e308] * 3, [FLOAT_MAX] * 4, [5e-324] * 3, [5e-324, FLOAT_MAX, 0.0]],
                         ids=["1e308", "max", "subnormal", "mixed"])
def test_extreme_but_finite_weights(fn, w):
    """Huge weights used to overflow the sum (IndexError: index -1, or 'weights sum to zero')."""
    w = np.asarray(w)
    idx = fn(w, np.random.default_rng(0))
    assert idx.shape == w.shape and np.all(w[idx] > 0)
    if np.all(w == w[0]):   # equal weights: systematic, stratified and residual give one copy each
        if fn not in (rs.multinomial, rs.multinomial_loop):
            assert np.array_equal(np.sort(idx), np.arange(w.size))
    assert 1.0 - 1e-12 <= rs.effective_sample_size(w) <= w.size + 1e-12


@settings(max_examples=60, deadline=None)
@given(
    w=arrays(np.float64, st.integers(1, 30),
             elements=st.floats(0, FLOAT_MAX, allow_subnormal=True, allow_nan=False, allow_infinity=False)
             ).filter(lambda a: a.max() > 0),
    seed=st.integers(0, 2**32 - 1),
)
def test_property_resamplers_over_the_whole_float_range(w, seed):
    """Any finite non-negative weights with one positive entry: valid indices, counts near n * w_i."""
    p = (w / w.max()) / (w / w.max()).sum()   # the exact normalisation, computed safely
    for fn in ALL:
        idx = fn(w, np.random.default_rng(seed))
        assert idx.shape == w.shape and idx.dtype == np.int64
        assert np.all((idx >= 0) & (idx < w.size))
        assert np.all(w[idx] > 0), fn.__name__
        if fn in (rs.systematic, rs.systematic_loop, rs.residual, rs.residual_loop):
            counts = np.bincount(idx, minlength=w.size)
            if fn in (rs.systematic, rs.systematic_loop):   # floor(n w_i) or ceil(n w_i) copies
                assert np.all(np.abs(counts - w.size * p) < 1 + 1e-9), fn.__name__
            else:                                           # at least floor(n w_i) copies
                assert np.all(counts >= np.floor(w.size * p * (1 - 1e-12))), fn.__name__
    ess = rs.effective_sample_size(w)
    assert np.isfinite(ess) and 1.0 - 1e-9 <= ess <= w.size + 1e-9


@pytest.mark.parametrize("name", ["stratified", "systematic"])
def test_fast_equals_readable_exactly(name):
    fast, loop = getattr(rs, name), getattr(rs, name + "_loop")
    for seed in range(50):
        w = np.random.default_rng(seed).random(int(5 + seed * 7)) ** 4
        assert np.array_equal(fast(w, np.random.default_rng(seed)), loop(w, np.random.default_rng(seed))), seed


def test_systematic_matches_textbook_pointer_definition(rng):
    """Independent of both implementations: count pointers (r + m)/N below each partial sum."""
    w = rng.random(200)
    seed = 99
    r = np.random.default_rng(seed).random()
    c = np.cumsum(w / w.sum())
    pointers = (r + np.arange(200)) / 200
    expected = np.array([np.sum((pointers >= lo) & (pointers < hi)) for lo, hi in zip(np.r_[0, c[:-1]], c)])
    got = np.bincount(rs.systematic(w, np.random.default_rng(seed)), minlength=200)
    assert np.array_equal(got, expected)


def test_systematic_counts_are_floor_or_ceil(rng):
    w = rng.random(1000)
    w /= w.sum()
    counts = np.bincount(rs.systematic(w, rng), minlength=1000)
    assert np.all((counts == np.floor(1000 * w)) | (counts == np.ceil(1000 * w)))


# -------------------------------------------- regression: rounding at the end
@pytest.mark.parametrize("fn", ALL, ids=lambda f: f.__name__)
def test_cumsum_just_below_one_does_not_index_past_the_end(fn):
    w = np.full(10, 0.1)
    assert np.cumsum(w)[-1] < 1.0           # the trap: 0.9999999999999999
    idx = fn(w, AlmostOne(np.random.PCG64(0)))
    assert idx.shape == (10,) and idx.min() >= 0 and idx.max() <= 9
    if fn is not rs.multinomial:          # (the fast multinomial draws exponentials, not uniforms)
        assert idx.max() == 9


@pytest.mark.parametrize("n", [10, 999_983])
def test_pointer_rounding_up_to_one_is_handled(n):
    """r + m rounds up to m + 1 for r just below 1: pointers land on partial sums, or on 1.0."""
    w = np.ones(n)
    fns = [rs.systematic, rs.stratified] + ([rs.systematic_loop, rs.stratified_loop] if n < 1000 else [])
    for fn in fns:
        a = fn(w, AlmostOne(np.random.PCG64(0)))
        assert a.shape == (n,) and a.min() >= 0 and a.max() == n - 1, fn.__name__


@pytest.mark.parametrize("name", ["systematic_resample", "stratified_resample"])
def test_filterpy_fails_on_the_same_input(monkeypatch, name):
    """Documents why the regression tests above exist (filterpy 2.0.0)."""
    monkeypatch.setattr(fp, "random", AlmostOne(np.random.PCG64(0)).random)
    try:
        getattr(fp, name)(np.full(10, 0.1))
    except IndexError:
        return
    pytest.skip("this filterpy version no longer indexes past the end")


# ------------------------------------------------------------- unbiasedness
@pytest.mark.parametrize("fn", FAST, ids=lambda f: f.__name__)
@pytest.mark.parametrize("w", [W4, np.array([0.02, 0.13, 0.0, 0.35, 0.07, 0.43])], ids=["w4", "w6"])
def test_fast_resamplers_are_unbiased(fn, w):
    counts = offspring_samples(fn, w, 10_000, np.random.default_rng(7))
    assert counts.sum(axis=1).min() == counts.sum(axis=1).max() == len(w)
    assert_unbiased(counts, len(w) * w)


@pytest.mark.parametrize("fn", LOOP, ids=lambda f: f.__name__)
def test_readable_resamplers_are_unbiased(fn):
    counts = offspring_samples(fn, W4, 4_000, np.random.default_rng(8))
    assert_unbiased(counts, 4 * W4)


@pytest.mark.parametrize("fn", FAST, ids=lambda f: f.__name__)
def test_unbiased_when_drawing_a_different_number(fn):
    w = np.array([0.1, 0.6, 0.3])
    counts = offspring_samples(fn, w, 10_000, np.random.default_rng(9), n=11)
    assert_unbiased(counts, 11 * w)


def test_residual_remainder_options_unbiased():
    for rem in ("stratified", "systematic"):
        counts = offspring_samples(lambda w, r, rem=rem: rs.residual(w, r, remainder=rem), W4, 10_000, np.random.default_rng(3))
        assert_unbiased(counts, 4 * W4)


def test_unbiasedness_check_catches_filterpy_residual(monkeypatch):
    """The same check fails for filterpy 2.0.0's residual_resample, which is biased."""
    rng = np.random.default_rng(11)
    monkeypatch.setattr(fp, "random", rng.random)
    counts = np.array([np.bincount(fp.residual_resample(W4), minlength=4) for _ in range(6_000)])
    mean = counts.mean(axis=0)
    if np.allclose(mean, 4 * W4, atol=0.05):
        pytest.skip("this filterpy version has an unbiased residual_resample")
    assert np.allclose(mean, [2.75, 1.25, 0.0, 0.0], atol=0.03)
    with pytest.raises(AssertionError):
        assert_unbiased(counts, 4 * W4)


# ----------------------------------------------------------------- variance
def test_offspring_variance_ordering():
    rng = np.random.default_rng(5)
    w = rng.random(50) ** 2
    w /= w.sum()
    reps = 4_000
    var = {fn.__name__: offspring_samples(fn, w, reps, rng).var(axis=0, ddof=1).sum() for fn in FAST}
    theory = 50 * np.sum(w * (1 - w))        # multinomial: Var N_i = N w_i (1 - w_i)
    assert abs(var["multinomial"] / theory - 1) < 5 * np.sqrt(2.0 / reps)
    for name in ("stratified", "systematic", "residual"):
        assert var[name] < 0.5 * var["multinomial"], var
    # systematic: each count is floor or ceil of N w_i, so the variance is f(1 - f) per particle at most
    f = 50 * w - np.floor(50 * w)
    assert var["systematic"] <= np.sum(f * (1 - f)) * (1 + 5 * np.sqrt(2.0 / reps))


def test_multinomial_fast_and_loop_agree_in_distribution():
    """Chi-square on the offspring count of particle 0 (Binomial(N, w0) for both)."""
    from scipy import stats

    w = np.array([0.3, 0.2, 0.5])
    for fn in (rs.multinomial, rs.multinomial_loop):
        c0 = offspring_samples(fn, w, 3_000, np.random.default_rng(21))[:, 0]
        k = np.arange(4)
        observed = np.bincount(c0, minlength=4)
        expected = 3_000 * stats.binom.pmf(k, 3, 0.3)
        chi2 = np.sum((observed - expected) ** 2 / expected)
        assert chi2 < stats.chi2.ppf(0.9999, df=3), (fn.__name__, observed, expected)


def test_sorted_uniforms_are_uniform():
    from scipy import stats

    u = rs._sorted_uniforms(20_000, np.random.default_rng(2))
    assert np.all(np.diff(u) >= 0) and u[0] >= 0 and u[-1] < 1
    assert stats.kstest(u, "uniform").pvalue > 1e-4


# -------------------------------------------------------------- log-weights
def test_normalize_log_weights_handles_huge_magnitudes():
    w, L = rs.normalize_log_weights([-1e5, -1e5 - np.log(3), -np.inf])
    np.testing.assert_allclose(w, [0.75, 0.25, 0.0])
    np.testing.assert_allclose(L, -1e5 + np.log(4 / 3))


def test_normalize_log_weights_degenerate_flag_and_strict():
    w, L = rs.normalize_log_weights(np.full(5, -np.inf))
    assert L == -np.inf and np.allclose(w, 0.2)
    with pytest.raises(rs.DegenerateWeightsError, match="every log-weight"):
        rs.normalize_log_weights([np.nan, -np.inf], strict=True)
    assert issubclass(rs.DegenerateWeightsError, ValueError)


def test_normalize_log_weights_nan_is_zero_weight_and_reported():
    w, L = rs.normalize_log_weights([0.0, np.nan, 0.0])
    np.testing.assert_allclose(w, [0.5, 0.0, 0.5])
    assert rs.effective_sample_size_log([0.0, np.nan, 0.0]) == pytest.approx(2.0)


def test_normalize_log_weights_rejects_bad_input():
    with pytest.raises(ValueError, match=r"\+inf"):
        rs.normalize_log_weights([0.0, np.inf])
    with pytest.raises(ValueError, match="1-D"):
        rs.normalize_log_weights([[0.0]])
    with pytest.raises(ValueError, match="empty"):
        rs.normalize_log_weights([])


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.integers(1, 30), elements=st.floats(-800, 50)))
def test_property_log_normalisation_matches_linear(a):
    w, L = rs.normalize_log_weights(a)
    assert abs(w.sum() - 1) < 1e-12
    lin = np.exp(a)
    if lin.sum() > 1e-300:
        np.testing.assert_allclose(w, lin / lin.sum(), rtol=1e-9, atol=1e-200)
        np.testing.assert_allclose(L, np.log(lin.sum()), rtol=1e-12, atol=1e-12)
    assert rs.logsumexp(a) == pytest.approx(L)


# ---------------------------------------------------- effective sample size
@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.integers(1, 60), elements=st.floats(1e-3, 1.0)))
def test_property_ess_equals_variance_formula(w):
    n = w.size
    ess = rs.effective_sample_size(w)
    assert 1 - 1e-9 <= ess <= n + 1e-9
    assert ess == pytest.approx(rs.ess_from_weight_variance(rs.weight_variance(w), n), rel=1e-9)
    assert rs.weight_variance_from_ess(min(ess, n), n) == pytest.approx(rs.weight_variance(w), rel=1e-6, abs=1e-15)


def test_ess_values():
    assert rs.effective_sample_size(np.ones(8)) == pytest.approx(8)
    assert rs.effective_sample_size([0, 0, 3.0]) == pytest.approx(1)
    assert rs.effective_sample_size([2.0, 1.0, 1.0]) == pytest.approx(16 / 6)
    assert rs.effective_sample_size_log([0.0, 0.0, -np.inf, -np.inf]) == pytest.approx(2)
    assert np.isnan(rs.effective_sample_size_log([-np.inf, -np.inf]))


def test_needs_resampling_threshold():
    w = np.array([0.4, 0.2, 0.2, 0.2])        # N_eff = 1/0.28 = 3.571
    assert not rs.needs_resampling(w, 0.85) and rs.needs_resampling(w, 0.9)
    assert not rs.needs_resampling(w, 0.0) and rs.needs_resampling(w, 1.0)
    with pytest.raises(ValueError, match="threshold"):
        rs.needs_resampling(w, 1.5)


# ------------------------------------------------------------- bad input
@pytest.mark.parametrize("fn", FAST, ids=lambda f: f.__name__)
@pytest.mark.parametrize(
    "w, match",
    [([0.5, -0.1], "non-negative"), ([0.5, np.nan], "finite"), ([0.0, 0.0], "sum to zero"),
     ([], "empty"), ([[0.5, 0.5]], "1-D")],
)
def test_bad_weights_raise(fn, w, match, rng):
    with pytest.raises(ValueError, match=match):
        fn(w, rng)


@pytest.mark.parametrize("fn", ALL, ids=lambda f: f.__name__)
def test_rng_must_be_generator(fn):
    with pytest.raises(TypeError, match="rng"):
        fn([0.5, 0.5], 42)


def test_bad_n_and_names(rng):
    with pytest.raises(ValueError, match="n must be a whole number >= 0"):
        rs.systematic([1.0], rng, n=-1)
    with pytest.raises(TypeError, match="n must be a whole number"):
        rs.systematic([1.0], rng, n=2.5)
    with pytest.raises(ValueError, match="remainder"):
        rs.residual([1.0], rng, remainder="wheel")
    assert rs.get_resampler("residual") is rs.residual
    with pytest.raises(ValueError, match="unknown resampler"):
        rs.get_resampler("best")
    with pytest.raises(ValueError, match=r"indices must lie in \[0, 2\]"):
        rs.offspring_counts([0, 3], 3)
    with pytest.raises(ValueError, match="ess must lie"):
        rs.weight_variance_from_ess(0.5, 10)
    with pytest.raises(ValueError, match="variance must be >= 0"):
        rs.ess_from_weight_variance(-1.0, 10)


# --------------------------------------------------------- bootstrap filter
def test_bootstrap_filter_matches_the_kalman_posterior():
    """Static scalar, Gaussian prior and readings: the posterior is Gaussian with known moments."""
    rng = np.random.default_rng(30)
    n = 20_000
    z = 1.0 + 0.5 * rng.standard_normal(10)
    res = rs.bootstrap_filter(rng.normal(0.0, 2.0, n), [(None, zk) for zk in z], None,
                              lambda x, zk: -0.5 * ((zk - x) / 0.5) ** 2, rng, threshold=0.0)
    prec = 1 / 4 + 10 / 0.25
    mean, var = (z.sum() / 0.25) / prec, 1 / prec
    w, x = res.weights[-1], res.particles[-1]
    m = np.sum(w * x)
    ess = res.ess[-1]
    assert abs(m - mean) < 5 * np.sqrt(var / ess)
    assert abs(np.sum(w * (x - m) ** 2) / var - 1) < 5 * np.sqrt(2 / ess)
    # the evidence: p(z_1) for the first reading is N(z_1; 0, 4 + 0.25), up to the constant of the likelihood
    ll0 = res.log_evidence[0]
    expected = -0.5 * z[0] ** 2 / 4.25 + 0.5 * np.log(0.25 / 4.25)
    assert abs(ll0 - expected) < 0.05


def test_bootstrap_filter_degenerate_step_keeps_uniform_weights():
    rng = np.random.default_rng(0)
    res = rs.bootstrap_filter(np.arange(5.0), [(None, 0), (None, 1)], None,
                              lambda x, z: np.full(5, -np.inf) if z == 0 else -x, rng)
    assert res.log_evidence[0] == -np.inf and np.allclose(res.weights[0], 0.2)
    assert np.isfinite(res.log_evidence[1]) and res.weights[1][0] > res.weights[1][4]


def test_bootstrap_filter_bad_input():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="threshold"):
        rs.bootstrap_filter([0.0], [(None, 1)], None, lambda x, z: x, rng, threshold=-0.1)
    with pytest.raises(ValueError, match="empty"):
        rs.bootstrap_filter([0.0], [], None, lambda x, z: x, rng)
    with pytest.raises(ValueError, match="move is None"):
        rs.bootstrap_filter([0.0], [(1.0, 1)], None, lambda x, z: x, rng)
    with pytest.raises(ValueError, match="shape"):
        rs.bootstrap_filter([0.0, 1.0], [(None, 1)], None, lambda x, z: np.zeros(3), rng)


def test_offspring_moments():
    w = np.array([0.6, 0.3, 0.1])
    mean, var = rs.offspring_moments("multinomial", w, 3000, np.random.default_rng(1))
    assert np.all(np.abs(mean - 3 * w) < 5 * np.sqrt(3 * w * (1 - w) / 3000))
    assert np.all(np.abs(var / (3 * w * (1 - w)) - 1) < 5 * np.sqrt(2 / 3000) * 2)
