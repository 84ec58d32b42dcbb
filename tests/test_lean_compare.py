"""The lean path of compare.AnonymousLandmarks.log_likelihood gives the general path's numbers bit for bit."""

import numpy as np
import pytest

from localize import compare as C
from localize.sensors import LandmarkModel


def general(sensor, poses, z):
    """The general (N, K, L) path of AnonymousLandmarks.log_likelihood, forced (the lean path switched off)."""
    old = C._LEAN_MAX
    C._LEAN_MAX = 0
    try:
        return sensor.log_likelihood(poses, z)
    finally:
        C._LEAN_MAX = old


def random_case(rng, n_lm, n_z, n=400, spread=8.0):
    lms = rng.uniform(-spread, spread, (n_lm, 2))
    sensor = C.AnonymousLandmarks(LandmarkModel(lms, rng.uniform(0.05, 0.5), rng.uniform(0.01, 0.3)))
    poses = np.column_stack([rng.uniform(-spread, spread, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    z = np.column_stack([rng.uniform(0.1, 12.0, n_z), rng.uniform(-np.pi, np.pi, n_z)])
    return sensor, poses, z


@pytest.mark.parametrize("n_lm", [1, 2, 5, 6, 7])
@pytest.mark.parametrize("n_z", [1, 3, 4, 7])
def test_lean_equals_general_bit_for_bit(n_lm, n_z):
    rng = np.random.default_rng(100 * n_lm + n_z)
    for _ in range(5):
        sensor, poses, z = random_case(rng, n_lm, n_z)
        lean = sensor.log_likelihood(poses, z)
        assert np.array_equal(lean, general(sensor, poses, z))


def test_lean_is_taken_and_matches_on_the_chapters_scenarios():
    # the chapter's anonymous scenarios: the filter's own sightings, particles spread over the area
    for name in ("global", "kidnapping", "ambiguity"):
        sc = C.scenario(name)
        data = C.simulate(sc, np.random.default_rng(3))
        sensor = C.AnonymousLandmarks(LandmarkModel(sc.landmarks, 2 * sc.sigma_range, 2 * sc.sigma_bearing))
        rng = np.random.default_rng(4)
        x0, x1, y0, y1 = sc.area
        poses = np.column_stack([rng.uniform(x0, x1, 1000), rng.uniform(y0, y1, 1000), rng.uniform(-np.pi, np.pi, 1000)])
        seen = [z for z in data.z if 0 < len(z) < C._LEAN_MAX]
        assert len(seen) >= 10
        for z in seen:
            assert np.array_equal(sensor.log_likelihood(poses, z), general(sensor, poses, z))


def test_bearings_outside_pi_take_numpy_mod_and_still_agree():
    # unwrapped bearings (z - e + pi outside [-2 pi, 4 pi)): the lean path falls back on np.mod
    rng = np.random.default_rng(7)
    sensor, poses, z = random_case(rng, 4, 3)
    z[:, 1] += np.array([6 * np.pi, -5 * np.pi, 0.0])
    assert np.array_equal(sensor.log_likelihood(poses, z), general(sensor, poses, z))


def test_wrap_boundaries_agree_with_numpy_mod():
    # bearings whose difference lands exactly on, or a rounding away from, the wrap's edges
    lms = np.array([[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0]])
    sensor = C.AnonymousLandmarks(LandmarkModel(lms, 0.2, 0.05))
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2], [0.0, 0.0, -np.pi], [0.0, 0.0, np.nextafter(np.pi, 0)]])
    tiny = np.nextafter(0.0, 1.0)
    for zb in (-np.pi, np.pi, 0.0, -0.0, tiny, -tiny, np.nextafter(np.pi, 0), np.nextafter(-np.pi, 0)):
        z = np.array([[5.0, zb], [5.0, -zb]])
        assert np.array_equal(sensor.log_likelihood(poses, z), general(sensor, poses, z)), zb


def test_many_sightings_or_landmarks_take_the_general_path():
    rng = np.random.default_rng(8)
    sensor, poses, z = random_case(rng, 9, 9)
    out = sensor.log_likelihood(poses, z)
    assert np.array_equal(out, general(sensor, poses, z))
    # and it is the density the readable loop computes (up to its constant)
    loop = sensor.log_likelihood_loop(poses, z)
    assert np.allclose(out - out[0], loop - loop[0], atol=1e-8)


def test_lean_agrees_with_the_readable_loop():
    rng = np.random.default_rng(9)
    sensor, poses, z = random_case(rng, 6, 4)
    out, loop = sensor.log_likelihood(poses, z), sensor.log_likelihood_loop(poses, z)
    assert np.allclose(out - out[0], loop - loop[0], atol=1e-8)


# ---------------------------------------------------------------- reusing the runs of an experiment


def test_experiment_run_is_run_filters_with_its_snapshots():
    sc = C.scenario("ambiguity", n_steps=12, n_particles=200)
    ex = C.start_monte_carlo({"amb": sc}, range(3), processes=1, snapshots={("amb", 2): (0, 5)})
    got = ex.run("amb", 2)
    ref = C.run_filters(sc, 2, snapshot_steps=(0, 5))
    assert sorted(got.snapshots) == [0, 5]
    for name in C.FILTERS:
        assert np.array_equal(got.estimates[name], ref.estimates[name])
        assert np.array_equal(got.covs[name], ref.covs[name])
    assert np.array_equal(got.snapshots[5]["MCL"], ref.snapshots[5]["MCL"])
    assert all(np.array_equal(a, b) for a, b in zip(got.snapshots[0]["EKF"], ref.snapshots[0]["EKF"]))
    assert ex.run("amb", 0).snapshots == {}


def test_snapshots_leave_the_metrics_unchanged():
    sc = C.scenario("tracking", n_steps=12, n_particles=200)
    plain = C.start_monte_carlo({"t": sc}, range(2), processes=1).result()["t"]
    kept = C.start_monte_carlo({"t": sc}, range(2), processes=1, snapshots={("t", 1): (3,)}).result()["t"]
    for name in C.FILTERS:
        assert np.array_equal(plain.metrics[name].pos_err, kept.metrics[name].pos_err)
        assert np.array_equal(plain.metrics[name].nees, kept.metrics[name].nees)


def test_experiment_run_and_snapshots_reject_unknown_keys():
    sc = C.scenario("tracking", n_steps=10, n_particles=50)
    with pytest.raises(ValueError, match="snapshots keys"):
        C.start_monte_carlo({"t": sc}, range(2), processes=1, snapshots={("x", 0): (1,)})
    with pytest.raises(ValueError, match="snapshots keys"):
        C.start_monte_carlo({"t": sc}, range(2), processes=1, snapshots={("t", 5): (1,)})
    ex = C.start_monte_carlo({"t": sc}, range(2), processes=1)
    with pytest.raises(KeyError, match="no scenario"):
        ex.run("x", 0)
    with pytest.raises(KeyError, match="seed 7"):
        ex.run("t", 7)
