"""``python -m cosim calibrate``: the payload and the time offset recovered from a SYNTHETIC ROS 2 bag made from a
run of this project's plant with a known payload (tests/recording_helpers.py: 250 Hz, noise 1e-6 m, an offset that
is no whole number of samples), the fitted values written and a scenario run with them, the JSON, and every bad
input one line."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cli_helpers import ROOT, cosim  # noqa: E402
from recording_helpers import synthetic_plant_bag  # noqa: E402

from cosim import api  # noqa: E402
from cosim.analysis.calibrate import CalibrationError, calibrate, parse_fits  # noqa: E402
from cosim.errors import ScenarioError  # noqa: E402
from cosim.io.recordings import RecordingError  # noqa: E402
from cosim.io.runlog import read_run  # noqa: E402

pytestmark = pytest.mark.integration

SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"  # native FMUs: a 0.3 s run takes a fraction of a second
STOP_S = 0.3
PAYLOAD = 0.3  # kg on the plant; the controller's model keeps its own 0 kg, so the joints show it (about 50 um)
START = 0.1  # kg, the fit's wrong start
OFFSET_S = 0.2137  # the recording starts 53.425 samples of 4 ms before the run
MAPS = {f"plant.q[{i}]": f"/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)}
MAP_ARGS = [f"--map=plant.q[{i}]=/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)]
SETS = [f"time.stop={STOP_S}", f"plant.mass.payload={START}"]
BASE = [f"--set={s}" for s in SETS]
# The targets: payload within 2 %, offset within 1 ms. The noise allows far better: the standard errors are
# about 1e-3 kg and 1e-6 s here, and the fit must also lie within 5 of its own standard errors of the truth
PAYLOAD_RTOL = 0.02
OFFSET_ATOL_S = 1e-3
SIGMAS = 5.0


@pytest.fixture(scope="module")
def truth(tmp_path_factory) -> tuple[Path, Path]:
    """(the run log with the true payload, the synthetic bag made from it)."""
    d = tmp_path_factory.mktemp("calibrate")
    log = d / "truth.mcap"
    api.run(str(SCENARIO), {"time.stop": STOP_S, "plant.mass.payload": PAYLOAD}, log=True, out=log, signals=False)
    return log, synthetic_plant_bag(d / "robot_bag", log, offset_s=OFFSET_S, noise=1e-6, rate_hz=250.0)


def test_payload_and_offset_are_recovered_from_a_wrong_start(truth):
    _, bag = truth
    cal = calibrate(SCENARIO, bag, MAPS, parse_fits(["plant.mass.payload=0:1", "offset"]), sets=SETS)
    payload, offset = cal.parameters
    assert cal.converged, cal.text()
    assert payload["start"] == START and payload["label"] == "plant.mass.payload", payload
    err_p, err_o = payload["value"] - PAYLOAD, offset["value"] - OFFSET_S
    assert abs(err_p) <= PAYLOAD_RTOL * PAYLOAD and abs(err_p) <= SIGMAS * payload["stderr"], (err_p, payload)
    assert abs(err_o) <= OFFSET_ATOL_S and abs(err_o) <= SIGMAS * offset["stderr"], (err_o, offset)
    for name in MAPS:  # down to the noise (1e-6 m) from tens of um at 0.1 kg
        assert cal.rms_after[name] < 2e-6 < 10 * 2e-6 < cal.rms_before[name], (name, cal.rms_before, cal.rms_after)
    assert 2 <= cal.runs <= cal.evaluations, (cal.runs, cal.evaluations)  # the offset's derivatives cost no run
    assert -1 <= cal.correlation[0][1] <= 1 and cal.correlation[0][0] == pytest.approx(1.0), cal.correlation


def test_the_cli_writes_json_and_a_file_of_values_that_makes_the_scenario_run_as_the_robot(truth, tmp_path):
    log, bag = truth
    out = tmp_path / "fitted.yaml"
    res = cosim("calibrate", SCENARIO, "--measured", bag, *MAP_ARGS, "--fit=plant.mass.payload=0:1", "--fit=offset",
                *BASE, "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    data = json.loads(res.stdout)
    assert data["converged"] and data["out"] == str(out) and data["runs"] >= 2, data
    fitted = data["parameters"][0]["value"]
    assert abs(fitted - PAYLOAD) <= PAYLOAD_RTOL * PAYLOAD, data["parameters"]
    text = out.read_text()
    assert "# Written by: python -m cosim calibrate" in text and "--fit plant.mass.payload=0:1" in text, text[:800]
    assert "\n# On: " in text and "# Residual RMS before -> after: plant.q[1]" in text, text[:800]
    # the values only: the offset is the recording's clock, which this scenario does not replay (header only)
    assert yaml.safe_load(text) == {"plant.mass.payload": fitted}, text
    assert not list(tmp_path.glob(".*.tmp")), "the temporary file was renamed"
    # the scenario with the file runs, and its joints are the robot's: within the payload's small error (about
    # 1e-3 kg x 1.7e-4 m/kg), where the start's 0.1 kg was tens of um off
    run = api.run(str(SCENARIO), {"parameters": str(out), "time.stop": STOP_S})
    q_truth = read_run(log)
    for i in (1, 2, 3):
        want = np.interp(run.time, q_truth.signal(f"plant.q[{i}]").t, q_truth.signal(f"plant.q[{i}]").y)
        diff = float(np.max(np.abs(run[f"plant.q[{i}]"] - want)))
        assert diff < 2e-6, f"plant.q[{i}]: calibrated run {diff:.3g} m from the robot's"


def test_a_fit_that_does_not_converge_exits_1_and_says_what_it_found(truth):
    _, bag = truth
    res = cosim("calibrate", SCENARIO, "--measured", bag, *MAP_ARGS, "--fit=plant.mass.payload=0:1", "--fit=offset",
                *BASE, "--max-runs", "2")
    assert res.returncode == 1, res.stderr
    assert "DID NOT CONVERGE" in res.stdout and "stopped after 2 runs" in res.stdout, res.stdout
    assert "plant.mass.payload" in res.stdout and "RMS before" in res.stdout, res.stdout


@pytest.mark.parametrize("fits, maps, extra, message", [
    (["plant.mass.paylod"], MAPS, {}, "plant has no parameter 'mass.paylod'; did you mean plant.mass.payload"),
    (["plnt.mass.payload"], MAPS, {}, "unknown name 'plnt'; did you mean plant?"),
    (["plant.mass.payload=0.2:1"], MAPS, {}, "the start value 0.1 (the scenario's) is outside the bounds"),
    (["plant.mass.payload"], {"plant.qq[1]": MAPS["plant.q[1]"]}, {}, "not a signal of the run: plant.qq[1]"),
    (["plant.mass.payload"], {"plant.q[1]": "/joint_states.position[delta_joint_9]"}, {}, "no joint named"),
    (["plant.mass.payload"], MAPS, {"offset": 100.0}, "no overlap; try --fit offset"),
])
def test_bad_input_is_one_line(truth, fits, maps, extra, message):
    _, bag = truth
    with pytest.raises((CalibrationError, ScenarioError, RecordingError)) as info:
        calibrate(SCENARIO, bag, maps, parse_fits(fits), sets=SETS, **extra)
    text = str(info.value)
    assert message in text and "\n" not in text, text


def test_bad_input_exits_2_with_one_line(truth):
    _, bag = truth
    res = cosim("calibrate", SCENARIO, "--measured", bag, *MAP_ARGS, "--fit=plant.mass.payload=1:0", *BASE)
    assert res.returncode == 2 and res.stderr.strip().count("\n") == 0, res.stderr
    assert "the lower bound 1 is not below the upper 0" in res.stderr, res.stderr


def test_a_payload_the_controller_knows_too_is_reported_unidentifiable_from_the_joints(truth):
    """CTC cancels a payload its model carries: set on plant and controller alike, it barely moves the joints (a
    few 1e-11 m per gram), so its standard error is far above any payload, where the plant's alone is below 1 %."""
    _, bag = truth
    cal = calibrate(SCENARIO, bag, MAPS, parse_fits(["plant.mass.payload,ctl.mass.payload=0:1"]),
                    sets=SETS + [f"ctl.mass.payload={START}"], offset=OFFSET_S)
    (linked,) = cal.parameters
    assert linked["names"] == ["plant.mass.payload", "ctl.mass.payload"], linked
    assert linked["stderr"] > 10.0, f"a linked payload's standard error {linked['stderr']} kg: the joints told it"
    # the residual stays the plant-only payload's effect (tens of um), which no linked value can make
    assert min(cal.rms_after.values()) > 10e-6, cal.rms_after
