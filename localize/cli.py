"""The command line: ``python -m localize run ...`` (also installed as ``localize``).

Global localization with Monte Carlo Localization on a real (or simulated) log::

    localize run --map wean.dat --log robotdata1.log --out out/
    localize run --log intel-corrected.log.gz --build-map --out out/intel
    localize map --log intel-corrected.log.gz --out intel.yaml

``run`` reads a map and a log (formats detected from their content), spreads
particles uniformly over the free space of the map, and filters every scan:
predict with the odometry motion between scans, weight with a range sensor
model, resample. It writes

* ``DIR/trajectory.csv`` — one row per scan: ``time,x,y,theta`` (the robot
  centre in the map frame, metres and radians; the mean of the heaviest
  cluster of particles), then ``spread`` (the particles' position standard
  deviation, metres), ``n_eff`` and ``state`` (``searching``, ``localized``
  or ``lost``, from the filter's own evidence: see
  :class:`localize.mcl.StateRules`); with reference poses in the log also
  ``ref_x,ref_y,ref_theta,error``;
* ``DIR/summary.json`` — particles, scans, seconds per scan, real-time factor,
  the ``state`` section (first localized scan, lost intervals, final state,
  events such as rejected odometry records), errors against the reference
  while localized, and the settings used;
* ``DIR/particles.gif`` (with ``--animate``; ``.mp4`` too when ``ffmpeg`` exists).

``DIR`` always holds one complete run or none (:mod:`localize._output`): the
files are written under temporary names and moved into place together when
the run is complete, ``summary.json`` last (it lists the run's files);
results of an earlier run that this one does not produce are removed; a second
run on a folder being written is refused; ``DIR`` is checked before the
filter starts, and a run that would not fit into memory is refused before it
allocates (:mod:`localize._resources`).

``map`` builds an occupancy grid map from a log with known (corrected) poses
and writes it as a ROS ``map_server`` map (YAML + PGM).

``run`` also reads ROS bags (``--log robot.bag`` or a ROS 2 bag folder, see
:mod:`localize.io.rosbag`) and AMCL parameter files (``--amcl-params``, see
:mod:`localize.amcl`), and writes ``DIR/trajectory.tum`` (and
``DIR/reference.tum`` for logs with reference poses) for ``evo``; for a bag, also
``DIR/localization.bag`` (ROS 1) or ``DIR/localization_bag/`` (ROS 2) with
``/amcl_pose`` and the particle cloud. ``demo`` simulates a log in a built-in
world and localizes it: a first run that needs no download.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import sys
import textwrap
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence, TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from . import __version__
from ._checks import check_count, check_rng
from ._output import RunOutput
from ._resources import check_memory
from .grid import OccupancyGrid
from .motion import ReversibleOdometry  # re-exported: cli.ReversibleOdometry is its old name

if TYPE_CHECKING:
    pass

__all__ = ["main", "build_parser", "RunResult", "localize_log", "make_sensor", "Progress", "ReversibleOdometry",
           "converged_at"]

EXAMPLES = """\
examples:
  # no data at hand: simulate a robot in a built-in office, localize it, animate it
  localize demo --out out/demo

  # your robot: a ROS 1 bag or a ROS 2 bag folder, a map_server map, your AMCL parameters
  localize run --map office.yaml --log robot.bag --amcl-params amcl.yaml --out out/robot
  localize run --map office.yaml --log office_run/ --amcl-params nav2_params.yaml --out out/office
  localize run --map office.yaml --log rosbag2_2024_05_01/ --scan-topic /front/scan --laser-pose 0.2 0 0

  # the CMU 16-831 homework data (Wean Hall): map in P(free), log in cm
  localize run --map wean.dat --log robotdata1.log --out out/wean --animate

  # a CARMEN log with corrected poses: build the map from them, then localize globally
  localize run --log intel-corrected.log.gz --build-map --out out/intel

  # the same in two steps, keeping the map (ROS map_server YAML + PGM)
  localize map --log intel-corrected.log.gz --out intel.yaml
  localize run --map intel.yaml --log intel-corrected.log.gz --sensor beam --animate

  # a ROS map whose walls are painted grey (see `localize.io.ros`)
  localize run --map willow.yaml --not-free-is-occupied --log sim.log
"""


# ============================================================================ defaults
#: The defaults of ``localize run`` (see its --help and chapter 9 for the reasons behind each).
DEFAULTS: dict[str, Any] = {
    "particles": "auto",
    "sensor": "likelihood",
    "beams": 30,
    "max_range": 30.0,
    "alphas": (0.05, 0.01, 0.02, 0.05),
    "sigma_hit": 0.2,
    "z_short": 0.2,
    "temper": 0.3,
    "min_motion": (0.2, 0.3),
    "injection": 0.0,
    "min_range": 0.05,
    "kld": 0.05,
    "min_particles": 2000,
    "augmented": (0.0, 0.0),
    "recovery": 0.0,
    "restart_after": 5,
    "min_ess": 0.0,
    "unknown_penalty": 0.0,
    "expand": (0.0, 0.0),
    "unknown_beams": "skip",
    "short_beams": 1.0,
    "odometry_sign": "auto",
    "occupied_penalty": 5.0,
}


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
    """``n`` particles, or :func:`auto_particles` of ``grid`` for ``"auto"``."""
    if isinstance(n, str):
        if n != "auto":
            raise ValueError(f"n_particles must be a whole number >= 1 or 'auto'; got {n!r}")
        if grid is None:
            raise ValueError("n_particles='auto' sizes the cloud from the map: pass grid=... (or a number)")
        return auto_particles(grid)
    return check_count(n, "n_particles")


# ============================================================================ progress
class Progress(tqdm):
    """tqdm's progress bar over the scans, drawn only when the stream is a terminal.

    :meth:`update_to` takes the number of scans done so far (what
    :func:`localize.mcl.run_filter` passes its ``callback``).

    Examples
    --------
    >>> import io
    >>> buf = io.StringIO()                       # not a terminal: nothing is drawn
    >>> p = Progress(10, stream=buf)
    >>> p.update_to(5); p.close()
    >>> buf.getvalue()
    ''
    >>> p = Progress(10, stream=buf, enabled=True)
    >>> p.update_to(10); p.close()          # redrawn at most every 0.1 s, and when closed
    >>> "10/10 scans" in buf.getvalue()
    True
    """

    def __init__(self, total: int, stream: TextIO | None = None, enabled: bool | None = None,
                 label: str = "scans") -> None:
        stream = sys.stderr if stream is None else stream
        if enabled is None:
            enabled = bool(getattr(stream, "isatty", lambda: False)())
        super().__init__(total=max(int(total), 1), file=stream, disable=not enabled, unit=" " + label,
                         bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt}{unit} [{elapsed}<{remaining}]",
                         dynamic_ncols=True)

    def update_to(self, done: int) -> None:
        """Move the bar to ``done`` scans."""
        self.update(int(done) - self.n)


# ============================================================================ the filter run
def make_sensor(kind: str, grid: OccupancyGrid, max_range: float, sensor_offset: NDArray, **params: Any):
    """Build the range sensor model named ``kind`` ("likelihood" or "beam") for the CLI.

    Defaults (those of the command line) are chosen for real data: maps are
    10-15 cm off (walls drawn thicker than the laser sees them, furniture
    moved), so ``sigma_hit`` is a generous 0.3 m and a random-reading
    component is always present. Keyword
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


@dataclass
class RunResult:
    """What :func:`localize_log` returns: the run driver's record of every scan, with the scans' times.

    ``trace`` is :func:`localize.mcl.run_filter`'s :class:`~localize.mcl.RunTrace` (the one trace type);
    the other attributes are read from it: ``estimates`` (its ``poses``), ``spread`` (the position spread
    of *all* particles, ``hypot(std_x, std_y)``), ``n_eff``, ``updated``, ``seconds``, ``snapshots``,
    ``state`` (``searching``, ``localized`` or ``lost``, see :class:`localize.mcl.StateRules`) and
    ``covariances`` (``(K, 3, 3)``, the particles' variances on the diagonal, for the result bag).
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
    from dataclasses import replace

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


def localize_log(
    grid: OccupancyGrid,
    log,
    n_particles: int | str = DEFAULTS["particles"],
    rng: np.random.Generator | None = None,
    sensor: str = DEFAULTS["sensor"],
    alphas: Sequence[float] = DEFAULTS["alphas"],
    beams: int | None = DEFAULTS["beams"],
    max_range: float | None = DEFAULTS["max_range"],
    init: str = "global",
    init_std: Sequence[float] = (0.1, 0.1, 0.05),
    min_motion: tuple[float, float] = DEFAULTS["min_motion"],
    resample_threshold: float = 0.5,
    injection: float = DEFAULTS["injection"],
    free_space_only: bool = True,
    temper: float = DEFAULTS["temper"],
    snapshot_every: int = 0,
    snapshot_particles: int = 1000,
    progress: Progress | None = None,
    sensor_params: dict | None = None,
    min_range: float = DEFAULTS["min_range"],
    augmented: Any = None,
    kld: Any = "default",
    rules: Any = None,
    unknown_allowed: bool = True,
    unknown_penalty: float = DEFAULTS["unknown_penalty"],
    recovery_injection: float = DEFAULTS["recovery"],
    restart_after: int = DEFAULTS["restart_after"],
    min_ess: float = DEFAULTS["min_ess"],
    odometry_outliers: float = 0.0,
    min_trans: float = 1e-3,
    expand: tuple[float, float] = DEFAULTS["expand"],
    unknown_beams: str = DEFAULTS["unknown_beams"],
    short_beams: float = DEFAULTS["short_beams"],
    z_short: float = DEFAULTS["z_short"],
    odometry_sign: str = DEFAULTS["odometry_sign"],
    occupied_penalty: float = DEFAULTS["occupied_penalty"],
) -> RunResult:
    """Run MCL over a :class:`~localize.io.LaserLog` on ``grid`` and return the per-scan estimates.

    The keyword defaults are those of ``localize run`` (:data:`DEFAULTS`):
    an initial cloud sized to the map (:func:`auto_particles`) shrunk by
    KLD-sampling, ``sigma_hit`` 0.2 m, short readings weighted 0.2
    (``z_short``), tempering 0.3, a 5 cm minimum range,
    particles allowed in unknown cells, restarts on (expansion resetting off),
    beams that end in unknown cells at an agreed place left out (``unknown_beams``),
    and so are those reading more than 1 m shorter than the map there (``short_beams``).

    The filtering loop is :func:`localize.mcl.run_filter`, the one run driver
    (update gating, estimates, the searching / localized / lost state); this
    function only builds the filter from the command line's settings.

    Parameters
    ----------
    grid : OccupancyGrid
        The map.
    log : LaserLog
        Scans and odometry (the controls are consecutive odometry poses).
    n_particles : int or "auto"
        Number of particles (with ``kld``: the initial number); ``"auto"``
        sizes it to the map's free space (:func:`auto_particles`).
    rng : numpy.random.Generator
        The only source of randomness (required).
    sensor : {"likelihood", "beam"}
        Sensor model (see :func:`make_sensor`).
    alphas : four floats
        Odometry noise of PR table 5.6 (variances ``alpha1*rot1**2 + alpha2*trans**2`` ...).
    beams : int or None
        Use this many evenly spread beams of each scan (None: all). Fewer beams are
        faster and, because neighbouring beams' errors are correlated, less
        over-confident (PR section 6.3.4).
    max_range : float or None
        The sensor model's maximum range: readings beyond it are treated as "no
        return" (None: the log's).
    init : {"global", "reference"}
        Uniform particles over the free space (global localization), or a
        Gaussian around the log's first reference pose (pose tracking).
    init_std : three floats
        Standard deviations of the tracking prior.
    min_motion : (metres, radians)
        Weight the particles only after the robot moved at least this far or
        turned this much since the last update (repeating the same scan while
        standing still would make the filter over-confident). (0, 0) updates
        at every scan.
    resample_threshold, injection
        See :class:`~localize.mcl.MCL`.
    free_space_only : bool
        Give zero weight to particles that leave the map's known-free cells
        (a robot cannot stand in a wall or outside the mapped building).
    temper : float
        Multiply each scan's log-likelihood by this factor in (0, 1] (see
        :mod:`localize.sensors`): softens the over-confidence of treating
        neighbouring beams as independent.
    snapshot_every : int
        Keep a subsample of the particle set every so many scans (for animations); 0: never.
    progress : Progress, optional
        Updated after each scan.
    sensor_params : dict, optional
        Extra keyword arguments of the sensor model.
    min_range : float
        Readings at or below this range (metres) are not evidence (likelihood
        field; AMCL's ``laser_min_range``).
    augmented : localize.mcl.Augmented or (alpha_slow, alpha_fast), optional
        Augmented MCL (random particles when the scans suddenly fit worse).
    kld : localize.kld.KLDSampling, "default" or None
        KLD-sampling: the particle count adapts to the spread of the belief.
        ``"default"`` is the command line's (``epsilon`` 0.05, at least 2000
        particles, at most ``n_particles``); None keeps the count fixed.
    rules : localize.mcl.StateRules, optional
        Thresholds of the honest state.
    unknown_allowed : bool
        With ``free_space_only``, let particles stand in unknown cells too.
    unknown_penalty : float
        Log-likelihood subtracted per update from particles in unknown cells
        (see :class:`~localize.mcl.MCL`).
    recovery_injection : float
        Fraction of random particles injected at each resampling while the
        state is ``lost`` (see :func:`localize.mcl.run_filter`).
    restart_after : int
        Global localization again after this many updates agreed on a place
        where the scans do not fit (0: never; see :func:`localize.mcl.run_filter`).
    min_ess : float
        Adaptive tempering: no update leaves fewer than ``min_ess * N``
        effective particles (see :class:`~localize.mcl.MCL`).
    odometry_outliers : float
        Share of particles moved by an odometry outlier at each step (see
        :class:`localize.mcl.RobustOdometry`); 0 uses the plain model.
    min_trans : float
        Odometry steps shorter than this (metres) count as turns on the spot
        (no first rotation towards a direction the odometry noise made up;
        ROS AMCL uses 0.01).
    expand : (metres, radians)
        Expansion resetting when the scans stop fitting an agreed cloud (see
        :func:`localize.mcl.run_filter`); (0, 0) never.
    unknown_beams : {"skip", "score"}
        "skip": once the cloud agrees on one place, beams that end in the
        map's unknown cells there are left out of the update
        (``skip_unknown_beams`` of :func:`localize.mcl.run_filter`); "score":
        every beam is scored.
    short_beams : float
        Metres: once the cloud agrees on one place, beams that read more than
        this much shorter than the map's range from there (something the map
        does not show in front) are left out of the update, unless more than
        half of the scan does (``skip_short_beams`` of
        :func:`localize.mcl.run_filter`); 0 scores them.
    z_short : float
        Likelihood field: weight in [0, 1] of short readings from unmapped
        obstacles (``z_short`` of :class:`localize.sensors.LikelihoodField`:
        no returned beam scores below that of a likely short reading);
        ``sensor_params["z_short"]`` wins over it; 0 scores PR table 6.3 exactly.
        Ignored by the beam model, whose mixture has its own ``z_short``.

    Returns
    -------
    RunResult
    """
    from .mcl import MCL, RobustOdometry, run_filter

    check_rng(rng)
    if unknown_beams not in ("skip", "score"):
        raise ValueError(f"unknown_beams must be 'skip' or 'score'; got {unknown_beams!r}")
    n_particles = resolve_particles(n_particles, grid)
    log, sign_check = check_log_odometry(log, odometry_sign, min_range=min_range)
    if init not in ("global", "reference"):
        raise ValueError(f"init must be 'global' or 'reference'; got {init!r}")
    if beams is not None and beams < log.n_beams:
        log = log.select_beams(count=beams)
    mr = log.max_range if max_range is None else min(float(max_range), log.max_range)
    params = dict(sensor_params or {})
    params.setdefault("sigma_hit", DEFAULTS["sigma_hit"])
    if isinstance(kld, str):
        if kld != "default":
            raise ValueError(f"kld must be a localize.kld.KLDSampling, 'default' or None; got {kld!r}")
        from .kld import KLDSampling

        kld = KLDSampling(epsilon=DEFAULTS["kld"], n_min=min(DEFAULTS["min_particles"], int(n_particles)),
                          n_max=int(n_particles), chunked=True)
    if sensor == "likelihood":
        if min_range:
            params.setdefault("min_range", float(min_range))
        params.setdefault("z_short", z_short)
    model = make_sensor(sensor, grid, mr, log.sensor_offset, temper=temper, **params)
    ranges = np.minimum(log.ranges, mr)
    motion: Any = ReversibleOdometry(alphas, min_trans=min_trans)
    if odometry_outliers:
        motion = RobustOdometry(motion, outlier=odometry_outliers)
    opts: dict[str, Any] = dict(resample_threshold=resample_threshold, injection=injection,
                                free_space_only=free_space_only, augmented=augmented, kld=kld,
                                unknown_allowed=unknown_allowed, unknown_penalty=unknown_penalty, min_ess=min_ess,
                                occupied_penalty=occupied_penalty)
    if init == "global":
        f = MCL.uniform(grid, n_particles, motion, model, rng=rng, **opts)
    else:
        if log.poses is None:
            raise ValueError("init='reference' needs reference poses in the log (log.poses is None)")
        f = MCL.gaussian(log.poses[0], tuple(init_std), n_particles, motion, model, rng=rng, grid=grid, **opts)
    k_scans = len(log)
    snap_steps: Sequence[int] = ()
    if snapshot_every:
        snap_steps = sorted(set(range(0, k_scans, snapshot_every)) | {k_scans - 1})
    odo = log.odometry
    angles = log.angles
    tr = run_filter(f, k_scans, lambda k: (odo[k - 1], odo[k]), lambda k: (ranges[k], angles), grid=grid,
                    min_motion=tuple(min_motion), rules=rules, snapshot_steps=snap_steps,
                    snapshot_particles=snapshot_particles, odometry=odo, recovery_injection=recovery_injection,
                    restart_after=restart_after, expand=tuple(expand), skip_unknown_beams=unknown_beams == "skip",
                    skip_short_beams=short_beams,
                    callback=None if progress is None else progress.update_to)
    return RunResult(times=np.asarray(log.times), trace=tr, odometry_check=sign_check)


# ============================================================================ outputs
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


def write_trajectory(path: Path, res: RunResult, reference: NDArray | None = None) -> Path:
    """Write ``trajectory.csv``: ``time,x,y,theta,spread,n_eff,state`` (+ reference and error)."""
    cols = ["time", "x", "y", "theta", "spread", "n_eff", "state"]
    state = res.state if res.state is not None else np.full(len(res.times), "")
    if reference is not None:
        cols += ["ref_x", "ref_y", "ref_theta", "error"]
        err = np.hypot(*(res.estimates[:, :2] - reference[:, :2]).T)
    extra = getattr(res, "columns", None) or {}  # more per-scan columns (localize.smooth: passes, source)
    cols += list(extra)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for k in range(len(res.times)):
            row = [f"{res.times[k]:.6f}", *(f"{v:.6f}" for v in res.estimates[k]), f"{res.spread[k]:.4f}",
                   f"{res.n_eff[k]:.1f}", str(state[k])]
            if reference is not None:
                row += [*(f"{v:.6f}" for v in reference[k]), f"{err[k]:.4f}"]
            w.writerow(row + [str(v[k]) for v in extra.values()])
    return path


def summarize(res: RunResult, log, n_particles: int, reference: NDArray | None, settings: dict,
              threshold: float = 0.5, hold: int = 20) -> dict:
    """The numbers of ``summary.json``."""
    dt = float(log.times[-1] - log.times[0])
    distinct = np.unique(log.times).size / len(log.times)
    backwards = float(np.mean(np.diff(log.times) < 0)) if len(log.times) > 1 else 0.0
    reliable = bool(dt > 0 and backwards < 0.01 and distinct > 0.5)
    out: dict[str, Any] = {
        "particles": int(n_particles),
        "scans": int(len(res.times)),
        "scans_with_update": int(res.updated.sum()),
        "seconds": round(res.seconds, 3),
        "seconds_per_scan": round(res.seconds_per_scan, 6),
        "log_duration_s": round(dt, 3) if reliable else None,
        "real_time_factor": round(dt / res.seconds, 3) if reliable and res.seconds > 0 else None,
        "convergence_threshold_m": threshold,
        "convergence_step": converged_at(res.spread, threshold, hold),
        "convergence_criterion": (f"first scan from which the particles' position spread (or, for *_reference, "
                                  f"the error) stays below the threshold for {hold} scans"),
        "final_estimate": [round(float(v), 4) for v in res.estimates[-1]],
    }
    if not reliable:
        out["real_time_factor_note"] = "the log's time stamps are not usable (too coarse or out of order)"
    if res.trace is not None:
        out["state"] = res.trace.state_summary()
        out["state"]["meaning"] = ("searching: no single, well-fitting hypothesis yet; localized: one cluster holds "
                                   "most of the weight, is tight, and the scans fit the map there; lost: it was "
                                   "localized and no longer is (see localize.mcl.StateRules)")
    chk = getattr(res, "odometry_check", None)
    if chk is not None:
        out["odometry_sign"] = {**chk.summary(), "meaning": (
            "odometry steps (step k: from scan k to scan k+1 of the scans used) driven backwards because the two "
            "scans fit the reversed step clearly better; checked because the odometry never reports reversing "
            "or --odometry-sign check (see localize.scanmatch.check_odometry_sign)")}
    if reference is not None:
        err = np.hypot(*(res.estimates[:, :2] - reference[:, :2]).T)
        cs = converged_at(err, threshold, hold)
        out["convergence_step_reference"] = cs
        out["median_error_m"] = round(float(np.median(err)), 4)
        out["median_error_after_convergence_m"] = (
            round(float(np.median(err[cs:])), 4) if cs is not None else None)
        out["final_error_m"] = round(float(err[-1]), 4)
        if res.state is not None:
            loc = res.state == "localized"
            out["median_error_while_localized_m"] = round(float(np.median(err[loc])), 4) if loc.any() else None
            out["p90_error_while_localized_m"] = (round(float(np.percentile(err[loc], 90)), 4)
                                                  if loc.any() else None)
            out["localized_scans_over_1m_off"] = int(np.sum(loc & (err > 1.0)))
    out["settings"] = settings
    return out


def write_summary(path: Path, summary: dict) -> Path:
    """Write ``summary.json`` (indented JSON, one trailing newline)."""
    with open(path, "w") as fh:
        json.dump(summary, fh, indent=2)
        fh.write("\n")
    return path


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


def headline(summary: dict) -> str:
    """The terminal's one-line account of the state: "localized from scan K; lost at ...; final state ...".

    Examples
    --------
    >>> headline({"state": {"first_localized_scan": 12, "lost_intervals": [[40, 45]], "final_state": "localized",
    ...                     "scans_without_valid_readings": 0, "events": []}})
    'localized from scan 12; lost at scans 40-45; final state: localized'
    >>> headline({"state": {"first_localized_scan": None, "lost_intervals": [], "final_state": "searching",
    ...                     "scans_without_valid_readings": 90, "events": []}, "scans": 90})
    'NOT localized: still searching at the end; 90 of 90 scans had no valid reading'
    """
    st = summary.get("state")
    if not st:
        return f"converged (particle spread < 0.5 m) at scan {summary.get('convergence_step')}"
    k = st["first_localized_scan"]
    parts = [f"localized from scan {k}" if k is not None else "NOT localized: still searching at the end"]
    if st["lost_intervals"]:
        parts.append("lost at scans " + ", ".join(f"{a}-{b}" for a, b in st["lost_intervals"]))
    if k is not None:
        parts.append(f"final state: {st['final_state']}")
    if st.get("scans_without_valid_readings"):
        parts.append(f"{st['scans_without_valid_readings']} of {summary.get('scans', '?')} scans had no valid reading")
    rejected = sum("odometry" in t for _, t in st.get("events", []))
    if rejected:
        parts.append(f"{rejected} impossible odometry step(s) rejected")
    return "; ".join(parts)


def write_animation(out_dir: Path, grid: OccupancyGrid, res: RunResult, reference: NDArray | None,
                    fps: int = 8, n_particles: int | None = None) -> list[Path]:
    """Save the particle snapshots as ``particles.gif`` (Pillow) and ``particles.mp4`` (if ffmpeg exists).

    The command line passes the staging folder of its :class:`~localize._output.RunOutput`,
    so that an interrupted animation never reaches ``--out``.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.animation import FFMpegWriter, PillowWriter

    from .plot.mcl import animate_snapshots

    aspect = grid.height_m / grid.width_m
    anim = animate_snapshots(grid, res.snapshots, true_poses=reference, estimates=res.estimates,
                             figsize=(6.0, max(3.0, min(8.0, 6.0 * aspect))), size=2.0, n_particles=n_particles)
    written = []
    try:
        gif = out_dir / "particles.gif"
        _save_animation(anim, gif, PillowWriter(fps=fps), dpi=80)
        written.append(gif)
        if shutil.which("ffmpeg"):
            mp4 = out_dir / "particles.mp4"
            _save_animation(anim, mp4, FFMpegWriter(fps=fps), dpi=100)
            written.append(mp4)
    finally:
        plt.close("all")
    return written


def _save_animation(anim, path: Path, writer, dpi: int) -> None:
    """``anim.save`` with Ctrl-C kept a KeyboardInterrupt and other failures an ``OSError`` naming the file.

    (Interrupted before its first frame, matplotlib's writers end in an
    ``IndexError`` raised while cleaning up, which would hide the interrupt.)
    """
    try:
        anim.save(path, writer=writer, dpi=dpi)
    except KeyboardInterrupt:
        raise
    except Exception as exc:
        ctx = exc.__context__
        while ctx is not None:
            if isinstance(ctx, KeyboardInterrupt):
                raise KeyboardInterrupt from None
            ctx = ctx.__context__
        raise OSError(f"{path.name}: could not write the animation ({type(exc).__name__}: {exc})") from exc


# ============================================================================ argument parsing
def _number_type(cast: type, expect: str, ok: Any, name: str) -> Any:
    """An argparse ``type``: the option's text as ``cast`` (int or float), finite and with ``ok(value)`` true.

    Its error says what was expected (``expect``), which argparse prefixes with the option's name.
    """

    def parse(s: str):
        try:
            v = cast(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expect}; got {s!r}") from None
        if not (np.isfinite(v) and ok(v)):
            raise argparse.ArgumentTypeError(f"expected {expect}; got {s}")
        return v

    parse.__name__ = name
    return parse


_positive_int = _number_type(int, "a whole number >= 1", lambda v: v >= 1, "positive_int")


def _particles(s: str) -> int | str:
    """``--particles``: a whole number >= 1, or ``auto``."""
    if s.strip().lower() == "auto":
        return "auto"
    try:
        return _positive_int(s)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1 or 'auto'; got {s}") from None
_positive_float = _number_type(float, "a positive number", lambda v: v > 0, "positive_float")
_nonneg_float = _number_type(float, "a number >= 0", lambda v: v >= 0, "nonneg_float")
_seed = _number_type(int, "a whole number >= 0 (a random generator's seed)", lambda v: v >= 0, "seed")
_nonneg_int = _number_type(int, "a whole number >= 0", lambda v: v >= 0, "nonneg_int")
_unit_fraction = _number_type(float, "a number in (0, 1]", lambda v: 0 < v <= 1, "unit_fraction")
_fraction = _number_type(float, "a fraction in [0, 1)", lambda v: 0 <= v < 1, "fraction")
_weight = _number_type(float, "a weight in [0, 1]", lambda v: 0 <= v <= 1, "weight")


def _penalty(s: str) -> float:
    """``--occupied-penalty``: a positive number of nats, or ``inf``."""
    if s.strip().lower() in ("inf", "infinity"):
        return float("inf")
    try:
        return _positive_float(s)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected a positive number of nats or 'inf'; got {s}") from None


def _shown(value: Any) -> str:
    """A default as ``--help`` shows it: numbers by ``:g``, the values of a tuple separated by spaces."""
    if isinstance(value, (tuple, list)):
        return " ".join(_shown(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class FilterOption:
    """One filter option of ``localize run``: its flag, how its text is read, and its help.

    The default is ``DEFAULTS[dest]`` (``dest`` is the flag as argparse names it, ``--max-range`` ->
    ``max_range``); ``{default}`` in ``help`` is replaced by it as ``--help`` shows it.
    """

    flag: str
    type: Any = None
    nargs: int | None = None
    metavar: str | tuple[str, ...] | None = None
    help: str = ""
    choices: tuple[str, ...] | None = None

    @property
    def dest(self) -> str:
        return self.flag.lstrip("-").replace("-", "_")

    @property
    def default(self) -> Any:
        return DEFAULTS[self.dest]

    def add_to(self, parser: Any) -> None:
        """Add the option to ``parser`` (an argparse parser or argument group)."""
        kw = {k: v for k, v in (("type", self.type), ("nargs", self.nargs), ("metavar", self.metavar),
                                ("choices", self.choices)) if v is not None}
        text = " ".join(self.help.split()).format(default=_shown(self.default))
        parser.add_argument(self.flag, default=self.default, help=text, **kw)


#: The filter options of ``localize run`` whose defaults are :data:`DEFAULTS` (the parser is built from
#: this table, and ``summary.json``'s settings list them).
FILTER_OPTIONS: tuple[FilterOption, ...] = (
    FilterOption("--particles", _particles, metavar="N", help="""
        number of particles at the start, or 'auto' (default {default}): one per 0.5 m x 0.5 m x 10 degree
        cell of the pose space over the map's free space (KLD-sampling's cells), between 20,000 and 300,000
        -- about 75,000 for 520 m^2 of free floor, 115,000 for 800 m^2. With --kld (on by default) this is
        the initial and largest number: a dense uniform cloud, because with fewer particles most cells of
        the pose space are empty, and the filter then needs luck to have a particle near the robot.
        KLD-sampling shrinks the cloud to a few thousand once the filter agrees. Example: --particles
        100000"""),
    FilterOption("--sensor", choices=("likelihood", "beam"), help="""
        sensor model: 'likelihood' field (fast, robust to small map errors) or the 'beam' model with ray
        casting (default {default}). Example: --sensor beam"""),
    FilterOption("--beams", _positive_int, metavar="B", help="""
        use B evenly spread beams of each scan (default {default}). Example: --beams 180"""),
    FilterOption("--max-range", _positive_float, metavar="M", help="""
        sensor model's maximum range in metres; longer readings count as 'no return' (default {default}).
        Example: --max-range 20"""),
    FilterOption("--alphas", _nonneg_float, 4, ("A1", "A2", "A3", "A4"), help="""
        odometry noise alpha1..alpha4 of Probabilistic Robotics table 5.6, as variances (default {default}).
        A step driven backwards is moved as a forward step of a robot facing the other way, and a step whose
        translation lies within the translation noise of a turn on the spot, sqrt(A3*t^2 + A4*turn^2), gets
        the noise of a turn on the spot (an odometry point off the robot's axis creeps sideways while it
        turns; taken as a drive, that step would turn almost 90 degrees and scatter the particles by half a
        metre). Example: --alphas 0.1 0.02 0.05 0.1"""),
    FilterOption("--sigma-hit", _positive_float, metavar="M", help="""
        standard deviation of a beam's end point about the nearest wall (likelihood field) or of a reading
        about the ray-cast range (beam model), metres (default {default}): the map's error sets it, not the
        laser's (a few cm) -- real maps draw walls 0.1-0.15 m off and furniture moves.
        Example: --sigma-hit 0.3"""),
    FilterOption("--z-short", _weight, metavar="W", help="""
        likelihood field: weight in [0, 1] of short readings, beams stopped by something the map does not
        show (people, chairs, a door shut since the map was made) (default {default}). No returned beam then
        scores below W*lambda*exp(-lambda*z) + z_rand/max_range (lambda 0.5 per metre), so a short reading
        that ends in the map's free space counts as a likely unmapped obstacle, not as a miss that rules the
        true pose out. 0 scores the end points as Probabilistic Robotics table 6.3 does. Example:
        --z-short 0"""),
    FilterOption("--temper", _unit_fraction, metavar="T", help="""
        multiply each scan's log-likelihood by T in (0, 1] (default {default}): neighbouring beams see the
        same wall, so 30 beams are not 30 independent measurements, and an over-confident filter locks onto
        a wrong place. Example: --temper 0.1"""),
    FilterOption("--min-motion", _nonneg_float, 2, ("M", "RAD"), help="""
        weight the particles only after moving M metres or turning RAD radians since the last update, like
        ROS AMCL (default {default}; 0 0 updates at every scan). Example: --min-motion 0 0"""),
    FilterOption("--injection", _fraction, metavar="F", help="""
        fraction in [0, 1) of random particles injected at each resampling (default {default}). Example:
        --injection 0.01"""),
    FilterOption("--min-range", _nonneg_float, metavar="M", help="""
        readings at or below M metres are not evidence, like ROS AMCL's laser_min_range: lasers report 0 (or
        a few millimetres) for a failed reading, and nothing closer than the robot's own body is real
        (default {default}; likelihood field). Example: --min-range 0.1"""),
    FilterOption("--kld", _nonneg_float, metavar="EPS", help="""
        KLD-sampling (Fox 2003): after each resampling keep only as many particles as a belief of this
        spread needs, with KL-divergence bound EPS; --particles is then the initial (and largest) number, so
        global localization starts with a dense cloud that shrinks once the filter agrees (default
        {default}; 0 keeps the number fixed). Example: --kld 0.1"""),
    FilterOption("--min-particles", _positive_int, metavar="N", help="""
        with --kld, never fewer than N particles (default {default}). Example: --min-particles 2000"""),
    FilterOption("--augmented", _nonneg_float, 2, ("SLOW", "FAST"), help="""
        augmented MCL (Probabilistic Robotics table 8.3): inject random particles when the short-term
        average scan likelihood (rate FAST) drops below the long-term one (rate SLOW); 0 0 switches it off
        (default {default}). Example: --augmented 0.01 0.2"""),
    FilterOption("--recovery", _nonneg_float, metavar="F", help="""
        while the state is 'lost', replace the fraction F of the particles by random ones at each
        resampling, so that the filter searches again (default {default}). Example: --recovery 0"""),
    FilterOption("--restart-after", _nonneg_int, metavar="K", help="""
        start global localization again (all --particles drawn over the map beside the cloud, each half of the
        weight) when the cloud has agreed on one place but the scans have not fitted the map there for K
        updates in a row: it is confidently wrong. Before the filter is first localized, a cloud gathered
        more loosely (within 2 m) counts too, and so do updates at which the map cannot judge the scans at all
        (their beams end in its unknown cells): a cloud stuck on such a place would otherwise search there
        for ever. A "lost" filter whose best place has not fitted the scans for K updates restarts too. The
        old cloud and the new search then run side by side for up to 30 updates; the new one replaces the old
        place only if it wins both the sensor model's weight and the ray-cast fit of the scans, and fits them
        acceptably (default {default}; 0 never). Example: --restart-after 5"""),
    FilterOption("--min-ess", _nonneg_float, metavar="F", help="""
        adaptive tempering: no single scan may leave fewer than F*N effective particles, so the first scans
        cannot collapse the cloud onto a look-alike place (default {default}; 0 off). Example: --min-ess 0.1"""),
    FilterOption("--expand", _nonneg_float, 2, ("M", "RAD"), help="""
        expansion resetting: when the cloud agrees on a place but the scan just used does not fit the map
        there, spread every particle by Gaussian noise of M metres and RAD radians, so that the next scans can
        find a robot that the odometry lost (wheel slip, a bump) (default {default}; 0 0 never). Example:
        --expand 0.2 0.1"""),
    FilterOption("--unknown-beams", choices=("skip", "score"), help="""
        'skip': once the cloud agrees on one place, the beams whose end point there lies in a cell the map
        leaves unknown are left out of the update, and a scan with no other beam is not used; 'score': every
        beam is scored, an end point in an unknown cell with one neutral score (default {default}). The map
        cannot say whether such a beam fits, and scored it pulls the cloud of a robot that drives through a
        region the map left unknown towards that region's known walls. Example: --unknown-beams score"""),
    FilterOption("--short-beams", _nonneg_float, metavar="M", help="""
        once the cloud agrees on one place, a beam that reads more than M metres shorter than the map's range
        from there is left out of the update: it hit something the map does not show (a person, a chair, a box
        in front of the mapped wall), and scored it lets a few particles at a wrong place, where its end point
        lies on some mapped wall, take the weight from the robot's cloud. If more than half of a scan reads
        short, every beam is scored: the place is then more likely wrong than cluttered (default {default}: twice
        the 0.5 m within which the cloud counts as agreed, more than its own error explains; 0 scores every
        beam). Example: --short-beams 0"""),
    FilterOption("--occupied-penalty", _penalty, metavar="NATS", help="""
        a particle standing in one of the map's obstacles loses NATS of log-likelihood at each update (default
        {default}: a pose in a wall is e^-5, about 150 times, less likely than one in free space with the same
        scan fit); 'inf' gives it zero weight. Finite, a robot that drives through an obstacle the map is wrong
        about (a door drawn shut, furniture since moved, walls drawn too thick) keeps its cloud: every particle
        in it pays the same, and the scans decide. Outside the map a particle has zero weight either way.
        Example: --occupied-penalty inf"""),
    FilterOption("--odometry-sign", choices=ODOMETRY_SIGN, help="""
        'check': compare every odometry step of at least 5 cm with the two scans around it, and drive
        backwards the steps whose reverse fits the scans clearly better (the second scan's end points, placed
        with the step reversed, lie within 70 percent of the distance they lie at with the step as logged); 'auto'
        (default {default}): check only odometry that never reports reversing, a speed without a sign that
        records every backing-up as driving forwards (the Freiburg 079 log's does); 'trust': never.
        summary.json lists the steps reversed. Example: --odometry-sign trust"""),
)


def _wrap(text: str, width: int = 79) -> str:
    """Wrap a help paragraph (the parsers use RawDescriptionHelpFormatter to keep the examples' layout)."""
    return textwrap.fill(" ".join(text.split()), width=width)


def _scan_slice(s: str) -> slice:
    parts = s.split(":")
    if len(parts) > 3:
        raise argparse.ArgumentTypeError(f"expected START:STOP[:STEP]; got {s!r}")
    try:
        vals = [int(p) if p else None for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected whole numbers in START:STOP[:STEP]; got {s!r}") from None
    if len(vals) == 3 and vals[2] is not None and vals[2] < 1:
        raise argparse.ArgumentTypeError(f"STEP must be >= 1; got {vals[2]}")
    return slice(*vals)


def _add_resolution(parser: Any, what: str) -> None:
    """``--resolution``: the cell size of the map that ``run --build-map`` and ``map`` build from a log."""
    parser.add_argument("--resolution", type=_positive_float, default=0.05, metavar="M",
                        help=f"cell size of {what}, metres (default 0.05). Example: --resolution 0.1")


def _add_frames_and_quiet(parser: Any, frames: int) -> None:
    """``--frames`` and ``--quiet``: the options of ``run`` that ``demo`` passes on to it."""
    parser.add_argument("--frames", type=_positive_int, default=frames, metavar="K",
                        help=f"number of animation frames (default {frames}). Example: --frames {2 * frames}")
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no summary on the terminal.")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``localize`` (``run`` and ``map`` sub-commands)."""
    ap = argparse.ArgumentParser(
        prog="localize",
        description="Monte Carlo Localization on robot logs (CMU 16-831, CARMEN) and maps (CMU, ROS map_server).",
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"localize {__version__}",
                    help="print the version and exit.")
    sub = ap.add_subparsers(dest="command", metavar="{run,map,demo}")
    sub.required = True

    run = sub.add_parser(
        "run", help="global localization with MCL on a log",
        description=_wrap("Global localization with Monte Carlo Localization: particles start uniform over the "
                          "map's free space and are moved by the log's odometry and weighted by its laser scans. "
                          "Writes DIR/trajectory.csv (time,x,y,theta per scan, map frame, metres and radians, and the "
                          "filter's state: searching, localized or lost), "
                          "DIR/summary.json, DIR/trajectory.tum (for evo) and, with --animate, DIR/particles.gif; "
                          "for a ROS bag also DIR/localization.bag (ROS 1) or DIR/localization_bag/ (ROS 2) with "
                          "/amcl_pose and the particle cloud. The results appear together "
                          "when the run is complete (an interrupted run leaves DIR as it was), results of an "
                          "earlier run that this one does not produce are removed, and two runs cannot write "
                          "one DIR at the same time."),
        epilog=EXAMPLES + "\nAMCL parameters (--amcl-params FILE.yaml), ROS 1 amcl or nav2 nav2_amcl:\n" + _amcl_table(),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    g = run.add_argument_group("input")
    g.add_argument("--map", type=Path, metavar="FILE",
                   help="the map: a CMU 16-831 map (wean.dat) or a ROS map_server YAML. "
                        "Example: --map wean.dat")
    g.add_argument("--log", type=Path, metavar="FILE", required=True,
                   help="the log: CMU 16-831 (O/L records, cm), CARMEN (FLASER/ODOM ..., may be gzipped), a ROS 1 "
                        "bag or a ROS 2 bag folder (sqlite3 or MCAP; needs pip install \"localize[ros]\"). "
                        "Example: --log robotdata1.log or --log robot.bag")
    g.add_argument("--map-format", choices=["cmu", "ros"], default=None,
                   help="override the map format detected from the file's content. Example: --map-format ros")
    g.add_argument("--log-format", choices=["cmu", "carmen", "rosbag"], default=None,
                   help="override the log format detected from the file's content. Example: --log-format carmen")
    g.add_argument("--scan-topic", metavar="TOPIC", default=None,
                   help="ROS bags: the sensor_msgs/LaserScan topic (needed when the bag has several). "
                        "Example: --scan-topic /front/scan")
    g.add_argument("--odom-topic", metavar="TOPIC", default=None,
                   help="ROS bags: the nav_msgs/Odometry topic (default: the bag's one, else the odom -> base "
                        "transform on /tf; --odom-topic /tf forces the latter). Example: --odom-topic /wheel/odom")
    g.add_argument("--laser-pose", type=float, nargs=3, default=None, metavar=("X", "Y", "YAW"),
                   help="the laser's mounting pose in the robot frame, metres and radians; overrides the log's "
                        "(a bag's /tf_static, CMU's 25 cm ahead). Needed for a bag without /tf_static. "
                        "Example: --laser-pose 0.2 0 0")
    g.add_argument("--amcl-params", type=Path, default=None, metavar="FILE.yaml",
                   help="take the filter settings from a ROS 1 amcl or nav2 AMCL parameter file (the mapping is "
                        "printed; options given on the command line win). Example: --amcl-params nav2_params.yaml")
    g.add_argument("--build-map", action="store_true",
                   help="instead of --map, build the map from the log's reference (corrected) poses, as CARMEN "
                        "corrected logs carry them. Example: --build-map --resolution 0.05")
    _add_resolution(g, "a map built with --build-map")
    g.add_argument("--not-free-is-occupied", action="store_true",
                   help="ROS maps: treat every cell that is not free as an obstacle (maps with grey walls).")
    g.add_argument("--scans", type=_scan_slice, default=None, metavar="START:STOP[:STEP]",
                   help="use only these scans of the log (Python slice). Example: --scans 0:500 or --scans ::2")
    f = run.add_argument_group("filter")
    f.add_argument("--seed", type=_seed, default=0, metavar="S",
                   help="seed of the random generator, a whole number >= 0: the same seed gives the same run "
                        "(default 0). "
                        "Example: --seed 7")
    for opt in FILTER_OPTIONS:  # the options whose defaults are DEFAULTS
        opt.add_to(f)
    f.add_argument("--smooth", action="store_true",
                   help="offline: filter the recorded log forwards and again backwards in time (the same settings, "
                        "the log reversed), and combine the two passes scan by scan. The backward pass localizes "
                        "the start that the forward pass spent searching; where both are localized but disagree "
                        "(a look-alike corridor), the pass whose estimates fit the scans better wins, and a tie "
                        "is reported as not localized. trajectory.csv gets the columns passes (both, disagree, "
                        "forward, backward, none: which passes are localized at the scan and whether they agree) "
                        "and source; summary.json a 'smooth' section. Takes twice as long (see localize.smooth). "
                        "Example: --smooth")
    f.add_argument("--track", action="store_true",
                   help="pose tracking instead of global localization: start around the log's first reference "
                        "pose (needs a corrected log).")
    o = run.add_argument_group("output")
    o.add_argument("--out", type=Path, default=Path("localize-out"), metavar="DIR",
                   help="output folder, created if needed and checked before the run starts; it holds one "
                        "complete run's results or none (default ./localize-out). Example: --out out/wean")
    o.add_argument("--animate", action="store_true",
                   help="also write DIR/particles.gif (and particles.mp4 when ffmpeg is installed).")
    _add_frames_and_quiet(o, frames=100)

    mp = sub.add_parser(
        "map", help="build an occupancy grid map from a log with known poses",
        description=_wrap("Occupancy grid mapping with known poses (log-odds, inverse sensor model): builds a "
                          "map from a log's reference (corrected) poses and writes it as a ROS map_server map "
                          "(YAML + PGM)."),
        epilog="example:\n  localize map --log intel-corrected.log.gz --out intel.yaml --resolution 0.05",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    mp.add_argument("--log", type=Path, required=True, metavar="FILE",
                    help="a log with reference poses (e.g. a corrected CARMEN log). Example: --log intel.log.gz")
    mp.add_argument("--log-format", choices=["cmu", "carmen"], default=None,
                    help="override the log format detected from the content. Example: --log-format carmen")
    mp.add_argument("--out", type=Path, required=True, metavar="FILE.yaml",
                    help="the map's YAML; the PGM is written beside it. Example: --out maps/intel.yaml")
    _add_resolution(mp, "the map")
    mp.add_argument("--every", type=_positive_int, default=1, metavar="K",
                    help="use every K-th scan (default 1). Example: --every 4")
    mp.add_argument("--quiet", action="store_true", help="print nothing.")

    dm = sub.add_parser(
        "demo", help="simulate a robot in a built-in world and localize it (no download needed)",
        description="A first run without data: simulates a robot driving through a built-in office (laser with "
                    "realistic noise, unmapped clutter, an imperfect map: walls off by a few centimetres, a moved "
                    "cupboard), writes the log and map as CMU 16-831 files (DIR/robot.log, DIR/map.dat) and the "
                    "true poses (DIR/truth.tum), then runs `localize run` on them with an animation. "
                    "Rerun or vary it with the printed command.",
        epilog="example:\n  localize demo --out out/demo\n  evo_ape tum out/demo/truth.tum out/demo/trajectory.tum",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    dm.add_argument("--out", type=Path, default=Path("localize-demo"), metavar="DIR",
                    help="output folder (default ./localize-demo). Example: --out out/demo")
    dm.add_argument("--seed", type=_seed, default=0, metavar="S",
                    help="seed of the simulation and of the filter (default 0). Example: --seed 3")
    dm.add_argument("--steps", type=_positive_int, default=150, metavar="K",
                    help="number of scans to simulate (default 150). Example: --steps 300")
    dm.add_argument("--particles", type=_particles, default="auto", metavar="N",
                    help="number of particles, or 'auto' (default, as for localize run: one per pose cell of the "
                         "office's free space, about 30,000). "
                         "Example: --particles 10000")
    dm.add_argument("--no-animate", action="store_true", help="skip the animation (faster).")
    _add_frames_and_quiet(dm, frames=60)  # passed on to `localize run`
    run.set_defaults(_option_dests={s: a.dest for a in run._actions for s in a.option_strings})
    return ap


# ============================================================================ main
def run_kwargs(args: argparse.Namespace, grid: OccupancyGrid | None = None) -> dict:
    """The keyword arguments of :func:`localize_log` that the ``run`` options stand for.

    The benchmarks call this with the parser's defaults, so that they measure
    exactly what ``localize run`` does. ``--particles auto`` (the default)
    needs the map, ``grid``, to size the initial cloud (:func:`auto_particles`).

    Examples
    --------
    >>> from localize.maps import office
    >>> args = build_parser().parse_args(["run", "--log", "x.log", "--map", "m.yaml"])
    >>> args.particles
    'auto'
    >>> run_kwargs(args, grid=office())["n_particles"] == auto_particles(office())
    True
    """
    from .kld import KLDSampling
    from .mcl import Augmented

    n_particles = resolve_particles(args.particles, grid)
    kld = None
    if args.kld > 0:
        kld = KLDSampling(epsilon=args.kld, n_min=min(args.min_particles, n_particles), n_max=n_particles,
                          chunked=True)
    slow, fast = args.augmented
    aug = None
    if slow > 0 or fast > 0:
        try:
            aug = Augmented(alpha_slow=slow, alpha_fast=fast, temperature=float(args.beams))
        except ValueError as e:
            raise ValueError(f"--augmented {slow:g} {fast:g}: {e}") from None
    if not args.recovery < 1:
        raise ValueError(f"--recovery must be a fraction below 1; got {args.recovery:g}")
    return dict(
        n_particles=n_particles, sensor=args.sensor, alphas=tuple(args.alphas), beams=args.beams,
        max_range=args.max_range, init="reference" if args.track else "global", min_motion=tuple(args.min_motion),
        injection=args.injection, temper=args.temper, sensor_params={"sigma_hit": args.sigma_hit},
        min_range=args.min_range, kld=kld, augmented=aug, recovery_injection=args.recovery,
        restart_after=max(int(args.restart_after), 0), min_ess=args.min_ess,
        unknown_allowed=True, unknown_penalty=DEFAULTS["unknown_penalty"], expand=tuple(args.expand),
        unknown_beams=args.unknown_beams, short_beams=args.short_beams, z_short=args.z_short, occupied_penalty=args.occupied_penalty,
        odometry_sign=args.odometry_sign,
    )


def _amcl_table() -> str:
    from .amcl import MAPPING_TABLE

    return "\n".join("  " + line for line in MAPPING_TABLE.splitlines())


def _given_options(args, argv: Sequence[str]) -> set[str]:
    """Destinations of the options written on the command line (unique prefixes count, as in argparse)."""
    opts: dict[str, str] = getattr(args, "_option_dests", {})
    given = set()
    for tok in argv:
        if tok == "--":
            break
        if not tok.startswith("--"):
            continue
        name = tok.split("=", 1)[0]
        if name in opts:
            given.add(opts[name])
            continue
        hits = {d for o, d in opts.items() if o.startswith(name)}
        if len(hits) == 1:
            given |= hits
    return given


# ============================================================================ main
def _read_relaying_warnings(err: TextIO, read, *args, **kwargs):
    """``read(*args, **kwargs)``; the warnings it gives (a reader's skipped records ...) are printed to ``err``
    as ``localize: warning: ...`` lines (no Python warning noise)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = read(*args, **kwargs)
    for w in caught:
        print(f"localize: warning: {w.message}", file=err)
    return out


def _load(args, err: TextIO):
    from dataclasses import replace

    from . import io as lio
    from .io import rosbag

    pose = getattr(args, "laser_pose", None)
    if args.log_format == "rosbag" or (args.log_format is None and rosbag.is_rosbag(args.log)):
        log = rosbag.read_rosbag(args.log, scan_topic=getattr(args, "scan_topic", None),
                                 odom_topic=getattr(args, "odom_topic", None), laser_pose=pose)
        if log.skipped:
            print(f"localize: warning: {args.log}: skipped " + "; ".join(f"{n} {k}" for k, n in log.skipped.items()),
                  file=err)
    else:
        if getattr(args, "scan_topic", None) or getattr(args, "odom_topic", None):
            raise ValueError("--scan-topic and --odom-topic apply to ROS bags only")
        log = _read_relaying_warnings(err, lio.read_log, args.log, format=args.log_format)
        for msg in lio.time_stamp_problems(log):
            print(f"localize: warning: {msg}; the filter follows the record order", file=err)
        if pose is not None:
            log = replace(log, sensor_offset=np.asarray(pose, dtype=float),
                          meta={**log.meta, "sensor_offset_source": "given (--laser-pose)"})
    min_range = getattr(args, "min_range", None)
    if min_range:
        r = np.array(log.ranges, copy=True)
        r[r < min_range] = log.max_range
        log = replace(log, ranges=r, meta={**log.meta, "min_range": min_range})
    return log


def _apply_amcl(args, out: TextIO, err: TextIO) -> dict:
    """Read --amcl-params into ``args`` (options written on the command line win); return the run's extras."""
    extras: dict[str, Any] = {"sensor_params": {}, "kld": None, "augmented": None, "resample_threshold": 0.5}
    if args.amcl_params is None:
        return extras
    from .amcl import read_amcl_params

    m = read_amcl_params(args.amcl_params)
    st = m.settings
    given = _given_options(args, getattr(args, "_argv", []))
    kept = []
    for dest in ("particles", "alphas", "sensor", "beams", "max_range", "min_range", "sigma_hit", "min_motion"):
        if dest in given:
            kept.append(dest)
        else:
            setattr(args, dest, st[dest])
    if "z_short" in given:  # AMCL's likelihood field has no short-reading term: off unless asked for
        kept.append("z_short")
    else:
        args.z_short = 0.0
    if args.sensor == st["sensor"]:
        extras["sensor_params"] = dict(st["sensor_params"])
    extras.update(kld=st["kld"], augmented=st["augmented"], resample_threshold=st["resample_threshold"])
    if not args.quiet:
        print(m.table(), file=out)
        if kept:
            print("  command-line options kept: " + ", ".join("--" + d.replace("_", "-") for d in kept), file=out)
    for w in m.warnings():
        print(f"localize: warning: {w}", file=err)
    extras["mapping"] = {"file": str(args.amcl_params), "dialect": m.dialect,
                         "mapped": [{"parameter": r[0], "value": _jsonable(r[1]), "setting": r[2]} for r in m.rows],
                         "ignored": [r[0] for r in m.ignored], "command_line_kept": kept}
    return extras


def _jsonable(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    return v if isinstance(v, (int, float, str, bool)) or v is None else str(v)


def _check_free_space(grid: OccupancyGrid, where: str) -> None:
    if not grid.free.any():
        raise ValueError(f"{where}: the map has no free cell to localize in ({grid.occupied.sum()} occupied, "
                         f"{grid.unknown.sum()} unknown of {grid.data.size} cells); check the map's format and "
                         "thresholds (ROS maps: --not-free-is-occupied only adds obstacles)")


def _cmd_map(args, out: TextIO, err: TextIO | None = None) -> int:
    from . import io as lio
    from .mapping import map_from_log

    if args.out.suffix.lower() not in (".yaml", ".yml"):
        raise ValueError(f"--out {args.out}: the map's file name must end in .yaml (the PGM is written beside it)")
    log = _load(args, out if err is None else err)
    if log.poses is None:
        raise ValueError(f"{args.log}: the log has no reference poses to build a map from "
                         "(CARMEN corrected logs have them)")
    names = (args.out.name, args.out.with_suffix(".pgm").name)
    with RunOutput(args.out.parent, results=names, last=args.out.name) as dest:  # YAML and PGM appear together
        dest.open()  # checked before the mapping runs
        grid = map_from_log(log, resolution=args.resolution, every=args.every)
        lio.write_ros_map(dest.path(args.out.name), grid)
        dest.commit()
    path = args.out
    if not args.quiet:
        print(f"wrote {path} and {path.with_suffix('.pgm')}: {map_summary(grid)}", file=out)
    return 0


def _cmd_run(args, out: TextIO, err: TextIO) -> int:
    if args.map is None and not args.build_map:
        raise ValueError("give --map FILE, or --build-map to build the map from the log's corrected poses")
    if args.map is not None and args.build_map:
        raise ValueError("give either --map or --build-map, not both")
    extras = _apply_amcl(args, out, err)  # a bad parameter file is reported before --out is touched
    with RunOutput(args.out) as dest:  # the results appear in --out only when complete (localize._output)
        dest.open()  # check that --out can be written, and lock it, before anything else
        return _run(args, out, err, dest, extras)


def _run(args, out: TextIO, err: TextIO, dest: RunOutput, extras: dict) -> int:
    from . import io as lio
    from .mapping import map_from_log

    t_start = time.perf_counter()
    log = _load(args, err)
    if args.scans is not None:
        log = log.select(args.scans)
    if args.build_map:
        if log.poses is None:
            raise ValueError(f"{args.log}: --build-map needs reference poses in the log (it has none); give --map")
        grid = map_from_log(log, resolution=args.resolution)
        map_desc = f"built from {args.log} (resolution {args.resolution:g} m)"
    else:
        kw = {"not_free": "occupied"} if args.not_free_is_occupied else {}
        fmt = args.map_format or lio.detect_map_format(args.map)
        if kw and fmt != "ros":
            raise ValueError("--not-free-is-occupied applies to ROS map_server maps only")
        grid = _read_relaying_warnings(err, lio.read_map, args.map, format=fmt, **kw)
        map_desc = str(args.map)
    _check_free_space(grid, map_desc)
    if args.particles == "auto":
        args.particles = auto_particles(grid)
    check_memory(args.particles, min(args.beams, log.n_beams), args.sensor, n_cells=grid.data.size)  # before allocating
    t_read = time.perf_counter() - t_start
    quiet = args.quiet
    progress = Progress(len(log), stream=err, enabled=None if not quiet else False)
    is_bag = log.format in lio.BAG_FORMATS
    frames = max(1, int(np.ceil(len(log) / args.frames))) if args.animate or is_bag else 0
    rng = np.random.default_rng(args.seed)
    kw = run_kwargs(args)
    # an AMCL parameter file adds what the options cannot say (its sensor parameters, KLD bounds,
    # recovery rates, resampling interval); options written on the command line still win
    kw["sensor_params"] = {**extras["sensor_params"], **kw["sensor_params"]}
    kw["resample_threshold"] = extras["resample_threshold"]
    if extras["kld"] is not None:
        kw["kld"] = extras["kld"]
    if extras["augmented"] is not None:
        kw["augmented"] = extras["augmented"]
    if getattr(args, "smooth", False):  # forward and backward pass, combined (localize.smooth)
        from .smooth import smooth_log as run_log
    else:
        run_log = localize_log
    res = run_log(grid, log, rng=rng, snapshot_every=frames, progress=progress, **kw)
    progress.close()
    ref = log.poses
    write_trajectory(dest.path("trajectory.csv"), res, ref)
    outputs = _write_standard_outputs(dest.stage, res, log, err)
    kld_used, aug_used = kw["kld"], kw["augmented"]
    settings = {
        "map": map_desc, "log": str(args.log), "log_format": log.format, "seed": args.seed,
        **{opt.dest: _jsonable(getattr(args, opt.dest)) for opt in FILTER_OPTIONS},
        "beams": min(args.beams, log.n_beams), "init": "reference" if args.track else "global",
        "scans": None if args.scans is None else [args.scans.start, args.scans.stop, args.scans.step],
        "laser_pose": [round(float(v), 6) for v in log.sensor_offset],
        "resample_threshold": kw["resample_threshold"],
        "kld": None if kld_used is None else {"epsilon": kld_used.epsilon, "delta": kld_used.delta,
                                              "n_min": kld_used.n_min, "n_max": kld_used.n_max},
        "augmented": None if aug_used is None else [aug_used.alpha_slow, aug_used.alpha_fast],
    }
    if "mapping" in extras:
        settings["amcl_params"] = extras["mapping"]
    if is_bag:
        settings["bag"] = {k: log.meta.get(k) for k in ("scan_topic", "odom_topic", "odometry", "scan_frame",
                                                         "base_frame", "sensor_offset_source")}
    summary = summarize(res, log, args.particles, ref, settings)
    if getattr(args, "smooth", False):
        summary["settings"]["smooth"] = True
        summary["smooth"] = res.smooth.summary()
    summary["seconds_reading_files"] = round(t_read, 3)
    if args.animate:
        t_anim = time.perf_counter()
        files = write_animation(dest.stage, grid, res, ref, n_particles=args.particles)
        summary["animation"] = [p.name for p in files]
        summary["seconds_animation"] = round(time.perf_counter() - t_anim, 3)
    total = time.perf_counter() - t_start          # everything: reading, filtering and the animation
    summary["seconds_total"] = round(total, 3)
    if summary["log_duration_s"]:
        summary["real_time_factor_total"] = round(summary["log_duration_s"] / total, 3)
    summary["files"] = ["trajectory.csv", *outputs, *summary.get("animation", []), "summary.json"]
    write_summary(dest.path("summary.json"), summary)
    written, removed = dest.commit()
    if removed and not quiet:
        print(f"removed {', '.join(p.name for p in removed)} of an earlier run from {args.out}", file=out)
    if not quiet:
        rtf = summary["real_time_factor"]
        lines = [
            f"{len(log)} scans, {args.particles} particles, {summary['seconds_per_scan'] * 1000:.1f} ms per scan"
            + (f", {rtf:g}x real time" if rtf else ""),
            headline(summary),
        ]
        if getattr(args, "smooth", False):
            from .smooth import headline as smooth_headline
            lines.append(smooth_headline(summary["smooth"]))
        if summary.get("odometry_sign", {}).get("steps_reversed"):
            o = summary["odometry_sign"]
            lines.append(f"odometry: {o['steps_reversed']} of {o['steps_checked']} steps checked against the scans "
                         "were driven backwards (the odometry reports no reversing; --odometry-sign trust keeps it)")
        if ref is not None and summary.get("median_error_while_localized_m") is not None:
            lines.append(f"against the log's reference poses, while localized: median error "
                         f"{summary['median_error_while_localized_m']} m, 90% {summary['p90_error_while_localized_m']} m"
                         f" ({summary['localized_scans_over_1m_off']} localized scans more than 1 m off)")
        lines.append(f"wrote {', '.join(str(p) for p in written)}")
        print("\n".join(lines), file=out)
    return 0


def _cmd_demo(args, out: TextIO, err: TextIO) -> int:
    from ._output import RESULT_FILES
    from .demo import DEMO_FILES, make_demo
    from .io.tum import read_tum

    quiet = args.quiet
    rng = np.random.default_rng(args.seed)
    score = {}

    def add_score(dest: RunOutput) -> None:  # inside the staging folder, before anything appears in --out
        _, est = read_tum(dest.path("trajectory.tum"))
        e = np.hypot(*(est[:, :2] - d.poses[:, :2]).T)
        cs = converged_at(e, 0.5, 20)
        score.update({"truth": "truth.tum", "convergence_step_truth": cs,
                      "median_error_after_convergence_m": None if cs is None else round(float(np.median(e[cs:])), 3),
                      "final_error_m": round(float(e[-1]), 3)})
        summary = json.loads(dest.path("summary.json").read_text())
        summary["demo"] = score
        summary["settings"].update(map=str(args.out / "map.dat"), log=str(args.out / "robot.log"))
        summary["files"] = [*DEMO_FILES, *summary["files"]]
        write_summary(dest.path("summary.json"), summary)

    # the simulated files are staged with the results: one complete demo appears in --out, or nothing
    with RunOutput(args.out, results=(*DEMO_FILES, *RESULT_FILES), before_commit=add_score) as dest:
        dest.open()  # the lock first: a refused or interrupted demo leaves --out as it was
        d = make_demo(dest.stage, rng, steps=args.steps)
        argv = ["run", "--map", str(d.map_path), "--log", str(d.log_path), "--out", str(args.out),
                "--particles", str(args.particles), "--seed", str(args.seed), "--frames", str(args.frames)]
        argv += ([] if args.no_animate else ["--animate"]) + (["--quiet"] if quiet else [])
        shown = [str(args.out / Path(a).name) if a in (str(d.map_path), str(d.log_path)) else a for a in argv]
        if not quiet:
            print(f"simulated {args.steps} scans of a robot in the built-in office (map with a moved cupboard, walls "
                  f"drawn at another resolution, unmapped clutter): {', '.join(DEMO_FILES)}", file=out)
            print("localizing: localize " + " ".join(shown), file=out)
        run_args = build_parser().parse_args(argv)
        run_args._argv = shown
        code = _run(run_args, out, err, dest, _apply_amcl(run_args, out, err))
    if not quiet:
        cs, med = score["convergence_step_truth"], score["median_error_after_convergence_m"]
        print(f"against the true poses: within 0.5 m from scan {cs}" + (f", median error {med} m after that"
                                                                           if med is not None else "")
              + f", final error {score['final_error_m']} m", file=out)
        print(f"compare with evo: evo_ape tum {args.out / 'truth.tum'} {args.out / 'trajectory.tum'}", file=out)
    return code


def _write_standard_outputs(out_dir: Path, res: RunResult, log, err: TextIO) -> list[str]:
    """trajectory.tum (+ reference.tum) for evo; for a bag input the result bag. Returns the names written."""
    from .io import rosbag
    from .io.tum import write_tum

    names = []
    write_tum(out_dir / "trajectory.tum", res.times, res.estimates,
              comment=f"localize estimate (map frame) for {log.source}\ntimestamp x y z qx qy qz qw")
    names.append("trajectory.tum")
    if log.poses is not None:
        write_tum(out_dir / "reference.tum", res.times, log.poses,
                  comment=f"reference poses of {log.source}\ntimestamp x y z qx qy qz qw")
        names.append("reference.tum")
    if len(res.times) > 1 and np.any(np.diff(res.times) <= 0):
        print("localize: warning: the log's time stamps do not increase everywhere; evo may refuse "
              "trajectory.tum", file=err)
    if log.format in rosbag.BAG_FORMATS:
        name = "localization.bag" if log.format == "rosbag1" else "localization_bag"
        clouds = {k: p for k, (p, _w) in res.snapshots.items()}
        rosbag.write_result_bag(out_dir / name, res.times, res.estimates, res.covariances, clouds, storage=log.format)
        names.append(name)
    return names


def main(argv: Sequence[str] | None = None, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Entry point of ``localize`` / ``python -m localize``. Returns the exit status.

    Errors in the input files are reported as ``localize: error: file:line: ...``
    with exit status 2, without a traceback.

    Examples
    --------
    >>> import io
    >>> err = io.StringIO()
    >>> main(["run", "--log", "missing.log", "--map", "missing.dat"], stderr=err)
    2
    >>> print(err.getvalue().strip())
    localize: error: missing.log: no such file
    """
    out = sys.stdout if stdout is None else stdout
    err = sys.stderr if stderr is None else stderr
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse already printed usage / help
        return int(e.code or 0)
    args._argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if args.command == "map":
            return _cmd_map(args, out, err)
        if args.command == "demo":
            return _cmd_demo(args, out, err)
        return _cmd_run(args, out, err)
    except (ValueError, TypeError, OSError, ImportError) as e:
        print(f"localize: error: {e}", file=err)
        if getattr(e, "output_note", None):
            print(f"localize: {e.output_note}", file=err)
        return 2
    except KeyboardInterrupt as e:
        print("localize: interrupted" + (f"; {e.output_note}" if getattr(e, "output_note", None) else ""),
              file=err)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
