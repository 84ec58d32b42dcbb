"""Foundations: occupancy-grid transforms, distance field and free-space sampling.

    python benchmarks/bench_grid.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import best_of, table  # noqa: E402

from localize import OccupancyGrid, maps  # noqa: E402


def main() -> None:
    g = maps.benchmark_map(800)
    rng = np.random.default_rng(0)
    pts = g.sample_free(1_000_000, rng)
    rows = []
    t = best_of(lambda: g.world_to_cell(pts))
    rows.append({"operation": "world_to_cell, 1e6 points", "time [ms]": f"{t * 1e3:.1f}",
                 "rate": f"{1e6 / t / 1e6:.0f} M points/s"})
    t = best_of(lambda: OccupancyGrid(g.data, g.resolution).distance_field, repeat=3)
    rows.append({"operation": "distance field, 800 x 800 (scipy EDT)", "time [ms]": f"{t * 1e3:.1f}", "rate": ""})
    t = best_of(lambda: g.sample_free(100_000, rng))
    rows.append({"operation": "sample_free, 1e5 poses", "time [ms]": f"{t * 1e3:.1f}",
                 "rate": f"{1e5 / t / 1e6:.1f} M poses/s"})
    print(table(rows, ["operation", "time [ms]", "rate"]))


if __name__ == "__main__":
    main()
