"""FMU log text reaches the terminal as text, not as control sequences (issue 25)."""

from cosim.errors import exit_text, printable


def test_escape_sequences_and_fake_lines_are_shown_escaped():
    raw = "step failed\x1b[2J\x1b]0;title\x07\nTraceback (most recent call last):\r\n\tFile"
    shown = printable(raw)
    assert "\x1b" not in shown and "\n" not in shown and "\r" not in shown and "\x07" not in shown, repr(shown)
    assert shown == "step failed\\x1b[2J\\x1b]0;title\\x07\\nTraceback (most recent call last):\\r\\n File", shown


def test_plain_text_is_unchanged():
    text = "t = 0.25 s: leg 1 has no solution (p = (0.1, 0.0, -0.45) m) é"
    assert printable(text) == text


def test_an_error_quoting_an_fmu_reaches_the_terminal_escaped_line_by_line():
    """Every error line is printable, whatever it quotes (a variable name, a description); issue lines stay lines."""
    text = exit_text("component 'x': variable \"\x1b]0;pwned\x07v\" is unknown\nsecond issue", "error")
    assert text == "error:\ncomponent 'x': variable \"\\x1b]0;pwned\\x07v\" is unknown\nsecond issue", text
