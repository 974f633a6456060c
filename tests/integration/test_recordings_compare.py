"""``python -m cosim compare RUN.mcap RECORDING --map ...``: a run of this project's plant against a SYNTHETIC ROS 2
bag made from it (tests/recording_helpers.py: 250 Hz, noise 1e-6 m, joint names, an offset that is no whole
number of samples), and against a CSV; the offset recovered below the sampling step, the tolerances applied,
the JSON, and bad input one line with exit 2. The existing compare of two logs is tests/unit/test_compare.py."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cli_helpers import cosim  # noqa: E402
from recording_helpers import synthetic_plant_bag, write_csv  # noqa: E402

from cosim.analysis.recording_compare import compare_recording  # noqa: E402
from cosim.errors import CosimError  # noqa: E402
from cosim.io.runlog import read_run  # noqa: E402

pytestmark = pytest.mark.integration

RUN = Path(__file__).resolve().parents[1] / "golden" / "helix_ctc.mcap"  # linear delta, q in m, every 20 ms
OFFSET_S = 0.2137  # 53.425 samples of 4 ms: the correlation's grid alone is 1.7 ms off
RATE_HZ = 250.0
# the offset from cross-correlation refined below the step: within 0.5 % of the recording's 4 ms step (the
# residual's minimum moves by about noise / slope: 1e-6 m over ~0.05 m/s is 20 us at the slowest of the helix)
OFFSET_ATOL_S = 20e-6
MAPS = [f"--map=plant.q[{i}]=/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)]


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return synthetic_plant_bag(tmp_path_factory.mktemp("bag") / "synthetic_delta", RUN, rate_hz=RATE_HZ,
                               offset_s=OFFSET_S, noise=1e-6)


def test_align_recovers_a_fractional_offset_and_reports_each_signal(bag):
    res = cosim("compare", RUN, bag, *MAPS, "--align", "--json", "--tol", "plant.q=5e-4")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert abs(out["offset_s"] - OFFSET_S) < OFFSET_ATOL_S, f"offset {out['offset_s']} vs {OFFSET_S}"
    assert out["ok"] and out["recording"] == str(bag) and len(out["signals"]) == 3
    for s in out["signals"]:
        # noise 1e-6 m plus the linear interpolation of a 250 Hz cubic through 50 Hz samples: RMSE near the noise
        assert s["rmse"] < 2e-5, s
        assert s["offset_s"] == out["offset_s"] and s["reference"].startswith("/joint_states.position[")
        assert s["tolerance"] == 5e-4 and s["unit"] == "m", s


def test_without_align_the_given_offset_is_used_and_a_wrong_one_fails_the_tolerance(bag):
    maps = {f"plant.q[{i}]": f"/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)}
    good = compare_recording(RUN, bag, maps, offset=OFFSET_S, tolerances={"plant.q": 5e-4})
    bad = compare_recording(RUN, bag, maps, tolerances={"plant.q": 5e-4})
    assert good.ok and good.offset == OFFSET_S and good.offset_how == "given", good.text()
    worst = max(d.max_error for d in bad.diffs)
    assert not bad.ok and worst > 5e-4, f"0.21 s off, the joints differ by more than the tolerance: {worst}"


def test_the_runs_own_regression_tolerances_apply(bag):
    """helix_ctc's regression.tolerances (1e-9 m on plant.q, for its baseline) travel in its log: a
    measurement is held to them when no tolerance is given, and fails them (noise 1e-6 m)."""
    cmp = compare_recording(RUN, bag, {"plant.q[1]": "/joint_states.position[delta_joint_1]"}, align=True)
    assert not cmp.ok and cmp.diffs[0].tolerance == 1e-9, cmp.text()
    assert "FAILED: plant.q[1]" in cmp.text()


def test_a_csv_in_millimetres_against_the_run(tmp_path):
    """A CSV in mm is converted to the run's m; exact samples of the run at its own stamps compare to 0."""
    sig = read_run(RUN).signal("plant.q[2]")
    path = write_csv(tmp_path / "meas.csv", "time [s],q2 [mm]", np.column_stack([sig.t, sig.y * 1e3]),
                     comments=["synthetic: plant.q[2] of tests/golden/helix_ctc.mcap in mm"])
    cmp = compare_recording(RUN, path, {"plant.q[2]": "q2"}, tolerances={"plant.q": 1e-12})
    # mm -> m is one multiplication by 1e-3 of a number printed with 17 digits: a few ulp of 0.5 m
    assert cmp.ok and cmp.diffs[0].max_error < 1e-15 and cmp.diffs[0].unit == "m", cmp.text()


@pytest.mark.parametrize("maps, extra, said", [
    ({"plant.q[1]": "/joint_state.position[delta_joint_1]"}, {}, "no topic '/joint_state'; did you mean "
                                                                 "/joint_states?"),
    ({"plant.q[9]": "/joint_states.position[delta_joint_1]"}, {}, "no signal 'plant.q[9]'"),
    ({"plant.q[1]": "/joint_states.position[delta_joint_1]"}, {"units": {"plant.q[1]": "deg"}},
     "unit 'deg' does not convert to 'm' (rad is not m)"),
    ({"plant.q[1]": "/joint_states.position[delta_joint_1]"}, {"offset": 100.0}, "no overlap"),
    ({}, {}, "needs --map"),
])
def test_bad_input_is_one_line(bag, maps, extra, said):
    with pytest.raises(CosimError) as exc:
        compare_recording(RUN, bag, maps, **extra)
    assert said in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


def test_the_command_ends_bad_input_with_one_line_and_exit_2(bag):
    res = cosim("compare", RUN, bag, "--map", "plant.q[1]")
    assert res.returncode == 2, res.stdout + res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "expected RUN_SIGNAL=RECORDING_SIGNAL" in lines[0], res.stderr
