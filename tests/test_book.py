"""Checks of the book itself: notebook/script pairs, stored outputs, table of contents, README."""

from __future__ import annotations

import json
import re
from pathlib import Path

import jupytext
import nbformat
import pytest
import yaml

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks the book's structure, not numerics
pytestmark = pytest.mark.tooling

ROOT = Path(__file__).resolve().parents[1]
BOOK = ROOT / "book"
NOTEBOOKS = sorted(BOOK.glob("[0-9][0-9]_*.ipynb"))


def _twin(nb_path: Path) -> Path:
    """The jupytext source of a chapter: book/src/NN_name.py (pyproject.toml's formats = "ipynb,src//py:percent")."""
    return nb_path.parent / "src" / (nb_path.stem + ".py")


def _cells(nb):
    out = []
    for c in nb.cells:
        tags = sorted(c.metadata.get("tags", []))
        out.append((c.cell_type, c.source.strip(), tags))
    return out


def test_there_are_notebooks():
    assert NOTEBOOKS, "book/ holds no NN_name.ipynb chapters"


def test_each_chapter_is_listed_once_in_the_file_browser():
    """The jupytext twins live in book/src/, not beside the notebooks a reader opens."""
    beside = sorted(p.name for p in BOOK.glob("[0-9][0-9]_*.py"))
    assert not beside, f"jupytext twins beside the notebooks: {beside}; they belong in book/src/ (git mv them)"
    config = (ROOT / "pyproject.toml").read_text()
    assert 'formats = "ipynb,src//py:percent"' in config, "pyproject.toml's [tool.jupytext] must pair into src/"


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_pairs_with_its_twin_in_src(nb_path):
    """JupyterLab's jupytext follows the notebook's own pairing: saving a chapter updates book/src/, nothing else."""
    formats = nbformat.read(nb_path, as_version=4).metadata.get("jupytext", {}).get("formats")
    assert formats == "ipynb,src//py:percent", (
        f"{nb_path.name} pairs as {formats!r}; rebuild with: python tools/build_notebooks.py {nb_path.relative_to(ROOT)}")


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_and_script_in_sync(nb_path):
    py = _twin(nb_path)
    assert py.exists(), (f"{nb_path.name} has no jupytext twin {py.relative_to(ROOT)}; "
                         f"run: jupytext --set-formats ipynb,src//py:percent {nb_path.relative_to(ROOT)}")
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


def _unversioned(text: str) -> str:
    """``text`` without the version number in its header's ``jupytext_version:`` line (any other difference in
    what jupytext writes, the header included, still counts)."""
    return re.sub(r"^(#\s+jupytext_version:).*$", r"\1", text, count=1, flags=re.M)


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_script_is_what_jupytext_writes_from_the_notebook(nb_path):
    # JupyterLab's jupytext refuses to open a notebook that is newer than its twin and differs
    # from it even in the order of a cell's metadata keys ("File Load Error ... is more recent
    # than"); a clone sets the files' times in any order, so the twin must be jupytext's own text
    py = _twin(nb_path)
    want = jupytext.writes(jupytext.read(nb_path), fmt="py:percent")
    # the header names the jupytext release that wrote it: a newer one installed is not a difference in the text
    assert _unversioned(py.read_text()) == _unversioned(want), (
        f"{py.name} is not what jupytext writes from {nb_path.name}; "
        f"rebuild with: python tools/build_notebooks.py {py.relative_to(ROOT)}")


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


def _hide_solutions():
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    import hide_solutions

    return hide_solutions


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_solutions_hidden_in_jupyterlab_and_html_book(nb_path):
    """Code solutions open collapsed in JupyterLab (jupyter.source_hidden) and in the book (hide-cell)."""
    is_hidden = _hide_solutions().is_hidden
    for which, nb in (("notebook", nbformat.read(nb_path, as_version=4)), ("twin", jupytext.read(_twin(nb_path)))):
        bad = [k for k, c in enumerate(nb.cells) if not is_hidden(c)]
        assert not bad, f"{nb_path.name} ({which}): solution cells {bad} are not hidden; run python tools/hide_solutions.py"


def _math_free(src: str) -> tuple[str, int]:
    """Replace $...$ and $$...$$ by placeholders, as JupyterLab does before its markdown parser runs."""
    n = 0

    def sub(_m):
        nonlocal n
        n += 1
        return f"MATH{n}X"

    return re.sub(r"\$\$.+?\$\$|\$(?:[^$\n]|\n(?!\n))+?\$", sub, src, flags=re.S), n  # not across paragraphs


SOLUTION_MD = [(nb.name, k, c.source) for nb in NOTEBOOKS for k, c in enumerate(jupytext.read(nb).cells)
               if c.cell_type == "markdown" and "solution" in c.metadata.get("tags", [])]


def test_there_are_markdown_solutions():
    assert len(SOLUTION_MD) >= 10


@pytest.mark.parametrize("name, k, src", SOLUTION_MD, ids=[f"{n}-{k}" for n, k, _ in SOLUTION_MD])
def test_markdown_solutions_render_collapsed_in_both(name, k, src):
    """Render each written-out solution as JupyterLab (CommonMark, math set aside) and MyST (dollarmath) do.

    Both must give one closed ``<details>`` block titled Solution whose inside
    is rendered markdown (no raw MyST directive, no literal ``**``), with every
    formula kept whole for MathJax.
    """
    from markdown_it import MarkdownIt
    from mdit_py_plugins.dollarmath import dollarmath_plugin

    lab_src, n_math = _math_free(src)
    lab = MarkdownIt("commonmark").render(lab_src)
    myst = MarkdownIt("commonmark").use(dollarmath_plugin).render(src)
    for who, html in (("JupyterLab", lab), ("Jupyter Book", myst)):
        where = f"{name} cell {k} in {who}"
        assert html.lstrip().startswith("<details>") and html.rstrip().endswith("</details>"), where
        assert html.count("<details") == 1 and "<details open" not in html, where
        assert re.search(r"<summary>.*Solution.*</summary>", html), where
        assert "{admonition}" not in html and ":class:" not in html and "````" not in html, where
        assert "**" not in html, f"{where}: markdown inside <details> was not rendered"
        assert "<h1" not in html and "<h2" not in html and "<h3" not in html, f"{where}: a heading in a solution"
    for i in range(1, n_math + 1):
        assert f"MATH{i}X" in lab, f"{name} cell {k}: formula {i} was split by the markdown parser"
    assert myst.count('class="math') == n_math, f"{name} cell {k}: MyST did not see every formula as math"
    assert "$" not in re.sub(r'<(span|div) class="math[^"]*">.*?</\1>', "", myst, flags=re.S), (
        f"{name} cell {k}: a stray $ is shown as text")


def test_hide_solutions_converts_the_old_admonition_form():
    hs = _hide_solutions()
    cell = nbformat.v4.new_markdown_cell("````{admonition} Solution\n:class: dropdown, tip\n\n### Part a\n"
                                         "Take $\\gamma = 1$.\n````", metadata={"tags": ["solution"]})
    assert not hs.is_hidden(cell)
    assert hs.hide(cell) and hs.is_hidden(cell)
    assert "{admonition}" not in cell.source and "**Part a**" in cell.source and "$\\gamma = 1$" in cell.source
    assert not hs.hide(cell)                      # idempotent
    code = nbformat.v4.new_code_cell("x = 1", metadata={"tags": ["solution"]})
    assert not hs.is_hidden(code) and hs.hide(code) and hs.is_hidden(code)
    assert code.metadata["jupyter"] == {"source_hidden": True, "outputs_hidden": True}
    assert code.source.splitlines()[0].startswith("# Solution") and not hs.hide(code)


@pytest.mark.parametrize("nb_path", NOTEBOOKS, ids=lambda p: p.name)
def test_no_volatile_output_stored(nb_path):
    """Cells whose output is volatile (timings) store none and are not compared by nbval."""
    nb = json.loads(nb_path.read_text())
    for k, c in enumerate(nb["cells"]):
        tags = c.get("metadata", {}).get("tags", [])
        if "remove-output" in tags and c["cell_type"] == "code":
            assert not c.get("outputs"), f"{nb_path.name} cell {k}: remove-output cell stores output"
            assert "nbval-ignore-output" in tags, f"{nb_path.name} cell {k}: tag it nbval-ignore-output too"


# --- characters and cell kinds that render wrongly ------------------------------------------------

# A control character in a cell's source is always a mistake. The one that happens: a Python string
# without the r prefix turns "\tfrac" into TAB + "frac" and "\big" into BACKSPACE + "ig", and the
# formula renders broken. TAB is refused too, also in code: the project indents with spaces (ruff),
# and a tab wanted inside a string is written as the escape "\t", not as the character itself.
CONTROL = re.compile(r"[\x00-\x09\x0b-\x1f\x7f]")       # every C0 control and DEL except "\n"
SOURCES = NOTEBOOKS + sorted((BOOK / "homework").glob("*.ipynb"))


def _control_characters(text: str) -> list[str]:
    """Each control character of ``text`` with its line number and the text around it."""
    found = []
    for m in CONTROL.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        found.append(f"line {line}: {m.group()!r} in {text[max(0, m.start() - 25):m.end() + 15]!r}")
    return found


def test_the_control_character_check_catches_an_unescaped_tfrac():
    assert _control_characters("$\tfrac12$ and $\\big($")[0].startswith("line 1: '\\t'")
    assert len(_control_characters("a \\tfrac\n\\big\r\n")) == 1            # only the \r
    assert not _control_characters("$\\tfrac12 \\big($\n    indented with spaces\n")


@pytest.mark.parametrize("nb_path", SOURCES, ids=lambda p: p.name)
def test_no_control_characters_in_notebook_or_twin(nb_path):
    """No cell source (notebook) and no line of the twin holds a TAB, BACKSPACE or other control character."""
    bad = []
    for k, cell in enumerate(json.loads(nb_path.read_text())["cells"]):
        bad += [f"{nb_path.name} cell {k} ({cell['cell_type']}) {hit}"
                for hit in _control_characters("".join(cell["source"]))]
    twins = [_twin(nb_path)] if nb_path.parent == BOOK else sorted(nb_path.parent.glob("*.py"))
    for py in twins:
        bad += [f"{py.relative_to(ROOT)} {hit}" for hit in _control_characters(py.read_text())]
    assert not bad, ("control characters (a LaTeX backslash read as an escape: write \\\\tfrac or use a raw "
                     "string; indent with spaces):\n" + "\n".join(bad))


# A code cell holding prose: jupytext makes a code cell of a "# %%" block, so a lost "[markdown]"
# marker turns a section (its heading and its formulas) into Python comments that the reader sees as
# code. Caught: a code cell whose every line is a comment, and any comment shaped like a markdown
# heading ("# ## Title") or a display formula ("# $$ ... $$").
PROSE_IN_COMMENT = re.compile(r"^\s*#\s?(#{1,6}\s+\S|\$\$)")


def _prose_in_code(source: str) -> str | None:
    """Why a code cell's source looks like markdown that lost its marker (None if it does not)."""
    lines = [line for line in source.splitlines() if line.strip()]
    if lines and all(line.lstrip().startswith("#") for line in lines):
        return f"every line is a comment: {lines[0]!r}"
    for line in lines:
        if PROSE_IN_COMMENT.match(line):
            return f"a markdown heading or formula as a comment: {line.strip()!r}"
    return None


def test_the_prose_in_code_check():
    assert _prose_in_code("# ## KLD-sampling\n#\n# text")                    # only comments
    assert _prose_in_code("fig\n#\n# ## KLD-sampling: as many as needed\n# text")
    assert _prose_in_code("x = 1\n# $$ n(k) = k $$")
    assert _prose_in_code("# Solution\nx = 1  # the # count\n# #1 is the first") is None
    assert _prose_in_code("# the next lines draw\nplt.show()") is None


KNOWN_PROSE_IN_CODE: dict[str, str] = {}   # notebook name -> why it is a known failure (none today)


@pytest.mark.parametrize("nb_path", [
    pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=KNOWN_PROSE_IN_CODE[p.name]))
    if p.name in KNOWN_PROSE_IN_CODE else p for p in NOTEBOOKS], ids=lambda p: p.name)
def test_no_markdown_stored_as_comments_in_a_code_cell(nb_path):
    bad = [f"cell {k}: {why}" for k, c in enumerate(nbformat.read(nb_path, as_version=4).cells)
           if c.cell_type == "code" and (why := _prose_in_code(c.source))]
    assert not bad, (f"{nb_path.name}: markdown in a code cell (a missing '# %% [markdown]' marker in "
                     f"{_twin(nb_path).relative_to(ROOT)}?):\n" + "\n".join(bad))
