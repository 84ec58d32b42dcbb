"""Tests of localize.histogram (the tile world) against the worked example and the loop oracles."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from localize import discrete as db
from localize import histogram as h
from localize.maps import tile_world

P_HIT, P_MISS = 0.85, 0.15


@pytest.fixture
def world():
    return tile_world()


def test_worked_example_first_cycle(world):
    """Uniform 1/35, sense blue (.097 / .017), move left with fill .001 (.106 / .019 / .001)."""
    b = db.uniform(world.shape)
    assert b[0, 0] == pytest.approx(0.0286, abs=5e-5)
    b = h.sense(b, world, "blue", P_HIT, P_MISS)
    blue = world == "blue"
    np.testing.assert_allclose(b[blue], 0.85 / 8.75)
    np.testing.assert_allclose(b[~blue], 0.15 / 8.75)
    assert b[blue][0].round(3) == 0.097 and b[~blue][0].round(3) == 0.017
    b = h.move(b, "left", fill=0.001)
    assert set(np.unique(b.round(3))) == {0.001, 0.019, 0.106}
    np.testing.assert_array_equal(b[:, -1].round(3), 0.001)
    # the high tiles moved one to the left of the blue ones
    np.testing.assert_array_equal(np.argwhere(b.round(3) == 0.106), np.argwhere(blue) - [0, 1])


def test_green_table_matches_seed_to_rounding(world):
    b = h.move(h.sense(db.uniform(world.shape), world, "blue", P_HIT, P_MISS), "left", fill=0.001)
    b = h.sense(b, world, "green", P_HIT, P_MISS)
    seed = np.array([
        [.027, .027, .027, .005, .005, .005, .0001],
        [.005, .005, .027, .154, .005, .005, .0001],
        [.005, .005, .005, .154, .027, .005, .001],
        [.005, .027, .027, .154, .005, .027, .001],
        [.005, .027, .005, .027, .027, .154, .0001]])
    np.testing.assert_allclose(b, seed, atol=1.6e-3)


def test_hand_calculation_0116():
    """(.2*.005 + .5*.005 + .2*.027 + .1*.027) = .0116 for the circled tile when moving left."""
    t = np.array([[0.005, 0.005, 0.005], [0.027, 0.027, 0.005], [0.005, 0.027, 0.027]])
    k = h.noisy_step_kernel("left")
    raw = h.move(t / t.sum(), "left", k, normalize=False) * t.sum()
    assert raw[1, 1] == pytest.approx(0.0116)


@pytest.mark.parametrize("name", ["up", "down", "left", "right"])
def test_noisy_kernel_rotations(name):
    k = h.noisy_step_kernel(name)
    assert k.sum() == pytest.approx(1.0)
    dr, dc = h.STEPS[name]
    # staying put is one step back from the intended tile
    assert k[1 - dr, 1 - dc] == 0.1 and k[1, 1] == 0.5
    # a point mass spreads to 4 tiles: intended .5, two diagonals .2, start .1
    b = np.zeros((5, 5))
    b[2, 2] = 1.0
    out = h.move(b, name, k)
    assert out[2 + dr, 2 + dc] == pytest.approx(0.5) and out[2, 2] == pytest.approx(0.1)
    assert np.sort(out.ravel())[-4:].tolist() == pytest.approx([0.1, 0.2, 0.2, 0.5])


@settings(max_examples=30, deadline=None)
@given(rows=st.integers(1, 6), cols=st.integers(1, 6), seed=st.integers(0, 2**31 - 1),
       step=st.sampled_from(list(h.STEPS.values()) + [(0, 0), (2, -1)]),
       noisy=st.booleans(), mode=st.sampled_from(["constant", "wrap"]), fill=st.sampled_from([0.0, 0.01]))
def test_move_equals_readable(rows, cols, seed, step, noisy, mode, fill):
    rng = np.random.default_rng(seed)
    b = db.normalize(rng.random((rows, cols)) + 0.01)
    k = db.normalize(rng.random((3, 3))) if noisy else None
    fast = h.move(b, step, k, fill, mode=mode, normalize=False)
    slow = h.move_readable(b, step, k, fill, mode=mode, normalize=False)
    np.testing.assert_allclose(fast, slow, atol=1e-13)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), z=st.sampled_from(["red", "green", "blue", "yellow"]))
def test_sense_equals_readable(seed, z):
    rng = np.random.default_rng(seed)
    w = tile_world()
    b = db.normalize(rng.random(w.shape))
    np.testing.assert_allclose(h.sense(b, w, z, 0.7, 0.1), h.sense_readable(b, w, z, 0.7, 0.1), atol=1e-14)


def test_wrap_move_conserves_and_bounded_drops():
    b = np.zeros((3, 3))
    b[:, 0] = 1 / 3
    assert h.move(b, "left", mode="wrap")[:, 2].sum() == pytest.approx(1.0)
    with pytest.raises(db.ZeroLikelihoodError, match="moved off"):
        h.move(b, "left", fill=0.0)


def test_repeated_cycles_localize_the_robot(world):
    """A robot driven round the world with a noisy sensor ends with its true tile the most likely."""
    rng = np.random.default_rng(3)
    pos = np.array([4, 0])
    b = db.uniform(world.shape)
    moves = ["right"] * 6 + ["up"] * 4 + ["left"] * 6 + ["down"] * 4
    for name in moves:
        colour = world[tuple(pos)]
        if rng.random() > 0.85:     # a wrong reading
            colour = rng.choice([c for c in ["red", "green", "blue", "yellow"] if c != colour])
        b = h.sense(b, world, colour, P_HIT, P_MISS)
        pos = pos + h.STEPS[name]
        b = h.move(b, name, fill=0.001)
    assert tuple(np.unravel_index(b.argmax(), b.shape)) == tuple(pos)


# ------------------------------------------------------------------ bad input
def test_bad_inputs(world):
    u = db.uniform(world.shape)
    with pytest.raises(ValueError, match="matches no tile"):
        h.sense(u, world, "purple", P_HIT, P_MISS)
    with pytest.raises(ValueError, match="same shape"):
        h.sense(db.uniform((5, 6)), world, "red", P_HIT, P_MISS)
    with pytest.raises(ValueError, match="sum to 1"):
        h.sense(u * 2, world, "red", P_HIT, P_MISS)
    with pytest.raises(ValueError, match="negative"):
        h.move(np.where(np.arange(35).reshape(5, 7) == 0, 2.0, -1 / 34), "left")
    with pytest.raises(ValueError, match="p_hit"):
        h.sense(u, world, "red", -0.1, P_MISS)
    with pytest.raises(ValueError, match="both zero"):
        h.sense(u, world, "red", 0.0, 0.0)
    with pytest.raises(ValueError, match="sum to 1"):
        h.move(u, "left", kernel=np.full((3, 3), 0.2))
    with pytest.raises(ValueError, match="fill"):
        h.move(u, "left", fill=-1)
    with pytest.raises(ValueError, match="step must be one of"):
        h.move(u, "north")
    with pytest.raises(TypeError, match="whole numbers"):
        h.move(u, (0.5, 0))
    with pytest.raises(ValueError, match="unit moves"):
        h.noisy_step_kernel((1, 1))
    with pytest.raises(ValueError, match="must be 1"):
        h.noisy_step_kernel("up", 0.5, 0.3, 0.1)
    with pytest.raises(ValueError, match="2-D"):
        h.sense(db.uniform(3), ["a", "b", "c"], "a", P_HIT, P_MISS)


def test_all_zero_likelihood_reported(world):
    b = np.zeros(world.shape)
    b[world == "red"] = 1.0
    b /= b.sum()
    with pytest.raises(db.ZeroLikelihoodError):
        h.sense(b, world, "blue", 1.0, 0.0)
    with pytest.raises(db.ZeroLikelihoodError):
        h.sense_readable(b, world, "blue", 1.0, 0.0)


def test_sense_signature_reads_well_in_help():
    """help(histogram.sense) shows the reading as required, not as an object's memory address."""
    import inspect
    import pydoc

    sig = str(inspect.signature(h.sense))
    assert "object at" not in sig and "measurement=<required>" in sig and "z=<required>" in sig, sig
    assert "object at 0x" not in pydoc.render_doc(h.sense, renderer=pydoc.plaintext)
    world = np.array([["green", "blue"]])
    with pytest.raises(TypeError, match="needs the reading"):
        h.sense(np.full((1, 2), 0.5), world, p_hit=0.8, p_miss=0.2)
    with pytest.raises(TypeError, match="twice"):
        h.sense(np.full((1, 2), 0.5), world, "blue", 0.8, 0.2, z="blue")
