"""Hide exercise solutions in the HTML book (they stay visible in the notebooks).

    python tools/hide_solutions.py            # update book/NN_*.py and .ipynb in place
    python tools/hide_solutions.py --check    # exit 1 if a solution is not hidden
    python tools/hide_solutions.py 06_particle   # only the chapters whose names contain this

Cells tagged ``solution`` are made collapsible in the Jupyter Book build:

* a code cell also gets the ``hide-cell`` tag (myst-nb shows a "Show code
  cell" toggle in place of the cell);
* a markdown cell is wrapped in a MyST ``{admonition}`` with the ``dropdown``
  class, titled "Solution" (markdown headings inside are turned into bold
  lines, since a dropdown cannot hold headings).

The notebook and its jupytext twin are updated together, without
re-executing anything, so stored outputs are kept.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import jupytext
import nbformat

ROOT = Path(__file__).resolve().parents[1]
FENCE = "````{admonition} Solution\n:class: dropdown, tip\n\n"


def hide(cell) -> bool:
    """Make one solution cell collapsible; return True if it changed."""
    tags = list(cell.metadata.get("tags", []))
    if "solution" not in tags:
        return False
    if cell.cell_type == "code":
        if "hide-cell" in tags:
            return False
        cell.metadata["tags"] = tags + ["hide-cell"]
        return True
    src = cell.source
    if src.lstrip().startswith("````{admonition} Solution"):
        return False
    body = re.sub(r"^#{1,6}\s+(.*)$", r"**\1**", src.strip(), flags=re.M)
    cell.source = FENCE + body + "\n````"
    return True


def is_hidden(cell) -> bool:
    tags = cell.metadata.get("tags", [])
    if "solution" not in tags:
        return True
    if cell.cell_type == "code":
        return "hide-cell" in tags
    return cell.source.lstrip().startswith("````{admonition} Solution")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    bad = []
    only = [a for a in argv if not a.startswith("--")]
    for nb_path in sorted((ROOT / "book").glob("[0-9][0-9]_*.ipynb")):
        if only and not any(o in nb_path.name for o in only):
            continue
        py_path = nb_path.with_suffix(".py")
        nb = nbformat.read(nb_path, as_version=4)
        if "--check" in argv:
            bad += [f"{nb_path.name} cell {k}" for k, c in enumerate(nb.cells) if not is_hidden(c)]
            continue
        if sum(hide(c) for c in nb.cells):
            nbformat.write(nb, nb_path)
            if py_path.exists():
                twin = jupytext.read(py_path)
                for c in twin.cells:
                    hide(c)
                jupytext.write(twin, py_path, fmt="py:percent")
            print(f"updated {nb_path.name} and its twin")
    if bad:
        print("solutions not hidden (run python tools/hide_solutions.py):\n  " + "\n  ".join(bad))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
