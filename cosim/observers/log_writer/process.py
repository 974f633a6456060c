"""The log's writer process: a :class:`~cosim.observers.log_writer.sink.LogSink` in a child process, fed through a
pipe (see :mod:`cosim.observers.log_writer`).

:class:`WriterProcess`: the sink's calls sent through a pipe to a :class:`LogSink` in a child process, so that
encoding, compressing and writing take the other core, not the master's loop. The child ignores Ctrl-C (the master
finishes the log); a master that dies closes the pipe, and the child then writes what it has (with the rows of the
:class:`RowMirror` a forked child shares) and exits, leaving the file unfinished (recoverable), as a killed writer in
the master would.
"""

from __future__ import annotations

import fcntl
import mmap
import os
import pickle
import struct
import sys
import threading
from pathlib import Path

from ... import procs
from ...errors import STOP_SIGNALS
from .mirror import RowMirror
from .sink import LogSink, os_reason

__all__ = ["WriterFailed", "WriterProcess", "live_view_serving", "main", "writer_forks"]

_FRAME = struct.Struct("<I")
_PIPE_BYTES = 1 << 20  # the pipe to the child holds about 1 MB (Linux): ~1700 steps of helix_ctc's rows
_SUCCESS = b"ok\n"


class WriterFailed(Exception):
    """The writer process reported a failure (its reason) or ended without one."""


class _Fork:
    """When the writer may be a fork of the master (:func:`writer_forks`): only when no other Python thread runs and
    no live view serves in this process (their threads would be missing in the child with whatever they held; the
    live view's recorder forks before the server starts); a thread of a native library (OpenBLAS' idle pool) is
    left behind harmlessly, as the child calls none of them."""

    serving = 0
    """Live views serving in this process (:class:`cosim.observers.live.LiveView` counts itself in and out)."""

    @classmethod
    def possible(cls) -> bool:
        return (hasattr(os, "fork") and sys.platform != "darwin" and threading.active_count() == 1
                and cls.serving == 0)


def writer_forks() -> bool:
    """Whether a :class:`WriterProcess` made now would be a fork of this process (it then starts at once)."""
    return _Fork.possible()


def live_view_serving(serving: bool) -> None:
    """A live view's server starts (True) or has stopped (False) in this process: no writer is forked meanwhile."""
    _Fork.serving += 1 if serving else -1


class WriterProcess:
    """A :class:`LogSink` in a child process: the same methods, sent through a pipe (see the module docstring).

    Start it early, then :meth:`open` the file. Every call raises :class:`WriterFailed` with the child's
    reason once the child has failed.

    The child is a fork of this process where that is safe (:func:`writer_forks`: POSIX but macOS, no other
    Python thread, no live view serving): it has every module it needs but foxglove, which it imports while
    the master loads its FMUs, and is ready in about 0.04 s. Elsewhere it is a new interpreter
    (``python -m cosim.observers.log_writer``), which takes about 0.1 s of a core to start: on a 10 s
    helix_ctc_analytic run of native FMUs (0.08 s unlogged) that start alone made the logged loop 1.3x longer.
    Either way it is started by :func:`cosim.procs.start`, in a session of its own (Ctrl-C and the supervisor's
    kill of the run's process group are the master's), ignoring the stop signals (the master finishes the log),
    with its standard streams as pipes to the master; a forked one closes every other descriptor it inherited
    (a live view's port, the log's claim, FMU files) and shares :attr:`RowMirror.BYTES` of memory with the master
    (the :class:`RowMirror`).
    """

    def __init__(self) -> None:
        self.forked = writer_forks()
        self._shared = mmap.mmap(-1, RowMirror.BYTES) if self.forked else None  # anonymous: shared across the fork
        rules = dict(name="log-writer", group="session", ignore=STOP_SIGNALS, pipes=True)
        if self.forked:
            self._proc = procs.start(_forked, self._shared, close_fds=True, **rules)
        else:
            self._proc = procs.start(None, how="exec", argv=[sys.executable, "-m", __package__], env=_exec_env(),
                                     **rules)
        self._fd = self._proc.stdin.fileno()
        try:
            fcntl.fcntl(self._fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
        except (ImportError, AttributeError, OSError):  # not Linux, or above this user's limit: the default works
            pass
        self.failure: str | None = None
        self.pid = self._proc.pid
        self._queue: list[bytes] = []
        self._queued = 0

    def _send(self, op: str, *args) -> None:
        """Queue a call; the queue goes down the pipe with the next block of samples (about one write
        per block: a write costs the master several us), on a flush, and at the end."""
        if self.failure is not None:
            raise WriterFailed(self.failure)
        payload = pickle.dumps((op, args), protocol=pickle.HIGHEST_PROTOCOL)
        self._queue += (_FRAME.pack(len(payload)), payload)
        self._queued += len(payload)
        if op in ("blocks", "flush", "finish") or self._queued > _PIPE_BYTES // 4:
            self._write()

    def _write(self) -> None:
        view = memoryview(b"".join(self._queue))
        self._queue.clear()
        self._queued = 0
        try:
            while view:
                view = view[os.write(self._fd, view):]
        except OSError:  # the child is gone (broken pipe): say why
            raise WriterFailed(self._reason()) from None

    def _reason(self, out: bytes | None = None) -> str:
        if self._proc.wait(10) is None:
            self._proc.kill()
            self._proc.wait()
        out = (self._proc.stdout.read() if out is None else out).decode(errors="replace").strip()
        err = self._proc.stderr.read().decode(errors="replace").strip()
        lines = [ln for ln in out.splitlines() if ln.startswith("error: ")]
        self.failure = lines[-1][len("error: "):] if lines else (
            f"the writer process ended (exit status {self._proc.returncode})"
            + (f": {err.splitlines()[-1]}" if err else ""))
        return self.failure

    def open(self, path: str | Path, chunk_size: int, zstd_level: int) -> None:
        self._send("open", str(path), chunk_size, zstd_level)

    def mirror(self, sections: list, offset_ns: int) -> RowMirror | None:
        """A :class:`RowMirror` of the run's batches of rows (``sections``: per batch ``(parts, width, cap)``, see
        there; ``offset_ns``: the publisher's log-time offset), or None when this writer shares no memory with the
        master (a new interpreter), there are no rows, or they do not fit (:meth:`RowMirror.fits`)."""
        if self._shared is None or not sections or not RowMirror.fits(sections):
            return None
        self._send("mirror", [(list(parts), width, cap) for parts, width, cap in sections], offset_ns)
        return RowMirror(self._shared, sections)

    def channel(self, *args) -> None:
        self._send("channel", *args)

    def blocks(self, *args) -> None:
        self._send("blocks", *args)

    def message(self, *args) -> None:
        self._send("message", *args)

    def metadata(self, *args) -> None:
        self._send("metadata", *args)

    def attachment(self, *args) -> None:
        self._send("attachment", *args)

    def flush(self) -> None:
        self._send("flush")

    def finish(self, timeout: float = 120.0) -> None:
        """Finish the file and wait for the child to end; raises WriterFailed when it could not."""
        self._send("finish")
        self._close_pipe()
        if self._proc.wait(timeout) is None:
            self._proc.kill()
            self._proc.wait()
            raise WriterFailed(f"the writer process did not finish the file within {timeout:g} s")
        out = self._proc.stdout.read()
        if self._proc.returncode != 0 or not out.endswith(_SUCCESS):
            raise WriterFailed(self._reason(out))

    def abandon(self) -> None:
        """Leave the file unfinished (its chunks written) and let the child end."""
        self._close_pipe()
        if self._proc.wait(30) is None:
            self._proc.kill()
            self._proc.wait()

    def _close_pipe(self) -> None:
        try:
            self._proc.stdin.close()
        except OSError:
            pass


def _read_exactly(stream, n: int) -> bytes | None:
    data = stream.read(n)
    if len(data) < n:
        return None
    return data


def _serve(inp, out, shared=None) -> int:
    """The child's loop: calls from the master until ``finish`` (exit 0, ``ok``) or the end of the pipe
    (the master died: the file is left unfinished). A failure is one line ``error: reason``, exit 1.

    ``shared``: the memory a forked child shares with its master (:class:`RowMirror`); when the master dies, the
    rows it had not sent yet are read from there and written too (per channel, those later than its last block
    received), so the log reaches the last step each component completed."""
    sink: LogSink | None = None
    mirror = None  # the sections the master declared (op "mirror") and its log-time offset
    last: dict[int, int] = {}  # with a mirror: per channel, the last stamp received through the pipe
    try:
        while True:
            head = _read_exactly(inp, _FRAME.size)
            payload = None if head is None else _read_exactly(inp, _FRAME.unpack(head)[0])
            if payload is None:  # the master is gone: leave the file unfinished, as a killed writer would
                if sink is not None:
                    if shared is not None and mirror is not None:
                        blocks = RowMirror.unsent(shared, mirror[0], last)
                        if blocks:
                            sink.blocks(mirror[1], blocks)
                    sink.flush()
                os._exit(0)  # now, the writer still referenced: collecting it would finish the file
            op, args = pickle.loads(payload)
            if op == "open":
                sink = LogSink(*args)
            elif op == "finish":
                sink.finish()
                out.write(_SUCCESS)
                out.flush()
                return 0
            elif op == "mirror":
                mirror = args
            else:
                if op == "blocks" and mirror is not None:
                    for cid, stamps, _, _ in args[1]:
                        if stamps:
                            last[cid] = stamps[-1]
                getattr(sink, op)(*args)
    except OSError as exc:
        out.write(f"error: {os_reason(exc)}\n".encode())
        out.flush()
        return 1


def _forked(shared: mmap.mmap) -> int:
    """The forked writer's life (its pipes are its standard streams): foxglove imported, then :func:`_serve`."""
    import foxglove  # noqa: F401  # lazy: the master's --help loads this module without it

    return _serve(os.fdopen(0, "rb"), os.fdopen(1, "wb", buffering=0), shared)


def _exec_env() -> dict[str, str]:
    """The environment of a new interpreter's writer: this one's, with the folder holding the cosim package first on
    its path."""
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[3])
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def main() -> int:
    """The new interpreter's writer (``python -m cosim.observers.log_writer``): the rules it was started with
    (:func:`cosim.procs.entered`: the stop signals ignored, the master finishes the log), then :func:`_serve`."""
    procs.entered()
    return _serve(sys.stdin.buffer, sys.stdout.buffer)
