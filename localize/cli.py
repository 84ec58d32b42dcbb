"""The command line: ``python -m localize run ...`` (also installed as ``localize``).

Global localization with Monte Carlo Localization on a real (or simulated) log::

    localize run --map wean.dat --log robotdata1.log --out out/
    localize run --log intel-corrected.log.gz --build-map --out out/intel
    localize map --log intel-corrected.log.gz --out intel.yaml

``run`` reads a map and a log (formats detected from their content), spreads
particles uniformly over the free space of the map (and its unknown patches of
floor, ``OccupancyGrid.holes``), and filters every scan:
predict with the odometry motion between scans, weight with a range sensor
model, resample. It writes

* ``DIR/trajectory.csv`` — one row per scan: ``time,x,y,theta`` (the robot
  centre in the map frame, metres and radians; the mean of the heaviest
  cluster of particles), then ``spread`` (the particles' position standard
  deviation, metres), ``n_eff``, ``state`` (``searching``, ``localized``
  or ``lost``, from the filter's own evidence), ``p_localized`` (the
  probability that the estimate is within 1 m of the robot) and ``p_place``
  (the most ``p_localized`` could be were the scans' fit sure): the state is
  *localized* from ``p_localized`` 0.95 on, and a localized filter turns
  *lost* when ``p_localized`` falls below 0.7 or ``p_place`` below 0.95
  (:class:`localize.reliability.ReliabilityState`; with ``--state
  thresholds`` the two are empty and the state comes from
  :class:`localize.policies.StateRules`; with ``--smooth`` they are the
  pass's whose estimate the row takes, and the state is the combination's,
  :mod:`localize.smooth`); with reference poses in the log also
  ``ref_x,ref_y,ref_theta,error``; last the pose covariance of the heaviest
  cluster, ``cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,cov_thetatheta``;
* ``DIR/report.png`` — the map with the trajectory coloured by state, the
  reference (the log's, or ``--reference FILE``), the final particles, and the
  error (or spread) against time, with ``p_localized`` and ``p_place``
  (:func:`localize.plot.report.report_figure`);
* ``DIR/summary.json`` — particles, scans, seconds per scan, real-time factor,
  the ``state`` section (first localized scan, lost intervals, final state,
  ``final_p_localized`` and ``final_p_place`` as the CSV's last row writes them,
  events such as rejected odometry records), errors against the reference
  while localized, the final pose with its covariance, the map check
  (:func:`localize.pipeline.check_map`), and the settings used;
* ``DIR/map.yaml`` + ``map.pgm`` with ``--build-map`` (the map the run used);
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
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence, TextIO

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from . import __version__
from . import settings as _settings
from ._checks import check_count, check_positive
from ._output import RunOutput
from ._resources import check_memory
from .grid import OccupancyGrid
from .io.rosbag import BAG_FORMATS
from .motion import ReversibleOdometry  # noqa: F401  (re-exported: cli.ReversibleOdometry is its old name)

# the pipeline, re-exported under its old names (localize.cli.localize_log ...): new code imports localize.pipeline
from .pipeline import (  # noqa: F401
    AUTO_PARTICLES,
    ODOMETRY_SIGN,
    Inputs,
    RunResult,
    augmented_filter,
    auto_particles,
    check_log_odometry,
    check_map,
    converged_at,
    kld_sampling,
    localize_log,
    make_sensor,
    map_summary,
    particles_for_area,
    read_inputs,
    read_log_file,
    resolve_particles,
)
from .reliability import LOCALIZED_AT, LOST_BELOW, floor_text  # the probability state: its thresholds, its numbers
from .settings import RunSettings

__all__ = ["main", "build_parser", "Progress", "run_kwargs", "write_trajectory", "summarize", "write_summary",
           "headline", "write_animation"]

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


RUN_EXAMPLES = """\
examples:
  # a CARMEN log with corrected poses: build the map from them, localize
  localize run --log intel-corrected.log.gz --build-map --out out/intel
  # your robot: a ROS 2 bag folder, its map_server map, its AMCL parameters
  localize run --map office.yaml --log office_run/ --amcl-params nav2.yaml
  # a known start (x y yaw), and a reference trajectory to compare with
  localize run --map office.yaml --log office_run/ --initial-pose 2 3.5 1.57 \\
               --reference gt.tum
"""


# ============================================================================ settings
#: The defaults of ``localize run``: :data:`localize.settings.DEFAULTS` (see its --help and chapter 9 for the
#: reasons behind each).
DEFAULTS = _settings.DEFAULTS


# ============================================================================ progress
class Progress(tqdm):
    """tqdm's progress bar over the scans, drawn only when the stream is a terminal.

    :meth:`update_to` takes the number of scans done so far (what
    :func:`localize.runloop.run_filter` passes its ``callback``).

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


# ============================================================================ outputs
#: The pose covariance's columns of ``trajectory.csv`` and their (row, column) in the 3x3 covariance of x, y, theta.
COV_COLUMNS = {"cov_xx": (0, 0), "cov_xy": (0, 1), "cov_xtheta": (0, 2), "cov_yy": (1, 1), "cov_ytheta": (1, 2),
               "cov_thetatheta": (2, 2)}


def pose_covariances(res: RunResult) -> NDArray:
    """``(T, 3, 3)``: the covariance of x, y, theta behind each estimate of ``res``.

    For one pass, the weighted covariance of the best cluster
    (:attr:`localize.runloop.RunTrace.cov`). For ``--smooth``, the covariance
    of the pass whose estimate is used at the scan; where both passes agree
    and the estimate is their weighted mean, the two covariances fused as
    independent estimates, ``(Cf^-1 + Cb^-1)^-1`` (the two passes share only
    the scan itself, so this is slightly over-confident).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> c = np.repeat(np.eye(3)[None] * 0.04, 2, axis=0)
    >>> float(pose_covariances(SimpleNamespace(covariances=c, smooth=None))[0, 0, 0])
    0.04
    """
    sm = getattr(res, "smooth", None)
    cf = None if sm is None else getattr(sm.forward, "cov", None)
    cb = None if sm is None else getattr(sm.backward, "cov", None)
    if cf is None or cb is None:
        return np.asarray(res.covariances, dtype=float)
    pick_b = sm.source == "backward" if sm.from_backward is None else sm.from_backward
    out = np.where(np.asarray(pick_b)[:, None, None], cb, cf)
    both = np.asarray(sm.source) == "both"
    if both.any():
        reg = 1e-12 * np.eye(3)
        out[both] = np.linalg.inv(np.linalg.inv(cf[both] + reg) + np.linalg.inv(cb[both] + reg))
    return out


def _per_scan(res: RunResult, name: str) -> NDArray:
    """The trace's per-scan column ``name``, or NaN at every scan when the run has none."""
    v = getattr(res.trace, name, None) if res.trace is not None else None
    return np.full(len(res.times), np.nan) if v is None or len(v) != len(res.times) else np.asarray(v, dtype=float)


def write_trajectory(path: Path, res: RunResult, reference: NDArray | None = None,
                     covariances: NDArray | None = None) -> Path:
    """Write ``trajectory.csv``: ``time,x,y,theta,spread,n_eff,state,p_localized,p_place`` (the last two rounded
    down to four decimals, so that the state follows from them exactly; empty without ``--state probability``)
    (+ reference and error, the smoother's columns), then the pose covariance
    ``cov_xx ... cov_thetatheta`` (:data:`COV_COLUMNS`; ``covariances``, default :func:`pose_covariances`)."""
    cols = ["time", "x", "y", "theta", "spread", "n_eff", "state", "p_localized", "p_place"]
    state = res.state if res.state is not None else np.full(len(res.times), "")
    p_loc, p_place = (_per_scan(res, name) for name in ("p_localized", "p_place"))
    if reference is not None:
        cols += ["ref_x", "ref_y", "ref_theta", "error"]
        err = np.hypot(*(res.estimates[:, :2] - reference[:, :2]).T)
    extra = getattr(res, "columns", None) or {}  # more per-scan columns (localize.smooth: passes, source)
    cols += list(extra) + list(COV_COLUMNS)
    cov = pose_covariances(res) if covariances is None else np.asarray(covariances, dtype=float)
    cov_terms = np.stack([cov[:, i, j] for i, j in COV_COLUMNS.values()], axis=1)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for k in range(len(res.times)):
            row = [f"{res.times[k]:.6f}", *(f"{v:.6f}" for v in res.estimates[k]), f"{res.spread[k]:.4f}",
                   f"{res.n_eff[k]:.1f}", str(state[k]), floor_text(p_loc[k], 4), floor_text(p_place[k], 4)]
            if reference is not None:
                row += [*(f"{v:.6f}" for v in reference[k]), f"{err[k]:.4f}"]
            w.writerow(row + [str(v[k]) for v in extra.values()] + [f"{v:.6g}" for v in cov_terms[k]])
    return path


#: What summary.json says the state means when it comes from ``p_localized``.
STATE_MEANING = ("p_localized: the probability that the estimate is within 1 m of the robot, from the scans' fit to "
                 "the map there (calibrated at start-up on this map and sensor model), the particles' own mass "
                 "near it, and its share against the look-alike places kept as rivals "
                 f"(localize.reliability.ReliabilityState); localized: p_localized reached {LOCALIZED_AT}; "
                 f"p_place: the most p_localized could be were the scans' fit sure (the root of the smallest of "
                 "the particles' mass near the estimate, the probe and the rivals' share); "
                 f"lost: it was localized and p_localized fell below {LOST_BELOW} or p_place below {LOCALIZED_AT} "
                 "(another place probable); searching: never localized yet")


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
        # the spread of a cloud that never said "localized" (a one-cell map, a featureless corridor) is no
        # convergence: only a filter whose state became localized reports one
        "convergence_step": (converged_at(res.spread, threshold, hold)
                             if res.trace is None or res.trace.first_localized() is not None else None),
        "convergence_criterion": (f"first scan from which the particles' position spread (or, for *_reference, "
                                  f"the error) stays below the threshold for {hold} scans"),
        "final_estimate": [round(float(v), 4) for v in res.estimates[-1]],
        "final_pose": final_pose(res),
    }
    if res.trace is not None and getattr(res.trace, "n_valid", None) is not None:
        out["valid_readings_median"] = float(np.median(res.trace.n_valid))
        out["beams_used"] = int(min(settings.get("beams") or log.n_beams, log.n_beams))
    if not reliable:
        out["real_time_factor_note"] = "the log's time stamps are not usable (too coarse or out of order)"
    if res.trace is not None:
        out["state"] = res.trace.state_summary()
        out["state"]["meaning"] = STATE_MEANING if "final_p_localized" in out["state"] else (
            "searching: no single, well-fitting hypothesis yet; localized: one cluster holds most of the weight, "
            "is tight, and the scans fit the map there; lost: it was localized and no longer is (no map: "
            "see localize.policies.StateRules)")
    if "stated_max_range" in log.meta:
        out["max_range"] = {"stated_m": log.meta["stated_max_range"], "used_m": round(float(log.max_range), 4),
                            "source": log.meta.get("max_range_source"),
                            "meaning": "the readings above the range the log states are measurements, not 'no "
                                       "return' (see localize.pipeline.check_log_max_range); --max-range caps it"}
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


def final_pose(res: RunResult) -> dict:
    """The last scan's estimate and its covariance (x, y, theta; metres and radians), as ``summary.json`` holds it.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> r = SimpleNamespace(estimates=np.array([[1.0, 2.0, 0.5]]), covariances=np.eye(3)[None] * 0.01, smooth=None,
    ...                     times=np.array([3.0]), state=np.array(["localized"]))
    >>> fp = final_pose(r)
    >>> fp["x"], fp["theta"], fp["std"], fp["state"]
    (1.0, 0.5, [0.1, 0.1, 0.1], 'localized')
    """
    x, y, th = (round(float(v), 4) for v in res.estimates[-1])
    c = pose_covariances(res)[-1]
    state = getattr(res, "state", None)
    return {"time": round(float(res.times[-1]), 6), "x": x, "y": y, "theta": th,
            "covariance": [[float(f"{v:.6g}") for v in row] for row in c],
            "std": [round(float(np.sqrt(max(c[i, i], 0.0))), 4) for i in range(3)],
            "state": None if state is None else str(state[-1])}


def write_report(path: Path, grid: OccupancyGrid, res: RunResult, reference: NDArray | None = None,
                 title: str | None = None, dpi: int = 90) -> Path:
    """Save ``report.png``: :func:`localize.plot.report.report_figure` of the run (the final cloud is the last
    scan's snapshot, which :func:`localize.pipeline.localize_log` always keeps).

    The second panel's axis is the time since the first scan when the log's
    time stamps increase, else the scan index.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from .plot.report import report_figure

    t = np.asarray(res.times, dtype=float)
    times = t - t[0] if len(t) > 1 and np.all(np.diff(t) > 0) else None
    fig = report_figure(grid, res.trace, reference, times=times, title=title)
    try:
        fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)
    return path


def write_summary(path: Path, summary: dict) -> Path:
    """Write ``summary.json`` (indented JSON, one trailing newline)."""
    with open(path, "w") as fh:
        json.dump(summary, fh, indent=2)
        fh.write("\n")
    return path


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
    >>> headline({"state": {"first_localized_scan": 3, "lost_intervals": [[50, 59]], "final_state": "lost",
    ...                     "final_p_localized": 0.81, "final_p_place": 0.8, "events": []}})
    'localized from scan 3 (p_localized 0.81, p_place 0.80 at the end); lost at scans 50-59; final state: lost'
    >>> headline({"state": {"first_localized_scan": 3, "lost_intervals": [], "final_state": "lost",
    ...                     "final_p_localized": 0.9, "final_p_place": 0.9499, "events": []}})
    'localized from scan 3 (p_localized 0.90, p_place 0.94 at the end); final state: lost'
    """
    st = summary.get("state")
    if not st:
        return f"converged (particle spread < 0.5 m) at scan {summary.get('convergence_step')}"
    k = st["first_localized_scan"]
    parts = [f"localized from scan {k}" if k is not None else "NOT localized: still searching at the end"]
    if st.get("final_p_localized") is not None:
        place = st.get("final_p_place")
        # rounded down, so that a value just below a threshold never reads as the threshold
        place = f", p_place {floor_text(place, 2)}" if place is not None and place < LOCALIZED_AT else ""   # it decided
        parts[0] += f" (p_localized {floor_text(st['final_p_localized'], 2)}{place} at the end)"
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


def advice(summary: dict) -> list[str]:
    """What to try when a run ends lost or searching, from the evidence in ``summary`` (empty otherwise).

    * few valid readings per scan (median below a third of the beams used):
      the range limits, ``--max-range`` / ``--min-range``;
    * never localized: ``--particles`` (more of the pose space covered), and
      the map (does the report's map match the scans?);
    * lost after a stretch localized: ``--restart-after`` / ``--recovery-injection``.

    Examples
    --------
    >>> s = {"particles": 20000, "valid_readings_median": 3, "beams_used": 30,
    ...      "state": {"final_state": "searching", "first_localized_scan": None, "lost_intervals": []}}
    >>> for line in advice(s): print(line[:60])
    try --max-range / --min-range: a scan has 3 valid readings o
    try --particles 40000: never localized with 20000 particles;
    """
    st = summary.get("state") or {}
    if st.get("final_state", "localized") == "localized":
        return []
    out = []
    valid, beams = summary.get("valid_readings_median"), summary.get("beams_used")
    if valid is not None and beams and valid < beams / 3:
        out.append(f"try --max-range / --min-range: a scan has {valid:g} valid readings of {beams} beams (median); "
                   "readings beyond --max-range or at most --min-range are not evidence")
    n = summary.get("particles", 0)
    if st.get("first_localized_scan") is None:
        out.append(f"try --particles {2 * n}: never localized with {n} particles; more cover more of the map's "
                   "poses (and check in report.png that the map fits the scans)")
    elif st.get("final_state") == "lost":
        out.append("try --restart-after 3 or --recovery-injection 0.05: localized for a stretch, then lost to the "
                   "end; a sooner restart or random particles while lost search the map again")
    return out


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
    counts = n_particles
    if res.trace is not None and getattr(res.trace, "n_particles", None) is not None:
        counts = {k: int(res.trace.n_particles[k]) for k in res.snapshots}   # what KLD-sampling really drew
    anim = animate_snapshots(grid, res.snapshots, true_poses=reference, estimates=res.estimates,
                             figsize=(6.0, max(3.0, min(8.0, 6.0 * aspect))), size=2.0, n_particles=counts,
                             truth_label="reference path")
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
_positive_int = _settings.argparse_type(check_count, "positive_int")
_seed = _settings.argparse_type(lambda v, name: check_count(v, name, minimum=0), "seed")
_particles = _settings.argparse_type(_settings.check_particles, "particles")
_positive_float = _settings.argparse_type(lambda v, name: check_positive(v, name, "metres"), "positive_float")


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """``--help``: the description and examples as written, each option's line after a 28-column name."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=28)


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
                        help=f"{what}'s cell size, m (default 0.05)")


def _add_frames_and_quiet(parser: Any, frames: int) -> None:
    """``--frames`` and ``--quiet``: the options of ``run`` that ``demo`` passes on to it."""
    parser.add_argument("--frames", type=_positive_int, default=frames, metavar="K",
                        help=f"animation frames (default {frames})")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no summary (default off)")


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
        usage="localize run --log FILE (--map FILE | --build-map) [--out DIR] [options]",
        description=_wrap("Monte Carlo Localization on a log: particles start over the map's free space (or "
                          "around --initial-pose), move with the odometry and are weighted by the laser scans. "
                          "Writes DIR/trajectory.csv (pose, state, p_localized and p_place, covariance per scan), DIR/report.png, "
                          "DIR/summary.json and DIR/trajectory.tum; all together when the run is complete."),
        epilog=RUN_EXAMPLES + "\nAMCL parameters (--amcl-params FILE.yaml), ROS 1 amcl or nav2 nav2_amcl:\n"
        + _amcl_table() + "\n\nEach setting's rationale: localize.settings.explain(NAME), and chapter 9.",
        formatter_class=_HelpFormatter)
    g = run.add_argument_group("input")
    g.add_argument("--log", type=Path, metavar="FILE", required=True,
                   help="CMU, CARMEN, ROS bag or bag folder (required)")
    g.add_argument("--map", type=Path, metavar="FILE",
                   help="CMU map or map_server YAML (default none)")
    g.add_argument("--build-map", action="store_true",
                   help="map from the log's poses, saved (default off)")
    _add_resolution(g, "the map")
    g.add_argument("--amcl-params", type=Path, default=None, metavar="FILE",
                   help="settings from an amcl / nav2 YAML (default none)")
    g.add_argument("--reference", type=Path, default=None, metavar="FILE",
                   help="TUM or CSV time,x,y,theta (default: the log's)")
    g.add_argument("--scans", type=_scan_slice, default=None, metavar="A:B[:S]",
                   help="only these scans, a Python slice (default all)")
    g.add_argument("--laser-pose", type=float, nargs=3, default=None, metavar=("X", "Y", "YAW"),
                   help="laser's pose on the robot (default: the log's)")
    g.add_argument("--scan-topic", metavar="TOPIC", default=None,
                   help="bags: LaserScan topic (default: the only one)")
    g.add_argument("--odom-topic", metavar="TOPIC", default=None,
                   help="bags: Odometry topic or /tf (default: found)")
    g.add_argument("--map-format", choices=["cmu", "ros"], default=None, metavar="FMT",
                   help="map format: cmu, ros (default: detected)")
    g.add_argument("--log-format", choices=["cmu", "carmen", "rosbag"], default=None, metavar="FMT",
                   help="cmu, carmen, rosbag (default: detected)")
    g.add_argument("--not-free-is-occupied", action="store_true",
                   help="ROS maps: grey is wall, not unknown (default off)")
    groups = {"sensor": run.add_argument_group("sensor"), "filter": run.add_argument_group("filter")}
    groups["recovery"] = run.add_argument_group(
        "recovery", "knowing when the filter is wrong, and finding the robot again: the default --state and "
                    "--restart-after suffice so far; --injection, --augmented, --recovery-injection, --expand and "
                    "--sensor-reset are expert settings, off by default")
    _settings.add_arguments(run, groups)  # one option per setting of localize.settings.RunSettings
    groups["filter"].add_argument("--seed", type=_seed, default=0, metavar="S",
                                  help="random seed: same seed, same run (default 0)")
    groups["filter"].add_argument("--smooth", action="store_true",
                                  help="offline: filter forwards and back (default off)")
    o = run.add_argument_group("output")
    o.add_argument("--out", type=Path, default=Path("localize-out"), metavar="DIR",
                   help="output folder (default ./localize-out)")
    o.add_argument("--animate", action="store_true",
                   help="also DIR/particles.gif and .mp4 (default off)")
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


# ============================================================================ the run command
def run_kwargs(args: argparse.Namespace, grid: OccupancyGrid | None = None) -> dict:
    """``{"settings": RunSettings}``: the keyword arguments of :func:`localize.pipeline.localize_log` that the
    ``run`` options stand for, ``--particles auto`` resolved on ``grid`` when given.

    (Kept for callers of the old keyword form; new code reads
    :func:`localize.settings.from_namespace` or builds a
    :class:`~localize.settings.RunSettings`.)

    Examples
    --------
    >>> from localize.maps import office
    >>> args = build_parser().parse_args(["run", "--log", "x.log", "--map", "m.yaml"])
    >>> run_kwargs(args, grid=office())["settings"].particles == auto_particles(office())
    True
    """
    s = _settings.from_namespace(args)
    if grid is not None:
        s = replace(s, particles=resolve_particles(s.particles, grid))
    return {"settings": s}


def _amcl_table() -> str:
    from .amcl import MAPPING_TABLE

    return "\n".join("  " + line for line in MAPPING_TABLE.splitlines())


def _warner(err: TextIO):
    def warn(message: str) -> None:
        print(f"localize: warning: {message}", file=err)
    return warn


def _load(args, err: TextIO):
    """The log of ``args`` (``run`` or ``map``), the readers' warnings printed to ``err``."""
    return read_log_file(args.log, args.log_format, scan_topic=getattr(args, "scan_topic", None),
                         odom_topic=getattr(args, "odom_topic", None), laser_pose=getattr(args, "laser_pose", None),
                         min_range=getattr(args, "min_range", None), warn=_warner(err))


def _run_settings(args, out: TextIO, err: TextIO) -> tuple[RunSettings, dict | None]:
    """The run's settings from the options and ``--amcl-params`` (options written on the command line win),
    and the AMCL mapping section of ``summary.json`` (None without a parameter file)."""
    settings = _settings.from_namespace(args)
    if args.amcl_params is None:
        return settings, None
    from .amcl import read_amcl_params

    m = read_amcl_params(args.amcl_params)
    given = _settings.given_options(getattr(args, "_option_dests", {}), getattr(args, "_argv", []))
    settings, kept = _settings.with_amcl(settings, m.settings, given)
    if not args.quiet:
        print(m.table(), file=out)
        if kept:
            print("  command-line options kept: " + ", ".join("--" + d.replace("_", "-") for d in kept), file=out)
    for w in m.warnings():
        print(f"localize: warning: {w}", file=err)
    mapping = {"file": str(args.amcl_params), "dialect": m.dialect,
               "mapped": [{"parameter": r[0], "value": _jsonable(r[1]), "setting": r[2]} for r in m.rows],
               "ignored": [r[0] for r in m.ignored], "command_line_kept": kept}
    return settings, mapping


_jsonable = _settings.jsonable


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


def _inputs(args) -> Inputs:
    """What ``localize run`` reads, from its options."""
    return Inputs(log=args.log, map=args.map, log_format=args.log_format, map_format=args.map_format,
                  scan_topic=args.scan_topic, odom_topic=args.odom_topic,
                  laser_pose=None if args.laser_pose is None else tuple(args.laser_pose), build_map=args.build_map,
                  resolution=args.resolution, not_free_is_occupied=args.not_free_is_occupied, scans=args.scans)


def _cmd_run(args, out: TextIO, err: TextIO) -> int:
    inputs = _inputs(args)
    settings, amcl = _run_settings(args, out, err)  # a bad parameter file is reported before --out is touched
    with RunOutput(args.out) as dest:  # the results appear in --out only when complete (localize._output)
        dest.open()  # check that --out can be written, and lock it, before anything else
        return _run(args, inputs, settings, amcl, out, err, dest)


def _run(args, inputs: Inputs, settings: RunSettings, amcl: dict | None, out: TextIO, err: TextIO,
         dest: RunOutput) -> int:
    """Read, filter (:mod:`localize.pipeline`), write the outputs into ``dest`` and report."""
    t_start = time.perf_counter()
    log, grid, map_desc = read_inputs(inputs, settings.min_range, warn=_warner(err))
    map_check = check_map(grid, inputs.map, log, max_range=settings.max_range)
    for w in map_check.warnings:
        _warner(err)(f"{map_desc}: {w}")
    if settings.particles == "auto" and map_check.robot_m2 < map_check.free_m2:  # sized from where the robot can be
        settings = replace(settings, particles=particles_for_area(map_check.robot_m2))
        _warner(err)(f"--particles auto: {settings.particles} particles for the {map_check.robot_m2:.0f} m^2 the "
                     "robot can be in (the initial cloud still covers all free cells)")
    settings = replace(settings, particles=resolve_particles(settings.particles, grid))
    check_memory(settings.particles, min(settings.beams, log.n_beams), settings.sensor,
                 n_cells=grid.data.size)  # before allocating
    reference, reference_note = _reference(args, log)
    t_read = time.perf_counter() - t_start
    progress = Progress(len(log), stream=err, enabled=None if not args.quiet else False)
    is_bag = log.format in BAG_FORMATS
    frames = max(1, int(np.ceil(len(log) / args.frames))) if args.animate or is_bag else 0
    if args.smooth:  # forward and backward pass, combined (localize.smooth)
        from .smooth import smooth_log as run_log
    else:
        run_log = localize_log
    res = run_log(grid, log, rng=np.random.default_rng(args.seed), settings=settings, snapshot_every=frames,
                  progress=progress)
    progress.close()
    write_trajectory(dest.path("trajectory.csv"), res, log.poses)
    outputs = _write_standard_outputs(dest.stage, res, log, err)
    if inputs.build_map:  # the map the run used, for --map next time
        from .io import write_ros_map

        trinary = OccupancyGrid(np.where(grid.occupied, 1.0, np.where(grid.free, 0.0, np.nan)), grid.resolution,
                                origin=tuple(grid.origin))  # the run's free / occupied / unknown, as --map reads them
        write_ros_map(dest.path("map.yaml"), trinary)
        outputs += ["map.yaml", "map.pgm"]
    ref, ref_note = (reference if reference is not None else log.poses), reference_note
    t_report = time.perf_counter()
    write_report(dest.path("report.png"), grid, res, ref,
                 title=f"{Path(args.log).name}: {headline_short(res)}" + (f" (reference: {ref_note})" if ref_note
                                                                          else ""))
    t_report = time.perf_counter() - t_report
    outputs.append("report.png")
    summary = summarize(res, log, settings.particles, log.poses,
                        _settings_section(args, settings, log, map_desc, amcl, is_bag))
    if args.smooth:
        summary["settings"]["smooth"] = True
        summary["smooth"] = res.smooth.summary()
    summary["seconds_reading_files"] = round(t_read, 3)
    summary["seconds_report"] = round(t_report, 3)
    summary["map_check"] = {"free_m2": round(map_check.free_m2, 1), "outside_m2": round(map_check.outside_m2, 1),
                            "robot_m2": round(map_check.robot_m2, 1), "free_share": round(map_check.free_share, 3),
                            "scanned_m2": None if map_check.scanned_m2 is None else round(map_check.scanned_m2, 1),
                            "thresholds": map_check.thresholds, "warnings": list(map_check.warnings)}
    if reference is not None:
        summary["reference"] = _reference_section(args.reference, res, reference)
        summary["reference"]["label"] = getattr(args, "_reference_label", None)
    if args.animate:
        t_anim = time.perf_counter()
        files = write_animation(dest.stage, grid, res, log.poses, n_particles=settings.particles)
        summary["animation"] = [p.name for p in files]
        summary["seconds_animation"] = round(time.perf_counter() - t_anim, 3)
    total = time.perf_counter() - t_start          # everything: reading, filtering and the animation
    summary["seconds_total"] = round(total, 3)
    if summary["log_duration_s"]:
        summary["real_time_factor_total"] = round(summary["log_duration_s"] / total, 3)
    summary["files"] = ["trajectory.csv", *outputs, *summary.get("animation", []), "summary.json"]
    write_summary(dest.path("summary.json"), summary)
    written, removed = dest.commit()
    if not args.quiet:
        if removed:
            print(f"removed {', '.join(p.name for p in removed)} of an earlier run from {args.out}", file=out)
        print(_report(summary, len(log), written, args.smooth), file=out)
    return 0


def _reference(args, log) -> tuple[NDArray | None, str | None]:
    """``--reference FILE`` matched to the log's scans (None without it), and how the report names it."""
    if getattr(args, "reference", None) is None:
        return None, ("the log's poses" if log.poses is not None else None)
    from .pipeline import match_reference, read_reference

    t, poses = read_reference(args.reference)
    return match_reference(t, poses, log.times, where=f"--reference {args.reference}"), Path(args.reference).name


def _reference_section(path: Path, res: RunResult, reference: NDArray) -> dict:
    """``summary.json``'s ``reference`` section: the file, the scans it covers, the error while localized."""
    err = np.hypot(*(res.estimates[:, :2] - reference[:, :2]).T)
    ok = np.isfinite(err)
    loc = ok & (np.asarray(res.state) == "localized") if res.state is not None else ok
    return {"file": str(path), "scans_matched": int(ok.sum()),
            "median_error_m": round(float(np.median(err[ok])), 4),
            "median_error_while_localized_m": round(float(np.median(err[loc])), 4) if loc.any() else None,
            "final_error_m": None if not ok[-1] else round(float(err[-1]), 4)}


def headline_short(res: RunResult) -> str:
    """The report's title: the final state and the first localized scan.

    >>> from types import SimpleNamespace
    >>> headline_short(SimpleNamespace(state=np.array(["searching", "localized", "localized"])))
    'localized from scan 1, final state localized'
    """
    state = np.asarray(res.state) if res.state is not None else None
    if state is None:
        return "no state"
    loc = np.flatnonzero(state == "localized")
    first = f"localized from scan {loc[0]}" if loc.size else "never localized"
    return f"{first}, final state {state[-1]}"


def _settings_section(args, settings: RunSettings, log, map_desc: str, amcl: dict | None, is_bag: bool) -> dict:
    """The ``settings`` section of ``summary.json``: the files, the filter's settings and what they built."""
    kld, aug = kld_sampling(settings, settings.particles), augmented_filter(settings)
    section = {
        "map": map_desc, "log": str(args.log), "log_format": log.format, "seed": args.seed,
        **settings.summary(),
        "beams": min(settings.beams, log.n_beams), "init": "reference" if settings.track else "global",
        "scans": None if args.scans is None else [args.scans.start, args.scans.stop, args.scans.step],
        "laser_pose": [round(float(v), 6) for v in log.sensor_offset],
        "resample_threshold": settings.resample_threshold,
        "kld": None if kld is None else {"epsilon": kld.epsilon, "delta": kld.delta, "n_min": kld.n_min,
                                         "n_max": kld.n_max},
        "augmented": None if aug is None else [aug.alpha_slow, aug.alpha_fast],
    }
    if amcl is not None:
        section["amcl_params"] = amcl
    if is_bag:
        section["bag"] = {k: log.meta.get(k) for k in ("scan_topic", "odom_topic", "odometry", "scan_frame",
                                                        "base_frame", "sensor_offset_source")}
    return section


def _report(summary: dict, n_scans: int, written: list[Path], smooth: bool) -> str:
    """The terminal's account of a run: speed, state, passes, odometry, errors, files."""
    rtf = summary["real_time_factor"]
    lines = [
        f"{n_scans} scans, {summary['particles']} particles, {summary['seconds_per_scan'] * 1000:.2g} ms per scan"
        + (f", {_times(rtf)} real time" if rtf else ""),
        headline(summary),
    ]
    if (summary.get("state") or {}).get("lost_intervals"):
        lines.append("  (lost: the filter had been localized, then stopped being sure of its estimate: the scans fit "
                     "the map poorly there, or as well elsewhere; it searches again)")
    if smooth:
        from .smooth import headline as smooth_headline
        lines.append(smooth_headline(summary["smooth"]))
    if summary.get("odometry_sign", {}).get("steps_reversed"):
        o = summary["odometry_sign"]
        lines.append(f"odometry: {o['steps_reversed']} of {o['steps_checked']} steps checked against the scans "
                     "were driven backwards (the odometry reports no reversing; --odometry-sign trust keeps it)")
    if summary.get("median_error_while_localized_m") is not None:
        lines.append(f"against the log's reference poses, while localized: median error "
                     f"{summary['median_error_while_localized_m']:.2f} m, 90% "
                     f"{summary['p90_error_while_localized_m']:.2f} m ({summary['localized_scans_over_1m_off']} "
                     "localized scans more than 1 m off)")
    ref = summary.get("reference")
    if ref and ref.get("median_error_while_localized_m") is not None:
        lines.append(f"against {ref.get('label') or Path(ref['file']).name}: median error {ref['median_error_while_localized_m']:.2f} m "
                     "while localized" + (f", final error {ref['final_error_m']:.2f} m"
                                          if ref.get("final_error_m") is not None else ""))
    lines += advice(summary)
    fp = summary.get("final_pose")
    if fp:
        lines.append(f"final pose: x {fp['x']:.2f} m, y {fp['y']:.2f} m, yaw {fp['theta']:.3f} rad "
                     f"(std {fp['std'][0]:.2f} m, {fp['std'][1]:.2f} m, {fp['std'][2]:.3f} rad; {fp['state']})")
    lines.append(f"wrote {', '.join(str(p) for p in written)}")
    return "\n".join(lines)


def _times(factor: float) -> str:
    """A real-time factor at the precision a loaded machine's timing supports (two significant figures).

    >>> _times(201.444), _times(26.548), _times(3.42)
    ('200x', '27x', '3.4x')
    """
    return f"{float(f'{factor:.2g}'):g}x"


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
        argv = ["run", "--map", str(d.map_path), "--log", str(d.log_path), "--reference", str(d.truth_path),
                "--out", str(args.out),
                "--particles", str(args.particles), "--seed", str(args.seed), "--frames", str(args.frames)]
        argv += ([] if args.no_animate else ["--animate"]) + (["--quiet"] if quiet else [])
        staged = (str(d.map_path), str(d.log_path), str(d.truth_path))
        shown = [str(args.out / Path(a).name) if a in staged else a for a in argv]
        if not quiet:
            print(f"simulated {args.steps} scans of a robot in the built-in office (map with a moved cupboard, walls "
                  f"drawn at another resolution, unmapped clutter): {', '.join(DEMO_FILES)}", file=out)
            print("localizing: localize " + " ".join(shown), file=out)
        run_args = build_parser().parse_args(argv)
        run_args._argv = shown
        run_args._reference_label = "the true poses"
        settings, amcl = _run_settings(run_args, out, err)
        code = _run(run_args, _inputs(run_args), settings, amcl, out, err, dest)
    if not quiet:
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
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # argparse already printed usage / help
        return int(e.code or 0)
    except KeyboardInterrupt:
        print("localize: interrupted; nothing written", file=err)
        return 130
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
    except MemoryError:  # the memory check's estimate was too low for this machine
        print("localize: error: out of memory: use fewer --particles or --beams (the run's estimate of its own "
              "needs was too low here; nothing written)", file=err)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
