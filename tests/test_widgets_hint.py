"""Widget cells show a hint, not a repr, before the notebook runs; labels are not cut off.

An untrusted or not-yet-executed notebook can only show a widget output's
text/plain (or Markdown) form. Every builder in localize.widgets wraps its
container with :func:`localize.widgets.with_hint`, so that form is a sentence
telling the reader what to do, while a live kernel still shows the widget.
"""

from __future__ import annotations

import contextlib
import io

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from localize import maps  # noqa: E402
from localize.sensors import LikelihoodField  # noqa: E402
from localize.widgets import HINT, with_hint  # noqa: E402
from localize.widgets import histogram as wh  # noqa: E402
from localize.widgets import maps as wmaps  # noqa: E402
from localize.widgets import particles as wp  # noqa: E402
from localize.widgets import sensors as ws  # noqa: E402

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks our own tooling, not numerics
pytestmark = pytest.mark.tooling


def _build(factory):
    with contextlib.redirect_stdout(io.StringIO()):       # no frontend: swallow the terminal codes
        w = factory()
    plt.close("all")
    return w


BUILDERS = {
    "hallway_app": wh.hallway_app,
    "tile_world_app": wh.tile_world_app,
    "robot_on_map": lambda: wmaps.robot_on_map(maps.office()),
    "sir_app": wp.sir_app,
    "beam_density_widget": ws.beam_density_widget,
    "pose_scan_widget": lambda: ws.pose_scan_widget(maps.office(), LikelihoodField(maps.office(), 8.0), [0.0], [1.0],
                                                    start=(6.6000000000000005, 5.6000000000000005, 0.3)),
}


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_builders_show_a_hint_before_running_and_the_widget_when_live(name):
    w = _build(BUILDERS[name])
    assert repr(w) == HINT
    bundle = w._repr_mimebundle_()
    assert bundle["text/plain"] == HINT and bundle["text/markdown"] == HINT
    assert "application/vnd.jupyter.widget-view+json" in bundle      # a live kernel still renders the widget
    assert "children=" not in repr(w)


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_no_label_is_cut_off(name):
    w = _build(BUILDERS[name])
    stack, seen = [w], 0
    while stack:
        c = stack.pop()
        if getattr(c, "description", "") and hasattr(getattr(c, "style", None), "description_width"):
            assert c.style.description_width == "initial", (name, c.description)
            seen += 1
        stack.extend(getattr(c, "children", ()))
    assert seen >= 1


def test_with_hint_keeps_the_widget_class_and_a_custom_hint():
    import ipywidgets as W

    box = with_hint(W.HBox([W.FloatSlider(description="a long description")]), hint="run me")
    assert isinstance(box, W.HBox) and repr(box) == "run me"
    other = with_hint(W.HBox([]))
    assert repr(other) == HINT and type(other) is type(box)          # one subclass per widget class


def test_pose_sliders_start_on_cell_centres_and_whole_steps():
    g = maps.office()
    w = _build(BUILDERS["pose_scan_widget"])
    x, y, th = (c.value for c in w.children[:3])
    assert (x, y, th) == ws.pose_scan_start(g, (6.6000000000000005, 5.6000000000000005, 0.3)) == (6.65, 5.65, 18.0)
    r = g.resolution
    for v, lo in ((x, g.origin[0]), (y, g.origin[1])):
        frac = ((v - lo) / r) % 1.0
        assert abs(frac - 0.5) < 1e-6                                  # a centre, far from both edges
    assert abs(th / 2 - round(th / 2)) < 1e-9


def test_pose_scan_figure_axes_do_not_rescale_between_poses():
    g = maps.office()
    model = LikelihoodField(g, 8.0)
    angles = np.radians(np.arange(-90.0, 91.0, 30.0))
    measured = np.full(angles.shape, 3.0)
    limits = []
    for pose in ((6.65, 5.65, 18.0), (1.05, 1.05, -90.0), (18.95, 10.95, 180.0)):
        fig = ws.pose_scan_figure(g, model, angles, measured, *pose)
        limits.append([(ax.get_xlim(), ax.get_ylim()) for ax in fig.axes])
        plt.close(fig)
    assert limits[0] == limits[1] == limits[2]
