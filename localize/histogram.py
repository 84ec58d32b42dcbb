"""Histogram localization in a 2-D world of labelled tiles.

The world is a 2-D array of labels (colours, say): ``world[r, c]`` is the
label of the tile in row ``r`` and column ``c``. Rows are numbered from the
top as the world is printed (matrix order), so a move *up* is
``step = (-1, 0)`` and a move *left* is ``(0, -1)``. The robot carries a
sensor that reads the label of its tile correctly with probability-like
weight ``p_hit`` and reports it where the tile differs with weight
``p_miss`` (the weights need not sum to one: only their ratio matters after
normalisation).

* :func:`sense` is Bayes rule with that likelihood (PR table 4.1, line 4);
* :func:`move` shifts the belief by a commanded ``step`` and, with a
  ``kernel``, spreads it according to the motion noise (PR table 4.1,
  line 3, a convolution);
* :func:`noisy_step_kernel` builds the kernel of a robot that reaches the
  intended tile half of the time, slips diagonally forwards and sometimes
  stays put, rotated for each of the four moves.

The loops :func:`sense_readable` and :func:`move_readable` are the same steps
as the pseudocode reads; the tests hold the vectorised ones equal to them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import discrete
from ._checks import check_nonnegative
from .discrete import ZeroLikelihoodError, as_belief, as_kernel

__all__ = [
    "ZeroLikelihoodError",
    "STEPS",
    "likelihood",
    "sense",
    "move",
    "noisy_step_kernel",
    "sense_readable",
    "move_readable",
]

#: The four unit moves of the tile world, as (drow, dcol) with row 0 at the top.
STEPS = {"up": (-1, 0), "down": (1, 0), "left": (0, -1), "right": (0, 1)}
#: How far from 1 the motion kernel's probabilities may sum (round-off of decimal inputs such as 0.1).
_SUM_TOL = 1e-9


def _world(world: ArrayLike, shape: tuple[int, ...] | None) -> NDArray:
    w = np.asarray(world)
    if w.ndim != 2:
        raise ValueError(f"world must be a 2-D array of tile labels; got shape {w.shape}")
    if shape is not None and w.shape != shape:
        raise ValueError(f"world and belief must have the same shape; world has {w.shape}, belief has {shape}")
    return w


def likelihood(world: ArrayLike, measurement, p_hit: float, p_miss: float) -> NDArray[np.float64]:
    """``p(z | x)`` of reading ``measurement`` on every tile: ``p_hit`` where it matches, else ``p_miss``.

    Raises
    ------
    ValueError
        if no tile of ``world`` carries ``measurement`` (most likely a typo such
        as ``'blu'``; a colour the map does not contain cannot be localised on),
        or if the weights are negative or both zero.

    Examples
    --------
    >>> likelihood([["red", "blue"]], "blue", 0.85, 0.15)
    array([[0.15, 0.85]])
    """
    w = _world(world, None)
    ph, pm = check_nonnegative(p_hit, "p_hit"), check_nonnegative(p_miss, "p_miss")
    if ph == 0 and pm == 0:
        raise ValueError("p_hit and p_miss are both zero; at least one must be > 0")
    match = w == measurement
    if not np.any(match):
        labels = ", ".join(repr(v) for v in np.unique(w).tolist())
        raise ValueError(f"measurement {measurement!r} matches no tile of the world; its tiles carry {labels}")
    return np.where(match, ph, pm)


class _Required:
    """The default of the reading of :func:`sense`: none given (it may come as ``measurement=`` or ``z=``).

    A named sentinel, so that ``help(sense)`` shows ``measurement=<required>``
    instead of an ``<object object at 0x...>`` address.

    >>> _NO_Z
    <required>
    """

    def __repr__(self) -> str:
        return "<required>"


_NO_Z = _Required()


def sense(belief: ArrayLike, world: ArrayLike, measurement=_NO_Z, p_hit: float | None = None,
          p_miss: float | None = None, *, z=_NO_Z) -> NDArray[np.float64]:
    """Measurement update: multiply by ``p_hit`` where the tile matches the reading, ``p_miss`` elsewhere, normalise.

    The reading may also be passed as ``z=`` (the notation table's name for it).

    Parameters
    ----------
    belief : array_like, shape (R, C)
        Prior, sums to one.
    world : array_like, shape (R, C)
        Tile labels.
    measurement
        The label the sensor reported.
    p_hit, p_miss : float
        Likelihood weights (>= 0) of a reading that matches / does not match the tile.

    Raises
    ------
    ValueError
        bad belief, shape mismatch, unknown measurement, bad weights.
    ZeroLikelihoodError
        if the reading is impossible everywhere the belief is non-zero
        (e.g. ``p_miss = 0`` and the belief only covers tiles of other colours).

    Examples
    --------
    >>> world = np.array([["green", "blue", "green"]])
    >>> sense(np.full((1, 3), 1 / 3), world, "blue", 0.85, 0.15).round(3)
    array([[0.13 , 0.739, 0.13 ]])
    >>> sense(np.full((1, 3), 1 / 3), world, z="blue", p_hit=0.85, p_miss=0.15).round(3)
    array([[0.13 , 0.739, 0.13 ]])
    """
    if z is not _NO_Z:
        if measurement is not _NO_Z:
            raise TypeError("sense() got the reading twice: pass measurement=... or z=..., not both")
        measurement = z
    if measurement is _NO_Z or p_hit is None or p_miss is None:
        raise TypeError("sense(belief, world, measurement, p_hit, p_miss) needs the reading (measurement= or z=), "
                        "p_hit and p_miss")
    b = as_belief(belief)
    w = _world(world, b.shape)
    post = b * likelihood(w, measurement, p_hit, p_miss)   # checked weights: no need to re-check
    total = float(post.sum())
    if not total > 0.0:
        raise ZeroLikelihoodError(
            f"reading {measurement!r} is impossible wherever the belief is non-zero (p_hit={p_hit}, "
            f"p_miss={p_miss}); make p_miss > 0 or reset the belief")
    post /= total
    return post


def _step(step) -> tuple[int, int]:
    if isinstance(step, str):
        if step not in STEPS:
            raise ValueError(f"step must be one of {sorted(STEPS)} or a (drow, dcol) pair; got {step!r}")
        return STEPS[step]
    s = tuple(np.atleast_1d(np.asarray(step)).tolist())
    if len(s) != 2:
        raise ValueError(f"step must be a (drow, dcol) pair of whole numbers; got {step!r}")
    for v in s:
        if isinstance(v, bool) or not float(v).is_integer():
            raise TypeError(f"step must hold whole numbers of tiles; got {step!r}")
    return int(s[0]), int(s[1])


def move(belief: ArrayLike, step, kernel: ArrayLike | None = None, fill: float = 0.0, *,
         mode: str = "constant", normalize: bool = True) -> NDArray[np.float64]:
    """Motion update: shift the belief by ``step`` tiles, spread by ``kernel``, normalise.

    Parameters
    ----------
    belief : array_like, shape (R, C)
        Belief before the move, sums to one.
    step : (int, int) or str
        Commanded move ``(drow, dcol)``; row 0 is the top row, so ``(0, -1)``
        is one tile to the left. The names in :data:`STEPS` also work.
    kernel : array_like, shape (2a+1, 2b+1), optional
        Motion noise relative to the *intended* tile: ``kernel[a + dr, b + dc]``
        is the probability of ending ``(dr, dc)`` away from it
        (:func:`noisy_step_kernel` builds one). ``None`` is a perfect move.
    fill : float
        Belief assumed on the tiles outside the world (>= 0). A perfect move
        to the left leaves the rightmost column with ``fill``. The default 0
        is the exact Bayes prediction for a motion model you trust (and what a
        hand calculation gives); a small positive value (the book uses 0.001)
        keeps every tile possible, so the filter can recover if the robot in
        fact did not move. Belief moved off the world is dropped.
    mode : {"constant", "wrap"}
        ``"constant"`` (default): the bounded world just described.
        ``"wrap"``: a cyclic (torus) world; ``fill`` is ignored.
    normalize : bool
        Renormalise the result (default). ``False`` returns the raw sum of
        total probability, to compare with a hand calculation.

    Notes
    -----
    Why the defaults differ from :func:`localize.discrete.predict`: the tile
    world has edges, so ``move`` is bounded by default and loses the belief
    that leaves the floor; it therefore renormalises by default to return a
    distribution. ``discrete.predict`` models chapter 1's hallway, cyclic by
    default (``mode="wrap"``, as filterpy), where no mass is lost and nothing
    needs renormalising; in its bounded mode it leaves the sum below one on
    purpose so that the lost mass stays visible.

    Examples
    --------
    >>> b = np.array([[0.0, 0.5, 0.5]])
    >>> move(b, (0, -1), fill=0.0).round(3)
    array([[0.5, 0.5, 0. ]])
    >>> move(b, "left", kernel=[[0.0, 0.8, 0.2]]).round(3)   # 20 % of the time it stays
    array([[0.4, 0.5, 0.1]])
    """
    b = as_belief(belief)
    if b.ndim != 2:
        raise ValueError(f"belief must be a 2-D array over the tiles; got shape {b.shape}")
    k = np.ones((1, 1)) if kernel is None else as_kernel(kernel, 2)
    f = check_nonnegative(fill, "fill")
    out = discrete._predict(b, k, offset=_step(step), mode=mode, cval=f if mode == "constant" else 0.0)
    if not normalize:
        return out
    total = float(out.sum())
    if total <= 0.0:
        raise ZeroLikelihoodError("after the move no belief is left on the world (all of it moved off the edge "
                                  "and fill is 0); use fill > 0 or mode='wrap'")
    return out / out.sum()


def noisy_step_kernel(step, p_forward: float = 0.5, p_diagonal: float = 0.2,
                      p_stay: float = 0.1) -> NDArray[np.float64]:
    """A 3 x 3 motion kernel for a unit ``step``, relative to the intended tile.

    The robot reaches the intended tile with ``p_forward``, each of the two
    tiles diagonally ahead (beside the intended one) with ``p_diagonal``, and
    stays where it was with ``p_stay``; the model is drawn for "up" and
    rotated for the other three moves. The four numbers must sum to one.

    Examples
    --------
    >>> noisy_step_kernel("up")
    array([[0. , 0. , 0. ],
           [0.2, 0.5, 0.2],
           [0. , 0.1, 0. ]])
    >>> noisy_step_kernel((0, -1))     # left: staying put is one tile to the right of the target
    array([[0. , 0.2, 0. ],
           [0. , 0.5, 0.1],
           [0. , 0.2, 0. ]])
    """
    dr, dc = _step(step)
    if abs(dr) + abs(dc) != 1:
        raise ValueError(f"step must be one of the four unit moves (up, down, left, right); got {step!r}")
    pf, pd, ps = (check_nonnegative(v, n) for v, n in [(p_forward, "p_forward"), (p_diagonal, "p_diagonal"),
                                             (p_stay, "p_stay")])
    total = pf + 2 * pd + ps
    if abs(total - 1.0) > _SUM_TOL:
        raise ValueError(f"p_forward + 2 * p_diagonal + p_stay must be 1; got {total:.6g}")
    k = np.zeros((3, 3))
    k[1, 1] = pf
    k[1 - dr, 1 - dc] = ps            # staying = one step back from the target
    k[1 + dc, 1 + dr] += pd           # the two sideways neighbours of the target
    k[1 - dc, 1 - dr] += pd
    return k


def sense_readable(belief: ArrayLike, world: ArrayLike, measurement, p_hit: float, p_miss: float) -> NDArray:
    """:func:`sense` as loops over the tiles (the test oracle).

    Examples
    --------
    >>> sense_readable(np.full((1, 2), 0.5), [["a", "b"]], "a", 0.6, 0.2).round(3)
    array([[0.75, 0.25]])
    """
    b = as_belief(belief)
    w = _world(world, b.shape)
    likelihood(w, measurement, p_hit, p_miss)  # same checks as the fast path
    rows, cols = b.shape
    post = np.zeros_like(b)
    for r in range(rows):
        for c in range(cols):
            hit = w[r, c] == measurement
            post[r, c] = b[r, c] * (p_hit if hit else p_miss)
    total = post.sum()
    if total <= 0:
        raise ZeroLikelihoodError("the measurement is impossible wherever the belief is non-zero")
    return post / total


def move_readable(belief: ArrayLike, step, kernel: ArrayLike | None = None, fill: float = 0.0, *,
                  mode: str = "constant", normalize: bool = True) -> NDArray:
    """:func:`move` as loops: every tile (and every tile outside, holding ``fill``) pushes its belief
    to the tiles the robot may reach from it.

    Examples
    --------
    >>> move_readable(np.array([[0.0, 0.5, 0.5]]), (0, -1)).round(3)
    array([[0.5, 0.5, 0. ]])
    """
    b = as_belief(belief)
    k = np.ones((1, 1)) if kernel is None else as_kernel(kernel, 2)
    dr, dc = _step(step)
    rows, cols = b.shape
    kr, kc = k.shape[0] // 2, k.shape[1] // 2
    out = np.zeros_like(b)
    reach_r, reach_c = abs(dr) + kr, abs(dc) + kc
    if mode == "wrap":
        src_rows, src_cols = range(rows), range(cols)
    else:
        src_rows, src_cols = range(-reach_r, rows + reach_r), range(-reach_c, cols + reach_c)
    for r in src_rows:
        for c in src_cols:
            inside = 0 <= r < rows and 0 <= c < cols
            mass = b[r, c] if inside else fill
            for i in range(k.shape[0]):
                for j in range(k.shape[1]):
                    tr, tc = r + dr + i - kr, c + dc + j - kc
                    if mode == "wrap":
                        out[tr % rows, tc % cols] += mass * k[i, j]
                    elif 0 <= tr < rows and 0 <= tc < cols:
                        out[tr, tc] += mass * k[i, j]
    return out / out.sum() if normalize else out
