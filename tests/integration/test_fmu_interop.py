"""Our FMUs as any FMI importer sees them (issue 14), driven through fmpy directly, not our master:

- outputs are valid in initialization mode (computed from the parameters and inputs of that moment);
- the ModelStructure ``dependencies`` of every output (and ME state derivative) are the truth:
  perturbing one input changes, without a step, exactly the outputs declared to depend on it;
- every plant accepts any communication step > 0 (1e-13 s, 1e-6 s, 0.1 s) and reports an
  impossible one as fmi2Discard with a logged message, never fmi2Fatal.
"""

from __future__ import annotations

import math
from ctypes import c_double
from pathlib import Path

import numpy as np
import pytest

from fmus import registry

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
NAMES = registry.available()

# Inputs are perturbed by this much relative to their start value (absolute below 1): large
# enough that a dependent output moves far above rounding (sensitivities are O(1e-3) to O(1e4)),
# small enough to stay in the workspace and away from the effort limits.
PERTURBATION = 1e-4
# The feedthrough check runs at a generic operating point: every input moved off its start value
# (often a symmetric pose at rest, where e.g. qd_ref = J^-1 v_ref is 0 whatever p_ref) by
# OFFSET * (1 + k / n) relative, input k of n. Small enough to keep the CTC effort (stiffness
# 22500 1/s^2) far from its 500 N limit, where the effort would stop depending on anything.
OFFSET = 1e-3
# "Changed": by more than 1e-9 relative (a million times double rounding, which recomputing a
# value through another path may add) plus 1e-15 absolute (rounding of values near zero); a
# dependent output moves by at least ~1e-7 here (sensitivity x PERTURBATION).
CHANGE_RTOL, CHANGE_ATOL = 1e-9, 1e-15
# Closed-form round trips (IK then FK, trajectory formula evaluated twice): rounding only.
CLOSED_FORM_TOL = 1e-12
# Exudyn's index-3 generalized-alpha enforces the position constraints to its Newton tolerance
# (absolute 1e-10): platform position against FK of the joints, measured <= 2.1e-11 m.
EXUDYN_POSITION_TOL_M = 1e-9
# Velocity-level constraints are not enforced by index-3 generalized-alpha, only implied through
# the integration formulas: platform velocity against J(q) qd, measured <= 4.8e-7 m/s (rotary).
EXUDYN_VELOCITY_TOL = 1e-5
# A step absorbed below the plant's resolution (1 ns) may leave the state that old: |qd| * 1 ns.
RESOLUTION_S = 1e-9


def _path(name: str) -> str:
    return str(registry.build(name, ROOT / ".fmu_cache"))


class _Instance:
    """One FMU instance through fmpy (FMU2Slave for co-simulation, FMU3Model for model exchange),
    with its log messages collected."""

    def __init__(self, name: str, start_time: float = 0.0, parameters: dict[str, float] | None = None):
        import fmpy

        path = _path(name)
        self.name = name
        self.md = fmpy.read_model_description(path)
        self.me = self.md.fmiVersion.startswith("3")
        self.var = {v.name: v for v in self.md.modelVariables}
        self.messages: list[str] = []
        unzipped = fmpy.extract(path)
        if self.me:
            from fmpy.fmi3 import FMU3Model

            self.fmu = FMU3Model(guid=self.md.guid, unzipDirectory=unzipped,
                                 modelIdentifier=self.md.modelExchange.modelIdentifier, instanceName=name)
            self.fmu.instantiate(loggingOn=True, logMessage=self._log3)
        else:
            from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
            from fmpy.fmi2 import calloc, free

            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipped,
                                 modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
            self._callbacks = fmi2CallbackFunctions()
            self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
            self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        if parameters:
            self.set(list(parameters), list(parameters.values()))
        if self.me:
            self.fmu.enterInitializationMode(startTime=start_time)
        else:
            self.fmu.setupExperiment(startTime=start_time)
            self.fmu.enterInitializationMode()
        self.time = start_time

    def _log2(self, env, instance, status, category, message):
        self.messages.append((message or b"").decode())

    def _log3(self, env, status, category, message):
        self.messages.append((message or b"").decode())

    def names(self, causality: str) -> list[str]:
        return [v.name for v in self.md.modelVariables if v.causality == causality]

    def get(self, names: list[str]) -> list[float]:
        out = []
        for n in names:
            v = self.var[n]
            if v.type == "Boolean":
                out.append(float(self.fmu.getBoolean([v.valueReference])[0]))
            elif self.me:
                out.append(self.fmu.getFloat64([v.valueReference])[0])
            else:
                out.append(self.fmu.getReal([v.valueReference])[0])
        return out

    def set(self, names: list[str], values) -> None:
        vrs = [self.var[n].valueReference for n in names]
        values = [float(x) for x in values]
        if self.me:
            self.fmu.setFloat64(vrs, values)
        else:
            self.fmu.setReal(vrs, values)

    def exit_initialization(self) -> None:
        self.fmu.exitInitializationMode()
        if self.me:
            self.fmu.updateDiscreteStates()
            self.fmu.enterContinuousTimeMode()

    def step(self, h: float) -> None:
        """A communication step (CS) or one explicit Euler step of the states (ME, the importer's job)."""
        if self.me:
            n = len(self.md.derivatives)
            x, dx = (c_double * n)(), (c_double * n)()
            self.fmu.getContinuousStates(x, n)
            self.fmu.getContinuousStateDerivatives(dx, n)
            self.fmu.setTime(self.time + h)
            self.fmu.setContinuousStates((c_double * n)(*[a + h * b for a, b in zip(x, dx)]), n)
        else:
            self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=h)
        self.time += h

    def close(self) -> None:
        # free the instance but keep the library loaded (unloading a pythonfmu library crashes at GC)
        if self.me:
            self.fmu.terminate()
            self.fmu.fmi3FreeInstance(self.fmu.component)
        else:
            self.fmu.terminate()
            self.fmu.fmi2FreeInstance(self.fmu.component)


def _start_inputs(inst: _Instance) -> dict[str, float]:
    return {n: float(inst.var[n].start) for n in inst.names("input")}


def _declared(inst: _Instance) -> dict[str, set[str]]:
    """Output (and ME state derivative) -> the inputs it depends on directly, from ModelStructure."""
    inputs = set(inst.names("input"))
    out = {}
    for unknown in [*inst.md.outputs, *(inst.md.derivatives if inst.me else [])]:
        assert unknown.dependencies is not None, f"{inst.name}: {unknown.variable.name} declares no dependencies"
        out[unknown.variable.name] = {d.name for d in unknown.dependencies if d.name in inputs}
    return out


# --------------------------------------------------------------------------- item 1: initialization mode


@pytest.mark.parametrize("name", NAMES)
def test_outputs_in_initialization_mode_equal_those_after_it(name):
    """Inputs set to off-start values in initialization mode: the outputs read there are finite and
    equal (bit for bit: same code, same values) those read right after exitInitializationMode."""
    inst = _Instance(name)
    try:
        inputs = {n: v + PERTURBATION * max(1.0, abs(v)) for n, v in _start_inputs(inst).items()}
        observed = list(_declared(inst))
        inst.set(list(inputs), list(inputs.values()))
        during = inst.get(observed)
        inst.exit_initialization()
        after = inst.get(observed)
    finally:
        inst.close()
    assert all(map(math.isfinite, during)), f"{name}: non-finite outputs in initialization mode: " \
                                            f"{dict(zip(observed, during))}"
    differ = {n: (a, b) for n, a, b in zip(observed, during, after) if a != b}  # exact: same code, same values
    assert not differ, f"{name}: (initialization mode, after it) differ: {differ}"


def test_trajectory_outputs_in_initialization_mode_are_the_reference_at_the_start_time():
    from delta.trajectories import Helix

    t0 = 0.25
    inst = _Instance("helix", start_time=t0)
    try:
        p = inst.get(["p_ref.x", "p_ref.y", "p_ref.z"])
    finally:
        inst.close()
    expected = Helix().evaluate(t0)[0]
    assert np.allclose(p, expected, rtol=0, atol=CLOSED_FORM_TOL), f"p_ref({t0} s) {p} vs helix {expected}"


def test_ik_outputs_in_initialization_mode_follow_the_inputs_of_that_moment():
    from delta.kinematics import ik
    from delta.robots import get_preset

    p = (0.03, -0.02, -0.52)
    inst = _Instance("linear_ik")
    try:
        inst.set(["p_ref.x", "p_ref.y", "p_ref.z"], p)
        q = inst.get(["q_ref[1]", "q_ref[2]", "q_ref[3]", "reachable"])
    finally:
        inst.close()
    expected = ik(get_preset("linear_delta_thesis"), p).require()
    assert q[3] == 1.0, f"{p} is reachable, the FMU says reachable = {q[3]}"
    assert np.allclose(q[:3], expected, rtol=0, atol=CLOSED_FORM_TOL), f"q_ref {q[:3]} vs IK {expected}"


PLANTS = [n for n in NAMES if "plant" in n]


@pytest.mark.parametrize("name", PLANTS)
def test_plant_outputs_in_initialization_mode_are_the_initial_state(name):
    """Set initial.p after a first read (the model is rebuilt from the new parameters): the
    plant's p in initialization mode is initial.p (IK then FK: a closed-form round trip)."""
    p0 = (0.02, 0.01, -0.48) if name.startswith("linear") else (0.02, 0.01, -0.45)
    inst = _Instance(name)
    try:
        inst.get(["p.x"])  # builds the model from the start values
        inst.set(["initial.p.x", "initial.p.y", "initial.p.z"], p0)
        p = inst.get(["p.x", "p.y", "p.z"])
        v = inst.get(["v.x", "v.y", "v.z"])
    finally:
        inst.close()
    assert np.allclose(p, p0, rtol=0, atol=CLOSED_FORM_TOL), f"{name}: p {p} vs initial.p {p0}"
    assert np.allclose(v, 0.0, rtol=0, atol=CLOSED_FORM_TOL), f"{name}: v {v} vs initial.v 0"


# --------------------------------------------------------------------------- item 2: ModelStructure


def _check_feedthrough(inst: _Instance, phase: str) -> list[str]:
    """Perturb each input alone at a generic operating point; the outputs that change without a
    step must be exactly those declared dependent (see CHANGE_RTOL). Booleans (reachable, valid)
    do not flip under a small perturbation: they are only checked not to change when independent."""
    declared = _declared(inst)
    observed = list(declared)
    start = _start_inputs(inst)
    point = {n: v + OFFSET * (1 + k / len(start)) * max(1.0, abs(v)) for k, (n, v) in enumerate(start.items())}
    inst.set(list(point), list(point.values()))
    base = inst.get(observed)
    problems = []
    for name, value in point.items():
        inst.set([name], [value + PERTURBATION * max(1.0, abs(value))])
        moved = inst.get(observed)
        inst.set([name], [value])
        for out, a, b in zip(observed, base, moved):
            dependent = name in declared[out]
            boolean = inst.var[out].type == "Boolean"
            changed = abs(b - a) > CHANGE_RTOL * max(abs(a), abs(b)) + CHANGE_ATOL
            if changed != dependent and not (boolean and dependent):
                problems.append(f"{phase}: {out} {'declares' if dependent else 'does not declare'} a dependency "
                                f"on {name}, but perturbing it moved {out} from {a!r} to {b!r}")
    assert inst.get(observed) == base, f"{inst.name} {phase}: outputs did not return with the inputs"
    return problems


@pytest.mark.parametrize("name", NAMES)
def test_declared_dependencies_are_the_direct_feedthrough(name):
    """A plant starts off its symmetric home pose, where the platform dynamics have exact zeros by symmetry (a leg in
    the x-z plane moves the platform in neither y nor its velocity's y: the model-exchange plant's der(v.y) does not
    depend on u[1] there, though it does everywhere else)."""
    inst = _Instance(name)
    try:
        if "initial.p.x" in inst.var:
            p0 = (0.02, 0.01, -0.48) if name.startswith("linear") else (0.02, 0.01, -0.45)
            inst.set(["initial.p.x", "initial.p.y", "initial.p.z"], p0)
        problems = _check_feedthrough(inst, "initialization mode")
        inst.exit_initialization()
        inst.step(1e-3)
        problems += _check_feedthrough(inst, "after a 1 ms step")
    finally:
        inst.close()
    assert not problems, f"{name}:\n" + "\n".join(problems)


def test_plants_and_trajectories_declare_no_direct_feedthrough():
    """What the master's Gauss-Seidel order relies on, now from the FMUs rather than scenarios."""
    from cosim.fmi import load_fmu

    for name in NAMES:
        if "plant" in name or registry.get(name).role == "trajectory":
            feed = load_fmu(_path(name)).feedthrough
            assert all(deps == [] for deps in feed.values()), f"{name}: declared dependencies {feed}"


# --------------------------------------------------------------------------- item 3: any step > 0

CS_PLANTS = [(n, f) for n in PLANTS if registry.get(n).fmi == 2
             for f in (("full", "lumped") if "exudyn" in n else (None,))]
STEPS = (1e-3, 1e-13, 1e-6, 0.1, 1e-13, 1e-3)


def _robot(name: str):
    from delta.robots import get_preset

    return get_preset("linear_delta_thesis" if name.startswith("linear") else "rotary_delta_prototype")


@pytest.mark.parametrize(("name", "fidelity"), CS_PLANTS, ids=[f"{n}-{f}" if f else n for n, f in CS_PLANTS])
def test_plant_accepts_tiny_and_long_steps(name, fidelity):
    """Steps of 1e-13 s (a tool adding float steps), 1e-6 s and 0.1 s, from a moving start: every
    doStep returns OK (fmpy raises otherwise), the states stay finite, the platform state matches
    the kinematics of the joint state, and a 1e-13 s step leaves the state within |qd| * 1 ns."""
    from delta.kinematics import fk, platform_velocity

    robot = _robot(name)
    inst = _Instance(name, parameters={"initial.v.x": 0.05, "initial.v.z": -0.03})
    Q, QD = ["q[1]", "q[2]", "q[3]"], ["qd[1]", "qd[2]", "qd[3]"]
    P, V = ["p.x", "p.y", "p.z"], ["v.x", "v.y", "v.z"]
    exudyn = "exudyn" in name
    pos_tol = EXUDYN_POSITION_TOL_M if exudyn else CLOSED_FORM_TOL
    vel_tol = EXUDYN_VELOCITY_TOL if exudyn else CLOSED_FORM_TOL
    try:
        if fidelity:
            inst.fmu.setString([inst.var["model.fidelity"].valueReference], [fidelity])
        inst.exit_initialization()
        worst = {"p": 0.0, "v": 0.0}
        for h in STEPS:
            q0, qd0 = np.array(inst.get(Q)), np.array(inst.get(QD))
            inst.step(h)
            q, qd, p, v = (np.array(inst.get(names)) for names in (Q, QD, P, V))
            state = np.concatenate([q, qd, p, v])
            assert np.all(np.isfinite(state)), f"{name} {fidelity}: non-finite state after h = {h}: {state}"
            fk_p = fk(robot, q).p
            fk_v = platform_velocity(robot, q, fk_p, qd)
            worst["p"] = max(worst["p"], float(np.max(np.abs(p - fk_p))))
            worst["v"] = max(worst["v"], float(np.max(np.abs(v - fk_v))))
            assert np.allclose(p, fk_p, rtol=0, atol=pos_tol), f"{name} {fidelity} h = {h}: p {p} vs FK(q) {fk_p}"
            assert np.allclose(v, fk_v, rtol=0, atol=vel_tol), f"{name} {fidelity} h = {h}: v {v} vs J qd {fk_v}"
            if h < RESOLUTION_S:
                bound = np.abs(qd0) * RESOLUTION_S + CLOSED_FORM_TOL
                assert np.all(np.abs(q - q0) <= bound), f"{name} {fidelity}: h = {h} moved q by {q - q0} > {bound}"
        print(f"{name} {fidelity}: largest |p - FK(q)| = {worst['p']:.2e} m, |v - J qd| = {worst['v']:.2e} m/s")
    finally:
        inst.close()


@pytest.mark.parametrize("name", ["linear_analytic_plant", "linear_exudyn_plant"])
def test_impossible_step_is_discarded_with_a_logged_message(name):
    """A zero step and a non-finite effort: fmi2Discard (status 2, not fmi2Fatal = 4) and a message
    through the FMI logger; a zero step leaves the instance usable, a failed one refuses to go on."""
    from fmpy.fmi1 import FMICallException

    inst = _Instance(name)
    try:
        if "exudyn" in name:
            inst.fmu.setString([inst.var["model.fidelity"].valueReference], ["lumped"])
        inst.exit_initialization()
        with pytest.raises(FMICallException) as zero:
            inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.0)
        assert zero.value.status == 2, f"h = 0: status {zero.value.status}, expected 2 (discard)"
        assert any("must be a finite h > 0" in m for m in inst.messages), f"log: {inst.messages}"
        inst.step(1e-3)  # still usable
        inst.set(["u[1]"], [float("nan")])
        with pytest.raises(FMICallException) as bad:
            inst.fmu.doStep(currentCommunicationPoint=inst.time, communicationStepSize=1e-3)
        assert bad.value.status == 2, f"u = NaN: status {bad.value.status}, expected 2 (discard)"
        assert any("non-finite effort" in m for m in inst.messages), f"log: {inst.messages}"
        inst.set(["u[1]"], [0.0])
        with pytest.raises(FMICallException) as refused:
            inst.fmu.doStep(currentCommunicationPoint=inst.time, communicationStepSize=1e-3)
        assert refused.value.status == 2, f"after a failure: status {refused.value.status}, expected 2"
        assert any("cannot continue" in m for m in inst.messages), f"log: {inst.messages}"
    finally:
        inst.close()
