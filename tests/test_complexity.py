"""Code is read before it runs: no function of the package above cyclomatic complexity 25 (radon's count)."""

from pathlib import Path

import pytest

radon = pytest.importorskip("radon.complexity", reason="radon is in the test extra: pip install -e '.[test]'")

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks our own tooling, not numerics
pytestmark = pytest.mark.tooling

ROOT = Path(__file__).resolve().parent.parent
LIMIT = 25


def test_no_function_of_the_package_is_above_complexity_25():
    too_complex = []
    for path in sorted((ROOT / "localize").rglob("*.py")):
        for block in radon.cc_visit(path.read_text()):
            if block.complexity > LIMIT:
                too_complex.append(f"{path.relative_to(ROOT)}:{block.lineno} {block.name} ({block.complexity})")
    assert not too_complex, "split these into functions that each do one thing: " + "; ".join(too_complex)


def test_the_check_would_see_a_complex_function():
    branches = "\n".join(f"    if x == {i}:\n        return {i}" for i in range(LIMIT + 1))
    (block,) = radon.cc_visit(f"def f(x):\n{branches}\n    return -1\n")
    assert block.complexity > LIMIT


def test_the_core_run_loop_stays_short():
    import inspect

    from localize.runloop import run

    assert len(inspect.getsource(run).splitlines()) <= 50
