"""The condition of a state event, as a scenario writes it: ``SIGNAL < VALUE`` or ``SIGNAL > VALUE``.

The engine's events (:mod:`cosim.engine.events`) read it; the scenario's schema checks it when the file is read
(:mod:`cosim.engine.schema`): one reading of the syntax for both.
"""

from __future__ import annotations

import math
import re

from ..errors import shown

__all__ = ["parse_condition", "condition_issue"]

_CONDITION = re.compile(r"^\s*([^\s<>=]+)\s*([<>])\s*([^\s<>=]+)\s*$")


def parse_condition(text: str) -> tuple[str, str, float]:
    """``"SIGNAL < VALUE"`` -> (signal, "<", value); raises ValueError saying what a condition looks like."""
    m = _CONDITION.match(text)
    value = None
    if m:
        try:
            value = float(m.group(3))
        except ValueError:
            value = None
    if m is None or value is None or not math.isfinite(value):
        # Refused (correctness): a condition we cannot read: when the event fires is a guess
        raise ValueError(f"condition {shown(repr(text))} is not 'SIGNAL < VALUE' or 'SIGNAL > VALUE' (SIGNAL a "
                         "component.variable, VALUE a finite number)")
    return m.group(1), m.group(2), value


def condition_issue(text: str) -> str | None:
    """What is wrong with the condition ``text`` (:func:`parse_condition`'s message), or None."""
    try:
        parse_condition(text)
    except ValueError as exc:
        return str(exc)
    return None
