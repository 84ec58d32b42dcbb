"""The discrete Bayes filter: a belief held as a histogram over cells.

The Bayes filter (Thrun, Burgard and Fox, *Probabilistic Robotics*, 2005,
table 2.1; "PR" below) alternates two steps on a belief ``bel(x)``:

* **prediction** (total probability): ``bel_bar(x) = sum_x' p(x | u, x') bel(x')``.
  When the motion is the same everywhere, ``p(x | u, x')`` depends only on
  ``x - x'`` and the sum is a *convolution* of the belief with a motion kernel;
* **correction** (Bayes rule): ``bel(x) = eta * p(z | x) * bel_bar(x)``, where
  ``eta`` is whatever number makes the belief sum to one (normalisation).

On a grid of cells (PR table 4.1, the discrete Bayes filter) both steps are
array operations: :func:`predict` shifts and convolves, :func:`update`
multiplies and normalises. Both accept beliefs of any dimension (a 1-D
hallway, a 2-D tile world, ...). The functions mirror
``filterpy.discrete_bayes`` (same numbers; the tests check it) but check
their input: a belief must be finite, non-negative and sum to one, a kernel
must sum to one, shapes must agree, and a measurement that every cell finds
impossible raises :class:`ZeroLikelihoodError` instead of returning NaN.

:func:`predict_readable` and :func:`update_readable` are the same steps
written as loops over cells, the way the pseudocode reads; the tests hold
the fast versions equal to them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

__all__ = [
    "ZeroLikelihoodError",
    "as_belief",
    "as_kernel",
    "normalize",
    "uniform",
    "shift",
    "predict",
    "update",
    "predict_readable",
    "update_readable",
]

#: How far from one the sum of a belief or kernel may be (absolute).
SUM_TOLERANCE = 1e-6


class ZeroLikelihoodError(ValueError):
    """The measurement has zero probability wherever the belief is non-zero.

    Multiplying the prior by such a likelihood leaves nothing to normalise
    (``0 / 0``). It means the sensor model rules out every place the robot
    could be: a wrong model, a wrong map, or a prior that was too sure.
    A filter can catch this (it is a ``ValueError``) and recover, e.g. by
    re-initialising to a uniform belief.
    """


def _finite_nonnegative(a: NDArray, name: str, total: float | None = None) -> float:
    """Raise unless every entry is finite and >= 0; return the sum (one comparison pass and one sum)."""
    s = float(a.sum()) if total is None else total
    if np.isfinite(s) and bool((a >= 0).all()):
        return s
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ValueError(f"{name} contains NaN or infinite values (first at index {tuple(int(i) for i in bad)}); "
                         "probabilities must be finite numbers in [0, 1]")
    if np.any(a < 0):
        bad = np.argwhere(a < 0)[0]
        raise ValueError(f"{name} contains negative values (first {float(a[tuple(bad)])!r} at index "
                         f"{tuple(int(i) for i in bad)}); probabilities must be >= 0")
    raise ValueError(f"{name} sums to {s!r}; its entries are too large to add up")


def as_belief(belief: ArrayLike, name: str = "belief", atol: float = SUM_TOLERANCE) -> NDArray[np.float64]:
    """Check that ``belief`` is a probability distribution and return it as a float array.

    A belief must be non-empty, finite, non-negative and sum to one within
    ``atol``. The array is not copied when it is already a float array.

    Raises
    ------
    ValueError
        naming ``name``, what was wrong and the allowed range.

    Examples
    --------
    >>> as_belief([0.25, 0.75])
    array([0.25, 0.75])
    >>> as_belief([0.5, 0.6])
    Traceback (most recent call last):
    ...
    ValueError: belief must sum to 1 (within 1e-06); it sums to 1.1. Normalise it first (localize.discrete.normalize).
    """
    b = np.asarray(belief, dtype=float)
    if b.size == 0:
        raise ValueError(f"{name} is empty; it needs at least one cell")
    s = _finite_nonnegative(b, name)
    if abs(s - 1.0) > atol:
        raise ValueError(f"{name} must sum to 1 (within {atol:g}); it sums to {s:.6g}. "
                         "Normalise it first (localize.discrete.normalize).")
    return b


def as_kernel(kernel: ArrayLike, ndim: int, name: str = "kernel") -> NDArray[np.float64]:
    """Check a motion kernel: ``ndim`` dimensions, odd length on each axis, probabilities summing to one.

    The centre element (index ``len // 2`` on each axis) is the probability of
    landing exactly where the commanded motion leads.

    Examples
    --------
    >>> as_kernel([0.1, 0.8, 0.1], 1)
    array([0.1, 0.8, 0.1])
    >>> as_kernel([0.5, 0.5], 1)
    Traceback (most recent call last):
    ...
    ValueError: kernel must have an odd length on every axis so that it has a centre; got shape (2,)
    """
    k = np.asarray(kernel, dtype=float)
    if k.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), like the belief; got shape {k.shape}")
    if any(n % 2 == 0 for n in k.shape):
        raise ValueError(f"{name} must have an odd length on every axis so that it has a centre; got shape {k.shape}")
    s = _finite_nonnegative(k, name)
    if abs(s - 1.0) > SUM_TOLERANCE:
        raise ValueError(f"{name} must sum to 1 (it is a probability distribution over displacements); "
                         f"it sums to {s:.6g}")
    return k


def normalize(p: ArrayLike) -> NDArray[np.float64]:
    """Scale non-negative numbers so that they sum to one (returns a new array).

    Unlike ``filterpy.discrete_bayes.normalize`` the input is not modified.

    Raises
    ------
    ValueError
        if ``p`` has negative, NaN or infinite entries.
    ZeroLikelihoodError
        if ``p`` sums to zero (there is nothing to normalise).

    Examples
    --------
    >>> normalize([1, 1, 2])
    array([0.25, 0.25, 0.5 ])
    """
    a = np.asarray(p, dtype=float)
    if a.size == 0:
        raise ValueError("p is empty; it needs at least one cell")
    s = _finite_nonnegative(a, "p")
    if s <= 0.0:
        raise ZeroLikelihoodError("p sums to zero: there is no probability mass to normalise "
                                  "(every cell was ruled out)")
    return a / s


def uniform(shape: int | tuple[int, ...], mask: ArrayLike | None = None) -> NDArray[np.float64]:
    """A uniform belief over ``shape`` (or over the cells where ``mask`` is True).

    Examples
    --------
    >>> uniform(4)
    array([0.25, 0.25, 0.25, 0.25])
    >>> uniform(3, mask=[True, False, True])
    array([0.5, 0. , 0.5])
    """
    b = np.ones(shape, dtype=float)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != b.shape:
            raise ValueError(f"mask must have the belief's shape {b.shape}; got {m.shape}")
        if not m.any():
            raise ValueError("mask selects no cell; a belief needs at least one possible cell")
        b = m.astype(float)
    return b / b.sum()


def _offsets(offset: int | tuple[int, ...], ndim: int) -> tuple[int, ...]:
    offs = (offset,) if np.ndim(offset) == 0 else tuple(offset)  # type: ignore[arg-type]
    if len(offs) != ndim:
        raise ValueError(f"offset must have one entry per belief axis ({ndim}); got {offset!r}")
    out = []
    for o in offs:
        if isinstance(o, (bool, np.bool_)) or not float(o).is_integer():
            raise TypeError(f"offset must be a whole number of cells; got {o!r}")
        out.append(int(o))
    return tuple(out)


def shift(belief: NDArray, offset: tuple[int, ...], mode: str = "wrap", cval: float = 0.0) -> NDArray:
    """Move every cell's value by whole cells ``offset`` (wrap around, or drop and fill with ``cval``).

    Examples
    --------
    >>> shift(np.array([1.0, 2.0, 3.0]), (1,), mode="constant")
    array([0., 1., 2.])
    """
    if mode == "wrap":
        return np.roll(belief, offset, axis=tuple(range(belief.ndim)))
    out = np.full_like(belief, cval)
    src, dst = [], []
    for n, o in zip(belief.shape, offset):
        if abs(o) >= n:
            return out
        src.append(slice(max(0, -o), n - max(0, o)))
        dst.append(slice(max(0, o), n - max(0, -o)))
    out[tuple(dst)] = belief[tuple(src)]
    return out


def _check_mode(mode: str) -> None:
    if mode not in ("wrap", "constant"):
        raise ValueError(f"mode must be 'wrap' (a cyclic world) or 'constant' (a bounded world); got {mode!r}")


def predict(belief: ArrayLike, kernel: ArrayLike, offset: int | tuple[int, ...] = 0, mode: str = "wrap",
            cval: float = 0.0) -> NDArray[np.float64]:
    """Prediction step: move the belief by ``offset`` cells, blurred by the motion ``kernel``.

    Computes ``bel_bar(x) = sum_x' p(x | x') bel(x')`` where the robot is
    commanded to move by ``offset`` cells and ``kernel[c + d]`` (``c`` the
    kernel's centre) is the probability that it ends ``d`` cells beyond the
    commanded cell. This is a shift followed by a convolution (PR table 4.1,
    line 3). Same numbers as ``filterpy.discrete_bayes.predict(belief,
    offset, kernel)`` in a cyclic world (see ``mode`` for bounded ones).

    Parameters
    ----------
    belief : array_like
        Prior belief, any number of dimensions, sums to one.
    kernel : array_like
        Motion noise, same number of dimensions, odd length per axis, sums to one.
    offset : int or tuple of int
        Commanded move in cells (one entry per axis; positive = towards higher index).
    mode : {"wrap", "constant"}
        ``"wrap"``: a cyclic world, mass leaving one end enters the other.
        ``"constant"``: a bounded world, mass leaving it is lost and the cells
        outside count as holding ``cval``. The result is then *not*
        renormalised (call :func:`normalize`), so the lost mass is visible.
        Shift and blur act together on each source cell, so a robot on the
        last cell that undershoots stays on the map; filterpy shifts first
        and blurs after, which loses that mass (the two agree away from the
        edges and everywhere with ``mode="wrap"``).
    cval : float
        Belief assumed outside a bounded world (``mode="constant"``), >= 0.

    Notes
    -----
    :func:`localize.histogram.move` (the 2-D tile world) has the opposite
    defaults, bounded and renormalising: its world has edges, so belief is
    lost at every move and must be renormalised. Here the default world is
    cyclic and conserves mass, so the result is returned as is.

    Returns
    -------
    ndarray
        The predicted belief ``bel_bar``, same shape.

    Examples
    --------
    >>> prior = predict([0, 1.0, 0, 0, 0], [0.1, 0.8, 0.1], offset=2)
    >>> prior.round(3)
    array([0. , 0. , 0.1, 0.8, 0.1])
    >>> predict([0, 0, 0, 0, 1.0], [0.1, 0.8, 0.1], offset=1).round(3)   # wraps round
    array([0.8, 0.1, 0. , 0. , 0.1])
    """
    return _predict(as_belief(belief), kernel, offset, mode, cval)


def _predict(b: NDArray[np.float64], kernel: ArrayLike, offset: int | tuple[int, ...] = 0, mode: str = "wrap",
             cval: float = 0.0) -> NDArray[np.float64]:
    """:func:`predict` for a belief that has already been checked."""
    k = as_kernel(kernel, b.ndim)
    _check_mode(mode)
    cval = float(cval)
    if not np.isfinite(cval) or cval < 0:
        raise ValueError(f"cval must be a finite probability >= 0; got {cval!r}")
    offs = _offsets(offset, b.ndim)
    if k.size == 1:       # a perfect move: a plain shift
        return shift(b, offs, mode, cval) * float(k.flat[0])
    if mode == "wrap":
        moved = np.roll(b, offs, axis=tuple(range(b.ndim)))
        return ndimage.convolve(moved, k, mode="wrap")
    # bounded world: pad with cval so that the shift and the blur act together on every
    # source cell (a robot on the last cell that undershoots stays on the map)
    # Sum one shifted copy per non-zero kernel entry: out[x] = sum_m k[m] * src[x - d_m] with
    # d_m = offset + m - centre, src = belief padded with cval (fast for the sparse motion kernels).
    pad = [abs(o) + n // 2 for o, n in zip(offs, k.shape)]
    big = np.pad(b, [(p, p) for p in pad], mode="constant", constant_values=cval)
    out = np.zeros_like(b)
    for m in zip(*np.nonzero(k)):
        d = [o + mi - n // 2 for o, mi, n in zip(offs, m, k.shape)]
        out += k[m] * big[tuple(slice(p - di, p - di + n) for p, di, n in zip(pad, d, b.shape))]
    return out


def update(belief: ArrayLike, likelihood: ArrayLike) -> NDArray[np.float64]:
    """Correction step: ``bel(x) = eta * likelihood(x) * belief(x)`` (Bayes rule, PR table 2.1 line 4).

    Parameters
    ----------
    belief : array_like
        Prior belief, sums to one.
    likelihood : array_like
        ``p(z | x)`` for every cell, same shape, finite and >= 0. It need not
        sum to one (it is a function of ``x``, not a distribution over it).

    Raises
    ------
    ZeroLikelihoodError
        if the likelihood is zero wherever the belief is non-zero.

    Examples
    --------
    >>> update([0.25, 0.25, 0.25, 0.25], [0.6, 0.2, 0.2, 0.6]).round(3)
    array([0.375, 0.125, 0.125, 0.375])
    """
    return _update(as_belief(belief), likelihood)


def _update(b: NDArray[np.float64], likelihood: ArrayLike) -> NDArray[np.float64]:
    """:func:`update` for a belief that has already been checked."""
    lik = np.asarray(likelihood, dtype=float)
    if lik.shape != b.shape:
        raise ValueError(f"likelihood must have the belief's shape {b.shape}; got {lik.shape}")
    _finite_nonnegative(lik, "likelihood")
    post = b * lik
    s = float(post.sum())
    if not s > 0.0:
        raise ZeroLikelihoodError(
            "the likelihood is zero wherever the belief is non-zero: the measurement is impossible under "
            "the sensor model and this prior. Check the model (a likelihood should rarely be exactly 0) "
            "or reset the belief."
        )
    return post / s


def predict_readable(belief: ArrayLike, kernel: ArrayLike, offset: int = 0, mode: str = "wrap",
                     cval: float = 0.0) -> NDArray[np.float64]:
    """:func:`predict` for a 1-D belief as loops, exactly as the total-probability sum reads.

    ``bel_bar[x] = sum over x' and d of bel[x'] * kernel[c + d]`` where the
    robot starting at ``x'`` ends at ``x = x' + offset + d``. Used as the
    oracle of the fast version.

    Examples
    --------
    >>> predict_readable([0, 1.0, 0, 0, 0], [0.1, 0.8, 0.1], offset=2).round(3)
    array([0. , 0. , 0.1, 0.8, 0.1])
    """
    b = as_belief(belief)
    k = as_kernel(kernel, 1)
    _check_mode(mode)
    n, c = len(b), len(k) // 2
    out = np.zeros(n)
    # every source cell outside a bounded world also holds cval
    reach = abs(offset) + len(k)
    sources = range(n) if mode == "wrap" else range(-reach, n + reach)
    for src in sources:
        mass = b[src] if 0 <= src < n else cval
        for m in range(len(k)):
            dst = src + offset + (m - c)
            if mode == "wrap":
                out[dst % n] += mass * k[m]
            elif 0 <= dst < n:
                out[dst] += mass * k[m]
    return out


def update_readable(belief: ArrayLike, likelihood: ArrayLike) -> NDArray[np.float64]:
    """:func:`update` as a loop: multiply cell by cell, then divide by the total.

    Examples
    --------
    >>> update_readable([0.5, 0.5], [0.9, 0.1]).round(3)
    array([0.9, 0.1])
    """
    b = as_belief(belief).ravel()
    lik = np.asarray(likelihood, dtype=float).ravel()
    post = np.zeros(len(b))
    total = 0.0
    for x in range(len(b)):
        post[x] = lik[x] * b[x]
        total += post[x]
    if total <= 0.0:
        raise ZeroLikelihoodError("the likelihood is zero wherever the belief is non-zero")
    for x in range(len(b)):
        post[x] /= total
    return post.reshape(np.shape(belief))
