"""``python -m cosim``: see :mod:`cosim.cli`.

Exit: once the command has finished (its log written and closed, its summary printed), a process
that loaded Exudyn ends with ``os._exit`` after running the ``atexit`` handlers and flushing
stdout and stderr, skipping the interpreter's finalization and the shared libraries' destructors.
Runs that loaded Exudyn sometimes aborted there (``corrupted double-linked list``, exit 134) after
printing their result and finishing their log: 2 in 129 in the issue, 1 in 60 here after a solver
failure, and 1 in 200 of ``benchmarks/exit_stress.py --plain-exit`` (a *completed* run). glibc
finds the heap already corrupted when a shared library's destructor (libGLX's, loaded with
Exudyn's GLFW, or libgfortran's, caught under gdb) frees its buffers in ``exit``, after the
interpreter's finalization. The write that corrupts it was not found: 300 runs of the bare plant
(the same solver failure, no FMUs, no master) never aborted, and glibc's malloc checks (a few runs,
``libc_malloc_debug``) caught nothing earlier. Nothing is left to do at that point, so
finalization is skipped: the exit code and the output are always the run's
(``benchmarks/exit_stress.py``: 200 runs, no abnormal exit).
"""

import sys

from .cli import main


def _exit(code: object) -> None:
    """Leave with ``code`` (as ``sys.exit`` would); without Exudyn loaded, exactly ``sys.exit``."""
    if "exudyn" not in sys.modules:
        sys.exit(code)
    import atexit
    import os

    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # sys.exit("message"): printed, status 1
        print(code, file=sys.stderr)
        status = 1
    try:
        atexit._run_exitfuncs()  # e.g. removal of extracted FMUs
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # closed or broken pipe: nothing more can be written
                pass
        os._exit(status)


if __name__ == "__main__":  # also imported by multiprocessing's spawned workers
    try:
        result = main()
    except SystemExit as stop:
        result = stop.code
    _exit(result)
