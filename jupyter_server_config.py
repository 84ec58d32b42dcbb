"""Jupyter server configuration of the book: reading and running a chapter never changes the clone.

Used by the README's book command, ``jupyter lab book/ --config=jupyter_server_config.py``.

The chapters ``book/NN_name.ipynb`` and their jupytext twins ``book/src/NN_name.py`` are the
book's source, kept in git. JupyterLab's autosave (every two minutes) rewrote both after a
reader's Run All: new widget ids, progress bars, execution metadata, the solution cells'
``outputs_hidden`` flags, so that the reader's next ``git pull`` conflicted. Here the server
reports those files as read-only (``writable: false`` in their contents model) and refuses to
overwrite them. JupyterLab then runs them as usual but never autosaves them; Ctrl+S says
'read-only, use "Save as..." instead', and closing a run chapter offers "Save as". A copy saved
under a new name is the reader's own (names ending in ``-mine.ipynb`` are ignored by git).
The homework (``book/homework/``) stays writable: it is meant to be filled in.

Solutions: JupyterLab shows a cell's output again when the cell runs, so Run All printed
the answers of the exercises under them. Every kernel this server starts runs
``jupyter_kernel_startup.py`` (through ``PYTHONSTARTUP``; a reader's own ``PYTHONSTARTUP`` file
still runs after it), which folds the output of cells tagged ``solution`` into a closed
"Output of the solution (click to show)" (:mod:`localize.widgets._solutions`).

Running as root: Jupyter refuses to start as root unless told so (``--allow-root``); this
file does not change that (see the README).

Checked by ``tests/test_book_server_config.py`` (the contents manager, without a browser)
and ``tests/test_browser.py`` (JupyterLab in Chromium: Run All, then save, leaves every file
byte-identical).
"""

import os
import re
from pathlib import Path

from jupyter_server.services.contents.largefilemanager import AsyncLargeFileManager
from tornado.web import HTTPError

BOOK = Path(__file__).resolve().parent / "book"
_CHAPTER = re.compile(r"\d\d_\w+")
READ_ONLY_HINT = ('is a chapter of the book, kept in git: it opens read-only so that running it never changes '
                  'your clone. Use File > "Save Notebook As..." to keep your own copy (a name ending in '
                  '-mine.ipynb is ignored by git).')


def is_book_source(os_path) -> bool:
    """True for ``book/NN_name.ipynb`` and its twin ``book/src/NN_name.py`` (not the homework)."""
    p = Path(os_path).resolve()
    if not _CHAPTER.fullmatch(p.stem):
        return False
    return (p.parent == BOOK and p.suffix == ".ipynb") or (p.parent == BOOK / "src" and p.suffix == ".py")


class BookContentsManager(AsyncLargeFileManager):
    """The default contents manager, with the book's chapters and their twins read-only."""

    async def get(self, path, content=True, type=None, format=None, **kwargs):  # noqa: A002 - the API's names
        model = await super().get(path, content=content, type=type, format=format, **kwargs)
        if model.get("type") != "directory" and is_book_source(self._get_os_path(path)):
            model["writable"] = False
        return model

    async def save(self, model, path=""):
        if is_book_source(self._get_os_path(path.strip("/"))):
            raise HTTPError(403, f"{path} {READ_ONLY_HINT}")
        return await super().save(model, path)


c = get_config()  # noqa: F821 - defined by the config loader
c.ServerApp.contents_manager_class = BookContentsManager

# kernels inherit the server's environment: fold the solutions' outputs (see above)
KERNEL_STARTUP = str(Path(__file__).resolve().with_name("jupyter_kernel_startup.py"))
if os.environ.get("PYTHONSTARTUP") not in (None, "", KERNEL_STARTUP):
    os.environ["LOCALIZE_USER_PYTHONSTARTUP"] = os.environ["PYTHONSTARTUP"]
os.environ["PYTHONSTARTUP"] = KERNEL_STARTUP
