"""Grade a class's homework: ``python -m localize.grade SUBMISSIONS --out grades/`` (or ``localize-grade``).

Presentation layer (like :mod:`localize.check`, whose checks it runs): no
algorithm imports it. The pieces:

* :mod:`localize.grade.sections`: the homework's sections, the check of each
  function and its points (the one place for points);
* :mod:`localize.grade.runner`: one submission in its own process, in a
  scratch folder, under time and memory limits, without the solutions;
* :mod:`localize.grade.sheet`: the CSV grade sheet and the feedback files;
* :mod:`localize.grade.cli`: the command, grading two submissions at a time.

The teacher's page of the book (chapter 12) shows the whole round: hand out,
collect, grade, add a question.
"""

from .cli import find_submissions, grade_class, main
from .runner import Grade, Limits, grade_submission
from .sections import SECTIONS, Section, Task, max_points
from .sheet import feedback_text, write_sheet

__all__ = ["SECTIONS", "Section", "Task", "max_points", "Grade", "Limits", "grade_submission", "find_submissions",
           "grade_class", "main", "feedback_text", "write_sheet"]
