"""FMU state of the python FMUs, and their tunable payload (issue 34 item 1, python build), through FMPy.

Every python FMU of the registry (pythonfmu FMI 2.0 co-simulation, pythonfmu3 FMI 3.0 model exchange; the Exudyn
plants with both fidelities):

* declares ``canGetAndSetFMUstate`` and ``canSerializeFMUstate`` (FMI 3.0: ``...FMUState``);
* a round trip is exact: K steps with varying inputs, get the state, N steps (outputs A), set the state, the same N
  steps (outputs B): A == B bit for bit; the payload changed after the get and the state set again gives A too (the
  state restores the parameter and the core objects follow it); the state serialized and deserialized into a fresh
  instance (instantiated and initialized with the same parameters) gives A;
* a state of another FMU, in memory or serialized, and damaged bytes are refused: an FMI failing status with the
  reason (both guids) logged, never a crash, and the instance carries on. pythonfmu's binary has no failing status
  for Python code but fatal (every Python exception becomes fmi2Fatal / fmi3Fatal), so a refusal is status 4 (the
  native build, tests/integration/test_native_state.py, returns 3); the instance stays valid
  (``fmus._names.spare_wrapper_references``), which the steps after each refusal show.

``mass.payload`` is tunable wherever it is declared: set after K steps it changes what follows and keeps the motion
(the analytic plant and the model-based controllers: equal, bit for bit, to a fresh instance started with it at the
motion state reached); a heavier payload sags the platform held by the same efforts, in the Exudyn plant as in the
analytic one. A fixed parameter set after initialization is refused with the reason logged.

Model exchange steps are explicit Euler steps driven from here (setTime, setContinuousStates, derivatives,
completedIntegratorStep) by tests/fmu_state_harness.py, as in the native test. The FMUs are built into the project's
.fmu_cache (reused while their sources do not change).
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from fmu_state_harness import (H, Built, Instances, across_initialization, differ, probe, refused, same_bits,
                               set_tunable)

from fmus import registry

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
NAMES = registry.available()
K, N = 5, 5  # steps before the state is taken, steps compared after it
PAYLOAD = "mass.payload"
PAYLOAD_CHANGE = 0.5  # kg added to the payload: a part picked up
FATAL = 4  # what pythonfmu's binary returns when Python code refuses (see the module docstring)
INTERFACE = {2: "cs", 3: "me"}  # pythonfmu builds FMI 2.0 co-simulation FMUs, pythonfmu3 FMI 3.0 model exchange ones
LUMPED = {"model.fidelity": "lumped"}
CASES = [(n, {}) for n in NAMES] + [(n, LUMPED) for n in NAMES if n.endswith("exudyn_plant")]
CASE_IDS = [n + ("-lumped" if start else "") for n, start in CASES]


@lru_cache(maxsize=None)
def _built(name: str) -> Built:
    path = registry.build(name, ROOT / ".fmu_cache")
    return Built.load(path, name, registry.get(name).fmi)


@pytest.fixture
def instances():
    """Make instances (``instances(built, label)``) of the interface the build has, logging on (pythonfmu logs only
    with it); free them at the end, whatever happened."""
    made = Instances(logging_on=True)
    yield lambda built, label="a": made(built, INTERFACE[built.fmi], label)
    made.free()


# ----------------------------------------------------------------------------- capability and round trip

@pytest.mark.parametrize("name", NAMES)
def test_capabilities_are_declared(name):
    """modelDescription.xml declares the FMU state capabilities for the interface the FMU has."""
    built = _built(name)
    kind = built.md.coSimulation if built.fmi == 2 else built.md.modelExchange
    flags = {"get and set": kind.canGetAndSetFMUstate, "serialize": kind.canSerializeFMUstate}
    assert all(flags.values()), f"{name} (FMI {built.fmi}): capabilities {flags}, expected both true"


@pytest.mark.parametrize("name,start", CASES, ids=CASE_IDS)
def test_round_trip_is_bit_exact(name, start, instances):
    """K steps, get; N steps (A); set, N steps (B == A); the payload changed, set again, N steps (== A); serialized,
    deserialized into a fresh initialized instance, N steps (== A)."""
    built = _built(name)
    a = instances(built)
    a.initialize(start)
    a.steps(K)
    (state, k, t), first, again = a.twice(N)
    assert same_bits(first, again), f"{name} {start}: after set state, {differ(first, again)}"

    if built.has(PAYLOAD):  # the state restores the parameter; the core objects follow it
        a.set_state(state, k, t)
        set_tunable(a, {PAYLOAD: a.get_real([PAYLOAD])[0] + PAYLOAD_CHANGE})
        changed = a.steps(N)
        assert not same_bits(first, changed), f"{name} {start}: the payload changed nothing: {first[-1]}"
        a.set_state(state, k, t)
        restored = a.steps(N)
        assert same_bits(first, restored), f"{name} {start}: payload changed, state set, {differ(first, restored)}"

    data = a.serialize(state)
    a.free_state(state)
    fresh = instances(built, "fresh")
    fresh.initialize(start)
    fresh.set_serialized(data, k, t)
    elsewhere = fresh.steps(N)
    assert same_bits(first, elsewhere), \
        f"{name} {start}: deserialized into a fresh instance, {differ(first, elsewhere)}"
    assert not [m for m in a.messages + fresh.messages if "FMU state" in m], a.messages + fresh.messages


@pytest.mark.parametrize("name", [n for n in NAMES if "plant" in n])
def test_state_across_initialization(name, instances):
    """A state taken in initialization mode, set after K steps: the next N steps are those of a freshly initialized
    instance. A state taken after K steps, set into an instance in initialization mode: after
    exitInitializationMode the next N steps are those of the instance it was taken from."""
    built = _built(name)
    (from_start, restarted), (after_k, continued) = across_initialization(lambda label: instances(built, label), K, N)
    assert same_bits(from_start, restarted), \
        f"{name}: initialization state set after initialization, {differ(from_start, restarted)}"
    assert same_bits(after_k, continued), f"{name}: state set in initialization mode, {differ(after_k, continued)}"


# ----------------------------------------------------------------------------- refusals

@pytest.mark.parametrize("name", NAMES)
def test_state_of_another_fmu_is_refused(name, instances):
    """The in-memory and the serialized state of the next FMU of the same FMI version are refused; the message names
    the other FMU's guid and this one's. The instance is unharmed: its own state still round-trips."""
    built = _built(name)
    same_version = [n for n in NAMES if _built(n).fmi == built.fmi]
    other_built = _built(same_version[(same_version.index(name) + 1) % len(same_version)])
    this, other = instances(built), instances(other_built, "other")
    this.initialize()
    other.initialize()
    other.steps(2)
    foreign = other.get_state()
    data = other.serialize(foreign)
    set_ = this.fmu.setFMUstate if this.fmi == 2 else this.fmu.setFMUState
    guids = (other_built.md.guid, built.md.guid)
    for what, arg in (("in-memory", foreign), ("serialized", this.deserialize(data))):
        logged = refused(this, set_, arg, status=FATAL)
        assert any(all(g in m for g in guids) for m in logged), \
            f"{name}: {what} state of {other_built.name}: expected a message naming {guids}, got {logged}"
        if what == "serialized":
            this.free_state(arg)
    other.free_state(foreign)
    this.steps(1)
    (own, _, _), first, again = this.twice(N)
    this.free_state(own)
    assert same_bits(first, again), f"{name}: its own state after the refusals, {differ(first, again)}"


def test_state_of_another_build_is_refused(tmp_path, instances, monkeypatch):
    """The same FMU built again (a new guid) refuses a state of the first build, naming both guids. Built again in a
    cache of its own: forced into the user's, it replaced the FMU other tests were running (a checkpoint's FMU
    then had another SHA-256)."""
    first = _built("linear_pid")
    monkeypatch.setenv("DELTA_COSIM_CACHE", str(tmp_path / "cache"))
    path = registry.build("linear_pid", tmp_path, force=True)
    again = Built.load(path, "linear_pid", 2)
    assert again.md.guid != first.md.guid, f"the rebuild kept the guid {first.md.guid}"
    old, new = instances(first, "old"), instances(again, "new")
    old.initialize()
    new.initialize()
    old.steps(K)
    copy = new.deserialize(old.serialized())
    logged = refused(new, new.fmu.setFMUstate, copy, status=FATAL)
    new.free_state(copy)
    guids = (first.md.guid, again.md.guid)
    assert any(all(g in m for g in guids) for m in logged), f"expected a message naming {guids}, got {logged}"
    assert np.all(np.isfinite(new.steps(2))), f"no step after the refusal: {new.messages}"


@pytest.mark.parametrize("name", ["linear_pid", "rotary_analytic_plant_me"])
def test_damaged_bytes_are_refused(name, instances):
    """Truncated, padded and corrupted bytes, another format version, another build's guid, not a state at all:
    deserializing gives a state that setting refuses, saying why; the intact bytes still restore exactly."""
    built = _built(name)
    a = instances(built)
    a.initialize()
    a.steps(K)
    data = a.serialized()
    first = a.steps(N)
    head = data.index(b"\n", len(b"delta-cosim FMU state\n")) + 1  # the body starts here

    def flipped(at: int) -> bytes:
        return data[:at] + bytes([data[at] ^ 0x01]) + data[at + 1:]

    guid = data.index(built.md.guid.encode())
    cases = {
        "truncated by a byte": (data[:-1], "checksum mismatch"),
        "truncated into the header": (data[:head - 2], "truncated"),
        "padded": (data + b" ", "checksum mismatch"),
        "a value corrupted": (flipped(head + len(data[head:]) // 2), "checksum mismatch"),
        "the magic corrupted": (flipped(0), "not a delta-cosim FMU state"),
        "another format version": (data.replace(b'"format":1', b'"format":9', 1), "format version 9"),
        "another build's guid": (flipped(guid + 3), "checksum mismatch"),
        "empty": (b"", "not a delta-cosim FMU state"),
        "pickle": (b"\x80\x04\x95\x00", "not a delta-cosim FMU state"),
    }
    set_ = a.fmu.setFMUstate if a.fmi == 2 else a.fmu.setFMUState
    for what, (damaged, reason) in cases.items():
        copy = a.deserialize(damaged)
        logged = refused(a, set_, copy, status=FATAL)
        a.free_state(copy)
        assert any(reason in m for m in logged), f"{name}: {what}: expected {reason!r} in {logged}"
    a.set_serialized(data, K, K * H)
    again = a.steps(N)
    assert same_bits(first, again), f"{name}: intact bytes after the refusals, {differ(first, again)}"


@pytest.mark.parametrize("name", ["linear_ctc", "rotary_analytic_plant", "linear_exudyn_plant",
                                  "linear_analytic_plant_me"])
def test_fixed_parameter_after_initialization_is_refused(name, instances):
    """``mass.platform`` (fixed) set after initialization: refused naming the parameter and why, nothing stored; the
    instance keeps stepping. The same for a fixed string parameter (the Exudyn plant's ``model.fidelity``)."""
    built = _built(name)
    inst = instances(built)
    inst.initialize()
    inst.steps(2)
    before = inst.get_real(["mass.platform"])
    set_ = inst.fmu.setReal if inst.fmi == 2 else inst.fmu.setFloat64
    logged = refused(inst, set_, [built.var("mass.platform").valueReference], [1.0], status=FATAL)
    assert any('"mass.platform"' in m and "fixed" in m for m in logged), \
        f"{name}: expected a message naming the fixed parameter, got {logged}"
    after = inst.get_real(["mass.platform"])
    assert after == before, f"{name}: mass.platform changed by a refused set: {before} -> {after}"
    if built.has("model.fidelity"):
        fidelity = built.var("model.fidelity").valueReference
        logged = refused(inst, inst.fmu.setString, [fidelity], ["lumped"], status=FATAL)
        assert any('"model.fidelity"' in m and "fixed" in m for m in logged), f"{name}: model.fidelity: {logged}"
    assert np.all(np.isfinite(inst.steps(2))), f"{name}: no step after the refusal"


# ----------------------------------------------------------------------------- tunable payload

DECLARING = [n for n in NAMES if n.rsplit("_", 1)[-1] in ("pdplus", "ctc") or "plant" in n]


@pytest.mark.parametrize("name", DECLARING)
def test_payload_is_tunable_and_keeps_the_motion(name, instances):
    """Set after K steps: the next step (derivative evaluation) differs from an unchanged instance's, a plant's motion
    state is not reset, and (but for the Exudyn plant, whose multibody state is not its outputs) it equals, bit for
    bit, that of a fresh instance started with the new payload at the motion state reached."""
    built = _built(name)
    variability = built.var(PAYLOAD).variability
    assert variability == "tunable", f"{name}: {PAYLOAD} is {variability}, expected tunable"
    new = float(built.var(PAYLOAD).start) + PAYLOAD_CHANGE
    changed, unchanged = instances(built, "changed"), instances(built, "unchanged")
    for inst in (changed, unchanged):
        inst.initialize()
        inst.steps(K)
    k, t = changed.k, changed.t
    motion = [f"{q}.{a}" for q in ("p", "v") for a in "xyz"] if built.has("initial.p.x") and built.fmi == 2 else []
    held = changed.outputs()
    start = {PAYLOAD: new, **(dict(zip((f"initial.{n}" for n in motion), changed.get_real(motion))) if motion else {})}
    set_tunable(changed, {PAYLOAD: new})
    changed.read_states()
    kept = changed.outputs()
    if "plant" in name:  # a controller's effort follows the payload at once (G(q), M(q)); a plant moves by steps
        assert same_bits(held, kept), f"{name}: the payload moved the plant before any step, {differ(held, kept)}"
    got, base = probe(changed), probe(unchanged)
    assert not same_bits(got, base), f"{name}: the payload change had no effect: {got}"
    if name.endswith("exudyn_plant"):
        return
    fresh = instances(built, "fresh")
    fresh.initialize(start, t)
    fresh.k = k
    if fresh.nx:
        fresh.x[:fresh.nx] = list(held[-fresh.nx:])
    reference = probe(fresh)
    assert same_bits(got, reference), \
        f"{name}: payload set after K steps vs a fresh instance, {differ(got, reference)}"


SAG_STEPS = 20  # steps after the payload change
# Same lumped masses, two integrators: the analytic plant's RK4 and the Exudyn plant's generalized-alpha (second
# order, rho_inf = 0.8), both at h = 1 ms. The sag's acceleration, a second difference of the positions, agrees to
# their discretisation error of it, (h / T)^2 for the motion's time scale T of tens of ms: below 1e-3 (measured
# 3e-5 linear, 2e-4 rotary). The first step after the change is left out: generalized-alpha's algorithmic
# acceleration takes one step to follow a jump of the load (it gives ~0.75 of it there).
LUMPED_RTOL = 1e-3


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_heavier_payload_sags_alike_in_the_exudyn_and_analytic_plants(kind, instances):
    """Every plant at its home pose held by the hold efforts (the inputs' start values); after K steps the payload
    grows by PAYLOAD_CHANGE in one instance and not in another. The difference of their platform heights (the sag)
    goes down in the analytic plant and in the Exudyn plant, full and lumped, with the acceleration
    ``PAYLOAD_CHANGE g / M_eff`` of the effective mass of vertical motion:

    * the lumped Exudyn plant has the analytic model's masses: the same acceleration within LUMPED_RTOL;
    * the full one has rigid rods where the analytic model puts a share ``w_inertia`` of each rod's mass at the
      platform (the rest at its carriage or elbow): whatever the rods' true share in vertical motion (between 0 and
      1), the effective masses differ by at most ``6 m_rod max(w, 1 - w)``, which bounds the relative difference of
      the accelerations by that over the analytic ``M_eff``."""
    def sag(name: str, start: dict) -> np.ndarray:
        built = _built(name)
        runs = []
        for label, change in (("heavy", PAYLOAD_CHANGE), ("base", 0.0)):
            inst = instances(built, f"{label}_{start.get('model.fidelity', 'full')}")
            inst.wobble = 0.0
            inst.initialize(start)
            inst.steps(K)
            if change:
                inst.set_real({PAYLOAD: inst.get_real([PAYLOAD])[0] + change})
            z = []
            for _ in range(SAG_STEPS):
                inst.step()
                z.append(inst.get_real(["p.z"])[0])
            runs.append(z)
        return np.array(runs[0]) - np.array(runs[1])

    analytic = sag(f"{kind}_analytic_plant", {})
    full, lumped = sag(f"{kind}_exudyn_plant", {}), sag(f"{kind}_exudyn_plant", LUMPED)
    for label, dz in (("analytic", analytic), ("Exudyn full", full), ("Exudyn lumped", lumped)):
        assert np.all(dz[1:] < 0.0), f"{kind} {label}: the heavier payload did not sag the platform: dz = {dz}"

    def acceleration(dz: np.ndarray) -> float:
        return float(dz[-1] - 2.0 * dz[-2] + dz[-3]) / H**2

    a_analytic, a_full, a_lumped = acceleration(analytic), acceleration(full), acceleration(lumped)
    print(f"{kind}: sag acceleration analytic {a_analytic:.6f}, Exudyn full {a_full:.6f} "
          f"({a_full / a_analytic - 1:+.2e}), lumped {a_lumped:.6f} ({a_lumped / a_analytic - 1:+.2e}) m/s2")
    assert abs(a_lumped / a_analytic - 1.0) <= LUMPED_RTOL, \
        f"{kind}: lumped Exudyn sag acceleration {a_lumped} vs analytic {a_analytic} (rtol {LUMPED_RTOL})"
    built = _built(f"{kind}_analytic_plant")
    rod, w = float(built.var("mass.rod").start), float(built.var("model.w_inertia").start)
    m_eff = PAYLOAD_CHANGE * float(built.var("model.gravity").start) / abs(a_analytic)
    rods_rtol = 6.0 * rod * max(w, 1.0 - w) / m_eff
    assert abs(a_full / a_analytic - 1.0) <= rods_rtol, \
        f"{kind}: full Exudyn sag acceleration {a_full} vs analytic {a_analytic} (rtol {rods_rtol:.3f}: the rods)"


# ----------------------------------------------------------------------------- the Exudyn plant itself

PLANT_CASES = [(kind, fidelity) for kind in ("linear", "rotary") for fidelity in ("full", "lumped")]
# macro steps of a plan: split into 3 integrator steps (2.5 ms), a shorter one (the Newton matrix refactorised), one
# an ulp-scale longer (a tool adding float steps)
STEP_PLAN = (1e-3, 1e-3, 2.5e-3, 1e-3, 0.5e-3, 1e-3 + 1e-13, 1e-3)


def _plant(kind: str, fidelity: str, payload: float | None = None):  # noqa: ANN202
    """The Exudyn plant of the kind's preset as the FMU builds it (1 ms integrator steps at most), at home."""
    from delta.actuators import kind_of
    from delta.robots import get_preset
    from fmus.adapters.common import PRESET, home
    from multibody import SolverSettings, make_plant

    masses = kind_of(kind).masses_type
    m = masses() if payload is None else masses(payload=payload)
    return make_plant(get_preset(PRESET[kind]), m, fidelity=fidelity, settings=SolverSettings(max_step=1e-3),
                      p0=home(kind))


def _drive(plant, kind: str, first: int, n: int) -> np.ndarray:  # noqa: ANN001
    """Steps ``first`` .. ``first + n`` of STEP_PLAN (cycled) under hold efforts wobbling by 30 %: q, qd, p, v."""
    from fmus.adapters.common import hold_effort

    u0 = np.array(hold_effort(kind))
    rows = []
    for i in range(first, first + n):
        out = plant.step(plant.time, STEP_PLAN[i % len(STEP_PLAN)], u0 * (1.0 + 0.3 * math.sin(0.37 * i)))
        rows.append(np.concatenate([out.q, out.qd, out.p, out.v]))
    return np.array(rows)


@pytest.mark.parametrize("kind,fidelity", PLANT_CASES)
def test_plant_state_continues_exactly_in_place_and_in_another_plant(kind, fidelity):
    """DeltaPlant.get_state after 30 steps of varying size with a payload change among them (plain data, through
    JSON); 30 more steps; set_state into the same plant and into another one with another history (other steps, no
    payload change): the same 30 steps bit for bit."""
    import json

    from fmus._names import is_plain

    plant = _plant(kind, fidelity)
    _drive(plant, kind, 0, 12)
    plant.set_payload(0.2)
    _drive(plant, kind, 12, 18)
    state = plant.get_state()
    assert is_plain(state), f"{kind} {fidelity}: the plant state is not plain data"
    state = json.loads(json.dumps(state))
    first = _drive(plant, kind, 30, 30)
    plant.set_state(state)
    again = _drive(plant, kind, 30, 30)
    assert same_bits(first, again), f"{kind} {fidelity}: set_state in place, {differ(first, again)}"
    other = _plant(kind, fidelity)
    _drive(other, kind, 100, 7)
    other.set_state(state)
    elsewhere = _drive(other, kind, 30, 30)
    assert same_bits(first, elsewhere), f"{kind} {fidelity}: set_state into another plant, {differ(first, elsewhere)}"


@pytest.mark.parametrize("kind,fidelity", PLANT_CASES)
def test_set_payload_gives_the_system_built_with_it(kind, fidelity):
    """After set_payload, the platform's mass, inertia and weight and the solver's mass matrix are those of a plant
    built with that payload, bit for bit."""
    plant, built = _plant(kind, fidelity), _plant(kind, fidelity, payload=0.7)
    _drive(plant, kind, 0, 3)
    plant.set_payload(0.7)
    for what, got, expected in (
            ("platform", plant.mbs.GetObject(plant._platform), built.mbs.GetObject(built._platform)),
            ("weight", plant.mbs.GetLoad(plant._platform_weight), built.mbs.GetLoad(built._platform_weight))):
        for key in set(expected) & {"mass", "inertia", "loadVector"}:
            assert np.array_equal(got[key], expected[key]), \
                f"{kind} {fidelity} {what} {key}: {got[key]} vs {expected[key]}"
    m_got, m_built = plant._solver.GetSystemMassMatrix(), built._solver.GetSystemMassMatrix()
    assert same_bits(m_got, m_built), f"{kind} {fidelity}: mass matrix, {differ(m_got, m_built)}"
