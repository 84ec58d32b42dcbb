"""What the map says about the filter's answer: evidence for the run driver's policies and state.

A particle filter can agree with itself on a wrong place: its sensor model
scores each particle, and a likelihood field never asks whether a beam passed
through a wall. The functions here judge the *estimate* against the map,
with no ground truth:

* :func:`scan_fit` -- the share of beams whose reading agrees with the range
  ray-cast in the map from the estimate (a wrong place lets beams pass
  through walls, and the ray cast sees it); :func:`scan_fits` for many
  scans and poses in one ray cast;
* :func:`expected_fit` -- the share the sensor model itself expects on the
  right pose, the yardstick for :func:`scan_fit`;
* :func:`pinned` -- whether the scan fits the estimate clearly better than
  the estimate moved a little (a featureless corridor fits every stretch);
* :func:`free_share` -- the share of the weight on the map's free space;
* :func:`unexplained_beams` -- the beams the map cannot explain at an agreed
  place (end point in an unknown cell, or a reading much shorter than the
  map allows: clutter), for the beam-mask policy.

Used by :mod:`localize.policies`, :mod:`localize.runloop` and
:mod:`localize.smooth`.
"""

from __future__ import annotations

from math import erf, sqrt
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .geometry import compose
from .grid import OccupancyGrid
from .sensors import select_beams, sensor_poses

__all__ = ["expected_fit", "scan_fit", "scan_fits", "pinned", "free_share", "unexplained_beams", "SHORT_BEAMS_MAX_SHARE"]

#: :func:`unexplained_beams`' ``short``: when more than this share of a scan's valid beams read short at the
#: agreed place, none is left out (most of the scan contradicting the map says the place is wrong; a
#: cluttered room still shows most of its walls).
SHORT_BEAMS_MAX_SHARE = 0.5


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
    z_hit = getattr(sensor, "z_hit", None)
    sigma = getattr(sensor, "sigma_hit", None)
    if z_hit is None or sigma is None:
        return 0.9
    return float(z_hit) * erf(float(fit_distance) / (float(sigma) * sqrt(2.0)))


def scan_fit(caster: Any, pose: NDArray, offset: NDArray, ranges: NDArray, angles: NDArray, fit_d: float,
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

    Parameters
    ----------
    caster : localize.raycast.RayCaster
        Ray caster on the map.
    pose : ndarray (3,)
        The robot's pose; ``offset`` is the laser's pose on the robot.
    ranges, angles : ndarray (B,)
        Valid readings and their beam angles.
    fit_d : float
        Largest disagreement (m) that still counts as a fit.
    min_beams : int
        Fewest judged beams for a fit.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.raycast import RayCaster
    >>> g = office()
    >>> rc = RayCaster(g, 8.0, method="march")
    >>> a = np.linspace(-1.5, 1.5, 31)
    >>> pose = np.array([3.0, 3.0, 1.0])
    >>> z = rc.cast(pose[None], a)[0]
    >>> scan_fit(rc, pose, np.zeros(3), z, a, 0.2, 5), scan_fit(rc, pose + [1.5, 0, 0], np.zeros(3), z, a, 0.2, 5) < 0.5
    (1.0, True)
    """
    if ranges.size < min_beams:
        return float("nan")
    pose = np.asarray(pose, dtype=float)
    if not np.all(np.isfinite(pose)):
        caster.cast(sensor_poses(pose[None, :], offset), angles)   # the caster's error for a pose it cannot cast
    return float(scan_fits(caster, pose[None, :], offset, np.asarray(ranges)[None, :],
                           np.ones((1, np.size(ranges)), dtype=bool), angles, fit_d, min_beams)[0])


def scan_fits(caster: Any, poses: NDArray, offset: NDArray, scans: NDArray, valid: NDArray, angles: NDArray,
              fit_d: float, min_beams: int, short_unjudged: bool = False) -> NDArray[np.float64]:
    """:func:`scan_fit` of scan ``i`` at pose ``i`` for every ``i``, in one ray cast.

    ``valid (N, B)`` marks the readings to judge; a pose with a NaN gets NaN.
    With ``short_unjudged``, a reading more than ``fit_d`` *shorter* than the
    map allows is not judged either: something the map does not show stands
    in front (a person, a moved cabinet), which says nothing against the pose;
    only a reading that agrees or one that passed through a mapped wall counts.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.raycast import RayCaster
    >>> g = office()
    >>> rc = RayCaster(g, 8.0, method="march")
    >>> a = np.linspace(-1.5, 1.5, 31)
    >>> poses = np.array([[3.0, 3.0, 1.0], [4.5, 3.0, 1.0]])
    >>> z = rc.cast(poses[:1], a)
    >>> f = scan_fits(rc, poses, np.zeros(3), np.vstack([z, z]), np.ones((2, 31), bool), a, 0.2, 5)
    >>> float(f[0]) == scan_fit(rc, poses[0], np.zeros(3), z[0], a, 0.2, 5), bool(f[1] < 0.5)
    (True, True)
    """
    ok_pose = np.all(np.isfinite(poses), axis=1)
    out = np.full(len(poses), np.nan)
    if not ok_pose.any():
        return out
    sp = sensor_poses(poses[ok_pose], offset)
    expected = caster.cast(sp, angles)
    judged = valid[ok_pose].copy()
    g = caster.grid
    if g.unknown.any():
        th = sp[:, 2:3] + angles[None, :]
        reach = expected + 0.5 * g.resolution
        hit = np.stack([sp[:, 0:1] + reach * np.cos(th), sp[:, 1:2] + reach * np.sin(th)], axis=-1).reshape(-1, 2)
        cells = g.world_to_cell(hit, outside="clip")
        known = (~g.unknown[cells[:, 0], cells[:, 1]] & g.contains(hit)).reshape(expected.shape)
        judged &= known
    with np.errstate(invalid="ignore"):
        if short_unjudged:
            judged &= scans[ok_pose] >= expected - fit_d
        agree = judged & (np.abs(scans[ok_pose] - expected) <= fit_d)
    n_judged = judged.sum(axis=1)
    fit = np.where(n_judged >= min_beams, agree.sum(axis=1) / np.maximum(n_judged, 1), np.nan)
    out[ok_pose] = fit
    return out


def pinned(sensor: Any, pose: NDArray, z: tuple, shift: float, min_contrast: float, lo_r: float = 0.0,
           hi_r: float = np.inf) -> bool:
    """Whether the scan ``z`` fits ``pose`` better than ``pose`` moved by ``shift`` in any of four directions.

    The contrast is the drop of the sensor model's log-likelihood per beam it
    scored (the model's tempering undone); the pose is pinned when the
    smallest drop is at least ``min_contrast``. The beams counted are those the
    sensor scores: of the ``max_beams`` it thins a scan to (if it does), the
    readings in ``(lo_r, hi_r)`` -- a beam left out of the update (set to the
    maximum range by :func:`unexplained_beams`' caller) adds nothing to the
    drop, so it does not dilute it either, and a 1081-beam scan read by a
    30-beam model is judged as the 30 beams it is.

    Examples
    --------
    >>> class Wall:                     # a wall ahead: the reading pins x, nothing pins y
    ...     def log_likelihood(self, poses, ranges, angles):
    ...         return -0.5 * ((5.0 - poses[:, 0] - ranges[0]) / 0.1) ** 2
    >>> pinned(Wall(), np.array([2.0, 0.0, 0.0]), (np.array([3.0]), np.zeros(1)), 1.0, 0.1)
    False
    """
    d = np.array([[0.0, 0.0, 0.0], [shift, 0.0, 0.0], [-shift, 0.0, 0.0], [0.0, shift, 0.0], [0.0, -shift, 0.0]])
    probes = compose(np.asarray(pose, dtype=float), d)
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


def free_share(grid: OccupancyGrid, allowed: NDArray[np.bool_], particles: NDArray, weights: NDArray) -> float:
    """Share of the weight on particles whose cell is ``allowed`` (a boolean image shaped like ``grid``).

    Particles outside the grid, or at NaN poses, count as not allowed.

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office()
    >>> p = np.array([[3.0, 3.0, 0.0], [-50.0, 0.0, 0.0]])
    >>> free_share(g, ~g.occupied, p, np.array([0.75, 0.25]))
    0.75
    """
    cells = grid.world_to_cell(particles[:, :2], outside="flag")
    inside = cells[:, 0] >= 0
    inside[inside] = allowed[cells[inside, 0], cells[inside, 1]]
    return float(weights[inside].sum() / max(weights.sum(), 1e-300))


def unexplained_beams(grid: OccupancyGrid, pose: NDArray, offset: NDArray, z: tuple, max_range: float, *,
                      unknown: bool = True, caster: Any = None, short: float = 0.0) -> tuple[tuple, int, int]:
    """``(z, n_unknown, n_short)``: the scan with the beams the map cannot explain at ``pose`` set to
    ``max_range`` (no return: not scored), and how many of each kind those were.

    With ``unknown``, the beams whose end point falls in an unknown cell; with ``short > 0`` (metres, needs
    ``caster``), those that read more than ``short`` shorter than the range ray-cast from the pose -- unless
    more than :data:`SHORT_BEAMS_MAX_SHARE` of the valid beams do.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.raycast import RayCaster
    >>> g = office()
    >>> rc = RayCaster(g, 8.0, method="march")
    >>> a = np.linspace(-1.5, 1.5, 7)
    >>> pose = np.array([3.0, 3.0, 1.0])
    >>> r = rc.cast(pose[None], a)[0]
    >>> r[3] -= 1.5                           # something the map does not show, 1.5 m in front of a wall
    >>> z, n_unknown, n_short = unexplained_beams(g, pose, np.zeros(3), (r, a), 8.0, caster=rc, short=1.0)
    >>> n_unknown, n_short, float(z[0][3])
    (0, 1, 8.0)
    """
    sx, sy, sth = sensor_poses(np.asarray(pose, dtype=float)[None, :], offset)[0]
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
