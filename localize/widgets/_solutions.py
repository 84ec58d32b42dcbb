"""Solutions stay folded after Run All: a kernel hook that puts a solution cell's output in a closed disclosure.

(Not a widget: private to the package so that the widget conventions and benchmarks skip it; the
book's kernels install it through ``jupyter_kernel_startup.py``.)

The chapters open with their solution cells collapsed (``tools/hide_solutions.py`` sets
``jupyter.outputs_hidden``), but JupyterLab shows a cell's output again whenever the cell
runs, so Run All printed every answer (chapter 3: "45 deg / 30 deg = 1.5 -> not a whole
number of bins") under the exercise. JupyterLab sends each cell's metadata, its tags
included, with the request to run it; :func:`install` registers IPython hooks that, for a
cell tagged ``solution``, capture what the cell prints and displays (text, figures, the value
of its last line) and show it as one closed ``<details>`` element, "Output of the solution
(click to show)", which a click opens. Errors and warnings are shown as usual; other cells
are untouched. Stored outputs do not change: ``pytest --nbval`` and
``tools/build_notebooks.py`` run cells without their metadata.

The book's Jupyter server (``jupyter_server_config.py``) installs it in every kernel it
starts; ``tests/test_widgets_solutions.py`` checks it in a real kernel and
``tests/test_browser.py`` in JupyterLab.
"""

from __future__ import annotations

import base64
import html
from typing import Any

__all__ = ["TAG", "SUMMARY", "folded_html", "install"]

#: The cell tag that marks a solution.
TAG = "solution"
#: What the closed disclosure says.
SUMMARY = "Output of the solution (click to show)"


def _png_src(data: Any) -> str:
    text = base64.b64encode(data).decode("ascii") if isinstance(data, (bytes, bytearray)) else str(data).strip()
    return f'<img src="data:image/png;base64,{text}"/>'


def folded_html(stdout: str, outputs: list[dict]) -> str:
    """One closed ``<details>`` holding printed text and display outputs (mime bundles), in order.

    Examples
    --------
    >>> page = folded_html("45 / 30 = 1.5\\n", [{"text/plain": "<Figure size 640x480 with 1 Axes>"}])
    >>> page.startswith("<details><summary>Output of the solution (click to show)</summary>")
    True
    >>> "<pre>45 / 30 = 1.5\\n</pre>" in page, page.endswith("</details>")
    (True, True)
    """
    parts = [f"<details><summary>{SUMMARY}</summary>"]
    if stdout:
        parts.append(f"<pre>{html.escape(stdout)}</pre>")
    for data in outputs:
        if "image/png" in data:
            parts.append(_png_src(data["image/png"]))
        elif "text/html" in data:
            parts.append(str(data["text/html"]))
        elif "text/plain" in data:
            parts.append(f"<pre>{html.escape(str(data['text/plain']))}</pre>")
    parts.append("</details>")
    return "".join(parts)


class _Folder:
    """The pre/post run-cell hooks of one IPython shell."""

    def __init__(self, shell) -> None:
        self.shell = shell
        self.active = None          # (capture_output, its CapturedIO, the display hook it replaced)

    def _tags(self) -> list:
        kernel = getattr(self.shell, "kernel", None)
        try:
            parent = kernel.get_parent() if kernel is not None else {}
        except Exception:  # noqa: BLE001 - an unusual kernel: behave as without the hook
            return []
        tags = (parent or {}).get("metadata", {}).get("tags", [])
        return tags if isinstance(tags, list) else []

    def pre_run_cell(self, info=None) -> None:
        if self.active is not None or TAG not in self._tags():
            return
        from IPython.core.displayhook import CapturingDisplayHook
        from IPython.utils.capture import capture_output

        cap = capture_output(stdout=True, stderr=False, display=True)
        io = cap.__enter__()
        hook = self.shell.display_trap.hook                # the value of the cell's last line, too
        self.shell.display_trap.hook = CapturingDisplayHook(shell=self.shell, outputs=io._outputs)
        self.active = (cap, io, hook)

    def post_run_cell(self, result=None) -> None:
        if self.active is None:
            return
        cap, io, hook = self.active
        self.active = None
        self.shell.display_trap.hook = hook
        cap.__exit__(None, None, None)
        outputs = [o["data"] for o in io._outputs]
        widgets = [d for d in outputs if "application/vnd.jupyter.widget-view+json" in d]
        shown = [d for d in outputs if d not in widgets]
        widgets = [d for d in widgets if _widget_alive(d)]  # a closed one (a finished progress bar) is gone
        from IPython.display import display

        if io.stdout or shown:
            display({"text/html": folded_html(io.stdout, shown),
                     "text/plain": f"{SUMMARY[:-len(' (click to show)')]}: hidden (open it in JupyterLab)"},
                    raw=True)
        for d in widgets:                                   # a widget cannot live inside HTML: show it as is
            display(d, raw=True)


def _widget_alive(data: dict) -> bool:
    """Whether the widget a widget-view bundle shows still exists (tqdm closes its bars when they finish)."""
    try:
        from ipywidgets.widgets.widget import _instances
    except ImportError:  # pragma: no cover - another ipywidgets layout: keep the view
        return True
    return data["application/vnd.jupyter.widget-view+json"].get("model_id") in _instances


def install(shell=None) -> bool:
    """Fold the output of cells tagged ``solution`` in this IPython kernel; True if installed.

    Does nothing (returns False) outside an IPython kernel; installing twice keeps one hook.

    Examples
    --------
    >>> install()            # outside a kernel
    False
    """
    if shell is None:
        try:
            from IPython import get_ipython
        except ImportError:  # pragma: no cover - IPython comes with ipywidgets
            return False
        shell = get_ipython()
    if shell is None or getattr(shell, "kernel", None) is None:
        return False
    for folder in getattr(shell, "_localize_solution_folders", []):
        shell.events.unregister("pre_run_cell", folder.pre_run_cell)
        shell.events.unregister("post_run_cell", folder.post_run_cell)
    folder = _Folder(shell)
    shell.events.register("pre_run_cell", folder.pre_run_cell)
    shell.events.register("post_run_cell", folder.post_run_cell)
    shell._localize_solution_folders = [folder]
    return True
