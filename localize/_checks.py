"""Validation shared by the whole package: one check, one wording, for each kind of argument.

Every public function validates its inputs with these helpers, so that a wrong
argument gets the same clear message wherever it is passed: the argument's
name, what was wrong, and the expected type or range. All of them take the
value first and its name second, ``check_positive(sigma, "sigma_hit")``.

Particle arrays
---------------

The convention (DESIGN.md, the preface): N particles are an ``(N, 3)`` array,
one pose ``(x, y, theta)`` per **row**. Most wrong shapes are caught by the
length of the last axis: a ``(3, 5)`` array given the wrong way round (rows x,
y and theta of five particles) has 5 columns and is rejected. Only a
``(3, 3)`` array is ambiguous: three particles, or the rows x, y, theta of
three particles? It is read as three particles (rows); :func:`check_poses`
warns with :class:`PoseShapeWarning` whenever its third column does not look
like headings (values outside ``[-pi, pi]``): with the fix ``.T`` when its
third row does (the fingerprint of a transposed array), else saying that
headings are radians. An array whose third column is headings is read
silently, as are symmetric ones (both readings are the same).

Examples
--------
>>> import numpy as np
>>> check_poses(np.zeros((4, 3))).shape
(4, 3)
>>> check_poses(np.zeros((3, 5)))
Traceback (most recent call last):
...
ValueError: particles must be an (N, 3) array, one particle (x, y, theta) per row; got shape (3, 5) (if the rows are x, y and theta, pass its transpose .T)
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .geometry import as_poses

__all__ = ["PoseShapeWarning", "check_poses", "check_rng", "check_number", "check_positive", "check_nonnegative",
           "check_probability", "check_interval", "check_choice", "check_count", "check_alphas", "check_max_range", "check_angles", "check_grid", "check_sensor_poses"]

#: Radians of round-off allowed beyond 2 pi before beam angles are taken for degrees.
ANGLE_SLACK = 1e-9
#: What every rng error suggests.
RNG_HINT = "np.random.default_rng(seed)"


def check_rng(rng: Any, name: str = "rng") -> np.random.Generator:
    """``rng`` itself if it is a ``numpy.random.Generator``, else ``TypeError``.

    Randomness enters every function through an explicit generator (DESIGN.md),
    never through numpy's global state, so that a seed reproduces a run.

    >>> check_rng(None)
    Traceback (most recent call last):
    ...
    TypeError: rng must be a numpy.random.Generator, e.g. np.random.default_rng(seed); got NoneType
    """
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"{name} must be a numpy.random.Generator, e.g. {RNG_HINT}; got {type(rng).__name__}")
    return rng


def _as_float(value: Any, name: str, what: str) -> float:
    """``float(value)``, or ``TypeError`` saying that ``name`` must be ``what`` (booleans are not numbers)."""
    if isinstance(value, bool):
        raise TypeError(f"{name} must be {what}; got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be {what}; got {value!r}") from None


def check_number(value: Any, name: str, unit: str = "") -> float:
    """``value`` as a finite float; ``TypeError`` if it is not a number, ``ValueError`` if NaN or infinite."""
    v = _as_float(value, name, f"a number of {unit}" if unit else "a number")
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite; got {value!r}")
    return v


def check_positive(value: Any, name: str, unit: str = "") -> float:
    """``value`` as a finite float ``> 0``.

    >>> check_positive(0.2, "sigma_hit")
    0.2
    >>> check_positive(0, "sigma_hit", "metres")
    Traceback (most recent call last):
    ...
    ValueError: sigma_hit must be a finite number of metres > 0; got 0
    """
    v = check_number(value, name, unit)
    if v <= 0:
        what = f"a finite number of {unit}" if unit else "a finite number"
        raise ValueError(f"{name} must be {what} > 0; got {value!r}")
    return v


def check_nonnegative(value: Any, name: str, unit: str = "") -> float:
    """``value`` as a finite float ``>= 0``."""
    v = check_number(value, name, unit)
    if v < 0:
        what = f"a finite number of {unit}" if unit else "a finite number"
        raise ValueError(f"{name} must be {what} >= 0; got {value!r}")
    return v


def check_probability(value: Any, name: str) -> float:
    """``value`` as a float in ``[0, 1]``."""
    v = check_number(value, name)
    if not 0.0 <= v <= 1.0:
        raise ValueError(f"{name} must be a probability in [0, 1]; got {value!r}")
    return v


def check_interval(value: Any, name: str, low: float, high: float, *, open_low: bool = False,
                   open_high: bool = False, what: str = "a number") -> float:
    """``value`` as a float between ``low`` and ``high`` (``open_low`` / ``open_high``: that end excluded).

    >>> check_interval(0.3, "temper", 0, 1, open_low=True)
    0.3
    >>> check_interval(1, "injection", 0, 1, open_high=True, what="a fraction")
    Traceback (most recent call last):
    ...
    ValueError: injection must be a fraction in [0, 1); got 1
    """
    v = _as_float(value, name, what)
    inside = (v > low if open_low else v >= low) and (v < high if open_high else v <= high)
    if not (math.isfinite(v) and inside):
        span = f"{'(' if open_low else '['}{low:g}, {high:g}{')' if open_high else ']'}"
        raise ValueError(f"{name} must be {what} in {span}; got {value!r}")
    return v


def check_choice(value: Any, name: str, choices: tuple[str, ...]) -> str:
    """``value`` if it is one of the strings ``choices``.

    >>> check_choice("sonar", "sensor", ("likelihood", "beam"))
    Traceback (most recent call last):
    ...
    ValueError: sensor must be one of likelihood, beam; got 'sonar'
    """
    if value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(choices)}; got {value!r}")
    return value


def check_count(value: Any, name: str, minimum: int = 1) -> int:
    """``value`` as an ``int >= minimum``; a float is accepted only if it is whole (``1e4``).

    >>> check_count(1e4, "n_particles")
    10000
    >>> check_count(2.5, "n_particles")
    Traceback (most recent call last):
    ...
    TypeError: n_particles must be a whole number >= 1; got 2.5
    """
    f = _as_float(value, name, f"a whole number >= {minimum}")
    if not math.isfinite(f) or f != int(f):
        raise TypeError(f"{name} must be a whole number >= {minimum}; got {value!r}")
    n = int(f)
    if n < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}; got {value!r}")
    return n


def check_alphas(alphas: ArrayLike, n: int, name: str = "alphas") -> NDArray[np.float64]:
    """Motion noise parameters ``alpha1..alphan`` (PR convention: they scale variances) as a finite float array >= 0.

    >>> check_alphas([0.1, 0.0, 0.2, 0.1], 4).tolist()
    [0.1, 0.0, 0.2, 0.1]
    >>> check_alphas([0.1, 0.1], 4)
    Traceback (most recent call last):
    ...
    ValueError: alphas must hold 4 numbers (alpha1..alpha4); got shape (2,)
    """
    a = np.asarray(alphas, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"{name} must hold {n} numbers (alpha1..alpha{n}); got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite; got {a.tolist()}")
    if np.any(a < 0):
        raise ValueError(f"{name} must be >= 0 (they scale noise variances); got {a.tolist()}")
    return a


def check_max_range(max_range: Any, name: str = "max_range") -> float:
    """The sensor's maximum range as a positive float (metres)."""
    return check_positive(max_range, name, "metres")


def check_angles(angles: ArrayLike, name: str = "angles") -> NDArray[np.float64]:
    """Beam angles as a finite 1-D float array of radians (a scalar becomes one beam).

    Values beyond ``2 pi`` in magnitude are taken for degrees and rejected with
    the fix (``np.radians``).
    """
    a = np.asarray(angles, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of beam angles in radians; got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (radians relative to the sensor heading); found NaN or inf")
    if a.size and float(np.max(np.abs(a))) > 2 * np.pi + ANGLE_SLACK:
        raise ValueError(f"{name}: beam angles must be radians in [-2 pi, 2 pi]; got values up to "
                         f"{float(np.max(np.abs(a))):g} -- degrees? convert with np.radians({name})")
    return a


def check_grid(grid: Any, name: str = "grid"):
    """``grid`` itself if it is a :class:`localize.OccupancyGrid`, else ``TypeError``."""
    # by name: grid.py imports this module, and this one, imported by every layer, imports none of them
    for c in type(grid).__mro__:
        if c.__name__ == "OccupancyGrid" and c.__module__ == "localize.grid":
            return grid
    raise TypeError(f"{name} must be a localize.OccupancyGrid (see localize.maps); got {type(grid).__name__}")


def check_sensor_poses(poses: ArrayLike, name: str = "poses") -> NDArray[np.float64]:
    """One pose ``(3,)`` or many ``(N, 3)`` as a finite ``(N, 3)`` float array (no transposition warning)."""
    p = as_poses(poses, name)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2:
        raise ValueError(f"{name} must be an (N, 3) array of poses (x, y, theta); got shape {p.shape}")
    return p


class PoseShapeWarning(UserWarning):
    """A (3, 3) particle array looks transposed (rows x, y, theta instead of one particle per row)."""


def check_poses(poses: ArrayLike, name: str = "particles", stacklevel: int = 3) -> NDArray[np.float64]:
    """A finite float ``(N, 3)`` array of particles (N >= 1), one ``(x, y, theta)`` per row.

    Raises ``ValueError`` naming ``name`` for any other shape or a NaN /
    infinite value; warns :class:`PoseShapeWarning` for a ``(3, 3)`` array
    that looks transposed (see the module docstring).

    Examples
    --------
    >>> import warnings
    >>> xs, ys, ths = [1.0, 5.0, 9.0], [2.0, 6.0, 8.0], [0.1, 0.2, 0.3]
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     _ = check_poses(np.array([xs, ys, ths]))     # rows x, y, theta: transposed
    >>> print(w[0].message)      # doctest: +ELLIPSIS
    particles has shape (3, 3) and is read as 3 particles, one (x, y, theta) per row; ...
    >>> check_poses(np.array([xs, ys, ths]).T)[:, 2]     # one particle per row: no warning
    array([0.1, 0.2, 0.3])
    """
    p = np.asarray(poses, dtype=float)
    if p.ndim != 2 or p.shape[-1] != 3 or p.shape[0] < 1:
        hint = " (if the rows are x, y and theta, pass its transpose .T)" if p.ndim == 2 and p.shape[0] == 3 else ""
        raise ValueError(f"{name} must be an (N, 3) array, one particle (x, y, theta) per row; "
                         f"got shape {p.shape}{hint}")
    p = as_poses(p, name)
    if p.shape == (3, 3) and not np.array_equal(p, p.T):  # a symmetric array reads the same both ways
        why = _ambiguity(p)
        if why:
            warnings.warn(f"{name} has shape (3, 3) and is read as 3 particles, one (x, y, theta) per row; {why}",
                          PoseShapeWarning, stacklevel=stacklevel)
    return p


def _ambiguity(p: NDArray[np.float64]) -> str:
    """Why a (3, 3) particle array may be meant the other way round ("" when its rows are clearly particles)."""
    col_ok = bool(np.all(np.abs(p[:, 2]) <= np.pi))
    row_ok = bool(np.all(np.abs(p[2, :]) <= np.pi))
    column = np.round(p[:, 2], 3).tolist()
    if row_ok and not col_ok:
        return (f"its third column {column} does not look like headings in [-pi, pi] but its third row does: "
                "if the rows are x, y and theta, pass its transpose .T")
    if not col_ok:
        return (f"its third column {column} does not look like headings in [-pi, pi] (nor does its third row): "
                "headings are radians, one per row")
    return ""  # both readings plausible: read as rows, as documented (warning here would flag every 3-particle test)
