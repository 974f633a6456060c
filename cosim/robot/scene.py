"""The delta robot's 3D scene on the log's ``/scene`` channels: rails or arms, rods, platform, the platform's trail
and the reference path (:class:`cosim.engine.plugins.Scene`, drawn by :class:`cosim.observers.publish.Publisher`)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Sequence

import numpy as np

from delta.kinematics import inverse_kinematics, leg_axes, platform_offsets
from delta.model import build_model
from delta.robots import get_preset

from ..engine.names import expand_signal
from ..engine.structure import SystemStructure
from ..observers.publish import IDENTITY, REFERENCE_POINTS, entity, line, line_of, vec
from . import sections
from .preflight import sampled_positions

__all__ = ["Drawing", "RobotScene", "drawing", "reference_path", "scene"]


class Drawing:
    """A robot's scene: what does not move computed once (the model, the base, the platform offsets),
    what does per call, through the model's scalar formulas (about 30 us a scene)."""

    _SPHERE = {"x": 0.02, "y": 0.02, "z": 0.02}
    _RED = {"r": 0.9, "g": 0.1, "b": 0.1, "a": 1.0}

    def __init__(self, robot) -> None:

        self.robot = robot
        self.model = model = build_model(robot)
        self.offsets = platform_offsets(model).tolist()  # platform joints relative to the platform, (3, 3)
        self.base = model.actuator.radius * leg_axes(model)  # rail tops or motor axes, z = 0
        self.base_line = line(1, self.base, (0.5, 0.5, 0.5, 1.0))

    def update(self, p, t_ns: int, trail: list | None = None) -> dict | None:
        """A ``foxglove.SceneUpdate`` (JSON form) drawing the robot with the platform at ``p`` (3,), m.

        Linear delta: rails, carriages, rods, platform. Rotary delta: base, arms, forearms, platform. ``trail``:
        the platform's recent positions in their JSON form (dicts or fragments), drawn as a line. ``t_ns`` is the
        message's log time. None when ``p`` is unreachable (nothing sensible to draw)."""

        model, actuator = self.model, self.model.actuator
        x, y, z = (float(v) for v in p)
        q, _, _, fault = inverse_kinematics(model, (x, y, z))
        if fault > 0:  # a leg without solution: nothing sensible to draw (a joint beyond its limit is drawn)
            return None
        joints_a = []  # carriage joints or elbows B_i = b_i - l_i(q_i) at p = 0 (as delta.kinematics.actuator_points)
        for qi, (c, s, ox, oy), (bx, by, bz) in zip(q, model.legs, self.offsets):
            lx, ly, lz = actuator.leg(qi, c, s, ox, oy, 0.0, 0.0, 0.0, model.xp)[:3]
            joints_a.append((bx - lx, by - ly, bz - lz))
        joints_p = [(x + bx, y + by, z + bz) for bx, by, bz in self.offsets]  # platform joints
        colour, width = actuator.guide_style
        lines = [line(2, actuator.guides(self.robot, self.base, np.array(joints_a)), colour, width), self.base_line,
                 line(2, [v for pair in zip(joints_a, joints_p) for v in pair], (0.9, 0.6, 0.1, 1.0)),
                 line(1, joints_p, (0.1, 0.7, 0.3, 1.0), 0.01)]
        spheres = [{"pose": {"position": vec(v), "orientation": IDENTITY}, "size": self._SPHERE, "color": self._RED}
                   for v in joints_a + [(x, y, z)]]
        entities = [entity("robot", t_ns, lines, spheres)]
        if trail is not None and len(trail) > 1:
            entities.append(entity("trail", t_ns, [line_of(0, trail, (0.85, 0.1, 0.1, 0.8), 0.003)]))
        return {"deletions": [], "entities": entities}


@lru_cache(maxsize=8)
def drawing(robot) -> Drawing:
    return Drawing(robot)


def reference_path(system: SystemStructure) -> np.ndarray | None:
    """The system's whole reference path (n, 3), m, from its ``trajectory`` section; None without one."""
    if sections.trajectory(system) is None:
        return None

    t0, t1, step = system.seconds()
    n = int(min(REFERENCE_POINTS, max(2, round((t1 - t0) / step) + 1)))
    return sampled_positions(sections.trajectory_object(system), np.linspace(t0, t1, n))


@dataclass
class RobotScene:
    """The scene of one run (:class:`cosim.engine.plugins.Scene`): the robot's drawing, the signals of the
    platform position it follows, its rate, the whole reference path (None: the reference signals so far)."""

    drawing: Drawing
    position: Sequence[str]
    rate_hz: float
    reference: Any

    def update(self, p, t_ns: int, trail: list | None = None) -> dict | None:
        return self.drawing.update(p, t_ns, trail)


def scene(system: SystemStructure) -> RobotScene | None:
    """The scene ``system``'s ``scene`` section asks for (its ``robot`` drawn); None without one."""
    spec, robot = sections.section(system, "scene"), sections.robot(system)
    if spec is None or not robot:
        return None
    return RobotScene(drawing(get_preset(robot)), expand_signal(spec["position"]), spec["rate_hz"],
                      reference_path(system))
