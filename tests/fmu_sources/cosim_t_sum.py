"""Test FMU: y = a + b and n = steps taken (an Integer output next to a Real one)."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Integer, Real


class CosimTSum(Fmi2Slave):
    author = "cosim tests"
    description = "sum and step counter"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.a = 0.0
        self.b = 0.0
        self.y = 0.0
        self.n = 0
        self.register_variable(Real("a", causality=Fmi2Causality.input))
        self.register_variable(Real("b", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))
        self.register_variable(Integer("n", causality=Fmi2Causality.output, initial="exact"))

    def do_step(self, current_time, step_size):
        self.y = self.a + self.b
        self.n += 1
        return True
