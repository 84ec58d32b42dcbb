"""Self-checks for exercises and homework: test *your* implementation like a patient TA.

Each ``check.<name>(fn)`` takes a function you wrote, runs it on cases with
known answers, and returns a :class:`Report`. The report is truthy when every
property holds, prints one line per property (``PASS`` / ``FAIL``) and, for
each failure, a hint that names the usual mistake behind it. A check never
crashes on a wrong answer: exceptions, wrong types and wrong shapes become
failed properties.

    >>> from localize import check
    >>> def my_normalize(p):
    ...     p = np.asarray(p, dtype=float)
    ...     return p / p.sum()
    >>> report = check.normalize(my_normalize)
    >>> bool(report)
    True
    >>> print(report)                                   # doctest: +ELLIPSIS
    normalize: all 5 checks passed
      PASS  returns an array of the input's shape
    ...

Statistical checks (samplers, resamplers) use fixed seeds and tolerances
derived from the sample size (five standard errors or more), so a correct
implementation passes every time and the typical mistakes fail every time.
The reference implementations are the ones in :mod:`localize`; the checks
compare against them.

Signatures the checks expect (the same as :mod:`localize`'s own):

=========================  ====================================================
check                      your function
=========================  ====================================================
``normalize``              ``fn(p) -> array``
``bayes_update``           ``fn(belief, likelihood) -> array``
``histogram_sense``        ``fn(belief, world, measurement, p_hit, p_miss)``
``histogram_move``         ``fn(belief, step, fill)`` (a perfect move)
``sample_odometry``        ``fn(poses, u, alphas, rng) -> (N, 3)``
``odometry_pdf``           ``fn(pose, u, prev_pose, alphas) -> density``
``beam_model``             ``fn(z, z_expected, params) -> p(z | z_expected)``
``scan_log_likelihood``    ``fn(ranges, expected, params) -> float``
``resampler``              ``fn(weights, rng) -> indices``
``low_variance_sampler``   ``fn(weights, rng) -> indices``
``effective_sample_size``  ``fn(weights) -> float``
``mcl_step``               ``fn(particles, u, ranges, angles, motion, sensor, rng) -> (N, 3)``
=========================  ====================================================

``params`` for the beam model is a dict with keys ``z_hit, z_short, z_max,
z_rand, sigma_hit, lambda_short, max_range`` (see :data:`BEAM_PARAMS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Report",
    "Verdict",
    "BEAM_PARAMS",
    "normalize",
    "bayes_update",
    "histogram_sense",
    "histogram_move",
    "sample_odometry",
    "odometry_pdf",
    "beam_model",
    "scan_log_likelihood",
    "resampler",
    "low_variance_sampler",
    "effective_sample_size",
    "mcl_step",
]

#: Beam-model parameters used by :func:`beam_model` and :func:`scan_log_likelihood`.
BEAM_PARAMS: dict[str, float] = dict(
    z_hit=0.7, z_short=0.1, z_max=0.05, z_rand=0.15, sigma_hit=0.2, lambda_short=0.5, max_range=10.0
)


# ---------------------------------------------------------------------------- reports
@dataclass
class Verdict:
    """One checked property: its name, whether it held, what was seen and a hint."""

    name: str
    passed: bool
    detail: str = ""
    hint: str = ""


@dataclass
class Report:
    """The outcome of a check: a list of :class:`Verdict`, truthy when all passed.

    ``print(report)`` gives one line per property and a hint for each failure;
    ``report.failures`` lists the failed verdicts; ``report.hints`` their hints.
    """

    subject: str
    verdicts: list[Verdict] = field(default_factory=list)

    def add(self, name: str, passed: bool, detail: str = "", hint: str = "") -> bool:
        self.verdicts.append(Verdict(name, bool(passed), detail, "" if passed else hint))
        return bool(passed)

    @property
    def passed(self) -> bool:
        return bool(self.verdicts) and all(v.passed for v in self.verdicts)

    def __bool__(self) -> bool:
        return self.passed

    @property
    def failures(self) -> list[Verdict]:
        return [v for v in self.verdicts if not v.passed]

    @property
    def hints(self) -> list[str]:
        return [v.hint for v in self.failures if v.hint]

    def __str__(self) -> str:
        n = len(self.verdicts)
        bad = len(self.failures)
        head = (f"{self.subject}: all {n} checks passed" if self.passed
                else f"{self.subject}: {bad} of {n} checks FAILED")
        lines = [head]
        for v in self.verdicts:
            lines.append(f"  {'PASS' if v.passed else 'FAIL'}  {v.name}")
            if not v.passed:
                if v.detail:
                    lines.append(f"        seen: {v.detail}")
                if v.hint:
                    lines.append(f"        hint: {v.hint}")
        return "\n".join(lines)

    __repr__ = __str__


class _Stop(Exception):
    """Raised inside a check when a failure makes the remaining properties meaningless."""


def _call(report: Report, name: str, fn: Callable, *args: Any, _hint: str = "", **kwargs: Any) -> Any:
    """Call the student's function; an exception becomes a failed verdict and stops the check."""
    try:
        with np.errstate(all="ignore"):
            return fn(*args, **kwargs)
    except NotImplementedError:
        report.add(name, False, "your function raised NotImplementedError",
                   "replace `raise NotImplementedError` with your implementation")
    except Exception as err:  # noqa: BLE001 - any student error becomes a verdict
        report.add(name, False, f"your function raised {type(err).__name__}: {err}",
                   _hint or "run your function on the same input in a cell of its own and read the traceback")
    raise _Stop


def _array(report: Report, name: str, value: Any, shape: tuple | None = None,
           integer: bool = False) -> NDArray:
    """Convert a returned value to an array, failing the check on a wrong type or shape."""
    if value is None:
        report.add(name, False, "your function returned None", "did you forget the `return` statement?")
        raise _Stop
    try:
        a = np.asarray(value, dtype=np.int64 if integer and _is_intlike(value) else float)
    except (TypeError, ValueError):
        report.add(name, False, f"returned {type(value).__name__} {str(value)[:60]!r}",
                   "return a NumPy array (np.asarray(...)) of numbers")
        raise _Stop from None
    if a.dtype == object:
        report.add(name, False, "returned a ragged or object array", "return a NumPy array of numbers")
        raise _Stop
    if shape is not None and a.shape != tuple(shape):
        report.add(name, False, f"returned shape {a.shape}, expected {tuple(shape)}",
                   "keep one entry per input element (check which axis you sum or index over)")
        raise _Stop
    return a


def _is_intlike(value: Any) -> bool:
    try:
        a = np.asarray(value)
    except Exception:  # noqa: BLE001
        return False
    return a.dtype.kind in "iub" or (a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.round(a)))


def _run(subject: str, body: Callable[[Report], None]) -> Report:
    report = Report(subject)
    try:
        body(report)
    except _Stop:
        pass
    return report


def _fixed(value: Any) -> str:
    return np.array2string(np.asarray(value, dtype=float), precision=4, suppress_small=True, max_line_width=100)


# ---------------------------------------------------------------------------- discrete filters
def normalize(fn: Callable) -> Report:
    """Check ``fn(p)`` scales non-negative numbers to sum to one, without changing ``p``."""

    def body(r: Report) -> None:
        p = np.array([1.0, 2.0, 3.0, 4.0])
        kept = p.copy()
        out = _array(r, "returns an array of the input's shape", _call(r, "runs on [1, 2, 3, 4]", fn, p), p.shape)
        r.add("returns an array of the input's shape", True)
        total = float(np.sum(out))
        r.add("the result sums to one", abs(total - 1.0) < 1e-9, f"sum = {total:.6g}",
              "you returned the input unchanged: divide by the sum" if np.allclose(out, kept)
              else "divide every entry by the sum of all entries (eta = 1 / sum)")
        r.add("the result is proportional to the input", np.allclose(out * kept.sum(), kept, rtol=1e-9),
              f"got {_fixed(out)}, expected {_fixed(kept / kept.sum())}",
              "each entry must become p_i / sum(p): no softmax, no subtracting the mean")
        r.add("the input array is left unchanged", np.array_equal(p, kept), f"input became {_fixed(p)}",
              "return p / p.sum() instead of dividing in place with p /= p.sum()")
        q = np.arange(1.0, 7.0).reshape(2, 3)
        out2 = _array(r, "works on a 2-D belief (sums over all cells)", _call(r, "runs on a 2-D array", fn, q),
                      q.shape)
        r.add("works on a 2-D belief (sums over all cells)", np.allclose(out2, q / q.sum(), rtol=1e-9),
              f"got {_fixed(out2)}",
              "sum over all cells with p.sum(), not along one axis (p.sum(axis=0))")

    return _run("normalize", body)


def bayes_update(fn: Callable) -> Report:
    """Check ``fn(belief, likelihood)`` computes Bayes rule ``eta * likelihood * belief``."""
    from . import discrete, maps

    def body(r: Report) -> None:
        world = maps.hallway(10, doors=(0, 1, 8))
        prior = np.array([0.05, 0.05, 0.1, 0.2, 0.2, 0.1, 0.1, 0.1, 0.05, 0.05])
        lik = np.where(world == 1, 0.6, 0.2)
        expected = discrete.update(prior, lik)
        keep_p, keep_l = prior.copy(), lik.copy()
        out = _array(r, "returns one probability per cell", _call(r, "runs on the hallway", fn, prior, lik),
                     prior.shape)
        r.add("returns one probability per cell", True)
        r.add("the posterior sums to one", abs(float(out.sum()) - 1.0) < 1e-9, f"sum = {float(out.sum()):.6g}",
              "after multiplying, divide by the sum (the normaliser eta of Bayes rule)")
        prod = prior * lik
        add = prior + lik
        ok = np.allclose(out, expected, rtol=1e-8, atol=1e-12)
        if ok:
            hint = ""
        elif np.allclose(out / out.sum(), add / add.sum()):
            hint = "you added the likelihood to the belief: Bayes rule multiplies them"
        elif np.allclose(out, prod):
            hint = "the product is right but not normalised: divide by its sum"
        elif np.allclose(out, lik / lik.sum()):
            hint = "you ignored the prior belief: multiply the likelihood by the belief"
        else:
            hint = "posterior(x) = likelihood(x) * belief(x) / sum over x of the same product"
        r.add("the posterior is eta * likelihood * belief", ok, f"got {_fixed(out)}, expected {_fixed(expected)}",
              hint)
        r.add("the inputs are left unchanged", np.array_equal(prior, keep_p) and np.array_equal(lik, keep_l),
              "", "compute a new array instead of modifying belief or likelihood in place")

    return _run("bayes_update", body)


def _tile_world() -> NDArray:
    return np.array([list("GGGGG"), list("GRRGG"), list("GGBGG"), list("GGGGG")])


def histogram_sense(fn: Callable) -> Report:
    """Check ``fn(belief, world, measurement, p_hit, p_miss)`` against :func:`localize.histogram.sense`."""
    from . import histogram

    def body(r: Report) -> None:
        world = _tile_world()
        prior = np.full(world.shape, 1.0 / world.size)
        expected = histogram.sense(prior, world, "R", 0.85, 0.15)
        out = _array(r, "returns a belief of the world's shape",
                     _call(r, "runs on a 4 x 5 tile world", fn, prior.copy(), world, "R", 0.85, 0.15), world.shape)
        r.add("returns a belief of the world's shape", True)
        r.add("the belief sums to one", abs(float(out.sum()) - 1.0) < 1e-9, f"sum = {float(out.sum()):.6g}",
              "normalise after multiplying by p_hit / p_miss")
        swapped = histogram.sense(prior, world, "R", 0.15, 0.85)
        ok = np.allclose(out, expected, rtol=1e-8)
        hint = ("you swapped p_hit and p_miss: tiles whose colour MATCHES the measurement get p_hit"
                if np.allclose(out, swapped, rtol=1e-8)
                else "multiply by p_hit where world == measurement, by p_miss elsewhere, then normalise")
        r.add("matching tiles gain, others lose (Bayes rule)", ok, f"got {_fixed(out)}", hint)
        prior2 = np.zeros(world.shape)
        prior2[1, 1] = prior2[2, 2] = 0.5
        exp2 = histogram.sense(prior2, world, "B", 0.85, 0.15)
        out2 = _array(r, "uses the prior belief", _call(r, "runs on a peaked prior", fn, prior2, world, "B", 0.85,
                                                        0.15), world.shape)
        r.add("uses the prior belief", np.allclose(out2, exp2, rtol=1e-8), f"got {_fixed(out2)}",
              "multiply the PRIOR by the likelihood; do not start from a uniform belief")

    return _run("histogram_sense", body)


def histogram_move(fn: Callable) -> Report:
    """Check a perfect move ``fn(belief, step, fill)`` against :func:`localize.histogram.move`.

    ``step`` is ``(drow, dcol)`` with row 0 at the top: ``(0, -1)`` is one tile
    to the left. Tiles uncovered at the edge receive ``fill`` before normalising.
    """
    from . import histogram

    def body(r: Report) -> None:
        rng = np.random.default_rng(3)
        b = rng.random((4, 5))
        b /= b.sum()
        for step in [(0, -1), (0, 1), (-1, 0), (1, 0)]:
            exp = histogram.move(b, step, fill=0.001)
            name = f"a perfect move by {step} shifts the belief"
            out = _array(r, name, _call(r, name, fn, b.copy(), step, 0.001), b.shape)
            ok = np.allclose(out, exp, rtol=1e-8)
            if ok:
                r.add(name, True)
                continue
            wrap = histogram.move(b, step, mode="wrap")
            opposite = histogram.move(b, (-step[0], -step[1]), fill=0.001)
            if np.allclose(out, wrap, rtol=1e-8):
                hint = "your world wraps around (np.roll); this world is bounded: fill the uncovered tiles"
            elif np.allclose(out, opposite, rtol=1e-8):
                hint = "you moved the belief the opposite way: the robot moving left moves its belief left"
            elif np.allclose(out.sum(), 1.0) is False:
                hint = "normalise after filling the uncovered tiles"
            else:
                hint = ("shift by the step (drow, dcol), put `fill` on the tiles uncovered at the edge, "
                        "then normalise")
            r.add(name, False, f"got {_fixed(out)}", hint)

    return _run("histogram_move", body)


# ---------------------------------------------------------------------------- motion
def sample_odometry(fn: Callable) -> Report:
    """Check ``fn(poses, u, alphas, rng)`` samples the odometry motion model (PR table 5.6).

    The distribution is compared with :func:`localize.motion.sample_odometry`
    (noise variances ``alpha1*rot1**2 + alpha2*trans**2`` etc.).
    """
    from . import motion
    from .geometry import angle_diff

    def body(r: Report) -> None:
        u = (np.array([1.0, 2.0, 0.3]), np.array([1.8, 2.9, 1.1]))
        start = np.array([[0.5, -0.5, 2.9], [3.0, 1.0, -2.0], [0.0, 0.0, 0.0]])
        exact = motion.sample_odometry(start, u, [0, 0, 0, 0], np.random.default_rng(0))
        name = "no noise (alphas = 0) reproduces the motion exactly"
        out = _array(r, name, _call(r, name, fn, start.copy(), u, np.zeros(4), np.random.default_rng(0)), (3, 3))
        dpos = np.abs(out[:, :2] - exact[:, :2]).max()
        dth = np.abs(angle_diff(out[:, 2], exact[:, 2])).max()
        ok = dpos < 1e-9 and dth < 1e-9
        if ok:
            hint = ""
        elif np.allclose(out[:, :2], exact[:, :2], atol=1e-6):
            hint = "positions are right but headings are not: theta' = theta + rot1 + rot2"
        else:
            hint = ("rot1 = atan2(y'-y, x'-x) - theta, trans = distance, rot2 = theta' - theta - rot1 "
                    "from the two odometry poses; angles are radians (no np.degrees / np.radians)")
        r.add(name, ok, f"max position error {dpos:.3g} m, heading error {dth:.3g} rad", hint)
        wrapped = np.all((out[:, 2] >= -np.pi) & (out[:, 2] < np.pi))
        r.add("headings are wrapped to [-pi, pi)", wrapped, f"headings {_fixed(out[:, 2])}",
              "wrap the new heading with localize.wrap_angle (or (a + pi) % (2 pi) - pi)")

        n = 40_000
        alphas = np.array([0.05, 0.01, 0.02, 0.05])
        name = "samples have the model's mean and covariance"
        got = _array(r, name, _call(r, name, fn, np.zeros((n, 3)), u, alphas, np.random.default_rng(1)), (n, 3))
        ref = motion.sample_odometry(np.zeros((400_000, 3)), u, alphas, np.random.default_rng(2))

        def feats(p):  # unwrap headings around the reference mean
            m = float(np.angle(np.exp(1j * ref[:, 2]).mean()))
            return np.column_stack([p[:, 0], p[:, 1], m + angle_diff(p[:, 2], m)])

        fg, fr = feats(got), feats(ref)
        sd = fr.std(axis=0)
        mean_err = np.abs(fg.mean(axis=0) - fr.mean(axis=0)) / (sd / math.sqrt(n))
        var_ratio = fg.var(axis=0) / fr.var(axis=0)
        # the sample variance has relative standard error sqrt(2/n) (plus the
        # kurtosis of a curved distribution): allow 8 of them
        var_tol = 8.0 * math.sqrt(2.0 / n) + 0.02
        ok_mean = bool(np.all(mean_err < 6.0))
        ok_var = bool(np.all(np.abs(var_ratio - 1.0) < var_tol))
        if ok_mean and ok_var:
            hint = ""
        elif np.all(var_ratio < 0.5):
            hint = ("the spread is far too small: alpha1*rot1**2 + alpha2*trans**2 is a VARIANCE; "
                    "pass its square root as the standard deviation")
        elif np.all(var_ratio > 2.0):
            hint = "the spread is too large: are you using the variance as a standard deviation the other way round?"
        else:
            hint = ("rot1 noise variance = a1*rot1**2 + a2*trans**2, trans: a3*trans**2 + a4*(rot1**2 + rot2**2), "
                    "rot2: a1*rot2**2 + a2*trans**2 (PR table 5.6)")
        r.add("samples have the model's mean", ok_mean, f"mean offsets in standard errors {_fixed(mean_err)}", hint)
        r.add("samples have the model's covariance", ok_var, f"variance ratios (yours / reference) {_fixed(var_ratio)}",
              hint)
        a = _array(r, "uses the rng it is given (reproducible)",
                   _call(r, "uses the rng it is given (reproducible)", fn, np.zeros((5, 3)), u, alphas,
                         np.random.default_rng(7)))
        b = _array(r, "uses the rng it is given (reproducible)",
                   _call(r, "uses the rng it is given (reproducible)", fn, np.zeros((5, 3)), u, alphas,
                         np.random.default_rng(7)))
        r.add("uses the rng it is given (reproducible)", np.array_equal(a, b), "",
              "draw noise with rng.normal(...) from the rng argument, not from numpy's global random functions")

    return _run("sample_odometry", body)


def odometry_pdf(fn: Callable) -> Report:
    """Check ``fn(pose, u, prev_pose, alphas)`` against :func:`localize.motion.odometry_pdf`.

    The reference is a density over ``(x, y, theta)``, so it carries the
    Jacobian factor ``1/trans`` that PR table 5.5 leaves out; the hint says so
    if that is the only difference.
    """
    from . import motion

    def body(r: Report) -> None:
        u = (np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.5, 0.6]))
        prev = np.array([2.0, 1.0, 0.4])
        alphas = np.array([0.05, 0.02, 0.05, 0.01])
        rng = np.random.default_rng(11)
        poses = motion.sample_odometry(np.tile(prev, (12, 1)), u, alphas, rng)
        ref = motion.odometry_pdf(poses, u, prev, alphas)
        vals = []
        for p in poses:
            v = _array(r, "returns a finite, non-negative density", _call(r, "runs on single poses", fn, p, u, prev,
                                                                        alphas))
            vals.append(float(np.reshape(v, -1)[0]) if v.size else np.nan)
        vals = np.array(vals)
        r.add("returns a finite, non-negative density", bool(np.all(np.isfinite(vals)) and np.all(vals >= 0)),
              f"values {_fixed(vals)}", "a density is exp(-e**2 / (2 var)) / sqrt(2 pi var): never negative or NaN")
        good = np.isclose(vals, ref, rtol=1e-5, atol=1e-12)
        ratio = vals / np.where(ref > 0, ref, np.nan)
        trans = np.hypot(*(poses[:, :2] - prev[:2]).T)
        if np.all(good):
            hint = ""
        elif np.allclose(ratio, trans, rtol=1e-3):
            hint = ("your density is over (rot1, trans, rot2) as in PR table 5.5; over (x, y, theta) divide by the "
                    "translation (the Jacobian of the change of variables)")
        elif np.allclose(ratio, ratio[0], rtol=1e-3):
            hint = (f"off by a constant factor {ratio[0]:.4g}: did you forget the Gaussian normaliser "
                    "1/sqrt(2 pi variance), or use a standard deviation where a variance belongs?")
        else:
            hint = ("prob(a, var) = exp(-a**2 / (2 var)) / sqrt(2 pi var) with var = a1*rot1**2 + a2*trans**2 ... "
                    "evaluated at the MEASURED motion; multiply the three and divide by the translation")
        r.add("matches the odometry density", bool(np.all(good)),
              f"ratio yours / reference {_fixed(ratio)}", hint)
        # a motion whose headings cross the +-pi seam
        prev2 = np.array([0.0, 0.0, 3.0])
        seam = motion.sample_odometry(np.tile(prev2, (6, 1)), u, alphas, np.random.default_rng(12))
        ref2 = motion.odometry_pdf(seam, u, prev2, alphas)
        vals2 = np.array([float(np.reshape(np.asarray(_call(r, "runs on single poses", fn, p, u, prev2, alphas),
                                                      float), -1)[0]) for p in seam])
        r.add("angle differences are wrapped", bool(np.allclose(vals2, ref2, rtol=1e-5, atol=1e-12)),
              f"got {_fixed(vals2)}, expected {_fixed(ref2)}",
              "wrap every angle difference (rot1_hat - rot1 etc.) to [-pi, pi) before the Gaussian")

    return _run("odometry_pdf", body)


# ---------------------------------------------------------------------------- sensors
def _beam_ref(z: NDArray, z_exp: NDArray, prm: dict) -> NDArray:
    """The beam mixture of PR section 6.3 with truncated, normalised components (the check's oracle)."""
    from scipy.special import erf

    zmax = prm["max_range"]
    s = prm["sigma_hit"]
    lam = prm["lambda_short"]
    z = np.asarray(z, float)
    ze = np.asarray(z_exp, float)
    inside = (z >= 0) & (z < zmax)
    norm_hit = 0.5 * (erf((zmax - ze) / (s * math.sqrt(2))) - erf((0 - ze) / (s * math.sqrt(2))))
    p_hit = np.where(inside, np.exp(-0.5 * ((z - ze) / s) ** 2) / (s * math.sqrt(2 * math.pi)) / norm_hit, 0.0)
    short_ok = inside & (z <= ze)
    p_short = np.where(short_ok, lam * np.exp(-lam * z) / (1 - np.exp(-lam * ze)), 0.0)
    p_max = (z >= zmax).astype(float)
    p_rand = np.where(inside, 1.0 / zmax, 0.0)
    return prm["z_hit"] * p_hit + prm["z_short"] * p_short + prm["z_max"] * p_max + prm["z_rand"] * p_rand


def beam_model(fn: Callable, params: dict | None = None) -> Report:
    """Check a beam-model density ``fn(z, z_expected, params)`` (PR section 6.3, table 6.1).

    Properties: agreement with the four-part mixture, and normalisation — the
    continuous part integrates over ``[0, max_range)`` to ``1 - z_max`` and the
    point mass at ``max_range`` carries ``z_max``.
    """
    prm = dict(BEAM_PARAMS if params is None else params)

    def body(r: Report) -> None:
        zmax = prm["max_range"]
        z_exp = 4.0
        zs = np.array([0.5, 2.0, 3.9, 4.0, 4.3, 7.0, 9.5, zmax])
        vals = np.array([float(np.reshape(_array(r, "returns a number per reading",
                                                 _call(r, "runs on single readings", fn, z, z_exp, dict(prm))), -1)[0])
                         for z in zs])
        r.add("returns a number per reading", bool(np.all(np.isfinite(vals))), f"values {_fixed(vals)}",
              "return a finite probability density for every reading")
        ref = _beam_ref(zs, np.full_like(zs, z_exp), prm)
        # normalisation by numerical integration over [0, zmax) (midpoint rule, 20000 cells)
        grid = (np.arange(20_000) + 0.5) * (zmax / 20_000)
        dens = np.array([float(np.reshape(np.asarray(fn(z, z_exp, dict(prm)), float), -1)[0]) for z in grid[::10]])
        integral = float(dens.sum() * zmax / 2_000)
        point = vals[-1]
        total = integral + point
        r.add("integrates to one (continuous part + max-range mass)", abs(total - 1.0) < 5e-3,
              f"integral over [0, max_range) = {integral:.4f}, mass at max_range = {point:.4f}, total {total:.4f}",
              "each component must be a normalised density: divide the Gaussian by its mass inside [0, max_range) "
              "and the exponential by 1 - exp(-lambda z*); the max-range reading is a point mass of weight z_max")
        ok = np.allclose(vals, ref, rtol=1e-3, atol=1e-9)
        r.add("matches the four-part mixture", ok, f"got {_fixed(vals)}, expected {_fixed(ref)}",
              "p = z_hit p_hit + z_short p_short + z_max p_max + z_rand p_rand; p_short is zero beyond the expected "
              "range, p_rand is 1/max_range below max_range")

    return _run("beam_model", body)


def scan_log_likelihood(fn: Callable, params: dict | None = None) -> Report:
    """Check ``fn(ranges, expected, params)`` returns the log-likelihood of a whole scan.

    Beams are independent given the pose, so the scan likelihood is the
    *product* of the beam densities and its log is the sum of their logs.
    """
    prm = dict(BEAM_PARAMS if params is None else params)

    def body(r: Report) -> None:
        rng = np.random.default_rng(5)
        expected = rng.uniform(1.0, 9.0, 180)
        ranges = np.clip(expected + rng.normal(0, 0.2, 180), 0.0, prm["max_range"])
        ref = float(np.log(_beam_ref(ranges, expected, prm)).sum())
        name = "returns the log of the product of beam densities"
        v = _array(r, name, _call(r, name, fn, ranges, expected, dict(prm)))
        val = float(np.reshape(v, -1)[0])
        probs = _beam_ref(ranges, expected, prm)
        if np.isclose(val, ref, rtol=1e-6):
            hint = ""
        elif np.isclose(val, probs.sum(), rtol=1e-6) or np.isclose(val, np.log(probs.sum()), rtol=1e-6):
            hint = ("you added the beam probabilities (a heuristic some reports use); independent beams multiply: "
                    "sum their LOGS")
        elif val == -np.inf or (np.isfinite(val) is False):
            hint = ("the product of 180 small numbers underflows to 0 and log(0) = -inf: add log-probabilities "
                    "instead of multiplying probabilities")
        else:
            hint = "log p(scan | pose) = sum over beams of log p(z_k | z_k*)"
        r.add(name, bool(np.isclose(val, ref, rtol=1e-6)), f"got {val:.6g}, expected {ref:.6g}", hint)
        r.add("stays finite for 180 beams (no underflow)", bool(np.isfinite(val)), f"got {val}",
              "work in log space: sum log-densities instead of taking the log of a product")
        shifted = float(np.reshape(np.asarray(fn(ranges, expected + 1.0, dict(prm)), float), -1)[0])
        r.add("a matching scan scores higher than a shifted one", bool(val > shifted),
              f"matching {val:.4g}, shifted by 1 m {shifted:.4g}",
              "a likelihood must reward agreement between measured and expected ranges")

    return _run("scan_log_likelihood", body)


# ---------------------------------------------------------------------------- resampling
_SCHEMES = ("multinomial", "stratified", "systematic", "residual")


class _EdgeRNG(np.random.Generator):
    """A generator whose uniform draws sit at the very top of their range; other methods are PCG64's.

    It reproduces the rare event in which a resampling pointer lands just
    below 1.0 — the case where a cumulative sum that rounds below one makes
    a resampler index past the end of the particle array.
    """

    _TOP = float(np.nextafter(1.0, 0.0))

    def __init__(self, seed: int = 0) -> None:
        super().__init__(np.random.PCG64(seed))

    def random(self, size=None, dtype=np.float64, out=None):
        return self._TOP if size is None else np.full(size, self._TOP)

    def uniform(self, low=0.0, high=1.0, size=None):
        lo, hi = np.asarray(low, float), np.asarray(high, float)
        v = lo + (hi - lo) * self._TOP
        if size is None:
            return float(v) if v.ndim == 0 else v
        return np.broadcast_to(v, size).copy()


def _indices(r: Report, name: str, fn: Callable, w: NDArray, rng: np.random.Generator) -> NDArray:
    idx = _array(r, name, _call(r, name, fn, w.copy(), rng), integer=True)
    if idx.shape != (len(w),):
        r.add(name, False, f"returned shape {idx.shape}, expected ({len(w)},)",
              "return N indices, one per new particle (not the new particles, not the counts)")
        raise _Stop
    if idx.dtype.kind not in "iu":
        r.add(name, False, f"returned values of type {idx.dtype}", "return whole-number indices (np.int64)")
        raise _Stop
    if idx.min() < 0 or idx.max() >= len(w):
        r.add(name, False, f"an index is out of range: min {idx.min()}, max {idx.max()} for N = {len(w)}",
              "indices run from 0 to N - 1; when the cumulative sum of the weights ends just below one, "
              "guard the last index (e.g. set cumsum[-1] = 1.0 or clip)")
        raise _Stop
    return idx


def resampler(fn: Callable, scheme: str | None = None, repeats: int = 4000) -> Report:
    """Check a resampler ``fn(weights, rng) -> indices``.

    Every scheme: N valid indices; unbiased (the mean offspring count of
    particle i over ``repeats`` runs is N * w_i within five standard errors);
    reproducible with the same rng; robust to a cumulative sum that rounds
    below one. With ``scheme`` given, also the variance signature of that
    scheme: systematic gives every particle floor(N w_i) or ceil(N w_i)
    copies; systematic, stratified and residual have lower offspring variance
    than multinomial.
    """
    if scheme is not None and scheme not in _SCHEMES:
        raise ValueError(f"scheme must be one of {_SCHEMES} or None; got {scheme!r}")
    from . import resample as ref

    def body(r: Report) -> None:
        w = np.array([0.30, 0.05, 0.15, 0.02, 0.18, 0.10, 0.12, 0.08])
        n = len(w)
        _indices(r, "returns N valid indices", fn, w, np.random.default_rng(0))
        r.add("returns N valid indices", True)
        counts = np.zeros((repeats, n))
        rng = np.random.default_rng(1)
        for k in range(repeats):
            counts[k] = np.bincount(_indices(r, "returns N valid indices", fn, w, rng), minlength=n)
        mean = counts.mean(axis=0)
        # multinomial has the largest offspring variance, N w (1 - w); use it as the bound
        se = np.sqrt(n * w * (1 - w) / repeats)
        z = np.abs(mean - n * w) / se
        unbiased = bool(np.all(z < 5.0))
        r.add("unbiased: mean offspring count is N * w_i", unbiased,
              f"mean counts {_fixed(mean)}, expected {_fixed(n * w)}",
              "every particle must be copied N * w_i times on average: check the offsets of your pointers "
              "(systematic: u_m = r + m / N with r ~ U[0, 1/N)); residual: draw the remainder from "
              "N * w_i - floor(N * w_i), not from w_i")
        a = _indices(r, "reproducible with the same rng", fn, w, np.random.default_rng(42))
        b = _indices(r, "reproducible with the same rng", fn, w, np.random.default_rng(42))
        r.add("reproducible with the same rng", np.array_equal(a, b), "",
              "draw random numbers from the rng argument, not from np.random")
        # cumulative sum that rounds to just below one (filterpy's resamplers index past the end
        # here): ten weights of 0.1 sum to 0.9999999999999999 in floating point, and a random
        # offset at the top of its range puts the last pointer at 1.0.
        w2 = np.full(10, 0.1)
        tail_ok = True
        for _ in range(20):
            try:
                idx = np.asarray(fn(w2.copy(), _EdgeRNG(3)))
            except Exception:  # noqa: BLE001
                tail_ok = False
                break
            if idx.shape != (10,) or idx.min() < 0 or idx.max() >= 10:
                tail_ok = False
                break
        r.add("never indexes past the end when the weights sum to slightly below one", tail_ok, "",
              "np.cumsum of ten weights 0.1 ends at 0.9999999999999999; set its last entry to 1.0 "
              "(or use np.searchsorted and clip) so a pointer near 1 still finds a particle")
        if scheme is None:
            return
        var = counts.var(axis=0)
        var_multi = n * w * (1 - w)
        if scheme == "systematic":
            lo, hi = np.floor(n * w), np.ceil(n * w)
            ok = bool(np.all((counts >= lo - 1e-9) & (counts <= hi + 1e-9)))
            r.add("low variance: every particle gets floor(N w_i) or ceil(N w_i) copies", ok,
                  f"count ranges seen {_fixed(counts.min(0))} .. {_fixed(counts.max(0))}",
                  "use ONE random number r in [0, 1/N) and N equally spaced pointers r + m/N "
                  "(m = 0 .. N-1); a pointer per draw, or r in [0, 1), breaks this")
        if scheme in ("systematic", "stratified", "residual"):
            ok = bool(var.sum() < 0.8 * var_multi.sum())
            r.add(f"{scheme} has lower offspring variance than multinomial", ok,
                  f"total variance {var.sum():.3f}, multinomial {var_multi.sum():.3f}",
                  f"{scheme} resampling must spread its pointers over [0, 1); independent uniform draws "
                  "give multinomial resampling")
        if scheme == "multinomial":
            ok = bool(abs(var.sum() / var_multi.sum() - 1.0) < 0.15)
            r.add("multinomial has offspring variance N w (1 - w)", ok,
                  f"total variance {var.sum():.3f}, expected {var_multi.sum():.3f}",
                  "draw N independent uniforms and find each one's particle in the cumulative sum")
        _ = ref  # the reference module documents the schemes

    return _run(f"resampler ({scheme or 'any scheme'})", body)


def low_variance_sampler(fn: Callable) -> Report:
    """Check the low-variance (systematic) sampler of PR table 4.4: ``fn(weights, rng) -> indices``."""
    rep = resampler(fn, scheme="systematic")
    rep.subject = "low_variance_sampler"
    return rep


def effective_sample_size(fn: Callable) -> Report:
    """Check ``fn(weights)`` returns ``1 / sum(w_i**2)`` for normalised weights (Kong, Liu and Wong 1994)."""

    def body(r: Report) -> None:
        cases = [(np.full(50, 1 / 50), 50.0, "equal weights give N"),
                 (np.eye(1, 20, 3).ravel(), 1.0, "one particle with all the weight gives 1")]
        w = np.array([0.5, 0.25, 0.125, 0.125])
        cases.append((w, 1.0 / float((w ** 2).sum()), "matches 1 / sum(w**2)"))
        for weights, expected, name in cases:
            v = _array(r, name, _call(r, name, fn, weights.copy()))
            val = float(np.reshape(v, -1)[0])
            hint = ("N_eff = 1 / sum(w_i**2) for normalised weights" if not np.isclose(val, 1 / expected)
                    else "you returned sum(w**2); N_eff is its reciprocal")
            r.add(name, bool(np.isclose(val, expected, rtol=1e-9)), f"got {val:.6g}, expected {expected:.6g}", hint)
        raw = w * 8.0
        name = "normalises unnormalised weights first"
        val = float(np.reshape(_array(r, name, _call(r, name, fn, raw.copy())), -1)[0])
        r.add(name, bool(np.isclose(val, 1.0 / float((w ** 2).sum()), rtol=1e-9)), f"got {val:.6g}",
              "divide the weights by their sum before squaring: N_eff = (sum w)**2 / sum(w**2)")

    return _run("effective_sample_size", body)


# ---------------------------------------------------------------------------- MCL
def mcl_step(fn: Callable) -> Report:
    """Check one MCL iteration ``fn(particles, u, ranges, angles, motion, sensor, rng) -> particles``.

    ``motion(particles, u, rng)`` samples the motion model; ``sensor(particles,
    ranges, angles)`` returns per-particle LOG-likelihoods. Your step must
    move every particle, weight it by its likelihood and resample.

    Properties: shape and finiteness; the particles follow the motion;
    the survivors are distributed in proportion to the likelihood (a
    statistical test); log-likelihoods of -1000 and below do not turn into
    0/0 = NaN (log-sum-exp); the rng argument is used.
    """
    from . import motion as mm

    def body(r: Report) -> None:
        n = 2000
        rng0 = np.random.default_rng(21)
        parts = np.column_stack([rng0.uniform(0, 10, n), rng0.uniform(0, 10, n), rng0.uniform(-np.pi, np.pi, n)])
        u = (np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.0]))

        def motion(p, uu, rng):
            return mm.sample_odometry(p, uu, [0.0, 0.0, 0.0, 0.0], rng)

        def flat(p, ranges, angles):
            return np.zeros(len(p))

        ranges, angles = np.array([1.0]), np.array([0.0])
        name = "returns (N, 3) finite particles"
        out = _array(r, name, _call(r, name, fn, parts.copy(), u, ranges, angles, motion, flat,
                                    np.random.default_rng(0)), (n, 3))
        r.add(name, bool(np.all(np.isfinite(out))), "", "no NaN: check your normalisation of the weights")
        moved = mm.sample_odometry(parts, u, [0, 0, 0, 0], np.random.default_rng(0))
        # with a flat likelihood every surviving particle is one of the moved ones
        on_moved = np.mean([np.any(np.all(np.isclose(o, moved), axis=1)) for o in out[:200]])
        r.add("particles are moved by the motion model", bool(on_moved > 0.99), f"{on_moved:.0%} of particles moved",
              "apply motion(particles, u, rng) to every particle before weighting")

        def sensor_right(p, ranges, angles):  # strongly prefers x > 5
            return np.where(p[:, 0] > 5.0, 0.0, np.log(0.25)) - 1500.0

        name = "resamples in proportion to the likelihood (log-sum-exp)"
        lse_hint = ("exp(-1500) underflows to 0 for every particle and 0/0 gives NaN: subtract the largest "
                    "log-likelihood before exponentiating (log-sum-exp)")
        out2 = _array(r, name, _call(r, name, fn, parts.copy(), u, ranges, angles, motion, sensor_right,
                                     np.random.default_rng(1), _hint=lse_hint), (n, 3))
        if not np.all(np.isfinite(out2)):
            r.add(name, False, "NaN particles after log-likelihoods around -1500", lse_hint)
            raise _Stop
        moved_x = moved[:, 0]
        w = np.where(moved_x > 5.0, 1.0, 0.25)
        p_right = float(w[moved_x > 5.0].sum() / w.sum())
        frac = float(np.mean(out2[:, 0] > 5.0))
        se = math.sqrt(p_right * (1 - p_right) / n)
        ok = abs(frac - p_right) < 6 * se
        if ok:
            hint = ""
        elif abs(frac - np.mean(moved_x > 5.0)) < 6 * se:
            hint = "the particles were not resampled by weight: draw indices with probability proportional to w"
        else:
            hint = ("weights are exp(log-likelihood - max), normalised; resample N indices with those "
                    "probabilities")
        r.add(name, ok, f"fraction with x > 5: {frac:.3f}, expected {p_right:.3f} +- {se:.3f}", hint)
        a = _array(r, "reproducible with the same rng", _call(r, "reproducible with the same rng", fn, parts.copy(), u,
                                                              ranges, angles, motion, sensor_right,
                                                              np.random.default_rng(9)))
        b = _array(r, "reproducible with the same rng", _call(r, "reproducible with the same rng", fn, parts.copy(), u,
                                                              ranges, angles, motion, sensor_right,
                                                              np.random.default_rng(9)))
        r.add("reproducible with the same rng", np.array_equal(a, b), "",
              "pass rng to the motion model and draw the resampling numbers from it")

    return _run("mcl_step", body)
