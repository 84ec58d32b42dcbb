# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Homework: build a localizer, one checked piece at a time
#
# Each exercise asks for one function. Write it in the cell with
# `raise NotImplementedError`, run the cell, then run the check below it: the
# check tests your function the way a teaching assistant would and prints, for
# every property, PASS or FAIL with a hint. A report that says
# "all N checks passed" means your function agrees with the reference
# implementation in `localize` on every property tested.
#
# The checks never look at your code, only at what it returns, so any correct
# implementation passes. Statistical checks use fixed seeds and tolerances
# derived from the sample size: a correct sampler passes every time.

# %% [markdown] tags=["teacher"]
# *Teachers:* this is the solutions source. The student notebook
# `homework.ipynb` is generated from it by `python tools/make_homework.py`,
# which replaces the body of every function in a cell tagged `solution` by
# `raise NotImplementedError` and drops cells tagged `teacher`.

# %%
import math

import numpy as np

from localize import check
from localize.geometry import wrap_angle

# %% [markdown]
# ## 1. Normalising a belief (chapter 1)
#
# Write `normalize(p)` that returns a *new* array with the entries of `p`
# divided by their sum, for an array of any shape.

# %% tags=["solution"]
def normalize(p):
    """Return p divided by its sum (a new array, any shape)."""
    p = np.asarray(p, dtype=float)
    return p / p.sum()


# %%
check.normalize(normalize)

# %% [markdown]
# ## 2. The correction step (chapter 1)
#
# Write `bayes_update(belief, likelihood)`: Bayes rule on a grid,
# $\mathrm{bel}(x) = \eta\, p(z \mid x)\, \overline{\mathrm{bel}}(x)$.

# %% tags=["solution"]
def bayes_update(belief, likelihood):
    """Posterior belief: likelihood times prior, normalised."""
    posterior = np.asarray(belief, dtype=float) * np.asarray(likelihood, dtype=float)
    return posterior / posterior.sum()


# %%
check.bayes_update(bayes_update)

# %% [markdown]
# ## 3. Sensing and moving in the tile world (chapter 2)
#
# `histogram_sense(belief, world, measurement, p_hit, p_miss)` multiplies the
# belief by `p_hit` on tiles whose label equals the measurement and by `p_miss`
# elsewhere, then normalises. `histogram_move(belief, step, fill)` performs a
# perfect move by `step = (drow, dcol)` (row 0 at the top) in a bounded world:
# belief that leaves the world is lost, uncovered tiles get `fill`, and the
# result is normalised.

# %% tags=["solution"]
def histogram_sense(belief, world, measurement, p_hit, p_miss):
    """Measurement update of the tile world."""
    likelihood = np.where(np.asarray(world) == measurement, p_hit, p_miss)
    posterior = np.asarray(belief, dtype=float) * likelihood
    return posterior / posterior.sum()


def histogram_move(belief, step, fill):
    """Perfect move by (drow, dcol) in a bounded world, uncovered tiles filled, normalised."""
    b = np.asarray(belief, dtype=float)
    dr, dc = step
    rows, cols = b.shape
    out = np.full_like(b, fill)
    for r in range(rows):
        for c in range(cols):
            r2, c2 = r + dr, c + dc
            if 0 <= r2 < rows and 0 <= c2 < cols:
                out[r2, c2] = b[r, c]
    return out / out.sum()


# %%
print(check.histogram_sense(histogram_sense))
print(check.histogram_move(histogram_move))

# %% [markdown]
# ## 4. The odometry motion model (chapter 4)
#
# `sample_odometry(poses, u, alphas, rng)`: for `(N, 3)` poses and
# `u = (prev_odom, odom)`, turn the two odometry poses into
# $(\delta_{rot1}, \delta_{trans}, \delta_{rot2})$, perturb each with zero-mean
# Gaussian noise of *variance* $\alpha_1\delta_{rot1}^2 + \alpha_2\delta_{trans}^2$,
# $\alpha_3\delta_{trans}^2 + \alpha_4(\delta_{rot1}^2 + \delta_{rot2}^2)$ and
# $\alpha_1\delta_{rot2}^2 + \alpha_2\delta_{trans}^2$ (Probabilistic Robotics,
# table 5.6), and move every pose. Use `rng` for all random numbers.
#
# `odometry_pdf(pose, u, prev_pose, alphas)` is the density of one pose
# over $(x, y, \theta)$: PR table 5.5 with the variances evaluated at the
# *measured* motion, divided by the hypothesised translation (the Jacobian).

# %% tags=["solution"]
def _control(prev, cur, theta):
    rot1 = wrap_angle(math.atan2(cur[1] - prev[1], cur[0] - prev[0]) - theta)
    trans = math.hypot(cur[0] - prev[0], cur[1] - prev[1])
    return rot1, trans


def sample_odometry(poses, u, alphas, rng):
    """Draw successor poses from the odometry motion model."""
    a1, a2, a3, a4 = alphas
    prev, cur = (np.asarray(v, dtype=float) for v in u)
    rot1, trans = _control(prev, cur, prev[2])
    rot2 = wrap_angle(cur[2] - prev[2] - rot1)
    poses = np.asarray(poses, dtype=float)
    n = len(poses)
    r1 = rot1 - rng.normal(0.0, math.sqrt(a1 * rot1**2 + a2 * trans**2), n)
    tr = trans - rng.normal(0.0, math.sqrt(a3 * trans**2 + a4 * (rot1**2 + rot2**2)), n)
    r2 = rot2 - rng.normal(0.0, math.sqrt(a1 * rot2**2 + a2 * trans**2), n)
    x = poses[:, 0] + tr * np.cos(poses[:, 2] + r1)
    y = poses[:, 1] + tr * np.sin(poses[:, 2] + r1)
    return np.column_stack([x, y, wrap_angle(poses[:, 2] + r1 + r2)])


def _gauss(a, var):
    return math.exp(-0.5 * a * a / var) / math.sqrt(2 * math.pi * var)


def odometry_pdf(pose, u, prev_pose, alphas):
    """Density of `pose` given the odometry `u` and the previous pose, over (x, y, theta)."""
    a1, a2, a3, a4 = alphas
    prev, cur = (np.asarray(v, dtype=float) for v in u)
    rot1, trans = _control(prev, cur, prev[2])
    rot2 = wrap_angle(cur[2] - prev[2] - rot1)
    rot1_h, trans_h = _control(prev_pose, pose, prev_pose[2])
    rot2_h = wrap_angle(pose[2] - prev_pose[2] - rot1_h)
    p = (_gauss(wrap_angle(rot1 - rot1_h), a1 * rot1**2 + a2 * trans**2)
         * _gauss(trans - trans_h, a3 * trans**2 + a4 * (rot1**2 + rot2**2))
         * _gauss(wrap_angle(rot2 - rot2_h), a1 * rot2**2 + a2 * trans**2))
    return p / trans_h


# %%
print(check.sample_odometry(sample_odometry))
print(check.odometry_pdf(odometry_pdf))

# %% [markdown]
# ## 5. The beam model (chapter 5)
#
# `beam_pdf(z, z_expected, params)`: the density of one range reading `z` given
# the expected range, the mixture of PR section 6.3 with every component a
# normalised density: a Gaussian truncated to $[0, z_{max}]$, an exponential
# truncated to $[0, z^*]$, a point mass at $z_{max}$ and a uniform on
# $[0, z_{max})$. `params` holds `z_hit, z_short, z_max, z_rand, sigma_hit,
# lambda_short, max_range`.
#
# `scan_log_likelihood(ranges, expected, params)`: the log-likelihood of a
# whole scan, assuming the beams are independent.

# %% tags=["solution"]
def beam_pdf(z, z_expected, params):
    """Beam-model density of one reading."""
    zmax, s, lam = params["max_range"], params["sigma_hit"], params["lambda_short"]
    if z >= zmax:
        return params["z_max"]
    mass = 0.5 * (math.erf((zmax - z_expected) / (s * math.sqrt(2))) - math.erf(-z_expected / (s * math.sqrt(2))))
    p_hit = math.exp(-0.5 * ((z - z_expected) / s) ** 2) / (s * math.sqrt(2 * math.pi)) / mass
    p_short = lam * math.exp(-lam * z) / (1 - math.exp(-lam * z_expected)) if z <= z_expected else 0.0
    return params["z_hit"] * p_hit + params["z_short"] * p_short + params["z_rand"] / zmax


def scan_log_likelihood(ranges, expected, params):
    """Sum of the beams' log-densities."""
    return float(sum(math.log(beam_pdf(z, e, params)) for z, e in zip(ranges, expected)))


# %%
print(check.beam_model(beam_pdf))
print(check.scan_log_likelihood(scan_log_likelihood))

# %% [markdown]
# ## 6. Resampling (chapter 6)
#
# `low_variance_sampler(weights, rng)`: the low-variance (systematic)
# resampler of PR table 4.4, returning the indices of the chosen particles.
# `multinomial_resampler(weights, rng)`: $N$ independent draws.
# `effective_sample_size(weights)`: $1/\sum_i w_i^2$ for normalised weights.

# %% tags=["solution"]
def low_variance_sampler(weights, rng):
    """Systematic resampling: one random offset, N equally spaced pointers."""
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    n = len(w)
    cumulative = np.cumsum(w)
    cumulative[-1] = 1.0  # guard against a sum that rounds below one
    pointers = rng.uniform(0.0, 1.0 / n) + np.arange(n) / n
    # r + (n-1)/n can round up to exactly 1.0: clip so it still finds the last particle
    return np.minimum(np.searchsorted(cumulative, pointers, side="right"), n - 1)


def multinomial_resampler(weights, rng):
    """N independent spins of the roulette wheel."""
    w = np.asarray(weights, dtype=float)
    cumulative = np.cumsum(w / w.sum())
    cumulative[-1] = 1.0
    return np.minimum(np.searchsorted(cumulative, rng.random(len(w)), side="right"), len(w) - 1)


def effective_sample_size(weights):
    """Kong-Liu-Wong effective sample size."""
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    return 1.0 / float(np.sum(w**2))


# %%
print(check.low_variance_sampler(low_variance_sampler))
print(check.resampler(multinomial_resampler, scheme="multinomial"))
print(check.effective_sample_size(effective_sample_size))

# %% [markdown]
# ## 7. One step of Monte Carlo Localization (chapter 7)
#
# `mcl_step(particles, u, ranges, angles, motion, sensor, rng)`: move every
# particle with `motion(particles, u, rng)`, weight it with the
# **log**-likelihoods `sensor(particles, ranges, angles)`, and resample $N$
# particles in proportion to the weights. Log-likelihoods of real scans are
# in the hundreds or thousands below zero: exponentiate them safely.

# %% tags=["solution"]
def mcl_step(particles, u, ranges, angles, motion, sensor, rng):
    """Predict, weight (in log space) and resample."""
    moved = motion(particles, u, rng)
    log_w = sensor(moved, ranges, angles)
    w = np.exp(log_w - np.max(log_w))
    return moved[low_variance_sampler(w, rng)]


# %%
check.mcl_step(mcl_step)
