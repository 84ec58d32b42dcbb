"""The report picture of a run: where the filter put the robot, how sure it was, and how it did.

:func:`report_figure` draws two panels from a :class:`localize.runloop.RunTrace`:

* the map with the estimated trajectory coloured by the state (*searching*,
  *localized*, *lost*), the reference trajectory when one is known, the final
  particle cloud (when the trace holds a snapshot of the last step), start and
  end marked, and a legend;
* the error against the reference over the scans (when one is given), or the
  spread of the best cluster, on a log axis, with the state shaded behind it;
  with the probability state, ``p_localized`` and ``p_place`` on a second
  axis (0-1, right) with the two thresholds the state is read from.

``localize run`` writes it as ``report.png`` with every run.
"""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from numpy.typing import ArrayLike

from ..grid import OccupancyGrid
from ..reliability import LOCALIZED_AT, LOST_BELOW
from . import draw_map

__all__ = ["report_figure", "STATE_COLORS"]

#: Colour of each state in the report (trajectory points and the shading of the time panel).
STATE_COLORS = {"searching": "tab:orange", "localized": "tab:green", "lost": "tab:red"}


def _state_runs(state: np.ndarray) -> list[tuple[int, int, str]]:
    """``[(first, last, state), ...]``: the stretches of equal state."""
    out = []
    start = 0
    for k in range(1, len(state) + 1):
        if k == len(state) or state[k] != state[start]:
            out.append((start, k - 1, str(state[start])))
            start = k
    return out


def _draw_final_cloud(ax: Any, trace: Any, last: int, max_particles: int) -> None:
    """The particles of the last step's snapshot (at most ``max_particles``), labelled with how many the filter had."""
    if last not in getattr(trace, "snapshots", {}):
        return
    parts, w = trace.snapshots[last]
    sub = slice(None) if len(parts) <= max_particles else np.linspace(0, len(parts) - 1, max_particles).astype(int)
    n_all = getattr(trace, "n_particles", None)
    n_all = int(n_all[last]) if n_all is not None and len(n_all) > last else len(parts)
    shown = min(len(parts), max_particles)
    label = f"final particles ({n_all:,})" if shown >= n_all else f"final particles ({shown:,} of {n_all:,})"
    ax.scatter(parts[sub, 0], parts[sub, 1], s=2, color="tab:purple", alpha=0.35, linewidths=0, label=label,
               zorder=2)


def _draw_probability(ax2: Any, trace: Any, t: np.ndarray) -> Any:
    """``p_localized`` and ``p_place`` on a twin axis of ``ax2`` with the state's thresholds; the twin axis (None
    when the trace has no finite ``p_localized``: the threshold state)."""
    p = getattr(trace, "p_localized", None)
    if p is None or len(p) != len(t) or not np.any(np.isfinite(p)):
        return None
    ax3 = ax2.twinx()
    ax3.plot(t, p, color="tab:blue", lw=1.0, label="p_localized (right axis)")
    place = getattr(trace, "p_place", None)
    if place is not None and len(place) == len(t) and np.any(np.isfinite(place)):
        ax3.plot(t, place, color="tab:cyan", lw=0.8, ls="--", label="p_place (right axis)")
    for level in (LOCALIZED_AT, LOST_BELOW):
        ax3.axhline(level, color="tab:blue", lw=0.6, ls=":", alpha=0.8)
    ax3.set_ylim(0.0, 1.02)
    ax3.set_ylabel(f"probability (dotted: {LOCALIZED_AT:g} localized, {LOST_BELOW:g} lost)")
    return ax3


def report_figure(grid: OccupancyGrid, trace: Any, reference: ArrayLike | None = None, *,
                  times: ArrayLike | None = None, title: str | None = None, max_particles: int = 3000) -> Figure:
    """The report picture of a run (see the module's docstring); returns the Figure.

    Parameters
    ----------
    grid : OccupancyGrid
        The map the run used.
    trace : localize.runloop.RunTrace
        The run; ``trace.snapshots[len(trace) - 1]``, if present, is drawn as
        the final particle cloud.
    reference : array_like (T, 3), optional
        Reference poses per scan (ground truth or a SLAM estimate); NaN rows
        are allowed (no reference at that scan).
    times : array_like (T,), optional
        Time of each scan (s) for the second panel's axis (default: the scan index).
    title : str, optional
        Title above both panels.
    max_particles : int
        At most this many particles of the final cloud are drawn.

    Examples
    --------
    >>> from localize.maps import office
    >>> from localize.mcl import MCL
    >>> from localize.runloop import run_filter
    >>> from localize.sensors import LikelihoodField
    >>> g = office()
    >>> lf = LikelihoodField(g, 8.0, sigma_hit=0.2, temper=0.2)
    >>> rng = np.random.default_rng(1)
    >>> angles = np.linspace(-np.pi / 2, np.pi / 2, 37)
    >>> truth = np.array([[3.0, 3.0, 1.0]])
    >>> f = MCL.uniform(g, 3000, (0.0,) * 4, lf, rng=rng)
    >>> tr = run_filter(f, 8, lambda k: None, lambda k: (lf.sample(truth, angles, rng)[0], angles), snapshot_steps=[7])
    >>> fig = report_figure(g, tr, np.repeat(truth, 8, axis=0))
    >>> labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    >>> labels[:3], labels[-2:]
    (['final particles (3,000)', 'reference', 'estimate: searching'], ['start', 'end'])
    >>> plt.close(fig)
    """
    poses = np.asarray(trace.poses, dtype=float)
    state = np.asarray(trace.state)
    t = np.arange(len(poses), dtype=float) if times is None else np.asarray(times, dtype=float)
    ref = None if reference is None else np.asarray(reference, dtype=float)
    if ref is not None and ref.shape != poses.shape:
        raise ValueError(f"reference must hold one pose per scan, shape {poses.shape}; got {ref.shape}")
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1.35, 1.0]})
    draw_map(grid, ax=ax)
    last = len(poses) - 1
    _draw_final_cloud(ax, trace, last, max_particles)
    if ref is not None:
        ax.plot(ref[:, 0], ref[:, 1], color="k", lw=1.0, alpha=0.6, label="reference", zorder=3)
    ax.plot(poses[:, 0], poses[:, 1], color="0.4", lw=0.6, alpha=0.7, zorder=3)
    for name, color in STATE_COLORS.items():
        sel = state == name
        if sel.any():
            ax.scatter(poses[sel, 0], poses[sel, 1], s=9, color=color, label=f"estimate: {name}", zorder=4)
    ax.plot(*poses[0, :2], marker="o", ms=9, mfc="none", mec="k", mew=1.5, ls="none", label="start", zorder=5)
    ax.plot(*poses[-1, :2], marker="s", ms=9, mfc="none", mec="k", mew=1.5, ls="none", label="end", zorder=5)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    leg = ax.legend(loc="lower left", bbox_to_anchor=(0.01, 0.0), bbox_transform=fig.transFigure, ncol=4, fontsize=8,
                    frameon=False)  # below the panels, off the map (the layout leaves the figure's bottom free)
    leg.set_in_layout(False)
    ax.set_title("trajectory over the map, coloured by state")

    if ref is not None:
        err = np.hypot(*(poses[:, :2] - ref[:, :2]).T)
        ax2.plot(t, err, color="k", lw=1.2, label="position error (m)")
        ax2.set_ylabel("error against the reference (m)")
    else:
        ax2.plot(t, np.asarray(trace.spread, dtype=float), color="k", lw=1.2, label="spread of the best cluster (m)")
        ax2.set_ylabel("spread of the best cluster (m)")
    shown = np.asarray(ax2.lines[0].get_ydata(), dtype=float)
    if np.any(np.isfinite(shown) & (shown > 0)):  # log scale needs a positive value (a run of 3 particles may not)
        ax2.set_yscale("log")
    for a, b, name in _state_runs(state):
        lo = t[a] - (0.5 if times is None else 0.0)
        hi = t[b] + (0.5 if times is None else 0.0)
        ax2.axvspan(lo, hi, color=STATE_COLORS.get(name, "0.8"), alpha=0.15, lw=0)
    ax3 = _draw_probability(ax2, trace, t)
    handles = ax2.get_legend_handles_labels()[0] + ([] if ax3 is None else ax3.get_legend_handles_labels()[0])
    handles += [Patch(color=c, alpha=0.3, label=n) for n, c in STATE_COLORS.items()]
    leg2 = ax2.legend(handles=handles, loc="lower right", bbox_to_anchor=(0.99, 0.0), bbox_transform=fig.transFigure,
                      ncol=3, fontsize=8, frameon=False)    # below the panel, as the map's: off every curve
    leg2.set_in_layout(False)
    ax2.set_xlabel("time (s)" if times is not None else "scan")
    ax2.grid(True, alpha=0.3, which="both")
    ax2.set_title("error" if ref is not None else "spread", loc="left")
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    return fig
