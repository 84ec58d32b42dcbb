"""Tests of localize.multiscale: the coarse-to-fine localizer finds the robot for far fewer cell updates."""

import numpy as np
import pytest

from localize.maps import city_world
from localize.multiscale import MultiScaleLocalizer, SingleScaleLocalizer, simulate_readings

B = 10
MOVES = ([(0, 1)] * 20 + [(1, 0)] * 20 + [(0, -1)] * 20 + [(-1, 0)] * 15) * 2


@pytest.mark.parametrize("seed", [0, 1])
def test_both_find_the_robot_and_multiscale_is_cheaper(seed):
    rng = np.random.default_rng(seed)
    fine, coarse = city_world((30, 30), B, rng, n_districts=8)
    truth, fz, cz = simulate_readings(fine, coarse, B, (100, 120), MOVES, rng)
    ms, ss = MultiScaleLocalizer(fine, coarse, B), SingleScaleLocalizer(fine, coarse, B)
    for m, f, c in zip(MOVES, fz, cz):
        ms.step(m, c, f)
        ss.step(m, c, f)
    final = tuple(truth[-1] + MOVES[-1])
    assert ms.phase == "fine" and ms.switched_at is not None and ms.switched_at < len(MOVES) // 2
    r0, r1, c0, c1 = ms.window
    assert r0 <= final[0] < r1 and c0 <= final[1] < c1
    assert ms.estimate() == final and ss.estimate() == final
    assert ss.cells_updated == len(MOVES) * fine.size
    assert ms.cells_updated * 50 < ss.cells_updated
    assert ms.belief.sum() == pytest.approx(1.0)


def test_coarse_move_splits_block_mass():
    fine = np.zeros((4, 6), int)
    coarse = np.array([[0, 1, 2], [3, 4, 5]])
    ms = MultiScaleLocalizer(fine, coarse, 2, p_coarse=(1.0, 0.0), fill=0.0, threshold=1.0)
    ms.step((0, 1), coarse_z=1, fine_z=0)   # read district 1: all belief there; then half moves right
    np.testing.assert_allclose(ms.coarse_belief, [[0, 0.5, 0.5], [0, 0, 0]])


def test_simulate_readings_respects_accuracy():
    rng = np.random.default_rng(5)
    fine, coarse = city_world((10, 10), 5, rng)
    moves = [(0, 1), (0, -1)] * 1000
    truth, fz, cz = simulate_readings(fine, coarse, 5, (7, 7), moves, rng, 0.8, 0.9)
    right_f = np.mean(fz == fine[truth[:, 0], truth[:, 1]])
    right_c = np.mean(cz == coarse[truth[:, 0] // 5, truth[:, 1] // 5])
    se = np.sqrt(0.2 * 0.8 / len(moves))
    assert abs(right_f - 0.8) < 5 * se and abs(right_c - 0.9) < 5 * se


def test_bad_input():
    fine = np.zeros((4, 6), int)
    with pytest.raises(ValueError, match="block x the coarse"):
        MultiScaleLocalizer(fine, np.zeros((2, 2)), 2)
    with pytest.raises(ValueError, match="threshold"):
        MultiScaleLocalizer(fine, np.zeros((2, 3)), 2, threshold=0)
    with pytest.raises(ValueError, match="margin"):
        MultiScaleLocalizer(fine, np.zeros((2, 3)), 2, margin=0)
    with pytest.raises(TypeError, match="Generator"):
        simulate_readings(fine, np.zeros((2, 3)), 2, (0, 0), [], rng=0)
    ms = MultiScaleLocalizer(fine, np.arange(6).reshape(2, 3), 2)
    with pytest.raises(ValueError, match="unit move"):
        ms.step((1, 1), 0, 0)
