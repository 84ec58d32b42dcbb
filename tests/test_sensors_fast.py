"""The blocked likelihood-field update (issue 41) against the two versions it replaces.

``LikelihoodField.log_likelihood`` works on blocks of poses with work arrays kept on the object and sums
each pose's beams in numpy's own order; it must give *the same bits* as the vectorised formula it
replaced (kept below as ``vectorised_reference``: N x B float32 temporaries, one ``sum``), because the
book's stored outputs and the benchmark trajectories depend on every bit. Both are also held to the
readable per-beam oracle ``log_likelihood_reference`` within the tolerance the float32 end points allow.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

import localize.sensors as sensors
from localize import OccupancyGrid
from localize.maps import office
from localize.sensors import LikelihoodField, sensor_poses

MAXR = 8.0


def vectorised_reference(lf: LikelihoodField, poses, ranges, angles) -> np.ndarray:
    """``LikelihoodField.log_likelihood`` as it was before issue 41, verbatim (N x B temporaries)."""
    z, a = lf._prepare(ranges, angles)
    sp = sensor_poses(poses, lf.sensor_offset)
    n = sp.shape[0]
    if z.size == 0:
        return np.zeros(n)
    g = lf.grid
    inv = 1.0 / g.resolution
    f32 = np.float32
    bx = (z * np.cos(a) * inv).astype(f32)
    by = (z * np.sin(a) * inv).astype(f32)
    c = np.cos(sp[:, 2]).astype(f32)[:, None]
    s = np.sin(sp[:, 2]).astype(f32)[:, None]
    x0 = ((sp[:, 0] - g.origin[0]) * inv + lf._pad).astype(f32)[:, None]
    y0 = ((sp[:, 1] - g.origin[1]) * inv + lf._pad).astype(f32)[:, None]
    ex = c * bx
    ex -= s * by
    ex += x0
    ey = s * bx
    ey += c * by
    ey += y0
    rows_p, cols_p = lf.table.shape
    lo_x, lo_y = float(x0.min()) if n else 0.0, float(y0.min()) if n else 0.0
    hi_x, hi_y = float(x0.max()) if n else 0.0, float(y0.max()) if n else 0.0
    reach = lf.max_range * inv + 1
    if lo_x - reach < 0 or lo_y - reach < 0 or hi_x + reach >= cols_p or hi_y + reach >= rows_p:
        np.clip(ex, 0, cols_p - 1, out=ex)
        np.clip(ey, 0, rows_p - 1, out=ey)
    j = ex.astype(np.int32)
    i = ey.astype(np.int32)
    i *= lf._wp
    i += j
    vals = lf.table.ravel().take(i)
    if lf.z_short > 0:
        np.maximum(vals, lf.short_floor(z).astype(f32)[None, :], out=vals)
    ll = vals.sum(axis=1, dtype=np.float64)
    return ll * lf.temper if lf.temper != 1.0 else ll


@pytest.fixture(scope="module")
def grid():
    return office()


@pytest.fixture(scope="module")
def grid_unknown():
    """The office with an unknown band inside it and unknown margins: end points land in unknown cells."""
    g = office()
    d = np.array(g.data, dtype=float)
    d[:, :12] = np.nan
    d[30:45, 40:90] = np.nan
    d[-8:, :] = np.nan
    return OccupancyGrid(d, g.resolution, origin=g.origin, unknown_is_obstacle=False)


def cloud(grid, n, rng):
    """Free poses, poses anywhere in and around the map (inside walls, in unknown cells) and far off it."""
    (x0, y0), (h, w) = grid.origin, grid.shape
    span_x, span_y = w * grid.resolution, h * grid.resolution
    anywhere = np.c_[rng.uniform(x0 - 3, x0 + span_x + 3, n), rng.uniform(y0 - 3, y0 + span_y + 3, n),
                     rng.uniform(-4, 4, n)]
    far = np.array([[x0 - 40.0, y0 + 2.0, 0.3], [x0 + span_x + 25.0, y0 - 30.0, -2.0]])
    return np.vstack([grid.sample_free(n, rng), anywhere, far])


def scan(rng, b, maxr=MAXR):
    """Readings with every kind of beam: returned, at and beyond max range, +inf, 0 and tiny."""
    z = rng.uniform(0.0, maxr * 1.3, b)
    z[::7] = np.inf
    z[3::11] = maxr
    z[5::13] = 0.0
    return z, np.sort(rng.uniform(-np.pi, np.pi, b))


CASES = {
    "plain": dict(),
    "z_short floor": dict(z_short=0.2, lambda_short=0.7),
    "offset, tempered, thinned": dict(sensor_offset=(0.25, -0.05, 0.1), temper=0.3, max_beams=17),
    "min_range, max_dist, weights": dict(min_range=0.4, max_dist=0.5, z_hit=0.6, z_rand=0.4, sigma_hit=0.1),
    "everything": dict(z_short=0.1, sensor_offset=(-0.1, 0.2, -0.5), temper=0.5, max_beams=40, min_range=0.2),
}


@pytest.mark.parametrize("kw", CASES.values(), ids=CASES.keys())
@pytest.mark.parametrize("unknown", ["none", "neutral", "distance", "obstacle"])
def test_same_bits_as_the_vectorised_formula(grid, grid_unknown, kw, unknown, monkeypatch):
    g = grid if unknown == "none" else grid_unknown
    extra = {"neutral": dict(unknown_neutral=True), "distance": dict(unknown_neutral=False),
             "obstacle": dict(unknown_is_obstacle=True)}.get(unknown, {})
    lf = LikelihoodField(g, MAXR, **{"z_hit": 0.9, "z_rand": 0.1, **kw, **extra})
    rng = np.random.default_rng(41)
    poses = cloud(g, 700, rng)
    for b, block in [(60, 1 << 16), (60, 997), (5, 64), (130, 3000), (300, 1 << 16), (1, 10)]:
        monkeypatch.setattr(sensors, "_LF_BLOCK", block)    # several blocks, a short last one
        z, a = scan(rng, b)
        fast = lf.log_likelihood(poses, z, a)
        np.testing.assert_array_equal(fast, vectorised_reference(lf, poses, z, a), err_msg=f"{b} beams")
    # the work arrays kept between calls carry nothing over: a fresh model agrees on the last scan
    fresh = LikelihoodField(g, MAXR, **{"z_hit": 0.9, "z_rand": 0.1, **kw, **extra})
    np.testing.assert_array_equal(fresh.log_likelihood(poses[:33], z, a), fast[:33])


@pytest.mark.parametrize("kw", CASES.values(), ids=CASES.keys())
def test_held_to_the_per_beam_oracle(grid_unknown, kw):
    """Float32 end points can fall in a neighbouring cell of the float64 oracle's only at a cell border."""
    lf = LikelihoodField(grid_unknown, MAXR, **{"z_hit": 0.9, "z_rand": 0.1, **kw})
    rng = np.random.default_rng(7)
    poses = cloud(grid_unknown, 25, rng)
    z, a = scan(rng, 45)
    np.testing.assert_allclose(lf.log_likelihood(poses, z, a), lf.log_likelihood_reference(poses, z, a),
                               rtol=1e-5, atol=1e-4)


def test_a_scan_without_returns_or_poses_and_bad_readings(grid):
    lf = LikelihoodField(grid, MAXR, min_range=0.5)
    poses = grid.sample_free(5, np.random.default_rng(0))
    assert lf.log_likelihood(poses, [MAXR, np.inf, 0.3], [0.0, 1.0, 2.0]).tolist() == [0.0] * 5
    assert lf.log_likelihood(np.empty((0, 3)), [1.0], [0.0]).shape == (0,)
    with pytest.raises(ValueError, match="NaN"):
        lf.log_likelihood(poses, [1.0, math.nan], [0.0, 1.0])
    with pytest.raises(ValueError, match="NaN"):
        vectorised_reference(lf, poses, [1.0, math.nan], [0.0, 1.0])


@pytest.mark.parametrize("n", [1, 2, 7, 8, 9, 15, 16, 17, 99, 100, 127, 128, 129, 136, 255, 256, 257, 361, 1081])
def test_rowsum_adds_in_numpys_order(n):
    rng = np.random.default_rng(n)
    v = (rng.normal(size=(n, 40)) * 10.0 ** rng.integers(-6, 7, size=(n, 40))).astype(np.float32)
    got = np.empty(40)
    sensors._rowsum(v.astype(np.float64), got, np.empty((8, 40)))
    np.testing.assert_array_equal(got, np.ascontiguousarray(v.T).sum(axis=1, dtype=np.float64))
    assert sensors._rowsum_is_numpys(n)
    # a different order would differ in the last bits on such numbers: the test can fail
    assert not np.array_equal(np.cumsum(v.astype(np.float64)[::-1], axis=0)[-1], got) or n < 3


def test_rows_longer_than_numpys_buffer_take_the_transposed_sum(grid, monkeypatch):
    lf = LikelihoodField(grid, MAXR)
    rng = np.random.default_rng(3)
    poses = grid.sample_free(6, rng)
    z, a = rng.uniform(0.1, MAXR, 9000), rng.uniform(-np.pi, np.pi, 9000)
    monkeypatch.setattr(sensors, "_ROWSUM_OK", {9000: False})
    np.testing.assert_array_equal(lf.log_likelihood(poses, z, a), vectorised_reference(lf, poses, z, a))


def test_a_pickled_model_leaves_its_work_arrays_behind_and_scores_alike(grid):
    lf = LikelihoodField(grid, MAXR, z_short=0.1)
    rng = np.random.default_rng(9)
    poses, (z, a) = cloud(grid, 300, rng), scan(rng, 50)
    before = lf.log_likelihood(poses, z, a)
    blob = pickle.dumps(lf)
    assert "_work_arrays" in lf.__dict__
    again = pickle.loads(blob)
    assert "_work_arrays" not in again.__dict__
    np.testing.assert_array_equal(again.log_likelihood(poses, z, a), before)


# ------------------------------------------------------------ the float32 opt-in
def entries(lf: LikelihoodField, poses, ranges, angles) -> np.ndarray:
    """The float32 table entries ``(N, B)`` that ``log_likelihood`` sums (after the ``z_short`` floor)."""
    z, a = lf._prepare(ranges, angles)
    sp = sensor_poses(poses, lf.sensor_offset)
    g, f32 = lf.grid, np.float32
    inv = 1.0 / g.resolution
    bx, by = (z * np.cos(a) * inv).astype(f32), (z * np.sin(a) * inv).astype(f32)
    c, s = np.cos(sp[:, 2]).astype(f32)[:, None], np.sin(sp[:, 2]).astype(f32)[:, None]
    x0 = ((sp[:, 0] - g.origin[0]) * inv + lf._pad).astype(f32)[:, None]
    y0 = ((sp[:, 1] - g.origin[1]) * inv + lf._pad).astype(f32)[:, None]
    rows_p, cols_p = lf.table.shape
    ex = np.clip(c * bx - s * by + x0, 0, cols_p - 1)
    ey = np.clip(s * bx + c * by + y0, 0, rows_p - 1)
    vals = lf.table[ey.astype(np.int32), ex.astype(np.int32)]
    if lf.z_short > 0:
        vals = np.maximum(vals, lf.short_floor(z).astype(f32)[None, :])
    return vals


def float32_bound(lf: LikelihoodField, vals: np.ndarray) -> np.ndarray:
    """The class docstring's bound: ``temper gamma_(B-1) sum_k |v_k|``, ``gamma_n = n u / (1 - n u)``, ``u = 2^-24``."""
    u, nb = 2.0 ** -24, vals.shape[1]
    gamma = max(nb - 1, 0) * u / (1 - max(nb - 1, 0) * u)
    return lf.temper * gamma * np.abs(vals.astype(np.float64)).sum(axis=1)


@pytest.mark.parametrize("kw", CASES.values(), ids=CASES.keys())
@pytest.mark.parametrize("unknown", ["none", "neutral", "obstacle"])
def test_float32_sums_stay_within_the_derived_bound(grid, grid_unknown, kw, unknown, monkeypatch):
    g = grid if unknown == "none" else grid_unknown
    extra = {"obstacle": dict(unknown_is_obstacle=True)}.get(unknown, {})
    args = {"z_hit": 0.9, "z_rand": 0.1, **kw, **extra}
    lf64 = LikelihoodField(g, MAXR, **args)
    lf32 = LikelihoodField(g, MAXR, dtype=np.float32, **args)
    np.testing.assert_array_equal(lf32.table, lf64.table)
    rng = np.random.default_rng(32)
    poses = cloud(g, 700, rng)
    worst = 0.0
    for b, block in [(60, 1 << 16), (130, 3000), (300, 997), (1, 10)]:
        monkeypatch.setattr(sensors, "_LF_BLOCK", block)
        z, a = scan(rng, b)
        ll64, ll32 = lf64.log_likelihood(poses, z, a), lf32.log_likelihood(poses, z, a)
        vals = entries(lf64, poses, z, a)
        # the entries are the default path's: their float64 sum is its result to the bit
        exact = vals.astype(np.float64).sum(axis=1) * (lf64.temper if lf64.temper != 1.0 else 1.0)
        np.testing.assert_allclose(exact, ll64, rtol=1e-13, atol=1e-12)
        bound = float32_bound(lf32, vals)
        assert ll32.dtype == np.float64 and ll32.shape == ll64.shape
        assert np.all(np.abs(ll32 - ll64) <= bound + 1e-15 * np.abs(ll64)), f"{b} beams"
        worst = max(worst, float(np.max(np.abs(ll32 - ll64) / np.maximum(bound, 1e-300))))
        # the bound is tight enough to catch a lost beam: every entry is far larger than it
        if vals.shape[1] > 1:
            assert np.all(np.abs(vals).min(axis=1) * lf32.temper > bound)
    assert 0.0 < worst <= 1.0            # float32 sums really differ from the float64 ones, within the bound


def test_float32_held_to_the_per_beam_oracle(grid_unknown):
    lf = LikelihoodField(grid_unknown, MAXR, z_short=0.1, dtype="float32")
    rng = np.random.default_rng(7)
    poses = cloud(grid_unknown, 25, rng)
    z, a = scan(rng, 45)
    ref = lf.log_likelihood_reference(poses, z, a)
    bound = float32_bound(lf, entries(lf, poses, z, a))
    np.testing.assert_allclose(lf.log_likelihood(poses, z, a), ref, rtol=1e-5, atol=1e-4 + bound.max())


def test_float32_option_checked_shown_and_pickled(grid):
    lf = LikelihoodField(grid, MAXR, dtype=np.float32)
    assert lf.dtype is np.float32 and repr(lf).endswith("dtype=float32)")
    assert LikelihoodField(grid, MAXR).dtype is np.float64 and "dtype" not in repr(LikelihoodField(grid, MAXR))
    for bad in (np.int32, "float16", "no such type", 3, None):
        with pytest.raises(ValueError, match="dtype must be np.float64"):
            LikelihoodField(grid, MAXR, dtype=bad)
    rng = np.random.default_rng(4)
    poses, (z, a) = cloud(grid, 200, rng), scan(rng, 40)
    before = lf.log_likelihood(poses, z, a)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(lf)).log_likelihood(poses, z, a), before)
