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

The modules, in the order the book meets them (``help(localize.<module>)``
lists each one's functions):

===============================  ==========================================================================
module                           what it holds
===============================  ==========================================================================
:mod:`localize.geometry`         angles and planar poses: ``wrap_angle``, pose composition (preface)
:mod:`localize.grid`             ``OccupancyGrid``: cells, resolution, origin, distance field (preface)
:mod:`localize.maps`             built-in worlds: ``office``, ``tile_world``, ``city_world``, ... (preface on)
:mod:`localize.discrete`         the discrete Bayes filter on a hallway: ``update``, ``predict`` (chapter 1)
:mod:`localize.histogram`        the tile world: ``sense``, ``move``, noisy step kernels (chapter 2)
:mod:`localize.multiscale`       coarse-to-fine histogram localization (chapter 2)
:mod:`localize.gridloc`          (x, y, theta) grid localization, ``coarsen`` (chapter 3)
:mod:`localize.motion`           odometry and velocity motion models: samplers and densities (chapter 4)
:mod:`localize.raycast`          expected ranges: exact walk, ray marcher, lookup table (chapter 5)
:mod:`localize.sensors`          beam model, likelihood field, landmark model (chapter 5)
:mod:`localize.beam_learning`    fitting the beam model's parameters (chapter 5)
:mod:`localize.resample`         resamplers and the effective sample size (chapter 6)
:mod:`localize.diagnostics`      exact posteriors and distances to judge a particle filter (chapters 6, 8)
:mod:`localize.mcl`              the particle filter: MCL, augmented MCL (chapters 7, 8)
:mod:`localize.estimate`         one answer from a cloud: ``estimate_pose``, clusters, covariance (chapter 7)
:mod:`localize.runloop`          the run loop of PR table 8.2, ``run_filter``, its record (chapters 7, 8)
:mod:`localize.policies`         the loop's rules as objects: gating, beam masks, recovery, state (chapters 8, 9)
:mod:`localize.evidence`         what the map says about an estimate: scan fit, probes (chapters 8, 9)
:mod:`localize.reliability`      "am I localized?" as a calibrated probability (chapter 8)
:mod:`localize.kld`              KLD-sampling (chapter 8)
:mod:`localize.sim`              simulated robots: odometry, scans, sightings, kidnapping (chapters 3-10)
:mod:`localize.metrics`          errors, RMSE, NEES, convergence, success rates (chapters 7-10)
:mod:`localize.io`               maps and logs: CMU, CARMEN, ROS map_server and bags (chapter 9)
:mod:`localize.mapping`          occupancy grid mapping with known poses (chapter 9)
:mod:`localize.scanmatch`        does the odometry agree with the scans? (chapter 9)
:mod:`localize.smooth`           forwards and backwards over a recorded log (chapter 9)
:mod:`localize.settings`         the settings of a run over a log, each once (chapter 9)
:mod:`localize.pipeline`         a log in, a trajectory out: read, map, filter, collect (chapter 9)
:mod:`localize.cli`              ``python -m localize``: the command line (chapter 9)
:mod:`localize.ekf`              EKF and UKF landmark localization (chapter 10)
:mod:`localize.compare`          the EKF-versus-MCL experiments (chapter 10)
:mod:`localize.plot`             figures, one module per topic
:mod:`localize.widgets`          the interactive figures of the chapters
:mod:`localize.check`            self-checks for the exercises and the homework
:mod:`localize.grade`            grading a class's homework (chapter 12)
===============================  ==========================================================================

Every submodule is in that list:

    >>> all(f":mod:`localize.{name}`" in localize.__doc__ for name in localize._SUBMODULES)
    True
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
    "multiscale", "pipeline", "plot", "policies", "raycast", "reliability", "resample", "runloop", "scanmatch",
    "sensors",
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
