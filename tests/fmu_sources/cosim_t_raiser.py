"""Test FMU: copies u to y and raises in do_step once t >= fail_time."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTRaiser(Fmi2Slave):
    author = "cosim tests"
    description = "fails at a given time"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.fail_time = 1.0
        self.u = 0.0
        self.y = 0.0
        self.register_variable(Real("fail_time", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial="exact"))

    def do_step(self, current_time, step_size):
        if current_time >= self.fail_time - 1e-12:
            raise RuntimeError(f"deliberate failure at t = {current_time}")
        self.y = self.u
        return True
