"""Occupancy grid mapping with known poses: build a map from a log with corrected poses.

Localization needs a map; when none ships with a log, but the log carries good
poses (the SLAM-corrected CARMEN logs do), the map can be *built*: every laser
beam says that the cells it crossed are free and the cell where it ended is
occupied. Each cell keeps the log-odds of being occupied,

    l = log(p / (1 - p)),

and every observation adds the log-odds of an *inverse sensor model* minus
the prior's (Thrun, Burgard and Fox, *Probabilistic Robotics* 2005, "PR",
table 9.1; Moravec and Elfes 1985). Adding is multiplying odds — Bayes' rule
for a binary state under the usual independence assumptions — and it is
symmetric and cheap. The values are clamped to ``[logit(p_min), logit(p_max)]``
so that the map can still change when the world does (as OctoMap does:
Hornung et al. 2013).

Two versions of the inverse sensor model are here:

* :func:`inverse_range_sensor_model` — PR table 9.2 literally: for one cell,
  find the beam nearest in bearing and decide "free", "occupied" or "no
  information" from the cell's distance. Readable, per cell, slow.
* :class:`OccupancyMapper` — the practical *ray* form used to build real maps:
  walk along each beam in steps of ``step`` (half a cell by default); the cells
  of the sample points before the range are free, the cell of the end point is
  occupied (unless the reading is "no return" or beyond ``usable_range``;
  "no return" readings clear nothing unless ``clear_no_return``).
  Within one scan a cell counts at most once, and "occupied" beats "free".
  An end point exactly on a cell border counts in the cell beyond it.
  :meth:`OccupancyMapper.update_loop` is the readable loop version (the test
  oracle); :meth:`OccupancyMapper.update` the vectorised one, equal to it.

Examples
--------
A robot at the centre of a 4 m x 4 m room sweeps a scan round itself:

>>> from localize.maps import draw_box
>>> from localize.grid import OccupancyGrid
>>> from localize.raycast import cast
>>> d = np.zeros((40, 40)); d[:2] = d[-2:] = 1; d[:, :2] = d[:, -2:] = 1
>>> room = OccupancyGrid(d, 0.1)
>>> angles = np.radians(np.arange(-180, 180, 1.0))
>>> pose = np.array([2.0, 2.0, 0.0])
>>> ranges = cast(room, pose[None], angles, 10.0)[0]
>>> m = OccupancyMapper.for_extent((0, 4, 0, 4), resolution=0.1)
>>> for _ in range(5):
...     m.update(pose, ranges, angles, max_range=10.0)
>>> g = m.grid()
>>> float(g.data[20, 20]) < 0.2, float(np.nanmax(g.data)) > 0.9     # centre free, walls occupied
(True, True)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_max_range, check_positive
from .geometry import as_poses, compose, wrap_angle
from .grid import OccupancyGrid

#: An end point that lies exactly on a cell border (ray casters return such ranges) is
#: counted in the cell beyond it, the obstacle whose surface stopped the beam.
_HIT_EPS = 1e-6
#: A map larger than this many cells is taken for a mistake in its resolution or extent.
_MAX_CELLS = 50_000_000

__all__ = [
    "log_odds",
    "probability",
    "inverse_range_sensor_model",
    "OccupancyMapper",
    "build_map",
    "map_from_log",
]


def log_odds(p: ArrayLike) -> NDArray[np.float64] | float:
    """Log-odds ``log(p / (1 - p))`` of probabilities in (0, 1).

    Examples
    --------
    >>> round(float(log_odds(0.7)), 4), float(log_odds(0.5))
    (0.8473, 0.0)
    """
    a = np.asarray(p, dtype=float)
    if np.any(~np.isfinite(a)) or np.any(a <= 0) or np.any(a >= 1):
        raise ValueError(f"p must lie strictly between 0 and 1; got {p!r}")
    out = np.log(a) - np.log1p(-a)
    return float(out) if out.ndim == 0 else out


def probability(l: ArrayLike) -> NDArray[np.float64] | float:
    """Probability ``1 - 1 / (1 + exp(l))`` from log-odds (the inverse of :func:`log_odds`).

    Examples
    --------
    >>> round(float(probability(log_odds(0.7))), 6)
    0.7
    """
    a = np.asarray(l, dtype=float)
    out = 0.5 * (1.0 + np.tanh(0.5 * a))  # = 1 / (1 + exp(-l)), without overflow
    return float(out) if out.ndim == 0 else out


def inverse_range_sensor_model(
    cell: ArrayLike,
    laser_pose: ArrayLike,
    ranges: ArrayLike,
    angles: ArrayLike,
    max_range: float,
    alpha: float,
    beta: float,
    l_occ: float,
    l_free: float,
    l0: float = 0.0,
) -> float:
    """PR table 9.2: the log-odds one scan contributes to one cell (readable reference).

    Parameters
    ----------
    cell : (x, y)
        Centre of the cell, metres.
    laser_pose : (x, y, theta)
        Pose of the laser.
    ranges, angles : array_like (B,)
        The scan; readings ``>= max_range`` are "no return".
    alpha : float
        Thickness of obstacles (metres): a cell within ``alpha / 2`` of the
        measured range is occupied.
    beta : float
        Opening angle of a beam (radians).
    l_occ, l_free, l0 : float
        Log-odds of the model's "occupied" and "free" answers and of the prior.

    Returns
    -------
    float
        ``l_occ``, ``l_free`` or ``l0`` (no information).

    Examples
    --------
    >>> angles = np.radians([-10.0, 0.0, 10.0])
    >>> z = np.array([2.0, 3.0, 2.0])
    >>> kw = dict(max_range=10.0, alpha=0.2, beta=np.radians(2), l_occ=0.85, l_free=-0.4)
    >>> [inverse_range_sensor_model((x, 0.0), (0, 0, 0), z, angles, **kw) for x in (1.0, 3.0, 4.0)]
    [-0.4, 0.85, 0.0]
    """
    x, y = (float(v) for v in np.asarray(cell, dtype=float)[:2])
    xs, ys, th = (float(v) for v in as_poses(laser_pose, "laser_pose"))
    z = np.asarray(ranges, dtype=float)
    a = np.asarray(angles, dtype=float)
    r = float(np.hypot(x - xs, y - ys))
    phi = float(wrap_angle(np.arctan2(y - ys, x - xs) - th))
    k = int(np.argmin(np.abs(wrap_angle(phi - a))))
    z_max = float(max_range)
    zk = min(float(z[k]), z_max)
    if r > min(z_max, zk + alpha / 2) or abs(float(wrap_angle(phi - a[k]))) > beta / 2:
        return l0
    if zk < z_max and abs(r - zk) < alpha / 2:
        return l_occ
    if r <= zk:
        return l_free
    return l0  # pragma: no cover - unreachable: r <= zk + alpha/2 and not within alpha/2 means r < zk


class OccupancyMapper:
    """Occupancy grid mapping with known poses, in log-odds (PR table 9.1, ray form).

    Parameters
    ----------
    shape : (H, W)
        Rows (y) and columns (x) of the map.
    resolution : float
        Cell side in metres.
    origin : (x, y)
        World coordinates of the lower-left corner of cell (0, 0).
    p_occ, p_free : float
        Inverse sensor model: probability that the cell where a beam ends is
        occupied (> 0.5), and that a cell the beam crossed is (< 0.5).
    p_prior : float
        Prior occupancy of every cell (0.5: nothing known).
    p_min, p_max : float
        Clamping bounds of the cell probabilities (keeps the map able to
        change: a moved chair can be cleared again).
    usable_range : float
        Readings beyond it are trusted only as free space up to
        ``usable_range`` (long readings are noisy and graze walls); "no return"
        readings likewise.
    step : float, optional
        Spacing of the sample points along a beam (default: half a cell).
    clear_no_return : bool
        Whether a "no return" reading clears the cells along its beam (up to
        ``usable_range``). Off by default: in real buildings most such
        readings leave through windows and doors or vanish on black or shiny
        surfaces, and clearing along them paints free space outside the walls
        and erases glass.

    Examples
    --------
    >>> m = OccupancyMapper((10, 20), 0.1)
    >>> m.update([0.05, 0.55, 0.0], ranges=[1.0], angles=[0.0], max_range=5.0)
    >>> m.counts()                       # 10 cells crossed, 1 hit
    (10, 1)
    >>> print(m.grid().data[5, 8:12].round(2))
    [0.4 0.4 0.7 nan]
    """

    def __init__(
        self,
        shape: tuple[int, int],
        resolution: float,
        origin: ArrayLike = (0.0, 0.0),
        p_occ: float = 0.7,
        p_free: float = 0.4,
        p_prior: float = 0.5,
        p_min: float = 0.12,
        p_max: float = 0.97,
        usable_range: float = 20.0,
        step: float | None = None,
        clear_no_return: bool = False,
    ) -> None:
        try:
            h, w = (int(s) for s in shape)
        except (TypeError, ValueError):
            raise ValueError(f"shape must be a pair (rows, columns); got {shape!r}") from None
        if h < 1 or w < 1:
            raise ValueError(f"shape must have at least one row and one column; got {shape!r}")
        if h * w > _MAX_CELLS:
            raise ValueError(f"shape {shape} has {h * w} cells; more than 50 million is surely a mistake "
                             "(coarser resolution or a smaller extent?)")
        res = check_positive(resolution, "resolution", "metres per cell")
        org = np.asarray(origin, dtype=float)
        if org.shape != (2,) or not np.all(np.isfinite(org)):
            raise ValueError(f"origin must be a finite pair (x, y); got {origin!r}")
        for name, v in (("p_occ", p_occ), ("p_free", p_free), ("p_prior", p_prior), ("p_min", p_min),
                        ("p_max", p_max)):
            if not 0.0 < float(v) < 1.0:
                raise ValueError(f"{name} must lie strictly between 0 and 1; got {v!r}")
        if not p_free < p_prior < p_occ:
            raise ValueError(f"need p_free < p_prior < p_occ (free evidence lowers, hits raise); got "
                             f"{p_free}, {p_prior}, {p_occ}")
        if not p_min < p_prior < p_max:
            raise ValueError(f"need p_min < p_prior < p_max; got {p_min}, {p_prior}, {p_max}")
        check_positive(usable_range, "usable_range", "metres")
        st = res / 2.0 if step is None else float(step)
        if not (np.isfinite(st) and 0 < st <= res):
            raise ValueError(f"step must be in (0, resolution] = (0, {res:g}] metres; got {step!r}")
        self.shape = (h, w)
        self.resolution = res
        self.origin = org
        self.l0 = float(log_odds(p_prior))
        self.l_occ = float(log_odds(p_occ)) - self.l0
        self.l_free = float(log_odds(p_free)) - self.l0
        self.l_min = float(log_odds(p_min))
        self.l_max = float(log_odds(p_max))
        self.usable_range = float(usable_range)
        self.step = st
        self.clear_no_return = bool(clear_no_return)
        self.log_odds = np.full(h * w, self.l0)
        self.observed = np.zeros(h * w, dtype=bool)
        self._stamp = np.full(h * w, -1, dtype=np.int64)
        self.n_scans = 0
        self._last_counts = (0, 0)

    @classmethod
    def for_extent(cls, extent: tuple[float, float, float, float], resolution: float, margin: float = 0.0,
                   **kwargs) -> "OccupancyMapper":
        """A mapper covering ``(xmin, xmax, ymin, ymax)`` plus ``margin`` metres, origin snapped to the grid.

        Examples
        --------
        >>> OccupancyMapper.for_extent((-1.0, 3.0, 0.0, 2.0), 0.5).shape
        (4, 8)
        """
        xmin, xmax, ymin, ymax = (float(v) for v in extent)
        if not (np.isfinite([xmin, xmax, ymin, ymax]).all() and xmax > xmin and ymax > ymin):
            raise ValueError(f"extent must be finite (xmin, xmax, ymin, ymax) with max > min; got {extent!r}")
        res = float(resolution)
        x0 = np.floor((xmin - margin) / res) * res
        y0 = np.floor((ymin - margin) / res) * res
        w = int(np.ceil((xmax + margin - x0) / res - 1e-9))
        h = int(np.ceil((ymax + margin - y0) / res - 1e-9))
        return cls((max(h, 1), max(w, 1)), res, origin=(x0, y0), **kwargs)

    # ------------------------------------------------------------ the beam geometry
    def _beam_extent(self, ranges: NDArray, max_range: float) -> tuple[NDArray, NDArray]:
        """Free-space length of each beam and whether it ends in a hit."""
        hit = (ranges < max_range) & (ranges <= self.usable_range)
        free_len = np.where(hit, ranges, min(self.usable_range, max_range))
        if not self.clear_no_return:
            free_len = np.where(ranges >= max_range, 0.0, free_len)
        return free_len, hit

    def _check_scan(self, laser_pose, ranges, angles, max_range):
        p = as_poses(laser_pose, "laser_pose").reshape(-1)
        if p.shape != (3,):
            raise ValueError(f"laser_pose must be one pose (x, y, theta); got shape {np.shape(laser_pose)}")
        z = np.asarray(ranges, dtype=float).reshape(-1)
        a = np.asarray(angles, dtype=float).reshape(-1)
        if z.shape != a.shape:
            raise ValueError(f"ranges ({z.size}) and angles ({a.size}) must have one value per beam")
        if np.any(~np.isfinite(z)) or np.any(z < 0):
            raise ValueError("ranges must be finite and >= 0 (use max_range for 'no return')")
        return p, z, a, check_max_range(max_range)

    # ------------------------------------------------------------ readable version
    def update_loop(self, laser_pose: ArrayLike, ranges: ArrayLike, angles: ArrayLike, max_range: float) -> None:
        """Integrate one scan, beam by beam and point by point (the readable oracle of :meth:`update`)."""
        p, z, a, mr = self._check_scan(laser_pose, ranges, angles, max_range)
        h, w = self.shape
        free_len, hit = self._beam_extent(z, mr)
        cos_a, sin_a = np.cos(p[2] + a), np.sin(p[2] + a)
        occupied: set[int] = set()
        free: set[int] = set()

        def cell_of(x: float, y: float) -> int | None:
            j = int(np.floor((x - self.origin[0]) / self.resolution))
            i = int(np.floor((y - self.origin[1]) / self.resolution))
            return i * w + j if (0 <= i < h and 0 <= j < w) else None

        for b in range(z.size):
            k = 0
            while True:
                d = (k + 0.5) * self.step
                if not d < free_len[b]:
                    break
                c = cell_of(p[0] + d * cos_a[b], p[1] + d * sin_a[b])
                if c is not None:
                    free.add(c)
                k += 1
            if hit[b]:
                zh = z[b] + _HIT_EPS  # an end point on a cell border belongs to the cell beyond
                c = cell_of(p[0] + zh * cos_a[b], p[1] + zh * sin_a[b])
                if c is not None:
                    occupied.add(c)
        free -= occupied  # "occupied" beats "free" within one scan
        for c in free:
            self.log_odds[c] = min(max(self.log_odds[c] + self.l_free, self.l_min), self.l_max)
            self.observed[c] = True
        for c in occupied:
            self.log_odds[c] = min(max(self.log_odds[c] + self.l_occ, self.l_min), self.l_max)
            self.observed[c] = True
        self.n_scans += 1
        self._last_counts = (len(free), len(occupied))

    # ------------------------------------------------------------ fast version
    def update(self, laser_pose: ArrayLike, ranges: ArrayLike, angles: ArrayLike, max_range: float) -> None:
        """Integrate one scan taken from ``laser_pose`` (vectorised over beams and sample points).

        Parameters
        ----------
        laser_pose : (x, y, theta)
            Pose of the laser (robot pose composed with the sensor offset).
        ranges, angles : array_like (B,)
            The scan; readings ``>= max_range`` mean "no return".
        max_range : float
            The sensor's maximum range.
        """
        p, z, a, mr = self._check_scan(laser_pose, ranges, angles, max_range)
        h, w = self.shape
        free_len, hit = self._beam_extent(z, mr)
        cos_a, sin_a = np.cos(p[2] + a), np.sin(p[2] + a)
        # sample points (k + 0.5) * step < free_len of every beam, without a Python loop
        n_max = np.ceil(free_len / self.step).astype(np.int64) + 1
        beam = np.repeat(np.arange(z.size), n_max)
        starts = np.cumsum(n_max) - n_max
        k = np.arange(beam.size) - np.repeat(starts, n_max)
        d = (k + 0.5) * self.step
        keep = d < free_len[beam]
        beam, d = beam[keep], d[keep]
        free = self._cells(p[0] + d * cos_a[beam], p[1] + d * sin_a[beam], h, w)
        zh = z[hit] + _HIT_EPS
        occ = self._cells(p[0] + zh * cos_a[hit], p[1] + zh * sin_a[hit], h, w)
        stamp = self.n_scans
        self._stamp[occ] = stamp
        free = free[self._stamp[free] != stamp]
        # fancy assignment applies each cell once even when it is listed several times
        lo = self.log_odds
        lo[free] = np.clip(lo[free] + self.l_free, self.l_min, self.l_max)
        lo[occ] = np.clip(lo[occ] + self.l_occ, self.l_min, self.l_max)
        self.observed[free] = True
        self.observed[occ] = True
        self.n_scans += 1
        self._last_counts = (free, occ)  # counted on demand by counts()

    def _cells(self, x: NDArray, y: NDArray, h: int, w: int) -> NDArray[np.int64]:
        j = np.floor((x - self.origin[0]) / self.resolution).astype(np.int64)
        i = np.floor((y - self.origin[1]) / self.resolution).astype(np.int64)
        ok = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        return i[ok] * w + j[ok]

    # ------------------------------------------------------------ results
    def counts(self) -> tuple[int, int]:
        """Cells marked free and occupied by the last scan."""
        free, occ = self._last_counts
        if isinstance(free, int):
            return free, occ
        return int(np.unique(free).size), int(np.unique(occ).size)

    def probabilities(self) -> NDArray[np.float64]:
        """Occupancy probability of every cell, shape (H, W); unobserved cells hold the prior."""
        return probability(self.log_odds).reshape(self.shape)

    def grid(self, unknown: str = "nan", occupied_threshold: float = 0.5) -> OccupancyGrid:
        """The map as an :class:`~localize.OccupancyGrid` (never-observed cells NaN, or the prior).

        ``unknown="prior"`` keeps the prior probability in unobserved cells.
        """
        if unknown not in ("nan", "prior"):
            raise ValueError(f"unknown must be 'nan' or 'prior'; got {unknown!r}")
        p = self.probabilities()
        if unknown == "nan":
            p = np.where(self.observed.reshape(self.shape), p, np.nan)
        return OccupancyGrid(p, self.resolution, origin=self.origin, occupied_threshold=occupied_threshold)


def _scan_extent(laser: NDArray, ranges: NDArray, angles: NDArray, max_range: float,
                 usable_range: float, clear_no_return: bool) -> tuple[float, float, float, float]:
    reach = np.where(ranges >= max_range, usable_range if clear_no_return else 0.0, np.minimum(ranges, usable_range))
    ang = laser[:, 2:3] + angles[None, :]
    ex = laser[:, 0:1] + reach * np.cos(ang)
    ey = laser[:, 1:2] + reach * np.sin(ang)
    xs = np.concatenate([ex.ravel(), laser[:, 0]])
    ys = np.concatenate([ey.ravel(), laser[:, 1]])
    return float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())


def build_map(
    poses: ArrayLike,
    ranges: ArrayLike,
    angles: ArrayLike,
    max_range: float,
    sensor_offset: ArrayLike = (0.0, 0.0, 0.0),
    resolution: float = 0.05,
    usable_range: float = 20.0,
    margin: float = 0.5,
    extent: tuple[float, float, float, float] | None = None,
    occupied_threshold: float = 0.5,
    **model,
) -> OccupancyGrid:
    """Build an occupancy grid from scans taken at known robot poses.

    Parameters
    ----------
    poses : array_like (K, 3)
        Robot poses (map frame) of the scans.
    ranges : array_like (K, B)
        Ranges; ``>= max_range`` is "no return".
    angles : array_like (B,)
        Beam angles relative to the laser heading.
    max_range : float
        The sensor's maximum range.
    sensor_offset : (dx, dy, dtheta)
        Laser pose in the robot frame.
    resolution : float
        Cell side of the new map in metres.
    usable_range : float
        See :class:`OccupancyMapper`.
    margin : float
        Free border (metres) around what the scans reach (ignored with ``extent``).
    extent : (xmin, xmax, ymin, ymax), optional
        The map's extent; by default everything the scans reach.
    **model
        ``p_occ``, ``p_free``, ``p_min``, ``p_max``, ``step``, ``clear_no_return`` of
        :class:`OccupancyMapper`.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.raycast import cast
    >>> truth = office()
    >>> poses = np.array([[3.0, 5.5, 0.0], [10.0, 5.5, 0.0], [16.0, 5.5, np.pi]])
    >>> angles = np.radians(np.arange(-180, 180, 2.0))
    >>> z = cast(truth, poses, angles, 20.0)
    >>> g = build_map(poses, z, angles, max_range=20.0, resolution=0.1)
    >>> g.resolution, bool(g.occupied.sum() > 100)
    (0.1, True)
    """
    p = as_poses(poses, "poses").reshape(-1, 3)
    z = np.asarray(ranges, dtype=float)
    a = np.asarray(angles, dtype=float).reshape(-1)
    if z.ndim != 2 or z.shape != (p.shape[0], a.size):
        raise ValueError(f"ranges must have shape (K, B) = ({p.shape[0]}, {a.size}) (one row per pose, "
                         f"one column per angle); got {z.shape}")
    laser = compose(p, as_poses(sensor_offset, "sensor_offset"))
    if extent is None:
        extent = _scan_extent(laser, z, a, float(max_range), float(usable_range),
                              bool(model.get("clear_no_return", False)))
        m = OccupancyMapper.for_extent(extent, resolution, margin=margin, usable_range=usable_range, **model)
    else:
        m = OccupancyMapper.for_extent(extent, resolution, margin=0.0, usable_range=usable_range, **model)
    for k in range(p.shape[0]):
        m.update(laser[k], z[k], a, max_range)
    return m.grid(occupied_threshold=occupied_threshold)


def map_from_log(log, resolution: float = 0.05, poses: ArrayLike | None = None, every: int = 1,
                 **kwargs) -> OccupancyGrid:
    """Build a map from a :class:`~localize.io.LaserLog` with known poses (default: its reference poses).

    ``every`` uses every ``every``-th scan (mapping the 4,791 scans of Freiburg
    079 at full rate takes a while; every 4th gives nearly the same map).
    Other keyword arguments go to :func:`build_map`.

    Examples
    --------
    >>> from localize.io import LaserLog
    >>> log = LaserLog(times=[0.0], odometry=[[0, 0, 0]], ranges=[[1.0, 1.0, 1.0]],
    ...                angles=[-0.5, 0.0, 0.5], max_range=5.0, poses=[[0.0, 0.0, 0.0]])
    >>> map_from_log(log, resolution=0.1).shape
    (20, 20)
    """
    if poses is None:
        if log.poses is None:
            raise ValueError("the log has no reference poses (log.poses is None); pass poses=... "
                             "(mapping needs known poses)")
        poses = log.poses
    p = as_poses(poses, "poses")
    if p.shape != (len(log), 3):
        raise ValueError(f"poses must have shape ({len(log)}, 3), one per scan; got {p.shape}")
    every = int(every)
    if every < 1:
        raise ValueError(f"every must be a positive integer; got {every}")
    idx = np.arange(0, len(log), every)
    return build_map(p[idx], log.ranges[idx], log.angles, log.max_range, sensor_offset=log.sensor_offset,
                     resolution=resolution, **kwargs)
