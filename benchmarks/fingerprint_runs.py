"""Fingerprints of bench_global runs, to show that a refactoring changed no trajectory byte for byte.

    nice python benchmarks/fingerprint_runs.py before.json            # on the old commit (a git worktree)
    nice python benchmarks/fingerprint_runs.py after.json             # on the new one
    nice python benchmarks/fingerprint_runs.py after.json --compare before.json

Each run (3 starts x 2 seeds on every log of bench_global.py, 300 scans, the CLI's defaults; ``--held-out``
for the other draw) is reduced to the sha256 of its ``trajectory.csv`` (its first ``--columns`` columns, so
that columns added later do not count) and of its event list.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing as mp
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bench_global as B  # noqa: E402

from localize import cli  # noqa: E402

COLUMNS = 7          # time,x,y,theta,spread,n_eff,state: the columns trajectory.csv had before the covariance


def fingerprint(job: dict) -> dict:
    bad_map, sub, kw = B.prepare(job)
    res = cli.localize_log(bad_map, sub, rng=np.random.default_rng(job["seed"]), **kw)
    with tempfile.TemporaryDirectory() as d:
        lines = cli.write_trajectory(Path(d) / "trajectory.csv", res).read_bytes().splitlines()
    kept = b"\n".join(b",".join(line.split(b",")[:job["columns"]]) for line in lines)
    events = json.dumps([[int(k), str(t)] for k, t in res.trace.events]).encode()
    return {"job": f"{job['name']}:{job['start']}:{job['seed']}", "traj": hashlib.sha256(kept).hexdigest(),
            "events": hashlib.sha256(events).hexdigest()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path, help="JSON file for the fingerprints")
    ap.add_argument("--held-out", action="store_true", help="the held-out draw of bench_global.py")
    ap.add_argument("--columns", type=int, default=COLUMNS, help=f"columns of trajectory.csv hashed ({COLUMNS})")
    ap.add_argument("--compare", type=Path, default=None, help="fingerprints of the other version to compare")
    args = ap.parse_args(argv)
    base = B.HELD_OUT if args.held_out else 0
    jobs = []
    for name in [*B.LOGS, "willow"]:
        log, _ = B.load(name)
        starts = (list(range(base, base + 3)) if name == "willow"
                  else B.start_scans(len(log), 300, 3, held_out=args.held_out))
        jobs += [{"name": name, "start": s, "seed": seed, "scans": 300, "opts": {}, "clean": False, "args": [],
                  "columns": args.columns} for s in starts for seed in range(base, base + 2)]
    with mp.get_context("fork").Pool(2) as pool:
        rows = pool.map(fingerprint, jobs, chunksize=1)
    args.out.write_text(json.dumps(rows, indent=1))
    print(f"{len(rows)} runs fingerprinted into {args.out}")
    if args.compare is not None:
        other = {r["job"]: (r["traj"], r["events"]) for r in json.loads(args.compare.read_text())}
        same = [r["job"] for r in rows if other.get(r["job"]) == (r["traj"], r["events"])]
        print(f"identical to {args.compare}: {len(same)} of {len(rows)}")
        for r in rows:
            if other.get(r["job"]) != (r["traj"], r["events"]):
                print("differs:", r["job"])
        return 0 if len(same) == len(rows) else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
