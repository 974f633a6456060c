"""The run log's writer: component samples encoded as JSON messages and written to MCAP, in this
process or in a writer process on another core.

:class:`cosim.publish.Publisher` hands its sinks each component channel's samples in blocks: the
stamps and the *rows* (the bytes of the logged values as the FMU buffers hold them, one row per
sample); every other message (scene, transforms, events) comes encoded. Here:

- :class:`BlockLayout`, :func:`encode_samples` and :func:`encode_block`: a block of samples becomes
  the channel's messages in its layout. ``samples`` (the default): one message per sample,
  ``{"t": s, "<variable>": value, ...}``, what Foxglove and PlotJuggler plot as time series;
  ``blocks``: one message per block, ``{"t": [...], "<variable>": [...], ...}`` (one array element
  per sample), the cheapest to write. Either way one ``struct`` call reads the rows and orjson
  writes the numbers;
- :class:`McapFile`: an MCAP writer by lists of messages: message records packed into zstd chunks,
  message indexes after each chunk, and the summary (schemas, channels, statistics, chunk,
  metadata and attachment indexes) by :meth:`McapFile.finish`. A file never finished has every
  chunk written so far and no summary: ``cosim recover`` reads it;
- :class:`LogSink`: one log file fed by the publisher's calls (``channel``, ``blocks``, ``message``)
  and the recorder's (``metadata``, ``attachment``, ``flush``, ``finish``, ``abandon``);
- :class:`WriterProcess`: the same calls sent through a pipe to a :class:`LogSink` in a child
  process (``python -m cosim.log_writer``), so that encoding, compressing and writing take the
  other core, not the master's loop. The child ignores Ctrl-C (the master finishes the log); a
  master that dies closes the pipe, and the child then writes what it has and exits, leaving the
  file unfinished (recoverable), as a killed writer in the master would.

The child imports no numpy (it starts in about 0.1 s): rows are read with :mod:`struct`.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import struct
import subprocess
import sys
import zlib
from dataclasses import dataclass, field
from itertools import accumulate, repeat
from operator import add
from pathlib import Path
from typing import Any

import orjson

__all__ = ["BlockLayout", "encode_block", "encode_messages", "encode_samples", "row_format", "McapFile", "LogSink",
           "WriterProcess", "WriterFailed"]

_MAGIC = b"\x89MCAP0\r\n"
_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time
_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, record length, start, end, uncompressed size, uncompressed crc


def _string(s: str) -> bytes:
    b = s.encode()
    return struct.pack("<I", len(b)) + b


def _map(d: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in d.items())
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


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
    """How a component channel's samples become its messages (see :mod:`cosim.publish`).

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
    are written by one orjson call and cut at their commas (a number, ``true``, ``false`` or ``null``
    has none), then joined with the keys (:meth:`BlockLayout.joints`): no dict and no Python loop per
    sample.
    """
    times = [s * 1e-9 for s in stamps]
    if layout.fmt is None:
        keys = ("t", *layout.keys)
        return [orjson.dumps(dict(zip(keys, (t, *values)))) for t, values in zip(times, data)]
    n = len(stamps)
    flat = layout.rows_struct(n, skip).unpack(data)
    width = len(flat) // n
    values = orjson.dumps(flat)[1:-1].split(b",")
    joints = layout.joints()
    columns = [repeat(joints[0], n), orjson.dumps(times)[1:-1].split(b",")]
    fmi2 = {e for at, count, fmi2_bool in layout.columns if fmi2_bool for e in range(at, at + max(count, 1))}
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


# --------------------------------------------------------------------------- MCAP file


class McapFile:
    """An MCAP file written by blocks of messages (see the module docstring).

    Schemas and channels go in the data section as they are added, before their first message;
    messages fill a chunk, compressed with zstd once it holds ``chunk_size`` bytes (or on
    :meth:`flush`). Raises OSError when the file cannot be written.
    """

    def __init__(self, path: str | Path, chunk_size: int = 256 * 1024, zstd_level: int = 1,
                 library: str = "delta-cosim"):
        import zstandard

        self._f = open(path, "wb")  # noqa: SIM115 - closed by finish() or abandon()
        self._pos = 0
        self._zstd = zstandard.ZstdCompressor(level=zstd_level)
        self.chunk_size = chunk_size
        self._schemas: list[bytes] = []  # records, repeated in the summary
        self._channels: list[bytes] = []
        self._chunk: list[bytes] = []  # the open chunk's records
        self._chunk_ids: list[int] = []  # its messages' channels, log times and offsets (for the message index)
        self._chunk_times: list[int] = []
        self._chunk_offsets: list[int] = []
        self._chunk_bytes = 0
        self._chunk_indexes: list[bytes] = []
        self._attachment_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._counts: dict[int, int] = {}
        self._messages = 0
        self._start = self._end = 0
        self._n_chunks = self._n_attachments = self._n_metadata = 0
        self._write(_MAGIC + _record(0x01, _string("") + _string(library)))

    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._pos += len(data)

    def schema(self, schema_id: int, name: str, encoding: str, data: bytes) -> None:
        rec = _record(0x03, struct.pack("<H", schema_id) + _string(name) + _string(encoding)
                      + struct.pack("<I", len(data)) + data)
        self._schemas.append(rec)
        self._write(rec)

    def channel(self, channel_id: int, schema_id: int, topic: str, encoding: str, metadata: dict[str, str]) -> None:
        rec = _record(0x04, struct.pack("<HH", channel_id, schema_id) + _string(topic) + _string(encoding)
                      + _map(metadata))
        self._channels.append(rec)
        self._write(rec)
        self._counts[channel_id] = 0

    def messages(self, ids: list[int], times: list[int], datas: list[bytes]) -> None:
        """Add messages (channel ids, log times in ns, data) in this order to the open chunk."""
        n = len(ids)
        if n == 0:
            return
        lengths = list(map(len, datas))
        parts = [None] * (2 * n)  # each record: opcode, content length, channel, sequence, two times, data
        parts[0::2] = map(_MESSAGE.pack, repeat(5, n), map(add, lengths, repeat(22, n)), ids, repeat(0, n), times,
                          times)
        parts[1::2] = datas
        offsets = list(accumulate(map(add, lengths, repeat(31, n)), initial=self._chunk_bytes))
        self._chunk += parts
        self._chunk_ids += ids
        self._chunk_times += times
        self._chunk_offsets += offsets[:-1]
        self._chunk_bytes = offsets[-1]
        lo, hi = min(times), max(times)
        if self._messages == 0 or lo < self._start:
            self._start = lo
        if hi > self._end:
            self._end = hi
        self._messages += n
        if self._chunk_bytes >= self.chunk_size:
            self._close_chunk()

    def _close_chunk(self) -> None:
        if not self._chunk:
            return
        data = b"".join(self._chunk)
        packed = self._zstd.compress(data)
        index: dict[int, list[int]] = {}  # channel id -> [log time, offset, ...]
        for cid, t, at in zip(self._chunk_ids, self._chunk_times, self._chunk_offsets):
            entry = index.get(cid)
            if entry is None:
                entry = index[cid] = []
            entry += (t, at)
        for cid, entry in index.items():
            self._counts[cid] += len(entry) // 2
        start, end = min(self._chunk_times), max(self._chunk_times)
        body_len = 8 * 3 + 4 + 4 + 4 + 8 + len(packed)
        head = _CHUNK_HEAD.pack(6, body_len, start, end, len(data), zlib.crc32(data))
        chunk_at = self._pos
        self._write(head + _string("zstd") + struct.pack("<Q", len(packed)))
        self._write(packed)
        chunk_len = self._pos - chunk_at
        offsets, indexes = {}, []
        at = self._pos
        for cid, entries in index.items():
            pairs = struct.pack(f"<{len(entries)}Q", *entries)
            rec = _record(0x07, struct.pack("<HI", cid, len(pairs)) + pairs)
            offsets[cid] = at
            at += len(rec)
            indexes.append(rec)
        self._write(b"".join(indexes))
        offsets_map = b"".join(struct.pack("<HQ", cid, off) for cid, off in offsets.items())
        self._chunk_indexes.append(_record(0x08, struct.pack("<QQQQ", start, end, chunk_at, chunk_len)
                                           + struct.pack("<I", len(offsets_map)) + offsets_map
                                           + struct.pack("<Q", at - (chunk_len + chunk_at)) + _string("zstd")
                                           + struct.pack("<QQ", len(packed), len(data))))
        self._n_chunks += 1
        self._chunk, self._chunk_ids, self._chunk_times, self._chunk_offsets = [], [], [], []
        self._chunk_bytes = 0

    def metadata(self, name: str, values: dict[str, str]) -> None:
        at = self._pos
        rec = _record(0x0C, _string(name) + _map(values))
        self._write(rec)
        self._metadata_indexes.append(_record(0x0D, struct.pack("<QQ", at, len(rec)) + _string(name)))
        self._n_metadata += 1

    def attachment(self, name: str, media_type: str, data: bytes, log_time: int, create_time: int) -> None:
        at = self._pos
        body = struct.pack("<QQ", log_time, create_time) + _string(name) + _string(media_type) \
            + struct.pack("<Q", len(data)) + data
        rec = _record(0x09, body + struct.pack("<I", zlib.crc32(body)))
        self._write(rec)
        self._attachment_indexes.append(_record(0x0A, struct.pack("<QQQQQ", at, len(rec), log_time, create_time,
                                                                  len(data)) + _string(name) + _string(media_type)))
        self._n_attachments += 1

    def flush(self) -> None:
        """Write the open chunk and hand the file's buffer to the OS (a killed process keeps it all)."""
        self._close_chunk()
        self._f.flush()

    def finish(self) -> None:
        """Write the open chunk, the summary and the footer, and close the file."""
        self._close_chunk()
        self._write(_record(0x0F, struct.pack("<I", 0)))  # data end; no data section CRC
        summary_start = self._pos
        groups = [(0x03, self._schemas), (0x04, self._channels), (0x0B, [self._statistics()]),
                  (0x08, self._chunk_indexes), (0x0A, self._attachment_indexes), (0x0D, self._metadata_indexes)]
        summary, offsets = [], []
        at = summary_start
        for opcode, records in groups:
            if not records:
                continue
            data = b"".join(records)
            offsets.append(_record(0x0E, struct.pack("<BQQ", opcode, at, len(data))))
            summary.append(data)
            at += len(data)
        offset_start = at
        summary_data = b"".join(summary) + b"".join(offsets)
        footer_head = struct.pack("<BQQQ", 0x02, 20, summary_start, offset_start)
        crc = zlib.crc32(footer_head, zlib.crc32(summary_data))
        self._write(summary_data + footer_head + struct.pack("<I", crc) + _MAGIC)
        self._f.close()

    def _statistics(self) -> bytes:
        counts = b"".join(struct.pack("<HQ", cid, n) for cid, n in self._counts.items())
        return _record(0x0B, struct.pack("<QHIIIIQQ", self._messages, len(self._schemas), len(self._channels),
                                         self._n_attachments, self._n_metadata, self._n_chunks, self._start,
                                         self._end) + struct.pack("<I", len(counts)) + counts)

    def abandon(self) -> None:
        """Write the open chunk and close the file without a summary (an unfinished, recoverable log)."""
        try:
            self._close_chunk()
        finally:
            self._f.close()


# --------------------------------------------------------------------------- a log file fed by the publisher


class LogSink:
    """One MCAP log fed by :class:`cosim.publish.Publisher` (see the module docstring).

    The publisher's channel ``cid`` (0, 1, ...) is MCAP channel ``cid + 1``; channels with the same
    schema share one schema record.
    """

    def __init__(self, path: str | Path, chunk_size: int = 256 * 1024, zstd_level: int = 1):
        self.file = McapFile(path, chunk_size, zstd_level)
        self._layouts: dict[int, BlockLayout] = {}
        self._schema_ids: dict[tuple[str, bytes], int] = {}

    def channel(self, cid: int, topic: str, schema_name: str, schema: bytes, metadata: dict[str, str],
                layout: BlockLayout | None) -> None:
        key = (schema_name, schema)
        sid = self._schema_ids.get(key)
        if sid is None:
            sid = self._schema_ids[key] = len(self._schema_ids) + 1
            self.file.schema(sid, schema_name, "jsonschema", schema)
        self.file.channel(cid + 1, sid, topic, "json", metadata)
        if layout is not None:
            self._layouts[cid] = layout

    def blocks(self, offset_ns: int, blocks: list[tuple[int, list[int], bytes | list, Any]]) -> None:
        """Samples ``(cid, stamps, rows, skip)`` of component channels (see :func:`encode_messages`), in the
        order of their log times."""
        ids, times, datas = [], [], []
        for cid, stamps, data, skip in blocks:
            t, d = encode_messages(self._layouts[cid], stamps, data, skip, offset_ns)
            times += t
            datas += d
            ids += [cid + 1] * len(t)
        if len(blocks) > 1:
            order = sorted(range(len(times)), key=times.__getitem__)
            ids, times, datas = [ids[i] for i in order], [times[i] for i in order], [datas[i] for i in order]
        self.file.messages(ids, times, datas)

    def message(self, cid: int, log_time: int, data: bytes) -> None:
        self.file.messages([cid + 1], [log_time], [data])

    def metadata(self, name: str, values: dict[str, str]) -> None:
        self.file.metadata(name, values)

    def attachment(self, name: str, media_type: str, data: bytes, log_time: int, create_time: int) -> None:
        self.file.attachment(name, media_type, data, log_time, create_time)

    def flush(self) -> None:
        self.file.flush()

    def finish(self) -> None:
        self.file.finish()

    def abandon(self) -> None:
        self.file.abandon()


# --------------------------------------------------------------------------- the writer process

_FRAME = struct.Struct("<I")
_PIPE_BYTES = 1 << 20  # the pipe to the child holds about 1 MB (Linux): ~1700 steps of helix_ctc's rows
_SUCCESS = b"ok\n"


class WriterFailed(Exception):
    """The writer process reported a failure (its reason) or ended without one."""


class WriterProcess:
    """A :class:`LogSink` in a child process: the same methods, sent through a pipe (see the module docstring).

    Start it early (the interpreter takes about 0.1 s to start), then :meth:`open` the file. Every
    call raises :class:`WriterFailed` with the child's reason once the child has failed.
    """

    def __init__(self) -> None:
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self._proc = subprocess.Popen([sys.executable, "-m", "cosim.log_writer"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0,
                                      start_new_session=True, env=env)  # own session: Ctrl-C is the master's
        self._fd = self._proc.stdin.fileno()
        try:
            import fcntl

            fcntl.fcntl(self._fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
        except (ImportError, AttributeError, OSError):  # not Linux, or above this user's limit: the default works
            pass
        self.failure: str | None = None
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


def _serve(inp, out) -> int:
    """The child's loop: calls from the master until ``finish`` (exit 0, ``ok``) or the end of the pipe
    (the master died: the file is left unfinished). A failure is one line ``error: reason``, exit 1."""
    sink: LogSink | None = None
    try:
        while True:
            head = _read_exactly(inp, _FRAME.size)
            if head is None:
                if sink is not None:
                    sink.abandon()
                return 0
            payload = _read_exactly(inp, _FRAME.unpack(head)[0])
            if payload is None:
                if sink is not None:
                    sink.abandon()
                return 0
            op, args = pickle.loads(payload)
            if op == "open":
                sink = LogSink(*args)
            elif op == "finish":
                sink.finish()
                out.write(_SUCCESS)
                out.flush()
                return 0
            else:
                getattr(sink, op)(*args)
    except OSError as exc:
        out.write(f"error: {os_reason(exc)}\n".encode())
        out.flush()
        return 1


def os_reason(exc: OSError) -> str:
    """The OS's reason for a failed write, in a message's words."""
    import errno

    if exc.errno == errno.ENOSPC:
        return "no space left on device"
    return exc.strerror or str(exc)


def main() -> int:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the master handles Ctrl-C and finishes the log
    return _serve(sys.stdin.buffer, sys.stdout.buffer)


if __name__ == "__main__":
    sys.exit(main())
