"""Runs that end early, shared by the tests that hold two ways of stepping to the same ending (the turn in C
against the Python calls, the loop in C against the Python loop): the cases, how a run's ending is summed up,
and the error each case must end with."""

from __future__ import annotations

from typing import Any, Callable

from cosim.errors import FMIError

# what, {component: (test FMU, FMI version, parameters)}, connections, stop time, step
ENDING_CASES = [
    ("rejected step, FMI 2", {"st": ("Stair", 2, {"t_reject": 0.55})}, [], 1.0, 0.1),
    ("rejected step, FMI 3", {"st": ("Stair", 3, {"t_reject": 0.55})}, [], 1.0, 0.1),
    ("termination, FMI 2", {"st": ("Stair", 2, {"t_terminate": 0.35})}, [], 1.0, 0.1),
    ("termination, FMI 3", {"st": ("Stair", 3, {"t_terminate": 0.35})}, [], 1.0, 0.1),
    ("non-finite output", {"osc": ("VanDerPol", 2, {"mu": 1e6}), "a": ("Feedthrough", 2, {})},
     [("osc.x0", "a.Real_input")], 1.0, 1e-3),
]


def ending(run: Callable[[], Any]) -> tuple:
    """(error, None) with the error's class, component, FMI function and text, or (None, the result's steps,
    time, cause and message) of ``run()``, which returns a run's result."""
    try:
        result = run()
    except FMIError as exc:
        return (type(exc).__name__, exc.component, exc.function, str(exc)), None
    return None, (result.steps, result.sim_time, result.terminated_by, result.message)


def expected_error(what: str) -> str | None:
    """The error class a case of :data:`ENDING_CASES` must end with (None: it ends without one)."""
    return {"rejected": "FMIError", "termination": None, "non-finite": "FMIError"}[what.split()[0].split(",")[0]]
