"""A recorded run, scan by scan: the particle cloud, the scan over the map at the estimate, and the state.

Chapter 9 runs the command line's filter (:func:`localize.pipeline.localize_log`,
the library behind ``localize run``) on a real log. :func:`log_run` does the
same run and keeps the particles of every scan; :func:`reallog_figure` is the
callback: left, the map with the cloud after the scan's update, the scan's
end points drawn from the *estimate* (they fall on the walls when the
estimate is right) and the reference pose when the log has one; right, the
error against the reference (or the cloud's spread) over the whole run,
shaded by the filter's state (*searching*, *localized*, *lost*: see
:class:`localize.policies.StateRules`), with the chosen scan marked.
:func:`reallog_widget` puts a slider over the scans. :func:`demo_run` is a
simulated log in the office that needs no data, for the tests and the demos.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import interactive_app, slider

__all__ = ["LogRun", "log_run", "demo_run", "reallog_figure", "reallog_widget", "DEMOS", "DEMO_VARIANTS"]

#: Colours of the filter's states (as in :func:`localize.plot.report.report_figure`).
STATE_COLORS = {"searching": "tab:orange", "localized": "tab:green", "lost": "tab:red"}


@dataclass(frozen=True)
class LogRun:
    """A run kept for replay: the map, the log as the filter read it (beams thinned), and its trace.

    ``trace`` is a :class:`localize.runloop.RunTrace` whose ``snapshots`` hold
    the particles of every scan; ``reference`` the log's reference poses (or None).
    """

    grid: Any
    log: Any
    trace: Any
    reference: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.trace)


def log_run(grid: Any, log: Any, *, seed: int = 0, snapshot_particles: int = 500, **changes: Any) -> LogRun:
    """Run :func:`localize.pipeline.localize_log` (the defaults of ``localize run``, ``changes`` by keyword)
    with seed ``seed``, keeping ``snapshot_particles`` particles of every scan.

    The estimates are those of ``localize run --seed SEED`` with the same settings.

    Examples
    --------
    >>> r = demo_run()
    >>> len(r), len(r.trace.snapshots) == len(r), r.log.n_beams
    (80, True, 30)
    """
    from ..pipeline import localize_log, settings_with

    res = localize_log(grid, log, rng=np.random.default_rng(int(seed)), snapshot_every=1,
                       snapshot_particles=int(snapshot_particles), **changes)
    beams = settings_with(None, **changes).beams
    shown = log.select_beams(count=beams) if beams is not None and beams < log.n_beams else log
    ref = None if log.poses is None else np.asarray(log.poses, dtype=float)
    return LogRun(grid=grid, log=shown, trace=res.trace, reference=ref)


@lru_cache(maxsize=1)
def demo_run() -> LogRun:
    """A global localization on a simulated 80-scan log in the office (laser 25 cm ahead), 3,000 particles.

    Examples
    --------
    >>> r = demo_run()
    >>> str(r.trace.state[0]), str(r.trace.state[-1]), r.trace.first_localized()
    ('searching', 'localized', 23)
    """
    from ..maps import office
    from ..sim import range_run

    run = range_run(office(0.1), np.random.default_rng(909), n_steps=80, dt=0.5, speed=0.4,
                    sensor_offset=(0.25, 0.0, 0.0), max_range=12.0, n_clutter=4)
    log = run.to_log()
    return log_run(run.grid, log, seed=0, particles=3000)


def _spans(state: NDArray) -> list[tuple[int, int, str]]:
    """Runs of equal state: ``(first, last, state)``."""
    cuts = np.flatnonzero(state[1:] != state[:-1]) + 1
    starts = np.r_[0, cuts]
    ends = np.r_[cuts - 1, len(state) - 1]
    return [(int(a), int(b), str(state[a])) for a, b in zip(starts, ends)]


def _scan_panel(ax: Any, run: LogRun, k: int, zoom: float | None = None) -> None:
    """The map, the cloud of scan ``k``, the scan drawn at the estimate; ``zoom``: half-width (m) around it."""
    from ..geometry import compose
    from ..plot import draw_map, draw_robot

    tr, log = run.trace, run.log
    draw_map(run.grid, ax=ax)
    parts, w = tr.snapshots[k]
    ax.scatter(parts[:, 0], parts[:, 1], s=5 if zoom is None else 12, color="tab:purple", alpha=0.5, linewidths=0,
               label=f"particles ({int(tr.n_particles[k]):,}, {len(parts)} drawn)", zorder=2)
    est = tr.poses[k]
    r = np.asarray(log.ranges[k], dtype=float)
    hit = r < log.max_range
    laser = compose(est, log.sensor_offset)
    ends = laser[:2] + r[hit, None] * np.column_stack([np.cos(laser[2] + log.angles[hit]),
                                                       np.sin(laser[2] + log.angles[hit])])
    ax.plot(ends[:, 0], ends[:, 1], ".", color="tab:blue", ms=4 if zoom is None else 7,
            label="scan drawn at the estimate", zorder=4)
    draw_robot(est, ax=ax, radius=0.3, color=STATE_COLORS.get(str(tr.state[k]), "k"))
    if run.reference is not None and np.all(np.isfinite(run.reference[k])):
        ax.plot(*run.reference[k, :2], "k+", ms=12, mew=2, label="reference pose", zorder=5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    if zoom is not None:
        ax.set_xlim(est[0] - zoom, est[0] + zoom)
        ax.set_ylim(est[1] - zoom, est[1] + zoom)
    else:
        x0, x1, y0, y1 = run.grid.extent
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_ylabel("y (m)")
        ax.legend(loc="lower left", fontsize=7, framealpha=0.85)


def _time_panel(ax: Any, run: LogRun, k: int) -> float | None:
    from matplotlib.patches import Patch

    tr = run.trace
    steps = np.arange(len(tr))
    err = None
    if run.reference is not None:
        e = np.hypot(*(tr.poses[:, :2] - run.reference[:, :2]).T)
        ax.semilogy(steps, np.maximum(e, 1e-3), color="k", lw=1.0, label="error against the reference (m)")
        err = float(e[k])
    else:
        ax.semilogy(steps, np.maximum(tr.spread, 1e-3), color="k", lw=1.0, label="spread of the best cluster (m)")
    for a, b, name in _spans(np.asarray(tr.state)):
        ax.axvspan(a - 0.5, b + 0.5, color=STATE_COLORS.get(name, "0.8"), alpha=0.2, lw=0)
    ax.axvline(k, color="tab:blue", lw=1.5)
    handles = ax.get_legend_handles_labels()[0] + [Patch(color=c, alpha=0.35, label=n)
                                                   for n, c in STATE_COLORS.items()]
    ax.legend(handles=handles, loc="upper right", fontsize=7)
    ax.set_xlim(-0.5, len(tr) - 0.5)
    ax.set_xlabel("scan")
    ax.grid(True, which="both", alpha=0.3)
    return err


def reallog_figure(scan: int = 0, run: LogRun | None = None, zoom: float = 4.0,
                   figsize: tuple[float, float] = (15, 4.8)):
    """The callback: scan ``scan`` of ``run`` (default :func:`demo_run`) over the map, around the estimate
    (``zoom`` metres each way), and the state over the run.

    Returns a Figure whose ``state`` attribute is the filter's state at that scan
    and ``error`` its position error against the reference (None without one).

    Examples
    --------
    >>> fig = reallog_figure(0)
    >>> fig.state, fig.error > 0.5
    ('searching', True)
    >>> reallog_figure(79).state
    'localized'
    >>> reallog_figure(80)
    Traceback (most recent call last):
    ...
    ValueError: scan must be a whole number in [0, 79] (the run has 80 scans); got 80
    """
    from matplotlib.figure import Figure

    run = demo_run() if run is None else run
    n = len(run)
    if isinstance(scan, bool) or not isinstance(scan, (int, np.integer)) or not 0 <= scan < n:
        raise ValueError(f"scan must be a whole number in [0, {n - 1}] (the run has {n} scans); got {scan!r}")
    k = int(scan)
    if k not in run.trace.snapshots:
        raise ValueError(f"the run kept no particles of scan {k}: make it with log_run (snapshots of every scan)")
    if not float(zoom) > 0:
        raise ValueError(f"zoom must be a positive number of metres; got {zoom!r}")
    fig = Figure(figsize=figsize)
    ax, ax_zoom, ax2 = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1.0, 0.8, 1.0]})
    _scan_panel(ax, run, k)
    _scan_panel(ax_zoom, run, k, zoom=float(zoom))
    ax_zoom.set_title(f"around the estimate (±{float(zoom):g} m): the scan\nlies on the walls if the estimate is "
                      "right", fontsize=9)
    err = _time_panel(ax2, run, k)
    state = str(run.trace.state[k])
    fit = run.trace.fit[k]
    words = [f"scan {k} of {n}: {state.upper()}"]
    if err is not None:
        words.append(f"error {err:.2f} m")
    words.append(f"spread {run.trace.spread[k]:.2f} m")
    if np.isfinite(fit):
        words.append(f"fit {fit:.0%}")
    if not run.trace.updated[k]:
        words.append("scan not used (robot did not move enough)")
    fig.suptitle(", ".join(words), fontsize=11)
    ax.set_title("the map and the particle cloud", fontsize=9)
    ax2.set_title("the whole run: error and state (blue line: this scan)", fontsize=9)
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.11, top=0.84, wspace=0.22)
    fig.state = state
    fig.error = err
    return fig


def reallog_widget(run: LogRun | None = None, scan: int = 0, zoom: float = 4.0):
    """A slider over the scans of ``run`` (default :func:`demo_run`); see :func:`reallog_figure`.

    Examples
    --------
    >>> wid = reallog_widget()
    >>> [c.description for c in wid.children[:2]], wid.children[0].max
    (['scan', 'zoom [m]'], 79)
    >>> import matplotlib.pyplot as plt; plt.close("all")
    """
    import ipywidgets as W

    run = demo_run() if run is None else run
    return interactive_app(
        reallog_figure,
        scan=W.IntSlider(value=int(scan), min=0, max=len(run) - 1, step=1, description="scan",
                         continuous_update=False),
        run=W.fixed(run),
        zoom=slider(float(zoom), 1.0, 10.0, 0.5, "zoom [m]", fmt=".1f"),
        figsize=W.fixed((15, 4.8)),
    )


#: Zero-argument demos returning the widget's default figure (see tests/test_widgets_common.py).
DEMOS = {"reallog": lambda: reallog_figure()}
#: Other settings whose figures must differ from the default.
DEMO_VARIANTS = {"reallog": [lambda: reallog_figure(40), lambda: reallog_figure(79), lambda: reallog_figure(zoom=8.0)]}
