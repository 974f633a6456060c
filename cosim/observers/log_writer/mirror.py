"""The rows a run's master has not sent to its forked log writer yet, in memory the writer shares (see
:class:`RowMirror`): a crash of the master loses no completed step of the log.
"""

from __future__ import annotations

import ctypes
import mmap
import pickle
import struct

__all__ = ["RowMirror", "row_section"]


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
    it (a stamp, a row and the count: about 0.25 us a row, where ``struct.pack_into`` and an mmap slice took 0.5), or
    by the master's loop in C (:attr:`addresses`), which writes the same layout: the count is the memory's, not a copy.
    The publisher's batch of joint rows is held here alone (:meth:`read` gives them back), in the mirror's memory or,
    without a mirror, in memory of its own (:func:`row_section`)."""

    __slots__ = ("_counter", "_row_views", "_rows", "_stamps", "addresses", "cap", "width")

    def __init__(self, shared, at: int, width: int, cap: int) -> None:
        view = memoryview(shared)
        self._counter = view[at:at + 8].cast("q")
        self._stamps = view[at + 8:at + 8 + 8 * cap].cast("q")
        rows = at + 8 + 8 * cap
        self._rows = view[rows:rows + cap * width]
        self._row_views = [view[rows + i * width:rows + (i + 1) * width] for i in range(cap)]
        self._counter[0] = 0
        self.width, self.cap = width, cap
        base = ctypes.addressof(ctypes.c_char.from_buffer(shared))
        self.addresses = (base + at, base + at + 8, base + rows)
        """The count's, the stamps' and the rows' addresses, for a loop in C (``cosim_steps``)."""

    def put(self, stamp: int, row: bytes) -> None:
        i = self._counter[0]
        self._stamps[i] = stamp
        self._row_views[i][:] = row
        self._counter[0] = i + 1

    @property
    def count(self) -> int:
        return self._counter[0]

    def read(self) -> tuple[list[int], bytes]:
        """The stamps and the rows (their bytes back to back) counted so far."""
        n = self._counter[0]
        return self._stamps[:n].tolist(), self._rows[:n * self.width].tobytes()

    def sent(self) -> None:
        self._counter[0] = 0


def row_section(width: int, cap: int) -> _Section:
    """A :class:`_Section` of ``cap`` rows of ``width`` bytes in memory of its own (a batch no mirror holds)."""
    return _Section(bytearray(RowMirror.size(width, cap)), 0, width, cap)


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
