"""Output files written safely: checked first, claimed by one run, renamed into place when finished.

A run's log ``X.mcap`` is written as ``X.mcap.partial`` next to it and renamed to ``X.mcap``
only once it is finished, so ``X.mcap`` is always a complete file (or the previous run's).
An exclusive lock ``X.mcap.lock`` (``flock``, released by the kernel when its process ends,
however it ends) keeps two runs off one path: the second fails at once naming the first
(pid, start, command line). A ``.partial`` file without a live owner is what a killed run
left behind; it is never overwritten (recover it with ``python -m cosim recover``, or delete
it). :func:`claim` does all of this, including the writability check, before the run loads
a single FMU.
"""

from __future__ import annotations

import fcntl
import json
import os
import shlex
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from .. import procs
from ..engine import supervision
from ..errors import CosimError, printable

__all__ = ["OutputError", "OutputClaim", "check_output", "claim", "exclusive", "output_dir", "partial_path",
           "writable_parent"]


class OutputError(CosimError, OSError):
    """An output file cannot be written (directory, permission, lock held, disk full)."""


def partial_path(target: str | Path) -> Path:
    target = Path(target)
    return target.with_name(target.name + ".partial")


def writable_parent(target: Path) -> None:
    """Raise OutputError (one line) unless ``target``'s directory exists or can be made, and takes files, and
    ``target`` is a regular file or nothing (a finished log replaces it)."""
    if target.is_dir():
        raise OutputError(f"{target}: is a directory; give a file path for the output")
    if target.exists() and not target.is_file():  # a device, a pipe, a socket: never replaced by a log
        raise OutputError(f"{target}: is not a regular file (a device, pipe or socket); a log replaces only "
                          "regular files: give another --out")
    for parent in [target.parent, *target.parent.parents]:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{target}: cannot write the output: {parent} is a file, not a directory")
            break
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{target}: cannot create its directory {target.parent}: {exc.strerror}") from None


class OutputClaim:
    """The right to write ``target``: the held lock and the partial file the writer fills.

    ``state`` is what became of the log, set by the run that writes it: ``"none"`` (never
    started: nothing to keep), ``"finished"`` (complete, possibly marked as an error or an
    interruption), or why it could not be finished (kept as the partial file).
    """

    def __init__(self, target: Path, lock_fd: int, lock: Path):
        self.target = target
        self.partial = partial_path(target)
        self.state = "none"
        self._fd: int | None = lock_fd
        self._lock = lock

    def commit(self) -> Path:
        """The partial file becomes ``target`` (atomically, replacing an older one); the lock is released."""
        try:
            os.replace(self.partial, self.target)
        except OSError as exc:
            self.release()
            raise OutputError(f"{self.target}: cannot rename the finished log {self.partial} into place: "
                              f"{exc.strerror}") from None
        self.release()
        return self.target

    def discard(self) -> None:
        """Remove the partial file (nothing was written into it) and release the lock."""
        try:
            self.partial.unlink(missing_ok=True)
        finally:
            self.release()

    def release(self) -> None:
        """Release the lock, keeping whatever partial file there is; idempotent."""
        if self._fd is None:
            return
        try:
            self._lock.unlink(missing_ok=True)  # while still holding it: a waiting run re-checks the inode
        except OSError:
            pass
        procs.close_fd(self._fd)  # one a component closed behind our back: said by the run (intact)
        self._fd = None

    def intact(self) -> bool:
        """Whether the lock is still held: False when a component of the run closed its descriptor (and with it
        most likely the log writer's pipe)."""
        return self._fd is None or procs.open_fd(self._fd)


def _describe_owner(lock: Path) -> str:
    """Who holds ``lock``, from the one JSON line its owner wrote (a command line with a newline in a file name
    cannot forge a field of it, as it could the ``key=value`` lines written before)."""
    try:
        fields = json.loads(lock.read_text(encoding="utf-8", errors="replace") or "{}")
    except (OSError, ValueError):
        return "another run"
    if not isinstance(fields, dict):
        return "another run"
    pid, started, command = fields.get("pid"), fields.get("started"), fields.get("command")
    when = time.strftime("%H:%M:%S", time.localtime(started)) if isinstance(started, (int, float)) else "?"
    shown = printable(shlex.join(command)) if isinstance(command, list) and all(
        isinstance(a, str) for a in command) else "?"
    return f"another run (pid {pid if isinstance(pid, int) else '?'}, started {when}: {shown})"


def _take_lock(lock: Path, cannot: str, held: Callable[[str], str]) -> int:
    """The descriptor of ``lock``, created if need be and held (``flock``, not waiting); OutputError with ``cannot``
    and the system's reason when it cannot be opened, with ``held(who holds it)`` when another process holds it. A
    lock its owner removed between our open and our hold is taken again (the owner unlinks it while holding it)."""
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputError(f"{cannot}: {exc.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OutputError(held(_describe_owner(lock))) from None
        try:
            if os.stat(lock).st_ino == os.fstat(fd).st_ino:
                return fd
        except FileNotFoundError:  # its owner finished and removed it between our open and lock
            pass
        os.close(fd)


def _write_owner(fd: int) -> None:
    """This command as the lock's owner: one JSON line, any name escaped (and any locale)."""
    os.ftruncate(fd, 0)
    argv = ["python -m cosim" if sys.argv[0].endswith("__main__.py") else sys.argv[0], *sys.argv[1:]]
    owner = {"pid": supervision.command_pid(), "started": round(time.time(), 3), "command": argv}
    os.write(fd, (json.dumps(owner) + "\n").encode("ascii"))


@contextmanager
def exclusive(folder: Path, what: str) -> Iterator[None]:
    """Hold ``folder``'s ``.lock`` for the block: a second command writing into the same folder at once (two sweeps
    appending to one ``results.csv`` corrupted it) is refused with one line naming the first (:func:`_describe_owner`);
    the lock goes with the block, or with the process."""
    lock = folder / ".lock"
    fd = _take_lock(lock, f"{folder}: cannot write in it", lambda who: f"{folder}: "
                    f"{who.replace('another run', 'another command', 1)} is writing {what} there; wait for it to "
                    "end or choose another folder")
    try:
        _write_owner(fd)
        yield
    finally:
        try:
            lock.unlink(missing_ok=True)  # while still holding it
        except OSError:
            pass
        os.close(fd)


def output_dir(target: str | Path, option: str = "--out") -> Path:
    """``target`` as the folder a command writes its files in, made if need be; OutputError (one line) when it is a
    file, a device or a FIFO, or cannot be made (a report written 'into' a file was a FileExistsError traceback)."""
    target = Path(target)
    if os.path.lexists(target) and not target.is_dir():
        raise OutputError(f"{option} {target}: is a file, not a folder: give a folder to write into")
    for parent in target.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{option} {target}: cannot make the folder: {parent} is a file, not a folder")
            break
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {target}: cannot make the folder: {exc.strerror or exc}") from None
    return target


def check_output(target: Path, inputs: tuple[str | Path | None, ...] = ()) -> None:
    """Raise OutputError (one line) unless ``target`` can be written (:func:`writable_parent`) and is none of
    ``inputs`` (the files the command reads: an output written over one would replace it)."""
    writable_parent(target)
    for source in inputs:
        if source is not None and target.exists() and Path(source).exists() and os.path.samefile(target, source):
            raise OutputError(f"{target}: is this command's own input ({source}); writing it would replace it: "
                              "give another output path")


def claim(target: str | Path, inputs: tuple[str | Path | None, ...] = ()) -> OutputClaim:
    """Check that ``target`` can be written and claim it for this process (see the module docstring).

    Raises OutputError naming the problem: an unwritable directory, a parent that is a file, a
    run already writing ``target``, a partial file left by a run that did not finish, or ``target``
    being one of the run's ``inputs`` (its scenario or archive, which the log would replace).
    """

    # absolute from here on: an FMU that changes the working directory (chdir) must not move the log, its
    # partial file or its lock (issue 25)
    target = Path(target).absolute()
    check_output(target, inputs)
    lock = target.with_name(target.name + ".lock")
    fd = _take_lock(lock, f"{target}: cannot write in {target.parent}",
                    lambda who: f"{target}: {who} is writing it; wait for it to end or choose another --out")
    out = OutputClaim(target, fd, lock)
    partial = out.partial
    if partial.exists():
        out.release()
        raise OutputError(f"{partial}: left by a run that did not finish; recover it "
                          f"(python -m cosim recover {partial}) or delete it, then run again")
    try:
        _write_owner(fd)
        os.close(os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
    except OSError as exc:
        out.release()
        raise OutputError(f"{target}: cannot write in {target.parent}: {exc.strerror}") from None
    return out
