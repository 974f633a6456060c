"""A recording component read on its absolute stamps (``time_origin: absolute``): the run's t is the stamp minus the
offset, as ``compare --time-origin absolute`` counts it. On a SYNTHETIC ROS 2 bag of the plant's joints
(tests/recording_helpers.py: stamps from a wall-clock epoch, the recording starting 0.5 s before the run), the replay
with the absolute offset is the replay counted from the first message, bit for bit; ``compare`` with the absolute
offset gives the in-log comparison's figures; a recording too short is refused naming both ranges in stamps."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cli_helpers import ROOT, cosim  # noqa: E402
from recording_helpers import EPOCH_NS, synthetic_plant_bag  # noqa: E402

from cosim import api  # noqa: E402
from cosim.io.recordings import read_recording  # noqa: E402
from cosim.io.runlog import read_run  # noqa: E402

pytestmark = pytest.mark.integration

SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
STOP_S = 0.3  # of the run the bag is made from
REPLAY_STOP_S = 0.29  # of the replays: the bag's last sample is up to a sampling step (4 ms) before STOP_S
OFFSET_S = 0.5  # 125 samples of 4 ms: the run starts on a sample (no kink of the first pose held before it to
# interpolate across); a whole number of 2^-22 s, so EPOCH + 0.5 s is that double exactly
ABSOLUTE_S = EPOCH_NS // 10 ** 9 + OFFSET_S  # the bag's first stamp is the epoch (tests/recording_helpers.py)
STAMP_STEP_S = 2.0 ** -22  # a double's step at 1.7e9 s (2^30 <= 1.7e9 < 2^31): what compare's absolute times round to
SIGNALS = {f"q[{i}]": f"/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)}


def _with_meas(d: Path, name: str, **meas) -> Path:
    data = yaml.safe_load(SCENARIO.read_text())
    data["name"] = name
    data["components"]["meas"] = {"recording": "robot_bag", "signals": SIGNALS, **meas}
    data["logging"] = {"out": f"{name}.mcap", "signals": "all"}
    del data["compare"], data["checks"]  # the helix's tracking check: not the subject here
    path = d / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("time_origin")
    truth = d / "truth.mcap"
    api.run(str(SCENARIO), {"time.stop": STOP_S}, log=True, out=truth, signals=False)
    synthetic_plant_bag(d / "robot_bag", truth, offset_s=OFFSET_S, noise=1e-6, rate_hz=250.0)
    out = {"dir": d}
    for name, meas in (("first", {"offset": OFFSET_S}),
                       ("absolute", {"offset": ABSOLUTE_S, "time_origin": "absolute"})):
        res = cosim("run", _with_meas(d, name, **meas), "--stop-time", REPLAY_STOP_S, "--quiet", cwd=d)
        assert res.returncode == 0, res.stderr
        out[name] = d / f"{name}.mcap"
    return out


def test_the_absolute_offset_replays_the_recording_as_the_offset_from_its_first_message(runs):
    first, absolute = read_run(runs["first"]), read_run(runs["absolute"])
    for i in (1, 2, 3):
        a, b = first.signal(f"meas.q[{i}]"), absolute.signal(f"meas.q[{i}]")
        assert np.array_equal(a.t_ns, b.t_ns) and np.array_equal(a.y, b.y), \
            f"meas.q[{i}]: largest difference {np.max(np.abs(a.y - b.y)):.3g} m"
        assert np.ptp(a.y) > 1e-3, f"meas.q[{i}] moves ({np.ptp(a.y):.3g} m): the comparison means something"


def test_compare_on_absolute_stamps_counts_the_offset_as_the_replay_does(runs):
    """The run's plant against the bag at the absolute offset (compare --time-origin absolute), and against the bag
    replayed in the log (meas): the same recorded samples at the same run stamps; they differ by the rounding of the
    absolute times only (a double's step at 1.7e9 s times the joints' largest speed)."""
    log = runs["absolute"]
    maps = [a for i in (1, 2, 3) for a in ("--map", f"plant.q[{i}]={SIGNALS[f'q[{i}]']}")]
    res = cosim("compare", log, runs["dir"] / "robot_bag", *maps, "--time-origin", "absolute",
                "--offset", repr(ABSOLUTE_S), "--json")
    assert res.returncode == 0, res.stdout + res.stderr
    on_stamps = {s["name"]: s for s in json.loads(res.stdout)["signals"]}
    maps = [a for i in (1, 2, 3) for a in ("--map", f"plant.q[{i}]=meas.q[{i}]")]
    res = cosim("compare", log, log, *maps, "--json")
    assert res.returncode == 0, res.stdout + res.stderr
    in_log = {s["name"]: s for s in json.loads(res.stdout)["signals"]}
    qd_max = max(float(np.abs(read_run(log).signal(f"plant.qd[{i}]").y).max()) for i in (1, 2, 3))
    for name, sig in in_log.items():
        assert 0.5e-6 <= sig["rmse"] <= 2e-6, sig  # the bag's noise: the replay is the robot's joints
        assert abs(on_stamps[name]["rmse"] - sig["rmse"]) <= STAMP_STEP_S * qd_max, (on_stamps[name], sig)


def test_a_recording_too_short_on_absolute_stamps_names_both_ranges(runs):
    path = _with_meas(runs["dir"], "late", offset=ABSOLUTE_S + 0.2, time_origin="absolute")
    res = cosim("run", path, "--stop-time", REPLAY_STOP_S, "--no-log", "--quiet", cwd=runs["dir"])
    err = res.stderr.strip()
    assert res.returncode == 2 and "\n" not in err, (res.returncode, err)
    bag = read_recording(runs["dir"] / "robot_bag", SIGNALS, time_origin="absolute")
    lo, hi = max(t[0] for t in bag.times.values()), min(t[-1] for t in bag.times.values())
    start = ABSOLUTE_S + 0.2
    assert "late.yaml:" in err and "components.meas:" in err and \
        f"covers stamps {lo:.6f} .. {hi:.6f} s (time_origin absolute), the run t = 0 .. {REPLAY_STOP_S:g} s needs " \
        f"{start:.6f} .. {start + REPLAY_STOP_S:.6f} s with offset {start:.6f} s" in err, err
