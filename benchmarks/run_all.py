"""Run every benchmark script in this folder and collect their tables.

    python benchmarks/run_all.py            # print all tables
    python benchmarks/run_all.py --write    # also write benchmarks/RESULTS.md

Each ``bench_*.py`` script is standalone and prints a Markdown table of its
speed targets (measured on one core: run with ``taskset -c 0`` to pin it).
Benchmarks are not tests: nothing here fails a build.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write", action="store_true", help="write benchmarks/RESULTS.md")
    ap.add_argument("only", nargs="*", help="names of scripts to run (default: all)")
    args = ap.parse_args(argv)
    scripts = sorted(HERE.glob("bench_*.py"))
    if args.only:
        scripts = [s for s in scripts if any(o in s.name for o in args.only)]
    env = dict(os.environ, MPLBACKEND="Agg")
    parts = [
        "# Benchmark results",
        "",
        f"Measured {_dt.date.today().isoformat()} on {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, with `python benchmarks/run_all.py --write`.",
        "",
    ]
    status = 0
    for s in scripts:
        print(f"## {s.stem}", flush=True)
        r = subprocess.run([sys.executable, str(s)], capture_output=True, text=True, env=env, cwd=HERE.parent)
        out = r.stdout.strip()
        print(out)
        if r.returncode:
            status = 1
            print(r.stderr, file=sys.stderr)
        parts += [f"## {s.stem}", "", out, ""]
    if args.write:
        (HERE / "RESULTS.md").write_text("\n".join(parts) + "\n")
    return status


if __name__ == "__main__":
    sys.exit(main())
