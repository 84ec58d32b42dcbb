"""The book's sliders work the way a reader uses them: JupyterLab in a real Chromium.

What the test does, per notebook in ``TARGETS`` (and a tiny notebook it writes
itself, with a negative control proving that the check can fail; it runs when
the preface is missing or with ``LOCALIZE_BROWSER_ALL=1``):

1. Copies the book into a temporary root with outputs stripped from the
   notebooks under test (the source files are never opened, so JupyterLab's
   autosave cannot touch them; stripped prompts make "all cells ran" visible).
2. Starts JupyterLab on 127.0.0.1 with a random port and token and private
   Jupyter/IPython config, data, runtime and settings folders.
3. Opens the notebook in Debian's ``/usr/bin/chromium`` driven by the
   ``playwright`` Python package (Playwright's own browser download is not
   used), waits for the kernel, clicks Run > Run All Cells and waits until
   every code cell has an execution count and nothing was written to stderr.
4. Finds the slider by its description label, presses ArrowRight (or
   ArrowLeft at the end of the range) on its focused handle, checks that the
   value shown in its readout changed, and asserts that the PNG of the
   figure in the slider's cell changed while the figures of every other
   widget in the notebook stayed byte-identical (no shared state between
   widgets). Then it moves the slider back and asserts the figure returns to
   byte-identical PNG (matplotlib PNGs carry no timestamp). Widget figures
   are matplotlib output in an Output widget (``interact``,
   ``interactive_output``; a ``data:`` URL) or an ``ipywidgets.Image``
   (a ``blob:`` URL, read back with ``fetch``).
5. Saves screenshots (whole page and the widget cell before/after) and the
   server log under ``$PYTEST_ARTIFACTS/browser`` or a temporary folder whose
   path is printed at the start of the run.
6. Shuts down kernels and the server over the REST API (SIGTERM/SIGKILL as a
   fallback) and kills any leftover process still referring to the temporary
   root.

Skipped, with the reason, when ``playwright``, ``jupyterlab`` or Chromium
(``/usr/bin/chromium`` or ``$LOCALIZE_CHROMIUM``) is missing. Install with
``apt-get install -y chromium`` and ``pip install playwright``; do not run
``playwright install``. Facts this relies on (selectors, pitfalls, timings)
were measured on this machine kind; see the project notes on widgets in the
browser. Marked ``browser``: deselect with ``-m "not browser"``.

Time on this 2-core machine while other jobs kept it fully loaded: about
60-80 s for the preface and the motion chapter (server 8 s, JupyterLab 5 s,
per notebook kernel 2 s, Run All 5-18 s, slider 1 s); ``timings.txt`` in
the artifacts folder has the breakdown of each run.

Adding a chapter: append ``(notebook, slider label)`` to ``TARGETS`` (run by
default) or ``EXTRA_TARGETS`` (run with ``LOCALIZE_BROWSER_ALL=1``). Targets
whose notebook does not exist yet are skipped.
"""

from __future__ import annotations

import base64
import os
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

# (notebook path relative to book/, description label of the slider to move).
# The slider's figure must change; all other widgets' figures must not.
# Each notebook costs a kernel start and a Run All (5-15 s on 2 cores), so the
# default run covers the preface and one model chapter; LOCALIZE_BROWSER_ALL=1
# adds EXTRA_TARGETS.
TARGETS = [
    ("00_preface.ipynb", "heading [°]"),
    ("04_motion_models.ipynb", "alpha1"),  # the odometry widget's; the velocity widget also has one
]
EXTRA_TARGETS = [
    ("01_bayes_filter.ipynb", "motion noise"),
]
RUN_ALL_TARGETS = bool(os.environ.get("LOCALIZE_BROWSER_ALL"))
if RUN_ALL_TARGETS:
    TARGETS += EXTRA_TARGETS
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
    (path / "timings.txt").write_text("".join(f"{s:7.2f} s  {name}\n" for name, s in TIMINGS))


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


def _stripped_copy(src: Path, dst: Path) -> None:
    """Copy a notebook without outputs, widget state or jupytext pairing (so the .ipynb is what runs)."""
    nb = nbformat.read(src, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = []
            cell.execution_count = None
    nb.metadata.pop("widgets", None)
    nb.metadata.pop("jupytext", None)
    nbformat.write(nb, dst)
    dst.with_suffix(".py").unlink(missing_ok=True)
    (dst.parent / "src" / (dst.stem + ".py")).unlink(missing_ok=True)   # the jupytext twin (book/src/)


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
    if BOOK.is_dir():
        shutil.copytree(BOOK, root / "book", ignore=shutil.ignore_patterns("_build", ".ipynb_checkpoints"))
    for nb_name, _ in TARGETS:
        if (BOOK / nb_name).exists():
            _stripped_copy(BOOK / nb_name, root / "book" / nb_name)
    nbformat.write(_selftest_notebook(), root / SELFTEST)

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
        [sys.executable, "-m", "jupyterlab", "--no-browser", "--allow-root", "--ServerApp.ip=127.0.0.1",
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
            lab_page.evaluate("""async () => {
                await window.jupyterapp.commands.execute('docmanager:save').catch(() => null);
                await window.jupyterapp.commands.execute('application:close-all');
            }""")
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

# Run All finished: kernel idle, nothing queued, and every code cell numbered or an error was shown.
_JS_RUN_ALL_FINISHED = """() => {
    const idle = [...document.querySelectorAll('.jp-StatusBar-TextItem')]
        .some(e => /^Python.*\\|\\s*Idle\\s*$/.test(e.textContent.trim()));
    const prompts = [...document.querySelectorAll('.jp-Notebook .jp-CodeCell .jp-InputPrompt')]
        .map(e => e.textContent.trim());
    // every code cell has run: read from the notebook model, because a cell whose source is
    // collapsed (the hidden solutions) shows no prompt
    const nb = window.jupyterapp && window.jupyterapp.shell.currentWidget;
    const cells = nb && nb.content && nb.content.model ? nb.content.model.cells : null;
    let done = cells !== null && cells.length > 0;
    for (let i = 0; cells !== null && i < cells.length; i++) {
        const c = cells.get(i);
        if (c.type === 'code' && (c.executionCount === null || c.executionCount === undefined)) done = false;
    }
    const err = document.querySelector(".jp-Notebook [data-mime-type='application/vnd.jupyter.stderr']");
    return idle && !prompts.includes('[*]:') && (done || err !== null);
}"""

# Widget figures: matplotlib output shown in an Output widget (interact, interactive_output) as a
# data: URL, or an ipywidgets.Image, shown from a blob: URL.
_FIGURES = ".jp-Notebook .widget-output img, .jp-Notebook img.widget-image"

# Sources of every widget figure in the notebook, and whether each sits in slider idx's cell.
_JS_WIDGET_SOURCES = """(idx) => {
    const slider = document.querySelectorAll('.jp-Notebook .widget-slider')[idx];
    const cell = slider.closest('.jp-Cell');
    return [...document.querySelectorAll('%s')]
        .filter(i => /^(data:image\\/png|blob:)/.test(i.src))
        .map(i => ({own: cell.contains(i), src: i.src}));
}""" % _FIGURES

# The same with the image bytes as a data: URL (blob: images are fetched and encoded).
_JS_WIDGET_FIGURES = """async (idx) => {
    const slider = document.querySelectorAll('.jp-Notebook .widget-slider')[idx];
    const cell = slider.closest('.jp-Cell');
    const imgs = [...document.querySelectorAll('%s')].filter(i => /^(data:image\\/png|blob:)/.test(i.src));
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
}""" % _FIGURES

_JS_OWN_FIGURE_NOT = """([idx, old]) => {
    const slider = document.querySelectorAll('.jp-Notebook .widget-slider')[idx];
    const imgs = [...slider.closest('.jp-Cell').querySelectorAll('%s')]
        .filter(i => /^(data:image\\/png|blob:)/.test(i.src));
    return imgs.length > 0 && imgs.map(i => i.src).join('|') !== old;
}""" % _FIGURES.replace(".jp-Notebook ", "")


def _png(src: str) -> bytes:
    assert src.startswith("data:image/png;base64,"), src[:40]
    data = base64.b64decode(src.split(",", 1)[1])
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "widget figure is not a PNG"
    return data


def _figures(page, idx: int) -> tuple[list[bytes], list[bytes]]:
    """(own figures, other widgets' figures) as PNG bytes, in page order."""
    try:
        figs = page.evaluate(_JS_WIDGET_FIGURES, idx)
    except playwright_sync.Error:  # a blob: image was replaced while being read: settle and retry once
        _settle(page, idx)
        figs = page.evaluate(_JS_WIDGET_FIGURES, idx)
    return [_png(f["src"]) for f in figs if f["own"]], [_png(f["src"]) for f in figs if not f["own"]]


def _settle(page, idx: int) -> None:
    """Wait until the kernel is idle and the slider's figures are unchanged over two polls 0.3 s apart."""
    last = None
    for _ in range(80):
        page.wait_for_function(_JS_KERNEL_IDLE, timeout=REDRAW_TIMEOUT_MS)
        now = page.evaluate(_JS_WIDGET_SOURCES, idx)
        if now == last:
            return
        last = now
        page.wait_for_timeout(300)
    raise AssertionError("the widget figures kept changing for 24 s")


def open_and_run_all(page, rel: str) -> None:
    """Open ``rel`` (relative to the server root) in JupyterLab and run all cells; fail on errors."""
    with _phase(f"{rel}: open the notebook"):
        page.evaluate("async (path) => { await window.jupyterapp.commands.execute('docmanager:open', {path}); }",
                      rel)
        page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=KERNEL_TIMEOUT_MS)
    with _phase(f"{rel}: kernel start until idle"):
        page.wait_for_function(_JS_KERNEL_IDLE, timeout=KERNEL_TIMEOUT_MS)
    with _phase(f"{rel}: Run All"):
        page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
        page.locator("li.lm-Menu-item[data-command='runmenu:run-all']").click()
        page.wait_for_function(_JS_RUN_ALL_FINISHED, timeout=RUN_ALL_TIMEOUT_MS, polling=250)
    stderr = page.locator(".jp-Notebook [data-mime-type='application/vnd.jupyter.stderr']").all_inner_texts()
    assert not stderr, f"{rel}: cells wrote to stderr (error or warning):\n" + "\n---\n".join(stderr)[:4000]
    prompts = page.locator(".jp-Notebook .jp-CodeCell .jp-InputPrompt").all_inner_texts()
    shown = [p for p in prompts if p.strip()]  # a cell with collapsed source (a hidden solution) shows none
    assert shown and all(p.strip().startswith("[") and p.strip()[1:-2].isdigit() for p in shown), prompts


def slider_index(page, label: str | None) -> int:
    """Index (in page order) of the first slider with description ``label`` (None: the first slider)."""
    labels = [t.strip() for t in page.locator(".jp-Notebook .widget-slider").evaluate_all(
        "els => els.map(e => (e.querySelector('label.widget-label') || {}).textContent || '')")]
    assert labels, "no ipywidgets slider was rendered in the notebook"
    if label is None:
        return 0
    assert label in labels, f"no slider labelled {label!r}; sliders found: {labels}"
    return labels.index(label)


def slider_value(page, idx: int) -> str:
    """The value slider ``idx`` shows: its readout, else aria-valuetext (aria-valuenow is rounded)."""
    return page.locator(".jp-Notebook .widget-slider").nth(idx).evaluate("""s => {
        const r = s.querySelector('.widget-readout');
        const h = s.querySelector('.noUi-handle');
        return (r && r.textContent.trim()) || h.getAttribute('aria-valuetext') || h.getAttribute('aria-valuenow');
    }""")


def move_slider(page, idx: int, key: str, timeout: float = REDRAW_TIMEOUT_MS) -> tuple[str, str]:
    """Press ``key`` on slider ``idx``'s handle; wait for its figure to redraw. Returns (old, new) value."""
    handle = page.locator(".jp-Notebook .widget-slider").nth(idx).locator(".noUi-handle").first
    before = slider_value(page, idx)
    old = "|".join(f["src"] for f in page.evaluate(_JS_WIDGET_SOURCES, idx) if f["own"])
    handle.focus()
    page.keyboard.press(key)
    after = slider_value(page, idx)
    assert after != before, f"pressing {key} did not move the slider (value {before})"
    try:
        page.wait_for_function(_JS_OWN_FIGURE_NOT, arg=[idx, old], timeout=timeout, polling=100)
    except playwright_sync.TimeoutError as exc:
        raise FigureDidNotChange(f"moving the slider {before} -> {after} did not change its figure "
                                 f"within {timeout / 1000:.0f} s") from exc
    _settle(page, idx)
    return before, after


def check_slider(page, idx: int, shots: Path) -> None:
    """Move slider ``idx`` one step and back; its figure changes then returns, others never change."""
    handle = page.locator(".jp-Notebook .widget-slider").nth(idx).locator(".noUi-handle").first
    cell_idx = page.evaluate("""(idx) => {
        const s = document.querySelectorAll('.jp-Notebook .widget-slider')[idx];
        return [...document.querySelectorAll('.jp-Notebook .jp-Cell')].indexOf(s.closest('.jp-Cell'));
    }""", idx)
    cell = page.locator(".jp-Notebook .jp-Cell").nth(cell_idx)
    _settle(page, idx)
    own0, others0 = _figures(page, idx)
    assert own0, "the slider's cell shows no PNG figure after Run All"
    cell.screenshot(path=shots / "widget-before.png")
    at_end = handle.get_attribute("aria-valuenow") == handle.get_attribute("aria-valuemax")
    forward, back = ("ArrowLeft", "ArrowRight") if at_end else ("ArrowRight", "ArrowLeft")

    with _phase("slider: move one step, redraw, settle"):
        move_slider(page, idx, forward)
    own1, others1 = _figures(page, idx)
    cell.screenshot(path=shots / "widget-after.png")
    page.screenshot(path=shots / "page-after.png")
    assert own1 != own0, "the figure's PNG did not change"
    assert others1 == others0, "moving one slider changed another widget's figure (shared state?)"

    move_slider(page, idx, back)
    own2, others2 = _figures(page, idx)
    assert own2 == own0, "moving the slider back did not give back the byte-identical figure"
    assert others2 == others0, "moving one slider changed another widget's figure (shared state?)"


def _close_sessions(base: str, token: str) -> None:
    """Shut down every kernel of the server (one notebook at a time keeps memory low)."""
    import json

    req = urllib.request.Request(f"{base}/api/sessions", headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(req, timeout=5) as r:
        sessions = json.load(r)
    for s in sessions:
        _request(f"{base}/api/sessions/{s['id']}", "DELETE", token)


# ---------------------------------------------------------------- tests


@pytest.mark.skipif((BOOK / "00_preface.ipynb").exists() and not RUN_ALL_TARGETS,
                    reason="the preface covers the harness; LOCALIZE_BROWSER_ALL=1 adds this self-test "
                           "and its negative control")
def test_selftest_notebook_slider_redraws_only_its_own_figure(page, artifacts):
    """The harness on a notebook it wrote: a real redraw passes, a slider that changes nothing fails."""
    shots = artifacts / "selftest"
    shots.mkdir(exist_ok=True)
    open_and_run_all(page, SELFTEST)
    check_slider(page, slider_index(page, "freq"), shots)
    # Negative control: the test must be able to fail.
    with pytest.raises(FigureDidNotChange):
        move_slider(page, slider_index(page, "ignored"), "ArrowRight", timeout=1_500)


@pytest.mark.parametrize("notebook,label", [
    pytest.param(nb, label, id=nb.removesuffix(".ipynb"),
                 marks=pytest.mark.skipif(not (BOOK / nb).exists(), reason=f"book/{nb} does not exist yet"))
    for nb, label in TARGETS])
def test_chapter_slider_redraws_its_figure(page, artifacts, notebook, label):
    shots = artifacts / notebook.removesuffix(".ipynb")
    shots.mkdir(exist_ok=True)
    open_and_run_all(page, f"book/{notebook}")
    page.screenshot(path=shots / "page-after-run-all.png")
    check_slider(page, slider_index(page, label), shots)
