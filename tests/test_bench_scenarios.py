"""benchmarks/bench_scenarios.py: the scenarios' checks counted over many seeds agree with the tests' own checks."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scenarios as S

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(BENCH))
    try:
        import bench_scenarios
    finally:
        sys.path.remove(str(BENCH))
    return bench_scenarios


@pytest.fixture(scope="module")
def kidnapped():
    sc = S.kidnapping(90)
    return sc, S.run(sc, 0, state="probability")


def test_an_honest_run_passes_and_each_lie_is_counted(bench, kidnapped):
    """The kidnapping's seed 0 (which its test passes) passes here too; doctored copies of its trace (always
    localized, localized three scans too long, lost after scan 100, a probability of 0.9 everywhere) each break the
    one rule they lie about, by the number of scans they lie at."""
    sc, tr = kidnapped
    err = S.position_errors(sc, tr)
    state = np.asarray(tr.state).astype(str)
    row = bench.judge(sc, tr, "both")
    assert row["passes"] and row["loc_off"] == 0 and row["near"] >= 20, row

    def fake(st=state, p=None):
        return SimpleNamespace(state=st, poses=tr.poses, p_localized=tr.p_localized if p is None else p,
                               events=tr.events)

    excused = bench.T.excused(sc)
    always = bench.judge(sc, fake(np.full(err.size, "localized")), "both")
    assert not always["passes"] and always["loc_off"] == int(np.sum((err > 1.0) & ~excused))
    slow = state.copy()
    slow[90:93] = "localized"                        # noticed three scans late: excused within the grace ...
    assert bench.judge(sc, fake(slow), "both")["loc_off"] == 0
    late = bench.judge(sc, fake(slow), None)         # ... and counted without it
    assert late["loc_off"] == int(np.sum(err[90:93] > 1.0)) > 0 and not late["passes"]
    lost_after = np.where(np.arange(err.size) >= 100, "lost", state)
    lost = bench.judge(sc, fake(lost_after), "both", survives=True)
    assert lost["lost_near"] == int(np.sum((lost_after == "lost") & (err <= 0.3))) > 0 and not lost["passes"]
    assert bench.judge(sc, fake(lost_after), "both", survives=False)["lost_near"] == 0
    sure = bench.judge(sc, fake(p=np.full(err.size, 0.9)), "both")
    assert sure["p_high_off"] == int(np.sum((err > 1.0) & ~excused)) > 0 and not sure["passes"]


def test_the_summary_names_the_failing_seeds(bench):
    rows = [{"case": "kidnapping", "seed": s, "passes": s != 3, "loc": 100, "loc_off": 2 * (s == 3), "p_high_off": 0,
             "near": 50, "near_loc": 49, "lost_near": 0, "restarts_right": 0} for s in range(4)]
    (line,) = bench.summarize(rows)
    assert line["runs"] == 4 and line["pass"] == 3 and line["failing seeds"] == "3"
    assert line["localized > 1 m off"] == "2 of 400" and line["scans within 0.3 m localized"] == "98.0%"
