"""The Python API (cosim.api): overrides by dotted name, metrics, signals, with and without a log."""

from pathlib import Path

import numpy as np
import pytest

from cosim import api
from cosim.errors import ScenarioError

pytestmark = pytest.mark.integration
SCENARIO = Path(__file__).parents[2] / "scenarios" / "helix_ctc_analytic.yaml"


def test_run_with_overrides_gives_metrics_and_every_signal(tmp_path):
    over = {"time.stop": 0.2, "trajectory.params.rx": 0.05, "ctl.gain.kp[1]": 2.0e4}
    res = api.run(SCENARIO, over, log=True, out=tmp_path / "run.mcap")
    assert res.status == "completed" and Path(res.mcap).exists(), (res.status, res.mcap)
    assert res.time.shape == (201,) and res.time[-1] == pytest.approx(0.2, abs=1e-12), res.time[-3:]
    # the trajectory override reaches the trajectory FMU: x starts at centre + rx
    assert res["traj.p_ref.x"][0] == 0.05, res["traj.p_ref.x"][0]
    err = res["plant.p.x"] - res["traj.p_ref.x"]
    assert res.metrics["rmse_x"] == pytest.approx(float(np.sqrt(np.mean(err ** 2))), rel=1e-9), res.metrics
    assert res.metrics["peak_effort"] == np.max(np.abs([res[f"ctl.u[{i}]"] for i in (1, 2, 3)])), res.metrics
    assert "plant.v.x" in res.signals, sorted(res.signals)[:10]  # unconnected outputs too


def test_run_without_log_or_signals(tmp_path):
    res = api.run(SCENARIO, {"time.stop": 0.1}, signals=False)
    assert res.mcap is None and res.signals == {}, (res.mcap, len(res.signals))
    assert res.metrics["steps"] == 100 and res.metrics["rmse_z"] > 0, res.metrics


def test_unknown_name_is_one_line():
    with pytest.raises(ScenarioError) as exc:
        api.load(SCENARIO, {"ctl.gain.kp[1]": 1.0, "trajectory.params.radius": 0.1})
    assert "helix has no parameter 'radius'" in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


def test_an_ssp_archive_runs_from_the_api_as_its_scenario(tmp_path):
    """A path of an SSP archive (our export of a scenario) runs as the scenario itself, overrides included, and the
    archive's unpacked FMUs are gone after the run."""
    import os
    import tempfile

    from cosim.fmi.extract import SSP_PREFIX
    from cosim.io.ssp.write import export_ssp

    archive = tmp_path / "helix.ssp"
    export_ssp(api.load(SCENARIO), archive)
    overrides = {"time.stop": 0.02, "ctl.gain.kp[1]": 3.5e3}
    a, b = api.run(archive, overrides), api.run(SCENARIO, overrides)
    assert a.run.steps == b.run.steps == 20
    assert np.array_equal(a["plant.p.x"], b["plant.p.x"]) and np.array_equal(a["ctl.u[1]"], b["ctl.u[1]"])
    assert not list(Path(tempfile.gettempdir()).glob(f"{SSP_PREFIX}{os.getpid()}-*")), "an unpacked archive is left"
