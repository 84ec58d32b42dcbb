"""Scan-to-scan evidence about the odometry: did the robot drive the way its odometry says?

Some odometry cannot tell forwards from backwards: a speed measured without a
sign (one encoder channel, a speed estimated from its magnitude) integrates
every reversing manoeuvre as driving forwards. Freiburg building 079's log is
one (its odometry never reports a negative speed, while the robot backs up
about a hundred times; tests/test_real_data.py measures it). A particle filter
fed such a step moves every particle the wrong way, twice the step's length
from where the robot is, and a robot that backs up for tens of scans leaves
its cloud behind.

Two consecutive scans settle it without a map: the end points of the second
scan, placed with the odometry's step, fall on those of the first; placed with
the step reversed, they do not (or the other way round). :func:`check_odometry_sign`
compares the two fits at every step and reverses the steps whose reversed
version fits clearly better. The fit is the mean of the squared distance from
each end point to the nearest end point of the other scan, truncated at
``trunc`` (a robust point-to-point score, the first step of ICP; Besl and
McKay 1992, Lu and Milios 1997 for scans). Only the sign is decided; the
step's length and turn stay the odometry's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._checks import check_positive
from .geometry import compose, relative, transform_points

__all__ = ["scan_points", "step_fit", "OdometrySignCheck", "check_odometry_sign", "reports_reversing"]


def scan_points(ranges, angles, max_range: float, min_range: float = 0.0,
                sensor_offset=(0.0, 0.0, 0.0)) -> NDArray[np.float64]:
    """End points ``(M, 2)`` of one scan's returned beams in the robot frame.

    Readings at or above ``max_range`` (no return) or below ``min_range`` are left out.

    Examples
    --------
    >>> scan_points([1.0, 80.0, 2.0], [0.0, 0.1, np.pi / 2], max_range=80.0).round(6)
    array([[1., 0.],
           [0., 2.]])
    """
    r = np.asarray(ranges, dtype=float)
    a = np.asarray(angles, dtype=float)
    ok = (r < float(max_range)) & (r >= float(min_range)) & np.isfinite(r)
    pts = np.c_[r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])]
    return transform_points(np.asarray(sensor_offset, dtype=float), pts)


def step_fit(prev_points: NDArray, points: NDArray, step, trunc: float = 0.3, tree=None) -> float:
    """How well ``points`` placed by ``step`` (a pose in the frame of ``prev_points``) fall on ``prev_points``.

    Mean over ``points`` of ``min(d, trunc)**2``, ``d`` the distance to the
    nearest of ``prev_points``: 0 is a perfect fit, ``trunc**2`` no overlap at
    all. ``tree`` may be a :class:`scipy.spatial.cKDTree` of ``prev_points``.

    Examples
    --------
    >>> wall = np.c_[np.full(50, 2.0), np.linspace(-1, 1, 50)]     # a wall 2 m ahead
    >>> moved = wall - [0.3, 0.0]                                   # seen after driving 0.3 m
    >>> round(step_fit(wall, moved, (0.3, 0.0, 0.0)), 6), round(step_fit(wall, moved, (-0.3, 0.0, 0.0)), 3)
    (0.0, 0.09)
    """
    from scipy.spatial import cKDTree

    if len(points) == 0 or len(prev_points) == 0:
        return float(trunc) ** 2
    tree = cKDTree(prev_points) if tree is None else tree
    d, _ = tree.query(transform_points(np.asarray(step, dtype=float), points), distance_upper_bound=trunc)
    return float(np.mean(np.minimum(d, trunc) ** 2))


def reports_reversing(odometry, min_step: float = 0.01) -> bool:
    """Whether any odometry step moves backwards by more than ``min_step`` metres (its speed has a sign).

    Examples
    --------
    >>> reports_reversing([[0, 0, 0], [0.5, 0, 0], [1.0, 0, 0]]), reports_reversing([[0, 0, 0], [-0.5, 0, 0]])
    (False, True)
    """
    odo = np.asarray(odometry, dtype=float).reshape(-1, 3)
    if len(odo) < 2:
        return False
    return bool(np.any(relative(odo[:-1], odo[1:])[:, 0] < -float(min_step)))


@dataclass(frozen=True)
class OdometrySignCheck:
    """What :func:`check_odometry_sign` found.

    ``odometry`` is the log's odometry with the ``reversed`` steps (step ``k``
    goes from scan ``k`` to scan ``k + 1``) driven backwards; ``checked`` is
    the number of steps long enough to be checked; ``fits`` holds, per
    reversed step, the fit of the odometry's step and of its reverse
    (see :func:`step_fit`).
    """

    odometry: NDArray[np.float64]
    reversed: NDArray[np.int64]
    checked: int
    fits: NDArray[np.float64]

    def summary(self) -> dict:
        return {"steps_checked": int(self.checked), "steps_reversed": int(self.reversed.size),
                "reversed_steps": [int(k) for k in self.reversed]}


def check_odometry_sign(ranges, angles, odometry, max_range: float, *, min_range: float = 0.05,
                        sensor_offset=(0.0, 0.0, 0.0), ratio: float = 0.5, min_step: float = 0.05,
                        trunc: float = 0.3) -> OdometrySignCheck:
    """Reverse the odometry steps whose reverse fits consecutive scans clearly better.

    For every step of at least ``min_step`` metres, the end points of scan
    ``k + 1`` are placed on those of scan ``k`` with the odometry's step
    ``(dx, dy, dtheta)`` and with its reverse ``(-dx, -dy, dtheta)``; the step
    is reversed where the reverse's :func:`step_fit` is below ``ratio`` times
    the odometry's (0.5: the reversed step's end points lie, on average,
    within 70% of the distance of the odometry's; a corridor that cannot tell
    the two apart changes nothing). The odometry is then integrated again from
    its first pose with the corrected steps.

    Parameters
    ----------
    ranges : array (K, B)
        The scans (metres); readings ``>= max_range`` are no return.
    angles : array (B,)
        Beam angles (radians) in the laser's frame.
    odometry : array (K, 3)
        Odometry pose at each scan.
    max_range, min_range : float
        Readings outside ``[min_range, max_range)`` are not used.
    sensor_offset : pose
        The laser's pose in the robot frame.
    ratio : float in (0, 1]
        How much better the reverse must fit.
    min_step : float
        Shorter steps are not checked (their sign matters little).
    trunc : float
        Distance (metres) beyond which an end point counts as unmatched.

    Examples
    --------
    A robot that backs up 0.4 m from a wall 2 m ahead, with odometry that says it drove forwards:

    >>> wall = np.c_[np.full(41, 2.0), np.linspace(-1, 1, 41)]
    >>> angles = np.arctan2(wall[:, 1], wall[:, 0])
    >>> ranges = np.array([np.hypot(*wall.T), np.hypot(wall[:, 0] + 0.4, wall[:, 1])])
    >>> chk = check_odometry_sign(ranges, angles, [[0, 0, 0], [0.4, 0, 0]], max_range=30.0)
    >>> chk.reversed.tolist(), chk.odometry[-1].round(6).tolist()
    ([0], [-0.4, 0.0, 0.0])
    """
    from scipy.spatial import cKDTree

    ratio = float(ratio)
    if not 0.0 < ratio <= 1.0:
        raise ValueError(f"ratio must be in (0, 1]; got {ratio}")
    check_positive(trunc, "trunc", "metres")
    odo = np.asarray(odometry, dtype=float).reshape(-1, 3)
    r = np.asarray(ranges, dtype=float)
    if r.ndim != 2 or r.shape[0] != odo.shape[0]:
        raise ValueError(f"ranges must have one row per odometry pose; got {r.shape} and {odo.shape}")
    steps = relative(odo[:-1], odo[1:]) if len(odo) > 1 else np.zeros((0, 3))
    rev, fits, checked = [], [], 0
    pts = [None] * len(odo)

    def points(k):
        if pts[k] is None:
            pts[k] = scan_points(r[k], angles, max_range, min_range, sensor_offset)
        return pts[k]

    for k, s in enumerate(steps):
        if np.hypot(s[0], s[1]) < min_step:
            continue
        p, q = points(k), points(k + 1)
        if len(p) < 10 or len(q) < 10:
            continue
        checked += 1
        tree = cKDTree(p)
        f_odo = step_fit(p, q, s, trunc, tree)
        f_rev = step_fit(p, q, (-s[0], -s[1], s[2]), trunc, tree)
        if f_rev < ratio * f_odo:
            rev.append(k)
            fits.append((f_odo, f_rev))
    new = odo.copy()
    if rev:
        steps = steps.copy()
        steps[rev, :2] *= -1.0
        for k, s in enumerate(steps):
            new[k + 1] = compose(new[k], s)
    return OdometrySignCheck(odometry=new, reversed=np.asarray(rev, dtype=np.int64), checked=checked,
                             fits=np.asarray(fits, dtype=float).reshape(-1, 2))
