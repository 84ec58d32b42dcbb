"""A robot on a map: the preface's first interactive figure.

:func:`robot_on_map_figure` is the callback (pose in, figure out);
:func:`robot_on_map` wires three sliders to it.
"""

from __future__ import annotations

import numpy as np

from ..geometry import transform_points
from ..grid import OccupancyGrid
from ..plot import draw_map, draw_robot
from . import interactive_app

__all__ = ["robot_on_map_figure", "robot_on_map", "DEMOS"]


def robot_on_map_figure(grid: OccupancyGrid, x: float, y: float, theta_deg: float, figsize=(7, 4.2)):
    """Draw ``grid`` with a robot at ``(x, y)`` heading ``theta_deg`` degrees, and its local axes.

    The robot's own frame is drawn as two arrows: its x axis (forward, red)
    and y axis (left, green), each 1 m long, mapped into the world with
    :func:`localize.geometry.transform_points`. The title says whether the
    robot stands in free space.

    Examples
    --------
    >>> from localize import maps
    >>> fig = robot_on_map_figure(maps.office(), 10.0, 5.5, 90.0)
    >>> fig.axes[0].get_title()
    'robot at (10.00 m, 5.50 m), heading 90°: free space'
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=figsize)
    draw_map(grid, ax=ax)
    pose = np.array([x, y, np.radians(theta_deg)])
    draw_robot(pose, ax=ax, radius=0.3)
    origin, ex, ey = transform_points(pose, [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    for tip, color in ((ex, "tab:red"), (ey, "tab:green")):
        ax.annotate("", xy=tip, xytext=origin, arrowprops=dict(arrowstyle="->", color=color, lw=2))
    where = "free space" if grid.is_free(pose)[()] else "NOT free (inside an obstacle, unknown or off the map)"
    ax.set_title(f"robot at ({x:.2f} m, {y:.2f} m), heading {theta_deg:.0f}°: {where}")
    xmin, xmax, ymin, ymax = grid.extent
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    fig.tight_layout()
    return fig


def robot_on_map(grid: OccupancyGrid, x: float = 10.0, y: float = 5.5, theta_deg: float = 0.0):
    """Sliders for x, y and heading that redraw :func:`robot_on_map_figure`. Returns the widget."""
    from ipywidgets import FloatSlider

    xmin, xmax, ymin, ymax = grid.extent
    res = grid.resolution

    def figure(x, y, heading):
        return robot_on_map_figure(grid, x, y, heading)

    return interactive_app(
        figure,
        x=FloatSlider(value=x, min=xmin, max=xmax - res, step=res, description="x [m]"),
        y=FloatSlider(value=y, min=ymin, max=ymax - res, step=res, description="y [m]"),
        heading=FloatSlider(value=theta_deg, min=-180.0, max=179.0, step=1.0, description="heading [°]"),
    )


def _demo():
    from .. import maps

    return robot_on_map_figure(maps.office(), 10.0, 5.5, 30.0)


DEMOS = {"robot_on_map": _demo}
