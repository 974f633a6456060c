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
Euler steps driven from here (setTime, setContinuousStates, derivatives, completedIntegratorStep) by
tests/fmu_state_harness.py, as in the python-build test.
"""

from __future__ import annotations

import ctypes
import struct
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from fmu_state_harness import (H, REAL, Built, Instance, Instances, across_initialization, differ, probe, refused,
                               same_bits, set_tunable)

from fmus import registry

pytestmark = pytest.mark.integration

NATIVE = registry.native_names()
FMI = (2, 3)
INTERFACES = ("cs", "me")
K, N = 5, 5  # steps before the state is taken, steps compared after it
PAYLOAD = "mass.payload"
PAYLOAD_CHANGE = 0.5  # kg added to the payload: a part picked up
ERROR = 3  # the FMI status of a refusal
# Serialized layout offsets (fmus/native/c/state.c, format 2): magic, version, token, the first value
AT_VERSION, AT_TOKEN, AT_DATA = 8, 24, 152


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("native_state")


def _built(cache: Path, name: str, fmi: int) -> Built:
    """The FMU built from the sources as they are now (rebuilt if they changed since: the FMI 2 and 3 builds of one
    model then have the same token), unzipped once per build."""
    path = registry.build(name, cache, native=True, fmi=fmi)
    return _unzipped(path, path.stat().st_mtime_ns, name, fmi)


@lru_cache(maxsize=None)
def _unzipped(path: Path, mtime_ns: int, name: str, fmi: int) -> Built:
    return Built.load(path, name, fmi)


@pytest.fixture
def instances():
    """Make instances (``instances(built, interface, label)``); free them (and the states they hold) at the end,
    whatever happened."""
    made = Instances()
    yield made
    made.free()


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
    (state, k, t), first, again = a.twice(N)
    assert same_bits(first, again), f"{name} FMI {fmi} {interface}: after set state, {differ(first, again)}"

    tunable = _tunable(built)
    if tunable is not None:  # the state restores the parameter; the cached constants follow it
        a.set_state(state, k, t)
        value = a.get_real([tunable])[0]
        a.set_real({tunable: value + PAYLOAD_CHANGE if tunable == PAYLOAD else 1.5 * value + 1.0})
        changed = a.steps(N)
        if tunable == PAYLOAD:
            assert not same_bits(first, changed), f"{name} FMI {fmi} {interface}: the payload changed nothing"
        a.set_state(state, k, t)
        restored = a.steps(N)
        assert same_bits(first, restored), \
            f"{name} FMI {fmi} {interface}: after {tunable} changed and the state set, {differ(first, restored)}"

    data = a.serialize(state)
    a.free_state(state)
    fresh = instances(built, interface, "fresh")
    fresh.initialize()
    fresh.set_serialized(data, k, t)
    elsewhere = fresh.steps(N)
    assert same_bits(first, elsewhere), \
        f"{name} FMI {fmi} {interface}: deserialized into a fresh instance, {differ(first, elsewhere)}"

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
    assert same_bits(later, reused), \
        f"{name} FMI {fmi} {interface}: a state written into a reused handle, {differ(later, reused)}"
    assert not [m for m in a.messages + fresh.messages if "FMU state" in m], a.messages + fresh.messages


@pytest.mark.parametrize("name,fmi,interface", CASES)
def test_state_across_initialization(name, fmi, interface, cache, instances):
    """A state taken in initialization mode, set after K steps: the next N steps are those of a freshly initialized
    instance. A state taken after K steps, set into an instance in initialization mode: after
    exitInitializationMode the next N steps are those of the instance it was taken from."""
    built = _built(cache, name, fmi)
    (from_start, restarted), (after_k, continued) = \
        across_initialization(lambda label: instances(built, interface, label), K, N)
    assert same_bits(from_start, restarted), \
        f"{name} FMI {fmi} {interface}: initialization state set after initialization, {differ(from_start, restarted)}"
    assert same_bits(after_k, continued), \
        f"{name} FMI {fmi} {interface}: state set in initialization mode, {differ(after_k, continued)}"


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
        logged = refused(this, call, arg, status=ERROR)
        assert any(all(t in m for t in tokens) for m in logged), \
            f"{name} FMI {fmi}: {what} state of {other_name}: expected a message naming {tokens}, got {logged}"
    other.free_state(foreign)
    this.steps(1)
    (own, _, _), first, again = this.twice(N)
    this.free_state(own)
    assert same_bits(first, again), f"{name} FMI {fmi}: its own state after the refusals, {differ(first, again)}"


@pytest.mark.parametrize("name,fmi", [(n, f) for n in NATIVE for f in FMI])
def test_damaged_or_null_state_is_refused(name, fmi, cache, instances):
    """Truncated, padded and corrupted bytes, a NULL state: each refused with a message saying which; afterwards
    the intact bytes still restore the state exactly."""
    built = _built(cache, name, fmi)
    a = instances(built, "cs")
    a.initialize()
    a.steps(K)
    data = a.serialized()
    first = a.steps(N)

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
        logged = refused(a, a.deserialize, damaged, status=ERROR)
        assert any(reason in m for m in logged), f"{name} FMI {fmi}: {what}: expected {reason!r} in {logged}"
    null = ctypes.c_void_p()
    logged = refused(a, a.fmu.setFMUstate if fmi == 2 else a.fmu.setFMUState, null, status=ERROR)
    assert any("NULL" in m for m in logged), f"{name} FMI {fmi}: NULL state: {logged}"
    a.set_serialized(data, K, K * H)
    again = a.steps(N)
    assert same_bits(first, again), f"{name} FMI {fmi}: intact bytes after the refusals, {differ(first, again)}"


@pytest.mark.parametrize("name", NATIVE)
def test_state_of_other_version_or_interface_is_refused(name, cache, instances):
    """A state of the FMI 2 build (same model, same token) into the FMI 3 build, and a co-simulation state into a
    model exchange instance of the same binary: refused, naming what differs."""
    two, three = _built(cache, name, 2), _built(cache, name, 3)
    cs2, cs3, me2 = instances(two, "cs"), instances(three, "cs", "three"), instances(two, "me", "me")
    for inst in (cs2, cs3, me2):
        inst.initialize()
    state = cs2.get_state()
    logged = refused(cs3, cs3.deserialize, cs2.serialize(state), status=ERROR)
    assert any("FMI 2 build" in m and "FMI 3 build" in m for m in logged), f"{name}: FMI 2 state into FMI 3: {logged}"
    logged = refused(me2, me2.fmu.setFMUstate, state, status=ERROR)
    assert any("co-simulation instance" in m and "model exchange instance" in m for m in logged), \
        f"{name}: CS state into an ME instance: {logged}"
    logged = refused(me2, me2.deserialize, cs2.serialize(state), status=ERROR)
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
    assert same_bits(expected, retried), f"FMI {fmi}: retried after the discarded step, {differ(expected, retried)}"


# ----------------------------------------------------------------------------- tunable payload

def _motion_start(built: Built, inst: Instance) -> dict[str, float]:
    """The start parameters that put a fresh instance at ``inst``'s motion state: the CS plant's platform state
    (``initial.p``, ``initial.v``: its internal state is exactly the outputs ``p``, ``v``); nothing for the others
    (the controllers keep no state; an ME importer holds the states and sets them)."""
    if inst.me or not built.has("initial.p.x"):
        return {}
    names = [f"{q}.{a}" for q in ("p", "v") for a in "xyz"]
    return dict(zip((f"initial.{n}" for n in names), inst.get_real(names)))


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
        set_tunable(changed, {PAYLOAD: new})
        changed.read_states()
        x_after = np.array(changed.x[:changed.nx])
        assert same_bits(x_before, x_after), \
            f"{name} FMI {fmi} ME: states reset by the payload: {x_before} -> {x_after}"
        fresh = instances(built, interface, "fresh")
        fresh.initialize(start, changed.t)
        fresh.k = changed.k
        if fresh.nx:
            fresh.x[:fresh.nx] = list(x_before)
        got, reference, base = probe(changed), probe(fresh), probe(unchanged)
        assert not same_bits(got, base), f"{name} FMI {fmi} {interface}: the payload change had no effect: {got}"
        assert same_bits(got, reference), \
            f"{name} FMI {fmi} {interface}: payload set after K steps vs a fresh instance with it, " \
            f"{differ(got, reference)}"


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
            inst.event_iteration()
            inst.fmu.enterContinuousTimeMode()
        assert np.all(np.isfinite(inst.step())), f"{name} FMI {fmi} {interface}: no step after the refusal"
