"""Occupancy grids: the map every localizer in this book reads.

Convention (used by every loader and every algorithm in :mod:`localize`):
``grid.data[i, j]`` is the probability that the cell whose centre is at

    x = origin_x + (j + 0.5) * resolution
    y = origin_y + (i + 0.5) * resolution

is occupied. Row ``i`` grows with ``y`` (so plot with ``origin="lower"``),
column ``j`` grows with ``x``. **Unknown cells are NaN** — the only allowed
value outside ``[0, 1]``. For range sensing an unknown cell is treated as an
obstacle unless ``unknown_is_obstacle=False`` is given: a laser cannot see
through what the map does not know.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_positive, check_rng

__all__ = ["OccupancyGrid"]


class OccupancyGrid:
    """A 2-D occupancy grid map with metric coordinates.

    Parameters
    ----------
    data : array_like, shape (H, W)
        Occupancy probabilities in ``[0, 1]``; NaN marks unknown cells.
    resolution : float
        Cell side in metres, > 0.
    origin : (float, float)
        World coordinates of the lower-left corner of cell ``(0, 0)``.
    occupied_threshold : float
        Cells with ``data >= occupied_threshold`` are obstacles (default 0.5).
    unknown_is_obstacle : bool
        Whether unknown (NaN) cells block rays and count as obstacles in the
        distance field (default True).

    The grid is immutable: ``data`` is a read-only copy, which is what makes
    caching the distance field safe.

    Examples
    --------
    >>> g = OccupancyGrid.from_ascii('''
    ... #####
    ... #..?#
    ... #####
    ... ''', resolution=0.5)
    >>> g.shape, g.width_m, g.height_m
    ((3, 5), 2.5, 1.5)
    >>> g.world_to_cell([[0.75, 0.75]])       # row 1, column 1: a free cell
    array([[1, 1]])
    >>> bool(g.is_free([[0.75, 0.75]])[0]), bool(g.is_free([[1.75, 0.75]])[0])
    (True, False)
    """

    def __init__(
        self,
        data: ArrayLike,
        resolution: float,
        origin: ArrayLike = (0.0, 0.0),
        occupied_threshold: float = 0.5,
        unknown_is_obstacle: bool = True,
    ) -> None:
        arr = np.array(data, dtype=float, copy=True)
        if arr.ndim != 2:
            raise ValueError(
                f"data must be a 2-D array of occupancy probabilities (rows = y, columns = x); "
                f"got {arr.ndim} dimension(s) with shape {arr.shape}"
            )
        if arr.shape[0] == 0 or arr.shape[1] == 0:
            raise ValueError(f"data must have at least one row and one column; got shape {arr.shape}")
        if np.any(np.isinf(arr)):
            raise ValueError("data contains infinite values; use probabilities in [0, 1] and NaN for unknown")
        known = arr[~np.isnan(arr)]
        if known.size and (known.min() < 0.0 or known.max() > 1.0):
            bad = np.argwhere((arr < 0) | (arr > 1))[0]
            raise ValueError(
                "data must hold occupancy probabilities in [0, 1] (NaN marks unknown cells); "
                f"found {arr[tuple(bad)]!r} at row {bad[0]}, column {bad[1]}"
            )
        res = check_positive(resolution, "resolution", "metres per cell")
        org = np.asarray(origin, dtype=float)
        if org.shape != (2,):
            raise ValueError(f"origin must be a pair (x, y) in metres; got shape {org.shape}")
        if not np.all(np.isfinite(org)):
            raise ValueError(f"origin must be finite; got {tuple(org.tolist())}")
        thr = float(occupied_threshold)
        if not 0.0 < thr <= 1.0:
            raise ValueError(f"occupied_threshold must lie in (0, 1]; got {occupied_threshold!r}")
        arr.setflags(write=False)
        self._data = arr
        self._resolution = res
        org.setflags(write=False)
        self._origin = org
        self._threshold = thr
        self._unknown_is_obstacle = bool(unknown_is_obstacle)

    # ------------------------------------------------------------------ build
    @classmethod
    def from_ascii(
        cls,
        text: str,
        resolution: float = 1.0,
        origin: ArrayLike = (0.0, 0.0),
        occupied: str = "#",
        free: str = ". ",
        unknown: str = "?",
        **kwargs,
    ) -> "OccupancyGrid":
        """Build a grid from ASCII art: the first line of text is the top of the map.

        ``#`` is an obstacle, ``.`` or a space is free, ``?`` is unknown (the
        character sets can be changed). Leading and trailing blank lines are
        ignored; all remaining lines must have the same length.

        Examples
        --------
        >>> OccupancyGrid.from_ascii("#.\\n..").data
        array([[0., 0.],
               [1., 0.]])
        """
        lines = text.split("\n")
        while lines and not lines[0].strip():
            lines.pop(0)
        while lines and not lines[-1].strip():
            lines.pop()
        if not lines:
            raise ValueError("ASCII map is empty")
        width = len(lines[0])
        rows = []
        for k, line in enumerate(lines):
            if len(line) != width:
                raise ValueError(
                    f"ASCII map line {k + 1} has {len(line)} characters, expected {width} "
                    "(every line must have the same width)"
                )
            row = []
            for col, ch in enumerate(line):
                if ch in occupied:
                    row.append(1.0)
                elif ch in free:
                    row.append(0.0)
                elif ch in unknown:
                    row.append(np.nan)
                else:
                    raise ValueError(
                        f"ASCII map line {k + 1}, column {col + 1}: unexpected character {ch!r}; "
                        f"use {occupied!r} for obstacles, {free!r} for free and {unknown!r} for unknown"
                    )
            rows.append(row)
        return cls(np.array(rows[::-1]), resolution, origin, **kwargs)

    # ------------------------------------------------------------ properties
    @property
    def data(self) -> NDArray[np.float64]:
        """Occupancy probabilities, shape (H, W), read-only; NaN = unknown."""
        return self._data

    @property
    def resolution(self) -> float:
        """Cell side in metres."""
        return self._resolution

    @property
    def origin(self) -> NDArray[np.float64]:
        """World (x, y) of the lower-left corner of cell (0, 0)."""
        return self._origin

    @property
    def occupied_threshold(self) -> float:
        return self._threshold

    @property
    def unknown_is_obstacle(self) -> bool:
        return self._unknown_is_obstacle

    @property
    def shape(self) -> tuple[int, int]:
        return self._data.shape  # type: ignore[return-value]

    @property
    def width_m(self) -> float:
        """Extent along x in metres."""
        return self.shape[1] * self._resolution

    @property
    def height_m(self) -> float:
        """Extent along y in metres."""
        return self.shape[0] * self._resolution

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` for ``matplotlib.imshow(..., origin="lower")``."""
        x0, y0 = self._origin
        return (float(x0), float(x0 + self.width_m), float(y0), float(y0 + self.height_m))

    @cached_property
    def unknown(self) -> NDArray[np.bool_]:
        """Boolean mask of unknown cells."""
        m = np.isnan(self._data)
        m.setflags(write=False)
        return m

    @cached_property
    def occupied(self) -> NDArray[np.bool_]:
        """Boolean mask of cells known to be occupied (``data >= occupied_threshold``)."""
        with np.errstate(invalid="ignore"):
            m = self._data >= self._threshold
        m.setflags(write=False)
        return m

    @cached_property
    def obstacles(self) -> NDArray[np.bool_]:
        """Cells that stop a range sensor: occupied, plus unknown if ``unknown_is_obstacle``."""
        m = self.occupied | self.unknown if self._unknown_is_obstacle else self.occupied.copy()
        m.setflags(write=False)
        return m

    @cached_property
    def free(self) -> NDArray[np.bool_]:
        """Boolean mask of cells known to be free (known and below the threshold)."""
        m = ~self.occupied & ~self.unknown
        m.setflags(write=False)
        return m

    @cached_property
    def holes(self) -> NDArray[np.bool_]:
        """Unknown cells where the robot may stand: the holes of the mapped floor.

        A region of unknown cells (4-connected) is a hole when it does not reach
        the map's edge and more of the known cells along its border are open
        floor than not: free cells in a 3 x 3 block of free cells, the smallest
        patch of floor a grid can show. A hole is a patch of floor that the map
        left unknown (people standing there while it was built, glass, a region
        erased by hand), and the robot may well drive through it. The unknown
        that reaches the edge is the outside of the building; a region fenced
        by walls, or seen only through a door as the thin lines of free cells
        that a laser's rays leave, is space the robot did not reach. Global
        localization and its restarts draw particles here as well as in the
        free cells when the filter lets particles stand in unknown cells
        (:class:`localize.mcl.MCL`, ``unknown_allowed``), and the place search
        looks here (:func:`localize.placesearch.lattice`): a robot that starts
        in a hole is otherwise never looked for where it is.

        Examples
        --------
        >>> data = np.zeros((12, 12))
        >>> data[[0, -1], :] = data[:, [0, -1]] = 1.0      # a walled room
        >>> data[5:7, 3:5] = np.nan                        # a patch of its floor left unknown
        >>> data[8:11, 7] = 1.0                            # a closet in its corner, never looked into
        >>> data[8:11, 8:11] = np.nan
        >>> g = OccupancyGrid(data, 0.5)
        >>> int(g.unknown.sum()), np.argwhere(g.holes).tolist()
        (13, [[5, 3], [5, 4], [6, 3], [6, 4]])
        """
        from scipy import ndimage

        floor = ndimage.binary_opening(self.free, structure=np.ones((3, 3), dtype=bool))
        labels, n = ndimage.label(self.unknown)
        padded = np.pad(labels, 1)
        floor_n, other_n = np.zeros(n + 1), np.zeros(n + 1)
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):         # each known cell's neighbour's region
            nb = padded[1 + di:1 + di + labels.shape[0], 1 + dj:1 + dj + labels.shape[1]]
            border = ~self.unknown & (nb > 0)
            np.add.at(floor_n, nb[border & floor], 1)
            np.add.at(other_n, nb[border & ~floor], 1)
        hole = floor_n > other_n
        hole[np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))] = False
        hole[0] = False
        m = hole[labels]
        m.setflags(write=False)
        return m

    @cached_property
    def distance_field(self) -> NDArray[np.float64]:
        """Euclidean distance (metres) from each cell centre to the nearest obstacle centre.

        Computed once with :func:`scipy.ndimage.distance_transform_edt` and
        cached. Obstacle cells hold 0. A map with no obstacle at all gets
        ``inf`` everywhere.
        """
        from scipy.ndimage import distance_transform_edt

        obst = self.obstacles
        if not obst.any():
            d = np.full(self.shape, np.inf)
        else:
            d = distance_transform_edt(~obst, sampling=self._resolution)
        d = np.asarray(d, dtype=float)
        d.setflags(write=False)
        return d

    # ------------------------------------------------------------ transforms
    def _points(self, points: ArrayLike, name: str = "points") -> NDArray[np.float64]:
        p = np.asarray(points, dtype=float)
        if p.ndim == 0 or p.shape[-1] < 2:
            raise ValueError(f"{name} must have shape (..., 2) holding (x, y); got shape {p.shape}")
        return p[..., :2]

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """True where a world point ``(x, y)`` (or pose) lies inside the map's extent.

        NaN points are outside.
        """
        p = self._points(points)
        rel = (p - self._origin) / self._resolution
        with np.errstate(invalid="ignore"):
            return (
                (rel[..., 0] >= 0) & (rel[..., 0] < self.shape[1])
                & (rel[..., 1] >= 0) & (rel[..., 1] < self.shape[0])
            )

    def world_to_cell(self, points: ArrayLike, outside: str = "raise") -> NDArray[np.int64]:
        """Cell indices ``(i, j)`` = (row, column) of world points, shape ``(..., 2)``.

        Parameters
        ----------
        points : array_like, shape (..., 2) or (..., 3)
            World coordinates (a pose's heading is ignored).
        outside : {"raise", "clip", "flag"}
            What to do with points outside the map: raise ``ValueError``
            (default, with the count and the first offending point), clip to
            the nearest border cell, or return ``-1`` for both indices.
            Points are never wrapped around.
        """
        if outside not in ("raise", "clip", "flag"):
            raise ValueError(f"outside must be 'raise', 'clip' or 'flag'; got {outside!r}")
        p = self._points(points)
        inside = self.contains(p)
        rel = (p - self._origin) / self._resolution
        with np.errstate(invalid="ignore"):
            j = np.floor(np.nan_to_num(rel[..., 0], nan=-1.0)).astype(np.int64)
            i = np.floor(np.nan_to_num(rel[..., 1], nan=-1.0)).astype(np.int64)
        if not np.all(inside):
            if outside == "raise":
                n_bad = int(np.size(inside) - np.count_nonzero(inside))
                first = p[~inside][0]
                xmin, xmax, ymin, ymax = self.extent
                raise ValueError(
                    f"{n_bad} point(s) lie outside the map, first ({first[0]:.3f}, {first[1]:.3f}); "
                    f"the map covers x in [{xmin:.3f}, {xmax:.3f}) and y in [{ymin:.3f}, {ymax:.3f}). "
                    "Pass outside='clip' or outside='flag' to handle them."
                )
            if outside == "clip":
                i = np.clip(i, 0, self.shape[0] - 1)
                j = np.clip(j, 0, self.shape[1] - 1)
            else:
                i = np.where(inside, i, -1)
                j = np.where(inside, j, -1)
        return np.stack([i, j], axis=-1)

    def cell_to_world(self, cells: ArrayLike) -> NDArray[np.float64]:
        """World coordinates ``(x, y)`` of the centres of cells ``(i, j)``.

        Raises ``ValueError`` for indices outside the grid.

        Examples
        --------
        >>> g = OccupancyGrid(np.zeros((4, 6)), 0.25, origin=(-1.0, 2.0))
        >>> g.cell_to_world([[0, 0], [3, 5]])
        array([[-0.875,  2.125],
               [ 0.375,  2.875]])
        """
        c = np.asarray(cells)
        if c.ndim == 0 or c.shape[-1] != 2:
            raise ValueError(f"cells must have shape (..., 2) holding (row, column); got shape {c.shape}")
        if not np.issubdtype(c.dtype, np.integer):
            if not np.all(np.isfinite(c)) or not np.all(np.equal(np.mod(c, 1), 0)):
                raise ValueError("cells must hold whole-number (row, column) indices")
            c = c.astype(np.int64)
        i, j = c[..., 0], c[..., 1]
        bad = (i < 0) | (i >= self.shape[0]) | (j < 0) | (j >= self.shape[1])
        if np.any(bad):
            first = c[bad][0]
            raise ValueError(
                f"cell ({int(first[0])}, {int(first[1])}) is outside the grid of shape {self.shape} "
                f"(rows 0..{self.shape[0] - 1}, columns 0..{self.shape[1] - 1})"
            )
        x = self._origin[0] + (j + 0.5) * self._resolution
        y = self._origin[1] + (i + 0.5) * self._resolution
        return np.stack([x, y], axis=-1).astype(float)

    def is_free(self, points: ArrayLike, *, holes: bool = False) -> NDArray[np.bool_]:
        """True where a world point lies in a known-free cell (False outside the map); with ``holes``, in one of the
        :attr:`holes` too."""
        cells = self.world_to_cell(points, outside="flag")
        i, j = cells[..., 0], cells[..., 1]
        ok = i >= 0
        out = np.zeros(i.shape, dtype=bool)
        out[ok] = self.free[i[ok], j[ok]]
        if holes:
            out[ok] |= self.holes[i[ok], j[ok]]
        return out

    def distance_at(self, points: ArrayLike, outside: float = np.nan) -> NDArray[np.float64]:
        """Distance-field value (metres) of the cell holding each point; ``outside`` beyond the map."""
        cells = self.world_to_cell(points, outside="flag")
        i, j = cells[..., 0], cells[..., 1]
        ok = i >= 0
        out = np.full(i.shape, float(outside))
        out[ok] = self.distance_field[i[ok], j[ok]]
        return out

    # --------------------------------------------------------------- sampling
    def sample_free(self, n: int, rng: np.random.Generator, *, holes: bool = False) -> NDArray[np.float64]:
        """Draw ``n`` poses uniformly over the free space, headings uniform in ``[-pi, pi)``.

        A free cell is picked uniformly, then a point uniformly inside it;
        with ``holes``, a cell of the free space or of the :attr:`holes`.

        Examples
        --------
        >>> g = OccupancyGrid.from_ascii("###\\n#.#\\n###")
        >>> p = g.sample_free(1000, np.random.default_rng(0))
        >>> bool(np.all(g.is_free(p)))
        True
        """
        check_rng(rng)
        n = check_count(n, "n", minimum=0)
        free = np.flatnonzero(self.free | self.holes if holes else self.free)
        if free.size == 0:
            raise ValueError("the map has no free cell to sample from")
        k = free[rng.integers(0, free.size, size=n)]
        i, j = np.divmod(k, self.shape[1])
        u = rng.random((n, 2))
        x = self._origin[0] + (j + u[:, 0]) * self._resolution
        y = self._origin[1] + (i + u[:, 1]) * self._resolution
        th = rng.uniform(-np.pi, np.pi, size=n)
        return np.stack([x, y, th], axis=-1)

    def __repr__(self) -> str:
        return (
            f"OccupancyGrid(shape={self.shape}, resolution={self._resolution:g}, "
            f"origin=({self._origin[0]:g}, {self._origin[1]:g}), "
            f"free={int(self.free.sum())}, obstacles={int(self.obstacles.sum())}, "
            f"unknown={int(self.unknown.sum())})"
        )
