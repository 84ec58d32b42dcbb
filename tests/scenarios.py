"""Simulated runs with one known fault each, for the acceptance tests of the run's state (issue 43).

Each function returns a :class:`Scenario`: the map the filter is given, the
log it reads (odometry, scans and the log's stated maximum range, as a
:class:`localize.io.LaserLog`) and the simulated truth (the robot's poses and
the scans at which the fault happens). :func:`run` localizes the log as
``localize run`` does (:func:`localize.pipeline.localize_log` with the command
line's default settings, a fixed number of particles so that a run takes a
second) and returns the run driver's trace; :func:`position_errors` compares
its estimates with the truth.

Nothing here knows how the state is computed: the scenarios are facts about a
robot, a map and a log.

Most scenarios drive the robot of ``tests/test_cli.py``'s state tests (the
world of random rooms, seed 3: asymmetric, unlike the office world, which a
half turn maps onto itself; 150 scans, 0.2 m per scan, a 12 m laser). A
scenario whose fault needs another drive says which.

Examples
--------
>>> sc = kidnapping()
>>> len(sc.log), sc.fault_scans.tolist(), sc.truth.shape
(150, [90], (150, 3))
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from localize import io, maps, pipeline, sim
from localize.geometry import compose, relative
from localize.grid import OccupancyGrid

__all__ = ["Scenario", "run", "position_errors", "dead_laser", "corrupt_odometry", "kidnapping", "corridor",
           "missing_odometry_in_turn", "understated_max_range", "moved_obstacle", "walking_person",
           "start_in_a_hole"]

#: The particles every scenario is run with (the CLI's default, "auto", sizes the cloud from the map's
#: free space: about 20,000 here, 7 times slower and no different in these small worlds).
PARTICLES = 3000


@dataclass(frozen=True, eq=False)
class Scenario:
    """One simulated run with a known fault: what the filter is given and what really happened.

    Attributes
    ----------
    name : str
    grid : OccupancyGrid
        The map the filter is given.
    log : localize.io.LaserLog
        What the filter reads: scans, odometry, the stated maximum range.
    truth : ndarray (K, 3)
        The robot's true pose at each scan.
    fault : ndarray (K,) of bool
        The scans at which the fault acts (the laser is dead, the odometry record
        is corrupt or missing, the robot is carried away, a person blocks the laser ...).
    note : str
        What the fault is, in one sentence.
    extra : dict
        What a scenario knows beyond that (the true world of a moved obstacle,
        the beams a person blocked).
    """

    name: str
    grid: OccupancyGrid
    log: io.LaserLog
    truth: NDArray[np.float64]
    fault: NDArray[np.bool_]
    note: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def fault_scans(self) -> NDArray[np.int64]:
        """First scan of each stretch of faulty scans."""
        f = np.concatenate([[False], self.fault])
        return np.flatnonzero(f[1:] & ~f[:-1])


def run(sc: Scenario, seed: int = 0, **changes):
    """Localize ``sc.log`` on ``sc.grid`` as ``localize run`` does; return the run driver's trace.

    The settings are the command line's defaults (``changes`` overrides them), with
    :data:`PARTICLES` particles and global localization (the robot's start is unknown).
    """
    kw = dict(particles=PARTICLES)
    kw.update(changes)
    res = pipeline.localize_log(sc.grid, sc.log, rng=np.random.default_rng(seed), **kw)
    return res.trace


def position_errors(sc: Scenario, trace) -> NDArray[np.float64]:
    """Distance (m) between the trace's estimate and the true robot position at each scan.

    Examples
    --------
    >>> sc = corridor()
    >>> tr = run(sc, seed=0)
    >>> err = position_errors(sc, tr)
    >>> err.shape, bool(np.all(tr.state != "localized"))       # 16 m of corridor: nowhere known
    ((120,), True)
    """
    return np.hypot(*(np.asarray(trace.poses)[:, :2] - sc.truth[:, :2]).T)


# ---------------------------------------------------------------------------- the worlds
@lru_cache(maxsize=None)
def rooms() -> OccupancyGrid:
    """The 10 m x 15 m world of random rooms of ``tests/test_cli.py`` (seed 3)."""
    return maps.random_rooms((150, 100), 0.1, np.random.default_rng(3))


def _drive(world: OccupancyGrid, seed: int = 2, n_steps: int = 150, **kw) -> sim.RangeRun:
    """The robot of test_cli's state tests: 0.4 m/s, a scan every 0.5 s, a 12 m laser, seeded."""
    args = dict(n_steps=n_steps, dt=0.5, speed=0.4, max_range=12.0, n_clutter=3)
    args.update(kw)
    return sim.range_run(world, np.random.default_rng(seed), **args)


def _scenario(name: str, grid: OccupancyGrid, r: sim.RangeRun, note: str, fault=None, **log_changes) -> Scenario:
    log = r.to_log()
    if log_changes:
        log = replace(log, **log_changes)
    f = np.zeros(len(r), dtype=bool) if fault is None else np.asarray(fault, dtype=bool)
    return Scenario(name=name, grid=grid, log=log, truth=np.array(r.poses), fault=f, note=note)


def _from(k: int, n: int) -> NDArray[np.bool_]:
    m = np.zeros(n, dtype=bool)
    m[k:] = True
    return m


def _at(scans, n: int) -> NDArray[np.bool_]:
    m = np.zeros(n, dtype=bool)
    m[list(scans)] = True
    return m


# ---------------------------------------------------------------------------- today's four
def dead_laser(value: float = 0.0, from_scan: int = 0) -> Scenario:
    """The laser returns ``value`` at every beam from ``from_scan`` on (0: failed readings, 12: no return).

    Examples
    --------
    >>> sc = dead_laser(12.0, from_scan=80)
    >>> bool(np.all(sc.log.ranges[80:] == 12.0)), bool(np.any(sc.log.ranges[:80] < 12.0)), int(sc.fault.sum())
    (True, True, 70)
    """
    r = _drive(rooms())
    ranges = np.array(r.ranges)
    ranges[from_scan:] = value
    return _scenario("dead laser", rooms(), r, f"every reading is {value:g} m from scan {from_scan} on",
                     _from(from_scan, len(r)), ranges=ranges)


def corrupt_odometry(at: int = 70, jump: float | None = None) -> Scenario:
    """One odometry record is corrupt: the steps into and out of record ``at`` are wrong.

    By default the record reads (1e15, 1e15, 0.3), as one of a real log did: an
    impossible step, which a driver can reject. With ``jump`` the record's x
    reads ``jump`` metres more than the truth: a plausible step (a flipped bit
    of a small number), which it cannot tell from a real one.

    Examples
    --------
    >>> sc = corrupt_odometry(jump=2.0)
    >>> steps = np.diff(sc.log.odometry[69:72, 0]) - np.diff(_drive(rooms()).odometry[69:72, 0])
    >>> steps.round(3).tolist(), sc.fault_scans.tolist()
    ([2.0, -2.0], [70])
    """
    r = _drive(rooms())
    odo = np.array(r.odometry)
    if jump is None:
        odo[at] = [1e15, 1e15, 0.3]
        what = f"odometry record {at} reads (1e15, 1e15, 0.3)"
    else:
        odo[at, 0] += jump
        what = f"odometry record {at} reads {jump:g} m too far in x"
    return _scenario("corrupt odometry", rooms(), r, what, _at([at, at + 1], len(r)), odometry=odo)


def kidnapping(at: int = 90) -> Scenario:
    """The robot is carried to a random free pose before scan ``at``; its odometry reports an ordinary step."""
    r = _drive(rooms(), kidnap_at=[at])
    return _scenario("kidnapping", rooms(), r, f"carried away before scan {at}", r.kidnapped)


def corridor() -> Scenario:
    """A 60 m x 3 m corridor with nothing along it; the robot drives 16 m along its middle (test_cli's)."""
    d = np.zeros((30, 600))              # walls all round, the ends beyond the laser's 12 m
    d[:3] = d[-3:] = 1
    d[:, :3] = d[:, -3:] = 1
    g = OccupancyGrid(d, 0.1)
    r = sim.range_run(g, np.random.default_rng(0), n_steps=120, dt=0.5, speed=0.4, max_range=12.0, n_clutter=0,
                      waypoints=[[22.0, 1.5], [38.0, 1.5]], start=[22.0, 1.5, 0.0])
    return _scenario("featureless corridor", g, r, "no scan can tell where along the corridor the robot is",
                     np.ones(len(r), dtype=bool))


# ---------------------------------------------------------------------------- the four new ones
def missing_odometry_in_turn(scans: tuple[int, ...] = (89, 90, 91, 92)) -> Scenario:
    """The odometry of the motion into ``scans`` is missing: those steps read as standing still.

    In the default drive, the robot turns left by 88 degrees and drives 0.6 m
    over scans 89-92. A SLAM-corrected CARMEN log whose ``ODOM`` records are
    missing between two scans reads exactly so (:func:`localize.io.read_carmen_log`
    re-anchors the odometry at every scan: a step without a record is no motion),
    and the turn never reappears in the odometry.

    Examples
    --------
    >>> sc = missing_odometry_in_turn()
    >>> from localize.geometry import wrap_angle
    >>> turn = wrap_angle(sc.truth[92, 2] - sc.truth[88, 2])
    >>> round(float(np.degrees(turn))), bool(np.allclose(sc.log.odometry[88], sc.log.odometry[92]))
    (88, True)
    """
    r = _drive(rooms())
    steps = relative(r.odometry[:-1], r.odometry[1:])        # steps[k - 1]: the motion into scan k
    steps[np.asarray(scans) - 1] = 0.0
    odo = np.empty_like(r.odometry)
    odo[0] = r.odometry[0]
    for k in range(1, len(r)):
        odo[k] = compose(odo[k - 1], steps[k - 1])
    return _scenario("missing odometry in a turn", rooms(), r,
                     f"the odometry of scans {scans[0]}-{scans[-1]} (a left turn) reads as standing still",
                     _at(scans, len(r)), odometry=odo)


def understated_max_range(stated: float = 2.5) -> Scenario:
    """The log's header states a maximum range of ``stated`` m; the laser really reads up to 12 m.

    At 2.5 m, most readings of the default drive exceed the stated range (the
    median reading is 2.8 m); a reader that believes the header takes them all
    as "no return".

    Examples
    --------
    >>> sc = understated_max_range()
    >>> sc.log.max_range, bool(np.mean(sc.log.ranges > sc.log.max_range) > 0.5)
    (2.5, True)
    """
    r = _drive(rooms())
    return _scenario("understated max range", rooms(), r,
                     f"the log states a {stated:g} m maximum range; its readings go to 12 m",
                     np.ones(len(r), dtype=bool), max_range=stated)


#: A cabinet 1.2 m x 0.6 m: where the map has it, and where it stands when the robot drives.
CABINET_MAPPED = (4.9, 1.8, 6.1, 2.4)
CABINET_MOVED = (6.3, 1.4, 7.5, 2.0)


def moved_obstacle(mapped: tuple = CABINET_MAPPED, moved: tuple = CABINET_MOVED) -> Scenario:
    """The map shows a cabinet at ``mapped`` (x0, y0, x1, y1); since it was made, the cabinet moved to ``moved``.

    Otherwise the map is perfect (no unmapped clutter). The robot drives past
    both places, and the laser sees the cabinet's new place, and the floor
    where the map still draws it.

    Examples
    --------
    >>> sc = moved_obstacle()
    >>> x, y = 5.5, 2.1                                  # the cabinet's mapped centre
    >>> i, j = int(y / 0.1), int(x / 0.1)
    >>> float(sc.grid.data[i, j]), float(sc.extra["world"].data[i, j])
    (1.0, 0.0)
    """
    res = rooms().resolution
    mapped_d = np.array(rooms().data)
    maps.draw_box(mapped_d, res, *mapped)
    world_d = np.array(rooms().data)
    maps.draw_box(world_d, res, *moved)
    world = OccupancyGrid(world_d, res)
    r = _drive(world, n_clutter=0)
    sc = _scenario("moved obstacle", OccupancyGrid(mapped_d, res), r,
                   f"a 1.2 m x 0.6 m cabinet drawn at {mapped} stands at {moved}", np.ones(len(r), dtype=bool))
    sc.extra["world"] = world
    return sc


def _circle_ranges(sensor: NDArray, angles: NDArray, centre: NDArray, radius: float) -> NDArray:
    """Range along each beam from ``sensor`` (x, y, theta) to a circle (inf where the beam misses it)."""
    d = np.stack([np.cos(sensor[2] + angles), np.sin(sensor[2] + angles)], axis=-1)
    s = sensor[:2] - centre
    b = d @ s
    disc = b ** 2 - (s @ s - radius ** 2)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def walking_person(start: int = 60, n_scans: int = 20, ahead: float = 0.6, radius: float = 0.25,
                   sway: float = 0.2) -> Scenario:
    """A perfect map; for ``n_scans`` scans from ``start`` a person walks ``ahead`` m in front of the laser.

    The person is a circle of ``radius`` m (a torso seen at hip height) whose
    centre keeps ``ahead`` m in front of the laser and sways ``sway`` m from
    side to side (a step per scan); at the defaults it hides 30-50 degrees of
    the scan. The map holds every other obstacle exactly (no unmapped clutter);
    the laser has the simulator's usual noise.

    Examples
    --------
    >>> sc = walking_person()
    >>> blocked = sc.extra["blocked"]                    # beams that hit the person, per scan
    >>> int(sc.fault.sum()), int(blocked[:60].sum()), bool(blocked[60:80].mean() > 0.15)
    (20, 0, True)
    """
    r = _drive(rooms(), n_clutter=0)
    rng = np.random.default_rng(7)
    ranges = np.array(r.ranges)
    laser = compose(r.poses, r.sensor_offset)
    blocked = np.zeros(ranges.shape, dtype=bool)
    for i, k in enumerate(range(start, start + n_scans)):
        side = sway * (1.0 if i % 2 else -1.0)
        centre = compose(laser[k], [ahead, side, 0.0])[:2]
        z = _circle_ranges(laser[k], r.angles, centre, radius)
        hit = z < ranges[k]
        ranges[k, hit] = np.clip(z[hit] + rng.normal(0.0, 0.01, hit.sum()), 0.0, r.max_range)
        blocked[k] = hit
    sc = _scenario("walking person", rooms(), r, f"a person walks {ahead:g} m in front of the laser at scans "
                   f"{start}-{start + n_scans - 1}", _at(range(start, start + n_scans), len(r)), ranges=ranges)
    sc.extra["blocked"] = blocked
    return sc


def start_in_a_hole(side: float = 3.0) -> Scenario:
    """The robot starts amid a square of ``side`` m that the map leaves unknown: floor the map does not know.

    People stood there while the map was made, or the region was erased, as
    ``benchmarks/bench_global.py`` does to every map it degrades. The square
    is centred on the robot's first pose and covers whatever lies there
    (floor, and walls if any); the robot leaves it after a dozen scans. The
    rest of the map is perfect, with the simulator's usual unmapped clutter.

    Examples
    --------
    >>> sc = start_in_a_hole()
    >>> cells = sc.grid.world_to_cell(sc.truth[:, :2])
    >>> int(sc.fault.sum()), bool(sc.grid.holes[cells[0, 0], cells[0, 1]])
    (12, True)
    """
    world = rooms()
    r = _drive(world)
    res = world.resolution
    i, j = world.world_to_cell(np.asarray(r.poses)[0, :2])
    h = int(round(side / res / 2))
    data = np.array(world.data)
    data[max(i - h, 0):i + h, max(j - h, 0):j + h] = np.nan
    grid = OccupancyGrid(data, res)
    cells = grid.world_to_cell(np.asarray(r.poses)[:, :2])
    return _scenario("start in a hole", grid, r, f"the robot starts amid a {side:g} m square the map leaves unknown",
                     grid.unknown[cells[:, 0], cells[:, 1]])


def waiting_robot(drive: int = 80, wait: int = 300, sigma: float = 0.01) -> Scenario:
    """The robot drives ``drive`` scans, then stands still for ``wait`` scans (at a door, in a queue).

    The laser keeps scanning while it waits: the same view, with fresh noise of
    ``sigma`` m per reading; the odometry does not move, so the filter (which
    weights its particles only after some motion) uses none of those scans. A
    robot that stands still does not get lost, and a laser's scan rate is no
    hazard: 300 scans are 30 s at 10 Hz, 7.5 s at 40 Hz.

    Examples
    --------
    >>> sc = waiting_robot()
    >>> len(sc.log), bool(np.all(sc.log.odometry[80:] == sc.log.odometry[79])), int(sc.fault.sum())
    (380, True, 300)
    """
    r = _drive(rooms(), n_steps=drive)
    log = r.to_log()
    rng = np.random.default_rng(11)
    last = np.asarray(log.ranges[-1])
    still = np.where(last >= log.max_range, last,
                     np.clip(last + rng.normal(0.0, sigma, (wait, last.size)), 0.0, log.max_range))
    dt = float(np.median(np.diff(log.times)))
    log = replace(log, times=np.concatenate([log.times, log.times[-1] + dt * np.arange(1, wait + 1)]),
                  odometry=np.vstack([log.odometry, np.repeat(log.odometry[-1:], wait, axis=0)]),
                  ranges=np.vstack([log.ranges, still]),
                  poses=np.vstack([log.poses, np.repeat(log.poses[-1:], wait, axis=0)]))
    fault = np.concatenate([np.zeros(drive, dtype=bool), np.ones(wait, dtype=bool)])
    return Scenario(name="waiting robot", grid=rooms(), log=log, truth=np.asarray(log.poses), fault=fault,
                    note=f"drives {drive} scans, then stands still for {wait} scans")
