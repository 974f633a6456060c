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

import platform
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import orjson

from .algorithm import Runtime
from .fmu import BOOLEAN, INTEGER, REAL

__all__ = ["McapRecorder", "scene_update", "SCENE_SCHEMA"]

_JSON_TYPE = {REAL: "number", INTEGER: "integer", BOOLEAN: "boolean"}


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


class McapRecorder:
    """Observer writing the run to an MCAP file (see the module docstring)."""

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
        w = self._writer = Writer(self._file, compression=CompressionType.ZSTD, chunk_size=256 * 1024)
        w.start(profile="", library="cosim")
        plan = rt.plan
        self._channels: list[tuple[int, list[tuple[Any, int]], tuple[str, ...]] | None] = []
        for c, name in enumerate(plan.names):
            logged = plan.logged[c] if plan.logged else []
            if not logged:
                self._channels.append(None)
                continue
            slave = rt.slaves[c]
            props = {"t": {"type": "number", "description": "simulation time", "unit": "s"}}
            sources = []
            keys = ["t"]
            for v in logged:
                props[v.name] = {"type": _JSON_TYPE.get(v.kind, "string"), "description": v.description or "",
                                 "unit": v.unit or "", "causality": v.causality}
                is_out = v.causality == "output"
                sources.append(slave.locate(v, output=is_out))
                keys.append(v.name)
            schema = {"title": f"cosim.{plan.infos[c].md.modelName}", "type": "object", "properties": props,
                      "description": f"signals of component {name} ({plan.infos[c].path.name})"}
            sid = w.register_schema(name=f"cosim.{name}", encoding="jsonschema", data=orjson.dumps(schema))
            cid = w.register_channel(topic=f"/{name}", message_encoding="json", schema_id=sid,
                                     metadata={"fmu": str(plan.infos[c].path.name),
                                               "step_multiple": str(rt.multiples[c])})
            self._channels.append((cid, sources, tuple(keys)))
        self._h_ns = [m * rt.step_ns for m in rt.multiples]
        self._step_ns = rt.step_ns
        self._scene = None
        if self.scene_robot is not None and self.scene_position:
            sources = [rt.slaves[plan.names.index(r.split(".", 1)[0])].locate(plan.port(r).var) for r in
                       self.scene_position]
            sid = w.register_schema(name="foxglove.SceneUpdate", encoding="jsonschema",
                                    data=orjson.dumps(SCENE_SCHEMA))
            cid = w.register_channel(topic="/scene", message_encoding="json", schema_id=sid)
            self._scene = (cid, sources)
            self._next_scene = rt.start_ns
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
            w.add_attachment(log_time=now, create_time=now, name=f"scenario/{self.scenario_file.name}",
                             media_type="application/yaml", data=self.scenario_file.read_bytes())
        for name, info in zip(rt.plan.names, rt.plan.infos):
            w.add_attachment(log_time=now, create_time=now, name=f"fmu/{name}/modelDescription.xml",
                             media_type="application/xml", data=info.model_description_xml())

    def _log(self, c: int, t_ns: int) -> None:
        ch = self._channels[c]
        if ch is None:
            return
        cid, sources, keys = ch
        vals = [t_ns * 1e-9]
        vals += [arr[i] for arr, i in sources]
        self._writer.add_message(cid, t_ns, orjson.dumps(dict(zip(keys, vals))), t_ns)
        self.messages += 1

    def _draw(self, t_ns: int) -> None:
        if self._scene is None or t_ns < self._next_scene:
            return
        self._next_scene = t_ns + self.scene_period_ns
        cid, sources = self._scene
        msg = scene_update(self.scene_robot, [arr[i] for arr, i in sources], t_ns)
        if msg is not None:
            self._writer.add_message(cid, t_ns, orjson.dumps(msg), t_ns)
            self.messages += 1

    def stepped(self, k: int, t_ns: int, active: Sequence[int]) -> None:
        h = self._h_ns
        t_start = t_ns - self._step_ns
        add = self._writer.add_message
        for c in active:
            ch = self._channels[c]
            if ch is None:
                continue
            stamp = t_start + h[c]  # the end of this component's own (possibly multi-rate) step
            cid, sources, keys = ch
            vals = [stamp * 1e-9]
            vals += [arr[i] for arr, i in sources]
            add(cid, stamp, orjson.dumps(dict(zip(keys, vals))), stamp)
        self.messages += len(active)
        if self._scene is not None and t_ns >= self._next_scene:
            self._draw(t_ns)
        if time.monotonic() - self._last_flush > self.flush_interval:
            self._writer.flush()
            self._last_flush = time.monotonic()

    def finish(self, rt: Runtime | None, error: BaseException | None) -> None:
        if self._writer is None:
            return
        try:
            if error is not None:
                self._writer.add_metadata("outcome", {"status": "error" if not isinstance(
                    error, KeyboardInterrupt) else "interrupted", "message": str(error) or type(error).__name__,
                    "completed_steps": str(rt.k_done if rt else 0)})
            else:
                self._writer.add_metadata("outcome", {"status": "completed",
                                                      "completed_steps": str(rt.k_done if rt else 0)})
            self._writer.finish()
        finally:
            self._writer = None
            self._file.close()
