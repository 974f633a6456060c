"""``calibrate --out`` writes a file of values that a scenario uses with ``parameters: FILE``: on a scenario that
replays the robot's recording beside the plant (a recording component, ``meas``), the fitted payload and the fitted
time offset (as ``components.meas.offset``) land in the file; the scenario naming it runs with them (the replayed
joints meet the simulated ones to the recording's noise); its log runs again with ``run --from-log`` to the same
values without the file; and a bad file or a name the scenario's FMU lacks is one line, exit 2. The recording is a
SYNTHETIC ROS 2 bag made from a run of this project's plant (tests/recording_helpers.py)."""

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
from cosim.io.runlog import read_run  # noqa: E402

pytestmark = pytest.mark.integration

SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
STOP_S = 0.3  # of the run the bag is made from
RUN_STOP_S = 0.29  # of the scenario that replays it: the bag's last sample is up to 4 ms before STOP_S
PAYLOAD = 0.3  # kg on the plant (the controller's model keeps 0 kg, so the joints show it)
OFFSET_S = 0.2137  # the recording starts 53.425 samples of 4 ms before the run
NOISE_M = 1e-6
SIGNALS = {f"q[{i}]": f"/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)}
MAP_ARGS = [f"--map=plant.q[{i}]={SIGNALS[f'q[{i}]']}" for i in (1, 2, 3)]
PAYLOAD_RTOL = 0.02  # as tests/integration/test_calibrate.py: the target; the fit is far better
OFFSET_ATOL_S = 1e-3


@pytest.fixture(scope="module")
def robot(tmp_path_factory) -> Path:
    """A folder with the bag (robot_bag/) and a scenario (twin.yaml) replaying it as ``meas`` at offset 0, the plant
    at 0.1 kg."""
    d = tmp_path_factory.mktemp("calibrate_parameters")
    truth = d / "truth.mcap"
    api.run(str(SCENARIO), {"time.stop": STOP_S, "plant.mass.payload": PAYLOAD}, log=True, out=truth, signals=False)
    synthetic_plant_bag(d / "robot_bag", truth, offset_s=OFFSET_S, noise=NOISE_M, rate_hz=250.0)
    data = yaml.safe_load(SCENARIO.read_text())
    data.update(name="twin", time={"stop": RUN_STOP_S, "step": 0.001}, logging={"out": "twin.mcap", "signals": "all"})
    data["components"]["plant"]["parameters"] = {"mass.payload": 0.1}
    data["components"]["meas"] = {"recording": "robot_bag", "signals": SIGNALS}
    del data["compare"], data["checks"]  # the helix's tracking check: not the subject here
    (d / "twin.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return d


def test_the_fitted_values_and_offset_make_the_twin_replay_the_robot_and_its_log_runs_again(robot):
    assert cosim("run", "twin.yaml", "--quiet", cwd=robot).returncode == 0  # at the start values: twin.mcap
    res = cosim("calibrate", "twin.yaml", "--measured", "robot_bag", *MAP_ARGS, "--fit=plant.mass.payload=0:1",
                "--fit=offset", "--out", "fitted.yaml", "--json", cwd=robot)
    assert res.returncode == 0, res.stderr
    cal = {p["label"]: p["value"] for p in json.loads(res.stdout)["parameters"]}
    assert abs(cal["plant.mass.payload"] - PAYLOAD) <= PAYLOAD_RTOL * PAYLOAD and \
        abs(cal["offset"] - OFFSET_S) <= OFFSET_ATOL_S, cal
    text = (robot / "fitted.yaml").read_text()
    values = yaml.safe_load(text)
    assert values == {"plant.mass.payload": cal["plant.mass.payload"], "components.meas.offset": cal["offset"]}, text
    assert "# Written by: python -m cosim calibrate twin.yaml --measured robot_bag" in text, text

    data = yaml.safe_load((robot / "twin.yaml").read_text())
    data["parameters"] = "fitted.yaml"
    (robot / "twin_fitted.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    res = cosim("run", "twin_fitted.yaml", "--out", "fitted_run.mcap", "--quiet", cwd=robot)
    assert res.returncode == 0, res.stderr
    res = cosim("run", "twin.yaml", f"--set=plant.mass.payload={PAYLOAD}", f"--set=components.meas.offset={OFFSET_S}",
                "--out", "true_run.mcap", "--quiet", cwd=robot)  # the twin at the true values, for reference
    assert res.returncode == 0, res.stderr
    fitted, true, start = (_replay_rmse(robot, log) for log in ("fitted_run.mcap", "true_run.mcap", "twin.mcap"))
    for name in fitted:  # the replayed joints meet the simulated ones as at the true values: the fitted payload
        # (within 2 %, 0.006 kg) moves the joints by at most 0.006 kg x 170 um/kg = 1 um, the offset's error (below
        # 1 ms, in fact a few us) less; the start's 0.1 kg and offset 0 were 100 um and more off
        assert abs(fitted[name] - true[name]) <= PAYLOAD_RTOL * PAYLOAD * 170e-6 < 100e-6 < start[name], \
            (name, fitted[name], true[name], start[name])

    (robot / "fitted.yaml").unlink()  # the log holds the scenario as run, the file's values applied
    res = cosim("run", "--from-log", "fitted_run.mcap", "--out", "again.mcap", "--quiet", cwd=robot)
    assert res.returncode == 0, res.stderr
    first, again = read_run(robot / "fitted_run.mcap"), read_run(robot / "again.mcap")
    for name in ("plant.q[1]", "plant.q[3]", "meas.q[2]"):
        a, b = first.signal(name), again.signal(name)
        assert np.array_equal(a.t_ns, b.t_ns) and np.array_equal(a.y, b.y), f"{name}: the log's run differs"


def _replay_rmse(folder: Path, log: str) -> dict[str, float]:
    """RMSE of the plant's joints against the replayed ones (meas), in the one log (compare)."""
    maps = [a for i in (1, 2, 3) for a in ("--map", f"plant.q[{i}]=meas.q[{i}]")]
    res = cosim("compare", log, log, *maps, "--json", cwd=folder)
    assert res.returncode == 0, res.stdout + res.stderr
    return {s["name"]: s["rmse"] for s in json.loads(res.stdout)["signals"]}


def test_a_bad_file_of_values_is_one_line_and_exit_2(robot):
    (robot / "bad.yaml").write_text("# fitted\nplant.mass.paylod: 0.3\n")
    res = cosim("run", "twin.yaml", "--set", "parameters=bad.yaml", "--no-log", "--quiet", cwd=robot)
    err = res.stderr.strip()
    assert res.returncode == 2 and "\n" not in err, (res.returncode, err)
    assert err.startswith("error: bad.yaml:2 (a parameters file, named at --set parameters=bad.yaml): "
                          "linear_analytic_plant.fmu has no variable 'mass.paylod'; did you mean mass.payload"), err
    res = cosim("run", "twin.yaml", "--set", "parameters=gone.yaml", "--no-log", "--quiet", cwd=robot)
    assert res.returncode == 2 and res.stderr.strip() == ("error: --set parameters=gone.yaml: parameters file "
                                                          "gone.yaml: no such file"), res.stderr
