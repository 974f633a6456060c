"""The calibration's pure parts (:mod:`cosim.analysis.calibrate`): --fit parsed and refused, the residual at a
time offset, the weighting by unit, and the standard errors against ordinary least squares' closed form. The fit
on runs is tests/integration/test_calibrate.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.analysis.calibrate import OFFSET, CalibrationError, Fit, _Problem, _uncertainty, _weigh, parse_fits


def test_fits_parse_bounds_linked_names_and_the_offset():
    fits = parse_fits(["plant.mass.payload=0:1", "offset", "plant.mass.rod,ctl.mass.rod=:2", "plant.w=-1:"])
    assert fits[0] == Fit(("plant.mass.payload",), 0.0, 1.0), fits[0]
    assert fits[1].is_offset and fits[1].low == -math.inf and fits[1].high == math.inf, fits[1]
    assert fits[2].names == ("plant.mass.rod", "ctl.mass.rod") and fits[2].label == "plant.mass.rod,ctl.mass.rod"
    assert (fits[2].low, fits[2].high) == (-math.inf, 2.0) and (fits[3].low, fits[3].high) == (-1.0, math.inf)


@pytest.mark.parametrize("items, message", [
    (["plant.mass.payload=1:0"], "the lower bound 1 is not below the upper 0"),
    (["plant.mass.payload=0.5:0.5"], "is not below"),
    (["plant.mass.payload=a:1"], "bounds are LOW:HIGH"),
    (["plant.mass.payload=0.1"], "bounds are LOW:HIGH"),
    (["plant.mass.payload=nan:1"], "bounds are LOW:HIGH"),
    (["=0:1"], "expected NAME[=LOW:HIGH]"),
    (["a,,b"], "expected NAME[=LOW:HIGH]"),
    (["offset,plant.mass.payload"], "cannot be linked"),
    (["plant.mass.payload", "plant.mass.payload,ctl.mass.payload"], "plant.mass.payload is fitted twice"),
    ([], "at least one --fit"),
])
def test_bad_fits_are_one_line(items, message):
    with pytest.raises(CalibrationError) as info:
        parse_fits(items)
    assert message in str(info.value) and "\n" not in str(info.value), str(info.value)


def test_the_residual_meets_the_recording_at_tau_minus_the_offset():
    t = np.linspace(0.0, 1.0, 1001)  # the run: y = 2 t (linear: interpolation is exact)
    tau = np.array([0.3, 0.5, 0.7])  # recorded at tau, the run's time tau - offset
    offset = 0.2137
    problem = _Problem({"a": tau}, {"a": 2.0 * (tau - offset)}, {"a": 0.5})
    raw = problem.residuals(t, {"a": 2.0 * t}, offset, weighted=False)["a"]
    assert np.allclose(raw, 0.0, atol=1e-15), raw
    shifted = problem.residuals(t, {"a": 2.0 * t}, offset + 0.01, weighted=True)["a"]
    # 10 ms later in the run's clock is 20 mm lower, divided by the weight's 0.5
    assert np.allclose(shifted, -0.02 / 0.5, atol=1e-12), shifted


def test_signals_of_one_unit_share_a_weight_and_units_are_weighed_apart():
    problem = _Problem({"q1": np.zeros(3), "q2": np.zeros(3), "th": np.zeros(3)},
                       {"q1": np.array([0.0, 1.0, 2.0]), "q2": np.array([0.0, 0.1, 0.2]),
                        "th": np.array([5.0, 5.0, 5.0])}, {})
    text = _weigh(problem, {"q1": "m", "q2": "m", "th": "rad"})
    assert problem.scale["q1"] == problem.scale["q2"] == pytest.approx(np.std([0.0, 1.0, 2.0])), problem.scale
    assert problem.scale["th"] == 1.0, "a signal of its unit that never moves: no spread to weigh by (1)"
    assert "m 0.816" in text and "rad 0" in text, text


def test_standard_errors_are_ordinary_least_squares_on_a_linear_model():
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1.0, 200)
    jac = np.column_stack([np.ones_like(x), x])  # y = a + b x: the Jacobian of its residual
    y = 1.0 + 2.0 * x + rng.normal(0.0, 0.01, x.size)
    coef, *_ = np.linalg.lstsq(jac, y, rcond=None)
    r = jac @ coef - y
    se, corr, note = _uncertainty(jac, r, 2)
    s2 = float(r @ r) / (x.size - 2)  # the textbook: cov = s^2 (X^T X)^-1
    cov = s2 * np.linalg.inv(jac.T @ jac)
    assert np.allclose(se, np.sqrt(np.diag(cov)), rtol=1e-10), (se, cov)
    assert corr[0][1] == pytest.approx(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1]), rel=1e-10), corr
    assert note == "" and corr[0][0] == pytest.approx(1.0), (note, corr)


def test_a_value_that_changes_nothing_is_reported_as_not_identifiable():
    jac = np.column_stack([np.ones(10), np.zeros(10)])
    se, _, note = _uncertainty(jac, np.full(10, 0.1), 2)
    assert all(math.isinf(v) for v in se) and "not identifiable" in note, (se, note)


def test_no_jacobian_no_errors():
    se, corr, note = _uncertainty(None, np.zeros(4), 2)
    assert se == [None, None] and corr == [] and note == "", (se, corr, note)
    assert OFFSET == "offset"
