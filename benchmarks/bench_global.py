"""Global localization on real logs and maps that disagree with them, with the CLI's defaults.

    nice python benchmarks/bench_global.py                      # the full benchmark (~ an hour on 2 cores)
    nice python benchmarks/bench_global.py --starts 4 --seeds 1  # a quick subset while iterating
    nice python benchmarks/bench_global.py --write              # also write its section of RESULTS.md

For every CARMEN log in ``$LOCALIZE_DATA/carmen`` (Intel, Freiburg 079, ACES,
CSAIL) the map is built from the log's corrected poses
(:func:`localize.mapping.map_from_log`) and then degraded the way real maps
disagree with real scans (:func:`degrade_map`): walls grown by 0.10-0.15 m, a
few obstacles added that are not there and a few removed that are, and one
region left unknown. The filter gets the raw odometry and the real scans and
starts global localization at ``--starts`` scans spread over the log, with
``--seeds`` seeds each; a run lasts ``--scans`` scans (or to the end of the
log). The Willow Garage ROS map joins with simulated scans
(:func:`localize.sim.range_run` in the true map plus unmapped clutter) under
the same degradations.

A run **succeeds** when the estimate comes within 0.5 m and 10 degrees of the
corrected pose at some scan within the first 30% of the run and stays within
1 m from then on. The table also counts the runs whose honest state
(``searching`` / ``localized`` / ``lost``) *ended* ``localized`` while more
than 1 m off: the filter claiming to know where it is when it does not; and
the runs whose state said ``localized`` more than 1 m off at *some* scan.

Every run uses :func:`localize.pipeline.localize_log` with the settings of
``localize run``'s defaults (:func:`localize.settings.parse_options`);
``--set name=value`` overrides one (experiments, never the reported table).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from _util import run_jobs, table  # noqa: E402

from localize import io, mapping, pipeline, settings, sim  # noqa: E402
from localize.geometry import angle_diff  # noqa: E402
from localize.grid import OccupancyGrid  # noqa: E402

LOGS = ("intel", "freiburg-079", "aces", "csail")
MAP_EVERY = {"freiburg-079": 4}          # mapping the 4,791 Freiburg scans: every 4th is enough
SUCCESS_M, SUCCESS_RAD, STAY_M, WITHIN = 0.5, np.radians(10.0), 1.0, 0.3
NEAR_M = 0.3                             # "centimetres right": within this of the reference


# ------------------------------------------------------------------ maps that disagree with the scans
def degrade_map(grid: OccupancyGrid, rng: np.random.Generator, grow=(0.10, 0.15), n_added: int = 4,
                n_removed: int = 4, unknown_share: float = 0.05) -> OccupancyGrid:
    """``grid`` made wrong the way real maps are (a new grid; ``grid`` is not changed).

    * walls grown by a uniform ``grow`` metres (a map drawn with thick walls);
    * ``n_added`` square obstacles (0.3-0.8 m) drawn where nothing is;
    * ``n_removed`` squares (0.5-1.0 m) of obstacle cells erased (furniture
      or a wall piece the map does not show);
    * one square region of ``unknown_share`` of the free area left unknown.

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office(0.05)
    >>> d = degrade_map(g, np.random.default_rng(0))
    >>> bool(d.occupied.sum() > g.occupied.sum()), bool(d.unknown.sum() > 0)
    (True, True)
    """
    from scipy.ndimage import distance_transform_edt

    res = grid.resolution
    data = np.array(grid.data, copy=True)
    occ = grid.occupied
    r = rng.uniform(*grow)
    d = distance_transform_edt(~occ, sampling=res)
    data[(d <= r) & ~np.isnan(data)] = 1.0
    g1 = OccupancyGrid(data, res, origin=grid.origin)
    g2, _ = sim.add_clutter(g1, n_added, rng, size=(0.3, 0.8), clearance=0.4)
    data = np.array(g2.data, copy=True)
    occ_idx = np.argwhere(g2.occupied)
    for _ in range(n_removed):
        i, j = occ_idx[rng.integers(len(occ_idx))]
        h = int(round(rng.uniform(0.5, 1.0) / res / 2))
        blk = data[max(i - h, 0):i + h + 1, max(j - h, 0):j + h + 1]
        blk[blk >= 0.5] = 0.0
    free = np.argwhere(g2.free)
    side = int(round(np.sqrt(unknown_share * len(free))))
    i, j = free[rng.integers(len(free))]
    data[max(i - side // 2, 0):i + side // 2, max(j - side // 2, 0):j + side // 2] = np.nan
    return OccupancyGrid(data, res, origin=grid.origin)


# ------------------------------------------------------------------ data sets
_DATA: dict = {}


def data_root() -> Path:
    return Path(os.environ.get("LOCALIZE_DATA", HERE.parent.parent / "shared" / "data"))


def load(name: str, root: Path | None = None):
    """``(log, map)`` of a data set: a CARMEN log and its map from the corrected poses, or Willow's map."""
    if name in _DATA:
        return _DATA[name]
    root = data_root() if root is None else root
    if name == "willow":
        # grey walls (100-200) are walls; the unknown outside (205) stays unknown (see localize.io.ros)
        g = io.read_map(root / "willow" / "willow-2010-02-18-0.10.yaml", occupied_thresh=0.2)
        _DATA[name] = (None, g)
    else:
        log = io.read_log(root / "carmen" / f"{name}-corrected.log.gz")
        _DATA[name] = (log, mapping.map_from_log(log, resolution=0.05, every=MAP_EVERY.get(name, 1)))
    return _DATA[name]


class _NoReturn:
    """A simulated laser whose beams with nothing in range read ``max_range`` (no return), not a hit near it.

    ``laser`` is a :class:`localize.sensors.BeamModel`; a beam whose ray-cast range is ``max_range`` and
    whose drawn reading lies within 5 ``sigma_hit`` of it (the hit part of the mixture) reads ``max_range``.
    Short and random readings of such beams stay as drawn.
    """

    def __init__(self, laser) -> None:
        self.laser = laser

    def sample(self, poses, angles, rng: np.random.Generator) -> np.ndarray:
        m = self.laser
        expected = m.expected(poses, angles)
        z = m.sample_expected(expected, rng)
        far = (expected >= m.max_range) & (z >= m.max_range - 5.0 * m.sigma_hit)
        z[far] = m.max_range
        return z


def willow_log(world: OccupancyGrid, n_scans: int, rng: np.random.Generator):
    """A simulated robot in the Willow map: 181 beams over 180 degrees, 30 m range, unmapped clutter.

    It drives 0.5 m between scans, like the robots of the CARMEN logs (0.3-1 m),
    and when its way is blocked it turns towards the more open side until it
    can drive on (``when_blocked="open_side"``), instead of dithering left and
    right on the spot for tens of scans.

    The simulated laser sees *through* the map's unknown cells. Much of the
    Willow map's free space ends in unknown without a wall (fans of free
    cells swept by the mapping robot's beams through doors); a real beam
    there goes on into the room beyond. A laser that stopped at the edge of
    the unknown would report walls that no map shows, on which no filter that
    treats unknown as "the map does not know" (the CLI, ROS AMCL) can agree:
    measured, an exact scan at the true pose then scored up to 9 nats worse
    than the same scan turned by 5 degrees.

    A beam with nothing within 30 m reports "no return" (30 m), as a real
    laser does (:class:`_NoReturn`): the beam model's truncated hit density
    about an expected 30 m would otherwise draw readings a few centimetres
    short of it, end points in mid-air that no real scanner produces.
    """
    from localize.sensors import BeamModel

    angles = np.radians(np.linspace(-90, 90, 181))
    cluttered, _ = sim.add_clutter(world, 10, rng)
    see_through = OccupancyGrid(cluttered.data, cluttered.resolution, origin=cluttered.origin,
                                unknown_is_obstacle=False)
    laser = _NoReturn(BeamModel(see_through, 30.0, method="exact", **sim.DEFAULT_SCAN_NOISE))
    run = sim.range_run(cluttered, rng, n_steps=n_scans, angles=angles, max_range=30.0, speed=0.5, dt=1.0,
                        n_clutter=0, sensor=laser, when_blocked="open_side")
    return io.LaserLog(times=run.times, odometry=run.odometry, ranges=run.ranges, angles=run.angles,
                       max_range=run.max_range, poses=run.poses, source="willow-sim", format="sim")


def start_scans(n_log: int, n_scans: int, n_starts: int, held_out: bool = False) -> list[int]:
    """``n_starts`` start scans spread evenly over a log, leaving ``n_scans`` after the last where it can.

    ``held_out`` gives ``n_starts`` other scans, each between two of the standard ones: the midpoints of
    the standard spacing, and a quarter of the way to the second start.
    """
    last = max(n_log - n_scans, 0)
    if held_out:
        step = last / max(n_starts - 1, 1)
        return sorted({int(round(v)) for v in [*(step * (k + 0.5) for k in range(n_starts - 1)), step / 4]})
    return sorted({int(round(v)) for v in np.linspace(0, last, n_starts)})


HELD_OUT = 1000
"""First Willow world and first seed of ``--held-out`` (the standard draw uses 0, 1, 2, ...)."""


# ------------------------------------------------------------------ one run
def judge(est: np.ndarray, ref: np.ndarray) -> dict:
    """Success by the benchmark's rule, scans to convergence and the error after it."""
    e_xy = np.hypot(*(est[:, :2] - ref[:, :2]).T)
    e_th = np.abs(angle_diff(est[:, 2], ref[:, 2]))
    n = len(e_xy)
    close = np.flatnonzero((e_xy <= SUCCESS_M) & (e_th <= SUCCESS_RAD))
    conv = None
    for k in close:
        if k > WITHIN * n:
            break
        if np.all(e_xy[k:] <= STAY_M):
            conv = int(k)
            break
    return {"success": conv is not None, "converged_at": conv, "final_error": float(e_xy[-1]),
            "error_after": float(np.median(e_xy[conv:])) if conv is not None else None, "errors": e_xy}


def prepare(job: dict):
    """``(map, log, keyword arguments)`` of one benchmark run."""
    name, start, n_scans, opts = job["name"], job["start"], job["scans"], job["opts"]
    log, grid = load(name)
    map_rng = np.random.default_rng([start, 12345])
    if name == "willow":
        sub = willow_log(grid, n_scans, np.random.default_rng([start, 777]))
    else:
        sub = log.select(slice(start, min(start + n_scans, len(log))))
    bad_map = grid if job.get("clean") else degrade_map(grid, map_rng)
    s = settings.parse_options(job.get("args", []))
    s = replace(s, particles=pipeline.resolve_particles(s.particles, bad_map))
    opts = dict(opts)
    if isinstance(opts.get("kld"), list):
        from localize.kld import KLDSampling
        e_, lo_, hi_ = opts["kld"]
        opts["kld"] = KLDSampling(epsilon=e_, n_min=lo_, n_max=hi_)
    if isinstance(opts.get("augmented"), list):
        from localize.mcl import Augmented
        opts["augmented"] = Augmented(*opts["augmented"])
    if opts.pop("_unknown_not_obstacle", False):
        bad_map = OccupancyGrid(bad_map.data, bad_map.resolution, origin=bad_map.origin, unknown_is_obstacle=False)
    kw = {"settings": pipeline.settings_with(s, **opts)}
    return bad_map, sub, kw


def run_one(job: dict) -> dict:
    name, start, seed = job["name"], job["start"], job["seed"]
    bad_map, sub, kw = prepare(job)
    t0 = time.perf_counter()
    res = pipeline.localize_log(bad_map, sub, rng=np.random.default_rng(seed), **kw)
    wall = time.perf_counter() - t0
    j = judge(res.estimates, sub.poses)
    dur = float(sub.times[-1] - sub.times[0])
    final_state = str(res.state[-1])
    return {"name": name, "start": start, "seed": seed, "scans": len(sub), "success": j["success"],
            "converged_at": j["converged_at"], "error_after": j["error_after"], "final_error": j["final_error"],
            "wall": wall, "rtf": dur / wall if dur > 0 else None, "final_state": final_state,
            "false_localized": final_state == "localized" and j["final_error"] > STAY_M,
            "scans_false_localized": int(np.sum((res.state == "localized") & (j["errors"] > STAY_M))),
            "first_localized": res.trace.first_localized(), **state_counts(res.trace, j["errors"])}


P_BINS = 10


def state_counts(trace, errors: np.ndarray) -> dict:
    """What the state said against the reference, scan by scan, as counts (summed over runs by the table).

    ``loc``/``loc_off``: scans whose state is localized, and of them those more than STAY_M off;
    ``near``/``near_loc``: scans within WITHIN_M of the reference after the first localized scan, and of
    them those whose state is localized; ``p_n``/``p_sum``/``p_right`` per bin of ``p_localized`` (when the
    trace has it): scans, sum of p, scans truly within STAY_M.
    """
    loc = trace.state == "localized"
    first = trace.first_localized()
    after = np.arange(len(errors)) >= (first if first is not None else len(errors))
    near = after & (errors <= NEAR_M)
    out = {"loc": int(loc.sum()), "loc_off": int(np.sum(loc & (errors > STAY_M))), "near": int(near.sum()),
           "near_loc": int(np.sum(near & loc))}
    p = getattr(trace, "p_localized", None)
    if p is not None and np.all(np.isfinite(p)):           # NaN: the threshold state has no probability
        p = np.asarray(p, dtype=float)
        k = np.clip((p * P_BINS).astype(int), 0, P_BINS - 1)
        right = errors <= STAY_M
        out["p_n"] = np.bincount(k, minlength=P_BINS).tolist()
        out["p_sum"] = np.bincount(k, weights=p, minlength=P_BINS).tolist()
        out["p_right"] = np.bincount(k, weights=right, minlength=P_BINS).astype(int).tolist()
    return out


def _pct(v, q):
    return float(np.percentile(v, q)) if len(v) else float("nan")


def times_reliable(name: str) -> bool:
    """Whether a log's time stamps give its duration (some CARMEN logs keep only 6 significant digits)."""
    if name == "willow":
        return True
    t = np.asarray(load(name)[0].times)
    return bool(t[-1] > t[0] and np.mean(np.diff(t) < 0) < 0.01 and np.unique(t).size / t.size > 0.5)


def summarize(rows: list[dict]) -> list[dict]:
    out = []
    order = {n: i for i, n in enumerate([*LOGS, "willow"])}
    for name in sorted(dict.fromkeys(r["name"] for r in rows), key=lambda n: order.get(n, 99)):
        rs = [r for r in rows if r["name"] == name]
        conv = [r["converged_at"] for r in rs if r["success"]]
        after = [r["error_after"] for r in rs if r["success"]]
        ok = sum(r["success"] for r in rs)
        rtf = [r["rtf"] for r in rs if r["rtf"]] if times_reliable(name) else []
        out.append({
            "log": name, "runs": len(rs), "success": f"{ok}/{len(rs)} ({100.0 * ok / len(rs):.0f}%)",
            "scans to conv. median": f"{_pct(conv, 50):.0f}" if conv else "-",
            "p90": f"{_pct(conv, 90):.0f}" if conv else "-",
            "error after conv. median (m)": f"{np.median(after):.2f}" if after else "-",
            "wall per run median (s)": f"{np.median([r['wall'] for r in rs]):.1f}",
            "real-time factor median": f"{np.median(rtf):.0f}x" if rtf else "-",
            "ended localized": sum(r["final_state"] == "localized" for r in rs),
            "ended localized > 1 m off": sum(r["false_localized"] for r in rs),
            "localized > 1 m off at some scan": (sum(r["scans_false_localized"] > 0 for r in rs)
                                                 if all("scans_false_localized" in r for r in rs) else "-"),
        })
    return out


def state_quality(rows: list[dict]) -> list[dict]:
    """Per log and over all: how often "localized" is wrong, and how often a right estimate says so."""
    out = []
    order = {n: i for i, n in enumerate([*LOGS, "willow"])}
    names = sorted(dict.fromkeys(r["name"] for r in rows), key=lambda n: order.get(n, 99))
    for name in [*names, "all"]:
        rs = [r for r in rows if (name == "all" or r["name"] == name) and "loc" in r]
        if not rs:
            continue
        loc, off = sum(r["loc"] for r in rs), sum(r["loc_off"] for r in rs)
        near, near_loc = sum(r["near"] for r in rs), sum(r["near_loc"] for r in rs)
        out.append({"log": name, "scans": sum(r["scans"] for r in rs), "scans localized": loc,
                    f"of them > {STAY_M:g} m off": f"{off} ({100.0 * off / max(loc, 1):.2f}%)",
                    f"scans within {NEAR_M:g} m after the first localized": near,
                    "of them localized": f"{near_loc} ({100.0 * near_loc / max(near, 1):.1f}%)"})
    return out


def calibration(rows: list[dict], min_count: int = 50) -> list[dict]:
    """The reliability diagram of ``p_localized`` over all runs: per bin, mean p against the share right."""
    rs = [r for r in rows if "p_n" in r]
    if not rs:
        return []
    n = np.sum([r["p_n"] for r in rs], axis=0)
    s = np.sum([r["p_sum"] for r in rs], axis=0)
    right = np.sum([r["p_right"] for r in rs], axis=0)
    out = []
    for b in range(P_BINS):
        if n[b] >= min_count:
            out.append({"p_localized": f"{b / P_BINS:.1f}-{(b + 1) / P_BINS:.1f}", "scans": int(n[b]),
                        "mean p": f"{s[b] / n[b]:.3f}", f"share within {STAY_M:g} m": f"{right[b] / n[b]:.3f}",
                        "difference": f"{right[b] / n[b] - s[b] / n[b]:+.3f}"})
    return out


def reliability_figure(rows: list[dict], path: Path, min_count: int = 50) -> Path:
    """The reliability diagram of ``p_localized`` (bins with at least ``min_count`` scans) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rs = [r for r in rows if "p_n" in r]
    n = np.sum([r["p_n"] for r in rs], axis=0)
    mean_p = np.sum([r["p_sum"] for r in rs], axis=0) / np.maximum(n, 1)
    share = np.sum([r["p_right"] for r in rs], axis=0) / np.maximum(n, 1)
    keep = n >= min_count
    fig, ax = plt.subplots(figsize=(4.2, 4.0), constrained_layout=True)
    ax.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--", label="calibrated")
    ax.fill_between([0, 1], [-0.1, 0.9], [0.1, 1.1], color="grey", alpha=0.15, label="within 0.1")
    ax.plot(mean_p[keep], share[keep], "o-", color="C2", label="p_localized")
    for x, y, c in zip(mean_p[keep], share[keep], n[keep]):
        ax.annotate(f"{c}", (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7, color="grey")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("mean p_localized in the bin")
    ax.set_ylabel(f"share of scans within {STAY_M:g} m")
    ax.legend(loc="upper left", fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_section(text: str, name: str = "bench_global") -> None:
    """Put ``text`` (starting with "## " + ``name``) into RESULTS.md: in place of the old section, or
    before the first benchmark section that sorts after it (the order of run_all.py)."""
    import re

    path = HERE / "RESULTS.md"
    old = path.read_text() if path.exists() else "# Benchmark results\n"
    heads = [(m.start(), m.group(1)) for m in re.finditer(r"^## (bench_\w+)", old, flags=re.M)]
    body = text.strip() + "\n\n"
    mine = [i for i, (_, head) in enumerate(heads) if head == name]
    if mine:
        i = mine[0]
        start = heads[i][0]
        stop = heads[i + 1][0] if i + 1 < len(heads) else len(old)
        new = old[:start] + body + old[stop:]
    else:
        after = [pos for pos, head in heads if head > name]
        pos = after[0] if after else len(old)
        new = old[:pos] + body + old[pos:]
    path.write_text(new)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--logs", nargs="*", default=[*LOGS, "willow"], help="data sets (default: all five)")
    ap.add_argument("--starts", type=int, default=20, help="start scans per log (default 20)")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per start (default 3)")
    ap.add_argument("--scans", type=int, default=300, help="scans per run, or to the end of the log (default 300)")
    ap.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="override a setting (localize.settings.RunSettings; experiments only), e.g. --set n_particles=20000")
    ap.add_argument("--args", default="", metavar="'OPTIONS'",
                    help="options of `localize run` for every run (experiments), e.g. --args '--particles 20000'")
    ap.add_argument("--clean-map", action="store_true", help="diagnostics: localize on the undegraded map")
    ap.add_argument("--held-out", action="store_true",
                    help="a second, independent draw that no default was chosen on: other start scans (between "
                         "the standard ones), so other map degradations, other Willow worlds and other seeds")
    ap.add_argument("--write", action="store_true", help="write the bench_global section of RESULTS.md")
    ap.add_argument("--section", default="bench_global", metavar="NAME",
                    help="the section --write writes (default bench_global); an experiment with --set or --args "
                         "gets its own, e.g. bench_global_z_short_0")
    ap.add_argument("--json", type=Path, default=None,
                    help="also write every run's row to this file (JSON lines, as the runs finish)")
    ap.add_argument("--table-from", type=Path, default=None, metavar="FILE",
                    help="do not run: print the table of the runs stored in FILE by --json (e.g. of a run cut short)")
    args = ap.parse_args(argv)
    if args.write and (args.set or args.args or args.clean_map or args.held_out) and args.section == "bench_global":
        ap.error("--write with --set, --args, --clean-map or --held-out needs --section NAME: the bench_global section is "
                 "the table of the defaults")
    opts = {}
    for kv in args.set:
        if "=" not in kv:
            ap.error(f"--set expects NAME=VALUE (a setting of localize.settings.RunSettings, or an old localize_log keyword); got {kv!r}")
        k, v = kv.split("=", 1)
        try:
            opts[k] = json.loads(v)          # numbers, lists, true/false ...
        except json.JSONDecodeError:
            opts[k] = v                      # ... and words as they are: --set odometry_sign=trust
    root = data_root()
    names = [n for n in args.logs if (root / ("willow" if n == "willow" else "carmen")).exists()]
    t0 = time.perf_counter()
    for n in names:                      # load in the parent: the workers inherit the maps
        load(n)
    t_load = time.perf_counter() - t0
    jobs = []
    for n in names:
        log, _ = load(n)
        base = HELD_OUT if args.held_out else 0
        starts = (list(range(base, base + args.starts)) if n == "willow"
                  else start_scans(len(log), args.scans, args.starts, held_out=args.held_out))
        jobs += [{"name": n, "start": s, "seed": seed, "scans": args.scans, "opts": opts, "clean": args.clean_map,
                  "args": args.args.split(), "order": i}
                 for i, s in enumerate(starts) for seed in range(base, base + args.seeds)]
    # interleave the logs, so that a run stopped early still covers every log
    jobs.sort(key=lambda j: (j["seed"], j["order"], j["name"]))
    t1 = time.perf_counter()
    if args.table_from:
        rows = [json.loads(line) for line in open(args.table_from) if line.strip()]
        jobs = rows
    else:
        rows = run_jobs(run_one, jobs, args.workers, args.json)
    wall = time.perf_counter() - t1
    if args.table_from:
        wall = sum(r["wall"] for r in rows) / max(args.workers, 1)
    cols = ["log", "runs", "success", "scans to conv. median", "p90", "error after conv. median (m)",
            "wall per run median (s)", "real-time factor median", "ended localized", "ended localized > 1 m off",
            "localized > 1 m off at some scan"]
    cmd = "nice python benchmarks/bench_global.py" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:]) if a != "--write")
    quality, calib = state_quality(rows), calibration(rows)
    text = "\n".join([
        f"## {args.section}",
        "",
        f"Global localization with the CLI defaults{' except the overrides named at the end' if opts or args.args else ''} on degraded maps (walls +0.10-0.15 m, obstacles added and "
        f"removed, a region unknown), raw odometry; {args.starts} starts x {args.seeds} seeds per log"
        f"{' (the held-out draw: other starts, degradations, Willow worlds and seeds)' if args.held_out else ''}, runs of "
        f"{args.scans} scans or to the end of the log. Success: within {SUCCESS_M} m and 10 deg of the reference "
        f"within the first {WITHIN:.0%} of the run, within {STAY_M} m after. `{cmd.strip()}`; "
        f"{len(jobs)} runs on {args.workers} processes in {wall / 60:.1f} min (+{t_load:.0f} s reading and mapping)."
        + (f" Overrides: {opts}." if opts else "") + (f" Options: `{args.args}`." if args.args else ""),
        "",
        table(summarize(rows), cols),
        "",
        "What the state said, scan by scan (every scan of every run judged against the reference):",
        "",
        table(quality, list(quality[0]) if quality else ["log"]),
        "",
    ] + (["Calibration of `p_localized` (bins holding at least 50 scans):", "",
          table(calib, list(calib[0])), ""] if calib else []))
    if args.write and calib:
        figure = reliability_figure(rows, HERE / f"{args.section}_reliability.png")
        text += f"\n![reliability of p_localized]({figure.name})\n"
    print(text)
    if args.write:
        write_section(text, args.section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
