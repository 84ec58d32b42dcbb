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
# # The Bayes filter
#
# Every localizer in this book, from a grid of a few cells to a particle filter
# on a real building, is the same algorithm: the **Bayes filter**. This chapter
# builds it on the smallest world that still shows everything, a hallway of
# twenty cells with three doors, and writes each step as one line of numpy.
#
# You will learn
#
# * what a **belief** is and why we keep a whole distribution instead of one guess;
# * the **correction** step (Bayes rule) that folds in a measurement;
# * the **prediction** step (total probability) that folds in a motion, and why on
#   a grid it is a *convolution*;
# * why we divide by a sum at the end of each step (**normalisation**);
# * the **Markov assumption** that makes the filter cheap, and what breaks when it
#   does not hold;
# * what happens in a bounded world and with a wrong sensor model.

# %%
import matplotlib.pyplot as plt
import numpy as np
from filterpy import discrete_bayes

import localize
from localize import discrete
from localize.maps import hallway
from localize.plot.histogram import draw_bars

print("localize", localize.__version__)

# %% [markdown]
# ## A robot in a hallway
#
# The robot drives along a corridor split into 20 cells. Its only sensor tells
# whether it faces a **door** or a **wall**. The map says where the doors are:
# cells 2, 5 and 13. This is the example with which *Probabilistic Robotics*
# (Thrun, Burgard and Fox 2005, "PR" below; figure 1.1 and section 2.4.2) opens.
#
# The robot does not know where it is. We describe what it *does* know by a
# **belief**: a number `bel[x]` for each cell `x`, the probability that the robot
# is in cell `x`. The numbers are non-negative and sum to one. Knowing nothing
# means every cell is equally likely: the uniform belief.

# %%
world = hallway(20, doors=(2, 5, 13))
belief = discrete.uniform(len(world))
print("doors at cells", np.flatnonzero(world).tolist())
print("uniform belief: every cell holds", round(float(belief[0]), 4))

fig, ax = plt.subplots(figsize=(7, 2.2))
draw_bars(belief, ax, world=world, title="the uniform belief (door cells shaded)")
plt.show()

# %% [markdown]
# ## Correction: Bayes rule
#
# The robot reads **door**. How should the belief change? Bayes rule says
#
# $$ \mathrm{bel}(x) \;=\; \eta \; p(z \mid x)\; \overline{\mathrm{bel}}(x), $$
#
# where $\overline{\mathrm{bel}}(x)$ is the belief before the reading,
# $p(z \mid x)$ is the **measurement model** — how likely the reading $z$ would be
# if the robot were at $x$ — and $\eta$ is whatever number makes the result sum
# to one. Our sensor is right three times out of four:
# $p(\text{door} \mid \text{door cell}) = 0.75$ and
# $p(\text{door} \mid \text{wall cell}) = 0.25$.
#
# Read the formula cell by cell: a cell where the reading is expected is
# multiplied by 0.75, a cell where it is surprising by 0.25. Then we divide by the
# total. The list of $p(z \mid x)$ over all cells is called the **likelihood**;
# note that it does *not* have to sum to one (it is a function of the position,
# not a distribution over positions).

# %%
likelihood = np.where(world == 1, 0.75, 0.25)
unnormalised = likelihood * belief
print("sum before normalising:", round(float(unnormalised.sum()), 4))
belief = discrete.update(belief, likelihood)
print("after reading 'door': door cells", round(float(belief[2]), 4), " wall cells", round(float(belief[0]), 4))
assert np.isclose(unnormalised.sum(), 0.325)

# %% [markdown]
# The number we divided by, $p(z) = \sum_x p(z\mid x)\,\overline{\mathrm{bel}}(x) = 0.325$,
# is the probability of reading "door" at all under our current belief. It is
# the **normaliser** $1/\eta$. Division by it is what keeps the belief a
# probability distribution; forgetting it is the most common bug in a first
# histogram filter.
#
# One reading leaves three equally likely doors. Reading "door" again from the
# same place would only sharpen those three peaks: the robot must **move**.

# %% [markdown]
# ## Prediction: total probability, and a convolution
#
# The robot drives one cell to the right. Its wheels are imperfect: with
# probability 0.8 it moves one cell, with 0.1 it stays (undershoot), with 0.1 it
# moves two (overshoot). Where can it be now? It is at $x$ if it was at $x'$ and
# moved from $x'$ to $x$, summed over all $x'$ (the law of total probability,
# PR equation 2.12):
#
# $$ \overline{\mathrm{bel}}(x) \;=\; \sum_{x'} p(x \mid u, x')\; \mathrm{bel}(x'). $$
#
# Because the motion noise is the same everywhere, $p(x \mid u, x')$ depends only
# on the displacement $x - x'$. The sum is then a **convolution** of the belief
# with the noise **kernel** `[0.1, 0.8, 0.1]`, after a shift by the commanded
# one cell. The kernel reads from short to long: its middle entry is the
# commanded move, its **first** entry the undershoot (one cell short, here
# staying put) and its **last** entry the overshoot (one cell too far). This
# kernel is symmetric, so the order does not show; a lopsided one such as
# `[0.1, 0.6, 0.3]` (overshoots three times as often as it undershoots) must
# be written in this order, and `discrete.predict` shifts the extra mass to
# the right. `discrete.predict(belief, kernel, offset)` does exactly this;
# `discrete.predict_readable` does it with two loops, the way the sum reads, and
# the tests check that both agree.

# %%
kernel = np.array([0.1, 0.8, 0.1])
predicted = discrete.predict(belief, kernel, offset=1)
print("fast   :", predicted.round(3)[:8])
print("loops  :", discrete.predict_readable(belief, kernel, offset=1).round(3)[:8])
print("still sums to", round(float(predicted.sum()), 6))
assert round(float(belief[2]), 3) == 0.115 and round(float(predicted[3]), 3) == 0.100   # the peak's drop, in the text below

fig, axes = plt.subplots(2, 1, figsize=(7, 3.8), sharex=True)
draw_bars(belief, axes[0], world=world, title="after reading 'door'")
draw_bars(predicted, axes[1], world=world, color="tab:gray", title="after moving one cell right: shifted and blurred")
fig.tight_layout()
plt.show()

# %% [markdown]
# Prediction moved the three peaks one cell right and made them lower and wider:
# moving **loses** information, sensing **gains** it. Each peak's height drops
# from 0.115 to 0.100: 20 % of its mass spread to the neighbours, and only a
# little came back from the lower wall cells beside it.

# %% [markdown]
# ## The whole filter
#
# Alternate the two steps and you have the Bayes filter (PR table 2.1):
#
# ```
# for each time step t:
#     bel_bar(x) = sum_x' p(x | u_t, x') bel(x')      # prediction
#     bel(x)     = eta * p(z_t | x) * bel_bar(x)       # correction
# ```
#
# We let the robot start in cell 0 and drive right one cell per step, reading
# door or wall at each stop, with a better sensor than before (right 9 times in
# 10: likelihoods 0.9 and 0.1). In this run the sensor happens to be right every
# time; the robot reads what the map says at its true cell.

# %%
belief = discrete.uniform(len(world))
truth = 0
history = []
for t in range(15):
    if t > 0:
        belief = discrete.predict(belief, kernel, offset=1)
        truth += 1
    z = world[truth]
    belief = discrete.update(belief, np.where(world == z, 0.9, 0.1))
    history.append((truth, z, belief))
    print(f"t={t}: at cell {truth:2d}, reads {'door' if z else 'wall'};"
          f" most likely cell {int(belief.argmax()):2d} with p = {belief.max():.3f}")

print("t=2: belief at the three doors", {int(d): round(float(history[2][2][d]), 3) for d in (2, 5, 13)})

fig, axes = plt.subplots(4, 1, figsize=(7, 7), sharex=True)
for ax, t in zip(axes, [0, 2, 5, 14]):
    tr, z, b = history[t]
    draw_bars(b, ax, world=world, truth=tr, ylim=0.8,
              title=f"t = {t}: read {'door' if z else 'wall'} (red triangle = true cell)")
fig.tight_layout()
plt.show()

# %% [markdown]
# After the first door ($t = 2$) the three doors are the likely places, but
# not equally likely: doors 2 and 13 hold 0.230 each, door 5 only 0.194
# (printed above the figure). A robot now at door 5 that undershot or
# overshot once would have stood on door 2 when it read "wall", a reading a
# door gives only one time in ten; the walls before doors 2 and 13 leave no
# such doubt. After the
# second ($t = 5$) the gap between the doors, two walls, has ruled out most of
# them, and by $t = 14$, past the third door, one place in the hallway explains
# everything the robot has seen: the belief has a single tall peak at the true
# cell. That is localization. (The peak never reaches 1: the motion noise keeps
# blurring it, and the neighbours look alike.)

# %% [markdown]
# ## The same numbers as filterpy
#
# `filterpy.discrete_bayes` (Labbe, *Kalman and Bayesian Filters in Python*,
# chapter 2) implements the same two steps. Run on the same problem, the two
# libraries agree to the last bit that matters; the test suite checks this on
# every commit (`tests/test_discrete.py`).

# %%
ours = discrete.uniform(len(world))
theirs = np.full(len(world), 1 / len(world))
truth = 0
for t in range(8):
    if t > 0:
        ours = discrete.predict(ours, kernel, offset=1)
        theirs = discrete_bayes.predict(theirs, 1, kernel)
        truth += 1
    lik = np.where(world == world[truth], 0.75, 0.25)
    ours = discrete.update(ours, lik)
    theirs = discrete_bayes.update(lik, theirs)
print("largest difference:", f"{np.abs(ours - theirs).max():.1e}")
assert np.allclose(ours, theirs, atol=1e-12)

# %% [markdown]
# ## The Markov assumption
#
# Why may the filter forget everything but the current belief? The correction
# step multiplies by $p(z_t \mid x_t)$, which assumes that, **once we know where
# the robot is**, the reading does not depend on earlier readings or motions; the
# prediction step assumes the same of the motion. Together this is the **Markov
# assumption** (PR section 2.4.4): the state $x_t$ summarises the past. Without
# it the belief would have to depend on the whole history
# $z_{1:t}, u_{1:t}$, and the work per step would grow with $t$.
#
# The assumption is wrong in small ways all the time — a person standing in front
# of a door makes several readings wrong *together*; an error in the map makes
# the same reading wrong every time the robot passes — and the filter then
# counts the same evidence twice and becomes overconfident. We will see its
# consequences again with real laser data, where neighbouring beams are far from
# independent.
#
# A small demonstration: suppose the robot stands still and reads "door" five
# times, but the five readings are really one reading repeated (say, the same
# camera frame processed five times). Treating them as independent multiplies
# the likelihood five times:

# %%
b1 = discrete.update(discrete.uniform(len(world)), np.where(world == 1, 0.75, 0.25))
b5 = discrete.uniform(len(world))
for _ in range(5):
    b5 = discrete.update(b5, np.where(world == 1, 0.75, 0.25))
print(f"P(at some door) after one reading: {b1[world == 1].sum():.3f}; "
      f"after the same reading counted 5 times: {b5[world == 1].sum():.3f}")
assert round(b5[world == 1].sum(), 2) == 0.98 and round(b1[world == 1].sum(), 2) == 0.35

# %% [markdown]
# The evidence did not change, yet the filter is nearly certain the robot is at
# a door: 98 % instead of 35 %. If that one reading was wrong, the filter will
# need many correct readings to climb back.

# %% [markdown]
# ## Cyclic versus bounded worlds
#
# `predict` wraps around by default (`mode="wrap"`): belief that leaves the right
# end enters on the left, as in a circular corridor — which is what
# `filterpy` does too, and convenient for exercises. A real hallway has ends. With
# `mode="constant"`, belief pushed beyond the end is **lost**, and the cells at
# the start receive `cval` (the belief we assume outside the map; 0 by default).
# The result then sums to less than one and we normalise it: the robot must be
# somewhere in the hallway.

# %%
b = np.zeros(20)
b[17:] = [0.2, 0.3, 0.5]
for mode in ["wrap", "constant"]:
    moved = discrete.predict(b, kernel, offset=2, mode=mode)
    print(f"{mode:8s}: cells 0-2 {moved[:3].round(3)}, cells 17-19 {moved[17:].round(3)}, "
          f"sum {moved.sum():.3f}")
assert np.allclose(moved[18:], [0.2 * 0.1, 0.2 * 0.8 + 0.3 * 0.1]) and round(1 - moved.sum(), 2) == 0.79

# %% [markdown]
# In the wrapped world most of the belief re-appeared at the start of the
# hallway. In the bounded one only the moves that end inside the hallway are
# left: cell 17's intended move of two cells (0.2 x 0.8 = 0.16) and the
# undershoots of cells 17 and 18 (0.02 and 0.03), so cell 19 holds 0.19 and
# cell 18 holds 0.02; the other 79 % of the mass fell off. In a bounded world the motion model should say what
# the robot does at a wall (it stops). Our `predict` treats the edge as a drop;
# an exercise asks you to model the stop.

# %% [markdown]
# ## A wrong sensor model
#
# The filter is only as good as its models. Suppose the sensor is really right
# 75 % of the time, but we *believe* it is perfect: `p_hit = 1`, `p_miss = 0`. A
# single wrong reading then gives zero likelihood to the true cell, and zero
# times anything stays zero: the filter can never return. Worse, if the wrong
# reading is also impossible everywhere else, there is nothing left at all.
# `localize` then raises `ZeroLikelihoodError` instead of silently producing
# `0/0 = NaN`.

# %%
def run_with_model(readings, p_hit, p_miss):
    """Filter the readings of a robot that starts in cell 0 and moves right; return the final belief."""
    b = discrete.uniform(20)
    for t, z in enumerate(readings):
        if t > 0:
            b = discrete.predict(b, kernel, offset=1)
        b = discrete.update(b, np.where(world == z, p_hit, p_miss))
    return b


rng = np.random.default_rng(1)
n_runs, n_steps = 300, 15
runs = []
for _ in range(n_runs):
    cells = [0]
    for t in range(1, n_steps):                    # the real robot moves with the kernel's noise
        cells.append((cells[-1] + rng.choice([0, 1, 2], p=kernel)) % 20)
    cells = np.array(cells)
    right = rng.random(n_steps) < 0.75             # the real sensor: right 75 % of the time
    runs.append((cells[-1], np.where(right, world[cells], 1 - world[cells])))

outcome = {}
for p_hit, p_miss in [(0.75, 0.25), (0.99, 0.01), (1.0, 0.0)]:
    correct, claimed, crashed = [], [], 0
    for last_cell, readings in runs:
        try:
            b = run_with_model(readings, p_hit, p_miss)
            correct.append(b.argmax() == last_cell)
            claimed.append(b.max())
        except discrete.ZeroLikelihoodError:
            crashed += 1
    print(f"model p_hit={p_hit:4.2f}: most likely cell is right in {np.mean(correct):4.0%} of runs, "
          f"the filter claims {np.mean(claimed):4.0%}; ZeroLikelihoodError in {crashed / n_runs:4.0%}")
    outcome[p_hit] = (np.mean(correct), np.mean(claimed), crashed / n_runs)

try:
    run_with_model(runs[0][1], 1.0, 0.0)
except discrete.ZeroLikelihoodError as err:
    print("for example:", str(err)[:74], "...")
# the claims of the text below
se = np.sqrt(outcome[0.75][0] * (1 - outcome[0.75][0]) / n_runs)    # sampling error of the hit rate
assert round(100 * se, 1) == 2.4 and abs(outcome[0.75][0] - outcome[0.75][1]) < 2 * se   # calibrated
assert outcome[0.99][1] > 2 * outcome[0.99][0] and abs(outcome[0.99][0] - outcome[0.75][0]) < 3 * se
assert outcome[1.0][2] > 0.5                             # "fails in most runs"

# %% [markdown]
# Over 300 simulated runs of 15 readings, the filter with the honest model
# (0.75) is **calibrated**: the probability it gives its best guess is about how
# often that guess is right (the gap is within twice the sampling error
# of 300 runs, 2.4 points). The overconfident model (0.99) picks the right cell about
# as often, but claims more than twice the certainty it delivers: a planner
# that trusts it will take risks it should not. The "perfect" model fails in
# most runs: a single reading that disagrees with the map wherever the belief
# still lives leaves nothing to normalise.
# A good rule of thumb: **never let a likelihood be exactly zero**, and when in
# doubt, make the sensor model a little *less* sure than your calibration says.

# %% [markdown]
# ## Try it
#
# Move the sliders: the sensor's accuracy, the motion noise and the number of
# sense/move cycles. The grey line is the prediction (before the reading), the
# bars the correction. Watch how a poor sensor needs more cycles, and how
# heavy motion noise flattens the prediction between readings. (In the HTML book
# the figure below the widget shows the default setting.)

# %% tags=["nbval-ignore-output"]
from localize.widgets.histogram import hallway_app, hallway_figure  # noqa: E402

hallway_app()

# %%
fig = hallway_figure(p_hit=0.75, motion_noise=0.2, n_steps=6)
plt.show()

# %% [markdown]
# ## Summary
#
# * A **belief** is a probability distribution over where the robot is.
# * **Correction**: multiply by the likelihood $p(z\mid x)$, then normalise.
# * **Prediction**: sum over where the robot came from; on a grid with the same
#   noise everywhere, a shift and a convolution.
# * The **Markov assumption** lets the filter keep only the current belief;
#   evidence counted twice makes it overconfident.
# * Never let a likelihood be exactly zero; `localize` reports it if it happens.

# %% [markdown]
# ## Exercises
#
# 1. **By hand.** A 5-cell cyclic hallway has doors at cells 0 and 3. The belief
#    is uniform, the sensor reads "door" with $p(\text{door}\mid\text{door}) = 0.8$
#    and $p(\text{door}\mid\text{wall}) = 0.1$. (a) Compute the belief after one
#    reading of "door". (b) The robot moves one cell right with kernel
#    `[0.1, 0.8, 0.1]`; compute the prediction.
# 2. **Implementation.** Write `predict_stop(belief, kernel, offset)` for a
#    bounded hallway where a robot that would run past an end **stops at the end
#    cell** instead of falling off. Check that it conserves mass, then test it
#    with `localize.check.predict_stop(predict_stop)`: it tries both ends, a
#    lopsided kernel and the classic slips (a hallway that wraps, mass that is
#    lost or renormalised, shifting before blurring).
# 3. **Experiment.** A robot starts in cell 0 and moves right one cell per
#    cycle; its sensor is right 75 % of the time and the filter knows it. Over
#    200 runs, how much belief lies within one cell of the true cell after
#    5, 10 and 15 cycles, on average? How does this change for a sensor that is
#    right 90 % of the time?

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 1
w5 = np.array([1, 0, 0, 1, 0])
b = discrete.update(discrete.uniform(5), np.where(w5 == 1, 0.8, 0.1))
print("(a)", b.round(4))     # doors 0.8*0.2 / (2*0.16 + 3*0.02) = 0.421, walls 0.053
print("(b)", discrete.predict(b, [0.1, 0.8, 0.1], offset=1).round(4))

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# By hand: after the reading the unnormalised values are $0.8 \cdot 0.2 = 0.16$
# at the two doors and $0.1 \cdot 0.2 = 0.02$ at the three walls, total $0.38$;
# so doors hold $0.421$ and walls $0.053$. For the prediction, list where each
# cell's mass can come from. Cell 1, for example, is reached from cell 0 moving
# one cell (0.8), from cell 1 staying (0.1) and from cell 4 overshooting by two
# across the wrap (0.1): $0.8 \cdot 0.421 + 0.1 \cdot 0.053 + 0.1 \cdot 0.053 = 0.347$.
#
# </details>

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 2: stopping at the ends of a bounded hallway
def predict_stop(belief, kernel, offset):
    belief = discrete.as_belief(belief)
    n, c = len(belief), len(kernel) // 2
    out = np.zeros(n)
    for src in range(n):
        for m, p in enumerate(kernel):
            out[min(max(src + offset + m - c, 0), n - 1)] += belief[src] * p
    return out


b = np.zeros(20)
b[17:] = [0.2, 0.3, 0.5]
moved = predict_stop(b, kernel, 2)
print(moved[15:].round(3), "sum", round(float(moved.sum()), 6))
print(localize.check.predict_stop(predict_stop))

# %% jupyter={"outputs_hidden": true, "source_hidden": true} tags=["solution", "hide-cell"]
# Solution (click to show)
# Exercise 3: belief near the truth after t cycles, averaged over 200 runs
def belief_near_truth(p_sensor, rng, checkpoints=(5, 10, 15)):
    b, out = discrete.uniform(20), []
    for t in range(max(checkpoints)):
        if t > 0:
            b = discrete.predict(b, kernel, offset=1)
        z = world[t] if rng.random() < p_sensor else 1 - world[t]
        b = discrete.update(b, np.where(world == z, p_sensor, 1 - p_sensor))
        if t + 1 in checkpoints:
            out.append(b[max(t - 1, 0):t + 2].sum())
    return out


rng = np.random.default_rng(7)
for p in [0.75, 0.9]:
    mean = np.mean([belief_near_truth(p, rng) for _ in range(200)], axis=0)
    print(f"sensor right {p:.2f}: belief within one cell after 5/10/15 cycles: {mean.round(2)}")

# %% [markdown] tags=["solution"]
# <details>
# <summary><b>Solution</b> (click to show)</summary>
#
# The better sensor concentrates the belief faster and further. Notice that
# neither reaches certainty even after 15 cycles: the motion noise blurs the
# belief at every step, and in this hallway long stretches of wall look alike.
#
# </details>

# %% [markdown]
# ## References
#
# * S. Thrun, W. Burgard, D. Fox. *Probabilistic Robotics*. MIT Press, 2005:
#   chapter 2 (the Bayes filter, table 2.1; the Markov assumption, section 2.4.4)
#   and table 4.1 (the discrete Bayes filter).
# * D. Fox, W. Burgard, S. Thrun. Markov localization for mobile robots in
#   dynamic environments. *Journal of Artificial Intelligence Research* 11, 1999.
# * R. Labbe. *Kalman and Bayesian Filters in Python*, chapter 2 "Discrete
#   Bayes Filter", 2015–2020 (and its library `filterpy`).
