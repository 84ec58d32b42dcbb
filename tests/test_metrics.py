"""Tests of localize.metrics."""

import numpy as np
import pytest

from localize import metrics as m


def test_position_and_heading_errors():
    est = np.array([[1.0, 1.0, np.pi - 0.05], [0.0, 0.0, 0.0]])
    tru = np.array([[4.0, 5.0, -np.pi + 0.05], [0.0, 0.0, 2 * np.pi]])
    assert np.allclose(m.position_error(est, tru), [5.0, 0.0])
    assert np.allclose(m.heading_error(est, tru), [0.1, 0.0])             # wrapped, not 2 pi - 0.1
    assert np.allclose(m.heading_error(est, tru, absolute=False), [-0.1, 0.0])
    assert m.heading_error([0, 0, 3.0], [0, 0, -3.0]) == pytest.approx(2 * np.pi - 6.0)
    assert isinstance(m.position_error([0, 0, 0], [1, 0, 0]), float)
    with pytest.raises(ValueError, match="matching shapes"):
        m.position_error(np.zeros((3, 3)), np.zeros((2, 3)))


def test_rmse():
    assert m.rmse([1.0, 1.0, 1.0]) == pytest.approx(1.0)
    assert m.rmse([0.0, 2.0]) == pytest.approx(np.sqrt(2.0))
    assert np.allclose(m.rmse([[1.0, 3.0], [1.0, 3.0]], axis=0), [1.0, 3.0])
    with pytest.raises(ValueError, match="NaN"):
        m.rmse([1.0, np.nan])
    with pytest.raises(ValueError, match="empty"):
        m.rmse([])


def test_nees_of_a_consistent_filter_is_chi2_3():
    """Errors drawn from N(0, P): mean NEES is 3 within the chi-square bounds, with wrapped headings."""
    rng = np.random.default_rng(0)
    n = 2000
    A = rng.normal(size=(3, 3))
    P = A @ A.T * 0.05 + np.eye(3) * 0.01
    err = rng.multivariate_normal(np.zeros(3), P, size=n)
    truth = np.column_stack([rng.uniform(-5, 5, (n, 2)), np.full(n, np.pi - 0.01)])   # at the seam
    est = truth + err
    est[:, 2] = (est[:, 2] + np.pi) % (2 * np.pi) - np.pi
    q = m.nees(est, np.broadcast_to(P, (n, 3, 3)), truth)
    lo, hi = m.nees_bounds(3, n, 0.999)
    assert lo < q.mean() < hi
    # an overconfident filter (covariance 4x too small) is caught
    q_bad = m.nees(est, np.broadcast_to(P / 4, (n, 3, 3)), truth)
    assert q_bad.mean() > hi


def test_nees_bad_cov():
    with pytest.raises(ValueError, match="singular"):
        m.nees([0, 0, 0], np.zeros((3, 3)), [1, 0, 0])
    with pytest.raises(ValueError, match="shape"):
        m.nees([0, 0, 0], np.eye(2), [1, 0, 0])
    with pytest.raises(ValueError, match="positive definite"):
        m.nees([0, 0, 0], -np.eye(3), [1, 0, 0])


def test_nees_bounds_values_and_coverage():
    lo, hi = m.nees_bounds(2, 1, 0.95)
    assert lo == pytest.approx(0.0506356, rel=1e-5) and hi == pytest.approx(7.3777589, rel=1e-5)
    lo, hi = m.nees_bounds(3, 100)
    assert lo < 3 < hi and hi - lo < 1.0
    with pytest.raises(ValueError):
        m.nees_bounds(0, 1)
    with pytest.raises(ValueError):
        m.nees_bounds(3, 1, confidence=1.0)


def test_convergence_step():
    assert m.convergence_step([0.1, 0.1], 0.5) == 0
    assert m.convergence_step([9, 9, 0.1, 0.6, 0.1, 0.1], 0.5) == 4
    assert m.convergence_step([9, 0.1, 0.2, np.nan, 0.1], 0.5) == 4           # NaN counts as lost
    assert m.convergence_step([0.1, 0.1, 0.7], 0.5) is None
    assert m.convergence_step([0.5], 0.5) is None                             # "below" is strict
    with pytest.raises(ValueError, match="threshold"):
        m.convergence_step([0.1], 0.0)
    with pytest.raises(ValueError, match="1-D"):
        m.convergence_step([[0.1]], 1.0)


def test_failure_rate():
    assert m.failure_rate([0.1, 0.2, 0.3, 2.0], 1.0) == pytest.approx(0.25)
    assert m.failure_rate([np.nan, 0.1], 1.0) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="empty"):
        m.failure_rate([], 1.0)


def test_summary():
    truth = np.zeros((5, 3))
    est = np.array([[5, 0, 0], [0.1, 0, 1.0], [0.1, 0, 0.1], [0.1, 0, 0.1], [0, 0.1, 0.0]], float)
    s = m.summary(est, truth, threshold=0.5, heading_threshold=0.2)
    assert s["converged_at"] == 2                # step 1 has the position but not the heading
    assert s["final_position"] == pytest.approx(0.1)
    assert s["rmse_position"] == pytest.approx(np.sqrt((25 + 4 * 0.01) / 5))


# --- localized / success_rate / progress (the book's slow experiments) ---

def test_localized_needs_every_one_of_the_last_steps_and_wraps_headings():
    truth = np.zeros((6, 3))
    est = truth.copy()
    est[:, 2] = np.pi - 0.05            # heading pi - 0.05 against truth -pi + 0.05 ...
    tru = truth.copy()
    tru[:, 2] = -np.pi + 0.05           # ... is 0.1 rad off once wrapped
    assert m.localized(est, tru)
    est2 = est.copy()
    est2[-3, 0] = 0.6                   # one of the last five steps is 0.6 m off
    assert not m.localized(est2, tru)
    assert m.localized(est2, tru, last=2)


@pytest.mark.parametrize("kwargs, match", [({"last": 0}, "last"), ({"last": 7}, "last"),
                                           ({"position_tol": 0.0}, "position_tol")])
def test_localized_rejects_bad_options(kwargs, match):
    with pytest.raises(ValueError, match=match):
        m.localized(np.zeros((6, 3)), np.zeros((6, 3)), **kwargs)


def test_success_rate_counts_trials_with_and_without_a_progress_bar(capsys):
    def trial(seed):
        truth = np.zeros((5, 3))
        return truth + [0.1 * seed, 0.0, 0.0], truth        # seeds 0-4 within 0.5 m, 5-9 not

    assert m.success_rate(trial, range(10)) == 0.5
    assert m.success_rate(trial, range(10), progress_bar=True, desc="trials") == 0.5
    assert "trials" in capsys.readouterr().err               # the bar went to stderr, not stdout
    with pytest.raises(ValueError, match="seeds"):
        m.success_rate(trial, [])


def test_progress_is_transparent():
    items = [3, 1, 2]
    assert m.progress(items, enabled=False) is items
    assert list(m.progress(items, enabled=True)) == items
