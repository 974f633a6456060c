"""Test FMU: a source that misbehaves in the step that reaches ``at`` s, as foreign code can in our process.

``mode``: 0 behaves; 1 segfaults (reads address 0); 2 aborts; 3 calls the C library's ``exit(3)``; 4 blocks the
stop signals in its thread and sleeps in C for ``hold`` s with the Python lock held (a call through
``ctypes.PyDLL``): no other thread of the process can run Python, so neither the watchdog nor a signal handler
can act. ``mode`` 5 and 6 do what 1 and 4 do, in ``exitInitializationMode`` instead of a step. ``mode`` 7 ignores the
stop signals and busy-loops in Python for ``hold`` s (the lock taken and given back, but the signals never acted on);
``mode`` 8 starts a process that sleeps ``hold`` s holding the run's stdout and stderr, and goes on normally;
``mode`` 10 stops (SIGSTOP) the processes its own process started (the log writer among them) once and goes on;
``mode`` 11 closes every file descriptor above 2 of its process once (the master's pipes, files and shared memory
among them) and goes on, as a careless daemonising library can."""
import signal
import ctypes
import os
import subprocess
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


def _holding():
    """Say that the stop signals can no longer act: create the file ``$COSIM_T_CRASH_HOLDING`` names, if any."""
    path = os.environ.get("COSIM_T_CRASH_HOLDING")
    if path:
        open(path, "w").close()


def _hold_in_c(seconds):
    """Sleep ``seconds`` in C with the Python lock held; the file says so just before (the call is looked up first,
    so nothing but the call itself comes after it)."""
    sleep = ctypes.PyDLL(None).sleep
    _holding()
    sleep(seconds)


class CosimTCrash(Fmi2Slave):
    author = "cosim tests"
    description = "a source that crashes on purpose"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.mode = 0
        self.at = 0.0
        self.hold = 60.0
        self.y = 0.0
        self.register_variable(Integer("mode", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("at", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("hold", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))

    def exit_initialization_mode(self):
        if self.mode == 5:
            ctypes.string_at(0)
        elif self.mode == 6:
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM, signal.SIGHUP})
            _hold_in_c(int(self.hold))

    def do_step(self, current_time, step_size):
        if current_time + step_size >= self.at - 1e-12:
            if self.mode == 1:
                ctypes.string_at(0)
            elif self.mode == 2:
                os.abort()
            elif self.mode == 3:
                ctypes.CDLL(None).exit(3)
            elif self.mode == 4:
                signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM, signal.SIGHUP})
                _hold_in_c(int(self.hold))
            elif self.mode == 8 and not getattr(self, "_started", False):
                self._started = True
                subprocess.Popen(["sleep", str(int(self.hold))])  # inherits stdout and stderr
            elif self.mode == 10 and not getattr(self, "_started", False):
                self._started = True
                for task in os.listdir("/proc/self/task"):
                    with open(f"/proc/self/task/{task}/children") as f:
                        for child in f.read().split():
                            os.kill(int(child), signal.SIGSTOP)
            elif self.mode == 11 and not getattr(self, "_started", False):
                self._started = True
                os.closerange(3, os.sysconf("SC_OPEN_MAX"))
            elif self.mode == 7:
                for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                    signal.signal(s, signal.SIG_IGN)
                _holding()
                end = time.monotonic() + self.hold
                while time.monotonic() < end:
                    pass
        self.y = current_time + step_size
        return True
