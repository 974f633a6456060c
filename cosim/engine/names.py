"""Component names in dotted references (``COMP.VARIABLE``, ``COMP.PARAM`` in ``--set``), and as file names.

A component name may be any text without control characters, as SSP allows (``DP Controller``,
``Ship.Engine``). In a dotted reference the component is everything up to the first dot, so a name
with spaces needs nothing (``DP Controller.gain.kp``). A name that holds a dot, an ``=`` or starts
with a single quote is written in single quotes, with ``\\'`` and ``\\\\`` inside: ``'Ship.Engine'.rpm``.
That is the quoting of FMI 2.0 / 3.0 structured names (``q-name``) and of Modelica (the ``'a.b'``
an FMU exporter writes for such a name), so one rule covers the names users already read in FMUs;
quotes around any other name are allowed too (``'DP Controller'.gain.kp``). The variable part after
the component is never parsed here: FMI variable names keep their own dots and quotes.
"""

from __future__ import annotations

from ..errors import shown

__all__ = ["expand_signal", "name_problem", "quote", "ref", "safe_stem", "split_ref"]

_QUOTE = "'"


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot be a component name (empty, control characters), else None."""
    if not name:
        return "a component name must not be empty"
    bad = next((c for c in name if ord(c) < 32 or ord(c) == 127), None)
    if bad is not None:
        return f"component name {name!r} holds the control character {bad!r}"
    return None


def quote(name: str) -> str:
    """``name`` as the head of a dotted reference: as is, or in single quotes when it holds ``.`` or ``=``
    or starts with a quote."""
    if "." in name or "=" in name or name.startswith(_QUOTE):
        return _QUOTE + name.replace("\\", "\\\\").replace(_QUOTE, "\\" + _QUOTE) + _QUOTE
    return name


def ref(component: str, rest: str) -> str:
    """The dotted reference ``COMP.rest`` (the component quoted if needed)."""
    return f"{quote(component)}.{rest}" if rest else quote(component)


def split_ref(text: str) -> tuple[str, str | None, int]:
    """``(component, rest, end)`` of a dotted reference: ``rest`` is the text after the dot that ends the
    component (None when there is none), ``end`` the index where the component's text ends.

    Raises ValueError for an unterminated quote or text right after a closing quote.
    """
    if not text.startswith(_QUOTE):
        head, dot, rest = text.partition(".")
        return head, (rest if dot else None), len(head)
    out, i = [], 1
    while i < len(text):
        c = text[i]
        if c == "\\" and i + 1 < len(text) and text[i + 1] in (_QUOTE, "\\"):
            out.append(text[i + 1])
            i += 2
        elif c == _QUOTE:
            end = i + 1
            if end == len(text) or text[end] in "=":
                return "".join(out), None, end
            if text[end] != ".":
                # Refused (correctness): a name we cannot split: which component is meant is a guess
                raise ValueError(f"{shown(repr(text))}: expected '.' after the quoted component name {''.join(out)!r}")
            return "".join(out), text[end + 1:], end
        else:
            out.append(c)
            i += 1
    # Refused (correctness): a name we cannot split: which component is meant is a guess
    raise ValueError(f"{shown(repr(text))}: the quoted component name has no closing quote (write ' inside as \\')")


def safe_stem(name: str, default: str = "run") -> str:
    """``name`` as a file name in a folder of ours: letters, digits, ``.``, ``_`` and ``-`` kept, any other
    character ``_``, no leading dot (an SSP's system named ``../../x`` must not put its log outside
    ``runs/``, a component named so not its FMU outside the work folder)."""
    stem = "".join(c if c.isalnum() or c in "._-" else "_" for c in name).lstrip(".")
    return stem or default


def expand_signal(spec: str | list[str]) -> list[str]:
    """``"plant.p"`` -> ``["plant.p.x", "plant.p.y", "plant.p.z"]``; a list is kept as is."""
    if isinstance(spec, list):
        return list(spec)
    return [f"{spec}.{axis}" for axis in "xyz"]
