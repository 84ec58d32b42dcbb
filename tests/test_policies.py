"""Each policy of the run driver (localize.policies) on its own: what it decides, and what it leaves alone."""

import numpy as np
import pytest

from localize.estimate import Estimate
from localize.grid import OccupancyGrid
from localize.maps import office
from localize.mcl import MCL, Proposal
from localize.motion import odometry_pair
from localize.policies import (
    BeamMasks,
    Context,
    Expansion,
    FitWindow,
    MapEvidence,
    MotionGate,
    OdometryCheck,
    Probation,
    Redraw,
    Restart,
    SensorReset,
    StateRules,
    Step,
    ThresholdState,
)
from localize.raycast import RayCaster
from localize.sensors import LikelihoodField

ANGLES = np.linspace(-np.pi / 2, np.pi / 2, 19)
POSE = np.array([3.0, 3.0, 0.5])


class Flat:
    """A sensor model that says nothing (every pose equally likely)."""

    sigma_hit, z_hit, max_range = 0.1, 0.9, 8.0

    def log_likelihood(self, poses, *z):
        return np.zeros(len(poses))


def _estimate(best_weight=1.0, spread=0.1, heading_std=0.05):
    s = spread / np.sqrt(2.0)
    std = np.array([s, s, heading_std])
    return Estimate(POSE, POSE, std, np.diag(std ** 2), best_weight, 1, 100.0, std)


def _scan_step(k, pose=POSE, shift=(0.0, 0.0), grid=None):
    """A step whose scan was taken at ``pose + shift`` in the office, used in the update."""
    g = office() if grid is None else grid
    truth = pose + np.array([shift[0], shift[1], 0.0])
    r = RayCaster(g, 8.0, method="exact").cast(truth[None], ANGLES)[0]
    valid = r < 8.0
    return Step(k, z=(r, ANGLES), scan=(r, ANGLES, valid), n_valid=int(valid.sum()), pose=pose.copy(),
                estimate=_estimate())


# ------------------------------------------------------------------ control and measurement
def test_odometry_check_rejects_impossible_and_nan_steps_and_says_so():
    ctx = Context(StateRules())
    check = OdometryCheck(max_step=20.0)
    ok = ([0.0, 0.0, 0.0], [0.3, 0.0, 0.1])
    assert check.admit(Step(1, pair=odometry_pair(ok)), ok, ctx) is ok
    far = ([0.0, 0.0, 0.0], [30.0, 0.0, 0.0])
    assert check.admit(Step(2, pair=odometry_pair(far)), far, ctx) is None
    nan = ([0.0, 0.0, 0.0], [np.nan, 0.0, 0.0])
    assert OdometryCheck(None).admit(Step(3, pair=odometry_pair(nan)), nan, ctx) is None
    assert OdometryCheck(None).admit(Step(4, pair=odometry_pair(far)), far, ctx) is far     # no bound, finite
    assert [k for k, _ in ctx.events] == [2, 3]
    assert "30 m is impossible" in ctx.events[0][1] and "NaN" in ctx.events[1][1]
    assert check.admit(Step(5), 0.7, ctx) == 0.7          # not an odometry pair: not judged


def test_motion_gate_counts_motion_from_the_last_used_scan_in_distance_and_angle():
    odo = np.array([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.35, 0, 0], [0.35, 0, 0.6]], dtype=float)
    gate = MotionGate((0.3, 0.5), odometry=odo)
    used = []
    for k in range(len(odo)):
        if gate.admits(Step(k)):
            gate.used()
            used.append(k)
    assert used == [0, 3, 4]          # 0.35 m after scan 0; then a 0.6 rad turn on the spot


def test_beam_masks_leave_out_short_beams_and_skip_a_scan_with_nothing_left():
    g = office()
    f = MCL.gaussian(POSE, (1e-6, 1e-6, 1e-6), 20, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
    caster = RayCaster(g, 8.0, method="march")
    masks = BeamMasks(g, np.zeros(3), 8.0, short=1.0, caster=caster)
    r = RayCaster(g, 8.0, method="exact").cast(POSE[None], ANGLES)[0]
    cluttered = r.copy()
    cluttered[:3] = np.maximum(r[:3] - 1.5, 0.1)          # three beams blocked by something unmapped
    z = masks.apply(f, (cluttered, ANGLES))
    assert z is not None and masks.n_short == 3 and np.all(z[0][:3] == 8.0)
    most = np.maximum(r - 1.5, 0.1)                       # most of the scan reads short: the place is wrong,
    assert masks.apply(f, (most, ANGLES))[0] is not None and masks.n_short == 3    # nothing is left out
    blank = OccupancyGrid(np.full(g.shape, np.nan), g.resolution, origin=g.origin)
    blind = BeamMasks(blank, np.zeros(3), 8.0, unknown=True)    # every beam ends where the map knows nothing
    assert blind.apply(f, (r, ANGLES)) is None and blind.n_blind == 1 and blind.n_unknown == int((r < 8).sum())
    ctx = Context(StateRules())
    masks.report(9, ctx)
    blind.report(9, ctx)
    assert len(ctx.events) == 2 and "3 beams that read more than 1 m shorter" in ctx.events[0][1]
    assert "1 scan had no other valid beam" in ctx.events[1][1]


# ------------------------------------------------------------------ evidence
def test_map_evidence_fits_the_scan_at_the_truth_and_not_a_metre_away():
    g = office()
    f = MCL.gaussian(POSE, (1e-3, 1e-3, 1e-3), 50, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
    ev = MapEvidence(g, Flat(), StateRules())
    ctx = Context(StateRules())
    right, wrong = _scan_step(0), _scan_step(1, shift=(1.0, 0.0))
    ev.assess(right, f, ctx)
    ev.assess(wrong, f, ctx)
    assert right.fit == 1.0 and wrong.fit < 0.5 and ev.wrong(wrong.fit) and not ev.wrong(right.fit)
    assert right.on_map == 1.0 and not right.off_map


def test_map_evidence_calls_a_cloud_off_the_map_only_when_no_weight_is_on_it():
    g = office()
    f = MCL.gaussian([-20.0, -20.0, 0.0], (1e-3, 1e-3, 1e-3), 10, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
    step = _scan_step(0)
    MapEvidence(g, Flat(), StateRules()).assess(step, f, Context(StateRules()))
    assert step.on_map == 0.0 and step.off_map
    # in a wall, with a finite price for obstacles: not off the map (the map may be wrong), outside it is
    wall = np.argwhere(g.occupied)[len(np.argwhere(g.occupied)) // 2]
    xy = g.cell_to_world(wall)
    f = MCL.gaussian([xy[0], xy[1], 0.0], (1e-4, 1e-4, 1e-3), 10, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
    for soft, off in [(True, False), (False, True)]:
        step = _scan_step(0)
        MapEvidence(g, Flat(), StateRules(), soft=soft).assess(step, f, Context(StateRules()))
        assert step.on_map == 0.0 and step.off_map is off


def test_fit_window_keeps_the_last_fits_and_those_since_a_loss():
    w = FitWindow(3)
    for v in (0.1, 0.2, 0.3, 0.4):
        w.add(v)
    assert w.recent == [0.2, 0.3, 0.4] and w.mean == pytest.approx(0.3)
    w.since_loss = []
    assert np.isnan(w.judging())
    w.add(0.9)
    assert w.judging() == pytest.approx(0.9) and w.mean == pytest.approx((0.3 + 0.4 + 0.9) / 3)
    w.clear()
    assert np.isnan(w.mean)


# ------------------------------------------------------------------ recovery
def test_expansion_spreads_an_agreed_cloud_whose_scan_does_not_fit_and_nothing_else():
    g = office()
    ev = MapEvidence(g, Flat(), StateRules())
    for agreed, fit, spreads in [(True, 0.1, True), (False, 0.1, False), (True, 0.95, False), (True, np.nan, False)]:
        f = MCL.gaussian(POSE, (1e-4, 1e-4, 1e-4), 200, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
        exp = Expansion((0.3, 0.1))
        step = _scan_step(0)
        step.agreed, step.fit = agreed, fit
        exp.apply(step, f, ev)
        assert bool(f.particles[:, 0].std() > 0.2) is spreads and exp.count == int(spreads)
        if spreads:     # the noise has the asked standard deviations (200 draws: 5 standard errors)
            assert abs(f.particles[:, 0].std() - 0.3) < 5 * 0.3 / np.sqrt(2 * 200)


def test_restart_counts_poor_fits_of_an_agreed_cloud_and_starts_a_probation():
    g = office()
    ev = MapEvidence(g, Flat(), StateRules())
    ctx = Context(StateRules())
    f = MCL.gaussian(POSE, (1e-3, 1e-3, 1e-3), 100, (0.0,) * 4, Flat(), rng=np.random.default_rng(1), grid=g)
    restart = Restart(after=3, n_fresh=300)
    for k in range(3):
        step = _scan_step(k, shift=(1.0, 0.0))       # the scan fits 1 m away: the agreed place is wrong
        step.agreed = True
        ev.assess(step, f, ctx)
        ctx.fits.add(step.fit)
        restart.count(step, ctx, ev, gathered=False)
        assert restart.due(f, ctx) is (k == 2)
    restart.start(step, f, ctx, min_fit=0.4)
    assert f.n == 400 and ctx.probation is not None and ctx.probation.n_old == 100
    np.testing.assert_allclose(np.exp(f.log_weights[100:]).sum(), 0.5)
    assert ctx.fits.recent == [] and restart.poor == 0 and not ctx.agreed
    assert "300 particles drawn over the map" in ctx.events[-1][1]
    # a good fit resets the count
    good = _scan_step(5)
    good.agreed = True
    ev.assess(good, f, ctx)
    ctx.fits.add(good.fit)
    restart.poor = 2
    restart.count(good, ctx, ev, gathered=False)
    assert restart.poor == 0


def test_restart_with_p_localized_counts_the_updates_below_its_lost_threshold():
    """With the probability state, an update counts against the place when p_localized is below the state's
    threshold for lost (Restart.lost_below, by default ReliabilityState's), and one at or above it resets the count;
    an update-free step leaves the count as it is."""
    g = office()
    f = MCL.gaussian(POSE, (1e-3, 1e-3, 1e-3), 100, (0.0,) * 4, Flat(), rng=np.random.default_rng(1), grid=g)
    for lost_below, counted in ((0.5, [False, False, True]), (0.7, [True, False, True])):
        restart, ctx = Restart(after=2, n_fresh=300, lost_below=lost_below), Context(StateRules())
        for p, counts in zip((0.6, 0.7, 0.49), counted):
            step = _scan_step(0)
            step.agreed, step.p_localized = True, p
            before = restart.poor
            restart.count(step, ctx, MapEvidence(g, Flat(), StateRules()), gathered=False)
            assert restart.poor == (before + 1 if counts else 0), (lost_below, p)
        idle = _scan_step(0)
        idle.z, idle.p_localized, before = None, 0.1, restart.poor
        restart.count(idle, ctx, MapEvidence(g, Flat(), StateRules()), gathered=False)
        assert restart.poor == before
    restart.poor = 2
    assert restart.due(f, ctx)


def test_default_policies_give_the_restart_the_probability_states_lost_threshold():
    from localize.reliability import LOST_BELOW
    from localize.runloop import default_policies
    from localize.sensors import LikelihoodField

    g = office()
    f = MCL.uniform(g, 200, (0.01,) * 4, LikelihoodField(g, 8.0, sigma_hit=0.2), rng=np.random.default_rng(0))
    pol = default_policies(f, restart_after=3, state="probability")
    assert pol.restart.lost_below == LOST_BELOW == pol.state.lost_below
    # one threshold for every restart: with the threshold state no step has a p_localized to compare with it,
    # and the restart counts the fits (test above)
    assert default_policies(f, restart_after=3).restart.lost_below == LOST_BELOW


def test_probation_shows_the_old_place_until_the_new_one_wins_weight_and_fit():
    f = MCL.gaussian(POSE, (1e-3, 1e-3, 1e-3), 50, (0.0,) * 4, Flat(), rng=np.random.default_rng(2))
    far = POSE + [5.0, 0.0, 0.0]
    f.add_particles(np.tile(far, (50, 1)), share=0.5)
    f.replace(f.particles, np.concatenate([np.full(50, np.log(0.1 / 50)), np.full(50, np.log(0.9 / 50))]))
    trial = Probation(50, POSE, min_fit=0.4, window=5)
    e = f.estimate()
    assert np.allclose(trial.estimate(f, e).pose[:2], POSE[:2], atol=0.01)     # no fits yet: the old place
    trial.fits = [[0.2] * 3, [0.8] * 3]
    shown = trial.estimate(f, e)
    assert np.allclose(shown.pose[:2], far[:2], atol=0.01) and shown.best_weight == pytest.approx(0.9)


def test_redraw_re_draws_a_failed_cloud_and_injects_only_while_lost():
    g = office()
    f = MCL.gaussian(POSE, (1e-3, 1e-3, 1e-3), 100, (0.0,) * 4, Flat(), rng=np.random.default_rng(3), grid=g)
    ctx = Context(StateRules())
    redraw = Redraw(on_failure=True, injection=0.2)
    step = Step(4, degenerate=True)
    assert redraw.due(step, f)
    redraw.apply(step, f, ctx)
    assert f.particles[:, 0].std() > 1.0 and "zero likelihood" in ctx.events[0][1]
    assert not Redraw(on_failure=False).due(step, f)
    used = Step(5, z=(np.ones(3), np.zeros(3)))
    assert not redraw.searching(used, ctx)
    ctx.state = "lost"
    assert redraw.searching(used, ctx) and not redraw.searching(Step(6), ctx)     # only with an update


def _lidar_step(truth, p_localized, grid=None):
    """A step whose 90-beam, 360-degree scan was taken at ``truth`` in the office, weighed with ``p_localized``."""
    g = office() if grid is None else grid
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    r = RayCaster(g, 8.0, method="exact").cast(np.asarray(truth, dtype=float)[None], angles)[0]
    valid = r < 8.0
    return Step(7, z=(r, angles), scan=(r, angles, valid), n_valid=int(valid.sum()), p_localized=p_localized)


def test_sensor_reset_draws_more_the_more_the_filter_doubts_and_nothing_without_doubt():
    reset = SensorReset(office(), LikelihoodField(office(), 8.0, sigma_hit=0.1), share=0.2, below=0.7)
    shares = [reset.share_at(_lidar_step(POSE, p)) for p in (0.0, 0.35, 0.7, 0.95, float("nan"))]
    assert shares == pytest.approx([0.2, 0.1, 0.0, 0.0, 0.0])
    unused = _lidar_step(POSE, 0.0)
    unused.z = None                                  # the motion gate kept the scan out: no evidence, no reset
    assert reset.share_at(unused) == 0.0
    dead = _lidar_step(POSE, 0.0)
    dead.n_valid = 0
    assert reset.share_at(dead) == 0.0
    calm, doubt = _lidar_step(POSE, 0.9), _lidar_step(POSE, 0.0)
    reset.propose(calm)
    reset.propose(doubt)
    assert calm.proposal is None and calm.reset_share == 0.0           # the filter's own sampler, no reset
    assert isinstance(doubt.proposal, Proposal) and doubt.reset_share == pytest.approx(0.2)
    with pytest.raises(ValueError, match="share"):
        SensorReset(office(), Flat(), share=1.0)


def test_sensor_reset_draws_near_the_places_where_the_scan_fits():
    """Where the scan fits best is where it was taken (a 360-degree scan in the office); draws go near the places."""
    g = office()
    lf = LikelihoodField(g, 8.0, sigma_hit=0.1)
    truth = np.array([6.0, 4.0, 1.0])
    reset = SensorReset(g, lf, share=0.1, n_places=8, spread=(0.1, 0.05), seed=1)
    step = _lidar_step(truth, 0.0, g)
    places = reset.places(step)
    assert 1 <= len(places) <= 8
    assert np.hypot(*(places[0, :2] - truth[:2])) < 0.3          # the best place is the robot's
    n = 800
    poses = reset.near(places)(n, np.random.default_rng(0))
    assert poses.shape == (n, 3) and np.all(np.abs(poses[:, 2]) <= np.pi)
    # every draw lies near one of the places: 0.1 m of spread per axis, so 4.5 sd is 0.64 m in the plane
    d = np.hypot(*(poses[:, None, :2] - places[None, :, :2]).transpose(2, 0, 1)).min(axis=1)
    assert d.max() < 1.0
    # each place is drawn equally often: near the robot about n / len(places); 5 binomial sd below that is a fail
    near = int(np.sum(np.hypot(*(poses[:, :2] - truth[:2]).T) < 0.5))
    k = len(places)
    assert near >= n / k - 5 * np.sqrt(n * (1 / k) * (1 - 1 / k))
    step.p_localized = 0.0
    reset.propose(step)
    assert step.proposal is not None and reset.n_resets == 1      # counted for the run's report


def test_sensor_reset_injects_through_the_resampling_with_its_own_sampler():
    g = office()
    f = MCL.gaussian(POSE, (0.05, 0.05, 0.05), 1000, (0.0,) * 4, Flat(), rng=np.random.default_rng(2), grid=g)
    far = np.array([[20.0, 2.0, 0.0]])
    f.resample(injection=0.25, proposal=Proposal(lambda n, rng: np.repeat(far, n, axis=0)))
    at_far = np.all(f.particles == far, axis=1)
    assert f.status.n_injected == 250 and int(at_far.sum()) == 250
    assert np.allclose(f.weights, 1e-3)                     # no log_weight: weighed alike
    f.resample(injection=0.25)                              # the proposal is for that one call: uniform again
    assert int(np.all(f.particles == far, axis=1).sum()) < 250
    f = MCL.gaussian(POSE, (0.05, 0.05, 0.05), 1000, (0.0,) * 4, Flat(), rng=np.random.default_rng(2), grid=g)
    f.resample(injection=0.25, proposal=Proposal(lambda n, rng: np.repeat(far, n, axis=0),
                                                 lambda x: np.full(len(x), np.log(3.0))))
    at_far = np.all(f.particles == far, axis=1)
    assert f.weights[at_far].sum() == pytest.approx(0.5)    # 250 drawn at 3 times the weight of 750 kept
    assert f.status.n_eff == pytest.approx(1.0 / np.sum(f.weights ** 2))


def test_sensor_reset_weighs_its_draws_as_a_uniform_prior_over_the_free_space_would():
    """Importance weights: the draws near the places, weighed, estimate the mass the prior's uniform part puts
    anywhere, ``(1 - p) (1 - s) / (p s)`` times the region's share of the free space's volume (against a kept
    particle's weight). Checked on a box about one place, to 5 standard errors of 40,000 draws."""
    g = office()
    reset = SensorReset(g, Flat(), share=0.1, spread=(0.1, 0.05))
    places = np.array([[3.0, 3.0, 0.5], [6.0, 4.0, -2.0], [3.1, 3.0, 0.6]])
    p, s = 0.3, 0.08
    draws = reset.near(places)(40_000, np.random.default_rng(5))
    w = np.exp(reset.log_weight(places, p, s)(draws))
    half = np.array([0.25, 0.25, 0.15])                      # a box about the first place (it holds the third too)
    inside = np.all(np.abs(draws - places[0]) < half, axis=1)
    volume = float(np.prod(2 * half))
    free_volume = np.count_nonzero(g.free) * g.resolution ** 2 * 2 * np.pi
    expected = (1 - p) * (1 - s) / (p * s) * volume / free_volume
    values = w * inside
    assert values.mean() == pytest.approx(expected, abs=5 * values.std() / np.sqrt(values.size))
    # the density q: three places, so a pose at the second (alone) has a third of one Gaussian's peak density
    peak = 1.0 / ((2 * np.pi) ** 1.5 * 0.1 * 0.1 * 0.05)
    assert reset.log_q(places, places[1:2])[0] == pytest.approx(np.log(peak / 3), rel=1e-9)


def test_mcl_takes_injection_and_soft_obstacles_for_one_call_only():
    g = office()
    wall = g.cell_to_world(np.argwhere(g.occupied)[100])
    f = MCL(np.array([[wall[0], wall[1], 0.0], [3.0, 3.0, 0.0]]), (0.0,) * 4, Flat(), rng=np.random.default_rng(0),
            grid=g, free_space_only=True, occupied_penalty=5.0)
    f.update(np.ones(1), soft_obstacles=False)
    assert f.log_weights[0] == -np.inf
    f.replace(f.particles, np.full(2, -np.log(2)))
    f.update(np.ones(1))
    assert f.log_weights[0] - f.log_weights[1] == pytest.approx(-5.0)
    f = MCL.uniform(g, 1000, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
    f.resample(injection=0.25)
    assert f.status.n_injected == 250 and f.injection == 0.0
    with pytest.raises(ValueError, match="injection"):
        f.resample(injection=1.5)


# ------------------------------------------------------------------ the state
def _state_run(confident_pattern, degenerate_at=()):
    g = office()
    rules = StateRules(probe_shift=0.0)
    ctx = Context(rules)
    state = ThresholdState(Flat(), rules, MapEvidence(g, Flat(), rules))
    out = []
    for k, ok in enumerate(confident_pattern):
        step = _scan_step(k, shift=(0.0, 0.0) if ok else (1.0, 0.0))
        step.estimate = _estimate() if ok else _estimate(best_weight=0.3)
        step.degenerate = k in degenerate_at
        ctx.fits.add(1.0 if ok else 0.1)
        out.append(state.update(step, ctx))
    return out, ctx


def test_threshold_state_needs_hold_confident_scans_and_hold_lost_doubtful_ones():
    states, ctx = _state_run([1, 1, 1, 1, 0, 0, 0, 1])
    assert states == ["searching"] * 2 + ["localized"] * 4 + ["lost"] * 2
    assert ("state searching -> localized") in [t for _, t in ctx.events]
    states, _ = _state_run([1, 1, 1, 1, 1], degenerate_at=(4,))
    assert states[-1] == "lost"                          # every particle got zero likelihood: lost at once


def test_a_lost_filter_needs_fits_judged_since_the_loss():
    """After a loss the fits of the lost place do not vouch for the next one: with no judged fit since, the
    state cannot be localized again however confident the cloud is."""
    g = office()
    rules = StateRules(probe_shift=0.0, hold=1)
    ctx = Context(rules, state="localized")
    state = ThresholdState(Flat(), rules, MapEvidence(g, Flat(), rules))
    ctx.fits.add(1.0)
    state.interrupt(ctx)
    assert ctx.state == "lost"
    ctx.fits.since_loss = []
    step = _scan_step(0)
    assert not state.confident(step, ctx)
    ctx.fits.add(1.0)
    assert state.confident(step, ctx)


def test_threshold_state_in_an_unknown_map_needs_a_judged_fit():
    """A map that cannot judge (every cell unknown) gives no fit: a searching filter never becomes localized,
    however tight its cloud, while on the known map the same scan makes it localized."""
    g = office()
    blank = OccupancyGrid(np.full(g.shape, np.nan), g.resolution, origin=g.origin)
    rules = StateRules(probe_shift=0.0, hold=1)
    f = MCL.gaussian(POSE, (1e-3, 1e-3, 1e-3), 50, (0.0,) * 4, Flat(), rng=np.random.default_rng(0))
    for grid, expected in [(blank, "searching"), (g, "localized")]:
        ctx = Context(rules)
        evidence = MapEvidence(grid, Flat(), rules)
        state = ThresholdState(Flat(), rules, evidence)
        step = _scan_step(0, grid=g)
        evidence.assess(step, f, ctx)
        if np.isfinite(step.fit):
            ctx.fits.add(step.fit)
        assert bool(np.isnan(step.fit)) is (grid is blank)
        assert state.update(step, ctx) == expected
