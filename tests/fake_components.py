"""Fake components for master tests (as libcosim's mock slave): the Slave protocol in Python, no FMU to build.

A :class:`FakeSlave` has real inputs and outputs (ctypes buffers, as the FMI wrappers have), a state, and a
step function ``step(t, h, inputs, state) -> outputs`` written in the test. It records every call, so a test
can check what the execution called, in which order and at which times. :func:`plan` wires fake components
into a :class:`~cosim.engine.system.SystemPlan` the way ``build_plan`` would from a scenario.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from cosim.engine.system import Link, Port, SystemPlan
from cosim.fmi import REAL, Terminated, Variable

StepFunction = Callable[[float, float, list[float], dict], list[float]]


def real(name: str, vr: int, causality: str) -> Variable:
    return Variable(name=name, vr=vr, kind=REAL, fmi_type="Real", causality=causality, variability="continuous",
                    unit=None, description=None, start=0.0, index=vr + 1)


@dataclass
class FakeInfo:
    """What the execution and the plan read of an FMU description."""

    name: str
    variables: dict[str, Variable]
    feedthrough: dict[str, list[str] | None] = field(default_factory=dict)
    path: Any = None


class FakeSlave:
    """A component with ``inputs`` and ``outputs`` (Real scalars) stepped by ``step``; ``calls`` records each call.

    ``initial``: the outputs after initialization; ``end_at``: the component asks to end the simulation
    (FMI terminate) in the step that reaches this time.
    """

    model_exchange = False
    events = 0
    can_save_state = True  # set False on an instance: a component without FMU state
    can_serialize_state = True

    def __init__(self, name: str, inputs: Sequence[str], outputs: Sequence[str], step: StepFunction,
                 initial: Sequence[float] | None = None, end_at: float | None = None):
        self.name = name
        self.time = 0.0
        variables = [real(n, i, "input") for i, n in enumerate(inputs)]
        variables += [real(n, len(inputs) + i, "output") for i, n in enumerate(outputs)]
        self.info = FakeInfo(name, {v.name: v for v in variables})
        self._step = step
        self._initial = list(initial) if initial is not None else [0.0] * len(outputs)
        self._end_at = end_at
        self.state: dict = {}
        self.calls: list[tuple] = []
        self.inputs_seen: list[list[float]] = []
        self.in_vars: list[Variable] = []
        self.out_vars: list[Variable] = []
        self.in_values: Any = None
        self.out_values: Any = None
        self._computed: list[float] = []

    # -- Slave protocol
    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None:
        self.in_vars, self.out_vars = list(inputs), list(outputs)
        self.in_values = (ctypes.c_double * max(1, len(inputs)))()
        self.out_values = (ctypes.c_double * max(1, len(outputs)))()

    def locate(self, var: Variable, output: bool = True) -> tuple[Any, int]:
        names = [v.name for v in (self.out_vars if output else self.in_vars)]
        return (self.out_values if output else self.in_values), names.index(var.name)

    def instantiate(self) -> None:
        self.calls.append(("instantiate",))

    def setup_experiment(self, start: float, stop: float) -> None:
        self.calls.append(("setup_experiment", start, stop))

    def set_start(self, values: dict[str, Any]) -> None:
        self.calls.append(("set_start", dict(values)))
        self.state.update(values)

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self.calls.append(("enter_initialization", start, stop))
        self._computed = list(self._initial)

    def exit_initialization(self) -> None:
        self.calls.append(("exit_initialization",))

    def set_inputs(self) -> None:
        self.calls.append(("set_inputs", self.time))
        self._inputs = [self.in_values[i] for i in range(len(self.in_vars))]

    def step(self, t: float, h: float) -> None:
        self.calls.append(("step", t, h))
        self.inputs_seen.append(list(self._inputs))
        self._computed = list(self._step(t, h, self._inputs, self.state))
        self.time = t + h
        if self._end_at is not None and self.time >= self._end_at - 1e-12:
            raise Terminated(self.name, "fmi2DoStep", self.time)

    def get_outputs(self) -> None:
        self.calls.append(("get_outputs", self.time))
        by_name = dict(zip(self._output_names(), self._computed))
        for i, v in enumerate(self.out_vars):
            self.out_values[i] = by_name[v.name]

    def set_step_get(self, t: float, h: float) -> None:
        self.set_inputs()
        try:
            self.step(t, h)
        finally:
            self.get_outputs()

    def terminate(self) -> None:
        self.calls.append(("terminate",))

    def free(self) -> None:
        self.calls.append(("free",))

    # -- state (FMI getFMUstate / setFMUstate) and an event's changes
    def save_state(self, into=None):
        from cosim.fmi.slave import ComponentState

        self.calls.append(("save_state", self.time))
        buffers = [bytes(self.in_values), bytes(self.out_values)]
        handle = (dict(self.state), list(self._computed), list(getattr(self, "_inputs", [])))
        if into is None:
            return ComponentState(handle, self.time, buffers, {})
        into.handle, into.time, into.buffers = handle, self.time, buffers
        return into

    def restore_state(self, saved) -> None:
        self.calls.append(("restore_state", saved.time))
        state, computed, inputs = saved.handle
        self.state, self._computed, self._inputs = dict(state), list(computed), list(inputs)
        ctypes.memmove(self.in_values, saved.buffers[0], len(saved.buffers[0]))
        ctypes.memmove(self.out_values, saved.buffers[1], len(saved.buffers[1]))
        self.time = saved.time

    def free_state(self, saved) -> None:
        self.calls.append(("free_state",))

    def set_values(self, values: dict) -> None:
        self.calls.append(("set_values", self.time, {v.name: list(x) for v, x in values.items()}))
        for var, flat in values.items():
            self.state[var.name] = flat[0] if len(flat) == 1 else list(flat)

    # -- helpers
    def _output_names(self) -> list[str]:
        return [n for n, v in self.info.variables.items() if v.causality == "output"]

    def steps(self) -> list[tuple[float, float]]:
        return [(c[1], c[2]) for c in self.calls if c[0] == "step"]


def plan(slaves: Sequence[FakeSlave], connections: Sequence[tuple[str, str]], order: Sequence[int] | None = None,
         start_values: Sequence[dict] | None = None) -> SystemPlan:
    """A plan of ``slaves`` with ``connections`` (``("a.y", "b.u")``); every output read each step."""
    names = [s.name for s in slaves]

    def port(ref: str) -> Port:
        comp, var = ref.split(".", 1)
        c = names.index(comp)
        return Port(c, slaves[c].info.variables[var])

    links = [Link(port(a), port(b)) for a, b in connections]
    inputs = [[lk.dst.var for lk in links if lk.dst.comp == c] for c in range(len(slaves))]
    outputs = [[v for v in s.info.variables.values() if v.causality == "output"] for s in slaves]
    return SystemPlan(names, [s.info for s in slaves], links, list(order if order is not None else range(len(slaves))),
                      [dict(v) for v in (start_values or [{}] * len(slaves))], inputs, outputs,
                      [list(i) + list(o) for i, o in zip(inputs, outputs)])
