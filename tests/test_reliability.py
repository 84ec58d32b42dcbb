"""The probability of being localized (localize.reliability): calibrated on the map and sensor, on data it was
not calibrated on, and filtered over scans like the Bayes filter of chapter 1."""

import numpy as np
import pytest

from localize.grid import OccupancyGrid
from localize.maps import office
from localize.reliability import EvidenceModel, LocalizedBelief, calibrate, calibration_fits, reliability_table
from localize.sensors import LikelihoodField

ANGLES = np.linspace(-np.pi, np.pi, 36, endpoint=False)


@pytest.fixture(scope="module")
def model():
    # map_error 0: the held-out scans below are simulated too, with no map error beyond the sensor model's
    return calibrate(office(), LikelihoodField(office(), 8.0, sigma_hit=0.1), ANGLES, np.random.default_rng(0),
                     map_error=0.0)


def test_the_evidence_model_separates_right_from_wrong(model):
    assert model.p_right.sum() == pytest.approx(1.0) and model.p_wrong.sum() == pytest.approx(1.0)
    centres = 0.5 * (model.edges[:-1] + model.edges[1:])
    assert centres @ model.p_right > centres @ model.p_wrong + 0.3     # right poses fit the scans far better
    assert np.all(model.likelihood(np.nan) == 1.0)                     # no judged fit: no evidence


def test_one_scan_posterior_is_calibrated_on_scans_it_was_not_calibrated_on(model):
    """Held-out simulated scans (another seed): in every bin of p(right | fit) with at least 50 scans, the share
    of right estimates is the bin's mean probability within four standard errors of the bin's share."""
    from localize.reliability import error_levels

    lf = LikelihoodField(office(), 8.0, sigma_hit=0.1)
    f_right, f_wrong = [], None                              # right estimates at every error level, as calibrated
    for i, e in enumerate(error_levels(lf, ANGLES.size, 1.0)):
        f_r, f_w = calibration_fits(office(), lf, ANGLES, np.random.default_rng(10 + i), n_poses=80, error=e)
        f_right.append(f_r)
        f_wrong = f_w if f_wrong is None else np.concatenate([f_wrong, f_w])
    f_right = np.concatenate(f_right)
    prior = f_right.size / (f_right.size + f_wrong.size)
    p = np.array([model.posterior(f, prior) for f in np.concatenate([f_right, f_wrong])])
    right = np.r_[np.ones(f_right.size, bool), np.zeros(f_wrong.size, bool)]
    rows = [r for r in reliability_table(p, right, n_bins=10) if r[2] >= 50]
    assert len(rows) >= 2
    for lo, hi, n, mean_p, share in rows:
        assert abs(share - mean_p) <= 4 * np.sqrt(max(mean_p * (1 - mean_p), 0.01) / n), (lo, hi, n, mean_p, share)
    # a wrong formula -- the likelihoods swapped -- is far from calibrated
    swapped = EvidenceModel(model.edges, model.p_wrong, model.p_right, model.n_wrong, model.n_right, 1.0)
    q = np.array([swapped.posterior(f, prior) for f in np.concatenate([f_right, f_wrong])])
    worst = max(abs(s - m) for _, _, n, m, s in reliability_table(q, right, n_bins=10) if n >= 50)
    assert worst > 0.5


def test_the_belief_rises_with_fitting_scans_falls_with_poor_ones_and_drifts_without_evidence(model):
    b = LocalizedBelief(model)
    assert b.p == 0.0
    ps = [b.step(0.95) for _ in range(6)]
    assert all(np.diff(ps) > 0) and ps[-1] > 0.95
    down = [b.step(0.05) for _ in range(3)]
    assert all(np.diff([ps[-1], *down]) < 0) and down[-1] < 0.1
    b = LocalizedBelief(model, prior=1.0, p_lose=0.01)
    assert b.step(np.nan) == pytest.approx(0.99)                     # only the transition: 1 - p_lose
    with pytest.raises(ValueError, match="p_lose"):
        LocalizedBelief(model, p_lose=1.5)


def test_calibration_refuses_a_map_that_cannot_judge_any_scan():
    g = office()
    blank = OccupancyGrid(np.where(g.free, 0.0, np.nan), g.resolution, origin=g.origin)
    with pytest.raises(ValueError, match="too few scans the map can judge"):
        calibrate(blank, LikelihoodField(g, 8.0, sigma_hit=0.1), ANGLES, np.random.default_rng(0), n_poses=30)


# --------------------------------------------------------------------------- the pieces of the calibration
def test_batched_fits_equal_the_one_pose_fit_with_unknown_cells_and_bad_poses():
    from localize.evidence import scan_fit
    from localize.raycast import RayCaster
    from localize.reliability import scan_fits

    g = office()
    d = np.array(g.data, dtype=float)
    d[20:40, 20:40] = np.nan                                   # an unknown square: beams ending there are not judged
    g2 = OccupancyGrid(d, g.resolution, origin=g.origin)
    rc = RayCaster(g2, 8.0, method="march")
    rng = np.random.default_rng(3)
    poses = g.sample_free(40, rng)
    scans = rc.cast(poses + rng.normal(0, 0.3, poses.shape) * [1, 1, 0.1], ANGLES) + rng.normal(0, 0.05, (40, 36))
    valid = scans < 8.0
    poses[5] = np.nan
    got = scan_fits(rc, poses, np.zeros(3), scans, valid, ANGLES, 0.2, 5)
    want = [scan_fit(rc, poses[i], np.zeros(3), scans[i][valid[i]], ANGLES[valid[i]], 0.2, 5) if i != 5 else np.nan
            for i in range(40)]
    np.testing.assert_array_equal(got, want)


def test_a_short_reading_says_nothing_against_the_pose_a_long_one_does():
    from localize.raycast import RayCaster
    from localize.reliability import scan_fits

    g = office()
    rc = RayCaster(g, 8.0, method="march")
    pose = np.array([[3.0, 3.0, 1.0]])
    z = rc.cast(pose, ANGLES)
    short, long_ = z.copy(), z.copy()
    short[0, :18] *= 0.3                                     # half the beams stopped by something unmapped
    long_[0, :18] = np.minimum(long_[0, :18] + 2.0, 7.9)      # half the beams through mapped walls
    ok = np.ones((1, 36), bool)
    f = lambda s, unj: float(scan_fits(rc, pose, np.zeros(3), s, ok, ANGLES, 0.2, 5, short_unjudged=unj)[0])  # noqa: E731
    assert f(short, True) == 1.0 and f(short, False) == pytest.approx(0.5, abs=0.06)
    assert f(long_, True) == f(long_, False) <= 0.55


def test_simulated_scans_follow_the_sensor_models_mixture():
    """z_hit 0.6, z_rand 0.4: the share of readings within 3 sigma of the map's range is 0.6 * 0.997 plus the random
    readings that land there; the tolerance is four binomial standard errors of 36 x 300 beams."""
    from localize.raycast import RayCaster
    from localize.reliability import simulate_scans

    g = office()
    lf = LikelihoodField(g, 8.0, sigma_hit=0.1, z_hit=0.6, z_rand=0.4)
    poses = g.sample_free(300, np.random.default_rng(4))
    z = simulate_scans(g, lf, poses, ANGLES, np.random.default_rng(5))
    cast = RayCaster(g, 8.0, method="march").cast(poses, ANGLES)
    hit = cast < 8.0
    near = np.abs(z - cast) <= 0.3
    expected = 0.6 * 0.9973 + 0.4 * 0.6 / 8.0            # a uniform reading lands in the 0.6 m band 0.6/8 of the time
    n = int(hit.sum())
    assert abs(near[hit].mean() - expected) <= 4 * np.sqrt(expected * (1 - expected) / n)
    assert np.all(z[~hit] == 8.0) or lf.z_rand > 0          # no wall in range: max range unless a random reading


def test_look_alikes_are_far_from_the_truth_and_fit_the_scan():
    """A world of two identical rooms: the best wrong place found for a scan taken in one room is never within the
    radius, and the scan fits it (in the twin room or elsewhere) as a random place does not."""
    from localize.raycast import RayCaster
    from localize.reliability import look_alikes, scan_fits

    room = np.zeros((30, 45))
    room[[0, -1], :] = 1.0
    room[:, [0, -1]] = 1.0
    room[10:15, 12:16] = 1.0                                  # a pillar
    g = OccupancyGrid(np.hstack([room, room]), 0.1)           # two identical rooms, 4.5 m apart
    lf = LikelihoodField(g, 6.0, sigma_hit=0.1)
    rng = np.random.default_rng(6)
    truth = np.array([[1.0, 0.8, 0.3], [2.8, 1.8, -2.0]])
    rc = RayCaster(g, 6.0, method="march")
    scans = rc.cast(truth, ANGLES)
    alike = look_alikes(g, lf, truth, np.where(scans < 6.0, scans, np.inf), ANGLES, rng, radius=1.0,
                        n_places=400, n_refine=100)
    assert np.all(np.hypot(*(alike[:, :2] - truth[:, :2]).T) >= 1.0)
    fits = scan_fits(rc, alike, np.zeros(3), scans, scans < 6.0, ANGLES, 0.2, 5)
    assert np.all(fits > 0.7)                     # as a filter's wrong answer would: the scan fits it well
    # a random wrong place does not: the search is what finds look-alikes
    rand = g.sample_free(200, np.random.default_rng(7))
    f_rand = scan_fits(rc, rand, np.zeros(3), np.repeat(scans[:1], 200, 0), np.repeat(scans[:1] < 6.0, 200, 0),
                       ANGLES, 0.2, 5)
    assert np.nanmedian(f_rand) < 0.5


# --------------------------------------------------------------------------- the state
class _Step:
    def __init__(self, k, pose, cloud, *, fit_scan=None, u=None, pair=None):
        self.k, self.pose, self.cloud, self.u, self.pair = k, np.asarray(pose, float), cloud, u, pair
        self.degenerate = self.off_map = False
        self.scan = fit_scan
        self.n_valid = 0 if fit_scan is None else int(fit_scan[2].sum())
        self.z = None if fit_scan is None else (fit_scan[0][fit_scan[2]], fit_scan[1][fit_scan[2]])
        self.p_localized = self.evidence = self.fit = np.nan
        if cloud is not None:                                   # the best cluster is the whole cloud here
            w = np.exp(cloud[1] - np.max(cloud[1]))
            w /= w.sum()
            sd = np.sqrt(w @ (cloud[0][:, :2] - w @ cloud[0][:, :2]) ** 2)
            self.estimate = type("E", (), {"spread": float(np.hypot(*sd))})()

    @property
    def updated(self):
        return self.z is not None


class _Ctx:
    def __init__(self):
        self.state, self.events = "searching", []


def _scan_at(pose, lf, rng):
    from localize.reliability import simulate_scans

    z = simulate_scans(lf.grid, lf, np.atleast_2d(pose), ANGLES, rng)[0]
    return (z, ANGLES, z < lf.max_range)


def test_the_state_follows_p_localized_and_a_jump_starts_a_new_hypothesis():
    from localize.reliability import ReliabilityState

    g = office()
    lf = LikelihoodField(g, 8.0, sigma_hit=0.1, z_hit=0.9, z_rand=0.1)
    rng = np.random.default_rng(7)
    state = ReliabilityState(g, lf, probe_shift=0.0)
    ctx = _Ctx()
    truth = np.array([3.0, 3.0, 1.0])
    tight = (np.tile(truth, (100, 1)) + rng.normal(0, 0.05, (100, 3)), np.full(100, -np.log(100)))
    ps = []
    for k in range(8):                                          # the right place, scans that fit
        st = _Step(k, truth, tight, fit_scan=_scan_at(truth, lf, rng))
        state.update(st, ctx)
        ps.append(st.p_localized)
    assert ctx.state == "localized" and ps[-1] >= 0.9 and ps[0] <= ps[-1]
    wrong = truth + [3.0, 0.0, 1.5]                             # kidnapped: the estimate stays, the robot is elsewhere
    ps = []
    for k in range(8, 16):
        st = _Step(k, truth, tight, fit_scan=_scan_at(wrong, lf, rng))
        state.update(st, ctx)
        ps.append(st.p_localized)
    assert ctx.state == "lost" and st.p_localized < 0.5 and np.all(np.diff(ps) < 0)   # every poor fit lowers it
    assert any("localized -> lost" in t for _, t in ctx.events)
    # a spread cloud: the geometric mean of the belief and the cloud's mass near the estimate, whatever the scan
    # says (never more than the root of that mass; the product of the two would be the mass times the belief)
    spread = (g.sample_free(100, rng), np.full(100, -np.log(100)))
    st = _Step(16, truth, spread, fit_scan=_scan_at(truth, lf, rng))
    state.update(st, ctx)
    mass = np.mean(np.hypot(*(spread[0][:, :2] - truth[:2]).T) <= 1.0)
    assert st.p_localized == pytest.approx(np.sqrt(state.belief.p * mass), rel=1e-12)
    assert st.p_localized <= np.sqrt(mass) + 1e-12
    assert state.jumped(_Step(12, truth + [2.0, 0, 0], tight))            # 2 m with no odometry: a new place
    assert not state.jumped(_Step(12, truth + [0.3, 0, 0], tight))


def test_the_margin_forgives_a_poor_fit_but_not_another_place():
    """A localized filter stays localized through a scan that fits poorly (``p_localized`` between the two
    thresholds, the place part ``m`` still 1), and turns lost when a sixth of the cloud's weight gathers 3 m away
    while the scans still fit the estimate: ``p_localized`` is still above ``LOST_BELOW``, but with a sure belief
    it could be at most ``sqrt(m)``, below ``LOCALIZED_AT``. The old margin, on ``p_localized`` alone, kept it
    localized there."""
    from localize.reliability import LOCALIZED_AT, LOST_BELOW, ReliabilityState

    g = office()
    lf = LikelihoodField(g, 8.0, sigma_hit=0.1, z_hit=0.9, z_rand=0.1)
    rng = np.random.default_rng(7)
    state = ReliabilityState(g, lf, probe_shift=0.0, rivals=False)
    ctx = _Ctx()
    truth = np.array([3.0, 3.0, 1.0])
    tight = (np.tile(truth, (120, 1)) + rng.normal(0, 0.05, (120, 3)), np.full(120, -np.log(120)))
    for k in range(8):
        state.update(_Step(k, truth, tight, fit_scan=_scan_at(truth, lf, rng)), ctx)
    assert ctx.state == "localized"
    for k in range(8, 12):                                       # scans that fit poorly, until p dips below
        st = _Step(k, truth, tight, fit_scan=_scan_at(truth + [3.0, 0.0, 1.5], lf, rng))
        state.update(st, ctx)
        if st.p_localized < LOCALIZED_AT:
            break
    assert LOST_BELOW <= st.p_localized < LOCALIZED_AT and state.place_limit == 1.0 and ctx.state == "localized"
    for k in range(12, 16):                                      # the fit recovers: the belief rises again
        state.update(_Step(k, truth, tight, fit_scan=_scan_at(truth, lf, rng)), ctx)
    assert ctx.state == "localized"
    split = tight[0].copy()
    split[:20] += [3.0, 0.0, 0.0]                                # 20 of 120 particles, a sixth, 3 m away
    st = _Step(16, truth, (split, tight[1]), fit_scan=_scan_at(truth, lf, rng))
    state.update(st, ctx)
    assert st.p_localized >= LOST_BELOW                          # the old margin would have kept it localized
    assert state.place_limit == pytest.approx(np.sqrt(100 / 120)) and ctx.state == "lost"
    assert st.p_place == state.place_limit                       # trajectory.csv's p_place column
    assert "p_place 0.912 below 0.95: another place is probable" in ctx.events[-1][1]


def test_a_corridor_never_pins_the_estimate():
    """Scans in a long featureless corridor fit the estimate moved along it as well: the probe's mass stays near a
    third (estimate, one metre ahead, one behind) however many scans come, and the state never says localized."""
    from localize.reliability import ReliabilityState

    g = OccupancyGrid.from_ascii("#" * 80 + "\n" + "." * 80 + "\n" + "." * 80 + "\n" + "#" * 80, resolution=0.25)
    lf = LikelihoodField(g, 6.0, sigma_hit=0.05, z_hit=0.95, z_rand=0.05)
    rng = np.random.default_rng(8)
    state = ReliabilityState(g, lf)
    ctx = _Ctx()
    pose = np.array([10.0, 0.5, 0.0])
    tight = (np.tile(pose, (50, 1)), np.full(50, -np.log(50)))
    for k in range(20):
        state.update(_Step(k, pose, tight, fit_scan=_scan_at(pose, lf, rng)), ctx)
    assert 0.2 < state.probe_mass < 0.45 and ctx.state == "searching"


def test_no_evidence_from_inside_a_mapped_obstacle():
    from localize.reliability import ReliabilityState

    g = office()
    lf = LikelihoodField(g, 8.0, sigma_hit=0.1)
    state = ReliabilityState(g, lf)
    wall = np.argwhere(g.occupied)[0]
    x, y = g.cell_to_world(wall[None])[0] if hasattr(g, "cell_to_world") else (
        g.origin[0] + (wall[1] + 0.5) * g.resolution, g.origin[1] + (wall[0] + 0.5) * g.resolution)
    st = _Step(0, [x, y, 0.0], None, fit_scan=_scan_at([3.0, 3.0, 0.0], lf, np.random.default_rng(9)))
    assert np.isnan(state.fit(st))
    st = _Step(0, [3.0, 3.0, 0.0], None, fit_scan=_scan_at([3.0, 3.0, 0.0], lf, np.random.default_rng(9)))
    assert state.fit(st) > 0.7


def test_map_error_bounds_the_evidence_against_a_right_estimate():
    """With the robust part, no fit is more than 1 / (map_error * bin width) times likelier at a wrong place than
    at a right one (10:1 for 0.1 and ten bins): a moved cabinet cannot condemn a right estimate in one scan."""
    lf = LikelihoodField(office(), 8.0, sigma_hit=0.1)
    robust = calibrate(office(), lf, ANGLES, np.random.default_rng(0), map_error=0.1)
    plain = calibrate(office(), lf, ANGLES, np.random.default_rng(0), map_error=0.0)
    assert np.max(robust.p_wrong / robust.p_right) <= 1.0 / (0.1 * 0.1)
    np.testing.assert_allclose(robust.p_right, 0.9 * plain.p_right + 0.1 * 0.1)   # the mixture, bin by bin
    np.testing.assert_allclose(robust.p_right.sum(), 1.0)
    # p(fit | right) is the mean over the error levels, and a wider error fits worse
    np.testing.assert_allclose(plain.p_right, plain.p_right_at.mean(axis=0))
    centres = 0.5 * (plain.edges[:-1] + plain.edges[1:])
    assert np.all(np.diff(plain.p_right_at @ centres) < 0)


def test_the_command_line_states_the_thresholds_the_state_uses():
    """``localize run --help`` and summary.json name the probability state's thresholds: the ones it uses."""
    import dataclasses

    from localize import cli, settings
    from localize.reliability import LOCALIZED_AT, LOST_BELOW, ReliabilityState

    text = " ".join({f.name: f for f in dataclasses.fields(settings.RunSettings)}["state"].metadata["cli_help"].split())
    assert f"localized at {LOCALIZED_AT}, lost below {LOST_BELOW}; restarts when it stays below {LOST_BELOW}" in text
    assert f"reached {LOCALIZED_AT};" in cli.STATE_MEANING
    assert f"fell below {LOST_BELOW} or p_place below {LOCALIZED_AT} " in cli.STATE_MEANING
    assert f"no longer allow {LOCALIZED_AT}: p_place" in text
    state = ReliabilityState(office(), LikelihoodField(office(), 8.0, sigma_hit=0.2))
    assert (state.localized_at, state.lost_below) == (LOCALIZED_AT, LOST_BELOW)


# ------------------------------------------------------------------ calibrated once per map and sensor
def test_calibrate_once_keys_on_content_and_never_on_a_function(monkeypatch):
    """A second run on an equal map and sensor model reuses the model; any change of the map, the sensor's
    parameters, the beams or the seed calibrates again; a sensor holding a function is never cached (its
    content cannot be read, and a key by identity could match another function later); the cache stays small."""
    from localize import reliability

    monkeypatch.setattr(reliability, "_CALIBRATIONS", type(reliability._CALIBRATIONS)())
    calls = []
    real = reliability.calibrate
    monkeypatch.setattr(reliability, "calibrate", lambda *a, **k: calls.append(1) or real(*a, **k))
    angles = np.linspace(-np.pi, np.pi, 24, endpoint=False)

    def run(grid=None, angles=angles, seed=0, **sensor):
        grid = office() if grid is None else grid
        return reliability.calibrate_once(grid, LikelihoodField(grid, 8.0, **{"sigma_hit": 0.1, **sensor}), angles,
                                          seed, n_poses=40)

    first = run()
    assert run() is first and len(calls) == 1                       # a new, equal map and sensor: the cached one
    run(sigma_hit=0.2), run(seed=1), run(angles=angles[::2])
    data = office().data.copy()
    data[50, 50] = 1.0 - data[50, 50]                                 # one cell of the map changed
    run(grid=OccupancyGrid(data, office().resolution, office().origin))
    assert len(calls) == 5                                           # each change calibrates anew
    assert len(reliability._CALIBRATIONS) == reliability._CALIBRATIONS_KEPT
    assert run() is not first and len(calls) == 6                    # the oldest was let go

    class WithFunction(LikelihoodField):
        pass

    odd = WithFunction(office(), 8.0, sigma_hit=0.1)
    odd.score = lambda x: x
    assert reliability.content_key(odd) is None
    reliability.calibrate_once(office(), odd, angles, 0, n_poses=40)
    reliability.calibrate_once(office(), odd, angles, 0, n_poses=40)
    assert len(calls) == 8                                           # never cached


def test_floor_text_writes_a_probability_rounded_down_and_never_below_its_own_decimals():
    """The CSV's and the summary's probabilities: rounded down (a value just below a threshold never reads as the
    threshold), and a value that already has that many decimals is written as it is (the headline writes the
    summary's four-decimal values again with two: 0.57 must not read 0.56)."""
    from localize.reliability import LOCALIZED_AT, LOST_BELOW, floor_text

    for decimals in (2, 3, 4):
        exact = np.round(np.arange(0, 10 ** decimals + 1) / 10 ** decimals, decimals)
        assert [floor_text(v, decimals) for v in exact] == [f"{v:.{decimals}f}" for v in exact]
    x = np.random.default_rng(0).random(20000)
    for decimals in (2, 4):
        written = np.array([float(floor_text(v, decimals)) for v in x])
        assert np.all(written <= x) and np.all(x - written < 10.0 ** -decimals)
    for t in (LOCALIZED_AT, LOST_BELOW):
        below = np.nextafter(t, 0.0)
        assert float(floor_text(below, 2)) < t and float(floor_text(below, 4)) < t and float(floor_text(t, 2)) == t
