"""The scenario's trajectory section drives our trajectory FMUs: the helix FMU follows it, and
`python -m cosim check` reports a component that disagrees with it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.observers.recorders import Probe
from cosim.run import run_scenario
from cosim.engine.scenario import load_scenario
from delta.trajectories import Helix

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[2]
# the FMU evaluates the same closed form in float64 at the same times: rounding only
EXACT = 1e-12

SCENARIO = """\
name: section
robot: linear_delta_thesis
trajectory:
  type: helix
  params: {rx: 0.05, ry: 0.08, omega: 2.0, z0: -0.5, vz: 0.002, duration: 1.0}
initial_state: {from_trajectory: false}
components:
  traj: {fmu: helix}
time: {stop: 0.5, step: 0.01}
logging: {signals: outputs}
"""


def test_helix_fmu_follows_the_trajectory_section(tmp_path):
    path = tmp_path / "section.yaml"
    path.write_text(SCENARIO)
    probe = Probe(["traj.p_ref.x", "traj.p_ref.y", "traj.p_ref.z"])
    run_scenario(load_scenario(path), out=tmp_path / "section.mcap", observers=[probe])
    t = np.asarray(probe.t_ns) * 1e-9
    expected = Helix(rx=0.05, ry=0.08, omega=2.0, z0=-0.5, vz=0.002, duration=1.0).sample(t)[0]
    got = np.column_stack([probe.values[f"traj.p_ref.{a}"] for a in "xyz"])
    err = np.abs(got - expected).max()
    assert err <= EXACT, f"max |FMU - section helix| = {err} m vs {EXACT}; first rows {got[:2]} vs {expected[:2]}"


def test_check_reports_a_component_that_disagrees(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(SCENARIO.replace("traj: {fmu: helix}", "traj: {fmu: helix, parameters: {helix.rx: 0.2}}"))
    r = subprocess.run([sys.executable, "-m", "cosim", "check", str(path)], cwd=ROOT, capture_output=True, text=True)
    want = (f"error: {path}:8: components.traj.parameters.helix.rx: 0.2 disagrees with trajectory.params rx = 0.05; "
            "set it in one place (trajectory.params)")
    assert r.returncode != 0, f"exit {r.returncode} vs non-zero: {r.stderr}"
    assert r.stderr.strip() == want, f"{r.stderr.strip()!r} vs {want!r}"
    ok = subprocess.run([sys.executable, "-m", "cosim", "check", str(path), "--set", "traj.helix.rx=0.05"], cwd=ROOT,
                        capture_output=True, text=True)
    assert ok.returncode == 0, f"equal values: exit {ok.returncode} vs 0: {ok.stderr}"


def test_a_yaml_1_1_exponent_in_the_parameters_is_a_number(tmp_path):
    """PyYAML reads '5e-2' as a string (YAML 1.1); the typed parameters make it the number it is checked as."""
    text = (ROOT / "scenarios" / "helix_ctc_analytic.yaml").read_text()
    text = text.replace("  type: helix                    #", "  params: {rx: 5e-2, ry: 5e-2}\n  type: helix  #")
    (tmp_path / "s.yaml").write_text(text.replace("../runs/", str(tmp_path) + "/"))
    probe = Probe(["traj.p_ref.x"])
    res = run_scenario(load_scenario(tmp_path / "s.yaml", {("time", "stop"): 0.01}), log=False, observers=[probe])
    assert res.status == "completed", res.message
    assert probe.values["traj.p_ref.x"][0] == pytest.approx(0.05, abs=1e-15)
