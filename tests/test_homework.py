"""The homework: its solutions pass every check, its student template fails them gracefully."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import jupytext
import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
HW = ROOT / "book" / "homework"


def _run(nb, tmp_path):
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    texts = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for out in cell.get("outputs", []):
            assert out.output_type != "error", f"cell raised: {out.get('ename')}: {out.get('evalue')}"
            if "text" in out:
                texts.append(out.text)
            elif "text/plain" in out.get("data", {}):
                texts.append(out.data["text/plain"])
    return "\n".join(texts)


def test_template_is_generated_from_solutions():
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "make_homework.py"), "--check"], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_template_has_stubs_and_no_solutions():
    nb = nbformat.read(HW / "homework.ipynb", as_version=4)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert code.count("raise NotImplementedError") == 17
    assert "np.searchsorted" not in code and "math.erf" not in code
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")


@pytest.mark.slow
def test_solutions_pass_every_check(tmp_path):
    text = _run(jupytext.read(HW / "homework_solutions.py"), tmp_path)
    assert "FAILED" not in text, text
    assert text.count("checks passed") == 17, text


@pytest.mark.slow
def test_student_template_fails_gracefully(tmp_path):
    text = _run(nbformat.read(HW / "homework.ipynb", as_version=4), tmp_path)
    assert text.count("checks FAILED") == 17, text
    assert text.count("replace `raise NotImplementedError`") >= 17
