"""Running the EKF, the UKF and MCL side by side on the same landmark problems.

The chapter "MCL versus the EKF" asks which filter to use, and answers with
measurements: every filter gets exactly the same controls and range-bearing
sightings (from :mod:`localize.sim`), over many seeds, in six scenarios
(:data:`SCENARIOS`):

1. ``tracking`` -- a good initial estimate, small noise;
2. ``large_prior`` -- a large initial uncertainty;
3. ``global`` -- no prior at all (the EKF gets a guess in the middle);
4. ``kidnapping`` -- the robot is carried away mid-run without being told;
5. ``ambiguity`` -- four landmarks on a square that look alike (unknown
   correspondences) and one "tell" that is only seen from part of the path:
   the belief is four-modal until the tell comes into view;
6. ``heading_noise`` -- strong heading noise and sparse sightings, where the
   linearisation of the EKF breaks.

:func:`run_filters` runs one seed and returns a :class:`Run` (estimates,
covariances, optional snapshots for figures); :func:`monte_carlo` runs many
and returns a :class:`MonteCarlo` with per-seed metrics; :func:`summary_rows`
and :func:`format_table` turn those into the chapter's tables. Nothing here
plots (see :mod:`localize.plot.ekf`). Wall-clock times are recorded in the
results but the book only reports them from ``benchmarks/bench_ekf.py``.

Definitions used throughout (stated once, here):

* **position error** -- distance from the estimate to the true position; the
  estimate of MCL is the mean of its heaviest particle cluster
  (:func:`localize.mcl.estimate_pose`);
* **RMSE** -- root mean square of the errors over the *second half* of the
  run (after the start-up transient), per seed;
* **NEES** -- ``e^T P^-1 e`` with ``e = truth - mean`` (heading wrapped) and
  ``P`` the filter's covariance (for MCL the weighted particle covariance
  about the particle mean); its average over ``S`` seeds is consistent at
  the 95% level when inside ``chi2.ppf([0.025, 0.975], 3 S) / S``
  (Bar-Shalom, Li and Kirubarajan 2001, section 5.4);
* **failure** -- the mean position error over the last :data:`FAIL_WINDOW`
  steps is :data:`FAIL_THRESHOLD` metres or more.

Errors, RMSE, NEES and its bounds come from :mod:`localize.metrics`.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import metrics as _metrics_mod
from ._checks import check_count, check_rng
from .ekf import EKFLocalizer, UKFLocalizer
from .geometry import wrap_angle
from .motion import VelocityMotion

__all__ = [
    "FAIL_THRESHOLD",
    "FAIL_WINDOW",
    "FILTERS",
    "SCENARIOS",
    "Scenario",
    "LandmarkData",
    "Run",
    "FilterMetrics",
    "MonteCarlo",
    "AnonymousLandmarks",
    "scenario",
    "simulate",
    "run_filters",
    "monte_carlo",
    "start_monte_carlo",
    "Experiment",
    "summary_rows",
    "format_table",
    "rate_tolerance",
    "rates_differ",
]

#: A run fails when its mean position error over the last FAIL_WINDOW steps exceeds this (metres).
FAIL_THRESHOLD = 1.0
#: Number of final steps over which failure is judged.
FAIL_WINDOW = 10
#: The filters compared, in table order.
FILTERS = ("EKF", "UKF", "MCL")
#: AnonymousLandmarks takes its lean path for fewer sightings and landmarks than this (numpy sums
#: fewer than 8 numbers in order along any axis; from 8 on it sums pairwise along the last).
_LEAN_MAX = 8
_TWO_PI = 2 * np.pi


# ----------------------------------------------------------------------------
# scenarios
# ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Scenario:
    """One test problem: world, robot, sensor, noise, prior and filter settings.

    Attributes
    ----------
    name, title : str
        Key in :data:`SCENARIOS` and a human-readable title.
    landmarks : ndarray (L, 2)
        Landmark positions, metres.
    n_steps : int
        Number of control steps of a run.
    dt : float
        Time step, seconds.
    v, w : float
        Commanded translational (m/s) and rotational (rad/s) velocity; the
        robot drives a circle of radius ``v / w``.
    start : ndarray (3,)
        True start pose.
    alphas : ndarray (6,)
        Velocity-model noise (PR table 5.3), used by the simulator *and* the filters.
    sigma_range, sigma_bearing : float
        Sensor noise (m, rad), used by the simulator and the filters.
    max_range : float
        Landmarks farther than this are not seen.
    sense_every : int
        Sightings arrive every ``sense_every`` steps (1 = every step).
    prior : {"tracking", "gaussian", "global", "symmetric"}
        ``tracking``/``gaussian``: the filters start at a Gaussian guess drawn
        around the truth with standard deviations ``prior_std``; ``global``:
        MCL starts uniform over ``area`` and the Gaussian filters at a pose
        drawn uniformly from ``area`` (a guess) with the covariance of that
        uniform prior. ``symmetric``: the robot is known to be at one of
        ``n_modes`` poses, the truth rotated about the origin by multiples of
        ``2*pi/n_modes``, each with standard deviations ``prior_std``; MCL
        samples all of them, the Gaussian filters must bet on one (drawn at
        random).
    n_modes : int
        Number of modes of the ``symmetric`` prior.
    prior_std : ndarray (3,)
    area : (xmin, xmax, ymin, ymax)
        Where the robot may be (global prior, random particles, kidnapping).
    kidnap_step : int or None
        Before this step the robot is carried elsewhere on its route (see :func:`simulate`).
    known_ids : bool
        Whether the filters are told which landmark each sighting is of.
    n_particles : int
        MCL's particle count.
    recovery : bool
        Use augmented MCL (PR table 8.3) with random particles from ``area``;
        the log-likelihoods enter its averages divided by 5 (about the number
        of sightings per step, see :class:`localize.mcl.Augmented`), which
        stops the averages from jumping with the number of sightings.
    mcl_inflation : float
        MCL's sensor model uses ``mcl_inflation`` times the true noise
        standard deviations (>= 1). A flatter likelihood keeps particles
        alive when the prior is much wider than the posterior (global
        localization), at the price of a less certain belief.
    """

    name: str
    title: str
    landmarks: NDArray[np.float64]
    n_steps: int = 30
    dt: float = 0.5
    v: float = 0.6
    w: float = 0.2
    start: NDArray[np.float64] = field(default_factory=lambda: np.array([0.0, -3.0, 0.0]))
    alphas: NDArray[np.float64] = field(default_factory=lambda: np.array([0.02, 0.005, 0.02, 0.02, 0.001, 0.001]))
    sigma_range: float = 0.2
    sigma_bearing: float = 0.05
    max_range: float = 9.0
    sense_every: int = 1
    prior: str = "tracking"
    prior_std: NDArray[np.float64] = field(default_factory=lambda: np.array([0.1, 0.1, 0.05]))
    area: tuple[float, float, float, float] = (-7.0, 7.0, -7.0, 7.0)
    n_modes: int = 4
    kidnap_step: int | None = None
    known_ids: bool = True
    n_particles: int = 1000
    recovery: bool = False
    mcl_inflation: float = 1.0

    def __post_init__(self) -> None:
        lm = np.asarray(self.landmarks, dtype=float)
        if lm.ndim != 2 or lm.shape[1] != 2 or len(lm) < 1:
            raise ValueError(f"landmarks must be an (L, 2) array; got shape {lm.shape}")
        object.__setattr__(self, "landmarks", lm)
        for name in ("start", "alphas", "prior_std"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float))
        if self.prior not in ("tracking", "gaussian", "global", "symmetric"):
            raise ValueError(f"prior must be 'tracking', 'gaussian', 'global' or 'symmetric'; got {self.prior!r}")
        check_count(self.n_modes, "n_modes")
        if int(self.n_steps) < FAIL_WINDOW:
            raise ValueError(f"n_steps must be >= {FAIL_WINDOW} (the failure window); got {self.n_steps}")
        check_count(self.n_particles, "n_particles")
        if not self.mcl_inflation >= 1.0:
            raise ValueError(f"mcl_inflation must be >= 1; got {self.mcl_inflation}")
        check_count(self.sense_every, "sense_every")
        if self.kidnap_step is not None and not 0 < self.kidnap_step < self.n_steps:
            raise ValueError(f"kidnap_step must lie in (0, n_steps={self.n_steps}); got {self.kidnap_step}")

    @property
    def prior_cov(self) -> NDArray[np.float64]:
        """Covariance the Gaussian filters start with."""
        if self.prior == "global":
            x0, x1, y0, y1 = self.area
            return np.diag([(x1 - x0) ** 2 / 12, (y1 - y0) ** 2 / 12, np.pi**2 / 3])
        return np.diag(self.prior_std**2)


_WORLD = np.array([[-5.0, -4.0], [5.0, -5.0], [6.0, 4.0], [-4.0, 5.0], [0.5, 6.5], [-6.5, 0.5]])
_SQUARE = np.array([[4.0, 4.0], [-4.0, 4.0], [-4.0, -4.0], [4.0, -4.0], [10.0, 0.0]])

#: The six scenarios of the chapter (defaults sized for 50 seeds in seconds; scale with ``scenario(name, ...)``).
SCENARIOS: dict[str, Scenario] = {
    "tracking": Scenario("tracking", "1 Tracking", _WORLD),
    "large_prior": Scenario("large_prior", "2 Large initial uncertainty", _WORLD, prior="gaussian",
                            prior_std=np.array([2.0, 2.0, 0.8])),
    "global": Scenario("global", "3 Global localization (anonymous landmarks)", _WORLD, prior="global",
                       known_ids=False, recovery=True, mcl_inflation=2.0),
    "kidnapping": Scenario("kidnapping", "4 Kidnapping (anonymous landmarks)", _WORLD, kidnap_step=15, n_steps=40,
                           known_ids=False, recovery=True, mcl_inflation=2.0),
    "ambiguity": Scenario("ambiguity", "5 Ambiguity (symmetric, anonymous landmarks)", _SQUARE, known_ids=False,
                          prior="symmetric", prior_std=np.array([0.2, 0.2, 0.05]), area=(-6.0, 6.0, -6.0, 6.0),
                          mcl_inflation=2.0),
    "heading_noise": Scenario("heading_noise", "6 Strong heading noise", _WORLD, sense_every=6,
                              alphas=np.array([0.02, 0.005, 1.0, 4.0, 0.5, 0.5]), mcl_inflation=1.5),
}


def scenario(name: str, **changes: Any) -> Scenario:
    """A scenario of :data:`SCENARIOS`, optionally with some fields changed.

    Examples
    --------
    >>> s = scenario("tracking", n_particles=1000)
    >>> s.n_particles, s.title
    (1000, '1 Tracking')
    """
    if name not in SCENARIOS:
        raise ValueError(f"name must be one of {sorted(SCENARIOS)}; got {name!r}")
    return replace(SCENARIOS[name], **changes)


# ----------------------------------------------------------------------------
# data
# ----------------------------------------------------------------------------


@dataclass
class LandmarkData:
    """What the filters see and what they should have found.

    Attributes
    ----------
    truth : ndarray (T, 3)
        True pose after each control.
    controls : ndarray (T, 2)
        Commanded ``(v, w)`` of each step.
    z : list of ndarray (K_t, 2)
        Range-bearing sightings after each step (possibly empty).
    ids : list of ndarray (K_t,)
        Which landmark each sighting is of (the filters may not be told).
    start : ndarray (3,)
        True pose before the first control.
    """

    truth: NDArray[np.float64]
    controls: NDArray[np.float64]
    z: list
    ids: list
    start: NDArray[np.float64]


def simulate(sc: Scenario, rng: np.random.Generator) -> LandmarkData:
    """Simulate one run of scenario ``sc`` with :func:`localize.sim.landmark_run`.

    The robot is commanded ``(v, w)`` at every step; it sees the landmarks
    within ``max_range``, at every ``sense_every``-th step. With
    ``kidnap_step = k`` the run is two simulated runs back to back: after
    ``k`` steps the robot is carried to a uniform random pose in ``area``
    (2 m away from its border) and goes on from there.

    Examples
    --------
    >>> d = simulate(scenario("tracking", n_steps=12), np.random.default_rng(0))
    >>> d.truth.shape, d.controls.shape, len(d.z), d.z[0].shape[1]
    ((12, 3), (12, 2), 12, 2)
    """
    from . import sim

    check_rng(rng)
    kw = dict(landmarks=sc.landmarks, dt=sc.dt, velocity_alphas=sc.alphas, sigma_range=sc.sigma_range,
              sigma_bearing=sc.sigma_bearing, max_range=sc.max_range)
    n_first = sc.n_steps if sc.kidnap_step is None else sc.kidnap_step
    truth, controls, zs, ids = [], [], [], []
    start = np.asarray(sc.start, dtype=float)
    for n in (n_first, sc.n_steps - n_first):
        if n == 0:
            break
        run = sim.landmark_run(rng, n + 1, start=start, controls=np.tile([sc.v, sc.w], (n, 1)), **kw)
        truth.append(np.asarray(run.poses[1:], dtype=float))
        controls.append(np.asarray(run.controls[1:], dtype=float))
        for k in range(1, n + 1):
            z, i = run.sightings(k)
            zs.append(np.array(z, dtype=float).reshape(-1, 2))
            ids.append(np.array(i, dtype=np.int64).reshape(-1))
        # the kidnapper: carry the robot to another point of its route
        a = rng.uniform(0.5 * np.pi, 1.5 * np.pi)
        p = truth[-1][-1]
        start = np.array([np.cos(a) * p[0] - np.sin(a) * p[1], np.sin(a) * p[0] + np.cos(a) * p[1],
                          float(wrap_angle(p[2] + a))])
    for t in range(sc.n_steps):
        if (t + 1) % sc.sense_every:
            zs[t], ids[t] = zs[t][:0], ids[t][:0]
    return LandmarkData(np.vstack(truth), np.vstack(controls), zs, ids, np.asarray(sc.start, dtype=float).copy())


# ----------------------------------------------------------------------------
# MCL with anonymous landmarks
# ----------------------------------------------------------------------------


class AnonymousLandmarks:
    """Sensor model for landmarks that look alike (unknown correspondences).

    Each sighting may be of any landmark, with equal prior probability:
    ``p(z_k | x) = (1/L) sum_j p(z_k | x, c_k = j)`` (PR section 7.5 sums
    over correspondences in the same way), and sightings are independent.
    ``p(z_k | x, j)`` is the Gaussian range-bearing density of PR table 6.4
    around the wrapped model's ``expected(poses)`` (a
    :class:`localize.sensors.LandmarkModel`);
    :meth:`log_likelihood_loop` is the readable version that asks the model
    itself for each ``(sighting, landmark)`` pair, and the test oracle.

    Parameters
    ----------
    model : LandmarkModel-like
        Has ``expected(poses) -> (N, L, 2)``, ``log_likelihood(poses, z, ids)``
        and the noise standard deviations ``sigma_range``, ``sigma_bearing``.

    Examples
    --------
    >>> class Model:                      # a stand-in with the LandmarkModel interface
    ...     lms = np.array([[5.0, 0.0], [0.0, 5.0]])
    ...     sigma_range, sigma_bearing = 0.1, 0.05
    ...     def expected(self, poses):
    ...         d = self.lms[None] - poses[:, None, :2]
    ...         return np.stack([np.hypot(d[..., 0], d[..., 1]),
    ...                          np.arctan2(d[..., 1], d[..., 0]) - poses[:, None, 2]], -1)
    >>> s = AnonymousLandmarks(Model())
    >>> ll = s.log_likelihood(np.array([[0.0, 0, 0], [0.0, 0, np.pi / 2], [1.0, 1, 0]]), [[5.0, 0.0]])
    >>> bool(abs(ll[0] - ll[1]) < 1e-9), bool(ll[2] < ll[0] - 10)   # rotated by 90 deg: same view
    (True, True)
    """

    def __init__(self, model: Any) -> None:
        if not callable(getattr(model, "expected", None)):
            raise TypeError("model must have expected(poses) -> (N, L, 2), like localize.sensors.LandmarkModel")
        sigma_range, sigma_bearing = getattr(model, "sigma_range", None), getattr(model, "sigma_bearing", None)
        for name, v in (("model.sigma_range", sigma_range), ("model.sigma_bearing", sigma_bearing)):
            if v is None or not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0; got {v!r}")
        self.model = model
        self.sigma = np.array([sigma_range, sigma_bearing], dtype=float)

    def log_likelihood(self, poses: ArrayLike, z: ArrayLike, ids: Any = None) -> NDArray[np.float64]:
        """``sum_k log((1/L) sum_j p(z_k | x, j))`` for every pose (vectorised); ``ids`` is ignored.

        With fewer than :data:`_LEAN_MAX` sightings and landmarks (the chapter's
        worlds) the work goes through :meth:`_log_likelihood_lean`, which gives the
        same numbers bit for bit at about a third of the cost.
        """
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        zz = np.asarray(z, dtype=float).reshape(-1, 2)
        e = np.asarray(self.model.expected(p), dtype=float)            # (N, L, 2)
        if len(zz) == 0:
            return np.zeros(len(p))
        if len(zz) < _LEAN_MAX and e.ndim == 3 and 0 < e.shape[1] < _LEAN_MAX:
            return self._log_likelihood_lean(e, zz)
        dr = (zz[None, :, None, 0] - e[:, None, :, 0]) / self.sigma[0]  # (N, K, L)
        db = np.mod(zz[None, :, None, 1] - e[:, None, :, 1] + np.pi, 2 * np.pi) - np.pi
        db /= self.sigma[1]
        per = -0.5 * (dr * dr + db * db)
        top = per.max(axis=2, keepdims=True)
        per -= top
        np.exp(per, out=per)
        lse = top[..., 0] + np.log(per.sum(axis=2))
        const = np.log(2 * np.pi * self.sigma.prod()) + np.log(e.shape[1])
        return lse.sum(axis=1) - len(zz) * const

    def _log_likelihood_lean(self, e: NDArray, zz: NDArray) -> NDArray[np.float64]:
        """:meth:`log_likelihood` for ``K, L < _LEAN_MAX``: the same operations in the same order, bit for bit.

        One sighting at a time over ``(L, N)`` arrays (reductions over the first
        axis run as fast element-wise passes; numpy sums fewer than 8 numbers in
        order along either axis, and a maximum is exact), with the bearing
        wrapped by adding or subtracting ``2*pi`` where numpy's ``mod`` would,
        which is exact while ``z - e + pi`` lies in ``[-2*pi, 4*pi)`` (``np.mod``
        otherwise).
        """
        n, n_lm = e.shape[0], e.shape[1]
        er = np.ascontiguousarray(e[..., 0].T)                          # (L, N)
        eb = np.ascontiguousarray(e[..., 1].T)
        sr, sb = self.sigma
        lo = (zz[:, 1].min() - eb.max()) + np.pi                        # rounding is monotone: true bounds
        hi = (zz[:, 1].max() - eb.min()) + np.pi
        exact = bool(lo >= -_TWO_PI and hi < 2 * _TWO_PI)
        total = np.zeros(n)
        per, db = np.empty((n_lm, n)), np.empty((n_lm, n))
        for zr, zb in zz:
            np.subtract(zr, er, out=per)
            per /= sr
            np.subtract(zb, eb, out=db)
            db += np.pi
            if exact:       # np.mod(db, 2 pi): fmod leaves db in [0, 2 pi) alone, is exact above, adds 2 pi below
                neg, big = db < 0.0, db >= _TWO_PI
                db += neg * _TWO_PI
                db -= big * _TWO_PI
            else:
                np.mod(db, _TWO_PI, out=db)
            db -= np.pi
            db /= sb
            per *= per
            db *= db
            per += db
            per *= -0.5
            top = per.max(axis=0)
            per -= top
            np.exp(per, out=per)
            top += np.log(per.sum(axis=0))
            total += top
        const = np.log(2 * np.pi * self.sigma.prod()) + np.log(n_lm)
        return total - len(zz) * const

    def log_likelihood_loop(self, poses: ArrayLike, z: ArrayLike) -> NDArray[np.float64]:
        """Readable version: one call of the model's ``log_likelihood`` per sighting and landmark.

        Equal to :meth:`log_likelihood` up to an additive constant when the
        model's own density is the Gaussian of PR table 6.4.
        """
        p = np.asarray(poses, dtype=float).reshape(-1, 3)
        n_lm = np.asarray(self.model.expected(p[:1])).shape[1]
        out = np.zeros(len(p))
        for zk in np.asarray(z, dtype=float).reshape(-1, 2):
            per = np.stack([np.asarray(self.model.log_likelihood(p, zk[None], np.array([j])), dtype=float)
                            for j in range(n_lm)])
            out += np.logaddexp.reduce(per, axis=0) - np.log(n_lm)
        return out


# ----------------------------------------------------------------------------
# running the filters
# ----------------------------------------------------------------------------


class _Gaussian:
    def __init__(self, f, known_ids):
        self.f, self.known_ids = f, known_ids

    def step(self, u, z, ids):
        self.f.predict(u)
        if len(z):
            self.f.update(z, ids if self.known_ids else None)

    def belief(self):
        return self.f.mean, self.f.cov

    def snapshot(self):
        return self.f.mean.copy(), self.f.cov.copy()


class _Particles:
    def __init__(self, f, known_ids):
        self.f, self.known_ids = f, known_ids
        self.est = f.estimate()

    def step(self, u, z, ids):
        if len(z):
            self.est = self.f.step(u, z, ids) if self.known_ids else self.f.step(u, z)
        else:
            self.est = self.f.step(u)

    def belief(self):
        return self.est.pose, self.est.mean, self.est.cov

    def snapshot(self):
        return self.f.particles.copy()


def _make_filters(sc: Scenario, data: LandmarkData, rng: np.random.Generator, names, sensor_factory=None):
    from . import mcl as _mcl

    if sc.prior == "global":   # the Gaussian filters must start somewhere: a random guess
        x0, x1, y0, y1 = sc.area
        mean = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-np.pi, np.pi)])
    else:
        mean = data.start + rng.normal(0.0, sc.prior_std)
        mean[2] = wrap_angle(mean[2])
    modes = None
    if sc.prior == "symmetric":   # the noisy guess, rotated about the origin; the Gaussians bet on one
        a = 2 * np.pi * np.arange(sc.n_modes) / sc.n_modes
        c, s_ = np.cos(a), np.sin(a)
        modes = np.column_stack([c * mean[0] - s_ * mean[1], s_ * mean[0] + c * mean[1], wrap_angle(mean[2] + a)])
        mean = modes[rng.integers(sc.n_modes)]
    cov = sc.prior_cov
    kw = dict(dt=sc.dt, mean=mean, cov=cov)
    out = {}
    for name in names:
        if name == "EKF":
            out[name] = _Gaussian(EKFLocalizer(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw),
                                  sc.known_ids)
        elif name == "UKF":
            out[name] = _Gaussian(UKFLocalizer(sc.landmarks, sc.sigma_range, sc.sigma_bearing, sc.alphas, **kw),
                                  sc.known_ids)
        elif name == "MCL":
            x0, x1, y0, y1 = sc.area

            def sampler(n, g, x0=x0, x1=x1, y0=y0, y1=y1):
                return np.column_stack([g.uniform(x0, x1, n), g.uniform(y0, y1, n), g.uniform(-np.pi, np.pi, n)])

            if sensor_factory is None:
                from .sensors import LandmarkModel

                k = sc.mcl_inflation
                model = LandmarkModel(sc.landmarks, k * sc.sigma_range, k * sc.sigma_bearing)
            else:
                model = sensor_factory(sc)
            sensor = model if sc.known_ids else AnonymousLandmarks(model)
            if sc.prior == "global":
                parts = sampler(sc.n_particles, rng)
            elif modes is not None:
                which = rng.integers(len(modes), size=sc.n_particles)
                parts = modes[which] + rng.normal(0.0, sc.prior_std, (sc.n_particles, 3))
                parts[:, 2] = wrap_angle(parts[:, 2])
            else:
                parts = _mcl.gaussian_particles(mean, cov, sc.n_particles, rng)
            opts = dict(augmented=_mcl.Augmented(0.01, 0.2, temperature=5.0)) if sc.recovery else {}
            f = _mcl.MCL(parts, VelocityMotion(sc.alphas, sc.dt), sensor, rng=rng, sampler=sampler, **opts)
            out[name] = _Particles(f, sc.known_ids)
        else:
            raise ValueError(f"filter names must be among {FILTERS}; got {name!r}")
    return out


@dataclass
class Run:
    """One seed of one scenario, all filters.

    Attributes
    ----------
    scenario : Scenario
    seed : int
    truth : ndarray (T, 3)
    estimates : dict name -> ndarray (T, 3)
        The filter's answer at each step (MCL: best-cluster mean).
    means, covs : dict name -> ndarray (T, 3), (T, 3, 3)
        Mean and covariance of the belief (used for NEES).
    seconds : dict name -> float
        Wall-clock time spent in the filter's steps (not printed in the book).
    snapshots : dict step -> dict name -> (mean, cov) or particles
    data : LandmarkData
    """

    scenario: Scenario
    seed: int
    truth: NDArray[np.float64]
    estimates: dict
    means: dict
    covs: dict
    seconds: dict
    snapshots: dict
    data: LandmarkData


def run_filters(sc: Scenario, seed: int, filters=FILTERS, snapshot_steps=(), data: LandmarkData | None = None,
                sensor_factory=None) -> Run:
    """Run the chosen filters on one simulated run of ``sc``.

    Parameters
    ----------
    sc : Scenario
    seed : int
        Seeds the simulation (``default_rng(seed)``) and, independently, the
        filters' own randomness (the prior draw, MCL's sampling).
    filters : sequence of {"EKF", "UKF", "MCL"}
    snapshot_steps : sequence of int
        Steps at which to keep a copy of each belief (for figures).
    data : LandmarkData, optional
        Use these data instead of simulating.
    sensor_factory : callable, optional
        ``sensor_factory(scenario)`` builds MCL's landmark model (default
        :class:`localize.sensors.LandmarkModel`).

    Returns
    -------
    Run
    """
    if not isinstance(sc, Scenario):
        raise TypeError(f"sc must be a Scenario (see localize.compare.scenario); got {type(sc).__name__}")
    filters = tuple(filters)
    bad = [f for f in filters if f not in FILTERS]
    if bad or not filters:
        raise ValueError(f"filters must be a non-empty subset of {FILTERS}; got {filters}")
    seq = np.random.SeedSequence(int(seed))
    sim_seed, filt_seed = seq.spawn(2)
    if data is None:
        data = simulate(sc, np.random.default_rng(sim_seed))
    frng = np.random.default_rng(filt_seed)
    fs = _make_filters(sc, data, frng, filters, sensor_factory)
    T = len(data.truth)
    est = {n: np.zeros((T, 3)) for n in filters}
    means = {n: np.zeros((T, 3)) for n in filters}
    covs = {n: np.zeros((T, 3, 3)) for n in filters}
    secs = dict.fromkeys(filters, 0.0)
    snaps: dict = {}
    want = set(int(s) for s in snapshot_steps)
    for t in range(T):
        u, z, ids = data.controls[t], data.z[t], data.ids[t]
        for n, f in fs.items():
            t0 = time.perf_counter()
            f.step(u, z, ids)
            secs[n] += time.perf_counter() - t0
            b = f.belief()
            if len(b) == 2:
                est[n][t], covs[n][t] = b
                means[n][t] = b[0]
            else:
                est[n][t], means[n][t], covs[n][t] = b
        if t in want:
            snaps[t] = {n: f.snapshot() for n, f in fs.items()}
    return Run(sc, int(seed), data.truth, est, means, covs, secs, snaps, data)


# ----------------------------------------------------------------------------
# metrics
# ----------------------------------------------------------------------------


@dataclass
class FilterMetrics:
    """Per-seed metrics of one filter in one scenario (arrays over seeds S and steps T)."""

    pos_err: NDArray[np.float64]      # (S, T) metres
    head_err: NDArray[np.float64]     # (S, T) radians, absolute
    nees: NDArray[np.float64]         # (S, T)
    pos_rmse: NDArray[np.float64]     # (S,) second half of the run
    head_rmse: NDArray[np.float64]    # (S,) radians, second half
    failed: NDArray[np.bool_]         # (S,)
    sec_per_step: NDArray[np.float64]  # (S,)

    @property
    def failure_rate(self) -> float:
        """Fraction of seeds that failed."""
        return float(self.failed.mean())


@dataclass
class MonteCarlo:
    """All seeds of one scenario."""

    scenario: Scenario
    seeds: list
    metrics: dict  # name -> FilterMetrics
    fail_threshold: float = FAIL_THRESHOLD

    @property
    def n_seeds(self) -> int:
        return len(self.seeds)

    @property
    def n_steps(self) -> int:
        return next(iter(self.metrics.values())).pos_err.shape[1]

    @property
    def nees_bounds(self) -> tuple[float, float]:
        """95% band of the seed-averaged NEES."""
        return _metrics_mod.nees_bounds(3, self.n_seeds)

    def nees_in_band(self, name: str, from_step: int | None = None) -> float:
        """Fraction of steps (second half by default) whose seed-averaged NEES lies in the 95% band."""
        m = self.metrics[name].nees.mean(axis=0)
        start = self.n_steps // 2 if from_step is None else int(from_step)
        lo, hi = self.nees_bounds
        sel = m[start:]
        return float(np.mean((sel >= lo) & (sel <= hi)))


def _metrics(runs: list, name: str) -> FilterMetrics:
    pe, he, ne, sec = [], [], [], []
    M = _metrics_mod
    for r in runs:
        e = r.estimates[name]
        pe.append(M.position_error(e, r.truth))
        he.append(M.heading_error(e, r.truth))
        # a collapsed particle cloud has a singular covariance: floor it at (1 micrometre)^2
        ne.append(M.nees(r.means[name], r.covs[name] + 1e-12 * np.eye(3), r.truth))
        sec.append(r.seconds[name] / len(r.truth))
    pe, he, ne = np.array(pe), np.array(he), np.array(ne)
    half = pe.shape[1] // 2
    final = pe[:, -FAIL_WINDOW:].mean(axis=1)
    return FilterMetrics(pe, he, ne, M.rmse(pe[:, half:], axis=1), M.rmse(he[:, half:], axis=1),
                         final >= FAIL_THRESHOLD, np.array(sec))


#: Worker pools of :func:`monte_carlo`, one per size, started once and reused (``spawn``: the workers
#: are fresh interpreters, safe to start from a Jupyter kernel's threads on every platform).
_POOLS: dict[int, Any] = {}


def _pool(processes: int):
    if processes not in _POOLS:
        import atexit
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        _POOLS[processes] = pool = ProcessPoolExecutor(processes, mp_context=multiprocessing.get_context("spawn"),
                                                       initializer=_quiet_worker)
        atexit.register(pool.shutdown)
    return _POOLS[processes]


def _quiet_worker() -> None:
    # Ctrl-C (or a Jupyter kernel's interrupt or shutdown) reaches the whole process group: the parent
    # stops the pool; the workers must not print a KeyboardInterrupt traceback each
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_seed(args: tuple) -> Run:
    sc, seed, filters, sensor_factory, snapshot_steps = args
    return run_filters(sc, seed, filters, snapshot_steps=snapshot_steps, sensor_factory=sensor_factory)


class _Later:
    """A job run in the calling process when its result is asked for (the serial path), like a Future."""

    def __init__(self, args: tuple) -> None:
        self.args, self._run = args, None

    def result(self) -> Run:
        if self._run is None:
            self._run = _run_seed(self.args)
        return self._run

    def done(self) -> bool:
        return self._run is not None


class Experiment:
    """Monte Carlo runs of several scenarios, under way in worker processes (see :func:`start_monte_carlo`).

    :meth:`result` waits for the runs that are still going and returns the
    :class:`MonteCarlo` of every scenario, under the keys it was started with.
    """

    def __init__(self, scenarios: dict, seeds: list, filters: tuple, jobs: dict) -> None:
        self.scenarios, self.seeds, self.filters = scenarios, seeds, filters
        self._jobs = jobs            # key -> list of futures, one per seed, in seed order
        self._result: dict | None = None

    def __repr__(self) -> str:
        return (f"Experiment({len(self.scenarios)} scenarios x {len(self.seeds)} seeds, "
                f"{self.n_done()} of {self.n_runs} runs done)")

    @property
    def n_runs(self) -> int:
        """Number of runs (scenarios times seeds)."""
        return len(self.scenarios) * len(self.seeds)

    def n_done(self) -> int:
        """How many runs have finished so far."""
        return sum(f.done() for fs in self._jobs.values() for f in fs)

    def run(self, key: Any, seed: int) -> Run:
        """The :class:`Run` of one scenario and seed (waits for it): the same as ``run_filters(scenario, seed)``.

        It carries the snapshots asked for in :func:`start_monte_carlo`'s
        ``snapshots``, so that a figure of one seed needs no second run.
        """
        if key not in self._jobs:
            raise KeyError(f"no scenario {key!r} in this experiment; it has {list(self._jobs)}")
        if int(seed) not in self.seeds:
            raise KeyError(f"seed {seed!r} is not among this experiment's seeds ({self.seeds[0]}..{self.seeds[-1]})")
        return self._jobs[key][self.seeds.index(int(seed))].result()

    def result(self, progress: bool = False) -> dict:
        """Wait for every run; ``{key: MonteCarlo}`` in the order the scenarios were given.

        ``progress=True`` shows a tqdm bar over the runs
        (:func:`localize.metrics.progress`; in a notebook, in a cell tagged
        ``nbval-ignore-output`` and ``remove-output``). Calling it again returns
        the same results.
        """
        if self._result is None:
            futures = [f for fs in self._jobs.values() for f in fs]
            bar = _metrics_mod.progress(futures, progress, desc=f"{self.n_runs} runs", total=len(futures))
            runs = iter([f.result() for f in bar])
            out = {}
            for key, sc in self.scenarios.items():
                got = [next(runs) for _ in self.seeds]
                out[key] = MonteCarlo(sc, list(self.seeds), {n: _metrics(got, n) for n in self.filters})
            self._result = out
        return self._result


def start_monte_carlo(scenarios, seeds, filters=FILTERS, sensor_factory=None,
                      processes: int | None = None, snapshots: dict | None = None) -> Experiment:
    """Start the Monte Carlo runs of several scenarios in worker processes and return at once.

    The runs go on in the background while the caller does other things (in
    a notebook: while the next cells draw figures); ``.result()`` of the
    returned :class:`Experiment` waits for them and gives the
    :class:`MonteCarlo` of each scenario, the same as :func:`monte_carlo`
    would have (for any number of processes).

    Parameters
    ----------
    scenarios : dict key -> Scenario, or sequence of Scenario
        A sequence is keyed by the scenarios' names.
    seeds : iterable of int
    filters : sequence of names
    sensor_factory : callable, optional
        See :func:`run_filters`; must be picklable (a module-level function or class).
    processes : int or None
        Worker processes (``None``, the default: one per CPU). With 1 there
        are no workers: ``.result()`` computes the runs, in the calling process.
    snapshots : dict, optional
        ``{(key, seed): steps}``: keep the beliefs at these steps in that run
        (see :func:`run_filters`), to draw it with :meth:`Experiment.run`
        instead of running it again. The metrics do not change.

    Returns
    -------
    Experiment

    Examples
    --------
    >>> ex = start_monte_carlo([scenario("tracking", n_steps=10)], range(2), filters=("EKF",), processes=1)
    >>> ex
    Experiment(1 scenarios x 2 seeds, 0 of 2 runs done)
    >>> mc = ex.result()["tracking"]
    >>> bool(np.array_equal(mc.metrics["EKF"].pos_err,
    ...                     monte_carlo(scenario("tracking", n_steps=10), range(2), filters=("EKF",)).metrics["EKF"].pos_err))
    True
    """
    if isinstance(scenarios, Scenario):
        raise TypeError("scenarios must be a dict or a sequence of Scenario; for one scenario use monte_carlo")
    if not hasattr(scenarios, "items"):
        scenarios = list(scenarios)
        names = [getattr(sc, "name", None) for sc in scenarios]
        if len(set(names)) != len(names):
            raise ValueError(f"scenario names repeat ({names}): pass a dict with one key per scenario")
        scenarios = dict(zip(names, scenarios))
    scenarios = dict(scenarios)
    if not scenarios:
        raise ValueError("scenarios must hold at least one Scenario")
    for key, sc in scenarios.items():
        if not isinstance(sc, Scenario):
            raise TypeError(f"scenarios[{key!r}] must be a Scenario (see localize.compare.scenario); "
                            f"got {type(sc).__name__}")
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must name at least one seed")
    filters = tuple(filters)
    bad = [f for f in filters if f not in FILTERS]
    if bad or not filters:
        raise ValueError(f"filters must be a non-empty subset of {FILTERS}; got {filters}")
    snaps = _snapshot_plan(snapshots, scenarios, seeds)
    n_proc = (os.cpu_count() or 1) if processes is None else check_count(processes, "processes")
    n_jobs = len(scenarios) * len(seeds)
    pool = _pool(n_proc) if n_proc > 1 and n_jobs > 1 else None
    jobs = {}
    for key, sc in scenarios.items():
        args = [(sc, s, filters, sensor_factory, snaps.get((key, s), ())) for s in seeds]
        jobs[key] = [pool.submit(_run_seed, a) for a in args] if pool is not None else [_Later(a) for a in args]
    return Experiment(scenarios, seeds, filters, jobs)


def _snapshot_plan(snapshots: dict | None, scenarios: dict, seeds: list) -> dict:
    """``start_monte_carlo``'s ``snapshots``, checked: ``{(key, seed): tuple of steps}``."""
    plan = {}
    for where, steps in (snapshots or {}).items():
        if not (isinstance(where, tuple) and len(where) == 2 and where[0] in scenarios and where[1] in seeds):
            raise ValueError(f"snapshots keys must be (scenario key, seed) pairs of this experiment "
                             f"(keys {list(scenarios)}, seeds {seeds[0]}..{seeds[-1]}); got {where!r}")
        plan[where[0], int(where[1])] = tuple(int(k) for k in steps)
    return plan


def monte_carlo(sc: Scenario, seeds, filters=FILTERS, sensor_factory=None, progress: bool = False,
                processes: int | None = 1) -> MonteCarlo:
    """Run all ``filters`` on ``sc`` for every seed and collect the metrics.

    Parameters
    ----------
    sc : Scenario
    seeds : iterable of int
        E.g. ``range(50)``.
    filters : sequence of names
    sensor_factory : callable, optional
        See :func:`run_filters`.
    progress : bool
        Show a tqdm progress bar over the seeds (:func:`localize.metrics.progress`;
        in a notebook, keep it in a cell tagged ``nbval-ignore-output`` and
        ``remove-output``).
    processes : int or None
        Worker processes that share the seeds (``None``: one per CPU; default
        1, no workers). Every seed is its own independent run, so the result
        is the same for any number of processes (only the measured seconds
        differ); ``sensor_factory`` must then be picklable (a module-level
        function or class). To run several scenarios at once, or in the
        background, use :func:`start_monte_carlo`.

    Returns
    -------
    MonteCarlo

    Examples
    --------
    >>> sc = scenario("tracking", n_steps=10)
    >>> one = monte_carlo(sc, range(2), filters=("EKF",))
    >>> two = monte_carlo(sc, range(2), filters=("EKF",), processes=2)
    >>> bool(np.array_equal(one.metrics["EKF"].pos_err, two.metrics["EKF"].pos_err))
    True
    """
    if not isinstance(sc, Scenario):
        raise TypeError(f"sc must be a Scenario (see localize.compare.scenario); got {type(sc).__name__}")
    ex = start_monte_carlo({sc.name: sc}, seeds, filters, sensor_factory, processes=processes)
    futures = ex._jobs[sc.name]
    runs = [f.result() for f in _metrics_mod.progress(futures, progress, desc=f"scenario {sc.name}",
                                                       total=len(futures))]
    return MonteCarlo(sc, ex.seeds, {n: _metrics(runs, n) for n in ex.filters})


# ----------------------------------------------------------------------------
# tables
# ----------------------------------------------------------------------------


def summary_rows(mcs, timing: bool = False) -> list[dict]:
    """One row per scenario and filter: mean ± std of the metrics over seeds.

    Columns: ``scenario, filter, failure_rate, pos_rmse_all, pos_rmse_all_std,
    pos_rmse, pos_rmse_std, head_rmse_deg_all, head_rmse_deg_all_std, head_rmse_deg, head_rmse_deg_std,
    nees, nees_median, nees_in_band`` (and ``ms_per_step`` with ``timing=True`` --
    wall-clock, so not for stored notebook outputs).

    * ``pos_rmse_all`` / ``head_rmse_deg_all``: mean over **all** seeds of the
      per-seed RMSE (failed runs included: what a user of the filter gets);
      ``pos_rmse`` / ``head_rmse_deg``: over the seeds that did **not** fail (how
      accurate the filter is when it works; NaN if every seed failed).
    * ``nees``: the seed- and time-average over the second half (dominated by
      the worst runs: an overconfident filter shows here); ``nees_median``: the
      median of the same values; ``nees_in_band``: the fraction of those steps
      whose seed-averaged NEES lies inside the 95% band
      (:attr:`MonteCarlo.nees_bounds`).
    """
    rows = []
    for mc in mcs:
        half = mc.n_steps // 2
        for name, m in mc.metrics.items():
            ok = ~m.failed
            row = dict(
                scenario=mc.scenario.title, filter=name,
                failure_rate=m.failure_rate,
                pos_rmse_all=float(np.mean(m.pos_rmse)),
                pos_rmse_all_std=float(np.std(m.pos_rmse)),
                pos_rmse=float(np.mean(m.pos_rmse[ok])) if ok.any() else float("nan"),
                pos_rmse_std=float(np.std(m.pos_rmse[ok])) if ok.any() else float("nan"),
                head_rmse_deg_all=float(np.degrees(np.mean(m.head_rmse))),
                head_rmse_deg_all_std=float(np.degrees(np.std(m.head_rmse))),
                head_rmse_deg=float(np.degrees(np.mean(m.head_rmse[ok]))) if ok.any() else float("nan"),
                head_rmse_deg_std=float(np.degrees(np.std(m.head_rmse[ok]))) if ok.any() else float("nan"),
                nees=float(m.nees[:, half:].mean()),
                nees_median=float(np.median(m.nees[:, half:])),
                nees_in_band=mc.nees_in_band(name),
            )
            if timing:
                row["ms_per_step"] = float(1e3 * m.sec_per_step.mean())
            rows.append(row)
    return rows


def rate_tolerance(n: int, rate: float = 0.5, z: float = 3.0) -> float:
    """How far a failure rate measured on ``n`` seeds may fall from ``rate`` by chance alone.

    ``z`` binomial standard errors, ``z * sqrt(rate (1 - rate) / n)``, plus one
    run (``1 / n``) for the discreteness of a count. A claim about a Monte Carlo
    rate ("MCL fails in about 10% of the runs") is checked with this tolerance,
    so that it holds on any machine: another CPU rounds differently, a few
    seeds take another path, and the count moves by about a standard error.

    Examples
    --------
    >>> round(rate_tolerance(50), 3)                 # the widest: at a rate of 1/2
    0.232
    >>> round(rate_tolerance(50, rate=0.0), 3)       # a claimed zero allows one run in 50
    0.02
    """
    n = check_count(n, "n (the number of seeds)")
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"rate must lie in [0, 1]; got {rate!r}")
    return float(z * np.sqrt(rate * (1.0 - rate) / n) + 1.0 / n)


def rates_differ(rate_a: float, rate_b: float, n: int, z: float = 3.0) -> bool:
    """Is ``rate_a`` larger than ``rate_b`` by more than chance explains?

    Both rates measured on ``n`` seeds each; the difference must exceed ``z``
    standard errors of a difference of two binomial proportions (each at
    least one run in ``n``, so that two counts of zero do not look certain).

    Examples
    --------
    >>> rates_differ(0.80, 0.08, 50), rates_differ(0.12, 0.08, 50)
    (True, False)
    """
    n = check_count(n, "n (the number of seeds)")
    pa, pb = (min(max(p, 1.0 / n), 1.0 - 1.0 / n) for p in (rate_a, rate_b))
    se = np.sqrt(pa * (1 - pa) / n + pb * (1 - pb) / n)
    return bool(rate_a - rate_b > z * se)


def format_table(rows: list[dict], digits: int = 2) -> str:
    """Rows of :func:`summary_rows` as a Markdown table (mean ± std).

    Examples
    --------
    >>> print(format_table([dict(scenario="s", filter="EKF", pos_rmse=0.1234, pos_rmse_std=0.01,
    ...                          failure_rate=0.0)]))
    | scenario | filter | failure rate | position RMSE, successes [m] |
    |---|---|---|---|
    | s | EKF | 0% | 0.12 ± 0.01 |
    """
    if not rows:
        raise ValueError("rows is empty")
    cols = [("scenario", "scenario"), ("filter", "filter"), ("failure_rate", "failure rate"),
            ("pos_rmse_all", "position RMSE, all runs [m]"), ("pos_rmse", "position RMSE, successes [m]"),
            ("head_rmse_deg_all", "heading RMSE, all runs [deg]"), ("head_rmse_deg", "heading RMSE, successes [deg]"),
            ("nees", "mean NEES (3 = ideal)"), ("nees_in_band", "NEES in 95% band"),
            ("nees_median", "median NEES"), ("ms_per_step", "ms/step")]
    cols = [(k, h) for k, h in cols if k in rows[0]]

    def fmt(r, k):
        v = r[k]
        if k in ("scenario", "filter"):
            return str(v)
        if k in ("failure_rate", "nees_in_band"):
            return f"{100 * v:.0f}%"
        if k + "_std" in r:
            if not np.isfinite(v):
                return "—"
            return f"{v:.{digits}f} ± {r[k + '_std']:.{digits}f}"
        if not np.isfinite(v):
            return "—"
        return f"{v:.{digits}f}" if abs(v) < 1e4 else f"{v:.1e}"

    lines = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt(r, k) for k, _ in cols) + " |" for r in rows]
    return "\n".join(lines)
