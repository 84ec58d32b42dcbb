"""How good is a localizer? Errors, RMSE, NEES, convergence and failure rate.

All functions take estimated and true poses as ``(T, 3)`` arrays (or any
``(..., 3)``) of ``(x, y, theta)`` and are vectorised. Heading errors are
*wrapped*: an estimate of 179 degrees for a true heading of -179 degrees is 2
degrees off, not 358.

* :func:`position_error`, :func:`heading_error`, :func:`pose_errors` —
  per-step errors;
* :func:`rmse` — root mean square of errors;
* :func:`nees` and :func:`nees_bounds` — the normalised estimation error
  squared and its chi-square acceptance interval, the standard check that a
  filter's covariance is honest (Bar-Shalom, Li and Kirubarajan, *Estimation
  with Applications to Tracking and Navigation*, 2001, section 5.4);
* :func:`convergence_step` — the first step after which the error stays
  below a threshold;
* :func:`failure_rate` — the fraction of runs that end (or stay) lost;
* :func:`localized` and :func:`success_rate` — did a run end localized, and
  in what fraction of seeded trials (with an optional progress bar,
  :func:`progress`, for the slow experiments of the book).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_count
from .geometry import as_poses, wrap_angle

__all__ = [
    "position_error",
    "heading_error",
    "pose_errors",
    "rmse",
    "nees",
    "nees_bounds",
    "convergence_step",
    "failure_rate",
    "summary",
    "localized",
    "success_rate",
    "progress",
]


def _pair(estimate: ArrayLike, truth: ArrayLike) -> tuple[NDArray, NDArray]:
    e = as_poses(estimate, "estimate")
    t = as_poses(truth, "truth")
    try:
        np.broadcast_shapes(e.shape, t.shape)
    except ValueError:
        raise ValueError(f"estimate and truth must have matching shapes; got {e.shape} and {t.shape}") from None
    return e, t


def position_error(estimate: ArrayLike, truth: ArrayLike) -> NDArray[np.float64] | float:
    """Euclidean distance between estimated and true positions (metres).

    Examples
    --------
    >>> position_error([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]], [[3.0, 4.0, 1.0], [1.0, 1.0, 2.0]])
    array([5., 0.])
    """
    e, t = _pair(estimate, truth)
    d = np.hypot(e[..., 0] - t[..., 0], e[..., 1] - t[..., 1])
    return float(d) if d.ndim == 0 else d


def heading_error(estimate: ArrayLike, truth: ArrayLike, absolute: bool = True) -> NDArray[np.float64] | float:
    """Heading error ``wrap(theta_est - theta_true)`` in radians, in ``[-pi, pi)``.

    With ``absolute=True`` (default) its magnitude, in ``[0, pi]``.

    Examples
    --------
    >>> est = [[0, 0, np.radians(179.0)]]
    >>> true = [[0, 0, np.radians(-179.0)]]
    >>> np.degrees(heading_error(est, true)).round(6)
    array([2.])
    >>> np.degrees(heading_error(est, true, absolute=False)).round(6)
    array([-2.])
    """
    e, t = _pair(estimate, truth)
    d = wrap_angle(e[..., 2] - t[..., 2])
    d = np.abs(d) if absolute else d
    return float(d) if np.ndim(d) == 0 else d


def pose_errors(estimate: ArrayLike, truth: ArrayLike) -> NDArray[np.float64]:
    """Signed errors ``(dx, dy, dtheta)`` of estimates, heading wrapped: what :func:`nees` uses.

    Examples
    --------
    >>> pose_errors([1.0, 2.0, 3.1], [0.5, 2.5, -3.1]).round(6)
    array([ 0.5     , -0.5     , -0.083185])
    """
    e, t = _pair(estimate, truth)
    d = e - t
    d[..., 2] = wrap_angle(d[..., 2])
    return d


def rmse(errors: ArrayLike, axis: int | None = None) -> NDArray[np.float64] | float:
    """Root mean square ``sqrt(mean(e^2))``; NaN entries are an error.

    Examples
    --------
    >>> round(rmse([3.0, -4.0]), 6)
    3.535534
    """
    e = np.asarray(errors, dtype=float)
    if e.size == 0:
        raise ValueError("errors is empty; need at least one error to average")
    if np.any(np.isnan(e)):
        raise ValueError("errors contains NaN; drop the steps without an estimate first")
    r = np.sqrt(np.mean(e * e, axis=axis))
    return float(r) if np.ndim(r) == 0 else r


def nees(estimate: ArrayLike, cov: ArrayLike, truth: ArrayLike) -> NDArray[np.float64] | float:
    """Normalised estimation error squared ``e^T P^-1 e`` of pose estimates.

    ``e`` is the signed error of :func:`pose_errors` (heading wrapped), ``P``
    the filter's ``3 x 3`` covariance. If the filter is consistent (errors
    zero-mean with covariance ``P``), NEES follows a chi-square distribution
    with 3 degrees of freedom: its mean is 3. Much larger values mean the
    filter is overconfident.

    Parameters
    ----------
    estimate, truth : array_like, shape (..., 3)
    cov : array_like, shape (..., 3, 3)
        Symmetric positive definite.

    Examples
    --------
    >>> P = np.diag([0.04, 0.04, 0.01])
    >>> round(nees([0.2, 0.0, 0.1], P, [0.0, 0.0, 0.0]), 6)        # 1 + 1
    2.0
    """
    d = pose_errors(estimate, truth)
    P = np.asarray(cov, dtype=float)
    if P.shape[-2:] != (3, 3):
        raise ValueError(f"cov must have shape (..., 3, 3); got {P.shape}")
    try:
        sol = np.linalg.solve(P, d[..., None])[..., 0]
    except np.linalg.LinAlgError:
        raise ValueError("cov is singular; a pose covariance must be positive definite") from None
    q = np.sum(d * sol, axis=-1)
    if np.any(q < 0):
        raise ValueError("cov is not positive definite (a negative quadratic form was found)")
    return float(q) if np.ndim(q) == 0 else q


def nees_bounds(dof: int = 3, n_runs: int = 1, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided chi-square acceptance interval for the (run-averaged) NEES.

    The average of ``n_runs`` independent NEES values of a consistent filter
    is ``chi2(dof * n_runs) / n_runs``. The returned interval holds it with
    probability ``confidence``.

    Examples
    --------
    >>> [round(b, 3) for b in nees_bounds(3, 1)]
    [0.216, 9.348]
    >>> [round(b, 3) for b in nees_bounds(3, 50)]
    [2.359, 3.72]
    """
    from scipy.stats import chi2

    dof, n_runs = check_count(dof, "dof"), check_count(n_runs, "n_runs")
    c = float(confidence)
    if not 0 < c < 1:
        raise ValueError(f"confidence must lie in (0, 1); got {confidence}")
    a = (1 - c) / 2
    k = dof * n_runs
    return float(chi2.ppf(a, k) / n_runs), float(chi2.ppf(1 - a, k) / n_runs)


def convergence_step(errors: ArrayLike, threshold: float) -> int | None:
    """First step ``k`` from which the error stays below ``threshold`` to the end.

    Returns ``None`` if the last error is not below the threshold (the run
    never converged). A run that is below the threshold from the start
    converges at step 0. NaN errors (no estimate) count as above.

    Examples
    --------
    >>> convergence_step([5.0, 0.2, 3.0, 0.3, 0.1, 0.2], threshold=0.5)
    3
    >>> convergence_step([5.0, 0.2, 3.0], threshold=0.5) is None
    True
    """
    e = np.asarray(errors, dtype=float)
    if e.ndim != 1 or e.size == 0:
        raise ValueError(f"errors must be a non-empty 1-D array over time; got shape {e.shape}")
    t = float(threshold)
    if not t > 0:
        raise ValueError(f"threshold must be > 0; got {threshold}")
    above = ~(e < t)
    if above[-1]:
        return None
    idx = np.flatnonzero(above)
    return 0 if idx.size == 0 else int(idx[-1] + 1)


def failure_rate(final_errors: ArrayLike, threshold: float) -> float:
    """Fraction of runs whose (final) error is at or above ``threshold``, or NaN.

    Examples
    --------
    >>> failure_rate([0.1, 0.2, 3.0, np.nan], threshold=0.5)     # NaN: no estimate counts as failed
    0.5
    """
    e = np.asarray(final_errors, dtype=float).reshape(-1)
    if e.size == 0:
        raise ValueError("final_errors is empty; need at least one run")
    t = float(threshold)
    if not t > 0:
        raise ValueError(f"threshold must be > 0; got {threshold}")
    return float(np.mean(~(e < t)))


def summary(estimate: ArrayLike, truth: ArrayLike, threshold: float = 0.5,
            heading_threshold: float = np.radians(15.0)) -> dict[str, float | int | None]:
    """A run's errors in one dict: RMSE, final errors, convergence step.

    Converged means position error below ``threshold`` *and* heading error
    below ``heading_threshold`` from that step on.

    Examples
    --------
    >>> truth = np.zeros((4, 3))
    >>> est = np.array([[3.0, 0, 0], [1.0, 0, 0], [0.1, 0, 0], [0.0, 0, 0.05]])
    >>> s = summary(est, truth)
    >>> s["converged_at"], round(s["rmse_position"], 4), round(s["final_heading_deg"], 3)
    (2, 1.5819, 2.865)
    """
    pe = position_error(estimate, truth)
    he = heading_error(estimate, truth)
    pe, he = np.atleast_1d(pe), np.atleast_1d(he)
    ok = np.where((pe < threshold) & (he < heading_threshold), 0.0, np.inf)
    return {
        "rmse_position": rmse(pe),
        "rmse_heading_deg": float(np.degrees(rmse(he))),
        "final_position": float(pe[-1]),
        "final_heading_deg": float(np.degrees(he[-1])),
        "converged_at": convergence_step(ok, 0.5),
    }


def progress(iterable: Iterable, enabled: bool = True, desc: str | None = None, total: int | None = None) -> Iterable:
    """Wrap ``iterable`` in a tqdm progress bar when ``enabled``, else return it unchanged.

    Uses ``tqdm.auto``: a widget bar in Jupyter, a text bar on stderr in a
    terminal. The bar disappears when the loop ends (``leave=False``), so a
    notebook keeps only the results. In a chapter, put a loop with a progress
    bar in a cell tagged ``nbval-ignore-output`` and ``remove-output`` (the
    bar's text holds timings) and print the results in the next cell.

    Examples
    --------
    >>> list(progress(range(3), enabled=False))
    [0, 1, 2]
    >>> sum(progress(range(4), enabled=True, desc="adding"))   # a bar on stderr outside Jupyter
    6
    """
    if not enabled:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, desc=desc, total=total, leave=False)


def localized(estimate: ArrayLike, truth: ArrayLike, position_tol: float = 0.5, heading_tol: float = 0.2,
              last: int = 5) -> bool:
    """True when the estimate is within both tolerances of the truth at each of the ``last`` steps.

    Parameters
    ----------
    estimate, truth : array_like, shape (T, 3)
        Estimated and true poses of one run.
    position_tol : float
        Metres.
    heading_tol : float
        Radians (wrapped difference).
    last : int
        How many final steps must be within tolerance (1 <= last <= T).

    Examples
    --------
    >>> truth = np.zeros((6, 3))
    >>> est = truth + [0.1, 0.0, 0.05]
    >>> localized(est, truth), localized(est + [0.6, 0, 0], truth)
    (True, False)
    """
    est, tru = _pair(estimate, truth)
    if est.ndim != 2:
        raise ValueError(f"estimate and truth must be (T, 3) trajectories; got shape {est.shape}")
    if not 1 <= int(last) <= est.shape[0]:
        raise ValueError(f"last must be between 1 and the number of steps ({est.shape[0]}); got {last}")
    if position_tol <= 0 or heading_tol <= 0:
        raise ValueError(f"position_tol and heading_tol must be > 0; got {position_tol}, {heading_tol}")
    k = int(last)
    return bool(np.all(position_error(est[-k:], tru[-k:]) < position_tol)
                and np.all(heading_error(est[-k:], tru[-k:]) < heading_tol))


def success_rate(trial: Callable[[int], tuple[Any, Any]], seeds: Iterable[int], *, position_tol: float = 0.5,
                 heading_tol: float = 0.2, last: int = 5, progress_bar: bool = False,
                 desc: str | None = None) -> float:
    """Fraction of seeded trials that end :func:`localized`.

    Parameters
    ----------
    trial : callable
        ``trial(seed) -> (estimated poses, true poses)``, both ``(T, 3)``; it
        must draw all its randomness from generators seeded by ``seed``.
    seeds : iterable of int
        One trial per seed, e.g. ``range(20)``.
    position_tol, heading_tol, last
        As in :func:`localized`.
    progress_bar : bool
        Show a tqdm progress bar over the trials (see :func:`progress`).
    desc : str, optional
        Label of the progress bar.

    Examples
    --------
    >>> def trial(seed):            # a "filter" that is right for even seeds only
    ...     truth = np.zeros((5, 3))
    ...     return truth + [seed % 2, 0.0, 0.0], truth
    >>> success_rate(trial, range(10))
    0.5
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must name at least one seed")
    ok = [localized(*trial(s), position_tol=position_tol, heading_tol=heading_tol, last=last)
          for s in progress(seeds, progress_bar, desc=desc)]
    return float(np.mean(ok))
