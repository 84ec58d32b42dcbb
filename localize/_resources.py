"""How much memory a filter run needs, how much the process may use, and refusing before allocating.

The command line calls :func:`check_memory` before it spreads the particles:
``--particles 100000000`` should be refused with a sentence (what the run
needs, what there is, what to change), not end in a ``MemoryError`` traceback
minutes into a run.

**What there is** (:func:`memory_room`) is the smallest of: the machine's
``MemAvailable``; the room left under a cgroup limit (v2 ``memory.max``, v1
``memory.limit_in_bytes``: containers); and the room left under the process's
own limits, ``RLIMIT_AS`` (``ulimit -v``) against the address space in use
(``VmSize``) and ``RLIMIT_DATA`` (``ulimit -d``) against ``VmData``.

**What a run needs** (:func:`estimate_run_bytes`) was measured, not guessed:
the peak of :mod:`tracemalloc` over a whole run (``localize_log`` on a
4-scan simulated log of 180-beam scans) for 2 000-300 000 particles, 30-180
beams and maps of 24 000 to 16 000 000 cells, by
``python tests/test_faults_memory.py`` (it prints the table and the fit).
Measured (December 2026, numpy 2):

* every run: about 5 MB whatever its size;
* likelihood field: 48 bytes per particle + 26.1 per particle and beam
  (300 000 x 30: 250 MB; 300 000 x 60: 485 MB; 100 000 x 180: 473 MB) and
  79-80 bytes per map cell (the distance field and its scipy temporaries:
  2000 x 2000 cells 320 MB, 4000 x 4000 1272 MB);
* beam model: about 410 bytes per particle + 13 per particle and beam
  (100 000 x 30: 92 MB, x 90: 170 MB); its compact ray-casting table is
  capped (90 MB, :func:`localize.raycast.compact_bins`) but its build costs
  500-720 bytes per cell on small maps and 60-75 on large ones (300 x 300:
  66 MB, 600 x 600: 195 MB, 2000 x 2000: 363 MB, 3000 x 3000: 676 MB).

Measured again at stop 62 (the same script): the map's cells cost more than
that, 97-98 bytes each with the likelihood field (2000 x 2000 cells 395 MB,
4000 x 4000 1555 MB) and up to 92 with the beam model (3000 x 3000: 826 MB),
and every run now also builds, per cell, the map's holes (unknown patches of
floor) and the place search's blurred likelihood field; runs with many
particles stay well below the per-particle constants (the sensor updates
work in chunks).
The constants below are those numbers rounded up by about 10%; over those 15
runs the estimate is 1.10 to 32 times the measured peak (1.10-1.27 where the
map's cells or the beam model dominate), never below it; the estimate of a
run on a 10 000 x 10 000 map with the likelihood field and 300 000 particles
is 10.2 GB (issue 39 measured 8.7 GB for such a run; the old constants said
37 GB), and ``tests/test_cli_faults.py`` holds the estimate above a
measured peak and within a factor 6 of it.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["BYTES_PER_PARTICLE", "BYTES_PER_PARTICLE_BEAM", "BYTES_PER_CELL", "estimate_run_bytes",
           "available_memory", "memory_room", "check_memory", "format_bytes", "BASE_BYTES"]

#: Fixed bytes per particle (poses, weights, resampling indices and copies), by sensor model.
BYTES_PER_PARTICLE = {"likelihood": 56, "beam": 448}
#: Bytes per particle and beam of one sensor update, by sensor model.
BYTES_PER_PARTICLE_BEAM = {"likelihood": 29, "beam": 15}
#: Bytes per map cell of the sensor model's precomputed tables, by sensor model.
BYTES_PER_CELL = {"likelihood": 107, "beam": 75}
#: Bytes of every run whatever its size (measured: 7.7 MB for 1000 particles and 30 beams on a 24 000-cell
#: map, of which 0.8 MB are the particles' and 2 MB the cells').
BASE_BYTES = 8 * 1024**2
#: The beam model's ray-casting table: bytes per cell while it is built, and the cap of the whole.
_TABLE_BUILD_PER_CELL, _TABLE_BUILD_CAP = 760, 220_000_000


def estimate_run_bytes(n_particles: int, n_beams: int, sensor: str = "likelihood", n_cells: int = 0) -> int:
    """Peak memory (bytes) of a filter run: ``n_particles`` particles, ``n_beams`` beams, a map of ``n_cells``.

    Examples
    --------
    >>> format_bytes(estimate_run_bytes(10_000, 30))
    '16.8 MB'
    >>> format_bytes(estimate_run_bytes(300_000, 30, n_cells=10_000 * 10_000))   # a 10 000 x 10 000 map
    '10.2 GB'
    >>> format_bytes(estimate_run_bytes(100_000_000, 30, "beam", n_cells=800 * 800))
    '83.9 GB'
    """
    kind = sensor if sensor in BYTES_PER_CELL else "beam"  # an unknown model: the dearer one
    n, b, c = int(n_particles), int(n_beams), int(n_cells)
    per_particle = BYTES_PER_PARTICLE[kind] + b * BYTES_PER_PARTICLE_BEAM[kind]
    tables = c * BYTES_PER_CELL[kind]
    if kind == "beam":
        tables += min(c * _TABLE_BUILD_PER_CELL, _TABLE_BUILD_CAP)
    return BASE_BYTES + n * per_particle + tables


_CGROUP = Path("/sys/fs/cgroup")


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _cgroup_room() -> int | None:
    """Bytes left under a cgroup memory limit (v2, else v1), or None when unlimited / unknown."""
    base = _CGROUP
    for limit_file, used_file in (("memory.max", "memory.current"),
                                  ("memory/memory.limit_in_bytes", "memory/memory.usage_in_bytes")):
        limit, used = _read_int(base / limit_file), _read_int(base / used_file)
        if limit is not None and used is not None and limit < 2**60:  # v1 writes about 2**63 for "none"
            return max(limit - used, 0)
    return None


def _process_status(field: str) -> int | None:
    """A ``kB`` field of ``/proc/self/status`` (``VmSize``, ``VmData``) in bytes, or None."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _rlimit_room() -> int | None:
    """Bytes left under the process's own limits (``ulimit -v``, ``ulimit -d``), or None when unlimited."""
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    rooms = []
    for limit, field in ((resource.RLIMIT_AS, "VmSize"), (resource.RLIMIT_DATA, "VmData")):
        soft = resource.getrlimit(limit)[0]
        if soft == resource.RLIM_INFINITY or soft < 0:
            continue
        used = _process_status(field)
        if used is not None:
            rooms.append(max(soft - used, 0))
    return min(rooms) if rooms else None


def _machine_available() -> int | None:
    avail = _process_status_meminfo()
    if avail is None and hasattr(os, "sysconf"):
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError):
            avail = None
    return avail


def _process_status_meminfo() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def memory_room() -> tuple[int | None, str]:
    """Bytes a new allocation can use now and what limits it: the machine, a cgroup, or the process's limit.

    Returns ``(None, "unknown")`` when nothing can be read.

    Examples
    --------
    >>> room, source = memory_room()
    >>> source in ("the machine's available memory", "the container's memory limit (cgroup)",
    ...            "the process's memory limit (ulimit -v / -d)", "unknown")
    True
    """
    rooms = [(r, s) for r, s in ((_machine_available(), "the machine's available memory"),
                                 (_cgroup_room(), "the container's memory limit (cgroup)"),
                                 (_rlimit_room(), "the process's memory limit (ulimit -v / -d)")) if r is not None]
    if not rooms:
        return None, "unknown"
    return min(rooms, key=lambda rs: rs[0])


def available_memory() -> int | None:
    """Bytes of memory a new allocation can use now (the smallest of :func:`memory_room`'s), or None if unknown."""
    return memory_room()[0]


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

    ``available`` defaults to :func:`memory_room` (the machine, a cgroup or
    the process's limit, whichever is smallest); when that is unknown the run
    is allowed. The message names ``option``, what the run needs, what there
    is, what limits it, and the largest particle count that fits (or, when
    the map's tables alone do not fit, that the map is too large).

    Examples
    --------
    >>> check_memory(1000, 30, available=10**9) < 10**9
    True
    >>> check_memory(10**8, 30, available=2 * 1024**3)
    Traceback (most recent call last):
    ...
    ValueError: --particles 100000000 needs about 86.2 GB of memory (30 beams, likelihood sensor), but only 2.0 GB is available: use at most about 1800000 particles, or fewer --beams
    >>> check_memory(1000, 30, n_cells=10**9, available=2 * 1024**3)
    Traceback (most recent call last):
    ...
    ValueError: --particles 1000 needs about 99.7 GB of memory (30 beams, likelihood sensor), but only 2.0 GB is available: the map's 1000000000 cells alone need 99.7 GB for the sensor model's tables; use a coarser map (a larger resolution) or crop it
    """
    need = estimate_run_bytes(n_particles, n_beams, sensor, n_cells)
    source = ""
    if available is None:
        have = available_memory()
        room, what = memory_room()
        if room == have and what != "the machine's available memory":
            source = f" under {what}"
    else:
        have = int(available)
    if have is None or need <= have:
        return need
    shown_need, shown_have = format_bytes(need), format_bytes(have)
    if shown_need == shown_have:  # "needs 2.6 GB, but only 2.6 GB": say it with the digits that differ
        shown_need, shown_have = f"{need / 1024**3:.3f} GB", f"{have / 1024**3:.3f} GB"
    head = (f"{option} {n_particles} needs about {shown_need} of memory ({n_beams} beams, {sensor} sensor), "
            f"but only {shown_have} is available{source}: ")
    tables = estimate_run_bytes(0, n_beams, sensor, n_cells)  # with the fixed part of every run
    if tables >= 0.8 * have:
        raise ValueError(head + f"the map's {n_cells} cells alone need {format_bytes(tables)} for the sensor "
                                "model's tables; use a coarser map (a larger resolution) or crop it")
    per = estimate_run_bytes(1, n_beams, sensor) - estimate_run_bytes(0, n_beams, sensor)
    fit = max(int((0.8 * have - tables) / per), 0)
    fit = int(float(f"{fit:.2g}")) if fit >= 100 else fit
    raise ValueError(head + f"use at most about {fit} particles, or fewer --beams")
