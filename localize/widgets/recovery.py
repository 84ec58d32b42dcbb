"""Recovering from a kidnapping: random injection and augmented MCL's two averages.

:func:`kidnap_figure` is the callback: it tracks a simulated robot in the
office with MCL, kidnaps it (carries it elsewhere without telling the
filter) and draws the position error and the share of particles that were
replaced by random ones at each step. Its parameters are the repairs of the
chapter on MCL failures: a fixed injection rate, and augmented MCL's
``alpha_slow``, ``alpha_fast`` and ``temperature`` (PR table 8.3,
:class:`localize.mcl.Augmented`). :func:`kidnap_widget` wires sliders to it.

What to look for: with augmented MCL the injection jumps after the
kidnapping; with a fast ``alpha_fast`` and ``temperature = 1`` it also fires
in bursts while the filter is localized, since the likelihood of a whole
scan varies from step to step; a slower ``alpha_fast`` or a temperature of
the order of the number of beams calms it, at the price of a slower reaction.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from . import figure_output, slider, with_hint

__all__ = ["kidnap_trial", "kidnap_summary", "kidnap_figure", "kidnap_widget", "DEMOS", "DEMO_VARIANTS"]

KIDNAP_AT = 12
N_STEPS = 36
N_BEAMS = 36
#: The robot (seed) of the chapter's figure and the widget's first setting: one whose default filter recovers and
#: whose variants show what chapter 8 says of them (of seeds 0-11 with the simulated laser's no-return readings,
#: the default filter recovers within the 24 steps after the kidnapping in 8, 10 and 11).
ROBOT = 8


@lru_cache(maxsize=8)
def kidnap_trial(alpha_slow: float = 0.1, alpha_fast: float = 0.5, temperature: float = 1.0,
                 injection: float = 0.0, augmented: bool = True, n_particles: int = 1000, seed: int = ROBOT):
    """Track, kidnap at step 12 and (perhaps) recover; returns ``(run, trace)``.

    The robot starts well localized (a Gaussian cloud around the truth) in
    the office, scans with 36 beams scored by the tempered likelihood field,
    and is carried elsewhere at step 12 of 36. Results are cached (the same
    parameters redraw at once); treat them as read-only.

    Examples
    --------
    >>> run, trace = kidnap_trial(n_particles=200, seed=1)
    >>> len(trace), int(trace.n_injected[:3].sum()) >= 0
    (36, True)
    """
    from ..mcl import MCL, Augmented, OdometryMotion
    from ..runloop import run_mcl
    from ..sim import range_run

    if int(n_particles) < 50:
        raise ValueError(f"n_particles must be >= 50; got {n_particles}")
    if not 0.0 <= float(injection) < 1.0:
        raise ValueError(f"injection must lie in [0, 1); got {injection}")
    if augmented and not 0.0 < float(alpha_slow) < float(alpha_fast) <= 1.0:
        raise ValueError(f"augmented MCL needs 0 < alpha_slow < alpha_fast <= 1; got alpha_slow={alpha_slow}, "
                         f"alpha_fast={alpha_fast}")
    if not float(temperature) >= 1.0:
        raise ValueError(f"temperature must be >= 1; got {temperature}")
    grid, model = _world()
    angles = np.linspace(-np.pi, np.pi, N_BEAMS, endpoint=False)
    run = range_run(grid, np.random.default_rng(seed), n_steps=N_STEPS, angles=angles, max_range=8.0,
                    kidnap_at=[KIDNAP_AT])
    opts = {}
    if injection > 0:
        opts["injection"] = float(injection)
    if augmented:
        opts["augmented"] = Augmented(float(alpha_slow), float(alpha_fast), temperature=float(temperature))
    f = MCL.gaussian(run.poses[0], (0.2, 0.2, 0.1), int(n_particles), OdometryMotion(run.alphas, min_std=0.01),
                     model, rng=np.random.default_rng(100 + seed), grid=grid, **opts)
    return run, run_mcl(f, run)


@lru_cache(maxsize=1)
def _world():
    """The office and its tempered likelihood field, built once."""
    from ..maps import office
    from ..sensors import LikelihoodField

    grid = office()
    return grid, LikelihoodField(grid, 8.0, sigma_hit=0.2, temper=0.1)


def kidnap_summary(run, trace, localized_within: float = 0.5) -> dict:
    """Numbers for the title: recovery step, and how much was injected while localized.

    Returns a dict with ``recovered`` (steps after the kidnapping until the
    error stays below ``localized_within``, or None), ``injected_after``
    (the largest share injected in the three steps after the kidnapping) and
    ``injected_localized`` (mean share injected at the steps, before or after
    the kidnapping, when the filter was within ``localized_within`` of the truth).

    Examples
    --------
    >>> s = kidnap_summary(*kidnap_trial(n_particles=200, seed=1))
    >>> sorted(s)
    ['injected_after', 'injected_localized', 'recovered']
    """
    from ..metrics import position_error

    e = position_error(trace.poses, run.poses)
    share = trace.n_injected / trace.n_particles
    after = e[KIDNAP_AT:]
    bad = np.flatnonzero(after >= localized_within)
    if bad.size and bad[-1] == after.size - 1:
        recovered = None
    else:
        recovered = int(bad[-1]) + 1 if bad.size else 0
    ok = e < localized_within
    ok[KIDNAP_AT:KIDNAP_AT + 1] = False
    return {"recovered": recovered, "injected_after": float(share[KIDNAP_AT:KIDNAP_AT + 3].max()),
            "injected_localized": float(share[ok].mean()) if ok.any() else float("nan")}


def kidnap_figure(alpha_slow: float = 0.1, alpha_fast: float = 0.5, temperature: float = 1.0,
                  injection: float = 0.0, augmented: bool = True, n_particles: int = 1000, seed: int = ROBOT,
                  figsize=(9.5, 4.6)):
    """The callback: error (top) and share of particles injected (bottom) around a kidnapping.

    Returns a matplotlib Figure; its ``summary`` attribute holds
    :func:`kidnap_summary`.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> fig = kidnap_figure(n_particles=200, seed=1)
    >>> len(fig.axes), sorted(fig.summary)[0]
    (2, 'injected_after')
    >>> plt.close(fig)
    """
    from matplotlib.figure import Figure

    from ..metrics import position_error

    run, trace = kidnap_trial(float(alpha_slow), float(alpha_fast), float(temperature), float(injection),
                              bool(augmented), int(n_particles), int(seed))
    s = kidnap_summary(run, trace)
    e = position_error(trace.poses, run.poses)
    share = trace.n_injected / trace.n_particles
    steps = np.arange(len(e))
    fig = Figure(figsize=figsize)
    ax, ax2 = fig.subplots(2, 1, sharex=True)
    ax.semilogy(steps, np.maximum(e, 1e-2), color="tab:green", lw=1.8)
    ax.axvline(KIDNAP_AT, color="k", ls=":", lw=1)
    ax.axhline(0.5, color="0.6", lw=0.8)
    ax.set_ylim(1e-2, 40)
    ax.set_ylabel("position error [m]")
    ax.grid(True, alpha=0.3)
    rec = "never (still lost at the end)" if s["recovered"] is None else f"{s['recovered']} steps after"
    ax.set_title(f"kidnapped at step {KIDNAP_AT} (dotted); recovered: {rec}", fontsize=9)
    ax2.bar(steps, share, color="tab:orange", width=0.8, label="share of particles injected")
    if augmented:
        ax2.plot(steps, trace.p_inject, color="k", lw=1, label="1 − w_fast / w_slow")
    ax2.axvline(KIDNAP_AT, color="k", ls=":", lw=1)
    ax2.set_ylim(0, 1.02)
    ax2.set_xlim(-0.5, len(e) - 0.5)
    ax2.set_xlabel("step")
    ax2.set_ylabel("injected")
    ax2.legend(loc="upper right", fontsize=8)
    ax2.grid(True, alpha=0.3)
    ax2.set_title(f"injected while localized: {s['injected_localized']:.0%} of the particles per step on average",
                  fontsize=9)
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.11, top=0.93, hspace=0.35)
    fig.summary = s
    return fig


def kidnap_widget(**defaults):
    """Sliders for the injection rate and augmented MCL's ``alpha_slow``, ``alpha_fast`` and temperature.

    Examples
    --------
    >>> wid = kidnap_widget(n_particles=200)
    >>> [c.description for c in wid.children[:3]]
    ['augmented MCL', 'alpha_slow', 'alpha_fast']
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    import ipywidgets as W

    p = dict(alpha_slow=0.1, alpha_fast=0.5, temperature=1.0, injection=0.0, augmented=True, n_particles=1000,
             seed=ROBOT)
    p.update(defaults)
    controls = dict(
        augmented=W.Checkbox(value=p["augmented"], description="augmented MCL"),
        alpha_slow=slider(p["alpha_slow"], -2.5, -0.3, 0.1, "alpha_slow", fmt=".3f", log=True),
        alpha_fast=slider(p["alpha_fast"], 0.05, 1.0, 0.05, "alpha_fast"),
        temperature=slider(p["temperature"], 0, 1.6, 0.2, "temperature", fmt=".1f", log=True),
        injection=slider(p["injection"], 0.0, 0.2, 0.01, "fixed injection"),
        n_particles=W.Dropdown(options=sorted({300, 1000, 3000, int(p["n_particles"])}), value=int(p["n_particles"]),
                               description="particles"),
        seed=W.IntSlider(value=p["seed"], min=0, max=9, description="robot (seed)", continuous_update=False),
    )

    def show(**v):
        try:
            fig = kidnap_figure(**v)
        except ValueError as err:                  # e.g. alpha_slow >= alpha_fast: say so instead of a traceback
            print("not a valid setting:", err)
            return None
        return fig

    out = figure_output(show, controls)
    c = controls
    return with_hint(W.VBox([c["augmented"], c["alpha_slow"], c["alpha_fast"],
                             W.HBox([c["temperature"], c["injection"]]), W.HBox([c["n_particles"], c["seed"]]), out]))


#: Zero-argument demos returning the widget's default figure (see tests/test_widgets_common.py).
DEMOS = {"kidnap": lambda: kidnap_figure()}
#: Other settings whose figures must differ from the default.
DEMO_VARIANTS = {"kidnap": [lambda: kidnap_figure(alpha_fast=0.2), lambda: kidnap_figure(temperature=36.0),
                            lambda: kidnap_figure(augmented=False, injection=0.05)]}
