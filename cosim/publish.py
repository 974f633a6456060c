"""What a run publishes: the channels, schemas and messages shared by the MCAP log and the live view.

A :class:`Publisher` is an observer that declares the run's channels in a ``foxglove.Context``
and logs every exchanged signal into it. Every sink attached to that context receives the
same channels, schemas and messages: the MCAP file (:class:`cosim.mcap_log.McapRecorder`),
the Foxglove WebSocket server (:class:`cosim.live.LiveView`), or both. One formula per
message, in one place.

Channels (JSON encoding, each with a titled JSON Schema):

- ``/<component>``: the component's logged variables, ``{"t": s, "<variable>": value, ...}``;
  the schema lists each variable with unit, description and causality;
- ``/scene``: ``foxglove.SceneUpdate`` at ``scene_rate_hz``: the robot (rails or arms,
  rods, platform) and the platform's trail over the last ``trail_s`` seconds;
- ``/scene/reference``: ``foxglove.SceneUpdate``, the reference path as a line: the whole
  path when the scenario has a ``trajectory:`` section, else the reference signal so far;
  sent at the start and every second (a viewer that joins or seeks late still gets it);
- ``/tf``: ``foxglove.FrameTransforms`` with the scene: ``world -> base`` (identity) and
  ``base -> platform`` (the platform position);
- ``/events``: events of model-exchange components (time, component, kind).

Scene and transform messages use Foxglove's published schemas (:mod:`cosim.foxglove_schemas`).

Time stamps: a message's log time is its simulation time plus :attr:`Publisher.offset_ns`:
with ``stamps="wall"`` (default) the wall clock at the run's start minus the simulated start,
so viewers show the real date; with ``stamps="simulation"`` zero. The ``"t"`` field of every
message is the simulation time in s either way, and the log's ``time`` metadata record keeps
the offset (:func:`cosim.runlog.time_offset_ns` reads it back; logs without it have offset 0).

Inputs are published with the value held over the step that ends at the stamp; outputs with
their value at the stamp.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np
import orjson

from .algorithm import Runtime
from .errors import CosimError
from .fmu import BINARY, BOOLEAN, INTEGER, REAL, STRING

__all__ = [
    "EVENTS_SCHEMA",
    "STAMPS",
    "Publisher",
    "frame_transforms",
    "reference_path",
    "reference_update",
    "scene_update",
    "time_metadata",
]

STAMPS = ("wall", "simulation")
_TRAIL_S = 3.0  # s of platform trail drawn in the scene
_REFERENCE_PERIOD_NS = 1_000_000_000  # /scene/reference resent every simulated second
_REFERENCE_POINTS = 600  # the whole reference path is drawn with at most this many points

_JSON_TYPE = {REAL: {"type": "number"}, INTEGER: {"type": "integer"}, BOOLEAN: {"type": "boolean"},
              STRING: {"type": "string"}, BINARY: {"type": "string", "contentEncoding": "base64"}}

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
        import base64

        return lambda b: base64.b64encode(b).decode("ascii")
    return bool if v.kind == BOOLEAN else None  # FMI 2.0 Booleans are C ints


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


def component_schema(rt: Runtime, c: int) -> tuple[dict, list]:
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


def _vec(p) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": _IDENTITY}


def _line(kind: int, points, rgba, thickness=0.006) -> dict:
    """A ``foxglove.LinePrimitive``: kind 0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST."""
    return {"type": kind, "pose": _POSE, "thickness": thickness, "scale_invariant": False,
            "points": [_vec(p) for p in points], "color": dict(zip("rgba", rgba)), "colors": [], "indices": []}


def _entity(entity_id: str, t_ns: int, lines: list, spheres: list = (), frame: str = "base") -> dict:
    """A ``foxglove.SceneEntity`` that stays until replaced by the next one with the same id."""
    return {"timestamp": _stamp(t_ns), "frame_id": frame, "id": entity_id, "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": False, "metadata": [], "arrows": [], "cubes": [], "spheres": list(spheres),
            "cylinders": [], "lines": lines, "triangles": [], "texts": [], "models": []}


def scene_update(robot, p, t_ns: int, trail=None) -> dict | None:
    """A ``foxglove.SceneUpdate`` (JSON form) drawing ``robot`` with the platform at ``p`` (3,), m.

    Linear delta: rails, carriages, rods, platform. Rotary delta: base, arms, forearms,
    platform. ``trail`` (n, 3), m: the platform's recent positions, drawn as a line.
    ``t_ns`` is the message's log time. None when ``p`` is unreachable (nothing sensible to draw).
    """
    from delta.kinematics import actuator_points, ik, leg_axes, platform_offsets
    from delta.model import build_model

    model = build_model(robot)  # once: every helper below takes the model
    actuator = model.actuator
    p = np.asarray(p, dtype=float)
    res = ik(model, p)
    if not res.ok:
        return None
    joints_a = actuator_points(model, res.q)  # carriage joints or elbows, (3, 3)
    joints_p = p + platform_offsets(model)  # platform joints, (3, 3)
    base = actuator.radius * leg_axes(model)  # rail tops or motor axes, z = 0
    colour, width = actuator.guide_style
    lines = [_line(2, actuator.guides(robot, base, joints_a), colour, width), _line(1, base, (0.5, 0.5, 0.5, 1.0))]
    lines.append(_line(2, [x for pair in zip(joints_a, joints_p) for x in pair], (0.9, 0.6, 0.1, 1.0)))
    lines.append(_line(1, joints_p, (0.1, 0.7, 0.3, 1.0), 0.01))
    spheres = [{"pose": {"position": _vec(x), "orientation": _IDENTITY},
                "size": {"x": 0.02, "y": 0.02, "z": 0.02}, "color": {"r": 0.9, "g": 0.1, "b": 0.1, "a": 1.0}}
               for x in list(joints_a) + [p]]
    entities = [_entity("robot", t_ns, lines, spheres)]
    if trail is not None and len(trail) > 1:
        entities.append(_entity("trail", t_ns, [_line(0, trail, (0.85, 0.1, 0.1, 0.8), 0.003)]))
    return {"deletions": [], "entities": entities}


def reference_update(points, t_ns: int) -> dict:
    """A ``foxglove.SceneUpdate`` drawing the reference path ``points`` (n, 3), m, as a line."""
    return {"deletions": [], "entities": [_entity("reference", t_ns, [_line(0, points, (0.1, 0.4, 0.95, 0.6),
                                                                               0.004)])]}


def frame_transforms(p, t_ns: int) -> dict:
    """A ``foxglove.FrameTransforms``: ``world -> base`` (identity), ``base -> platform`` (translation ``p``)."""
    stamp = _stamp(t_ns)
    return {"transforms": [
        {"timestamp": stamp, "parent_frame_id": "world", "child_frame_id": "base",
         "translation": {"x": 0.0, "y": 0.0, "z": 0.0}, "rotation": _IDENTITY},
        {"timestamp": stamp, "parent_frame_id": "base", "child_frame_id": "platform",
         "translation": _vec(p), "rotation": _IDENTITY}]}


def reference_path(scenario) -> np.ndarray | None:
    """The scenario's whole reference path (n, 3), m, from its ``trajectory:`` section; None without one."""
    spec = getattr(scenario, "trajectory", None)
    if spec is None:
        return None
    from .preflight import make_trajectory, sampled_positions

    t0, t1 = scenario.time.start, scenario.time.stop
    n = int(min(_REFERENCE_POINTS, max(2, round((t1 - t0) / scenario.time.step) + 1)))
    return sampled_positions(make_trajectory(spec, scenario.source), np.linspace(t0, t1, n))


# --------------------------------------------------------------------------- publisher


class Publisher:
    """Observer logging the run's channels into a ``foxglove.Context`` (see the module docstring).

    Parameters
    ----------
    scene_robot
        A robot preset (``delta.robots``) to draw; None: no ``/scene``, ``/scene/reference``, ``/tf``.
    scene_position
        The three signals of the platform position (``["plant.p.x", "plant.p.y", "plant.p.z"]``).
    scene_rate_hz
        Scene and transform messages per simulated second.
    stamps
        ``"wall"`` (log time from the run's wall-clock start) or ``"simulation"``.
    reference
        The whole reference path (n, 3), m (:func:`reference_path`); or None.
    reference_signals
        Without ``reference``: three signals whose values so far are drawn as the reference path.
    """

    def __init__(self, scene_robot=None, scene_position: Sequence[str] | None = None, scene_rate_hz: float = 30.0,
                 stamps: str = "wall", reference=None, reference_signals: Sequence[str] | None = None):
        if stamps not in STAMPS:
            raise CosimError(f"time stamps must be one of {', '.join(STAMPS)}, got {stamps!r}")
        if not scene_rate_hz > 0:
            raise CosimError(f"scene rate must be > 0 Hz, got {scene_rate_hz}")
        self.scene_robot = scene_robot
        self.scene_position = list(scene_position) if scene_position else None
        self.scene_period_ns = round(1e9 / scene_rate_hz)
        self.stamps = stamps
        self.reference = None if reference is None else np.asarray(reference, dtype=float)
        self.reference_signals = list(reference_signals) if reference_signals else None
        self.offset_ns: int | None = None
        self._context = None
        self._opened: list[Any] = []

    @property
    def context(self):
        """The ``foxglove.Context`` the channels live in; sinks attach to it before :meth:`start`."""
        if self._context is None:
            import foxglove

            self._context = foxglove.Context()
        return self._context

    def origin(self, rt: Runtime) -> int:
        """Fix (once) and return the offset log time - simulation time, ns."""
        if self.offset_ns is None:
            self.offset_ns = time.time_ns() - rt.start_ns if self.stamps == "wall" else 0
        return self.offset_ns

    def _channel(self, topic: str, schema_name: str, schema: dict, metadata: dict[str, str] | None = None):
        import foxglove

        ch = foxglove.Channel(topic, schema=foxglove.Schema(name=schema_name, encoding="jsonschema",
                                                            data=orjson.dumps(schema)),
                              message_encoding="json", context=self.context, metadata=metadata or {})
        self._opened.append(ch)
        return ch.base.log

    # -- observer protocol
    def start(self, rt: Runtime) -> None:
        from .foxglove_schemas import FRAME_TRANSFORMS, SCENE_UPDATE

        plan = rt.plan
        off = self.origin(rt)
        # per component: the channel's log function, its sources (grouped), the JSON keys, the value reader
        self._channels: list[tuple[Any, list, tuple[str, ...], Any] | None] = []
        for c, name in enumerate(plan.names):
            if not (plan.logged and plan.logged[c]):
                self._channels.append(None)
                continue
            schema, readers = component_schema(rt, c)
            log = self._channel(f"/{name}", f"cosim.{name}", schema,
                                {"fmu": str(plan.infos[c].path.name), "step_multiple": str(rt.multiples[c])})
            keys = tuple(schema["properties"])
            if all(n is None and conv is None for _, _, n, conv in readers):  # plain scalars: grouped reads
                self._channels.append((log, _gather([(arr, i) for arr, i, _, _ in readers]), keys, _values))
            else:
                self._channels.append((log, readers, keys, _values_any))
        self._h_ns = [m * rt.step_ns for m in rt.multiples]
        self._step_ns = rt.step_ns
        self._t0 = rt.start_ns
        self._rt = rt
        self._scene = None
        if self.scene_robot is not None and self.scene_position:
            sources = [rt.where(plan.port(r)) for r in self.scene_position]
            ref_sources = None
            if self.reference is None and self.reference_signals:
                ref_sources = [rt.where(plan.port(r)) for r in self.reference_signals]
            self._scene = (self._channel("/scene", "foxglove.SceneUpdate", SCENE_UPDATE), sources,
                           self._channel("/tf", "foxglove.FrameTransforms", FRAME_TRANSFORMS),
                           self._channel("/scene/reference", "foxglove.SceneUpdate", SCENE_UPDATE), ref_sources)
            keep = max(2, round(_TRAIL_S * 1e9 / self.scene_period_ns) + 1)
            self._trail: deque = deque(maxlen=keep)
            self._ref_points: list = [] if self.reference is None else list(self.reference)
            self._next_scene = rt.start_ns
            self._next_reference = rt.start_ns
        # model-exchange components report their events (time, kind) on one /events channel
        self._event_sources = [(c, s) for c, s in enumerate(rt.slaves) if hasattr(s, "event_log")]
        self._events_log = None
        if self._event_sources:
            self._events_log = self._channel("/events", "cosim.events", EVENTS_SCHEMA)
        for c in range(len(plan.names)):
            self._log(c, rt.start_ns, off)
        self._draw(rt.start_ns)

    def _log(self, c: int, t_ns: int, off: int) -> None:
        ch = self._channels[c]
        if ch is None:
            return
        log, groups, keys, values = ch
        log(orjson.dumps(dict(zip(keys, values(t_ns, groups)))), t_ns + off)

    def _draw(self, t_ns: int) -> None:
        if self._scene is None or t_ns < self._next_scene:
            return
        self._next_scene = t_ns + self.scene_period_ns
        scene_log, sources, tf_log, ref_log, ref_sources = self._scene
        stamp = t_ns + self.offset_ns
        p = [arr[i] for arr, i in sources]
        self._trail.append(p)
        if ref_sources is not None:
            self._ref_points.append([arr[i] for arr, i in ref_sources])
            if len(self._ref_points) > 2 * _REFERENCE_POINTS:  # every other point: the resent line stays bounded
                self._ref_points = self._ref_points[::2]
        msg = scene_update(self.scene_robot, p, stamp, self._trail)
        if msg is not None:
            scene_log(orjson.dumps(msg), stamp)
            tf_log(orjson.dumps(frame_transforms(p, stamp)), stamp)
        if t_ns >= self._next_reference and len(self._ref_points) > 1:
            self._next_reference = t_ns + _REFERENCE_PERIOD_NS
            ref_log(orjson.dumps(reference_update(self._ref_points, stamp)), stamp)

    def _log_events(self) -> None:
        names = self._rt.plan.names
        for c, slave in self._event_sources:
            events = slave.event_log
            if not events:
                continue
            for t, kind in events:
                t = float(t)
                self._events_log(orjson.dumps({"t": t, "component": names[c], "kind": kind}),
                                 round(t * 1e9) + self.offset_ns)
            events.clear()

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        h = self._h_ns
        t_start = self._t0 + k * self._step_ns
        off = self.offset_ns
        dumps = orjson.dumps
        channels = self._channels
        for c in active:
            ch = channels[c]
            if ch is None:
                continue
            stamp = t_start + h[c]  # the end of this component's own (possibly multi-rate) step
            if stamp > t_ns and self._rt.t_end_ns is not None:  # an FMU ended the run: the time reached
                stamp = t_ns
            log, groups, keys, values = ch
            log(dumps(dict(zip(keys, values(stamp, groups)))), stamp + off)
        if self._events_log is not None:
            self._log_events()
        if self._scene is not None and t_ns >= self._next_scene:
            self._draw(t_ns)

    def finish(self, rt: Runtime | None, error: BaseException | None) -> None:
        for ch in self._opened:
            ch.close()
        self._opened.clear()
