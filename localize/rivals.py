"""Is there another place where the scans fit as well? The estimate against the rivals it has not forgotten.

The fit of a scan at the estimate (:mod:`localize.reliability`) cannot tell a
look-alike: a room whose mirror image is another room, a corridor whose every
stretch looks the same, a place that fits well enough while the robot's place
fits better. Once the particle filter has settled on one of them, resampling
has removed the others: the cloud no longer knows they exist.

:class:`RivalBank` keeps them. Every hypothesis, the estimate's place and
each rival, is a small particle filter of its own (``particles`` particles,
chapter 6), moved by the robot's odometry through the filter's own motion
model (chapter 4) and weighed on the scans the filter uses with the filter's
sensor model (chapter 5). A rival is the place where the robot would be if
the estimate is in the wrong place (a room's mirror image is the half turn
about its centre); ``G`` relates its particles' mean to the filter's estimate,
the robot at ``G ∘ x_t``. Each hypothesis scores a scan by the mean likelihood
of its particles, a particle filter's estimate of ``p(z_t | z_1..t-1)`` under
that hypothesis (its marginal likelihood), and each rival keeps the log-odds
it has gathered against the estimate's place since it was found,

.. math:: L_i \\leftarrow L_i + \\log \\hat p(z_t \\mid \\text{rival } i) - \\log \\hat p(z_t \\mid \\text{estimate}),

the histogram filter of chapter 2 over a handful of hypotheses. The estimate's
share of the posterior, ``1 / (1 + sum_i exp(s_i L_i))`` (even prior odds), is
a third estimate of "am I localized?": a rival that fits as well holds it at
a half.

Why a particle filter per hypothesis and not a pose: a place is never scored
exactly where the robot is. Stop 64 found the bank's rivals moved rigidly with
the estimate, each scored at its best of a few small moves, paid for every
offset between the two alone (a rival found 0.04 m from the robot slid off it
while the estimate converged elsewhere and lost 56 nats in four scans), and a
rival moved to its best move at every scan followed the scan's noise instead.
Tracked alike, every place follows its own scans with the same model of motion
and noise, and no place is favoured by how it is followed: the estimate's
place is the bank's own particles too, not the filter's estimate (the filter
only tells the bank where the estimate is, to keep the rivals at least
``radius`` from it and to move the cloud when a rival wins).

The sensor model counts its beams as independent readings of an exact map;
they are neither, and its log-likelihood ratios are too sure of themselves
(a cupboard the map misplaces costs one place three nats at one scan, the
other place at the next). The share believes each rival's odds only as far
as its own per-scan differences support them: ``s_i`` is
:func:`evidence_scale` of the bank's record of them, ``2 |mean| / variance``
at most 1, from the identity that the variance of an exact Gaussian
log-likelihood ratio is twice its mean (:attr:`RivalBank.believed`). A place
that loses a few nats at every scan is believed in full; one whose
differences swing by more than their mean is believed less, and the move to
a rival (below) is decided on the same believed odds: two places that no scan
tells apart gather differences of either sign, and their raw sum, a random
walk, would reach any odds in the end. Rivals are
found every ``every`` scans by a search over the whole map for the places where
the newest scan fits best (:func:`localize.placesearch.best_places`), ranked
again on the last ``window`` scans; a new rival starts with the log-odds of
every scan since the place was chosen (up to ``history``), taken along the
estimate's trajectory, so that a place that fits the last few scans does not
outweigh one that has fitted many, and with a copy of the estimate's particles
about its place. Every rival is hill-climbed on the window when the search
runs, the estimate's place alike.

The search over the whole map ranks places on the newest scan alone, and one
scan can rank the robot's place below a dozen look-alikes: after a turn the
odometry missed, the filter's estimate may settle a metre or two from the
robot and turned by half a radian, and the robot's place fits the scans after
it better by a few nats each, yet the newest scan alone does not single it out
(``tests/test_state_scenarios.py``, the missing turn). So the search also looks
around the estimate: poses 1.25 and 2 ``radius`` away in eight directions,
turned by 0 and +-0.5 rad (the near misses that the evidence model's
calibration counts as wrong, :func:`localize.reliability.calibrate`), ranked
on the window by the coarse model of the search and climbed like the others.
A near miss joins the bank only if the scans since the place was chosen fit
it better than the estimate's place (odds above even): around any estimate
lies a continuum of poses, and a slope of the estimate's own peak is no other
place.

When a rival's believed odds reach those the state calls *localized*
(``LOCALIZED_AT``, 19 to 1 against the estimate) over at least a window of
scans, the filter was on the wrong place:
:meth:`localize.reliability.ReliabilityState.take_switch` moves the cloud there
by ``G`` (through :meth:`RivalBank.switch`, which keeps the
old place as a rival, with the odds it lost by), so that the decision can be
reversed by later scans. A restart that lands on the same look-alike again
would not.

**Limits, measured** (``benchmarks/RESULTS.md``, ``bench_global_experiments_stop65``). A rival placed by hand
10 cm and 0.05 rad off its place loses nats in the first scans, while its particles reach the place, and the
bank is then sure of a hall that no scan can tell from its mirror image (``tests/test_rivals.py``, a strict xfail):
a place's particles start where it was found, with no spread of their own beyond the estimate's. The search's
climb moves the rivals it finds in steps down to 3 cm before they start. Sixteen particles per place lost the robot
where the filter's thousands did not (the estimate's place drifted 0.4 m and a mirror image won); the default is
three times that. In a world that a half turn maps onto itself, the mirror image holds the share near a half
for as long as no scan tells the two apart, and the state says so: ``localize demo``'s seed 7 ends lost 0.12 m
from the robot. Earlier designs and what they measured: ``bench_global_experiments_stop55`` to ``_stop64``.

This is multi-hypothesis tracking in the spirit of Jensfelt and Kristensen's
(*Active global localization for a mobile robot using multiple hypothesis
tracking*, IEEE T-RA 2001), with the correlative search of scan matchers
(Olson, *Real-time correlative scan matching*, ICRA 2009) to find the
hypotheses, applied to the question of Akai's reliability estimation
(*Reliable Monte Carlo localization for mobile robots*, 2023).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_positive
from .geometry import compose, inverse, mean_pose, relative
from .grid import OccupancyGrid
from .motion import OdometryMotion
from .placesearch import best_places, climb_on, coarse_model, distinct, scores, stencil
from .resample import logsumexp, systematic

__all__ = ["RivalBank", "evidence_scale"]


#: Places the search finds per rival kept: the newest scan alone ranks many look-alikes alike (every corner of
#: a room fits a scan of a corner); the window of scans ranks them again, and the best are kept.
SEARCHED = 4

#: The near misses searched around the estimate (:meth:`RivalBank.search`): distances in units of ``radius``, and
#: the largest turn (radians) of a near miss, the bank's and the calibration's (:func:`localize.reliability.calibration_fits`).
NEAR_RINGS = (1.25, 2.0)
NEAR_TURN = 0.5


def _added(m: NDArray) -> NDArray[np.float64]:
    """Row sums of ``m`` added column by column (the order in which the scans came)."""
    total = np.zeros(m.shape[0])
    for col in m.T:
        total += col
    return total


def evidence_scale(d: ArrayLike) -> NDArray[np.float64]:
    """How far to believe a sum of per-scan log-likelihood differences, from the differences themselves (per row).

    If each difference ``d_t`` were an exact log-likelihood ratio, drawn as a
    Gaussian ``N(mu, sigma^2)``, its variance would be ``2 |mu|``: every
    log-likelihood ratio ``d = log p1(z) - log p0(z)`` obeys ``E[exp(d)] = 1``
    for ``z`` drawn from ``p0`` (and ``E[exp(-d)] = 1`` from ``p1``), and for a
    Gaussian that says ``mu + sigma^2 / 2 = 0``. A sensor model that counts its beams as independent readings of
    an exact map scatters its differences far wider than that: a cupboard the
    map misplaces costs one place three nats at one scan and the other place
    at the next. Read as Gaussian evidence with the mean and variance the
    differences show, their sum is worth ``2 |mean| / variance`` times itself
    (the log-likelihood ratio of ``N(mean, variance)`` against
    ``N(-mean, variance)``), never more than the sensor model says (at most
    1). Fewer than two differences (NaN: no record) say nothing of their own
    spread: 1.

    Examples
    --------
    >>> evidence_scale([[-3.0, -3.5, -2.5, -3.0]]).round(2)      # one place loses at every scan: the sum holds
    array([1.])
    >>> evidence_scale([[-3.0, 2.0, -4.0, 1.0]]).round(2)        # +-3 nats about -1: worth a quarter of it
    array([0.23])
    >>> evidence_scale([[np.nan, -6.0]]).round(2)                # one scan: no spread to judge by
    array([1.])
    """
    d = np.atleast_2d(np.asarray(d, dtype=float))
    n = np.sum(np.isfinite(d), axis=1)
    out = np.ones(d.shape[0])
    many = n >= 2
    if many.any():
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.nanmean(d[many], axis=1)
            var = np.nanvar(d[many], axis=1, ddof=1)
            out[many] = np.where(var > 2.0 * np.abs(mean), 2.0 * np.abs(mean) / var, 1.0)
    return out


class RivalBank:
    """The estimate against the other places the robot could be, each place tracked by particles of its own.

    Parameters
    ----------
    grid : OccupancyGrid
        The map.
    sensor : range sensor model
        The filter's (``log_likelihood(poses, ranges, angles)``).
    radius : float
        Metres: a rival is at least this far from the estimate (what "right" means).
    n_rivals : int
        Rivals kept (the best by their odds).
    every : int
        Search for new rivals every so many scans the filter used.
    window : int
        Scans the search ranks its places on and climbs every rival on; no switch before the bank has seen this many.
    history : int
        Scans kept since the place was chosen: a new rival's odds are summed over them (memory, not a threshold).
    switch_odds : float
        A rival this much more probable than the estimate takes its place (:meth:`switch`).
    seed : int
        Seed of the bank's own generator, for the search and the particles (the filter's random stream is not
        touched).
    motion : callable, optional
        The filter's motion model, ``motion(poses, (prev_odom, odom), rng)`` (an
        :class:`~localize.motion.OdometryMotion`); default: ``OdometryMotion()``.
    particles : int
        Particles per place, the estimate's and each rival's.

    Examples
    --------
    A hall with pillars placed with half-turn symmetry: a scan fits the robot's pose and its mirror image alike.

    >>> from localize.maps import symmetric_room
    >>> from localize.sensors import LikelihoodField
    >>> from localize.raycast import RayCaster
    >>> grid = symmetric_room(tell=False)
    >>> lf = LikelihoodField(grid, 8.0, sigma_hit=0.1)
    >>> bank = RivalBank(grid, lf, seed=0)
    >>> angles = np.linspace(-np.pi, np.pi, 60, endpoint=False)
    >>> x = np.array([2.0, 4.5, 0.3])
    >>> z = (RayCaster(grid, 8.0).cast(x[None], angles)[0], angles)
    >>> share = bank.observe(x, z)
    >>> mirror = bank.places(x)[np.argmax(bank.L)]
    >>> bool(np.hypot(*(mirror[:2] - [10.0, 1.5])) < 0.2), 0.25 < share < 0.75  # the half turn about (6, 3)
    (True, True)
    """

    def __init__(self, grid: OccupancyGrid, sensor: Any, *, radius: float = 1.0, n_rivals: int = 4, every: int = 5,
                 window: int = 10, history: int = 200, switch_odds: float = 19.0, seed: int = 0,
                 motion: Any = None, particles: int = 48) -> None:
        self.grid, self.sensor = grid, sensor
        self.radius = check_positive(radius, "radius", "metres")
        self.n_rivals, self.every, self.window, self.history = (
            check_count(v, n) for v, n in ((n_rivals, "n_rivals"), (every, "every"), (window, "window"),
                                           (history, "history")))
        self.switch_log_odds = float(np.log(check_positive(switch_odds, "switch_odds", "odds")))
        self.rng = np.random.default_rng(seed)
        self.coarse = coarse_model(grid, sensor)
        self.scans: deque = deque(maxlen=self.history)     # (estimate, z) of the scans used since the place
        self.G = np.empty((0, 3))                          # each rival: robot at G ∘ estimate
        self.L = np.empty(0)                               # each rival's log-odds against the estimate
        self.D = np.empty((0, 0))                          # each rival's per-scan differences, one column per scan
        self.used = 0
        self.motion = OdometryMotion() if motion is None else motion
        self.k = check_count(particles, "particles")
        self.offsets = np.zeros((1, self.k, 3))            # each place's particles as poses relative to the place
        self.prev: NDArray | None = None                   # (the estimate's first); the estimate at the last scan,
        self.prev_odom: NDArray | None = None              # and the odometry reading then

    def hold(self, G: ArrayLike, L: ArrayLike, D: ArrayLike | None = None) -> None:
        """Hold the rivals ``G`` (``(R, 3)``) with log-odds ``L`` (``(R,)``) against the estimate, and their
        per-scan differences ``D`` (``(R, S)``, one column per scan the bank keeps; default: no record, NaN,
        so that their odds are believed as they are), each with a copy of the estimate's particles about its place.
        A rival placed by hand (a test, a caller's guess) starts here."""
        G, L = np.atleast_2d(np.asarray(G, dtype=float)).reshape(-1, 3), np.asarray(L, dtype=float).reshape(-1)
        D = np.full((len(G), len(self.scans)), np.nan) if D is None else np.asarray(D, dtype=float)
        if len(L) != len(G) or D.shape != (len(G), len(self.scans)):
            raise ValueError(f"need G (R, 3), L (R,) and D (R, {len(self.scans)}: one column per scan kept); got "
                             f"{G.shape}, {L.shape} and {D.shape}")
        self.G, self.L, self.D = G, L, D
        self.offsets = np.concatenate([self.offsets[:1], np.repeat(self.offsets[:1], len(G), axis=0)])

    @property
    def believed(self) -> NDArray[np.float64]:
        """Each rival's log-odds as far as its own per-scan differences support them: ``L`` times
        :func:`evidence_scale` of its differences (``L`` itself for a rival without a record of them)."""
        return self.L * evidence_scale(self.D)

    @property
    def share(self) -> float:
        """The estimate's posterior among itself and the rivals (1 with none), on the :attr:`believed` odds."""
        return float(np.exp(-logsumexp(np.concatenate([[0.0], self.believed]))))

    def places(self, pose: NDArray) -> NDArray[np.float64]:
        """Where each rival puts the robot when the estimate is ``pose``: ``(R, 3)``."""
        return compose(self.G, np.asarray(pose, dtype=float)[None])

    def observe(self, pose: ArrayLike, z: tuple, odom: ArrayLike | None = None) -> float:
        """Score the scan ``z`` the filter used at the estimate's place and at each rival; search when due.

        ``pose`` is the filter's estimate, ``odom`` the odometry reading at this scan (the places' particles move
        by the odometry since the last scan the bank saw; without one, by the estimate's own step). Returns the
        estimate's :attr:`share`.
        """
        pose = np.asarray(pose, dtype=float)
        if len(self.scans) == self.scans.maxlen:            # the oldest scan is forgotten, and its differences
            self.D = self.D[:, 1:]
        self.scans.append((pose, z))
        d = np.full(len(self.G), np.nan)
        m = self._track(pose, z, None if odom is None else np.asarray(odom, dtype=float))
        if len(self.G) and np.isfinite(m[0]):
            d = m[1:] - m[0]
            self.L = self.L + d
        self.D = np.column_stack([self.D, d])
        self._keep(np.isfinite(self.L))                     # a rival that left the map, or ran into a wall
        self.used += 1
        if self.used % self.every == 0 or self.used <= 1:
            self.search(pose)
        return self.share

    def _track(self, pose: NDArray, z: tuple, odom: NDArray | None = None) -> NDArray[np.float64]:
        """Move every place's particles with the motion model (by the odometry since the last scan, or by the
        estimate's step without it), weigh them on the scan and resample; return each place's mean likelihood of
        the scan (log), the estimate's first."""
        G = np.vstack([np.zeros((1, 3)), self.G])
        prev = pose if self.prev is None else self.prev
        before = compose(compose(G, prev[None])[:, None, :], self.offsets).reshape(-1, 3)
        if self.prev is None:
            moved = before
        elif odom is not None and self.prev_odom is not None:
            moved = self.motion(before, (self.prev_odom, odom), self.rng)    # the odometry, as the filter moves
        else:
            moved = self.motion(before, (prev, pose), self.rng)
        self.prev_odom = odom
        ll = scores(self.sensor, moved, z).reshape(len(G), self.k)
        m = np.array([logsumexp(row) for row in ll]) - np.log(self.k)
        moved = moved.reshape(len(G), self.k, 3)
        for h in range(len(G)):
            if np.isfinite(m[h]):
                moved[h] = moved[h, systematic(np.exp(ll[h] - np.max(ll[h])), self.rng)]
        centre = np.array([mean_pose(q) for q in moved])                     # the rivals' places follow their
        centre[0] = pose                                                     # particles; the estimate's is its own
        self.G = compose(centre[1:], inverse(pose)[None])
        self.offsets = compose(inverse(centre)[:, None, :], moved)
        self.prev = pose
        return m

    def _keep(self, mask: NDArray[np.bool_]) -> None:
        self.G, self.L, self.D = self.G[mask], self.L[mask], self.D[mask]
        self.offsets = self.offsets[np.concatenate([[True], mask])]

    def _scan_ll(self, hyps: NDArray, shape: NDArray, scans: list | None = None, model: Any = None) -> NDArray[np.float64]:
        """Log-likelihood ``(H, S)`` of each of the window's scans (or ``scans``) for hypotheses ``(H, 3)`` (poses
        now) moved along ``shape`` (one pose per scan, in the frame of the estimate now)."""
        scans = list(self.scans)[-self.window:] if scans is None else scans
        ll = np.zeros((len(hyps), len(scans)))
        for j, (_, z) in enumerate(scans):
            ll[:, j] = scores(self.sensor if model is None else model, compose(hyps, shape[j][None]), z)
        return ll

    def _window_ll(self, hyps: NDArray, shape: NDArray, scans: list | None = None, model: Any = None) -> NDArray[np.float64]:
        """The sum of :meth:`_scan_ll` over the scans (added scan by scan)."""
        return _added(self._scan_ll(hyps, shape, scans, model))

    def _climb(self, hyps: NDArray, shape: NDArray, iterations: int = 8) -> tuple[NDArray, NDArray]:
        """Hill-climb each hypothesis on the window's log-likelihood (:func:`localize.placesearch.climb_on`)."""
        return climb_on(lambda p: self._window_ll(p, shape), hyps, stencil(0.25, 0.05, 4), iterations)

    def search(self, pose: NDArray) -> None:
        """Hill-climb the rivals on the window, add the best new places for the newest scan and the near misses
        around the estimate that the scans favour over it, keep the best."""
        z_now = self.scans[-1][1]
        every = np.array([p for p, _ in self.scans])
        shape = relative(pose, every[-self.window:])                          # the window in the current frame
        found, _ = best_places(self.grid, self.sensor, z_now, self.rng, coarse=self.coarse,
                               n_best=SEARCHED * self.n_rivals, away_from=pose, radius=self.radius)
        old = self.places(pose)
        if len(old):
            far = np.min(np.hypot(*(found[:, None, :2] - old[None, :, :2]).transpose(2, 0, 1)), axis=1) >= self.radius
            found = found[far]
        if len(found) > self.n_rivals:       # the places that fit the newest scan best, ranked on the window
            found = found[np.argsort(-self._window_ll(found, shape))[:self.n_rivals]]
        near = self._near(pose)                # ranked on the window by the coarse model: they are climbed first
        near = near[np.argsort(-self._window_ll(near, shape, model=self.coarse))[:self.n_rivals]]
        n_near = len(near)
        found = np.vstack([found, near])
        if len(old) + len(found) == 0:
            return
        hyps, ll = self._climb(np.vstack([pose[None], old, found]), shape)   # the estimate climbed alike
        est_now, est_ll, hyps, ll = hyps[0], ll[0], hyps[1:], ll[1:]
        if not np.isfinite(est_ll):
            return
        n_old = len(old)
        new = hyps[n_old:]
        w = self._scan_ll(np.vstack([est_now[None], new]), shape)             # the new rivals' differences, scan
        d_new = w[1:] - w[0]                                                   # by scan
        if len(self.scans) > self.window:      # a new rival is weighed on every scan since the place was chosen
            older = list(self.scans)[:-self.window]
            o_shape = relative(pose, every[:-self.window])
            o = self._scan_ll(np.vstack([pose[None], new]), o_shape, older)
            o_ll = _added(o)
            est_ll, ll = est_ll + o_ll[0], np.concatenate([ll[:n_old], ll[n_old:] + o_ll[1:]])
            d_new = np.hstack([o[1:] - o[0], d_new])
        L = np.concatenate([self.L, ll[n_old:] - est_ll])
        D = np.vstack([self.D, d_new])
        ok = np.isfinite(L) & (np.hypot(*(hyps[:, :2] - pose[:2]).T) >= self.radius)
        ok[len(ok) - n_near:] &= L[len(L) - n_near:] > 0.0     # a near miss counts once the scans favour it
        G = compose(hyps, inverse(pose)[None])
        order = [i for i in np.argsort(-L) if ok[i]]
        kept = distinct(hyps, order, self.n_rivals, self.radius, heading=np.inf)   # distinct places, the best first
        offsets = np.concatenate([self.offsets[1:], np.repeat(self.offsets[:1], len(hyps) - n_old, axis=0)])
        self.G, self.L, self.D = G[kept], L[kept], D[kept]
        self.offsets = np.concatenate([self.offsets[:1], offsets[kept]])

    def _near(self, pose: NDArray) -> NDArray[np.float64]:
        """Poses beyond ``radius`` around the estimate, turned by up to half a radian: where the robot is if the
        filter was carried away by its odometry (the near misses of :func:`localize.reliability.calibrate`)."""
        b = np.arange(8) * np.pi / 4
        d = self.radius * np.array(NEAR_RINGS)
        h = np.array([-NEAR_TURN, 0.0, NEAR_TURN])
        B, D, H = (a.ravel() for a in np.meshgrid(b, d, h, indexing="ij"))
        return np.column_stack([pose[0] + D * np.cos(B), pose[1] + D * np.sin(B), pose[2] + H])

    def winner(self) -> int | None:
        """The rival that should take the estimate's place (odds of ``switch_odds`` or more, over at least a
        window of scans: a place the search found for one scan fits that scan better than the estimate almost
        always), or None."""
        if len(self.L) == 0 or len(self.scans) < self.window:
            return None
        b = self.believed
        i = int(np.argmax(b))
        return i if b[i] >= self.switch_log_odds else None

    def switch(self, i: int) -> NDArray[np.float64]:
        """Make rival ``i`` the estimate: returns its transform ``G`` (move the cloud by it); the old estimate
        becomes a rival with the odds it lost by, and the others keep theirs, against the new estimate."""
        g, li = self.G[i].copy(), float(self.L[i])
        g_inv = inverse(g)
        others = np.arange(len(self.G)) != i
        self.G = np.vstack([compose(self.G[others], g_inv[None]), g_inv[None]])
        self.L = np.concatenate([self.L[others] - li, [-li]])
        self.D = np.vstack([self.D[others] - self.D[i], -self.D[i]])
        self.offsets = np.concatenate([self.offsets[1 + i][None], self.offsets[1:][others], self.offsets[:1]])
        self.scans = deque(((compose(g, p), z) for p, z in self.scans), maxlen=self.history)
        if self.prev is not None:
            self.prev = compose(g, self.prev)
        return g

    def clear(self) -> None:
        """Forget the rivals and the window (the estimate moved to a place the bank did not choose)."""
        self.scans.clear()
        self.G, self.L, self.D = np.empty((0, 3)), np.empty(0), np.empty((0, 0))
        self.offsets, self.prev, self.prev_odom = np.zeros((1, self.k, 3)), None, None
        self.used = 0
