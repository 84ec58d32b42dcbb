"""Offline smoothing (``localize run --smooth``) against the forward pass alone, on bench_global's runs.

    nice python benchmarks/bench_smooth.py --starts 20 --seeds 1 --write   # the reported table (~ 15 min on 2 cores)
    nice python benchmarks/bench_smooth.py --starts 4 --seeds 1            # a quick subset

Every run is one of :mod:`bench_global`'s (same logs, degraded maps, start
scans, seeds and CLI defaults, built by ``bench_global.prepare``): the forward
pass is exactly bench_global's run of that start and seed. The smoothed run
(:func:`localize.smooth.smooth_log`) adds the backward pass over the reversed
log and combines the two. Both trajectories are judged by bench_global's rule
(``bench_global.judge``: within 0.5 m and 10 deg of the reference within the
first 30% of the run, within 1 m from then on), on the same starts. The table
counts failures the smoothing turns into successes and successes it turns
into failures, and, for honesty, the runs with any scan whose state says
``localized`` while more than 1 m off (forward pass vs smoothed).

``--cache DIR`` keeps each run's two passes (``.npz``) and does not filter a run
again that DIR already holds (its passes are recombined); ``--from-cache DIR``
only recombines (to study the combination rules).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bench_global as bg  # noqa: E402

from localize import smooth  # noqa: E402
from localize.runloop import RunTrace  # noqa: E402

_KEEP = ("poses", "means", "stds", "spread", "best_weight", "n_eff", "n_particles", "n_injected", "p_inject",
         "updated", "resampled", "degenerate", "n_valid", "fit", "on_map", "state")


def _save(path: Path, fw: RunTrace, bw: RunTrace) -> None:
    arrays = {f"{p}_{k}": getattr(tr, k) for p, tr in (("f", fw), ("b", bw)) for k in _KEEP}
    arrays["f_events"] = np.array(json.dumps([[int(k), t] for k, t in fw.events]))
    arrays["b_events"] = np.array(json.dumps([[int(k), t] for k, t in bw.events]))
    arrays["seconds"] = np.array([fw.seconds, bw.seconds])
    np.savez_compressed(path, **arrays)


def _load(path: Path) -> tuple[RunTrace, RunTrace]:
    z = np.load(path)
    out = []
    for i, p in enumerate(("f", "b")):
        kw = {k: z[f"{p}_{k}"] for k in _KEEP}
        ev = [(int(k), str(t)) for k, t in json.loads(str(z[f"{p}_events"]))]
        out.append(RunTrace(**kw, events=ev, beam_evaluations=0, seconds=float(z["seconds"][i])))
    return out[0], out[1]


def _fit_for(bad_map, sub, kw):
    s = kw["settings"]
    return smooth.scan_fit_function(bad_map, sub, 2.0 * s.sigma_hit, min_range=float(s.min_range or 0.0),
                                    max_range=s.max_range)


def _job_file(cache: Path, job: dict) -> Path:
    return cache / f"{job['name']}-{job['start']}-{job['seed']}.npz"


def run_one(job: dict) -> dict:
    bad_map, sub, kw = bg.prepare(job)
    cache = Path(job["cache"]) if job.get("cache") else None
    t0 = time.perf_counter()
    cached = _job_file(Path(job["from_cache"] or job["cache"]), job) if (job.get("from_cache") or cache) else None
    if cached is not None and (job.get("from_cache") or cached.exists()):
        fw, bw = _load(cached)                                        # bw in the log's scan order
        s = smooth.combine(fw, bw, _fit_for(bad_map, sub, kw), odometry=sub.odometry)
        wall_f, wall_s = fw.seconds, fw.seconds + bw.seconds + (time.perf_counter() - t0)
    else:
        res = smooth.smooth_log(bad_map, sub, rng=np.random.default_rng(job["seed"]), **kw)
        s = res.smooth
        wall_f, wall_s = res.forward.seconds, res.seconds + res.seconds_combine
        if cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
            _save(_job_file(cache, job), s.forward, s.backward)
    ref = sub.poses
    jf = bg.judge(s.forward.poses, ref)
    js = bg.judge(s.poses, ref)
    e_f, e_s = jf["errors"], js["errors"]
    both = s.summary()
    return {"name": job["name"], "start": job["start"], "seed": job["seed"], "scans": len(sub),
            "forward_success": jf["success"], "smooth_success": js["success"],
            "forward_false": bool(np.any((s.forward.state == "localized") & (e_f > bg.STAY_M))),
            "smooth_false": bool(np.any((s.state == "localized") & (e_s > bg.STAY_M))),
            "forward_localized": float(np.mean(s.forward.state == "localized")),
            "smooth_localized": float(np.mean(s.state == "localized")),
            "agree": both["share_agree_where_both_localized"], "disagreements": len(both["disagreements"]),
            "smooth_median_error": float(np.median(e_s)), "wall_forward": wall_f, "wall_smooth": wall_s}


def summarize(rows: list[dict]) -> list[dict]:
    out = []
    order = {n: i for i, n in enumerate([*bg.LOGS, "willow"])}
    names = sorted(dict.fromkeys(r["name"] for r in rows), key=lambda n: order.get(n, 99))
    for name in [*names, "all"]:
        rs = [r for r in rows if name in ("all", r["name"])]
        n = len(rs)
        f_ok = sum(r["forward_success"] for r in rs)
        s_ok = sum(r["smooth_success"] for r in rs)
        agree = [r["agree"] for r in rs if r["agree"] is not None]
        out.append({
            "log": name, "runs": n,
            "forward success": f"{f_ok}/{n} ({100.0 * f_ok / n:.0f}%)",
            "smoothed success": f"{s_ok}/{n} ({100.0 * s_ok / n:.0f}%)",
            "failures fixed": sum(r["smooth_success"] and not r["forward_success"] for r in rs),
            "successes lost": sum(r["forward_success"] and not r["smooth_success"] for r in rs),
            "scans localized, forward / smoothed": (f"{100 * np.mean([r['forward_localized'] for r in rs]):.0f}% / "
                                                    f"{100 * np.mean([r['smooth_localized'] for r in rs]):.0f}%"),
            "passes agree (median share)": f"{100 * np.median(agree):.0f}%" if agree else "-",
            "runs localized > 1 m off, forward / smoothed": (f"{sum(r['forward_false'] for r in rs)} / "
                                                             f"{sum(r['smooth_false'] for r in rs)}"),
            "filter seconds per run median, forward / smoothed": (f"{np.median([r['wall_forward'] for r in rs]):.1f} / "
                                                            f"{np.median([r['wall_smooth'] for r in rs]):.1f}"),
        })
    return out


def write_section(text: str) -> None:
    """Put ``text`` (starting with "## bench_smooth") into RESULTS.md in place of the old section, or in order."""
    import re

    path = HERE / "RESULTS.md"
    old = path.read_text() if path.exists() else "# Benchmark results\n"
    heads = [(m.start(), m.group(1)) for m in re.finditer(r"^## (bench_\w+)", old, flags=re.M)]
    body = text.strip() + "\n\n"
    mine = [i for i, (_, name) in enumerate(heads) if name == "bench_smooth"]
    if mine:
        i = mine[0]
        stop = heads[i + 1][0] if i + 1 < len(heads) else len(old)
        new = old[:heads[i][0]] + body + old[stop:]
    else:
        after = [pos for pos, name in heads if name > "bench_smooth"]
        pos = after[0] if after else len(old)
        new = old[:pos] + body + old[pos:]
    path.write_text(new)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--logs", nargs="*", default=[*bg.LOGS, "willow"], help="data sets (default: all five)")
    ap.add_argument("--starts", type=int, default=20, help="start scans per log (default 20, as bench_global)")
    ap.add_argument("--seeds", type=int, default=1, help="seeds per start (default 1: bench_global's seed 0)")
    ap.add_argument("--scans", type=int, default=300, help="scans per run, or to the end of the log (default 300)")
    ap.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    ap.add_argument("--cache", type=Path, default=None, metavar="DIR", help="keep each run's two passes here; runs already there are recombined, not filtered again")
    ap.add_argument("--from-cache", type=Path, default=None, metavar="DIR",
                    help="do not filter: recombine the passes kept by --cache DIR")
    ap.add_argument("--json", type=Path, default=None, help="also write every run's row to this file (JSON lines)")
    ap.add_argument("--write", action="store_true", help="write the bench_smooth section of RESULTS.md")
    args = ap.parse_args(argv)
    root = bg.data_root()
    names = [n for n in args.logs if (root / ("willow" if n == "willow" else "carmen")).exists()]
    for n in names:
        bg.load(n)
    jobs = []
    for n in names:
        log, _ = bg.load(n)
        starts = list(range(args.starts)) if n == "willow" else bg.start_scans(len(log), args.scans, args.starts)
        jobs += [{"name": n, "start": s, "seed": seed, "scans": args.scans, "opts": {}, "args": [],
                  "cache": str(args.cache) if args.cache else None,
                  "from_cache": str(args.from_cache) if args.from_cache else None}
                 for s in starts for seed in range(args.seeds)]
    t1 = time.perf_counter()
    rows = []
    sink = open(args.json, "w") if args.json else None
    work = (mp.get_context("fork").Pool(args.workers).imap_unordered(run_one, jobs, chunksize=1)
            if args.workers > 1 else map(run_one, jobs))
    for r in work:
        rows.append(r)
        if sink:
            sink.write(json.dumps(r) + "\n")
            sink.flush()
    wall = time.perf_counter() - t1
    if sink:
        sink.close()
    cols = ["log", "runs", "forward success", "smoothed success", "failures fixed", "successes lost",
            "scans localized, forward / smoothed", "passes agree (median share)",
            "runs localized > 1 m off, forward / smoothed", "filter seconds per run median, forward / smoothed"]
    from _util import table

    cmd = "nice python benchmarks/bench_smooth.py" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:]) if a != "--write")
    text = "\n".join([
        "## bench_smooth",
        "",
        "Offline smoothing (`localize run --smooth`: a forward and a backward pass, combined scan by scan) against "
        "the forward pass alone, on the same runs as bench_global (its logs, degraded maps, raw odometry, CLI "
        f"defaults; {args.starts} starts x {args.seeds} seed(s) per log, runs of {args.scans} scans or to the end "
        "of the log; the forward pass is bench_global's run of that start and seed). Success by bench_global's rule "
        "applied to each trajectory. 'runs localized > 1 m off': runs with any scan whose state says localized "
        f"while more than 1 m from the reference. Seconds: the filtering loops (and the combination), without "
        f"reading and map building. `{cmd.strip()}`; {len(jobs)} runs on {args.workers} processes "
        f"in {wall / 60:.1f} min.",
        "",
        table(summarize(rows), cols),
        "",
    ])
    print(text)
    if args.write:
        write_section(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
