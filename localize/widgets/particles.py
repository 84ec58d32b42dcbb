"""Sliders for the chapter "Particle filters": a particle filter on the ring corridor.

:func:`sir_figure` is the pure callback (parameters -> matplotlib Figure,
seeded by its ``seed`` argument, no shared state); :func:`sir_app` wires
ipywidgets to it: number of particles, resampler, resampling threshold,
motion noise, number of steps and seed.
"""

from __future__ import annotations

import numpy as np

from ..resample import RESAMPLERS, SIRResult, bootstrap_filter
from ..sim import CorridorRun, corridor_run
from . import interactive_app

__all__ = ["sir_corridor", "sir_figure", "sir_app", "DEMOS", "DEMO_VARIANTS"]


def sir_corridor(n_particles: int = 300, resampler: str = "systematic", threshold: float = 0.5,
                 n_steps: int = 30, sigma_move: float = 0.2, seed: int = 0) -> tuple[CorridorRun, SIRResult]:
    """Simulate the ring corridor and run the bootstrap particle filter on it from a uniform prior.

    The robot's run is drawn from ``seed``; the filter's randomness from
    ``seed + 1``, so changing the filter's settings never changes the run.

    Returns
    -------
    run : localize.sim.CorridorRun
    result : localize.resample.SIRResult

    Examples
    --------
    >>> run, res = sir_corridor(n_particles=200, n_steps=25, seed=3)
    >>> est = run.ring_mean(res.particles, res.weights)
    >>> bool(run.ring_error(est)[-1] < 1.0)
    True
    """
    n_particles = int(n_particles)
    if n_particles < 1:
        raise ValueError(f"n_particles must be >= 1; got {n_particles}")
    if resampler not in RESAMPLERS:
        raise ValueError(f"resampler must be one of {', '.join(RESAMPLERS)}; got {resampler!r}")
    run = corridor_run(np.random.default_rng(seed), n_steps=int(n_steps), sigma_move=sigma_move)
    rng = np.random.default_rng(seed + 1)
    prior = rng.uniform(0.0, run.length, n_particles)
    steps = [(None if k == 0 else run.controls[k], run.z[k]) for k in range(len(run))]
    res = bootstrap_filter(prior, steps, run.move, run.log_likelihood, rng, resampler=resampler,
                           threshold=threshold)
    return run, res


def sir_figure(n_particles: int = 300, resampler: str = "systematic", threshold: float = 0.5,
               n_steps: int = 30, sigma_move: float = 0.2, seed: int = 0):
    """Three panels: the belief at three steps, the error over time, and N_eff over time.

    Examples
    --------
    >>> fig = sir_figure(n_particles=100, n_steps=10)
    >>> len(fig.axes)
    5
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..plot.particles import corridor_belief, ess_trace

    run, res = sir_corridor(n_particles, resampler, threshold, n_steps, sigma_move, seed)
    fig = Figure(figsize=(9, 5.6), dpi=80)
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(5, 2, height_ratios=[1, 1, 1, 0.25, 1.6])
    T = len(run)
    show = sorted({0, min(4, T - 1), T - 1})
    for r, k in enumerate(show):
        ax = fig.add_subplot(gs[r, :])
        corridor_belief(run, res.particles[k], res.weights[k], k, ax=ax)
        if r < len(show) - 1:
            ax.set_xticklabels([])
    fig.axes[-1].set_xlabel("position on the ring corridor [m]  (doors shaded, truth red)")
    est = run.ring_mean(res.particles, res.weights)
    err = run.ring_error(est)
    ax_e = fig.add_subplot(gs[4, 0])
    ax_e.plot(np.arange(T), err, color="tab:blue")
    ax_e.set_xlabel("step")
    ax_e.set_ylabel("error of the mean [m]")
    ax_e.set_ylim(0, run.length / 2)
    ax_n = fig.add_subplot(gs[4, 1])
    ess_trace(res.ess, int(n_particles), res.resampled, ax=ax_n, threshold=threshold)
    ax_n.set_title(f"{resampler}: resampled {int(res.resampled.sum())} of {T} steps", fontsize=9)
    fig.subplots_adjust(left=0.08, right=0.98, top=0.97, bottom=0.09, hspace=0.35, wspace=0.25)
    return fig


def sir_app():
    """Sliders (particles, resampler, threshold, motion noise, steps, seed) redrawing :func:`sir_figure`."""
    from ipywidgets import Dropdown, FloatSlider, IntSlider

    return interactive_app(
        sir_figure,
        n_particles=IntSlider(value=300, min=10, max=3000, step=10, description="particles",
                              continuous_update=False),
        resampler=Dropdown(options=list(RESAMPLERS), value="systematic", description="resampler"),
        threshold=FloatSlider(value=0.5, min=0.0, max=1.0, step=0.05, description="N_eff/N <",
                              continuous_update=False),
        n_steps=IntSlider(value=30, min=2, max=80, description="steps", continuous_update=False),
        sigma_move=FloatSlider(value=0.2, min=0.0, max=1.0, step=0.05, description="motion noise",
                               continuous_update=False),
        seed=IntSlider(value=0, min=0, max=30, description="seed", continuous_update=False),
    )


DEMOS = {"sir": lambda: sir_figure()}
DEMO_VARIANTS = {
    "sir": [
        lambda: sir_figure(n_particles=30),
        lambda: sir_figure(resampler="multinomial"),
        lambda: sir_figure(threshold=0.0),
        lambda: sir_figure(sigma_move=0.5),
    ]
}
