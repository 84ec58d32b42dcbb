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
# # Grid localization in (x, y, θ)
#
# A robot on a floor has a position *and a heading*, and what its range sensor
# sees depends on both: the same spot looks different facing north and facing
# east. Grid localization (PR section 8.2, table 8.1; Burgard et al. 1996; Fox,
# Burgard and Thrun 1999) keeps a histogram over all three: one probability per
# map cell and per **heading bin**. This chapter builds it on the office map
# with a simulated laser and odometry, and measures how the cell size trades
# accuracy against work.
#
# You will learn
#
# * how a pose grid is laid out (`belief[k, i, j]`: heading bin, row, column);
# * why the motion update is a **rotation-aware convolution**: each heading slice
#   moves in its own direction;
# * how a table of **expected ranges**, computed once per map, makes the
#   measurement update a table lookup;
# * what the cell size and the number of headings buy, and what they cost.

# %%
import matplotlib.pyplot as plt
import numpy as np

import localize
from localize import geometry, maps, motion, raycast
from localize.gridloc import GridLocalizer, coarsen, expected_range_table
from localize.plot import draw_map, draw_robot, draw_scan

print("localize", localize.__version__)

# %% [markdown]
# ## The world, the robot and its data
#
# The map is the office of the preface, drawn at 5 cm. The robot drives along the
# corridor and turns into a room through a door. Its **odometry** (what the
# wheels report) is the commanded path; the **true** path drifts from it
# according to the odometry motion model of PR table 5.6 (`localize.motion`). At
# every stop the robot takes a **scan** of 12 beams, one every 30°, up to 8 m,
# simulated on the map by ray casting (`localize.raycast`), with 5 cm Gaussian
# noise and 5 % of beams returning nothing (max range).

# %%
truth_map = maps.office(0.05)
ANGLES = np.radians(np.arange(0, 360, 30.0))
MAX_RANGE = 8.0
ALPHAS = (0.02, 0.002, 0.02, 0.002)

odom = [[2.0, 5.5, 0.0]]
for _ in range(15):
    odom.append([odom[-1][0] + 0.5, 5.5, 0.0])
odom.append([odom[-1][0], 5.5, -np.pi / 2])               # turn right on the spot
for _ in range(5):
    odom.append([odom[-1][0], odom[-1][1] - 0.5, -np.pi / 2])
odom = np.array(odom)

rng = np.random.default_rng(3)
truth = [odom[0]]
for t in range(1, len(odom)):
    truth.append(motion.sample_odometry(truth[-1][None], (odom[t - 1], odom[t]), ALPHAS, rng)[0])
truth = np.array(truth)
scans = raycast.cast(truth_map, truth, ANGLES, MAX_RANGE, method="march")
scans = np.clip(scans + rng.normal(0.0, 0.05, scans.shape), 0.0, MAX_RANGE)
scans[rng.random(scans.shape) < 0.05] = MAX_RANGE
print(f"{len(odom)} poses; the true path ends {np.hypot(*(truth[-1, :2] - odom[-1, :2])):.2f} m "
      "from where odometry says")

fig, ax = plt.subplots(figsize=(9, 5.2))
draw_map(truth_map, ax)
ax.plot(odom[:, 0], odom[:, 1], "--", color="tab:gray", label="odometry")
ax.plot(truth[:, 0], truth[:, 1], color="tab:blue", label="true path")
draw_scan(truth[8], ANGLES, scans[8], ax, max_range=MAX_RANGE)
draw_robot(truth[8], ax, radius=0.25)
ax.legend(loc="upper right")
ax.set_title("the office, the robot's path and one scan (step 8)")
plt.show()

# %% [markdown]
# ## The pose grid
#
# The filter works on a coarser copy of the map: `coarsen` merges blocks of
# cells, and a coarse cell is an obstacle if *any* of its cells is, so thin
# walls survive. (Simply redrawing the map at 25 cm would round 20 cm walls
# away.) With 20 cm cells and 36 heading bins of 10° each, the belief is an array
# `belief[k, i, j]` of 36 x 60 x 100 = 216,000 numbers, the probability that the
# robot's heading lies in bin $k$ (centred on $\theta_k = -\pi + k \cdot 10°$)
# and its position in cell $(i, j)$. Only free cells can hold belief.

# %%
grid = coarsen(truth_map, 4)
K = 36
print(grid)
print("belief shape (headings, rows, columns):", (K,) + grid.shape)

# %% [markdown]
# ## The measurement update: expected ranges, computed once
#
# To weigh a scan we need, for every bin, the range each beam *should* read
# there. Casting $216{,}000 \times 12$ rays at every step would be slow; but the
# range from cell $(i, j)$ along an **absolute** direction $\phi$ does not depend
# on the robot's heading. Beam $b$, at angle $\alpha_b$ to the robot's heading,
# looks along $\theta_k + \alpha_b$. If the beam angles are multiples of the bin
# width (our 30° beams and 10° bins are), that is again a bin direction,
# $\theta_{(k + m_b) \bmod K}$. So one table `E[k, i, j]`, the range from cell
# $(i, j)$ along direction $\theta_k$, serves every heading and every beam
# (PR section 6.3 discusses such precomputation). `expected_range_table`
# builds it with the lookup table of `localize.raycast`.
#
# The likelihood of a beam is a Gaussian around the expected range, mixed with
# a small uniform floor for readings the map cannot explain (a reduced form of
# PR's beam model, table 6.1; chapter 5 of this book treats the full model).
# The Gaussian's width must cover the sensor noise *and* the cell size: the
# table gives the range from the cell's centre, the robot can be anywhere in it.

# %%
E = expected_range_table(grid, K, MAX_RANGE)
print("table:", E.shape, E.dtype, f"{E.nbytes / 1e6:.1f} MB")

fig, axes = plt.subplots(1, 2, figsize=(11, 3.4), layout="constrained")
for ax, k in zip(axes, [18, 27]):
    img = ax.imshow(np.where(grid.free, E[k], np.nan), origin="lower", extent=grid.extent, cmap="magma")
    ax.set_title(f"expected range looking {np.degrees(-np.pi + k * 2 * np.pi / K):.0f}° (E[{k}])")
    ax.set_xlabel("x [m]")
fig.colorbar(img, ax=axes, label="range [m]", shrink=0.9)
plt.show()

# %% [markdown]
# One scan, from the very first stop, applied to a uniform belief:

# %%
loc = GridLocalizer(grid, K, ANGLES, MAX_RANGE, expected=E, sigma_hit=0.2, alphas=ALPHAS)
loc.update(scans[0])
est = loc.estimate()
print(f"after one scan: most likely pose ({est[0]:.2f} m, {est[1]:.2f} m, {np.degrees(est[2]):.0f}°); "
      f"truth ({truth[0, 0]:.2f} m, {truth[0, 1]:.2f} m, {np.degrees(truth[0, 2]):.0f}°)")
mass_near = loc.marginal_xy()[np.hypot(*(grid.cell_to_world(np.argwhere(np.ones(grid.shape, bool)))
                                       - truth[0, :2]).T).reshape(grid.shape) < 0.5 + 1e-9].sum()
# (+ 1e-9: cells whose centre lies exactly 0.5 m away count as inside on every CPU, whatever its hypot rounds to)
print(f"belief within 0.5 m of the truth: {mass_near:.3f}")
cell_xy = grid.cell_to_world(np.argwhere(np.ones(grid.shape, bool))).reshape(grid.shape + (2,))
east = cell_xy[..., 0] > 15.0                          # the far end of the corridor
k2, i2, j2 = np.unravel_index(np.argmax(np.where(east, loc.belief, 0.0)), loc.belief.shape)
print(f"second candidate: ({cell_xy[i2, j2, 0]:.1f} m, {cell_xy[i2, j2, 1]:.1f} m, "
      f"{np.degrees(loc.theta[k2]):.0f}°), belief beyond x = 15 m: {loc.marginal_xy()[east].sum():.3f}")
assert 0.985 < mass_near < 0.999
assert abs(cell_xy[i2, j2, 0] - 18.1) < 0.5 and abs(abs(np.degrees(loc.theta[k2])) - 180) < 10
assert 0.001 < loc.marginal_xy()[east].sum() < 0.01

# left: the whole office on a log colour scale, so that the faint mirror candidate shows;
# right: the 2 m around the start on a linear scale. The truth is a ring, so it hides no cell.
m = loc.marginal_xy()
fig, axes = plt.subplots(1, 2, figsize=(11, 3.9), width_ratios=(2.2, 1), layout="constrained")
draw_map(grid, axes[0], alpha=0.35)
img = axes[0].imshow(np.ma.masked_where(m < 1e-5, np.log10(np.maximum(m, 1e-5))), origin="lower", extent=grid.extent,
                     cmap="viridis", vmin=-5, vmax=0)
fig.colorbar(img, ax=axes[0], label="log10 of the belief per 20 cm cell", shrink=0.85)
axes[0].annotate(f"mirror candidate: {m[east].sum():.1%} of the belief", (cell_xy[i2, j2, 0], cell_xy[i2, j2, 1]),
                 xytext=(12.0, 8.0), fontsize=8, arrowprops=dict(arrowstyle="->", color="k"))
axes[0].set_title("after the first scan: belief over (x, y), summed over headings", fontsize=9)
draw_map(grid, axes[1], alpha=0.35)
img = axes[1].imshow(np.ma.masked_less(m, 1e-4), origin="lower", extent=grid.extent, cmap="viridis", vmin=0)
fig.colorbar(img, ax=axes[1], label="belief per cell", shrink=0.85)
axes[1].set_xlim(truth[0, 0] - 1, truth[0, 0] + 1)
axes[1].set_ylim(truth[0, 1] - 1, truth[0, 1] + 1)
axes[1].set_title("zoom on the start (linear scale)", fontsize=9)
for ax in axes:
    ax.plot(*truth[0, :2], "o", ms=12, mfc="none", mec="tab:red", mew=2, label="truth")
    ax.set_xlabel("x [m]")
axes[0].legend(loc="lower right", fontsize=8)
plt.show()

# %% [markdown]
# Twelve ranges already point at the right place in this office: the walls,
# doors and furniture around the start are distinctive, and 99 % of the belief
# lies within half a metre of the truth. Not all of the rest is scattered
# noise: a faint **second candidate** sits at the other end of the corridor,
# near x = 18 m, facing back (180°). The corridor's two ends look almost alike
# from inside, so the mirror pose explains the twelve ranges nearly as well,
# and it holds about half a percent of the belief (the spot that the log
# colour scale on the left brings out). The next steps, as the robot drives towards the middle,
# tell the two apart. (That the first scan is so decisive is luck of the place: in the
# middle of a long, plain corridor one scan would leave many candidates, and
# the robot would have to drive before the belief settles, as in the hallway of
# chapter 1.)

# %% [markdown]
# ## The motion update: a rotation-aware convolution
#
# Two odometry readings give the motion as a turn `rot1`, a straight drive
# `trans` and a turn `rot2` (PR section 5.4). A robot whose heading is in bin $k$
# drives `trans` metres along $\theta_k + \text{rot1}$: every heading slice of
# the belief moves **in its own direction**. So the prediction shifts each of the
# $K$ slices by its own displacement (split into whole cells, moved exactly, and a
# fraction, spread by a small Gaussian kernel), and then shifts the heading axis
# by `rot1 + rot2`, with a blur of its own. The widths of the blurs come from
# the odometry noise parameters $\alpha_1..\alpha_4$ (PR table 5.6), plus a
# floor of half a cell and half a bin for the discretisation (PR section 8.2.2
# advises inflating the noise of coarse grids).
#
# To see it, start from a belief that is sure of the position but not of the
# heading (four headings equally likely), and drive 1.5 m forward:

# %%
demo = GridLocalizer(grid, K, ANGLES, MAX_RANGE, expected=E, alphas=ALPHAS)
b = np.zeros(demo.belief.shape)
i, j = grid.world_to_cell([[10.0, 5.5]])[0]
for k in [0, 9, 18, 27]:                       # headings -180°, -90°, 0°, 90°
    b[k, i, j] = 0.25
demo.belief = b
demo.predict([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]])
fig, ax = plt.subplots(figsize=(9, 5.2))
draw_map(grid, ax, alpha=0.5)
m = demo.marginal_xy()
ax.imshow(np.ma.masked_less(m / m.max(), 1e-3), origin="lower", extent=grid.extent, cmap="viridis")
ax.plot(10.0, 5.5, "r+", ms=14, mew=2)
ax.set_xlim(6, 14)
ax.set_ylim(2.5, 8.5)
ax.set_title("four headings, one odometry reading of 1.5 m forward: four blobs")
plt.show()
moved = [np.average(grid.cell_to_world(np.argwhere(np.ones(grid.shape, bool))), axis=0,
                    weights=demo.belief[k].ravel()) for k in [0, 9, 18, 27]]
for k, c in zip([0, 9, 18, 27], moved):
    print(f"heading {np.degrees(demo.theta[k]):5.0f}°: belief centred at ({c[0]:.2f}, {c[1]:.2f})")

# %% [markdown]
# Each heading's blob moved 1.5 m in its own direction and was blurred by the
# motion noise; parts that landed on wall cells were removed (a robot cannot be
# inside a wall). Notice that the blobs for -90° and 90° passed *through* the
# corridor walls into the rooms: the grid motion model only asks whether the
# end cell is free, not whether the way there is (PR's grid localization does
# the same). It is an approximation that the next scan repairs, since a robot
# "in the room" would see the room.

# %% [markdown]
# ## Global localization along the path
#
# Now the full filter: uniform start, then at every stop a prediction with the
# odometry and an update with the scan (PR table 8.1).

# %%
loc = GridLocalizer(grid, K, ANGLES, MAX_RANGE, expected=E, sigma_hit=0.2, alphas=ALPHAS)
pos_err, head_err, estimates = [], [], []
for t in range(len(odom)):
    if t > 0:
        loc.predict((odom[t - 1], odom[t]))
    loc.update(scans[t])
    e = loc.estimate()
    estimates.append(e)
    pos_err.append(np.hypot(*(e[:2] - truth[t, :2])))
    head_err.append(abs(geometry.angle_diff(e[2], truth[t, 2])))
    if t == 3:
        east_mass_3 = loc.marginal_xy()[east].sum()
estimates = np.array(estimates)
print("position error [m] per step:", np.round(pos_err, 2))
print("belief beyond x = 15 m after step 3 (the second candidate) below 1e-6:", bool(east_mass_3 < 1e-6))
print(f"final heading error: {np.degrees(head_err[-1]):.1f}° (bin width {360 / K:.0f}°)")
odo_err = np.hypot(*(odom[:, :2] - truth[:, :2]).T)
print(f"odometry alone is off by {odo_err[-1]:.2f} m at the end; the filter by {pos_err[-1]:.2f} m")
assert east_mass_3 < 1e-6                                  # the mirror candidate is gone
assert max(pos_err) < 1.5 * grid.resolution and min(pos_err) < 0.3 * grid.resolution
assert sum(e > 0.71 * grid.resolution for e in pos_err) >= 1  # some steps: a neighbouring cell won

fig, axes = plt.subplots(1, 2, figsize=(12, 4), gridspec_kw={"width_ratios": [1.6, 1]})
draw_map(grid, axes[0], alpha=0.6)
axes[0].plot(truth[:, 0], truth[:, 1], color="tab:blue", label="truth")
axes[0].plot(odom[:, 0], odom[:, 1], "--", color="tab:gray", label="odometry")
axes[0].plot(estimates[:, 0], estimates[:, 1], "o", ms=3, color="tab:red", label="grid estimate")
axes[0].legend(loc="upper right", fontsize=8)
axes[0].set_title("estimates along the path")
axes[1].plot(pos_err, label="grid filter")
axes[1].plot(odo_err, "--", label="odometry")
axes[1].axhline(grid.resolution, color="0.7", lw=1)
axes[1].text(0.3, grid.resolution * 1.1, "cell size", fontsize=8)
axes[1].set_xlabel("step")
axes[1].set_ylabel("position error [m]")
axes[1].legend()
fig.tight_layout()
plt.show()

# %% [markdown]
# The filter's error stays at the scale of a cell from the first scan on, while
# odometry drifts. The estimate is the centre of the most likely bin, and the
# truth can be anywhere inside its cell: even when the right cell wins, the error
# is anything from zero (the truth near the centre, as at the steps with 0.04
# and 0.06 m) to half the cell's diagonal (0.14 m for 20 cm cells), about 0.08 m
# on average for a truth placed at random in the cell. When a neighbouring cell
# wins, as at the steps with 0.25 and 0.27 m, the error exceeds that. So the
# *resolution* of the estimate is a cell and a bin, not its error at every step.

# %% [markdown]
# ## Resolution, accuracy and cost
#
# How fine must the grid be? We run the same data through grids of 50, 25, 20 and
# 10 cm with 12, 36, 36 and 72 headings. The sensor model's width is at least
# the cell size. For each we report the number of bins, the mean errors over the
# path after the first three steps, and the work per step: the prediction
# touches every bin a few times per blur tap, the update once per beam. We count
# the update's bin-beam evaluations, which do not depend on the machine; the
# times follow in the cell after, and vary from run to run.

# %% tags=["nbval-ignore-output", "remove-output"]
# four grids, the finest with 1.7 million bins: a progress bar while they run (not stored)
import time  # noqa: E402

from localize.metrics import progress  # noqa: E402

configs = [(10, 12), (5, 36), (4, 36), (2, 72)]
rows, timings = [], []
for factor, n_head in progress(configs, desc="grids"):
    g = coarsen(truth_map, factor)
    t0 = time.perf_counter()
    lc = GridLocalizer(g, n_head, ANGLES, MAX_RANGE, sigma_hit=max(0.2, g.resolution), alphas=ALPHAS)
    t1 = time.perf_counter()
    pe, he = [], []
    for t in range(len(odom)):
        if t > 0:
            lc.predict((odom[t - 1], odom[t]))
        lc.update(scans[t])
        e = lc.estimate()
        pe.append(np.hypot(*(e[:2] - truth[t, :2])))
        he.append(abs(geometry.angle_diff(e[2], truth[t, 2])))
    t2 = time.perf_counter()
    rows.append((g.resolution, n_head, lc.n_cells, np.mean(pe[3:]), np.degrees(np.mean(he[3:])),
                 lc.n_cells * len(ANGLES)))
    timings.append((t1 - t0, (t2 - t1) / len(odom)))

# %%
ratio_bins = rows[-1][2] / rows[0][2]
ratio_err = rows[0][3] / rows[-1][3]
print(f"10 cm against 50 cm: {ratio_bins:.0f} times the bins, position error smaller by {ratio_err:.1f}")
assert ratio_bins == 150 and 3.0 < ratio_err < 4.2                 # the text below says 150 and 3.6
assert all(a[3] > b[3] for a, b in zip(rows, rows[1:]))             # the error falls as the cells shrink
assert 200 * 200 * 72 == 2_880_000
print("| cell [m] | headings | bins | mean position error [m] | mean heading error [°] | bin-beam evaluations per update |")
print("|---|---|---|---|---|---|")
for r in rows:
    print(f"| {r[0]:.2f} | {r[1]} | {r[2]:,} | {r[3]:.3f} | {r[4]:.1f} | {r[5]:,} |")

# %% tags=["nbval-ignore-output", "remove-output"]
# wall-clock times on the machine that ran this notebook (they vary; not checked)
for (factor, n_head), (build, per_step) in zip(configs, timings):
    print(f"cell {0.05 * factor:.2f} m, {n_head} headings: table {build:.2f} s, predict + update {per_step * 1e3:.0f} ms")

# %% [markdown]
# Halving the cell size quadruples the number of cells; doubling the headings
# doubles it again. From 50 cm and 12 headings to 10 cm and 72 headings the
# cells are 5 times finer each way and the headings 6 times finer, so the 10 cm
# grid has $25 \times 6 = 150$ times the bins of the 50 cm one. The error
# falls roughly in proportion to the cell size (the estimate is a bin centre),
# while the work grows with the cube of the resolution: from 50 cm to 10 cm the
# position error drops by a factor of 3.6 and the work grows by 150. (A 200 x 200 x 72 grid, 2.9
# million bins, takes a few hundred milliseconds per update on a laptop;
# `benchmarks/bench_histogram.py` measures it.) This is the trade-off that makes
# particle filters attractive: they put their samples only where the belief is.

# %% [markdown]
# ## Try it: cell size and heading bins
#
# The widget reruns the filter on this chapter's data with the cell size and
# number of heading bins you pick (the heading bins must divide the 30° beam
# spacing, hence 12, 24, 36 or 72). Watch two things: how the error along the
# path follows the cell size — and where a coarse grid mistakes a
# neighbouring cell for the right one — and how few heading bins make the
# estimate's heading, and with it the motion update, coarse. The title gives
# the number of bins, the work of every update. (In the HTML book the figure
# below shows the default, this chapter's 20 cm and 36 headings.)

# %% tags=["nbval-ignore-output"]
from localize.widgets.gridloc import grid_resolution_figure, grid_resolution_widget  # noqa: E402

grid_resolution_widget()

# %%
fig = grid_resolution_figure(0.2, 36)
fig

# %% [markdown]
# ## Summary
#
# * The pose grid holds one probability per (heading bin, cell): $K \cdot H \cdot W$ numbers.
# * Prediction: shift every heading slice along its own direction, blur by the
#   odometry noise, shift and blur the headings: a rotation-aware convolution.
# * Correction: a table of expected ranges along each absolute direction, made
#   once per map, turns the beam model into table lookups.
# * Work grows with the cube of the resolution (cells in x, y and θ); accuracy
#   does not keep up.

# %% [markdown]
# ## Exercises
#
# 1. **By hand.** A grid has 16 heading bins. A beam points 45° to the left of
#    the robot. For a robot in bin $k = 3$, which row of the expected-range table
#    does the beam use? Which bin width would make a beam at 45° fall *between*
#    two rows?
# 2. **Implementation.** Write `marginal_heading_plot(loc)`: a polar plot of
#    `loc.marginal_theta()`, and use it to show the heading belief after the first
#    scan and after the turn at step 16.
# 3. **Experiment.** Kidnap the robot: after step 10, continue the filter with
#    the scans of a different place (shift every later true pose by 6.5 m in x, recasting
#    the scans). How many steps does the grid filter need to find the robot
#    again? What does the `min_sigma_xy` floor have to do with it?

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 1
K16 = 16
m_b = round(np.radians(45) / (2 * np.pi / K16))
print("beam offset in bins:", m_b, "-> table row", (3 + m_b) % K16)
print("bin width 30° (12 bins): 45° / 30° =", 45 / 30, "-> not a whole number of bins")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# With 16 bins of 22.5°, 45° is exactly two bins, so the beam uses row
# $(3 + 2) \bmod 16 = 5$. With bins of 30°, 20° or 10° (12, 18 or 36 bins), 45°
# is not a whole number of bins and the beam falls between rows;
# `GridLocalizer` then snaps it to the nearest bin, an error of up to half a bin.
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 2
def marginal_heading_plot(loc, ax):
    th = loc.theta
    ax.bar(th, loc.marginal_theta(), width=2 * np.pi / loc.K, alpha=0.7)
    return ax


lc = GridLocalizer(grid, K, ANGLES, MAX_RANGE, expected=E, sigma_hit=0.2, alphas=ALPHAS)
fig, axes = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(8, 3.6))
for t in range(17):
    if t > 0:
        lc.predict((odom[t - 1], odom[t]))
    lc.update(scans[t])
    if t in (0, 16):
        marginal_heading_plot(lc, axes[0 if t == 0 else 1]).set_title(f"heading belief, step {t}")
fig.tight_layout()
plt.show()

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 3: kidnapping after step 10
kid_truth = truth.copy()
kid_truth[11:, 0] += 6.5
ok = truth_map.is_free(kid_truth)
print("kidnapped poses all free:", bool(ok.all()))
kid_scans = scans.copy()
kid_scans[11:] = np.clip(raycast.cast(truth_map, kid_truth[11:], ANGLES, MAX_RANGE, method="march")
                         + rng.normal(0, 0.05, (len(odom) - 11, len(ANGLES))), 0, MAX_RANGE)
for floor in [0.5, 2.0]:
    lc = GridLocalizer(grid, K, ANGLES, MAX_RANGE, expected=E, sigma_hit=0.2, alphas=ALPHAS, min_sigma_xy=floor)
    errs = []
    for t in range(len(odom)):
        if t > 0:
            lc.predict((odom[t - 1], odom[t]))
        lc.update(kid_scans[t])
        errs.append(np.hypot(*(lc.estimate()[:2] - kid_truth[t, :2])))
    print(f"min_sigma_xy = {floor} cells: errors after the kidnap {np.round(errs[11:], 1)}")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# (All kidnapped poses are in free space, as printed.) The grid filter never
# assigns exactly zero to a free bin, so it can recover — but only as fast as
# the evidence overturns the old peak: eight steps with the default floor. A
# wider motion blur (larger `min_sigma_xy`) keeps more belief spread over the map
# and recovers in four, at the price of a vaguer estimate while tracking;
# chapter 8 meets the same trade-off in MCL as random particle injection.
#
# </details>

# %% [markdown]
# 4. **Implementation, self-checked.** Write the correction step yourself:
#    `grid_update(belief, expected, beam_bins, ranges, beam_pdf)` multiplies a
#    `(K, H, W)` belief by the likelihood of a scan and normalises. `expected[k, i, j]`
#    is the range from cell $(i, j)$ along the *absolute* heading bin $k$; beam $b$,
#    `beam_bins[b]` bins to the left of the robot's heading, therefore looks along
#    bin `(k + beam_bins[b]) % K` for a robot in bin $k$ (what `GridLocalizer` does
#    with its `np.roll` of the table). Test it with `check.grid_update(grid_update)`,
#    which tries the classic mistakes: the beam offset forgotten or applied the
#    wrong way, and a product of 360 beam likelihoods that underflows.

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
from localize import check  # noqa: E402


def grid_update(belief, expected, beam_bins, ranges, beam_pdf):
    """Posterior of grid localization after one scan, computed in log space."""
    k = np.arange(belief.shape[0])
    log_lik = np.zeros(belief.shape)
    for b, z in zip(beam_bins, ranges):
        log_lik += np.log(beam_pdf(z, expected[(k + b) % len(k)]))
    posterior = belief * np.exp(log_lik - log_lik.max())
    return posterior / posterior.sum()


print(check.grid_update(grid_update))

# %% [markdown]
# ## References
#
# * S. Thrun, W. Burgard, D. Fox. *Probabilistic Robotics*. MIT Press, 2005:
#   table 5.6 (odometry motion model), table 6.1 (beam model), section 8.2 and
#   table 8.1 (grid localization).
# * W. Burgard, D. Fox, D. Hennig, T. Schmidt. Estimating the absolute position of
#   a mobile robot using position probability grids. *AAAI* 1996.
# * D. Fox, W. Burgard, S. Thrun. Markov localization for mobile robots in
#   dynamic environments. *Journal of Artificial Intelligence Research* 11, 1999.
# * W. Burgard, A. Derr, D. Fox, A. B. Cremers. Integrating global position
#   estimation and position tracking for mobile robots: the dynamic Markov
#   localization approach. *IROS* 1998 (updating only the cells that matter).
