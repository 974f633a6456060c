"""Microseconds per call of the analytic model and the CTC law (measurements, no assertions).

Run: ``python benchmarks/analytic_model.py``.
"""

from __future__ import annotations

import timeit

import numpy as np

from delta.closed_loop import simulate
from delta.control import default_controller
from delta.dynamics import analytic_model, joint_references
from delta.robots import linear_delta_thesis, rotary_delta_prototype
from delta.trajectories import Helix


def _per_call_us(fn, number: int = 2000) -> float:
    return min(timeit.repeat(fn, number=number, repeat=5)) / number * 1e6


def main() -> None:
    helix = Helix()
    times = np.linspace(0.0, 10.0, 64)
    for robot in (linear_delta_thesis, rotary_delta_prototype):
        model = analytic_model(robot)
        q, qd, qdd = joint_references(model, *helix.sample(times))
        ctc = default_controller("ctc", robot, model)
        f = model.inverse_dynamics(q[0], qd[0], qdd[0])
        state = {"k": 0}

        def next_q():
            state["k"] = (state["k"] + 1) % len(q)
            return state["k"]

        # Fresh q on every call (no FK cache hit), as in a running loop.
        inv = _per_call_us(lambda: model.inverse_dynamics(q[next_q()], qd[0], qdd[0]))
        fwd = _per_call_us(lambda: model.forward_dynamics(q[next_q()], qd[0], f))
        ctc_us = _per_call_us(lambda: ctc.step(q[next_q()], qd[0], q[0], qd[0], qdd[0]))
        cached = _per_call_us(lambda: model.inverse_dynamics(q[0], qd[0], qdd[0]))
        print(f"{robot.name}: inverse_dynamics {inv:.1f} us (FK cached: {cached:.1f} us), "
              f"forward_dynamics {fwd:.1f} us, CTC.step {ctc_us:.1f} us")
        t0 = timeit.default_timer()
        simulate(robot, model, helix, ctc, 10.0)
        wall = timeit.default_timer() - t0
        print(f"{robot.name}: 10 s closed loop (CTC, h = 1 ms, RK4) in {wall:.2f} s wall, "
              f"{wall / 10.0:.2f}x real time")


if __name__ == "__main__":
    main()
