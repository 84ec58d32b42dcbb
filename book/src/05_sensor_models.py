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
# # Range sensors, ray casting and measurement models
#
# The motion model of the previous chapter spreads the belief out; the
# **measurement model** pulls it back together. It answers the question
#
# > If the robot were at pose $x$ in map $m$, how likely is the scan $z$ it
# > has just taken?
#
# that is, it gives the likelihood $p(z \mid x, m)$ that the Bayes filter's
# correction step multiplies into the belief. A laser scanner returns a few
# hundred ranges per scan, one per beam, so this question is asked for
# every particle and every beam, at every step: the projects this book
# started from all found that **ray casting**, computing the range each beam
# *should* read from a hypothetical pose, is where a particle filter spends
# its time. One of them could only run a few hundred particles in MATLAB,
# another moved its ray caster to C++. We make it fast in plain numpy, and
# keep a slow, obviously correct version next to it as the judge.
#
# You will learn
#
# * three ways to cast rays in an occupancy grid: an exact **cell walk**
#   (Amanatides and Woo), **ray marching** on a distance field, and a
#   precomputed **lookup table**, and what each one costs and gets wrong;
# * the **beam model** of *Probabilistic Robotics* (Thrun, Burgard and Fox,
#   2005, "PR", section 6.3): a mixture of a noisy hit, unexpected short
#   readings, max-range failures and random readings;
# * the **likelihood field** (PR section 6.4), the default of ROS AMCL,
#   which needs no ray casting at all;
# * why the beams of a scan are combined by a **product** (a sum of logs),
#   not a sum, why that product is overconfident, and how to temper it;
# * a **landmark** model with its Jacobian, for the EKF chapter;
# * how to **learn** the beam model's parameters from data with EM.

# %%
import inspect
import math

import matplotlib.pyplot as plt
import numpy as np
from scipy import integrate

import localize
from localize import maps
from localize.beam_learning import fit_beam_model
from localize.plot import draw_map, draw_robot
from localize.plot.sensors import plot_beam_pdf, plot_likelihood_field, plot_ranges, plot_scan_on_map
from localize.raycast import RayCaster, _axis_walk, cast, cast_ray
from localize.sensors import BeamModel, LandmarkModel, LikelihoodField, select_beams
from localize.widgets.sensors import (
    beam_density_widget,
    pose_scan_figure,
    pose_scan_start,
    pose_scan_widget,
    pseudo_density_figure,
)

rng = np.random.default_rng(5)
grid = maps.office()
MAX_RANGE = 8.0
print(localize.__name__, grid)

# %% [markdown]
# ## What a range scan is
#
# A planar laser scanner sweeps a beam across its field of view and reports,
# for each of $B$ directions $\phi_k$ (relative to the sensor's heading), the
# distance $z^k$ to the first surface the beam met. If nothing reflects the
# beam within its maximum range, the scanner reports exactly `max_range`: a
# "no return". A scan is therefore $z = (z^1, \dots, z^B)$ with
# $0 \le z^k \le z_\text{max}$.
#
# The sensor sits somewhere on the robot (the CMU robot of the data chapter
# has its laser 25 cm ahead of its centre). Every model here takes the
# sensor's pose in the robot frame as `sensor_offset = (dx, dy, dtheta)` and
# applies it itself; the filters hand it *robot* poses.
#
# Given the map and a pose, the range a perfect sensor would read along each
# beam is the **expected range** $z^{k*}$. Here is a pose in the office map
# and its 61 expected ranges over a 180° field of view.

# %%
angles = np.linspace(-np.pi / 2, np.pi / 2, 61)
true_pose = np.array([6.2, 5.4, 0.35])
expected = cast(grid, true_pose, angles, MAX_RANGE, method="exact")[0]
fig, ax = plt.subplots(figsize=(8, 5))
plot_scan_on_map(grid, true_pose, angles, expected=expected, max_range=MAX_RANGE, ax=ax)
ax.set_title("Expected ranges from one pose (ray cast in the map)")
plt.show()
print("first ten expected ranges [m]:", expected[:10].round(2))

# %% [markdown]
# ## Ray casting, three ways
#
# `localize.raycast.cast(grid, poses, angles, max_range, method=...)` returns
# an `(N, B)` array of expected ranges for $N$ sensor poses and $B$ beams.
# The conventions are the same for every method and are tested:
#
# * the range is the distance to the point where the ray **enters** the
#   first obstacle cell (occupied, or unknown when the grid treats unknown
#   cells as obstacles, its default);
# * a ray that travels `max_range` without a hit, or **leaves the map**,
#   returns `max_range`; beyond the map's edge the laser sees open space;
# * a sensor **inside an obstacle** cell reads 0 on every beam, and so does
#   a sensor **outside the map** (`outside="zero"`, the default, makes such
#   particles unlikely under any model; `outside="raise"` raises instead).
#   NaN poses always raise.

# %%
demo = localize.OccupancyGrid.from_ascii("""
#######.....
#.....?.....
#######.....
""", resolution=1.0)
rays = {"towards the unknown cell": [1.5, 1.5, 0.0], "out of the open side": [8.5, 1.5, np.pi / 2],
        "from inside a wall": [0.5, 0.5, 0.0], "from outside the map": [-3.0, 1.5, 0.0]}
for name, pose in rays.items():
    print(f"{name:28s} -> {cast(demo, pose, [0.0], 20.0)[0, 0]:5.2f} m")
transparent = localize.OccupancyGrid(demo.data, 1.0, unknown_is_obstacle=False)
print("unknown cell transparent     ->", f"{cast(transparent, [1.5, 1.5, 0.0], [0.0], 20.0)[0, 0]:5.2f} m",
      "(the ray leaves the map)")

# %% [markdown]
# ### The exact cell walk (the oracle)
#
# A ray crosses a sequence of cells; a cell is entered whenever the ray
# crosses a vertical or a horizontal grid line. Amanatides and Woo ("A fast
# voxel traversal algorithm for ray tracing", Eurographics 1987) noticed
# that the distances along the ray at which it crosses successive vertical
# lines grow by a constant, $1/|\cos\phi|$ cells, and those of horizontal
# lines by $1/|\sin\phi|$. So the walk keeps two numbers, the distance to the
# next vertical and to the next horizontal line, and always steps across the
# nearer one. Each step costs an addition and a comparison, and the walk
# visits exactly the cells the ray passes through. This is the readable
# version in `localize`, one ray at a time. Setting up the walk is the same
# for both axes (which way the index steps, how far to the first grid line,
# how far between lines), so one small function does it, once for x with
# $\cos\phi$ and once for y with $\sin\phi$:

# %%
print(inspect.getsource(_axis_walk))
source = inspect.getsource(cast_ray)
print(source.splitlines()[0])
print('    """(docstring omitted)"""' + source.split('"""')[2])

# %% [markdown]
# It is exact, and slow: a Python loop per cell per ray, about 0.04 million
# rays per second. A particle filter with 10,000 particles and 60 beams needs
# 600,000 rays per step. The tests compare it with an even simpler oracle
# (sampling the ray every 0.1 mm) and then use it to judge the two fast
# methods.
#
# ### Ray marching on a clearance field
#
# Far from walls the cell walk wastes its time: it could jump. If we know,
# for each free cell, the distance $d$ from anywhere in the cell to the
# nearest obstacle, a ray in that cell can safely jump $d$ ahead: it cannot
# have skipped an obstacle (Hart's "sphere tracing", 1996). The distance is
# the Euclidean distance transform of the map, computed once. Near a wall
# $d$ becomes small and pure marching would crawl (and, with the usual
# centre-to-centre distances, it can even clip corners); so our marcher
# takes the *longer* of the safe jump and the cell walk's step to the next
# cell boundary. Both steps are safe, so it finds exactly the cell the exact
# walk finds; and all rays march together as numpy arrays, rays that have
# finished dropping out. The working state is float32; the final range is
# recomputed in float64 from where the ray entered the hit cell.
#
# ### A lookup table
#
# The fastest cast is no cast: precompute the range from every cell centre
# in every one of `n_bins` headings and look it up. Building the table
# naively would cast $H \times W \times$ `n_bins` rays (230 million for an
# 800 x 800 map at 1° bins). Instead, for each heading the map is swept along
# parallel lines of that heading, and one pass along each line gives every
# cell on it the distance to the next obstacle ahead (and, in the opposite
# direction, behind): a few seconds for that map. The lookup then rounds the
# pose to its cell centre and the beam's heading to the nearest bin: its
# error is a *quantisation* error, studied below.
#
# ### Do they agree?
#
# On a random map, 300 random poses and 24 random beam angles each:

# %%
rmap = maps.random_rooms((90, 110), 0.1, np.random.default_rng(2024), n_boxes=25)
r_poses = rmap.sample_free(300, rng)
r_angles = rng.uniform(-np.pi, np.pi, 24)
z_exact = cast(rmap, r_poses, r_angles, 6.0, method="exact")
z_march = cast(rmap, r_poses, r_angles, 6.0, method="march")
z_lut = cast(rmap, r_poses, r_angles, 6.0, method="lut", n_bins=360)
err_march, err_lut = np.abs(z_march - z_exact), np.abs(z_lut - z_exact)
# the marcher's error is pure round-off (~1e-14 m, digits that differ between CPUs): print its bound
print(f"march: max |error| below 1e-9 m: {err_march.max() < 1e-9}, within one cell on "
      f"{np.mean(err_march <= 0.1):.2%} of rays")
bound = 2 * rmap.resolution + z_exact * np.pi / 360
print(f"lut:   within 2 cells + r*pi/n_bins on {np.mean(err_lut <= bound):.2%} of rays, "
      f"median error {np.median(err_lut) * 100:.1f} cm, worst {err_lut.max():.2f} m")

# %% [markdown]
# The marcher is exact up to rounding. The table is exact *at cell centres
# and bin headings* in most cases, and otherwise carries three errors
# (documented in `RayCaster`): the swept line passes near, not through,
# the cell centre; the pose moves to its cell centre (at most
# $\text{resolution}/\sqrt 2$); and the beam turns to the nearest bin (at
# most $\delta = \pi/n_\text{bins}$). The last one grows with the range: a
# beam of length $r$ hitting a wall at incidence angle $\alpha$ moves its hit
# point by about $r\delta$ sideways, which changes the range by
# $r\delta\tan\alpha$, without bound for grazing beams. The figure compares
# a coarse table (36 bins, 10°) with a fine one (360 bins, 1°): on the left
# the distribution of the errors, on the right how the large ones (the 90th
# percentile) grow with the range, each against its line
# $2\,\text{cells} + r\pi/n_\text{bins}$ (errors of zero are drawn at 0.1 mm on
# the log scale).

# %%
# left: how the errors are distributed (most are a few cm; a few rays are off by metres: grazing
# beams and beams that turn past a corner). Right: how the large errors grow with the range, the
# 90th percentile per 1 m of range against the line 2 cells + r pi / n_bins of each table
fig, axs = plt.subplots(1, 2, figsize=(10, 3.6), layout="constrained")
r_edges = np.arange(0.0, 7.0, 1.0)
for nb, colour in ((36, "tab:orange"), (360, "tab:blue")):
    e = np.abs(cast(rmap, r_poses, r_angles, 6.0, method="lut", n_bins=nb) - z_exact).ravel()
    r_ex = z_exact.ravel()
    under = np.mean(e <= 2 * rmap.resolution + r_ex * np.pi / nb)
    print(f"n_bins = {nb:3d}: median error {np.median(e) * 100:.1f} cm, {under:.1%} of rays under the line, "
          f"{np.mean(e > 1.0):.1%} off by more than 1 m")
    axs[0].plot(np.sort(e) + 1e-4, np.arange(1, e.size + 1) / e.size, color=colour, label=f"n_bins = {nb}")
    which = np.digitize(r_ex, r_edges) - 1
    p90 = [np.percentile(e[which == b], 90) for b in range(len(r_edges) - 1)]
    mid = r_edges[:-1] + 0.5
    axs[1].plot(mid, p90, "o-", color=colour, label=f"n_bins = {nb}: 90th percentile")
    axs[1].plot(mid, 2 * rmap.resolution + mid * np.pi / nb, "--", color=colour, label=f"n_bins = {nb}: the line")
axs[0].axvline(2 * rmap.resolution, color="0.5", lw=1)
axs[0].text(2 * rmap.resolution * 1.1, 0.05, "2 cells", fontsize=8)
axs[0].set_xscale("log")
axs[0].set_xlabel("|lut - exact| [m] (log scale)")
axs[0].set_ylabel("fraction of rays with a smaller error")
axs[0].legend(fontsize=8)
axs[1].set_xlabel("exact range [m]")
axs[1].set_ylabel("|lut - exact| [m]")
axs[1].set_ylim(0, None)
axs[1].legend(fontsize=7)
plt.show()

# %% [markdown]
# **Speed.** `python benchmarks/bench_raycast.py` measures 10,000 poses x 60
# beams on the 800 x 800 benchmark map (CPU time of one core, on the shared
# 2-core machine the book was written on; your numbers will differ):
#
# | method | time for 600,000 rays | rays per second |
# |---|---:|---:|
# | `"exact"` (Python cell walk) | about 15 s | 0.04 M |
# | `"march"` (vectorised) | about 0.13 s | 4.5 M |
# | `"lut"` (table lookup) | about 5 ms | 115 M |
#
# plus one-off costs: 0.25 s for the clearance field and about 6 s for the
# 360-bin table (460 MB of 16-bit ranges for that map; the office map's table
# takes 17 MB and a fraction of a second). For reference, the C++ library
# range_libc (Walsh and Karaman 2018) reaches about 5 M rays/s marching and
# 150 M rays/s with its table on this machine. In a filter, build one
# `RayCaster(grid, max_range, method)` and call its `cast` at every step:
# it keeps the field or the table.
#
# ### The simplest marcher, and its step size
#
# Many first implementations (the CMU homework reports among this book's
# sources, for example) cast a ray by walking along it in **fixed steps**:
# look up the cell under the point, stop at the first occupied one. Two errors
# follow from the step $s$. The range comes out up to one step too long, since
# the wall is noticed only at the first sample inside it; and a sample can land
# *beyond* a wall thinner than a step — or cut the corner of an obstacle cell —
# so the ray **slips through** and reads whatever lies behind. The first error
# is bounded by $s$; the second is not bounded at all. A step no longer than
# the cell size keeps both small but costs $r/s$ lookups per ray, which is what
# the marcher above avoids. (A classic slip when writing the loop: adding the
# distance travelled to itself instead of adding the step doubles the step each
# time, so far ranges are sampled ever more coarsely.) On the random map above:

# %%
def fixed_step_cast(grid, poses, angles, max_range, step):
    """Walk every ray in steps of ``step`` metres; first sample in an obstacle (or off the map) ends it."""
    t = np.arange(step, max_range + step / 2, step)                       # sample distances
    a = poses[:, 2:3] + angles[None, :]                                  # (P, B) beam directions
    px = poses[:, 0, None, None] + t * np.cos(a)[..., None]               # (P, B, S)
    py = poses[:, 1, None, None] + t * np.sin(a)[..., None]
    j = np.floor((px - grid.origin[0]) / grid.resolution).astype(int)
    i = np.floor((py - grid.origin[1]) / grid.resolution).astype(int)
    inside = (i >= 0) & (i < grid.shape[0]) & (j >= 0) & (j < grid.shape[1])
    blocked = ~inside | grid.obstacles[np.clip(i, 0, grid.shape[0] - 1), np.clip(j, 0, grid.shape[1] - 1)]
    first = np.where(blocked.any(axis=-1), blocked.argmax(axis=-1), t.size - 1)
    return np.minimum(t[first], max_range)


print(" step [m] | lookups per ray | mean |error| | rays that slip through (error > 0.5 m)")
slips = {}
for s_step in (0.05, 0.1, 0.2, 0.4):
    z_fixed = fixed_step_cast(rmap, r_poses, r_angles, 6.0, s_step)
    err_fixed = np.abs(z_fixed - z_exact)
    slips[s_step] = np.mean(err_fixed > 0.5)
    print(f"  {s_step:5.2f}  | {6.0 / s_step:15.0f} | {100 * err_fixed.mean():9.1f} cm | {slips[s_step]:8.2%}")
assert slips[0.05] < slips[0.2] < slips[0.4]

# %% [markdown]
# With steps of half a cell the error is a few centimetres and rays rarely
# slip; at two and four cells a growing share of rays passes through thin walls
# and corners — and those are the beams that ruin a particle's weight, since
# they report a far wall where the map has a near one.
#
# ## The beam model
#
# A real scan is not the expected scan plus a little Gaussian noise. People
# walk in front of the robot, glass and black surfaces swallow the beam,
# sunlight and cross-talk produce phantom readings. PR (section 6.3) models
# the reading $z$ of a beam with expected range $z^*$ as a mixture of four
# causes:
#
# * **hit**: the beam hit the expected surface, with Gaussian noise:
#   $p_\text{hit}(z) = \eta\,\mathcal N(z; z^*, \sigma_\text{hit}^2)$ on
#   $[0, z_\text{max}]$, where $\eta$ divides by the Gaussian's mass inside
#   that interval (it matters only for $z^*$ near 0 or near $z_\text{max}$);
# * **short**: something not in the map stood in front:
#   $p_\text{short}(z) = \lambda e^{-\lambda z} / (1 - e^{-\lambda z^*})$ on
#   $[0, z^*]$, an exponential (nearer obstacles hide farther ones) divided by
#   its mass below $z^*$, since it can only be short of the expected surface;
# * **max**: the beam got no return and read $z_\text{max}$: a point mass;
# * **rand**: a random reading, uniform $1/z_\text{max}$ on $[0, z_\text{max})$.
#
# $$p(z \mid z^*) = z_\text{hit}\,p_\text{hit} + z_\text{short}\,p_\text{short}
#  + z_\text{max}\,p_\text{max} + z_\text{rand}\,p_\text{rand},$$
#
# with weights that sum to one,
#
# $$z_\text{hit} + z_\text{short} + z_\text{max} + z_\text{rand} = 1.$$
#
# (One of the seed reports writes the exponential with a scale instead of a
# rate, $\frac{1}{\lambda}e^{-z/\lambda}$, and without its normaliser; PR and
# `localize` use the rate $\lambda$ in 1/m and the normalised form.)
#
# Because it mixes densities with a probability mass, PR calls the picture a
# **pseudo-density**; we draw the mass as a bar whose *area* is $z_\text{max}$:

# %%
beam = BeamModel(grid, MAX_RANGE, z_hit=0.75, z_short=0.1, z_max=0.05, z_rand=0.1, sigma_hit=0.15,
                 lambda_short=0.7, method="lut")
fig, ax = plt.subplots(figsize=(8, 3.8))
plot_beam_pdf(beam, 5.0, ax=ax)
ax.set_title("Beam model pseudo-density for an expected range z* = 5 m (after PR figure 6.4)")
plt.show()

# %% [markdown]
# Every component is a proper density, and the whole mixture has
# probability one: the continuous part integrates to $1 - z_\text{max}$ over
# $[0, z_\text{max})$, and the point mass supplies the rest. The tests check
# this for many $z^*$; here for three:

# %%
for zstar in (0.05, 5.0, MAX_RANGE):
    cont = integrate.quad(lambda z: float(beam.pdf(min(z, MAX_RANGE * (1 - 1e-12)), zstar)), 0, MAX_RANGE,
                          points=[zstar] if zstar < MAX_RANGE else None, limit=400)[0]
    print(f"z* = {zstar:4.2f} m: integral of the density {cont:.6f} + max-range mass {beam.z_max:.2f} "
          f"= {cont + beam.z_max:.6f}")

# %% [markdown]
# **A reading at max range** is where a density and a point mass meet. The
# reading $z = z_\text{max}$ ("no return") has a probability of its own, the mass
# $z_\text{max}$, while the continuous parts give any single reading probability
# zero. A likelihood, though, only compares hypotheses for the *same* reading, and
# PR's table 6.1 adds all four terms at every $z$; `BeamModel`, the self-check
# `check.beam_model` and the homework follow it:
# $p(z_\text{max} \mid z^*) = z_\text{hit}\,p_\text{hit}(z_\text{max} \mid z^*) +
# z_\text{short}\,p_\text{short}(z_\text{max} \mid z^*) + z_\text{max}$ (the uniform
# part stops below $z_\text{max}$), and a reading beyond $z_\text{max}$ counts as
# $z_\text{max}$. A beam expected to hit a wall well inside the range scores about
# the mass alone; a beam expected to fly into open space ($z^* = z_\text{max}$) has
# half of its truncated hit Gaussian at $z_\text{max}$ and scores far more, so a
# particle that expects open space where the laser saw none is rewarded (ROS
# AMCL's beam model does the same). Adding a mass to a density mixes units, but it
# changes no integral (a point has no width), and every particle is scored the
# same way for the same reading, so the weights stay comparable:

# %%
for zstar in (5.0, MAX_RANGE):
    hit_density = beam.z_hit * float(beam.components(MAX_RANGE, zstar)["p_hit"])
    print(f"p(z = max range | z* = {zstar:4.1f} m) = {float(beam.pdf(MAX_RANGE, zstar)):.3f}"
          f"  = hit density {hit_density:.3f} per metre + the mass z_max = {beam.z_max:.2f}")

# %% [markdown]
# So the 4.040 is neither a probability nor a density alone: 3.989 of it is
# the hit part's density (per metre, half of its truncated Gaussian piles up
# against $z_\text{max}$), and 0.050 is the point mass, a probability. Being
# larger than 1, it could not be a probability; it is a likelihood, used only
# to compare particles on the same reading.
#
# Sampling from the model (what the simulator of the particle-filter
# chapters does) first picks a cause with the mixture weights, then draws
# from it by inverting its cumulative distribution. The histogram of 200,000
# draws matches the density:

# %%
draws = beam.sample_expected(np.full(200_000, 5.0), rng)
fig, ax = plt.subplots(figsize=(8, 3.2))
counts, edges = np.histogram(draws[draws < MAX_RANGE], bins=160, range=(0, MAX_RANGE))
# divide by *all* draws, so that the bars integrate to 1 - z_max like the density's continuous part
ax.stairs(counts / (draws.size * np.diff(edges)), edges, fill=True, color="0.7", label="samples")
zz = np.linspace(0, MAX_RANGE, 800, endpoint=False)
ax.plot(zz, beam.pdf(zz, 5.0), "k", lw=1, label="pdf")
ax.set_xlabel("z [m]")
ax.legend()
plt.show()
print(f"fraction of max-range readings: {np.mean(draws == MAX_RANGE):.4f} (z_max = {beam.z_max})")
assert abs(np.mean(draws == MAX_RANGE) - beam.z_max) < 5 * np.sqrt(beam.z_max * (1 - beam.z_max) / draws.size)

# %% [markdown]
# ## Expected versus measured scans
#
# Now a measured scan. We simulate it from the true pose with the beam
# model itself, and add what the map does not know: two people standing in
# front of the robot.

# %%
world = np.array(grid.data)
for cx, cy in [(7.3, 5.9), (8.2, 5.0)]:
    maps.draw_box(world, grid.resolution, cx - 0.15, cy - 0.15, cx + 0.15, cy + 0.15)
world = localize.OccupancyGrid(world, grid.resolution)
world_beam = BeamModel(world, MAX_RANGE, **beam.params, method="march")
measured = world_beam.sample(true_pose[None], angles, rng)[0]
expected = beam.expected(true_pose[None], angles)[0]
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4), gridspec_kw={"width_ratios": [1.3, 1]})
plot_scan_on_map(grid, true_pose, angles, measured=measured, expected=expected, max_range=MAX_RANGE, ax=ax0,
                 zoom=4.5)
ax0.set_title("Measured (orange) and expected (blue) scans at the true pose")
plot_ranges(angles, measured=measured, expected=expected, max_range=MAX_RANGE, ax=ax1)
plt.tight_layout()
plt.show()

# %% [markdown]
# Most measured end points sit on the walls the ray caster found; a few fall
# short (the people, and the model's own short readings), a few read max
# range, a few are random. A good model must score this scan highly at the
# true pose despite those outliers.
#
# ## Combining the beams: product, not sum
#
# If the beams' errors are independent given the pose, the likelihood of the
# scan is the **product** of the beams' likelihoods (PR equation 6.2):
#
# $$p(z \mid x, m) = \prod_{k=1}^{B} p(z^k \mid x, m),\qquad
#   \log p(z \mid x, m) = \sum_{k} \log p(z^k \mid x, m).$$
#
# In log space the product becomes a sum, which does not underflow (61
# densities of order 0.01 multiply to $10^{-122}$) and is what
# `log_likelihood(poses, ranges, angles)` returns for every pose. Let us
# score the true pose and poses displaced by 10, 20 and 30 cm across the
# corridor:

# %%
cands = true_pose + np.array([[0, 0, 0], [0, 0.1, 0], [0, 0.2, 0], [0, 0.3, 0]])
per_beam = beam.pdf(measured, beam.expected(cands, angles))  # (4, 61) densities
log_product = np.log(per_beam).sum(axis=1)
beam_sum = per_beam.sum(axis=1)
for c, lp, s in zip(cands, log_product, beam_sum):
    print(f"y = {c[1]:.1f}: log of the product {lp:8.1f}   sum of densities {s:6.2f}")
print(f"true pose versus 10 cm off: product ratio exp({log_product[0] - log_product[1]:.1f}), "
      f"sum ratio {beam_sum[0] / beam_sum[1]:.2f}")
assert log_product[0] - log_product[1] > 20 and beam_sum[0] / beam_sum[1] < 2   # the sum separates weakly

# %% [markdown]
# One of the seed reports scored a particle by *summing* the per-beam
# probabilities (and exponentiating the sum). A sum treats the scan as "how
# many beams fit", which sounds robust, but it is not the probability of
# anything: it cannot be plugged into Bayes' rule, and it separates poses
# only weakly, because one excellent beam cannot make up for, and one
# terrible beam cannot veto, anything. The product is the likelihood under
# the stated independence assumption and is what Bayes' rule needs; its
# robustness to outliers comes from the mixture (the short and random
# components keep a single bad beam from reaching zero), not from summing.
#
# ### The plain Gaussian model
#
# The colour-tile tutorial among our seeds uses the simplest model: each
# beam's error is zero-mean Gaussian, nothing else. That is the beam model
# with $z_\text{hit} = 1$. It works on clean data; one unexpected obstacle
# ruins it. Below, the scan with the two people, scored by both models at
# the true pose and at a pose 30 cm away:

# %%
gauss = BeamModel(grid, MAX_RANGE, 1.0, 0.0, 0.0, 0.0, sigma_hit=0.15, caster=beam.caster)
two = cands[[0, 3]]
for name, model in [("plain Gaussian", gauss), ("mixture", beam)]:
    ll = model.log_likelihood(two, measured, angles)
    winner = "true pose" if ll[0] > ll[1] else "WRONG pose"
    print(f"{name:15s}: log-likelihood true {ll[0]:12.1f}, 30 cm off {ll[1]:12.1f} -> {winner} wins")
    assert (ll[0] > ll[1]) == (name == "mixture")
assert np.isclose(0.5 * (3 / 0.15) ** 2, 200)      # the cost of one beam 3 m short, below

# %% [markdown]
# Under the Gaussian a beam that reads 3 m short costs $\frac12(3/0.15)^2 =
# 200$ nats, more than all the other beams together can earn back, so the
# model prefers whichever pose best "explains" the people, a wrong one.
#
# ### Overconfidence, and tempering
#
# The independence assumption is false: neighbouring beams see the same
# wall, the same unmapped chair, the same map error. A product of $B$
# correlated beams counts the same evidence many times over, and the
# posterior becomes far too sharp. With 10 cm of displacement already worth
# the factor printed above, a cloud of particles collapses onto one or two
# of them. A way to see it is the effective sample size (ESS) of the
# normalised weights $w_i$, $1/\sum_i w_i^2$: 1 means one particle holds all
# the weight.

# %%
cloud = true_pose + rng.normal(0, [0.15, 0.15, 0.05], size=(2000, 3))
cloud = cloud[grid.is_free(cloud)]


def ess(logw):
    w = np.exp(logw - logw.max())
    w /= w.sum()
    return 1.0 / np.sum(w**2)


rows = []
for label, kwargs in [("all 61 beams", {}), ("max_beams = 12", {"max_beams": 12}),
                      ("temper = 0.1", {"temper": 0.1}), ("12 beams and temper = 0.3", {"max_beams": 12, "temper": 0.3})]:
    m = BeamModel(grid, MAX_RANGE, **beam.params, caster=beam.caster, **kwargs)
    rows.append((label, ess(m.log_likelihood(cloud, measured, angles))))
print(f"{len(cloud)} particles around the true pose")
for label, e in rows:
    print(f"  {label:28s} ESS = {e:7.1f}")
assert all(e > 2 * rows[0][1] for _, e in rows[1:])    # both remedies widen the posterior

# %% [markdown]
# Two standard remedies, both options of every range model here:
#
# * **beam subsampling** (`max_beams`, as ROS AMCL's `laser_max_beams`): use
#   a few evenly spaced beams, far enough apart to be closer to independent;
# * **tempering** (`temper` $= \gamma \in (0, 1]$): raise the likelihood to
#   the power $\gamma$, i.e. multiply the log-likelihood by $\gamma$, as if the
#   scan held $\gamma B$ independent beams (PR section 6.3.4 mentions this
#   "dampening"; Thrun et al. set it by hand).
#
# Neither is derived from first principles; both trade a little information
# for a posterior that is not overconfident, which keeps a particle filter
# from throwing away the particles that would have recovered from a wrong
# lock. The MCL chapters use `temper` values found by experiment.
#
# ## The likelihood field
#
# The beam model needs a ray cast per beam and is discontinuous in the pose
# (a beam passing a door edge jumps from 2 m to 8 m). The **likelihood
# field** model (PR section 6.4, table 6.3; the default of ROS AMCL) skips
# ray casting altogether. It projects each beam's *end point* into the map
# and asks how far it is from the nearest obstacle, $d$:
#
# $$p(z^k \mid x, m) = z_\text{hit}\,\mathcal N(d; 0, \sigma_\text{hit}^2)
#   + \frac{z_\text{rand}}{z_\text{max}},$$
#
# skipping max-range readings. Since $d$ depends only on the end point's
# cell, the whole bracket is precomputed per cell from the map's distance
# field: scoring a scan is one table lookup per beam (about 110 M beams per
# second with `benchmarks/bench_sensors.py`, against 4.5 M rays per second
# for marching). End points outside the map get the distance `max_dist`.

# %%
lf = LikelihoodField(grid, MAX_RANGE, z_hit=0.85, z_rand=0.15, sigma_hit=0.15)
fig, ax = plt.subplots(figsize=(9, 5))
plot_likelihood_field(lf, ax=ax)
ends = lf.endpoints(true_pose[None], measured, angles)[0][measured < MAX_RANGE]
ax.plot(ends[:, 0], ends[:, 1], "c.", ms=4, label="measured end points at the true pose")
ax.legend(loc="upper right", fontsize=8)
ax.set_title("Likelihood field of the office: end-point density")
plt.show()

# %% [markdown]
# How do both models score poses displaced by 20 cm along the corridor
# ($\pm x$), across it ($\pm y$) and turned by $\pm 0.1$ rad, on this scan
# with its two people?

# %%
offsets = np.array([[0, 0, 0], [0.2, 0, 0], [-0.2, 0, 0], [0, 0.2, 0], [0, -0.2, 0], [0, 0, 0.1], [0, 0, -0.1]])
cands = true_pose + offsets
drop = {}
for name, model in [("beam model", beam), ("likelihood field", lf)]:
    ll = model.log_likelihood(cands, measured, angles)
    drop[name] = ll - ll[0]
    print(f"{name:17s} log-likelihood minus the true pose's:", drop[name].round(1))
b_, f_ = drop["beam model"], drop["likelihood field"]
assert np.all(b_[3:] < -25) and np.all(f_[[4, 5, 6]] < -10)   # sharp across (beam model) and in heading
assert -5 < f_[3] < 0                                          # ... but the field hardly notices +20 cm in y
assert np.all(np.abs(b_[1:3]) < 5) and np.all(np.abs(f_[1:3]) < 5) and f_[1] > 0   # along: hardly at all
# the most one beam can lose against a perfect one: the field's peak over its floor (at max_dist);
# the beam model's peak at z = z* over its lowest value, for each beam's z* of this scan
cap_field = float(np.diff(lf.point_log_prob([lf.max_dist, 0.0]))[0])
z_star = beam.expected(true_pose[None], angles)[0]
z_grid = np.linspace(0, MAX_RANGE * (1 - 1e-9), 8001)
cap_beam = np.array([np.log(beam.pdf(z, z)) - np.log(beam.pdf(z_grid, z)).min() for z in z_star])
print(f"largest loss of one beam: likelihood field {cap_field:.2f} nats "
      f"(ln({np.exp(lf.point_log_prob(0.0)):.3f} / {np.exp(lf.point_log_prob(lf.max_dist)):.4f})), "
      f"beam model {np.median(cap_beam):.1f} nats (median over this scan's beams)")
print(f"an end point 20 cm from the nearest wall loses {float(np.diff(lf.point_log_prob([0.2, 0.0]))[0]):.2f} nats")

# %% [markdown]
# In heading both models are sharp, and the beam model is sharp across the
# corridor in both directions. The likelihood field is sharp for the shift
# towards the lower wall ($-y$) but hardly notices the same shift towards the
# upper one (a drop of only about 3 nats): it scores each end point by its
# distance to the nearest obstacle in *any* direction, so end points pushed
# into a wall still sit on an obstacle and score fully; each end point that
# now falls short of the other wall loses a bounded amount (a 20 cm miss
# costs 0.88 nats, and the uniform floor caps the loss per beam at 4.76
# nats, printed above; the beam model's cap is about the same, 5.1 nats, so
# the two models differ in *which* beams lose, not in how much one beam can
# lose); and in this scan about as many end
# points that sat slightly off the walls at the true pose land on them after
# the shift. Which direction comes off lightly depends on the scan and on the
# walls' thickness; the lesson is that the field's verdict across a corridor
# is weaker than it looks. *Along* the corridor both models hardly care: most beams end on the two long walls, which
# look the same 20 cm further on, and only the few beams that reach a door,
# the pillar or the far end carry that information (the corridor version of
# the aperture problem). The likelihood field even prefers the pose 20 cm
# ahead by a small margin: its end points are scored by the distance to
# *any* wall, so the people's end points, which the beam model explains as
# short readings, find a better match there. A single scan in a corridor
# localizes the robot across it, not along it; the filter accumulates the
# rest over time.
#
# The likelihood field is smoother in the pose and much faster; it ignores
# what lies *along* the beam (it happily accepts an end point behind a wall),
# which the beam model does not. The MCL chapter compares both on real data.
#
# ### What came before: occupancy lookup and hit counting
#
# Before ray casting, the CMU homework reports among our sources tried two
# cheaper scores, and both lost. Each projects the beams' end points into the
# map, as the likelihood field does, and then
#
# * **occupancy lookup** reads the (smoothed) occupancy probability at every
#   end point and adds them up: a pose scores well if its end points land on
#   walls;
# * **hit counting** thresholds that probability and counts the end points
#   that land on an obstacle cell.
#
# Both reward end points on walls and punish nothing else. A pose whose beams
# pass *through* walls, or that stands inside a wall or outside the building,
# is not penalised as long as its end points happen to touch some obstacle; and
# neither score is a likelihood, so it cannot be multiplied into Bayes rule
# (the sum has the weakness of the previous section). The likelihood field is
# what these become when done properly — a density of the distance to the
# nearest obstacle, with a floor for unexplained readings — and the beam model
# adds what lies along the ray. Compare the three scores on the scan with the
# two people, at the true pose, 20 cm across the corridor, and at a pose *inside
# the corridor's wall* facing the same way:

# %%
from scipy import ndimage  # noqa: E402

occ = np.nan_to_num(np.asarray(grid.data, dtype=float), nan=1.0)
smooth = ndimage.gaussian_filter(occ, sigma=1.0)                       # a blurred map, as in the reports


def endpoint_scores(pose):
    ends = lf.endpoints(np.asarray(pose)[None], measured, angles)[0][measured < MAX_RANGE]
    ij = np.array([grid.world_to_cell(e) if grid.contains(e) else (-1, -1) for e in ends])
    ok = ij[:, 0] >= 0
    o = np.zeros(len(ends))
    o[ok] = smooth[ij[ok, 0], ij[ok, 1]]
    return o.sum(), int(np.sum(o >= 0.5))


wall_y = next(y for y in np.arange(true_pose[1], 0, -0.05) if grid.obstacles[tuple(grid.world_to_cell([true_pose[0], y]))])
test_poses = {"true pose": true_pose, "20 cm across": true_pose + [0, 0.2, 0],
              "inside the wall": np.array([true_pose[0], wall_y, true_pose[2]])}
print(f"{'':16s} | occupancy sum | hits | beam log-likelihood")
scores = {}
for name, pose in test_poses.items():
    occ_sum, hits = endpoint_scores(pose)
    scores[name] = (occ_sum, hits, float(beam.log_likelihood(pose[None], measured, angles)[0]))
    print(f"{name:16s} | {occ_sum:13.1f} | {hits:4d} | {scores[name][2]:10.1f}")
assert scores["inside the wall"][2] < scores["true pose"][2] - 100                  # the beam model: impossible
assert scores["inside the wall"][1] >= 0.2 * scores["true pose"][1]                # hit counting: still plausible
assert scores["true pose"][1] > scores["20 cm across"][1] > scores["inside the wall"][1]

# %% [markdown]
# The end-point scores do rank the three poses in the right order, but they
# leave the pose inside the wall far from impossible — a quarter or so of the
# true pose's hits, in a score that counts hits, not probability — while the
# beam model rules it out by nearly 200 nats, because from inside a wall every
# beam is expected to read zero. This is the failure the
# reports describe — particles drifting out of the free space — and the reason
# they moved to ray casting.
#
# ## Landmarks: range and bearing
#
# Some robots do not see walls but **landmarks** they can identify: beacons,
# fiducial markers, trees. A sighting of landmark $j$ at $(m_x, m_y)$ is a
# range and a bearing (PR section 6.6),
#
# $$r = \sqrt{(m_x - x)^2 + (m_y - y)^2} + \varepsilon_r, \qquad
#   \varphi = \operatorname{atan2}(m_y - y, m_x - x) - \theta + \varepsilon_\varphi,$$
#
# with independent Gaussian noises and the bearing difference wrapped to
# $[-\pi, \pi)$. The EKF chapter linearises it with the Jacobian with respect
# to the pose, $H = \begin{pmatrix} -\Delta x/r & -\Delta y/r & 0\\
# \Delta y/r^2 & -\Delta x/r^2 & -1\end{pmatrix}$ (PR equation 7.14), which
# `LandmarkModel.jacobian` returns and the tests check against finite
# differences:

# %%
lm = LandmarkModel([[2.0, 9.0], [15.0, 10.0], [18.0, 1.5]], sigma_range=0.1, sigma_bearing=0.05)
print("expected (range, bearing):\n", lm.expected(true_pose).round(3)[0])
sighting = lm.sample(true_pose, rng)
print("a noisy sighting:\n", sighting.round(3))
H = lm.jacobian(true_pose, 1)
step = 1e-6
num = np.column_stack([(lm.expected(true_pose + e, [1])[0, 0] - lm.expected(true_pose - e, [1])[0, 0]) / (2 * step)
                       for e in np.eye(3) * step])
# the finite differences carry round-off of about 1e-16 / step = 1e-10, whose digits differ between
# CPUs: print the bound they are checked against, not the round-off itself
err = np.abs(H - num).max()
assert err < 1e-7, err
print("Jacobian for landmark 1:\n", H.round(4), "\nagrees with central finite differences to < 1e-7:", err < 1e-7)

# %% [markdown]
# ## Learning the beam model's parameters
#
# Where do $z_\text{hit}, \dots, \lambda_\text{short}$ come from? From data:
# record scans at known poses, ray cast the expected ranges, and fit. PR
# (section 6.3.3, table 6.2) gives an **expectation-maximisation** algorithm:
#
# 1. *E-step*: for each reading, compute the probability $e_{i,c}$ that cause
#    $c$ produced it, proportional to $z_c\,p_c(z_i \mid z_i^*)$;
# 2. *M-step*: each weight is the mean of its $e_{i,c}$; $\sigma_\text{hit}$ is
#    the $e_\text{hit}$-weighted RMS of $z_i - z_i^*$; $\lambda_\text{short}$ is
#    the rate that best explains the short readings;
# 3. repeat until the likelihood stops improving.
#
# Our `fit_beam_model` follows the table with two corrections (documented
# in `localize.beam_learning`): the responsibilities use the *weighted*
# components, as EM requires, and readings at max range belong to the point
# mass alone. PR's closed form $\lambda = \sum e_\text{short} / \sum
# e_\text{short} z$ ignores that the short readings are truncated at $z^*$;
# the default solves the truncated equation instead. A test recovers known
# parameters from simulated scans; so do we, here from 200 poses x 61 beams:

# %%
truth = dict(z_hit=0.7, z_short=0.12, z_max=0.06, z_rand=0.12, sigma_hit=0.12, lambda_short=0.9)
gen = BeamModel(grid, MAX_RANGE, **truth, caster=beam.caster)
poses_fit = grid.sample_free(200, np.random.default_rng(11))
zs_fit = gen.expected(poses_fit, angles)
z_fit = gen.sample_expected(zs_fit, np.random.default_rng(12))
seen = zs_fit < MAX_RANGE
fit = fit_beam_model(z_fit[seen], zs_fit[seen], MAX_RANGE)
fit_pr = fit_beam_model(z_fit[seen], zs_fit[seen], MAX_RANGE, exact_lambda=False)
print(f"{seen.sum()} readings, EM converged after {fit.n_iter} iterations")
print(f"{'parameter':14s} {'true':>7s} {'EM':>7s} {'EM, PR lambda':>14s}")
for k in truth:
    print(f"{k:14s} {truth[k]:7.3f} {fit.params[k]:7.3f} {fit_pr.params[k]:14.3f}")
# "recovers known parameters": weights within 0.01 (about 3 standard errors for 12,000 readings), sigma_hit
# within 5 % and lambda_short within 10 %; PR's closed-form lambda ignores the truncation and is far off
assert all(abs(fit.params[k] - truth[k]) < 0.01 for k in ("z_hit", "z_short", "z_max", "z_rand"))
assert abs(fit.params["sigma_hit"] / truth["sigma_hit"] - 1) < 0.05
assert abs(fit.params["lambda_short"] / truth["lambda_short"] - 1) < 0.1 < abs(fit_pr.params["lambda_short"] / truth["lambda_short"] - 1)

# %% [markdown]
# With real data the fitted model is only as good as the poses used to
# compute $z^*$ (a pose error of 5 cm inflates $\sigma_\text{hit}$), and the
# beam model itself is an idealisation: PR warns that the fitted parameters
# are usually too confident for use in a filter, which is the
# overconfidence discussed above.
#
# ## Try it: place a pose
#
# The seed CMU report validated its ray caster with a point-and-click tool:
# put a particle on the map, see what it would measure. The widget below
# does the same with sliders: choose $x$, $y$ and the heading; the left panel
# shows that pose's ray-cast scan (blue) against the measured scan (orange),
# the right panel both as range profiles, and the title gives the scan's
# log-likelihood and its weight relative to the true pose. Try to find
# another pose that explains the scan almost as well. The $x$ and $y$
# sliders step from cell centre to cell centre and the heading in whole 2°
# steps: the table lookup works per cell and per heading bin, so a slider
# sitting on a cell edge would flip between two cells on the last bit of its
# value. (In the static book, the figure after the widget shows its starting
# state.)

# %% tags=["nbval-ignore-output"]
pose_scan_widget(grid, beam, angles, measured, start=true_pose + [0.4, 0.2, 0.0], reference_pose=true_pose)

# %%
# the widget's starting position: x and y on cell centres, the heading on the slider's 2-degree steps
fig = pose_scan_figure(grid, beam, angles, measured, *pose_scan_start(grid, true_pose + [0.4, 0.2, 0.0]),
                       reference_pose=true_pose)
plt.show()

# %% [markdown]
# ## Try it: the beam model's parameters
#
# Six sliders for $z_\text{hit}, z_\text{short}, z_\text{max}, z_\text{rand},
# \sigma_\text{hit}, \lambda_\text{short}$ (and one for $z^*$) redraw the
# pseudo-density. Four independent sliders cannot keep the weights summing
# to one, so the figure divides them by their sum and shows the result in
# its title. Watch how a small $z_\text{rand}$ puts a floor under the
# density, which is what makes the model robust.

# %% tags=["nbval-ignore-output"]
beam_density_widget(max_range=10.0)

# %%
fig = pseudo_density_figure(z_hit=0.7, z_short=0.1, z_max=0.1, z_rand=0.1, sigma_hit=0.2, lambda_short=0.5)
plt.show()

# %% [markdown]
# ## Summary
#
# * A measurement model gives $p(z \mid x, m)$; for a scan with independent
#   beams it is a product, computed as a sum of logs.
# * Expected ranges come from ray casting: the exact Amanatides-Woo cell
#   walk (readable, the oracle), vectorised marching on a clearance field
#   (exact too, about 4.5 M rays/s) or a lookup table (about 115 M rays/s,
#   with a quantisation error of a cell or two plus $r\pi/n_\text{bins}$).
#   Rays leaving the map read `max_range`; sensors outside the map or inside
#   walls read 0.
# * The beam model mixes a truncated Gaussian hit, truncated exponential
#   short readings, a max-range mass and a uniform floor; each part is
#   normalised, and the mixture has total probability one.
# * A plain Gaussian model is broken by a single unexpected obstacle; a sum
#   of beam probabilities is not a likelihood. The product is principled but
#   overconfident, since real beams are correlated: subsample and temper.
# * The likelihood field scores beam end points against the distance field,
#   needs no ray casting and is the fastest model.
# * The landmark model and its Jacobian serve the EKF; EM fits the beam
#   model's parameters from data.
#
# **Literature.** S. Thrun, W. Burgard, D. Fox, *Probabilistic Robotics*, MIT
# Press 2005, chapter 6 (tables 6.1-6.4, figures 6.3-6.5, equation 7.14).
# J. Amanatides, A. Woo, "A fast voxel traversal algorithm for ray tracing",
# *Eurographics* 1987. J. C. Hart, "Sphere tracing", *The Visual Computer*
# 12(10), 1996. C. Walsh, S. Karaman, "CDDT: Fast approximate 2D ray casting
# for accelerated localization", *ICRA* 2018 (range_libc). D. Fox, W.
# Burgard, S. Thrun, "Markov localization for mobile robots in dynamic
# environments", *JAIR* 11, 1999 (the beam model's origin). A. P. Dempster,
# N. M. Laird, D. B. Rubin, "Maximum likelihood from incomplete data via the
# EM algorithm", *J. Royal Statistical Society B* 39, 1977.

# %% [markdown]
# ## Exercises
#
# 1. **By hand.** A beam model has $z_\text{max} = 10$ m, $z_\text{hit} = 0.8$,
#    $z_\text{short} = 0.1$, $z_\text{max}$-weight $0.05$, $z_\text{rand} = 0.05$,
#    $\sigma_\text{hit} = 0.2$ m, $\lambda_\text{short} = 0.5$/m. The expected
#    range is $z^* = 3$ m. (a) Compute $p(z \mid z^*)$ for $z = 3$ m, $z = 2$ m
#    and $z = 10$ m (no return). (b) A scan has 30 beams that all read exactly
#    their expected range of 3 m; by how much does its log-likelihood drop if
#    one of them reads 2 m instead? And under the plain Gaussian model?
# 2. **Implementation.** Write the *plain* ray marcher of range_libc for one
#    ray: step by the value of `grid.distance_field` at the current cell
#    (centre-to-centre distances) and stop when it falls below half a cell.
#    On a random map, compare it with `cast_ray` on 2,000 random rays: on
#    what fraction does it differ by more than one cell, and why does
#    `localize`'s marcher need the clearance field and the cell-walk step?
# 3. **Experiment.** Tempering versus beam count. For the cloud of particles
#    above and five simulated scans from the true pose, compute the mean ESS
#    under the beam model for `max_beams` in (5, 10, 20, 61) without
#    tempering, and find for 61 beams the `temper` that gives the same mean
#    ESS as 10 beams. What does that say about how many "independent" beams
#    the 61 are worth?
# 4. **Implementation (self-checked).** Write the simplest ray caster of all,
#    for one beam: `my_ray_cast(grid, pose, angle, max_range)` walks from the
#    sensor at `pose = (x, y, theta)` in the direction `theta + angle` in fixed
#    steps and returns the distance at which a step first lands in an obstacle
#    cell (`grid.obstacles`, indexed by `grid.world_to_cell`), or `max_range`
#    if none does within `max_range` or the beam leaves the map. Check it with
#    `localize.check.ray_cast(my_ray_cast)`: its map has walls one cell thick,
#    and it accepts a range within one cell of the exact one. Then make the
#    step one and a half cells and run the check again. What goes wrong, and
#    why? (See "The simplest marcher, and its step size" above.)

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 1
m = BeamModel(None, 10.0, 0.8, 0.1, 0.05, 0.05, sigma_hit=0.2, lambda_short=0.5)
p = m.pdf([3.0, 2.0, 10.0], 3.0)
print("(a) p(3) = %.4f, p(2) = %.4f, p(10) = %.4f" % tuple(p))
print(f"(b) mixture: log-likelihood drops by {math.log(p[0] / p[1]):.2f}")
g = BeamModel(None, 10.0, 1.0, 0.0, 0.0, 0.0, sigma_hit=0.2)
print(f"    plain Gaussian: drops by {float(g.beam_log_pdf(3.0, [[3.0]])[0, 0] - g.beam_log_pdf(2.0, [[3.0]])[0, 0]):.2f}")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# (a) At $z = z^* = 3$: the hit term is $0.8 \cdot \frac{1}{0.2\sqrt{2\pi}} = 0.8 \cdot 1.995 = 1.596$
# ($\eta = 1$ to many digits), the short term $0.1 \cdot 0.5 e^{-1.5} / (1 - e^{-1.5}) = 0.0144$,
# the random term $0.05/10 = 0.005$: $p(3) = 1.615$ per metre. At $z = 2$: the Gaussian is
# five standard deviations away ($\approx 0$), the short term is $0.1 \cdot 0.5 e^{-1} / 0.777 = 0.0237$,
# plus $0.005$: $p(2) = 0.0287$. At $z = 10$: only the point mass, $0.05$ (plus a negligible hit term).
# (b) The log-likelihood changes by $\log(1.615 / 0.0287) = 4.03$ nats: about the gain of
# four good beams. Under the plain Gaussian the drop is $\frac12 (1/0.2)^2 = 12.5$ nats; with a
# 3 m short reading it would be $112.5$, which no number of good beams at other poses can
# compensate in a close comparison.
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 2
def plain_march(grid, x, y, angle, max_range):
    t, res = 0.0, grid.resolution
    df = grid.distance_field
    while t < max_range:
        px, py = x + t * math.cos(angle), y + t * math.sin(angle)
        if not grid.contains([px, py]):
            return max_range
        i, j = grid.world_to_cell([px, py])
        d = df[i, j]
        if d < res / 2:
            return t
        t += d
    return max_range


ex_map = maps.random_rooms((80, 80), 0.1, np.random.default_rng(3), n_boxes=20)
ex_poses = ex_map.sample_free(2000, np.random.default_rng(4))
plain = np.array([plain_march(ex_map, *p, 6.0) for p in ex_poses])
exact_r = np.array([cast_ray(ex_map, *p, 6.0) for p in ex_poses])
# whole per cent: a ray that grazes a cell corner may count on one CPU and not on another
print(f"plain marcher off by more than one cell on {np.mean(np.abs(plain - exact_r) > 0.1):.0%} of rays")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# The plain marcher overshoots: the distance field holds distances between cell *centres*,
# so a step of $d$ from a point that is not a centre can cut the corner of an obstacle cell
# (up to $\sqrt 2 \cdot$ resolution too far), and it stops inside the obstacle rather than
# at its boundary. On most rays the result is off by under a cell, but a few per cent of rays
# slip through a corner and read a far wall. `localize` steps only by the distance between
# the cell *squares* (the clearance field, which never cuts a corner) and, when that is small,
# by the cell walk's step to the next boundary, so it visits the cells the exact walk visits.
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 3
scans = world_beam.sample(np.repeat(true_pose[None], 5, axis=0), angles, np.random.default_rng(31))


def mean_ess(model, temper=1.0):
    return float(np.mean([ess(temper * model.log_likelihood(cloud, z, angles)) for z in scans]))


ess_k = {}
for k in (5, 10, 20, 61):
    m = BeamModel(grid, MAX_RANGE, **beam.params, caster=beam.caster, max_beams=k)
    ess_k[k] = mean_ess(m)
    print(f"max_beams = {k:2d}: mean ESS = {ess_k[k]:7.1f}")
target = mean_ess(BeamModel(grid, MAX_RANGE, **beam.params, caster=beam.caster, max_beams=10))
temps = np.geomspace(0.02, 1, 40)
ess_t = np.array([mean_ess(beam, g) for g in temps])
best = temps[np.argmin(np.abs(np.log(ess_t) - np.log(target)))]
print(f"61 beams tempered by {best:.3f} give mean ESS {mean_ess(beam, best):.1f}, like 10 beams ({target:.1f})")
print(f"61 beams x {best:.3f} = {61 * best:.1f} 'independent' beams")
assert ess_k[5] > ess_k[20] > ess_k[10] > ess_k[61]          # higher with fewer beams, but not monotonic
from localize.sensors import select_beams  # noqa: E402

assert not set(select_beams(61, 10)) <= set(select_beams(61, 20))   # the 10 are not a subset of the 20
# is "20 beams beat 10" a property of the model or of these five scans? Five other scans each, six times:
few = {k: BeamModel(grid, MAX_RANGE, **beam.params, caster=beam.caster, max_beams=k) for k in (10, 20)}
wins = 0
for seed in range(31, 37):
    scans = world_beam.sample(np.repeat(true_pose[None], 5, axis=0), angles, np.random.default_rng(seed))
    wins += mean_ess(few[20]) > mean_ess(few[10])
print(f"20 beams give a larger mean ESS than 10 for {wins} of 6 seeds of five scans (seed 31 is the one above)")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# Dropping beams raises the ESS overall (5 beams against all 61), but not
# monotonically: with these five scans 20 beams give a *larger* mean ESS than 10. That is a
# property of the scans, not of the model: over six seeds of five scans it held for two
# (printed above); which of the two wins depends on the scans. The 10 evenly spaced beams are not a subset of the 20, and a handful of beams that happen to hit a person or a door edge
# decides how peaked the weights are; with so few beams, which ones are kept matters as much as
# how many. Tempering the full scan by a factor $\gamma$ widens the weights smoothly instead. The $\gamma$ that matches 10 beams need not be $10/61$: the ESS of one cloud
# depends on *which* beams are kept (10 beams spread over the field of view keep most of the
# geometry, while a random tenth of the log-likelihood would not), and on the outliers in each
# scan, which is why we average over several scans. The product $61\gamma$ says how many
# independent beams the tempered scan is treated as. On real data the right $\gamma$ is found by
# experiment (the MCL chapters), since it depends on how correlated the beams' errors really
# are: a map error seen by 20 neighbouring beams is one piece of evidence, not twenty.
#
# </details>


# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 4
from localize import check  # noqa: E402


def my_ray_cast(grid, pose, angle, max_range, step=None):
    """Walk along the beam in fixed steps (a quarter of a cell unless told) until a step lands in an obstacle."""
    x, y, theta = pose
    step = grid.resolution / 4 if step is None else step
    c, s = math.cos(theta + angle), math.sin(theta + angle)
    t = 0.0
    while t < max_range:
        p = (x + t * c, y + t * s)
        if not grid.contains(p):
            return max_range
        if grid.obstacles[tuple(grid.world_to_cell(p))]:
            return t
        t += step
    return max_range


print(check.ray_cast(my_ray_cast))
print()
print(check.ray_cast(lambda grid, pose, angle, max_range: my_ray_cast(grid, pose, angle, max_range,
                                                                       step=1.5 * grid.resolution)))

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# With a quarter-cell step the first step inside a wall is at most a quarter
# of a cell beyond where the beam entered it, so the range is a little too
# long but well within one cell, and the check passes. With a step of one and
# a half cells a step can land on each side of a wall one cell thick without
# ever landing in it: the beam passes through the wall and reads whatever lies
# behind, the slip described in the chapter. Shorter steps make the slip rarer
# but cost more lookups per ray, and a step of any fixed length can still cut
# the corner of an obstacle cell; walking from cell to cell across every grid
# line, as `localize.raycast.cast_ray` does, visits every cell the beam
# touches and never slips.
#
# </details>
