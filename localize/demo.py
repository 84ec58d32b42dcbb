"""The data of ``localize demo``: a simulated robot log and an imperfect map, written as CMU 16-831 files.

A first run of the command line needs data, and the public logs are a download
away (see chapter 9 for their addresses). :func:`make_demo` simulates them
instead, with the traps of real data:

* the **world** is the built-in office drawn at 5 cm, the **map** the same
  office drawn at 10 cm, so walls are off by up to a few centimetres;
* the map shows a **cupboard that is no longer there**, and the world holds
  unmapped **clutter** (people, boxes) that returns short readings;
* the laser sits 25 cm ahead of the robot's centre (as on the CMU robot), its
  readings follow the beam model's mixture (Gaussian noise, short readings,
  missed returns, random readings), and the odometry drifts with the noise of
  Probabilistic Robotics' odometry model.

The files are those a user would download: ``map.dat`` (CMU map, P(free)),
``robot.log`` (CMU log, centimetres), plus ``truth.tum``, the true poses, for
scoring with ``evo`` or :func:`localize.io.read_tum`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from . import maps, sim
from ._checks import check_rng
from .grid import OccupancyGrid
from .io.cmu import write_cmu_map
from .io.tum import write_tum

__all__ = ["DemoData", "make_demo", "DEMO_SENSOR_OFFSET", "DEMO_FILES"]

PathLike = str | os.PathLike

#: The laser's pose on the demo robot: 25 cm ahead of its centre, like the CMU 16-831 robot.
DEMO_SENSOR_OFFSET = (0.25, 0.0, 0.0)
#: The files :func:`make_demo` writes (``localize demo`` stages them with the run's results).
DEMO_FILES = ("map.dat", "robot.log", "truth.tum")


@dataclass(frozen=True)
class DemoData:
    """What :func:`make_demo` wrote and the truth behind it.

    Attributes
    ----------
    map_path, log_path, truth_path : Path
        The files written: the map, the log and the true poses.
    run : localize.sim.RangeRun
        The simulated run the log was written from (the truth: ``times``,
        ``poses`` and the ``world`` the scans were taken in are its).
    grid : OccupancyGrid
        The map written to ``map_path`` (coarser than the world, with the cupboard).
    cupboard : ndarray, shape (4,)
        The box ``(x0, y0, x1, y1)`` that the map shows and the world does not.
    """

    map_path: Path
    log_path: Path
    truth_path: Path
    run: sim.RangeRun
    grid: OccupancyGrid
    cupboard: NDArray[np.float64]

    @property
    def times(self) -> NDArray[np.float64]:
        """Time of each scan (s): the run's."""
        return self.run.times

    @property
    def poses(self) -> NDArray[np.float64]:
        """True poses of the robot centre, shape (T, 3): the run's."""
        return self.run.poses

    @property
    def world(self) -> OccupancyGrid:
        """The world the scans were taken in: the run's."""
        return self.run.world


def make_demo(folder: PathLike, rng: np.random.Generator, steps: int = 150) -> DemoData:
    """Simulate the demo robot and write ``map.dat``, ``robot.log`` and ``truth.tum`` into ``folder``.

    Parameters
    ----------
    folder : path
        Created if needed.
    rng : numpy.random.Generator
        The only source of randomness: the same seed writes the same files.
    steps : int
        Number of scans (one every 0.5 s, at 0.4 m/s).

    Examples
    --------
    >>> d = make_demo(tmp_dir(), np.random.default_rng(0), steps=5)
    >>> d.map_path.name, d.log_path.name, d.poses.shape
    ('map.dat', 'robot.log', (5, 3))
    >>> from localize import io
    >>> len(io.read_log(d.log_path)), io.read_map(d.map_path).resolution
    (5, 0.1)
    """
    check_rng(rng)
    steps = int(steps)
    if steps < 2:
        raise ValueError(f"steps must be >= 2; got {steps}")
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    world = maps.office(0.05)
    run = sim.range_run(world, rng, n_steps=steps, dt=0.5, speed=0.4, sensor_offset=DEMO_SENSOR_OFFSET,
                        max_range=12.0, n_clutter=6)
    office = maps.office(0.1)
    grid, boxes = sim.add_clutter(office, 1, rng, size=(0.8, 1.0), clearance=0.8, avoid=run.poses,
                                  avoid_radius=0.6)
    map_name, log_name, truth_name = DEMO_FILES
    map_path = write_cmu_map(out / map_name, grid)
    log_path = sim.write_cmu_log(out / log_name, run)
    truth = write_tum(out / truth_name, run.times, run.poses,
                      comment="true poses of the simulated robot (localize demo)\ntimestamp x y z qx qy qz qw")
    return DemoData(map_path=map_path, log_path=log_path, truth_path=truth, run=run, grid=grid, cupboard=boxes[0])
