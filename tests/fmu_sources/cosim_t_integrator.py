"""Test FMU: x' = u, exact for an input held over the step (x += u h); no direct feedthrough."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTIntegrator(Fmi2Slave):
    author = "cosim tests"
    description = "integrator"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.x0 = 0.0
        self.u = 0.0
        self.x = 0.0
        self.register_variable(Real("x0", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("x", causality=Fmi2Causality.output, initial="exact"))

    def exit_initialization_mode(self):
        self.x = self.x0

    def do_step(self, current_time, step_size):
        self.x += self.u * step_size
        return True
