"""Noise sliders: where the EKF breaks and MCL does not, and where the EKF is as good.

:func:`noise_figure` is the callback (noise settings in, figure out): it runs
the EKF, the UKF and MCL on the same simulated landmark runs
(:func:`localize.compare.run_filters`, tracking scenario with the given
noise) and draws one run's beliefs at the last step next to the position
error of every run. :func:`noise_widget` wires sliders to it.

With landmarks that look alike (the default), turn up the heading noise and
thin out the sightings: the EKF and the UKF start to associate sightings with
the wrong landmarks and get lost, while MCL keeps up. Turn them down: all three agree to the
centimetre, and the EKF does it at a fraction of MCL's cost
(``benchmarks/bench_ekf.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..compare import FAIL_THRESHOLD, run_filters, scenario
from ..metrics import position_error
from ..plot import draw_poses
from ..plot.ekf import FILTER_COLORS, draw_gaussian_belief, draw_landmarks
from . import figure_output, with_hint

__all__ = ["noise_runs", "noise_figure", "noise_widget", "DEMOS", "DEMO_VARIANTS"]


def noise_runs(heading_noise: float = 1.0, sigma_bearing: float = 0.05, sense_every: int = 1,
               n_particles: int = 500, n_seeds: int = 4, n_steps: int = 40, seed: int = 0,
               anonymous: bool = False):
    """Run all three filters on ``n_seeds`` tracking runs with the given noise.

    Parameters
    ----------
    heading_noise : float
        Factor on the rotational noise of the motion (alphas 3 to 6 of the
        velocity model), > 0; 1 is the tracking scenario.
    sigma_bearing : float
        Bearing noise of the sensor, radians, > 0.
    sense_every : int
        Sightings every this many steps, >= 1.
    n_particles : int
        MCL's particles, >= 10.
    n_seeds, n_steps, seed : int
        Runs use seeds ``seed, seed + 1, ...``.
    anonymous : bool
        Landmarks look alike: the filters are not told which one they see
        (EKF/UKF associate by maximum likelihood, MCL sums over landmarks).

    Returns
    -------
    list of localize.compare.Run
        The last step of each is kept as a snapshot.

    Examples
    --------
    >>> runs = noise_runs(n_seeds=1, n_steps=12, n_particles=100)
    >>> len(runs), sorted(runs[0].estimates)
    (1, ['EKF', 'MCL', 'UKF'])
    """
    if not heading_noise > 0:
        raise ValueError(f"heading_noise must be a factor > 0; got {heading_noise!r}")
    if not sigma_bearing > 0:
        raise ValueError(f"sigma_bearing must be > 0 radians; got {sigma_bearing!r}")
    if int(n_particles) < 10:
        raise ValueError(f"n_particles must be >= 10; got {n_particles}")
    if int(n_seeds) < 1:
        raise ValueError(f"n_seeds must be >= 1; got {n_seeds}")
    base = scenario("tracking")
    alphas = base.alphas.copy()
    alphas[2:] *= float(heading_noise)
    sc = scenario("tracking", alphas=alphas, sigma_bearing=float(sigma_bearing), sense_every=int(sense_every),
                  n_particles=int(n_particles), n_steps=int(n_steps), known_ids=not anonymous,
                  mcl_inflation=1.5 if anonymous else 1.0)
    return [run_filters(sc, int(seed) + k, snapshot_steps=(sc.n_steps - 1,)) for k in range(int(n_seeds))]


def noise_figure(heading_noise: float = 1.0, sigma_bearing: float = 0.05, sense_every: int = 1,
                 n_particles: int = 500, n_seeds: int = 4, n_steps: int = 40, seed: int = 0,
                 anonymous: bool = True, runs: list | None = None, figsize=(11, 4.2)):
    """The widget's callback: beliefs of the first run (left), errors of all runs (right).

    Parameters are those of :func:`noise_runs` (here ``anonymous`` defaults to
    True); pass ``runs`` to draw precomputed runs instead.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> fig = noise_figure(n_seeds=1, n_steps=12, n_particles=100)
    >>> len(fig.axes)
    2
    >>> plt.close(fig)
    """
    import matplotlib.pyplot as plt

    if runs is None:
        runs = noise_runs(heading_noise, sigma_bearing, sense_every, n_particles, n_seeds, n_steps, seed,
                          anonymous)
    r0 = runs[0]
    sc = r0.scenario
    T = len(r0.truth)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=figsize, gridspec_kw={"width_ratios": [1, 1.25]})
    draw_landmarks(sc.landmarks, ax=ax, labels=False, s=90)
    ax.plot(r0.truth[:, 0], r0.truth[:, 1], color="k", lw=1.5, label="truth")
    for name in ("EKF", "UKF", "MCL"):
        e = r0.estimates[name]
        ax.plot(e[:, 0], e[:, 1], color=FILTER_COLORS[name], lw=1, alpha=0.8)
    snap = r0.snapshots[T - 1]
    ax.set_xlim(-8, 8)
    ax.set_ylim(-8, 8)
    draw_poses(snap["MCL"][:: max(1, len(snap["MCL"]) // 300)], ax=ax, color=FILTER_COLORS["MCL"], length=0.35,
               alpha=0.4)
    for name in ("EKF", "UKF"):
        m, P = snap[name]
        draw_gaussian_belief(m, P, ax=ax, color=FILTER_COLORS[name], length=1.2, label=f"{name} 2σ")
    ax.set_aspect("equal")
    ax.set_title(f"seed {r0.seed}, step {T - 1}: EKF/UKF ellipses, MCL particles", fontsize=9)
    ax.legend(loc="lower left", fontsize=7)

    t = np.arange(T)
    lines = []
    for name in ("EKF", "UKF", "MCL"):
        errs = np.array([position_error(r.estimates[name], r.truth) for r in runs])
        for e in errs:
            ax2.plot(t, np.maximum(e, 1e-3), color=FILTER_COLORS[name], lw=0.6, alpha=0.35)
        ax2.plot(t, np.maximum(np.median(errs, axis=0), 1e-3), color=FILTER_COLORS[name], lw=2.2, label=name)
        fails = int(np.sum(errs[:, -10:].mean(axis=1) >= FAIL_THRESHOLD))
        lines.append(f"{name}: RMSE {np.sqrt(np.mean(errs[:, T // 2:] ** 2)):.2f} m, lost {fails}/{len(runs)}")
    ax2.axhline(FAIL_THRESHOLD, color="gray", ls="--", lw=1)
    ax2.set_yscale("log")
    ax2.set_ylim(1e-2, 20)
    ax2.set_xlabel("step")
    ax2.set_ylabel("position error [m]")
    ax2.set_title("; ".join(lines), fontsize=8)
    ax2.legend(fontsize=7, loc="upper left")
    ids = "landmarks look alike" if not sc.known_ids else "landmarks identified"
    fig.suptitle(f"heading noise ×{heading_noise:g}, bearing σ {np.degrees(sc.sigma_bearing):.1f}°, "
                 f"sightings every {sc.sense_every} step(s), {sc.n_particles} particles, {ids}", fontsize=10)
    # fixed margins: tight_layout on log axes cost more than the filters themselves (2x the redraw time)
    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.12, top=0.84, wspace=0.22)
    return fig


def noise_widget(**defaults: Any):
    """Sliders for the heading noise, bearing noise, sighting rate and particle count.

    Returns the ipywidgets container (display it as the last line of a cell).
    """
    import ipywidgets as W

    # the widget's defaults keep a redraw under 100 ms (benchmarks/bench_widgets.py); the chapter's
    # static figures call noise_figure() with its larger defaults (4 seeds x 40 steps, 500 particles)
    p = dict(heading_noise=1.0, sigma_bearing=0.05, sense_every=1, n_particles=200, seed=0, anonymous=True,
             n_seeds=WIDGET_SEEDS, n_steps=WIDGET_STEPS)
    p.update(defaults)
    hn = W.FloatLogSlider(value=p["heading_noise"], base=10, min=-1, max=2, step=0.25, description="heading ×")
    sb = W.FloatSlider(value=p["sigma_bearing"], min=0.01, max=0.3, step=0.01, description="bearing σ")
    se = W.IntSlider(value=p["sense_every"], min=1, max=12, description="sight every")
    n = W.IntSlider(value=p["n_particles"], min=100, max=3000, step=100, description="particles")
    seed = W.IntSlider(value=p["seed"], min=0, max=20, description="seed")
    anon = W.Checkbox(value=p["anonymous"], description="landmarks look alike")

    def show(heading_noise, sigma_bearing, sense_every, n_particles, seed, anonymous):
        return noise_figure(heading_noise, sigma_bearing, sense_every, n_particles, n_seeds=p["n_seeds"],
                            n_steps=p["n_steps"], seed=seed, anonymous=anonymous)

    out = figure_output(show, dict(heading_noise=hn, sigma_bearing=sb, sense_every=se, n_particles=n,
                                          seed=seed, anonymous=anon))
    return with_hint(W.VBox([W.HBox([hn, sb, se]), W.HBox([n, seed, anon]), out]))


#: Seeds and steps per redraw of :func:`noise_widget` (small, so that a redraw stays under 100 ms).
WIDGET_SEEDS, WIDGET_STEPS = 2, 16


def _demo(**kw):
    def f():
        return noise_figure(n_seeds=WIDGET_SEEDS, n_steps=WIDGET_STEPS, n_particles=200, **kw)

    return f


DEMOS = {"noise_widget": _demo()}
DEMO_VARIANTS = {"noise_widget": [_demo(heading_noise=30.0, sense_every=6), _demo(sigma_bearing=0.2),
                                  _demo(anonymous=False)]}
