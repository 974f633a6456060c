"""Every process the platform starts, started one way: :func:`start` (and its threads: :func:`thread`).

Five kinds of child (docs/master.md draws who starts whom, what each owns and how each ends):

- the run's supervised child (:func:`cosim.engine.supervision.supervise`): a fork that goes on with the command
  (``target`` None: :func:`start` returns None in the child);
- a contained call (:func:`cosim.engine.supervision.contained`, a sweep's case): a fork that runs one function;
- a sweep's pool worker (:class:`cosim.analysis.cluster.ForkPool`): a fork that runs the cases it is handed over a
  socket pair;
- the offload worker (:mod:`cosim.engine.offload`): a :mod:`multiprocessing` process (fork, or spawn off Linux and on
  Python 3.12+), the one way to hand a child multiprocessing's shared ring and semaphores;
- the log writer (:mod:`cosim.observers.log_writer`): a fork, or a new interpreter (``how="exec"``) where a fork
  is not safe.

The conventions, the same for each child, applied in the child before it runs anything of its own
(:meth:`Rules.enter`; an exec'd child calls :func:`entered` first, which reads them from its environment):

- **group**: ``"own"`` (``setpgid``: a process group of its own, so that a terminal's signals reach its parent
  only, which forwards them, and the parent can kill the group), ``"session"`` (``setsid``: out of reach of the
  terminal's and of the group's signals), or None (the parent's group);
- **signals**: those in ``ignore`` are ignored, those in ``default`` take their default action (no handler of the
  parent runs in a child). A child that runs a function writes nothing to its parent's signal wakeup descriptor
  (``signal.set_wakeup_fd(-1)``);
- **parent**: with ``die_with_parent`` the child is killed when its parent dies, however it dies
  (``PR_SET_PDEATHSIG`` on Linux), and leaves at once if its parent is already gone;
- **pipes**: with ``pipes`` the child's standard input, output and error are pipes to the parent (:attr:`Child.stdin`,
  :attr:`Child.stdout`, :attr:`Child.stderr`: binary files, stdin unbuffered); with ``close_fds`` every other
  descriptor it inherited is closed (a live view's port, the log's claim, FMU files). Before a fork the parent's
  standard output and error are flushed, so a child never writes the parent's buffered text a second time;
- **exit**: a child that runs a function leaves through :func:`cosim.errors.exit_now` with the function's return
  value (None: 0): its own output flushed, then ``os._exit``, never the parent's ``atexit`` handlers, temporary
  folders or the interpreter's finalization. An exception that escapes the function is written to its stderr,
  status :data:`EX_SOFTWARE`;
- **reaping**: the parent reaps through the :class:`Child` (:meth:`~Child.poll`, :meth:`~Child.wait`,
  :meth:`~Child.alive`, :meth:`~Child.kill`), ``returncode`` as ``subprocess.Popen``'s (negative: the signal that
  ended it).

This module imports the standard library and :mod:`cosim.errors` only: the log's exec'd writer loads it at start.
"""

from __future__ import annotations

import ctypes
import errno
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time
import traceback
import warnings
from dataclasses import asdict, dataclass, replace
from typing import Any, Callable, Iterable

from .errors import exit_now

__all__ = ["Child", "EX_SOFTWARE", "Rules", "close_fd", "die_with_parent", "entered", "open_fd", "start", "thread"]

EX_SOFTWARE = 70
"""Exit status of a child whose function raised (sysexits' ``EX_SOFTWARE``)."""

_ENV = "COSIM_CHILD"  # an exec'd child's rules, as JSON (read by entered())


@dataclass(frozen=True)
class Rules:
    """A child's conventions (see the module docstring), applied in the child by :meth:`enter`."""

    group: str | None = None  # "own", "session" or None
    ignore: tuple[int, ...] = ()
    default: tuple[int, ...] = ()
    parent: int | None = None  # die with this process (the parent's pid when the child was started)

    def enter(self) -> None:
        try:
            if self.group == "own":
                os.setpgid(0, 0)
            elif self.group == "session":
                os.setsid()
        except OSError:  # already a group or session leader: it stays where it is
            pass
        for sig, action in [*((s, signal.SIG_IGN) for s in self.ignore), *((s, signal.SIG_DFL) for s in self.default)]:
            try:
                signal.signal(sig, action)
            except ValueError:  # not the main thread (a child forked from another thread keeps its handlers)
                pass
        if self.parent is not None:
            _die_with(self.parent)


def _die_with(parent: int) -> None:
    """End this process when ``parent`` ends, however it ends (SIGKILL included): the kernel's parent-death signal on
    Linux; everywhere, an exit now when it has already ended (a child that outlives its parent elsewhere finds out
    by itself: the offload worker compares ``os.getppid()`` while it waits)."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:
        exit_now(0)


def die_with_parent() -> None:
    """For a process another library forked (a process pool's worker): end it when its parent ends, SIGKILL
    included, as :func:`start`'s ``die_with_parent`` does for ours."""
    _die_with(os.getppid())


def entered() -> None:
    """Apply the rules :func:`start` gave an exec'd child (its first call; nothing when it was not started so)."""
    text = os.environ.pop(_ENV, None)
    if text:
        data = json.loads(text)
        Rules(data.get("group"), tuple(data.get("ignore", ())), tuple(data.get("default", ())),
              data.get("parent")).enter()


class Child:
    """A child started by :func:`start`, seen from its parent: ``pid``, ``name``, the pipes (``stdin``, ``stdout``,
    ``stderr``: None without ``pipes``), ``returncode`` (None until it is reaped) and, for a fork, ``status``: the
    raw wait status (``os.WIFSIGNALED`` tells a crash from an exit; None until it is reaped)."""

    def __init__(self, pid: int, name: str, *, stdin: Any = None, stdout: Any = None, stderr: Any = None,
                 popen: subprocess.Popen | None = None, process: Any = None) -> None:
        self.pid, self.name = pid, name
        self.stdin, self.stdout, self.stderr = stdin, stdout, stderr
        self.returncode: int | None = None
        self.status: int | None = None
        self._popen, self._process = popen, process

    def _reaped(self, status: int) -> None:
        self.status, self.returncode = status, os.waitstatus_to_exitcode(status)

    def poll(self) -> int | None:
        """Reap the child if it has ended: its exit code, else None."""
        if self.returncode is None:
            if self._popen is not None:
                self.returncode = self._popen.poll()
            elif self._process is not None:
                if not self._process.is_alive():  # reaps it
                    self.returncode = self._process.exitcode
            else:  # raises ChildProcessError when another waiter took it
                pid, status = os.waitpid(self.pid, os.WNOHANG)
                if pid:
                    self._reaped(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int | None:
        """Wait for the child's end and reap it: its exit code, or None when it still runs after ``timeout`` s."""
        if self.returncode is not None:
            return self.returncode
        if self._popen is not None:
            try:
                self.returncode = self._popen.wait(timeout)
            except subprocess.TimeoutExpired:
                return None
        elif self._process is not None:
            self._process.join(timeout)
            return self.poll()
        elif timeout is None:
            self._reaped(os.waitpid(self.pid, 0)[1])
        else:
            deadline = time.monotonic() + timeout
            while self.poll() is None:
                if time.monotonic() > deadline:
                    return None
                time.sleep(0.005)
        return self.returncode

    def alive(self) -> bool:
        return self.poll() is None

    def kill(self, signum: int = signal.SIGKILL, group: bool = False) -> None:
        """Send ``signum`` (default SIGKILL) to the child, or to its process group; nothing once it is reaped (its
        pid may be another process's by then)."""
        if self.returncode is not None:
            return
        try:
            (os.killpg if group else os.kill)(self.pid, signum)
        except ProcessLookupError:
            pass


def start(target: Callable[..., int | None] | None, *args: Any, name: str, how: str = "fork",
          via_multiprocessing: bool = False, argv: list[str] | None = None, env: dict[str, str] | None = None,
          group: str | None = None, ignore: Iterable[int] = (), default: Iterable[int] = (),
          die_with_parent: bool = False, pipes: bool = False, close_fds: bool = False) -> Child | None:
    """Start a child (the conventions: see the module docstring) and return its :class:`Child`.

    ``how``: ``"fork"`` (``os.fork``; ``target`` None: the child goes on from here, and this returns None in it),
    ``"spawn"`` (a new interpreter through :mod:`multiprocessing`, ``target`` and ``args`` pickled) or ``"exec"``
    (``argv``, with ``env``: a new program, which calls :func:`entered` first). ``via_multiprocessing``: a fork made
    by :mod:`multiprocessing` (``args`` may then hold its shared objects, as for a spawn). ``name``: the child's
    name (a multiprocessing process's ``name``; messages). ``pipes`` and ``close_fds``: a fork or an exec.
    """
    rules = Rules(group, tuple(ignore), tuple(default), os.getpid() if die_with_parent else None)
    if how == "exec":
        return _exec(argv or [], env, rules, name, pipes)
    if how == "spawn" or via_multiprocessing:
        process = multiprocessing.get_context(how).Process(target=_run, args=(rules, target, args), name=name,
                                                           daemon=True)
        process.start()
        return Child(process.pid, name, process=process)
    return _fork(target, args, rules, name, pipes, close_fds)


def _fork(target: Callable[..., int | None] | None, args: tuple, rules: Rules, name: str, pipes: bool,
          close_fds: bool) -> Child | None:
    ends = [os.pipe() for _ in range(3)] if pipes else []  # (read, write) of the child's stdin, stdout, stderr
    theirs = (ends[0][0], ends[1][1], ends[2][1]) if pipes else ()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    with warnings.catch_warnings():  # Python >= 3.12 warns of any other OS thread (OpenBLAS' idle pool): the
        warnings.simplefilter("ignore", DeprecationWarning)  # children call none of them
        pid = os.fork()
    if pid == 0:
        if target is None:
            rules.enter()
            return None
        _run(rules, target, args, theirs, [fd for pair in ends for fd in pair], close_fds)
    for fd in theirs:
        os.close(fd)
    if not pipes:
        return Child(pid, name)
    return Child(pid, name, stdin=os.fdopen(ends[0][1], "wb", buffering=0), stdout=os.fdopen(ends[1][0], "rb"),
                 stderr=os.fdopen(ends[2][0], "rb"))


def _run(rules: Rules, target: Callable[..., int | None], args: tuple, fds: tuple[int, ...] = (),
         pipes: Iterable[int] = (), close_fds: bool = False) -> None:
    """A child's life: its rules, its ends of the pipes as its standard streams (``fds``; every descriptor of the
    ``pipes`` closed then), ``target(*args)``, its exit. Never returns."""
    code = EX_SOFTWARE
    try:
        rules.enter()
        for std, fd in enumerate(fds):
            os.dup2(fd, std)
        if close_fds:
            os.closerange(3, _max_fd())
        else:
            for fd in set(pipes) - {0, 1, 2}:
                os.close(fd)
        try:
            signal.set_wakeup_fd(-1)  # the parent's wakeup pipe (its watchdog's) is never the child's to write
        except ValueError:
            pass
        result = target(*args)
        code = 0 if result is None else int(result)
    except SystemExit as stop:
        code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    except BaseException:  # noqa: BLE001 - nothing escapes a child into its parent's code: said on its stderr
        try:
            os.write(2, traceback.format_exc().encode(errors="replace"))
        except OSError:
            pass
    finally:
        exit_now(code)


def _exec(argv: list[str], env: dict[str, str] | None, rules: Rules, name: str, pipes: bool) -> Child:
    env = dict(os.environ if env is None else env)
    env[_ENV] = json.dumps(asdict(replace(rules, group=None)))  # the group is made here, by Popen
    pipe = subprocess.PIPE if pipes else None
    popen = subprocess.Popen(argv, stdin=pipe, stdout=pipe, stderr=pipe, bufsize=0, env=env,
                             start_new_session=rules.group == "session",
                             process_group=0 if rules.group == "own" else None)
    return Child(popen.pid, name, stdin=popen.stdin, stdout=popen.stdout, stderr=popen.stderr, popen=popen)


def _max_fd() -> int:
    try:
        return min(os.sysconf("SC_OPEN_MAX"), 1 << 16)
    except (ValueError, OSError):
        return 4096


def thread(target: Callable[..., Any], *args: Any, name: str) -> threading.Thread:
    """A daemon thread of this process, started: it never keeps the process from ending (the watchdog, a sweep's
    cluster start)."""
    t = threading.Thread(target=target, args=args, name=name, daemon=True)
    t.start()
    return t


def _unless_closed(op: Callable[[int], Any], fd: int) -> bool:
    """``op(fd)``: True, or False when ``fd`` was closed behind its owner's back (EBADF)."""
    try:
        op(fd)
    except OSError as exc:
        if exc.errno == errno.EBADF:
            return False
        raise
    return True


def open_fd(fd: int) -> bool:
    """Whether descriptor ``fd`` is open: False once something closed it behind its owner's back (a component that
    closes every descriptor it did not open, as a careless daemonising library does)."""
    return _unless_closed(os.fstat, fd)


def close_fd(fd: int) -> bool:
    """Close descriptor ``fd`` at the end of its use: True, or False when it was already closed behind our back
    (the owner says so where it matters, see :func:`open_fd`)."""
    return _unless_closed(os.close, fd)
