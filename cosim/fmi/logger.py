"""FMU log messages: the FMI 1 / FMI 2 logger dispatch (one native proxy for every instance) and the text shown."""

from __future__ import annotations

import ast
import itertools
import re
import threading
import weakref
from typing import Any, Protocol


class Base(Protocol):
    """What the dispatch uses of an FMU instance (:class:`cosim.fmi.slave.Base` is one; declared here so that
    this module does not depend on the instances, which depend on it)."""

    name: str  # the instance name

    def _on_log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        """One message the FMU logged."""


# FMI 1.0 and 2.0 loggers are variadic; fmpy formats the message in a native proxy that keeps *one*
# global target for both versions (the logger of the instance created last), so every instance gets
# the same dispatcher and is told apart by its first argument: the componentEnvironment it was
# instantiated with (FMI 2, small integers) or, in FMI 1.0, which has none, the component itself (an
# address). An FMI 1.0 component is known only once fmiInstantiate returned; what it logs before
# (a GUID mismatch) names it by instance name (FMI1_INSTANTIATING, only while instantiating).
FMI2_LOG_TARGETS: weakref.WeakValueDictionary[int, "Base"] = weakref.WeakValueDictionary()
FMI1_INSTANTIATING: weakref.WeakValueDictionary[bytes, "Base"] = weakref.WeakValueDictionary()
FMI2_ENVIRONMENTS = itertools.count(1)
_FMI2_LOGGER: Any = None
CALLING = threading.local()
"""``CALLING.slave``: the instance whose lifecycle call (``Base._guard``) this thread is making, if any."""


def _without_environment(instance: bytes | None) -> "Base | None":
    """The instance a message with a NULL componentEnvironment (some exporters' FMUs send one) is about: the one
    whose call this thread is making, else the only live FMI 2 instance of that instance name."""
    caller = getattr(CALLING, "slave", None)
    if caller is not None:
        return caller
    name = (instance or b"").decode("utf-8", "replace")
    named = [s for s in list(FMI2_LOG_TARGETS.values()) if s.name == name]
    return named[0] if len(named) == 1 else None


def fmi2_logger() -> Any:
    """The one logger callback of FMI 1.0 and 2.0 instances (an ``fmi2CallbackLoggerTYPE``; FMI 1.0's type
    has the same signature)."""
    global _FMI2_LOGGER
    if _FMI2_LOGGER is None:
        from fmpy.fmi2 import fmi2CallbackLoggerTYPE  # lazy: --help loads this module without it

        def dispatch(env, instance, status, category, message):  # noqa: ANN001, ANN202
            slave = FMI2_LOG_TARGETS.get(env) if env else _without_environment(instance)
            if slave is None and instance is not None:  # FMI 1.0 while instantiating: by instance name
                slave = FMI1_INSTANTIATING.get(instance)
            if slave is not None:
                slave._on_log(status, category, message)

        _FMI2_LOGGER = fmi2CallbackLoggerTYPE(dispatch)
    return _FMI2_LOGGER


# pythonfmu / pythonfmu3 report a Python exception as this text and the exception's repr
_PY_EXCEPTION = re.compile(r"Fatal py exception encountered: \[[^\]]*\][^\n]*\n(?P<repr>.*)", re.S)
_REPR = re.compile(r"(?P<type>[A-Za-z_][\w.]*)\((?P<args>.*)\)", re.S)


def log_text(message: str) -> str:
    """An FMU's log message as shown to the user: a Python exception reported by pythonfmu as
    ``Fatal py exception encountered: [where] ...\\nType('text')`` becomes ``Type: text``; its ``unknown error`` (the
    text pythonfmu gives an exception it could not fetch: an FMU of ours logged why before raising) is nothing to
    show, so the message before it stays the one an error names."""
    m = _PY_EXCEPTION.match(message)
    if m is None:
        return message
    rep = m["repr"].strip()
    if rep == "unknown error":
        return ""
    r = _REPR.fullmatch(rep)
    if r is not None:
        try:
            args = ast.literal_eval(f"({r['args']},)") if r["args"].strip() else ()
        except (ValueError, SyntaxError):
            return rep
        if len(args) == 1 and isinstance(args[0], str):
            return f"{r['type']}: {args[0]}"
        if not args:
            return r["type"]
    return rep
