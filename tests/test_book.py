"""Checks of the book itself: notebook/script pairs, stored outputs, table of contents, README."""

from __future__ import annotations

import json
import re
from pathlib import Path

import jupytext
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
BOOK = ROOT / "book"
NOTEBOOKS = sorted(BOOK.glob("[0-9][0-9]_*.ipynb"))


def _cells(nb):
    out = []
    for c in nb.cells:
        tags = sorted(c.metadata.get("tags", []))
        out.append((c.cell_type, c.source.strip(), tags))
    return out


def test_there_are_notebooks():
    assert NOTEBOOKS, "book/ holds no NN_name.ipynb chapters"


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_and_script_in_sync(nb_path):
    py = nb_path.with_suffix(".py")
    assert py.exists(), f"{nb_path.name} has no jupytext twin {py.name}; run: jupytext --to py:percent {nb_path}"
    nb_cells = _cells(jupytext.read(nb_path))
    py_cells = _cells(jupytext.read(py))
    assert len(nb_cells) == len(py_cells), (
        f"{nb_path.name} has {len(nb_cells)} cells but {py.name} has {len(py_cells)}: "
        f"rebuild with: python tools/build_notebooks.py {py.relative_to(ROOT)}"
    )
    for k, (a, b) in enumerate(zip(nb_cells, py_cells)):
        assert a == b, (
            f"cell {k} differs between {nb_path.name} and {py.name}; "
            f"rebuild with: python tools/build_notebooks.py {py.relative_to(ROOT)}"
        )


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_committed_executed(nb_path):
    nb = json.loads(nb_path.read_text())
    assert nb["metadata"]["kernelspec"]["name"] == "python3"
    code = [c for c in nb["cells"] if c["cell_type"] == "code" and "".join(c["source"]).strip()]
    assert code, f"{nb_path.name} has no code"
    counts = [c["execution_count"] for c in code]
    assert all(isinstance(n, int) for n in counts), f"{nb_path.name}: some code cells were never executed"
    assert counts == list(range(1, len(code) + 1)), f"{nb_path.name} was not executed top to bottom in one run"
    for c in code:
        for o in c.get("outputs", []):
            assert o["output_type"] != "error", f"{nb_path.name} stores an error output"
            if o.get("name") == "stderr":
                text = "".join(o.get("text", ""))
                assert "Warning" not in text, f"{nb_path.name} stores a warning: {text[:200]}"
    src = "\n".join("".join(c["source"]) for c in code)
    assert re.search(r"^\s*(import localize|from localize)", src, re.M), f"{nb_path.name} does not import localize"
    assert "np.random.seed" not in src, "use an explicit np.random.default_rng(seed), not the global seed"


def _toc_files():
    toc = yaml.safe_load((ROOT / "_toc.yml").read_text())
    files = [toc["root"]]
    for key in ("chapters", "sections"):
        for entry in toc.get(key, []) or []:
            files.append(entry["file"])
    for part in toc.get("parts", []) or []:
        for entry in part.get("chapters", []):
            files.append(entry["file"])
    return files


def _readme_chapters():
    text = (ROOT / "README.md").read_text()
    m = re.search(r"<!-- chapters.*?-->(.*?)<!-- end chapters -->", text, re.S)
    assert m, "README.md lacks the <!-- chapters --> ... <!-- end chapters --> list"
    return re.findall(r"\]\((book/[^)]+)\.ipynb\)", m.group(1))


def test_toc_lists_every_chapter_once():
    files = _toc_files()
    assert len(files) == len(set(files))
    for f in files:
        assert (ROOT / f"{f}.ipynb").exists(), f"_toc.yml lists {f} but {f}.ipynb does not exist"
    listed = {f"{f}.ipynb" for f in files}
    for nb in NOTEBOOKS:
        assert str(nb.relative_to(ROOT)) in listed, f"{nb.name} is not in _toc.yml"


def test_readme_chapter_list_matches_toc():
    assert _readme_chapters() == _toc_files()


def test_readme_commands_present():
    text = (ROOT / "README.md").read_text()
    assert 'python -m pip install -e ".[book]" && jupyter lab book/' in text
    assert 'python -m pip install -e ".[test]" && pytest --nbval' in text


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_solutions_hidden_in_html_book(nb_path):
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    from hide_solutions import is_hidden

    nb = jupytext.read(nb_path)
    bad = [k for k, c in enumerate(nb.cells) if not is_hidden(c)]
    assert not bad, f"{nb_path.name}: solution cells {bad} are not hidden; run python tools/hide_solutions.py"


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_no_volatile_output_stored(nb_path):
    """Cells whose output is volatile (timings) store none and are not compared by nbval."""
    nb = json.loads(nb_path.read_text())
    for k, c in enumerate(nb["cells"]):
        tags = c.get("metadata", {}).get("tags", [])
        if "remove-output" in tags and c["cell_type"] == "code":
            assert not c.get("outputs"), f"{nb_path.name} cell {k}: remove-output cell stores output"
            assert "nbval-ignore-output" in tags, f"{nb_path.name} cell {k}: tag it nbval-ignore-output too"
