"""The model-exchange integrators on a model in plain Python (no FMU): x' = -x, z = x - 1/2.

Closed forms: x(t) = x0 e^-t, the indicator crosses zero at t = ln(2 x0).
"""

from __future__ import annotations

import math

import pytest

from cosim.fmi.integrators import SOLVERS, make_integrator

RTOL = 1e-10
ROOT_ATOL = 1e-9  # s: both locate roots to ~100 eps (|t| + |h|); the state error at rtol 1e-10 dominates


class Decay:
    """An OdeModel (cosim.fmi.integrators) over ctypes-like arrays, counting right-hand-side calls."""

    nx, nz = 1, 1

    def __init__(self, x0: float = 1.0):
        self.t, self.x, self.rhs_calls = 0.0, x0, 0

    def set_time(self, t):
        self.t = t

    def get_x(self, x):
        x[0] = self.x

    def set_x(self, x):
        self.x = x[0]

    def get_dx(self, dx):
        self.rhs_calls += 1
        dx[0] = -self.x

    def rhs(self, t, x, dx):
        self.set_time(t)
        self.set_x(x)
        self.get_dx(dx)

    def get_z(self, z):
        z[0] = self.x - 0.5

    def get_nominals(self, x):
        x[0] = 1.0


@pytest.mark.parametrize("solver", SOLVERS)
def test_state_event_located_and_state_exact(solver):
    m = Decay()
    integ = make_integrator(solver, m, 0.0, RTOL, math.inf)
    t, event = integ.advance(1.0)
    assert event, f"{solver}: no state event found before t = 1 (x(1) = {math.exp(-1):.3f} < 0.5)"
    assert abs(t - math.log(2)) <= ROOT_ATOL, f"{solver}: root at {t!r}, expected ln 2 = {math.log(2)!r}"
    assert m.t == t and abs(m.x - 0.5) <= 1e-9, f"{solver}: model left at t = {m.t}, x = {m.x}"
    integ.reset(t)  # as after the event
    t2, event2 = integ.advance(2.0)
    assert t2 == 2.0 and not event2, f"{solver}: reached {t2}, event {event2}"
    assert abs(m.x - math.exp(-2)) <= 1e-8, f"{solver}: x(2) = {m.x!r} vs e^-2 = {math.exp(-2)!r}"


@pytest.mark.parametrize("solver", SOLVERS)
def test_max_step_bounds_the_internal_steps(solver):
    free, bounded = Decay(x0=10.0), Decay(x0=10.0)
    for model, max_step in ((free, math.inf), (bounded, 1e-2)):
        integ = make_integrator(solver, model, 0.0, 1e-6, max_step)
        t, _ = integ.advance(1.0)
        assert t == 1.0, f"{solver}: stopped at {t} (no root: x stays above 0.5 until t = ln 20)"
    # at least one right-hand side per bounded step; unbounded, a smooth decay needs far fewer
    assert bounded.rhs_calls >= 100 > free.rhs_calls, \
        f"{solver}: {bounded.rhs_calls} RHS calls with max_step 0.01 vs {free.rhs_calls} without"


@pytest.mark.parametrize("solver", SOLVERS)
def test_never_steps_past_the_stop_time(solver):
    m = Decay(x0=10.0)
    integ = make_integrator(solver, m, 0.0, RTOL, math.inf)
    seen = []
    original = m.set_time
    m.set_time = lambda t: (seen.append(t), original(t))
    t, _ = integ.advance(0.25)
    assert t == 0.25 and max(seen) <= 0.25, f"{solver}: reached {t}, evaluated up to {max(seen)}"


class Blowup(Decay):
    """x' = x^2 from x0 = 1: x = 1 / (1 - t) leaves every bound before t = 1."""

    nz = 0

    def get_dx(self, dx):
        self.rhs_calls += 1
        dx[0] = self.x * self.x


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_diverging_model_fails_with_a_reason_instead_of_stalling(solver):
    from cosim.fmi.integrators import IntegratorError

    integ = make_integrator(solver, Blowup(), 0.0, 1e-8, math.inf)
    with pytest.raises(IntegratorError) as err:
        integ.advance(2.0)
    assert solver.upper()[:3] in str(err.value).upper(), f"{solver}: {err.value}"
