"""Play and step through a Monte Carlo Localization run.

:func:`simulate` runs one global-localization experiment in the office world
(a simulated robot, the odometry model, a likelihood-field or beam sensor
model) and returns the run and the filter's trace with a snapshot at every
step. :func:`mcl_run_figure` is the drawing callback (a run, a trace and a
step in, a figure out), and :func:`mcl_player` wires sliders for the number of
particles, the resampler, the resampling threshold and the noise parameters,
plus a play button, to it. Runs are cached inside one player, keyed by their
parameters, so that stepping through time only redraws.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..maps import office
from ..mcl import MCL, OdometryMotion
from ..metrics import heading_error, position_error
from ..plot import draw_map, draw_robot
from ..plot.mcl import draw_particles
from ..runloop import run_mcl
from . import figure_output, with_hint

__all__ = ["simulate", "mcl_run_figure", "mcl_widget_figure", "mcl_player", "DEMOS", "DEMO_VARIANTS"]

RESAMPLER_NAMES = ("systematic", "stratified", "residual", "multinomial")


def simulate(
    n_particles: int = 5000,
    resampler: str = "systematic",
    threshold: float = 0.5,
    alpha_scale: float = 1.0,
    sigma_hit: float = 0.2,
    sensor: str = "likelihood_field",
    n_steps: int = 40,
    n_beams: int = 36,
    seed: int = 0,
    temper: float = 0.1,
):
    """Simulate a robot in the office and run MCL on it from a uniform prior.

    Parameters
    ----------
    n_particles : int
        Particles of the filter, >= 10.
    resampler : str
        One of ``systematic``, ``stratified``, ``residual``, ``multinomial``.
    threshold : float
        Resample when ``N_eff < threshold * N``, in [0, 1].
    alpha_scale : float
        The filter's odometry alphas are the simulator's true alphas times
        this factor (1 = correctly tuned; < 1 overconfident, > 1 cautious).
    sigma_hit : float
        Standard deviation (m) of the sensor model's hit component.
    sensor : {"likelihood_field", "beam"}
    n_steps, n_beams, seed : int
        Length of the run, beams per scan (spread all round), and the seed of
        everything random.
    temper : float
        The sensor model's tempering factor (see :class:`localize.sensors.BeamModel`).

    Returns
    -------
    run : localize.sim.RangeRun
    trace : localize.runloop.RunTrace
        With a snapshot ``(particles, weights)`` at every step.

    Examples
    --------
    >>> run, trace = simulate(n_particles=200, n_steps=3, n_beams=8)
    >>> len(trace), sorted(trace.snapshots)
    (3, [0, 1, 2])
    """
    from ..sensors import BeamModel, LikelihoodField
    from ..sim import range_run

    if int(n_particles) < 10:
        raise ValueError(f"n_particles must be >= 10; got {n_particles}")
    if resampler not in RESAMPLER_NAMES:
        raise ValueError(f"resampler must be one of {RESAMPLER_NAMES}; got {resampler!r}")
    if not alpha_scale > 0:
        raise ValueError(f"alpha_scale must be > 0; got {alpha_scale!r}")
    if not sigma_hit > 0:
        raise ValueError(f"sigma_hit must be > 0 metres; got {sigma_hit!r}")
    grid = office()
    rng = np.random.default_rng(seed)
    angles = np.linspace(-np.pi, np.pi, int(n_beams), endpoint=False)
    run = range_run(grid, rng, n_steps=int(n_steps), angles=angles, max_range=8.0)
    if sensor == "likelihood_field":
        model = LikelihoodField(grid, run.max_range, sigma_hit=sigma_hit, temper=temper)
    elif sensor == "beam":
        model = BeamModel(grid, run.max_range, sigma_hit=sigma_hit, method="lut", temper=temper)
    else:
        raise ValueError(f"sensor must be 'likelihood_field' or 'beam'; got {sensor!r}")
    motion = OdometryMotion(np.asarray(run.alphas) * alpha_scale, min_std=0.01)
    f = MCL.uniform(grid, int(n_particles), motion, model, rng=np.random.default_rng(seed + 1),
                    resampler=resampler, resample_threshold=threshold)
    trace = run_mcl(f, run, snapshot_steps=range(len(run)))
    return run, trace


def mcl_run_figure(run: Any, trace: Any, step: int, figsize=(10, 3.6)):
    """Draw the belief at ``step`` (left) and the position error so far (right).

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> run, trace = simulate(n_particles=100, n_steps=3, n_beams=8)
    >>> fig = mcl_run_figure(run, trace, 2)
    >>> fig.axes[0].get_title()[:7]
    'step 2:'
    >>> plt.close(fig)
    """
    import matplotlib.pyplot as plt

    step = int(step)
    if not 0 <= step < len(trace):
        raise ValueError(f"step must lie in [0, {len(trace) - 1}]; got {step}")
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=figsize, gridspec_kw={"width_ratios": [1.7, 1]})
    grid = run.grid
    draw_map(grid, ax=ax)
    p, w = trace.snapshots[step]
    draw_particles(p, ax=ax, weights=w, size=3)
    draw_robot(run.poses[step], ax=ax, radius=0.3, color="tab:blue")
    e = trace.poses[step]
    ax.plot([e[0]], [e[1]], marker="x", color="tab:green", markersize=10, mew=2.5, zorder=4)
    pe = position_error(trace.poses, run.poses[: len(trace)])
    he = heading_error(trace.poses, run.poses[: len(trace)])
    ax.set_title(f"step {step}: {len(p)} particles, N_eff = {trace.n_eff[step]:.0f}, "
                 f"error {pe[step]:.2f} m / {np.degrees(he[step]):.0f}°", fontsize=9)
    xmin, xmax, ymin, ymax = grid.extent
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax2.semilogy(np.arange(len(pe)), np.maximum(pe, 1e-3), color="0.6", lw=1)
    ax2.semilogy(np.arange(step + 1), np.maximum(pe[: step + 1], 1e-3), color="tab:red", lw=2)
    res = np.flatnonzero(trace.resampled[: step + 1])
    ax2.plot(res, np.full(res.shape, 1.5e-3), "|", color="k", label="resampled")
    ax2.set_ylim(1e-3, 30)
    ax2.set_xlabel("step")
    ax2.set_ylabel("position error [m]")
    ax2.legend(loc="upper right", fontsize=8)
    ax2.grid(True, alpha=0.3)
    # fixed margins: tight_layout on a log axis costs more than the rest of the redraw
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.13, top=0.9, wspace=0.25)
    return fig


def mcl_widget_figure(step: int = 20, cache: dict | None = None, **params: Any):
    """The widget's callback: simulate (or reuse a cached run) and draw ``step``.

    ``cache`` is a dict owned by one widget; runs are stored under their
    parameters so that moving the step slider only redraws.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> c = {}
    >>> fig = mcl_widget_figure(1, cache=c, n_particles=100, n_steps=2, n_beams=8)
    >>> len(c)
    1
    >>> plt.close(fig)
    """
    key = tuple(sorted(params.items()))
    if cache is not None and key in cache:
        run, trace = cache[key]
    else:
        run, trace = simulate(**params)
        if cache is not None:
            cache.clear()           # keep one run: they hold a snapshot per step
            cache[key] = (run, trace)
    return mcl_run_figure(run, trace, min(int(step), len(trace) - 1))


def mcl_player(n_steps: int = 40, **defaults: Any):
    """The interactive MCL player: parameter controls, a step slider and a play button.

    Returns the ipywidgets container (display it as the last line of a cell).

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> w = mcl_player(n_steps=3, n_particles=200)
    >>> type(w).__name__, len(w.children)
    ('VBox', 2)
    >>> plt.close("all")
    """
    import ipywidgets as W

    cache: dict = {}
    p = dict(n_particles=5000, resampler="systematic", threshold=0.5, alpha_scale=1.0, sigma_hit=0.2)
    p.update(defaults)
    n_particles = W.IntSlider(value=p["n_particles"], min=100, max=20_000, step=100, description="particles")
    resampler = W.Dropdown(options=RESAMPLER_NAMES, value=p["resampler"], description="resampler")
    threshold = W.FloatSlider(value=p["threshold"], min=0.0, max=1.0, step=0.05, description="N_eff/N <")
    alpha_scale = W.FloatLogSlider(value=p["alpha_scale"], base=10, min=-1, max=1, step=0.1,
                                   description="alpha ×")
    sigma_hit = W.FloatSlider(value=p["sigma_hit"], min=0.05, max=1.0, step=0.05, description="sigma_hit [m]")
    step = W.IntSlider(value=0, min=0, max=n_steps - 1, description="step")
    play = W.Play(value=0, min=0, max=n_steps - 1, interval=400, description="play")
    W.jslink((play, "value"), (step, "value"))

    def show(step, n_particles, resampler, threshold, alpha_scale, sigma_hit):
        return mcl_widget_figure(step, cache=cache, n_particles=n_particles, resampler=resampler,
                                 threshold=threshold, alpha_scale=alpha_scale, sigma_hit=sigma_hit, n_steps=n_steps)

    out = figure_output(show, dict(step=step, n_particles=n_particles, resampler=resampler, threshold=threshold,
                                   alpha_scale=alpha_scale, sigma_hit=sigma_hit))
    controls = W.VBox([W.HBox([play, step]), W.HBox([n_particles, resampler]),
                       W.HBox([threshold, alpha_scale, sigma_hit])])
    return with_hint(W.VBox([controls, out]))


def _demo(**kw):
    def f():
        kw.setdefault("n_particles", 2000)
        return mcl_widget_figure(11, n_steps=12, n_beams=18, **kw)

    return f


DEMOS = {"mcl_player": _demo()}
DEMO_VARIANTS = {"mcl_player": [_demo(n_particles=300), _demo(threshold=1.0), _demo(alpha_scale=3.0),
                                _demo(sigma_hit=0.5), _demo(resampler="multinomial")]}
