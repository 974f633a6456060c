"""The bounds of a sweep, which its command line checks too: a module of its own, so that ``python -m cosim
--help`` reads them without loading the sweep (:mod:`cosim.analysis.sweep`)."""

from __future__ import annotations

import os

__all__ = ["MAX_CASES", "MAX_WORKERS"]

MAX_CASES = 1_000_000
"""Cases one sweep may hold (its table and case list live in memory; at 0.1 s a case that is a day on 2 workers)."""

MAX_WORKERS = 4 * (os.cpu_count() or 1)
"""Processes of the embedded cluster, at most: more only share the same CPUs (each case is single-threaded), and
each costs its memory and start-up (a hundred thousand never started, and the sweep hung)."""
