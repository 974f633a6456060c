"""PythonFMU's libraries in our process: kept loaded, and their interpreter state reset before exit."""

from __future__ import annotations

import atexit
import ctypes
import os
from typing import Any

# Callbacks and library handles handed to FMUs live as long as the process: an FMU may call its
# logger while being freed, and pythonfmu libraries must not be unloaded (GC of their objects crashes).
KEEP_ALIVE: list[Any] = []

# PythonFMU's native wrapper (pythonfmu 0.7.0 and pythonfmu3 0.3.4, PySlaveInstance.cpp) keeps a
# global std::shared_ptr<PyState>: made by the first fmiXInstantiate, reset by the exported
# finalizePythonInterpreter(), which the library's __attribute__((destructor)) also calls. A
# library still loaded when the process exits (the first pythonfmu library a process loads
# stays: its STB_GNU_UNIQUE symbols make it NODELETE, so fmpy's dlclose in freeInstance leaves
# it) is torn down in the wrong order: exit() runs the pointer's static destructor (it frees the
# 128-byte control block), then _dl_fini runs that destructor function, whose reset decrements
# the use count inside the freed block (``lock xadd`` at offset 8; valgrind: "Invalid read of
# size 4 at finalizePythonInterpreter ... inside a block of size 128 free'd"). In a chunk of
# glibc's unsorted bin that word is the low half of its bk pointer, so the next free or malloc
# that walks the bin aborts: "corrupted double-linked list", "free(): corrupted unsorted chunks".
# Resetting the state ourselves while the library is loaded (pythonfmu makes it again at the
# next instantiation) leaves both destructors an empty pointer: no write to freed memory.
PYTHONFMU_LIBRARIES: set[str] = set()  # file names of the PythonFMU libraries this process instantiated


def release_pythonfmu_state(library: str) -> None:
    """Reset the interpreter state of the PythonFMU library ``library`` (a path or the name it was loaded under)
    if it is loaded in this process, through its exported ``finalizePythonInterpreter`` (see above); found without
    loading it (an unloaded library ran its hooks in order). Any other library, or one without the function:
    nothing. Our FMUs register the same reset for the hosts they run in (``fmus/requirements.py``, which runs
    inside the FMU with the standard library alone, so it cannot import this module)."""
    if not hasattr(os, "RTLD_NOLOAD"):  # Windows: pythonfmu resets it from DllMain, in order
        return
    try:
        reset = ctypes.CDLL(library, mode=os.RTLD_NOLOAD | os.RTLD_NOW).finalizePythonInterpreter
    except (OSError, AttributeError):
        return
    reset.argtypes, reset.restype = [], None
    reset()


def _release_pythonfmu_libraries() -> None:
    """At interpreter exit (before ``exit`` runs the libraries' destructors): the PythonFMU libraries
    still loaded, e.g. the process's first one or one whose instance was never freed."""
    for name in sorted(PYTHONFMU_LIBRARIES):
        release_pythonfmu_state(name)


atexit.register(_release_pythonfmu_libraries)
