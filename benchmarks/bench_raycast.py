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
from _util import best_wall_cpu, scan_scene  # benchmarks/ is on sys.path when run as a script

from localize.raycast import RayCaster, build_table

N_POSES, N_BEAMS, MAX_RANGE = 10_000, 60, 10.0


def main() -> None:
    grid, poses, angles, rng = scan_scene(N_POSES, N_BEAMS)
    rays = N_POSES * N_BEAMS
    rows = []

    march = RayCaster(grid, MAX_RANGE, "march")
    w, c = time.perf_counter(), time.process_time()
    march.clearance  # noqa: B018 - build the cache
    rows.append(("march: clearance field", time.perf_counter() - w, time.process_time() - c, None))
    w, c = best_wall_cpu(lambda: march.cast(poses, angles), 5)
    rows.append(("march: 10,000 x 60", w, c, rays))

    w, c = time.perf_counter(), time.process_time()
    table = build_table(grid, MAX_RANGE, n_bins=360)
    rows.append(("lut: build 360 bins", time.perf_counter() - w, time.process_time() - c, None))
    lut = RayCaster(grid, MAX_RANGE, "lut", n_bins=360)
    lut.__dict__["table"] = table  # reuse the table just built
    w, c = best_wall_cpu(lambda: lut.cast(poses, angles, dtype=np.float32), 10)
    rows.append(("lut: 10,000 x 60 (float32 out)", w, c, rays))
    w, c = best_wall_cpu(lambda: lut.cast(poses, angles), 10)
    rows.append(("lut: 10,000 x 60 (float64 out)", w, c, rays))

    exact = RayCaster(grid, MAX_RANGE, "exact")
    sub = poses[:100]
    w, c = best_wall_cpu(lambda: exact.cast(sub, angles), 1)
    rows.append(("exact (oracle): 100 x 60", w, c, 100 * N_BEAMS))

    print(f"Ray casting on benchmark_map(800), max_range {MAX_RANGE} m, {N_POSES} poses x {N_BEAMS} beams\n")
    print("| task | wall [ms] | CPU [ms] | M rays/s (CPU) |")
    print("|---|---:|---:|---:|")
    for name, wall, cpu, n in rows:
        rate = f"{n / cpu / 1e6:.2f}" if n and cpu > 0 else ""
        print(f"| {name} | {wall * 1e3:.1f} | {cpu * 1e3:.1f} | {rate} |")


if __name__ == "__main__":
    main()
