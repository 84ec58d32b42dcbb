"""Built-in example worlds, drawn in code so that the book runs anywhere.

* :func:`hallway` — the 1-D corridor with doors of the Bayes-filter chapter.
* :func:`office` — a 20 m x 12 m office with rooms, a corridor and furniture.
* :func:`symmetric_room` — a near-symmetric hall that fools a localizer.
* :func:`random_rooms` — random box worlds for tests and benchmarks.
* :func:`benchmark_map` — the 800 x 800 map the speed targets refer to.
* :func:`tile_world` — the 5 x 7 floor of coloured tiles of the histogram chapter.
* :func:`city_world` — a city of coloured tiles in labelled districts (coarse-to-fine localization).
* :func:`draw_box` — add a filled rectangle (a desk, a pillar) to an occupancy array.

Every name of ``__all__`` is listed above:

>>> import localize.maps as maps
>>> all(f":func:`{name}`" in maps.__doc__ for name in maps.__all__)
True
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ._checks import check_rng
from .grid import OccupancyGrid

__all__ = ["hallway", "office", "symmetric_room", "random_rooms", "benchmark_map", "draw_box", "tile_world", "city_world"]


def hallway(n_cells: int = 20, doors: tuple[int, ...] = (2, 5, 13)) -> NDArray[np.int64]:
    """A 1-D hallway: ``1`` where a cell faces a door, ``0`` where it faces wall.

    The default has three doors with unequal gaps, like the corridor of
    *Probabilistic Robotics* (Thrun, Burgard and Fox 2005, figure 1.1), so
    that a robot that has seen two doors knows where it is.

    Examples
    --------
    >>> hallway(10, doors=(0, 1, 8))
    array([1, 1, 0, 0, 0, 0, 0, 0, 1, 0])
    """
    n_cells = int(n_cells)
    if n_cells < 1:
        raise ValueError(f"n_cells must be >= 1; got {n_cells}")
    h = np.zeros(n_cells, dtype=np.int64)
    for d in doors:
        if not 0 <= int(d) < n_cells:
            raise ValueError(f"door position {d} is outside the hallway of {n_cells} cells (0..{n_cells - 1})")
        h[int(d)] = 1
    return h


def draw_box(data: NDArray, resolution: float, x0: float, y0: float, x1: float, y1: float,
             value: float = 1.0) -> None:
    """Fill the cells of the world rectangle ``[x0, x1] x [y0, y1]`` (metres, origin 0) in place.

    Edges are rounded to the nearest cell boundary. A rectangle thinner than a
    cell still fills the one row or column that holds its centre line, so a
    thin wall survives a coarse resolution (``office(0.25)`` keeps every wall).

    Examples
    --------
    >>> d = np.zeros((4, 4))
    >>> draw_box(d, 0.25, 0.0, 0.45, 1.0, 0.55)     # a 10 cm wall in 25 cm cells
    >>> d[:, 0]
    array([0., 0., 1., 0.])
    """
    j0, j1 = int(round(x0 / resolution)), int(round(x1 / resolution))
    i0, i1 = int(round(y0 / resolution)), int(round(y1 / resolution))
    if j1 <= j0 and x1 > x0:
        j0 = int(np.floor(0.5 * (x0 + x1) / resolution))
        j1 = j0 + 1
    if i1 <= i0 and y1 > y0:
        i0 = int(np.floor(0.5 * (y0 + y1) / resolution))
        i1 = i0 + 1
    data[max(i0, 0):max(i1, 0), max(j0, 0):max(j1, 0)] = value


def _walls(data: NDArray, res: float, segments, t: float) -> None:
    for (xa, ya, xb, yb) in segments:
        draw_box(data, res, min(xa, xb) - t / 2, min(ya, yb) - t / 2,
                 max(xa, xb) + t / 2, max(ya, yb) + t / 2)


def office(resolution: float = 0.1) -> OccupancyGrid:
    """A 20 m x 12 m office: four rooms, a corridor, doors and furniture.

    The layout is deliberately irregular (rooms of different sizes, doors at
    different offsets, a few desks and a pillar) so that global localization
    has a unique answer, yet long stretches of corridor look alike.

    Examples
    --------
    >>> g = office()
    >>> g.shape, g.resolution
    ((120, 200), 0.1)
    >>> bool(0.5 < g.free.mean() < 0.9)
    True
    """
    res = float(resolution)
    if res <= 0 or res > 0.5:
        raise ValueError(f"resolution must be in (0, 0.5] metres for the office; got {resolution}")
    W, H, t = 20.0, 12.0, 0.2
    d = np.zeros((int(round(H / res)), int(round(W / res))))
    # outer walls
    _walls(d, res, [(0.1, 0.1, 19.9, 0.1), (0.1, 11.9, 19.9, 11.9),
                    (0.1, 0.1, 0.1, 11.9), (19.9, 0.1, 19.9, 11.9)], t)
    # corridor between y = 4.5 and y = 6.5
    _walls(d, res, [(0.1, 4.5, 19.9, 4.5), (0.1, 6.5, 19.9, 6.5)], t)
    # room partitions below the corridor: rooms [0,7], [7,12], [12,20]
    _walls(d, res, [(7.0, 0.1, 7.0, 4.5), (12.0, 0.1, 12.0, 4.5)], t)
    # above the corridor: rooms [0,5], [5,13], [13,20]
    _walls(d, res, [(5.0, 6.5, 5.0, 11.9), (13.0, 6.5, 13.0, 11.9)], t)
    # doors (openings in the corridor walls), at irregular offsets
    for (xa, xb, y) in [(2.0, 3.0, 4.5), (9.0, 10.0, 4.5), (15.5, 16.5, 4.5),
                        (3.5, 4.5, 6.5), (8.0, 9.0, 6.5), (17.0, 18.0, 6.5)]:
        draw_box(d, res, xa, y - t, xb, y + t, 0.0)
    # furniture: desks, a pillar, a cabinet
    for box in [(1.0, 1.0, 2.5, 1.8), (4.0, 2.5, 5.5, 3.2), (8.0, 1.0, 9.0, 2.2),
                (13.5, 1.0, 16.0, 1.6), (17.5, 2.5, 18.5, 3.5), (1.0, 9.5, 3.0, 10.5),
                (8.5, 8.5, 9.5, 9.5), (14.0, 10.6, 18.5, 11.4), (10.8, 5.3, 11.2, 5.7)]:
        draw_box(d, res, *box)
    return OccupancyGrid(d, res)


def symmetric_room(resolution: float = 0.1, tell: bool = True) -> OccupancyGrid:
    """A 12 m x 6 m hall with four pillars placed with 180-degree symmetry.

    Seen from inside, a pose and the pose rotated by 180 degrees about the
    hall's centre give identical scans, so a localizer has two equally good
    answers. With ``tell=True`` (default) one small box in a corner breaks the
    tie — but only for a robot that happens to see it, which is exactly the
    trap the chapter on failures studies.

    Examples
    --------
    >>> a, b = symmetric_room(tell=False), symmetric_room()
    >>> bool(np.array_equal(a.data, a.data[::-1, ::-1])), bool(np.array_equal(b.data, b.data[::-1, ::-1]))
    (True, False)
    """
    res = float(resolution)
    if res <= 0 or res > 0.5:
        raise ValueError(f"resolution must be in (0, 0.5] metres; got {resolution}")
    W, H = 12.0, 6.0
    d = np.zeros((int(round(H / res)), int(round(W / res))))
    t = 0.2
    draw_box(d, res, 0.0, 0.0, W, t)
    draw_box(d, res, 0.0, H - t, W, H)
    draw_box(d, res, 0.0, 0.0, t, H)
    draw_box(d, res, W - t, 0.0, W, H)
    for (cx, cy) in [(3.0, 2.0), (5.0, 4.0)]:
        for (px, py) in [(cx, cy), (W - cx, H - cy)]:
            draw_box(d, res, px - 0.3, py - 0.3, px + 0.3, py + 0.3)
    if tell:
        draw_box(d, res, W - 1.0, t, W - t, t + 0.4)
    return OccupancyGrid(d, res)


def random_rooms(
    shape: tuple[int, int],
    resolution: float,
    rng: np.random.Generator,
    n_boxes: int = 20,
    border: bool = True,
    max_box: float = 0.15,
) -> OccupancyGrid:
    """A random world: a walled rectangle with ``n_boxes`` random boxes inside.

    Used by tests (random maps for ray-casting agreement) and benchmarks.
    ``max_box`` is the largest box side as a fraction of the map's side.

    Examples
    --------
    >>> g = random_rooms((50, 80), 0.1, np.random.default_rng(1), n_boxes=5)
    >>> g.shape, bool(g.obstacles[0].all())
    ((50, 80), True)
    """
    check_rng(rng)
    h, w = (int(s) for s in shape)
    if h < 3 or w < 3:
        raise ValueError(f"shape must be at least (3, 3); got {shape}")
    d = np.zeros((h, w))
    if border:
        d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 1.0
    for _ in range(int(n_boxes)):
        bh = int(rng.integers(1, max(2, int(h * max_box))))
        bw = int(rng.integers(1, max(2, int(w * max_box))))
        i = int(rng.integers(0, h - bh))
        j = int(rng.integers(0, w - bw))
        d[i:i + bh, j:j + bw] = 1.0
    return OccupancyGrid(d, resolution)


def benchmark_map(size: int = 800, resolution: float = 0.05) -> OccupancyGrid:
    """The deterministic ``size x size`` map used by the speed benchmarks.

    A 40 m x 40 m (at the defaults) building: a grid of rooms joined by
    doors, plus furniture, built from a fixed seed. It has the size of the
    CMU 16-831 Wean Hall map (800 x 800 cells at 10 cm) in cell count.
    """
    rng = np.random.default_rng(831)
    size = int(size)
    if size < 50:
        raise ValueError(f"size must be >= 50 cells; got {size}")
    d = np.zeros((size, size))
    d[:2, :] = d[-2:, :] = d[:, :2] = d[:, -2:] = 1.0
    step = size // 5
    for k in range(1, 5):
        d[k * step:k * step + 2, :] = 1.0
        d[:, k * step:k * step + 2] = 1.0
    # doors in every wall segment
    for k in range(1, 5):
        for m in range(5):
            a = m * step + int(rng.integers(step // 5, step - step // 5 - step // 10))
            d[k * step:k * step + 2, a:a + step // 10] = 0.0
            b = m * step + int(rng.integers(step // 5, step - step // 5 - step // 10))
            d[b:b + step // 10, k * step:k * step + 2] = 0.0
    for _ in range(60):
        bh, bw = (int(v) for v in rng.integers(3, step // 6, size=2))
        i, j = (int(v) for v in rng.integers(4, size - 4 - step // 6, size=2))
        d[i:i + bh, j:j + bw] = 1.0
    return OccupancyGrid(d, resolution)


def tile_world() -> NDArray[np.str_]:
    """The 5 x 7 world of coloured tiles used by the histogram-localization chapter.

    Four colours (``"red"``, ``"green"``, ``"blue"``, ``"yellow"``); row 0 is
    the top row as printed. The layout is designed so that a robot with a
    colour sensor that is right 85 % of the time reproduces the worked example
    of the chapter: five blue tiles, so that after reading 'blue' from a
    uniform start the blue tiles hold 0.097 and the others 0.017.

    Examples
    --------
    >>> w = tile_world()
    >>> w.shape, int((w == "blue").sum())
    ((5, 7), 5)
    """
    g, r, b, y = "green", "red", "blue", "yellow"
    return np.array([
        [g, g, g, r, r, r, r],
        [r, r, g, g, b, r, r],
        [y, y, y, g, b, b, g],
        [y, g, g, g, b, g, g],
        [y, g, y, g, g, g, b],
    ])


def city_world(blocks: tuple[int, int], block: int, rng: np.random.Generator, n_colours: int = 4,
               n_districts: int = 6) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """A large tile world for multi-scale localization: random tile colours in random districts.

    Returns ``(fine, coarse)``: ``coarse`` has shape ``blocks`` and holds a
    district label in ``0 .. n_districts - 1`` per block; ``fine`` has shape
    ``blocks * block`` and holds a tile colour in ``0 .. n_colours - 1``.

    Examples
    --------
    >>> fine, coarse = city_world((3, 4), 5, np.random.default_rng(0))
    >>> fine.shape, coarse.shape
    ((15, 20), (3, 4))
    """
    check_rng(rng)
    hb, wb = (int(v) for v in blocks)
    if hb < 1 or wb < 1 or int(block) < 1:
        raise ValueError(f"blocks and block must be >= 1; got {blocks} and {block}")
    if n_colours < 2 or n_districts < 2:
        raise ValueError("n_colours and n_districts must be >= 2")
    coarse = rng.integers(0, n_districts, size=(hb, wb))
    fine = rng.integers(0, n_colours, size=(hb * int(block), wb * int(block)))
    return fine, coarse
