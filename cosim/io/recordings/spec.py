"""Signal specs: which value of a recording a name stands for.

``/topic.field.sub[3]`` selects a numeric field of a bag's topic by path (fields by name, array elements by a
0-based index); ``[NAME]`` selects by name: in a ``sensor_msgs/msg/JointState`` an element of ``position``,
``velocity`` or ``effort`` by the joint's name (``/joint_states.position[joint1]``), in an array of messages the
one whose ``child_frame_id`` (or ``name``) is NAME (``/tf.transforms[tool0].transform.translation.x``).
Any other spec names a column of a CSV file (``q1``) or a signal of our run log (``ctl.q[1]``), verbatim.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass

import numpy as np

from ...errors import shown
from .errors import RecordingError

__all__ = ["BagSpec", "parse_bag_spec", "Resolver"]

_TOKEN = re.compile(r"\.([A-Za-z_][A-Za-z0-9_]*)|\[([^\]]+)\]")


@dataclass(frozen=True)
class BagSpec:
    """A parsed ``/topic.path`` spec: the topic and the steps of its path (a field name, an int index or a
    str key)."""

    text: str
    topic: str
    steps: tuple[str | int | tuple[str], ...]  # a field: str; an index: int; a key by name: (name,)


def parse_bag_spec(text: str) -> BagSpec:
    """``"/joint_states.position[joint1]"`` -> BagSpec; a spec without a field path is one line saying so."""
    m = re.match(r"(/[A-Za-z0-9_/~]*)", text)
    topic = m.group(1).rstrip("/") if m else ""
    rest = text[m.end():] if m else text
    steps: list = []
    pos = 0
    while pos < len(rest):
        t = _TOKEN.match(rest, pos)
        if t is None:
            # Refused (correctness): a signal name we cannot read: which field is meant is a guess
            raise RecordingError(f"signal {shown(repr(text))}: cannot read {shown(repr(rest[pos:]))}; a bag signal is /TOPIC.FIELD.SUB[INDEX] "
                                 "(e.g. /joint_states.position[joint1], /tcp_pose.pose.position.x)")
        field, sel = t.groups()
        if field is not None:
            steps.append(field)
        else:
            sel = sel.strip()
            steps.append(int(sel) if re.fullmatch(r"\d+", sel) else (sel,))
        pos = t.end()
    if not topic or not steps or not isinstance(steps[0], str):
        # Refused (correctness): a signal name we cannot read: which field is meant is a guess
        raise RecordingError(f"signal {shown(repr(text))}: a bag signal is /TOPIC.FIELD... naming a numeric field (e.g. "
                             "/joint_states.position[joint1], /tcp_pose.pose.position.x)")
    return BagSpec(text, topic, tuple(steps))


def _fields(obj) -> list[str]:
    names = list(getattr(type(obj), "__dataclass_fields__", {})) or dir(obj)
    return [k for k in names if not k.startswith("_")]


def _hint(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=2)
    return f"; did you mean {' or '.join(close)}?" if close else ""


class Resolver:
    """The value a :class:`BagSpec` selects in each message of its topic, and the header stamp nearest to it.

    The position of a keyed element is looked up once and checked on each message (a cheap compare), so a
    1 kHz topic is read at the pace of its deserialisation. ``where`` prefixes every message (the file)."""

    def __init__(self, spec: BagSpec, msgtype: str, where: str) -> None:
        self.spec, self.msgtype, self.where = spec, msgtype, where
        self._cache: dict[int, int] = {}  # step number -> element position found for its key

    def _fail(self, what: str, index: int | None = None, t_s: float | None = None) -> RecordingError:
        at = f" (message {index}, log time {t_s:.6f} s)" if index is not None and t_s is not None else ""
        return RecordingError(f"{self.where}: {self.spec.text}: {what}{at}")

    def value(self, msg, index: int = 0, t_s: float = 0.0) -> tuple[float, object]:
        """(the selected number, the innermost object on the path that has a ``header``: for its stamp)."""
        obj, parent, stamped = msg, None, msg if hasattr(msg, "header") else None
        for k, step in enumerate(self.spec.steps):
            if isinstance(step, str):
                if not hasattr(obj, step):
                    fields = _fields(obj)
                    kind = getattr(type(obj), "__msgtype__", type(obj).__name__)
                    # Refused (correctness): a field the message does not have
                    raise self._fail(f"no field {step!r} in {kind} (fields: {', '.join(fields)}){_hint(step, fields)}")
                parent, obj = obj, getattr(obj, step)
            else:
                obj, parent = self._element(obj, parent, step, k, index, t_s), obj
            if hasattr(obj, "header"):
                stamped = obj
        if isinstance(obj, (bool, np.bool_)) or not isinstance(obj, (int, float, np.integer, np.floating)):
            what = type(obj).__name__ if not hasattr(obj, "__len__") else f"an array of {len(obj)}"
            # Refused (correctness): no number to replay: which element is meant is a guess
            raise self._fail(f"is {what}, not a number; select one element ([0], [NAME]) or a numeric field",
                             index, t_s)
        return float(obj), stamped

    def _element(self, seq, parent, step, k: int, index: int, t_s: float):
        if not hasattr(seq, "__len__") or isinstance(seq, (str, bytes)):
            # Refused (correctness): an index into something that is no array
            raise self._fail(f"[{step if isinstance(step, int) else step[0]}] applied to {type(seq).__name__}, "
                             "not an array", index, t_s)
        n = len(seq)
        if isinstance(step, int):
            if step >= n:
                # Refused (correctness): an element the array does not have
                raise self._fail(f"index [{step}] out of range: the array has {n} element(s)", index, t_s)
            return seq[step]
        key = step[0]
        names = self._names(seq, parent)
        pos = self._cache.get(k)
        if pos is None or pos >= len(names) or names[pos] != key:
            if key not in names:
                shown = ", ".join(map(str, names[:12])) or "none"
                what = "joint" if parent is not None and hasattr(parent, "name") else "element"
                # Refused (correctness): a name the array does not have
                raise self._fail(f"no {what} named {key!r} (names: {shown}){_hint(key, list(map(str, names)))}",
                                 index, t_s)
            pos = self._cache[k] = names.index(key)
        if pos >= n:
            # Refused (correctness): names and values do not pair: which value is meant is a guess
            raise self._fail(f"{key!r} is name {pos + 1} of {len(names)} but the array has {n} element(s) "
                             "(an empty position, velocity or effort?)", index, t_s)
        return seq[pos]

    @staticmethod
    def _names(seq, parent) -> list:
        """The names that key an array: a JointState's ``name`` for its parallel arrays, else each element's
        ``child_frame_id`` (transforms) or ``name``."""
        if parent is not None and isinstance(getattr(parent, "name", None), list):
            return parent.name
        for attr in ("child_frame_id", "name"):
            if len(seq) and hasattr(seq[0], attr):
                return [getattr(e, attr) for e in seq]
        return []
