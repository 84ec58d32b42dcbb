"""Am I localized? A probability, calibrated on the user's own map and sensor, filtered over the scans.

Whether the filter's estimate is right is a hidden binary state, ``right``
(within ``right_radius`` of the robot) or ``wrong``. The filter never sees the
truth, but every scan gives evidence: how well the scan fits the map at the
estimate (:func:`scan_fits`, as :func:`localize.evidence.scan_fit`). The Bayes filter of chapter 1
(:mod:`localize.discrete`) turns that evidence into a belief, scan by scan:

* **prediction**: a right estimate stays right with probability
  ``1 - p_lose`` per step (:class:`ReliabilityState`: per update of the
  particle filter, not per scan of the log); a wrong one becomes right only with ``p_find``
  (:class:`ReliabilityState` uses 0: the particle filter finds the robot by
  moving its estimate, and a new place is a new hypothesis);
* **correction**: ``p(fit | right)`` and ``p(fit | wrong)``, the
  :class:`EvidenceModel`.

The evidence model is not chosen on benchmark logs: :func:`calibrate` learns
it at start-up from the user's own map and sensor model -- scans simulated at
poses drawn over the map's free space from the sensor model's own mixture
(:func:`simulate_scans`), scored at poses a little off (right: errors from the
sensor's precision, :func:`converged_error`, up to half the radius,
:func:`error_levels`) and at wrong poses: a metre or more off, and the place
elsewhere in the map where the scan fits best (:func:`look_alikes`, the
look-alike a particle filter would select). A map with look-alike rooms gives
a ``p(fit | wrong)`` with mass at high fits, and the filter then needs more
scans to be sure. ``p(fit | right)`` keeps a uniform share :data:`MAP_ERROR`
for the scans at which the map is wrong (a moved cabinet), so that one poor
fit never condemns a right estimate.

:class:`ReliabilityState` is the run driver's state policy built on it
(the default of ``localize run``, ``--state probability``; ``run_filter(..., state="probability")``):
``p_localized`` is the geometric mean of the belief and the particle filter's
own mass near its estimate (the smallest of the weight within the radius, a
five-pose probe that a featureless corridor cannot pass, and the estimate's
share against the look-alike places a :class:`~localize.rivals.RivalBank`
keeps, which also moves the cloud to a rival that wins); *localized* from
0.95, *lost* below 0.7, or as soon as the place part alone (the mass, the
probe, the share) no longer allows 0.95: the margin forgives a dip in the
fit, never another place.

**Limits, measured** (``benchmarks/RESULTS.md``, ``bench_global_state_probability``,
``tests/test_state_scenarios.py`` and chapter 8). The bank holds a handful of
look-alikes, not a continuum: in a long featureless corridor ``p_localized``
reaches 0.55-0.73 far off, though the state never says localized there (a
strict xfail; with the simulator's default laser, whose beams that hit nothing
read a few centimetres short of the range and fit the corridor's far end, it
said localized 21 m off: ``BeamModel``'s ``no_return``). In ``localize demo``'s
office (a room nearly symmetric under a half turn, whose map shows a cupboard
that is not there) the mirror image fits the scans better than the true place
over stretches of tens of scans, and the state says localized there until
the scans tell them apart. The threshold state (``--state thresholds``),
the command line's default until stop 53, does no better on any of these
(``bench_global_experiments_stop53``). On buildings that none of this was
chosen on (``benchmarks/bench_state.py``: generated grids of alike rooms,
halls of boxes, the office and the symmetric hall, each seen by four kinds
of laser), the probability errs the other way from the real logs: it is
over-confident. Of the scans it calls localized, 3.4% and 1.9% (two draws, stop
65; 5.6% and 2.0% at stop 62) are more than 1 m off (the threshold state: 10.0% and 8.3%), most of them in
the symmetric hall and the grids of alike rooms. Until stop 64 the cause was mostly the bank's
(``bench_global_experiments_stop55`` to ``_stop64``): it scored the estimate,
which the filter keeps where the scans fit best, against rivals that followed
it rigidly, so a rival on the robot's place but a few centimetres off it lost
nats at most scans; since stop 65 every place, the estimate's too, is tracked
by a particle filter of its own (:mod:`localize.rivals`). The bank still counts
two poses less than a metre apart as one place whatever their headings.
Measured against the truth (``benchmarks/why_wrong.py``,
``bench_global_experiments_stop57``), most of those wrong claims rest on scans
that barely tell the two places apart (a few nats over tens of scans, either
way): a bank that held the robot's place and weighed it as fairly as the
estimate would leave *localized* possible at about a fifth of them (draw 0:
117 of 537). In the demo's office (seeds 0-9, localized more than 0.5 m off)
the wrong claims fell from 74 to 55 when the bank believed its odds only as
far as their spread supports them, to 43 when the margin between the
thresholds was kept for the fit, and to 6 when the places were tracked (stop
65). At five of those six the scans favour the wrong place under the
filter's own sensor model (``benchmarks/why_wrong.py --demo 10``), and no
bank can help there.

This follows the reliability estimation of Akai et al. (*Reliable Monte Carlo
localization for mobile robots*, 2023; als_ros), where a classifier's output
enters a binary filter of the same shape; here the class-conditional
densities come from simulation on the user's map instead of training data.

Examples
--------
>>> from localize.maps import office
>>> from localize.sensors import LikelihoodField
>>> lf = LikelihoodField(office(), 8.0, sigma_hit=0.1)
>>> model = calibrate(office(), lf, np.linspace(-np.pi, np.pi, 36, endpoint=False), np.random.default_rng(0))
>>> belief = LocalizedBelief(model)
>>> [round(belief.step(0.95), 2) for _ in range(3)]          # scans that fit: sure after two
[0.69, 0.99, 1.0]
>>> [round(belief.step(0.05), 2) for _ in range(4)]          # scans that fit nowhere: lost after a few
[0.89, 0.38, 0.05, 0.01]
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass
from decimal import ROUND_FLOOR, Decimal
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import discrete
from ._checks import check_count, check_positive, check_rng
from .evidence import scan_fits
from .geometry import compose, relative, wrap_angle
from .grid import OccupancyGrid
from .raycast import RayCaster
from .resample import logsumexp
from .rivals import NEAR_TURN, RivalBank
from .sensors import sensor_poses

__all__ = ["EvidenceModel", "calibrate", "calibrate_once", "content_key", "calibration_fits", "simulate_scans", "look_alikes", "converged_error", "error_levels",
           "LocalizedBelief",
           "ReliabilityState", "reliability_table", "floor_text", "LOCALIZED_AT", "LOST_BELOW"]

def floor_text(v: float, decimals: int) -> str:
    """``v`` written with ``decimals`` decimals, rounded down (empty for NaN): a threshold that is a multiple of
    ``10**-decimals`` compares with the written value as with ``v`` itself, so a probability just below 0.95
    never reads "0.95" (the state's events, ``trajectory.csv``).

    Examples
    --------
    >>> floor_text(0.94996, 4), floor_text(0.9497, 3), floor_text(0.95, 4), floor_text(float("nan"), 4)
    ('0.9499', '0.949', '0.9500', '')

    A value that already has no more decimals is written as it is (``0.57 * 100`` is 56.99999999999999 in floating
    point, and ``floor`` of it would write 0.56): the rounding is done on the value's shortest decimal form.

    >>> floor_text(0.57, 2), floor_text(0.0003, 4), floor_text(1e-05, 4), floor_text(1.0, 2)
    ('0.57', '0.0003', '0.0000', '1.00')
    """
    v = float(v)
    if not np.isfinite(v):
        return "" if np.isnan(v) else f"{v:.{decimals}f}"
    # repr is the shortest decimal that reads back as v, and reading is monotone: v < 0.95 exactly when it is
    return str(Decimal(repr(v)).quantize(Decimal(1).scaleb(-decimals), rounding=ROUND_FLOOR))


#: Share of the scans at a right estimate whose fit the map gets wrong for reasons no sensor model simulates
#: (a moved cabinet, a crowd, glass, a door left open): the robust part of ``p(fit | right)``, as ``z_rand``
#: is the robust part of a beam's likelihood (the same 0.1 as the command line's ``z_rand``; not fitted).
MAP_ERROR = 0.1

#: The documented thresholds of :class:`ReliabilityState` on ``p_localized``: *localized* from this ...
LOCALIZED_AT = 0.95
#: ... and a localized filter *lost* below this (restarts count the updates below it too).
LOST_BELOW = 0.7

#: Index of the two states in a belief ``[p(wrong), p(right)]``.
WRONG, RIGHT = 0, 1


@dataclass(frozen=True)
class EvidenceModel:
    """``p(fit | right)`` and ``p(fit | wrong)`` as histograms of the scan fit over ``[0, 1]``.

    Attributes
    ----------
    edges : ndarray (K + 1,)
        Bin edges of the fit.
    p_right, p_wrong : ndarray (K,)
        Probability of each bin given a right / wrong estimate (each sums to one).
    n_right, n_wrong : int
        Calibration samples behind each histogram.
    right_radius : float
        What "right" means (metres).
    spreads : tuple of float
        Errors (m per axis) of the right estimates ``p(fit | right)`` was calibrated at (:func:`error_levels`).
    p_right_at : ndarray (L, K), optional
        ``p(fit | right)`` at each of them; :attr:`p_right` is their mean.
    """

    edges: NDArray[np.float64]
    p_right: NDArray[np.float64]
    p_wrong: NDArray[np.float64]
    n_right: int
    n_wrong: int
    right_radius: float
    spreads: tuple = ()
    p_right_at: NDArray[np.float64] | None = None

    def likelihood(self, fit: float) -> NDArray[np.float64]:
        """``[p(fit | wrong), p(fit | right)]``; a NaN fit (the map cannot judge) is no evidence: ``[1, 1]``."""
        if not np.isfinite(fit):
            return np.ones(2)
        k = int(np.clip(np.searchsorted(self.edges, fit, side="right") - 1, 0, len(self.p_right) - 1))
        return np.array([self.p_wrong[k], self.p_right[k]])

    def posterior(self, fit: float, prior: float = 0.5) -> float:
        """``p(right | fit)`` for one scan with prior ``prior`` (no filtering over time)."""
        return float(discrete.update([1.0 - prior, prior], self.likelihood(fit))[RIGHT])


def _histogram(values: NDArray, edges: NDArray) -> NDArray:
    counts = np.histogram(np.clip(values, 0.0, 1.0), bins=edges)[0].astype(float)
    return (counts + 1.0) / (counts.sum() + len(counts))       # Laplace: no bin is impossible


def simulate_scans(grid: OccupancyGrid, sensor: Any, poses: ArrayLike, angles: ArrayLike,
                   rng: np.random.Generator) -> NDArray[np.float64]:
    """Scans ``(N, B)`` at ``poses`` drawn from the sensor model's own mixture (PR section 6.3).

    Each beam is a hit (the ray-cast range plus Gaussian noise of ``sigma_hit``)
    with weight ``z_hit``, a short reading (exponential below the cast range,
    rate ``lambda_short``; something the map does not show) with ``z_short``, a
    random reading (uniform up to ``max_range``) with ``z_rand``, or a max-range
    reading with ``z_max``; a ray that hits nothing reads ``max_range``. The
    weights are the model's (missing ones count as 0), so the calibration sees
    as much clutter as the user's sensor model expects.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.sensors import LikelihoodField
    >>> lf = LikelihoodField(office(), 8.0, sigma_hit=0.1)
    >>> z = simulate_scans(office(), lf, [[3.0, 3.0, 0.0]], np.linspace(-1, 1, 5), np.random.default_rng(0))
    >>> z.shape, bool(np.all((z >= 0) & (z <= 8.0)))
    ((1, 5), True)
    """
    rng = check_rng(rng)
    a = np.asarray(angles, dtype=float)
    max_range = float(sensor.max_range)
    offset = np.asarray(getattr(sensor, "sensor_offset", np.zeros(3)), dtype=float)
    cast = RayCaster(grid, max_range, method="march").cast(sensor_poses(np.atleast_2d(poses), offset), a)
    w = np.array([float(getattr(sensor, name, 0.0) or 0.0) for name in ("z_hit", "z_short", "z_rand", "z_max")])
    w = w / w.sum() if w.sum() > 0 else np.array([1.0, 0.0, 0.0, 0.0])
    kind = rng.choice(4, size=cast.shape, p=w)
    sigma = float(getattr(sensor, "sigma_hit", 0.2))
    lam = float(getattr(sensor, "lambda_short", 0.5) or 0.5)
    u = rng.random(cast.shape)
    short = -np.log1p(u * np.expm1(-lam * cast)) / lam          # exponential truncated at the cast range
    z = np.choose(kind, [cast + rng.normal(0.0, sigma, cast.shape), short, u * max_range,
                         np.full(cast.shape, max_range)])
    z = np.where(cast >= max_range, max_range, z)
    return np.clip(z, 0.0, max_range)


def look_alikes(grid: OccupancyGrid, sensor: Any, truth: NDArray, scans: NDArray, angles: NDArray,
                rng: np.random.Generator, radius: float, n_places: int = 150, n_headings: int = 12,
                n_best: int = 4, n_refine: int = 32) -> NDArray[np.float64]:
    """For each true pose, the pose at least ``radius`` away where its scan scores best: a filter's wrong answer.

    A particle filter does not settle on a random wrong place; it selects the
    place whose look fits the scans best. This searches for it as the filter
    would: the sensor model's log-likelihood of the scan at ``n_places`` free
    positions x ``n_headings`` headings, then ``n_refine`` poses scattered
    around each of the ``n_best`` best (half the search's spacing and half a heading step),
    keeping every candidate at least ``radius`` from the truth.
    """
    out = np.empty_like(truth)
    step = 2.0 * np.pi / n_headings
    for i in range(len(truth)):
        ok = np.isfinite(scans[i]) & (scans[i] < float(sensor.max_range))
        if not ok.any():
            out[i] = grid.sample_free(1, rng)[0]
            continue
        xy = grid.sample_free(n_places, rng)[:, :2]
        xy = xy[np.hypot(*(xy - truth[i, :2]).T) >= radius]
        if len(xy) == 0:
            out[i] = np.nan
            continue
        th = rng.uniform(-np.pi, np.pi) + step * np.arange(n_headings)
        cand = np.column_stack([np.repeat(xy, n_headings, axis=0), np.tile(th, len(xy))])
        ll = sensor.log_likelihood(cand, scans[i][ok], angles[ok])
        best = cand[np.argsort(ll)[-n_best:]]
        spread = np.sqrt(grid.width_m * grid.height_m / max(n_places, 1))
        near = (np.repeat(best, n_refine, axis=0)
                + rng.normal(0.0, 1.0, (n_best * n_refine, 3)) * [0.5 * spread, 0.5 * spread, 0.5 * step])
        near = near[(np.hypot(*(near[:, :2] - truth[i, :2]).T) >= radius) & grid.is_free(near[:, :2])]
        cand = np.vstack([best, near])
        out[i] = cand[int(np.argmax(sensor.log_likelihood(cand, scans[i][ok], angles[ok])))]
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def converged_error(sensor: Any, n_beams: int) -> float:
    """Standard deviation (metres, per axis) of a converged filter's position: ``sigma_hit / sqrt(T * B)``.

    A scan of ``B`` scored beams (the sensor's ``max_beams`` of the scan's ``n_beams``), each with noise
    ``sigma_hit``, tempered by ``T`` (the model counts it as ``T * B`` independent readings), pins a
    position to about this: the posterior's spread under the filter's own sensor model.

    Examples
    --------
    >>> class LF:
    ...     sigma_hit, temper, max_beams = 0.3, 0.3, 30
    >>> round(converged_error(LF(), 180), 3)        # 0.3 / sqrt(9)
    0.1
    """
    b = int(n_beams)
    m = getattr(sensor, "max_beams", None)
    if m is not None:
        b = min(b, int(m))
    t = float(getattr(sensor, "temper", 1.0) or 1.0)
    return float(float(getattr(sensor, "sigma_hit", 0.2)) / np.sqrt(max(1.0, t * b)))


@dataclass(frozen=True)
class _Sample:
    """Simulated scans at free poses and the fits of the wrong poses: what every level of ``right`` shares."""

    truth: NDArray
    scans: NDArray
    valid: NDArray
    angles: NDArray
    typical: float
    caster: RayCaster
    offset: NDArray
    fit_d: float
    min_beams: int
    f_wrong: NDArray

    def right_fits(self, error: float, rng: np.random.Generator) -> NDArray:
        """Fits at the true poses moved by Gaussian errors of ``error`` (m per axis; heading: seen at the median
        range), NaN dropped."""
        n = len(self.truth)
        right = self.truth.copy()
        right[:, :2] += rng.normal(0.0, error, (n, 2))
        right[:, 2] = wrap_angle(right[:, 2] + rng.normal(0.0, error / max(self.typical, error), n))
        f = scan_fits(self.caster, right, self.offset, self.scans, self.valid, self.angles, self.fit_d,
                      self.min_beams)
        return f[np.isfinite(f)]


def _sample(grid: OccupancyGrid, sensor: Any, angles: ArrayLike, rng: np.random.Generator, n_poses: int,
            fit_distance: float | None, radius: float, min_beams: int) -> _Sample:
    n = check_count(n_poses, "n_poses")
    a = np.asarray(angles, dtype=float)
    max_range = float(sensor.max_range)
    lo = float(getattr(sensor, "min_range", 0.0) or 0.0)
    offset = np.asarray(getattr(sensor, "sensor_offset", np.zeros(3)), dtype=float)
    fit_d = 2.0 * float(getattr(sensor, "sigma_hit", 0.2)) if fit_distance is None else float(fit_distance)
    caster = RayCaster(grid, max_range, method="march")
    truth = grid.sample_free(n, rng)
    scans = simulate_scans(grid, sensor, truth, a, rng)
    valid = np.isfinite(scans) & (scans > lo) & (scans < max_range)
    typical = float(np.median(scans[valid])) if valid.any() else max_range
    r = np.sqrt(rng.uniform(radius ** 2, (4.0 * radius) ** 2, n))
    phi = rng.uniform(-np.pi, np.pi, n)
    near = truth + np.column_stack([r * np.cos(phi), r * np.sin(phi), rng.uniform(-NEAR_TURN, NEAR_TURN, n)])
    alike = look_alikes(grid, sensor, truth, np.where(valid, scans, np.inf), a, rng, radius)
    f_wrong = np.concatenate([scan_fits(caster, near, offset, scans, valid, a, fit_d, min_beams),
                              scan_fits(caster, alike, offset, scans, valid, a, fit_d, min_beams)])
    return _Sample(truth, scans, valid, a, typical, caster, offset, fit_d, int(min_beams),
                   f_wrong[np.isfinite(f_wrong)])


def calibration_fits(grid: OccupancyGrid, sensor: Any, angles: ArrayLike, rng: np.random.Generator, *,
                     n_poses: int = 300, fit_distance: float | None = None, radius: float = 1.0,
                     min_beams: int = 5,
                     error: float | None = None) -> tuple[NDArray, NDArray]:
    """The scan fits of :func:`calibrate`: ``(fits at right poses, fits at wrong poses)``, NaN dropped.

    ``n_poses`` true poses are drawn over the free space and a scan simulated
    at each from the sensor model's own mixture (:func:`simulate_scans`). The
    scan is scored (:func:`scan_fits`, as :class:`localize.policies.MapEvidence` scores the run's scans)

    * at the true pose moved as far as a right estimate is off (right):
      Gaussian errors of ``error`` metres in x and y (default
      :func:`converged_error`), and in heading the angle under which it is
      seen at the scans' median range;
    * wrong, half and half: at the true pose moved by ``radius`` to 4 times
      ``radius`` with a heading error of up to 0.5 rad (a filter carried
      away by its odometry), and at the place at least ``radius`` away where
      the scan scores best (:func:`look_alikes`: a filter that settled on a
      look-alike).
    """
    rng = check_rng(rng)
    s = _sample(grid, sensor, angles, rng, n_poses, fit_distance, radius, min_beams)
    e = converged_error(sensor, s.angles.size) if error is None else check_positive(error, "error", "metres")
    return s.right_fits(e, rng), s.f_wrong


def error_levels(sensor: Any, n_beams: int, radius: float) -> tuple[float, ...]:
    """The errors (m per axis) of right estimates at which ``p(fit | right)`` is calibrated:
    :func:`converged_error` doubled as long as it stays within half of ``radius``.

    Examples
    --------
    >>> class LF:
    ...     sigma_hit, temper, max_beams = 0.3, 0.3, 30
    >>> [round(e, 2) for e in error_levels(LF(), 180, 1.0)]
    [0.1, 0.2, 0.4]
    """
    e = converged_error(sensor, n_beams)
    levels = [e]
    while levels[-1] * 2.0 <= 0.5 * radius:
        levels.append(levels[-1] * 2.0)
    return tuple(levels)


def calibrate(grid: OccupancyGrid, sensor: Any, angles: ArrayLike, rng: np.random.Generator, *,
              n_poses: int = 300, n_bins: int = 10, right_radius: float = 1.0, map_error: float = MAP_ERROR,
              fit_distance: float | None = None, min_beams: int = 5) -> EvidenceModel:
    """The :class:`EvidenceModel` of this map and sensor, from simulated scans (see :func:`calibration_fits`).

    ``p(fit | right)`` is the mean of its calibrations at the errors of :func:`error_levels`: how far a
    right estimate is off is not known (a cloud that stood still for a while claims less spread than its
    error), anywhere from the sensor's precision to half the radius, each doubling as likely (a log-uniform
    prior on the error's scale). The simulation knows only the disagreement the sensor model expects; ``p(fit | right)`` is
    mixed with a uniform fit with weight ``map_error`` (:data:`MAP_ERROR`), the scans at which the map is
    wrong about what the robot sees, so that no single poor fit condemns a right estimate.

    Takes a second or two for a few hundred poses.
    """
    check_positive(right_radius, "right_radius", "metres")
    rng = check_rng(rng)
    s = _sample(grid, sensor, angles, rng, n_poses, fit_distance, right_radius, min_beams)
    levels = error_levels(sensor, s.angles.size, right_radius)
    f_rights = [s.right_fits(e, rng) for e in levels]
    if min(f.size for f in f_rights) < 10 or s.f_wrong.size < 10:
        raise ValueError(f"calibration found too few scans the map can judge ({f_rights[0].size} right, "
                         f"{s.f_wrong.size} wrong): the map's free space is tiny or mostly unknown")
    edges = np.linspace(0.0, 1.0, int(n_bins) + 1)
    edges[-1] = 1.0 + 1e-9                      # a perfect fit of 1.0 falls in the last bin
    uniform = np.diff(np.minimum(edges, 1.0))
    p_rights = np.array([(1.0 - map_error) * _histogram(f, edges) + map_error * uniform for f in f_rights])
    return EvidenceModel(edges, p_rights.mean(axis=0), _histogram(s.f_wrong, edges),
                         int(sum(f.size for f in f_rights)), int(s.f_wrong.size), float(right_radius), levels,
                         p_rights)


def content_key(obj: Any, depth: int = 3) -> str | None:
    """A digest of what ``obj`` holds: its type, and each attribute's value (arrays by their bytes, shape and
    dtype; objects, such as a sensor's grid, by their own attributes, ``depth`` levels down). Two objects with
    the same digest compute the same. None when ``obj`` holds something whose content it cannot read (a
    function, an object deeper than ``depth``): such an object has no key.

    Examples
    --------
    >>> from localize.maps import office
    >>> content_key(office()) == content_key(office()), content_key(office()) == content_key(office(0.2))
    (True, False)
    >>> content_key({"f": lambda x: x}) is None
    True
    """
    h = hashlib.sha1()
    opaque = []

    def feed(o: Any, d: int) -> None:
        h.update(type(o).__qualname__.encode())
        if isinstance(o, np.ndarray):
            h.update(f"{o.shape}{o.dtype}".encode())
            h.update(np.ascontiguousarray(o).tobytes())
        elif isinstance(o, (bool, int, float, complex, str, bytes, type(None), np.generic)):
            h.update(repr(o).encode())
        elif isinstance(o, (tuple, list)):
            for v in o:
                feed(v, d)
        elif isinstance(o, dict):
            for k in sorted(o, key=repr):
                h.update(repr(k).encode())
                feed(o[k], d)
        elif isinstance(o, type):
            h.update(f"{o.__module__}.{o.__qualname__}".encode())
        elif d > 0 and hasattr(o, "__dict__") and not callable(o):     # a function's code is not its __dict__
            feed(vars(o), d - 1)
        else:
            opaque.append(o)

    feed(obj, depth)
    return None if opaque else h.hexdigest()


#: Evidence models calibrated in this process, by the content of what they were calibrated on (a few entries).
_CALIBRATIONS: OrderedDict = OrderedDict()
_CALIBRATIONS_KEPT = 4


def calibrate_once(grid: OccupancyGrid, sensor: Any, angles: ArrayLike, seed: int, **options: Any) -> EvidenceModel:
    """:func:`calibrate` with ``np.random.default_rng(seed)``, computed once per process for the same map,
    sensor model, beam angles, seed and options (the same inputs give the same model: the two passes of
    ``localize run --smooth``, the runs of a notebook on one map, a test suite). A sensor model that
    :func:`content_key` cannot read is calibrated every time.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.sensors import LikelihoodField
    >>> lf, angles = LikelihoodField(office(), 8.0, sigma_hit=0.1), np.linspace(-np.pi, np.pi, 36, endpoint=False)
    >>> a = calibrate_once(office(), lf, angles, 0)
    >>> a is calibrate_once(office(), LikelihoodField(office(), 8.0, sigma_hit=0.1), angles, 0)
    True
    >>> a is calibrate_once(office(), LikelihoodField(office(), 8.0, sigma_hit=0.2), angles, 0)
    False
    >>> np.array_equal(a.p_right, calibrate(office(), lf, angles, np.random.default_rng(0)).p_right)
    True
    """
    a = np.asarray(angles, dtype=float)
    key = content_key((grid, sensor, a, int(seed), options))   # None: content it cannot read, never cached
    if key in _CALIBRATIONS:
        _CALIBRATIONS.move_to_end(key)
        return _CALIBRATIONS[key]
    model = calibrate(grid, sensor, a, np.random.default_rng(int(seed)), **options)
    if key is not None:
        _CALIBRATIONS[key] = model
        while len(_CALIBRATIONS) > _CALIBRATIONS_KEPT:
            _CALIBRATIONS.popitem(last=False)
    return model


class LocalizedBelief:
    """The binary Bayes filter over "the estimate is right": ``p_localized`` scan by scan.

    Parameters
    ----------
    model : EvidenceModel
        ``p(fit | right)``, ``p(fit | wrong)``.
    p_lose : float
        Per scan, the chance that a right estimate becomes wrong (wheel slip, a kidnapping).
    p_find : float
        Per scan, the chance that a wrong estimate becomes right on its own (the particle filter
        found the robot); the evidence then has to say so.
    prior : float
        ``p_localized`` before the first scan (a global localization starts knowing nothing).
    """

    def __init__(self, model: EvidenceModel, p_lose: float = 0.01, p_find: float = 0.05, prior: float = 0.0) -> None:
        for name, v in (("p_lose", p_lose), ("p_find", p_find), ("prior", prior)):
            if not 0.0 <= float(v) <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1]; got {v!r}")
        self.model = model
        self.transition = np.array([[1.0 - p_find, p_find], [p_lose, 1.0 - p_lose]])   # rows: from wrong, right
        self.belief = np.array([1.0 - prior, prior])

    @property
    def p(self) -> float:
        """The current probability that the estimate is right."""
        return float(self.belief[RIGHT])

    def predict(self) -> None:
        """One scan ahead: the transition."""
        self.belief = self.belief @ self.transition

    def correct(self, fit: float) -> None:
        """Bayes' rule with the scan's fit (NaN: no evidence)."""
        self.belief = discrete.update(self.belief, self.model.likelihood(fit))

    def step(self, fit: float) -> float:
        """Predict one scan ahead, then correct with the scan's fit (NaN: no correction); returns ``p``."""
        self.predict()
        self.correct(fit)
        return self.p


def reliability_table(p: ArrayLike, right: ArrayLike, n_bins: int = 10, min_count: int = 1) -> list[tuple]:
    """``[(bin low, bin high, scans, mean p, share right), ...]``: a reliability diagram as rows.

    A calibrated probability has ``share right`` close to ``mean p`` in every bin.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> p = rng.uniform(0, 1, 20000)
    >>> rows = reliability_table(p, rng.uniform(0, 1, 20000) < p, n_bins=4)
    >>> all(abs(share - mean) < 0.02 for _, _, _, mean, share in rows)
    True
    """
    p = np.asarray(p, dtype=float)
    right = np.asarray(right, dtype=bool)
    edges = np.linspace(0.0, 1.0, int(n_bins) + 1)
    k = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, int(n_bins) - 1)
    rows = []
    for b in range(int(n_bins)):
        sel = k == b
        if sel.sum() >= min_count:
            rows.append((float(edges[b]), float(edges[b + 1]), int(sel.sum()), float(p[sel].mean()),
                         float(right[sel].mean())))
    return rows


class ReliabilityState:
    """The run's *searching* / *localized* / *lost* state from ``p_localized``, a calibrated probability.

    At every step of :func:`localize.runloop.run`, ``p_localized`` is the
    probability that the estimate lies within ``right_radius`` of the robot,
    the geometric mean ``sqrt(b * m)`` of two estimates of it:

    * ``b``: the probability that the place the filter chose is the robot's
      place, a :class:`LocalizedBelief` over the scans' fits to the map there,
      with the :class:`EvidenceModel` calibrated at the first scan on this
      map and this sensor model (:func:`calibrate`; the scan's own beam
      angles). A new place is a new hypothesis: when the estimate moves by
      more than ``right_radius`` beyond what the odometry explains (another
      cluster won), the belief starts again from even odds;
    * ``m``: the filter's own mass near its estimate, the smaller of the share
      of the weight within ``right_radius`` of it and the share the scan itself
      gives the estimate against the estimate moved by ``probe_shift`` metres
      forwards, backwards, left and right under the sensor model (a cloud that
      resampling alone shrank onto one stretch of a featureless corridor has
      all its weight there, but the scan fits every stretch alike), and, with
      ``rivals`` (default), the estimate's share of the posterior against the
      other places where the scans since the place was chosen fit as well
      (:class:`localize.rivals.RivalBank`: a room and its mirror image hold it
      at a half; each rival's odds believed as far as the spread of its
      per-scan differences supports them, :attr:`~localize.rivals.RivalBank.believed`).
      A rival that becomes 19 times more probable than the
      estimate (the odds of ``localized_at``) takes its place: the run loop
      moves the cloud there (:meth:`take_switch`), the old place becomes a
      rival, and the belief starts again from even odds, as at any new place.
      Only while the estimate itself fits as a right place's scans do (the
      belief and the scan's own fit both say right more probably than wrong):
      two places that fit, one better, is the look-alike problem; an estimate
      that stops fitting is a failure, and finding the robot again is the
      restarts' business.

    Both estimate the same probability, each from other evidence; neither is
    a condition the other leaves out. Their product counts the doubt twice:
    two estimates of a probability ``q`` multiply to about ``q**2``, and in the
    middle of the range that is far too low (measured on ``bench_global.py``'s
    standard draw: where the product said 0.1-0.8, the estimate was within the
    radius 0.1-0.4 more often than it said). The geometric mean counts it once
    (a logarithmic opinion pool with equal weights), and the thresholds on it
    are those the product had, restated (0.95 and 0.7 are about the roots of
    0.9 and 0.5). Before the rival bank, that brought the held-out draw within
    0.1 in eight of ten bins, at most 0.15 off, against 0.35 for the product;
    with the bank and the transition per update (stop 50), the bins below 0.3
    are within 0.09 and those of 0.3-0.9 cautious by 0.11-0.23, while the bin
    above 0.9, which holds 92% of the scans, stays within 0.01
    (``benchmarks/RESULTS.md``, ``bench_global_held_out_state_probability``).
    The caution comes mostly from ``b``: a right estimate's scans where the
    map is wrong fit poorly for a stretch of scans, and the belief counts
    them as independent evidence (``bench_global_experiments_stop50``).

    The state is derived from it: ``localized`` once ``p_localized`` reaches
    ``localized_at``; ``lost`` and ``searching`` (never localized yet) turn
    ``localized`` again there. A localized filter turns ``lost`` when
    ``p_localized`` falls below ``lost_below`` (or every particle failed), or
    when ``m`` alone no longer allows ``localized_at``: ``sqrt(m)`` (the most
    ``p_localized`` can be, with a sure ``b``; :attr:`place_limit`, the
    ``p_place`` column of ``trajectory.csv``) below it.
    The margin between the two thresholds is for the fit: where the map is
    wrong, a right place's scans fit poorly for a while and ``b`` dips, and a
    state that turned lost at every such dip would cry wolf. A ``m`` below
    0.9 is not such a dip: a tenth of the probability is at another place
    (the cloud's own weight elsewhere, a rival as the scans weigh it), and
    *localized* claims the place. Measured, the localized scans held in the
    margin: on ``bench_global.py``'s real logs (35 runs of each draw) 465 of
    512 were limited by ``b`` and every one of the 512 was right; on
    ``bench_state.py``'s generated buildings (seeds 0-3 and 1000-1003) 403 of
    473 were limited by ``m``, and 205 of those were more than a metre off
    (``benchmarks/RESULTS.md``, ``bench_global_experiments_stop62``).

    Parameters
    ----------
    grid : OccupancyGrid
        The map.
    sensor : range sensor model
        The filter's model (its mixture weights, noise and range limits shape the calibration).
    right_radius : float
        What "right" means (metres).
    p_change : float
        Per update (a step at which the filter used its scan: the robot moved enough for the motion gate),
        the chance that a right place becomes wrong (the robot slips or is carried away) without the
        estimate jumping (``p_lose`` of :class:`LocalizedBelief`). Not per scan: a robot that stands
        still does not get lost by waiting, and a laser that scans at 40 Hz is no more hazardous than one
        at 5 Hz (``tests/test_state_scenarios.py``, the waiting robot). A wrong place never becomes right
        by itself (``p_find`` 0): the filter finds the robot by moving its estimate to another place, and
        that starts a new hypothesis; without evidence the probability only falls.
    localized_at, lost_below : float
        The documented thresholds on ``p_localized``.
    probe_shift : float
        Metres; 0 leaves the probe out.
    seed : int
        Seed of the calibration's own generator (the filter's random stream is not touched).
    model : EvidenceModel, optional
        A calibration made beforehand (default: made at the first scan with :func:`calibrate_once`, once per
        map, sensor model and beam angles in a process).
    fit_distance : float, optional
        Metres within which a reading agrees with the map (default: twice the sensor's ``sigma_hit``).
    rivals : bool
        Keep a :class:`localize.rivals.RivalBank` (default); False leaves it out (the share is then 1).
    motion : callable, optional
        The filter's odometry motion model, which the bank's places move by (default: the bank's).
    """

    def __init__(self, grid: OccupancyGrid, sensor: Any, *, right_radius: float = 1.0, p_change: float = 0.01,
                 localized_at: float = LOCALIZED_AT, lost_below: float = LOST_BELOW, probe_shift: float = 1.0, seed: int = 0,
                 model: EvidenceModel | None = None, fit_distance: float | None = None, rivals: bool = True,
                 motion: Any = None) -> None:
        if not 0.0 <= lost_below <= localized_at <= 1.0:
            raise ValueError(f"need 0 <= lost_below <= localized_at <= 1; got {lost_below!r}, {localized_at!r}")
        self.grid, self.sensor = grid, sensor
        self.radius, self.p_change = check_positive(right_radius, "right_radius", "metres"), float(p_change)
        self.localized_at, self.lost_below = float(localized_at), float(lost_below)
        self.probe_shift, self.seed, self.model = float(probe_shift), int(seed), model
        self.fit_distance = fit_distance
        self.belief: LocalizedBelief | None = None if model is None else self._fresh(model)
        self.last_pose: NDArray | None = None
        self.last_p: float | None = None
        self.probe_ll = np.zeros(5)
        self.caster = RayCaster(grid, float(sensor.max_range), method="march")
        self.occupied = grid.occupied
        self.offset = np.asarray(getattr(sensor, "sensor_offset", np.zeros(3)), dtype=float)
        self.fit_d = 2.0 * float(getattr(sensor, "sigma_hit", 0.2)) if fit_distance is None else float(fit_distance)
        self.rivals = RivalBank(grid, sensor, radius=self.radius, switch_odds=localized_at / (1.0 - localized_at),
                                seed=self.seed, motion=motion) if rivals and localized_at < 1.0 else None
        self.pending: int | None = None                # a rival that won at this step
        self.place_limit = 1.0                         # sqrt(m) at the last step: p_localized with a sure belief

    def _fresh(self, model: EvidenceModel) -> LocalizedBelief:
        return LocalizedBelief(model, p_lose=self.p_change, p_find=0.0, prior=0.5)

    def _calibrate(self, angles: NDArray) -> None:
        self.model = calibrate_once(self.grid, self.sensor, angles, self.seed, right_radius=self.radius,
                                    fit_distance=self.fit_distance)
        self.belief = self._fresh(self.model)

    def jumped(self, step: Any) -> bool:
        """Whether the estimate moved by more than ``right_radius`` beyond what the odometry explains."""
        if self.last_pose is None or step.pose is None:
            return True
        moved = np.zeros(3)
        if step.u is not None and step.pair is not None:
            moved = relative(step.pair[0], step.pair[1])
        expected = compose(self.last_pose, moved)
        return bool(not np.all(np.isfinite(expected)) or np.hypot(*(step.pose[:2] - expected[:2])) > self.radius)

    def cloud_mass(self, step: Any) -> float:
        """The share of the weight within ``right_radius`` of the estimate."""
        particles, log_w = step.cloud
        w = np.exp(np.asarray(log_w, dtype=float) - np.max(log_w))
        near = np.hypot(*(particles[:, :2] - step.pose[:2]).T) <= self.radius
        return float(w[near].sum() / w.sum())

    def probe(self, step: Any) -> None:
        """Add the scan's log-likelihood at the estimate and at it moved by ``probe_shift`` in four directions."""
        s = self.probe_shift
        d = np.array([[0.0, 0.0, 0.0], [s, 0.0, 0.0], [-s, 0.0, 0.0], [0.0, s, 0.0], [0.0, -s, 0.0]])
        with np.errstate(divide="ignore", invalid="ignore"):
            ll = np.asarray(self.sensor.log_likelihood(compose(step.pose, d), *step.z), dtype=float)
        if ll.shape == (5,) and np.isfinite(ll[0]):
            self.probe_ll = self.probe_ll + np.where(np.isfinite(ll), ll, -np.inf)

    @property
    def probe_mass(self) -> float:
        """The estimate's posterior against the four moved poses, over the scans since the place was chosen.

        A histogram filter over five hypotheses ("the robot is where the estimate says", or a
        ``probe_shift`` ahead, behind, left, right of it) with the sensor model: in a featureless corridor
        the scans never tell the estimate from the poses ahead and behind, and this stays at a third.
        """
        if self.probe_shift <= 0:
            return 1.0
        return float(np.exp(self.probe_ll[0] - logsumexp(self.probe_ll)))

    def fit(self, step: Any) -> float:
        """The share of the scan's judged readings that agree with the map at the estimate (:func:`scan_fits`).

        NaN (no evidence) when the map calls the estimate's cell occupied: the evidence model was
        calibrated on free space, and a robot the map puts inside an obstacle (a cabinet that has moved
        since the map was made, a wall drawn too thick) casts rays that start in it.
        """
        cell = self.grid.world_to_cell(np.asarray(step.pose[:2], dtype=float), outside="flag")
        if cell[0] >= 0 and self.occupied[cell[0], cell[1]]:
            return float("nan")
        if np.isfinite(step.fit):
            return float(step.fit)                  # MapEvidence scored it already, the same way
        ranges, angles, valid = step.scan
        return float(scan_fits(self.caster, np.asarray(step.pose, dtype=float)[None], self.offset, ranges[None],
                               valid[None], angles, self.fit_d, 5)[0])

    def _new_place(self) -> None:
        self.belief = self._fresh(self.model)
        self.probe_ll = np.zeros(5)
        if self.rivals is not None:
            self.rivals.clear()

    def interrupt(self, ctx: Any) -> None:
        """A restart: the place is in question again (even odds), and a localized filter is lost now."""
        if self.model is not None:
            self._new_place()
        if ctx.state == "localized":
            ctx.state = "lost"

    def p_localized(self, step: Any) -> float:
        """Advance the belief by one step and return ``p_localized``."""
        if self.model is None and step.scan is not None and step.n_valid > 0:
            self._calibrate(np.asarray(step.scan[1], dtype=float))
        if self.belief is None:
            step.p_place = self.place_limit
            return 0.0
        judged = bool(step.updated and step.n_valid > 0)
        if self.jumped(step):
            self._new_place()
        self.last_pose = np.array(step.pose, dtype=float)
        if step.updated:                    # a step the filter used: the robot moved (the scan rate is no hazard)
            self.belief.predict()
        if step.degenerate or step.off_map:
            self.belief.belief = np.array([1.0, 0.0])
        elif step.updated and step.scan is not None and step.n_valid > 0:
            step.evidence = self.fit(step)
            self.belief.correct(step.evidence)
            if self.probe_shift > 0 and isinstance(step.z, tuple) and len(step.z) == 2:
                self.probe(step)
        mass = self.cloud_mass(step)
        share = self.rival_share(step, mass)
        m = min(mass, self.probe_mass, share)
        self.place_limit = step.p_place = float(np.sqrt(m))
        p = float(np.sqrt(self.belief.p * m))
        if not judged and self.last_p is not None:
            p = min(p, self.last_p)         # no new evidence, no rise (the cloud's mass only wanders by resampling)
        self.last_p = p
        return p

    def rival_share(self, step: Any, mass: float) -> float:
        """The estimate's share against its rivals (1 without a bank), after weighing this step's scan when the
        cloud holds most of its weight (``mass``) at the estimate: the place the filter chose, against the others."""
        if self.rivals is None:
            return 1.0
        if not (step.updated and step.n_valid > 0 and isinstance(step.z, tuple) and len(step.z) == 2
                and mass > 0.5 and not (step.degenerate or step.off_map)):
            return self.rivals.share
        odom = None if step.u is None or step.pair is None else step.pair[1]    # an admitted odometry reading
        share = self.rivals.observe(step.pose, step.z, odom)
        i = self.rivals.winner()
        # a rival won while the scans still fit the estimate as a right place's do (the belief, and this scan
        # alone, say right more probably than wrong): two places that both fit, the look-alike problem. When the
        # estimate stops fitting, the filter failed, and finding the robot again is the restarts' business.
        fits = self.belief.p > 0.5 and self.model.posterior(step.evidence) > 0.5
        self.pending = i if i is not None and fits else None
        return share

    def take_switch(self, allowed: bool = True) -> NDArray | None:
        """The transform to move the cloud by when a rival won at this step (:class:`localize.rivals.RivalBank`),
        or None. The rival becomes the estimate, here and in the bank (the old place a rival), and a new place
        starts at even odds, as after any jump. ``allowed=False`` (a restart's probation holds two clouds) lets
        the moment pass: the bank keeps its odds, and the rival wins again at a later scan if it still should."""
        i, self.pending = self.pending, None
        if i is None or not allowed:
            return None
        g = self.rivals.switch(i)
        self.last_pose = compose(g, self.last_pose)   # the bank's move: not a jump that starts the bank again
        self.belief = self._fresh(self.model)
        self.probe_ll = np.zeros(5)
        return g

    def update(self, step: Any, ctx: Any) -> str:
        """The state after this step from its ``p_localized`` (computed here if not yet); sets ``ctx.state``."""
        prev = ctx.state
        if not np.isfinite(step.p_localized):
            step.p_localized = self.p_localized(step)
        p = step.p_localized
        elsewhere = self.place_limit < self.localized_at      # the place part alone no longer allows the claim
        cur = prev
        if p >= self.localized_at:
            cur = "localized"
        elif prev == "localized" and (p < self.lost_below or elsewhere or step.degenerate or step.off_map):
            cur = "lost"
        ctx.state = cur
        if cur != prev:
            why = f"p_localized {p:.2f}"
            if cur == "lost" and p >= self.lost_below and elsewhere:
                why += f"; p_place {floor_text(self.place_limit, 3)} below {self.localized_at:g}: another place is probable"
            ctx.events.append((step.k, f"state {prev} -> {cur} ({why})"))
        return cur
