"""Speed of the command-line localizer on a CMU-sized log, including reading the files.

A simulated robot drives for 135 s through the 800 x 800-cell benchmark map
(10 cm cells, like the Wean Hall map) and logs about 700 scans of 180 beams;
the map and the log are written in the CMU 16-831 formats, then
``localize run`` reads them and localizes globally, once with 1,000 and once
with 10,000 particles. The real-time factor is the log's duration divided by
the wall-clock time of the whole command (reading + filtering + writing).

Targets (issue 10): >= 10x real time with 1,000 particles, >= 1x with 10,000.

    python benchmarks/bench_cli.py
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from localize import cli, io, maps, sim


def make_data(folder: Path, n_scans: int = 700, duration: float = 135.0) -> tuple[Path, Path]:
    grid = maps.benchmark_map(800, 0.1)
    run = sim.range_run(grid, np.random.default_rng(16831), n_steps=n_scans, dt=duration / n_scans,
                        speed=0.5, sensor_offset=(0.25, 0.0, 0.0), max_range=30.0, n_clutter=20)
    map_path = io.write_cmu_map(folder / "bench.dat", grid)
    log_path = sim.write_cmu_log(folder / "bench.log", run)
    return map_path, log_path


def run_once(map_path: Path, log_path: Path, out: Path, particles: int, extra: list[str] | None = None) -> dict:
    t0 = time.perf_counter()
    status = cli.main(["run", "--map", str(map_path), "--log", str(log_path), "--particles", str(particles),
                       "--out", str(out), "--quiet", *(extra or [])])
    wall = time.perf_counter() - t0
    if status != 0:
        raise RuntimeError(f"localize run exited with {status}")
    summary = json.loads((out / "summary.json").read_text())
    summary["wall_s"] = wall
    return summary


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        map_path, log_path = make_data(folder)
        t_make = time.perf_counter() - t0
        log = io.read_log(log_path)
        rows = []
        for n, target, extra in [(1000, 10.0, []), (10000, 1.0, []), (1000, 10.0, ["--min-motion", "0", "0"]),
                                 (10000, 1.0, ["--min-motion", "0", "0"]), (1000, None, ["--sensor", "beam"]),
                                 (1000, None, ["--beams", "180", "--min-motion", "0", "0"])]:
            s = run_once(map_path, log_path, folder / f"out{n}", n, extra)
            rtf = log.duration / s["wall_s"]
            rows.append((n, " ".join(extra) or "defaults", s["scans"], s["scans_with_update"],
                         s["seconds_reading_files"], s["wall_s"], 1000 * s["seconds_per_scan"], rtf, target))
    print(f"# bench_cli: `localize run` on a CMU-sized log ({len(log)} scans x {log.n_beams} beams over "
          f"{log.duration:.0f} s, 800 x 800 map); data made in {t_make:.1f} s\n")
    print("| particles | options | scans | updates | reading files (s) | total wall (s) | ms per scan "
          "| real-time factor | target | ok |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|:--:|")
    for n, opt, k, ku, tr, wall, ms, rtf, target in rows:
        tgt = "-" if target is None else f"{target:g}x"
        ok = "-" if target is None else ("yes" if rtf >= target else "NO")
        print(f"| {n} | {opt} | {k} | {ku} | {tr:.2f} | {wall:.2f} | {ms:.1f} | {rtf:.1f}x | {tgt} | {ok} |")
    print("\nThe real-time factor counts everything the command does: reading both files, building the "
          "sensor model's table, filtering, writing the outputs. Measured on a shared machine: noisy.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
