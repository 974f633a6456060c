"""``python -m cosim``: see :mod:`cosim.cli`.

Exit: once the command has finished (its log written and closed, its summary printed), the
process ends with ``os._exit`` after running the ``atexit`` handlers and flushing stdout and
stderr, skipping the interpreter's finalization and the shared libraries' destructors.

Why: runs sometimes aborted there, after printing their result (``corrupted double-linked
list``, ``free(): corrupted unsorted chunks``, exit 134), with Exudyn loaded and without it
(``helix_ctc_analytic``). The write that corrupts the heap is PythonFMU's (0.7.0; pythonfmu3
0.3.4 has the same code), in the process's first PythonFMU library, which stays loaded to the
end: ``exit`` runs the static destructor of its global ``std::shared_ptr<PyState>`` (freeing the
control block), then ``_dl_fini`` runs the library's destructor function,
``finalizePythonInterpreter``, which decrements the use count inside the freed block. valgrind::

    Invalid read of size 4
       at finalizePythonInterpreter (in .../binaries/linux64/helix.so)
       by _dl_call_fini / _dl_fini / __run_exit_handlers / exit
     Address ... is 8 bytes inside a block of size 128 free'd
       at operator delete / __run_exit_handlers / exit
     Block was alloc'd at operator new / pythonfmu::createInstance / fmi2Instantiate

(the instruction is ``lock xadd`` on that word: in a chunk of glibc's unsorted bin it is the bk
pointer, which the next free walking the bin finds corrupt, e.g. in libGLX's or libgfortran's
destructor when Exudyn is loaded). :mod:`cosim.fmi.pythonfmu` now resets that state itself before the
library is unloaded or the process exits, which removes the write (valgrind: no invalid access
left). This exit stays as a second guard for what third-party destructors may still do after
the command's work is done: nothing is left to finalize, and the exit code and the output are
always the command's.
"""

import atexit
import os
import sys
import traceback

from .cli import main
from .engine import supervision
from .errors import exit_now, printable


def _exit(code: object) -> None:
    """Leave with ``code`` as ``sys.exit`` would, without the interpreter's finalization."""
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # sys.exit("message"): printed, status 1
        print(code, file=sys.stderr)
        status = 1
    try:
        threading = sys.modules.get("threading")
        if threading is not None and hasattr(threading, "_shutdown"):
            threading._shutdown()  # as at a normal exit: non-daemon threads end first
        atexit._run_exitfuncs()  # e.g. removal of extracted FMUs
    finally:
        supervision.finished()  # a supervised run's child ends through here: not a crash
        exit_now(status)


def _internal_error(exc: Exception) -> int:
    """An exception no command turned into its error (a defect): one line naming it and where it was raised, exit 2;
    the whole traceback with ``COSIM_TRACEBACK=1``. Without this the interpreter printed the traceback and the
    supervisor reported the exit as 'an exit() inside a component'."""
    if os.environ.get("COSIM_TRACEBACK"):
        traceback.print_exception(exc)
    frame = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" at {os.path.basename(frame.filename)}:{frame.lineno}" if frame else ""
    text = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
    print(printable(f"error: internal error ({text}){where}; a defect of delta-cosim, not of the input alone: "
                    "please report it with the command line (COSIM_TRACEBACK=1 shows the traceback)"),
          file=sys.stderr)
    return 2


if __name__ == "__main__":  # also imported by multiprocessing's spawned workers
    supervision.ENABLED = True  # `run` forks its supervisor here, never in a library user's process
    try:
        result = main()
    except SystemExit as stop:
        result = stop.code
    except Exception as exc:  # a defect of ours that an input reached: one line, never "an exit() in a component"
        result = _internal_error(exc)
    _exit(result)
