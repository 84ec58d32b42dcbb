"""localize: robot localization from the Bayes filter to Monte Carlo Localization.

The companion package of the book in ``book/``. Submodules are imported on
demand (``import localize.mcl``), the foundations are at the top level::

    >>> import localize
    >>> localize.wrap_angle(4.0) < 0
    True
"""

from .geometry import wrap_angle
from .grid import OccupancyGrid

__all__ = ["OccupancyGrid", "wrap_angle", "__version__"]
__version__ = "0.1.0"
