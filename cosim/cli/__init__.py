"""Command line: ``python -m cosim <command> ...``.

The CLI is thin: each subcommand parses its options, calls one library
function and prints the result (readable, or JSON with ``--json``). Heavy
imports happen inside the command that needs them. Errors print one line on
stderr (one line per issue for a scenario) and exit non-zero: 2 for an
unreachable pose, bad input or a failed FMU, 1 for a failed acceptance check,
130 on Ctrl-C and 143 on SIGTERM (the MCAP log is finished first). With ``--json`` an
error is also a JSON object ``{"ok": false, "error": ...}`` on stdout.

Every command is registered the same way: a command module has ``register(subparsers)``, which adds its
parsers and sets each one's ``handler`` (and ``supervised=True`` for a command that loads FMUs in this
process: run, check and compare, run under the supervisor of :mod:`cosim.engine.supervision`); this package
lists them (:data:`COMMANDS`, in the order of ``--help``). A module registers without importing anything
heavy: each handler imports its command's modules inside it, so that ``--help`` starts in a fraction of a
second.
"""

from __future__ import annotations

import argparse
import os
import json
import sys
from typing import Sequence

from fmus import cli as fmus_cli

from ..errors import EXIT_BAD_INPUT, STOP_SIGNALS, exit_status, exit_text, user_errors
from . import calibrate, compare, export, layout, report, robot, run, ssp, sweep
from .common import EXIT_OK, Handler

__all__ = ["COMMANDS", "build_parser", "main"]

COMMANDS = (robot, run, compare, calibrate, report, export, layout, ssp, sweep, fmus_cli)
"""The command modules, each with ``register(subparsers)``, in the order ``--help`` lists their commands."""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("delta-cosim")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


class _Version(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked (reading the installed
    distributions' metadata cost every command about 15 ms of its start)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str = "show program's version number and exit"):  # noqa: A002
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):  # noqa: ANN001 - argparse's signature
        parser._print_message(f"{parser.prog} (delta-cosim) {_version()}\n", sys.stdout)
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m cosim", description="Delta robot FMI co-simulation platform")
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    return parser


def _leaf(parser: argparse.ArgumentParser, argv: Sequence[str]) -> argparse.ArgumentParser:
    """The (sub)parser the command line selected: ``run``, ``robot ik``, ..."""
    while True:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            return parser
        chosen = next((a.choices[w] for a in subs for w in argv if w in a.choices), None)
        if chosen is None:
            return parser
        parser, argv = chosen, argv[list(argv).index(chosen.prog.split()[-1]) + 1:]


def _unknown(parser: argparse.ArgumentParser, argv: Sequence[str], extra: list[str]) -> None:
    """argparse's 'unrecognized arguments' with the closest options of the command (exit 2)."""
    import difflib

    leaf = _leaf(parser, argv)
    options = [o for a in leaf._actions for o in a.option_strings]
    hints = []
    for word in extra:
        if word.startswith("-"):
            close = difflib.get_close_matches(word.split("=", 1)[0], options, n=2, cutoff=0.75)
            if close:
                hints.append(f"{word}: did you mean {' or '.join(close)}?")
    leaf.error(f"unrecognized arguments: {' '.join(extra)}" + ("; " + "; ".join(hints) if hints else ""))


class _Parser(argparse.ArgumentParser):
    """argparse with a close-match hint for an invalid command (Python 3.14's suggest_on_error);
    subparsers are of the same class (``add_subparsers`` uses ``type(self)``)."""

    def error(self, message: str):
        import difflib
        import re

        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = re.findall(r"'([^']*)'", m.group(2)) or [c.strip() for c in m.group(2).split(",")]
            close = difflib.get_close_matches(m.group(1), choices, n=2, cutoff=0.6)
            if close:
                message += f"; did you mean {' or '.join(close)}?"
        self.print_usage(sys.stderr)
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        exc = SystemExit(EXIT_BAD_INPUT)
        exc.message = f"{self.prog}: {message}"  # for --json's error object (main)
        raise exc


def _crashed(args: argparse.Namespace, record, reason: str) -> int:
    """The supervisor's report of a run (or a check) whose process died inside a component (cosim.engine.supervision): one
    line naming the component, the phase, the time and how it died, then where the log written so far is."""
    from ..fmi.extract import sweep_orphans
    from ..io.recover import recover_crashed

    sweep_orphans()  # the FMUs the dead child extracted
    message = f"{record.where()} {reason}"
    lines = [exit_text(message, "crash")]
    _, where = recover_crashed(record.info())
    if where is not None:
        lines.append(where)
    _error_json(args, message, "crash")
    print("\n".join(lines), file=sys.stderr)
    return EXIT_BAD_INPUT  # an error (2): the run failed


def _terminate_as_interrupt(signum, frame) -> None:
    """SIGTERM or SIGHUP outside the simulation loop: unwind like Ctrl-C (logs finished, worker stopped)."""
    from ..errors import Interrupted

    raise Interrupted(signum)


def _error_json(args: argparse.Namespace | None, text: str, kind: str) -> None:
    """With --json the error is a JSON object on stdout too, so a reader always gets one."""
    if args is not None and getattr(args, "json", False):
        print(json.dumps({"ok": False, "error": text, "kind": kind}, indent=2))


def _lenient_output() -> None:
    """Text a stream's encoding cannot carry (a non-ASCII path or name on an ASCII stdout, ``PYTHONIOENCODING=ascii``)
    written as escapes instead of failing the command after its work is done (a completed run ended with exit 2
    printing its summary). A stream that already has a lenient error handler (surrogateescape under the C locale)
    keeps it."""
    for stream in (sys.stdout, sys.stderr):
        if getattr(stream, "errors", None) == "strict" and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # a stream that cannot change now: as it is
                pass


def main(argv: Sequence[str] | None = None) -> int:
    import signal

    argv = list(sys.argv[1:] if argv is None else argv)
    _lenient_output()
    try:
        os.getcwd()  # relative paths, the FMU cache and default logs are all under it
    except FileNotFoundError:
        print(exit_text("the working folder no longer exists (deleted or moved after this shell entered it): cd to "
                        "an existing folder and run again", "error"), file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
        if extra:
            _unknown(parser, argv, extra)
    except KeyboardInterrupt as exc:  # Ctrl-C while starting (imports): interrupted, no traceback
        message, kind, code = exit_status(exc)
        print(exit_text(message, kind), file=sys.stderr)
        return code
    except SystemExit as exc:  # a usage error (a bad option or value): with --json, a JSON object on stdout too
        if exc.code == EXIT_BAD_INPUT and "--json" in argv:
            print(json.dumps({"ok": False, "error": getattr(exc, "message", "invalid arguments"), "kind": "usage"},
                             indent=2))
        raise
    handler: Handler = args.handler
    if threading_main():  # the same shutdown path as Ctrl-C (logs finished, worker stopped, temp files removed)
        for sig in STOP_SIGNALS:
            if sig != signal.SIGINT:  # Ctrl-C raises KeyboardInterrupt by itself
                signal.signal(sig, _terminate_as_interrupt)
    try:
        if getattr(args, "supervised", False):  # commands that load and call FMUs: a supervisor names a crash inside one
            from ..engine import supervision

            code = supervision.supervise(lambda record, reason: _crashed(args, record, reason))
            if code is not None:  # the supervisor: the command went on in its child process
                return code
        return handler(args)
    except (*_user_errors(), KeyboardInterrupt) as exc:
        message, kind, code = exit_status(exc)
        _error_json(args, message, kind)
        print(exit_text(message, kind), file=sys.stderr)
        return code
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. `| head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK


def _user_errors() -> tuple[type[BaseException], ...]:
    """The errors a command ends on with one line: the master's and those of the domains plugged in (their
    plugins loaded now if no command did)."""
    from ..engine import plugins

    plugins.installed()
    return user_errors()


def threading_main() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()
