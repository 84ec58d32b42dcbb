"""Tests of localize.gridloc: (x, y, theta) grid localization."""

import numpy as np
import pytest

from localize import OccupancyGrid
from localize.discrete import ZeroLikelihoodError
from localize.gridloc import (
    GridLocalizer,
    coarsen,
    expected_range_table,
    gaussian_beam_pdf,
    heading_bins,
    motion_blur,
    predict_readable,
    shift_kernel,
    update_readable,
)

RES = 0.25


def box_room(h=12, w=16, res=RES, boxes=((3, 4, 5, 7),)):
    """A walled room with rectangular obstacles given as (row0, col0, row1, col1) cell ranges."""
    d = np.zeros((h, w))
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 1.0
    for r0, c0, r1, c1 in boxes:
        d[r0:r1, c0:c1] = 1.0
    return OccupancyGrid(d, res)


def analytic_empty_room_table(h, w, res, theta, max_range):
    """Range from each cell centre to the inner face of the walls of an empty walled room, along each theta."""
    xs = (np.arange(w) + 0.5) * res
    ys = (np.arange(h) + 0.5) * res
    X, Y = np.meshgrid(xs, ys)
    lo_x, hi_x, lo_y, hi_y = res, (w - 1) * res, res, (h - 1) * res
    out = np.empty((len(theta), h, w))
    for k, t in enumerate(theta):
        c, s = np.cos(t), np.sin(t)
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(c > 1e-12, (hi_x - X) / c, np.where(c < -1e-12, (lo_x - X) / c, np.inf))
            ty = np.where(s > 1e-12, (hi_y - Y) / s, np.where(s < -1e-12, (lo_y - Y) / s, np.inf))
        out[k] = np.minimum(np.minimum(tx, ty), max_range)
    return out.astype(np.float32)


def test_heading_bins_and_errors():
    assert np.allclose(np.degrees(heading_bins(8)), [-180, -135, -90, -45, 0, 45, 90, 135])
    with pytest.raises(ValueError, match="even integer"):
        heading_bins(7)


@pytest.mark.parametrize("shift, sigma", [(0.0, 0.5), (2.3, 0.6), (-3.7, 1.2), (0.5, 0.8)])
def test_shift_kernel_moves_the_mean(shift, sigma):
    n, w = shift_kernel(shift, sigma)
    r = len(w) // 2
    assert len(w) % 2 == 1 and w.sum() == pytest.approx(1.0)
    mean = n + (np.arange(-r, r + 1) * w).sum()
    assert mean == pytest.approx(shift, abs=0.02)


def test_injected_table_matches_raycast_exact():
    g = box_room(boxes=())
    theta = heading_bins(8)
    analytic = analytic_empty_room_table(*g.shape, RES, theta, 5.0)
    exact = expected_range_table(g, 8, 5.0, method="exact")
    free = g.free
    np.testing.assert_allclose(exact[:, free], analytic[:, free], atol=1e-4)


def test_lut_table_close_to_exact():
    g = box_room()
    exact = expected_range_table(g, 16, 5.0, method="exact")
    lut = expected_range_table(g, 16, 5.0, method="lut")
    err = np.abs(exact - lut)[:, g.free]
    assert np.mean(err <= 2 * RES + 1e-6) > 0.95


@pytest.fixture
def small_loc():
    g = box_room(8, 9, boxes=((3, 3, 5, 4),))
    theta = heading_bins(8)
    table = expected_range_table(g, 8, 3.0, method="exact")
    rng = np.random.default_rng(4)
    loc = GridLocalizer(g, 8, angles=[0.0, np.pi / 2, np.pi, 1.0], max_range=3.0, expected=table,
                        range_step=1e-4)
    b = rng.random(loc.belief.shape) * g.free
    loc.belief = b / b.sum()
    assert len(theta) == loc.K
    return loc


@pytest.mark.parametrize("u", [
    [[0, 0, 0], [0.4, 0.1, 0.3]],
    [[1, 1, 1.0], [0.8, 1.3, 2.5]],
    [[0, 0, 0], [0, 0, -0.8]],
    [[0, 0, 0], [-0.6, 0.0, 0.0]],
])
def test_predict_equals_readable(small_loc, u):
    expected = predict_readable(small_loc, u)
    small_loc.predict(u)
    np.testing.assert_allclose(small_loc.belief, expected, atol=1e-13)


def test_update_equals_readable(small_loc):
    z = [0.7, 1.2, 3.0, 0.9]
    expected = update_readable(small_loc, z)
    small_loc.update(z)
    np.testing.assert_allclose(small_loc.belief, expected, rtol=1e-3, atol=1e-12)


def _mean_xy(loc):
    m = loc.marginal_xy()
    h, w = m.shape
    ys, xs = (np.arange(h) + 0.5) * loc.grid.resolution, (np.arange(w) + 0.5) * loc.grid.resolution
    return (m.sum(0) * xs).sum(), (m.sum(1) * ys).sum()


@pytest.mark.parametrize("heading, dx, dy", [(0.0, 1.0, 0.0), (np.pi / 2, 0.0, 1.0), (-3 * np.pi / 4, -0.707, -0.707)])
def test_motion_turns_with_each_heading(heading, dx, dy):
    """A 1 m forward move shifts the belief along the robot's own heading (rotation-aware)."""
    g = OccupancyGrid(np.zeros((60, 60)), 0.1)
    loc = GridLocalizer(g, 8, [0.0], 5.0, expected=np.full((8, 60, 60), 5.0), alphas=(0, 0, 0, 0))
    loc.reset(pose=[3.0, 3.0, heading], sigma_xy=0.2, sigma_theta=0.05)
    x0, y0 = _mean_xy(loc)
    th0 = loc.theta[loc.marginal_theta().argmax()]
    loc.predict([[0, 0, 0], [1.0, 0, 0]])   # odometry: 1 m forward in the odometry frame
    x1, y1 = _mean_xy(loc)
    assert (x1 - x0, y1 - y0) == pytest.approx((dx, dy), abs=0.03)
    assert loc.theta[loc.marginal_theta().argmax()] == pytest.approx(th0)


def test_rotation_moves_heading_bins():
    g = OccupancyGrid(np.zeros((20, 20)), 0.1)
    loc = GridLocalizer(g, 36, [0.0], 5.0, expected=np.full((36, 20, 20), 5.0), alphas=(0, 0, 0, 0))
    loc.reset(pose=[1.0, 1.0, 0.0], sigma_theta=0.01)
    loc.predict([[0, 0, 0], [0, 0, np.radians(50)]])
    assert np.degrees(loc.theta[loc.marginal_theta().argmax()]) == pytest.approx(50, abs=10)
    # the blur widths follow PR's odometry variances
    sxy, sth = motion_blur(0.0, 1.0, 0.0, [0, 0, 0.02, 0], 0.1, np.pi / 18, 0.0, 0.5)
    assert sxy == pytest.approx(np.sqrt(0.5 * 0.02) / 0.1)
    assert sth == pytest.approx(0.5)
    sxy, sth = motion_blur(0.3, 1.0, -0.1, [0.1, 0.02, 0, 0], 0.1, np.pi / 18, 0.0, 0.0)
    var_rot1, var_rot2 = 0.1 * 0.09 + 0.02, 0.1 * 0.01 + 0.02
    assert sxy == pytest.approx(np.sqrt(0.5 * var_rot1) / 0.1)
    assert sth == pytest.approx(np.sqrt(var_rot1 + var_rot2) / (np.pi / 18))
    with pytest.raises(ValueError, match="no noise"):
        motion_blur(0.0, 1.0, 0.0, [0, 0, 0.02, 0], 0.1, np.pi / 18, 0.0, 0.0)


def test_global_localization_in_a_room():
    """From a uniform prior, a few scans and moves find the true pose to within a cell and a bin."""
    from localize import raycast

    g = box_room(16, 24, boxes=((3, 4, 6, 8), (10, 15, 12, 20), (4, 17, 5, 18)))
    angles = np.linspace(-np.pi, np.pi, 16, endpoint=False)
    loc = GridLocalizer(g, 16, angles, 6.0, expected=expected_range_table(g, 16, 6.0, method="exact"),
                        sigma_hit=0.15, alphas=(0.01, 0.001, 0.01, 0.001))
    rng = np.random.default_rng(0)
    truth = np.array([2.6, 2.1, 0.0])
    odom = truth.copy()
    for t in range(4):
        if t > 0:
            new = truth + [0.5, 0.0, 0.0]
            loc.predict([odom, new])
            truth = odom = new
        z = raycast.cast(g, truth, angles, 6.0, method="exact")[0] + rng.normal(0, 0.05, len(angles))
        loc.update(np.clip(z, 0, 6.0))
    est = loc.estimate()
    assert np.hypot(*(est[:2] - truth[:2])) <= RES * 1.5
    assert abs(est[2] - truth[2]) <= loc.bin_width / 2 + 1e-9
    assert loc.belief.sum() == pytest.approx(1.0)
    assert np.all(loc.belief[:, ~g.free] == 0)


def test_gaussian_beam_pdf_integrates_to_one():
    pdf = gaussian_beam_pdf(0.2, 5.0)
    z = np.linspace(0, 5.0, 20001)
    assert np.trapezoid(pdf(z, 2.5), z) == pytest.approx(1.0, abs=1e-3)


# ------------------------------------------------------------------ bad input
def test_bad_inputs():
    g = box_room()
    table = np.full((8,) + g.shape, 2.0)
    with pytest.raises(TypeError, match="OccupancyGrid"):
        GridLocalizer(np.zeros((3, 3)), 8, [0.0], 3.0, expected=table)
    with pytest.raises(ValueError, match="even integer"):
        GridLocalizer(g, 7, [0.0], 3.0, expected=table)
    with pytest.raises(ValueError, match="shape"):
        GridLocalizer(g, 8, [0.0], 3.0, expected=table[:, :-1])
    with pytest.raises(ValueError, match="max_range"):
        GridLocalizer(g, 8, [0.0], -1.0, expected=table)
    with pytest.raises(ValueError, match="angles"):
        GridLocalizer(g, 8, [], 3.0, expected=table)
    with pytest.raises(ValueError, match="finite"):
        GridLocalizer(g, 8, [0.0], 3.0, expected=table * np.nan)
    loc = GridLocalizer(g, 8, [0.0, 1.0], 3.0, expected=table)
    with pytest.raises(ValueError, match="one reading per beam"):
        loc.update([1.0])
    with pytest.raises(ValueError, match=">= 0"):
        loc.update([1.0, -1.0])
    with pytest.raises(ValueError, match="prev_odom, odom"):
        loc.predict([0, 0, 0])
    with pytest.raises(ValueError, match="no noise"):
        GridLocalizer(g, 8, [0.0], 3.0, expected=table, alphas=(0, 0, 0, 0), min_sigma_xy=0).predict(
            [[0, 0, 0], [1, 0, 0]])


def test_belief_leaving_the_map_is_reported():
    g = OccupancyGrid(np.zeros((4, 4)), 0.25)
    loc = GridLocalizer(g, 4, [0.0], 1.0, expected=np.ones((4, 4, 4)), alphas=(0, 0, 0, 0))
    loc.reset(pose=[0.5, 0.5, 0.0], sigma_xy=0.1, sigma_theta=0.1)
    with pytest.raises(ZeroLikelihoodError, match="no belief is left"):
        loc.predict([[0, 0, 0], [50.0, 0, 0]])


def test_zero_likelihood_scan_is_reported():
    g = box_room()
    table = np.full((8,) + g.shape, 2.0)
    loc = GridLocalizer(g, 8, [0.0], 3.0, expected=table, beam_pdf=lambda z, e: (np.abs(z - e) < 0.1) * 1.0)
    with pytest.raises(ZeroLikelihoodError):
        loc.update([0.5])


def test_coarsen_keeps_thin_walls_and_unknown():
    d = np.zeros((6, 6))
    d[:, 2] = 1.0              # a wall one cell thick
    d[0, 5] = np.nan           # unknown next to free cells: free wins
    d[4:, 4:] = np.nan         # an all-unknown block stays unknown
    c = coarsen(OccupancyGrid(d, 0.1), 2)
    assert c.resolution == pytest.approx(0.2) and c.shape == (3, 3)
    assert c.occupied[:, 1].all() and not c.occupied[:, 0].any()
    assert c.free[0, 2] and c.unknown[2, 2]
    with pytest.raises(ValueError, match="factor"):
        coarsen(OccupancyGrid(d, 0.1), 0)
    with pytest.raises(ValueError, match="larger than the map"):
        coarsen(OccupancyGrid(d, 0.1), 7)


def test_beams_sharing_a_heading_bin_are_reported():
    """180 one-degree beams on 36 ten-degree bins use 19 directions: the constructor warns and says how many."""
    g = OccupancyGrid(np.zeros((6, 6)), 0.5)
    half_circle = np.radians(np.arange(-90, 90, 1.0))
    with pytest.warns(UserWarning, match=r"180 distinct beam angles snap onto 19 heading bins of 10 degrees"):
        loc = GridLocalizer(g, 36, half_circle, 5.0, expected=np.ones((36, 6, 6)))
    assert sum(loc.beams_per_bin.values()) == 180 and max(loc.beams_per_bin.values()) in (10, 11)   # 11: both ends
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")             # one beam per bin: silent
        one_each = GridLocalizer(g, 36, half_circle[::10], 5.0, expected=np.ones((36, 6, 6)))
    assert set(one_each.beams_per_bin.values()) == {1}
