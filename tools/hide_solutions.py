"""Hide exercise solutions from the reader, in JupyterLab and in the HTML book, with a way to reveal them.

    python tools/hide_solutions.py            # update book/NN_*.ipynb and book/src/NN_*.py in place
    python tools/hide_solutions.py --check    # exit 1 if a solution is not hidden
    python tools/hide_solutions.py 06_particle   # only the chapters whose names contain this

Cells tagged ``solution`` are made collapsible in both places where students read:

* a **code** cell gets the ``hide-cell`` tag (the HTML book shows a "Show code
  cell" toggle in its place) and the standard notebook metadata
  ``jupyter.source_hidden`` and ``jupyter.outputs_hidden`` (JupyterLab opens it
  collapsed: a bar with the cell's first line, expanded by a click). Its first
  line becomes the comment ``# Solution (click to show)`` so that the collapsed
  bar says what it hides;
* a **markdown** cell is wrapped in an HTML ``<details>`` element with the
  summary "Solution". JupyterLab and Jupyter Book (MyST) both render it as a
  closed disclosure triangle with the markdown and the ``$math$`` inside
  rendered, which neither does for a MyST ``{admonition}`` (JupyterLab showed
  its raw markup). Blank lines separate the HTML tags from the markdown, as
  CommonMark requires for the inside to be parsed as markdown, and headings
  inside become bold lines (a heading inside would break the page's sections).

JupyterLab shows a code cell's output again when the cell runs (``outputs_hidden`` is reset), so
after Run All the answers would be printed under the exercises: the kernels of the book's
Jupyter server (``jupyter_server_config.py``) fold the output of every cell tagged ``solution``
into a closed "Output of the solution" disclosure (:mod:`localize.widgets._solutions`).

Cells in the older MyST admonition form are converted. The notebook and its
jupytext twin are updated together, without re-executing anything, so stored
outputs are kept. ``tests/test_book.py`` checks every chapter with
:func:`is_hidden` and renders the markdown solutions as both readers do.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import jupytext
import nbformat

ROOT = Path(__file__).resolve().parents[1]
OPEN = "<details>\n<summary><b>Solution</b> (click to show)</summary>\n\n"
CLOSE = "\n\n</details>"
CODE_HEAD = "# Solution (click to show)"
_ADMONITION = re.compile(r"^\s*````\{admonition\} Solution\n(?::class:[^\n]*\n)?\n?(.*?)\n?````\s*$", re.S)


def _markdown_body(src: str) -> str:
    """The solution's markdown without any wrapper: old admonition or details form, or plain."""
    src = src.strip()
    m = _ADMONITION.match(src)
    if m:
        return m.group(1).strip()
    if src.startswith("<details>") and src.endswith("</details>"):
        inner = src[len("<details>"):-len("</details>")]
        inner = re.sub(r"^\s*<summary>.*?</summary>", "", inner, count=1, flags=re.S)
        return inner.strip()
    return src


def hide(cell) -> bool:
    """Make one solution cell collapsible (JupyterLab and HTML book); return True if it changed."""
    tags = list(cell.metadata.get("tags", []))
    if "solution" not in tags:
        return False
    before = (cell.source, repr(cell.metadata))
    if cell.cell_type == "code":
        if "hide-cell" not in tags:
            cell.metadata["tags"] = tags + ["hide-cell"]
        jup = dict(cell.metadata.get("jupyter", {}))
        jup.update(source_hidden=True, outputs_hidden=True)
        cell.metadata["jupyter"] = jup
        if not cell.source.startswith(CODE_HEAD):
            cell.source = CODE_HEAD + "\n" + cell.source
    else:
        body = re.sub(r"^#{1,6}\s+(.*)$", r"**\1**", _markdown_body(cell.source), flags=re.M)
        cell.source = OPEN + body + CLOSE
    return (cell.source, repr(cell.metadata)) != before


def is_hidden(cell) -> bool:
    """True unless ``cell`` is a solution that a reader of JupyterLab or of the HTML book would see at once."""
    tags = cell.metadata.get("tags", [])
    if "solution" not in tags:
        return True
    if cell.cell_type == "code":
        jup = cell.metadata.get("jupyter", {})
        return ("hide-cell" in tags and jup.get("source_hidden") is True and jup.get("outputs_hidden") is True
                and cell.source.startswith(CODE_HEAD))
    src = cell.source
    return (src.startswith(OPEN) and src.endswith(CLOSE) and "{admonition}" not in src
            and not re.search(r"^#{1,6}\s", src, re.M))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    bad = []
    only = [a for a in argv if not a.startswith("--")]
    for nb_path in sorted((ROOT / "book").glob("[0-9][0-9]_*.ipynb")):
        if only and not any(o in nb_path.name for o in only):
            continue
        py_path = nb_path.parent / "src" / (nb_path.stem + ".py")   # the jupytext twin
        nb = nbformat.read(nb_path, as_version=4)
        if "--check" in argv:
            bad += [f"{nb_path.name} cell {k}" for k, c in enumerate(nb.cells) if not is_hidden(c)]
            continue
        if sum(hide(c) for c in nb.cells):
            nbformat.write(nb, nb_path)
            print(f"updated {nb_path.name}")
        if py_path.exists():
            twin = jupytext.read(py_path)
            if sum(hide(c) for c in twin.cells):
                jupytext.write(twin, py_path, fmt="py:percent")
                print(f"updated {py_path.name}")
    if bad:
        print("solutions not hidden (run python tools/hide_solutions.py):\n  " + "\n  ".join(bad))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
