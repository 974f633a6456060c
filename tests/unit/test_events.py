"""Scenario events in the execution, on fake components (tests/fake_components.py): time events on and between grid
points, state events located by restoring every component's state and stepping again, against analytic crossing
times; the fallback without state."""

from __future__ import annotations

import math

import pytest
from fake_components import FakeSlave, plan

from cosim.engine.events import Change, EventSpec
from cosim.engine.execution import Execution
from cosim.engine.system import Port

STEP_NS = 1_000_000  # 1 ms
G = 9.81
LOCATE_TOL = 1e-6  # s: the events' default tolerance, the issue's requirement


def ball(name: str = "ball", y0: float = 1.0) -> FakeSlave:
    """A falling body in closed form, y(t) = y0 - G t^2 / 2 (exact at any step end: no integration error), plus
    ``k`` (an input no connection drives) echoed as output ``kk`` so an event's change is visible."""
    def step(t, h, u, state):
        t1 = t + h
        return [y0 - 0.5 * G * t1 * t1, float(state.get("k", 0.0))]
    return FakeSlave(name, ["k"], ["y", "kk"], step, initial=[y0, 0.0])


def sine(name: str = "osc", f: float = 2.0) -> FakeSlave:
    def step(t, h, u, state):
        return [math.sin(2.0 * math.pi * f * (t + h))]
    return FakeSlave(name, [], ["y"], step)


def echo(name: str = "sink") -> FakeSlave:
    """y = its input u plus the running sum of u * h (stateful: a wrong restore shows)."""
    def step(t, h, u, state):
        state["sum"] = state.get("sum", 0.0) + u[0] * h
        return [u[0] + state["sum"]]
    return FakeSlave(name, ["u"], ["y"], step)


def execution(slaves, connections, stop_ns, multiples=None, algorithm="gauss_seidel"):
    p = plan(slaves, connections)
    ex = Execution(p, 0, stop_ns, STEP_NS, multiples or [1] * len(slaves), algorithm)
    for s in slaves:
        ex.add_slave(s)
    return ex, p


def port(p, slaves, ref: str) -> Port:
    comp, var = ref.split(".", 1)
    c = p.names.index(comp)
    return Port(c, slaves[c].info.variables[var])


def run_watching(ex: Execution, slaves) -> list[tuple[float, float]]:
    """Initialize and run ``ex`` to its end; (ball's kk, sink's y) after every macro step, as an observer sees them."""
    seen: list[tuple[float, float]] = []

    class Watch:
        def start(self, ex): pass
        def stepped(self, k, t_ns, active): seen.append((slaves[0].out_values[1], slaves[1].out_values[0]))
        def finish(self, ex, error): pass

    ex.add_observer(Watch())
    ex.initialize()
    ex.simulate_until()
    return seen


def set_k(p, slaves, value: float, ref: str = "ball.k") -> tuple[Change, ...]:
    pt = port(p, slaves, ref)
    return (Change(pt.comp, pt.var, (value,)),)


@pytest.mark.parametrize("algorithm", ["gauss_seidel", "jacobi"])
def test_a_state_event_is_located_to_a_microsecond_of_its_analytic_crossing(algorithm):
    slaves = [ball(), echo()]
    ex, p = execution(slaves, [("ball.y", "sink.u")], 600 * STEP_NS, algorithm=algorithm)
    ex.set_events([EventSpec(index=0, changes=set_k(p, slaves, 1.0), shown={"ball.k": 1.0},
                             signal=port(p, slaves, "ball.y"), op="<", value=0.0)])
    ex.initialize()
    ex.simulate_until()
    fired = ex.events.fired
    t_star = math.sqrt(2.0 / G)  # y0 - G t^2 / 2 = 0
    assert len(fired) == 1, f"one crossing, fired {fired}"
    assert 0.0 <= fired[0].t - t_star <= LOCATE_TOL, (
        f"located at {fired[0].t!r} s, analytic crossing {t_star!r} s: {fired[0].t - t_star:.3g} s after it")
    assert ex.events.restarts > 0, "located by re-stepping"
    # the component stepped to the event's time, took the value, and stepped on to the grid
    steps = slaves[0].steps()
    k = int(t_star / 1e-3)
    assert (k * 1e-3, fired[0].t - k * 1e-3) in [(round(a, 12), b) for a, b in steps] or any(
        abs(a + b - fired[0].t) < 1e-15 for a, b in steps), f"no step ends at the event's time {fired[0].t!r}"
    assert slaves[0].out_values[1] == 1.0, f"kk after the event = {slaves[0].out_values[1]}, expected 1.0"


def test_the_trial_steps_of_a_located_event_leave_no_trace():
    """A state event located by re-stepping gives, bit for bit, the run of a time event at the located time: every
    trial step was undone (each component's state, its exchanged values, the downstream sink's running sum)."""
    def run(kind: str, t_at: float = 0.0) -> tuple[list[float], float]:
        slaves = [ball(), echo()]
        ex, p = execution(slaves, [("ball.y", "sink.u")], 600 * STEP_NS)
        common = dict(index=0, changes=set_k(p, slaves, 0.5), shown={"ball.k": 0.5})
        if kind == "state":
            ex.set_events([EventSpec(**common, signal=port(p, slaves, "ball.y"), op="<", value=0.0)])
        else:
            ex.set_events([EventSpec(**common, at=t_at, at_ns=round(t_at * 1e9))])
        seen = run_watching(ex, slaves)
        return seen, ex.events.fired[0].t

    located, t_e = run("state")
    timed, _ = run("time", t_e)
    assert located == timed, "the located event's run differs from a time event's at the same time"
    assert located[-1][0] == 0.5, f"kk after the event = {located[-1][0]}"


def test_a_repeating_state_event_fires_at_every_upward_crossing():
    f = 2.0
    slaves = [sine(f=f), ball()]
    ex, p = execution(slaves, [], 2000 * STEP_NS)
    ex.set_events([EventSpec(index=0, changes=set_k(p, slaves, 1.0), shown={"ball.k": 1.0},
                             signal=port(p, slaves, "osc.y"), op=">", value=0.5, repeat=True)])
    ex.initialize()
    ex.simulate_until()
    expected = [(math.asin(0.5) / (2 * math.pi) + n) / f for n in range(4)]
    got = [e.t for e in ex.events.fired]
    assert len(got) == len(expected), f"fired at {got}, expected {expected}"
    for a, b in zip(got, expected):
        assert 0.0 <= a - b <= LOCATE_TOL, f"fired at {a!r}, crossing at {b!r}"


def test_a_state_event_without_repeat_fires_once():
    slaves = [sine(), ball()]
    ex, p = execution(slaves, [], 2000 * STEP_NS)
    ex.set_events([EventSpec(index=0, changes=set_k(p, slaves, 1.0), shown={}, signal=port(p, slaves, "osc.y"),
                             op=">", value=0.5)])
    ex.initialize()
    ex.simulate_until()
    assert len(ex.events.fired) == 1, f"fired {len(ex.events.fired)} times"


def test_without_state_a_state_event_fires_at_the_end_of_its_step_with_one_warning():
    slaves = [ball(), echo()]
    slaves[1].can_save_state = False
    ex, p = execution(slaves, [("ball.y", "sink.u")], 600 * STEP_NS)
    ex.set_events([EventSpec(index=0, changes=set_k(p, slaves, 1.0), shown={}, signal=port(p, slaves, "ball.y"),
                             op="<", value=0.0)])
    ex.initialize()
    ex.simulate_until()
    t_end = math.ceil(math.sqrt(2.0 / G) / 1e-3) * 1e-3
    assert [round(e.t, 12) for e in ex.events.fired] == [round(t_end, 12)], (
        f"fired at {[e.t for e in ex.events.fired]}, expected the end of the step {t_end}")
    assert len(ex.events.warnings) == 1 and "sink" in ex.events.warnings[0], f"warnings: {ex.events.warnings}"
    assert not any(c[0] == "restore_state" for c in slaves[0].calls), "nothing restored without state"


def test_a_time_event_between_grid_points_cuts_the_step_there():
    slaves = [ball(), echo()]
    ex, p = execution(slaves, [("ball.y", "sink.u")], 5 * STEP_NS)
    ex.set_events([EventSpec(index=0, changes=set_k(p, slaves, 2.0), shown={"ball.k": 2.0}, at=0.0025,
                             at_ns=2_500_000)])
    ex.initialize()
    ex.simulate_until()
    steps = [(round(t, 12), round(h, 12)) for t, h in slaves[0].steps()]
    assert steps == [(0.0, 0.001), (0.001, 0.001), (0.002, 0.0005), (0.0025, 0.0005), (0.003, 0.001),
                     (0.004, 0.001)], f"steps {steps}"
    sets = [c for c in slaves[0].calls if c[0] == "set_values"]
    assert sets == [("set_values", 0.0025, {"k": [2.0]})], f"set calls {sets}"
    assert [(e.t, e.event) for e in ex.events.fired] == [(0.0025, 0)], f"fired {ex.events.fired}"


def test_a_time_event_on_the_grid_is_set_before_the_step_that_starts_there():
    slaves = [ball()]
    ex, p = execution(slaves, [], 5 * STEP_NS)
    ex.set_events([EventSpec(index=0, changes=set_k(p, slaves, 3.0), shown={}, at=0.002, at_ns=2_000_000)])
    ex.initialize()
    ex.simulate_until()
    steps = [round(t, 12) for t, _ in slaves[0].steps()]
    assert steps == [0.0, 0.001, 0.002, 0.003, 0.004], f"no step is cut: {steps}"
    calls = [c[0] for c in slaves[0].calls]
    i_set = calls.index("set_values")
    assert slaves[0].calls[i_set][1] == pytest.approx(0.002, abs=0), "set at 2 ms"
    assert [c for c in slaves[0].calls[i_set:] if c[0] == "step"][0][1] == 0.002, "before the step from 2 ms"


def test_a_multi_rate_component_steps_to_the_cut_and_on_to_the_end_of_its_own_step():
    slow, fast = ball("ball"), sine("osc")
    ex, p = execution([slow, fast], [], 4 * STEP_NS, multiples=[2, 1])
    ex.set_events([EventSpec(index=0, changes=set_k(p, [slow, fast], 1.0), shown={}, at=0.0005, at_ns=500_000)])
    ex.initialize()
    ex.simulate_until()
    steps = [(round(t, 12), round(h, 12)) for t, h in slow.steps()]
    assert steps == [(0.0, 0.0005), (0.0005, 0.0015), (0.002, 0.002)], f"slow component's steps {steps}"


@pytest.mark.parametrize("interval", [1, 10, 37])
def test_saving_the_state_every_few_steps_and_replaying_gives_the_same_run(interval):
    """The system's state is saved every ``state_save_interval`` macro steps; a crossing restores the last save and
    takes the steps since again (with the time events in them, on and between grid points) before locating: the run
    is the one that saves at every step, bit for bit, and the event at the same time."""
    def run(every: int):
        slaves = [ball(), echo()]
        ex, p = execution(slaves, [("ball.y", "sink.u")], 600 * STEP_NS)
        ex.state_save_interval = every
        ex.set_events([
            EventSpec(index=0, changes=set_k(p, slaves, 0.25), shown={}, at=0.445, at_ns=445_000_000),
            EventSpec(index=1, changes=set_k(p, slaves, 0.5), shown={}, at=0.4485, at_ns=448_500_000),
            EventSpec(index=2, changes=set_k(p, slaves, 1.0), shown={}, signal=port(p, slaves, "ball.y"), op="<",
                      value=0.0)])
        seen = run_watching(ex, slaves)
        saves = sum(1 for c in slaves[0].calls if c[0] == "save_state")
        return seen, [(e.t, e.event) for e in ex.events.fired], saves

    every_step, fired_1, saves_1 = run(1)
    sparse, fired_n, saves_n = run(interval)
    assert fired_n == fired_1, f"events {fired_n} saving every {interval} steps, {fired_1} every step"
    assert sparse == every_step, f"the run saving every {interval} steps differs from the one saving every step"
    if interval > 1:
        assert saves_n < saves_1 / (interval / 2), f"{saves_n} saves every {interval} steps against {saves_1}"
