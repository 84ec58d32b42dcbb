"""Choose, and check, another numpy SIMD dispatch for a second notebook pass.

    python tools/other_dispatch.py            # prints a value for NPY_DISABLE_CPU_FEATURES
    NPY_DISABLE_CPU_FEATURES="$v" python tools/other_dispatch.py --check "$v"

numpy picks, at import, the best of the SIMD levels it was built for
(``__cpu_dispatch__``) that this CPU supports. Switching off the highest one
makes numpy run its next-best kernels for sin, cos, exp, sums and sorts, which
round differently in the last bit: the stored outputs of the notebooks must not
notice. ``--check`` exits non-zero unless the named features are really off.
"""

from __future__ import annotations

import sys

from numpy._core import _multiarray_umath as _m  # numpy >= 2.0


def highest_levels() -> list[str]:
    """The dispatch targets this CPU runs, highest first, without the baseline."""
    on = [d for d in _m.__cpu_dispatch__ if _m.__cpu_features__.get(d)]
    return list(reversed(on))


def choose() -> str:
    """Features to disable: the highest dispatched level and everything that needs it.

    On x86-64 with AVX-512 that is every AVX-512 target (numpy then runs its AVX2
    kernels); on a CPU whose best level is AVX2, the AVX2 level (numpy runs its
    baseline kernels). Elsewhere (ARM, ...), the highest dispatched target.
    """
    on = highest_levels()
    if not on:
        raise SystemExit("numpy dispatches to no SIMD level above its baseline on this CPU: "
                         "there is no other dispatch to test")
    avx512 = [d for d in on if d.startswith("AVX512") or d == "X86_V4"]
    return " ".join(avx512 if avx512 else [on[0]])


def main(argv: list[str]) -> int:
    if len(argv) >= 1 and argv[0] == "--check":
        want = argv[1].split() if len(argv) > 1 else []
        still = [d for d in want if _m.__cpu_features__.get(d)]
        if not want or still:
            print(f"NPY_DISABLE_CPU_FEATURES did not take effect: still on: {still or 'nothing asked'}",
                  file=sys.stderr)
            return 1
        print("numpy dispatch now:", ", ".join(highest_levels()) or "baseline only",
              "| off:", ", ".join(want))
        return 0
    print(choose())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
