"""The run log's writer: component samples encoded as JSON messages and written to MCAP (by foxglove-sdk's MCAP
writer), in this process or in a writer process on another core.

:class:`cosim.observers.publish.Publisher` hands its sinks each component channel's samples in blocks: the stamps and
the *rows* (the bytes of the logged values as the FMU buffers hold them, one row per sample); every other message
(scene, transforms, events) comes encoded. One module per role:

- :mod:`.encode`: a block of samples becomes the channel's messages in its layout (:class:`BlockLayout`,
  :func:`encode_samples`, :func:`encode_block`, :func:`encode_messages`);
- :mod:`.sink`: :class:`LogSink`, one log file fed by the publisher's calls and the recorder's, written by
  foxglove-sdk's MCAP writer (a file never finished has every chunk flushed so far and no summary: ``cosim
  recover`` reads it); :class:`FoxgloveChannels`, what it has in common with the live view;
- :mod:`.process`: :class:`WriterProcess`, the same calls sent through a pipe to a :class:`LogSink` in a child
  process (a fork of the master, or ``python -m cosim.observers.log_writer``, started by :func:`cosim.procs.start`),
  so that encoding, compressing and writing take the other core, not the master's loop;
- :mod:`.mirror`: :class:`RowMirror`, the rows the master has not sent yet, in memory a forked writer shares, so that
  a crash of the master loses no completed step.

The child needs no numpy or fmpy (rows are read with :mod:`struct`): this package imports neither, so an exec'd
child starts in about 0.1 s, a forked one at once.
"""

from .encode import BlockLayout, encode_block, encode_messages, encode_samples, row_format, samples_helper
from .mirror import RowMirror, row_section
from .process import WriterFailed, WriterProcess, _serve, live_view_serving, writer_forks  # noqa: F401 - _serve:
# the writer's loop, which benchmarks/log_writer_process.py times as cosim.observers.log_writer._serve
from .sink import FoxgloveChannels, LogSink, os_reason

__all__ = ["BlockLayout", "FoxgloveChannels", "encode_block", "encode_messages", "encode_samples", "row_format",
           "samples_helper", "LogSink", "RowMirror", "row_section", "WriterProcess", "WriterFailed",
           "live_view_serving", "writer_forks", "os_reason"]
