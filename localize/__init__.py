"""localize: robot localization from the Bayes filter to Monte Carlo Localization.

The companion package of the book in ``book/``. The foundations are imported
with the package; the main classes and every submodule are at the top level
too, imported on first use (so ``import localize`` stays fast)::

    >>> import localize
    >>> localize.wrap_angle(4.0) < 0
    True
    >>> localize.MCL is localize.mcl.MCL and localize.GridLocalizer is localize.gridloc.GridLocalizer
    True

Where the main names live:

==============================================================  ==============================================
name                                                            module
==============================================================  ==============================================
``MCL``, ``Augmented``                                          :mod:`localize.mcl` (chapters 7, 8)
``OdometryMotion``, ``VelocityMotion``                          :mod:`localize.motion` (chapters 4, 7)
``KLDSampling``                                                 :mod:`localize.kld` (chapter 8)
``GridLocalizer``                                               :mod:`localize.gridloc` (chapter 3)
``BeamModel``, ``LikelihoodField``, ``LandmarkModel``           :mod:`localize.sensors` (chapter 5)
``RayCaster``                                                   :mod:`localize.raycast` (chapter 5)
``EKFLocalizer``, ``UKFLocalizer``                              :mod:`localize.ekf` (chapter 10)
``OccupancyGrid``, ``wrap_angle``                               :mod:`localize.grid`, :mod:`localize.geometry`
==============================================================  ==============================================
"""

from __future__ import annotations

import importlib
from typing import Any

from .geometry import wrap_angle
from .grid import OccupancyGrid

#: Top-level name -> submodule that defines it (imported on first access).
_LAZY_NAMES = {
    "MCL": "mcl",
    "Augmented": "mcl",
    "OdometryMotion": "motion",
    "VelocityMotion": "motion",
    "KLDSampling": "kld",
    "GridLocalizer": "gridloc",
    "BeamModel": "sensors",
    "LikelihoodField": "sensors",
    "LandmarkModel": "sensors",
    "RayCaster": "raycast",
    "EKFLocalizer": "ekf",
    "UKFLocalizer": "ekf",
}
_SUBMODULES = (
    "beam_learning", "check", "cli", "compare", "diagnostics", "discrete", "ekf", "estimate", "evidence",
    "geometry", "grid", "gridloc", "histogram", "io", "kld", "mapping", "maps", "mcl", "metrics", "motion",
    "multiscale", "pipeline", "plot", "policies", "raycast", "resample", "runloop", "scanmatch", "sensors",
    "settings", "sim", "smooth", "widgets",
)

__all__ = ["OccupancyGrid", "wrap_angle", "__version__", *_LAZY_NAMES]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name in _LAZY_NAMES:
        value = getattr(importlib.import_module(f".{_LAZY_NAMES[name]}", __name__), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'localize' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY_NAMES) | set(_SUBMODULES))
