"""The process that grades one submission: ``localize.grade.runner`` starts it, nothing else imports it.

It runs in a scratch folder that :func:`localize.grade.runner.grade_submission`
prepared, under the resource limits that function set, with only the
``localize`` package importable (the teacher's solutions are not on the path).
It reads its job from ``.grader/job.json``, then

1. imports :mod:`localize.check` and every module the checks use, records the
   attributes of those modules (and of their classes) and installs an audit
   hook (PEP 578) that refuses, and records as tampering, an import of the
   solution module, opening the solutions file, writing or deleting a file
   outside the scratch folder or inside its ``.grader/``, and starting a
   program;
2. runs the notebook's code cells in order, each under a soft time limit, a
   cell that raises or runs too long being reported and skipped;
3. grades each task (one function, one check) in a forked child under the
   task's time limit, so that an endless loop, a crash or a tampering call in
   one function costs only that function;
4. writes one JSON line per finding to the result file (opened before any
   student code ran, outside the scratch folder).

Python cannot sandbox code against itself: these defences stop accidents and
the classic tricks (a patched ``localize.check``, a deleted grader file, an
imported solution), not a determined attacker. For that, run the grader in a
container or as a user who cannot read the solutions.
"""

from __future__ import annotations

import ast
import importlib
import json
import os
import select
import signal
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Callable

_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND
_PATH_EVENTS = {"os.remove": 1, "os.rmdir": 1, "shutil.rmtree": 1, "os.truncate": 1, "os.chmod": 1,
                "os.chown": 1, "os.rename": 2, "os.link": 2, "os.symlink": 2, "os.utime": 1, "os.mkdir": 1,
                "shutil.move": 2, "shutil.copyfile": 2}
_PROGRAM_EVENTS = ("os.system", "os.exec", "os.posix_spawn", "os.spawn", "subprocess.Popen", "os.startfile",
                   "pty.spawn")


class _CellTimeout(BaseException):
    """Raised in a notebook cell that ran past its soft time limit (a BaseException: `except Exception` misses it)."""


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder + os.sep)


def _audit_hook(work: str, grader: str, forbidden: tuple[str, ...], found: list[str]) -> Callable:
    """The PEP 578 hook: refuse and record what a submission must not do."""

    def refuse(why: str, error: type[Exception] = PermissionError) -> None:
        if why not in found:
            found.append(why)
        raise error(f"the grader refuses this: {why}")

    def writable(path: Any) -> str | None:
        """What ``path`` is if it is outside the scratch folder or one of the grader's files, else None."""
        if isinstance(path, int):
            return None
        real = os.path.realpath(os.fsdecode(path))
        if _inside(real, grader):
            return f"the grader's file {os.path.relpath(real, work)}"
        return None if _inside(real, work) else f"{real}, outside its scratch folder"

    def hook(event: str, args: tuple) -> None:
        if event == "import":
            if any(part in forbidden for part in str(args[0]).split(".")):
                refuse(f"imports the solution module {args[0]}", ImportError)
        elif event == "open":
            path, mode, flags = args
            if path is None or isinstance(path, int):
                return
            name = os.path.basename(os.fsdecode(path))
            if any(name.startswith(f) for f in forbidden):
                refuse(f"opens the solutions file {name}")
            writing = (isinstance(mode, str) and any(c in mode for c in "wax+")) or bool(flags & _WRITE_FLAGS)
            real = writable(path) if writing else None
            if real is not None:
                refuse(f"writes {real}")
        elif event in _PATH_EVENTS:
            for path in args[:_PATH_EVENTS[event]]:
                real = writable(path)
                if real is not None:
                    verb = "deletes" if event in ("os.remove", "os.rmdir", "shutil.rmtree") else f"changes ({event})"
                    refuse(f"{verb} {real}")
        elif event.startswith(_PROGRAM_EVENTS):
            refuse(f"starts a program ({event})")

    return hook


def _check_modules() -> list[str]:
    """``localize.check`` and every module its functions import (so that all are recorded before student code)."""
    import localize.check as check

    names = {"localize", "localize.check"}
    for node in ast.walk(ast.parse(Path(check.__file__).read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                names.add(f"localize.{node.module}")
            else:
                names.update(f"localize.{a.name}" for a in node.names)
    return sorted(names)


def _snapshot() -> dict[tuple[str, str], Any]:
    """Every attribute of the localize, numpy and math modules loaded now, and of the classes localize defines."""
    roots = ("localize", "numpy", "math", "builtins", "__main__")
    out: dict[tuple[str, str], Any] = {}
    for name, module in list(sys.modules.items()):
        if module is None or name.split(".")[0] not in roots:
            continue
        for attr, value in list(vars(module).items()):
            out[(name, attr)] = value
            if isinstance(value, type) and getattr(value, "__module__", "").startswith("localize"):
                for cattr, cvalue in list(vars(value).items()):
                    out[(f"{name}.{attr}", cattr)] = cvalue
    return out


def _changed(before: dict[tuple[str, str], Any]) -> list[str]:
    """What was replaced or deleted since ``before`` (attributes added since are not counted)."""
    now = _snapshot()
    return [f"replaces {owner}.{attr}" for (owner, attr), value in before.items()
            if now.get((owner, attr), _MISSING) is not value and not (owner, attr)[1].startswith("__")]


_MISSING = object()


def _is_check_cell(source: str) -> bool:
    """A cell that only calls ``check.NAME(...)`` (or prints it): the grader runs those checks itself."""
    try:
        body = ast.parse(source).body
    except SyntaxError:
        return False

    def is_check(node: ast.AST) -> bool:
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
            return len(node.args) == 1 and is_check(node.args[0])
        return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and isinstance(node.func.value, ast.Name) and node.func.value.id == "check")

    return bool(body) and all(isinstance(n, ast.Expr) and is_check(n.value) for n in body)


def _cells(notebook: Path) -> list[str]:
    nb = json.loads(notebook.read_text(encoding="utf-8"))
    out = []
    for cell in nb.get("cells", []):
        if cell.get("cell_type") == "code":
            src = cell.get("source", "")
            out.append("".join(src) if isinstance(src, list) else str(src))
    return out


def _strip_magics(source: str) -> str:
    """IPython magics and shell lines (``%...``, ``!...``) are not Python: comment them out."""
    return "\n".join(f"# {line}" if line.lstrip().startswith(("%", "!")) else line for line in source.splitlines())


def _run_cells(cells: list[str], ns: dict, limit: float, emit: Callable[[dict], None]) -> None:
    def on_alarm(signum, frame):  # noqa: ARG001
        raise _CellTimeout

    for k, source in enumerate(cells):
        if not source.strip() or _is_check_cell(source):
            continue
        try:
            code = compile(_strip_magics(source), f"<code cell {k + 1}>", "exec")
        except SyntaxError as err:
            emit({"kind": "cell", "cell": k + 1, "error": f"SyntaxError: {err.msg} (line {err.lineno})"})
            continue
        signal.signal(signal.SIGALRM, on_alarm)
        signal.setitimer(signal.ITIMER_REAL, limit)
        try:
            exec(code, ns)
        except _CellTimeout:
            emit({"kind": "cell", "cell": k + 1, "error": f"ran longer than {limit:g} s and was stopped"})
        except BaseException as err:  # noqa: BLE001 - a student's error (SystemExit included) is a finding
            emit({"kind": "cell", "cell": k + 1, "error": f"{type(err).__name__}: {err}"[:300]})
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)


def _grade_task(task: dict, ns: dict, before: dict, found: list[str]) -> dict:
    """Run one check on the student's function (in the forked child)."""
    from localize import check

    name = task["function"]
    out = {"kind": "task", "function": name, "passed": False, "report": "", "hint": ""}
    fn = ns.get(name)
    if not callable(fn):
        out["report"] = f"{name}: not graded: the notebook defines no function {name}"
        out["hint"] = f"define {name} with the name and arguments the notebook gives it"
        return out
    try:
        report = getattr(check, task["check"])(fn, **task.get("kwargs", {}))
        out.update(passed=bool(report), report=str(report), hint=(report.hints or [""])[0])
    except BaseException as err:  # noqa: BLE001 - a check that cannot finish is a failed task, with the reason
        out["report"] = f"{name}: the check stopped: {type(err).__name__}: {err}"[:500]
        out["hint"] = "run the check in your notebook and read its report"
    tampered = found + _changed(before)
    if tampered:
        out.update(passed=False, tamper=tampered)
    return out


def _fork_task(task: dict, ns: dict, before: dict, found: list[str], limit: float) -> dict:
    """Grade one task in a child process; a child that runs too long is killed, one that dies is reported."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: grade, send one JSON line, leave without running any cleanup of the parent's
        os.close(read)
        try:
            result = _grade_task(task, ns, before, found)
        except BaseException as err:  # noqa: BLE001
            result = {"kind": "task", "function": task["function"], "passed": False,
                      "report": f"grading failed: {type(err).__name__}: {err}", "hint": ""}
        with os.fdopen(write, "w") as pipe:
            pipe.write(json.dumps(result))
        os._exit(0)
    os.close(write)
    chunks, deadline = [], time.monotonic() + limit
    with os.fdopen(read, "rb") as pipe:
        while True:
            left = deadline - time.monotonic()
            ready = select.select([pipe], [], [], max(left, 0.0))[0] if left > 0 else []
            if not ready:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return {"kind": "task", "function": task["function"], "passed": False, "timeout": True,
                        "report": f"{task['function']}: stopped after {limit:g} s (an endless loop?)",
                        "hint": f"ran longer than {limit:g} s: look for a loop that never ends"}
            chunk = os.read(pipe.fileno(), 1 << 16)
            if not chunk:
                break
            chunks.append(chunk)
    _, status = os.waitpid(pid, 0)
    try:
        return json.loads(b"".join(chunks).decode())
    except ValueError:
        why = (f"killed by {signal.Signals(-os.waitstatus_to_exitcode(status)).name}"
               if os.WIFSIGNALED(status) else f"exit code {os.waitstatus_to_exitcode(status)}")
        return {"kind": "task", "function": task["function"], "passed": False, "crashed": True,
                "report": f"{task['function']}: the process grading it died ({why})",
                "hint": f"crashed the Python process ({why}): over the memory limit?"}


def main(work: str) -> None:
    """Grade the submission in the scratch folder ``work`` (see the module's docstring)."""
    work = os.path.realpath(work)
    grader = os.path.join(work, ".grader")
    job = json.loads(Path(grader, "job.json").read_text())
    result = open(job["result"], "a", buffering=1)  # noqa: SIM115 - opened before any student code, kept open

    def emit(record: dict) -> None:
        result.write(json.dumps(record) + "\n")

    sys.dont_write_bytecode = True
    for name in _check_modules():
        importlib.import_module(name)
    before = _snapshot()
    found: list[str] = []
    sys.addaudithook(_audit_hook(work, os.path.realpath(grader), tuple(job["forbidden"]), found))
    ns: dict = {"__name__": "__main__"}
    try:
        cells = _cells(Path(work, job["notebook"]))
    except (ValueError, OSError, AttributeError, TypeError) as err:
        emit({"kind": "notebook", "error": f"not a readable notebook: {type(err).__name__}: {err}"[:300]})
        cells = []
    try:
        _run_cells(cells, ns, job["cell_limit"], emit)
    except BaseException:  # noqa: BLE001 - never expected; recorded so that the teacher sees it
        emit({"kind": "notebook", "error": "grading stopped: " + traceback.format_exc(limit=3)[-300:]})
    tampered = found + _changed(before)
    if tampered:
        emit({"kind": "tamper", "why": tampered})
    else:
        for task in job["tasks"]:
            record = _fork_task(task, ns, before, found, job["task_limit"])
            emit(record)
            if record.get("tamper"):
                emit({"kind": "tamper", "why": record["tamper"]})
                break
    emit({"kind": "done"})
    result.close()
    sys.stdout.flush()
    os._exit(0)  # no atexit handler or finaliser a submission registered runs after the grade is written
