"""Ray-casting speed and accuracy on 800 x 800 benchmark maps (issues 5 and 19).

    taskset -c 1 python benchmarks/bench_raycast.py

Three tables, 10,000 poses x 60 beams each, times the best of several
repeats (wall-clock and CPU time of this process; the CPU column is the
fairer one on a machine shared with other jobs):

1. **Tables on a building-sized map** (``benchmark_map(800, 0.1)``: 80 m x
   80 m at 10 cm like the Wean Hall map, 30 m maximum range): the 16-bit
   ``"lut"`` table at 360 bins beside the ``"compact"`` table (issue 19
   targets: <= 100 MB, build <= 2 s, ``BeamModel.log_likelihood`` >= 100 M
   beams/s), and each one's error against the exact caster on a subset.
2. **Ray marching** (``benchmark_map(800)``, 5 cm, 10 m as in issue 5):
   ``RayCaster(method="march")`` beside a plain 15-line numpy marcher
   (:func:`plain_march`), in alternating runs (target: >= 1.5x the plain one).
3. The issue 5 rows on the same 5 cm map (march, lut, the exact oracle).
"""

from __future__ import annotations

import time

import numpy as np
from _util import best_wall_cpu, scan_scene  # benchmarks/ is on sys.path when run as a script
from scipy.ndimage import distance_transform_edt

from localize.raycast import RayCaster, build_compact_table, build_table
from localize.sensors import BeamModel

N_POSES, N_BEAMS = 10_000, 60


def plain_march(grid, edt, poses, angles, max_range):
    """A plain numpy marcher: float32 positions, step by the distance field, drop finished rays each round.

    ``edt``: Euclidean distance (cells) from each cell centre to the nearest
    obstacle centre. Fast and simple, but not exact: a step of the centre
    distance can cut a corner (within a cell of the exact range on ~99% of rays).
    """
    f32, res, (h, w) = np.float32, grid.resolution, grid.shape
    x = np.repeat(((poses[:, 0] - grid.origin[0]) / res).astype(f32), len(angles))
    y = np.repeat(((poses[:, 1] - grid.origin[1]) / res).astype(f32), len(angles))
    th = (poses[:, 2:3] + angles[None, :]).ravel()
    dx, dy, t = np.cos(th).astype(f32), np.sin(th).astype(f32), np.zeros(x.size, f32)
    out, ray, limit = np.full(x.size, max_range), np.arange(x.size), f32(max_range / res)
    while ray.size:
        i, j = np.floor(y).astype(np.int32), np.floor(x).astype(np.int32)
        inside = (i >= 0) & (i < h) & (j >= 0) & (j < w) & (t < limit)
        d = np.where(inside, edt[np.clip(i, 0, h - 1), np.clip(j, 0, w - 1)], f32(-1))
        out[ray[d == 0]] = t[d == 0] * res
        keep = d > 0
        x, y, dx, dy, t, ray, d = x[keep], y[keep], dx[keep], dy[keep], t[keep], ray[keep], d[keep]
        x += d * dx
        y += d * dy
        t += d
    return out.reshape(len(poses), len(angles))


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    value = fn()
    return value, time.perf_counter() - w, time.process_time() - c


def row(name, wall, cpu, n=None, extra=""):
    rate = f"{n / cpu / 1e6:.0f}" if n and cpu > 0 else ""
    return f"| {name} | {wall * 1e3:.1f} | {cpu * 1e3:.1f} | {rate} | {extra} |"


def tables_on_building(rows_out: list[str]) -> None:
    max_range = 30.0
    grid, poses, angles, rng = scan_scene(N_POSES, N_BEAMS, resolution=0.1)
    rays = N_POSES * N_BEAMS
    lut = RayCaster(grid, max_range, "lut", n_bins=360)
    table, w_lut, c_lut = timed(lambda: build_table(grid, max_range, 360))
    lut.__dict__["table"] = table
    compact = RayCaster(grid, max_range, "compact")
    ct, w_ct, c_ct = min((timed(lambda: build_compact_table(grid, max_range, compact.n_bins)) for _ in range(3)),
                         key=lambda r: r[2])
    compact.__dict__["compact_table"] = ct
    # error against the exact caster on a subset of the poses
    sub, sub_angles = poses[:500], angles
    exact = RayCaster(grid, max_range, "exact").cast(sub, sub_angles)
    res = grid.resolution
    errs = {}
    for name, rc, nb in (("lut", lut, 360), ("compact", compact, compact.n_bins)):
        e = np.abs(rc.cast(sub, sub_angles) - exact)
        code = max_range / 65535 if name == "lut" else max_range / 510
        bound = 2 * res + exact * np.pi / nb + code
        errs[name] = (np.median(e), np.quantile(e, 0.9), np.mean(e <= bound))
    scan = BeamModel(grid, max_range, method="exact").sample(poses[:1], angles, rng)[0]
    lines = [f"Building-sized map: benchmark_map(800, 0.1) (80 m x 80 m, {int((~grid.obstacles).sum()):,} open "
             f"cells), max_range {max_range:g} m, {N_POSES:,} poses x {N_BEAMS} beams\n",
             "| structure | heading bins | memory [MB] | build wall [s] | build CPU [s] | cast [M rays/s CPU] "
             "| BeamModel.log_likelihood [M beams/s CPU] | median error [m] | 90% error [m] | within bound |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, rc, nb, mem, wb, cb in (("lut (16-bit, all cells)", lut, 360, table.nbytes, w_lut, c_lut),
                                      ("compact (8-bit, open cells)", compact, compact.n_bins, ct.nbytes, w_ct, c_ct)):
        _, c_cast = best_wall_cpu(lambda rc=rc: rc.cast(poses, angles, dtype=np.float32), 10)
        model = BeamModel(grid, max_range, caster=rc)
        _, c_ll = best_wall_cpu(lambda model=model: model.log_likelihood(poses, scan, angles), 10)
        med, p90, within = errs[name.split()[0]]
        lines.append(f"| {name} | {nb} | {mem / 1e6:.0f} | {wb:.2f} | {cb:.2f} | {rays / c_cast / 1e6:.0f} "
                     f"| {rays / c_ll / 1e6:.0f} | {med:.3f} | {p90:.3f} | {within:.1%} |")
    lines.append(f"\nErrors against the exact caster on {len(sub) * len(sub_angles):,} rays; the bound is "
                 "2 cells + r pi / n_bins + the coding step (max_range / 65535 or / 510). Targets (compact): "
                 "memory <= 100 MB, build <= 2 s, log_likelihood >= 100 M beams/s.")
    rows_out += lines


def marchers(rows_out: list[str]) -> tuple:
    max_range = 10.0
    grid, poses, angles, _ = scan_scene(N_POSES, N_BEAMS)
    rays = N_POSES * N_BEAMS
    edt = distance_transform_edt(~grid.obstacles).astype(np.float32)
    march = RayCaster(grid, max_range, "march")
    _, w_field, c_field = timed(lambda: march._clearance8)
    lib, plain = [], []
    for _ in range(5):  # alternate, so that both see the same machine load
        lib.append(best_wall_cpu(lambda: march.cast(poses, angles, dtype=np.float32), 3))
        plain.append(best_wall_cpu(lambda: plain_march(grid, edt, poses, angles, max_range), 3))
    ratios = [p[1] / m[1] for m, p in zip(lib, plain)]
    exact = RayCaster(grid, max_range, "exact").cast(poses[:200], angles)
    err_lib = np.abs(march.cast(poses[:200], angles) - exact)
    err_plain = np.abs(plain_march(grid, edt, poses[:200], angles, max_range) - exact)
    best_lib, best_plain = min(c for _, c in lib), min(c for _, c in plain)
    rows_out += [
        f"Ray marching on benchmark_map(800) (5 cm), max_range {max_range:g} m, {N_POSES:,} poses x {N_BEAMS} "
        "beams, five alternating runs\n",
        "| marcher | CPU per run [ms] (5 runs) | best CPU [ms] | M rays/s (best) | max error vs exact [m] "
        "| within 1 cell of exact |",
        "|---|---|---:|---:|---:|---:|",
        f"| RayCaster(method=\"march\") | {' '.join(f'{c * 1e3:.0f}' for _, c in lib)} | {best_lib * 1e3:.0f} "
        f"| {rays / best_lib / 1e6:.1f} | {err_lib.max():.1e} | {np.mean(err_lib <= grid.resolution):.1%} |",
        f"| plain 15-line numpy marcher | {' '.join(f'{c * 1e3:.0f}' for _, c in plain)} | {best_plain * 1e3:.0f} "
        f"| {rays / best_plain / 1e6:.1f} | {err_plain.max():.2f} | {np.mean(err_plain <= grid.resolution):.1%} |",
        "",
        f"Speed-up of the library's marcher over the plain one, run by run: {' '.join(f'{r:.2f}x' for r in ratios)}; "
        f"best against best {best_plain / best_lib:.2f}x (target >= 1.5x). The library's marcher is exact "
        "(same cell as the cell walk); the plain one can cut corners.",
    ]
    return grid, poses, angles, march, (w_field, c_field)


def issue5_rows(rows_out: list[str], grid, poses, angles, march, field_times) -> None:
    max_range = 10.0
    rays = N_POSES * N_BEAMS
    rows = [row("march: clearance field", *field_times)]
    rows.append(row("march: 10,000 x 60", *best_wall_cpu(lambda: march.cast(poses, angles), 5), rays))
    table, w, c = timed(lambda: build_table(grid, max_range, n_bins=360))
    rows.append(row("lut: build 360 bins", w, c, extra=f"{table.nbytes / 1e6:.0f} MB"))
    lut = RayCaster(grid, max_range, "lut", n_bins=360)
    lut.__dict__["table"] = table  # reuse the table just built
    rows.append(row("lut: 10,000 x 60 (float32 out)", *best_wall_cpu(lambda: lut.cast(poses, angles, np.float32), 10),
                    rays))
    compact = RayCaster(grid, max_range, "compact")
    ct, w, c = timed(lambda: compact.compact_table)
    rows.append(row(f"compact: build {compact.n_bins} bins", w, c, extra=f"{ct.nbytes / 1e6:.0f} MB"))
    rows.append(row("compact: 10,000 x 60 (float32 out)",
                    *best_wall_cpu(lambda: compact.cast(poses, angles, np.float32), 10), rays))
    exact = RayCaster(grid, max_range, "exact")
    rows.append(row("exact (oracle): 100 x 60", *best_wall_cpu(lambda: exact.cast(poses[:100], angles), 1),
                    100 * N_BEAMS))
    rows_out += [f"Issue 5 rows: benchmark_map(800) (5 cm), max_range {max_range:g} m, {N_POSES:,} poses x {N_BEAMS} "
                 "beams\n", "| task | wall [ms] | CPU [ms] | M rays/s (CPU) | |", "|---|---:|---:|---:|---|", *rows]


def main() -> None:
    out: list[str] = []
    tables_on_building(out)
    out.append("")
    scene = marchers(out)
    out.append("")
    issue5_rows(out, *scene)
    print("\n".join(out))


if __name__ == "__main__":
    main()
