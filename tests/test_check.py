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
    fails_with(check.histogram_sense(lambda b, w, m, h, mi: histogram.sense(b, w, m, mi, h)), "swapped")
    fails_with(check.histogram_sense(lambda b, w, m, h, mi: histogram.sense(np.full_like(b, 1 / b.size), w, m, h, mi)),
               "PRIOR")
    assert check.histogram_move(lambda b, s, f: histogram.move(b, s, fill=f))
    fails_with(check.histogram_move(lambda b, s, f: np.roll(b, s, axis=(0, 1))), "wraps around")
    fails_with(check.histogram_move(lambda b, s, f: histogram.move(b, (-s[0], -s[1]), fill=f)), "opposite way")


# ------------------------------------------------------------------ motion
def test_sample_odometry_reference_passes():
    assert check.sample_odometry(motion.sample_odometry)
    assert check.sample_odometry(lambda p, u, a, rng: motion.sample_odometry(p, u, a, rng, sign=+1))


def _sampler(var_is_std=False, degrees=False, wrap=True):
    def fn(poses, u, alphas, rng):
        a1, a2, a3, a4 = alphas
        (x0, y0, t0), (x1, y1, t1) = u
        rot1 = math.atan2(y1 - y0, x1 - x0) - t0
        trans = math.hypot(x1 - x0, y1 - y0)
        rot2 = t1 - t0 - rot1
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

    def global_rng(p, u, a, rng):
        return _sampler()(p, u, a, np.random.default_rng())

    fails_with(check.sample_odometry(global_rng), "rng.normal")


def _prob(a, var):
    return math.exp(-0.5 * a * a / var) / math.sqrt(2 * math.pi * var)


def _pdf(jacobian=True, normaliser=True, wrap=True):
    def fn(pose, u, prev, alphas):
        a1, a2, a3, a4 = alphas
        (x0, y0, t0), (x1, y1, t1) = u
        w = wrap_angle if wrap else (lambda a: a)
        rot1 = w(math.atan2(y1 - y0, x1 - x0) - t0)
        trans = math.hypot(x1 - x0, y1 - y0)
        rot2 = w(t1 - t0 - rot1)
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


# ------------------------------------------------------------------ sensors
def _beam(normalise=True):
    def fn(z, z_exp, prm):
        zmax, s, lam = prm["max_range"], prm["sigma_hit"], prm["lambda_short"]
        if z >= zmax:
            return prm["z_max"]
        hit = math.exp(-0.5 * ((z - z_exp) / s) ** 2) / (s * math.sqrt(2 * math.pi))
        if normalise:
            mass = 0.5 * (math.erf((zmax - z_exp) / (s * math.sqrt(2))) - math.erf(-z_exp / (s * math.sqrt(2))))
            hit /= mass
        short = lam * math.exp(-lam * z) if z <= z_exp else 0.0
        if normalise and z <= z_exp:
            short /= 1 - math.exp(-lam * z_exp)
        return prm["z_hit"] * hit + prm["z_short"] * short + prm["z_rand"] / zmax

    return fn


def test_beam_model():
    assert check.beam_model(_beam())
    fails_with(check.beam_model(_beam(normalise=False)), "normalised density")


def test_beam_oracle_matches_localize_sensors():
    sensors = pytest.importorskip("localize.sensors")
    if not hasattr(sensors, "BeamModel"):
        pytest.skip("localize.sensors.BeamModel not available")
    from localize import maps

    prm = check.BEAM_PARAMS
    try:
        model = sensors.BeamModel(maps.office(), prm["max_range"], z_hit=prm["z_hit"], z_short=prm["z_short"],
                                  z_max=prm["z_max"], z_rand=prm["z_rand"], sigma_hit=prm["sigma_hit"],
                                  lambda_short=prm["lambda_short"])
    except TypeError as err:
        pytest.skip(f"BeamModel signature differs: {err}")
    z = np.array([0.2, 1.0, 3.9, 4.0, 4.5, 9.0, 10.0])
    np.testing.assert_allclose(model.pdf(z, np.full_like(z, 4.0)), check._beam_ref(z, np.full_like(z, 4.0), prm),
                               rtol=1e-9)


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
def _mcl(log_space=True, resample_by_weight=True, move=True):
    def fn(particles, u, ranges, angles, motion_model, sensor, rng):
        p = motion_model(particles, u, rng) if move else particles.copy()
        ll = sensor(p, ranges, angles)
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
