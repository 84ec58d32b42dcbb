"""Grid (Markov) localization in (x, y, theta) on an occupancy grid.

The belief is a histogram over poses: one probability per map cell and
heading bin, an array ``belief[k, i, j]`` for heading ``theta_k`` and the
cell in row ``i``, column ``j`` of the :class:`~localize.grid.OccupancyGrid`
(PR table 8.1, "Grid localization"; Burgard et al. 1996; Fox, Burgard and
Thrun 1999). Heading bins are centred on ``theta_k = -pi + k * 2 pi / K``.

**Prediction (odometry).** Two odometry readings give the motion
``(rot1, trans, rot2)`` (PR section 5.4). A robot in heading bin ``k``
translates by the same motion *turned by its own heading*, so each heading
slice of the belief is shifted by its own displacement: a
**rotation-aware convolution**. Each slice is moved by the whole-cell part
of its displacement and blurred by a small Gaussian kernel centred on the
fractional part; then the heading axis is shifted by ``rot1 + rot2`` and
blurred (cyclically). The blur's widths come from the odometry noise of PR
table 5.6 (``alpha1..alpha4`` as variances ``alpha1*rot1**2 + alpha2*trans**2``
...), with the position noise made isotropic (the mean of the along-track
and across-track variances), plus a floor that accounts for the cell size
(PR section 8.2.2 recommends inflating the noise of a coarse grid).

**Correction (range beams).** The expected range of every beam from every
cell is precomputed once: a table ``E[k, i, j]`` of the range from the
centre of cell ``(i, j)`` along the *absolute* direction ``theta_k``. Beam
``b`` at angle ``alpha_b`` relative to the robot, snapped to a multiple
``m_b`` of the bin width, looks along ``theta_k + alpha_b``, i.e. table row
``(k + m_b) mod K``: one table serves every heading. The table is stored as
integer range codes, and for each scan the beam likelihood is tabulated over
all codes once, so the update is one gather per beam. The default beam
likelihood is a Gaussian around the expected range mixed with a uniform
floor (a reduced form of PR's beam model, table 6.1); any ``pdf(z,
z_expected)`` (for example ``localize.sensors.BeamModel(...).pdf``) can be
given instead.

:func:`predict_readable` and :func:`update_readable` are the loop versions
(per cell, as the pseudocode reads) that the tests hold the fast ones equal
to.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from ._checks import check_angles, check_grid, check_max_range, check_nonnegative
from .discrete import ZeroLikelihoodError
from .geometry import as_poses, wrap_angle
from .grid import OccupancyGrid
from .motion import odometry_to_control, odometry_variances

__all__ = [
    "GridLocalizer",
    "coarsen",
    "heading_bins",
    "expected_range_table",
    "motion_blur",
    "shift_kernel",
    "predict_readable",
    "update_readable",
    "gaussian_beam_pdf",
]

#: The most range levels a uint16 code of the likelihood table can index.
_MAX_LEVELS = int(np.iinfo(np.uint16).max)
#: Motion-kernel weights below this fraction of the largest are set to 0 (the blur stays exactly local).
_KERNEL_CUTOFF = 1e-12


def heading_bins(n_headings: int) -> NDArray[np.float64]:
    """Centres ``-pi + k * 2 pi / K`` of ``K`` heading bins.

    Examples
    --------
    >>> np.degrees(heading_bins(4))
    array([-180.,  -90.,    0.,   90.])
    """
    k = int(n_headings)
    if k != n_headings or k < 4 or k % 2:
        raise ValueError(f"n_headings must be an even integer >= 4; got {n_headings!r}")
    return -np.pi + np.arange(k) * (2 * np.pi / k)


def coarsen(grid: OccupancyGrid, factor: int) -> OccupancyGrid:
    """The map at a ``factor`` times coarser resolution: each coarse cell takes the *most* occupied of its cells.

    Taking the maximum keeps thin walls: a wall one fine cell thick still
    blocks the coarse cell it passes through (averaging would dissolve it).
    Unknown (NaN) cells count as occupied only when no known cell of the
    block is. Rows and columns that do not fill a whole block are dropped.

    Examples
    --------
    >>> g = OccupancyGrid(np.eye(4), 0.1)
    >>> c = coarsen(g, 2)
    >>> c.data, c.resolution
    (array([[1., 0.],
           [0., 1.]]), 0.2)
    """
    f = int(factor)
    if f != factor or f < 1:
        raise ValueError(f"factor must be a whole number >= 1; got {factor!r}")
    h, w = grid.shape[0] // f, grid.shape[1] // f
    if h == 0 or w == 0:
        raise ValueError(f"factor {f} is larger than the map {grid.shape}")
    blocks = grid.data[:h * f, :w * f].reshape(h, f, w, f)
    known = ~np.isnan(blocks)
    filled = np.where(known, blocks, -1.0).max(axis=(1, 3))
    data = np.where(filled < 0, np.nan, filled)
    return OccupancyGrid(data, grid.resolution * f, grid.origin, grid.occupied_threshold, grid.unknown_is_obstacle)


def expected_range_table(grid: OccupancyGrid, n_headings: int, max_range: float,
                         method: str = "lut") -> NDArray[np.float32]:
    """Expected ranges ``E[k, i, j]`` from every cell centre along every heading bin direction.

    Built with :mod:`localize.raycast`: ``method="lut"`` (default) uses its
    precomputed lookup table with ``n_bins = n_headings`` (fast, exact to
    about a cell), ``"march"`` or ``"exact"`` cast every ray.

    Examples
    --------
    >>> g = OccupancyGrid.from_ascii('''
    ... #####
    ... #...#
    ... #####
    ... ''')
    >>> E = expected_range_table(g, 4, 10.0, method="exact")
    >>> E.shape, float(E[2, 1, 1]), float(E[0, 1, 1])       # from cell (1, 1): 2 m east, 1 m west
    ((4, 3, 5), 2.5, 0.5)
    """
    from . import raycast

    theta = heading_bins(n_headings)
    h, w = grid.shape
    if method == "lut":
        caster = raycast.RayCaster(grid, max_range, method="lut", n_bins=int(n_headings))
        codes = caster.table.reshape(h, w, n_headings)              # heading k * 2 pi / K
        table = codes.astype(np.float32) * np.float32(caster.lut_scale)
        table[codes == raycast.LUT_MAX_CODE] = max_range
        # our bin k is at -pi + k * 2 pi / K = the table's bin (k + K/2) mod K
        table = np.roll(table, -n_headings // 2, axis=2)
        return np.ascontiguousarray(np.moveaxis(table, 2, 0))
    ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    xy = grid.cell_to_world(np.stack([ii.ravel(), jj.ravel()], -1))
    poses = np.column_stack([xy, np.zeros(len(xy))])
    r = raycast.cast(grid, poses, theta, max_range, method=method)
    return np.ascontiguousarray(r.T.reshape(len(theta), h, w).astype(np.float32))


def gaussian_beam_pdf(sigma: float, max_range: float, z_hit: float = 0.9) -> Callable:
    """``pdf(z, z_exp) = z_hit * N(z; z_exp, sigma) + (1 - z_hit) / max_range`` (ranges clipped to max_range).

    Examples
    --------
    >>> pdf = gaussian_beam_pdf(0.2, 10.0)
    >>> round(float(pdf(3.0, 3.0)), 4), round(float(pdf(3.0, 8.0)), 4)
    (1.8052, 0.01)
    """
    s, m, zh = float(sigma), float(max_range), float(z_hit)
    if s <= 0 or m <= 0 or not 0 <= zh < 1:
        raise ValueError(f"need sigma > 0, max_range > 0 and 0 <= z_hit < 1; got {sigma}, {max_range}, {z_hit}")
    norm = zh / (s * np.sqrt(2 * np.pi))

    def pdf(z, z_exp):
        d = np.minimum(np.asarray(z, dtype=float), m) - np.minimum(np.asarray(z_exp, dtype=float), m)
        return norm * np.exp(-0.5 * (d / s) ** 2) + (1 - zh) / m

    return pdf


def shift_kernel(shift: float, sigma: float) -> tuple[int, NDArray[np.float64]]:
    """Split a fractional ``shift`` (cells) blurred by ``sigma`` into a whole-cell shift and an odd kernel.

    Returns ``(n, w)``: move by ``n`` whole cells, then push each cell's mass
    to offsets ``-R..R`` with weights ``w`` (a Gaussian centred on the
    fractional part ``shift - n``, sampled at whole cells, normalised).

    Examples
    --------
    >>> n, w = shift_kernel(2.5, 0.5)
    >>> n, w.round(3)
    (2, array([0.   , 0.   , 0.009, 0.491, 0.491, 0.009, 0.   ]))
    """
    s, sig = float(shift), float(sigma)
    if not np.isfinite(s) or not np.isfinite(sig) or sig <= 0:
        raise ValueError(f"shift must be finite and sigma > 0; got {shift!r}, {sigma!r}")
    n = int(np.floor(s))
    f = s - n
    r = int(np.ceil(3 * sig)) + 1
    m = np.arange(-r, r + 1)
    w = np.exp(-0.5 * ((m - f) / sig) ** 2)
    w[w < _KERNEL_CUTOFF * w.max()] = 0.0
    return n, w / w.sum()


def motion_blur(rot1: float, trans: float, rot2: float, alphas: ArrayLike, resolution: float,
                bin_width: float, min_sigma_xy: float = 0.5, min_sigma_theta: float = 0.5) -> tuple[float, float]:
    """Blur widths ``(sigma_xy in cells, sigma_theta in bins)`` of one odometry motion.

    ``sigma_xy**2 = (var_trans + trans**2 * var_rot1) / 2 / resolution**2 + min_sigma_xy**2``
    (the mean of the along- and across-track variances, PR table 5.6, plus the
    cell-size floor) and ``sigma_theta**2 = (var_rot1 + var_rot2) / bin_width**2 + min_sigma_theta**2``.

    Examples
    --------
    >>> sxy, sth = motion_blur(0.0, 1.0, 0.0, [0.0, 0.0, 0.01, 0.0], 0.1, np.pi / 18, 0.0, 0.5)
    >>> round(sxy, 4), round(sth, 4)
    (0.7071, 0.5)
    """
    v1, vt, v2 = (float(v) for v in odometry_variances(rot1, trans, rot2, alphas))
    sxy2 = 0.5 * (vt + trans**2 * v1) / resolution**2 + float(min_sigma_xy) ** 2
    sth2 = (v1 + v2) / bin_width**2 + float(min_sigma_theta) ** 2
    if sxy2 <= 0 or sth2 <= 0:
        raise ValueError("the motion has no noise at all: give alphas > 0 or min_sigma_xy, min_sigma_theta > 0")
    return float(np.sqrt(sxy2)), float(np.sqrt(sth2))


def _check_u(u: ArrayLike) -> tuple[NDArray, NDArray]:
    a = np.asarray(u, dtype=float)
    if a.shape != (2, 3):
        raise ValueError(f"u must be the pair (prev_odom, odom) of odometry poses, shape (2, 3); got {a.shape}")
    as_poses(a, "u")
    return a[0], a[1]


class GridLocalizer:
    """Markov localization on a grid of ``K`` headings x the map's cells.

    The belief has one bin per free map cell and heading bin, so its cost
    follows the map's resolution: for a coarser filter pass a coarser map,
    :func:`coarsen` ``(grid, factor)``, which keeps thin walls (chapter 3
    localizes on the 10 cm office coarsened to 20 cm and 50 cm).

    **Beams are snapped onto the heading bins.** The expected ranges are
    stored per heading bin (``K`` directions), so each beam is compared with
    the expected range of the bin nearest to its absolute direction. With a
    dense scan and coarse bins several beams land on the same bin: 180
    one-degree beams on ``K = 36`` ten-degree bins use only 19 directions
    (the half circle), and the about ten beams in each bin are all compared
    with one expected range, as if the scan were ten repeated copies of 19
    beams. Pass a subset, about one beam per bin (``angles[::10]`` there), or
    more heading bins. The constructor warns when distinct beam angles share
    a bin (``beams_per_bin`` tells how many land in each used bin).

    Parameters
    ----------
    grid : OccupancyGrid
        The map; the filter's cells are the map's cells (see :func:`coarsen`).
    n_headings : int
        Heading bins ``K`` (even, >= 4).
    angles : array_like, shape (B,)
        Beam angles relative to the robot's heading; each is snapped to the
        nearest multiple of the bin width ``2 pi / K`` (error <= pi / K).
    max_range : float
        Sensor maximum range (metres); readings >= max_range mean "no return".
    expected : array_like, shape (K, H, W), optional
        Expected range from each cell centre along each absolute heading bin
        (:func:`expected_range_table`). Built with :mod:`localize.raycast`'s
        lookup table when omitted.
    sigma_hit, z_hit : float
        Parameters of the default beam likelihood :func:`gaussian_beam_pdf`.
    beam_pdf : callable, optional
        ``pdf(z, z_expected)`` used instead of the default (vectorised).
    alphas : array_like, shape (4,)
        Odometry noise alpha1..alpha4 (PR table 5.6, as variances).
    min_sigma_xy, min_sigma_theta : float
        Blur floors in cells and bins, for the discretisation.
    range_step : float, optional
        Resolution of the stored expected ranges (default ``resolution / 4``).

    Examples
    --------
    >>> g = OccupancyGrid.from_ascii('''
    ... ########
    ... #......#
    ... #..#...#
    ... #......#
    ... ########
    ... ''', resolution=0.5)
    >>> loc = GridLocalizer(g, 8, angles=[0, np.pi / 2, np.pi, -np.pi / 2], max_range=5.0)
    >>> loc.belief.shape, round(float(loc.belief.sum()), 6)
    ((8, 5, 8), 1.0)

    Twelve beams 10 degrees apart on 45-degree bins share them, and say so:

    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     dense = GridLocalizer(g, 8, np.radians(np.arange(-60, 60, 10)), 5.0)
    >>> dense.beams_per_bin, len(caught)
    ({7: 4, 0: 5, 1: 3}, 1)
    """

    def __init__(self, grid: OccupancyGrid, n_headings: int, angles: ArrayLike, max_range: float, *,
                 expected: ArrayLike | None = None, sigma_hit: float = 0.2, z_hit: float = 0.9,
                 beam_pdf: Callable | None = None, alphas: ArrayLike = (0.05, 0.005, 0.05, 0.005),
                 min_sigma_xy: float = 0.5, min_sigma_theta: float = 0.5,
                 range_step: float | None = None) -> None:
        self.grid = grid = check_grid(grid)
        self.theta = heading_bins(n_headings)
        self.K = len(self.theta)
        self.bin_width = 2 * np.pi / self.K
        self.max_range = mr = check_max_range(max_range)
        a = check_angles(angles)
        if a.size == 0:
            raise ValueError("angles must hold at least one beam angle; got an empty array")
        self.angles = a
        self.beam_bins = np.round(np.asarray(wrap_angle(a)) / self.bin_width).astype(int) % self.K
        #: heading bin -> number of beams snapped onto it, in the order of the beams
        self.beams_per_bin = {int(k): int(np.sum(self.beam_bins == k)) for k in dict.fromkeys(self.beam_bins.tolist())}
        distinct = len(np.unique(np.round(np.asarray(wrap_angle(a)), 12)))
        if distinct > len(self.beams_per_bin):
            warnings.warn(
                f"{distinct} distinct beam angles snap onto {len(self.beams_per_bin)} heading bins of "
                f"{np.degrees(self.bin_width):.3g} degrees (up to {max(self.beams_per_bin.values())} beams per bin), "
                "so beams in one bin are compared with the same expected range and count as repeated evidence; "
                "pass about one beam per bin (a subset of the angles) or more heading bins", stacklevel=2)
        self.alphas = np.asarray(alphas, dtype=float)
        odometry_variances(0.0, 0.0, 0.0, self.alphas)   # validates alphas
        self.min_sigma_xy = check_nonnegative(min_sigma_xy, "min_sigma_xy", "cells")
        self.min_sigma_theta = check_nonnegative(min_sigma_theta, "min_sigma_theta", "heading bins")
        self.pdf = beam_pdf if beam_pdf is not None else gaussian_beam_pdf(sigma_hit, mr, z_hit)
        if expected is None:
            expected = expected_range_table(grid, self.K, mr)
        e = np.asarray(expected, dtype=np.float32)
        shape = (self.K,) + grid.shape
        if e.shape != shape:
            raise ValueError(f"expected must have shape (n_headings, H, W) = {shape}; got {e.shape}")
        if not np.all(np.isfinite(e)) or e.min() < 0:
            raise ValueError("expected ranges must be finite and >= 0")
        self.range_step = float(range_step) if range_step is not None else grid.resolution / 4
        if self.range_step <= 0:
            raise ValueError(f"range_step must be > 0; got {range_step!r}")
        self.n_levels = int(np.ceil(mr / self.range_step)) + 1
        if self.n_levels > _MAX_LEVELS:
            raise ValueError(f"max_range / range_step = {self.n_levels} levels exceeds {_MAX_LEVELS} (the codes are "
                             "uint16); use a larger range_step")
        self.expected = e
        self.codes = np.round(np.minimum(e, mr) / self.range_step).astype(np.uint16)
        self.free = grid.free
        if not self.free.any():
            raise ValueError("the map has no free cell to localize in")
        self.reset()

    # --------------------------------------------------------------- belief
    @property
    def shape(self) -> tuple[int, int, int]:
        return self.belief.shape  # type: ignore[return-value]

    @property
    def n_cells(self) -> int:
        """Number of (heading, row, column) bins: the work of one update."""
        return int(self.belief.size)

    def reset(self, pose: ArrayLike | None = None, sigma_xy: float = 0.5,
              sigma_theta: float = 0.3) -> None:
        """Uniform belief over free cells and headings, or a Gaussian around ``pose``.

        ``sigma_xy`` (metres) and ``sigma_theta`` (radians) set the Gaussian's spread.

        Examples
        --------
        >>> g = OccupancyGrid(np.zeros((10, 10)), 0.1)
        >>> loc = GridLocalizer(g, 8, [0.0], 1.0, expected=np.ones((8, 10, 10)))
        >>> loc.reset(pose=[0.55, 0.25, np.pi / 2], sigma_xy=0.05, sigma_theta=0.1)
        >>> loc.estimate().round(3)
        array([0.55 , 0.25 , 1.571])
        """
        free = self.free.astype(float)
        if pose is None:
            b = np.broadcast_to(free, (self.K,) + free.shape).copy()
        else:
            p = as_poses(pose).reshape(3)
            h, w = self.grid.shape
            xy = self.grid.cell_to_world(np.stack(np.meshgrid(np.arange(h), np.arange(w), indexing="ij"), -1))
            d2 = ((xy[..., 0] - p[0]) ** 2 + (xy[..., 1] - p[1]) ** 2) / float(sigma_xy) ** 2
            dth = np.asarray(wrap_angle(self.theta - p[2])) / float(sigma_theta)
            b = np.exp(-0.5 * dth**2)[:, None, None] * (np.exp(-0.5 * d2) * free)[None]
            if b.sum() <= 0:
                raise ValueError("the Gaussian prior puts no mass on a free cell; widen sigma_xy")
        self.belief = b / b.sum()

    # ------------------------------------------------------------ prediction
    def predict(self, u: ArrayLike) -> None:
        """Prediction with odometry ``u = (prev_odom, odom)`` (a rotation-aware convolution).

        Examples
        --------
        >>> g = OccupancyGrid(np.zeros((20, 20)), 0.1)
        >>> loc = GridLocalizer(g, 8, [0.0], 1.0, expected=np.ones((8, 20, 20)), alphas=(0, 0, 0, 0))
        >>> loc.reset(pose=[0.55, 0.55, np.pi / 2], sigma_xy=0.05, sigma_theta=0.1)
        >>> loc.predict([[0, 0, 0], [0.5, 0, 0]])       # 0.5 m forward: along +y for this heading
        >>> loc.estimate().round(3)
        array([0.55 , 1.05 , 1.571])
        """
        prev, odom = _check_u(u)
        rot1, trans, rot2 = (float(v) for v in odometry_to_control(prev, odom))
        sxy, sth = motion_blur(rot1, trans, rot2, self.alphas, self.grid.resolution, self.bin_width,
                               self.min_sigma_xy, self.min_sigma_theta)
        res = self.grid.resolution
        direction = self.theta + rot1
        drow = trans * np.sin(direction) / res
        dcol = trans * np.cos(direction) / res
        kr = [shift_kernel(v, sxy) for v in drow]
        kc = [shift_kernel(v, sxy) for v in dcol]
        # pad so that nothing is cut before the whole-cell shift brings it back onto the map
        pr = max(abs(n) + len(w) // 2 for n, w in kr)
        pc = max(abs(n) + len(w) // 2 for n, w in kc)
        h, w_ = self.grid.shape
        padded = np.zeros((h + 2 * pr, w_ + 2 * pc))
        out = np.empty_like(self.belief)
        for k in range(self.K):           # one loop per heading slice, each a vectorised 2-D operation
            (nr, wr), (nc, wc) = kr[k], kc[k]
            padded[pr:pr + h, pc:pc + w_] = self.belief[k]
            s = ndimage.convolve1d(padded, wr, axis=0, mode="constant")
            s = ndimage.convolve1d(s, wc, axis=1, mode="constant")
            out[k] = s[pr - nr:pr - nr + h, pc - nc:pc - nc + w_]
        nt, wt = shift_kernel((rot1 + rot2) / self.bin_width, sth)
        out = ndimage.convolve1d(out, wt, axis=0, mode="wrap")
        out = np.roll(out, nt, axis=0)
        out *= self.free
        total = out.sum()
        if total <= 0:
            raise ZeroLikelihoodError("after the motion no belief is left on a free cell (it all moved off the "
                                      "map or into obstacles); reset the belief")
        self.belief = out / total

    # ------------------------------------------------------------ correction
    def log_likelihood(self, ranges: ArrayLike) -> NDArray[np.float32]:
        """``log p(z | heading, cell)`` of a scan, shape ``(K, H, W)``.

        Examples
        --------
        >>> g = OccupancyGrid.from_ascii("#####\\n#...#\\n#####")
        >>> loc = GridLocalizer(g, 4, [0.0], 5.0, expected=expected_range_table(g, 4, 5.0, "exact"))
        >>> loc.log_likelihood([2.5]).shape
        (4, 3, 5)
        """
        z = np.asarray(ranges, dtype=float)
        if z.shape != self.angles.shape:
            raise ValueError(f"ranges must have one reading per beam, shape {self.angles.shape}; got {z.shape}")
        if not np.all(np.isfinite(z)) or np.any(z < 0):
            raise ValueError("ranges must be finite and >= 0 (use max_range for 'no return')")
        levels = np.arange(self.n_levels) * self.range_step
        ll = np.zeros(self.belief.shape, dtype=np.float32)
        for b in range(len(z)):            # one loop per beam, each a gather over all bins
            p = np.asarray(self.pdf(np.full(levels.shape, min(z[b], self.max_range)), levels), dtype=float)
            if np.any(~np.isfinite(p)) or np.any(p < 0):
                raise ValueError("beam_pdf returned negative or non-finite values")
            with np.errstate(divide="ignore"):
                table = np.log(p).astype(np.float32)
            codes = np.roll(self.codes, -int(self.beam_bins[b]), axis=0)
            ll += table[codes]
        return ll

    def update(self, ranges: ArrayLike) -> None:
        """Correction with a scan: multiply by the beam likelihoods (in logs), normalise.

        Examples
        --------
        >>> g = OccupancyGrid.from_ascii("#####\\n#...#\\n#####")
        >>> loc = GridLocalizer(g, 4, [0.0], 5.0, expected=expected_range_table(g, 4, 5.0, "exact"))
        >>> loc.update([2.5])       # 2.5 m ahead: at one end of the corridor, looking along it
        >>> loc.marginal_xy().round(2)   # the corridor is symmetric: both ends are equally likely
        array([[0.  , 0.  , 0.  , 0.  , 0.  ],
               [0.  , 0.49, 0.02, 0.49, 0.  ],
               [0.  , 0.  , 0.  , 0.  , 0.  ]])
        """
        ll = self.log_likelihood(ranges)
        support = self.belief > 0
        top = ll[support].max() if support.any() else -np.inf
        if not np.isfinite(top):
            raise ZeroLikelihoodError("the scan has zero likelihood wherever the belief is non-zero")
        post = self.belief * np.exp(ll - top)
        total = post.sum()
        if total <= 0:
            raise ZeroLikelihoodError("the scan has zero likelihood wherever the belief is non-zero")
        self.belief = post / total

    def step(self, u: ArrayLike, ranges: ArrayLike) -> None:
        """``predict(u)`` then ``update(ranges)`` (one cycle of PR table 8.1).

        Examples
        --------
        >>> g = OccupancyGrid.from_ascii("######\\n#....#\\n######")
        >>> loc = GridLocalizer(g, 4, [0.0, np.pi / 2], 5.0, expected=expected_range_table(g, 4, 5.0, "exact"))
        >>> loc.step([[0, 0, 0], [0, 0, 0]], [3.5, 0.5])     # no motion, then a scan of two beams
        >>> round(float(loc.marginal_xy()[1, 1] + loc.marginal_xy()[1, 4]), 3)   # at an end, looking along
        1.0
        """
        self.predict(u)
        self.update(ranges)

    # ------------------------------------------------------------- estimates
    def cell_pose(self, k: int, i: int, j: int) -> NDArray[np.float64]:
        """The pose ``(x, y, theta)`` at the centre of bin ``(k, i, j)``.

        Examples
        --------
        >>> loc = GridLocalizer(OccupancyGrid(np.zeros((2, 2)), 0.5), 4, [0.0], 1.0, expected=np.ones((4, 2, 2)))
        >>> loc.cell_pose(2, 1, 0).round(3)
        array([0.25, 0.75, 0.  ])
        """
        x, y = self.grid.cell_to_world([[int(i), int(j)]])[0]
        return np.array([x, y, self.theta[int(k)]])

    def estimate(self) -> NDArray[np.float64]:
        """The most likely pose: the centre of the bin with the highest belief (see :meth:`reset`)."""
        k, i, j = np.unravel_index(int(np.argmax(self.belief)), self.belief.shape)
        return self.cell_pose(k, i, j)

    def marginal_xy(self) -> NDArray[np.float64]:
        """Belief over cells, summed over headings, shape ``(H, W)``.

        Examples
        --------
        >>> loc = GridLocalizer(OccupancyGrid(np.zeros((2, 3)), 0.5), 4, [0.0], 1.0, expected=np.ones((4, 2, 3)))
        >>> loc.marginal_xy().round(3)
        array([[0.167, 0.167, 0.167],
               [0.167, 0.167, 0.167]])
        """
        return self.belief.sum(axis=0)

    def marginal_theta(self) -> NDArray[np.float64]:
        """Belief over heading bins, shape ``(K,)``.

        Examples
        --------
        >>> loc = GridLocalizer(OccupancyGrid(np.zeros((2, 3)), 0.5), 4, [0.0], 1.0, expected=np.ones((4, 2, 3)))
        >>> loc.marginal_theta().round(3)
        array([0.25, 0.25, 0.25, 0.25])
        """
        return self.belief.sum(axis=(1, 2))


# ---------------------------------------------------------------- readable
def predict_readable(loc: GridLocalizer, u: ArrayLike) -> NDArray[np.float64]:
    """The prediction of :meth:`GridLocalizer.predict` as loops over every bin (the test oracle).

    Each bin ``(k, i, j)`` pushes its belief to the cells the robot may reach:
    for every row offset, column offset (kernels of :func:`shift_kernel` for
    that heading's displacement) and heading offset. Returns the new belief
    without changing ``loc``.

    Examples
    --------
    >>> g = OccupancyGrid(np.zeros((6, 6)), 0.1)
    >>> loc = GridLocalizer(g, 4, [0.0], 1.0, expected=np.ones((4, 6, 6)))
    >>> slow = predict_readable(loc, [[0, 0, 0], [0.2, 0, 0.3]])
    >>> loc.predict([[0, 0, 0], [0.2, 0, 0.3]])
    >>> bool(np.allclose(slow, loc.belief))
    True
    """
    prev, odom = _check_u(u)
    rot1, trans, rot2 = (float(v) for v in odometry_to_control(prev, odom))
    sxy, sth = motion_blur(rot1, trans, rot2, loc.alphas, loc.grid.resolution, loc.bin_width,
                           loc.min_sigma_xy, loc.min_sigma_theta)
    res = loc.grid.resolution
    K, H, W = loc.belief.shape
    nt, wt = shift_kernel((rot1 + rot2) / loc.bin_width, sth)
    rt = len(wt) // 2
    out = np.zeros_like(loc.belief)
    for k in range(K):
        nr, wr = shift_kernel(trans * np.sin(loc.theta[k] + rot1) / res, sxy)
        nc, wc = shift_kernel(trans * np.cos(loc.theta[k] + rot1) / res, sxy)
        r, c = len(wr) // 2, len(wc) // 2
        for i in range(H):
            for j in range(W):
                mass = loc.belief[k, i, j]
                if mass == 0:
                    continue
                for a in range(len(wr)):
                    ti = i + nr + a - r
                    if not 0 <= ti < H or wr[a] == 0:
                        continue
                    for b in range(len(wc)):
                        tj = j + nc + b - c
                        if not 0 <= tj < W or wc[b] == 0:
                            continue
                        for t in range(len(wt)):
                            tk = (k + nt + t - rt) % K
                            out[tk, ti, tj] += mass * wr[a] * wc[b] * wt[t]
    out *= loc.free
    return out / out.sum()


def update_readable(loc: GridLocalizer, ranges: ArrayLike) -> NDArray[np.float64]:
    """The correction of :meth:`GridLocalizer.update` as loops, with unquantised expected ranges.

    For every bin, multiply the belief by the product over beams of
    ``pdf(z_b, E[(k + m_b) mod K, i, j])``, then normalise. Returns the new
    belief without changing ``loc``.

    Examples
    --------
    >>> g = OccupancyGrid.from_ascii("#####\\n#...#\\n#####")
    >>> loc = GridLocalizer(g, 4, [0.0], 5.0, expected=expected_range_table(g, 4, 5.0, "exact"))
    >>> slow = update_readable(loc, [2.5])
    >>> loc.update([2.5])
    >>> bool(np.allclose(slow, loc.belief, rtol=1e-3))
    True
    """
    z = np.asarray(ranges, dtype=float)
    K, H, W = loc.belief.shape
    out = np.zeros_like(loc.belief)
    for k in range(K):
        for i in range(H):
            for j in range(W):
                p = loc.belief[k, i, j]
                for b in range(len(z)):
                    e = loc.expected[(k + loc.beam_bins[b]) % K, i, j]
                    p *= float(loc.pdf(min(z[b], loc.max_range), min(float(e), loc.max_range)))
                out[k, i, j] = p
    total = out.sum()
    if total <= 0:
        raise ZeroLikelihoodError("the scan has zero likelihood wherever the belief is non-zero")
    return out / total
