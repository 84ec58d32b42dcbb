"""Motion-model speed: sampling and densities for 10^6 poses, and the widget redraw.

    python benchmarks/bench_motion.py [--n 1000000] [--repeat 7]

Prints a Markdown table with the best-of-``repeat`` wall time and CPU time
(``time.process_time``, which other processes on a shared machine disturb
less) of each operation, and its target from issue 4:

* ``sample_odometry`` of 10^6 particles: < 100 ms
* ``odometry_pdf`` of 10^6 poses: < 150 ms
* a widget redraw (new alphas -> 500 samples + density grid -> PNG): < 100 ms

The readable one-pose-at-a-time versions are timed on 2,000 poses and
scaled, to show what vectorising buys.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

from localize import motion as m  # noqa: E402
from localize.widgets import motion as wm  # noqa: E402


def best(fn, repeat: int) -> tuple[float, float]:
    """Best wall and best CPU time in seconds over ``repeat`` calls (after one warm-up)."""
    fn()
    wall = cpu = float("inf")
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - w0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1_000_000, help="number of poses")
    ap.add_argument("--repeat", type=int, default=7, help="timed repetitions (the best is reported)")
    args = ap.parse_args(argv)
    n = args.n
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(0, 20, n), rng.uniform(0, 20, n), rng.uniform(-np.pi, np.pi, n)])
    u = ([1.0, 2.0, 0.3], [1.5, 2.2, 0.5])
    a4 = [0.05, 0.02, 0.02, 0.05]
    a6 = [0.02, 0.01, 0.02, 0.02, 0.01, 0.02]
    succ = m.sample_odometry(poses, u, a4, rng)
    succ_v = m.sample_velocity(poses, (1.0, 0.5), 0.1, a6, rng)
    one = poses[0]
    succ_one = succ - poses + one

    rows = []

    def add(name, fn, target_ms=None, scale=1.0):
        wall, cpu = best(fn, args.repeat)
        wall, cpu = wall * scale * 1e3, cpu * scale * 1e3
        ok = "" if target_ms is None else ("yes" if wall < target_ms else ("CPU only" if cpu < target_ms else "no"))
        rows.append((name, f"{wall:.1f}", f"{cpu:.1f}", "" if target_ms is None else f"< {target_ms}", ok))

    add(f"sample_odometry, {n:,} particles", lambda: m.sample_odometry(poses, u, a4, rng), 100)
    add(f"odometry_pdf, {n:,} poses (N prev poses)", lambda: m.odometry_pdf(succ, u, poses, a4), 150)
    add(f"odometry_pdf, {n:,} poses (one prev pose)", lambda: m.odometry_pdf(succ_one, u, one, a4))
    add(f"sample_velocity, {n:,} particles", lambda: m.sample_velocity(poses, (1.0, 0.5), 0.1, a6, rng))
    add(f"velocity_pdf, {n:,} poses", lambda: m.velocity_pdf(succ_v, (1.0, 0.5), poses, 0.1, a6))
    k = 2000
    add(f"readable sample_motion_model_odometry (x{n // k} of {k:,})",
        lambda: [m.sample_motion_model_odometry(poses[i], u, a4, rng) for i in range(k)], scale=n / k)
    add(f"readable motion_model_odometry (x{n // k} of {k:,})",
        lambda: [m.motion_model_odometry(succ[i], u, poses[i], a4) for i in range(k)], scale=n / k)

    view = wm.OdometryCloudView(n=500)
    alphas = iter(np.linspace(0.01, 0.3, 10_000))

    def redraw():
        view.update(next(alphas), 0.01, 0.02, 0.02)
        return view.png()

    add("widget redraw: odometry, 500 samples + 80x80 density -> PNG", redraw, 100)
    vview = wm.VelocityCloudView(n=500)

    def vredraw():
        vview.update(next(alphas) * 0.3, 0.01, 0.01, 0.01, 0.01, 0.01, 1.0, 0.8)
        return vview.png()

    add("widget redraw: velocity, 500 samples + 60x60x16 density -> PNG", vredraw, 100)
    add("(for comparison) new odometry figure + full PNG render",
        lambda: wm.figure_png(wm.odometry_cloud_figure(next(alphas))))

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"Motion models: best of {args.repeat}, {os.cpu_count()} cores, load average {load:.1f} "
          "(timings on a busy machine are inflated; CPU time is less affected)\n")
    print("| operation | wall [ms] | CPU [ms] | target [ms] | met |")
    print("|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
