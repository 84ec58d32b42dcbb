"""Where in the map does this scan fit? A coarse-to-fine search over the whole free space.

A particle filter answers the question with thousands of particles and many
scans. Some parts of the run driver need a quick answer from one scan: the
probability of being localized compares the estimate with its best *rival*,
the place elsewhere where the scans fit as well
(:class:`localize.reliability.ReliabilityState`). :func:`best_places` finds
such places in two stages:

1. **Search**: the scan is scored by a *blurred* likelihood field
   (:func:`coarse_model`, end points blurred by :data:`COARSE_SIGMA`) at every
   position of a lattice ``2 * COARSE_SIGMA`` apart where the robot may stand
   (a free cell, or one of the map's unknown patches of floor; :func:`lattice`,
   randomly shifted at each call, each position moved to its map cell's
   centre) x :data:`COARSE_HEADINGS` headings: the scan is rotated once per
   heading and slid from cell to cell
   (:meth:`localize.sensors.LikelihoodField.log_likelihood_at_cells`). The
   filter's own sensor model is far too peaked to be searched on a coarse
   grid: the grid pose nearest the robot may be 0.4 m and 5 degrees off and
   score tens of nats below a look-alike that happens to lie on the grid.
   Blurred, every grid pose near the robot scores well.
2. **Refine**: each of the ``n_best`` best distinct places (no two within a
   lattice step and 45 degrees) is hill-climbed with the filter's own
   sensor model (:func:`climb`), with steps from half the lattice's spacing
   and half its heading step halving five times.

This is the correlative idea of scan matchers (Olson, *Real-time correlative
scan matching*, ICRA 2009: a blurred cost table searched exhaustively, coarse
to fine) on the likelihood field of chapter 6.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count, check_rng
from .geometry import compose
from .grid import OccupancyGrid
from .sensors import LikelihoodField

__all__ = ["COARSE_SIGMA", "COARSE_HEADINGS", "coarse_model", "lattice", "best_places", "climb", "climb_on", "stencil",
           "scores", "distinct"]

#: Standard deviation (m) of the blurred likelihood field the search scores with: half the spacing of its
#: lattice of positions (1 m), and about how far a 10-degree heading step moves an end point 5 m away (0.44 m).
COARSE_SIGMA = 0.5

#: Headings of the search (10 degrees apart).
COARSE_HEADINGS = 36


def coarse_model(grid: OccupancyGrid, sensor: Any, sigma: float = COARSE_SIGMA) -> LikelihoodField:
    """A likelihood field of ``grid`` with end points blurred by ``sigma``, with the sensor's range limits.

    Examples
    --------
    >>> from localize.maps import office
    >>> lf = LikelihoodField(office(), 8.0, sigma_hit=0.1, max_beams=30)
    >>> c = coarse_model(office(), lf)
    >>> c.sigma_hit, c.max_range, c.max_beams
    (0.5, 8.0, 30)
    """
    return LikelihoodField(grid, float(sensor.max_range), sigma_hit=float(sigma),
                           sensor_offset=getattr(sensor, "sensor_offset", (0.0, 0.0, 0.0)),
                           max_beams=getattr(sensor, "max_beams", None) or 60,
                           min_range=float(getattr(sensor, "min_range", 0.0) or 0.0), unknown_is_obstacle=False)


def lattice(grid: OccupancyGrid, spacing: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """Positions ``(P, 2)`` where the robot may stand, on a square lattice of ``spacing`` metres, shifted by a random
    offset: the map's free cells and its :attr:`~localize.grid.OccupancyGrid.holes` (unknown patches of the floor).

    Examples
    --------
    >>> from localize.maps import office
    >>> xy = lattice(office(), 1.0, np.random.default_rng(0))
    >>> xy.shape[1], bool(np.all(office().is_free(xy))), 100 < len(xy) < 240
    (2, True, True)
    """
    x0, x1, y0, y1 = grid.extent
    off = rng.uniform(0.0, spacing, 2)
    gx, gy = np.meshgrid(np.arange(x0 + off[0], x1, spacing), np.arange(y0 + off[1], y1, spacing))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    return xy[grid.is_free(xy, holes=True)]


def scores(sensor: Any, poses: NDArray, z: tuple) -> NDArray[np.float64]:
    """The sensor model's log-likelihood of the scan ``z`` at ``poses``; -inf where it cannot score one."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ll = np.asarray(sensor.log_likelihood(poses, *z), dtype=float)
    return np.where(np.isfinite(ll), ll, -np.inf)      # a pose the model cannot score ranks last


def climb(sensor: Any, poses: NDArray, z: tuple, steps: NDArray, iterations: int = 10) -> tuple[NDArray, NDArray]:
    """Hill-climb each pose: move it to the best of itself and itself composed with each of ``steps`` (poses in
    its own frame, e.g. :func:`stencil`), until no move helps or after ``iterations``; ``(poses, scores)``.

    Every pose gets the same moves, so two poses that see the scan alike end alike.

    Examples
    --------
    >>> class Bowl:                        # a score that peaks at (1, 2, 0.3)
    ...     def log_likelihood(self, p, *z):
    ...         return -np.sum((p - [1.0, 2.0, 0.3]) ** 2, axis=1)
    >>> p, ll = climb(Bowl(), np.array([[0.0, 0.0, 0.0]]), (), stencil(0.5, 0.1, 6), iterations=50)
    >>> np.round(p, 1), bool(ll[0] > -1e-3)
    (array([[1. , 2. , 0.3]]), True)
    """
    return climb_on(lambda p: scores(sensor, p, z), poses, steps, iterations)


def climb_on(score: Callable[[NDArray], NDArray], poses: NDArray, steps: NDArray,
             iterations: int = 10) -> tuple[NDArray, NDArray]:
    """:func:`climb` with any score of poses ``(N, 3) -> (N,)`` (e.g. a window of scans); ``(poses, scores)``."""
    poses = np.array(poses, dtype=float)
    moves = np.vstack([np.zeros(3), np.asarray(steps, dtype=float)])
    score_now = np.full(len(poses), -np.inf)
    for _ in range(int(iterations)):
        cand = compose(poses[:, None, :], moves[None, :, :])                  # (N, 1 + M, 3)
        ll = score(cand.reshape(-1, 3)).reshape(len(poses), len(moves))
        k = np.argmax(ll, axis=1)
        poses, score_now = cand[np.arange(len(poses)), k], ll[np.arange(len(poses)), k]
        if np.all(k == 0):
            break
    return poses, score_now


def stencil(xy: float, heading: float, levels: int) -> NDArray[np.float64]:
    """The moves of :func:`climb`: steps along x, y and the heading of ``xy`` metres and ``heading`` radians,
    halved ``levels - 1`` times, forwards and backwards (``6 * levels`` moves).

    Examples
    --------
    >>> stencil(0.4, 0.1, 2)[:, 0].tolist()
    [0.4, 0.0, 0.0, 0.2, 0.0, 0.0, -0.4, -0.0, -0.0, -0.2, -0.0, -0.0]
    """
    scales = np.array([xy, xy, heading])[None, :] * 0.5 ** np.arange(int(levels))[:, None]
    steps = (scales[:, None, :] * np.eye(3)[None]).reshape(-1, 3)
    return np.vstack([steps, -steps])


def distinct(cand: NDArray, order: ArrayLike, n: int, spacing: float, heading: float = np.pi / 4) -> list[int]:
    """Indices of the first ``n`` candidates in ``order`` that are distinct places: none within ``spacing``
    metres of one kept before it with a heading within ``heading`` radians (``np.inf``: any heading).

    Examples
    --------
    >>> cand = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.1], [0.3, 0.0, 3.0], [2.0, 0.0, 0.0]])
    >>> distinct(cand, [0, 1, 2, 3], 4, 1.0), distinct(cand, [0, 1, 2, 3], 4, 1.0, heading=np.inf)
    ([0, 2, 3], [0, 3])
    """
    kept: list[int] = []
    for i in order:
        if len(kept) == n:
            break
        if kept:
            k = cand[kept]
            dth = np.abs((k[:, 2] - cand[i, 2] + np.pi) % (2.0 * np.pi) - np.pi)
            if np.any((np.hypot(*(k[:, :2] - cand[i, :2]).T) < spacing) & (dth < heading)):
                continue
        kept.append(int(i))
    return kept


def _best_first(ll: NDArray, k: int) -> NDArray[np.intp]:
    """Indices of the ``k`` largest entries of ``ll``, largest first (a partial sort)."""
    k = min(int(k), len(ll))
    top = np.argpartition(ll, len(ll) - k)[len(ll) - k:] if k < len(ll) else np.arange(len(ll))
    return top[np.argsort(ll[top])[::-1]]


def best_places(grid: OccupancyGrid, sensor: Any, z: tuple, rng: np.random.Generator, *,
                coarse: LikelihoodField | None = None, n_best: int = 16,
                away_from: NDArray | None = None, radius: float = 0.0) -> tuple[NDArray, NDArray]:
    """``(places (k, 3), log-likelihoods (k,))``: where the scan ``z`` fits best, best first (see the module).

    ``away_from`` and ``radius``: only places at least ``radius`` metres from
    the position ``away_from`` count (the rivals of an estimate). ``k`` is at
    most ``n_best``; 0 when no free place qualifies.

    Examples
    --------
    >>> from localize.maps import random_rooms
    >>> from localize.raycast import RayCaster
    >>> grid = random_rooms((150, 100), 0.1, np.random.default_rng(3))
    >>> lf = LikelihoodField(grid, 8.0, sigma_hit=0.1)
    >>> angles = np.linspace(-np.pi, np.pi, 60, endpoint=False)
    >>> truth = np.array([4.0, 7.0, 0.5])
    >>> z = (RayCaster(grid, 8.0).cast(truth[None], angles)[0], angles)
    >>> places, ll = best_places(grid, lf, z, np.random.default_rng(1))
    >>> bool(np.hypot(*(places[0, :2] - truth[:2])) < 0.3), bool(np.all(np.diff(ll) <= 0))
    (True, True)
    >>> rivals, _ = best_places(grid, lf, z, np.random.default_rng(1), away_from=truth[:2], radius=1.0)
    >>> bool(np.all(np.hypot(*(rivals[:, :2] - truth[:2]).T) >= 1.0))
    True
    """
    rng = check_rng(rng)
    n_best = check_count(n_best, "n_best")
    coarse = coarse_model(grid, sensor) if coarse is None else coarse
    spacing = 2.0 * float(coarse.sigma_hit)
    step = 2.0 * np.pi / COARSE_HEADINGS

    def allowed(p: NDArray) -> NDArray[np.bool_]:
        if away_from is None:
            return np.ones(len(p), dtype=bool)
        return np.hypot(*(p[:, :2] - np.asarray(away_from, dtype=float)[:2]).T) >= radius

    cells = coarse.grid.world_to_cell(lattice(grid, spacing, rng))
    xy = coarse.grid.cell_to_world(cells)                 # each lattice position moved to its cell's centre
    th = rng.uniform(-np.pi, np.pi) + step * np.arange(COARSE_HEADINGS)
    ok = allowed(xy)
    cells, xy = cells[ok], xy[ok]
    if len(xy) == 0:
        return np.empty((0, 3)), np.empty(0)
    ll = coarse.log_likelihood_at_cells(cells, th, *z).ravel()     # position by position, each heading
    for k in (64 * n_best, len(ll)):        # the best first; all of them if too few distinct places are among those
        order = _best_first(ll, k)
        cand = np.column_stack([xy[order // COARSE_HEADINGS], th[order % COARSE_HEADINGS]])
        kept = distinct(cand, range(len(cand)), n_best, spacing)
        if len(kept) == n_best or len(order) == len(ll):
            break
    best = cand[kept]                                      # the best few lattice poses: one place each
    places, p_ll = climb(sensor, best, z, stencil(0.5 * spacing, 0.5 * step, 6))
    ok = allowed(places)
    places, p_ll = places[ok], p_ll[ok]
    places[:, 2] = (places[:, 2] + np.pi) % (2.0 * np.pi) - np.pi
    keep = np.argsort(p_ll)[::-1]
    return places[keep], p_ll[keep]
