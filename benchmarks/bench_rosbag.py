"""Speed of the ROS bag path: writing a log as a bag, reading it back, and ``localize run`` on it.

The CMU-sized simulated log of ``bench_cli.py`` (700 scans x 180 beams over
135 s, 800 x 800 map) is written as a ROS 1 bag and as ROS 2 bags (sqlite3,
MCAP) with rosbags' writer; ``read_rosbag`` reads it back (deserialising every
LaserScan, Odometry and tf message in Python), and ``localize run`` localizes
from it with 1,000 particles, writing the result bag too. With the real data
present (``LOCALIZE_DATA``), the largest log, Freiburg 079 (4,791 scans x 360
beams), is read as well. No target was set; the numbers show what reading a
bag costs next to filtering it.

    python benchmarks/bench_rosbag.py
"""

from __future__ import annotations

import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from bench_cli import make_data  # noqa: E402

from localize import cli, io  # noqa: E402


def timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def main() -> int:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        map_path, log_path = make_data(folder)
        log = io.read_log(log_path)
        for storage in ("rosbag1", "sqlite3", "mcap"):
            bag = folder / ("bench.bag" if storage == "rosbag1" else f"bench_{storage}")
            _, t_write = timed(io.write_rosbag_log, bag, log, storage=storage, time_offset=1.0)
            back, t_read = timed(io.read_rosbag, bag)
            out = folder / f"out_{storage}"
            status, t_run = timed(cli.main, ["run", "--map", str(map_path), "--log", str(bag),
                                             "--particles", "1000", "--out", str(out), "--quiet"])
            assert status == 0 and (out / "summary.json").exists()
            rows.append((f"simulated CMU-sized ({len(log)} x {log.n_beams})", storage, t_write, t_read,
                         1000 * t_read / len(back), t_run, log.duration / t_run))
        data = os.environ.get("LOCALIZE_DATA")
        frb = Path(data) / "carmen" / "freiburg-079-corrected.log.gz" if data else None
        if frb is not None and frb.exists():
            big = io.read_log(frb)
            fixed = dataclasses.replace(big, times=1.0 + 0.1 * np.arange(len(big)))  # its clock is too coarse
            for storage in ("rosbag1", "mcap"):
                bag = folder / ("frb.bag" if storage == "rosbag1" else f"frb_{storage}")
                _, t_write = timed(io.write_rosbag_log, bag, fixed, storage=storage)
                back, t_read = timed(io.read_rosbag, bag)
                rows.append((f"Freiburg 079 ({len(big)} x {big.n_beams})", storage, t_write, t_read,
                             1000 * t_read / len(back), None, None))
    print("# bench_rosbag: ROS bags written with rosbags, read back, localized (1,000 particles)\n")
    print("| log | storage | write (s) | read_rosbag (s) | read per scan (ms) | localize run (s) | real-time factor |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name, storage, tw, tr, ms, trun, rtf in rows:
        run_txt = "-" if trun is None else f"{trun:.2f}"
        rtf_txt = "-" if rtf is None else f"{rtf:.1f}x"
        print(f"| {name} | {storage} | {tw:.2f} | {tr:.2f} | {ms:.2f} | {run_txt} | {rtf_txt} |")
    print("\n`localize run` counts reading the bag and the map, filtering, and writing trajectory.csv, "
          "trajectory.tum and the result bag. Measured on a shared machine: noisy.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
