"""KLD-sampling: how many particles does the belief need right now?

Fox (2003), "Adapting the sample size in particle filters through
KLD-sampling", *International Journal of Robotics Research* 22(12), and
*Probabilistic Robotics* (Thrun, Burgard and Fox 2005), section 8.3.7 and
table 8.4.

The idea: cover the pose space with bins (say 0.5 m x 0.5 m x 10 degrees).
Draw particles from the weighted set one at a time and count ``k``, the number
of bins that have at least one particle. If the true posterior were a discrete
distribution over those ``k`` bins, then with probability ``1 - delta`` the
Kullback-Leibler divergence between the sample-based estimate and the truth is
below ``epsilon`` as soon as the number of samples reaches

    n(k) = (k - 1) / (2 epsilon) * (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z_{1-delta})^3,

the Wilson-Hilferty approximation of the chi-square quantile
``chi2_{k-1, 1-delta} / (2 epsilon)``. A belief spread over the whole map
fills many bins and asks for many particles; a belief concentrated on one
spot fills a few and needs only a few hundred.

:func:`kld_bound` is the formula, :func:`kld_sample_size` is the vectorised
stopping rule used by :class:`localize.mcl.MCL`, and
:func:`kld_sample_size_loop` is the same rule written as the loop of table 8.4
(the test oracle).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_number, check_positive
from .geometry import as_poses

__all__ = ["KLDSampling", "kld_bound", "bin_keys", "kld_sample_size", "kld_sample_size_loop", "pose_bins"]


def _check_eps_delta(epsilon: float, delta: float) -> tuple[float, float]:
    eps = check_positive(epsilon, "epsilon (the KL-divergence bound, e.g. 0.05)")
    dl = check_number(delta, "delta")
    if not 0.0 < dl < 1.0:
        raise ValueError(f"delta must lie in (0, 1) (probability that the bound fails), e.g. 0.01; got {delta!r}")
    return eps, dl


def _check_bin_size(bin_size: ArrayLike) -> NDArray[np.float64]:
    b = np.asarray(bin_size, dtype=float)
    if b.shape != (3,) or np.any(~np.isfinite(b)) or np.any(b <= 0):
        raise ValueError(f"bin_size must be three positive sizes (bx [m], by [m], btheta [rad]); got {bin_size!r}")
    return b


def kld_bound(k: ArrayLike, epsilon: float = 0.05, delta: float = 0.01) -> NDArray[np.float64] | float:
    """Number of samples KLD-sampling asks for when ``k`` bins are occupied.

    Parameters
    ----------
    k : int or array_like of int
        Number of non-empty bins, >= 1. For ``k = 1`` the bound is 0 (one
        bin needs no samples to be estimated; the minimum sample size of the
        filter applies instead).
    epsilon : float
        Allowed Kullback-Leibler divergence between the sample-based and the
        true (binned) posterior, > 0 (Fox uses 0.05 ... 0.2).
    delta : float
        Probability that the divergence exceeds ``epsilon``, in (0, 1).

    Returns
    -------
    float or ndarray
        ``(k-1)/(2 epsilon) * (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z)^3`` with
        ``z`` the upper ``1 - delta`` quantile of the standard normal
        (Fox 2003, eq. 11; PR table 8.4 line 16).

    Examples
    --------
    >>> round(float(kld_bound(2)), 1)           # two bins already need ~66 samples
    65.9
    >>> kld_bound([1, 10, 100, 1000], epsilon=0.05, delta=0.01).round(0)
    array([    0.,   217.,  1347., 11059.])
    """
    eps, dl = _check_eps_delta(epsilon, delta)
    kk = np.asarray(k, dtype=float)
    if np.any(~np.isfinite(kk)) or np.any(kk < 1):
        raise ValueError("k (number of non-empty bins) must be >= 1")
    z = NormalDist().inv_cdf(1.0 - dl)
    km1 = np.maximum(kk - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    n = km1 / (2.0 * eps) * (1.0 - a + np.sqrt(a) * z) ** 3
    n = np.where(kk > 1, n, 0.0)
    return float(n) if n.ndim == 0 else n


def bin_keys(poses: ArrayLike, bin_size: ArrayLike) -> NDArray[np.int64]:
    """One integer per pose naming its ``(x, y, theta)`` histogram bin.

    Two poses get the same key exactly when they fall in the same bin of
    side ``bin_size = (bx, by, btheta)`` (metres, metres, radians). Keys are
    only comparable within one call.

    Examples
    --------
    >>> p = np.array([[0.1, 0.1, 0.0], [0.4, 0.2, 0.05], [0.6, 0.1, 0.0]])
    >>> k = bin_keys(p, (0.5, 0.5, 0.2))
    >>> bool(k[0] == k[1]), bool(k[0] == k[2])
    (True, False)
    """
    p = as_poses(poses)
    if p.ndim != 2:
        raise ValueError(f"poses must be an (N, 3) array; got shape {p.shape}")
    b = _check_bin_size(bin_size)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.floor(p / b).astype(np.int64)
    idx -= idx.min(axis=0)
    span = idx.max(axis=0) + 1
    return (idx[:, 0] * span[1] + idx[:, 1]) * span[2] + idx[:, 2]


def _rule_inputs(poses: ArrayLike, bin_size: ArrayLike, epsilon: float, delta: float,
                 n_min: int) -> tuple[NDArray[np.int64], float, float, int]:
    """The stopping rule's inputs, checked once for both of its versions: the candidates' bin keys (at
    least one), ``epsilon`` and ``delta`` (see :func:`kld_bound`) and ``n_min``."""
    epsilon, delta = _check_eps_delta(epsilon, delta)
    n_min = check_count(n_min, "n_min")
    keys = bin_keys(poses, bin_size)
    if keys.size == 0:
        raise ValueError("poses is empty; need at least one candidate sample")
    return keys, epsilon, delta, n_min


def kld_sample_size(
    poses: ArrayLike,
    bin_size: ArrayLike,
    epsilon: float = 0.05,
    delta: float = 0.01,
    n_min: int = 100,
) -> int:
    """KLD-sampling stopping rule applied to a sequence of candidate samples.

    ``poses`` are candidate samples drawn one after another (i.i.d.) from the
    weighted particle set. The answer is the smallest ``n`` such that the
    first ``n`` candidates satisfy ``n >= n_min`` and ``n >= kld_bound(k(n))``,
    where ``k(n)`` counts the bins hit by the first ``n`` candidates. When no
    prefix satisfies the rule, all candidates are needed and ``len(poses)``
    is returned (the caller's ``n_max``).

    Vectorised over all prefixes at once: the first occurrence of each bin
    key marks where ``k`` grows.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> spot = rng.normal([2.0, 3.0, 0.0], [0.05, 0.05, 0.02], size=(5000, 3))
    >>> kld_sample_size(spot, (0.5, 0.5, 0.2), n_min=50) < 200        # concentrated: few
    True
    >>> wide = rng.uniform([0, 0, -np.pi], [20, 10, np.pi], size=(5000, 3))
    >>> kld_sample_size(wide, (0.5, 0.5, 0.2))                         # spread: all of them
    5000
    """
    keys, epsilon, delta, n_min = _rule_inputs(poses, bin_size, epsilon, delta, n_min)
    m = keys.size
    _, first = np.unique(keys, return_index=True)
    new_bin = np.zeros(m, dtype=np.int64)
    new_bin[first] = 1
    k = np.cumsum(new_bin)
    need = np.maximum(kld_bound(k, epsilon, delta), n_min)
    n = np.arange(1, m + 1)
    ok = n >= need
    return int(np.argmax(ok)) + 1 if ok.any() else m


_RULE = inspect.signature(kld_sample_size)  # the arguments and defaults of both versions of the rule


def kld_sample_size_loop(poses: ArrayLike, bin_size: ArrayLike, *rule: Any, **rule_kw: Any) -> int:
    """The same rule as :func:`kld_sample_size`, written as the loop of PR table 8.4.

    Readable and slow: the test oracle for the vectorised version. It takes
    :func:`kld_sample_size`'s arguments (``epsilon``, ``delta`` and ``n_min``,
    by position or keyword), with its defaults and its checks.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> p = rng.normal([0, 0, 0], [1.0, 1.0, 0.5], size=(3000, 3))
    >>> kld_sample_size_loop(p, (0.5, 0.5, 0.2)) == kld_sample_size(p, (0.5, 0.5, 0.2))
    True
    """
    args = _RULE.bind(poses, bin_size, *rule, **rule_kw)
    args.apply_defaults()
    keys, epsilon, delta, n_min = _rule_inputs(*args.args)
    occupied: set[int] = set()
    k = 0
    n_chi = 0.0
    n = 0
    for key in keys.tolist():
        n += 1
        if key not in occupied:
            occupied.add(key)
            k += 1
            if k > 1:
                n_chi = kld_bound(k, epsilon, delta)
        if n >= n_chi and n >= n_min:
            return n
    return n


#: The pose-space bin of :class:`KLDSampling` and :func:`pose_bins`: 0.5 m x 0.5 m x 10 degrees.
_DEFAULT_BIN = (0.5, 0.5, float(np.radians(10.0)))


def pose_bins(grid, bin_size: ArrayLike = _DEFAULT_BIN) -> int:
    """How many KLD histogram bins of the pose space the map's free space holds.

    ``free area / (bx * by) * (2 pi / btheta)``: with one particle per bin, a
    uniform cloud leaves few bins near the robot empty (for a Poisson cloud
    of one particle per bin, about 37% of the bins stay empty, against 90%
    with a tenth as many). The command line's initial cloud is this number
    (``localize run --particles auto``).

    Examples
    --------
    >>> from localize.maps import office
    >>> g = office()
    >>> area = g.free.sum() * g.resolution ** 2
    >>> pose_bins(g) == round(area / 0.25 * 36)
    True
    """
    b = _check_bin_size(bin_size)
    area = float(np.count_nonzero(grid.free)) * float(grid.resolution) ** 2
    return int(round(area / (b[0] * b[1]) * (2.0 * np.pi / b[2])))


@dataclass(frozen=True)
class KLDSampling:
    """Settings of KLD-sampling for :class:`localize.mcl.MCL`.

    Attributes
    ----------
    epsilon, delta : float
        The error bound and its confidence (see :func:`kld_bound`).
    bin_size : (float, float, float)
        Histogram bin of the pose space, (metres, metres, radians).
    n_min, n_max : int
        The particle count never falls below ``n_min`` nor exceeds ``n_max``.
    chunked : bool
        Draw the candidates in growing chunks (``max(4 n_min, 2 N)`` first,
        then all ``n_max``) instead of all ``n_max`` at once. Same rule, same
        distribution, far less work when ``n_max`` is a large initial cloud
        and the belief has shrunk (the command line's setting); a different
        random stream than the default.

    Examples
    --------
    >>> KLDSampling(epsilon=0.1).n_max
    20000
    """

    epsilon: float = 0.05
    delta: float = 0.01
    bin_size: tuple[float, float, float] = _DEFAULT_BIN
    n_min: int = 200
    n_max: int = 20_000
    chunked: bool = False

    def __post_init__(self) -> None:
        _check_eps_delta(self.epsilon, self.delta)
        _check_bin_size(self.bin_size)
        check_count(self.n_min, "n_min")
        if int(self.n_max) < int(self.n_min):
            raise ValueError(f"n_max must be >= n_min = {self.n_min}; got {self.n_max}")
