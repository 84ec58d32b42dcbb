"""A robot that starts on a patch of floor the map leaves unknown: is it found, and how soon?

Maps leave patches of floor unknown: people stood there while the map was
made, a glass floor, a region erased by hand. ``localize run`` lets particles
stand in unknown cells, and since stop 60 it draws them over the map's
*holes* as well (``OccupancyGrid.holes``: unknown regions that do not reach
the map's edge and whose border is mostly open floor), and its place search
looks there. This benchmark measures what that changes, on buildings and
lasers that nothing was chosen on: ``bench_state.py``'s four kinds of building
x four lasers x 4 seeds (the same worlds and logs), with the free cells of a
square of 5% of the free area, centred on the robot's first pose, left unknown
in the map the filter is given (walls in the square stay). Every run starts
in the hole, the worst case; judged as ``bench_global.py`` judges (success:
within 0.5 m and 10 degrees within the first 30% of the run, within 1 m
after).

    nice python benchmarks/bench_holes.py [--first-seed S] [--json F] [--write]
    python benchmarks/bench_holes.py --table-from AFTER.jsonl [BEFORE.jsonl]

To compare two versions, run each checkout's own copy of this script with its
own ``--json`` file (it measures the ``localize`` beside it, as printed on
stderr), then ``--table-from`` both files.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bench_global as bg  # noqa: E402
import bench_state as bs  # noqa: E402
from _util import run_jobs, table  # noqa: E402

from localize import pipeline  # noqa: E402
from localize.grid import OccupancyGrid  # noqa: E402

#: Share of the free area the unknown square covers (bench_global's degraded maps leave the same share unknown).
SHARE = 0.05


def hole_at_start(grid: OccupancyGrid, start: np.ndarray, share: float = SHARE) -> OccupancyGrid:
    """``grid`` with the free cells of a square of ``share`` of its free area, centred on ``start``, unknown."""
    res = grid.resolution
    side = int(round(np.sqrt(share * grid.free.sum())))
    i, j = grid.world_to_cell(np.asarray(start, dtype=float)[:2])
    data = np.array(grid.data)
    block = data[max(i - side // 2, 0):i + side // 2, max(j - side // 2, 0):j + side // 2]
    block[block < grid.occupied_threshold] = np.nan
    return OccupancyGrid(data, res, origin=grid.origin)


def run_one(job: dict) -> dict:
    world_map, log = bs.prepare(job)
    grid = hole_at_start(world_map, np.asarray(log.poses)[0])
    res = pipeline.localize_log(grid, log, rng=np.random.default_rng(job["seed"]), settings=bs.run_settings(job, grid))
    j = bg.judge(res.estimates, log.poses)
    state = np.asarray(res.state)
    return {"kind": job["kind"], "laser": job["laser"], "seed": job["seed"], "success": bool(j["success"]),
            "converged_at": j["converged_at"], "final_error": j["final_error"],
            "loc": int(np.sum(state == "localized")),
            "loc_off": int(np.sum((state == "localized") & (j["errors"] > bg.STAY_M)))}


def _rows(path: Path) -> dict:
    return {(r["kind"], r["laser"], r["seed"]): r for r in map(json.loads, path.read_text().splitlines()) if r}


def summary(after: dict, before: dict | None) -> str:
    """Markdown: by building kind, success, median scans to convergence and wrong localized scans."""
    runs = {"after": after, "before": before} if before else {"after": after}
    keys = sorted(after) if before is None else sorted(set(after) & set(before))
    out = []
    for kind in [*bs.KINDS, "all"]:
        kk = [k for k in keys if kind in ("all", k[0])]
        row = {"building": kind, "runs": len(kk)}
        for name, rows in runs.items():
            conv = [rows[k]["converged_at"] for k in kk if rows[k]["converged_at"] is not None]
            loc = sum(rows[k]["loc"] for k in kk)
            off = sum(rows[k]["loc_off"] for k in kk)
            row[f"success, {name}"] = sum(rows[k]["success"] for k in kk)
            row[f"scans to conv. median, {name}"] = f"{statistics.median(conv):g}" if conv else "-"
            row[f"localized > 1 m off, {name}"] = f"{off} of {loc} ({100 * off / max(loc, 1):.1f}%)"
        if before:
            won = sum(after[k]["success"] and not before[k]["success"] for k in kk)
            lost = sum(before[k]["success"] and not after[k]["success"] for k in kk)
            row["won / lost (McNemar p)"] = f"{won} / {lost} (p = {bs._mcnemar(won, lost):.3f})"
        out.append(row)
    return table(out, list(out[0]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first-seed", type=int, default=0, metavar="S", help="first seed of the 4 (default 0)")
    ap.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="also write every run's row to this file (JSON lines)")
    ap.add_argument("--table-from", type=Path, nargs="+", default=None, metavar="FILE",
                    help="do not run: the table of the rows in FILE (after), beside a second FILE's (before)")
    ap.add_argument("--write", action="store_true", help="write the bench_holes section of RESULTS.md")
    args = ap.parse_args(argv)
    if args.table_from:
        if len(args.table_from) > 2:
            ap.error("--table-from takes one file (the rows to show) or two (after, then before)")
        for p in args.table_from:
            if not p.is_file():
                ap.error(f"{p}: no such file (give a file that bench_holes.py --json F wrote)")
        after = _rows(args.table_from[0])
        before = _rows(args.table_from[1]) if len(args.table_from) == 2 else None
        how = f"`python benchmarks/bench_holes.py --table-from {' '.join(map(str, args.table_from))}`"
    else:
        jobs = [{"kind": k, "laser": laser, "seed": s, "scans": 150, "state": "probability"}
                for s in range(args.first_seed, args.first_seed + 4) for k in bs.KINDS for laser in bs.LASERS]
        after = {(r["kind"], r["laser"], r["seed"]): r for r in run_jobs(run_one, jobs, args.workers, args.json)}
        before = None
        how = f"`nice python benchmarks/bench_holes.py --first-seed {args.first_seed}`"
    text = "## bench_holes\n\n" + __doc__.split("\n\n")[1].replace("\n", " ") + f" {how}.\n\n" + summary(after, before)
    print(text)
    if args.write:
        bg.write_section(text, "bench_holes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
