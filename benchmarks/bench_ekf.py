"""Time per filter step: EKF, UKF and MCL on the same landmark runs.

    python benchmarks/bench_ekf.py [--seeds 5]

Runs the filters of ``localize.compare`` on simulated runs of the tracking
scenario (identified landmarks) and of the global-localization scenario
(landmarks that look alike), and prints a Markdown table of the wall-clock
time per step (median over seeds) and its ratio to the EKF's. The chapter
"MCL versus the EKF" quotes these numbers; the book itself never prints a
timing. Numbers measured while other jobs share the CPU are noisy.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np

from localize import compare as C


def time_per_step(sc: C.Scenario, name: str, seeds) -> float:
    """Median over seeds of the seconds per step spent inside one filter's steps."""
    out = []
    for s in seeds:
        data = C.simulate(sc, np.random.default_rng(1000 + s))
        run = C.run_filters(sc, s, filters=(name,), data=data)
        out.append(run.seconds[name] / len(run.truth))
    return float(np.median(out))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=5, help="runs per configuration (default 5)")
    args = ap.parse_args(argv)
    seeds = range(args.seeds)
    t0 = time.perf_counter()
    rows = []
    for key, label in (("tracking", "identified landmarks"), ("global", "landmarks look alike")):
        base = C.scenario(key)
        ekf = time_per_step(base, "EKF", seeds)
        rows.append((label, "EKF", "", ekf, 1.0))
        ukf = time_per_step(base, "UKF", seeds)
        rows.append((label, "UKF", "", ukf, ukf / ekf))
        for n in (300, 1000, 3000):
            m = time_per_step(C.scenario(key, n_particles=n), "MCL", seeds)
            rows.append((label, "MCL", str(n), m, m / ekf))
    print(f"Python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}; "
          f"median of {args.seeds} runs of {C.scenario('tracking').n_steps} steps")
    print()
    print("| sightings | filter | particles | time per step [ms] | × EKF |")
    print("|---|---|---|---|---|")
    for label, f, n, sec, ratio in rows:
        print(f"| {label} | {f} | {n} | {1e3 * sec:.2f} | {ratio:.1f} |")
    print()
    print(f"(total {time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
