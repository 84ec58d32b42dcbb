"""Why does the state say *localized* while the estimate is wrong? Each wrong claim, by what the scans said.

    nice python benchmarks/why_wrong.py                      # bench_state.py's draw, seeds 0-3 (~ 6 min on 2 cores)
    nice python benchmarks/why_wrong.py --first-seed 1000    # another draw
    nice python benchmarks/why_wrong.py --demo 10            # localize demo, seeds 0-9

``bench_state.py`` counts the scans whose state says *localized* while the
estimate is more than 1 m from the robot. This script runs the same
simulated buildings, lasers and robots (or ``localize demo``'s), knows the
true pose at every scan, and asks of each such wrong claim what the scans
since the place was chosen said. At every scan the filter used, the truth and
the estimate are each moved to the best pose within a few centimetres
(:func:`localize.placesearch.climb`: neither is favoured by being better
placed) and scored with the filter's own sensor model and the scan it used;
the differences, truth minus estimate, are summed since the state last
started a place (a jump, a restart, a switch to a rival).

* **the scans favour the wrong place** (sum below 0): under the filter's own
  model the robot's true path fits the scans worse than the estimate's. The
  map is wrong there (an unmapped obstacle, a cupboard that is gone), or the
  place is a look-alike and the clutter tipped it. No tracking of the rival
  places can find the robot from these scans: only a state that counts the
  noise of this evidence (and says "not sure") avoids the claim.
* **the scans favour the robot's place, held as a rival** (sum above 0, and
  a rival of :class:`localize.rivals.RivalBank` within 0.5 m of the robot):
  the evidence was there and the bank had the place, but its odds did not
  follow (a rival following the estimate rigidly, re-placed only at the
  searches).
* **the scans favour the robot's place, not held** (sum above 0, no rival
  near the robot): the bank's place search did not find it.

The classes are the diagnosis, not a score; the table prints how many wrong
claims fall in each, with the median sum and the median number of scans behind it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bench_global as bg  # noqa: E402
import bench_state as bs  # noqa: E402
from _util import run_jobs, table  # noqa: E402

from localize import pipeline  # noqa: E402
from localize import reliability as rel  # noqa: E402
from localize.placesearch import climb, stencil  # noqa: E402

#: Moves of the climb each pose takes before it is scored (10 cm and 0.03 rad, halving three times).
MOVES = stencil(0.1, 0.03, 4)
#: Metres: a rival this close to the robot holds the robot's place.
HELD = 0.5
#: The share of a bank that held the robot's place, from which ``p_localized`` (the geometric mean) could reach
#: *localized* (0.95 squared).
SURE = rel.LOCALIZED_AT ** 2
CLASSES = ("scans favour the wrong place", "scans favour the robot's place, held as a rival",
           "scans favour the robot's place, not held")


class Recorder:
    """Wraps :class:`~localize.reliability.ReliabilityState` for one run: the evidence of truth and estimate."""

    def __init__(self, truth: np.ndarray) -> None:
        self.truth = truth
        self.rows: dict[int, tuple[float, int, bool, float]] = {}   # step -> (sum, scans, truth held, sum of squares)
        self.total, self.count, self.squares = 0.0, 0, 0.0

    def __enter__(self) -> "Recorder":
        """Record the runs made inside the ``with`` block (the state's methods wrapped, and restored on exit)."""
        global _CURRENT
        if _CURRENT is not None:
            raise RuntimeError("a Recorder is already recording")
        _CURRENT = self
        rel.ReliabilityState.p_localized = _p_localized
        rel.ReliabilityState._new_place = _new_place
        rel.ReliabilityState.take_switch = _take_switch
        return self

    def __exit__(self, *exc) -> None:
        global _CURRENT
        _CURRENT = None
        (rel.ReliabilityState.p_localized, rel.ReliabilityState._new_place,
         rel.ReliabilityState.take_switch) = _ORIG

    def observe(self, state, step) -> None:
        if step.updated and isinstance(step.z, tuple) and len(step.z) == 2 and step.pose is not None:
            _, ll = climb(state.sensor, np.vstack([self.truth[step.k], step.pose]), step.z, MOVES, 10)
            if np.all(np.isfinite(ll)):
                self.total += float(ll[0] - ll[1])
                self.squares += float(ll[0] - ll[1]) ** 2
                self.count += 1
        held = False
        bank = state.rivals
        if bank is not None and len(bank.G) and step.pose is not None:
            places = bank.places(step.pose)
            held = bool(np.min(np.hypot(*(places[:, :2] - self.truth[step.k, :2]).T)) <= HELD)
        self.rows[step.k] = (self.total, self.count, held, self.squares)

    def restart(self) -> None:
        self.total, self.count, self.squares = 0.0, 0, 0.0


_CURRENT: Recorder | None = None
_ORIG = (rel.ReliabilityState.p_localized, rel.ReliabilityState._new_place, rel.ReliabilityState.take_switch)


def _p_localized(state, step):
    out = _ORIG[0](state, step)
    if _CURRENT is not None:
        _CURRENT.observe(state, step)
    return out


def _new_place(state):
    if _CURRENT is not None:
        _CURRENT.restart()
    return _ORIG[1](state)


def _take_switch(state, allowed=True):
    g = _ORIG[2](state, allowed)
    if g is not None and _CURRENT is not None:
        _CURRENT.restart()
    return g


def classify(rows: dict, errors: np.ndarray, state: np.ndarray, off: float = bg.STAY_M) -> list[dict]:
    """One record (:func:`claim`) per wrong claim: a step whose state says localized while more than ``off`` metres
    from the robot."""
    wrong = np.flatnonzero((state == "localized") & (errors > off))
    return [claim(*rows[int(k)]) for k in wrong if int(k) in rows]


def run_state_job(job: dict) -> dict:
    grid, log = bs.prepare(job)
    s = bs.run_settings(job, grid)
    with Recorder(log.poses) as rec:
        res = pipeline.localize_log(grid, log, rng=np.random.default_rng(job["seed"]), settings=s)
    j = bg.judge(res.estimates, log.poses)
    return {"run": f"{job['kind']} {job['laser']} {job['seed']}", "kind": job["kind"],
            "claims": classify(rec.rows, j["errors"], np.asarray(res.state)), "localized": int(np.sum(res.state == "localized"))}


def run_demo_job(job: dict) -> dict:
    """``localize demo --seed S``'s files, then ``localize run`` on them as a user would (the command line)."""
    from localize import cli, demo, io
    seed = job["seed"]
    with tempfile.TemporaryDirectory() as d:
        data = demo.make_demo(Path(d) / "data", np.random.default_rng(seed))
        _, poses = io.read_tum(data.truth_path)
        with Recorder(np.asarray(poses, dtype=float)) as rec:
            cli.main(["run", "--log", str(data.log_path), "--map", str(data.map_path), "--seed", str(seed), "--quiet",
                      "--out", str(Path(d) / "out"), *job.get("args", [])])
        rows = np.genfromtxt(Path(d) / "out" / "trajectory.csv", delimiter=",", names=True, dtype=None, encoding=None)
    n = min(len(rows), len(rec.truth))
    e = np.hypot(rows["x"][:n] - rec.truth[:n, 0], rows["y"][:n] - rec.truth[:n, 1])
    state = np.asarray(rows["state"][:n])
    claims = classify(rec.rows, e, state, off=0.5)          # the demo's own criterion: 0.5 m
    return {"run": f"demo {seed}", "kind": "demo", "claims": claims, "localized": int(np.sum(state == "localized"))}


def claim(total: float, count: int, held: bool, squares: float) -> dict:
    """A wrong claim's class, from the sum of the per-scan differences (truth minus estimate) over ``count`` scans
    and whether a rival held the robot's place; and the estimate's share against the robot's place that a bank
    holding it would give: from the sum as it is (``share``), and believed only as far as the differences' own spread
    supports it (``share_noise``: the sum scaled by ``2 |mean| / variance``, at most 1, the slope of a Gaussian
    log-likelihood ratio; 1 when the differences are exact log-likelihood ratios).

    Examples
    --------
    >>> c = claim(-3.0, 10, False, 0.9)           # 10 scans of -0.3 nats, no spread: the sum holds
    >>> c["class"], round(c["share"], 3), round(c["share_noise"], 3)
    (0, 0.953, 0.953)
    >>> c = claim(-3.0, 10, False, 90.0)          # the same sum from differences of +-3 nats: noise
    >>> round(c["share_noise"], 2)
    0.55
    >>> claim(5.0, 20, True, 50.0)["class"], claim(5.0, 20, False, 50.0)["class"]
    (1, 2)
    """
    mean = total / count if count else 0.0
    var = max(squares - count * mean ** 2, 0.0) / (count - 1) if count > 1 else 0.0
    scale = 1.0 if var <= 2.0 * abs(mean) else 2.0 * abs(mean) / var      # one scan, or no spread: the sum holds
    return {"class": 0 if total < 0 else (1 if held else 2), "sum": total, "scans": count,
            "share": float(1.0 / (1.0 + np.exp(np.clip(total, -50, 50)))),
            "share_noise": float(1.0 / (1.0 + np.exp(np.clip(scale * total, -50, 50))))}


def report(rows: list[dict]) -> str:
    claims = [c for r in rows for c in r["claims"]]
    localized = sum(r["localized"] for r in rows)
    out = []
    for i, name in enumerate(CLASSES):
        cs = [c for c in claims if c["class"] == i]
        runs = sum(any(c["class"] == i for c in r["claims"]) for r in rows)
        out.append({"class": name, "wrong claims": len(cs), "runs": runs,
                    "median sum (nats)": f"{np.median([c['sum'] for c in cs]):+.1f}" if cs else "-",
                    "median scans behind it": f"{np.median([c['scans'] for c in cs]):.0f}" if cs else "-",
                    "share >= 0.9025 (sum)": sum(c["share"] >= SURE for c in cs),
                    "share >= 0.9025 (noise)": sum(c["share_noise"] >= SURE for c in cs)})
    by_kind = {}
    for r in rows:
        for c in r["claims"]:
            by_kind.setdefault(r["kind"], [0, 0, 0])[c["class"]] += 1
    text = table(out, ["class", "wrong claims", "runs", "median sum (nats)", "median scans behind it",
                       "share >= 0.9025 (sum)", "share >= 0.9025 (noise)"])
    text += f"\n\nOf {localized:,} localized scans in {len(rows)} runs; by building: " + "; ".join(
        f"{k} {v[0]} / {v[1]} / {v[2]}" for k, v in sorted(by_kind.items())) + " (the three classes, in order)"
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--first-seed", type=int, default=0, metavar="S", help="bench_state.py's draw (default 0)")
    ap.add_argument("--seeds", type=int, default=4, help="runs per building kind and laser (default 4)")
    ap.add_argument("--scans", type=int, default=150, help="scans per run (default 150)")
    ap.add_argument("--demo", type=int, default=0, metavar="N", help="localize demo's seeds 0..N-1 instead")
    ap.add_argument("--args", default="", metavar="'OPTIONS'", help="options of `localize run` for every run")
    ap.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    args = ap.parse_args(argv)
    if args.demo:
        jobs = [{"seed": s, "args": args.args.split()} for s in range(args.demo)]
        rows = run_jobs(run_demo_job, jobs, args.workers)
    else:
        jobs = [{"kind": k, "laser": la, "seed": seed, "state": "probability", "scans": args.scans,
                 "args": args.args.split()}
                for seed in range(args.first_seed, args.first_seed + args.seeds) for k in bs.KINDS for la in bs.LASERS]
        rows = run_jobs(run_state_job, jobs, args.workers)
    print(report(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
