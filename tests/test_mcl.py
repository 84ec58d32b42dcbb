"""Tests of localize.mcl (Monte Carlo Localization) and localize.kld (KLD-sampling).

The first part checks the filter's mechanics with tiny test doubles (a sensor
that measures x and y directly, a motion model that shifts poses), where the
exact posterior is known in closed form. The second part runs MCL end to end
on the office map with the real motion and sensor models and the simulated
robot of localize.sim.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from localize.kld import KLDSampling, bin_keys, kld_bound, kld_sample_size, kld_sample_size_loop
from localize.maps import office
from localize.mcl import MCL, Augmented, estimate_pose, gaussian_particles, mcl_step_loop, uniform_particles


# ----------------------------------------------------------------- test doubles
class XYSensor:
    """Measures the position (x, y) with Gaussian noise of standard deviation sigma."""

    def __init__(self, sigma: float = 0.5):
        self.sigma = sigma

    def log_likelihood(self, poses, z):
        d = (poses[:, :2] - np.asarray(z)[None, :2]) / self.sigma
        return -0.5 * np.sum(d * d, axis=1)


class ConstSensor:
    """Returns a fixed log-likelihood array (to provoke degenerate updates)."""

    def __init__(self, values):
        self.values = np.asarray(values, dtype=float)

    def log_likelihood(self, poses, *z):
        return np.broadcast_to(self.values, (len(poses),)).copy()


def shift(poses, u, rng):
    """Deterministic motion: add u to every pose."""
    return poses + np.asarray(u, dtype=float)


def noisy_shift(sigma):
    def move(poses, u, rng):
        return poses + np.asarray(u, dtype=float) + rng.normal(0.0, sigma, poses.shape) * [1, 1, 0]

    return move


def box_sampler(n, rng):
    return np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), rng.uniform(-np.pi, np.pi, n)])


def far_sampler(n, rng):
    """Marks injected particles: they all sit at (100, 100)."""
    return np.tile([100.0, 100.0, 0.0], (n, 1))


def make(n=1000, seed=0, **kw):
    rng = np.random.default_rng(seed)
    p = box_sampler(n, rng)
    kw.setdefault("sampler", box_sampler)
    return MCL(p, shift, XYSensor(), rng=rng, **kw)


# ----------------------------------------------------------------- construction
def test_bad_arguments_are_named():
    rng = np.random.default_rng(0)
    p = np.zeros((10, 3))
    with pytest.raises(TypeError, match="rng"):
        MCL(p, shift, XYSensor(), rng=0)
    with pytest.raises(ValueError, match="particles"):
        MCL(np.zeros((10, 2)), shift, XYSensor(), rng=rng)
    with pytest.raises(TypeError, match="log_likelihood"):
        MCL(p, shift, object(), rng=rng)
    with pytest.raises(ValueError, match="resample_threshold"):
        MCL(p, shift, XYSensor(), rng=rng, resample_threshold=1.5)
    with pytest.raises(ValueError, match="injection"):
        MCL(p, shift, XYSensor(), rng=rng, injection=1.0, sampler=box_sampler)
    with pytest.raises(ValueError, match="grid=|sampler"):
        MCL(p, shift, XYSensor(), rng=rng, injection=0.05)
    with pytest.raises(ValueError, match="resampler"):
        MCL(p, shift, XYSensor(), rng=rng, resampler="roulette")
    with pytest.raises(ValueError, match="log_weights"):
        MCL(p, shift, XYSensor(), rng=rng, log_weights=np.full(10, -np.inf))
    with pytest.raises(ValueError, match="on_degenerate"):
        MCL(p, shift, XYSensor(), rng=rng, on_degenerate="panic")
    with pytest.raises(ValueError, match="alpha_fast"):
        Augmented(0.1, 0.05)
    with pytest.raises(ValueError, match="alphas"):
        MCL(p, (0.1, 0.1), XYSensor(), rng=rng)
    f = MCL(p, shift, XYSensor(), rng=rng)
    f.sensor = type("Wrong", (), {"log_likelihood": lambda self, poses: np.zeros(3)})()
    with pytest.raises(ValueError, match="expected \\(10,\\)"):
        f.update()


def test_initialisers():
    rng = np.random.default_rng(1)
    g = office()
    p = uniform_particles(g, 5000, rng)
    assert p.shape == (5000, 3) and g.is_free(p).all()
    # uniform over free cells: the share in the left half matches the free-cell share
    free_left = g.free[:, : g.shape[1] // 2].sum() / g.free.sum()
    share = np.mean(p[:, 0] < g.width_m / 2)
    assert abs(share - free_left) < 5 * np.sqrt(free_left * (1 - free_left) / 5000)
    q = gaussian_particles([1.0, 2.0, np.pi - 0.01], (0.1, 0.2, 0.3), 20_000, rng)
    assert np.all((q[:, 2] >= -np.pi) & (q[:, 2] < np.pi))
    assert np.allclose(q[:, :2].std(axis=0), [0.1, 0.2], rtol=0.03)
    with pytest.raises(ValueError, match="cov"):
        gaussian_particles([0, 0, 0], np.ones((3, 3)) * -1, 10, rng)
    with pytest.raises(ValueError, match="n must"):
        gaussian_particles([0, 0, 0], (1, 1, 1), 0, rng)


# ----------------------------------------------------------------- weights
def test_update_matches_bayes_rule_in_log_space():
    f = make(500, log_weights=np.linspace(-3, 0, 500))
    prior = f.log_weights.copy()
    ll = XYSensor().log_likelihood(f.particles, [5.0, 5.0])
    f.update([5.0, 5.0])
    expected = prior + ll
    expected -= np.log(np.sum(np.exp(expected)))
    np.testing.assert_allclose(f.log_weights, expected, atol=1e-12)
    assert abs(f.weights.sum() - 1.0) < 1e-12
    # the evidence is log sum W_prior p(z|x)
    assert abs(f.status.log_evidence - np.log(np.sum(np.exp(prior + ll)))) < 1e-10


def test_tiny_likelihoods_do_not_underflow():
    """A 1000-beam scan gives log-likelihoods near -1e5: linear weights would all be 0."""
    f = make(200)
    f.sensor = ConstSensor(-1e5 - np.arange(200.0))
    f.update()
    assert np.isfinite(f.log_weights).all()
    assert abs(f.weights[0] - 1 / np.sum(np.exp(-np.arange(200.0)))) < 1e-9
    assert not f.status.degenerate


def test_scan_that_matches_nothing_is_recovered_not_nan():
    f = make(300, resample_threshold=0.0)
    before_p = f.particles.copy()
    f.update([5.0, 5.0])
    before_w = f.log_weights.copy()
    f.sensor = ConstSensor(-np.inf)                      # every particle impossible
    est = f.step(None, "anything")
    assert f.status.degenerate and f.status.n_degenerate == 1
    assert "zero likelihood" in f.status.message
    assert not np.isnan(f.log_weights).any() and not np.isnan(f.particles).any()
    assert np.isfinite(est.pose).all()
    np.testing.assert_array_equal(f.particles, before_p)   # measurement ignored
    np.testing.assert_allclose(f.log_weights, before_w)
    # the next good measurement works as usual and clears the flag
    f.sensor = XYSensor()
    f.update([5.0, 5.0])
    assert not f.status.degenerate and f.status.n_degenerate == 1


def test_nan_and_inf_likelihoods_count_as_invalid():
    f = make(4)
    f.sensor = ConstSensor([np.nan, np.inf, -1.0, -2.0])
    f.update()
    assert f.status.n_invalid == 2 and "invalid" in f.status.message
    np.testing.assert_allclose(f.weights, [0, 0, 1 / (1 + np.exp(-1)), np.exp(-1) / (1 + np.exp(-1))])
    f.sensor = ConstSensor(np.nan)
    f.update()
    assert f.status.degenerate and np.isfinite(f.log_weights).any()


def test_degenerate_reinitialize_draws_from_sampler():
    f = make(100, on_degenerate="reinitialize", sampler=far_sampler)
    f.sensor = ConstSensor(-np.inf)
    f.update()
    assert f.status.degenerate
    np.testing.assert_array_equal(f.particles, np.tile([100.0, 100.0, 0.0], (100, 1)))
    np.testing.assert_allclose(f.weights, 0.01)


def test_free_space_only_zeroes_particles_in_walls():
    g = office()
    rng = np.random.default_rng(3)
    p = np.array([[0.5, 0.5, 0.0], [0.05, 0.05, 0.0], [-5.0, 3.0, 0.0], [10.0, 5.5, 0.0]])
    f = MCL(p, shift, ConstSensor(0.0), rng=rng, grid=g, free_space_only=True)
    f.update()
    np.testing.assert_allclose(f.weights, [0.5, 0, 0, 0.5])


def test_occupied_penalty_is_a_finite_price_for_standing_in_an_obstacle():
    """--occupied-penalty: a particle in a known obstacle loses that many nats; outside the grid it has no weight."""
    g = office()
    p = np.array([[0.5, 0.5, 0.0], [0.05, 0.05, 0.0], [-5.0, 3.0, 0.0], [10.0, 5.5, 0.0]])   # free, wall, off, free
    f = MCL(p, shift, ConstSensor(0.0), rng=np.random.default_rng(3), grid=g, free_space_only=True,
            occupied_penalty=5.0)
    f.update()
    w = f.weights
    assert w[2] == 0.0 and w[0] == pytest.approx(w[3])
    assert w[1] / w[0] == pytest.approx(np.exp(-5.0))
    # a whole cloud in an obstacle the map is wrong about (a door drawn shut) keeps its weights: the scans decide
    door = np.tile([0.05, 0.05, 0.0], (50, 1)) + np.c_[np.linspace(0, 0.04, 50), np.zeros((50, 2))]

    class Ramp:                                       # a scan that prefers the particles further right
        def log_likelihood(self, poses, *z):
            return poses[:, 0] * 10.0

    soft = MCL(door, shift, Ramp(), rng=np.random.default_rng(0), grid=g, free_space_only=True, occupied_penalty=5.0)
    soft.update()
    assert not soft.status.degenerate
    assert soft.weights[-1] / soft.weights[0] == pytest.approx(np.exp(0.4))
    hard = MCL(door, shift, Ramp(), rng=np.random.default_rng(0), grid=g, free_space_only=True)
    assert not hard._in_free_space(door).any()        # all 50 stand in the office's corner wall
    hard.update()
    assert hard.status.degenerate                     # np.inf (the MCL default): every particle has zero weight
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="occupied_penalty must be > 0"):
            MCL(p, shift, ConstSensor(0.0), rng=np.random.default_rng(0), grid=g, free_space_only=True,
                occupied_penalty=bad)


def test_run_filter_keeps_a_cloud_that_walks_into_an_obstacle_with_a_finite_penalty():
    """Not "off the map": an agreed cloud is neither re-drawn nor called lost for standing in a mapped obstacle
    (a door drawn shut); while the filter searches, a particle in an obstacle still has zero weight."""
    from localize.mcl import OdometryMotion
    from localize.runloop import run_filter

    g = office()
    occ = g.occupied
    n = int(round(1.0 / g.resolution))
    i, j = next((i, j) for i, j in np.argwhere(occ[:, 1:] & ~occ[:, :-1])
                if j > n and g.free[i, j - n:j + 1].all())                 # 1 m of free floor, then an obstacle
    wall = g.origin + (np.array([j + 1, i]) + 0.5) * g.resolution
    start = wall - [1.0, 0.0]
    odo = np.zeros((5, 3))
    odo[3:, 0] = 1.0                                                      # the robot steps 1 m right, into it
    where = [start, start, start, wall, wall]
    for penalty, redrawn in ((5.0, False), (np.inf, True)):
        f = MCL.gaussian([*start, 0.0], (0.01, 0.01, 0.001), 200, OdometryMotion((0.0,) * 4), XYSensor(0.1),
                         rng=np.random.default_rng(0), grid=g, free_space_only=True, occupied_penalty=penalty)
        tr = run_filter(f, 5, lambda k: (odo[k - 1], odo[k]), lambda k: (where[k],), grid=g, min_motion=(0.0, 0.0))
        assert any("re-drawn" in t for k, t in tr.events) is redrawn, tr.events
        assert (np.abs(tr.poses[-1, :2] - wall).max() < 0.05) is not redrawn, tr.poses[-1]
        assert f.soft_obstacles                                           # left as it was found
    # searching, the same cloud started in the obstacle has zero weight there: it is re-drawn
    f = MCL.gaussian([*wall, 0.0], (0.01, 0.01, 0.001), 200, OdometryMotion((0.0,) * 4), XYSensor(0.1),
                     rng=np.random.default_rng(0), grid=g, free_space_only=True, occupied_penalty=5.0)
    tr = run_filter(f, 2, lambda k: None, lambda k: (wall,), grid=g, min_motion=(0.0, 0.0))
    assert tr.degenerate[0]


# ----------------------------------------------------------------- resampling policy
def test_resampling_threshold_policy():
    f = make(1000, resample_threshold=0.0)
    f.step(None, [5.0, 5.0])
    assert not f.status.resampled                       # 0 never resamples on its own
    f = make(1000, resample_threshold=1.0)
    f.sensor = ConstSensor(0.0)
    f.step(None, "z")
    assert f.status.resampled                           # 1 always does
    f = make(1000, resample_threshold=0.5)
    f.sensor = ConstSensor(np.where(np.arange(1000) < 600, 0.0, -50.0))
    f.step(None, "z")                                   # N_eff = 600 > 500: keep
    assert not f.status.resampled and abs(f.status.n_eff - 600) < 1e-6
    f = make(1000, resample_threshold=0.5)
    f.sensor = ConstSensor(np.where(np.arange(1000) < 400, 0.0, -50.0))
    f.step(None, "z")                                   # N_eff = 400 < 500: resample
    assert f.status.resampled and np.all(f.log_weights == -np.log(1000))


@pytest.mark.parametrize("name", ["multinomial", "stratified", "systematic", "residual"])
def test_every_resampler_keeps_only_possible_particles(name):
    f = make(500, resampler=name, resample_threshold=1.0)
    f.sensor = ConstSensor(np.where(np.arange(500) % 5 == 0, 0.0, -np.inf))
    keep = f.particles[::5].copy()
    f.step(None, "z")
    assert f.n == 500
    assert {tuple(r) for r in f.particles} <= {tuple(r) for r in keep}


def test_custom_resampler_callable():
    calls = []

    def first_only(w, rng):
        calls.append(len(w))
        return np.zeros(len(w), dtype=np.int64)

    f = make(50, resampler=first_only, resample_threshold=1.0)
    f.step(None, [1.0, 1.0])
    assert calls == [50] and np.all(f.particles == f.particles[0])


# ----------------------------------------------------------------- statistics of the posterior
def test_weighted_particles_match_the_kalman_posterior():
    """Linear-Gaussian case: prior N(m0, s0^2), measurement z with noise s -> closed-form posterior.

    The weighted particle mean must match the exact posterior mean within 5 Monte Carlo standard errors
    (standard error from the effective sample size); a filter that forgot the prior weights or used
    the wrong sign would be off by far more.
    """
    rng = np.random.default_rng(7)
    n, m0, s0, s, z = 20_000, 2.0, 1.0, 0.5, 3.0
    p = np.column_stack([rng.normal(m0, s0, n), np.zeros(n), np.zeros(n)])
    f = MCL(p, shift, XYSensor(s), rng=rng, resample_threshold=0.0)
    f.update([z, 0.0])
    post_var = 1 / (1 / s0**2 + 1 / s**2)
    post_mean = post_var * (m0 / s0**2 + z / s**2)
    w = f.weights
    mean = float(w @ f.particles[:, 0])
    var = float(w @ (f.particles[:, 0] - mean) ** 2)
    se = np.sqrt(post_var / f.n_eff)
    assert abs(mean - post_mean) < 5 * se
    assert abs(var - post_var) < 5 * post_var * np.sqrt(2 / f.n_eff)
    # second measurement on top of the *weighted* set (no resampling in between)
    f.update([z, 0.0])
    post_var2 = 1 / (1 / s0**2 + 2 / s**2)
    post_mean2 = post_var2 * (m0 / s0**2 + 2 * z / s**2)
    mean2 = float(f.weights @ f.particles[:, 0])
    assert abs(mean2 - post_mean2) < 5 * np.sqrt(post_var2 / f.n_eff)


def test_step_agrees_with_textbook_loop():
    """MCL.step (vectorised, systematic) and the table 8.2 loop (multinomial) give the same posterior."""
    rng = np.random.default_rng(11)
    n = 4000
    p0 = np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), np.zeros(n)])
    move = noisy_shift(0.3)
    f = MCL(p0.copy(), move, XYSensor(0.7), rng=np.random.default_rng(1), resample_threshold=1.0)
    f.step([1.0, 0.5, 0.0], [6.0, 4.0])
    loop = mcl_step_loop(p0[:1000], [1.0, 0.5, 0.0], ([6.0, 4.0],), move, XYSensor(0.7), np.random.default_rng(2))
    # exact posterior of the x coordinate: uniform prior [1, 11] (after the shift) times N(6, 0.7^2 + 0.3^2 ...)
    # both must be close to 6 and 4 with spread ~0.7: compare the two samples' means by their standard errors
    for k, target in ((0, 6.0), (1, 4.0)):
        se = np.sqrt(f.particles[:, k].var() / n + loop[:, k].var() / 1000)
        assert abs(f.particles[:, k].mean() - loop[:, k].mean()) < 5 * se
        assert abs(f.particles[:, k].mean() - target) < 0.1
        assert abs(f.particles[:, k].std() - loop[:, k].std()) < 0.1


# ----------------------------------------------------------------- injection and augmented MCL
def test_fixed_injection_replaces_the_stated_fraction():
    f = make(1000, injection=0.05, sampler=far_sampler, resample_threshold=1.0)
    f.step(None, [5.0, 5.0])
    n_far = int(np.sum(f.particles[:, 0] == 100.0))
    assert f.status.n_injected == 50 and n_far == 50


def test_augmented_averages_follow_table_8_3():
    """w_slow and w_fast, kept in log space, equal the linear-space recursion of PR table 8.3."""
    a_slow, a_fast = 0.05, 0.5
    f = make(200, augmented=(a_slow, a_fast), sampler=far_sampler, resample_threshold=0.0)
    levels = [-1.0, 0.0, 0.0, -0.1, 0.0, 0.0, 0.0, -3.0, -3.0, -3.0]
    w_slow = w_fast = np.exp(levels[0])     # both start at the first w_avg (see Augmented)
    for lv in levels:
        f.log_weights = np.full(f.n, -np.log(f.n))    # keep prior weights uniform
        f.sensor = ConstSensor(lv)
        f.update()
        w_avg = np.exp(lv)
        w_slow += a_slow * (w_avg - w_slow)
        w_fast += a_fast * (w_avg - w_fast)
        assert abs(np.exp(f.status.log_w_slow) - w_slow) < 1e-12
        assert abs(np.exp(f.status.log_w_fast) - w_fast) < 1e-12
        assert abs(f.status.p_inject - max(0.0, 1 - w_fast / w_slow)) < 1e-12
    assert f.status.p_inject > 0.5            # the likelihood dropped: inject
    assert f.needs_resampling()


def test_augmented_injects_after_a_sudden_drop():
    f = make(2000, augmented=Augmented(0.05, 0.5), sampler=far_sampler, resample_threshold=0.5)
    f.sensor = ConstSensor(0.0)
    for _ in range(30):
        f.step(None, "z")
    assert f.status.p_inject == 0 and f.status.n_injected == 0
    f.sensor = ConstSensor(-5.0)             # the world suddenly fits much worse (kidnapping)
    f.step(None, "z")
    p = f.status.p_inject
    assert p > 0.3 and f.status.resampled
    # binomial count of injected particles: within 5 standard deviations of n p
    assert abs(f.status.n_injected - 2000 * p) < 5 * np.sqrt(2000 * p * (1 - p))
    assert int(np.sum(f.particles[:, 0] == 100.0)) == f.status.n_injected


def test_augmented_temperature_scales_the_drop():
    hot = make(100, augmented=Augmented(0.05, 0.5, temperature=60.0), sampler=far_sampler)
    cold = make(100, augmented=Augmented(0.05, 0.5), sampler=far_sampler)
    for f in (hot, cold):
        f.sensor = ConstSensor(0.0)
        for _ in range(10):
            f.step(None, "z")
        f.sensor = ConstSensor(-60.0)
        f.update()
    assert 0 < hot.status.p_inject < cold.status.p_inject


# ----------------------------------------------------------------- estimate
def test_estimate_uses_circular_mean_and_finds_best_cluster():
    rng = np.random.default_rng(5)
    p = rng.normal([1.0, 1.0, np.pi], [0.05, 0.05, 0.1], size=(4000, 3))
    p[:, 2] = (p[:, 2] + np.pi) % (2 * np.pi) - np.pi           # straddles the seam
    e = estimate_pose(p)
    assert abs(abs(e.mean[2]) - np.pi) < 0.01                   # not 0, as an arithmetic mean would say
    assert abs(e.std[2] - 0.1) < 0.01 and abs(e.std[0] - 0.05) < 0.005
    assert e.n_clusters == 1 and not e.multimodal
    q = rng.normal([8.0, 1.0, 0.0], 0.05, size=(2000, 3))
    w = np.r_[np.full(4000, 1.0), np.full(2000, 3.0)]           # second cluster heavier: 6000 vs 4000
    e = estimate_pose(np.vstack([p, q]), w)
    assert e.multimodal and e.n_clusters == 2
    assert abs(e.best_weight - 0.6) < 1e-9
    assert np.allclose(e.pose[:2], [8.0, 1.0], atol=0.01)
    assert 3.0 < e.mean[0] < 6.0
    assert e.cov.shape == (3, 3) and np.allclose(e.cov, e.cov.T)


def test_estimate_input_checks():
    with pytest.raises(ValueError, match="weights"):
        estimate_pose(np.zeros((3, 3)), [1, -1, 1])
    with pytest.raises(ValueError, match="cluster_size"):
        estimate_pose(np.zeros((3, 3)), cluster_size=0)


# ----------------------------------------------------------------- KLD-sampling
def test_kld_bound_matches_chi_square_quantile():
    k = np.array([2, 5, 10, 50, 200, 2000])
    exact = chi2.ppf(0.99, k - 1) / (2 * 0.05)
    approx = kld_bound(k, 0.05, 0.01)
    assert np.all(np.abs(approx / exact - 1) < np.where(k < 10, 0.02, 0.002))
    assert kld_bound(1) == 0.0
    with pytest.raises(ValueError, match="epsilon"):
        kld_bound(3, epsilon=0)
    with pytest.raises(ValueError, match="delta"):
        kld_bound(3, delta=1.5)


@pytest.mark.parametrize("seed", range(5))
def test_kld_vectorised_equals_loop(seed):
    rng = np.random.default_rng(seed)
    spread = [0.2, 1.0, 3.0, 0.5, 6.0][seed]
    p = rng.normal([0, 0, 0], [spread, spread, min(spread, 3.0)], size=(6000, 3))
    b = (0.5, 0.5, np.radians(10))
    assert kld_sample_size(p, b, n_min=50) == kld_sample_size_loop(p, b, n_min=50)


@pytest.mark.parametrize("bad, error, match", [
    (dict(poses=np.zeros((0, 3))), ValueError, "empty"),
    (dict(n_min=0), ValueError, "n_min"),
    (dict(n_min=2.5), TypeError, "n_min"),
    (dict(epsilon=0.0), ValueError, "epsilon"),
    (dict(delta=1.0), ValueError, "delta"),
    (dict(bin_size=(0.5, 0.5)), ValueError, "bin_size"),
])
def test_kld_loop_and_vectorised_reject_the_same_input(bad, error, match):
    # the oracle checks its input as the fast version does: a single point (one bin, where the loop
    # never reaches kld_bound) still has its epsilon and delta checked
    kw = dict(poses=np.zeros((1, 3)), bin_size=(0.5, 0.5, 0.2), epsilon=0.05, delta=0.01, n_min=10)
    kw.update(bad)
    for rule in (kld_sample_size, kld_sample_size_loop):
        with pytest.raises(error, match=match):
            rule(kw["poses"], kw["bin_size"], epsilon=kw["epsilon"],
                 delta=kw["delta"], n_min=kw["n_min"])


def test_bin_keys_identify_bins():
    rng = np.random.default_rng(2)
    p = rng.uniform(-3, 3, size=(500, 3))
    b = np.array([0.5, 0.7, 0.3])
    keys = bin_keys(p, b)
    cells = np.floor(p / b).astype(int)
    same_key = keys[:, None] == keys[None, :]
    same_cell = np.all(cells[:, None, :] == cells[None, :, :], axis=2)
    assert np.array_equal(same_key, same_cell)


def test_kld_particle_count_falls_as_belief_concentrates():
    rng = np.random.default_rng(4)
    n0 = 20_000
    p = box_sampler(n0, rng)
    f = MCL(p, noisy_shift(0.02), XYSensor(0.3), rng=rng, resample_threshold=1.0,
            kld=KLDSampling(epsilon=0.05, n_min=100, n_max=n0))
    counts = []
    for _ in range(6):
        f.step([0.0, 0.0, 0.0], [4.0, 6.0])
        counts.append(f.n)
    assert counts[-1] < 2000 < n0
    assert counts[-1] <= counts[0]
    assert f.status.n_particles == f.n
    e = f.estimate()
    assert np.allclose(e.pose[:2], [4.0, 6.0], atol=0.1)


def test_estimate_ignores_a_veil_of_unlikely_particles():
    """A uniform cloud with two heavy spots: the light particles must not join the spots into one cluster."""
    rng = np.random.default_rng(8)
    veil = np.column_stack([rng.uniform(0, 20, 20_000), rng.uniform(0, 12, 20_000), rng.uniform(-np.pi, np.pi, 20_000)])
    w = np.full(20_000, 1e-9)
    a = np.all(np.abs(veil[:, :2] - [4.0, 3.0]) < 0.3, axis=1)
    b = np.all(np.abs(veil[:, :2] - [15.0, 9.0]) < 0.3, axis=1)
    w[a], w[b] = 2.0, 1.0
    e = estimate_pose(veil, w)
    assert e.n_clusters == 2
    assert np.allclose(e.pose[:2], [4.0, 3.0], atol=0.15)
    assert abs(e.best_weight - 2 * a.sum() / (2 * a.sum() + b.sum())) < 0.01


# ----------------------------------------------------------------- end to end in the office
# The settings the chapter "Monte Carlo Localization" recommends for this world: a 36-beam
# scanner all round, 8 m range, the beam model through the lookup table, tempered (PR 6.3.4).
ANGLES = np.linspace(-np.pi, np.pi, 36, endpoint=False)
MAX_RANGE = 8.0
GLOBAL_PARTICLES = 10_000      # the default particle count for global localization in the office


@pytest.fixture(scope="module")
def office_grid():
    return office()


@pytest.fixture(scope="module")
def beam_model(office_grid):
    from localize.sensors import BeamModel

    return BeamModel(office_grid, MAX_RANGE, sigma_hit=0.2, temper=0.05, method="lut")


@pytest.fixture(scope="module")
def field_model(office_grid):
    from localize.sensors import LikelihoodField

    return LikelihoodField(office_grid, MAX_RANGE, sigma_hit=0.2, temper=0.1)


def _run(grid, seed, n_steps, **kw):
    from localize.sim import range_run

    return range_run(grid, np.random.default_rng(seed), n_steps=n_steps, angles=ANGLES, max_range=MAX_RANGE, **kw)


def _errors(trace, run):
    from localize.metrics import heading_error, position_error

    return position_error(trace.poses, run.poses), heading_error(trace.poses, run.poses)


@pytest.mark.slow
def test_global_localization_in_the_office_succeeds_in_95_percent(office_grid, beam_model):
    """20 seeded robots, each started at a random place; MCL starts uniform with the default count.

    Success: within 0.5 m and 0.2 rad of the truth over the last 5 of 20 steps.
    """
    from localize.mcl import OdometryMotion
    from localize.runloop import run_mcl

    ok = []
    for seed in range(20):
        run = _run(office_grid, seed, 20)
        f = MCL.uniform(office_grid, GLOBAL_PARTICLES, OdometryMotion(run.alphas, min_std=0.01), beam_model,
                        rng=np.random.default_rng(seed + 100))
        pe, he = _errors(run_mcl(f, run), run)
        ok.append(bool(np.all(pe[-5:] < 0.5) and np.all(he[-5:] < 0.2)))
    assert np.mean(ok) >= 0.95, f"succeeded in {sum(ok)} of 20 runs: {ok}"


def test_tracking_error_stays_below_bound(office_grid, beam_model):
    """From a start guess 0.36 m / 8 degrees off, 500 particles track with RMSE < 0.15 m and max < 0.35 m."""
    from localize.mcl import OdometryMotion
    from localize.runloop import run_mcl

    for seed in (11, 12, 13):
        run = _run(office_grid, seed, 40)
        guess = run.poses[0] + [0.3, -0.2, np.radians(8)]
        f = MCL.gaussian(guess, (0.3, 0.3, np.radians(10)), 500, OdometryMotion(run.alphas, min_std=0.01),
                         beam_model, rng=np.random.default_rng(seed))
        pe, he = _errors(run_mcl(f, run), run)
        assert np.sqrt(np.mean(pe[5:] ** 2)) < 0.15, (seed, pe.round(2))
        assert pe[5:].max() < 0.35, (seed, pe.round(2))
        assert np.sqrt(np.mean(he[5:] ** 2)) < np.radians(3.0), (seed, he.round(3))
        assert not np.isnan(f.log_weights).any()


def test_kidnapped_robot_is_recovered_by_augmented_mcl(office_grid, field_model):
    """Kidnapped at step 15 of 50: augmented MCL (PR table 8.3) is back within 0.5 m in at least 4 of 5 runs,
    each time within 35 steps; plain MCL, with nothing to recover with, in at most 1."""
    from localize.mcl import OdometryMotion
    from localize.runloop import run_mcl

    def recovered(seed, **opts):
        run = _run(office_grid, seed, 50, kidnap_at=[15])
        f = MCL.gaussian(run.poses[0], (0.2, 0.2, 0.1), 5000, OdometryMotion(run.alphas, min_std=0.01), field_model,
                         rng=np.random.default_rng(100 + seed), grid=office_grid, **opts)
        tr = run_mcl(f, run)
        pe, _ = _errors(tr, run)
        assert pe[10:15].max() < 0.3                     # it was tracking before the kidnapping
        assert pe[15] > 1.0                              # and lost right after it
        bad = np.flatnonzero(pe[15:] >= 0.5)
        return not (bad.size and bad[-1] == pe.size - 16)   # below 0.5 m from some step to the end (35 steps)

    aug = [recovered(s, augmented=Augmented(0.1, 0.5)) for s in range(5)]
    plain = [recovered(s) for s in range(5)]
    assert sum(aug) >= 4, aug
    assert sum(plain) <= 1, plain


def test_scan_that_matches_nothing_with_a_real_sensor_model(office_grid):
    """A scan that no particle can explain: the filter must report it and carry on, with no NaN and no
    floating-point warning escaping. The model only knows short readings (unmapped obstacles in front of the
    wall, PR's p_short), so a reading beyond the expected range has likelihood exactly zero."""
    from localize.sensors import BeamModel

    shorts_only = BeamModel(office_grid, MAX_RANGE, z_hit=0.0, z_short=1.0, z_max=0.0, z_rand=0.0)
    f = MCL.uniform(office_grid, 500, (0.01,) * 4, shorts_only, rng=np.random.default_rng(1))
    before = f.particles.copy()
    # every beam reads 7.99 m: longer than the way to the nearest wall for every particle in the office
    est = f.step(None, np.full(36, 7.99), ANGLES)
    assert f.status.degenerate and f.status.log_evidence == -np.inf
    assert np.isfinite(est.pose).all() and not np.isnan(f.log_weights).any()
    np.testing.assert_array_equal(f.particles, before)


def test_landmark_mcl_with_the_velocity_model():
    """The same filter with another motion and sensor model: velocity commands and range-bearing sightings."""
    from localize.mcl import VelocityMotion
    from localize.sensors import LandmarkModel
    from localize.sim import landmark_run

    run = landmark_run(np.random.default_rng(3), n_steps=40)
    model = LandmarkModel(run.landmarks, run.sigma_range, run.sigma_bearing)
    f = MCL.gaussian(run.poses[0], (0.3, 0.3, 0.1), 1000, VelocityMotion(run.velocity_alphas, run.dt), model,
                     rng=np.random.default_rng(4))
    errors = []
    for k in range(1, len(run)):
        f.predict(run.controls[k])
        z, ids = run.sightings(k)
        if len(ids):
            f.update(z, ids)
        if f.needs_resampling():
            f.resample()
        errors.append(np.hypot(*(f.estimate().pose[:2] - run.poses[k, :2])))
    # 0.06 m here; dead reckoning from the same prior (no updates) drifts to 0.33 m
    assert np.sqrt(np.mean(np.square(errors[5:]))) < 0.15, np.round(errors, 2)


def _clusters_by_flood_fill(xy, size):
    """Readable oracle: group points whose cells touch (8-neighbourhood), by breadth-first search."""
    cells = {}
    lo = xy.min(axis=0)
    for k, (x, y) in enumerate(xy):
        cells.setdefault((int(np.floor((x - lo[0]) / size)), int(np.floor((y - lo[1]) / size))), []).append(k)
    label, groups = {}, []
    for start in cells:
        if start in label:
            continue
        label[start] = len(groups)
        queue, members = [start], []
        while queue:
            c = queue.pop()
            members.extend(cells[c])
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    nb = (c[0] + dx, c[1] + dy)
                    if nb in cells and nb not in label:
                        label[nb] = label[start]
                        queue.append(nb)
        groups.append(frozenset(members))
    return set(groups)


@pytest.mark.parametrize("seed", range(4))
def test_cluster_labels_match_flood_fill(seed):
    from localize.estimate import _cluster_labels

    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, 10, size=(6, 2))
    xy = np.vstack([c + rng.normal(0, 0.3, size=(50, 2)) for c in centres])
    labels, n = _cluster_labels(xy, np.full(len(xy), 1.0 / len(xy)), 0.5, 1.0)   # mass 1: every cell kept
    fast = {frozenset(np.flatnonzero(labels == k).tolist()) for k in range(n)}
    assert fast == _clusters_by_flood_fill(xy, 0.5)


# ----------------------------------------------------------------- invariants
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_values = st.one_of(st.floats(-1e6, 1e3), st.just(-np.inf), st.just(np.inf), st.just(np.nan))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(_values, min_size=8, max_size=8), min_size=1, max_size=4))
def test_weights_never_become_nan(updates):
    """Whatever the sensor returns, log-weights stay NaN-free and normalised, or the update is flagged."""
    f = make(8, resample_threshold=0.0)
    for ll in updates:
        prior = f.log_weights.copy()
        f.sensor = ConstSensor(ll)
        f.update()
        assert not np.isnan(f.log_weights).any()
        assert abs(f.weights.sum() - 1.0) < 1e-9
        possible = np.isfinite(prior) & np.isfinite(np.asarray(ll))   # positive prior weight and likelihood
        assert f.status.degenerate == (not possible.any())
        if f.status.degenerate:
            np.testing.assert_array_equal(f.log_weights, prior)          # the measurement was ignored
        assert f.status.n_invalid == int(np.sum(np.isnan(ll) | (np.asarray(ll) == np.inf)))
        assert 1.0 - 1e-9 <= f.status.n_eff <= 8.0 + 1e-9


def test_all_options_together():
    """KLD-sampling, a fixed injection and augmented MCL in one filter: sizes and bookkeeping stay consistent."""
    rng = np.random.default_rng(9)
    f = MCL(box_sampler(5000, rng), noisy_shift(0.05), XYSensor(0.3), rng=rng, sampler=box_sampler,
            injection=0.05, augmented=Augmented(0.1, 0.5), kld=KLDSampling(n_min=200, n_max=5000),
            resample_threshold=1.0)
    for k in range(8):
        z = [4.0, 6.0] if k < 5 else [8.0, 2.0]          # the "robot" jumps at step 5
        e = f.step([0.0, 0.0, 0.0], z)
        assert f.n == f.particles.shape[0] == f.log_weights.shape[0] == f.status.n_particles
        assert 200 <= f.n <= 5000 and f.status.n_injected >= round(0.05 * f.n) - 1
    assert f.status.p_inject > 0 or np.allclose(e.pose[:2], [8.0, 2.0], atol=0.3)
    assert "kld=" in repr(f) and "augmented=" in repr(f) and "injection=" in repr(f)


# ----------------------------------------------------------------- the run driver and its state
def _line(n=400, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), np.zeros(n)]), rng


def test_augmented_injects_when_every_likelihood_is_zero():
    """The worst possible fit (w_avg = 0) must raise the injection probability, not skip the averages."""
    g = office()
    p, rng = _line()
    f = MCL(g.sample_free(400, rng), shift, XYSensor(0.3), rng=rng, grid=g, augmented=Augmented(0.05, 0.5))
    for _ in range(3):
        f.step(None, [5.0, 5.0])
    assert f.status.p_inject == 0.0

    class Nothing:
        def log_likelihood(self, poses, *z):
            return np.full(len(poses), -np.inf)

    f.sensor = Nothing()
    injected = 0
    for _ in range(6):                                          # w_fast falls by half each time, w_slow by 5%
        f.step(None, [5.0, 5.0])
        assert f.status.degenerate
        injected += f.status.n_injected
    assert f.status.p_inject > 0.3 and injected > 0


def test_adaptive_tempering_keeps_the_stated_effective_sample_size():
    p, rng = _line(2000)
    f = MCL(p, shift, XYSensor(0.05), rng=rng, min_ess=0.3)
    f.update([3.0, 4.0])                                        # a sharp sensor would leave a handful
    assert 0.0 < f.status.beta < 1.0
    assert f.n_eff == pytest.approx(0.3 * 2000, rel=0.02)
    g = MCL(p, shift, XYSensor(5.0), rng=np.random.default_rng(0), min_ess=0.3)
    g.update([3.0, 4.0])                                        # a weak one is left alone
    assert g.status.beta == 1.0
    with pytest.raises(ValueError, match="min_ess"):
        MCL(p, shift, XYSensor(), rng=rng, min_ess=1.0)


def test_chunked_kld_draws_the_same_number_as_the_full_draw():
    """Chunked KLD-sampling is the same rule: the particle counts agree in distribution."""
    counts = {False: [], True: []}
    for chunked in (False, True):
        for seed in range(30):
            rng = np.random.default_rng(seed)
            p = rng.normal([5, 5, 0], [0.3, 0.3, 0.1], size=(3000, 3))
            f = MCL(p, shift, XYSensor(), rng=rng, kld=KLDSampling(n_min=100, n_max=50_000, chunked=chunked))
            f.resample()
            counts[chunked].append(f.n)
    a, b = np.mean(counts[False]), np.mean(counts[True])
    sd = np.std(counts[False]) / np.sqrt(30) + 1.0
    assert abs(a - b) < 4 * sd * np.sqrt(2), (a, b)
    assert max(counts[True]) < 50_000


def test_unknown_cells_allowed_with_a_soft_penalty():
    data = np.zeros((20, 20))
    data[:, 10:] = np.nan                                       # the right half of the map is unknown
    from localize.grid import OccupancyGrid

    g = OccupancyGrid(data, 0.5)
    p = np.array([[2.0, 5.0, 0.0], [7.0, 5.0, 0.0]])           # one in free space, one in unknown space

    class Flat:
        def log_likelihood(self, poses, *z):
            return np.zeros(len(poses))

    strict = MCL(p, shift, Flat(), rng=np.random.default_rng(0), grid=g, free_space_only=True)
    strict.update()
    assert strict.weights[1] == 0.0
    soft = MCL(p, shift, Flat(), rng=np.random.default_rng(0), grid=g, free_space_only=True, unknown_allowed=True,
               unknown_penalty=1.0)
    soft.update()
    assert soft.weights[1] / soft.weights[0] == pytest.approx(np.exp(-1.0))


def test_global_localization_and_injection_draw_in_the_maps_holes_only_when_unknown_cells_are_allowed():
    from localize.grid import OccupancyGrid

    data = np.zeros((20, 20))
    data[[0, -1], :] = data[:, [0, -1]] = 1.0                     # a walled room ...
    data[8:12, 8:12] = np.nan                                   # ... whose floor has an unknown patch
    g = OccupancyGrid(data, 0.5)
    n = 20_000

    class Flat:
        def log_likelihood(self, poses, *z):
            return np.zeros(len(poses))

    def share_in_holes(poses):
        c = g.world_to_cell(poses)
        assert not np.any(g.occupied[c[:, 0], c[:, 1]])
        return float(g.holes[c[:, 0], c[:, 1]].mean())

    share = 16 / (16 + g.free.sum())                            # the patch's share of the floor, cell for cell
    tol = 5 * np.sqrt(share * (1 - share) / n)
    allowed = MCL.uniform(g, n, shift, Flat(), rng=np.random.default_rng(0), free_space_only=True,
                          unknown_allowed=True)
    assert abs(share_in_holes(allowed.particles) - share) < tol
    assert abs(share_in_holes(allowed.sampler(n, np.random.default_rng(1))) - share) < tol   # injection, restarts
    strict = MCL.uniform(g, n, shift, Flat(), rng=np.random.default_rng(0), free_space_only=True)
    assert share_in_holes(strict.particles) == 0.0 and share_in_holes(strict.sampler(n, np.random.default_rng(1))) == 0.0
    assert abs(share_in_holes(uniform_particles(g, n, np.random.default_rng(2), holes=True)) - share) < tol


def test_run_filter_rejects_an_impossible_odometry_step_and_reports_it():
    from localize.mcl import OdometryMotion
    from localize.runloop import run_filter

    g = office()
    rng = np.random.default_rng(0)
    f = MCL.gaussian([5.0, 5.5, 0.0], (0.05, 0.05, 0.02), 200, OdometryMotion((0.0,) * 4), XYSensor(), rng=rng,
                     grid=g)
    odo = np.zeros((4, 3))
    odo[:, 0] = [0.0, 0.1, 1e15, 0.3]
    tr = run_filter(f, 4, lambda k: (odo[k - 1], odo[k]), lambda k: None)
    assert [k for k, t in tr.events if "impossible" in t] == [2, 3]
    assert np.all(np.abs(tr.poses[:, 0] - 5.0) < 0.5)           # the particles stayed in the building


def test_run_filter_state_without_a_scan_fit():
    """A non-range sensor (no scan to fit): the state follows cluster share and spread alone."""
    from localize.policies import StateRules
    from localize.runloop import run_filter

    p, rng = _line(3000)
    f = MCL(p, shift, XYSensor(0.2), rng=rng)
    tr = run_filter(f, 8, lambda k: None, lambda k: ([5.0, 5.0],), rules=StateRules(hold=2))
    assert list(tr.state[:1]) == ["searching"] and tr.state[-1] == "localized"
    assert tr.first_localized() is not None and tr.lost_intervals() == []
    assert tr.state_summary()["final_state"] == "localized"
    with pytest.raises(ValueError, match="min_share"):
        StateRules(min_share=0.0)


def test_update_with_a_non_uniform_prior_is_bayes_rule():
    # prior N(2, 1) carried by the log-weights of evenly spaced particles, a GPS reading z = 3 with 0.5 m noise:
    # the posterior is N(2.8, 0.2) (product of Gaussians); the weights are prior x likelihood, normalised
    class GPS:
        def log_likelihood(self, poses, z):
            return -0.5 * ((poses[:, 0] - z) / 0.5) ** 2

    x = np.linspace(-4.0, 8.0, 20_001)
    particles = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    prior = -0.5 * (x - 2.0) ** 2
    f = MCL(particles, lambda p, u, rng: p, GPS(), rng=np.random.default_rng(3), log_weights=prior,
            resample_threshold=0.0)
    f.update(3.0)
    expected = np.exp(prior - 0.5 * ((x - 3.0) / 0.5) ** 2)
    np.testing.assert_allclose(f.weights, expected / expected.sum(), rtol=1e-9, atol=1e-300)
    e = f.estimate()
    assert e.mean[0] == pytest.approx(2.8, abs=1e-6) and e.std[0] == pytest.approx(np.sqrt(0.2), abs=1e-6)
    # resampling keeps that posterior: the mean of N equally weighted copies is within 4 standard errors
    f.resample()
    n = f.n
    assert abs(f.particles[:, 0].mean() - 2.8) < 4 * np.sqrt(0.2 / n) + (x[1] - x[0])


# ----------------------------------------------------------------- beams that end where the map says nothing
def _office_with_unknown_east(x_from: float = 6.5):
    """The office map with every cell east of ``x_from`` metres unknown."""
    from localize.grid import OccupancyGrid

    g = office()
    data = np.array(g.data, copy=True)
    cols = np.arange(data.shape[1]) * g.resolution + g.origin[0] + g.resolution / 2
    data[:, cols > x_from] = np.nan
    return OccupancyGrid(data, g.resolution, origin=g.origin)


class _RecordingField:
    """A likelihood field that remembers the ranges of every update it scores."""

    def __init__(self, grid):
        from localize.sensors import LikelihoodField

        self.inner = LikelihoodField(grid, 8.0, sigma_hit=0.2)
        self.sensor_offset, self.min_range, self.max_range = self.inner.sensor_offset, 0.0, 8.0
        self.sigma_hit = 0.2
        self.seen = []

    def log_likelihood(self, poses, ranges, angles):
        self.seen.append(np.array(ranges, dtype=float))
        return self.inner.log_likelihood(poses, ranges, angles)


def _skip_beams(grid, f, offset, z, max_range, **kw):
    """The beams the map cannot explain at the cloud's mean pose (what the beam-mask policy asks)."""
    from localize.evidence import unexplained_beams
    from localize.geometry import mean_pose

    return unexplained_beams(grid, mean_pose(f.particles, f.weights), offset, z, max_range, **kw)


def test_skip_unknown_beams_leaves_out_exactly_the_beams_that_end_in_unknown_cells():

    g = _office_with_unknown_east(6.5)
    f = MCL.gaussian([5.0, 5.5, 0.0], (1e-6, 1e-6, 1e-6), 50, (0.0,) * 4, XYSensor(), rng=np.random.default_rng(0))
    angles = np.array([0.0, np.pi, np.pi / 2, 0.0, 0.0])
    ranges = np.array([2.5, 2.5, 0.5, 8.0, 1.0])      # east into unknown, west, north, no return, east but short
    z, n, n_short = _skip_beams(g, f, np.zeros(3), (ranges, angles), 8.0)
    assert (n, n_short) == (1, 0)
    np.testing.assert_array_equal(z[0], [8.0, 2.5, 0.5, 8.0, 1.0])
    np.testing.assert_array_equal(z[1], angles)
    assert ranges[0] == 2.5                           # the caller's scan is not changed


def test_skip_short_beams_leaves_out_the_beams_that_read_well_short_of_the_map():
    """From (5, 5.5) facing east in the office the map's walls are 5.8 m east, 4.8 m west, 0.9 m north: a
    reading 2.8 m short of the east wall is left out, one 0.1 m short (the pose's own error) is kept; when
    most of the scan reads short, nothing is left out."""
    from localize.evidence import SHORT_BEAMS_MAX_SHARE
    from localize.raycast import RayCaster

    g = office()
    caster = RayCaster(g, 8.0, method="march")
    f = MCL.gaussian([5.0, 5.5, 0.0], (1e-6, 1e-6, 1e-6), 50, (0.0,) * 4, XYSensor(), rng=np.random.default_rng(0))
    expected = caster.cast(np.array([[5.0, 5.5, 0.0]]), np.array([0.0, np.pi, np.pi / 2]))[0]
    np.testing.assert_allclose(expected, [5.8, 4.8, 0.9], atol=0.06)
    angles = np.array([0.0, 0.0, np.pi, np.pi / 2, 0.0])
    ranges = np.array([5.7, 3.0, 4.8, 0.9, 8.0])      # east (a little short), east (2.8 m short), west, north, none
    z, n, n_short = _skip_beams(g, f, np.zeros(3), (ranges, angles), 8.0, caster=caster, short=1.0)
    assert (n, n_short) == (0, 1)
    np.testing.assert_array_equal(z[0], [5.7, 8.0, 4.8, 0.9, 8.0])
    assert ranges[1] == 3.0                           # the caller's scan is not changed
    z, n, n_short = _skip_beams(g, f, np.zeros(3), (ranges, angles), 8.0, caster=caster, short=3.0)
    assert n_short == 0                               # 2.8 m short is within a 3 m margin
    # three of the four valid beams read short: the place is more likely wrong than cluttered
    most = np.array([3.0, 3.0, 2.0, 0.9, 8.0])
    assert 3 > SHORT_BEAMS_MAX_SHARE * 4
    z, n, n_short = _skip_beams(g, f, np.zeros(3), (most, angles), 8.0, caster=caster, short=1.0)
    assert n_short == 0 and np.array_equal(z[0], most)


def test_the_probe_counts_the_beams_the_sensor_scored():
    """The probe's contrast is per beam the sensor model scored: a 361-beam scan read by a model that thins
    it to 31 beams, and a scan whose beams were left out of the update (set to the maximum range), are
    judged as the beams that were scored -- dividing by every valid reading made the contrast 12x (or 2x)
    too small, so a pose the scan pins would never be called localized."""
    from localize.evidence import pinned as _pinned
    from localize.raycast import RayCaster
    from localize.sensors import LikelihoodField, select_beams

    g = office()
    pose = np.array([5.0, 5.5, 0.3])
    angles = np.radians(np.linspace(-90, 90, 361))
    ranges = RayCaster(g, 8.0, method="exact").cast(pose[None, :], angles)[0]
    sel = select_beams(361, 31)
    plain = LikelihoodField(g, 8.0, sigma_hit=0.2)
    thinning = LikelihoodField(g, 8.0, sigma_hit=0.2, max_beams=31)
    shift = 1.0
    d = np.array([[shift, 0.0], [-shift, 0.0], [0.0, shift], [0.0, -shift]])
    probes = np.tile(pose, (5, 1))
    probes[1:, 0] += np.cos(pose[2]) * d[:, 0] - np.sin(pose[2]) * d[:, 1]
    probes[1:, 1] += np.sin(pose[2]) * d[:, 0] + np.cos(pose[2]) * d[:, 1]

    def contrast(sensor, r, a):
        ll = sensor.log_likelihood(probes, r, a)
        n = int(np.sum(r[select_beams(r.size, sensor.max_beams)] < 8.0))
        return (ll[0] - ll[1:].max()) / n

    c = contrast(plain, ranges[sel], angles[sel])
    assert c > 0.05                                   # the office pins this pose
    assert contrast(thinning, ranges, angles) == pytest.approx(c)
    for factor, pinned in ((0.8, True), (1.25, False)):
        assert _pinned(plain, pose, (ranges[sel], angles[sel]), shift, factor * c, 0.0, 8.0) is pinned
        assert _pinned(thinning, pose, (ranges, angles), shift, factor * c, 0.0, 8.0) is pinned
    # every other beam left out of the update: the contrast of the beams that were scored
    half = ranges[sel].copy()
    half[1::2] = 8.0
    c_half = contrast(plain, half, angles[sel])
    assert c_half == pytest.approx(contrast(plain, ranges[sel][::2], angles[sel][::2]))
    assert _pinned(plain, pose, (half, angles[sel]), shift, 0.8 * c_half, 0.0, 8.0)
    assert not _pinned(plain, pose, (half, angles[sel]), shift, 1.25 * c_half, 0.0, 8.0)


def _corridor(panel_at: float | None = None):
    """A corridor 20 m long and 4 m wide (x 0..20, y -2..2), closed at both ends; with ``panel_at``, a panel
    across it at that x (something the map does not show)."""
    from localize.grid import OccupancyGrid

    data = np.zeros((40, 220))
    data[0, :] = data[-1, :] = 1.0
    data[:, 0] = data[:, 200:] = 1.0
    if panel_at is not None:
        data[:, int(round(panel_at / 0.1))] = 1.0
    return OccupancyGrid(data, 0.1, origin=(0.0, -2.0))


def test_run_filter_skip_short_beams_keeps_an_agreed_cloud_that_unmapped_clutter_would_pull_away():
    """A robot at x = 10 m of a corridor faces a panel at x = 18 m that the map does not show. Scored, the
    beams on it fit a few particles 2 m further on (where they would end on the mapped end wall) perfectly,
    and those take all the weight at once; left out as reading 2 m short of the map at the agreed place,
    the cloud stays with the robot."""
    from localize.policies import StateRules
    from localize.raycast import RayCaster
    from localize.runloop import run_filter
    from localize.sensors import LikelihoodField

    g = _corridor()
    angles = np.radians(np.arange(-90, 91, 10.0))
    scan = RayCaster(_corridor(18.0), 15.0, method="exact").cast(np.array([[10.0, 0.0, 0.0]]), angles)[0]
    ahead = np.abs(angles) < np.radians(15)
    np.testing.assert_allclose(scan[ahead], 8.0, atol=0.15)               # the panel, not the wall at 10 m
    sides = (np.where(np.abs(angles) > np.radians(30), scan, 15.0), angles)   # first: the side walls only
    rules = StateRules(hold=1, min_fit=0.0, restart_fit=0.0, probe_shift=0.0, min_beams=1)
    scans = [sides] + [(scan, angles)] * 4
    out = {}
    for short in (1.0, 0.0):
        rng = np.random.default_rng(3)
        f = MCL.gaussian([10.0, 0.0, 0.0], (0.03, 0.03, 0.01), 300, (0.0,) * 4,
                         LikelihoodField(g, 15.0, sigma_hit=0.2), rng=rng)
        stray = np.column_stack([rng.normal(12.0, 0.03, 10), rng.normal(0.0, 0.03, 10), np.zeros(10)])
        f.particles = np.vstack([f.particles, stray])
        f.log_weights = np.full(310, -np.log(310))
        out[short] = run_filter(f, 5, lambda k: None, lambda k: scans[k], grid=g, rules=rules,
                                skip_short_beams=short)
    kept, pulled = out[1.0], out[0.0]
    assert np.all(np.abs(kept.poses[:, 0] - 10.0) < 0.2)
    assert any(f"{3 * 4} beams that read more than 1 m shorter" in t for _, t in kept.events)
    assert np.all(np.abs(pulled.poses[1:, 0] - 12.0) < 0.1)           # the look-alike took it at the first scan
    assert not any("shorter" in t for _, t in pulled.events)
    with pytest.raises(ValueError, match="skip_short_beams must be a length in metres"):
        run_filter(MCL.gaussian([10.0, 0.0, 0.0], (0.03,) * 3, 10, (0.0,) * 4, XYSensor(), rng=np.random.default_rng(0)), 1, lambda k: None,
                   lambda k: None, skip_short_beams=-1.0)


def test_run_filter_skips_unknown_beams_only_once_the_cloud_agrees():
    from localize.policies import StateRules
    from localize.runloop import run_filter

    g = _office_with_unknown_east(6.5)
    angles = np.array([0.0, 0.1, -0.1])
    scan = (np.full(3, 2.5), angles)                  # from (5, 5.5) heading east every end point is unknown
    # the first scan looks west, at mapped walls: the map can judge it, so the filter may call itself localized
    # (an unjudged fit never makes a state localized); the later ones look east
    scans = [(np.full(3, 2.5), angles + np.pi)] + [scan] * 3
    rules = StateRules(hold=1, min_fit=0.0, restart_fit=0.0, probe_shift=0.0, min_beams=1)
    runs = {}
    for skip in (True, False):
        sensor = _RecordingField(g)
        f = MCL.gaussian([5.0, 5.5, 0.0], (0.02, 0.02, 0.01), 300, (0.0,) * 4, sensor, rng=np.random.default_rng(1))
        tr = run_filter(f, 4, lambda k: None, lambda k: scans[k], grid=g, rules=rules, skip_unknown_beams=skip)
        runs[skip] = (tr, sensor.seen)
    tr, seen = runs[True]
    assert str(tr.state[0]) == "localized"
    # step 0: the cloud has not agreed yet (no previous step), so the scan is scored; after that it agrees
    # and every beam ends in unknown there: the scans are not used, and the trace says so
    assert list(tr.updated) == [True, False, False, False]
    assert len(seen) == 1 and np.all(seen[0] == 2.5)
    assert any("left out" in t and "3 scans had no other valid beam" in t for _, t in tr.events)
    tr_all, seen_all = runs[False]
    assert tr_all.updated.all() and len(seen_all) == 4
    assert not any("left out" in t for _, t in tr_all.events)


def test_a_fit_the_map_cannot_judge_never_makes_the_state_localized():
    """A tight cloud whose every beam ends in the map's unknown cells has no evidence that the scans fit:
    it stays searching however long it agrees with itself; once a judged scan has made it localized, the
    unjudged ones that follow do not take that away."""
    from localize.policies import StateRules
    from localize.runloop import run_filter

    g = _office_with_unknown_east(6.5)
    angles = np.array([0.0, 0.1, -0.1])
    east = (np.full(3, 2.5), angles)                   # from (5, 5.5): every end point in unknown cells
    west = (np.full(3, 2.5), angles + np.pi)           # towards mapped walls: the map can judge it
    rules = StateRules(hold=1, min_fit=0.0, restart_fit=0.0, probe_shift=0.0, min_beams=1)

    def run(scans):
        f = MCL.gaussian([5.0, 5.5, 0.0], (0.02, 0.02, 0.01), 300, (0.0,) * 4, _RecordingField(g),
                         rng=np.random.default_rng(1))
        return run_filter(f, len(scans), lambda k: None, lambda k: scans[k], grid=g, rules=rules)

    blind = run([east] * 6)
    assert np.all(np.isnan(blind.fit)) and np.all(blind.best_weight > 0.9)   # agreed, but never judged
    assert list(blind.state) == ["searching"] * 6 and blind.first_localized() is None
    seen = run([west] + [east] * 5)
    assert np.isfinite(seen.fit[0]) and np.all(np.isnan(seen.fit[1:]))
    assert list(seen.state) == ["localized"] * 6


class _Flat:
    """A sensor model that scores every pose alike: the state then follows the cloud's shape and the fit."""

    sensor_offset, min_range, max_range, sigma_hit, z_hit = np.zeros(3), 0.0, 8.0, 0.2, 0.9

    def log_likelihood(self, poses, ranges, angles):
        return np.zeros(len(poses))


def test_a_lost_filter_is_not_localized_again_on_the_fits_of_the_place_it_lost():
    """Fits judged while localized vouch for that place only. The cloud scatters (lost), gathers again
    where every beam ends in the map's unknown cells (no fit can be judged): it stays lost until a scan
    the map can judge fits, though the fits before the loss were good."""
    from localize.policies import StateRules
    from localize.runloop import run_filter

    g = _office_with_unknown_east(6.5)
    angles = np.array([0.0, 0.1, -0.1])
    east = (np.full(3, 2.5), angles)                   # from (5, 5.5): every end point in unknown cells
    west = (np.full(3, 2.5), angles + np.pi)           # towards mapped walls: the map can judge it
    home = np.array([5.0, 5.5, 0.0])
    tight = np.array([0.02, 0.02, 0.01])

    def motion(p, u, rng):
        if u == "scatter":                             # metres apart: no longer one place
            return p + rng.normal(0.0, 1.0, p.shape) * np.array([2.0, 2.0, 1.0])
        if u == "gather":                              # one tight cloud again
            return home + rng.normal(0.0, 1.0, p.shape) * tight
        return p

    rng = np.random.default_rng(4)
    rules = StateRules(hold=1, hold_lost=1, min_fit=0.0, restart_fit=0.0, probe_shift=0.0, min_beams=1)
    plan = [(None, west), ("scatter", east), ("gather", east), (None, east), (None, east), (None, west)]
    f = MCL(home + rng.normal(0.0, 1.0, (300, 3)) * tight, motion, _Flat(), rng=rng)
    tr = run_filter(f, len(plan), lambda k: plan[k][0], lambda k: plan[k][1], grid=g, rules=rules)
    assert np.isfinite(tr.fit[0]) and np.all(np.isnan(tr.fit[2:5])) and np.isfinite(tr.fit[5])
    assert tr.spread[1] > 2 * rules.max_spread and np.all(tr.spread[2:] < 0.1)   # scattered, then one place
    assert list(tr.state) == ["localized", "lost", "lost", "lost", "lost", "localized"]


def test_run_filter_scores_every_beam_while_searching():
    """With a uniform cloud nothing has been agreed: skip_unknown_beams changes nothing at all."""
    from localize.runloop import run_filter

    g = _office_with_unknown_east(6.5)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 9)
    scan = (np.full(9, 2.0), angles)
    out = []
    for skip in (True, False):
        sensor = _RecordingField(g)
        f = MCL.uniform(g, 2000, (0.0,) * 4, sensor, rng=np.random.default_rng(2), free_space_only=True)
        tr = run_filter(f, 2, lambda k: None, lambda k: scan, grid=g, skip_unknown_beams=skip)
        out.append((tr.poses, sensor.seen))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert all(np.all(s == 2.0) for s in out[0][1])


# --------------------------------------------------- restarts on probation (run_filter's restart_after)
class _Prefers:
    """A sensor model that scores a pose by its distance to one place, whatever the scan says.

    It stands for a likelihood that favours a look-alike (a likelihood field scores beams that end in a
    map's unknown cells neutrally, so a wrong place where most beams do can outscore the right one):
    only the ray-cast fit can tell which place the scans belong to.
    """

    sensor_offset, min_range, max_range, sigma_hit, z_hit = np.zeros(3), 0.0, 8.0, 0.2, 0.9

    def __init__(self, place):
        self.place = np.asarray(place, dtype=float)

    def log_likelihood(self, poses, ranges, angles):
        d = poses[:, :2] - self.place[:2]
        dth = np.angle(np.exp(1j * (poses[:, 2] - self.place[2])))
        return -0.5 * np.sum(d * d, axis=1) / 0.5**2 - 0.5 * (dth / 0.3) ** 2


_HERE, _THERE = np.array([3.0, 3.0, 0.0]), np.array([15.0, 8.0, 0.0])   # free poses 13 m apart in the office


def _restart_run(start, prefers, clutter, sampler=None, n_steps=45):
    """A stationary robot at _HERE: ``clutter`` scans that fit nowhere (every beam 0.3 m), then true scans."""
    from localize.raycast import RayCaster
    from localize.runloop import run_filter

    g = office()
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    true_scan = RayCaster(g, 8.0).cast(_HERE[None], angles)[0]
    sampler = sampler or (lambda n, rng: uniform_particles(g, n, rng))
    f = MCL.gaussian(start, np.diag([0.02, 0.02, 0.01]) ** 2, 2000, (0.0,) * 4, _Prefers(prefers),
                     rng=np.random.default_rng(3), sampler=sampler)
    return run_filter(f, n_steps, lambda k: None, lambda k: (np.full(36, 0.3) if k < clutter else true_scan, angles),
                      grid=g, restart_after=3)


def test_a_restart_keeps_the_right_place_when_a_look_alike_only_wins_the_likelihood():
    tr = _restart_run(_HERE, _THERE, clutter=8)
    restarts = [k for k, t in tr.events if "global localization again" in t]
    ends = [(k, t) for k, t in tr.events if " won (" in t]
    assert restarts == [2]                          # three cluttered scans that do not fit: a restart ...
    # ... the fresh particles find _THERE, which takes all the weight, but the scans fit _HERE only:
    # the trial runs its full length and the old place stays
    assert len(ends) == 1 and "after 30 updates the old place won" in ends[0][1]
    assert "weight 1 of the new" in ends[0][1]
    err = np.hypot(*(tr.poses[:, :2] - _HERE[:2]).T)
    assert err.max() < 0.2                          # the estimate never jumps to the look-alike
    # while on probation the shown place holds almost none of the weight: the state does not pretend
    assert np.all(tr.best_weight[3:32] < 1e-3)
    assert not np.any(tr.state[3:32] == "localized")


def test_a_restart_replaces_a_wrong_place_that_loses_both_likelihood_and_fit():
    def room(n, rng):                               # global localization over the robot's room
        return np.column_stack([rng.uniform(1, 6, n), rng.uniform(1, 5, n), rng.uniform(-np.pi, np.pi, n)])

    tr = _restart_run(_THERE, _HERE, clutter=0, sampler=room)
    ends = [t for _, t in tr.events if " won (" in t]
    assert [k for k, t in tr.events if "global localization again" in t] == [2]
    # the old cloud's share falls below 1e-4 within the first updates and the fit agrees: decided early
    assert len(ends) == 1 and "after 3 updates the particles drawn over the map won" in ends[0]
    err = np.hypot(*(tr.poses[:, :2] - _HERE[:2]).T)
    assert err[0] > 10 and np.all(err[6:] < 0.3)


def test_a_probation_survives_a_cloud_with_no_weight_left():
    """A group whose every particle got zero likelihood is dropped, not turned into NaN weights."""
    from localize.policies import Context, Probation, StateRules

    f = MCL.gaussian([3.0, 3.0, 0.0], np.eye(3) * 1e-4, 10, (0.0,) * 4, XYSensor(), rng=np.random.default_rng(0))
    f.particles = np.vstack([f.particles, f.particles + [1.0, 0.0, 0.0]])
    f.log_weights = np.concatenate([np.full(10, -np.inf), np.full(10, -np.log(10))])
    trial = Probation(10, _HERE, 0.0, 5)
    trial.updates, trial.fits = 1, [[0.9], [0.1]]
    ctx = Context(StateRules())
    assert trial.resample(f, 7, 0.0, ctx) is False                 # decided
    events = ctx.events
    assert f.n == 10 and np.all(np.isfinite(f.log_weights)) and np.allclose(f.particles[:, 0], 4.0, atol=0.1)
    assert "particles drawn over the map won" in events[0][1]


def test_a_probation_favours_a_new_place_only_on_enough_evidence():
    """One or two scans are no evidence: early in a probation a fresh cloud that outweighs and outfits the old
    place is not yet shown (the estimate would jump to a random pile of the new particles and back); nor is
    one whose fit, though better than the old place's, is too poor to be the robot's place either."""
    from localize.policies import PROBATION, Probation

    def _trial_favours(trial, shares):
        p = Probation(1, _HERE, trial["min_fit"], 5)
        p.fits = trial["fits"]
        return p.favours(shares)

    shares = np.log([0.1, 0.9])                     # the fresh cloud holds most of the weight ...
    for n in range(1, PROBATION[0] + 2):
        trial = {"fits": [[0.2] * n, [0.8] * n], "min_fit": 0.4}   # ... and fits better at every scan so far
        assert _trial_favours(trial, shares) == int(n >= PROBATION[0])
    trial = {"fits": [[0.2] * 5, [0.8] * 5], "min_fit": 0.4}
    assert _trial_favours(trial, np.log([0.9, 0.1])) == 0            # the weight decides too
    # better than a poorly fitting old place is not enough: the new place must fit the scans acceptably
    assert _trial_favours({"fits": [[0.1] * 5, [0.3] * 5], "min_fit": 0.4}, shares) == 0
    assert _trial_favours({"fits": [[0.1] * 5, [0.5] * 5], "min_fit": 0.4}, shares) == 1
    assert _trial_favours({"fits": [[0.2], [0.8]], "min_fit": 0.4}, np.array([-np.inf, 0.0])) == 1  # no weight left


class _Fades(_Prefers):
    """Prefers one place for the first ``until`` updates, then says nothing about any pose (a flat likelihood)."""

    def __init__(self, place, until):
        super().__init__(place)
        self.until, self.calls = until, 0

    def log_likelihood(self, poses, ranges, angles):
        self.calls += 1
        ll = super().log_likelihood(poses, ranges, angles)
        return ll if self.calls <= self.until else np.zeros(len(poses))


def test_a_filter_lost_for_restart_after_updates_searches_the_map_again():
    """Lost without agreeing on a wrong place (the cloud spread out, the robot carried away): after restart_after
    more updates whose scans do not fit the best place, global localization starts again on probation."""
    from localize.policies import StateRules
    from localize.raycast import RayCaster
    from localize.runloop import run_filter

    g = office()
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    here, there = (RayCaster(g, 8.0).cast(p[None], angles)[0] for p in (_HERE, _THERE))

    def motion(p, u, rng):                          # from step 10 on the odometry says nothing useful
        return p + rng.normal(0.0, 1.0, p.shape) * [0.3, 0.3, 0.1]

    def run(restart_after, kidnapped=True):
        f = MCL.gaussian(_HERE, np.diag([0.02, 0.02, 0.01]) ** 2, 2000, motion, _Fades(_HERE, 10),
                         rng=np.random.default_rng(5), sampler=lambda n, rng: uniform_particles(g, n, rng))
        return run_filter(f, 60, lambda k: "drift" if k >= 10 else None,
                          lambda k: (there if kidnapped and k >= 10 else here, angles), grid=g,
                          restart_after=restart_after, rules=StateRules(probe_shift=0.0))  # the double pins nothing

    tr = run(3)
    assert tr.state[9] == "localized"
    k_lost = tr.lost_intervals()[0][0]
    restarts = [(k, t) for k, t in tr.events if "global localization again" in t]
    assert restarts and restarts[0][0] == k_lost + 3 and "the filter has been lost" in restarts[0][1]
    assert np.all(tr.spread[k_lost:restarts[0][0] + 1] > 0.5)          # not agreed: the other trigger could not fire
    assert not any("global localization again" in t for _, t in run(0).events)   # 0: never
    # lost while the scans still fit where it is (the odometry only blurred the cloud): no restart
    calm = run(3, kidnapped=False)
    assert calm.lost_intervals() and not any("global localization again" in t for _, t in calm.events)
