"""The book's widgets work the way a reader uses them: JupyterLab in a real Chromium.

One JupyterLab server and one Chromium page for the whole module. What it does:

1. Copies the book as a reader's clone has it (notebooks with their stored outputs, their
   jupytext twins, the homework) and the book's ``jupyter_server_config.py`` and
   ``jupyter_kernel_startup.py`` into a temporary root, and starts JupyterLab on it with the
   README's ``--config`` (127.0.0.1, a random port and token, private Jupyter/IPython config,
   data, runtime and settings folders).
2. For every chapter that builds a widget (a widget builder called alone on a line of
   ``book/src/NN_name.py``, the same rule as ``tests/test_widgets_display.py``): opens it, clears
   all outputs, runs the cells up to its last widget (Run All Above, then that cell; chapters in
   ``FULL_RUN``: Run > Run All Cells) and waits until every one of them has an execution count
   and nothing was written to stderr.
3. For EVERY widget of the chapter: moves one control (a slider one step with the keyboard, or
   another toggle button; ``CONTROLS`` names the control where the first slider is not the
   right one), asserts that the PNG of the figure in the widget's cell changed while the figures
   of every other widget stayed byte-identical (no shared state), moves it back and asserts the
   figure returns to the byte-identical PNG. Figures are matplotlib output in an Output widget
   (a ``data:`` URL) or an ``ipywidgets.Image`` (a ``blob:`` URL, read back with ``fetch``).
4. In the ``FULL_RUN`` chapters, checks that no solution's answer shows after Run All: the
   output of every cell tagged ``solution`` is one closed "Output of the solution" disclosure.
5. Tries to save (the chapters are read-only: Ctrl+S must not write), and at the end asserts
   that no file of the copied clone changed, byte for byte: a reader's run leaves ``git
   status`` clean.
6. Saves screenshots (per widget before/after, the page after Run All) and the server log under
   ``$PYTEST_ARTIFACTS/browser`` or a temporary folder whose path is printed; ``timings.txt``
   ``timings-test_browser.txt`` there has the time of every phase.

A self-test notebook with a negative control (a slider its figure ignores must fail the
check) runs with ``LOCALIZE_BROWSER_ALL=1``. Skipped, with the reason, when ``playwright``,
``jupyterlab`` or Chromium (``/usr/bin/chromium`` or ``$LOCALIZE_CHROMIUM``) is missing. Install
with ``apt-get install -y chromium`` and ``pip install playwright``; do not run ``playwright
install``. Facts this relies on (selectors, pitfalls, timings) were measured on this machine
kind; see the project notes on widgets in the browser. Marked ``browser``: deselect with
``-m "not browser"``. ``LOCALIZE_BROWSER_CHAPTERS=03,07`` limits the run to those chapters.
"""

from __future__ import annotations

import base64
import hashlib
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import nbformat
import pytest

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[1]
BOOK = ROOT / "book"
CHROMIUM = Path(os.environ.get("LOCALIZE_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-quic", "--disable-sync"]

# Widget cells: a builder of localize.widgets called alone at the start of a line of a chapter's source.
_BUILDER_CALL = re.compile(r"^(\w+(?:_widget|_app|_player)|robot_on_map)\(", re.M)
# The control moved per builder: ("slider", label), ("toggle", None) or ("button", (forward, back) labels);
# default: the cell's first slider.
CONTROLS = {
    "mcl_player": ("slider", "step"),                 # the step slider only redraws (its run is cached)
    "grid_resolution_widget": ("toggle", None),       # only toggle buttons
    "tile_world_app": ("button", ("next cycle", "reset")),   # before the first reading no slider matters
    "kidnap_widget": ("slider", "alpha_fast"),
}
# Chapters run with Run All, whose solutions are then checked (chapter 3: the answer the issue saw leak;
# chapter 7: a solution with progress bars). The others run up to their last widget cell (Run > Run All
# Above Selected Cell, then that cell), which saves about 40 % of the time.
FULL_RUN = {"03", "07"}
ONLY = [c.strip() for c in os.environ.get("LOCALIZE_BROWSER_CHAPTERS", "").split(",") if c.strip()]


def widget_chapters() -> list[tuple[str, list[str]]]:
    """(notebook name, builders of its widget cells in order) for every chapter with a widget."""
    out = []
    for src in sorted((BOOK / "src").glob("[0-9][0-9]_*.py")):
        builders = _BUILDER_CALL.findall(src.read_text())
        if builders and (not ONLY or src.stem[:2] in ONLY):
            out.append((src.stem + ".ipynb", builders))
    return out


RUN_ALL_TARGETS = bool(os.environ.get("LOCALIZE_BROWSER_ALL"))
SELFTEST = "selftest.ipynb"  # written by the fixture; see _selftest_notebook()

KERNEL_TIMEOUT_MS = 60_000
RUN_ALL_TIMEOUT_MS = 120_000
REDRAW_TIMEOUT_MS = 15_000

playwright_sync = pytest.importorskip(
    "playwright.sync_api", reason="the playwright package is not installed (pip install playwright)")
pytest.importorskip("jupyterlab", reason="jupyterlab is not installed (pip install -e '.[book]')")


TIMINGS: list[tuple[str, float]] = []  # (phase, seconds), written to timings.txt for the report


class _phase:
    """Context manager recording how long a phase of the test took."""

    def __init__(self, name: str):
        self.name = name

    def __enter__(self):
        self.t0 = time.perf_counter()

    def __exit__(self, *exc):
        TIMINGS.append((self.name, time.perf_counter() - self.t0))


class FigureDidNotChange(AssertionError):
    """Moving a slider did not change its figure within the timeout."""


# ---------------------------------------------------------------- fixtures


def _report(request, line: str) -> None:
    """Print a line to the terminal even when output is captured."""
    tr = request.config.pluginmanager.get_plugin("terminalreporter")
    if tr is not None:
        tr.write_line(line)


@pytest.fixture(scope="module")
def artifacts(request, tmp_path_factory) -> Path:
    base = os.environ.get("PYTEST_ARTIFACTS")
    path = Path(base) / "browser" if base else tmp_path_factory.mktemp("browser-artifacts")
    path.mkdir(parents=True, exist_ok=True)
    _report(request, f"\nbrowser test artifacts (screenshots, server log, timings): {path}")
    TIMINGS.clear()
    yield path
    name = request.module.__name__.rsplit(".", 1)[-1]
    (path / f"timings-{name}.txt").write_text("".join(f"{s:7.2f} s  {name}\n" for name, s in TIMINGS)
                                               + f"{sum(s for _, s in TIMINGS):7.2f} s  total of the phases\n")


def _selftest_notebook() -> nbformat.NotebookNode:
    """Two interact widgets: ``freq`` redraws its figure, ``ignored`` is a slider its figure ignores."""
    nb = nbformat.v4.new_notebook()
    nb.cells = [
        nbformat.v4.new_code_cell("import matplotlib.pyplot as plt\nimport numpy as np\n"
                                  "from ipywidgets import interact"),
        nbformat.v4.new_code_cell(
            "def wave(freq=1):\n"
            "    fig, ax = plt.subplots(figsize=(4, 3))\n"
            "    t = np.linspace(0, 1, 200)\n"
            "    ax.plot(t, np.sin(2 * np.pi * freq * t))\n"
            "    plt.show()\n\n"
            "interact(wave, freq=(1, 10));"),
        nbformat.v4.new_code_cell(
            "def constant(ignored=1):\n"
            "    fig, ax = plt.subplots(figsize=(4, 3))\n"
            "    ax.plot([0, 1], [0, 1])\n"
            "    plt.show()\n\n"
            "interact(constant, ignored=(1, 10));"),
    ]
    nb.metadata["kernelspec"] = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    return nb


SERVER_CONFIG = "jupyter_server_config.py"      # the README's book command loads it with --config
SNAPSHOT: dict[str, str] = {}                    # sha256 of every file of the copied book, before any test


def _digests(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder`` that git would see (not checkpoints or language-server files)."""
    out = {}
    for f in sorted(folder.rglob("*")):
        rel = f.relative_to(folder).as_posix()
        if f.is_file() and not any(part in (".ipynb_checkpoints", ".virtual_documents", "__pycache__")
                                   for part in f.relative_to(folder).parts):
            out[rel] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _request(url: str, method: str = "GET", token: str | None = None, timeout: float = 5.0) -> int:
    req = urllib.request.Request(url, method=method, data=b"" if method != "GET" else None)
    if token:
        req.add_header("Authorization", f"token {token}")
    with urllib.request.urlopen(req, timeout=timeout) as r:
        return r.status


def _pids_referring_to(path: Path) -> list[int]:
    """PIDs whose command line mentions ``path`` (our server's kernels, via their connection files)."""
    key = (str(path).rstrip("/") + "/").encode()
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit() and int(d.name) != os.getpid():
            try:
                if key in (d / "cmdline").read_bytes():
                    pids.append(int(d.name))
            except OSError:
                pass
    return pids


@pytest.fixture(scope="module")
def lab(tmp_path_factory, artifacts):
    """A JupyterLab server over a temporary copy of the book. Yields (base_url, token, root)."""
    if not CHROMIUM.exists():
        pytest.skip(f"Chromium not found at {CHROMIUM}: install it with `apt-get install -y chromium` "
                    "or set LOCALIZE_CHROMIUM")
    tmp = tmp_path_factory.mktemp("lab")
    root, home = tmp / "root", tmp / "home"
    root.mkdir()
    # the clone as a reader has it: notebooks with outputs, their twins, the server config of the README
    if BOOK.is_dir():
        shutil.copytree(BOOK, root / "book", ignore=shutil.ignore_patterns("_build", ".ipynb_checkpoints"))
    for name in (SERVER_CONFIG, "jupyter_kernel_startup.py"):
        shutil.copy2(ROOT / name, root / name)
    nbformat.write(_selftest_notebook(), root / SELFTEST)
    SNAPSHOT.clear()
    SNAPSHOT.update(_digests(root / "book"))

    env = dict(os.environ)
    for var, sub in [("JUPYTER_CONFIG_DIR", "config"), ("JUPYTER_DATA_DIR", "data"),
                     ("JUPYTER_RUNTIME_DIR", "runtime"), ("JUPYTERLAB_SETTINGS_DIR", "settings"),
                     ("JUPYTERLAB_WORKSPACES_DIR", "workspaces"), ("IPYTHONDIR", "ipython")]:
        (home / sub).mkdir(parents=True)
        env[var] = str(home / sub)
    # No "get notified about Jupyter news?" toast; render every cell (no virtual scrolling).
    settings = home / "settings" / "@jupyterlab"
    (settings / "apputils-extension").mkdir(parents=True)
    (settings / "apputils-extension" / "notification.jupyterlab-settings").write_text(
        '{"fetchNews": "false", "checkForUpdates": false}')
    (settings / "notebook-extension").mkdir(parents=True)
    (settings / "notebook-extension" / "tracker.jupyterlab-settings").write_text('{"windowingMode": "none"}')
    # The kernel imports this checkout's localize and finds the real data like the tests do.
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    if "LOCALIZE_DATA" not in env and (ROOT.parent / "shared" / "data").is_dir():
        env["LOCALIZE_DATA"] = str(ROOT.parent / "shared" / "data")
    env["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"

    port, token = _free_port(), secrets.token_hex(16)
    base = f"http://127.0.0.1:{port}"
    log = open(artifacts / "jupyterlab.log", "w")  # noqa: SIM115 - closed in teardown
    proc = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", f"--config={root / SERVER_CONFIG}", "--no-browser", "--allow-root",
         "--ServerApp.ip=127.0.0.1",
         f"--ServerApp.port={port}", "--ServerApp.port_retries=0", f"--IdentityProvider.token={token}",
         f"--ServerApp.root_dir={root}", "--LabApp.news_url=None",
         "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
         "--LabApp.extension_manager=readonly", "--LabApp.expose_app_in_browser=True"],
        env=env, stdout=log, stderr=subprocess.STDOUT, cwd=root)
    t_start = time.perf_counter()
    try:
        deadline = time.monotonic() + 60
        while True:
            if proc.poll() is not None:
                log.flush()
                pytest.fail(f"JupyterLab exited with {proc.returncode}:\n"
                            + (artifacts / "jupyterlab.log").read_text()[-3000:])
            try:
                if _request(f"{base}/api/status?token={token}") == 200:
                    break
            except (urllib.error.URLError, ConnectionError, TimeoutError):
                pass
            if time.monotonic() > deadline:
                pytest.fail("JupyterLab did not answer /api/status within 60 s; see jupyterlab.log")
            time.sleep(0.25)
        TIMINGS.append(("server: start until /api/status answers", time.perf_counter() - t_start))
        yield base, token, root
    finally:
        t_stop = time.perf_counter()
        try:
            _request(f"{base}/api/shutdown", "POST", token)
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            pass
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for pid in _pids_referring_to(tmp):  # orphaned kernels: only processes using our tmp dir
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        log.close()
        TIMINGS.append(("server: shutdown and cleanup", time.perf_counter() - t_stop))


@pytest.fixture(scope="module")
def lab_page(lab, artifacts):
    """One Chromium page with JupyterLab loaded once; each test opens its notebook in it."""
    base, token, _ = lab
    with playwright_sync.sync_playwright() as pw:
        with _phase("browser: launch"):
            b = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            page = b.new_page(viewport={"width": 1280, "height": 1000})
            page.set_default_timeout(30_000)
            with _phase("JupyterLab: load the application"):
                page.goto(f"{base}/lab?token={token}&reset", wait_until="domcontentloaded")
                page.wait_for_function("() => window.jupyterapp && window.jupyterapp.shell", timeout=60_000)
                page.wait_for_selector(".jp-LabShell .lm-MenuBar-itemLabel", timeout=60_000)
            yield page
        finally:
            b.close()


@pytest.fixture
def page(lab_page, lab, artifacts, request):
    """The JupyterLab page; afterwards a screenshot, then notebook saved and closed, kernels shut down."""
    try:
        yield lab_page
    finally:
        name = request.node.name.replace("/", "_")
        try:
            lab_page.screenshot(path=artifacts / f"{name}-final.png")
            close_all(lab_page)
        except playwright_sync.Error:
            pass
        try:
            _close_sessions(lab[0], lab[1])
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            pass


# ---------------------------------------------------------------- page helpers

# The status bar's kernel item, e.g. "Python 3 (ipykernel) | Idle". (The toolbar's execution
# indicator says "idle" before any kernel exists, so it is not used.)
_JS_KERNEL_IDLE = """() => [...document.querySelectorAll('.jp-StatusBar-TextItem')]
    .some(e => /^Python.*\\|\\s*Idle\\s*$/.test(e.textContent.trim()))"""

# The notebook panel in front, and its cells by index (windowingMode "none": every cell is in the DOM).
_JS_CELLS = "[...document.querySelectorAll('.jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook .jp-Cell')]"

# Run All finished: kernel idle, nothing queued, and every code cell up to `upto` numbered or an error was shown.
_JS_RUN_ALL_FINISHED = """(upto) => {
    const idle = [...document.querySelectorAll('.jp-StatusBar-TextItem')]
        .some(e => /^Python.*\\|\\s*Idle\\s*$/.test(e.textContent.trim()));
    const prompts = [...document.querySelectorAll('.jp-Notebook .jp-CodeCell .jp-InputPrompt')]
        .map(e => e.textContent.trim());
    // every code cell has run: read from the notebook model, because a cell whose source is
    // collapsed (the hidden solutions) shows no prompt
    const nb = window.jupyterapp && window.jupyterapp.shell.currentWidget;
    const cells = nb && nb.content && nb.content.model ? nb.content.model.cells : null;
    let done = cells !== null && cells.length > 0;
    for (let i = 0; cells !== null && i < Math.min(cells.length, upto + 1); i++) {
        const c = cells.get(i);
        if (c.type === 'code' && c.sharedModel.getSource().trim()
            && (c.executionCount === null || c.executionCount === undefined)) done = false;
    }
    const err = document.querySelector(".jp-Notebook [data-mime-type='application/vnd.jupyter.stderr']");
    return idle && !prompts.includes('[*]:') && (done || err !== null);
}"""

# Widget figures: matplotlib output shown in an Output widget as a data: URL, or an
# ipywidgets.Image, shown from a blob: URL.
_FIGURES = ".widget-output img, img.widget-image"

# Every widget figure of the notebook: its source, and whether it sits in cell `idx`.
_JS_SOURCES = """(idx) => {
    const cell = %s[idx];
    const nb = document.querySelector('.jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook');
    return [...nb.querySelectorAll('%s')]
        .filter(i => /^(data:image\\/png|blob:)/.test(i.src))
        .map(i => ({own: cell.contains(i), src: i.src}));
}""" % (_JS_CELLS, _FIGURES)

# The same with the image bytes as a data: URL (blob: images are fetched and encoded).
_JS_FIGURES = """async (idx) => {
    const cell = %s[idx];
    const nb = document.querySelector('.jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook');
    const imgs = [...nb.querySelectorAll('%s')].filter(i => /^(data:image\\/png|blob:)/.test(i.src));
    const out = [];
    for (const i of imgs) {
        let data = i.src;
        if (data.startsWith('blob:')) {
            const b = new Uint8Array(await (await fetch(i.src)).arrayBuffer());
            let s = '';
            for (let k = 0; k < b.length; k += 0x8000) s += String.fromCharCode.apply(null, b.subarray(k, k + 0x8000));
            data = 'data:image/png;base64,' + btoa(s);
        }
        out.push({own: cell.contains(i), src: data});
    }
    return out;
}""" % (_JS_CELLS, _FIGURES)

_JS_OWN_FIGURE_NOT = """([idx, old]) => {
    const imgs = [...%s[idx].querySelectorAll('%s')].filter(i => /^(data:image\\/png|blob:)/.test(i.src));
    return imgs.length > 0 && imgs.map(i => i.src).join('|') !== old;
}""" % (_JS_CELLS, _FIGURES)

# What a reader sees of each solution cell's output after Run All.
_JS_SOLUTION_OUTPUTS = """(indices) => indices.map(idx => {
    const cell = %s[idx];
    const area = cell.querySelector('.jp-OutputArea');
    const details = area ? [...area.querySelectorAll('details')] : [];
    const shown = area ? [...area.querySelectorAll('.jp-OutputArea-output')]
        .filter(o => !o.querySelector('details')).map(o => o.innerText.trim()).filter(t => t) : [];
    const hiddenArea = cell.querySelector('.jp-OutputPlaceholder') !== null;
    return {idx, details: details.length, open: details.some(d => d.open), shown, hiddenArea,
            summary: details.map(d => (d.querySelector('summary') || {innerText: ''}).innerText)};
})""" % _JS_CELLS


def _png(src: str) -> bytes:
    assert src.startswith("data:image/png;base64,"), src[:40]
    data = base64.b64decode(src.split(",", 1)[1])
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "widget figure is not a PNG"
    return data


def _figures(page, idx: int) -> tuple[list[bytes], list[bytes]]:
    """(figures of cell idx, other widgets' figures) as PNG bytes, in page order."""
    try:
        figs = page.evaluate(_JS_FIGURES, idx)
    except playwright_sync.Error:  # a blob: image was replaced while being read: settle and retry once
        _settle(page, idx)
        figs = page.evaluate(_JS_FIGURES, idx)
    return [_png(f["src"]) for f in figs if f["own"]], [_png(f["src"]) for f in figs if not f["own"]]


def _settle(page, idx: int) -> None:
    """Wait until the kernel is idle and the figures are unchanged over two polls 0.3 s apart."""
    last = None
    for _ in range(80):
        page.wait_for_function(_JS_KERNEL_IDLE, timeout=REDRAW_TIMEOUT_MS)
        now = page.evaluate(_JS_SOURCES, idx)
        if now == last:
            return
        last = now
        page.wait_for_timeout(300)
    raise AssertionError("the widget figures kept changing for 24 s")


def close_all(page) -> None:
    """Close every document without saving (a run chapter is dirty; chapters are read-only anyway)."""
    page.evaluate("""async () => {
        const app = window.jupyterapp;
        for (const w of [...app.shell.widgets('main')]) {
            if (w.context && w.context.model) w.context.model.dirty = false;
        }
        await app.commands.execute('application:close-all');
    }""")
    for button in page.locator(".jp-Dialog .jp-mod-reject").all():   # a dialog left open: dismiss it
        button.click()


def open_and_run_all(page, rel: str, upto: int | None = None) -> None:
    """Open ``rel`` (relative to the server root), clear its outputs, run all cells (or cells 0..upto); fail on errors."""
    with _phase(f"{rel}: open the notebook"):
        page.evaluate("async (path) => { await window.jupyterapp.commands.execute('docmanager:open', {path}); }",
                      rel)
        page.wait_for_selector(".jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook .jp-Cell",
                               timeout=KERNEL_TIMEOUT_MS)
    with _phase(f"{rel}: kernel start until idle"):
        page.wait_for_function(_JS_KERNEL_IDLE, timeout=KERNEL_TIMEOUT_MS)
    with _phase(f"{rel}: clear outputs, Run All" + ("" if upto is None else f" up to cell {upto}")):
        page.evaluate("async () => { await window.jupyterapp.commands.execute('notebook:clear-all-cell-outputs'); }")
        if upto is None:
            page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
            page.locator("li.lm-Menu-item[data-command='runmenu:run-all']").click()
        else:          # Run All Above the cell after `upto`, as a reader who stops at the widget would
            page.evaluate("""async (k) => { const app = window.jupyterapp;
                app.shell.currentWidget.content.activeCellIndex = k;
                await app.commands.execute('notebook:run-all-above'); }""", upto + 1)
        page.wait_for_function(_JS_RUN_ALL_FINISHED, arg=10**9 if upto is None else upto,
                               timeout=RUN_ALL_TIMEOUT_MS, polling=250)
    stderr = page.locator(".jp-Notebook [data-mime-type='application/vnd.jupyter.stderr']").all_inner_texts()
    assert not stderr, f"{rel}: cells wrote to stderr (error or warning):\n" + "\n---\n".join(stderr)[:4000]


def _cell(page, idx: int):
    return page.locator(".jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook .jp-Cell").nth(idx)


def _sliders(page, idx: int):
    return _cell(page, idx).locator(".widget-slider")


def _slider(page, idx: int, label: str | None):
    """The slider labelled ``label`` in cell ``idx`` (None: the first one)."""
    sliders = _sliders(page, idx)
    labels = [t.strip() for t in sliders.evaluate_all(
        "els => els.map(e => (e.querySelector('label.widget-label') || {}).textContent || '')")]
    assert labels, f"cell {idx} shows no slider"
    if label is None:
        return sliders.nth(0), labels[0]
    assert label in labels, f"no slider labelled {label!r} in cell {idx}; sliders found: {labels}"
    return sliders.nth(labels.index(label)), label


def _slider_value(slider) -> str:
    """The value a slider shows: its readout, else aria-valuetext (aria-valuenow is rounded)."""
    return slider.evaluate("""s => {
        const r = s.querySelector('.widget-readout');
        const h = s.querySelector('.noUi-handle');
        return (r && r.textContent.trim()) || h.getAttribute('aria-valuetext') || h.getAttribute('aria-valuenow');
    }""")


def _wait_for_new_figure(page, idx: int, old: str, what: str, timeout: float = REDRAW_TIMEOUT_MS) -> None:
    try:
        page.wait_for_function(_JS_OWN_FIGURE_NOT, arg=[idx, old], timeout=timeout, polling=100)
    except playwright_sync.TimeoutError as exc:
        raise FigureDidNotChange(f"{what} did not change the figure within {timeout / 1000:.0f} s") from exc
    _settle(page, idx)


def _own_sources(page, idx: int) -> str:
    return "|".join(f["src"] for f in page.evaluate(_JS_SOURCES, idx) if f["own"])


def press_slider(page, idx: int, slider, key: str, timeout: float = REDRAW_TIMEOUT_MS) -> tuple[str, str]:
    """Press ``key`` on a slider's handle (what a reader's keyboard does); wait for cell idx's figure to redraw."""
    handle = slider.locator(".noUi-handle").first
    before, old = _slider_value(slider), _own_sources(page, idx)
    handle.focus()
    page.keyboard.press(key)
    after = _slider_value(slider)
    assert after != before, f"pressing {key} did not move the slider (value {before})"
    _wait_for_new_figure(page, idx, old, f"moving the slider {before} -> {after}", timeout)
    return before, after


def click_toggle(page, idx: int, button) -> None:
    old = _own_sources(page, idx)
    button.click()
    _wait_for_new_figure(page, idx, old, f"clicking {button.inner_text()!r}")


def check_widget(page, idx: int, control: tuple[str, str | None], shots: Path) -> str:
    """Move one control of the widget in cell ``idx`` and back: its figure changes then returns; others never change.

    Returns a description of the control moved.
    """
    cell = _cell(page, idx)
    cell.scroll_into_view_if_needed()
    _settle(page, idx)
    own0, others0 = _figures(page, idx)
    assert own0, f"the widget in cell {idx} shows no figure after Run All"
    cell.screenshot(path=shots / f"cell{idx:03d}-before.png")
    kind, label = control
    if kind == "toggle":
        buttons = cell.locator(".widget-toggle-button")
        active = [k for k in range(buttons.count()) if "mod-active" in (buttons.nth(k).get_attribute("class") or "")]
        assert active and buttons.count() > 1, f"cell {idx}: no toggle buttons to switch"
        other = next(k for k in range(buttons.count()) if k not in active)
        desc = f"toggle {buttons.nth(active[0]).inner_text()!r} -> {buttons.nth(other).inner_text()!r}"
        with _phase(f"cell {idx}: {desc}, redraw, settle"):
            click_toggle(page, idx, buttons.nth(other))
        forward = lambda: None  # noqa: E731 - already done
        back = lambda: click_toggle(page, idx, buttons.nth(active[0]))  # noqa: E731
    elif kind == "button":
        fwd_label, back_label = label
        desc = f"button {fwd_label!r}, then {back_label!r}"
        with _phase(f"cell {idx}: {desc}, redraw, settle"):
            click_toggle(page, idx, cell.locator(".widget-button", has_text=fwd_label).first)
        forward = lambda: None  # noqa: E731
        back = lambda: click_toggle(page, idx, cell.locator(".widget-button", has_text=back_label).first)  # noqa: E731
    else:
        slider, name = _slider(page, idx, label)
        handle = slider.locator(".noUi-handle").first
        at_end = handle.get_attribute("aria-valuenow") == handle.get_attribute("aria-valuemax")
        fwd, bwd = ("ArrowLeft", "ArrowRight") if at_end else ("ArrowRight", "ArrowLeft")
        with _phase(f"cell {idx}: slider {name!r} one step, redraw, settle"):
            old, new = press_slider(page, idx, slider, fwd)
        desc = f"slider {name!r} {old} -> {new}"
        forward = lambda: None  # noqa: E731
        back = lambda: press_slider(page, idx, slider, bwd)  # noqa: E731
    forward()
    own1, others1 = _figures(page, idx)
    cell.screenshot(path=shots / f"cell{idx:03d}-after.png")
    assert own1 != own0, f"cell {idx}: {desc}: the figure's PNG did not change"
    assert others1 == others0, f"cell {idx}: {desc} changed another widget's figure (shared state?)"
    back()
    own2, others2 = _figures(page, idx)
    assert own2 == own0, f"cell {idx}: {desc} and back did not give back the byte-identical figure"
    assert others2 == others0, f"cell {idx}: {desc} changed another widget's figure (shared state?)"
    return desc


def _close_sessions(base: str, token: str) -> None:
    """Shut down every kernel of the server (one notebook at a time keeps memory low)."""
    import json

    req = urllib.request.Request(f"{base}/api/sessions", headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(req, timeout=5) as r:
        sessions = json.load(r)
    for s in sessions:
        _request(f"{base}/api/sessions/{s['id']}", "DELETE", token)


def widget_cells(notebook: Path, builders: list[str]) -> list[tuple[int, str]]:
    """(cell index, builder) of the cells that build a widget, in order."""
    nb = nbformat.read(notebook, as_version=4)
    out = []
    for k, cell in enumerate(nb.cells):
        if cell.cell_type == "code":
            out += [(k, b) for b in _BUILDER_CALL.findall(cell.source)]
    assert [b for _, b in out] == builders, f"{notebook.name}: widget cells {out} do not match its source {builders}"
    return out


def solution_cells(notebook: Path) -> list[int]:
    nb = nbformat.read(notebook, as_version=4)
    return [k for k, c in enumerate(nb.cells) if c.cell_type == "code" and "solution" in c.metadata.get("tags", [])]


# ---------------------------------------------------------------- tests


@pytest.mark.skipif(not RUN_ALL_TARGETS,
                    reason="the chapters cover the harness; LOCALIZE_BROWSER_ALL=1 adds this self-test "
                           "and its negative control")
def test_selftest_notebook_slider_redraws_only_its_own_figure(page, artifacts):
    """The harness on a notebook it wrote: a real redraw passes, a slider that changes nothing fails."""
    shots = artifacts / "selftest"
    shots.mkdir(exist_ok=True)
    open_and_run_all(page, SELFTEST)
    check_widget(page, 1, ("slider", "freq"), shots)
    # Negative control: the test must be able to fail.
    slider, _ = _slider(page, 2, "ignored")
    with pytest.raises(FigureDidNotChange):
        press_slider(page, 2, slider, "ArrowRight", timeout=1_500)


@pytest.mark.parametrize("notebook,builders", [
    pytest.param(nb, builders, id=nb[:2]) for nb, builders in widget_chapters()])
def test_every_widget_of_the_chapter_redraws_and_no_answer_shows(page, lab, artifacts, notebook, builders):
    shots = artifacts / notebook.removesuffix(".ipynb")
    shots.mkdir(exist_ok=True)
    cells = widget_cells(BOOK / notebook, builders)
    n_cells = len(nbformat.read(BOOK / notebook, as_version=4).cells)
    full = notebook[:2] in FULL_RUN or cells[-1][0] == n_cells - 1
    open_and_run_all(page, f"book/{notebook}", upto=None if full else cells[-1][0])
    page.screenshot(path=shots / "page-after-run-all.png", full_page=False)
    moved = []
    for idx, builder in cells:
        moved.append(f"{builder}: " + check_widget(page, idx, CONTROLS.get(builder, ("slider", None)), shots))
    (shots / "controls-moved.txt").write_text("\n".join(moved) + "\n")
    # Run All showed no answer: every solution's output is one closed disclosure, or hidden
    sols = solution_cells(BOOK / notebook) if full else []
    seen = page.evaluate(_JS_SOLUTION_OUTPUTS, sols)
    for s in seen:
        assert not s["open"] and not s["shown"], f"{notebook}: solution cell {s['idx']} shows its answer: {s}"
        assert s["details"] <= 1 and all("Output of the solution" in t for t in s["summary"]), s
    if seen:
        _cell(page, sols[0]).scroll_into_view_if_needed()
        page.screenshot(path=shots / "first-solution-after-run-all.png")
    # Ctrl+S on a run chapter: read-only, nothing is written (checked byte for byte at the end)
    _cell(page, 0).click()
    page.keyboard.press("Escape")
    page.keyboard.press("Control+s")
    page.get_by_text("is read-only").first.wait_for(timeout=10_000)


def test_the_readers_clone_is_unchanged(lab):
    """After every chapter above was run, its widgets moved and a save tried: no file of the book changed."""
    assert SNAPSHOT, "the lab fixture took no snapshot"
    now = _digests(lab[2] / "book")
    changed = sorted(k for k in set(now) | set(SNAPSHOT) if now.get(k) != SNAPSHOT.get(k))
    assert not changed, f"files changed, added or removed by reading the book: {changed}"
