"""Tuning the sensor model: tempering and ``sigma_hit`` on a cluttered scan.

The real logs of the book are not shipped with it, so the widget uses a
stand-in with the same troubles: a scan of 72 beams simulated in the office
*with unmapped clutter* (boxes the map does not know, as people and
furniture in a real building), scored against the plain map.

:func:`tuning_figure` is the callback. Left: the weight the sensor model gives
to positions around the true pose (heading fixed at the truth), i.e. how
sharply one scan would localize the robot. Right: the effective sample size
of a cloud of particles around the truth as a function of the tempering
factor, for the chosen ``sigma_hit``; the dot is the current setting.
:func:`tuning_widget` wires sliders to it. :func:`residual_correlation` and
:func:`suggest_temper` implement the rule of thumb of the chapter on real logs:
temper a scan of ``B`` beams down to its effective number of independent beams.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from . import interactive_app, slider

__all__ = ["cluttered_scans", "sensor_model", "residual_correlation", "suggest_temper", "tuning_figure",
           "tuning_widget", "DEMOS", "DEMO_VARIANTS"]

N_BEAMS = 72
MAX_RANGE = 8.0


@lru_cache(maxsize=2)
def cluttered_scans(seed: int = 7, n_scans: int = 10):
    """A short run in the office with 8 unmapped boxes: ``(run, angles)``; the scans see the boxes, the map does not.

    Examples
    --------
    >>> run, angles = cluttered_scans()
    >>> run.ranges.shape, angles.shape
    ((10, 72), (72,))
    """
    from ..maps import office
    from ..sim import range_run

    angles = np.linspace(-np.pi, np.pi, N_BEAMS, endpoint=False)
    run = range_run(office(), np.random.default_rng(seed), n_steps=int(n_scans), angles=angles, max_range=MAX_RANGE,
                    n_clutter=8)
    return run, angles


@lru_cache(maxsize=16)
def sensor_model(kind: str = "likelihood_field", sigma_hit: float = 0.2):
    """The untempered sensor model scored on the plain office map (temper the log-likelihood yourself).

    Examples
    --------
    >>> type(sensor_model("beam", 0.2)).__name__
    'BeamModel'
    """
    from ..sensors import BeamModel, LikelihoodField

    run, _ = cluttered_scans()
    if not 0.01 <= float(sigma_hit) <= 2.0:
        raise ValueError(f"sigma_hit must lie in [0.01, 2] metres; got {sigma_hit}")
    if kind == "likelihood_field":
        return LikelihoodField(run.grid, MAX_RANGE, sigma_hit=float(sigma_hit))
    if kind == "beam":
        return BeamModel(run.grid, MAX_RANGE, sigma_hit=float(sigma_hit), method="lut")
    raise ValueError(f"kind must be 'likelihood_field' or 'beam'; got {kind!r}")


def residual_correlation(residuals: ArrayLike) -> float:
    """Lag-1 correlation of beam residuals around the scan, averaged over scans (rows).

    ``residuals[s, b]`` is measured minus expected range of beam ``b`` in scan
    ``s`` at a known pose (NaN for beams to leave out, e.g. max-range readings).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> white = rng.normal(size=(20, 100))
    >>> round(residual_correlation(white), 1)
    0.0
    >>> smooth = white + np.roll(white, 1, axis=1)       # neighbours share half their error
    >>> round(residual_correlation(smooth), 1)
    0.5
    """
    r = np.atleast_2d(np.asarray(residuals, dtype=float))
    a, b = r, np.roll(r, -1, axis=1)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        raise ValueError("residual_correlation needs at least 3 pairs of finite neighbouring residuals")
    a, b = a[ok], b[ok]
    a, b = a - a.mean(), b - b.mean()
    return float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))


def suggest_temper(rho: float) -> float:
    """Tempering factor ``(1 - rho) / (1 + rho)`` for beams whose errors have lag-1 correlation ``rho``.

    For errors that are correlated like a first-order autoregressive process
    along the scan, ``B`` beams carry about as much information as
    ``B (1 - rho) / (1 + rho)`` independent ones; tempering by this factor
    counts the scan that many times instead of ``B``. A starting point, to be
    checked against logs with ground truth.

    Examples
    --------
    >>> suggest_temper(0.0), round(suggest_temper(0.8), 3)
    (1.0, 0.111)
    """
    rho = float(rho)
    if not -1.0 < rho < 1.0:
        raise ValueError(f"rho must lie in (-1, 1); got {rho}")
    return float(min(1.0, (1.0 - max(rho, 0.0)) / (1.0 + max(rho, 0.0))))


def _ess(logw: np.ndarray) -> float:
    w = np.exp(logw - logw.max())
    w /= w.sum()
    return float(1.0 / np.sum(w * w))


@lru_cache(maxsize=16)
def _cloud_loglik(kind: str, sigma_hit: float):
    run, angles = cluttered_scans()
    truth = run.poses[0]
    cloud = truth + np.random.default_rng(1).normal(0.0, [0.3, 0.3, 0.1], size=(2000, 3))
    cloud = cloud[run.grid.is_free(cloud)]
    return sensor_model(kind, sigma_hit).log_likelihood(cloud, run.ranges[0], angles)


@lru_cache(maxsize=16)
def _surface(kind: str, sigma_hit: float):
    run, angles = cluttered_scans()
    truth = run.poses[0]
    xs = truth[0] + np.linspace(-1.0, 1.0, 41)
    ys = truth[1] + np.linspace(-1.0, 1.0, 41)
    X, Y = np.meshgrid(xs, ys)
    poses = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, truth[2])])
    ll = np.full(X.size, -np.inf)
    free = run.grid.is_free(poses)
    ll[free] = sensor_model(kind, sigma_hit).log_likelihood(poses[free], run.ranges[0], angles)
    return xs, ys, ll.reshape(X.shape)


def tuning_figure(temper: float = 0.1, sigma_hit: float = 0.2, kind: str = "likelihood_field", figsize=(11, 4)):
    """The callback: weight around the true pose (left) and the cloud's ESS against tempering (right).

    Returns a Figure whose ``ess`` attribute is the ESS at the current setting.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> fig = tuning_figure()
    >>> 1 <= fig.ess <= 2000
    True
    >>> plt.close(fig)
    """
    from matplotlib.figure import Figure

    from ..plot import draw_map

    temper = float(temper)
    if not 0.0 < temper <= 1.0:
        raise ValueError(f"temper must lie in (0, 1]; got {temper}")
    run, angles = cluttered_scans()
    truth = run.poses[0]
    xs, ys, ll = _surface(kind, float(sigma_hit))
    w = np.exp(temper * (ll - np.max(ll)))
    cloud_ll = _cloud_loglik(kind, float(sigma_hit))
    temps = np.geomspace(0.005, 1.0, 40)
    ess_curve = np.array([_ess(t * cloud_ll) for t in temps])
    ess_now = _ess(temper * cloud_ll)
    fig = Figure(figsize=figsize)
    ax, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.1, 1]})
    draw_map(run.world, ax=ax, alpha=0.35)
    draw_map(run.grid, ax=ax, alpha=0.6)
    ax.imshow(np.ma.masked_less(w, 1e-3), origin="lower", cmap="viridis", vmin=0, vmax=1, alpha=0.85,
              extent=(xs[0], xs[-1], ys[0], ys[-1]))
    ends = truth[:2] + run.ranges[0][:, None] * np.column_stack([np.cos(truth[2] + angles), np.sin(truth[2] + angles)])
    hit = run.ranges[0] < MAX_RANGE
    ax.plot(ends[hit, 0], ends[hit, 1], ".", color="tab:orange", ms=3, label="scan end points")
    ax.plot(*truth[:2], "r+", ms=12, mew=2, label="true pose")
    ax.set_xlim(truth[0] - 4, truth[0] + 4)
    ax.set_ylim(truth[1] - 3, truth[1] + 3)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=7)
    sd = np.sqrt(np.sum(w * ((xs[None, :] - truth[0]) ** 2 + (ys[:, None] - truth[1]) ** 2)) / np.sum(w))
    ax.set_title(f"weight around the truth (heading fixed): spread {sd:.2f} m\n"
                 "light grey: clutter the map does not know", fontsize=9)
    ax2.semilogx(temps, ess_curve, color="tab:blue")
    ax2.plot([temper], [ess_now], "o", color="tab:red", ms=8)
    ax2.set_xlim(temps[0], 1.0)
    ax2.set_ylim(0, cloud_ll.size * 1.05)
    ax2.set_xlabel("tempering factor γ")
    ax2.set_ylabel(f"ESS of {cloud_ll.size} particles")
    ax2.grid(True, alpha=0.3)
    ax2.set_title(f"{kind.replace('_', ' ')}, sigma_hit {float(sigma_hit):.2f} m, γ = {temper:.3f}\n"
                  f"the {N_BEAMS} beams count as {temper * N_BEAMS:.1f}; ESS {ess_now:.0f}", fontsize=9)
    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.13, top=0.86, wspace=0.2)
    fig.ess = ess_now
    return fig


def tuning_widget(temper: float = 0.1, sigma_hit: float = 0.2, kind: str = "likelihood_field"):
    """Sliders for the tempering factor and ``sigma_hit``, and the model; see :func:`tuning_figure`.

    Examples
    --------
    >>> wid = tuning_widget()
    >>> [c.description for c in wid.children[:3]]
    ['tempering γ', 'sigma_hit [m]', 'model']
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    import ipywidgets as W

    return interactive_app(
        tuning_figure,
        temper=slider(float(temper), -2.3, 0, 0.1, "tempering γ", fmt=".3f", log=True),
        sigma_hit=slider(float(sigma_hit), 0.05, 0.5, 0.05, "sigma_hit [m]"),
        kind=W.ToggleButtons(options=["likelihood_field", "beam"], value=kind, description="model"),
        figsize=W.fixed((11, 4)),
    )


#: Zero-argument demos returning the widget's default figure (see tests/test_widgets_common.py).
DEMOS = {"tuning": lambda: tuning_figure()}
#: Other settings whose figures must differ from the default.
DEMO_VARIANTS = {"tuning": [lambda: tuning_figure(temper=1.0), lambda: tuning_figure(sigma_hit=0.1),
                            lambda: tuning_figure(kind="beam")]}
