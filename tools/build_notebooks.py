"""Build executed notebooks from their jupytext percent scripts.

    python tools/build_notebooks.py book/src/04_motion_models.py [more.py ...]
    python tools/build_notebooks.py book/04_motion_models.ipynb     # the same: its source is found
    python tools/build_notebooks.py --all

Each chapter's source is ``book/src/NN_name.py`` (jupytext percent), paired with
the notebook ``book/NN_name.ipynb`` (``formats = "ipynb,src//py:percent"`` in
``pyproject.toml``), so that a reader's file browser lists every chapter once.
For each script: convert to .ipynb with jupytext, execute it top to bottom in
the book/ folder with a fresh kernel (nbclient), and write the notebook with
its outputs to book/. The .py file is the source you edit; the .ipynb is
generated, committed with outputs, and checked by ``pytest --nbval``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jupytext
import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
BOOK = ROOT / "book"
SRC = "src"                                  # the twins' folder, relative to the notebooks
FORMATS = f"ipynb,{SRC}//py:percent"         # jupytext's pairing, as in pyproject.toml


def twin_of(notebook: Path) -> Path:
    """The jupytext source of ``book/NN_name.ipynb``: ``book/src/NN_name.py``."""
    return notebook.parent / SRC / (notebook.stem + ".py")


def notebook_of(script: Path) -> Path:
    """The notebook of ``book/src/NN_name.py``: ``book/NN_name.ipynb``."""
    return script.parent.parent / (script.stem + ".ipynb")


def source_path(arg: Path) -> Path:
    """Accept the source, its notebook, or the old place ``book/NN_name.py``; return the source."""
    arg = Path(arg).resolve()
    if arg.suffix == ".ipynb" or arg.parent.name != SRC:
        arg = twin_of(arg.with_suffix(".ipynb"))
    if not arg.exists():
        raise SystemExit(f"{arg}: no such chapter source (sources live in book/{SRC}/NN_name.py)")
    return arg


def strip_volatile(cell) -> None:
    """Drop the stored outputs of cells tagged ``remove-output`` (e.g. wall-clock timings).

    Such output is not part of the book (the HTML build removes it too); a
    reader who runs the notebook sees it live. The cell must also carry
    ``nbval-ignore-output`` so that ``pytest --nbval`` does not compare it.
    """
    tags = cell.get("metadata", {}).get("tags", [])
    if cell.get("cell_type") == "code" and "remove-output" in tags:
        cell["outputs"] = []


def build(py: Path, timeout: int = 900) -> float:
    nb = jupytext.read(py)
    nb.metadata["kernelspec"] = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    nb.metadata.setdefault("jupytext", {})["formats"] = FORMATS
    out = notebook_of(py)
    t0 = time.perf_counter()
    NotebookClient(nb, timeout=timeout, kernel_name="python3",
                   resources={"metadata": {"path": str(out.parent)}}).execute()
    dt = time.perf_counter() - t0
    # keep metadata minimal and machine-independent
    nb.metadata.pop("widgets", None)
    for k, cell in enumerate(nb.cells):
        cell.metadata.pop("execution", None)
        cell.id = f"cell-{k:03d}"  # stable ids: rebuilding changes only what really changed
        strip_volatile(cell)
    nbformat.write(nb, out)
    # the twin as jupytext writes it from the notebook (same cells; metadata in jupytext's order), so
    # that JupyterLab's jupytext never finds the two "different" whichever file a clone touched last
    jupytext.write(nbformat.read(out, as_version=4), py, fmt="py:percent")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scripts", nargs="*", type=Path)
    ap.add_argument("--all", action="store_true", help=f"build every book/{SRC}/NN_*.py")
    args = ap.parse_args(argv)
    scripts = sorted((BOOK / SRC).glob("[0-9][0-9]_*.py")) if args.all else [source_path(s) for s in args.scripts]
    if not scripts:
        ap.error("give scripts or --all")
    for s in scripts:
        dt = build(s)
        print(f"{s}: executed in {dt:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
