"""Gaussian landmark localization: the EKF and the UKF, built on filterpy.

A robot moves with the velocity motion model (or the odometry model) and
observes landmarks at known positions with a range-bearing sensor. The
belief is one Gaussian ``N(mu, Sigma)`` over the pose ``(x, y, theta)``.

* :class:`EKFLocalizer` is EKF localization with known correspondences,
  *Probabilistic Robotics* (Thrun, Burgard and Fox 2005, "PR") table 7.2, on
  :class:`filterpy.kalman.ExtendedKalmanFilter`, with the analytic Jacobians
  of this module (:func:`velocity_jacobians`, :func:`odometry_jacobians`,
  :func:`landmark_jacobian`). Without ids it associates each sighting with
  the most likely landmark, as in PR table 7.3.
* :class:`UKFLocalizer` is the same problem on
  :class:`filterpy.kalman.UnscentedKalmanFilter` with angle-aware mean and
  residual functions (the heading and the bearings are averaged as unit
  vectors and differenced modulo ``2*pi``). Unlike PR table 7.4 the control
  noise enters additively, mapped to state space by the motion Jacobian.
* :func:`ekf_localization_known_correspondences` is the readable version of
  table 7.2 (plain numpy, a loop over sightings): the test oracle of the
  filterpy-based class.

Noise parameters follow PR: the velocity model's ``alphas = (a1..a6)`` give
the variances ``a1*v**2 + a2*w**2`` of the translational velocity,
``a3*v**2 + a4*w**2`` of the rotational velocity and ``a5*v**2 + a6*w**2`` of
the final rotation rate ``gamma`` (PR table 5.3; table 7.2 omits gamma, we
add its variance ``(a5*v**2 + a6*w**2) * dt**2`` to the heading). The
odometry model's ``alphas = (a1..a4)`` are those of PR table 5.6.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as _scipy_linalg  # filterpy's EKF inverts S with it; the lean update does the same
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from filterpy.kalman import unscented_transform as _unscented_transform
from numpy.typing import ArrayLike, NDArray

from . import motion as _motion
from ._checks import check_alphas, check_positive
from .geometry import _wrap_scalar, as_poses, wrap_angle
from .sensors import ON_LANDMARK, LandmarkModel, range_bearing, range_bearing_jacobian

__all__ = [
    "velocity_motion",
    "velocity_jacobians",
    "velocity_noise",
    "odometry_controls",
    "odometry_motion",
    "odometry_jacobians",
    "odometry_noise",
    "landmark_measurement",
    "landmark_jacobian",
    "numerical_jacobian",
    "ekf_localization_known_correspondences",
    "EKFLocalizer",
    "UKFLocalizer",
]

_SMALL = 1e-3  # below this |s| the sinc helpers use their Taylor series
#: A covariance may be asymmetric by this much (round-off) and still count as symmetric.
_SYMMETRY_TOL = 1e-12
#: The UKF raises its covariance's eigenvalues to at least this, so that the next Cholesky factorisation succeeds.
_MIN_EIGENVALUE = 1e-12


# ----------------------------------------------------------------------------
# small checked-input helpers
# ----------------------------------------------------------------------------


def _control(u: ArrayLike, n: int, name: str = "u") -> NDArray[np.float64]:
    c = np.asarray(u, dtype=float)
    if c.shape != (n,) or np.any(~np.isfinite(c)):
        raise ValueError(f"{name} must be {n} finite numbers; got {np.asarray(u).tolist()!r}")
    return c


def _pose(pose: ArrayLike, name: str = "pose") -> NDArray[np.float64]:
    p = as_poses(pose, name)
    if p.shape != (3,):
        raise ValueError(f"{name} must be a single pose of shape (3,); got shape {p.shape}")
    return p


def _sinc(s: NDArray) -> NDArray:
    """sin(s)/s, exact at 0."""
    return np.sinc(s / np.pi)


def _dsinc(s: NDArray) -> NDArray:
    """Derivative of sin(s)/s, stable near 0 (Taylor: -s/3 + s**3/30)."""
    s = np.asarray(s, dtype=float)
    small = np.abs(s) < _SMALL
    safe = np.where(small, 1.0, s)
    exact = (np.cos(safe) - np.sin(safe) / safe) / safe
    return np.where(small, -s / 3.0 + s**3 / 30.0, exact)


# ----------------------------------------------------------------------------
# motion models: mean and Jacobians
# ----------------------------------------------------------------------------


def velocity_motion(poses: ArrayLike, u: ArrayLike, dt: float) -> NDArray[np.float64]:
    """Noise-free velocity motion model ``g(u, x)`` (PR table 7.2, line 6).

    The robot follows a circular arc with translational velocity ``v`` and
    rotational velocity ``w`` for ``dt`` seconds. Written as
    ``x + v*dt*cos(theta + w*dt/2) * sinc(w*dt/2)``, which equals the
    textbook ``x - v/w*sin(theta) + v/w*sin(theta + w*dt)`` and stays exact for
    straight motion (``w = 0``); computed by :func:`localize.motion.move_velocity`.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
    u : array_like, shape (2,)
        ``(v, w)`` in m/s and rad/s.
    dt : float
        Time step in seconds, > 0.

    Returns
    -------
    ndarray, shape (..., 3)
        The moved poses, heading wrapped to ``[-pi, pi)``.

    Examples
    --------
    >>> velocity_motion([0.0, 0.0, 0.0], [1.0, np.pi / 2], 1.0).round(6)   # quarter circle
    array([0.63662 , 0.63662 , 1.570796])
    >>> velocity_motion([0.0, 0.0, 0.0], [1.0, 0.0], 2.0).round(6)
    array([2., 0., 0.])
    """
    p = as_poses(poses)
    v, w = _control(u, 2)
    return _motion.move_velocity(p, v, w, check_positive(dt, "dt", "seconds"))


def velocity_jacobians(pose: ArrayLike, u: ArrayLike, dt: float) -> tuple[NDArray, NDArray]:
    """Jacobians of :func:`velocity_motion`: ``G = dg/dx`` (3x3) and ``V = dg/du`` (3x2).

    These are PR table 7.2, lines 4 and 5, in a form that is also valid for
    ``w = 0`` (the textbook expressions divide by ``w``).

    Examples
    --------
    >>> G, V = velocity_jacobians([0.0, 0.0, 0.0], [1.0, 0.0], 1.0)
    >>> G.round(6) + 0.0
    array([[1., 0., 0.],
           [0., 1., 1.],
           [0., 0., 1.]])
    >>> V.round(6)
    array([[1. , 0. ],
           [0. , 0.5],
           [0. , 1. ]])
    """
    x, y, th = _pose(pose)
    v, w = _control(u, 2)
    return _velocity_jacobians(th, v, w, check_positive(dt, "dt", "seconds"))


def _velocity_jacobians(th: float, v: float, w: float, dt: float) -> tuple[NDArray, NDArray]:
    """:func:`velocity_jacobians` after its checks (heading ``th``, control ``(v, w)``, ``dt > 0``)."""
    half = 0.5 * w * dt
    s, ds = float(_sinc(np.asarray(half))), float(_dsinc(half))
    c, sn = np.cos(th + half), np.sin(th + half)
    G = np.array([[1.0, 0.0, -v * dt * s * sn],
                  [0.0, 1.0, v * dt * s * c],
                  [0.0, 0.0, 1.0]])
    # d/dw of v*dt*s(half)*cos(th+half) with d half/dw = dt/2
    V = np.array([[dt * s * c, v * dt * 0.5 * dt * (ds * c - s * sn)],
                  [dt * s * sn, v * dt * 0.5 * dt * (ds * sn + s * c)],
                  [0.0, dt]])
    return G, V


def velocity_noise(u: ArrayLike, dt: float, alphas: ArrayLike) -> NDArray[np.float64]:
    """Covariance ``M`` of the noisy controls ``(v, w)`` (PR table 7.2, line 7).

    ``M = diag(a1*v**2 + a2*w**2, a3*v**2 + a4*w**2)``. The filters map it to
    state space as ``V M V^T`` and add the final-rotation noise of PR table
    5.3, ``(a5*v**2 + a6*w**2) * dt**2``, to the heading variance.

    Parameters
    ----------
    u : array_like, shape (2,)
        ``(v, w)``.
    dt : float
        Time step, > 0 (checked; ``M`` itself does not depend on it).
    alphas : array_like, shape (6,)

    Returns
    -------
    ndarray, shape (2, 2)

    Examples
    --------
    >>> velocity_noise([1.0, 0.5], 1.0, [0.1, 0.0, 0.0, 0.2, 0, 0]).round(6)
    array([[0.1 , 0.  ],
           [0.  , 0.05]])
    """
    v, w = _control(u, 2)
    check_positive(dt, "dt", "seconds")
    var_v, var_w, _ = _motion.velocity_variances(v, w, check_alphas(alphas, 6))
    return np.diag([float(var_v), float(var_w)])


def _velocity_process_cov(pose: NDArray, u: NDArray, dt: float, alphas: NDArray) -> tuple[NDArray, NDArray]:
    """``G`` and ``V M V^T`` (plus the final rotation's variance) for a checked pose, control, ``dt`` and alphas.

    The lean path of the filters' prediction: :func:`velocity_jacobians` and
    :func:`velocity_noise` without their per-call checks (the filter checked
    ``alphas`` and ``dt`` once, when it was made, and checks ``u`` at each step).
    """
    G, V = _velocity_jacobians(pose[2], u[0], u[1], dt)
    var_v, var_w, var_gamma = _motion._velocity_variances(u[0], u[1], alphas, "squared")
    M = np.diag([float(var_v), float(var_w)])
    Q = V @ M @ V.T
    Q[2, 2] += float(var_gamma) * dt**2
    return G, Q


def odometry_controls(u: ArrayLike) -> NDArray[np.float64]:
    """Turn an odometry pair ``(prev_odom, odom)`` into ``(rot1, trans, rot2)`` (PR table 5.6).

    Delegates to :func:`localize.motion.odometry_to_control`. A 3-vector is taken to be ``(rot1, trans, rot2)`` already.

    Examples
    --------
    >>> odometry_controls([[0.0, 0.0, 0.0], [1.0, 1.0, np.pi / 2]]).round(6)
    array([0.785398, 1.414214, 0.785398])
    """
    a = np.asarray(u, dtype=float)
    if a.shape == (3,):
        if np.any(~np.isfinite(a)):
            raise ValueError(f"u must be finite; got {a.tolist()}")
        return a
    if a.shape != (2, 3) or np.any(~np.isfinite(a)):
        raise ValueError(f"u must be (prev_odom, odom), shape (2, 3), or (rot1, trans, rot2); got shape {a.shape}")
    return np.array(_motion.odometry_to_control(a[0], a[1]), dtype=float)


def odometry_motion(poses: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
    """Noise-free odometry motion: turn ``rot1``, drive ``trans``, turn ``rot2``.

    ``u`` is ``(rot1, trans, rot2)`` or an odometry pair; the motion is
    :func:`localize.motion.move_odometry`.

    Examples
    --------
    >>> odometry_motion([1.0, 0.0, np.pi / 2], [0.0, 2.0, -np.pi / 2]).round(6)
    array([1., 2., 0.])
    """
    r1, tr, r2 = odometry_controls(u)
    return _motion.move_odometry(as_poses(poses), r1, tr, r2)


def odometry_jacobians(pose: ArrayLike, u: ArrayLike) -> tuple[NDArray, NDArray]:
    """Jacobians of :func:`odometry_motion`: ``G`` (3x3) and ``V = d/d(rot1, trans, rot2)`` (3x3).

    Examples
    --------
    >>> G, V = odometry_jacobians([0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    >>> G[:, 2].round(6), V[:, 0].round(6)
    (array([0., 1., 1.]), array([0., 1., 1.]))
    """
    _, _, th = _pose(pose)
    r1, tr, _ = odometry_controls(u)
    c, s = np.cos(th + r1), np.sin(th + r1)
    G = np.array([[1.0, 0.0, -tr * s], [0.0, 1.0, tr * c], [0.0, 0.0, 1.0]])
    V = np.array([[-tr * s, c, 0.0], [tr * c, s, 0.0], [1.0, 0.0, 1.0]])
    return G, V


def odometry_noise(u: ArrayLike, alphas: ArrayLike) -> NDArray[np.float64]:
    """Covariance ``M`` of ``(rot1, trans, rot2)`` in the odometry model (PR table 5.6).

    Variances ``a1*rot1**2 + a2*trans**2``, ``a3*trans**2 + a4*(rot1**2 + rot2**2)``
    and ``a1*rot2**2 + a2*trans**2``.

    Examples
    --------
    >>> np.diag(odometry_noise([0.5, 1.0, 0.0], [0.1, 0.01, 0.02, 0.1])).round(6)
    array([0.035, 0.045, 0.01 ])
    """
    r1, tr, r2 = odometry_controls(u)
    return np.diag([float(v) for v in _motion.odometry_variances(r1, tr, r2, check_alphas(alphas, 4))])


# ----------------------------------------------------------------------------
# the range-bearing measurement
# ----------------------------------------------------------------------------


def landmark_measurement(poses: ArrayLike, landmark: ArrayLike) -> NDArray[np.float64]:
    """Expected range and bearing of one landmark, ``h(x, m)`` (PR table 7.2, line 12).

    The landmark model's :func:`localize.sensors.range_bearing`, with checked input.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
    landmark : array_like, shape (2,)
        Landmark position ``(m_x, m_y)``.

    Returns
    -------
    ndarray, shape (..., 2)
        ``(range, bearing)``, bearing relative to the robot's heading in ``[-pi, pi)``.

    Examples
    --------
    >>> landmark_measurement([0.0, 0.0, np.pi / 2], [3.0, 4.0]).round(6)
    array([ 5.      , -0.643501])
    """
    p = as_poses(poses)
    m = np.asarray(landmark, dtype=float)
    if m.shape != (2,) or np.any(~np.isfinite(m)):
        raise ValueError(f"landmark must be a finite (x, y) pair; got {np.asarray(landmark).tolist()!r}")
    return range_bearing(p, m)


def landmark_jacobian(pose: ArrayLike, landmark: ArrayLike) -> NDArray[np.float64]:
    """Jacobian ``H = dh/dx`` (2x3) of the range-bearing measurement (PR table 7.2, line 13).

    ``H = [[-dx/r, -dy/r, 0], [dy/q, -dx/q, -1]]`` with ``q = r**2``: the
    landmark model's :func:`localize.sensors.range_bearing_jacobian`, checked.

    Raises
    ------
    ValueError
        When the pose sits on the landmark (the bearing is undefined there).

    Examples
    --------
    >>> landmark_jacobian([0.0, 0.0, 0.0], [3.0, 4.0]).round(6)
    array([[-0.6 , -0.8 ,  0.  ],
           [ 0.16, -0.12, -1.  ]])
    """
    p = _pose(pose)
    m = np.asarray(landmark, dtype=float)
    if m.shape != (2,):
        raise ValueError(f"landmark must be an (x, y) pair; got shape {m.shape}")
    H, on = range_bearing_jacobian(p, m)
    if on:
        raise ValueError(f"pose {p.tolist()} coincides with landmark {m.tolist()} "
                         f"(nearer than ON_LANDMARK = {ON_LANDMARK:g} m): the bearing Jacobian is undefined")
    return H


def numerical_jacobian(f, x: ArrayLike, eps: float = 1e-6, angle_rows: tuple[int, ...] = ()) -> NDArray[np.float64]:
    """Central-difference Jacobian of ``f`` at ``x``; rows in ``angle_rows`` are wrapped.

    Used by the tests to check the analytic Jacobians of this module.

    Examples
    --------
    >>> numerical_jacobian(lambda p: landmark_measurement(p, [3.0, 4.0]), [0.0, 0.0, 0.0],
    ...                    angle_rows=(1,)).round(6)
    array([[-0.6 , -0.8 ,  0.  ],
           [ 0.16, -0.12, -1.  ]])
    """
    x = np.asarray(x, dtype=float)
    eps = check_positive(eps, "eps")
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        diff = np.asarray(f(x + d), dtype=float) - np.asarray(f(x - d), dtype=float)
        for r in angle_rows:
            diff[r] = wrap_angle(diff[r])
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=-1)


# ----------------------------------------------------------------------------
# the readable algorithm (the test oracle)
# ----------------------------------------------------------------------------


def ekf_localization_known_correspondences(
    mu: ArrayLike, Sigma: ArrayLike, u: ArrayLike, z: ArrayLike, ids: ArrayLike, landmarks: ArrayLike,
    alphas: ArrayLike, sigma_range: float, sigma_bearing: float, dt: float = 1.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """EKF localization with known correspondences, PR table 7.2, line by line.

    The readable version: the velocity model with the textbook ``v/w``
    formulas (``w`` must be nonzero), then one Kalman update per sighting.
    :class:`EKFLocalizer` is tested against it.

    Parameters
    ----------
    mu, Sigma : array_like, shapes (3,), (3, 3)
        Prior mean and covariance.
    u : array_like, shape (2,)
        ``(v, w)``, ``w != 0``.
    z : array_like, shape (K, 2)
        Range-bearing sightings.
    ids : array_like of int, shape (K,)
        Which landmark each sighting is of (the correspondences ``c``).
    landmarks : array_like, shape (L, 2)
    alphas : array_like, shape (6,)
    sigma_range, sigma_bearing : float
    dt : float

    Returns
    -------
    (mu, Sigma) : the posterior.

    Examples
    --------
    >>> mu, S = ekf_localization_known_correspondences(
    ...     [0, 0, 0], np.eye(3) * 0.1, [1.0, 0.1], [[4.0, 0.9]], [0], [[3.0, 3.0]],
    ...     [0.1] * 4 + [0, 0], 0.2, 0.05)
    >>> mu.round(3), bool(np.trace(S) < 0.3)
    (array([ 0.715, -0.181,  0.043]), True)
    """
    mu = np.asarray(mu, dtype=float)
    Sigma = np.asarray(Sigma, dtype=float)
    v, w = _control(u, 2)
    if w == 0:
        raise ValueError("u[1] (w) must be nonzero in the textbook formulas; use EKFLocalizer for w = 0")
    a = check_alphas(alphas, 6)
    th = mu[2]
    # lines 2-5: Jacobians of g with respect to the state and the control
    G = np.array([[1, 0, -v / w * np.cos(th) + v / w * np.cos(th + w * dt)],
                  [0, 1, -v / w * np.sin(th) + v / w * np.sin(th + w * dt)],
                  [0, 0, 1]])
    V = np.array([
        [(-np.sin(th) + np.sin(th + w * dt)) / w,
         v * (np.sin(th) - np.sin(th + w * dt)) / w**2 + v * np.cos(th + w * dt) * dt / w],
        [(np.cos(th) - np.cos(th + w * dt)) / w,
         -v * (np.cos(th) - np.cos(th + w * dt)) / w**2 + v * np.sin(th + w * dt) * dt / w],
        [0, dt]])
    # line 7: control noise
    M = np.diag([a[0] * v**2 + a[1] * w**2, a[2] * v**2 + a[3] * w**2])
    # line 8-9: predicted mean and covariance
    mu = mu + np.array([-v / w * np.sin(th) + v / w * np.sin(th + w * dt),
                        v / w * np.cos(th) - v / w * np.cos(th + w * dt),
                        w * dt])
    Sigma = G @ Sigma @ G.T + V @ M @ V.T
    Sigma[2, 2] += (a[4] * v**2 + a[5] * w**2) * dt**2   # PR table 5.3's final rotation
    # line 10: measurement noise
    Q = np.diag([sigma_range**2, sigma_bearing**2])
    lms = np.asarray(landmarks, dtype=float)
    # lines 11-19: one update per observed feature
    for zi, j in zip(np.asarray(z, dtype=float).reshape(-1, 2), np.asarray(ids, dtype=int).reshape(-1)):
        dx, dy = lms[j, 0] - mu[0], lms[j, 1] - mu[1]
        q = dx**2 + dy**2
        z_hat = np.array([np.sqrt(q), np.arctan2(dy, dx) - mu[2]])
        H = np.array([[-dx / np.sqrt(q), -dy / np.sqrt(q), 0], [dy / q, -dx / q, -1]])
        S = H @ Sigma @ H.T + Q
        K = Sigma @ H.T @ np.linalg.inv(S)
        innov = zi - z_hat
        innov[1] = wrap_angle(innov[1])
        mu = mu + K @ innov
        Sigma = (np.eye(3) - K @ H) @ Sigma
    mu[2] = wrap_angle(mu[2])
    return mu, Sigma


# ----------------------------------------------------------------------------
# filterpy-based filters
# ----------------------------------------------------------------------------


class _PoseEKF(ExtendedKalmanFilter):
    """filterpy's EKF with a nonlinear state transition ``g`` instead of ``F x + B u``."""

    g = None  # set before each predict

    def predict_x(self, u=0):
        self.x = self.g(self.x)


def _residual_z(a, b):
    d = np.array(a, dtype=float) - b
    flat = d.reshape(-1)
    # wrap_angle gives bearings already in [-pi, pi) back bit for bit: only call it (its numpy
    # overhead is most of this function's cost) when one of the few bearings lies outside
    if not all(-math.pi <= x < math.pi for x in flat[1::2].tolist()):
        flat[1::2] = wrap_angle(flat[1::2])
    return d


def _residual_x(a, b):
    d = np.array(a, dtype=float) - b
    flat = d.reshape(-1)
    flat[2] = _wrap_scalar(float(flat[2]), True)     # wrap_angle of one number, without its numpy overhead
    return d


def _state_mean(sigmas, Wm):
    x = np.dot(Wm, sigmas[:, 0])
    y = np.dot(Wm, sigmas[:, 1])
    t = np.arctan2(np.dot(Wm, np.sin(sigmas[:, 2])), np.dot(Wm, np.cos(sigmas[:, 2])))
    return np.array([x, y, t])


def _z_mean(sigmas, Wm):
    z = np.empty(sigmas.shape[1])
    z[0::2] = Wm @ sigmas[:, 0::2]
    z[1::2] = np.arctan2(Wm @ np.sin(sigmas[:, 1::2]), Wm @ np.cos(sigmas[:, 1::2]))
    return z


class _VectorUKF(UnscentedKalmanFilter):
    """filterpy's UKF with the motion model applied to all sigma points in one call.

    ``_sigmas_of = (x, P, sigmas)`` remembers the last sigma points drawn and the
    belief they were drawn from (see :meth:`UKFLocalizer._refresh_sigmas`).
    """

    _sigmas_of = None

    def sigmas_of(self, x, P):
        """``points_fn.sigma_points(x, P)``, from memory when ``(x, P)`` are bit for bit the last ones."""
        seen = self._sigmas_of
        if seen is not None and np.array_equal(seen[0], x) and np.array_equal(seen[1], P):
            return seen[2].copy()
        sigmas = self.points_fn.sigma_points(x, P)
        self._sigmas_of = (np.array(x, dtype=float), np.array(P, dtype=float), sigmas.copy())
        return sigmas

    def compute_process_sigmas(self, dt, fx=None, **fx_args):
        if fx is None:
            fx = self.fx
        sigmas = self.sigmas_of(self.x, self.P)
        self.sigmas_f = np.asarray(fx(sigmas, dt, **fx_args), dtype=float)

    def update_all(self, z: NDArray, R: NDArray, hx_all) -> None:
        """filterpy's ``update(z, R)``, line for line, with the measurement of all sigma points in one call.

        ``hx_all(sigmas (7, 3)) -> (7, dim_z)`` gives row ``i`` equal to filterpy's
        ``hx(sigmas[i])`` (element-wise functions: the same numbers); the
        unscented transform, the gain and the update are filterpy's own.
        """
        self.sigmas_h = np.atleast_2d(hx_all(self.sigmas_f))
        zp, self.S = _unscented_transform(self.sigmas_h, self.Wm, self.Wc, R, self.z_mean, self.residual_z)
        self.SI = self.inv(self.S)
        Pxz = self.cross_variance(self.x, zp, self.sigmas_f, self.sigmas_h)
        self.K = np.dot(Pxz, self.SI)
        self.y = self.residual_z(z, zp)
        self.x = self.state_add(self.x, np.dot(self.K, self.y))
        self.P = self.P - np.dot(self.K, np.dot(self.S, self.K.T))
        self.z = np.array(z, copy=True)
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()
        self._log_likelihood = None
        self._likelihood = None
        self._mahalanobis = None


class _GaussianLocalizer:
    """Shared set-up, checks and accessors of the EKF and the UKF."""

    def __init__(self, landmarks, sigma_range, sigma_bearing, alphas, motion, dt, mean, cov):
        #: The measurement model: its h, H and noise R are the filter's.
        self.model = LandmarkModel(landmarks, sigma_range, sigma_bearing)
        self.landmarks = self.model.landmarks
        self.sigma_range, self.sigma_bearing = self.model.sigma_range, self.model.sigma_bearing
        if motion not in ("velocity", "odometry"):
            raise ValueError(f"motion must be 'velocity' or 'odometry'; got {motion!r}")
        self.motion = motion
        self.alphas = check_alphas(alphas, 6 if motion == "velocity" else 4)
        self.dt = check_positive(dt, "dt", "seconds")
        self.R1 = self.model.R

    @staticmethod
    def _check_belief(mean, cov):
        m = _pose(mean, "mean").copy()
        m[2] = wrap_angle(m[2])
        c = np.asarray(cov, dtype=float)
        if c.shape != (3, 3) or np.any(~np.isfinite(c)):
            raise ValueError(f"cov must be a finite (3, 3) matrix; got shape {c.shape}")
        if not np.allclose(c, c.T, atol=_SYMMETRY_TOL) or np.min(np.linalg.eigvalsh(c)) <= 0:
            raise ValueError("cov must be symmetric positive definite")
        return m, c

    def _process(self, u):
        """Mean function, Jacobian G and state-space process covariance for control ``u``."""
        mean = self.mean
        if self.motion == "velocity":
            uu = _control(u, 2)
            G, Q = _velocity_process_cov(mean, uu, self.dt, self.alphas)
            v, w, dt = uu[0], uu[1], self.dt
            # velocity_motion with only the check that matters per call (finite poses): u and dt are checked
            return (lambda x: _motion._move_velocity(as_poses(x), v, w, dt)), G, Q
        uu = odometry_controls(u)
        G, V = odometry_jacobians(mean, uu)
        Q = V @ odometry_noise(uu, self.alphas) @ V.T
        return (lambda x: odometry_motion(x, uu)), G, Q

    def _sightings(self, z, ids):
        zz = np.asarray(z, dtype=float).reshape(-1, 2) if np.size(z) else np.zeros((0, 2))
        if np.any(~np.isfinite(zz)):
            raise ValueError("z must be finite (range, bearing) pairs")
        if ids is None:
            return zz, None
        ii = np.asarray(ids).reshape(-1)
        if ii.shape[0] != zz.shape[0]:
            raise ValueError(f"ids must have one entry per sighting ({zz.shape[0]}); got {ii.shape[0]}")
        if ii.size and (not np.issubdtype(ii.dtype, np.integer) or ii.min() < 0 or ii.max() >= len(self.landmarks)):
            raise ValueError(f"ids must be integers in [0, {len(self.landmarks) - 1}]; got {ii.tolist()}")
        return zz, ii.astype(int)

    def associate(self, z: ArrayLike) -> NDArray[np.int64]:
        """Maximum-likelihood data association (PR table 7.3, lines 11-18).

        For each sighting pick the landmark whose predicted measurement, with
        innovation covariance ``S = H Sigma H^T + Q``, makes it most likely.

        Examples
        --------
        >>> f = EKFLocalizer([[5, 0], [0, 5]], 0.1, 0.05, [0.01] * 6, cov=np.eye(3) * 0.01)
        >>> f.associate([[5.0, 1.57], [5.0, 0.0]]).tolist()
        [1, 0]
        """
        zz, _ = self._sightings(z, None)
        if len(zz) == 0:
            return np.zeros(0, dtype=np.int64)
        x, P = self.mean, self.cov
        zhat = range_bearing(x, self.landmarks)                         # (L, 2)
        H, on = range_bearing_jacobian(x, self.landmarks)               # the Jacobians of all landmarks
        S = H @ P @ H.transpose(0, 2, 1) + self.R1                      # (L, 2, 2)
        Sinv = np.linalg.inv(S)
        logdet = np.log(np.linalg.det(S))
        e = zz[:, None, :] - zhat[None]                                 # (K, L, 2)
        e[..., 1] = wrap_angle(e[..., 1])
        ll = -0.5 * (np.einsum("kli,lij,klj->kl", e, Sinv, e) + logdet)
        ll[:, on] = -np.inf                                             # on a landmark: its bearing says nothing
        return np.argmax(ll, axis=1).astype(np.int64)

    def associate_loop(self, z: ArrayLike) -> NDArray[np.int64]:
        """Readable version of :meth:`associate` (PR table 7.3's loops); the test oracle."""
        zz, _ = self._sightings(z, None)
        out = np.empty(len(zz), dtype=np.int64)
        mean, cov = self.mean, self.cov
        for k, zk in enumerate(zz):
            best, best_ll = 0, -np.inf
            for j, m in enumerate(self.landmarks):
                H, on = range_bearing_jacobian(mean, m)
                if on:
                    continue
                S = H @ cov @ H.T + self.R1
                e = _residual_z(zk, range_bearing(mean, m))
                ll = -0.5 * (e @ np.linalg.solve(S, e) + np.log(np.linalg.det(S)))
                if ll > best_ll:
                    best, best_ll = j, ll
            out[k] = best
        return out

    def estimate(self) -> NDArray[np.float64]:
        """The mean pose ``(x, y, theta)``."""
        return self.mean

    def step(self, u: ArrayLike, z: ArrayLike, ids: ArrayLike | None = None) -> NDArray[np.float64]:
        """``predict(u)`` then ``update(z, ids)``; returns the new mean."""
        self.predict(u)
        self.update(z, ids)
        return self.mean


class EKFLocalizer(_GaussianLocalizer):
    """EKF landmark localization (PR table 7.2) on filterpy's ``ExtendedKalmanFilter``.

    Parameters
    ----------
    landmarks : array_like, shape (L, 2)
        Known landmark positions.
    sigma_range, sigma_bearing : float
        Standard deviations of the range (m) and bearing (rad) noise.
    alphas : array_like
        Motion noise in the PR convention: 6 values for ``motion="velocity"``,
        4 for ``motion="odometry"`` (see the module docstring).
    motion : {"velocity", "odometry"}
        Control ``u`` is ``(v, w)`` for the velocity model, or the odometry
        pair ``(prev_odom, odom)`` (or ``(rot1, trans, rot2)``) for the odometry model.
    dt : float
        Time step of the velocity model, s.
    mean, cov : array_like
        Initial belief, ``(3,)`` and ``(3, 3)`` symmetric positive definite
        (default: the origin with identity covariance).

    Attributes
    ----------
    kf : filterpy.kalman.ExtendedKalmanFilter
        The underlying filterpy object (``kf.x`` is a ``(3, 1)`` column).

    Examples
    --------
    >>> lms = [[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0]]
    >>> ekf = EKFLocalizer(lms, 0.1, 0.02, [0.05] * 4 + [0.0, 0.0], dt=1.0,
    ...                    mean=[0.0, 0.0, 0.0], cov=np.diag([0.5, 0.5, 0.1]))
    >>> ekf.predict([1.0, 0.0])
    >>> ekf.update([[4.0, 0.0], [5.099, 1.7682]], ids=[0, 1])
    >>> ekf.mean.round(2) + 0.0, bool(np.trace(ekf.cov) < 0.1)
    (array([1., 0., 0.]), True)
    """

    def __init__(self, landmarks: ArrayLike, sigma_range: float, sigma_bearing: float, alphas: ArrayLike,
                 motion: str = "velocity", dt: float = 1.0, mean: ArrayLike = (0.0, 0.0, 0.0),
                 cov: ArrayLike | None = None):
        cov = np.eye(3) if cov is None else cov
        super().__init__(landmarks, sigma_range, sigma_bearing, alphas, motion, dt, mean, cov)
        self.kf = _PoseEKF(dim_x=3, dim_z=2)
        self.reset(mean, cov)

    def reset(self, mean: ArrayLike, cov: ArrayLike) -> None:
        """Set the belief to ``N(mean, cov)``.

        Examples
        --------
        >>> f = EKFLocalizer([[1, 1]], 0.1, 0.1, [0] * 6)
        >>> f.reset([1, 2, 3], np.eye(3)); f.mean.tolist()
        [1.0, 2.0, 3.0]
        """
        m, c = self._check_belief(mean, cov)
        self.kf.x = m.reshape(3, 1)
        self.kf.P = c.copy()

    @property
    def mean(self) -> NDArray[np.float64]:
        """Mean pose, shape (3,)."""
        return self.kf.x.reshape(3).copy()

    @property
    def cov(self) -> NDArray[np.float64]:
        """Pose covariance, shape (3, 3)."""
        return self.kf.P.copy()

    # -- generic EKF steps (a linear model makes these the Kalman filter) -----
    def predict_model(self, fx, F: ArrayLike, Q: ArrayLike) -> None:
        """EKF prediction with a given mean function and Jacobian: ``mu <- fx(mu)``, ``P <- F P F^T + Q``.

        ``fx`` maps a ``(3,)`` pose to a ``(3,)`` pose. With ``fx(x) = F x + B u``
        this is exactly the Kalman filter's prediction.

        Examples
        --------
        >>> f = EKFLocalizer([[1, 1]], 0.1, 0.1, [0] * 6, cov=np.eye(3))
        >>> f.predict_model(lambda x: x + 1.0, np.eye(3), np.eye(3))
        >>> f.mean.tolist(), np.diag(f.cov).tolist()
        ([1.0, 1.0, 1.0], [2.0, 2.0, 2.0])
        """
        self.kf.g = lambda x: np.asarray(fx(x.reshape(3)), dtype=float).reshape(3, 1)
        self.kf.F = np.asarray(F, dtype=float)
        self.kf.Q = np.asarray(Q, dtype=float)
        self.kf.predict()
        self.kf.x[2, 0] = wrap_angle(self.kf.x[2, 0])
        self.kf.x_prior = self.kf.x.copy()

    def update_model(self, z: ArrayLike, hx, H: ArrayLike, R: ArrayLike, residual=None) -> None:
        """EKF update with a given measurement function and Jacobian (filterpy's ``update``).

        ``hx`` maps a ``(3,)`` pose to the predicted measurement; ``H`` is its
        Jacobian at the current mean; ``residual(z, z_hat)`` defaults to
        subtraction. The heading is wrapped afterwards.

        Examples
        --------
        >>> f = EKFLocalizer([[1, 1]], 0.1, 0.1, [0] * 6, cov=np.eye(3))
        >>> f.update_model([2.0, 0.0, 0.0], lambda x: x, np.eye(3), np.eye(3))
        >>> f.mean.tolist(), np.diag(f.cov).tolist()
        ([1.0, 0.0, 0.0], [0.5, 0.5, 0.5])
        """
        zz = np.asarray(z, dtype=float).reshape(-1, 1)
        Hm = np.asarray(H, dtype=float)
        res = (lambda a, b: np.asarray(residual(a.reshape(-1), b.reshape(-1))).reshape(-1, 1)) if residual \
            else np.subtract
        self.kf.update(zz, HJacobian=lambda x: Hm,
                       Hx=lambda x: np.asarray(hx(x.reshape(3)), dtype=float).reshape(-1, 1),
                       R=np.asarray(R, dtype=float), residual=res)
        self.kf.x[2, 0] = wrap_angle(self.kf.x[2, 0])
        self.kf.P = 0.5 * (self.kf.P + self.kf.P.T)

    # -- the localization steps -------------------------------------------------
    def predict(self, u: ArrayLike) -> None:
        """Prediction step (PR table 7.2, lines 2-9) for control ``u``.

        Examples
        --------
        >>> f = EKFLocalizer([[1, 1]], 0.1, 0.1, [0.1, 0, 0, 0, 0, 0], cov=np.eye(3) * 1e-6)
        >>> f.predict([1.0, 0.0]); f.mean.tolist(), round(float(f.cov[0, 0]), 4)
        ([1.0, 0.0, 0.0], 0.1)
        """
        g, G, Q = self._process(u)
        self.predict_model(g, G, Q)

    def update(self, z: ArrayLike, ids: ArrayLike | None = None) -> None:
        """Correction with range-bearing sightings ``z (K, 2)`` (PR table 7.2, lines 10-19).

        One Kalman update per sighting, each linearised at the current mean.
        ``ids=None`` means unknown correspondences: each sighting is first
        associated by maximum likelihood (PR table 7.3). An empty ``z`` is a
        no-op.
        """
        zz, ii = self._sightings(z, ids)
        if ii is None:
            ii = self.associate(zz) if len(zz) else np.zeros(0, dtype=int)
        for zk, j in zip(zz, ii):
            m = self.landmarks[j]
            H, on = range_bearing_jacobian(self.kf.x[:, 0], m)
            if on:
                continue  # on top of the landmark: the bearing says nothing
            self._update_sighting(zk, m, H)

    def _update_sighting(self, zk: NDArray, m: NDArray, H: NDArray) -> None:
        """One range-bearing correction: ``update_model(zk, h_m, H, R1, _residual_z)``, bit for bit, leaner.

        The lean path of :meth:`update`: filterpy's ``ExtendedKalmanFilter.update``
        (Joseph form) written out with the same operations in the same order,
        on inputs this class has checked, without the per-call generality (the
        ``deepcopy`` of ``z``, argument juggling) that costs more than the
        3x3 algebra itself. ``tests/test_lean_ekf.py`` holds it equal to
        :meth:`update_model`, which calls filterpy.
        """
        kf, R = self.kf, self.R1
        x, P = kf.x, kf.P
        z = zk.reshape(-1, 1)
        PHT = np.dot(P, H.T)
        S = np.dot(H, PHT) + R
        SI = _scipy_linalg.inv(S)
        K = PHT.dot(SI)
        hx = range_bearing(x.reshape(3), m).reshape(-1, 1)
        y = _residual_z(z.reshape(-1), hx.reshape(-1)).reshape(-1, 1)
        x = x + np.dot(K, y)
        I_KH = kf._I - np.dot(K, H)
        P = np.dot(I_KH, P).dot(I_KH.T) + np.dot(K, R).dot(K.T)
        kf.S, kf.SI, kf.K, kf.y, kf.z = S, SI, K, y, z.copy()
        kf._log_likelihood = kf._likelihood = kf._mahalanobis = None
        kf.x_post, kf.P_post = x.copy(), P.copy()
        x[2, 0] = wrap_angle(x[2, 0])
        kf.x, kf.P = x, 0.5 * (P + P.T)


class UKFLocalizer(_GaussianLocalizer):
    """UKF landmark localization on filterpy's ``UnscentedKalmanFilter``.

    Same parameters and methods as :class:`EKFLocalizer`; the sigma points
    are van der Merwe's scaled points (``alpha``, ``beta``, ``kappa``). The
    heading of the sigma points is averaged as unit vectors, bearings
    likewise; residuals are wrapped. All sightings of a step are fused in one
    stacked update. The control noise is mapped into state space with the
    motion Jacobian (additive process noise), a simplification of PR table 7.4
    which augments the state with the control and measurement noise.

    Attributes
    ----------
    kf : filterpy.kalman.UnscentedKalmanFilter

    Examples
    --------
    The EKF's example with :meth:`step` (predict, then update) and
    unknown correspondences (each sighting associated by maximum likelihood):

    >>> ukf = UKFLocalizer([[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0]], 0.1, 0.02, [0.05] * 4 + [0.0, 0.0],
    ...                    cov=np.diag([0.5, 0.5, 0.1]))
    >>> ukf.step([1.0, 0.0], [[4.0, 0.0], [5.099, 1.7682]]).round(1) + 0.0
    array([1., 0., 0.])
    >>> bool(np.trace(ukf.cov) < 0.1)
    True
    """

    def __init__(self, landmarks: ArrayLike, sigma_range: float, sigma_bearing: float, alphas: ArrayLike,
                 motion: str = "velocity", dt: float = 1.0, mean: ArrayLike = (0.0, 0.0, 0.0),
                 cov: ArrayLike | None = None, alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0):
        cov = np.eye(3) if cov is None else cov
        super().__init__(landmarks, sigma_range, sigma_bearing, alphas, motion, dt, mean, cov)
        points = MerweScaledSigmaPoints(3, alpha=check_positive(alpha, "alpha"), beta=float(beta), kappa=float(kappa),
                                        subtract=_residual_x)
        self.kf = _VectorUKF(dim_x=3, dim_z=2, dt=self.dt, hx=None, fx=None, points=points,
                                        x_mean_fn=_state_mean, z_mean_fn=_z_mean,
                                        residual_x=_residual_x, residual_z=_residual_z)
        self.reset(mean, cov)

    def reset(self, mean: ArrayLike, cov: ArrayLike) -> None:
        """Set the belief to ``N(mean, cov)``."""
        m, c = self._check_belief(mean, cov)
        self.kf.x = m
        self.kf.P = c.copy()
        self.kf._sigmas_of = None
        self._refresh_sigmas()

    @property
    def mean(self) -> NDArray[np.float64]:
        """Mean pose, shape (3,)."""
        return np.asarray(self.kf.x, dtype=float).reshape(3).copy()

    @property
    def cov(self) -> NDArray[np.float64]:
        """Pose covariance, shape (3, 3)."""
        return np.asarray(self.kf.P, dtype=float).copy()

    def _fix(self) -> None:
        self.kf.x = np.asarray(self.kf.x, dtype=float).reshape(3)
        self.kf.x[2] = wrap_angle(self.kf.x[2])
        P = 0.5 * (self.kf.P + self.kf.P.T)
        w, v = np.linalg.eigh(P)
        if w.min() <= _MIN_EIGENVALUE:   # keep P positive definite for the next Cholesky
            P = (v * np.maximum(w, _MIN_EIGENVALUE)) @ v.T
        self.kf.P = P

    def _refresh_sigmas(self) -> None:
        """``kf.sigmas_f = sigma_points(kf.x, kf.P)``, computed again only if ``x`` or ``P`` changed.

        The sigma points are a deterministic function of ``(x, P)``: when both
        are bit for bit those they were last computed from, the stored ones
        are the ones a new computation would give (one Cholesky factorisation
        and seven sigma points saved, the lean path of a step; the next
        prediction starts from the same memory).
        """
        self.kf.sigmas_f = self.kf.sigmas_of(self.kf.x, self.kf.P)

    def predict(self, u: ArrayLike) -> None:
        """Unscented prediction through the motion model's mean function."""
        g, _, Q = self._process(u)
        self.kf.Q = Q
        self.kf.predict(fx=lambda x, dt: g(x))
        # filterpy has just drawn the sigma points of its (x, P); _fix changes them only at the edges
        self.kf._sigmas_of = (np.array(self.kf.x, dtype=float), np.array(self.kf.P, dtype=float),
                              np.array(self.kf.sigmas_f, dtype=float))
        self._fix()
        self._refresh_sigmas()

    def update(self, z: ArrayLike, ids: ArrayLike | None = None) -> None:
        """Unscented correction with all sightings of this step stacked in one vector.

        ``ids=None`` associates by maximum likelihood on the linearised model
        (as the EKF does). An empty ``z`` is a no-op.
        """
        zz, ii = self._sightings(z, ids)
        if len(zz) == 0:
            return
        if ii is None:
            ii = self.associate(zz)
        lms = self.landmarks[ii]

        def hx_all(sigmas):      # row i: range_bearing(sigmas[i], lms).reshape(-1), all rows at once
            return range_bearing(sigmas[:, None, :], lms[None]).reshape(len(sigmas), -1)

        self._refresh_sigmas()
        R = np.kron(np.eye(len(zz)), self.R1)
        self.kf.update_all(zz.reshape(-1), R, hx_all)
        self._fix()
        self._refresh_sigmas()
