"""validate_model: analytic inverse dynamics against the Exudyn plant, linear and rotary delta.

The plant is driven along the validation motion (prescribed joints, h = 0.2 ms, spectral radius
0.5, Newton relative tolerance 1e-8: multibody.validate.FORCE_COMPARISON_SETTINGS) and its drive
reactions are compared with the analytic model. Run with ``-s`` to see the tables.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from delta.dynamics import RotaryDeltaMasses
from multibody.validate import validate_model

pytestmark = pytest.mark.integration

MASSLESS_TORQUE_TOL = 0.005
"""Relative RMS (issue target). With massless forearms the plant and the analytic model are the
same physics (arm inertia + elbow mass + motor inertia, point-mass platform); what remains is the
integrator's O(h^2) reaction error and the arm's finite radius (its inertia about the motor axis
is ``m La^2 / 3 + m r^2 / 4`` in the plant, ``m La^2 / 3`` in the model: 8e-4 relative)."""

LSQ_TOL = 1e-9
"""Relative slack for comparisons between least-squares optima and grid rows (rounding only)."""

WS = np.array([0.0, 0.1, 0.2, 0.3, 1.0 / 3.0, 0.4, 0.5, 0.6, 2.0 / 3.0, 0.7, 0.8, 0.9, 1.0])
"""The standard grid plus 1/3 (the exact platform-side share of a uniform rod's inertia) and 2/3
(the thesis's / Codourey's value)."""


@pytest.fixture(scope="module")
def rotary_pick():
    calls = []
    report = validate_model("rotary_delta_prototype", "pick_place", ws=WS, separate=True,
                            progress=lambda done, total: calls.append((done, total)))
    return report, calls


@pytest.mark.parametrize("trajectory,duration", [("pick_place", None), ("helix", 0.5)])
def test_rotary_massless_forearms_match_analytic_torques(trajectory, duration):
    report = validate_model("rotary_delta_prototype", trajectory, ws=[2.0 / 3.0], separate=True,
                            masses=RotaryDeltaMasses(rod=0.0), duration=duration)
    print("\n" + report.text())
    assert report.effort_unit == "N*m"
    assert report.best_w_continuous is None and report.separate is None, "massless rods: w must not matter"
    assert report.best.rms_rel < MASSLESS_TORQUE_TOL, (
        f"{trajectory}: RMS torque error {report.best.rms_rel:.4%} >= {MASSLESS_TORQUE_TOL:.2%}")


def test_rotary_pick_cycle_error_vs_w_with_rod_mass(rotary_pick):
    report, _ = rotary_pick
    print("\n" + report.text())
    rms = [row.rms_rel for row in report.sweep]
    assert [row.w_inertia for row in report.sweep] == pytest.approx(WS.tolist())
    assert report.best.rms_rel == min(rms), f"best row {report.best} is not the minimum of {rms}"
    # the analytic efforts are affine in w, so the continuous optimum lies within one grid step
    # of the best grid point and is at least as good as every grid point
    k = rms.index(min(rms))
    lo, hi = WS[max(k - 1, 0)], WS[min(k + 1, len(WS) - 1)]
    assert lo <= report.best_w_continuous <= hi, (
        f"least-squares w {report.best_w_continuous} outside the grid bracket [{lo}, {hi}]")
    # the separate split minimises over a set containing every single w
    assert report.separate.rms_rel <= report.best.rms_rel * (1 + LSQ_TOL), (
        f"separate split RMS {report.separate.rms_rel} > best single-w RMS {report.best.rms_rel}")


def test_linear_pick_cycle_best_w_and_error_at_two_thirds():
    report = validate_model("linear_delta_thesis", "pick_place", ws=WS, separate=True)
    print("\n" + report.text())
    at_two_thirds = report.sweep[8]
    assert at_two_thirds.w_inertia == pytest.approx(2.0 / 3.0)
    print(f"w = 2/3: RMS {at_two_thirds.rms_rel:.2%}; best w {report.best_w} "
          f"(least squares {report.best_w_continuous:.3f}): RMS {report.best.rms_rel:.2%}")
    assert report.best.rms_rel <= at_two_thirds.rms_rel, (
        f"best RMS {report.best.rms_rel} above the w = 2/3 RMS {at_two_thirds.rms_rel}")
    assert report.separate.rms_rel <= report.best.rms_rel * (1 + LSQ_TOL), (
        f"separate split RMS {report.separate.rms_rel} > best single-w RMS {report.best.rms_rel}")


def test_report_serialises_and_progress_reaches_total(rotary_pick):
    report, calls = rotary_pick
    data = json.loads(json.dumps(report.as_dict()))
    assert data["best_w"] == report.best_w and len(data["sweep"]) == len(WS)
    assert data["best_w_inertia"] == report.separate.w_inertia
    assert data["best_w_gravity"] == report.separate.w_gravity
    assert "<- best" in report.text()
    done = [d for d, _ in calls]
    totals = {t for _, t in calls}
    assert len(totals) == 1, f"progress total changed during the run: {sorted(totals)}"
    assert done == sorted(done) and done[-1] == totals.pop(), f"progress not monotonic to the total: {done[-5:]}"


def test_unknown_trajectory_is_rejected_with_the_valid_names():
    with pytest.raises(ValueError, match="helix, pick_place"):
        validate_model("rotary_delta_prototype", "figure_eight")


def test_cli_validate_model_prints_the_sweep_and_best_w(capsys):
    from cosim.cli import main

    code = main(["validate-model", "--robot", "rotary_delta_prototype", "--trajectory", "helix",
                 "--duration", "0.1", "--w", "0", "0.5", "1", "--json"])
    payload = json.loads(capsys.readouterr().out)
    assert code == 0, payload
    assert [row["w_inertia"] for row in payload["sweep"]] == [0.0, 0.5, 1.0], payload["sweep"]
    assert payload["best_w"] in (0.0, 0.5, 1.0) and 0.0 <= payload["best_w_gravity"] <= 1.0, payload
    assert payload["effort_unit"] == "N*m" and payload["samples"] >= 500, payload
    assert main(["validate-model", "--robot", "nope"]) == 2
    assert "unknown preset 'nope'" in capsys.readouterr().err
    for argv, message in ((["--w", "1.5"], "argument --w: expected a finite number in [0, 1], got '1.5'"),
                          (["--step", "0"], "argument --step: expected a finite number > 0, got '0'")):
        with pytest.raises(SystemExit) as stop:  # argparse's usage error: the option and what it takes
            main(["validate-model", "--robot", "linear_delta_thesis", *argv])
        assert stop.value.code == 2 and message in capsys.readouterr().err, argv
