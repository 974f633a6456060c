"""A block of a component channel's samples as the channel's JSON messages (see :mod:`cosim.observers.log_writer`).

:class:`BlockLayout`, :func:`encode_samples` and :func:`encode_block`: a block of samples (the stamps and the *rows*:
the bytes of the logged values as the FMU buffers hold them, one row per sample) becomes the channel's messages in its
layout. ``samples`` (the default): one message per sample, ``{"t": s, "<variable>": value, ...}``, what Foxglove and
PlotJuggler plot as time series; ``blocks``: one message per block, ``{"t": [...], "<variable>": [...], ...}`` (one
array element per sample), the cheapest to write. Either way one ``struct`` call reads the rows and orjson writes the
numbers; the per-sample messages are joined by a small C helper (``cosim/observers/samples.c``) where a compiler is.

No numpy or fmpy here (rows are read with :mod:`struct`): the writer process loads this module at its start.
"""

from __future__ import annotations

import ctypes
import struct
import threading
from dataclasses import dataclass, field
from itertools import accumulate, repeat
from pathlib import Path
from typing import Any

import orjson

from ...cbuild import Library

__all__ = ["BlockLayout", "encode_block", "encode_messages", "encode_samples", "row_format", "samples_helper"]


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
                   skip: tuple[int, int] | None = None, times: bytes | None = None) -> list[bytes]:
    """One message per sample at ``stamps`` (simulation ns): ``{"t": s, "<key>": value, ...}``, byte for byte
    what ``orjson.dumps`` writes of that dict (the messages of logs written before blocks).

    ``data`` and ``skip`` as in :func:`encode_block`. With a row format, the numbers of the whole block
    are written by orjson, two calls (the times, the values), and joined with the keys
    (:meth:`BlockLayout.joints`) between them: by ``cosim_samples`` (``samples.c``, :func:`samples_helper`), one
    pass in C over orjson's output, else cut at their commas (a number, ``true``, ``false`` or ``null``
    has none) and joined in Python. No dict and no Python loop per sample either way. ``times``: the times as
    orjson writes them (:func:`times_json`), where the caller encodes several channels of the same stamps.
    """
    if layout.fmt is None:
        keys = ("t", *layout.keys)
        return [orjson.dumps(dict(zip(keys, (s * 1e-9, *values)))) for s, values in zip(stamps, data)]
    n = len(stamps)
    flat = layout.rows_struct(n, skip).unpack(data)
    join = _samples_helper()
    t_json = times_json(stamps) if times is None else times
    if join is None:
        return _samples_py(layout, t_json, flat, n)
    v_json = orjson.dumps(flat)
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


def _samples_py(layout: BlockLayout, t_json: bytes, flat: tuple, n: int) -> list[bytes]:
    """:func:`encode_samples`'s messages without the C helper: orjson's numbers cut at their commas, one list
    of them per element of the row, joined with the keys sample by sample."""
    width = len(flat) // n
    values = orjson.dumps(flat)[1:-1].split(b",")
    joints = layout.joints()
    columns = [repeat(joints[0], n), t_json[1:-1].split(b",")]
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


def times_json(stamps: list[int]) -> bytes:
    """The ``"t"`` values (s) of samples at ``stamps`` (simulation ns) as a JSON array, as :func:`encode_samples`
    writes them."""
    return orjson.dumps([s * 1e-9 for s in stamps])


def encode_messages(layout: BlockLayout, stamps: list[int], data: bytes | list, skip: tuple[int, int] | None,
                    offset_ns: int) -> tuple[list[int], list[bytes]]:
    """(log times, messages) of a block of samples in its channel's layout: one message per sample logged at
    its stamp + ``offset_ns`` (``samples``), or one logged at its last stamp + ``offset_ns`` (``blocks``)."""
    if layout.per_sample:
        return [s + offset_ns for s in stamps], encode_samples(layout, stamps, data, skip)
    return [stamps[-1] + offset_ns], [encode_block(layout, stamps, data, skip)]
