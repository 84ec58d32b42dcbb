"""One MCL cycle side by side with Beluga (C++), before and after a change to ``localize`` (issue 41).

    python benchmarks/bench_peer.py [WORKDIR] [--before TREE] [--float32] [--rounds 3] [--ns 10000 50000 200000]

WORKDIR (default: ``$BELUGA_BENCH_WORKDIR``, else ``../beluga-work`` beside the repository) is what the shared Beluga benchmark (``../shared/peers/beluga-bench``, its README) builds and
exports: ``WORKDIR/bin/beluga_cycle_O2``, ``_O3`` (its ``build.sh``) and ``WORKDIR/data``
(its ``export_inputs.py``). One cycle = motion + likelihood-field update (100 beams) + normalisation
+ resampling, on the 800 x 800 benchmark map; each program prints the median of 10 cycles. ``TREE``
is a checkout of ``localize`` to compare against (e.g. ``git worktree add /tmp/before main``): its
``py_cycle.py`` runs with ``PYTHONPATH=TREE``, the current one with this repository's root. ``--float32``
adds a run of ``py_cycle.py`` whose likelihood field is built with ``dtype=np.float32`` (the opt-in that
sums each pose's beams in single precision; a copy of the script with that one argument added).

Every round runs, for each N, Beluga -O2, localize (after), Beluga -O3, localize (before), one after
the other and each pinned to one core (``taskset -c 1``), so that the machine's drift hits them
alike; the table gives each program's median over the rounds of its per-run median, and the median
(and range) over the rounds of each round's ratio. Peak memory is each child's maximum resident set size (``os.wait4``), the largest
over the rounds. The load average is printed beside the table: on a shared machine only the ratios
mean anything.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PEER = ROOT.parent / "shared" / "peers" / "beluga-bench"


def run(cmd: list[str], env: dict | None = None) -> tuple[float, float]:
    """(median ms the program printed, its peak resident memory in MB)."""
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", "1", *cmd]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    m = re.search(r"median_ms=([0-9.]+)", out)
    if proc.returncode != 0 or m is None:
        raise SystemExit(f"{' '.join(cmd)} failed (exit {proc.returncode}): {out.strip()[-300:]}")
    return float(m.group(1)), usage.ru_maxrss / 1024.0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("workdir", type=Path, nargs="?",
                    default=Path(os.environ.get("BELUGA_BENCH_WORKDIR", ROOT.parent / "beluga-work")),
                    help="the Beluga benchmark's WORKDIR (bin/ and data/)")
    ap.add_argument("--before", type=Path, help="a checkout of localize to compare against")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--ns", type=int, nargs="+", default=[10_000, 50_000, 200_000])
    ap.add_argument("--peer", type=Path, default=PEER, help="the beluga-bench directory (its py_cycle.py)")
    ap.add_argument("--float32", action="store_true", help="also run the cycle with LikelihoodField(dtype=np.float32)")
    args = ap.parse_args(argv)
    data, bins, cycle = args.workdir / "data", args.workdir / "bin", args.peer / "py_cycle.py"
    missing = [f for f in (bins / "beluga_cycle_O2", bins / "beluga_cycle_O3", cycle, data / "map.u8")
               if not f.exists()]
    if missing:   # a benchmark, not a test: say what to do and stop without failing run_all.py
        print(f"bench_peer: skipped, {missing[0]} is missing: build Beluga and export the inputs into WORKDIR "
              f"as {args.peer / 'README.md'} says, then pass WORKDIR (or set BELUGA_BENCH_WORKDIR)")
        return
    progs = {"Beluga -O2": ([str(bins / "beluga_cycle_O2"), str(data), "{n}", "seq"], None),
             "localize": ([sys.executable, str(cycle), str(data), "{n}"], {**os.environ, "PYTHONPATH": str(ROOT)})}
    progs["Beluga -O3"] = ([str(bins / "beluga_cycle_O3"), str(data), "{n}", "seq"], None)
    if args.before:
        progs["localize before"] = (progs["localize"][0], {**os.environ, "PYTHONPATH": str(args.before)})
    if args.float32:
        progs["localize float32"] = ([sys.executable, float32_cycle(cycle), str(data), "{n}"], progs["localize"][1])
    times: dict = {(p, n): [] for p in progs for n in args.ns}
    peaks: dict = {(p, n): 0.0 for p in progs for n in args.ns}
    loads = [os.getloadavg()[0]]
    for r in range(args.rounds):
        for n in args.ns:
            for name, (cmd, env) in progs.items():
                ms, mb = run([c.format(n=n) for c in cmd], env)
                times[name, n].append(ms)
                peaks[name, n] = max(peaks[name, n], mb)
            loads.append(os.getloadavg()[0])
        print(f"round {r + 1}/{args.rounds} done, load {loads[-1]:.1f}", file=sys.stderr)
    report(times, peaks, list(progs), args.ns, args.rounds, loads, bool(args.before))

def float32_cycle(cycle: Path) -> str:
    """A copy of ``py_cycle.py`` (in the temporary directory) whose likelihood field sums in float32."""
    text = cycle.read_text()
    call = "sigma_hit=0.2)"
    if text.count(call) != 1:
        raise SystemExit(f"{cycle}: expected one LikelihoodField(..., {call} call to add dtype=np.float32 to")
    path = Path(tempfile.gettempdir()) / "py_cycle_float32.py"
    path.write_text(text.replace(call, "sigma_hit=0.2, dtype=np.float32)"))
    return str(path)


def report(times: dict, peaks: dict, names: list[str], ns: list[int], rounds: int, loads: list[float],
           before: bool) -> None:
    """Print the two Markdown tables: times with ratios, then peak memory."""
    med = {k: statistics.median(v) for k, v in times.items()}
    cols = [f"{p} [ms]" for p in names] + ["localize / Beluga -O3"]
    if before:
        cols.append("localize / before")
    if "localize float32" in names:
        cols.append("float32 / Beluga -O3")
    print(f"One MCL cycle (median of 10 cycles a run, median of {rounds} interleaved rounds), one core; "
          f"1-minute load average {min(loads):.1f}-{max(loads):.1f} on {os.cpu_count()} cores\n")
    print("| N | " + " | ".join(cols) + " |")
    print("|---:|" + "---:|" * len(cols))
    def ratio(a: str, b: str, n: int) -> str:
        """Median over the rounds of the round's ratio (the two ran back to back), and its range."""
        r = sorted(x / y for x, y in zip(times[a, n], times[b, n]))
        return f"{statistics.median(r):.2f}x ({r[0]:.2f}-{r[-1]:.2f})"

    for n in ns:
        row = [f"{med[p, n]:.1f}" for p in names] + [ratio("localize", "Beluga -O3", n)]
        if before:
            row.append(ratio("localize", "localize before", n))
        if "localize float32" in names:
            row.append(ratio("localize float32", "Beluga -O3", n))
        print(f"| {n:,} | " + " | ".join(row) + " |")
    print("\nPeak resident memory [MB] (largest over the rounds)\n")
    print("| N | " + " | ".join(names) + " |")
    print("|---:|" + "---:|" * len(names))
    for n in ns:
        print(f"| {n:,} | " + " | ".join(f"{peaks[p, n]:.0f}" for p in names) + " |")


if __name__ == "__main__":
    main()
