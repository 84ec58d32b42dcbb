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
from functools import partial
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import resample as _rs
from ._checks import check_count, check_grid, check_nonnegative, check_poses, check_positive, check_rng
from .estimate import Estimate, _estimate, estimate_pose
from .geometry import as_poses, wrap_angle
from .geometry import relative as _relative
from .grid import OccupancyGrid
from .kld import KLDSampling, kld_sample_size
from .motion import OdometryMotion, ReversibleOdometry, VelocityMotion, odometry_pair  # noqa: F401  (re-exported: their old home)

__all__ = [
    "MCL",
    "MCLStatus",
    "Estimate",
    "OdometryMotion",
    "ReversibleOdometry",
    "VelocityMotion",
    "Augmented",
    "Proposal",
    "KLDSampling",
    "gaussian_particles",
    "uniform_particles",
    "estimate_pose",
    "mcl_step_loop",
    "RobustOdometry",
]

#: Names that moved when the run driver was split by idea (their new modules); ``localize.mcl.<name>`` still
#: works, with a DeprecationWarning.
_MOVED = {
    "run_filter": "runloop", "run_mcl": "runloop", "RunTrace": "runloop", "MCLTrace": "runloop",
    "StateTrack": "runloop", "StateRules": "policies", "STATES": "policies", "PROBATION": "policies",
    "expected_fit": "evidence", "SHORT_BEAMS_MAX_SHARE": "evidence",
}


def __getattr__(name: str) -> Any:
    """Deprecated homes of the run driver's names (:mod:`localize.runloop`, :mod:`localize.policies`,
    :mod:`localize.evidence`)."""
    if name in _MOVED:
        import importlib
        import warnings

        module = _MOVED[name]
        warnings.warn(f"localize.mcl.{name} moved to localize.{module}.{name}; import it from there",
                      DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(f"localize.{module}"), name)
    raise AttributeError(f"module 'localize.mcl' has no attribute {name!r}")

Motion = Callable[[NDArray[np.float64], Any, np.random.Generator], NDArray[np.float64]]
Sampler = Callable[[int, np.random.Generator], NDArray[np.float64]]

RESAMPLERS = tuple(_rs.RESAMPLERS)

#: Augmented MCL's injection probability below this is rounding noise of two equal averages, not a failure.
_P_INJECT_NOISE = 1e-9
#: Eigenvalues of a prior covariance down to ``-_PSD_TOL`` are rounding noise of a singular matrix.
_PSD_TOL = 1e-12


# --------------------------------------------------------------------------- initialisers
def uniform_particles(grid: OccupancyGrid, n: int, rng: np.random.Generator, *,
                      holes: bool = False) -> NDArray[np.float64]:
    """``n`` poses drawn uniformly over the known-free cells of ``grid``, headings uniform.

    The prior of global localization: the robot is somewhere in free space,
    facing anywhere (the initialisation of the seed 001 report). With
    ``holes``, in the map's :attr:`~localize.grid.OccupancyGrid.holes` too
    (unknown patches of the floor).

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office()
    >>> p = uniform_particles(g, 500, np.random.default_rng(0))
    >>> p.shape, bool(g.is_free(p).all())
    ((500, 3), True)
    """
    return check_grid(grid).sample_free(check_count(n, "n"), check_rng(rng), holes=bool(holes))


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

    def clear_step(self) -> None:
        """Start a new step: nothing resampled or injected yet."""
        self.resampled = False
        self.n_injected = 0


@dataclass(frozen=True)
class Proposal:
    """Where the particles injected at a resampling are drawn, and what each weighs (:meth:`MCL.resample`).

    ``draw(n, rng)`` returns ``(n, 3)`` poses. ``log_weight(poses)``, when
    given, is the log of each drawn particle's weight against a kept one's
    (an importance weight: the particles are no longer drawn from the belief
    alone); None weighs them alike, as random injection does.

    Examples
    --------
    >>> f = toy_mcl()
    >>> f.resample(injection=0.5, proposal=Proposal(lambda n, rng: np.full((n, 3), 9.0), lambda p: np.full(len(p), -1.0)))
    >>> drawn = f.particles[:, 0] == 9.0
    >>> int(drawn.sum()), round(float(f.weights[drawn][0] / f.weights[~drawn][0]), 3)       # exp(-1)
    (50, 0.368)
    """

    draw: Sampler
    log_weight: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None


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


# --------------------------------------------------------------------------- the filter's arguments
def _initial_particles(particles: ArrayLike) -> NDArray[np.float64]:
    p = check_poses(particles, "particles")  # (N, 3); warns on a (3, 3) that looks transposed
    if p.ndim != 2 or p.shape[0] < 1:
        raise ValueError(f"particles must be an (N, 3) array with N >= 1; got shape {p.shape}")
    out = np.array(p, dtype=float)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _initial_log_weights(log_weights: ArrayLike | None, n: int) -> NDArray[np.float64]:
    if log_weights is None:
        return np.full(n, -np.log(n))
    lw = np.asarray(log_weights, dtype=float)
    if lw.shape != (n,):
        raise ValueError(f"log_weights must have shape ({n},) like the particles; got {lw.shape}")
    if np.any(np.isnan(lw)) or np.any(lw == np.inf):
        raise ValueError("log_weights must not contain NaN or +inf")
    norm = _rs.logsumexp(lw)
    if not np.isfinite(norm):
        raise ValueError("log_weights are -inf everywhere; at least one particle needs a positive weight")
    return lw - norm


def _fraction(value: Any, name: str, closed: bool = False) -> float:
    v = float(value)
    if closed and not 0.0 <= v <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1] (a fraction of N); got {value!r}")
    if not closed and not 0.0 <= v < 1.0:
        raise ValueError(f"{name} must be a fraction in [0, 1); got {value!r}")
    return v


def _augmented(augmented: Any) -> Augmented | None:
    if augmented is None or isinstance(augmented, Augmented):
        return augmented
    try:
        return Augmented(*augmented)
    except TypeError:
        raise TypeError(
            f"augmented must be an Augmented(...) or a pair (alpha_slow, alpha_fast); got {augmented!r}"
        ) from None


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
        and recovery. Defaults to uniform over the free cells of ``grid``
        (and its :attr:`~localize.grid.OccupancyGrid.holes` with
        ``unknown_allowed``).
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
        The default ``sampler`` (and :meth:`uniform`) then draws over the
        map's :attr:`~localize.grid.OccupancyGrid.holes` as well as its free
        cells: the robot may also start in an unknown patch of the floor.
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
        self.particles = _initial_particles(particles)
        n = self.particles.shape[0]
        self.log_weights = _initial_log_weights(log_weights, n)
        self.motion = motion if callable(motion) else OdometryMotion(motion)
        if not callable(getattr(sensor, "log_likelihood", None)):
            raise TypeError(
                "sensor must have a method log_likelihood(poses, *z) -> (N,) "
                f"(e.g. localize.sensors.BeamModel); got {type(sensor).__name__}"
            )
        self.sensor = sensor
        self._resample_fn = _rs.get_resampler(resampler)
        self.resampler_name = resampler if isinstance(resampler, str) else getattr(resampler, "__name__", "custom")
        self.resample_threshold = _fraction(resample_threshold, "resample_threshold", closed=True)
        self.injection = _fraction(injection, "injection")
        self.augmented = _augmented(augmented)
        if kld is not None and not isinstance(kld, KLDSampling):
            raise TypeError(f"kld must be a localize.kld.KLDSampling or None; got {type(kld).__name__}")
        self.kld = kld
        self.grid = None if grid is None else check_grid(grid)
        if sampler is None and grid is not None:
            sampler = partial(grid.sample_free, holes=bool(unknown_allowed))
        self.sampler = sampler
        if on_degenerate not in ("keep", "reinitialize"):
            raise ValueError(f"on_degenerate must be 'keep' or 'reinitialize'; got {on_degenerate!r}")
        self.on_degenerate = on_degenerate
        if sampler is None and (self.injection > 0 or self.augmented is not None or on_degenerate == "reinitialize"):
            raise ValueError(
                "random injection, augmented MCL and on_degenerate='reinitialize' need random particles: "
                "pass grid=... (uniform over free cells) or sampler=f(n, rng)"
            )
        self.min_ess = _fraction(min_ess, "min_ess")
        op = float(occupied_penalty)
        if not op > 0:
            raise ValueError(f"occupied_penalty must be > 0 nats (np.inf: zero weight); got {occupied_penalty!r}")
        self.occupied_penalty = op
        self.soft_obstacles = True      # the run driver passes update(soft_obstacles=...): only once the cloud agrees
        self._init_free_space(free_space_only, unknown_allowed, check_nonnegative(unknown_penalty, "unknown_penalty"))
        self.status = MCLStatus(n_particles=n, n_eff=self.n_eff)

    def _init_free_space(self, free_space_only: bool, unknown_allowed: bool, unknown_penalty: float) -> None:
        """The masks of :meth:`update`'s free-space rule (particles in obstacles or off the map)."""
        grid = self.grid
        if free_space_only and grid is None:
            raise ValueError("free_space_only=True needs the map: pass grid=...")
        self.free_space_only = bool(free_space_only)
        self.unknown_penalty = unknown_penalty if (free_space_only and unknown_allowed) else 0.0
        if self.free_space_only:
            allowed = ~grid.occupied if unknown_allowed else grid.free
            self._free = np.ascontiguousarray(allowed)
            if self.unknown_penalty:
                self._unknown = np.ascontiguousarray(grid.unknown)
            if np.isfinite(self.occupied_penalty):
                self._occupied = np.ascontiguousarray(grid.occupied)

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
        recovery draw from its free space). With ``unknown_allowed``, the
        particles are drawn over the map's
        :attr:`~localize.grid.OccupancyGrid.holes` too. Other options as in
        :class:`MCL`.

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
        holes = bool(options.get("unknown_allowed", False))
        return cls(uniform_particles(grid, n, rng, holes=holes), motion, sensor, rng=rng, **options)

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

    def update(self, *z: Any, soft_obstacles: bool | None = None, **kwargs: Any) -> None:
        """Weight the particles by the measurement: ``log w += log p(z | x)``.

        Arguments go to ``sensor.log_likelihood(particles, *z, **kwargs)``.
        ``soft_obstacles`` says for this update whether a particle in a known
        obstacle pays ``occupied_penalty`` (True) or gets zero weight (False);
        None uses the filter's ``soft_obstacles`` attribute (True).
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
            soft = self.soft_obstacles if soft_obstacles is None else bool(soft_obstacles)
            if np.isfinite(self.occupied_penalty) and soft:   # in a known obstacle: a finite penalty
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
                self.redraw()
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

    def resample(self, injection: float | None = None, proposal: Proposal | None = None) -> None:
        """Draw a new, equally weighted particle set (always; see :meth:`needs_resampling`).

        With KLD-sampling the new set's size is chosen by the KLD bound; then
        random particles replace ``injection * N`` of the new set (rounded)
        or, with augmented MCL, each particle with probability ``p_inject``
        -- whichever replaces more. ``injection`` (in [0, 1)) overrides the
        filter's own share for this resampling only, and ``proposal`` (a
        :class:`Proposal`) where the injected particles are drawn instead of
        the filter's own sampler, and what they weigh (sensor resetting draws
        them where the scan fits: :class:`localize.policies.SensorReset`).

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
        share = self.injection if injection is None else float(injection)
        if not 0.0 <= share < 1.0:
            raise ValueError(f"injection must be a fraction in [0, 1); got {injection!r}")
        n_inj = int(round(share * n))
        if self.augmented is not None and st.p_inject > 0:
            n_inj = max(n_inj, int(self.rng.binomial(n, st.p_inject)))
        if n_inj > 0:
            where = self.rng.choice(n, size=n_inj, replace=False) if n_inj < n else np.arange(n)
            new = new.copy() if new.base is not None else new
            draw = self.sampler if proposal is None else proposal.draw
            new[where] = np.asarray(draw(n_inj, self.rng), dtype=float)
        self.particles = new
        self.log_weights = np.full(n, -np.log(n))
        if n_inj > 0 and proposal is not None and proposal.log_weight is not None:      # importance weights
            lw = np.zeros(n)
            lw[where] = np.asarray(proposal.log_weight(new[where]), dtype=float)
            self.log_weights = lw - _rs.logsumexp(lw)
        st.n_injected = n_inj
        st.resampled = True
        st.n_particles = n
        weighed = n_inj > 0 and proposal is not None and proposal.log_weight is not None
        st.n_eff = _ess(self.log_weights) if weighed else float(n)

    # ------------------------------------------------------------ changing the set (for the run's policies)
    def replace(self, particles: ArrayLike, log_weights: ArrayLike) -> None:
        """Put a new weighted set in place: ``particles`` (N, 3) and *normalised* ``log_weights`` (N,).

        Examples
        --------
        >>> f = toy_mcl()
        >>> f.replace(np.zeros((4, 3)), np.full(4, -np.log(4)))
        >>> f.n, f.status.n_particles
        (4, 4)
        """
        p = np.asarray(particles, dtype=float)
        lw = np.asarray(log_weights, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or lw.shape != (p.shape[0],):
            raise ValueError(f"replace needs particles (N, 3) and log_weights (N,); got {p.shape} and {lw.shape}")
        self.particles, self.log_weights = p, lw
        self.status.n_particles = self.n

    def add_particles(self, particles: ArrayLike, share: float) -> None:
        """Add ``particles`` (M, 3) beside the set, equally weighted, holding ``share`` of the total weight.

        Examples
        --------
        >>> f = toy_mcl()                      # 101 particles
        >>> f.add_particles(np.zeros((99, 3)), share=0.5)
        >>> f.n, round(float(f.weights[-99:].sum()), 6)
        (200, 0.5)
        """
        new = np.asarray(particles, dtype=float)
        m = new.shape[0]
        self.particles = np.vstack([self.particles, new])
        self.log_weights = np.concatenate([self.log_weights + np.log(1.0 - share), np.full(m, np.log(share / m))])

    def redraw(self) -> None:
        """Draw every particle anew from the sampler (global localization again), equally weighted.

        Examples
        --------
        >>> from localize.maps import office
        >>> class Flat:
        ...     def log_likelihood(self, poses, *z):
        ...         return np.zeros(len(poses))
        >>> f = MCL.gaussian([3, 3, 0], (0.1, 0.1, 0.1), 500, (0.01,) * 4, Flat(), rng=np.random.default_rng(0),
        ...                  grid=office())
        >>> f.redraw()
        >>> bool(f.particles[:, 0].std() > 1.0)
        True
        """
        n = self.n
        self.particles = np.asarray(self.sampler(n, self.rng), dtype=float)
        self.log_weights = np.full(n, -np.log(n))

    def diffuse(self, std: ArrayLike) -> None:
        """Move every particle by Gaussian noise of standard deviations ``std = (sx, sy, stheta)``.

        Examples
        --------
        >>> f = toy_mcl()
        >>> f.diffuse([0.0, 1.0, 0.0])
        >>> bool(f.particles[:, 1].std() > 0.5), float(f.particles[:, 0].max())
        (True, 10.0)
        """
        noise = self.rng.normal(0.0, 1.0, self.particles.shape) * np.asarray(std, dtype=float)
        self.particles = self.particles + noise
        self.particles[:, 2] = wrap_angle(self.particles[:, 2])

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
        st.clear_step()
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
        cells = self.grid.world_to_cell(poses[:, :2], outside="flag")
        out = cells[:, 0] >= 0
        out[out] = mask[cells[out, 0], cells[out, 1]]
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


# --------------------------------------------------------------------------- robust odometry
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
        pair = odometry_pair(u)
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
