"""Cost of saving and restoring an FMU's state (issue 34), beside one doStep of the same FMU, in one run.

For each native FMU (co-simulation instance, FMI 2.0 and 3.0), initialized with its start values:

* get: ``fmi2GetFMUstate`` / ``fmi3GetFMUState`` into the same handle (as the master's ``save_state(into=...)``
  reuses its handle: no allocation);
* set: ``fmi2SetFMUstate`` / ``fmi3SetFMUState`` of that handle;
* serialize + deserialize: ``SerializeFMUstate`` into a fixed buffer, ``DeSerializeFMUstate`` of it into a new
  state, ``FreeFMUstate`` of that state (a checkpoint written and read back), with the size of the bytes;
* doStep: one 1 ms step from the saved state, measured as (set + doStep) - set so that every step starts at the
  same point (a plant with zero effort would otherwise fall out of its workspace within a long loop).

Every function is called through ctypes as our master calls an FMU (``cosim.fmi.slave``'s ``_bound_call``): a
function pointer whose prototype declares no argument types, with its arguments converted to C once and bound, so
ctypes converts nothing per call. Figures are ns per call, the best of ``--rounds`` rounds of ``--calls`` calls
each, and include ctypes' own cost of a call and the Python loop's, printed on its own (the same bound call of
``fmi2GetTypesPlatform`` / ``fmi3GetVersion``, which does no work). Target: get and set under 1 us each.

A python FMU's get + set (the pythonfmu build of ``--python-fmu``, called through PYFUNCTYPE as the master calls a
PythonFMU library) where its modelDescription declares ``canGetAndSetFMUstate``; otherwise the line says so.

    python benchmarks/fmu_state.py [--fmi 2 3] [--calls 20000] [--rounds 3] [--python-fmu linear_ctc] [--only NAME]
"""

from __future__ import annotations

import argparse
import ctypes
import math
import sys
import time
from functools import partial
from pathlib import Path
from typing import Any, Callable

import record

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

H = 1e-3  # the step of the doStep figure, s


def bound(dll: Any, name: str, *args: Any, python: bool = False) -> Callable[[], int]:
    """``name(*args)`` as a call without arguments, as ``cosim.fmi.slave.Base._bound_call`` makes it: a prototype
    with no argument types (ctypes skips its per-call conversions), the arguments already C values; PYFUNCTYPE for
    a PythonFMU library (the GIL kept across the call, as the master does)."""
    factory = ctypes.PYFUNCTYPE if python else ctypes.CFUNCTYPE
    f = factory(ctypes.c_int)(ctypes.cast(getattr(dll, name), ctypes.c_void_p).value)
    return partial(f, *args)


def ns_per_call(call: Callable[[], int], calls: int, rounds: int, *, check: bool = True) -> float:
    """Best of ``rounds`` rounds of ``calls`` calls, ns per call; (``check``) the call's status is checked first."""
    status = call()
    if check and status > 1:
        sys.exit(f"{getattr(call, 'func', call)} returned status {status}")
    best = math.inf
    for _ in range(rounds):
        t0 = time.perf_counter_ns()
        for _ in range(calls):
            call()
        best = min(best, (time.perf_counter_ns() - t0) / calls)
    return best


class Subject:
    """One FMU instance, initialized with its start values, and its FMU-state calls bound."""

    def __init__(self, path: Path, fmi: int, python: bool = False) -> None:
        from fmpy import extract, read_model_description

        self.md = read_model_description(str(path))
        self.fmi, self.python = fmi, python
        if fmi == 2:
            from fmpy.fmi2 import FMU2Slave as Slave
        else:
            from fmpy.fmi3 import FMU3Slave as Slave
        self.fmu = Slave(guid=self.md.guid, unzipDirectory=extract(str(path)),
                         modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="bench")
        self.fmu.instantiate()
        if fmi == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()
        self.c = ctypes.c_void_p(self.fmu.component)
        self.handle = ctypes.c_void_p()

    @property
    def can_save(self) -> bool:
        return bool(getattr(self.md.coSimulation, "canGetAndSetFMUstate", False))

    def call(self, name2: str, name3: str, *args: Any) -> Callable[[], int]:
        return bound(self.fmu.dll, name2 if self.fmi == 2 else name3, *args, python=self.python)

    def get(self) -> Callable[[], int]:
        return self.call("fmi2GetFMUstate", "fmi3GetFMUState", self.c, ctypes.byref(self.handle))

    def set(self) -> Callable[[], int]:
        return self.call("fmi2SetFMUstate", "fmi3SetFMUState", self.c, self.handle)

    def floor(self) -> Callable[[], int]:
        """A bound call that does no work: ctypes' and the loop's cost of one call."""
        return bound(self.fmu.dll, "fmi2GetTypesPlatform" if self.fmi == 2 else "fmi3GetVersion", python=self.python)

    def do_step(self) -> Callable[[], int]:
        if self.fmi == 2:
            return self.call("fmi2DoStep", "", self.c, ctypes.c_double(0.0), ctypes.c_double(H), ctypes.c_int(1))
        self._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        return self.call("", "fmi3DoStep", self.c, ctypes.c_double(0.0), ctypes.c_double(H), ctypes.c_bool(True),
                         *(ctypes.byref(f) for f in self._flags))

    def serialize_round(self) -> tuple[Callable[[], None], int]:
        """(serialize + deserialize + free as one call, the serialized size in bytes)."""
        size = ctypes.c_size_t()
        sized = self.call("fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize", self.c, self.handle,
                          ctypes.byref(size))
        if sized() != 0:
            sys.exit("SerializedFMUstateSize failed")
        buffer = ctypes.create_string_buffer(size.value)
        copy = ctypes.c_void_p()
        serialize = self.call("fmi2SerializeFMUstate", "fmi3SerializeFMUState", self.c, self.handle, buffer, size)
        deserialize = self.call("fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState", self.c, buffer, size,
                                ctypes.byref(copy))
        free = self.call("fmi2FreeFMUstate", "fmi3FreeFMUState", self.c, ctypes.byref(copy))

        def round_trip() -> int:
            return serialize() | deserialize() | free()

        return round_trip, size.value

    def close(self) -> None:
        if self.handle:
            self.call("fmi2FreeFMUstate", "fmi3FreeFMUState", self.c, ctypes.byref(self.handle))()
        self.fmu.freeInstance()


def measure(subject: Subject, calls: int, rounds: int, *, serialize: bool = True) -> dict[str, float]:
    get, set_ = subject.get(), subject.set()
    figures = {"floor": ns_per_call(subject.floor(), calls, rounds, check=False),
               "get": ns_per_call(get, calls, rounds), "set": ns_per_call(set_, calls, rounds)}
    step = subject.do_step()

    def set_and_step() -> int:
        return set_() | step()

    figures["step"] = ns_per_call(set_and_step, calls, rounds) - figures["set"]
    if serialize:
        round_trip, size = subject.serialize_round()
        figures["serialize"] = ns_per_call(round_trip, calls, rounds)
        figures["bytes"] = size
    return figures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fmi", type=int, nargs="+", choices=(2, 3), default=[2, 3], help="FMI versions (default 2 3)")
    ap.add_argument("--calls", type=int, default=20000, help="calls per round (default 20000)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds, best kept (default 3)")
    ap.add_argument("--python-fmu", default="linear_ctc", help="python FMU whose get + set is measured too "
                    "(default linear_ctc; '' for none)")
    ap.add_argument("--only", nargs="*", default=None, help="native FMUs to measure (default: every one)")
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "fmu_state") as rec:
        _measure(args, rec)


def _measure(args, rec: record.Recording) -> None:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    from fmus import registry

    names = args.only or registry.native_names()
    print(f"FMU state through ctypes bound calls (as the master calls), ns per call, best of {args.rounds} rounds of "
          f"{args.calls} calls; every figure includes the floor (ctypes + loop, a call that does no work). "
          f"doStep = (set + doStep) - set, one {H * 1e3:g} ms step from the same state. Target: get, set < 1000 ns.")
    print(f"{'FMU':<26} {'FMI':>3} {'bytes':>6} {'floor':>6} {'get':>6} {'set':>6} {'ser+de':>7} {'doStep':>7} "
          f"{'(get+set)/doStep':>17}")
    worst = {"get": 0.0, "set": 0.0}
    native: list[dict[str, float]] = []
    for fmi in args.fmi:
        for name in names:
            subject = Subject(registry.build(name, native=True, fmi=fmi), fmi)
            try:
                f = measure(subject, args.calls, args.rounds)
            finally:
                subject.close()
            worst = {k: max(worst[k], f[k]) for k in worst}
            native.append(f)
            print(f"{name:<26} {fmi:>3} {f['bytes']:>6.0f} {f['floor']:>6.0f} {f['get']:>6.0f} {f['set']:>6.0f} "
                  f"{f['serialize']:>7.0f} {f['step']:>7.0f} {(f['get'] + f['set']) / f['step']:>17.3f}")
    print(f"worst get {worst['get']:.0f} ns, worst set {worst['set']:.0f} ns (target < 1000 each)")
    if native:
        rec.put("native_fmus", len(native))
        for key in ("floor", "get", "set"):  # us: [smallest, largest] over the FMU builds
            rec.put(f"native_{key}_us", [min(f[key] for f in native) / 1e3, max(f[key] for f in native) / 1e3])
        rec.put("native_worst_us", max(worst.values()) / 1e3)
        ratios = [(f["get"] + f["set"]) / f["step"] for f in native]
        rec.put("native_state_per_step", [min(ratios), max(ratios)])
    if args.python_fmu:
        subject = Subject(registry.build(args.python_fmu), 2, python=True)
        try:
            if not subject.can_save:
                print(f"python FMU {args.python_fmu}: FMU state not available (its modelDescription does not declare "
                      f"canGetAndSetFMUstate)")
                return
            f = measure(subject, max(1, args.calls // 10), args.rounds, serialize=False)
        finally:
            subject.close()
        ratio = (f["get"] + f["set"]) / f["step"]
        rec.put("python_fmu", args.python_fmu)
        rec.put("python_get_us", f["get"] / 1e3)
        rec.put("python_set_us", f["set"] / 1e3)
        rec.put("python_step_us", f["step"] / 1e3)
        print(f"python FMU {args.python_fmu} (FMI 2, pythonfmu): floor {f['floor']:.0f} ns, get {f['get']:.0f} ns, "
              f"set {f['set']:.0f} ns, doStep {f['step']:.0f} ns: (get+set)/doStep {ratio:.3f}")


if __name__ == "__main__":
    main()
