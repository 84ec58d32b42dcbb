"""The book's Jupyter server configuration keeps a reader's clone clean (issue 40).

``jupyter_server_config.py`` (the README's book command loads it) makes the chapters and their
jupytext twins read-only in the contents manager that JupyterLab talks to. Here the very class
the server builds (jupytext's contents manager derived from the configured one, as the jupytext
server extension does) runs on a copy of the book: chapters and twins report
``writable: false`` and a save leaves both files byte-identical, while the homework and a
reader's own copy stay writable. ``tests/test_browser.py`` checks the same in JupyterLab.
"""

from __future__ import annotations

import asyncio
import hashlib
import os
import shutil
from pathlib import Path
from unittest import mock

import pytest

pytest.importorskip("jupyter_server")
jupytext_cm = pytest.importorskip("jupytext.async_contentsmanager")

from tornado.web import HTTPError  # noqa: E402
from traitlets.config.loader import PyFileConfigLoader  # noqa: E402

# the lowest-versions CI job (.ci/run, job 3) deselects this module: it checks our own tooling, not numerics
pytestmark = pytest.mark.tooling

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "jupyter_server_config.py"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def manager(tmp_path):
    """The server's contents manager over a copy of the book, configured by a copy of the config file."""
    shutil.copy(CONFIG, tmp_path / CONFIG.name)
    book = tmp_path / "book"
    (book / "src").mkdir(parents=True)
    (book / "homework").mkdir()
    for name in ("01_bayes_filter.ipynb", "src/01_bayes_filter.py", "homework/homework.ipynb"):
        shutil.copy(ROOT / "book" / name, book / name)
    with mock.patch.dict(os.environ):           # the config sets PYTHONSTARTUP for the kernels: not for us
        config = PyFileConfigLoader(CONFIG.name, path=str(tmp_path)).load_config()
    base = config.ServerApp.contents_manager_class
    assert base.__name__ == "BookContentsManager"
    cls = jupytext_cm.build_async_jupytext_contents_manager_class(base)   # what the jupytext extension does
    return cls(root_dir=str(book)), book


def test_readme_book_command_loads_the_config():
    readme = (ROOT / "README.md").read_text()
    command = readme.split("<!-- book-command -->", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    assert f"--config={CONFIG.name}" in command and "jupyter lab" in command, command


def test_chapters_and_twins_are_read_only_and_saving_changes_no_byte(manager):
    cm, book = manager
    files = [book / "01_bayes_filter.ipynb", book / "src" / "01_bayes_filter.py"]
    before = [_digest(f) for f in files]

    async def run():
        for path in ("01_bayes_filter.ipynb", "src/01_bayes_filter.py"):
            assert (await cm.get(path, content=False))["writable"] is False, path
        model = await cm.get("01_bayes_filter.ipynb")
        model["content"]["cells"][0]["source"] += "\nedited"          # a run, an edit, anything
        model["content"]["metadata"]["widgets"] = {"state": {}}
        with pytest.raises(HTTPError) as err:
            await cm.save({"type": "notebook", "content": model["content"]}, "01_bayes_filter.ipynb")
        assert "read-only" in str(err.value) and "Save Notebook As" in str(err.value)
        # a reader's own copy, and the homework, are writable
        await cm.save({"type": "notebook", "content": model["content"]}, "01_bayes_filter-mine.ipynb")
        assert (await cm.get("01_bayes_filter-mine.ipynb", content=False))["writable"] is True
        assert (await cm.get("homework/homework.ipynb", content=False))["writable"] is True

    asyncio.run(run())
    assert [_digest(f) for f in files] == before
    assert (book / "01_bayes_filter-mine.ipynb").exists()


def test_kernels_of_the_server_run_the_book_startup_and_keep_the_readers_own(tmp_path):
    env = {"PYTHONSTARTUP": "/home/reader/.pythonrc"}
    with mock.patch.dict(os.environ, env):
        PyFileConfigLoader(CONFIG.name, path=str(ROOT)).load_config()
        assert os.environ["PYTHONSTARTUP"] == str(ROOT / "jupyter_kernel_startup.py")
        assert os.environ["LOCALIZE_USER_PYTHONSTARTUP"] == "/home/reader/.pythonrc"
        PyFileConfigLoader(CONFIG.name, path=str(ROOT)).load_config()       # loading twice changes nothing
        assert os.environ["LOCALIZE_USER_PYTHONSTARTUP"] == "/home/reader/.pythonrc"


def test_a_readers_copies_are_ignored_by_git():
    import subprocess

    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    names = ["book/01_bayes_filter-mine.ipynb", "book/src/01_bayes_filter-mine.py"]
    out = subprocess.run(["git", "check-ignore", *names], cwd=ROOT, capture_output=True, text=True)
    assert out.stdout.split() == names, out
