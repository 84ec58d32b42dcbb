"""Learning the beam model's intrinsic parameters from data (PR table 6.2).

Given readings ``z_i`` and the ranges ``z*_i`` that ray casting predicts for
them (from poses known, say, from a localized log), the parameters
``Theta = (z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short)`` of
:class:`localize.sensors.BeamModel` are fitted by expectation-maximisation
(Dempster, Laird and Rubin 1977; *Probabilistic Robotics*, Thrun, Burgard and
Fox 2005, section 6.3.3, table 6.2):

* **E-step**: for every reading, the probability ``e_i,c`` that component
  ``c`` produced it (its "responsibility"), proportional to the weighted
  component density ``z_c p_c(z_i | z*_i)``;
* **M-step**: each weight becomes the mean responsibility; ``sigma_hit`` the
  responsibility-weighted RMS error of the hits; ``lambda_short`` the rate
  that best explains the short readings.

Two details differ from the printed table, both on purpose:

1. PR's table computes the responsibilities from the *unweighted* component
   densities; EM proper weights them by the current mixture weights (which
   is what makes the iteration increase the likelihood). We weight them.
2. A reading at ``max_range`` is a point mass: it is assigned wholly to the
   max-range component, and readings below ``max_range`` never to it. PR's
   table mixes the mass with densities at ``z = max_range``.

PR's closed-form update ``lambda = sum e_short / sum e_short z`` ignores the
truncation of the exponential at ``z*``; with ``exact_lambda=True``
(default) the M-step instead solves the truncated-exponential likelihood
equation numerically, which removes a bias when ``z*`` is not much larger
than ``1 / lambda``. The ``sigma_hit`` update ignores the (tiny) truncation
of the Gaussian at 0 and ``max_range``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .sensors import BeamModel, check_ranges

__all__ = ["BeamFit", "fit_beam_model"]

#: The rate of short readings (1/m) is searched in this bracket; at its ends the fit stops at the end.
_LAMBDA_BRACKET = (1e-6, 1e6)
#: The EM never lets sigma_hit (m) or lambda_short (1/m) fall below this: a zero would make the model degenerate.
_MIN_PARAM = 1e-6
#: Densities below this are raised to it before their logarithm (a reading no component explains).
_TINY_DENSITY = 1e-300

_NAMES = ("z_hit", "z_short", "z_max", "z_rand", "sigma_hit", "lambda_short")


@dataclass
class BeamFit:
    """Result of :func:`fit_beam_model`.

    Attributes
    ----------
    params : dict
        The fitted ``z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short``.
    log_likelihood : list of float
        Data log-likelihood after each iteration (non-decreasing, up to the
        approximate sigma update).
    n_iter : int
    converged : bool
    """

    params: dict[str, float]
    log_likelihood: list[float] = field(default_factory=list)
    n_iter: int = 0
    converged: bool = False

    def model(self, grid=None, max_range: float = 1.0, **kwargs) -> BeamModel:
        """A :class:`BeamModel` with the fitted parameters.

        Examples
        --------
        >>> BeamFit(params=dict(z_hit=0.7, z_short=0.1, z_max=0.1, z_rand=0.1, sigma_hit=0.2,
        ...                     lambda_short=1.0)).model(None, 8.0)
        BeamModel(max_range=8, z_hit=0.7, z_short=0.1, z_max=0.1, z_rand=0.1, sigma_hit=0.2, lambda_short=1)
        """
        return BeamModel(grid, max_range, **self.params, **kwargs)


def _solve_lambda(e: np.ndarray, z: np.ndarray, zs: np.ndarray, lam0: float) -> float:
    """Maximise sum e [log lam - lam z - log(1 - exp(-lam z*))] over lam > 0."""
    from scipy.optimize import brentq

    s = e.sum()
    if s <= 0:
        return lam0
    ez = (e * z).sum()

    def score(lam: float) -> float:
        x = lam * zs
        # z* / (exp(lam z*) - 1), stable for small and large x
        tail = np.where(x < 1e-8, 1.0 / lam - zs / 2, zs / np.expm1(np.minimum(x, 700.0)))
        return s / lam - ez - float((e * tail).sum())

    lo, hi = _LAMBDA_BRACKET
    if score(lo) <= 0:
        return lo  # short readings look uniform over [0, z*]: the rate tends to 0
    if score(hi) >= 0:
        return hi
    return float(brentq(score, lo, hi, xtol=1e-10, rtol=1e-10))


def fit_beam_model(z: ArrayLike, z_expected: ArrayLike, max_range: float, init: dict | None = None,
                   n_iter: int = 200, tol: float = 1e-8, exact_lambda: bool = True) -> BeamFit:
    """Fit the beam model's intrinsic parameters by EM (PR table 6.2).

    Parameters
    ----------
    z : array_like
        Measured ranges (any shape; readings >= max_range are "no return").
    z_expected : array_like
        Ray-cast ranges for the same beams (same shape as ``z``).
    max_range : float
    init : dict, optional
        Starting parameters (default: 0.7, 0.1, 0.1, 0.1, 0.5 m, 1/m).
    n_iter : int
        Maximum number of EM iterations.
    tol : float
        Stop when the mean log-likelihood per reading changes less than this.
    exact_lambda : bool
        Solve the truncated-exponential M-step exactly (default) or use PR's
        closed form ``sum e_short / sum e_short z``.

    Returns
    -------
    BeamFit

    Examples
    --------
    >>> from localize.sensors import BeamModel
    >>> true = BeamModel(None, 10.0, 0.7, 0.15, 0.05, 0.1, sigma_hit=0.15, lambda_short=0.8)
    >>> rng = np.random.default_rng(0)
    >>> zs = rng.uniform(0.5, 9.5, 20000)
    >>> fit = fit_beam_model(true.sample_expected(zs, rng), zs, 10.0)
    >>> {k: round(v, 2) for k, v in fit.params.items()}
    {'z_hit': 0.7, 'z_short': 0.15, 'z_max': 0.05, 'z_rand': 0.1, 'sigma_hit': 0.15, 'lambda_short': 0.8}
    """
    zz = check_ranges(z, float(max_range), name="z").ravel()
    zs = np.asarray(z_expected, dtype=float).ravel()
    if zs.shape != zz.shape:
        raise ValueError(f"z_expected must have the same number of beams as z; got {zs.size} and {zz.size}")
    if not np.all(np.isfinite(zs)) or (zs < 0).any():
        raise ValueError("z_expected must hold finite ranges >= 0")
    p = dict(zip(_NAMES, (0.7, 0.1, 0.1, 0.1, 0.5, 1.0))) if init is None else dict(init)
    missing = set(_NAMES) - set(p)
    if missing:
        raise ValueError(f"init is missing {sorted(missing)}; give all of {_NAMES}")
    model = BeamModel(None, max_range, **p)
    zmax = model.max_range
    zs = np.clip(zs, model.z_floor, zmax)
    at_max = zz >= zmax
    history: list[float] = []
    converged = False
    it = 0
    while it < int(n_iter):
        it += 1
        c = model.components(zz, zs)
        w_hit = model.z_hit * c["p_hit"]
        w_short = model.z_short * c["p_short"]
        w_rand = model.z_rand * c["p_rand"]
        dens = w_hit + w_short + w_rand
        # E-step: responsibilities; a max-range reading belongs to the max component alone
        with np.errstate(divide="ignore", invalid="ignore"):
            e_hit = np.where(at_max, 0.0, w_hit / dens)
            e_short = np.where(at_max, 0.0, w_short / dens)
            e_rand = np.where(at_max, 0.0, w_rand / dens)
        e_max = at_max.astype(float)
        ll = float(np.where(at_max, np.log(max(model.z_max, _TINY_DENSITY)),
                            np.log(np.maximum(dens, _TINY_DENSITY))).mean())
        history.append(ll)
        # M-step
        z_hit, z_short, z_max, z_rand = e_hit.mean(), e_short.mean(), e_max.mean(), e_rand.mean()
        sh = e_hit.sum()
        sigma = float(np.sqrt((e_hit * (zz - zs) ** 2).sum() / sh)) if sh > 0 else model.sigma_hit
        sigma = max(sigma, _MIN_PARAM)
        if exact_lambda:
            lam = _solve_lambda(e_short, zz, zs, model.lambda_short)
        else:
            ss = (e_short * zz).sum()
            lam = float(e_short.sum() / ss) if ss > 0 else model.lambda_short
        tot = z_hit + z_short + z_max + z_rand
        model = BeamModel(None, zmax, z_hit / tot, z_short / tot, z_max / tot, z_rand / tot,
                          sigma_hit=sigma, lambda_short=max(lam, _MIN_PARAM))
        if len(history) > 1 and abs(history[-1] - history[-2]) < tol:
            converged = True
            break
    params = {k: float(v) for k, v in model.params.items()}
    return BeamFit(params=params, log_likelihood=history, n_iter=it, converged=converged)
