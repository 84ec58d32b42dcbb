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
# programs, years ago: the CMU 16-831 course's map of Wean Hall and its robot
# logs, CARMEN logs from the Radish archive, maps saved by ROS `map_server`.
# Each format is simple, and each hides a trap that silently turns a working localizer into one
# that never converges: a map stored as the probability of *free* space, a map
# whose text lines are columns, ranges in centimetres, a laser mounted 25 cm ahead
# of the robot's centre, readings of 81.83 m that mean "nothing there".
#
# This chapter walks through those traps on a log that our simulator writes in
# the CMU format, so that it runs anywhere. Then it builds a map from a log with
# known poses, runs the command-line localizer on the real Intel lab log, and
# meets the few rules beyond chapter 7's loop that a real log needs. The
# measurements behind the command line's defaults are in the appendix,
# [Why the defaults are what they are](13_appendix_defaults.ipynb).

# %%
import io as stdio
import json
import os
import tempfile
import warnings
from dataclasses import replace
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
# heading, an error that does not average out, since it rotates with the robot
# (last line above).
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
#
# A CMU file does not say what its laser's maximum is, so the reader takes
# **80 m** (`io.cmu.CMU_MAX_RANGE`) as the threshold: every reading at or above
# 8000 cm, the scanner's 8183 cm included, is "no return". That is why the cell
# below prints a maximum of 80 m beside readings stored as 81.83 m. (Our
# simulated laser reaches only 12 m; its "no return" readings are written as
# 8183 cm, like the real scanner's.)

# %%
print("maximum range of the log:", log.max_range, "m  (io.cmu.CMU_MAX_RANGE; no return at or above it)")
print("share of no-return readings:", round(float(log.no_return.mean()), 3))
print("readings stored as 8183 cm:", int((log.ranges >= 81.8).sum()), "of", log.ranges.size)
print("longest reading that is not 'no return':", round(float(log.ranges[~log.no_return].max()), 2), "m")
assert np.all(log.ranges[log.no_return] >= 81.8) and log.ranges[~log.no_return].max() < 12.0

# %% [markdown]
# ## Trap 6: unknown cells, and maps that are wrong
#
# Cells the map maker never observed are unknown (`NaN`). A laser cannot see
# through them — or rather, we cannot promise that it can — so ray casting and
# the distance field treat them as obstacles, while chapter 7's global localizer
# draws its initial particles only from *known free* cells. The command-line
# localizer lets particles stand in unknown cells, and draws them over the map's
# *holes* as well (`grid.holes`): unknown patches that do not reach the map's
# edge and whose border is mostly open floor, not walls or the thin lines of
# free cells that rays seen through a door leave — where people stood while the
# map was made, or a region erased by hand. A robot can start there, and a
# filter that never looks there finds it only once it drives out.
#
# Real maps are also wrong: the Wean Hall map draws walls 10-15 cm thicker than
# the laser sees them, and furniture has moved. A `sigma_hit` of a few
# centimetres — the laser's own noise — punishes the *true* pose for the map's
# mistakes. The command-line localizer therefore uses `sigma_hit = 0.2 m`, looks at 30 beams
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
fig, axes = plt.subplots(1, 3, figsize=(12, 2.8))
axes[0].imshow(img, cmap="gray", vmin=0, vmax=255)
axes[0].set_title(f"the picture: walls grey {img[0, 0]}, p = {(255 - img[0, 0]) / 255:.2f}", fontsize=9)
axes[0].set_xticks([])
axes[0].set_yticks([])
draw_map(strict, ax=axes[1])
axes[1].set_title(f"trinary: {int(strict.occupied.sum())} wall cells (the pillar);\n"
                  f"the grey walls are {int(strict.unknown.sum())} unknown cells (blue)", fontsize=9)
draw_map(fixed, ax=axes[2])
axes[2].set_title(f"not_free='occupied': {int(fixed.occupied.sum())} wall cells", fontsize=9)
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
# `mapping.OccupancyMapper` applies the model along each beam, as practical
# mappers do: cells the beam crosses are free, the cell where it ends is
# occupied, a "no return" teaches nothing; probabilities are clamped to
# [0.12, 0.97], so that a map can still change when a door opens. We build the
# office from the simulated scans and the robot's *true* poses:

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
# outvotes such noise, which is why the map of the Intel lab below is clean.
# Cells never seen stay unknown (blue-grey). On a real log the same two lines
# build the map:
#
# ```python
# log = io.read_log("../shared/data/carmen/intel-corrected.log.gz")
# intel = mapping.map_from_log(log, resolution=0.05)
# ```

# %% [markdown]
# ## The command-line localizer
#
# `localize run` (or `python -m localize run`) puts everything together: it
# detects the formats from the files' contents, spreads particles over the map's
# free space, and filters every scan, writing one estimate per scan to
# `trajectory.csv` (the robot centre in the map frame, and the filter's state)
# and the run's numbers to `summary.json`; `--animate` adds a GIF of the cloud.
# `localize run --help` documents every option with an example.

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
# ## A real log, one command
#
# Now real data: the Intel Research Lab log (CARMEN format, a robot driving
# through an office floor, with SLAM-corrected poses but no map). `--build-map`
# builds the map from the corrected poses, as in the section on mapping;
# `--scans 0:300` keeps the first 300 scans, so that the cell takes seconds; the
# filter starts with particles all over the map (global localization), every
# other setting at its default.
#
# ```bash
# localize run --log ../shared/data/carmen/intel-corrected.log.gz --build-map --resolution 0.1 \
#              --scans 0:300 --seed 0 --out out/intel
# ```
#
# If the data sits beside the book (`../shared/data`, or the folder named by
# the environment variable `LOCALIZE_DATA`), the next cell runs this command;
# without the data, the cells on the Intel log do nothing.

# %% tags=["nbval-ignore-output"]
data = Path(os.environ.get("LOCALIZE_DATA", "../../shared/data"))
intel_file = data / "carmen" / "intel-corrected.log.gz"
have_intel = intel_file.exists()
if have_intel:
    terminal = stdio.StringIO()
    cli.main(["run", "--log", str(intel_file), "--build-map", "--resolution", "0.1", "--scans", "0:300",
              "--seed", "0", "--out", str(folder / "intel")], stdout=terminal, stderr=stdio.StringIO())
    print(hide(terminal.getvalue()))
else:
    print(f"real data not found at {data}: the cells on the Intel log are skipped")

# %% [markdown]
# The terminal reports the run's speed, the filter's own account of itself —
# *searching*, *localized* or *lost*, from its own evidence, never from the
# corrected poses — and the error against the corrected poses at the scans it
# called localized.
#
# Besides `trajectory.csv` and `summary.json`, the command drew the run over
# its map in `report.png` (with `localize.plot.report.report_figure`); the
# next cell shows it. `localize run` is a thin layer over the library
# `localize.pipeline` (`read_inputs`, `localize_log`). For the replay further
# down we call the library with the same settings and seed, keeping the
# particles of every scan (`localize.widgets.reallog.log_run`; the cell checks
# that it gives the command's trajectory):

# %% tags=["nbval-ignore-output"]
from IPython.display import Image, display  # noqa: E402

from localize.widgets.reallog import log_run, reallog_figure, reallog_widget  # noqa: E402

if have_intel:
    intel_log, intel_map, _ = pipeline.read_inputs(
        pipeline.Inputs(log=intel_file, build_map=True, resolution=0.1, scans=slice(0, 300)),
        settings.DEFAULTS["min_range"], warn=lambda message: None)
    intel = log_run(intel_map, intel_log, seed=0)
    written = np.loadtxt(folder / "intel" / "trajectory.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
    assert np.allclose(written, intel.trace.poses, atol=1e-5)      # the command's trajectory
    display(Image(filename=str(folder / "intel" / "report.png")))  # the command's picture, as it wrote it

# %% tags=["remove-cell"]
if have_intel:    # what the text says about this run, with margins for another machine's round-off
    err_i = np.hypot(*(intel.trace.poses[:, :2] - intel.reference[:, :2]).T)
    localized_i = intel.trace.state == "localized"
    assert intel.trace.first_localized() is not None and intel.trace.first_localized() <= 30
    assert np.median(err_i[localized_i]) < 0.1 and err_i[localized_i].max() < 1.0
    assert np.median(err_i[:5]) > 1.0                                  # the first estimates are far off

# %% [markdown]
# Left: the map, the corrected path (thin black line) and the estimate of each
# scan. At the first scans the particles cover the whole floor and the
# estimate, the best of many hypotheses, is metres off; a few scans later the
# cloud has gathered on the robot and the state turns *localized* (green). Right: the error against the
# corrected poses over the run, with the state behind it. The error of the
# localized scans is a few centimetres, its median under the map's 10 cm cells.
#
# ## What a real log needs beyond the textbook loop
#
# Chapter 7 printed the loop that runs the filter, `localize.runloop.run`:
# predict, update, estimate, resample, and at named points a call to a
# **policy**; chapter 8 met the policies that recover a lost robot. A real log
# needs three more, each there to prevent one failure:
#
# | policy (`localize.policies`) | the failure it prevents | what it does |
# |---|---|---|
# | `OdometryCheck` | a corrupt odometry record (a pose 1 km away, a NaN) throws every particle off the map | a step longer than the map's diagonal, or not finite, is refused: the particles stay put, and `events` says so |
# | `MotionGate` | a robot standing still sends the same scan again and again; each use counts it as new evidence, and the cloud grows over-confident (chapter 8) | a scan is used only after the odometry moved 0.2 m or turned 0.3 rad since the last used one (`--min-motion`, AMCL's `update_min_d`/`update_min_a`) |
# | `BeamMasks` | a chair the map does not show stops beams short; scored, they let particles at a wrong place win | once the cloud agrees, beams reading more than 1 m shorter than the map there (`--skip-short-beams`), or ending in unknown cells (`--unknown-beams`), are left out |
#
# And the **state** (`localize.reliability.ReliabilityState`, chapter 8). We watch the
# three policies on the simulated log, one odometry record corrupted to a pose
# 1 km away:

# %%
corrupt = np.array(log.odometry, copy=True)
corrupt[50, 0] += 1000.0
res_c = pipeline.localize_log(grid, replace(log, odometry=corrupt), rng=np.random.default_rng(0), particles=3000)
for k, text in res_c.trace.events:
    if "odometry" in text or "beams" in text:
        print(f"scan {k:3d}: {text}")
err_c = np.hypot(*(res_c.estimates[:, :2] - run.poses[:, :2]).T)
print(f"scans used: {int(res_c.updated.sum())} of {len(log)} (the others came before the robot had moved "
      "0.2 m or turned 0.3 rad)")
print(f"localized from scan {res_c.trace.first_localized()}; error after scan 60 at most {err_c[60:].max():.2f} m")
assert sum("impossible" in text for _, text in res_c.trace.events) == 2 and err_c[60:].max() < 0.5
assert res_c.updated.sum() < len(log) and any("shorter than the map" in text for _, text in res_c.trace.events)
assert settings.DEFAULTS["min_motion"] == (0.2, 0.3) and settings.DEFAULTS["skip_short_beams"] == 1.0

# %% [markdown]
# The corrupt record makes two impossible steps — from the last good pose to
# the wrong one, and back — and both are refused; the robot is not lost. The
# motion gate used fewer scans than the log holds, and once the cloud agreed,
# beams that hit the unmapped boxes of the simulated office were left out.
#
# ### The state, in plain words
#
# The state uses no ground truth. It is chapter 8's Bayes filter over the
# filter: at every scan the run computes `p_localized`, the probability that
# the estimate is within 1 m of the robot, and writes it to `trajectory.csv`
# beside the state read from it: *localized* once it reaches 0.95, *lost*
# when a localized filter falls below 0.7 (or when the second kind of
# evidence below alone no longer allows 0.95: the column `p_place` holds
# the most it allows), *searching* before the first time. Two kinds of
# evidence enter it (their geometric mean):
#
# 1. **the scans fit the map at the estimate**: the belief of chapter 8's
#    two-state filter over the scans' fits, with $p(\text{fit} \mid
#    \text{right})$ and $p(\text{fit} \mid \text{wrong})$ calibrated when
#    the run starts, on this run's map and sensor model (a second or two);
# 2. **no other place fits as well**: the smallest of three shares, each
#    the estimate's against its alternatives — the particles' weight within
#    1 m of it; the scans at the estimate against the same pose moved 1 m
#    forwards, backwards, left or right (in a featureless corridor every
#    stretch fits alike, and this stays near a third); and the estimate
#    against the look-alike places that the rival bank of chapter 8 keeps.
#
# When `p_localized` has stayed below 0.7 for five updates, the filter
# searches the whole map again beside its cloud (`--restart-after`).
#
# `localize run --state thresholds` replaces the probability by fixed rules
# (`localize.policies.StateRules`): the best
# cluster holds 80% of the weight within 0.5 m and 20°, the last five scans
# fit the map at least 60% as well as a correct pose's, the 1 m probe fits
# clearly worse, and three such scans in a row make *localized*, three
# others *lost*. Rules like these are thresholds chosen on a few logs. On
# the Intel run above they call the robot lost while it is centimetres from
# the corrected path:

# %%
from localize.policies import StateRules  # noqa: E402
from localize.reliability import LOCALIZED_AT, LOST_BELOW  # noqa: E402

r = StateRules()        # the numbers of the rules above
assert (r.min_share, r.max_spread, round(np.degrees(r.max_heading_std)), r.min_fit, r.fit_window) == (0.8, 0.5, 20, 0.6, 5)
assert (r.probe_shift, r.hold, r.hold_lost) == (1.0, 3, 3)
assert (LOCALIZED_AT, LOST_BELOW, settings.DEFAULTS["restart_after"], settings.DEFAULTS["state"]) == (0.95, 0.7, 5, "probability")
if have_intel:
    for name, run_i in (("probability", intel), ("thresholds", log_run(intel_map, intel_log, seed=0, state="thresholds"))):
        e_i = np.hypot(*(run_i.trace.poses[:, :2] - run_i.reference[:, :2]).T)
        lost = run_i.trace.state == "lost"
        where = ", ".join(f"{a}-{b}" for a, b in run_i.trace.lost_intervals())
        print(f"state from {name}: localized from scan {run_i.trace.first_localized()}, "
              + (f"lost at scans {where} while at most {e_i[lost].max():.1f} m off" if lost.any() else "never lost"))
    k_i = intel.trace.first_localized()
    print(f"p_localized from scan {k_i} on: at least {np.floor(intel.trace.p_localized[k_i:].min() * 100) / 100:.2f}")
    assert not np.any(intel.trace.state == "lost") and intel.trace.p_localized[k_i:].min() > LOCALIZED_AT

# %% [markdown]
# ## The defaults, and the failure each one prevents
#
# Every setting of a run is one field of `localize.settings.RunSettings`, with
# its default, unit, valid range and help; the command line's `--help`, the
# benchmarks and this table are generated from it. Each default below is there
# because, measured, the run fails without it; the appendix
# ([Why the defaults are what they are](13_appendix_defaults.ipynb)) gives the
# measurements.

# %%
from dataclasses import fields  # noqa: E402

from IPython.display import Markdown  # noqa: E402

prevents = {
    "particles": "no particle near the robot at the start: the cloud gathers on a look-alike place",
    "sigma_hit": "the true pose punished for the map's own error (walls drawn 0.1-0.15 m off)",
    "temper": "30 correlated beams counted as 30 independent ones: the cloud locks onto the first place that looks right",
    "z_short": "a beam stopped by an unmapped chair rules the true pose out",
    "min_motion": "the same scan of a robot standing still counted again and again: an over-confident cloud",
    "min_range": "failed readings (0 m) taken as obstacles touching the robot",
    "kld": "tens of thousands of particles kept after the filter has agreed: a slow run",
    "state": "thresholds chosen on a few logs: localized while a metre off, or lost while centimetres right",
    "restart_after": "a cloud that is confidently wrong stays wrong to the end of the log",
    "unknown_beams": "beams ending where the map knows nothing pull an agreed cloud out of that region",
    "skip_short_beams": "beams hitting unmapped clutter hand the weight to particles at a wrong place",
    "occupied_penalty": "a door drawn shut in the map wipes out a correct cloud that drives through it",
    "odometry_sign": "odometry that never reports reversing carries the cloud forwards while the robot backs up",
}
meta = {f.name: f.metadata for f in fields(settings.RunSettings)}
assert (settings.DEFAULTS["sigma_hit"], settings.DEFAULTS["beams"], settings.DEFAULTS["temper"]) == (0.2, 30, 0.3)
assert set(prevents) <= set(settings.setting_names(cli_only=True)), set(prevents) - set(meta)
rows = ["| setting (`--flag`) | default | unit | the failure it prevents |", "|---|---|---|---|"]
for name, failure in prevents.items():
    value = settings.DEFAULTS[name]
    shown = " ".join(str(v) for v in value) if isinstance(value, tuple) else str(value)
    rows.append(f"| `--{name.replace('_', '-')}` | {shown} | {meta[name]['unit'] or '-'} | {failure} |")
Markdown("\n".join(rows))

# %% [markdown]
# Two more rules are not settings: `OdometryCheck` (above), and the odometry
# model for a robot that turns on the spot while its odometry point creeps a
# few millimetres sideways, which the textbook model reads as a 90° turn, a
# drive and a turn back (the appendix measures it on the Freiburg log).
#
# ## Replay a run, scan by scan
#
# The widget replays the Intel run (without the data, a simulated one) one
# scan at a time. Left: the map and the particle cloud after that scan's
# update. Middle: a close-up around the estimate, with the scan drawn from the
# **estimate** (blue dots: on the walls when the estimate is right), the
# estimate coloured by the state and the corrected pose (black cross). Right:
# the error over the run, the state behind it. Slide to the first scans to
# watch the search, then to where the state changes. (The HTML book shows scan
# 3 below the widget, while the filter is still searching.)

# %% tags=["nbval-ignore-output"]
replay = intel if have_intel else None      # None: the widget's own simulated run
reallog_widget(replay, scan=3)

# %%
fig = reallog_figure(3) if replay is None else reallog_figure(3, replay)
assert fig.state == "searching"
fig

# %% [markdown]
# ## Your robot: ROS bags in, AMCL settings in, standard trajectories out
#
# Your own robot records ROS bags, its map was saved by `map_server`, and it
# runs AMCL with a parameter file. `localize` reads all three without a ROS
# installation (`pip install -e ".[ros]"` adds the pure-Python
# [rosbags](https://ternaris.gitlab.io/rosbags/) package) and writes what the
# evaluation tools read.
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
#    Topics are found by type (name them with `--scan-topic` / `--odom-topic`
#    when there are several), the laser's mounting on `/tf_static` (or
#    `--laser-pose X Y YAW`), and each scan gets the odometry interpolated at
#    its own time stamp, as AMCL asks tf.
# 4. **Evaluate** with [evo](https://github.com/MichaelGrupp/evo):
#    `evo_ape tum reference.tum trajectory.tum --plot` on the files of
#    `out/office/`; `localization_bag/` holds `/amcl_pose` and the particle
#    cloud to replay in RViz or Foxglove.
#
# We try it on the simulated log of this chapter, written as a ROS 2 MCAP bag
# with rosbags' own writer, the laser's 25 cm offset on `/tf_static`.

# %%
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
# prints what it made of each parameter and warns about those it ignores;
# `localize run --help` lists the whole mapping, and the appendix has it as a
# table. Options written on the command line win over the file.

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
# **Where the public logs live**, and their licences: see the appendix.
#
# ## Tuning the models from your robot's data
#
# The defaults are starting points. Three groups of numbers should come from
# your own robot, measured on a log with **reference poses** (a corrected SLAM
# log, motion capture, or a few spots measured by tape):
#
# * **The motion alphas** (chapter 4). Turn both the odometry and the reference
#   poses of every step into $(\delta_\text{rot1}, \delta_\text{trans},
#   \delta_\text{rot2})$; the differences are samples of the motion noise, whose
#   *variances* are linear in the alphas, so least squares on the squared
#   differences gives the alphas. Do it at the rate at which your filter
#   integrates odometry (chapter 4: the alphas depend on the step length).
# * **`sigma_hit`** (chapter 5). From the reference poses, the distances of the
#   scan's end points to the nearest wall are the hit errors; their robust
#   spread is `sigma_hit` (for the beam model, chapter 5's EM fit). It measures
#   the map as much as the laser.
# * **Tempering.** One unmapped cupboard spoils a run of neighbouring beams.
#   With a correlation $\rho$ of neighbouring beams' residuals, $B$ beams carry
#   about as much information as $B(1-\rho)/(1+\rho)$ independent ones: temper
#   by that factor (`localize.widgets.tuning.suggest_temper`), then check that
#   the cloud's spread matches its actual error on the log.
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
# steps. The cross terms $\alpha_2$ and $\alpha_4$ add only a few percent to
# the variances here, too little to separate: a tuning log should mix turns on
# the spot, straight drives and arcs, so that each term dominates somewhere.
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
# Here only the unmapped boxes spoil runs of neighbours, so the correlation is
# weak. Against a real map it is far stronger — a wall drawn 5 cm off biases
# every beam that hits it — which is why the command line tempers harder (0.3).
#
# ### Try it: tempering and `sigma_hit`
#
# The widget scores one cluttered scan of 72 beams with either model. Left: the
# weight one scan gives to positions around the true pose (heading held at the
# truth). Right: the effective sample size of particles spread around the
# truth, against the tempering factor; the dot is your setting. At
# $\gamma = 0.1$ the 72 beams count as seven. A small `sigma_hit` sharpens the
# weight as a large tempering factor does. (The HTML book shows the default
# setting below the widget.)

# %% tags=["nbval-ignore-output"]
from localize.widgets.tuning import tuning_figure, tuning_widget  # noqa: E402

tuning_widget()

# %%
fig = tuning_figure(temper=0.1, sigma_hit=0.2)
print(f"ESS at gamma = 0.1: {fig.ess:.0f}; untempered: {tuning_figure(temper=1.0).ess:.0f}")
assert tuning_figure(temper=1.0).ess < 0.1 * fig.ess
fig

# %% [markdown]
# ## Summary
#
# * Read the format's definition, then *plot* what you read: a scan over its map
#   shows inverted probabilities, mirrored axes, wrong units, reversed beams and
#   a forgotten laser offset at a glance.
# * Convert once, at the border (`localize.io`): metres, radians, occupancy
#   probabilities; bad input is an error with a file and a line.
# * Real maps and scans disagree by 0.1 m or more: choose `sigma_hit` for the map,
#   not for the laser, and temper the likelihood.
# * With known poses, a map is a sum of log-odds (occupancy grid mapping).
# * `localize run` reads the files, builds the map if asked, and runs the loop of
#   chapter 7 with a few policies a real log needs: corrupt odometry is refused,
#   a standing robot's scans are not reused, beams the map cannot explain are
#   left out once the cloud agrees.
# * A filter must say when it does not know — searching, localized or lost —
#   from its own evidence, never from ground truth.
# * Each default prevents one measured failure; the appendix has the numbers.

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
# **3 (experiment).** On the first 30 scans of the simulated log of this chapter
# (`log.select(slice(0, 30))`), run global
# localization (`pipeline.localize_log`, seeds 0 to 3) with `temper=1` and with the
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
first = log.select(slice(0, 30))
for particles in (1000, "auto"):
    for temper in (1.0, 0.3):
        steps = []
        for seed in range(4):
            res = pipeline.localize_log(grid, first, n_particles=particles, rng=np.random.default_rng(seed), temper=temper)
            steps.append(pipeline.converged_at(np.hypot(*(res.estimates[:, :2] - run.poses[:30, :2]).T), 0.5))
        converged[particles, temper] = sum(s is not None for s in steps)
        print(f"{particles!s:>5} particles, temper {temper:3}: converged in {converged[particles, temper]} of 4 seeds")
print("'auto' is", pipeline.resolve_particles("auto", grid), "particles on this map")
assert all(converged[1000, t] <= 2 for t in (1.0, 0.3))     # "at most half of the seeds", either way
assert converged["auto", 1.0] == converged["auto", 0.3] == 4

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# In this small office the number of particles decides, not the tempering:
# with 1,000 particles the filter converges in at most half of the seeds,
# tempered or not. A seed that fails has no particle near the truth after the first
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
#
# </details>

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

