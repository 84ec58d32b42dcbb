"""The grade sheet (CSV) and one feedback file per student."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

from .runner import Grade
from .sections import SECTIONS, max_points

__all__ = ["COLUMNS", "sheet_rows", "write_sheet", "feedback_text"]

#: The grade sheet's columns: the student, the points of each section, the total, the first failing hint, the notes.
COLUMNS: tuple[str, ...] = ("student", *(s.key for s in SECTIONS), "total", "first failing hint", "notes")


def sheet_rows(grades: list[Grade]) -> list[dict[str, str]]:
    """One row per student (sorted by name), then a row ``max`` with the points available.

    Examples
    --------
    >>> rows = sheet_rows([Grade("ada", {"normalize": 1})])
    >>> rows[0]["student"], rows[0]["1_normalize"], rows[0]["total"], rows[-1]["total"]
    ('ada', '1', '1', '32')
    """
    rows = []
    for g in sorted(grades, key=lambda g: g.student):
        row = {"student": g.student, **{s.key: str(g.section_points(s)) for s in SECTIONS}}
        row.update({"total": str(g.total), "first failing hint": g.first_hint, "notes": " | ".join(g.notes)})
        rows.append(row)
    rows.append({"student": "max", **{s.key: str(s.points) for s in SECTIONS}, "total": str(max_points()),
                 "first failing hint": "", "notes": ""})
    return rows


def write_sheet(grades: list[Grade], path: str | os.PathLike) -> Path:
    """Write the grade sheet CSV at ``path`` in one step (a reader never sees half a sheet).

    Examples
    --------
    >>> p = write_sheet([Grade("ada", {"normalize": 1})], tmp_dir() / "grades.csv")
    >>> p.read_text().splitlines()[0].split(",")[:3]
    ['student', '0_world_to_cell', '1_normalize']
    """
    path = Path(path)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(sheet_rows(grades))
    partial = path.with_name(f".{path.name}.partial")
    partial.write_text(buffer.getvalue())
    os.replace(partial, path)
    return path


def feedback_text(grade: Grade) -> str:
    """A student's feedback: the total, then each section's points and the report of each check.

    Examples
    --------
    >>> text = feedback_text(Grade("ada", {"normalize": 1}, {"normalize": "normalize: all 5 checks passed"}))
    >>> for line in text.splitlines()[:6]:
    ...     print(line)
    Homework feedback for ada: 1 of 32 points
    <BLANKLINE>
    ## 0. world_to_cell: 0 of 1 points
    world_to_cell: not graded (see the notes above)
    <BLANKLINE>
    ## 1. normalize: 1 of 1 points
    """
    out = [f"Homework feedback for {grade.student}: {grade.total} of {max_points()} points", ""]
    if grade.notes:
        out += ["Notes from the grader:", *[f"  - {n}" for n in grade.notes], ""]
    for s in SECTIONS:
        out.append(f"## {s.number}. {s.title}: {grade.section_points(s)} of {s.points} points")
        for t in s.tasks:
            out.append(grade.reports.get(t.function, f"{t.function}: not graded (see the notes above)"))
        out.append("")
    return "\n".join(out)
