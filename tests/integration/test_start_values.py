"""Start values as FMI allows them and FMPy applies them (issue 26, item 5), on the Forgetful test FMU.

Forgetful (tests/cfmus) has a parameter p (y = p) and an output z declared initial="exact". Its FMI 2 build
behaves as some exporters' FMUs do: fmi2SetupExperiment resets every variable (values set before it are lost),
and its log messages carry a NULL componentEnvironment. The master must set start values where FMPy and libcosim
do (after the setup, before initialization mode), accept the output z as FMI allows, give the same outputs as
fmpy.simulate_fmu with the same start values (exactly: y and z are copies), and put the FMU's logged reason in
the error of a failing call.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cfmus import build

from cosim.engine.scenario import parse_scenario
from cosim.errors import FMIError, ScenarioError
from cosim.io.runlog import read_run
from cosim.run import run_scenario

pytestmark = pytest.mark.integration
STOP, STEP = 0.5, 0.1
FMI_TYPE = {"cs": "CoSimulation", "me": "ModelExchange"}


def _run(tmp_path: Path, fmi: int, interface: str, parameters: dict):
    text = yaml.safe_dump({
        "name": "start_values", "time": {"stop": STOP, "step": STEP},
        "components": {"f": {"path": str(build("Forgetful", fmi, interface if fmi == 1 else None)),
                             "interface": interface,
                             "parameters": parameters}},
        "logging": {"signals": "all"}})
    path = tmp_path / f"f{fmi}{interface}.yaml"
    path.write_text(text)
    out = path.with_suffix(".mcap")
    return run_scenario(parse_scenario(text, str(path)), out=out), out


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("interface", ["cs", "me"])
def test_start_values_reach_the_fmu_as_fmpy_sets_them(tmp_path, fmi, interface):
    from fmpy import simulate_fmu

    start = {"p": 3.0, "z": 5.0}  # z: an output with initial="exact"
    res, out = _run(tmp_path, fmi, interface, start)
    assert res.status == "completed", res.message
    log = read_run(out)
    ref = simulate_fmu(str(build("Forgetful", fmi)), fmi_type=FMI_TYPE[interface], stop_time=STOP,
                       output_interval=STEP, start_values=start, output=["y", "z"])
    for name in ("y", "z"):
        ours = np.asarray(log.signal(f"f.{name}").y, dtype=float)
        assert np.all(ours == start["p" if name == "y" else "z"]), f"FMI {fmi} {interface}: {name} = {ours}"
        theirs = ref[name][: len(ours)]
        assert np.array_equal(ours[: len(theirs)], theirs), f"FMI {fmi} {interface} {name}: {ours} vs FMPy {theirs}"


@pytest.mark.parametrize("fmi", [1, 2, 3])
@pytest.mark.parametrize("interface", ["cs", "me"])
def test_a_failing_call_carries_the_fmus_message_even_without_its_environment(tmp_path, fmi, interface):
    """FMI 2: the message comes with a NULL componentEnvironment, FMI 1.0 with a NULL component (after
    instantiation); it must still name the reason and the failing call."""
    with pytest.raises(FMIError) as exc:
        _run(tmp_path, fmi, interface, {"p": -1.0})
    text = str(exc.value)
    call = {1: "Initialize", 2: "ExitInitializationMode", 3: "ExitInitializationMode"}[fmi]
    assert "p = -1 is negative" in text and call in text, text


def test_an_output_calculated_by_the_fmu_is_still_refused(tmp_path):
    with pytest.raises(ScenarioError, match="cannot be set before initialization"):
        _run(tmp_path, 2, "cs", {"y": 1.0})
