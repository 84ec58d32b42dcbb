"""Solutions open collapsed in JupyterLab, with a way to reveal them: checked in a real Chromium.

Reuses the JupyterLab server and page of ``tests/test_browser.py`` (same
skips: no playwright, no jupyterlab or no Chromium). The chapter is only
opened, not run: what a student sees on opening it is what is checked.

* every markdown solution is a closed ``<details>`` element whose summary
  says Solution, whose inside is rendered markdown with its formulas typeset
  by MathJax (no raw ``$`` or MyST directive text), and which opens on a click
  on its summary;
* every code solution shows only JupyterLab's collapsed-input bar, whose text
  is the cell's first line ``# Solution (click to show)``, and its outputs are
  collapsed too; a click on the bar reveals the code.

Marked ``browser`` like the slider tests.
"""

from __future__ import annotations

import nbformat
import pytest
from test_browser import BOOK, KERNEL_TIMEOUT_MS, artifacts, lab, lab_page, page  # noqa: F401 - fixtures

pytestmark = pytest.mark.browser

NOTEBOOK = "01_bayes_filter.ipynb"   # small, with both markdown and code solutions

_JS_STATE = """() => {
    const nb = document.querySelector('.jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook');
    const details = [...nb.querySelectorAll('.jp-MarkdownCell .jp-RenderedMarkdown details')];
    const md = details.map(d => ({
        open: d.open,
        summary: (d.querySelector('summary') || {textContent: ''}).textContent,
        text: [...d.childNodes].filter(n => n.nodeName !== 'SUMMARY').map(n => n.textContent).join(' '),
        math: d.querySelectorAll('mjx-container').length,
        // a closed <details> is as tall as its summary (its children may still report a layout size)
        visibleHeight: d.getBoundingClientRect().height
                       - (d.querySelector('summary') || d).getBoundingClientRect().height,
    }));
    const bars = [...nb.querySelectorAll('.jp-CodeCell .jp-InputPlaceholder')].map(e => e.textContent.trim());
    const outBars = nb.querySelectorAll('.jp-CodeCell .jp-OutputPlaceholder').length;
    const raw = nb.textContent.includes('{admonition}') || nb.textContent.includes(':class: dropdown');
    return {md, bars, outBars, raw};
}"""


def _expected(nb_path):
    nb = nbformat.read(nb_path, as_version=4)
    sol = [c for c in nb.cells if "solution" in c.metadata.get("tags", [])]
    md = [c for c in sol if c.cell_type == "markdown"]
    code = [c for c in sol if c.cell_type == "code"]
    return md, code


def test_solutions_collapsed_and_revealable_in_jupyterlab(page, artifacts):  # noqa: F811
    md, code = _expected(BOOK / NOTEBOOK)
    assert md and code, f"{NOTEBOOK} should have markdown and code solutions for this test"
    page.evaluate("async (path) => { await window.jupyterapp.commands.execute('docmanager:open', {path}); }",
                  f"book/{NOTEBOOK}")
    page.wait_for_selector(".jp-Notebook .jp-MarkdownCell details", timeout=KERNEL_TIMEOUT_MS)
    page.wait_for_function("() => document.querySelectorAll('.jp-Notebook details mjx-container').length > 0",
                           timeout=KERNEL_TIMEOUT_MS)
    state = page.evaluate(_JS_STATE)
    first_md = page.locator(".jp-Notebook .jp-MarkdownCell:has(details)").first
    first_md.scroll_into_view_if_needed()
    page.screenshot(path=artifacts / "solutions-collapsed.png")
    assert not state["raw"], "raw MyST admonition markup is shown"
    assert len(state["md"]) == len(md), state
    for d, cell in zip(state["md"], md):
        assert not d["open"] and "Solution" in d["summary"], d
        assert d["visibleHeight"] < 2, f"a closed solution shows content: {d}"
        assert "$" not in d["text"] and "**" not in d["text"], f"unrendered markdown or math: {d['text'][:200]}"
        assert ("$" in cell.source) == (d["math"] > 0), f"formulas not typeset: {d}"
    assert len(state["bars"]) == len(code), state
    assert all(b.startswith("# Solution (click to show)") for b in state["bars"]), state["bars"]
    assert state["outBars"] >= sum(bool(c.outputs) for c in code), state
    # revealing: a click on a summary opens it, a click on a bar shows the code
    page.locator(".jp-Notebook .jp-MarkdownCell details summary").first.click()
    assert page.evaluate("() => document.querySelector('.jp-Notebook .jp-MarkdownCell details').open")
    opened = page.evaluate("""() => { const d = document.querySelector('.jp-Notebook .jp-MarkdownCell details');
        return d.getBoundingClientRect().height - d.querySelector('summary').getBoundingClientRect().height; }""")
    assert opened > 20, f"an opened solution should show its text; height {opened}"
    n_bars = len(state["bars"])
    page.locator(".jp-Notebook .jp-CodeCell .jp-InputPlaceholder").first.click()
    page.wait_for_function(f"() => document.querySelectorAll('.jp-Notebook .jp-InputPlaceholder').length < {n_bars}")
    page.screenshot(path=artifacts / "solutions-revealed.png")
