"""The log-level pipeline: read a log and a map, build the sensor model and the filter, run it, collect the result.

What ``localize run`` does between parsing its options and writing its files,
as a library that the command line (:mod:`localize.cli`), the offline
smoother (:mod:`localize.smooth`), the benchmarks and chapter 9 import:

* :func:`read_log_file`, :func:`read_map_file`, :func:`read_inputs` -- the
  files, formats detected from their content (:mod:`localize.io`), a map built
  from a corrected log's poses (:func:`localize.mapping.map_from_log`);
* :func:`localize_log` -- one run of the run driver
  :func:`localize.runloop.run_filter` over a log, with the settings of a
  :class:`~localize.settings.RunSettings`; it returns a :class:`RunResult`;
* :func:`make_sensor`, :func:`kld_sampling`, :func:`augmented_filter`,
  :func:`auto_particles` -- the pieces it builds from the settings;
* :func:`check_log_odometry` -- the scans' check of the odometry's sign;
* :func:`check_log_max_range` -- the readings' check of the maximum range the log states;
* :func:`converged_at` -- when a trajectory's error (or spread) settles.

Examples
--------
>>> from localize import sim
>>> from localize.io import LaserLog
>>> from localize.maps import office
>>> from localize.settings import RunSettings
>>> g = office(0.1)
>>> run = sim.range_run(g, np.random.default_rng(1), n_steps=12, dt=0.5, speed=0.4, max_range=10.0)
>>> log = LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles,
...                max_range=run.max_range, poses=run.poses)
>>> s = RunSettings(particles=500, track=True, kld=0, min_motion=(0, 0))
>>> res = localize_log(g, log, s, rng=np.random.default_rng(0))
>>> res.estimates.shape, bool(np.hypot(*(res.estimates[-1, :2] - run.poses[-1, :2])) < 0.5)
((12, 3), True)
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_rng
from .grid import OccupancyGrid
from .motion import ReversibleOdometry
from .settings import DEFAULTS, LEGACY_NAMES, RunSettings

__all__ = ["RunResult", "localize_log", "make_sensor", "check_log_odometry", "check_log_max_range", "auto_particles",
           "resolve_particles", "converged_at", "kld_sampling", "augmented_filter", "settings_with", "read_log_file", "read_map_file",
           "read_inputs", "Inputs", "check_free_space", "map_summary", "AUTO_PARTICLES", "ODOMETRY_SIGN",
           "read_reference", "match_reference", "MapCheck", "check_map", "particles_for_area", "scanned_area"]


# ============================================================================ particles
#: ``--particles auto``: one particle per KLD bin of the map's free space, within these bounds.
AUTO_PARTICLES: tuple[int, int] = (20_000, 300_000)


def auto_particles(grid: OccupancyGrid) -> int:
    """The initial cloud of ``localize run --particles auto`` (the default) for a map.

    One particle per 0.5 m x 0.5 m x 10 degree bin of the free space
    (:func:`localize.kld.pose_bins`, KLD-sampling's bins), so that a uniform
    cloud leaves few bins near the robot empty whatever the building's size;
    at least 20,000 and at most 300,000 (:data:`AUTO_PARTICLES`). About
    75,000 for a floor of 520 m^2 of free space, 115,000 for 800 m^2.

    Examples
    --------
    >>> from localize.maps import office
    >>> auto_particles(office())                 # the book's office: 204 m^2 of free space
    29412
    """
    from .kld import pose_bins

    lo, hi = AUTO_PARTICLES
    return int(min(max(pose_bins(grid), lo), hi))


def resolve_particles(n: int | str, grid: OccupancyGrid | None) -> int:
    """``n`` particles, or :func:`auto_particles` of ``grid`` for ``"auto"``.

    >>> resolve_particles(700, None), resolve_particles("auto", OccupancyGrid(np.zeros((10, 10)), 0.1))
    (700, 20000)
    """
    if isinstance(n, str):
        if n != "auto":
            raise ValueError(f"n_particles must be a whole number >= 1 or 'auto'; got {n!r}")
        if grid is None:
            raise ValueError("n_particles='auto' sizes the cloud from the map: pass grid=... (or a number)")
        return auto_particles(grid)
    return check_count(n, "n_particles")


# ============================================================================ settings -> objects
def settings_with(settings: RunSettings | None = None, **changes: Any) -> RunSettings:
    """``settings`` (default :class:`~localize.settings.RunSettings`) with ``changes``, old names accepted.

    Besides the settings' own names, the keywords :func:`localize_log` had
    before the settings had a home are read: ``n_particles``, ``short_beams``,
    ``recovery``; ``init`` ("global" / "reference", the setting ``track``);
    ``kld`` as a :class:`~localize.kld.KLDSampling`, ``"default"`` or None (off);
    ``augmented`` as an :class:`~localize.mcl.Augmented`, a pair or None (off);
    ``sensor_params`` with a ``sigma_hit`` (the setting ``sigma_hit``).

    Examples
    --------
    >>> s = settings_with(n_particles=500, init="reference", kld=None, sensor_params={"sigma_hit": 0.15})
    >>> s.particles, s.track, s.kld, s.sigma_hit, s.sensor_params
    (500, True, 0.0, 0.15, {})
    """
    ch: dict[str, Any] = {LEGACY_NAMES.get(k, k): v for k, v in changes.items()}
    if "init" in ch:
        init = ch.pop("init")
        if init not in ("global", "reference"):
            raise ValueError(f"init must be 'global' or 'reference'; got {init!r}")
        ch["track"] = init == "reference"
    if "kld" in ch and not isinstance(ch["kld"], (int, float)):
        k = ch.pop("kld")
        if k is None:
            ch["kld"] = 0.0
        elif isinstance(k, str):
            if k != "default":
                raise ValueError(f"kld must be a localize.kld.KLDSampling, 'default' or None; got {k!r}")
        else:
            ch.update(kld=k.epsilon, kld_delta=k.delta, min_particles=k.n_min, kld_max_particles=k.n_max,
                      kld_chunked=k.chunked)
    if "augmented" in ch:
        a = ch.pop("augmented")
        if a is None:
            ch["augmented"] = (0.0, 0.0)
        elif isinstance(a, (tuple, list)):
            ch.update(augmented=tuple(a[:2]), augmented_temperature=float(a[2]) if len(a) > 2 else 1.0)
        else:
            ch.update(augmented=(a.alpha_slow, a.alpha_fast), augmented_temperature=a.temperature)
    if "sensor_params" in ch:
        params = dict(ch["sensor_params"] or {})
        if "sigma_hit" in params:
            ch["sigma_hit"] = params.pop("sigma_hit")
        ch["sensor_params"] = params
    return replace(settings if settings is not None else RunSettings(), **ch)


def kld_sampling(settings: RunSettings, n_particles: int):
    """The :class:`~localize.kld.KLDSampling` of ``settings`` for a run of ``n_particles``, or None (``kld`` 0).

    >>> k = kld_sampling(RunSettings(), 30000)
    >>> k.epsilon, k.n_min, k.n_max, k.chunked
    (0.05, 2000, 30000, True)
    """
    if not settings.kld > 0:
        return None
    from .kld import KLDSampling

    n_max = int(n_particles) if settings.kld_max_particles is None else settings.kld_max_particles
    return KLDSampling(epsilon=settings.kld, delta=settings.kld_delta, n_min=min(settings.min_particles, n_max),
                       n_max=n_max, chunked=settings.kld_chunked)


def augmented_filter(settings: RunSettings):
    """The :class:`~localize.mcl.Augmented` of ``settings``, or None (rates 0 0).

    >>> augmented_filter(RunSettings(augmented=(0.01, 0.2)))
    Augmented(alpha_slow=0.01, alpha_fast=0.2, temperature=30.0)
    """
    slow, fast = settings.augmented
    if not (slow > 0 or fast > 0):
        return None
    from .mcl import Augmented

    temperature = settings.augmented_temperature
    if temperature is None:
        temperature = float(settings.beams) if settings.beams is not None else 1.0
    try:
        return Augmented(alpha_slow=slow, alpha_fast=fast, temperature=temperature)
    except ValueError as e:
        raise ValueError(f"--augmented {slow:g} {fast:g}: {e}") from None


def make_sensor(kind: str, grid: OccupancyGrid, max_range: float, sensor_offset: NDArray, **params: Any):
    """Build the range sensor model named ``kind`` ("likelihood" or "beam") for a log run.

    Defaults are chosen for real data: maps are 10-15 cm off (walls drawn
    thicker than the laser sees them, furniture moved), so ``sigma_hit`` is a
    generous 0.3 m and a random-reading component is always present. Keyword
    arguments override them (``sigma_hit``, ``temper``, ``z_hit`` ...).

    Examples
    --------
    >>> from localize.maps import office
    >>> make_sensor("likelihood", office(), 8.0, np.zeros(3), sigma_hit=0.2)
    LikelihoodField(max_range=8, z_hit=0.9, z_rand=0.1, sigma_hit=0.2, max_dist=0.8)
    """
    from . import sensors

    if kind == "likelihood":
        kw: dict[str, Any] = dict(z_hit=0.9, z_rand=0.1, sigma_hit=0.3, unknown_is_obstacle=False,
                                  unknown_neutral=True)
        kw.update(params)
        return sensors.LikelihoodField(grid, max_range, sensor_offset=tuple(sensor_offset), **kw)
    if kind == "beam":
        # ray casting by the compact lookup table (under 90 MB, about a second to build for an
        # 800 x 800 map; see localize.raycast); method="march" needs no table but is ~30x slower
        kw = dict(z_hit=0.75, z_short=0.05, z_max=0.05, z_rand=0.15, sigma_hit=0.3, lambda_short=0.5,
                  method="compact")
        kw.update(params)
        return sensors.BeamModel(grid, max_range, sensor_offset=tuple(sensor_offset), **kw)
    raise ValueError(f"sensor must be 'likelihood' or 'beam'; got {kind!r}")


# ============================================================================ the result
@dataclass
class RunResult:
    """What :func:`localize_log` returns: the run driver's record of every scan, with the scans' times.

    ``trace`` is :func:`localize.runloop.run_filter`'s :class:`~localize.runloop.RunTrace` (the one trace type);
    the other attributes are read from it: ``estimates`` (its ``poses``), ``spread`` (the position spread
    of *all* particles, ``hypot(std_x, std_y)``), ``n_eff``, ``updated``, ``seconds``, ``snapshots``,
    ``state`` (``searching``, ``localized`` or ``lost``, see :class:`localize.policies.StateRules`) and
    ``covariances`` (``(K, 3, 3)``: the weighted covariance of the best cluster per scan, the trace's ``cov``;
    for a trace without one, the variances of all particles on the diagonal). ``snapshots`` always hold
    the last scan's particles (the report's final cloud).
    """

    times: NDArray[np.float64]
    trace: Any
    odometry_check: Any = None

    @property
    def estimates(self) -> NDArray[np.float64]:
        return self.trace.poses

    @property
    def spread(self) -> NDArray[np.float64]:
        return np.hypot(self.trace.stds[:, 0], self.trace.stds[:, 1])

    @property
    def covariances(self) -> NDArray[np.float64]:
        cov = getattr(self.trace, "cov", None)
        if cov is not None:
            return np.asarray(cov, dtype=float)
        covs = np.zeros((len(self.trace), 3, 3))
        covs[:, [0, 1, 2], [0, 1, 2]] = self.trace.stds ** 2
        return covs

    def __getattr__(self, name: str) -> Any:
        if name in ("n_eff", "updated", "seconds", "snapshots", "state"):
            return getattr(self.trace, name)
        raise AttributeError(f"RunResult has no attribute {name!r}")

    @property
    def seconds_per_scan(self) -> float:
        return self.seconds / max(len(self.times), 1)


# ============================================================================ maximum range
#: A laser says "no return" with one value (its maximum, or an error code; a few lasers have a handful of
#: codes). Readings above the stated maximum that take at least this many values are measurements.
MAX_RANGE_DISTINCT = 20
#: ... and at least this share of the readings: fewer change little whether they are used or not.
MAX_RANGE_SHARE = 0.01


def _measurements(distinct: int, share: float) -> bool:
    """Whether readings above a stated maximum range are measurements rather than no-return codes."""
    return distinct >= MAX_RANGE_DISTINCT and share >= MAX_RANGE_SHARE


def _warn_user(message: str) -> None:
    warnings.warn(message, UserWarning, stacklevel=5)   # at the caller of localize_log or smooth_log


def run_max_range(log, s: RunSettings):
    """``check_log_max_range`` as a run does it: a Python warning, unless ``s.max_range`` keeps the stated range."""
    keeps = s.max_range is not None and s.max_range <= log.max_range
    return check_log_max_range(log, None if keeps else _warn_user)[0]


def check_log_max_range(log, warn: Callable[[str], None] | None = None):
    """``(log, message)``: the log with the maximum range its readings show, when its stated one is too short.

    Readings at or above a log's ``max_range`` mean "no return". A header can
    understate the laser's reach (a configuration copied from another laser,
    a driver's default): then a reader that believes it throws most of the
    scan away, and the filter localizes on the few short beams that are left.
    A laser reports "no return" as one value (or a handful of error codes);
    measurements take a continuum of values. When at least
    :data:`MAX_RANGE_DISTINCT` distinct values, and at least
    :data:`MAX_RANGE_SHARE` of the readings, lie above the stated maximum,
    they are measurements, and the log's ``max_range`` becomes its largest
    reading (readings equal to the stated maximum still mean "no return").
    ``message`` says what was changed (also sent to ``warn``); it is None,
    and the log is returned as it is, otherwise. ``--max-range`` (the
    setting) still caps the range a run uses.

    Examples
    --------
    >>> from localize.io import LaserLog
    >>> rng = np.random.default_rng(0)
    >>> ranges = rng.uniform(0.5, 12.0, (20, 90))                 # a 12 m laser ...
    >>> ranges[:, 0] = 2.5                                       # ... whose no-return code is 2.5
    >>> log = LaserLog(times=np.arange(20.0), odometry=np.zeros((20, 3)), ranges=ranges,
    ...                angles=np.linspace(-1.5, 1.5, 90), max_range=2.5)   # ... in a log that states 2.5 m
    >>> fixed, msg = check_log_max_range(log)
    >>> round(fixed.max_range, 2), bool(fixed.no_return[:, 0].all()), int(fixed.no_return[:, 1:].sum())
    (12.0, True, 1)
    >>> print(msg)
    the log states a maximum range of 2.5 m, but 82% of its readings lie above it (1472 distinct values, up to 12 m): they are measurements, so the run uses 12 m (--max-range 2.5 keeps the stated one)
    >>> check_log_max_range(fixed)[1] is None                     # nothing above the maximum now
    True
    """
    stated = float(log.max_range)
    above = log.ranges[log.ranges > stated]
    distinct = int(np.unique(above).size)
    share = above.size / log.ranges.size
    if not _measurements(distinct, share):
        return log, None
    reach = float(above.max())
    msg = (f"the log states a maximum range of {stated:g} m, but {share:.0%} of its readings lie above it "
           f"({distinct} distinct values, up to {reach:.3g} m): they are measurements, so the run uses "
           f"{reach:.3g} m (--max-range {stated:g} keeps the stated one)")
    ranges = np.where(log.ranges == stated, reach, log.ranges)      # the stated maximum still means no return
    log = replace(log, ranges=ranges, max_range=reach,
                  meta={**log.meta, "stated_max_range": stated,
                        "max_range_source": f"largest reading ({distinct} distinct values above the stated "
                                            f"{stated:g} m, {share:.0%} of the readings)"})
    if warn is not None:
        warn(msg)
    return log, msg


# ============================================================================ odometry
#: ``--odometry-sign``: when the scans may reverse odometry steps (see :func:`check_log_odometry`).
ODOMETRY_SIGN = ("auto", "check", "trust")


def check_log_odometry(log, mode: str = DEFAULTS["odometry_sign"], min_range: float = DEFAULTS["min_range"]):
    """``(log, check)``: the log with the odometry steps the scans say were driven backwards reversed.

    ``mode`` "check" compares every step of the odometry with consecutive scans
    (:func:`localize.scanmatch.check_odometry_sign`); "auto" (the default of
    ``localize run``) does so only for odometry that never reports reversing
    (:func:`localize.scanmatch.reports_reversing`): a speed without a sign,
    whose backing-up manoeuvres read as driving forwards; "trust" never.
    ``check`` is the :class:`~localize.scanmatch.OdometrySignCheck`, or None
    when nothing was checked. A log whose steps all keep their sign is
    returned as it is.

    Examples
    --------
    >>> from localize.io import LaserLog
    >>> wall = np.c_[np.full(41, 2.0), np.linspace(-1, 1, 41)]            # a wall 2 m ahead
    >>> angles = np.arctan2(wall[:, 1], wall[:, 0])
    >>> log = LaserLog(times=[0.0, 1.0], odometry=[[0, 0, 0], [0.4, 0, 0]], angles=angles, max_range=30.0,
    ...                ranges=[np.hypot(*wall.T), np.hypot(wall[:, 0] + 0.4, wall[:, 1])])   # backs up 0.4 m
    >>> fixed, chk = check_log_odometry(log)
    >>> chk.reversed.tolist(), fixed.odometry[-1].round(3).tolist()
    ([0], [-0.4, 0.0, 0.0])
    >>> check_log_odometry(log, "trust")[1] is None
    True
    """
    from .scanmatch import check_odometry_sign, reports_reversing

    if mode not in ODOMETRY_SIGN:
        raise ValueError(f"odometry_sign must be one of {', '.join(ODOMETRY_SIGN)}; got {mode!r}")
    if mode == "trust" or (mode == "auto" and reports_reversing(log.odometry)):
        return log, None
    chk = check_odometry_sign(log.ranges, log.angles, log.odometry, log.max_range, min_range=min_range or 0.0,
                              sensor_offset=log.sensor_offset)
    if chk.reversed.size:
        log = replace(log, odometry=chk.odometry, meta={**log.meta, "odometry_reversed_by_scans": chk.summary()})
    return log, chk


# ============================================================================ the run
def localize_log(grid: OccupancyGrid, log, settings: RunSettings | None = None, *, rng: np.random.Generator | None = None,
                 progress: Any = None, snapshot_every: int = 0, snapshot_particles: int = 1000, rules: Any = None,
                 **changes: Any) -> RunResult:
    """Run MCL over a :class:`~localize.io.LaserLog` on ``grid`` with ``settings``; return the per-scan estimates.

    The filtering loop is :func:`localize.runloop.run_filter`, the one run driver
    (update gating, estimates, the searching / localized / lost state); this
    function builds the filter from the settings (:class:`~localize.settings.RunSettings`,
    default: those of ``localize run``), with ``changes`` to them by keyword
    (:func:`settings_with`: ``beams=60``, ``init="reference"``, ...).

    Parameters
    ----------
    grid : OccupancyGrid
        The map.
    log : LaserLog
        Scans and odometry (the controls are consecutive odometry poses).
    settings : RunSettings, optional
        The run's settings (see ``localize run --help`` for each).
    rng : numpy.random.Generator
        The only source of randomness (required).
    progress : object with ``update_to(done)``, optional
        Told the number of scans done after each scan.
    snapshot_every : int
        Keep a subsample of ``snapshot_particles`` particles every so many scans (for animations); 0: never.
    rules : localize.policies.StateRules, optional
        Thresholds of the honest state.
    **changes
        Settings changed for this run (see :func:`settings_with`).

    Returns
    -------
    RunResult
    """
    from .mcl import MCL, RobustOdometry
    from .runloop import run_filter

    check_rng(rng)
    s = settings_with(settings, **changes)
    n_particles = resolve_particles(s.particles, grid)
    log = run_max_range(log, s)
    log, sign_check = check_log_odometry(log, s.odometry_sign, min_range=s.min_range)
    if s.beams is not None and s.beams < log.n_beams:
        log = log.select_beams(count=s.beams)
    mr = log.max_range if s.max_range is None else min(float(s.max_range), log.max_range)
    model = make_sensor(s.sensor, grid, mr, log.sensor_offset, temper=s.temper, **_sensor_params(s))
    ranges = np.minimum(log.ranges, mr)
    motion: Any = ReversibleOdometry(s.alphas, min_trans=s.min_trans)
    if s.odometry_outliers:
        motion = RobustOdometry(motion, outlier=s.odometry_outliers)
    opts: dict[str, Any] = dict(resample_threshold=s.resample_threshold, injection=s.injection,
                                free_space_only=s.free_space_only, augmented=augmented_filter(s),
                                kld=kld_sampling(s, n_particles), unknown_allowed=s.unknown_allowed,
                                unknown_penalty=s.unknown_penalty, min_ess=s.min_ess,
                                occupied_penalty=s.occupied_penalty)
    if s.initial_pose is not None:  # a known start (--initial-pose, AMCL's initial_pose_*)
        _check_initial_pose(grid, s)
        f = MCL.gaussian(np.asarray(s.initial_pose, dtype=float), tuple(s.initial_std), n_particles, motion, model,
                         rng=rng, grid=grid, **opts)
    elif not s.track:
        f = MCL.uniform(grid, n_particles, motion, model, rng=rng, **opts)
    else:
        if log.poses is None:
            raise ValueError("init='reference' (track) needs reference poses in the log (log.poses is None)")
        f = MCL.gaussian(log.poses[0], tuple(s.init_std), n_particles, motion, model, rng=rng, grid=grid, **opts)
    k_scans = len(log)
    snap_steps: Sequence[int] = [k_scans - 1]  # the last scan's cloud, always (the report's final particles)
    if snapshot_every:
        snap_steps = sorted(set(range(0, k_scans, snapshot_every)) | {k_scans - 1})
    odo = log.odometry
    angles = log.angles
    tr = run_filter(f, k_scans, lambda k: (odo[k - 1], odo[k]), lambda k: (ranges[k], angles), grid=grid,
                    min_motion=tuple(s.min_motion), rules=rules, snapshot_steps=snap_steps,
                    snapshot_particles=snapshot_particles, odometry=odo, recovery_injection=s.recovery_injection,
                    restart_after=s.restart_after, expand=tuple(s.expand),
                    skip_unknown_beams=s.unknown_beams == "skip", skip_short_beams=s.skip_short_beams,
                    state=s.state, sensor_reset=s.sensor_reset,
                    callback=None if progress is None else progress.update_to)
    return RunResult(times=np.asarray(log.times), trace=tr, odometry_check=sign_check)


def _check_initial_pose(grid: OccupancyGrid, s: RunSettings) -> None:
    """ValueError if ``s.initial_pose`` lies off the map, or comes with ``track``."""
    if s.track:
        raise ValueError("give either --track (the log's first reference pose) or --initial-pose, not both")
    x, y = s.initial_pose[0], s.initial_pose[1]
    if not grid.contains(np.array([[x, y]]))[0]:
        x0, y0 = grid.origin
        raise ValueError(f"--initial-pose {x:g} {y:g}: outside the map ({x0:g} to {x0 + grid.width_m:g} m in x, "
                         f"{y0:g} to {y0 + grid.height_m:g} m in y); give the pose in the map's frame")


def _sensor_params(s: RunSettings) -> dict[str, Any]:
    """The sensor model's keyword arguments of ``s`` (``sensor_params`` win over the named settings)."""
    params = dict(s.sensor_params)
    params.setdefault("sigma_hit", s.sigma_hit)
    if s.sensor == "likelihood":
        if s.min_range:
            params.setdefault("min_range", float(s.min_range))
        params.setdefault("z_short", s.z_short)
    return params


# ============================================================================ files
@dataclass(frozen=True)
class Inputs:
    """The files of a run and how to read them (``localize run``'s input options).

    ``map`` is a map file, or None with ``build_map`` (the map built from the
    log's reference poses at ``resolution``); ``scans`` selects scans of the log.
    """

    log: Path
    map: Path | None = None
    log_format: str | None = None
    map_format: str | None = None
    scan_topic: str | None = None
    odom_topic: str | None = None
    laser_pose: tuple[float, float, float] | None = None
    build_map: bool = False
    resolution: float = 0.05
    not_free_is_occupied: bool = False
    scans: slice | None = None

    def __post_init__(self) -> None:
        if self.map is None and not self.build_map:
            raise ValueError("give --map FILE, or --build-map to build the map from the log's corrected poses")
        if self.map is not None and self.build_map:
            raise ValueError("give either --map or --build-map, not both")


def _relaying_warnings(warn: Callable[[str], None] | None, read: Callable, *args: Any, **kwargs: Any) -> Any:
    """``read(*args, **kwargs)``, each warning it gives passed to ``warn`` as text (or left to Python: None)."""
    if warn is None:
        return read(*args, **kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = read(*args, **kwargs)
    for w in caught:
        warn(str(w.message))
    return out


def read_log_file(path: Path, format: str | None = None, *, scan_topic: str | None = None,
                  odom_topic: str | None = None, laser_pose: ArrayLike | None = None,
                  min_range: float | None = None, warn: Callable[[str], None] | None = None):
    """Read a log (CMU, CARMEN or a ROS bag, detected from the content) as a :class:`~localize.io.LaserLog`.

    ``laser_pose`` overrides the log's sensor mounting pose; readings below
    ``min_range`` become "no return" (the log's maximum range); the readers'
    warnings (skipped records, time stamps) go to ``warn``.

    Examples
    --------
    >>> read_log_file(Path("missing.log"))
    Traceback (most recent call last):
    ...
    localize.io._common.FormatError: missing.log: no such file
    """
    from . import io as lio
    from .io import rosbag

    if format == "rosbag" or (format is None and rosbag.is_rosbag(path)):
        log = rosbag.read_rosbag(path, scan_topic=scan_topic, odom_topic=odom_topic, laser_pose=laser_pose)
        if log.skipped and warn is not None:
            warn(f"{path}: skipped " + "; ".join(f"{n} {k}" for k, n in log.skipped.items()))
        over = log.meta.get("above_range_max")
        if over and warn is not None and _measurements(over["distinct"], over["share"]):
            warn(f"{path}: {over['share']:.0%} of the readings ({over['distinct']} distinct values, up to "
                 f"{over['largest']:.3g} m) lie above the scans' range_max ({log.max_range:g} m): ROS and AMCL "
                 "discard them, and so does this run; if the laser reaches further, its driver's range_max is "
                 "set too short")
    else:
        if scan_topic or odom_topic:
            raise ValueError("--scan-topic and --odom-topic apply to ROS bags only")
        log = _relaying_warnings(warn, lio.read_log, path, format=format)
        for msg in lio.time_stamp_problems(log):
            if warn is not None:
                warn(f"{msg}; the filter follows the record order")
        if laser_pose is not None:
            log = replace(log, sensor_offset=np.asarray(laser_pose, dtype=float),
                          meta={**log.meta, "sensor_offset_source": "given (--laser-pose)"})
    log, _ = check_log_max_range(log, None if warn is None else (lambda m: warn(f"{path}: {m}")))
    if min_range:                                   # after it: a short reading becomes the real "no return"
        r = np.array(log.ranges, copy=True)
        r[r < min_range] = log.max_range
        log = replace(log, ranges=r, meta={**log.meta, "min_range": min_range})
    return log


def read_map_file(path: Path, format: str | None = None, *, not_free_is_occupied: bool = False,
                  warn: Callable[[str], None] | None = None) -> OccupancyGrid:
    """Read a map (CMU 16-831 or ROS map_server, detected from the content); its warnings go to ``warn``.

    >>> from localize import io
    >>> path = io.write_cmu_map(tmp_dir() / "m.dat", OccupancyGrid(np.zeros((4, 6)), 0.1))
    >>> read_map_file(path).shape
    (4, 6)
    >>> read_map_file(path, not_free_is_occupied=True)
    Traceback (most recent call last):
    ...
    ValueError: --not-free-is-occupied applies to ROS map_server maps only
    """
    from . import io as lio

    kw = {"not_free": "occupied"} if not_free_is_occupied else {}
    fmt = format or lio.detect_map_format(path)
    if kw and fmt != "ros":
        raise ValueError("--not-free-is-occupied applies to ROS map_server maps only")
    return _relaying_warnings(warn, lio.read_map, path, format=fmt, **kw)


def check_free_space(grid: OccupancyGrid, where: str) -> None:
    """ValueError naming ``where`` if ``grid`` has no free cell to localize in.

    >>> check_free_space(OccupancyGrid(np.ones((2, 2)), 0.1), "walls.dat")
    Traceback (most recent call last):
    ...
    ValueError: walls.dat: the map has no free cell to localize in (4 occupied, 0 unknown of 4 cells); check the map's format and thresholds (ROS maps: --not-free-is-occupied only adds obstacles)
    """
    if not grid.free.any():
        raise ValueError(f"{where}: the map has no free cell to localize in ({grid.occupied.sum()} occupied, "
                         f"{grid.unknown.sum()} unknown of {grid.data.size} cells); check the map's format and "
                         "thresholds (ROS maps: --not-free-is-occupied only adds obstacles)")


def read_inputs(inputs: Inputs, min_range: float | None = None, warn: Callable[[str], None] | None = None):
    """``(log, grid, map_description)``: the log (its ``scans``) and the map of a run, checked.

    Examples
    --------
    >>> Inputs(log=Path("missing.log"), map=Path("m.dat"), build_map=True)
    Traceback (most recent call last):
    ...
    ValueError: give either --map or --build-map, not both
    """
    from .mapping import map_from_log

    log = read_log_file(inputs.log, inputs.log_format, scan_topic=inputs.scan_topic, odom_topic=inputs.odom_topic,
                        laser_pose=inputs.laser_pose, min_range=min_range, warn=warn)
    if inputs.scans is not None:
        log = log.select(inputs.scans)
    if inputs.build_map:
        if log.poses is None:
            raise ValueError(f"{inputs.log}: --build-map needs reference poses in the log (it has none); give --map")
        grid = map_from_log(log, resolution=inputs.resolution)
        desc = f"built from {inputs.log} (resolution {inputs.resolution:g} m)"
    else:
        grid = read_map_file(inputs.map, inputs.map_format, not_free_is_occupied=inputs.not_free_is_occupied,
                             warn=warn)
        desc = str(inputs.map)
    check_free_space(grid, desc)
    return log, grid, desc


def _read_reference_csv(p: Path) -> tuple[NDArray, NDArray]:
    """``(times, poses)`` of a CSV file with columns time, x, y, theta (a header naming them, or none)."""
    from .io._common import FormatError

    rows, cols = [], None
    for n, line in enumerate(p.read_text().splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        f = [v.strip() for v in s.split(",")]
        if cols is None and not rows:
            try:
                float(f[0])
            except ValueError:
                names = [v.lower() for v in f]
                missing = [c for c in ("time", "x", "y", "theta") if c not in names]
                if missing:
                    raise FormatError(p, n, f"the header names no column {', '.join(missing)}; expected "
                                            "time,x,y,theta") from None
                cols = [names.index(c) for c in ("time", "x", "y", "theta")]
                continue
        idx = cols or [0, 1, 2, 3]
        if len(f) <= max(idx):
            raise FormatError(p, n, f"expected time,x,y,theta; got {len(f)} field(s)")
        try:
            rows.append([float(f[i]) for i in idx])
        except ValueError:
            raise FormatError(p, n, f"expected numbers (time,x,y,theta); got {s[:60]!r}") from None
        if not np.all(np.isfinite(rows[-1])):
            raise FormatError(p, n, f"expected finite numbers; got {s[:60]!r}")
    if not rows:
        raise FormatError(p, None, "the file holds no poses (expected CSV time,x,y,theta or TUM)")
    a = np.array(rows)
    return a[:, 0], a[:, 1:4]


def read_reference(path: Path) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(times, poses)`` of a reference trajectory file: TUM, or CSV with columns time, x, y, theta.

    The format is read from the content: lines of eight space-separated numbers
    are TUM (:func:`localize.io.tum.read_tum`), comma-separated lines CSV (a
    header naming ``time,x,y,theta`` is optional; a ``trajectory.csv`` of an
    earlier run qualifies). Times must not decrease.

    Examples
    --------
    >>> p = tmp_dir() / "ref.csv"
    >>> _ = p.write_text("time,x,y,theta\\n0.0,1,2,0\\n1.0,2,2,0.5\\n")
    >>> t, poses = read_reference(p)
    >>> t.tolist(), poses[1].tolist()
    ([0.0, 1.0], [2.0, 2.0, 0.5])
    >>> _ = p.write_text("time,x,y\\n0.0,1,2\\n")
    >>> read_reference(p)
    Traceback (most recent call last):
    ...
    localize.io._common.FormatError: ...ref.csv:1: the header names no column theta; expected time,x,y,theta
    """
    from .io._common import FormatError
    from .io.tum import read_tum

    p = Path(path)
    if not p.is_file():
        raise FormatError(p, None, "no such file (--reference: a TUM file or a CSV with time,x,y,theta)")
    first = next((ln.strip() for ln in p.read_text().splitlines() if ln.strip() and not ln.startswith("#")), "")
    if "," not in first and len(first.split()) == 8:
        t, poses = read_tum(p)
    else:
        t, poses = _read_reference_csv(p)
    if np.any(np.diff(t) < 0):
        k = int(np.flatnonzero(np.diff(t) < 0)[0])
        raise FormatError(p, None, f"the times go back (pose {k + 2}: {t[k + 1]:g} after {t[k]:g}); sort the file")
    return t, poses


def match_reference(ref_times: ArrayLike, ref_poses: ArrayLike, times: ArrayLike, max_gap: float = 0.5,
                    where: str = "the reference") -> NDArray[np.float64]:
    """The reference pose at each of ``times``: interpolated between the two nearest reference poses.

    A scan more than ``max_gap`` seconds from every reference pose gets NaN
    (no reference there); headings are interpolated on the circle. Raises a
    ValueError when no scan gets a reference (the files cover different times).

    Examples
    --------
    >>> match_reference([0.0, 1.0], [[0, 0, 3.0], [1, 0, -2.9]], [0.5, 5.0]).round(3).tolist()
    [[0.5, 0.0, -3.092], [nan, nan, nan]]
    """
    rt = np.asarray(ref_times, dtype=float)
    rp = np.asarray(ref_poses, dtype=float).reshape(-1, 3)
    t = np.asarray(times, dtype=float)
    out = np.full((t.size, 3), np.nan)
    j = np.clip(np.searchsorted(rt, t), 1, max(rt.size - 1, 1))
    i = j - 1
    if rt.size == 1:
        i = j = np.zeros(t.size, dtype=int)
    gap_i, gap_j = np.abs(t - rt[i]), np.abs(rt[j] - t)
    span = rt[j] - rt[i]
    inside = (t >= rt[i]) & (t <= rt[j]) & (span > 0) & (np.minimum(gap_i, gap_j) <= max_gap)
    u = np.where(span > 0, (t - rt[i]) / np.where(span > 0, span, 1.0), 0.0)
    dth = np.angle(np.exp(1j * (rp[j, 2] - rp[i, 2])))
    interp = np.column_stack([rp[i, :2] + u[:, None] * (rp[j, :2] - rp[i, :2]),
                              np.angle(np.exp(1j * (rp[i, 2] + u * dth)))])
    out[inside] = interp[inside]
    near = np.where(gap_i <= gap_j, i, j)
    exact = ~inside & (np.abs(t - rt[near]) <= max_gap)
    out[exact] = rp[near[exact]]
    if not np.isfinite(out[:, 0]).any():
        raise ValueError(f"{where}: its times ({rt[0]:g} to {rt[-1]:g} s) match none of the log's scans "
                         f"({t[0]:g} to {t[-1]:g} s, within {max_gap:g} s); give a reference of this log, "
                         "in the log's clock")
    return out


@dataclass(frozen=True)
class MapCheck:
    """What :func:`check_map` found: the free area, where it lies, what the thresholds did; ``warnings`` (text).

    ``free_m2`` is the map's free area, ``outside_m2`` the part of it connected
    to the map's edge (a building drawn with walls all round has none: free
    space reaching the edge is the outside, or a map cut off), ``robot_m2``
    the area the robot can be in (``free_m2``, less what a flagged map reads as
    free wrongly), ``free_share`` the free share of the map's cells,
    ``scanned_m2`` the area the scans cover (with a log).
    """

    free_m2: float
    outside_m2: float
    robot_m2: float
    free_share: float
    warnings: tuple[str, ...] = ()
    thresholds: str | None = None
    scanned_m2: float | None = None


def particles_for_area(area_m2: float) -> int:
    """``--particles auto`` for ``area_m2`` of free space: one per 0.5 m x 0.5 m x 10 degree bin, within
    :data:`AUTO_PARTICLES` (as :func:`auto_particles` does for a whole map).

    >>> particles_for_area(204.0), particles_for_area(1.0)
    (29376, 20000)
    """
    lo, hi = AUTO_PARTICLES
    return int(min(max(round(area_m2 / 0.25 * 36), lo), hi))


def _ros_thresholds(path: Path | None) -> tuple[str, float, int] | None:
    """For a map_server map whose free_thresh makes map_saver's unknown grey (205) free: what that did, the
    grey's share of the image, and the number of pixels free under map_server's default free_thresh 0.196."""
    from .io import read_pgm
    from .io.ros import parse_map_yaml

    if path is None or Path(path).suffix.lower() not in (".yaml", ".yml"):
        return None
    try:
        y = parse_map_yaml(path)
        img_name = str(y["image"][0])
        img = read_pgm((Path(path).parent / img_name) if not Path(img_name).is_absolute() else img_name)
    except (ValueError, KeyError, OSError):
        return None
    free_t = float(y.get("free_thresh", (0.196, 0))[0])
    negate = bool(y.get("negate", (0, 0))[0])
    grey = 205
    occ = (img / 255.0) if negate else (255.0 - img) / 255.0
    p = grey / 255 if negate else (255 - grey) / 255
    if p >= free_t or img.ndim != 2:
        return None
    share = float(np.mean(img == grey))
    return (f"free_thresh {free_t:g} makes map_saver's 'unknown' grey ({grey}, occupancy {p:.3f}) free: "
            f"{share:.0%} of the image is that grey", share, int(np.sum(occ < 0.196)))


def scanned_area(log, cell: float = 0.25, max_scans: int = 400, max_range: float | None = None) -> float:
    """The area (m^2) the log's scans cover: the union of the scans' polygons (end points clipped to
    ``max_range``, "no return" beams at it) placed at the log's reference poses, else its odometry, rasterised
    at ``cell`` metres; at most ``max_scans`` evenly spread scans. Odometry drift smears the union, so the
    area is if anything too large.

    Examples
    --------
    >>> from localize.io import LaserLog
    >>> ang = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    >>> log = LaserLog(times=[0.0], odometry=[[0.0, 0.0, 0.0]], ranges=np.full((1, 360), 2.0), angles=ang,
    ...                max_range=10.0)
    >>> a = scanned_area(log, cell=0.05)         # a disc of radius 2 m: 12.57 m^2, plus the boundary cells
    >>> bool(np.pi * 4 < a < np.pi * 2.05 ** 2)
    True
    """
    from PIL import Image, ImageDraw

    poses = np.asarray(log.poses if log.poses is not None else log.odometry, dtype=float)
    mr = float(log.max_range if max_range is None else min(max_range, log.max_range))
    idx = np.unique(np.linspace(0, len(poses) - 1, min(len(poses), max_scans)).astype(int))
    r = np.minimum(np.nan_to_num(np.asarray(log.ranges, dtype=float)[idx], nan=mr, posinf=mr), mr)
    a = np.asarray(log.angles, dtype=float)
    ang = poses[idx, 2:3] + a[None, :]
    xs = poses[idx, 0:1] + r * np.cos(ang)
    ys = poses[idx, 1:2] + r * np.sin(ang)
    x0, y0 = min(xs.min(), poses[idx, 0].min()), min(ys.min(), poses[idx, 1].min())
    w = int(np.ceil((max(xs.max(), poses[idx, 0].max()) - x0) / cell)) + 2
    h = int(np.ceil((max(ys.max(), poses[idx, 1].max()) - y0) / cell)) + 2
    img = Image.new("1", (w, h), 0)
    draw = ImageDraw.Draw(img)
    for k in range(len(idx)):
        px = np.r_[poses[idx[k], 0], xs[k]]
        py = np.r_[poses[idx[k], 1], ys[k]]
        draw.polygon(list(zip(((px - x0) / cell).tolist(), ((py - y0) / cell).tolist())), fill=1)
    return float(np.asarray(img).sum()) * cell * cell


def check_map(grid: OccupancyGrid, map_path: Path | None = None, log=None,
              max_range: float | None = None) -> MapCheck:
    """Check that the map's free space is plausible for a robot's laser; warn (text) when it is not.

    Two signs of a map whose unknown reads as free: for a ROS map, a
    ``free_thresh`` above map_saver's unknown grey 205 (occupancy 0.196) with
    more than 5% of the image that grey (the grey then counts as free); for
    any map, more than half of the cells free *and* more than a quarter of
    the free area connected to the map's edge (the outside of the building:
    a floor drawn with walls all round has none). With a ``log``, a third
    sign, reported but not acted on: free space more than 5 times the area the
    scans cover (:func:`scanned_area`; a log that visits part of a building
    also gives it). ``robot_m2``, the area the
    robot can be in, leaves out what a flagged map reads as free wrongly (the
    grey; the free space reaching the edge); the command line sizes
    ``--particles auto`` from it. (A map cropped inside a building, like the
    Willow Garage map, reaches its edge too, but is not mostly free.)

    Examples
    --------
    >>> from localize.maps import office
    >>> check_map(office()).warnings
    ()
    >>> open_field = OccupancyGrid(np.zeros((100, 100)), 0.1)          # everything free, to the edge
    >>> c = check_map(open_field)
    >>> c.free_share, c.outside_m2, len(c.warnings)
    (1.0, 100.0, 1)
    """
    from scipy import ndimage

    free = np.asarray(grid.free)
    cell = float(grid.resolution) ** 2
    free_m2 = float(free.sum()) * cell
    labels, _ = ndimage.label(free)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    edge = edge[edge > 0]
    outside_m2 = float(np.isin(labels, edge).sum()) * cell if edge.size else 0.0
    share = float(free.mean()) if free.size else 0.0
    warns, robot_m2 = [], free_m2
    ros = _ros_thresholds(map_path)
    if ros is not None and ros[1] > 0.05:
        robot_m2 = min(robot_m2, ros[2] * cell) if ros[2] > 0 else robot_m2
        warns.append(f"{ros[0]}, {share:.0%} of the map's cells read free ({free_m2:.0f} m^2; {ros[2] * cell:.0f} "
                     "m^2 with map_server's default free_thresh 0.196); set free_thresh: 0.196 in the YAML, or "
                     "--not-free-is-occupied")
    if share > 0.5 and outside_m2 > 0.25 * free_m2:
        robot_m2 = min(robot_m2, free_m2 - outside_m2) if free_m2 > outside_m2 else robot_m2
        warns.append(f"{share:.0%} of the map's cells are free and {outside_m2:.0f} m^2 of the {free_m2:.0f} m^2 "
                     "of free space reach the map's edge: the outside of the building reads as free (is the "
                     "unknown read as free?)")
    seen = None
    if log is not None and len(log):
        seen = scanned_area(log, max_range=max_range)
        if free_m2 > 5 * seen:
            warns.append(f"the map has {free_m2:.0f} m^2 of free space, {free_m2 / max(seen, 1e-9):.0f} times the "
                         f"{seen:.0f} m^2 the scans cover: the particles search all of it (a log of part of the "
                         "building; else check the map's thresholds)")
    return MapCheck(free_m2=free_m2, outside_m2=outside_m2, robot_m2=robot_m2, free_share=share,
                    warnings=tuple(warns), thresholds=None if ros is None else ros[0], scanned_m2=seen)


def map_summary(grid: OccupancyGrid) -> str:
    """One line on a map: size, and free, occupied and *unknown* cells counted apart.

    (The grid's repr counts unknown cells among the obstacles, as a range
    sensor sees them; a map summary should not.)

    Examples
    --------
    >>> g = OccupancyGrid(np.array([[0.0, 1.0], [np.nan, 0.0]]), 0.5)
    >>> map_summary(g)
    '2 x 2 cells of 0.5 m (1 x 1 m): 2 free, 1 occupied, 1 unknown'
    """
    rows, cols = grid.shape
    return (f"{cols} x {rows} cells of {grid.resolution:g} m ({grid.width_m:g} x {grid.height_m:g} m): "
            f"{int(grid.free.sum())} free, {int(grid.occupied.sum())} occupied, {int(grid.unknown.sum())} unknown")


# ============================================================================ results
def converged_at(values: ArrayLike, threshold: float = 0.5, hold: int = 20) -> int | None:
    """First scan from which ``values`` stay below ``threshold`` for ``hold`` scans in a row.

    Fewer than ``hold`` scans left at the end of the log count if all of them
    are below. Returns None if that never happens. (A stricter reading, "below
    until the end of the log", is :func:`localize.metrics.convergence_step`.)

    Examples
    --------
    >>> converged_at([3.0, 0.2, 0.9, 0.3, 0.2, 0.1, 0.2, 2.0], threshold=0.5, hold=3)
    3
    >>> converged_at([3.0, 2.0], hold=3) is None
    True
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    hold = check_count(hold, "hold")
    ok = v < float(threshold)
    run = 0
    for k in range(v.size - 1, -1, -1):  # run[k] = consecutive oks starting at k
        run = run + 1 if ok[k] else 0
        ok[k] = run >= hold or (run == v.size - k and run > 0)
    idx = np.flatnonzero(ok)
    return int(idx[0]) if idx.size else None
