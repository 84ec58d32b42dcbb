"""Tests of localize.discrete: the 1-D (and N-D) discrete Bayes filter."""

import numpy as np
import pytest
from filterpy import discrete_bayes as fp
from hypothesis import given, settings
from hypothesis import strategies as st

from localize import discrete as db
from localize.maps import hallway


def _random_belief(rng, n):
    return db.normalize(rng.random(n) + 0.01)


def test_hallway_against_filterpy():
    """The PR door example run through both libraries gives the same numbers at every step."""
    world = hallway(20)
    z_seq = [1, 1, 0, 0, 0, 1, 0, 0, 0]   # robot reads door / wall while moving right
    kernel = [0.1, 0.8, 0.1]
    ours = db.uniform(20)
    theirs = np.full(20, 1 / 20)
    for z in z_seq:
        lik = np.where(world == z, 0.75, 0.25)
        ours = db.update(ours, lik)
        theirs = fp.update(lik, theirs)
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-15)
        ours = db.predict(ours, kernel, offset=1)
        theirs = fp.predict(theirs, 1, kernel)
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-15)
    assert ours.argmax() == theirs.argmax()


@pytest.mark.parametrize("offset", [-3, -1, 0, 2, 5])
@pytest.mark.parametrize("kernel", [[1.0], [0.2, 0.6, 0.2], [0.05, 0.1, 0.5, 0.3, 0.05]])
def test_predict_matches_filterpy_wrap(rng, offset, kernel):
    b = _random_belief(rng, 17)
    np.testing.assert_allclose(db.predict(b, kernel, offset), fp.predict(b, offset, np.array(kernel)), atol=1e-15)


@pytest.mark.parametrize("offset", [-2, 0, 3])
def test_predict_matches_filterpy_constant(rng, offset):
    b = _random_belief(rng, 15)
    k = np.array([0.1, 0.7, 0.2])
    ours = db.predict(b, k, offset, mode="constant", cval=0.01)
    theirs = fp.predict(b, offset, k, mode="constant", cval=0.01)
    # filterpy shifts first (with a cubic spline, exact for whole cells up to rounding) and blurs after;
    # we move and blur each source cell together. Away from the edges the two are the same.
    inner = slice(abs(offset) + 1, len(b) - abs(offset) - 1)
    np.testing.assert_allclose(ours[inner], theirs[inner], atol=1e-9)
    if offset == 0:
        np.testing.assert_allclose(ours, theirs, atol=1e-9)


def test_bounded_edge_keeps_undershoot_unlike_filterpy():
    b = np.zeros(6)
    b[-1] = 1.0
    k = np.array([0.2, 0.6, 0.2])
    assert db.predict(b, k, 1, mode="constant")[-1] == pytest.approx(0.2)
    assert fp.predict(b, 1, k, mode="constant")[-1] == pytest.approx(0.0, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(3, 30), offset=st.integers(-40, 40), seed=st.integers(0, 2**31 - 1),
       klen=st.sampled_from([1, 3, 5]), mode=st.sampled_from(["wrap", "constant"]),
       cval=st.sampled_from([0.0, 0.001]))
def test_predict_equals_readable(n, offset, seed, klen, mode, cval):
    rng = np.random.default_rng(seed)
    b = _random_belief(rng, n)
    k = db.normalize(rng.random(klen) + 0.01)
    np.testing.assert_allclose(db.predict(b, k, offset, mode, cval), db.predict_readable(b, k, offset, mode, cval),
                               atol=1e-13)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 30), seed=st.integers(0, 2**31 - 1))
def test_update_equals_readable_and_sums_to_one(n, seed):
    rng = np.random.default_rng(seed)
    b = _random_belief(rng, n)
    lik = rng.random(n) + 1e-3
    post = db.update(b, lik)
    np.testing.assert_allclose(post, db.update_readable(b, lik), atol=1e-14)
    assert post.sum() == pytest.approx(1.0)


def test_wrap_conserves_mass_and_constant_loses_it():
    b = np.zeros(6)
    b[-1] = 1.0
    assert db.predict(b, [0.2, 0.6, 0.2], 1).sum() == pytest.approx(1.0)
    lost = db.predict(b, [0.2, 0.6, 0.2], 1, mode="constant")
    assert lost.sum() == pytest.approx(0.2)   # only the undershoot stays inside
    assert lost[-1] == pytest.approx(0.2)


def test_predict_2d_offsets():
    b = np.zeros((4, 5))
    b[1, 1] = 1.0
    k = np.zeros((3, 3))
    k[1, 1] = 1.0
    out = db.predict(b, k, offset=(2, -1))
    assert out[3, 0] == 1.0 and out.sum() == 1.0


def test_update_two_doors_localizes():
    """After seeing door, moving, door, moving, door the mode is at the only consistent place."""
    world = hallway(20, doors=(2, 5, 13))
    b = db.uniform(20)
    for z, move in [(1, 3), (1, 8), (1, 0)]:
        b = db.update(b, np.where(world == z, 0.9, 0.1))
        b = db.predict(b, [0.05, 0.9, 0.05], move)
    assert b.argmax() == 13


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("belief, match", [
    ([0.5, 0.6], "sum to 1"),
    ([1.2, -0.2], "negative"),
    ([np.nan, 1.0], "NaN"),
    ([], "empty"),
])
def test_bad_beliefs(belief, match):
    with pytest.raises(ValueError, match=match):
        db.predict(belief, [1.0])
    with pytest.raises(ValueError, match=match):
        db.update(belief, np.ones(len(belief)))


@pytest.mark.parametrize("kernel, match", [
    ([0.2, 0.2, 0.2], "sum to 1"),
    ([0.5, 0.5], "odd length"),
    ([1.2, -0.2, 0.0], "negative"),
    ([[1.0]], "dimension"),
])
def test_bad_kernels(kernel, match):
    with pytest.raises(ValueError, match=match):
        db.predict([0.5, 0.5, 0.0], kernel)


def test_bad_offset_mode_cval():
    with pytest.raises(TypeError, match="whole number"):
        db.predict([0.5, 0.5], [1.0], offset=0.5)
    with pytest.raises(ValueError, match="mode"):
        db.predict([0.5, 0.5], [1.0], mode="reflect")
    with pytest.raises(ValueError, match="cval"):
        db.predict([0.5, 0.5], [1.0], mode="constant", cval=-1)
    with pytest.raises(ValueError, match="offset must have one entry"):
        db.predict([0.5, 0.5], [1.0], offset=(1, 1))


def test_likelihood_shape_and_sign():
    with pytest.raises(ValueError, match="shape"):
        db.update([0.5, 0.5], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="negative"):
        db.update([0.5, 0.5], [1.0, -1.0])


def test_zero_likelihood_is_reported_not_nan():
    with pytest.raises(db.ZeroLikelihoodError, match="impossible"):
        db.update([1.0, 0.0], [0.0, 1.0])
    with pytest.raises(db.ZeroLikelihoodError):
        db.update_readable([1.0, 0.0], [0.0, 1.0])
    with pytest.raises(db.ZeroLikelihoodError):
        db.normalize([0.0, 0.0])
    assert issubclass(db.ZeroLikelihoodError, ValueError)


def test_normalize_does_not_modify_input():
    a = np.array([1.0, 3.0])
    out = db.normalize(a)
    assert a.tolist() == [1.0, 3.0] and out.tolist() == [0.25, 0.75]


def test_uniform_mask_errors():
    with pytest.raises(ValueError, match="no cell"):
        db.uniform(2, mask=[False, False])
    with pytest.raises(ValueError, match="shape"):
        db.uniform(2, mask=[True])
