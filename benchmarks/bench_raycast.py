"""Ray-casting speed on the 800 x 800 benchmark map (issue 5 targets).

    python benchmarks/bench_raycast.py

Casts 10,000 poses x 60 beams with each method of :mod:`localize.raycast` and
prints a Markdown table. Times are the best of a few repeats, both wall-clock
and CPU time of this process (the CPU column is the fairer one on a machine
shared with other jobs). ``"exact"`` is the readable oracle, timed on a
subset and extrapolated. Targets: march >= 3.5 M rays/s, lut >= 100 M rays/s,
lut table built in seconds.
"""

from __future__ import annotations

import time

import numpy as np
from _util import best_wall_cpu  # noqa: E402  (benchmarks/ is on sys.path when run as a script)

from localize.maps import benchmark_map
from localize.raycast import RayCaster, build_table

N_POSES, N_BEAMS, MAX_RANGE = 10_000, 60, 10.0


def best(fn, repeats: int = 5) -> tuple[float, float]:
    """Best wall and CPU seconds over ``repeats`` calls (after one warm-up call)."""
    return best_wall_cpu(fn, repeats)


def main() -> None:
    grid = benchmark_map(800)
    rng = np.random.default_rng(0)
    poses = grid.sample_free(N_POSES, rng)
    angles = np.linspace(-np.pi / 2, np.pi / 2, N_BEAMS)
    rays = N_POSES * N_BEAMS
    rows = []

    march = RayCaster(grid, MAX_RANGE, "march")
    w, c = time.perf_counter(), time.process_time()
    march.clearance  # noqa: B018 - build the cache
    rows.append(("march: clearance field", time.perf_counter() - w, time.process_time() - c, None))
    w, c = best(lambda: march.cast(poses, angles))
    rows.append(("march: 10,000 x 60", w, c, rays))

    w, c = time.perf_counter(), time.process_time()
    table = build_table(grid, MAX_RANGE, n_bins=360)
    rows.append(("lut: build 360 bins", time.perf_counter() - w, time.process_time() - c, None))
    lut = RayCaster(grid, MAX_RANGE, "lut", n_bins=360)
    lut.__dict__["table"] = table  # reuse the table just built
    w, c = best(lambda: lut.cast(poses, angles, dtype=np.float32), repeats=10)
    rows.append(("lut: 10,000 x 60 (float32 out)", w, c, rays))
    w, c = best(lambda: lut.cast(poses, angles), repeats=10)
    rows.append(("lut: 10,000 x 60 (float64 out)", w, c, rays))

    exact = RayCaster(grid, MAX_RANGE, "exact")
    sub = poses[:100]
    w, c = best(lambda: exact.cast(sub, angles), repeats=1)
    rows.append(("exact (oracle): 100 x 60", w, c, 100 * N_BEAMS))

    print(f"Ray casting on benchmark_map(800), max_range {MAX_RANGE} m, {N_POSES} poses x {N_BEAMS} beams\n")
    print("| task | wall [ms] | CPU [ms] | M rays/s (CPU) |")
    print("|---|---:|---:|---:|")
    for name, wall, cpu, n in rows:
        rate = f"{n / cpu / 1e6:.2f}" if n and cpu > 0 else ""
        print(f"| {name} | {wall * 1e3:.1f} | {cpu * 1e3:.1f} | {rate} |")


if __name__ == "__main__":
    main()
