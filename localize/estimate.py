"""The answer to "where is the robot?": a particle cloud summarised as a pose, its spread and its modes.

:func:`estimate_pose` clusters the weighted particles (cells of ``cluster_size``
metres holding most of the weight, joined where they touch) and returns an
:class:`Estimate`: the weighted mean of the heaviest cluster, the mean and
spread of the whole cloud and the share of the weight the best cluster holds.
:meth:`localize.mcl.MCL.estimate` and the run driver (:mod:`localize.runloop`)
use it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_poses, check_positive
from .geometry import wrap_angle

__all__ = ["Estimate", "estimate_pose"]

#: The estimate's cluster histogram has at most this many cells along each side (its cells grow beyond
#: ``cluster_size`` when the particles spread wider), so that a cloud spread over a large map stays cheap.
_MAX_CLUSTER_CELLS = 512

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
    cluster_cov : ndarray (3, 3)
        Weighted covariance of the best cluster alone (like ``cov``): the
        pose covariance a navigation stack wants (ROS AMCL publishes one with
        every pose). With one cluster it equals ``cov``.

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
    cluster_cov: NDArray[np.float64] | None = None

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
        return Estimate(mean.copy(), mean, std, cov, 1.0, 1, n_eff, std, cov)
    inside = labels >= 0
    share = np.bincount(labels[inside], weights=w[inside], minlength=n_lab)
    if n_lab == 1 and share[0] >= mass * (1.0 - 1e-9):
        # one cluster that holds the weight the histogram was asked to cover: the belief is unimodal
        return Estimate(mean.copy(), mean, std, cov, 1.0, 1, n_eff, std, cov)
    best = int(np.argmax(share))
    sel = labels == best
    wb = w[sel] / share[best]
    pose, ccov, cstd = _weighted_stats(p[sel], wb)
    n_clusters = int(np.count_nonzero(share >= max(min_share, 1e-12)))
    return Estimate(pose, mean, std, cov, float(share[best]), max(n_clusters, 1), n_eff, cstd, ccov)


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
