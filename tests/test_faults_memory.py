"""The memory check (issue 39, finding 3): the process's own limit, cgroups, and a map's measured cost.

Run as a script, ``python tests/test_faults_memory.py``, it measures the peak
of :mod:`tracemalloc` over whole runs and prints the table behind the
constants of :mod:`localize._resources` (a minute or two on 2 cores).
"""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from localize import _resources, cli, io, maps, sim
from localize.grid import OccupancyGrid

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("memory")
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(4), n_steps=6, dt=0.5, speed=0.4,
                        sensor_offset=(0.25, 0.0, 0.0), max_range=12.0)
    return io.write_cmu_map(d / "office.dat", grid), sim.write_cmu_log(d / "office.log", run)


def limited(argv, address_space: int):
    """Run ``python -m localize argv`` with ``ulimit -v`` set to ``address_space`` bytes."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (address_space, address_space))

    return subprocess.run([sys.executable, "-m", "localize", *map(str, argv)], capture_output=True, text=True,
                          cwd=ROOT, preexec_fn=limit)


@pytest.mark.skipif(sys.platform != "linux", reason="ulimit -v and /proc are Linux's")
def test_three_million_particles_under_ulimit_v_are_refused_with_a_sentence(files, tmp_path):
    m, lg = files
    r = limited(["run", "--map", m, "--log", lg, "--particles", 3_000_000, "--beams", 60, "--out", tmp_path / "o",
                 "--quiet"], 3_000_000 * 1024)  # ulimit -v 3000000 (kB)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "MemoryError" not in r.stderr
    assert r.stderr.startswith("localize: error: --particles 3000000 needs about 5.0 GB of memory (60 beams")
    assert "under the process's memory limit (ulimit -v / -d): use at most about" in r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.skipif(sys.platform != "linux", reason="ulimit -v and /proc are Linux's")
def test_memory_room_reads_the_process_limit():
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (4 * 1024**3, 4 * 1024**3)); "
            "from localize._resources import memory_room, _process_status; room, what = memory_room(); "
            "print(room, what, _process_status('VmSize'), sep='|')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    room, what, used = out.strip().split("|")
    assert what == "the process's memory limit (ulimit -v / -d)"
    assert int(room) == 4 * 1024**3 - int(used) and 0 < int(room) < 4 * 1024**3


@pytest.mark.parametrize("version, files, room", [
    ("v2", {"memory.max": "2147483648\n", "memory.current": "1073741824\n"}, 1024**3),
    ("v2 unlimited", {"memory.max": "max\n", "memory.current": "1073741824\n"}, None),
    ("v1", {"memory/memory.limit_in_bytes": "3221225472\n", "memory/memory.usage_in_bytes": "1073741824\n"},
     2 * 1024**3),
    ("v1 unlimited", {"memory/memory.limit_in_bytes": "9223372036854771712\n",
                      "memory/memory.usage_in_bytes": "1073741824\n"}, None),
])
def test_cgroup_limits_v1_and_v2(tmp_path, monkeypatch, version, files, room):
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    monkeypatch.setattr(_resources, "_CGROUP", tmp_path)
    assert _resources._cgroup_room() == room


def test_the_smallest_room_wins_and_is_named(monkeypatch):
    monkeypatch.setattr(_resources, "_machine_available", lambda: 20 * 1024**3)
    monkeypatch.setattr(_resources, "_cgroup_room", lambda: None)
    monkeypatch.setattr(_resources, "_rlimit_room", lambda: 2 * 1024**3)
    with pytest.raises(ValueError, match=r"only 2\.0 GB is available under the process's memory limit"):
        _resources.check_memory(3_000_000, 60)


def test_a_10000_by_10000_map_is_not_refused_when_it_fits():
    """Issue 39: such a run needed 8.7 GB then (the old estimate said 37.3 GB and 'at most about 0 particles');
    measured again at stop 62, a map's cell costs 97-98 bytes (16 million cells: 1.56 GB), about 9.1 GB for
    10^8 cells, and the estimate rounds that up by about 10%."""
    need = _resources.check_memory(300_000, 30, n_cells=10_000 * 10_000, available=11 * 1024**3)
    assert 9.0 * 1024**3 <= need <= 10.5 * 1024**3


def test_a_map_too_large_for_any_particle_count_says_so():
    with pytest.raises(ValueError, match=r"the map's 100000000 cells alone need 10\.\d GB for the sensor model's "
                                         r"tables; use a coarser map") as e:
        _resources.check_memory(300_000, 30, n_cells=10_000 * 10_000, available=4 * 1024**3)
    assert "at most about 0 particles" not in str(e.value)


def test_equal_looking_sizes_are_told_apart():
    need = _resources.estimate_run_bytes(3_000_000, 30)
    with pytest.raises(ValueError, match=r"needs about (\d\.\d{3}) GB .* only (\d\.\d{3}) GB") as e:
        _resources.check_memory(3_000_000, 30, available=need - 10 * 1024**2)
    a, b = (float(x) for x in __import__("re").findall(r"(\d\.\d{3}) GB", str(e.value))[:2])
    assert a > b


# ------------------------------------------------------------------ the measurement behind the constants
def measure(n: int, beams: int, sensor: str, side: int = 0) -> tuple[int, int]:
    """Peak bytes (tracemalloc) of ``localize_log`` on the office padded to ``side`` x ``side`` cells."""
    office = maps.office(0.1)
    run = sim.range_run(office, np.random.default_rng(4), n_steps=4, dt=0.5, speed=0.4,
                        sensor_offset=(0.25, 0.0, 0.0), max_range=12.0)
    log = io.LaserLog(times=run.times, odometry=run.odometry, ranges=run.ranges, angles=run.angles, max_range=12.0,
                      sensor_offset=(0.25, 0, 0))
    h, w = office.data.shape
    data = np.zeros((max(side, h), max(side, w)))
    data[:h, :w] = office.data
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 1
    grid = OccupancyGrid(data, 0.1, origin=office.origin)
    tracemalloc.start()
    try:
        cli.localize_log(grid, log, n_particles=n, rng=np.random.default_rng(0), sensor=sensor, beams=beams,
                         min_motion=(0.0, 0.0))
        return tracemalloc.get_traced_memory()[1], grid.data.size
    finally:
        tracemalloc.stop()


def test_the_estimate_holds_on_a_larger_map():
    """The cells' share (likelihood field; the beam model's table build takes 20 s here: see __main__)."""
    peak, cells = measure(2000, 30, "likelihood", side=600)  # 360 000 cells
    est = _resources.estimate_run_bytes(2000, 30, "likelihood", n_cells=cells)
    assert peak <= est <= 1.5 * peak, (peak, est)


if __name__ == "__main__":  # the table behind the constants of localize._resources
    measure(50, 30, "likelihood")
    measure(50, 30, "beam")
    for spec in ("5000 30 likelihood 0", "20000 30 likelihood 0", "20000 180 likelihood 0", "300000 30 likelihood 0",
                 "300000 60 likelihood 0", "100000 180 likelihood 0", "2000 30 likelihood 2000",
                 "2000 30 likelihood 4000", "5000 30 beam 0", "100000 30 beam 0", "100000 90 beam 0",
                 "2000 30 beam 300", "2000 30 beam 600", "2000 30 beam 2000", "5000 30 beam 3000"):
        n, b, s, side = spec.split()
        peak, cells = measure(int(n), int(b), s, int(side))
        est = _resources.estimate_run_bytes(int(n), int(b), s, cells)
        print(f"{s:>10} {n:>7} particles {b:>4} beams {cells:>9} cells: peak {peak / 1e6:8.1f} MB, "
              f"estimate {est / 1e6:8.1f} MB ({est / peak:.2f}x)", flush=True)
