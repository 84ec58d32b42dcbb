"""The probability of being localized (localize.reliability): calibrated on the map and sensor, on data it was
not calibrated on, and filtered over scans like the Bayes filter of chapter 1."""

import numpy as np
import pytest

from localize.grid import OccupancyGrid
from localize.maps import office
from localize.reliability import EvidenceModel, LocalizedBelief, calibrate, calibration_fits, reliability_table
from localize.sensors import LikelihoodField

ANGLES = np.linspace(-np.pi, np.pi, 36, endpoint=False)


@pytest.fixture(scope="module")
def model():
    return calibrate(office(), LikelihoodField(office(), 8.0, sigma_hit=0.1), ANGLES, np.random.default_rng(0))


def test_the_evidence_model_separates_right_from_wrong(model):
    assert model.p_right.sum() == pytest.approx(1.0) and model.p_wrong.sum() == pytest.approx(1.0)
    centres = 0.5 * (model.edges[:-1] + model.edges[1:])
    assert centres @ model.p_right > centres @ model.p_wrong + 0.3     # right poses fit the scans far better
    assert np.all(model.likelihood(np.nan) == 1.0)                     # no judged fit: no evidence


def test_one_scan_posterior_is_calibrated_on_scans_it_was_not_calibrated_on(model):
    """Held-out simulated scans (another seed): in every bin of p(right | fit) with at least 50 scans, the share
    of right estimates is the bin's mean probability within four standard errors of the bin's share."""
    lf = LikelihoodField(office(), 8.0, sigma_hit=0.1)
    f_right, f_wrong = calibration_fits(office(), lf, ANGLES, np.random.default_rng(1), n_poses=400)
    prior = f_right.size / (f_right.size + f_wrong.size)
    p = np.array([model.posterior(f, prior) for f in np.concatenate([f_right, f_wrong])])
    right = np.r_[np.ones(f_right.size, bool), np.zeros(f_wrong.size, bool)]
    rows = [r for r in reliability_table(p, right, n_bins=10) if r[2] >= 50]
    assert len(rows) >= 3
    for lo, hi, n, mean_p, share in rows:
        assert abs(share - mean_p) <= 4 * np.sqrt(max(mean_p * (1 - mean_p), 0.01) / n), (lo, hi, n, mean_p, share)
    # a wrong formula -- the likelihoods swapped -- is far from calibrated
    swapped = EvidenceModel(model.edges, model.p_wrong, model.p_right, model.n_wrong, model.n_right, 1.0)
    q = np.array([swapped.posterior(f, prior) for f in np.concatenate([f_right, f_wrong])])
    worst = max(abs(s - m) for _, _, n, m, s in reliability_table(q, right, n_bins=10) if n >= 50)
    assert worst > 0.5


def test_the_belief_rises_with_fitting_scans_falls_with_poor_ones_and_drifts_without_evidence(model):
    b = LocalizedBelief(model)
    assert b.p == 0.0
    ps = [b.step(0.95) for _ in range(6)]
    assert all(np.diff(ps) > 0) and ps[-1] > 0.95
    down = [b.step(0.05) for _ in range(3)]
    assert all(np.diff([ps[-1], *down]) < 0) and down[-1] < 0.1
    b = LocalizedBelief(model, prior=1.0, p_lose=0.01)
    assert b.step(np.nan) == pytest.approx(0.99)                     # only the transition: 1 - p_lose
    with pytest.raises(ValueError, match="p_lose"):
        LocalizedBelief(model, p_lose=1.5)


def test_calibration_refuses_a_map_that_cannot_judge_any_scan():
    g = office()
    blank = OccupancyGrid(np.where(g.free, 0.0, np.nan), g.resolution, origin=g.origin)
    with pytest.raises(ValueError, match="too few scans the map can judge"):
        calibrate(blank, LikelihoodField(g, 8.0, sigma_hit=0.1), ANGLES, np.random.default_rng(0), n_poses=30)
