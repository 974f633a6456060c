"""Which variables a scenario or SSP may give start values: the FMI rule (cosim.fmi.description.settable_at_start)."""

from __future__ import annotations

import pytest

from cosim.fmi.description import REAL, Variable, initial_of, settable_at_start


def var(causality: str, variability: str, initial: str | None = None) -> Variable:
    return Variable(name="v", vr=0, kind=REAL, fmi_type="Real", causality=causality, variability=variability,
                    unit=None, description=None, start=0.0, index=1, initial=initial)


@pytest.mark.parametrize("causality, variability, initial, settable", [
    ("parameter", "fixed", None, True),           # default initial exact
    ("parameter", "tunable", "exact", True),
    ("input", "continuous", None, True),
    ("output", "continuous", "exact", True),      # FMI 2 allows it; fmpy.simulate_fmu applies it (issue 26)
    ("output", "discrete", "approx", True),
    ("local", "continuous", "exact", True),
    ("output", "continuous", None, False),        # default initial calculated
    ("output", "continuous", "calculated", False),
    ("calculatedParameter", "fixed", None, False),
    ("calculatedParameter", "fixed", "approx", True),
    ("output", "constant", "exact", False),
    ("independent", "continuous", None, False),
])
def test_the_fmi_rule_for_start_values(causality, variability, initial, settable):
    v = var(causality, variability, initial)
    assert settable_at_start(v) is settable, (causality, variability, initial, initial_of(v))
