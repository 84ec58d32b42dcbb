"""Time every widget's default redraw: ``python benchmarks/bench_widgets.py``.

The book promises that each interactive figure redraws in under 100 ms at its
default settings (issue 7). This script finds every ``localize.widgets.<topic>``
module that exists *now* (modules added later are picked up automatically),
and for each entry of the module's ``DEMOS`` dict it measures

* **callback**: the zero-argument demo callable, i.e. the widget's callback
  with its default parameters, building a matplotlib Figure;
* **redraw**: callback plus rendering that Figure to PNG the way Jupyter's
  inline backend does (100 dpi, ``bbox_inches="tight"``), which is what a reader waits for after moving a
  slider (the browser then only swaps an ``<img>``).

Each demo is called once to warm up (imports, font cache, lookup tables built
on first use), then repeated until about ``--budget`` seconds have passed (at
least 3, at most ``--max-repeats`` runs). The table shows medians in
milliseconds of wall-clock time and of CPU time (``time.process_time``: this
process only, so it hardly changes when other jobs share the cores), and
whether the callback (the issue's measure) and the whole redraw meet the
100 ms target on CPU time.

Wall-clock numbers from a shared machine are noisy: run it on a quiet machine
before reading much into single numbers. Exits with status 0 even when a demo is
slow (it is a report, not a test); a demo that raises is reported in the table
and makes the exit status 1.

Widget module convention (checked by ``tests/test_widgets_common.py``)
--------------------------------------------------------------------------
``DEMOS: dict[str, Callable[[], matplotlib.figure.Figure]]`` maps a demo name
to a zero-argument callable that runs the widget's callback once with its
default parameters and returns the Figure. Optional
``DEMO_VARIANTS: dict[str, list[Callable[[], Figure]]]`` lists, for a demo
name, callables with *other* parameter values whose figures must differ.
"""

from __future__ import annotations

import argparse
import importlib
import io
import pkgutil
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from types import ModuleType

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

TARGET_MS = 100.0
# Jupyter's inline backend renders at figure.dpi (100 by default) with bbox_inches="tight"
# (matplotlib_inline.config.InlineBackend.print_figure_kwargs); "tight" costs an extra draw.
INLINE_DPI = 100
INLINE_KWARGS = {"format": "png", "bbox_inches": "tight"}


def widget_modules() -> Iterator[tuple[str, ModuleType | Exception]]:
    """Yield ``(name, module)`` for every public ``localize.widgets`` submodule.

    A module that fails to import is yielded as ``(name, exception)`` so that
    the report can show it instead of stopping.
    """
    import localize.widgets as pkg

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        full = f"{pkg.__name__}.{info.name}"
        try:
            yield full, importlib.import_module(full)
        except Exception as exc:  # noqa: BLE001 - reported, not hidden
            yield full, exc


def time_demo(demo: Callable[[], object], budget: float = 1.0, max_repeats: int = 15,
              dpi: int = INLINE_DPI) -> dict[str, list[float]]:
    """Time one demo. Returns lists of seconds: callback and redraw (callback + PNG), wall and CPU."""
    fig = demo()  # warm-up: imports, caches, fonts
    fig.savefig(io.BytesIO(), dpi=dpi, **INLINE_KWARGS)
    plt.close(fig)
    t: dict[str, list[float]] = {"cb_wall": [], "cb_cpu": [], "rd_wall": [], "rd_cpu": []}
    start = time.perf_counter()
    while len(t["cb_wall"]) < max_repeats and (len(t["cb_wall"]) < 3 or time.perf_counter() - start < budget):
        c0, t0 = time.process_time(), time.perf_counter()
        fig = demo()
        c1, t1 = time.process_time(), time.perf_counter()
        fig.savefig(io.BytesIO(), dpi=dpi, **INLINE_KWARGS)
        c2, t2 = time.process_time(), time.perf_counter()
        plt.close(fig)
        t["cb_wall"].append(t1 - t0)
        t["cb_cpu"].append(c1 - c0)
        t["rd_wall"].append(t2 - t0)
        t["rd_cpu"].append(c2 - c0)
    return t


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=1.0, help="seconds of timed runs per demo (default 1)")
    ap.add_argument("--max-repeats", type=int, default=15, help="most timed runs per demo (default 15)")
    args = ap.parse_args(argv)

    rows, failed = [], False
    for name, mod in widget_modules():
        short = name.rsplit(".", 1)[1]
        if isinstance(mod, Exception):
            rows.append(f"| {short} | (import failed) | {type(mod).__name__}: {mod} | | | | | |")
            failed = True
            continue
        demos = getattr(mod, "DEMOS", None)
        if not demos:
            rows.append(f"| {short} | (no DEMOS) | | | | | | |")
            continue
        for demo_name, demo in demos.items():
            try:
                t = time_demo(demo, args.budget, args.max_repeats)
            except Exception as exc:  # noqa: BLE001 - reported in the table
                rows.append(f"| {short} | {demo_name} | {type(exc).__name__}: {exc} | | | | | |")
                failed = True
                continue
            ms = {k: 1e3 * statistics.median(v) for k, v in t.items()}
            ok = {k: "yes" if ms[k] < TARGET_MS else "**no**" for k in ("cb_cpu", "rd_cpu")}
            rows.append(f"| {short} | {demo_name} | {ms['cb_wall']:.1f} | {ms['cb_cpu']:.1f} | {ms['rd_wall']:.1f} "
                        f"| {ms['rd_cpu']:.1f} | {ok['cb_cpu']} | {ok['rd_cpu']} ({len(t['cb_wall'])} runs) |")

    print(f"Widget redraw times at default settings (median ms; redraw = callback + PNG at {INLINE_DPI} dpi, "
          f"bbox tight; target {TARGET_MS:.0f} ms, judged on CPU time)\n")
    print("| module | demo | callback wall | callback CPU | redraw wall | redraw CPU | callback < 100 ms "
          "| redraw < 100 ms |")
    print("|---|---|---:|---:|---:|---:|---|---|")
    print("\n".join(rows) if rows else "| (no localize.widgets modules yet) | | | | | | | |")
    print(f"\nmatplotlib {matplotlib.__version__}, Python {sys.version.split()[0]}. Wall-clock columns "
          "grow when other processes share the cores; the CPU column (this process only) much less.")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
