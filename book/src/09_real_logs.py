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
# # Real logs: reading robot data, building maps, localizing from the command line
#
# Everything so far ran on simulated robots whose every convention we chose
# ourselves. Real data arrives in files written by other people, for other
# programs, years ago. Students of the CMU 16-831 course receive a map of Wean
# Hall and a few robot logs in a home-grown text format; engineers meet CARMEN
# logs from the Radish archive and maps saved by ROS `map_server`. Each format is
# simple, and each hides a trap that silently turns a working localizer into one
# that never converges: a map stored as the probability of *free* space, a map
# whose text lines are columns, ranges in centimetres, a laser mounted 25 cm ahead
# of the robot's centre, readings of 81.83 m that mean "nothing there".
#
# This chapter walks through those traps on a log that our simulator writes in
# the CMU format, so that it runs anywhere. Then it builds a map from a log with
# known poses (occupancy grid mapping), and shows the command-line localizer
# that runs the whole pipeline on the real CMU or Intel data with one command.

# %%
import json
import re
import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import localize
from localize import cli, io, mapping, maps, pipeline, settings, sim
from localize.geometry import compose
from localize.plot import draw_map, draw_robot, draw_scan
from localize.sensors import LikelihoodField

rng = np.random.default_rng(909)
folder = Path(tempfile.mkdtemp())


def hide(text):
    """Print file paths without the random temporary folder."""
    return str(text).replace(str(folder) + "/", "")


# %% [markdown]
# ## A robot log in the CMU 16-831 format
#
# We drive a simulated robot through the office world for 60 s. Like the
# course's robot, its laser sits 25 cm ahead of its centre and sweeps 180 beams
# from its right (-90°) counter-clockwise to +89°. Then we save the map and the
# log exactly as the course distributes them.

# %%
world = maps.office(0.1)
run = sim.range_run(world, rng, n_steps=120, dt=0.5, speed=0.4, sensor_offset=(0.25, 0.0, 0.0),
                    max_range=12.0, n_clutter=4)
map_file = io.write_cmu_map(folder / "office.dat", world)
log_file = sim.write_cmu_log(folder / "office.log", run)
print(run)
print("map file, first lines:")
for line in map_file.read_text().splitlines()[:8]:
    print("   ", line[:70] + (" ..." if len(line) > 70 else ""))
print("log file, first two records (cut):")
for line in log_file.read_text().splitlines()[:2]:
    print("   ", line[:90], "...")

# %% [markdown]
# The map header says the map is 2000 cm by 1200 cm in 10 cm cells; the line
# `global_map[0]: 120 200` gives the two sizes (values per line, then lines,
# following the original BeeSoft loader). An odometry record `O x y theta ts`
# holds centimetres, radians and seconds; a laser record `L` holds the robot's
# odometry pose, the laser's pose in the same frame, 180 ranges in centimetres
# and a time stamp.
#
# `localize.io` reads both into the book's conventions — metres, radians, an
# `OccupancyGrid` of occupancy probabilities with rows growing with $y$:

# %%
grid = io.read_cmu_map(map_file)
log = io.read_cmu_log(log_file)
print(grid)
print(log)
print("laser offset measured from the file:", log.sensor_offset.round(3) + 0.0, "(x forward, y left, theta)")
print("first odometry pose [m, m, rad]:", log.odometry[0].round(3))

# %% [markdown]
# ## Trap 1: the map stores P(free), not P(occupied)
#
# In `wean.dat` a wall cell holds a value near **0** and the floor a value near
# **1**: the number is the probability that the cell is *free*. Unknown cells
# hold -1. Some copies of the homework instructions say the opposite; the file
# itself is unambiguous once you plot it — a map read the wrong way round shows
# white walls on a black floor, and every range model then rewards particles
# for standing inside walls. The loader converts to occupancy `1 - value` and
# turns -1 into `NaN`.

# %%
text = map_file.read_text().splitlines()
raw = np.array([[float(v) for v in line.split()] for line in text[7:]])  # as stored: P(free)
fig, axes = plt.subplots(1, 2, figsize=(10, 3.4))
wrong = localize.OccupancyGrid(np.where(raw < 0, np.nan, raw).T, 0.1)  # P(free) taken for P(occupied)
draw_map(wrong, ax=axes[0])
axes[0].set_title("wrong: P(free) read as P(occupied)")
draw_map(grid, ax=axes[1])
axes[1].set_title("right: io.read_cmu_map (occupancy = 1 - P(free))")
plt.tight_layout()
plt.show()
print("fraction of the map that is obstacle, wrong way round:", round(float(wrong.occupied.mean()), 3),
      " right:", round(float(grid.occupied.mean()), 3))

# %% [markdown]
# ## Trap 2: text lines are columns (handedness)
#
# The file holds one text line per **x** cell; the values on a line run over
# **y**. A natural `np.loadtxt` gives an array indexed `[x, y]`, and showing it
# as an image puts x downwards and y to the right: the picture is transposed,
# which for a map is a *reflection* — left and right turn into up and down, and a
# counter-clockwise robot becomes a clockwise one. Transposing to `[y, x]` and
# drawing with the origin at the lower left (`origin="lower"`, our convention)
# gives back the world with x to the right and y up, so that headings turn
# counter-clockwise as they should.

# %%
fig, axes = plt.subplots(1, 2, figsize=(10, 3.4), gridspec_kw={"width_ratios": [1, 1.7]})
axes[0].imshow(1 - np.where(raw < 0, np.nan, raw), cmap="gray_r")
axes[0].set_title("file as an image: rows = x (mirrored)")
axes[0].set_xlabel("column = y cell")
axes[0].set_ylabel("row = x cell")
draw_map(grid, ax=axes[1])
draw_robot(run.poses[0], ax=axes[1])
axes[1].set_title("read_cmu_map: x right, y up")
plt.tight_layout()
plt.show()
print("array shapes: file [x, y] =", raw.shape, "  grid.data [y, x] =", grid.data.shape)

# %% [markdown]
# ## Trap 3: units and beam order
#
# Ranges are in centimetres: forget the factor 100 and every wall is 100 times
# too far. The beams start at the robot's **right** and sweep counter-clockwise;
# reverse them and each scan is mirrored about the robot's heading. Both mistakes
# are easy to see by drawing one scan at the robot's true pose over the map: the
# end points must fall on the walls.

# %%
k = 60
laser = compose(run.poses[k], log.sensor_offset)
fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
for ax, angles, title in [(axes[0], log.angles[::-1], "beams reversed (left to right)"),
                          (axes[1], log.angles, "beams from the right, counter-clockwise")]:
    draw_map(grid, ax=ax)
    draw_scan(laser, angles, log.ranges[k], ax=ax, max_range=log.max_range, rays=False)
    draw_robot(run.poses[k], ax=ax)
    ax.set_title(title)
plt.tight_layout()
plt.show()

# %% [markdown]
# A number says the same as the picture. The likelihood field (chapter 5) scores
# a scan by how close its end points fall to walls; we compare the score of the
# true pose under each reading of the file:

# %%
lf = LikelihoodField(grid, 12.0, sigma_hit=0.1, sensor_offset=log.sensor_offset)
lf_no_offset = LikelihoodField(grid, 12.0, sigma_hit=0.1)
z = np.minimum(log.ranges[k], 12.0)
cases = {
    "correct": lf.log_likelihood(run.poses[k:k + 1], z, log.angles),
    "beams reversed": lf.log_likelihood(run.poses[k:k + 1], z[::-1], log.angles),
    "ranges left in cm": lf.log_likelihood(run.poses[k:k + 1], np.minimum(z * 100, 12.0), log.angles),
    "laser offset ignored": lf_no_offset.log_likelihood(run.poses[k:k + 1], z, log.angles),
}
for name, ll in cases.items():
    print(f"{name:>22}: log-likelihood of the true pose {float(ll[0]):8.1f}")

# %% [markdown]
# ## Trap 4: where the laser is
#
# The log's `L` records hold both the robot's pose and the laser's; on the course's
# robot the laser is 25 cm ahead of the centre. The loader measures the offset
# from the file (the median of the laser poses seen from the robot poses) and the
# sensor models apply it (`sensor_offset`): the filter estimates the pose of the
# robot's *centre*, which is what the odometry describes, and each scan is taken
# from `pose ⊕ offset`. Ignoring 25 cm shifts every end point by 25 cm along the
# heading — an error of the same size as a real map's own inaccuracy, and one
# that does not average out, since it rotates with the robot (last line above).
#
# ## Trap 5: "no return" is not a wall
#
# A laser that sees nothing reports its maximum: 8183 cm on the course's SICK
# scanner, 81.83 m or 81.91 m in the CARMEN logs, 50 m where a logger capped it.
# Such a reading says "the beam went further than I can measure" — through a
# door, out of a window, onto a black or shiny surface. Treated as a real range
# it puts an obstacle 80 m away. The readers flag every reading at or above the
# file's maximum (`log.no_return`); the likelihood field skips them and the beam
# model gives them their own mixture component (PR table 6.1).

# %%
print("maximum range of the log:", log.max_range, "m")
print("share of no-return readings:", round(float(log.no_return.mean()), 3))
print("readings stored as 8183 cm:", int((log.ranges >= 81.8).sum()))

# %% [markdown]
# ## Trap 6: unknown cells, and maps that are wrong
#
# Cells the map maker never observed are unknown (`NaN`). A laser cannot see
# through them — or rather, we cannot promise that it can — so ray casting and
# the distance field treat them as obstacles, while a global localizer draws its
# initial particles only from *known free* cells.
#
# Real maps are also simply wrong. In the Wean Hall map the walls are drawn
# roughly 10-15 cm thicker than the laser sees them, and some furniture has moved
# since the map was made. A sensor model whose `sigma_hit` is a few centimetres
# — the laser's own noise — punishes the *true* pose for the map's mistakes. The
# command-line localizer therefore uses `sigma_hit = 0.2 m`, looks at 30 beams
# per scan, and multiplies each scan's log-likelihood by a factor 0.3
# (`temper`): neighbouring beams are far from independent, and an over-confident
# filter locks onto the first place that looks right (PR section 6.3.4).
#
# ## Bad files say where they are bad
#
# A truncated line, a field that is not a number, a `NaN`, a map header that
# disagrees with its data: the readers stop with `file:line: what was expected`
# rather than return something half-read. Record types that a reader knows and
# does not need (a CARMEN log's `RAWLASER1` or `TRUEPOS` lines) are skipped and
# counted in one warning.

# %%
lines = log_file.read_text().splitlines()
bad = folder / "truncated.log"
bad.write_text("\n".join(lines[:5] + [lines[5][:200]] + lines[6:]) + "\n")
try:
    io.read_log(bad)
except io.FormatError as e:
    print("FormatError:", hide(e))

carmen_file = folder / "tiny_carmen.log"
carmen_file.write_text(
    "PARAM robot_front_laser_max 81.83 nohost 0\n"
    "FLASER 3 1.0 2.0 81.83 0 0 0 0 0 0 0.1 host 0.1\n"
    "RAWLASER1 0 -1.57 3.14 1.57 81.83 0.01 0 3 1 2 3 0 0.1 host 0.1\n"
    "TRUEPOS 0 0 0 0 0 0 0.1 host 0.1\n"
    "FLASER 3 1.1 2.0 81.83 0.1 0 0 0.1 0 0 0.2 host 0.2\n")
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    tiny = io.read_log(carmen_file)
print("ParseWarning:", hide(caught[0].message))
print(tiny)

# %% [markdown]
# ## ROS maps, and walls painted grey
#
# A ROS `map_server` map is a YAML file (resolution, origin, thresholds) next to
# a PGM or PNG picture whose first row is the *top* of the map. A pixel's
# occupancy is `p = (255 - value) / 255`; in the default *trinary* mode cells
# above `occupied_thresh` (0.65) are walls, cells below `free_thresh` (0.196)
# free, and everything between unknown. Maps edited by hand often have walls
# painted mid-grey — the Willow Garage office map (in `../shared/data/willow/`)
# has walls of grey 100-200, so by its own thresholds most of its walls are
# *unknown*. A laser is stopped by unknown cells anyway, but plots and anything
# that counts walls are off; `io.read_ros_map` exposes the thresholds and offers
# `not_free="occupied"`.

# %%
img = np.full((30, 50), 254, dtype=np.uint8)
img[:3], img[-3:], img[:, :3], img[:, -3:] = 150, 150, 150, 150  # grey walls
img[12:18, 20:30] = 0  # a black pillar
io.write_pgm(folder / "grey.pgm", img)
(folder / "grey.yaml").write_text("image: grey.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\n"
                                  "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
strict = io.read_map(folder / "grey.yaml")
fixed = io.read_map(folder / "grey.yaml", not_free="occupied")
fig, axes = plt.subplots(1, 2, figsize=(9, 2.8))
draw_map(strict, ax=axes[0])
axes[0].set_title(f"trinary: {int(strict.occupied.sum())} walls, {int(strict.unknown.sum())} unknown")
draw_map(fixed, ax=axes[1])
axes[1].set_title(f"not_free='occupied': {int(fixed.occupied.sum())} walls")
plt.tight_layout()
plt.show()

# %% [markdown]
# ## Mapping with known poses
#
# The CARMEN logs of `../shared/data/carmen/` come with *corrected* poses (a SLAM
# estimate) but no map. With the poses known, building the map is the easy half
# of SLAM: **occupancy grid mapping** (PR chapter 9; Moravec and Elfes 1985).
# Every cell keeps the log-odds $l = \log\frac{p}{1-p}$ of being occupied, and each
# scan adds the log-odds of an *inverse sensor model* — "given this beam, how
# likely is this cell occupied?" — minus the prior's (PR table 9.1):
#
# $$ l_{t,i} = l_{t-1,i} + \log\frac{p(m_i \mid z_t, x_t)}{1 - p(m_i \mid z_t, x_t)} - l_0 .$$
#
# Adding log-odds multiplies odds: it is Bayes' rule for a binary cell, and it
# is cheap and symmetric. PR table 9.2 writes the inverse model per cell: find the
# beam nearest in bearing; if the cell lies within $\alpha/2$ of the measured range
# it is occupied, if it lies before it, free, otherwise nothing is learned.

# %%
beams = np.radians([-10.0, 0.0, 10.0])
reading = np.array([2.0, 3.0, 2.0])
for x in (1.0, 2.99, 3.5):
    l_cell = mapping.inverse_range_sensor_model((x, 0.0), (0.0, 0.0, 0.0), reading, beams, max_range=10.0,
                                                alpha=0.2, beta=np.radians(2.0), l_occ=0.85, l_free=-0.41)
    print(f"cell at x = {x:4.2f} m in front of a reading of 3 m: log-odds {l_cell:+.2f}")

# %% [markdown]
# `mapping.OccupancyMapper` applies the same model along each beam instead of per
# cell, which is what practical mappers do: cells the beam crosses are free, the
# cell where it ends is occupied, a "no return" teaches nothing. Probabilities are
# clamped to [0.12, 0.97] so that a map can still change when a door opens.
# We build the office from the simulated scans and the robot's *true* poses:

# %%
built = mapping.map_from_log(io.LaserLog(times=log.times, odometry=log.odometry, ranges=log.ranges,
                                         angles=log.angles, max_range=log.max_range,
                                         sensor_offset=log.sensor_offset, poses=run.poses),
                             resolution=0.1, usable_range=10.0, extent=(0.0, 20.0, 0.0, 12.0))
fig, ax = plt.subplots(figsize=(8, 4.2))
draw_map(built, ax=ax)
ax.plot(run.poses[:, 0], run.poses[:, 1], color="tab:red", lw=1, label="robot path")
ax.legend(loc="upper right")
ax.set_title("a map built from 120 scans at known poses")
plt.show()
print("built map:", built)

# %% [markdown]
# The map shows what the robot saw in its minute of driving: the room it
# crossed, sharp walls where many beams ended, the corridor wall through the
# door, and faint grey streaks beyond the walls where the simulated laser's
# *random* readings (the `z_rand` part of the beam model) pretended to see far
# through them. Each streak cell got one or two "free" votes against none for
# "occupied"; a longer drive that looks at the same places from many poses
# outvotes such noise, which is why the maps of the real logs below are clean.
# Cells never seen stay unknown (blue-grey).
#
# On the real logs the same two lines build the maps of the Intel lab (910 scans)
# and of Freiburg building 079 (4,791 scans) in a few seconds each:
#
# ```python
# log = io.read_log("../shared/data/carmen/intel-corrected.log.gz")
# intel = mapping.map_from_log(log, resolution=0.05)
# ```
#
# If the real data sits beside the book (`../shared/data`, or a folder named by
# the environment variable `LOCALIZE_DATA`), the next cell builds the Intel map
# and tracks the robot through all 910 scans with the real odometry increments,
# starting from the first corrected pose. (Its output is not checked by the
# tests, since the data may be absent; `tests/test_real_data.py` checks the
# numbers.)

# %% tags=["nbval-ignore-output"]
import os  # noqa: E402

data = Path(os.environ.get("LOCALIZE_DATA", "../../shared/data"))
intel_file = data / "carmen" / "intel-corrected.log.gz"
if intel_file.exists():
    intel = io.read_log(intel_file)
    intel_map = mapping.map_from_log(intel, resolution=0.05)
    res = pipeline.localize_log(intel_map, intel, n_particles=500, rng=np.random.default_rng(0), init="reference",
                                beams=60, alphas=(0.02, 0.005, 0.01, 0.02), temper=1.0, min_motion=(0.0, 0.0),
                                sensor_params={"sigma_hit": 0.15})
    e = np.hypot(*(res.estimates[:, :2] - intel.poses[:, :2]).T)
    fig, ax = plt.subplots(figsize=(7, 6.5))
    draw_map(intel_map, ax=ax)
    ax.plot(intel.poses[:, 0], intel.poses[:, 1], color="tab:green", lw=1.5, label="corrected poses")
    ax.plot(res.estimates[:, 0], res.estimates[:, 1], ".", color="tab:red", ms=2, label="MCL, 500 particles")
    ax.legend(loc="lower left")
    ax.set_title(f"Intel lab: map from corrected poses; tracking median error {np.median(e):.3f} m")
    plt.show()
else:
    print(f"real data not found at {data}: skipped")

# %% [markdown]
# ## The command-line localizer
#
# `python -m localize run` (installed as `localize`) puts everything together: it
# detects the formats from the files' contents, spreads particles uniformly over
# the map's free space, and filters every scan — odometry motion, likelihood
# field, resampling — writing one estimate per scan to `trajectory.csv`
# (`time,x,y,theta`, the robot centre in the map frame) and the run's numbers to
# `summary.json`. On a terminal it draws a progress bar; `--animate` adds a GIF
# of the particle cloud. `localize run --help` documents every option with an
# example.

# %%
status = cli.main(["run", "--map", str(map_file), "--log", str(log_file), "--particles", "3000",
                   "--seed", "0", "--out", str(folder / "out"), "--quiet"])
summary = json.loads((folder / "out" / "summary.json").read_text())
est = np.loadtxt(folder / "out" / "trajectory.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
err = np.hypot(*(est[:, :2] - run.poses[:, :2]).T)
print("exit status:", status)
print("scans:", summary["scans"], " particles:", summary["particles"])
print("particle cloud converged (spread < 0.5 m) at scan:", summary["convergence_step"])
print("the filter's own account:", cli.headline(summary))
k_loc = summary["state"]["first_localized_scan"]
if k_loc is not None:
    ok = np.mean(err[k_loc:] < 0.5)
    share = "at least 90%" if ok >= 0.9 else f"{ok:.0%}"   # a share of ~100 scans: no finer than that
    print(f"against the simulator's truth, from scan {k_loc} on: {share} of the estimates within 0.5 m")

# %%
fig, ax = plt.subplots(figsize=(8, 4.2))
draw_map(grid, ax=ax)
ax.plot(run.poses[:, 0], run.poses[:, 1], color="tab:green", lw=2, label="true path")
ax.plot(est[:, 0], est[:, 1], ".", color="tab:red", ms=3, label="estimate per scan")
ax.legend(loc="upper right")
ax.set_title("global localization on the simulated CMU-format log")
plt.show()

# %% [markdown]
# ### The same on real data, one command each
#
# With the CMU 16-831 data (the map `wean.dat` and a log `robotdata1.log`):
#
# ```bash
# localize run --map wean.dat --log robotdata1.log --out out/wean --animate
# ```
#
# With a corrected CARMEN log, which carries no map, `--build-map` first builds
# one from the corrected poses (the log's own poses then also score the result:
# `trajectory.csv` gains `ref_x,ref_y,ref_theta,error` columns):
#
# ```bash
# localize run --log ../shared/data/carmen/intel-corrected.log.gz --build-map --out out/intel
# ```
#
# What the test suite measures on the real logs (`tests/test_real_data.py`):
# starting from the first corrected pose, MCL with the real odometry increments
# tracks the Intel robot over all 910 scans with a median position error of
# about 4 cm against the corrected poses (Freiburg 079, first 800 scans: also
# about 4 cm). Global localization from a uniform start, with the command line's
# defaults, on maps that are *right* (built from the log's own corrected poses)
# converges in most seeds within 100 scans on Intel and 200 (every fourth scan)
# on Freiburg 079. Maps that are wrong the way real maps are wrong are harder:
# the benchmark below. The number of particles that global localization
# needs grows with the size and the self-similarity of the building. Real logs also hold surprises no
# noise model explains: at scans 837-846 of Freiburg 079 the odometry reports
# almost a metre forward while the corrected poses move backward — a filter
# that trusts it loses the robot there. Recovery (chapter 8) finds it again;
# better, the scans themselves say which way the robot went (`--odometry-sign`,
# below). A quieter surprise: while the Freiburg robot turns on the spot, its
# odometry point, which lies a few centimetres off the axis the robot turns
# about, creeps a few millimetres *sideways*. The odometry model of chapter 4
# explains every step as "turn towards the destination, drive, turn", so it
# reads such a step as a turn of almost 90 degrees, a drive of 5 mm and a turn
# back, and its noise, which grows with the squared turns, scatters the
# particles by about half a metre at every step of a turn that moved the robot
# by two centimetres. The command line's odometry model
# (`localize.motion.ReversibleOdometry`) counts a step whose translation lies
# within the translation noise of a turn on the spot as a turn on the spot: the
# particles move by the measured step, with the noise of a turn. In 117 of the
# Freiburg log's steps this changes the noise from about 0.46 m to about 3 cm
# (`tests/test_real_data.py`); a robot that turned at a wall for thirty scans
# used to spread a correct cloud over two metres and lose it.
#
# ### Searching, localized, lost: what the filter can know
#
# Every row of `trajectory.csv` carries a `state`, and `summary.json` a `state`
# section (first localized scan, lost intervals, final state); the terminal's
# headline reads "localized from scan K; lost at scans ...", and errors against a
# reference are reported only for the scans the filter called localized. The
# state uses no ground truth, only evidence the filter has
# (`localize.mcl.StateRules`):
#
# * **one hypothesis** — the best cluster holds at least 80% of the weight, with a
#   position spread under 0.5 m and a heading spread under 20 degrees;
# * **the scans fit the map there** — the share of beams whose reading agrees
#   with the range ray-cast in the map from the estimate (within twice
#   `sigma_hit`), averaged over five updates, is at least 60% of what the sensor
#   model expects on a correct pose. The likelihood field never asks whether a
#   beam passed *through* a wall, so a cloud can agree with itself on a wrong
#   room; the ray cast does ask. A beam whose cast ray ends in one of the map's
#   unknown cells cannot be judged; a filter none of whose scans the map could
#   judge yet (since the start, a restart or the moment it got lost) has no
#   evidence that they fit, and does not become localized on it. The fits made
#   before the robot was lost vouch for the place it was lost at, not for the
#   one the cloud gathers on next;
# * **the scan pins the pose** — moved 1 m forwards, backwards, left or right,
#   the estimate must fit the scan clearly worse (by 0.1 nat per beam). In a
#   featureless corridor a cloud can shrink onto one stretch by resampling alone
#   (KLD-sampling makes it small enough for that) while every stretch fits
#   equally well; at the true pose in the four real logs this probe fails in
#   only 1–4% of the scans;
# * **readings the sensor can make** — at least five per scan between
#   `--min-range` and `--max-range`. A laser that reads 0 (or only "no return")
#   everywhere gives no evidence: the run ends "NOT localized", not "converged at
#   scan 89";
# * **particles on the map and likelihoods above zero** — if every particle got
#   zero likelihood or left the map (a corrupt odometry record), the
#   filter says so and starts over. An odometry step longer than the map's
#   diagonal is rejected as a corrupt record (`events` in `summary.json`).
#
# Three confident updates in a row make the state *localized*; three that are
# not make it *lost*.

# %% [markdown]
# ### Defaults for maps that disagree with the scans
#
# Real maps are drawn with walls 0.1–0.15 m too thick, doors open or shut,
# furniture moved and parts left unknown. The command line's defaults
# (`localize.settings.RunSettings`, each explained in `localize run --help`) follow from
# that physics, not from one data set:
#
# * **`--particles auto --kld 0.05 --min-particles 2000`** — a dense initial
#   cloud, shrunk by KLD-sampling once the filter agrees. In a building of
#   500–1000 m² a 0.5 m x 0.5 m x 10° cell of the pose space holds, with 5,000
#   uniform particles, a particle only about once in twenty: the filter then
#   depends on luck to have any particle near the truth. So `auto` puts one
#   particle in each such cell of the map's free space on average
#   (`localize.kld.pose_bins`; between 20,000 and 300,000), about 75,000 for
#   a floor of 520 m² — a default that grows with the building instead of
#   one number fitted to one. The big cloud costs only the first few scans.
# * **`--sigma-hit 0.2`** — the map's error (0.1–0.15 m), not the laser's (a
#   few cm), sets the width of the hit term; **`--temper 0.3`** — 30 beams are
#   not 30 independent measurements (neighbouring beams see the same wall).
# * **`--z-short 0.2`** — a beam stopped short by something the map does not
#   show (a person, a chair, a door shut since the map was made) ends in the
#   map's free space, far from any wall, and the likelihood field alone scores
#   it as a miss, just as it scores a beam of a wrong pose. Probabilistic
#   Robotics' beam model has a term for such readings, an exponential density
#   $z_\text{short}\,\lambda e^{-\lambda z}$ that is largest for short
#   readings. Here it is a floor: no returned beam scores below
#   $\log(z_\text{rand}/z_\text{max} + z_\text{short}\,\lambda e^{-\lambda z})$
#   ($\lambda$ = 0.5 per metre). A beam that fits a wall scores as before, a
#   short one that fits nothing costs the true pose less, and a long one that
#   fits nothing (the typical beam of a wrong pose, which passes where the map
#   has a wall) is nearly as bad as before. AMCL's likelihood field has no such term;
#   `--z-short 0` scores the end points as PR table 6.3 does.
# * **unknown cells are not obstacles for the likelihood field** — an end point
#   in an unknown cell (beyond the outer walls of a map built from scans, or in
#   a region the map leaves unknown) gets one neutral score, the same for every
#   pose: the map says nothing there. Counted as obstacles, unknown cells would
#   give a perfect score to every beam that ends beyond an outer wall, which
#   rewards wrong poses whose beams "pass through" walls. An end point off the
#   map is a miss, as in ROS AMCL. Particles may stand in unknown cells (the
#   robot drives there), with no penalty: a penalty per update pushes a cloud
#   whose robot drives through a region the map left unknown towards that
#   region's known edge, metres from the robot (the benchmark below measured it).
# * **`--unknown-beams skip`** — once the cloud has agreed on one place, a beam
#   whose end point *at that place* lies in an unknown cell is left out of the
#   update, and a scan with no other beam is not used: the odometry alone
#   carries the cloud. The neutral score is fair while the filter searches
#   (every particle is its own hypothesis), but not to a cloud that agrees: a
#   particle half a metre away that puts such a beam on some known wall, or
#   moves a beam that misses a moved cupboard into the unknown, scores better
#   than the robot's pose. Driving through the region a map leaves unknown,
#   scan after scan of such small wins pulled the cloud more than a metre out
#   of it. AMCL has no such rule; `--unknown-beams score` scores every beam.
# * **`--short-beams 1`** — once the cloud has agreed on one place, a beam that
#   reads more than 1 m *shorter* than the map's wall as ray-cast from that
#   place is left out of the update too: it hit something the map does not
#   show. The short-reading floor makes such a beam cost the true pose little,
#   but it still pays a few particles at a wrong place where its end point
#   happens to lie on a mapped wall. A robot blocked by clutter stands close to
#   it and turns on the spot, most of its scan on the clutter, and a handful of
#   particles 1–2 m away can take all of the weight in two updates (the test
#   `test_run_filter_skip_short_beams_keeps_an_agreed_cloud_that_unmapped_clutter_would_pull_away`
#   builds the simplest case: a panel across a corridor). The margin is twice
#   the 0.5 m spread within which the cloud counts as agreed, more than its own
#   error explains. When more than half of a scan reads short, every beam is
#   scored: a place where most of the scan contradicts the map is more likely
#   wrong than cluttered, and the scan must be free to move the cloud. ROS
#   AMCL's beam skipping (`do_beamskip`, off by default) is a vote of the whole
#   cloud: it leaves out the beams whose end point lies near a mapped wall for
#   at most 30% of the particles, and scores every beam when 90% of them would
#   go. This rule asks the map at the one agreed place instead.
#   `--short-beams 0` scores every beam.
# * **`--expand M RAD`, off by default** — expansion resetting (Ueda et al.
#   2004): when the cloud agrees on a place but the scan just used does not fit
#   the map there, every particle is moved by Gaussian noise of M metres and RAD
#   radians. A tight cloud that the odometry carried away from the robot cannot
#   be pulled back by the scans, since no particle is near the truth any more.
#   Odometry does that: wheels slip, and odometry without a sign (below) drives
#   the cloud forwards while the robot backs up. But a map that disagrees with
#   the scans (the demo's cupboard that is no longer there) also makes scans
#   fit badly at the right place, and there the spreading throws a correct
#   cloud away: with it on, the demo loses its robot again and again. So it is
#   an option (`--expand 0.2 0.1`) for a robot whose odometry you know slips,
#   not a default.
# * **`--odometry-sign auto`** — the Freiburg 079 robot's odometry never
#   reports driving backwards: its speed has no sign, and in about a hundred
#   of its steps the robot backs up while the odometry says it drives
#   forwards, carrying every particle twice the step's length away from the
#   robot. Two consecutive scans settle which way it went, without the map:
#   the end points of the second scan, placed with the odometry's step, should
#   fall on those of the first. `localize.scanmatch.check_odometry_sign`
#   scores both directions (the mean squared distance from each end point to
#   the nearest end point of the other scan, capped at 0.3 m: the first step of
#   ICP) and drives a step backwards where the reverse scores less than half.
#   Only the sign is changed, never the length or the turn. In a corridor the
#   two directions score alike and nothing changes. `auto` checks only
#   odometry that never reports reversing (odometry with a sign is trusted);
#   `summary.json` lists the steps it reversed. On the whole Freiburg log it
#   reverses 77 of the 3,631 steps it checks, and in every one of them the
#   corrected poses move backwards (`tests/test_real_data.py`).
# * **`--occupied-penalty 5`** — a robot cannot stand in a wall, so particles
#   in the map's obstacles should lose. Zero weight is too much for a map that
#   is wrong: a door drawn shut, furniture moved since, a passage narrowed by
#   walls drawn 0.15 m too thick. When the robot drives through such a place,
#   every particle of a correct cloud ends up "in the wall", the cloud is
#   wiped out, and global localization starts again. So, once the cloud
#   agrees on one place, a particle in an obstacle loses 5 nats per update
#   (e^-5, about 1/150). When the whole cloud is in the obstacle, every
#   particle pays the same and the scans decide. While the filter is still
#   searching, a particle in an obstacle keeps zero weight, because there it
#   is only one wrong hypothesis among many. Outside the map it has zero
#   weight either way.
# * **`--restart-after 5`** — when the cloud has agreed on a place where the
#   scans have not fitted the map for five updates, it is confidently wrong:
#   global localization starts again, with as many new particles as at the
#   start beside the old cloud, half of the weight each. The two clouds are
#   then on probation side by side, each resampled on its own, for up to 30
#   updates. The new search replaces the old place only if it wins on both
#   counts: the weight the sensor model gives it *and* the share of beams
#   whose reading matches the range ray-cast in the map (the fit), and only
#   if that fit is acceptable in itself (at least half the expected share). The
#   likelihood field alone would often pick a look-alike whose beams end in
#   the map's unknown cells, since it scores those neutrally; the ray cast
#   cannot judge them and so does not reward them. Meanwhile the estimate is
#   the place favoured so far (the old one for the first three scans, which
#   are too few to judge by), with only its share of the weight, so the
#   state does not claim "localized". Before the first
#   localization, a cloud gathered less tightly (within 2 m) also counts, and
#   so does an update whose fit the map cannot judge because the beams at the
#   estimate end in unknown cells. A wrong room whose beams all end in the
#   unknown scores as well as the right one, and a cloud stuck there would
#   otherwise search there to the end of the log. A filter that is *lost*
#   and whose best place has not fitted the scans for five updates restarts
#   too, whether its cloud agrees on that place or has spread out: it has
#   said that it does not know where the robot is, and a search beside the
#   old cloud changes nothing if it finds no better place.
# * **`--min-range 0.05`** — readings at or below 5 cm are failures, not
#   evidence (ROS AMCL's `laser_min_range`).
#
# `benchmarks/bench_global.py` measures them on every real log this project has
# — the Intel lab, Freiburg 079, ACES and CSAIL with maps built from their
# corrected poses and then degraded (walls grown, obstacles added and removed, a
# region unknown), with the raw odometry, from many start scans and seeds — and
# on the Willow Garage map with simulated scans. Its table (from
# `benchmarks/RESULTS.md`, so this cell needs no data) also counts the runs whose
# state *ended* "localized" while more than 1 m off:

# %%
def results_section(name):
    """The section ``## name`` of benchmarks/RESULTS.md ("" if there is none)."""
    results = Path("../benchmarks/RESULTS.md")
    text = results.read_text() if results.exists() else ""
    head = re.search(rf"^## {re.escape(name)}$", text, flags=re.M)   # the exact heading, not a longer one
    if head is None:
        return ""
    section = text[head.start():]
    return (section[:section.find("\n## ", 3)] if "\n## " in section[3:] else section).strip()


def table_rows(section):
    """The data rows of the section's table, by their first cell (a list of the row's cells)."""
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and len(cells) > 2 and cells[1].isdigit():
            rows[cells[0]] = cells
    return rows


section = results_section("bench_global")
print(section or "benchmarks/RESULTS.md has no bench_global section yet")

# %% [markdown]
# The target of the issue that asked for this benchmark — 95% success on every
# log — is reached: Intel (100%), Freiburg 079 (97%), ACES (100%), CSAIL (98%)
# and the simulated Willow runs (95%), with the least to spare on Willow.
# Each default named above is there for one of these failures. The map-sized
# initial cloud is for ACES, where a fixed cloud of 50,000 particles, started
# in a stretch of the building that looks the same in several places, often
# localized only after the first 30% of the run. Leaving out the beams that
# end in unknown cells once the cloud agrees is for the runs whose robot
# drives through the square that the degraded map leaves unknown: without it
# they failed at every seed, because the cloud was pulled out of the square.
# Leaving out the beams that read well short of the map once the cloud agrees
# is for Willow too: with `--short-beams 0` (section
# `bench_global_short_beams_0`) Willow succeeds in 88% instead of 95%. The
# four runs it turns into successes are the failure it was made for: a
# correct, tight cloud that lost all of its weight, within one or two updates,
# to a few particles 1–2 m away while the robot stood close to clutter; on
# the four real logs it changes the success of one run (ACES 98% without
# it). It costs no confidence: 277 of the 300 runs end "localized" with it
# and without it (the table's "ended localized" column), and it halves the
# runs that call a wrong place "localized" at some scan (3 with it, 6
# without: the last column). The runs that end
# "lost" end near the robot, in a stretch where the scans fit the map poorly
# (the note under the table in `benchmarks/RESULTS.md`); they say so, they are
# not wrong.
# The short-reading floor is for unmapped clutter. The same runs with
# `--z-short 0` (the section `bench_global_z_short_0` of
# `benchmarks/RESULTS.md`) succeed on Willow in 77% instead of 95% and on
# ACES in 95% instead of 100% (on Intel, Freiburg and CSAIL equally often).
# Willow's simulated robot drives among ten
# unmapped objects per run, and their beams end short of the mapped walls. The odometry check is for
# Freiburg. With `--odometry-sign trust` (section
# `bench_global_odometry_sign_trust`) Freiburg succeeds in 80% instead of 97%,
# and the runs from start scans 709 and 1182 fail at every seed: the runs in
# which the robot backs up most often (in 37 and 50 of their 300 steps) while
# its odometry says forwards. The probation of a restart is for Willow, the
# largest of the five buildings. Its simulated robot turns on the spot
# wherever it is blocked, unmapped clutter stands in its way, and much of its
# map is unknown, so a wrong place whose beams end in the unknown can look as
# good as the right one to the likelihood field. When clutter makes a correct
# cloud fit poorly for a few scans, the restart's new particles find such a
# place; deciding by the weight alone, the filter would jump there.
#
# What the table does show is honesty: no run ended "localized" while more
# than 1 m off. A failed run ended either "lost" or "searching", and said so,
# or localized again within 1 m of the robot after it had left it. The last
# column is stricter: three Willow runs did call a wrong place "localized" for
# a few scans early on, each time the mirror image of the right place in that
# large, symmetric building (heading 180 degrees off), whose scans passed the
# fit test too, before the state turned "lost" and the search went on. The next
# cell checks these statements against the table, so that a re-run of the
# benchmark cannot silently contradict them.

# %% tags=["remove-cell"]
if section:
    rows = {}
    for name, cells in table_rows(section).items():
        ok, runs = cells[2].split()[0].split("/")
        rows[name] = dict(success=int(ok) / int(runs), off=int(cells[9]))
    assert {"intel", "freiburg-079", "aces", "csail", "willow"} <= set(rows), sorted(rows)
    claims = {"intel": 1.0, "freiburg-079": 0.97, "aces": 1.0, "csail": 0.98, "willow": 0.95}
    for log_name, rate in claims.items():
        assert abs(rows[log_name]["success"] - rate) < 0.01, (log_name, rows[log_name])
    assert all(r["success"] >= 0.95 for r in rows.values()), rows
    assert all(r["off"] == 0 for r in rows.values())
    some_scan = {name: int(cells[10]) for name, cells in table_rows(section).items()}
    assert some_scan == {"intel": 0, "freiburg-079": 0, "aces": 0, "csail": 0, "willow": 3}, some_scan
    scored = {name: cells[2].split()[0]
              for name, cells in table_rows(results_section("bench_global_short_beams_0")).items()}
    assert scored == {"intel": "60/60", "freiburg-079": "58/60", "aces": "59/60", "csail": "59/60",
                      "willow": "53/60"}, scored
    ended = [sum(int(cells[8]) for cells in table_rows(results_section(name)).values())
             for name in ("bench_global", "bench_global_short_beams_0")]
    assert ended == [277, 277], ended
    wrong_at_some_scan = [sum(int(cells[10]) for cells in table_rows(results_section(name)).values())
                          for name in ("bench_global", "bench_global_short_beams_0")]
    assert wrong_at_some_scan == [3, 6], wrong_at_some_scan
    without = {name: cells[2].split()[0] for name, cells in table_rows(results_section("bench_global_z_short_0")).items()}
    assert without == {"intel": "60/60", "freiburg-079": "58/60", "aces": "57/60", "csail": "59/60",
                       "willow": "46/60"}, without
    trusted = table_rows(results_section("bench_global_odometry_sign_trust"))["freiburg-079"][2].split()[0]
    assert trusted == "48/60", trusted

# %% tags=["remove-cell"]
from localize.grid import OccupancyGrid  # noqa: E402

assert abs(pipeline.auto_particles(OccupancyGrid(np.zeros((400, 130)), 0.1)) - 75_000) < 500   # 520 m^2 of free floor
d = settings.DEFAULTS                                                # the defaults the text names
assert (d["sigma_hit"], d["temper"], d["z_short"], d["beams"], d["min_range"]) == (0.2, 0.3, 0.2, 30, 0.05), d
assert (d["odometry_sign"], d["occupied_penalty"], d["restart_after"]) == ("auto", 5.0, 5), d
assert d["skip_short_beams"] == 1.0 and d["unknown_beams"] == "skip", d

# %% [markdown]
# A benchmark on which the defaults were chosen flatters them: each default
# above was adopted because it fixed failures of these very runs. So the
# benchmark has a second draw, `bench_global.py --held-out`, on which nothing
# was chosen: other start scans (between the standard ones), and so other map
# degradations, other Willow worlds and other seeds. Its table:

# %%
held_out = results_section("bench_global_held_out")
print(held_out or "benchmarks/RESULTS.md has no bench_global_held_out section yet")

# %% [markdown]
# The four real logs reach 95% there too. The simulated Willow runs do not
# (87%), and here the work is not finished: in most of the failed runs the
# filter finds the robot, but only after the first 30% of the run. Where the
# simulated robot starts inside the square that the degraded map leaves
# unknown, or next to unmapped clutter, its first scans say nothing the map
# can check, and the search settles on places whose beams end in the map's
# unknown cells, which a likelihood field cannot rule out; the restart rules
# above find the robot later. The note of that section in
# `benchmarks/RESULTS.md` lists the failures. The honesty holds on this draw
# as well: no run ended "localized" more than 1 m off, and four runs (two on
# ACES, one each on Freiburg and Willow) called a look-alike "localized" for a
# few scans before the state turned "lost".

# %% tags=["remove-cell"]
if held_out:
    rates = {name: cells[2].split()[0] for name, cells in table_rows(held_out).items()}
    assert {"intel", "freiburg-079", "aces", "csail", "willow"} <= set(rates), rates
    assert all(int(r.split("/")[0]) >= 0.95 * int(r.split("/")[1]) for name, r in rates.items() if name != "willow"), rates
    assert rates["willow"] == "52/60", rates                                  # 87%
    assert all(int(cells[9]) == 0 for cells in table_rows(held_out).values())
    some_scan = {name: int(cells[10]) for name, cells in table_rows(held_out).items()}
    assert some_scan == {"intel": 0, "freiburg-079": 1, "aces": 2, "csail": 0, "willow": 1}, some_scan

# %% [markdown]
# On speed (`benchmarks/bench_cli.py`): a CMU-sized log — 700 scans of 180
# beams over 135 s, an 800 x 800 map — runs, including reading the files, at
# tens of times real time with 1,000 particles, and faster than real time with
# 10,000.

# %% [markdown]
# ## Your robot: ROS bags in, AMCL settings in, standard trajectories out
#
# Your own robot records ROS bags, its map was saved by `map_server` (or
# `nav2_map_server`'s `map_saver_cli`), and it already runs AMCL with a parameter
# file. `localize` reads all three without a ROS installation (`pip install -e
# ".[ros]"` adds the pure-Python [rosbags](https://ternaris.gitlab.io/rosbags/)
# package), and writes its estimate in the formats the evaluation tools read.
#
# 1. **Record** the laser, the odometry and the transforms while you drive
#    around (ROS 2; `rosbag record` on ROS 1):
#
#    ```bash
#    ros2 bag record -s mcap /scan /odom /tf /tf_static -o office_run
#    ```
#
# 2. **Make the map**, e.g. with `slam_toolbox` while driving, then save it:
#    `ros2 run nav2_map_server map_saver_cli -f office` (writes `office.yaml`
#    and `office.pgm`). Or build it from known poses with `localize map`.
# 3. **Localize** with the settings your robot uses:
#
#    ```bash
#    localize run --map office.yaml --log office_run/ --amcl-params nav2_params.yaml --out out/office
#    ```
#
#    Topics are found by type (one `sensor_msgs/LaserScan`, one
#    `nav_msgs/Odometry`, else the `odom -> base` transform on `/tf`); name them
#    with `--scan-topic` / `--odom-topic` when there are several. The laser's
#    mounting comes from `/tf_static`, or from `--laser-pose X Y YAW`. Each scan
#    gets the odometry at its own time stamp, interpolated, as AMCL asks tf.
#    Readings that are NaN, infinite or outside `[range_min, range_max]` are
#    "no return", as in AMCL.
# 4. **Evaluate** with [evo](https://github.com/MichaelGrupp/evo):
#    `out/office/trajectory.tum` holds `timestamp x y z qx qy qz qw` per scan
#    (`reference.tum` too, when the log has reference poses), so
#    `evo_ape tum reference.tum trajectory.tum --plot` computes the absolute pose
#    error, and `out/office/localization_bag/` (`localization.bag` for a ROS 1
#    input) holds `/amcl_pose` and the particle cloud to replay beside the data
#    in RViz or Foxglove.
#
# We try it on the simulated log of this chapter, written as a ROS 2 MCAP bag
# with rosbags' own writer, the laser's 25 cm offset on `/tf_static`.

# %%
import io as stdio

from localize import amcl
from localize.io import rosbag

bag = rosbag.write_rosbag_log(folder / "office_run", log, storage="mcap", time_offset=1.7e9)
for topic, msgtype in sorted(io.bag_topics(bag).items()):
    print(f"{topic:12s} {msgtype}")
from_bag = io.read_rosbag(bag)
print(from_bag)
print("laser mounting from /tf_static:", [round(float(v), 3) + 0.0 for v in from_bag.sensor_offset],
      "| odometry:", from_bag.meta["odometry"])

# %% [markdown]
# The same seed and options give the same estimates from the bag as from the CMU
# file: the bag is just another container for the same scans and odometry.

# %%
quiet_err = stdio.StringIO()
cli.main(["run", "--map", str(map_file), "--log", str(bag), "--particles", "3000", "--seed", "0",
          "--out", str(folder / "out_bag"), "--quiet"], stderr=quiet_err)
est_bag = np.loadtxt(folder / "out_bag" / "trajectory.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
print("same trajectory as from the CMU log:", bool(np.array_equal(est_bag, est)))
print("written:", ", ".join(sorted(p.name for p in (folder / "out_bag").iterdir())))

# %% [markdown]
# Now with AMCL's settings. The parameter file below is a nav2 one (ROS 1 files,
# with `odom_alpha1`, `laser_z_hit`, `kld_err` ..., are read too). `localize`
# prints what it made of each parameter and warns about those it ignores; the
# table in `localize run --help` lists the whole mapping:
#
# | AMCL parameter (nav2 / ROS 1) | `localize` setting |
# |---|---|
# | `alpha1..4` / `odom_alpha1..4` | `--alphas`, PR table 5.6 variances. ROS 1's `diff` and `omni` models use the sums as standard deviations (no square root): converted at one step of `update_min_d`/`update_min_a`. ROS 1's omni code swaps alpha1 and alpha4 against its documentation: undone |
# | `alpha5` | ignored (omni strafe noise; differential model only) |
# | `laser_model_type` | `--sensor`: `likelihood_field` → likelihood, `beam` → beam, `likelihood_field_prob` → likelihood (no beam skipping) |
# | `max_beams` / `laser_max_beams` | `--beams` |
# | `laser_min_range`, `laser_max_range` | shorter readings are "no return"; `--max-range` (-1: the scan's own) |
# | `z_hit, z_short, z_max, z_rand` | mixture weights, normalised to sum 1 (`z_short`, `z_max` for the beam model only; the likelihood field's `--z-short` is 0 with a parameter file, as AMCL's has no such term, unless written on the command line) |
# | `sigma_hit`, `lambda_short` | `--sigma-hit`; the beam model's short-reading rate |
# | `laser_likelihood_max_dist` | the likelihood field's distance cap |
# | `min_particles`, `max_particles` | `--particles` = `max_particles`; KLD-sampling between the two |
# | `pf_err`, `pf_z` / `kld_err`, `kld_z` | KLD $\epsilon$ = `pf_err`, $\delta = 1 - \Phi(\text{pf\_z})$: `pf_z` is the normal *quantile*, so the default 0.99 means $\delta = 0.16$, not 0.01 |
# | `recovery_alpha_slow`, `recovery_alpha_fast` | augmented MCL (chapter 8); both 0: off |
# | `update_min_d`, `update_min_a` | `--min-motion` |
# | `resample_interval` | 1: resample after every update; larger: no counterpart (`N_eff < N/2` is used) |
# | frames, topics, tf, initial pose, beam skipping, `random_seed` | ignored, each with a warning |
#
# Two differences remain by design: AMCL scores a scan as $1 + \sum_k p_k^3$,
# an ad-hoc cure for correlated beams, where `localize` multiplies the beams'
# likelihoods and tempers the product (`--temper`); and options written on the
# command line win over the file.

# %%
params = folder / "amcl.yaml"
params.write_text("""amcl:
  ros__parameters:
    robot_model_type: "nav2_amcl::DifferentialMotionModel"
    alpha1: 0.05
    alpha2: 0.01
    alpha3: 0.02
    alpha4: 0.05
    laser_model_type: "likelihood_field"
    max_beams: 30
    sigma_hit: 0.3
    z_hit: 0.9
    z_rand: 0.1
    min_particles: 3000
    max_particles: 3000
    update_min_d: 0.2
    update_min_a: 0.3
    base_frame_id: "base_link"
    do_beamskip: false
""")
print(hide(amcl.read_amcl_params(params).table()))
warn_err = stdio.StringIO()
cli.main(["run", "--map", str(map_file), "--log", str(bag), "--amcl-params", str(params), "--seed", "0",
          "--out", str(folder / "out_amcl"), "--quiet"], stderr=warn_err)
for line in warn_err.getvalue().splitlines():
    print(hide(line))

# %% [markdown]
# The TUM file is what `evo` reads; here we read it back ourselves and compute
# the absolute position error against the simulator's true poses (what
# `evo_ape tum truth.tum trajectory.tum` reports as the translation APE, without
# alignment).

# %%
t_tum, est_tum = io.read_tum(folder / "out_amcl" / "trajectory.tum")
ape = np.hypot(*(est_tum[:, :2] - run.poses[:, :2]).T)
k0 = pipeline.converged_at(ape, 0.5)
print("scans:", len(t_tum), "| first time stamp:", round(float(t_tum[0]), 1), "s")
print("within 0.5 m of the truth from scan", k0, f"| median APE afterwards {np.median(ape[k0:]):.1f} m")

# %% [markdown]
# **Where the public logs live.** The CARMEN logs used in this book come from
# [Radish, the Robotics Data Set Repository](http://radish.sourceforge.net/)
# (Howard and Roy, 2003); the SLAM-corrected versions (`*-corrected.log.gz`)
# were published with the Freiburg SLAM benchmark
# (<http://ais.informatik.uni-freiburg.de/slamevaluation/datasets.php>, Kümmerle
# et al., 2009). Radish states no blanket licence: the data sets are free for
# research, and each names its contributor, whom publications should credit.
# The CMU 16-831 data (`wean.dat` and the `robotdata*.log` files of Wean Hall)
# is handed out with the particle-filter assignment of Carnegie Mellon's course
# 16-831, *Statistical Techniques in Robotics*; no licence is stated with it, so
# use it for study and do not redistribute it. The Willow Garage map used in the
# tests ships with ROS under the BSD licence. None of these files is part of this
# repository; `localize demo` runs without any of them.
#
# ## Tuning the models from your robot's data
#
# The defaults of `localize` are starting points. Three groups of numbers should
# come from your own robot, and each can be measured from a log that has
# **reference poses** — a corrected (SLAM) log like the CARMEN ones, a run with
# motion capture, or a few spots measured by tape:
#
# * **The motion alphas** (chapter 4). For every odometry step, turn both the
#   odometry readings and the reference poses into $(\delta_\text{rot1},
#   \delta_\text{trans}, \delta_\text{rot2})$; the differences are samples of
#   the motion noise. The model says their *variances* are linear in the alphas
#   ($\alpha_1\delta_\text{rot1}^2 + \alpha_2\delta_\text{trans}^2$ and so on),
#   so the squared differences, regressed on $\delta_\text{rot1}^2$,
#   $\delta_\text{trans}^2$, ..., give the alphas by least squares. Do it at the
#   rate at which your filter integrates odometry: with squared terms the alphas
#   depend on the step length (chapter 4).
# * **`sigma_hit`** (chapter 5). Project the scans from the reference poses; for
#   the likelihood field, the distances of the end points to the nearest
#   obstacle *are* the hit errors, and their robust spread is `sigma_hit`; for
#   the beam model, the EM fit of chapter 5 (`localize.beam_learning`) estimates
#   all six parameters at once. Either way the answer measures the map as much as
#   the laser, which is why it is larger than the laser's data sheet says.
# * **Tempering.** Beams do not err independently: one unmapped cupboard or one
#   misdrawn wall spoils a run of neighbours. Measure the correlation $\rho$ of
#   neighbouring beams' residuals at the reference poses; $B$ beams then carry
#   about as much information as $B(1-\rho)/(1+\rho)$ independent ones, and
#   tempering by that factor is a first guess (`localize.widgets.tuning.suggest_temper`).
#   Then check it: run the filter on the log and compare the spread of the
#   particle cloud with its actual error against the reference poses. A filter
#   whose errors are often several times its own spread is overconfident —
#   lower the tempering factor (or raise `sigma_hit`); one whose cloud is much
#   wider than its errors wastes particles.
#
# Here is the first recipe on a simulated log whose true alphas we know, at one
# odometry step per scan:

# %%
from localize import motion  # noqa: E402
from localize.geometry import wrap_angle  # noqa: E402
from localize.widgets.tuning import cluttered_scans, residual_correlation, sensor_model, suggest_temper  # noqa: E402

tune_run = sim.range_run(maps.office(), np.random.default_rng(77), n_steps=600, angles=np.radians([0.0]),
                         max_range=8.0, n_clutter=0)
r1_o, t_o, r2_o = motion.odometry_to_control(tune_run.odometry[:-1], tune_run.odometry[1:])
r1_t, t_t, r2_t = motion.odometry_to_control(tune_run.poses[:-1], tune_run.poses[1:])
moving = t_t > 0.05                                      # rot1 means nothing without a translation
# the simulator draws the noise with variances of the *true* motion: regress on the reference poses' motion
e_rot = np.concatenate([wrap_angle(r1_t - r1_o)[moving], wrap_angle(r2_t - r2_o)[moving]])
rot_design = np.column_stack([np.concatenate([r1_t[moving] ** 2, r2_t[moving] ** 2]),
                              np.concatenate([t_t[moving] ** 2] * 2)])
a12 = np.linalg.lstsq(rot_design, e_rot**2, rcond=None)[0]
e_tr = (t_t - t_o)[moving]
tr_design = np.column_stack([t_t[moving] ** 2, r1_t[moving] ** 2 + r2_t[moving] ** 2])
a34 = np.linalg.lstsq(tr_design, e_tr**2, rcond=None)[0]
print("alphas x 1000, true  ", np.round(1000 * np.asarray(tune_run.alphas), 1))
print("alphas x 1000, fitted", np.round(1000 * np.r_[a12, a34], 1), f"from {moving.sum()} steps")
# the main terms: within 25 % (a variance from n squared samples has a relative standard error of sqrt(2/n),
# 6 % here; regression on two correlated regressors widens it); the cross terms alpha2 and alpha4: not determined
assert abs(a12[0] / tune_run.alphas[0] - 1) < 0.25 and abs(a34[0] / tune_run.alphas[2] - 1) < 0.25

# %% [markdown]
# The two main terms, $\alpha_1$ (rotation error per rotation) and $\alpha_3$
# (translation error per translation), come out within about 20 % from 500
# steps. The cross terms $\alpha_2$ and $\alpha_4$ do not: in this log they add
# a few percent to the variances, too little to separate from the main terms.
# A tuning log should therefore mix the motions on purpose — turns on the spot,
# straight drives, and arcs — so that each term dominates somewhere; and for a
# filter, an overestimate of a small term is harmless, an underestimate of a
# large one is not.
#
# And the third recipe, the residual correlation along the scan, on the
# cluttered scans of the widget below:

# %%
scan_run, scan_angles = cluttered_scans()
expected = sensor_model("beam", 0.2).expected(scan_run.poses, scan_angles)
residuals = np.where(scan_run.ranges < 8.0, scan_run.ranges - expected, np.nan)
rho = residual_correlation(residuals)
print(f"lag-1 correlation of the beam residuals: {rho:.2f} -> tempering factor about {suggest_temper(rho):.2f}")
assert 0.0 < rho < 0.5

# %% [markdown]
# In this simulation every beam gets its own noise and only the unmapped boxes
# spoil runs of neighbours, so the correlation is weak and the suggestion mild.
# Real scans against a real map are usually far more correlated — a map drawn
# 5 cm off along a wall biases every beam that hits the wall — which is why the
# command line's default, measured on the real logs, tempers harder (0.3).
#
# ### Try it: tempering and `sigma_hit`
#
# The widget scores one cluttered scan of 72 beams with either model. Left: the
# weight one scan gives to positions around the true pose (the heading held at
# the truth) — how sharply the filter would believe this scan. Right: the
# effective sample size of about 1800 particles spread around the truth, as a
# function of the tempering factor; the dot is your setting. Untempered, a few
# dozen particles take all the weight; at $\gamma = 0.1$ the 72 beams count as seven and
# hundreds of particles survive. A small `sigma_hit` sharpens the weight the way
# a large tempering factor does. (In the HTML book the figure below the widget
# shows the default setting.)

# %% tags=["nbval-ignore-output"]
from localize.widgets.tuning import tuning_figure, tuning_widget  # noqa: E402

tuning_widget()

# %%
fig = tuning_figure(temper=0.1, sigma_hit=0.2)
print(f"ESS at gamma = 0.1: {fig.ess:.0f}; untempered: {tuning_figure(temper=1.0).ess:.0f}")
assert tuning_figure(temper=1.0).ess < 0.1 * fig.ess
fig

# %% [markdown]
# ## Offline: forwards and backwards in time (`localize run --smooth`)
#
# A filter running on the robot knows at scan *k* only the scans up to *k*: it
# spends the first scans of a log searching, and where two corridors look
# alike it may pick the wrong one and hold on to it until much later. A
# *recorded* log has all its scans. `--smooth` filters it twice with the same
# settings — forwards, and backwards over the reversed log — and combines the
# two passes scan by scan (`localize.smooth`). Going backwards needs no new
# motion model: the reversed odometry pair is the inverse relative pose, a robot
# driving backwards, which the command line's motion model already handles.
# (The odometry's sign is checked once, on the log as recorded, before both
# passes: played backwards, every step of an odometry without a sign reads as
# reversing.)
#
# * the **backward pass** starts at the end of the log and has long localized
#   when it reaches the start: the scans the forward pass spent searching get an
#   answer;
# * where **both** passes are localized and agree (within 0.5 m and 10°), the
#   estimate is their mean weighted by the spreads;
# * where both are localized but **disagree** — one of them on a look-alike
#   place — the pass whose estimates fit the scans better (the share of beams
#   the map confirms by ray casting, compared scan by scan over the stretch)
#   wins; if the scans cannot tell the places apart, the stretch is reported
#   *ambiguous* and not localized;
# * where only **one** pass is localized, its estimate — unless the other
#   pass's estimate, not localized yet, fits those scans clearly better: a
#   lone pass that has just re-localized after losing the robot may sit on a
#   look-alike place, and it is then *overruled* (not localized there).
#
# `trajectory.csv` gains the columns `passes` (`both`, `disagree`, `forward`,
# `backward`, `none`) and `source`, `summary.json` a `smooth` section, and the
# terminal a line such as "forward and backward pass agree on 100% of the 91
# scans where both are localized; forward pass localized from scan 6, backward
# pass from scan 0". On the same simulated log as above:

# %%
import csv  # noqa: E402

cli.main(["run", "--map", str(map_file), "--log", str(log_file), "--smooth", "--particles", "20000",
          "--seed", "0", "--out", str(folder / "smooth"), "--quiet"])
smoothed = json.loads((folder / "smooth" / "summary.json").read_text())
with open(folder / "smooth" / "trajectory.csv") as fh:
    rows = list(csv.DictReader(fh))
xy = np.array([[float(r["x"]), float(r["y"])] for r in rows])
err_s = np.hypot(*(xy - run.poses[:, :2]).T)
two = smoothed["smooth"]
print("forward pass alone: localized from scan 0?", two["forward_first_localized_scan"] == 0)
print("smoothed trajectory:", cli.headline(smoothed))
agree = two["share_agree_where_both_localized"]
print("where both passes are localized they agree on", "at least 90%" if agree >= 0.9 else f"{agree:.0%}",
      "of the scans")
print("smoothed estimates within 0.5 m of the truth:", "all" if err_s.max() < 0.5 else f"{np.mean(err_s < 0.5):.0%}")
assert smoothed["state"]["first_localized_scan"] == 0 and err_s.max() < 0.5

# %%
colours = {"both": "tab:green", "forward": "tab:blue", "backward": "tab:orange", "disagree": "tab:red",
           "none": "tab:gray"}
fig, ax = plt.subplots(figsize=(8, 2.6))
passes = np.array([r["passes"] for r in rows])
for name, c in colours.items():
    k = np.flatnonzero(passes == name)
    if k.size:
        ax.plot(k, err_s[k], ".", color=c, label=name)
ax.set_xlabel("scan")
ax.set_ylabel("error of the smoothed estimate (m)")
ax.set_ylim(0, 0.6)
ax.legend(title="passes localized", ncol=5, loc="upper center", fontsize=8)
plt.show()

# %% [markdown]
# On the benchmark's logs and degraded maps (`benchmarks/bench_smooth.py`: the
# same runs as `bench_global`, 20 starts x 2 seeds per data set, each
# trajectory judged by bench_global's rule), the forward pass alone now
# succeeds in 197 of 200 runs, and smoothing adds little to that: it turns 3
# failures into successes and 2 successes into failures (198 of 200). What it
# adds is the share of each log that is localized — 95% of the scans instead
# of 87% — because the backward pass localizes the start that the forward
# pass spends searching. Two smoothed runs (one on ACES, one on Willow) call
# scans localized while more than 1 m off, against three forward runs, all
# on Willow (the table's next-to-last column). Where one pass is still *searching*
# (the backward pass near the log's end, the forward pass near its start), its
# estimate is never preferred to the other pass's: it is the best place of a
# fresh cloud for the few scans it has seen, so it fits those scans by
# selection. It cannot help where both passes go wrong at the same place, and
# a pass that is wrong with confidence can
# still win a stretch. It is an
# offline tool: it needs the whole log and takes more than twice the time
# of one pass. The table, from `benchmarks/RESULTS.md` (the cell after it
# checks these numbers against it):

# %%
section = results_section("bench_smooth")
print(section or "benchmarks/RESULTS.md has no bench_smooth section yet")

# %% tags=["remove-cell"]
if section:
    every = table_rows(section)["all"]
    assert every[2].startswith("197/200") and every[3].startswith("198/200"), every
    assert (every[4], every[5]) == ("3", "2"), every
    assert every[6] == "87% / 95%" and every[8] == "3 / 2", every
    assert [table_rows(section)[name][8] for name in ("aces", "willow")] == ["0 / 1", "3 / 1"], section
    seconds = [float(v) for v in every[9].split("/")]
    assert seconds[1] > 2 * seconds[0], every          # "more than twice the time of one pass"

# %% [markdown]
# ## Summary
#
# * Read the file format's definition, then *plot* what you read: a map over its
#   scans shows inverted probabilities, mirrored axes, wrong units, reversed
#   beams and a forgotten laser offset at a glance.
# * Convert once, at the border: `localize.io` turns every format into metres,
#   radians, an `OccupancyGrid` of occupancy probabilities (NaN unknown) and a
#   `LaserLog`.
# * Bad input is an error with a file and a line, never a half-read result.
# * Real maps and scans disagree by 0.1 m or more: choose `sigma_hit` for the map,
#   not for the laser, and temper the likelihood.
# * A filter must say when it does not know: searching, localized or lost, from
#   the cluster weight, the spread and whether the scans fit the map — and a
#   global localizer needs a dense initial cloud (KLD-sampling shrinks it).
# * With known poses, a map is a sum of log-odds (occupancy grid mapping).

# %% [markdown]
# ## Exercises
#
# **1 (by hand).** A line of a CMU map file reads `... 0.95 -1 0.02 ...`, and these
# are the values number 101, 102 and 103 on text line 41 (both counted from 1),
# in a map with 10 cm cells. (a) Which world points $(x, y)$ are the centres of
# these three cells? (b) What occupancy does `read_cmu_map` store for each, and at
# which `grid.data[i, j]`? (c) A CMU laser record's beam 46: at what angle to the
# robot's heading does it point?
#
# **2 (implementation).** Write a reader for a made-up "XY log": each line is
# `SCAN t x y theta r1 ... rn` with ranges in millimetres, beams from +90° down to
# -90° (clockwise!) and 0 meaning "no return", from a scanner that reaches 30 m.
# Return an `io.LaserLog` in the book's conventions, and reject a line with the
# wrong number of fields with `io.FormatError(path, line, ...)`. Test it on a
# file you write yourself, then with `check.xy_reader(read_xy_log)`, which
# tries the traps (units, beam order, "no return", line numbers).
#
# **3 (experiment).** On the simulated log of this chapter, run global
# localization (`pipeline.localize_log`, seeds 0 to 7) with `temper=1` and with the
# default `temper=0.3`, first with 1,000 particles, then with the default
# number (`n_particles="auto"`). In how many seeds does it converge (within
# 0.5 m: `pipeline.converged_at`)? What decides here, the tempering or the number of
# particles? Then explain what tempering changes, and why it matters on real
# logs whose maps disagree with their scans.

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Solution 1. Text line 41 is x cell 40; values 101..103 are y cells 100..102.
x_cell, y_cells = 40, np.array([100, 101, 102])
centres = np.column_stack([np.full(3, (x_cell + 0.5) * 0.1), (y_cells + 0.5) * 0.1])
print("cell centres [m]:", centres.round(2).tolist())
p_free = np.array([0.95, -1.0, 0.02])
occ = np.where(p_free < 0, np.nan, 1 - p_free)
print("stored occupancy:", occ.round(2).tolist(), "at grid.data[i=y, j=x] =", [(int(i), x_cell) for i in y_cells])
print("beam 46 points at", -90 + 45, "degrees, i.e. 45 degrees to the robot's right")


# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Solution 2.
def read_xy_log(path):
    times, odo, ranges = [], [], []
    for n, line in enumerate(Path(path).read_text().splitlines(), start=1):
        tok = line.split()
        if not tok:
            continue
        if tok[0] != "SCAN":
            raise io.FormatError(path, n, f"expected a SCAN record; got {tok[0]!r}")
        if ranges and len(tok) != 5 + len(ranges[0]):
            raise io.FormatError(path, n, f"expected {5 + len(ranges[0])} fields like the first scan; got {len(tok)}")
        try:
            v = np.array(tok[1:], dtype=float)
        except ValueError:
            raise io.FormatError(path, n, "every field after SCAN must be a number") from None
        times.append(v[0])
        odo.append(v[1:4])
        r = v[4:][::-1] / 1000.0  # clockwise -> counter-clockwise, mm -> m
        ranges.append(np.where(r == 0, 30.0, r))  # 0 means no return: use max_range
    n_beams = len(ranges[0])
    return io.LaserLog(times=times, odometry=odo, ranges=ranges, angles=np.linspace(-np.pi / 2, np.pi / 2, n_beams),
                       max_range=30.0, source=str(path), format="xy")


xy = folder / "test.xy"
xy.write_text("SCAN 0.0 1 2 0 1000 0 3000\nSCAN 0.1 1.1 2 0 1000 2000 3000\n")
xy_log = read_xy_log(xy)
print(xy_log, xy_log.ranges.tolist())
xy.write_text("SCAN 0.0 1 2 0 1000 0 3000\nSCAN 0.1 1.1 2 0 1000\n")
try:
    read_xy_log(xy)
except io.FormatError as e:
    print("rejected:", hide(e))
print(localize.check.xy_reader(read_xy_log))

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Solution 3.
converged = {}
for particles in (1000, "auto"):
    for temper in (1.0, 0.3):
        steps = []
        for seed in range(8):
            res = pipeline.localize_log(grid, log, n_particles=particles, rng=np.random.default_rng(seed), temper=temper)
            steps.append(pipeline.converged_at(np.hypot(*(res.estimates[:, :2] - run.poses[:, :2]).T), 0.5))
        converged[particles, temper] = sum(s is not None for s in steps)
        print(f"{particles!s:>5} particles, temper {temper:3}: converged in {converged[particles, temper]} of 8 seeds")
print("'auto' is", pipeline.resolve_particles("auto", grid), "particles on this map")
assert all(2 <= converged[1000, t] <= 6 for t in (1.0, 0.3))     # "about half the seeds", either way
assert converged["auto", 1.0] == converged["auto", 0.3] == 8

# %% [markdown]
# In this small office the number of particles decides, not the tempering:
# with 1,000 particles the filter converges in about half the seeds, tempered
# or not. A seed that fails has no particle near the truth after the first
# scans, and no tempering can help a filter with no particle near the truth.
# With the default cloud (one particle per pose cell of the free space) every
# seed converges, untempered too. The office is kind: its rooms differ, and its
# simulated scans fit its map.
#
# Tempering matters where many places fit a scan almost as well — on real logs,
# whose maps disagree with their scans. Untempered, every scan multiplies the
# weights by the product of 30 beam likelihoods *as if the beams were
# independent*; a handful of scans put all the weight on the few particles that
# matched best, often at a wrong place, and resampling discards the rest before
# the robot has seen enough to tell the places apart (the effective sample size
# of the widget's figure above: untempered, it falls below a tenth of its value
# at 0.1). Tempering raises each scan's likelihood to a small power, so evidence
# accumulates over many scans and the cloud keeps its alternatives until they
# are really ruled out. Too small a factor and the filter converges slowly and
# tracks loosely: it is a dial between over- and under-confidence.

# %% [markdown]
# **4 (implementation, self-checked).** The ROS map trap in code: write
# `map_image(image, negate)` that turns a `map_server` picture (an `(H, W)` array
# of grey values as stored in the PGM file) into occupancy in `localize`'s
# convention: 1.0 occupied, 0.0 free, NaN unknown, by the trinary rule and the
# default thresholds of this chapter, and with row 0 at the *bottom*. Test it with
# `check.map_image(map_image)`; it tries the picture upside down, white read as
# occupied, `negate` ignored and unknown cells made free.

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
from localize import check  # noqa: E402


def map_image(image, negate):
    """Occupancy of a map_server picture (trinary, default thresholds), row 0 = the bottom of the map."""
    v = np.asarray(image, dtype=float)
    p = v / 255.0 if negate else (255.0 - v) / 255.0
    occupancy = np.full(p.shape, np.nan)
    occupancy[p > 0.65] = 1.0
    occupancy[p < 0.196] = 0.0
    return np.flipud(occupancy)


print(check.map_image(map_image))
mine = map_image(io.read_pgm(folder / "grey.pgm"), negate=False)
print("agrees with io.read_map on grey.yaml:", bool(np.array_equal(mine, strict.data, equal_nan=True)))
