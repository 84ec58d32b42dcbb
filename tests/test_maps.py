"""Tests of the built-in worlds in localize.maps."""

import numpy as np
import pytest
from scipy import ndimage

from localize import maps


def test_hallway():
    h = maps.hallway()
    assert h.shape == (20,) and set(np.unique(h)) == {0, 1} and h.sum() == 3
    # gaps between doors are all different, so two sightings identify the place
    gaps = np.diff(np.flatnonzero(h))
    assert len(set(gaps.tolist())) == len(gaps)
    with pytest.raises(ValueError, match="outside the hallway"):
        maps.hallway(5, doors=(7,))
    with pytest.raises(ValueError, match="n_cells"):
        maps.hallway(0)


def test_office_is_connected_and_closed():
    g = maps.office()
    assert g.shape == (120, 200)
    labels, n = ndimage.label(g.free)
    assert n == 1, "every free cell of the office must be reachable"
    assert g.obstacles[0].all() and g.obstacles[-1].all() and g.obstacles[:, 0].all() and g.obstacles[:, -1].all()


def test_office_has_no_symmetry():
    d = maps.office().data
    assert not np.array_equal(d, d[::-1]) and not np.array_equal(d, d[:, ::-1]) and not np.array_equal(d, d[::-1, ::-1])


def test_symmetric_room():
    a = maps.symmetric_room(tell=False)
    assert np.array_equal(a.data, a.data[::-1, ::-1])
    b = maps.symmetric_room()
    diff = np.argwhere(a.data != b.data)
    assert 0 < len(diff) < 0.01 * a.data.size  # a small tell-tale only


def test_random_rooms_deterministic():
    a = maps.random_rooms((40, 60), 0.1, np.random.default_rng(3))
    b = maps.random_rooms((40, 60), 0.1, np.random.default_rng(3))
    np.testing.assert_array_equal(a.data, b.data)
    with pytest.raises(TypeError):
        maps.random_rooms((40, 60), 0.1, 3)


def test_benchmark_map():
    g = maps.benchmark_map()
    assert g.shape == (800, 800) and g.resolution == 0.05
    assert 0.8 < g.free.mean() < 0.97
    labels, n = ndimage.label(g.free)
    sizes = np.bincount(labels.ravel())[1:]
    assert sizes.max() > 0.9 * g.free.sum(), "the rooms must be joined by doors"
    np.testing.assert_array_equal(g.data, maps.benchmark_map().data)
