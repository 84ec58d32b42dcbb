"""Generate the student homework notebook from its solutions source.

    python tools/make_homework.py          # writes book/homework/homework.ipynb
    python tools/make_homework.py --check  # exit 1 if the committed file is out of date

The source is ``book/homework/homework_solutions.py`` (jupytext percent
format). In every cell tagged ``solution``, each top-level function keeps its
signature and docstring and its body becomes ``raise NotImplementedError``;
helper functions whose names start with ``_`` are dropped. Cells tagged
``teacher`` are dropped. Everything else is copied. The student notebook is stored without outputs: it is meant to fail
until a student fills it in, so ``pytest --nbval`` does not run it
(``conftest.py`` ignores ``book/homework``); ``tests/test_homework.py`` runs
both versions.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import jupytext
import nbformat

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "book" / "homework" / "homework_solutions.py"
TARGET = ROOT / "book" / "homework" / "homework.ipynb"


def stub_source(code: str) -> str:
    """Replace each public function's body by ``raise NotImplementedError``; drop private helpers."""
    tree = ast.parse(code)
    lines = code.splitlines()
    out: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            if node.name.startswith("_"):
                continue
            header_end = node.body[0].lineno - 1
            doc = ast.get_docstring(node)
            if doc is not None:
                header_end = node.body[0].end_lineno
            out.extend(lines[node.lineno - 1 - len(node.decorator_list):header_end])
            out.append("    # YOUR CODE HERE")
            out.append("    raise NotImplementedError")
            out.append("")
            out.append("")
        else:
            out.extend(lines[node.lineno - 1:node.end_lineno])
    return "\n".join(out).rstrip() + "\n"


def build() -> nbformat.NotebookNode:
    nb = jupytext.read(SOURCE)
    nb.cells = [c for c in nb.cells if "teacher" not in c.metadata.get("tags", [])]
    for cell in nb.cells:
        tags = cell.metadata.get("tags", [])
        if cell.cell_type == "code" and "solution" in tags:
            cell.source = stub_source(cell.source).rstrip()
            cell.metadata["tags"] = [t for t in tags if t != "solution"] + ["exercise"]
    for k, cell in enumerate(nb.cells):
        cell.id = f"hw-{k:02d}"  # stable ids: regenerating gives the same file
    nb.metadata.pop("jupytext", None)
    nb.metadata["kernelspec"] = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    return nb


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    text = nbformat.writes(build())
    if "--check" in argv:
        if not TARGET.exists() or TARGET.read_text() != text:
            print(f"{TARGET.relative_to(ROOT)} is out of date: run python tools/make_homework.py")
            return 1
        return 0
    TARGET.write_text(text)
    print(f"wrote {TARGET.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
