"""Robot recordings read into arrays: ROS 2 bags (MCAP or SQLite), ROS 1 bags, CSV files and our own run logs.

The API (docs/recordings.md is the user's page)::

    from cosim.io.recordings import read_recording
    rec = read_recording("robot_bag/", {"q1": "/joint_states.position[joint1]",
                                        "x": "/tcp_pose.pose.position.x"}, time="header")
    rec.times["q1"], rec.values["q1"], rec.units["q1"]   # (n,) s from the first message, (n,), unit
    rec.sample("q1", t, interpolation="linear")          # or "hold"
    rec.converted("q1", "deg")                           # in another unit (cosim.io.recordings.units)

``read_recording(path, specs, *, time="header"|"log", time_origin="first"|"absolute", units=None, window=None)``
-> :class:`Recording` (``times``, ``values``, ``units`` by name; ``source``, ``kind``, ``end_note`` where a cut
bag ended, ``origin_s`` the absolute time subtracted).

Signal specs (``specs``: name -> spec):

- a bag's field by path: ``/topic.field.sub[3]`` (0-based index); ``[NAME]`` selects a JointState element by
  joint name (``/joint_states.position[joint1]``, ``.velocity[...]``, ``.effort[...]``) or, in an array of
  messages, the one whose ``child_frame_id`` or ``name`` is NAME (``/tf.transforms[tool0].transform.rotation.w``);
  PoseStamped ``/tcp.pose.position.x``, TransformStamped ``/t.transform.translation.x``;
- a CSV column by its name (``q1``; header ``time [s],q1 [deg]``, see :mod:`.csvfile`);
- a signal of our run log (``ctl.q[1]``), read by :func:`cosim.io.runlog.read_run`.

Time: a bag's ``header`` stamps (of the innermost message on the path with a header) or ``log`` (receive)
times, as the caller chooses; counted from the earliest stamp of the signals read unless
``time_origin="absolute"``. Units: bags carry none (give them in ``units``); a CSV column's is in its header; our
logs' are the FMUs'. ``units[name]`` asks for a unit: a recorded one converts to it, none is taken as it.

Every problem is one line (:class:`RecordingError`, a ``CosimError``): unknown topic (with the topics and the
closest), field or joint; no messages (in the window); time not increasing; NaN; units that do not convert; a bag
that cannot be opened. A ROS 2 MCAP bag cut short is read up to where it ends, with ``end_note`` saying so.
Memory: only the selected topics' messages are deserialised, one at a time (benchmarks/recording_read.py).

This package is generic: it imports nothing of ``delta``, ``fmus`` or ``multibody``.
"""

from __future__ import annotations

from .errors import RecordingError
from .recording import RECORDING_SUFFIXES, Recording, read_recording, recording_kind
from .units import UNITS, convert, unit_factor

__all__ = ["RecordingError", "Recording", "read_recording", "recording_kind", "RECORDING_SUFFIXES", "UNITS",
           "convert", "unit_factor"]
