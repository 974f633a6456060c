"""Python API: load a scenario with overrides by dotted name, run it, get metrics and signals.

>>> from cosim import api
>>> res = api.run("scenarios/helix_ctc_analytic.yaml",
...               {"time.stop": 0.2, "trajectory.params.rx": 0.05, "ctl.gain.kp[1]": 2.0e4})  # doctest: +SKIP
>>> res.metrics["rmse_x"], res["plant.p.x"][-1]  # doctest: +SKIP

Dotted names (:func:`cosim.engine.overrides.resolve_name`) are those of ``--set`` on the command line:
``COMP.PARAM`` sets a component parameter (``ctl.gain.kp[1]``, ``plant.mass.payload``); other
names walk the scenario's sections (``time.stop``, ``time.step``, ``trajectory.params.rx``,
``algorithm``, ``parallel``). An unknown name raises :class:`~cosim.errors.ScenarioError`
(a ``ValueError``) with the close matches.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .analysis.metrics import metric_names, metrics
from .engine.execution import Execution
from .engine.overrides import dotted_overrides
from .engine.scenario import load_scenario
from .engine.schema import Scenario
from .engine.structure import SystemStructure
from .engine.system import Port
from .engine.wiring import index_text
from .errors import ScenarioError, UnknownSignalError
from .fmi import BOOLEAN, INTEGER, REAL
from .observers.recorders import PeakEffort
from .io.checkpoint import read_checkpoint
from .io.ssp.scenario import open_ssp
from .io.ssp.spec import is_ssp
from .run import RunResult, resumed, run_scenario

__all__ = ["PeakEffort", "Result", "SignalRecorder", "load", "metric_names", "metrics", "resume", "run"]

_NUMERIC = (REAL, INTEGER, BOOLEAN)


def load(scenario: str | Path | Scenario, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """The scenario at ``scenario`` (a YAML path), validated, with ``overrides`` applied.

    Parameters
    ----------
    scenario : path of a scenario file (a :class:`Scenario` is returned as is when there are no overrides)
    overrides : {dotted name: value}, e.g. ``{"trajectory.params.rx": 0.05, "time.stop": 0.5,
        "ctl.gain.kp[1]": 4e4, "ctl.gain.kp": [4e4, 4e4, 4e4]}`` (a list sets ``name[1]..name[n]``)
    """
    if isinstance(scenario, Scenario):
        if not overrides:
            return scenario
        if scenario.source is None or scenario.source == "<string>":
            raise ScenarioError("overrides need the scenario's file: pass its path, not a Scenario")
        scenario = scenario.source
    return load_scenario(scenario, dotted_overrides(dict(overrides or {})))


class SignalRecorder:
    """Observer: every numeric input and output the master reads, at every macro step, by name."""

    def __init__(self) -> None:
        self.t_ns: list[int] = []
        self.names: list[str] = []
        self._rows: list[list[float]] = []

    def start(self, rt: Execution) -> None:

        self._src = []
        for c, name in enumerate(rt.plan.names):
            seen = set()
            for var in list(rt.plan.inputs[c]) + list(rt.plan.outputs[c]):
                if var.name in seen or var.kind not in _NUMERIC:
                    continue
                seen.add(var.name)
                arr, i = rt.where(Port(c, var))
                for e in range(var.count):
                    label = index_text(var, e) if var.shape else ""
                    self.names.append(f"{name}.{var.name}{label}")
                    self._src.append((arr, i + e))
        self.stepped(-1, rt.now_ns, ())  # the start, or a resumed run's checkpoint time

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        self.t_ns.append(t_ns)
        self._rows.append([arr[i] for arr, i in self._src])

    def finish(self, rt: Execution, error: BaseException | None) -> None:
        return None

    def arrays(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        table = np.asarray(self._rows, dtype=float).reshape(len(self._rows), len(self.names))
        return np.asarray(self.t_ns, dtype=np.int64) * 1e-9, {n: table[:, j] for j, n in enumerate(self.names)}


@dataclass
class Result:
    """A finished run: ``metrics`` (:func:`metrics`), ``time`` (s) and ``signals`` (name -> array,
    one value per macro step and the start), the full :class:`~cosim.run.RunResult` as ``run``."""

    run: RunResult
    metrics: dict[str, float]
    time: np.ndarray
    signals: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def status(self) -> str:
        return self.run.status

    @property
    def mcap(self) -> str | None:
        return self.run.mcap

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.signals[name]
        except KeyError:

            close = difflib.get_close_matches(name, list(self.signals), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise UnknownSignalError(f"no signal {name!r}{hint}") from None

    def to_pandas(self):
        """The signals as a pandas DataFrame indexed by time in s (needs pandas, not a dependency)."""
        try:
            import pandas as pd  # optional: pandas is not a dependency
        except ImportError:
            raise ImportError("Result.to_pandas needs pandas: pip install pandas") from None
        return pd.DataFrame(self.signals, index=pd.Index(self.time, name="t"))


def run(scenario: str | Path | Scenario | SystemStructure, overrides: Mapping[str, Any] | None = None, *,
        log: bool = False,
        out: str | Path | None = None, signals: bool = True, progress: bool = False,
        checkpoint_at: float | None = None, checkpoint_out: str | Path | None = None) -> Result:
    """Run a scenario (a YAML path or :func:`load`-ed, or an SSP archive's path) with ``overrides`` (dotted names),
    or a system structure as it is (:class:`~cosim.engine.structure.SystemStructure`: made in code, or a scenario's
    ``structure()``), and return a :class:`Result`.

    Parameters
    ----------
    log : write the MCAP log (to ``out``, else the scenario's ``logging.out``)
    signals : keep every signal in memory (every output of every component, and the connected inputs)
    progress : show the progress bar
    checkpoint_at : write a checkpoint when the run reaches this time, s (to ``checkpoint_out``, else beside the
        log with the suffix ``.ckpt``); :func:`resume` continues it

    Raises :class:`~cosim.errors.CosimError` subclasses (bad input, pre-flight, FMU failure).
    """
    options = dict(log=log, out=out, signals=signals, progress=progress, checkpoint_at=checkpoint_at,
                   checkpoint_out=checkpoint_out)
    if isinstance(scenario, SystemStructure):
        if overrides:
            raise ScenarioError("overrides need a scenario: a system structure is run as it is")
        return _run(scenario, **options)
    if isinstance(scenario, (str, Path)) and is_ssp(scenario):  # its FMUs unpacked for the run only
        with open_ssp(scenario, dotted_overrides(dict(overrides or {}))) as system:
            return _run(system, **options)
    return _run(load(scenario, overrides).structure(), **options)


def resume(checkpoint: str | Path, sets: Mapping[str, Any] | None = None, *, stop_time: float | None = None,
           log: bool = False, out: str | Path | None = None, signals: bool = True, progress: bool = False) -> Result:
    """Continue the run a checkpoint holds (``python -m cosim run --resume``) and return a :class:`Result` of the
    time after it.

    Parameters
    ----------
    checkpoint : a file written by ``run(..., checkpoint_at=T)`` or ``python -m cosim run --checkpoint-at T``
    sets : {component.variable: value} set at the checkpoint's time, as an event (tunable parameters and inputs
        no connection drives, e.g. ``{"plant.mass.payload": 0.3}``)
    stop_time : the end, s (default: the stop time of the run that wrote the checkpoint)
    log, out : write the MCAP log, to ``out`` (default: beside the checkpoint, ``<checkpoint>.resumed.mcap``)

    Raises :class:`~cosim.errors.CosimError` subclasses (a damaged checkpoint, one of another FMU build, a name
    that cannot be set during a run, ...).
    """
    ck = read_checkpoint(checkpoint)
    if log and out is None:  # as the CLI: beside the checkpoint, never over the log of the run that wrote it
        out = Path(ck.path).with_suffix(".resumed.mcap")
    with resumed(ck, stop_time) as scenario:  # a run of an SSP archive: the archive unpacked again meanwhile
        return _run(scenario, log=log, out=out, signals=signals, progress=progress, resume=ck,
                    resume_sets=dict(sets or {}))


def _run(sc: Scenario | SystemStructure, *, signals: bool, **options: Any) -> Result:
    peak = PeakEffort()
    observers: list[Any] = [peak]
    recorder = None
    if signals:
        recorder = SignalRecorder()
        observers.append(recorder)
    res = run_scenario(sc, observers=observers, read_all=signals,  # every output read each step, also without a log
                       **options)
    t, values = recorder.arrays() if recorder is not None else (np.zeros(0), {})
    return Result(res, metrics(sc, res, peak.peak), t, values)
