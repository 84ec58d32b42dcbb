"""localize.pipeline: the log-level pipeline as a library, driven by a RunSettings."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from localize import cli, io, maps, pipeline, sim
from localize.grid import OccupancyGrid
from localize.kld import KLDSampling
from localize.mcl import Augmented
from localize.settings import RunSettings


@pytest.fixture(scope="module")
def office_run():
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(2), n_steps=16, dt=0.5, speed=0.4, max_range=10.0,
                        angles=np.linspace(-np.pi / 2, np.pi / 2, 61))
    log = io.LaserLog(times=run.times, odometry=run.odometry, ranges=run.ranges, angles=run.angles,
                      max_range=run.max_range, poses=run.poses)
    return grid, log


def _same(a, b) -> bool:
    return np.array_equal(a.estimates, b.estimates) and np.array_equal(a.state, b.state)


def test_settings_and_the_old_keywords_run_the_same_filter_bit_for_bit(office_run):
    grid, log = office_run
    s = RunSettings(particles=1500, track=True, kld=0.0, min_motion=(0.0, 0.0), sigma_hit=0.15, beams=31,
                    augmented=(0.01, 0.2), augmented_temperature=1.0, recovery_injection=0.05, skip_short_beams=0.5)
    a = pipeline.localize_log(grid, log, s, rng=np.random.default_rng(3))
    b = pipeline.localize_log(grid, log, rng=np.random.default_rng(3), n_particles=1500, init="reference", kld=None,
                              min_motion=(0.0, 0.0), sensor_params={"sigma_hit": 0.15}, beams=31,
                              augmented=Augmented(0.01, 0.2), recovery_injection=0.05, short_beams=0.5)
    assert _same(a, b)
    # ... and a setting that matters changes the run (the comparison can fail)
    c = pipeline.localize_log(grid, log, dataclasses.replace(s, sigma_hit=0.4), rng=np.random.default_rng(3))
    assert not np.array_equal(a.estimates, c.estimates)


def test_the_library_defaults_are_the_command_lines(office_run):
    grid, log = office_run
    kw = cli.run_kwargs(cli.build_parser().parse_args(["run", "--log", "-", "--map", "-", "--particles", "2000"]))
    a = pipeline.localize_log(grid, log, rng=np.random.default_rng(0), **kw)
    b = pipeline.localize_log(grid, log, rng=np.random.default_rng(0), particles=2000)
    assert _same(a, b)


def test_kld_and_augmented_objects_become_settings_and_come_back():
    k = KLDSampling(epsilon=0.03, delta=0.2, n_min=300, n_max=4000)
    s = pipeline.settings_with(kld=k, particles=4000)
    assert pipeline.kld_sampling(s, s.particles) == k
    # the command line's: its bounds follow the particles, never below min_particles unless there are fewer
    assert pipeline.kld_sampling(RunSettings(), 1000) == KLDSampling(epsilon=0.05, n_min=1000, n_max=1000,
                                                                     chunked=True)
    assert pipeline.kld_sampling(RunSettings(kld=0), 1000) is None
    aug = Augmented(alpha_slow=0.002, alpha_fast=0.3, temperature=7.0)
    assert pipeline.augmented_filter(pipeline.settings_with(augmented=aug)) == aug
    assert pipeline.augmented_filter(RunSettings(beams=45, augmented=(0.01, 0.2))).temperature == 45.0
    assert pipeline.augmented_filter(RunSettings()) is None
    with pytest.raises(ValueError, match="init must be 'global' or 'reference'"):
        pipeline.settings_with(init="somewhere")
    with pytest.raises(ValueError, match="kld must be a localize.kld.KLDSampling, 'default' or None"):
        pipeline.settings_with(kld="lots")


def test_settings_passed_are_not_changed(office_run):
    grid, log = office_run
    s = RunSettings(particles="auto", kld=0.0, min_motion=(0.0, 0.0))
    res = pipeline.localize_log(grid, log.select(slice(0, 3)), s, rng=np.random.default_rng(0))
    assert s.particles == "auto" and len(res.times) == 3


def test_inputs_are_checked_before_anything_is_read(tmp_path):
    with pytest.raises(ValueError, match="give --map FILE, or --build-map"):
        pipeline.Inputs(log=tmp_path / "a.log")
    walls = io.write_cmu_map(tmp_path / "walls.dat", OccupancyGrid(np.ones((20, 30)), 0.1))
    with pytest.raises(ValueError, match="the map has no free cell to localize in"):
        pipeline.check_free_space(io.read_map(walls), str(walls))


def test_read_inputs_selects_scans_and_builds_the_map(tmp_path):
    grid = maps.office(0.1)
    run = sim.range_run(grid, np.random.default_rng(8), n_steps=12, dt=0.5, angles=io.carmen_angles(181),
                        max_range=12.0, sensor="ideal")
    log = io.LaserLog(times=run.times, odometry=run.poses, ranges=run.ranges, angles=run.angles,
                      max_range=run.max_range, poses=run.poses)
    path = io.write_carmen_log(tmp_path / "sim.log", log)
    warnings: list[str] = []
    got, built, desc = pipeline.read_inputs(pipeline.Inputs(log=path, build_map=True, resolution=0.1,
                                                            scans=slice(2, 10)), min_range=0.05, warn=warnings.append)
    assert len(got) == 8 and np.allclose(got.poses, run.poses[2:10], atol=1e-3)
    assert desc == f"built from {path} (resolution 0.1 m)" and built.resolution == 0.1 and built.free.any()
    assert warnings == []


# ============================================================================ the maximum range a log states
def _ranges_log(ranges, max_range: float) -> io.LaserLog:
    ranges = np.asarray(ranges, dtype=float)
    k, b = ranges.shape
    return io.LaserLog(times=np.arange(k, dtype=float), odometry=np.zeros((k, 3)), ranges=ranges,
                       angles=np.linspace(-1.5, 1.5, b), max_range=max_range)


def test_readings_above_an_understated_maximum_are_used_and_the_stated_value_stays_no_return():
    rng = np.random.default_rng(4)
    r = rng.uniform(0.3, 9.0, (40, 60))
    r[:, ::7] = 4.0                                      # the stated maximum: what the laser said for no return
    fixed, msg = pipeline.check_log_max_range(_ranges_log(r, 4.0))
    assert fixed.max_range == pytest.approx(r.max())
    assert np.array_equal(fixed.no_return, (r == 4.0) | (r == r.max()))
    keep = r != 4.0
    assert np.array_equal(fixed.ranges[keep], r[keep])   # every measurement as it was read
    assert fixed.meta["stated_max_range"] == 4.0 and "largest reading" in fixed.meta["max_range_source"]
    above = float(np.mean(r > 4.0))
    assert f"{above:.0%} of its readings lie above it" in msg and "--max-range 4 keeps" in msg


@pytest.mark.parametrize("codes", [[81.91], [8.183, 8.19, 8.191, 65.533, 65.534]])
def test_no_return_codes_above_the_stated_maximum_are_not_measurements(codes):
    """A SICK log states 81.83 m and writes 81.91 for no return; some lasers have a handful of error codes."""
    rng = np.random.default_rng(5)
    stated = min(codes) - 0.01
    r = rng.uniform(0.3, stated - 0.1, (50, 90))
    r[rng.random(r.shape) < 0.3] = rng.choice(codes, size=int(np.sum(rng.random(r.shape) < 0.3)))[0]
    r[:, :len(codes)] = codes                            # every code, on every scan
    log = _ranges_log(r, stated)
    fixed, msg = pipeline.check_log_max_range(log)
    assert fixed is log and msg is None


def test_a_few_stray_readings_above_the_maximum_do_not_change_the_log():
    rng = np.random.default_rng(6)
    r = rng.uniform(0.3, 29.0, (100, 100))
    stray = rng.choice(r.size, size=int(0.005 * r.size), replace=False)      # 0.5%: 50 distinct values
    r.flat[stray] = rng.uniform(30.5, 60.0, stray.size)
    log = _ranges_log(r.copy(), 30.0)
    assert pipeline.check_log_max_range(log) == (log, None)
    r.flat[rng.choice(r.size, size=int(0.02 * r.size), replace=False)] = rng.uniform(30.5, 60.0, 200)   # 2%: used
    assert pipeline.check_log_max_range(_ranges_log(r, 30.0))[0].max_range > 30.0


def test_a_run_uses_the_readings_unless_max_range_keeps_the_stated_one(office_run):
    grid, log = office_run                                   # a 10 m laser
    short = dataclasses.replace(log, max_range=3.0)          # whose log says 3 m
    with pytest.warns(UserWarning, match="states a maximum range of 3 m") as said:
        a = pipeline.localize_log(grid, short, RunSettings(particles=300, track=True), rng=np.random.default_rng(0))
    assert len(said) == 1 and said[0].filename == __file__            # said once, where the run was asked for
    b = pipeline.localize_log(grid, dataclasses.replace(log, max_range=float(log.ranges.max())),
                              RunSettings(particles=300, track=True), rng=np.random.default_rng(0))
    assert _same(a, b)                                        # the run with the range the readings show
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        c = pipeline.localize_log(grid, short, RunSettings(particles=300, track=True, max_range=3.0),
                                  rng=np.random.default_rng(0))
    assert not [w for w in caught if "maximum range" in str(w.message)]   # the user kept the stated range
    assert np.median(c.trace.n_valid) < np.median(a.trace.n_valid)


def test_reading_a_log_file_checks_its_maximum_range_before_min_range(tmp_path):
    rng = np.random.default_rng(7)
    r = rng.uniform(0.05, 9.0, (30, 181))
    log = io.LaserLog(times=np.arange(30.0), odometry=np.zeros((30, 3)), ranges=r, angles=io.carmen_angles(181),
                      max_range=9.5)
    path = io.write_carmen_log(tmp_path / "short.log", log)
    text = path.read_text()
    assert "PARAM robot_front_laser_max 9.5 " in text
    path.write_text(text.replace("PARAM robot_front_laser_max 9.5 ", "PARAM robot_front_laser_max 3 "))  # says 3 m
    said = []
    got = pipeline.read_log_file(path, min_range=0.2, warn=said.append)
    assert len(said) == 1 and said[0].startswith(f"{path}: the log states a maximum range of 3 m")
    assert got.max_range > 8.5
    short = np.asarray(io.read_log(path).ranges) < 0.2
    assert short.any() and np.all(got.ranges[short] == got.max_range)   # below min_range: the real no return


def test_smoothing_checks_the_maximum_range_once_for_both_passes(office_run):
    from localize.smooth import smooth_log

    grid, log = office_run
    short = dataclasses.replace(log, max_range=3.0)
    with pytest.warns(UserWarning, match="states a maximum range of 3 m") as said:
        smooth_log(grid, short, np.random.default_rng(0), settings=RunSettings(particles=300, track=True))
    assert len(said) == 1 and said[0].filename == __file__
