"""benchmarks/why_wrong.py: the diagnosis of wrong claims (truth against estimate under the filter's own model)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from localize import reliability

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def ww():
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location("why_wrong", BENCH / "why_wrong.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        yield mod
    finally:
        sys.path.remove(str(BENCH))


def test_claim_classes_and_shares(ww):
    """The class follows the sign of the sum and whether the robot's place was held; the share is the two-place
    posterior of the sum; with noise, the sum counts by 2 |mean| / variance."""
    c = ww.claim(-4.0, 8, True, 2.0)                        # truth worse: class 0 whatever the bank held
    assert c["class"] == 0
    assert c["share"] == pytest.approx(1.0 / (1.0 + np.exp(-4.0)))
    assert ww.claim(4.0, 8, True, 2.0)["class"] == 1
    assert ww.claim(4.0, 8, False, 2.0)["class"] == 2
    d = np.array([2.0, -1.0, 3.0, -2.5, 1.5, 0.5])           # mean 0.583, sample variance 4.14
    c = ww.claim(float(d.sum()), d.size, False, float(np.sum(d ** 2)))
    scale = 2.0 * abs(d.mean()) / d.var(ddof=1)
    assert c["share_noise"] == pytest.approx(1.0 / (1.0 + np.exp(scale * d.sum())))
    assert c["share_noise"] > c["share"]                      # noise makes the bank less sure of the estimate's loss


def test_recorder_restores_the_state_and_refuses_nesting(ww):
    original = reliability.ReliabilityState.p_localized
    with pytest.raises(KeyError):
        with ww.Recorder(np.zeros((3, 3))):
            assert reliability.ReliabilityState.p_localized is not original
            with pytest.raises(RuntimeError, match="already recording"):
                ww.Recorder(np.zeros((3, 3))).__enter__()
            raise KeyError("a run that fails")
    assert reliability.ReliabilityState.p_localized is original


def test_a_short_run_is_recorded_scan_by_scan(ww):
    """A real (short) run of bench_state.py's: every scan the filter used adds to the sum since the place, and the
    state's methods are its own again afterwards."""
    job = {"kind": "boxes", "laser": "sick-180", "seed": 0, "state": "probability", "scans": 12, "args": []}
    grid, log = ww.bs.prepare(job)
    from localize import pipeline, settings
    s = settings.parse_options(["--state", "probability", "--particles", "3000"])
    with ww.Recorder(log.poses) as rec:
        res = pipeline.localize_log(grid, log, rng=np.random.default_rng(0), settings=s)
    assert reliability.ReliabilityState.p_localized is ww._ORIG[0]
    assert sorted(rec.rows) == list(range(len(log)))
    counts = [rec.rows[k][1] for k in sorted(rec.rows)]
    assert counts[-1] >= 1 and all(np.isfinite(rec.rows[k][0]) for k in rec.rows)
    e = np.hypot(*(res.estimates[:, :2] - log.poses[:, :2]).T)
    claims = ww.classify(rec.rows, e, np.asarray(res.state), off=0.0)     # every localized scan counts here
    assert len(claims) == int(np.sum(np.asarray(res.state) == "localized"))
    assert all(c["class"] in (0, 1, 2) for c in claims)
