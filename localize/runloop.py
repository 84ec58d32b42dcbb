"""Running a particle filter over a log: the core loop, its record, and the run driver that assembles them.

:func:`run` is the loop of *Probabilistic Robotics* table 8.2 (Thrun, Burgard
and Fox 2005) as it runs on a real robot's log: at each step the particles
move by the odometry, are weighted by the scan, the belief is summarised, and
the set is resampled. Everything else a real log needs -- a corrupt odometry
record, a robot standing still, beams the map cannot explain, a filter that
lost the robot -- is a policy of :mod:`localize.policies`, consulted at one
named point of the loop. A :class:`Recorder` observes the steps and makes the
:class:`RunTrace`.

:func:`run_filter` assembles the default policies from plain arguments (what
the command line, the book and :func:`run_mcl` call); ``run(mcl, n, control,
scan)`` with no policies is the bare loop, bit for bit a loop of
:meth:`localize.mcl.MCL.step`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .estimate import Estimate
from .geometry import compose
from .grid import OccupancyGrid
from .motion import OdometryMotion, odometry_pair
from .policies import (
    BeamMasks,
    Context,
    Expansion,
    MapEvidence,
    MotionGate,
    OdometryCheck,
    Redraw,
    Restart,
    SensorReset,
    StateRules,
    Step,
    ThresholdState,
    is_scan,
)
from .reliability import ReliabilityState, floor_text

__all__ = ["run", "Policies", "Recorder", "RunTrace", "StateTrack", "MCLTrace", "run_filter", "run_mcl",
           "default_policies"]


# --------------------------------------------------------------------------- what a run returns
@dataclass(frozen=True, eq=False, kw_only=True)
class StateTrack:
    """The estimate and the state at every step of a run, and what they answer.

    Shared by :class:`RunTrace` (one filter run) and
    :class:`localize.smooth.Smoothed` (two passes combined); its fields are
    given by keyword.

    Attributes
    ----------
    poses : ndarray (T, 3)
        The estimate at each step.
    stds : ndarray (T, 3)
        Spread of the particles behind it: standard deviations in x and y (m)
        and the circular standard deviation of the heading (rad).
    spread : ndarray (T,)
        Position spread of the best cluster (m).
    state : ndarray (T,) of str
        ``searching``, ``localized`` or ``lost`` (see :class:`~localize.policies.StateRules`).
    """

    poses: NDArray[np.float64]
    stds: NDArray[np.float64]
    spread: NDArray[np.float64]
    state: NDArray[np.str_]

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    def first_localized(self) -> int | None:
        """First step whose state is ``localized`` (None if never)."""
        k = np.flatnonzero(self.state == "localized")
        return int(k[0]) if k.size else None

    def lost_intervals(self) -> list[tuple[int, int]]:
        """``[(first, last), ...]`` steps of each stretch in state ``lost``."""
        return _intervals(self.state == "lost")


@dataclass(frozen=True, eq=False, kw_only=True)
class RunTrace(StateTrack):
    """What :func:`run_filter` did at every step (one row per scan); built by keyword.

    Attributes
    ----------
    poses, means, stds : ndarray (T, 3)
        Estimate (mean of the best cluster), weighted mean and spread of all particles.
    spread : ndarray (T,)
        Position spread of the best cluster (m).
    best_weight, n_eff : ndarray (T,)
    n_particles, n_injected : ndarray (T,) of int
    p_inject : ndarray (T,)
    updated, resampled, degenerate : ndarray (T,) of bool
        Whether the step used its scan, resampled, and whether every particle got zero likelihood.
    n_valid : ndarray (T,) of int
        Valid readings of the scan (inside the sensor's range limits; range scans only).
    fit : ndarray (T,)
        Share of valid beams that fit the map at the estimate (NaN when not assessed).
    on_map : ndarray (T,)
        Weight share of particles in the map's free space (NaN without a map).
    state : ndarray (T,) of str
        ``searching``, ``localized`` or ``lost`` (see :class:`~localize.policies.StateRules`).
    events : list of (int, str)
        Special events: rejected odometry, re-drawn particles, state changes.
    beam_evaluations : int
        Particle x beam likelihood evaluations (the run's machine-independent cost).
    seconds : float
        Wall time of the filtering loop.
    snapshots : dict[int, tuple[ndarray, ndarray]]
        ``step -> (particles, weights)`` after the update of that step.
    cov : ndarray (T, 3, 3), optional
        Weighted covariance of the best cluster behind each estimate
        (:attr:`localize.estimate.Estimate.cluster_cov`).
    p_localized : ndarray (T,), optional
        The probability that the estimate is within a metre of the robot
        (:class:`localize.reliability.ReliabilityState`; NaN for a run whose state comes from
        :class:`~localize.policies.ThresholdState`, e.g. without a map).
    p_place : ndarray (T,), optional
        The most ``p_localized`` could be with a sure fit belief, the place part's root
        (:attr:`localize.reliability.ReliabilityState.place_limit`; NaN as ``p_localized``). A
        localized filter turns lost when it falls below ``localized_at``: with ``p_localized``, the
        state is a function of the two columns.
    """

    means: NDArray[np.float64]
    best_weight: NDArray[np.float64]
    n_eff: NDArray[np.float64]
    n_particles: NDArray[np.int64]
    n_injected: NDArray[np.int64]
    p_inject: NDArray[np.float64]
    updated: NDArray[np.bool_]
    resampled: NDArray[np.bool_]
    degenerate: NDArray[np.bool_]
    n_valid: NDArray[np.int64]
    fit: NDArray[np.float64]
    on_map: NDArray[np.float64]
    events: list
    beam_evaluations: int
    seconds: float
    snapshots: dict = field(default_factory=dict)
    cov: NDArray[np.float64] | None = None
    p_localized: NDArray[np.float64] | None = None
    p_place: NDArray[np.float64] | None = None


    def state_summary(self) -> dict:
        """The per-run account: first localized step, lost intervals, final state, share of time localized.

        Examples
        --------
        See :func:`run_filter`.
        """
        n = len(self)
        return {
            "first_localized_scan": self.first_localized(),
            "lost_intervals": [list(iv) for iv in self.lost_intervals()],
            "final_state": str(self.state[-1]) if n else "searching",
            "share_localized": round(float(np.mean(self.state == "localized")), 4) if n else 0.0,
            "scans_without_valid_readings": int(np.sum(self.n_valid == 0)),
            "degenerate_updates": int(self.degenerate.sum()),
            "events": [[int(k), str(t)] for k, t in self.events],
            **self._p_summary(),
        }

    def _p_summary(self) -> dict:
        p = self.p_localized
        if p is None or len(p) == 0 or not np.all(np.isfinite(p)):
            return {}
        # the final values rounded down, as trajectory.csv writes them: they compare with the thresholds as the run's
        out = {"final_p_localized": float(floor_text(p[-1], 4)), "mean_p_localized": round(float(np.mean(p)), 4)}
        if self.p_place is not None and len(self.p_place) == len(p) and np.isfinite(self.p_place[-1]):
            out["final_p_place"] = float(floor_text(self.p_place[-1], 4))
        return out


#: The old name of :class:`RunTrace` (what :func:`run_mcl` returned before the run driver was one).
MCLTrace = RunTrace


def _intervals(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.diff(m.astype(np.int8))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return [(int(a), int(b)) for a, b in zip(starts, stops)]


# --------------------------------------------------------------------------- the policies, together
@dataclass(eq=False)
class Policies:
    """The policies a run is given, and the order in which the core loop consults them.

    Every field is optional: ``Policies()`` (no policy) leaves the plain
    filter loop, bit for bit what :meth:`localize.mcl.MCL.step` does at each step.
    See :mod:`localize.policies` for what each one does.
    """

    rules: StateRules = field(default_factory=StateRules)
    odometry: OdometryCheck | None = None
    gate: MotionGate | None = None
    beams: BeamMasks | None = None
    evidence: MapEvidence | None = None
    soft_once_agreed: bool = False
    expansion: Expansion | None = None
    restart: Restart | None = None
    redraw: Redraw | None = None
    reset: SensorReset | None = None
    state: ThresholdState | ReliabilityState | None = None
    ctx: Context = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.ctx is None:
            self.ctx = Context(self.rules)

    @property
    def events(self) -> list:
        """What the policies did: ``[(step, text), ...]``."""
        return self.ctx.events

    def admit(self, step: Step, u: Any) -> Any:
        """The control to move with (None: do not move)."""
        step.pair = odometry_pair(u) if u is not None else None
        if self.odometry is not None:
            u = self.odometry.admit(step, u, self.ctx)
        step.u = u
        return u

    def measurement(self, step: Step, mcl: Any, z: Any) -> Any:
        """The measurement to weight the particles with (None: no update this step)."""
        if is_scan(z):
            ranges, angles = np.asarray(z[0], dtype=float), np.asarray(z[1], dtype=float)
            lo_r = float(getattr(mcl.sensor, "min_range", 0.0) or 0.0)
            hi_r = float(getattr(mcl.sensor, "max_range", np.inf))
            valid = np.isfinite(ranges) & (ranges > lo_r) & (ranges < hi_r)
            step.scan, step.n_valid = (ranges, angles, valid), int(valid.sum())
        if z is not None and self.gate is not None and not self.gate.admits(step):
            z = None
        if z is not None and self.beams is not None and self.ctx.agreed and is_scan(z):
            z = self.beams.apply(mcl, z)
        if z is not None and self.gate is not None:
            self.gate.used()
        step.z = z
        return z

    def update_options(self) -> dict:
        """Keyword arguments of this step's :meth:`~localize.mcl.MCL.update`."""
        if not self.soft_once_agreed:
            return {}
        self.ctx.soft = self.ctx.agreed         # a finite price for obstacles only once the cloud agrees
        return {"soft_obstacles": self.ctx.soft}

    def estimate(self, step: Step, mcl: Any) -> Estimate:
        """The belief summarised (the favoured place while a restart is on probation)."""
        step.cloud = (mcl.particles, mcl.log_weights)
        step.n_eff = mcl.status.n_eff
        step.degenerate = bool(step.updated and mcl.status.degenerate)
        e = mcl.estimate()
        if self.ctx.probation is not None:
            e = self.ctx.probation.estimate(mcl, e)
        step.estimate = e
        step.pose = e.pose if np.all(np.isfinite(e.pose)) else e.mean
        return e

    def assess(self, step: Step, mcl: Any) -> None:
        """The evidence of this step, and what it changes: the fit window, the restart counts, an expansion."""
        ctx = self.ctx
        if self.evidence is not None:
            self.evidence.assess(step, mcl, ctx)
        step.agreed = ctx.agreed = self.rules.agreed(step.estimate)
        gathered = ctx.state == "searching" and self.rules.gathered(step.estimate)
        if step.updated and np.isfinite(step.fit):
            ctx.fits.add(step.fit)
        if isinstance(self.state, ReliabilityState):
            step.p_localized = self.state.p_localized(step)      # "am I localized?": the evidence, weighed
        if self.reset is not None:
            self.reset.propose(step)                             # sensor resetting: in doubt, look where z fits
        if self.restart is not None and self.evidence is not None:
            self.restart.count(step, ctx, self.evidence, gathered)
        if self.expansion is not None and self.evidence is not None:
            self.expansion.apply(step, mcl, self.evidence)
        if ctx.probation is not None and step.updated and not step.degenerate:
            ctx.probation.updates += 1

    def intervene(self, step: Step, mcl: Any) -> bool:
        """A restart, a redraw or a probation's own resampling instead of the plain one; True if one happened."""
        ctx = self.ctx
        g = self.state.take_switch(ctx.probation is None) if isinstance(self.state, ReliabilityState) else None
        if g is not None:
            mcl.replace(compose(g[None], mcl.particles), mcl.log_weights)
            odds = float(np.exp(self.state.rivals.switch_log_odds))
            ctx.events.append((step.k, f"a rival place fits the scans {odds:.0f} times better than the estimate or more:"
                                       f" the cloud moves there (x' = G x, G = {np.round(g, 2).tolist()})"))
        if self.restart is not None and self.restart.due(mcl, ctx):
            self.restart.start(step, mcl, ctx, self.rules.restart_fit * self.evidence.fit_expected)
            if self.state is not None:
                self.state.interrupt(ctx)
            return True
        if self.redraw is not None and self.redraw.due(step, mcl):
            self.redraw.apply(step, mcl, ctx)
            return True
        if ctx.probation is not None:
            lost = ctx.state == "lost" and self.redraw is not None
            if not ctx.probation.resample(mcl, step.k, self.redraw.injection if lost else 0.0, ctx):
                ctx.probation = None
            return True
        return False

    def resample_anyway(self, step: Step) -> bool:
        """Resample even with enough effective particles (to inject while lost, or to reset while in doubt)."""
        return (self.redraw is not None and self.redraw.searching(step, self.ctx)) or step.reset_share > 0

    def injection(self, mcl: Any, step: Step | None = None) -> float | None:
        """The injected share at this resampling (None: the filter's own): with sensor resetting the share
        drawn from ``step.proposal`` (:class:`SensorReset`, whose importance weights are for that share),
        else random particles while lost (:class:`Redraw`)."""
        if step is not None and step.proposal is not None:
            return step.reset_share
        if self.redraw is not None and self.ctx.state == "lost" and self.redraw.injection > 0 and mcl.sampler:
            return max(mcl.injection, self.redraw.injection)
        return None

    def conclude(self, step: Step) -> str:
        """The state after this step."""
        if self.state is not None:
            self.state.update(step, self.ctx)
        self.ctx.agreed = self.ctx.agreed and self.ctx.state != "searching"
        step.state = self.ctx.state
        return step.state

    def close(self, last: int) -> None:
        """The run's totals into the events."""
        for p in (self.expansion, self.beams, self.reset):
            if p is not None:
                p.report(last, self.ctx)


# --------------------------------------------------------------------------- the core loop
def run(mcl: Any, n_steps: int, control: Callable[[int], Any], scan: Callable[[int], Any], *,
        policies: Policies | None = None, observers: Sequence[Callable[[Step, Any], None]] = ()) -> list:
    """Run a particle filter over ``n_steps`` steps: the loop of PR table 8.2, with its policies.

    ``control(k)`` is the motion into step ``k`` (not asked at step 0),
    ``scan(k)`` the measurement at step ``k`` (None: none). Each observer is
    called with the :class:`~localize.policies.Step` and the filter at the end
    of each step. Returns the policies' events ``[(step, text), ...]``.

    Examples
    --------
    >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
    >>> poses = []
    >>> events = run(f, 3, lambda k: 0.5, lambda k: (3.0 + 0.5 * k,), observers=[lambda s, m: poses.append(s.pose)])
    >>> [round(float(p[0]), 1) for p in poses], events
    ([3.0, 3.5, 4.0], [])
    """
    p = Policies() if policies is None else policies
    for k in range(int(n_steps)):
        mcl.status.clear_step()
        step = Step(k, n_particles=mcl.n)
        u = p.admit(step, control(k) if k > 0 else None)       # a corrupt odometry record is not believed
        if u is not None:
            mcl.predict(u)                                      # line 4: x_t ~ p(x_t | u_t, x_{t-1})
        z = p.measurement(step, mcl, scan(k))                   # gated by motion, beams masked; None: no update
        if z is not None:
            mcl.update(*z, **p.update_options())                # line 5: w_t = p(z_t | x_t)
        p.estimate(step, mcl)                                   # the belief summarised, before resampling
        p.assess(step, mcl)                                     # what the map says about the estimate
        if not p.intervene(step, mcl):                          # restart, redraw, probation
            if mcl.needs_resampling() or p.resample_anyway(step):
                mcl.resample(injection=p.injection(mcl, step),  # lines 8-11: draw i with probability w_t[i]
                             proposal=step.proposal)            # (injected: where the scan fits, if reset)
        p.conclude(step)                                        # searching, localized or lost
        for watch in observers:
            watch(step, mcl)
    p.close(int(n_steps) - 1)
    return p.events


# --------------------------------------------------------------------------- the record
class Recorder:
    """An observer of :func:`run` that keeps one row per step, and makes the :class:`RunTrace`.

    ``snapshot_steps`` are the steps whose weighted particle set (after the
    update) is kept, at most ``snapshot_particles`` evenly spaced particles each.

    Examples
    --------
    >>> f = toy_mcl()
    >>> rec = Recorder(snapshot_steps=[1])
    >>> events = run(f, 2, lambda k: 0.5, lambda k: (3.0,), observers=[rec])
    >>> tr = rec.trace(events)
    >>> len(tr), sorted(tr.snapshots), int(tr.beam_evaluations)
    (2, [1], 202)
    """

    def __init__(self, snapshot_steps: Any = (), snapshot_particles: int | None = None) -> None:
        self.keep = {int(k) for k in snapshot_steps}
        self.snapshot_particles = snapshot_particles
        self.rows: list[tuple] = []
        self.snapshots: dict = {}
        self.evaluations = 0

    def __call__(self, step: Step, mcl: Any) -> None:
        e, st = step.estimate, mcl.status
        self.rows.append((step.pose, e.mean, e.std, e.spread, e.best_weight, step.n_eff, step.n_particles,
                          st.n_injected, st.p_inject, step.updated, st.resampled, step.degenerate, step.n_valid,
                          step.fit, step.on_map, step.state, e.cov if e.cluster_cov is None else e.cluster_cov,
                          step.p_localized, step.p_place))
        if step.updated:
            self.evaluations += step.n_particles * (int(np.size(step.z[1])) if is_scan(step.z) else 1)
        if step.k in self.keep:
            particles, log_w = step.cloud
            w = np.exp(log_w)
            sub = slice(None)
            if self.snapshot_particles is not None and len(particles) > self.snapshot_particles:
                sub = np.linspace(0, len(particles) - 1, int(self.snapshot_particles)).astype(int)
            self.snapshots[step.k] = (particles[sub].copy(), w[sub].copy())

    def trace(self, events: list, seconds: float = 0.0) -> "RunTrace":
        """The :class:`RunTrace` of the steps seen so far."""
        cols = list(zip(*self.rows))
        arr = [np.array(c) for c in cols]
        return RunTrace(poses=np.array(cols[0], dtype=float).reshape(-1, 3),
                        means=np.array(cols[1], dtype=float).reshape(-1, 3),
                        stds=np.array(cols[2], dtype=float).reshape(-1, 3),
                        spread=arr[3].astype(float), best_weight=arr[4].astype(float), n_eff=arr[5].astype(float),
                        n_particles=arr[6].astype(np.int64), n_injected=arr[7].astype(np.int64),
                        p_inject=arr[8].astype(float), updated=arr[9].astype(bool), resampled=arr[10].astype(bool),
                        degenerate=arr[11].astype(bool), n_valid=arr[12].astype(np.int64), fit=arr[13].astype(float),
                        on_map=arr[14].astype(float), state=np.array(cols[15], dtype="<U9"), events=events,
                        beam_evaluations=int(self.evaluations), seconds=float(seconds), snapshots=self.snapshots,
                        cov=np.array(cols[16], dtype=float).reshape(-1, 3, 3),
                        p_localized=np.array(cols[17], dtype=float), p_place=np.array(cols[18], dtype=float))


def _check_driver_arguments(recovery_injection: float, skip_short_beams: float,
                            expand: tuple[float, float]) -> tuple[float, tuple[float, float]]:
    if not 0.0 <= float(recovery_injection) < 1.0:
        raise ValueError(f"recovery_injection must be a fraction in [0, 1); got {recovery_injection!r}")
    short_m = float(skip_short_beams)
    if not (np.isfinite(short_m) and short_m >= 0):
        raise ValueError(f"skip_short_beams must be a length in metres >= 0 (0: never); got {skip_short_beams!r}")
    ex_xy, ex_th = (float(v) for v in expand)
    if not (np.isfinite(ex_xy) and np.isfinite(ex_th) and ex_xy >= 0 and ex_th >= 0):
        raise ValueError(f"expand must be two numbers >= 0 (metres, radians); got {expand!r}")
    return short_m, (ex_xy, ex_th)


def default_policies(mcl: Any, *, grid: OccupancyGrid | None = None, min_motion: tuple[float, float] = (0.0, 0.0),
                     max_step: float | None = None, rules: StateRules | None = None, recover: bool = True,
                     recovery_injection: float = 0.0, restart_after: int = 0,
                     expand: tuple[float, float] = (0.0, 0.0), odometry: ArrayLike | None = None,
                     skip_unknown_beams: bool = False, skip_short_beams: float = 0.0,
                     state: str = "thresholds", sensor_reset: float = 0.0) -> Policies:
    """The policies :func:`run_filter` runs ``mcl`` with, from its arguments (see there).

    Examples
    --------
    >>> p = default_policies(toy_mcl(), restart_after=5)
    >>> p.restart is None, p.state is not None          # a restart needs the map's evidence: no map, no restart
    (True, True)
    """
    rules = StateRules() if rules is None else rules
    short_m, (ex_xy, ex_th) = _check_driver_arguments(recovery_injection, skip_short_beams, expand)
    grid = mcl.grid if grid is None else grid
    if grid is not None and not isinstance(grid, OccupancyGrid):
        raise TypeError(f"grid must be an OccupancyGrid or None; got {type(grid).__name__}")
    if max_step is None and grid is not None:
        max_step = float(np.hypot(grid.width_m, grid.height_m))
    sensor = mcl.sensor
    soft = bool(np.isfinite(getattr(mcl, "occupied_penalty", np.inf)))
    p = Policies(rules=rules, odometry=OdometryCheck(max_step), redraw=Redraw(recover, float(recovery_injection)),
                 soft_once_agreed=soft)
    d_min, a_min = (float(v) for v in min_motion)
    if d_min > 0 or a_min > 0:
        p.gate = MotionGate((d_min, a_min), odometry)
    if grid is not None:
        p.evidence = MapEvidence(grid, sensor, rules, soft=soft)
        if skip_unknown_beams or short_m > 0:
            p.beams = BeamMasks(grid, p.evidence.offset, float(getattr(sensor, "max_range", np.inf)),
                                unknown=skip_unknown_beams, short=short_m, caster=p.evidence.caster)
        if ex_xy > 0 or ex_th > 0:
            p.expansion = Expansion((ex_xy, ex_th))
        if restart_after:
            p.restart = Restart(restart_after, mcl.kld.n_max if mcl.kld is not None else mcl.n)
    # the rival bank's places move as the filter's particles do, when the filter's motion model reads odometry
    odometric = isinstance(mcl.motion, OdometryMotion) or isinstance(getattr(mcl.motion, "base", None), OdometryMotion)
    motion = mcl.motion if odometric else None
    _add_state(p, grid, sensor, state, sensor_reset, motion)
    return p


def _add_state(p: Policies, grid: OccupancyGrid | None, sensor: Any, state: str, sensor_reset: float,
               motion: Any = None) -> None:
    """The state's policy (and sensor resetting, which reads its ``p_localized``) into ``p``."""
    if state not in ("thresholds", "probability"):
        raise ValueError(f"state must be 'thresholds' or 'probability'; got {state!r}")
    if state == "probability" and (p.evidence is None or not callable(getattr(sensor, "log_likelihood", None))
                                   or not np.isfinite(float(getattr(sensor, "max_range", np.inf)))):
        raise ValueError("state='probability' needs a map (grid) and a range sensor model with a finite max_range "
                         "and log_likelihood: the probability is calibrated on them; use state='thresholds'")
    if state == "thresholds":
        if sensor_reset > 0:
            raise ValueError("sensor_reset needs state='probability': it draws particles while p_localized is low")
        p.state = ThresholdState(sensor, p.rules, p.evidence)
        return
    p.state = ReliabilityState(grid, sensor, fit_distance=p.rules.fit_distance, motion=motion)
    if sensor_reset > 0:
        bank = p.state.rivals                   # the same map and sensor: its blurred field serves the place search
        p.reset = SensorReset(grid, sensor, sensor_reset, p.state.lost_below,
                              coarse=None if bank is None else bank.coarse)


def run_filter(
    mcl: Any,
    n_steps: int,
    control: Callable[[int], Any],
    scan: Callable[[int], tuple | None],
    *,
    grid: OccupancyGrid | None = None,
    min_motion: tuple[float, float] = (0.0, 0.0),
    max_step: float | None = None,
    rules: StateRules | None = None,
    snapshot_steps: Any = (),
    snapshot_particles: int | None = None,
    recover: bool = True,
    recovery_injection: float = 0.0,
    restart_after: int = 0,
    expand: tuple[float, float] = (0.0, 0.0),
    odometry: ArrayLike | None = None,
    callback: Callable[[int], None] | None = None,
    skip_unknown_beams: bool = False,
    skip_short_beams: float = 0.0,
    state: str = "thresholds",
    sensor_reset: float = 0.0,
) -> RunTrace:
    """The one run driver: filter a sequence of controls and scans, with update gating and an honest state.

    The command line (:func:`localize.pipeline.localize_log`), the book's chapters
    and :func:`run_mcl` all run their filters through this loop. At step
    ``k``:

    1. ``u = control(k)`` moves the particles (``None``: no motion). An
       odometry pair whose step is longer than ``max_step`` metres (default:
       the map's diagonal -- no robot moves further than that between two
       scans of one building) is a corrupt record: it is rejected and
       reported in ``events``, the particles stay where they were.
    2. ``scan(k)`` returns the measurement ``(ranges, angles)`` or None. It is
       used only after the odometry says the robot moved at least
       ``min_motion = (metres, radians)`` since the last update (repeating
       the same scan of a standing robot would make the filter
       over-confident; ROS AMCL's ``update_min_d`` / ``update_min_a``).
    3. The estimate is taken from the weighted set; the filter resamples as
       its policy says.
    4. The state (:class:`StateRules`) is updated from the evidence: share of
       weight in the best cluster, its spread, how well the scan fits the map
       at the estimate, valid readings, all-zero likelihoods, particles off
       the map. With ``recover`` (default), a filter whose particles all got
       zero likelihood or all left the free space re-draws them uniformly
       (global localization again) and says so.

    Parameters
    ----------
    mcl : localize.mcl.MCL
        The initialised filter (advanced in place).
    n_steps : int
        Number of steps.
    control, scan : callables of the step index
        See above.
    grid : OccupancyGrid, optional
        The map: needed for the scan fit, the off-map check and ``max_step``
        (default: the filter's own ``grid``). Particles count as off the map
        outside the grid or in known obstacle cells (unknown cells are allowed).
    min_motion : (float, float)
        Update gating; ``(0, 0)`` uses every scan.
    max_step : float, optional
        Longest believable odometry step (metres).
    rules : StateRules, optional
        Thresholds of the state.
    snapshot_steps : iterable of int
        Steps whose weighted particle set (after the update) is kept.
    snapshot_particles : int, optional
        Keep at most this many (evenly spaced) particles per snapshot.
    recover : bool
        Re-draw the particles when all of them got zero likelihood or left the map.
    recovery_injection : float
        While the state is ``lost``, replace this fraction of the particles by
        random ones at each resampling (in [0, 1)): the filter searches the
        map again instead of insisting on the place it lost.
    restart_after : int
        Global localization again (0: never): when the cloud has agreed on one
        place (best cluster share and spread within the rules) but the scans
        have not fitted the map there for this many updates in a row, the
        filter is probably confidently wrong. As many uniform particles as at
        the start (``kld.n_max`` with KLD-sampling) are added beside the
        current cloud, each half of the weight, and the two clouds are on
        probation side by side for up to 30 updates (each resampled within
        itself, keeping its share; ``recovery_injection`` goes to the new one
        only). The new search replaces the old place only if it beats it on
        both the sensor model's evidence (its share of the weight) *and* the
        ray-cast fit of the recent scans at its best cluster, and that fit is
        at least ``rules.restart_fit`` times the expected one (better than a
        poorly fitting old place is not yet the robot's place): a look-alike
        whose beams end in the map's unknown cells (scored neutrally by a
        likelihood field) can win the weight, not the fit. Meanwhile the
        estimate is the favoured place (the old one until each cloud has had
        three scans fitted: one or two are no evidence) and ``best_weight``
        its share of the whole cloud, so the state stays honest. ``events``
        says which won.
        While the state is still ``searching`` (never localized since the
        start or the last restart), a cloud *gathered*
        on one place (best cluster share within the rules, spread within four
        times ``max_spread``) counts as well, and so does an update whose fit
        the map cannot judge (too few beams end on known cells): a cloud that
        collapsed onto a place the map knows nothing about (a wrong room
        whose beams all end in unknown cells scores as well as the right
        one) would otherwise search there to the end of the log. And a
        ``lost`` filter whose best place has not fitted the scans for this
        many updates (updates the map cannot judge leave the count as it
        is) restarts too, whether its cloud agrees on that place or has
        spread out (after a kidnapping): lost, it has already said that it
        does not know, and the probation keeps the old place if the search
        finds nothing better.
    sensor_reset : float
        Sensor resetting (Lenser and Veloso 2000; :class:`~localize.policies.SensorReset`),
        with ``state="probability"`` only: at each update whose ``p_localized``
        is below the state's threshold for *lost*, the filter resamples and up
        to this share of the particles (in (0, 1); 0, default: never) is drawn
        near the places where the scan fits the map best, the more the lower
        ``p_localized``, with importance weights (a robot that may be anywhere
        with probability ``1 - p_localized``).
    expand : (metres, radians)
        Expansion resetting (Ueda et al. 2004): when the cloud has agreed on
        one place but the scan just used does not fit the map there (its fit
        below ``rules.restart_fit`` times the expected), every particle is
        moved by Gaussian noise of these standard deviations. A tight cloud
        that the odometry carried away from the robot (wheel slip, a bump,
        odometry that misses that the robot backs up) cannot be pulled back by
        the scans, since no particle is near the truth any more; spread a
        little wider, the next scans find the robot again and the cloud
        shrinks back. ``(0, 0)`` (default) never expands.
    odometry : array_like (T, 3), optional
        Odometry pose at each step, for the gating (default: the second pose of
        each odometry control).
    callback : callable, optional
        Called with ``k + 1`` after each step (progress bars).
    skip_unknown_beams : bool
        Once the cloud has agreed on one place (best cluster share and spread
        within the rules, and the state past ``searching``), leave out of each
        update the beams whose end point *at that place* falls in one of the
        map's unknown cells (needs ``grid``). The map cannot say whether such
        a beam fits; scored, it lets particles a metre away win by putting it
        on some known wall instead, and a robot driving through a region the
        map left unknown is pulled out of it. A scan with no other valid
        beam is not used at all (the odometry alone carries the cloud), and
        ``events`` counts the beams left out. While the filter searches, every
        beam is scored: then each particle is its own hypothesis.
    skip_short_beams : float
        Metres (0, default: never). Like ``skip_unknown_beams``, once the
        cloud has agreed on one place: leave out of each update the beams
        that read more than this much *shorter* than the range ray-cast in
        the map from that place (needs ``grid``). Such a beam hit something
        the map does not show (a person, a chair, a box in front of the
        mapped wall). Scored, it favours any few particles at a wrong place
        where its end point happens to lie on a mapped wall, and when the
        robot stands close to such clutter (blocked by it, turning on the
        spot) a handful of particles a metre or two away can take all the
        weight in two updates. A cloud agreed within ``rules.max_spread``
        explains no reading that much short by its own error when the value
        is at least twice that (the CLI uses 1 m, twice the default 0.5 m).
        When more than half of a scan's valid beams read short, none is left
        out: a place where most of the scan hits things the map does not
        show is more likely wrong than cluttered, and the scan must be free
        to move the cloud. ``events`` counts the beams left out.

    state : {"thresholds", "probability"}
        Where the state comes from: the thresholds of ``rules``
        (:class:`~localize.policies.ThresholdState`, default), or ``p_localized``
        (:class:`~localize.reliability.ReliabilityState`: a Bayes filter over "the
        estimate is within 1 m", calibrated on the map and the sensor model; needs
        ``grid``), which then also drives ``restart_after``. ``p_localized`` of the
        trace is NaN with thresholds. The command line's default is the
        probability (:class:`localize.settings.RunSettings`); this function keeps
        the thresholds as its default, which need no map (chapter 8 passes
        ``state="probability"``).

    Returns
    -------
    RunTrace

    Examples
    --------
    A robot standing in the office world, its laser simulated; the filter
    starts uniform and localizes:

    >>> from localize.maps import office
    >>> from localize.mcl import MCL
    >>> from localize.sensors import LikelihoodField
    >>> g = office()
    >>> lf = LikelihoodField(g, 8.0, sigma_hit=0.2, temper=0.2)
    >>> rng = np.random.default_rng(1)
    >>> angles = np.linspace(-np.pi / 2, np.pi / 2, 37)
    >>> truth = np.array([[3.0, 3.0, 1.0]])
    >>> f = MCL.uniform(g, 4000, (0.0,) * 4, lf, rng=rng, free_space_only=True)
    >>> tr = run_filter(f, 15, lambda k: None, lambda k: (lf.sample(truth, angles, rng)[0], angles))
    >>> str(tr.state[0]), tr.first_localized() is not None, bool(np.hypot(*(tr.poses[-1, :2] - truth[0, :2])) < 0.5)
    ('searching', True, True)
    >>> sorted(tr.state_summary())[:3]
    ['degenerate_updates', 'events', 'final_state']

    With ``state="probability"`` the trace carries ``p_localized``; a robot
    driving through the office:

    >>> from localize.sim import range_run
    >>> r = range_run(g, np.random.default_rng(2), n_steps=30, angles=angles, max_range=8.0)
    >>> from localize.motion import OdometryMotion
    >>> f = MCL.gaussian(r.poses[0], (0.3, 0.3, 0.1), 2000, OdometryMotion(r.alphas, min_std=0.01), lf,
    ...                  rng=np.random.default_rng(3), grid=g)
    >>> tr = run_filter(f, 30, r.control, lambda k: (r.ranges[k], angles), state="probability")
    >>> s = tr.state_summary()
    >>> s["final_state"], s["final_p_localized"] >= 0.9, bool(np.hypot(*(tr.poses[-1, :2] - r.poses[-1, :2])) < 0.5)
    ('localized', True, True)
    """
    t = int(n_steps)
    if t < 1:
        raise ValueError(f"n_steps must be >= 1; got {n_steps!r}")
    policies = default_policies(mcl, grid=grid, min_motion=min_motion, max_step=max_step, rules=rules,
                                recover=recover, recovery_injection=recovery_injection, restart_after=restart_after,
                                expand=expand, odometry=odometry, skip_unknown_beams=skip_unknown_beams,
                                skip_short_beams=skip_short_beams, state=state, sensor_reset=sensor_reset)
    record = Recorder(snapshot_steps, snapshot_particles)
    watch = [record] if callback is None else [record, lambda step, mcl: callback(step.k + 1)]
    t0 = time.perf_counter()
    events = run(mcl, t, control, scan, policies=policies, observers=watch)
    return record.trace(events, time.perf_counter() - t0)


def run_mcl(
    mcl: Any,
    run: Any,
    snapshot_steps: Any = (),
    n_steps: int | None = None,
) -> "RunTrace":
    """Run a filter over a recorded (or simulated) range run and record what it did (a :class:`RunTrace`).

    ``run`` is anything with ``ranges (T, B)``, ``angles (B,)`` and
    ``control(k)`` giving the motion into step ``k`` -- a
    :class:`localize.sim.RangeRun`, for instance. Step 0 is a measurement
    only; step ``k >= 1`` is ``mcl.step(run.control(k), run.ranges[k], run.angles)``.

    Parameters
    ----------
    mcl : localize.mcl.MCL
        The filter, already initialised (it is advanced in place).
    run : object
        The data, see above.
    snapshot_steps : iterable of int
        Steps whose weighted particle set (after the update) is kept.
    n_steps : int, optional
        Stop after this many steps (default: the whole run).

    Examples
    --------
    >>> class Run:                                # a robot standing still, measured by a "GPS"
    ...     ranges = np.full((4, 1), 3.0)
    ...     angles = np.zeros(1)
    ...     def control(self, k):
    ...         return None
    >>> class GPS:
    ...     def log_likelihood(self, poses, ranges, angles):
    ...         return -0.5 * ((poses[:, 0] - ranges[0]) / 0.2) ** 2
    >>> from localize.mcl import MCL
    >>> rng = np.random.default_rng(0)
    >>> p0 = np.column_stack([rng.uniform(0, 10, 1000), np.zeros(1000), np.zeros(1000)])
    >>> tr = run_mcl(MCL(p0, lambda p, u, rng: p, GPS(), rng=rng), Run(), snapshot_steps=[0])
    >>> len(tr), round(float(tr.poses[-1, 0]), 1), tr.beam_evaluations, sorted(tr.snapshots)
    (4, 3.0, 4000, [0])
    """
    ranges = np.asarray(run.ranges, dtype=float)
    angles = np.asarray(run.angles, dtype=float)
    t = ranges.shape[0] if n_steps is None else int(n_steps)
    if not 1 <= t <= ranges.shape[0]:
        raise ValueError(f"n_steps must lie in [1, {ranges.shape[0]}]; got {n_steps!r}")
    # the one driver, without gating or recovery: every step predicts and measures
    return run_filter(mcl, t, run.control, lambda k: (ranges[k], angles), snapshot_steps=snapshot_steps,
                      recover=False)
