"""What the command modules share: the numeric option types, the exit codes, and the one way a command prints its
result (readable, or JSON with ``--json``)."""

from __future__ import annotations

import argparse
import json
from typing import Callable

from ..errors import number_option

__all__ = ["EXIT_CHECK_FAILED", "EXIT_OK", "Handler", "MARGIN", "NUMBER", "POSITIVE", "emit"]

NUMBER = number_option()
"""A finite number (every numeric option refuses nan and infinities: :func:`cosim.errors.number_option`)."""
MARGIN = number_option(ge=0, le=1)
POSITIVE = number_option(gt=0)

EXIT_OK = 0
EXIT_CHECK_FAILED = 1

Handler = Callable[[argparse.Namespace], int]


def emit(args: argparse.Namespace, payload: dict, text: str) -> None:
    """``payload`` as JSON with ``--json``, else ``text``, on stdout."""
    if getattr(args, "json", False):
        print(json.dumps(payload, indent=2))
    else:
        print(text)
