"""Deterministic simulated robots: the worlds the book's filters are tested on.

Everything here is a pure function of its arguments and an explicit
``rng: numpy.random.Generator``: the same seed gives the same run, bit for bit,
so chapters and tests can state exact outcomes.

* :func:`range_run` — a robot with a laser range finder driving through an
  :class:`~localize.OccupancyGrid`: true poses, noisy odometry readings in an
  odometry frame with an arbitrary origin, scans with the failure modes of
  real lasers (short readings from obstacles that are not in the map, missed
  returns at maximum range, random readings), and optional *kidnapping*
  (the robot is carried to another place without its odometry noticing).
* :func:`landmark_run` — a robot driven by velocity commands among point
  landmarks, seeing range-bearing sightings with known ids (the setting of
  EKF localization, *Probabilistic Robotics* section 7.4).
* :func:`corridor_run` — the one-dimensional toy of the particle-filter
  chapter: a robot on a ring-shaped corridor with doors, a noisy door
  detector and noisy steps.
* :func:`write_cmu_log` — write a range run as a CMU 16-831 style log, so
  that the chapter on real logs can run on simulated data anywhere.

Time steps
----------
Both runs have ``T`` steps ``k = 0 .. T-1``. Step 0 is the start: the robot
is at ``poses[0]`` and takes its first measurement. Between step ``k-1`` and
``k`` it moves; the control of that motion is ``run.control(k)`` (for the
odometry model the pair of odometry readings ``(odometry[k-1], odometry[k])``
of :mod:`localize.motion`), then it measures again. A filter therefore runs::

    for k in range(1, len(run)):
        pf.predict(run.control(k)); pf.update(run.ranges[k], run.angles)

Noise
-----
Odometry readings are made from the *true* motion between two steps: its
``(rot1, trans, rot2)`` decomposition is perturbed with the odometry model's
Gaussian noise (:func:`localize.motion.sample_odometry` with the roles of true
and measured motion swapped; alphas as in PR table 5.6, as *variances*
``alpha1*rot1**2 + alpha2*trans**2`` ...). A filter using the same alphas is
therefore tuned correctly to first order. Scans come from the beam model's
sampler, :meth:`localize.sensors.BeamModel.sample`, evaluated in the *true*
world, which holds obstacles that the map given to the filter does not.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_grid, check_max_range, check_nonnegative, check_positive, check_rng
from .geometry import as_poses, compose, relative, wrap_angle
from .grid import OccupancyGrid
from .io import cmu as _cmu
from .io.cmu import CMU_ANGLES  # re-exported: the CMU scanner's 180 beams, the default of range_run
from .maps import draw_box
from .motion import move_velocity, sample_odometry, sample_velocity
from .sensors import range_bearing

__all__ = [
    "SimulatedRun",
    "RangeRun",
    "LandmarkRun",
    "CorridorRun",
    "corridor_run",
    "range_run",
    "landmark_run",
    "add_clutter",
    "default_landmarks",
    "odometry_readings",
    "wander_path",
    "write_cmu_log",
    "CMU_ANGLES",
    "DEFAULT_ODOMETRY_ALPHAS",
]


#: Odometry noise of the simulated robot (PR alphas, variances): a few
#: percent of the motion, the order of magnitude of a real differential drive.
DEFAULT_ODOMETRY_ALPHAS: tuple[float, float, float, float] = (0.02, 0.0005, 0.02, 0.0005)



class _ReadOnly:
    """Makes every array field of a simulated record read-only once it is built."""

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            a = getattr(self, f.name)
            if isinstance(a, np.ndarray):
                a.setflags(write=False)


def _motion_step(k: int, n: int) -> int:
    """``k`` as the index of the motion into step ``k`` of an ``n``-step run: 1 .. n-1 (step 0 has none)."""
    k = int(k)
    if not 1 <= k < n:
        raise ValueError(f"k must be in [1, {n - 1}] (step 0 has no motion); got {k}")
    return k


# =========================================================================
# results
# =========================================================================
@dataclass(frozen=True, eq=False, kw_only=True)
class SimulatedRun(_ReadOnly):
    """What every simulated run of a robot in the plane records (arrays are read-only); built by keyword.

    Shared by :class:`RangeRun` and :class:`LandmarkRun`.

    Attributes
    ----------
    times : ndarray, shape (T,)
        Time of each step in seconds.
    poses : ndarray, shape (T, 3)
        True poses of the robot centre in the map frame.
    odometry : ndarray, shape (T, 3)
        Odometry readings (robot centre) in the odometry frame. Its origin is
        arbitrary (``odometry[0]`` is not ``poses[0]``): only the motion
        between two readings carries information.
    odometry_alphas : ndarray, shape (4,)
        Odometry noise (PR alphas, variances) used for the readings.
    dt : float
        Seconds between steps.
    """

    times: NDArray[np.float64]
    poses: NDArray[np.float64]
    odometry: NDArray[np.float64]
    odometry_alphas: NDArray[np.float64]
    dt: float

    def __len__(self) -> int:
        return int(self.times.shape[0])


@dataclass(frozen=True, eq=False, kw_only=True)
class RangeRun(SimulatedRun):
    """A simulated run of a robot with a range finder (arrays are read-only).

    Attributes
    ----------
    times, poses, odometry, odometry_alphas, dt
        See :class:`SimulatedRun`; :attr:`alphas` is ``odometry_alphas``.
    ranges : ndarray, shape (T, B)
        Scan at each step, metres; readings ``>= max_range`` mean "no return".
    angles : ndarray, shape (B,)
        Beam angles relative to the sensor's heading.
    max_range : float
    sensor_offset : ndarray, shape (3,)
        Pose of the range finder in the robot frame.
    kidnapped : ndarray of bool, shape (T,)
        True at steps ``k`` where the robot was carried away between ``k-1``
        and ``k`` (its odometry reports an ordinary step straight ahead).
    grid : OccupancyGrid
        The map the filter is given.
    world : OccupancyGrid
        The true world the scans were taken in: ``grid`` plus the unmapped
        obstacles (``clutter``).
    clutter : ndarray, shape (M, 4)
        Unmapped obstacles as boxes ``(x0, y0, x1, y1)`` in metres.
    meta : dict
        The path's ``radius`` and ``speed``.
    """

    ranges: NDArray[np.float64]
    angles: NDArray[np.float64]
    max_range: float
    sensor_offset: NDArray[np.float64]
    kidnapped: NDArray[np.bool_]
    grid: OccupancyGrid
    world: OccupancyGrid
    clutter: NDArray[np.float64]
    meta: dict = field(default_factory=dict)

    @property
    def alphas(self) -> NDArray[np.float64]:
        """The odometry noise of the readings, :attr:`odometry_alphas` (PR alphas), for ``OdometryMotion(run.alphas)``."""
        return self.odometry_alphas

    def control(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The odometry-model control ``u = (odometry[k-1], odometry[k])`` of the motion into step ``k``.

        Examples
        --------
        >>> from localize.maps import office
        >>> run = range_run(office(), np.random.default_rng(0), n_steps=3, angles=[])
        >>> prev, now = run.control(2)
        >>> bool(np.array_equal(now, run.odometry[2]))
        True
        """
        k = _motion_step(k, len(self))
        return self.odometry[k - 1], self.odometry[k]

    @property
    def controls(self) -> NDArray[np.float64]:
        """All controls as one array ``(T, 2, 3)``: ``controls[k] = (odometry[k-1], odometry[k])``.

        The same indexing as :attr:`CorridorRun.controls` and
        :attr:`LandmarkRun.controls` (the motion *into* step ``k``; row 0 is
        no motion, ``(odometry[0], odometry[0])``); ``controls[k]`` equals
        :meth:`control` ``(k)`` for ``k >= 1``.

        Examples
        --------
        >>> from localize.maps import office
        >>> run = range_run(office(), np.random.default_rng(0), n_steps=3, angles=[])
        >>> run.controls.shape, bool(np.array_equal(run.controls[2], np.stack(run.control(2))))
        ((3, 2, 3), True)
        """
        prev = np.concatenate([self.odometry[:1], self.odometry[:-1]])
        out = np.stack([prev, self.odometry], axis=1)
        out.flags.writeable = False
        return out

    def to_log(self, odometry_rate: int = 1):
        """The run as a :class:`localize.io.LaserLog`, what a robot would have recorded (plus the truth).

        ``odometry`` and the scans are the run's; the true poses become the
        log's reference ``poses``; every ``odometry_rate``-th step also gives
        an odometry record (``odom_times``, ``odom_poses``). The io writers
        (:func:`localize.io.write_cmu_log`, ...) write it.

        Examples
        --------
        >>> from localize.maps import office
        >>> run = range_run(office(), np.random.default_rng(0), n_steps=4, sensor="ideal")
        >>> log = run.to_log(odometry_rate=2)
        >>> len(log), log.n_beams, log.odom_times.tolist() == run.times[::2].tolist()
        (4, 180, True)
        """
        from .io import LaserLog

        rate = check_count(odometry_rate, "odometry_rate")
        return LaserLog(times=self.times, odometry=self.odometry, ranges=self.ranges, angles=self.angles,
                        max_range=self.max_range, sensor_offset=self.sensor_offset, poses=self.poses,
                        odom_times=self.times[::rate], odom_poses=self.odometry[::rate], format="sim",
                        source="localize.sim.range_run")

    @property
    def sensor_poses(self) -> NDArray[np.float64]:
        """True poses of the range finder, shape (T, 3)."""
        return compose(self.poses, self.sensor_offset)

    @property
    def kidnap_steps(self) -> NDArray[np.int64]:
        """Steps at which the robot arrived by being kidnapped."""
        return np.flatnonzero(self.kidnapped)

    def __repr__(self) -> str:
        return (f"RangeRun(steps={len(self)}, beams={self.angles.size}, max_range={self.max_range:g} m, "
                f"dt={self.dt:g} s, kidnappings={int(self.kidnapped.sum())}, clutter={len(self.clutter)})")


@dataclass(frozen=True, eq=False, kw_only=True)
class LandmarkRun(SimulatedRun):
    """A simulated run among point landmarks (arrays are read-only).

    Attributes
    ----------
    times, poses, odometry, odometry_alphas, dt
        See :class:`SimulatedRun` (the odometry is that of the true motion,
        for filters that use the odometry model instead).
    controls : ndarray, shape (T, 2)
        Commanded ``(v, omega)`` of the motion *into* step ``k`` (row 0 is
        zero: nothing moves before the start). The true motion is the
        velocity model applied to this command (PR table 5.3).
    landmarks : ndarray, shape (L, 2)
        Landmark positions; landmark ``j`` has id ``j``.
    steps, ids : ndarray of int, shape (K,)
        Sighting ``s`` was taken at step ``steps[s]`` of landmark ``ids[s]``.
    z : ndarray, shape (K, 2)
        Measured ``(range, bearing)`` of each sighting, bearing relative to
        the robot's heading, wrapped to ``[-pi, pi)``.
    sigma_range, sigma_bearing, max_range, fov : float
    velocity_alphas : ndarray, shape (6,)
    """

    controls: NDArray[np.float64]
    landmarks: NDArray[np.float64]
    steps: NDArray[np.int64]
    ids: NDArray[np.int64]
    z: NDArray[np.float64]
    sigma_range: float
    sigma_bearing: float
    max_range: float
    fov: float
    velocity_alphas: NDArray[np.float64]

    def sightings(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """``(z, ids)`` of the sightings at step ``k``: shapes ``(K_k, 2)`` and ``(K_k,)``."""
        k = int(k)
        if not 0 <= k < len(self):
            raise ValueError(f"k must be in [0, {len(self) - 1}]; got {k}")
        m = self.steps == k
        return self.z[m], self.ids[m]

    def __repr__(self) -> str:
        return (f"LandmarkRun(steps={len(self)}, landmarks={len(self.landmarks)}, sightings={len(self.ids)}, "
                f"dt={self.dt:g} s)")


# =========================================================================
# building blocks
# =========================================================================
def add_clutter(grid: OccupancyGrid, n: int, rng: np.random.Generator, size: tuple[float, float] = (0.3, 0.6),
                clearance: float = 0.5, avoid: ArrayLike | None = None, avoid_radius: float = 1.0
                ) -> tuple[OccupancyGrid, NDArray[np.float64]]:
    """Put ``n`` unmapped square obstacles (people, boxes, chairs) into free space.

    Parameters
    ----------
    grid : OccupancyGrid
        The map. It is not changed: a new grid is returned.
    n : int
        Number of obstacles (>= 0).
    rng : numpy.random.Generator
    size : (float, float)
        Range of the square's side in metres.
    clearance : float
        Minimum distance from each square's centre to mapped obstacles.
    avoid : array_like, shape (P, 2) or (P, 3), optional
        Points (e.g. the start pose) that no obstacle may come within
        ``avoid_radius`` of.

    Returns
    -------
    world : OccupancyGrid
        ``grid`` with the obstacles drawn in.
    boxes : ndarray, shape (n, 4)
        ``(x0, y0, x1, y1)`` of each obstacle.

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office()
    >>> world, boxes = add_clutter(g, 3, np.random.default_rng(0))
    >>> boxes.shape, int(world.occupied.sum() - g.occupied.sum()) > 0
    ((3, 4), True)
    """
    rng = check_rng(rng)
    n = check_count(n, "n", minimum=0)
    lo, hi = (float(s) for s in size)
    if not 0 < lo <= hi:
        raise ValueError(f"size must be (min, max) with 0 < min <= max metres; got {size}")
    pts = np.zeros((0, 2)) if avoid is None else np.asarray(avoid, dtype=float).reshape(-1, np.shape(avoid)[-1])[:, :2]
    data = np.array(grid.data, copy=True)
    boxes = np.zeros((n, 4))
    origin = grid.origin
    for k in range(n):
        for _attempt in range(1000):
            c = grid.sample_free(1, rng)[0, :2]
            s = rng.uniform(lo, hi)
            if grid.distance_at(c) < clearance + s / 2:
                continue
            if pts.size and np.min(np.hypot(*(pts - c).T)) < avoid_radius + s / 2:
                continue
            break
        else:
            raise ValueError("could not place clutter: the map has too little free space for the requested clearance")
        x0, y0 = c - s / 2 - origin
        draw_box(data, grid.resolution, x0, y0, x0 + s, y0 + s, 1.0)
        boxes[k] = [c[0] - s / 2, c[1] - s / 2, c[0] + s / 2, c[1] + s / 2]
    world = OccupancyGrid(data, grid.resolution, origin=grid.origin, occupied_threshold=grid.occupied_threshold,
                          unknown_is_obstacle=grid.unknown_is_obstacle)
    return world, boxes


def odometry_readings(poses: ArrayLike, alphas: ArrayLike, rng: np.random.Generator,
                      origin: ArrayLike | None = None) -> NDArray[np.float64]:
    """Noisy odometry readings of a true trajectory, in a frame with an arbitrary origin.

    Each true motion ``poses[k-1] -> poses[k]`` is decomposed into
    ``(rot1, trans, rot2)``, perturbed with the odometry model's noise
    (alphas as in PR table 5.6, as variances) and added onto the previous
    reading. Errors therefore accumulate, as on a real robot.

    Parameters
    ----------
    poses : array_like, shape (T, 3)
        True poses.
    alphas : array_like, shape (4,)
    rng : numpy.random.Generator
    origin : array_like, shape (3,), optional
        The first reading. Default: drawn at random (x, y in [-50, 50) m, any
        heading), which makes plain "odometry = pose" mistakes visible.

    Returns
    -------
    ndarray, shape (T, 3)

    Examples
    --------
    >>> truth = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, np.pi / 2]])
    >>> odo = odometry_readings(truth, [0, 0, 0, 0], np.random.default_rng(0), origin=[5.0, 5.0, np.pi])
    >>> odo.round(6)                          # no noise: the same motion, seen from another origin
    array([[ 5.      ,  5.      , -3.141593],
           [ 4.      ,  5.      , -3.141593],
           [ 4.      ,  4.      , -1.570796]])
    """
    rng = check_rng(rng)
    p = as_poses(poses)
    if p.ndim != 2:
        raise ValueError(f"poses must be a (T, 3) trajectory; got shape {p.shape}")
    if origin is None:
        origin = np.array([rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-np.pi, np.pi)])
    out = np.empty_like(p)
    out[0] = as_poses(origin, "origin")
    out[0, 2] = wrap_angle(out[0, 2])
    if len(p) > 1:
        # the true motions, each seen from its start pose; perturb them all with the odometry model
        steps = relative(p[:-1], p[1:])
        zero = np.zeros_like(steps)
        noisy = sample_odometry(zero, (zero, steps), alphas, rng)
        for k in range(1, len(p)):                   # accumulate: errors add up as on a real robot
            c, s = np.cos(out[k - 1, 2]), np.sin(out[k - 1, 2])
            dx, dy, dth = noisy[k - 1]
            out[k] = [out[k - 1, 0] + c * dx - s * dy, out[k - 1, 1] + s * dx + c * dy,
                      wrap_angle(out[k - 1, 2] + dth)]
    return out


def _free_pose(world: OccupancyGrid, rng: np.random.Generator, radius: float) -> NDArray[np.float64]:
    for _ in range(10_000):
        p = world.sample_free(1, rng)[0]
        if world.distance_at(p[:2]) >= radius:
            return p
    raise ValueError(f"no free pose with clearance {radius} m found in the map")


def _segment_clear(world: OccupancyGrid, a: NDArray, b: NDArray, radius: float) -> bool:
    n = max(2, int(np.ceil(np.hypot(*(b - a)) / (0.5 * world.resolution))) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    return bool(np.all(world.distance_at(a + t * (b - a), outside=0.0) >= radius))


def wander_path(world: OccupancyGrid, n_steps: int, rng: np.random.Generator, start: ArrayLike | None = None,
                speed: float = 0.3, dt: float = 1.0, radius: float = 0.25, waypoints: ArrayLike | None = None,
                max_turn: float = 0.6, when_blocked: str = "random") -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A collision-free trajectory: a wander controller, or a route through waypoints.

    Every step the robot turns by at most ``max_turn`` and then drives
    straight for at most ``speed * dt`` metres. The *wander* controller keeps
    its heading (with a small random drift) while the way ahead is open and
    turns towards the most open of seven probe directions when it is not.
    With ``waypoints`` it turns towards the next waypoint instead. A step
    whose end point would come closer than ``radius`` to an obstacle is not
    driven: the robot only turns (and, in wander mode, picks a new
    direction). The whole straight segment of a step is checked (at points
    half a cell apart), not only its end.

    Parameters
    ----------
    world : OccupancyGrid
        The true world, including unmapped obstacles.
    n_steps : int
        Number of poses ``T`` (>= 1).
    rng : numpy.random.Generator
    start : array_like, shape (3,), optional
        Start pose; default a random free pose with clearance ``2 * radius``.
    speed, dt : float
        Forward speed (m/s) and step duration (s).
    radius : float
        Robot radius: minimum clearance of every pose (metres).
    waypoints : array_like, shape (M, 2), optional
        Visit these points in order (a waypoint counts as reached within
        ``speed * dt``), then stop. They must be reachable in straight lines.
    max_turn : float
        Largest turn per step (radians).
    when_blocked : "random" or "open_side"
        How a blocked robot turns on the spot: ``"random"`` (default) by
        ``max_turn`` to the left or right at random at every blocked step, so
        that it may dither in place for many steps; ``"open_side"`` towards
        the side whose probe rays reach farther, and on the same way until a
        step can be driven again (as a robot that backs out of a corner).

    Returns
    -------
    poses : ndarray, shape (T, 3)
    planned : ndarray, shape (T, 3)
        ``planned[k]`` is the motion ``(dx, dy, dtheta)`` in the robot frame
        from step ``k-1`` to ``k`` (row 0 is zero).

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office()
    >>> poses, _ = wander_path(g, 50, np.random.default_rng(1))
    >>> poses.shape, bool(np.all(g.distance_at(poses[:, :2]) >= 0.25))
    ((50, 3), True)
    """
    rng = check_rng(rng)
    n_steps = check_count(n_steps, "n_steps")
    speed, dt, radius, max_turn = float(speed), float(dt), float(radius), float(max_turn)
    if when_blocked not in ("random", "open_side"):
        raise ValueError(f"when_blocked must be 'random' or 'open_side'; got {when_blocked!r}")
    if not (speed >= 0 and dt > 0 and radius > 0 and max_turn > 0):
        raise ValueError(
            f"need speed >= 0, dt > 0, radius > 0 and max_turn > 0; got speed={speed}, dt={dt}, "
            f"radius={radius}, max_turn={max_turn}"
        )
    step_len = speed * dt
    from .raycast import RayCaster

    probe = RayCaster(world, max_range=3.0, method="exact", outside="zero")
    probe_angles = np.radians([-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0])
    if start is None:
        pose = _free_pose(world, rng, 2 * radius)
    else:
        pose = as_poses(start, "start").astype(float).copy()
        if world.distance_at(pose[:2]) < radius:
            raise ValueError(f"start {pose[:2].round(3).tolist()} is within radius {radius} m of an obstacle")
    wps = None if waypoints is None else np.asarray(waypoints, dtype=float).reshape(-1, 2)
    wp_i = 0
    escape = 0.0                      # "open_side": the way a blocked robot turns (+1 left, -1 right)
    poses = np.zeros((n_steps, 3))
    planned = np.zeros((n_steps, 3))
    poses[0] = pose
    for k in range(1, n_steps):
        if wps is not None:
            while wp_i < len(wps) and np.hypot(*(wps[wp_i] - pose[:2])) <= max(step_len, 1e-9):
                wp_i += 1
            if wp_i >= len(wps):
                turn, dist = 0.0, 0.0
            else:
                d = wps[wp_i] - pose[:2]
                want = float(wrap_angle(np.arctan2(d[1], d[0]) - pose[2]))
                turn = float(np.clip(want, -max_turn, max_turn))
                dist = min(step_len, float(np.hypot(*d))) if abs(want) <= max_turn else 0.0
        else:
            ranges = probe.cast(pose, probe_angles)[0]
            if ranges[3] > 1.0 + radius:
                turn = float(np.clip(rng.normal(0.0, 0.15), -max_turn, max_turn))
            else:
                best = probe_angles[int(np.argmax(ranges + 0.01 * rng.random(7)))]
                turn = float(np.clip(best, -max_turn, max_turn))
            dist = step_len
        th = float(wrap_angle(pose[2] + turn))
        new = np.array([pose[0] + dist * np.cos(th), pose[1] + dist * np.sin(th), th])
        if dist > 0 and not _segment_clear(world, pose[:2], new[:2], radius):
            if wps is not None:
                raise ValueError(
                    f"the route to waypoint {wp_i} {wps[wp_i].round(3).tolist()} passes within {radius} m of an "
                    f"obstacle near ({new[0]:.2f}, {new[1]:.2f})"
                )
            # blocked: turn on the spot, away from the current heading
            if when_blocked == "random":
                escape = rng.choice([-1.0, 1.0])
            elif escape == 0.0:                      # towards the more open side, and keep that way
                r = probe.cast(pose, probe_angles)[0]
                escape = 1.0 if r[4:].max() + 0.01 * rng.random() >= r[:3].max() + 0.01 * rng.random() else -1.0
            new = np.array([pose[0], pose[1], wrap_angle(pose[2] + escape * max_turn)])
        else:
            escape = 0.0
        planned[k] = relative(pose, new)
        poses[k] = new
        pose = new
    return poses, planned


def _beam_model(world: OccupancyGrid, max_range: float, sensor_offset, params: dict):
    try:
        from .sensors import BeamModel
    except ImportError as e:  # pragma: no cover - only while the sensors module is missing
        raise ImportError(
            "range_run needs localize.sensors.BeamModel to simulate scans; pass sensor=<object with "
            ".sample(poses, angles, rng)> or n_beams=0"
        ) from e
    return BeamModel(world, max_range, sensor_offset=sensor_offset, method="exact", **params)


class _IdealSensor:
    """Noise-free ranges from exact ray casting in the true world."""

    def __init__(self, world: OccupancyGrid, max_range: float, sensor_offset: NDArray) -> None:
        from .raycast import RayCaster

        self.caster = RayCaster(world, max_range, method="exact")
        self.offset = sensor_offset

    def sample(self, poses: NDArray, angles: NDArray, rng: np.random.Generator) -> NDArray:
        return self.caster.cast(compose(poses, self.offset), angles)


#: Beam-model mixture of the simulated laser (PR section 6.3 names): mostly
#: hits with 5 cm noise, a few short readings, missed returns and random ones.
DEFAULT_SCAN_NOISE: dict[str, float] = {
    "z_hit": 0.85, "z_short": 0.05, "z_max": 0.05, "z_rand": 0.05, "sigma_hit": 0.05, "lambda_short": 0.5,
}


def range_run(
    grid: OccupancyGrid,
    rng: np.random.Generator,
    n_steps: int = 100,
    *,
    start: ArrayLike | None = None,
    waypoints: ArrayLike | None = None,
    speed: float = 0.3,
    dt: float = 1.0,
    radius: float = 0.25,
    angles: ArrayLike | None = None,
    max_range: float = 8.0,
    sensor_offset: ArrayLike = (0.0, 0.0, 0.0),
    alphas: ArrayLike = DEFAULT_ODOMETRY_ALPHAS,
    n_clutter: int = 5,
    kidnap_at: Sequence[int] = (),
    scan_noise: dict | None = None,
    sensor: Any = "beam",
    odom_origin: ArrayLike | None = None,
    when_blocked: str = "random",
) -> RangeRun:
    """Simulate a robot with a laser range finder driving through a map.

    Parameters
    ----------
    grid : OccupancyGrid
        The map (what a filter will be given).
    rng : numpy.random.Generator
        The only source of randomness: the same seed gives the same run.
    n_steps : int
        Number of steps ``T`` (poses and scans), >= 1.
    start, waypoints, speed, dt, radius
        The trajectory, see :func:`wander_path` (default: wander from a random
        free pose at 0.3 m per 1 s step).
    angles : array_like, shape (B,), optional
        Beam angles relative to the sensor heading; default
        :data:`CMU_ANGLES` (180 beams, -90 .. +89 degrees). An empty array
        (or ``angles=[]``) simulates no scans.
    max_range : float
        The laser's maximum range in metres (readings of ``max_range`` mean
        "no return").
    sensor_offset : (dx, dy, dtheta)
        Pose of the laser in the robot frame (CMU robot: ``(0.25, 0, 0)``).
    alphas : array_like, shape (4,)
        Odometry noise, PR alphas (variances); see :func:`odometry_readings`.
    n_clutter : int
        Number of unmapped obstacles (see :func:`add_clutter`): the source of
        systematically short readings.
    kidnap_at : sequence of int
        Steps (1 .. T-1) at which the robot arrives by being carried to a
        random free pose. Its odometry reports an ordinary step straight
        ahead. (With ``waypoints``, the route restarts from its first
        waypoint after each kidnapping.)
    scan_noise : dict, optional
        Keyword arguments of :class:`localize.sensors.BeamModel` for the
        simulated laser (default :data:`DEFAULT_SCAN_NOISE`). A beam with
        nothing within ``max_range`` reads ``max_range`` ("no return", as a
        real scanner reports it; ``no_return=True`` of the model), unless
        ``scan_noise`` says ``no_return=False``: PR's sampler, whose hit part
        then reads a few ``sigma_hit`` short of the range, an end point in
        mid-air.
    sensor : "beam", "ideal" or object with ``sample(poses, angles, rng)``
        How scans are made: ``"beam"`` (default) samples
        :class:`localize.sensors.BeamModel` built on the true world with
        ``scan_noise``; ``"ideal"`` casts exact, noise-free rays in the true
        world (short readings then come from the clutter only); an object is
        used as is (it receives robot poses and must apply its own sensor
        offset).
    odom_origin : array_like, shape (3,), optional
        First odometry reading (default: random, see :func:`odometry_readings`).
    when_blocked : "random" or "open_side"
        How the wandering robot turns when its way is blocked (see :func:`wander_path`).

    Returns
    -------
    RangeRun

    Examples
    --------
    >>> from localize.maps import office
    >>> run = range_run(office(), np.random.default_rng(0), n_steps=5, angles=np.radians([-45, 0, 45]),
    ...                 sensor="ideal")
    >>> run
    RangeRun(steps=5, beams=3, max_range=8 m, dt=1 s, kidnappings=0, clutter=5)
    >>> run.poses.shape, run.odometry.shape, run.ranges.shape
    ((5, 3), (5, 3), (5, 3))
    >>> u = run.control(1)                      # (previous odometry, odometry): a motion-model control
    >>> bool(np.all(run.ranges <= run.max_range))
    True
    """
    rng = check_rng(rng)
    check_grid(grid)
    n_steps = check_count(n_steps, "n_steps")
    max_range = check_max_range(max_range)
    ang = CMU_ANGLES.copy() if angles is None else np.asarray(angles, dtype=float).reshape(-1)
    if not np.all(np.isfinite(ang)):
        raise ValueError("angles must be finite")
    offset = as_poses(sensor_offset, "sensor_offset").reshape(3)
    alphas = np.asarray(alphas, dtype=float).reshape(-1)
    if alphas.shape != (4,) or np.any(alphas < 0):
        raise ValueError(f"alphas must be 4 non-negative numbers (PR alpha1..alpha4); got {alphas.tolist()}")
    kid = sorted({int(k) for k in kidnap_at})
    if kid and (kid[0] < 1 or kid[-1] >= n_steps):
        raise ValueError(f"kidnap_at steps must lie in [1, {n_steps - 1}]; got {list(kidnap_at)}")

    avoid = None if start is None else np.asarray(start, dtype=float).reshape(1, -1)
    if waypoints is not None:
        wp = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        avoid = wp if avoid is None else np.vstack([avoid[:, :2], wp])
    world, boxes = add_clutter(grid, n_clutter, rng, avoid=avoid, avoid_radius=max(1.0, 3 * radius))

    # trajectory, cut into legs at the kidnapping steps
    bounds = [0] + kid + [n_steps]
    poses = np.zeros((n_steps, 3))
    planned = np.zeros((n_steps, 3))
    leg_start = start
    for a, b in zip(bounds[:-1], bounds[1:]):
        if a > 0:
            # kidnapped between a-1 and a: carried to a random place; the robot believes it drove
            # one ordinary step straight ahead, and its odometry says so
            leg_start = _free_pose(world, rng, 2 * radius)
            planned[a] = [speed * dt, 0.0, 0.0]
        p, pl = wander_path(world, b - a, rng, start=leg_start, speed=speed, dt=dt, radius=radius,
                            waypoints=waypoints, when_blocked=when_blocked)
        poses[a:b] = p
        planned[a + 1:b] = pl[1:]

    # odometry: true motion with noise; at a kidnapping the planned motion instead
    odo_origin = None if odom_origin is None else as_poses(odom_origin, "odom_origin")
    steps_for_odometry = np.zeros_like(poses)
    for k in range(1, n_steps):
        steps_for_odometry[k] = compose(steps_for_odometry[k - 1],
                                        planned[k] if k in kid else relative(poses[k - 1], poses[k]))
    odometry = odometry_readings(steps_for_odometry, alphas, rng, origin=odo_origin)

    # scans in the true world
    if ang.size:
        if isinstance(sensor, str):
            if sensor == "beam":
                model = _beam_model(world, max_range, offset,
                                    {**DEFAULT_SCAN_NOISE, "no_return": True, **(scan_noise or {})})
            elif sensor == "ideal":
                model = _IdealSensor(world, max_range, offset)
            else:
                raise ValueError(f"sensor must be 'beam', 'ideal' or an object with a sample method; got {sensor!r}")
        elif hasattr(sensor, "sample"):
            model = sensor
        else:
            raise TypeError(f"sensor must be 'beam', 'ideal' or have sample(poses, angles, rng); got {sensor!r}")
        ranges = np.asarray(model.sample(poses, ang, rng), dtype=float)
        if ranges.shape != (n_steps, ang.size):
            raise ValueError(f"sensor.sample returned shape {ranges.shape}; expected {(n_steps, ang.size)}")
        ranges = np.clip(ranges, 0.0, max_range)
    else:
        ranges = np.zeros((n_steps, 0))
    kidnapped = np.zeros(n_steps, dtype=bool)
    kidnapped[kid] = True
    return RangeRun(
        times=np.arange(n_steps) * dt, poses=poses, odometry=odometry, ranges=ranges, angles=ang,
        max_range=max_range, sensor_offset=offset, kidnapped=kidnapped, grid=grid, world=world,
        clutter=boxes, odometry_alphas=alphas, dt=dt, meta={"radius": radius, "speed": speed},
    )


# =========================================================================
# landmark run
# =========================================================================
def default_landmarks() -> NDArray[np.float64]:
    """Eight landmarks around a 20 m x 12 m area (the office's footprint).

    Examples
    --------
    >>> default_landmarks().shape
    (8, 2)
    """
    return np.array([[2.0, 2.0], [10.0, 1.0], [18.0, 2.5], [19.0, 9.0],
                     [12.0, 11.0], [4.0, 10.5], [7.0, 6.0], [14.0, 5.0]])


def landmark_run(
    rng: np.random.Generator,
    n_steps: int = 100,
    *,
    landmarks: ArrayLike | None = None,
    start: ArrayLike = (10.0, 1.5, 0.0),
    controls: ArrayLike | None = None,
    dt: float = 0.5,
    velocity_alphas: ArrayLike = (0.01, 0.001, 0.001, 0.01, 0.001, 0.001),
    odometry_alphas: ArrayLike = DEFAULT_ODOMETRY_ALPHAS,
    sigma_range: float = 0.2,
    sigma_bearing: float = 0.05,
    max_range: float = 8.0,
    fov: float = 2 * np.pi,
) -> LandmarkRun:
    """Simulate a robot driven by velocity commands, sighting point landmarks.

    The true motion applies the velocity model (PR table 5.3, alphas as
    variances) to each command; sightings of the landmarks within
    ``max_range`` and within the field of view ``fov`` (centred on the
    heading) are ``(range, bearing)`` with independent Gaussian noise of
    standard deviations ``sigma_range`` and ``sigma_bearing`` (PR section
    6.6), bearing wrapped to ``[-pi, pi)``, with the landmark's id.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_steps : int
        Number of steps ``T`` (>= 1).
    landmarks : array_like, shape (L, 2), optional
        Default :func:`default_landmarks`.
    start : (x, y, theta)
    controls : array_like, shape (T, 2) or (T-1, 2), optional
        Commanded ``(v, omega)``; with ``T`` rows, row 0 is ignored.
        Default: 0.6 m/s on an oval lap of about 30 m through the middle of the
        landmark field (one lap is ``2*pi*4.5 / (0.6*dt)`` steps).
    dt : float
        Seconds per step.
    velocity_alphas, odometry_alphas
        Noise of the executed motion (6 alphas) and of the odometry readings
        (4 alphas), both PR conventions.
    sigma_range, sigma_bearing : float
        Measurement noise (metres, radians), >= 0.
    max_range, fov : float
        Visibility: range in metres and full field of view in radians.

    Returns
    -------
    LandmarkRun

    Examples
    --------
    >>> run = landmark_run(np.random.default_rng(0), n_steps=20)
    >>> run
    LandmarkRun(steps=20, landmarks=8, sightings=..., dt=0.5 s)
    >>> z, ids = run.sightings(0)
    >>> z.shape[1], bool(np.all(z[:, 0] <= run.max_range))
    (2, True)
    """
    rng = check_rng(rng)
    n_steps = check_count(n_steps, "n_steps")
    lm = default_landmarks() if landmarks is None else np.asarray(landmarks, dtype=float)
    if lm.ndim != 2 or lm.shape[1] != 2 or not np.all(np.isfinite(lm)):
        raise ValueError(f"landmarks must be a finite (L, 2) array of positions; got shape {lm.shape}")
    dt = check_positive(dt, "dt", "seconds")
    for name, v in (("sigma_range", sigma_range), ("sigma_bearing", sigma_bearing), ("max_range", max_range)):
        check_nonnegative(v, name)
    fov = float(fov)
    if not 0 < fov <= 2 * np.pi:
        raise ValueError(f"fov must be in (0, 2*pi] radians; got {fov}")
    if controls is None:
        # an oval lap (radius about 4.5 m) whose curvature has two periods per lap, so it closes
        v, radius = 0.6, 4.5
        period = 2 * np.pi * radius / (v * dt)
        k = np.arange(n_steps)
        u = np.stack([np.full(n_steps, v), v / radius * (1 + 0.6 * np.cos(4 * np.pi * (k - 1) / period))], axis=1)
        u[0] = 0.0
    else:
        c = np.asarray(controls, dtype=float)
        if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] not in (n_steps, n_steps - 1):
            raise ValueError(f"controls must have shape ({n_steps}, 2) or ({n_steps - 1}, 2); got {c.shape}")
        u = np.zeros((n_steps, 2))
        u[n_steps - c.shape[0]:] = c
        u[0] = 0.0
    va = np.asarray(velocity_alphas, dtype=float)
    poses = np.zeros((n_steps, 3))
    poses[0] = as_poses(start, "start")
    for k in range(1, n_steps):
        if np.any(va > 0):
            poses[k] = sample_velocity(poses[k - 1], u[k], dt, va, rng)
        else:
            poses[k] = move_velocity(poses[k - 1], u[k, 0], u[k, 1], dt)
    odometry = odometry_readings(poses, odometry_alphas, rng)
    # sightings: the landmark model's noise-free (range, bearing) of every landmark at every step, (T, L, 2)
    true_z = range_bearing(poses[:, None, :], lm[None, :, :])
    rng_true, bearing_true = true_z[..., 0], true_z[..., 1]
    visible = (rng_true <= max_range) & (np.abs(bearing_true) <= fov / 2)
    steps, ids = np.nonzero(visible)
    noise = rng.standard_normal((steps.size, 2))
    z = np.stack([np.maximum(rng_true[steps, ids] + sigma_range * noise[:, 0], 0.0),
                  wrap_angle(bearing_true[steps, ids] + sigma_bearing * noise[:, 1])], axis=1).reshape(-1, 2)
    return LandmarkRun(
        times=np.arange(n_steps) * dt, poses=poses, controls=u, odometry=odometry, landmarks=lm,
        steps=steps.astype(np.int64), ids=ids.astype(np.int64), z=z, dt=dt, sigma_range=float(sigma_range),
        sigma_bearing=float(sigma_bearing), max_range=float(max_range), fov=fov, velocity_alphas=va,
        odometry_alphas=np.asarray(odometry_alphas, dtype=float),
    )


# =========================================================================
# CMU 16-831 log writer
# =========================================================================
def write_cmu_log(path: str | os.PathLike, run: RangeRun, decimals: int = 3, odometry_rate: int = 1,
                  angle_decimals: int = 6) -> Path:
    """Write a :class:`RangeRun` as a CMU 16-831 style robot log: :func:`localize.io.write_cmu_log` of
    :meth:`RangeRun.to_log` (see there for the format).

    Each step gives an ``O`` record followed by an ``L`` record at the same
    time stamp (only every ``odometry_rate``-th step writes an ``O`` record);
    positions are written with ``decimals`` digits after the point (in cm),
    angles with ``angle_decimals`` (in radians).

    The run must have been simulated with the CMU beam layout
    (``angles=CMU_ANGLES``, the default of :func:`range_run`) and a maximum
    range below 81.83 m. The true poses are not part of the format; keep
    ``run.poses`` for scoring.

    Examples
    --------
    >>> from localize.maps import office
    >>> run = range_run(office(), np.random.default_rng(2), n_steps=3, sensor_offset=(0.25, 0, 0), sensor="ideal")
    >>> p = write_cmu_log(tmp_dir() / "sim.log", run)
    >>> lines = p.read_text().splitlines()
    >>> len(lines), lines[1].split()[0], len(lines[1].split())
    (6, 'L', 188)
    """
    if not isinstance(run, RangeRun):
        raise TypeError(f"run must be a RangeRun; got {type(run).__name__}")
    return _cmu.write_cmu_log(path, run.to_log(odometry_rate), decimals, angle_decimals)


# =========================================================================
# 1-D corridor
# =========================================================================
@dataclass(frozen=True, eq=False)
class CorridorRun(_ReadOnly):
    """A robot on a ring corridor of ``length`` metres with doors (arrays read-only).

    Position ``x`` lives on the circle ``[0, length)``; the doors are the
    1-metre cells ``[j, j + 1)`` where ``doors[j] == 1`` (the hallway of
    :func:`localize.maps.hallway`). At each step the robot is told to move
    ``u`` metres and actually moves ``u + N(0, sigma_move**2)``; then its
    door detector reports 1 ("door") with probability ``p_hit`` in front of a
    door and ``p_false`` in front of a wall.

    Attributes
    ----------
    positions : ndarray, shape (T,)
        True positions.
    controls : ndarray, shape (T,)
        Commanded motion into step ``k`` (``controls[0] = 0``).
    z : ndarray of int, shape (T,)
        Door-detector readings.
    doors : ndarray of int, shape (length,)
    sigma_move, p_hit, p_false : float
    """

    positions: NDArray[np.float64]
    controls: NDArray[np.float64]
    z: NDArray[np.int64]
    doors: NDArray[np.int64]
    sigma_move: float
    p_hit: float
    p_false: float

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @property
    def length(self) -> float:
        """Circumference of the ring in metres."""
        return float(self.doors.size)

    def control(self, k: int) -> float:
        """The commanded motion into step ``k`` (``controls[k]``), as :meth:`RangeRun.control`.

        Examples
        --------
        >>> run = corridor_run(np.random.default_rng(0), n_steps=3)
        >>> bool(run.control(1) == run.controls[1])
        True
        """
        k = _motion_step(k, len(self))
        return float(self.controls[k])

    def at_door(self, x: ArrayLike) -> NDArray[np.bool_]:
        """True where position(s) ``x`` face a door.

        Examples
        --------
        >>> run = corridor_run(np.random.default_rng(0), n_steps=2)
        >>> run.at_door([2.5, 3.5, 22.5]).tolist()        # doors at [2, 3), [5, 6), [13, 14); 22.5 wraps to 2.5
        [True, False, True]
        """
        cell = np.floor(np.mod(np.asarray(x, dtype=float), self.length)).astype(np.int64) % self.doors.size
        return self.doors[cell] == 1

    def log_likelihood(self, x: ArrayLike, z: int) -> NDArray[np.float64]:
        """``log p(z | x)`` of a door reading for positions ``x`` (vectorised).

        Examples
        --------
        >>> run = corridor_run(np.random.default_rng(0), n_steps=2)
        >>> np.exp(run.log_likelihood([2.5, 3.5], 0)).round(2)      # reads "wall": 1 - 0.8 at a door, 1 - 0.1 at a wall
        array([0.2, 0.9])
        """
        door = self.at_door(x)
        p1 = np.where(door, self.p_hit, self.p_false)
        return np.log(p1 if int(z) == 1 else 1.0 - p1)

    def move(self, x: ArrayLike, u: float, rng: np.random.Generator) -> NDArray[np.float64]:
        """Sample the motion model for positions ``x``: ``x + u + noise``, wrapped onto the ring.

        Examples
        --------
        >>> run = corridor_run(np.random.default_rng(0), n_steps=2, sigma_move=0.0)
        >>> run.move([0.5, 19.5], 1.0, np.random.default_rng(1))
        array([1.5, 0.5])
        """
        x = np.asarray(x, dtype=float)
        return np.mod(x + float(u) + self.sigma_move * rng.standard_normal(x.shape), self.length)

    def ring_error(self, estimate: ArrayLike) -> NDArray[np.float64]:
        """Shortest distance along the ring between estimates (shape (T,)) and the true positions.

        Examples
        --------
        >>> run = corridor_run(np.random.default_rng(0), n_steps=2, start=0.5, sigma_move=0.0)
        >>> run.ring_error([19.5, 1.0])                   # 1 m back across the seam; 0.5 m behind
        array([1. , 0.5])
        """
        d = np.mod(np.asarray(estimate, dtype=float) - self.positions, self.length)
        return np.minimum(d, self.length - d)

    def ring_mean(self, particles: ArrayLike, weights: ArrayLike | None = None) -> NDArray[np.float64] | float:
        """Weighted circular mean position of particles on the ring (along the last axis).

        The plain average of 19 m and 1 m on a 20 m ring is 10 m, the point
        opposite both; the circular mean is 0 m, between them.

        Examples
        --------
        >>> run = corridor_run(np.random.default_rng(0), n_steps=2)
        >>> round(run.ring_mean([19.0, 1.0, 0.5], [1.0, 1.0, 0.0]) % 20.0, 6) in (0.0, 20.0)
        True
        """
        a = 2 * np.pi * np.asarray(particles, dtype=float) / self.length
        w = np.ones(a.shape) if weights is None else np.asarray(weights, dtype=float)
        ang = np.arctan2(np.sum(w * np.sin(a), axis=-1), np.sum(w * np.cos(a), axis=-1))
        out = np.mod(ang * self.length / (2 * np.pi), self.length)
        return float(out) if np.ndim(out) == 0 else out


def corridor_run(
    rng: np.random.Generator,
    n_steps: int = 30,
    *,
    doors: ArrayLike | None = None,
    start: float | None = None,
    step: float = 1.0,
    sigma_move: float = 0.2,
    p_hit: float = 0.8,
    p_false: float = 0.1,
) -> CorridorRun:
    """Simulate the door-detecting robot on a ring corridor (see :class:`CorridorRun`).

    Parameters
    ----------
    rng : numpy.random.Generator
    n_steps : int
        Number of steps ``T`` (>= 1); step 0 only measures.
    doors : array_like of 0/1, optional
        Default :func:`localize.maps.hallway` (20 m, doors at 2, 5 and 13 m).
    start : float, optional
        Start position; default uniform on the ring.
    step : float
        Commanded motion per step (metres).
    sigma_move : float
        Standard deviation of the motion noise per step (metres).
    p_hit, p_false : float
        Probabilities of reading "door" in front of a door and a wall.

    Examples
    --------
    >>> run = corridor_run(np.random.default_rng(0), n_steps=5, start=1.5)
    >>> run.positions.round(2), run.z
    (array([1.5 , 2.53, 3.5 , 4.63, 5.65]), array([0, 0, 0, 0, 1]))
    >>> run.log_likelihood([2.5, 8.0], 1).round(4)               # log 0.8, log 0.1
    array([-0.2231, -2.3026])
    """
    from .maps import hallway

    rng = check_rng(rng)
    n_steps = check_count(n_steps, "n_steps")
    d = hallway() if doors is None else np.asarray(doors)
    if d.ndim != 1 or d.size < 2 or not np.all(np.isin(d, (0, 1))):
        raise ValueError(f"doors must be a 1-D array of 0 (wall) and 1 (door) with >= 2 cells; got {d!r}")
    for name, v in (("p_hit", p_hit), ("p_false", p_false)):
        if not 0.0 < float(v) < 1.0:
            raise ValueError(f"{name} must lie in (0, 1); got {v}")
    check_nonnegative(sigma_move, "sigma_move")
    run0 = CorridorRun(np.zeros(1), np.zeros(1), np.zeros(1, np.int64), d.astype(np.int64), float(sigma_move),
                       float(p_hit), float(p_false))
    length = run0.length
    x = np.empty(n_steps)
    x[0] = rng.uniform(0, length) if start is None else float(start) % length
    u = np.full(n_steps, float(step))
    u[0] = 0.0
    for k in range(1, n_steps):
        x[k] = run0.move(x[k - 1], u[k], rng)
    p1 = np.where(run0.at_door(x), p_hit, p_false)
    z = (rng.random(n_steps) < p1).astype(np.int64)
    return CorridorRun(x, u, z, d.astype(np.int64), float(sigma_move), float(p_hit), float(p_false))
