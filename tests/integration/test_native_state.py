"""FMU state of the native C FMUs, and their tunable payload (issue 34 item 1), through FMPy.

For every native FMU, FMI 2.0 and 3.0, co-simulation (CS) and model exchange (ME), each binary having both:

* a round trip is exact: K steps with varying inputs, get the state, N steps (outputs A), set the state, the same
  N steps (outputs B): A == B bit for bit; the same after a tunable parameter changed between get and set (the
  parameter-only constants model.c caches follow the restored parameters, so they need not be saved); the state
  serialized and deserialized into a fresh instance (instantiated and initialized) gives A too;
* a state taken in initialization mode and set after it continues as a freshly initialized instance; a state taken
  after initialization and set into an instance in initialization mode continues through exitInitializationMode;
* a state is refused with an FMI error and a logged reason, never a crash: NULL; of another native FMU (serialized
  or in memory: the message names its token); of the other FMI version or interface; truncated, padded or
  corrupted bytes; and the instance carries on after each refusal.

``mass.payload`` is tunable wherever it is declared (the model-based controllers and the analytic plant, CS and ME):
set after initialization it takes effect at the next step (CS) or derivative evaluation (ME), with the motion state
kept: the outputs equal, bit for bit, those of a fresh instance started with that payload at the same motion state
(the plant's ``initial.p``/``initial.v`` set to the state reached; ME: the same time and continuous states). A fixed
parameter set after initialization is refused with the reason logged.

No tolerance anywhere: the same C code on the same numbers gives the same bits. Model exchange steps are explicit
Euler steps driven from here (setTime, setContinuousStates, derivatives, completedIntegratorStep).
"""

from __future__ import annotations

import ctypes
import math
import struct
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from fmus import registry

pytestmark = pytest.mark.integration

NATIVE = registry.native_names()
FMI = (2, 3)
INTERFACES = ("cs", "me")
K, N = 5, 5  # steps before the state is taken, steps compared after it
H = 1e-3  # communication / Euler step, s (the FMUs' default experiment step)
REAL, BOOLEAN = ("Real", "Float64"), ("Boolean",)
PAYLOAD = "mass.payload"
PAYLOAD_CHANGE = 0.5  # kg added to the payload: a part picked up
# Serialized layout offsets (fmus/native/c/runtime.c, format 2): magic, version, token, the first value
AT_VERSION, AT_TOKEN, AT_DATA = 8, 24, 152


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("native_state")


@dataclass(frozen=True)
class Built:
    """One built native FMU, unzipped once."""

    name: str
    fmi: int
    md: object
    unzip: str

    def var(self, name: str):  # noqa: ANN201
        return next(v for v in self.md.modelVariables if v.name == name)

    def has(self, name: str) -> bool:
        return any(v.name == name for v in self.md.modelVariables)


def _built(cache: Path, name: str, fmi: int) -> Built:
    """The FMU built from the sources as they are now (rebuilt if they changed since: the FMI 2 and 3 builds of one
    model then have the same token), unzipped once per build."""
    path = registry.build(name, cache, native=True, fmi=fmi)
    return _unzipped(path, path.stat().st_mtime_ns, name, fmi)


@lru_cache(maxsize=None)
def _unzipped(path: Path, mtime_ns: int, name: str, fmi: int) -> Built:
    from fmpy import extract, read_model_description

    return Built(name, fmi, read_model_description(str(path)), extract(str(path)))


_FMI2_LOGS: dict[int, list[str]] = {}


def _fmi2_log(env, instance_name, status, category, message) -> None:  # noqa: ANN001
    _FMI2_LOGS[env].append(message.decode())


@lru_cache(maxsize=1)
def _fmi2_logger():  # noqa: ANN202
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE

    return fmi2CallbackLoggerTYPE(_fmi2_log)


def _fmi2_callbacks(messages: list[str]):  # noqa: ANN202
    """FMI 2 callbacks whose logger appends to ``messages``. FMPy's proxy (which formats the variadic message) keeps
    one Python logger for the process, so one logger serves every instance and tells them apart by the
    componentEnvironment, a key of ``_FMI2_LOGS``."""
    from fmpy.fmi2 import (calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, free)
    from fmpy.logging import addLoggerProxy

    key = len(_FMI2_LOGS) + 1
    _FMI2_LOGS[key] = messages
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _fmi2_logger()
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = key
    addLoggerProxy(ctypes.byref(callbacks))
    return callbacks


class Instance:
    """One instance driven from here: inputs varied with the step index, CS doStep or ME explicit Euler steps; the
    FMU's log messages collected in ``messages``."""

    def __init__(self, built: Built, interface: str, label: str = "a") -> None:
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        self.built, self.fmi, self.me = built, built.fmi, interface == "me"
        md = built.md
        cls = {(2, False): FMU2Slave, (2, True): FMU2Model, (3, False): FMU3Slave, (3, True): FMU3Model}
        kind = md.modelExchange if self.me else md.coSimulation
        self.fmu = cls[self.fmi, self.me](guid=md.guid, unzipDirectory=built.unzip,
                                          modelIdentifier=kind.modelIdentifier,
                                          instanceName=f"{built.name}_{interface}_{label}")
        self.messages: list[str] = []
        if self.fmi == 2:
            self.fmu.instantiate(callbacks=_fmi2_callbacks(self.messages))
        else:
            self.fmu.instantiate(logMessage=lambda *args: self.messages.append(args[-1].decode()))
        variables = md.modelVariables
        self.inputs = [v for v in variables if v.causality == "input" and v.type in REAL]
        self.real_out = [v.valueReference for v in variables if v.causality == "output" and v.type in REAL]
        self.bool_out = [v.valueReference for v in variables if v.causality == "output" and v.type in BOOLEAN]
        self.nx = len(md.derivatives) if self.me else 0
        self.x = (ctypes.c_double * max(self.nx, 1))()
        self.dx = (ctypes.c_double * max(self.nx, 1))()
        self.k, self.t = 0, 0.0

    # -- values
    def set_real(self, names_values: dict[str, float]) -> None:
        vrs = [self.built.var(n).valueReference for n in names_values]
        (self.fmu.setReal if self.fmi == 2 else self.fmu.setFloat64)(vrs, list(names_values.values()))

    def get_real(self, names: list[str]) -> list[float]:
        vrs = [self.built.var(n).valueReference for n in names]
        return (self.fmu.getReal if self.fmi == 2 else self.fmu.getFloat64)(vrs)

    def set_inputs(self) -> None:
        """Inputs of step ``k``: their start values (a valid pose, zero efforts) moved by a few thousandths."""
        if not self.inputs:
            return
        values = [float(v.start or 0.0) for v in self.inputs]
        values = [s + 1e-3 * max(1.0, abs(s)) * math.sin(0.7 * self.k + 1.3 * i) for i, s in enumerate(values)]
        (self.fmu.setReal if self.fmi == 2 else self.fmu.setFloat64)([v.valueReference for v in self.inputs], values)

    def outputs(self) -> np.ndarray:
        """Every output (booleans as 0/1), then (ME) the continuous states the importer holds."""
        real = (self.fmu.getReal if self.fmi == 2 else self.fmu.getFloat64)(self.real_out) if self.real_out else []
        boolean = [float(b) for b in self.fmu.getBoolean(self.bool_out)] if self.bool_out else []
        return np.array([*real, *boolean, *self.x[:self.nx]], dtype=float)

    # -- life cycle
    def initialize(self, start: dict[str, float] | None = None, t0: float = 0.0, *, exit_: bool = True) -> None:
        """Initialization mode at ``t0`` with the parameters ``start`` and the inputs of step 0; then (``exit_``)
        out of it, into step mode (CS) or continuous-time mode (ME)."""
        if self.fmi == 2:
            self.fmu.setupExperiment(startTime=t0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=t0)
        self.t, self.k = t0, 0
        if start:
            self.set_real(start)
        self.set_inputs()
        if exit_:
            self.exit_initialization()

    def exit_initialization(self) -> None:
        self.fmu.exitInitializationMode()
        if self.me:
            self._event_iteration()
            self.fmu.enterContinuousTimeMode()
            self.read_states()

    def _event_iteration(self) -> None:
        (self.fmu.newDiscreteStates if self.fmi == 2 else self.fmu.updateDiscreteStates)()

    def read_states(self) -> None:
        """The importer's copy of the continuous states from the FMU (after an FMU state was set)."""
        if self.nx:
            self.fmu.getContinuousStates(self.x, self.nx)

    def derivatives(self) -> np.ndarray:
        if self.fmi == 2:
            self.fmu.getDerivatives(self.dx, self.nx)
        else:
            self.fmu.getContinuousStateDerivatives(self.dx, self.nx)
        return np.array(self.dx[:self.nx])

    def step(self) -> np.ndarray:
        """One step with the inputs of step ``k``; the outputs after it."""
        self.set_inputs()
        if not self.me:
            self.fmu.doStep(self.t, H)
        else:
            self.fmu.setTime(self.t)
            if self.nx:
                self.fmu.setContinuousStates(self.x, self.nx)
                dx = self.derivatives()
                for i in range(self.nx):
                    self.x[i] += H * dx[i]
            self.fmu.setTime(self.t + H)
            if self.nx:
                self.fmu.setContinuousStates(self.x, self.nx)
            self.fmu.completedIntegratorStep()
        self.t += H
        self.k += 1
        return self.outputs()

    def steps(self, n: int) -> np.ndarray:
        return np.stack([self.step() for _ in range(n)])

    # -- FMU state
    def get_state(self, into=None):  # noqa: ANN001, ANN201
        """A new FMU state, or the state now written into the handle ``into`` (FMI's reuse, as the master's
        ``save_state(into=...)``)."""
        if into is None:
            return self.fmu.getFMUstate() if self.fmi == 2 else self.fmu.getFMUState()
        get = self.fmu.fmi2GetFMUstate if self.fmi == 2 else self.fmu.fmi3GetFMUState
        get(self.fmu.component, ctypes.byref(into))
        return into

    def set_state(self, state, k: int, t: float) -> None:  # noqa: ANN001
        """The FMU state, and the importer's part: step index, time, (ME) continuous states read back."""
        (self.fmu.setFMUstate if self.fmi == 2 else self.fmu.setFMUState)(state)
        self.k, self.t = k, t
        self.read_states()

    def free_state(self, state) -> None:  # noqa: ANN001
        (self.fmu.freeFMUstate if self.fmi == 2 else self.fmu.freeFMUState)(state)

    def serialize(self, state) -> bytes:  # noqa: ANN001
        return bytes((self.fmu.serializeFMUstate if self.fmi == 2 else self.fmu.serializeFMUState)(state))

    def deserialize(self, data: bytes):  # noqa: ANN201
        return (self.fmu.deSerializeFMUstate if self.fmi == 2 else self.fmu.deserializeFMUState)(data)

    def free(self) -> None:
        self.fmu.freeInstance()


@pytest.fixture
def instances():
    """Make instances; free them (and the states they hold) at the end, whatever happened."""
    made: list[Instance] = []

    def make(built: Built, interface: str, label: str = "a") -> Instance:
        made.append(Instance(built, interface, label))
        return made[-1]

    yield make
    for inst in reversed(made):
        inst.free()


def _differ(a: np.ndarray, b: np.ndarray) -> str:
    """Where two output histories differ, with both values (for an assertion's message)."""
    if a.shape != b.shape:
        return f"shapes {a.shape} vs {b.shape}"
    bad = np.argwhere(a.view(np.uint64) != b.view(np.uint64))
    return "; ".join(f"at {tuple(int(i) for i in idx)}: {a[tuple(idx)]!r} vs {b[tuple(idx)]!r}" for idx in bad[:4])


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def _tunable(built: Built) -> str | None:
    """The tunable Real parameter changed between get and set: the payload where there is one."""
    if built.has(PAYLOAD):
        return PAYLOAD
    names = [v.name for v in built.md.modelVariables
             if v.causality == "parameter" and v.variability == "tunable" and v.type in REAL]
    return names[0] if names else None


CASES = [(n, f, i) for n in NATIVE for f in FMI for i in INTERFACES]


@pytest.mark.parametrize("name,fmi,interface", CASES)
def test_round_trip_is_bit_exact(name, fmi, interface, cache, instances):
    """K steps, get; N steps (A); set, N steps (B == A); a tunable parameter changed before set, set again, N
    steps (== A); serialized, deserialized into a fresh initialized instance, N steps (== A)."""
    built = _built(cache, name, fmi)
    a = instances(built, interface)
    a.initialize()
    a.steps(K)
    k, t = a.k, a.t
    state = a.get_state()
    first = a.steps(N)
    a.set_state(state, k, t)
    again = a.steps(N)
    assert _same_bits(first, again), f"{name} FMI {fmi} {interface}: after set state, {_differ(first, again)}"

    tunable = _tunable(built)
    if tunable is not None:  # the state restores the parameter; the cached constants follow it
        a.set_state(state, k, t)
        value = a.get_real([tunable])[0]
        a.set_real({tunable: value + PAYLOAD_CHANGE if tunable == PAYLOAD else 1.5 * value + 1.0})
        changed = a.steps(N)
        if tunable == PAYLOAD:
            assert not _same_bits(first, changed), f"{name} FMI {fmi} {interface}: the payload changed nothing"
        a.set_state(state, k, t)
        restored = a.steps(N)
        assert _same_bits(first, restored), \
            f"{name} FMI {fmi} {interface}: after {tunable} changed and the state set, {_differ(first, restored)}"

    data = a.serialize(state)
    a.free_state(state)
    fresh = instances(built, interface, "fresh")
    fresh.initialize()
    copy = fresh.deserialize(data)
    fresh.set_state(copy, k, t)
    fresh.free_state(copy)
    elsewhere = fresh.steps(N)
    assert _same_bits(first, elsewhere), \
        f"{name} FMI {fmi} {interface}: deserialized into a fresh instance, {_differ(first, elsewhere)}"

    handle = fresh.get_state()
    address = handle.value
    fresh.step()
    fresh.get_state(into=handle)  # the state now, written into the same handle (the master's save_state(into=...))
    assert handle.value == address, f"{name}: the reused handle moved: {address:#x} -> {handle.value:#x}"
    k, t = fresh.k, fresh.t
    later = fresh.steps(N)
    fresh.set_state(handle, k, t)
    reused = fresh.steps(N)
    fresh.free_state(handle)
    assert _same_bits(later, reused), \
        f"{name} FMI {fmi} {interface}: a state written into a reused handle, {_differ(later, reused)}"
    assert not [m for m in a.messages + fresh.messages if "FMU state" in m], a.messages + fresh.messages


@pytest.mark.parametrize("name,fmi,interface", CASES)
def test_state_across_initialization(name, fmi, interface, cache, instances):
    """A state taken in initialization mode, set after K steps: the next N steps are those of a freshly initialized
    instance. A state taken after K steps, set into an instance in initialization mode: after
    exitInitializationMode the next N steps are those of the instance it was taken from."""
    built = _built(cache, name, fmi)
    reference = instances(built, interface, "reference")
    reference.initialize()
    from_start = reference.steps(N)

    a = instances(built, interface)
    a.initialize(exit_=False)
    initial = a.get_state()
    a.exit_initialization()
    a.steps(K)
    k, t = a.k, a.t
    later = a.get_state()
    after_k = a.steps(N)
    a.set_state(initial, 0, 0.0)
    restarted = a.steps(N)
    assert _same_bits(from_start, restarted), \
        f"{name} FMI {fmi} {interface}: initialization state set after initialization, {_differ(from_start, restarted)}"

    b = instances(built, interface, "b")
    b.initialize(exit_=False)
    (b.fmu.setFMUstate if fmi == 2 else b.fmu.setFMUState)(later)
    b.exit_initialization()
    b.k, b.t = k, t
    continued = b.steps(N)
    assert _same_bits(after_k, continued), \
        f"{name} FMI {fmi} {interface}: state set in initialization mode, {_differ(after_k, continued)}"
    a.free_state(initial)
    a.free_state(later)


def _refused(inst: Instance, call, *args) -> list[str]:  # noqa: ANN001
    """Call an FMU-state function that must fail with fmi2Error / fmi3Error; the messages it logged."""
    from fmpy.fmi1 import FMICallException

    before = len(inst.messages)
    with pytest.raises(FMICallException) as exc:
        call(*args)
    assert exc.value.status == 3, f"{exc.value} (status {exc.value.status}, expected 3: error)"
    return inst.messages[before:]


@pytest.mark.parametrize("name,fmi", [(n, f) for n in NATIVE for f in FMI])
def test_state_of_another_fmu_is_refused(name, fmi, cache, instances):
    """The serialized state and the in-memory state of the next native FMU in the list are refused; the message
    names the other FMU's token and this one's. The instance is unharmed: its own state still round-trips."""
    other_name = NATIVE[(NATIVE.index(name) + 1) % len(NATIVE)]
    built, other_built = _built(cache, name, fmi), _built(cache, other_name, fmi)
    this, other = instances(built, "cs"), instances(other_built, "cs", "other")
    this.initialize()
    other.initialize()
    other.steps(2)
    foreign = other.get_state()
    data = other.serialize(foreign)
    set_ = this.fmu.setFMUstate if fmi == 2 else this.fmu.setFMUState
    free = this.fmu.freeFMUstate if fmi == 2 else this.fmu.freeFMUState
    tokens = (other_built.md.guid, built.md.guid)
    for what, call, arg in (("serialized", this.deserialize, data), ("in-memory", set_, foreign),
                            ("freed through this FMU", free, foreign)):
        logged = _refused(this, call, arg)
        assert any(all(t in m for t in tokens) for m in logged), \
            f"{name} FMI {fmi}: {what} state of {other_name}: expected a message naming {tokens}, got {logged}"
    other.free_state(foreign)
    this.steps(1)
    k, t = this.k, this.t
    own = this.get_state()
    first = this.steps(N)
    this.set_state(own, k, t)
    this.free_state(own)
    again = this.steps(N)
    assert _same_bits(first, again), f"{name} FMI {fmi}: its own state after the refusals, {_differ(first, again)}"


@pytest.mark.parametrize("name,fmi", [(n, f) for n in NATIVE for f in FMI])
def test_damaged_or_null_state_is_refused(name, fmi, cache, instances):
    """Truncated, padded and corrupted bytes, a NULL state: each refused with a message saying which; afterwards
    the intact bytes still restore the state exactly."""
    built = _built(cache, name, fmi)
    a = instances(built, "cs")
    a.initialize()
    a.steps(K)
    state = a.get_state()
    data = a.serialize(state)
    first = a.steps(N)
    a.free_state(state)

    def flipped(at: int) -> bytes:
        return data[:at] + bytes([data[at] ^ 0x40]) + data[at + 1:]

    version = struct.pack("=I", 99)
    cases = {
        "truncated by a byte": (data[:-1], "truncated or corrupted"),
        "truncated into the header": (data[:AT_DATA - 1], "too few"),
        "one byte": (data[:1], "too few"),
        "padded": (data + b"\0", "truncated or corrupted"),
        "a value corrupted": (flipped(AT_DATA + 3), "checksum"),
        "the checksum corrupted": (flipped(len(data) - 1), "checksum"),
        "the magic corrupted": (flipped(0), "magic"),
        "another format version": (data[:AT_VERSION] + version + data[AT_VERSION + 4:], "format version 99"),
        "another build's token": (flipped(AT_TOKEN + 5), "another model or build"),
    }
    for what, (damaged, reason) in cases.items():
        logged = _refused(a, a.deserialize, damaged)
        assert any(reason in m for m in logged), f"{name} FMI {fmi}: {what}: expected {reason!r} in {logged}"
    null = ctypes.c_void_p()
    logged = _refused(a, a.fmu.setFMUstate if fmi == 2 else a.fmu.setFMUState, null)
    assert any("NULL" in m for m in logged), f"{name} FMI {fmi}: NULL state: {logged}"
    copy = a.deserialize(data)
    a.set_state(copy, K, K * H)
    a.free_state(copy)
    again = a.steps(N)
    assert _same_bits(first, again), f"{name} FMI {fmi}: intact bytes after the refusals, {_differ(first, again)}"


@pytest.mark.parametrize("name", NATIVE)
def test_state_of_other_version_or_interface_is_refused(name, cache, instances):
    """A state of the FMI 2 build (same model, same token) into the FMI 3 build, and a co-simulation state into a
    model exchange instance of the same binary: refused, naming what differs."""
    two, three = _built(cache, name, 2), _built(cache, name, 3)
    cs2, cs3, me2 = instances(two, "cs"), instances(three, "cs", "three"), instances(two, "me", "me")
    for inst in (cs2, cs3, me2):
        inst.initialize()
    state = cs2.get_state()
    logged = _refused(cs3, cs3.deserialize, cs2.serialize(state))
    assert any("FMI 2 build" in m and "FMI 3 build" in m for m in logged), f"{name}: FMI 2 state into FMI 3: {logged}"
    logged = _refused(me2, me2.fmu.setFMUstate, state)
    assert any("co-simulation instance" in m and "model exchange instance" in m for m in logged), \
        f"{name}: CS state into an ME instance: {logged}"
    logged = _refused(me2, me2.deserialize, cs2.serialize(state))
    assert any("co-simulation instance" in m for m in logged), f"{name}: serialized CS state into ME: {logged}"
    cs2.free_state(state)


@pytest.mark.parametrize("fmi", FMI)
def test_state_set_after_a_discarded_step_continues(fmi, cache, instances):
    """The master's retry: a step of the analytic plant discarded (a NaN effort; the instance then refuses further
    steps), the state saved before it set: the instance steps again, exactly as one that never failed."""
    from fmpy.fmi1 import FMICallException

    built = _built(cache, "linear_analytic_plant", fmi)
    failing, twin = instances(built, "cs"), instances(built, "cs", "twin")
    for inst in (failing, twin):
        inst.initialize()
        inst.steps(K)
    k, t = failing.k, failing.t
    state = failing.get_state()
    failing.set_real({"u[1]": float("nan")})
    with pytest.raises(FMICallException) as exc:
        failing.fmu.doStep(t, H)
    assert exc.value.status == 2, f"a NaN effort: status {exc.value.status}, expected 2 (discard)"
    assert any("non-finite effort" in m for m in failing.messages), failing.messages
    failing.set_state(state, k, t)
    failing.free_state(state)
    retried, expected = failing.steps(N), twin.steps(N)
    assert _same_bits(expected, retried), f"FMI {fmi}: retried after the discarded step, {_differ(expected, retried)}"


# ----------------------------------------------------------------------------- tunable payload

def _motion_start(built: Built, inst: Instance) -> dict[str, float]:
    """The start parameters that put a fresh instance at ``inst``'s motion state: the CS plant's platform state
    (``initial.p``, ``initial.v``: its internal state is exactly the outputs ``p``, ``v``); nothing for the others
    (the controllers keep no state; an ME importer holds the states and sets them)."""
    if inst.me or not built.has("initial.p.x"):
        return {}
    names = [f"{q}.{a}" for q in ("p", "v") for a in "xyz"]
    return dict(zip((f"initial.{n}" for n in names), inst.get_real(names)))


def _probe(inst: Instance) -> np.ndarray:
    """What the payload must change: CS, the outputs after one step; ME, at the current time and states with the
    inputs of the next step, the derivatives and the outputs."""
    if not inst.me:
        return inst.step()
    inst.set_inputs()
    inst.fmu.setTime(inst.t)
    if inst.nx:
        inst.fmu.setContinuousStates(inst.x, inst.nx)
        return np.concatenate([inst.derivatives(), inst.outputs()])
    return inst.outputs()


def _set_tunable(inst: Instance, values: dict[str, float]) -> None:
    """Set tunable parameters after initialization: in step mode (CS), in event mode (ME, as FMI requires)."""
    if inst.me:
        inst.fmu.enterEventMode()
        inst.set_real(values)
        inst._event_iteration()
        inst.fmu.enterContinuousTimeMode()
    else:
        inst.set_real(values)


@pytest.mark.parametrize("fmi,interface", [(f, i) for f in FMI for i in INTERFACES])
def test_payload_is_tunable_and_keeps_the_motion(fmi, interface, cache, instances):
    """In every native FMU that declares ``mass.payload`` (it must be tunable there), set after K steps: the next
    step / derivative evaluation differs from an unchanged instance's, and equals, bit for bit, that of a fresh
    instance started with the new payload at the motion state reached (the motion was not reset)."""
    declaring = [n for n in NATIVE if _built(cache, n, fmi).has(PAYLOAD)]
    expected = {f"{kind}_{m}" for kind in ("linear", "rotary") for m in ("pdplus", "ctc", "analytic_plant",
                                                                         "analytic_plant_me")}
    assert expected <= set(declaring), f"FMI {fmi}: {sorted(expected - set(declaring))} do not declare {PAYLOAD}"
    for name in declaring:
        built = _built(cache, name, fmi)
        variability = built.var(PAYLOAD).variability
        assert variability == "tunable", f"{name} FMI {fmi}: {PAYLOAD} is {variability}, expected tunable"
        new = float(built.var(PAYLOAD).start) + PAYLOAD_CHANGE
        changed, unchanged = instances(built, interface, "changed"), instances(built, interface, "unchanged")
        for inst in (changed, unchanged):
            inst.initialize()
            inst.steps(K)
        x_before = np.array(changed.x[:changed.nx])
        start = {PAYLOAD: new, **_motion_start(built, changed)}
        _set_tunable(changed, {PAYLOAD: new})
        changed.read_states()
        x_after = np.array(changed.x[:changed.nx])
        assert _same_bits(x_before, x_after), \
            f"{name} FMI {fmi} ME: states reset by the payload: {x_before} -> {x_after}"
        fresh = instances(built, interface, "fresh")
        fresh.initialize(start, changed.t)
        fresh.k = changed.k
        if fresh.nx:
            fresh.x[:fresh.nx] = list(x_before)
        got, reference, base = _probe(changed), _probe(fresh), _probe(unchanged)
        assert not _same_bits(got, base), f"{name} FMI {fmi} {interface}: the payload change had no effect: {got}"
        assert _same_bits(got, reference), \
            f"{name} FMI {fmi} {interface}: payload set after K steps vs a fresh instance with it, " \
            f"{_differ(got, reference)}"


@pytest.mark.parametrize("fmi,interface", [(f, i) for f in FMI for i in INTERFACES])
def test_fixed_parameter_after_initialization_is_refused(fmi, interface, cache, instances):
    """``mass.platform`` (fixed) set after initialization: an FMI error naming the parameter and why; the instance
    keeps stepping."""
    from fmpy.fmi1 import FMICallException

    for name in (n for n in NATIVE if _built(cache, n, fmi).has("mass.platform")):
        built = _built(cache, name, fmi)
        inst = instances(built, interface)
        inst.initialize()
        inst.steps(2)
        if inst.me:
            inst.fmu.enterEventMode()
        before = len(inst.messages)
        with pytest.raises(FMICallException) as exc:
            inst.set_real({"mass.platform": 1.0})
        logged = inst.messages[before:]
        assert exc.value.status == 3, f"{name} FMI {fmi} {interface}: status {exc.value.status}, expected 3 (error)"
        assert any('"mass.platform"' in m and "fixed" in m for m in logged), \
            f"{name} FMI {fmi} {interface}: expected a message naming the fixed parameter, got {logged}"
        if inst.me:
            inst._event_iteration()
            inst.fmu.enterContinuousTimeMode()
        assert np.all(np.isfinite(inst.step())), f"{name} FMI {fmi} {interface}: no step after the refusal"
