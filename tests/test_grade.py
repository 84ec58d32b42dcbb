"""Grading a class: the command, its grade sheet row by row, its defences, and agreement with the student's checks."""

from __future__ import annotations

import ast
import csv
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import nbformat
import pytest

from localize.grade import SECTIONS, Limits, grade_submission, max_points
from localize.grade.cli import find_submissions, main

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks our own tooling, not numerics
pytestmark = pytest.mark.tooling

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from make_submissions import KINDS, filled, make_class  # noqa: E402

FULL = {s.key: s.points for s in SECTIONS}
#: The check's time limit in the class test: the checks of a correct homework take well under a second each.
TASK_S = 10.0


def _section(function: str):
    return next(s for s in SECTIONS for t in s.tasks if t.function == function)


def _only_zero(row: dict, function: str) -> None:
    """Every section at full marks except the one holding ``function``, which is zero."""
    zero = _section(function).key
    assert {k: int(row[k]) for k in FULL} == {**FULL, zero: 0}, row
    assert int(row["total"]) == max_points() - _section(function).points


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """The class of tools/make_submissions.py, graded by the documented command."""
    base = tmp_path_factory.mktemp("class")
    made = make_class(base / "submissions")
    assert len(made) >= 8
    r = subprocess.run([sys.executable, "-m", "localize.grade", str(base / "submissions"), "--out",
                        str(base / "grades"), "--check-time-limit", str(TASK_S)], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    with open(base / "grades" / "grades.csv", newline="") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    return base, made, rows, r


def _grade_all(notebooks: dict[str, nbformat.NotebookNode], folder: Path, limits: Limits | None = None) -> dict:
    """name -> Grade of each notebook, graded by grade_submission two at a time (as ``grade_class`` does)."""
    for name, nb in notebooks.items():
        nbformat.write(nb, folder / f"{name}.ipynb")
    with ThreadPoolExecutor(max_workers=2) as pool:
        grades = pool.map(lambda name: grade_submission(folder / f"{name}.ipynb", limits=limits), notebooks)
        return dict(zip(notebooks, grades))


HONEST = ("full", "empty", "wraps", "millimetres", "no_q")


@pytest.fixture(scope="module")
def honest(tmp_path_factory):
    """kind -> (notebook, Grade) for each honest kind of submission, graded once for the tests below."""
    notebooks = {kind: filled(*KINDS[kind][:2]) for kind in HONEST}
    grades = _grade_all(notebooks, tmp_path_factory.mktemp("honest"), Limits(task_s=60))
    return {kind: (notebooks[kind], grades[kind]) for kind in HONEST}


@pytest.mark.slow
def test_grade_sheet_row_by_row(graded):
    base, made, rows, _ = graded
    assert set(rows) == set(made) | {"max"}
    assert {k: int(rows["max"][k]) for k in FULL} == FULL and int(rows["max"]["total"]) == max_points() == 32
    full = rows["full"]
    assert {k: int(full[k]) for k in FULL} == FULL and int(full["total"]) == 32
    assert full["first failing hint"] == "" and full["notes"] == ""
    empty = rows["empty"]
    assert int(empty["total"]) == 0 and all(int(empty[k]) == 0 for k in FULL)
    assert empty["first failing hint"] == "world_to_cell: replace `raise NotImplementedError` with your implementation"
    # three classic mistakes: zero in their own section only, with the hint the student's check gives
    _only_zero(rows["wraps"], "predict_stop")
    assert rows["wraps"]["first failing hint"].startswith("predict_stop: your hallway wraps around")
    _only_zero(rows["millimetres"], "read_xy_log")
    assert rows["millimetres"]["first failing hint"] == "read_xy_log: the file stores millimetres: divide by 1000 for metres"
    _only_zero(rows["no_q"], "in_gate")
    assert "without the sensor noise Q" in rows["no_q"]["first failing hint"]
    # an endless loop in one function costs that function, and the sheet says why
    _only_zero(rows["loops"], "normalize")
    assert rows["loops"]["notes"] == f"normalize: stopped after {TASK_S:g} s (an endless loop?)"
    # tampering: zero everywhere, and the reason
    for student, why in [("deletes", "deletes the grader's file .grader/job.json"),
                         ("imports_solution", "imports the solution module homework_solutions"),
                         ("patches_check", "replaces localize.check.normalize")]:
        row = rows[student]
        assert int(row["total"]) == 0 and all(int(row[k]) == 0 for k in FULL), student
        assert row["notes"].split(" | ")[0] == f"zero for tampering: the submission {why}", row["notes"]
        assert row["first failing hint"] == row["notes"].split(" | ")[0]


@pytest.mark.slow
def test_one_feedback_file_per_student(graded):
    base, made, rows, r = graded
    feedback = base / "grades" / "feedback"
    assert sorted(p.stem for p in feedback.glob("*.txt")) == sorted(made)
    full = (feedback / "full.txt").read_text()
    assert full.startswith("Homework feedback for full: 32 of 32 points")
    assert full.count("checks passed") == sum(len(s.tasks) for s in SECTIONS)
    wraps = (feedback / "wraps.txt").read_text()
    assert "## 12. predict_stop: 0 of 2 points" in wraps and "FAIL" in wraps and "wraps around" in wraps
    assert "zero for tampering" in (feedback / "deletes.txt").read_text()
    assert f"graded {len(made)} submissions" in r.stdout


@pytest.mark.slow
def test_the_grader_and_the_students_own_checks_agree(honest):
    """For each kind of honest submission, every check cell of the notebook gives the grader's verdict and hint."""
    from localize import check

    for kind in HONEST:
        nb, grade = honest[kind]
        ns: dict = {}
        reports = {}
        for cell in nb.cells:
            if cell.cell_type != "code":
                continue
            calls = _check_calls(cell.source)
            if not calls:
                exec(cell.source, ns)
                continue
            for node in calls:  # the report the student sees when running this cell
                report = eval(compile(ast.Expression(node), "<check cell>", "eval"), ns)
                assert isinstance(report, check.Report)
                reports[ast.unparse(node.args[0])] = report
        assert sorted(reports) == sorted(t.function for s in SECTIONS for t in s.tasks)
        for s in SECTIONS:
            for t in s.tasks:
                report = reports[t.function]
                assert (grade.points[t.function] == t.points) == bool(report), (kind, t.function)
                assert grade.reports[t.function] == str(report), (kind, t.function)
                assert grade.hints[t.function] == (report.hints or [""])[0], (kind, t.function)


def _check_calls(source: str) -> list[ast.Call]:
    calls = []
    for node in ast.parse(source).body:
        value = node.value if isinstance(node, ast.Expr) else None
        if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "print":
            value = value.args[0]
        if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) and \
                isinstance(value.func.value, ast.Name) and value.func.value.id == "check":
            calls.append(value)
    return calls


def test_the_notebook_check_cells_are_the_graders_checks():
    """The calls in the student notebook's check cells, in order, are those of localize.grade.sections."""
    nb = nbformat.read(ROOT / "book" / "homework" / "homework.ipynb", as_version=4)
    calls = [ast.unparse(c) for cell in nb.cells if cell.cell_type == "code" for c in _check_calls(cell.source)]
    assert calls == [ast.unparse(ast.parse(t.call()).body[0].value) for s in SECTIONS for t in s.tasks]


# ------------------------------------------------------------------ what a submission may break, one at a time
_AT_TOP = "p = np.asarray(p, dtype=float)\n"
EDGE = {
    "a cell that loops at the top level is stopped, the rest is graded":
        ([], "while True:\n    pass", 32, "code cell 2: ran longer than 3 s and was stopped"),
    "a function that crashes the interpreter costs that function":
        ([("normalize", _AT_TOP, _AT_TOP + "    import ctypes\n    ctypes.string_at(0)\n")], "", 31,
         "normalize: the process grading it died (killed by SIGSEGV)"),
    "a function over the memory limit costs that function":
        ([("normalize", _AT_TOP, _AT_TOP + "    _ = bytearray(10**11)\n")], "", 31, ""),
    "a notebook that ends the interpreter gets zero for what was not graded":
        ([], "import os\nos._exit(3)", 0, "the grading process ended early (exit code 3)"),
    "starting a program is tampering":
        ([], "import os\nos.system('true')", 0, "zero for tampering: the submission starts a program (os.system)"),
    "reading the solutions file is tampering":
        ([], f"try:\n    open({str(ROOT / 'teacher' / 'homework_solutions.py')!r}).read()\nexcept Exception:\n    pass",
         0, "zero for tampering: the submission opens the solutions file homework_solutions.py"),
    "patching numpy inside a function is tampering":
        ([("normalize", _AT_TOP, _AT_TOP + "    np.allclose = lambda *a, **k: True\n")], "", 0,
         "zero for tampering: the submission replaces numpy.allclose"),
    "writing outside the scratch folder is refused and is tampering":
        ([], f"try:\n    open({str(ROOT / 'localize' / 'check.py')!r}, 'a')\nexcept Exception:\n    pass", 0,
         f"zero for tampering: the submission writes {ROOT / 'localize' / 'check.py'}, outside its scratch folder"),
    "a cell with a syntax error is reported, the rest is graded":
        ([], "def oops(:\n    pass", 32, "code cell 2: SyntaxError: invalid syntax (line 1)"),
}


@pytest.fixture(scope="module")
def edge_grades(tmp_path_factory):
    """name -> Grade of each EDGE submission, and check.py's modification time before and after grading them all."""
    before = (ROOT / "localize" / "check.py").stat().st_mtime_ns
    notebooks = {f"edge{k}": filled(*EDGE[name][:2]) for k, name in enumerate(EDGE)}
    grades = _grade_all(notebooks, tmp_path_factory.mktemp("edge"),
                        Limits(submission_s=120, cell_s=3, task_s=30, memory_mb=2048))
    after = (ROOT / "localize" / "check.py").stat().st_mtime_ns
    return dict(zip(EDGE, grades.values())), before, after


@pytest.mark.slow
@pytest.mark.parametrize("name", list(EDGE))
def test_what_a_submission_breaks_costs_only_that(name, edge_grades):
    _, _, total, note = EDGE[name]
    grades, before, after = edge_grades
    grade = grades[name]
    assert grade.total == total, grade.notes
    if note:
        assert grade.notes and grade.notes[0].startswith(note), grade.notes
    assert after == before, "grading the EDGE submissions wrote to localize/check.py"


def test_the_solutions_are_not_importable_in_the_sandbox(tmp_path):
    """Even without the audit hook's refusal, teacher/ is not on the grading process's path. The environment's own
    folders may lie inside the checkout (the README's `.venv`): they are the only part of it on the path."""
    nb = filled([], "import importlib.util\nassert importlib.util.find_spec('teacher') is None\n"
                    "assert importlib.util.find_spec('tools') is None\nimport sys\n"
                    f"assert not [p for p in sys.path if p.startswith({str(ROOT)!r}) and not p.startswith(sys.prefix)], "
                    "sys.path")
    nbformat.write(nb, tmp_path / "s.ipynb")
    grade = grade_submission(tmp_path / "s.ipynb")
    assert grade.notes == [] and grade.total == 32


def test_find_submissions_and_the_command_report_bad_input(tmp_path, capsys):
    with pytest.raises(ValueError, match="holds no submission"):
        find_submissions(tmp_path)
    (tmp_path / "bob").mkdir()
    for name in ("a.ipynb", "b.ipynb"):
        (tmp_path / "bob" / name).write_text("{}")
    with pytest.raises(ValueError, match="holds 2 notebooks"):
        find_submissions(tmp_path)
    assert main([str(tmp_path / "nowhere")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main([str(tmp_path), "--memory-limit", "0"]) == 2
    assert "memory_mb must be a finite number of MiB > 0" in capsys.readouterr().err


def test_a_notebook_that_is_not_json_gets_zero_with_the_reason(tmp_path):
    (tmp_path / "x.ipynb").write_text("not a notebook")
    grade = grade_submission(tmp_path / "x.ipynb")
    assert grade.total == 0
    assert grade.notes[0].startswith("not a readable notebook: JSONDecodeError"), grade.notes



@pytest.mark.slow
def test_otter_grades_like_the_grader(tmp_path, honest):
    """The otter-grader route (otter assign, then otter run without Docker) gives each section the same points."""
    pytest.importorskip("otter", reason="otter-grader is not installed (pip install -e '.[grade]')")
    import json

    otter = [sys.executable, "-m", "otter"]
    r = subprocess.run([*otter, "assign", str(ROOT / "teacher" / "otter" / "homework.ipynb"), str(tmp_path / "dist")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    (zip_path,) = (tmp_path / "dist" / "autograder").glob("*.zip")
    for kind in ("wraps",):  # fifteen sections at full marks, one at zero: both outcomes
        notebook, grade = honest[kind]
        nb = tmp_path / f"{kind}.ipynb"
        nbformat.write(notebook, nb)
        out = tmp_path / f"out_{kind}"
        out.mkdir()
        r = subprocess.run([*otter, "run", "-a", str(zip_path), "-o", str(out), str(nb)], capture_output=True,
                           text=True)
        assert r.returncode == 0, r.stdout + r.stderr
        scores = {t["name"]: t["score"] for t in json.loads((out / "results.json").read_text())["tests"]
                  if "score" in t}
        assert scores == {f"q{s.number}": float(grade.section_points(s)) for s in SECTIONS}, kind
