# ---
# jupyter:
#   jupytext:
#     formats: ipynb,src//py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Teaching with this book: hand out, collect, grade
#
# This page is for the teacher who assigns the homework. It shows the whole
# round on a small class that the page makes up: what the students get, how
# to collect their notebooks, the **one command** that grades them all and
# writes a grade sheet and a feedback file per student, what that command does
# with a submission that loops forever or tries to cheat, how to grade on
# Gradescope instead with otter-grader, and how to add a question of your own.
#
# Everything below runs from the repository's root folder's `book/` (where
# this notebook lives); the paths are relative to it.

# %%
import csv
import sys
import tempfile
from pathlib import Path

import nbformat

from localize.grade import SECTIONS, Limits, grade_class, max_points

ROOT = Path("..").resolve()

# %% [markdown]
# ## What the students get
#
# The homework is one notebook, `book/homework/homework.ipynb`: twenty-one
# functions to write in sixteen sections, each followed by a cell that runs its
# self-check from `localize.check` and prints, like a patient teaching
# assistant, PASS or FAIL with a hint for every property. The student's folder
# holds nothing else: the solutions live in `teacher/homework_solutions.py`,
# outside `book/`, and the student notebook is **generated** from them by
# `python tools/make_homework.py` (every solution's body becomes
# `raise NotImplementedError`). Edit the solutions, never the student notebook.

# %%
student_folder = sorted(p.name for p in (ROOT / "book" / "homework").iterdir())
template = nbformat.read(ROOT / "book" / "homework" / "homework.ipynb", as_version=4)
stubs = sum(c.source.count("raise NotImplementedError") for c in template.cells if c.cell_type == "code")
print("the student's folder holds:", student_folder)
print("functions to write:", stubs, "in", len(SECTIONS), "sections")
print("solutions, for the teacher:", (ROOT / "teacher" / "homework_solutions.py").relative_to(ROOT))

# %% [markdown]
# ## Points: one table
#
# The points of every section live in one place, `localize/grade/sections.py`:
# each function earns its points when its check passes **in full** (a function
# right on four properties out of five is still wrong). The grader and the
# otter-grader assignment both read this table; change the points there.

# %%
for s in SECTIONS:
    tasks = ", ".join(f"{t.function} ({t.points})" for t in s.tasks)
    print(f"{s.number:>2}. {s.title:<16} {s.points} point{'s' if s.points > 1 else ' '}: {tasks}")
print(f"total: {max_points()} points")

# %% [markdown]
# ## Hand it out, collect it
#
# Hand out `book/homework/homework.ipynb` (with the book, or on its own: it
# needs `pip install` of this package, nothing else). Students fill in the
# functions, run the check cells until every report says "all checks passed",
# and hand in their notebook.
#
# Collect the notebooks into one folder, either as `NAME.ipynb` files or as
# folders `NAME/` holding one notebook each (the layout most learning
# platforms download): the name becomes the student's row of the grade sheet.
#
# Here we make up a class of four with `tools/make_submissions.py` (the tool
# the tests and the benchmark use): a complete homework, the untouched
# template, one with a classic mistake (a hallway that wraps around in
# section 12) and one that deletes a file of the grader's.

# %%
sys.path.insert(0, str(ROOT / "tools"))
from make_submissions import KINDS, filled  # noqa: E402

workspace = Path(tempfile.mkdtemp())
submissions = workspace / "submissions"
submissions.mkdir()
for name, kind in [("ada", "full"), ("bob", "empty"), ("cy", "wraps"), ("dee", "deletes")]:
    changes, extra, _ = KINDS[kind]
    nbformat.write(filled(changes, extra), submissions / f"{name}.ipynb")
print(sorted(p.name for p in submissions.iterdir()))

# %% [markdown]
# ## Grade the class: one command
#
# From the repository's root folder:
#
# ```bash
# python -m localize.grade submissions/ --out grades/
# ```
#
# (`localize-grade submissions/ --out grades/` is the same command, installed
# with the package.) It writes `grades/grades.csv`, one row per student with
# the points of every section, the total, the first failing hint and notes,
# and `grades/feedback/NAME.txt`, the reports of every check, as the student's
# own check cells print them. The same in Python, on our class:

# %% tags=["nbval-ignore-output", "remove-output"]
grades = grade_class(submissions, workspace / "grades", jobs=2)

# %%
with open(workspace / "grades" / "grades.csv", newline="") as f:
    rows = list(csv.DictReader(f))
for row in rows:
    print(f"{row['student']:<5} total {row['total']:>2}, section 12: {row['12_predict_stop']}")
    if row["first failing hint"]:
        print(f"      first failing hint: {row['first failing hint']}")

# %%
feedback = (workspace / "grades" / "feedback" / "cy.txt").read_text()
print(feedback.splitlines()[0])
print("...")
print(feedback.split("## 12.", 1)[1].split("\n\n", 1)[0].join(["## 12.", ""]))

# %% [markdown]
# Bob's template earns nothing, and his hint says why; Cy loses the two points
# of section 12 and her feedback quotes the check's hint; Dee's notebook tried
# to delete the grader's job file: the deletion was refused and the submission
# gets zero, with the reason on the sheet.
#
# ## What the grader protects against
#
# Every submission runs in **its own Python process**, two at a time (`--jobs`),
# in a scratch folder that holds a copy of the notebook and nothing of the
# teacher's. Only the `localize` package is importable there: the solutions
# are not on the path. The process has a memory limit and a CPU-time limit
# (`resource.setrlimit`), every notebook cell a time limit, and every check of
# every function runs in a child process of its own with a time limit, so
# that an endless loop or a crash costs only the function that has it:

# %%
limits = Limits()
print(f"one submission: {limits.submission_s:g} s (--time-limit)")
print(f"one notebook cell: {limits.cell_s:g} s (--cell-time-limit)")
print(f"one function's check: {limits.task_s:g} s (--check-time-limit)")
print(f"memory: {limits.memory_mb:g} MiB of address space (--memory-limit)")

# %% [markdown]
# A submission that imports the solution module, opens the solutions file,
# deletes or rewrites a grader file or any file outside its scratch folder,
# starts a program, or replaces a function of `localize.check` or numpy (to
# make a check pass) is refused where Python's audit hooks can refuse it, and
# gets **zero for the whole homework** with a line saying what it did. One
# honest limit: Python cannot sandbox code against itself, so these defences
# stop accidents and the usual tricks, not a determined attacker; for that,
# run the command in a container or as a user who cannot read `teacher/`.
#
# How long does a class take? `benchmarks/bench_grade.py` grades thirty
# submissions (the kinds above, looping ones included) with the default
# limits, two at a time; its last measurement, from `benchmarks/RESULTS.md`:

# %%
results = (ROOT / "benchmarks" / "RESULTS.md").read_text()
section = results.split("## bench_grade", 1)[1].split("\n## ", 1)[0]
header, _, row = [line for line in section.splitlines() if line.startswith("|")][:3]
measured = dict(zip([h.strip() for h in header.strip("|").split("|")], [v.strip() for v in row.strip("|").split("|")]))
print(f"{measured['submissions']} submissions, {measured['jobs']} at a time: {measured['wall [s]']} s "
      f"(load average {measured['load average before / after']} on a shared 2-core machine; target < 300 s)")

# %% [markdown]
#
# ## On Gradescope, or one notebook at a time: otter-grader
#
# Courses that grade on Gradescope use [otter-grader](https://otter-grader.readthedocs.io).
# `python tools/make_homework.py` also writes `teacher/otter/homework.ipynb`,
# the same homework in otter's format: one question per section with the
# points of the table above, and tests that call the same `localize.check`
# functions (a failing test shows the check's report, hints included). Then
#
# ```bash
# pip install -e ".[grade]"                            # otter-grader
# otter assign teacher/otter/homework.ipynb dist/      # dist/autograder/*.zip, dist/student/
# otter run -a dist/autograder/homework-autograder_*.zip alice.ipynb   # one submission, here, no Docker
# ```
#
# Upload the zip as the assignment's autograder on Gradescope, after adding
# the line that installs this package to the `requirements` of the
# assignment's configuration (the first cell of `teacher/otter/homework.ipynb`,
# written by `tools/make_homework.py`). `otter run` grades the student notebook
# of this book as it is, and `tests/test_grade.py` checks that it gives every
# section the same points as `python -m localize.grade`. `otter grade`, otter's
# own command for a whole class, needs Docker; `python -m localize.grade` does
# not.
#
# ## Adding a question
#
# 1. Write its self-check in `localize/check.py`: a function that takes the
#    student's function and returns a `Report`, one verdict per property, with
#    a hint that names the mistake the student's result reveals (see the
#    module's docstring); test it in `tests/test_check.py` with the classic
#    mistakes it must catch.
# 2. Add the exercise to `teacher/homework_solutions.py`: a markdown cell with
#    the task, a code cell tagged `solution` with your solution, and a cell
#    that calls the check (`check.my_check(my_function)`).
# 3. Add a `Section` with its `Task` and points to `localize/grade/sections.py`.
# 4. Run `python tools/make_homework.py` (it rewrites the student notebook and
#    the otter assignment), then `pytest tests/test_homework.py
#    tests/test_grade.py`: they fail if the notebook's check cells and the
#    grader's table disagree, or if your solution does not pass its own check.

# %%
assert [g.total for g in sorted(grades, key=lambda g: g.student)] == [max_points(), 0, max_points() - 2, 0]
print("the four totals as stated:", [g.total for g in sorted(grades, key=lambda g: g.student)])
