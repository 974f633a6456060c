"""The time grid (cosim.engine.grid): integer-nanosecond points, and doubles on which every step lands exactly."""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from cosim.engine.execution import Execution
from cosim.engine.grid import NS_PER_S, Grid, grid_error, step_between
from cosim.engine.schema import TimeGrid
from fake_components import FakeSlave, plan

STOPS = (0.1, 0.3, 0.7, 1.0, 2.0, 2.2, 3.0, 10.0)
STEPS = (1e-4, 1e-3, 0.01, 0.05, 0.1)
PAIRS = [(stop, step) for stop in STOPS for step in STEPS]  # 40 stop/step pairs, 2 s / 1e-4 s among them
THIRTIETH = 1 / 30


def grid_of(stop: float, step: float, start: float = 0.0) -> Grid:
    t = TimeGrid(stop=stop, step=step, start=start)
    return Grid(t.start_ns, t.stop_ns, t.step_ns)


def test_the_old_formula_overshoots_where_the_grid_does_not():
    """The reason for the grid: (k step_ns) * 1e-9 + step_ns * 1e-9 ends past 2.0 s at the last step of 2 s / 1e-4 s.
    Counted over the pairs, so a change of PAIRS that no longer exercises an overshoot fails here."""
    overshoot = []
    for stop, step in PAIRS:
        g = grid_of(stop, step)
        t_last = (g.start_ns + (g.n_steps - 1) * g.step_ns) * 1e-9
        if t_last + g.step_ns * 1e-9 > g.stop_ns / NS_PER_S:
            overshoot.append((stop, step))
    assert (2.0, 1e-4) in overshoot, f"2 s / 1e-4 s no longer overshoots with the old formula: {overshoot}"
    assert len(overshoot) >= 5, f"only {len(overshoot)} of {len(PAIRS)} pairs overshoot with the old formula"


@pytest.mark.parametrize("stop, step", PAIRS + [(1.0, THIRTIETH), (2.0, THIRTIETH), (0.5, THIRTIETH)])
@pytest.mark.parametrize("start", [0.0, 0.25])
def test_every_step_lands_on_the_next_point_and_the_last_on_the_stop_time(stop, step, start):
    g = grid_of(stop + start, step, start)
    stop_s = g.stop_ns / NS_PER_S
    assert g.t_ns(0) == g.start_ns and g.t_ns(g.n_steps) == g.stop_ns, (g.t_ns(0), g.t_ns(g.n_steps))
    t = g.time(0)
    for k in range(g.n_steps):
        h = g.step_size(k)
        t_next = g.time(k + 1)
        assert h > 0 and t + h == t_next, f"k = {k}: {t!r} + {h!r} = {t + h!r}, point {k + 1} is {t_next!r}"
        t = t + h
    assert t == stop_s, f"the last step ends at {t!r}, the stop time is {stop_s!r}"


@pytest.mark.parametrize("stop, step", [(2.0, 1e-4), (1.0, THIRTIETH), (3.0, 0.1)])
def test_each_point_is_the_double_nearest_its_nanoseconds(stop, step):
    g = grid_of(stop, step)
    for k in range(0, g.n_steps + 1, max(1, g.n_steps // 500)):
        exact = Fraction(g.t_ns(k), NS_PER_S)
        t = g.time(k)
        assert abs(Fraction(t) - exact) <= Fraction(abs(t)) * Fraction(1, 2**53), (k, t, exact)


def test_a_step_that_is_no_whole_number_of_nanoseconds_is_rounded_and_the_stop_time_still_hit():
    """1/30 s: 33333333 ns per step, 30 steps to 1 s; the points are k / 30 s rounded to the nanosecond, each step
    33333333 or 33333334 ns, the last point exactly 1 s."""
    g = grid_of(1.0, THIRTIETH)
    assert (g.step_ns, g.n_steps, g.t_ns(30)) == (33_333_333, 30, NS_PER_S), (g.step_ns, g.n_steps, g.t_ns(30))
    for k in range(31):
        assert abs(Fraction(g.t_ns(k)) - Fraction(k * NS_PER_S, 30)) <= Fraction(1, 2), (k, g.t_ns(k))
    widths = {g.t_ns(k + 1) - g.t_ns(k) for k in range(30)}
    assert widths <= {33_333_333, 33_333_334}, widths


def test_a_span_that_is_no_whole_number_of_steps_is_refused():
    assert grid_error(0, NS_PER_S, 300_000_000) is not None  # 1 s in steps of 0.3 s
    with pytest.raises(ValueError, match="not a whole number of steps"):
        TimeGrid(stop=1.0, step=0.3)
    with pytest.raises(ValueError, match="not a whole number of steps"):
        Grid(0, NS_PER_S, 300_000_000)
    with pytest.raises(ValueError, match="resolution"):
        TimeGrid(stop=1.0, step=1e-10)


def test_step_between_reaches_the_next_double_or_the_one_just_below():
    """Points far apart relative to t (t < t_next / 2): the rounded difference can miss, a neighbour hits; where no
    double hits (ties rounded to even away from t_next) t + h is the double just below t_next, never past it."""
    misses = unreachable = 0
    for k in range(1, 4000):
        t, t_next = k / 7919, 3 * k / 7919 + 1e-3
        misses += t + (t_next - t) != t_next
        h = step_between(t, t_next)
        if t + h != t_next:
            unreachable += 1
            assert t + h == math.nextafter(t_next, 0.0), (t, t_next, h, t + h)
            # no double within 8 ulps of h reaches t_next either
            for x in (h, math.nextafter(h, 0.0)):
                for _ in range(8):
                    assert t + x != t_next, (t, t_next, x)
                    x = math.nextafter(x, math.inf)
    assert misses >= unreachable > 0, f"{misses} misses, {unreachable} unreachable: the test no longer exercises them"


def test_a_multi_rate_step_ends_on_the_stop_time_not_past_it():
    """A component of step multiple 3 on a grid of 10 steps: its last step, at k = 9, is one base step long."""
    g = Grid(0, 10 * 1_000_000, 1_000_000)
    assert g.end(9, 3) == 10 and g.end(6, 3) == 9
    assert g.time(9) + g.step_size(9, 3) == g.time(10) == 0.01


def test_index_finds_the_last_point_at_or_before_a_time():
    g = grid_of(1.0, THIRTIETH)
    for k in range(31):
        assert g.index(g.t_ns(k)) == k and (k == 0 or g.index(g.t_ns(k) - 1) == k - 1), k
    assert g.index(2 * NS_PER_S) == 30


def test_the_execution_calls_its_components_on_the_grid():
    """Every doStep of a run, serial as in the worker, gets the grid's t and h: t + h is the next call's t, the last
    one the stop time; a multi-rate component's last step is cut at the stop time."""
    steps = {"a": [], "b": []}

    def rec(name):
        def step(t, h, u, state):
            steps[name].append((t, h))
            return [0.0]
        return step

    slaves = [FakeSlave("a", [], ["y"], rec("a")), FakeSlave("b", [], ["y"], rec("b"))]
    tg = TimeGrid(stop=2.0, step=1e-4)
    ex = Execution(plan(slaves, []), tg.start_ns, tg.stop_ns, tg.step_ns, [1, 3], "jacobi")
    for s in slaves:
        ex.add_slave(s)
    ex.initialize()
    ex.simulate_until()
    for name, calls in steps.items():
        for (t, h), (t_next, _) in zip(calls, calls[1:]):
            assert t + h == t_next, f"{name}: {t!r} + {h!r} = {t + h!r}, next call at {t_next!r}"
        t, h = calls[-1]
        assert t + h == 2.0, f"{name}: the last step ends at {t + h!r}"
    assert len(steps["a"]) == 20000 and len(steps["b"]) == 6667, (len(steps["a"]), len(steps["b"]))


@pytest.mark.parametrize("stop, step, start", [(2.0, 1e-4, 0.0), (1.25, THIRTIETH, 0.25), (10.0, 0.1, 3.0)])
def test_the_hot_loop_chunks_give_the_same_doubles(stop, step, start):
    """Execution.simulate_until takes its times and base step sizes from Grid.chunk: the same as time, step_size."""
    g = grid_of(stop, step, start)
    for k0, k1 in [(0, g.n_steps), (3, 17), (g.n_steps - 5, g.n_steps)]:
        times, steps = g.chunk(k0, k1)
        assert times == [g.time(k) for k in range(k0, k1)], (k0, k1)
        assert steps == [g.step_size(k) for k in range(k0, k1)], (k0, k1)


def test_a_step_below_what_a_double_tells_apart_is_refused():
    """At 8e9 s neighbouring doubles are 9.5e-7 s apart: a 1e-7 s step would give an FMU steps of 0 s."""
    from cosim.engine.grid import resolution_error, seconds

    start = 8_000_000_000 * 1_000_000_000
    why = resolution_error(start, start + 1_000_000, 100)
    assert why is not None and "below what a double tells apart at t = 8000000000.001 s" in why, why
    assert resolution_error(start, start + 1_000_000, 2_000) is None  # 2e-6 s: two doubles apart, accepted
    assert resolution_error(0, 1_000_000_000, 1) is None  # 1 ns at 1 s: far above the resolution
    with pytest.raises(ValueError, match="below what a double tells apart"):
        TimeGrid(start=8e9, stop=8e9 + 1e-3 * 1024 / 1000, step=1e-7)
    assert seconds(8_000_000_000_000_100_000) == "8000000000.0001" and seconds(500_000_000) == "0.5"


def test_step_multiples_with_a_long_common_period_are_refused_before_any_fmu():
    """Multiples of 7919 and 7907 repeat every 62 615 533 base steps: a schedule of that length is refused at once,
    naming the components; over a run shorter than the period the schedule holds the run's steps only."""
    from cosim.engine.execution import MAX_SCHEDULE
    from cosim.errors import ScenarioError

    slaves = [FakeSlave(n, [], ["y"], lambda t, h, u: [0.0]) for n in ("a", "b")]
    long_run = 10 ** 8
    with pytest.raises(ScenarioError, match=r"a every 7919, b every 7907 base steps\) repeat only every 62615533"):
        Execution(plan(slaves, []), 0, long_run * 1000, 1000, [7919, 7907])
    short = Execution(plan(slaves, []), 0, 1000 * 1000, 1000, [7919, 7907])
    assert len(short.schedule()) == 1000 <= MAX_SCHEDULE
    assert len(Execution(plan(slaves, []), 0, 1000 * 1000, 1000, [1, 2]).schedule()) == 2
