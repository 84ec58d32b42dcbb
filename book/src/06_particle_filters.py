# ---
# jupyter:
#   jupytext:
#     formats: ipynb,src//py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Particle filters
#
# A grid filter stores one probability per cell. That is exact enough when the
# cells are small, and hopeless when the state has three dimensions and the map is
# a building: an 800 x 800 map with 360 headings has 230 million cells. A
# **particle filter** stores instead a few hundred or thousand *guesses* of the
# state, the **particles**, and lets them move and multiply where the evidence
# says the robot is. It is the algorithm behind Monte Carlo Localization, the
# subject of the next two chapters.
#
# You will learn
#
# * how a **set of samples** represents a probability density, and how accurate
#   that representation is;
# * **importance sampling**: drawing from one distribution and *weighting* to
#   describe another;
# * **sequential importance resampling** (SIR), the particle filter, run on a
#   one-dimensional robot and checked against the exact Bayes filter;
# * the four common **resamplers** (multinomial, stratified, systematic,
#   residual), why they are all unbiased, and how much noise each adds;
# * how to **test** a resampler statistically, with two real bugs from a
#   popular library as the motivating example;
# * the **effective sample size** and adaptive resampling, and how the
#   "variance of the weights" rule of some implementations relates to it.
#
# The main reference is *Probabilistic Robotics* (Thrun, Burgard and Fox 2005,
# "PR" below), chapter 4.3. The particle filter itself goes back to Gordon,
# Salmond and Smith (1993) and, for robots, to Dellaert, Fox, Burgard and Thrun
# (1999).

# %%
import contextlib
import inspect

import matplotlib.pyplot as plt
import numpy as np
from filterpy.monte_carlo import resampling as fp_resampling
from scipy import stats

import localize
from localize import discrete
from localize import resample as rs
from localize.diagnostics import AlmostOne, exact_corridor_posteriors, ring_histogram, tv_distance
from localize.plot import particles as pp
from localize.sim import corridor_run
from localize.widgets.particles import sir_app, sir_figure

print("localize", localize.__version__)

# %% [markdown]
# ## A density as a cloud of samples
#
# Take a density $f(x)$ with two bumps, such as the belief of a robot that is
# either near one door or near another. Draw $N$ numbers at random from it. Where
# $f$ is high the draws fall densely, where $f$ is low they are sparse: the set of
# draws *is* a description of $f$. In the figure each tick below the axis is one
# draw, a **particle**; the shaded bars are their histogram, scaled to integrate
# to one.

# %%
rng = np.random.default_rng(6)
mix = [(0.35, -2.0, 0.6), (0.65, 1.5, 1.0)]         # (weight, mean, std) of each bump


def f(x):
    return sum(w * stats.norm.pdf(x, m, s) for w, m, s in mix)


def sample_f(n, rng):
    comp = rng.choice(len(mix), size=n, p=[w for w, _, _ in mix])
    means = np.array([m for _, m, _ in mix])[comp]
    stds = np.array([s for _, _, s in mix])[comp]
    return rng.normal(means, stds)


fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
for ax, n in zip(axes, (50, 2000)):
    pp.density_and_samples(f, sample_f(n, rng), (-5, 5), ax=ax, bins=40)
    ax.set_title(f"N = {n} samples of f", fontsize=10)
fig.tight_layout()
plt.show()

# %% [markdown]
# Anything we want to know about $f$ becomes an average over the particles. The
# probability that $x > 0$ is the fraction of particles with $x > 0$; the mean is
# the mean of the particles; in general
#
# $$ E_f[h(x)] = \int h(x) f(x)\,dx \;\approx\; \frac{1}{N} \sum_{i=1}^N h(x_i). $$
#
# How good is this? The average of $N$ independent draws has a standard deviation
# of $\sigma_h/\sqrt{N}$: ten times more particles buy about three times more
# accuracy, *whatever the dimension of $x$*. That last point is why sampling beats
# grids in three and more dimensions. We check the $1/\sqrt{N}$ law by repeating
# each estimate 200 times.

# %%
p_true = sum(w * stats.norm.sf(0, m, s) for w, m, s in mix)
mean_true = sum(w * m for w, m, _ in mix)
print(f"exact: P(x > 0) = {p_true:.4f}, E[x] = {mean_true:.4f}\n")
print(f"{'N':>6} | {'RMSE of P(x>0)':>14} | {'RMSE of E[x]':>12} | {'RMSE x sqrt(N)':>14}")
scaled = []
for n in (10, 100, 1000, 10000):
    est = np.array([(s > 0).mean() for s in (sample_f(n, rng) for _ in range(200))])
    est_m = np.array([sample_f(n, rng).mean() for _ in range(200)])
    e_p = np.sqrt(np.mean((est - p_true) ** 2))
    e_m = np.sqrt(np.mean((est_m - mean_true) ** 2))
    print(f"{n:>6} | {e_p:>14.4f} | {e_m:>12.4f} | {e_p * np.sqrt(n):>14.2f}")
    scaled.append(e_p * np.sqrt(n))
print(f"sqrt(p (1 - p)) = {np.sqrt(p_true * (1 - p_true)):.3f}")
# 200 repetitions estimate an RMSE to about 1/sqrt(2 * 200) = 5 % relative
assert all(abs(v / np.sqrt(p_true * (1 - p_true)) - 1) < 0.15 for v in scaled)

# %% [markdown]
# The last column stays put, around $\sqrt{p(1-p)} \approx 0.49$ (printed
# last), within the scatter that 200 repetitions leave (about 5 %): the error
# falls like $1/\sqrt{N}$.

# %% [markdown]
# ## Importance sampling
#
# A filter cannot draw from the posterior directly: that is what it is trying to
# find. It can draw from something easier, a **proposal** $g$, and correct with
# weights. Since
#
# $$ E_f[h(x)] = \int h(x) \frac{f(x)}{g(x)} g(x)\,dx = E_g\!\left[h(x)\,w(x)\right],
# \qquad w(x) = \frac{f(x)}{g(x)}, $$
#
# samples $x_i$ from $g$ with **importance weights** $w_i = f(x_i)/g(x_i)$
# represent $f$ just as well, provided $g > 0$ wherever $f > 0$. The weights only
# need to be known up to a constant: we normalise them to sum to one, and the
# estimate becomes $\sum_i \tilde w_i h(x_i)$. (PR section 4.3.3 derives the
# particle filter this way.)
#
# Below, the proposal is a wide normal distribution. The stems are the normalised
# weights: tall where $f$ is large relative to $g$.

# %%
N = 400
g_wide = stats.norm(0, 3)
x = g_wide.rvs(size=N, random_state=rng)
w = f(x) / g_wide.pdf(x)
w /= w.sum()

fig, ax = plt.subplots(figsize=(8, 3))
xs = np.linspace(-6, 6, 400)
ax.plot(xs, f(xs), "k", lw=2, label="target f")
ax.plot(xs, g_wide.pdf(xs), "tab:orange", lw=1.5, label="proposal g = N(0, 3²)")
ax2 = ax.twinx()
pp.weighted_samples(x, w, ax=ax2, label="weighted samples")
ax.legend(loc="upper left", fontsize=8)
ax.set_xlabel("x")
ax.set_xlim(-6, 6)
plt.show()
m_is = np.sum(w * x)
se_is = np.sqrt(np.sum(w * (x - m_is) ** 2) / rs.effective_sample_size(w))
print(f"importance estimate of E[x] = {m_is:.3f} +- {se_is:.3f} (one standard error); exact {mean_true:.3f}")
assert abs(m_is - mean_true) < 3 * se_is

# %% [markdown]
# How many particles are *really* working? If one particle had all the weight we
# would effectively have a single sample. The **effective sample size**
# (Kong, Liu and Wong 1994)
#
# $$ N_\text{eff} = \frac{1}{\sum_i \tilde w_i^2} $$
#
# is $N$ for equal weights and $1$ when one weight is one. A proposal that is too
# narrow, or in the wrong place, wastes particles: most of them get a tiny weight.

# %%
proposal_est = []
for name, g in [("N(0, 3²), wide", g_wide), ("N(1.5, 0.7²), too narrow", stats.norm(1.5, 0.7)),
                ("N(-3, 1²), in the wrong place", stats.norm(-3, 1))]:
    xg = g.rvs(size=N, random_state=rng)
    wg = f(xg) / g.pdf(xg)
    proposal_est.append(np.sum(wg * xg) / wg.sum())
    print(f"proposal {name:32s}: N_eff = {rs.effective_sample_size(wg):6.1f} of {N}, "
          f"estimate of E[x] = {proposal_est[-1]:6.3f}")
assert abs(proposal_est[1] - mean_true) > 1 and abs(proposal_est[2] - mean_true) > 1   # "their estimates are wrong"

# %% [markdown]
# The narrow proposal never visits the left bump and the misplaced one hardly
# visits the right bump, so their estimates are wrong, and nothing in the
# samples themselves says so. The lesson carries over to filters: when the motion model
# spreads particles too little, the measurement finds too few good ones.

# %% [markdown]
# ## Sequential importance resampling: the particle filter
#
# A Bayes filter alternates a prediction (motion) and a correction (measurement).
# The particle filter does the same with samples (PR table 4.3):
#
# 1. **Predict.** Move every particle by sampling the motion model,
#    $x_t^{[i]} \sim p(x_t \mid u_t, x_{t-1}^{[i]})$. The particles now sample the
#    prediction $\overline{bel}(x_t)$: this is the proposal.
# 2. **Weight.** The target is the posterior
#    $bel(x_t) \propto p(z_t \mid x_t)\,\overline{bel}(x_t)$, so the importance
#    weight is target over proposal: the measurement likelihood,
#    $w^{[i]} = p(z_t \mid x_t^{[i]})$.
# 3. **Resample.** Draw $N$ particles from the weighted set, each with probability
#    equal to its weight, and forget the weights. Particles in unlikely places
#    die, likely ones multiply.
#
# Our test robot lives on the hallway of the chapter on the Bayes filter, made
# continuous and closed into a ring: 20 m long, doors at 2, 5 and 13 m. Each step
# it is told to move 1 m and moves $1 + \mathcal{N}(0, 0.2^2)$ m; its door
# detector says "door" with probability 0.8 in front of a door and 0.1 in front of
# a wall. `localize.sim.corridor_run` simulates it.

# %%
run = corridor_run(np.random.default_rng(11), n_steps=25)
print("true positions:", run.positions[:6].round(2), "...")
print("readings      :", run.z[:12], "...")

# %% [markdown]
# Here is the whole filter, written out with the library's pieces: the motion
# sampler and likelihood of the run, log-weights normalised with log-sum-exp
# (`rs.normalize_log_weights`, see the box below), and the systematic resampler.

# %%
def particle_filter(run, n, rng):
    x = rng.uniform(0, run.length, n)                    # uniform prior: the robot is lost
    history = []
    for k in range(len(run)):
        if k > 0:
            x = run.move(x, run.controls[k], rng)        # 1. predict: sample the motion model
        logw = run.log_likelihood(x, run.z[k])           # 2. weight by the measurement likelihood
        w, _ = rs.normalize_log_weights(logw)
        history.append((x.copy(), w))
        x = x[rs.systematic(w, rng)]                     # 3. resample
    return history


history = particle_filter(run, 1000, np.random.default_rng(1))

# %% [markdown]
# ```{admonition} Why log-weights?
# A laser scan has hundreds of beams and the likelihood of a scan is the product
# of theirs: numbers like $10^{-400}$, which underflow to zero in floating point.
# Filters therefore keep $\log w$ and normalise with the *log-sum-exp* trick:
# subtract the largest log-weight before exponentiating, so the best particle gets
# $e^0 = 1$ and nothing overflows. If *every* log-weight is $-\infty$ (no particle
# explains the reading), `normalize_log_weights` returns uniform weights and flags
# the case with `log_norm = -inf` (or raises `DegenerateWeightsError` with
# `strict=True`), so the filter can react instead of producing NaN.
# ```

# %%
w_demo, log_norm = rs.normalize_log_weights([-1200.0, -1201.0, -1205.0])
print("weights from log-weights -1200, -1201, -1205:", w_demo.round(4), f"log-norm {log_norm:.3f}")
print("nothing fits:", rs.normalize_log_weights([-np.inf, -np.inf, np.nan]))

# %% [markdown]
# The same loop is `localize.resample.bootstrap_filter`, which also records the
# effective sample size and supports adaptive resampling; with the same seed it
# produces exactly the same particles.

# %%
steps = [(None if k == 0 else run.controls[k], run.z[k]) for k in range(len(run))]
rng_a = np.random.default_rng(1)
prior = rng_a.uniform(0, run.length, 1000)
res = rs.bootstrap_filter(prior, steps, run.move, run.log_likelihood, rng_a, threshold=1.0)
same = all(np.array_equal(h[0], p) for h, p in zip(history, res.particles))
print("hand-written loop and bootstrap_filter agree:", same)

# %% [markdown]
# Watch the belief: uniform at first, then several bumps (every place where the
# readings so far would fit), then one bump that dominates. But look where it
# is: at steps 5 and 9 it sits some 3 m ahead of the robot (red line), and only
# at the last step is it on the robot. The filter is not broken; the readings
# misled it, as the next section shows. Doors are shaded.

# %%
fig, axes = plt.subplots(5, 1, figsize=(8, 6.5), sharex=True)
for ax, k in zip(axes, (0, 2, 5, 9, 24)):
    pp.corridor_belief(run, history[k][0], history[k][1], k, ax=ax)
axes[-1].set_xlabel("position on the ring [m]")
fig.tight_layout()
plt.show()

# %% [markdown]
# ### Is it right? Compare with the exact Bayes filter
#
# On a one-dimensional world we can compute the exact posterior with the grid
# filter of the Bayes-filter chapter on cells of 5 cm (`localize.discrete`), and
# measure how far the particle belief is from it: the **total variation
# distance**, half the summed absolute difference of the probability per 1 m
# cell (0 = identical, 1 = disjoint). Both live in `localize.diagnostics`; here
# is the exact filter's loop (a Gaussian motion kernel out to 3 standard
# deviations, the door likelihood of each reading, and the belief summed per
# metre):

# %%
print(inspect.getsource(exact_corridor_posteriors).split('"""')[-1])

# %%
def tv_distance_to(exact, particles, weights):
    """TV distance between the exact belief and the particles', per 1 m cell of the ring."""
    return tv_distance(exact, ring_histogram(particles, weights, run.length))


exact = exact_corridor_posteriors(run)
tv_by_n = []
print(f"{'N':>6} | TV distance at step 5 | at step 24   (mean of 10 runs)")
for n in (30, 100, 300, 1000, 3000):
    tvs = []
    for seed in range(10):
        h = particle_filter(run, n, np.random.default_rng(100 + seed))
        tvs.append([tv_distance_to(exact[k], *h[k]) for k in (5, 24)])
    t5, t24 = np.mean(tvs, axis=0)
    print(f"{n:>6} | {t5:21.3f} | {t24:10.3f}")
    tv_by_n.append((n, t5, t24))
n_tv, t5_tv, t24_tv = np.array(tv_by_n).T
slope5 = np.polyfit(np.log(n_tv), np.log(t5_tv), 1)[0]
print(f"slope of log TV against log N at step 5: {slope5:.2f} (1/sqrt(N) would be -0.5)")
assert -0.65 < slope5 < -0.35 and np.all(np.diff(t24_tv) < 0)

# %% [markdown]
# The particle filter converges to the Bayes filter: the distance falls roughly
# like $1/\sqrt{N}$. With 30 particles it is a rough sketch, with a few
# thousand it is close to exact.
#
# So the exact filter tells us what to make of the misplaced bump above. At the
# steps in the figure, compare where each puts its peak, and what the robot
# read:

# %%
def offset(a, b, length):
    """Signed distance from b to a on the ring."""
    return (a - b + length / 2) % length - length / 2


door_cell = np.asarray(run.doors)
for k in (5, 9, 24):
    pf_hist = np.bincount(np.floor(history[k][0]).astype(int) % int(run.length), weights=history[k][1],
                          minlength=int(run.length))
    pf_peak, ex_peak = pf_hist.argmax() + 0.5, exact[k].argmax() + 0.5
    print(f"step {k:2d}: particle peak {offset(pf_peak, run.positions[k], run.length):+.1f} m from the robot, "
          f"exact filter's peak {offset(ex_peak, run.positions[k], run.length):+.1f} m")
    assert pf_peak == ex_peak
    assert (abs(offset(pf_peak, run.positions[k], run.length)) > 2) == (k != 24)
wrong = [(k, "missed a door" if run.z[k] == 0 else "saw a door that is not there")
         for k in range(10) if run.z[k] != door_cell[int(run.positions[k] % run.length)]]
print("wrong readings in the first ten steps:", wrong)
assert wrong == [(2, "missed a door"), (3, "missed a door"), (7, "saw a door that is not there")]

# %% [markdown]
# Both filters put the peak in the same wrong place: at steps 2 and 3, both
# inside the door at 5 m, the detector missed it; at step 7 it reported a door
# where there is none; and
# the belief follows the evidence — a door seen 3 m too early is best explained
# by a robot 3 m further on. That is what a correct filter does with a 0.8 / 0.1
# detector; only later readings (more doors, seen where they are) bring the
# peak back to the robot by step 24.

# %% [markdown]
# ## Resampling, four ways
#
# Step 3 needs $N$ indices drawn so that particle $i$ is picked with probability
# $\tilde w_i$. Every scheme below is **unbiased**: particle $i$ gets on average
# exactly $N \tilde w_i$ copies ("offspring"). They differ in how much the actual
# number of copies *varies* around that average, i.e. how much extra noise
# resampling injects. Picture the normalised weights laid end to end on $[0, 1)$
# (the bottom row of the figure); each scheme places $N$ pointers and particle
# $i$ gets one copy per pointer that lands in its segment.
#
# * **Multinomial** — the *roulette wheel* of many lecture notes: $N$ independent
#   uniform pointers, one spin of the wheel per new particle.
# * **Stratified** (Kitagawa 1996) — split $[0,1)$ into $N$ equal strata and draw
#   one uniform pointer in each.
# * **Systematic** — one random offset $r \in [0, 1/N)$ and pointers
#   $r, r + 1/N, r + 2/N, \dots$: the **low-variance sampler** of PR table 4.4.
#   Particle $i$ then gets either $\lfloor N\tilde w_i \rfloor$ or
#   $\lceil N\tilde w_i \rceil$ copies.
# * **Residual** (Liu and Chen 1998) — first give each particle
#   $\lfloor N\tilde w_i \rfloor$ copies for certain, then fill the few remaining
#   places at random in proportion to the leftover fractions.

# %%
w10 = np.random.default_rng(3).random(10) ** 2
w10 /= w10.sum()
n10 = w10.size
prng = np.random.default_rng(4)
pointers = {
    "multinomial": np.sort(prng.random(n10)),
    "stratified": (prng.random(n10) + np.arange(n10)) / n10,
    "systematic": (prng.random() + np.arange(n10)) / n10,
}
fig, ax = plt.subplots(figsize=(8, 2.6))
pp.resampling_pointers(w10, pointers, ax=ax)
fig.tight_layout()
plt.show()

# %% [markdown]
# Multinomial pointers can bunch up and leave heavy particles unpicked; systematic
# ones cannot. (`rs.multinomial_loop` is the roulette wheel written out: one spin
# `u = rng.random()` per new particle, then a walk along the slices until their
# running sum passes `u`.) Each scheme exists in `localize.resample` twice: a readable loop
# that mirrors the pseudocode (the *test oracle*) and a fast vectorised version.
# Here is the readable low-variance sampler: compare it line by line with PR
# table 4.4.

# %%
print(inspect.getsource(rs.systematic_loop).split('"""')[-1])

# %% [markdown]
# A word on notation first. The code draws `r = rng.random()` in $[0, 1)$ and
# places pointer `m` at `(r + m) / n`; the offset of the text and of PR, in
# $[0, 1/N)$, is that `r` divided by $N$. The pointers are the same. In this
# chapter $r$ always means the offset in $[0, 1/N)$: the offset $r = 0.125$
# with $N = 4$ is `rng.random()` returning $0.5$.
#
# Two details differ from the printed pseudocode, both deliberate. The loop
# advances while `u >= c` instead of `u > c`, so a particle of weight zero can
# never be chosen even if $r$ happens to be exactly 0; and it never steps past the
# last particle with positive weight, however the running sum rounds. The fast
# version gives identical indices for the same random numbers:

# %%
for name in ("stratified", "systematic"):
    a = getattr(rs, name)(w10, np.random.default_rng(5))
    b = getattr(rs, name + "_loop")(w10, np.random.default_rng(5))
    print(f"{name:10s} fast {a}\n{'':10s} loop {b}  equal: {np.array_equal(a, b)}")

# %% [markdown]
# ### How much noise does each resampler add?
#
# We resample the ten weights above 5000 times with each scheme and record each
# particle's number of copies. The mean should be $N \tilde w_i$; the variance for
# multinomial resampling is the binomial $N \tilde w_i (1 - \tilde w_i)$.

# %%
reps = 5_000                     # standard errors of the mean counts: 0.01 to 0.02 copies
moments = {name: rs.offspring_moments(name, w10, reps, np.random.default_rng(7)) for name in rs.RESAMPLERS}
print(f"{'resampler':12s} | {'max |mean - Nw|':>15s} | {'max z-score':>11s} | {'total variance':>14s}")
for name, (mean, var) in moments.items():
    z = np.abs(mean - n10 * w10) / np.sqrt(np.maximum(var, 1 / reps) / reps)
    print(f"{name:12s} | {np.max(np.abs(mean - n10 * w10)):15.4f} | {z.max():11.2f} | {var.sum():14.3f}")
print(f"{'theory, mult.':12s} | {'':15s} | {'':11s} | {np.sum(n10 * w10 * (1 - w10)):14.3f}")
total_var = {name: var.sum() for name, (_, var) in moments.items()}
assert all(total_var[k] < total_var["multinomial"] / 3 for k in ("stratified", "systematic", "residual"))
assert min(total_var, key=total_var.get) == "systematic"

fig, ax = plt.subplots(figsize=(8, 3))
pp.offspring_variance_bars(w10, {k: v for k, (_, v) in moments.items()}, ax=ax)
ax.set_title("offspring-count variance per particle (N = 10)", fontsize=10)
fig.tight_layout()
plt.show()

# %% [markdown]
# All four are unbiased (every z-score is a few units at most). Multinomial
# resampling matches its theory and adds by far the most noise; systematic,
# stratified and residual each add less than a third of it here, systematic the
# least. Douc,
# Cappé and Moulines (2005) prove the ordering for stratified and residual
# against multinomial. In practice **systematic** is the default: lowest noise
# in most cases, one random number, and the fastest.
#
# Speed matters when a filter resamples every step. `benchmarks/bench_resample.py`
# times the four on $10^6$ particles against filterpy's implementations; on our
# 2-core machine the vectorised systematic resampler runs about 10 times faster
# than filterpy's Python loop, and each of ours beats its filterpy counterpart.
# (Run it yourself: `python benchmarks/bench_resample.py`.)

# %% [markdown]
# ## A lesson in testing resamplers
#
# A resampler can return perfectly valid indices and still be wrong: wrong in
# *distribution*. Such bugs survive any test that only looks at one draw. The
# widely used filterpy library (version 2.0.0) had two.
#
# **Bias in residual resampling.** The residual scheme keeps
# $\lfloor N w_i \rfloor$ copies and should draw the rest in proportion to the
# fractions $N w_i - \lfloor N w_i \rfloor$. filterpy subtracts the copies from
# $w_i$ instead of $N w_i$. For the weights $[0.5, 0.3, 0.15, 0.05]$ that makes the
# first two "fractions" negative and the last two vanish from the draw. A
# statistical test finds it at once: resample many times and compare the mean
# number of copies with $N w_i$, allowing a few standard errors.
#
# filterpy draws its random numbers from numpy's *global* generator. To keep this
# page reproducible we hand it our own generator while we call it.

# %%
@contextlib.contextmanager
def filterpy_uses(rng):
    """Temporarily make filterpy's resamplers draw from ``rng`` (they use numpy's global state)."""
    saved = fp_resampling.random
    fp_resampling.random = rng.random
    try:
        yield
    finally:
        fp_resampling.random = saved


w4 = np.array([0.5, 0.3, 0.15, 0.05])
reps = 5_000                     # standard error of a mean count: at most 0.5 / sqrt(5000) = 0.007 copies
with filterpy_uses(np.random.default_rng(8)):
    fp_counts = np.array([np.bincount(fp_resampling.residual_resample(w4), minlength=4) for _ in range(reps)])
ours_mean, ours_var = rs.offspring_moments("residual", w4, reps, np.random.default_rng(8))
fp_mean = fp_counts.mean(axis=0)
print("expected N*w            :", 4 * w4)
print("ours, mean offspring    :", ours_mean.round(3))
print("filterpy, mean offspring:", fp_mean.round(3))
se = np.sqrt(np.maximum(fp_counts.var(axis=0, ddof=1), 1 / reps) / reps)
print("filterpy z-scores       :", (np.abs(fp_mean - 4 * w4) / se).round(0))
# every count is at least 5 standard errors from N w, and within 5 of what filterpy's formula gives (see below)
assert np.all(np.abs(fp_mean - 4 * w4) > 5 * se) and np.all(np.abs(fp_mean - [2.75, 1.25, 0, 0]) < 5 * se)
assert np.all(np.abs(ours_mean - 4 * w4) < 5 * np.sqrt(np.maximum(ours_var, 1 / reps) / reps))

fig, ax = plt.subplots(figsize=(6, 2.6))
idx = np.arange(4)
ax.bar(idx - 0.2, ours_mean, 0.4, color=pp.RESAMPLER_COLORS["residual"], label="localize residual")
ax.bar(idx + 0.2, fp_counts.mean(axis=0), 0.4, color=pp.RESAMPLER_COLORS["filterpy residual"],
       label="filterpy 2.0.0 residual")
ax.step(np.r_[idx - 0.5, 3.5], np.r_[4 * w4, 4 * w4[-1]], where="post", color="k", label="N w (unbiased)")
ax.set_xticks(idx)
ax.set_xlabel("particle")
ax.set_ylabel("mean offspring")
ax.legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# The heavy particles get too many copies (2.75 instead of 2 for the first) and
# the light ones none at all: a filter using it loses diversity faster than it
# should. The 2.75 follows from the bug: the copies are 2, 1, 0, 0, one particle
# is left to draw, and the "fractions" $w_i - \text{copies}_i$, divided by their
# sum $-2$, become $0.75, 0.35, -0.075, -0.025$, with the running sum
# $0.75, 1.1, 1.025, 1$: a uniform draw below 0.75 lands on particle 0, any
# other on particle 1. The extra copy goes to particle 0 three times in four
# (mean $2 + 0.75$), else to particle 1 ($1 + 0.25$). A z-score over a hundred
# for the first particle leaves no doubt; a correct resampler, like ours above,
# stays within a few units.
#
# **Running off the end.** filterpy's systematic and stratified resamplers walk
# along the cumulative sum of the weights until it passes each pointer. When the
# weights sum to *just below* one in floating point, as ten weights of 0.1 do, a
# pointer close to 1 is never passed and the index runs past the end of the
# array. We can provoke it with a generator whose uniform numbers are the largest
# double below one (`localize.diagnostics.AlmostOne`, a `numpy.random.Generator`
# whose `random` is overridden):

# %%
print(inspect.getsource(AlmostOne.random))
tenths = np.full(10, 0.1)
print(f"sum of ten 0.1 in floating point: {float(np.cumsum(tenths)[-1])!r}")
with filterpy_uses(AlmostOne(np.random.PCG64(0))):
    try:
        fp_resampling.systematic_resample(tenths)
    except IndexError as e:
        print("filterpy systematic_resample:", type(e).__name__, "-", e)
print("localize systematic         :", rs.systematic(tenths, AlmostOne(np.random.PCG64(0))))
almost = rs.systematic(tenths, AlmostOne(np.random.PCG64(0)))
pointer_8 = (np.nextafter(1.0, 0.0) + 7) / 10
print(f"pointer 8: {float(pointer_8)!r}; normalised running sum after particle 7: "
      f"{float(np.cumsum(tenths)[7] / np.cumsum(tenths)[-1])!r}")
assert np.bincount(almost, minlength=10).tolist() == [1, 1, 1, 1, 1, 1, 1, 0, 1, 2]

# %% [markdown]
# Ours divides the cumulative sum by its last element (which makes the last entry
# exactly 1.0) and clamps every index to the last particle with positive weight,
# so it returns ten valid indices. Look at them, though: particle 7 is missing
# and particle 9 appears twice, although every particle has $N w_i = 1$ and
# "floor or ceil" promises exactly one copy each. That promise holds in exact
# arithmetic. Here the eighth pointer, $(r + 7)/10$ with $r$ one rounding step
# below 1, rounds to exactly 0.8, the same double as the normalised running sum
# at the end of particle 7's segment (printed above): the pointer lands on the
# boundary and counts for particle 8, and every later pointer shifts by one. It
# takes an $r$ within a few rounding steps of such a boundary — a chance of the
# order of $10^{-15}$ per call — so it does not bias the filter, but a test that
# checks the floor-or-ceil property exactly must allow for it.
# Both cases are regression tests in `tests/test_resample.py`, next to the
# statistical tests every resampler must pass: valid indices for any weights
# (a property test with `hypothesis`), an offspring mean within five standard
# errors of $N w_i$, and lower offspring variance for systematic and stratified
# than for multinomial. A test is only worth having if it can fail: the same
# unbiasedness check, applied to filterpy's residual resampler, fails.

# %% [markdown]
# ## Effective sample size and adaptive resampling
#
# Resampling is not free. It throws particles away, and copies are identical, so
# the set loses **diversity**: after many rounds all particles may descend from a
# handful of ancestors. Never resampling is worse: the weights degenerate until
# one particle carries everything. Watch $N_\text{eff}$ on the corridor robot
# with 500 particles, never resampling (threshold 0) and resampling at every
# step (threshold 1).

# %%
fig, ax = plt.subplots(figsize=(8, 2.8))
run30 = corridor_run(np.random.default_rng(11), n_steps=30)
steps30 = [(None if k == 0 else run30.controls[k], run30.z[k]) for k in range(len(run30))]
for thr, color, label in [(0.0, "tab:red", "never resample"), (0.5, "tab:blue", "resample if N_eff < N/2"),
                          (1.0, "tab:green", "resample every step")]:
    rng_f = np.random.default_rng(2)
    r = rs.bootstrap_filter(rng_f.uniform(0, run30.length, 500), steps30, run30.move, run30.log_likelihood,
                            rng_f, threshold=thr)
    pp.ess_trace(r.ess, 500, r.resampled, ax=ax, color=color, label=label)
ax.axhline(250, color="0.4", ls="--", lw=1)
ax.legend(fontsize=8, loc="lower left")
fig.tight_layout()
plt.show()

# %% [markdown]
# Without resampling $N_\text{eff}$ collapses to a handful of particles within
# a few steps. The middle road is **adaptive resampling** (Liu and Chen 1995;
# Doucet, Godsill and Andrieu 2000): resample only when $N_\text{eff}$ falls below
# a threshold, typically $N/2$. `MCL` in the next chapter takes the threshold as
# `resample_threshold`.
#
# ### The weight-variance rule, and how it relates
#
# Some implementations resample when the **variance of the weights** exceeds a
# threshold instead, for example a CMU 16-831 homework report among this book's
# sources, which thresholded the standard deviation of the weights. The two
# rules are the same rule in disguise. For normalised weights (mean $1/N$), with
# the population variance
# $\operatorname{Var}(w) = \frac{1}{N}\sum_i (w_i - \tfrac1N)^2 = \frac{1}{N}\sum_i w_i^2 - \frac{1}{N^2}$,
#
# $$ \sum_i w_i^2 = N \operatorname{Var}(w) + \frac{1}{N}
# \quad\Longrightarrow\quad
# N_\text{eff} = \frac{1}{\sum_i w_i^2} = \frac{N}{1 + N^2 \operatorname{Var}(w)}. $$
#
# So "variance above $v$" is "$N_\text{eff}$ below $N/(1 + N^2 v)$". The catch is
# the $N^2$: the same variance threshold means something different for every
# particle count, while a threshold on $N_\text{eff}/N$ does not. A check on
# random weights, and the conversion of a standard-deviation threshold of
# $3 \times 10^{-5}$ (the order of magnitude the report used, with 800 to 1000
# particles):

# %%
wr = np.random.default_rng(9).random(1000) ** 3
wr /= wr.sum()
print(f"N_eff directly            : {rs.effective_sample_size(wr):.3f}")
print(f"N / (1 + N^2 Var(w))      : {rs.ess_from_weight_variance(rs.weight_variance(wr), 1000):.3f}")
fracs = {}
for n in (100, 800, 1000, 5000, 100_000):
    fracs[n] = rs.ess_from_weight_variance((3e-5) ** 2, n) / n
    print(f"std threshold 3e-5 with N = {n:7d}  <=>  resample when N_eff < {fracs[n]:.4f} N")
assert fracs[800] > 0.999 and fracs[1000] > 0.999 and fracs[100] > 0.9999 and abs(fracs[100_000] - 0.1) < 1e-3

# %% [markdown]
# If that report's weights were normalised, its threshold resampled whenever
# $N_\text{eff}$ dropped below 99.9 % of $N$, which is nearly every step; with
# fewer particles it triggers even more readily (99.999 % with 100), and only
# with about $10^5$ particles does the same number become a selective rule
# ($N_\text{eff} < 0.1\,N$). (If the weights were
# not normalised the number means something else again, which is the point.)
# The figure shows the general relation: the fraction $N_\text{eff}/N =
# 1/(1 + N^2 \operatorname{Var}(w))$ depends on the product
# $N \cdot \mathrm{std}(w)$ only, so one curve serves every $N$; a fixed
# threshold on $\mathrm{std}(w)$ slides along it as $N$ changes.

# %%
# N_eff / N = 1 / (1 + (N std)^2): one curve in N * std(w). The dots put the report's fixed threshold,
# std = 3e-5, on it for each N of the table above: only near N = 100,000 does it fall on the slope
fig, ax = plt.subplots(figsize=(6.5, 3.2))
x = np.logspace(-3, 1.5, 300)
ax.semilogx(x, [rs.ess_from_weight_variance((v / 1000) ** 2, 1000) / 1000 for v in x], color="tab:blue")
for n, frac in fracs.items():
    ax.plot(n * 3e-5, frac, "o", color="tab:red")
    ax.annotate(f"N = {n:,}", (n * 3e-5, frac), xytext=(4, -13 if n in (800, 5000) else 7),
                textcoords="offset points", fontsize=8, color="tab:red")
ax.axhline(0.5, color="0.5", ls="--", lw=1)
ax.text(1.2e-3, 0.53, "the usual rule: resample when N_eff < N/2", fontsize=8, color="0.4")
ax.set_xlabel("N x standard deviation of the normalised weights")
ax.set_ylabel("N_eff / N")
ax.set_ylim(-0.05, 1.18)
ax.set_title("red: the report's threshold std(w) = 3e-5 at each N", fontsize=9)
fig.tight_layout()
plt.show()

# %% [markdown]
# ### Does the threshold matter?
#
# We run the corridor filter with 200 particles for 40 steps on 30 different
# robots for each threshold, and compare its final belief with the exact
# posterior (total variation distance, as above). We also record how often it
# resampled and its final $N_\text{eff}$.

# %%
print(f"{'threshold':>9} | {'resamplings':>11} | {'final N_eff':>11} | {'TV to exact, mean':>17} | {'median':>6}")
tv_by_thr = {}
robots = [corridor_run(np.random.default_rng(200 + seed), n_steps=40) for seed in range(30)]  # once, for every threshold
exact_end = [exact_corridor_posteriors(rr)[-1] for rr in robots]
for thr in (0.0, 0.1, 0.5, 0.9, 1.0):
    n_res, ess_end, tvs = [], [], []
    for seed, (rr, ex) in enumerate(zip(robots, exact_end)):
        st = [(None if k == 0 else rr.controls[k], rr.z[k]) for k in range(len(rr))]
        rng_f = np.random.default_rng(seed)
        out = rs.bootstrap_filter(rng_f.uniform(0, rr.length, 200), st, rr.move, rr.log_likelihood, rng_f,
                                  threshold=thr)
        n_res.append(out.resampled.sum())
        ess_end.append(out.ess[-1])
        tvs.append(tv_distance(ex, ring_histogram(out.particles[-1], out.weights[-1], rr.length)))
    print(f"{thr:9.1f} | {np.mean(n_res):11.1f} | {np.mean(ess_end):11.1f} | {np.mean(tvs):17.3f} | "
          f"{np.median(tvs):6.3f}")
    tv_by_thr[thr] = np.mean(tvs)
assert tv_by_thr[0.0] > 2 * max(v for k, v in tv_by_thr.items() if k > 0)       # never resampling: far worse
assert max(tv_by_thr[k] for k in (0.5, 0.9, 1.0)) - min(tv_by_thr[k] for k in (0.5, 0.9, 1.0)) < 0.05

# %% [markdown]
# Never resampling is far worse than anything else: after 40 steps a handful of
# particles carry all the weight and the belief is a caricature of the posterior.
# Resampling rarely (threshold 0.1) already repairs most of that. On this problem,
# where the motion noise scatters the copies again at every step, resampling
# often is harmless, and thresholds from 0.5 to 1 do about equally well. When the
# motion noise is small, copies stay identical and frequent resampling costs
# diversity; the chapter on failures of MCL returns to this.

# %% [markdown]
# ## Try it
#
# The widget runs the corridor filter. Change the number of particles (try 10
# and 3000), the resampler, the resampling threshold and the motion noise; each
# setting of the seed is a different robot. The three top panels show the belief
# at steps 0, 4 and the last; below are the error of the estimate and
# $N_\text{eff}$ (circles mark resampling steps, the dashed line the threshold).

# %% tags=["nbval-ignore-output"]
sir_app()

# %% [markdown]
# For readers of the static book, the widget's default view:

# %%
sir_figure()

# %% [markdown]
# ## From a ring to a floor: a particle cloud in two dimensions
#
# Nothing in the filter above depended on the state being one number. On a
# floor a particle is a pose $(x, y, \theta)$ — a row of an `(N, 3)` array — the
# motion model is the odometry model of chapter 4 and the likelihood is a range
# sensor's (chapter 5; here the beam model, tempered as chapter 5 explains). The loop is the same three lines. Below, a robot in the office
# scans 36 beams at every step; the filter starts from 2000 particles spread
# uniformly over the free floor.

# %%
from localize import maps, motion  # noqa: E402
from localize.metrics import position_error  # noqa: E402
from localize.plot.mcl import draw_particles  # noqa: E402
from localize.plot import draw_map, draw_robot  # noqa: E402
from localize.sensors import BeamModel  # noqa: E402
from localize.sim import range_run  # noqa: E402

floor = maps.office()
BEAMS = np.linspace(-np.pi, np.pi, 36, endpoint=False)
field = BeamModel(floor, 8.0, sigma_hit=0.2, temper=0.05, method="lut")


def particle_filter_2d(run, n, rng):
    """The bootstrap filter of this chapter on poses: predict, weight, resample; returns the history."""
    x = floor.sample_free(n, rng)                                   # uniform over the free floor
    history = []
    for k in range(len(run)):
        if k > 0:
            x = motion.sample_odometry(x, run.control(k), run.alphas, rng, min_std=0.01)   # 1. predict
        w, _ = rs.normalize_log_weights(field.log_likelihood(x, run.ranges[k], BEAMS))    # 2. weight
        history.append((x.copy(), w))
        x = x[rs.systematic(w, rng)]                                                     # 3. resample
    return history


run_2d = range_run(floor, np.random.default_rng(14), n_steps=15, angles=BEAMS, max_range=8.0)
hist_2d = particle_filter_2d(run_2d, 2000, np.random.default_rng(15))

fig, axes = plt.subplots(1, 4, figsize=(13, 2.4))
for ax, k in zip(axes, (0, 1, 4, 14)):
    draw_map(floor, ax=ax)
    draw_particles(hist_2d[k][0], ax=ax, weights=hist_2d[k][1], size=2)
    draw_robot(run_2d.poses[k], ax=ax, radius=0.3, color="tab:blue")
    ax.set_title(f"step {k}", fontsize=9)
    ax.set_xlim(*floor.extent[:2])
    ax.set_ylim(*floor.extent[2:])
    ax.set_xticks([])
    ax.set_yticks([])
fig.tight_layout()
plt.show()
mean_2d = np.array([np.average(h[0][:, :2], axis=0, weights=h[1]) for h in hist_2d])
err_2d = np.hypot(*(mean_2d - run_2d.poses[:, :2]).T)
print(f"error of the weighted mean at steps 0, 4, 14: {err_2d[0]:.1f} m, {err_2d[4]:.1f} m, {err_2d[14]:.2f} m")
assert err_2d[0] > 2 and err_2d[14] < 0.3

# %% [markdown]
# The first scan fits many places a little; after resampling (step 1) the
# particles sit in small clumps wherever a wall arrangement matches, the
# motion model spreads each clump again, and every scan thins them out: by
# step 4 a handful of clumps remain, by step 14 one, on the robot.
# This is Monte Carlo Localization, the subject of the next chapter; the library
# version (`localize.mcl.MCL`) adds estimates, adaptive resampling and the
# repairs of chapter 8.
#
# ### Particle deprivation
#
# In one dimension a thousand particles covered 20 m densely. On a floor they
# must cover area *and* heading, and they thin out fast: 2000 particles over the
# office's 204 m² of free floor leave one particle per 0.1 m², each with a
# random heading. If, after the first resamplings, no particle is
# near the true pose, no later scan can help — the filter can only reweight the
# hypotheses it holds. This is **particle deprivation** (PR section 4.3.4 and
# 8.3.5). We measure how often it happens: eight robots, each filtered with
# 250, 1000 and 4000 particles for 20 steps, counting a run as lost if its
# estimate is more than 0.5 m off at the last step.

# %% tags=["nbval-ignore-output", "remove-output"]
# 24 runs of a 20-step global localization: a progress bar while they run (not stored)
from localize.metrics import progress  # noqa: E402

N_TRY, SEEDS_2D = (250, 1000, 4000), range(8)
robots_2d = {seed: range_run(floor, np.random.default_rng(200 + seed), n_steps=20, angles=BEAMS, max_range=8.0)
             for seed in SEEDS_2D}                   # one robot per seed, the same for every particle count
final_err = {}
for n, seed in progress([(n, s) for n in N_TRY for s in SEEDS_2D], desc="global localizations"):
    r = robots_2d[seed]
    h = particle_filter_2d(r, n, np.random.default_rng(300 + seed))
    final_err[n, seed] = float(np.hypot(*(np.average(h[-1][0][:, :2], axis=0, weights=h[-1][1])
                                          - r.poses[-1, :2])))

# %%
# counts, not percentages: with 8 runs a rate is a count (and 1/8 = 12.5% sits on a rounding tie)
lost = {n: int(sum(final_err[n, s] > 0.5 for s in SEEDS_2D)) for n in N_TRY}
for n in N_TRY:
    print(f"{n:5d} particles: lost in {lost[n]} of {len(SEEDS_2D)} runs")
assert lost[250] >= lost[1000] >= lost[4000] and lost[250] - lost[4000] >= len(SEEDS_2D) / 2

# %% [markdown]
# ### How many particles?
#
# A rough count says where these numbers come from. A particle can *capture*
# the robot if it lands within some radius $r$ of the true position with a
# heading within $\pm\Delta$ — close enough that the motion noise and the next
# few scans pull it in. With free area $A$, the chance that one uniform
# particle does is $p = \frac{\pi r^2}{A}\cdot\frac{2\Delta}{2\pi}$, and the
# chance that at least one of $N$ does is $1 - (1 - p)^N \approx 1 - e^{-Np}$.
# With $r = 0.5$ m and $\Delta = 0.3$ rad in the office:

# %%
area = floor.free.sum() * floor.resolution**2
p_capture = np.pi * 0.5**2 / area * (2 * 0.3) / (2 * np.pi)
for n in N_TRY:
    print(f"{n:5d} particles: P(at least one captures the robot) = {1 - (1 - p_capture) ** n:.2f}")
n_95 = np.log(0.05) / np.log(1 - p_capture)
print(f"particles for 95 %: {n_95:,.0f}")
assert 5_000 < n_95 < 15_000

# %% [markdown]
# The count is rough — a distinctive first scan pulls particles in from
# further away than 0.5 m, an ambiguous one (a corridor that looks the same
# all along) from less far, and a particle that captures the robot can still
# lose to a look-alike place — but it predicts the trend of the measurement:
# hopeless with a few hundred particles, rarely right with a thousand,
# usually right with several thousand. And it shows the scaling that matters: **N grows with the free area
# times the heading range, divided by the size of the capture region.** Double
# the building and you need twice the particles for global localization; a
# sharper sensor model *shrinks* the capture region (so tempering, which widens
# it, lets fewer particles find the robot). Once the robot is found, tracking
# needs only enough particles to cover the motion noise of one step — a few
# hundred — so the particle count that global localization needs is wasted
# afterwards. Three practical answers follow, and the next two chapters use
# them: start with many particles and let **KLD-sampling** cut them down as the
# belief concentrates (chapter 8); watch $N_\text{eff}/N$ and the fit of the
# scans to notice deprivation; and **inject random particles** when the fit
# drops, so that a lost filter gets new hypotheses (chapter 8).

# %% [markdown]
# ## Summary
#
# * A set of $N$ samples represents a density; averages over it have errors that
#   shrink like $1/\sqrt{N}$ in any dimension.
# * Importance sampling draws from a proposal and weights by target over
#   proposal. In the particle filter the proposal is the motion model and the
#   weight is the measurement likelihood.
# * Resampling turns weighted particles into equally weighted ones. All four
#   schemes here are unbiased; systematic (the low-variance sampler) adds the
#   least noise and is the fastest.
# * Test resamplers statistically: the mean offspring must be $N w_i$ within a
#   few standard errors. Two bugs in a popular library show why.
# * $N_\text{eff} = 1/\sum w_i^2 = N/(1 + N^2 \operatorname{Var}(w))$; resample when
#   it falls below a fraction of $N$, not when the weight variance passes a fixed
#   number.
# * On a floor the same loop runs on `(N, 3)` poses. Global localization needs
#   particles in proportion to the free area times the heading range over the
#   capture region; with too few, **particle deprivation** leaves no particle
#   near the robot and the filter cannot recover.
#
# Next: the same filter on robot poses with a laser, **Monte Carlo
# Localization**.

# %% [markdown]
# ## Exercises
#
# 1. **By hand.** Four particles have weights $[0.1, 0.2, 0.3, 0.4]$.
#    (a) Compute $N_\text{eff}$ and check it against
#    $N/(1 + N^2 \operatorname{Var}(w))$.
#    (b) Run the low-variance sampler (PR table 4.4) by hand with the random
#    offset $r = 0.125$ (in $[0, 1/N)$, as in PR). Which particles are chosen?
#    Check your answer with `rs.systematic_loop`, whose `rng.random()` must then
#    return $N r = 0.5$ (the solution shows how).
#    (c) For particle 3 ($w = 0.4$), give the mean and variance of its number of
#    copies under multinomial and under systematic resampling.
# 2. **Implementation.** Write `residual_fixed(weights, rng)`, residual
#    resampling done right (the fractions are $N w_i - \lfloor N w_i \rfloor$), in
#    a few lines of numpy. Test it statistically, the way this chapter tests
#    filterpy's version: mean offspring within five standard errors of $N w_i$
#    for the weights $[0.5, 0.3, 0.15, 0.05]$.
# 3. **Experiment.** How does the particle filter's distance from the exact
#    posterior depend on $N$? For the corridor run of this chapter, plot the
#    total variation distance at step 10 against $N \in \{25, 50, \dots, 3200\}$
#    (mean over 10 seeds) on log-log axes and fit the slope. Then repeat with
#    multinomial instead of systematic resampling. What do you expect, and what
#    do you see?

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 1
w_ex = np.array([0.1, 0.2, 0.3, 0.4])
print(f"(a) N_eff = 1 / sum w^2 = 1 / {np.sum(w_ex ** 2):.2f} = {1 / np.sum(w_ex ** 2):.4f}")
print(f"    Var(w) = {rs.weight_variance(w_ex):.4f}; N / (1 + N^2 Var) = {rs.ess_from_weight_variance(rs.weight_variance(w_ex), 4):.4f}")
pointers_ex = 0.125 + np.arange(4) / 4
print("(b) pointers", pointers_ex, "-> cumulative", np.cumsum(w_ex).round(2),
      "-> particles", np.searchsorted(np.cumsum(w_ex), pointers_ex, side="right"))


class FixedDraw(np.random.Generator):
    """A generator whose random() returns one chosen number: replays a hand calculation."""

    def __init__(self, value):
        super().__init__(np.random.PCG64(0))
        self.value = value

    def random(self, size=None, dtype=np.float64, out=None):
        return self.value


print("    rs.systematic_loop with rng.random() = N r = 0.5:", rs.systematic_loop(w_ex, FixedDraw(4 * 0.125)))
print(f"(c) multinomial: mean {4 * 0.4:.1f}, variance {4 * 0.4 * 0.6:.2f};"
      f" systematic: 1 or 2 copies, P(2) = 0.6 -> mean 1.6, variance {0.6 * 0.4:.2f}")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# (a) $\sum w_i^2 = 0.01 + 0.04 + 0.09 + 0.16 = 0.30$, so $N_\text{eff} = 3.33$.
# The mean weight is $0.25$ and $\operatorname{Var}(w) = (0.0225 + 0.0025 + 0.0025 +
# 0.0225)/4 = 0.0125$; $4/(1 + 16 \cdot 0.0125) = 4/1.2 = 3.33$.
#
# (b) The pointers are $0.125, 0.375, 0.625, 0.875$ and the cumulative weights
# $0.1, 0.3, 0.6, 1.0$. Walking along: $0.125$ lies in $[0.1, 0.3)$, particle 1;
# $0.375$ in $[0.3, 0.6)$, particle 2; $0.625$ and $0.875$ in $[0.6, 1.0)$,
# particle 3 twice. Particle 0 is lost and particle 3, the heaviest, doubles.
#
# (c) Multinomial: the count is binomial, mean $N w = 1.6$, variance
# $N w (1 - w) = 0.96$. Systematic: pointers are $1/N$ apart and particle 3's
# segment is $1.6/N$ long, so it holds one or two pointers; the mean must be 1.6,
# so $P(2) = 0.6$, and the variance is $0.6 \cdot 0.4 = 0.24$, four times less.
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 2
def residual_fixed(weights, rng):
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    n = w.size
    copies = np.floor(n * w).astype(int)
    frac = n * w - copies                                   # the fix: n * w, not w
    rest = n - copies.sum()
    if rest > 0:
        extra = rng.choice(n, size=rest, p=frac / frac.sum())
        copies += np.bincount(extra, minlength=n)
    return np.repeat(np.arange(n), copies)


rng_ex = np.random.default_rng(12)
counts = np.array([np.bincount(residual_fixed(w4, rng_ex), minlength=4) for _ in range(5_000)])
mean, var = counts.mean(axis=0), counts.var(axis=0, ddof=1)
z = np.abs(mean - 4 * w4) / np.sqrt(np.maximum(var, 1 / 5_000) / 5_000)
print("mean offspring", mean.round(3), " expected", 4 * w4, " z-scores", z.round(2))
print("unbiased (all z < 5):", bool(np.all(z < 5)))

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 3
def tv_at(n, seed, resampler, k=10):
    rng_x = np.random.default_rng(seed)
    out = rs.bootstrap_filter(rng_x.uniform(0, run.length, n), steps[:k + 1], run.move, run.log_likelihood,
                              rng_x, resampler=resampler, threshold=1.0)
    return tv_distance_to(exact[k], out.particles[k], out.weights[k])


ns = 25 * 2 ** np.arange(8)
fig, ax = plt.subplots(figsize=(6, 3.2))
for resampler in ("systematic", "multinomial"):
    tv = np.array([np.mean([tv_at(n, 300 + s, resampler) for s in range(10)]) for n in ns])
    slope = np.polyfit(np.log(ns), np.log(tv), 1)[0]
    ax.loglog(ns, tv, "o-", color=pp.RESAMPLER_COLORS[resampler], label=f"{resampler}: slope {slope:.2f}")
    print(f"{resampler:12s} slope {slope:.2f}; TV at N = 3200: {tv[-1]:.3f}")
ax.set_xlabel("particles N")
ax.set_ylabel("TV distance at step 10")
ax.legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# Both lines have slopes near $-1/2$: Monte Carlo error shrinks like
# $1/\sqrt{N}$ (for the smallest $N$ the distance saturates, which flattens the fit
# a little). Multinomial resampling adds more noise at every step, so its line lies
# above the systematic one by a roughly constant factor: the same accuracy costs
# more particles. Choosing the resampler changes the constant, not the rate.
#
# </details>
