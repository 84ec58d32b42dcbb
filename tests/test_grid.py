"""Tests of localize.grid.OccupancyGrid: validation, transforms, masks, sampling, distance field."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from localize import OccupancyGrid, maps


def small():
    return OccupancyGrid.from_ascii(
        """
        #######
        #..?..#
        #.....#
        #######
        """.replace("        ", ""),
        resolution=0.5,
        origin=(-1.0, 2.0),
    )


def test_from_ascii_orientation():
    g = small()
    assert g.shape == (4, 7)
    # first text line is the top of the map = last row
    assert np.all(g.data[-1] == 1.0) and np.all(g.data[0] == 1.0)
    # the '?' sits on the second text line = row 2, column 3
    assert np.isnan(g.data[2, 3]) and g.unknown.sum() == 1
    assert g.extent == (-1.0, 2.5, 2.0, 4.0)


def test_cell_centre_convention():
    g = small()
    # DESIGN: x = origin_x + (j + 0.5) * res, y = origin_y + (i + 0.5) * res
    np.testing.assert_allclose(g.cell_to_world([2, 3]), [-1.0 + 3.5 * 0.5, 2.0 + 2.5 * 0.5])


@given(st.integers(0, 3), st.integers(0, 6))
def test_cell_world_roundtrip(i, j):
    g = small()
    assert tuple(g.world_to_cell(g.cell_to_world([i, j]))) == (i, j)


@given(st.floats(0, 0.999999), st.floats(0, 0.999999))
def test_points_inside_a_cell_map_to_it(u, v):
    g = small()
    x = g.origin[0] + (4 + u) * g.resolution
    y = g.origin[1] + (1 + v) * g.resolution
    assert tuple(g.world_to_cell([x, y])) == (1, 4)


def test_edge_cells_and_outside():
    g = small()
    xmin, xmax, ymin, ymax = g.extent
    assert tuple(g.world_to_cell([xmin, ymin])) == (0, 0)
    assert tuple(g.world_to_cell([xmax - 1e-9, ymax - 1e-9])) == (3, 6)
    # the upper edges belong to no cell: outside is reported, never wrapped
    with pytest.raises(ValueError, match="outside the map"):
        g.world_to_cell([xmax, ymin])
    with pytest.raises(ValueError, match=r"1 point\(s\)"):
        g.world_to_cell([[0.0, 3.0], [xmin - 0.01, 3.0]])
    np.testing.assert_array_equal(g.world_to_cell([[xmin - 5, ymax + 5]], outside="clip"), [[3, 0]])
    np.testing.assert_array_equal(g.world_to_cell([[xmin - 5, 3.0], [np.nan, 3.0]], outside="flag"), [[-1, -1], [-1, -1]])
    assert not g.contains([np.nan, 3.0])
    with pytest.raises(ValueError, match="outside must be"):
        g.world_to_cell([0, 0], outside="wrap")
    with pytest.raises(ValueError, match="outside the grid"):
        g.cell_to_world([4, 0])
    with pytest.raises(ValueError, match="outside the grid"):
        g.cell_to_world([0, -1])


def test_vectorised_transforms():
    g = maps.office()
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0], [g.width_m, g.height_m], size=(50, 20, 2))
    cells = g.world_to_cell(pts)
    assert cells.shape == (50, 20, 2)
    centres = g.cell_to_world(cells)
    assert np.all(np.abs(centres - pts) <= g.resolution / 2 + 1e-12)


def test_masks():
    g = small()
    assert g.free.sum() == 9 and g.occupied.sum() == 18 and g.unknown.sum() == 1
    assert g.obstacles.sum() == 19
    g2 = OccupancyGrid(g.data, g.resolution, g.origin, unknown_is_obstacle=False)
    assert g2.obstacles.sum() == 18
    assert not g.is_free([0.75, 3.25])  # the unknown cell
    assert g.is_free([-0.25, 2.75])
    assert not g.is_free([100.0, 100.0])


def test_threshold():
    g = OccupancyGrid([[0.2, 0.6, 0.9]], 1.0, occupied_threshold=0.65)
    np.testing.assert_array_equal(g.occupied, [[False, False, True]])


def test_immutable():
    g = small()
    with pytest.raises(ValueError):
        g.data[0, 0] = 0.0
    src = np.zeros((2, 2))
    g2 = OccupancyGrid(src, 1.0)
    src[0, 0] = 1.0
    assert g2.data[0, 0] == 0.0


def test_distance_field_against_brute_force():
    rng = np.random.default_rng(2)
    g = maps.random_rooms((30, 40), 0.1, rng, n_boxes=6)
    d = g.distance_field
    occ = np.argwhere(g.obstacles)
    cells = np.argwhere(np.ones(g.shape, bool))
    brute = np.sqrt(((cells[:, None, :] - occ[None, :, :]) ** 2).sum(-1)).min(1) * g.resolution
    np.testing.assert_allclose(d.ravel(), brute, atol=1e-9)
    assert g.distance_field is d  # cached
    assert g.distance_at([[0.05, 0.05]])[0] == 0.0
    assert np.isnan(g.distance_at([[-1.0, 0.0]])[0])


def test_distance_field_empty_map():
    g = OccupancyGrid(np.zeros((3, 3)), 1.0)
    assert np.all(np.isinf(g.distance_field))


def test_sample_free_uniform_over_free_space():
    g = small()
    rng = np.random.default_rng(5)
    n = 90_000
    p = g.sample_free(n, rng)
    assert p.shape == (n, 3)
    assert np.all(g.is_free(p))
    assert np.all((p[:, 2] >= -np.pi) & (p[:, 2] < np.pi))
    # each of the 9 free cells gets n/9 samples; binomial sd = sqrt(n p (1-p))
    cells = g.world_to_cell(p)
    _, counts = np.unique(cells[:, 0] * 100 + cells[:, 1], return_counts=True)
    assert len(counts) == 9
    sd = np.sqrt(n * (1 / 9) * (8 / 9))
    assert np.all(np.abs(counts - n / 9) < 5 * sd)
    # uniform heading: mean of cos ~ 0 with sd 1/sqrt(2n)
    assert abs(np.cos(p[:, 2]).mean()) < 5 / np.sqrt(2 * n)
    # reproducible with the same seed
    np.testing.assert_array_equal(g.sample_free(10, np.random.default_rng(1)), g.sample_free(10, np.random.default_rng(1)))


def _holes_map() -> OccupancyGrid:
    """A walled room amid unknown that reaches the map's edge, with a patch of its floor left unknown, and a back
    room that the map's laser saw only through its door: one-cell lines of free cells between unknown strips."""
    data = np.full((30, 30), np.nan)
    data[2:28, 2:28] = 0.0
    data[2, 2:28] = data[27, 2:28] = data[2:28, 2] = data[2:28, 27] = 1.0
    data[8:12, 6:11] = np.nan                                   # the patch: 4 x 5 cells
    data[18, 14:27] = data[18:27, 14] = 1.0                     # the back room's walls, its door at column 20
    data[19:27, 15:27] = np.nan
    data[19:27, 16:27:2] = 0.0                                   # the rays that crossed it
    data[18, 20] = 0.0
    return OccupancyGrid(data, 0.1)


def test_holes_are_the_unknown_patches_of_the_floor():
    g = _holes_map()
    holes = g.holes
    assert {(int(i), int(j)) for i, j in np.argwhere(holes)} == {(i, j) for i in range(8, 12) for j in range(6, 11)}
    # neither the outside (it reaches the edge) nor the strips between the rays (bordered by one-cell lines of free
    # cells, not by floor) is a hole
    assert g.unknown[0, 0] and g.unknown[20, 15] and not holes[0, 0] and not holes[20, 15]
    with pytest.raises(ValueError):
        holes[8, 6] = False                       # read-only, like the other masks
    # small()'s one unknown cell has no open floor around it (a 3 x 3 block of free cells) ...
    assert small().unknown.sum() == 1 and not small().holes.any()
    # ... and a map without unknown cells has none, and neither has an unknown map (it all reaches the edge)
    assert not OccupancyGrid(np.zeros((4, 4)), 1.0).holes.any()
    assert not OccupancyGrid(np.full((4, 4), np.nan), 1.0).holes.any()


def test_sample_free_with_holes_draws_over_the_floor_and_its_holes_alike():
    g = _holes_map()
    n = 60_000
    p = g.sample_free(n, np.random.default_rng(2), holes=True)
    cells = g.world_to_cell(p)
    in_hole = g.holes[cells[:, 0], cells[:, 1]]
    assert np.all(g.free[cells[:, 0], cells[:, 1]] | in_hole)           # never in a wall or the outside
    assert np.array_equal(g.is_free(p, holes=True), np.ones(n, dtype=bool))
    assert np.array_equal(g.is_free(p), ~in_hole)                        # is_free alone: the free cells only
    share = g.holes.sum() / (g.holes.sum() + g.free.sum())               # uniform per cell over both
    assert abs(in_hole.mean() - share) < 5 * np.sqrt(share * (1 - share) / n)
    # without holes: the free cells only
    assert np.all(g.is_free(g.sample_free(1000, np.random.default_rng(2))))


def test_sample_free_errors():
    g = small()
    with pytest.raises(TypeError, match="Generator"):
        g.sample_free(3, 0)
    with pytest.raises(ValueError, match="n must be"):
        g.sample_free(-1, np.random.default_rng())
    with pytest.raises(ValueError, match="no free cell"):
        OccupancyGrid(np.ones((2, 2)), 1.0).sample_free(1, np.random.default_rng())


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(data=np.zeros(5), resolution=1.0), "2-D array"),
        (dict(data=np.zeros((0, 3)), resolution=1.0), "at least one row"),
        (dict(data=np.zeros((2, 2)), resolution=0.0), r"resolution must be a finite number of metres per cell > 0"),
        (dict(data=np.zeros((2, 2)), resolution=-0.1), r"resolution must be a finite number of metres per cell > 0"),
        (dict(data=np.zeros((2, 2)), resolution=np.nan), "resolution must be finite"),
        (dict(data=[[0.0, 1.5]], resolution=1.0), r"\[0, 1\].*1\.5.*row 0, column 1"),
        (dict(data=[[0.0, -0.2]], resolution=1.0), r"\[0, 1\]"),
        (dict(data=[[0.0, np.inf]], resolution=1.0), "infinite"),
        (dict(data=np.zeros((2, 2)), resolution=1.0, origin=(np.nan, 0.0)), "origin must be finite"),
        (dict(data=np.zeros((2, 2)), resolution=1.0, origin=(0.0, 0.0, 0.0)), "origin must be a pair"),
        (dict(data=np.zeros((2, 2)), resolution=1.0, occupied_threshold=0.0), "occupied_threshold"),
    ],
)
def test_rejects_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        OccupancyGrid(**kwargs)


def test_rejects_a_resolution_that_is_not_a_number():
    with pytest.raises(TypeError, match="resolution must be a number of metres per cell; got 'big'"):
        OccupancyGrid(np.zeros((2, 2)), "big")


def test_nan_is_the_unknown_marker():
    g = OccupancyGrid([[np.nan, 0.0]], 1.0)
    assert g.unknown[0, 0] and g.free[0, 1]


def test_from_ascii_errors():
    with pytest.raises(ValueError, match="line 2 has 3 characters, expected 2"):
        OccupancyGrid.from_ascii("##\n###")
    with pytest.raises(ValueError, match="line 1, column 2: unexpected character 'x'"):
        OccupancyGrid.from_ascii("#x")
    with pytest.raises(ValueError, match="empty"):
        OccupancyGrid.from_ascii("\n\n")


@settings(max_examples=30, deadline=None)
@given(st.floats(0.01, 2.0), st.floats(-50, 50), st.floats(-50, 50))
def test_roundtrip_any_resolution_origin(res, ox, oy):
    g = OccupancyGrid(np.zeros((7, 9)), res, origin=(ox, oy))
    cells = np.argwhere(np.ones(g.shape, bool))
    np.testing.assert_array_equal(g.world_to_cell(g.cell_to_world(cells)), cells)


def test_repr():
    assert "shape=(4, 7)" in repr(small()) and "unknown=1" in repr(small())
