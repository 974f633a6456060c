"""Parallel co-simulation: the feed-forward components run ahead in a worker process.

A component whose inputs all come from components that are themselves free of feedback
(in helix_ctc the trajectory and the inverse kinematics: functions of time alone) never
waits for the rest of the system. The master hands that *feed-forward group* to one worker
process, which runs it with the same code as a serial run (the same FMUs, :class:`~cosim.engine.execution.Execution`,
schedule and algorithm) on the machine's other core, and publishes the
values the master reads from each component, call after call, into a ring buffer in shared
memory. In the master each of those components is replaced by a :class:`Proxy` bound to the
same variables: its ``get_outputs`` copies the next published values byte for byte, so the
master's other components, its observers and the MCAP log see exactly the values of a serial
run (``tests/integration/test_parallel.py`` checks bit identity). Threads would not do:
pythonfmu FMUs hold the GIL for the whole call.

Synchronisation is one pair of counting semaphores per component (entries filled, entries
free); in the steady state the worker is ahead, so the master's acquire and release never
block and never make a system call. When the ring is full the worker naps until a quarter
of it is free instead of waiting on the semaphore, for the same reason. A failure in the worker travels
as an error entry plus the exception over a pipe, and is raised by the master where a serial
run would have raised it: at that component's step. A dead worker is reported as such. A worker
whose master dies (killed, even by SIGKILL) ends too: by the kernel's parent-death signal on
Linux, and by checking its parent while it waits on a full ring everywhere.
"""

from __future__ import annotations

import ctypes
import importlib
import multiprocessing as mp
import os
import pickle
import signal
import sys
import time as _time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import procs
from ..errors import STOP_SIGNALS, CosimError
from ..fmi import PY_KINDS, Terminated, Variable, cleanup_extracted, load_fmu
from ..fmi import extract as _extract
from .assembly import assemble
from .execution import Execution, byte_view
from .system import Link, Port, SystemPlan

__all__ = ["AUTO_MIN_STEPS", "RING", "feedforward", "choose", "Offload", "Proxy"]

AUTO_MIN_STEPS = 2000  # below this, starting the worker and loading its FMUs again can outweigh what it saves
RING = 1024  # entries per component: about 1 s of look-ahead at 1 ms
_FAILED, _ENDED = 1, 2  # entry statuses besides 0 (values): the step failed / the FMU ended the simulation
_NAP = 0.002  # s, the worker's sleep while its ring is full
_BURST = RING // 4  # free entries a full ring waits for: fewer, longer bursts disturb the master less
_POLL = 0.05  # s, the master's wait between liveness checks when the worker is behind
# fork starts the worker in milliseconds with everything imported (spawn: a new interpreter,
# about 0.5 s). It happens before any FMU is loaded in the master; Python 3.12+ deprecates
# forking a process with threads (numpy's BLAS has some), so there and off Linux: spawn.
_START_METHOD = "fork" if sys.platform == "linux" and sys.version_info < (3, 12) else "spawn"
_END_TIMEOUT = 60.0  # s, the longest wait for the worker to report its end after the last step


def feedforward(plan: SystemPlan) -> list[int]:
    """The largest set of components whose inputs all come from inside the set (plan order)."""
    sources = [set() for _ in plan.names]
    for lk in plan.links:
        sources[lk.dst.comp].add(lk.src.comp)
    group: set[int] = set()
    grew = True
    while grew:
        grew = False
        for c in plan.order:
            if c not in group and sources[c] <= group:
                group.add(c)
                grew = True
    return [c for c in plan.order if c in group]


def usable_cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def busy_cpus(samples: int = 5, gap: float = 0.002) -> int:
    """CPUs other processes keep busy now: the kernel's count of runnable threads (``/proc/loadavg``'s fourth
    field, this process's reading thread included) less one, the median of ``samples`` readings ``gap`` s apart
    (a process that ran for an instant is not a busy CPU); 0 where the kernel does not say (not Linux)."""
    readings = []
    for i in range(samples):
        try:
            with open("/proc/loadavg", encoding="ascii") as f:
                readings.append(int(f.read().split()[3].partition("/")[0]))
        except (OSError, ValueError, IndexError):
            return 0
        if i + 1 < samples:
            _time.sleep(gap)
    return max(0, sorted(readings)[len(readings) // 2] - 1)


def choose(plan: SystemPlan, mode: str, n_steps: int, writer_process: bool = False) -> tuple[list[int], str]:
    """Components to offload under ``mode`` (auto, on, off) and a note saying why or why not.

    ``auto`` runs ahead only what a worker pays for: a feed-forward group with a PythonFMU in it (its step, the GIL
    and an interpreter, costs tens of microseconds the worker takes off the master) on a CPU no other process keeps
    busy. Compiled FMUs' steps cost the master about a microsecond each, less than handing their values over
    through the ring, and a worker sharing its CPU with another process makes the master wait for it
    (helix_ctc_analytic, native FMUs, 10 s: 0.35 s with the worker against 0.18 s serial, quiet; issue 36 item 5,
    ``benchmarks/parallel_auto.py``). ``writer_process``: the run's log is written by a writer process
    (:class:`cosim.observers.log_writer.WriterProcess`), which takes a CPU too.
    """
    if mode == "off":
        return [], ""
    group = feedforward(plan)
    names = ", ".join(plan.names[c] for c in group)
    why = ""
    if plan.events:
        why = "the scenario has events, which set values in and save the state of every component in this process"
    elif not group:
        why = "every component is in a feedback loop"
    elif len(group) == len(plan.names):
        why = "every component is feed-forward: nothing would be left to overlap with"
    else:
        strings = [f"{plan.names[c]}.{v.name}" for c in group for v in plan.outputs[c] if v.kind in PY_KINDS]
        replayed = [plan.names[c] for c in group if getattr(plan.infos[c], "slave", None) is not None]
        restructured = [plan.names[c] for c in group
                        if plan.infos[c] is not None and plan.infos[c].structural_parameters()]
        if replayed:  # a worker loads its components' FMUs again, from their files
            why = f"{', '.join(replayed)} replay recordings, not FMUs a worker process could load"
        elif strings:
            why = f"{', '.join(strings)} are strings or binaries (only fixed-size values are shared)"
        elif restructured:
            why = f"{', '.join(restructured)} have structural parameters (array sizes are set per run)"
        elif mode == "auto":
            why = _auto_serial(plan, group, names, n_steps, writer_process)
        if not why and not _main_importable():
            why = f"the main program {sys.modules['__main__'].__file__} is not a file a worker process can import"
    if why:
        return [], f"parallel: {mode}: serial run ({why})"
    return group, f"parallel: {names} run ahead in a worker process"


def _auto_serial(plan: SystemPlan, group: list[int], names: str, n_steps: int, writer_process: bool) -> str:
    """Why ``auto`` runs ``group`` serially ("" : it runs ahead)."""
    if n_steps < AUTO_MIN_STEPS:
        return f"{n_steps} steps is too short to pay for starting a worker; auto needs {AUTO_MIN_STEPS}"
    if not any(_python_fmu(plan.infos[c]) for c in group):
        return f"{names} are compiled FMUs, whose steps a worker would hardly take off the master"
    cpus = usable_cpus()
    if cpus < 2:
        return "one CPU available"
    busy = busy_cpus()
    if cpus - busy - (1 if writer_process else 0) < 2:
        writer = " and the log's writer process" if writer_process else ""
        return f"{cpus} CPUs, {busy} kept busy by other processes{writer}: no free CPU for a worker"
    return ""


def _python_fmu(info) -> bool:
    """Whether PythonFMU exported the FMU (its steps run Python: tens of microseconds)."""
    return info is not None and (info.md.generationTool or "").startswith("PythonFMU")


def _main_importable() -> bool:
    """A spawned worker re-imports the main script: impossible for one read from stdin."""
    path = getattr(sys.modules.get("__main__"), "__file__", None)
    return _START_METHOD != "spawn" or path is None or os.path.exists(path)


# --------------------------------------------------------------------------- shared layout


@dataclass(frozen=True)
class _Layout:
    """Per component: the byte size of each output buffer; statuses then entries, one block each."""

    sizes: list[list[int]]

    def entry(self, j: int) -> int:
        return sum(self.sizes[j])

    def offsets(self, j: int) -> tuple[int, int]:
        """(status array offset, first entry offset) of component ``j`` in the shared block."""
        off = 0
        for i in range(j):
            off += 8 * RING + RING * self.entry(i)
        return off, off + 8 * RING

    @property
    def total(self) -> int:
        return sum(8 * RING + RING * self.entry(j) for j in range(len(self.sizes)))


class _Ring:
    """One component's ring in the shared block: statuses, entries, filled/free semaphores.

    ``moves[slot]`` pairs each of the component's output buffers with its bytes in entry
    ``slot`` as (destination, source) views: ring to buffers in the master (``publish``
    false), buffers to ring in the worker.
    """

    def __init__(self, raw: Any, layout: _Layout, j: int, filled: Any, free: Any, buffers: list[Any],
                 publish: bool = False):
        status_off, data_off = layout.offsets(j)
        self.status = (ctypes.c_int64 * RING).from_buffer(raw, status_off)
        self.filled, self.free = filled, free
        self.n = 0  # entries passed so far
        block = memoryview(raw).cast("B")
        entry = layout.entry(j)
        self.moves: list[list[tuple[memoryview, memoryview]]] = []
        for slot in range(RING):
            at = data_off + slot * entry
            pairs = []
            for values in buffers:
                size = ctypes.sizeof(values)
                mine, shared = byte_view(values), block[at:at + size]
                pairs.append((shared, mine) if publish else (mine, shared))
                at += size
            self.moves.append(pairs)


# --------------------------------------------------------------------------- master side


class Offload:
    """The worker process and the shared ring of a feed-forward group, seen from the master."""

    def __init__(self, ex: Execution, comps: list[int], templates: list[Any]):
        plan, multiples = ex.plan, ex.multiples
        self.names = [plan.names[c] for c in comps]
        self.worker_time: dict[str, float] = {}
        self._messages: list[tuple[str, Any]] = []
        self._closed = False
        self.layout = _Layout([[ctypes.sizeof(b.values) for b in t.out_bufs] for t in templates])
        index = {c: j for j, c in enumerate(comps)}
        # The master extracts the group's FMUs and owns the directories: the worker uses them and
        # never removes them, so a worker that is killed leaves nothing behind.
        extracted = [(str(plan.infos[c].path), plan.infos[c].stamp, str(plan.infos[c].unzipdir)) for c in comps]
        spec = dict(
            names=self.names, paths=[str(plan.infos[c].path) for c in comps], extracted=extracted,
            kinds=[("me" if t.model_exchange else "cs", getattr(t, "rtol", 1e-6), getattr(t, "solver", "cvode"),
                    getattr(t, "max_step", None)) for t in templates],
            start_values=[plan.start_values[c] for c in comps],
            inputs=[[v.name for v in plan.inputs[c]] for c in comps],
            outputs=[[v.name for v in plan.outputs[c]] for c in comps],
            links=[(index[lk.src.comp], lk.src.var.name, index[lk.dst.comp], lk.dst.var.name)
                   for lk in plan.links if lk.dst.comp in index],
            order=[index[c] for c in plan.order if c in index],
            multiples=[multiples[c] for c in comps], algorithm=ex.algorithm_name,
            start_ns=ex.start_ns, stop_ns=ex.stop_ns, step_ns=ex.step_ns, sizes=self.layout.sizes, parent=os.getpid())
        ctx = mp.get_context(_START_METHOD)
        self.raw = ctx.RawArray(ctypes.c_char, self.layout.total)
        self.filled = [ctx.Semaphore(0) for _ in comps]
        self.free = [ctx.Semaphore(RING) for _ in comps]
        self.stop = ctx.Event()
        self._conn, send = ctx.Pipe(duplex=False)
        # Ctrl-C and a closed terminal (the whole process group) are the master's, which stops the worker;
        # SIGTERM ends it (the master's handler is not the worker's); it dies with its master
        self.process = procs.start(_worker, spec, self.raw, self.filled, self.free, self.stop, send,
                                   name="cosim-worker", how=_START_METHOD, via_multiprocessing=True,
                                   ignore=[s for s in STOP_SIGNALS if s != signal.SIGTERM], default=[signal.SIGTERM],
                                   die_with_parent=True)
        send.close()
        self.proxies = [Proxy(self, j, t) for j, t in enumerate(templates)]  # templates are bound already

    def ring(self, j: int, buffers: list[Any]) -> _Ring:
        return _Ring(self.raw, self.layout, j, self.filled[j], self.free[j], buffers)

    # -- messages from the worker: ("error", packed exception) or ("done", {name: seconds})
    def _drain(self) -> None:
        try:
            while self._conn.poll():
                self._messages.append(self._conn.recv())
        except (EOFError, OSError):
            pass

    def raise_if_failed(self, proxy: "Proxy") -> None:
        alive = self.process.alive()  # before reading: a worker that reported and died is read in full
        self._drain()
        for kind, payload in self._messages:
            if kind == "error":
                raise _unpack(payload, self.names)
        if not alive:
            raise CosimError(f"component {proxy.name!r}: the worker process running {', '.join(self.names)} "
                             f"exited (code {self.process.returncode}) at t = {proxy.time:.6g} s")

    def termination(self, proxy: "Proxy") -> Terminated:
        """The worker's report that ``proxy``'s component ended the simulation (sent before its end)."""
        deadline = _time.monotonic() + _END_TIMEOUT
        while True:
            self._drain()
            for kind, payload in self._messages:
                if kind == "terminated":
                    return Terminated(*payload)
            self.raise_if_failed(proxy)
            if _time.monotonic() > deadline:
                raise CosimError(f"component {proxy.name!r}: the worker marked the end of the simulation but "
                                 f"did not say when within {_END_TIMEOUT:g} s")
            self._conn.poll(_POLL)

    def wait(self, proxy: "Proxy", ring: _Ring) -> None:
        """Block until ``ring`` has an entry (the worker is behind, e.g. while it starts)."""
        while not ring.filled.acquire(True, _POLL):
            self.raise_if_failed(proxy)

    def finish(self, proxy: "Proxy") -> None:
        """After the last step: the worker's end report (its component times) or its failure."""
        deadline = _time.monotonic() + _END_TIMEOUT
        while True:
            self._drain()
            if any(kind == "done" for kind, _ in self._messages):
                break
            self.raise_if_failed(proxy)
            if _time.monotonic() > deadline:
                raise CosimError(f"the worker process running {', '.join(self.names)} did not finish "
                                 f"within {_END_TIMEOUT:g} s of the last step")
            self._conn.poll(_POLL)
        self.worker_time = next(p for kind, p in self._messages if kind == "done")

    def close(self) -> None:
        """Stop the worker (it frees its FMUs) and release the shared block; idempotent."""
        if self._closed:
            return
        self._closed = True
        self.stop.set()
        if self.process.wait(5.0) is None:
            self.process.kill(signal.SIGTERM)
            self.process.wait(1.0)
        self._conn.close()


class Proxy:
    """Stands in the master for a component the worker runs: same buffers, values from the ring."""

    def __init__(self, group: Offload, j: int, template: Any):
        self.group, self.j = group, j
        self.name, self.info = template.name, template.info
        self.time = 0.0
        self.model_exchange = False  # whatever it is, the worker runs it: integrated and counted there
        self.events = 0
        self._template = template  # bound, never instantiated: it owns the buffers the worker's layout matches
        self._ring = group.ring(j, [b.values for b in template.out_bufs])

    def locate(self, var: Variable, output: bool = True) -> tuple[Any, int]:
        return self._template.locate(var, output)

    # the worker runs the lifecycle; these keep the master's calls in the same places
    def instantiate(self) -> None: ...
    def setup_experiment(self, start: float, stop: float) -> None: ...
    def set_start(self, values: dict[str, Any]) -> None: ...
    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start

    def exit_initialization(self) -> None: ...
    def set_inputs(self) -> None: ...

    def step(self, t: float, h: float) -> None:
        self.time = t + h

    def set_step_get(self, t: float, h: float) -> None:
        self.step(t, h)
        self.get_outputs()

    _ended: Terminated | None = None

    def get_outputs(self) -> None:
        if self._ended is not None:  # read once more when the run ends there: the values are in place
            return
        r = self._ring
        if not r.filled.acquire(False):
            self.group.wait(self, r)
        slot = r.n % RING
        status = r.status[slot]
        if status == _FAILED:
            self.group.raise_if_failed(self)
            raise CosimError(f"component {self.name!r}: the worker process reported a failure at "
                             f"t = {self.time:.6g} s without its message")
        for d, src in r.moves[slot]:
            d[:] = src
        r.free.release()
        r.n += 1
        if status == _ENDED:  # the component ended the simulation in the worker: end here, as a serial run would
            self._ended = self.group.termination(self)
            raise self._ended

    def terminate(self) -> None:
        if not self.group.worker_time:
            self.group.finish(self)

    def free(self) -> None:
        self.group.close()


# --------------------------------------------------------------------------- worker side


class _Stopped(Exception):
    """The master asked the worker to stop (run ended early, Ctrl-C, failure)."""


class _Publisher:
    """A worker slave whose every ``get_outputs`` also fills the next entry of its ring."""

    def __init__(self, slave: Any, ring: _Ring, stop: Any, parent: int):
        self._slave, self._r, self._stop, self._parent = slave, ring, stop, parent
        self.napped = 0.0  # s asleep on a full ring (counted in the component's time by simulate)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._slave, name)

    def _claim(self) -> int:
        r = self._r
        if not r.free.acquire(False):
            t0 = _time.perf_counter()
            while _free_count(r.free) < _BURST or not r.free.acquire(True, _NAP):
                if self._stop.is_set() or os.getppid() != self._parent:  # asked to stop, or the master is gone
                    raise _Stopped
                _time.sleep(_NAP)
            self.napped += _time.perf_counter() - t0
        return r.n % RING

    _ended = False  # the slave ended the simulation (FMI termination) in its last step

    def step(self, t: float, h: float) -> None:
        try:
            self._slave.step(t, h)
        except Terminated:
            self._ended = True
            raise

    def set_step_get(self, t: float, h: float) -> None:
        try:
            self._slave.set_step_get(t, h)
        except Terminated:
            self._ended = True
            raise
        self._publish()

    def get_outputs(self) -> None:
        self._slave.get_outputs()
        self._publish()

    def _publish(self) -> None:
        """The outputs just read into the next entry of the ring."""
        r = self._r
        slot = self._claim()
        for d, src in r.moves[slot]:
            d[:] = src
        r.status[slot] = _ENDED if self._ended else 0
        r.filled.release()
        r.n += 1

    def fail(self) -> None:
        """Publish an error entry, so the master raises where this component's next values were due."""
        slot = self._claim()
        self._r.status[slot] = _FAILED
        self._r.filled.release()
        self._r.n += 1


def _free_count(sem: Any) -> int:
    try:
        return sem.get_value()
    except NotImplementedError:  # macOS has no sem_getvalue: wait for one entry at a time
        return _BURST


def _worker(spec: dict, raw: Any, filled: list, free: list, stop: Any, conn: Any) -> int:
    """Entry point of the worker process (started by :func:`cosim.procs.start`: its signals, its death with the master,
    no wakeup pipe of the master's): run the feed-forward group, publishing as it goes; its exit status.

    Off Linux the worker notices its master's death while waiting (:meth:`_Publisher._claim` compares
    ``os.getppid()``, as its ring fills within a second)."""
    _extract._EXTRACTED.update({(Path(p), tuple(stamp)): Path(d) for p, stamp, d in spec["extracted"]})
    inherited = set(_extract._EXTRACTED)  # the master's extractions (forked: all of them): the master removes them
    slaves: list[Any] = []
    pubs: list[_Publisher] = []
    code = 1
    try:
        try:
            ex = _execution(spec, raw, filled, free, stop, slaves, pubs)
            ex.initialize()
            ex.simulate_until()
            if ex.terminated is not None:  # one of ours ended the simulation: the master ends there too
                term = ex.terminated
                conn.send(("terminated", (term.component, term.function, term.time)))
            for s in slaves:
                s.terminate()
            conn.send(("done", {n: t - p.napped for n, t, p in zip(spec["names"], ex.comp_time, pubs)}))
            code = 0
        except _Stopped:
            code = 0
        except BaseException as exc:  # noqa: BLE001 - every failure goes to the master
            conn.send(("error", _pack(exc)))
            try:
                for p in pubs:
                    p.fail()
            except _Stopped:
                pass
    finally:
        for s in slaves:
            try:
                s.free()
            except Exception:  # noqa: BLE001 - freeing after a failure: nothing left to report to
                pass
        cleanup_extracted(keep=inherited)
        conn.close()
    # cosim.procs leaves without the interpreter's finalisation: the worker has nothing left to finalise, and it
    # skips the teardown of the loaded pythonfmu libraries, where pythonfmu has known crashes at exit (PythonFMU
    # issue 228). A forked worker must not run its parent's atexit handlers.
    return code


def _execution(spec: dict, raw: Any, filled: list, free: list, stop: Any, slaves: list, pubs: list) -> Execution:
    """The worker's execution of its group: the same plan, grid and algorithm as the master's, each component
    wrapped in a :class:`_Publisher` that fills its ring."""
    infos = [load_fmu(p) for p in spec["paths"]]
    variables = [info.variables for info in infos]
    links = [Link(Port(a, variables[a][av]), Port(b, variables[b][bv])) for a, av, b, bv in spec["links"]]
    plan = SystemPlan(spec["names"], infos, links, spec["order"], spec["start_values"],
                      [[variables[j][v] for v in spec["inputs"][j]] for j in range(len(infos))],
                      [[variables[j][v] for v in spec["outputs"][j]] for j in range(len(infos))])
    ex = assemble(plan, (spec["start_ns"], spec["stop_ns"], spec["step_ns"]), spec["multiples"], spec["algorithm"],
                  spec["kinds"])
    slaves += ex.slaves  # bound to the plan's variables: the buffers the ring's layout describes
    layout = _Layout(spec["sizes"])
    for j, s in enumerate(slaves):
        sizes = [ctypes.sizeof(b.values) for b in s.out_bufs]
        if sizes != layout.sizes[j]:  # same FMU, same variables: cannot differ unless the code does
            raise CosimError(f"component {s.name!r}: worker buffer layout {sizes} differs from the master's "
                             f"{layout.sizes[j]}")
        ring = _Ring(raw, layout, j, filled[j], free[j], [b.values for b in s.out_bufs], publish=True)
        pubs.append(_Publisher(s, ring, stop, spec["parent"]))
        ex.replace_slave(j, pubs[j])
    return ex


# --------------------------------------------------------------------------- errors across processes


def _pack(exc: BaseException) -> tuple[str, str, str, bytes]:
    """An exception as plain data: our error classes keep their attributes (component, time...)."""
    try:
        state = pickle.dumps(dict(vars(exc)))
    except Exception:  # noqa: BLE001 - an attribute that does not pickle: keep the message only
        state = pickle.dumps({})
    return type(exc).__module__, type(exc).__qualname__, str(exc), state


def _unpack(payload: tuple[str, str, str, bytes], names: list[str]) -> BaseException:
    module, qualname, text, state = payload
    try:
        cls = getattr(importlib.import_module(module), qualname)
        if isinstance(cls, type) and issubclass(cls, CosimError):
            exc = cls.__new__(cls)
            Exception.__init__(exc, text)
            exc.__dict__.update(pickle.loads(state))
            return exc
    except Exception:  # noqa: BLE001 - unknown class: fall through to a generic error
        pass
    return CosimError(f"worker process running {', '.join(names)}: {qualname}: {text}")

