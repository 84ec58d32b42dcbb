"""The pose covariance of the estimate (localize.estimate): symmetric, positive semi-definite, and the
particles' own covariance within sampling error."""

import numpy as np

from localize.estimate import estimate_pose
from localize.mcl import gaussian_particles


def test_cluster_covariance_is_the_particles_covariance_within_sampling_error():
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.005], [0.0, 0.005, 0.01]])
    n = 20_000
    p = gaussian_particles([2.0, 3.0, 0.5], cov, n, np.random.default_rng(0))
    e = estimate_pose(p)
    c = e.cluster_cov
    assert c.shape == (3, 3) and np.allclose(c, c.T)
    assert np.linalg.eigvalsh(c).min() >= 0.0
    # standard error of a sample covariance entry: sqrt((s_ii s_jj + s_ij^2) / n); 5 of them
    se = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov ** 2) / n)
    assert np.all(np.abs(c - cov) < 5 * se)
    # a wrong formula (standard deviations instead of variances) would be far outside
    assert not np.all(np.abs(np.sqrt(np.abs(c)) - cov) < 5 * se)


def test_cluster_covariance_is_that_of_the_best_cluster_alone():
    rng = np.random.default_rng(1)
    a = gaussian_particles([2.0, 2.0, 0.0], (0.1, 0.1, 0.05), 3000, rng)
    b = gaussian_particles([12.0, 7.0, 1.0], (0.1, 0.1, 0.05), 1000, rng)
    e = estimate_pose(np.vstack([a, b]))
    assert e.n_clusters == 2 and 0.6 < e.best_weight <= 0.75        # the clusters hold 90% of the weight
    assert np.all(np.diag(e.cluster_cov)[:2] < 0.02)          # 0.1 m spread: 0.01 m^2, not the 10 m between modes
    assert e.cov[0, 0] > 10.0
    np.testing.assert_allclose(np.sqrt(np.diag(e.cluster_cov)), e.cluster_std, rtol=0.2)
