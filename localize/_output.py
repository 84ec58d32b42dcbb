"""One run's results in one folder: complete, or not at all.

:class:`RunOutput` is what the command line writes ``--out DIR`` through:

* **checked first**: :meth:`RunOutput.open` creates ``DIR`` and a staging
  folder inside it, so an unwritable ``--out`` is reported before minutes of
  filtering (the command line calls it first, before reading the input
  files; a folder it created is removed again if the run ends without
  results);
* **locked**: a lock file ``DIR/.localize.lock`` (an ``flock``, released by
  the kernel even if the run is killed; removed when the run ends) keeps a
  second run from writing the same folder; it is refused at its start with the
  first run's process id;
* **staged**: every result is written into ``DIR/.localize-partial-<pid>/``;
  only when all of them are complete are they moved into ``DIR`` with
  ``os.replace`` (atomic per file), ``summary.json`` last — its presence
  marks a complete run, and it lists the run's files;
* **no stale files**: results of an earlier run that this run does not
  produce (``particles.gif`` of an earlier ``--animate``) are removed, and
  the terminal is told;
* **nothing half-written**: an error or Ctrl-C before the commit deletes the
  staging folder, leaving ``DIR`` as it was (an earlier complete run stays;
  a folder created for the run is removed again).

Examples
--------
>>> d = tmp_dir() / "out"
>>> with RunOutput(d) as o:
...     _ = o.open()                # checks and locks the folder
...     _ = o.path("trajectory.csv").write_text("time,x,y,theta\\n")
...     _ = o.path("summary.json").write_text("{}")
...     written, removed = o.commit()
>>> sorted(p.name for p in d.iterdir() if not p.name.startswith("."))
['summary.json', 'trajectory.csv']
>>> with RunOutput(d) as o:        # a failing run leaves the earlier results alone
...     _ = o.open().path("summary.json").write_text("half")
...     raise ValueError("the filter failed")
Traceback (most recent call last):
...
ValueError: the filter failed
>>> (d / "summary.json").read_text(), sorted(p.name for p in d.iterdir())
('{}', ['summary.json', 'trajectory.csv'])
"""

from __future__ import annotations

import datetime as _dt
import os
import shutil
import signal
import socket
import sys
from pathlib import Path
from typing import TextIO

__all__ = ["RunOutput", "RESULT_FILES", "LOCK_NAME"]

#: Every file a run may write into ``--out``; those a run does not write are removed as stale.
RESULT_FILES = ("trajectory.csv", "trajectory.tum", "reference.tum", "localization.bag", "localization_bag",
                "summary.json", "particles.gif", "particles.mp4")
#: The lock file of a folder being written.
LOCK_NAME = ".localize.lock"
_STAGE_PREFIX = ".localize-partial-"

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


class RunOutput:
    """Write one run's results into ``folder`` atomically (see the module docstring).

    Parameters
    ----------
    folder : path
        The output folder (created with its parents).
    option : str
        The option that named it, for messages (``--out``).
    results : sequence of str
        The files a run may produce; those not written by :meth:`commit` are
        removed from ``folder`` as results of an earlier run.
    last : str
        The file moved into place last (the "complete run" marker).
    err : text stream, optional
        Where to say that an aborted run left the folder untouched (the
        sentence is also attached to the exception as ``output_note``).
    """

    def __init__(self, folder: str | os.PathLike, option: str = "--out", results=RESULT_FILES,
                 last: str = "summary.json", err: TextIO | None = None) -> None:
        self.folder = Path(folder)
        self.option = option
        self.results = tuple(results)
        self.last = last
        self.err = err
        self.stage: Path | None = None
        self._lock_fd: int | None = None
        self._created: list[Path] = []
        self._committed = False
        self.interrupted = False
        self._old_handler = None
        self._old_hook = sys.unraisablehook

    # ------------------------------------------------------------ open / close
    def __enter__(self) -> "RunOutput":
        return self

    def open(self) -> "RunOutput":
        """Check that the folder can be written and lock it; call before the long work starts.

        Raises ``ValueError`` naming the option and the folder when it cannot
        be created or written, or when another run holds its lock.
        """
        if self.stage is not None:
            return self
        where = f"{self.option} {self.folder}"
        if self.folder.exists() and not self.folder.is_dir():
            raise ValueError(f"{where}: exists and is not a folder; give a folder for the results")
        missing = [p for p in (self.folder, *self.folder.parents) if not p.exists()]
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"{where}: cannot create the output folder ({exc.strerror or exc})") from None
        self._created = missing[::-1]  # outermost first
        try:
            self._lock()
            for old in self.folder.glob(_STAGE_PREFIX + "*"):  # left by a killed run (we hold the lock)
                shutil.rmtree(old, ignore_errors=True)
            stage = self.folder / f"{_STAGE_PREFIX}{os.getpid()}"
            stage.mkdir()
            self.stage = stage
            probe = stage / ".probe"
            probe.write_bytes(b"")
            probe.unlink()
            self._watch_sigint()
        except OSError as exc:
            self.close()
            raise ValueError(f"{where}: cannot write into the output folder ({exc.strerror or exc})") from None
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        staged = self.stage is not None and self.stage.is_dir() and any(self.stage.iterdir())
        if exc is not None and not self._committed and (staged or isinstance(exc, KeyboardInterrupt)):
            kept = [n for n in self.results if (self.folder / n).exists()]
            state = (f"it still holds the earlier run's {', '.join(kept)}" if kept else "it holds no results")
            note = f"nothing written to {self.folder} ({state})"
            try:  # the command line prints it after the error message
                exc.output_note = note
            except AttributeError:  # pragma: no cover - exceptions without a __dict__
                pass
            if self.err is not None:
                print(f"localize: {note}", file=self.err)
        self.close()
        return False

    def close(self) -> None:
        """Remove the staging folder, release the lock, remove folders made for a run that wrote nothing."""
        if self.stage is not None and self.stage.exists():
            shutil.rmtree(self.stage, ignore_errors=True)
        self.stage = None
        self._unwatch_sigint()
        self._unlock()
        if not self._committed:
            for d in reversed(self._created):  # innermost first; only while empty
                try:
                    d.rmdir()
                except OSError:
                    break
        self._created = []

    # ------------------------------------------------------------ Ctrl-C
    def _watch_sigint(self) -> None:
        """Remember any Ctrl-C, then raise KeyboardInterrupt as usual.

        Python drops a KeyboardInterrupt raised inside a finalizer or weakref
        callback ("Exception ignored in ..."; matplotlib's animation writers
        run many), and the run would carry on; :meth:`commit` refuses to
        publish a run that saw a Ctrl-C.
        """
        import threading

        if threading.current_thread() is not threading.main_thread():
            return
        previous = signal.getsignal(signal.SIGINT)
        if previous in (signal.SIG_IGN, None):  # Ctrl-C ignored (a background job) or not set from Python
            return

        def handler(signum, frame):
            self.interrupted = True
            if callable(previous):
                previous(signum, frame)
            raise KeyboardInterrupt

        hook = sys.unraisablehook

        def unraisable(info):  # the swallowed Ctrl-C is remembered: no "Exception ignored" traceback
            if not isinstance(info.exc_value, KeyboardInterrupt):
                hook(info)

        self._old_handler, self._old_hook = previous, hook
        signal.signal(signal.SIGINT, handler)
        sys.unraisablehook = unraisable

    def _unwatch_sigint(self) -> None:
        if self._old_handler is not None:
            signal.signal(signal.SIGINT, self._old_handler)
            sys.unraisablehook = self._old_hook
            self._old_handler = None

    # ------------------------------------------------------------ the lock
    def _lock(self) -> None:
        lock = self.folder / LOCK_NAME
        where = f"{self.option} {self.folder}"
        while True:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
            if fcntl is None:  # pragma: no cover - Windows: no lock, but still staged and atomic
                break
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.read(fd, 200).decode(errors="replace").strip() or "another process"
                os.close(fd)
                raise ValueError(f"{where}: another run ({holder}) is writing this folder; wait for it to "
                                 "finish or choose another output folder") from None
            try:  # the holder before us may have removed the file between our open and our flock
                if os.stat(lock).st_ino == os.fstat(fd).st_ino:
                    break
            except FileNotFoundError:
                pass
            os.close(fd)
        os.ftruncate(fd, 0)
        now = _dt.datetime.now().isoformat(timespec="seconds")
        os.write(fd, f"pid {os.getpid()} on {socket.gethostname()}, started {now}".encode())
        self._lock_fd = fd

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            try:
                os.unlink(self.folder / LOCK_NAME)  # while still holding it: see _lock
            except OSError:  # pragma: no cover
                pass
            os.close(self._lock_fd)  # closing releases the flock
            self._lock_fd = None

    # ------------------------------------------------------------ writing
    def path(self, name: str) -> Path:
        """Where to write the result ``name`` now (inside the staging folder)."""
        if self.stage is None:
            raise RuntimeError("open() the RunOutput first: `with RunOutput(folder) as out: out.open(); ...`")
        if name not in self.results:
            raise ValueError(f"{name!r} is not one of the run's result files {self.results}")
        return self.stage / name

    def final(self, name: str) -> Path:
        """Where the result ``name`` will be after :meth:`commit`."""
        return self.folder / name

    def commit(self) -> tuple[list[Path], list[Path]]:
        """Move the staged results into the folder; remove stale ones. Returns (written, removed).

        Ctrl-C is held back while the files move (POSIX), so that the folder
        never mixes two runs.
        """
        if self.stage is None:
            raise RuntimeError("commit() outside the `with` block")
        staged = [n for n in self.results if (self.stage / n).exists()]  # files, and a ROS 2 bag folder
        if self.last not in staged:
            raise RuntimeError(f"commit() before {self.last} was written")
        blocked = _block_sigint()
        try:
            if self.interrupted:  # a Ctrl-C that Python swallowed somewhere: the run is not complete
                raise KeyboardInterrupt
            removed = []
            marker = self.folder / self.last
            if marker.exists():  # first: the folder stops claiming a complete run
                marker.unlink()
            for name in self.results:
                target = self.folder / name
                if name not in staged and target.exists():
                    _remove(target)
                    removed.append(target)
            written = []
            for name in sorted(staged, key=lambda n: n == self.last):
                if (self.stage / name).is_dir() and (self.folder / name).exists():
                    _remove(self.folder / name)  # os.replace cannot put a folder over another one
                os.replace(self.stage / name, self.folder / name)
                written.append(self.folder / name)
            self._committed = True
        finally:
            _unblock_sigint(blocked)
        return written, removed


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def _block_sigint() -> bool:
    if hasattr(signal, "pthread_sigmask") and sys.platform != "win32":
        import threading

        if threading.current_thread() is threading.main_thread():
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            return True
    return False


def _unblock_sigint(blocked: bool) -> None:
    if blocked:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
