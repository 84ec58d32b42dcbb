"""How much memory a filter run needs, how much the machine has, and refusing before allocating.

The command line calls :func:`check_memory` before it spreads the particles:
``--particles 100000000`` should be refused with a sentence (what the run
needs, what there is, what to change), not end in a ``MemoryError`` traceback
minutes into a run.

The estimate is per particle: the pose and weight arrays (a few dozen bytes)
plus, per beam, the temporaries of one sensor update (end points, cell
indices, distances and densities of an ``(N, B)`` evaluation); and per map
cell, the sensor model's tables (the likelihood field's distance field). The
constants were measured with :mod:`tracemalloc` on runs of 5 000-20 000
particles and 30-180 beams (likelihood field: 28-47 bytes per particle and
beam, about 300 per cell; beam model: 145-151 per particle and beam, 50 per
cell) and rounded up; ``tests/test_cli_faults.py`` holds the estimate above a
measured peak.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["BYTES_PER_PARTICLE", "BYTES_PER_PARTICLE_BEAM", "estimate_run_bytes", "available_memory",
           "check_memory", "format_bytes"]

#: Fixed bytes per particle: poses, weights, resampling indices and copies.
BYTES_PER_PARTICLE = 256
#: Bytes per particle and beam of one sensor update, by sensor model.
BYTES_PER_PARTICLE_BEAM = {"likelihood": 48, "beam": 160}
#: Bytes per map cell of the sensor model's precomputed tables (distance field, ...).
BYTES_PER_CELL = {"likelihood": 400, "beam": 64}


def estimate_run_bytes(n_particles: int, n_beams: int, sensor: str = "likelihood", n_cells: int = 0) -> int:
    """Peak memory (bytes) of a filter run: ``n_particles`` particles, ``n_beams`` beams, a map of ``n_cells``.

    Examples
    --------
    >>> format_bytes(estimate_run_bytes(10_000, 30))
    '16.2 MB'
    >>> format_bytes(estimate_run_bytes(100_000_000, 30, "beam", n_cells=800 * 800))
    '470.9 GB'
    """
    per_beam = BYTES_PER_PARTICLE_BEAM.get(sensor, max(BYTES_PER_PARTICLE_BEAM.values()))
    per_cell = BYTES_PER_CELL.get(sensor, max(BYTES_PER_CELL.values()))
    return int(n_particles) * (BYTES_PER_PARTICLE + int(n_beams) * per_beam) + int(n_cells) * per_cell


def _cgroup_room() -> int | None:
    """Bytes left under a cgroup v2 memory limit (containers), or None when unlimited / unknown."""
    base = Path("/sys/fs/cgroup")
    try:
        limit = (base / "memory.max").read_text().strip()
        if limit == "max":
            return None
        used = int((base / "memory.current").read_text().strip())
        return max(int(limit) - used, 0)
    except (OSError, ValueError):
        return None


def available_memory() -> int | None:
    """Bytes of memory a new allocation can use now (Linux ``MemAvailable``, cgroup limit), or None if unknown."""
    avail = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        avail = None
    if avail is None and hasattr(os, "sysconf"):
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError):
            avail = None
    room = _cgroup_room()
    if room is not None:
        avail = room if avail is None else min(avail, room)
    return avail


def format_bytes(n: float) -> str:
    """Bytes in the largest unit that keeps the number >= 1 (powers of 1024).

    Examples
    --------
    >>> format_bytes(512), format_bytes(3 * 1024**3)
    ('512 B', '3.0 GB')
    """
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")  # pragma: no cover


def check_memory(n_particles: int, n_beams: int, sensor: str = "likelihood", available: int | None = None,
                 option: str = "--particles", n_cells: int = 0) -> int:
    """Raise ``ValueError`` (not ``MemoryError``, later) when a run would not fit into memory; return the estimate.

    ``available`` defaults to :func:`available_memory`; when that is unknown
    the run is allowed. The message names ``option``, what the run needs, what
    there is and the largest particle count that fits.

    Examples
    --------
    >>> check_memory(1000, 30, available=10**9) < 10**9
    True
    >>> check_memory(10**8, 30, available=2 * 1024**3)
    Traceback (most recent call last):
    ...
    ValueError: --particles 100000000 needs about 158.0 GB of memory (30 beams, likelihood sensor), but only 2.0 GB is available: use at most about 1000000 particles, or fewer --beams
    """
    need = estimate_run_bytes(n_particles, n_beams, sensor, n_cells)
    have = available_memory() if available is None else int(available)
    if have is None or need <= have:
        return need
    per = estimate_run_bytes(1, n_beams, sensor)
    fit = max(int(0.8 * (have - estimate_run_bytes(0, n_beams, sensor, n_cells)) / per), 0)
    fit = int(float(f"{fit:.2g}")) if fit >= 100 else fit
    raise ValueError(f"{option} {n_particles} needs about {format_bytes(need)} of memory ({n_beams} beams, {sensor} "
                     f"sensor), but only {format_bytes(have)} is available: use at most about {fit} particles, "
                     "or fewer --beams")
