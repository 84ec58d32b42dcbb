"""Speed of the histogram filters: ``python benchmarks/bench_histogram.py``.

Targets (issue 3):

* a histogram update (tile world ``sense`` / ``move``) costs at most 50 ns per
  cell per observation;
* one update (predict + correct) of a 200 x 200 x 72 (x, y, theta) grid takes
  under one second;
* each widget redraw (callback plus PNG rendering) takes under 100 ms.

Prints Markdown tables. Wall-clock times on a shared machine: compare them with
the targets, not with each other to the last digit.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import best_of, table  # noqa: E402

from localize import OccupancyGrid, discrete, histogram  # noqa: E402
from localize.gridloc import GridLocalizer  # noqa: E402
from localize.maps import random_rooms  # noqa: E402


def bench_tile_world(sizes=(100, 300, 1000)) -> list[dict]:
    rng = np.random.default_rng(0)
    rows = []
    for n in sizes:
        world = rng.integers(0, 4, size=(n, n))
        belief = discrete.uniform(world.shape)
        k = histogram.noisy_step_kernel("left")
        cells = world.size
        cases = {
            "sense": lambda b=belief, w=world: histogram.sense(b, w, 2, 0.85, 0.15),
            "move (perfect)": lambda b=belief: histogram.move(b, "left", fill=1e-3),
            "move (3x3 kernel)": lambda b=belief, k=k: histogram.move(b, "left", k, fill=1e-3),
            "sense + move (3x3)": lambda b=belief, w=world, k=k: histogram.move(
                histogram.sense(b, w, 2, 0.85, 0.15), "left", k),
        }
        for name, fn in cases.items():
            t = best_of(fn, repeat=5)
            ns = t / cells * 1e9
            rows.append({"grid": f"{n} x {n}", "operation": name, "time [ms]": f"{t * 1e3:.2f}",
                         "ns / cell": f"{ns:.1f}", "target <= 50 ns": "ok" if ns <= 50 else "SLOW"})
    return rows


def bench_gridloc() -> list[dict]:
    rows = []
    for (h, w, K, B) in [(100, 100, 36, 8), (200, 200, 72, 8), (200, 200, 72, 16)]:
        g = random_rooms((h, w), 0.05, np.random.default_rng(1), n_boxes=15)
        loc = GridLocalizer(g, K, np.linspace(-np.pi, np.pi, B, endpoint=False), 4.0,
                            expected=np.full((K, h, w), 2.0, dtype=np.float32))
        z = np.full(B, 1.5)
        u = np.array([[0.0, 0.0, 0.0], [0.2, 0.02, 0.1]])
        tp = best_of(lambda loc=loc, u=u: loc.predict(u), repeat=3)
        tu = best_of(lambda loc=loc, z=z: loc.update(z), repeat=3)
        tot = tp + tu
        rows.append({"grid": f"{w} x {h} x {K}", "beams": B, "cells": f"{loc.n_cells:,}",
                     "predict [ms]": f"{tp * 1e3:.0f}", "update [ms]": f"{tu * 1e3:.0f}",
                     "ns / cell": f"{tot / loc.n_cells * 1e9:.0f}",
                     "target < 1 s (200x200x72)": ("ok" if tot < 1 else "SLOW") if (h, K) == (200, 72) else ""})
    return rows


def bench_table_build() -> list[dict]:
    from localize.gridloc import expected_range_table

    g = random_rooms((200, 200), 0.05, np.random.default_rng(1), n_boxes=15)
    t = best_of(lambda: expected_range_table(g, 72, 4.0, method="lut"), repeat=1)
    return [{"map": "200 x 200", "headings": 72, "method": "lut", "build [s]": f"{t:.2f}"}]


def bench_widgets() -> list[dict]:
    from localize.widgets import histogram as wh

    rows = []
    for name, demo in wh.DEMOS.items():
        def redraw(demo=demo):
            fig = demo()
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
            plt.close(fig)
        t = best_of(redraw, repeat=5)
        rows.append({"widget": name, "redraw [ms]": f"{t * 1e3:.0f}", "target < 100 ms": "ok" if t < 0.1 else "SLOW"})
    return rows


def main() -> int:
    print("## Tile-world histogram filter (per cell per observation)\n")
    print(table(bench_tile_world(), ["grid", "operation", "time [ms]", "ns / cell", "target <= 50 ns"]))
    print("\n## (x, y, theta) grid localization: one predict + one update\n")
    print(table(bench_gridloc(), ["grid", "beams", "cells", "predict [ms]", "update [ms]", "ns / cell",
                                  "target < 1 s (200x200x72)"]))
    print("\n## Expected-range table (once per map)\n")
    print(table(bench_table_build(), ["map", "headings", "method", "build [s]"]))
    print("\n## Widget redraws (callback + PNG at 100 dpi)\n")
    print(table(bench_widgets(), ["widget", "redraw [ms]", "target < 100 ms"]))
    _ = OccupancyGrid  # imported for readers who adapt the script
    return 0


if __name__ == "__main__":
    sys.exit(main())
