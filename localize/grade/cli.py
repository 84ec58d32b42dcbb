"""``python -m localize.grade SUBMISSIONS --out grades/``: grade a class's homework notebooks.

Every submission is graded in its own process under time and memory limits
(:func:`localize.grade.runner.grade_submission`), two at a time by default;
the grade sheet ``grades.csv`` and one ``feedback/STUDENT.txt`` per student
are written into ``--out``.
"""

from __future__ import annotations

import argparse
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from .runner import Grade, Limits, grade_submission
from .sheet import feedback_text, write_sheet

__all__ = ["find_submissions", "grade_class", "main"]


def find_submissions(folder: str | os.PathLike) -> dict[str, Path]:
    """The submissions in ``folder``: ``NAME.ipynb`` files, or subfolders ``NAME/`` holding one ``.ipynb``.

    Raises ``ValueError`` naming the folder when it holds none, or a subfolder
    holding several notebooks (which one to grade?).

    Examples
    --------
    >>> d = tmp_dir()
    >>> _ = (d / "ada.ipynb").write_text("{}")
    >>> (d / "bob").mkdir(); _ = (d / "bob" / "homework.ipynb").write_text("{}")
    >>> sorted(find_submissions(d))
    ['ada', 'bob']
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder} is not a folder: give the folder that holds the submitted notebooks")
    found: dict[str, Path] = {}
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith(".") or entry.name.endswith(".ipynb_checkpoints"):
            continue
        if entry.is_file() and entry.suffix == ".ipynb":
            found[entry.stem] = entry
        elif entry.is_dir():
            notebooks = [p for p in sorted(entry.glob("*.ipynb"))]
            if len(notebooks) > 1:
                raise ValueError(f"{entry} holds {len(notebooks)} notebooks ({', '.join(p.name for p in notebooks)}):"
                                 " leave only the one to grade")
            if notebooks:
                found[entry.name] = notebooks[0]
    if not found:
        raise ValueError(f"{folder} holds no submission: NAME.ipynb files or NAME/ folders with one .ipynb each")
    return found


def grade_class(folder: str | os.PathLike, out: str | os.PathLike, jobs: int = 2, limits: Limits | None = None,
                progress: bool = False) -> list[Grade]:
    """Grade every submission in ``folder``, ``jobs`` at a time; write ``out/grades.csv`` and ``out/feedback/``.

    Examples
    --------
    >>> d = tmp_dir()
    >>> _ = (d / "ada.ipynb").write_text('{"cells": [], "metadata": {}, "nbformat": 4, "nbformat_minor": 5}')
    >>> [g.total for g in grade_class(d, d / "grades")]
    [0]
    >>> sorted(p.name for p in (d / "grades").rglob("*.*"))
    ['ada.txt', 'grades.csv']
    """
    submissions = find_submissions(folder)
    if int(jobs) < 1:
        raise ValueError(f"jobs must be at least 1; got {jobs}")
    out = Path(out)
    (out / "feedback").mkdir(parents=True, exist_ok=True)
    limits = limits or Limits()

    def one(item: tuple[str, Path]) -> Grade:
        student, path = item
        grade = grade_submission(path, student, limits)
        (out / "feedback" / f"{student}.txt").write_text(feedback_text(grade))
        if progress:
            print(f"graded {student}: {grade.total} points", file=sys.stderr, flush=True)
        return grade

    with ThreadPoolExecutor(max_workers=int(jobs)) as pool:
        grades = list(pool.map(one, submissions.items()))
    write_sheet(grades, out / "grades.csv")
    return grades


def main(argv: list[str] | None = None) -> int:
    """The command line: ``python -m localize.grade SUBMISSIONS [--out DIR] [--jobs N] [limits]``.

    Returns the exit status: 0 when the class was graded, 2 (with the reason on
    stderr) when the input was wrong.

    Examples
    --------
    >>> main([str(tmp_dir() / "nowhere")])          # stderr: error: ... is not a folder: give the folder ...
    2
    """
    parser = argparse.ArgumentParser(prog="python -m localize.grade", description=(
        "Grade a class's homework notebooks: each in its own process under time and memory limits, "
        "with the checks of localize.check. Writes OUT/grades.csv and OUT/feedback/STUDENT.txt."))
    parser.add_argument("submissions", help="folder of NAME.ipynb files (or NAME/ folders with one notebook each)")
    parser.add_argument("--out", default="grades", help="folder for grades.csv and feedback/ (default: grades)")
    parser.add_argument("--jobs", type=int, default=2, help="submissions graded at once (default: 2)")
    d = Limits()
    parser.add_argument("--time-limit", type=float, default=d.submission_s,
                        help=f"seconds for one submission (default: {d.submission_s:g})")
    parser.add_argument("--cell-time-limit", type=float, default=d.cell_s,
                        help=f"seconds for one notebook cell (default: {d.cell_s:g})")
    parser.add_argument("--check-time-limit", type=float, default=d.task_s,
                        help=f"seconds for the check of one function (default: {d.task_s:g})")
    parser.add_argument("--memory-limit", type=float, default=d.memory_mb,
                        help=f"MiB of address space for one submission (default: {d.memory_mb:g})")
    args = parser.parse_args(argv)
    try:
        limits = Limits(args.time_limit, args.cell_time_limit, args.check_time_limit, args.memory_limit)
        grades = grade_class(args.submissions, args.out, args.jobs, limits, progress=True)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"graded {len(grades)} submissions: {Path(args.out) / 'grades.csv'}, feedback in {Path(args.out) / 'feedback'}")
    return 0
