"""What a run publishes: the channels, schemas and messages shared by the MCAP log and the live view.

A :class:`Publisher` is an observer that declares the run's channels and publishes every
exchanged signal to its sinks. Every sink receives the same channels, schemas and messages:
the MCAP file (:class:`cosim.observers.mcap_log.McapRecorder`), the Foxglove WebSocket server
(:class:`cosim.observers.live.LiveView`), or both. One formula per message, in one place: a component's
samples leave the master as blocks of rows of raw values (cheap for the master's loop), turned
into JSON messages by :func:`cosim.observers.log_writer.encode_messages` in the sink (in the log's writer
process, or for the live view).

Channels (JSON encoding, each with a titled JSON Schema):

- ``/<component>``: the component's logged variables; the schema lists each variable with unit,
  description and causality; the channel's metadata says its ``layout`` (the scenario's
  ``logging.layout``):

  - ``samples`` (default): one message per sample, ``{"t": s, "<variable>": value, ...}`` (an
    array variable's value is a list), logged at its stamp: what Foxglove and PlotJuggler plot
    as time series as they are, the messages of logs written before blocks (which have no
    ``layout`` metadata);
  - ``blocks``: one message per block of consecutive samples, ``{"t": [s, ...], "<variable>":
    [value, ...], ...}``, one array element per sample, one message per ``1 / scene_rate_hz`` of
    simulated time (sooner when a block is full) logged at its last sample's stamp; each property of the
    schema is an array of the sample's type. Cheaper to write; viewers see arrays.

  :mod:`cosim.io.runlog` reads both alike;
- ``/scene``: ``foxglove.SceneUpdate`` at ``scene_rate_hz``: the robot (rails or arms,
  rods, platform) and the platform's trail over the last ``trail_s`` seconds;
- ``/scene/reference``: ``foxglove.SceneUpdate``, the reference path as a line: the whole
  path when the scenario has a ``trajectory:`` section, else the reference signal so far;
  sent at the start and every second (a viewer that joins or seeks late still gets it);
- ``/tf``: ``foxglove.FrameTransforms`` with the scene: ``world -> base`` (identity) and
  ``base -> platform`` (the platform position);
- ``/events``: events of model-exchange components (time, component, kind).

Scene and transform messages use Foxglove's published schemas (:mod:`cosim.observers.foxglove_schemas`).

Time stamps: a message's log time is its simulation time plus :attr:`Publisher.offset_ns`:
with ``stamps="wall"`` (default) the wall clock at the run's start minus the simulated start,
so viewers show the real date; with ``stamps="simulation"`` zero. The ``"t"`` field of every
message is the simulation time in s either way, and the log's ``time`` metadata record keeps
the offset (:func:`cosim.io.runlog.time_offset_ns` reads it back; logs without it have offset 0).

Inputs are published with the value held over the step that ends at the stamp; outputs with
their value at the stamp.
"""

from __future__ import annotations

import base64
import ctypes
import time
from collections import deque
from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np
import orjson

from ..engine.cloop import Blocks, steps_to
from ..engine.execution import Execution, byte_view
from ..errors import CosimError
from ..fmi import BINARY, BOOLEAN, INTEGER, REAL, STRING
from .foxglove_schemas import FRAME_TRANSFORMS, SCENE_UPDATE
from .log_writer import BlockLayout, row_format, row_section

__all__ = [
    "EVENTS_SCHEMA",
    "LAYOUTS",
    "STAMPS",
    "Publisher",
    "frame_transforms",
    "reference_update",
    "time_metadata",
    "vec",
    "line",
    "line_of",
    "entity",
    "IDENTITY",
]

STAMPS = ("wall", "simulation")
LAYOUTS = ("samples", "blocks")
_TRAIL_S = 3.0  # s of platform trail drawn in the scene
_REFERENCE_PERIOD_NS = 1_000_000_000  # /scene/reference resent every simulated second
REFERENCE_POINTS = 600  # the whole reference path is drawn with at most this many points
_BLOCK_ROWS = 256  # samples of a component channel handed over at once, at most

_JSON_TYPE = {REAL: {"type": "number"}, INTEGER: {"type": "integer"}, BOOLEAN: {"type": "boolean"},
              STRING: {"type": "string"}, BINARY: {"type": "string", "contentEncoding": "base64"}}

EVENTS_SCHEMA = {
    "title": "cosim.Event",
    "description": "An event: one of the scenario's events that fired (event, set), or one the master handled in a "
                   "model-exchange component (component, kind: FMI event mode)",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "event time (a state event's located crossing)", "unit": "s"},
        "event": {"type": "integer", "description": "the scenario event's index in its events list, from 0 (-1: the "
                                                   "--set of a resumed run, at the checkpoint's time)"},
        "set": {"type": "object", "description": "the values the scenario event set, component.variable: value"},
        "component": {"type": "string", "description": "the model-exchange component in event mode"},
        "kind": {"type": "string", "description": "what triggered it: state, time, step or input (joined by +)"},
    },
    "required": ["t"],
}


# --------------------------------------------------------------------------- time stamps


def time_metadata(stamps: str, offset_ns: int, sim_start_ns: int) -> dict[str, str]:
    """The log's ``time`` metadata record (MCAP metadata values are strings)."""
    wall = sim_start_ns + offset_ns
    return {"stamps": stamps, "offset_ns": str(offset_ns), "sim_start_ns": str(sim_start_ns),
            "log_time_at_sim_start_ns": str(wall),
            "note": "log time = simulation time + offset_ns; the 't' field of each message is simulation time"}


# --------------------------------------------------------------------------- component channels


def _json_type(v) -> dict:
    """The JSON Schema of a logged variable's value (arrays: a flat list, row-major)."""
    item = dict(_JSON_TYPE[v.kind])
    if not v.is_array:
        return item
    return {"type": "array", "items": item, "minItems": v.count, "maxItems": v.count,
            "description": f"shape {'x'.join(map(str, v.shape))}, row-major"}


def _converter(v):
    """None when the buffer's value is already the JSON value (floats, ints, C bools), else a function."""
    if v.kind == BINARY:

        return lambda b: base64.b64encode(b).decode("ascii")
    return bool if v.kind == BOOLEAN else None  # FMI 2.0 Booleans are C ints


def _values_any(readers) -> list:
    """The logged values read one by one (components with strings or binaries). ``readers`` holds per
    variable ``(array, offset, count or None for a scalar, converter or None)``."""
    vals = []
    for arr, i, n, conv in readers:
        if n is None:
            vals.append(arr[i] if conv is None else conv(arr[i]))
        else:
            vals.append(arr[i:i + n] if conv is None else [conv(x) for x in arr[i:i + n]])
    return vals


def block_layout(keys: Sequence[str], readers, kinds: Sequence[str], per_sample: bool = False):
    """``(BlockLayout, runs)`` of a component channel: ``runs`` (``(array, offset, count)`` per stretch of
    consecutive elements of one ctypes array, in row order; a row is their bytes one after the other)
    when every value lives in a ctypes array (numbers, Booleans), else None (values read one by one).
    ``keys``: one JSON key per reader; ``per_sample``: the channel's layout is ``samples``."""

    if any(kind not in (REAL, INTEGER, BOOLEAN) for kind in kinds) or any(
            not isinstance(getattr(arr, "_type_", None), type) or n == 0 for arr, _, n, _ in readers):
        return BlockLayout(tuple(keys), per_sample=per_sample), None
    runs: list[list] = []
    fmt, columns = [], []
    at = 0
    for (arr, i, n, _), kind in zip(readers, kinds):
        count = 1 if n is None else n
        if runs and runs[-1][0] is arr and runs[-1][1] + runs[-1][2] == i:
            runs[-1][2] += count
        else:
            runs.append([arr, i, count])
        fmt.append(row_format(arr._type_, count))
        columns.append((at, 0 if n is None else n, kind == BOOLEAN and arr._type_ is not ctypes.c_bool))
        at += count
    return BlockLayout(tuple(keys), "".join(fmt), tuple(columns), per_sample), [tuple(r) for r in runs]


class _Rows:
    """A component channel's samples not yet handed to the sinks: their stamps, and their values as
    rows of bytes copied from the FMU buffers (``runs``, see :func:`block_layout`) or, without runs,
    as lists (``readers``, see :func:`_values_any`)."""

    __slots__ = ("cid", "cap", "capture", "stamps", "data", "raw", "runs", "sources", "width", "puts")

    def __init__(self, cid: int, runs, readers, block_bytes: int):

        self.cid = cid
        self.stamps: list[int] = []
        self.data: list = []
        self.raw = runs is not None
        self.runs = runs
        self.sources = None
        self.width: int | None = None  # bytes of a row; None: rows of values (not raw)
        self.puts: tuple = ()  # each mirror's put of a row, when its rows are a batch mirrored (Publisher.start)
        if runs is None:
            self.capture = partial(_values_any, readers)
            self.cap = _BLOCK_ROWS
        else:  # one join per sample: the runs' bytes in one new bytes object
            self.sources = [byte_view(arr, i, n) for arr, i, n in runs]
            self.capture = partial(b"".join, self.sources)
            self.width = sum(len(v) for v in self.sources)
            self.cap = max(1, min(_BLOCK_ROWS, block_bytes // max(1, self.width)))

    @property
    def parts(self) -> list[tuple[int, int, int | None]]:
        """Its channel's place in a row (as :attr:`_Joint.parts`): all of it."""
        return [(self.cid, 0, self.width)]

    def take(self) -> tuple[int, list[int], bytes | list, None]:
        """The block so far; the lists are emptied in place (the publisher holds their ``append``)."""
        block = (self.cid, self.stamps[:], b"".join(self.data) if self.raw else self.data[:], None)
        self.stamps.clear()
        self.data.clear()
        return block


class _Joint:
    """The samples of every logged component at once, when all of them step at every macro step and log
    numbers only (the common case): one join per step for all their rows, handed over as one block
    of bytes that each channel reads between the others' values (``skip``).

    The rows and their stamps are held in :attr:`area` (a section of the writer's
    :class:`~cosim.observers.log_writer.RowMirror`, else memory of its own,
    :func:`~cosim.observers.log_writer.row_section`), written by :meth:`put` or by the master's loop in C
    (:attr:`copies`: per stretch of the row, its byte offset in the row, the FMU buffer's address and bytes)."""

    def __init__(self, channels: list[_Rows], block_bytes: int):
        self.parts = []  # (channel, byte offset in the joint row, bytes)
        self.copies = []
        sources, at = [], 0
        for rows in channels:
            self.parts.append((rows.cid, at, rows.width))
            sources += rows.sources
            for (arr, i, n), view in zip(rows.runs, rows.sources):
                size = ctypes.sizeof(arr._type_)
                self.copies.append((at, ctypes.addressof(arr) + i * size, n * size))
                at += len(view)
        self.width = at
        self.capture = partial(b"".join, sources)
        self.cap = max(1, min(_BLOCK_ROWS, block_bytes // max(1, at)))
        self.area: Any = None  # the rows held (Publisher.start)
        self.puts: tuple = ()  # every other mirror's put of a row (see Publisher.start)

    @property
    def held(self) -> bool:
        """Whether rows are held."""
        return self.area.count > 0

    def put(self, stamp: int, row: bytes) -> None:
        self.area.put(stamp, row)
        for put in self.puts:
            put(stamp, row)

    def take(self) -> list[tuple[int, list[int], bytes, tuple[int, int]]]:
        """The rows held, as each channel's block (one bytes object: pickled once for every channel); they stay held
        until :meth:`Publisher.flush` has handed them over."""
        stamps, rows = self.area.read()
        return [(cid, stamps, rows, (at, self.width - at - size)) for cid, at, size in self.parts]


def block_schema(schema: dict) -> dict:
    """The schema of a component channel's block messages from the schema of one sample (see
    :func:`component_schema`): each property an array of the sample's values, with its unit,
    description and causality."""
    props = {}
    for key, prop in schema["properties"].items():
        item = {k: v for k, v in prop.items() if k not in ("description", "unit", "causality")}
        props[key] = {"type": "array", "items": item,
                      **{k: prop[k] for k in ("description", "unit", "causality") if k in prop}}
    return {**schema, "description": schema["description"] + "; each message is a block of consecutive samples, "
            "one array element per sample", "properties": props, "required": list(props)}


def component_schema(rt: Execution, c: int) -> tuple[dict, list]:
    """(JSON Schema, readers) of component ``c``'s channel; readers as in :func:`_values_any`."""
    plan = rt.plan
    props = {"t": {"type": "number", "description": "simulation time", "unit": "s"}}
    readers = []
    for v in plan.logged[c]:
        props[v.name] = {**_json_type(v), "description": v.description or "", "unit": v.unit or "",
                         "causality": v.causality}
        arr, i = rt.slaves[c].locate(v, output=v.causality == "output")
        readers.append((arr, i, v.count if v.is_array else None, _converter(v)))
    schema = {"title": f"cosim.{plan.infos[c].md.modelName}", "type": "object", "properties": props,
              "description": f"signals of component {plan.names[c]} ({plan.infos[c].path.name})"}
    return schema, readers


# --------------------------------------------------------------------------- 3D scene

def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def vec(p) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def _point(p) -> orjson.Fragment:
    """:func:`_vec` serialised once, for points that appear in many messages (trail, reference path)."""
    return orjson.Fragment(orjson.dumps(vec(p)))


IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": IDENTITY}


def line(kind: int, points, rgba, thickness=0.006) -> dict:
    """A ``foxglove.LinePrimitive``: kind 0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST."""
    return line_of(kind, [vec(p) for p in points], rgba, thickness)


def line_of(kind: int, vecs: list, rgba, thickness=0.006) -> dict:
    """:func:`_line` of points already in their JSON form (``{"x", "y", "z"}`` or its fragment)."""
    return {"type": kind, "pose": _POSE, "thickness": thickness, "scale_invariant": False,
            "points": vecs, "color": dict(zip("rgba", rgba)), "colors": [], "indices": []}


def entity(entity_id: str, t_ns: int, lines: list, spheres: list = (), frame: str = "base") -> dict:
    """A ``foxglove.SceneEntity`` that stays until replaced by the next one with the same id."""
    return {"timestamp": _stamp(t_ns), "frame_id": frame, "id": entity_id, "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": False, "metadata": [], "arrows": [], "cubes": [], "spheres": list(spheres),
            "cylinders": [], "lines": lines, "triangles": [], "texts": [], "models": []}


def reference_update(points, t_ns: int) -> dict:
    """A ``foxglove.SceneUpdate`` drawing the reference path ``points`` (n, 3), m, as a line."""
    return _reference_update([vec(v) for v in points], t_ns)


def _reference_update(vecs: list, t_ns: int) -> dict:
    return {"deletions": [], "entities": [entity("reference", t_ns, [line_of(0, vecs, (0.1, 0.4, 0.95, 0.6),
                                                                                0.004)])]}


def frame_transforms(p, t_ns: int) -> dict:
    """A ``foxglove.FrameTransforms``: ``world -> base`` (identity), ``base -> platform`` (translation ``p``)."""
    stamp = _stamp(t_ns)
    return {"transforms": [
        {"timestamp": stamp, "parent_frame_id": "world", "child_frame_id": "base",
         "translation": {"x": 0.0, "y": 0.0, "z": 0.0}, "rotation": IDENTITY},
        {"timestamp": stamp, "parent_frame_id": "base", "child_frame_id": "platform",
         "translation": vec(p), "rotation": IDENTITY}]}


# --------------------------------------------------------------------------- publisher


class Publisher:
    """Observer publishing the run's channels to its sinks (see the module docstring).

    A sink (the MCAP log's :class:`cosim.observers.log_writer.LogSink` or writer process, the live view's
    Foxglove channels) is attached before :meth:`start` and receives, in the run's order:

    - ``channel(cid, topic, schema_name, schema_json, metadata, layout)``: a channel ``cid`` (0, 1, ...);
      ``layout`` (:class:`cosim.observers.log_writer.BlockLayout`) for a component channel, else None;
    - ``blocks(offset_ns, blocks)``: samples of component channels, ``(cid, stamps, rows, skip)`` each
      (simulation ns; raw values, see :class:`_Rows` and :class:`_Joint`), made into the channel's
      messages in its layout by :func:`cosim.observers.log_writer.encode_messages` (log times: stamps +
      ``offset_ns``);
    - ``message(cid, log_time, data)``: any other message, JSON encoded;
    - optionally ``mirror(sections, offset_ns)``, once before the first sample: a
      :class:`cosim.observers.log_writer.RowMirror` into which each row is also copied until its block is handed
      over (so a crash of this process loses no completed step), one section per batch of rows (the joint rows,
      else each channel's rows), or None.

    Samples are copied from the FMU buffers at each step (about 0.2 us per component; by the master's loop in C,
    without entering Python, where every logged component steps every macro step and logs numbers only:
    :meth:`loop_blocks`) and handed over every ``1 / scene_rate_hz`` of simulated time (whether or not a scene is
    drawn), before any other message (so the order is the run's), and when a block is full. Where blocks end
    depends on the simulation alone: a run logs the same messages serial or parallel, with or
    without a live view.

    Parameters
    ----------
    scene
        What ``/scene`` draws (:class:`cosim.engine.plugins.Scene`: the drawing, the three signals it follows,
        its rate, the whole reference path or None), given by the domain plugged in; None: no ``/scene``,
        ``/scene/reference``, ``/tf``.
    rate_hz
        Without a scene: blocks of samples handed over per simulated second (with one: the scene's rate, at which
        scene and transform messages are sent too).
    stamps
        ``"wall"`` (log time from the run's wall-clock start) or ``"simulation"``.
    reference_signals
        Without ``reference``: three signals whose values so far are drawn as the reference path.
    layout
        The component channels' layout (:data:`LAYOUTS`): ``"samples"``, one message per sample, or
        ``"blocks"``, one per block of samples.
    """

    BLOCK_BYTES = 64 * 1024
    """Bytes of rows a component channel holds at most before they are handed over."""

    def __init__(self, scene=None, stamps: str = "wall", reference_signals: Sequence[str] | None = None,
                 layout: str = "samples", rate_hz: float = 30.0):
        if stamps not in STAMPS:
            raise CosimError(f"time stamps must be one of {', '.join(STAMPS)}, got {stamps!r}")
        if layout not in LAYOUTS:
            raise CosimError(f"log layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
        rate_hz = scene.rate_hz if scene is not None else rate_hz
        if not rate_hz > 0:
            raise CosimError(f"scene rate must be > 0 Hz, got {rate_hz}")
        self.scene = scene
        self.scene_position = list(scene.position) if scene is not None and scene.position else None
        self.scene_period_ns = round(1e9 / rate_hz)
        self.stamps = stamps
        self.layout = layout
        reference = None if scene is None else scene.reference
        self.reference = None if reference is None else np.asarray(reference, dtype=float)
        self.reference_signals = list(reference_signals) if reference_signals else None
        self.offset_ns: int | None = None
        self._sinks: list[Any] = []
        self._mirrors: list[Any] = []
        self._pending: list[_Rows] = []
        self._n = 0  # steps with samples not handed over

    def attach(self, sink) -> None:
        """Add a sink; it receives every channel and message from :meth:`start` on."""
        self._sinks.append(sink)

    def origin(self, rt: Execution) -> int:
        """Fix (once) and return the offset log time - simulation time, ns."""
        if self.offset_ns is None:
            self.offset_ns = time.time_ns() - rt.start_ns if self.stamps == "wall" else 0
        return self.offset_ns

    def _channel(self, topic: str, schema_name: str, schema: dict, metadata: dict[str, str] | None = None,
                 layout=None) -> int:
        cid = self._n_channels
        self._n_channels += 1
        data = orjson.dumps(schema)
        for sink in self._sinks:
            sink.channel(cid, topic, schema_name, data, metadata or {}, layout)
        return cid

    def _send(self, cid: int, log_time: int, data: bytes) -> None:
        """A message other than samples: the samples before it first, so the sinks see the run's order."""
        self.flush()
        for sink in self._sinks:
            sink.message(cid, log_time, data)

    def flush(self) -> None:
        """Hand every pending sample to the sinks."""
        if not self._n:
            return
        self._n = 0
        blocks = self._joint.take() if self._joint is not None and self._joint.held else []
        blocks += [rows.take() for rows in self._pending if rows.stamps]
        for sink in self._sinks:
            sink.blocks(self.offset_ns, blocks)
        for m in self._mirrors:  # sent: down the pipe
            m.sent()
        if self._joint is not None:
            self._joint.area.sent()

    # -- observer protocol
    def start(self, rt: Execution) -> None:

        plan = rt.plan
        self.origin(rt)
        self._n_channels = 0
        self._pending = []
        self._n = 0
        self._rows_of: dict[int, _Rows] = {}
        for c, name in enumerate(plan.names):
            if not (plan.logged and plan.logged[c]):
                continue
            schema, readers = component_schema(rt, c)
            per_sample = self.layout == "samples"
            layout, runs = block_layout(tuple(schema["properties"])[1:], readers, [v.kind for v in plan.logged[c]],
                                        per_sample)
            cid = self._channel(f"/{name}", f"cosim.{name}", schema if per_sample else block_schema(schema),
                                {"fmu": str(plan.infos[c].path.name), "step_multiple": str(rt.multiples[c]),
                                 "layout": self.layout}, layout)
            rows = _Rows(cid, runs, readers, self.BLOCK_BYTES)
            self._pending.append(rows)
            self._rows_of[c] = rows
        self._grid = rt.grid
        self._rt = rt
        self._scene = None
        if self.scene is not None and self.scene_position:
            sources = [rt.where(plan.port(r)) for r in self.scene_position]
            ref_sources = None
            if self.reference is None and self.reference_signals:
                ref_sources = [rt.where(plan.port(r)) for r in self.reference_signals]
            self._scene = (self._channel("/scene", "foxglove.SceneUpdate", SCENE_UPDATE), sources,
                           self._channel("/tf", "foxglove.FrameTransforms", FRAME_TRANSFORMS),
                           self._channel("/scene/reference", "foxglove.SceneUpdate", SCENE_UPDATE), ref_sources)
            keep = max(2, round(_TRAIL_S * 1e9 / self.scene_period_ns) + 1)
            self._trail: deque = deque(maxlen=keep)  # points as JSON fragments: each serialised once
            self._ref_points: list = [] if self.reference is None else [_point(v) for v in self.reference]
            self._next_reference = rt.now_ns
            self._drawing = self.scene
        # model-exchange components report their events (time, kind) on one /events channel
        self._event_sources = [(c, s) for c, s in enumerate(rt.slaves) if hasattr(s, "event_log")]
        self._fired = rt.events.fired if rt.events is not None else None  # the scenario's events
        self._n_fired = 0
        self._events_cid = None
        if self._event_sources or self._fired is not None:
            self._events_cid = self._channel("/events", "cosim.events", EVENTS_SCHEMA)
        # a block is handed over before any channel's can be full (the fastest fills one sample a step)
        self._cap = min((rows.cap for rows in self._pending), default=_BLOCK_ROWS)
        logged = [c for c in plan.order if c in self._rows_of]
        self._joint = None
        if logged and all(rt.multiples[c] == 1 and self._rows_of[c].raw for c in logged):
            self._joint = _Joint([self._rows_of[c] for c in logged], self.BLOCK_BYTES)
            self._cap = min(self._cap, self._joint.cap)
        self._n = 0
        # the writers' copies of the rows not sent yet (a crash of this process keeps them): one section per batch, the
        # joint rows or each channel's rows, of bytes or of values (width None; cosim.observers.log_writer.RowMirror)
        batches = [self._joint] if self._joint is not None else self._pending
        sections = [(batch.parts, batch.width, self._cap) for batch in batches]
        self._mirrors = []
        for sink in self._sinks:
            mirror = getattr(sink, "mirror", None)
            made = mirror(sections, self.offset_ns) if mirror is not None and sections else None
            if made is not None:
                self._mirrors.append(made)
        for i, batch in enumerate(batches):
            batch.puts = tuple(m.sections[i].put for m in self._mirrors)
        if self._joint is not None:  # its rows held in the first mirror's section, else in memory of its own
            self._joint.area = self._mirrors[0].sections[0] if self._mirrors else row_section(self._joint.width,
                                                                                              self._cap)
            self._joint.puts = self._joint.puts[1:]
        # per component: None (not logged) or (add a row, read a row, add a stamp, step multiple, mirror the row)
        self._by_comp: list[tuple[Any, Any, Any, int, tuple] | None] = [None] * len(plan.names)
        for c, rows in self._rows_of.items():
            self._by_comp[c] = (rows.data.append, rows.capture, rows.stamps.append, rt.multiples[c], rows.puts)
        if self._joint is not None:
            self._joint.put(rt.now_ns, self._joint.capture())
            self._n = 1
        else:
            for c, entry in enumerate(self._by_comp):
                if entry is not None:
                    add, read, stamp, m, puts = entry
                    row = read()
                    add(row)
                    # the time the component's values are of: a multi-rate component in a run resumed inside its
                    # step is at the end of that step
                    k = rt.k_done
                    t_own = rt.now_ns if k == 0 or m == 1 else self._grid.t_ns(self._grid.end((k - 1) // m * m, m))
                    stamp(t_own)
                    for put in puts:
                        put(t_own, row)
                    self._n = 1
        self._next_tick = rt.now_ns
        self._tick(rt.now_ns)

    def _tick(self, t_ns: int) -> None:
        """Every scene period: the samples so far, then the scene."""
        self._next_tick = t_ns + self.scene_period_ns
        self.flush()
        if self._scene is None:
            return
        scene_cid, sources, tf_cid, ref_cid, ref_sources = self._scene
        stamp = t_ns + self.offset_ns
        p = [arr[i] for arr, i in sources]
        self._trail.append(_point(p))
        if ref_sources is not None:
            self._ref_points.append(_point([arr[i] for arr, i in ref_sources]))
            if len(self._ref_points) > 2 * REFERENCE_POINTS:  # every other point: the resent line stays bounded
                self._ref_points = self._ref_points[::2]
        msg = self._drawing.update(p, stamp, list(self._trail))
        if msg is not None:
            self._send(scene_cid, stamp, orjson.dumps(msg))
            self._send(tf_cid, stamp, orjson.dumps(frame_transforms(p, stamp)))
        if t_ns >= self._next_reference and len(self._ref_points) > 1:
            self._next_reference = t_ns + _REFERENCE_PERIOD_NS
            self._send(ref_cid, stamp, orjson.dumps(_reference_update(self._ref_points, stamp)))

    def _log_events(self) -> None:
        fired = self._fired
        if fired is not None and len(fired) > self._n_fired:
            for e in fired[self._n_fired:]:
                self._send(self._events_cid, round(e.t * 1e9) + self.offset_ns,
                           orjson.dumps({"t": e.t, "event": e.event, "set": e.set}))
            self._n_fired = len(fired)
        names = self._rt.plan.names
        for c, slave in self._event_sources:
            events = slave.event_log
            if not events:
                continue
            for t, kind in events:
                t = float(t)
                self._send(self._events_cid, round(t * 1e9) + self.offset_ns,
                           orjson.dumps({"t": t, "component": names[c], "kind": kind}))
            events.clear()

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        joint = self._joint
        if joint is not None and self._rt.t_end_ns is None:  # every logged component stepped, to t_ns
            joint.put(t_ns, joint.capture())
        else:
            if joint is not None:  # the last step of a run an FMU ended: some components only
                self.flush()
            grid = self._grid
            by_comp = self._by_comp
            ended = self._rt.t_end_ns is not None  # an FMU ended the run: no stamp past the time reached
            for c in active:
                entry = by_comp[c]
                if entry is not None:
                    add, read, stamp, m, puts = entry
                    row = read()
                    add(row)
                    # the end of this component's own (possibly multi-rate) step
                    t_end = grid.t_ns(grid.end(k, m))
                    if ended:
                        t_end = min(t_end, t_ns)
                    stamp(t_end)
                    for put in puts:
                        put(t_end, row)
        self._n += 1
        if self._n >= self._cap:
            self.flush()
        if self._events_cid is not None:
            self._log_events()
        if t_ns >= self._next_tick:
            self._tick(t_ns)

    def loop_blocks(self) -> Blocks | None:
        """What the master's loop in C needs to run blocks of macro steps with this publisher (see
        :class:`cosim.engine.cloop.Blocks`): each step's joint row copied in C into :attr:`_Joint.area`, Python entered
        where a scene is due or the rows are full; None (Python after every step) without joint rows, with events to
        log, or with more than one mirror."""
        joint = self._joint
        if joint is None or self._events_cid is not None or joint.puts or self._rt.t_end_ns is not None:
            return None
        return Blocks(self._free, self._block_stepped, (joint.area, joint.copies))

    def _free(self, k: int) -> int:
        return min(self._cap - self._n, steps_to(self._grid, k, self._next_tick))

    def _block_stepped(self, k: int, n: int) -> None:
        """Macro steps ``k .. k + n - 1`` done, their rows copied (:meth:`loop_blocks`): what :meth:`stepped` does after
        the last of them (none of the others fills the rows or reaches the scene's time)."""
        if n == 0:
            return
        self._n += n
        if self._n >= self._cap:
            self.flush()
        t_ns = self._grid.t_ns(k + n)
        if t_ns >= self._next_tick:
            self._tick(t_ns)

    def finish(self, rt: Execution | None, error: BaseException | None) -> None:
        self.flush()  # normally done: each sink flushes the publisher before it closes
