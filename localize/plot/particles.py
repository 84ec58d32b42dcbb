"""Figures of the chapter "Particle filters": samples, weights, resamplers, ESS.

Every function draws onto the ``ax`` (or axes) it is given, or a new figure,
and returns what it drew, so figures compose. Nothing here computes filter
results: pass arrays in.
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np
from numpy.typing import ArrayLike

from . import new_axes

__all__ = [
    "RESAMPLER_COLORS",
    "density_and_samples",
    "weighted_samples",
    "resampling_pointers",
    "offspring_variance_bars",
    "corridor_belief",
    "ess_trace",
]

RESAMPLER_COLORS = {"multinomial": "tab:red", "stratified": "tab:orange", "systematic": "tab:green",
                    "residual": "tab:purple", "filterpy residual": "tab:gray"}


def density_and_samples(pdf: Callable[[np.ndarray], np.ndarray], samples: ArrayLike, xlim: tuple[float, float],
                        ax=None, bins: int = 40, color: str = "tab:blue", label: str = "f(x)"):
    """A density curve, a histogram of samples scaled as a density, and the samples as a rug below.

    The picture of "a density represented by samples": where ``f`` is large
    the samples are dense.

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg")
    >>> from scipy.stats import norm
    >>> arts = density_and_samples(norm.pdf, np.random.default_rng(0).normal(size=200), (-4, 4))
    >>> sorted(arts)
    ['curve', 'histogram', 'rug']
    """
    _, ax = new_axes(ax, figsize=(7, 3))
    s = np.asarray(samples, dtype=float).reshape(-1)
    xs = np.linspace(xlim[0], xlim[1], 400)
    fx = np.asarray(pdf(xs), dtype=float)
    (curve,) = ax.plot(xs, fx, color="k", lw=2, label=label)
    hist = ax.hist(s, bins=bins, range=xlim, density=True, color=color, alpha=0.3,
                   label=f"histogram of {s.size} samples")
    top = max(float(fx.max()), float(np.max(hist[0])) if len(hist[0]) else 0.0)
    rug = ax.vlines(s, -0.12 * top, -0.02 * top, color=color, lw=0.8, alpha=0.7, label="samples (particles)")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlim(*xlim)
    ax.set_ylim(-0.15 * top, 1.15 * top)
    ax.set_xlabel("x")
    ax.legend(loc="upper right", fontsize=8)
    return {"curve": curve, "histogram": hist, "rug": rug}


def weighted_samples(samples: ArrayLike, weights: ArrayLike, ax=None, color: str = "tab:blue", label=None):
    """Draw weighted particles as stems whose height is the normalised weight.

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg")
    >>> stems = weighted_samples([0.0, 1.0], [1.0, 3.0])
    >>> stems.get_segments()[1][1].round(2).tolist()
    [1.0, 0.75]
    """
    _, ax = new_axes(ax, figsize=(7, 3))
    x = np.asarray(samples, dtype=float).reshape(-1)
    w = np.asarray(weights, dtype=float).reshape(-1)
    if x.shape != w.shape:
        raise ValueError(f"samples and weights must have the same length; got {x.size} and {w.size}")
    w = w / w.sum()
    stems = ax.vlines(x, 0, w, color=color, lw=1.0, alpha=0.8, label=label)
    ax.set_ylabel("normalised weight")
    return stems


def resampling_pointers(weights: ArrayLike, pointers: Mapping[str, ArrayLike], ax=None):
    """The cumulative weights as a ruler on [0, 1) and each scheme's pointers above it.

    Each row is one resampling scheme; particle ``i`` is chosen once for
    every pointer that falls into its segment ``[c_{i-1}, c_i)``.

    Parameters
    ----------
    weights : array_like, shape (N,)
    pointers : mapping name -> array of pointer positions in [0, 1)

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg")
    >>> ax = resampling_pointers([0.5, 0.3, 0.2], {"systematic": [0.1, 0.43, 0.77]})
    >>> [t.get_text() for t in ax.get_yticklabels()]
    ['weights', 'systematic']
    """
    import matplotlib.pyplot as plt

    _, ax = new_axes(ax, figsize=(8, 0.9 + 0.55 * len(pointers)))
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    c = np.concatenate([[0.0], np.cumsum(w)])
    cmap = plt.get_cmap("tab20")
    for i in range(w.size):
        ax.barh(0, w[i], left=c[i], height=0.6, color=cmap(i % 20), edgecolor="k", lw=0.5)
        if w[i] > 0.04:
            ax.text(c[i] + w[i] / 2, 0, str(i), ha="center", va="center", fontsize=8)
    names = list(pointers)
    for r, name in enumerate(names, start=1):
        u = np.asarray(pointers[name], dtype=float)
        ax.plot(u, np.full(u.shape, r), "v", color=RESAMPLER_COLORS.get(name, "k"), ms=6)
        ax.vlines(u, 0.3, r, color=RESAMPLER_COLORS.get(name, "k"), lw=0.5, alpha=0.4)
    ax.set_yticks(range(len(names) + 1))
    ax.set_yticklabels(["weights"] + names)
    ax.set_ylim(-0.8, len(names) + 0.6)
    ax.set_xlim(0, 1)
    ax.set_xlabel("cumulative weight")
    return ax


def offspring_variance_bars(weights: ArrayLike, variances: Mapping[str, ArrayLike], ax=None,
                            theory: bool = True):
    """Grouped bars: the offspring-count variance of each particle under each resampler.

    With ``theory`` the multinomial variance ``N w_i (1 - w_i)`` is drawn as
    a black step line for reference.

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg")
    >>> ax = offspring_variance_bars([0.5, 0.5], {"multinomial": [0.5, 0.5], "systematic": [0.0, 0.0]})
    >>> len(ax.patches)
    4
    """
    _, ax = new_axes(ax, figsize=(8, 3))
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    n = w.size
    k = len(variances)
    width = 0.8 / max(k, 1)
    idx = np.arange(n)
    for j, (name, v) in enumerate(variances.items()):
        ax.bar(idx - 0.4 + (j + 0.5) * width, np.asarray(v, dtype=float), width=width,
               color=RESAMPLER_COLORS.get(name, None), label=name)
    if theory:
        ax.step(np.r_[idx - 0.5, n - 0.5], np.r_[n * w * (1 - w), n * w[-1] * (1 - w[-1])], where="post",
                color="k", lw=1, label="N w (1 - w)")
    ax.set_xticks(idx)
    ax.set_xlabel("particle i")
    ax.set_ylabel("Var(offspring count)")
    ax.set_ylim(0, 1.3 * ax.get_ylim()[1])          # room for the legend above the bars
    ax.legend(fontsize=8, ncol=min(k + 1, 5), loc="upper center")
    return ax


def corridor_belief(run, particles: ArrayLike, weights: ArrayLike | None, step: int, ax=None,
                    bins: int | None = None, color: str = "tab:blue"):
    """The particle belief on the ring corridor at one step: weighted histogram, doors, true position.

    ``run`` is a :class:`localize.sim.CorridorRun`; ``particles`` and
    ``weights`` the particles (and weights) of that step.

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg")
    >>> from localize.sim import corridor_run
    >>> run = corridor_run(np.random.default_rng(0), n_steps=3)
    >>> ax = corridor_belief(run, np.random.default_rng(1).uniform(0, 20, 100), None, 0)
    >>> tuple(float(v) for v in ax.get_xlim())
    (0.0, 20.0)
    """
    _, ax = new_axes(ax, figsize=(8, 1.8))
    L = run.length
    x = np.asarray(particles, dtype=float).reshape(-1)
    w = np.full(x.size, 1.0 / x.size) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    bins = int(4 * L) if bins is None else int(bins)
    for j in np.flatnonzero(run.doors):
        ax.axvspan(j, j + 1, color="tan", alpha=0.35, lw=0)
    # one filled step artist instead of a bar patch per bin (ax.hist): several times faster to redraw
    counts, edges = np.histogram(x, bins=bins, range=(0, L), weights=w)
    ax.stairs(counts, edges, fill=True, color=color, alpha=0.85)
    ax.axvline(run.positions[step], color="tab:red", lw=2)
    ax.set_xlim(0, L)
    z = "door" if run.z[step] else "wall"
    ax.text(0.005, 0.92, f"step {step}: reads '{z}'", transform=ax.transAxes, fontsize=8, va="top")
    ax.set_yticks([])
    return ax


def ess_trace(ess: ArrayLike, n: int, resampled: ArrayLike | None = None, ax=None, threshold: float | None = None,
              label: str | None = None, color: str = "tab:blue"):
    """Effective sample size over time, with resampling steps marked and the threshold line.

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg")
    >>> ax = ess_trace([100, 60, 40, 100], 100, [False, False, True, False], threshold=0.5)
    >>> len(ax.lines)
    3
    """
    _, ax = new_axes(ax, figsize=(7, 2.5))
    e = np.asarray(ess, dtype=float)
    (line,) = ax.plot(np.arange(e.size), e, color=color, lw=1.5, label=label)
    if resampled is not None:
        r = np.flatnonzero(np.asarray(resampled, dtype=bool))
        ax.plot(r, e[r], "o", color=color, ms=4, mfc="white")
    if threshold is not None:
        ax.axhline(threshold * n, color="0.4", ls="--", lw=1)
    ax.set_ylim(0, 1.05 * n)
    ax.set_xlabel("step")
    ax.set_ylabel("N_eff")
    return ax
