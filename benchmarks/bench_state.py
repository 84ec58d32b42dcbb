"""Am I localized? The state's honesty on simulated buildings, lasers and runs that no default was chosen on.

    nice python benchmarks/bench_state.py --write          # the reported table (~ 6 min on 2 cores)
    nice python benchmarks/bench_state.py --seeds 1        # a quick subset

``bench_global.py`` judges the state on five logs, four of them real. Its
defaults (the probability state's thresholds, the restarts) were measured
there. This benchmark asks the same questions on data of another kind, which
nothing in ``localize`` was chosen on: simulated robots in four kinds of
building, each seen by four lasers, with the command line's defaults and both
states (``--state probability``, the default, and ``--state thresholds``),
from an unknown start (global localization).

* **Buildings** (a new one for every seed where the kind is random):
  ``rooms``, a grid of 3-5 x 3-5 rooms of 4-7 m with a door in every wall
  and furniture (:func:`building`: many rooms alike, the look-alike
  problem); ``boxes``, a walled hall of 14-24 m with 25 random boxes
  (:func:`localize.maps.random_rooms`); ``office``
  (:func:`localize.maps.office`); ``hall``, a room that is the same under a
  half turn but for a small tell (:func:`localize.maps.symmetric_room`).
* **Lasers**: 181 beams over 180 degrees to 30 m (a SICK LMS); 683 over 240
  degrees to 5.6 m (a Hokuyo URG-04LX); 360 over 360 degrees to 12 m (a
  spinning lidar); 91 over 90 degrees to 10 m (a narrow depth camera's
  slice). Readings from the simulator's beam model with its default noise.
* **The world is not the map**: every run adds five unmapped boxes (people,
  chairs) to the world the laser sees (:func:`localize.sim.range_run`'s
  ``n_clutter``), and the odometry drifts by the simulator's default noise.
* **A run**: ``--scans`` scans at 0.4 m per scan, the robot wandering
  between free poses; the filter gets the map, the log, no start.

Judged as ``bench_global.py`` judges (:func:`bench_global.judge`, :func:`bench_global.state_counts`):
success is within 0.5 m and 10 deg of the truth within the first 30% of the
run and within 1 m after; a scan whose state says *localized* while more than
1 m off is a wrong claim; of the scans within 0.3 m after the first localized
one, the share that say *localized*; the reliability of ``p_localized``
(the probability state).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bench_global as bg  # noqa: E402
from _util import run_jobs, table  # noqa: E402

from localize import maps, pipeline, settings, sim  # noqa: E402
from localize.grid import OccupancyGrid  # noqa: E402

RESOLUTION = 0.05
KINDS = ("rooms", "boxes", "office", "hall")
#: name: (beams, field of view in degrees, maximum range in metres)
LASERS = {"sick-180": (181, 180.0, 30.0), "urg-240": (683, 240.0, 5.6), "lidar-360": (360, 360.0, 12.0),
          "narrow-90": (91, 90.0, 10.0)}
STATES = ("probability", "thresholds")


def building(rng: np.random.Generator, resolution: float = RESOLUTION) -> OccupancyGrid:
    """A grid of 3-5 x 3-5 rooms of 4-7 m each, 0.15 m walls, one door (0.9-1.2 m) in every inner wall between two
    rooms, and 0-3 pieces of furniture (0.4-1.2 m) per room, all drawn from ``rng``.

    Examples
    --------
    >>> g = building(np.random.default_rng(0))
    >>> bool(10.0 < g.width_m < 40.0), bool(0.5 < g.free.mean() < 0.98)
    (True, True)
    """
    ny, nx = (int(v) for v in rng.integers(3, 6, size=2))
    room = rng.uniform(4.0, 7.0)
    cells = int(round(room / resolution))
    wall = max(1, int(round(0.15 / resolution)))
    h, w = ny * cells + wall, nx * cells + wall
    d = np.zeros((h, w))
    for i in range(ny + 1):
        d[i * cells:i * cells + wall, :] = 1.0
    for j in range(nx + 1):
        d[:, j * cells:j * cells + wall] = 1.0

    def door() -> tuple[int, int]:
        width = int(round(rng.uniform(0.9, 1.2) / resolution))
        a = int(rng.integers(wall + 2, cells - width - 2))
        return a, a + width

    for i in range(1, ny):                 # horizontal inner walls: a door into every room below
        for j in range(nx):
            a, b = door()
            d[i * cells:i * cells + wall, j * cells + a:j * cells + b] = 0.0
    for j in range(1, nx):                 # vertical inner walls
        for i in range(ny):
            a, b = door()
            d[i * cells + a:i * cells + b, j * cells:j * cells + wall] = 0.0
    for i in range(ny):
        for j in range(nx):
            for _ in range(int(rng.integers(0, 4))):
                bh, bw = (int(round(v / resolution)) for v in rng.uniform(0.4, 1.2, size=2))
                y0 = i * cells + wall + int(rng.integers(0, cells - wall - bh))
                x0 = j * cells + wall + int(rng.integers(0, cells - wall - bw))
                d[y0:y0 + bh, x0:x0 + bw] = 1.0
    return OccupancyGrid(d, resolution)


def make_map(kind: str, rng: np.random.Generator) -> OccupancyGrid:
    """The map of a building of ``kind`` (:data:`KINDS`)."""
    if kind == "rooms":
        return building(rng)
    if kind == "boxes":
        side = rng.uniform(14.0, 24.0, size=2)
        shape = tuple(int(round(s / RESOLUTION)) for s in side)
        return maps.random_rooms(shape, RESOLUTION, rng, n_boxes=25, max_box=0.12)
    if kind == "office":
        return maps.office(RESOLUTION)
    if kind == "hall":
        return maps.symmetric_room(RESOLUTION, tell=True)
    raise ValueError(f"unknown building kind {kind!r}; choose one of {', '.join(KINDS)}")


def laser_angles(laser: str) -> np.ndarray:
    """The beam angles of a laser of :data:`LASERS`: evenly spread over its field of view (a full turn without
    repeating the first beam)."""
    n_beams, fov, _ = LASERS[laser]
    half = np.radians(fov) / 2.0
    return (np.linspace(-half, half, n_beams) if fov < 360.0
            else np.linspace(-np.pi, np.pi, n_beams, endpoint=False))


def prepare(job: dict):
    """``(map, log)`` of one run: the building, and a robot's log in it (the same for both states)."""
    kind, laser, seed = job["kind"], job["laser"], job["seed"]
    rng = np.random.default_rng([seed, KINDS.index(kind), list(LASERS).index(laser), 4343])
    grid = make_map(kind, rng)
    run = sim.range_run(grid, rng, n_steps=job["scans"], speed=0.4, dt=1.0, angles=laser_angles(laser),
                        max_range=LASERS[laser][2], n_clutter=5, when_blocked="open_side")
    return grid, run.to_log()


def run_settings(job: dict, grid) -> settings.RunSettings:
    """The settings of ``localize run`` for a job: the defaults, its ``--state`` and options, particles resolved on
    ``grid`` (also :mod:`why_wrong`'s, so that its runs are this benchmark's)."""
    s = settings.parse_options(["--state", job["state"], *job.get("args", [])])
    return replace(s, particles=pipeline.resolve_particles(s.particles, grid))


def run_one(job: dict) -> dict:
    grid, log = prepare(job)
    s = run_settings(job, grid)
    t0 = time.perf_counter()
    res = pipeline.localize_log(grid, log, rng=np.random.default_rng(job["seed"]), settings=s)
    wall = time.perf_counter() - t0
    j = bg.judge(res.estimates, log.poses)
    return {"name": job["kind"], "kind": job["kind"], "laser": job["laser"], "seed": job["seed"],
            "state": job["state"], "scans": len(log), "success": j["success"], "wall": wall,
            "final_error": j["final_error"], "final_state": str(res.state[-1]),
            "first_localized": res.trace.first_localized(), **bg.state_counts(res.trace, j["errors"])}


def _mcnemar(won: int, lost: int) -> float:
    """Two-sided sign test on the runs whose success differs."""
    from scipy.stats import binomtest

    return 1.0 if won + lost == 0 else float(binomtest(won, won + lost, 0.5).pvalue)


def compare(rows: list[dict], by: str) -> list[dict]:
    """Per value of ``by`` (kind or laser) and over all: both states side by side on the same runs."""
    out = []
    values = list(dict.fromkeys(r[by] for r in rows))
    for v in [*values, "all"]:
        rs = [r for r in rows if v in ("all", r[by])]
        runs = {s: {(r["kind"], r["laser"], r["seed"]): r for r in rs if r["state"] == s} for s in STATES}
        both = sorted(set(runs[STATES[0]]) & set(runs[STATES[1]]))
        if not both:
            continue
        row = {by: v, "runs": len(both)}
        for s in STATES:
            sel = [runs[s][k] for k in both]
            loc, off = sum(r["loc"] for r in sel), sum(r["loc_off"] for r in sel)
            near, near_loc = sum(r["near"] for r in sel), sum(r["near_loc"] for r in sel)
            row[f"success, {s}"] = sum(r["success"] for r in sel)
            row[f"runs ever localized > 1 m off, {s}"] = sum(r["loc_off"] > 0 for r in sel)
            row[f"scans localized > 1 m off, {s}"] = f"{off} of {loc} ({100.0 * off / max(loc, 1):.1f}%)"
            row[f"within 0.3 m that say localized, {s}"] = f"{100.0 * near_loc / max(near, 1):.1f}%"
        won = sum(runs[STATES[0]][k]["success"] and not runs[STATES[1]][k]["success"] for k in both)
        lost = sum(runs[STATES[1]][k]["success"] and not runs[STATES[0]][k]["success"] for k in both)
        row["probability won / lost (McNemar p)"] = f"{won} / {lost} (p = {_mcnemar(won, lost):.2f})"
        out.append(row)
    return out


def report(rows: list[dict], args: argparse.Namespace, section: str, how: str) -> str:
    """The RESULTS.md section of these runs (``how``: the command and its time), with the reliability figure
    written beside it when ``args.write``."""
    by_kind, by_laser = compare(rows, "kind"), compare(rows, "laser")
    prob = [r for r in rows if r["state"] == "probability"]
    calib = bg.calibration(prob)
    seeds = f"seeds {args.first_seed}-{args.first_seed + args.seeds - 1}"
    text = "\n".join([
        f"## {section}",
        "",
        "The state (searching / localized / lost) on simulated buildings, lasers and runs that no default was chosen "
        "on: four kinds of building (a grid of rooms, a hall of boxes, the office, the half-turn-symmetric hall) x "
        "four lasers (180 deg / 30 m, 240 deg / 5.6 m, 360 deg / 12 m, 90 deg / 10 m), five unmapped boxes in "
        f"every world, global localization with the CLI defaults under each `--state`; {args.seeds} runs per "
        f"building kind and laser ({seeds}{', the held-out draw' if args.first_seed else ''}), {args.scans} scans "
        f"each. Judged as bench_global judges. {how}",
        "",
        "By building:",
        "",
        table(by_kind, list(by_kind[0])) if by_kind else "(no runs)",
        "",
        "By laser:",
        "",
        table(by_laser, list(by_laser[0])) if by_laser else "(no runs)",
        "",
    ] + (["Calibration of `p_localized` (probability state; bins holding at least 50 scans):", "",
          table(calib, list(calib[0])), ""] if calib else []))
    if args.write and calib:
        figure = bg.reliability_figure(prob, HERE / f"{section}_reliability.png")
        text += f"\n![reliability of p_localized]({figure.name})\n"
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kinds", nargs="*", default=list(KINDS), help=f"buildings (default: {' '.join(KINDS)})")
    ap.add_argument("--lasers", nargs="*", default=list(LASERS), help=f"lasers (default: {' '.join(LASERS)})")
    ap.add_argument("--seeds", type=int, default=4, help="runs per building kind and laser (default 4)")
    ap.add_argument("--first-seed", type=int, default=0, metavar="S",
                    help="seeds S, S+1, ...: another draw of buildings, worlds and runs (default 0; the held-out draw: "
                         "--first-seed 1000)")
    ap.add_argument("--scans", type=int, default=150, help="scans per run (default 150)")
    ap.add_argument("--states", nargs="*", default=list(STATES), help="states to run (default: both)")
    ap.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="also write every run's row to this file (JSON lines)")
    ap.add_argument("--table-from", type=Path, nargs="+", default=None, metavar="FILE",
                    help="do not run: print the tables of the runs stored by --json in these files (e.g. one state's "
                         "runs from one file and the other's, measured on other code of that state, from another)")
    ap.add_argument("--args", default="", metavar="'OPTIONS'",
                    help="options of `localize run` for every run (experiments), e.g. --args '--sensor-reset 0.1'")
    ap.add_argument("--write", action="store_true",
                    help="write the bench_state section of RESULTS.md (bench_state_held_out with --first-seed)")
    args = ap.parse_args(argv)
    for name, given, known in (("--kinds", args.kinds, KINDS), ("--lasers", args.lasers, LASERS)):
        bad = [g for g in given if g not in known]
        if bad:
            ap.error(f"{name}: unknown {', '.join(bad)}; choose from {', '.join(known)}")
    if args.write and args.args:
        ap.error("--write writes the defaults' section: leave --args out")
    jobs = [{"kind": k, "laser": la, "seed": seed, "state": s, "scans": args.scans, "args": args.args.split()}
            for seed in range(args.first_seed, args.first_seed + args.seeds) for k in args.kinds for la in args.lasers for s in args.states]
    t0 = time.perf_counter()
    if args.table_from:
        rows = [json.loads(line) for f in args.table_from for line in open(f) if line.strip()]
    else:
        rows = run_jobs(run_one, jobs, args.workers, args.json)
    wall = time.perf_counter() - t0 if not args.table_from else sum(r["wall"] for r in rows) / args.workers
    cmd = "nice python benchmarks/bench_state.py" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:]) if a != "--write")
    section = "bench_state" + ("_held_out" if args.first_seed else "")
    text = report(rows, args, section, f"`{cmd.strip()}`; {len(rows)} runs on {args.workers} processes in "
                                      f"{wall / 60:.1f} min.")
    print(text)
    if args.write:
        bg.write_section(text, section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
