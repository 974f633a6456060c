"""A recording as a component in a closed loop: the helix's trajectory, recorded (a run of helix_ctc_analytic
exported as CSV, the reader's format), replaces the trajectory FMU and drives the IK + CTC + analytic plant; a
SYNTHETIC ROS 2 bag of the original run's joints (tests/recording_helpers.py: noise 1e-6 m, 250 Hz, an offset of
0.212 s, other joint names) is replayed beside the simulated joints, and ``compare`` finds them close."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.io.recordings.export import export_csv
from cosim.io.runlog import read_run
from recording_helpers import synthetic_plant_bag

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
STOP = 1.0  # s of the helix: a quarter turn and more, every reference component moving
REPLAY_STOP = 0.99  # the replays end a little before: the synthetic bag's last sample is up to 4 ms before STOP
N = 991  # samples of a replay: 0 .. 0.99 s at 1 ms
DECIMATE = 4  # the 1 kHz recording kept every 4th sample: 250 Hz, h = 4 ms
H_REC = 0.001 * DECIMATE
BAG_OFFSET = 0.212  # s: the bag starts 53 samples before the run, so the run's start is one of its samples (the bag
# holds the first pose before it: linear interpolation across that start would add a kink of qd * 4 ms)

REPLAY = """\
name: helix_replay
robot: linear_delta_thesis
trajectory: {{type: helix}}                 # the plant's initial state, as in the original run
components:
  traj:
    recording: {traj}
    signals: {{p_ref.x: p_ref.x, p_ref.y: p_ref.y, p_ref.z: p_ref.z, v_ref.x: v_ref.x, v_ref.y: v_ref.y,
              v_ref.z: v_ref.z, a_ref.x: a_ref.x, a_ref.y: a_ref.y, a_ref.z: a_ref.z}}
    interpolation: {how}
  meas:
    recording: robot_bag
    signals: {{"q[1]": "/joint_states.position[delta_joint_1]", "q[2]": "/joint_states.position[delta_joint_2]",
              "q[3]": "/joint_states.position[delta_joint_3]"}}
    units: {{"q[1]": m, "q[2]": m, "q[3]": m}}
    offset: {offset}
  ik:   {{fmu: linear_ik}}
  ctl:  {{fmu: linear_ctc}}
  plant: {{fmu: linear_analytic_plant}}
connections:
  - {{from: traj.p_ref, to: ik.p_ref}}
  - {{from: traj.v_ref, to: ik.v_ref}}
  - {{from: traj.a_ref, to: ik.a_ref}}
  - {{from: ik.q_ref, to: ctl.q_ref}}
  - {{from: ik.qd_ref, to: ctl.qd_ref}}
  - {{from: ik.qdd_ref, to: ctl.qdd_ref}}
  - {{from: plant.q, to: ctl.q}}
  - {{from: plant.qd, to: ctl.qd}}
  - {{from: ctl.u, to: plant.u}}
time: {{stop: {stop}, step: 0.001}}
logging: {{out: {out}, signals: all}}
"""


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("replay")
    done = _run(["run", str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"), "--stop-time", str(STOP),
                 "--out", str(d / "orig.mcap"), "--quiet"], d)
    assert done.returncode == 0, done.stderr
    export_csv(d / "orig.mcap", d / "exported")
    lines = (d / "exported" / "traj.csv").read_text().splitlines()
    (d / "traj250.csv").write_text("\n".join([lines[0], *lines[1::DECIMATE]]) + "\n")
    synthetic_plant_bag(d / "robot_bag", d / "orig.mcap", offset_s=BAG_OFFSET)
    out = {"dir": d}
    for name, traj, how in (("hold1k", "exported/traj.csv", "hold"), ("hold250", "traj250.csv", "hold"),
                            ("linear250", "traj250.csv", "linear")):
        (d / f"{name}.yaml").write_text(REPLAY.format(traj=traj, how=how, offset=BAG_OFFSET, stop=REPLAY_STOP,
                                                      out=f"{name}.mcap"))
        done = _run(["run", f"{name}.yaml", "--quiet"], d)
        assert done.returncode == 0, (name, done.stderr)
        out[name] = d / f"{name}.mcap"
    return out


def _joints(log: Path, prefix: str = "plant.q") -> np.ndarray:
    return read_run(log).joints(prefix)[1]


def test_the_recorded_trajectory_on_the_runs_grid_reproduces_the_run_exactly(runs):
    """Recorded at the run's own communication points (1 kHz) and held: the IK gets the very values the
    trajectory FMU gave, so every joint is the same double."""
    orig, replay = _joints(runs["dir"] / "orig.mcap")[:N], _joints(runs["hold1k"])
    assert orig.shape == replay.shape and np.array_equal(orig, replay), np.max(np.abs(orig - replay))


def test_a_coarser_recording_reproduces_the_run_within_its_interpolation_error(runs):
    """At 250 Hz, held: the reference lags by up to one recording period, so a joint is off by at most
    h * max|qd_ref|; linear: by the interpolation error of a smooth signal, h^2 / 8 * max|qdd_ref| per joint, which
    the plant, driven by a reference with a kink at every sample, may exceed: within twice that."""
    orig_log = read_run(runs["dir"] / "orig.mcap")
    qd_max = np.abs(orig_log.joints("ik.qd_ref")[1][:N]).max()
    qdd_max = np.abs(orig_log.joints("ik.qdd_ref")[1][:N]).max()
    orig = orig_log.joints("plant.q")[1][:N]
    hold = np.abs(_joints(runs["hold250"]) - orig).max()
    linear = np.abs(_joints(runs["linear250"]) - orig).max()
    assert hold <= H_REC * qd_max, (hold, H_REC * qd_max)
    assert linear <= 2 * H_REC ** 2 / 8 * qdd_max, (linear, 2 * H_REC ** 2 / 8 * qdd_max)
    assert linear < hold / 100, (linear, hold)


def test_the_replayed_joint_state_sits_beside_the_simulated_one_and_compare_finds_them_close(runs):
    """The bag's joints (noise 1e-6 m, 250 Hz, linear between samples) replayed with their offset are the run's
    joints to the noise (a maximum over 991 samples within 5 sigma) plus the 250 Hz linear interpolation's error
    (h^2 / 8 * max|qdd| = 1.6e-6 m): within 1e-5 m; the RMSE is the noise's, within a factor 2."""
    log = runs["hold1k"]
    meta = read_run(log).signal("meas.q[1]")
    assert meta.unit == "m", meta.unit
    maps = [a for i in (1, 2, 3) for a in ("--map", f"plant.q[{i}]=meas.q[{i}]")]
    done = _run(["compare", str(log), str(log), *maps, "--tol", "plant.q=1e-5", "--json"], runs["dir"])
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads(done.stdout)
    for sig in result["signals"]:
        assert sig["ok"] and sig["max_abs"] <= 1e-5 and 0.5e-6 <= sig["rmse"] <= 2e-6, sig
