"""FMI 1.0 through the master against FMPy on the same files (issue 26, item 3).

The FMUs are the C models of ``tests/cfmus`` built for FMI 1.0, one file per interface (FMI 1.0 has
no file with both). The test matrix is test_third_party's for FMI 2 and 3, where the feature exists
in FMI 1.0, with its referee (``fmpy.simulate_fmu`` on the same file, interface and output grid) and
its tolerances (``CS_RTOL``, ``ME_RTOL``, ``EVENT_ATOL``, justified there). What FMI 1.0 lacks:

- a co-simulation slave cannot ask to end the simulation (no ``fmiTerminated``): its ``fmiDiscard``
  is a failed step for the master, as for FMPy and libcosim; model exchange ends it through the
  event update's ``terminateSimulation``;
- FMPy 0.3 never calls ``fmiCompletedIntegratorStep`` of an FMI 1.0 FMU (it reads a flag that
  FMI 1.0 does not have), so it sees no step event: the master's step events of ``Halving`` are
  checked against FMPy on the FMI 2.0 build of the same model core.
"""

from __future__ import annotations

import copy
import json

import pytest
from cfmus import MODELS_FMI1, build
from cli_helpers import cosim
from fmpy.validation import validate_fmu
from test_third_party import (
    CS_RTOL,
    EVENT_ATOL,
    ME_RTOL,
    _validate_messages,
    _yaml,
    assert_same,
    fmpy_event_times,
    fmpy_run,
    one,
    run_master,
    same_with_and_without_the_worker,
)

from cosim.errors import ComponentSourceError, FMIError
from cosim.fmi import FMUInfo, load_fmu, make_slave

pytestmark = pytest.mark.integration

CASES = [  # model, stop, step, outputs, exactly compared outputs (test_third_party.CASES without FMI 3's)
    ("VanDerPol", 20.0, 0.01, ["x0", "x1"], ()),
    ("BouncingBall", 3.0, 0.01, ["h", "v", "bounces"], ("bounces",)),
    ("Stair", 8.0, 0.1, ["counter", "ramp"], ("counter", "ramp")),
    ("Halving", 5.0, 0.01, ["x", "count"], ("count",)),
]
IDS = [c[0] for c in CASES]


@pytest.mark.parametrize("interface", ["cs", "me"])
@pytest.mark.parametrize("model", MODELS_FMI1)
def test_fmi1_fmus_pass_fmpy_validation(model, interface):
    problems = validate_fmu(str(build(model, 1, interface)))
    assert problems == [], f"{model} FMI 1 {interface}: validate_fmu found {problems}, expected none"


def test_fmi1_description_one_interface_and_its_direct_dependencies(tmp_path):
    """FMI 1.0 declares each output's direct dependencies as ``DirectDependency`` (fmpy does not read it: read
    from the XML), the same as the FMI 2.0 build's ModelStructure; an output without the element depends on
    every input (None). Causality and variability are read in FMI 2 terms (internal -> local, variability
    parameter -> causality parameter)."""
    import zipfile

    cs, me = load_fmu(build("Feedthrough", 1, "cs")), load_fmu(build("Feedthrough", 1, "me"))
    assert (cs.interfaces, me.interfaces) == (["cs"], ["me"]), (cs.interfaces, me.interfaces)
    fmi2 = load_fmu(build("Feedthrough", 2)).feedthrough
    assert cs.feedthrough == me.feedthrough == fmi2 and any(fmi2.values()), (cs.feedthrough, fmi2)
    vdp = load_fmu(build("VanDerPol", 1, "cs")).feedthrough
    assert vdp and all(deps == [] for deps in vdp.values()), vdp  # states only: no input
    stripped = tmp_path / "Feedthrough.fmu"  # the same file without the DirectDependency elements
    with zipfile.ZipFile(build("Feedthrough", 1, "cs")) as zin, zipfile.ZipFile(stripped, "w") as zout:
        for item in zin.namelist():
            data = zin.read(item)
            if item == "modelDescription.xml":
                import re

                data = re.sub(rb"<DirectDependency>.*?</DirectDependency>|<DirectDependency\s*/>", b"", data,
                              flags=re.S)
                assert b"DirectDependency" not in data
            zout.writestr(item, data)
    assert load_fmu(stripped).feedthrough == {name: None for name in fmi2}, load_fmu(stripped).feedthrough
    p = cs.variables["Real_parameter"]
    assert (p.causality, p.variability) == ("parameter", "fixed"), (p.causality, p.variability)
    with pytest.raises(ComponentSourceError, match="has no me interface"):
        make_slave("m", cs, "me")


@pytest.mark.parametrize("model,stop,step,names,exact", CASES, ids=IDS)
def test_fmi1_cosimulation_matches_fmpy(tmp_path, model, stop, step, names, exact):
    fmu = build(model, 1, "cs")
    res, log = run_master(tmp_path, {"m": one(fmu, "cs")}, stop, step)
    assert res.status == "completed", res.message
    assert_same(log, fmpy_run(fmu, "cs", stop, step, names), names, CS_RTOL, exact)


@pytest.mark.parametrize("solver", ["cvode", "dop853"])
@pytest.mark.parametrize("model,stop,step,names,exact", CASES, ids=IDS)
def test_fmi1_model_exchange_matches_fmpy(tmp_path, model, stop, step, names, exact, solver):
    fmu = build(model, 1, "me")
    res, log = run_master(tmp_path, {"m": one(fmu, "me", solver=solver)}, stop, step)
    assert res.status == "completed", res.message
    # FMPy sees no FMI 1.0 step event (module docstring): its Halving reference is the FMI 2.0 build
    referee = build(model, 2) if model == "Halving" else fmu
    assert_same(log, fmpy_run(referee, "me", stop, step, names), names, ME_RTOL, exact)
    ours = [e["t"] for e in log.events]
    theirs = fmpy_event_times(referee, stop, step, names)
    assert len(ours) == len(theirs) == res.events["m"], \
        f"event count: ours {len(ours)} (summary {res.events['m']}) vs FMPy {len(theirs)}"
    if model == "Halving":
        assert {e["kind"] for e in log.events} == {"step"}, f"event kinds {log.events}, expected step events"
    if model == "BouncingBall" and solver == "dop853":  # as in test_third_party: the closed form is the referee
        from test_third_party import bounce_times

        theirs = bounce_times(len(ours))
    worst = max((abs(a - b) for a, b in zip(ours, theirs)), default=0.0)
    assert worst <= EVENT_ATOL, f"event times differ by up to {worst:.3g} s: ours {ours} vs {theirs}"


def test_fmi1_termination_in_the_initial_event_update_ends_the_run_at_the_start(tmp_path):
    res, log = run_master(tmp_path, {"m": one(build("Stair", 1, "me"), "me", {"t_terminate": 0.0})}, 5.0, 0.1)
    assert res.terminated_by == "m" and res.steps == 0 and res.sim_time == 0.0, (res.message, res.steps)
    assert list(log.signal("m.counter").t) == [0.0], "one sample, at the start"


def test_fmi1_rejected_step_is_an_error_with_the_message_the_component_logged(tmp_path):
    """Two instances of one FMU: the error names the one whose step was rejected, the FMI function, the
    time, and the message that instance logged (through the FMI 1.0 logger: no componentEnvironment)."""
    fmu = build("Stair", 1, "cs")
    path = tmp_path / "reject.yaml"
    path.write_text(_yaml({"early": one(fmu, "cs", {"t_reject": 4.05}), "late": one(fmu, "cs", {"t_reject": 3.05})},
                          5.0, 0.1))
    proc = cosim("run", str(path), "--no-log")
    assert proc.returncode == 2, f"exit {proc.returncode}: {proc.stdout} {proc.stderr}"
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "component 'late': Stair_fmiDoStep returned discard at t = 3 s" in lines[0], lines[0]
    assert "(step rejected at t = 3.04999" in lines[0] and "crosses t_reject" in lines[0], \
        f"the FMU's log message is missing: {lines[0]}"
    assert "reaching" not in lines[0], f"a rejected step reached nothing beyond its start: {lines[0]}"


@pytest.mark.parametrize("turn", ["C", "Python"])
def test_fmi1_cosimulation_cannot_end_the_simulation(tmp_path, monkeypatch, turn):
    """FMI 1.0 co-simulation has no fmiTerminated: the Stair's partial step at t_terminate is a failed step
    (libcosim's reading too), reported with the time the slave reached and its message, whether the C turn
    or Python makes the calls. (FMPy 0.3.32 declares fmiDoStep as returning a string and crashes on any
    status but fmiOK, so it cannot be the referee here; the master declares the status.)"""
    if turn == "Python":
        monkeypatch.setattr("cosim.fmi.slave.make_turn", lambda *args: None)
    fmu = build("Stair", 1, "cs")
    with pytest.raises(FMIError) as info:
        run_master(tmp_path, {"m": one(fmu, "cs")}, 12.0, 0.1)
    text = str(info.value)
    assert "Stair_fmiDoStep returned discard at t = 10.4 s" in text and "reaching t = 10.5 s" in text, text
    assert "(the model terminates the simulation at t = 10.4999" in text, f"the FMU's log message is missing: {text}"


def test_fmi1_log_message_at_instantiation_reaches_the_error():
    """A message logged before the FMU has a component (here: a GUID mismatch, with a NULL component) is
    dispatched by instance name to the component being instantiated."""
    info = load_fmu(build("VanDerPol", 1, "cs"))
    md = copy.copy(info.md)
    md.guid = "{00000000-0000-0000-0000-000000000000}"
    slave = make_slave("vdp", FMUInfo(info.path, md, info.variables, info.stamp), "cs")
    try:
        with pytest.raises(FMIError) as err:
            slave.instantiate()
    finally:
        slave.free()
    assert "component 'vdp'" in str(err.value) and "the GUID does not match this binary" in str(err.value), \
        str(err.value)


FT_INPUTS = {"Real_input": -1.125, "Integer_input": -(2 ** 31), "Boolean_input": True, "String_input": "héllo",
             "Enumeration_input": 3}


@pytest.mark.parametrize("interface", ["cs", "me"])
def test_fmi1_types_travel_and_are_logged_as_their_schema_says(tmp_path, interface):
    """Every FMI 1.0 type from one component to the next and into the log (fmiBoolean is a char: logged as a
    JSON boolean); the receiver in model exchange takes discrete inputs at an event update."""
    a, b = build("Feedthrough", 1, "cs"), build("Feedthrough", 1, interface)
    types = [n.removesuffix("_input") for n in FT_INPUTS]
    res, log = run_master(tmp_path, {"a": one(a, "cs", FT_INPUTS), "b": one(b, interface)}, 0.05, 0.01,
                          connections=[(f"a.{t}_output", f"b.{t}_input") for t in types])
    assert res.status == "completed", res.message
    for name, value in FT_INPUTS.items():
        got = log.signal("b." + name.replace("_input", "_output")).y[-1]
        assert got == value, f"{name}: b logged {got!r}, a was given {value!r}"
    assert _validate_messages(tmp_path / "run.mcap") > 0


def test_fmi1_in_the_parallel_worker_as_in_a_serial_run(tmp_path):
    """The FMI 1.0 model-exchange stair (no inputs) runs ahead in the worker process, re-created there by
    make_slave from its path and interface; a loop of two FMI 1.0 feedthroughs (CS and ME) stays in the
    master. With and without the worker: the same logged values, the same end of the simulation."""

    comps = {"stair": one(build("Stair", 1, "me"), "me"), "a": one(build("Feedthrough", 1, "cs"), "cs"),
             "b": one(build("Feedthrough", 1, "me"), "me")}
    conns = [{"from": "stair.ramp", "to": "a.Real_input"}, {"from": "a.Real_output", "to": "b.Real_input"},
             {"from": "b.Integer_output", "to": "a.Integer_input"}, {"from": "stair.counter", "to": "b.Integer_input"}]
    logs = same_with_and_without_the_worker(tmp_path, "fmi1_worker", comps, conns)
    assert logs["off"].signal("a.Real_output").y[-1] == 5.5, "the stair's ramp (0.5 * 11) reached a"


def test_fmi1_live_view_serves_the_component_channel(tmp_path):
    """The live view works on the Slave protocol: an FMI 1.0 model-exchange component's channel is served
    with the schema it is logged with, and its messages validate."""
    import asyncio
    import subprocess
    import sys
    import time

    import jsonschema
    import yaml
    from cli_helpers import free_port
    from test_live import ROOT, _watch

    scenario = tmp_path / "vdp.yaml"
    scenario.write_text(yaml.safe_dump({"name": "vdp1", "components": {"m": one(build("VanDerPol", 1, "me"), "me")},
                                        "time": {"stop": 3.0, "step": 0.01}}))
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(scenario), "--live", str(port), "--realtime",
                             "--no-log", "--quiet"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        channels, got, _ = asyncio.run(_watch(port, {"/m"}, want=5, deadline=time.monotonic() + 90))
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, f"exit {proc.returncode}: {err.decode()}"
    assert len(got["/m"]) >= 5, f"{len(got['/m'])} messages on /m, channels {sorted(channels)}"
    validator = jsonschema.Draft202012Validator(json.loads(channels["/m"]["schema"]))
    for log_time, msg in got["/m"]:
        errors = list(validator.iter_errors(msg))
        assert not errors, f"/m at {log_time} ns: {errors[0].message}"
        assert {"x0", "x1"} <= set(msg), f"/m message without the outputs: {msg}"


@pytest.mark.parametrize("algorithm", ["gauss_seidel", "jacobi"])
def test_fmi1_multi_rate_as_the_fmi2_build_of_the_same_models(tmp_path, algorithm):
    """Multi-rate with FMI 1.0: the stair steps every 5th macro step (0.5 s) and feeds a feedthrough that steps
    every one (0.1 s). The FMI 2.0 builds of the same model cores (the multi-rate schedule is tested on them
    against exact recurrences, test_cosim_master) give the same logged samples at the same times: the stair's
    every 0.5 s, the feedthrough's every 0.1 s."""
    runs = {}
    for fmi in (1, 2):
        def fmu(model, fmi=fmi):  # noqa: ANN001, ANN202
            return str(build(model, fmi, "cs" if fmi == 1 else None))

        comps = {"stair": {"path": fmu("Stair"), "interface": "cs", "step_multiple": 5},
                 "a": {"path": fmu("Feedthrough"), "interface": "cs"}}
        conns = [("stair.ramp", "a.Real_input")]
        (tmp_path / str(fmi)).mkdir()
        res, log = run_master(tmp_path / str(fmi), comps, 4.0, 0.1, connections=conns, algorithm=algorithm)
        assert res.status == "completed" and res.steps == 40, (fmi, res.status, res.message, res.steps)
        runs[fmi] = log
    for name in ("stair.ramp", "stair.counter", "a.Real_output"):
        one_, two = runs[1].signal(name), runs[2].signal(name)
        assert one_.t_ns.tolist() == two.t_ns.tolist() and one_.y.tolist() == two.y.tolist(), \
            f"{name}: FMI 1.0 {list(zip(one_.t_ns, one_.y))[:12]} vs FMI 2.0 {list(zip(two.t_ns, two.y))[:12]}"
    assert runs[1].signal("stair.ramp").t_ns.tolist() == [k * 500_000_000 for k in range(9)], "the stair's steps"
    assert runs[1].signal("a.Real_output").t_ns.tolist() == [k * 100_000_000 for k in range(41)], "the feedthrough's"
