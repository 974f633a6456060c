"""The master uses the FMU state of FMUs that are not ours (issue 34).

The FMUs are the C models of ``tests/cfmus``, built with gcc against FMPy's FMI headers. ``BouncingBall`` and
``Integrator`` (FMI 2 and 3) keep their state as the Modelica Reference FMUs do (GetFMUstate copies the instance
and the model's data, SetFMUstate copies them back, serialization writes those bytes and de-serialization checks
only their size); ``VanDerPol`` declares no state. Through ``python -m cosim run`` (as a user runs it):

- a checkpoint written at ``T_CHECKPOINT`` and resumed gives the uninterrupted run's samples from there bit for
  bit, and writing it leaves the run unchanged;
- a state event on the ball's height is located by restoring the FMUs' states and stepping again, to within
  ``LOCATE_TOL`` after its analytic time, and logged on ``/events``;
- with a stateless FMU in the system, the event fires at the end of its macro step, with one note naming it;
- a serialized state of one FMU given to another is refused by the FMU: an error, not a crash.

Tolerances: ``LOCATE_TOL = 1e-6`` s is the events' default tolerance (the issue's requirement); the ball's flight is
a quadratic, which the FMU's RK4 integrates exactly, so its height carries only round-off (~1e-15 m, i.e. ~1e-15 s
near the crossing at 3 m/s). ``GRID_ATOL = 1e-12`` s: grid times are integer nanoseconds times 1e-9.
``REBOUND_ATOL = 1e-9`` m/s: the FMU bisects an impact to 1e-13 s (g times that is 1e-12 m/s); measured 6e-13.
"""

from __future__ import annotations

import hashlib
import json
import math
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
import yaml
from cfmus import build
from cli_helpers import cosim
from fmpy import fmi2, fmi3
from fmpy.fmi1 import FMICallException

from cosim.io.runlog import read_run

pytestmark = pytest.mark.integration

G, H0, E = 9.81, 1.0, 0.7  # BouncingBall defaults (|g|, m/s2; m; restitution)
STEP = 0.01  # s, the macro step
STOP = 3.0  # s: past the ball's fourth impact
T_CHECKPOINT = 1.0  # s: after the first impact (0.45 s), before the second (1.08 s)
H_EVENT = 0.5  # m: the state event's threshold on the ball's height
E_EVENT = 0.5  # the restitution the event sets
LOCATE_TOL = 1e-6
GRID_ATOL = 1e-12
REBOUND_ATOL = 1e-9


def scenario(tmp_path: Path, components: dict[str, tuple[str, int]], connections=(), events=()) -> Path:
    """A scenario file of cfmus FMUs (name -> (model, FMI version)), every signal logged."""
    text = yaml.safe_dump({
        "name": "third_party_state",
        "components": {name: {"path": str(build(model, fmi))} for name, (model, fmi) in components.items()},
        "connections": [{"from": a, "to": b} for a, b in connections],
        "time": {"stop": STOP, "step": STEP},
        "logging": {"signals": "all"},
        "events": list(events),
    }, sort_keys=False)
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return path


def stateful_system(tmp_path: Path, ball_fmi: int, integ_fmi: int, events=()) -> Path:
    """The ball's height integrated by the Integrator: two FMUs with state, one connection."""
    return scenario(tmp_path, {"ball": ("BouncingBall", ball_fmi), "integ": ("Integrator", integ_fmi)},
                    [("ball.h", "integ.u")], events)


def run(*args) -> dict:
    """``python -m cosim run *args --json``: the run's summary; the command must succeed."""
    proc = cosim("run", *args, "--json")
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr}"
    return json.loads(proc.stdout)


def assert_bit_identical(log, ref, what: str, since: float = -math.inf) -> int:
    """``log``'s samples at ``since`` and after equal ``ref``'s bit for bit, every signal; returns how many."""
    assert set(log.signals) == set(ref.signals), f"{what}: signals {sorted(log.signals)} vs {sorted(ref.signals)}"
    n = 0
    for name in sorted(ref.signals):
        ours, theirs = log.signals[name], ref.signals[name]
        keep = ours.t >= since
        t, y = ours.t[keep], ours.y[keep]
        ref_keep = theirs.t >= since
        t_ref, y_ref = theirs.t[ref_keep], theirs.y[ref_keep]
        assert len(t) == len(t_ref), f"{what}, {name}: {len(t)} samples vs {len(t_ref)} in the reference run"
        assert np.array_equal(t, t_ref), f"{what}, {name}: sample times {t[:3]}... vs {t_ref[:3]}..."
        bad = np.flatnonzero(y != y_ref)
        assert bad.size == 0, (f"{what}, {name}: first difference at t = {t[bad[0]]!r}: {y[bad[0]]!r} vs "
                               f"{y_ref[bad[0]]!r} in the reference run ({bad.size} samples differ)")
        n += len(t)
    return n


# --------------------------------------------------------------------------- (a) checkpoint and resume


@pytest.mark.parametrize("ball_fmi, integ_fmi", [(2, 3), (3, 2)])
def test_resumed_checkpoint_continues_the_uninterrupted_run_bit_for_bit(tmp_path, ball_fmi, integ_fmi):
    path = stateful_system(tmp_path, ball_fmi, integ_fmi)
    full, part, resumed, ckpt = (tmp_path / n for n in ("full.mcap", "part.mcap", "resumed.mcap", "run.ckpt"))
    run(path, "--out", full)
    written = run(path, "--out", part, "--checkpoint-at", T_CHECKPOINT, "--checkpoint-out", ckpt)
    assert written["checkpoint"] == str(ckpt), f"checkpoint {written['checkpoint']!r}, expected {str(ckpt)!r}"
    summary = run("--resume", ckpt, "--out", resumed)
    assert summary["status"] == "completed", f"resumed run: {summary['status']}: {summary.get('message')}"

    ref, log = read_run(full), read_run(resumed)
    # saving and serializing the states did not disturb the run that wrote the checkpoint
    assert_bit_identical(read_run(part), ref, "the run that wrote the checkpoint")
    first = min(float(s.t[0]) for s in log.signals.values())
    assert abs(first - T_CHECKPOINT) <= GRID_ATOL, f"resumed log starts at {first!r} s, checkpoint at {T_CHECKPOINT} s"
    n = assert_bit_identical(log, ref, "resumed run", since=T_CHECKPOINT - GRID_ATOL)
    n_expected = 5 * (round((STOP - T_CHECKPOINT) / STEP) + 1)  # five signals, T..STOP inclusive
    assert n == n_expected, f"{n} samples compared, expected {n_expected}"
    # the states restored were mid-run ones, not the start: the ball had bounced, the integral had grown
    bounces, x = log.signals["ball.bounces"].y[0], log.signals["integ.x"].y[0]
    assert bounces == 1 and x > 0.0, f"at the checkpoint bounces = {bounces}, integ.x = {x}; expected 1 and > 0"


# --------------------------------------------------------------------------- (b) a state event located by state


def first_crossing(h: float) -> float:
    """When the falling ball's height first reaches ``h``: H0 - G t^2 / 2 = h."""
    return math.sqrt(2.0 * (H0 - h) / G)


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_state_event_on_a_third_party_output_is_located_with_its_fmu_state(tmp_path, fmi):
    path = stateful_system(tmp_path, fmi, 3 if fmi == 2 else 2,
                           events=[{"when": f"ball.h < {H_EVENT}", "set": {"ball.e": E_EVENT}}])
    out = tmp_path / "run.mcap"
    summary = run(path, "--out", out)
    log = read_run(out)
    t_star = first_crossing(H_EVENT)
    assert len(log.events) == 1, f"/events holds {log.events}, expected one event"
    ev = log.events[0]
    assert (ev["event"], ev["set"]) == (0, {"ball.e": E_EVENT}), (
        f"/events: event {ev['event']}, set {ev['set']}; expected event 0, set {{'ball.e': {E_EVENT}}}")
    assert 0.0 <= ev["t"] - t_star <= LOCATE_TOL, (
        f"event at {ev['t']!r} s, analytic crossing {t_star!r} s: {ev['t'] - t_star:.3g} s after it")
    located = [n for n in summary["notes"] if "located" in n]
    assert len(located) == 1 and located[0].startswith("1 state event"), f"notes {summary['notes']}"
    assert not any("cannot save" in n for n in summary["notes"]), f"a fallback note: {summary['notes']}"
    # the restitution set before the impact is the one the impact used: rebound at E_EVENT times the impact speed
    t_impact = first_crossing(0.0)
    v = log.signals["ball.v"]
    k = int(np.searchsorted(v.t, t_impact))
    v_expected = E_EVENT * G * t_impact - G * (v.t[k] - t_impact)
    assert abs(v.y[k] - v_expected) <= REBOUND_ATOL, (
        f"v({v.t[k]}) = {v.y[k]!r}, expected {v_expected!r} after a rebound with e = {E_EVENT}")


# --------------------------------------------------------------------------- (c) a stateless FMU in the system


def test_a_stateless_third_party_fmu_moves_the_event_to_the_end_of_its_step_with_one_note(tmp_path):
    md = fmpy.read_model_description(str(build("VanDerPol", 2)))
    assert not md.coSimulation.canGetAndSetFMUstate, "VanDerPol must stay without FMU state for this test"
    path = scenario(tmp_path, {"ball": ("BouncingBall", 2), "integ": ("Integrator", 3), "vdp": ("VanDerPol", 2)},
                    [("ball.h", "integ.u")], [{"when": f"ball.h < {H_EVENT}", "set": {"ball.e": E_EVENT}}])
    out = tmp_path / "run.mcap"
    summary = run(path, "--out", out)
    t_end = math.ceil(first_crossing(H_EVENT) / STEP) * STEP  # the end of the macro step of the crossing
    times = [e["t"] for e in read_run(out).events]
    assert len(times) == 1 and abs(times[0] - t_end) <= GRID_ATOL, (
        f"fired at {times}, expected once at the end of the step, {t_end!r} s")
    naming = [n for n in summary["notes"] if "vdp" in n]
    assert len(naming) == 1 and "state" in naming[0], f"notes naming vdp: {naming}; expected one on state events"
    others = [n for n in summary["notes"] if "state event" in n and ("ball" in n or "integ" in n)]
    assert not others, f"notes naming the components with state: {others}"


# --------------------------------------------------------------------------- (d) another FMU's state is refused


def with_state_swapped(src: Path, dst: Path, giver: str, taker: str) -> None:
    """``src``'s checkpoint with ``giver``'s serialized FMU state in ``taker``'s place, its size and checksum in the
    header updated: the checkpoint's own checks pass, the FMU alone can tell."""
    with zipfile.ZipFile(src) as z:
        members = {name: z.read(name) for name in z.namelist()}
    header = json.loads(members["checkpoint.json"])
    comps = {c["name"]: c for c in header["components"]}
    blob = members[comps[giver]["state"]]
    taker_entry = comps[taker]
    members[taker_entry["state"]] = blob
    taker_entry.update(state_bytes=len(blob), state_sha256=hashlib.sha256(blob).hexdigest())
    members["checkpoint.json"] = json.dumps(header).encode()
    with zipfile.ZipFile(dst, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)


@pytest.mark.parametrize("giver, taker, fmi_function", [("ball", "integ", "fmi3DeserializeFMUState"),
                                                         ("integ", "ball", "fmi2DeSerializeFMUstate")])
def test_a_checkpoint_holding_another_fmus_state_is_refused_by_the_fmu(tmp_path, giver, taker, fmi_function):
    path = stateful_system(tmp_path, 2, 3)
    ckpt, bad = tmp_path / "run.ckpt", tmp_path / "swapped.ckpt"
    run(path, "--out", tmp_path / "part.mcap", "--checkpoint-at", T_CHECKPOINT, "--checkpoint-out", ckpt)
    with_state_swapped(ckpt, bad, giver, taker)
    proc = cosim("run", "--resume", bad, "--out", tmp_path / "resumed.mcap")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, f"exit {proc.returncode}, expected 2 (an error); stderr: {proc.stderr}"
    assert len(lines) == 1, f"stderr has {len(lines)} lines, expected one: {proc.stderr}"
    assert f"'{taker}'" in lines[0] and fmi_function in lines[0] and "not a state of this FMU" in lines[0], (
        f"stderr {lines[0]!r}; expected it to name {taker!r}, {fmi_function} and the FMU's reason")


class Instance:
    """An FMPy co-simulation instance of a cfmus FMU, initialized at t = 0, its log messages collected."""

    def __init__(self, model: str, fmi: int, tmp_path: Path):
        path = build(model, fmi)
        md = fmpy.read_model_description(str(path))
        self.fmi, self.messages = fmi, []
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        unzipped = fmpy.extract(str(path), unzipdir=str(tmp_path / f"{model}{fmi}"))
        kind = fmi2.FMU2Slave if fmi == 2 else fmi3.FMU3Slave
        self.fmu = kind(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=model, instanceName=model)
        if fmi == 2:
            callbacks = fmi2.fmi2CallbackFunctions()
            callbacks.logger = fmi2.fmi2CallbackLoggerTYPE(
                lambda env, name, status, category, message: self.messages.append(message.decode()))
            callbacks.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
            callbacks.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)
            self.fmu.instantiate(callbacks=callbacks)
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.instantiate(logMessage=lambda env, status, category, message:
                                 self.messages.append(message.decode()))
            self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def get(self, name: str) -> float:
        vr = [self.vr[name]]
        return (self.fmu.getReal(vr) if self.fmi == 2 else self.fmu.getFloat64(vr))[0]

    def set(self, name: str, value: float) -> None:
        (self.fmu.setReal if self.fmi == 2 else self.fmu.setFloat64)([self.vr[name]], [value])

    def serialized_state(self) -> bytes:
        state = self.fmu.getFMUState()
        try:
            return bytes(self.fmu.serializeFMUState(state))
        finally:
            self.fmu.freeFMUState(state)

    def deserialize(self, data: bytes):
        return (self.fmu.deSerializeFMUstate if self.fmi == 2 else self.fmu.deserializeFMUState)(data)


@pytest.mark.parametrize("fmi", [2, 3])
def test_an_fmu_refuses_another_fmus_serialized_state_and_lives_on(tmp_path, fmi):
    """Directly through FMPy: the Integrator refuses the BouncingBall's bytes with an error (logged), and the
    instance goes on with its own state, which still round-trips."""
    ball, integ = Instance("BouncingBall", fmi, tmp_path), Instance("Integrator", fmi, tmp_path)
    try:
        foreign = ball.serialized_state()
        integ.set("u", 1.0)
        integ.fmu.doStep(0.0, 0.5)  # x = 0.5 (exact: RK4 of a constant rate)
        x_before = integ.get("x")
        with pytest.raises(FMICallException) as info:
            integ.deserialize(foreign)
        assert info.value.status == 3, f"status {info.value.status}, expected 3 (Error)"
        assert any("not a state of this FMU" in m for m in integ.messages), f"logged {integ.messages}"
        own = integ.serialized_state()
        integ.set("u", 2.0)
        integ.fmu.doStep(0.5, 0.5)
        x_after = integ.get("x")
        assert x_after == x_before + 1.0, f"x = {x_after!r} after the step, expected {x_before + 1.0!r}"
        state = integ.deserialize(own)
        integ.fmu.setFMUState(state)
        integ.fmu.freeFMUState(state)
        x_restored = integ.get("x")
        assert x_restored == x_before, f"x = {x_restored!r} after restoring its own state, expected {x_before!r}"
    finally:
        for inst in (ball, integ):
            inst.fmu.terminate()
            inst.fmu.freeInstance()
