"""What each test FMU declares: variables, model structure, default experiment.

One ``Model`` per (model, FMI version). ``generate.py`` turns it into
modelDescription.xml and into the C table of variables (``variables.h``) that
the model's C file includes, so the XML and the binary share one source.
Variable types are FMI 3 names; the FMI 2 description maps Float64 -> Real,
Int32 -> Integer (other FMI 3-only types are not used there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Var", "Model", "MODEL_SPECS", "state_space_defaults"]


@dataclass(frozen=True)
class Var:
    """One model variable.

    ``field`` is the ModelData member (default: ``name``); ``dims`` holds, per
    array dimension, a fixed size (int) or the name of the structural parameter
    giving it (str); ``derivative`` names the state this variable is the
    derivative of; ``start`` is a scalar or a list (arrays), bytes for Binary.
    """

    name: str
    vr: int
    type: str
    causality: str = "local"
    variability: str | None = None
    initial: str | None = None
    start: object = None
    description: str = ""
    field: str | None = None
    unit: str | None = None
    nominal: float | None = None
    derivative: str | None = None
    dims: tuple = ()
    declared_type: str | None = None
    attributes: tuple = ()  # extra (name, value) XML attributes, e.g. clocks


@dataclass(frozen=True)
class Model:
    """One FMU: ``outputs``/``derivatives``/``event_indicators`` map a variable
    name to the names it depends on (state, input) in ModelStructure."""

    name: str
    fmi: int
    source: str  # C file under c/models/
    description: str
    variables: tuple
    outputs: dict = field(default_factory=dict)
    derivatives: dict = field(default_factory=dict)
    event_indicators: dict = field(default_factory=dict)
    experiment: dict = field(default_factory=dict)
    units: tuple = ()
    enumerations: dict = field(default_factory=dict)  # type name -> ((item, value), ...)
    might_return_early: bool = False
    step_events: bool = False  # model exchange needs fmi{2,3}CompletedIntegratorStep (c: MODEL.step_event)
    fmu_state: bool = False  # get, set and serialize the FMU state (c: core_get_state ..., -DCFMU_FMU_STATE=1)


def _time() -> Var:
    return Var("time", 0, "Float64", "independent", "continuous", description="Simulation time", unit="s")


UNITS = {
    "s": {"s": 1},
    "1/s": {"s": -1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
}


def _bouncing_ball(fmi: int) -> Model:
    return Model(
        "BouncingBall",
        fmi,
        "bouncing_ball.c",
        "Ball bouncing on a floor at h = 0: impacts are state events, a slow rebound ends in rest",
        (
            _time(),
            Var("h", 1, "Float64", "output", "continuous", "calculated", description="Height above the floor",
                unit="m", nominal=1.0),
            Var("der(h)", 2, "Float64", "local", "continuous", "calculated", field="der_h",
                description="Derivative of h", unit="m/s", derivative="h"),
            Var("v", 3, "Float64", "output", "continuous", "calculated", description="Velocity, up positive",
                unit="m/s", nominal=1.0),
            Var("der(v)", 4, "Float64", "local", "continuous", "calculated", field="der_v",
                description="Derivative of v", unit="m/s2", derivative="v"),
            Var("g", 5, "Float64", "parameter", "fixed", "exact", -9.81, "Gravity acceleration", unit="m/s2"),
            Var("e", 6, "Float64", "parameter", "tunable", "exact", 0.7, "Coefficient of restitution"),
            Var("h0", 7, "Float64", "parameter", "fixed", "exact", 1.0, "Initial height", unit="m"),
            Var("bounces", 8, "Int32", "output", "discrete", "calculated", description="Number of impacts so far"),
        ),
        outputs={"h": ["h"], "v": ["v"], "bounces": []},
        derivatives={"der(h)": ["v"], "der(v)": []},
        event_indicators={"h": ["h"]},
        experiment={"startTime": 0.0, "stopTime": 3.0, "stepSize": 0.01},
        units=("s", "m", "m/s", "m/s2"),
        fmu_state=fmi > 1,  # as the Reference FMUs' BouncingBall (FMI 1.0 has no FMU state)
    )


def _stair(fmi: int) -> Model:
    return Model(
        "Stair",
        fmi,
        "stair.c",
        "Counter stepped by time events at t = 1, 2, 3 ... s; asks to terminate at t_terminate",
        (
            _time(),
            Var("counter", 1, "Int32", "output", "discrete", "calculated",
                description="1 at the start, +1 at every whole second"),
            Var("ramp", 2, "Float64", "output", "discrete", "calculated", description="0.5 * counter"),
            Var("t_terminate", 3, "Float64", "parameter", "fixed", "exact", 10.5,
                "Time at which the model asks to end the simulation", unit="s"),
            Var("t_reject", 4, "Float64", "parameter", "fixed", "exact", 1e300,
                "A co-simulation step crossing this time is rejected (default: never)", unit="s"),
        ),
        outputs={"counter": [], "ramp": []},
        experiment={"startTime": 0.0, "stopTime": 10.0, "stepSize": 0.1},
        units=("s",),
        might_return_early=True,
    )


def _halving(fmi: int) -> Model:
    return Model(
        "Halving",
        fmi,
        "halving.c",
        "der(x) = -k x; a step event each time x has halved once more (count += 1)",
        (
            _time(),
            Var("x", 1, "Float64", "output", "continuous", "exact", 1.0, "Decaying state", nominal=1.0),
            Var("der(x)", 2, "Float64", "local", "continuous", "calculated", field="der_x",
                description="Derivative of x", derivative="x"),
            Var("k", 3, "Float64", "parameter", "fixed", "exact", 1.0, "Decay rate", unit="1/s"),
            Var("count", 4, "Int32", "output", "discrete", "calculated",
                description="Step events so far: x fell below 1/2, 1/4, 1/8, ..."),
        ),
        outputs={"x": ["x"], "count": []},
        derivatives={"der(x)": ["x"]},
        experiment={"startTime": 0.0, "stopTime": 5.0, "stepSize": 0.01},
        units=("s", "1/s"),
        step_events=True,
    )


def _van_der_pol(fmi: int) -> Model:
    return Model(
        "VanDerPol",
        fmi,
        "van_der_pol.c",
        "Van der Pol oscillator: der(x0) = x1, der(x1) = mu (1 - x0^2) x1 - x0",
        (
            _time(),
            Var("x0", 1, "Float64", "output", "continuous", "exact", 2.0, "First state", nominal=2.0),
            Var("der(x0)", 2, "Float64", "local", "continuous", "calculated", field="der_x0",
                description="Derivative of x0", derivative="x0"),
            Var("x1", 3, "Float64", "output", "continuous", "exact", 0.0, "Second state", nominal=2.0),
            Var("der(x1)", 4, "Float64", "local", "continuous", "calculated", field="der_x1",
                description="Derivative of x1", derivative="x1"),
            Var("mu", 5, "Float64", "parameter", "fixed", "exact", 1.0, "Damping parameter"),
        ),
        outputs={"x0": ["x0"], "x1": ["x1"]},
        derivatives={"der(x0)": ["x1"], "der(x1)": ["x0", "x1"]},
        experiment={"startTime": 0.0, "stopTime": 20.0, "stepSize": 0.01},
        units=("s",),
    )


def _integrator(fmi: int) -> Model:
    return Model(
        "Integrator",
        fmi,
        "integrator.c",
        "der(x) = k u: integrates its input, k tunable; declares FMU state",
        (
            _time(),
            Var("x", 1, "Float64", "output", "continuous", "exact", 0.0, "Integral of k u", nominal=1.0),
            Var("der(x)", 2, "Float64", "local", "continuous", "calculated", field="der_x",
                description="Derivative of x", derivative="x"),
            Var("u", 3, "Float64", "input", "continuous", None, 0.0, "Integrand"),
            Var("k", 4, "Float64", "parameter", "tunable", "exact", 1.0, "Gain on u"),
        ),
        outputs={"x": ["x"]},
        derivatives={"der(x)": ["u"]},
        experiment={"startTime": 0.0, "stopTime": 1.0, "stepSize": 0.01},
        units=("s",),
        fmu_state=True,
    )


def _horizon(fmi: int) -> Model:
    return Model(
        "Horizon",
        fmi,
        "horizon.c",
        "der(x) = 1; fails any step ending past its stopTime (Error), t_reached = the time reached",
        (
            _time(),
            Var("x", 1, "Float64", "output", "continuous", "exact", 0.0, "Integrated time since the start",
                unit="s", nominal=1.0),
            Var("der(x)", 2, "Float64", "local", "continuous", "calculated", field="der_x",
                description="Derivative of x", derivative="x"),
            Var("t_reached", 3, "Float64", "output", "continuous", "calculated",
                description="The time the FMU is at (its own t + h after a step)", unit="s"),
        ),
        outputs={"x": ["x"], "t_reached": []},
        derivatives={"der(x)": []},
        experiment={"startTime": 0.0, "stopTime": 2.0, "stepSize": 1e-4},
        units=("s",),
    )


def _forgetful(fmi: int) -> Model:
    return Model(
        "Forgetful",
        fmi,
        "forgetful.c",
        "y = p, z an output with initial exact; FMI 2: setupExperiment forgets values set before it; log "
        "messages carry no componentEnvironment (FMI 1.0: no component)",
        (
            _time(),
            Var("p", 1, "Float64", "parameter", "fixed", "exact", 1.0, "A parameter (must be >= 0)"),
            Var("y", 2, "Float64", "output", "continuous", "calculated", description="y = p"),
            Var("z", 3, "Float64", "output", "discrete", "exact", 0.0,
                "An output whose start value an importer may set (initial exact)"),
        ),
        outputs={"y": [], "z": []},
        experiment={"startTime": 0.0, "stopTime": 1.0, "stepSize": 0.1},
        units=("s",),
    )


def state_space_defaults(m: int = 3, n: int = 3, r: int = 3) -> dict[str, list[list[float]] | list[float]]:
    """The StateSpace defaults for given sizes, as in c/models/state_space.c."""
    A = [[0.0] * n for _ in range(n)]
    B = [[0.0] * m for _ in range(n)]
    C = [[0.0] * n for _ in range(r)]
    D = [[0.0] * m for _ in range(r)]
    for i in range(n):
        A[i][i] = -1.0 - 0.5 * i
        if i + 1 < n:
            A[i][i + 1] = 0.5
        if i > 0:
            A[i][i - 1] = -0.5
        if i < m:
            B[i][i] = 1.0
    for i in range(r):
        if i < n:
            C[i][i] = 1.0
        if i + 1 < n:
            C[i][i + 1] = 0.5
        if i < m:
            D[i][i] = 0.1
    return {
        "A": A,
        "B": B,
        "C": C,
        "D": D,
        "x0": [float(i + 1) for i in range(n)],
        "u": [-0.5 if j % 2 else 1.0 for j in range(m)],
        "offset": [0.1, 0.2, 0.3],
    }


def _flat(matrix) -> list[float]:
    return [x for row in matrix for x in row]


def _state_space() -> Model:
    d = state_space_defaults()
    return Model(
        "StateSpace",
        3,
        "state_space.c",
        "Linear system der(x) = A x + B u, y = C x + D u + offset with sizes set by structural parameters",
        (
            _time(),
            Var("m", 1, "UInt64", "structuralParameter", "fixed", "exact", 3, "Number of inputs"),
            Var("n", 2, "UInt64", "structuralParameter", "fixed", "exact", 3, "Number of states"),
            Var("r", 3, "UInt64", "structuralParameter", "fixed", "exact", 3, "Number of outputs"),
            Var("A", 4, "Float64", "parameter", "fixed", "exact", _flat(d["A"]), "System matrix", dims=("n", "n")),
            Var("B", 5, "Float64", "parameter", "fixed", "exact", _flat(d["B"]), "Input matrix", dims=("n", "m")),
            Var("C", 6, "Float64", "parameter", "fixed", "exact", _flat(d["C"]), "Output matrix", dims=("r", "n")),
            Var("D", 7, "Float64", "parameter", "fixed", "exact", _flat(d["D"]), "Feedthrough matrix",
                dims=("r", "m")),
            Var("x0", 8, "Float64", "parameter", "fixed", "exact", d["x0"], "Initial state", dims=("n",)),
            Var("u", 9, "Float64", "input", "continuous", None, d["u"], "Input", dims=("m",)),
            Var("y", 10, "Float64", "output", "continuous", "calculated", description="Output", dims=("r",)),
            Var("x", 11, "Float64", "local", "continuous", "calculated", description="State", dims=("n",)),
            Var("der(x)", 12, "Float64", "local", "continuous", "calculated", field="der_x",
                description="Derivative of x", derivative="x", dims=("n",)),
            Var("offset", 13, "Float64", "parameter", "tunable", "exact", d["offset"],
                "Added to the first min(r, 3) outputs", dims=(3,)),
        ),
        outputs={"y": ["x", "u"]},
        derivatives={"der(x)": ["x", "u"]},
        experiment={"startTime": 0.0, "stopTime": 10.0, "stepSize": 0.01},
        units=("s",),
    )


# FMI 3 type -> (parameter start, input start)
_FEEDTHROUGH_STARTS = {
    "Float32": (0.25, 1.5),
    "Float64": (0.5, 2.5),
    "Int8": (-1, -8),
    "UInt8": (1, 8),
    "Int16": (-2, -16),
    "UInt16": (2, 16),
    "Int32": (-3, -32),
    "UInt32": (3, 32),
    "Int64": (-4, -64),
    "UInt64": (4, 64),
    "Boolean": (True, False),
    "String": ("parameter", "input"),
    "Binary": (b"\x01\x02", b"\x0a\x0b\x0c"),
    "Enumeration": (2, 1),
}
_FMI2_NAMES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String",
               "Enumeration": "Enumeration"}


def _feedthrough(fmi: int) -> Model:
    types = list(_FEEDTHROUGH_STARTS) if fmi == 3 else list(_FMI2_NAMES)  # FMI 1.0: the FMI 2.0 types
    variables = [_time()]
    outputs = {}
    for k, t in enumerate(types, start=1):
        name = t if fmi == 3 else _FMI2_NAMES[t]
        p_start, u_start = _FEEDTHROUGH_STARTS[t]
        is_float = t in ("Float32", "Float64")
        declared = "Option" if t == "Enumeration" else None
        signal = "continuous" if is_float else "discrete"
        variables += [
            Var(f"{name}_parameter", 10 * k + 1, t, "parameter", "tunable", "exact", p_start,
                f"{name} parameter (only stored)", field=f"{t}_parameter", declared_type=declared),
            Var(f"{name}_input", 10 * k + 2, t, "input", signal, None, u_start, f"{name} input",
                field=f"{t}_input", declared_type=declared),
            Var(f"{name}_output", 10 * k + 3, t, "output", signal, "calculated", None,
                f"{name} output = {name}_input", field=f"{t}_output", declared_type=declared),
        ]
        outputs[f"{name}_output"] = [f"{name}_input"]
    if fmi == 3:
        variables += [
            Var("Float64_array_input", 201, "Float64", "input", "continuous", None, [1.0, 2.0, 3.0],
                "Float64 array input", dims=(3,)),
            Var("Float64_array_output", 202, "Float64", "output", "continuous", "calculated", None,
                "Float64 array output = Float64_array_input", dims=(3,)),
        ]
        outputs["Float64_array_output"] = ["Float64_array_input"]
    return Model(
        "Feedthrough",
        fmi,
        "feedthrough.c",
        "Every output equals its input, for each variable type",
        tuple(variables),
        outputs=outputs,
        experiment={"startTime": 0.0, "stopTime": 2.0, "stepSize": 0.01},
        units=("s",),
        enumerations={"Option": (("first", 1), ("second", 2), ("third", 3))},
    )


def _clocked() -> Model:
    return Model(
        "Clocked",
        3,
        "clocked.c",
        "Counts the activations of an input Clock (for testing importers that do not support clocks)",
        (
            _time(),
            Var("tick", 1, "Clock", "input", "discrete", None, None, "Triggered input clock",
                attributes=(("intervalVariability", "triggered"),)),
            Var("ticks", 2, "Int32", "output", "discrete", "calculated", None, "Number of activations of tick",
                attributes=(("clocks", "1"),)),
        ),
        outputs={"ticks": []},
        experiment={"startTime": 0.0, "stopTime": 1.0, "stepSize": 0.01},
        units=("s",),
    )


MODEL_SPECS: dict[tuple[str, int], Model] = {
    ("BouncingBall", 1): _bouncing_ball(1),
    ("Stair", 1): _stair(1),
    ("VanDerPol", 1): _van_der_pol(1),
    ("Feedthrough", 1): _feedthrough(1),
    ("Halving", 1): _halving(1),
    ("BouncingBall", 2): _bouncing_ball(2),
    ("BouncingBall", 3): _bouncing_ball(3),
    ("Stair", 2): _stair(2),
    ("Stair", 3): _stair(3),
    ("VanDerPol", 2): _van_der_pol(2),
    ("VanDerPol", 3): _van_der_pol(3),
    ("StateSpace", 3): _state_space(),
    ("Feedthrough", 2): _feedthrough(2),
    ("Feedthrough", 3): _feedthrough(3),
    ("Clocked", 3): _clocked(),
    ("Halving", 2): _halving(2),
    ("Halving", 3): _halving(3),
    ("Horizon", 2): _horizon(2),
    ("Horizon", 3): _horizon(3),
    ("Integrator", 2): _integrator(2),
    ("Integrator", 3): _integrator(3),
    ("Forgetful", 1): _forgetful(1),
    ("Forgetful", 2): _forgetful(2),
    ("Forgetful", 3): _forgetful(3),
}
