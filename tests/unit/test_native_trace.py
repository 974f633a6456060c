"""Every native model, traced on symbols, against the :mod:`delta` formulas it calls, evaluated on floats.

The traced functions (CasADi ``Function`` objects, evaluated numerically here; both builds of an FMU evaluate
them: the python build in CasADi's machine, :mod:`fmus.traced`, the native build as compiled C, compared at the FMU
level in ``tests/integration/test_native_fmus.py``) must give what the formulas give on plain floats (their own
float path: the trajectory's ``evaluate_scalar``, the law's ``output_scalar``, ``inverse_kinematics``,
``integrate``) on the same parameters, inputs, time and state. A formula that branches on a computed value without
the namespace fails to trace (CasADi refuses the truth value of a symbol); one that calls ``math`` on a symbol
traces to NaN and fails here.

Tolerance: the trace computes the same operations in CasADi's order; agreement is at rounding level,
RTOL = 1e-12 relative to the size of each quantity (positions ~0.5 m, efforts ~10-100 N).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

ca = pytest.importorskip("casadi")

from fmus import registry  # noqa: E402
from fmus.native.generate import _trace  # noqa: E402
from fmus.native.interface import interface  # noqa: E402

RTOL = 1e-12
NATIVE = registry.native_names()


class Native:
    """One native model's traced functions on a values array, as the C glue calls them."""

    def __init__(self, name: str) -> None:
        self.model = registry.get(name).native_model()
        self.itf = interface(name, self.model)
        self.vr = {v.name: v.vr for v in self.itf.variables}
        self.values = np.array([v.start or 0.0 for v in self.itf.variables], dtype=float)
        self.state = np.array(self.model.initial_state() or [0.0], dtype=float)
        self.fns = {w: _trace(self.model, self.itf, w) for w in ("start", "refresh", "advance", "derivatives", "accept")}

    def set(self, name: str, value: float) -> None:
        self.values[self.vr[name]] = value

    def get(self, name: str) -> float:
        return float(self.values[self.vr[name]])

    def call(self, which: str, t: float = 0.0, h: float = 0.0) -> list[str]:
        fn, info = self.fns[which]
        out, state, ok, details = (np.array(x).ravel() for x in fn(t, h, self.values, self.state))
        self.values[info.sets] = out[:len(info.sets)]
        if which == "start" and self.model.n_state:
            self.state = np.array(self.model.initial_state(), dtype=float)
        if info.sets_state:
            self.state = state[:self.model.n_state]
        failed, first = [], 0
        for (reason, _, n), good in zip(info.checks, ok):  # a reason with values: printed as the C glue prints it
            if good == 0.0:
                failed.append(reason % tuple(details[first:first + n]) if n else reason)
            first += n
        return failed


def declared(name: str):
    """FMU ``name``'s adapter made in Python for its declarations: its parameters' start values."""
    return registry.get(name).declared()


def robot_model(name: str, masses: bool = False):
    """The robot model (:func:`delta.model.build_model`) of FMU ``name``'s start values, on floats."""
    from delta.model import build_model
    from fmus.adapters.common import masses_from, robot_from

    fmu = declared(name)
    return build_model(robot_from(fmu, fmu.KIND), masses_from(fmu, fmu.KIND) if masses else None)


def close(native: float, python: float, what: str, scale: float = 1e-3) -> None:
    """Equal to RTOL relative, or to RTOL times ``scale`` (the size of the quantity over the run) near zero."""
    assert math.isclose(native, python, rel_tol=RTOL, abs_tol=RTOL * scale), f"{what}: native {native!r}, python {python!r}"


def test_every_native_model_traces():
    """Each model's five functions trace (no branch on a symbol) to finite expressions."""
    for name in NATIVE:
        native = Native(name)
        assert native.fns["refresh"][0].n_out() == 4, name


REFS = ("p_ref.x", "p_ref.y", "p_ref.z", "v_ref.x", "v_ref.y", "v_ref.z", "a_ref.x", "a_ref.y", "a_ref.z")


def trajectory(name: str, params: dict):
    """The trajectory FMU ``name`` generates with its start values under ``params``, made on floats."""
    fmu = declared(name)
    return type(fmu).from_parameters({**fmu.values, **params})


@pytest.mark.parametrize("t", [0.0, 0.37, 5.2, 12.0])
def test_helix_matches_the_float_path(t):
    native, helix = Native("helix"), trajectory("helix", {"helix.omega": 2.5})
    native.set("helix.omega", 2.5)
    assert native.call("refresh", t) == []
    for n, x in zip(REFS, (x for xyz in helix.evaluate_scalar(t) for x in xyz)):
        close(native.get(n), x, f"helix {n} at t = {t}")


SEGMENTED = [
    ("point_to_point", {}),
    ("point_to_point", {"move.t0": 0.4, "move.profile": "cubic", "move.end.y": -0.08}),
    ("pick_place", {}),
    ("pick_place", {"cycle.count": 3, "cycle.profile": "cubic", "cycle.direction.x": 0.3, "cycle.direction.y": -0.7}),
    ("pick_place", {"cycle.count": 16, "cycle.time": 0.3}),  # every cycle the native code holds, and after them
    ("pick_place", {"cycle.count": 15, "cycle.time": 0.3}),  # the rest after the last cycle, one before the most
    ("waypoints", {}),
    ("waypoints", {"waypoints.dwell": 0.0, "waypoints.segment_time": 0.6}),
]


@pytest.mark.parametrize("name,params", SEGMENTED)
def test_segmented_trajectories_match_the_float_path(name, params):
    """Knots and segment choice traced: every segment, the rests, zero-length rests, after the end."""
    native, traj = Native(name), trajectory(name, params)
    for n, x in params.items():
        native.set(n, native.itf.by_name()[n].choices.index(x) if isinstance(x, str) else x)
    end = traj.end_time
    peak = {"p": 1.0, "v": 10.0, "a": max(1.0, traj.peak_acceleration)}
    cubic = traj.profile == "cubic"
    knots = [*traj._t0.tolist(), *traj._t1.tolist()]
    times = [0.0, *np.linspace(0.0, end + 0.5, 401)[1:], *(k * 1e-3 for k in range(round(end * 1e3) + 2)), end + 1.0]
    for t in times:
        floats = dict(zip(REFS, (x for xyz in traj.evaluate_scalar(t) for x in xyz)))
        assert native.call("refresh", t) == []
        # The cubic profile's acceleration jumps at each knot. CasADi simplifies what it builds ((a + b) - a
        # is b), so a knot time may differ from the float path's by an ulp, which can put a sample that is
        # within an ulp of a knot on the other side of the jump: there only p and v (continuous) are compared.
        at_jump = cubic and min(abs(t - k) for k in knots) < 1e-12
        for n in ("p_ref.x", "p_ref.y", "p_ref.z", "v_ref.x", "v_ref.y", "v_ref.z", "a_ref.x", "a_ref.z"):
            if at_jump and n.startswith("a_"):
                continue
            # near the rests a value is the rounding of a scaling near 0; compare it to the peak (7.1 g)
            close(native.get(n), floats[n], f"{name} {params} {n} at t = {t}", peak[n[0]])


def test_pick_place_refuses_more_cycles_than_the_native_code_holds():
    from delta.trajectories import NATIVE_MAX_CYCLES

    native = Native("pick_place")
    native.set("cycle.count", NATIVE_MAX_CYCLES + 1)
    failed = native.call("refresh", 0.1)
    assert failed and "cycle.count" in failed[0], failed


POSES = {"linear": [(0.1, 0.0, -0.45), (0.05, -0.08, -0.6), (0.0, 0.0, -0.3), (2.0, 0.0, -0.45)],
         "rotary": [(0.0, 0.0, -0.4108), (0.05, 0.03, -0.45), (0.5, 0.5, -0.1)]}


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_ik_matches_the_float_path_and_holds_when_unreachable(kind):
    from delta.kinematics import inverse_kinematics, proximity, set_pose
    from delta.model import Data

    name = f"{kind}_ik"
    native, model = Native(name), robot_model(name)
    held = None
    for p in POSES[kind]:
        v, a = (0.1, -0.05, 0.02), (0.3, 0.2, -0.1)
        for n, x in zip(REFS, (*p, *v, *a)):
            native.set(n, x)
        q, qd, qdd, fault = inverse_kinematics(model, p, v, a)
        failed = native.call("refresh")
        reachable = fault == 0
        assert bool(native.get("reachable")) == reachable, (kind, p, failed)
        assert (failed == []) == reachable, (kind, p, failed)
        if reachable:
            held = (*q, *qd, *qdd)
            close(native.get("singularity.proximity"), proximity(set_pose(model, Data(model), q, p)), f"{name} proximity")
        assert held is not None, "the first pose must be reachable"
        for n, x in zip([f"{g}[{i}]" for g in ("q_ref", "qd_ref", "qdd_ref") for i in (1, 2, 3)], held):
            close(native.get(n), x, f"{name} {n} at p_ref = {p} (held: {not reachable})")


JOINTS = {"linear": [(0.5, 0.5, 0.5), (0.45, 0.52, 0.6), (0.1, 0.9, 0.5), (0.5, 0.5, 0.5)],
          "rotary": [(0.3, 0.3, 0.3), (2.5, -2.5, 2.5), (0.2, 0.5, 0.35), (0.3, 0.3, 2.8), (1.5, -1.0, 0.2)]}


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_fk_matches_the_float_path_and_holds_when_invalid(kind):
    from delta.dynamics import platform_state
    from delta.errors import UnreachableError
    from delta.kinematics import proximity, working_mode_fault
    from delta.model import Data

    name = f"{kind}_fk"
    native, model = Native(name), robot_model(name)
    validity, held = [], None
    for q in JOINTS[kind]:
        qd = tuple(0.1 * i for i in (1, 2, 3))
        for i, (x, xd) in enumerate(zip(q, qd), 1):
            native.set(f"q[{i}]", x)
            native.set(f"qd[{i}]", xd)
        data = Data(model)
        try:
            p, v = platform_state(model, data, q, qd)
            valid = working_mode_fault(model, q, p) is None
        except UnreachableError:  # the rods cannot meet
            valid = False
        failed = native.call("refresh")
        validity.append(valid)
        assert bool(native.get("valid")) == valid, (kind, q, failed)
        assert (failed == []) == valid, (kind, q, failed)
        if valid:
            held = (*p, *v, proximity(data))
        for n, x in zip(("p.x", "p.y", "p.z", "v.x", "v.y", "v.z", "singularity.proximity"), held):
            close(native.get(n), x, f"{name} {n} at q = {q} (held: {not valid})")
    assert True in validity and False in validity, f"the poses must test both branches: {validity}"


def law(name: str, h: float):
    """The control law of FMU ``name``'s start values, made on floats as :mod:`delta.control` makes it."""
    fmu = declared(name)
    gains = [fmu.vec([f"gain.{g}[{i}]" for i in (1, 2, 3)]) for g in ("kp", "ki", "kd") if f"gain.{g}[1]" in fmu.values]
    model = (robot_model(name, masses=True),) if fmu.MODEL_BASED else ()
    return fmu.LAW_CLASS(*model, *gains, h, u_max=fmu.values["limit.u_max"] or None)


@pytest.mark.parametrize("name", [n for n in NATIVE if n.endswith(("_pd", "_pid", "_pdplus", "_ctc"))])
def test_controllers_match_the_float_path(name):
    native, ref, fmu = Native(name), law(name, 1e-3), declared(name)
    rng = np.random.default_rng(7)
    kind = name.split("_")[0]
    scale = 0.02 if kind == "linear" else 0.05
    inputs = {f"{n}[{i}]": fmu.values[f"{n}[{i}]"] for n in ("q", "qd", "q_ref", "qd_ref", "qdd_ref") for i in (1, 2, 3)}
    for step in range(4):
        for n in inputs:
            inputs[n] += scale * rng.standard_normal()
            native.set(n, inputs[n])
        x = [tuple(inputs[f"{n}[{i}]"] for i in (1, 2, 3)) for n in ("q", "qd", "q_ref", "qd_ref", "qdd_ref")]
        assert native.call("refresh") == []
        for i, u in enumerate(ref.output_scalar(*x), 1):
            close(native.get(f"u[{i}]"), u, f"{name} u[{i}] before step {step}")
        if ref.stateful:
            ref.step(*x)
        assert native.call("advance", step * 1e-3, 1e-3) == []


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_analytic_plant_matches_the_float_path(kind):
    from delta.dynamics import integrate
    from delta.kinematics import inverse_kinematics

    name = f"{kind}_analytic_plant"
    native, model, fmu = Native(name), robot_model(name, masses=True), declared(name)
    assert native.call("start") == []
    u = [fmu.values[f"u[{i}]"] * 1.05 for i in (1, 2, 3)]
    for i, x in enumerate(u, 1):
        native.set(f"u[{i}]", x)
    p, v, h = fmu.vec(["initial.p.x", "initial.p.y", "initial.p.z"]), (0.0, 0.0, 0.0), 1e-3
    for step in range(20):
        p, v = integrate(model, p, v, u, h, fmu.values["solver.max_step"])
        assert native.call("advance", step * h, h) == []
        assert native.call("refresh", (step + 1) * h) == []
    q, qd, _, fault = inverse_kinematics(model, p, v)
    assert fault == 0
    for n, x in zip(("q[1]", "q[2]", "q[3]", "qd[1]", "qd[2]", "qd[3]", "p.x", "p.y", "p.z", "v.x", "v.y", "v.z"),
                    (*q, *qd, *p, *v)):
        close(native.get(n), x, f"{name} {n} after 20 steps")


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_analytic_plant_me_derivatives_match_the_float_path(kind):
    """The model-exchange plant: its states p, v start at the initial platform state; the derivatives (dp/dt = v,
    dv/dt from the platform dynamics) and, apart from them, the outputs q, qd (inverse kinematics) are the formulas'."""
    from delta.dynamics import platform_dynamics
    from delta.kinematics import inverse_kinematics

    name = f"{kind}_analytic_plant_me"
    native, model, fmu = Native(name), robot_model(name, masses=True), declared(name)
    assert native.call("start") == []
    p = fmu.vec(["initial.p.x", "initial.p.y", "initial.p.z"])
    for n, x in zip(("p.x", "p.y", "p.z", "v.x", "v.y", "v.z"), (*p, 0.0, 0.0, 0.0)):
        close(native.get(n), x, f"{name} initial {n}")
    v = tuple(0.01 * (i + 1) for i in range(3))
    for a, x in zip("xyz", v):
        native.set(f"v.{a}", x)
    u = fmu.vec(["u[1]", "u[2]", "u[3]"])
    sets = set(native.fns["derivatives"][1].sets)
    assert native.call("derivatives") == []
    assert not sets & {native.vr[n] for n in ("q[1]", "qd[1]")}, "derivatives computed the outputs too"
    for n, x in zip(("der(p.x)", "der(p.y)", "der(p.z)", "der(v.x)", "der(v.y)", "der(v.z)"),
                    (*v, *platform_dynamics(model, p, v, u))):
        close(native.get(n), x, f"{name} {n}")
    assert native.call("accept") == []  # the accepted state's outputs
    q, qd, _, _ = inverse_kinematics(model, p, v)
    for n, x in zip(("q[1]", "q[2]", "q[3]", "qd[1]", "qd[2]", "qd[3]"), (*q, *qd)):
        close(native.get(n), x, f"{name} {n}")


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_analytic_plant_faults_are_checks(kind):
    """A non-finite effort and a platform driven out of the workspace fail the step with their reason."""
    native = Native(f"{kind}_analytic_plant")
    assert native.call("start") == []
    native.set("u[1]", float("nan"))
    assert "non-finite effort u" in native.call("advance", 0.0, 1e-3)
    native = Native(f"{kind}_analytic_plant")
    native.call("start")
    native.state[:3] = (5.0, 0.0, -0.4)  # far outside the workspace
    failed = native.call("refresh")
    assert failed and "has no solution" in failed[0], failed


@pytest.mark.parametrize("kind", ["linear", "rotary"])
@pytest.mark.parametrize("side", [0, 1])
def test_analytic_plant_end_stop_names_the_joint_value_as_the_float_path(kind, side):
    """A joint past its range (below or above) fails the model-exchange accept of an accepted state with the words
    of the float path: the leg, the joint value and the limit (delta.kinematics.joint_limit_reason); the model-exchange
    derivatives, which the integrator's trial states see, do not check it. The states are the platform's: the state
    is the initial pose moved along an axis until a joint passes its range on the side ``side`` (0: below)."""
    from delta.kinematics import END_STOP, inverse_kinematics, joint_limit_reason

    native = Native(f"{kind}_analytic_plant")
    native.call("start")
    model, p0 = robot_model(f"{kind}_analytic_plant", masses=True), native.state[:3].copy()
    directions = [np.array(d, dtype=float) / np.linalg.norm(d) for d in itertools.product((-1, 0, 1), repeat=3) if any(d)]
    for direction in directions:
        for k in range(1, 2000):  # 0.5 mm steps, up to 1 m
            p = p0 + direction * 5e-4 * k
            q, _, _, fault = inverse_kinematics(model, list(p))
            if fault:
                break
        if fault < 0 and (q[-fault - 1] > model.q_max) == bool(side):
            break
    else:
        pytest.fail(f"no joint passes its {('lower', 'upper')[side]} limit along a line from the initial state")
    for name, x in zip(("p.x", "p.y", "p.z"), p):
        native.set(name, float(x))
    assert native.call("derivatives") == [], "a trial state is not checked"
    failed = native.call("accept")  # the C glue reports the first
    assert failed and failed[0] == f"{END_STOP}: {joint_limit_reason(model, -fault, q[-fault - 1])}", failed


@pytest.mark.parametrize("kind", ["linear", "rotary"])
def test_analytic_plant_step_end_stop_is_the_float_paths(kind):
    """The co-simulation plant's state moved along each axis until a joint passes its range: the refresh at the step's end
    fails with the float path's reason (delta.kinematics.joint_limit_reason), joint value included."""
    from delta.kinematics import END_STOP, inverse_kinematics, joint_limit_reason

    native = Native(f"{kind}_analytic_plant")
    native.call("start")
    model, p0 = robot_model(f"{kind}_analytic_plant", masses=True), native.state[:3].copy()
    seen = 0
    for direction in np.vstack([np.eye(3), -np.eye(3)]):
        for k in range(1, 2000):  # 0.5 mm steps, up to 1 m
            p = p0 + direction * 5e-4 * k
            q, _, _, fault = inverse_kinematics(model, list(p), [0.0, 0.0, 0.0])
            if fault > 0:  # no solution before a joint limit: not this direction
                break
            if fault < 0:
                native.state[:3] = p
                native.state[3:] = 0.0
                expected = f"{END_STOP}: {joint_limit_reason(model, -fault, q[-fault - 1])}"
                failed = native.call("refresh")  # the C glue reports the first
                assert failed and failed[0] == expected, (direction, failed, expected)
                seen += 1
                break
    assert seen, "no joint limit along any axis from the initial state"


@pytest.mark.parametrize("name,parameter,value,reason", [
    ("linear_pd", "gain.kp[2]", -1.0, "PD.kp must be > 0 per joint (joint 2)"),
    ("rotary_pid", "gain.ki[1]", float("nan"), "PID.ki must be >= 0 per joint (joint 1)"),
    ("linear_ctc", "limit.u_max", -5.0, "CTC.u_max must be > 0 per joint"),
    ("linear_ik", "geometry.rod_length", 0.0, "geometry.rod_length must be > 0"),
    ("rotary_fk", "geometry.q_max", -3.0, "geometry.q_min must be < geometry.q_max"),
    ("linear_analytic_plant", "mass.platform", -0.1, "mass.platform must be >= 0"),
    ("rotary_pdplus", "model.w_gravity", 1.5, "model.w_gravity must be in [0, 1]"),
    ("helix", "helix.rx", -0.1, "Helix.rx must be >= 0 m"),
    ("point_to_point", "move.duration", 0.0, "PointToPoint.duration must be > 0 and finite"),
    ("point_to_point", "move.start.x", float("inf"), "PointToPoint.start must be finite"),
    ("waypoints", "waypoints.dwell", -1.0, "Waypoints.dwell must be >= 0 s"),
    ("pick_place", "cycle.direction.x", 0.0, "PickAndPlace.direction must be a non-zero"),
])
def test_a_bad_parameter_fails_with_its_reason_as_an_error(name, parameter, value, reason):
    """The dataclass and controller checks, traced: a bad parameter fails with its reason (an error)."""
    native = Native(name)
    native.set(parameter, value)
    if parameter == "cycle.direction.x":
        native.set("cycle.direction.y", 0.0)
    which = "start" if name.endswith("plant") else "refresh"
    failed = native.call(which)
    assert any(reason in f for f in failed), (failed, reason)
    assert native.fns[which][1].checks[[r for r, _, _ in native.fns[which][1].checks].index(
        next(f for f in failed if reason in f))][1], "a bad parameter must be an error"
