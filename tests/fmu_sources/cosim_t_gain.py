"""Test FMU: y = k * u (direct feedthrough)."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTGain(Fmi2Slave):
    author = "cosim tests"
    description = "gain"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 1.0
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))

    def do_step(self, current_time, step_size):
        self.y = self.k * self.u
        return True
