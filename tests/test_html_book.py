"""The static HTML book builds cleanly and every chapter is there, with its figures and working links.

One ``jupyter-book build`` per test session (Jupyter Book 1, execution off, as
``_config.yml`` says) feeds all the checks in this module:

* the build exits 0 and prints no Sphinx warning or error (missing files,
  unknown references, documents outside the toc, bad toc entries ...) other
  than those matched by ``ALLOWED_WARNINGS`` (empty: add a pattern only with a
  comment saying why it is harmless);
* every file that ``_toc.yml`` lists has an HTML page with a title;
* every internal link, image, script and stylesheet of every page resolves to a
  file of the build, and every ``#fragment`` into a page of the book names an
  element id of that page;
* each chapter page shows at least as many images as its notebook has stored
  PNG/JPEG/SVG outputs (so figures are not lost, e.g. by stripped outputs);
* no page needs the network (scripts, stylesheets, images from other hosts),
  since the book must render offline;
* a widget output cell is followed by a code cell with a static figure, for
  readers of the HTML book where widgets cannot run (checked on the
  notebooks, no build needed);
* a screenshot of the first page is saved for a human to look at (under
  ``$PYTEST_ARTIFACTS/html-book`` or a temporary folder printed in the run),
  when Chromium and playwright are installed.

The build runs on a copy of the checkout without hidden folders, ``_build``
and caches, so that local debris (``.pytest_cache`` ...) cannot add pages or
warnings, and nothing is written into the working tree. It takes about 10 s
for the preface alone on this 2-core machine. The checks follow whatever
``_toc.yml`` lists, so they keep working as chapters are added.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlparse

import nbformat
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
TOC = ROOT / "_toc.yml"
SOURCE_SUFFIXES = (".ipynb", ".md", ".rst", ".py")
ALLOWED_WARNINGS: list[str] = []  # regexes of harmless warnings, each with a comment saying why
EXTERNAL_SCHEMES = {"http", "https", "mailto", "tel", "javascript", "data", "ftp"}
IMAGE_MIMES = ("image/png", "image/jpeg", "image/svg+xml", "image/gif")
WIDGET_MIME = "application/vnd.jupyter.widget-view+json"
REMOVED_TAGS = {"remove-output", "remove-cell", "remove_output", "remove_cell"}
ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def _jupyter_book() -> str | None:
    exe = Path(sys.executable).with_name("jupyter-book")
    return str(exe) if exe.exists() else shutil.which("jupyter-book")


def toc_files(toc: Path = TOC) -> list[str]:
    """Document names (paths without suffix, relative to the book root) that ``_toc.yml`` lists, in order."""
    data = yaml.safe_load(toc.read_text())
    found: list[str] = []

    def walk(node):
        if isinstance(node, dict):
            for key in ("root", "file"):
                if isinstance(node.get(key), str):
                    found.append(node[key])
            if isinstance(node.get("glob"), str):
                found.extend(sorted(str(p.relative_to(toc.parent)) for p in toc.parent.glob(node["glob"])
                                    if p.suffix in {".ipynb", ".md"}))
            for value in node.values():
                if isinstance(value, (dict, list)):
                    walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(data)
    names = []
    for f in found:
        for suffix in SOURCE_SUFFIXES:
            f = f.removesuffix(suffix)
        if f not in names:
            names.append(f)
    return names


def _source(docname: str) -> Path | None:
    for suffix in SOURCE_SUFFIXES:
        if (ROOT / (docname + suffix)).exists():
            return ROOT / (docname + suffix)
    return None


def _shown(cell) -> bool:
    return not REMOVED_TAGS & set(cell.get("metadata", {}).get("tags", []))


class _PageParser(HTMLParser):
    """Collects (tag, attribute, url) links and the element ids of one HTML page."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.links: list[tuple[str, str, str]] = []
        self.ids: set[str] = set()
        self.title = ""
        self._in_h1 = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("id", "name"):
            if a.get(key):
                self.ids.add(a[key])
        if tag == "h1":
            self._in_h1 = True
        if tag == "meta" and (a.get("http-equiv") or "").lower() == "refresh":
            m = re.search(r"url=\s*['\"]?([^'\"]+)", a.get("content") or "", re.IGNORECASE)
            if m:
                self.links.append(("meta", "content", m.group(1).strip()))
        for attr in ("href", "src"):
            if a.get(attr) is not None and tag in {"a", "link", "img", "script", "source", "iframe", "video",
                                                   "audio", "embed"}:
                if tag == "link" and attr == "href" and a.get("rel") in {"canonical", "alternate"}:
                    continue
                self.links.append((tag, attr, a[attr]))

    def handle_endtag(self, tag):
        if tag == "h1":
            self._in_h1 = False

    def handle_data(self, data):
        if self._in_h1:
            self.title += data


def _parse(page: Path) -> _PageParser:
    p = _PageParser()
    p.feed(page.read_text(encoding="utf-8", errors="replace"))
    return p


class Build:
    """Result of one book build: output folder, log, exit status, seconds."""

    def __init__(self, html: Path, log: str, returncode: int, seconds: float):
        self.html, self.log, self.returncode, self.seconds = html, log, returncode, seconds
        self._pages: dict[Path, _PageParser] = {}

    def page(self, path: Path) -> _PageParser:
        if path not in self._pages:
            self._pages[path] = _parse(path)
        return self._pages[path]

    def html_pages(self) -> list[Path]:
        return sorted(p for p in self.html.rglob("*.html")
                      if not {"_static", "_sources"} & set(p.relative_to(self.html).parts))


@pytest.fixture(scope="session")
def html_book(tmp_path_factory) -> Build:
    """Build the book once per session into a temporary folder (skipped without _toc.yml or jupyter-book)."""
    if not TOC.exists():
        pytest.skip("no _toc.yml yet")
    jb = _jupyter_book()
    if jb is None:
        pytest.skip("jupyter-book is not installed (pip install -e '.[book]')")
    tmp = tmp_path_factory.mktemp("book")
    src, out = tmp / "src", tmp / "out"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".*", "_build", "*.egg-info", "__pycache__"))
    env = dict(os.environ, NO_COLOR="1", PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT),
                                                                                  os.environ.get("PYTHONPATH")])))
    t0 = time.perf_counter()
    proc = subprocess.run([jb, "build", str(src), "--path-output", str(out)], capture_output=True, text=True,
                          env=env, timeout=600)
    seconds = time.perf_counter() - t0
    log = ANSI.sub("", proc.stdout + "\n" + proc.stderr)
    (tmp / "build.log").write_text(log)
    return Build(out / "_build" / "html", log.replace(str(src), "<book>"), proc.returncode, seconds)


def test_build_succeeds_without_warnings(html_book):
    book = html_book
    assert book.returncode == 0, f"jupyter-book build failed:\n{book.log[-4000:]}"
    problems = [line for line in book.log.splitlines()
                if re.search(r"\b(WARNING|ERROR|CRITICAL|SEVERE)\b", line)
                and not any(re.search(pat, line) for pat in ALLOWED_WARNINGS)]
    assert not problems, f"{len(problems)} warning(s) in the book build ({book.seconds:.0f} s):\n" + "\n".join(problems)


def test_every_toc_entry_has_a_page(html_book):
    book = html_book
    docs = toc_files()
    assert docs, "_toc.yml lists no files"
    for doc in docs:
        assert _source(doc) is not None, f"_toc.yml lists {doc!r} but no {doc}.ipynb/.md exists"
        page = book.html / f"{doc}.html"
        assert page.exists(), f"no HTML page for {doc} (expected {page.relative_to(book.html)})"
        assert book.page(page).title.strip(" \n#¶"), f"{doc}.html has no <h1> title"
    assert (book.html / "index.html").exists(), "the book has no index.html"


def _check_target(book: Build, page: Path, url: str) -> str | None:
    """None if ``url`` (from ``page``) resolves in the build, else a description of the problem."""
    u = urlparse(url)
    if u.scheme in EXTERNAL_SCHEMES or u.netloc or url.startswith("//"):
        return None
    path = unquote(u.path)
    if path == "":
        target = page
    else:
        target = (book.html / path.lstrip("/")) if path.startswith("/") else (page.parent / path)
        target = Path(os.path.normpath(target))
        if target.is_dir():
            target = target / "index.html"
        if not target.exists():
            return f"missing file {path}"
    if u.fragment and target.suffix == ".html" and book.html in target.parents:
        if unquote(u.fragment) not in book.page(target).ids:
            return f"no element with id #{u.fragment} in {target.relative_to(book.html)}"
    return None


def test_internal_links_and_images_resolve(html_book):
    book = html_book
    problems = []
    pages = book.html_pages()
    assert pages, "the build wrote no HTML pages"
    for page in pages:
        for tag, attr, url in book.page(page).links:
            if url in {"", "#"}:
                continue
            err = _check_target(book, page, url)
            if err:
                problems.append(f"{page.relative_to(book.html)}: <{tag} {attr}={url!r}>: {err}")
    assert not problems, f"{len(problems)} broken link(s):\n" + "\n".join(problems[:50])


def test_toc_files_reads_parts_chapters_sections_and_globs(tmp_path):
    (tmp_path / "book").mkdir()
    for name in ("a.ipynb", "b.md", "c1.ipynb", "c2.ipynb", "c2.py"):
        (tmp_path / "book" / name).write_text("")
    toc = tmp_path / "_toc.yml"
    toc.write_text("format: jb-book\nroot: intro\nparts:\n- caption: P\n  chapters:\n  - file: book/a.ipynb\n"
                   "    sections:\n    - file: book/b\n  - glob: book/c*\n  - url: https://example.org\n")
    assert toc_files(toc) == ["intro", "book/a", "book/b", "book/c1", "book/c2"]


def test_link_checker_reports_broken_links(tmp_path):
    """The checker itself: good links pass, a missing file and a missing #id are reported."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "b.html").write_text('<h1 id="top">B</h1><p id="x">x</p>')
    (tmp_path / "sub" / "a.html").write_text("<h1>A</h1>")
    build = Build(tmp_path, "", 0, 0.0)
    page = tmp_path / "sub" / "a.html"
    assert _check_target(build, page, "../b.html#x") is None
    assert _check_target(build, page, "https://example.org/missing.html") is None
    assert _check_target(build, page, "../c.html") == "missing file ../c.html"
    assert "no element with id #nope" in _check_target(build, page, "../b.html#nope")
    assert "no element with id #y" in _check_target(build, tmp_path / "b.html", "#y")
    assert [u for _, _, u in _parse(tmp_path / "b.html").links] == []
    (tmp_path / "index.html").write_text('<meta http-equiv="Refresh" content="0; url=sub/a.html" />')
    assert _parse(tmp_path / "index.html").links == [("meta", "content", "sub/a.html")]


def test_chapter_pages_show_their_figures(html_book):
    book = html_book
    for doc in toc_files():
        src = _source(doc)
        if src is None or src.suffix != ".ipynb":
            continue
        nb = nbformat.read(src, as_version=4)
        expected = sum(1 for cell in nb.cells if cell.cell_type == "code" and _shown(cell)
                       for out in cell.get("outputs", [])
                       if any(m in out.get("data", {}) for m in IMAGE_MIMES) and WIDGET_MIME not in out.get("data", {}))
        page = book.html / f"{doc}.html"
        imgs = [url for tag, _, url in book.page(page).links if tag == "img"]
        assert len(imgs) >= expected, (
            f"{doc}.html shows {len(imgs)} image(s) but the notebook stores {expected} figure output(s)")
        for url in imgs:
            if urlparse(url).scheme == "data":
                continue
            f = Path(os.path.normpath(page.parent / unquote(urlparse(url).path)))
            assert f.exists() and f.stat().st_size > 100, f"{doc}.html: image {url} is missing or empty"


def test_pages_need_no_network(html_book):
    """Scripts, stylesheets and images all come from the build folder: the book renders offline."""
    book = html_book
    offenders = set()
    for page in book.html_pages():
        for tag, _, url in book.page(page).links:
            remote = urlparse(url).scheme in {"http", "https"} or url.startswith("//")
            if remote and tag in {"script", "link", "img", "iframe", "source", "embed"}:
                offenders.add(f"<{tag}> {url}")
    assert not offenders, "pages load resources from the network:\n" + "\n".join(sorted(offenders))


def test_widget_outputs_are_followed_by_a_static_figure():
    """In the HTML book a widget is dead; the next code cell must draw its figure for static readers."""
    if not TOC.exists():
        pytest.skip("no _toc.yml yet")
    checked = 0
    for doc in toc_files():
        src = _source(doc)
        if src is None or src.suffix != ".ipynb":
            continue
        cells = [c for c in nbformat.read(src, as_version=4).cells if c.cell_type == "code"]
        for i, cell in enumerate(cells):
            if not _shown(cell) or not any(WIDGET_MIME in o.get("data", {}) for o in cell.get("outputs", [])):
                continue
            checked += 1
            nxt = cells[i + 1] if i + 1 < len(cells) else None
            assert nxt is not None and any(m in o.get("data", {}) for o in nxt.get("outputs", [])
                                           for m in IMAGE_MIMES), (
                f"{src.name}: the widget in code cell {i + 1} ({cell.source.splitlines()[0][:60]!r}) is not "
                "followed by a code cell showing a static figure")
    if checked == 0:
        pytest.skip("no widget outputs in the notebooks listed in _toc.yml")


def test_screenshot_of_the_first_page(request, tmp_path_factory):
    """Saves a full-page screenshot of the book's first page as an artifact, to be looked at by eye."""
    chromium = Path(os.environ.get("LOCALIZE_CHROMIUM", "/usr/bin/chromium"))
    if not chromium.exists():
        pytest.skip(f"no Chromium at {chromium} for the screenshot (apt-get install -y chromium)")
    pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
    book = request.getfixturevalue("html_book")
    base = os.environ.get("PYTEST_ARTIFACTS")
    outdir = Path(base) / "html-book" if base else tmp_path_factory.mktemp("html-book-artifacts")
    first = toc_files()[0]
    out = outdir / (first.replace("/", "_") + ".png")
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "browser_screenshot.py"),
                           str(book.html / f"{first}.html"), str(out), "--full-page"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert out.exists() and out.stat().st_size > 10_000, f"screenshot {out} is missing or nearly empty"
    tr = request.config.pluginmanager.get_plugin("terminalreporter")
    if tr is not None:
        tr.write_line(f"\nHTML book: built in {book.seconds:.1f} s; screenshot of {first}: {out}")


def test_solutions_collapsed_in_html_book(html_book):
    """Written-out solutions are closed <details> blocks with rendered math; code solutions sit behind a toggle."""
    book = html_book
    for doc in toc_files():
        src = _source(doc)
        if src is None or src.suffix != ".ipynb":
            continue
        nb = nbformat.read(src, as_version=4)
        sol = [c for c in nb.cells if "solution" in c.metadata.get("tags", [])]
        n_md = sum(c.cell_type == "markdown" for c in sol)
        n_code = sum(c.cell_type == "code" for c in sol)
        text = (book.html / f"{doc}.html").read_text(encoding="utf-8")
        assert "{admonition}" not in text and ":class: dropdown" not in text, f"{doc}: raw MyST markup in the page"
        blocks = re.findall(r"<details>(.*?)</details>", text, re.S)
        assert len(blocks) >= n_md, f"{doc}: {n_md} written solutions but {len(blocks)} <details> blocks"
        for b in blocks:
            assert "<summary>" in b and "Solution" in b, f"{doc}: a <details> block without its summary"
            assert "$" not in re.sub(r"<[^>]+>", "", b), f"{doc}: unrendered $math$ inside a solution"
        assert text.count("tag_hide-cell") >= n_code, f"{doc}: a code solution is not behind a toggle"
