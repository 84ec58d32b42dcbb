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
# # Preface: how to read this book
#
# A robot that does not know where it is cannot do much else. *Localization* is
# the problem of working out the robot's pose — its position and heading — from
# a map, from what its wheels report, and from what its sensors see. None of
# these is exact: wheels slip, lasers bounce off glass, maps go out of date. The
# answer is therefore not a single pose but a **belief**, a probability
# distribution over poses, and the tools of this book are the ways to keep that
# belief up to date.
#
# The path through the book:
#
# 1. **The Bayes filter** on a one-dimensional hallway: prediction and correction.
# 2. **Histogram localization**: the same filter on a grid of tiles, and why fine
#    grids get expensive.
# 3. **Grid localization in (x, y, θ)** with a range sensor.
# 4. **Motion models**: what odometry really tells us.
# 5. **Range sensors**: ray casting and measurement models.
# 6. **Particle filters**: beliefs made of samples, and resampling.
# 7. **Monte Carlo Localization** (MCL) on a map.
# 8. **When MCL fails**, and how to make it recover.
# 9. **Real logs**: reading robot data and maps, and a command-line localizer.
# 10. **MCL versus the EKF**: which filter to use, measured.
#
# Every chapter is a Jupyter notebook that imports the companion package
# `localize`. The package is also meant for your own work and homework: every
# function in it is documented, tested, and fast enough for real data.

# %% [markdown]
# ## Why not simply use GPS?
#
# Satellite navigation answers "where am I?" outdoors, so why a book on
# localization? A GPS receiver measures how long the signals of at least four
# satellites took to reach it and intersects the resulting spheres. Every
# nanosecond of timing error is 30 cm of range error, and the errors do not
# vanish: the satellites' orbits and clocks are known only approximately, the
# atmosphere slows the signals by an amount that changes with the weather, the
# receiver's cheap clock must be estimated along with the position, and near
# buildings the receiver often hears a reflection instead of the direct signal.
# A consumer receiver under open sky is therefore off by one to several metres —
# enough to put a robot in the wrong room or a car in the wrong lane. And
# indoors, where most of this book's robots live, it usually gives no usable fix
# at all: walls and ceilings weaken the signals, and what arrives is mostly
# reflections. A robot has to localize
# itself against what it can sense — its own wheels and the walls around it —
# and that is what the following chapters do.

# %% [markdown]
# ## Running the book
#
# From a clone of the repository, one command installs everything and opens the
# book in JupyterLab:
#
# ```bash
# python -m pip install -e ".[book]" && jupyter lab book/
# ```
#
# Run a chapter top to bottom with *Run → Run All Cells*. Cells that show
# sliders are interactive: move a slider and the figure below it redraws. In the
# static HTML version of the book the sliders cannot run; a fixed figure with the
# default settings is shown instead, and you need the notebook to play.
#
# The notebooks are *executable documents*: our test suite runs every one of them
# and compares each printed result with the one stored in the file, so the
# numbers you read are the numbers the code produces. Each notebook has a twin
# `.py` file (the same cells in plain text), which is what we review and edit.

# %%
import matplotlib.pyplot as plt
import numpy as np

import localize
from localize import geometry, maps
from localize.plot import draw_map, draw_poses, draw_robot

print("localize", localize.__version__)

# %% [markdown]
# ## Conventions
#
# These hold everywhere in the book and in `localize`; the docstrings repeat them
# where they matter.
#
# **Units.** Metres, seconds and radians (the SI units). Figures may label
# angles in degrees for readability; code never stores degrees.
#
# **Poses.** A pose is the triple $(x, y, \theta)$: position in metres and heading
# in radians, measured counter-clockwise from the $x$ axis. In code a pose is a
# NumPy array whose last axis has length 3. A set of $N$ poses — a particle
# cloud, say — is an `(N, 3)` array, never a list of objects, and every function
# works on whole arrays at once.
#
# **Angles** are kept in the half-open interval $[-\pi, \pi)$ with
# `localize.wrap_angle`. Forgetting to wrap is one of the classic bugs of
# localization code: an estimate of 359° and a truth of 1° are 2° apart, not 358°.

# %%
print(localize.wrap_angle(np.radians([359.0, 180.0, -180.0, 540.0])).round(4))
print("difference of 1° and 359°:", round(np.degrees(geometry.angle_diff(np.radians(1), np.radians(359))), 6), "degrees")

# %% [markdown]
# **Frames.** Three frames appear again and again:
#
# * the **map frame** (also called world frame), fixed to the building, in which
#   the map and the answer are expressed;
# * the **robot frame**, attached to the robot: $x$ points forward, $y$ to the left;
# * the **odometry frame**, in which the wheel encoders integrate the robot's
#   motion. It starts wherever the robot was switched on, so only *differences*
#   of odometry poses carry information.
#
# A pose $a$ in some frame and a pose $b$ expressed relative to $a$ combine into
# $a \oplus b$, the *composition* of poses (Smith, Self and Cheeseman 1990). Its
# inverse $\ominus a$ undoes $a$, and $\ominus a \oplus b$ is "$b$ seen from $a$" —
# exactly how two odometry readings turn into a motion of the robot.

# %%
a = np.array([2.0, 1.0, np.pi / 2])    # robot at (2, 1), facing +y
b = np.array([1.0, 0.0, 0.0])          # one metre straight ahead, in the robot's frame
print("a ⊕ b =", geometry.compose(a, b).round(6) + 0.0)   # + 0.0 turns a rounded -0.0 into 0.0
print("b seen from a again:", geometry.relative(a, geometry.compose(a, b)).round(6) + 0.0)

# %% [markdown]
# **Maps.** A map is a `localize.OccupancyGrid`: a 2-D array of occupancy
# probabilities plus a resolution (metres per cell) and an origin. The cell in
# row $i$ and column $j$ has its centre at
#
# $$x = x_0 + (j + \tfrac12)\,r, \qquad y = y_0 + (i + \tfrac12)\,r,$$
#
# so rows grow with $y$ and the array is drawn with `origin="lower"`. Unknown
# cells are `NaN`; a range sensor treats them as obstacles by default, since a map
# that does not know a cell cannot promise that a laser passes through it. Every
# loader in `localize.io` converts its file format to this one convention.
# A small map can be drawn as text, top row first:

# %%
tiny = localize.OccupancyGrid.from_ascii(
    """
########
#......#
#..##..#
#......?
########
""",
    resolution=0.5,
)
print(tiny)
print("row 0 (the bottom wall):", tiny.data[0])
print("cell of the point (1.3 m, 1.8 m):", tiny.world_to_cell([1.3, 1.8]))
print("centre of that cell:", tiny.cell_to_world([3, 2]))

# %% [markdown]
# Asking for a point outside the map is an error that says so, rather than an
# index that silently wraps round to the other side of the array:

# %%
try:
    tiny.world_to_cell([5.0, 1.0])
except ValueError as err:
    print("ValueError:", err)

# %% [markdown]
# **Randomness.** Every function that draws random numbers takes a
# `numpy.random.Generator` argument called `rng`. There is no hidden global seed:
# each notebook creates its own generator, so running it again gives the same
# numbers, and your experiments are reproducible.
#
# **Weights.** Particle filters multiply many small probabilities. We store the
# *logarithms* of particle weights and normalise them with the log-sum-exp trick,
# so a scan of 180 beams does not underflow to zero.
#
# ## Notation
#
# We follow *Probabilistic Robotics* (Thrun, Burgard and Fox, 2005), written PR
# below, and give its table numbers when we implement one of its algorithms.
#
# | symbol | meaning | in code |
# |---|---|---|
# | $x_t$ | the robot's pose at time $t$ | `pose`, `(3,)`; particles `(N, 3)` |
# | $u_t$ | control or odometry between $t-1$ and $t$ | `u` |
# | $z_t$ | measurement at time $t$ (a scan, a landmark sighting) | `z`, `ranges` |
# | $m$ | the map | `grid` |
# | $\mathrm{bel}(x_t)$ | belief after the measurement | `belief` |
# | $\overline{\mathrm{bel}}(x_t)$ | predicted belief, before the measurement | `predicted` |
# | $\eta$ | normaliser that makes a belief sum to one | `normalize` |
# | $\alpha_1, \dots, \alpha_6$ | motion-noise parameters (PR tables 5.3 and 5.6) | `alphas` |
#
# One difference from PR is worth stating early: PR writes the motion noise as
# variances such as $\alpha_1 \delta_{rot1}^2 + \alpha_2 \delta_{trans}^2$, and so
# do we; some course materials and reports use standard deviations, or absolute
# values instead of squares. The motion-model chapter shows what the difference
# does and how to reproduce each source.

# %% [markdown]
# ## A first picture
#
# Here is the office that most chapters use: 20 m by 12 m, rooms on both sides of
# a corridor, desks and a pillar. A robot stands in the corridor; the arrows show
# its own frame (red: forward, green: left). Around it, a cloud of 200 poses drawn
# uniformly over the free space — the belief of a robot that has just woken up
# and has no idea where it is. The rest of the book is about shrinking that cloud
# to the right place.

# %%
rng = np.random.default_rng(2026)
office = maps.office()
print(office)
assert np.allclose(office.extent[1] - office.extent[0], 20.0) and np.allclose(office.extent[3] - office.extent[2], 12.0)
fig, ax = plt.subplots(figsize=(8, 5))
draw_map(office, ax=ax)
draw_poses(office.sample_free(200, rng), ax=ax, length=0.4, color="tab:orange", alpha=0.7)
robot = np.array([10.0, 5.5, np.radians(20.0)])
draw_robot(robot, ax=ax, radius=0.35)
origin, ex, ey = geometry.transform_points(robot, [[0, 0], [1.2, 0], [0, 1.2]])
for tip, color in ((ex, "tab:red"), (ey, "tab:green")):
    ax.annotate("", xy=tip, xytext=origin, arrowprops=dict(arrowstyle="->", color=color, lw=2))
ax.set_title("The office map, a robot, and a belief that knows nothing yet")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Try it: move the robot
#
# The cell below shows sliders for the robot's pose. Move them and watch the
# robot's frame turn with it; the title tells you when the pose leaves free
# space. (In the HTML book this cell cannot run; the figure after it shows the
# default pose.)

# %% tags=["nbval-ignore-output"]
from localize.widgets.maps import robot_on_map, robot_on_map_figure  # noqa: E402

robot_on_map(office, x=10.0, y=5.5, theta_deg=20.0)

# %% [markdown]
# Without a running kernel the sliders cannot move, so here is what they show
# for another pose: the robot carried into the room at the bottom left, onto
# the desk, and turned to 135°. Its frame turns with it (forward now points
# up and to the left), and the title warns that the pose is not in free space.

# %%
fig = robot_on_map_figure(office, 4.8, 2.8, 135.0)
print(fig.axes[0].get_title())
plt.show()

# %% [markdown]
# ## Exercise: which cell is a point in?
#
# Write `world_to_cell(points, origin, resolution)`: for `(N, 2)` world points
# $(x, y)$ return the **integer** `(row, column)` of the cell that holds each, by
# the formula above (without calling `OccupancyGrid.world_to_cell`). Then run
# `localize.check.world_to_cell(world_to_cell)`: it prints PASS or FAIL for each
# property it tests, with a hint that names the usual mistake behind a failure
# (rows and columns swapped, `round` instead of `floor`, the origin forgotten).
# The code exercises of the chapters come with such self-checks, and the
# homework notebook (`book/homework/homework.ipynb`) collects them.

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
def world_to_cell(points, origin, resolution):
    """(row, column) of the cell holding each (x, y) point."""
    rel = (np.asarray(points, dtype=float) - np.asarray(origin, dtype=float)) / resolution
    return np.floor(rel[:, ::-1]).astype(int)   # column from x, row from y


print(localize.check.world_to_cell(world_to_cell))
print("on the tiny map:", world_to_cell([[1.3, 1.8]], tiny.origin, tiny.resolution)[0],
      "=", tiny.world_to_cell([1.3, 1.8]))

# %% [markdown]
# ## References
#
# * S. Thrun, W. Burgard, D. Fox. *Probabilistic Robotics*. MIT Press, 2005.
# * R. Smith, M. Self, P. Cheeseman. Estimating uncertain spatial relationships
#   in robotics. In *Autonomous Robot Vehicles*, Springer, 1990.
# * K. V. Mardia, P. E. Jupp. *Directional Statistics*. Wiley, 2000 (circular
#   means and spreads of headings).
