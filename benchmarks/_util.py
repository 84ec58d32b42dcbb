"""Small timing helpers shared by the benchmark scripts (not a test utility)."""

from __future__ import annotations

import json
import multiprocessing as mp
import sys
import time
from pathlib import Path
from typing import Callable


def best_of(fn: Callable[[], object], repeat: int = 5, number: int = 1) -> float:
    """Best wall time in seconds of ``number`` calls of ``fn``, over ``repeat`` rounds."""
    fn()  # warm-up (caches, lazy imports)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def table(rows: list[dict], columns: list[str]) -> str:
    """Render rows as a Markdown table."""
    head = "| " + " | ".join(columns) + " |"
    sep = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(str(r.get(c, "")) for c in columns) + " |" for r in rows]
    return "\n".join([head, sep, *body])


def _claim(path: Path):
    """``path`` opened empty for writing, and locked: a second benchmark given the same file stops with a clear
    error instead of interleaving its rows with the first one's (two writers corrupt JSON lines silently)."""
    sink = open(path, "a")
    try:
        import fcntl
    except ImportError:          # not POSIX: no lock, as before
        fcntl = None
    if fcntl is not None:
        try:
            fcntl.flock(sink.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            sink.close()
            raise SystemExit(f"{path} is being written by another benchmark process; give this run another --json file") from None
    sink.truncate(0)
    return sink


def announce() -> None:
    """Say on stderr which checkout is measured: each script puts its own first on the path, before PYTHONPATH."""
    import localize

    print(f"measuring localize {localize.__version__} from {Path(localize.__file__).parent}", file=sys.stderr)


def run_jobs(run_one: Callable[[dict], dict], jobs: list[dict], workers: int = 2,
             json_path: Path | None = None) -> list[dict]:
    """``run_one`` on every job, in ``workers`` forked processes when more than one; the rows in the order they
    finish, each also appended to ``json_path`` (JSON lines) at once, so that a run cut short keeps what it did."""
    announce()
    rows: list[dict] = []
    sink = _claim(Path(json_path)) if json_path else None

    def keep(row: dict) -> None:
        rows.append(row)
        if sink:
            sink.write(json.dumps(row) + "\n")
            sink.flush()

    try:
        if workers > 1:
            with mp.get_context("fork").Pool(workers) as pool:
                for row in pool.imap_unordered(run_one, jobs, chunksize=1):
                    keep(row)
        else:
            for job in jobs:
                keep(run_one(job))
    finally:
        if sink:
            sink.close()
    return rows


def best_wall_cpu(fn: Callable[[], object], repeats: int = 5) -> tuple[float, float]:
    """Best wall-clock and best CPU seconds of one call of ``fn`` over ``repeats`` calls (after a warm-up).

    CPU time (this process only) is the fairer number on a shared machine.
    """
    fn()
    walls, cpus = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return min(walls), min(cpus)


def scan_scene(n_poses: int = 10_000, n_beams: int = 60, seed: int = 0, resolution: float = 0.05):
    """The scene of the ray-casting and sensor speed targets.

    Returns ``(grid, poses, angles, rng)``: ``benchmark_map(800, resolution)``
    (5 cm cells: 40 m x 40 m; 10 cm: the Wean Hall map's 80 m x 80 m),
    ``n_poses`` poses drawn uniformly over its free space, ``n_beams`` beam
    angles over 180 degrees, and the generator (to draw more from the same stream).
    """
    import numpy as np

    from localize.maps import benchmark_map

    grid = benchmark_map(800, resolution)
    rng = np.random.default_rng(seed)
    poses = grid.sample_free(n_poses, rng)
    angles = np.linspace(-np.pi / 2, np.pi / 2, n_beams)
    return grid, poses, angles, rng
