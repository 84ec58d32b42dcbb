"""Tests of localize.diagnostics: the references chapters 6 and 8 measure particle filters against."""

import numpy as np
import pytest
from scipy import stats

from localize import discrete, resample
from localize.diagnostics import (
    AlmostOne,
    exact_corridor_posteriors,
    nearest_particle_distance,
    ring_histogram,
    tv_distance,
)
from localize.sim import corridor_run


def _exact_by_hand(run, cpm=20):
    """The exact filter written out with a kernel of +-12 cells (3 sigma of 0.2 m at 5 cm cells)."""
    m = int(run.length * cpm)
    centres = (np.arange(m) + 0.5) / cpm
    kernel = stats.norm.pdf(np.arange(-12, 13) / cpm, 0, run.sigma_move)
    kernel /= kernel.sum()
    bel, out = discrete.uniform(m), []
    for k in range(len(run)):
        if k > 0:
            bel = discrete.predict(bel, kernel, offset=int(round(run.controls[k] * cpm)))
        bel = discrete.update(bel, np.exp(run.log_likelihood(centres, run.z[k])))
        out.append(np.bincount(np.floor(centres).astype(int), weights=bel, minlength=int(run.length)))
    return out


def test_exact_corridor_posteriors_equal_the_filter_written_out():
    run = corridor_run(np.random.default_rng(11), n_steps=12)
    assert run.sigma_move == 0.2
    got, want = exact_corridor_posteriors(run), _exact_by_hand(run)
    assert len(got) == len(run)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
        assert g.sum() == pytest.approx(1.0, abs=1e-12)


def test_a_large_particle_cloud_approaches_the_exact_posterior():
    """TV distance of a particle filter to the exact posterior shrinks with N (chapter 6's claim, small)."""
    run = corridor_run(np.random.default_rng(11), n_steps=6)
    exact = exact_corridor_posteriors(run)[-1]
    steps = [(None if k == 0 else run.controls[k], run.z[k]) for k in range(len(run))]

    def tv(n, seed):
        rng = np.random.default_rng(seed)
        out = resample.bootstrap_filter(rng.uniform(0, run.length, n), steps, run.move, run.log_likelihood, rng)
        return tv_distance(exact, ring_histogram(out.particles[-1], out.weights[-1], run.length))

    small = np.mean([tv(50, s) for s in range(8)])
    large = np.mean([tv(5000, s) for s in range(8)])
    assert large < 0.5 * small      # 1/sqrt(N) would give a tenth; half leaves room for 8 seeds' scatter
    assert large < 0.1


def test_ring_histogram_and_tv_distance():
    p = ring_histogram([0.5, 3.5, 4.2, -0.5], [1.0, 1.0, 1.0, 1.0], length=4.0)
    np.testing.assert_allclose(p, [0.5, 0.0, 0.0, 0.5])      # 4.2 wraps to cell 0, -0.5 to cell 3
    assert tv_distance(p, p) == 0.0
    assert tv_distance([1, 0, 0], [0, 0.5, 0.5]) == 1.0
    with pytest.raises(ValueError, match="same shape"):
        tv_distance([1.0], [0.5, 0.5])
    with pytest.raises(ValueError, match="probability distribution"):
        tv_distance([0.5, 0.6], [0.5, 0.5])
    with pytest.raises(ValueError, match="one entry per particle"):
        ring_histogram([1.0, 2.0], [1.0], 4.0)
    with pytest.raises(ValueError, match="not all zero"):
        ring_histogram([1.0], [0.0], 4.0)


def test_nearest_particle_distance_counts_only_headings_within_the_limit():
    cloud = np.array([[1.0, 0.0, 0.0], [0.1, 0.0, np.pi], [0.0, 2.0, -0.15]])
    assert nearest_particle_distance(cloud, [0.0, 0.0, 0.0]) == pytest.approx(1.0)
    assert nearest_particle_distance(cloud, [0.0, 0.0, 0.0], max_heading=0.1) == pytest.approx(1.0)
    assert nearest_particle_distance(cloud, [0.0, 0.0, -np.pi + 0.05]) == pytest.approx(0.1)   # across the seam
    assert nearest_particle_distance(cloud, [0.0, 0.0, 1.5]) == np.inf
    with pytest.raises(ValueError, match="particles"):
        nearest_particle_distance(cloud[:, :2], [0.0, 0.0, 0.0])


def test_almost_one_draws_the_largest_double_below_one():
    top = np.nextafter(1.0, 0.0)
    g = AlmostOne(np.random.PCG64(0))
    assert g.random() == top and np.all(g.random(5) == top)
    assert AlmostOne(3).normal() == np.random.Generator(np.random.PCG64(3)).normal()   # the rest is PCG64
    # the case it exists for: ten weights of 0.1 sum below one, the last pointer still lands on a particle
    idx = resample.systematic(np.full(10, 0.1), AlmostOne())
    assert idx.min() >= 0 and idx.max() <= 9 and idx.size == 10
