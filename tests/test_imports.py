"""The import graph of the ``localize`` package: no cycle, and algorithms never import presentation.

The graph is read from the source with :mod:`ast` (nothing is imported): every ``import`` and
``from ... import`` statement of a module, at module level and inside functions alike, gives an
edge from the module to the ``localize`` module it names. A function-level import hides a cycle
from the interpreter but not from a reader, so it counts here too.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks our own tooling, not numerics
pytestmark = pytest.mark.tooling

PACKAGE = Path(__file__).resolve().parent.parent / "localize"

#: Presentation: figures, widgets, the homework's self-checks and the command line. Everything else in
#: the package is an algorithm, a model, a world, a reader or a library pipeline, and may not import these.
PRESENTATION = ("localize.plot", "localize.widgets", "localize.check", "localize.cli", "localize.__main__", "localize.grade")


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _resolve(importer: str, is_package: bool, level: int, module: str | None) -> str:
    """The absolute name of ``from <level dots><module> import ...`` written in ``importer``."""
    if level == 0:
        return module or ""
    base = importer.split(".") if is_package else importer.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def _known(name: str, modules: set[str]) -> str | None:
    """``name`` or its longest prefix that is a module of the package (``localize.io.ros.read`` -> ``localize.io.ros``)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


@functools.lru_cache(maxsize=1)
def import_graph() -> dict[str, set[str]]:
    """``{module: modules of the package it imports}`` for every module of ``localize``.

    ``from . import sensors`` names the submodule ``localize.sensors``; ``from .io import LaserLog``
    names the package ``localize.io`` (its ``__init__``).
    """
    files = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    modules = set(files)
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(name, is_package, node.level, node.module)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            for t in targets:
                hit = _known(t, modules)
                if hit is not None and hit != name:
                    edges.add(hit)
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of modules (first repeated at the end), or None.

    A module's ``__init__`` importing its own submodules is not a cycle of ideas (the package re-exports
    them), so the edges from a package to its own submodules, and from a submodule to its parent
    package's ``__init__``, are left out.
    """
    def own(a: str, b: str) -> bool:
        return b.startswith(a + ".") or a.startswith(b + ".")

    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if own(m, n):
                continue
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state:
                found = visit(n)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return None


def _is_presentation(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in PRESENTATION)


def test_the_graph_is_read_from_the_source():
    g = import_graph()
    # edges the package is known to have, one of each form the parser must read
    assert "localize._checks" in g["localize.grid"]            # module level: `from ._checks import ...`
    assert "localize.plot.mcl" in g["localize.cli"]            # function level: `from .plot.mcl import ...`
    assert "localize.settings" in g["localize.cli"]            # `from . import settings as _settings`
    assert "localize.io.rosbag" in g["localize.cli"]           # `from .io.rosbag import BAG_FORMATS`
    assert "localize.sensors" in g["localize.pipeline"]        # function level: `from . import sensors`
    assert "localize.grid" not in g["localize._checks"]        # DESIGN: _checks imports no layer above geometry
    assert len(g) >= 40


def test_the_cycle_finder_finds_a_cycle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycle(g) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
    assert find_cycle({"localize.io": {"localize.io.ros"}, "localize.io.ros": {"localize.io"}}) is None


def test_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


ALGORITHMS = sorted(m for m in import_graph() if not _is_presentation(m) and m != "localize")


@pytest.mark.parametrize("module", ALGORITHMS)
def test_algorithms_never_import_presentation(module):
    bad = sorted(n for n in import_graph()[module] if _is_presentation(n))
    assert not bad, f"{module} imports {', '.join(bad)} (presentation: figures, widgets, checks, command line)"
