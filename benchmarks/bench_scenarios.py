"""The state's acceptance scenarios on many seeds: how often each of ``tests/test_state_scenarios.py``'s checks fails.

    nice python benchmarks/bench_scenarios.py --write        # the reported table (~ 6 min on 2 cores)
    nice python benchmarks/bench_scenarios.py --seeds 4      # a quick subset

``tests/test_state_scenarios.py`` localizes each simulated fault of
``tests/scenarios.py`` (a dead laser, a corrupt or missing odometry record,
a kidnapping, a moved obstacle, a person in front of the laser, ...) with two
seeds of the filter, and asserts that no scan breaks the state's rules: never
*localized* more than 1 m off, *localized* at most scans within 0.3 m, never
*lost* within 0.3 m where a right estimate survives the fault, ``p_localized``
below the *lost* threshold wherever the estimate is more than 1 m off. Two
seeds can pass by luck. This benchmark runs every scenario with ``--seeds``
seeds of the filter (the same simulated log, another random stream; seeds 0
and 1 are the tests' own) and counts, per scenario, the runs that pass those
shared checks (``honest_run``'s, with the same excused scans and thresholds,
taken from the test module itself) and the scans that break each rule.

The scenario-specific assertions of the tests (a kidnapping noticed within
three scans, a run that ends localized, ...) are not counted here; the table
adds the restarts of global localization (``--restart-after``'s) made while the
estimate was within 0.3 m of the robot at the scan before: a right estimate
thrown away.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import bench_global as bg  # noqa: E402
import scenarios as S  # noqa: E402
import test_state_scenarios as T  # noqa: E402
from _util import run_jobs, table  # noqa: E402

from localize.reliability import LOST_BELOW  # noqa: E402

#: name -> (scenario, settings changed from the defaults, fault scans excused, a right estimate survives the fault),
#: as the tests run them.
CASES = {
    "dead laser from scan 80": (lambda: S.dead_laser(0.0, from_scan=80), {}, "exclude", False),
    "corrupt odometry record": (lambda: S.corrupt_odometry(70), {}, "both", False),
    "plausible corrupt record (3 m)": (lambda: S.corrupt_odometry(70, jump=3.0), {}, "both", False),
    "kidnapping": (lambda: S.kidnapping(90), {}, "both", False),
    "kidnapping, --sensor-reset 0.1": (lambda: S.kidnapping(90), {"sensor_reset": 0.1, "restart_after": 0}, "both",
                                       False),
    "missing odometry in a turn": (S.missing_odometry_in_turn, {}, "both", False),
    "understated max range": (lambda: S.understated_max_range(2.5), {}, None, True),
    "understated max range kept (--max-range 2.5)": (lambda: S.understated_max_range(2.5), {"max_range": 2.5}, None,
                                                     True),
    "moved obstacle": (S.moved_obstacle, {}, None, True),
    "walking person": (S.walking_person, {}, None, True),
    "start in a hole of the map": (S.start_in_a_hole, {}, None, False),
}


def judge(sc: S.Scenario, tr, excusing: str | None = None, survives: bool = False) -> dict:
    """Count what the trace ``tr`` of ``sc`` breaks of the tests' shared checks (``honest_run``'s), outside the
    scans the tests excuse (``excusing``: "both" excuses the fault's scans and ``GRACE`` more from every check,
    "exclude" leaves the fault's scans out of the scans within 0.3 m, None excuses nothing); ``survives``: the
    fault is one a right estimate survives (never lost within 0.3 m). ``passes`` is whether it breaks none."""
    err = S.position_errors(sc, tr)
    state = np.asarray(tr.state).astype(str)
    p = np.asarray(tr.p_localized, dtype=float)
    excuse = T.excused(sc) if excusing == "both" else None
    exclude = T.excused(sc) if excusing == "both" else sc.fault if excusing == "exclude" else None
    judged = np.ones(err.size, dtype=bool) if excuse is None else ~excuse
    loc = (state == "localized") & judged
    far = (err > T.FAR) & judged
    never = not np.any(state == "localized")                  # the tests' judged_near asserts it was localized
    near = np.zeros(err.size, dtype=bool) if never else T.judged_near(state, err, exclude)
    row = {"loc": int(loc.sum()), "loc_off": int(np.sum(loc & far)), "p_high_off": int(np.sum(far & (p >= LOST_BELOW))),
           "near": int(near.sum()), "near_loc": int(np.sum(near & (state == "localized"))),
           "p_near": float(p[near].mean()) if near.any() else float("nan"),
           "lost_near": int(np.sum((state == "lost") & (err <= T.NEAR))) if survives else 0,
           "restarts_right": int(sum("global localization again" in text and err[max(k - 1, 0)] <= T.NEAR
                                     for k, text in tr.events)),
           "final_error": float(err[-1]), "final_state": str(state[-1])}
    row["passes"] = bool(row["loc_off"] == 0 and row["p_high_off"] == 0 and row["lost_near"] == 0
                         and row["near"] >= 20 and row["near_loc"] >= T.MIN_SHARE * row["near"]
                         and row["p_near"] >= 0.8)
    return row


def run_one(job: dict) -> dict:
    make, changes, excusing, survives = CASES[job["case"]]
    sc = make()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")             # the understated range's warning: the tests assert it
        tr = S.run(sc, job["seed"], state=T.STATE, **changes)
    return {"case": job["case"], "seed": job["seed"], "wall": time.perf_counter() - t0,
            **judge(sc, tr, excusing, survives)}


def summarize(rows: list[dict]) -> list[dict]:
    out = []
    for case in CASES:
        rs = sorted((r for r in rows if r["case"] == case), key=lambda r: r["seed"])
        if not rs:
            continue
        loc, off = sum(r["loc"] for r in rs), sum(r["loc_off"] for r in rs)
        near, near_loc = sum(r["near"] for r in rs), sum(r["near_loc"] for r in rs)
        out.append({
            "scenario": case, "runs": len(rs), "pass": sum(r["passes"] for r in rs),
            "failing seeds": " ".join(str(r["seed"]) for r in rs if not r["passes"]) or "-",
            "localized > 1 m off": f"{off} of {loc}",
            "p >= 0.7 while > 1 m off": sum(r["p_high_off"] for r in rs),
            "scans within 0.3 m localized": f"{100 * near_loc / near:.1f}%" if near else "-",
            "lost within 0.3 m": sum(r["lost_near"] for r in rs) if CASES[case][3] else "-",
            "restarts while within 0.3 m": sum(r["restarts_right"] for r in rs),
        })
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=12, help="seeds of the filter per scenario (default 12: 0-11)")
    ap.add_argument("--cases", nargs="*", default=list(CASES), help="scenarios (default: all)")
    ap.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="also write every run's row to this file (JSON lines)")
    ap.add_argument("--write", action="store_true", help="write the bench_scenarios section of RESULTS.md")
    args = ap.parse_args(argv)
    bad = [c for c in args.cases if c not in CASES]
    if bad:
        ap.error(f"--cases: unknown {', '.join(bad)}; choose from: " + "; ".join(CASES))
    if args.seeds < 1:
        ap.error(f"--seeds must be at least 1; got {args.seeds}")
    jobs = [{"case": c, "seed": s} for c in args.cases for s in range(args.seeds)]
    t0 = time.perf_counter()
    rows = run_jobs(run_one, jobs, args.workers, args.json)
    wall = time.perf_counter() - t0
    summary = summarize(rows)
    n_pass = sum(r["passes"] for r in rows)
    text = "\n".join([
        "## bench_scenarios", "",
        "The acceptance scenarios of `tests/test_state_scenarios.py` with seeds 0-"
        f"{args.seeds - 1} of the filter each (the tests run seeds 0 and 1); a run passes when it breaks none of "
        "the checks every test shares (never localized more than 1 m off, at least "
        f"{T.MIN_SHARE:.0%} of the scans within 0.3 m localized, `p_localized` below {LOST_BELOW} wherever more than "
        "1 m off and at least 0.8 on average within 0.3 m, never lost within 0.3 m where a right estimate survives "
        "the fault), outside the scans the tests excuse. "
        f"`nice python benchmarks/bench_scenarios.py --seeds {args.seeds}`; {len(rows)} runs on {args.workers} "
        f"processes in {wall / 60:.1f} min: {n_pass} pass.", "",
        table(summary, list(summary[0])) if summary else "(no runs)", ""])
    print(text)
    if args.write:
        bg.write_section(text, "bench_scenarios")
    return 0


if __name__ == "__main__":
    sys.exit(main())
