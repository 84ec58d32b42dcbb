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
# # Probabilistic motion models
#
# Tell a robot to drive one metre and it drives *about* one metre, in *about*
# the direction it was facing. Wheels slip on a dusty floor, a tyre is a
# millimetre smaller than its twin, the encoders count ticks and not
# distance. Every localizer therefore needs an answer to one question:
#
# > Given where the robot was, $x_{t-1}$, and what it was told or what its
# > odometry says, $u_t$, where may it be now?
#
# The answer is a probability distribution, the **motion model**
# $p(x_t \mid u_t, x_{t-1})$ that the Bayes filter's prediction step uses. A
# filter needs it in one of two forms:
#
# * a **sampler**, which draws possible successor poses; a particle filter
#   moves each particle with one draw (chapter on MCL);
# * a **density**, which scores a given successor pose; a grid filter sums
#   over all cells with it (chapter on histogram localization).
#
# The two must describe the *same* distribution. This sounds obvious, but the
# textbook pseudocode (Thrun, Burgard & Fox, *Probabilistic Robotics*, 2005,
# "PR" below, chapter 5) gives a sampler and a density that do not quite
# agree, and we will see why and fix it.
#
# You will learn
#
# * a first, simple model: "drive forward $d$ metres" with Gaussian noise;
# * the **odometry model** (rotation, translation, rotation) with its four
#   noise parameters $\alpha_1..\alpha_4$, as sampler and as density;
# * why a density over $(x, y, \theta)$ needs a **Jacobian**, and why PR's
#   table 5.5 integrates to the distance driven instead of to one;
# * the **velocity model** with $\alpha_1..\alpha_6$ and its final rotation
#   $\gamma$, and how to drive straight without dividing by zero;
# * what the different noise conventions found in course notes change, and
#   what they do not.

# %%
import inspect
import math

import matplotlib.pyplot as plt
import numpy as np

import localize
from localize import motion
from localize.geometry import wrap_angle
from localize.plot import draw_robot
from localize.plot.ekf import covariance_ellipse
from localize.plot.motion import (
    PR_FIG_5_9_ALPHAS,
    banana_figure,
    density_and_samples_figure,
    draw_samples,
    square_path_figure,
    update_rate_figure,
)
from localize.widgets.motion import odometry_cloud_figure, odometry_widget, velocity_cloud_figure, velocity_widget

rng = np.random.default_rng(2005)
np.set_printoptions(precision=4, suppress=True, linewidth=110)
print("localize", localize.__version__)

# %% [markdown]
# ## A first model: "drive one metre"
#
# Start with the simplest robot command there is: *move forward one metre*.
# Each time the robot obeys, two things go wrong a little:
#
# 1. it does not face exactly where it thinks it faces, so its heading is off
#    by a small random angle $\varepsilon_\theta \sim \mathcal N(0, \sigma_\theta^2)$;
# 2. it does not drive exactly one metre, but $1 + \varepsilon_d$ with
#    $\varepsilon_d \sim \mathcal N(0, \sigma_d^2)$.
#
# Turn first by $\varepsilon_\theta$, then drive $1 + \varepsilon_d$ along the new
# heading. Localization tutorials that introduce particle filters often use
# exactly this model, with the two standard deviations found by driving the
# real robot many times and measuring where it stops (calibration).
# `localize.motion.sample_forward` implements it for any number of poses
# at once.

# %%
start = np.array([0.0, 0.0, 0.0])
forward = motion.sample_forward(np.tile(start, (500, 1)), 1.0, sigma_distance=0.05, sigma_heading=0.1, rng=rng)
print("mean end pose      ", forward.mean(axis=0).round(3))
print("std of x, y, theta ", forward.std(axis=0).round(3))
# the new heading is always the direction in which the robot drove:
drive_dir = np.arctan2(forward[:, 1], forward[:, 0])
print("heading == direction of travel (to 1e-12):", bool(np.abs(wrap_angle(forward[:, 2] - drive_dir)).max() < 1e-12))

# %%
fig, ax = plt.subplots(figsize=(5, 3.2))
draw_samples(forward, ax=ax)
draw_robot(start, ax=ax, radius=0.05, color="k")
ax.set_aspect("equal")
ax.set_xlabel("x [m]")
ax.set_ylabel("y [m]")
ax.set_title("500 draws of 'drive 1 m' ($\\sigma_d$ = 5 cm, $\\sigma_\\theta$ = 0.1 rad)", fontsize=9)
plt.show()

# %% [markdown]
# The cloud is an ellipse about twice as wide as it is long (standard
# deviations 0.1 m sideways and 0.05 m along, printed above), bent a little
# along the circle of radius 1 m around the start: heading noise moves the
# robot sideways, distance noise moves it along. Two random numbers per draw decide three coordinates,
# so the samples lie on a two-dimensional surface in $(x, y, \theta)$ space:
# the heading is always exactly the direction of travel (the last line
# printed above). A real robot can end up facing a little to the side of the
# way it drove; the models below add a third noise term for that.
#
# Over the *position* alone the model does have a density. In polar
# coordinates around the start, distance $r$ and direction $\varphi$, the
# noise is simply a product of two Gaussians. But an area element in the plane
# is $dx\,dy = r\,dr\,d\varphi$, so the density per square metre is the polar
# density divided by $r$:
#
# $$p(x, y) = \frac{\mathcal N(r - d;\ \sigma_d^2)\ \mathcal N(\varphi - \theta;\ \sigma_\theta^2)}{r}.$$
#
# Keep this factor $1/r$ in mind: it is the whole story of the section on
# densities below. `forward_pdf_xy` evaluates it; a quick check that it
# integrates to one on a grid of 1 cm cells:

# %%
h = 0.01
xs = np.arange(-0.5, 1.5, h) + h / 2
X, Y = np.meshgrid(xs, xs - 1.0)
p_fwd = motion.forward_pdf_xy(np.stack([X, Y], -1), start, 1.0, 0.05, 0.1)
print("integral of p(x, y) over the grid:", round(float(p_fwd.sum() * h * h), 4))
print("the same without the 1/r factor:  ", round(float((p_fwd * np.hypot(X, Y)).sum() * h * h), 4))

# %% [markdown]
# Without the $1/r$ the "density" integrates to the mean distance driven
# (1 m here, so the mistake hides; drive 2 m and it integrates to 2).

# %% [markdown]
# ## The odometry motion model
#
# Most robots do not execute commands blindly: wheel encoders integrate the
# wheel rotations into an **odometry pose** $\bar x_t = (\bar x, \bar y, \bar\theta)$.
# This pose drifts and lives in its own frame, whose origin is wherever the
# robot was switched on, so we cannot use it as the robot's pose in the map.
# But the *difference* between two consecutive odometry poses is a good
# measurement of how the robot moved. The odometry model (PR section 5.4)
# treats this difference as the control $u_t = (\bar x_{t-1}, \bar x_t)$.
#
# Any planar motion can be described as three steps (PR figure 5.7): turn by
# $\delta_\text{rot1}$ to face the destination, drive straight
# $\delta_\text{trans}$, turn by $\delta_\text{rot2}$ into the final heading:
#
# $$\delta_\text{rot1} = \operatorname{atan2}(\bar y' - \bar y,\ \bar x' - \bar x) - \bar\theta,\qquad
# \delta_\text{trans} = \sqrt{(\bar x' - \bar x)^2 + (\bar y' - \bar y)^2},\qquad
# \delta_\text{rot2} = \bar\theta' - \bar\theta - \delta_\text{rot1}.$$
#
# (If the robot did not translate at all, $\operatorname{atan2}(0, 0)$ means
# nothing; we then set $\delta_\text{rot1} = 0$ and put the whole turn into
# $\delta_\text{rot2}$.) Here is one odometry step, and the same step read in
# an odometry frame with a different origin: the control is the same.

# %%
odo_prev, odo_now = np.array([2.0, 1.0, 0.3]), np.array([2.9, 1.5, 0.8])
rot1, trans, rot2 = motion.odometry_to_control(odo_prev, odo_now)
print(f"rot1 = {rot1:.4f} rad, trans = {trans:.4f} m, rot2 = {rot2:.4f} rad")
frame = np.array([-5.0, 3.0, 1.2])   # another origin and orientation of the odometry frame
again = motion.odometry_to_control(localize.geometry.compose(frame, odo_prev), localize.geometry.compose(frame, odo_now))
print("in another odometry frame:", np.round(again, 4))

# %% [markdown]
# ### Noise, and the meaning of the alphas
#
# The true motion is the measured one with each of the three parts perturbed
# by independent zero-mean Gaussian noise. PR lets the *variance* of each
# noise grow with the size of the motion:
#
# | noise on | variance |
# |---|---|
# | $\delta_\text{rot1}$ | $\alpha_1\,\delta_\text{rot1}^2 + \alpha_2\,\delta_\text{trans}^2$ |
# | $\delta_\text{trans}$ | $\alpha_3\,\delta_\text{trans}^2 + \alpha_4\,(\delta_\text{rot1}^2 + \delta_\text{rot2}^2)$ |
# | $\delta_\text{rot2}$ | $\alpha_1\,\delta_\text{rot2}^2 + \alpha_2\,\delta_\text{trans}^2$ |
#
# Read $\alpha_1$ as "rotation error per rotation", $\alpha_2$ "rotation error
# per translation", $\alpha_3$ "translation error per translation" and
# $\alpha_4$ "translation error per rotation". A robot that stands still gets
# no noise at all. The sampler is PR's table 5.6; our readable version, kept
# one pose at a time so that it reads like the book, is the test oracle of the
# fast `sample_odometry`:

# %%
print(inspect.getsource(motion.sample_motion_model_odometry).split('"""')[2])

# %% [markdown]
# The fast version does the same for a million particles at once with array
# operations, in well under a tenth of a second (`benchmarks/bench_motion.py`
# measures it). With the same random numbers both give the same poses:

# %%
u = (odo_prev, odo_now)
alphas = [0.05, 0.01, 0.02, 0.02]
slow = motion.sample_motion_model_odometry(start, u, alphas, np.random.default_rng(7))
fast = motion.sample_odometry(start[None], u, alphas, np.random.default_rng(7))[0]
print("readable:", slow.round(6), " fast:", fast.round(6))
assert np.allclose(slow, fast)

# %% [markdown]
# ### Drawing the noise: sums of uniforms, or numpy
#
# Line 5-7 of the sampler need one Gaussian draw each. `localize` takes them
# from numpy's `Generator.standard_normal`, which uses the ziggurat method:
# exact (up to floating point) and fast. PR (table 5.4) shows two older tricks
# that need nothing but a uniform generator, and some course code still uses
# them. Both rest on the central limit theorem in miniature: a sum of
# independent uniforms is already bell-shaped.
#
# * **Normal, variance $b^2$:** $\tfrac12 \sum_{i=1}^{12} \mathrm{rand}(-b, b)$.
#   One uniform on $[-b, b]$ has variance $b^2/3$; twelve have $4b^2$, and
#   halving divides the variance by four.
# * **Triangular, variance $b^2$:** $\tfrac{\sqrt 6}{2}\,\big(\mathrm{rand}(-b, b) + \mathrm{rand}(-b, b)\big)$.
#   Two uniforms give a tent on $[-2b, 2b]$ with variance $2b^2/3$; the factor
#   $\sqrt6/2$ scales it to $b^2$ and to the support $[-\sqrt6 b, \sqrt6 b]$.
#
# They are approximations with visible limits: the twelve-uniform "normal" can
# never go beyond $6b$ (a true normal does, about twice in $10^9$ draws:
# $P(|Z| > 6) = 2.0 \times 10^{-9}$, printed below) and its tails
# are a little thin; the triangular distribution has no tails at all, which is
# why it is occasionally used on purpose, as a cheap noise that cannot produce
# outliers. Neither is faster than numpy's generator, which draws one number
# where they draw twelve or two.

# %%
rng_u = np.random.default_rng(54)            # its own generator, so the rest of the chapter is unchanged
b_sd, n_u = 0.1, 200_000
normal_12 = 0.5 * rng_u.uniform(-b_sd, b_sd, (n_u, 12)).sum(axis=1)
triangular = np.sqrt(6) / 2 * rng_u.uniform(-b_sd, b_sd, (n_u, 2)).sum(axis=1)
numpy_normal = b_sd * rng_u.standard_normal(n_u)
print(f"a true normal beyond 6 standard deviations: P(|Z| > 6) = {math.erfc(6 / math.sqrt(2)):.1e}")
print("                    std     kurtosis  largest |value| / b")
for name, v in [("12 uniforms", normal_12), ("triangular", triangular), ("numpy normal", numpy_normal)]:
    kurt = np.mean((v - v.mean()) ** 4) / v.var() ** 2
    print(f"{name:15s}   {v.std():.4f}    {kurt:.2f}      {np.abs(v).max() / b_sd:.2f}")
se_std = b_sd / np.sqrt(2 * n_u)             # standard error of a sample std
assert all(abs(v.std() - b_sd) < 5 * se_std * 1.2 for v in (normal_12, triangular, numpy_normal))
assert np.abs(triangular).max() <= np.sqrt(6) * b_sd and np.abs(normal_12).max() <= 6 * b_sd
kurtosis = {name: np.mean((v - v.mean()) ** 4) / v.var() ** 2
            for name, v in [("12", normal_12), ("tri", triangular), ("np", numpy_normal)]}
assert abs(kurtosis["12"] - 2.9) < 0.05 and abs(kurtosis["tri"] - 2.4) < 0.05 and abs(kurtosis["np"] - 3) < 0.06

fig, ax = plt.subplots(figsize=(6.5, 3))
bins = np.linspace(-0.4, 0.4, 81)
for v, label in [(numpy_normal, "numpy standard_normal"), (normal_12, "sum of 12 uniforms"),
                 (triangular, "triangular (sum of 2)")]:
    ax.hist(v, bins=bins, density=True, histtype="step", label=label)
ax.set_xlabel("noise value (b = 0.1)")
ax.set_ylabel("density")
ax.legend(fontsize=8)
ax.set_title("three ways to draw zero-mean noise of standard deviation 0.1 (PR table 5.4)", fontsize=9)
plt.show()

# %% [markdown]
# All three have the standard deviation asked for. The sum of twelve uniforms
# is hard to tell from the normal by eye (its kurtosis is 2.9 instead of 3:
# slightly thinner tails); the triangle is clearly different, and its kurtosis
# of 2.4 says it. For a particle filter the difference between the first two
# does not matter; use numpy's generator, which is exact, faster and already
# seeded through `rng`.

# %% [markdown]
# ### The banana
#
# Draw 500 successors of one pose for three settings of the alphas, in the
# spirit of PR figure 5.9: typical noise, large rotational noise ($\alpha_1$
# ten times larger, $\alpha_2$ — rotation error per metre driven — also ten
# times larger) and large translational noise ($\alpha_3$ ten times larger).
# The motion is a small turn, 2 m ahead, another small turn. It has to be a
# long drive for the banana to show: rotation noise moves the end point
# sideways by the angle error *times the distance*, and only when that
# sideways spread is large compared with the spread along the way does the
# cloud bend.

# %%
u_demo = ((0.0, 0.0, 0.0), (1.0, 0.3, 0.6))      # the step of the later sections
u_banana = ((0.0, 0.0, 0.0), (2.0, 0.4, 0.5))
fig = banana_figure(u_banana, PR_FIG_5_9_ALPHAS, rng,
                    titles=["typical", "large rotation noise ($\\alpha_1, \\alpha_2$)",
                            "large translation noise ($\\alpha_3$)"])
fig

# %%
# the shape in numbers: spread across and along the direction of travel, for each panel
r1_b, tr_b, r2_b = motion.odometry_to_control(*u_banana)
shape = []
for name, a in zip(["typical", "large rotation", "large translation"], PR_FIG_5_9_ALPHAS):
    sd_rot1, sd_trans, _ = np.sqrt(motion.odometry_variances(r1_b, tr_b, r2_b, a))
    shape.append(sd_rot1 * tr_b / sd_trans)
    print(f"{name:18s}: sideways spread {sd_rot1 * tr_b:.2f} m, along the way {sd_trans:.2f} m, "
          f"ratio {shape[-1]:.1f}")
assert shape[1] > 2.5 and shape[2] < 0.5       # a banana (wide and curved) and a streak along the way

# %% [markdown]
# Rotation noise swings the end point around the start on a circle of
# radius $\delta_\text{trans}$: with a sideways spread three times the spread
# along the way, that is the curved, banana-shaped cloud of the middle panel. Translation
# noise stretches the cloud along the direction of travel. Which of the two
# dominates decides where a particle filter needs its particles: after a long
# straight drive, spread along the corridor; after a sharp turn, spread
# sideways.

# %% [markdown]
# ## The density, and the Jacobian
#
# A grid filter needs the other face of the model: the density
# $p(x_t \mid u_t, x_{t-1})$ at a given successor pose $x_t = (x', y', \theta')$.
# The recipe (PR table 5.5) runs the kinematics backwards. From $x_{t-1}$ to
# $x_t$ the robot must have turned, driven and turned by
#
# $$\hat\delta_\text{rot1} = \operatorname{atan2}(y' - y,\ x' - x) - \theta,\qquad
# \hat\delta_\text{trans} = \sqrt{(x' - x)^2 + (y' - y)^2},\qquad
# \hat\delta_\text{rot2} = \theta' - \theta - \hat\delta_\text{rot1},$$
#
# and the density scores how far these are from what odometry measured,
# with the three Gaussian noise densities. So far so good; two details need
# care.
#
# **The Jacobian.** The product of the three Gaussians is a density over
# $(\delta_\text{rot1}, \delta_\text{trans}, \delta_\text{rot2})$, per radian
# per metre per radian. A grid filter needs a density per *cell* of
# $(x, y, \theta)$ space. The map from one to the other is polar coordinates
# again: $x' = x + \delta_\text{trans}\cos(\theta + \delta_\text{rot1})$,
# $y' = y + \delta_\text{trans}\sin(\theta + \delta_\text{rot1})$,
# $\theta' = \theta + \delta_\text{rot1} + \delta_\text{rot2}$, and its
# Jacobian determinant is $\delta_\text{trans}$:
#
# $$dx'\,dy'\,d\theta' = \hat\delta_\text{trans}\ d\delta_\text{rot1}\,d\delta_\text{trans}\,d\delta_\text{rot2}
# \quad\Longrightarrow\quad
# p(x', y', \theta') = \frac{p(\hat\delta_\text{rot1}, \hat\delta_\text{trans}, \hat\delta_\text{rot2})}{\hat\delta_\text{trans}}.$$
#
# Table 5.5 returns the numerator only. Integrate it over $(x, y, \theta)$
# and you get $\int p(\delta)\,\hat\delta_\text{trans}\,d\delta$: the
# **expected translation**, not one. For relative comparisons between
# nearby cells the factor hardly matters (it changes slowly), which is why the
# slip is easy to miss, but a grid filter normalises over all cells, and cells
# close to the start get too little weight without it.
#
# **Which variances.** Table 5.5 computes the noise variances from the
# *hypothesised* motion $\hat\delta$, while the sampler of table 5.6 computes
# them from the *measured* motion $\delta$. These are two different models.
# The sampler's is the one with a clear story ("the true motion is the
# measured one plus noise whose size depends on the measured motion"), so our
# density uses the measured motion too, and then the two agree exactly.
#
# **Two small completions.** The noise on the angles is wrapped (an angle
# error of $2\pi + 0.1$ is an error of $0.1$), so the angle densities are
# wrapped normals; and a pose can also be reached by turning the other way
# and driving *backwards* ($\hat\delta_\text{trans} < 0$), which the sampler
# does when the translation noise is large compared with the translation. The
# density adds that second way. Neither matters for typical noise; both
# matter for the density to integrate to exactly one when noise is large.
#
# **When there is no density.** A robot that turns on the spot has
# $\delta_\text{trans} = 0$, hence $\delta_\text{rot1} = 0$, and PR's variance of
# the rot1 noise, $\alpha_1\delta_\text{rot1}^2 + \alpha_2\delta_\text{trans}^2$, is
# exactly zero. All successors then lie on one line through the start: a
# distribution without a density over $(x, y, \theta)$. The sampler is happy
# with that; `odometry_pdf` refuses with an error instead of returning
# infinities. A grid filter passes `min_std`, a floor on every noise standard
# deviation, which is realistic anyway: no robot turns in place perfectly.

# %%
turn_on_spot = ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
try:
    motion.odometry_pdf([0.0, 0.0, 1.0], turn_on_spot, start, [0.05, 0.01, 0.02, 0.02])
except ValueError as err:
    print("ValueError:", str(err)[:120], "...")
dens_by_dist = []
for dist in (0.02, 0.01, 0.005):
    dens = motion.odometry_pdf([dist, 0.0, 1.0], turn_on_spot, start, [0.05, 0.01, 0.02, 0.02], min_std=0.01)
    print(f"with min_std=0.01, {dist * 100:.1f} cm ahead of the start: {float(dens):.1f}")
    dens_by_dist.append(float(dens))
assert all(1.9 < a / b < 2.1 for a, b in zip(dens_by_dist[1:], dens_by_dist))   # halving the distance doubles it

# %% [markdown]
# Halving the distance to the start roughly doubles the density: that is the
# Jacobian $1/\hat\delta_\text{trans}$ again. The density is infinite *at* the
# start, yet integrable (in the plane, $\int 1/r\,dx\,dy = \int dr\,d\varphi$).
# A grid filter should therefore not evaluate it only at the centre of the
# start cell but average it over the cell.
#
# Let us check all this numerically: the density on a grid of
# $(x, y, \theta)$ cells, with and without the Jacobian, and PR's table 5.5
# written out literally.

# %%
def table_5_5(pose, u, prev, a):
    """PR table 5.5 as printed (variances at the hypothesised motion, no Jacobian), vectorised."""
    r1, t, r2 = motion.odometry_to_control(*u)
    dx, dy = pose[..., 0] - prev[0], pose[..., 1] - prev[1]
    r1h = np.arctan2(dy, dx) - prev[2]
    th = np.hypot(dx, dy)
    r2h = pose[..., 2] - prev[2] - r1h

    def prob(e, var):
        return np.exp(-0.5 * e**2 / var) / np.sqrt(2 * np.pi * var)

    p1 = prob(wrap_angle(r1 - r1h), a[0] * r1h**2 + a[1] * th**2)
    p2 = prob(t - th, a[2] * th**2 + a[3] * (r1h**2 + r2h**2))
    p3 = prob(wrap_angle(r2 - r2h), a[0] * r2h**2 + a[1] * th**2)
    return p1 * p2 * p3


u_int = ((0.0, 0.0, 0.0), (1.5, 0.4, 0.5))
a_int = [0.05, 0.02, 0.02, 0.05]
h, n_th = 0.02, 72
gx = np.arange(-0.5, 3.0, h) + h / 2
gy = np.arange(-1.5, 2.3, h) + h / 2
gt = -np.pi + (np.arange(n_th) + 0.5) * 2 * np.pi / n_th
GX, GY, GT = np.meshgrid(gx, gy, gt, indexing="ij")
grid_poses = np.stack([GX, GY, GT], -1)
cell = h * h * 2 * np.pi / n_th
p_ours = motion.odometry_pdf(grid_poses, u_int, start, a_int)
p_pr = table_5_5(grid_poses, u_int, start, a_int)
d_hat = np.hypot(GX, GY)
print(f"measured translation                    {motion.odometry_to_control(*u_int)[1]:.4f} m")
print(f"integral of odometry_pdf                {p_ours.sum() * cell:.4f}")
print(f"integral of odometry_pdf x trans_hat    {(p_ours * d_hat).sum() * cell:.4f}   (no Jacobian)")
print(f"integral of table 5.5 as printed        {p_pr.sum() * cell:.4f}")
print(f"integral of table 5.5 / trans_hat       {(p_pr / d_hat).sum() * cell:.4f}")
assert abs(p_ours.sum() * cell - 1) < 2e-3
assert abs((p_ours * d_hat).sum() * cell - motion.odometry_to_control(*u_int)[1]) < 0.01   # "about 1.55 m"
assert abs((p_pr / d_hat).sum() * cell - 1.15) < 0.01

# %% [markdown]
# Our density integrates to one. Without the Jacobian it integrates to the
# translation, about 1.55 m. The printed table does not integrate to one even
# with the Jacobian added (about 1.15 here): with variances that change from
# one hypothesised pose to the next it is not a normalised density of
# anything, and its shape differs from the sampler's cloud too (the next
# cells compare moments).
#
# ### Density and samples side by side
#
# On the left, the position density (the density over $(x, y, \theta)$ with
# the heading integrated out, `odometry_pdf_xy`); on the right, 500 samples
# of the same model.

# %%
fig = density_and_samples_figure(u_demo, (0.2, 0.05, 0.02, 0.01), rng)
fig

# %% [markdown]
# The same agreement in numbers: the mean and covariance of $10^5$ samples
# against the moments of the density computed on the grid. The sample means
# have standard errors of about $\sigma/\sqrt{n}$, around a millimetre here.
# The last line shows the mean of the table-5.5 variant: it differs from the
# sampler's by far more than the standard error.

# %%
big = motion.sample_odometry(np.zeros((100_000, 3)), u_int, a_int, rng)


def grid_mean_cov(p):
    w = (p * cell).ravel()
    pts = grid_poses.reshape(-1, 3)
    mean = w @ pts / w.sum()
    c = pts - mean
    return mean, (c * w[:, None]).T @ c / w.sum()


m_d, c_d = grid_mean_cov(p_ours)
print("sample mean       ", big.mean(axis=0).round(4), " std err", (big.std(axis=0) / np.sqrt(len(big))).round(4))
print("density mean      ", m_d.round(4))
print("sample cov\n", np.cov(big.T).round(4))
print("density cov\n", c_d.round(4))
m_pr, _ = grid_mean_cov(p_pr / d_hat)
print("table 5.5 / trans_hat, mean", m_pr.round(4))
std_err = big.std(axis=0) / np.sqrt(len(big))
assert np.all(std_err < 0.0015) and np.all(np.abs(m_pr - m_d) > 10 * std_err)   # "around a millimetre"; "far more"

# %% [markdown]
# ## The velocity motion model
#
# Some robots report no odometry, or a planner needs to predict the effect
# of a command before it is executed. Then the control is a velocity pair
# $u_t = (v, \omega)$: translational speed $v$ (m/s) and rotational speed
# $\omega$ (rad/s), held for $\Delta t$ seconds (PR section 5.3). Constant
# $v$ and $\omega$ drive the robot along a circular arc of radius $v/\omega$,
# turning by $\omega\Delta t$:
#
# $$x' = x - \tfrac{v}{\omega}\sin\theta + \tfrac{v}{\omega}\sin(\theta + \omega\Delta t),\qquad
# y' = y + \tfrac{v}{\omega}\cos\theta - \tfrac{v}{\omega}\cos(\theta + \omega\Delta t),\qquad
# \theta' = \theta + \omega\Delta t.$$
#
# The noise model perturbs both speeds, with variances
# $\alpha_1 v^2 + \alpha_2\omega^2$ and $\alpha_3 v^2 + \alpha_4\omega^2$ (PR
# table 5.3). That gives two noise numbers for three coordinates again: every
# sample would end up facing exactly along its arc. So PR adds a third noise
# term, a final rotation at rate $\hat\gamma$ with variance
# $\alpha_5 v^2 + \alpha_6\omega^2$, applied on top:
# $\theta' = \theta + \hat\omega\Delta t + \hat\gamma\Delta t$. Without it the
# model has no density over $(x, y, \theta)$ at all.
#
# **Driving straight.** The formula divides by $\omega$. At $\omega = 0$ it
# fails outright, and close to zero it subtracts two nearly equal large
# numbers. The arc's end point can be written without the division: the robot
# moves along the chord of the arc, which points at half the turn,
# $\theta + \omega\Delta t/2$, and has length
# $v\Delta t\cdot\frac{\sin(\omega\Delta t/2)}{\omega\Delta t/2}$ (the factor
# is 1 when $\omega = 0$). `move_velocity` uses this form, so straight
# driving is the smooth limit of turning, not a special case:

# %%
for w in [0.5, 1e-4, 1e-9, 0.0]:
    chord = motion.move_velocity(start, 1.0, w, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.float64(1.0) / np.float64(w)
        pr_x = -r * np.sin(0.0) + r * np.sin(0.0 + w * 1.0)
        pr_y = r * np.cos(0.0) - r * np.cos(0.0 + w * 1.0)
    # x to 9 decimals, y to 6 significant digits: fine enough to show what rounding destroys, and no
    # finer than every CPU agrees on (the subtraction at omega = 1e-4 leaves ~1e-12 m of round-off)
    print(f"omega = {w:<7g} chord form: ({chord[0]:.9f}, {chord[1]:.5e})   v/omega form: ({pr_x:.9f}, {pr_y:.5e})")

# %% [markdown]
# At $\omega = 10^{-9}$ the textbook form has lost the sideways offset to
# rounding, and at $\omega = 0$ it returns "not a number". The chord form is
# exact in both cases.
#
# Here are velocity-model samples with and without the final rotation. On
# the left, their positions: $\gamma$ turns the robot where it stands, so
# both clouds have the same spread and their $2\sigma$ ellipses nearly
# coincide; the final rotation is invisible in $(x, y)$. On the right we plot, for each sample, its heading against the heading that
# its position implies (twice the chord angle): without $\gamma$ all points
# sit on the diagonal.

# %%
a_vel = np.array([0.02, 0.01, 0.02, 0.02, 0.01, 0.02])
with_g = motion.sample_velocity(np.zeros((500, 3)), (1.0, 0.8), 1.0, a_vel, rng)
without_g = motion.sample_velocity(np.zeros((500, 3)), (1.0, 0.8), 1.0, a_vel * [1, 1, 1, 1, 0, 0], rng)
fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), layout="constrained")
# left: gamma only turns the robot where it stands, so both position clouds have the same spread;
# their 2-sigma ellipses (dashed for "without") nearly coincide
for s, c, ls in ((with_g, "tab:red", "-"), (without_g, "tab:blue", "--")):
    axes[0].scatter(s[:, 0], s[:, 1], s=3, color=c, alpha=0.35)
    covariance_ellipse(s.mean(axis=0), np.cov(s.T), ax=axes[0], color=c, ls=ls, lw=2)
t = np.linspace(0, 1, 40)
arc = motion.move_velocity(np.zeros((40, 3)), 1.0 * t, 0.8 * t, 1.0)
axes[0].plot(arc[:, 0], arc[:, 1], "k--", lw=1)
axes[0].set_aspect("equal")
axes[0].set_xlabel("x [m]")
axes[0].set_ylabel("y [m]")
axes[0].set_title("positions: red with $\\gamma$, blue without (2σ ellipses)", fontsize=9)
axes[1].set_title("headings: only $\\gamma$ lets them leave the diagonal", fontsize=9)
for s, c in ((with_g, "tab:red"), (without_g, "tab:blue")):
    implied = 2 * np.arctan2(s[:, 1], s[:, 0])
    axes[1].scatter(implied, s[:, 2], s=3, color=c, alpha=0.5)
axes[1].set_xlabel("heading implied by the position [rad]")
axes[1].set_ylabel("sampled heading [rad]")
plt.show()

# %% [markdown]
# The density of the velocity model (PR table 5.1) runs the geometry
# backwards: find the circle through both positions that is tangent to the
# old heading, read off $\hat v$, $\hat\omega$ and the leftover rotation
# $\hat\gamma$, and score them. The same three corrections as for odometry
# apply. (1) A Jacobian: the map $(\hat v, \hat\omega, \hat\gamma) \mapsto (x', y', \theta')$
# has determinant $\Delta t^3\,c\,\left|\frac{\sin\psi}{\psi}\right|/2$, where $c$ is
# the chord length and $\psi$ the chord's angle to the old heading, half the
# turn (the tangent-chord theorem). (2) The printed table takes the circle's
# radius as positive, which makes $\hat v$ negative on right turns; the radius
# needs a sign. (3) Turns differ by whole circles and angles wrap; we take the
# turn closest to the commanded one. `velocity_pdf` does this, with the
# chord angle again making straight motion a regular case. It integrates to one:

# %%
h, n_th = 0.02, 60
vx = np.arange(0.1, 1.5, h) + h / 2
vy = np.arange(-0.2, 1.0, h) + h / 2
vt = -np.pi + (np.arange(n_th) + 0.5) * 2 * np.pi / n_th
VX, VY, VT = np.meshgrid(vx, vy, vt, indexing="ij")
p_vel = motion.velocity_pdf(np.stack([VX, VY, VT], -1), (1.0, 0.8), start, 1.0, a_vel)
print("integral of velocity_pdf:", round(float(p_vel.sum() * h * h * 2 * np.pi / n_th), 4))
print("straight command, at the expected pose:",
      round(float(motion.velocity_pdf([1.0, 0.0, 0.0], (1.0, 0.0), start, 1.0, a_vel)), 4))

# %% [markdown]
# ## Noise conventions: squares, absolute values, plus or minus
#
# Course notes and reports write the odometry model in several ways, and a
# reader who wants to reproduce one needs to know which:
#
# | source | variance of the rot1 noise | sign |
# |---|---|---|
# | PR 2005, tables 5.3 and 5.6 (our default) | $\alpha_1\delta_\text{rot1}^2 + \alpha_2\delta_\text{trans}^2$ | odometry: subtract; velocity: add |
# | a CMU 16-831 particle-filter homework report | $\alpha_1\lvert\delta_\text{rot1}\rvert + \alpha_2\lvert\delta_\text{trans}\rvert$, and $\alpha_4\lvert\delta_\text{rot1} + \delta_\text{rot2}\rvert$ in the translation | subtract |
# | a particle-filter report written in MATLAB, velocity model | $\alpha_1\lvert v\rvert + \alpha_2\lvert\omega\rvert$ | add |
#
# **The sign does not matter** for the distribution: zero-mean Gaussian noise
# is symmetric, so "true = measured minus noise" and "true = measured plus
# noise" describe the same model. With the same random numbers the two
# conventions negate every noise value (`sign=-1` and `sign=+1` below: a
# sample that overshoots in one undershoots by as much in the other), but the
# clouds they produce are statistically identical and a filter cannot tell
# them apart.
#
# **Squares versus absolute values do matter.** With squares the standard
# deviation grows in proportion to the motion; with absolute values the
# *variance* does. Both are 1 for a motion of size 1, so the alphas look
# alike, but:
#
# * the units differ ($\alpha_2$ multiplies m² in one and m in the other), so
#   alphas cannot be copied from one convention to the other;
# * with squares, the result depends on **how often odometry is read**. Driving
#   2 m in $n$ steps of $2/n$ m adds $n$ independent noises of variance
#   $\alpha_3 (2/n)^2$, in total $4\alpha_3/n$: the faster the odometry rate,
#   the more confident the model. With absolute values the total is
#   $n \cdot \alpha_3 \cdot 2/n = 2\alpha_3$ whatever $n$ is, like a random walk.
#
# The figure shows both conventions for 1, 4 and 16 odometry updates over the
# same 2 m drive, all with the same alphas.

# %%
fig = update_rate_figure((0.02, 0.02, 0.05, 0.01), rng)
fig

# %% [markdown]
# So: squared terms are PR's and our default, but their alphas are only valid
# for the odometry rate they were tuned at. If your filter integrates several
# odometry readings per update (many do, to save time), tune the alphas for
# that update distance, or use `noise="absolute"`. Any other variant can be
# passed as a function; here is the CMU report's form, with
# $|\delta_\text{rot1} + \delta_\text{rot2}|$ in the translation noise:

# %%
def cmu_variances(rot1, trans, rot2, a):
    return (a[0] * np.abs(rot1) + a[1] * np.abs(trans),
            a[2] * np.abs(trans) + a[3] * np.abs(rot1 + rot2),
            a[0] * np.abs(rot2) + a[1] * np.abs(trans))


a_cmu = [0.03, 0.03, 0.01, 0.01]        # the values the report settled on
for noise in ("squared", "absolute", cmu_variances):
    name = noise if isinstance(noise, str) else "cmu_variances"
    sd = np.sqrt(motion.odometry_variances(0.2, 0.1, -0.2, a_cmu, noise))
    print(f"{name:14s} std of (rot1, trans, rot2) for a 10 cm step: {np.round(sd, 4)}")
plus = motion.sample_odometry(np.zeros((3, 3)), u_demo, a_cmu, np.random.default_rng(1), noise=cmu_variances, sign=+1)
minus = motion.sample_odometry(np.zeros((3, 3)), u_demo, a_cmu, np.random.default_rng(1), noise=cmu_variances, sign=-1)
print("sign=+1:\n", plus.round(4), "\nsign=-1:\n", minus.round(4))
sd_sq = np.sqrt(motion.odometry_variances(0.2, 0.1, -0.2, a_cmu, "squared"))
sd_abs = np.sqrt(motion.odometry_variances(0.2, 0.1, -0.2, a_cmu, "absolute"))
print(f"rotation noise, absolute against squared: {sd_abs[0] / sd_sq[0]:.1f} times larger")
assert 2 < sd_abs[0] / sd_sq[0] < 3

# %% [markdown]
# Note how different the 10 cm step is: with absolute values the rotation
# noise of a short step is about two and a half times larger than with squares.

# %% [markdown]
# ## Many particles, many steps
#
# A particle filter applies the sampler to every particle at every odometry
# step. Without sensor updates the cloud only grows. Here 300 particles start
# at the same pose and follow the odometry of a 2 m square, four steps per
# side, one colour per step from dark to light. The turn at each corner
# enters the next step's $\delta_\text{rot1}$, and its rotation noise
# ($\alpha_1\cdot(\pi/2)^2$) is what fans the cloud out after each corner.

# %%
fig = square_path_figure((0.02, 0.005, 0.02, 0.01), rng, n=300)
fig

# %% [markdown]
# This growing cloud is what the sensor model of the next chapters has to
# pull back together.
#
# ## Try it: the alphas
#
# Move the sliders and watch the 500-sample cloud (right) and the position
# density (left) change together. Each redraw takes a few tens of
# milliseconds (`python benchmarks/bench_motion.py` measures it). A second
# widget does the same for the velocity model, including $v$ and $\omega$.
# In the static book the figures below the widgets show their default state.

# %% tags=["nbval-ignore-output"]
odometry_widget()

# %%
odometry_cloud_figure()

# %% tags=["nbval-ignore-output"]
velocity_widget()

# %%
velocity_cloud_figure()

# %% [markdown]
# ## Summary
#
# * A motion model is a distribution over the next pose. Particle filters
#   sample from it, grid filters evaluate its density; both must be the same
#   distribution.
# * The odometry model turns two odometry readings into
#   $(\delta_\text{rot1}, \delta_\text{trans}, \delta_\text{rot2})$ and perturbs
#   each with Gaussian noise whose variance is set by $\alpha_1..\alpha_4$.
# * A density over $(x, y, \theta)$ is the density of the noise divided by the
#   Jacobian $\hat\delta_\text{trans}$. PR table 5.5 leaves this out (it
#   integrates to the translation) and computes its variances from the
#   hypothesised motion; `localize.motion.odometry_pdf` uses the sampler's
#   variances and the Jacobian, so that sampler and density agree.
# * The velocity model needs the final rotation $\gamma$ to have a density, and
#   the chord form to drive straight.
# * Squared and absolute-value noise conventions differ in units and in how
#   the noise depends on the odometry rate; the sign of the noise is irrelevant.
#
# **Literature.** S. Thrun, W. Burgard, D. Fox, *Probabilistic Robotics*, MIT
# Press 2005, chapter 5 (tables 5.1, 5.3, 5.5, 5.6; figures 5.7-5.9).
# D. Fox, W. Burgard, S. Thrun, "Markov localization for mobile robots in
# dynamic environments", *JAIR* 11, 1999 (the odometry model in grid
# localization). J. Borenstein, H. R. Everett, L. Feng, "Measurement and
# correction of systematic odometry errors in mobile robots", *IEEE Trans.
# Robotics and Automation* 12(6), 1996 (where odometry errors come from and
# how to calibrate them).

# %% [markdown]
# ## Exercises
#
# 1. **By hand.** Odometry reads $(2, 1, 0)$ and then $(3, 2, \pi/2)$.
#    (a) Compute $\delta_\text{rot1}, \delta_\text{trans}, \delta_\text{rot2}$.
#    (b) With $\alpha = (0.1, 0.01, 0.01, 0.1)$, compute the standard deviations
#    of the three noises. (c) A robot at $(0, 0, 0)$ in the map receives this
#    odometry. Where does the noise-free motion take it, and what is the
#    density there?
# 2. **Implementation.** Write a vectorised sampler for the "forward $d$ metres"
#    model *with a third noise*: after driving, turn by
#    $\mathcal N(0, \sigma_\text{final}^2)$. Show that it is the odometry model
#    with $\delta_\text{rot1} = \delta_\text{rot2} = 0$ and a suitable choice of
#    noise, by comparing the sample means and covariances of both for $10^5$
#    samples.
# 3. **Experiment (calibration).** A "real" robot (simulated with alphas you do
#    not look at, `rng_robot` below) drives 1 m straight 200 times and turns
#    $90°$ on the spot 200 times; you observe its true end poses. Estimate
#    $\alpha_1$ and $\alpha_3$ from the spread of the end poses, and compare
#    with the hidden values. (Harder: the same 400 end poses also give
#    $\alpha_2$ and $\alpha_4$.)
#
# **Checking yourself.** Exercise 1: `motion.odometry_to_control`,
# `motion.odometry_variances` and `motion.odometry_pdf` compute (a), (b) and (c)
# (after you did them by hand). Exercise 2 checks itself: the two means must
# agree within a few standard errors ($\sigma/\sqrt{10^5}$, a few tenths of a
# millimetre) and the covariances to about $10^{-4}$. Exercise 3: the hidden
# values are in the solution; an estimate from 200 runs is good when within
# about 30 % (three relative standard errors of $\sqrt{2/200} = 10\%$). The
# homework (`book/homework/homework.ipynb`, section 4, "The odometry motion model") has you
# write PR table 5.6's sampler and table 5.5's density, and checks them with
# `localize.check.sample_odometry(fn)` and `localize.check.odometry_pdf(fn)`.

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 1
r1, t, r2 = motion.odometry_to_control([2, 1, 0], [3, 2, np.pi / 2])
print(f"(a) rot1 = {r1:.4f} (pi/4), trans = {t:.4f} (sqrt 2), rot2 = {r2:.4f} (pi/4)")
sd = np.sqrt(motion.odometry_variances(r1, t, r2, [0.1, 0.01, 0.01, 0.1]))
print("(b) standard deviations", sd.round(4))
end = motion.move_odometry(start, r1, t, r2)
dens = motion.odometry_pdf(end, ([2, 1, 0], [3, 2, np.pi / 2]), start, [0.1, 0.01, 0.01, 0.1])
print("(c) noise-free end pose", end.round(4), " density there", round(float(dens), 4))

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# (a) The displacement is $(1, 1)$, so $\delta_\text{rot1} = \operatorname{atan2}(1, 1) - 0 = \pi/4$,
# $\delta_\text{trans} = \sqrt 2$, $\delta_\text{rot2} = \pi/2 - 0 - \pi/4 = \pi/4$.
# (b) $\sigma_\text{rot1}^2 = 0.1\,(\pi/4)^2 + 0.01 \cdot 2 = 0.0817$, so
# $\sigma_\text{rot1} = \sigma_\text{rot2} = 0.286$ rad;
# $\sigma_\text{trans}^2 = 0.01 \cdot 2 + 0.1\,(2 (\pi/4)^2) = 0.1434$, so
# $\sigma_\text{trans} = 0.379$ m.
# (c) The same displacement applied from $(0, 0, 0)$: $(1, 1, \pi/2)$. There all
# three errors are zero, so the density is
# $\frac{1}{(2\pi)^{3/2}\,\sigma_\text{rot1}\sigma_\text{trans}\sigma_\text{rot2}}\cdot\frac{1}{\sqrt 2}
# = \frac{1}{15.75 \cdot 0.0310}\cdot 0.7071 \approx 1.45$ per m² rad
# (the wrapped-normal images and the backwards branch add a little).
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 2
def sample_forward_turn(poses, d, sigma_d, sigma_heading, sigma_final, rng):
    eps = rng.standard_normal((len(poses), 3))
    heading = poses[:, 2] + sigma_heading * eps[:, 0]
    dist = d + sigma_d * eps[:, 1]
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] + dist * np.cos(heading)
    out[:, 1] = poses[:, 1] + dist * np.sin(heading)
    out[:, 2] = wrap_angle(heading + sigma_final * eps[:, 2])
    return out


def fixed_noise(sd_rot1, sd_trans, sd_rot2):
    """A noise 'convention' with constant standard deviations."""
    return lambda r1, t, r2, a: (sd_rot1**2, sd_trans**2, sd_rot2**2)


n = 100_000
ours = sample_forward_turn(np.zeros((n, 3)), 1.0, 0.05, 0.1, 0.03, rng)
theirs = motion.sample_odometry(np.zeros((n, 3)), ((0, 0, 0), (1, 0, 0)), [0, 0, 0, 0], rng,
                                noise=fixed_noise(0.1, 0.05, 0.03))
print("means", ours.mean(axis=0).round(4), theirs.mean(axis=0).round(4))
print("max |cov difference|", float(np.abs(np.cov(ours.T) - np.cov(theirs.T)).max().round(6)))

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# The heading noise is $\delta_\text{rot1}$'s noise, the distance noise is
# $\delta_\text{trans}$'s and the final turn is $\delta_\text{rot2}$'s, with
# constant standard deviations instead of ones that scale with the motion.
# The covariances agree to within sampling error (below $10^{-4}$ here).
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 3
rng_robot = np.random.default_rng(99)
hidden = [0.03, 0.002, 0.01, 0.005]
straight = motion.sample_odometry(np.zeros((200, 3)), ((0, 0, 0), (1, 0, 0)), hidden, rng_robot)
spin = motion.sample_odometry(np.zeros((200, 3)), ((0, 0, 0), (0, 0, np.pi / 2)), hidden, rng_robot)
# straight: trans noise has variance alpha3 * 1 (+ alpha4 * 0); the distance driven shows it
alpha3_hat = np.var(np.hypot(straight[:, 0], straight[:, 1]))
# on the spot: rot1 = 0, so only rot2 carries noise, with variance alpha1 * (pi/2)^2
alpha1_hat = np.var(wrap_angle(spin[:, 2] - np.pi / 2)) / (np.pi / 2) ** 2
# the same runs give the other two: driving straight, rot1 and rot2 each get variance alpha2 * 1^2,
# so the final heading has variance 2 alpha2; on the spot the distance noise has variance
# alpha4 * (pi/2)^2 around a distance of 0, so its mean square estimates it
alpha2_hat = np.var(wrap_angle(straight[:, 2])) / 2
alpha4_hat = np.mean(spin[:, 0] ** 2 + spin[:, 1] ** 2) / (np.pi / 2) ** 2
for k, est in enumerate((alpha1_hat, alpha2_hat, alpha3_hat, alpha4_hat)):
    print(f"alpha{k + 1}: estimated {est:.4f}, hidden {hidden[k]}")
print("relative standard error with 200 runs: about", round(math.sqrt(2 / 200), 2))

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# Each manoeuvre isolates one alpha: a straight drive has
# $\delta_\text{rot1} = \delta_\text{rot2} = 0$, so the distance noise has variance
# $\alpha_3$; a turn on the spot has $\delta_\text{trans} = 0$, so the heading
# noise has variance $\alpha_1(\pi/2)^2$. A variance estimated from 200 runs
# has a relative standard error of $\sqrt{2/200} = 10\%$, so estimates within
# 20-30 % of the truth are as good as this experiment allows. The same two
# manoeuvres also give the other two alphas: driving straight, each of the two
# rotations gets variance $\alpha_2 \cdot 1^2$, so the final heading varies by
# $2\alpha_2$; turning on the spot, the distance driven (zero on average) has
# variance $\alpha_4 (\pi/2)^2$. No third manoeuvre is needed.
# On a real robot the "true end pose" comes from an external reference (a
# motion-capture system, or marks on the floor), and systematic errors (a
# wheel diameter that is off) should be calibrated out first (Borenstein et
# al. 1996), because the alphas describe only the random part.
#
# </details>
