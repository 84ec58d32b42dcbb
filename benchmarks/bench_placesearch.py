"""The place search (``localize.placesearch.best_places``): does it find the robot's place, and how fast?

The rival bank and sensor resetting ask the search, every few scans, where in
the whole map one scan fits best. Two things matter: **recall** (is the
robot's own place among the ``n_best`` places found, within 0.3 m and 0.1 rad,
and is it the first?) and **time per search**. Both are measured on buildings
no default was chosen on: ``bench_state.py``'s four kinds of building and four
lasers (a building drawn from its own seed, 25 poses each, scans ray-cast with
2 cm noise), and, for time, ``bench_cli.py``'s 800 x 800-cell map with its
30 m laser. The sensor model is the likelihood field ``localize run`` builds with its defaults
(``pipeline.make_sensor`` with ``settings.DEFAULTS``; the beams kept by ``max_beams``).

    python benchmarks/bench_placesearch.py [--write]
    python benchmarks/bench_placesearch.py --sigma 0.5 0.35 0.25 0.15 --draw 778   # the coarse model's blur, on
                                                                                   # another draw of buildings

To compare two versions of the search, run each checkout's own copy of this
script: it measures the ``localize`` beside it (printed on stderr).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import bench_global as bg  # noqa: E402
import bench_state as bs  # noqa: E402
from _util import announce  # noqa: E402

from localize import maps, pipeline, settings  # noqa: E402
from localize.geometry import angle_diff  # noqa: E402
from localize.placesearch import COARSE_SIGMA, best_places, coarse_model  # noqa: E402
from localize.raycast import RayCaster  # noqa: E402

POSES = 25
N_BEST = 16
#: The seed of the buildings' draw (the first entry of each building's seed; the reported table's).
DRAW = 777


def _model(grid, max_range: float):
    """The likelihood field ``localize run`` builds with its defaults (its beams kept by ``max_beams``)."""
    d = settings.DEFAULTS
    return pipeline.make_sensor("likelihood", grid, max_range, np.zeros(3), temper=d["temper"],
                                sigma_hit=d["sigma_hit"], z_short=d["z_short"], min_range=d["min_range"],
                                max_beams=d["beams"])


def _search(grid, lf, coarse, truths, angles, rng) -> tuple[int, int, float]:
    """``(found among n_best, found first, seconds of search)`` over the poses ``truths``."""
    caster = RayCaster(grid, lf.max_range)
    found = first = 0
    seconds = 0.0
    for i, x in enumerate(truths):
        z = np.clip(caster.cast(x[None], angles)[0] + rng.normal(0.0, 0.02, len(angles)), 0.01, lf.max_range)
        t0 = time.perf_counter()
        places, _ = best_places(grid, lf, (z, angles), np.random.default_rng(i), coarse=coarse, n_best=N_BEST)
        seconds += time.perf_counter() - t0
        dth = np.abs(angle_diff(places[:, 2], x[2]))
        hit = (np.hypot(*(places[:, :2] - x[:2]).T) < 0.3) & (dth < 0.1)
        found += bool(hit.any())
        first += bool(hit[:1].any())
    return found, first, seconds


def measure(sigma: float = COARSE_SIGMA, draw: int = DRAW) -> list[dict]:
    """One row per building kind and laser, and one for ``bench_cli``'s map: the search with a coarse model
    blurred by ``sigma`` (its lattice ``2 * sigma`` apart), on the buildings of the draw ``draw``."""
    rows = []
    for kind in bs.KINDS:
        for laser, (_, _, max_range) in bs.LASERS.items():
            rng = np.random.default_rng([draw, bs.KINDS.index(kind), list(bs.LASERS).index(laser)])
            grid = bs.make_map(kind, rng)
            lf = _model(grid, max_range)
            found, first, seconds = _search(grid, lf, coarse_model(grid, lf, sigma), grid.sample_free(POSES, rng),
                                            bs.laser_angles(laser), rng)
            rows.append({"map": kind, "laser": laser, "poses": POSES, "found": found, "first": first,
                         "ms": 1000.0 * seconds / POSES})
    rng = np.random.default_rng(16831 if draw == DRAW else [16831, draw])
    grid = maps.benchmark_map(800, 0.1)
    lf = _model(grid, 30.0)
    found, first, seconds = _search(grid, lf, coarse_model(grid, lf, sigma), grid.sample_free(POSES, rng),
                                    np.linspace(-np.pi / 2, np.pi / 2, 180), rng)
    rows.append({"map": "bench_cli (80 x 80 m)", "laser": "cmu-180", "poses": POSES, "found": found, "first": first,
                 "ms": 1000.0 * seconds / POSES})
    return rows


def report(rows: list[dict]) -> str:
    lines = ["## bench_placesearch", "",
             f"`placesearch.best_places` with the command line's default likelihood field ({settings.DEFAULTS['beams']} beams), {N_BEST} "
             f"places per search, {POSES} poses per map and laser (`python benchmarks/bench_placesearch.py`). "
             "Found: the robot's place (0.3 m, 0.1 rad) among the places; first: the best of them.", "",
             "| map | laser | poses | found | first | ms per search |", "|---|---|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['map']} | {r['laser']} | {r['poses']} | {r['found']} | {r['first']} | {r['ms']:.1f} |")
    g = _generated(rows)
    lines.append(f"| all generated | | {g['poses']} | {g['found']} | {g['first']} | {g['ms']:.1f} |")
    return "\n".join(lines) + "\n"


def _generated(rows: list[dict]) -> dict:
    """The generated buildings' rows of :func:`measure` (all but ``bench_cli``'s map, the last) added up: poses, found
    and first summed, milliseconds per search averaged."""
    small = rows[:-1]
    return {"poses": sum(r["poses"] for r in small), "found": sum(r["found"] for r in small),
            "first": sum(r["first"] for r in small), "ms": float(np.mean([r["ms"] for r in small]))}


def sweep(sigmas: list[float], draw: int) -> str:
    """A table of the search with each coarse blur in ``sigmas``: found and first over the generated buildings,
    and the time per search there and on ``bench_cli``'s map."""
    lines = [f"Coarse blur against recall, on the buildings of draw {draw} ({POSES} poses per map and laser; found "
             "and first as above; `python benchmarks/bench_placesearch.py --sigma ... --draw "
             f"{draw}`).", "",
             "| sigma (m) | lattice (m) | found, generated | first, generated | ms per search, generated | "
             "found, bench_cli | ms per search, bench_cli |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for sigma in sigmas:
        rows = measure(sigma, draw)
        g, big = _generated(rows), rows[-1]
        lines.append(f"| {sigma:g} | {2 * sigma:g} | {g['found']} of {g['poses']} | {g['first']} | {g['ms']:.1f} | "
                     f"{big['found']} of {big['poses']} | {big['ms']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write", action="store_true", help="write the bench_placesearch section of RESULTS.md")
    ap.add_argument("--sigma", type=float, nargs="+", metavar="M",
                    help="instead of the table: recall and time with each of these coarse blurs (m)")
    ap.add_argument("--draw", type=int, default=DRAW, help=f"the buildings' draw (default {DRAW}: the table's)")
    args = ap.parse_args(argv)
    if args.write and (args.sigma or args.draw != DRAW):
        ap.error("--write writes the default table: leave out --sigma and --draw")
    if args.sigma and not all(np.isfinite(v) and v > 0 for v in args.sigma):
        ap.error(f"--sigma takes blurs in metres above 0; got {' '.join(f'{v:g}' for v in args.sigma)}")
    announce()
    if args.sigma:
        print(sweep(args.sigma, args.draw))
        return 0
    text = report(measure(draw=args.draw))
    print(text)
    if args.write:
        bg.write_section(text, "bench_placesearch")
    return 0


if __name__ == "__main__":
    sys.exit(main())
