"""Test FMU: a source that sleeps a little per step, so a run lasts long enough to interrupt."""
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTSlow(Fmi2Slave):
    author = "cosim tests"
    description = "slow ramp"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.delay = 0.001
        self.y = 0.0
        self.register_variable(Real("delay", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))

    def do_step(self, current_time, step_size):
        time.sleep(self.delay)
        self.y = current_time + step_size
        return True
