"""A recording read: :func:`read_recording` (the formats, by the path) and :class:`Recording` (per signal its
times, values and unit, sampled at any time)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Mapping

import numpy as np

from ...errors import CosimError, file_problem
from ..runlog import read_run
from .bags import bag_kind, read_bag
from .csvfile import read_csv
from .errors import RecordingError
from .spec import parse_bag_spec
from .units import convert

__all__ = ["Recording", "read_recording", "recording_kind", "RECORDING_SUFFIXES"]

RECORDING_SUFFIXES = (".mcap", ".db3", ".bag", ".csv")


@dataclass
class Recording:
    """Signals of one recording, by the names the caller gave them.

    ``times[name]`` (n,) s, strictly increasing (from the time origin); ``values[name]`` (n,) in
    ``units[name]`` ('' when neither the file nor the caller said); ``source``: the file; ``kind``: 'ros2',
    'ros1', 'csv' or 'log'; ``end_note``: where a cut bag ended ('' when it was read whole); ``origin_s``: the
    absolute time (s) subtracted from every stamp (0 with ``time_origin='absolute'``), ``origin_ns`` the same in
    whole nanoseconds (exact)."""

    source: Path
    kind: str
    times: dict[str, np.ndarray] = field(default_factory=dict)
    values: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    end_note: str = ""
    origin_s: float = 0.0
    origin_ns: int = 0

    @property
    def names(self) -> list[str]:
        return list(self.values)

    def span(self, name: str) -> tuple[float, float]:
        t = self.times[name]
        return float(t[0]), float(t[-1])

    def sample(self, name: str, t: np.ndarray | float, interpolation: Literal["linear", "hold"] = "linear"
               ) -> np.ndarray:
        """``name``'s values at times ``t`` (s, same origin): linear between samples, or held from the last
        sample at or before ``t`` (a zero-order hold, as a recorder saw it). Outside the recorded span the first
        or last value is held; callers check the span (:meth:`span`) when that matters."""
        times, values = self.times[name], self.values[name]
        tt = np.asarray(t, dtype=float)
        if interpolation == "linear":
            return np.interp(tt, times, values)
        if interpolation == "hold":
            i = np.clip(np.searchsorted(times, tt, side="right") - 1, 0, len(times) - 1)
            return values[i]
        # Refused (correctness): an interpolation we do not know: the replayed values would be a guess
        raise CosimError(f"interpolation {interpolation!r}: valid: linear, hold")

    def converted(self, name: str, unit: str) -> np.ndarray:
        """``name``'s values in ``unit`` (RecordingError when its unit does not convert; a signal without a unit
        is taken as already in ``unit``)."""
        have = self.units[name]
        return self.values[name] if not have else convert(self.values[name], have, unit,
                                                          f"{self.source}: {name}")


def recording_kind(path: str | Path) -> str | None:
    """'ros2', 'ros1', 'csv' or 'log' (our run log) for a path that is a recording, else None."""
    path = Path(path)
    if path.suffix == ".csv":
        return "csv"
    kind = bag_kind(path)
    if kind is not None:
        return kind
    return "log" if path.suffix == ".mcap" else None


def read_recording(path: str | Path, specs: Mapping[str, str], *, time: Literal["header", "log"] = "header",
                   time_origin: Literal["first", "absolute"] = "first", units: Mapping[str, str] | None = None,
                   window: tuple[float, float] | None = None) -> Recording:
    """Read the signals ``specs`` (name -> spec, see :mod:`cosim.io.recordings`) of the recording at ``path``.

    ``time``: a bag's 'header' stamps or 'log' (receive) times (CSV files and our logs have one time);
    ``time_origin``: 'first' counts from the earliest stamp of the signals read, 'absolute' keeps the stamps
    (s since the epoch in a bag); ``units``: name -> the unit the caller wants (a recorded unit is converted to
    it; a signal recorded without one is taken to be in it); ``window``: (start, stop) s after the origin.
    Raises RecordingError (one line) for what cannot be read; a cut bag reads what it holds (``end_note``)."""
    path = Path(path)
    if time not in ("header", "log"):
        # Refused (correctness): a time base we do not know: each sample's time would be a guess
        raise RecordingError(f"time {time!r}: valid: header (the messages' stamps), log (receive times)")
    if time_origin not in ("first", "absolute"):
        # Refused (correctness): a time origin we do not know: each sample's time would be a guess
        raise RecordingError(f"time_origin {time_origin!r}: valid: first, absolute")
    if not specs:
        # Refused (correctness): nothing to read
        raise RecordingError(f"{path}: no signal asked for")
    problem = file_problem(path, directory_ok=True)
    if problem is not None:
        # Refused (security): a FIFO or a device named as a recording would be read for ever
        raise RecordingError(f"{path}: {problem}")
    kind = recording_kind(path)
    if kind is None:
        # Refused (correctness): a file of no format we read
        raise RecordingError(f"{path}: not a recording (a ROS 2 bag folder or .mcap/.db3 file, a ROS 1 .bag, a "
                             ".csv, or a run log .mcap)")
    t_ns: dict[str, np.ndarray] = {}
    vals: dict[str, np.ndarray] = {}
    got_units: dict[str, str] = {n: "" for n in specs}
    end_note = ""
    if kind in ("ros1", "ros2"):
        read = read_bag(path, {n: parse_bag_spec(s) for n, s in specs.items()}, time)
        for n in specs:
            t_ns[n] = np.asarray(read.t_ns[n], dtype=np.int64)
            vals[n] = np.asarray(read.values[n], dtype=float)
        end_note = read.end_note
    elif kind == "csv":
        t, columns, got_units = read_csv(path, specs)
        for n in specs:
            t_ns[n] = np.round(t * 1e9).astype(np.int64)
            vals[n] = columns[n]
    else:
        log = read_run(path)
        for n, s in specs.items():
            sig = log.signal(s)
            t_ns[n], vals[n], got_units[n] = sig.t_ns, np.asarray(sig.y, dtype=float), sig.unit
    return _finish(path, kind, specs, t_ns, vals, got_units, dict(units or {}), time_origin, window, end_note)


def _finish(path: Path, kind: str, specs: Mapping[str, str], t_ns: dict, vals: dict, got_units: dict,
            units: dict, time_origin: str, window: tuple[float, float] | None, end_note: str) -> Recording:
    """Checks (messages, monotonic time, NaN), the time origin, the window and the units."""
    for n, s in specs.items():
        if not len(t_ns[n]):
            # Refused (correctness): no samples: nothing to replay
            raise RecordingError(f"{path}: {s}: no messages" + (f" ({end_note})" if end_note else ""))
    origin_ns = min(int(t[0]) for t in t_ns.values()) if time_origin == "first" else 0
    if end_note:
        end_note += f"; read up to t = {(max(int(t[-1]) for t in t_ns.values()) - origin_ns) * 1e-9:.6g} s"
    rec = Recording(path, kind, end_note=end_note, origin_s=origin_ns * 1e-9, origin_ns=origin_ns)
    for n, s in specs.items():
        t = (t_ns[n] - origin_ns) * 1e-9
        bad = np.flatnonzero(np.diff(t_ns[n]) <= 0)
        if len(bad):
            i = int(bad[0]) + 1
            # Refused (correctness): two values at one time, or out of order: interpolation between them is a guess
            raise RecordingError(f"{path}: {s}: time is not increasing at sample {i} (t = {t[i]:.9g} s after "
                                 f"{t[i - 1]:.9g} s); a bag's header stamps can be out of order: read with "
                                 "time: log")
        nan = np.flatnonzero(~np.isfinite(vals[n]))
        if len(nan):
            i = int(nan[0])
            # Refused (correctness): a NaN or inf sample would drive the FMUs with a non-finite value
            raise RecordingError(f"{path}: {s}: {vals[n][i]} at sample {i} (t = {t[i]:.9g} s)"
                                 + (f", and {len(nan) - 1} more" if len(nan) > 1 else ""))
        y = vals[n]
        if window is not None:
            keep = (t >= window[0]) & (t <= window[1])
            if not keep.any():
                # Refused (correctness): no samples in the window: nothing to replay
                raise RecordingError(f"{path}: {s}: no messages in t = {window[0]:g} .. {window[1]:g} s (it has "
                                     f"{t[0]:.6g} .. {t[-1]:.6g} s)")
            t, y = t[keep], y[keep]
        unit = got_units.get(n, "")
        if n in units and units[n] != unit:
            y = convert(y, unit, units[n], f"{path}: {s}") if unit else y
            unit = units[n]
        rec.times[n], rec.values[n], rec.units[n] = t, y, unit
    return rec
