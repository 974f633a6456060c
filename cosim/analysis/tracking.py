"""What a run tracked, read from its log: the compared signals (the ``compare`` section of the scenario attached to
the log, ``plant.p`` vs ``traj.p_ref`` when there is none) actual vs reference at the stamps both carry, their
velocities when logged, the joints and the efforts (:func:`tracking`); reports and the controller table are made
from it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..engine.bounded_yaml import load_yaml
from ..engine.names import expand_signal
from ..engine.schema import Compare
from ..engine.structure import DOCUMENT_ATTACHMENT
from ..errors import CosimError
from ..io.runlog import AXES, RunLog, read_run
from ..observers.stats import ErrorStats

__all__ = ["JOINTS", "Pair", "ReportError", "Tracking", "scenario_doc", "tracking"]

_DEFAULT_ACTUAL, _DEFAULT_REFERENCE = "plant.p", "traj.p_ref"
JOINTS = ["q[1]", "q[2]", "q[3]"]


class ReportError(CosimError, ValueError):
    """A run log cannot be reported on: a signal is missing, or the log holds no samples of it."""


# --------------------------------------------------------------------------- data


def _stats(axes: Sequence[str], actual: Sequence[str], reference: Sequence[str], unit: str, t: np.ndarray,
           e: np.ndarray) -> list[ErrorStats]:
    return [ErrorStats.of(e[:, j], t, name=ax, actual=a, reference=r, unit=unit)
            for j, (ax, a, r) in enumerate(zip(axes, actual, reference))]


@dataclass(frozen=True)
class Pair:
    """Actual and reference signals on the stamps they share: t (n,) s, actual/reference (n, k)."""

    actual_names: list[str]
    reference_names: list[str]
    unit: str
    t: np.ndarray
    actual: np.ndarray
    reference: np.ndarray

    @property
    def error(self) -> np.ndarray:
        return self.actual - self.reference


@dataclass(frozen=True)
class Tracking:
    """What a run tracked: position (and velocity when logged) actual vs reference, and the efforts."""

    run: RunLog
    source: str  # where the signal names came from
    axes: list[str]  # "x", "y", "z" (or the signal names when they are not a platform vector)
    position: Pair
    velocity: Pair | None
    efforts: tuple[list[str], str, np.ndarray, np.ndarray] | None  # names, unit, t (n,), values (n, k)
    joints: Pair | None = None  # joint positions q[1..3] vs their references q_ref[1..3]

    @property
    def is_platform(self) -> bool:
        return self.axes == list(AXES)

    def position_stats(self) -> list[ErrorStats]:
        p = self.position
        return _stats(self.axes, p.actual_names, p.reference_names, p.unit, p.t, p.error)

    def velocity_stats(self) -> list[ErrorStats]:
        v = self.velocity
        return [] if v is None else _stats(self.axes, v.actual_names, v.reference_names, v.unit, v.t, v.error)

    def joint_stats(self) -> list[ErrorStats]:
        q = self.joints
        return [] if q is None else _stats(JOINTS, q.actual_names, q.reference_names, q.unit, q.t, q.error)


def scenario_doc(run: RunLog) -> tuple[str | None, dict]:
    """The scenario the run ran (name of its attachment, mapping), or (None, {}): the scenario as run (its
    ``effective/scenario.json``: overrides applied, and the only readable one of a run from an SSP archive,
    whose ``scenario/`` attachment is the archive), else the attached scenario file."""
    import yaml  # lazy: --help loads this module without it

    names = [n for n in run.attachments if n == DOCUMENT_ATTACHMENT]
    names += [n for n in run.attachments if n.startswith("scenario/") and not n.lower().endswith(".ssp")]
    for name in names:
        try:
            doc = load_yaml(run.attachments[name])[0]
        except yaml.YAMLError as exc:
            why = " ".join(str(exc).split())
            # Refused (correctness): the scenario as run cannot be read: which signals to compare is a guess
            raise ReportError(f"{run.path}: attachment {name} is not valid YAML ({why})") from None
        return name, doc if isinstance(doc, dict) else {}
    return None, {}


def _compare_spec(run: RunLog) -> tuple[list[str], list[str], str]:
    from pydantic import ValidationError  # lazy: --help loads this module without it


    att, doc = scenario_doc(run)
    section = doc.get("compare")
    if section is None:
        why = f"no compare section in {att}" if att else "no scenario attached"
        return (expand_signal(_DEFAULT_ACTUAL), expand_signal(_DEFAULT_REFERENCE),
                f"default {_DEFAULT_ACTUAL} vs {_DEFAULT_REFERENCE} ({why})")
    try:
        cmp = Compare.model_validate(section)
    except ValidationError as exc:
        # Refused (correctness): the compare section cannot be read: which signals to compare is a guess
        raise ReportError(f"{run.path}: the compare section of {att} is invalid: "
                          f"{exc.errors()[0]['msg']}") from None
    actual, reference = expand_signal(cmp.actual), expand_signal(cmp.reference)
    if len(actual) != len(reference):
        # Refused (correctness): signals that do not pair: which is compared with which is a guess
        raise ReportError(f"{run.path}: the compare section of {att} pairs {len(actual)} actual signals with "
                          f"{len(reference)} reference signals")
    return actual, reference, f"compare section of {att}"


def _get(run: RunLog, name: str, role: str, source: str):
    if name not in run:
        try:
            run.signal(name)
        except CosimError as exc:
            # Refused (correctness): a signal the log does not hold
            raise ReportError(f"{exc} (the {role} signal, from the {source})") from None
    return run.signals[name]


def _pair(run: RunLog, actual: list[str], reference: list[str], source: str) -> Pair:
    a = [_get(run, n, "actual", source) for n in actual]
    r = [_get(run, n, "reference", source) for n in reference]
    stamps = a[0].t_ns
    for s in a[1:] + r:
        stamps = np.intersect1d(stamps, s.t_ns, assume_unique=True)
    if stamps.size == 0:
        # Refused (correctness): no common stamps: values would have to be interpolated
        raise ReportError(f"{run.path}: {actual[0]} and {reference[0]} share no time stamp")

    def on_stamps(s) -> np.ndarray:
        return s.y[np.searchsorted(s.t_ns, stamps)]

    units = {s.unit for s in a + r}
    return Pair(actual, reference, a[0].unit if len(units) == 1 else "", stamps * 1e-9,
                 np.column_stack([on_stamps(s) for s in a]), np.column_stack([on_stamps(s) for s in r]))


def _velocity_name(name: str) -> str | None:
    """``plant.p.x`` -> ``plant.v.x``, ``traj.p_ref.x`` -> ``traj.v_ref.x``; other names have none."""
    comp, _, var = name.partition(".")
    head, _, axis = var.rpartition(".")
    if head in ("p", "p_ref") and axis in AXES:
        return f"{comp}.{'v' + head[1:]}.{axis}"
    return None


def _efforts(run: RunLog, actual_component: str):
    """The efforts the plant received (``<plant>.u[i]``), else a controller's ``u[i]`` output."""
    candidates = [actual_component] + [n.split(".", 1)[0] for n in run.find("u[1]")
                                       if run.signals[n].causality == "output"]
    for comp in dict.fromkeys(candidates):
        names = [f"{comp}.u[{i}]" for i in range(1, 4)]
        if all(n in run for n in names):
            parts = [run.signals[n] for n in names]
            if all(np.array_equal(p.t_ns, parts[0].t_ns) for p in parts):
                return names, parts[0].unit, parts[0].t, np.column_stack([p.y for p in parts])
    return None


def _joints(run: RunLog, actual_component: str) -> Pair | None:
    """The plant's joint positions ``q[1..3]`` against their references ``q_ref[1..3]``.

    The reference is the component that outputs ``q_ref`` (the inverse kinematics), else one
    that receives it (the controller's input); None when the log has no such signals.
    """
    actual = [f"{actual_component}.{q}" for q in JOINTS]
    if not all(n in run for n in actual):
        return None
    candidates = sorted(run.find("q_ref[1]"), key=lambda n: run.signals[n].causality != "output")
    for name in candidates:
        reference = [f"{name.split('.', 1)[0]}.q_ref[{i}]" for i in range(1, 4)]
        if all(n in run for n in reference):
            return _pair(run, actual, reference, "joint signals")
    return None


def tracking(run: RunLog | str | Path) -> Tracking:
    """The signals a report shows, aligned in time. Raises ReportError naming the file and a missing signal."""
    run = run if isinstance(run, RunLog) else read_run(run)
    actual, reference, source = _compare_spec(run)
    position = _pair(run, actual, reference, source)
    axes = [n.rpartition(".")[2] for n in actual]
    if axes != list(AXES):
        axes = list(actual)
    v_act, v_ref = [_velocity_name(n) for n in actual], [_velocity_name(n) for n in reference]
    velocity = None
    if all(v_act + v_ref) and all(n in run for n in v_act + v_ref):
        velocity = _pair(run, v_act, v_ref, "velocity of the compared signals")
    comp = actual[0].split(".", 1)[0]
    return Tracking(run, source, axes, position, velocity, _efforts(run, comp), _joints(run, comp))
