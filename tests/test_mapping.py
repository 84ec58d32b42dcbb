"""Tests of localize.mapping: occupancy grid mapping with known poses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from localize import mapping
from localize.grid import OccupancyGrid
from localize.io import LaserLog
from localize.mapping import OccupancyMapper, inverse_range_sensor_model, log_odds, probability
from localize.raycast import cast


def box_room(w=60, h=40, res=0.1):
    d = np.zeros((h, w))
    d[:2] = d[-2:] = 1
    d[:, :2] = d[:, -2:] = 1
    d[15:25, 30:33] = 1  # a pillar
    return OccupancyGrid(d, res)


def test_log_odds_probability():
    p = np.array([0.01, 0.3, 0.5, 0.97])
    assert np.allclose(probability(log_odds(p)), p)
    assert probability(800.0) == 1.0 and probability(-800.0) == 0.0  # no overflow warning
    for bad in (0.0, 1.0, np.nan, -0.1):
        with pytest.raises(ValueError, match="strictly between 0 and 1"):
            log_odds(bad)


def test_single_beam_counts_and_values():
    m = OccupancyMapper((10, 40), 0.1, p_occ=0.8, p_free=0.3)
    m.update([0.05, 0.55, 0.0], [2.0], [0.0], max_range=5.0)
    free, occ = m.counts()
    assert (free, occ) == (20, 1)  # cells x = 0.0 .. 2.0 crossed; the end point's cell is the hit
    g = m.grid()
    row = g.data[5]
    assert np.allclose(row[:20], 0.3) and row[20] == pytest.approx(0.8) and np.isnan(row[21:]).all()
    assert np.isnan(g.data[4]).all()  # neighbouring rows untouched


def test_no_return_and_usable_range():
    m = OccupancyMapper((10, 100), 0.1, usable_range=3.0)
    m.update([0.05, 0.55, 0.0], [9.0], [0.0], max_range=9.0)  # "no return": clears nothing by default
    assert m.counts() == (0, 0) and not m.observed.any()
    m2 = OccupancyMapper((10, 100), 0.1, usable_range=3.0, clear_no_return=True)
    m2.update([0.05, 0.55, 0.0], [9.0], [0.0], max_range=9.0)
    assert m2.counts() == (31, 0)  # cleared up to the usable range (x < 3.05), no hit
    m.update([0.05, 0.55, 0.0], [5.0], [0.0], max_range=9.0)  # a real return beyond the usable range
    assert m.counts() == (31, 0)


def test_occupied_beats_free_within_a_scan_and_once_per_scan():
    m = OccupancyMapper((10, 40), 0.1)
    # beam 1 ends at x = 1.05 (cell 10); beam 2, along the same line, passes through cell 10 to x = 2.0
    m.update([0.05, 0.55, 0.0], [1.0, 1.95, 1.95], [0.0, 0.0, 0.0], max_range=5.0)
    lo = m.log_odds.reshape(m.shape)
    assert lo[5, 10] == pytest.approx(m.l0 + m.l_occ)
    # cells crossed by two beams count once per scan
    assert lo[5, 5] == pytest.approx(m.l0 + m.l_free)


def test_clamping_keeps_the_map_changeable():
    m = OccupancyMapper((10, 40), 0.1, p_max=0.9, p_min=0.2)
    for _ in range(30):
        m.update([0.05, 0.55, 0.0], [1.0], [0.0], max_range=5.0)
    p = m.probabilities()
    assert p[5, 10] == pytest.approx(0.9) and p[5, 5] == pytest.approx(0.2)
    # the obstacle goes away: six scans through it bring the cell below 0.5 again
    # (from logit(0.9) = 2.20 in steps of logit(0.4) = -0.41)
    for _ in range(6):
        m.update([0.05, 0.55, 0.0], [3.0], [0.0], max_range=5.0)
    assert m.probabilities()[5, 10] < 0.5


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), clear=st.booleans())
def test_fast_update_equals_readable_loop(seed, clear):
    rng = np.random.default_rng(seed)
    kw = dict(usable_range=4.0, clear_no_return=clear)
    fast = OccupancyMapper((30, 50), 0.1, origin=(-1.0, -0.5), **kw)
    slow = OccupancyMapper((30, 50), 0.1, origin=(-1.0, -0.5), **kw)
    angles = np.sort(rng.uniform(-np.pi, np.pi, 40))
    for _ in range(3):
        pose = np.array([rng.uniform(-1.5, 4.5), rng.uniform(-1, 3), rng.uniform(-np.pi, np.pi)])  # may be outside
        z = rng.uniform(0.0, 6.0, 40)
        z[rng.random(40) < 0.2] = 6.0  # no return
        fast.update(pose, z, angles, max_range=6.0)
        slow.update_loop(pose, z, angles, max_range=6.0)
        assert fast.counts() == slow.counts()
    assert np.array_equal(fast.log_odds, slow.log_odds)
    assert np.array_equal(fast.observed, slow.observed)


def test_ray_model_agrees_with_pr_table_9_2():
    """The ray form and the per-cell inverse model of PR table 9.2 classify nearly the same cells.

    PR's model marks every cell within alpha/2 of a reading as occupied (a band two
    cells deep for alpha = 2 cells) where the ray form marks only the end point's
    cell; so hits are compared one way, free cells the other.
    """
    room = box_room()
    pose = np.array([2.0, 2.0, 0.3])
    angles = np.radians(np.arange(-180, 180, 1.0))
    z = cast(room, pose[None], angles, 10.0)[0]
    m = OccupancyMapper(room.shape, room.resolution, usable_range=10.0)
    m.update(pose, z, angles, max_range=10.0)
    ray = np.sign(m.log_odds.reshape(room.shape) - m.l0)
    pr = np.zeros(room.shape)
    for i in range(room.shape[0]):
        for j in range(room.shape[1]):
            pr[i, j] = np.sign(inverse_range_sensor_model(room.cell_to_world([i, j]), pose, z, angles, 10.0,
                                                          alpha=0.2, beta=np.radians(1.0),
                                                          l_occ=m.l_occ, l_free=m.l_free))
    assert (pr[ray > 0] > 0).mean() > 0.9      # the ray form's hits are occupied for PR too
    assert (ray[pr < 0] < 0).mean() > 0.98     # PR's free cells are free for the ray form
    assert (pr[ray < 0] != 0).mean() > 0.97    # and what the ray form clears, PR has an opinion on
    assert room.occupied[ray > 0].all()        # and every hit is on a true wall


def test_pr_model_cases():
    kw = dict(max_range=5.0, alpha=0.2, beta=np.radians(3), l_occ=1.0, l_free=-1.0, l0=0.0)
    z, a = np.array([2.0, 5.0]), np.radians([0.0, 90.0])
    assert inverse_range_sensor_model((1.0, 0.0), (0, 0, 0), z, a, **kw) == -1.0
    assert inverse_range_sensor_model((2.05, 0.0), (0, 0, 0), z, a, **kw) == 1.0
    assert inverse_range_sensor_model((2.5, 0.0), (0, 0, 0), z, a, **kw) == 0.0  # behind the obstacle
    assert inverse_range_sensor_model((1.0, 0.5), (0, 0, 0), z, a, **kw) == 0.0  # outside the beam's cone
    assert inverse_range_sensor_model((0.0, 4.99), (0, 0, 0), z, a, **kw) == -1.0  # max reading: free, never hit


def test_build_map_recovers_a_known_world():
    room = box_room()
    rng = np.random.default_rng(7)
    free = room.sample_free(40, rng)
    angles = np.radians(np.arange(-90, 90, 2.0))
    offset = np.array([0.2, 0.0, 0.0])
    from localize.geometry import compose

    z = cast(room, compose(free, offset), angles, 8.0)
    g = mapping.build_map(free, z, angles, max_range=8.0, sensor_offset=offset, resolution=0.1,
                          extent=(0.0, 6.0, 0.0, 4.0))
    assert g.shape == room.shape
    seen = ~g.unknown
    # known cells agree with the truth: walls occupied, floor free (a few boundary cells may differ)
    wrong = (g.occupied != room.occupied) & seen
    assert wrong.sum() / seen.sum() < 0.02
    # the wall faces that the robot can see are found
    from scipy.ndimage import binary_dilation

    surface = room.occupied & binary_dilation(room.free)  # wall cells next to the floor
    assert (g.occupied & surface).sum() / surface.sum() > 0.8
    # a wrong sensor offset gives a worse map: the map depends on it
    g_bad = mapping.build_map(free, z, angles, max_range=8.0, resolution=0.1, extent=(0.0, 6.0, 0.0, 4.0))
    wrong_bad = (g_bad.occupied != room.occupied) & ~g_bad.unknown
    assert wrong_bad.sum() > 2 * wrong.sum()


def test_map_from_log_and_validation():
    log = LaserLog(times=[0.0, 1.0], odometry=np.zeros((2, 3)), ranges=np.ones((2, 3)), angles=[-0.5, 0, 0.5],
                   max_range=5.0)
    with pytest.raises(ValueError, match="no reference poses"):
        mapping.map_from_log(log)
    g = mapping.map_from_log(log, poses=[[0, 0, 0], [0.5, 0, 0]], resolution=0.1)
    assert g.occupied.sum() >= 3
    with pytest.raises(ValueError, match=r"poses must have shape \(2, 3\)"):
        mapping.map_from_log(log, poses=[[0, 0, 0]])
    with pytest.raises(ValueError, match="every"):
        mapping.map_from_log(log, poses=np.zeros((2, 3)), every=0)
    with pytest.raises(ValueError, match="ranges must have shape"):
        mapping.build_map(np.zeros((2, 3)), np.ones((3, 3)), [0, 1, 2], 5.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(shape=(0, 5)), "at least one row"),
        (dict(resolution=0.0), "resolution"),
        (dict(p_occ=0.4), "p_free < p_prior < p_occ"),
        (dict(p_free=1.0), "strictly between"),
        (dict(p_max=0.4), "p_min < p_prior < p_max"),
        (dict(usable_range=-1.0), "usable_range"),
        (dict(step=0.5), "step must be in"),
        (dict(origin=(0.0,)), "origin"),
        (dict(shape=(100_000, 100_000)), "50 million"),
    ],
)
def test_mapper_rejects_bad_parameters(kwargs, match):
    args = dict(shape=(10, 10), resolution=0.1)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        OccupancyMapper(**args)


def test_update_rejects_bad_scans():
    m = OccupancyMapper((10, 10), 0.1)
    with pytest.raises(ValueError, match="one value per beam"):
        m.update([0, 0, 0], [1.0, 2.0], [0.0], 5.0)
    with pytest.raises(ValueError, match="finite and >= 0"):
        m.update([0, 0, 0], [np.nan], [0.0], 5.0)
    with pytest.raises(ValueError, match="max_range"):
        m.update([0, 0, 0], [1.0], [0.0], 0.0)
    with pytest.raises(ValueError, match="laser_pose"):
        m.update([0, 0], [1.0], [0.0], 5.0)
    with pytest.raises(ValueError, match="unknown must be"):
        m.grid(unknown="zero")
    with pytest.raises(ValueError, match="extent"):
        OccupancyMapper.for_extent((1, 0, 0, 1), 0.1)
