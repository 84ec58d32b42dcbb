"""Grading a class: thirty generated submissions with ``python -m localize.grade``'s defaults, 2 at a time.

The class is ``tools/make_submissions.py``'s kinds repeated (full marks, the
empty template, three classic mistakes, an endless loop in one function,
three tamperings), numbered ``student01_full`` ... Each submission runs in its
own limited process (``localize.grade.runner``); the looping ones cost the
check's time limit (20 s by default) on top of their grading.

Target (issue 42): thirty submissions in under five minutes on 2 cores.

    nice python benchmarks/bench_grade.py            # print the table
    nice python benchmarks/bench_grade.py --write    # also write its section of RESULTS.md
"""

from __future__ import annotations

import argparse
import collections
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tools"))
sys.path.insert(0, str(HERE))

from _util import table  # noqa: E402
from make_submissions import make_class  # noqa: E402

from localize.grade import Limits, grade_class, max_points  # noqa: E402

TARGET_S = 300.0


def measure(count: int, jobs: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        kinds = make_class(Path(tmp) / "submissions", count)
        load_before = os.getloadavg()[0]
        cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        grades = grade_class(Path(tmp) / "submissions", Path(tmp) / "grades", jobs=jobs, limits=Limits())
        wall = time.perf_counter() - t0
        cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        load_after = os.getloadavg()[0]
    totals = collections.Counter(kinds[g.student] for g in grades if g.total == max_points())
    return {
        "submissions": len(grades), "jobs": jobs, "wall [s]": f"{wall:.1f}",
        "wall per submission [s]": f"{wall / len(grades):.1f}",
        "CPU of the graders [s]": f"{(cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime):.1f}",
        "load average before / after": f"{load_before:.1f} / {load_after:.1f}",
        "full marks": f"{sum(totals.values())} (all {sum(1 for k in kinds.values() if k == 'full')} 'full')",
        "target": f"< {TARGET_S:.0f} s", "ok": "yes" if wall < TARGET_S else "**no**",
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=30, help="submissions (default 30)")
    ap.add_argument("--jobs", type=int, default=2, help="submissions graded at once (default 2)")
    ap.add_argument("--write", action="store_true", help="write the bench_grade section of RESULTS.md")
    args = ap.parse_args(argv)
    row = measure(args.count, args.jobs)
    columns = list(row)
    text = "\n".join([
        f"# bench_grade: {row['submissions']} generated submissions graded by `python -m localize.grade` "
        f"(defaults: {Limits().task_s:g} s per check, {Limits().memory_mb:g} MiB), {row['jobs']} at a time",
        "", table([row], columns), "",
        f"Measured {time.strftime('%Y-%m-%d')} on {os.cpu_count()} cores, shared: the load average (1 min) says how "
        "busy the machine was; the wall time "
        "includes the looping submissions' time limit. `nice python benchmarks/bench_grade.py --write`.",
    ])
    print(text)
    if args.write:
        from bench_global import write_section

        write_section("## bench_grade\n\n" + text, "bench_grade")
    return 0


if __name__ == "__main__":
    sys.exit(main())
