"""Test FMU: y = offset + amplitude * sin(2 pi f t) (no inputs)."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTSource(Fmi2Slave):
    author = "cosim tests"
    description = "sine source"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.amplitude = 1.0
        self.frequency = 1.0
        self.offset = 0.0
        self.y = 0.0
        for name in ("amplitude", "frequency", "offset"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))

    def exit_initialization_mode(self):
        self.y = self.offset

    def do_step(self, current_time, step_size):
        t = current_time + step_size
        self.y = self.offset + self.amplitude * math.sin(2.0 * math.pi * self.frequency * t)
        return True
