"""Coarse-to-fine (multi-scale) histogram localization in a large tile world.

A histogram filter pays for every cell at every step, so a city-sized grid
of one-metre tiles is expensive. The multi-scale idea (Burgard, Fox, Hennig
and Schmidt 1996, "Estimating the absolute position of a mobile robot using
position probability grids"; Fox, Burgard and Thrun 1999, "Markov
localization for mobile robots in dynamic environments") is to
localize first on a coarse grid of *blocks* with a coarse sensor (which
district am I in?), and once one block holds nearly all the belief, to run
the fine filter (which colour is my tile?) only in a small window around
that block. The window follows the robot.

:class:`MultiScaleLocalizer` does that; :class:`SingleScaleLocalizer` runs the
fine filter on the whole world with the same sensors, as the baseline. Both
count the cells they update so that a chapter can show the saving.

The fine world is a 2-D array of tile labels; the coarse world holds one
label per ``block x block`` square of tiles. Rows count from the top, moves
are ``(drow, dcol)`` as in :mod:`localize.histogram`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import discrete
from . import histogram as hist
from ._checks import check_rng

__all__ = ["MultiScaleLocalizer", "SingleScaleLocalizer", "simulate_readings"]


def _check_worlds(fine: ArrayLike, coarse: ArrayLike, block: int) -> tuple[NDArray, NDArray, int]:
    f, c = np.asarray(fine), np.asarray(coarse)
    if f.ndim != 2 or c.ndim != 2:
        raise ValueError(f"fine and coarse worlds must be 2-D label arrays; got shapes {f.shape} and {c.shape}")
    b = int(block)
    if b < 1 or b != block:
        raise ValueError(f"block must be a whole number of tiles >= 1; got {block!r}")
    if f.shape != (c.shape[0] * b, c.shape[1] * b):
        raise ValueError(f"the fine world must be block x the coarse world: coarse {c.shape} x {b} = "
                         f"{(c.shape[0] * b, c.shape[1] * b)}, fine {f.shape}")
    return f, c, b


class SingleScaleLocalizer:
    """The baseline: one histogram filter over every tile, fed both sensors.

    Parameters
    ----------
    fine, coarse : array_like
        Tile labels and block labels (``fine.shape == coarse.shape * block``).
    block : int
        Tiles per block side.
    p_fine, p_coarse : (float, float)
        ``(p_hit, p_miss)`` of the tile-colour and the district sensors.
    fill : float
        Belief given to tiles entering from outside the world on a move.

    Examples
    --------
    >>> fine = np.array([[0, 1], [1, 0]]).repeat(2, 0).repeat(2, 1)
    >>> loc = SingleScaleLocalizer(fine, [[0, 1], [1, 0]], 2)
    >>> loc.step((0, 0), coarse_z=1, fine_z=1)
    >>> loc.cells_updated, loc.belief.shape
    (16, (4, 4))
    """

    def __init__(self, fine: ArrayLike, coarse: ArrayLike, block: int, p_fine=(0.85, 0.15),
                 p_coarse=(0.9, 0.1), fill: float = 1e-6) -> None:
        self.fine, self.coarse, self.block = _check_worlds(fine, coarse, block)
        self.p_fine, self.p_coarse, self.fill = tuple(p_fine), tuple(p_coarse), float(fill)
        self.belief = discrete.uniform(self.fine.shape)
        self._coarse_up = np.repeat(np.repeat(self.coarse, self.block, 0), self.block, 1)
        self.cells_updated = 0

    def step(self, step, coarse_z, fine_z) -> None:
        """Sense both readings at the current tile, then move by ``step``.

        Examples
        --------
        >>> fine = np.array([[0, 1], [1, 0]]).repeat(2, 0).repeat(2, 1)
        >>> loc = SingleScaleLocalizer(fine, [[0, 1], [1, 0]], 2, p_fine=(0.9, 0.1), p_coarse=(0.9, 0.1))
        >>> loc.step((0, 0), coarse_z=1, fine_z=1)
        >>> round(float(loc.belief[0, 2]), 3)    # one of the 8 tiles of colour 1, all in district 1
        0.123
        """
        lik = hist.likelihood(self.fine, fine_z, *self.p_fine) * hist.likelihood(self._coarse_up, coarse_z,
                                                                                   *self.p_coarse)
        self.belief = discrete.update(self.belief, lik)
        self.belief = hist.move(self.belief, step, fill=self.fill)
        self.cells_updated += self.belief.size

    def estimate(self) -> tuple[int, int]:
        """The most likely tile ``(row, col)``.

        Examples
        --------
        >>> loc = SingleScaleLocalizer(np.arange(4).reshape(2, 2), [[0]], 2, p_fine=(0.9, 0.1))
        >>> loc.step((0, 0), coarse_z=0, fine_z=3)
        >>> loc.estimate()
        (1, 1)
        """
        r, c = np.unravel_index(int(np.argmax(self.belief)), self.belief.shape)
        return int(r), int(c)


class MultiScaleLocalizer:
    """Coarse-to-fine histogram localization: blocks first, then tiles in a moving window.

    Phase ``"coarse"``: a histogram filter over the blocks, updated with the
    district reading. A one-tile move shifts a fraction ``1 / block`` of each
    block's belief into the neighbouring block (exact when the robot is
    uniformly spread inside its block). When the window of
    ``(2 * margin + 1) x (2 * margin + 1)`` blocks round the most likely block
    holds at least ``threshold`` of the belief, phase ``"fine"`` starts: a
    tile filter over that window, whose prior spreads
    each block's belief evenly over its tiles, updated with both readings.
    When the most likely tile comes within ``block // 2`` tiles of the
    window's edge, the window is re-centred (belief outside the new window is
    dropped, new tiles get ``fill``).

    Parameters
    ----------
    fine, coarse, block, p_fine, p_coarse, fill
        As for :class:`SingleScaleLocalizer`.
    threshold : float
        Belief the window must hold before the fine phase starts, in (0, 1].
    margin : int
        Blocks of context round the chosen block in the fine window (>= 1).

    Examples
    --------
    >>> fine = np.array([[0, 1], [1, 0]]).repeat(2, 0).repeat(2, 1)
    >>> loc = MultiScaleLocalizer(fine, [[0, 1], [1, 0]], 2, threshold=0.5)
    >>> loc.phase, loc.cells_updated
    ('coarse', 0)
    """

    def __init__(self, fine: ArrayLike, coarse: ArrayLike, block: int, p_fine=(0.85, 0.15),
                 p_coarse=(0.9, 0.1), fill: float = 1e-6, threshold: float = 0.95, margin: int = 1) -> None:
        self.fine, self.coarse, self.block = _check_worlds(fine, coarse, block)
        if not 0.0 < float(threshold) <= 1.0:
            raise ValueError(f"threshold must lie in (0, 1]; got {threshold!r}")
        if int(margin) < 1:
            raise ValueError(f"margin must be >= 1 block; got {margin!r}")
        self.p_fine, self.p_coarse = tuple(p_fine), tuple(p_coarse)
        self.fill, self.threshold, self.margin = float(fill), float(threshold), int(margin)
        self.coarse_belief = discrete.uniform(self.coarse.shape)
        self.phase = "coarse"
        self.window: tuple[int, int, int, int] | None = None   # r0, r1, c0, c1 in tiles
        self.belief: NDArray | None = None                     # fine belief over the window
        self.cells_updated = 0
        self.switched_at: int | None = None
        self._steps = 0

    # ---------------------------------------------------------------- coarse
    def _coarse_step(self, step, coarse_z) -> None:
        b = discrete.update(self.coarse_belief, hist.likelihood(self.coarse, coarse_z, *self.p_coarse))
        dr, dc = hist._step(step)
        k = np.zeros((3, 3))
        frac = 1.0 / self.block
        if dr == 0 and dc == 0:
            k[1, 1] = 1.0
        else:
            if abs(dr) + abs(dc) != 1:
                raise ValueError(f"step must be a unit move or (0, 0); got {step!r}")
            k[1, 1] = 1.0 - frac
            k[1 + dr, 1 + dc] = frac
        self.coarse_belief = hist.move(b, (0, 0), k, fill=self.fill)
        self.cells_updated += self.coarse_belief.size
        if self._window_mass() >= self.threshold:
            self._start_fine()

    def _window_mass(self) -> float:
        """Coarse belief inside the fine window that would be opened now."""
        br, bc = np.unravel_index(int(np.argmax(self.coarse_belief)), self.coarse_belief.shape)
        r0, r1, c0, c1 = (v // self.block for v in self._window_around(int(br) * self.block, int(bc) * self.block))
        return float(self.coarse_belief[r0:r1, c0:c1].sum())

    def _window_around(self, r: int, c: int) -> tuple[int, int, int, int]:
        """Window of whole blocks centred on tile (r, c)'s block, clipped to the world."""
        n = 2 * self.margin + 1
        br, bc = r // self.block, c // self.block
        hb, wb = self.coarse.shape
        r0 = min(max(br - self.margin, 0), max(hb - n, 0))
        c0 = min(max(bc - self.margin, 0), max(wb - n, 0))
        r1, c1 = min(r0 + n, hb), min(c0 + n, wb)
        return r0 * self.block, r1 * self.block, c0 * self.block, c1 * self.block

    def _start_fine(self) -> None:
        br, bc = np.unravel_index(int(np.argmax(self.coarse_belief)), self.coarse_belief.shape)
        r0, r1, c0, c1 = self._window_around(int(br) * self.block, int(bc) * self.block)
        up = np.repeat(np.repeat(self.coarse_belief, self.block, 0), self.block, 1)
        self.window = (r0, r1, c0, c1)
        self.belief = discrete.normalize(up[r0:r1, c0:c1] + self.fill)
        self.phase = "fine"
        self.switched_at = self._steps

    # ------------------------------------------------------------------ fine
    def _fine_step(self, step, coarse_z, fine_z) -> None:
        r0, r1, c0, c1 = self.window  # type: ignore[misc]
        fw = self.fine[r0:r1, c0:c1]
        cw = np.repeat(np.repeat(self.coarse, self.block, 0), self.block, 1)[r0:r1, c0:c1]
        lik = np.where(fw == fine_z, *self.p_fine) * np.where(cw == coarse_z, *self.p_coarse)
        b = discrete.update(self.belief, lik)
        self.belief = hist.move(b, step, fill=self.fill)
        self.cells_updated += self.belief.size
        r, c = self.estimate()
        edge = self.block // 2
        near = (r - r0 < edge and r0 > 0) or (r1 - 1 - r < edge and r1 < self.fine.shape[0]) or \
               (c - c0 < edge and c0 > 0) or (c1 - 1 - c < edge and c1 < self.fine.shape[1])
        if near:
            self._recentre(r, c)

    def _recentre(self, r: int, c: int) -> None:
        new = self._window_around(r, c)
        full = np.full(self.fine.shape, self.fill)
        r0, r1, c0, c1 = self.window  # type: ignore[misc]
        full[r0:r1, c0:c1] = self.belief
        n0, n1, m0, m1 = new
        self.window = new
        self.belief = discrete.normalize(full[n0:n1, m0:m1])

    # ---------------------------------------------------------------- public
    def step(self, step, coarse_z, fine_z) -> None:
        """Sense the readings of the current tile, then move by ``step`` (a unit move or ``(0, 0)``).

        Examples
        --------
        >>> fine = np.array([[0, 1], [1, 0]]).repeat(2, 0).repeat(2, 1)
        >>> loc = MultiScaleLocalizer(fine, [[0, 1], [1, 0]], 2, p_coarse=(0.99, 0.01), threshold=0.9)
        >>> loc.step((0, 0), coarse_z=1, fine_z=1)   # the coarse window of 2 x 2 blocks holds everything
        >>> loc.phase, loc.cells_updated
        ('fine', 4)
        """
        if self.phase == "coarse":
            self._coarse_step(step, coarse_z)
        else:
            self._fine_step(step, coarse_z, fine_z)
        self._steps += 1

    def estimate(self) -> tuple[int, int]:
        """The most likely tile (fine phase) or the centre tile of the most likely block (coarse phase).

        Examples
        --------
        >>> loc = MultiScaleLocalizer(np.zeros((8, 8), int), np.arange(16).reshape(4, 4), 2, threshold=0.99)
        >>> loc.step((0, 0), coarse_z=15, fine_z=0)
        >>> loc.phase, loc.estimate()               # the centre tile of block (3, 3)
        ('coarse', (7, 7))
        """
        if self.phase == "coarse":
            br, bc = np.unravel_index(int(np.argmax(self.coarse_belief)), self.coarse_belief.shape)
            return int(br) * self.block + self.block // 2, int(bc) * self.block + self.block // 2
        r, c = np.unravel_index(int(np.argmax(self.belief)), self.belief.shape)  # type: ignore[arg-type]
        return int(r) + self.window[0], int(c) + self.window[2]  # type: ignore[index]


def simulate_readings(fine: ArrayLike, coarse: ArrayLike, block: int, start: tuple[int, int], moves,
                      rng: np.random.Generator, p_correct_fine: float = 0.85,
                      p_correct_coarse: float = 0.9):
    """Drive a robot through ``moves`` from tile ``start`` and record noisy readings.

    At each step the robot first reads its tile's label and its block's label
    (each is right with the given probability, otherwise a uniformly chosen
    other label), then moves; a move that would leave the world is not made.

    Returns
    -------
    truth : ndarray, shape (T, 2)
        The tile the robot was on when it took each reading.
    fine_z, coarse_z : ndarray, shape (T,)
        The readings.

    Examples
    --------
    >>> fine = np.array([[0, 1], [1, 0]]).repeat(2, 0).repeat(2, 1)
    >>> t, f, c = simulate_readings(fine, [[0, 1], [1, 0]], 2, (0, 0), [(0, 1)] * 3,
    ...                             np.random.default_rng(0), 1.0, 1.0)
    >>> t.tolist(), f.tolist(), c.tolist()
    ([[0, 0], [0, 1], [0, 2]], [0, 0, 1], [0, 0, 1])
    """
    check_rng(rng)
    f, c, b = _check_worlds(fine, coarse, block)
    fl, cl = np.unique(f), np.unique(c)
    pos = np.array(start, dtype=int)
    truth, fz, cz = [], [], []

    def read(value, labels, p):
        if rng.random() < p or len(labels) == 1:
            return value
        others = labels[labels != value]
        return others[rng.integers(len(others))]

    for mv in moves:
        truth.append(pos.copy())
        fz.append(read(f[tuple(pos)], fl, p_correct_fine))
        cz.append(read(c[pos[0] // b, pos[1] // b], cl, p_correct_coarse))
        new = pos + hist._step(mv)
        if 0 <= new[0] < f.shape[0] and 0 <= new[1] < f.shape[1]:
            pos = new
    return np.array(truth), np.array(fz), np.array(cz)
