"""Resampling: turning weighted particles into equally weighted ones.

A particle filter carries ``N`` particles with importance weights. Resampling
draws ``N`` new particles from the old ones, particle ``i`` being picked with
probability ``w_i``, so that afterwards all weights are equal again. Every
resampler here returns the *indices* of the chosen particles: the new particle
set is ``particles[idx]``.

All four resamplers are *unbiased*: the expected number of copies (offspring)
of particle ``i`` is exactly ``N * w_i``. They differ in the *variance* of the
offspring counts, i.e. in how much randomness resampling adds:

* :func:`multinomial` — ``N`` independent spins of a roulette wheel whose
  slices are the weights (Gordon, Salmond and Smith 1993). Largest variance.
* :func:`stratified` — one uniform draw in each of ``N`` equal strata of
  ``[0, 1)`` (Kitagawa 1996).
* :func:`systematic` — one uniform offset shared by ``N`` equally spaced
  pointers: the *low-variance sampler* of *Probabilistic Robotics* (Thrun,
  Burgard and Fox 2005, table 4.4). Fast and the usual choice.
* :func:`residual` — ``floor(N * w_i)`` copies deterministically, the
  remaining few drawn at random from the fractional parts (Liu and Chen 1998).

Each has a readable loop version (``*_loop``) that mirrors the pseudocode and
serves as the test oracle, and a vectorised version used by the filters.
Weights need not be normalised (they are divided by their sum); they must be
finite and non-negative with a positive sum.

Log-weights
-----------
Filters keep log-weights, because a product of hundreds of beam likelihoods
underflows to zero in linear space. :func:`normalize_log_weights` turns them
into normalised weights with the log-sum-exp trick. When *no* particle has a
usable weight (every log-weight is ``-inf`` or NaN) the measurement carries no
information the filter can use; the function then returns uniform weights and
``log_norm = -inf`` as a flag that callers must check (or raises
:class:`DegenerateWeightsError` with ``strict=True``). NaN log-weights are
treated as ``-inf`` (weight zero), and their number is reported by
:func:`weight_diagnostics`.

References
----------
* Douc, Cappé and Moulines, "Comparison of resampling schemes for particle
  filtering", ISPA 2005 — the variance comparison of the four schemes.
* Kong, Liu and Wong, JASA 1994 — the effective sample size.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_number, check_rng

__all__ = [
    "DegenerateWeightsError",
    "multinomial",
    "stratified",
    "systematic",
    "residual",
    "multinomial_loop",
    "stratified_loop",
    "systematic_loop",
    "residual_loop",
    "RESAMPLERS",
    "get_resampler",
    "offspring_counts",
    "effective_sample_size",
    "effective_sample_size_log",
    "normalize_log_weights",
    "logsumexp",
    "weight_variance",
    "ess_from_weight_variance",
    "weight_variance_from_ess",
    "needs_resampling",
    "offspring_moments",
    "SIRResult",
    "bootstrap_filter",
]


class DegenerateWeightsError(ValueError):
    """Every log-weight is ``-inf`` or NaN: no particle explains the data.

    Raised by :func:`normalize_log_weights` with ``strict=True``. A filter
    usually recovers by keeping uniform weights (the measurement is ignored)
    or by re-initialising, and reports that it did so.
    """


# --------------------------------------------------------------------- checks
def _check_weights(weights: ArrayLike, name: str = "weights") -> NDArray[np.float64]:
    """Validated weights divided by their sum (float64, 1-D, non-empty).

    Any finite non-negative weights with a positive entry are accepted, from
    subnormal numbers to the largest float (``[1e308] * 3`` is three equal
    weights): they are scaled by their maximum before they are summed.
    """
    w = np.asarray(weights, dtype=float)
    if w.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of N particle weights; got shape {w.shape}")
    if w.size == 0:
        raise ValueError(f"{name} is empty; need at least one particle")
    if not np.all(np.isfinite(w)):
        k = int(np.flatnonzero(~np.isfinite(w))[0])
        raise ValueError(
            f"{name} must be finite; {name}[{k}] = {w[k]!r}. "
            "Carry log-weights and use normalize_log_weights() to avoid overflow and underflow"
        )
    if np.any(w < 0):
        k = int(np.flatnonzero(w < 0)[0])
        raise ValueError(f"{name} must be non-negative; {name}[{k}] = {w[k]!r}")
    top = w.max()
    if not top > 0:
        raise ValueError(
            f"{name} sum to zero; at least one weight must be positive "
            "(if every particle is impossible, re-initialise the filter or use uniform weights)"
        )
    # scale by the largest weight before summing: a sum of weights near the largest float
    # overflows to inf, and subnormal weights lose their digits when divided by their sum
    w = w / top
    return w / w.sum()


def _resampler_args(weights: ArrayLike, rng: Any, n: int | None) -> tuple[NDArray[np.float64], int]:
    """What every resampler checks: a generator, valid weights (normalised here) and the number of draws
    (one per particle when ``n`` is None, else a whole number >= 0)."""
    check_rng(rng)
    w = _check_weights(weights)
    return w, (w.size if n is None else check_count(n, "n", minimum=0))


def _check_threshold(threshold: float) -> float:
    """The adaptive-resampling threshold: a fraction of N in [0, 1]."""
    t = check_number(threshold, "threshold")
    if not 0.0 <= t <= 1.0:
        raise ValueError(f"threshold must be a fraction of N in [0, 1]; got {threshold!r}")
    return t


def _cdf(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cumulative sum of normalised weights whose last entry is exactly 1.0.

    Dividing by the last partial sum makes ``cdf[-1] == 1.0`` exactly, so no
    pointer in ``[0, 1)`` can fall beyond the end (filterpy's systematic and
    stratified resamplers index past the end when the plain cumulative sum
    rounds to just below one).
    """
    c = np.cumsum(w)
    c /= c[-1]
    return c


def _last_positive(w: NDArray[np.float64]) -> int:
    return int(np.flatnonzero(w > 0)[-1])


def _search(cdf: NDArray[np.float64], u: NDArray[np.float64], last: int) -> NDArray[np.int64]:
    """Index ``i`` with ``cdf[i-1] <= u < cdf[i]`` for each pointer ``u``.

    ``side="right"`` never selects a zero-weight particle (its interval is
    empty). A pointer that rounds up to 1.0 is mapped to the last particle
    with positive weight instead of running past the end.
    """
    idx = np.searchsorted(cdf, u, side="right")
    np.minimum(idx, last, out=idx)
    return idx.astype(np.int64, copy=False)


# ------------------------------------------------------ readable (oracles)
def multinomial_loop(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Multinomial resampling as a roulette wheel, one spin per new particle.

    The readable version of :func:`multinomial` (it is O(N^2): use it on
    small sets only). Each spin draws ``u`` uniformly in ``[0, 1)`` and walks
    along the wheel, whose slices are the normalised weights, until the
    running sum passes ``u``.

    Examples
    --------
    >>> multinomial_loop([0.0, 1.0, 0.0], np.random.default_rng(0))
    array([1, 1, 1])
    """
    w, n = _resampler_args(weights, rng, n)
    last = _last_positive(w)
    out = np.empty(n, dtype=np.int64)
    for m in range(n):
        u = rng.random()              # where the wheel stops
        i, c = 0, w[0]                # slice 0 covers [0, w[0])
        while u >= c and i < last:    # not in this slice yet: move on
            i += 1
            c += w[i]
        out[m] = i
    return out


def stratified_loop(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Stratified resampling, readable: one random pointer in each stratum.

    ``[0, 1)`` is cut into ``n`` equal strata; pointer ``m`` is uniform in
    ``[m/n, (m+1)/n)``. A single pass along the weights serves all pointers
    because they are increasing.

    Examples
    --------
    >>> stratified_loop([0.5, 0.5], np.random.default_rng(0))
    array([0, 1])
    """
    w, n = _resampler_args(weights, rng, n)
    last = _last_positive(w)
    u = (rng.random(n) + np.arange(n)) / n if n else np.empty(0)
    out = np.empty(n, dtype=np.int64)
    i, c = 0, w[0]
    for m in range(n):
        while u[m] >= c and i < last:
            i += 1
            c += w[i]
        out[m] = i
    return out


def systematic_loop(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Systematic (low-variance) resampling, readable: *Probabilistic Robotics* table 4.4.

    One random offset ``r`` in ``[0, 1/n)``; pointers ``r + m/n`` for
    ``m = 0..n-1``; one pass along the running sum of the weights. Two details
    differ from the printed pseudocode, both for robustness: the loop moves on
    while ``u >= c`` (not ``u > c``), so a particle of weight zero is never
    chosen even when ``r`` is exactly 0, and it never steps past the last
    particle with positive weight, whatever the rounding of the running sum.

    Examples
    --------
    >>> systematic_loop([0.1, 0.2, 0.3, 0.4], np.random.default_rng(3), n=10)
    array([0, 1, 1, 2, 2, 2, 3, 3, 3, 3])
    """
    w, n = _resampler_args(weights, rng, n)
    last = _last_positive(w)
    r = rng.random()
    out = np.empty(n, dtype=np.int64)
    i, c = 0, w[0]
    for m in range(n):
        u = (r + m) / n
        while u >= c and i < last:
            i += 1
            c += w[i]
        out[m] = i
    return out


def residual_loop(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Residual resampling, readable.

    Particle ``i`` first gets ``floor(n * w_i)`` copies. The ``R`` places
    left are filled by multinomial draws (roulette wheel) with probabilities
    proportional to the fractional parts ``n * w_i - floor(n * w_i)``. The
    expected number of copies is ``n * w_i`` exactly.

    Examples
    --------
    >>> residual_loop([0.5, 0.25, 0.25], np.random.default_rng(0), n=4)
    array([0, 0, 1, 2])
    """
    w, n = _resampler_args(weights, rng, n)
    out = []
    frac = np.empty(w.size)
    for i in range(w.size):
        copies = int(np.floor(n * w[i]))
        out.extend([i] * copies)
        frac[i] = n * w[i] - copies
    rest = n - len(out)
    if rest > 0:
        out.extend(multinomial_loop(frac, rng, n=rest).tolist())
    return np.sort(np.asarray(out, dtype=np.int64))


# --------------------------------------------------------------- fast paths
def _sorted_uniforms(n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``n`` i.i.d. uniforms on ``[0, 1)`` in increasing order, in O(n).

    The order statistics of ``n`` uniforms are distributed as the partial
    sums of ``n + 1`` standard exponentials divided by their total (Devroye,
    *Non-Uniform Random Variate Generation*, 1986, section V.2). Sorted
    pointers make the binary search cache-friendly.
    """
    e = rng.standard_exponential(n + 1)
    u = np.cumsum(e[:n])
    u /= u[-1] + e[n] if n else 1.0
    return u


def multinomial(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Multinomial resampling: ``n`` independent draws, ``P(i) = w_i``.

    Parameters
    ----------
    weights : array_like, shape (N,)
        Non-negative, finite importance weights with a positive sum (they are
        normalised here).
    rng : numpy.random.Generator
    n : int, optional
        Number of indices to draw (default ``N``).

    Returns
    -------
    ndarray of int64, shape (n,)
        Indices into the particle set, in increasing order. Particles of
        weight zero are never chosen.

    Notes
    -----
    Equal in distribution to :func:`multinomial_loop`, but O(N): it draws the
    ``n`` uniforms already sorted (:func:`_sorted_uniforms`) and finds their
    slices with one binary search.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> idx = multinomial([0.1, 0.0, 0.9], rng, n=8)
    >>> idx
    array([0, 2, 2, 2, 2, 2, 2, 2])
    >>> bool(np.all(idx != 1))
    True
    """
    w, n = _resampler_args(weights, rng, n)
    return _search(_cdf(w), _sorted_uniforms(n, rng), _last_positive(w))


def stratified(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Stratified resampling: one uniform pointer in each of ``n`` equal strata.

    Same parameters and return value as :func:`multinomial`. Uses the same
    random numbers as :func:`stratified_loop` and returns the same indices.

    Examples
    --------
    >>> stratified([0.25, 0.25, 0.5], np.random.default_rng(1))
    array([0, 2, 2])
    """
    w, n = _resampler_args(weights, rng, n)
    u = (rng.random(n) + np.arange(n)) / n if n else np.empty(0)
    return _search(_cdf(w), u, _last_positive(w))


def systematic(weights: ArrayLike, rng: np.random.Generator, n: int | None = None) -> NDArray[np.int64]:
    """Systematic (low-variance) resampling: ``n`` pointers ``1/n`` apart.

    Same parameters and return value as :func:`multinomial`. Particle ``i``
    gets either ``floor(n w_i)`` or ``ceil(n w_i)`` copies (in exact
    arithmetic: a pointer that rounds onto a segment boundary counts for the
    next particle, which can move one copy when ``r`` is within a few ulps of
    such a boundary). Uses the same
    random number as :func:`systematic_loop` and returns the same indices.

    Notes
    -----
    Instead of searching for each pointer, it counts the pointers that fall
    below each partial sum ``c_i``: pointers ``(r + m)/n < c_i`` number
    ``ceil(n c_i - r)``; differences of these counts are the offspring counts,
    and ``np.repeat`` expands them into indices. O(N) and no search.

    Examples
    --------
    >>> systematic([0.1, 0.2, 0.3, 0.4], np.random.default_rng(3), n=10)
    array([0, 1, 1, 2, 2, 2, 3, 3, 3, 3])
    """
    w, n = _resampler_args(weights, rng, n)
    r = rng.random()
    cdf = _cdf(w)
    k = np.ceil(n * cdf - r)
    np.clip(k, 0, n, out=k)
    k = k.astype(np.int64)
    k[_last_positive(w):] = n         # whatever the rounding, all n pointers are used
    counts = np.diff(k, prepend=0)
    return np.repeat(np.arange(w.size, dtype=np.int64), counts)


def residual(
    weights: ArrayLike,
    rng: np.random.Generator,
    n: int | None = None,
    remainder: str = "multinomial",
) -> NDArray[np.int64]:
    """Residual resampling: ``floor(n w_i)`` copies, the rest drawn from the remainders.

    Same parameters and return value as :func:`multinomial`, plus

    remainder : {"multinomial", "stratified", "systematic"}
        How the ``R = n - sum(floor(n w_i))`` remaining places are filled,
        from the fractional parts ``n w_i - floor(n w_i)`` (default
        multinomial, the classical scheme of Liu and Chen 1998).

    Notes
    -----
    Unbiased: the expected number of copies is ``floor(n w_i) + R * frac_i / R
    = n w_i``. (filterpy 2.0.0's ``residual_resample`` subtracts the copy
    counts from the *unscaled* weights ``w_i`` instead of ``n w_i``, which
    makes it biased towards heavy particles.)

    Examples
    --------
    >>> idx = residual([0.5, 0.3, 0.15, 0.05], np.random.default_rng(0))
    >>> np.bincount(idx, minlength=4)      # 2 and 1 copies are certain
    array([2, 1, 1, 0])
    """
    w, n = _resampler_args(weights, rng, n)
    if remainder not in ("multinomial", "stratified", "systematic"):
        raise ValueError(f"remainder must be 'multinomial', 'stratified' or 'systematic'; got {remainder!r}")
    scaled = n * w
    copies = np.floor(scaled)
    frac = scaled - copies
    copies = copies.astype(np.int64)
    rest = n - int(copies.sum())
    if rest > 0:
        extra = RESAMPLERS[remainder](frac, rng, n=rest)
        copies += np.bincount(extra, minlength=w.size)
    return np.repeat(np.arange(w.size, dtype=np.int64), copies)


RESAMPLERS: dict[str, Callable[..., NDArray[np.int64]]] = {
    "multinomial": multinomial,
    "stratified": stratified,
    "systematic": systematic,
    "residual": residual,
}
"""The fast resamplers by name (what ``MCL(resampler="systematic")`` looks up)."""


def get_resampler(name: str | Callable) -> Callable[..., NDArray[np.int64]]:
    """Look a resampler up by name; a callable is returned unchanged.

    Examples
    --------
    >>> get_resampler("systematic") is systematic
    True
    >>> get_resampler("roulette")
    Traceback (most recent call last):
    ...
    ValueError: unknown resampler 'roulette'; choose one of multinomial, stratified, systematic, residual
    """
    if callable(name):
        return name
    try:
        return RESAMPLERS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown resampler {name!r}; choose one of {', '.join(RESAMPLERS)}") from None


def offspring_counts(indices: ArrayLike, n_particles: int) -> NDArray[np.int64]:
    """Number of copies each of ``n_particles`` particles got from a resampling.

    Examples
    --------
    >>> offspring_counts([0, 0, 2, 2, 2], 4)
    array([2, 0, 3, 0])
    """
    idx = np.asarray(indices)
    if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
        raise ValueError(f"indices must be a 1-D integer array; got shape {idx.shape} and dtype {idx.dtype}")
    n_particles = int(n_particles)
    if idx.size and (idx.min() < 0 or idx.max() >= n_particles):
        raise ValueError(f"indices must lie in [0, {n_particles - 1}]; got range [{idx.min()}, {idx.max()}]")
    return np.bincount(idx, minlength=n_particles).astype(np.int64)


# ------------------------------------------------------------ log-weights
def logsumexp(log_weights: ArrayLike) -> float:
    """``log(sum(exp(a)))`` without overflow or underflow; ``-inf`` if all are ``-inf``.

    NaN entries are ignored (treated as ``-inf``).

    Examples
    --------
    >>> round(logsumexp([-1000.0, -1000.0]), 6)      # exp(-1000) underflows to 0
    -999.306853
    >>> logsumexp([-np.inf, -np.inf])
    -inf
    """
    a = np.asarray(log_weights, dtype=float)
    a = np.where(np.isnan(a), -np.inf, a)
    if a.size == 0:
        return -np.inf
    m = a.max()
    if not np.isfinite(m):
        return float(m)               # -inf (all impossible) or +inf
    return float(m + np.log(np.sum(np.exp(a - m))))


def _check_log_weights(log_weights: ArrayLike) -> NDArray[np.float64]:
    a = np.asarray(log_weights, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"log_weights must be a 1-D array of N log-weights; got shape {a.shape}")
    if a.size == 0:
        raise ValueError("log_weights is empty; need at least one particle")
    if np.any(np.isposinf(a)):
        k = int(np.flatnonzero(np.isposinf(a))[0])
        raise ValueError(
            f"log_weights[{k}] is +inf: an infinite likelihood (a density evaluated with zero spread?). "
            "Log-weights must be finite or -inf"
        )
    return a


def normalize_log_weights(
    log_weights: ArrayLike, strict: bool = False
) -> tuple[NDArray[np.float64], float]:
    """Normalised weights from log-weights, by the log-sum-exp trick.

    ``w_i = exp(a_i - L)`` with ``L = log(sum_j exp(a_j))`` computed after
    subtracting the largest ``a_j``, so nothing overflows and the best
    particle's weight never underflows.

    Parameters
    ----------
    log_weights : array_like, shape (N,)
        Log-weights; ``-inf`` is a particle of weight zero; NaN is treated as
        ``-inf``; ``+inf`` raises ``ValueError``.
    strict : bool
        What to do when every entry is ``-inf`` or NaN (see Returns).

    Returns
    -------
    weights : ndarray, shape (N,)
        Non-negative, summing to 1.
    log_norm : float
        ``L``, the log of the sum of the unnormalised weights. In a particle
        filter it is the log-likelihood of the measurement (up to the
        ``log N`` of the prior weights). **Degenerate case:** if every
        log-weight is ``-inf`` or NaN, the weights returned are uniform and
        ``log_norm`` is ``-inf`` — check ``np.isfinite(log_norm)`` — unless
        ``strict=True``, which raises :class:`DegenerateWeightsError`.

    Examples
    --------
    >>> w, L = normalize_log_weights([-1000.0, -1001.0, -np.inf])
    >>> w.round(6), round(L, 6)
    (array([0.731059, 0.268941, 0.      ]), -999.686738)
    >>> w, L = normalize_log_weights([-np.inf, np.nan])     # nothing fits
    >>> w, L
    (array([0.5, 0.5]), -inf)
    >>> normalize_log_weights([-np.inf, np.nan], strict=True)
    Traceback (most recent call last):
    ...
    localize.resample.DegenerateWeightsError: every log-weight is -inf or NaN ...
    """
    a = _check_log_weights(log_weights)
    a = np.where(np.isnan(a), -np.inf, a)
    m = a.max()
    if not np.isfinite(m):
        if strict:
            raise DegenerateWeightsError(
                f"every log-weight is -inf or NaN ({a.size} particles): no particle explains the "
                "measurement; re-initialise the filter or skip this update"
            )
        return np.full(a.size, 1.0 / a.size), -np.inf
    e = np.exp(a - m)
    s = e.sum()
    return e / s, float(m + np.log(s))


# ------------------------------------------------- effective sample size
def effective_sample_size(weights: ArrayLike) -> float:
    """Effective sample size ``N_eff = (sum w)^2 / sum w^2`` (Kong, Liu and Wong 1994).

    For normalised weights this is ``1 / sum w_i^2``: ``N`` when all weights
    are equal, 1 when one particle carries all the weight. Weights need not
    be normalised.

    Examples
    --------
    >>> effective_sample_size([1, 1, 1, 1])
    4.0
    >>> effective_sample_size([0, 0, 5, 0])
    1.0
    >>> round(effective_sample_size([0.7, 0.1, 0.1, 0.1]), 6)
    1.923077
    """
    w = _check_weights(weights)
    return float(1.0 / np.dot(w, w))


def effective_sample_size_log(log_weights: ArrayLike) -> float:
    """Effective sample size from log-weights; ``nan`` if every weight is zero.

    Examples
    --------
    >>> round(effective_sample_size_log([-2000.0, -2000.0, -np.inf]), 6)
    2.0
    """
    w, L = normalize_log_weights(log_weights)
    if not np.isfinite(L):
        return float("nan")
    return float(1.0 / np.dot(w, w))


def weight_variance(weights: ArrayLike) -> float:
    """Variance of the *normalised* weights, ``(1/N) sum (w_i - 1/N)^2``.

    This is the quantity the CMU 16-831 report of the book's sources thresholds to
    decide when to resample (there as a standard deviation). It is tied to
    the effective sample size by ``N_eff = N / (1 + N^2 Var(w))``, see
    :func:`ess_from_weight_variance`.

    Examples
    --------
    >>> weight_variance([1, 1, 1, 1])
    0.0
    >>> w = [0.7, 0.1, 0.1, 0.1]
    >>> round(weight_variance(w), 6), round(ess_from_weight_variance(weight_variance(w), 4), 6)
    (0.0675, 1.923077)
    """
    w = _check_weights(weights)
    return float(np.mean((w - 1.0 / w.size) ** 2))


def ess_from_weight_variance(variance: float, n: int) -> float:
    """``N_eff = N / (1 + N^2 Var(w))``: the ESS of ``N`` normalised weights with that variance.

    Follows from ``sum w_i^2 = N Var(w) + 1/N`` for weights that sum to one.

    Examples
    --------
    >>> ess_from_weight_variance(0.0, 1000)
    1000.0
    >>> round(ess_from_weight_variance(1e-6, 1000), 3)   # std 1e-3 halves N_eff
    500.0
    """
    n = check_count(n, "n")
    v = float(variance)
    if not v >= 0:
        raise ValueError(f"variance must be >= 0; got {variance!r}")
    return n / (1.0 + n * n * v)


def weight_variance_from_ess(ess: float, n: int) -> float:
    """Inverse of :func:`ess_from_weight_variance`: ``Var(w) = (N / N_eff - 1) / N^2``.

    Examples
    --------
    >>> weight_variance_from_ess(500, 1000)
    1e-06
    """
    n = check_count(n, "n")
    e = float(ess)
    if not 1.0 <= e <= n:
        raise ValueError(f"ess must lie in [1, n] = [1, {n}]; got {ess!r}")
    return (n / e - 1.0) / (n * n)


def needs_resampling(weights: ArrayLike, threshold: float = 0.5) -> bool:
    """Adaptive resampling rule: resample when ``N_eff < threshold * N``.

    ``threshold = 1`` resamples at (almost) every step, ``0`` never; 0.5 is
    the common choice (Doucet, Godsill and Andrieu 2000).

    Examples
    --------
    >>> needs_resampling([0.25, 0.25, 0.25, 0.25]), needs_resampling([0.97, 0.01, 0.01, 0.01])
    (False, True)
    """
    t = _check_threshold(threshold)
    w = _check_weights(weights)
    return bool(effective_sample_size(w) < t * w.size)


def offspring_moments(
    resampler: str | Callable, weights: ArrayLike, n_reps: int, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean and variance of each particle's offspring count over ``n_reps`` resamplings.

    The empirical check of a resampler: the mean must be ``N * w_i``
    (unbiasedness); the variance measures the noise resampling adds
    (multinomial: ``N w_i (1 - w_i)``).

    Examples
    --------
    >>> mean, var = offspring_moments("systematic", [0.5, 0.25, 0.25], 2000, np.random.default_rng(0))
    >>> mean.round(2), var.round(2)
    (array([1.5 , 0.75, 0.75]), array([0.25, 0.19, 0.19]))
    """
    fn = get_resampler(resampler)
    w = _check_weights(weights)
    n_reps = check_count(n_reps, "n_reps")
    counts = np.empty((n_reps, w.size))
    for k in range(n_reps):
        counts[k] = offspring_counts(fn(w, rng), w.size)
    return counts.mean(axis=0), counts.var(axis=0, ddof=1) if n_reps > 1 else np.zeros(w.size)


@dataclass(frozen=True, eq=False)
class SIRResult:
    """History of a :func:`bootstrap_filter` run (T steps, N particles).

    Attributes
    ----------
    particles : ndarray, shape (T, N, ...)
        Particles after the motion and the weighting of each step (before
        any resampling): with ``weights`` they represent the posterior.
    weights : ndarray, shape (T, N)
        Normalised weights of those particles.
    ess : ndarray, shape (T,)
        Effective sample size after weighting.
    resampled : ndarray of bool, shape (T,)
        Whether the step ended with resampling.
    log_evidence : ndarray, shape (T,)
        ``log p(z_k | z_1..k-1)`` estimated by the filter (``-inf`` when
        every particle was impossible; the weights were then kept uniform).
    """

    particles: NDArray
    weights: NDArray[np.float64]
    ess: NDArray[np.float64]
    resampled: NDArray[np.bool_]
    log_evidence: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.weights.shape[0])


def bootstrap_filter(
    initial: ArrayLike,
    steps: Iterable[tuple[Any, Any]],
    move: Callable[[NDArray, Any, np.random.Generator], NDArray] | None,
    log_likelihood: Callable[[NDArray, Any], NDArray],
    rng: np.random.Generator,
    resampler: str | Callable = "systematic",
    threshold: float = 1.0,
) -> SIRResult:
    """Sequential importance resampling (the bootstrap particle filter), for any state.

    The generic loop of Gordon, Salmond and Smith (1993) and of PR table 4.3,
    with adaptive resampling. For each step ``(u, z)``:

    1. *predict*: ``particles = move(particles, u, rng)`` (skipped when ``u``
       is None, e.g. at the first step);
    2. *weight*: ``log_w += log_likelihood(particles, z)``, normalised with
       log-sum-exp (skipped when ``z`` is None);
    3. *resample* if ``N_eff < threshold * N`` (always if ``threshold``
       is 1: the textbook loop): draw indices with ``resampler`` and reset
       the weights to ``1/N``.

    :class:`localize.mcl.MCL` is the same loop specialised to robot poses.

    Parameters
    ----------
    initial : array_like, shape (N, ...)
        Initial particles (equally weighted), e.g. samples of the prior.
    steps : iterable of (u, z)
        Controls and measurements.
    move : callable ``(particles, u, rng) -> particles``, or None
        Samples the motion model for all particles at once (None: a static
        state; every ``u`` must then be None).
    log_likelihood : callable ``(particles, z) -> (N,)``
        Log of ``p(z | x)`` for every particle.
    rng : numpy.random.Generator
    resampler : name or callable
        See :data:`RESAMPLERS`.
    threshold : float in [0, 1]
        Resample when ``N_eff < threshold * N``; 1 resamples after every
        measurement (even when the weights are all equal), 0 never.

    Returns
    -------
    SIRResult

    Examples
    --------
    Estimate a constant from noisy readings (true value 2.0):

    >>> rng = np.random.default_rng(0)
    >>> z = 2.0 + 0.5 * rng.standard_normal(20)
    >>> res = bootstrap_filter(
    ...     rng.uniform(-10, 10, 1000), [(None, zk) for zk in z],      # u = None: the state does not move
    ...     move=None, log_likelihood=lambda x, zk: -0.5 * ((zk - x) / 0.5) ** 2, rng=rng, threshold=0.5)
    >>> estimate = float(np.sum(res.weights[-1] * res.particles[-1]))
    >>> bool(abs(estimate - z.mean()) < 0.05), int(res.resampled.sum()) < 20   # the posterior mean is z's mean
    (True, True)
    """
    check_rng(rng)
    fn = get_resampler(resampler)
    t = _check_threshold(threshold)
    x = np.array(initial, dtype=float, copy=True)
    if x.ndim < 1 or x.shape[0] == 0:
        raise ValueError(f"initial must hold N >= 1 particles along its first axis; got shape {x.shape}")
    n = x.shape[0]
    logw = np.full(n, -np.log(n))
    hist_x, hist_w, ess, res, evid = [], [], [], [], []
    for u, z in steps:
        if u is not None:
            if move is None:
                raise ValueError("a step has a control u but move is None")
            x = np.asarray(move(x, u, rng), dtype=float)
        if z is not None:
            ll = np.asarray(log_likelihood(x, z), dtype=float)
            if ll.shape != (n,):
                raise ValueError(f"log_likelihood must return shape ({n},); got {ll.shape}")
            w, lnorm = normalize_log_weights(logw + ll)
        else:
            w, lnorm = normalize_log_weights(logw)
            lnorm = 0.0
        e = float(1.0 / np.dot(w, w))
        hist_x.append(x.copy())
        hist_w.append(w)
        ess.append(e)
        evid.append(lnorm)
        if z is not None and (t >= 1.0 or e < t * n):
            x = x[fn(w, rng)]
            logw = np.full(n, -np.log(n))
            res.append(True)
        else:
            with np.errstate(divide="ignore"):
                logw = np.log(w)
            res.append(False)
    if not hist_w:
        raise ValueError("steps is empty; need at least one (u, z) step")
    return SIRResult(particles=np.array(hist_x), weights=np.array(hist_w), ess=np.array(ess),
                     resampled=np.array(res), log_evidence=np.array(evid))
