"""Solution outputs stay folded when JupyterLab runs them (localize.widgets._solutions), in a real kernel.

The kernel is started as the book's Jupyter server starts it (``PYTHONSTARTUP`` =
``jupyter_kernel_startup.py``), and cells are sent as JupyterLab sends them: the cell's metadata,
tags included, as the execute request's metadata.
"""

from __future__ import annotations

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


@pytest.fixture(scope="module")
def kernel():
    env = dict(os.environ)
    env.pop("MPLBACKEND", None)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    env["PYTHONSTARTUP"] = str(ROOT / "jupyter_kernel_startup.py")
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


def run_cell(kc, code: str, tags=()) -> list[dict]:
    """Execute like JupyterLab: the cell's metadata goes with the request. Returns its iopub messages."""
    msg = kc.session.msg("execute_request", {"code": code, "silent": False, "store_history": True,
                                             "user_expressions": {}, "allow_stdin": False, "stop_on_error": True},
                         metadata={"tags": list(tags), "cellId": "test"})
    kc.shell_channel.send(msg)
    out, deadline = [], time.monotonic() + 120
    while True:
        try:
            m = kc.get_iopub_msg(timeout=max(0.1, deadline - time.monotonic()))
        except queue.Empty as exc:
            raise AssertionError("the kernel did not finish the cell") from exc
        if m["parent_header"].get("msg_id") != msg["header"]["msg_id"]:
            continue
        out.append(m)
        if m["msg_type"] == "status" and m["content"]["execution_state"] == "idle":
            return out


SOLUTION = """import matplotlib.pyplot as plt
print("45 deg / 30 deg = 1.5 -> not a whole number of bins")
plt.plot([0, 1], [1, 0])
plt.show()
6 * 7"""


def test_a_solution_cells_output_is_one_closed_disclosure(kernel):
    msgs = run_cell(kernel, SOLUTION, tags=["solution", "hide-cell"])
    kinds = [m["msg_type"] for m in msgs if m["msg_type"] not in ("status", "execute_input")]
    assert kinds == ["display_data"], kinds                      # no stream, no figure, no execute_result
    data = next(m for m in msgs if m["msg_type"] == "display_data")["content"]["data"]
    page = data["text/html"]
    assert page.startswith("<details><summary>Output of the solution (click to show)</summary>")
    assert "45 deg / 30 deg = 1.5" in page and "<img src=\"data:image/png;base64,iVBOR" in page and "42" in page
    assert "1.5" not in data["text/plain"]


def test_other_cells_and_errors_are_shown_as_usual(kernel):
    msgs = run_cell(kernel, 'print("visible")')
    assert [m["content"]["text"] for m in msgs if m["msg_type"] == "stream"] == ["visible\n"]
    msgs = run_cell(kernel, 'print("before")\n1 / 0', tags=["solution"])
    assert any(m["msg_type"] == "error" for m in msgs)
    folded = [m for m in msgs if m["msg_type"] == "display_data"]
    assert len(folded) == 1 and "before" in folded[0]["content"]["data"]["text/html"]
    msgs = run_cell(kernel, "'after an error'")                   # the hook has let go of the output
    assert [m["content"]["data"]["text/plain"] for m in msgs if m["msg_type"] == "execute_result"] == [
        "'after an error'"]


def test_a_finished_progress_bar_of_a_solution_is_not_shown_again(kernel):
    """A closed widget (tqdm's notebook bar with leave=False) cannot be displayed again: it is dropped."""
    msgs = run_cell(kernel, "import ipywidgets as W\nfrom IPython.display import display\n"
                            "bar = W.IntProgress(3)\ndisplay(bar)\nprint('done')\nbar.close()\n"
                            "kept = W.IntSlider(4)\ndisplay(kept)", tags=["solution"])
    shown = [m["content"]["data"] for m in msgs if m["msg_type"] == "display_data"]
    assert len(shown) == 2 and "done" in shown[0]["text/html"], shown       # the fold, then the live slider
    assert "application/vnd.jupyter.widget-view+json" in shown[1]
