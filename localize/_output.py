"""One run's results in one folder: complete, or not at all.

:class:`RunOutput` is what the command line writes ``--out DIR`` through:

* **checked first**: :meth:`RunOutput.open` creates ``DIR`` and a staging
  folder inside it, so an unwritable ``--out`` is reported before minutes of
  filtering (the command line calls it first, before reading the input
  files; a folder it created is removed again if the run ends without
  results);
* **locked**: a lock file ``DIR/.localize.lock`` (the maintained
  :mod:`filelock` package: an ``flock``, released by the kernel even if the
  run is killed; removed when the run ends) keeps a second run from writing
  the same folder; it is refused at its start with the first run's process id;
* **staged**: every result is written into ``DIR/.localize-partial-<pid>/``;
  only when all of them are complete are they moved into ``DIR`` with
  ``os.replace`` (atomic per file), ``summary.json`` last — its presence
  marks a complete run, and it lists the run's files;
* **no stale files**: results of an earlier run that this run does not
  produce (``particles.gif`` of an earlier ``--animate``) are removed, and
  the terminal is told;
* **nothing half-written**: an error or Ctrl-C before the commit deletes the
  staging folder, leaving ``DIR`` as it was (an earlier complete run stays;
  a folder created for the run is removed again); a full disk or a read-only
  folder while writing is reported as a sentence naming ``--out``, not as a
  bare ``[Errno 28]``;
* **inputs staged too**: a command that makes its own input files
  (``localize demo``) writes them into the staging folder as well, so they
  appear together with the results they belong to (``before_commit`` lets it
  complete the summary inside the staging folder).

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
import errno
import os
import shutil
import signal
import socket
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from filelock import FileLock, Timeout

__all__ = ["RunOutput", "RESULT_FILES", "LOCK_NAME"]

#: Every file a run may write into ``--out``; those a run does not write are removed as stale.
RESULT_FILES = ("trajectory.csv", "trajectory.tum", "reference.tum", "localization.bag", "localization_bag",
                "report.png", "map.yaml", "map.pgm", "summary.json", "particles.gif", "particles.mp4")
#: The lock file of a folder being written.
LOCK_NAME = ".localize.lock"
_STAGE_PREFIX = ".localize-partial-"
_HOLDER = ".holder"  # inside the staging folder: who holds the lock (for the refusal message)
#: errno values that mean "the folder cannot take the results" rather than a bug
_NO_ROOM = {errno.ENOSPC: "the disk is full", errno.EROFS: "the file system is read-only",
            errno.EDQUOT: "the disk quota is exceeded", errno.EACCES: "permission denied",
            errno.EPERM: "permission denied", errno.EFBIG: "a file is too large for the file system"}


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
    before_commit : callable, optional
        Called with this object at the start of :meth:`commit`, while every
        file is still staged (``localize demo`` adds its score to the staged
        summary there).
    """

    def __init__(self, folder: str | os.PathLike, option: str = "--out", results=RESULT_FILES,
                 last: str = "summary.json", err: TextIO | None = None,
                 before_commit: Callable[["RunOutput"], None] | None = None) -> None:
        self.folder = Path(folder)
        self.option = option
        self.results = tuple(results)
        self.last = last
        self.err = err
        self.before_commit = before_commit
        self.stage: Path | None = None
        self._lock: FileLock | None = None
        self._created: list[Path] = []
        self._committed = False
        self.interrupted = False
        self._old_handler = None
        self._old_hook = sys.unraisablehook

    @property
    def _where(self) -> str:
        return f"{self.option} {self.folder}"

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
        self._make_folder()
        try:
            self._acquire()
            self._make_stage()
            self._watch_sigint()
        except OSError as exc:
            self.close()
            raise ValueError(f"{self._where}: cannot write into the output folder ({_reason(exc)})") from None
        except BaseException:
            self.close()
            raise
        return self

    def _make_folder(self) -> None:
        if self.folder.exists() and not self.folder.is_dir():
            raise ValueError(f"{self._where}: exists and is not a folder; give a folder for the results")
        missing = [p for p in (self.folder, *self.folder.parents) if not p.exists()]
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"{self._where}: cannot create the output folder ({_reason(exc)})") from None
        self._created = missing[::-1]  # outermost first

    def _acquire(self) -> None:
        """Take the folder's lock (non-blocking) or refuse, naming the run that holds it."""
        for _ in range(10):
            lock = FileLock(self.folder / LOCK_NAME, timeout=0)
            try:
                lock.acquire()
            except Timeout:
                raise ValueError(f"{self._where}: another run ({self._holder()}) is writing this folder; wait for it "
                                 "to finish or choose another output folder") from None
            if _names_the_locked_file(lock):
                self._lock = lock
                return
            lock.release()  # we locked a file its holder had just removed (see _release): take the new one
        raise ValueError(f"{self._where}: the lock file {LOCK_NAME} keeps changing; is another program removing it?")

    def _holder(self) -> str:
        for stage in self.folder.glob(_STAGE_PREFIX + "*"):
            try:
                return (stage / _HOLDER).read_text().strip() or "another process"
            except OSError:
                continue
        return "another process"

    def _make_stage(self) -> None:
        for old in self.folder.glob(_STAGE_PREFIX + "*"):  # left by a killed run (we hold the lock)
            shutil.rmtree(old, ignore_errors=True)
        stage = self.folder / f"{_STAGE_PREFIX}{os.getpid()}"
        stage.mkdir()
        self.stage = stage
        now = _dt.datetime.now().isoformat(timespec="seconds")
        (stage / _HOLDER).write_text(f"pid {os.getpid()} on {socket.gethostname()}, started {now}")

    def __exit__(self, exc_type, exc, tb) -> bool:
        staged = self.stage is not None and self.stage.is_dir() and any(
            p.name != _HOLDER for p in self.stage.iterdir())
        note = None
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
        full = isinstance(exc, OSError) and exc.errno in _NO_ROOM and self._inside(exc.filename)
        self.close()
        if full:  # disk full, read-only: a sentence naming --out, not a bare [Errno 28]
            error = ValueError(f"{self._where}: cannot write the results ({_reason(exc)})")
            error.output_note = note
            raise error from exc
        return False

    def _inside(self, filename) -> bool:
        if filename is None:
            return False
        try:
            return Path(os.path.abspath(filename)).is_relative_to(os.path.abspath(self.folder))
        except (TypeError, ValueError):  # pragma: no cover
            return False

    def close(self) -> None:
        """Remove the staging folder, release the lock, remove folders made for a run that wrote nothing.

        Ctrl-C is held back meanwhile (POSIX), as in :meth:`commit`: cut short, it would leave the lock file or
        the folders behind."""
        blocked = _block_sigint()
        try:
            if self.stage is not None and self.stage.exists():
                shutil.rmtree(self.stage, ignore_errors=True)
            self.stage = None
            self._unwatch_sigint()
            self._release()
            if not self._committed:
                for d in reversed(self._created):  # innermost first; only while empty
                    try:
                        d.rmdir()
                    except OSError:
                        break
            self._created = []
        finally:
            _unblock_sigint(blocked)

    def _release(self) -> None:
        if self._lock is not None:
            try:  # removed while still held: a run that opened the old file finds it unlinked and retries
                os.unlink(self.folder / LOCK_NAME)
            except OSError:  # pragma: no cover
                pass
            self._lock.release()
            self._lock = None

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
            if isinstance(info.exc_value, KeyboardInterrupt):
                self.interrupted = True  # raised in a finalizer (a generator closed, a weakref callback)
            else:
                hook(info)

        self._old_handler, self._old_hook = previous, hook
        signal.signal(signal.SIGINT, handler)
        sys.unraisablehook = unraisable

    def _unwatch_sigint(self) -> None:
        if self._old_handler is not None:
            signal.signal(signal.SIGINT, self._old_handler)
            sys.unraisablehook = self._old_hook
            self._old_handler = None

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
        if self.before_commit is not None:
            self.before_commit(self)
        staged = [n for n in self.results if (self.stage / n).exists()]  # files, and a ROS 2 bag folder
        if self.last not in staged:
            raise RuntimeError(f"commit() before {self.last} was written")
        blocked = _block_sigint()
        try:
            if self.interrupted:  # a Ctrl-C that Python swallowed somewhere: the run is not complete
                raise KeyboardInterrupt
            removed = self._remove_stale(staged)
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

    def _remove_stale(self, staged: list[str]) -> list[Path]:
        marker = self.folder / self.last
        if marker.exists():  # first: the folder stops claiming a complete run
            marker.unlink()
        removed = []
        for name in self.results:
            target = self.folder / name
            if name not in staged and target.exists():
                _remove(target)
                removed.append(target)
        return removed


def _names_the_locked_file(lock: FileLock) -> bool:
    """Whether the lock's path still names the file it locked.

    A run that opened ``.localize.lock`` just before its holder removed it
    (:meth:`RunOutput._release` removes it while still holding it) would lock
    a file that no longer has a name, while a third run creates and locks a
    new one. filelock 4 checks this itself; for older versions the locked
    descriptor (not public API: skipped when absent) is compared with the path.
    """
    fd = getattr(getattr(lock, "_context", None), "lock_file_fd", None)
    if not isinstance(fd, int):
        return True
    try:
        return os.path.samestat(os.fstat(fd), os.stat(lock.lock_file))
    except OSError:
        return False


def _reason(exc: OSError) -> str:
    """The cause of an OSError in words, with the file it concerns."""
    text = _NO_ROOM.get(exc.errno) or exc.strerror or str(exc)
    return f"{text}: {exc.filename}" if exc.filename else text


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
