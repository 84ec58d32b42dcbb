"""How far a particle filter is from the answer it approximates, and an input that breaks resamplers.

The particle-filter chapters measure a filter against references instead of
trusting it:

* :func:`exact_corridor_posteriors` -- the exact Bayes filter of a ring
  corridor run (:func:`localize.sim.corridor_run`) on a fine grid
  (:mod:`localize.discrete`), as probability per 1 m cell;
* :func:`ring_histogram` -- a weighted particle cloud on the same ring, per
  1 m cell, and :func:`tv_distance` between the two;
* :func:`nearest_particle_distance` -- how far the particle nearest to the
  true pose is (particle deprivation, PR section 8.3.5);
* :class:`AlmostOne` -- a generator whose uniform numbers are the largest
  double below one, the worst case for a resampler's rounding.

Examples
--------
>>> p = ring_histogram([0.2, 0.7, 2.5], [0.25, 0.25, 0.5], length=4.0)
>>> p.tolist()
[0.5, 0.0, 0.5, 0.0]
>>> tv_distance(p, [0.25, 0.25, 0.25, 0.25])
0.5
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from . import discrete
from ._checks import check_count, check_poses, check_positive
from .geometry import as_poses, wrap_angle

__all__ = ["exact_corridor_posteriors", "ring_histogram", "tv_distance", "nearest_particle_distance", "AlmostOne"]

#: The motion kernel of :func:`exact_corridor_posteriors` reaches this many standard deviations each way.
KERNEL_SIGMAS = 3


def exact_corridor_posteriors(run, cells_per_m: int = 20) -> list[NDArray[np.float64]]:
    """The exact Bayes filter of a corridor run; its belief per 1 m cell at every step.

    The ring of ``run.length`` metres is cut into ``cells_per_m`` cells per
    metre; the belief starts uniform (the robot is lost), is moved by each
    control with a Gaussian kernel of ``run.sigma_move`` (out to
    :data:`KERNEL_SIGMAS` standard deviations) and weighted by
    ``exp(run.log_likelihood(cell centres, z))``: :func:`localize.discrete.predict`
    and :func:`localize.discrete.update`, the grid filter of the Bayes-filter
    chapter. Each step's belief is then summed per metre, the resolution at
    which :func:`ring_histogram` bins a particle cloud.

    Parameters
    ----------
    run : localize.sim.CorridorRun
        Uses its ``length``, ``sigma_move``, ``controls``, ``z`` and ``log_likelihood``.
    cells_per_m : int
        Grid cells per metre (5 cm by default).

    Examples
    --------
    >>> from localize.sim import corridor_run
    >>> run = corridor_run(np.random.default_rng(0), n_steps=3)
    >>> post = exact_corridor_posteriors(run)
    >>> len(post), post[0].shape == (int(run.length),), round(float(post[-1].sum()), 9)
    (3, True, 1.0)
    """
    cpm = check_count(cells_per_m, "cells_per_m")
    n_m = int(run.length)
    m = n_m * cpm
    centres = (np.arange(m) + 0.5) / cpm
    half = int(round(KERNEL_SIGMAS * float(run.sigma_move) * cpm))
    if half == 0:
        kernel = np.ones(1)
    else:
        kernel = stats.norm.pdf(np.arange(-half, half + 1) / cpm, 0, run.sigma_move)
        kernel /= kernel.sum()
    metre = np.floor(centres).astype(int)
    bel = discrete.uniform(m)
    per_metre = []
    for k in range(len(run)):
        if k > 0:
            bel = discrete.predict(bel, kernel, offset=int(round(run.controls[k] * cpm)))
        bel = discrete.update(bel, np.exp(run.log_likelihood(centres, run.z[k])))
        per_metre.append(np.bincount(metre, weights=bel, minlength=n_m))
    return per_metre


def ring_histogram(x: ArrayLike, weights: ArrayLike, length: float) -> NDArray[np.float64]:
    """Weighted particles at positions ``x`` on a ring of ``length`` metres, as probability per 1 m cell.

    Cell ``i`` holds the weight of the particles in ``[i, i + 1)`` (positions
    taken modulo the ``int(length)`` cells); the weights are normalised to sum
    to 1.

    Examples
    --------
    >>> ring_histogram([0.5, 3.5, 4.2], [1.0, 1.0, 2.0], length=4.0).tolist()
    [0.75, 0.0, 0.0, 0.25]
    """
    n = int(check_positive(length, "length", "metres"))
    pos = np.asarray(x, dtype=float).reshape(-1)
    w = np.asarray(weights, dtype=float).reshape(-1)
    if w.shape != pos.shape:
        raise ValueError(f"weights must have one entry per particle ({pos.size}); got {w.size}")
    if not (np.all(np.isfinite(w)) and np.all(w >= 0) and w.sum() > 0):
        raise ValueError("weights must be finite, >= 0 and not all zero")
    if not np.all(np.isfinite(pos)):
        raise ValueError("x must be finite positions in metres")
    return np.bincount(np.floor(pos).astype(np.int64) % n, weights=w / w.sum(), minlength=n)


def tv_distance(p: ArrayLike, q: ArrayLike) -> float:
    """Total variation distance ``0.5 * sum |p - q|`` of two distributions over the same cells.

    0 for identical distributions, 1 for disjoint ones. Both must be
    non-negative and sum to 1 (within 1e-6).

    Examples
    --------
    >>> tv_distance([1.0, 0.0], [0.0, 1.0]), tv_distance([0.5, 0.5], [0.5, 0.5])
    (1.0, 0.0)
    """
    a, b = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"p and q must have the same shape; got {a.shape} and {b.shape}")
    for name, v in (("p", a), ("q", b)):
        if not np.all(np.isfinite(v)) or np.any(v < 0) or abs(float(v.sum()) - 1.0) > 1e-6:
            raise ValueError(f"{name} must be a probability distribution (finite, >= 0, summing to 1); "
                             f"its sum is {float(v.sum()):.6g}")
    return float(0.5 * np.abs(a - b).sum())


def nearest_particle_distance(particles: ArrayLike, pose: ArrayLike, max_heading: float = 0.2) -> float:
    """Distance (m) from ``pose`` to the nearest particle whose heading is within ``max_heading`` (rad) of it.

    ``inf`` when no particle has such a heading. A filter whose nearest
    particle stays far from the truth is *deprived*: no scan can bring
    weight to a hypothesis that no particle represents (PR section 8.3.5).

    Examples
    --------
    >>> cloud = [[1.0, 0.0, 0.0], [0.3, 0.4, 3.0], [3.0, 4.0, 0.1]]
    >>> nearest_particle_distance(cloud, [0.0, 0.0, 0.0])     # the second points the wrong way
    1.0
    >>> nearest_particle_distance(cloud, [0.0, 0.0, 1.5])
    inf
    """
    p = check_poses(particles)
    x, y, th = as_poses(pose, "pose").reshape(3)
    mh = check_positive(max_heading, "max_heading", "radians")
    d = np.hypot(p[:, 0] - x, p[:, 1] - y)
    dh = np.abs(wrap_angle(p[:, 2] - th))
    return float(np.where(dh < mh, d, np.inf).min())


class AlmostOne(np.random.Generator):
    """A generator whose uniform numbers (``random``) are all the largest double below 1.

    The worst case for a resampler's rounding: a pointer just below 1 must
    still land on a particle when the weights' cumulative sum rounds below
    one (ten weights of 0.1 sum to 0.9999999999999999). Other methods are
    those of ``seed``: a bit generator, or an int that seeds PCG64.

    Examples
    --------
    >>> AlmostOne().random(2).tolist() == [np.nextafter(1.0, 0.0)] * 2
    True
    """

    def __init__(self, seed: int | np.random.BitGenerator = 0) -> None:
        super().__init__(seed if isinstance(seed, np.random.BitGenerator) else np.random.PCG64(seed))

    def random(self, size=None, dtype=np.float64, out=None):
        v = np.nextafter(1.0, 0.0)
        return float(v) if size is None else np.full(size, v)
