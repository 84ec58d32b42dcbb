"""Every widget of the book shows its figure in a real Jupyter kernel, when built and when a control moves.

The unit tests of the widget modules call the callbacks directly; what they
cannot see is whether the figure reaches the reader. Here one ipykernel (the
kernel a reader's JupyterLab starts: the inline matplotlib backend, no
``%matplotlib`` magic) builds each widget as its chapter does, and the test
speaks the widget protocol to it as the browser would:

* executing the builder must send a PNG figure (an ``image/png``
  ``display_data``) *into the widget's Output area* (while one of its Output
  widgets has taken the cell's messages, ``msg_id`` set to the request), and
  no figure outside it (a stray pyplot figure shown below the widget);
* a ``comm_msg`` that sets a control's value, what the frontend sends when a
  reader moves a slider, must again send a PNG into the Output area;
* widgets that draw into an ``ipywidgets.Image`` instead (the motion models)
  must send a new image value.

Before the fix of issue 40, ``grid_resolution_widget`` (chapter 3) and
``tuning_widget`` (chapter 9) failed both checks: ``ipywidgets.interactive``
displays nothing that its callback returns, and their figures are not pyplot
figures that the inline backend would show.
"""

from __future__ import annotations

import json
import os
import queue
import time
from pathlib import Path

import pytest

jupyter_client = pytest.importorskip("jupyter_client")
pytest.importorskip("ipykernel")

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks our own tooling, not numerics
pytestmark = pytest.mark.tooling

ROOT = Path(__file__).resolve().parents[1]

# name -> (code that builds the widget as `w`, code giving the control to move as `c`, its new value)
WIDGETS = {
    "preface robot_on_map": ("from localize import maps\nfrom localize.widgets.maps import robot_on_map\n"
                             "w = robot_on_map(maps.office())", "w.children[2]", 30.0),
    "ch1 hallway_app": ("from localize.widgets.histogram import hallway_app\nw = hallway_app()",
                        "w.children[1]", 0.3),
    "ch2 tile_world_app": ("from localize.widgets.histogram import tile_world_app\nw = tile_world_app()",
                           "w.children[0].children[0]", 0.7),
    "ch3 grid_resolution_widget": ("from localize.widgets.gridloc import grid_resolution_widget\n"
                                   "w = grid_resolution_widget(0.5, 12)", "w.children[1]", 24),
    "ch4 odometry_widget": ("from localize.widgets.motion import odometry_widget\nw = odometry_widget(n=50)",
                            "w.sliders['alpha1']", 0.3),
    "ch4 velocity_widget": ("from localize.widgets.motion import velocity_widget\n"
                            "w = velocity_widget(n=50, resolution=20)", "w.sliders['omega']", -1.0),
    "ch5 beam_density_widget": ("from localize.widgets.sensors import beam_density_widget\n"
                                "w = beam_density_widget()", "w.children[4]", 0.4),
    "ch5 pose_scan_widget": ("import numpy as np\nfrom localize import maps\nfrom localize.sensors import "
                             "LikelihoodField\nfrom localize.widgets.sensors import pose_scan_widget\n"
                             "g = maps.office()\nw = pose_scan_widget(g, LikelihoodField(g, 8.0), [0.0, 1.0], "
                             "[1.0, 2.0], start=(10.0, 5.5, 0.0))", "w.children[0]", 10.5),
    "ch6 sir_app": ("from localize.widgets.particles import sir_app\nw = sir_app()", "w.children[0]", 40),
    "ch7 mcl_player": ("from localize.widgets.mcl import mcl_player\nw = mcl_player(n_steps=3, n_particles=200)",
                       "w.children[0].children[0].children[1]", 1),
    "ch8 kidnap_widget": ("from localize.widgets.recovery import kidnap_widget\nw = kidnap_widget(n_particles=300)",
                          "w.children[2]", 0.3),
    "ch9 tuning_widget": ("from localize.widgets.tuning import tuning_widget\nw = tuning_widget()",
                          "w.children[1]", 0.3),
    "ch9 reallog_widget": ("from localize.widgets.reallog import reallog_widget\nw = reallog_widget()",
                           "w.children[0]", 10),
    "ch10 noise_widget": ("from localize.widgets.ekf import noise_widget\nw = noise_widget(n_particles=100)",
                          "w.children[0].children[2]", 3),
}


@pytest.fixture(scope="module")
def kernel():
    """A python3 ipykernel as JupyterLab starts it (own backend choice), importing this checkout."""
    env = dict(os.environ)
    env.pop("MPLBACKEND", None)           # the kernel picks the inline backend itself, as for a reader
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    km = jupyter_client.KernelManager(kernel_name="python3")
    km.start_kernel(env=env, cwd=str(ROOT / "book"))
    kc = km.client()
    kc.start_channels()
    try:
        kc.wait_for_ready(timeout=120)
        yield kc
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)


def _messages(kc, parent_id: str, timeout: float = 300.0) -> list[dict]:
    """The iopub messages of one request, in order, until the kernel goes idle for it."""
    out, deadline = [], time.monotonic() + timeout
    while True:
        try:
            msg = kc.get_iopub_msg(timeout=max(0.1, deadline - time.monotonic()))
        except queue.Empty as exc:
            raise AssertionError(f"the kernel did not finish request {parent_id} within {timeout:.0f} s") from exc
        if msg["parent_header"].get("msg_id") != parent_id:
            continue
        out.append(msg)
        if msg["msg_type"] == "status" and msg["content"]["execution_state"] == "idle":
            return out


def _execute(kc, code: str) -> list[dict]:
    msgs = _messages(kc, kc.execute(code))
    errors = [m["content"] for m in msgs if m["msg_type"] == "error"]
    assert not errors, "\n".join("\n".join(e["traceback"]) for e in errors)
    return msgs


def _figures(msgs: list[dict], parent_id: str) -> dict[str, int]:
    """Count PNG figures inside an Output widget (one that took this request's messages), outside, and Image updates."""
    capturing: set[str] = set()
    counts = {"inside": 0, "outside": 0, "image_value": 0, "stderr": 0}
    for m in msgs:
        t, c = m["msg_type"], m["content"]
        if t == "comm_msg" and c.get("data", {}).get("method") == "update":
            state = c["data"].get("state", {})
            if "msg_id" in state:
                (capturing.add if state["msg_id"] == parent_id else capturing.discard)(c["comm_id"])
            if ["value"] in c["data"].get("buffer_paths", []) and "format" not in state:
                counts["image_value"] += 1
        elif t in ("display_data", "update_display_data") and "image/png" in c.get("data", {}):
            counts["inside" if capturing else "outside"] += 1
        elif t == "stream" and c.get("name") == "stderr":
            counts["stderr"] += 1
    return counts


def _comm_update(kc, comm_id: str, state: dict) -> str:
    """Send what the frontend sends when a control moves; returns the request id."""
    msg = kc.session.msg("comm_msg", {"comm_id": comm_id, "data": {"method": "update", "state": state,
                                                                     "buffer_paths": []}})
    kc.shell_channel.send(msg)
    return msg["header"]["msg_id"]


@pytest.mark.parametrize("name", list(WIDGETS))
def test_widget_shows_its_figure_when_built_and_when_a_control_moves(kernel, name):
    build, control, value = WIDGETS[name]
    msg_id = kernel.execute(build + "\ndisplay(w)")           # a chapter's widget cell
    built = _figures(_messages(kernel, msg_id), msg_id)
    if "widgets.motion" in build:                 # draws into an ipywidgets.Image, created with its first picture
        assert built["outside"] == 0, built
    else:
        assert built["inside"] >= 1, f"{name}: building the widget showed no figure in it: {built}"
        assert built["outside"] == 0, f"{name}: a figure appeared outside the widget: {built}"
    # a selection (toggle buttons, dropdown) syncs the index of its option, a slider its value
    reply = _execute(kernel, f"import json\nc = {control}\nsel = hasattr(c, 'index')\n"
                             f"print(json.dumps([c.model_id, 'index' if sel else 'value', c.value, "
                             f"list(c._options_values).index({value!r}) if sel else {value!r}]))")
    comm_id, key, old, new = json.loads("".join(m["content"]["text"] for m in reply if m["msg_type"] == "stream"))
    assert old != value, f"{name}: pick another value for the test"
    req = _comm_update(kernel, comm_id, {key: new})
    moved = _figures(_messages(kernel, req), req)
    assert moved["stderr"] == 0, f"{name}: the redraw wrote to stderr: {moved}"
    if "widgets.motion" in build:
        assert moved["image_value"] >= 1, f"{name}: moving a slider sent no new image: {moved}"
    else:
        assert moved["inside"] >= 1, f"{name}: moving a control showed no figure in the widget: {moved}"
        assert moved["outside"] == 0, f"{name}: a figure appeared outside the widget: {moved}"


def test_every_widget_of_the_book_is_checked_here():
    """A widget that a chapter builds (a builder call alone on a line, as widget cells do) is in WIDGETS."""
    import re

    called = set()
    for src in sorted((ROOT / "book" / "src").glob("[0-9][0-9]_*.py")):
        called |= set(re.findall(r"^(\w+(?:_widget|_app|_player)|robot_on_map)\(", src.read_text(), re.M))
    assert called, "no widget builder call found in book/src"
    checked = {re.search(r"w = (\w+)\(", build).group(1) for build, _, _ in WIDGETS.values()}
    assert called <= checked, f"widgets of the book not checked in a kernel here: {sorted(called - checked)}"
