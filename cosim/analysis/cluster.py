"""Where a sweep's cases run (:class:`SweepCluster`): an existing Dask cluster (``--scheduler``), checked to be a Dask
scheduler before anything is built; or, embedded, a pool of worker processes forked from this process once it is
prepared (:class:`ForkPool`).

Why the embedded default is not a Dask ``LocalCluster``: a sweep of short cases never paid for it. Starting one took
about 4 s on the 2-core machine (a scheduler, and each worker a new interpreter importing Dask and the run's code),
so 32 cases of 0.1 s ran at 0.61x the serial loop. Workers forked after the FMUs are built, checked and
extracted start in milliseconds with all of it in memory: each case then forks its supervised child from a worker that
already holds the code, the parsed FMU descriptions and the extracted binaries. What Dask adds, reaching machines
beyond this one, is what ``--scheduler`` is for; on one machine a pool of forked workers does what is needed (a case
at a time per worker, results as they complete), forked as every process of the platform is
(:func:`cosim.procs.start`). Where ``fork`` is missing (not POSIX) the embedded
cluster is Dask's ``LocalCluster``, started in a thread while the FMUs are built."""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import logging
import multiprocessing
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from multiprocessing.connection import Connection
from typing import Any

from .. import procs
from .cases import SweepError

__all__ = ["ForkPool", "PRELOAD", "SweepCluster", "WORKER_CONFIG", "WorkerLost"]

PRELOAD = "cosim.analysis.sweep"
"""The module each embedded worker loads at its start (its ``dask_setup``; ``dask worker --preload`` takes it too)."""



# Dask settings of the embedded cluster's workers. Each case is one long task in the worker's
# single thread; the worker's own threads take the GIL from it. Dask's statistical profiler
# samples the task's stack every 10 ms (with it the workers spent 9-12 % CPU on top of the cases'
# own, without it 1-2 %; measured with 8 cases on 2 workers), and the event-loop tick (20 ms),
# memory monitor (100 ms) and system monitor (500 ms) wake it more often than a sweep needs.
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}


class WorkerLost(RuntimeError):
    """A case's worker ended before it returned the case (killed from outside, or crashed itself)."""


class _Worker:
    """One worker of a :class:`ForkPool`, seen from the sweep's process: its :class:`cosim.procs.Child`, its end of
    the socket pair, the case it runs (a future, None when idle) and its reader thread."""

    def __init__(self, number: int, child: procs.Child, sock: socket.socket, conn: Connection) -> None:
        self.number, self.child, self.sock, self.conn = number, child, sock, conn
        self.running: concurrent.futures.Future | None = None
        self.gone = False
        self.reader: threading.Thread | None = None
        self._reaping = threading.Lock()  # one waiter at a time: a second waitpid would find the child taken

    def name(self) -> str:
        return f"sweep worker {self.number} (pid {self.child.pid})"

    def wait(self, timeout: float) -> int | None:
        """The worker's exit code once it has ended (reaped), None while it still runs after ``timeout`` s."""
        with self._reaping:
            return self.child.wait(timeout)


class ForkPool:
    """The embedded cluster: ``workers`` processes forked from this one through :func:`cosim.procs.start`, each
    running one case at a time. Forked when created: create it once the process holds what every case needs.

    A worker ignores SIGINT (Ctrl-C stops the sweep in this process, which cancels the cases not started and waits
    for those running); it ends with this process (SIGKILL included). A case's crash ends only the child it runs
    in (:func:`cosim.analysis.sweep.run_loaded_case`); a worker killed from outside fails only the case it was
    running (:class:`WorkerLost`, naming the worker and how it ended) and the other workers take the cases left;
    once every worker is gone the cases left fail the same way. Each worker talks to this process over a socket
    pair (:class:`multiprocessing.connection.Connection`: the call ``(fn, args)`` pickled out, ``(ok, value)``
    back), read by one thread per worker here, which hands the next case to the worker as it answers."""

    def __init__(self, workers: int):
        self.n = workers
        self._lock = threading.Lock()
        self._pending: collections.deque = collections.deque()  # (future, fn, args) not handed to a worker yet
        self._workers: list[_Worker] = []
        self._closing = False
        for number in range(1, workers + 1):
            self._workers.append(self._fork(number))
        for w in self._workers:
            w.reader = procs.thread(self._read, w, name=f"sweep-worker-{w.number}-reader")

    def _fork(self, number: int) -> _Worker:
        ours, theirs = socket.socketpair()
        conn = Connection(os.dup(ours.fileno()))  # the socket kept beside it, to shut down (wakes its reader)
        keep = theirs.detach()
        others = [fd for w in self._workers for fd in (w.sock.fileno(), w.conn.fileno())]
        others += [ours.fileno(), conn.fileno()]  # this side's ends, which the child closes
        child = procs.start(_serve, keep, others, name=f"sweep worker {number}", die_with_parent=True,
                            ignore=(signal.SIGINT,))
        os.close(keep)
        return _Worker(number, child, ours, conn)

    def submit(self, fn: Callable[..., Any], *args: Any, **_dask: Any) -> concurrent.futures.Future:
        """``fn(*args)`` on a worker: a :class:`concurrent.futures.Future` (Dask's ``key=`` / ``pure=`` ignored)."""
        future: concurrent.futures.Future = concurrent.futures.Future()
        with self._lock:
            self._pending.append((future, fn, args))
            self._dispatch()
        return future

    def _dispatch(self) -> None:
        """Hand pending cases to idle workers (the lock held); with no worker left, fail them."""
        alive = [w for w in self._workers if not w.gone]
        if not alive:
            while self._pending:
                future, _, _ = self._pending.popleft()
                if future.set_running_or_notify_cancel():
                    future.set_exception(WorkerLost("every sweep worker has ended; the case did not run"))
            return
        for w in alive:
            while w.running is None and not w.gone and self._pending:
                future, fn, args = task = self._pending.popleft()
                if future.cancelled():  # the sweep stopped
                    continue
                try:
                    w.conn.send((fn, args))
                except (OSError, ValueError):  # the worker is gone: its reader says how; the case waits for another
                    self._pending.appendleft(task)
                    w.gone = True
                    continue
                if future.set_running_or_notify_cancel():
                    w.running = future

    def _read(self, w: _Worker) -> None:
        """The reader of worker ``w``: each answer completes its case and hands it the next; its end (EOF) fails
        the case it ran and leaves the rest to the others."""
        while True:
            try:
                ok, value = w.conn.recv()
            except (EOFError, OSError):
                break
            except Exception as exc:  # noqa: BLE001 - an answer that does not unpickle: the case's error
                ok, value = False, WorkerLost(f"{w.name()} answered what cannot be read: {type(exc).__name__}: {exc}")
            with self._lock:
                future, w.running = w.running, None
                self._dispatch()
            if future is None:
                continue
            if ok:
                future.set_result(value)
            else:
                future.set_exception(value)
        with self._lock:
            w.gone = True
            future, w.running = w.running, None
            self._dispatch()
        if future is None:
            return
        if self._closing:  # close() ended the pair: nobody waits for this case any more
            future.set_exception(WorkerLost(f"the sweep stopped before {w.name()} returned the case"))
            return
        code = w.wait(self.CLOSE_WAIT_S)
        how = ("its end not seen" if code is None else f"killed by {signal.Signals(-code).name}" if code < 0
               else f"exit status {code}")
        future.set_exception(WorkerLost(f"{w.name()} ended before it returned the case ({how})"))

    @staticmethod
    def as_completed(futures: Iterable[Any]) -> Iterator[Any]:
        return concurrent.futures.as_completed(futures)

    def pids(self) -> list[int]:
        """The workers' process ids (tests kill them)."""
        return [w.child.pid for w in self._workers]

    CLOSE_WAIT_S = 10.0
    """s the workers get to end once the pool is shut down; one still running then is killed."""

    def close(self) -> None:
        """Cancel the cases not started, let each worker end (its socket closed: it ends after the case it runs),
        within :attr:`CLOSE_WAIT_S`; kill one still running then, and reap every one."""
        with self._lock:
            self._closing = True
            while self._pending:
                self._pending.popleft()[0].cancel()
        for w in self._workers:
            try:
                w.sock.shutdown(socket.SHUT_RDWR)  # the worker and its reader here see the end
            except OSError:
                pass
        deadline = time.monotonic() + self.CLOSE_WAIT_S
        for w in self._workers:
            if w.wait(max(0.0, deadline - time.monotonic())) is None:
                w.child.kill()
                w.wait(1.0)
            if w.reader is not None:
                w.reader.join(1.0)
            w.conn.close()
            w.sock.close()


def _serve(fd: int, others: list[int]) -> int:
    """A worker's life: the other ends of every socket pair closed (a worker must see EOF when the sweep closes its
    own), then each ``(fn, args)`` received run and ``(True, result)`` or ``(False, exception)`` sent back, until the
    sweep closes the pair."""
    for other in others:
        procs.close_fd(other)
    _worker_start()
    conn = Connection(fd)
    while True:
        try:
            fn, args = conn.recv()
        except (EOFError, OSError):
            return 0
        try:
            answer = (True, fn(*args))
        except Exception as exc:  # noqa: BLE001 - the case's error, raised in the sweep's process by its future
            answer = (False, exc)
        try:
            conn.send(answer)
        except (OSError, ValueError):
            return 0
        except Exception as exc:  # noqa: BLE001 - an answer that does not pickle: said as text
            conn.send((False, RuntimeError(f"{type(exc).__name__}: the case's answer cannot be sent: {exc}")))


def _worker_start() -> None:
    """In each forked worker: standard streams of its own on the same file descriptors. The sweep's progress bar
    writes from a thread of the sweep's process: a stream's lock that thread held at the fork would stay held in the
    worker, and the first flush here (a case's child ending, the worker's own exit) would wait for ever. What the
    sweep's process had buffered is not written twice either (:func:`cosim.procs.start` flushed it before the
    fork)."""
    for name, errors in (("stdout", "strict"), ("stderr", "backslashreplace")):
        old = getattr(sys, name)
        fd = 1 if name == "stdout" else 2
        setattr(sys, name, open(fd, "w", encoding=getattr(old, "encoding", None) or "utf-8", errors=errors,
                                closefd=False, buffering=1))


def can_fork() -> bool:
    """Whether the embedded cluster is a :class:`ForkPool` (POSIX ``fork``) rather than Dask's ``LocalCluster``."""
    return "fork" in multiprocessing.get_all_start_methods()


class SweepCluster:
    """Where cases run: a Dask client on ``scheduler`` (an existing cluster), or the embedded cluster: a
    :class:`ForkPool`, or where ``fork`` is missing a Dask ``LocalCluster``.

    :meth:`start` probes the scheduler, or starts a ``LocalCluster`` in a thread (the caller builds the FMUs
    meanwhile); ``with`` forks the pool (the caller has prepared this process) or waits for the cluster, and yields
    ``(client, label)``; :meth:`close` if ``with`` is never entered.
    """

    CONNECT_TIMEOUT = 10.0
    """s, for an existing scheduler to accept a connection, answer Dask's handshake and say it is a scheduler."""

    def __init__(self, workers: int | None, scheduler: str | None):
        self.workers, self.scheduler = workers, scheduler
        self.cluster = self.client = self._thread = None
        self._error: BaseException | None = None
        self._scratch: str | None = None  # the embedded workers' folder, removed with the cluster
        self.forks = scheduler is None and can_fork()
        self.pool: ForkPool | None = None
        self._started = False

    def start(self) -> "SweepCluster":
        self._started = True
        logging.getLogger("distributed").setLevel(logging.ERROR)  # the process's: the cluster's and the client's
        if self.forks:
            return self
        if self.scheduler is None:
            self._thread = procs.thread(self._start_local, name="sweep-cluster-start")
        else:
            self._probe()
        return self

    def _probe(self) -> None:
        """Check that ``scheduler`` is a Dask scheduler, within :attr:`CONNECT_TIMEOUT`, before anything is built:
        Dask's client waits for ever on a silent listener, and reads an HTTP answer as a frame of 3 EiB."""

        from distributed.comm import connect  # lazy: --help loads this module without it

        address, timeout = self.scheduler, self.CONNECT_TIMEOUT

        async def identity() -> dict:
            comm = await connect(address, timeout=timeout)
            try:
                await comm.write({"op": "identity", "reply": True})
                return await comm.read()
            finally:
                comm.abort()

        try:  # connect() retries a refused connection for ``timeout``, then its handshake waits for ever: bounded
            answer = asyncio.run(asyncio.wait_for(identity(), timeout + 1.0))
        except TimeoutError:
            # Refused (security): a peer that accepts and never answers would hold the sweep for ever
            raise SweepError(f"--scheduler {address}: no answer from {address} within {timeout:g} s (it accepted "
                             f"the connection: is it a Dask scheduler?)") from None
        except ValueError as exc:  # parse_address: not an address of a comm Dask knows
            # Refused (correctness): an address we cannot read: where the cases go is a guess
            raise SweepError(f"--scheduler {address}: not a scheduler address ({exc}); expected tcp://HOST:PORT") \
                from None
        except OSError as exc:  # distributed's CommClosedError too: refused, or closed during the handshake
            if str(exc).startswith("Timed out trying to connect"):
                # Refused (correctness): no scheduler there: the cases would go nowhere
                raise SweepError(f"--scheduler {address}: cannot connect to {address} within {timeout:g} s "
                                 f"({_comm_reason(exc.__cause__ or exc)})") from None
            # Refused (correctness): not a scheduler: the cases would go nowhere
            raise SweepError(f"--scheduler {address}: {address} is not a Dask scheduler (it closed the connection "
                             f"in Dask's handshake: {_comm_reason(exc)})") from None
        except Exception:  # noqa: BLE001 - an answer in another protocol: a frame of 3 EiB, undecodable, ...
            # Refused (security): another protocol's answer (a frame of 3 EiB) is not read further
            raise SweepError(f"--scheduler {address}: {address} is not a Dask scheduler (its answer is not "
                             f"Dask's protocol)") from None
        if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
            kind = answer.get("type") if isinstance(answer, dict) else None
            # Refused (correctness): not a scheduler: the cases would go nowhere
            raise SweepError(f"--scheduler {address}: {address} is not a Dask scheduler"
                             + (f" (a Dask {kind})" if kind else ""))

    def _start_local(self) -> None:
        try:

            import dask  # lazy: --help loads this module without it
            from distributed import LocalCluster  # lazy: --help loads this module without it

            n = self.workers or os.cpu_count() or 1
            self._scratch = tempfile.mkdtemp(prefix="cosim-sweep-")  # not dask-scratch-space, left in the temp folder
            config = {**WORKER_CONFIG, "temporary-directory": self._scratch}  # the scheduler's and workers' folders
            with dask.config.set(config):  # the nannies hand this configuration to their workers
                self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                            dashboard_address=None, silence_logs=logging.ERROR,
                                            preload=[PRELOAD],  # its dask_setup
                                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})  # not 8787
        except BaseException as exc:  # noqa: BLE001 - raised in the caller's thread by __enter__
            self._error = exc

    def __enter__(self):
        if not self._started:
            self.start()
        n = self.workers or os.cpu_count() or 1
        if self.forks:
            self.pool = ForkPool(n)
            return self.pool, f"{n} local worker process{'es' if n > 1 else ''}"
        from distributed import Client  # lazy: --help loads this module without it

        if self.scheduler is not None:
            try:
                self.client = Client(self.scheduler, timeout="10s")
            except OSError as exc:
                # Refused (correctness): no scheduler there: the cases would go nowhere
                raise SweepError(f"--scheduler {self.scheduler}: cannot connect: {exc}") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            return self.client, f"{self.scheduler} ({n} workers)"
        try:
            self._thread.join()
            if self._error is not None:
                raise self._error
            self.client = Client(self.cluster)
        except BaseException:
            self.close()
            raise
        n = len(self.cluster.workers)
        return self.client, f"{n} local worker process{'es' if n > 1 else ''}"

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.close()
            self.pool = None
        if self._thread is not None:
            self._thread.join()
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)
            self._scratch = None


def _comm_reason(exc: BaseException) -> str:
    """distributed's comm error without its ``in <TCP ...>:`` prefix (``ConnectionRefusedError: [Errno 111] ...``);
    an error without text (a connect attempt that timed out on a loaded machine) by its kind."""
    text = re.sub(r"^in <[^>]*>: ", "", str(exc)).strip()
    return text or f"{type(exc).__name__}: the last attempt gave no reason"
