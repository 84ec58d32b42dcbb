"""Am I localized? A probability, calibrated on the user's own map and sensor, filtered over the scans.

Whether the filter's estimate is right is a hidden binary state, ``right``
(within ``right_radius`` of the robot) or ``wrong``. The filter never sees the
truth, but every scan gives evidence: how well the scan fits the map at the
estimate (:func:`localize.evidence.scan_fit`). The Bayes filter of chapter 1
(:mod:`localize.discrete`) turns that evidence into a belief, scan by scan:

* **prediction**: a right estimate stays right with probability
  ``1 - p_lose`` per scan; a wrong one becomes right only with ``p_find``
  (the particle filter found the robot; the evidence must then say so);
* **correction**: ``p(fit | right)`` and ``p(fit | wrong)``, the
  :class:`EvidenceModel`.

The evidence model is not chosen on benchmark logs: :func:`calibrate` learns
it at start-up from the user's own map and sensor model -- scans simulated at
poses drawn over the map's free space with the run's beams, range limits and
noise (the sensor model's own ``sample``), scored at poses a little off (right)
and at poses a metre or more off or elsewhere in the map (wrong). A map with
long featureless corridors gives a ``p(fit | wrong)`` with much mass at high
fits, and the filter then needs more scans to be sure: the model knows the
building.

**Limit, measured.** The wrong poses of :func:`calibrate` are near misses and
random other places; the wrong places a particle filter settles on are not
random: it *selects* the place that fits the scans best. In chapter 8's
kidnapping (office, seed 0) the filter sat 10-12 m from the robot for 16 scans
in a room that fits the scans at 0.6-0.8 of the beams, as well as the right
place does, and the filtered probability said 1.0 there. Fit alone cannot tell
a look-alike; the calibration needs look-alike wrong samples (the best-fitting
pose a metre or more from each simulated robot) and evidence that compares
places (the share of weight in competing clusters), before this probability
replaces the thresholds of :class:`localize.policies.StateRules`.

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
>>> [round(belief.step(0.95), 2) for _ in range(4)]          # scans that fit: sure after a few
[0.17, 0.51, 0.82, 0.95]
>>> [round(belief.step(0.05), 2) for _ in range(2)]          # scans that fit nowhere near: lost
[0.07, 0.0]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import discrete
from ._checks import check_count, check_positive, check_rng
from .evidence import scan_fit
from .geometry import wrap_angle
from .grid import OccupancyGrid
from .raycast import RayCaster

__all__ = ["EvidenceModel", "calibrate", "LocalizedBelief", "reliability_table"]

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
    """

    edges: NDArray[np.float64]
    p_right: NDArray[np.float64]
    p_wrong: NDArray[np.float64]
    n_right: int
    n_wrong: int
    right_radius: float

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


def calibration_fits(grid: OccupancyGrid, sensor: Any, angles: ArrayLike, rng: np.random.Generator, *,
                     n_poses: int = 300, fit_distance: float | None = None,
                     min_beams: int = 5) -> tuple[NDArray, NDArray]:
    """The scan fits of :func:`calibrate`: ``(fits at right poses, fits at wrong poses)``, NaN dropped.

    ``n_poses`` true poses are drawn over the free space; the sensor model
    simulates a scan at each (``sensor.sample``). The scan is scored

    * at the true pose moved as far as a converged filter's estimate is off:
      Gaussian errors of half the fit distance in position, and in heading the
      angle under which half the fit distance is seen at the scans' median
      range (right);
    * at the true pose moved by 1-4 m with a heading error of up to 0.5 rad (a
      near miss), and at another free pose (a look-alike elsewhere): wrong.
    """
    rng = check_rng(rng)
    n = check_count(n_poses, "n_poses")
    a = np.asarray(angles, dtype=float)
    max_range = float(sensor.max_range)
    lo = float(getattr(sensor, "min_range", 0.0) or 0.0)
    offset = np.asarray(getattr(sensor, "sensor_offset", np.zeros(3)), dtype=float)
    fit_d = 2.0 * float(getattr(sensor, "sigma_hit", 0.2)) if fit_distance is None else float(fit_distance)
    caster = RayCaster(grid, max_range, method="march")
    truth = grid.sample_free(n, rng)
    scans = np.asarray(sensor.sample(truth, a, rng), dtype=float)

    def moved(lo_m: float, hi_m: float, heading: float) -> NDArray:
        """The true poses moved by lo_m..hi_m metres (uniform over the ring) and up to ``heading`` radians."""
        r = np.sqrt(rng.uniform(lo_m ** 2, hi_m ** 2, n))
        phi = rng.uniform(-np.pi, np.pi, n)
        out = truth.copy()
        out[:, 0] += r * np.cos(phi)
        out[:, 1] += r * np.sin(phi)
        out[:, 2] = wrap_angle(out[:, 2] + rng.uniform(-heading, heading, n))
        return out

    ok_all = np.isfinite(scans) & (scans > lo) & (scans < max_range)
    typical = float(np.median(scans[ok_all])) if ok_all.any() else max_range
    right = truth.copy()
    right[:, :2] += rng.normal(0.0, 0.5 * fit_d, (n, 2))
    right[:, 2] = wrap_angle(right[:, 2] + rng.normal(0.0, 0.5 * fit_d / max(typical, fit_d), n))
    near = moved(1.0, 4.0, 0.5)
    elsewhere = grid.sample_free(n, rng)

    def fits(poses: NDArray) -> NDArray:
        out = np.full(n, np.nan)
        for i in range(n):
            ok = np.isfinite(scans[i]) & (scans[i] > lo) & (scans[i] < max_range)
            out[i] = scan_fit(caster, poses[i], offset, scans[i][ok], a[ok], fit_d, min_beams)
        return out

    f_right = fits(right)
    f_wrong = np.concatenate([fits(near), fits(elsewhere)])
    return f_right[np.isfinite(f_right)], f_wrong[np.isfinite(f_wrong)]


def calibrate(grid: OccupancyGrid, sensor: Any, angles: ArrayLike, rng: np.random.Generator, *,
              n_poses: int = 300, n_bins: int = 10, right_radius: float = 1.0, **kwargs: Any) -> EvidenceModel:
    """The :class:`EvidenceModel` of this map and sensor, from simulated scans (see :func:`calibration_fits`).

    Takes a second or two for a few hundred poses; ``kwargs`` go to :func:`calibration_fits`.
    """
    check_positive(right_radius, "right_radius", "metres")
    f_right, f_wrong = calibration_fits(grid, sensor, angles, rng, n_poses=n_poses, **kwargs)
    if f_right.size < 10 or f_wrong.size < 10:
        raise ValueError(f"calibration found too few scans the map can judge ({f_right.size} right, {f_wrong.size} "
                         "wrong): the map's free space is tiny or mostly unknown")
    edges = np.linspace(0.0, 1.0, int(n_bins) + 1)
    edges[-1] = 1.0 + 1e-9                      # a perfect fit of 1.0 falls in the last bin
    return EvidenceModel(edges, _histogram(f_right, edges), _histogram(f_wrong, edges), int(f_right.size),
                         int(f_wrong.size), float(right_radius))


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

    def step(self, fit: float) -> float:
        """Predict one scan ahead, then correct with the scan's fit (NaN: no correction); returns ``p``."""
        self.belief = self.belief @ self.transition
        self.belief = discrete.update(self.belief, self.model.likelihood(fit))
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
