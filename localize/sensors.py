"""Measurement models: how likely is a range scan (or a landmark sighting) from a pose?

Three models, each exposing the interface the filters use:

:class:`BeamModel`
    The beam model of *Probabilistic Robotics* (Thrun, Burgard and Fox 2005,
    "PR", section 6.3, table 6.1): each beam's reading is a mixture of a
    correct hit with Gaussian noise, an unexpected short reading, a
    max-range failure and a uniform random reading. Needs ray casting.
:class:`LikelihoodField`
    The likelihood-field ("end point") model of PR section 6.4, table 6.3,
    the default of ROS AMCL: a beam's end point is scored by its distance
    to the nearest obstacle. Needs only table lookups.
:class:`LandmarkModel`
    Range and bearing to known, identified landmarks (PR section 6.6), with
    the analytic Jacobian the EKF needs.

Common interface of the range models (agreed with the filters):

* ``log_likelihood(poses (N, 3), ranges (B,), angles (B,)) -> (N,)``: the
  log-likelihood of one scan for each *robot* pose; the model applies its
  ``sensor_offset = (dx, dy, dtheta)`` (the sensor's pose in the robot frame)
  itself. Beams are assumed independent given the pose, so the scan's
  log-likelihood is the *sum* of the beams' log-densities (a product of
  densities); ``max_beams`` keeps an evenly spaced subset and ``temper``
  (``0 < temper <= 1``) scales the sum, both ways to soften the
  overconfidence that the independence assumption brings.
* ``sample(poses (N, 3), angles (B,), rng) -> (N, B)``: simulated scans.
* Readings ``>= max_range`` (and ``+inf``) mean "no return" and are clipped
  to ``max_range``. Negative or NaN readings raise ``ValueError``.

Log-likelihoods are natural logarithms of (pseudo-)densities in 1/metre
units; only differences between poses matter to a filter.

Choosing ``temper`` (range models)
----------------------------------
The product over beams assumes that the beams' errors are independent. They
are not: a map error, a person or a door left open is seen by several
neighbouring beams, so a scan of ``B`` beams is far more confident than its
evidence, and in a particle filter one scan leaves a handful of particles
with all the weight (particle deprivation, chapter 7). ``temper`` multiplies
the scan's log-likelihood, i.e. raises the likelihood to that power, so the
scan counts as about ``temper * B`` independent beams.

* For global localization in the book's worlds keep ``temper * B`` at a few
  beams: the chapters use ``temper=0.05`` (beam model) and ``temper=0.1``
  (likelihood field) with 36 beams. When you change the number of beams,
  scale ``temper`` with ``1 / B`` (or keep ``B`` with ``max_beams``).
* An untempered likelihood field with 180 beams fails global localization
  in the office most of the time: 5000 uniform particles, beams over the
  full circle, ``sigma_hit=0.2``, 30 steps of :func:`localize.sim.range_run`,
  seeds 0-11 localized (within 0.5 m and 0.2 rad over the last 5 steps) in
  4 of 12 runs; with ``temper=0.02`` (the same ``temper * B`` as 0.1 with 36
  beams) in 12 of 12 (measured on the book's machine).
* Tracking from a good prior, a grid filter, or a single scan's maximum
  need little or no tempering; :class:`localize.mcl.MCL`'s ``min_ess``
  chooses the exponent at each update instead.

The default stays ``temper=1``, the textbook's product, because the right
value depends on the number of beams and on the filter, and because a model
built without it must keep returning PR's likelihood.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import (
    check_angles,
    check_grid,
    check_max_range,
    check_number,
    check_positive,
    check_probability,
    check_rng,
    check_sensor_poses,
)
from .geometry import as_poses, wrap_angle
from .grid import OccupancyGrid
from .raycast import RayCaster, coded_sum

__all__ = ["BeamModel", "LikelihoodField", "LandmarkModel", "range_bearing", "range_bearing_jacobian", "ON_LANDMARK",
           "check_ranges", "sensor_poses", "select_beams"]

_SQRT2PI = math.sqrt(2.0 * math.pi)
#: Farther than this many sigma_hit from 0 and from max_range, the truncated hit
#: Gaussian's normaliser eta is 1 to double precision (1 - ndtr(8) < 1e-15).
_ETA_SIGMAS = 8
#: Expected ranges below this fraction of max_range are raised to it (a ray cast from inside or against an
#: obstacle reads 0, where the short-reading density 1 / (1 - exp(-lambda z*)) divides by zero).
_Z_FLOOR = 1e-3
#: Probabilities handed to the inverse normal CDF are clipped into [_TINY_P, _BELOW_ONE], where it is finite.
_TINY_P, _BELOW_ONE = 1e-300, 1 - 1e-16
#: LikelihoodField.log_likelihood works on blocks of about this many end points (poses x beams), so that its
#: work arrays (48 bytes an end point, 3.1 MB) stay near the core instead of N x B temporaries.
_LF_BLOCK = 1 << 16
#: The likelihood field's table is built from distances capped at max_dist by a few shifted passes over the
#: map while max_dist spans at most this many cells; beyond, scipy's distance transform is the faster way.
_LF_MAX_CAP_CELLS = 96


# ------------------------------------------------------------------ helpers
def _ndtr(x: ArrayLike) -> NDArray[np.float64]:
    """The standard normal CDF, :func:`scipy.special.ndtr` (scipy is imported on first use, not with the module).

    Examples
    --------
    >>> float(_ndtr(0.0))
    0.5
    """
    from scipy.special import ndtr

    return ndtr(x)


def _ndtri(p: ArrayLike) -> NDArray[np.float64]:
    """The standard normal quantile, :func:`scipy.special.ndtri` (scipy imported on first use).

    Examples
    --------
    >>> round(float(_ndtri(0.975)), 4)
    1.96
    """
    from scipy.special import ndtri

    return ndtri(p)


def _weights(names: tuple[str, ...], values: tuple[float, ...], tol: float = 1e-6) -> NDArray[np.float64]:
    w = np.array([float(v) for v in values])
    for n, v in zip(names, w):
        if not np.isfinite(v) or v < 0 or v > 1:
            raise ValueError(f"{n} must be a mixture weight in [0, 1]; got {v!r}")
    if abs(w.sum() - 1.0) > tol:
        listing = " + ".join(f"{n}={v:g}" for n, v in zip(names, w))
        raise ValueError(
            f"the mixture weights must sum to 1; got {listing} = {w.sum():.6g}. "
            f"Divide each by their sum to normalise them."
        )
    return w


def _offset(sensor_offset: ArrayLike) -> NDArray[np.float64]:
    o = np.asarray(sensor_offset, dtype=float)
    if o.shape != (3,) or not np.all(np.isfinite(o)):
        raise ValueError(f"sensor_offset must be a finite (dx, dy, dtheta) in the robot frame; got {sensor_offset!r}")
    return o


def sensor_poses(poses: ArrayLike, sensor_offset: ArrayLike = (0.0, 0.0, 0.0)) -> NDArray[np.float64]:
    """Sensor poses ``(N, 3)`` of robots at ``poses``, for a sensor mounted at ``sensor_offset``.

    ``sensor_offset = (dx, dy, dtheta)`` is the sensor's pose in the robot's
    frame (the CMU 16-831 robot's laser sits 25 cm ahead of its centre).
    NaN poses raise ``ValueError``.

    Examples
    --------
    >>> sensor_poses([[1.0, 2.0, np.pi / 2]], (0.25, 0.0, 0.0)).round(6)
    array([[1.      , 2.25    , 1.570796]])
    """
    p = check_sensor_poses(poses)
    o = _offset(sensor_offset)
    if not o.any():
        return p
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    return np.stack([p[:, 0] + c * o[0] - s * o[1], p[:, 1] + s * o[0] + c * o[1], p[:, 2] + o[2]], axis=-1)


def check_ranges(ranges: ArrayLike, max_range: float, name: str = "ranges") -> NDArray[np.float64]:
    """Validate range readings and clip "no return" readings to ``max_range``.

    Readings must be >= 0 and not NaN; readings above ``max_range``
    (including ``+inf``) become ``max_range``. An empty scan raises.

    Examples
    --------
    >>> check_ranges([1.0, 12.0, np.inf], 10.0)
    array([ 1., 10., 10.])
    >>> check_ranges([-0.5], 10.0)
    Traceback (most recent call last):
    ...
    ValueError: ranges must be >= 0 metres; ranges[0] = -0.5
    """
    z = np.asarray(ranges, dtype=float)
    if z.ndim == 0:
        z = z.reshape(1)
    if z.size == 0:
        raise ValueError(f"{name} is empty: a scan needs at least one beam")
    if np.isnan(z).any():
        k = np.argwhere(np.isnan(z))[0]
        raise ValueError(f"{name} contains NaN (first at index {tuple(int(i) for i in k)}); "
                         "mark missing readings as max_range or drop them")
    if (z < 0).any():
        k = np.argwhere(z < 0)[0]
        where = int(k[0]) if z.ndim == 1 else tuple(int(i) for i in k)
        raise ValueError(f"{name} must be >= 0 metres; {name}[{where}] = {float(z[tuple(k)])!r}")
    return np.minimum(z, max_range)


def select_beams(n_beams: int, max_beams: int | None) -> NDArray[np.intp]:
    """Indices of at most ``max_beams`` evenly spaced beams out of ``n_beams``.

    The first and last beams are always kept (ROS AMCL's ``max_beams``).

    Examples
    --------
    >>> select_beams(181, 5)
    array([  0,  45,  90, 135, 180])
    >>> select_beams(3, None)
    array([0, 1, 2])
    """
    n = int(n_beams)
    if max_beams is None or max_beams >= n:
        return np.arange(n)
    m = int(max_beams)
    if m < 1:
        raise ValueError(f"max_beams must be >= 1 or None; got {max_beams}")
    if m == 1:
        return np.array([0])
    return np.round(np.linspace(0, n - 1, m)).astype(np.intp)


def _scan_beams(ranges: ArrayLike, angles: ArrayLike, max_range: float,
                max_beams: int | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A scan's checked readings and angles, thinned to ``max_beams`` (:func:`select_beams`)."""
    a = check_angles(angles)
    z = check_ranges(ranges, max_range)
    if z.ndim != 1 or z.shape != a.shape:
        raise ValueError(f"ranges and angles must be 1-D arrays of the same length; got {z.shape} and {a.shape}")
    sel = select_beams(a.size, max_beams)
    return z[sel], a[sel]


def _check_temper(temper: float) -> float:
    t = check_number(temper, "temper")
    if not 0.0 < t <= 1.0:
        raise ValueError(f"temper must lie in (0, 1] (1 = plain product of beams); got {temper!r}")
    return t


# ---------------------------------------------------------------- beam model
class BeamModel:
    """The beam range-finder model: a four-part mixture per beam (PR table 6.1).

    For a beam whose ray-cast ("expected") range is ``z*`` the reading ``z``
    in ``[0, max_range]`` has the pseudo-density

    ``p(z | z*) = z_hit p_hit + z_short p_short + z_max p_max + z_rand p_rand``

    * ``p_hit``: a normal density ``N(z; z*, sigma_hit^2)`` truncated to
      ``[0, max_range]`` and divided by its mass there, ``eta``;
    * ``p_short``: an exponential density ``lambda e^{-lambda z}`` truncated
      to ``[0, z*]`` and divided by its mass ``1 - e^{-lambda z*}``
      (unexpected objects in front of the map's obstacle);
    * ``p_max``: a point mass at ``max_range`` (no return);
    * ``p_rand``: uniform ``1 / max_range`` on ``[0, max_range)``.

    The three continuous parts integrate to one over ``[0, max_range]`` and
    the max-range part carries probability ``z_max``, so the whole reading
    distribution has mass one. At ``z = max_range`` :meth:`pdf` adds the
    *mass* ``z_max`` to the densities there, exactly as PR's algorithm
    does; this is a "pseudo-density", consistent across poses.

    ``lambda_short`` is a *rate* (1/metre), as in PR; a seed report writes
    the exponential with a scale ``1/lambda`` instead. An expected range
    below ``z_floor = 1e-3 * max_range`` (a sensor inside or touching an
    obstacle) is raised to ``z_floor`` so that the short part stays a proper
    density.

    Parameters
    ----------
    grid : OccupancyGrid or None
        The map. ``None`` builds a model that can only work with expected
        ranges given to it (:meth:`pdf`, :meth:`log_likelihood_expected`).
    max_range : float
        The sensor's maximum range (metres).
    z_hit, z_short, z_max, z_rand : float
        Mixture weights in ``[0, 1]`` summing to 1 (within 1e-6).
    sigma_hit : float
        Standard deviation of a correct hit (metres), > 0.
    lambda_short : float
        Rate of short readings (1/metre), > 0.
    sensor_offset : (dx, dy, dtheta)
        Sensor pose in the robot frame.
    max_beams : int or None
        Use only this many evenly spaced beams of each scan (None: all).
    temper : float
        Multiply the scan log-likelihood by this factor in ``(0, 1]`` (default 1,
        the plain product; see "Choosing temper" in the module's docstring:
        about ``2 / B`` to ``4 / B`` for global localization with ``B`` beams).
    method, n_bins : str, int or None
        Ray casting method and lookup-table bins (see
        :class:`localize.raycast.RayCaster`; ``None``: its default for the
        method, 360 for ``"lut"``, what fits the memory budget for ``"compact"``).
        Default ``"compact"``: the 8-bit table under 90 MB that the command
        line uses (``"lut"`` takes ``2 * H * W * 360`` bytes, 460 MB for an
        800 x 800 map).
    caster : RayCaster, optional
        Share a caster (and its table) between models.
    no_return : bool
        How :meth:`sample_expected` (a simulated laser) draws the hit part of a beam whose ray hits nothing
        within range: False (default) as PR's sampler does, from the normal about ``max_range`` truncated
        to the range, a reading a few ``sigma_hit`` short of it; True: ``max_range``, the "no return" of a
        real scanner (see there). The likelihoods do not depend on it.

    Examples
    --------
    >>> m = BeamModel(None, 10.0, 0.8, 0.1, 0.05, 0.05, sigma_hit=0.2, lambda_short=0.5)
    >>> m.pdf([2.0, 3.0, 10.0], 3.0).round(4)
    array([0.0287, 1.6151, 0.05  ])
    """

    def __init__(self, grid: OccupancyGrid | None, max_range: float, z_hit: float = 0.8, z_short: float = 0.1,
                 z_max: float = 0.05, z_rand: float = 0.05, sigma_hit: float = 0.2, lambda_short: float = 0.5,
                 *, sensor_offset: ArrayLike = (0.0, 0.0, 0.0), max_beams: int | None = None,
                 temper: float = 1.0, method: str = "compact", n_bins: int | None = None,
                 caster: RayCaster | None = None, no_return: bool = False) -> None:
        self.grid = None if grid is None else check_grid(grid)
        self.no_return = bool(no_return)
        self.max_range = check_max_range(max_range)
        w = _weights(("z_hit", "z_short", "z_max", "z_rand"), (z_hit, z_short, z_max, z_rand))
        self.z_hit, self.z_short, self.z_max, self.z_rand = (float(v) for v in w)
        self.sigma_hit = check_positive(sigma_hit, "sigma_hit", "metres")
        self.lambda_short = check_positive(lambda_short, "lambda_short")
        self.sensor_offset = _offset(sensor_offset)
        if max_beams is not None and int(max_beams) < 1:
            raise ValueError(f"max_beams must be >= 1 or None; got {max_beams}")
        self.max_beams = None if max_beams is None else int(max_beams)
        self.temper = _check_temper(temper)
        self.z_floor = _Z_FLOOR * self.max_range
        if caster is not None:
            if not isinstance(caster, RayCaster):
                raise TypeError(f"caster must be a localize.raycast.RayCaster; got {type(caster).__name__}")
            if caster.max_range != self.max_range:
                raise ValueError(f"caster.max_range ({caster.max_range}) differs from max_range ({self.max_range})")
            self.caster = caster
        elif self.grid is not None:
            self.caster = RayCaster(self.grid, self.max_range, method=method, n_bins=n_bins)
        else:
            self.caster = None

    @property
    def params(self) -> dict[str, float]:
        """The six intrinsic parameters as a dict (PR's Theta)."""
        return {"z_hit": self.z_hit, "z_short": self.z_short, "z_max": self.z_max, "z_rand": self.z_rand,
                "sigma_hit": self.sigma_hit, "lambda_short": self.lambda_short}

    def __repr__(self) -> str:
        p = ", ".join(f"{k}={v:g}" for k, v in self.params.items())
        return f"BeamModel(max_range={self.max_range:g}, {p})"

    # ---------------------------------------------------------- components
    def components(self, z: ArrayLike, z_expected: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """The four unweighted components ``p_hit, p_short, p_max, p_rand`` at ``z``.

        ``z`` is clipped to ``[0, max_range]``; ``p_max`` is 1 where
        ``z == max_range`` (a mass, not a density). Readable reference for
        :meth:`pdf`.

        Examples
        --------
        >>> m = BeamModel(None, 10.0)
        >>> {k: round(float(v), 4) for k, v in m.components(1.0, 3.0).items()}
        {'p_hit': 0.0, 'p_short': 0.3904, 'p_max': 0.0, 'p_rand': 0.1}
        """
        z = np.clip(np.asarray(z, dtype=float), 0.0, self.max_range)
        zs = np.clip(np.asarray(z_expected, dtype=float), self.z_floor, self.max_range)
        z, zs = np.broadcast_arrays(z, zs)
        sig, lam, zmax = self.sigma_hit, self.lambda_short, self.max_range
        eta = _ndtr((zmax - zs) / sig) - _ndtr(-zs / sig)
        p_hit = np.exp(-0.5 * ((z - zs) / sig) ** 2) / (sig * _SQRT2PI) / eta
        p_short = np.where(z <= zs, lam * np.exp(-lam * z) / -np.expm1(-lam * zs), 0.0)
        p_max = (z >= zmax).astype(float)
        p_rand = np.where(z < zmax, 1.0 / zmax, 0.0)
        return {"p_hit": p_hit, "p_short": p_short, "p_max": p_max, "p_rand": p_rand}

    def pdf(self, z: ArrayLike, z_expected: ArrayLike) -> NDArray[np.float64]:
        """Pseudo-density of readings ``z`` given expected ranges ``z_expected`` (broadcast).

        Readings above ``max_range`` count as ``max_range`` (no return).

        Examples
        --------
        >>> m = BeamModel(None, 5.0, 0.7, 0.2, 0.05, 0.05, sigma_hit=0.1, lambda_short=1.0)
        >>> m.pdf([0.5, 2.0, 5.0, 7.0], 2.0).round(4)
        array([0.1503, 2.8339, 0.05  , 0.05  ])
        """
        z = np.asarray(z, dtype=float)
        if np.isnan(z).any() or (z < 0).any():
            raise ValueError("z must hold readings >= 0 (not NaN); readings >= max_range mean no return")
        c = self.components(z, z_expected)
        p = self.z_hit * c["p_hit"] + self.z_short * c["p_short"] + self.z_max * c["p_max"]
        return p + self.z_rand * c["p_rand"]

    def beam_log_pdf(self, z: ArrayLike, z_expected: ArrayLike) -> NDArray:
        """Per-beam ``log pdf`` for already validated readings, vectorised and fast.

        ``z`` (B,) or (N, B) and ``z_expected`` (N, B), both already clipped
        to ``[0, max_range]``. Works in float32 when ``z_expected`` is
        float32. The normalisers that only matter near ``0`` and
        ``max_range`` are evaluated only where they differ from 1.

        Examples
        --------
        >>> m = BeamModel(None, 5.0, 0.7, 0.2, 0.05, 0.05, sigma_hit=0.1, lambda_short=1.0)
        >>> z = np.array([0.5, 2.0, 5.0])
        >>> bool(np.allclose(m.beam_log_pdf(z, np.full((1, 3), 2.0)), np.log(m.pdf(z, 2.0))))
        True
        """
        zs = np.asarray(z_expected)
        dt = np.float32 if zs.dtype == np.float32 else np.float64
        zs = np.maximum(zs.astype(dt, copy=False), dt(self.z_floor))
        z = np.asarray(z, dtype=dt)
        sig, lam, zmax = self.sigma_hit, self.lambda_short, self.max_range
        # hit: Gaussian; its truncation mass eta differs from 1 only within _ETA_SIGMAS sigma of 0 or max_range
        d = z - zs
        d *= dt(1.0 / sig)
        d *= d
        d *= dt(-0.5)
        g = np.exp(d)
        g *= dt(self.z_hit / (sig * _SQRT2PI))
        edge = (zs < _ETA_SIGMAS * sig) | (zs > zmax - _ETA_SIGMAS * sig)
        if edge.any():
            ze = zs[edge].astype(float)
            eta = _ndtr((zmax - ze) / sig) - _ndtr(-ze / sig)
            g[edge] /= eta.astype(dt)
        # short: lambda e^{-lambda z} / (1 - e^{-lambda z*}) on z <= z*; the numerator
        # depends on the reading only, so it is computed per beam and broadcast
        zb = np.broadcast_to(z, zs.shape)
        num = np.exp(dt(-lam) * z) * dt(self.z_short * lam)
        short = np.multiply(dt(-lam), zs)
        np.expm1(short, out=short)
        np.divide(num, short, out=short)
        short *= (zb <= zs)
        short *= dt(-1.0)
        g += short
        # max-range mass and uniform density, per beam
        extra = np.where(z >= zmax, dt(self.z_max), dt(self.z_rand / zmax))
        if self.z_max > 0 and self.z_rand > 0:  # the mixture never vanishes: plain log
            g += extra
            return np.log(g)
        # Without the floor (e.g. the plain Gaussian model z_hit = 1) a far-off reading
        # underflows the Gaussian to 0: add in log space instead, log(0) = -inf allowed.
        with np.errstate(divide="ignore"):
            rest = np.log(short + extra)
            d += dt(np.log(self.z_hit / (sig * _SQRT2PI))) if self.z_hit > 0 else dt(-np.inf)
            if edge.any():
                d[edge] -= np.log(eta).astype(dt)
        return np.logaddexp(d, rest)

    # ---------------------------------------------------------------- scans
    def _prepare(self, ranges: ArrayLike, angles: ArrayLike):
        return _scan_beams(ranges, angles, self.max_range, self.max_beams)

    def expected(self, poses: ArrayLike, angles: ArrayLike, dtype: type = np.float64) -> NDArray:
        """Ray-cast expected ranges ``(N, B)`` for robot ``poses`` (the sensor offset applied).

        Examples
        --------
        >>> from localize.maps import office
        >>> m = BeamModel(office(), 8.0, method="march", sensor_offset=(0.25, 0.0, 0.0))
        >>> m.expected([[6.0, 5.5, np.pi / 2]], [0.0]).round(3)   # wall at y = 6.4, sensor at y = 5.75
        array([[0.65]])
        """
        if self.caster is None:
            raise ValueError("this model has no map (grid=None); pass expected ranges to "
                             "log_likelihood_expected instead")
        return self.caster.cast(sensor_poses(poses, self.sensor_offset), angles, dtype=dtype)

    def log_likelihood_expected(self, ranges: ArrayLike, expected: ArrayLike) -> NDArray[np.float64]:
        """Scan log-likelihoods ``(N,)`` from readings ``(B,)`` and expected ranges ``(N, B)``.

        The sum of the beams' log pseudo-densities, times ``temper``. No beam
        subsampling here: pass the beams you want.

        Examples
        --------
        >>> m = BeamModel(None, 10.0, sigma_hit=0.2)
        >>> z = np.array([2.0, 3.0, 10.0])
        >>> ll = m.log_likelihood_expected(z, [[2.0, 3.0, 10.0], [2.5, 3.0, 10.0]])
        >>> bool(ll[0] > ll[1])
        True
        """
        z = check_ranges(ranges, self.max_range)
        zs = np.asarray(expected)
        if zs.ndim == 1:
            zs = zs[None, :]
        if zs.ndim != 2 or zs.shape[1] != z.shape[-1]:
            raise ValueError(f"expected must have shape (N, {z.shape[-1]}); got {zs.shape}")
        if zs.dtype != np.float32:
            zs = np.asarray(zs, dtype=float)
        ll = self.beam_log_pdf(z, np.minimum(zs, zs.dtype.type(self.max_range))).sum(axis=1, dtype=np.float64)
        return ll * self.temper if self.temper != 1.0 else ll

    def log_likelihood(self, poses: ArrayLike, ranges: ArrayLike, angles: ArrayLike) -> NDArray[np.float64]:
        """Log-likelihood ``(N,)`` of one scan for each robot pose.

        Parameters
        ----------
        poses : array_like, shape (N, 3)
            Robot poses (NaN raises; poses outside the map read 0 on every
            beam, see :mod:`localize.raycast`).
        ranges, angles : array_like, shape (B,)
            The scan: readings (>= max_range = no return) and beam angles in
            the sensor frame.

        Examples
        --------
        >>> from localize.maps import office
        >>> g = office()
        >>> m = BeamModel(g, 8.0, method="march")
        >>> angles = np.linspace(-np.pi / 2, np.pi / 2, 19)
        >>> true = np.array([[6.0, 5.5, 0.3]])
        >>> z = m.expected(true, angles)[0]
        >>> ll = m.log_likelihood(np.array([[6.0, 5.5, 0.3], [6.0, 5.8, 0.3]]), z, angles)
        >>> bool(ll[0] > ll[1] + 10)
        True
        """
        z, a = self._prepare(ranges, angles)
        if self.caster is not None and self.caster.coded:
            # expected ranges as 8-bit codes: score each beam at the 256 code levels once,
            # then one lookup per beam (same values as beam_log_pdf at the decoded ranges)
            codes, levels = self.caster.cast_codes(sensor_poses(poses, self.sensor_offset), a)
            per_level = self.beam_log_pdf(z, np.repeat(levels[:, None], z.size, axis=1))
            ll = coded_sum(codes, np.ascontiguousarray(per_level.T, dtype=np.float32))
        else:
            zs = self.expected(poses, a, dtype=np.float32)
            ll = self.beam_log_pdf(z, zs).sum(axis=1, dtype=np.float64)
        return ll * self.temper if self.temper != 1.0 else ll

    def sample_expected(self, expected: ArrayLike, rng: np.random.Generator) -> NDArray[np.float64]:
        """Draw readings from the mixture given expected ranges (any shape).

        Each beam first picks a component with the mixture weights, then
        draws from it by inverting its CDF: the truncated normal, the
        truncated exponential, ``max_range``, or uniform.

        A beam whose ray hits nothing within range (expected ``max_range``)
        draws its hit part from the normal about ``max_range`` truncated to
        the range, as PR's sampler does: a reading a few ``sigma_hit`` short
        of it, an end point in mid-air that no laser produces and that fits
        any wall just inside the range (a corridor's far end: ``localize
        run`` then localized a featureless corridor, ``tests/test_state_scenarios.py``).
        With ``no_return=True`` it reads ``max_range``, the "no return" of a
        real scanner; its short and random parts are drawn as for any beam,
        from the same random numbers.

        Examples
        --------
        >>> m = BeamModel(None, 10.0)
        >>> z = m.sample_expected(np.full(20000, 4.0), np.random.default_rng(0))
        >>> round(float(np.mean(z == 10.0)), 2), bool(z.min() >= 0)
        (0.05, True)
        >>> far = np.full(20000, 10.0)                # rays that hit nothing: no return from the hit part too
        >>> round(float(np.mean(BeamModel(None, 10.0, no_return=True).sample_expected(far, np.random.default_rng(0))
        ...                     == 10.0)), 2)
        0.85
        """
        rng = check_rng(rng)
        zs = np.clip(np.asarray(expected, dtype=float), self.z_floor, self.max_range)
        zmax, sig, lam = self.max_range, self.sigma_hit, self.lambda_short
        k = rng.choice(4, size=zs.shape, p=[self.z_hit, self.z_short, self.z_max, self.z_rand])
        u = rng.random(zs.shape)
        lo, hi = _ndtr(-zs / sig), _ndtr((zmax - zs) / sig)
        hit = zs + sig * _ndtri(np.clip(lo + u * (hi - lo), _TINY_P, _BELOW_ONE))
        short = -np.log1p(u * np.expm1(-lam * zs)) / lam
        rand = u * zmax
        if self.no_return:
            hit = np.where(zs >= zmax, zmax, hit)      # a ray that hits nothing returns nothing
        z = np.choose(k, [hit, short, np.full(zs.shape, zmax), rand])
        return np.clip(z, 0.0, zmax)

    def sample(self, poses: ArrayLike, angles: ArrayLike, rng: np.random.Generator) -> NDArray[np.float64]:
        """Simulated scans ``(N, B)`` from robot ``poses`` (ray cast, then :meth:`sample_expected`).

        Examples
        --------
        >>> from localize.maps import office
        >>> m = BeamModel(office(), 8.0, method="march")
        >>> z = m.sample([[6.0, 5.5, 0.0]], np.linspace(-1, 1, 5), np.random.default_rng(1))
        >>> z.shape, bool(np.all((0 <= z) & (z <= 8.0)))
        ((1, 5), True)
        """
        rng = check_rng(rng)
        return self.sample_expected(self.expected(poses, angles), rng)


def _rowsum(a: NDArray[np.float64], out: NDArray[np.float64], r: NDArray[np.float64]) -> None:
    """``out[j] = sum_k a[k, j]`` added in the order of numpy's pairwise summation of a contiguous row.

    ``a.T.copy().sum(axis=1)`` gives the same bits, but needs the transposed copy: numpy adds a row of
    ``n <= 128`` numbers into 8 running sums (element ``k`` into sum ``k % 8``), joins them as
    ``((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))`` and adds the ``n % 8`` left over one by one; a
    longer row is split in two at a multiple of 8 near its middle. Here each of those steps is one
    vectorised add over all the columns. ``r`` is ``(8, m)`` scratch. :func:`_rowsum_is_numpys` checks
    the claim against this numpy once per row length.
    """
    n = a.shape[0]
    if n < 8:
        out[...] = 0.0
        for k in range(n):
            out += a[k]
        return
    if n > 128:
        n2 = n // 2
        n2 -= n2 % 8
        right = np.empty_like(out)
        _rowsum(a[:n2], out, r)
        _rowsum(a[n2:], right, r)
        out += right
        return
    top = n - n % 8
    np.copyto(r, a[:8])
    for k in range(8, top, 8):
        r += a[k:k + 8]
    r[0] += r[1]
    r[2] += r[3]
    r[4] += r[5]
    r[6] += r[7]
    r[0] += r[2]
    r[4] += r[6]
    np.add(r[0], r[4], out=out)
    for k in range(top, n):
        out += a[k]


_ROWSUM_OK: dict[int, bool] = {}


def _rowsum_is_numpys(n: int) -> bool:
    """Whether :func:`_rowsum` gives numpy's own bits for rows of ``n`` float32 numbers summed in float64.

    Checked once per ``n`` on random numbers of mixed magnitudes (a different numpy, or a row longer than
    its 8192-element buffer, may add in another order: the caller then transposes and calls numpy).
    """
    if n not in _ROWSUM_OK:
        rng = np.random.default_rng(n)
        v = (rng.normal(size=(n, 64)) * 10.0 ** rng.integers(-4, 5, size=(n, 64))).astype(np.float32)
        got = np.empty(64)
        _rowsum(v.astype(np.float64), got, np.empty((8, 64)))
        _ROWSUM_OK[n] = bool(np.array_equal(got, np.ascontiguousarray(v.T).sum(axis=1, dtype=np.float64)))
    return _ROWSUM_OK[n]


# -------------------------------------------------------- likelihood field
def _capped_sq_distance(obstacles: NDArray[np.bool_], cap: int) -> NDArray[np.int16]:
    """Squared distance (in cells^2) from each cell centre to the nearest obstacle cell's, exact up to ``cap^2``.

    Above ``cap^2`` the value is only known to be larger (at most ``2 (cap + 1)^2``, so 16 bits hold it for
    ``cap <= 126``). Two passes, as in a separable distance transform: the vertical distance ``v`` to the
    nearest obstacle of the same column (capped at ``cap + 1``, two sweeps over the rows), then
    ``min_s v[i, j + s]^2 + s^2`` over ``|s| <= cap``. No obstacle anywhere: every value is above ``cap^2``.
    """
    rows, cols = obstacles.shape
    top = cap + 1
    if 2 * top * top > np.iinfo(np.int16).max:
        raise ValueError(f"cap must be at most 126 cells; got {cap}")
    v = np.full((rows, cols), top, dtype=np.int16)
    run = np.full(cols, top, dtype=np.int16)
    for i in range(rows):                       # downwards: distance to the nearest obstacle above or at i
        run += 1
        run[obstacles[i]] = 0
        np.minimum(run, top, out=run)
        v[i] = run
    run[...] = top
    for i in range(rows - 1, -1, -1):           # upwards
        run += 1
        run[obstacles[i]] = 0
        np.minimum(run, top, out=run)
        np.minimum(v[i], run, out=v[i])
    v *= v
    out = v.copy()
    tmp = np.empty_like(v)
    for s in range(1, min(cap, cols - 1) + 1):
        np.add(v[:, :-s], s * s, out=tmp[:, s:])             # an obstacle s columns to the left
        np.minimum(out[:, s:], tmp[:, s:], out=out[:, s:])
        np.add(v[:, s:], s * s, out=tmp[:, :-s])             # ... and to the right
        np.minimum(out[:, :-s], tmp[:, :-s], out=out[:, :-s])
    return out


class LikelihoodField:
    """The likelihood-field (end-point) model, PR table 6.3 (ROS AMCL's default).

    Each beam that returned (``z < max_range``) is projected to its end point
    in the world; the end point is scored by the distance ``d`` to the
    nearest obstacle: ``p = z_hit N(d; 0, sigma_hit^2) + z_rand / max_range``.
    Max-range readings are skipped, as in PR. There is no ray casting: the
    per-cell log-probabilities are precomputed once from the map's distance
    field, and a scan costs one table lookup per beam.

    End points outside the map get the distance ``max_dist``, like AMCL's
    ``laser_likelihood_max_dist``: the map says nothing there. Distances
    are capped at ``max_dist`` everywhere.

    Parameters
    ----------
    grid : OccupancyGrid
    max_range : float
    z_hit, z_rand : float
        Weights in [0, 1]; ``z_hit + z_rand`` must be 1 within 1e-6 (PR's
        ``z_max`` has no role since max-range readings are skipped).
    sigma_hit : float
        Standard deviation of the end-point error (metres), > 0.
    max_dist : float, optional
        Distance assigned to end points off the map, and the cap on the
        distance field. Default: ``4 * sigma_hit``, which scores an end
        point far from any wall like one clearly missing.
    sensor_offset, max_beams, temper
        As for :class:`BeamModel`. Untempered, 180 beams make the field so
        sharp that global localization in the office failed in 8 of 12 runs
        (see "Choosing temper" in the module's docstring); ``temper=0.02``
        localized all 12.
    min_range : float
        Readings ``<= min_range`` are skipped like max-range readings (ROS
        AMCL's ``laser_min_range``): a laser cannot measure closer than its
        minimum range, and real scanners report 0 (or a tiny number) for a
        failed reading. Such readings are not evidence. A reading of exactly
        0 is always skipped.
    unknown_is_obstacle : bool, optional
        Whether unknown map cells count as obstacles in the distance field
        (default: the grid's own setting). ``False`` measures every end point's
        distance to the nearest *known* obstacle, as ROS AMCL does. With
        ``True``, every beam that ends in unknown space -- beyond the outer
        walls of a map built from scans -- scores as a perfect hit, which
        rewards wrong poses whose scans seem to pass through walls. With
        ``False``, end points in unknown cells are scored by their distance
        to the nearest known obstacle; end points off the map always score as
        at ``max_dist`` (a miss, as in ROS AMCL).
    unknown_neutral : bool
        With ``unknown_is_obstacle=False``: give end points in unknown cells
        one neutral score instead, the same for every pose: the log of the
        *mean likelihood* of an end point dropped at a random place of the
        known map (``unknown_log_prob``): the map says nothing there. It is
        higher than the mean *log*-likelihood of such an end point (by
        Jensen's inequality), i.e. lenient to a beam the map cannot judge;
        the mean log-likelihood was measured in
        ``benchmarks/bench_global.py`` and lost on the real logs. The
        command line uses it.
    z_short : float
        Weight in [0, 1] of unexpected short readings (PR's ``p_short``, a
        person or a chair in front of the mapped wall). With ``z_short > 0``
        no returned beam scores below :meth:`short_floor` of its range,
        ``log(z_rand / max_range + z_short lambda_short e^(-lambda_short z))``:
        a short reading that ends in free space, far from any wall, is then
        explained as a likely unmapped obstacle instead of counted as a miss.
        The floor is largest for short readings and fades to the plain
        ``z_rand`` term for long ones. It is a floor, not a fourth mixture
        weight, so ``z_hit + z_rand`` still sums to 1. Default 0 (PR table
        6.3 exactly); the command line uses 0.2 (``--z-short``).
    lambda_short : float
        Rate (1/metre, > 0) of the exponential short-reading density.
    dtype : numpy float dtype
        Precision of the sum over a scan's beams in :meth:`log_likelihood`. ``np.float64`` (default) adds
        the float32 table entries in double precision, bit for bit as the whole-cloud formula did.
        ``np.float32`` adds them in single precision (less memory traffic, faster): the end points, and
        so the table entries, are the same; a pose's sum of ``B`` entries ``v_k`` then differs from the
        float64 one by at most ``gamma_(B-1) sum_k |v_k|`` with ``gamma_n = n u / (1 - n u)``,
        ``u = 2^-24`` (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed. 2002, eq. 4.4),
        times ``temper``: about 1e-3 nats for 100 beams whose entries are near 2 in magnitude.

    Examples
    --------
    >>> from localize.maps import office
    >>> lf = LikelihoodField(office(), 8.0, z_hit=0.9, z_rand=0.1, sigma_hit=0.1)
    >>> angles = np.linspace(-np.pi / 2, np.pi / 2, 19)
    >>> bm = BeamModel(office(), 8.0, method="march")
    >>> z = bm.expected([[6.0, 5.5, 0.3]], angles)[0]
    >>> ll = lf.log_likelihood([[6.0, 5.5, 0.3], [6.0, 5.8, 0.3]], z, angles)
    >>> bool(ll[0] > ll[1])
    True
    """

    def __init__(self, grid: OccupancyGrid, max_range: float, z_hit: float = 0.9, z_rand: float = 0.1,
                 sigma_hit: float = 0.2, *, max_dist: float | None = None,
                 sensor_offset: ArrayLike = (0.0, 0.0, 0.0), max_beams: int | None = None,
                 temper: float = 1.0, min_range: float = 0.0, unknown_is_obstacle: bool | None = None,
                 unknown_neutral: bool = True, z_short: float = 0.0, lambda_short: float = 0.5,
                 dtype: type | str = np.float64) -> None:
        try:
            dt = np.dtype(dtype) if isinstance(dtype, (type, str, np.dtype)) else None
        except TypeError:
            dt = None
        if dt is None or dt.type not in (np.float32, np.float64):
            raise ValueError(f"dtype must be np.float64 (default, exact sums) or np.float32 (faster); got {dtype!r}")
        self.dtype = dt.type
        self.unknown_neutral = bool(unknown_neutral)
        self.z_short = check_probability(z_short, "z_short")
        self.lambda_short = check_positive(lambda_short, "lambda_short", "per metre")
        grid = check_grid(grid)
        if unknown_is_obstacle is not None and bool(unknown_is_obstacle) != grid.unknown_is_obstacle:
            grid = OccupancyGrid(grid.data, grid.resolution, origin=grid.origin,
                                 occupied_threshold=grid.occupied_threshold,
                                 unknown_is_obstacle=bool(unknown_is_obstacle))
        self.grid = grid
        self.max_range = check_max_range(max_range)
        mn = float(min_range)
        if not (np.isfinite(mn) and 0.0 <= mn < self.max_range):
            raise ValueError(f"min_range must lie in [0, max_range = {self.max_range:g}) metres; got {min_range!r}")
        self.min_range = mn
        w = _weights(("z_hit", "z_rand"), (z_hit, z_rand))
        self.z_hit, self.z_rand = float(w[0]), float(w[1])
        self.sigma_hit = check_positive(sigma_hit, "sigma_hit", "metres")
        self.max_dist = 4.0 * self.sigma_hit if max_dist is None else check_positive(max_dist, "max_dist", "metres")
        self.sensor_offset = _offset(sensor_offset)
        if max_beams is not None and int(max_beams) < 1:
            raise ValueError(f"max_beams must be >= 1 or None; got {max_beams}")
        self.max_beams = None if max_beams is None else int(max_beams)
        self.temper = _check_temper(temper)
        self._build()

    def __repr__(self) -> str:
        return (f"LikelihoodField(max_range={self.max_range:g}, z_hit={self.z_hit:g}, z_rand={self.z_rand:g}, "
                f"sigma_hit={self.sigma_hit:g}, max_dist={self.max_dist:g}"
                + (f", z_short={self.z_short:g}" if self.z_short > 0 else "")
                + (", dtype=float32" if self.dtype is np.float32 else "") + ")")

    def short_floor(self, z: ArrayLike) -> NDArray[np.float64]:
        """The lowest score a returned beam of range ``z`` can get: ``log(z_rand / max_range + z_short p_short(z))``.

        ``p_short(z) = lambda_short e^(-lambda_short z)``. With ``z_short = 0`` this is ``log(z_rand / max_range)``,
        which every end point already scores at least, so the floor changes nothing.

        Examples
        --------
        >>> from localize.maps import office
        >>> lf = LikelihoodField(office(), 8.0, z_hit=0.9, z_rand=0.1, sigma_hit=0.1, z_short=0.2)
        >>> lf.short_floor([0.5, 7.5]).round(3)
        array([-2.404, -4.21 ])
        """
        z = np.asarray(z, dtype=float)
        lam = self.lambda_short
        return np.log(self.z_rand / self.max_range + self.z_short * lam * np.exp(-lam * z))

    def point_log_prob(self, d: ArrayLike) -> NDArray[np.float64]:
        """``log(z_hit N(d; 0, sigma_hit^2) + z_rand / max_range)`` for end-point distances ``d``.

        Examples
        --------
        >>> from localize.maps import office
        >>> lf = LikelihoodField(office(), 8.0, z_hit=0.9, z_rand=0.1, sigma_hit=0.1)
        >>> lf.point_log_prob([0.0, 0.1, 1.0]).round(4)
        array([ 1.2818,  0.784 , -4.29  ])
        """
        d = np.minimum(np.asarray(d, dtype=float), self.max_dist)
        g = self.z_hit * np.exp(-0.5 * (d / self.sigma_hit) ** 2) / (self.sigma_hit * _SQRT2PI)
        return np.log(g + self.z_rand / self.max_range)

    def _build(self) -> None:
        g = self.grid
        res = g.resolution
        pad = int(math.ceil(self.max_range / res)) + 2
        rows, cols = g.shape
        outside = float(self.point_log_prob(self.max_dist))
        self.unknown_log_prob = outside
        known = None
        if not g.unknown_is_obstacle and self.unknown_neutral:
            known = ~g.unknown
            if not known.any() or known.all():
                known = None
        # float32 from the start (the same rounding as a float64 table cast afterwards, without that table)
        table = np.full((rows + 2 * pad, cols + 2 * pad), outside, dtype=np.float32)
        inner = table[pad:pad + rows, pad:pad + cols]
        if not self._fill_capped(inner, known):
            cells = self.point_log_prob(g.distance_field)
            if known is not None:
                # the map says nothing about its unknown cells: an end point there scores the log of the mean
                # likelihood of one dropped at a random place of the known map (the same for every pose). Off
                # the map it is a miss, as in AMCL.
                self.unknown_log_prob = float(np.log(np.mean(np.exp(cells[known]))))
                cells = np.where(known, cells, self.unknown_log_prob)
            inner[...] = cells
        self._pad = pad
        self._table = table
        self._flat = self._table.ravel()
        self._wp = cols + 2 * pad

    def _fill_capped(self, inner: NDArray[np.float32], known: NDArray[np.bool_] | None) -> bool:
        """Fill the table's map cells from squared cell distances capped at ``max_dist`` (no scipy, no float field).

        Each map cell's score depends only on its squared distance ``d2 = a^2 + b^2`` (cells) to the nearest
        obstacle, and only while ``d2 * res^2 < max_dist^2``: a table over ``d2`` holds every score. Its
        entries are computed as scipy's distance transform computes the distance (``sqrt((a res)^2 + (b
        res)^2)``) and then exactly as the field-wide formula, so the float32 table is the one built from
        :attr:`OccupancyGrid.distance_field` -- provided that every way of writing ``d2`` as ``a^2 + b^2``
        gives the same float32 score (scipy may pick either nearest obstacle of a tie) and that the unknown
        cells' mean score rounds to float32 the same way within a margin far wider than the last bits a
        tie can change. Returns False (and fills nothing) where that is not so, or where the cap is so wide
        that scipy is the faster way; the caller then builds the table from the distance field.
        """
        g = self.grid
        kc = int(math.ceil(self.max_dist / g.resolution)) + 1     # every d2 above kc^2 scores as max_dist
        if kc > _LF_MAX_CAP_CELLS:
            return False
        far = kc * kc + 1
        a, b = np.triu_indices(kc + 1)                             # every a <= b <= kc: d2 = a^2 + b^2
        d2 = a * a + b * b
        ok = d2 < far
        a, b, d2 = a[ok], b[ok], d2[ok]
        ar, br = a * g.resolution, b * g.resolution
        dist = np.append(np.sqrt(ar * ar + br * br), self.max_dist)  # as scipy: sum of the squared offsets
        score = self.point_log_prob(dist)
        lut64 = np.full(far + 1, score[-1])
        lut64[d2] = score[:-1]                                     # one representative per d2 ...
        lut32 = lut64.astype(np.float32)
        if not np.array_equal(lut32[d2], score[:-1].astype(np.float32)):
            return False                                           # ... which every other one must match
        sq = _capped_sq_distance(g.obstacles, kc)
        np.minimum(sq, far, out=sq)
        if known is not None:
            cells = lut64.take(sq[known])                          # the known cells in C order, as cells[known]
            u = float(np.log(np.mean(np.exp(cells, out=cells))))
            del cells
            margin = 1e-12 * abs(u)
            if not np.float32(u) == np.float32(u - margin) == np.float32(u + margin):
                return False
            self.unknown_log_prob = u
        step = max(1, _LF_BLOCK // max(1, sq.shape[1]))              # rows at a time: small index temporaries
        for r in range(0, sq.shape[0], step):
            lut32.take(sq[r:r + step], out=inner[r:r + step])
        if known is not None:
            inner[~known] = np.float32(self.unknown_log_prob)
        return True

    @property
    def table(self) -> NDArray[np.float32]:
        """Per-cell end-point log-probability, padded by ``max_range`` on every side."""
        return self._table

    def endpoints(self, poses: ArrayLike, ranges: ArrayLike, angles: ArrayLike) -> NDArray[np.float64]:
        """World end points ``(N, B, 2)`` of the beams (readable helper for figures and tests).

        Examples
        --------
        >>> from localize.maps import office
        >>> lf = LikelihoodField(office(), 8.0)
        >>> lf.endpoints([[1.0, 1.0, np.pi / 2]], [2.0], [0.0]).round(6)
        array([[[1., 3.]]])
        """
        sp = sensor_poses(poses, self.sensor_offset)
        z = np.asarray(ranges, dtype=float)
        a = sp[:, 2:3] + np.asarray(angles, dtype=float)[None, :]
        return np.stack([sp[:, 0:1] + z * np.cos(a), sp[:, 1:2] + z * np.sin(a)], axis=-1)

    def log_likelihood_reference(self, poses: ArrayLike, ranges: ArrayLike, angles: ArrayLike) -> NDArray:
        """Readable version of :meth:`log_likelihood` (PR table 6.3 line by line): the test oracle.

        Examples
        --------
        >>> from localize.maps import office
        >>> lf = LikelihoodField(office(), 8.0)
        >>> pose, z, a = [[6.0, 5.5, 0.0]], [0.9, 8.0], [np.pi / 2, 0.0]
        >>> bool(np.isclose(lf.log_likelihood_reference(pose, z, a), lf.log_likelihood(pose, z, a), atol=1e-4)[0])
        True
        """
        z, a = self._prepare(ranges, angles)
        sp = sensor_poses(poses, self.sensor_offset)
        out = np.zeros(sp.shape[0])
        for n, (x, y, th) in enumerate(sp):
            q = 0.0
            for zk, ak in zip(z, a):
                if zk >= self.max_range or zk <= self.min_range:
                    continue
                ex, ey = x + zk * math.cos(th + ak), y + zk * math.sin(th + ak)
                g = self.grid
                if not g.unknown_is_obstacle and self.unknown_neutral and bool(g.contains([ex, ey])) and g.unknown[
                        tuple(g.world_to_cell([ex, ey]))]:
                    beam = self.unknown_log_prob          # the map says nothing here
                else:
                    beam = float(self.point_log_prob(g.distance_at([ex, ey], outside=self.max_dist)))
                if self.z_short > 0:                      # an unmapped obstacle in front explains it at least this well
                    beam = max(beam, float(self.short_floor(zk)))
                q += beam
            out[n] = q * self.temper
        return out

    def _prepare(self, ranges: ArrayLike, angles: ArrayLike):
        z, a = _scan_beams(ranges, angles, self.max_range, self.max_beams)
        keep = (z < self.max_range) & (z > self.min_range)
        return z[keep], a[keep]

    def log_likelihood(self, poses: ArrayLike, ranges: ArrayLike, angles: ArrayLike) -> NDArray[np.float64]:
        """Log-likelihood ``(N,)`` of one scan for each robot pose (vectorised end-point lookups).

        Max-range readings and readings ``<= min_range`` are skipped. End points off the map score as at
        ``max_dist``; poses far outside the map are clipped onto the padded
        table's border cells, which hold that score. With ``z_short > 0`` no
        beam scores below :meth:`short_floor` of its range.

        Poses are scored in blocks of about 65,536 end points with work arrays
        kept on the model (no N x B temporaries), giving the same bits as the
        whole-cloud formula: float32 end points, float64 sum of each pose's
        beams in numpy's summation order. With ``dtype=np.float32`` the same
        entries are summed in float32 (see the class's ``dtype``). Not
        thread-safe on one model.

        Examples
        --------
        >>> from localize.maps import office
        >>> lf = LikelihoodField(office(), 8.0, sigma_hit=0.1)
        >>> ll = lf.log_likelihood([[6.0, 5.5, 0.0], [6.0, 5.2, 0.0]], [0.9], [np.pi / 2])
        >>> bool(ll[0] > ll[1])    # 0.9 m to the wall at y = 6.4 fits the first pose
        True
        """
        z, a = self._prepare(ranges, angles)
        sp = sensor_poses(poses, self.sensor_offset)
        n = sp.shape[0]
        ll = np.zeros(n)
        if z.size == 0 or n == 0:
            return ll
        g = self.grid
        inv = 1.0 / g.resolution
        f32 = np.float32
        # end point in (padded) cell units: p + R(theta) (z cos a, z sin a), every step rounded to float32
        bx = (z * np.cos(a) * inv).astype(f32)
        by = (z * np.sin(a) * inv).astype(f32)
        c = np.cos(sp[:, 2]).astype(f32)
        s = np.sin(sp[:, 2]).astype(f32)
        x0 = ((sp[:, 0] - g.origin[0]) * inv + self._pad).astype(f32)
        y0 = ((sp[:, 1] - g.origin[1]) * inv + self._pad).astype(f32)
        del sp
        rows_p, cols_p = self._table.shape
        reach = self.max_range * inv + 1
        # poses far off the map: clip end points onto the padded table's border (which holds the off-map score)
        clip = (float(x0.min()) - reach < 0 or float(y0.min()) - reach < 0
                or float(x0.max()) + reach >= cols_p or float(y0.max()) + reach >= rows_p)
        single = self.dtype is np.float32
        floor = None
        if self.z_short > 0:
            floor = self.short_floor(z).astype(f32)[:, None]
            floor = floor if single else floor.astype(np.float64)
        b = z.size
        nb = max(1, min(n, _LF_BLOCK // b))
        # beams x poses layout: each beam's offsets fill a row of bx and by once per call, so that the products
        # broadcast only the poses' cos and sin along the rows (numpy's loops for a broadcast column are slow)
        work = self._work(nb, b)
        np.copyto(work[7], bx[:, None])
        np.copyto(work[8], by[:, None])
        exact_sum = _rowsum_is_numpys(b)
        for k in range(0, n, nb):
            m = min(nb, n - k)
            if m < nb:
                work = tuple(w[..., :m] for w in work)
            v32, vals, r = work[6], work[-2], work[-1]
            self._entries(c[k:k + m], s[k:k + m], x0[k:k + m], y0[k:k + m], clip, work)
            if single:       # float32 sums: the bound of the class's dtype
                if floor is not None:
                    np.maximum(v32, floor, out=v32)
                np.add.reduce(v32, axis=0, out=vals)
                ll[k:k + m] = vals
                continue
            np.copyto(vals, v32)
            if floor is not None:
                np.maximum(vals, floor, out=vals)
            if exact_sum:       # the sum over beams in numpy's own order: the same bits as vals.T.sum(axis=1)
                _rowsum(vals, ll[k:k + m], r)
            else:
                ll[k:k + m] = np.ascontiguousarray(vals.T, dtype=f32).sum(axis=1, dtype=np.float64)
        return ll * self.temper if self.temper != 1.0 else ll

    def log_likelihood_at_cells(self, cells: ArrayLike, headings: ArrayLike, ranges: ArrayLike,
                                angles: ArrayLike) -> NDArray[np.float64]:
        """Log-likelihood ``(P, H)`` of one scan for the robot at the centre of each map cell of ``cells``
        (``(P, 2)``, row and column) facing each of ``headings`` (radians): an exhaustive search's scores.

        The correlative scan matcher's way (Olson, *Real-time correlative scan
        matching*, ICRA 2009): for each heading the scan is rotated once, and
        every beam's end point becomes a whole number of cells from the
        robot's cell; sliding the scan from cell to cell is then one table
        lookup per beam, with no trigonometry per pose. A robot at a cell's
        centre puts each end point in the cell :meth:`log_likelihood` puts it
        in, except where the end point lies within float32 round-off of a
        cell's edge.

        Examples
        --------
        >>> from localize.maps import office
        >>> g = office()
        >>> lf = LikelihoodField(g, 8.0, sigma_hit=0.1)
        >>> cells = g.world_to_cell([[6.0, 5.5], [6.0, 5.2]])
        >>> ll = lf.log_likelihood_at_cells(cells, [0.0, np.pi / 2], [0.9], [np.pi / 2])
        >>> ll.shape, bool(ll[0, 0] > ll[1, 0])    # facing +x, 0.9 m to the wall at y = 6.4 on the left
        ((2, 2), True)
        >>> poses = np.column_stack([g.cell_to_world(cells), np.zeros(2)])
        >>> bool(np.array_equal(ll[:, 0], lf.log_likelihood(poses, [0.9], [np.pi / 2])))
        True
        """
        g = self.grid
        cells = np.asarray(cells)
        if cells.ndim != 2 or cells.shape[1] != 2 or not np.issubdtype(cells.dtype, np.integer):
            raise ValueError(f"cells must be an (P, 2) integer array of (row, column) map cells; got "
                             f"{cells.dtype} with shape {cells.shape}")
        rows, cols = g.shape
        if cells.size and ((cells < 0).any() or (cells >= (rows, cols)).any()):
            raise ValueError(f"cells must lie in the map's {rows} rows and {cols} columns; got rows "
                             f"{cells[:, 0].min()}..{cells[:, 0].max()}, columns {cells[:, 1].min()}..{cells[:, 1].max()}")
        th = np.asarray(headings, dtype=float).ravel()
        if not np.all(np.isfinite(th)):
            raise ValueError("headings must be finite radians")
        z, a = self._prepare(ranges, angles)
        out = np.zeros((len(cells), len(th)))
        if z.size == 0 or out.size == 0:
            return out
        inv = 1.0 / g.resolution
        ox, oy, oth = self.sensor_offset
        base = ((cells[:, 0] + self._pad) * self._wp + cells[:, 1] + self._pad).astype(np.intp)
        floor = self.short_floor(z).astype(np.float32).astype(float)[:, None] if self.z_short > 0 else None
        for k, t in enumerate(th):
            c, s = math.cos(t), math.sin(t)
            dx = (c * ox - s * oy + z * np.cos(t + oth + a)) * inv     # end points from the robot, in cells
            dy = (s * ox + c * oy + z * np.sin(t + oth + a)) * inv
            di, dj = (np.clip(np.floor(0.5 + d), -self._pad, self._pad - 1).astype(np.intp) for d in (dy, dx))
            off = di * self._wp + dj                                    # clipped onto the padding (off the map)
            v = self._flat.take(off[:, None] + base[None, :])          # beams x cells
            if floor is not None:
                v = np.maximum(v, floor)
            out[:, k] = v.sum(axis=0, dtype=np.float64)
        return out * self.temper if self.temper != 1.0 else out

    def _entries(self, c: NDArray, s: NDArray, x0: NDArray, y0: NDArray, clip: bool,
                 work: tuple[NDArray, ...]) -> None:
        """The table entries of one block's end points (beams x poses) into ``work``'s ``v32``."""
        ex, ey, t, j, i, ii, v32, bx, by = work[:9]
        np.multiply(bx, c, out=ex)
        np.multiply(by, s, out=t)
        ex -= t
        ex += x0
        np.multiply(bx, s, out=ey)
        np.multiply(by, c, out=t)
        ey += t
        ey += y0
        if clip:
            rows_p, cols_p = self._table.shape
            np.clip(ex, 0, cols_p - 1, out=ex)
            np.clip(ey, 0, rows_p - 1, out=ey)
        np.copyto(j, ex, casting="unsafe")       # truncation, as astype: every coordinate is >= 0 here
        np.copyto(i, ey, casting="unsafe")
        i *= self._wp
        i += j
        if ii is not i:
            np.copyto(ii, i)
        self._flat.take(ii, out=v32, mode="clip")   # every index is inside the table: "clip" never clips

    def __getstate__(self) -> dict:
        """Pickle without the work arrays of :meth:`log_likelihood` (rebuilt on the next call)."""
        state = self.__dict__.copy()
        state.pop("_work_arrays", None)
        state.pop("_work_key", None)
        return state

    def _work(self, poses: int, beams: int) -> tuple[NDArray, ...]:
        """Work arrays for blocks of ``beams`` x ``poses`` end points, kept between calls (a few MB)."""
        key = (beams, poses, self.dtype)
        if getattr(self, "_work_key", None) != key:
            f32, ip = np.float32, np.intp
            small = np.int32 if self._flat.size < 2 ** 31 else ip   # cell indices, exact in 32 bits
            ex, ey, t, v32, bx, by = (np.empty((beams, poses), dtype=f32) for _ in range(6))
            j, i = np.empty((beams, poses), dtype=small), np.empty((beams, poses), dtype=small)
            ii = i if small is ip else np.empty((beams, poses), dtype=ip)
            if self.dtype is np.float32:    # vals: one float32 sum per pose; no float64 copy, no scratch
                vals, r = np.empty(poses, dtype=f32), np.empty(poses, dtype=f32)
            else:
                vals, r = np.empty((beams, poses)), np.empty((8, poses))
            self._work_arrays = (ex, ey, t, j, i, ii, v32, bx, by, vals, r)
            self._work_key = key
        return self._work_arrays

    def sample(self, poses: ArrayLike, angles: ArrayLike, rng: np.random.Generator,
               method: str = "march") -> NDArray[np.float64]:
        """Simulated scans ``(N, B)``: ray-cast ranges plus Gaussian noise, random readings with prob. ``z_rand``.

        The likelihood field is not a generative model of ranges; this is
        the matching simulator (end points near obstacles, occasional random
        readings) used to test it.

        Examples
        --------
        >>> from localize.maps import office
        >>> lf = LikelihoodField(office(), 8.0)
        >>> lf.sample([[6.0, 5.5, 0.0]], np.linspace(-1, 1, 4), np.random.default_rng(0)).shape
        (1, 4)
        """
        rng = check_rng(rng)
        a = check_angles(angles)
        zs = RayCaster(self.grid, self.max_range, method=method).cast(sensor_poses(poses, self.sensor_offset), a)
        z = zs + rng.normal(0.0, self.sigma_hit, zs.shape)
        rand = rng.random(zs.shape) < self.z_rand
        z = np.where(rand, rng.uniform(0, self.max_range, zs.shape), z)
        z = np.where(zs >= self.max_range, self.max_range, z)
        return np.clip(z, 0.0, self.max_range)


# ----------------------------------------------------------- landmark model
#: A robot nearer than this (metres) to a landmark stands on it: the bearing,
#: and so the measurement Jacobian, is undefined there (the EKF skips such a
#: sighting; :meth:`LandmarkModel.jacobian` raises).
ON_LANDMARK = 1e-9


def range_bearing(poses: ArrayLike, landmarks: ArrayLike) -> NDArray[np.float64]:
    """The landmark model's noise-free measurement ``h(x, m)``: ``(range, bearing)`` (PR eq. 6.40).

    ``poses (..., 3)`` and ``landmarks (..., 2)`` broadcast against each
    other; the result has shape ``(..., 2)``, bearings relative to the
    heading in ``[-pi, pi)``. Unchecked (the inner loop of the EKF and the UKF);
    :meth:`LandmarkModel.expected` and :func:`localize.ekf.landmark_measurement`
    check their input and call it.

    Examples
    --------
    >>> range_bearing([0.0, 0.0, np.pi / 2], [3.0, 4.0]).round(6)
    array([ 5.      , -0.643501])
    """
    p, m = np.asarray(poses, dtype=float), np.asarray(landmarks, dtype=float)
    dx, dy = m[..., 0] - p[..., 0], m[..., 1] - p[..., 1]
    b = wrap_angle(np.arctan2(dy, dx) - p[..., 2])
    return np.stack(np.broadcast_arrays(np.hypot(dx, dy), b), axis=-1)


def range_bearing_jacobian(poses: ArrayLike, landmarks: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Jacobian ``H = dh/dx`` of :func:`range_bearing` and where it is undefined (PR eq. 7.14).

    ``H = [[-dx/r, -dy/r, 0], [dy/q, -dx/q, -1]]`` with ``(dx, dy)`` from the
    robot to the landmark and ``q = r**2``; shape ``(..., 2, 3)``. The second
    result is ``True`` where the robot stands on the landmark (``r <``
    :data:`ON_LANDMARK`); ``H`` is finite there but meaningless. Unchecked.

    Examples
    --------
    >>> H, on = range_bearing_jacobian([0.0, 0.0, 0.0], [[3.0, 4.0], [0.0, 0.0]])
    >>> H[0].round(4), on.tolist()
    (array([[-0.6 , -0.8 ,  0.  ],
           [ 0.16, -0.12, -1.  ]]), [False, True])
    """
    p, m = np.asarray(poses, dtype=float), np.asarray(landmarks, dtype=float)
    dx, dy = m[..., 0] - p[..., 0], m[..., 1] - p[..., 1]
    q = dx * dx + dy * dy
    on = q < ON_LANDMARK ** 2
    q = np.where(on, 1.0, q)
    r = np.sqrt(q)
    H = np.zeros(np.shape(q) + (2, 3))
    H[..., 0, 0], H[..., 0, 1] = -dx / r, -dy / r
    H[..., 1, 0], H[..., 1, 1], H[..., 1, 2] = dy / q, -dx / q, -1.0
    return H, on



class LandmarkModel:
    """Range and bearing to identified point landmarks (PR section 6.6, table 6.4).

    A sighting of landmark ``l`` at ``(mx, my)`` from pose ``(x, y, theta)``
    is ``z = (r, phi)`` with

    ``r = sqrt((mx - x)^2 + (my - y)^2) + e_r``,
    ``phi = atan2(my - y, mx - x) - theta + e_phi``,

    ``e_r ~ N(0, sigma_range^2)``, ``e_phi ~ N(0, sigma_bearing^2)``,
    independent; bearings wrapped to ``[-pi, pi)``. (PR also includes a
    signature; identities are given here as ``ids``.)

    Parameters
    ----------
    landmarks : array_like, shape (L, 2)
    sigma_range : float
        Metres, > 0.
    sigma_bearing : float
        Radians, > 0.

    Examples
    --------
    >>> lm = LandmarkModel([[2.0, 0.0], [0.0, 3.0]], 0.1, 0.05)
    >>> lm.expected([[0.0, 0.0, 0.0]]).round(4)
    array([[[2.    , 0.    ],
            [3.    , 1.5708]]])
    """

    def __init__(self, landmarks: ArrayLike, sigma_range: float, sigma_bearing: float) -> None:
        lm = np.asarray(landmarks, dtype=float)
        if lm.ndim != 2 or lm.shape[1] != 2 or lm.shape[0] == 0:
            raise ValueError(f"landmarks must be an (L, 2) array of (x, y) with L >= 1; got shape {lm.shape}")
        if not np.all(np.isfinite(lm)):
            raise ValueError("landmarks must be finite")
        lm.setflags(write=False)
        self.landmarks = lm
        self.sigma_range = check_positive(sigma_range, "sigma_range", "metres")
        self.sigma_bearing = check_positive(sigma_bearing, "sigma_bearing", "radians")

    def __repr__(self) -> str:
        return (f"LandmarkModel({len(self.landmarks)} landmarks, sigma_range={self.sigma_range:g}, "
                f"sigma_bearing={self.sigma_bearing:g})")

    @property
    def R(self) -> NDArray[np.float64]:
        """Measurement noise covariance ``diag(sigma_range^2, sigma_bearing^2)`` (for the EKF)."""
        return np.diag([self.sigma_range ** 2, self.sigma_bearing ** 2])

    def _ids(self, ids: ArrayLike | None) -> NDArray[np.intp]:
        if ids is None:
            return np.arange(len(self.landmarks))
        k = np.asarray(ids)
        if k.ndim == 0:
            k = k.reshape(1)
        if k.size == 0:
            return np.zeros(0, dtype=np.intp)
        if k.ndim != 1 or not np.issubdtype(k.dtype, np.integer):
            raise ValueError(f"ids must be a 1-D array of integer landmark indices; got {k!r}")
        if k.size and (k.min() < 0 or k.max() >= len(self.landmarks)):
            raise ValueError(f"ids must lie in 0..{len(self.landmarks) - 1}; got {k.tolist()}")
        return k.astype(np.intp)

    def expected(self, poses: ArrayLike, ids: ArrayLike | None = None) -> NDArray[np.float64]:
        """Noise-free ``(range, bearing)`` of landmarks ``ids`` (default all): shape ``(N, L, 2)``.

        Examples
        --------
        >>> LandmarkModel([[1.0, 1.0]], 0.1, 0.1).expected([0.0, 0.0, np.pi / 2]).round(4)
        array([[[ 1.4142, -0.7854]]])
        """
        p = check_sensor_poses(poses)
        return range_bearing(p[:, None, :], self.landmarks[self._ids(ids)][None])

    def log_likelihood(self, poses: ArrayLike, z: ArrayLike, ids: ArrayLike) -> NDArray[np.float64]:
        """Log-likelihood ``(N,)`` of sightings ``z`` ``(K, 2)`` of landmarks ``ids`` ``(K,)``.

        Gaussian in range and in the wrapped bearing difference. No
        sightings (K = 0) gives zeros.

        Examples
        --------
        >>> lm = LandmarkModel([[2.0, 0.0]], 0.1, 0.05)
        >>> ll = lm.log_likelihood([[0, 0, 0], [0.2, 0, 0]], [[2.0, 0.0]], [0])
        >>> bool(ll[0] > ll[1])
        True
        """
        k = self._ids(ids)
        zz = np.asarray(z, dtype=float).reshape(-1, 2) if np.size(z) else np.zeros((0, 2))
        if zz.shape[0] != k.shape[0]:
            raise ValueError(f"z has {zz.shape[0]} sightings but ids has {k.shape[0]}")
        if not np.all(np.isfinite(zz)):
            raise ValueError("z must be finite (range, bearing) pairs")
        if (zz[:, 0] < 0).any():
            raise ValueError("measured ranges in z must be >= 0")
        p = check_sensor_poses(poses)
        if k.size == 0:
            return np.zeros(p.shape[0])
        e = self.expected(p, k)
        dr = (zz[None, :, 0] - e[..., 0]) / self.sigma_range
        db = np.asarray(wrap_angle(zz[None, :, 1] - e[..., 1])) / self.sigma_bearing
        const = math.log(2 * math.pi * self.sigma_range * self.sigma_bearing)
        return (-0.5 * (dr ** 2 + db ** 2) - const).sum(axis=1)

    def sample(self, pose: ArrayLike, rng: np.random.Generator, ids: ArrayLike | None = None) -> NDArray[np.float64]:
        """A noisy sighting ``(K, 2)`` of landmarks ``ids`` (default all) from one pose.

        Examples
        --------
        >>> lm = LandmarkModel([[2.0, 0.0], [0.0, 3.0]], 0.1, 0.05)
        >>> lm.sample([0.0, 0.0, 0.0], np.random.default_rng(0)).shape
        (2, 2)
        """
        rng = check_rng(rng)
        p = as_poses(pose, "pose").reshape(-1, 3)
        if p.shape[0] != 1:
            raise ValueError(f"pose must be a single (x, y, theta); got shape {np.shape(pose)}")
        e = self.expected(p, ids)[0]
        noise = rng.normal(size=e.shape) * np.array([self.sigma_range, self.sigma_bearing])
        z = e + noise
        z[:, 0] = np.abs(z[:, 0])
        z[:, 1] = wrap_angle(z[:, 1])
        return z

    def jacobian(self, pose: ArrayLike, landmark_id: int) -> NDArray[np.float64]:
        """Jacobian ``(2, 3)`` of ``(range, bearing)`` with respect to ``(x, y, theta)`` (PR eq. 7.14).

        ``H = [[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]]`` with
        ``(dx, dy)`` from the robot to the landmark. Raises ``ValueError``
        when the robot stands on the landmark (``r <`` :data:`ON_LANDMARK`).

        Examples
        --------
        >>> lm = LandmarkModel([[3.0, 4.0]], 0.1, 0.05)
        >>> lm.jacobian([0.0, 0.0, 0.0], 0).round(4)
        array([[-0.6 , -0.8 ,  0.  ],
               [ 0.16, -0.12, -1.  ]])
        """
        p = as_poses(pose, "pose").reshape(-1)
        if p.shape != (3,):
            raise ValueError(f"pose must be a single (x, y, theta); got shape {np.shape(pose)}")
        k = int(self._ids([int(landmark_id)])[0])
        H, on = range_bearing_jacobian(p, self.landmarks[k])
        if on:
            raise ValueError(f"pose {p.tolist()} coincides with landmark {k} at {self.landmarks[k].tolist()} "
                             f"(nearer than ON_LANDMARK = {ON_LANDMARK:g} m): the bearing is undefined")
        return H
