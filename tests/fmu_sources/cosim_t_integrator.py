"""Test FMU: x' = u, exact for an input held over the step (x += u h); no direct feedthrough.

x starts at the parameter x0: read before the first step (initialization mode included) it is
x0, computed when read, as any importer expects of an output with initial="calculated"."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class CosimTIntegrator(Fmi2Slave):
    author = "cosim tests"
    description = "integrator"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.x0 = 0.0
        self.u = 0.0
        self.x = None  # None until the first step: x(t0) = x0
        self.register_variable(Real("x0", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("x", causality=Fmi2Causality.output, initial="calculated",
                                    getter=lambda: self.x0 if self.x is None else self.x))

    def do_step(self, current_time, step_size):
        self.x = (self.x0 if self.x is None else self.x) + self.u * step_size
        return True
