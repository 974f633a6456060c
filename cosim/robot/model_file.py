"""Identified model files: the analytic model's parameters that ``python -m cosim validate-model --out`` fitted.

A YAML file with the robot preset, the motions the parameters were fitted on, the parameters by FMU name
(``model.w_inertia``, ``model.w_gravity``, ``model.w_rotation``) and their fit figures (relative RMS and peak effort error per
motion, at the fitted split and at the default one). A scenario names it with ``model:`` and every
model-based component of ours (controllers that declare the parameters, the analytic plants) takes its
start values from it (:func:`model_start_values`, applied by the robot layer's pre-flight, :func:`cosim.robot.preflight.prepare`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from ..errors import Issue, ScenarioError, file_problem, written_by_rename
from ..engine.bounded_yaml import load_yaml
from ..engine.structure import SystemStructure

__all__ = ["FORMAT", "PARAMETERS", "ModelFile", "read_model_file", "write_model_file", "model_start_values",
           "system_model", "model_based"]

FORMAT = "cosim-identified-model/1"
MAX_MODEL_BYTES = 64 * 2 ** 10
"""Bytes an identified model file may hold (the ones ``validate-model`` writes hold about 1 kB)."""
PARAMETERS = ("model.w_inertia", "model.w_gravity", "model.w_rotation")
"""The FMU parameters an identified model may set: the leg mass split of the analytic model and the share of the
rods' rotational inertia (shares in [0, 1], see :mod:`delta.dynamics`)."""

# what the model is used by: our FMUs of these (role, variant); the Exudyn plant is the machine it was fitted to
_MODEL_BASED = (("controller", None), ("plant", "analytic"), ("plant", "analytic_me"))


@dataclass(frozen=True)
class ModelFile:
    """An identified model read from ``path``: ``robot`` preset, ``parameters`` by FMU name, the rest as written."""

    path: str
    robot: str
    parameters: dict[str, float]
    fitted_on: dict[str, Any]
    fit: dict[str, Any]


def _fail(path: str, message: str) -> ScenarioError:
    return ScenarioError(Issue("model", f"identified model {path}: {message} (write one with "
                                        f"`python -m cosim validate-model --robot PRESET --out FILE`)"))


def read_model_file(path: str | Path) -> ModelFile:
    """Read and check an identified model file; :class:`ScenarioError` naming the file and what is wrong."""
    path = str(path)
    problem = file_problem(path)
    if problem is not None:
        raise _fail(path, problem)
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_MODEL_BYTES + 1)  # bounded: a model file is outside input
    except OSError as exc:
        raise _fail(path, f"cannot read: {exc.strerror}") from None
    if len(raw) > MAX_MODEL_BYTES:
        raise _fail(path, f"larger than {MAX_MODEL_BYTES // 2 ** 10} kB, more than any identified model holds "
                          "(a few hundred bytes): refused unread")
    try:
        data = load_yaml(raw.decode("utf-8"))[0]  # bounded in what it expands to, too
    except (UnicodeDecodeError, yaml.YAMLError) as exc:
        raise _fail(path, f"not a YAML file: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise _fail(path, f"format must be {FORMAT!r}")
    robot, params = data.get("robot"), data.get("parameters")
    if not isinstance(robot, str):
        raise _fail(path, "robot must be a preset name")
    if not isinstance(params, dict) or not params:
        raise _fail(path, f"parameters must map some of {', '.join(PARAMETERS)} to values")
    for name, value in params.items():
        if name not in PARAMETERS:
            raise _fail(path, f"unknown parameter {name!r}; valid: {', '.join(PARAMETERS)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
            raise _fail(path, f"{name} must be a number in [0, 1], got {value!r}")
    return ModelFile(path, robot, {k: float(v) for k, v in params.items()}, dict(data.get("fitted_on") or {}),
                     dict(data.get("fit") or {}))


def write_model_file(path: str | Path, robot: str, parameters: dict[str, float], fitted_on: dict[str, Any],
                     fit: dict[str, Any], command: str) -> None:
    """Write an identified model atomically (a temporary file in the same folder, then renamed over ``path``),
    ``command`` in its header comment. Raises ``OSError`` when the folder cannot be written."""
    path = Path(path)
    body = {"format": FORMAT, "robot": robot, "fitted_on": fitted_on,
            "parameters": {k: float(v) for k, v in parameters.items()}, "fit": fit}
    for name, value in body["parameters"].items():
        if name not in PARAMETERS or not math.isfinite(value):
            raise ValueError(f"cannot write {name} = {value}")
    text = (f"# Identified model of {robot}: the analytic model's leg mass split fitted to the Exudyn plant.\n"
            f"# Written by: {command}\n# Scenarios use it with the top-level key  model: <path to this file>\n"
            + yaml.safe_dump(body, sort_keys=False, default_flow_style=False))
    with written_by_rename(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def model_based(entry: Any) -> bool:
    """Whether our FMU ``entry`` (:class:`fmus.definition.FmuDefinition`) computes with the analytic model."""
    return any(entry.role == role and (variant is None or entry.variant == variant) for role, variant in _MODEL_BASED)


def model_start_values(model: ModelFile, variables: Any) -> dict[str, float]:
    """The identified parameters that an FMU with ``variables`` (names) declares."""
    return {name: value for name, value in model.parameters.items() if name in variables}


def system_model(system: SystemStructure) -> ModelFile | None:
    """The identified model ``system``'s ``model`` section names, its path relative to the system's source file;
    read once per system (kept in its :attr:`~cosim.engine.structure.SystemStructure.made`); None without the
    section. Raises :class:`ScenarioError`."""
    name = system.domain.get("model")
    if name is None:
        return None
    if "model_file" not in system.made:
        path = Path(name)
        if not path.is_absolute() and system.source and system.source != "<string>":
            path = Path(system.source).parent / path
        system.made["model_file"] = read_model_file(path)
    return system.made["model_file"]
