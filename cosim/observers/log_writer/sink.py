"""One MCAP log file fed by the publisher's calls, written by foxglove-sdk's MCAP writer (see
:mod:`cosim.observers.log_writer`).

:class:`LogSink`: one log file fed by the publisher's calls (``channel``, ``blocks``, ``message``) and the recorder's
(``metadata``, ``attachment``, ``flush``, ``finish``, ``abandon``), written by foxglove-sdk's MCAP writer (zstd
chunks, indexes, summary). A file never finished has every chunk flushed so far and no summary: ``cosim recover``
reads it. :class:`FoxgloveChannels`: what a log file and the live view have in common. Failed writes, which the SDK
reports through logging, become OSError (:func:`os_reason`: the OS's reason in a message's words).
"""

from __future__ import annotations

import errno
import logging
import os
import re
import threading
from functools import partial
from pathlib import Path
from typing import Any

from .encode import BlockLayout, encode_messages, encode_samples, times_json

__all__ = ["FoxgloveChannels", "LogSink", "WRITER_LOGGER", "os_reason"]


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
        order of their log times (of one time, in the blocks' order)."""
        first = blocks[0][1] if blocks else None
        if len(blocks) > 1 and all(b[1] == first and self._layouts[b[0]].per_sample and self._layouts[b[0]].fmt
                                   for b in blocks):  # the joint rows: one message per sample of each channel
            t_json = times_json(first)  # written once for every channel
            logs = [self._log[cid] for cid, _, _, _ in blocks]
            datas = [encode_samples(self._layouts[cid], first, data, skip, t_json) for cid, _, data, skip in blocks]
            for j, s in enumerate(first):
                t = s + offset_ns
                for log, d in zip(logs, datas):
                    log(d[j], t)
            self._check()
            return
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


def os_reason(exc: OSError) -> str:
    """The OS's reason for a failed write, in a message's words."""

    if exc.errno == errno.ENOSPC:
        return "no space left on device"
    return exc.strerror or str(exc)
