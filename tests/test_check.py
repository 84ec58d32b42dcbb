"""The self-checks are fair: reference implementations pass, typical mistakes fail with the right hint."""

from __future__ import annotations

import math

import numpy as np
import pytest

from localize import check, discrete, histogram, motion, resample
from localize.geometry import wrap_angle


def fails_with(report, hint_part):
    assert not report, f"expected a failure, got:\n{report}"
    hints = " ".join(report.hints)
    assert hint_part in hints, f"expected a hint containing {hint_part!r}, got:\n{report}"


# ------------------------------------------------------------------ report mechanics
def test_report_prints_and_is_truthy():
    r = check.normalize(discrete.normalize)
    assert r and r.passed and not r.failures
    text = str(r)
    assert text.startswith("normalize: all") and "PASS" in text and "FAIL" not in text


def test_failure_shows_expected_next_to_seen():
    text = str(check.bayes_update(lambda b, lik: np.asarray(b) * np.asarray(lik)))
    seen = [ln for ln in text.splitlines() if ln.strip().startswith("seen:")]
    expected = [ln for ln in text.splitlines() if ln.strip().startswith("expected:")]
    assert seen and expected, text
    ref = discrete.update(np.array([0.05, 0.05, 0.1, 0.2, 0.2, 0.1, 0.1, 0.1, 0.05, 0.05]),
                          np.where(np.isin(np.arange(10), [0, 1, 8]), 0.6, 0.2))
    assert f"{ref[0]:.4f}" in expected[-1]
    # every failed verdict of every check carries an expected value or a hint that names it
    r = check.histogram_sense(lambda b, w, m, h, mi: histogram.sense(b, w, m, mi, h))
    assert all(v.expected for v in r.failures if v.detail), r


def test_not_implemented_and_wrong_types_never_crash():
    def stub(p):
        raise NotImplementedError

    r = check.normalize(stub)
    fails_with(r, "replace `raise NotImplementedError`")
    fails_with(check.normalize(lambda p: "hello"), "NumPy array")
    fails_with(check.normalize(lambda p: None), "`return`")
    fails_with(check.normalize(lambda p: [1, 2]), "one entry per input element")
    fails_with(check.effective_sample_size(lambda w: 1 / 0), "traceback")
    fails_with(check.resampler(lambda w, rng: {"a": 1}), "NumPy array")
    assert "FAIL" in str(check.resampler(lambda w, rng: np.zeros(3, int)))


# ------------------------------------------------------------------ normalize / Bayes
def test_normalize_mistakes():
    fails_with(check.normalize(lambda p: np.asarray(p, float)), "divide by the sum")

    def in_place(p):
        p /= p.sum()
        return p

    fails_with(check.normalize(in_place), "in place")
    fails_with(check.normalize(lambda p: np.asarray(p, float) / np.asarray(p, float).sum(axis=0)), "p.sum()")


def test_bayes_update():
    assert check.bayes_update(discrete.update)
    assert check.bayes_update(discrete.update_readable)
    fails_with(check.bayes_update(lambda b, lik: np.asarray(b) * np.asarray(lik)), "divide by its sum")  # forgot eta
    fails_with(check.bayes_update(lambda b, lik: (np.asarray(b) + lik) / (np.asarray(b) + lik).sum()), "multiplies")
    fails_with(check.bayes_update(lambda b, lik: np.asarray(lik) / np.sum(lik)), "ignored the prior")


def test_histogram_checks():
    assert check.histogram_sense(histogram.sense)
    assert check.histogram_sense(histogram.sense_readable)
    swapped = check.histogram_sense(lambda b, w, m, h, mi: histogram.sense(b, w, m, mi, h))
    fails_with(swapped, "swapped")
    assert not any("PRIOR" in h for h in swapped.hints), swapped   # one mistake, one (right) hint
    fails_with(check.histogram_sense(lambda b, w, m, h, mi: histogram.sense(np.full_like(b, 1 / b.size), w, m, h, mi)),
               "PRIOR")
    assert check.histogram_move(lambda b, s, f: histogram.move(b, s, fill=f))
    fails_with(check.histogram_move(lambda b, s, f: np.roll(b, s, axis=(0, 1))), "wraps around")
    fails_with(check.histogram_move(lambda b, s, f: histogram.move(b, (-s[0], -s[1]), fill=f)), "opposite way")


# ------------------------------------------------------------------ motion
def test_sample_odometry_reference_passes():
    assert check.sample_odometry(motion.sample_odometry)
    assert check.sample_odometry(lambda p, u, a, rng: motion.sample_odometry(p, u, a, rng, sign=+1))


def _sampler(var_is_std=False, degrees=False, wrap=True, spot_rule=True, wrap_controls=True):
    def fn(poses, u, alphas, rng):
        a1, a2, a3, a4 = alphas
        (x0, y0, t0), (x1, y1, t1) = u
        w = wrap_angle if wrap_controls else (lambda a: a)
        trans = math.hypot(x1 - x0, y1 - y0)
        rot1 = w(math.atan2(y1 - y0, x1 - x0) - t0) if (trans > 1e-9 or not spot_rule) else 0.0
        rot2 = w(t1 - t0 - rot1)
        if degrees:
            rot1, rot2 = math.degrees(rot1), math.degrees(rot2)
        v1 = a1 * rot1**2 + a2 * trans**2
        vt = a3 * trans**2 + a4 * (rot1**2 + rot2**2)
        v2 = a1 * rot2**2 + a2 * trans**2
        s = (lambda v: v) if var_is_std else math.sqrt
        n = len(poses)
        r1 = rot1 - rng.normal(0, s(v1), n) if v1 > 0 else np.full(n, rot1)
        tr = trans - rng.normal(0, s(vt), n) if vt > 0 else np.full(n, trans)
        r2 = rot2 - rng.normal(0, s(v2), n) if v2 > 0 else np.full(n, rot2)
        x = poses[:, 0] + tr * np.cos(poses[:, 2] + r1)
        y = poses[:, 1] + tr * np.sin(poses[:, 2] + r1)
        th = poses[:, 2] + r1 + r2
        return np.column_stack([x, y, wrap_angle(th) if wrap else th])

    return fn


def test_sample_odometry_mistakes():
    assert check.sample_odometry(_sampler())  # a student's correct loop-free version
    fails_with(check.sample_odometry(_sampler(var_is_std=True)), "VARIANCE")
    fails_with(check.sample_odometry(_sampler(degrees=True)), "radians")
    fails_with(check.sample_odometry(_sampler(wrap=False)), "wrap")
    # the homework erratum: atan2(0, 0) - theta as rot1 of a turn on the spot
    no_spot = check.sample_odometry(_sampler(spot_rule=False))
    fails_with(no_spot, "rot1 = 0")
    assert [v.name for v in no_spot.failures] == ["a turn on the spot (no translation): samples have the model's "
                                                  "mean and covariance"], no_spot
    # rot1 of a backwards move left unwrapped (3.30 instead of -2.98): the variances are off
    fails_with(check.sample_odometry(_sampler(wrap_controls=False)), "BEFORE computing the noise")

    def global_rng(p, u, a, rng):
        return _sampler()(p, u, a, np.random.default_rng())

    fails_with(check.sample_odometry(global_rng), "rng.normal")


def _prob(a, var):
    return math.exp(-0.5 * a * a / var) / math.sqrt(2 * math.pi * var)


def _pdf(jacobian=True, normaliser=True, wrap=True, wrap_controls=True):
    def fn(pose, u, prev, alphas):
        a1, a2, a3, a4 = alphas
        (x0, y0, t0), (x1, y1, t1) = u
        w = wrap_angle if wrap else (lambda a: a)
        wc = w if wrap_controls else (lambda a: a)
        rot1 = wc(math.atan2(y1 - y0, x1 - x0) - t0)
        trans = math.hypot(x1 - x0, y1 - y0)
        rot2 = wc(t1 - t0 - rot1)
        x, y, t = pose
        xp, yp, tp = prev
        rot1h = w(math.atan2(y - yp, x - xp) - tp)
        transh = math.hypot(x - xp, y - yp)
        rot2h = w(t - tp - rot1h)
        prob = _prob if normaliser else (lambda a, v: math.exp(-0.5 * a * a / v))
        p = (prob(w(rot1 - rot1h), a1 * rot1**2 + a2 * trans**2)
             * prob(trans - transh, a3 * trans**2 + a4 * (rot1**2 + rot2**2))
             * prob(w(rot2 - rot2h), a1 * rot2**2 + a2 * trans**2))
        return p / transh if jacobian else p

    return fn


def test_odometry_pdf():
    assert check.odometry_pdf(lambda p, u, q, a: motion.odometry_pdf(p, u, q, a))
    assert check.odometry_pdf(_pdf())
    fails_with(check.odometry_pdf(_pdf(jacobian=False)), "divide by the translation")
    fails_with(check.odometry_pdf(_pdf(normaliser=False)), "normaliser")
    fails_with(check.odometry_pdf(_pdf(wrap=False)), "wrap")
    # code that does wrap but has another mistake is not told to wrap
    no_jac = check.odometry_pdf(_pdf(jacobian=False))
    assert not any("wrap every angle" in h for h in no_jac.hints), no_jac
    assert "fix that first" in " ".join(no_jac.hints)
    # measured rot1 of a backwards move left unwrapped: its variance a1 * rot1**2 is off
    back = check.odometry_pdf(_pdf(wrap_controls=False))
    fails_with(back, "measured AND the hypothesised")
    assert [v.name for v in back.failures] == ["a move backwards (rot1 near pi)"], back


# ------------------------------------------------------------------ sensors
def _beam(normalise=True, mass_only=False, beyond_zero=False):
    """A student's beam model; the max-range convention of chapter 5 unless told otherwise."""
    def fn(z, z_exp, prm):
        zmax, s, lam = prm["max_range"], prm["sigma_hit"], prm["lambda_short"]
        if z > zmax and beyond_zero:
            return 0.0
        if z >= zmax and mass_only:
            return prm["z_max"]
        z = min(z, zmax)
        hit = math.exp(-0.5 * ((z - z_exp) / s) ** 2) / (s * math.sqrt(2 * math.pi))
        if normalise:
            mass = 0.5 * (math.erf((zmax - z_exp) / (s * math.sqrt(2))) - math.erf(-z_exp / (s * math.sqrt(2))))
            hit /= mass
        short = lam * math.exp(-lam * z) if z <= z_exp else 0.0
        if normalise and z <= z_exp:
            short /= 1 - math.exp(-lam * z_exp)
        rest = prm["z_max"] if z >= zmax else prm["z_rand"] / zmax
        return prm["z_hit"] * hit + prm["z_short"] * short + rest

    return fn


def test_beam_model():
    assert check.beam_model(_beam())
    fails_with(check.beam_model(_beam(normalise=False)), "normalised density")
    # the homework erratum: the point mass alone at a max-range reading
    mass_only = check.beam_model(_beam(mass_only=True))
    fails_with(mass_only, "point mass z_max alone")
    assert [v.name for v in mass_only.failures] == ["a reading at max range when max range is expected (open space)"]
    beyond = check.beam_model(_beam(beyond_zero=True))
    fails_with(beyond, "no return")
    assert [v.name for v in beyond.failures] == ["a reading beyond max range counts as max range"]


def _beam_model_like_check():
    from localize import maps, sensors

    prm = check.BEAM_PARAMS
    return prm, sensors.BeamModel(maps.office(), prm["max_range"], z_hit=prm["z_hit"], z_short=prm["z_short"],
                                  z_max=prm["z_max"], z_rand=prm["z_rand"], sigma_hit=prm["sigma_hit"],
                                  lambda_short=prm["lambda_short"])


def test_beam_oracle_matches_localize_sensors():
    prm, model = _beam_model_like_check()
    z = np.array([0.2, 1.0, 3.9, 4.0, 4.5, 9.0, 10.0, 12.0])
    for z_exp in (4.0, 9.9, 10.0):
        ze = np.full_like(z, z_exp)
        np.testing.assert_allclose(model.pdf(z, ze), check._beam_ref(z, ze, prm), rtol=1e-9)
        # the fast path takes readings already clipped to max_range (as log_likelihood_expected passes them)
        np.testing.assert_allclose(np.log(model.pdf(z, ze)),
                                   model.beam_log_pdf(np.minimum(z, prm["max_range"]), ze[None, :])[0], rtol=1e-6)


def test_max_range_convention_is_density_plus_mass():
    """One convention at z = max_range (chapter 5): the continuous densities there PLUS the point mass z_max."""
    prm, model = _beam_model_like_check()
    zmax = prm["max_range"]
    c = model.components(zmax, zmax)
    assert float(c["p_max"]) == 1.0 and float(c["p_rand"]) == 0.0
    hit = 1 / (prm["sigma_hit"] * math.sqrt(2 * math.pi)) / 0.5       # half the Gaussian lies inside [0, zmax]
    short = prm["lambda_short"] * math.exp(-prm["lambda_short"] * zmax) / (1 - math.exp(-prm["lambda_short"] * zmax))
    want = prm["z_hit"] * hit + prm["z_short"] * short + prm["z_max"]
    assert float(model.pdf(zmax, zmax)) == pytest.approx(want, rel=1e-12)
    assert float(check._beam_ref(np.array([zmax]), np.array([zmax]), prm)[0]) == pytest.approx(want, rel=1e-12)
    assert _beam()(zmax, zmax, dict(prm)) == pytest.approx(want, rel=1e-12)
    assert want == pytest.approx(2.84, abs=0.01)       # the value the issue quotes for the library
    # far from open space the max-range reading is (almost) the mass alone, and beyond max range is the same
    assert float(model.pdf(zmax, 4.0)) == pytest.approx(prm["z_max"], rel=1e-9)
    assert float(model.pdf(zmax + 3.0, 4.0)) == float(model.pdf(zmax, 4.0))


def _scan(mode):
    b = _beam()

    def fn(ranges, expected, prm):
        p = np.array([b(z, e, prm) for z, e in zip(ranges, expected)])
        if mode == "sum":
            return float(p.sum())
        return float(np.log(p).sum())

    return fn


def test_scan_log_likelihood():
    assert check.scan_log_likelihood(_scan("log"))
    fails_with(check.scan_log_likelihood(_scan("sum")), "sum their LOGS")


def test_scan_underflow_detected():
    b = _beam()

    def product_of_small(ranges, expected, prm):  # multiplies 180 densities scaled to cell probabilities
        p = np.array([b(z, e, prm) for z, e in zip(ranges, expected)]) * 1e-3
        return float(np.log(np.prod(p)) - len(p) * np.log(1e-3)) if np.prod(p) > 0 else float("-inf")

    with np.errstate(divide="ignore"):
        fails_with(check.scan_log_likelihood(product_of_small), "log")


# ------------------------------------------------------------------ resampling
@pytest.mark.parametrize("scheme", ["multinomial", "stratified", "systematic", "residual"])
def test_reference_resamplers_pass(scheme):
    assert check.resampler(getattr(resample, scheme), scheme=scheme, repeats=2000)


def test_loop_resamplers_pass():
    assert check.low_variance_sampler(resample.systematic_loop)


def _low_variance(off_by_one=False, wide_offset=False, no_guard=False):
    def fn(w, rng):
        n = len(w)
        r = rng.uniform(0, 1.0 if wide_offset else 1.0 / n)
        c = np.cumsum(w)
        if not no_guard:
            c[-1] = 1.0
        idx = np.empty(n, dtype=np.int64)
        i = 0
        for m in range(n):
            u = r + (m + 1 if off_by_one else m) / n
            while i < n - 1 and u > c[i]:
                i += 1
            if no_guard and u > c[i]:
                i += 1
            idx[m] = i
        return idx

    return fn


def test_low_variance_mistakes():
    assert check.low_variance_sampler(_low_variance())
    fails_with(check.low_variance_sampler(_low_variance(off_by_one=True)), "offsets")
    fails_with(check.low_variance_sampler(_low_variance(wide_offset=True)), "[0, 1/N)")
    fails_with(check.low_variance_sampler(_low_variance(no_guard=True)), "cumsum")


def _searchsorted_systematic(clip=True):
    def fn(w, rng):
        n = len(w)
        c = np.cumsum(w)
        c[-1] = 1.0
        idx = np.searchsorted(c, rng.uniform(0, 1.0 / n) + np.arange(n) / n, side="right")
        return np.minimum(idx, n - 1) if clip else idx

    return fn


def test_searchsorted_right_needs_a_clip():
    assert check.low_variance_sampler(_searchsorted_systematic())
    fails_with(check.low_variance_sampler(_searchsorted_systematic(clip=False)), "side='right'")


def test_filterpy_residual_is_caught_as_biased():
    from filterpy.monte_carlo import residual_resample

    fails_with(check.resampler(lambda w, rng: residual_resample(w), repeats=500), "N * w_i - floor")


def test_multinomial_is_not_low_variance():
    fails_with(check.resampler(resample.multinomial, scheme="systematic", repeats=500), "ONE random number")


def test_effective_sample_size():
    assert check.effective_sample_size(resample.effective_sample_size)
    fails_with(check.effective_sample_size(lambda w: float(np.sum(np.square(w)))), "reciprocal")
    fails_with(check.effective_sample_size(lambda w: 1.0 / float(np.sum(np.square(w)))), "before squaring")


# ------------------------------------------------------------------ MCL
def _mcl(log_space=True, resample_by_weight=True, move=True, weigh_first=False):
    def fn(particles, u, ranges, angles, motion_model, sensor, rng):
        ll = sensor(particles, ranges, angles) if weigh_first else None
        p = motion_model(particles, u, rng) if move else particles.copy()
        ll = sensor(p, ranges, angles) if ll is None else ll
        if log_space:
            w = np.exp(ll - ll.max())
        else:
            w = np.exp(ll)
        w = w / w.sum()
        if not resample_by_weight:
            return p[rng.integers(0, len(p), len(p))]
        idx = rng.choice(len(p), size=len(p), p=w)
        return p[idx]

    return fn


def test_mcl_step():
    assert check.mcl_step(_mcl())
    with np.errstate(invalid="ignore", divide="ignore"):
        fails_with(check.mcl_step(_mcl(log_space=False)), "log-sum-exp")
    fails_with(check.mcl_step(_mcl(resample_by_weight=False)), "proportional to w")
    fails_with(check.mcl_step(_mcl(move=False)), "motion(particles, u, rng)")
    before = check.mcl_step(_mcl(weigh_first=True))
    fails_with(before, "BEFORE moving")
    assert [v.name for v in before.failures] == ["weights the particles after moving them"], before


# ------------------------------------------------------------------ new exercises: preface, ch. 3, 8, 9, 10
def _world_to_cell(order="ij", rounding=np.floor, origin=True, as_int=True):
    def fn(points, org, res):
        rel = (np.asarray(points, float) - (org if origin else 0.0)) / res
        ij = rounding(rel[:, ::-1] if order == "ij" else rel)
        return ij.astype(int) if as_int else ij

    return fn


def test_world_to_cell():
    assert check.world_to_cell(_world_to_cell())
    fails_with(check.world_to_cell(_world_to_cell(order="ji")), "(column, row)")
    fails_with(check.world_to_cell(_world_to_cell(rounding=np.round)), "np.floor, not np.round")
    fails_with(check.world_to_cell(_world_to_cell(origin=False)), "subtract the origin")
    fails_with(check.world_to_cell(_world_to_cell(as_int=False)), ".astype(int)")


def _grid_update(roll=1, offsets=True, logs=True, prior=True):
    def fn(belief, expected, beam_bins, ranges, beam_pdf):
        k = belief.shape[0]
        ll = np.zeros(belief.shape)
        for b, z in zip(beam_bins, ranges):
            ll += np.log(beam_pdf(z, expected[(np.arange(k) + roll * (b if offsets else 0)) % k]))
        like = np.exp(ll - ll.max()) if logs else np.exp(ll)
        post = (belief if prior else 1.0) * like
        return post / post.sum()

    return fn


def test_grid_update():
    assert check.grid_update(_grid_update())
    fails_with(check.grid_update(_grid_update(roll=-1)), "wrong way")
    fails_with(check.grid_update(_grid_update(offsets=False)), "add the beam's offset")
    fails_with(check.grid_update(_grid_update(prior=False)), "ignored the prior")
    with np.errstate(all="ignore"):
        underflow = check.grid_update(_grid_update(logs=False))
    fails_with(underflow, "log-likelihoods")
    assert [v.name for v in underflow.failures] == ["360 beams do not underflow (work in log space)"]


def _map_image(flip=True, invert=False, use_negate=True, unknown=np.nan):
    def fn(image, negate):
        v = np.asarray(image, float)
        if invert:
            v = 255 - v
        p = v / 255 if (negate and use_negate) else (255 - v) / 255
        occ = np.full(p.shape, unknown)
        occ[p > 0.65] = 1.0
        occ[p < 0.196] = 0.0
        return np.flipud(occ) if flip else occ

    return fn


def test_map_image():
    assert check.map_image(_map_image())
    fails_with(check.map_image(_map_image(flip=False)), "np.flipud")
    fails_with(check.map_image(_map_image(invert=True)), "white means FREE")
    fails_with(check.map_image(_map_image(use_negate=False)), "ignored negate")
    fails_with(check.map_image(_map_image(unknown=0.5)), "UNKNOWN")


def _injection(normalised=False, upside_down=False, clip=True, swap_alphas=False):
    def fn(lik, w_slow, w_fast, a_slow, a_fast):
        lik = np.asarray(lik, float)
        if normalised:
            lik = lik / lik.sum()
        if swap_alphas:
            a_slow, a_fast = a_fast, a_slow
        w_avg = float(lik.mean())
        w_slow += a_slow * (w_avg - w_slow)
        w_fast += a_fast * (w_avg - w_fast)
        p = 1 - (w_slow / w_fast if upside_down else w_fast / w_slow)
        return w_slow, w_fast, max(0.0, p) if clip else p

    return fn


def test_injection():
    assert check.injection(_injection())
    with np.errstate(all="ignore"):
        fails_with(check.injection(_injection(normalised=True)), "NORMALISED weights")
    fails_with(check.injection(_injection(upside_down=True)), "upside down")
    fails_with(check.injection(_injection(clip=False)), "cannot be negative")
    fails_with(check.injection(_injection(swap_alphas=True)), "alpha_slow belongs to w_slow")


def test_injection_check_agrees_with_augmented_mcl():
    """The check's rule is the library's: MCL's averages after one update, in log space, match it."""
    from localize import mcl

    lik = np.array([0.02, 0.05, 0.08, 0.05])
    aug = mcl.Augmented(alpha_slow=0.05, alpha_fast=0.5)
    class Flat:
        def log_likelihood(self, poses, *z):
            return np.zeros(len(poses))

    f = mcl.MCL(np.zeros((4, 3)), lambda p, u, rng: p, Flat(), rng=np.random.default_rng(0), augmented=aug,
                sampler=lambda n, rng: np.zeros((n, 3)))
    f.status.log_w_slow = f.status.log_w_fast = math.log(0.5)
    f._update_averages(math.log(lik.mean()))
    ws, wf, p = _injection()(lik, 0.5, 0.5, 0.05, 0.5)
    assert math.exp(f.status.log_w_slow) == pytest.approx(ws) and math.exp(f.status.log_w_fast) == pytest.approx(wf)
    assert f.status.p_inject == pytest.approx(p)


def _ekf(wrap_innovation=True, inverse=True, update_cov=True, wrap_heading=True):
    from localize.ekf import landmark_jacobian, landmark_measurement

    def fn(mean, cov, z, m, q):
        h = landmark_jacobian(mean, m)
        s = h @ cov @ h.T + q
        k = cov @ h.T @ (np.linalg.inv(s) if inverse else s)
        y = z - landmark_measurement(mean, m)
        if wrap_innovation:
            y[1] = wrap_angle(y[1])
        mu = mean + k @ y
        if wrap_heading:
            mu[2] = wrap_angle(mu[2])
        return mu, (np.eye(3) - k @ h) @ cov if update_cov else cov

    return fn


def test_ekf_update():
    assert check.ekf_update(_ekf())
    fails_with(check.ekf_update(_ekf(wrap_innovation=False)), "innovation z - z_hat is not wrapped")
    fails_with(check.ekf_update(_ekf(inverse=False)), "instead of its inverse")
    fails_with(check.ekf_update(_ekf(update_cov=False)), "must shrink")
    fails_with(check.ekf_update(_ekf(wrap_heading=False)), "wrap the new heading")


def test_ekf_check_agrees_with_the_library_filter():
    from localize.ekf import EKFLocalizer

    f = EKFLocalizer(np.array([[5.0, -0.1]]), 0.2, 0.05, [0.0] * 6, mean=[0.0, 0.0, 3.12],
                     cov=np.diag([0.25, 0.25, 0.01]))
    f.update(np.array([[4.8, 3.05]]), ids=[0])
    mu, cov = _ekf()(np.array([0.0, 0.0, 3.12]), np.diag([0.25, 0.25, 0.01]), np.array([4.8, 3.05]),
                     np.array([5.0, -0.1]), np.diag([0.04, 0.0025]))
    np.testing.assert_allclose(f.mean[:2], mu[:2], atol=1e-9)
    assert abs(wrap_angle(f.mean[2] - mu[2])) < 1e-9
    np.testing.assert_allclose(f.cov, cov, atol=1e-9)


def test_every_failure_with_a_seen_value_shows_the_expected_one():
    """On failure a report puts the right answer next to the student's, for every check and mistake tested here."""
    reports = [
        check.normalize(lambda p: np.asarray(p, float)),
        check.bayes_update(lambda b, lik: np.asarray(b) * np.asarray(lik)),
        check.histogram_sense(lambda b, w, m, h, mi: histogram.sense(b, w, m, mi, h)),
        check.histogram_move(lambda b, s, f: np.roll(b, s, axis=(0, 1))),
        check.sample_odometry(_sampler(var_is_std=True)), check.sample_odometry(_sampler(spot_rule=False)),
        check.odometry_pdf(_pdf(jacobian=False)), check.odometry_pdf(_pdf(wrap=False)),
        check.beam_model(_beam(normalise=False)), check.beam_model(_beam(mass_only=True)),
        check.scan_log_likelihood(_scan("sum")),
        check.low_variance_sampler(_low_variance(wide_offset=True)),
        check.low_variance_sampler(_low_variance(no_guard=True)),
        check.effective_sample_size(lambda w: 1.0 / float(np.sum(np.square(w)))),
        check.mcl_step(_mcl(move=False)), check.mcl_step(_mcl(weigh_first=True)),
        check.world_to_cell(_world_to_cell(order="ji")), check.grid_update(_grid_update(roll=-1)),
        check.map_image(_map_image(flip=False)), check.injection(_injection(upside_down=True)),
        check.ekf_update(_ekf(inverse=False)),
    ]
    for r in reports:
        assert not r, r
        for v in r.failures:
            assert not v.detail or v.expected, f"{r.subject}: {v.name!r} shows {v.detail!r} without the expected value"
            assert "expected:" in str(r) or not v.detail


# ------------------------------------------------------------------ older code exercises: ch. 1, 8, 9, 10
def _predict_stop(mode="stop", mirror=False, sign=1, shift_first=False):
    def fn(belief, kernel, offset):
        belief = np.asarray(belief, float)
        kernel = np.asarray(kernel, float)[::-1] if mirror else np.asarray(kernel, float)
        offset = sign * offset
        n, c = belief.size, kernel.size // 2
        if mode == "wrap":
            return discrete.predict(belief, kernel, offset=offset)
        if shift_first:
            shifted = np.zeros(n)
            for src in range(n):
                shifted[min(max(src + offset, 0), n - 1)] += belief[src]
            belief, offset = shifted, 0
        out = np.zeros(n)
        for src in range(n):
            for m, p in enumerate(kernel):
                dst = src + offset + m - c
                if mode == "stop":
                    out[min(max(dst, 0), n - 1)] += belief[src] * p
                elif 0 <= dst < n:
                    out[dst] += belief[src] * p
        return out / out.sum() if mode == "renormalise" else out

    return fn


def test_predict_stop():
    assert check.predict_stop(_predict_stop())
    fails_with(check.predict_stop(_predict_stop(mode="wrap")), "wraps around")
    fails_with(check.predict_stop(_predict_stop(mode="lost")), "is lost")
    fails_with(check.predict_stop(_predict_stop(mode="renormalise")), "renormalising")
    fails_with(check.predict_stop(_predict_stop(shift_first=True)), "shifted first")
    fails_with(check.predict_stop(_predict_stop(mirror=True)), "mirrored")
    fails_with(check.predict_stop(_predict_stop(sign=-1)), "wrong way")

    def in_place(belief, kernel, offset):
        out = _predict_stop()(belief, kernel, offset)
        belief[:] = out
        return belief

    fails_with(check.predict_stop(in_place), "new array")


def test_predict_stop_matches_the_chapter_rule():
    """The check's reference is discrete.predict's bounded mode plus the lost mass put back on the end cells."""
    b = np.r_[np.zeros(7), 0.2, 0.3, 0.5]
    k = np.array([0.1, 0.8, 0.1])
    want = check._predict_stop_ref(b, k, 2)
    lost = discrete.predict(b, k, offset=2, mode="constant")
    np.testing.assert_allclose(want[:-1], lost[:-1], atol=1e-12)
    assert want[-1] == pytest.approx(1.0 - lost[:-1].sum())


def _kld(k_shift=0, only_on_new=False, use_n_min=True, lag=False, none_if_unmet=False):
    from localize.kld import bin_keys, kld_bound

    def fn(samples, bin_size, epsilon, delta, n_min):
        seen, n = set(), 0
        for key in bin_keys(samples, bin_size).tolist():
            n += 1
            new = key not in seen
            if not lag:
                seen.add(key)
            k = len(seen) + k_shift
            need = kld_bound(k, epsilon, delta) if k > 1 else 0.0
            seen.add(key)
            if only_on_new and not new:
                continue
            if n >= need and (n >= n_min or not use_n_min):
                return n
        return None if none_if_unmet else len(samples)

    return fn


def test_kld_loop():
    assert check.kld_loop(_kld())
    fails_with(check.kld_loop(_kld(k_shift=1)), "k - 1")
    fails_with(check.kld_loop(_kld(only_on_new=True)), "after every sample")
    fails_with(check.kld_loop(_kld(use_n_min=False)), "n >= n_min")
    fails_with(check.kld_loop(_kld(lag=True)), "BEFORE testing the rule")
    fails_with(check.kld_loop(_kld(none_if_unmet=True)), "one integer")


def test_kld_loop_accepts_the_library_loop():
    from localize.kld import kld_sample_size_loop

    assert check.kld_loop(kld_sample_size_loop)


def _xy_reader(reverse=True, mm=True, no_return=True, max_range=30.0, errors="format", line_base=1,
               skip_blank_numbering=False, reverse_angles=False):
    from pathlib import Path

    from localize import io

    def fn(path):
        times, odo, ranges = [], [], []
        lines = Path(path).read_text().splitlines()
        numbered = ([(k, s) for k, s in enumerate([s for s in lines if s.strip()], start=line_base)]
                    if skip_blank_numbering else list(enumerate(lines, start=line_base)))
        for n, line in numbered:
            tok = line.split()
            if not tok:
                continue
            if ranges and len(tok) != 5 + len(ranges[0]) and errors != "none":
                if errors == "format":
                    raise io.FormatError(path, n, "wrong field count")
                raise ValueError("wrong field count")
            if ranges and len(tok) != 5 + len(ranges[0]):
                continue
            v = np.array(tok[1:], dtype=float)
            times.append(v[0])
            odo.append(v[1:4])
            r = v[4:] / (1000.0 if mm else 1.0)
            r = r[::-1] if reverse else r
            ranges.append(np.where(r == 0, max_range, r) if no_return else r)
        angles = np.linspace(-np.pi / 2, np.pi / 2, len(ranges[0]))
        return io.LaserLog(times=times, odometry=odo, ranges=ranges, angles=angles[::-1] if reverse_angles else angles,
                           max_range=30.0 if max_range < 30 else max_range, source=str(path), format="xy")

    return fn


def test_xy_reader():
    assert check.xy_reader(_xy_reader())
    fails_with(check.xy_reader(_xy_reader(reverse=False)), "wrong angles")
    fails_with(check.xy_reader(_xy_reader(mm=False)), "millimetres")
    fails_with(check.xy_reader(_xy_reader(no_return=False)), "no return, not an obstacle")
    fails_with(check.xy_reader(_xy_reader(max_range=80.0)), "reaches 30 m")
    fails_with(check.xy_reader(_xy_reader(reverse=False, reverse_angles=True)), "reverse the file's beam order")
    fails_with(check.xy_reader(_xy_reader(errors="value")), "io.FormatError(path")
    fails_with(check.xy_reader(_xy_reader(errors="none")), "number of fields")
    fails_with(check.xy_reader(_xy_reader(line_base=0)), "count lines from 1")
    fails_with(check.xy_reader(_xy_reader(skip_blank_numbering=True)), "blank lines")


def _gate(wrap=True, with_q=True, euclid=False, sqrt=False, threshold=9.21, keep_inside=True):
    from localize.ekf import landmark_jacobian, landmark_measurement

    def fn(mean, cov, z, landmark, Q):
        h = landmark_jacobian(mean, landmark)
        s = h @ cov @ h.T + (Q if with_q else 0.0)
        y = np.asarray(z, float) - landmark_measurement(mean, landmark)
        if wrap:
            y[1] = wrap_angle(y[1])
        d2 = float(y @ y) if euclid else float(y @ np.linalg.solve(s, y))
        inside = (math.sqrt(d2) if sqrt else d2) <= threshold
        return inside if keep_inside else not inside

    return fn


def test_innovation_gate():
    assert check.innovation_gate(_gate())
    fails_with(check.innovation_gate(_gate(wrap=False)), "wrap the bearing innovation")
    fails_with(check.innovation_gate(_gate(with_q=False)), "without the sensor noise Q")
    fails_with(check.innovation_gate(_gate(euclid=True)), "Mahalanobis")
    fails_with(check.innovation_gate(_gate(sqrt=True)), "SQUARED")
    fails_with(check.innovation_gate(_gate(threshold=6.63)), "not 6.63")
    fails_with(check.innovation_gate(_gate(threshold=11.34)), "not 11.34")
    fails_with(check.innovation_gate(_gate(keep_inside=False)), "KEEP")


def test_new_checks_show_the_expected_value_next_to_the_students():
    reports = [check.predict_stop(_predict_stop(mode="lost")), check.kld_loop(_kld(k_shift=1)),
               check.xy_reader(_xy_reader(mm=False)), check.innovation_gate(_gate(wrap=False))]
    for r in reports:
        assert not r, r
        for v in r.failures:
            assert v.expected, f"{r.subject}: {v.name!r} shows {v.detail!r} without the expected value"
        assert "expected:" in str(r)


# ------------------------------------------------------------------ issue 40: classic mistakes the checks missed
def test_scan_log_likelihood_of_the_product_underflows_on_a_wrong_pose():
    """log(prod(p)) is right on a fitting scan but -inf where the product is below the smallest float."""
    b = _beam()

    def log_of_product(ranges, expected, prm):
        p = np.array([b(z, e, prm) for z, e in zip(ranges, expected)])
        with np.errstate(divide="ignore"):
            return float(np.log(np.prod(p)))

    r = check.scan_log_likelihood(log_of_product)
    fails_with(r, "you took the log of the product")
    assert [v.name for v in r.failures] == [
        "a scan at a wrong pose: finite, no underflow (log of the product = sum of the logs)"], r
    assert check.scan_log_likelihood(_scan("log"))


def _adaptive(always=False, never=False, keep_weights=False, threshold_arg=True):
    def fn(particles, weights, rng, threshold):
        w = np.asarray(weights, float) / np.sum(weights)
        thr = threshold if threshold_arg else 0.5
        if never or not (always or resample.effective_sample_size(w) < thr * len(w)):
            return particles, w
        idx = resample.systematic(w, rng)
        return particles[idx], (w[idx] / w[idx].sum() if keep_weights else np.full(len(w), 1.0 / len(w)))

    return fn


def test_resample_if_needed():
    assert check.resample_if_needed(_adaptive())
    always = check.resample_if_needed(_adaptive(always=True))
    fails_with(always, "resampling at every step")
    assert [v.name.split(" (")[0] for v in always.failures] == ["even weights", "threshold 0 never resamples"], always
    fails_with(check.resample_if_needed(_adaptive(never=True)), "resample now")
    fails_with(check.resample_if_needed(_adaptive(keep_weights=True)), "set every weight to 1/N")
    fails_with(check.resample_if_needed(_adaptive(threshold_arg=False)), "use the threshold argument")
    fails_with(check.resample_if_needed(lambda p, w, rng, t: p), "return the pair")


def _ray(step=0.05, heading=True, leave="max"):
    """A student's ray marcher: walk along the beam in steps of ``step`` metres."""
    def fn(grid, pose, angle, max_range):
        x, y, th = pose
        a = th + angle if heading else angle
        d = 0.0
        while d < max_range:
            px, py = x + d * np.cos(a), y + d * np.sin(a)
            if not grid.contains(np.array([px, py])):
                return max_range if leave == "max" else d
            i, j = grid.world_to_cell(np.array([px, py]))
            if grid.obstacles[i, j]:
                return d
            d += step
        return max_range

    return fn


def test_ray_cast():
    from localize.raycast import cast_ray

    assert check.ray_cast(lambda g, p, a, m: cast_ray(g, p[0], p[1], p[2] + a, m))   # the exact cell walker
    assert check.ray_cast(_ray(step=0.05))                   # half a cell: within one cell of the exact range
    thin = check.ray_cast(_ray(step=0.15))                   # a step longer than a cell jumps over thin walls
    fails_with(thin, "went through the wall one cell thick")
    assert [v.name for v in thin.failures] == ["ranges to a one-cell wall, within one cell of the exact range"], thin
    fails_with(check.ray_cast(_ray(heading=False)), "theta + angle")
    fails_with(check.ray_cast(_ray(leave="edge")), "leaves the map")


def test_world_to_cell_truncation_left_of_the_origin():
    trunc = check.world_to_cell(_world_to_cell(rounding=np.trunc))      # astype(int) of (p - origin) / r
    fails_with(trunc, "truncates toward zero")
    assert len(trunc.failures) == 1, trunc                              # right everywhere inside the map


def test_np_roll_the_wrong_way_says_so():
    fails_with(check.histogram_move(lambda b, s, f: np.roll(b, (-s[0], -s[1]), axis=(0, 1))), "moved the wrong way")
    fails_with(check.predict_stop(lambda b, k, off: discrete.predict(b, k, offset=-off)), "moved the wrong way")


def test_sample_odometry_shared_noise_and_variance_as_std():
    def shared(poses, u, alphas, rng):                      # one noise draw for all particles
        one = motion.sample_odometry(poses[:1], u, alphas, rng)
        return np.repeat(one, len(poses), axis=0) + np.c_[poses[:, :2] - poses[:1, :2], np.zeros(len(poses))]

    fails_with(check.sample_odometry(shared), "same noise (zero spread)")
    as_std = check.sample_odometry(_sampler(var_is_std=True))
    # every motion case, the backwards one too, names the mistake (not "wrap the angles")
    assert len(as_std.failures) == 3 and all("as a standard deviation" in v.hint for v in as_std.failures), as_std
