"""Offline localization of a recorded log: a forward and a backward pass, combined scan by scan.

A filter that runs while the robot drives (a *causal* filter) knows at scan
``k`` only the scans ``0 .. k``. A recorded log has them all. Run the same
filter twice -- forwards, and backwards over the reversed log -- and each scan
gets two independent answers:

* the **forward pass** is lost at the start of the log (global localization
  needs a few scans), and may lock onto a look-alike corridor it cannot tell
  from the right one until later scans show the difference;
* the **backward pass** starts at the end of the log: it has localized long
  before it reaches the start, so the scans the forward pass spent searching
  get an answer; and where the forward pass picked the wrong corridor, the
  backward pass arrives there from the other side, already knowing where it is.

Going backwards in time needs no new motion model: the reversed log's
odometry pair ``(odometry[k+1], odometry[k])`` *is* the inverse relative pose,
a robot driving backwards, which :class:`localize.mcl.ReversibleOdometry`
(the command line's motion model) moves correctly (a backward motion is the
forward motion of a robot turned by 180 degrees). Both passes are the one run
driver, :func:`localize.runloop.run_filter`, through
:func:`localize.pipeline.localize_log`, with the same settings.

The combination (:func:`combine`), at every scan, from the passes' own honest
states (``searching`` / ``localized`` / ``lost``):

* both localized and within ``agree_distance`` / ``agree_heading``: **both**,
  the mean of the two estimates weighted by their spreads (inverse variance);
* both localized but apart: **disagree**. For each stretch of such scans the
  two trajectories are compared on the stretch and ``window`` scans either
  side (there, each pass's place carried on by the odometry from the
  stretch's ends) by their scan fit: the share of beams whose reading agrees with the
  range ray-cast in the map from the estimate (the run driver's fit, see
  :class:`localize.policies.StateRules`; a wrong place lets beams pass through
  walls). The pass whose fit is better by at least ``min_z`` standard errors
  of the paired per-scan differences wins. If neither does, the stretch is
  *ambiguous*: the scans cannot tell the two places apart, so the state there
  is not ``localized`` (the estimate is the pass that had been localized
  longer going into the stretch). A pass that loses a stretch followed a wrong
  place: on the scans next to the stretch where it alone is localized, as
  long as its estimate follows that place (no jump against the odometry), the
  winner's estimate is used and the state is not ``localized``;
* only one localized: that one (**forward** or **backward**), unless the
  other pass's estimate (its cloud's mean, not localized) fits the scans of
  the stretch better by the same paired test: then the lone pass is
  *overruled* (it may have settled on a look-alike place, e.g. after a
  restart), the better-fitting estimate is used and the state is not
  ``localized``;
* neither: **none**; the state stays honest (``searching`` before the first
  localized scan of the combined trajectory, ``lost`` after it); the
  estimate is the one that fits the scans better (over five neighbouring
  scans), or without a fit function, or on a tie, that of the pass that was
  localized more recently in its own direction of time.

Examples
--------
>>> import numpy as np
>>> from localize import sim
>>> from localize.io import LaserLog
>>> from localize.maps import office
>>> g = office()
>>> run = sim.range_run(g, np.random.default_rng(2), n_steps=25, speed=0.5, angles=np.linspace(-1.5, 1.5, 31))
>>> log = LaserLog(times=run.times, odometry=run.odometry, ranges=run.ranges, angles=run.angles,
...                max_range=run.max_range, poses=run.poses)
>>> res = smooth_log(g, log, rng=np.random.default_rng(0), n_particles=3000, beams=31, kld=None)
>>> sorted(res.smooth.summary()["passes"])
['backward', 'both', 'disagree', 'forward', 'none']
>>> res.estimates.shape, res.state.shape, sorted(res.columns)
((25, 3), (25,), ['passes', 'source'])
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields, replace
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from ._checks import check_count, check_nonnegative, check_positive
from .evidence import scan_fit
from .geometry import angle_diff, circular_mean, compose, relative
from .grid import OccupancyGrid
from .pipeline import RunResult, check_log_odometry, localize_log, run_max_range, settings_with
from .runloop import RunTrace, StateTrack, _intervals
from .settings import RunSettings

__all__ = ["PASSES", "Smoothed", "SmoothResult", "reverse_log", "reverse_trace", "combine", "scan_fit_function",
           "smoothed_trace", "smooth_log", "headline"]

#: Values of the per-scan ``passes`` column.
PASSES = ("both", "disagree", "forward", "backward", "none")



def reverse_log(log):
    """The log played backwards: scans, odometry and reference poses in reverse order.

    The controls of the reversed log, ``(odometry[k+1], odometry[k])`` of the
    original, are the inverse relative poses: the robot drives its path
    backwards. Time stamps are reversed too (they decrease; the filter uses
    the record order only).

    Examples
    --------
    >>> import numpy as np
    >>> from localize.io import LaserLog
    >>> log = LaserLog(times=[0.0, 1.0, 2.0], odometry=[[0, 0, 0], [1, 0, 0], [2, 0, 0]],
    ...                ranges=np.ones((3, 2)), angles=[-0.5, 0.5], max_range=5.0)
    >>> reverse_log(log).odometry[:, 0]
    array([2., 1., 0.])
    """
    if len(log) < 1:
        raise ValueError("reverse_log: the log has no scan")
    return log.select(slice(None, None, -1))


def reverse_trace(trace: RunTrace) -> RunTrace:
    """A :class:`~localize.runloop.RunTrace` of a reversed log turned back into the log's own scan order.

    Every per-scan array (each array field of length ``T``) is flipped; an event of step ``k`` becomes one of
    scan ``T - 1 - k``; snapshots are renumbered the same way.
    """
    if not isinstance(trace, RunTrace):
        raise TypeError(f"trace must be a localize.runloop.RunTrace; got {type(trace).__name__}")
    t = len(trace)
    flipped = {f.name: np.ascontiguousarray(getattr(trace, f.name)[::-1]) for f in fields(trace)
               if isinstance(getattr(trace, f.name), np.ndarray) and getattr(trace, f.name).shape[:1] == (t,)}
    events = sorted(((t - 1 - int(k), str(text)) for k, text in trace.events), key=lambda e: e[0])
    snaps = {t - 1 - int(k): v for k, v in trace.snapshots.items()}
    return replace(trace, events=events, snapshots=snaps, **flipped)


def scan_fit_function(grid: OccupancyGrid, log, fit_distance: float, min_range: float = 0.0,
                      max_range: float | None = None, min_beams: int = 5, max_beams: int = 180
                      ) -> Callable[[NDArray, NDArray], NDArray]:
    """``fit(poses, scans)``: the share of each scan's beams that the map confirms at a pose.

    For scan ``scans[i]`` and robot pose ``poses[i]``: the share of valid
    readings (above ``min_range``, below ``max_range``) within
    ``fit_distance`` of the range ray-cast in ``grid`` (beams ending in
    unknown cells are not judged; NaN with fewer than ``min_beams`` judged),
    as the run driver's state uses it. At most ``max_beams`` evenly spread
    beams of each scan are used.
    """
    from .raycast import RayCaster

    if not isinstance(grid, OccupancyGrid):
        raise TypeError(f"grid must be an OccupancyGrid; got {type(grid).__name__}")
    fit_d = check_positive(fit_distance, "fit_distance", "m")
    lo = check_nonnegative(min_range, "min_range", "m")
    if log.n_beams > max_beams:
        log = log.select_beams(count=max_beams)
    hi = log.max_range if max_range is None else min(float(max_range), log.max_range)
    caster = RayCaster(grid, hi, method="march")
    offset = np.asarray(log.sensor_offset, dtype=float)
    ranges, angles = log.ranges, log.angles

    def fit(poses: NDArray, scans: NDArray) -> NDArray:
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        idx = np.asarray(scans, dtype=int).reshape(-1)
        out = np.full(len(idx), np.nan)
        for i, (k, pose) in enumerate(zip(idx, p)):
            r = ranges[k]
            ok = np.isfinite(r) & (r > lo) & (r < hi)
            if np.all(np.isfinite(pose)):
                out[i] = scan_fit(caster, pose, offset, r[ok], angles[ok], fit_d, min_beams)
        return out

    return fit


@dataclass(frozen=True, eq=False, kw_only=True)
class Smoothed(StateTrack):
    """The combined trajectory of a forward and a backward pass (see the module's docstring); built by keyword.

    Attributes
    ----------
    poses, stds : ndarray (T, 3)
        Combined estimate and the particles' spread of the pass(es) it came from.
    spread : ndarray (T,)
        Position spread of the best cluster (combined like the estimate).
    state : ndarray (T,) of str
        ``localized`` where at least one pass is; else ``searching`` before the
        first localized scan, ``lost`` after it.
    passes : ndarray (T,) of str
        ``both``, ``disagree``, ``forward``, ``backward`` or ``none``: which
        passes are localized at the scan, and whether they agree.
    source : ndarray (T,) of str
        Where the estimate comes from: ``both`` (their weighted mean),
        ``forward``, ``backward`` or ``none`` (neither localized: see the module's docstring for the estimate).
    forward, backward : RunTrace
        The two passes, both in the log's scan order.
    disagreements : list of dict
        One per stretch of ``disagree`` scans: first and last scan, the pass
        chosen, both passes' mean scan fit and the reason.
    overruled : list of dict
        One per stretch where only one pass is localized but the other
        pass's estimate fits the scans clearly better: first and last scan,
        the pass overruled, both mean scan fits. Those scans are not localized.
    agree_distance, agree_heading : float
        The agreement thresholds (metres, radians).
    from_backward : ndarray (T,) of bool
        Scans whose estimate is the backward pass's alone.
    """

    passes: NDArray[np.str_]
    source: NDArray[np.str_]
    forward: RunTrace
    backward: RunTrace
    disagreements: list = field(default_factory=list)
    overruled: list = field(default_factory=list)
    agree_distance: float = 0.5
    agree_heading: float = float(np.radians(10.0))
    from_backward: NDArray[np.bool_] | None = None


    def summary(self) -> dict:
        """The ``smooth`` section of ``summary.json``: which passes agree, where, and how disagreements were settled."""
        n = len(self)
        counts = {p: int(np.sum(self.passes == p)) for p in PASSES}
        both_loc = counts["both"] + counts["disagree"]
        fl = np.flatnonzero(self.forward.state == "localized")
        bl = np.flatnonzero(self.backward.state == "localized")
        return {
            "passes": counts,
            "scans_both_localized": both_loc,
            "share_agree_where_both_localized": round(counts["both"] / both_loc, 4) if both_loc else None,
            "share_localized": {"forward": round(fl.size / n, 4), "backward": round(bl.size / n, 4),
                                "smoothed": round(float(np.mean(self.state == "localized")), 4)},
            "forward_first_localized_scan": int(fl[0]) if fl.size else None,
            "backward_first_localized_scan": int(bl[0]) if bl.size else None,
            "disagreements": self.disagreements,
            "overruled": self.overruled,
            "agree_distance_m": self.agree_distance,
            "agree_heading_deg": round(float(np.degrees(self.agree_heading)), 3),
            "meaning": ("passes per scan -- both: forward and backward pass localized and within agree_distance_m "
                        "and agree_heading_deg (estimate: their mean weighted by the spreads); disagree: both "
                        "localized, apart (the pass whose estimates fit the scans better over the stretch wins); "
                        "forward / backward: only that pass localized; none: neither (state searching or lost)"),
        }


def combine(forward: RunTrace, backward: RunTrace, fit: Callable[[NDArray, NDArray], NDArray] | None = None, *,
            agree_distance: float = 0.5, agree_heading: float = float(np.radians(10.0)),
            odometry: NDArray | None = None, window: int = 10, min_z: float = 2.0,
            min_gain: float = 0.01) -> Smoothed:
    """Combine a forward and a backward pass, both in the log's scan order, scan by scan.

    Parameters
    ----------
    forward, backward : RunTrace
        The passes (the backward one turned into scan order by :func:`reverse_trace`).
    fit : callable ``fit(poses, scans) -> (n,)``, optional
        Scan fit of a pose at a scan (:func:`scan_fit_function`) to settle
        disagreements; without it, the pass localized longer wins. A pass
        still *searching* at a scan (never localized so far in its own time
        direction) is never compared there: its estimate is the best of a
        fresh cloud on the few scans it has seen, and fits them by selection.
    agree_distance, agree_heading : float
        Two localized estimates closer than this (metres, radians) agree.
    odometry : array_like (T, 3), optional
        The log's odometry poses. With them, the ``window`` scans either side of
        a stretch compare the two places carried on by the odometry from the
        stretch's ends (a pass not yet localized there is not held against its
        place), and a losing pass is distrusted only while it follows its place
        (until its estimate jumps against the odometry by more than
        ``agree_distance``).
    window : int
        With ``odometry``, the stretch of disagreeing scans is compared on this
        many scans either side too (without, on the stretch alone).
    min_z, min_gain : float
        A pass wins when the mean per-scan difference of the scan fits is at
        least ``min_z`` standard errors (a paired test over the compared scans)
        and at least ``min_gain``; else the stretch is *ambiguous*.

    Examples
    --------
    A pass of the doctests' toy filter (``toy_mcl``: particles on a line, a
    GPS that reads x = 5 m at every step):

    >>> from localize.runloop import run_filter
    >>> f = run_filter(toy_mcl(), 10, lambda k: None, lambda k: (5.0,))
    >>> [str(v) for v in f.state[:2]]                # a pass needs a few scans to localize
    ['searching', 'searching']
    >>> from dataclasses import replace
    >>> b = replace(f, state=np.full(10, "localized"))  # as if a backward pass had been localized throughout
    >>> s = combine(f, b)
    >>> [str(v) for v in s.passes[:2]], str(s.state[0]), s.first_localized()
    (['backward', 'backward'], 'localized', 0)
    """
    odo = _check_passes(forward, backward, odometry)
    d_max = check_positive(agree_distance, "agree_distance", "m")
    a_max = check_positive(agree_heading, "agree_heading", "rad")
    window = check_count(window, "window", minimum=0)
    test = _PairedTest(check_nonnegative(min_z, "min_z"), check_nonnegative(min_gain, "min_gain"))
    agree, passes = _classify(forward, backward, d_max, a_max)
    source = np.where(passes == "disagree", "", passes).astype("<U8")
    t = len(forward)
    ambiguous = np.zeros(t, dtype=bool)
    distrusted = np.zeros(t, dtype=bool)
    disagreements = [_settle(forward, backward, (a, b), fit, odo, window, test, passes, source, ambiguous,
                             distrusted, d_max) for a, b in _intervals(passes == "disagree")]
    overruled = [] if fit is None else _overrule(forward, backward, fit, test, passes, source, distrusted)
    take_b = (source == "backward") | _backward_where_none(forward, backward, fit, source)
    poses, stds, spread = _estimates(forward, backward, take_b, agree)
    loc = (source != "none") & ~ambiguous & ~distrusted
    state = np.where(loc, "localized", "searching").astype("<U9")
    seen = np.cumsum(loc) > 0
    state[~loc & seen] = "lost"
    return Smoothed(poses=poses, stds=stds, spread=spread, state=state, passes=passes, source=source,
                    forward=forward, backward=backward, disagreements=disagreements, overruled=overruled,
                    agree_distance=float(d_max),
                    agree_heading=float(a_max), from_backward=take_b & ~agree)


def _check_passes(forward: RunTrace, backward: RunTrace, odometry: NDArray | None) -> NDArray | None:
    """Check that the passes are traces of one log; the odometry as a float array (or None)."""
    for name, tr in (("forward", forward), ("backward", backward)):
        if not isinstance(tr, RunTrace):
            raise TypeError(f"{name} must be a localize.runloop.RunTrace (what run_filter returns); got "
                            f"{type(tr).__name__}")
    if len(forward) != len(backward):
        raise ValueError(f"the passes cover different logs: forward has {len(forward)} scans, backward "
                         f"{len(backward)} (reverse the backward pass's trace with reverse_trace)")
    if odometry is None:
        return None
    odo = np.asarray(odometry, dtype=float)
    if odo.shape != (len(forward), 3):
        raise ValueError(f"odometry must have shape ({len(forward)}, 3), one pose per scan; got {odo.shape}")
    return odo


def _classify(forward: RunTrace, backward: RunTrace, d_max: float, a_max: float) -> tuple[NDArray, NDArray]:
    """``(agree, passes)``: where both passes are localized and close, and the ``passes`` label of each scan."""
    fl, bl = forward.state == "localized", backward.state == "localized"
    pf, pb = forward.poses, backward.poses
    dist = np.hypot(pf[:, 0] - pb[:, 0], pf[:, 1] - pb[:, 1])
    dth = np.abs(angle_diff(pf[:, 2], pb[:, 2]))
    agree = fl & bl & (dist <= d_max) & (dth <= a_max)
    passes = np.full(len(forward), "none", dtype="<U8")
    passes[fl & ~bl] = "forward"
    passes[bl & ~fl] = "backward"
    passes[fl & bl] = "disagree"
    passes[agree] = "both"
    return agree, passes


@dataclass(frozen=True)
class _PairedTest:
    """A pass wins when the mean per-scan gain in scan fit is at least ``min_z`` standard errors and ``min_gain``."""

    min_z: float
    min_gain: float

    def wins(self, mean: float, z: float, two_sided: bool = True) -> bool:
        if two_sided:
            return abs(z) >= self.min_z and abs(mean) >= self.min_gain
        return mean >= self.min_gain and z >= self.min_z


def _settle(forward: RunTrace, backward: RunTrace, stretch: tuple[int, int], fit: Callable | None,
            odo: NDArray | None, window: int, test: _PairedTest, passes: NDArray, source: NDArray,
            ambiguous: NDArray, distrusted: NDArray, d_max: float) -> dict:
    """Settle one stretch of ``disagree`` scans (``source``, ``ambiguous``, ``distrusted`` are set); its row."""
    a, b = stretch
    scans = np.arange(a, b + 1)
    row: dict[str, Any] = {"scans": [a, b]}
    verdict = None if fit is None else _compare_stretch(forward.poses, backward.poses, fit, odo, a, b, window,
                                                        test, row)
    if verdict is not None:
        chosen, why = verdict, "its estimates fit the scans better"
    else:
        # a tie: the scans cannot tell the two places apart. The pass localized longer going into the stretch
        # gives the estimate (forward counts back from a, backward on from b), but the state is not localized
        run_f = _run_length((forward.state == "localized")[:a + 1][::-1])
        run_b = _run_length((backward.state == "localized")[b:])
        chosen = "forward" if run_f >= run_b else "backward"
        why = ("ambiguous: the scans fit both places equally well (state not localized here); the estimate is "
               "that of the pass localized longer going into the stretch")
        ambiguous[scans] = True
    row.update(chosen=chosen, reason=why)
    source[scans] = chosen
    if verdict is not None:
        alone = _loser_alone(forward, backward, verdict, a, b, odo, passes, d_max)
        if alone.size:
            source[alone] = verdict
            distrusted[alone] = True
            t = len(passes)
            row["distrusted_scans"] = [[int(x), int(y)] for x, y in _intervals(np.isin(np.arange(t), alone))]
    return row


def _compare_stretch(pf: NDArray, pb: NDArray, fit: Callable, odo: NDArray | None, a: int, b: int, window: int,
                     test: _PairedTest, row: dict) -> str | None:
    """The pass whose estimates fit the scans of the stretch ``a..b`` clearly better (None: a tie); ``row`` gets
    the compared scans, both mean fits and the z-score."""
    t = len(pf)
    # the two trajectories compared on the scans of the stretch and `window` scans either side (where a
    # pass's look-alike place shows itself, the other pass may not be localized yet)
    if odo is not None:
        # beyond the stretch, each pass's place is carried on by the odometry from the stretch's ends
        # (a pass still searching there is not held against its place)
        near = np.arange(max(a - window, 0), min(b + window, t - 1) + 1)
        hf, hb = _continue(pf, odo, near, a, b), _continue(pb, odo, near, a, b)
    else:                     # without odometry, only the stretch itself compares like with like
        near = np.arange(a, b + 1)
        hf, hb = pf[near], pb[near]
    ff, fb = fit(hf, near), fit(hb, near)
    ok = np.isfinite(ff) & np.isfinite(fb)
    d = fb[ok] - ff[ok]
    row.update(compared_scans=[int(near[0]), int(near[-1])], fit_forward=_round(np.mean(ff[ok]) if ok.any()
                                                                                 else np.nan),
               fit_backward=_round(np.mean(fb[ok]) if ok.any() else np.nan))
    if d.size < 2:
        return None
    mean, z = _paired_z(d)
    row["fit_z"] = _z_shown(z)
    if test.wins(mean, z):
        return "backward" if mean > 0 else "forward"
    return None


def _loser_alone(forward: RunTrace, backward: RunTrace, verdict: str, a: int, b: int, odo: NDArray | None,
                 passes: NDArray, d_max: float) -> NDArray:
    """The scans next to the stretch ``a..b`` where the losing pass alone is localized, following its place.

    The losing pass followed a wrong place through the whole of its localized stretch: it is not trusted
    where it alone is localized on that stretch (the winner's estimate is used, not localized). A scan where
    both agree ends it; with odometry, so does a jump against the odometry (a new hypothesis).
    """
    loser = "forward" if verdict == "backward" else "backward"
    lp = forward.poses if verdict == "backward" else backward.poses
    only = passes == loser
    lo_, hi_ = a - _run_length(only[:a][::-1]), b + _run_length(only[b + 1:])
    if odo is not None:
        jump = _jumps(lp, odo, d_max)
        lo_ = a - _run_length(~jump[lo_ + 1:a + 1][::-1])
        hi_ = b + _run_length(~jump[b + 1:hi_ + 1])
    return np.concatenate([np.arange(lo_, a), np.arange(b + 1, hi_ + 1)]).astype(int)


def _overrule(forward: RunTrace, backward: RunTrace, fit: Callable, test: _PairedTest, passes: NDArray,
              source: NDArray, distrusted: NDArray) -> list[dict]:
    """Stretches where a pass localized alone is overruled (``source`` and ``distrusted`` are set); their rows.

    A pass localized alone where the other pass's estimate, not localized, fits the scans clearly better (by
    the same paired test): the lone pass may have settled on a look-alike place, e.g. after a restart, while the
    other one's cloud already leans to the right place. No claim there; the better estimate.
    """
    overruled = []
    pf, pb = forward.poses, backward.poses
    for who, other in (("forward", "backward"), ("backward", "forward")):
        mine_p, other_p = (pf, pb) if who == "forward" else (pb, pf)
        # a pass still searching (never localized so far in its own time direction) has no place to offer:
        # its estimate is the best of a fresh cloud on the few scans it has seen, and fits them by selection
        other_searching = (backward if who == "forward" else forward).state == "searching"
        for a, b in _intervals((passes == who) & ~distrusted & ~other_searching):
            scans = np.arange(a, b + 1)
            fm, fo = fit(mine_p[scans], scans), fit(other_p[scans], scans)
            ok = np.isfinite(fm) & np.isfinite(fo)
            d = fo[ok] - fm[ok]
            if d.size < 2:
                continue
            mean, z = _paired_z(d)
            if test.wins(mean, z, two_sided=False):
                distrusted[scans] = True
                source[scans] = other
                overruled.append({"scans": [a, b], "pass": who, f"fit_{who}": _round(np.mean(fm[ok])),
                                  f"fit_{other}": _round(np.mean(fo[ok])), "fit_z": _z_shown(z)})
    return overruled


def _backward_where_none(forward: RunTrace, backward: RunTrace, fit: Callable | None, source: NDArray) -> NDArray:
    """Scans localized by neither pass whose estimate is the backward pass's.

    The estimate of the pass localized more recently in its own time direction (forward: last localized scan
    before, backward: first one after), whose place is the fresher -- unless the scans say otherwise: the
    estimate that fits the scans better over 5 neighbouring scans.
    """
    t = len(forward)
    fl, bl = forward.state == "localized", backward.state == "localized"
    idx = np.arange(t)
    since_f = idx - np.maximum.accumulate(np.where(fl, idx, -np.inf))          # inf: never localized so far
    until_b = np.minimum.accumulate(np.where(bl, idx, np.inf)[::-1])[::-1] - idx
    none = source == "none"
    b_none = none & (until_b < since_f)
    if fit is None or not none.any():
        return b_none
    ks = np.flatnonzero(none)
    diff = np.zeros(t)
    with np.errstate(invalid="ignore"):
        dk = fit(backward.poses[ks], ks) - fit(forward.poses[ks], ks)
    # ... between places only: a pass still searching there is not compared (see _overrule)
    dk[(forward.state[ks] == "searching") | (backward.state[ks] == "searching")] = np.nan
    diff[ks] = np.where(np.isfinite(dk), dk, 0.0)
    for a, b in _intervals(none):
        seg = diff[a:b + 1]
        c = np.concatenate([[0.0], np.cumsum(seg)])
        i = np.arange(seg.size)
        sm = c[np.minimum(i + 3, seg.size)] - c[np.maximum(i - 2, 0)]       # sum over scans i-2 .. i+2
        decided = np.abs(sm) > 1e-9
        b_none[a:b + 1] = np.where(decided, sm > 0, b_none[a:b + 1])
    f_search, b_search = forward.state == "searching", backward.state == "searching"
    b_none[none & b_search & ~f_search] = False     # the scans never choose a place a pass has not found yet
    b_none[none & f_search & ~b_search] = True
    return b_none


def _estimates(forward: RunTrace, backward: RunTrace, take_b: NDArray, agree: NDArray
               ) -> tuple[NDArray, NDArray, NDArray]:
    """``(poses, stds, spread)``: the backward pass's where ``take_b``, the forward pass's elsewhere, and where
    both agree their mean weighted by the inverse squared spreads (headings: :func:`~localize.geometry.circular_mean`)."""
    pf, pb = forward.poses, backward.poses
    poses = np.array(pf, dtype=float, copy=True)
    stds = np.array(forward.stds, dtype=float, copy=True)
    spread = np.array(forward.spread, dtype=float, copy=True)
    poses[take_b], stds[take_b], spread[take_b] = pb[take_b], backward.stds[take_b], backward.spread[take_b]
    if agree.any():
        sf = np.maximum(np.nan_to_num(forward.spread[agree], nan=1.0), 0.01)
        sb = np.maximum(np.nan_to_num(backward.spread[agree], nan=1.0), 0.01)
        wf, wb = 1.0 / sf ** 2, 1.0 / sb ** 2
        wsum = wf + wb
        xy = (pf[agree, :2] * wf[:, None] + pb[agree, :2] * wb[:, None]) / wsum[:, None]
        th = circular_mean(np.stack([pf[agree, 2], pb[agree, 2]], axis=-1), np.stack([wf, wb], axis=-1))
        poses[agree, :2], poses[agree, 2] = xy, th
        spread[agree] = 1.0 / np.sqrt(wsum)
        with np.errstate(divide="ignore"):
            vf = np.maximum(forward.stds[agree] ** 2, 1e-12)
            vb = np.maximum(backward.stds[agree] ** 2, 1e-12)
        stds[agree] = np.sqrt(1.0 / (1.0 / vf + 1.0 / vb))
    return poses, stds, spread


def _continue(p: NDArray, odo: NDArray, scans: NDArray, a: int, b: int) -> NDArray:
    """``p`` on ``scans``, with the scans before ``a`` / after ``b`` dead-reckoned from ``p[a]`` / ``p[b]``."""
    out = np.array(p[scans], dtype=float, copy=True)
    before, after = scans < a, scans > b
    if before.any():
        out[before] = compose(p[a], relative(odo[a], odo[scans[before]]))
    if after.any():
        out[after] = compose(p[b], relative(odo[b], odo[scans[after]]))
    return out


def _jumps(p: NDArray, odo: NDArray, tol: float) -> NDArray[np.bool_]:
    """``jump[k]``: the estimate moved from scan k-1 to k more than ``tol`` metres away from what the odometry says."""
    t = len(p)
    jump = np.zeros(t, dtype=bool)
    if t > 1:
        pred = compose(p[:-1], relative(odo[:-1], odo[1:]))
        with np.errstate(invalid="ignore"):
            jump[1:] = ~(np.hypot(*(p[1:, :2] - pred[:, :2]).T) <= tol)
    return jump


def _paired_z(d: NDArray) -> tuple[float, float]:
    """Mean of the paired differences ``d`` (at least two) and its z-score (mean over standard error; +-inf when
    the differences are all equal and not 0, 0 when all are 0)."""
    se = float(np.std(d, ddof=1) / np.sqrt(d.size))
    mean = float(np.mean(d))
    return mean, (mean / se if se > 0 else (np.inf * np.sign(mean) if mean else 0.0))


def _z_shown(z: float) -> float:
    """A z-score as summary.json shows it: 2 decimals, +-99 for an infinite one."""
    return _round(z, 2) if np.isfinite(z) else (99.0 if z > 0 else -99.0)


def _run_length(mask: NDArray[np.bool_]) -> int:
    """Number of leading True values."""
    m = np.asarray(mask, dtype=bool)
    stop = np.flatnonzero(~m)
    return int(stop[0]) if stop.size else int(m.size)


def _verdict(d: dict) -> str:
    other = "forward" if d["chosen"] == "backward" else "backward"
    if d["reason"].startswith("ambiguous"):
        return "ambiguous: the scans fit both, not localized there"
    if d.get("fit_forward") is None or d.get("fit_backward") is None:
        return f"{d['chosen']} taken"
    return f"{d['chosen']} taken: scan fit {d['fit_' + d['chosen']]:.2f} vs {d['fit_' + other]:.2f}"


def _round(v: float, digits: int = 3) -> float | None:
    return round(float(v), digits) if np.isfinite(v) else None


def smoothed_trace(s: Smoothed) -> RunTrace:
    """The combined trajectory as a :class:`~localize.runloop.RunTrace` (for the CLI's outputs and ``state`` summary).

    Per-scan evidence the combination does not redefine (``n_valid``,
    ``degenerate``, ...) is the forward pass's; events are the forward pass's
    (without its state changes), the backward pass's recoveries (marked
    "backward pass:"), and the state changes of the combined trajectory.
    ``means``, ``n_eff``, ``p_localized`` and ``p_place`` are those of the pass
    the scan's estimate is taken from (``source``; forward where both agree):
    the combined state is the combination's rule above, not derived from them.
    """
    fw, bw = s.forward, s.backward
    events = [(k, t) for k, t in fw.events if not t.startswith("state ")]
    events += [(k, "backward pass: " + t) for k, t in bw.events
               if not t.startswith("state ") and "odometry" not in t]      # the same odometry records as forward's
    prev = "searching"
    for k, cur in enumerate(s.state):
        if cur != prev:
            events.append((k, f"state {prev} -> {cur}"))
        prev = str(cur)
    events.sort(key=lambda e: e[0])
    pick_b = s.source == "backward" if s.from_backward is None else s.from_backward
    means = np.where(pick_b[:, None], bw.means, fw.means)
    n_eff = np.where(pick_b, bw.n_eff, fw.n_eff)
    # p_localized and p_place: the pass the row's estimate comes from says how sure it was (the state is the
    # combination's, not derived from them)
    probs = {name: np.where(pick_b, getattr(bw, name), getattr(fw, name)) for name in ("p_localized", "p_place")
             if getattr(fw, name) is not None and getattr(bw, name) is not None}
    return replace(fw, poses=s.poses, means=means, stds=s.stds, spread=s.spread, n_eff=n_eff, state=s.state,
                   **probs, events=events, beam_evaluations=fw.beam_evaluations + bw.beam_evaluations,
                   seconds=fw.seconds + bw.seconds)


@dataclass
class SmoothResult(RunResult):
    """:class:`localize.pipeline.RunResult` of a smoothed run (see :func:`smooth_log`): the combined trajectory.

    ``smooth`` is the :class:`Smoothed` record, ``columns`` the extra per-scan
    columns of ``trajectory.csv`` (``passes``, ``source``), ``forward`` and
    ``backward`` the two passes' own results (the backward one in reversed
    scan order, as it ran); ``seconds`` is the two filtering loops' time,
    ``seconds_combine`` that of the combination.
    """

    smooth: Any = None
    columns: dict = field(default_factory=dict)
    forward: Any = None
    backward: Any = None
    seconds_combine: float = 0.0


class _Offset:
    """A progress bar adapter: the second pass continues where the first stopped."""

    def __init__(self, progress: Any, offset: int) -> None:
        self.progress, self.offset = progress, offset

    def update_to(self, done: int) -> None:
        self.progress.update_to(self.offset + done)


def smooth_log(grid: OccupancyGrid, log, rng: np.random.Generator, *, settings: RunSettings | None = None,
               progress: Any = None, agree_distance: float = 0.5, agree_heading: float = float(np.radians(10.0)),
               fit_distance: float | None = None, snapshot_every: int = 0, **changes: Any):
    """Localize a recorded log forwards and backwards and combine the passes (``localize run --smooth``).

    Both passes are :func:`localize.pipeline.localize_log` with the same
    ``settings`` (:class:`~localize.settings.RunSettings`, with ``changes`` by
    keyword: ``particles``, ``sensor``, ``alphas``, ...), the backward one on
    :func:`reverse_log`; they share ``rng`` (forward first), so a seed
    reproduces the result. ``fit_distance`` (default twice the sensor's
    ``sigma_hit``) is the scan-fit tolerance that settles disagreements.

    Returns
    -------
    localize.pipeline.RunResult
        The combined trajectory (``estimates``, ``state``, ``trace`` as for one
        pass), with ``smooth`` (the :class:`Smoothed` record) and ``columns``
        (the per-scan ``passes`` and ``source`` columns of ``trajectory.csv``).
        Snapshots (animation frames) are the forward pass's.
    """
    if not isinstance(grid, OccupancyGrid):
        raise TypeError(f"grid must be an OccupancyGrid; got {type(grid).__name__}")
    if len(log) < 2:
        raise ValueError(f"--smooth needs a log of at least 2 scans to run backwards; this one has {len(log)}")
    check_positive(agree_distance, "agree_distance", "m")
    check_positive(agree_heading, "agree_heading", "rad")
    s = settings_with(settings, **changes)
    n = len(log)
    if progress is not None and hasattr(progress, "total"):
        progress.total = 2 * n
    # the odometry's signs are checked once, on the log as recorded (played backwards, every step of an
    # odometry without a sign reads as reversing); both passes then trust the corrected log
    log = run_max_range(log, s)
    log, sign_check = check_log_odometry(log, s.odometry_sign, min_range=s.min_range)
    s = replace(s, odometry_sign="trust")
    fw = localize_log(grid, log, s, rng=rng, progress=progress, snapshot_every=snapshot_every)
    bw = localize_log(grid, reverse_log(log), s, rng=rng, progress=None if progress is None else _Offset(progress, n))
    t0 = time.perf_counter()
    if fit_distance is None:
        fit_distance = 2.0 * s.sigma_hit
    fit = scan_fit_function(grid, log, fit_distance, min_range=float(s.min_range or 0.0), max_range=s.max_range)
    sm = combine(fw.trace, reverse_trace(bw.trace), fit, odometry=log.odometry, agree_distance=agree_distance,
                 agree_heading=agree_heading)
    return SmoothResult(times=fw.times, trace=smoothed_trace(sm), odometry_check=sign_check, smooth=sm,
                        columns={"passes": sm.passes, "source": sm.source}, forward=fw, backward=bw,
                        seconds_combine=time.perf_counter() - t0)


def headline(summary: dict) -> str:
    """The terminal's line on the two passes, from the ``smooth`` section of ``summary.json``.

    Examples
    --------
    >>> headline({"passes": {"both": 90, "disagree": 10, "forward": 0, "backward": 30, "none": 0},
    ...           "scans_both_localized": 100, "share_agree_where_both_localized": 0.9,
    ...           "forward_first_localized_scan": 30, "backward_first_localized_scan": 0,
    ...           "disagreements": [{"scans": [50, 59], "chosen": "backward", "fit_forward": 0.31,
    ...                              "fit_backward": 0.74, "reason": "..."}]})
    'forward and backward pass agree on 90% of the 100 scans where both are localized; forward pass localized from scan 30, backward pass from scan 0; they disagree on scans 50-59 (backward taken: scan fit 0.74 vs 0.31)'
    """
    p = summary["passes"]
    both = summary["scans_both_localized"]
    parts = []
    if both:
        parts.append(f"forward and backward pass agree on {100 * summary['share_agree_where_both_localized']:.0f}% "
                     f"of the {both} scans where both are localized")
    else:
        parts.append("forward and backward pass are never localized at the same scan")
    kf, kb = summary["forward_first_localized_scan"], summary["backward_first_localized_scan"]
    parts.append(("forward pass localized from scan " + str(kf) if kf is not None else "forward pass never localized")
                 + (", backward pass from scan " + str(kb) if kb is not None else ", backward pass never localized"))
    if summary["disagreements"]:
        shown = summary["disagreements"][:3]
        text = ", ".join(f"{d['scans'][0]}-{d['scans'][1]} ({_verdict(d)})" for d in shown)
        more = len(summary["disagreements"]) - len(shown)
        parts.append(f"they disagree on scans {text}" + (f" and {more} more stretches" if more > 0 else ""))
    over = summary.get("overruled") or []
    if over:
        text = ", ".join(f"{o['scans'][0]}-{o['scans'][1]} ({o['pass']})" for o in over[:3])
        parts.append(f"a pass localized alone is overruled on scans {text}" +
                     (f" and {len(over) - 3} more stretches" if len(over) > 3 else "") +
                     ": the other pass's estimate fits the scans better (not localized there)")
    if p.get("none"):
        parts.append(f"{p['none']} scans localized by neither pass")
    return "; ".join(parts)
