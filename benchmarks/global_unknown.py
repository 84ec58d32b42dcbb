"""Which runs of ``bench_global.py`` drive through the region that the degraded map leaves unknown?

``bench_global.py`` degrades every map (walls thickened, obstacles added and removed, **a region made
unknown**). A robot that starts, or spends the first scans, in that region had no particle near it there
until stop 60: global localization and every restart drew their particles over the map's *free* cells only.
They now draw over the map's holes too (``OccupancyGrid.holes``: unknown regions bordered mostly by open
floor), which holds the region when it lies amid the floor, not when it covers mostly walls. This reads a
``bench_global.py --json`` file and prints, per log, the success of the runs whose reference poses lie in
an unknown cell at some scan of the first 30% of the run (the window within which a run must find the
robot to count as a success) against the others.

    nice python benchmarks/global_unknown.py /tmp/F_ho.jsonl

No timing: it only rebuilds each start's map and log (``bench_global.prepare``, which the seed does not
change): about half a minute for the 100 starts of a draw.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_global as bg  # noqa: E402


def unknown_scans(job: dict) -> tuple[int, int]:
    """``(scans in the first 30% whose reference pose is in an unknown cell, such scans in the whole run)``."""
    grid, sub, _ = bg.prepare(job)
    cells = grid.world_to_cell(np.asarray(sub.poses)[:, :2], outside="flag")
    inside = cells[:, 0] >= 0
    unknown = np.zeros(len(cells), dtype=bool)
    unknown[inside] = grid.unknown[cells[inside, 0], cells[inside, 1]]
    first = int(np.floor(bg.WITHIN * len(cells))) + 1      # bench_global.judge: found at scan k <= 30% of n
    return int(unknown[:first].sum()), int(unknown.sum())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("json", help="a bench_global.py --json file")
    args = ap.parse_args(argv)
    path = Path(args.json)
    if not path.is_file():
        ap.error(f"{path}: no such file (give the file that bench_global.py --json F wrote)")
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError as exc:
            ap.error(f"{path}, line {i}: not JSON ({exc}); bench_global.py --json writes one run per line")
        if not isinstance(row, dict) or not {"name", "start", "seed", "scans", "success"} <= set(row):
            ap.error(f"{path}, line {i}: not a run of bench_global.py --json (needs name, start, seed, scans and "
                     "success)")
        rows.append(row)
    if not rows:
        ap.error(f"{args.json}: no runs in it (expected one JSON object per line, as bench_global.py --json writes)")
    table: dict[str, list[list[int]]] = {}
    failed = []
    counted: dict[tuple, tuple[int, int]] = {}      # a run's map and log depend on its log and start, not its seed
    for r in rows:
        key = (r["name"], r["start"], r["scans"])
        if key not in counted:
            bg.load(r["name"])
            counted[key] = unknown_scans({"name": r["name"], "start": r["start"], "seed": r["seed"],
                                          "scans": r["scans"], "opts": {}, "args": []})
        early, total = counted[key]
        t = table.setdefault(r["name"], [[0, 0], [0, 0]])      # [with, without] x [runs, successes]
        t[0 if early else 1][0] += 1
        t[0 if early else 1][1] += int(r["success"])
        if early and not r["success"]:
            failed.append(f"{r['name']} {r['start']} (seed {r['seed']}): {early} of the first 30% of the scans, "
                          f"{total} of all, in the unknown region")
    print("| log | runs in the unknown region early | of them successes | other runs | of them successes |")
    print("|---|---|---|---|---|")
    for name in sorted(table, key=lambda n: ([*bg.LOGS, "willow"] + [n]).index(n)):
        (n_with, s_with), (n_without, s_without) = table[name]
        print(f"| {name} | {n_with} | {s_with} | {n_without} | {s_without} |")
    print()
    print("\n".join(f"* {line}" for line in failed) or "No failed run was in the unknown region early.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
