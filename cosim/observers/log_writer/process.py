"""The run log's writer: component samples encoded as JSON messages and written to MCAP (by
foxglove-sdk's MCAP writer), in this process or in a writer process on another core.

:class:`cosim.observers.publish.Publisher` hands its sinks each component channel's samples in blocks: the
stamps and the *rows* (the bytes of the logged values as the FMU buffers hold them, one row per
sample); every other message (scene, transforms, events) comes encoded. Here:

- :class:`BlockLayout`, :func:`encode_samples` and :func:`encode_block`: a block of samples becomes
  the channel's messages in its layout. ``samples`` (the default): one message per sample,
  ``{"t": s, "<variable>": value, ...}``, what Foxglove and PlotJuggler plot as time series;
  ``blocks``: one message per block, ``{"t": [...], "<variable>": [...], ...}`` (one array element
  per sample), the cheapest to write. Either way one ``struct`` call reads the rows and orjson
  writes the numbers;
- :class:`LogSink`: one log file fed by the publisher's calls (``channel``, ``blocks``, ``message``)
  and the recorder's (``metadata``, ``attachment``, ``flush``, ``finish``, ``abandon``), written by
  foxglove-sdk's MCAP writer (zstd chunks, indexes, summary). A file never finished has every
  chunk flushed so far and no summary: ``cosim recover`` reads it;
- :class:`WriterProcess`: the same calls sent through a pipe to a :class:`LogSink` in a child
  process (``python -m cosim.observers.log_writer``), so that encoding, compressing and writing take the
  other core, not the master's loop. The child ignores Ctrl-C (the master finishes the log); a
  master that dies closes the pipe, and the child then writes what it has and exits, leaving the
  file unfinished (recoverable), as a killed writer in the master would.

The child needs no numpy or fmpy (rows are read with :mod:`struct`): this module imports neither, so an exec'd
child starts in about 0.1 s, a forked one (see :class:`WriterProcess`) at once.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import logging
import mmap
import os
import pickle
import re
import signal
import struct
import subprocess
import sys
import threading
import time
import traceback
import warnings
from dataclasses import dataclass, field
from functools import partial
from itertools import accumulate, repeat
from pathlib import Path
from typing import Any

import orjson

from ...cbuild import Library
from ...errors import STOP_SIGNALS

__all__ = ["BlockLayout", "FoxgloveChannels", "encode_block", "encode_messages", "encode_samples", "row_format",
           "samples_helper",
           "LogSink", "RowMirror", "WriterProcess", "WriterFailed", "live_view_serving", "writer_forks"]


# --------------------------------------------------------------------------- block messages


def row_format(ctype: Any, count: int) -> str:
    """The :mod:`struct` code of ``count`` elements of a ctypes number type (standard sizes, native order)."""
    if ctype is ctypes.c_bool:
        return f"{count}?"
    if ctype in (ctypes.c_double, ctypes.c_float):
        return f"{count}{'d' if ctypes.sizeof(ctype) == 8 else 'f'}"
    signed = ctype._type_ in "bhilq"
    code = {1: "b", 2: "h", 4: "i", 8: "q"}[ctypes.sizeof(ctype)]
    return f"{count}{code if signed else code.upper()}"


@dataclass(frozen=True)
class BlockLayout:
    """How a component channel's samples become its messages (see :mod:`cosim.observers.publish`).

    ``keys``: the JSON keys of the logged variables (``"t"`` comes first, not listed).
    ``fmt``: the :mod:`struct` format (``=``, no padding) of one sample's raw values, the row; None
    when each sample comes as a list of values instead (strings, binaries). ``columns``: per key
    ``(first element in the row, element count or 0 for a scalar, FMI 2 Boolean)``: a C int
    written ``true``/``false``. ``per_sample``: the channel's layout is ``samples`` (one message per
    sample, :func:`encode_samples`), else ``blocks`` (one per block, :func:`encode_block`).
    """

    keys: tuple[str, ...]
    fmt: str | None = None
    columns: tuple[tuple[int, int, bool], ...] = ()
    per_sample: bool = False
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def rows_struct(self, n: int, skip: tuple[int, int] | None = None) -> struct.Struct:
        """The struct of ``n`` rows, each between ``skip`` = (bytes before, bytes after) of other
        channels' values (cached: blocks come in a few sizes)."""
        found = self._cache.get((n, skip))
        if found is None:
            if len(self._cache) > 64:
                self._cache.clear()
            row = self.fmt if skip is None else f"{skip[0]}x{self.fmt}{skip[1]}x"
            found = self._cache[(n, skip)] = struct.Struct("=" + row * n)
        return found

    def joints(self) -> list[bytes]:
        """The bytes around a sample message's values (``fmt`` given): before ``t``, between ``t`` and
        the row's first value, between consecutive values, after the last one, so that
        ``{"t":T,"a":A,"b":[B1,B2]}`` is these parts and the values ``T, A, B1, B2`` taken in turn."""
        found = self._cache.get("joints")
        if found is None:
            found, closing = [b'{"t":'], b""  # closing: the bracket of an array just ended
            for key, (_, count, _) in zip(self.keys, self.columns):
                name = closing + b"," + orjson.dumps(key) + b":"
                found += [name] if count == 0 else [name + b"["] + [b","] * (count - 1)
                closing = b"]" if count else b""
            found.append(closing + b"}")
            self._cache["joints"] = found
        return found

    def fmi2_elements(self) -> frozenset[int]:
        """The row's elements that are FMI 2 Booleans (C ints written ``true``/``false``)."""
        found = self._cache.get("fmi2")
        if found is None:
            found = self._cache["fmi2"] = frozenset(e for at, count, fmi2_bool in self.columns if fmi2_bool
                                                    for e in range(at, at + max(count, 1)))
        return found

    def c_joints(self) -> tuple[bytes, Any, bytes]:
        """:meth:`joints` as ``cosim_samples`` takes them (see samples.c): back to back, the end of each
        (a ``size_t`` array), and a byte per element of the row, 1 for an FMI 2 Boolean."""
        found = self._cache.get("c_joints")
        if found is None:
            joints = self.joints()
            ends = (ctypes.c_size_t * len(joints))(*accumulate(map(len, joints)))
            fmi2 = self.fmi2_elements()
            found = self._cache["c_joints"] = (b"".join(joints), ends,
                                               bytes(e in fmi2 for e in range(len(joints) - 2)))
        return found

    def __getstate__(self):  # the cache stays behind (Structs do not pickle)
        return (self.keys, self.fmt, self.columns, self.per_sample)

    def __setstate__(self, state) -> None:
        for name, value in zip(("keys", "fmt", "columns", "per_sample"), state):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "_cache", {})


def encode_samples(layout: BlockLayout, stamps: list[int], data: bytes | list,
                   skip: tuple[int, int] | None = None) -> list[bytes]:
    """One message per sample at ``stamps`` (simulation ns): ``{"t": s, "<key>": value, ...}``, byte for byte
    what ``orjson.dumps`` writes of that dict (the messages of logs written before blocks).

    ``data`` and ``skip`` as in :func:`encode_block`. With a row format, the numbers of the whole block
    are written by orjson, two calls (the times, the values), and joined with the keys
    (:meth:`BlockLayout.joints`) between them: by ``cosim_samples`` (``samples.c``, :func:`samples_helper`), one
    pass in C over orjson's output, else cut at their commas (a number, ``true``, ``false`` or ``null``
    has none) and joined in Python. No dict and no Python loop per sample either way.
    """
    times = [s * 1e-9 for s in stamps]
    if layout.fmt is None:
        keys = ("t", *layout.keys)
        return [orjson.dumps(dict(zip(keys, (t, *values)))) for t, values in zip(times, data)]
    n = len(stamps)
    flat = layout.rows_struct(n, skip).unpack(data)
    join = _samples_helper()
    if join is None:
        return _samples_py(layout, times, flat, n)
    t_json, v_json = orjson.dumps(times), orjson.dumps(flat)
    joints, ends, fmi2 = layout.c_joints()
    width = len(flat) // n
    with _OUT_LOCK:  # the live view's thread and an in-process log share the buffer
        out = _out_buffer(len(t_json) + len(v_json) + n * (ends[-1] + 1 + 4 * width))
        size = join(t_json, len(t_json), v_json, len(v_json), n, width, joints, ends, fmi2, out)
        if size < 0:
            raise ValueError(f"cosim_samples: {n} samples of {width} values do not match orjson's output")
        return ctypes.string_at(out, size).split(b"\n")


_SAMPLES = Library(Path(__file__).resolve().parents[1] / "samples.c")
_SAMPLES_HELPER: list = []  # [cosim_samples, or None without a C compiler], looked for once per process
_OUT: list = [ctypes.create_string_buffer(1 << 16)]  # the join's output, grown as needed, reused
_OUT_LOCK = threading.Lock()


def _out_buffer(size: int):
    """A buffer of at least ``size`` bytes for ``cosim_samples``, reused from call to call (making one costs
    more than the join itself)."""
    if len(_OUT[0]) < size:
        _OUT[0] = ctypes.create_string_buffer(max(size, 2 * len(_OUT[0])))
    return _OUT[0]


def samples_helper():
    """The compiled ``cosim_samples`` (``samples.c``) with its argument and result types, or None when it cannot
    be built here (``_SAMPLES.reason`` says why)."""
    lib = _SAMPLES.get()
    if lib is None:
        return None
    f = lib.cosim_samples
    if f.restype is not ctypes.c_ssize_t:
        f.restype = ctypes.c_ssize_t
        f.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_size_t,
                      ctypes.c_size_t, ctypes.c_char_p, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]
    return f


def _samples_helper():
    if not _SAMPLES_HELPER:
        _SAMPLES_HELPER.append(samples_helper())
    return _SAMPLES_HELPER[0]


def _samples_py(layout: BlockLayout, times: list[float], flat: tuple, n: int) -> list[bytes]:
    """:func:`encode_samples`'s messages without the C helper: orjson's numbers cut at their commas, one list
    of them per element of the row, joined with the keys sample by sample."""
    width = len(flat) // n
    values = orjson.dumps(flat)[1:-1].split(b",")
    joints = layout.joints()
    columns = [repeat(joints[0], n), orjson.dumps(times)[1:-1].split(b",")]
    fmi2 = layout.fmi2_elements()
    for e in range(width):
        column = values[e::width]
        if e in fmi2:  # a C int: 0 is false, anything else true
            column = [b"false" if v == b"0" else b"true" for v in column]
        columns += (repeat(joints[e + 1], n), column)
    columns.append(repeat(joints[-1], n))
    return list(map(b"".join, zip(*columns)))


def encode_block(layout: BlockLayout, stamps: list[int], data: bytes | list,
                 skip: tuple[int, int] | None = None) -> bytes:
    """The block message of samples at ``stamps`` (simulation ns): ``{"t": [s, ...], "<key>": [value, ...]}``.

    ``data``: the rows (``len(stamps)`` of ``layout.fmt``, each between ``skip`` = (bytes before,
    bytes after) of other channels' values when the rows of several channels come together) or,
    without a format, one list of values per sample. An array variable's values are lists (one per
    sample). Numbers are orjson's (NaN and infinities as null), as in the per-sample messages of
    earlier logs.
    """
    msg: dict[str, Any] = {"t": [s * 1e-9 for s in stamps]}
    if layout.fmt is None:
        for key, column in zip(layout.keys, zip(*data)):
            msg[key] = column
        return orjson.dumps(msg)
    n = len(stamps)
    flat = layout.rows_struct(n, skip).unpack(data)
    width = len(flat) // n
    for key, (at, count, fmi2_bool) in zip(layout.keys, layout.columns):
        if count == 0:
            column = flat[at::width]
            msg[key] = [v != 0 for v in column] if fmi2_bool else column
        else:
            elements = [flat[at + e::width] for e in range(count)]
            if fmi2_bool:
                elements = [[v != 0 for v in el] for el in elements]
            msg[key] = list(zip(*elements))
    return orjson.dumps(msg)


def encode_messages(layout: BlockLayout, stamps: list[int], data: bytes | list, skip: tuple[int, int] | None,
                    offset_ns: int) -> tuple[list[int], list[bytes]]:
    """(log times, messages) of a block of samples in its channel's layout: one message per sample logged at
    its stamp + ``offset_ns`` (``samples``), or one logged at its last stamp + ``offset_ns`` (``blocks``)."""
    if layout.per_sample:
        return [s + offset_ns for s in stamps], encode_samples(layout, stamps, data, skip)
    return [stamps[-1] + offset_ns], [encode_block(layout, stamps, data, skip)]


# --------------------------------------------------------------------------- a log file fed by the publisher


WRITER_LOGGER = "foxglove.log_sink_set"
"""The logger under which foxglove-sdk reports a message its MCAP writer could not write (measured with 0.30:
``error logging message: McapError(Io(Os { code: 28, ...``); its WebSocket server logs under
``foxglove.websocket.server``."""


class _WriteFailures(logging.Handler):
    """foxglove-sdk's MCAP writer reports a failed write through Python logging (a warning of its
    ``foxglove.*`` loggers, one per lost message) instead of raising. While a sink is open, one
    handler counts them and keeps the OS's reason, and none is printed (a full disk would print a
    line per message). The loggers do not say which file failed: a sink that sees the count grow
    asks its own writer (:meth:`LogSink._check`)."""

    LOGGERS = ("foxglove", "foxglove_py")  # the SDK's Rust side logs under both
    _lock = threading.Lock()
    _handler: "_WriteFailures | None" = None
    _users = 0
    _propagate: list[bool] = []

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.count = 0
        self.reason: str | None = None

    @classmethod
    def attach(cls) -> "_WriteFailures":
        """The handler, on the loggers while any sink uses it (:meth:`detach`)."""
        with cls._lock:
            if cls._users == 0:
                cls._handler = cls()
                cls._propagate = []
                for name in cls.LOGGERS:
                    lg = logging.getLogger(name)
                    cls._propagate.append(lg.propagate)
                    lg.addHandler(cls._handler)
                    lg.propagate = False
            cls._users += 1
            return cls._handler

    @classmethod
    def detach(cls) -> None:
        with cls._lock:
            cls._users -= 1
            if cls._users == 0:
                for name, propagate in zip(cls.LOGGERS, cls._propagate):
                    lg = logging.getLogger(name)
                    lg.removeHandler(cls._handler)
                    lg.propagate = propagate
                cls._handler = None

    def emit(self, record: logging.LogRecord) -> None:
        text = record.getMessage()
        if record.name != WRITER_LOGGER and "McapError" not in text:
            return  # not the file's: e.g. the live view's server dropping a client (a port probe, a bad handshake)
        self.count += 1
        if self.reason is None or "Os {" in text:  # the OS's error, not "a write after a failed one"
            self.reason = text


def _os_error(text: str) -> OSError:
    """The OSError a foxglove-sdk failure text names (``Os { code: 28, ... message: "No space left on
    device" }``), else one carrying the text."""

    m = re.search(r"code: (\d+)", text)
    if m:
        code = int(m.group(1))
        return OSError(code, os.strerror(code))
    return OSError(text)


class FoxgloveChannels:
    """The publisher's channels (by its channel ids) on one foxglove-sdk context: what a log file (:class:`LogSink`)
    and the live view (:mod:`cosim.observers.live`) have in common. Users set ``_context``, ``_channels`` (list), ``_log``
    and ``_layouts`` (dicts)."""

    _context: Any
    _channels: list
    _log: dict
    _layouts: dict

    def channel(self, cid: int, topic: str, schema_name: str, schema: bytes, metadata: dict[str, str],
                layout: BlockLayout | None) -> None:
        import foxglove  # lazy: --help loads this module without it

        ch = foxglove.Channel(topic, schema=foxglove.Schema(name=schema_name, encoding="jsonschema", data=schema),
                              message_encoding="json", context=self._context, metadata=metadata)
        self._channels.append(ch)
        self._log[cid] = ch.base.log
        if layout is not None:
            self._layouts[cid] = layout


class LogSink(FoxgloveChannels):
    """One MCAP log fed by :class:`cosim.observers.publish.Publisher` (see the module docstring), written by
    foxglove-sdk's MCAP writer on a ``foxglove.Context`` of its own (zstd chunks of ``chunk_size``
    uncompressed bytes at ``zstd_level``, compressed in the calling thread). Raises OSError when the
    file cannot be written (at the call that finds out).

    The writer was chosen by measurement: on helix_ctc's per-sample messages it writes about 2 us a
    message where the ``mcap`` package's ``Writer`` (pure Python) takes about 7
    (``benchmarks/mcap_writer.py``); the whole writer process of helix_ctc_analytic (10 s, samples
    layout) costs about 14.7 us per step with it (``benchmarks/log_writer_process.py``), 40 with the ``mcap``
    package.
    """

    def __init__(self, path: str | Path, chunk_size: int = 256 * 1024, zstd_level: int = 1):
        import foxglove  # lazy: --help loads this module without it
        from foxglove.mcap import (  # lazy: --help loads this module without it
            MCAPCompression,
            MCAPWriteOptions,
        )

        self._failures = _WriteFailures.attach()  # before opening: the writer reports failures through logging
        self._seen = self._failures.count
        self._context = foxglove.Context()
        options = MCAPWriteOptions(compression=MCAPCompression.Zstd, chunk_size=chunk_size,
                                   compression_level=zstd_level, compression_threads=0)
        try:  # a path, not a Python file: the writer (Rust) then holds no Python object
            self._writer = foxglove.open_mcap(str(path), allow_overwrite=True, context=self._context,
                                              writer_options=options)
        except Exception as exc:  # foxglove raises a bare error type for I/O failures
            _WriteFailures.detach()
            raise _os_error(str(exc)) from None
        self._channels: list = []
        self._log: dict[int, Any] = {}
        self._layouts: dict[int, BlockLayout] = {}

    def _call(self, f, *args) -> None:
        """A call to the writer itself: its failure as OSError."""
        try:
            f(*args)
        except Exception as exc:  # foxglove raises a bare error type for I/O failures
            raise _os_error(self._failures.reason or str(exc)) from None

    def _check(self) -> None:
        """Raise OSError when a message write failed since the last check (a flush tells whether it was
        this file's: a writer that failed refuses every further write)."""
        if self._failures.count != self._seen:
            self._seen = self._failures.count
            self._call(self._writer.flush)

    def blocks(self, offset_ns: int, blocks: list[tuple[int, list[int], bytes | list, Any]]) -> None:
        """Samples ``(cid, stamps, rows, skip)`` of component channels (see :func:`encode_messages`), in the
        order of their log times."""
        logs, times, datas = [], [], []
        for cid, stamps, data, skip in blocks:
            t, d = encode_messages(self._layouts[cid], stamps, data, skip, offset_ns)
            times += t
            datas += d
            logs += [self._log[cid]] * len(t)
        order = sorted(range(len(times)), key=times.__getitem__) if len(blocks) > 1 else range(len(times))
        for i in order:
            logs[i](datas[i], times[i])
        self._check()

    def message(self, cid: int, log_time: int, data: bytes) -> None:
        self._log[cid](data, log_time)
        self._check()

    def metadata(self, name: str, values: dict[str, str]) -> None:
        self._call(self._writer.write_metadata, name, values)

    def attachment(self, name: str, media_type: str, data: bytes, log_time: int, create_time: int) -> None:
        self._call(partial(self._writer.attach, log_time=log_time, create_time=create_time, name=name,
                           media_type=media_type, data=data))

    def flush(self) -> None:
        """End the open chunk and hand it to the OS: a killed process leaves it readable."""
        self._call(self._writer.flush)
        self._seen = self._failures.count

    def finish(self) -> None:
        """Write the summary and index and close the file (after a failure: :meth:`abandon`)."""
        self._check()
        self._call(self._writer.close)
        self._end()

    def abandon(self) -> None:
        """Stop after a failed write: close the writer, its errors ignored (a writer that failed writes
        nothing more: the file keeps the chunks written before, and no summary)."""
        try:
            self._writer.close()
        except Exception:  # noqa: BLE001 - it failed before: that failure is the one reported
            pass
        self._end()

    def _end(self) -> None:
        for ch in self._channels:
            ch.close()
        self._channels.clear()
        if self._failures is not None:
            self._failures = None
            _WriteFailures.detach()


# --------------------------------------------------------------------------- the writer process

_FRAME = struct.Struct("<I")
_PIPE_BYTES = 1 << 20  # the pipe to the child holds about 1 MB (Linux): ~1700 steps of helix_ctc's rows
_SUCCESS = b"ok\n"


class WriterFailed(Exception):
    """The writer process reported a failure (its reason) or ended without one."""


def _exec_writer() -> subprocess.Popen:
    """The writer as a new interpreter (``python -m cosim.observers.log_writer``) in a session of its own (Ctrl-C
    is the master's)."""
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[3])  # the folder holding the cosim package
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return subprocess.Popen([sys.executable, "-m", "cosim.observers.log_writer"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0, start_new_session=True, env=env)


class _ForkedWriter:
    """The writer as a fork of the master, with what :class:`WriterProcess` uses of a ``subprocess.Popen``
    (``pid``, ``stdin``, ``stdout``, ``stderr``, ``wait``, ``kill``, ``returncode``).

    The child makes a session of its own (Ctrl-C and the supervisor's kill of the run's process group are
    the master's), keeps its three pipes and closes every other descriptor it inherited (a live view's port,
    the log's claim, FMU files), ignores the stop signals, imports foxglove, runs :func:`_serve` and leaves
    with ``os._exit`` (none of the master's exit handlers, temp folders or buffered files are touched). It
    is made only when no other Python thread runs and no live view serves in this process (their threads
    would be missing in the child with whatever they held; the live view's recorder forks before the
    server starts); a thread of a native library (OpenBLAS' idle pool) is left behind harmlessly, as the
    child calls none of them.
    """

    serving = 0
    """Live views serving in this process (:class:`cosim.observers.live.LiveView` counts itself in and out)."""

    @classmethod
    def possible(cls) -> bool:
        return (hasattr(os, "fork") and sys.platform != "darwin" and threading.active_count() == 1
                and cls.serving == 0)

    @classmethod
    def start(cls) -> "_ForkedWriter":
        pipes = [os.pipe() for _ in range(3)]  # (read, write) of the child's stdin, stdout, stderr
        keep = (pipes[0][0], pipes[1][1], pipes[2][1])
        shared = mmap.mmap(-1, RowMirror.BYTES)  # anonymous, shared with the child across the fork
        with warnings.catch_warnings():  # Python >= 3.12 warns of any other OS thread (OpenBLAS' idle pool here):
            warnings.simplefilter("ignore", DeprecationWarning)  # the child calls none of them (see the class)
            pid = os.fork()
        if pid == 0:  # the child: never returns
            code = 1
            try:
                os.setsid()
                for sig in STOP_SIGNALS:
                    signal.signal(sig, signal.SIG_IGN)
                for target, fd in enumerate(keep):
                    os.dup2(fd, target)
                os.closerange(3, _max_fd())
                import foxglove  # noqa: F401  # lazy: the master's --help loads this module without it

                code = _serve(os.fdopen(0, "rb"), os.fdopen(1, "wb", buffering=0), shared)
            except BaseException:  # noqa: BLE001 - said on the stderr pipe, read by WriterProcess._reason
                try:
                    os.write(2, traceback.format_exc().encode(errors="replace"))
                except OSError:
                    pass
            finally:
                os._exit(code)
        for fd in keep:
            os.close(fd)
        return cls(pid, pipes[0][1], pipes[1][0], pipes[2][0], shared)

    def __init__(self, pid: int, stdin: int, stdout: int, stderr: int, shared: mmap.mmap | None = None) -> None:
        self.pid = pid
        self.shared = shared
        self.stdin = os.fdopen(stdin, "wb", buffering=0)
        self.stdout = os.fdopen(stdout, "rb")
        self.stderr = os.fdopen(stderr, "rb")
        self.returncode: int | None = None

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.returncode is None:
            pid, status = os.waitpid(self.pid, 0 if deadline is None else os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
            elif time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(f"log writer {self.pid}", timeout)
            else:
                time.sleep(0.005)
        return self.returncode

    def kill(self) -> None:
        if self.returncode is None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


class RowMirror:
    """The rows of a run's component channels that the master has not sent to its forked writer yet, copied into
    memory the writer shares (made before the fork): if the master dies inside an FMU, the writer writes, per channel,
    the rows after the last block it received, and the recovered log reaches the last step each component completed,
    not the last block the master sent.

    One section per batch of rows the publisher keeps: the joint rows (:class:`cosim.observers.publish._Joint`: every
    logged component's values of one step in one row, the common case), else one per component channel of numbers
    (:class:`cosim.observers.publish._Rows`: a multi-rate run's, each component's rows at its own steps). A section is
    ``(parts, width, cap)``: per channel in its rows ``(cid, byte offset in the row, bytes)``, the bytes of a row, and
    the rows it holds at most (the publisher hands its rows over before any batch holds more). The sections lie one
    after the other in :attr:`BYTES` of shared memory, each its row count (i64, written after its row, so a counted
    row is complete), then ``cap`` stamps (i64), then ``cap`` rows, in this machine's byte order. A channel of strings
    or binaries (values as lists, not rows of bytes) has ``width`` None: its rows are pickled (see
    :class:`_ValuesSection`).

    The memory is made with the writer, before the run's channels are known: rows that do not fit (:meth:`fits`: the
    rows of every channel over one block; any 60 channels of rows up to 64 KiB fit, a block holding at most 64 KiB)
    have no mirror at all (not a part of them: every channel then ends at the same block), and a crash keeps the
    blocks sent alone (up to 1 / ``scene_rate_hz`` of simulated time less), as a writer that shares no memory (a new
    interpreter) does.
    """

    BYTES = 4 << 20

    def __init__(self, shared: mmap.mmap, sections: list) -> None:
        self.sections: list[_Section] = []
        at = 0
        for _, width, cap in sections:
            self.sections.append((_Section if width is not None else _ValuesSection)(shared, at, width, cap))
            at += self.size(width, cap)

    VALUES_BYTES = 64 * 1024
    """The pickled rows of values a section of a channel of strings or binaries holds at most (then it holds no more
    until they are sent: a crash keeps the rows up to there)."""

    @classmethod
    def size(cls, width: int | None, cap: int) -> int:
        """The bytes of a section of ``cap`` rows of ``width`` bytes, or of values (``width`` None), a multiple of 8
        (each section's count and stamps are aligned)."""
        if width is None:
            return 8 + 16 * cap + cls.VALUES_BYTES
        return 8 + 8 * cap + (cap * width + 7) // 8 * 8

    @classmethod
    def fits(cls, sections: list) -> bool:
        return sum(cls.size(width, cap) for _, width, cap in sections) <= cls.BYTES

    def sent(self) -> None:
        """The rows so far reached the writer (the pipe holds them): every section starts again."""
        for section in self.sections:
            section.sent()

    @classmethod
    def unsent(cls, shared: mmap.mmap, sections: list, last: dict[int, int]) -> list:
        """The blocks (as :meth:`LogSink.blocks` takes them) of the counted rows of each section whose stamps are
        later than ``last[cid]``, the last stamp received of its channels (all of them, none received)."""
        blocks, at = [], 0
        for parts, width, cap in sections:
            n = max(0, min(struct.unpack_from("=q", shared, at)[0], cap))
            stamps = list(struct.unpack_from(f"={n}q", shared, at + 8))
            after = last.get(parts[0][0])
            first = 0 if after is None else next((i for i, t in enumerate(stamps) if t > after), n)
            if first < n and width is None:  # rows of values, each pickled: its end after the stamps
                ends = struct.unpack_from(f"={n}q", shared, at + 8 + 8 * cap)
                area = at + 8 + 16 * cap
                values = [pickle.loads(shared[area + (ends[i - 1] if i else 0):area + ends[i]])
                          for i in range(first, n)]
                blocks.append((parts[0][0], stamps[first:], values, None))
            elif first < n:
                rows = bytes(shared[at + 8 + 8 * cap + first * width:at + 8 + 8 * cap + n * width])
                whole = len(parts) == 1  # a channel's own rows: as the publisher sends them, no other bytes around
                blocks += [(cid, stamps[first:], rows, None if whole else (off, width - off - size))
                           for cid, off, size in parts]
            at += cls.size(width, cap)
        return blocks


class _Section:
    """One batch's rows in a :class:`RowMirror` (at byte ``at`` of the shared memory), written through memoryviews of
    it (a stamp, a row and the count: about 0.25 us a row, where ``struct.pack_into`` and an mmap slice took 0.5)."""

    __slots__ = ("_count", "_counter", "_row_views", "_stamps")

    def __init__(self, shared: mmap.mmap, at: int, width: int, cap: int) -> None:
        view = memoryview(shared)
        self._counter = view[at:at + 8].cast("q")
        self._stamps = view[at + 8:at + 8 + 8 * cap].cast("q")
        rows = at + 8 + 8 * cap
        self._row_views = [view[rows + i * width:rows + (i + 1) * width] for i in range(cap)]
        self._count = 0
        self._counter[0] = 0

    def put(self, stamp: int, row: bytes) -> None:
        i = self._count
        self._stamps[i] = stamp
        self._row_views[i][:] = row
        self._count = i + 1
        self._counter[0] = i + 1

    def sent(self) -> None:
        self._count = 0
        self._counter[0] = 0


class _ValuesSection:
    """A channel's rows of values (lists with strings, as :class:`cosim.observers.publish._Rows` reads them) in a
    :class:`RowMirror`: per row its stamp and the end of its pickle in an area of :attr:`RowMirror.VALUES_BYTES`.
    A row that does not fit is not put, nor any after it until the rows are sent (the counted ones stay a prefix)."""

    __slots__ = ("_area", "_count", "_counter", "_ends", "_full", "_stamps", "_used")

    def __init__(self, shared: mmap.mmap, at: int, width: None, cap: int) -> None:
        view = memoryview(shared)
        self._counter = view[at:at + 8].cast("q")
        self._stamps = view[at + 8:at + 8 + 8 * cap].cast("q")
        self._ends = view[at + 8 + 8 * cap:at + 8 + 16 * cap].cast("q")
        self._area = view[at + 8 + 16 * cap:at + 8 + 16 * cap + RowMirror.VALUES_BYTES]
        self.sent()

    def put(self, stamp: int, values: list) -> None:
        if self._full:
            return
        data = pickle.dumps(values, protocol=pickle.HIGHEST_PROTOCOL)
        start = self._used
        end = start + len(data)
        if end > len(self._area):
            self._full = True
            return
        i = self._count
        self._stamps[i] = stamp
        self._area[start:end] = data
        self._ends[i] = self._used = end
        self._count = i + 1
        self._counter[0] = i + 1

    def sent(self) -> None:
        self._count = self._used = 0
        self._full = False
        self._counter[0] = 0


def writer_forks() -> bool:
    """Whether a :class:`WriterProcess` made now would be a fork of this process (it then starts at once)."""
    return _ForkedWriter.possible()


def live_view_serving(serving: bool) -> None:
    """A live view's server starts (True) or has stopped (False) in this process: no writer is forked meanwhile."""
    _ForkedWriter.serving += 1 if serving else -1


def _max_fd() -> int:
    try:
        return min(os.sysconf("SC_OPEN_MAX"), 1 << 16)
    except (ValueError, OSError):
        return 4096


class WriterProcess:
    """A :class:`LogSink` in a child process: the same methods, sent through a pipe (see the module docstring).

    Start it early, then :meth:`open` the file. Every call raises :class:`WriterFailed` with the child's
    reason once the child has failed.

    The child is a fork of this process where that is safe (:class:`_ForkedWriter`: POSIX but macOS, no other
    Python thread, no live view serving): it has every module it needs but foxglove, which it imports while
    the master loads its FMUs, and is ready in about 0.04 s. Elsewhere it is a new interpreter
    (``python -m cosim.observers.log_writer``), which takes about 0.1 s of a core to start: on a 10 s
    helix_ctc_analytic run of native FMUs (0.08 s unlogged) that start alone made the logged loop 1.3x longer.
    """

    def __init__(self) -> None:
        self._proc = _ForkedWriter.start() if _ForkedWriter.possible() else _exec_writer()
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
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
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
        shared = getattr(self._proc, "shared", None)
        if shared is None or not sections or not RowMirror.fits(sections):
            return None
        self._send("mirror", [(list(parts), width, cap) for parts, width, cap in sections], offset_ns)
        return RowMirror(shared, sections)

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
        try:
            self._proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
            raise WriterFailed(f"the writer process did not finish the file within {timeout:g} s") from None
        out = self._proc.stdout.read()
        if self._proc.returncode != 0 or not out.endswith(_SUCCESS):
            raise WriterFailed(self._reason(out))

    def abandon(self) -> None:
        """Leave the file unfinished (its chunks written) and let the child end."""
        self._close_pipe()
        try:
            self._proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
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


def os_reason(exc: OSError) -> str:
    """The OS's reason for a failed write, in a message's words."""

    if exc.errno == errno.ENOSPC:
        return "no space left on device"
    return exc.strerror or str(exc)


def main() -> int:

    for sig in STOP_SIGNALS:  # the master handles Ctrl-C and a closed terminal and finishes the log
        signal.signal(sig, signal.SIG_IGN)
    return _serve(sys.stdin.buffer, sys.stdout.buffer)


if __name__ == "__main__":
    sys.exit(main())
