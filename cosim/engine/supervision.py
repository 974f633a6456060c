"""A run's supervisor: the command line's run goes on in a child process, and its parent names a crash.

An FMU is foreign code inside our process: a segfault, an ``abort()`` or an ``exit()`` in ``doStep`` ends
the process with no Python frame left to say which component, and a PythonFMU FMU called with the Python
lock held can keep the watchdog's thread from ever running. So ``python -m cosim run`` forks once before
anything is loaded (:func:`supervise`): the child runs as it always did; the parent only waits, and reads
what the child's :class:`~cosim.engine.execution.Execution` keeps in a shared record (:class:`Record`: the
component with the turn, the macro step's time, the phase, the steps done; the component names and the
log's paths once the run starts). It costs the hot loop nothing but those stores.

When the child dies without finishing (a signal, or an exit that is not ours), the parent says which
component, in which phase, at which simulation time; recovers the log written so far into its target
(:func:`cosim.io.recover.recover`: every complete record up to the crash; a log written by a writer process
has every step sent before the crash) and removes the partial file and the claim's lock. It is also the
backstop of the watchdog and of the stop signals: the signals are forwarded once (the child runs in its
own process group, so a terminal's Ctrl-C reaches it through its parent only once), and a child that does
not end within its grace after a stop signal, or makes no progress for its watchdog budget plus the grace
while its own watchdog could not act, is killed and named the same way.
"""

from __future__ import annotations

import json
import mmap
import os
import pickle
import select
import signal
import sys
import time
from typing import Any, Callable

from .. import procs
from ..errors import STOP_SIGNALS, Interrupted, exit_status, exit_text, printable

__all__ = ["Record", "supervise", "contained", "record", "finished", "command_pid", "ENABLED", "MASTER", "PHASES",
           "WAITING"]

MASTER = -1
"""``current[0]`` when no component has the turn (the master between turns, its observers)."""
PHASES = ("initialization", "step", "termination", "waiting")
"""``current[2]``: the phase of the run, by index; ``waiting``: the run waits on purpose before its first step (for a
live view's first viewer, ``run --live-wait``), which the watchdogs take for progress, not a stall."""
WAITING = PHASES.index("waiting")

ENABLED = False
"""Set by ``python -m cosim`` (never by a library user's process, which must not be forked)."""

_FIELDS = 5  # component, time (s), phase, steps done, finished (1.0 once the child ends through our exit)
_INFO = 32 * 1024  # JSON of the run's description after the fields (names, log paths, watchdog budget)
_POLL_S = 0.05
_GRACE_S = 2.0  # the engine watchdog's grace (cosim.engine.watchdog.GRACE_S) is 2 s: ours comes after it
_STOP_WAIT_S = 3 * _GRACE_S + 1.0  # after a forwarded stop signal: the child's own grace, its hard abort, a margin
_HURRY = [False]  # a stop signal came: a log writer left by a dead run is waited for _WRITER_STOP_WAIT_S only
_WRITER_STOP_WAIT_S = 1.0
_WRITER_WAIT_S = 10.0  # a log writer process finishing what it received before its master died


class Record:
    """A small shared-memory record: ``current`` (doubles: component, start time, phase, steps done, finished) and the run's
    description (JSON). Anonymous and shared: written by one process, readable by the processes forked after
    it was made (the supervisor's child writes, the supervisor reads)."""

    def __init__(self) -> None:
        self._mm = mmap.mmap(-1, _FIELDS * 8 + _INFO)
        self.current = memoryview(self._mm)[: _FIELDS * 8].cast("d")
        self.current[0], self.current[2] = MASTER, 0

    def describe(self, **info: Any) -> None:
        """Store the run's description (merged with what is there): names, log paths, watchdog budget."""
        data = json.dumps({**self.info(), **info}).encode()[: _INFO - 4]
        self._mm[_FIELDS * 8: _FIELDS * 8 + 4] = len(data).to_bytes(4, "little")
        self._mm[_FIELDS * 8 + 4: _FIELDS * 8 + 4 + len(data)] = data

    def info(self) -> dict:
        n = int.from_bytes(self._mm[_FIELDS * 8: _FIELDS * 8 + 4], "little")
        if not n:
            return {}
        try:
            return json.loads(self._mm[_FIELDS * 8 + 4: _FIELDS * 8 + 4 + n])
        except ValueError:
            return {}

    def where(self) -> str:
        """``component 'ctl' in its step at t = 1.234 s`` (or the master's part), from the record."""
        c, phase, steps = int(self.current[0]), PHASES[int(self.current[2]) % len(PHASES)], self.current[3]
        info = self.info()
        names = info.get("names") or []
        # the macro step's start: the grid's point of the steps done (described at the start of the run)
        t = info["start_s"] + steps * info["step_s"] if "step_s" in info else self.current[1]
        if c == MASTER or not 0 <= c < len(names):
            return f"the master ({phase}, t = {t:.6g} s)"
        what = "its step" if phase == "step" else f"its {phase}"
        return f"component {printable(names[c])!r} in {what} at t = {t:.6g} s"


_RECORD: Record | None = None
_SUPERVISOR: int | None = None  # the supervisor's pid, in its child


def command_pid() -> int:
    """The pid of the command the user started: the supervisor's in a supervised run (signals sent to it reach
    the run), else this process's."""
    return _SUPERVISOR if _SUPERVISOR is not None else os.getpid()


def record() -> Record | None:
    """The record this process writes for its supervisor (None when it is not a supervised run)."""
    return _RECORD


def finished(message: str | None = None) -> None:
    """The supervised child ends through our own exit: whatever its exit code, it is not a crash; ``message``: the
    error it printed, if any (a :func:`contained` call returns it)."""
    if _RECORD is not None:
        if message is not None:
            _RECORD.describe(exit_message=message)
        _RECORD.current[4] = 1.0


def supervise(on_crash: Callable[[Record, str], int]) -> int | None:
    """Fork (when :data:`ENABLED`): returns None in the child, which goes on with the run; in the parent,
    waits for the child and returns its exit code, or ``on_crash(record, reason)``'s when it died without
    finishing (``reason``: ``crashed (SIGSEGV)``, ``exited with status 3``, ``was killed: no progress ...``).
    Without fork or when not enabled, returns None at once (the run goes on in this process, unsupervised)."""
    global _RECORD, _SUPERVISOR
    if not ENABLED or not hasattr(os, "fork") or os.environ.get("COSIM_SUPERVISE", "1") == "0":
        return None
    rec = Record()
    parent = os.getpid()
    # a group of its own: terminal signals reach the parent only, which forwards each once
    child = procs.start(None, name="run", group="own", die_with_parent=True)
    if child is None:
        _RECORD, _SUPERVISOR = rec, parent
        return None
    return _wait(child, rec, on_crash)


_RESULT_BYTES = 16 * 1024 * 1024  # a contained call's pickled result (anonymous: only the pages written are used)


def contained(fn: Callable[[], Any]) -> tuple[Any, str | None, Record]:
    """``fn()`` in a forked child process, supervised as ``python -m cosim run`` is: ``(fn's result, None, record)``
    when it returned; ``(None, why, record)`` when the child did not: it died inside a component (``why``:
    ``component 'src' in its step at t = 0.004 s crashed (SIGSEGV)``), left through :func:`hard_exit` (a stalled
    component: the error it printed), or was killed after no progress for its watchdog budget plus the grace.

    For a sweep's case in a Dask worker: a crash takes the child, never the worker and its other cases. ``fn`` runs
    with the child's :func:`record`, which the run's execution writes; what it returns must pickle (an exception it
    raises is returned as its ``why``, ``TypeName: text``). Not for the main thread of ``python -m cosim`` (its
    stop signals are not forwarded: the child leaves with its parent, ``PR_SET_PDEATHSIG``). POSIX only."""
    rec = Record()
    out = mmap.mmap(-1, _RESULT_BYTES)
    ending, ends = os.pipe()
    # a group of its own: the supervisor kills the whole group (the log writer, the offload worker)
    child = procs.start(_contained_child, fn, rec, out, ending, ends, name="contained", group="own",
                        die_with_parent=True)
    pid = child.pid
    os.close(ends)
    try:
        status, reason = _watch(child, rec, [], ending)
        n = int.from_bytes(out[:8], "little")
        if reason is None:
            _leftovers(pid)
        if reason is None and n:
            ok, value = pickle.loads(out[8:8 + n])
            return (value, None, rec) if ok else (None, value, rec)
        if reason is None and rec.current[4] == 1.0:  # our own exit without a result: the error it printed
            reason = rec.info().get("exit_message") or f"ended with status {os.waitstatus_to_exitcode(status)}"
            return None, reason, rec
        return None, f"{rec.where()} {reason or _death(pid, status, rec)}", rec
    finally:
        out.close()
        os.close(ending)


def _contained_child(fn: Callable[[], Any], rec: Record, out: mmap.mmap, ending: int, ends: int) -> int:
    """The child of :func:`contained`: ``fn()``'s result (or its exception, as text) pickled into ``out``, then a byte
    on ``ends``; its exit status (:func:`cosim.procs.start` leaves with it; a failure here: the status it sets)."""
    global _RECORD
    os.close(ending)
    _RECORD = rec
    try:
        data = pickle.dumps((True, fn()))
    except BaseException as exc:  # noqa: BLE001 - said to the parent, as text (an exception may not pickle)
        data = pickle.dumps((False, f"{type(exc).__name__}: {exc}"))
    if len(data) > _RESULT_BYTES - 8:
        data = pickle.dumps((False, f"the result is {len(data):,} bytes, more than {_RESULT_BYTES - 8:,}"))
    out[8:8 + len(data)] = data
    out[:8] = len(data).to_bytes(8, "little")
    rec.current[4] = 1.0
    os.write(ends, b"\0")
    return 0


def _wait(child: procs.Child, rec: Record, on_crash: Callable[[Record, str], int]) -> int:
    """The command's exit code once the ``child`` ended: its own, or ``on_crash``'s when it died or was killed;
    after a stop signal the code of that signal (128 + its number, 143 for SIGTERM) whatever it took to stop the
    child (one that ignored the signal and busy-looped was killed and ended with 2)."""
    pid = child.pid
    stopped_at: list[float] = []
    first: list[int] = []

    def forward(signum: int, frame: Any) -> None:
        _HURRY[0] = True  # once the child ended, its log writer gets a short grace only
        if not stopped_at:
            stopped_at.append(time.monotonic())
            first.append(signum)
        try:
            os.kill(pid, signum)
        except ProcessLookupError:
            pass

    def remember(signum: int, frame: Any) -> None:  # the child is gone: the crash's report, then this signal's code
        if not first:
            first.append(signum)
        _HURRY[0] = True  # a log writer still finishing gets a short grace only; what it wrote is recovered

    previous = {s: signal.signal(s, forward) for s in STOP_SIGNALS}
    try:
        status, reason = _watch(child, rec, stopped_at)
        if reason is None and rec.current[4] == 1.0:  # ended through our exit: its code is the command's
            _leftovers(pid)
            code = os.waitstatus_to_exitcode(status)
            if first and code == 0:  # a stop signal the child got (or missed) as it ended, after its last look:
                # honoured as by a process without a supervisor, which the signal ends with 128 + N at any time
                print(exit_text(*exit_status(Interrupted(first[0]))[:2]), file=sys.stderr)
                return 128 + first[0]
            return code
        for s in STOP_SIGNALS:  # a stop now must not cut the crash's handling short (report, writer, recovery)
            signal.signal(s, remember)
        code = on_crash(rec, reason or _death(pid, status, rec))
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        _HURRY[0] = False
    return 128 + first[0] if first else code


def _watch(child: procs.Child, rec: Record, stopped_at: list[float],
           wake: int | None = None) -> tuple[int, str | None]:
    """Wait for the forked ``child`` (:class:`cosim.procs.Child`, which reaps it): (its wait status, None) once it
    ended; (its wait status, why) when it was killed here: no end within :data:`_STOP_WAIT_S` of a stop signal
    (``stopped_at``), or no progress in ``rec`` for its watchdog budget plus the grace. The log writer process is
    waited for after a kill. ``wake``: a pipe the child writes a byte to just before it ends (its end is then seen at
    once, not at the next poll)."""
    seen, since = tuple(rec.current[:4]), time.monotonic()
    pause = _POLL_S
    while True:
        try:
            if child.poll() is not None:
                return child.status, None
        except ChildProcessError:
            return 0, "was lost (no such child process)"
        now = time.monotonic()
        state = tuple(rec.current[:4])  # component, time, phase, steps: any change is progress, and a wait on purpose
        if state != seen or state[2] == WAITING:
            seen, since = state, now
        budget = rec.info().get("watchdog_s")
        reason = None
        if stopped_at and now - stopped_at[0] > _STOP_WAIT_S:
            reason = f"did not stop within {_STOP_WAIT_S:g} s of the stop signal: killed"
        elif budget and now - since > budget + 2 * _GRACE_S:
            writer = rec.info().get("writer_pid")
            if writer and _stopped(writer):  # the run blocked on its log's pipe: name what stopped it
                reason = f"waited {now - since:.3g} s on the log writer (pid {writer}), which is stopped (SIGSTOP, " \
                         "a debugger or job control): the run was killed and the writer resumed to write what it had"
            else:
                reason = f"made no progress for {now - since:.3g} s (watchdog {budget:g} s) and could not be " \
                         f"stopped from inside: killed"
        if reason is not None:
            try:
                os.killpg(child.pid, signal.SIGKILL)
            except ProcessLookupError:  # not a group of its own (its setpgid failed): the child alone
                os.kill(child.pid, signal.SIGKILL)
            child.wait()
            _wait_for_writer(rec)
            return child.status, reason
        if wake is None:
            time.sleep(pause)
        elif select.select([wake], [], [], _POLL_S)[0]:
            os.read(wake, 1)
            wake, pause = None, 0.001  # it is ending: see its end soon


def _leftovers(pid: int) -> None:
    """Kill what is left of the process group of the child ``pid`` after it ended well: processes an FMU started
    and left running (they held the command's output pipe open, so ``cosim run | cat`` never ended). The log
    writer runs in a session of its own and has finished by then."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):  # nothing left (the usual case)
        pass


def _death(pid: int, status: int, rec: Record) -> str:
    """How a child that did not end through our exit died (``crashed (SIGSEGV)``); what is left of its process group
    is killed (the offload worker dies with it by itself) and its log writer waited for."""
    if os.WIFSIGNALED(status):
        reason = f"crashed ({signal.Signals(os.WTERMSIG(status)).name})"
    else:
        reason = f"exited with status {os.WEXITSTATUS(status)} (an exit() inside a component)"
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    _wait_for_writer(rec)
    return reason


def _stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (its state T or t in ``/proc``; False where there is no ``/proc``)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("T", "t")
    except (OSError, IndexError):
        return False


def _wait_for_writer(rec: Record) -> None:
    """Wait (bounded) for the log writer process, which writes what it received and ends by itself once its
    master's pipe is closed; killed after :data:`_WRITER_WAIT_S`, or :data:`_WRITER_STOP_WAIT_S` once a stop signal
    came (SIGTERM in this wait cut the crash's handling short: no report, the writer left running, nothing
    recovered)."""
    pid = rec.info().get("writer_pid")
    start = time.monotonic()
    if pid:
        try:
            os.kill(pid, signal.SIGCONT)  # a stopped writer writes what it received, then ends (its pipe closed)
        except ProcessLookupError:
            return
    while pid:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        waited = time.monotonic() - start
        if waited > _WRITER_WAIT_S or (_HURRY[0] and waited > _WRITER_STOP_WAIT_S):  # kill it, keep what it wrote
            os.kill(pid, signal.SIGKILL)
            return
        time.sleep(_POLL_S)
