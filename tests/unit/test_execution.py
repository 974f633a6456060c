"""The execution and its algorithms on fake components (tests/fake_components.py): no FMU is built."""

from __future__ import annotations

import os
import signal

import pytest
from fake_components import FakeSlave, plan

from cosim.engine.algorithm import ALGORITHMS, GaussSeidel, Jacobi
from cosim.engine.execution import Execution, StopRequest
from cosim.engine.schema import Scenario
from cosim.engine.supervision import MASTER
from cosim.engine.watchdog import Watchdog
from cosim.errors import Interrupted

STEP_NS = 1_000_000  # 1 ms


def counter(name: str = "src") -> FakeSlave:
    """y = number of steps taken."""
    def step(t, h, u, state):
        state["n"] = state.get("n", 0) + 1
        return [float(state["n"])]
    return FakeSlave(name, [], ["y"], step)


def echo(name: str = "sink") -> FakeSlave:
    """y = its input u, as it was when it stepped."""
    return FakeSlave(name, ["u"], ["y"], lambda t, h, u, state: [u[0]])


def execution(slaves, connections, algorithm="gauss_seidel", stop_ns=5 * STEP_NS, multiples=None, order=None):
    ex = Execution(plan(slaves, connections, order), 0, stop_ns, STEP_NS, multiples or [1] * len(slaves), algorithm)
    for s in slaves:
        ex.add_slave(s)
    return ex


class Recorder:
    def __init__(self):
        self.events = []

    def start(self, ex):
        self.events.append(("start", ex.k_done))

    def stepped(self, k, t_ns, active):
        self.events.append(("stepped", k, t_ns, list(active)))

    def finish(self, ex, error):
        self.events.append(("finish", error))


def test_the_registry_gives_the_scenario_its_choices():
    enum = Scenario.model_json_schema()["properties"]["algorithm"]["enum"]
    assert enum == list(ALGORITHMS) == ["gauss_seidel", "jacobi"]
    assert ALGORITHMS["gauss_seidel"] is GaussSeidel and ALGORITHMS["jacobi"] is Jacobi


def test_gauss_seidel_reads_outputs_of_the_same_step_jacobi_of_the_previous():
    seen = {}
    for algorithm in ALGORITHMS:
        src, sink = counter(), echo()
        ex = execution([src, sink], [("src.y", "sink.u")], algorithm)
        ex.initialize()
        ex.simulate_until()
        seen[algorithm] = [u[0] for u in sink.inputs_seen]
    assert seen["gauss_seidel"] == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert seen["jacobi"] == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_jacobi_sets_every_input_before_any_step():
    src, sink = counter(), echo()
    ex = execution([src, sink], [("src.y", "sink.u")], "jacobi", stop_ns=STEP_NS)
    ex.initialize()
    n_init = len(src.calls), len(sink.calls)
    ex.step()
    src_calls, sink_calls = src.calls[n_init[0]:], sink.calls[n_init[1]:]
    assert [c[0] for c in src_calls] == ["set_inputs", "step", "get_outputs"]
    assert [c[0] for c in sink_calls] == ["set_inputs", "step", "get_outputs"]


def test_times_are_exact_multiples_of_the_step_and_multi_rate_steps_every_m():
    fast, slow = counter("fast"), counter("slow")
    ex = execution([fast, slow], [], stop_ns=6 * STEP_NS, multiples=[1, 3])
    rec = Recorder()
    ex.add_observer(rec)
    ex.initialize()
    ex.simulate_until()
    assert fast.steps() == [(k * 1e-3, 1e-3) for k in range(6)]
    assert slow.steps() == [(0.0, 3e-3), (3e-3, 3e-3)]
    stepped = [e for e in rec.events if e[0] == "stepped"]
    assert [e[3] for e in stepped] == [[0, 1], [0], [0], [0, 1], [0], [0]]
    assert [e[2] for e in stepped] == [(k + 1) * STEP_NS for k in range(6)]


def test_observers_start_after_initialization_and_see_every_step():
    src = counter()
    ex = execution([src], [], stop_ns=3 * STEP_NS)
    rec = Recorder()
    ex.add_observer(rec)
    ex.initialize()
    assert rec.events == [("start", 0)] and ex.started == [rec]
    ex.step()
    ex.simulate_until(2 * STEP_NS)
    assert ex.k_done == 2
    ex.simulate_until()
    assert ex.k_done == 3 == ex.n_steps
    assert [e[1] for e in rec.events if e[0] == "stepped"] == [0, 1, 2]


@pytest.mark.parametrize("algorithm, read", [("gauss_seidel", ["a"]), ("jacobi", ["z", "a"])])
def test_a_component_that_ends_the_simulation_ends_it_inside_its_step(algorithm, read):
    """The order is z, a, b: a ends the run at t = 2 ms; Gauss-Seidel reads a only (z was read after its turn),
    Jacobi reads z and a (both stepped); b, after a in the order, does not step in that macro step."""
    z, b = counter("z"), counter("b")
    a = FakeSlave("a", [], ["y"], lambda t, h, u, s: [t + h], end_at=2e-3)
    ex = execution([z, a, b], [], algorithm)
    rec = Recorder()
    ex.add_observer(rec)
    ex.initialize()
    ex.simulate_until()
    assert ex.terminated is not None and ex.terminated.component == "a"
    assert ex.k_done == 2 and ex.t_end_ns == 2 * STEP_NS
    last = [e for e in rec.events if e[0] == "stepped"][-1]
    assert last[3] == [ex.plan.names.index(n) for n in read]
    assert len(b.steps()) == 1  # after a in the order: it does not step in the macro step a ended
    ex.simulate_until()  # ended: nothing more
    assert ex.k_done == 2


def test_the_execution_records_which_component_has_the_turn():
    """What the watchdog reads instead of the call stack: the component with the turn, its time; the master
    between turns."""
    ex = None
    seen = []

    def step(t, h, u, state):
        seen.append((int(ex.current[0]), int(ex.current[3]), watchdog._where()))
        return [0.0]

    a, b = counter("a"), FakeSlave("b", [], ["y"], step)
    ex = execution([a, b], [], stop_ns=2 * STEP_NS)
    watchdog = Watchdog(ex, None, StopRequest(), lambda err: None)
    ex.initialize()
    assert watchdog._where() == ("(master)", 0.0, "")
    ex.simulate_until()
    assert [s[:2] for s in seen] == [(1, 0), (1, 1)]  # b has the turn; steps done before it
    assert seen[1][2] == ("b", 1e-3, "")  # b's own time when the step was called
    assert int(ex.current[0]) == MASTER


def test_a_stop_request_ends_the_run_between_macro_steps():
    src = counter()
    ex = execution([src], [], stop_ns=10 * STEP_NS)
    ex.initialize()
    stop = StopRequest()
    stop.request(signal.SIGTERM)
    with pytest.raises(Interrupted):
        ex.simulate_until(None, stop)
    assert ex.k_done == 1 and len(src.steps()) == 1


def test_a_signal_no_step_boundary_saw_is_honoured_when_the_stop_context_ends():
    """A signal after the last macro step's check (or during an initialization, which checks none) is not dropped:
    leaving the stop context raises Interrupted with its signal; without a signal, or when the block already
    failed, nothing is added."""
    src = counter()
    ex = execution([src], [], stop_ns=3 * STEP_NS)
    ex.initialize()
    with pytest.raises(Interrupted) as caught:
        with StopRequest() as stop:
            ex.simulate_until(None, stop)
            os.kill(os.getpid(), signal.SIGTERM)  # the handler only sets the flag: the loop is over
            assert stop.requested and ex.k_done == 3
    assert caught.value.signum == signal.SIGTERM
    with StopRequest():
        pass
    with pytest.raises(ValueError):
        with StopRequest() as stop:
            stop.request(signal.SIGINT)
            raise ValueError("the block's own failure stays the error")


def test_initialization_sets_start_values_and_propagates_outputs_in_order():
    src = FakeSlave("src", [], ["y"], lambda t, h, u, s: [0.0], initial=[7.0])
    sink = echo()
    ex = Execution(plan([src, sink], [("src.y", "sink.u")], start_values=[{"k": 2.0}, {}]), 0, STEP_NS, STEP_NS,
                   [1, 1])
    ex.add_slave(src)
    ex.add_slave(sink)
    ex.initialize()
    assert ("set_start", {"k": 2.0}) in src.calls
    ex.simulate_until()
    assert sink.inputs_seen == [[0.0]]  # Gauss-Seidel: src stepped first (outputs 0.0), sink read it
    # the order of FMPy and libcosim: start values after the experiment's setup, before initialization mode
    assert src.calls[:4] == [("instantiate",), ("setup_experiment", 0.0, 1e-3), ("set_start", {"k": 2.0}),
                             ("enter_initialization", 0.0, 1e-3)], src.calls[:4]


def test_initialize_refuses_a_plan_with_components_missing():
    src, sink = counter(), echo()
    ex = Execution(plan([src, sink], [("src.y", "sink.u")]), 0, STEP_NS, STEP_NS, [1, 1])
    ex.add_slave(src)
    with pytest.raises(ValueError, match="1 components added, the plan has 2"):
        ex.initialize()


def test_observers_of_signals_run_on_fake_components():
    """The tracking error and peak-effort observers, on a reference and an actual signal of fakes."""
    from cosim.observers.recorders import ErrorObserver, PeakEffort

    ref = FakeSlave("ref", [], ["p.x", "p.y", "p.z"], lambda t, h, u, s: [t + h, 0.0, 0.0])
    act = FakeSlave("act", [], ["p.x", "p.y", "p.z", "u"], lambda t, h, u, s: [t + h + 1e-3, 0.0, 0.0, -(t + h) * 10])
    ex = execution([ref, act], [], stop_ns=4 * STEP_NS)
    tracking = ErrorObserver(["act.p.x", "act.p.y", "act.p.z"], ["ref.p.x", "ref.p.y", "ref.p.z"])
    peak = PeakEffort()
    ex.add_observer(tracking)
    ex.add_observer(peak)
    ex.initialize()
    ex.simulate_until()
    x, y, z = tracking.result()
    assert x.max_error == pytest.approx(1e-3) and y.max_error == 0.0 and z.rmse == 0.0
    assert peak.peak == pytest.approx(0.04)
