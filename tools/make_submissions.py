"""Generate a class of homework submissions for testing and benchmarking the grader.

    python tools/make_submissions.py DIR            # the eight kinds below, one each
    python tools/make_submissions.py DIR --count 30 # thirty: the kinds repeated, numbered

Each submission is the student notebook (book/homework/homework.ipynb) filled
in from the teacher's solutions (teacher/homework_solutions.py), then changed
the way a student's might be: with a classic mistake, an endless loop, or an
attempt to cheat. :data:`KINDS` says what the grader must give each one.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jupytext
import nbformat

ROOT = Path(__file__).resolve().parents[1]
SOLUTIONS = ROOT / "teacher" / "homework_solutions.py"
TEMPLATE = ROOT / "book" / "homework" / "homework.ipynb"

#: A change to one function of the solutions: (function, right text, wrong text).
Change = tuple[str, str, str]

#: name -> (changes to the solutions or None for the empty template, extra code cell or "", what the grader says)
KINDS: dict[str, tuple[list[Change] | None, str, str]] = {
    "full": ([], "", "full marks"),
    "empty": (None, "", "zero: every function raises NotImplementedError"),
    "wraps": ([("predict_stop", "min(max(src + offset + m - c, 0), n - 1)", "(src + offset + m - c) % n")], "",
              "section 12 zero, hint: the hallway wraps around"),
    "millimetres": ([("read_xy_log", "values[4:][::-1] / 1000.0", "values[4:][::-1]")], "",
                    "section 14 zero, hint: millimetres"),
    "no_q": ([("in_gate", "H @ cov @ H.T + Q", "H @ cov @ H.T")], "",
             "section 15 zero, hint: without the sensor noise Q"),
    "loops": ([("normalize", "p = np.asarray(p, dtype=float)\n", "p = np.asarray(p, dtype=float)\n"
                "    while True:\n        pass\n")], "", "section 1 zero, stopped after the check's time limit"),
    "deletes": ([], "import os\n\nos.remove('.grader/job.json')", "zero for tampering: deletes a grader file"),
    "imports_solution": ([], "try:\n    from homework_solutions import *\nexcept ImportError:\n    pass",
                         "zero for tampering: imports the solution module"),
    "patches_check": ([("normalize", "return p / p.sum()", "return p")],
                      "check.normalize = lambda fn: True\nlocalize_check = check", "zero for tampering: replaces "
                      "localize.check.normalize"),
}


def filled(changes: list[Change] | None, extra: str = "") -> nbformat.NotebookNode:
    """The student notebook with every exercise answered by the solutions (changed by ``changes``)."""
    template = nbformat.read(TEMPLATE, as_version=4)
    if changes is None:
        nb = template
    else:
        solutions = [c for c in jupytext.read(SOLUTIONS).cells if "teacher" not in c.metadata.get("tags", [])]
        answers = [c.source for c in solutions if "solution" in c.metadata.get("tags", [])]
        nb = template
        k = 0
        for cell in nb.cells:
            if "exercise" in cell.metadata.get("tags", []):
                cell.source = answers[k]
                k += 1
        for function, right, wrong in changes:
            cell = next(c for c in nb.cells if f"def {function}(" in c.source)
            if right not in cell.source:
                raise ValueError(f"the solution of {function} no longer contains {right!r}: update KINDS")
            cell.source = cell.source.replace(right, wrong)
    if extra:
        nb.cells.insert(2, nbformat.v4.new_code_cell(extra))
    for k, cell in enumerate(nb.cells):
        cell.id = f"sub-{k:02d}"
    return nb


def make_class(folder: str | Path, count: int | None = None) -> dict[str, str]:
    """Write the submissions into ``folder``; return each student's kind (a name of :data:`KINDS`)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = list(KINDS)
    students = ({n: n for n in names} if count is None
                else {f"student{i + 1:02d}_{names[i % len(names)]}": names[i % len(names)] for i in range(count)})
    for student, kind in students.items():
        changes, extra, _ = KINDS[kind]
        nbformat.write(filled(changes, extra), folder / f"{student}.ipynb")
    return students


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("--count", type=int, default=None)
    args = parser.parse_args(argv)
    made = make_class(args.folder, args.count)
    print(f"wrote {len(made)} submissions into {args.folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
