"""The rival bank (localize.rivals): the estimate against the places it could be mistaken for."""

from __future__ import annotations

import numpy as np
import pytest

from localize import sim
from localize.geometry import compose, inverse
from localize.maps import symmetric_room
from localize.raycast import RayCaster
from localize.rivals import RivalBank, evidence_scale
from localize.sensors import LikelihoodField

ANGLES = np.linspace(-np.pi, np.pi, 60, endpoint=False)
CENTRE_TURN = np.array([12.0, 6.0, np.pi])       # the half turn about the hall's centre (6, 3)


def _z(grid, pose):
    return RayCaster(grid, 8.0).cast(np.asarray(pose, dtype=float)[None], ANGLES)[0], ANGLES


def _lf(grid):
    return LikelihoodField(grid, 8.0, sigma_hit=0.1, temper=0.3)


def test_the_mirror_image_holds_the_share_near_a_half_and_a_tell_takes_it():
    """Symmetric hall, ten scans along a path, 20 seeds of the search: the half turn is held as a rival on every
    seed, and on most of them the share stays below the odds of *localized* (0.95). Not on all: the places'
    particles follow their scans' noise, each its own (the module's limits; on 9 of 20 seeds of stop 58's
    search, 11 of 20 of stop 59's, 13 of 20 of stop 65's tracked places, the share also stays within (0.2, 0.8)).
    With the tell (a box in one corner
    that the path sees), the same scans settle it on every seed: share > 0.95."""
    path = np.array([[1.0 + 0.4 * k, 1.0 + 0.1 * k, 0.0] for k in range(10)])
    for tell in (False, True):
        grid = symmetric_room(tell=tell)
        lf = _lf(grid)
        truth_path = compose(CENTRE_TURN[None], path) if tell else path      # in the tell room: near the box
        zs = [_z(grid, x) for x in truth_path]
        shares, mirror_off = [], []
        for seed in range(20):
            bank = RivalBank(grid, lf, every=5, seed=seed)
            for x, z in zip(truth_path, zs):
                share = bank.observe(x, z)
            shares.append(share)
            if not tell:
                places = bank.places(truth_path[-1])
                want = compose(CENTRE_TURN, truth_path[-1])
                mirror_off.append(np.min(np.hypot(*(places[:, :2] - want[:2]).T)))
        shares = np.array(shares)
        if tell:
            assert np.all(shares > 0.95), shares
        else:
            assert max(mirror_off) < 0.1, mirror_off
            assert np.sum(shares < 0.95) > 10 and np.median(shares) < 0.9, shares


def test_switch_swaps_the_estimate_and_its_rival_and_rebases_the_others():
    grid = symmetric_room(tell=False)
    bank = RivalBank(grid, _lf(grid), switch_odds=19.0)
    x = np.array([2.0, 4.5, 0.3])
    bank.hold([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]], [np.log(30.0), -1.0])
    assert bank.winner() is None              # odds won over fewer scans than a window: not yet
    bank.scans.extend([(x, None)] * bank.window)
    bank.hold(bank.G, bank.L)                 # the same rivals and odds, over the window's scans
    assert bank.winner() == 0
    where_before = bank.places(x)
    g = bank.switch(0)
    assert np.allclose(g, [1.0, 0.0, 0.0])
    x_new = compose(g, x)
    after = bank.places(x_new)
    # the other rival still puts the robot where it did; the old estimate is now a rival, with the odds it lost by
    assert np.allclose(after[0], where_before[1]) and np.allclose(after[1], x)
    assert np.allclose(bank.L, [-1.0 - np.log(30.0), -np.log(30.0)])
    assert bank.winner() is None
    bank.hold(bank.G, [np.log(18.0), 0.0])           # below the odds: no switch
    assert bank.winner() is None


def test_evidence_scale_believes_exact_log_likelihood_ratios_and_discounts_overconfident_ones():
    """Readings x ~ N(0, 1) weighed for N(1, 1) against N(0, 1): the log-likelihood ratios d = x - 1/2 have mean
    -1/2 and variance 1 = 2 |mean|, so their sum is believed in full. A model four times as sure of itself
    (4 d: mean -2, variance 16) is believed a quarter: 2 |mean| / variance = 4 / 16. 2,000 readings: the
    estimate's standard error is about 5% of it (delta method), the tolerance four times that; a formula without
    the 2 (1/8, or 1/2 for the exact ratios) or with the standard deviation for the variance (1/2) fails."""
    rng = np.random.default_rng(0)
    d = rng.normal(0.0, 1.0, 2000) - 0.5
    exact, sure = evidence_scale(np.vstack([d, 4.0 * d]))
    assert exact > 1.0 - 4 * 0.05
    assert abs(sure - 0.25) < 4 * 0.05 * 0.25
    # no record, or a single scan: nothing to judge the spread by
    assert np.array_equal(evidence_scale([[np.nan, np.nan], [np.nan, -40.0]]), [1.0, 1.0])


def test_the_share_counts_a_rivals_odds_as_far_as_its_differences_support_them():
    """Two rivals 6 nats down after four scans: one lost about 1.5 nats at every scan (believed: share 0.995 of
    the two alike), the other lost 14 and won 8, 5 and 1 (about a third believed: the estimate's share is lower).
    A switch keeps every record: the differences against the new estimate are the old ones minus the winner's."""
    grid = symmetric_room(tell=False)
    bank = RivalBank(grid, _lf(grid), switch_odds=19.0)
    x = np.array([2.0, 4.5, 0.3])
    bank.scans.extend([(x, None)] * 4)
    D = np.array([[-1.5, -1.6, -1.4, -1.5], [-14.0, 8.0, 5.0, -5.0]])
    bank.hold([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]], D.sum(axis=1), D)
    scale = evidence_scale(bank.D)
    assert scale[0] == 1.0 and 0.0 < scale[1] < 0.5
    assert np.allclose(bank.believed, bank.L * scale)
    assert bank.share == pytest.approx(1.0 / (1.0 + np.exp(bank.L[0]) + np.exp(bank.L[1] * scale[1])))
    assert bank.share < 1.0 / (1.0 + 2.0 * np.exp(-6.0))
    before = bank.D.copy()
    bank.switch(1)
    assert np.allclose(bank.D, [before[0] - before[1], -before[1]])
    assert np.allclose(bank.L, bank.D.sum(axis=1))
    # odds set without a record (a caller's own): believed as they are
    bank.hold(bank.G, [2.0, -1.0])
    assert np.array_equal(bank.believed, bank.L)
    with pytest.raises(ValueError, match=r"one column per scan kept"):
        bank.hold(bank.G, bank.L, np.zeros((2, 2)))


def test_the_record_of_differences_follows_the_scans_the_bank_keeps():
    """Every scan adds one difference per rival; a rival dropped drops its record; the oldest scan forgotten
    (``history``) forgets its column; the record's row sums are the odds when the bank kept every scan."""
    grid = symmetric_room(tell=False)
    lf = _lf(grid)
    bank = RivalBank(grid, lf, every=5, history=12, seed=0)
    path = np.array([[1.0 + 0.3 * k, 1.0 + 0.1 * k, 0.0] for k in range(16)])
    for k, x in enumerate(path):
        bank.observe(x, _z(grid, x))
        assert bank.D.shape == (len(bank.L), len(bank.scans)), (k, bank.D.shape, len(bank.L), len(bank.scans))
        if k < 12:
            assert np.allclose(np.nansum(bank.D, axis=1), bank.L, atol=1e-6), k


def test_bad_arguments_say_what_is_wrong():
    grid = symmetric_room()
    with pytest.raises(ValueError, match="radius"):
        RivalBank(grid, _lf(grid), radius=0.0)
    with pytest.raises(ValueError, match="switch_odds"):
        RivalBank(grid, _lf(grid), switch_odds=-1.0)
    with pytest.raises((ValueError, TypeError), match="every"):
        RivalBank(grid, _lf(grid), every=0)


def _mirror_start_run(rivals: bool, seed: int = 0):
    """A robot in the hall with the tell (a box in the bottom-right corner), driving towards it; the filter
    starts sure of the mirror image of the start (the half turn about the hall's centre)."""
    from localize.mcl import MCL
    from localize.motion import OdometryMotion
    from localize.reliability import ReliabilityState
    from localize.runloop import Recorder, default_policies, run

    grid = symmetric_room(tell=True)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 61)
    r = sim.range_run(grid, np.random.default_rng(seed), n_steps=40, start=(2.0, 1.3, 0.0),
                      waypoints=[(10.3, 1.3), (10.3, 4.7), (2.0, 4.7)], angles=angles, max_range=8.0, n_clutter=0)
    lf = LikelihoodField(grid, 8.0, sigma_hit=0.1, temper=0.3)
    f = MCL.gaussian(compose(CENTRE_TURN, r.poses[0]), (0.1, 0.1, 0.05), 1000, OdometryMotion(r.alphas, min_std=0.01),
                     lf, rng=np.random.default_rng(100 + seed), grid=grid)
    p = default_policies(f, grid=grid, state="probability")
    p.state = ReliabilityState(grid, lf, rivals=rivals)
    rec = Recorder()
    events = run(f, len(r.poses), r.control, lambda k: (r.ranges[k], angles), policies=p, observers=[rec])
    tr = rec.trace(events)
    return r, tr, np.hypot(*(tr.poses[:, :2] - r.poses[:, :2]).T)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_filter_sure_of_the_mirror_image_moves_to_the_robot_once_the_tell_decides(seed):
    """Without the bank the cloud stays on the mirror image, 'localized' while metres off (the scans fit it
    until the robot sees the box, and then no particle is near the robot). With it, the bank's search finds the
    robot's place, its odds grow once the box is in view, and the cloud moves there: the run ends within
    0.3 m, and no step after the move is 'localized' more than 1 m off."""
    _, tr_off, e_off = _mirror_start_run(False, seed)
    assert e_off[-1] > 5.0 and np.any((tr_off.state == "localized") & (e_off > 5.0))
    r, tr, e = _mirror_start_run(True, seed)
    moves = [k for k, text in tr.events if "rival place" in text]
    assert moves, tr.events
    assert e[-1] < 0.3, (e[-1], tr.events)
    after = np.arange(len(e)) > moves[-1]
    assert not np.any((tr.state == "localized") & (e > 1.0) & after)


def test_a_switch_waits_out_a_probation_and_is_taken_once():
    """``ReliabilityState.take_switch``: a rival that won is taken once; during a restart's probation
    (``allowed=False``) the moment passes and the bank keeps its rivals and odds as they were."""
    from localize.reliability import ReliabilityState

    grid = symmetric_room(tell=False)
    state = ReliabilityState(grid, _lf(grid))
    x = np.array([2.0, 4.5, 0.3])
    state.rivals.hold([[1.0, 0.0, 0.0]], [5.0])
    state.last_pose = x.copy()
    state.pending = 0
    assert state.take_switch(allowed=False) is None
    assert state.pending is None and np.allclose(state.rivals.L, [5.0]) and np.allclose(state.last_pose, x)
    state.pending = 0
    g = state.take_switch()
    assert np.allclose(g, [1.0, 0.0, 0.0]) and np.allclose(state.last_pose, compose(g, x))
    assert np.allclose(state.rivals.L, [-5.0])            # the old place, a rival now, with the odds it lost by
    assert state.take_switch() is None                    # once


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "known limitation (benchmarks/RESULTS.md, bench_global_experiments_stop65): a place's particles start where it "
    "was put, with no spread of their own beyond the estimate's; a rival put 10 cm off the mirror image loses nats "
    "in its first scans, while its particles reach the place, and no later scan gives them back"))
def test_a_rival_a_little_off_the_mirror_image_does_not_make_the_bank_sure_of_a_symmetric_hall():
    """A hall that is the same under a half turn, the robot driving 40 scans; its rival starts on the mirror
    image moved by 10 cm along each axis and 0.05 rad. No scan can tell the two places apart, so the bank must not
    become sure of either: the estimate's share stays within (0.1, 0.9) (p_localized is at most the square root of
    the belief times this share, so a share below 0.9 keeps it below the 0.95 at which the state says localized).
    Measured with rivals moved rigidly (to stop 64): 1.0, the rival 8.8 nats down (the experiment of
    branch exp-bank-marginal, neighbourhood-averaged scores and rivals moved to their best pose: 0.41). With the
    places tracked (stop 65, seeds 1-5): 0.98-1.00; the rival loses 12-16 nats in its first three scans, then
    -0.08 to +0.07 per scan on average."""
    grid = symmetric_room(tell=False)
    path = np.array([[1.0 + 0.2 * k, 1.0 + 0.05 * k, 0.02 * k] for k in range(40)])
    bank = RivalBank(grid, _lf(grid), seed=1)
    x0 = path[0]
    bank.hold(compose(compose(compose(CENTRE_TURN, x0), np.array([0.1, -0.1, 0.05])), inverse(x0))[None], [0.0])
    bank.used = 1                                     # the first search (at the first scan) has been made
    for x in path:
        share = bank.observe(x, _z(grid, x))
    assert 0.1 < share < 0.9, (share, bank.L)


def test_each_place_moves_by_the_odometry_and_scores_the_mean_likelihood_of_its_particles():
    """Noise-free motion, so every place's particles stay one pose: the estimate's place moves by the odometry
    between two scans even when the filter's estimate jumps (a correction is the filter's, not the robot's); a
    rival's log-odds grow by the scan's log-likelihood at its place minus at the estimate's place, each the mean
    likelihood of identical particles, which is the likelihood at that one pose."""
    from localize.motion import OdometryMotion

    grid = symmetric_room(tell=False)
    lf = _lf(grid)
    bank = RivalBank(grid, lf, motion=OdometryMotion((0.0, 0.0, 0.0, 0.0)), particles=8, every=1000, seed=0)
    x0, x1 = np.array([2.0, 4.5, 0.3]), np.array([2.5, 4.6, 0.3])
    odom0 = np.array([10.0, -3.0, 1.0])
    odom1 = compose(odom0, np.array([0.4, 0.0, 0.05]))          # the robot drove 0.4 m and turned 0.05 rad
    bank.observe(x0, _z(grid, x0), odom0)                        # the first scan (no motion yet; the search runs)
    rival = compose(CENTRE_TURN, x0)
    bank.hold(compose(rival, inverse(x0))[None], [0.0], np.zeros((1, len(bank.scans))))
    bank.observe(x1, _z(grid, x1), odom1)                        # the estimate jumped beyond the odometry
    moved = compose(x0, np.array([0.4, 0.0, 0.05]))
    assert np.allclose(compose(x1[None], bank.offsets[0]), moved[None], atol=1e-9)
    want = compose(rival, np.array([0.4, 0.0, 0.05]))
    assert np.allclose(bank.places(x1)[0], want, atol=1e-9)
    ll = lf.log_likelihood(np.vstack([moved, want]), *_z(grid, x1))
    assert bank.L[0] == pytest.approx(ll[1] - ll[0], abs=1e-6)


def test_a_rival_wins_only_on_odds_its_differences_support():
    """Odds of 30 to 1 from differences that swing either way (believed about a tenth) do not move the cloud;
    the same odds from steady differences do."""
    grid = symmetric_room(tell=False)
    bank = RivalBank(grid, _lf(grid), switch_odds=19.0)
    x = np.array([2.0, 4.5, 0.3])
    bank.scans.extend([(x, None)] * 10)
    swing = np.array([9.0, -8.0, 7.0, -6.0, 8.0, -7.0, 6.0, -5.0, 3.4, -3.0])
    bank.hold([[1.0, 0.0, 0.0]], [swing.sum()], swing[None])
    assert bank.L[0] >= np.log(19.0) and bank.believed[0] < np.log(19.0) and bank.winner() is None
    steady = np.full(10, swing.sum() / 10)
    bank.hold([[1.0, 0.0, 0.0]], [steady.sum()], steady[None])
    assert bank.winner() == 0


def test_a_near_miss_the_global_search_ranks_out_is_found_around_the_estimate(monkeypatch):
    """An estimate 1.5 m and 0.6 rad off the robot (a filter carried away by its odometry, as after a turn the
    odometry missed) on three paths in a random building. The global search is made to find nothing (on the
    newest scan alone it ranks the robot's place among its look-alikes, the missing turn of
    ``tests/test_state_scenarios.py``); the poses searched around the estimate find the robot's place, and its
    odds take the share. Without them the bank holds no rival and the share is 1."""
    from localize import rivals
    from localize.maps import random_rooms

    grid = random_rooms((150, 100), 0.1, np.random.default_rng(3))
    lf = _lf(grid)
    monkeypatch.setattr(rivals, "best_places", lambda *a, **k: (np.empty((0, 3)), np.empty(0)))
    rng = np.random.default_rng(0)
    off = np.array([0.9, 1.2, 0.6])
    for trial in range(3):
        while True:
            x0 = grid.sample_free(1, rng)[0]
            step = 0.2 * np.array([np.cos(x0[2]), np.sin(x0[2]), 0.0])
            path = x0[None] + np.arange(10)[:, None] * step[None]
            if grid.is_free(path[:, :2]).all() and grid.is_free((path + off)[:, :2]).all():
                break
        bank = RivalBank(grid, lf, seed=trial)
        for x in path:
            share = bank.observe(x + off, _z(grid, x), x)     # the odometry reads the robot's own path
        d = np.hypot(*(bank.places(path[-1] + off)[:, :2] - path[-1, :2]).T)
        assert d.size and d.min() < 0.7, f"path {trial}: no rival at the robot ({np.round(d, 2)} m)"
        assert share < 0.05, f"path {trial}: the estimate keeps a share of {share:.2f}"

