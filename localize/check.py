"""Self-checks for exercises and homework: test *your* implementation like a patient TA.

Each ``check.<name>(fn)`` takes a function you wrote, runs it on cases with
known answers, and returns a :class:`Report`. The report is truthy when every
property holds, prints one line per property (``PASS`` / ``FAIL``) and, for
each failure, what your function gave (``seen``) next to the right answer
(``expected``) and a hint. A hint that names a particular mistake is given
only when your result is what that mistake produces; otherwise the hint
restates the rule. A check never
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
``resample_if_needed``     ``fn(particles, weights, rng, threshold) -> (particles, weights)``
``mcl_step``               ``fn(particles, u, ranges, angles, motion, sensor, rng) -> (N, 3)``
``world_to_cell``          ``fn(points, origin, resolution) -> (N, 2)`` integer ``(row, col)``
``ray_cast``               ``fn(grid, pose, angle, max_range) -> range`` (one beam)
``grid_update``            ``fn(belief, expected, beam_bins, ranges, beam_pdf) -> (K, H, W)``
``map_image``              ``fn(image, negate) -> occupancy`` (row 0 at the bottom, NaN unknown)
``injection``              ``fn(likelihoods, w_slow, w_fast, alpha_slow, alpha_fast) -> (w_slow, w_fast, p)``
``ekf_update``             ``fn(mean, cov, z, landmark, Q) -> (mean, cov)``
``predict_stop``           ``fn(belief, kernel, offset) -> array`` (bounded hallway)
``kld_loop``               ``fn(samples, bin_size, epsilon, delta, n_min) -> n``
``xy_reader``              ``fn(path) -> io.LaserLog`` (chapter 9's "XY log")
``innovation_gate``        ``fn(mean, cov, z, landmark, Q) -> bool`` (keep?)
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
    "resample_if_needed",
    "mcl_step",
    "ray_cast",
    "world_to_cell",
    "grid_update",
    "map_image",
    "injection",
    "ekf_update",
    "predict_stop",
    "kld_loop",
    "xy_reader",
    "innovation_gate",
    "ODOMETRY_CASES",
    "XY_MAX_RANGE",
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
    expected: str = ""


@dataclass
class Report:
    """The outcome of a check: a list of :class:`Verdict`, truthy when all passed.

    ``print(report)`` gives one line per property and a hint for each failure;
    ``report.failures`` lists the failed verdicts; ``report.hints`` their hints.
    """

    subject: str
    verdicts: list[Verdict] = field(default_factory=list)

    def add(self, name: str, passed: bool, detail: str = "", hint: str = "", expected: str = "") -> bool:
        """Record one property; ``detail`` is what the student's function gave, ``expected`` the right answer."""
        self.verdicts.append(Verdict(name, bool(passed), detail, "" if passed else hint, expected))
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
                    lines.append(f"        seen:     {v.detail}")
                if v.expected:
                    lines.append(f"        expected: {v.expected}")
                if v.hint:
                    lines.append(f"        hint:     {v.hint}")
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
        report.add(name, False, f"returned shape {a.shape}",
                   "keep one entry per input element (check which axis you sum or index over)",
                   expected=f"shape {tuple(shape)}")
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
              else "divide every entry by the sum of all entries (eta = 1 / sum)", expected="sum = 1")
        r.add("the result is proportional to the input", np.allclose(out * kept.sum(), kept, rtol=1e-9),
              _fixed(out), "each entry must become p_i / sum(p): no softmax, no subtracting the mean",
              expected=_fixed(kept / kept.sum()))
        r.add("the input array is left unchanged", np.array_equal(p, kept), f"input became {_fixed(p)}",
              "return p / p.sum() instead of dividing in place with p /= p.sum()")
        q = np.arange(1.0, 7.0).reshape(2, 3)
        out2 = _array(r, "works on a 2-D belief (sums over all cells)", _call(r, "runs on a 2-D array", fn, q),
                      q.shape)
        r.add("works on a 2-D belief (sums over all cells)", np.allclose(out2, q / q.sum(), rtol=1e-9),
              _fixed(out2), "sum over all cells with p.sum(), not along one axis (p.sum(axis=0))",
              expected=_fixed(q / q.sum()))

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
              "after multiplying, divide by the sum (the normaliser eta of Bayes rule)", expected="sum = 1")
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
        r.add("the posterior is eta * likelihood * belief", ok, _fixed(out), hint, expected=_fixed(expected))
        r.add("the inputs are left unchanged", np.array_equal(prior, keep_p) and np.array_equal(lik, keep_l),
              "", "compute a new array instead of modifying belief or likelihood in place")

    return _run("bayes_update", body)


def _tile_world() -> NDArray:
    return np.array([list("GGGGG"), list("GRRGG"), list("GGBGG"), list("GGGGG")])


def histogram_sense(fn: Callable) -> Report:
    """Check ``fn(belief, world, measurement, p_hit, p_miss)`` against :func:`localize.histogram.sense`."""
    from . import histogram

    def diagnose(out: NDArray, prior: NDArray, world: NDArray, m: str) -> str:
        """Name the mistake whose result ``out`` reproduces (each candidate tested, not guessed)."""
        uniform = np.full(world.shape, 1.0 / world.size)
        if np.allclose(out, histogram.sense(prior, world, m, 0.15, 0.85), rtol=1e-8):
            return "you swapped p_hit and p_miss: tiles whose colour MATCHES the measurement get p_hit"
        if np.allclose(out, histogram.sense(uniform, world, m, 0.85, 0.15), rtol=1e-8):
            return "multiply the PRIOR by the likelihood; do not start from a uniform belief"
        if np.allclose(out, prior * np.where(world == m, 0.85, 0.15), rtol=1e-8):
            return "the product is right but not normalised: divide by its sum"
        return "multiply by p_hit where world == measurement, by p_miss elsewhere, then normalise"

    def body(r: Report) -> None:
        world = _tile_world()
        prior = np.full(world.shape, 1.0 / world.size)
        expected = histogram.sense(prior, world, "R", 0.85, 0.15)
        out = _array(r, "returns a belief of the world's shape",
                     _call(r, "runs on a 4 x 5 tile world", fn, prior.copy(), world, "R", 0.85, 0.15), world.shape)
        r.add("returns a belief of the world's shape", True)
        r.add("the belief sums to one", abs(float(out.sum()) - 1.0) < 1e-9, f"sum = {float(out.sum()):.6g}",
              "normalise after multiplying by p_hit / p_miss", expected="sum = 1")
        ok = np.allclose(out, expected, rtol=1e-8)
        r.add("matching tiles gain, others lose (Bayes rule)", ok, _fixed(out),
              "" if ok else diagnose(out, prior, world, "R"), expected=_fixed(expected))
        prior2 = np.zeros(world.shape)
        prior2[1, 1] = prior2[2, 2] = 0.5
        exp2 = histogram.sense(prior2, world, "B", 0.85, 0.15)
        out2 = _array(r, "uses the prior belief", _call(r, "runs on a peaked prior", fn, prior2.copy(), world, "B",
                                                        0.85, 0.15), world.shape)
        ok2 = np.allclose(out2, exp2, rtol=1e-8)
        r.add("uses the prior belief", ok2, _fixed(out2), "" if ok2 else diagnose(out2, prior2, world, "B"),
              expected=_fixed(exp2))

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
            wrap_opposite = histogram.move(b, (-step[0], -step[1]), mode="wrap")
            if np.allclose(out, wrap, rtol=1e-8):
                hint = "your world wraps around (np.roll); this world is bounded: fill the uncovered tiles"
            elif np.allclose(out, opposite, rtol=1e-8):
                hint = "you moved the belief the opposite way: the robot moving left moves its belief left"
            elif np.allclose(out, wrap_opposite, rtol=1e-8):
                hint = ("you moved the wrong way, and your world wraps around: np.roll(b, shift, axis) moves entries "
                        "towards HIGHER indices for a positive shift, so a step (drow, dcol) is np.roll(b, (drow, dcol), "
                        "axis=(0, 1)); and this world is bounded: fill the uncovered tiles instead of wrapping")
            elif np.allclose(out.sum(), 1.0) is False:
                hint = "normalise after filling the uncovered tiles"
            else:
                hint = ("shift by the step (drow, dcol), put `fill` on the tiles uncovered at the edge, "
                        "then normalise")
            r.add(name, False, _fixed(out), hint, expected=_fixed(exp))

    return _run("histogram_move", body)


# ---------------------------------------------------------------------------- motion
def _variance_as_std(rot1, trans, rot2, alphas):
    """The classic mistake as a noise convention: the variance formula used as a standard deviation."""
    from .motion import odometry_variances

    return tuple(np.square(v) for v in odometry_variances(rot1, trans, rot2, alphas))


#: Odometry pairs ``(prev_odom, odom)`` that :func:`sample_odometry` tests, with what each one catches.
ODOMETRY_CASES: list[tuple[str, tuple[NDArray, NDArray], str]] = [
    ("a forward move with a turn", (np.array([1.0, 2.0, 0.3]), np.array([1.8, 2.9, 1.1])),
     "rot1 noise variance = a1*rot1**2 + a2*trans**2, trans: a3*trans**2 + a4*(rot1**2 + rot2**2), "
     "rot2: a1*rot2**2 + a2*trans**2 (PR table 5.6)"),
    ("a turn on the spot (no translation)", (np.array([1.0, 2.0, 2.5]), np.array([1.0, 2.0, -2.9])),
     "without translation atan2(0, 0) is meaningless: set rot1 = 0 and rot2 = the whole (wrapped) heading "
     "change when trans is (nearly) zero, as chapter 4 does; otherwise rot1 = -theta gets the noise a1*theta**2"),
    ("a move backwards", (np.array([0.0, 0.0, -3.0]), np.array([0.8, 0.25, -3.05])),
     "driving backwards gives rot1 and rot2 near +-pi: wrap rot1 = atan2(dy, dx) - theta and "
     "rot2 = theta' - theta - rot1 to [-pi, pi) BEFORE computing the noise variances"),
]


def sample_odometry(fn: Callable) -> Report:
    """Check ``fn(poses, u, alphas, rng)`` samples the odometry motion model (PR table 5.6).

    The distribution is compared with :func:`localize.motion.sample_odometry`
    (noise variances ``alpha1*rot1**2 + alpha2*trans**2`` etc.) for each of
    the motions in :data:`ODOMETRY_CASES`: a forward move with a turn, a turn
    on the spot (no translation: ``rot1 = 0``) and a move backwards (``rot1``
    near pi, wrapped).
    """
    from . import motion
    from .geometry import angle_diff

    def body(r: Report) -> None:
        u = ODOMETRY_CASES[0][1]
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
        r.add(name, ok, _fixed(out), hint, expected=_fixed(exact))
        wrapped = np.all((out[:, 2] >= -np.pi) & (out[:, 2] < np.pi))
        r.add("headings are wrapped to [-pi, pi)", wrapped, f"headings {_fixed(out[:, 2])}",
              "wrap the new heading with localize.wrap_angle (or (a + pi) % (2 pi) - pi)",
              expected=f"headings {_fixed(exact[:, 2])}")

        n = 40_000
        alphas = np.array([0.05, 0.01, 0.02, 0.05])
        # the sample variance has relative standard error sqrt(2/n) (plus the
        # kurtosis of a curved distribution): allow 8 of them
        var_tol = 8.0 * math.sqrt(2.0 / n) + 0.02
        for k, (what, uk, case_hint) in enumerate(ODOMETRY_CASES):
            name = f"{what}: samples have the model's mean and covariance"
            start_k = np.array([2.0, -1.0, 0.7])
            got = _array(r, name, _call(r, name, fn, np.tile(start_k, (n, 1)), uk, alphas,
                                        np.random.default_rng(1 + k)), (n, 3))
            ref = motion.sample_odometry(np.tile(start_k, (400_000, 1)), uk, alphas, np.random.default_rng(100 + k))
            m = float(np.angle(np.exp(1j * ref[:, 2]).mean()))

            def feats(p, m=m):  # unwrap headings around the reference mean
                return np.column_stack([p[:, 0], p[:, 1], m + angle_diff(p[:, 2], m)])

            fg, fr = feats(got), feats(ref)
            sd = np.maximum(fr.std(axis=0), 1e-12)

            def matches(fa, fb, sd=sd):
                """Same mean (6 standard errors) and variances (var_tol) as the sample fb."""
                mean_err = np.abs(fa.mean(axis=0) - fb.mean(axis=0)) / (sd / math.sqrt(n))
                ratio = fa.var(axis=0) / np.maximum(fb.var(axis=0), 1e-300)
                return bool(np.all(mean_err < 6.0)), bool(np.all(np.abs(ratio - 1.0) < var_tol)), ratio

            ok_mean, ok_var, var_ratio = matches(fg, fr)

            def as_std(start_k=start_k, uk=uk, k=k):  # drawn only when needed: the mistake's distribution
                return feats(motion.sample_odometry(np.tile(start_k, (400_000, 1)), uk, alphas,
                                                    np.random.default_rng(200 + k), noise=_variance_as_std))

            if ok_mean and ok_var:
                hint = ""
            elif np.all(fg.std(axis=0) < 1e-12):
                hint = ("all particles got the same noise (zero spread): draw one noise value per particle, "
                        "rng.normal(0.0, sd, size=len(poses)), not one value shared by every particle")
            elif all(matches(fg, as_std())[:2]):
                hint = ("you used the VARIANCE alpha1*rot1**2 + alpha2*trans**2 as a standard deviation: pass its "
                        "square root to rng.normal")
            elif np.all(var_ratio < 0.5):
                hint = ("the spread is far too small: alpha1*rot1**2 + alpha2*trans**2 is a VARIANCE; "
                        "pass its square root as the standard deviation")
            elif np.all(var_ratio > 2.0) and k == 0:
                hint = ("the spread is too large: are you using the variance as a standard deviation the other "
                        "way round?")
            else:
                hint = case_hint
            r.add(name, ok_mean and ok_var,
                  f"mean (x, y, theta) {_fixed(fg.mean(axis=0))}, std {_fixed(fg.std(axis=0))}", hint,
                  expected=f"mean (x, y, theta) {_fixed(fr.mean(axis=0))}, std {_fixed(fr.std(axis=0))} "
                           f"(+- {_fixed(6 * sd / math.sqrt(n))} on the mean)")
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
        main_ok = bool(np.all(good))
        r.add("matches the odometry density", main_ok, f"ratio yours / reference {_fixed(ratio)}", hint,
              expected=f"ratio 1 everywhere (reference densities {_fixed(ref)})")

        def single(prev_k: NDArray, uk: tuple, poses_k: NDArray) -> NDArray:
            return np.array([float(np.reshape(np.asarray(_call(r, "runs on single poses", fn, q, uk, prev_k, alphas),
                                                         float), -1)[0]) for q in poses_k])

        elsewhere = ("your density already differs from the reference on the ordinary motion above: fix that "
                     "first; this case only adds {}")
        cases = [  # (what the case adds, odometry pair, previous pose, seed, rtol, the hint when it alone fails)
            ("angle differences are wrapped (headings cross +-pi)", "headings that cross the +-pi seam",
             u, np.array([0.0, 0.0, 3.0]), 12, 1e-5,
             "wrap every angle difference (rot1_hat - rot1 etc.) to [-pi, pi) before the Gaussian"),
            ("a move backwards (rot1 near pi)", "a backwards move",
             (np.array([0.0, 0.0, -3.0]), np.array([0.8, 0.25, -3.05])), np.array([1.0, 1.0, 2.0]), 13, 1e-4,
             "wrap rot1 = atan2(dy, dx) - theta and rot2 to [-pi, pi) for the measured AND the hypothesised "
             "motion before computing variances and differences"),
        ]
        for name, what, u_c, prev_c, seed, rtol, fix in cases:
            samples = motion.sample_odometry(np.tile(prev_c, (6, 1)), u_c, alphas, np.random.default_rng(seed))
            ref_c = motion.odometry_pdf(samples, u_c, prev_c, alphas)
            vals_c = single(prev_c, u_c, samples)
            ok_c = bool(np.allclose(vals_c, ref_c, rtol=rtol, atol=1e-12))
            r.add(name, ok_c, _fixed(vals_c), fix if main_ok else elsewhere.format(what), expected=_fixed(ref_c))

    return _run("odometry_pdf", body)


# ---------------------------------------------------------------------------- sensors
def _beam_ref(z: NDArray, z_exp: NDArray, prm: dict) -> NDArray:
    """The beam mixture of PR section 6.3 and table 6.1, as :class:`localize.sensors.BeamModel` (the oracle).

    Truncated, normalised components. The convention at a max-range reading
    (chapter 5): readings beyond ``max_range`` count as ``max_range``, and at
    ``z = max_range`` the point mass ``z_max`` is *added* to the continuous
    densities evaluated there (the hit Gaussian on ``[0, max_range]``, the
    short exponential on ``[0, z*]``), exactly as PR's table 6.1 reads; the
    uniform part lives on ``[0, max_range)`` and is 0 there.
    """
    from scipy.special import erf

    zmax = prm["max_range"]
    s = prm["sigma_hit"]
    lam = prm["lambda_short"]
    z = np.minimum(np.asarray(z, float), zmax)
    ze = np.minimum(np.asarray(z_exp, float), zmax)
    norm_hit = 0.5 * (erf((zmax - ze) / (s * math.sqrt(2))) - erf((0 - ze) / (s * math.sqrt(2))))
    p_hit = np.where(z >= 0, np.exp(-0.5 * ((z - ze) / s) ** 2) / (s * math.sqrt(2 * math.pi)) / norm_hit, 0.0)
    short_ok = (z >= 0) & (z <= ze)
    p_short = np.where(short_ok, lam * np.exp(-lam * z) / (1 - np.exp(-lam * ze)), 0.0)
    p_max = (z >= zmax).astype(float)
    p_rand = np.where((z >= 0) & (z < zmax), 1.0 / zmax, 0.0)
    return prm["z_hit"] * p_hit + prm["z_short"] * p_short + prm["z_max"] * p_max + prm["z_rand"] * p_rand


def beam_model(fn: Callable, params: dict | None = None) -> Report:
    """Check a beam-model density ``fn(z, z_expected, params)`` (PR section 6.3, table 6.1).

    Properties: agreement with the four-part mixture; normalisation (the
    continuous part integrates over ``[0, max_range)`` to ``1 - z_max`` and
    the point mass at ``max_range`` carries ``z_max``); a reading at max range
    when the expected range is max range too (open space: the hit density
    there *plus* the point mass, the convention of chapter 5 and of
    :class:`localize.sensors.BeamModel`); a reading beyond max range counts as
    max range.
    """
    prm = dict(BEAM_PARAMS if params is None else params)

    def one(r: Report, name: str, z: float, z_exp: float) -> float:
        v = _array(r, name, _call(r, name, fn, z, z_exp, dict(prm)))
        return float(np.reshape(v, -1)[0]) if v.size else float("nan")

    def body(r: Report) -> None:
        zmax = prm["max_range"]
        z_exp = 4.0
        zs = np.array([0.5, 2.0, 3.9, 4.0, 4.3, 7.0, 9.5, zmax])
        vals = np.array([one(r, "runs on single readings", z, z_exp) for z in zs])
        r.add("returns a number per reading", bool(np.all(np.isfinite(vals))), f"values {_fixed(vals)}",
              "return a finite probability density for every reading")
        ref = _beam_ref(zs, np.full_like(zs, z_exp), prm)
        # normalisation by numerical integration over [0, zmax) (midpoint rule, 2000 cells)
        grid = (np.arange(2_000) + 0.5) * (zmax / 2_000)
        dens = np.array([float(np.reshape(np.asarray(fn(z, z_exp, dict(prm)), float), -1)[0]) for z in grid])
        integral = float(dens.sum() * zmax / 2_000)
        point = vals[-1]
        total = integral + point
        r.add("integrates to one (continuous part + max-range mass)", abs(total - 1.0) < 5e-3,
              f"integral over [0, max_range) = {integral:.4f}, mass at max_range = {point:.4f}, total {total:.4f}",
              "each component must be a normalised density: divide the Gaussian by its mass inside [0, max_range] "
              "and the exponential by 1 - exp(-lambda z*); the max-range reading is a point mass of weight z_max",
              expected=f"integral {1 - prm['z_max']:.4f}, mass {prm['z_max']:.4f}, total 1")
        ok = np.allclose(vals, ref, rtol=1e-3, atol=1e-9)
        r.add("matches the four-part mixture", ok, _fixed(vals),
              "p = z_hit p_hit + z_short p_short + z_max p_max + z_rand p_rand; p_short is zero beyond the expected "
              "range, p_rand is 1/max_range below max_range", expected=_fixed(ref))
        name = "a reading at max range when max range is expected (open space)"
        v_open = one(r, name, zmax, zmax)
        ref_open = float(_beam_ref(np.array([zmax]), np.array([zmax]), prm)[0])
        only_mass = abs(v_open - prm["z_max"]) < 1e-9
        r.add(name, bool(np.isclose(v_open, ref_open, rtol=1e-3)), f"{v_open:.4g}",
              ("you returned the point mass z_max alone; at z = max_range add it to the continuous densities there "
               "(z_hit p_hit(max_range) + z_short p_short + z_max, as PR table 6.1 reads and chapter 5 explains), "
               "so that a particle expecting open space is rewarded for a max-range reading") if only_mass
              else ("at z = max_range: z_hit p_hit(max_range | z*) + z_short p_short + z_max (the uniform part is 0 "
                    "there); clip z* to max_range"), expected=f"{ref_open:.4g}")
        name = "a reading beyond max range counts as max range"
        v_far = one(r, name, zmax + 2.5, z_exp)
        r.add(name, bool(np.isclose(v_far, ref[-1], rtol=1e-3)), f"p({zmax + 2.5:g} | {z_exp:g}) = {v_far:.4g}",
              "a reading >= max_range means 'no return': treat it as z = max_range (np.minimum(z, max_range))",
              expected=f"p({zmax:g} | {z_exp:g}) = {ref[-1]:.4g}")

    return _run("beam_model", body)


def scan_log_likelihood(fn: Callable, params: dict | None = None) -> Report:
    """Check ``fn(ranges, expected, params)`` returns the log-likelihood of a whole scan.

    Beams are independent given the pose, so the scan likelihood is the
    *product* of the beam densities and its log is the sum of their logs.
    Two scans of 360 beams: one that fits its expected ranges, and the same
    readings scored at a wrong pose, whose product of densities (about
    ``exp(-1260)``) underflows to 0 in floating point, so that
    ``log(prod(p))`` gives ``-inf`` there.
    """
    prm = dict(BEAM_PARAMS if params is None else params)

    def body(r: Report) -> None:
        rng = np.random.default_rng(5)
        expected = rng.uniform(1.0, 9.0, 360)
        ranges = np.clip(expected + rng.normal(0, 0.2, 360), 0.0, prm["max_range"])
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
        elif not np.isfinite(val):
            hint = ("the product of 360 small numbers underflows to 0 and log(0) = -inf: add log-probabilities "
                    "instead of multiplying probabilities")
        else:
            hint = "log p(scan | pose) = sum over beams of log p(z_k | z_k*)"
        r.add(name, bool(np.isclose(val, ref, rtol=1e-6)), f"{val:.6g}", hint, expected=f"{ref:.6g}")
        # the same readings scored at a wrong pose: every beam about 3 m off, its product about exp(-1000)
        wrong = np.roll(expected, 90)
        ref_w = float(np.log(_beam_ref(ranges, wrong, prm)).sum())
        name = "a scan at a wrong pose: finite, no underflow (log of the product = sum of the logs)"
        vw = _array(r, name, _call(r, name, fn, ranges, wrong, dict(prm)))
        val_w = float(np.reshape(vw, -1)[0])
        ok = bool(np.isclose(val_w, ref_w, rtol=1e-6))
        if ok:
            hint = ""
        elif val_w == -np.inf and np.prod(_beam_ref(ranges, wrong, prm)) == 0.0:
            hint = (f"you took the log of the product: the product of these 360 densities is about "
                    f"exp({ref_w:.0f}), below the smallest float (about exp(-745)), so it is 0 and log(0) = -inf. "
                    "Sum the log-densities instead: np.sum(np.log(p))")
        elif not np.isfinite(val_w):
            hint = "work in log space: sum log-densities instead of taking the log of a product"
        else:
            hint = "log p(scan | pose) = sum over beams of log p(z_k | z_k*)"
        r.add(name, ok, f"{val_w:.6g}", hint, expected=f"{ref_w:.6g}")
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


_GUARD_HINT = ("Guard BOTH ends of the search: set cumsum[-1] = 1.0, and since a pointer can itself round to "
               "exactly 1.0 (r + (N-1)/N with r just below 1/N), clip the index to N - 1 "
               "(np.minimum(idx, N - 1)). With np.searchsorted(cumsum, u, side='right') setting cumsum[-1] = 1.0 "
               "is NOT enough: side='right' returns N for u == 1.0, so clip as well.")


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
              f"indices run from 0 to N - 1. {_GUARD_HINT}", expected=f"indices in 0 .. {len(w) - 1}")
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
              f"mean counts {_fixed(mean)}",
              "every particle must be copied N * w_i times on average: check the offsets of your pointers "
              "(systematic: u_m = r + m / N with r ~ U[0, 1/N)); residual: draw the remainder from "
              "N * w_i - floor(N * w_i), not from w_i", expected=f"{_fixed(n * w)} (+- {_fixed(5 * se)})")
        a = _indices(r, "reproducible with the same rng", fn, w, np.random.default_rng(42))
        b = _indices(r, "reproducible with the same rng", fn, w, np.random.default_rng(42))
        r.add("reproducible with the same rng", np.array_equal(a, b), "",
              "draw random numbers from the rng argument, not from np.random")
        # cumulative sum that rounds to just below one (filterpy's resamplers index past the end
        # here): ten weights of 0.1 sum to 0.9999999999999999 in floating point, and a random
        # offset at the top of its range puts the last pointer at 1.0.
        w2 = np.full(10, 0.1)
        tail_ok, tail_seen = True, ""
        for _ in range(20):
            try:
                idx = np.asarray(fn(w2.copy(), _EdgeRNG(3)))
            except Exception as err:  # noqa: BLE001
                tail_ok, tail_seen = False, f"your function raised {type(err).__name__}: {err}"
                break
            if idx.shape != (10,) or idx.min() < 0 or idx.max() >= 10:
                tail_ok, tail_seen = False, f"indices {idx.tolist()}"
                break
        r.add("never indexes past the end when the weights sum to slightly below one", tail_ok, tail_seen,
              "np.cumsum of ten weights 0.1 ends at 0.9999999999999999. " + _GUARD_HINT,
              expected="ten indices in 0 .. 9")
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
                  "(m = 0 .. N-1); a pointer per draw, or r in [0, 1), breaks this",
                  expected=f"counts between {_fixed(lo)} .. {_fixed(hi)}")
        if scheme in ("systematic", "stratified", "residual"):
            ok = bool(var.sum() < 0.8 * var_multi.sum())
            r.add(f"{scheme} has lower offspring variance than multinomial", ok,
                  f"total variance {var.sum():.3f}",
                  f"{scheme} resampling must spread its pointers over [0, 1); independent uniform draws "
                  "give multinomial resampling",
                  expected=f"below {0.8 * var_multi.sum():.3f} (0.8 x multinomial's {var_multi.sum():.3f})")
        if scheme == "multinomial":
            ok = bool(abs(var.sum() / var_multi.sum() - 1.0) < 0.15)
            r.add("multinomial has offspring variance N w (1 - w)", ok,
                  f"total variance {var.sum():.3f}",
                  "draw N independent uniforms and find each one's particle in the cumulative sum",
                  expected=f"{var_multi.sum():.3f} (within 15%)")
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
            r.add(name, bool(np.isclose(val, expected, rtol=1e-9)), f"{val:.6g}", hint, expected=f"{expected:.6g}")
        raw = w * 8.0
        name = "normalises unnormalised weights first"
        val = float(np.reshape(_array(r, name, _call(r, name, fn, raw.copy())), -1)[0])
        r.add(name, bool(np.isclose(val, 1.0 / float((w ** 2).sum()), rtol=1e-9)), f"{val:.6g}",
              "divide the weights by their sum before squaring: N_eff = (sum w)**2 / sum(w**2)",
              expected=f"{1.0 / float((w ** 2).sum()):.6g}")

    return _run("effective_sample_size", body)


def resample_if_needed(fn: Callable, threshold: float = 0.5) -> Report:
    """Check adaptive resampling ``fn(particles, weights, rng, threshold) -> (particles, weights)``.

    Resample (any unbiased scheme) only when the effective sample size falls
    below ``threshold * N`` (chapter 6; :func:`localize.resample.needs_resampling`);
    afterwards every particle has weight ``1/N``. Otherwise return the
    particles and their (normalised) weights unchanged: resampling at every
    step throws away information for nothing (Doucet, Godsill and Andrieu
    2000; PR section 4.3.4).

    Properties: nearly even weights (``N_eff = 0.9 N``) keep particles and
    weights; degenerate weights (``N_eff`` about 2) resample in proportion to
    the weights (a statistical test, five standard errors) and reset the
    weights to ``1/N``; ``threshold = 0`` never resamples; the rng is used.
    """
    from .resample import effective_sample_size as ess

    def call(r: Report, name: str, parts: NDArray, w: NDArray, seed: int, thr: float) -> tuple[NDArray, NDArray]:
        out = _call(r, name, fn, parts.copy(), w.copy(), np.random.default_rng(seed), thr)
        if not isinstance(out, (tuple, list)) or len(out) != 2:
            r.add(name, False, f"returned {type(out).__name__}",
                  "return the pair (particles, weights): the weights are needed whether or not you resampled")
            raise _Stop
        return (_array(r, name, out[0], parts.shape), _array(r, name, out[1], w.shape))

    def body(r: Report) -> None:
        n = 1000
        rng0 = np.random.default_rng(31)
        parts = np.column_stack([np.arange(n, dtype=float), rng0.uniform(0, 5, n), rng0.uniform(-np.pi, np.pi, n)])
        even = rng0.uniform(0.6, 1.4, n)
        even /= even.sum()
        name = f"even weights (N_eff = {ess(even) / n:.2f} N >= {threshold} N): particles and weights are kept"
        p1, w1 = call(r, name, parts, even, 0, threshold)
        ok = bool(np.array_equal(p1, parts) and np.allclose(w1, even, rtol=1e-9))
        if ok:
            hint = ""
        elif not np.array_equal(p1, parts):
            hint = (f"you resampled although N_eff = {ess(even):.0f} is above threshold * N = {threshold * n:.0f}: "
                    "resampling at every step throws away particles for nothing (it only adds noise); resample "
                    "only when effective_sample_size(weights) < threshold * N")
        else:
            hint = "without resampling the weights stay what they were (normalised); do not reset them to 1/N"
        r.add(name, ok, "particles changed" if not np.array_equal(p1, parts) else f"weights {_fixed(w1[:4])} ...",
              hint, expected="the same particles and weights")

        # degenerate weights: 3 particles share 0.9 of the weight
        heavy = np.full(n, 0.1 / (n - 3))
        heavy[[10, 500, 900]] = [0.5, 0.3, 0.1]
        name = f"degenerate weights (N_eff = {ess(heavy):.1f}): resampled in proportion to the weights"
        p2, w2 = call(r, name, parts, heavy, 1, threshold)
        src = p2[:, 0].astype(int)
        valid = bool(np.all(p2[:, 0] == np.round(p2[:, 0])) and np.all((src >= 0) & (src < n))
                     and np.array_equal(p2, parts[np.clip(src, 0, n - 1)]))
        if not valid:
            r.add(name, False, "the new particles are not copies of the old ones",
                  "resampling copies whole particles: new = particles[indices]")
            raise _Stop
        counts = np.bincount(src, minlength=n)[[10, 500, 900]]
        se = np.sqrt(n * heavy[[10, 500, 900]] * (1 - heavy[[10, 500, 900]]))
        ok = bool(np.all(np.abs(counts - n * heavy[[10, 500, 900]]) < 5 * se))
        if ok:
            hint = ""
        elif np.array_equal(p2, parts):
            hint = (f"N_eff = {ess(heavy):.1f} is far below threshold * N = {threshold * n:.0f}: resample now "
                    "(compare effective_sample_size(weights) < threshold * len(weights))")
        else:
            hint = "draw the indices with probability proportional to the weights (e.g. localize.resample.systematic)"
        r.add(name, ok, f"copies of the three heavy particles {counts.tolist()}", hint,
              expected=f"{_fixed(n * heavy[[10, 500, 900]])} +- {_fixed(5 * se)}")
        name = "after resampling every weight is 1/N"
        ok = bool(np.allclose(w2, 1.0 / n, rtol=1e-9))
        r.add(name, ok, f"weights {_fixed(w2[:4])} ..., sum {w2.sum():.4g}",
              "the copies already represent the weights: set every weight to 1/N (keeping the old weights "
              "counts them twice)", expected=f"all {1.0 / n:.4g}")
        name = "threshold 0 never resamples"
        p3, w3 = call(r, name, parts, heavy, 2, 0.0)
        r.add(name, bool(np.array_equal(p3, parts) and np.allclose(w3, heavy, rtol=1e-9)),
              "particles changed" if not np.array_equal(p3, parts) else "weights changed",
              "use the threshold argument: resample only when N_eff < threshold * N (never when it is 0)",
              expected="the same particles and weights")
        a = call(r, "reproducible with the same rng", parts, heavy, 9, threshold)[0]
        b = call(r, "reproducible with the same rng", parts, heavy, 9, threshold)[0]
        r.add("reproducible with the same rng", bool(np.array_equal(a, b)), "",
              "draw the resampling numbers from the rng argument, not from np.random")

    return _run("resample_if_needed", body)


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
              "apply motion(particles, u, rng) to every particle before weighting", expected="100% moved")

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
        r.add(name, ok, f"fraction with x > 5: {frac:.3f}", hint, expected=f"{p_right:.3f} +- {6 * se:.3f}")

        # Weight AFTER moving: particles at x in [0, 5] facing +x drive 5 m; the sensor sees x = 7.
        # Weighted after the move the survivors sit around x = 7; weighted before it, the weights
        # favour the particles nearest x = 7 BEFORE the move (x near 5), which then end near 10.
        name = "weights the particles after moving them"
        east = np.column_stack([rng0.uniform(0, 5, n), rng0.uniform(0, 10, n), np.zeros(n)])
        u5 = (np.array([0.0, 0.0, 0.0]), np.array([5.0, 0.0, 0.0]))

        def sensor_at_7(p, ranges, angles):
            return -0.5 * ((p[:, 0] - 7.0) / 0.5) ** 2 - 800.0

        out3 = _array(r, name, _call(r, name, fn, east.copy(), u5, ranges, angles, motion, sensor_at_7,
                                     np.random.default_rng(2), _hint=lse_hint), (n, 3))
        xs = east[:, 0] + 5.0
        w7 = np.exp(-0.5 * ((xs - 7.0) / 0.5) ** 2)
        want = float((w7 * xs).sum() / w7.sum())
        w_before = np.exp(-0.5 * ((east[:, 0] - 7.0) / 0.5) ** 2)
        before = float((w_before * xs).sum() / w_before.sum())
        mean_x = float(np.mean(out3[:, 0]))
        # the weighted posterior has sd 0.5 m; 2000 resampled draws give a mean within 0.02 m (5 standard
        # errors of an i.i.d. sample, and resampling repeats particles, so allow 0.1 m)
        ok = bool(np.isfinite(mean_x) and abs(mean_x - want) < 0.1)
        if ok:
            hint = ""
        elif abs(mean_x - before) < 0.3:
            hint = ("you weighted the particles BEFORE moving them (or resampled and then moved): the scan is taken "
                    "at the new pose, so call sensor(moved, ranges, angles) on the moved particles")
        else:
            hint = "order of one step: moved = motion(particles, u, rng); weights from sensor(moved, ...); resample"
        r.add(name, ok, f"mean x of the new particles {mean_x:.3f} m", hint, expected=f"{want:.3f} +- 0.1 m")
        a = _array(r, "reproducible with the same rng", _call(r, "reproducible with the same rng", fn, parts.copy(), u,
                                                              ranges, angles, motion, sensor_right,
                                                              np.random.default_rng(9)))
        b = _array(r, "reproducible with the same rng", _call(r, "reproducible with the same rng", fn, parts.copy(), u,
                                                              ranges, angles, motion, sensor_right,
                                                              np.random.default_rng(9)))
        r.add("reproducible with the same rng", np.array_equal(a, b), "",
              "pass rng to the motion model and draw the resampling numbers from it")

    return _run("mcl_step", body)


# ---------------------------------------------------------------------------- maps and grids
def world_to_cell(fn: Callable) -> Report:
    """Check ``fn(points, origin, resolution) -> (N, 2)`` integer ``(row, column)`` cells (the preface).

    The convention of :class:`localize.OccupancyGrid`: cell ``(i, j)`` covers
    ``x0 + j r <= x < x0 + (j + 1) r`` and ``y0 + i r <= y < y0 + (i + 1) r``,
    so row ``i`` grows with ``y``.
    """
    from .grid import OccupancyGrid

    def body(r: Report) -> None:
        origin, res = np.array([-1.5, 2.0]), 0.25
        grid = OccupancyGrid(np.zeros((8, 12)), res, origin=tuple(origin))
        pts = np.array([[-1.2, 2.1], [0.0, 3.3], [1.49, 2.74], [-0.76, 3.99], [1.0, 2.0]])
        want = grid.world_to_cell(pts)
        name = "points go to the (row, column) of the cell that contains them"
        raw = _call(r, name, fn, pts.copy(), origin.copy(), res)
        out = _array(r, name, raw, want.shape)
        ok = bool(np.array_equal(out, want))
        rel = (pts - origin) / res
        if ok:
            hint = ""
        elif np.array_equal(out, want[:, ::-1]):
            hint = "you returned (column, row): the ROW index i comes from y, the column j from x"
        elif np.array_equal(out, np.round(rel[:, ::-1])):
            hint = "use np.floor, not np.round: a point 0.9 cells into cell j is still in cell j"
        elif np.array_equal(out, np.floor(pts / res)[:, ::-1]):
            hint = "subtract the origin first: j = floor((x - x0) / r), i = floor((y - y0) / r)"
        else:
            hint = "i = floor((y - y0) / r), j = floor((x - x0) / r), returned as integer pairs (i, j)"
        r.add(name, ok, out.tolist(), hint, expected=want.tolist())
        kind = np.asarray(raw).dtype
        r.add("returns integers (usable as indices)", kind.kind in "iu", f"dtype {kind}",
              "numpy indexes with integers only: convert with .astype(int) after np.floor",
              expected="an integer dtype")
        # left of and below the origin (off the map): the cell index is negative, -1 for a point less than
        # one cell beyond the edge; truncation toward zero (astype(int) without floor) gives 0, a cell of the map
        below = np.array([[-1.6, 2.1], [-1.2, 1.9], [-1.55, 1.95], [-2.1, 1.4]])
        want_b = np.floor((below - origin) / res).astype(np.int64)[:, ::-1]
        name = "a point left of or below the origin gets a negative index (floor, not truncation)"
        out_b = _array(r, name, _call(r, name, fn, below.copy(), origin.copy(), res), want_b.shape)
        ok_b = bool(np.array_equal(out_b, want_b))
        if ok_b:
            hint = ""
        elif np.array_equal(out_b, np.trunc((below - origin) / res)[:, ::-1]):
            hint = ("astype(int) (and int()) truncates toward zero: -0.4 cells becomes 0, but the point lies in cell "
                    "-1. Take np.floor first, then astype(int)")
        else:
            hint = "i = floor((y - y0) / r), j = floor((x - x0) / r) holds on both sides of the origin"
        r.add(name, ok_b, out_b.tolist(), hint, expected=want_b.tolist())

    return _run("world_to_cell", body)


def ray_cast(fn: Callable) -> Report:
    """Check a single-beam ray caster ``fn(grid, pose, angle, max_range) -> range`` (chapter 5).

    ``pose = (x, y, theta)`` is the sensor pose, ``angle`` the beam's
    direction relative to ``theta``; the range is the distance to where the
    beam enters the first obstacle cell (``grid.obstacles``), or
    ``max_range`` if it meets none within ``max_range`` or leaves the map
    (the conventions of :mod:`localize.raycast`, whose cell walker
    :func:`localize.raycast.cast_ray` is the reference). A caster that steps
    along the beam is accepted within one cell of the exact range; the map has
    walls one cell thick, which a step longer than a cell jumps over.
    """
    from .grid import OccupancyGrid
    from .raycast import cast_ray

    res = 0.1
    data = np.zeros((60, 80))
    data[:, 50] = 1.0                       # a wall one cell thick at x in [5.0, 5.1)
    data[45, :40] = 1.0                     # and one at y in [4.5, 4.6), left part
    grid = OccupancyGrid(data, res)

    def one(r: Report, name: str, pose: NDArray, angle: float, max_range: float) -> float:
        v = _array(r, name, _call(r, name, fn, grid, pose.copy(), float(angle), float(max_range)))
        if v.size != 1:
            r.add(name, False, f"returned {v.size} values", "return one range (a float) for one beam")
            raise _Stop
        return float(v.reshape(-1)[0])

    def body(r: Report) -> None:
        rng = np.random.default_rng(17)
        m = 60
        poses = np.column_stack([rng.uniform(1.0, 4.5, m), rng.uniform(0.5, 4.0, m), rng.uniform(-0.6, 0.6, m)])
        angles = rng.uniform(-0.6, 0.6, m)              # towards the wall at x = 5.0, at many slants
        max_range = 8.0
        name = "ranges to a one-cell wall, within one cell of the exact range"
        got = np.array([one(r, name, p, a, max_range) for p, a in zip(poses, angles)])
        want = np.array([cast_ray(grid, p[0], p[1], p[2] + a, max_range) for p, a in zip(poses, angles)])
        absolute = np.array([cast_ray(grid, p[0], p[1], a, max_range) for p, a in zip(poses, angles)])
        err = got - want
        ok = bool(np.all(np.isfinite(got)) and np.all(np.abs(err) <= res + 1e-9))
        worst = int(np.argmax(np.abs(np.nan_to_num(err, nan=1e9))))
        if ok:
            hint = ""
        elif np.any(err > res + 1e-9) and np.all(err > -res - 1e-9):
            hint = (f"{int(np.sum(err > res + 1e-9))} of {m} beams went through the wall one cell thick: your "
                    "step along the beam is longer than a cell, so it can jump over a thin wall. Step at most half "
                    "a cell (or walk from cell to cell across every grid line, as localize.raycast.cast_ray does)")
        elif np.allclose(got, absolute, atol=res):
            hint = "the beam's direction in the world is theta + angle: you left out the sensor's heading"
        elif np.all(np.abs(err) < 0.5 * res + 0.5 * res * np.sqrt(2)) and np.any(np.abs(err) > res):
            hint = "the range is measured from the sensor's position (x, y), not from the centre of its cell"
        else:
            hint = ("walk along the beam from (x, y) in the direction theta + angle and return the distance at which "
                    "you first enter a cell with grid.obstacles True (a row i, column j = grid.world_to_cell)")
        r.add(name, ok, f"beam {worst}: {got[worst]:.3f} m", hint, expected=f"{want[worst]:.3f} m (+- {res} m)")

        name = "max_range when nothing is within reach"
        pose = np.array([1.0, 2.0, 0.0])
        val = one(r, name, pose, 0.0, 3.0)              # the wall is 4 m away
        r.add(name, abs(val - 3.0) < 1e-9, f"{val:.4g} m",
              "stop walking after max_range and return max_range (no return from the beam)", expected="3 m")
        name = "max_range when the beam leaves the map without a hit"
        val = one(r, name, pose, np.pi, max_range)      # 1 m to the map's left edge, then open space
        r.add(name, abs(val - max_range) < 1e-9, f"{val:.4g} m",
              "a beam that leaves the map meets nothing the map knows of: return max_range (the book's convention), "
              "not the distance to the edge, and never index outside the grid (a negative index wraps around "
              "in numpy)", expected=f"{max_range:g} m")

    return _run("ray_cast", body)


def grid_update(fn: Callable) -> Report:
    """Check the correction step of grid localization (chapter 3).

    ``fn(belief, expected, beam_bins, ranges, beam_pdf) -> posterior``:
    ``belief`` and ``expected`` are ``(K, H, W)`` (heading bin, row, column;
    ``expected[k, i, j]`` is the expected range from cell ``(i, j)`` along the
    *absolute* heading bin ``k``), ``beam_bins[b]`` is beam ``b``'s angle in
    heading bins relative to the robot, ``ranges[b]`` its reading and
    ``beam_pdf(z, z_expected)`` a vectorised beam density. Beam ``b`` of a
    robot in heading bin ``k`` looks along bin ``(k + beam_bins[b]) % K``.
    """

    def pdf(z, z_exp):
        z_exp = np.asarray(z_exp, float)
        return 0.9 * np.exp(-0.5 * ((z - z_exp) / 0.3) ** 2) / (0.3 * math.sqrt(2 * math.pi)) + 0.1 / 10.0

    def reference(belief, expected, bins, ranges, roll=+1, offsets=True, logs=True):
        k_count = belief.shape[0]
        ll = np.zeros(belief.shape)
        for b, z in zip(bins, ranges):
            idx = (np.arange(k_count) + roll * (b if offsets else 0)) % k_count
            ll += np.log(pdf(z, expected[idx]))
        if not logs:
            post = belief * np.exp(ll)
            return post / post.sum()
        post = belief * np.exp(ll - ll.max())
        return post / post.sum()

    def body(r: Report) -> None:
        rng = np.random.default_rng(8)
        k_count, h, w = 8, 5, 6
        expected = rng.uniform(0.5, 9.0, (k_count, h, w))
        belief = rng.random((k_count, h, w))
        belief /= belief.sum()
        bins = np.array([0, 2, 4, 6, 1])
        true = (3, 2, 4)                                    # the robot's bin: readings fit it
        ranges = np.array([expected[(true[0] + b) % k_count, true[1], true[2]] for b in bins]) + 0.05
        want = reference(belief, expected, bins, ranges)
        name = "posterior = eta * belief * product of beam likelihoods"
        out = _array(r, name, _call(r, name, fn, belief.copy(), expected.copy(), bins.copy(), ranges.copy(), pdf),
                     belief.shape)
        ok = bool(np.allclose(out, want, rtol=1e-6, atol=1e-12))
        if ok:
            hint = ""
        elif np.allclose(out, reference(belief, expected, bins, ranges, roll=-1), rtol=1e-6, atol=1e-12):
            hint = ("the beam offset goes the wrong way: beam b of heading bin k looks along (k + beam_bins[b]) % K, "
                    "not (k - beam_bins[b])")
        elif np.allclose(out, reference(belief, expected, bins, ranges, offsets=False), rtol=1e-6, atol=1e-12):
            hint = ("every beam used the robot's own heading bin: add the beam's offset, expected[(k + beam_bins[b]) "
                    "% K]")
        elif np.allclose(out, reference(np.ones_like(belief), expected, bins, ranges), rtol=1e-6, atol=1e-12):
            hint = "you ignored the prior belief: multiply it by the likelihood"
        elif np.isclose(float(np.sum(out)), 1.0) is False:
            hint = "normalise the posterior over all K x H x W bins"
        else:
            hint = ("log-likelihood of bin (k, i, j) = sum over beams b of log beam_pdf(ranges[b], "
                    "expected[(k + beam_bins[b]) % K, i, j]); posterior = belief * exp(ll - max ll), normalised")
        r.add(name, ok, f"belief of the true bin {float(out[true]):.4f}, sum {float(np.sum(out)):.4f}", hint,
              expected=f"belief of the true bin {float(want[true]):.4f}, sum 1")
        r.add("the true pose's bin is the most probable", bool(np.argmax(out) == np.ravel_multi_index(true, out.shape)),
              f"argmax at {np.unravel_index(int(np.argmax(out)), out.shape)}",
              "readings that fit a bin must raise it", expected=f"argmax at {true}")
        # 360 beams that fit nowhere well: the product of densities underflows to 0
        bins2 = np.arange(360) % k_count
        ranges2 = np.full(360, 9.9)
        want2 = reference(belief, expected, bins2, ranges2)
        name = "360 beams do not underflow (work in log space)"
        lse = ("the product of 360 beam densities underflows to 0 everywhere and 0/0 = NaN: add log-likelihoods "
               "and subtract their maximum before exponentiating")
        out2 = _array(r, name, _call(r, name, fn, belief.copy(), expected.copy(), bins2, ranges2, pdf, _hint=lse),
                      belief.shape)
        ok2 = bool(np.all(np.isfinite(out2)) and np.allclose(out2, want2, rtol=1e-5, atol=1e-12))
        r.add(name, ok2, f"largest bin {float(np.nanmax(out2)) if np.any(np.isfinite(out2)) else float('nan'):.4f}",
              lse if not np.all(np.isfinite(out2)) or np.allclose(out2, 0) else
              "same rule as above, with many beams", expected=f"largest bin {float(want2.max()):.4f}")

    return _run("grid_update", body)


def map_image(fn: Callable) -> Report:
    """Check ``fn(image, negate) -> occupancy`` reading a ROS ``map_server`` image (chapter 9).

    ``image`` is an ``(H, W)`` uint8 array as stored in the PGM file (first row
    = the TOP of the map); the result is in :class:`localize.OccupancyGrid`'s
    convention (row 0 = the bottom, ``y`` grows with the row): 1.0 for
    occupied, 0.0 for free, NaN for unknown, with map_server's trinary rule
    and default thresholds: ``p = (255 - v) / 255`` (or ``v / 255`` when
    ``negate``), occupied if ``p > 0.65``, free if ``p < 0.196``.
    """
    from .io.ros import image_to_occupancy

    def body(r: Report) -> None:
        img = np.full((5, 7), 254, dtype=np.uint8)
        img[0, :] = 0            # a wall along the top of the picture = the far (high y) side of the map
        img[:, 0] = 0
        img[3, 4] = 205          # unknown (map_server's grey)
        img[1, 5] = 150          # a grey wall: p = 0.41, unknown by the default thresholds
        for negate in (False, True):
            src = 255 - img if negate else img
            want = np.flipud(image_to_occupancy(src, negate=negate))
            inverted = np.flipud(image_to_occupancy(255 - src, negate=negate))   # = negate ignored, if negate
            name = f"negate={negate}: occupancy in the grid's convention (row 0 at the bottom)"
            out = _array(r, name, _call(r, name, fn, src.copy(), negate), want.shape)
            ok = bool(np.allclose(out, want, equal_nan=True))
            if ok:
                hint = ""
            elif np.allclose(out, np.flipud(want), equal_nan=True):
                hint = ("the picture's first row is the TOP of the map, the grid's row 0 the bottom (y grows with the "
                        "row): flip the image with np.flipud")
            elif any(np.allclose(out, c, equal_nan=True) for c in (np.flipud(inverted), inverted)):
                hint = ("white means FREE: occupancy p = (255 - value) / 255" if not negate else
                        "you ignored negate: with negate: 1 the picture is inverted, p = value / 255")
            elif not np.any(np.isnan(out)):
                hint = ("cells between the thresholds (and map_server's grey 205) are UNKNOWN: NaN, "
                        "not 0.5 or free")
            else:
                hint = "p = (255 - v) / 255 (v / 255 with negate); p > 0.65 -> 1, p < 0.196 -> 0, else NaN; flipud"
            r.add(name, ok, _fixed(out), hint, expected=_fixed(want))

    return _run("map_image", body)


# ---------------------------------------------------------------------------- augmented MCL
def injection(fn: Callable) -> Report:
    """Check augmented MCL's averages ``fn(likelihoods, w_slow, w_fast, alpha_slow, alpha_fast)`` (chapter 8).

    ``likelihoods`` are the measurement likelihoods ``p(z | x_i)`` of the
    (equally weighted) particles. Return ``(w_slow, w_fast, p_inject)``:
    ``w_avg`` = their mean, ``w_slow += alpha_slow (w_avg - w_slow)``,
    ``w_fast += alpha_fast (w_avg - w_fast)``, ``p_inject = max(0, 1 -
    w_fast / w_slow)`` (PR table 8.3).
    """

    def ref(lik, ws, wf, a_s, a_f):
        w_avg = float(np.mean(lik))
        ws = ws + a_s * (w_avg - ws)
        wf = wf + a_f * (w_avg - wf)
        return ws, wf, max(0.0, 1.0 - wf / ws)

    cases = [
        ("a step as good as usual injects nothing", np.array([0.2, 0.4, 0.6, 0.8]), 0.5, 0.5),
        ("a sudden bad fit injects (w_fast drops below w_slow)", np.array([0.02, 0.05, 0.08, 0.05]), 0.5, 0.5),
        ("a fit better than usual injects nothing (never a negative probability)", np.array([0.9, 0.8, 1.0, 0.9]),
         0.5, 0.5),
        ("every likelihood zero: injection still rises, no NaN", np.zeros(4), 0.3, 0.2),
    ]

    def body(r: Report) -> None:
        a_s, a_f = 0.05, 0.5
        for name, lik, ws, wf in cases:
            got = _call(r, name, fn, lik.copy(), ws, wf, a_s, a_f)
            try:
                g = tuple(float(v) for v in got)
                if len(g) != 3:
                    raise ValueError
            except (TypeError, ValueError):
                r.add(name, False, f"returned {got!r}", "return the tuple (w_slow, w_fast, p_inject)")
                raise _Stop from None
            want = ref(lik, ws, wf, a_s, a_f)
            ok = bool(np.allclose(g, want, rtol=1e-9, atol=1e-12))
            norm = ref(np.full(lik.shape, 1.0 / lik.size), ws, wf, a_s, a_f)
            w_avg = float(np.mean(lik))
            ws1, wf1 = ws + a_s * (w_avg - ws), wf + a_f * (w_avg - wf)
            if ok:
                hint = ""
            elif np.allclose(g, norm, rtol=1e-9):
                hint = ("you averaged the NORMALISED weights, which always average 1/N: w_avg is the mean of the "
                        "raw likelihoods p(z | x_i)")
            elif any(not math.isfinite(v) for v in g):
                hint = "do not normalise the likelihoods (0/0 when all are zero): w_avg is their plain mean"
            elif np.allclose(g[:2], ref(lik, ws, wf, a_f, a_s)[:2], rtol=1e-9):
                hint = "alpha_slow belongs to w_slow and alpha_fast to w_fast (alpha_slow << alpha_fast)"
            elif np.allclose(g[:2], (ws1, wf1), rtol=1e-9) and wf1 > 0 and (
                    np.isclose(g[2], 1.0 - ws1 / wf1) or np.isclose(g[2], max(0.0, 1.0 - ws1 / wf1))):
                hint = "the ratio is upside down: p_inject = 1 - w_fast / w_slow"
            elif np.allclose(g[:2], (ws1, wf1), rtol=1e-9) and g[2] < 0:
                hint = "a probability cannot be negative: p_inject = max(0, 1 - w_fast / w_slow)"
            else:
                hint = ("w_avg = mean(likelihoods); w_slow += alpha_slow (w_avg - w_slow); w_fast += alpha_fast "
                        "(w_avg - w_fast); p_inject = max(0, 1 - w_fast / w_slow)")
            r.add(name, ok, "(w_slow, w_fast, p_inject) = " + _fixed(g), hint,
                  expected=_fixed(want))

    return _run("injection", body)


# ---------------------------------------------------------------------------- EKF
def ekf_update(fn: Callable) -> Report:
    """Check one EKF correction with a range-bearing sighting ``fn(mean, cov, z, landmark, Q) -> (mean, cov)``.

    PR table 7.2 lines 12-21 for one landmark: ``z_hat = h(mean)``,
    ``H`` the Jacobian (:func:`localize.ekf.landmark_jacobian`), ``S = H cov
    H^T + Q``, ``K = cov H^T S^-1``, ``mean + K (z - z_hat)`` with the
    bearing innovation wrapped, ``(I - K H) cov``.
    """
    from .ekf import landmark_jacobian, landmark_measurement
    from .geometry import wrap_angle as _wrap

    def ref(mean, cov, z, m, q, wrap=True, inverse=True):
        zh = landmark_measurement(mean, m)
        h = landmark_jacobian(mean, m)
        s = h @ cov @ h.T + q
        k = cov @ h.T @ (np.linalg.inv(s) if inverse else s)
        y = z - zh
        if wrap:
            y[1] = _wrap(y[1])
        mu = mean + k @ y
        mu[2] = _wrap(mu[2])
        return mu, (np.eye(3) - k @ h) @ cov

    q = np.diag([0.04, 0.0025])
    cov = np.diag([0.25, 0.25, 0.01])
    cases = [
        ("a landmark ahead and to the left", np.array([1.0, 1.0, np.pi / 2]), np.array([4.0, 5.0]),
         np.array([5.3, -0.60])),
        ("a landmark behind the robot (bearing near +-pi)", np.array([0.0, 0.0, 3.12]), np.array([5.0, -0.1]),
         np.array([4.8, 3.05])),
    ]

    def body(r: Report) -> None:
        for name, mean, m, z in cases:
            got = _call(r, name, fn, mean.copy(), cov.copy(), z.copy(), m.copy(), q.copy())
            try:
                mu, sg = (np.asarray(v, dtype=float) for v in got)
            except (TypeError, ValueError):
                r.add(name, False, f"returned {type(got).__name__}", "return the pair (mean, cov)")
                raise _Stop from None
            if mu.shape != (3,) or sg.shape != (3, 3):
                r.add(name, False, f"shapes {mu.shape} and {sg.shape}", "mean has shape (3,), cov (3, 3)")
                raise _Stop
            want_mu, want_cov = ref(mean, cov, z, m, q)
            ok_mu = bool(np.allclose(mu[:2], want_mu[:2], atol=1e-8) and abs(_wrap(mu[2] - want_mu[2])) < 1e-8)
            ok_cov = bool(np.allclose(sg, want_cov, atol=1e-10))
            if ok_mu and ok_cov:
                hint = ""
            elif ok_mu and np.allclose(sg, cov):
                hint = "the covariance must shrink after a measurement: cov' = (I - K H) cov"
            elif ok_mu:
                hint = "cov' = (I - K H) cov (or the Joseph form); check the sign and the order of the product"
            elif np.allclose(mu, ref(mean, cov, z, m, q, wrap=False)[0], atol=1e-8):
                y = float(z[1] - landmark_measurement(mean, m)[1])
                hint = (f"the bearing innovation z - z_hat is not wrapped: here it is {y:.2f} rad, really "
                        f"{float(_wrap(y)):.2f}; wrap it to [-pi, pi) before K (z - z_hat)")
            elif np.allclose(mu, ref(mean, cov, z, m, q, inverse=False)[0], atol=1e-8):
                hint = "K = cov H^T S^-1: you multiplied by S instead of its inverse (np.linalg.solve or inv)"
            else:
                hint = ("z_hat = (range, bearing) from the PREDICTED mean; H = [[-dx/r, -dy/r, 0], [dy/q, -dx/q, -1]]; "
                        "mean' = mean + K (z - z_hat)")
            r.add(name, ok_mu and ok_cov, f"mean {_fixed(mu)}, cov diagonal {_fixed(np.diag(sg))}", hint,
                  expected=f"mean {_fixed(want_mu)}, cov diagonal {_fixed(np.diag(want_cov))}")
            r.add(f"{name}: the heading of the result is wrapped", bool(-np.pi <= mu[2] < np.pi),
                  f"theta = {mu[2]:.4f}", "wrap the new heading to [-pi, pi)", expected="theta in [-pi, pi)")

    return _run("ekf_update", body)


# ---------------------------------------------------------------------------- chapter 1: a bounded hallway
def _predict_stop_ref(belief: NDArray, kernel: NDArray, offset: int, *, together: bool = True) -> NDArray:
    """The bounded hallway of chapter 1: mass that would run past an end stays in the end cell.

    ``together=False`` is the shift-then-blur mistake: shift (stopping at the ends), then blur (stopping again).
    """
    n, c = belief.size, kernel.size // 2
    out = np.zeros(n)
    if together:
        for src in range(n):
            for m, p in enumerate(kernel):
                out[min(max(src + offset + m - c, 0), n - 1)] += belief[src] * p
        return out
    shifted = np.zeros(n)
    for src in range(n):
        shifted[min(max(src + offset, 0), n - 1)] += belief[src]
    for src in range(n):
        for m, p in enumerate(kernel):
            out[min(max(src + m - c, 0), n - 1)] += shifted[src] * p
    return out


def predict_stop(fn: Callable) -> Report:
    """Check ``fn(belief, kernel, offset)``: the prediction in a bounded hallway where the robot stops at the ends.

    Chapter 1, exercise 2. The robot is commanded ``offset`` cells (positive =
    towards higher index) and ends ``d`` cells beyond the commanded cell with
    probability ``kernel[c + d]`` (``c`` the kernel's centre); a move that
    would end past either end of the hallway ends **in the end cell**. Shift
    and blur act together on each source cell, so no mass is lost.
    """
    from . import discrete

    n = 10
    cases = [
        ("mass that would run past the right end stops in the last cell", np.r_[np.zeros(7), 0.2, 0.3, 0.5],
         np.array([0.1, 0.8, 0.1]), 2),
        ("a move to the left stops in the first cell", np.r_[0.5, 0.3, 0.2, np.zeros(7)],
         np.array([0.2, 0.7, 0.1]), -2),
        ("away from the ends it is the ordinary prediction (a lopsided kernel)",
         np.r_[np.zeros(3), 0.6, 0.4, np.zeros(5)], np.array([0.1, 0.6, 0.3]), 1),
    ]

    def diagnose(out: NDArray, b: NDArray, k: NDArray, off: int) -> str:
        lost = discrete.predict(b, k, offset=off, mode="constant")
        if np.allclose(out, discrete.predict(b, k, offset=off), atol=1e-9):
            return ("your hallway wraps around (np.roll, or discrete.predict's default mode='wrap'): mass leaving "
                    "one end entered the other; here it must stop in the end cell")
        if np.allclose(out, lost, atol=1e-9):
            return "mass that would leave the hallway is lost: add it to the end cell instead (clip the target cell)"
        if lost.sum() > 0 and np.allclose(out, lost / lost.sum(), atol=1e-9):
            return ("renormalising after losing the mass spreads it over every cell: put it on the end cell, where "
                    "the robot stopped")
        if np.allclose(out, _predict_stop_ref(b, k, off, together=False), atol=1e-9):
            return ("you shifted first and blurred after: a robot that would overshoot the end by 1 to 3 cells "
                    "stops at the end every time, so shift and blur each source cell together, then clip")
        if np.allclose(out, _predict_stop_ref(b, k[::-1], off), atol=1e-9):
            return ("the kernel is mirrored: kernel[c + d] is the chance of ending d cells BEYOND the commanded "
                    "cell (np.convolve's orientation, not np.correlate's)")
        if np.allclose(out, _predict_stop_ref(b, k, -off), atol=1e-9):
            return "you moved the wrong way: a positive offset moves towards higher cell indices"
        if np.allclose(out, discrete.predict(b, k, offset=-off), atol=1e-9):
            return ("you moved the wrong way, and your hallway wraps around: np.roll(b, shift) moves entries towards "
                    "HIGHER indices for a positive shift (np.roll(b, offset), not np.roll(b, -offset)); and here mass "
                    "must stop in the end cell instead of wrapping")
        return ("for every source cell src and kernel entry m, add belief[src] * kernel[m] to cell "
                "min(max(src + offset + m - c, 0), n - 1)")

    def body(r: Report) -> None:
        for name, b, k, off in cases:
            keep = b.copy()
            want = _predict_stop_ref(b, k, off)
            out = _array(r, name, _call(r, name, fn, b.copy(), k.copy(), off), (n,))
            ok = bool(np.allclose(out, want, atol=1e-9))
            r.add(name, ok, _fixed(out), "" if ok else diagnose(out, keep, k, off), expected=_fixed(want))
            r.add(f"{name}: mass is conserved", abs(float(out.sum()) - 1.0) < 1e-9, f"sum = {float(out.sum()):.6g}",
                  "nothing falls off a hallway whose ends stop the robot: the prediction must sum to one",
                  expected="sum = 1")
        b = cases[0][1].copy()
        keep = b.copy()
        _call(r, "the input belief is left unchanged", fn, b, cases[0][2].copy(), 2)
        r.add("the input belief is left unchanged", np.array_equal(b, keep), f"input became {_fixed(b)}",
              "build a new array (np.zeros(n)) instead of adding into the belief you were given",
              expected=_fixed(keep))

    return _run("predict_stop", body)


# ---------------------------------------------------------------------------- chapter 8: the KLD loop
def _kld_rule(keys: NDArray, epsilon: float, delta: float, n_min: int, *, k_shift: int = 0,
              only_on_new: bool = False, lag: bool = False) -> int:
    """The KLD stopping rule as PR table 8.4's loop, with switches for the classic mistakes."""
    from .kld import kld_bound

    seen: set[int] = set()
    n = 0
    for key in keys.tolist():
        n += 1
        new = key not in seen
        if not lag:
            seen.add(key)
        k = len(seen) + k_shift
        need = float(kld_bound(k, epsilon, delta)) if k > 1 else 0.0
        if lag:
            seen.add(key)
        if only_on_new and not new:
            continue
        if n >= need and n >= n_min:
            return n
    return n


def kld_loop(fn: Callable) -> Report:
    """Check the KLD stopping rule ``fn(samples, bin_size, epsilon, delta, n_min) -> n`` (chapter 8, exercise 2).

    ``samples`` (M, 3) are candidate particles drawn one after another; return
    the smallest ``n`` such that the first ``n`` of them satisfy ``n >= n_min``
    and ``n >= kld_bound(k)``, ``k`` the number of bins of size ``bin_size``
    they occupy (PR table 8.4), or ``M`` when no ``n`` does. The reference is
    :func:`localize.kld.kld_sample_size`.
    """
    from .kld import bin_keys, kld_sample_size

    rng = np.random.default_rng(11)
    b = (0.5, 0.5, float(np.radians(10.0)))
    spot = rng.normal([2.0, 3.0, 0.0], [0.3, 0.3, 0.1], size=(4000, 3))
    two = np.concatenate([rng.normal([1.0, 1.0, 0.5], [0.2, 0.2, 0.05], size=(1500, 3)),
                          rng.normal([8.0, 4.0, -2.0], [0.2, 0.2, 0.05], size=(1500, 3))])[rng.permutation(3000)]
    cases = [
        ("a concentrated cloud: the bound stops the loop", spot, 0.05, 0.01, 50),
        ("two clusters, a looser epsilon", two, 0.15, 0.05, 50),
        ("every sample in one bin: n_min decides", np.tile([[1.1, 1.1, 0.01]], (500, 1)), 0.05, 0.01, 120),
        ("the sample that reaches n_min opens a second bin: it counts at once",
         np.array([[1.1, 1.1, 0.01]] * 49 + [[3.1, 1.1, 0.01]] + [[1.1, 1.1, 0.01], [3.1, 1.1, 0.01]] * 50),
         0.05, 0.01, 50),
        ("a spread cloud never meets the bound: every sample is needed",
         rng.uniform([0, 0, -np.pi], [20, 10, np.pi], size=(3000, 3)), 0.05, 0.01, 50),
    ]

    def body(r: Report) -> None:
        outs, wants, alts = [], [], {}
        for name, s, eps, dl, n_min in cases:
            got = _call(r, name, fn, s.copy(), b, eps, dl, n_min)
            if not _is_intlike(got) or np.ndim(got) != 0:
                r.add(name, False, f"returned {got!r}", "return the number of samples n as one integer",
                      expected=str(kld_sample_size(s, b, eps, dl, n_min)))
                raise _Stop
            keys = bin_keys(s, b)
            outs.append(int(got))
            wants.append(kld_sample_size(s, b, eps, dl, n_min))
            for mistake, kw in {"k": dict(k_shift=1), "new": dict(only_on_new=True), "nmin": dict(n_min=1),
                                "lag": dict(lag=True)}.items():
                kw = {"n_min": n_min, **kw}
                alts.setdefault(mistake, []).append(_kld_rule(keys, eps, dl, kw.pop("n_min"), **kw))
        if outs == wants:
            hint = ""
        elif all(abs(o - w) == 1 for o, w in zip(outs, wants) if o != w):
            hint = "off by one: count the samples from 1 and stop at the FIRST n with n >= n(k) and n >= n_min"
        elif outs == alts["lag"]:
            hint = ("add the new sample's bin to the occupied set BEFORE testing the rule: k counts the bins of "
                    "the first n samples, this one included")
        elif outs == alts["k"]:
            hint = ("the bound of PR table 8.4 line 16 is written with k - 1 (kld_bound(k) already does that): "
                    "k is the number of occupied bins, pass it as it is")
        elif outs == alts["new"]:
            hint = ("test the stopping rule after every sample, not only when a sample opens a new bin (PR table "
                    "8.4 loops `until n >= n_chi and n >= n_min`)")
        elif outs == alts["nmin"]:
            hint = "also require n >= n_min: with one or two bins the bound asks for (almost) nothing"
        elif outs[:-1] == wants[:-1]:
            hint = "when no n meets the rule, every candidate is needed: return len(samples)"
        else:
            hint = ("loop over the samples; keep a set of occupied bin keys (localize.kld.bin_keys); after each sample "
                    "stop when n >= kld_bound(len(bins), epsilon, delta) and n >= n_min")
        for (name, *_), o, w in zip(cases, outs, wants):
            r.add(name, o == w, f"n = {o}", hint, expected=f"n = {w}")

    return _run("kld_loop", body)


# ---------------------------------------------------------------------------- chapter 9: a file-format trap
#: The "XY log" of chapter 9, exercise 2: ``SCAN t x y theta r1 ... rn``, ranges in millimetres from +90 down to
#: -90 degrees (clockwise), 0 = no return; the scanner reaches 30 m.
XY_MAX_RANGE = 30.0


def xy_reader(fn: Callable) -> Report:
    """Check a reader ``fn(path) -> io.LaserLog`` of chapter 9's made-up "XY log" (exercise 2).

    Each line is ``SCAN t x y theta r1 ... rn``: time [s], odometry pose
    [m, m, rad], then ranges in **millimetres** from +90 degrees **down** to
    -90 degrees (clockwise), ``0`` meaning "no return", for a scanner of
    :data:`XY_MAX_RANGE` metres. The book's conventions: ranges in metres,
    angles counter-clockwise from the robot's right (beam 0 at -pi/2), a
    reading ``>= max_range`` for no return. A line with the wrong number of
    fields raises :class:`localize.io.FormatError` naming its line (1-based,
    blank lines counted).
    """
    import tempfile
    from pathlib import Path

    from .io import FormatError

    good = "SCAN 0.0 1.0 2.0 0.1 1000 0 3000 2500\nSCAN 0.5 1.2 2.1 0.15 1200 2000 0 2400\n"
    file_order = np.array([[1.0, 0.0, 3.0, 2.5], [1.2, 2.0, 0.0, 2.4]])
    want_r = np.where(file_order == 0, XY_MAX_RANGE, file_order)[:, ::-1]
    want_a = np.linspace(-np.pi / 2, np.pi / 2, 4)

    def body(r: Report) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "robot.xy"
            path.write_text(good)
            name = "reads a two-scan file"
            log = _call(r, name, fn, path)
            try:
                times, odo, rng_, ang = (np.asarray(getattr(log, a), dtype=float)
                                         for a in ("times", "odometry", "ranges", "angles"))
                max_range = float(log.max_range)
            except (AttributeError, TypeError, ValueError):
                r.add(name, False, f"returned {type(log).__name__}",
                      "return an io.LaserLog(times=..., odometry=..., ranges=..., angles=..., max_range=...)",
                      expected="an io.LaserLog")
                raise _Stop from None
            r.add(name, rng_.shape == (2, 4) and odo.shape == (2, 3), f"ranges shape {rng_.shape}, "
                  f"odometry shape {odo.shape}", "one row per SCAN line, one column per beam (4 here)",
                  expected="ranges shape (2, 4), odometry shape (2, 3)")
            if rng_.shape != (2, 4) or ang.shape != (4,):
                raise _Stop
            r.add("times and odometry poses as written", np.allclose(times, [0.0, 0.5]) and
                  np.allclose(odo, [[1.0, 2.0, 0.1], [1.2, 2.1, 0.15]]), f"times {_fixed(times)}, odometry "
                  f"{_fixed(odo).replace(chr(10), '')}", "fields 2-5 are t, x, y, theta",
                  expected="times [0. 0.5], odometry [[1. 2. 0.1] [1.2 2.1 0.15]]")
            ok_a = bool(np.allclose(ang, want_a))
            r.add("beam angles counter-clockwise from the right, -pi/2 ... +pi/2", ok_a, _fixed(ang),
                  "the file runs from +90 down to -90 degrees; the book's beam 0 points right (-pi/2) and angles "
                  "increase counter-clockwise: reverse the file's beam order" if np.allclose(ang, want_a[::-1])
                  else "angles = np.linspace(-np.pi / 2, np.pi / 2, n_beams)", expected=_fixed(want_a))
            # compare each beam's reading at its angle, whatever order the student stored them in
            order = np.argsort(ang, kind="stable")
            got = rng_[:, order]
            hit = file_order != 0
            ok_r = bool(np.allclose(got[:, ::-1][hit], file_order[hit]))
            if ok_r:
                hint = ""
            elif np.allclose(got[hit[:, ::-1]], file_order[:, ::-1][hit[:, ::-1]] * 1000):
                hint = "the file stores millimetres: divide by 1000 for metres"
            elif np.allclose(got[:, ::-1][hit[:, ::-1]], file_order[:, ::-1][hit[:, ::-1]]):
                hint = ("the beams are paired with the wrong angles: the file's FIRST reading is at +90 degrees "
                        "(the robot's left), so reverse the readings together with the angles")
            else:
                hint = "reading i of the file (0-based) is at +90 - 180 i / (n - 1) degrees, in mm"
            r.add("each reading in metres at its own angle", ok_r, _fixed(got).replace("\n", ""), hint,
                  expected=_fixed(want_r).replace("\n", ""))
            none = got[:, ::-1][~hit]
            ok_n = bool(np.all(none >= max_range) and max_range == XY_MAX_RANGE)
            r.add("0 in the file means no return: a reading at max_range (30 m)", ok_n,
                  f"no-return readings {_fixed(none)}, max_range {max_range:g}",
                  "a 0 is no return, not an obstacle touching the sensor: store max_range there (30 m)"
                  if np.any(none < max_range) else "this scanner reaches 30 m: max_range=30.0",
                  expected="no-return readings >= 30, max_range 30")
            bad = "SCAN 0.0 1.0 2.0 0.1 1000 0 3000 2500\n\nSCAN 0.5 1.2 2.1 0.15 1200 2000\n"
            path.write_text(bad)
            name = "a short line raises io.FormatError naming its line (3: blank lines count)"
            try:
                with np.errstate(all="ignore"):
                    fn(path)
            except FormatError as err:
                r.add(name, err.line == 3, f"FormatError at line {err.line}: {err}",
                      "count lines from 1 and keep counting over blank lines: enumerate(text.splitlines(), start=1)",
                      expected="FormatError at line 3")
            except Exception as err:  # noqa: BLE001 - any student error becomes a verdict
                r.add(name, False, f"{type(err).__name__}: {err}",
                      "compare each line's field count with the first scan's and raise "
                      "io.FormatError(path, line_number, 'expected N fields; got M')", expected="FormatError at line 3")
            else:
                r.add(name, False, "no error", "check the number of fields of every line against the first line's",
                      expected="FormatError at line 3")

    return _run("xy_reader", body)


# ---------------------------------------------------------------------------- chapter 10: innovation gating
def innovation_gate(fn: Callable, gate: float = 9.21) -> Report:
    """Check ``fn(mean, cov, z, landmark, Q) -> bool``: keep a sighting inside the 99% innovation gate.

    Chapter 10, exercise 2. With ``z_hat`` and ``H`` at ``mean``
    (:func:`localize.ekf.landmark_measurement`, :func:`localize.ekf.landmark_jacobian`),
    ``y = z - z_hat`` with the bearing wrapped and ``S = H cov H^T + Q``,
    keep the sighting (return True) when ``y^T S^-1 y <= gate`` (9.21, the
    99% point of chi-square with 2 degrees of freedom).
    """
    from .ekf import landmark_jacobian, landmark_measurement
    from .geometry import wrap_angle as _wrap

    def d2(mean, cov, z, m, q, wrap=True, with_q=True, euclid=False):
        h = landmark_jacobian(mean, m)
        s = h @ cov @ h.T + (q if with_q else 0.0)
        y = np.asarray(z, float) - landmark_measurement(mean, m)
        if wrap:
            y[1] = _wrap(y[1])
        return float(y @ y) if euclid else float(y @ np.linalg.solve(s, y))

    q = np.diag([0.04, 0.0025])
    cov = np.diag([0.04, 0.04, 0.01])
    mean, m = np.array([1.0, 1.0, np.pi / 2]), np.array([4.0, 5.0])

    def along_range(target, c=cov):
        """A sighting whose only innovation is in range, at Mahalanobis distance ``target``."""
        h = landmark_jacobian(mean, m)
        s_inv = np.linalg.inv(h @ c @ h.T + q)
        return landmark_measurement(mean, m) + [math.sqrt(target / s_inv[0, 0]), 0.0]

    tiny = np.diag([1e-6, 1e-6, 1e-8])
    behind_mean, behind_m = np.array([0.0, 0.0, 3.12]), np.array([5.0, -0.1])
    zb = landmark_measurement(behind_mean, behind_m)
    zb = np.array([zb[0] + 0.05, _wrap(zb[1] + 0.03 * np.sign(zb[1]))])  # crosses +-pi
    cases = [
        ("a sighting close to the prediction is kept (distance 2)", mean, cov, along_range(2.0), m),
        ("distance 8 is kept (inside 9.21)", mean, cov, along_range(8.0), m),
        ("distance 10 is rejected (outside 9.21)", mean, cov, along_range(10.0), m),
        ("distance 40 is rejected", mean, cov, along_range(40.0), m),
        ("a bearing 1.2 rad off is rejected, though the numbers are small",
         mean, cov, landmark_measurement(mean, m) + [0.0, 1.2], m),
        ("a very uncertain pose: 3.5 m off in range is kept", mean, np.diag([4.0, 4.0, 0.01]),
         landmark_measurement(mean, m) + [3.5, 0.0], m),
        ("a sure pose: the sensor noise Q sets the gate (30 cm off kept)", mean, tiny, along_range(2.25, tiny), m),
        ("a landmark behind the robot (bearing near +-pi) is kept", behind_mean, cov, zb, behind_m),
    ]
    variants = {
        "wrap": lambda c: d2(*c, wrap=False) <= gate,
        "q": lambda c: d2(*c, with_q=False) <= gate,
        "euclid": lambda c: d2(*c, euclid=True) <= gate,
        "sqrt": lambda c: math.sqrt(d2(*c)) <= gate,
        "1dof": lambda c: d2(*c) <= 6.63,
        "3dof": lambda c: d2(*c) <= 11.34,
        "inverted": lambda c: d2(*c) > gate,
    }
    hints = {
        "wrap": "wrap the bearing innovation to [-pi, pi) before the distance: behind the robot z - z_hat is ~2 pi",
        "q": "S = H cov H^T + Q: without the sensor noise Q a well-known pose rejects every reading",
        "euclid": "use the Mahalanobis distance y^T S^-1 y, not y^T y: metres and radians need S to be compared",
        "sqrt": "9.21 is a bound on the SQUARED distance y^T S^-1 y; do not take its square root",
        "1dof": "a sighting has two numbers (range, bearing): the 99% gate is chi-square with 2 dof, 9.21 (not 6.63)",
        "3dof": "a sighting has two numbers (range, bearing): the 99% gate is chi-square with 2 dof, 9.21 (not 11.34)",
        "inverted": "return True to KEEP a sighting inside the gate (distance <= 9.21)",
    }

    def body(r: Report) -> None:
        outs = []
        for name, mu, c, z, lm in cases:
            got = _call(r, name, fn, mu.copy(), c.copy(), np.asarray(z, float).copy(), lm.copy(), q.copy())
            if not isinstance(got, (bool, np.bool_)) and not (np.ndim(got) == 0 and got in (0, 1)):
                r.add(name, False, f"returned {got!r}", "return True (keep) or False (skip)",
                      expected=str(d2(mu, c, z, lm, q) <= gate))
                raise _Stop
            outs.append(bool(got))
        args = [(mu, c, z, lm, q) for _, mu, c, z, lm in cases]
        wants = [d2(*a) <= gate for a in args]
        hint = ""
        if outs != wants:
            hint = next((hints[k] for k, v in variants.items() if [v(a) for a in args] == outs),
                        "y = z - z_hat (bearing wrapped); S = H cov H^T + Q; keep when y @ solve(S, y) <= 9.21")
        for (name, *_), o, w, a in zip(cases, outs, wants, args):
            r.add(name, o == w, f"{'kept' if o else 'rejected'}", hint,
                  expected=f"{'kept' if w else 'rejected'} (y^T S^-1 y = {d2(*a):.2f})")

    return _run("innovation_gate", body)
