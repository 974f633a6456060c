"""The python build's step (fmus.traced): the native model's traced functions under the C runtime's rules.

What the C runtime (fmus/native/c/runtime.c) does, the python runtime does: a failed error check fails the call
with its reason at its time; a warning is logged when its function starts reporting it, not again while it goes
on, and again after it stopped; a communication step splits into ceil(h / max_step) equal advances; the
constants follow a tunable parameter changed during the run; the traced model a python FMU carries (JSON) runs as
the one traced in the process.
"""

from __future__ import annotations

import pytest

pytest.importorskip("casadi")
pytest.importorskip("pythonfmu")

from fmus import registry  # noqa: E402
from fmus.traced import ModelCheckError, Runtime, TracedModel  # noqa: E402


def _make(name: str):  # noqa: ANN202
    """FMU ``name``'s python build made in Python (its class as the builder writes it, with the traced model)."""
    return registry.get(name).python_class()(instance_name=name, resources=None, visible=False)


def _vr(fmu, name: str) -> int:  # noqa: ANN001
    return next(v.value_reference for v in fmu.vars.values() if v.name == name)


def _warnings(fmu) -> list[str]:  # noqa: ANN001
    return [m.msg for m in fmu.log_queue if "unreachable" in m.msg]


def test_an_unreachable_reference_warns_when_it_starts_and_again_after_it_ended():
    ik = _make("linear_ik")
    ik.setup_experiment(0.0)
    ik.enter_initialization_mode()
    ik.exit_initialization_mode()
    x, q1, reachable = _vr(ik, "p_ref.x"), _vr(ik, "q_ref[1]"), _vr(ik, "reachable")
    held = ik.get_real([q1])
    for k, px in enumerate((2.0, 2.1, 2.2)):  # out of the workspace three steps in a row
        ik.set_real([x], [px])
        assert ik.get_boolean([reachable]) == [False]
        assert ik.get_real([q1]) == held, "the joint reference holds its last reachable value"
        ik.do_step(k * 1e-3, 1e-3)
    assert len(_warnings(ik)) == 1, _warnings(ik)
    assert "p_ref is unreachable: leg 1 has no solution; joint references hold" in _warnings(ik)[0], _warnings(ik)
    ik.set_real([x], [0.0])
    assert ik.get_boolean([reachable]) == [True]
    ik.set_real([x], [2.0])
    assert ik.get_boolean([reachable]) == [False]
    assert len(_warnings(ik)) == 2, "reported again after the reference came back"


def test_a_failed_error_check_fails_the_step_with_its_reason_at_its_time():
    pd = _make("linear_pd")
    pd.setup_experiment(0.0)
    pd.enter_initialization_mode()
    pd.exit_initialization_mode()
    assert pd.do_step(0.0, 1e-3)
    pd.set_real([_vr(pd, "gain.kp[1]")], [-1.0])  # tunable: taken, the law refuses it at its next evaluation
    assert not pd.do_step(1e-3, 1e-3)
    assert pd.log_queue[-1].msg == "t = 0.002 s: PD.kp must be > 0 per joint (joint 1)", pd.log_queue[-1].msg
    assert not pd.do_step(2e-3, 1e-3), "a failed instance refuses further steps"


def test_a_step_is_split_into_equal_advances_of_at_most_max_step():
    model = registry.get("linear_analytic_plant").traced_model()
    rt = Runtime(model, lambda message: None)
    index = [v[0] for v in model.variables].index("solver.max_step")
    rt.values[index] = 1e-3
    assert [rt.substeps(h) for h in (1e-3, 2.5e-3, 3e-3, 1e-4)] == [1, 3, 3, 1]
    rt.values[index] = 0.0
    with pytest.raises(ModelCheckError, match="solver.max_step must be a time > 0 s, got 0.0"):
        rt.substeps(1e-3)


def test_the_payload_set_during_a_run_changes_the_motion_from_then_on():
    """mass.payload is tunable: the constants that hold the lumped masses are computed again."""
    runs = []
    for payload in (None, 2.0):
        plant = _make("linear_analytic_plant")
        plant.setup_experiment(0.0)
        plant.enter_initialization_mode()
        plant.exit_initialization_mode()
        for k in range(20):
            if payload is not None and k == 10:
                plant.set_real([_vr(plant, "mass.payload")], [payload])
            assert plant.do_step(k * 1e-3, 1e-3)
            if k == 9:
                at_10 = plant.get_real([_vr(plant, "p.z")])
        runs.append((at_10, plant.get_real([_vr(plant, "p.z")])))
    assert runs[0][0] == runs[1][0], "the same motion before the payload changed"
    assert runs[1][1][0] < runs[0][1][0] - 1e-9, f"a heavier platform falls further under the same efforts: {runs}"


def test_the_model_a_python_fmu_carries_runs_as_the_one_traced_here():
    traced = registry.get("rotary_ctc").traced_model()
    again = TracedModel.loads(traced.dumps())
    outs = []
    for model in (traced, again):
        rt = Runtime(model, lambda message: None)
        names = [v[0] for v in model.variables]
        rt.values[names.index("q_ref[2]")] += 0.01
        rt.run("start", 0.0)
        rt.run("refresh", 0.0)
        outs.append([float(rt.values[names.index(f"u[{i}]")]) for i in (1, 2, 3)])
    assert outs[0] == outs[1] and outs[0] != [0.0, 0.0, 0.0], outs
