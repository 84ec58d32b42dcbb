"""Monte Carlo Localization: the particle filter on robot poses.

:class:`MCL` carries the belief as ``particles`` (an ``(N, 3)`` array of
poses) and ``log_weights`` (``(N,)``, normalised so that their log-sum-exp
is 0). One filter step is the loop of *Probabilistic Robotics* (Thrun,
Burgard and Fox 2005, table 8.2, "PR" below):

1. :meth:`MCL.predict` -- move every particle with a sample of the motion
   model (PR table 5.6 for odometry);
2. :meth:`MCL.update` -- multiply every weight by the measurement likelihood
   ``p(z | x)`` of the sensor model (added in log space);
3. :meth:`MCL.resample` -- draw a new, equally weighted set with a resampler
   from :mod:`localize.resample`, when the effective sample size has fallen
   below ``resample_threshold * N`` (adaptive resampling);
4. :meth:`MCL.estimate` -- summarise the belief.

:meth:`MCL.step` does all four. Options turn the basic filter into the
variants of PR chapter 8: a fixed fraction of random particles injected at
each resampling (``injection``), augmented MCL with the short- and long-term
averages ``w_fast`` and ``w_slow`` of the measurement likelihood (``augmented``,
PR table 8.3) and KLD-sampling, which adapts the number of particles
(``kld``, Fox 2003, PR table 8.4; see :mod:`localize.kld`).

Weights never become NaN. A likelihood that is NaN or ``+inf`` is counted as
invalid and treated as zero; if *every* particle ends with zero weight (a scan
that matches nothing, a sensor model with no random component), the filter
does not divide by zero: it keeps the particles, discards the measurement (or
re-draws the particles, see ``on_degenerate``) and says so in
:attr:`MCL.status`.

The motion model is any callable ``motion(poses, u, rng) -> poses``
(:class:`~localize.motion.OdometryMotion` and
:class:`~localize.motion.VelocityMotion` of :mod:`localize.motion`, also
importable from here); the sensor model is any object with a method
``log_likelihood(poses, *z) -> (N,)`` (the range models and the landmark
model of :mod:`localize.sensors`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import resample as _rs
from ._checks import check_count, check_grid, check_nonnegative, check_poses, check_positive, check_rng
from .geometry import as_poses, mean_pose, wrap_angle
from .geometry import relative as _relative
from .grid import OccupancyGrid
from .kld import KLDSampling, kld_sample_size
from .motion import OdometryMotion, ReversibleOdometry, VelocityMotion  # noqa: F401  (re-exported: their old home)
from .sensors import select_beams, sensor_poses

__all__ = [
    "MCL",
    "MCLStatus",
    "Estimate",
    "OdometryMotion",
    "ReversibleOdometry",
    "VelocityMotion",
    "Augmented",
    "KLDSampling",
    "gaussian_particles",
    "uniform_particles",
    "estimate_pose",
    "mcl_step_loop",
    "MCLTrace",
    "run_mcl",
    "run_filter",
    "RunTrace",
    "StateRules",
    "STATES",
    "expected_fit",
]

Motion = Callable[[NDArray[np.float64], Any, np.random.Generator], NDArray[np.float64]]
Sampler = Callable[[int, np.random.Generator], NDArray[np.float64]]

RESAMPLERS = tuple(_rs.RESAMPLERS)

#: The estimate's cluster histogram has at most this many cells along each side (its cells grow beyond
#: ``cluster_size`` when the particles spread wider), so that a cloud spread over a large map stays cheap.
_MAX_CLUSTER_CELLS = 512
#: Augmented MCL's injection probability below this is rounding noise of two equal averages, not a failure.
_P_INJECT_NOISE = 1e-9
#: Eigenvalues of a prior covariance down to ``-_PSD_TOL`` are rounding noise of a singular matrix.
_PSD_TOL = 1e-12


# --------------------------------------------------------------------------- initialisers
def uniform_particles(grid: OccupancyGrid, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``n`` poses drawn uniformly over the known-free cells of ``grid``, headings uniform.

    The prior of global localization: the robot is somewhere in free space,
    facing anywhere (the initialisation of the seed 001 report).

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office()
    >>> p = uniform_particles(g, 500, np.random.default_rng(0))
    >>> p.shape, bool(g.is_free(p).all())
    ((500, 3), True)
    """
    return check_grid(grid).sample_free(check_count(n, "n"), check_rng(rng))


def gaussian_particles(
    mean: ArrayLike, cov: ArrayLike, n: int, rng: np.random.Generator
) -> NDArray[np.float64]:
    """``n`` poses from a Gaussian around ``mean`` (the prior of pose tracking).

    ``cov`` is a ``(3, 3)`` covariance or three standard deviations
    ``(sx, sy, stheta)``. Headings are wrapped to ``[-pi, pi)``.

    Examples
    --------
    >>> p = gaussian_particles([1.0, 2.0, 3.1], (0.1, 0.1, 0.1), 20_000, np.random.default_rng(0))
    >>> p[:, :2].mean(axis=0).round(2), bool(np.all(p[:, 2] < np.pi))
    (array([1., 2.]), True)
    """
    m = as_poses(mean, "mean").reshape(3)
    c = np.asarray(cov, dtype=float)
    if c.shape == (3,):
        if np.any(c < 0):
            raise ValueError(f"cov given as standard deviations must be >= 0; got {cov!r}")
        c = np.diag(c**2)
    if c.shape != (3, 3) or np.any(~np.isfinite(c)):
        raise ValueError(f"cov must be a finite (3, 3) covariance or three standard deviations; got shape {c.shape}")
    if not np.allclose(c, c.T):
        raise ValueError("cov must be symmetric")
    if np.linalg.eigvalsh(c).min() < -_PSD_TOL:
        raise ValueError("cov must be positive semi-definite")
    p = check_rng(rng).multivariate_normal(m, c, size=check_count(n, "n"), method="eigh")
    p[:, 2] = wrap_angle(p[:, 2])
    return p


# --------------------------------------------------------------------------- estimate
@dataclass(frozen=True)
class Estimate:
    """A summary of the particle belief.

    Attributes
    ----------
    pose : ndarray (3,)
        The answer to "where is the robot?": the weighted mean of the heaviest
        cluster (equal to ``mean`` when the belief has one mode).
    mean : ndarray (3,)
        Weighted mean of all particles; circular mean for the heading.
        Meaningless when the belief is multimodal (it may lie in a wall
        between two hypotheses) -- use ``pose``.
    std : ndarray (3,)
        Weighted spread of all particles: standard deviations in x and y
        (metres) and the circular standard deviation of the heading (rad).
    cov : ndarray (3, 3)
        Weighted covariance, heading deviations taken about the circular mean.
    best_weight : float
        Share of the total weight held by the heaviest cluster, in (0, 1].
    n_clusters : int
        Number of clusters holding at least 1% of the weight.
    n_eff : float
        Effective sample size ``1 / sum(w**2)``.
    cluster_std : ndarray (3,)
        Spread of the best cluster alone (like ``std``); :attr:`spread` is its
        position part. With one cluster it equals ``std``.

    Examples
    --------
    >>> e = estimate_pose([[1.0, 2.0, 3.1], [1.2, 2.0, -3.1]])
    >>> e.pose.round(2), e.multimodal
    (array([ 1.1 ,  2.  , -3.14]), False)
    """

    pose: NDArray[np.float64]
    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    cov: NDArray[np.float64]
    best_weight: float
    n_clusters: int
    n_eff: float
    cluster_std: NDArray[np.float64] | None = None

    @property
    def spread(self) -> float:
        """Position spread of the best cluster, ``sqrt(sx**2 + sy**2)`` in metres."""
        s = self.std if self.cluster_std is None else self.cluster_std
        return float(np.hypot(s[0], s[1]))

    @property
    def multimodal(self) -> bool:
        """True when more than one cluster holds a noticeable share of the weight."""
        return self.n_clusters > 1


def _weighted_stats(p: NDArray, w: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Weighted mean (circular heading), covariance and spread; ``w`` sums to one."""
    s = float(w @ np.sin(p[:, 2]))
    c = float(w @ np.cos(p[:, 2]))
    th = float(wrap_angle(np.arctan2(s, c)))
    xy = w @ p[:, :2]
    mean = np.array([xy[0], xy[1], th])
    d = p - mean
    d[:, 2] = wrap_angle(d[:, 2])
    cov = (d * w[:, None]).T @ d
    r = min(max(np.hypot(s, c), 1e-300), 1.0)
    std = np.array([np.sqrt(max(cov[0, 0], 0.0)), np.sqrt(max(cov[1, 1], 0.0)), np.sqrt(-2.0 * np.log(r))])
    return mean, cov, std


def estimate_pose(
    particles: ArrayLike,
    weights: ArrayLike | None = None,
    cluster_size: float = 0.5,
    min_share: float = 0.01,
    mass: float = 0.9,
) -> Estimate:
    """Summarise a weighted particle set: mean, spread and the best cluster.

    Clusters are found on a 2-D histogram of the particle weights with cells
    of side ``cluster_size`` (metres). The heaviest cells that together hold
    ``mass`` of the weight are kept (so that a thin veil of unlikely particles
    spread over the whole map does not join every hypothesis into one), and
    kept cells that touch (8-neighbourhood) form one cluster. The heaviest
    cluster's weighted mean is the pose estimate. Clusters holding less than
    ``min_share`` of the weight are not counted in ``n_clusters``.

    Parameters
    ----------
    particles : array_like (N, 3)
    weights : array_like (N,), optional
        Non-negative weights (normalised here); uniform if omitted.
    cluster_size : float
        Histogram cell side in metres, > 0.
    min_share : float
        Smallest weight share for a cluster to count, in [0, 1).
    mass : float
        Share of the weight the clustered cells must cover, in (0, 1].

    Examples
    --------
    Two equally likely hypotheses 10 m apart, one with a little more weight:

    >>> rng = np.random.default_rng(0)
    >>> a = rng.normal([2, 2, 0.3], 0.1, size=(600, 3))
    >>> b = rng.normal([12, 2, 1.6], 0.1, size=(400, 3))
    >>> e = estimate_pose(np.vstack([a, b]))
    >>> e.n_clusters, round(e.best_weight, 2), e.pose.round(1)
    (2, 0.6, array([2. , 2. , 0.3]))
    >>> e.mean[:2].round(1)                     # the mean lies between them, in no cluster
    array([6., 2.])
    """
    p = check_poses(particles, "particles")  # (N, 3); warns on a (3, 3) that looks transposed
    if p.ndim != 2 or p.shape[0] == 0:
        raise ValueError(f"particles must be a non-empty (N, 3) array; got shape {p.shape}")
    n = p.shape[0]
    if weights is None:
        w = np.full(n, 1.0 / n)
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != (n,):
            raise ValueError(f"weights must have shape ({n},); got {w.shape}")
        if np.any(~np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError("weights must be finite, non-negative and not all zero")
        w = w / w.sum()
    cluster_size = check_positive(cluster_size, "cluster_size", "metres")
    if not 0.0 <= min_share < 1.0:
        raise ValueError(f"min_share must lie in [0, 1); got {min_share!r}")
    if not 0.0 < mass <= 1.0:
        raise ValueError(f"mass must lie in (0, 1]; got {mass!r}")
    return _estimate(p, w, cluster_size, min_share, mass)


def _estimate(p: NDArray, w: NDArray, cluster_size: float, min_share: float, mass: float) -> Estimate:
    """:func:`estimate_pose` without input checks (``w`` normalised): the filter's fast path."""
    mean, cov, std = _weighted_stats(p, w)
    n_eff = float(1.0 / (w @ w))

    labels, n_lab = _cluster_labels(p[:, :2], w, cluster_size, mass)
    if n_lab == 0:
        return Estimate(mean.copy(), mean, std, cov, 1.0, 1, n_eff, std)
    inside = labels >= 0
    share = np.bincount(labels[inside], weights=w[inside], minlength=n_lab)
    if n_lab == 1 and share[0] >= mass * (1.0 - 1e-9):
        # one cluster that holds the weight the histogram was asked to cover: the belief is unimodal
        return Estimate(mean.copy(), mean, std, cov, 1.0, 1, n_eff, std)
    best = int(np.argmax(share))
    sel = labels == best
    wb = w[sel] / share[best]
    pose, _, cstd = _weighted_stats(p[sel], wb)
    n_clusters = int(np.count_nonzero(share >= max(min_share, 1e-12)))
    return Estimate(pose, mean, std, cov, float(share[best]), max(n_clusters, 1), n_eff, cstd)


def _cluster_labels(xy: NDArray, w: NDArray, size: float, mass: float) -> tuple[NDArray[np.int64], int]:
    """Cluster label (0..K-1, or -1 outside every cluster) of each weighted point.

    The points are binned into square cells of side ``size``; the heaviest
    cells holding together ``mass`` of the weight are kept (but none lighter
    than 1% of the heaviest cell), and kept cells that touch
    (8-neighbourhood) form one cluster.
    """
    from scipy.ndimage import label

    lo = xy.min(axis=0)
    span = xy.max(axis=0) - lo
    size = max(size, float(span.max()) / _MAX_CLUSTER_CELLS)
    ij = np.floor((xy - lo) / size).astype(np.int64)
    shape = tuple(int(v) + 1 for v in ij.max(axis=0))
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    cell_w = np.bincount(flat, weights=w, minlength=shape[0] * shape[1])
    # heaviest first; ties (cells holding the same number of equal-weight copies are common after
    # resampling) in index order: an unstable sort orders them differently on different CPUs
    order = np.argsort(-cell_w, kind="stable")
    k = int(np.searchsorted(np.cumsum(cell_w[order]), mass * cell_w.sum())) + 1
    keep = np.zeros(cell_w.size, dtype=bool)
    keep[order[:k]] = True
    # a thin veil of particles (random ones injected or drawn beside a converged cloud) must not join every
    # hypothesis into one map-wide cluster: cells a hundred times lighter than the heaviest do not count
    keep &= cell_w > max(0.01 * float(cell_w.max()), 0.0)
    lab, n = label(keep.reshape(shape), structure=np.ones((3, 3), dtype=bool))
    return lab.reshape(-1)[flat] - 1, int(n)


# --------------------------------------------------------------------------- status
@dataclass
class MCLStatus:
    """What the filter did in its last step, and running counters.

    Attributes
    ----------
    n_particles : int
        Current number of particles.
    n_eff : float
        Effective sample size after the last update.
    resampled : bool
        Whether the last step resampled.
    n_injected : int
        Random particles injected at the last resampling.
    p_inject : float
        Augmented MCL's injection probability ``max(0, 1 - w_fast / w_slow)``.
    log_evidence : float
        ``log sum_i W_i p(z | x_i)``: the log of the average measurement
        likelihood under the predicted belief (PR's ``w_avg``); ``-inf``
        when the measurement matched no particle.
    n_invalid : int
        Particles whose likelihood was NaN or +inf in the last update
        (treated as zero).
    degenerate : bool
        True when the last update left every particle with zero weight and
        the filter had to recover.
    n_degenerate : int
        How many updates so far needed that recovery.
    message : str
        A readable account of the last step's special events ("" if none).

    Examples
    --------
    >>> MCLStatus(n_particles=100, n_eff=100.0)
    MCLStatus(n_particles=100, n_eff=100.0, resampled=False, n_injected=0, p_inject=0.0, log_evidence=0.0, n_invalid=0, degenerate=False, n_degenerate=0, message='')
    """

    n_particles: int = 0
    n_eff: float = 0.0
    resampled: bool = False
    n_injected: int = 0
    p_inject: float = 0.0
    log_evidence: float = 0.0
    n_invalid: int = 0
    degenerate: bool = False
    n_degenerate: int = 0
    message: str = ""
    beta: float = field(default=1.0, repr=False)
    log_w_slow: float = field(default=-np.inf, repr=False)
    log_w_fast: float = field(default=-np.inf, repr=False)


@dataclass(frozen=True)
class Augmented:
    """Settings of augmented MCL (PR table 8.3).

    ``w_slow`` and ``w_fast`` are exponential moving averages of the average
    measurement likelihood ``w_avg`` with rates ``alpha_slow << alpha_fast``.
    When the short-term average drops below the long-term one -- the scans
    suddenly fit the particles much worse than they used to -- random
    particles are injected with probability ``max(0, 1 - w_fast / w_slow)``.

    PR starts both averages at 0, which leaves the filter unable to notice a
    failure until ``w_slow`` has grown -- for about ``1 / alpha_slow`` steps;
    here both start at the first ``w_avg`` instead.

    ``temperature`` divides the log-likelihoods before they enter the two
    averages (1 = PR's rule). A 60-beam scan's likelihood swings by many
    orders of magnitude from step to step, which makes the ratio jumpy; a
    temperature equal to the number of beams averages per beam instead.

    With ``temperature=1`` the rule can feed on itself when each measurement
    is weak (a few landmark sightings): injected particles lower the average
    likelihood, which raises the injection probability, until most of the
    set is random even while tracking well. The EKF-versus-MCL chapter uses
    ``temperature=5`` for that reason; watch ``status.n_injected`` when tuning.

    Examples
    --------
    >>> Augmented(alpha_slow=0.01, alpha_fast=0.2)
    Augmented(alpha_slow=0.01, alpha_fast=0.2, temperature=1.0)
    """

    alpha_slow: float = 0.01
    alpha_fast: float = 0.2
    temperature: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha_slow < 1.0:
            raise ValueError(f"alpha_slow must lie in (0, 1); got {self.alpha_slow!r}")
        if not self.alpha_slow < self.alpha_fast < 1.0:
            raise ValueError(
                f"alpha_fast must lie in (alpha_slow, 1) = ({self.alpha_slow}, 1); got {self.alpha_fast!r}"
            )
        check_positive(self.temperature, "temperature")


# --------------------------------------------------------------------------- the filter
class MCL:
    """Monte Carlo Localization: a particle filter over poses ``(x, y, theta)``.

    Parameters
    ----------
    particles : array_like (N, 3)
        The initial particle set (see :meth:`uniform` and :meth:`gaussian`).
    motion : callable or array_like of 4 floats
        ``motion(poses, u, rng) -> poses``; four numbers are taken as the
        ``alphas`` of the odometry model (:class:`OdometryMotion`).
    sensor : object
        Has ``log_likelihood(poses, *z) -> (N,)``; :meth:`update` passes its
        arguments through (``ranges, angles`` for the range models,
        ``z, ids`` for the landmark model).
    rng : numpy.random.Generator
        The filter's only source of randomness.
    log_weights : array_like (N,), optional
        Initial log-weights (uniform if omitted); normalised here.
    resampler : {"systematic", "stratified", "residual", "multinomial"} or callable
        A resampler of :mod:`localize.resample` or ``f(weights, rng) -> indices``.
    resample_threshold : float
        Resample when ``N_eff < resample_threshold * N``, in [0, 1]. 1 resamples
        at every step (the textbook loop), 0 never resamples on its own.
    injection : float
        Fraction of particles replaced by random ones at each resampling, in
        [0, 1) (the fixed 5% of the seed 003 tutorial is 0.05).
    augmented : Augmented or (alpha_slow, alpha_fast) or None
        Augmented MCL (PR table 8.3): inject with probability
        ``max(0, 1 - w_fast / w_slow)``. Resampling is forced whenever that
        probability is positive.
    kld : KLDSampling or None
        Adapt the number of particles at each resampling (Fox 2003).
    sampler : callable, optional
        ``sampler(n, rng) -> (n, 3)`` draws random particles for injection
        and recovery. Defaults to uniform over the free cells of ``grid``.
    grid : OccupancyGrid, optional
        The map: the default ``sampler`` and, with ``free_space_only``, the
        set of allowed positions.
    free_space_only : bool
        Give zero weight to particles outside the known-free cells of ``grid``
        (robots cannot stand in walls).
    unknown_allowed : bool
        With ``free_space_only``: let particles stand in *unknown* cells too
        (only known obstacles and the outside of the map are forbidden). Real
        maps leave parts of a building unknown, and the robot drives there.
    occupied_penalty : float
        With ``free_space_only``: the log-likelihood a particle in a known
        obstacle loses at each update (> 0 nats). ``np.inf`` (the default)
        gives it zero weight. A finite penalty keeps the cloud of a robot that
        drives through an obstacle the map is wrong about (a door drawn shut,
        furniture since moved, a wall drawn too thick): when every particle is
        in it, every particle pays the same and the scans decide. Outside the
        grid the weight is zero either way. The attribute ``soft_obstacles``
        (True) switches the penalty on and off: :func:`run_filter` applies it
        only while the cloud agrees on one place, and gives particles in
        obstacles zero weight while it searches (a hypothesis in a wall is
        then just a wrong one).
    unknown_penalty : float
        With ``unknown_allowed``: subtract this from the log-likelihood of
        particles in unknown cells at each update (>= 0). A soft prior: when
        the whole cloud is in an unknown region it changes nothing (every
        particle pays it), but a few particles that wandered through a wall
        into the unknown outside of a building lose against those inside.
    min_ess : float
        Adaptive tempering, in [0, 1): when one update would leave fewer than
        ``min_ess * N`` effective particles, its log-likelihood is scaled by
        the largest factor ``beta <= 1`` that keeps ``min_ess * N`` of them
        (found by bisection; ``status.beta``). The annealing of Deutscher et
        al. (2000) and of adaptive SMC samplers: no single scan may collapse
        the cloud, so the outcome of global localization no longer hinges on
        which few particles happened to fit the *first* scans best -- a
        chance that grows with the number of particles (the best of more
        random poses fits a look-alike place better). 0 (default) switches it
        off.
    on_degenerate : {"keep", "reinitialize"}
        What to do when an update leaves every particle with zero weight:
        keep the particles and previous weights, ignoring the measurement
        (default), or re-draw all particles with ``sampler``.

    Examples
    --------
    A one-dimensional toy: a sensor that measures x with 0.2 m noise, a robot
    that does not move, particles spread over [0, 10] m.

    >>> class GPS:
    ...     def log_likelihood(self, poses, z):
    ...         return -0.5 * ((poses[:, 0] - z) / 0.2) ** 2
    >>> still = lambda poses, u, rng: poses
    >>> rng = np.random.default_rng(0)
    >>> p0 = np.column_stack([rng.uniform(0, 10, 2000), np.full(2000, 5.0), np.zeros(2000)])
    >>> f = MCL(p0, still, GPS(), rng=rng)
    >>> for _ in range(5):
    ...     e = f.step(None, 3.0)
    >>> round(float(e.pose[0]), 1), round(float(e.std[0]), 2)
    (3.0, 0.09)
    """

    def __init__(
        self,
        particles: ArrayLike,
        motion: Motion | ArrayLike,
        sensor: Any,
        *,
        rng: np.random.Generator,
        log_weights: ArrayLike | None = None,
        resampler: str | Callable[[NDArray, np.random.Generator], NDArray] = "systematic",
        resample_threshold: float = 0.5,
        injection: float = 0.0,
        augmented: Augmented | tuple[float, float] | None = None,
        kld: KLDSampling | None = None,
        sampler: Sampler | None = None,
        grid: OccupancyGrid | None = None,
        free_space_only: bool = False,
        on_degenerate: str = "keep",
        unknown_allowed: bool = False,
        unknown_penalty: float = 0.0,
        min_ess: float = 0.0,
        occupied_penalty: float = np.inf,
    ) -> None:
        self.rng = check_rng(rng)
        p = check_poses(particles, "particles")  # (N, 3); warns on a (3, 3) that looks transposed
        if p.ndim != 2 or p.shape[0] < 1:
            raise ValueError(f"particles must be an (N, 3) array with N >= 1; got shape {p.shape}")
        self.particles = np.array(p, dtype=float)
        self.particles[:, 2] = wrap_angle(self.particles[:, 2])
        n = self.particles.shape[0]
        if log_weights is None:
            self.log_weights = np.full(n, -np.log(n))
        else:
            lw = np.asarray(log_weights, dtype=float)
            if lw.shape != (n,):
                raise ValueError(f"log_weights must have shape ({n},) like the particles; got {lw.shape}")
            if np.any(np.isnan(lw)) or np.any(lw == np.inf):
                raise ValueError("log_weights must not contain NaN or +inf")
            norm = _rs.logsumexp(lw)
            if not np.isfinite(norm):
                raise ValueError("log_weights are -inf everywhere; at least one particle needs a positive weight")
            self.log_weights = lw - norm

        if callable(motion):
            self.motion = motion
        else:
            self.motion = OdometryMotion(motion)
        if not callable(getattr(sensor, "log_likelihood", None)):
            raise TypeError(
                "sensor must have a method log_likelihood(poses, *z) -> (N,) "
                f"(e.g. localize.sensors.BeamModel); got {type(sensor).__name__}"
            )
        self.sensor = sensor
        self._resample_fn = _rs.get_resampler(resampler)
        self.resampler_name = resampler if isinstance(resampler, str) else getattr(resampler, "__name__", "custom")
        thr = float(resample_threshold)
        if not 0.0 <= thr <= 1.0:
            raise ValueError(f"resample_threshold must lie in [0, 1] (a fraction of N); got {resample_threshold!r}")
        self.resample_threshold = thr
        inj = float(injection)
        if not 0.0 <= inj < 1.0:
            raise ValueError(f"injection must be a fraction in [0, 1); got {injection!r}")
        self.injection = inj
        if augmented is not None and not isinstance(augmented, Augmented):
            try:
                augmented = Augmented(*augmented)
            except TypeError:
                raise TypeError(
                    f"augmented must be an Augmented(...) or a pair (alpha_slow, alpha_fast); got {augmented!r}"
                ) from None
        self.augmented = augmented
        if kld is not None and not isinstance(kld, KLDSampling):
            raise TypeError(f"kld must be a localize.kld.KLDSampling or None; got {type(kld).__name__}")
        self.kld = kld
        self.grid = None if grid is None else check_grid(grid)
        if sampler is None and grid is not None:
            sampler = grid.sample_free
        self.sampler = sampler
        if on_degenerate not in ("keep", "reinitialize"):
            raise ValueError(f"on_degenerate must be 'keep' or 'reinitialize'; got {on_degenerate!r}")
        self.on_degenerate = on_degenerate
        if sampler is None and (inj > 0 or augmented is not None or on_degenerate == "reinitialize"):
            raise ValueError(
                "random injection, augmented MCL and on_degenerate='reinitialize' need random particles: "
                "pass grid=... (uniform over free cells) or sampler=f(n, rng)"
            )
        if free_space_only and grid is None:
            raise ValueError("free_space_only=True needs the map: pass grid=...")
        self.free_space_only = bool(free_space_only)
        me = float(min_ess)
        if not 0.0 <= me < 1.0:
            raise ValueError(f"min_ess must be a fraction in [0, 1); got {min_ess!r}")
        self.min_ess = me
        pen = check_nonnegative(unknown_penalty, "unknown_penalty")
        self.unknown_penalty = pen if (free_space_only and unknown_allowed) else 0.0
        if self.free_space_only:
            allowed = ~grid.occupied if unknown_allowed else grid.free
            self._free = np.ascontiguousarray(allowed)
            if self.unknown_penalty:
                self._unknown = np.ascontiguousarray(grid.unknown)
        op = float(occupied_penalty)
        if not op > 0:
            raise ValueError(f"occupied_penalty must be > 0 nats (np.inf: zero weight); got {occupied_penalty!r}")
        self.occupied_penalty = op
        self.soft_obstacles = True      # run_filter: only once the cloud agrees on one place
        if self.free_space_only and np.isfinite(op):
            self._occupied = np.ascontiguousarray(grid.occupied)
        self.status = MCLStatus(n_particles=n, n_eff=self.n_eff)

    # ------------------------------------------------------------ constructors
    @classmethod
    def uniform(
        cls,
        grid: OccupancyGrid,
        n: int,
        motion: Motion | ArrayLike,
        sensor: Any,
        *,
        rng: np.random.Generator,
        **options: Any,
    ) -> "MCL":
        """Global localization: ``n`` particles uniform over the free cells of ``grid``.

        ``grid`` is also passed on as the filter's map (random injection and
        recovery draw from its free space). Other options as in :class:`MCL`.

        Examples
        --------
        >>> from localize.maps import office
        >>> class Flat:
        ...     def log_likelihood(self, poses, *z):
        ...         return np.zeros(len(poses))
        >>> f = MCL.uniform(office(), 1000, (0.01,) * 4, Flat(), rng=np.random.default_rng(0))
        >>> f.n, round(f.status.n_eff)
        (1000, 1000)
        """
        rng = check_rng(rng)
        options.setdefault("grid", grid)
        return cls(uniform_particles(grid, n, rng), motion, sensor, rng=rng, **options)

    @classmethod
    def gaussian(
        cls,
        mean: ArrayLike,
        cov: ArrayLike,
        n: int,
        motion: Motion | ArrayLike,
        sensor: Any,
        *,
        rng: np.random.Generator,
        **options: Any,
    ) -> "MCL":
        """Pose tracking: ``n`` particles from a Gaussian around a known start pose.

        ``cov`` is a (3, 3) covariance or three standard deviations.

        Examples
        --------
        >>> class Flat:
        ...     def log_likelihood(self, poses, *z):
        ...         return np.zeros(len(poses))
        >>> f = MCL.gaussian([1, 2, 0.5], (0.1, 0.1, 0.05), 500, (0.01,) * 4, Flat(), rng=np.random.default_rng(0))
        >>> f.estimate().pose.round(1)
        array([1. , 2. , 0.5])
        """
        rng = check_rng(rng)
        return cls(gaussian_particles(mean, cov, n, rng), motion, sensor, rng=rng, **options)

    # ------------------------------------------------------------ properties
    @property
    def n(self) -> int:
        """Current number of particles."""
        return int(self.particles.shape[0])

    @property
    def weights(self) -> NDArray[np.float64]:
        """Normalised weights ``exp(log_weights)`` (they sum to 1)."""
        return np.exp(self.log_weights)

    @property
    def n_eff(self) -> float:
        """Effective sample size ``1 / sum(w**2)``, in [1, N]."""
        return float(np.exp(-_rs.logsumexp(2.0 * self.log_weights)))

    # ------------------------------------------------------------ the loop
    def predict(self, u: Any) -> None:
        """Move every particle by a sample of the motion model given control ``u``.

        For the odometry model ``u = (prev_odom, odom)``. Weights are
        unchanged (PR table 8.2 line 4).

        Examples
        --------
        >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
        >>> f.predict(1.0)
        >>> float(f.particles[0, 0]), float(f.particles[-1, 0])
        (1.0, 11.0)
        """
        new = self.motion(self.particles, u, self.rng)
        new = np.asarray(new, dtype=float)
        if new.shape != self.particles.shape:
            raise ValueError(
                f"the motion model returned shape {new.shape}; expected {self.particles.shape} like the particles"
            )
        self.particles = new

    def update(self, *z: Any, **kwargs: Any) -> None:
        """Weight the particles by the measurement: ``log w += log p(z | x)``.

        Arguments go to ``sensor.log_likelihood(particles, *z, **kwargs)``.
        NaN or +inf likelihoods count as invalid (zero weight, reported in
        ``status.n_invalid``). If no particle keeps a positive weight the
        filter recovers as ``on_degenerate`` says and sets
        ``status.degenerate``.

        Examples
        --------
        >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
        >>> f.update(3.0)
        >>> int(np.argmax(f.weights)), round(float(f.weights.sum()), 6), round(f.status.n_eff, 1)
        (30, 1.0, 17.7)
        >>> f.update(1e6)                  # absurd, but in log space the weights stay finite
        >>> f.status.degenerate
        False
        >>> f.update(np.inf)               # likelihood exactly zero for every particle
        >>> f.status.degenerate, f.status.message
        (True, 'every particle got zero likelihood: measurement ignored, weights kept')
        """
        st = self.status
        # log(0) = -inf and 0/0 = NaN inside a sensor model are handled below (and reported in the
        # status), so their floating-point warnings are silenced here
        with np.errstate(divide="ignore", invalid="ignore"):
            ll = np.asarray(self.sensor.log_likelihood(self.particles, *z, **kwargs), dtype=float)
        n = self.n
        if ll.shape != (n,):
            raise ValueError(f"sensor.log_likelihood returned shape {ll.shape}; expected ({n},), one per particle")
        bad = np.isnan(ll) | (ll == np.inf)
        n_bad = int(np.count_nonzero(bad))
        if n_bad:
            ll = np.where(bad, -np.inf, ll)
        if self.free_space_only:
            allowed = self._in_free_space(self.particles)
            if np.isfinite(self.occupied_penalty) and self.soft_obstacles:   # in a known obstacle: a finite penalty
                ll = np.where(allowed, ll, np.where(self._in_free_space(self.particles, self._occupied),
                                                    ll - self.occupied_penalty, -np.inf))
            else:
                ll = np.where(allowed, ll, -np.inf)
            if self.unknown_penalty:
                ll = ll - self.unknown_penalty * self._in_free_space(self.particles, self._unknown)
        st.beta = 1.0
        if self.min_ess > 0:
            ll, st.beta = _adaptive_temper(self.log_weights, ll, self.min_ess * n)
        lw = self.log_weights + ll
        w, lnorm = _rs.normalize_log_weights(lw)      # log-sum-exp; lnorm = -inf when no particle fits
        st.n_invalid = n_bad
        st.log_evidence = lnorm
        st.message = f"{n_bad} invalid likelihood(s) treated as zero" if n_bad else ""
        if not np.isfinite(lnorm):
            st.degenerate = True
            st.n_degenerate += 1
            if self.on_degenerate == "reinitialize":
                self.particles = self.sampler(n, self.rng)
                self.log_weights = np.full(n, -np.log(n))
                what = "particles re-drawn from the sampler"
            else:
                what = "measurement ignored, weights kept"
            st.message = (st.message + "; " if st.message else "") + (
                f"every particle got zero likelihood: {what}"
            )
            st.n_eff = self.n_eff
            if self.augmented is not None:
                # the worst possible fit is exactly when augmented MCL must inject: w_avg = 0
                self._update_averages(-np.inf)
        else:
            st.degenerate = False
            lw -= lnorm
            self.log_weights = lw
            if self.augmented is not None:
                self._update_averages(lnorm)
            st.n_eff = float(1.0 / (w @ w))

    def _update_averages(self, log_w_avg: float) -> None:
        a = self.augmented
        st = self.status
        lw = log_w_avg / a.temperature
        if st.log_w_slow == -np.inf:          # first measurement: start both averages at w_avg
            if lw == -np.inf:                 # nothing to compare with yet
                return
            st.log_w_slow = st.log_w_fast = lw
        st.log_w_slow = _ema_log(st.log_w_slow, lw, a.alpha_slow)
        st.log_w_fast = _ema_log(st.log_w_fast, lw, a.alpha_fast)
        p = float(-np.expm1(st.log_w_fast - st.log_w_slow))
        st.p_inject = p if p > _P_INJECT_NOISE else 0.0

    def needs_resampling(self) -> bool:
        """The resampling policy: ``N_eff < threshold * N``, or injection is due.

        With ``resample_threshold = 1`` every step resamples; augmented MCL
        forces a resampling whenever its injection probability is positive.

        Examples
        --------
        >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
        >>> f.needs_resampling()           # equal weights: N_eff = N
        False
        >>> f.update(3.0)
        >>> f.needs_resampling()           # N_eff = 17.7 < 0.5 * 101
        True
        """
        if self.augmented is not None and self.status.p_inject > 0:
            return True
        if self.resample_threshold >= 1.0:
            return True
        return _rs.needs_resampling(self.weights, self.resample_threshold)

    def resample(self) -> None:
        """Draw a new, equally weighted particle set (always; see :meth:`needs_resampling`).

        With KLD-sampling the new set's size is chosen by the KLD bound; then
        random particles replace ``injection * N`` of the new set (rounded)
        or, with augmented MCL, each particle with probability ``p_inject``
        -- whichever replaces more.

        Examples
        --------
        >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
        >>> f.update(3.0)
        >>> f.resample()
        >>> bool(np.all(np.abs(f.particles[:, 0] - 3.0) < 2.0)), round(f.n_eff)
        (True, 101)
        """
        st = self.status
        w = self.weights
        if self.kld is None:
            idx = np.asarray(self._resample_fn(w, self.rng))
            if idx.shape != (self.n,):
                raise ValueError(f"the resampler returned shape {idx.shape}; expected ({self.n},)")
            new = self.particles[idx]
        else:
            # n_max i.i.d. draws in random order: every prefix is an i.i.d. sample (PR table 8.4)
            sizes = [self.kld.n_max]
            if self.kld.chunked:
                first = min(self.kld.n_max, max(4 * self.kld.n_min, 2 * self.n))
                sizes = [first] + ([self.kld.n_max] if first < self.kld.n_max else [])
            for size in sizes:
                draws = _rs.multinomial(w, self.rng, n=size)
                cand = self.particles[self.rng.permutation(draws)]
                m = kld_sample_size(cand, self.kld.bin_size, self.kld.epsilon, self.kld.delta, self.kld.n_min)
                if m < size:
                    break
            new = cand[:m]
        n = new.shape[0]
        n_inj = int(round(self.injection * n))
        if self.augmented is not None and st.p_inject > 0:
            n_inj = max(n_inj, int(self.rng.binomial(n, st.p_inject)))
        if n_inj > 0:
            where = self.rng.choice(n, size=n_inj, replace=False) if n_inj < n else np.arange(n)
            new = new.copy() if new.base is not None else new
            new[where] = np.asarray(self.sampler(n_inj, self.rng), dtype=float)
        self.particles = new
        self.log_weights = np.full(n, -np.log(n))
        st.n_injected = n_inj
        st.resampled = True
        st.n_particles = n
        st.n_eff = float(n)

    def estimate(self, cluster_size: float = 0.5, min_share: float = 0.01, mass: float = 0.9) -> Estimate:
        """Summarise the belief (see :func:`estimate_pose`, whose checks it skips: the filter's own
        particles and normalised weights are valid by construction).

        Examples
        --------
        >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
        >>> f.update(3.0)
        >>> e = f.estimate()
        >>> round(float(e.pose[0]), 1), round(float(e.std[0]), 2), e.n_clusters
        (3.0, 0.5, 1)
        """
        w = self.weights
        return _estimate(self.particles, w / w.sum(), check_positive(cluster_size, "cluster_size", "metres"),
                         float(min_share), float(mass))

    def step(self, u: Any, *z: Any, **kwargs: Any) -> Estimate:
        """One full filter step: predict, update, estimate, resample if the policy says so.

        ``u`` is the control (``None`` skips the prediction), ``z`` the
        measurement arguments for the sensor model (none skips the update).
        The estimate is taken from the weighted set *before* resampling,
        which adds no resampling noise to it. Returns that estimate.

        Examples
        --------
        >>> f = toy_mcl()      # 101 particles on x = 0..10 m; u shifts x; z is a GPS reading of x (0.5 m noise)
        >>> e = f.step(0.5, 3.0)          # move 0.5 m, then measure x = 3
        >>> round(float(e.pose[0]), 1), f.status.resampled
        (3.0, True)
        """
        st = self.status
        st.resampled = False
        st.n_injected = 0
        if u is not None:
            self.predict(u)
        if z:
            self.update(*z, **kwargs)
        est = self.estimate()
        if self.needs_resampling():
            self.resample()
        st.n_particles = self.n
        return est

    def _in_free_space(self, poses: NDArray, mask: NDArray | None = None) -> NDArray[np.bool_]:
        mask = self._free if mask is None else mask
        g = self.grid
        rel = (poses[:, :2] - g.origin) / g.resolution
        j = np.floor(rel[:, 0]).astype(np.int64)
        i = np.floor(rel[:, 1]).astype(np.int64)
        h, w = self._free.shape
        ok = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        out = np.zeros(poses.shape[0], dtype=bool)
        out[ok] = mask[i[ok], j[ok]]
        return out

    def __repr__(self) -> str:
        opts = [f"n={self.n}", f"resampler={self.resampler_name!r}", f"threshold={self.resample_threshold:g}"]
        if self.injection:
            opts.append(f"injection={self.injection:g}")
        if self.augmented is not None:
            opts.append(f"augmented=({self.augmented.alpha_slow:g}, {self.augmented.alpha_fast:g})")
        if self.kld is not None:
            opts.append(f"kld=(eps={self.kld.epsilon:g}, delta={self.kld.delta:g})")
        return "MCL(" + ", ".join(opts) + ")"


# --------------------------------------------------------------------------- running a log
def run_mcl(
    mcl: "MCL",
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
    mcl : MCL
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


# --------------------------------------------------------------------------- helpers
def _ess(lw: NDArray) -> float:
    """Effective sample size of log-weights ``lw`` (0 when every weight is zero)."""
    n_eff = _rs.effective_sample_size_log(lw)
    return 0.0 if np.isnan(n_eff) else n_eff


def _adaptive_temper(log_w: NDArray, ll: NDArray, target: float) -> tuple[NDArray, float]:
    """``(beta * ll, beta)`` with the largest ``beta`` in (0, 1] whose update keeps ``target`` effective particles.

    ``-inf`` entries of ``ll`` (impossible poses) stay ``-inf`` at every ``beta``.
    """
    ok = np.isfinite(ll)
    if _ess(log_w + ll) >= target:
        return ll, 1.0
    llf = np.where(ok, ll, 0.0)
    base = np.where(ok, log_w, -np.inf)
    if _ess(base) < target:                 # the impossible poses alone leave too few: use the bare mask
        return np.where(ok, 0.0, -np.inf), 0.0
    lo, hi = 0.0, 1.0
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        if _ess(base + mid * llf) >= target:
            lo = mid
        else:
            hi = mid
    return np.where(ok, lo * llf, -np.inf), lo


def _ema_log(log_old: float, log_new: float, alpha: float) -> float:
    """``log((1 - alpha) * exp(log_old) + alpha * exp(log_new))`` without leaving log space."""
    return float(np.logaddexp(np.log1p(-alpha) + log_old, np.log(alpha) + log_new))


# --------------------------------------------------------------------------- the oracle
def mcl_step_loop(
    particles: ArrayLike,
    u: Any,
    z: tuple,
    motion: Motion,
    sensor: Any,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """One step of the textbook particle filter, written as PR table 8.2.

    For each particle: sample the motion model, weight it by the sensor
    model; then draw ``M`` particles with probability proportional to the
    weights (multinomial). Readable and slow; the tests compare
    :class:`MCL` against it statistically.

    Examples
    --------
    >>> move = lambda poses, u, rng: poses + [u, 0.0, 0.0]
    >>> p = np.column_stack([np.linspace(0, 4, 401), np.zeros(401), np.zeros(401)])
    >>> new = mcl_step_loop(p, 1.0, (3.0,), move, GPS(0.5), np.random.default_rng(0))   # GPS: see conftest.py
    >>> round(float(new[:, 0].mean()), 1)
    3.0
    """
    p = as_poses(particles, "particles")
    m = p.shape[0]
    moved = []
    weights = []
    for k in range(m):
        x = np.asarray(motion(p[k : k + 1], u, rng), dtype=float)[0]
        w = float(np.exp(sensor.log_likelihood(x[None, :], *z)[0]))
        moved.append(x)
        weights.append(w)
    total = sum(weights)
    out = []
    for _ in range(m):
        # spin the roulette wheel: walk the cumulative weights until they pass r
        r = rng.random() * total
        i = 0
        c = weights[0]
        while c <= r and i < m - 1:
            i += 1
            c += weights[i]
        out.append(moved[i])
    return np.array(out)


# --------------------------------------------------------------------------- the run driver
STATES = ("searching", "localized", "lost")


class RobustOdometry:
    """An odometry motion model with an outlier part: odometry that is plainly wrong now and then.

    The textbook model (PR table 5.6) assumes the odometry is right up to a
    few per cent. Real odometry fails outright: wheels slip, the robot is
    pushed, and some robots' odometry reports the *speed* without its sign,
    so that a robot backing out of a room seems to drive forward (the
    Freiburg 079 log does this in about 100 of its steps). No particle then
    follows the robot, and the scans cannot pull back a cloud that nowhere
    covers the truth. So a share ``outlier`` of the particles (drawn afresh
    at every step) moves by an odometry outlier instead: the reported
    translation scaled by a factor uniform in ``[-scale, scale]`` (standing
    still, backwards, too far), the reported rotation with noise of
    ``rot_std`` rad plus 20% of the rotation. The rest moves by ``base``. The
    scans decide which particles were right, as they always do; while the
    odometry is fine the outliers are weighted away at no cost but the share.

    Parameters
    ----------
    base : callable
        The ordinary motion model ``base(poses, u, rng)`` (e.g. :class:`ReversibleOdometry`).
    outlier : float
        Share of particles moved by an outlier, in [0, 1).
    scale : float
        Largest factor on the reported translation (> 0).
    rot_std : float
        Rotation noise of an outlier (radians, >= 0).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> m = RobustOdometry(ReversibleOdometry((0.05, 0.01, 0.02, 0.05)), outlier=0.1)
    >>> p = m(np.zeros((10000, 3)), ([0.0, 0.0, 0.0], [0.1, 0.0, 0.0]), rng)
    >>> back = p[:, 0] < -0.05                  # moved backwards although the odometry said forwards
    >>> bool(0.02 < back.mean() < 0.04), bool(np.median(p[:, 0]) > 0.09)
    (True, True)
    """

    def __init__(self, base: Callable, outlier: float = 0.1, scale: float = 1.5, rot_std: float = 0.05) -> None:
        if not callable(base):
            raise TypeError(f"base must be a motion model base(poses, u, rng); got {type(base).__name__}")
        if not 0.0 <= float(outlier) < 1.0:
            raise ValueError(f"outlier must be a fraction in [0, 1); got {outlier!r}")
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be a positive number; got {scale!r}")
        if not (np.isfinite(rot_std) and rot_std >= 0):
            raise ValueError(f"rot_std must be a number of radians >= 0; got {rot_std!r}")
        self.base, self.outlier, self.scale, self.rot_std = base, float(outlier), float(scale), float(rot_std)

    @property
    def alphas(self) -> Any:
        return getattr(self.base, "alphas", None)

    def __call__(self, poses: NDArray[np.float64], u: Any, rng: np.random.Generator) -> NDArray[np.float64]:
        out = np.asarray(self.base(poses, u, rng), dtype=float)
        pair = _odometry_pair(u)
        if pair is None or self.outlier <= 0 or len(out) == 0:
            return out
        m = np.flatnonzero(rng.random(len(out)) < self.outlier)
        if m.size == 0:
            return out
        dx, dy, dth = _relative(*pair)
        s = rng.uniform(-self.scale, self.scale, m.size)
        q = np.asarray(poses, dtype=float)[m]
        c, sn = np.cos(q[:, 2]), np.sin(q[:, 2])
        out = out.copy() if out is poses else out
        out[m, 0] = q[:, 0] + s * (c * dx - sn * dy)
        out[m, 1] = q[:, 1] + s * (sn * dx + c * dy)
        out[m, 2] = wrap_angle(q[:, 2] + dth + rng.normal(0.0, self.rot_std + 0.2 * abs(dth), m.size))
        return out

    def __repr__(self) -> str:
        return f"RobustOdometry({self.base!r}, outlier={self.outlier:g}, scale={self.scale:g})"


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
      sigma_hit^2)| < fit_distance)``, see :func:`expected_fit`). A filter
      can agree with itself on a wrong place (a converged cloud in a room
      that looks alike); the fit catches most of that, because the
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
    counts as confidently wrong, for :func:`run_filter`'s ``restart_after``:
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


def expected_fit(sensor: Any, fit_distance: float) -> float:
    """Share of valid beams a range model expects within ``fit_distance`` of an obstacle on the correct pose.

    For a mixture with a Gaussian hit part (``z_hit``, ``sigma_hit``) it is
    ``z_hit * P(|N(0, sigma_hit^2)| < fit_distance)``; other models get 0.9.

    Examples
    --------
    >>> class LF:
    ...     z_hit, sigma_hit = 0.9, 0.1
    >>> round(expected_fit(LF(), 0.2), 3)          # 0.9 * P(|Z| < 2)
    0.859
    """
    from math import erf, sqrt

    z_hit = getattr(sensor, "z_hit", None)
    sigma = getattr(sensor, "sigma_hit", None)
    if z_hit is None or sigma is None:
        return 0.9
    return float(z_hit) * erf(float(fit_distance) / (float(sigma) * sqrt(2.0)))


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
        ``searching``, ``localized`` or ``lost`` (see :class:`StateRules`).
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
        ``searching``, ``localized`` or ``lost`` (see :class:`StateRules`).
    events : list of (int, str)
        Special events: rejected odometry, re-drawn particles, state changes.
    beam_evaluations : int
        Particle x beam likelihood evaluations (the run's machine-independent cost).
    seconds : float
        Wall time of the filtering loop.
    snapshots : dict[int, tuple[ndarray, ndarray]]
        ``step -> (particles, weights)`` after the update of that step.
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
        }


#: The old name of :class:`RunTrace` (what :func:`run_mcl` returned before the run driver was one).
MCLTrace = RunTrace


def _intervals(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.diff(m.astype(np.int8))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return [(int(a), int(b)) for a, b in zip(starts, stops)]


def _is_scan(z: Any) -> bool:
    """True for a range scan ``(ranges (B,), angles (B,))``."""
    if not isinstance(z, tuple) or len(z) != 2:
        return False
    a, b = np.shape(z[0]), np.shape(z[1])
    return len(a) == 1 and a == b


def _odometry_pair(u: Any) -> tuple[NDArray, NDArray] | None:
    """``(prev, cur)`` if ``u`` is a pair of odometry poses, else None."""
    if isinstance(u, tuple) and len(u) == 2:
        a, b = np.asarray(u[0], dtype=float), np.asarray(u[1], dtype=float)
        if a.shape == (3,) and b.shape == (3,):
            return a, b
    return None


def run_filter(
    mcl: "MCL",
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
) -> RunTrace:
    """The one run driver: filter a sequence of controls and scans, with update gating and an honest state.

    The command line (:func:`localize.cli.localize_log`), the book's chapters
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
    mcl : MCL
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

    Returns
    -------
    RunTrace

    Examples
    --------
    A robot standing in the office world, its laser simulated; the filter
    starts uniform and localizes:

    >>> from localize.maps import office
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
    """
    rules = StateRules() if rules is None else rules
    if not 0.0 <= float(recovery_injection) < 1.0:
        raise ValueError(f"recovery_injection must be a fraction in [0, 1); got {recovery_injection!r}")
    base_injection = mcl.injection
    n_restart = mcl.kld.n_max if mcl.kld is not None else mcl.n
    short_m = float(skip_short_beams)
    if not (np.isfinite(short_m) and short_m >= 0):
        raise ValueError(f"skip_short_beams must be a length in metres >= 0 (0: never); got {skip_short_beams!r}")
    ex_xy, ex_th = (float(v) for v in expand)
    if not (np.isfinite(ex_xy) and np.isfinite(ex_th) and ex_xy >= 0 and ex_th >= 0):
        raise ValueError(f"expand must be two numbers >= 0 (metres, radians); got {expand!r}")
    poor = lost_run = 0
    recent: list[float] = []
    since_loss: list[float] | None = None   # the fits judged since the state last turned lost (None: not lost)
    fit_s = float("nan")
    t = int(n_steps)
    if t < 1:
        raise ValueError(f"n_steps must be >= 1; got {n_steps!r}")
    grid = mcl.grid if grid is None else grid
    if grid is not None and not isinstance(grid, OccupancyGrid):
        raise TypeError(f"grid must be an OccupancyGrid or None; got {type(grid).__name__}")
    if max_step is None and grid is not None:
        max_step = float(np.hypot(grid.width_m, grid.height_m))
    d_min, a_min = (float(v) for v in min_motion)
    odom = None if odometry is None else np.asarray(odometry, dtype=float)
    keep = {int(k) for k in snapshot_steps}
    sensor = mcl.sensor
    offset = np.asarray(getattr(sensor, "sensor_offset", np.zeros(3)), dtype=float)
    lo_r = float(getattr(sensor, "min_range", 0.0) or 0.0)
    hi_r = float(getattr(sensor, "max_range", np.inf))
    fit_d = rules.fit_distance
    if fit_d is None:
        fit_d = 2.0 * float(getattr(sensor, "sigma_hit", 0.2))
    fit_expected = expected_fit(sensor, fit_d)
    if grid is not None:
        from .raycast import RayCaster

        caster = RayCaster(grid, hi_r if np.isfinite(hi_r) else 1e3, method="march")
        free = ~grid.occupied         # "on the map": inside the grid and not in a known obstacle
        inside_grid = np.ones(grid.shape, dtype=bool)
    out = {name: np.zeros((t, 3)) for name in ("poses", "means", "stds")}
    spread, best, n_eff, p_inj, fit, on_map = (np.full(t, np.nan) for _ in range(6))
    n_p, n_inj, n_valid = (np.zeros(t, dtype=np.int64) for _ in range(3))
    updated, resampled, degen = (np.zeros(t, dtype=bool) for _ in range(3))
    state = np.empty(t, dtype="<U9")
    events: list[tuple[int, str]] = []
    snaps: dict = {}
    evals = 0
    st = mcl.status
    cur = "searching"
    good = bad = 0
    n_expanded = 0
    last_odom: NDArray | None = None
    agreed_before = False      # the cloud agreed on one place at the last step (for skip_unknown_beams)
    unjudged = 0               # updates of the current poor run whose fit the map could not judge
    soft_penalty = bool(np.isfinite(getattr(mcl, "occupied_penalty", np.inf)))   # ... and for occupied_penalty
    n_skipped = n_blind = n_shorts = 0
    trial: dict | None = None  # after a restart: the old cloud (particles [:n_old]) on probation beside the fresh one
    t0 = _now()
    for k in range(t):
        st.resampled = False
        st.n_injected = 0
        u = control(k) if k > 0 else None
        pair = _odometry_pair(u) if u is not None else None
        if pair is not None:
            step_len = float(np.hypot(*(pair[1][:2] - pair[0][:2])))
            if not np.all(np.isfinite(pair[0])) or not np.all(np.isfinite(pair[1])) or (
                    max_step is not None and step_len > max_step):
                events.append((k, f"odometry step of {step_len:.3g} m is impossible (longer than {max_step:.3g} m, "
                                  "the map's diagonal): corrupt record rejected, particles not moved"))
                u = None
        if u is not None:
            mcl.predict(u)
        z = scan(k)
        do_update = z is not None
        where = None if odom is None else odom[k]
        if where is None and pair is not None:
            where = pair[1]
        if do_update and last_odom is not None and where is not None and (d_min > 0 or a_min > 0):
            m = _relative(last_odom, where)
            do_update = bool(not np.all(np.isfinite(m)) or np.hypot(m[0], m[1]) >= d_min or abs(m[2]) >= a_min)
        n_p[k] = mcl.n
        if _is_scan(z):
            ranges, angles = np.asarray(z[0], dtype=float), np.asarray(z[1], dtype=float)
            valid = np.isfinite(ranges) & (ranges > lo_r) & (ranges < hi_r)
            n_valid[k] = int(valid.sum())
        if do_update and (skip_unknown_beams or short_m > 0) and agreed_before and grid is not None and _is_scan(z):
            z, n_skip, n_short = _skip_beams(grid, mcl, offset, z, hi_r, unknown=skip_unknown_beams,
                                             caster=caster, short=short_m)
            n_skipped += n_skip
            n_shorts += n_short
            if n_skip or n_short:
                if not np.any(np.asarray(z[0]) < hi_r):
                    do_update = False
                    n_blind += 1
        if do_update:
            if soft_penalty:
                mcl.soft_obstacles = agreed_before
            mcl.update(*z)
            evals += int(n_p[k]) * (int(np.size(z[1])) if _is_scan(z) else 1)
            last_odom = where
        if k in keep:
            w = mcl.weights
            sub = slice(None)
            if snapshot_particles is not None and mcl.n > snapshot_particles:
                sub = np.linspace(0, mcl.n - 1, int(snapshot_particles)).astype(int)
            snaps[k] = (mcl.particles[sub].copy(), w[sub].copy())
        e = mcl.estimate()
        if trial is not None:
            e = _trial_estimate(mcl, trial, e)
        pose = e.pose if np.all(np.isfinite(e.pose)) else e.mean
        out["poses"][k], out["means"][k], out["stds"][k] = pose, e.mean, e.std
        spread[k], best[k], n_eff[k] = e.spread, e.best_weight, st.n_eff
        degenerate = bool(do_update and st.degenerate)
        degen[k] = degenerate
        # ---- evidence
        if grid is not None:
            inside = _free_share(grid, free, mcl.particles, mcl.weights)
            on_map[k] = inside
        if do_update and grid is not None and n_valid[k] > 0 and _is_scan(z):
            fit[k] = _scan_fit(caster, pose, offset, ranges[valid], angles[valid], fit_d, rules.min_beams)
            if trial is not None:          # the fit of both places on probation (NaN: the map cannot judge: 0)
                for g, g_pose in enumerate(trial["poses"]):
                    f_g = fit[k] if g == trial["shown"] else _scan_fit(caster, g_pose, offset, ranges[valid],
                                                                        angles[valid], fit_d, rules.min_beams)
                    trial["fits"][g] = (trial["fits"][g] + [0.0 if np.isnan(f_g) else f_g])[-int(rules.fit_window):]
        off_map = grid is not None and on_map[k] == 0.0
        if off_map and soft_penalty and mcl.soft_obstacles:
            # a cloud in an obstacle the map may be wrong about is not off the map; outside the grid it is
            off_map = _free_share(grid, inside_grid, mcl.particles, mcl.weights) == 0.0
        agreed = e.best_weight >= rules.min_share and e.spread <= rules.max_spread
        agreed_before = agreed
        # a cloud gathered on one place (if less tightly than "agreed") while the filter searches, where the map
        # cannot judge the scans at all (their beams end in its unknown cells): that counts as not fitting
        gathered = cur == "searching" and e.best_weight >= rules.min_share and e.spread <= 4 * rules.max_spread
        if do_update and np.isfinite(fit[k]):
            recent = (recent + [float(fit[k])])[-int(rules.fit_window):]
            if since_loss is not None:
                since_loss = (since_loss + [float(fit[k])])[-int(rules.fit_window):]
            fit_s = float(np.mean(recent))
            wrong = fit_s < rules.restart_fit * fit_expected
            if agreed and wrong:
                poor += 1
            elif not (gathered and wrong):           # a loosely gathered cloud's poor fit leaves the count as it is
                poor = unjudged = 0
            # a lost filter whose best place does not fit the scans either, agreed on or not (outside a
            # probation; an update the map cannot judge leaves the count as it is)
            lost_run = lost_run + 1 if (cur == "lost" and wrong and trial is None) else 0
        elif do_update and gathered and grid is not None and _is_scan(z) and n_valid[k] >= rules.min_beams:
            poor += 1
            unjudged += 1
        if (ex_xy > 0 or ex_th > 0) and do_update and agreed and np.isfinite(fit[k]) and (
                fit[k] < rules.restart_fit * fit_expected):
            noise = mcl.rng.normal(0.0, 1.0, mcl.particles.shape) * np.array([ex_xy, ex_xy, ex_th])
            mcl.particles = mcl.particles + noise
            mcl.particles[:, 2] = wrap_angle(mcl.particles[:, 2])
            n_expanded += 1
        if trial is not None and do_update and not degenerate:
            trial["updates"] += 1
        lost_run = lost_run if cur == "lost" else 0
        if restart_after and max(poor, lost_run) >= restart_after and mcl.sampler is not None and trial is None:
            # global localization again, without throwing the current hypothesis away: the old cloud keeps
            # half of the weight, n_restart uniform particles share the other half; on probation (_probation)
            # the next scans decide which of the two stays
            fresh = np.asarray(mcl.sampler(n_restart, mcl.rng), dtype=float)
            trial = {"n_old": mcl.n, "updates": 0, "fits": [[], []], "poses": (pose, pose), "shown": 0,
                     "min_fit": rules.restart_fit * fit_expected}
            mcl.particles = np.vstack([mcl.particles, fresh])
            mcl.log_weights = np.concatenate([mcl.log_weights + np.log(0.5),
                                              np.full(n_restart, np.log(0.5 / n_restart))])
            where = ("the cloud gathered on a place where the map could not judge the scans (their beams end in "
                     "its unknown cells) or they did not fit it" if unjudged else
                     "the cloud agreed on a place where the scans have not fitted the map")
            n_poor = poor
            if poor < restart_after:
                where = "the filter has been lost, and the scans have not fitted the map at its best place,"
                n_poor = lost_run
            events.append((k, f"{where} for {n_poor} updates: {n_restart} particles drawn over the map "
                              "beside it (global localization again)"))
            poor = lost_run = 0
            unjudged = 0
            good = 0
            agreed_before = False
            recent, fit_s = [], float("nan")
            if cur == "localized":
                cur = "lost"
        elif recover and (degenerate or off_map) and mcl.sampler is not None:
            trial = None
            mcl.particles = np.asarray(mcl.sampler(mcl.n, mcl.rng), dtype=float)
            mcl.log_weights = np.full(mcl.n, -np.log(mcl.n))
            why = "every particle got zero likelihood" if degenerate else "every particle left the map's free space"
            agreed_before = False
            events.append((k, f"{why}: particles re-drawn over the map (global localization again)"))
        elif trial is not None:
            trial = _probation(mcl, trial, events, k, recovery_injection if cur == "lost" else 0.0)
        elif mcl.needs_resampling() or (cur == "lost" and recovery_injection > 0 and do_update):
            if cur == "lost" and recovery_injection > 0 and mcl.sampler is not None:
                mcl.injection = max(base_injection, float(recovery_injection))
            mcl.resample()
            mcl.injection = base_injection
        resampled[k], n_inj[k], p_inj[k] = st.resampled, st.n_injected, st.p_inject
        updated[k] = do_update
        # ---- state
        prev = cur
        if degenerate or off_map:
            good = 0
            if cur == "localized":
                cur = "lost"
        elif do_update:
            # the fits that judge this place: since the loss, for a filter that lost the robot
            fit_e = fit_s if since_loss is None else (float(np.mean(since_loss)) if since_loss else float("nan"))
            confident = ((not _is_scan(z) or n_valid[k] >= rules.min_beams) and e.best_weight >= rules.min_share
                         and e.spread <= rules.max_spread
                         and (e.cluster_std is None or e.cluster_std[2] <= rules.max_heading_std)
                         and (fit_e >= rules.min_fit * fit_expected if np.isfinite(fit_e) else
                              cur == "localized" or grid is None or not _is_scan(z)))
            if confident and rules.probe_shift > 0 and _is_scan(z) and n_valid[k] > 0:
                confident = _pinned(sensor, pose, z, rules.probe_shift, rules.min_contrast, lo_r, hi_r)
            if confident:
                good += 1
                bad = 0
                if cur != "localized" and good >= rules.hold:
                    cur = "localized"
            else:
                good = 0
                bad += 1
                if cur == "localized" and bad >= rules.hold_lost:
                    cur = "lost"
        state[k] = cur
        if prev == "localized" and cur == "lost":
            # the fits made while localized vouch for that place, not for wherever the cloud goes now: being
            # localized again takes fits judged since the loss (an update the map cannot judge gives none).
            # The restart rules keep their window: this changes what the filter says, not what it does.
            since_loss = []
        elif cur == "localized" or trial is not None:
            since_loss = None
        agreed_before = agreed_before and cur != "searching"
        if cur != prev:
            events.append((k, f"state {prev} -> {cur}"))
        if callback is not None:
            callback(k + 1)
    seconds = _now() - t0
    if n_expanded:
        events.append((t - 1, f"the cloud was spread wider (expansion resetting) at {n_expanded} updates whose scan "
                              "did not fit the map at the agreed place"))
    if n_skipped:
        events.append((t - 1, f"{n_skipped} beams whose end point at the agreed place lies in the map's unknown cells "
                              f"were left out of the updates" + (f"; {n_blind} scan{'s' * (n_blind != 1)} had no "
                                                                 "other valid beam and were not used" if n_blind else "")))
    if n_shorts:
        events.append((t - 1, f"{n_shorts} beams that read more than {short_m:g} m shorter than the map allows at "
                              "the agreed place (something the map does not show stands in front) were left out "
                              "of the updates"))
    if soft_penalty:
        mcl.soft_obstacles = True
    return RunTrace(poses=out["poses"], means=out["means"], stds=out["stds"], spread=spread, best_weight=best,
                    n_eff=n_eff, n_particles=n_p, n_injected=n_inj, p_inject=p_inj, updated=updated,
                    resampled=resampled, degenerate=degen, n_valid=n_valid, fit=fit, on_map=on_map, state=state,
                    events=events, beam_evaluations=evals, seconds=seconds, snapshots=snaps)


#: A restart's probation (:func:`_probation`): at least this many updates, at most this many, and the
#: share of the weight (log) below which the losing cloud is dropped early. Not fitted to a log: 30
#: updates is :class:`StateRules`' default ``fit_window`` (5) six times over, 1e-4 a share no resampling of
#: a few thousand particles would keep a particle of.
PROBATION = (3, 30, float(np.log(1e-4)))


def _trial_shares(mcl: MCL, n_old: int) -> NDArray:
    lw = mcl.log_weights
    sh = np.array([_rs.logsumexp(lw[:n_old]), _rs.logsumexp(lw[n_old:])])
    return sh - _rs.logsumexp(sh)


def _trial_fits(trial: dict) -> tuple[float, float]:
    """The mean recent ray-cast fit of the old and of the fresh cloud's best cluster (0 before any)."""
    f_old, f_new = (float(np.mean(f)) if f else 0.0 for f in trial["fits"])
    return f_old, f_new


def _trial_favours(trial: dict, shares: NDArray) -> int:
    """1 when the fresh cloud beats the old one on both the weight (the sensor model's evidence since the
    restart) and the recent ray-cast fit at its best cluster, with at least ``PROBATION[0]`` fits of each; else 0
    (the old place: the robot's history)."""
    if not np.all(np.isfinite(shares)):           # one cloud has no weight left at all: the other one
        return int(np.isfinite(shares[1]))
    if min(len(f) for f in trial["fits"]) < PROBATION[0]:     # one or two scans are no evidence yet: the old place
        return 0
    f_old, f_new = _trial_fits(trial)
    return int(shares[1] > shares[0] and f_new > f_old and f_new >= trial["min_fit"])


def _trial_estimate(mcl: MCL, trial: dict, e: Estimate) -> Estimate:
    """The estimate while a restart is on probation: the best cluster of the place favoured so far
    (:func:`_trial_favours`), its share of the weight counted against the whole cloud."""
    n_old = trial["n_old"]
    shares = _trial_shares(mcl, n_old)
    lw = mcl.log_weights
    ests = []
    for sl in (slice(0, n_old), slice(n_old, None)):
        # within the group, from the log-weights (uniform if it has none left): a group far behind would
        # underflow in mcl.weights
        wg, _ = _rs.normalize_log_weights(lw[sl])
        ests.append(_estimate(mcl.particles[sl], wg, 0.5, 0.01, 0.9))
    trial["poses"] = tuple(g.pose if np.all(np.isfinite(g.pose)) else g.mean for g in ests)
    g = trial["shown"] = _trial_favours(trial, shares)
    eg = ests[g]
    return Estimate(eg.pose, e.mean, e.std, e.cov, float(np.exp(shares[g]) * eg.best_weight), e.n_clusters, e.n_eff,
                    eg.cluster_std)


def _probation(mcl: MCL, trial: dict, events: list, k: int, injection: float) -> dict | None:
    """One step of a restart's probation: the old cloud (the first ``trial["n_old"]`` particles) and the
    fresh one are resampled each within itself, keeping their shares of the weight. The trial ends after
    ``PROBATION[1]`` updates, or earlier (after at least ``PROBATION[0]``) when one cloud holds less than
    ``exp(PROBATION[2])`` of the weight and the fit agrees with the weight; the fresh cloud replaces the
    old one only when it beats it on both (:func:`_trial_favours`). Returns the trial, or None when decided."""
    n_old = trial["n_old"]
    lw, every = mcl.log_weights, mcl.particles
    shares = _trial_shares(mcl, n_old)
    lo_min, hi, floor = PROBATION
    win = _trial_favours(trial, shares)
    done = trial["updates"] >= hi or not np.isfinite(shares[1 - win]) or (
        trial["updates"] >= lo_min and shares[1 - win] < floor)
    base = mcl.injection
    parts, logw = [], []
    groups = (slice(0, n_old), slice(n_old, None))
    for g, (sl, share) in enumerate(zip(groups, shares)):
        if done and g != win:
            continue
        mcl.particles, mcl.log_weights = every[sl], lw[sl] - _rs.logsumexp(lw[sl])
        mcl.injection = max(base, injection) if g == 1 else 0.0
        if mcl.needs_resampling():
            mcl.resample()
        mcl.injection = base
        parts.append(mcl.particles)
        logw.append(mcl.log_weights + (0.0 if done else share))
    mcl.particles = np.vstack(parts)
    mcl.log_weights = np.concatenate(logw)
    mcl.log_weights -= _rs.logsumexp(mcl.log_weights)
    mcl.status.n_particles = mcl.n
    if done:
        f_old, f_new = _trial_fits(trial)
        kept = "the particles drawn over the map" if win else "the old place"
        events.append((k, f"after {trial['updates']} updates {kept} won (weight {np.exp(shares[1]):.2g} of the "
                          f"new, recent fit {f_new:.2f} against {f_old:.2f} of the old): the other cloud dropped"))
        return None
    trial["n_old"] = len(parts[0])
    return trial


def _pinned(sensor: Any, pose: NDArray, z: tuple, shift: float, min_contrast: float, lo_r: float = 0.0,
            hi_r: float = np.inf) -> bool:
    """Whether the scan ``z`` fits ``pose`` better than ``pose`` moved by ``shift`` in any of four directions.

    The contrast is the drop of the sensor model's log-likelihood per beam it
    scored (the model's tempering undone); the pose is pinned when the
    smallest drop is at least ``min_contrast``. The beams counted are those the
    sensor scores: of the ``max_beams`` it thins a scan to (if it does), the
    readings in ``(lo_r, hi_r)`` -- a beam left out of the update (set to the
    maximum range by :func:`_skip_beams`) adds nothing to the drop, so it does
    not dilute it either, and a 1081-beam scan read by a 30-beam model is
    judged as the 30 beams it is.
    """
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = np.array([[0.0, 0.0], [shift, 0.0], [-shift, 0.0], [0.0, shift], [0.0, -shift]])
    probes = np.tile(np.asarray(pose, dtype=float), (5, 1))
    probes[:, 0] += c * d[:, 0] - s * d[:, 1]
    probes[:, 1] += s * d[:, 0] + c * d[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        ll = np.asarray(sensor.log_likelihood(probes, *z), dtype=float)
    if ll.shape != (5,) or not np.isfinite(ll[0]):
        return True                    # cannot probe: leave the decision to the other rules
    r = np.asarray(z[0], dtype=float).ravel()
    r = r[select_beams(r.size, getattr(sensor, "max_beams", None))]
    with np.errstate(invalid="ignore"):
        n_scored = int(np.sum(np.isfinite(r) & (r > lo_r) & (r < hi_r)))
    temper = float(getattr(sensor, "temper", 1.0) or 1.0)
    contrast = (ll[0] - np.max(np.where(np.isfinite(ll[1:]), ll[1:], -np.inf))) / (temper * max(n_scored, 1))
    return bool(contrast >= min_contrast)


def _now() -> float:
    import time

    return time.perf_counter()


#: :func:`run_filter`'s ``skip_short_beams``: when more than this share of a scan's valid beams read short at
#: the agreed place, none is left out (most of the scan contradicting the map says the place is wrong; a
#: cluttered room still shows most of its walls).
SHORT_BEAMS_MAX_SHARE = 0.5


def _skip_beams(grid: OccupancyGrid, mcl: MCL, offset: NDArray, z: tuple, max_range: float, *, unknown: bool = True,
                caster: Any = None, short: float = 0.0) -> tuple[tuple, int, int]:
    """``(z, n_unknown, n_short)``: the scan with beams the map cannot explain at the cloud's mean pose set to
    ``max_range`` (no return: not scored), and how many of each kind those were.

    With ``unknown``, the beams whose end point falls in an unknown cell; with ``short > 0`` (metres, needs
    ``caster``), those that read more than ``short`` shorter than the range ray-cast from the pose -- unless
    more than :data:`SHORT_BEAMS_MAX_SHARE` of the valid beams do.
    """
    sx, sy, sth = sensor_poses(mean_pose(mcl.particles, mcl.weights)[None, :], offset)[0]
    r = np.array(z[0], dtype=float)
    a = np.asarray(z[1], dtype=float)
    valid = np.isfinite(r) & (r < max_range)
    rr = np.where(valid, r, 0.0)
    blind = np.zeros(r.shape, dtype=bool)
    if unknown:
        cells = grid.world_to_cell(np.stack([sx + rr * np.cos(sth + a), sy + rr * np.sin(sth + a)], axis=1),
                                   outside="flag")
        blind = valid & (cells[:, 0] >= 0)
        blind[blind] = grid.unknown[cells[blind, 0], cells[blind, 1]]
    n_short = 0
    if short > 0 and caster is not None:
        expected = caster.cast(np.array([[sx, sy, sth]]), a)[0]
        short_beams = valid & ~blind & (r < expected - short)
        n_short = int(short_beams.sum())
        if n_short > SHORT_BEAMS_MAX_SHARE * int(valid.sum()):
            n_short = 0
        else:
            blind |= short_beams
    n = int(blind.sum()) - n_short
    if n or n_short:
        r[blind] = max_range
    return (r, a, *z[2:]), n, n_short


def _free_share(grid: OccupancyGrid, free: NDArray, particles: NDArray, weights: NDArray) -> float:
    rel = (particles[:, :2] - grid.origin) / grid.resolution
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(rel), axis=1) & (np.abs(rel).max(axis=1) < 1e9)
    j = np.zeros(len(rel), dtype=np.int64)
    i = np.zeros(len(rel), dtype=np.int64)
    j[ok] = np.floor(rel[ok, 0]).astype(np.int64)
    i[ok] = np.floor(rel[ok, 1]).astype(np.int64)
    h, w = free.shape
    ok &= (i >= 0) & (i < h) & (j >= 0) & (j < w)
    inside = np.zeros(len(rel), dtype=bool)
    inside[ok] = free[i[ok], j[ok]]
    return float(weights[inside].sum() / max(weights.sum(), 1e-300))


def _scan_fit(caster: Any, pose: NDArray, offset: NDArray, ranges: NDArray, angles: NDArray, fit_d: float,
              min_beams: int) -> float:
    """Share of beams whose reading agrees with the map's ray-cast range from ``pose`` within ``fit_d``.

    A beam that reads much longer than the map allows passed "through" a
    mapped wall; one that reads much shorter hit something the map does not
    show. Either way the map does not confirm it. (The likelihood field
    cannot see the first kind: it only asks how close the end point is to
    *some* obstacle, so a wrong pose whose beams pass through walls can score
    well; this check is what makes the state honest about it.) A beam whose
    cast ray stops at an *unknown* cell cannot be judged and is left out; with
    fewer than ``min_beams`` beams left the fit is NaN.
    """
    if ranges.size < min_beams:
        return float("nan")
    c, s = np.cos(pose[2]), np.sin(pose[2])
    sp = np.array([[pose[0] + c * offset[0] - s * offset[1], pose[1] + s * offset[0] + c * offset[1],
                    pose[2] + offset[2]]])
    expected = caster.cast(sp, angles)[0]
    g = caster.grid
    if g.unknown.any():
        a = sp[0, 2] + angles
        reach = expected + 0.5 * g.resolution
        hit = np.column_stack([sp[0, 0] + reach * np.cos(a), sp[0, 1] + reach * np.sin(a)])
        cells = g.world_to_cell(hit, outside="clip")
        judged = ~g.unknown[cells[:, 0], cells[:, 1]] & g.contains(hit)
        if int(judged.sum()) < min_beams:
            return float("nan")
        ranges, expected = ranges[judged], expected[judged]
    return float(np.mean(np.abs(ranges - expected) <= fit_d))
