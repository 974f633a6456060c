"""The hot loop in C: blocks of macro steps of a system whose components all have C turns, one call per block.

The Python loop (:meth:`~cosim.engine.execution.Execution.simulate_until` with the algorithm's macro step) pays
the interpreter per component and step: the turn's closure, a clock reading after each turn, the boxing of the
times, the observers' Python. Where nothing in a run needs Python between two macro steps, ``cosim_steps``
(``cosim/fmi/turn.c``) does the same work from C, as the fastest masters do: per macro step the link copies
(as bytes, from output buffers into input buffers), every component's turn (:func:`cosim.fmi.turn.make_turn`:
set, doStep, get, NaN check) in the algorithm's order (Gauss-Seidel: each component's links copied before its
turn; Jacobi: every link first), each component's wall time, the record the watchdog and the supervisor read
(the component with the turn, the macro step's time, the steps done) and the tracked errors' sums of an
:class:`ErrorSums` observer; the same values in the same order and the same double arithmetic as the Python
loop, so a run's results are the same bit for bit.

Where every observer is an :class:`ErrorSums` or offers :class:`Blocks` (the run's log: its recorder and publisher),
Python is entered once per block: at most :data:`BLOCK` macro steps or :data:`BUDGET_S` of wall time (a stop request
is answered at the block's end, within that time), a block also ending where progress is reported and where an
observer needs Python (:attr:`Blocks.free`: the publisher's next scene, its rows full); the log's row of each macro
step (every logged value, one row) is copied in C too, into the publisher's rows (:attr:`Blocks.rows`: the memory
its writer process shares, so that a crash keeps every completed step). With other observers (a live view, the
real-time pacing, an observer of the caller's) each macro step is one call, and the observers, the progress and the
stop request come after each as in the Python loop.
A run takes this loop when (:func:`make`) the helper is built, every component has a C turn (co-simulation,
numbers only, not a worker's proxy or publisher), every step multiple is 1 and every link joins buffers of the
same C type; otherwise, and around events, the Python loop runs.
"""

from __future__ import annotations

import ctypes
from ctypes import POINTER, c_double, c_int64, c_size_t, c_void_p
from typing import Any, Callable, Protocol

import numpy as np

from ..fmi import Terminated
from ..fmi.turn import Move, Steps, Turn, steps_helper
from .supervision import MASTER

__all__ = ["BLOCK", "BUDGET_S", "Blocks", "ErrorSums", "CLoop", "key", "make", "simulate", "steps_to"]

BLOCK = 4096
"""Macro steps a call runs at most (the grid's doubles are computed a block at a time)."""
BUDGET_S = 0.01
"""Wall seconds after which a call returns at the end of a macro step: how late a stop request is answered."""

_BYTES = set("bBhHiIlLqQfd?")  # ctypes simple types copied as their bytes (numbers, FMI booleans)


class ErrorSums(Protocol):
    """An observer whose every ``stepped`` only sums the errors of ``pairs`` (``error_sums`` True marks one):
    for pair ``j``, ``((actual array, index), (reference array, index))`` of ``c_double`` values,
    ``e = actual - reference``, ``sq[j] += e * e``, the largest ``|e|`` in ``mx[j]`` and the macro step's end (ns)
    when it was seen in ``t_mx[j]``; ``n`` counts the steps (:class:`cosim.observers.recorders.ErrorObserver`)."""

    error_sums: bool
    pairs: list
    sq: list[float]
    mx: list[float]
    t_mx: list[int]
    n: int


class Blocks:
    """What an observer that offers it (``loop_blocks()``: a :class:`Blocks`, or None when it needs Python after
    every macro step) is to the loop in C: ``free(k)``, the macro steps from ``k`` the loop may run before the observer
    needs Python (at least 1); ``stepped(k, n)``, after macro steps ``k .. k + n - 1``, in place of their
    ``stepped`` calls; ``rows``, optionally, where the loop copies each macro step's row: ``(section, copies)``, the
    section as :class:`cosim.observers.log_writer.mirror._Section` (``addresses`` of its count, stamps and rows,
    ``width``, ``cap``, ``count``) and per stretch of the row ``(byte offset in the row, address, bytes)``. A call
    returns when the section is full."""

    __slots__ = ("free", "rows", "stepped")

    def __init__(self, free: Callable[[int], int], stepped: Callable[[int, int], None], rows: Any = None) -> None:
        self.free, self.stepped, self.rows = free, stepped, rows


def steps_to(grid: Any, k: int, t_ns: int) -> int:
    """Macro steps from ``k`` up to and with the first that ends at or after ``t_ns`` (at least 1; all that remain
    when none does): where an observer that acts once a step's end reaches ``t_ns`` needs Python."""
    end = grid.index(t_ns)  # the last point at or before t_ns
    if grid.t_ns(end) < t_ns:
        end += 1
    return max(1, min(end, grid.n_steps) - k)


def _moves(ex: Any, c: int) -> list[Move] | None:
    """The links into component ``c`` as byte copies (adjacent elements merged), None when one converts."""
    out: list[Move] = []
    for lk in ex.plan.links:
        if lk.dst.comp != c:
            continue
        dv, di = ex.slaves[c].locate(lk.dst.var, output=False)
        sv, si = ex.slaves[lk.src.comp].locate(lk.src.var, output=True)
        kind = getattr(dv, "_type_", None)
        if kind is None or kind is not getattr(sv, "_type_", None) or getattr(kind, "_type_", None) not in _BYTES:
            return None
        size = ctypes.sizeof(kind)
        dst = ctypes.addressof(dv) + (di + lk.dst.offset) * size
        src = ctypes.addressof(sv) + (si + lk.src.offset) * size
        n = lk.count * size
        if out and out[-1].dst + out[-1].bytes == dst and out[-1].src + out[-1].bytes == src:
            out[-1].bytes += n
        else:
            out.append(Move(dst, src, n))
    return out


class CLoop:
    """``cosim_steps`` bound to an execution's components, links, record and error observers (:func:`make`)."""

    def __init__(self, ex: Any, turns: list[tuple[Turn, bool]], moves: list[list[Move]], sums: list[ErrorSums],
                 jacobi: bool, blocks: bool = True, observers: tuple[Blocks, ...] = ()):
        self.ex, self.sums, self.blocks, self.observers = ex, sums, blocks, observers
        order = list(ex.plan.order)
        self.order = order
        self.slaves = [ex.slaves[c] for c in order]
        flat = [m for c in order for m in moves[c]]
        first = [0]
        for c in order:
            first.append(first[-1] + len(moves[c]))
        pairs = [p for o in sums for p in o.pairs]
        n_pairs = len(pairs)
        self.times, self.steps, self.ends = (c_double * BLOCK)(), (c_double * BLOCK)(), (c_int64 * BLOCK)()
        # the same memory as arrays: a block's doubles are copied in whole (element by element through ctypes was
        # 0.59 us a step, a third of the master's own cost)
        self._arrays = tuple(np.ctypeslib.as_array(a) for a in (self.times, self.steps, self.ends))
        self._held = (0, 0)  # the macro steps whose doubles the arrays hold: first, how many (_window)
        self.wall = (c_double * len(ex.slaves))()
        self.sq, self.mx, self.t_mx = (c_double * max(1, n_pairs))(), (c_double * max(1, n_pairs))(), \
            (c_int64 * max(1, n_pairs))()
        address = ctypes.addressof
        self.s = Steps(n=len(order), turns=(POINTER(Turn) * len(order))(*[ctypes.pointer(turns[c][0]) for c in order]),
                       comp=(c_size_t * len(order))(*order), first=(c_size_t * len(first))(*first),
                       moves=(Move * max(1, len(flat)))(*flat), jacobi=int(jacobi), wall=self.wall,
                       record=_address(ex.current), master=float(MASTER), times=self.times, steps=self.steps,
                       ends=self.ends, n_pairs=n_pairs,
                       actual=(c_void_p * max(1, n_pairs))(*[address(a) + i * 8 for (a, i), _ in pairs]),
                       reference=(c_void_p * max(1, n_pairs))(*[address(r) + i * 8 for _, (r, i) in pairs]),
                       sq=self.sq, mx=self.mx, t_mx=self.t_mx, budget=BUDGET_S)
        self.section = None
        for o in observers:
            if o.rows is not None:
                self.section, copies = o.rows
                count, stamps, rows = self.section.addresses
                self.copies = (Move * len(copies))(*[Move(at, address, n) for at, address, n in copies])
                self.s.n_copies, self.s.copies, self.s.row_count = len(copies), self.copies, count
                self.s.row_stamps, self.s.rows = stamps, rows
                self.s.row_width, self.s.row_cap = self.section.width, self.section.cap
        proto = ctypes.PYFUNCTYPE if any(python for _, python in turns) else ctypes.CFUNCTYPE
        f = steps_helper()
        self.call = proto(c_size_t, c_void_p, c_size_t, c_size_t, c_size_t)(ctypes.cast(f, c_void_p).value)
        self.ref = ctypes.byref(self.s)

    def _window(self, k: int, n: int) -> int:
        """Where macro step ``k`` lies in the arrays, macro steps ``k .. k + n - 1`` there: the grid's doubles are
        computed for :data:`BLOCK` steps at a time (numpy's calls cost tens of us: a block that ends at each scene of
        a logged run, every 34 steps, paid them every time), kept while the blocks fall inside them."""
        w0, wn = self._held
        if w0 <= k and k + n <= w0 + wn:
            return k - w0
        m = max(n, min(BLOCK, self.ex.grid.n_steps - k))
        self._block(k, m)
        self._held = (k, m)
        return 0

    def _block(self, k: int, n: int) -> None:
        """The grid's doubles of macro steps ``k .. k + n - 1`` (as the Python loop gets them) into the arrays."""
        self._held = (0, 0)
        for array, values in zip(self._arrays, self.ex.grid.chunk_arrays(k, k + n)):
            array[:n] = values

    def run(self, k: int, n: int) -> int:
        """Macro steps ``k .. k + n - 1`` (fewer when the wall budget ran out): the steps done. Raises where the
        Python loop raises (:meth:`cosim.fmi.slave.CoSimulation.turn_failed`), after the steps before."""
        ex, sums = self.ex, self.sums
        if self.section is not None and self.section.count >= self.section.cap:
            raise RuntimeError("the log's rows are full: their observer did not hand them over")
        j0 = self._window(k, n)
        j = 0
        for o in sums:
            for p in range(len(o.pairs)):
                self.sq[j], self.mx[j], self.t_mx[j] = o.sq[p], o.mx[p], o.t_mx[p]
                j += 1
        wall, ctime = self.wall, ex.comp_time
        wall[:] = ctime
        self.inside(True)
        try:
            done = self.call(self.ref, k, j0, n)
        finally:
            self.inside(False)
        ctime[:] = wall
        j = 0
        for o in sums:
            for p in range(len(o.pairs)):
                o.sq[p], o.mx[p], o.t_mx[p] = self.sq[j], self.mx[j], self.t_mx[j]
                j += 1
            o.n += done
        ex.k_done = k + done
        failed = done < n and self.s.ended != 0
        if not failed:
            self.ended(k + done, None)
        for o in self.observers:  # the completed steps, also before a failed one (as the Python loop)
            o.stepped(k, done)
        if failed:
            self.ended(k + done, j0 + done)
        return done

    def inside(self, yes: bool) -> None:
        """Say that the loop in C runs (or no longer): the watchdog reads the step's time from the record, and a
        component's log messages are of its turn's time."""
        self.ex.in_c = yes
        for slave in self.slaves:
            slave.in_c_loop = yes

    def ended(self, k: int, j: int | None) -> None:
        """After the calls, at macro step ``k`` (the steps before it done): the components' times; ``j``: the step's
        index in the arrays when one of its turns ended it early, raised here as the Python loop raises."""
        s = self.s
        t_next = self.times[j] if j is not None else self.ex.grid.time(k)
        for slave in self.slaves:
            slave.time = t_next
        if j is not None and s.ended:
            t, h = self.times[j], self.steps[j]
            for slave in self.slaves[: s.failed]:  # their turns in that step completed
                slave.time = t + h
            self.slaves[s.failed].turn_failed(s.ended, t, h)


def _address(view: memoryview) -> int:
    """The address of a writable memoryview's first byte (the execution's shared record)."""
    return ctypes.addressof(ctypes.c_char.from_buffer(view))


def _turn(slave: Any) -> tuple[Turn, bool] | None:
    get = getattr(type(slave), "c_turn", None)  # the class's: a wrapper that delegates attributes has none
    return get(slave) if callable(get) else None


def key(ex: Any) -> tuple:
    """What a loop made for ``ex`` (:func:`make`) depends on: its components, their C turns and its observers (the
    execution keeps its loop while this stays the same)."""
    turns = [_turn(s) for s in ex.slaves]
    return (tuple(map(id, ex.slaves)), tuple(id(t[0]) if t is not None else None for t in turns),
            tuple(map(id, ex.observers)))


def make(ex: Any) -> CLoop | None:
    """The loop in C for execution ``ex`` as it stands (components initialized, links made, observers added), or
    None where the Python loop must run (see the module docstring)."""
    if steps_helper() is None or any(m != 1 for m in ex.multiples):
        return None
    turns = []
    for s in ex.slaves:
        turn = _turn(s)
        if turn is None:
            return None
        turns.append(turn)
    sums = [o for o in ex.observers if getattr(o, "error_sums", False) is True and
            all(getattr(a, "_type_", None) is c_double and getattr(r, "_type_", None) is c_double
                for (a, _), (r, _) in o.pairs)]
    offers = [o.loop_blocks() if callable(getattr(o, "loop_blocks", None)) else None
              for o in ex.observers if o not in sums]
    blocks = all(b is not None for b in offers) and sum(b.rows is not None for b in offers) <= 1
    moves = [_moves(ex, c) for c in range(len(ex.slaves))]
    if any(m is None for m in moves):
        return None
    return CLoop(ex, turns, moves, sums if blocks else [], ex.algorithm.name == "jacobi", blocks,
                 tuple(offers) if blocks else ())


def simulate(ex: Any, loop: CLoop, k_end: int, stop: Any, report: Any, every: int) -> None:
    """Macro steps from ``ex.k_done`` up to ``k_end`` through ``loop``: progress reported every ``every`` steps, a stop
    request answered between blocks, an FMU's end of the simulation handled as the Python loop handles it."""
    k = ex.k_done
    try:
        if not loop.blocks:
            _each(ex, loop, k_end, stop, report, every)
            return
        while k < k_end:
            n = min(k_end - k, BLOCK)
            if report is not None:
                n = min(n, every - k % every)
            for o in loop.observers:
                n = min(n, o.free(k))
            k += loop.run(k, n)
            if report is not None and k % every == 0:
                report(k)
            if stop is not None and stop.requested:
                raise stop.interrupted()
    except Terminated as term:
        ex._end_at(term, ex.k_done, loop.order, [o.stepped for o in ex.observers])


def _each(ex: Any, loop: CLoop, k_end: int, stop: Any, report: Any, every: int) -> None:
    """:func:`simulate` with observers that need Python after every macro step (a log, a live view): one call in C per
    macro step (every turn and link copy of it), then the observers, as the Python loop calls them."""
    stepped, active, call, ref, ends = [o.stepped for o in ex.observers], loop.order, loop.call, loop.ref, loop.ends
    wall, ctime = loop.wall, ex.comp_time
    k = ex.k_done
    wall[:] = ctime
    failed: int | None = None
    loop.inside(True)
    try:
        while k < k_end:
            n = min(k_end - k, BLOCK)
            loop._block(k, n)
            for j in range(n):
                if not call(ref, k, j, 1):
                    failed = j
                    return
                k += 1
                ex.k_done = k
                for f in stepped:
                    f(k - 1, ends[j], active)
                if report is not None and k % every == 0:
                    report(k)
                if stop is not None and stop.requested:
                    raise stop.interrupted()
    finally:
        loop.inside(False)
        ctime[:] = wall
        ex.k_done = k
        loop.ended(k, failed)
