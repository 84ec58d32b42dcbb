"""Acceptance tests of the run's state (issue 43): what an honest "localized / searching / lost" says.

Each test localizes one simulated fault of :mod:`scenarios` as ``localize run``
does and judges the state against the simulated truth. The tests know nothing
of how the state is computed: they read ``trace.state`` and ``trace.poses``,
and ``trace.p_localized`` only where a trace has one. The rules, after the issue:

* **never "localized" while more than 1 m off** (``FAR``): "localized" claims
  the estimate is within 1 m of the robot. Excused are only the scans of a
  fault that carries the robot away from the estimate (a kidnapping, a missing
  or corrupt odometry record) and ``GRACE`` scans after it: see :data:`GRACE`.
* **"localized" at most scans where the estimate is within 0.3 m**
  (``NEAR``), after the first localized scan: ``MIN_SHARE`` of them (see there).
* **"lost" is never said of an estimate within 0.3 m** where the fault is
  one that a right estimate survives (a moved obstacle, a person in front
  of the laser, an understated maximum range).
* with ``p_localized``: below the state's *lost* threshold wherever the estimate is more
  than 1 m off (outside the excused scans), on average at least 0.8 where it is within
  0.3 m (see :func:`check_probability`), and never rising while the laser is dead.

Each test runs two seeds (two filters on the same simulated log; about a
second of CPU each). Two seeds can pass by luck: ``benchmarks/bench_scenarios.py``
runs every scenario with twelve and counts the runs that break these checks
(``benchmarks/RESULTS.md``, ``bench_scenarios``): a scenario that fails there on
other seeds is not met, even when its test here passes. A test that the state fails is marked
``xfail(strict=True)`` with what it does wrong; remove the mark when the
state passes. ``test_the_checks_catch_a_dishonest_state`` feeds the checks
doctored traces (always localized, lost while right, a probability that
claims too much) and asserts that each check fails on them.
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace

import numpy as np
import pytest
import scenarios as S

from localize.reliability import LOST_BELOW

FAR = 1.0
NEAR = 0.3

#: Scans after the last scan of a fault that moves the robot away from its estimate during which the state
#: may still say "localized" while more than 1 m off. A scan that fits the map nowhere near the estimate is
#: also what a person standing in front of the laser or a glitch of the laser produces, and a state that
#: turned lost on one such scan would be wrong there (see test_walking_person...); a second one is evidence.
#: The command line weights the particles only after 0.2 m or 0.3 rad of odometry (the robot drives
#: 0.2 m per scan), so two scans hold one or two updates. The fault's own scans are excused too: a
#: kidnapping's scan is the first evidence of it, and while odometry records are missing the odometry
#: says the robot stands still, so the driver does not use those scans at all.
GRACE = 2

#: Share of the scans within NEAR of the truth, after the first localized scan, that must say "localized".
#: The issue asks 97% over the benchmarks' thousands of scans. These runs judge 70-145 scans each, and
#: every return to the right place after a fault (a kidnapping, a missing turn) may cost as many scans of
#: re-confirmation as the first localization did: 1-7 scans in these runs lie between the first estimate
#: within 0.3 m and the first "localized" (21-22 when the user keeps an understated 2.5 m range, which
#: leaves about half the beams). One such delay and a few scans of doubt around a fault are 5-10% of a
#: run: 0.9 requires the state to be right at nine of ten right scans.
MIN_SHARE = 0.9

SEEDS = (0, 1)


# ============================================================================ the checks
#: The state under test: issue 43's probability (the default of ``localize run``, ``--state probability``); the
#: threshold state's own tests are in test_cli.py.
STATE = "probability"


def _states(trace) -> np.ndarray:
    s = np.asarray(trace.state).astype(str)
    assert set(np.unique(s)) <= {"searching", "localized", "lost"}, f"unknown states {set(np.unique(s))}"
    return s


def _show(idx, err, state) -> str:
    idx = np.asarray(idx)
    shown = ", ".join(f"{k} ({err[k]:.2f} m, {state[k]})" for k in idx[:12])
    return shown + (f" ... ({idx.size} scans)" if idx.size > 12 else "")


def excused(sc: S.Scenario, grace: int = GRACE) -> np.ndarray:
    """The fault's scans and ``grace`` scans after each stretch of them."""
    m = np.array(sc.fault)
    for k in np.flatnonzero(sc.fault):
        m[k:k + grace + 1] = True
    return m


def check_never_localized_far(state, err, excuse=None) -> None:
    """No scan says "localized" while the estimate is more than FAR from the robot (outside ``excuse``)."""
    bad = (state == "localized") & (err > FAR)
    if excuse is not None:
        bad &= ~excuse
    assert not bad.any(), f"'localized' while more than {FAR} m off at scans " + _show(np.flatnonzero(bad), err, state)


def judged_near(state, err, exclude=None) -> np.ndarray:
    """Scans within NEAR of the truth from the first localized scan on (outside ``exclude``)."""
    k0 = np.flatnonzero(state == "localized")
    assert k0.size, "never localized"
    m = (err <= NEAR) & (np.arange(err.size) >= k0[0])
    if exclude is not None:
        m &= ~exclude
    return m


def check_localized_when_near(state, err, exclude=None, share: float = MIN_SHARE) -> None:
    """At least ``share`` of the scans within NEAR (after the first localized scan) say "localized"."""
    near = judged_near(state, err, exclude)
    assert near.sum() >= 20, f"only {near.sum()} scans within {NEAR} m to judge: the scenario did not localize"
    said = float(np.mean(state[near] == "localized"))
    miss = np.flatnonzero(near & (state != "localized"))
    assert said >= share, (f"only {said:.0%} of the {near.sum()} scans within {NEAR} m say 'localized' (at least "
                           f"{share:.0%} required); not at " + _show(miss, err, state))


def check_not_lost_when_near(state, err) -> None:
    """No scan within NEAR of the truth says "lost" (for faults that a right estimate survives)."""
    bad = (state == "lost") & (err <= NEAR)
    assert not bad.any(), f"'lost' while within {NEAR} m at scans " + _show(np.flatnonzero(bad), err, state)


def check_probability(trace, err, excuse=None, exclude=None) -> None:
    """With ``trace.p_localized``: low where the estimate is more than FAR off, high where it is within NEAR.

    * below :data:`~localize.reliability.LOST_BELOW` (0.7) at every scan more than FAR
      off (outside ``excuse``): at that probability a localized filter would stay
      localized. (The probability is the geometric mean of two estimates; this is the
      bound of 0.5 the test held their product to before, 0.7 ** 2 = 0.49. A calibrated
      probability can say 0.55 of a wrong estimate: of the scans at which it says so,
      about 45% are wrong.)
    * on average at least 0.8 over the scans within NEAR after the first localized
      scan (outside ``exclude``): every one of them is right, so a calibrated
      probability there is near 1; the issue allows a reliability bin to be off by
      0.1, and 0.8 leaves room for the scans of re-confirmation after a fault.
    """
    p = getattr(trace, "p_localized", None)
    if p is None:
        return
    p = np.asarray(p, dtype=float)
    assert p.shape == err.shape and np.all((p >= 0) & (p <= 1)), "p_localized must be a probability per scan"
    far = err > FAR
    if excuse is not None:
        far &= ~excuse
    high = far & (p >= LOST_BELOW)
    assert not np.any(high), (f"p_localized at or above {LOST_BELOW} while more than {FAR} m off at scans "
                              + ", ".join(f"{k} ({err[k]:.2f} m, p {p[k]:.2f})" for k in np.flatnonzero(high)[:12]))
    state = np.asarray(trace.state).astype(str)
    if np.any(state == "localized"):
        near = judged_near(state, err, exclude)
        if near.any():
            assert p[near].mean() >= 0.8, f"p_localized averages {p[near].mean():.2f} over the scans within {NEAR} m"


def check_no_evidence_claimed(trace, dead) -> None:
    """Over the scans of a dead laser the state never turns "localized" and ``p_localized`` never rises."""
    state = _states(trace)
    idx = np.flatnonzero(dead)
    turned = [int(k) for k in idx if k > 0 and state[k] == "localized" and state[k - 1] != "localized"]
    assert not turned, f"turned 'localized' without a valid reading at scans {turned}"
    if idx[0] == 0:
        assert not np.any(state == "localized"), "'localized' although the laser never gave a valid reading"
    p = getattr(trace, "p_localized", None)
    if p is not None:
        p = np.asarray(p, dtype=float)
        rise = np.flatnonzero(np.diff(p[idx]) > 1e-9) + idx[0] + 1
        assert not rise.size, f"p_localized rose without a valid reading at scans {rise[:12].tolist()}"


def honest_run(sc: S.Scenario, seed: int, *, excuse=None, exclude=None, keep_when_near: bool = False, **changes):
    """Localize ``sc`` with ``seed`` (and the settings ``changes``) and apply the checks every scenario shares;
    return (trace, err, state)."""
    tr = S.run(sc, seed, state=STATE, **changes)
    err = S.position_errors(sc, tr)
    state = _states(tr)
    assert np.all(np.isfinite(np.asarray(tr.poses))) and np.all(np.abs(np.asarray(tr.poses)[:, :2]) < 100), \
        "estimates left the map by more than 100 m"
    check_never_localized_far(state, err, excuse)
    check_localized_when_near(state, err, exclude)
    if keep_when_near:
        check_not_lost_when_near(state, err)
    check_probability(tr, err, excuse, exclude)
    return tr, err, state


# ============================================================================ today's four
@pytest.mark.parametrize("value", [0.0, 12.0, 0.03])      # failed readings, no return, all below min_range
def test_dead_laser_from_the_start_is_never_localized(value):
    sc = S.dead_laser(value)
    for seed in SEEDS:
        tr = S.run(sc, seed, state=STATE)
        state = _states(tr)
        assert np.all(state == "searching"), f"seed {seed}: {sorted(set(state))}"  # nothing found, nothing lost
        check_no_evidence_claimed(tr, sc.fault)
        check_probability(tr, S.position_errors(sc, tr))


def test_dead_laser_during_the_run_claims_no_new_evidence():
    """The laser dies at scan 80 (of 150); the odometry alone carries the estimate, which drifts to ~1.2 m off."""
    sc = S.dead_laser(0.0, from_scan=80)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, exclude=sc.fault)
        check_no_evidence_claimed(tr, sc.fault)


def test_corrupt_odometry_record_is_survived():
    """The issue's record, (1e15, 1e15, 0.3): impossible, rejected; the estimate stays right throughout."""
    sc = S.corrupt_odometry(70)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, excuse=excused(sc), exclude=excused(sc))
        assert state[-1] == "localized" and err[-1] < 0.5, f"seed {seed}: ends {state[-1]} {err[-1]:.2f} m off"


def test_plausible_corrupt_odometry_record_is_not_called_localized_while_off():
    """A record 3 m off that no rule can reject: the estimate jumps 2.7-3.7 m at scan 70 and must be found again."""
    sc = S.corrupt_odometry(70, jump=3.0)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, excuse=excused(sc), exclude=excused(sc))
        assert err[70] > FAR, f"seed {seed}: the record did not throw the estimate off ({err[70]:.2f} m)"


KIDNAP_NOTICED = 3      # scans: the kidnapping's own scan and GRACE more


def test_kidnapping_is_noticed_within_three_scans():
    sc = S.kidnapping(90)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, excuse=excused(sc), exclude=excused(sc))
        assert state[89] == "localized" and err[89] < NEAR, f"seed {seed}: not tracking before the kidnapping"
        after = state[90:90 + KIDNAP_NOTICED]
        assert np.any(after != "localized"), f"seed {seed}: still 'localized' at scans 90-{89 + KIDNAP_NOTICED}, " \
                                             f"{err[90:90 + KIDNAP_NOTICED].round(1).tolist()} m off"


def test_sensor_resetting_finds_a_kidnapped_robot_without_a_restart():
    """``--sensor-reset`` in place of ``--restart-after``: no count of bad updates, no probation; while
    ``p_localized`` doubts the place, part of the particles is drawn where the scan fits the map, and the
    filter finds the kidnapped robot again (and says so only once it has)."""
    sc = S.kidnapping(90)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, excuse=excused(sc), exclude=excused(sc), sensor_reset=0.1,
                                    restart_after=0)
        assert not any("global localization again" in text for _, text in tr.events), f"seed {seed}: restarted"
        assert any("sensor resetting" in text for _, text in tr.events), f"seed {seed}: no reset reported"
        assert np.any(state[90:90 + KIDNAP_NOTICED] != "localized"), f"seed {seed}: kidnapping not noticed"
        assert state[-1] == "localized" and err[-1] < 0.5, f"seed {seed}: ends {state[-1]} {err[-1]:.2f} m off"
        again = np.flatnonzero((state == "localized") & (np.arange(state.size) >= 90 + KIDNAP_NOTICED))
        assert again[0] <= 90 + RESET_FINDS, f"seed {seed}: localized again only at scan {again[0]}"


#: Scans after the kidnapping by which sensor resetting has found the robot and says so. Measured: 4 (seeds
#: 0 and 1); with the default restarts instead 12 and 14, with neither 24 and 51.
RESET_FINDS = 10


@cache
def _corridor_run(seed: int):
    """The corridor scenario localized with ``seed`` (once: both corridor tests read it)."""
    sc = S.corridor()
    return sc, S.run(sc, seed, state=STATE)


def test_featureless_corridor_is_never_localized():
    """A robot in a long, featureless corridor: its scans cannot tell where along it it is (3 seeds).

    Until stop 52 the simulated laser read a beam that hits nothing as a hit a few ``sigma_hit`` short of
    the 12 m range, end points in mid-air that fit a corridor end 12 m away: the state said localized there,
    21 m off (seed 0). A real laser reports no return there, and so does the simulated one now."""
    for seed in (0, 1, 2):
        sc, tr = _corridor_run(seed)
        state = _states(tr)
        err = S.position_errors(sc, tr)
        assert not np.any(state == "localized"), f"seed {seed}: 'localized' at " + \
            _show(np.flatnonzero(state == "localized"), err, state)


@pytest.mark.xfail(strict=True, reason="issue 43, open: p_localized reaches 0.73 (seed 0, scan 37, 23 m off), 0.55 "
                   "and 0.59 (seeds 1, 2) while the state says searching: the rival bank holds a handful of stretches "
                   "of the corridor, not its continuum of look-alikes")
def test_featureless_corridor_probability_stays_below_a_half():
    """1 m of a 16 m stretch that fits as well: the robot is not known to be there."""
    for seed in (0, 1, 2):
        p = np.asarray(_corridor_run(seed)[1].p_localized)
        assert np.max(p) <= 0.5, f"seed {seed}: p_localized reaches {np.max(p):.2f} in the corridor"


# ============================================================================ the four new ones
def test_missing_odometry_in_a_turn_is_not_called_localized():
    sc = S.missing_odometry_in_turn()
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, excuse=excused(sc), exclude=excused(sc))
        assert state[-1] == "localized" and err[-1] < NEAR, f"seed {seed}: ends {state[-1]} {err[-1]:.2f} m off"


def test_understated_max_range_does_not_make_a_right_estimate_lost():
    """Most readings lie above the 2.5 m the log states: the run says so and uses them (check_log_max_range)."""
    sc = S.understated_max_range(2.5)
    for seed in SEEDS:
        with pytest.warns(UserWarning, match=r"states a maximum range of 2.5 m, but \d+% of its readings"):
            tr, err, state = honest_run(sc, seed, keep_when_near=True)
        assert err[-1] < NEAR, f"seed {seed}: ends {err[-1]:.2f} m off"


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "issue 43, open: with half the beams left, the state says lost while within 0.3 m (benchmarks/RESULTS.md, "
    "bench_scenarios: 6 of 12 seeds fail, seed 0 among them, 17 scans lost within 0.3 m in all; 35 when every place "
    "was first tracked by its own particles (stop 65), 6 before, when seeds 0 and 1 passed by luck)"))
def test_understated_max_range_kept_by_the_user_leaves_the_state_honest():
    """``--max-range 2.5`` keeps the stated range: the readings above it are no return, and the run localizes on
    the short beams left (most of them). It may end less accurate, but its state must stay honest: not lost while
    within 0.3 m, not localized while 1 m off."""
    sc = S.understated_max_range(2.5)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, keep_when_near=True, max_range=2.5)
        assert float(np.mean(np.asarray(tr.n_valid)[10:])) < 0.6 * sc.log.n_beams, \
            f"seed {seed}: most readings were used; the setting did not keep the stated 2.5 m"


def test_moved_obstacle_does_not_make_a_right_estimate_lost():
    sc = S.moved_obstacle()
    for seed in SEEDS:
        honest_run(sc, seed, keep_when_near=True)


def test_walking_person_does_not_make_a_right_estimate_lost():
    sc = S.walking_person()
    person = np.flatnonzero(sc.fault)
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, keep_when_near=True)
        # the person is no reason for doubt: a right estimate stays "localized" through the 20 scans and after
        during = np.arange(person[0], person[-1] + 6)
        doubt = during[(err[during] <= NEAR) & (state[during] != "localized")]
        assert not doubt.size, f"seed {seed}: not 'localized' while right at " + _show(doubt, err, state)


def test_a_robot_that_starts_in_a_hole_of_the_map_is_found_early():
    """The robot starts amid a 3 m square of floor that the map leaves unknown. Global localization draws its
    particles over the map's holes as well as its free cells (``OccupancyGrid.holes``), so the filter looks for the
    robot where it is: found, by bench_global's rule, within the first 30% of the run (drawn over the free cells
    only, seed 1 was found at scan 74 of 150)."""
    sc = S.start_in_a_hole()
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed)
        found = np.flatnonzero((err <= 0.5) & (state == "localized"))
        assert found.size and found[0] <= 0.3 * len(err), f"seed {seed}: first localized within 0.5 m at " \
                                                           f"{found[:1].tolist()} of {len(err)} scans"
        assert state[-1] == "localized" and err[-1] < 0.5, f"seed {seed}: ends {state[-1]} {err[-1]:.2f} m off"


# ============================================================================ the checks can fail
def test_the_checks_catch_a_dishonest_state():
    """Doctored traces of a real run: each check fails on the lie it is there to catch."""
    sc = S.kidnapping(90)
    tr = S.run(sc, 0, state=STATE)
    err = S.position_errors(sc, tr)
    state = _states(tr)
    ex = excused(sc)
    check_never_localized_far(state, err, ex)                        # today's run passes ...
    check_localized_when_near(state, err, ex)
    with pytest.raises(AssertionError, match="while more than 1.0 m off"):
        check_never_localized_far(np.full(err.size, "localized"), err, ex)   # ... always localized does not
    slow = state.copy()
    slow[90:93] = "localized"                                        # a state that noticed three scans late ...
    check_never_localized_far(slow, err, ex)                         # ... is excused within the grace, ...
    with pytest.raises(AssertionError, match="while more than 1.0 m off at scans 90"):
        check_never_localized_far(slow, err, None)                   # ... and caught without it
    lost_after = np.where(np.arange(err.size) >= 100, "lost", state)
    with pytest.raises(AssertionError, match="scans within 0.3 m say 'localized'"):
        check_localized_when_near(lost_after, err, ex)
    with pytest.raises(AssertionError, match="'lost' while within 0.3 m"):
        check_not_lost_when_near(lost_after, err)

    def fake(p, st=state):
        return SimpleNamespace(state=st, poses=tr.poses, p_localized=p)

    honest = np.where(err > FAR, 0.05, 0.95)
    check_probability(fake(honest), err, ex, ex)
    with pytest.raises(AssertionError, match="at or above 0.7 while more than"):
        check_probability(fake(np.full(err.size, 0.9)), err, ex, ex)
    with pytest.raises(AssertionError, match="at or above 0.7 while more than"):
        check_probability(fake(np.where(err > FAR, LOST_BELOW, 0.95)), err, ex, ex)
    with pytest.raises(AssertionError, match="averages"):
        check_probability(fake(np.where(err > FAR, 0.05, 0.6)), err, ex, ex)

    dead = np.zeros(err.size, dtype=bool)
    dead[100:] = True
    turned = np.where(np.arange(err.size) >= 120, "localized", np.where(dead, "lost", state))
    with pytest.raises(AssertionError, match="without a valid reading at scans \\[120\\]"):
        check_no_evidence_claimed(fake(None, turned), dead)
    rising = np.linspace(0, 1, err.size)
    with pytest.raises(AssertionError, match="p_localized rose"):
        check_no_evidence_claimed(fake(rising, np.where(dead, "lost", state)), dead)


def test_a_robot_that_waits_stays_localized():
    """The robot stands still for 300 scans after driving 80: the laser keeps scanning, the filter uses none of
    those scans (no motion), and nothing suggests the estimate went wrong. The state stays localized and
    ``p_localized`` does not fall with the count of scans: how fast a laser scans is no hazard."""
    sc = S.waiting_robot()
    for seed in SEEDS:
        tr, err, state = honest_run(sc, seed, keep_when_near=True)
        wait = np.flatnonzero(sc.fault)
        assert np.all(state[wait] == "localized"), f"seed {seed}: " + _show(wait[state[wait] != "localized"], err,
                                                                            state)
        p = np.asarray(tr.p_localized)[wait]
        assert p.min() >= p[0] - 1e-12, f"seed {seed}: p_localized fell from {p[0]:.3f} to {p.min():.3f} while waiting"
