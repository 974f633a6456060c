"""What the live view's server logs about its viewers reaches stderr escaped, cut short, and a few lines at most."""

from __future__ import annotations

import io
import logging

from cosim.observers.live import ViewerMessages


def test_viewer_messages_are_escaped_cut_and_counted():
    out = io.StringIO()
    handler = ViewerMessages.attach(out)
    log = logging.getLogger("foxglove_py")
    try:
        log.warning("client sent unknown op '\x1b[2Jgotcha\x1b]0;title\x07'")
        log.warning("x" * 5000)
        for k in range(200):
            log.warning(f"connection {k} closed")
    finally:
        handler.detach()
    lines = out.getvalue().splitlines()
    assert "\x1b" not in out.getvalue() and "\x07" not in out.getvalue(), lines[0]
    assert lines[0] == "warning: live view: client sent unknown op '\\x1b[2Jgotcha\\x1b]0;title\\x07'", lines[0]
    assert lines[1].endswith("... (5000 characters)") and len(lines[1]) < 260, lines[1]
    assert len(lines) == ViewerMessages.SHOWN_LINES + 1, lines
    assert lines[-1] == "warning: live view: 197 more message(s) of its server not shown", lines[-1]
    assert logging.getLogger("foxglove_py").propagate and not logging.getLogger("foxglove_py").handlers
