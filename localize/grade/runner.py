"""Grade one submitted notebook in its own process, under time and memory limits, in a scratch folder.

:func:`grade_submission` copies the notebook into a fresh scratch folder,
starts ``localize.grade._sandbox`` there in a new Python process (isolated
mode: no ``PYTHONPATH``, no user site, only the ``localize`` package on the
path, so the teacher's solutions cannot be imported) with
``resource.setrlimit`` limits on memory (address space), CPU time, file size
and core dumps, and turns what the process reports into a :class:`Grade`.
The process is killed when it runs past the submission's time limit; whatever
it graded by then keeps its points, everything else gets zero with the reason.
It needs a POSIX system (``resource``, ``fork``; tested on Linux, where
``RLIMIT_AS`` is enforced).
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from .._checks import check_positive
from .sections import SECTIONS, SOLUTION_MODULES, Section

__all__ = ["Limits", "Grade", "grade_submission"]

_BOOT = ("import sys; sys.path.insert(0, sys.argv[2]); "
         "from localize.grade._sandbox import main; main(sys.argv[1])")


@dataclass(frozen=True)
class Limits:
    """The limits one submission is graded under.

    Parameters
    ----------
    submission_s : float
        Wall-clock seconds for the whole submission (the process is killed after it).
    cell_s : float
        Seconds for one notebook cell (a cell that runs longer is stopped and reported).
    task_s : float
        Seconds for one check of one function.
    memory_mb : float
        Address-space limit of the grading process, in MiB (``RLIMIT_AS``).

    Examples
    --------
    >>> Limits(task_s=5).task_s
    5
    >>> Limits(memory_mb=-1)
    Traceback (most recent call last):
    ...
    ValueError: memory_mb must be a finite number of MiB > 0; got -1
    """

    submission_s: float = 300.0
    cell_s: float = 60.0
    task_s: float = 20.0
    memory_mb: float = 2048.0

    def __post_init__(self) -> None:
        check_positive(self.submission_s, "submission_s", "s")
        check_positive(self.cell_s, "cell_s", "s")
        check_positive(self.task_s, "task_s", "s")
        check_positive(self.memory_mb, "memory_mb", "MiB")


@dataclass
class Grade:
    """The grade of one submission: points and report per task, and the notes that explain zeros.

    ``points[function]`` and ``reports[function]`` hold each task's points and
    the check's report (what the student's own ``localize.check`` call prints);
    ``notes`` says why something got zero that the reports do not explain
    (a cell that raised, a timeout, a crash, tampering).

    Examples
    --------
    >>> g = Grade("ada", {"normalize": 1}, {"normalize": "normalize: all 5 checks passed"})
    >>> g.section_points(SECTIONS[1]), g.total
    (1, 1)
    >>> Grade("bob", {"normalize": 0}, hints={"normalize": "divide by the sum"}).first_hint
    'normalize: divide by the sum'
    """

    student: str
    points: dict[str, int] = field(default_factory=dict)
    reports: dict[str, str] = field(default_factory=dict)
    hints: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    tampered: bool = False

    def section_points(self, section: Section) -> int:
        """The points earned in one section (zero for every section of a tampering submission)."""
        return 0 if self.tampered else sum(self.points.get(t.function, 0) for t in section.tasks)

    @property
    def total(self) -> int:
        """The points earned in the whole homework."""
        return sum(self.section_points(s) for s in SECTIONS)

    @property
    def first_hint(self) -> str:
        """The hint of the first failing task in notebook order, or the first note, or ''."""
        if self.tampered:
            return self.notes[0] if self.notes else ""
        for s in SECTIONS:
            for t in s.tasks:
                if self.points.get(t.function, 0) < t.points and self.hints.get(t.function):
                    return f"{t.function}: {self.hints[t.function]}"
        return self.notes[0] if self.notes else ""


def _limit_resources(limits: Limits):
    """The ``preexec_fn`` of the grading process: its memory, CPU time, file size and core dumps."""
    memory = int(limits.memory_mb * 2**20)
    cpu = int(limits.submission_s) + 10

    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
        resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 2**20, 64 * 2**20))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))

    return apply


def _prepare(notebook: Path, scratch: Path, limits: Limits) -> Path:
    """The scratch folder: work/ (the student's cwd, holding the notebook and .grader/), lib/, result.jsonl."""
    import localize

    work = scratch / "work"
    (work / ".grader").mkdir(parents=True)
    (work / "tmp").mkdir()
    (scratch / "lib").mkdir()
    os.symlink(Path(localize.__file__).resolve().parent, scratch / "lib" / "localize")
    shutil.copyfile(notebook, work / notebook.name)
    tasks = [{"function": t.function, "check": t.check, "kwargs": dict(t.kwargs)} for s in SECTIONS for t in s.tasks]
    job = {"notebook": notebook.name, "result": str(scratch / "result.jsonl"), "tasks": tasks,
           "forbidden": list(SOLUTION_MODULES), "cell_limit": limits.cell_s, "task_limit": limits.task_s}
    (work / ".grader" / "job.json").write_text(json.dumps(job, indent=1))
    return work


def _environment(work: Path) -> dict[str, str]:
    keep = ("PATH", "LANG", "LC_ALL", "NPY_DISABLE_CPU_FEATURES")
    env = {k: v for k, v in os.environ.items() if k in keep}
    env.update(HOME=str(work), TMPDIR=str(work / "tmp"), MPLBACKEND="Agg", MPLCONFIGDIR=str(work / "tmp"),
               OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return env


def _records(lines: list[str]) -> list[dict]:
    """The JSON objects among the sandbox's result lines (anything else is skipped)."""
    out = []
    for line in lines:
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict):
            out.append(record)
    return out


def _apply(grade: Grade, r: dict, points: dict[str, int]) -> None:
    """Enter one finding of the sandbox into ``grade``."""
    kind = r.get("kind")
    if kind == "cell" and "the grader refuses this" not in str(r.get("error")):
        grade.notes.append(f"code cell {r.get('cell')}: {r.get('error')}")
    elif kind == "notebook":
        grade.notes.append(str(r.get("error")))
    elif kind == "task" and r.get("function") in points:
        f = r["function"]
        grade.points[f] = points[f] if r.get("passed") is True else 0
        grade.reports[f] = str(r.get("report", ""))
        grade.hints[f] = str(r.get("hint", ""))
        if r.get("timeout") or r.get("crashed"):
            grade.notes.append(grade.reports[f])
    elif kind == "tamper":
        grade.tampered = True
        grade.notes[:0] = [f"zero for tampering: the submission {why}" for why in r.get("why", [])]


def _interpret(student: str, lines: list[str], ended: str) -> Grade:
    """Turn the sandbox's JSON lines (and how its process ended) into a :class:`Grade`."""
    grade = Grade(student)
    points = {t.function: t.points for s in SECTIONS for t in s.tasks}
    records = _records(lines)
    for r in records:
        _apply(grade, r, points)
    done = any(r.get("kind") == "done" for r in records)
    if not done:
        grade.notes.append(ended)
    missing = [f for f in points if f not in grade.reports]
    if missing and not grade.tampered:
        grade.notes.append(f"not graded ({'the process ended first' if not done else 'skipped'}): "
                           + ", ".join(missing))
    return grade


def grade_submission(notebook: str | os.PathLike, student: str | None = None, limits: Limits | None = None,
                     keep: str | os.PathLike | None = None) -> Grade:
    """Grade one submitted homework notebook in its own limited process.

    Parameters
    ----------
    notebook : path
        The submitted ``.ipynb``.
    student : str, optional
        The name on the grade sheet (default: the notebook's file name without ``.ipynb``).
    limits : Limits, optional
        Time and memory limits (default :class:`Limits`).
    keep : path, optional
        Keep the scratch folder here (for debugging) instead of deleting it.

    Returns
    -------
    Grade

    Examples
    --------
    >>> folder = tmp_dir()
    >>> nb = folder / "ada.ipynb"
    >>> _ = nb.write_text('{"cells": [{"cell_type": "code", "source": "def normalize(p):\\\\n    return p / p.sum()",'
    ...                   ' "metadata": {}, "outputs": []}], "metadata": {}, "nbformat": 4, "nbformat_minor": 5}')
    >>> g = grade_submission(nb)
    >>> g.points["normalize"], g.points["bayes_update"], g.total
    (1, 0, 1)
    >>> g.hints["bayes_update"]
    'define bayes_update with the name and arguments the notebook gives it'
    """
    notebook = Path(notebook)
    if not notebook.is_file():
        raise FileNotFoundError(f"no submission at {notebook}: give the path of a .ipynb file")
    limits = limits or Limits()
    student = student or notebook.stem
    scratch = Path(tempfile.mkdtemp(prefix="localize-grade-"))
    try:
        work = _prepare(notebook, scratch, limits)
        with open(scratch / "stdout.txt", "wb") as log:
            proc = subprocess.Popen([sys.executable, "-I", "-B", "-c", _BOOT, str(work), str(scratch / "lib")],
                                    cwd=work, env=_environment(work), stdin=subprocess.DEVNULL, stdout=log,
                                    stderr=subprocess.STDOUT, preexec_fn=_limit_resources(limits),
                                    start_new_session=True)
            try:
                code = proc.wait(timeout=limits.submission_s)
                ended = (f"the grading process ended early ({_describe(code)}): a crash, os._exit in the "
                         f"notebook, or over the memory limit of {limits.memory_mb:g} MiB")
            except subprocess.TimeoutExpired:
                ended = f"stopped after {limits.submission_s:g} s: the notebook did not finish (an endless loop?)"
            finally:
                _kill_group(proc)
        result = scratch / "result.jsonl"
        lines = result.read_text(errors="replace").splitlines() if result.exists() else []
        grade = _interpret(student, lines, ended)
        if not (work / ".grader" / "job.json").is_file() and not grade.tampered:
            grade.tampered = True
            grade.notes.insert(0, "zero for tampering: the submission deleted a grader file (.grader/job.json)")
        return grade
    finally:
        if keep is not None:
            shutil.copytree(scratch, Path(keep), symlinks=True, dirs_exist_ok=True)
        shutil.rmtree(scratch, ignore_errors=True)


def _describe(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def _kill_group(proc: subprocess.Popen) -> None:
    """Kill the grading process and every process it started (its own session)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()
