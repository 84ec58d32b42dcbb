"""The homework: its solutions pass every check, its student template fails them gracefully."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import jupytext
import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
HW = ROOT / "book" / "homework"
#: The teachers' source, outside the student's folder (tools/make_homework.py generates the student notebook from it).
SOLUTIONS = ROOT / "teacher" / "homework_solutions.py"
#: Functions the student writes (one stub each in the template, one checked report each).
N_EXERCISES = 21


def _run(nb, tmp_path):
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for out in cell.get("outputs", []):
            assert out.output_type != "error", f"cell raised: {out.get('ename')}: {out.get('evalue')}"
            if "text" in out:
                texts.append(out.text)
            elif "text/plain" in out.get("data", {}):
                texts.append(out.data["text/plain"])
    return "\n".join(texts)


def test_template_is_generated_from_solutions():
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "make_homework.py"), "--check"], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_template_has_stubs_and_no_solutions():
    nb = nbformat.read(HW / "homework.ipynb", as_version=4)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert code.count("raise NotImplementedError") == N_EXERCISES
    for answer in ("np.searchsorted", "math.erf", "min(max(src", "kld_bound(len(", "[::-1] / 1000",
                   "np.linalg.solve(S, y)"):
        assert answer not in code, answer
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")


def test_the_student_folder_holds_only_what_a_student_gets():
    assert sorted(p.name for p in HW.iterdir() if not p.name.startswith(".")) == ["homework.ipynb"]
    assert not list((ROOT / "book").rglob("*solutions*")), "solutions inside book/"


def test_otter_assignment_has_the_points_and_checks_of_the_grader():
    """The otter-grader master notebook: one question per section, its points and its check calls."""
    from localize.grade.sections import SECTIONS

    nb = nbformat.read(ROOT / "teacher" / "otter" / "homework.ipynb", as_version=4)
    assert nb.cells[0].cell_type == "raw" and nb.cells[0].source.startswith("# ASSIGNMENT CONFIG")
    questions = [c.source for c in nb.cells if c.cell_type == "raw" and c.source.startswith("# BEGIN QUESTION")]
    assert questions == [f"# BEGIN QUESTION\nname: q{s.number}\npoints:\n"
                         + "\n".join(f"  - {t.points}" for t in s.tasks) for s in SECTIONS]
    tests = [c.source for c in nb.cells if c.cell_type == "code" and c.source.startswith("report = check.")]
    assert tests == [f"report = {t.call()}\nprint(report.passed or report)" for s in SECTIONS for t in s.tasks]
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert code.count("# BEGIN SOLUTION") == code.count("# END SOLUTION") >= N_EXERCISES


@pytest.mark.slow
def test_solutions_pass_every_check(tmp_path):
    text = _run(jupytext.read(SOLUTIONS), tmp_path)
    assert "FAILED" not in text, text
    assert text.count("checks passed") == N_EXERCISES, text


@pytest.mark.slow
def test_student_template_fails_gracefully(tmp_path):
    text = _run(nbformat.read(HW / "homework.ipynb", as_version=4), tmp_path)
    assert text.count("checks FAILED") == N_EXERCISES, text
    assert text.count("replace `raise NotImplementedError`") >= N_EXERCISES


def _solutions() -> tuple[dict, dict]:
    """The homework's imports run in one namespace, and each solution cell's source by function name."""
    ns: dict = {}
    cells = {}
    for cell in jupytext.read(SOLUTIONS).cells:
        if cell.cell_type != "code":
            continue
        if "solution" in cell.metadata.get("tags", []):
            for name in ast.parse(cell.source).body:
                if isinstance(name, ast.FunctionDef) and not name.name.startswith("_"):
                    cells[name.name] = cell.source
        elif cell.source.lstrip().startswith(("import", "from")):
            exec(cell.source, ns)
    return ns, cells


# a classic mistake written into the homework's own solution must fail its check, with the hint for it
MISTAKES = [
    ("predict_stop", "predict_stop", "min(max(src + offset + m - c, 0), n - 1)", "(src + offset + m - c) % n",
     "wraps around"),
    ("predict_stop", "predict_stop", "min(max(src + offset + m - c, 0), n - 1)", "src + offset + m - c if "
     "0 <= src + offset + m - c < n else 0", None),
    ("kld_count", "kld_loop", "if n >= n_min and n >=", "if n >=", "n >= n_min"),
    ("kld_count", "kld_loop", "kld_bound(len(occupied),", "kld_bound(len(occupied) + 1,", "k - 1"),
    ("read_xy_log", "xy_reader", "values[4:][::-1] / 1000.0", "values[4:] / 1000.0", "wrong angles"),
    ("read_xy_log", "xy_reader", "values[4:][::-1] / 1000.0", "values[4:][::-1]", "millimetres"),
    ("read_xy_log", "xy_reader", "np.where(r == 0, 30.0, r)", "r", "no return, not an obstacle"),
    ("in_gate", "innovation_gate", "y[1] = wrap_angle(y[1])", "pass", "wrap the bearing innovation"),
    ("in_gate", "innovation_gate", "<= 9.21", "<= 6.63", "not 6.63"),
    ("in_gate", "innovation_gate", "H @ cov @ H.T + Q", "H @ cov @ H.T", "without the sensor noise Q"),
]


@pytest.mark.parametrize("fn, check_name, right, wrong, hint", MISTAKES,
                         ids=[f"{m[0]}:{m[3][:24]}" for m in MISTAKES])
def test_a_mistake_in_a_homework_solution_fails_its_check(fn, check_name, right, wrong, hint):
    from localize import check

    ns, cells = _solutions()
    source = cells[fn]
    assert right in source, f"the solution of {fn} changed: update MISTAKES"
    exec(source, ns)
    assert getattr(check, check_name)(ns[fn]), f"the homework's own {fn} fails check.{check_name}"
    exec(source.replace(right, wrong), ns)
    report = getattr(check, check_name)(ns[fn])
    assert not report, f"check.{check_name} passes {fn} with {right!r} written as {wrong!r}"
    if hint is not None:
        assert hint in str(report), str(report)
