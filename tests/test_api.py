"""API stumbles students hit: top-level names, the notation's names, radians, coarse maps, run controls."""

from __future__ import annotations

import numpy as np
import pytest

import localize
from localize import histogram, maps, raycast, sim


@pytest.mark.parametrize("name, module", sorted(localize._LAZY_NAMES.items()))
def test_main_classes_at_top_level(name, module):
    obj = getattr(localize, name)
    assert obj is getattr(getattr(localize, module), name)
    assert name in dir(localize) and name in localize.__all__


def test_submodules_and_unknown_names():
    assert localize.maps is maps and localize.check.Report
    from localize import MCL, GridLocalizer  # noqa: F401  - the import students write
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        localize.Nope  # noqa: B018


def test_sense_accepts_the_notation_name_z():
    world = np.array([["g", "r", "g"]])
    b = np.full((1, 3), 1 / 3)
    np.testing.assert_array_equal(histogram.sense(b, world, z="r", p_hit=0.8, p_miss=0.2),
                                  histogram.sense(b, world, "r", 0.8, 0.2))
    with pytest.raises(TypeError, match="twice"):
        histogram.sense(b, world, "r", 0.8, 0.2, z="r")
    with pytest.raises(TypeError, match="needs the reading"):
        histogram.sense(b, world, p_hit=0.8, p_miss=0.2)


def test_beam_angles_in_degrees_are_refused():
    grid = maps.office()
    pose = np.array([[6.0, 5.5, 0.0]])
    degrees = np.arange(-90.0, 91.0, 45.0)
    with pytest.raises(ValueError, match="degrees"):
        raycast.cast(grid, pose, degrees, 8.0)
    from localize.sensors import BeamModel

    with pytest.raises(ValueError, match="np.radians"):
        BeamModel(grid, 8.0).log_likelihood(pose, np.full(5, 3.0), degrees)
    from localize.gridloc import GridLocalizer

    with pytest.raises(ValueError, match="degrees"):
        GridLocalizer(grid, 8, degrees, 8.0, expected=np.ones((8,) + grid.shape))
    # radians up to a full turn are fine
    assert raycast.cast(grid, pose, np.radians(degrees), 8.0).shape == (1, 5)
    assert raycast.cast(grid, pose, [-2 * np.pi, 2 * np.pi], 8.0).shape == (1, 2)


@pytest.mark.parametrize("res", [0.05, 0.1, 0.2, 0.25, 0.3, 0.5])
def test_office_keeps_its_walls_at_coarse_resolutions(res):
    g = maps.office(res)
    walls = [(6.0, 4.5), (6.0, 6.5), (7.0, 2.0), (12.0, 3.0), (5.0, 9.0), (13.0, 9.0), (10.0, 0.1), (10.0, 11.9),
             (0.1, 6.0), (19.9, 6.0)]
    doors = [(2.5, 4.5), (9.5, 4.5), (4.0, 6.5), (17.5, 6.5)]
    def walled(p):  # a wall cell at the point or within half a cell of it (walls snap to cell edges)
        h = res / 2
        near = [p, (p[0] - h, p[1]), (p[0] + h, p[1]), (p[0], p[1] - h), (p[0], p[1] + h)]
        return any(g.occupied[tuple(g.world_to_cell(q, outside="clip"))] for q in near)

    lost = [p for p in walls if not walled(p)]
    assert not lost, f"office({res}) lost the walls at {lost}"
    assert not any(g.occupied[tuple(g.world_to_cell(p))] for p in doors), f"office({res}) closed a door"


def test_controls_indexed_alike_in_every_run():
    rng = np.random.default_rng(0)
    rr = sim.range_run(maps.office(), rng, n_steps=4, angles=[])
    cr = sim.corridor_run(rng, n_steps=4)
    for k in range(1, 4):
        np.testing.assert_array_equal(rr.controls[k], np.stack(rr.control(k)))
        assert cr.control(k) == cr.controls[k]
    np.testing.assert_array_equal(rr.controls[0, 0], rr.controls[0, 1])     # no motion into step 0
    assert rr.controls.shape == (4, 2, 3) and len(cr.controls) == 4
    for run in (rr, cr):
        with pytest.raises(ValueError, match="step 0 has no motion"):
            run.control(0)
