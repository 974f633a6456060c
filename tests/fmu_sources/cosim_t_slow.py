"""Test FMU: a source that sleeps a little per step, so a run lasts long enough to interrupt.

``spin`` > 0 makes a step busy-wait that long in Python instead (a step stuck in Python code,
which the watchdog can unwind; a long ``delay`` is one stuck in C, which it cannot). With ``$COSIM_T_SLOW_STEPPING``
set, its first step creates the file it names before it sleeps: a test waits for that file, not for a guessed time."""
import os
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTSlow(Fmi2Slave):
    author = "cosim tests"
    description = "slow ramp"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.delay = 0.001
        self.spin = 0.0
        self.y = 0.0
        self.register_variable(Real("delay", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("spin", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))

    def do_step(self, current_time, step_size):
        stepping = os.environ.get("COSIM_T_SLOW_STEPPING")
        if stepping and not getattr(self, "_said", False):
            self._said = True
            open(stepping, "w").close()
        time.sleep(self.delay)
        end = time.perf_counter() + self.spin
        while time.perf_counter() < end:
            pass
        self.y = current_time + step_size
        return True
