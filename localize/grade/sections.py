"""The homework's sections, the checks each one runs and the points they carry: the one place for points.

Each section of the homework (``book/homework/homework.ipynb``) asks for one to
three functions; each function is graded by one self-check of
:mod:`localize.check`, the same call the student's notebook makes in the cell
below the exercise, so that the grade and the hint a student sees cannot drift
apart. A task earns its points when its check passes in full (a function that
is right on four properties out of five is still wrong).

    >>> from localize.grade.sections import SECTIONS, max_points
    >>> len(SECTIONS), sum(len(s.tasks) for s in SECTIONS), max_points()
    (16, 21, 32)
    >>> print(SECTIONS[6].tasks[1].call())
    check.resampler(multinomial_resampler, scheme='multinomial')

``tools/make_homework.py`` writes these points into the otter-grader assignment
(``teacher/otter/homework.ipynb``), and ``python -m localize.grade`` uses them
for the class's grade sheet; ``tests/test_grade.py`` holds the calls here equal
to the check cells of the student notebook.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Task", "Section", "SECTIONS", "max_points", "SOLUTION_MODULES"]

#: Module names a submission must never import: the teacher's solutions (``teacher/homework_solutions.py``).
SOLUTION_MODULES: tuple[str, ...] = ("homework_solutions",)


@dataclass(frozen=True)
class Task:
    """One function a student writes and the :mod:`localize.check` function that grades it.

    Parameters
    ----------
    function : str
        The name the student's function has in the notebook.
    check : str
        The name of the check in :mod:`localize.check`.
    points : int
        Points earned when the check passes in full.
    kwargs : tuple of (str, object) pairs
        Keyword arguments of the check beyond the function.

    Examples
    --------
    >>> Task("normalize", "normalize", 1).call()
    'check.normalize(normalize)'
    """

    function: str
    check: str
    points: int
    kwargs: tuple[tuple[str, object], ...] = ()

    def call(self) -> str:
        """The check call as the student notebook writes it (``check.NAME(function, key=value)``).

        Examples
        --------
        >>> Task("f", "resampler", 1, (("scheme", "multinomial"),)).call()
        "check.resampler(f, scheme='multinomial')"
        """
        extra = "".join(f", {k}={v!r}" for k, v in self.kwargs)
        return f"check.{self.check}({self.function}{extra})"


@dataclass(frozen=True)
class Section:
    """A numbered section of the homework: its title, its tasks and their points.

    Examples
    --------
    >>> s = Section(1, "normalize", (Task("normalize", "normalize", 1),))
    >>> s.key, s.points
    ('1_normalize', 1)
    """

    number: int
    title: str
    tasks: tuple[Task, ...]

    @property
    def key(self) -> str:
        """The grade sheet's column name: ``NUMBER_TITLE``."""
        return f"{self.number}_{self.title}"

    @property
    def points(self) -> int:
        """The section's maximum points (the sum over its tasks)."""
        return sum(t.points for t in self.tasks)


def _s(number: int, title: str, *tasks: tuple) -> Section:
    return Section(number, title, tuple(Task(*t) for t in tasks))


#: The homework's sections in notebook order, with the points of each task.
SECTIONS: tuple[Section, ...] = (
    _s(0, "world_to_cell", ("world_to_cell", "world_to_cell", 1)),
    _s(1, "normalize", ("normalize", "normalize", 1)),
    _s(2, "bayes_update", ("bayes_update", "bayes_update", 1)),
    _s(3, "tile_world", ("histogram_sense", "histogram_sense", 1), ("histogram_move", "histogram_move", 1)),
    _s(4, "odometry_model", ("sample_odometry", "sample_odometry", 2), ("odometry_pdf", "odometry_pdf", 2)),
    _s(5, "beam_model", ("beam_pdf", "beam_model", 2), ("scan_log_likelihood", "scan_log_likelihood", 1)),
    _s(6, "resampling", ("low_variance_sampler", "low_variance_sampler", 2),
       ("multinomial_resampler", "resampler", 1, (("scheme", "multinomial"),)),
       ("effective_sample_size", "effective_sample_size", 1)),
    _s(7, "mcl_step", ("mcl_step", "mcl_step", 2)),
    _s(8, "grid_update", ("grid_update", "grid_update", 2)),
    _s(9, "injection", ("injection", "injection", 1)),
    _s(10, "map_image", ("map_image", "map_image", 1)),
    _s(11, "ekf_update", ("ekf_update", "ekf_update", 2)),
    _s(12, "predict_stop", ("predict_stop", "predict_stop", 2)),
    _s(13, "kld_count", ("kld_count", "kld_loop", 2)),
    _s(14, "xy_log", ("read_xy_log", "xy_reader", 2)),
    _s(15, "innovation_gate", ("in_gate", "innovation_gate", 2)),
)


def max_points() -> int:
    """The homework's total points.

    Examples
    --------
    >>> max_points() == sum(s.points for s in SECTIONS)
    True
    """
    return sum(s.points for s in SECTIONS)
