"""Measurement-model speed on the 800 x 800 benchmark map (issue 5 targets).

    python benchmarks/bench_sensors.py

10,000 poses x 60 beams. Prints a Markdown table of the best of a few
repeats, wall-clock and CPU time (the CPU column is the fairer one on a
shared machine). Targets: likelihood field >= 100 M beams/s; beam-model scan
log-likelihood of 10,000 x 60 beams in under 15 ms given the expected ranges.
"""

from __future__ import annotations

import numpy as np
from _util import best_wall_cpu, scan_scene  # benchmarks/ is on sys.path when run as a script

from localize.raycast import RayCaster
from localize.sensors import BeamModel, LikelihoodField

N_POSES, N_BEAMS, MAX_RANGE = 10_000, 60, 10.0


def main() -> None:
    grid, poses, angles, rng = scan_scene(N_POSES, N_BEAMS)
    beams = N_POSES * N_BEAMS
    caster = RayCaster(grid, MAX_RANGE, "march")
    bm = BeamModel(grid, MAX_RANGE, caster=caster)
    scan = bm.sample(poses[:1], angles, rng)[0]
    expected32 = caster.cast(poses, angles, dtype=np.float32)
    expected64 = expected32.astype(float)
    rows = []
    w, c = best_wall_cpu(lambda: bm.log_likelihood_expected(scan, expected32), 10)
    rows.append(("beam model, given expected ranges (float32)", w, c))
    w, c = best_wall_cpu(lambda: bm.log_likelihood_expected(scan, expected64), 10)
    rows.append(("beam model, given expected ranges (float64)", w, c))
    lf = LikelihoodField(grid, MAX_RANGE, 0.9, 0.1, sigma_hit=0.2)
    z = np.minimum(scan, MAX_RANGE - 1e-3)  # every beam returns: the worst case for the field
    w, c = best_wall_cpu(lambda: lf.log_likelihood(poses, z, angles), 10)
    rows.append(("likelihood field, whole scan", w, c))
    lf32 = LikelihoodField(grid, MAX_RANGE, 0.9, 0.1, sigma_hit=0.2, dtype=np.float32)
    w, c = best_wall_cpu(lambda: lf32.log_likelihood(poses, z, angles), 10)
    rows.append(("likelihood field, whole scan, dtype=float32 (float32 sums)", w, c))
    print(f"Measurement models on benchmark_map(800), {N_POSES} poses x {N_BEAMS} beams\n")
    print("| task | wall [ms] | CPU [ms] | M beams/s (CPU) |")
    print("|---|---:|---:|---:|")
    for name, wall, cpu in rows:
        print(f"| {name} | {wall * 1e3:.2f} | {cpu * 1e3:.2f} | {beams / cpu / 1e6:.0f} |")


if __name__ == "__main__":
    main()
