"""A recording as a component of a run: ``components: meas: {recording: FILE, signals: {q[1]: SPEC, ...}}``.

The recorded signals are replayed as outputs, so that a recorded command or trajectory drives FMUs through the
scenario's ``connections:``, and a recorded joint state is logged beside the simulated one (``compare``, ``table``,
``report`` and the live view see it as any component's output). The component has outputs only: its step moves
its clock, and its outputs are the recording sampled at the communication point reached, ``t + offset``
(``linear`` between samples, or ``hold``: the last sample at or before it, a sample stamped within half a
nanosecond after it counting as at it: run and recording times are both whole nanoseconds made seconds).

Made before the run (:func:`recording_info`, published to the engine in the ``cosim.recordings`` entry point
group, :func:`cosim.engine.plugins.recording_source`): the file read once, each output's unit taken from the
recording (or ``units:``), and the recording's time range checked to cover the run's (offset applied). Every
problem is one line (:class:`~cosim.errors.CosimError`), which the engine places at the scenario's file, line and
component.
"""

from __future__ import annotations

import ctypes
from fractions import Fraction
from dataclasses import dataclass, field
from html import escape
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from ...engine.structure import Replay
from ...errors import CosimError
from ...fmi import REAL, Variable
from ...fmi.slave import ComponentState
from .recording import Recording, read_recording

__all__ = ["RecordingInfo", "RecordingSlave", "recording_info"]

def quoteattr(text: str) -> str:
    """``text`` as an XML attribute value, quoted (xml.sax.saxutils imports urllib and ssl: 50 ms a start)."""
    return f'"{escape(text, quote=True)}"'


GENERATOR = "cosim recording"
"""``md.generationTool`` of a recording component: not an FMU (the parallel offload leaves it in the master)."""
SPAN_SLACK_S = 1e-9  # run and recording times are whole nanoseconds: a run within 1 ns of the span is inside it
HOLD_SLACK_S = 0.5e-9  # a sample stamped within half a nanosecond after t is the sample at t (rounding of t + offset)
BLOCK = 256  # communication points sampled ahead at once


@dataclass(frozen=True)
class RecordingInfo:
    """What the plan and the log read of a recording component, as of an FMU's description: ``variables`` (its
    outputs, Real), ``feedthrough`` (none: no inputs), ``path`` (the recording), ``md`` (what is read of an FMU's
    model description: ``modelName`` 'recording', ``generationTool``, an empty ``guid``); and ``slave(name)``, the
    object the execution steps."""

    path: Path
    recording: Recording
    replay: Replay
    variables: dict[str, Variable]
    offset_s: float  # the offset on the recording's times as read (from its first message): the replay's, or with
    # time_origin 'absolute' the replay's less the first message's stamp
    md: Any = field(default_factory=lambda: SimpleNamespace(
        modelName="recording", generationTool=GENERATOR, guid="", fmiVersion="", unitDefinitions=[],
        defaultExperiment=None, coSimulation=None, modelExchange=None))
    feedthrough: dict[str, list[str] | None] = field(default_factory=dict)
    ambiguous: dict[str, tuple[int, ...]] = field(default_factory=dict)  # none: the outputs are a mapping's keys
    shared: dict[str, str] = field(default_factory=dict)  # none: no value references
    notes: tuple[str, ...] = ()  # nothing read leniently
    interfaces: tuple[str, ...] = ("cs",)

    def structural_parameters(self) -> dict:
        return {}

    def model_description_xml(self) -> bytes:
        """The run log's description of this component (attached as an FMU's modelDescription.xml would be): the
        file, how it is replayed and each output's spec and unit. Not an FMI model description."""
        r = self.replay
        rows = "".join(f"  <Signal name={quoteattr(n)} spec={quoteattr(s)} "
                       f"unit={quoteattr(self.variables[n].unit or '')}/>\n" for n, s in r.signals)
        return (f'<?xml version="1.0" encoding="UTF-8"?>\n<cosimRecording file={quoteattr(str(self.path))} '
                f'kind={quoteattr(self.recording.kind)} interpolation={quoteattr(r.interpolation)} '
                f'offset_s="{r.offset_s!r}" time={quoteattr(r.time)} time_origin={quoteattr(r.time_origin)}>\n'
                f'{rows}</cosimRecording>\n').encode()

    def slave(self, name: str) -> "RecordingSlave":
        return RecordingSlave(name, self)


def recording_info(name: str, replay: Replay, base: Path, span: tuple[float, float]) -> RecordingInfo:
    """Read ``replay``'s file (relative to ``base``) and check it covers the run's ``span`` (start, stop) s, offset
    applied. Raises a one-line :class:`~cosim.errors.CosimError` (file missing, a spec or unit the reader refuses,
    a time range too short)."""
    path = Path(replay.file)
    path = path if path.is_absolute() else base / path
    if not path.exists():
        # Refused (correctness): no recording, nothing to replay
        raise CosimError(f"recording file not found: {path}")
    specs = dict(replay.signals)
    rec = read_recording(path, specs, time=replay.time, units=dict(replay.units))  # from its first message: its
    # times keep their nanoseconds, which absolute stamps (1.7e9 s, a double's step 0.24 us) would round
    absolute = replay.time_origin == "absolute"
    offset = float(Fraction(replay.offset_s) - Fraction(rec.origin_ns, 10 ** 9)) if absolute else \
        replay.offset_s  # exact, then rounded once
    lo = max(rec.times[n][0] for n in specs)
    hi = min(rec.times[n][-1] for n in specs)
    start, stop = (t + offset for t in span)
    if start < lo - SPAN_SLACK_S or stop > hi + SPAN_SLACK_S:
        if absolute:  # the ranges in the recording's stamps, s since the epoch: to the microsecond
            shift = rec.origin_ns * 1e-9
            covers = f"stamps {lo + shift:.6f} .. {hi + shift:.6f} s (time_origin absolute)"
            needs = f"{start + shift:.6f} .. {stop + shift:.6f} s with offset {replay.offset_s:.6f} s"
        else:
            covers, needs = f"t = {lo:.9g} .. {hi:.9g} s (its time, from its first message)", \
                f"{start:.9g} .. {stop:.9g} s with offset {replay.offset_s:g} s"
        # Refused (correctness): past its ends the replayed values would be made up
        raise CosimError(f"recording {path} covers {covers}, the run t = {span[0]:.9g} .. {span[1]:.9g} s needs "
                         f"{needs}" + (f" ({rec.end_note})" if rec.end_note else ""))
    variables = {}
    for k, (out, spec) in enumerate(replay.signals):
        variables[out] = Variable(name=out, vr=k, kind=REAL, fmi_type="Real", causality="output",
                                  variability="continuous" if replay.interpolation == "linear" else "discrete",
                                  unit=rec.units[out] or None, description=f"recorded {spec} ({path.name})",
                                  start=None, index=k + 1)
    return RecordingInfo(path, rec, replay, variables, offset)


class RecordingSlave:
    """A recording replayed as a co-simulation slave with outputs only (the :class:`cosim.fmi.Slave` protocol the
    execution's Python path steps): its step moves its clock, its outputs are the recording at the time reached."""

    model_exchange = False
    events = 0
    can_save_state = True  # its state is its clock and its outputs
    can_serialize_state = False  # a checkpoint file holds FMU states: not this

    def __init__(self, name: str, info: RecordingInfo):
        self.name = name
        self.info = info
        self.time = 0.0
        self._offset = info.offset_s
        self._hold = info.replay.interpolation == "hold"
        self._out: list[str] = []
        self.out_values: Any = (ctypes.c_double * 1)()
        self.in_values: Any = (ctypes.c_double * 1)()
        self._view = np.zeros(0)
        self._step_ns = 0  # the last step, ns: the spacing of the block of samples ahead
        self._block_ns = np.zeros(0, dtype=np.int64)  # the communication points sampled ahead, ns
        self._block = np.zeros((0, 0))  # their outputs, one row each

    def bind(self, inputs: list[Variable], outputs: list[Variable]) -> None:
        if inputs:
            # Refused (correctness): a connection into a replay would be dropped silently
            raise CosimError(f"component {self.name!r} replays a recording: it has no inputs "
                             f"({', '.join(v.name for v in inputs)})")
        self._out = [v.name for v in outputs]
        self.out_values = (ctypes.c_double * max(1, len(outputs)))()
        self._view = np.ctypeslib.as_array(self.out_values)[:len(outputs)]

    def locate(self, var: Variable, output: bool = True) -> tuple[Any, int]:
        return self.out_values, self._out.index(var.name)

    def instantiate(self) -> None: ...
    def setup_experiment(self, start: float, stop: float) -> None: ...
    def set_start(self, values: dict[str, Any]) -> None: ...
    def exit_initialization(self) -> None: ...
    def set_inputs(self) -> None: ...
    def terminate(self) -> None: ...
    def free(self) -> None: ...

    def enter_initialization(self, start: float, stop: float) -> None:
        self.time = start
        self.get_outputs()

    def step(self, t: float, h: float) -> None:
        self.time = t + h
        self._step_ns = round(h * 1e9)

    def get_outputs(self) -> None:
        """The outputs at :attr:`time`: a row of the samples taken ahead, else a new block of :data:`BLOCK` of them
        from here, spaced by the last step (the reader's :meth:`~.recording.Recording.sample` once per output and
        block: 20-30 us a call, where a step of a compiled FMU costs one)."""
        t_ns = round(self.time * 1e9)  # a communication point is the double of a whole number of ns (engine.grid)
        j = (t_ns - self._block_ns[0]) // self._step_ns if len(self._block_ns) and self._step_ns else -1
        if not (0 <= j < len(self._block_ns) and self._block_ns[j] == t_ns):
            self._sample_from(t_ns)
            j = 0
        self._view[:] = self._block[j]

    def _sample_from(self, t_ns: int) -> None:
        n = BLOCK if self._step_ns else 1
        self._block_ns = t_ns + self._step_ns * np.arange(n, dtype=np.int64)
        t = self._block_ns / 1e9 + self._offset  # each the double the grid gives (a correctly rounded division)
        if self._hold:
            t = t + HOLD_SLACK_S
        how = "hold" if self._hold else "linear"
        rec = self.info.recording
        self._block = np.column_stack([rec.sample(name, t, how) for name in self._out]) if self._out else \
            np.zeros((n, 0))

    def set_step_get(self, t: float, h: float) -> None:
        self.step(t, h)
        self.get_outputs()

    # -- state: the clock and the outputs (an event's restore and re-step)
    def save_state(self, into: ComponentState | None = None) -> ComponentState:
        buffers = [bytes(self.out_values)]
        if into is None:
            return ComponentState(None, self.time, buffers, {})
        into.time, into.buffers = self.time, buffers
        return into

    def restore_state(self, state: ComponentState) -> None:
        self.time = state.time
        ctypes.memmove(self.out_values, state.buffers[0], len(state.buffers[0]))

    def free_state(self, state: ComponentState) -> None: ...

    def set_values(self, values: dict) -> None:
        # Refused (correctness): a value set on a replay would be dropped silently
        raise CosimError(f"component {self.name!r} replays a recording: its outputs cannot be set "
                         f"({', '.join(v.name for v in values)})")

