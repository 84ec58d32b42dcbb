"""Probabilistic motion models: where a robot goes when it is told to move.

Three models, each as a *sampler* (draw successor poses, what a particle filter
needs) and a *density* (evaluate ``p(x_t | u_t, x_{t-1})``, what a grid filter
needs), vectorised over any number of poses:

* the **forward model** of many tutorials: "move ``d`` metres ahead" with
  Gaussian noise on the distance and on the heading
  (:func:`sample_forward`, :func:`forward_pdf_xy`);
* the **odometry model** (Thrun, Burgard & Fox, *Probabilistic Robotics*, 2005,
  "PR", section 5.4, tables 5.5 and 5.6): two odometry readings become a
  rotation ``rot1``, a translation ``trans`` and a rotation ``rot2``, each
  perturbed by zero-mean Gaussian noise (:func:`odometry_to_control`,
  :func:`sample_odometry`, :func:`odometry_pdf`, :func:`odometry_pdf_xy`);
* the **velocity model** (PR section 5.3, tables 5.1 and 5.3): a translational
  and rotational velocity ``(v, omega)`` held for ``dt`` seconds, perturbed,
  plus a final rotation ``gamma`` (:func:`sample_velocity`,
  :func:`velocity_pdf`).

Noise conventions
-----------------
The alphas follow PR: the noise *variances* are ``alpha1*rot1**2 +
alpha2*trans**2`` and so on (``noise="squared"``, the default). Some course
notes and reports write ``alpha1*|rot1| + alpha2*|trans|`` instead
(``noise="absolute"``); a callable reproduces any other variant (see
:func:`odometry_variances`). PR's odometry sampler *subtracts* the noise and
its velocity sampler *adds* it (``sign=-1`` / ``sign=+1``); the sign changes
which way a given random number pushes, never the distribution.

One model, two faces
--------------------
The sampler and the density here describe *the same* distribution, so that a
particle filter and a grid filter built on them agree. Where that departs from
PR's pseudocode:

* the noise variances are computed from the *measured* motion (as the
  samplers of tables 5.3 and 5.6 do), not from the hypothesised one (as table
  5.5 does);
* the density is over ``(x, y, theta)``: it includes the Jacobian of the map
  from noisy motion parameters to poses (``1/trans`` for odometry), without
  which table 5.5's value integrates to the translation instead of to one;
* angles are wrapped, so the angle noise is a wrapped normal, and every
  parameter combination that reaches the same pose is counted (a negative
  translation reaches the same point as a positive one turned by pi).

The readable versions :func:`sample_motion_model_odometry`,
:func:`motion_model_odometry`, :func:`sample_motion_model_velocity` and
:func:`motion_model_velocity` follow the book's pseudocode one pose at a time;
they are the test oracles of the vectorised functions.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_alphas, check_nonnegative, check_number, check_positive, check_rng
from .geometry import as_poses, relative, wrap_angle

__all__ = [
    "odometry_to_control",
    "odometry_variances",
    "velocity_variances",
    "move_odometry",
    "move_velocity",
    "sample_forward",
    "forward_pdf_xy",
    "sample_odometry",
    "odometry_pdf",
    "odometry_pdf_xy",
    "sample_velocity",
    "velocity_pdf",
    "sample_motion_model_odometry",
    "motion_model_odometry",
    "sample_motion_model_velocity",
    "motion_model_velocity",
    "OdometryMotion",
    "ReversibleOdometry",
    "VelocityMotion",
    "MIN_TRANS",
]

TWO_PI = 2.0 * math.pi
_LOG_SQRT_2PI = 0.5 * math.log(TWO_PI)
#: Translations at or below this (metres) count as "did not translate": rot1 is
#: then 0 and the whole heading change goes into rot2 (atan2 of a zero vector
#: is meaningless). Real drivers often use about 1 cm to ignore encoder jitter.
MIN_TRANS = 1e-9
#: The densities diverge like 1/distance at the previous position (a property
#: of the model); distances below this (metres) are raised to it.
_MIN_DIST = 1e-9
#: Turn rates (rad/s) and turned angles (rad) below this count as straight motion in the readable
#: velocity model, whose arc formulas divide by them (the limit is the straight line).
_STRAIGHT = 1e-9
#: Relative tolerance below which a value that should be nonzero is taken as zero: sin(psi)/psi of
#: the velocity density's branches, the readable density's "centre at infinity" test.
_TINY = 1e-12
#: Angle noise with a standard deviation below this is treated as a plain
#: Gaussian (the wrapped images add less than 1e-8 of the peak density).
_WRAP_SIGMA = 0.5

NoiseSpec = Union[str, Callable]


# ----------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------

def _check_sign(sign: int) -> float:
    if sign not in (-1, 1):
        raise ValueError(f"sign must be -1 (subtract the noise) or +1 (add it); got {sign!r}")
    return float(sign)


def _odometry_pair(u: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    try:
        prev_odom, odom = u  # type: ignore[misc]
    except (TypeError, ValueError):
        raise ValueError(
            "u must be the pair (prev_odom, odom) of two odometry poses (x, y, theta); "
            f"got {np.shape(u) if not isinstance(u, (list, tuple)) else f'{len(u)} items'}"
        ) from None
    return as_poses(prev_odom, "u[0] (prev_odom)"), as_poses(odom, "u[1] (odom)")


def _velocity_control(u: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    c = np.asarray(u, dtype=float)
    if c.ndim == 0 or c.shape[-1] != 2:
        raise ValueError(f"u must be (v, omega), shape (..., 2); got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"u (v, omega) must be finite; got NaN or infinite values in {c.tolist()}")
    return c[..., 0], c[..., 1]


def _check_xy(xy: ArrayLike) -> NDArray[np.float64]:
    """Positions ``(..., 2)`` as a finite float array (the domain of the ``*_pdf_xy`` densities)."""
    q = np.asarray(xy, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 2:
        raise ValueError(f"xy must have shape (..., 2); got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("xy contains NaN or infinite values")
    return q


def _broadcast_leading(name_a: str, a_shape: tuple, name_b: str, b_shape: tuple) -> tuple:
    try:
        return np.broadcast_shapes(a_shape, b_shape)
    except ValueError:
        raise ValueError(f"{name_a} with leading shape {a_shape} does not broadcast against "
                         f"{name_b} with leading shape {b_shape}") from None


# ----------------------------------------------------------------------------
# noise conventions
# ----------------------------------------------------------------------------

def odometry_variances(rot1: ArrayLike, trans: ArrayLike, rot2: ArrayLike, alphas: ArrayLike,
                       noise: NoiseSpec = "squared") -> tuple[NDArray, NDArray, NDArray]:
    """Noise variances of ``(rot1, trans, rot2)`` under a named convention.

    Parameters
    ----------
    rot1, trans, rot2 : array_like
        The measured motion (radians, metres, radians).
    alphas : array_like, shape (4,)
        ``alpha1`` (rotation from rotation), ``alpha2`` (rotation from
        translation), ``alpha3`` (translation from translation), ``alpha4``
        (translation from rotation); all >= 0.
    noise : {"squared", "absolute"} or callable
        ``"squared"`` (PR table 5.6, the default)::

            var_rot1  = alpha1*rot1**2 + alpha2*trans**2
            var_trans = alpha3*trans**2 + alpha4*(rot1**2 + rot2**2)
            var_rot2  = alpha1*rot2**2 + alpha2*trans**2

        ``"absolute"``: the same with ``|.|`` in place of ``(.)**2``, so that
        variances grow *linearly* with the motion (as in several course notes).
        A callable ``f(rot1, trans, rot2, alphas) -> (var_rot1, var_trans,
        var_rot2)`` is used as given.

    Returns
    -------
    var_rot1, var_trans, var_rot2 : ndarray

    Examples
    --------
    >>> v = odometry_variances(0.1, 1.0, 0.0, [0.1, 0.01, 0.05, 0.1])
    >>> [round(float(x), 6) for x in v]
    [0.011, 0.051, 0.01]
    >>> [round(float(x), 6) for x in odometry_variances(0.1, 1.0, 0.0, [0.1, 0.01, 0.05, 0.1], "absolute")]
    [0.02, 0.06, 0.01]
    """
    a1, a2, a3, a4 = (float(a) for a in check_alphas(alphas, 4))
    r1, t, r2 = (np.asarray(v, dtype=float) for v in (rot1, trans, rot2))
    if callable(noise):
        out = noise(r1, t, r2, np.array([a1, a2, a3, a4]))
        if len(out) != 3:
            raise ValueError("a noise callable must return (var_rot1, var_trans, var_rot2)")
        return tuple(np.asarray(o, dtype=float) for o in out)  # type: ignore[return-value]
    if noise == "squared":
        f = np.square
    elif noise == "absolute":
        f = np.abs
    else:
        raise ValueError(f"noise must be 'squared', 'absolute' or a callable; got {noise!r}")
    fr1, ft, fr2 = f(r1), f(t), f(r2)
    return a1 * fr1 + a2 * ft, a3 * ft + a4 * (fr1 + fr2), a1 * fr2 + a2 * ft


def velocity_variances(v: ArrayLike, omega: ArrayLike, alphas: ArrayLike,
                       noise: NoiseSpec = "squared") -> tuple[NDArray, NDArray, NDArray]:
    """Noise variances of ``(v, omega, gamma)`` for the velocity model.

    ``"squared"`` (PR table 5.3)::

        var_v     = alpha1*v**2 + alpha2*omega**2
        var_omega = alpha3*v**2 + alpha4*omega**2
        var_gamma = alpha5*v**2 + alpha6*omega**2

    ``"absolute"`` uses ``|v|`` and ``|omega|`` instead; a callable
    ``f(v, omega, alphas) -> (var_v, var_omega, var_gamma)`` is used as given.

    Examples
    --------
    >>> [round(float(x), 6) for x in velocity_variances(1.0, 0.5, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])]
    [0.15, 0.4, 0.65]
    """
    return _velocity_variances(v, omega, check_alphas(alphas, 6), noise)


def _velocity_variances(v: ArrayLike, omega: ArrayLike, a: NDArray, noise: NoiseSpec) -> tuple[NDArray, NDArray, NDArray]:
    """:func:`velocity_variances` with ``a`` already checked (the lean path)."""
    v = np.asarray(v, dtype=float)
    w = np.asarray(omega, dtype=float)
    if callable(noise):
        out = noise(v, w, a)
        if len(out) != 3:
            raise ValueError("a noise callable must return (var_v, var_omega, var_gamma)")
        return tuple(np.asarray(o, dtype=float) for o in out)  # type: ignore[return-value]
    if noise == "squared":
        fv, fw = v * v, w * w
    elif noise == "absolute":
        fv, fw = np.abs(v), np.abs(w)
    else:
        raise ValueError(f"noise must be 'squared', 'absolute' or a callable; got {noise!r}")
    return a[0] * fv + a[1] * fw, a[2] * fv + a[3] * fw, a[4] * fv + a[5] * fw


def _stds(variances, min_std: float, names: tuple[str, str, str]) -> list[NDArray]:
    out = []
    for var, name in zip(variances, names):
        var = np.asarray(var, dtype=float)
        if not np.all(np.isfinite(var)) or np.any(var < 0):
            raise ValueError(f"the noise variance of {name} must be finite and >= 0; got {var}")
        s = np.sqrt(var)
        if min_std > 0:
            s = np.maximum(s, min_std)
        out.append(s)
    return out


# ----------------------------------------------------------------------------
# deterministic kinematics
# ----------------------------------------------------------------------------

def odometry_to_control(prev_odom: ArrayLike, odom: ArrayLike,
                        min_trans: float = MIN_TRANS) -> tuple[NDArray, NDArray, NDArray]:
    """Turn two odometry poses into the motion ``(rot1, trans, rot2)``.

    The robot is pictured as turning by ``rot1`` towards its destination,
    driving straight ``trans`` metres, and turning by ``rot2`` into its final
    heading (PR section 5.4.1, figure 5.7). Only the *difference* of the two
    readings matters, so the odometry frame's arbitrary origin drops out.

    Parameters
    ----------
    prev_odom, odom : array_like, shape (..., 3)
        Consecutive odometry readings ``(x, y, theta)``; broadcast together.
    min_trans : float
        Translations ``<= min_trans`` metres count as none: then ``rot1 = 0``
        and ``rot2`` is the whole heading change.

    Returns
    -------
    rot1, trans, rot2 : ndarray or float
        Angles wrapped to ``[-pi, pi)``; ``trans >= 0``.

    Examples
    --------
    >>> r1, t, r2 = odometry_to_control([0.0, 0.0, 0.0], [1.0, 1.0, np.pi / 2])
    >>> round(float(r1), 6), round(float(t), 6), round(float(r2), 6)
    (0.785398, 1.414214, 0.785398)
    >>> [round(float(v), 6) for v in odometry_to_control([2, 3, 0.5], [2, 3, 1.0])]  # turn in place
    [0.0, 0.0, 0.5]
    """
    p = as_poses(prev_odom, "prev_odom")
    q = as_poses(odom, "odom")
    min_trans = check_nonnegative(min_trans, "min_trans")
    dx = q[..., 0] - p[..., 0]
    dy = q[..., 1] - p[..., 1]
    trans = np.hypot(dx, dy)
    moved = trans > min_trans
    rot1 = np.where(moved, wrap_angle(np.arctan2(dy, dx) - p[..., 2]), 0.0)
    rot2 = wrap_angle(q[..., 2] - p[..., 2] - rot1)
    rot1 = wrap_angle(rot1)
    if np.ndim(trans) == 0:
        return float(rot1), float(trans), float(rot2)
    return rot1, trans, rot2


def move_odometry(poses: ArrayLike, rot1: ArrayLike, trans: ArrayLike, rot2: ArrayLike) -> NDArray[np.float64]:
    """Apply a noise-free ``(rot1, trans, rot2)`` motion to poses.

    Examples
    --------
    >>> move_odometry([0.0, 0.0, 0.0], np.pi / 2, 2.0, -np.pi / 2).round(12)
    array([0., 2., 0.])
    """
    p = as_poses(poses)
    r1, t, r2 = (np.asarray(v, dtype=float) for v in (rot1, trans, rot2))
    heading = p[..., 2] + r1
    x = p[..., 0] + t * np.cos(heading)
    y = p[..., 1] + t * np.sin(heading)
    th = wrap_angle(heading + r2)
    return np.stack(np.broadcast_arrays(x, y, th), axis=-1)


def move_velocity(poses: ArrayLike, v: ArrayLike, omega: ArrayLike, dt: float,
                  gamma: ArrayLike = 0.0) -> NDArray[np.float64]:
    """Drive poses along a circular arc: speed ``v``, turn rate ``omega``, ``dt`` seconds.

    The robot turns by ``phi = omega*dt`` along an arc of length ``s = v*dt``.
    Its displacement is the *chord* of that arc: length ``s*sin(phi/2)/(phi/2)``
    in the direction ``theta + phi/2``. This is PR's equation 5.9 rewritten so
    that ``omega -> 0`` (straight driving) is exact and finite instead of a
    division by zero. A final extra rotation ``gamma*dt`` is added to the
    heading (PR equation 5.13).

    Examples
    --------
    >>> move_velocity([0.0, 0.0, 0.0], 1.0, 0.0, 2.0).round(12)       # straight
    array([2., 0., 0.])
    >>> move_velocity([0.0, 0.0, 0.0], np.pi / 2, np.pi / 2, 1.0).round(12)  # quarter circle, radius 1
    array([1.        , 1.        , 1.57079633])
    """
    p = as_poses(poses)
    dt = check_positive(dt, "dt", "seconds")
    return _move_velocity(p, v, omega, dt, gamma)


def _move_velocity(p: NDArray, v: ArrayLike, omega: ArrayLike, dt: float, gamma: ArrayLike = 0.0) -> NDArray:
    """:func:`move_velocity` without its checks: ``p`` a float pose array, ``dt > 0`` (the lean path)."""
    v, w, g = (np.asarray(a, dtype=float) for a in (v, omega, gamma))
    half = 0.5 * w * dt
    chord = v * dt * np.sinc(half / math.pi)     # np.sinc(x) = sin(pi x)/(pi x)
    c, s = _cos_sin(_wrap_exact(p[..., 2] + half))
    x = p[..., 0] + chord * c
    y = p[..., 1] + chord * s
    th = _wrap_exact(p[..., 2] + (w + g) * dt)
    return np.stack(np.broadcast_arrays(x, y, th), axis=-1)


# ----------------------------------------------------------------------------
# densities of (wrapped) normals
# ----------------------------------------------------------------------------

def _wrap_fast(a: NDArray) -> NDArray:
    """Wrap to [-pi, pi] (the endpoint may survive rounding; fine for densities)."""
    k = np.add(a, math.pi)
    k *= 1.0 / TWO_PI
    k = np.floor(k, out=k) if isinstance(k, np.ndarray) else np.floor(k)
    k *= TWO_PI
    return np.subtract(a, k, out=k) if isinstance(k, np.ndarray) else a - k


#: Headings that are stored are wrapped exactly, to [-pi, pi): the package's one wrap.
_wrap_exact = wrap_angle


def _cos_sin(angle: NDArray) -> tuple[NDArray, NDArray]:
    """cos and sin of angles in [-pi, pi] from one tangent of the half angle.

    ``t = tan(a/2)`` gives ``cos a = (1 - t^2)/(1 + t^2)`` and ``sin a = 2t/(1 + t^2)``
    to within a few units in the last place; numpy's vectorised ``tan`` is
    several times faster than ``cos`` plus ``sin`` on most machines.
    """
    if np.ndim(angle) == 0:
        a = float(angle)
        return np.asarray(math.cos(a)), np.asarray(math.sin(a))
    t = np.multiply(angle, 0.5)
    np.tan(t, out=t)
    t2 = t * t
    inv = t2 + 1.0
    np.reciprocal(inv, out=inv)
    c = np.subtract(1.0, t2, out=t2)
    c *= inv
    t *= 2.0
    t *= inv
    return c, t


def _normal(e: NDArray, s: NDArray) -> NDArray:
    return np.exp(-0.5 * np.square(e / s)) / (s * math.sqrt(TWO_PI))


def _wrapped_normal(e: NDArray, s: NDArray) -> NDArray:
    """Density of a wrapped normal at the wrapped error ``e`` in [-pi, pi]."""
    smax = float(np.max(s)) if np.size(s) else 0.0
    if smax <= _WRAP_SIGMA:
        return _normal(e, s)
    k_max = min(int(math.ceil(3.0 * smax / math.pi)) + 1, 200)
    total = _normal(e, s)
    for k in range(1, k_max + 1):
        total = total + _normal(e + k * TWO_PI, s) + _normal(e - k * TWO_PI, s)
    return total


def _degenerate(stds, names, what: str) -> None:
    for s, name in zip(stds, names):
        if np.any(np.asarray(s) <= 0):
            raise ValueError(
                f"the {what} density is degenerate: the noise standard deviation of {name} is 0 for this "
                "control and these alphas, so the successor poses lie on a lower-dimensional set and have no "
                "density over (x, y, theta). Use positive alphas and a non-zero motion, or pass min_std > 0")


# ----------------------------------------------------------------------------
# the simple forward model
# ----------------------------------------------------------------------------

def sample_forward(poses: ArrayLike, distance: float, sigma_distance: float, sigma_heading: float,
                   rng: np.random.Generator, bias_distance: float = 0.0,
                   bias_heading: float = 0.0) -> NDArray[np.float64]:
    """"Move ``distance`` metres ahead" with Gaussian noise on distance and heading.

    The simplest useful motion model: each pose first turns by a random angle
    ``N(bias_heading, sigma_heading**2)``, then drives
    ``distance + N(bias_distance, sigma_distance**2)`` metres along its new
    heading. Two noise numbers for three coordinates: the final heading always
    equals the direction of travel, which the odometry model's second
    rotation relaxes.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
    distance : float
        Commanded distance in metres (negative drives backwards).
    sigma_distance, sigma_heading : float
        Standard deviations (metres, radians), >= 0.
    rng : numpy.random.Generator
    bias_distance, bias_heading : float
        Means of the two noises (a calibrated robot has 0).

    Returns
    -------
    ndarray, same shape as ``poses``

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> p = sample_forward(np.zeros((10000, 3)), 1.0, 0.05, 0.1, rng)
    >>> round(float(p[:, 0].mean()), 2), round(float(p[:, 2].std()), 2)
    (0.99, 0.1)
    """
    p = as_poses(poses)
    rng = check_rng(rng)
    d = check_number(distance, "distance", "metres")
    sd = check_nonnegative(sigma_distance, "sigma_distance")
    sh = check_nonnegative(sigma_heading, "sigma_heading")
    bd, bh = check_number(bias_distance, "bias_distance", "metres"), check_number(bias_heading, "bias_heading", "radians")
    eps = rng.standard_normal(p.shape[:-1] + (2,))
    heading = p[..., 2] + bh + sh * eps[..., 1]
    dist = d + bd + sd * eps[..., 0]
    out = np.empty_like(p)
    out[..., 0] = p[..., 0] + dist * np.cos(heading)
    out[..., 1] = p[..., 1] + dist * np.sin(heading)
    out[..., 2] = wrap_angle(heading)
    return out


def forward_pdf_xy(xy: ArrayLike, prev_pose: ArrayLike, distance: float, sigma_distance: float,
                   sigma_heading: float) -> NDArray[np.float64]:
    """Density over the new *position* ``(x, y)`` of :func:`sample_forward` (no bias).

    In polar coordinates around the old position the noise is a product of
    two Gaussians, in the distance ``r`` and in the direction; over the plane
    ``dx dy = r dr dphi``, so the density is divided by ``r``. A negative
    distance reaching the same point from the opposite direction is counted
    too. (The heading is not part of the density: it is always the direction
    of travel, so the model has no density over ``(x, y, theta)``.)

    Examples
    --------
    >>> xs = np.linspace(-1, 3, 401)
    >>> X, Y = np.meshgrid(xs, xs - 2.0)
    >>> p = forward_pdf_xy(np.stack([X, Y], -1), [0.0, 0.0, 0.0], 1.0, 0.1, 0.2)
    >>> round(float(p.sum() * 0.01**2), 3)          # integrates to one
    1.0
    """
    q = _check_xy(xy)
    p = as_poses(prev_pose, "prev_pose")
    d = check_number(distance, "distance", "metres")
    sd = check_nonnegative(sigma_distance, "sigma_distance")
    sh = check_nonnegative(sigma_heading, "sigma_heading")
    if sd == 0 or sh == 0:
        raise ValueError("sigma_distance and sigma_heading must be > 0 for a density over (x, y); "
                         f"got {sigma_distance!r}, {sigma_heading!r}")
    dx = q[..., 0] - p[..., 0]
    dy = q[..., 1] - p[..., 1]
    r = np.hypot(dx, dy)
    e_dir = _wrap_fast(np.arctan2(dy, dx) - p[..., 2])
    sh_a, sd_a = np.asarray(sh), np.asarray(sd)
    dens = _wrapped_normal(e_dir, sh_a) * _normal(r - d, sd_a)
    dens = dens + _wrapped_normal(_wrap_fast(e_dir + math.pi), sh_a) * _normal(-r - d, sd_a)
    return dens / np.maximum(r, _MIN_DIST)


# ----------------------------------------------------------------------------
# the odometry model (PR section 5.4)
# ----------------------------------------------------------------------------

def _odometry_setup(u, alphas, noise, min_std, min_trans):
    prev_odom, odom = _odometry_pair(u)
    alphas = check_alphas(alphas, 4)
    min_std = check_nonnegative(min_std, "min_std")
    rot1, trans, rot2 = odometry_to_control(prev_odom, odom, min_trans)
    s1, st, s2 = _stds(odometry_variances(rot1, trans, rot2, alphas, noise), min_std, ("rot1", "trans", "rot2"))
    return (np.asarray(rot1), np.asarray(trans), np.asarray(rot2)), (s1, st, s2)


def sample_odometry(poses: ArrayLike, u: ArrayLike, alphas: ArrayLike, rng: np.random.Generator, *,
                    noise: NoiseSpec = "squared", sign: int = -1, min_std: float = 0.0,
                    min_trans: float = MIN_TRANS) -> NDArray[np.float64]:
    """Draw successor poses from the odometry motion model (PR table 5.6).

    For each pose: perturb the measured ``(rot1, trans, rot2)`` with
    independent zero-mean Gaussian noise whose variances come from
    :func:`odometry_variances`, then apply the perturbed motion.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
        Poses at time t-1 (e.g. ``(N, 3)`` particles).
    u : pair of array_like, each shape (..., 3)
        ``(prev_odom, odom)``: the odometry readings at t-1 and t.
        Usually one pair for all poses; leading axes broadcast with ``poses``.
    alphas : array_like, shape (4,)
        Noise parameters alpha1..alpha4 (>= 0), see :func:`odometry_variances`.
    rng : numpy.random.Generator
    noise : {"squared", "absolute"} or callable
        Variance convention; default PR's squares.
    sign : {-1, +1}
        Subtract the noise from the measured motion (PR table 5.6, default) or
        add it. Same distribution; mirrored samples for the same random numbers.
    min_std : float
        Floor on every noise standard deviation (default 0: pure PR).
    min_trans : float
        See :func:`odometry_to_control`.

    Returns
    -------
    ndarray, shape broadcast(poses, u) with last axis 3
        Successor poses, headings wrapped to ``[-pi, pi)``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    >>> sample_odometry([[0.0, 0.0, 0.0]], u, [0, 0, 0, 0], rng)      # no noise: exact
    array([[1., 0., 0.]])
    >>> p = sample_odometry(np.zeros((100_000, 3)), u, [0.01, 0.0, 0.04, 0.0], rng)
    >>> round(float(p[:, 0].mean()), 2), round(float(p[:, 0].std()), 2)
    (1.0, 0.2)
    """
    p = as_poses(poses)
    rng = check_rng(rng)
    sgn = _check_sign(sign)
    (rot1, trans, rot2), (s1, st, s2) = _odometry_setup(u, alphas, noise, min_std, min_trans)
    ctrl_shape = np.broadcast_shapes(rot1.shape, trans.shape, rot2.shape, s1.shape, st.shape, s2.shape)
    shape = _broadcast_leading("poses", p.shape[:-1], "u", ctrl_shape)
    m = math.prod(shape)
    flat_p = np.broadcast_to(p, shape + (3,)).reshape(m, 3)
    params = [rot1, trans, rot2, s1, st, s2]
    if ctrl_shape != ():
        params = [np.broadcast_to(v, shape).reshape(m) for v in params]
    out = np.empty((m, 3))
    # Work in blocks that fit in the CPU cache: several times faster than
    # whole-array temporaries for 10^6 particles, and the random numbers are
    # drawn in the same order as one big call (and as the readable version).
    block = _BLOCK
    for i in range(0, m, block):
        j = min(i + block, m)
        blk = [v if np.ndim(v) == 0 else v[i:j] for v in params]
        _odometry_block(flat_p[i:j], rng.standard_normal((j - i, 3)), sgn, *blk, out[i:j])
    return out.reshape(shape + (3,))


_BLOCK = 1 << 14


def _odometry_block(p, eps, sgn, rot1, trans, rot2, s1, st, s2, out) -> None:
    """Apply noisy odometry motions to a block of poses, writing into ``out``."""
    if sgn < 0:
        np.negative(eps, out=eps)
    r1 = eps[:, 0]
    r1 *= s1
    r1 += rot1                    # rot1_hat
    t = eps[:, 1]
    t *= st
    t += trans                    # trans_hat
    r2 = eps[:, 2]
    r2 *= s2
    r2 += rot2                    # rot2_hat
    heading = r1 + p[:, 2]        # theta + rot1_hat
    heading = _wrap_exact(heading)
    c, s = _cos_sin(heading)
    c *= t
    c += p[:, 0]
    out[:, 0] = c
    s *= t
    s += p[:, 1]
    out[:, 1] = s
    heading += r2
    out[:, 2] = _wrap_exact(heading)


def odometry_pdf(pose: ArrayLike, u: ArrayLike, prev_pose: ArrayLike, alphas: ArrayLike, *,
                 noise: NoiseSpec = "squared", min_std: float = 0.0,
                 min_trans: float = MIN_TRANS) -> NDArray[np.float64]:
    """Density ``p(pose | u, prev_pose)`` of the odometry model over ``(x, y, theta)``.

    The same distribution that :func:`sample_odometry` draws from. For a
    hypothesised successor ``pose``, recover the motion that leads there
    from ``prev_pose`` (``rot1_hat, trans_hat, rot2_hat``), score its
    difference from the measured motion with the noise densities, and divide
    by ``trans_hat``: the Jacobian of the polar-coordinate map from
    ``(rot1, trans, rot2)`` to ``(x, y, theta)`` (``dx dy dtheta = trans
    drot1 dtrans drot2``). Both ways of reaching the pose (positive
    translation, or negative translation after turning by pi) are counted,
    and the angle noise is wrapped.

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Hypothesised poses at time t.
    u : pair of array_like, each shape (..., 3)
        ``(prev_odom, odom)`` odometry readings.
    prev_pose : array_like, shape (..., 3)
        Poses at time t-1; broadcast with ``pose``.
    alphas : array_like, shape (4,)
    noise, min_std, min_trans
        As in :func:`sample_odometry`.

    Returns
    -------
    ndarray
        Densities in 1/(m^2 rad), shape of the broadcast leading axes.

    Raises
    ------
    ValueError
        If a noise standard deviation is 0 (no density exists; use
        ``min_std``), or on bad shapes, NaNs and negative alphas.

    Examples
    --------
    >>> u = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    >>> a = [0.05, 0.01, 0.01, 0.05]
    >>> float(odometry_pdf([1.0, 0.0, 0.0], u, [0.0, 0.0, 0.0], a).round(4))
    63.4936
    >>> float(odometry_pdf([0.0, 1.0, 0.0], u, [0.0, 0.0, 0.0], a))  # far off
    0.0
    """
    q = as_poses(pose, "pose")
    p = as_poses(prev_pose, "prev_pose")
    (rot1, trans, rot2), (s1, st, s2) = _odometry_setup(u, alphas, noise, min_std, min_trans)
    _degenerate((s1, st, s2), ("rot1", "trans", "rot2"), "odometry")
    pose_shape = _broadcast_leading("pose", q.shape[:-1], "prev_pose", p.shape[:-1])
    ctrl_shape = np.broadcast_shapes(rot1.shape, trans.shape, rot2.shape, s1.shape, st.shape, s2.shape)
    shape = _broadcast_leading("pose and prev_pose", pose_shape, "u", ctrl_shape)
    wrapped = max(float(np.max(s1)), float(np.max(s2))) > _WRAP_SIGMA
    mirror = bool(np.any(trans <= 7.0 * st))   # else the backwards branch is below exp(-24) of the peak
    m = math.prod(shape)
    flat_q = np.broadcast_to(q, shape + (3,)).reshape(m, 3)
    flat_p = np.broadcast_to(p, shape + (3,)).reshape(m, 3)
    params = [rot1, trans, rot2, s1, st, s2]
    if ctrl_shape != ():
        params = [np.broadcast_to(v, shape).reshape(m) for v in params]
    out = np.empty(m)
    for i in range(0, m, _BLOCK):        # cache-sized blocks, as in sample_odometry
        j = min(i + _BLOCK, m)
        blk = [v if np.ndim(v) == 0 else v[i:j] for v in params]
        out[i:j] = _odometry_density_block(flat_q[i:j], flat_p[i:j], *blk, wrapped, mirror)
    return out.reshape(shape) if shape else out[0]


def _odometry_density_block(q, p, rot1, trans, rot2, s1, st, s2, wrapped: bool, mirror: bool):
    """Odometry density of poses ``q`` (M, 3) from ``p`` (M, 3); see :func:`odometry_pdf`."""
    dx = q[:, 0] - p[:, 0]
    dy = q[:, 1] - p[:, 1]
    a = np.arctan2(dy, dx)
    dx *= dx
    dy *= dy
    dx += dy
    d = np.sqrt(dx, out=dx)                          # trans_hat
    e1 = _wrap_fast(a - p[:, 2] - rot1)              # rot1_hat - rot1
    a -= q[:, 2]
    a += rot2
    e2 = _wrap_fast(-a)                              # rot2_hat - rot2 = theta' - a - rot2
    et = d - trans                                   # trans_hat - trans
    norm = 1.0 / (TWO_PI ** 1.5 * s1 * st * s2)
    if wrapped:
        dens = _wrapped_normal(e1, s1) * _normal(et, st) * _wrapped_normal(e2, s2)
    else:
        z = e1 / s1
        z *= z
        et /= st
        et *= et
        z += et
        w = e2 / s2
        w *= w
        z += w
        z *= -0.5
        dens = np.exp(z, out=z)
        dens *= norm
    if mirror:                                       # trans_hat = -d after turning by an extra pi
        e1 += math.pi
        e1m = _wrap_fast(e1)
        e2 -= math.pi
        e2m = _wrap_fast(e2)
        etm = -d - trans
        if wrapped:
            dens += _wrapped_normal(e1m, s1) * _normal(etm, st) * _wrapped_normal(e2m, s2)
        else:
            dens += norm * np.exp(-0.5 * (np.square(e1m / s1) + np.square(etm / st) + np.square(e2m / s2)))
    np.maximum(d, _MIN_DIST, out=d)
    dens /= d
    return dens


def odometry_pdf_xy(xy: ArrayLike, u: ArrayLike, prev_pose: ArrayLike, alphas: ArrayLike, *,
                    noise: NoiseSpec = "squared", min_std: float = 0.0,
                    min_trans: float = MIN_TRANS) -> NDArray[np.float64]:
    """Marginal density of the new *position* ``(x, y)`` under the odometry model.

    :func:`odometry_pdf` with the heading integrated out (exactly: the
    ``rot2`` noise integrates to one), which is what a map of the
    position density shows.

    Examples
    --------
    >>> xs = np.linspace(-0.5, 2.0, 251)
    >>> X, Y = np.meshgrid(xs, xs - 1.25)
    >>> u = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    >>> p = odometry_pdf_xy(np.stack([X, Y], -1), u, [0.0, 0.0, 0.0], [0.05, 0.01, 0.01, 0.05])
    >>> round(float(p.sum() * 0.01**2), 3)
    1.0
    """
    q = _check_xy(xy)
    p = as_poses(prev_pose, "prev_pose")
    (rot1, trans, rot2), (s1, st, s2) = _odometry_setup(u, alphas, noise, min_std, min_trans)
    _degenerate((s1, st), ("rot1", "trans"), "odometry position")
    dx = q[..., 0] - p[..., 0]
    dy = q[..., 1] - p[..., 1]
    d = np.hypot(dx, dy)
    e1 = _wrap_fast(np.arctan2(dy, dx) - p[..., 2] - rot1)
    dens = _wrapped_normal(e1, s1) * _normal(d - trans, st)
    dens = dens + _wrapped_normal(_wrap_fast(e1 + math.pi), s1) * _normal(-d - trans, st)
    return dens / np.maximum(d, _MIN_DIST)


# ----------------------------------------------------------------------------
# the velocity model (PR section 5.3)
# ----------------------------------------------------------------------------

def _velocity_setup(u, dt, alphas, noise, min_std):
    v, w = _velocity_control(u)
    dt = check_positive(dt, "dt", "seconds")
    alphas = check_alphas(alphas, 6)
    min_std = check_nonnegative(min_std, "min_std")
    sv, sw, sg = _stds(_velocity_variances(v, w, alphas, noise), min_std, ("v", "omega", "gamma"))
    return v, w, dt, (sv, sw, sg)


def sample_velocity(poses: ArrayLike, u: ArrayLike, dt: float, alphas: ArrayLike, rng: np.random.Generator, *,
                    noise: NoiseSpec = "squared", sign: int = 1, min_std: float = 0.0) -> NDArray[np.float64]:
    """Draw successor poses from the velocity motion model (PR table 5.3).

    For each pose: perturb ``v`` and ``omega``, draw a final rotation rate
    ``gamma``, drive the arc of :func:`move_velocity` for ``dt`` seconds and
    turn by ``gamma*dt``. Without ``gamma`` every sample would end up facing
    exactly along its arc: a two-dimensional family of poses in a
    three-dimensional space, with no density.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
    u : array_like, shape (..., 2)
        ``(v, omega)`` in m/s and rad/s; leading axes broadcast with ``poses``.
    dt : float
        Duration in seconds, > 0.
    alphas : array_like, shape (6,)
        alpha1..alpha6 (>= 0), see :func:`velocity_variances`.
    rng : numpy.random.Generator
    noise : {"squared", "absolute"} or callable
    sign : {+1, -1}
        Add the noise (PR table 5.3, default) or subtract it.
    min_std : float
        Floor on every noise standard deviation.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> sample_velocity([[0.0, 0.0, 0.0]], (1.0, 0.0), 1.0, np.zeros(6), rng)   # straight, exact
    array([[1., 0., 0.]])
    >>> p = sample_velocity(np.zeros((50_000, 3)), (1.0, 0.5), 1.0, [0.01] * 6, rng)
    >>> p.mean(axis=0).round(2)
    array([0.96, 0.24, 0.5 ])
    """
    p = as_poses(poses)
    rng = check_rng(rng)
    sgn = _check_sign(sign)
    v, w, dt, stds = _velocity_setup(u, dt, alphas, noise, min_std)
    return _sample_velocity(p, v, w, dt, stds, rng, sgn)


def _sample_velocity(p: NDArray, v: NDArray, w: NDArray, dt: float, stds: list, rng: np.random.Generator,
                     sgn: float) -> NDArray[np.float64]:
    """:func:`sample_velocity` after its checks (``p`` poses, ``stds`` from :func:`_stds`): the shared arithmetic."""
    sv, sw, sg = stds
    ctrl_shape = np.broadcast_shapes(v.shape, w.shape, sv.shape, sw.shape, sg.shape)
    shape = _broadcast_leading("poses", p.shape[:-1], "u", ctrl_shape)
    m = math.prod(shape)
    flat_p = np.broadcast_to(p, shape + (3,)).reshape(m, 3)
    params = [v, w, sv, sw, sg]
    if ctrl_shape != ():
        params = [np.broadcast_to(x, shape).reshape(m) for x in params]
    out = np.empty((m, 3))
    for i in range(0, m, _BLOCK):        # cache-sized blocks; same random stream as one big draw
        j = min(i + _BLOCK, m)
        bv, bw, bsv, bsw, bsg = (x if np.ndim(x) == 0 else x[i:j] for x in params)
        eps = rng.standard_normal((j - i, 3))
        if sgn < 0:
            np.negative(eps, out=eps)
        v_hat = eps[:, 0] * bsv + bv
        w_hat = eps[:, 1] * bsw + bw
        g_hat = eps[:, 2] * bsg
        out[i:j] = _move_velocity(flat_p[i:j], v_hat, w_hat, dt, g_hat)
    return out.reshape(shape + (3,))


def velocity_pdf(pose: ArrayLike, u: ArrayLike, prev_pose: ArrayLike, dt: float, alphas: ArrayLike, *,
                 noise: NoiseSpec = "squared", min_std: float = 0.0) -> NDArray[np.float64]:
    """Density ``p(pose | u, prev_pose)`` of the velocity model over ``(x, y, theta)``.

    The same distribution that :func:`sample_velocity` draws from. A circle
    tangent to the old heading passes through the new position; by the
    tangent-chord theorem the arc turns by twice the chord's angle ``psi``
    (``phi = 2*psi``, plus whole turns), and the arc length is the chord
    length divided by ``sin(psi)/psi``. That gives ``v_hat`` and
    ``omega_hat``; the heading left over is ``gamma_hat*dt``. The density of
    these three noises is divided by the Jacobian
    ``dt**3 * chord * |sin(psi)/psi| / 2``. Straight motion (``psi = 0``) is
    the regular limit of the same formula, not a special case.

    Parameters
    ----------
    pose, prev_pose : array_like, shape (..., 3)
    u : array_like, shape (..., 2)
        ``(v, omega)``.
    dt : float
        > 0 seconds.
    alphas : array_like, shape (6,)
    noise, min_std
        As in :func:`sample_velocity`.

    Examples
    --------
    >>> a = [0.01, 0.01, 0.01, 0.01, 0.01, 0.01]
    >>> p = velocity_pdf([[1.0, 0.0, 0.0], [1.0, 0.3, 0.0]], (1.0, 0.0), [0.0, 0.0, 0.0], 1.0, a)
    >>> p.round(4)
    array([126.9873,   0.    ])
    """
    q = as_poses(pose, "pose")
    p = as_poses(prev_pose, "prev_pose")
    v, w, dt, (sv, sw, sg) = _velocity_setup(u, dt, alphas, noise, min_std)
    _degenerate((sv, sw, sg), ("v", "omega", "gamma"), "velocity")
    _broadcast_leading("pose", q.shape[:-1], "prev_pose", p.shape[:-1])
    c0, s0 = np.cos(p[..., 2]), np.sin(p[..., 2])
    dxw = q[..., 0] - p[..., 0]
    dyw = q[..., 1] - p[..., 1]
    lx = c0 * dxw + s0 * dyw                 # displacement in the old robot frame
    ly = -s0 * dxw + c0 * dyw
    chord = np.hypot(lx, ly)
    psi0 = np.arctan2(ly, lx)                # chord angle = half the turn
    dth = q[..., 2] - p[..., 2]
    j_star = np.round((0.5 * w * dt - psi0) / math.pi)   # branch nearest the commanded turn
    chord_safe = np.maximum(chord, _MIN_DIST)
    total = np.zeros(np.broadcast_shapes(psi0.shape, np.shape(w), np.shape(sv)))
    # the neighbouring branches differ from the commanded turn by at least pi:
    # negligible (below 3e-9 of the peak) unless the turn noise is large
    wide = float(np.max(sw)) * dt > _WRAP_SIGMA
    for dj in ((-1.0, 0.0, 1.0) if wide else (0.0,)):
        j = j_star + dj
        psi = psi0 + math.pi * j
        sc = np.sinc(psi / math.pi)                      # sin(psi)/psi
        ok = np.abs(sc) > _TINY
        sc_safe = np.where(ok, sc, 1.0)
        ell = np.where(np.remainder(j, 2.0) == 0, chord, -chord)
        v_hat = ell / sc_safe / dt
        w_hat = 2.0 * psi / dt
        g_err = _wrap_fast(dth - 2.0 * psi) / dt         # gamma_hat (nearest image)
        dens = _normal(v_hat - v, sv) * _normal(w_hat - w, sw) * _wrapped_normal(g_err * dt, sg * dt) * dt
        jac = dt ** 3 * chord_safe * np.abs(sc_safe) / 2.0
        total = total + np.where(ok, dens / jac, 0.0)
    return total[()] if total.ndim == 0 else total


# ----------------------------------------------------------------------------
# particle movers: a model with its parameters, called as motion(poses, u, rng)
# ----------------------------------------------------------------------------

class OdometryMotion:
    """The odometry motion model as a particle mover: ``motion(poses, u, rng)``.

    Wraps :func:`sample_odometry`; ``u = (prev_odom, odom)`` is the pair of
    odometry readings (PR table 5.6). ``alphas`` are the four noise
    parameters of PR, entering as variances ``alpha1*rot1**2 +
    alpha2*trans**2`` and so on. Keyword options (such as ``min_std``, a floor
    on the noise that keeps a standing robot's particles from collapsing) go
    to :func:`sample_odometry`. :class:`localize.mcl.MCL` takes any such
    callable as its ``motion``.

    **Pass the alphas of your robot.** The default ``(0.005, 0.005, 0.01,
    0.005)`` is a generic placeholder and is *not* the noise of the book's
    simulated robot, :data:`localize.sim.DEFAULT_ODOMETRY_ALPHAS` ``= (0.02,
    0.0005, 0.02, 0.0005)``: with the default, a filter would assume a quarter
    of the simulated robot's rotation noise (``alpha1``) and ten times its
    rotation-from-translation noise (``alpha2``). For a simulated run use
    ``OdometryMotion(run.alphas)``, the alphas its odometry was drawn with (as
    every chapter does); for a real robot, calibrate them (chapter 4,
    exercise 3) and inflate them a little rather than trust them exactly.

    Examples
    --------
    >>> from localize import sim
    >>> OdometryMotion().alphas.tolist() == list(sim.DEFAULT_ODOMETRY_ALPHAS)   # the default is not the simulator's
    False
    >>> move = OdometryMotion((0.0, 0.0, 0.0, 0.0))          # noise-free
    >>> p = move(np.zeros((2, 3)), ([0, 0, 0], [1, 0, 0]), np.random.default_rng(0))
    >>> p.round(6)
    array([[1., 0., 0.],
           [1., 0., 0.]])
    """

    def __init__(self, alphas: ArrayLike = (0.005, 0.005, 0.01, 0.005), **options) -> None:
        self.alphas = check_alphas(alphas, 4)
        self.options = options          # passed on: noise=, min_std=, ... (see sample_odometry)

    def __call__(self, poses: NDArray[np.float64], u, rng: np.random.Generator) -> NDArray[np.float64]:
        return sample_odometry(poses, u, self.alphas, rng, **self.options)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(alphas={tuple(round(float(a), 6) for a in self.alphas)})"


def _on_the_spot_noise(noise: NoiseSpec) -> Callable:
    """``noise`` (a :func:`odometry_variances` spec) for a step counted as a turn on the spot: the variances of
    ``rot1 = 0``, the same translation and ``rot2`` the whole turn, whatever ``rot1`` the step's direction gives."""
    def variances(rot1, trans, rot2, alphas):
        return odometry_variances(0.0, trans, wrap_angle(np.asarray(rot1) + rot2), alphas, noise)
    return variances


class ReversibleOdometry(OdometryMotion):
    """The odometry motion model (PR table 5.6) made safe for backward and on-the-spot motion.

    The textbook model explains every motion as "turn towards the destination,
    drive forward, turn". A robot that turns on the spot while its odometry
    creeps a centimetre *backwards* then gets ``rot1`` near +-180 degrees, and
    since the noise grows with ``rot1**2`` its particles scatter over metres.
    Real logs are full of such steps (the Intel log's very first scans). The
    fix used by ROS AMCL and others: a motion that goes backwards is the
    forward motion of a robot facing the other way. Both odometry poses and
    the particles are turned by 180 degrees, moved with the ordinary model,
    and turned back. Forward motions are passed to :func:`sample_odometry`
    unchanged. A step whose translation is within the translation noise of a
    turn on the spot (:meth:`on_the_spot`) gets the noise of a turn on the
    spot, not that of a turn of up to 90 degrees towards the direction of a
    creep of a few millimetres.

    Examples
    --------
    >>> back = ([0.0, 0.0, 0.0], [-0.02, 0.0, 0.5])      # creep back 2 cm while turning
    >>> rng = np.random.default_rng(0)
    >>> p = ReversibleOdometry((0.05, 0.05, 0.1, 0.05))(np.zeros((5000, 3)), back, rng)
    >>> bool(np.abs(p[:, 0].mean() + 0.02) < 0.005), bool(p[:, :2].std(axis=0).max() < 0.2)
    (True, True)
    >>> q = sample_odometry(np.zeros((5000, 3)), back, (0.05, 0.05, 0.1, 0.05), rng)   # the plain model
    >>> bool(q[:, :2].std(axis=0).max() > 0.4)                                         # scatters them
    True
    """

    def __init__(self, alphas: ArrayLike, min_trans: float = 1e-3) -> None:
        super().__init__(alphas, min_trans=check_nonnegative(min_trans, "min_trans", "metres"))
        self.min_trans = self.options["min_trans"]

    def __call__(self, poses: NDArray[np.float64], u, rng: np.random.Generator) -> NDArray[np.float64]:
        p0, p1 = _odometry_pair(u)
        step = relative(p0, p1)
        trans = math.hypot(step[0], step[1])
        options = self.options
        if trans > self.min_trans and trans <= self.on_the_spot(trans, float(step[2])):
            # the step as measured, with the noise of a turn on the spot
            options = {**options, "noise": _on_the_spot_noise(options.get("noise", "squared"))}
        if step[0] < 0 and trans > self.min_trans:
            flip = np.array([0.0, 0.0, math.pi])
            q = np.array(poses, dtype=float, copy=True)
            q[:, 2] += math.pi
            out = sample_odometry(q, (p0 + flip, p1 + flip), self.alphas, rng, **options)
            out[:, 2] = wrap_angle(out[:, 2] - math.pi)
            return out
        return sample_odometry(poses, (p0, p1), self.alphas, rng, **options)

    def on_the_spot(self, trans: float, turn: float) -> float:
        """The translation noise (metres, a standard deviation) of a turn on the spot by ``turn`` with ``trans``.

        A step whose translation ``trans`` is at most this counts as a turn on
        the spot. The value is the standard deviation of the translation noise
        that the model gives a turn on the spot of ``turn`` radians with a
        translation of ``trans`` (``sqrt(alpha3*trans**2 + alpha4*turn**2)``
        with the default noise): a translation that short is lost in that noise anyway, so its
        direction says nothing about how much the robot turned. Such a step
        moves the particles as measured, with the noise of a turn on the spot
        (``rot1 = 0``, ``rot2`` the whole turn). Decomposed as "turn towards
        the destination, drive, turn", it would make ``rot1`` up to 90 degrees
        (a robot whose odometry point lies a few centimetres off its axis
        creeps sideways while it turns), and the noise, which grows with
        ``rot1**2 + rot2**2``, would scatter the particles by half a metre at
        every step of a turn that moved them by millimetres. (ROS AMCL counts
        steps under a fixed 0.01 m as turns on the spot.)

        Examples
        --------
        >>> m = ReversibleOdometry((0.05, 0.01, 0.02, 0.05))
        >>> round(m.on_the_spot(0.005, 0.12), 4)       # 5 mm of creep while turning 7 degrees: on the spot
        0.0268
        >>> round(m.on_the_spot(0.5, 0.0), 4)          # half a metre straight ahead: a drive
        0.0707
        """
        noise = self.options.get("noise", "squared")
        var = odometry_variances(0.0, trans, turn, self.alphas, noise)[1]
        return float(np.sqrt(max(float(var), 0.0)))


class VelocityMotion:
    """The velocity motion model as a particle mover: ``motion(poses, (v, omega), rng)``.

    Wraps :func:`sample_velocity` with a fixed time step ``dt`` and the six
    ``alphas`` of PR table 5.3.

    Examples
    --------
    >>> VelocityMotion((0.1,) * 6, dt=0.5).dt
    0.5
    """

    def __init__(self, alphas: ArrayLike, dt: float, **options) -> None:
        self.alphas = check_alphas(alphas, 6)
        self.dt = check_positive(dt, "dt", "seconds")
        self.options = options
        # the options are checked once, here, and each call takes the lean path (the same numbers as
        # sample_velocity, which checks everything at every call); an unknown option is left to it
        self._lean = set(options) <= {"noise", "sign", "min_std"}
        if self._lean:
            self._noise = options.get("noise", "squared")
            self._sign = _check_sign(options.get("sign", 1))
            self._min_std = check_nonnegative(options.get("min_std", 0.0), "min_std")

    def __call__(self, poses: NDArray[np.float64], u, rng: np.random.Generator) -> NDArray[np.float64]:
        if not self._lean:
            return sample_velocity(poses, u, self.dt, self.alphas, rng, **self.options)
        p = as_poses(poses)
        rng = check_rng(rng)
        v, w = _velocity_control(u)
        stds = _stds(_velocity_variances(v, w, self.alphas, self._noise), self._min_std, ("v", "omega", "gamma"))
        return _sample_velocity(p, v, w, self.dt, stds, rng, self._sign)

    def __repr__(self) -> str:
        return f"VelocityMotion(alphas={tuple(round(float(a), 6) for a in self.alphas)}, dt={self.dt:g})"


# ----------------------------------------------------------------------------
# readable versions (test oracles): one pose at a time, like the pseudocode
# ----------------------------------------------------------------------------

def _sample(variance: float, z: float) -> float:
    """PR's ``sample(b)``: a zero-mean normal with variance b, from a standard normal z."""
    return math.sqrt(variance) * z


def _prob(a: float, variance: float) -> float:
    """PR's ``prob(a, b)``: zero-mean normal density with variance b at a."""
    return math.exp(-0.5 * a * a / variance) / math.sqrt(TWO_PI * variance)


def _prob_angle(a: float, variance: float) -> float:
    """Wrapped-normal density: ``prob`` summed over a +- 2 pi k."""
    a = float(wrap_angle(a))
    k_max = int(math.ceil(3.0 * math.sqrt(variance) / math.pi)) + 1
    return sum(_prob(a + TWO_PI * k, variance) for k in range(-k_max, k_max + 1))


def sample_motion_model_odometry(pose: ArrayLike, u: ArrayLike, alphas: ArrayLike, rng: np.random.Generator,
                                 noise: NoiseSpec = "squared", sign: int = -1) -> NDArray[np.float64]:
    """PR table 5.6, one pose, line by line (the oracle of :func:`sample_odometry`).

    Draws its three random numbers in the same order as :func:`sample_odometry`,
    so with equal generators both return the same poses.

    Examples
    --------
    >>> u = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    >>> a = [0.1, 0.01, 0.01, 0.1]
    >>> s1 = sample_motion_model_odometry([0, 0, 0], u, a, np.random.default_rng(3))
    >>> s2 = sample_odometry([[0, 0, 0]], u, a, np.random.default_rng(3))[0]
    >>> bool(np.allclose(s1, s2))
    True
    """
    x, y, theta = (float(c) for c in as_poses(pose, "pose").reshape(3))
    (xb, yb, thb), (xb2, yb2, thb2) = (tuple(float(c) for c in q.reshape(3)) for q in _odometry_pair(u))
    z = check_rng(rng).standard_normal(3)
    # lines 2-4: the measured motion
    trans = math.hypot(xb2 - xb, yb2 - yb)
    rot1 = float(wrap_angle(math.atan2(yb2 - yb, xb2 - xb) - thb)) if trans > MIN_TRANS else 0.0
    rot2 = float(wrap_angle(thb2 - thb - rot1))
    v1, vt, v2 = (float(np.asarray(var)) for var in odometry_variances(rot1, trans, rot2, alphas, noise))
    # lines 5-7: the true motion is the measured one minus (or plus) noise
    rot1_hat = rot1 + sign * _sample(v1, z[0])
    trans_hat = trans + sign * _sample(vt, z[1])
    rot2_hat = rot2 + sign * _sample(v2, z[2])
    # lines 8-10: apply it
    x_new = x + trans_hat * math.cos(theta + rot1_hat)
    y_new = y + trans_hat * math.sin(theta + rot1_hat)
    theta_new = float(wrap_angle(theta + rot1_hat + rot2_hat))
    return np.array([x_new, y_new, theta_new])


def motion_model_odometry(pose: ArrayLike, u: ArrayLike, prev_pose: ArrayLike, alphas: ArrayLike,
                          noise: NoiseSpec = "squared") -> float:
    """PR table 5.5, corrected to be the density of table 5.6, one pose at a time.

    Differences from the printed table, each needed for ``sampler == density``:
    variances from the *measured* motion; division by ``trans_hat`` (the
    Jacobian); wrapped angle errors; and the mirror branch (negative
    translation) added.

    Examples
    --------
    >>> u = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    >>> round(motion_model_odometry([1.0, 0.0, 0.0], u, [0, 0, 0], [0.05, 0.01, 0.01, 0.05]), 4)
    63.4936
    """
    x2, y2, th2 = (float(c) for c in as_poses(pose, "pose").reshape(3))
    x, y, theta = (float(c) for c in as_poses(prev_pose, "prev_pose").reshape(3))
    (xb, yb, thb), (xb2, yb2, thb2) = (tuple(float(c) for c in q.reshape(3)) for q in _odometry_pair(u))
    # lines 2-4: the measured motion
    trans = math.hypot(xb2 - xb, yb2 - yb)
    rot1 = math.atan2(yb2 - yb, xb2 - xb) - thb if trans > MIN_TRANS else 0.0
    rot1 = float(wrap_angle(rot1))
    rot2 = float(wrap_angle(thb2 - thb - rot1))
    v1, vt, v2 = (float(np.asarray(var)) for var in odometry_variances(rot1, trans, rot2, alphas, noise))
    if min(v1, vt, v2) <= 0:
        raise ValueError("the odometry density is degenerate: a noise variance is 0")
    # lines 5-7: the motion that would lead from prev_pose to pose
    trans_hat = math.hypot(x2 - x, y2 - y)
    rot1_hat = math.atan2(y2 - y, x2 - x) - theta
    rot2_hat = th2 - theta - rot1_hat
    total = 0.0
    for branch in (+1, -1):              # reach the point forwards, or backwards after a half turn
        if branch == -1:
            rot1_hat, trans_hat, rot2_hat = rot1_hat + math.pi, -trans_hat, rot2_hat - math.pi
        # lines 8-10, with the sampler's variances
        p1 = _prob_angle(rot1_hat - rot1, v1)
        p2 = _prob(trans_hat - trans, vt)
        p3 = _prob_angle(rot2_hat - rot2, v2)
        total += p1 * p2 * p3
    return total / max(abs(trans_hat), _MIN_DIST)   # the Jacobian of (rot1, trans, rot2) -> (x, y, theta)


def sample_motion_model_velocity(pose: ArrayLike, u: ArrayLike, dt: float, alphas: ArrayLike,
                                 rng: np.random.Generator, noise: NoiseSpec = "squared",
                                 sign: int = 1) -> NDArray[np.float64]:
    """PR table 5.3, one pose, line by line (the oracle of :func:`sample_velocity`).

    Uses the book's ``v/omega`` form, with straight driving as a separate case.

    Examples
    --------
    >>> a = [0.01] * 6
    >>> s1 = sample_motion_model_velocity([0, 0, 0], (1.0, 0.5), 1.0, a, np.random.default_rng(3))
    >>> s2 = sample_velocity([[0, 0, 0]], (1.0, 0.5), 1.0, a, np.random.default_rng(3))[0]
    >>> bool(np.allclose(s1, s2))
    True
    """
    x, y, theta = (float(c) for c in as_poses(pose, "pose").reshape(3))
    v, w = (float(c) for c in np.asarray(u, dtype=float).reshape(2))
    dt = check_positive(dt, "dt", "seconds")
    z = check_rng(rng).standard_normal(3)
    var_v, var_w, var_g = (float(np.asarray(var)) for var in velocity_variances(v, w, alphas, noise))
    v_hat = v + sign * _sample(var_v, z[0])
    w_hat = w + sign * _sample(var_w, z[1])
    g_hat = sign * _sample(var_g, z[2])
    if abs(w_hat) > _STRAIGHT:
        r = v_hat / w_hat
        x_new = x - r * math.sin(theta) + r * math.sin(theta + w_hat * dt)
        y_new = y + r * math.cos(theta) - r * math.cos(theta + w_hat * dt)
    else:                                # straight line: the limit omega -> 0
        x_new = x + v_hat * dt * math.cos(theta)
        y_new = y + v_hat * dt * math.sin(theta)
    theta_new = float(wrap_angle(theta + w_hat * dt + g_hat * dt))
    return np.array([x_new, y_new, theta_new])


def motion_model_velocity(pose: ArrayLike, u: ArrayLike, prev_pose: ArrayLike, dt: float, alphas: ArrayLike,
                          noise: NoiseSpec = "squared") -> float:
    """PR table 5.1, corrected to be the density of table 5.3, one pose at a time.

    Finds the circle through both positions tangent to the old heading
    (``mu``, centre ``(x*, y*)``), the turn ``dtheta`` around it and the
    implied ``v_hat, omega_hat, gamma_hat``. Departures from the printed
    table: the radius carries a sign (a right turn has ``v_hat > 0``), the
    turn is taken as the one nearest the commanded ``omega*dt`` (and its two
    neighbours are added), the final rotation error is wrapped, and the
    result is divided by the Jacobian ``dt**3 |v_hat dt| (1 - cos phi)/phi**2``.

    Examples
    --------
    >>> a = [0.01] * 6
    >>> round(motion_model_velocity([1.0, 0.0, 0.0], (1.0, 0.0), [0, 0, 0], 1.0, a), 4)
    126.9873
    """
    x2, y2, th2 = (float(c) for c in as_poses(pose, "pose").reshape(3))
    x, y, theta = (float(c) for c in as_poses(prev_pose, "prev_pose").reshape(3))
    v, w = (float(c) for c in np.asarray(u, dtype=float).reshape(2))
    dt = check_positive(dt, "dt", "seconds")
    var_v, var_w, var_g = (float(np.asarray(var)) for var in velocity_variances(v, w, alphas, noise))
    if min(var_v, var_w, var_g) <= 0:
        raise ValueError("the velocity density is degenerate: a noise variance is 0")
    denom = (y - y2) * math.cos(theta) - (x - x2) * math.sin(theta)
    chord = math.hypot(x2 - x, y2 - y)
    along = (x2 - x) * math.cos(theta) + (y2 - y) * math.sin(theta)
    if abs(denom) < _TINY * max(chord, 1e-300):
        # straight ahead or behind: a circle of infinite radius
        candidates = [(along / dt, 0.0)] + [(math.nan, k * TWO_PI / dt) for k in (-1, 1)]
    else:
        mu = 0.5 * ((x - x2) * math.cos(theta) + (y - y2) * math.sin(theta)) / denom
        xs = 0.5 * (x + x2) + mu * (y - y2)
        ys = 0.5 * (y + y2) + mu * (x2 - x)
        r_signed = -(xs - x) * math.sin(theta) + (ys - y) * math.cos(theta)   # > 0: centre on the left
        dtheta = math.atan2(y2 - ys, x2 - xs) - math.atan2(y - ys, x - xs)
        dtheta = float(wrap_angle(dtheta))
        k0 = round((w * dt - dtheta) / TWO_PI)
        candidates = []
        for k in (k0 - 1, k0, k0 + 1):
            phi = dtheta + k * TWO_PI
            candidates.append((phi / dt * r_signed, phi / dt))
    total = 0.0
    for v_hat, w_hat in candidates:
        if math.isnan(v_hat):
            continue                                 # a full circle cannot end away from the start
        phi = w_hat * dt
        gamma_hat = float(wrap_angle(th2 - theta - phi)) / dt
        p = _prob(v - v_hat, var_v) * _prob(w - w_hat, var_w) * _prob_angle(gamma_hat * dt, var_g * dt * dt) * dt
        if abs(phi) > _STRAIGHT:
            shape = (1.0 - math.cos(phi)) / (phi * phi)
        else:
            shape = 0.5
        jac = dt ** 3 * abs(v_hat * dt) * shape
        if jac > 0:
            total += p / max(jac, 1e-300)
    return total


def odometry_pair(u: object) -> tuple[NDArray, NDArray] | None:
    """``(prev, cur)`` if ``u`` is a pair of odometry poses, else None.

    Examples
    --------
    >>> odometry_pair(([0, 0, 0], [1, 0, 0]))[1]
    array([1., 0., 0.])
    >>> odometry_pair(0.5) is None
    True
    """
    if isinstance(u, tuple) and len(u) == 2:
        a, b = np.asarray(u[0], dtype=float), np.asarray(u[1], dtype=float)
        if a.shape == (3,) and b.shape == (3,):
            return a, b
    return None
