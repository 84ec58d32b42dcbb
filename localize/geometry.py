"""Angles and planar poses.

A pose is an array whose last axis holds ``(x, y, theta)`` in metres and
radians; every function here is vectorised over the leading axes, so one call
handles one pose, ``N`` particles (an ``(N, 3)`` array) or a batch of batches.
Angles are wrapped to the half-open interval ``[-pi, pi)``.

The composition operator follows the usual convention of the robotics
literature (Smith, Self and Cheeseman 1990; Thrun, Burgard and Fox,
*Probabilistic Robotics*, 2005): ``compose(a, b)`` is the pose ``b``, expressed
in the frame of ``a``, brought into the frame in which ``a`` is expressed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "wrap_angle",
    "angle_diff",
    "as_poses",
    "compose",
    "inverse",
    "relative",
    "transform_points",
    "circular_mean",
    "circular_std",
    "mean_pose",
    "yaw_to_quaternion",
    "quaternion_to_yaw",
]

TWO_PI = 2.0 * np.pi
#: The floor of the mean resultant length in :func:`circular_std`, which takes its logarithm.
_TINY = 1e-300


def wrap_angle(angle: ArrayLike, exact: bool = True) -> NDArray[np.float64] | float:
    """Wrap angles to the half-open interval ``[-pi, pi)``.

    The one angle wrap of the package: the motion models, the sensor models
    and the Kalman filters all call it.

    Parameters
    ----------
    angle : array_like
        Angles in radians, any shape.
    exact : bool
        ``True`` (default): the result lies in ``[-pi, pi)`` without
        exception, and an angle already inside is returned bit for bit (so
        wrapping twice changes nothing). ``False``: only the formula
        ``a - 2 pi floor((a + pi) / 2 pi)``, a little faster on big arrays; its
        result may land on ``+pi``, or one ulp beyond either end, and an angle
        one ulp below ``+pi`` comes back near ``-pi``. Good enough inside a
        periodic function (a density, a cosine); not for a heading that is
        stored and compared (re-wrapping it must change nothing, and ``+pi``
        and ``-pi`` must not be two headings).

    Returns
    -------
    float or ndarray
        The same angles, shifted by multiples of ``2*pi`` into ``[-pi, pi)``.
        A Python float (or 0-d input) gives a float back; NaN and infinities
        give NaN.

    Examples
    --------
    >>> from localize import wrap_angle
    >>> float(wrap_angle(3 * np.pi / 2))
    -1.5707963267948966
    >>> float(wrap_angle(np.pi))   # +pi maps to -pi: the interval is half-open
    -3.141592653589793
    """
    a = np.asarray(angle, dtype=float)
    if a.ndim == 0:
        return _wrap_scalar(float(a), exact)
    w = a + np.pi
    w *= 1.0 / TWO_PI
    np.floor(w, out=w)
    w *= -TWO_PI
    w += a                       # a - 2 pi k: in [-pi, pi] up to one rounding
    if exact:
        # Only values on or beyond an end need a second look (rare): fold what
        # rounding left outside, and give back inputs that were already inside
        # (the shift by pi and back rounds those within one ulp of +pi to -pi).
        out = (w <= -np.pi) | (w >= np.pi)
        if out.any():
            edge = np.flatnonzero(out)
            flat, src = w.reshape(-1), a.reshape(-1)
            e, s = flat[edge], src[edge]
            e[e >= np.pi] -= TWO_PI
            e[e < -np.pi] += TWO_PI
            inside = (s >= -np.pi) & (s < np.pi)
            e[inside] = s[inside]
            flat[edge] = e
    return w


def _wrap_scalar(a: float, exact: bool) -> float:
    """:func:`wrap_angle` of one float, without numpy's per-call overhead."""
    if exact and -math.pi <= a < math.pi:
        return a
    if not math.isfinite(a):
        return math.nan
    w = a - TWO_PI * math.floor((a + math.pi) / TWO_PI)
    if exact:
        if w >= math.pi:
            w -= TWO_PI
        elif w < -math.pi:
            w += TWO_PI
    return w


def angle_diff(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64] | float:
    """Signed smallest difference ``a - b`` of two angles, in ``[-pi, pi)``.

    Examples
    --------
    >>> round(float(angle_diff(np.radians(-179), np.radians(179))), 6)
    0.034907
    """
    return wrap_angle(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))


def as_poses(poses: ArrayLike, name: str = "poses") -> NDArray[np.float64]:
    """Convert to a float array of poses, checking the last axis has length 3.

    Raises ``ValueError`` naming the argument when the shape is wrong or a
    value is NaN or infinite.

    Examples
    --------
    >>> as_poses([1, 2, 0]).shape
    (3,)
    >>> as_poses([[1, 2]])
    Traceback (most recent call last):
    ...
    ValueError: poses must have shape (..., 3) holding (x, y, theta); got shape (1, 2)
    """
    p = np.asarray(poses, dtype=float)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ValueError(
            f"{name} must have shape (..., 3) holding (x, y, theta); got shape {p.shape}"
        )
    if not np.all(np.isfinite(p)):
        bad = np.argwhere(~np.isfinite(p))[0]
        raise ValueError(
            f"{name} contains NaN or infinite values (first at index {tuple(int(i) for i in bad)})"
        )
    return p


def compose(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Compose poses: ``a ⊕ b``.

    ``b`` is a pose expressed in the frame of ``a``; the result is the same
    pose expressed in the frame in which ``a`` is given. Broadcasts over
    leading axes.

    Examples
    --------
    >>> compose([1.0, 0.0, np.pi / 2], [1.0, 0.0, 0.0]).round(12)
    array([1.        , 1.        , 1.57079633])
    """
    a = as_poses(a, "a")
    b = as_poses(b, "b")
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    th = wrap_angle(a[..., 2] + b[..., 2])
    return np.stack(np.broadcast_arrays(x, y, th), axis=-1)


def inverse(p: ArrayLike) -> NDArray[np.float64]:
    """Inverse pose ``⊖p``, so that ``compose(p, inverse(p))`` is the identity.

    Examples
    --------
    >>> p = np.array([2.0, -1.0, 0.3])
    >>> np.allclose(compose(p, inverse(p)), 0.0)
    True
    """
    p = as_poses(p, "p")
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = -c * p[..., 0] - s * p[..., 1]
    y = s * p[..., 0] - c * p[..., 1]
    th = wrap_angle(-p[..., 2])
    return np.stack([x, y, np.broadcast_to(th, x.shape)], axis=-1)


def relative(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Pose of ``b`` seen from ``a``: ``⊖a ⊕ b``.

    This is how two odometry readings become a motion in the robot's frame.

    Examples
    --------
    >>> relative([1.0, 1.0, np.pi / 2], [1.0, 2.0, np.pi / 2]).round(12)
    array([1., 0., 0.])
    """
    return compose(inverse(a), b)


def transform_points(pose: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Map points from a pose's local frame into the frame the pose is given in.

    Parameters
    ----------
    pose : array_like, shape (..., 3)
    points : array_like, shape (..., 2)
        Local coordinates; leading axes broadcast against ``pose``'s.

    Examples
    --------
    >>> transform_points([1.0, 2.0, np.pi], [[1.0, 0.0]]).round(12)
    array([[0., 2.]])
    """
    pose = as_poses(pose, "pose")
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 0 or pts.shape[-1] != 2:
        raise ValueError(f"points must have shape (..., 2); got shape {pts.shape}")
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    x = pose[..., 0] + c * pts[..., 0] - s * pts[..., 1]
    y = pose[..., 1] + s * pts[..., 0] + c * pts[..., 1]
    return np.stack(np.broadcast_arrays(x, y), axis=-1)


def _weights(weights: ArrayLike | None, n: int, axis_len_name: str = "angles") -> NDArray | None:
    if weights is None:
        return None
    w = np.asarray(weights, dtype=float)
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise ValueError("weights must be finite and non-negative")
    if w.sum() <= 0:
        raise ValueError("weights sum to zero; at least one weight must be positive")
    return w


def circular_mean(
    angles: ArrayLike, weights: ArrayLike | None = None, axis: int = -1
) -> NDArray[np.float64] | float:
    """Mean direction of angles: the angle of the (weighted) mean unit vector.

    Averaging angles arithmetically fails across the ±pi seam (the mean of
    179° and -179° is 180°, not 0°); averaging unit vectors does not.

    Parameters
    ----------
    angles : array_like
    weights : array_like, optional
        Non-negative weights broadcastable to ``angles`` (need not sum to 1).
    axis : int
        Axis to average over.

    Examples
    --------
    >>> round(abs(float(circular_mean(np.radians([179.0, -179.0])))), 6)
    3.141593
    """
    s, c, _ = _sin_cos_sums(angles, weights, axis)
    return wrap_angle(np.arctan2(s, c))


def _sin_cos_sums(angles: ArrayLike, weights: ArrayLike | None, axis: int):
    """Weighted sums of the angles' sines and cosines, and the total weight (means and 1 when unweighted)."""
    a = np.asarray(angles, dtype=float)
    w = _weights(weights, a.shape[axis] if a.ndim else 1)
    if w is None:
        return np.sin(a).mean(axis=axis), np.cos(a).mean(axis=axis), None
    w = np.broadcast_to(w, a.shape)
    return (w * np.sin(a)).sum(axis=axis), (w * np.cos(a)).sum(axis=axis), w.sum(axis=axis)


def circular_std(
    angles: ArrayLike, weights: ArrayLike | None = None, axis: int = -1
) -> NDArray[np.float64] | float:
    """Circular standard deviation ``sqrt(-2 ln R)``, R the mean resultant length.

    For tightly concentrated angles it matches the ordinary standard
    deviation; it grows without bound as the angles spread round the circle
    (Mardia and Jupp, *Directional Statistics*, 2000, eq. 2.3.11).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> a = rng.normal(3.1, 0.05, size=100_000)   # straddles the seam
    >>> round(float(circular_std(a)), 3)
    0.05
    """
    s, c, tot = _sin_cos_sums(angles, weights, axis)
    if tot is not None:
        s, c = s / tot, c / tot
    r = np.clip(np.hypot(s, c), _TINY, 1.0)   # R = 0 (angles spread evenly) would give log(0)
    out = np.sqrt(-2.0 * np.log(r))
    return float(out) if np.ndim(out) == 0 else out


def mean_pose(poses: ArrayLike, weights: ArrayLike | None = None) -> NDArray[np.float64]:
    """Weighted mean of ``(N, 3)`` poses: arithmetic in x, y and circular in theta.

    Examples
    --------
    >>> mean_pose([[0, 0, np.pi - 0.1], [2, 0, -np.pi + 0.1]]).round(6)
    array([ 1.      ,  0.      , -3.141593])
    """
    p = as_poses(poses)
    if p.ndim != 2:
        raise ValueError(f"poses must be an (N, 3) array; got shape {p.shape}")
    if p.shape[0] == 0:
        raise ValueError("poses is empty; need at least one pose to average")
    w = _weights(weights, p.shape[0])
    if w is not None and w.shape != (p.shape[0],):
        raise ValueError(f"weights must have shape ({p.shape[0]},); got {w.shape}")
    xy = np.average(p[:, :2], axis=0, weights=w)
    th = circular_mean(p[:, 2], weights=w)
    return np.array([xy[0], xy[1], th])


# ------------------------------------------------------------ quaternions (ROS messages, TUM files)
def yaw_to_quaternion(theta: ArrayLike) -> NDArray[np.float64]:
    """Quaternions ``(qx, qy, qz, qw)`` of rotations by ``theta`` about z, shape ``(..., 4)``.

    Examples
    --------
    >>> yaw_to_quaternion(np.pi / 2).round(6)
    array([0.      , 0.      , 0.707107, 0.707107])
    """
    t = np.asarray(theta, dtype=float)
    out = np.zeros(t.shape + (4,))
    out[..., 2] = np.sin(t / 2)
    out[..., 3] = np.cos(t / 2)
    return out


def quaternion_to_yaw(q: ArrayLike) -> NDArray[np.float64]:
    """Heading (rotation about z, radians in [-pi, pi)) of quaternions ``(qx, qy, qz, qw)``.

    Examples
    --------
    >>> round(float(quaternion_to_yaw(yaw_to_quaternion(-2.0))), 12)
    -2.0
    """
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return wrap_angle(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
