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
# *Teachers:* this is the solutions source, kept outside the student's folder.
# `python tools/make_homework.py` generates from it the student notebook
# `book/homework/homework.ipynb` (the body of every function in a cell tagged
# `solution` becomes `raise NotImplementedError`; cells tagged `teacher` are
# dropped) and the otter-grader assignment `teacher/otter/homework.ipynb`.
# Grade a class with `python -m localize.grade SUBMISSIONS --out grades/`
# (chapter 12, "Teaching with this book").

# %%
import math
from pathlib import Path

import numpy as np

from localize import check, io
from localize.ekf import landmark_jacobian, landmark_measurement
from localize.geometry import wrap_angle
from localize.kld import bin_keys, kld_bound

# %% [markdown]
# ## 0. Which cell is a point in? (preface)
#
# Write `world_to_cell(points, origin, resolution)`: for `(N, 2)` world points
# `(x, y)`, a map origin `(x0, y0)` and cells of `resolution` metres, return the
# `(N, 2)` **integer** array of `(row, column)` indices in the convention of
# `localize.OccupancyGrid`: column $j$ covers $x_0 + j r \le x < x_0 + (j+1) r$
# and row $i$ covers $y_0 + i r \le y < y_0 + (i+1) r$ (rows grow with $y$).

# %% tags=["solution"]
def world_to_cell(points, origin, resolution):
    """(row, column) of the cells holding each point."""
    rel = (np.asarray(points, dtype=float) - np.asarray(origin, dtype=float)) / resolution
    return np.floor(rel[:, ::-1]).astype(int)


# %%
check.world_to_cell(world_to_cell)

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
# table 5.6), and move every pose. Use `rng` for all random numbers. Two motions
# need care, and the check tests both: a **turn on the spot** (no translation:
# $\operatorname{atan2}(0, 0)$ means nothing, so $\delta_{rot1} = 0$ and
# $\delta_{rot2}$ is the whole turn, as chapter 4 does) and a **move backwards**
# ($\delta_{rot1}$ near $\pm\pi$: wrap the angles before computing the variances).
#
# `odometry_pdf(pose, u, prev_pose, alphas)` is the density of one pose
# over $(x, y, \theta)$: PR table 5.5 with the variances evaluated at the
# *measured* motion, divided by the hypothesised translation (the Jacobian).

# %% tags=["solution"]
def _control(prev, cur, theta):
    trans = math.hypot(cur[0] - prev[0], cur[1] - prev[1])
    if trans < 1e-9:  # a turn on the spot: atan2(0, 0) means nothing, the whole turn is rot2
        return 0.0, trans
    return wrap_angle(math.atan2(cur[1] - prev[1], cur[0] - prev[0]) - theta), trans


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
# A reading at max range follows chapter 5's convention (that of PR table 6.1
# and of `localize.sensors.BeamModel`): a reading beyond `max_range` counts as
# `max_range`, and there the point mass `z_max` is *added* to the continuous
# densities at that reading (the hit Gaussian, and the short part if
# $z^* = z_{max}$); the uniform part is zero there.
#
# `scan_log_likelihood(ranges, expected, params)`: the log-likelihood of a
# whole scan, assuming the beams are independent.

# %% tags=["solution"]
def beam_pdf(z, z_expected, params):
    """Beam-model density of one reading."""
    zmax, s, lam = params["max_range"], params["sigma_hit"], params["lambda_short"]
    z, z_expected = min(z, zmax), min(z_expected, zmax)  # beyond max range = no return = max range
    mass = 0.5 * (math.erf((zmax - z_expected) / (s * math.sqrt(2))) - math.erf(-z_expected / (s * math.sqrt(2))))
    p_hit = math.exp(-0.5 * ((z - z_expected) / s) ** 2) / (s * math.sqrt(2 * math.pi)) / mass
    p_short = lam * math.exp(-lam * z) / (1 - math.exp(-lam * z_expected)) if z <= z_expected else 0.0
    # at max range: the point mass z_max, added to the densities there; below it: the uniform density
    rest = params["z_max"] if z >= zmax else params["z_rand"] / zmax
    return params["z_hit"] * p_hit + params["z_short"] * p_short + rest


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

# %% [markdown]
# ## 8. The correction step of grid localization (chapter 3)
#
# `grid_update(belief, expected, beam_bins, ranges, beam_pdf)`: the belief and
# the expected ranges are `(K, H, W)` arrays over heading bin, row and column;
# `expected[k, i, j]` is the range seen from cell `(i, j)` along the *absolute*
# heading bin `k`. Beam `b` sits `beam_bins[b]` bins to the left of the robot's
# heading, so for a robot in bin `k` it looks along bin `(k + beam_bins[b]) % K`.
# Return the posterior: the belief times the product over beams of
# `beam_pdf(ranges[b], expected_along_that_beam)`, normalised. A scan of
# hundreds of beams underflows as a product: add logs.

# %% tags=["solution"]
def grid_update(belief, expected, beam_bins, ranges, beam_pdf):
    """Multiply the (K, H, W) belief by the scan likelihood, in log space, and normalise."""
    k = np.arange(belief.shape[0])
    log_lik = np.zeros(belief.shape)
    for b, z in zip(beam_bins, ranges):
        log_lik += np.log(beam_pdf(z, expected[(k + b) % len(k)]))
    posterior = np.asarray(belief, dtype=float) * np.exp(log_lik - log_lik.max())
    return posterior / posterior.sum()


# %%
check.grid_update(grid_update)

# %% [markdown]
# ## 9. When to inject random particles: augmented MCL (chapter 8)
#
# `injection(likelihoods, w_slow, w_fast, alpha_slow, alpha_fast)`: given the
# measurement likelihoods $p(z \mid x_i)$ of the (equally weighted) particles,
# update the long- and short-term averages of PR table 8.3 and return
# `(w_slow, w_fast, p_inject)` with $p_{inject} = \max(0, 1 - w_{fast}/w_{slow})$.
# Which average of the likelihoods is it, and why not of the normalised weights?

# %% tags=["solution"]
def injection(likelihoods, w_slow, w_fast, alpha_slow, alpha_fast):
    """One update of augmented MCL's averages and the injection probability."""
    w_avg = float(np.mean(likelihoods))  # raw likelihoods: normalised weights always average 1/N
    w_slow += alpha_slow * (w_avg - w_slow)
    w_fast += alpha_fast * (w_avg - w_fast)
    return w_slow, w_fast, max(0.0, 1.0 - w_fast / w_slow)


# %%
check.injection(injection)

# %% [markdown]
# ## 10. Reading a ROS map picture (chapter 9)
#
# `map_image(image, negate)`: `image` is a `map_server` picture as stored in its
# PGM file, an `(H, W)` array of grey values 0-255 whose **first row is the top**
# of the map. Return occupancy in `localize.OccupancyGrid`'s convention (row 0
# at the bottom): $p = (255 - v)/255$ ($v/255$ when `negate`), 1.0 where
# $p > 0.65$, 0.0 where $p < 0.196$, NaN (unknown) in between.

# %% tags=["solution"]
def map_image(image, negate):
    """Occupancy (1 wall, 0 free, NaN unknown) of a map_server picture, row 0 = the bottom of the map."""
    v = np.asarray(image, dtype=float)
    p = v / 255.0 if negate else (255.0 - v) / 255.0
    occupancy = np.full(p.shape, np.nan)
    occupancy[p > 0.65] = 1.0
    occupancy[p < 0.196] = 0.0
    return np.flipud(occupancy)


# %%
check.map_image(map_image)

# %% [markdown]
# ## 11. One EKF correction with a landmark (chapter 10)
#
# `ekf_update(mean, cov, z, landmark, Q)`: the pose belief $\mathcal N(\mu, \Sigma)$,
# a range-bearing sighting `z` of the landmark at `landmark = (m_x, m_y)` with
# noise covariance `Q`. Return the corrected `(mean, cov)` (PR table 7.2, lines
# 12-21). `localize.ekf.landmark_measurement` and `landmark_jacobian` give
# $\hat z$ and $H$ if you want them.

# %% tags=["solution"]
def ekf_update(mean, cov, z, landmark, Q):
    """EKF measurement update with one range-bearing sighting."""
    from localize.ekf import landmark_jacobian, landmark_measurement

    H = landmark_jacobian(mean, landmark)
    S = H @ cov @ H.T + Q
    K = cov @ H.T @ np.linalg.inv(S)
    innovation = np.asarray(z, dtype=float) - landmark_measurement(mean, landmark)
    innovation[1] = wrap_angle(innovation[1])  # a bearing near +-pi
    new_mean = np.asarray(mean, dtype=float) + K @ innovation
    new_mean[2] = wrap_angle(new_mean[2])
    return new_mean, (np.eye(3) - K @ H) @ cov


# %%
check.ekf_update(ekf_update)

# %% [markdown]
# ## 12. A hallway with walls at both ends (chapter 1)
#
# `predict_stop(belief, kernel, offset)`: the prediction step of chapter 1 in a
# hallway of `n = len(belief)` cells that does **not** wrap around. The robot is
# commanded `offset` cells (positive towards higher indices) and ends `d` cells
# beyond the commanded cell with probability `kernel[c + d]`, where
# `c = len(kernel) // 2`. A move that would end beyond either end of the
# hallway ends in the end cell: the robot stops at the wall, so no belief is
# lost. Return a new array and leave `belief` unchanged. Why is it wrong to
# shift the whole belief first and blur it afterwards?

# %% tags=["solution"]
def predict_stop(belief, kernel, offset):
    """Prediction in a bounded hallway: moves that would pass an end stop in the end cell."""
    belief = np.asarray(belief, dtype=float)
    n, c = len(belief), len(kernel) // 2
    out = np.zeros(n)
    for src in range(n):
        for m, p in enumerate(kernel):   # shift and blur each source cell together, then clip
            out[min(max(src + offset + m - c, 0), n - 1)] += belief[src] * p
    return out


# %%
check.predict_stop(predict_stop)

# %% [markdown]
# ## 13. How many particles? The KLD stopping rule (chapter 8)
#
# `kld_count(samples, bin_size, epsilon, delta, n_min)`: `samples` is an
# `(M, 3)` array of candidate particles, drawn one after another. Walk through
# them as the loop of PR table 8.4 does (without its motion and sensor parts)
# and return the first `n` for which $n \ge n(k)$ and $n \ge n_{min}$, where `k`
# is the number of histogram bins of size `bin_size` that the first `n` samples
# occupy and $n(k)$ is `kld_bound(k, epsilon, delta)`; return `M` when no `n`
# qualifies. `bin_keys(samples, bin_size)` gives each sample's bin as one
# integer.

# %% tags=["solution"]
def kld_count(samples, bin_size, epsilon, delta, n_min):
    """Number of samples KLD-sampling draws before its stopping rule is met."""
    occupied = set()
    for n, key in enumerate(bin_keys(samples, bin_size).tolist(), start=1):
        occupied.add(key)   # this sample's bin counts before the test
        if n >= n_min and n >= kld_bound(len(occupied), epsilon, delta):
            return n
    return len(samples)     # the rule is never met: every candidate is needed


# %%
check.kld_loop(kld_count)

# %% [markdown]
# ## 14. A file-format trap: the XY log (chapter 9)
#
# `read_xy_log(path)`: read a made-up log whose every line is
# `SCAN t x y theta r1 ... rn`: time in seconds, the odometry pose (metres,
# metres, radians), then the ranges in **millimetres**, beams from +90° **down**
# to -90° (clockwise), `0` meaning "no return", from a scanner that reaches
# 30 m. Return an `io.LaserLog` in the book's conventions: ranges in metres,
# angles counter-clockwise from the robot's right (`-pi/2` ... `pi/2`), a
# reading of `max_range = 30.0` where there was no return. A line with another
# number of fields than the first scan raises
# `io.FormatError(path, line_number, message)`, lines counted from 1 (blank
# lines count).

# %% tags=["solution"]
def read_xy_log(path):
    """The XY log at `path` as an io.LaserLog in metres, counter-clockwise beams, 30 m for no return."""
    times, odometry, ranges = [], [], []
    for number, line in enumerate(Path(path).read_text().splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if fields[0] != "SCAN":
            raise io.FormatError(path, number, f"expected a SCAN record; got {fields[0]!r}")
        if ranges and len(fields) != 5 + len(ranges[0]):
            raise io.FormatError(path, number, f"expected {5 + len(ranges[0])} fields like the first scan; "
                                               f"got {len(fields)}")
        try:
            values = np.array(fields[1:], dtype=float)
        except ValueError:
            raise io.FormatError(path, number, "every field after SCAN must be a number") from None
        times.append(values[0])
        odometry.append(values[1:4])
        r = values[4:][::-1] / 1000.0               # clockwise -> counter-clockwise, mm -> m
        ranges.append(np.where(r == 0, 30.0, r))    # 0 is no return, not an obstacle at the sensor
    angles = np.linspace(-np.pi / 2, np.pi / 2, len(ranges[0]))
    return io.LaserLog(times=times, odometry=odometry, ranges=ranges, angles=angles, max_range=30.0,
                       source=str(path), format="xy")


# %%
check.xy_reader(read_xy_log)

# %% [markdown]
# ## 15. Innovation gating (chapter 10)
#
# `in_gate(mean, cov, z, landmark, Q)`: should the EKF use the range-bearing
# sighting `z` of the landmark at `landmark`, given the pose belief
# $\mathcal N(\mu, \Sigma)$ and the sensor noise `Q`? With $\hat z$ and $H$ at
# the mean (`landmark_measurement`, `landmark_jacobian`), the innovation
# $y = z - \hat z$ (bearing wrapped) and $S = H \Sigma H^\top + Q$, return True
# (keep it) when $y^\top S^{-1} y \le 9.21$, the 99% point of $\chi^2$ with two
# degrees of freedom. What does a gate protect the EKF against, and why does
# it keep a kidnapped robot lost?

# %% tags=["solution"]
def in_gate(mean, cov, z, landmark, Q):
    """Is the sighting inside the 99% innovation gate (chi-square, 2 dof)?"""
    H = landmark_jacobian(mean, landmark)
    y = np.asarray(z, dtype=float) - landmark_measurement(mean, landmark)
    y[1] = wrap_angle(y[1])
    S = H @ cov @ H.T + Q
    return bool(y @ np.linalg.solve(S, y) <= 9.21)


# %%
check.innovation_gate(in_gate)
