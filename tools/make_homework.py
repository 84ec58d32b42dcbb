"""Generate the student homework notebook and the otter-grader assignment from the solutions source.

    python tools/make_homework.py          # writes book/homework/homework.ipynb and teacher/otter/homework.ipynb
    python tools/make_homework.py --check  # exit 1 if a committed file is out of date

The source is ``teacher/homework_solutions.py`` (jupytext percent format),
kept outside ``book/`` so that the student's folder holds only what a student
gets. In every cell tagged ``solution``, each top-level function keeps its
signature and docstring and its body becomes ``raise NotImplementedError``;
helper functions whose names start with ``_`` are dropped. Cells tagged
``teacher`` are dropped. Everything else is copied. The student notebook is stored without outputs: it is meant to fail
until a student fills it in, so ``pytest --nbval`` does not run it
(``conftest.py`` ignores ``book/homework``); ``tests/test_homework.py`` runs
both versions.

The otter-grader assignment ``teacher/otter/homework.ipynb`` is the same
notebook in otter's format (https://otter-grader.readthedocs.io, "Creating
Assignments"): one question per section of :data:`localize.grade.sections.SECTIONS`
with its points, the solution bodies between ``# BEGIN SOLUTION`` and
``# END SOLUTION``, and one test per function that calls the same
``localize.check`` function as the student notebook and prints its report
when it fails (so the hints are the check's own). ``otter assign
teacher/otter/homework.ipynb dist/`` turns it into a student notebook and the
autograder zip a teacher uploads to Gradescope or runs with ``otter run``.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import jupytext
import nbformat

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "teacher" / "homework_solutions.py"
TARGET = ROOT / "book" / "homework" / "homework.ipynb"
OTTER = ROOT / "teacher" / "otter" / "homework.ipynb"

sys.path.insert(0, str(ROOT))
from localize.grade.sections import SECTIONS  # noqa: E402

#: otter assign's settings (https://otter-grader.readthedocs.io/en/latest/otter_assign/notebook_format.html)
OTTER_CONFIG = """# ASSIGNMENT CONFIG
name: homework
init_cell: true
check_all_cell: false
export_cell: false
run_tests: false
solutions_pdf: false
"""


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
    nb.metadata["otter"] = {"assignment_name": "homework"}  # `otter run` grades this notebook as it is
    nb.metadata["kernelspec"] = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    return nb


def otter_source(code: str) -> str:
    """Mark each public function's body, and each private helper, as otter's ``# BEGIN/END SOLUTION`` blocks."""
    tree = ast.parse(code)
    lines = code.splitlines()
    out: list[str] = []
    for node in tree.body:
        first = node.lineno - 1 - len(getattr(node, "decorator_list", []))
        if isinstance(node, ast.FunctionDef) and node.name.startswith("_"):
            out += ["# BEGIN SOLUTION NO PROMPT", *lines[first:node.end_lineno], "# END SOLUTION", "", ""]
        elif isinstance(node, ast.FunctionDef):
            body_start = node.body[0].lineno - 1
            if ast.get_docstring(node) is not None:
                body_start = node.body[0].end_lineno
            out += [*lines[first:body_start], "    # BEGIN SOLUTION", *lines[body_start:node.end_lineno],
                    "    # END SOLUTION", "", ""]
        else:
            out.extend(lines[first:node.end_lineno])
    return "\n".join(out).rstrip() + "\n"


def _test_cell(task) -> nbformat.NotebookNode:
    """One otter test: the student notebook's own check call; its report (with the hints) is the failure diff."""
    cell = nbformat.v4.new_code_cell(f"report = {task.call()}\nprint(report.passed or report)")
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text="True\n")]
    return cell


def build_otter() -> nbformat.NotebookNode:
    """The otter-grader master notebook: one question per section, with the points of localize.grade.sections."""
    nb = jupytext.read(SOURCE)
    by_function = {t.function: (s, t) for s in SECTIONS for t in s.tasks}
    cells = [nbformat.v4.new_raw_cell(OTTER_CONFIG)]
    for cell in nb.cells:
        tags = cell.metadata.get("tags", [])
        if "teacher" in tags:
            continue
        if cell.cell_type == "code" and "solution" in tags:
            names = [n.name for n in ast.parse(cell.source).body if isinstance(n, ast.FunctionDef)
                     and not n.name.startswith("_")]
            section = by_function[names[0]][0]
            assert {by_function[n][0] for n in names} == {section}, f"one solution cell, one section: {names}"
            head = f"# BEGIN QUESTION\nname: q{section.number}\npoints:\n"
            head += "".join(f"  - {t.points}\n" for t in section.tasks)
            cells += [nbformat.v4.new_raw_cell(head.rstrip()),
                      nbformat.v4.new_raw_cell("# BEGIN SOLUTION"),
                      nbformat.v4.new_code_cell(otter_source(cell.source).rstrip()),
                      nbformat.v4.new_raw_cell("# END SOLUTION"),
                      nbformat.v4.new_raw_cell("# BEGIN TESTS"),
                      *[_test_cell(t) for t in section.tasks],
                      nbformat.v4.new_raw_cell("# END TESTS"),
                      nbformat.v4.new_raw_cell("# END QUESTION")]
            continue
        new = (nbformat.v4.new_code_cell(cell.source) if cell.cell_type == "code"
               else nbformat.v4.new_markdown_cell(cell.source))
        cells.append(new)
    # the question's prompt (the markdown before the solution) belongs inside the question
    for k in range(1, len(cells)):
        if cells[k].cell_type == "raw" and cells[k].source.startswith("# BEGIN QUESTION") \
                and cells[k - 1].cell_type == "markdown":
            cells[k - 1], cells[k] = cells[k], cells[k - 1]
    out = nbformat.v4.new_notebook(cells=cells)
    for k, cell in enumerate(out.cells):
        cell.id = f"otter-{k:02d}"
    out.metadata["kernelspec"] = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    targets = {TARGET: nbformat.writes(build()), OTTER: nbformat.writes(build_otter())}
    if "--check" in argv:
        stale = [t for t, text in targets.items() if not t.exists() or t.read_text() != text]
        for t in stale:
            print(f"{t.relative_to(ROOT)} is out of date: run python tools/make_homework.py")
        return 1 if stale else 0
    for t, text in targets.items():
        t.parent.mkdir(parents=True, exist_ok=True)
        t.write_text(text)
        print(f"wrote {t.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
