"""Validation of particle arrays, shared by every function that takes a particle set.

The convention (DESIGN.md, the preface): N particles are an ``(N, 3)`` array,
one pose ``(x, y, theta)`` per **row**. Most wrong shapes are caught by the
length of the last axis: a ``(3, 5)`` array given the wrong way round (rows x,
y and theta of five particles) has 5 columns and is rejected. Only a
``(3, 3)`` array is ambiguous: three particles, or the rows x, y, theta of
three particles? It is read as three particles (rows); :func:`check_poses`
warns with :class:`PoseShapeWarning` when its third column does not look like
headings (values outside ``[-pi, pi]``) while its third row does, the
fingerprint of a transposed array.

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

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .geometry import as_poses

__all__ = ["PoseShapeWarning", "check_poses"]


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
    if p.shape == (3, 3):
        col_ok = bool(np.all(np.abs(p[:, 2]) <= np.pi))
        row_ok = bool(np.all(np.abs(p[2, :]) <= np.pi))
        if row_ok and not col_ok:
            warnings.warn(
                f"{name} has shape (3, 3) and is read as 3 particles, one (x, y, theta) per row; its third column "
                f"{np.round(p[:, 2], 3).tolist()} does not look like headings in [-pi, pi] but its third row does: "
                "if the rows are x, y and theta, pass its transpose .T",
                PoseShapeWarning, stacklevel=stacklevel)
    return p
