"""MCAP recorder: an observer that logs every exchanged signal, plus a Foxglove 3D scene.

- one channel ``/<component>`` per component, JSON encoding, a titled JSON Schema
  listing the logged variables with unit and description;
- messages serialised with orjson, stamped with the simulation time (ns);
- metadata (scenario, versions, platform) and attachments (the scenario file and
  each FMU's modelDescription.xml);
- a ``/scene`` channel of ``foxglove.SceneUpdate`` drawing the robot at about 30 Hz;
- zstd chunks flushed every ``flush_interval`` wall seconds, so a killed run
  leaves every complete chunk readable (see :mod:`cosim.recover`);
- ``finish`` always writes the summary and index, on success, error or Ctrl-C.

Inputs are logged with the value held over the step that ends at the stamp;
outputs with their value at the stamp.
"""

from __future__ import annotations

import functools
import platform
import struct
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import orjson

from .algorithm import Runtime
from .fmu import BINARY, BOOLEAN, INTEGER, REAL, STRING

__all__ = ["McapRecorder", "MessageSink", "scene_update", "SCENE_SCHEMA", "EVENTS_SCHEMA"]

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_OPCODE = 0x05
_MESSAGE_FIXED = 22  # bytes of a Message record after its length field, before the data

_JSON_TYPE = {REAL: {"type": "number"}, INTEGER: {"type": "integer"}, BOOLEAN: {"type": "boolean"},
              STRING: {"type": "string"}, BINARY: {"type": "string", "contentEncoding": "base64"}}


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
        import base64

        return lambda b: base64.b64encode(b).decode("ascii")
    return bool if v.kind == BOOLEAN else None  # FMI 2.0 Booleans are C ints


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def _vec(p) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
SCENE_SCHEMA = {
    "title": "foxglove.SceneUpdate",
    "description": "An update to the entities displayed in a 3D scene (Foxglove)",
    "type": "object",
    "properties": {
        "deletions": {"type": "array", "items": {"type": "object"}},
        "entities": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"},
            "lifetime": _TIME, "frame_locked": {"type": "boolean"},
            "metadata": {"type": "array"}, "arrows": {"type": "array"}, "cubes": {"type": "array"},
            "spheres": {"type": "array", "items": {"type": "object", "properties": {
                "pose": {"type": "object"}, "size": _VEC3, "color": _COLOR}}},
            "cylinders": {"type": "array"},
            "lines": {"type": "array", "items": {"type": "object", "properties": {
                "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
                "pose": {"type": "object"}, "thickness": {"type": "number"},
                "scale_invariant": {"type": "boolean"}, "points": {"type": "array", "items": _VEC3},
                "color": _COLOR, "colors": {"type": "array"}, "indices": {"type": "array"}}}},
            "triangles": {"type": "array"}, "texts": {"type": "array"}, "models": {"type": "array"}}}},
    },
}


EVENTS_SCHEMA = {
    "title": "cosim.Event",
    "description": "An event handled by the master in a model-exchange component (FMI event mode)",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "event time", "unit": "s"},
        "component": {"type": "string", "description": "the component in event mode"},
        "kind": {"type": "string", "description": "what triggered it: state, time, step or input (joined by +)"},
    },
}


def _line(kind: int, points, rgba, thickness=0.006) -> dict:
    return {"type": kind, "pose": _POSE, "thickness": thickness, "scale_invariant": False,
            "points": [_vec(p) for p in points], "color": dict(zip("rgba", rgba)), "colors": [], "indices": []}


def scene_update(robot, p, t_ns: int) -> dict | None:
    """A ``foxglove.SceneUpdate`` (JSON form) drawing ``robot`` with the platform at ``p`` (3,), m.

    Linear delta: rails, carriages, rods, platform. Rotary delta: base, arms, forearms,
    platform. None when ``p`` is unreachable (nothing sensible to draw).
    """
    import numpy as np

    from delta.kinematics import actuator_points, ik, platform_offsets
    from delta.robots import LinearDelta

    p = np.asarray(p, dtype=float)
    res = ik(robot, p)
    if not res.ok:
        return None
    q = res.q
    b = platform_offsets(robot)
    joints_a = actuator_points(robot, q)  # carriage joints or elbows, (3, 3)
    joints_p = p + b  # platform joints, (3, 3)
    lines = []
    if isinstance(robot, LinearDelta):
        from delta.kinematics import leg_axes

        e = robot.rail_radius * leg_axes(robot)
        top = e.copy()
        top[:, 2] = -robot.q_min
        bottom = e.copy()
        bottom[:, 2] = -robot.q_max
        lines.append(_line(2, [x for pair in zip(top, bottom) for x in pair], (0.6, 0.6, 0.6, 1.0), 0.01))
        base = e.copy()
        base[:, 2] = 0.0
    else:
        from delta.kinematics import leg_axes

        base = robot.base_radius * leg_axes(robot)
        lines.append(_line(2, [x for pair in zip(base, joints_a) for x in pair], (0.2, 0.4, 0.9, 1.0), 0.015))
    lines.append(_line(1, base, (0.5, 0.5, 0.5, 1.0)))
    lines.append(_line(2, [x for pair in zip(joints_a, joints_p) for x in pair], (0.9, 0.6, 0.1, 1.0)))
    lines.append(_line(1, joints_p, (0.1, 0.7, 0.3, 1.0), 0.01))
    spheres = [{"pose": {"position": _vec(x), "orientation": _POSE["orientation"]},
                "size": {"x": 0.02, "y": 0.02, "z": 0.02}, "color": {"r": 0.9, "g": 0.1, "b": 0.1, "a": 1.0}}
               for x in list(joints_a) + [p]]
    entity = {"timestamp": _stamp(t_ns), "frame_id": "base", "id": "robot", "lifetime": {"sec": 0, "nsec": 0},
              "frame_locked": False, "metadata": [], "arrows": [], "cubes": [], "spheres": spheres,
              "cylinders": [], "lines": lines, "triangles": [], "texts": [], "models": []}
    return {"deletions": [], "entities": [entity]}


@functools.lru_cache(maxsize=None)
def _packed_message_index() -> type:
    """mcap's ``MessageIndex`` whose ``write`` packs all (time, offset) pairs at once (same bytes;
    mcap's version makes two ``struct.pack`` calls per message when a chunk is finalized)."""
    from mcap.opcode import Opcode
    from mcap.records import MessageIndex

    class PackedMessageIndex(MessageIndex):
        def write(self, stream) -> None:  # noqa: ANN001
            n = len(self.records)
            stream.start_record(Opcode.MESSAGE_INDEX)
            stream.write2(self.channel_id)
            stream.write4(n * 16)
            stream.write(struct.pack(f"<{2 * n}Q", *[x for record in self.records for x in record]))
            stream.finish_record()

    return PackedMessageIndex


class MessageSink:
    """``Writer.add_message`` for the recorder's hot path, at a fraction of its cost.

    mcap's ``add_message`` builds a ``Message`` dataclass and writes its record with five
    ``struct.pack`` calls and two seeks (~10 us). This writes the same record bytes with
    one pack into the writer's open chunk and keeps the writer's statistics, chunk time
    range and message index exactly as ``add_message`` does (the index written with one
    pack too), then lets the writer finalize the chunk when it is full, so the file is
    byte-identical
    (``tests/unit/test_mcap_sink.py``). It needs the private state of mcap 1.x's
    ``Writer``; when that is not there, :meth:`add` is the public ``add_message``.
    """

    def __init__(self, writer: Any) -> None:
        self.writer = writer
        try:
            self._chunk_size = writer._Writer__chunk_size
            self._stats = writer._Writer__statistics
            self._chunk = writer._Writer__chunk_builder
            self._finalize = writer._Writer__maybe_finalize_chunk
            self._index_type = _packed_message_index()
            fast = (self._chunk is not None and hasattr(self._chunk, "message_indices")
                    and hasattr(self._chunk.record_writer, "_buffer") and hasattr(self._stats, "channel_message_counts"))
        except (AttributeError, ImportError):
            fast = False
        if not fast:
            self.add = self._add_public

    def _add_public(self, channel_id: int, t_ns: int, data: bytes) -> None:
        self.writer.add_message(channel_id, t_ns, data, t_ns)

    def add(self, channel_id: int, t_ns: int, data: bytes) -> None:
        """Append one message (log time = publish time = ``t_ns``, sequence 0)."""
        st = self._stats
        if st.message_count == 0 or t_ns < st.message_start_time:
            st.message_start_time = t_ns
        if t_ns > st.message_end_time:
            st.message_end_time = t_ns
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        ch = self._chunk
        if ch.num_messages == 0 or t_ns < ch.message_start_time:
            ch.message_start_time = t_ns
        if t_ns > ch.message_end_time:
            ch.message_end_time = t_ns
        index = ch.message_indices.get(channel_id)
        if index is None:
            index = ch.message_indices[channel_id] = self._index_type(channel_id=channel_id, records=[])
        buf = ch.record_writer._buffer
        offset = buf.tell()
        index.records.append((t_ns, offset))
        ch.num_messages += 1
        buf.write(_MESSAGE_HEAD.pack(_MESSAGE_OPCODE, _MESSAGE_FIXED + len(data), channel_id, 0, t_ns, t_ns))
        buf.write(data)
        if buf.tell() > self._chunk_size:
            self._finalize()


def _gather(sources: list[tuple[Any, int]]) -> list[tuple[Any, list[int] | None]]:
    """Group ``(array, index)`` sources by array, in order: ``(array, None)`` when the group is the
    whole array in order (read with one slice), else ``(array, indices)``."""
    groups: list[tuple[Any, list[int]]] = []
    for arr, i in sources:
        if groups and groups[-1][0] is arr:
            groups[-1][1].append(i)
        else:
            groups.append((arr, [i]))
    return [(arr, None if idx == list(range(len(arr))) else idx) for arr, idx in groups]


def _values(t_ns: int, groups) -> list:
    """``[t in s, logged values...]`` read from the grouped buffers."""
    vals = [t_ns * 1e-9]
    for arr, idx in groups:
        vals += arr[:] if idx is None else [arr[i] for i in idx]
    return vals


def _values_any(t_ns: int, readers) -> list:
    """``[t in s, logged values...]`` for components with arrays or values needing conversion.

    ``readers`` holds per variable ``(array, offset, count or None for a scalar, converter or None)``.
    """
    vals = [t_ns * 1e-9]
    for arr, i, n, conv in readers:
        if n is None:
            vals.append(arr[i] if conv is None else conv(arr[i]))
        else:
            vals.append(arr[i:i + n] if conv is None else [conv(x) for x in arr[i:i + n]])
    return vals


class McapRecorder:
    """Observer writing the run to an MCAP file (see the module docstring)."""

    CHUNK_SIZE = 256 * 1024
    """Uncompressed bytes per zstd chunk (a periodic flush ends a chunk earlier)."""

    def __init__(self, path: str | Path, scenario=None, scenario_file: str | Path | None = None,
                 flush_interval: float = 1.0, scene_robot=None, scene_position: list[str] | None = None,
                 scene_rate_hz: float = 30.0):
        self.path = Path(path)
        self.scenario = scenario
        self.scenario_file = Path(scenario_file) if scenario_file else None
        self.flush_interval = flush_interval
        self.scene_robot = scene_robot
        self.scene_position = scene_position
        self.scene_period_ns = int(round(1e9 / scene_rate_hz))
        self._writer = None
        self._file = None
        self.messages = 0

    # -- observer protocol
    def start(self, rt: Runtime) -> None:
        from mcap.writer import CompressionType, Writer

        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        w = self._writer = Writer(self._file, compression=CompressionType.ZSTD, chunk_size=self.CHUNK_SIZE)
        self._sink = MessageSink(w)
        w.start(profile="", library="cosim")
        plan = rt.plan
        # per component: channel id, its sources grouped by buffer (see _gather), the JSON keys
        self._channels: list[tuple[int, list, tuple[str, ...], Any] | None] = []
        for c, name in enumerate(plan.names):
            logged = plan.logged[c] if plan.logged else []
            if not logged:
                self._channels.append(None)
                continue
            slave = rt.slaves[c]
            props = {"t": {"type": "number", "description": "simulation time", "unit": "s"}}
            readers = []
            keys = ["t"]
            for v in logged:
                props[v.name] = {**_json_type(v), "description": v.description or "", "unit": v.unit or "",
                                 "causality": v.causality}
                arr, i = slave.locate(v, output=v.causality == "output")
                readers.append((arr, i, v.count if v.is_array else None, _converter(v)))
                keys.append(v.name)
            schema = {"title": f"cosim.{plan.infos[c].md.modelName}", "type": "object", "properties": props,
                      "description": f"signals of component {name} ({plan.infos[c].path.name})"}
            sid = w.register_schema(name=f"cosim.{name}", encoding="jsonschema", data=orjson.dumps(schema))
            cid = w.register_channel(topic=f"/{name}", message_encoding="json", schema_id=sid,
                                     metadata={"fmu": str(plan.infos[c].path.name),
                                               "step_multiple": str(rt.multiples[c])})
            if all(n is None and conv is None for _, _, n, conv in readers):  # plain scalars: grouped reads
                self._channels.append((cid, _gather([(arr, i) for arr, i, _, _ in readers]), tuple(keys), _values))
            else:
                self._channels.append((cid, readers, tuple(keys), _values_any))
        self._h_ns = [m * rt.step_ns for m in rt.multiples]
        self._step_ns = rt.step_ns
        self._t0 = rt.start_ns
        self._rt = rt
        self._scene = None
        if self.scene_robot is not None and self.scene_position:
            sources = [rt.where(plan.port(r)) for r in self.scene_position]
            sid = w.register_schema(name="foxglove.SceneUpdate", encoding="jsonschema",
                                    data=orjson.dumps(SCENE_SCHEMA))
            cid = w.register_channel(topic="/scene", message_encoding="json", schema_id=sid)
            self._scene = (cid, sources)
            self._next_scene = rt.start_ns
        # model-exchange components report their events (time, kind) on one /events channel
        self._event_sources = [(c, s) for c, s in enumerate(rt.slaves) if hasattr(s, "event_log")]
        self._events_channel = None
        if self._event_sources:
            sid = w.register_schema(name="cosim.events", encoding="jsonschema", data=orjson.dumps(EVENTS_SCHEMA))
            self._events_channel = w.register_channel(topic="/events", message_encoding="json", schema_id=sid)
        self._metadata(rt)
        self._last_flush = time.monotonic()
        t0 = rt.start_ns
        for c in range(len(plan.names)):
            self._log(c, t0)
        self._draw(t0)

    def _metadata(self, rt: Runtime) -> None:
        import fmpy
        import mcap

        w = self._writer
        versions = {"python": sys.version.split()[0], "fmpy": fmpy.__version__,
                    "mcap": getattr(mcap, "__version__", "?"), "orjson": orjson.__version__}
        try:
            from importlib.metadata import version

            versions["delta-cosim"] = version("delta-cosim")
        except Exception:  # not installed as a distribution: leave it out
            pass
        w.add_metadata("versions", versions)
        w.add_metadata("platform", {"system": platform.system(), "machine": platform.machine(),
                                    "node": platform.node(), "python_implementation": platform.python_implementation()})
        if self.scenario is not None:
            s = self.scenario
            w.add_metadata("scenario", {
                "name": s.name, "algorithm": s.algorithm, "step_s": repr(s.time.step), "stop_s": repr(s.time.stop),
                "start_s": repr(s.time.start), "robot": str(s.robot), "components": ",".join(s.components),
                "file": str(self.scenario_file or s.source or "")})
        now = time.time_ns()
        if self.scenario_file is not None and self.scenario_file.exists():
            ssp = self.scenario_file.suffix.lower() == ".ssp"  # an SSP archive (SSP 1.0 names its MIME type)
            w.add_attachment(log_time=now, create_time=now, name=f"scenario/{self.scenario_file.name}",
                             media_type="application/x-ssp-package" if ssp else "application/yaml",
                             data=self.scenario_file.read_bytes())
        for name, info in zip(rt.plan.names, rt.plan.infos):
            w.add_attachment(log_time=now, create_time=now, name=f"fmu/{name}/modelDescription.xml",
                             media_type="application/xml", data=info.model_description_xml())

    def _log(self, c: int, t_ns: int) -> None:
        ch = self._channels[c]
        if ch is None:
            return
        cid, groups, keys, values = ch
        self._sink.add(cid, t_ns, orjson.dumps(dict(zip(keys, values(t_ns, groups)))))
        self.messages += 1

    def _draw(self, t_ns: int) -> None:
        if self._scene is None or t_ns < self._next_scene:
            return
        self._next_scene = t_ns + self.scene_period_ns
        cid, sources = self._scene
        msg = scene_update(self.scene_robot, [arr[i] for arr, i in sources], t_ns)
        if msg is not None:
            self._sink.add(cid, t_ns, orjson.dumps(msg))
            self.messages += 1

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        h = self._h_ns
        t_start = self._t0 + k * self._step_ns
        add = self._sink.add
        dumps = orjson.dumps
        channels = self._channels
        for c in active:
            ch = channels[c]
            if ch is None:
                continue
            stamp = t_start + h[c]  # the end of this component's own (possibly multi-rate) step
            if stamp > t_ns and self._rt.t_end_ns is not None:  # an FMU ended the run: the time reached
                stamp = t_ns
            cid, groups, keys, values = ch
            add(cid, stamp, dumps(dict(zip(keys, values(stamp, groups)))))
        self.messages += len(active)
        if self._events_channel is not None:
            self._log_events()
        if self._scene is not None and t_ns >= self._next_scene:
            self._draw(t_ns)
        if time.monotonic() - self._last_flush > self.flush_interval:
            self._writer.flush()
            self._last_flush = time.monotonic()

    def _log_events(self) -> None:
        names = self._rt.plan.names
        for c, slave in self._event_sources:
            log = slave.event_log
            if not log:
                continue
            for t, kind in log:
                t = float(t)
                self._sink.add(self._events_channel, round(t * 1e9), orjson.dumps(
                    {"t": t, "component": names[c], "kind": kind}))
                self.messages += 1
            log.clear()

    def finish(self, rt: Runtime | None, error: BaseException | None) -> None:
        if self._writer is None:
            return
        try:
            if error is not None:
                self._writer.add_metadata("outcome", {"status": "error" if not isinstance(
                    error, KeyboardInterrupt) else "interrupted", "message": str(error) or type(error).__name__,
                    "completed_steps": str(rt.k_done if rt else 0)})
            else:
                outcome = {"status": "completed", "completed_steps": str(rt.k_done if rt else 0)}
                if rt is not None and rt.terminated is not None:
                    outcome.update(terminated_by=rt.terminated.component, end_time_s=repr(rt.terminated.time),
                                   message=str(rt.terminated))
                self._writer.add_metadata("outcome", outcome)
            self._writer.finish()
        finally:
            self._writer = None
            self._file.close()
