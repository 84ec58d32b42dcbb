"""Find notebook outputs that depend on floating-point round-off.

Another CPU (or numpy built with other SIMD kernels) rounds ``sin``, ``cos``,
``exp``, ``log`` and friends differently in the last bit. A printed number that
is downstream of resampling, thresholds or long float chains can then change.
This tool makes such a machine on demand: it starts the notebook kernels with an
IPython start-up file that nudges the results of numpy's transcendental ufuncs
and of its sums and products (``np.sum``, ``np.dot``, ...; not the
array methods) by one unit in the last place (ulp) at random, then runs ``pytest --nbval`` on the
notebooks you name. A cell that fails here prints something that a reader's
machine may print differently: print it at the precision its sample supports, or
move the claim into an assertion with a tolerance (see CONTRIBUTING.md).

    python tools/roundoff_fuzz.py book/07_mcl.ipynb [more.ipynb ...] [--seed 1] [pytest options]

It complements a run under another numpy dispatch
(``NPY_DISABLE_CPU_FEATURES``, see CONTRIBUTING.md), which changes the real
kernels but only on the machine you have.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

STARTUP = r'''
import os as _os
import numpy as _np

_rng = _np.random.default_rng(int(_os.environ.get("LOCALIZE_ULP_FUZZ_SEED", "1")))
_NAMES = ("sin", "cos", "tan", "exp", "expm1", "log", "log1p", "log2", "log10", "arctan2", "arctan",
          "arcsin", "arccos", "hypot", "sinh", "cosh", "tanh")
# sums and products: another summation order (SIMD width, BLAS blocking) rounds differently, but a
# sum of whole numbers is exact everywhere, so integer-valued results are left alone
# (not cumsum: a running sum is sequential, so every CPU computes the same one)
_SUMS = ("sum", "mean", "dot", "matmul", "einsum", "prod", "average")


def _nudge(r, whole=False):
    if isinstance(r, _np.ndarray) and r.dtype.kind == "f" and r.size:
        # exact cases (0, +-1, inf, nan) are exact on every CPU: leave them
        m = (_rng.random(r.shape) < 0.5) & _np.isfinite(r) & (r != 0) & (_np.abs(r) != 1)
        if whole:
            m &= r != _np.round(r)
        if m.any():
            r[m] = _np.nextafter(r[m], _np.where(_rng.random(int(m.sum())) < 0.5, _np.inf, -_np.inf))
        return r
    if (isinstance(r, (float, _np.floating)) and _np.isfinite(r) and r != 0 and abs(r) != 1
            and not (whole and r == round(r)) and _rng.random() < 0.5):
        return type(r)(_np.nextafter(r, _np.inf if _rng.random() < 0.5 else -_np.inf))
    return r


class _Fuzzed:
    def __init__(self, uf, whole=False):
        self._uf = uf
        self._whole = whole
        self.__name__ = uf.__name__
        self.__doc__ = uf.__doc__

    def __call__(self, *args, **kwargs):
        r = self._uf(*args, **kwargs)
        if isinstance(r, tuple):
            return tuple(_nudge(x, self._whole) for x in r)
        return _nudge(r, self._whole)

    def __getattr__(self, name):
        return getattr(self._uf, name)


for _n in _NAMES:
    setattr(_np, _n, _Fuzzed(getattr(_np, _n)))
for _n in _SUMS:
    setattr(_np, _n, _Fuzzed(getattr(_np, _n), whole=True))
'''


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("notebooks", nargs="+", type=Path)
    ap.add_argument("--seed", type=int, default=1, help="seed of the random nudges (default 1)")
    args, extra = ap.parse_known_args(argv)   # anything else goes to pytest
    with tempfile.TemporaryDirectory(prefix="ulpfuzz-") as d:
        start = Path(d) / "profile_default" / "startup"
        start.mkdir(parents=True)
        (start / "00-ulp-fuzz.py").write_text(STARTUP)
        env = dict(os.environ, IPYTHONDIR=d, LOCALIZE_ULP_FUZZ_SEED=str(args.seed))
        cmd = [sys.executable, "-m", "pytest", "--nbval", "-q", *map(str, args.notebooks), *extra]
        print("+", " ".join(cmd), f"(ulp nudges, seed {args.seed})", flush=True)
        return subprocess.call(cmd, env=env)


if __name__ == "__main__":
    sys.exit(main())
