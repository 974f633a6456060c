"""Errors of the co-simulation master, and how outside text is shown in a message (:func:`printable`).

:class:`CosimError` is the master's one root: every class here derives from it and from the builtin that
matches its meaning, so callers can catch either. A domain plugged into the master (the delta robot:
:mod:`cosim.robot`) keeps its own error root; the master shows those errors as one line too
(:data:`domain_errors`, which plugins extend through :mod:`cosim.engine.plugins`).
"""

from __future__ import annotations

import argparse
import errno
import math
import os
import re
import signal
import stat
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator


class CosimError(Exception):
    """Root of every error the master raises. ``exit_kind``: what :func:`exit_status` calls it (``"error"``;
    a domain's error class may say ``"unreachable"``, for a pose out of the workspace)."""

    exit_kind = "error"


domain_errors: list[type[BaseException]] = []
"""The error roots of the domains plugged in (:mod:`cosim.engine.plugins` appends them): errors of bad input shown
as one line, as a :class:`CosimError` is."""


def user_errors() -> tuple[type[BaseException], ...]:
    """The classes of the errors a command ends on with one line: :class:`CosimError` and the domains' roots."""
    return (CosimError, *domain_errors)


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def printable(text: str) -> str:
    """Text from outside (an FMU's log, a name or description in its modelDescription.xml) as it may reach a
    terminal or a log: control characters (escape sequences that clear the screen or retitle the window, line
    breaks that fake a traceback) written as their escapes (``\\x1b``, ``\\n``), tabs as spaces."""
    return _CONTROL.sub(lambda m: " " if m.group() == "\t" else repr(m.group())[1:-1], text)


SHOWN_CHARS = 120
"""Characters of a value given from outside (the command line, a file) that a message repeats (the rest is counted,
not echoed)."""


def shown(text: str) -> str:
    """``text`` as a message repeats it: whole up to :data:`SHOWN_CHARS`, else its start and its length."""
    return text if len(text) <= SHOWN_CHARS else f"{text[:SHOWN_CHARS]}... ({len(text)} characters)"


def utf8(value):  # noqa: ANN001, ANN201 - str, or containers of them
    """``value`` (a str, or a list, tuple or dict of them) as text any UTF-8 writer takes: under a locale that is not
    UTF-8 (``LC_ALL=C`` with Python's UTF-8 mode off) a non-ASCII file name or argument reaches Python as surrogate
    escapes of its bytes, which JSON, MCAP and the terminal refuse; its UTF-8 bytes are read as UTF-8 again (``ü``
    stays ``ü``), any other byte is replaced. Paths kept for the file system stay as they came."""
    if isinstance(value, str):
        return value.encode("utf-8", "surrogateescape").decode("utf-8", "replace")
    if isinstance(value, dict):
        return {utf8(k): utf8(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(utf8(v) for v in value)
    return value


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, *((signal.SIGHUP,) if hasattr(signal, "SIGHUP") else ()))
"""The signals that stop a run cleanly (Ctrl-C, a termination request, a closed terminal): the master finishes the
log and stops its processes; those processes ignore them (they reach the whole process group)."""

__all__ = [
    "CosimError",
    "domain_errors",
    "user_errors",
    "printable",
    "shown",
    "SHOWN_CHARS",
    "utf8",
    "SettingError",
    "Issue",
    "ScenarioError",
    "WiringError",
    "FMIError",
    "AlgebraicLoopError",
    "PreflightError",
    "ComponentSourceError",
    "Interrupted",
    "StallError",
    "number_option",
    "file_problem",
    "written_by_rename",
    "UnknownSignalError",
    "EXIT_BAD_INPUT",
    "exit_status",
    "exit_text",
    "exit_now",
]

EXIT_BAD_INPUT = 2  # the exit code of a command that ends on an error (bad input, a failed run)


@dataclass(frozen=True)
class Issue:
    """One problem found in a scenario: where (file, line, dotted path) and what."""

    path: str  # dotted location in the scenario, e.g. "components.ctl.parameters.gain.kp[1]"
    message: str
    file: str | None = None
    line: int | None = None

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}: " if self.file and self.line else (f"{self.file}: " if self.file else "")
        path = f"{self.path}: " if self.path else ""
        return f"{where}{path}{self.message}"


class ScenarioError(CosimError, ValueError):
    """A scenario is invalid. Holds every issue found, one per line of the message."""

    def __init__(self, issues: list[Issue] | Issue | str):
        if isinstance(issues, str):
            issues = [Issue("", issues)]
        elif isinstance(issues, Issue):
            issues = [issues]
        self.issues: list[Issue] = list(issues)
        super().__init__("\n".join(str(i) for i in self.issues))


class WiringError(ScenarioError):
    """A connection names a missing variable or joins incompatible ends (kept apart for tests)."""


class ComponentSourceError(ScenarioError):
    """A component's FMU cannot be found or built."""


class SettingError(CosimError, ValueError):
    """A setting of the master (a solver's name, an option's value) is not one it accepts."""


class UnknownSignalError(CosimError, KeyError):
    """A signal or variable name that the run, log or system does not have; the message says which
    (with close matches)."""

    def __str__(self) -> str:  # the message as written, not KeyError's repr of it
        return str(self.args[0]) if self.args else ""


class PreflightError(CosimError, ValueError):
    """The pre-flight check failed (e.g. the trajectory leaves the workspace)."""


class AlgebraicLoopError(ScenarioError):
    """Direct-feedthrough connections form a cycle; the message lists the variables in it."""

    def __init__(self, loop: list[str], remedy: str = ""):
        self.loop = list(loop)
        super().__init__(
            [Issue("connections", "algebraic loop through direct feedthrough: " + " -> ".join(self.loop)
                   + "; break it with a component that has no direct feedthrough" + (f" or {remedy}" if remedy else ""))]
        )


_STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")


class FMIError(CosimError, RuntimeError):
    """An FMI call returned a failing status (or the FMU raised).

    Names the component, the FMI function, the simulation time and the status.
    """

    def __init__(self, component: str, function: str, time: float, status: int | None = None,
                 detail: str = ""):
        self.component = component
        self.function = function
        self.time = time
        self.status = status
        label = "" if status is None else (
            f" returned {_STATUS[status] if 0 <= status < len(_STATUS) else status}")
        detail = _without_time(detail, time)
        tail = f": {detail}" if detail else ""
        super().__init__(f"component {component!r}: {function}{label} at t = {time:.6g} s{tail}")


_SAID_TIME = re.compile(r"(^|: )(\S+ at )?t = ([-+0-9.eE]+) s: ")


def _without_time(detail: str, time: float) -> str:
    """An FMU's message without the time it says (``t = 0 s: ...`` as our native FMUs log, ``NAME at t = 0 s: ...`` as
    our python FMUs do; at its start or after the master's ``the FMU rejected the step:``) when that is the time the
    error is said at already; a message of another time keeps it."""
    m = _SAID_TIME.search(detail)
    if m is None:
        return detail
    try:
        said = float(m.group(3))
    except ValueError:
        return detail
    if not (said == time or abs(said - time) <= 1e-9 * max(1.0, abs(time))):
        return detail
    who = f"{m.group(2)[:-len(' at ')]}: " if m.group(2) else ""
    return detail[:m.start()] + m.group(1) + who + detail[m.end():]


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal (SIGINT, SIGTERM, SIGHUP); the exit code is 128 + ``signum``."""

    def __init__(self, signum: int, detail: str = ""):
        self.signum = signum
        self.detail = detail
        name = signal.Signals(signum).name
        super().__init__(f"stopped by {name}{': ' + detail if detail else ''}")


class StallError(CosimError, TimeoutError):
    """A component made no progress within the wall-clock budget of one step (``watchdog_s``)."""

    outcome = "stalled"  # the log's outcome status

    def __init__(self, component: str, time: float, budget: float, where: str = ""):
        self.component = component
        self.time = time
        self.budget = budget
        super().__init__(f"component {component!r}{where}: no progress for {budget:g} s of wall-clock time in "
                         f"its step at t = {time:.6g} s (watchdog_s = {budget:g}); run stopped")


# --------------------------------------------------------------------------- how an error ends a process
# (the command line, the watchdog's hard exit, __main__ and the sweep's workers)

def exit_status(exc: BaseException) -> tuple[str, str, int]:
    """How an error ends a command: (its message, its kind: ``"unreachable"``, ``"error"`` or
    ``"interrupted"``, the exit code: 2, or 128 + the signal for an interruption).

    ``exc``: a CosimError, or a KeyboardInterrupt (Ctrl-C, or :class:`~cosim.errors.Interrupted`,
    which names its signal and what it stopped). The message is the ``error`` of ``--json``;
    :func:`exit_text` is its line(s) on stderr.
    """
    if isinstance(exc, KeyboardInterrupt):
        signum = getattr(exc, "signum", signal.SIGINT)
        detail = getattr(exc, "detail", "")
        return (f"interrupted ({signal.Signals(signum).name})" + (f": {detail}" if detail else ""), "interrupted",
                128 + signum)
    return str(exc), getattr(exc, "exit_kind", "error"), EXIT_BAD_INPUT


def exit_text(message: str, kind: str) -> str:
    """The stderr text of :func:`exit_status`'s ``message``: ``error: ...`` (a multi-line error below
    ``error:``, one issue a line), an interruption as it is; each line :func:`printable`, since a message may
    quote an FMU."""
    message = "\n".join(printable(line) for line in message.split("\n"))
    if kind == "interrupted":
        return message
    if kind == "error" and "\n" in message:
        return "error:\n" + message
    return f"error: {message}"


def exit_now(code: int) -> None:
    """Flush stdout and stderr (a closed stream or a broken pipe is passed over) and end the process
    with ``code`` at once: ``os._exit``, no interpreter finalization."""

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed or broken pipe: nothing more can be written
            pass
    os._exit(code)


# --------------------------------------------------------------------------- numbers given as options

def number_option(*, gt: float | None = None, ge: float | None = None, le: float | None = None,
                  whole: bool = False, nan: bool = False) -> Callable[[str], float]:
    """The argparse ``type`` of every numeric option of the command line (one rule for all of them): the text as a
    finite number (``whole``: an integer) within the bounds, else argparse's error naming the option, what is valid
    and what was given (exit 2). ``nan``: the text 'nan' is a value of its own (a quantity to be found)."""
    bounds = [f"> {gt:g}" if gt is not None else "", f">= {ge:g}" if ge is not None else "",
              f"<= {le:g}" if le is not None else ""]
    if ge is not None and le is not None:
        bounds = [f"in [{ge:g}, {le:g}]"]
    wanted = " ".join(["a whole number" if whole else "a finite number", *filter(None, bounds)])
    if nan:
        wanted += " (or nan)"

    def parse(text: str) -> float:
        x = int(text) if whole else float(text)  # not a number: argparse's "invalid float value: 'a'"
        if nan and x != x:
            return x
        if not math.isfinite(x) or (gt is not None and not x > gt) or (ge is not None and not x >= ge) or \
                (le is not None and not x <= le):
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {shown(repr(text))}")
        return x

    parse.__name__ = "int" if whole else "float"  # named in argparse's message for a text that is no number
    return parse


# --------------------------------------------------------------------------- files given as inputs

_KINDS = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def refused_by_system(exc: OSError, folder: str | os.PathLike) -> bool:
    """Whether ``exc`` is the system refusing to write into ``folder`` (a path in it named, or a full, read-only or
    over-quota disk), not a fault of what was being written: the remedy is another folder."""
    named = [Path(os.fsdecode(f)) for f in (exc.filename, exc.filename2) if f is not None]
    return any(f.is_relative_to(folder) for f in named) or exc.errno in (errno.ENOSPC, errno.EROFS, errno.EDQUOT)


def file_problem(path: str | os.PathLike, directory_ok: bool = False) -> str | None:
    """Why ``path`` cannot be read as an input file (None: it is a regular file, or with ``directory_ok`` a
    directory): missing, a directory, or a FIFO, a device or a socket, whose reading may block for ever (a FIFO
    nobody writes) or never end (``/dev/zero``). Every input file of a command is checked so before it is opened."""
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return "no such file"
    except OSError as exc:
        return f"cannot read it: {exc.strerror or exc}"
    if stat.S_ISDIR(st.st_mode):
        return None if directory_ok else "is a directory, not a file"
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _KINDS if test(st.st_mode)), "not a file")
        return f"not a regular file ({kind})"
    return None


@contextmanager
def written_by_rename(target: str | os.PathLike) -> Iterator[Path]:
    """A path beside ``target`` to write a whole output file to: renamed onto ``target`` when the block completes
    (atomically: the same folder), removed when it raises. ``target`` never holds a half-written file, and nothing
    is left beside it. The one way every command of ours writes a file that is not a run's log."""
    target = Path(target)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        yield tmp
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
