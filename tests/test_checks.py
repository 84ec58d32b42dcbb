"""Tests of localize._checks: the (N, 3) particle convention where a shape is ambiguous (issue 16)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from localize._checks import PoseShapeWarning, check_poses
from localize.mcl import MCL, estimate_pose

XS, YS, THS = [1.0, 5.0, 9.0], [2.0, 6.0, 8.0], [0.1, -0.2, 0.3]
TRANSPOSED = np.array([XS, YS, THS])  # rows x, y, theta: the wrong way round
RIGHT = TRANSPOSED.T                  # one particle (x, y, theta) per row


class Flat:
    def log_likelihood(self, poses, *z):
        return np.zeros(len(poses))


def still(poses, u, rng):
    return poses


def make_mcl(p):
    return MCL(p, still, Flat(), rng=np.random.default_rng(0))


@pytest.mark.parametrize("take", [make_mcl, estimate_pose, check_poses], ids=["MCL", "estimate_pose", "check_poses"])
def test_a_transposed_3_by_3_particle_array_warns(take):
    with pytest.warns(PoseShapeWarning, match=r"shape \(3, 3\).*transpose"):
        take(TRANSPOSED)


@pytest.mark.parametrize("take", [make_mcl, estimate_pose, check_poses], ids=["MCL", "estimate_pose", "check_poses"])
def test_a_3_by_3_particle_array_the_right_way_round_is_silent(take):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        take(RIGHT)


@pytest.mark.parametrize("take", [make_mcl, estimate_pose], ids=["MCL", "estimate_pose"])
def test_other_transposed_arrays_are_refused_with_a_hint(take):
    with pytest.raises(ValueError, match=r"\(N, 3\) array, one particle .* per row; got shape \(3, 5\).*\.T"):
        take(np.zeros((3, 5)))
    with pytest.raises(ValueError, match=r"got shape \(3,\)"):
        take(np.zeros(3))


def test_mcl_reads_a_3_by_3_array_as_three_particles():
    f = make_mcl(RIGHT)
    assert f.n == 3 and np.allclose(f.particles[:, 0], XS)


def test_check_poses_rejects_non_finite_values():
    p = RIGHT.copy()
    p[1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        check_poses(p)


# --- one wording across the package: the same bad argument gets the same message wherever it is passed
def test_rng_is_checked_with_one_message_everywhere():
    from localize import maps, sensors
    from localize.grid import OccupancyGrid
    from localize.multiscale import simulate_readings

    g = OccupancyGrid.from_ascii("#####\n#...#\n#####", resolution=1.0)
    calls = [lambda: g.sample_free(3, 0), lambda: maps.random_rooms((10, 10), 0.1, 0),
             lambda: maps.city_world((2, 2), 3, 0),
             lambda: simulate_readings(np.zeros((2, 2)), [[0]], 2, (0, 0), [], 0),
             lambda: sensors.BeamModel(None, 5.0).sample_expected([1.0], 0),
             lambda: sensors.LandmarkModel([[1.0, 1.0]], 0.1, 0.1).sample([0, 0, 0], 0)]
    for call in calls:
        with pytest.raises(TypeError, match=r"^rng must be a numpy.random.Generator, e.g. np.random.default_rng\(seed\); "
                                            r"got int$"):
            call()


def test_positive_numbers_are_checked_with_one_message_everywhere():
    from localize.ekf import EKFLocalizer
    from localize.grid import OccupancyGrid
    from localize.sensors import BeamModel, LandmarkModel

    for call, name in [(lambda: BeamModel(None, 5.0, sigma_hit=0.0), "sigma_hit"),
                       (lambda: LandmarkModel([[0, 0]], -1.0, 0.1), "sigma_range"),
                       (lambda: EKFLocalizer([[0, 0]], 0.1, 0.0, [0] * 6), "sigma_bearing"),
                       (lambda: EKFLocalizer([[0, 0]], 0.1, 0.1, [0] * 6, dt=0), "dt"),
                       (lambda: OccupancyGrid(np.zeros((2, 2)), -0.5), "resolution")]:
        with pytest.raises(ValueError, match=rf"^{name} must be a finite number (of [a-z ]+ )?> 0; got "):
            call()


def test_check_alphas():
    from localize._checks import check_alphas

    assert check_alphas((0, 0.1), 2).dtype == float
    with pytest.raises(ValueError, match=r"alphas must hold 6 numbers \(alpha1..alpha6\)"):
        check_alphas([0.1] * 4, 6)
    with pytest.raises(ValueError, match="must be >= 0"):
        check_alphas([0.1, -0.1], 2)
    with pytest.raises(ValueError, match="must be finite"):
        check_alphas([0.1, np.nan], 2)
