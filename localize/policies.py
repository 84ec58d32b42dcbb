"""The run driver's policies: every rule beyond the textbook loop, each a small object.

The core loop of :func:`localize.runloop.run` is PR table 8.2: move, weight,
estimate, resample. A filter that runs on a real robot's log needs more, and
each extra rule lives here, with its own tests (``tests/test_policies.py``):

* :class:`OdometryCheck` -- an odometry step longer than the map's diagonal
  is a corrupt record: the particles are not moved;
* :class:`MotionGate` -- a scan is used only after the robot moved (ROS
  AMCL's ``update_min_d`` / ``update_min_a``);
* :class:`BeamMasks` -- once the cloud agrees on one place, beams the map
  cannot explain there are left out of the update;
* :class:`MapEvidence` -- how well the scan fits the map at the estimate, and
  how much weight lies on free space (no ground truth used);
* :class:`Expansion` -- expansion resetting: a tight cloud whose scan does not
  fit is spread wider;
* :class:`Restart` and :class:`Probation` -- global localization again beside
  the current cloud, the two on probation until the scans pick one;
* :class:`Redraw` -- every particle re-drawn when all got zero likelihood or
  left the map, and random particles injected while lost;
* :class:`SensorReset` -- sensor resetting: while ``p_localized`` doubts the
  place, part of the particles is drawn where the scan fits the map;
* :class:`ThresholdState` -- the *searching* / *localized* / *lost* state from
  the thresholds of :class:`StateRules`.

They share what they know of the run in a :class:`Context` (the state, whether
the cloud agreed on one place at the last step, the recent fits and an open
probation) and write down what they did in its ``events``. A policy changes
the filter only through its methods (``update(soft_obstacles=...)``,
``resample(injection=...)``, ``add_particles``, ``redraw``, ``diffuse``,
``replace``), never by setting its attributes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import resample as _rs
from .estimate import Estimate, _estimate
from .evidence import expected_fit, free_share, pinned, scan_fit, unexplained_beams
from .geometry import mean_pose, wrap_angle
from .geometry import relative as _relative
from .grid import OccupancyGrid
from .mcl import Proposal
from .placesearch import best_places, coarse_model
from .reliability import LOST_BELOW

__all__ = [
    "StateRules",
    "Context",
    "Step",
    "OdometryCheck",
    "MotionGate",
    "BeamMasks",
    "MapEvidence",
    "FitWindow",
    "Expansion",
    "Restart",
    "Probation",
    "Redraw",
    "SensorReset",
    "ThresholdState",
    "PROBATION",
    "STATES",
]

STATES = ("searching", "localized", "lost")

#: A restart's probation (:class:`Probation`): at least this many updates, at most this many, and the
#: share of the weight (log) below which the losing cloud is dropped early. Not fitted to a log: 30
#: updates is :class:`StateRules`' default ``fit_window`` (5) six times over, 1e-4 a share no resampling of
#: a few thousand particles would keep a particle of.
PROBATION = (3, 30, float(np.log(1e-4)))


@dataclass(frozen=True)
class StateRules:
    """When the run driver calls the filter *localized*, *searching* or *lost*, from its own evidence.

    No ground truth is used: a scan counts as **confident** when

    * the scan holds at least ``min_beams`` valid readings (between the
      sensor's minimum and maximum range): no readings, no evidence;
    * the best cluster holds at least ``min_share`` of the weight (one
      hypothesis, not several look-alike places);
    * the best cluster's position spread is below ``max_spread`` metres and
      its heading spread below ``max_heading_std`` radians;
    * the scans *fit* the map at the estimate: the share of valid beams whose
      reading agrees with the range ray-cast in the map from the estimate
      within ``fit_distance`` (default ``2 * sigma_hit``), averaged over the
      last ``fit_window`` updates, is at least ``min_fit`` times the share
      the sensor model expects on a correct pose (``z_hit * P(|N(0,
      sigma_hit^2)| < fit_distance)``, see :func:`~localize.evidence.expected_fit`).
      A filter can agree with itself on a wrong place (a converged cloud in a
      room that looks alike); the fit catches most of that, because the
      likelihood field never checks whether a beam passed through a wall,
      and the ray cast does. Beams whose cast ray ends in an unknown cell
      are not judged; with fewer than ``min_beams`` judged the update has no
      fit. No judged fit since the start, the last restart or the last time
      the state turned lost is no evidence: it keeps a localized state (the
      last fits stand), it never makes one (runs without a map or without
      range scans have no fit at all, and the other conditions decide). The
      fits of a place the filter has lost vouch for that place, not for the
      one its cloud gathers on next.
    * the scan *pins* the pose: moved by ``probe_shift`` metres forwards,
      backwards, left or right, the estimate must fit the scan worse by at
      least ``min_contrast`` nats per beam the sensor model scored
      (untempered log-likelihood; beams left out of the update and beams
      the model thins away are not counted). In a featureless corridor a cloud can shrink
      onto one stretch by resampling alone (KLD-sampling makes it small
      enough for that), and every stretch fits equally well; this probe
      says so. (Range scans and sensors with ``log_likelihood`` only.)

    ``restart_fit`` (below ``min_fit``) is the fit under which an agreed cloud
    counts as confidently wrong, for :class:`Restart` and :class:`Expansion`:
    the scans at the truth fit a degraded real map at 0.45-0.8 of the beams
    (10% quantile to median), at random wrong poses at 0-0.3.

    The state starts ``searching``; ``hold`` confident updates in a row make it
    ``localized``. A localized filter turns ``lost`` after ``hold_lost``
    updates in a row that are not confident, and at once when every particle
    got zero likelihood or has left the map's free space. ``lost`` turns
    ``localized`` again like ``searching`` does.

    Examples
    --------
    >>> StateRules().hold
    3
    """

    min_beams: int = 5
    min_share: float = 0.8
    max_spread: float = 0.5
    max_heading_std: float = 0.35
    min_fit: float = 0.6
    restart_fit: float = 0.5
    fit_distance: float | None = None
    fit_window: int = 5
    hold: int = 3
    hold_lost: int = 3
    probe_shift: float = 1.0
    min_contrast: float = 0.1

    def __post_init__(self) -> None:
        if min(int(self.min_beams), int(self.hold), int(self.hold_lost), int(self.fit_window)) < 1:
            raise ValueError("min_beams, hold, hold_lost and fit_window must be whole numbers >= 1")
        if not 0.0 < self.min_share <= 1.0:
            raise ValueError(f"min_share must lie in (0, 1]; got {self.min_share!r}")
        if not 0.0 <= self.min_fit <= 1.0:
            raise ValueError(f"min_fit must lie in [0, 1]; got {self.min_fit!r}")
        for name in ("max_spread", "max_heading_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number; got {v!r}")
        if self.fit_distance is not None and not (np.isfinite(self.fit_distance) and self.fit_distance > 0):
            raise ValueError(f"fit_distance must be a positive length in metres or None; got {self.fit_distance!r}")

    def agreed(self, e: Estimate) -> bool:
        """The cloud agrees on one place: the best cluster holds ``min_share`` within ``max_spread``."""
        return bool(e.best_weight >= self.min_share and e.spread <= self.max_spread)

    def gathered(self, e: Estimate) -> bool:
        """Gathered on one place, if less tightly than :meth:`agreed` (spread within four times ``max_spread``)."""
        return bool(e.best_weight >= self.min_share and e.spread <= 4 * self.max_spread)

    def fit_scale(self, sensor: Any) -> tuple[float, float]:
        """``(fit_distance, expected fit)`` for ``sensor``: the distance defaults to twice its ``sigma_hit``."""
        fit_d = self.fit_distance
        if fit_d is None:
            fit_d = 2.0 * float(getattr(sensor, "sigma_hit", 0.2))
        return fit_d, expected_fit(sensor, fit_d)


# --------------------------------------------------------------------------- what one step knows
def is_scan(z: Any) -> bool:
    """True for a range scan ``(ranges (B,), angles (B,))``.

    Examples
    --------
    >>> is_scan((np.ones(3), np.zeros(3))), is_scan((5.0,))
    (True, False)
    """
    if not isinstance(z, tuple) or len(z) != 2:
        return False
    a, b = np.shape(z[0]), np.shape(z[1])
    return len(a) == 1 and a == b


@dataclass(eq=False)
class Step:
    """What one step of the run loop saw and did; the policies fill it in, observers read it.

    ``z`` is the measurement the update used (None: no update); ``scan`` the
    range scan as given (``ranges``, ``angles``, ``valid``), for the evidence.
    ``cloud`` is the weighted set right after the update; ``n_eff`` the
    effective sample size then. ``reset_share`` is the share of the particles
    :class:`SensorReset` draws at this step's resampling, ``proposal`` where it
    draws them and what they weigh (a :class:`localize.mcl.Proposal`; None: no reset).
    """

    k: int
    n_particles: int = 0
    u: Any = None
    pair: tuple | None = None
    z: Any = None
    scan: tuple | None = None
    n_valid: int = 0
    cloud: tuple | None = None
    estimate: Estimate | None = None
    pose: NDArray | None = None
    n_eff: float = float("nan")
    degenerate: bool = False
    fit: float = float("nan")
    on_map: float = float("nan")
    off_map: bool = False
    agreed: bool = False
    state: str = "searching"
    p_localized: float = float("nan")
    p_place: float = float("nan")
    evidence: float = float("nan")
    reset_share: float = 0.0
    proposal: Any = None

    @property
    def updated(self) -> bool:
        """Whether the step used its measurement."""
        return self.z is not None


class FitWindow:
    """The last ``size`` judged fits of the scans at the estimate, and those judged since the state turned lost.

    Examples
    --------
    >>> w = FitWindow(2)
    >>> w.add(0.5); w.add(0.7); w.add(0.9)
    >>> round(w.mean, 6), round(w.judging(), 6)
    (0.8, 0.8)
    >>> w.since_loss = []                        # the state just turned lost: no fit judges the next place yet
    >>> w.judging()
    nan
    """

    def __init__(self, size: int) -> None:
        self.size = int(size)
        self.recent: list[float] = []
        self.since_loss: list[float] | None = None

    def add(self, fit: float) -> None:
        """One more judged fit."""
        self.recent = (self.recent + [float(fit)])[-self.size:]
        if self.since_loss is not None:
            self.since_loss = (self.since_loss + [float(fit)])[-self.size:]

    def clear(self) -> None:
        """Forget the recent fits (a restart: they judged the old place)."""
        self.recent = []

    @property
    def mean(self) -> float:
        """Mean of the recent fits (NaN before any)."""
        return float(np.mean(self.recent)) if self.recent else float("nan")

    def judging(self) -> float:
        """The mean fit that judges the current place: since the loss, for a filter that lost the robot."""
        if self.since_loss is None:
            return self.mean
        return float(np.mean(self.since_loss)) if self.since_loss else float("nan")


@dataclass(eq=False)
class Context:
    """What the policies share about the run so far.

    Attributes
    ----------
    rules : StateRules
        The thresholds (when a cloud agrees, fits, ...).
    state : str
        ``searching``, ``localized`` or ``lost``.
    agreed : bool
        The cloud agreed on one place at the last step (and the state is past ``searching``).
    soft : bool
        Whether the last update priced particles in obstacles finitely (:class:`localize.mcl.MCL`'s
        ``occupied_penalty``) instead of giving them zero weight.
    fits : FitWindow
        The recent fits of the scans at the estimate.
    probation : Probation or None
        An open restart.
    events : list of (int, str)
        What the policies did, step by step.
    """

    rules: StateRules
    state: str = "searching"
    agreed: bool = False
    soft: bool = True
    fits: FitWindow = None  # type: ignore[assignment]
    probation: "Probation | None" = None
    events: list = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.fits is None:
            self.fits = FitWindow(self.rules.fit_window)


# --------------------------------------------------------------------------- control and measurement
class OdometryCheck:
    """Reject an odometry step that no robot can make between two scans: a corrupt record.

    A step longer than ``max_step`` metres (the map's diagonal, say), or with a
    NaN or infinite pose, leaves the particles where they were; ``events`` says so.

    Examples
    --------
    >>> from localize.motion import odometry_pair
    >>> ctx = Context(StateRules())
    >>> check = OdometryCheck(max_step=10.0)
    >>> step = Step(3, pair=odometry_pair(([0, 0, 0], [250.0, 0, 0])))
    >>> check.admit(step, "u", ctx) is None, ctx.events[0][1][:27]
    (True, 'odometry step of 250 m is i')
    """

    def __init__(self, max_step: float | None) -> None:
        self.max_step = max_step

    def admit(self, step: Step, u: Any, ctx: Context) -> Any:
        """``u``, or None for a corrupt odometry record."""
        if step.pair is None:
            return u
        prev, cur = step.pair
        step_len = float(np.hypot(*(cur[:2] - prev[:2])))
        finite = bool(np.all(np.isfinite(prev)) and np.all(np.isfinite(cur)))
        if finite and (self.max_step is None or step_len <= self.max_step):
            return u
        if self.max_step is None:
            ctx.events.append((step.k, "odometry step with a NaN or infinite pose: corrupt record rejected, "
                                       "particles not moved"))
        else:
            ctx.events.append((step.k, f"odometry step of {step_len:.3g} m is impossible (longer than "
                                       f"{self.max_step:.3g} m, the map's diagonal): corrupt record rejected, "
                                       "particles not moved"))
        return None


class MotionGate:
    """Use a scan only after the odometry says the robot moved ``min_motion = (metres, radians)`` since the last
    update (ROS AMCL's ``update_min_d`` / ``update_min_a``): the same scan of a standing robot, used again and
    again, would make the filter over-confident.

    ``odometry`` (T, 3) gives the odometry pose of each step; without it the second pose of each odometry
    control is used.

    Examples
    --------
    >>> from localize.motion import odometry_pair
    >>> gate = MotionGate((0.5, 1.0))
    >>> used = []
    >>> for k, x in enumerate([0.0, 0.2, 0.6]):          # the robot drives 0.2 m, then 0.4 m more
    ...     if gate.admits(Step(k, pair=odometry_pair(([0, 0, 0], [x, 0, 0])))):
    ...         gate.used()
    ...         used.append(k)
    >>> used
    [0, 2]
    """

    def __init__(self, min_motion: tuple[float, float], odometry: ArrayLike | None = None) -> None:
        self.d_min, self.a_min = (float(v) for v in min_motion)
        self.odometry = None if odometry is None else np.asarray(odometry, dtype=float)
        self.last: NDArray | None = None
        self._where: NDArray | None = None

    def admits(self, step: Step) -> bool:
        """Whether the robot moved enough since the last update for the step's scan to be used."""
        where = None if self.odometry is None else self.odometry[step.k]
        if where is None and step.pair is not None:
            where = step.pair[1]
        self._where = where
        if self.last is None or where is None or not (self.d_min > 0 or self.a_min > 0):
            return True
        m = _relative(self.last, where)
        return bool(not np.all(np.isfinite(m)) or np.hypot(m[0], m[1]) >= self.d_min or abs(m[2]) >= self.a_min)

    def used(self) -> None:
        """The scan admitted last was used: the robot's motion counts from there."""
        self.last = self._where


class BeamMasks:
    """Once the cloud agrees on one place, leave out of the update the beams the map cannot explain there.

    * ``unknown``: beams whose end point at that place falls in one of the
      map's unknown cells. The map cannot say whether such a beam fits;
      scored, it lets particles a metre away win by putting it on some known
      wall instead, and a robot driving through a region the map left unknown
      is pulled out of it.
    * ``short`` (metres, 0: never): beams that read more than this much
      *shorter* than the range ray-cast in the map from that place: they hit
      something the map does not show (a person, a chair, a box in front of
      the mapped wall). Scored, such a beam favours a few particles at a wrong
      place where its end point happens to lie on a mapped wall. A cloud
      agreed within ``StateRules.max_spread`` explains no reading that much
      short by its own error when ``short`` is at least twice that. When more
      than half of a scan's valid beams read short, none is left out (see
      :func:`~localize.evidence.unexplained_beams`).

    A scan with no other valid beam is not used at all (the odometry alone
    carries the cloud). While the filter searches, every beam is scored: then
    each particle is its own hypothesis. The place is the cloud's weighted
    mean pose.
    """

    def __init__(self, grid: OccupancyGrid, offset: NDArray, max_range: float, *, unknown: bool = False,
                 short: float = 0.0, caster: Any = None) -> None:
        self.grid, self.offset, self.max_range = grid, offset, float(max_range)
        self.unknown, self.short, self.caster = bool(unknown), float(short), caster
        self.n_unknown = self.n_short = self.n_blind = 0

    def apply(self, mcl: Any, z: tuple) -> tuple | None:
        """The scan with the unexplained beams left out, or None when no valid beam is left."""
        z, n_unknown, n_short = unexplained_beams(self.grid, mean_pose(mcl.particles, mcl.weights), self.offset, z,
                                                  self.max_range, unknown=self.unknown, caster=self.caster,
                                                  short=self.short)
        self.n_unknown += n_unknown
        self.n_short += n_short
        if (n_unknown or n_short) and not np.any(np.asarray(z[0]) < self.max_range):
            self.n_blind += 1
            return None
        return z

    def report(self, last: int, ctx: Context) -> None:
        """Add the run's counts of beams left out to ``ctx.events`` (at step ``last``)."""
        if self.n_unknown:
            blind = (f"; {self.n_blind} scan{'s' * (self.n_blind != 1)} had no other valid beam and were not used"
                     if self.n_blind else "")
            ctx.events.append((last, f"{self.n_unknown} beams whose end point at the agreed place lies in the map's "
                                     f"unknown cells were left out of the updates{blind}"))
        if self.n_short:
            ctx.events.append((last, f"{self.n_short} beams that read more than {self.short:g} m shorter than the map "
                                     "allows at the agreed place (something the map does not show stands in front) "
                                     "were left out of the updates"))


# --------------------------------------------------------------------------- evidence
class MapEvidence:
    """The map's judgement of the estimate at each step (no ground truth): the scan's fit and the weight on the map.

    ``fit`` is :func:`~localize.evidence.scan_fit` of the valid readings at the
    estimate (NaN when the map cannot judge); ``on_map`` the share of the
    weight on the map (inside the grid and not in a known obstacle);
    ``off_map`` is True when none is -- with a finite price for obstacles
    (``soft``), only when no weight is left inside the grid at all.
    """

    def __init__(self, grid: OccupancyGrid, sensor: Any, rules: StateRules, *, soft: bool = False) -> None:
        from .raycast import RayCaster

        self.grid, self.rules, self.soft = grid, rules, bool(soft)
        self.offset = np.asarray(getattr(sensor, "sensor_offset", np.zeros(3)), dtype=float)
        hi_r = float(getattr(sensor, "max_range", np.inf))
        self.caster = RayCaster(grid, hi_r if np.isfinite(hi_r) else 1e3, method="march")
        self.free = ~grid.occupied
        self.inside = np.ones(grid.shape, dtype=bool)
        self.fit_distance, self.fit_expected = rules.fit_scale(sensor)

    def fit_at(self, pose: NDArray, step: Step) -> float:
        """The fit of the step's valid readings at ``pose``."""
        ranges, angles, valid = step.scan
        return scan_fit(self.caster, pose, self.offset, ranges[valid], angles[valid], self.fit_distance,
                        self.rules.min_beams)

    def assess(self, step: Step, mcl: Any, ctx: Context) -> None:
        """Fill in ``step.on_map``, ``step.fit`` and ``step.off_map`` (and an open probation's fits)."""
        step.on_map = free_share(self.grid, self.free, mcl.particles, mcl.weights)
        if step.updated and step.n_valid > 0 and is_scan(step.z):
            step.fit = self.fit_at(step.pose, step)
            if ctx.probation is not None:
                ctx.probation.add_fits(step.fit, lambda pose: self.fit_at(pose, step))
        step.off_map = step.on_map == 0.0
        if step.off_map and self.soft and ctx.soft:
            # a cloud in an obstacle the map may be wrong about is not off the map; outside the grid it is
            step.off_map = free_share(self.grid, self.inside, mcl.particles, mcl.weights) == 0.0

    def wrong(self, fit: float) -> bool:
        """A fit this poor says an agreed cloud is confidently wrong (``rules.restart_fit`` of the expected)."""
        return bool(fit < self.rules.restart_fit * self.fit_expected)


# --------------------------------------------------------------------------- recovery
class Expansion:
    """Expansion resetting (Ueda et al. 2004): an agreed cloud whose scan does not fit the map is spread wider.

    Every particle is moved by Gaussian noise of ``std = (metres, radians)``.
    A tight cloud that the odometry carried away from the robot (wheel slip, a
    bump, odometry that misses that the robot backs up) cannot be pulled back
    by the scans, since no particle is near the truth any more; spread a
    little wider, the next scans find the robot again and the cloud shrinks
    back.
    """

    def __init__(self, std: tuple[float, float]) -> None:
        xy, th = (float(v) for v in std)
        self.std = np.array([xy, xy, th])
        self.count = 0

    def apply(self, step: Step, mcl: Any, evidence: MapEvidence) -> None:
        """Spread the cloud when it agrees and the step's scan fits poorly."""
        if step.updated and step.agreed and np.isfinite(step.fit) and evidence.wrong(step.fit):
            mcl.diffuse(self.std)
            self.count += 1

    def report(self, last: int, ctx: Context) -> None:
        """Add the run's count of expansions to ``ctx.events``."""
        if self.count:
            ctx.events.append((last, f"the cloud was spread wider (expansion resetting) at {self.count} updates whose "
                                     "scan did not fit the map at the agreed place"))


class Probation:
    """A restart on probation: the old cloud (the first ``n_old`` particles) and the fresh one side by side.

    Each is resampled within itself, keeping its share of the weight. The
    estimate is the favoured place (the old one until each cloud has had
    ``PROBATION[0]`` scans fitted: one or two are no evidence), its share
    counted against the whole cloud. The fresh cloud replaces the old one only
    when it beats it on both the weight (the sensor model's evidence since the
    restart) and the recent ray-cast fit at its best cluster, and that fit is
    at least ``min_fit``. The trial ends after ``PROBATION[1]`` updates, or
    earlier (after at least ``PROBATION[0]``) when one cloud holds less than
    ``exp(PROBATION[2])`` of the weight.
    """

    def __init__(self, n_old: int, pose: NDArray, min_fit: float, window: int) -> None:
        self.n_old = int(n_old)
        self.updates = 0
        self.fits: list[list[float]] = [[], []]
        self.poses = (pose, pose)
        self.shown = 0
        self.min_fit = float(min_fit)
        self.window = int(window)

    def shares(self, mcl: Any) -> NDArray:
        """Log share of the weight of the old and of the fresh cloud."""
        lw = mcl.log_weights
        sh = np.array([_rs.logsumexp(lw[:self.n_old]), _rs.logsumexp(lw[self.n_old:])])
        return sh - _rs.logsumexp(sh)

    def mean_fits(self) -> tuple[float, float]:
        """The mean recent ray-cast fit of the old and of the fresh cloud's best cluster (0 before any)."""
        f_old, f_new = (float(np.mean(f)) if f else 0.0 for f in self.fits)
        return f_old, f_new

    def favours(self, shares: NDArray) -> int:
        """1 when the fresh cloud wins on both weight and fit (with ``PROBATION[0]`` fits each), else 0."""
        if not np.all(np.isfinite(shares)):           # one cloud has no weight left at all: the other one
            return int(np.isfinite(shares[1]))
        if min(len(f) for f in self.fits) < PROBATION[0]:     # one or two scans are no evidence yet: the old place
            return 0
        f_old, f_new = self.mean_fits()
        return int(shares[1] > shares[0] and f_new > f_old and f_new >= self.min_fit)

    def add_fits(self, shown_fit: float, fit_at: Any) -> None:
        """The fit of both places on probation (NaN: the map cannot judge: 0)."""
        for g, g_pose in enumerate(self.poses):
            f_g = shown_fit if g == self.shown else fit_at(g_pose)
            self.fits[g] = (self.fits[g] + [0.0 if np.isnan(f_g) else f_g])[-self.window:]

    def estimate(self, mcl: Any, e: Estimate) -> Estimate:
        """The estimate while on probation: the best cluster of the favoured place."""
        shares = self.shares(mcl)
        lw = mcl.log_weights
        ests = []
        for sl in (slice(0, self.n_old), slice(self.n_old, None)):
            # within the group, from the log-weights (uniform if it has none left): a group far behind would
            # underflow in mcl.weights
            wg, _ = _rs.normalize_log_weights(lw[sl])
            ests.append(_estimate(mcl.particles[sl], wg, 0.5, 0.01, 0.9))
        self.poses = tuple(g.pose if np.all(np.isfinite(g.pose)) else g.mean for g in ests)
        g = self.shown = self.favours(shares)
        eg = ests[g]
        return Estimate(eg.pose, e.mean, e.std, e.cov, float(np.exp(shares[g]) * eg.best_weight), e.n_clusters,
                        e.n_eff, eg.cluster_std, eg.cluster_cov)

    def resample(self, mcl: Any, k: int, injection: float, ctx: Context) -> bool:
        """One step of the probation's resampling; True while the trial goes on, False once decided."""
        n_old = self.n_old
        lw, every = mcl.log_weights, mcl.particles
        shares = self.shares(mcl)
        lo_min, hi, floor = PROBATION
        win = self.favours(shares)
        done = self.updates >= hi or not np.isfinite(shares[1 - win]) or (
            self.updates >= lo_min and shares[1 - win] < floor)
        parts, logw = [], []
        for g, (sl, share) in enumerate(zip((slice(0, n_old), slice(n_old, None)), shares)):
            if done and g != win:
                continue
            mcl.replace(every[sl], lw[sl] - _rs.logsumexp(lw[sl]))
            if mcl.needs_resampling():
                mcl.resample(injection=max(mcl.injection, injection) if g == 1 else 0.0)
            parts.append(mcl.particles)
            logw.append(mcl.log_weights + (0.0 if done else share))
        lw_all = np.concatenate(logw)
        mcl.replace(np.vstack(parts), lw_all - _rs.logsumexp(lw_all))
        if done:
            f_old, f_new = self.mean_fits()
            kept = "the particles drawn over the map" if win else "the old place"
            ctx.events.append((k, f"after {self.updates} updates {kept} won (weight {np.exp(shares[1]):.2g} of the "
                                  f"new, recent fit {f_new:.2f} against {f_old:.2f} of the old): the other cloud "
                                  "dropped"))
            return False
        self.n_old = len(parts[0])
        return True


class Restart:
    """Global localization again, without throwing the current hypothesis away.

    When the cloud has agreed on one place but the scans have not fitted the
    map there for ``after`` updates in a row, the filter is probably
    confidently wrong. As many uniform particles as at the start (``n_fresh``)
    are added beside the current cloud, each half of the weight, and the two
    go on :class:`Probation`. While the state is still ``searching``, a cloud
    *gathered* on one place (:meth:`StateRules.gathered`) counts as well, and
    so does an update whose fit the map cannot judge (its beams end in
    unknown cells): a cloud that collapsed onto a place the map knows nothing
    about would otherwise search there to the end of the log. And a ``lost``
    filter whose best place has not fitted the scans for ``after`` updates
    restarts too (updates the map cannot judge leave that count as it is).
    """

    def __init__(self, after: int, n_fresh: int, lost_below: float = LOST_BELOW) -> None:
        self.after, self.n_fresh, self.lost_below = int(after), int(n_fresh), float(lost_below)
        self.poor = self.lost_run = self.unjudged = 0

    def count(self, step: Step, ctx: Context, evidence: MapEvidence, gathered: bool) -> None:
        """Count the step's evidence against the place the cloud is on."""
        if np.isfinite(step.p_localized):
            self.count_p(step, ctx, gathered)
            return
        if step.updated and np.isfinite(step.fit):
            wrong = evidence.wrong(ctx.fits.mean)
            if step.agreed and wrong:
                self.poor += 1
            elif not (gathered and wrong):           # a loosely gathered cloud's poor fit leaves the count as it is
                self.poor = self.unjudged = 0
            # a lost filter whose best place does not fit the scans either, agreed on or not (outside a
            # probation; an update the map cannot judge leaves the count as it is)
            self.lost_run = self.lost_run + 1 if (ctx.state == "lost" and wrong and ctx.probation is None) else 0
        elif step.updated and gathered and is_scan(step.z) and step.n_valid >= ctx.rules.min_beams:
            self.poor += 1
            self.unjudged += 1
        if ctx.state != "lost":
            self.lost_run = 0

    def count_p(self, step: Step, ctx: Context, gathered: bool) -> None:
        """Count with ``p_localized`` (:class:`localize.reliability.ReliabilityState`): an update at which the
        place the cloud agreed or gathered on is in doubt (``p_localized`` below ``lost_below``, the state's
        threshold for *lost*) counts against it, one above resets the count; a lost filter counts whether its
        cloud agrees or not (outside a probation)."""
        if not step.updated:
            return
        wrong = step.p_localized < self.lost_below
        self.poor = self.poor + 1 if (wrong and (step.agreed or gathered)) else 0
        self.lost_run = self.lost_run + 1 if (ctx.state == "lost" and wrong and ctx.probation is None) else 0
        self.unjudged = 0

    def due(self, mcl: Any, ctx: Context) -> bool:
        """Whether to restart now."""
        return (max(self.poor, self.lost_run) >= self.after and mcl.sampler is not None
                and ctx.probation is None)

    def start(self, step: Step, mcl: Any, ctx: Context, min_fit: float) -> None:
        """Add the fresh particles and open the probation."""
        fresh = np.asarray(mcl.sampler(self.n_fresh, mcl.rng), dtype=float)
        ctx.probation = Probation(mcl.n, step.pose, min_fit, ctx.rules.fit_window)
        mcl.add_particles(fresh, share=0.5)
        if np.isfinite(step.p_localized):                   # counted with p_localized (count_p)
            n_poor = max(self.poor, self.lost_run)
            where = (f"p_localized has stayed below {self.lost_below:g} at the place the cloud agreed or gathered on"
                     if self.poor >= self.after else
                     f"the filter has been lost, with p_localized below {self.lost_below:g},")
        elif self.poor >= self.after:
            n_poor = self.poor
            where = ("the cloud gathered on a place where the map could not judge the scans (their beams end in "
                     "its unknown cells) or they did not fit it" if self.unjudged else
                     "the cloud agreed on a place where the scans have not fitted the map")
        else:
            n_poor = self.lost_run
            where = "the filter has been lost, and the scans have not fitted the map at its best place,"
        ctx.events.append((step.k, f"{where} for {n_poor} updates: {self.n_fresh} particles drawn over the map "
                                   "beside it (global localization again)"))
        self.poor = self.lost_run = self.unjudged = 0
        ctx.agreed = False
        ctx.fits.clear()


class Redraw:
    """Global localization again when the filter has nothing left, and a search while lost.

    * ``on_failure``: when every particle got zero likelihood, or every
      particle left the map's free space, all are re-drawn uniformly;
    * ``injection`` (in [0, 1)): while the state is ``lost``, this fraction
      of the particles is replaced by random ones at each resampling (and a
      resampling is forced at each update): the filter searches the map
      again instead of insisting on the place it lost.
    """

    def __init__(self, on_failure: bool = True, injection: float = 0.0) -> None:
        self.on_failure = bool(on_failure)
        self.injection = float(injection)

    def due(self, step: Step, mcl: Any) -> bool:
        """Whether every particle failed at this step (and can be re-drawn)."""
        return self.on_failure and (step.degenerate or step.off_map) and mcl.sampler is not None

    def apply(self, step: Step, mcl: Any, ctx: Context) -> None:
        """Re-draw every particle and say why."""
        ctx.probation = None
        mcl.redraw()
        why = "every particle got zero likelihood" if step.degenerate else "every particle left the map's free space"
        ctx.agreed = False
        ctx.events.append((step.k, f"{why}: particles re-drawn over the map (global localization again)"))

    def searching(self, step: Step, ctx: Context) -> bool:
        """Whether the step resamples with injection because the filter is lost."""
        return ctx.state == "lost" and self.injection > 0 and step.updated


class SensorReset:
    """Sensor resetting (Lenser and Veloso 2000), weighed as a mixture proposal: in doubt, look where the scan fits.

    At an update whose ``p_localized`` is below ``below`` (the state's
    threshold for *lost*), the filter resamples, and the share
    ``s = share * (1 - p_localized / below)`` of the new set is drawn near the
    places where this scan fits the map best: the more doubt, the more
    particles. Those places come from :func:`localize.placesearch.best_places`
    (the scan scored over a lattice of the map's free space with a blurred
    likelihood field, the best ``n_places`` distinct places climbed on the
    sensor model); each is drawn equally often, spread by ``spread``
    (metres, radians). The scan that found them does not weight them: the
    next scans do, like any particle's.

    Drawn particles are not equally weighted with the kept ones: they were
    drawn from a proposal, and get importance weights, as the dual samples of
    Mixture MCL do (Thrun, Fox, Burgard and Dellaert, *Robust Monte Carlo
    localization for mobile robots*, Artificial Intelligence 128, 2001). With
    ``p = p_localized``, the prior of the robot's pose is ``p`` times the old
    belief plus ``1 - p`` times uniform over the free space and the holes ``u`` (the belief
    is wrong: the robot may be anywhere). The set was drawn from ``1 - s``
    times the old belief plus ``s`` times the places' mixture ``q``. Where the
    old belief is nil, a drawn particle's weight against a kept one is then

        ``(1 - p) u(x) (1 - s) / (p q(x) s)``

    (``p`` no lower than 0.001). Where ``q`` is dense the weight is small: a
    place that fits the scan is not made more probable by the draw, only
    looked at. A look-alike of a place the filter believes gets a small
    share, and loses it again unless the scans favour it; when the filter is
    sure of nothing (``p`` near 0) the drawn particles weigh as much as the
    kept ones.

    ``p_localized`` is NaN without :class:`localize.reliability.ReliabilityState`:
    then nothing is drawn.

    An expert setting, not the default (``localize run --sensor-reset``;
    ``benchmarks/RESULTS.md``, ``bench_global_experiments_stop56``): in place of
    the restarts (:class:`Restart`) it finds more robots on generated buildings
    and finds a kidnapped one sooner, but the state's wrong claims there do not
    fall, and on the demo they rise: every place it finds is one more place the
    rival bank can switch the cloud onto.
    """

    def __init__(self, grid: OccupancyGrid, sensor: Any, share: float = 0.1, below: float = LOST_BELOW, *,
                 n_places: int = 16, spread: tuple[float, float] = (0.1, 0.05), seed: int = 0,
                 coarse: Any = None) -> None:
        if not 0.0 < float(share) < 1.0:
            raise ValueError(f"share must be a fraction in (0, 1); got {share!r}")
        self.grid, self.sensor = grid, sensor
        self.share, self.below, self.n_places = float(share), float(below), int(n_places)
        self.spread = np.array([spread[0], spread[0], spread[1]], dtype=float)
        self.coarse = coarse_model(grid, sensor) if coarse is None else coarse    # the rival bank's, when given
        self.log_free_volume = float(np.log(max(np.count_nonzero(grid.free | grid.holes), 1) * grid.resolution ** 2 * 2 * np.pi))
        self.rng = np.random.default_rng(seed)       # the lattice's offsets: the filter's stream is not touched
        self.n_resets = 0

    def share_at(self, step: Step) -> float:
        """The share of the particles to draw at this step (0: none)."""
        p = step.p_localized
        if not (step.updated and is_scan(step.z) and np.isfinite(p) and p < self.below and step.n_valid > 0):
            return 0.0
        return self.share * (1.0 - p / self.below)

    def propose(self, step: Step) -> None:
        """Set the step's ``reset_share`` and ``proposal`` (a :class:`localize.mcl.Proposal`) for its
        resampling; 0 and None: no reset."""
        share = self.share_at(step)
        places = self.places(step) if share > 0 else np.empty((0, 3))
        if len(places) == 0:
            step.reset_share, step.proposal = 0.0, None
            return
        self.n_resets += 1
        step.reset_share = share
        step.proposal = Proposal(self.near(places), self.log_weight(places, step.p_localized, share))

    def places(self, step: Step) -> NDArray[np.float64]:
        """Where the step's scan fits the map best, ``(k, 3)`` (k may be 0)."""
        places, _ = best_places(self.grid, self.sensor, step.z, self.rng, coarse=self.coarse, n_best=self.n_places)
        return places

    def near(self, places: NDArray) -> Any:
        """``draw(n, rng)``: ``n`` poses, each near one of ``places`` (equally often), spread by ``spread``."""
        def draw(n: int, rng: np.random.Generator) -> NDArray[np.float64]:
            at = places[rng.integers(len(places), size=n)]
            out = at + rng.normal(size=(n, 3)) * self.spread
            out[:, 2] = wrap_angle(out[:, 2])
            return out

        return draw

    def log_q(self, places: NDArray, poses: NDArray) -> NDArray[np.float64]:
        """Log density of :meth:`near`'s draws at ``poses`` (per square metre and radian)."""
        d = np.asarray(poses, dtype=float)[:, None, :] - places[None, :, :]
        d[..., 2] = wrap_angle(d[..., 2], exact=False)                   # inside a density: the fast wrap
        log_n = -1.5 * np.log(2.0 * np.pi) - float(np.sum(np.log(self.spread)))
        each = log_n - 0.5 * np.sum((d / self.spread) ** 2, axis=2)              # (n, places): one Gaussian each
        top = each.max(axis=1)
        return top + np.log(np.exp(each - top[:, None]).sum(axis=1)) - np.log(len(places))

    def log_weight(self, places: NDArray, p: float, share: float) -> Any:
        """``f(poses)``: the log importance weight of particles drawn near ``places`` against a kept particle's,
        ``log((1 - p) u (1 - share) / (p q share))`` (see the class)."""
        p = min(max(float(p), 1e-3), 1.0 - 1e-9)
        const = np.log(1.0 - p) - self.log_free_volume + np.log(1.0 - share) - np.log(p) - np.log(share)

        def f(poses: NDArray) -> NDArray[np.float64]:
            return const - self.log_q(places, poses)

        return f

    def report(self, last: int, ctx: Context) -> None:
        """How many resamplings drew particles where the scan fits (one event at the end)."""
        if self.n_resets:
            ctx.events.append((last, f"sensor resetting: at {self.n_resets} updates in doubt, part of the particles "
                                     "was drawn where the scan fits the map"))


# --------------------------------------------------------------------------- the state
class ThresholdState:
    """The *searching* / *localized* / *lost* state from :class:`StateRules`' thresholds (see there)."""

    def __init__(self, sensor: Any, rules: StateRules, evidence: MapEvidence | None) -> None:
        self.sensor, self.rules, self.evidence = sensor, rules, evidence
        self.lo_r = float(getattr(sensor, "min_range", 0.0) or 0.0)
        self.hi_r = float(getattr(sensor, "max_range", np.inf))
        self.fit_expected = rules.fit_scale(sensor)[1]
        self.good = self.bad = 0

    def confident(self, step: Step, ctx: Context) -> bool:
        """Whether the step's evidence says the estimate is right."""
        r, e = self.rules, step.estimate
        scan = is_scan(step.z)
        fit_e = ctx.fits.judging()
        if np.isfinite(fit_e):
            fits = fit_e >= r.min_fit * self.fit_expected
        else:
            fits = ctx.state == "localized" or self.evidence is None or not scan
        ok = ((not scan or step.n_valid >= r.min_beams) and e.best_weight >= r.min_share
              and e.spread <= r.max_spread and (e.cluster_std is None or e.cluster_std[2] <= r.max_heading_std)
              and fits)
        if ok and r.probe_shift > 0 and scan and step.n_valid > 0:
            ok = pinned(self.sensor, step.pose, step.z, r.probe_shift, r.min_contrast, self.lo_r, self.hi_r)
        return bool(ok)

    def interrupt(self, ctx: Context) -> None:
        """A restart: a localized filter is lost now, and the confident run starts again."""
        self.good = 0
        if ctx.state == "localized":
            ctx.state = "lost"

    def update(self, step: Step, ctx: Context) -> str:
        """The state after this step (``ctx.state`` is updated too)."""
        prev = cur = ctx.state
        if step.degenerate or step.off_map:
            self.good = 0
            if cur == "localized":
                cur = "lost"
        elif step.updated:
            if self.confident(step, ctx):
                self.good += 1
                self.bad = 0
                if cur != "localized" and self.good >= self.rules.hold:
                    cur = "localized"
            else:
                self.good = 0
                self.bad += 1
                if cur == "localized" and self.bad >= self.rules.hold_lost:
                    cur = "lost"
        ctx.state = cur
        if prev == "localized" and cur == "lost":
            # the fits made while localized vouch for that place, not for wherever the cloud goes now: being
            # localized again takes fits judged since the loss (an update the map cannot judge gives none)
            ctx.fits.since_loss = []
        elif cur == "localized" or ctx.probation is not None:
            ctx.fits.since_loss = None
        if cur != prev:
            ctx.events.append((step.k, f"state {prev} -> {cur}"))
        return cur
