"""A Foxglove layout for a run's channels (``python -m cosim layout SCENARIO``): the 3D scene beside plots of the
joints, made with foxglove-sdk's ``foxglove.layouts`` and serialised by it.

The 3D panel shows ``/scene`` (the robot and its trail) and ``/scene/reference`` (the reference path) in the frames
``/tf`` carries, from the robot's base; the plots show, per joint ``i``, each component's output ``q[i]`` (the joint
positions: the plant's) against each component's input ``q_ref[i]`` (the reference the controller follows), and each
component's output ``u[i]`` (the joint torques or forces: the controller's), each joint in one colour. A field name
outside the message-path grammar's plain names (``q[1]``, ``p.x``) is quoted, as the grammar allows:
``/plant."q[1]"``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import CosimError
from .publish import frame_transforms

__all__ = ["Channel", "PLOTS", "channels_of", "layout", "message_path", "parse_message_path"]

_PLAIN = re.compile(r"[A-Za-z0-9_-]+")  # a name the message path grammar takes unquoted
_INDEXED = re.compile(r"(.+)\[(\d+)\]")
_COLOURS = ("#4e98e2", "#f5774d", "#61cbff", "#b6e35c", "#ab74f2", "#f7d154")  # joint i: the i-th, in turn

PLOTS = (("joint positions", (("q", "output", "solid"), ("q_ref", "input", "dashed"))),
         ("joint torques and forces", (("u", "output", "solid"),)))
"""Each plot: its title, then the series it draws: (array name, causality, line style) of every component's
variables ``name[i]`` of that causality."""


@dataclass(frozen=True)
class Channel:
    """A component's channel: its topic and, per field of its messages, (name, causality, unit)."""

    topic: str
    fields: Sequence[tuple[str, str, str]]


def _quoted(name: str) -> str:
    return name if _PLAIN.fullmatch(name) else '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def message_path(topic: str, field: str) -> str:
    """The Foxglove message path of ``field`` in ``topic``'s messages: ``/plant."q[1]"``, ``/ctl.t``."""
    plain_topic = topic.startswith("/") and all(not part or _PLAIN.fullmatch(part) for part in topic[1:].split("/"))
    return f"{topic if plain_topic else _quoted(topic)}.{_quoted(field)}"


def parse_message_path(path: str) -> tuple[str, str]:
    """(topic, field) of a path :func:`message_path` wrote (its inverse; for checks)."""
    m = re.fullmatch(r'("(?:[^"\\]|\\.)*"|[^".]+)\.("(?:[^"\\]|\\.)*"|[A-Za-z0-9_-]+)', path)
    if m is None:
        raise ValueError(f"not a topic.field message path: {path!r}")
    return tuple(re.sub(r"\\(.)", r"\1", p[1:-1]) if p.startswith('"') else p for p in m.groups())


def _plot(title: str, wanted, channels: Sequence[Channel]):
    """The plot panel ``title`` of ``wanted``'s series (see :data:`PLOTS`), or None when no channel has any."""
    import foxglove.layouts as fl  # lazy: --help loads this module without it

    series, units = [], []
    for array, causality, style in wanted:
        for ch in channels:
            for name, cause, unit in ch.fields:
                m = _INDEXED.fullmatch(name)
                if m is None or m.group(1) != array or cause != causality:
                    continue
                i = int(m.group(2))
                series.append((i, fl.PlotSeries(value=message_path(ch.topic, name), label=f"{ch.topic[1:]} {name}",
                                                color=_COLOURS[(i - 1) % len(_COLOURS)], line_style=style,
                                                timestamp_method="receiveTime")))
                units.append(unit)
    if not series:
        return None
    label = units[0] if units and len(set(units)) == 1 and units[0] else None
    return fl.PlotPanel(title=title, config=fl.PlotConfig(paths=[s for _, s in sorted(series, key=lambda s: s[0])],
                                                           show_legend=True, y_axis_label=label))


def layout(channels: Sequence[Channel], scene: bool, name: str = "run"):
    """The layout (a ``foxglove.layouts.Layout``) of a run with these component ``channels`` and, when ``scene``,
    the ``/scene``, ``/scene/reference`` and ``/tf`` channels. CosimError when it would show nothing."""
    import foxglove.layouts as fl  # lazy: --help loads this module without it

    plots = [p for p in (_plot(title, wanted, channels) for title, wanted in PLOTS) if p is not None]
    panels = []
    if scene:
        frames = frame_transforms((0.0, 0.0, 0.0), 0)["transforms"]  # the frames /tf carries: world, base, platform
        base = frames[0]["child_frame_id"]
        panels.append(fl.ThreeDeePanel(title=f"{name}: scene", config=fl.ThreeDeeConfig(
            topics={"/scene": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                    "/scene/reference": fl.BaseRendererSceneUpdateTopicSettings(visible=True)},
            transforms={f["child_frame_id"]: fl.BaseRendererLayerSettingsTransform(visible=True) for f in frames},
            follow_tf=base, follow_mode="follow-none")))
    if not panels and not plots:
        raise CosimError(f"layout: {name} has no 3D scene (logging.scene) and no joint signals "
                         f"({', '.join(sorted({a for _, w in PLOTS for a, _, _ in w}))}) to show")
    column = plots[0] if len(plots) == 1 else fl.SplitContainer(direction="column", items=[
        fl.SplitItem(content=p) for p in plots]) if plots else None
    if not panels:
        return fl.Layout(content=column)
    if column is None:
        return fl.Layout(content=panels[0])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=panels[0]), fl.SplitItem(proportion=2, content=column)]))


def channels_of(plan) -> list[Channel]:
    """The component channels a run of ``plan`` (:func:`cosim.engine.prepare.prepare`) logs and serves, as
    :class:`cosim.observers.publish.Publisher` makes them: one per component with logged variables."""
    return [Channel(f"/{name}", [(v.name, v.causality, v.unit or "") for v in plan.logged[c]])
            for c, name in enumerate(plan.names) if plan.logged and plan.logged[c]]
