"""A sweep's cases: the cartesian product of ``--grid`` axes, times ``-n`` random draws (seeded) of the ``--random``
ones (:func:`make_cases`); names and values as ``--set`` reads them."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..engine.overrides import parse_set_value
from ..errors import CosimError
from .limits import MAX_CASES

__all__ = ["Case", "SweepError", "make_cases", "parse_grid", "parse_random"]

_RANDOM = re.compile(r"^(uniform|normal)\(\s*([^,()]+)\s*,\s*([^,()]+)\s*\)$")


class SweepError(CosimError, ValueError):
    """A bad sweep definition or output directory."""


@dataclass(frozen=True)
class Case:
    """One run: overrides by dotted name, and its id (a hash of the names and values)."""

    values: dict[str, Any]

    @property
    def id(self) -> str:
        text = json.dumps(sorted((k, repr(v)) for k, v in self.values.items()))
        return hashlib.sha256(text.encode()).hexdigest()[:12]


def _value(text: str, where: str) -> Any:

    return parse_set_value(text.strip(), where)


def _top_level_split(text: str) -> list[str]:
    """Split at commas outside brackets: ``1,[2,3],4`` -> ``["1", "[2,3]", "4"]`` (list values)."""
    parts, depth, cur = [], 0, ""
    for ch in text:
        depth += ch in "[(" and 1 or (-1 if ch in "])" else 0)
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    return parts + [cur]


def parse_grid(items: Sequence[str]) -> dict[str, list[Any]]:
    """``["ctl.gain.kp[1]=1e4,4e4"]`` -> ``{"ctl.gain.kp[1]": [1e4, 4e4]}`` (values as ``--set`` reads them;
    a list value in brackets, ``ctl.gain.kp=[1e4,1e4,1e4],[4e4,4e4,4e4]``, sets every element; names joined by
    commas, ``plant.mass.payload,ctl.mass.payload=0,0.5``, are one axis: each case sets them all to its value)."""
    out: dict[str, list[Any]] = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or not name or not values.strip():
            # Refused (correctness): a grid we cannot read: its values would be a guess
            raise SweepError(f"--grid {item}: expected NAME=V1,V2,...")
        if name in out:
            # Refused (correctness): which values are meant is a guess
            raise SweepError(f"--grid {item}: {name} is given twice")
        out[name] = [_value(v, f"--grid {item}") for v in _top_level_split(values)]
    return out


def parse_random(items: Sequence[str]) -> dict[str, tuple[str, float, float]]:
    """``["plant.mass.payload=uniform(0,0.5)"]`` -> ``{"plant.mass.payload": ("uniform", 0.0, 0.5)}``."""
    out: dict[str, tuple[str, float, float]] = {}
    for item in items:
        name, sep, dist = item.partition("=")
        m = _RANDOM.match(dist.strip())
        if not sep or not name or m is None:
            # Refused (correctness): a distribution we cannot read: the draws would be a guess
            raise SweepError(f"--random {item}: expected NAME=uniform(A,B) or NAME=normal(MU,SIGMA)")
        try:
            a, b = float(m[2]), float(m[3])
        except ValueError:
            # Refused (correctness): a distribution we cannot read: the draws would be a guess
            raise SweepError(f"--random {item}: the bounds must be numbers") from None
        if not math.isfinite(b - a):  # nan, an infinity, or a span past the largest double (-1e308, 1e308)
            # Refused (correctness): no draw from an infinite or NaN bound is a number
            raise SweepError(f"--random {item}: the bounds must be finite numbers whose difference is finite")
        if m[1] == "uniform" and not a < b:
            # Refused (correctness): no value lies between them
            raise SweepError(f"--random {item}: uniform(A,B) needs A < B")
        if m[1] == "normal" and not b >= 0:
            # Refused (correctness): no distribution has a negative spread
            raise SweepError(f"--random {item}: normal(MU,SIGMA) needs SIGMA >= 0")
        out[name] = (m[1], a, b)
    return out


def make_cases(grid: dict[str, list[Any]], random: dict[str, tuple[str, float, float]], n: int | None,
               seed: int | None) -> list[Case]:
    """Cartesian product of ``grid``, each combined with ``n`` draws of ``random`` (numpy, ``seed``)."""

    if random and not n:
        # Refused (correctness): how many draws is a guess
        raise SweepError("--random needs -n N (the number of draws)")
    if n and not random:
        # Refused (correctness): draws of nothing: -n would be dropped silently
        raise SweepError("-n needs at least one --random NAME=DIST")
    if not grid and not random:
        # Refused (correctness): nothing to run
        raise SweepError("nothing to sweep: give --grid NAME=V1,V2,... and/or --random NAME=DIST -n N")
    both = set(grid) & set(random)
    if both:
        # Refused (correctness): which values are meant is a guess
        raise SweepError(f"{', '.join(sorted(both))}: both --grid and --random")
    total = math.prod(len(v) for v in grid.values()) * (n or 1)
    if total > MAX_CASES:
        count = f"{total:,}" if total < 10 ** 15 else f"more than {10 ** 15:,}"  # exact: 1,001,000 is not 1e+06
        # Refused (security): a sweep's cases are held in memory: their number is bounded
        raise SweepError(f"the sweep has {count} cases, more than the {MAX_CASES:,} it may have: fewer grid values "
                         "or draws")
    rng = np.random.default_rng(seed)
    draws = [{name: float(rng.uniform(a, b) if kind == "uniform" else rng.normal(a, b))
              for name, (kind, a, b) in random.items()} for _ in range(n or 1)]
    axes = list(grid)
    linked = [name.strip() for axis in axes for name in axis.split(",")]
    twice = sorted({n for n in linked if linked.count(n) > 1} | (set(linked) & set(random)))
    if twice:
        # Refused (correctness): which values are meant is a guess
        raise SweepError(f"{', '.join(twice)}: set by more than one --grid or --random")
    cases = []
    for combo in itertools.product(*(grid[k] for k in axes)):
        # an axis "a,b=V1,V2" sets a and b to the same value in each case (a payload on the plant and the controller)
        values = {name.strip(): v for axis, v in zip(axes, combo) for name in axis.split(",")}
        for draw in draws:
            cases.append(Case({**values, **draw}))
    ids = [c.id for c in cases]
    if len(set(ids)) != len(ids):
        # Refused (correctness): a case run twice: its results would count twice
        raise SweepError("some cases repeat the same values (a grid value given twice?)")
    return cases
